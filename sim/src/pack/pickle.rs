//! LIBERO's init states (`init_files/<suite>/<task>.pruned_init`) read without Python or torch.
//!
//! A `.pruned_init` file is a `torch.save` ZIP archive whose `*/data.pkl` is a protocol-2 pickle of one
//! NumPy float64 array `[N, 1 + nq + nv]` (rows `[time, qpos, qvel]`, robosuite's flattened
//! `MjSimState`). The reader below is a small pickle machine that accepts exactly that shape of pickle:
//! the only callables it resolves are `numpy.core.multiarray._reconstruct`, `numpy.ndarray`,
//! `numpy.dtype` and `_codecs.encode`, and nothing is ever executed. Anything else is an error naming
//! the opcode or global and its byte offset.

use std::io::Read;
use std::path::Path;

/// Errors reading an init file.
#[derive(Debug, thiserror::Error)]
pub enum InitError {
    /// The file cannot be read or is not a ZIP archive with a `data.pkl`.
    #[error("{path}: {message}")]
    Container {
        /// The file.
        path: String,
        /// What is wrong.
        message: String,
    },
    /// The pickle is not the one accepted shape.
    #[error("{path}: pickle byte {offset}: {message}")]
    Pickle {
        /// The file.
        path: String,
        /// Byte offset in `data.pkl`.
        offset: usize,
        /// What is wrong.
        message: String,
    },
    /// Asked for a state past the end of the file.
    #[error("{path}: init state {k} asked for, the file holds {rows}")]
    Missing {
        /// The file.
        path: String,
        /// The state asked for.
        k: usize,
        /// States in the file.
        rows: usize,
    },
    /// The rows do not fit the model.
    #[error(
        "{path}: init states have {width} columns (1 + nq + nv), but this model needs {expected} (nq {nq}, nv {nv}); is it the init file of another task?"
    )]
    Width {
        /// The file.
        path: String,
        /// Columns in the file.
        width: usize,
        /// Columns the model needs.
        expected: usize,
        /// The model's nq.
        nq: usize,
        /// The model's nv.
        nv: usize,
    },
}

/// The init states of one task: `rows × width` float64 values, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct InitStates {
    /// Number of states (50 in every `.pruned_init`).
    pub rows: usize,
    /// Values per state, 1 + nq + nv.
    pub width: usize,
    /// The states, row-major.
    pub data: Vec<f64>,
    /// Where they came from (for error messages).
    pub source: String,
}

/// One state split into its parts.
#[derive(Debug, Clone, PartialEq)]
pub struct InitState<'a> {
    /// Simulation time.
    pub time: f64,
    /// Joint positions.
    pub qpos: &'a [f64],
    /// Joint velocities.
    pub qvel: &'a [f64],
}

impl InitStates {
    /// Reads a `.pruned_init` / `.init` file.
    pub fn read(path: &Path) -> Result<InitStates, InitError> {
        let name = path.display().to_string();
        let container = |message: String| InitError::Container {
            path: name.clone(),
            message,
        };
        let file = std::fs::File::open(path).map_err(|e| container(e.to_string()))?;
        let mut zip = zip::ZipArchive::new(file)
            .map_err(|e| container(format!("not a torch archive (ZIP): {e}")))?;
        let entry = (0..zip.len())
            .filter_map(|i| zip.by_index(i).ok().map(|f| f.name().to_string()))
            .find(|n| n == "data.pkl" || n.ends_with("/data.pkl"))
            .ok_or_else(|| container("the archive holds no data.pkl".into()))?;
        let mut bytes = Vec::new();
        zip.by_name(&entry)
            .map_err(|e| container(e.to_string()))?
            .read_to_end(&mut bytes)
            .map_err(|e| container(e.to_string()))?;
        let (rows, width, data) =
            parse_array(&bytes).map_err(|(offset, message)| InitError::Pickle {
                path: name.clone(),
                offset,
                message,
            })?;
        Ok(InitStates {
            rows,
            width,
            data,
            source: name,
        })
    }

    /// [`InitStates::state`], with a missing state as [`InitError::Missing`].
    pub fn require(&self, k: usize, nq: usize, nv: usize) -> Result<InitState<'_>, InitError> {
        self.state(k, nq, nv)?.ok_or_else(|| InitError::Missing {
            path: self.source.clone(),
            k,
            rows: self.rows,
        })
    }

    /// State `k` split for a model with `nq` and `nv`; a width mismatch is [`InitError::Width`].
    pub fn state(
        &self,
        k: usize,
        nq: usize,
        nv: usize,
    ) -> Result<Option<InitState<'_>>, InitError> {
        if self.width != 1 + nq + nv {
            return Err(InitError::Width {
                path: self.source.clone(),
                width: self.width,
                expected: 1 + nq + nv,
                nq,
                nv,
            });
        }
        if k >= self.rows {
            return Ok(None);
        }
        let row = &self.data[k * self.width..(k + 1) * self.width];
        Ok(Some(InitState {
            time: row[0],
            qpos: &row[1..1 + nq],
            qvel: &row[1 + nq..],
        }))
    }
}

/// Values on the pickle machine's stack and memo.
#[derive(Debug, Clone, PartialEq)]
enum Value {
    Mark,
    None,
    Bool(bool),
    Int(i64),
    Str(String),
    Bytes(Vec<u8>),
    Tuple(Vec<Value>),
    Global(&'static str),
    /// `numpy.dtype('f8', False, True)` after its state was set: byte order char.
    Dtype {
        kind: String,
        order: Option<String>,
    },
    /// An ndarray under construction, then with its state.
    Array {
        shape: Vec<usize>,
        dtype: Option<Box<Value>>,
        fortran: bool,
        data: Option<Vec<u8>>,
    },
}

const ALLOWED: [(&str, &str, &str); 4] = [
    ("numpy.core.multiarray", "_reconstruct", "reconstruct"),
    ("numpy", "ndarray", "ndarray"),
    ("numpy", "dtype", "dtype"),
    ("_codecs", "encode", "encode"),
];

type PResult<T> = Result<T, (usize, String)>;

struct Machine<'a> {
    b: &'a [u8],
    pos: usize,
    stack: Vec<Value>,
    memo: std::collections::HashMap<u32, Value>,
}

impl Machine<'_> {
    fn take(&mut self, n: usize) -> PResult<&[u8]> {
        if self.pos + n > self.b.len() {
            return Err((self.pos, "unexpected end of pickle".into()));
        }
        let s = &self.b[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    fn u8(&mut self) -> PResult<u8> {
        Ok(self.take(1)?[0])
    }
    fn u32(&mut self) -> PResult<u32> {
        let s = self.take(4)?;
        Ok(u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
    }
    fn line(&mut self) -> PResult<String> {
        let start = self.pos;
        let end = self.b[start..]
            .iter()
            .position(|&c| c == b'\n')
            .ok_or((start, "unterminated GLOBAL".to_string()))?;
        self.pos = start + end + 1;
        String::from_utf8(self.b[start..start + end].to_vec())
            .map_err(|_| (start, "GLOBAL name is not UTF-8".to_string()))
    }
    fn pop(&mut self, at: usize) -> PResult<Value> {
        self.stack.pop().ok_or((at, "stack underflow".into()))
    }
    fn pop_mark(&mut self, at: usize) -> PResult<Vec<Value>> {
        let i = self
            .stack
            .iter()
            .rposition(|v| *v == Value::Mark)
            .ok_or((at, "no MARK on the stack".to_string()))?;
        let items = self.stack.split_off(i + 1);
        self.stack.pop();
        Ok(items)
    }
}

fn int(v: &Value, at: usize) -> PResult<i64> {
    match v {
        Value::Int(i) => Ok(*i),
        other => Err((at, format!("expected an integer, found {other:?}"))),
    }
}

/// Calls one of the allowed globals.
fn call(f: &str, args: Vec<Value>, at: usize) -> PResult<Value> {
    match (f, args.as_slice()) {
        ("encode", [Value::Str(s), Value::Str(enc)]) if enc == "latin1" || enc == "latin-1" => {
            let mut out = Vec::with_capacity(s.len());
            for c in s.chars() {
                let c = c as u32;
                if c > 255 {
                    return Err((at, "latin1 data holds a character above U+00FF".into()));
                }
                out.push(c as u8);
            }
            Ok(Value::Bytes(out))
        }
        (
            "reconstruct",
            [
                Value::Global("ndarray"),
                Value::Tuple(shape),
                Value::Bytes(_),
            ],
        ) => {
            if shape.len() != 1 || int(&shape[0], at)? != 0 {
                return Err((at, "ndarray reconstruct with a non-empty shape".into()));
            }
            Ok(Value::Array {
                shape: vec![],
                dtype: None,
                fortran: false,
                data: None,
            })
        }
        ("dtype", [Value::Str(kind), Value::Bool(false), Value::Bool(true)]) => Ok(Value::Dtype {
            kind: kind.clone(),
            order: None,
        }),
        _ => Err((at, format!("call of `{f}` with unexpected arguments"))),
    }
}

/// Applies BUILD (`__setstate__`) to a dtype or an array.
fn build(obj: Value, state: Value, at: usize) -> PResult<Value> {
    let Value::Tuple(s) = state else {
        return Err((at, "BUILD state is not a tuple".into()));
    };
    match obj {
        Value::Dtype { kind, .. } => match s.as_slice() {
            [
                Value::Int(3),
                Value::Str(order),
                Value::None,
                Value::None,
                Value::None,
                Value::Int(-1),
                Value::Int(-1),
                Value::Int(0),
            ] => Ok(Value::Dtype {
                kind,
                order: Some(order.clone()),
            }),
            _ => Err((at, "unexpected dtype state".into())),
        },
        Value::Array { .. } => match s.as_slice() {
            [
                Value::Int(1),
                Value::Tuple(shape),
                dtype @ Value::Dtype { .. },
                Value::Bool(fortran),
                Value::Bytes(data),
            ] => {
                let shape = shape
                    .iter()
                    .map(|v| {
                        int(v, at).and_then(|i| {
                            usize::try_from(i).map_err(|_| (at, "negative dimension".to_string()))
                        })
                    })
                    .collect::<PResult<Vec<usize>>>()?;
                Ok(Value::Array {
                    shape,
                    dtype: Some(Box::new(dtype.clone())),
                    fortran: *fortran,
                    data: Some(data.clone()),
                })
            }
            _ => Err((at, "unexpected ndarray state".into())),
        },
        other => Err((at, format!("BUILD on {other:?}"))),
    }
}

/// Runs the pickle and returns the float64 matrix it holds: (rows, columns, values).
pub fn parse_array(b: &[u8]) -> Result<(usize, usize, Vec<f64>), (usize, String)> {
    let mut m = Machine {
        b,
        pos: 0,
        stack: Vec::new(),
        memo: Default::default(),
    };
    let result = loop {
        let at = m.pos;
        let op = m.u8()?;
        match op {
            0x80 => {
                let proto = m.u8()?;
                if proto > 4 {
                    return Err((at, format!("pickle protocol {proto} (expected 2)")));
                }
            }
            b'c' => {
                let module = m.line()?;
                let name = m.line()?;
                let f = ALLOWED
                    .iter()
                    .find(|(md, n, _)| *md == module && *n == name)
                    .map(|(_, _, tag)| *tag)
                    .ok_or_else(|| (at, format!("global `{module}.{name}` is not allowed")))?;
                m.stack.push(Value::Global(f));
            }
            b'q' => {
                let k = m.u8()? as u32;
                let v = m
                    .stack
                    .last()
                    .cloned()
                    .ok_or((at, "BINPUT on an empty stack".to_string()))?;
                m.memo.insert(k, v);
            }
            b'r' => {
                let k = m.u32()?;
                let v = m
                    .stack
                    .last()
                    .cloned()
                    .ok_or((at, "LONG_BINPUT on an empty stack".to_string()))?;
                m.memo.insert(k, v);
            }
            b'h' | b'j' => {
                let k = if op == b'h' { m.u8()? as u32 } else { m.u32()? };
                let v = m
                    .memo
                    .get(&k)
                    .cloned()
                    .ok_or((at, format!("memo {k} is empty")))?;
                m.stack.push(v);
            }
            b'K' => {
                let v = m.u8()?;
                m.stack.push(Value::Int(v as i64));
            }
            b'M' => {
                let s = m.take(2)?;
                let v = u16::from_le_bytes([s[0], s[1]]);
                m.stack.push(Value::Int(v as i64));
            }
            b'J' => {
                let v = m.u32()? as i32;
                m.stack.push(Value::Int(v as i64));
            }
            b'N' => m.stack.push(Value::None),
            0x88 => m.stack.push(Value::Bool(true)),
            0x89 => m.stack.push(Value::Bool(false)),
            b'(' => m.stack.push(Value::Mark),
            b'X' | 0x8c => {
                let n = if op == b'X' {
                    m.u32()? as usize
                } else {
                    m.u8()? as usize
                };
                let s = m.take(n)?;
                let s = String::from_utf8(s.to_vec())
                    .map_err(|_| (at, "string is not UTF-8".to_string()))?;
                m.stack.push(Value::Str(s));
            }
            b'C' | b'B' => {
                let n = if op == b'C' {
                    m.u8()? as usize
                } else {
                    m.u32()? as usize
                };
                let s = m.take(n)?.to_vec();
                m.stack.push(Value::Bytes(s));
            }
            b')' => m.stack.push(Value::Tuple(vec![])),
            0x85..=0x87 => {
                let n = (op - 0x84) as usize;
                if m.stack.len() < n {
                    return Err((at, "stack underflow".into()));
                }
                let items = m.stack.split_off(m.stack.len() - n);
                if items.contains(&Value::Mark) {
                    return Err((at, "MARK inside a tuple".into()));
                }
                m.stack.push(Value::Tuple(items));
            }
            b't' => {
                let items = m.pop_mark(at)?;
                m.stack.push(Value::Tuple(items));
            }
            b'R' => {
                let args = m.pop(at)?;
                let f = m.pop(at)?;
                let (Value::Global(f), Value::Tuple(args)) = (f, args) else {
                    return Err((at, "REDUCE needs a global and a tuple".into()));
                };
                let v = call(f, args, at)?;
                m.stack.push(v);
            }
            b'b' => {
                let state = m.pop(at)?;
                let obj = m.pop(at)?;
                let v = build(obj, state, at)?;
                m.stack.push(v);
            }
            b'.' => break m.pop(at)?,
            other => return Err((at, format!("opcode 0x{other:02x} is not accepted"))),
        }
    };
    let at = m.pos;
    let Value::Array {
        shape,
        dtype: Some(dtype),
        fortran,
        data: Some(data),
    } = result
    else {
        return Err((at, "the pickle does not hold a NumPy array".into()));
    };
    match *dtype {
        Value::Dtype {
            ref kind,
            order: Some(ref order),
        } if kind == "f8" && (order == "<" || order == "=") => {}
        other => {
            return Err((
                at,
                format!("array dtype {other:?}, expected little-endian f8"),
            ));
        }
    }
    if shape.len() != 2 {
        return Err((at, format!("array of shape {shape:?}, expected 2-D")));
    }
    let (rows, cols) = (shape[0], shape[1]);
    // Checked: a damaged file can claim any shape.
    let bytes = rows.checked_mul(cols).and_then(|n| n.checked_mul(8));
    if bytes != Some(data.len()) {
        return Err((at, format!("{} data bytes for shape {shape:?}", data.len())));
    }
    let vals: Vec<f64> = data
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
        .collect();
    let vals = if fortran && rows > 0 && cols > 0 {
        (0..rows * cols)
            .map(|i| vals[(i % cols) * rows + i / cols])
            .collect()
    } else {
        vals
    };
    Ok((rows, cols, vals))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Builds the pickle `torch.save(np.array(values).reshape(rows, cols))` writes (protocol 2,
    /// data through `_codecs.encode(latin1)`), as the LIBERO files hold it.
    pub(crate) fn numpy_pickle(rows: u8, cols: u8, values: &[f64]) -> Vec<u8> {
        let mut p = vec![0x80, 2];
        let global = |p: &mut Vec<u8>, m: &str, n: &str| {
            p.push(b'c');
            p.extend_from_slice(m.as_bytes());
            p.push(b'\n');
            p.extend_from_slice(n.as_bytes());
            p.push(b'\n');
        };
        let unicode = |p: &mut Vec<u8>, s: &str| {
            p.push(b'X');
            p.extend_from_slice(&(s.len() as u32).to_le_bytes());
            p.extend_from_slice(s.as_bytes());
        };
        global(&mut p, "numpy.core.multiarray", "_reconstruct");
        global(&mut p, "numpy", "ndarray");
        p.extend_from_slice(&[b'K', 0, 0x85]);
        global(&mut p, "_codecs", "encode");
        p.extend_from_slice(&[b'q', 3]);
        unicode(&mut p, "b");
        unicode(&mut p, "latin1");
        p.extend_from_slice(&[b'q', 5, 0x86, b'R', 0x87, b'R']);
        p.extend_from_slice(&[b'(', b'K', 1, b'K', rows, b'K', cols, 0x86]);
        global(&mut p, "numpy", "dtype");
        unicode(&mut p, "f8");
        p.extend_from_slice(&[0x89, 0x88, 0x87, b'R']);
        p.extend_from_slice(&[b'(', b'K', 3]);
        unicode(&mut p, "<");
        p.extend_from_slice(&[
            b'N', b'N', b'N', b'J', 0xff, 0xff, 0xff, 0xff, b'J', 0xff, 0xff, 0xff, 0xff, b'K', 0,
            b't', b'b',
        ]);
        p.push(0x89);
        p.extend_from_slice(&[b'h', 3]);
        let latin: String = values
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .map(|b| b as char)
            .collect();
        unicode(&mut p, &latin);
        p.extend_from_slice(&[b'h', 5, 0x86, b'R', b't', b'b', b'.']);
        p
    }

    #[test]
    fn reads_the_numpy_pickle_exactly() {
        let vals: Vec<f64> = (0..12).map(|i| i as f64 * 0.25 - 1.0 + 1e-9).collect();
        let (r, c, v) = parse_array(&numpy_pickle(3, 4, &vals)).unwrap();
        assert_eq!((r, c), (3, 4));
        assert_eq!(v, vals);
    }

    #[test]
    fn refuses_other_globals_and_truncation() {
        let e = parse_array(b"\x80\x02cnumpy\nsystem\n").unwrap_err();
        assert!(e.1.contains("`numpy.system` is not allowed"), "{e:?}");
        let p = numpy_pickle(1, 2, &[1.0, 2.0]);
        let e = parse_array(&p[..p.len() - 3]).unwrap_err();
        assert!(
            e.1.contains("end of pickle") || e.1.contains("underflow"),
            "{e:?}"
        );
        let e = parse_array(b"\x80\x02cos\nsystem\n").unwrap_err();
        assert_eq!(e.0, 2);
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(2000))]
        /// Fuzzing the reader: a real numpy pickle with bytes replaced, cut or duplicated, and
        /// arbitrary bytes, give an array or an error at an offset inside the input, never a
        /// panic (overflow checks are on in tests) and never an allocation the input cannot fill.
        #[test]
        fn damaged_pickles_never_panic(
            edits in proptest::collection::vec((0usize..4096, 0u8..3, proptest::prelude::any::<u8>()), 1..6),
        ) {
            let mut b = numpy_pickle(3, 4, &[0.5; 12]);
            for (at, kind, v) in edits {
                let i = at % b.len().max(1);
                match kind {
                    0 => if i < b.len() { b[i] = v },
                    1 => b.truncate(i),
                    _ => { let tail = b[i..].to_vec(); b.extend_from_slice(&tail[..tail.len().min(32)]) }
                }
            }
            check(&b)?;
        }

        #[test]
        fn arbitrary_bytes_never_panic(b in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..256)) {
            check(&b)?;
        }
    }

    fn check(b: &[u8]) -> Result<(), proptest::test_runner::TestCaseError> {
        match parse_array(b) {
            Ok((r, c, v)) => proptest::prop_assert_eq!(r * c, v.len()),
            Err((offset, msg)) => {
                proptest::prop_assert!(
                    offset <= b.len(),
                    "offset {} of {}: {}",
                    offset,
                    b.len(),
                    msg
                )
            }
        }
        Ok(())
    }

    #[test]
    fn a_huge_claimed_shape_is_an_error_not_an_allocation() {
        let mut p = numpy_pickle(3, 4, &[0.5; 12]);
        // The shape's two small ints (`K 3`, `K 4`) become 4-byte ints of 2^31 - 1 each.
        let at = p.windows(4).position(|w| w == [b'K', 3, b'K', 4]).unwrap();
        p.splice(
            at..at + 4,
            [b'J', 0xff, 0xff, 0xff, 0x7f, b'J', 0xff, 0xff, 0xff, 0x7f],
        );
        let e = parse_array(&p).unwrap_err();
        assert!(e.0 <= p.len(), "{e:?}");
    }

    #[test]
    fn width_mismatch_names_both_sizes() {
        let s = InitStates {
            rows: 2,
            width: 5,
            data: vec![0.0; 10],
            source: "x.pruned_init".into(),
        };
        let st = s.state(1, 2, 2).unwrap().unwrap();
        assert_eq!((st.qpos.len(), st.qvel.len()), (2, 2));
        assert!(s.state(2, 2, 2).unwrap().is_none());
        let e = s.require(2, 2, 2).unwrap_err().to_string();
        assert!(
            e.contains("init state 2 asked for, the file holds 2"),
            "{e}"
        );
        let e = s.state(0, 41, 37).unwrap_err().to_string();
        assert!(e.contains("5 columns") && e.contains("needs 79"), "{e}");
    }
}
