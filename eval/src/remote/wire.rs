//! openpi's message format: msgpack maps whose numpy arrays travel as
//! `{"__ndarray__": true, "data": <bin>, "dtype": "<f4", "shape": [..]}` (openpi_client's
//! `msgpack_numpy`; the marker keys are msgpack *bin* strings when Python packs them, so both bin
//! and str keys are read), and numpy scalars as `{"__npgeneric__": true, "data": v, "dtype": ..}`.

use rmpv::Value;

/// A decoding problem, in words naming the key.
pub type WireError = String;

/// A numpy array read off the wire.
#[derive(Clone, Debug, PartialEq)]
pub struct NdArray {
    /// numpy type string, e.g. `<f4`, `|u1`.
    pub dtype: String,
    /// Shape.
    pub shape: Vec<usize>,
    /// Raw bytes in `dtype`, C order.
    pub data: Vec<u8>,
}

/// An array `value` of `dtype` and `shape` in openpi's encoding (marker keys as bin, as Python's
/// packer writes them).
pub fn ndarray(dtype: &str, shape: &[usize], data: Vec<u8>) -> Value {
    Value::Map(vec![
        (Value::Binary(b"__ndarray__".to_vec()), Value::Boolean(true)),
        (Value::Binary(b"data".to_vec()), Value::Binary(data)),
        (Value::Binary(b"dtype".to_vec()), Value::from(dtype)),
        (
            Value::Binary(b"shape".to_vec()),
            Value::Array(shape.iter().map(|&n| Value::from(n as u64)).collect()),
        ),
    ])
}

/// A float32 array (`<f4`) of `shape` from `values` (row-major).
pub fn f32_array(shape: &[usize], values: &[f32]) -> Value {
    ndarray(
        "<f4",
        shape,
        values.iter().flat_map(|v| v.to_le_bytes()).collect(),
    )
}

/// A uint8 array (`|u1`) of `shape`.
pub fn u8_array(shape: &[usize], values: Vec<u8>) -> Value {
    ndarray("|u1", shape, values)
}

/// Whether a map key is `name`, as a str or a bin string.
fn key_is(k: &Value, name: &str) -> bool {
    match k {
        Value::String(s) => s.as_str() == Some(name),
        Value::Binary(b) => b.as_slice() == name.as_bytes(),
        _ => false,
    }
}

/// The value under `name` in a map (str or bin key).
pub fn get<'a>(map: &'a Value, name: &str) -> Option<&'a Value> {
    match map {
        Value::Map(entries) => entries
            .iter()
            .find(|(k, _)| key_is(k, name))
            .map(|(_, v)| v),
        _ => None,
    }
}

/// A map from str keys.
pub fn map(entries: Vec<(&str, Value)>) -> Value {
    Value::Map(
        entries
            .into_iter()
            .map(|(k, v)| (Value::from(k), v))
            .collect(),
    )
}

/// Reads an openpi array (`what` names it in errors).
pub fn read_ndarray(v: &Value, what: &str) -> Result<NdArray, WireError> {
    if !matches!(get(v, "__ndarray__"), Some(Value::Boolean(true))) {
        return Err(format!(
            "`{what}` is not a numpy array (no `__ndarray__` marker)"
        ));
    }
    let data = match get(v, "data") {
        Some(Value::Binary(b)) => b.clone(),
        _ => return Err(format!("`{what}`: `data` is not bytes")),
    };
    let dtype = match get(v, "dtype") {
        Some(Value::String(s)) => s
            .as_str()
            .ok_or_else(|| format!("`{what}`: `dtype` is not UTF-8"))?
            .to_string(),
        Some(Value::Binary(b)) => {
            String::from_utf8(b.clone()).map_err(|_| format!("`{what}`: `dtype` is not UTF-8"))?
        }
        _ => return Err(format!("`{what}`: no `dtype` string")),
    };
    let shape = match get(v, "shape") {
        Some(Value::Array(dims)) => dims
            .iter()
            .map(|d| {
                d.as_u64()
                    .map(|n| n as usize)
                    .ok_or_else(|| format!("`{what}`: shape entry {d} is not a size"))
            })
            .collect::<Result<Vec<_>, _>>()?,
        _ => return Err(format!("`{what}`: `shape` is not a list")),
    };
    let n: usize = shape.iter().product();
    let size =
        item_size(&dtype).ok_or_else(|| format!("`{what}`: dtype `{dtype}` is not supported"))?;
    if data.len() != n * size {
        return Err(format!(
            "`{what}`: {} bytes for shape {shape:?} of `{dtype}` ({} expected)",
            data.len(),
            n * size
        ));
    }
    Ok(NdArray { dtype, shape, data })
}

/// Bytes per item of the numpy type strings this client reads.
fn item_size(dtype: &str) -> Option<usize> {
    match dtype {
        "<f4" | "<i4" | "<u4" => Some(4),
        "<f8" | "<i8" | "<u8" => Some(8),
        "|u1" | "|i1" | "|b1" => Some(1),
        _ => None,
    }
}

impl NdArray {
    /// The values as f32 (float, integer and bool arrays; little-endian).
    pub fn to_f32(&self) -> Vec<f32> {
        let d = &self.data;
        match self.dtype.as_str() {
            "<f4" => d
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect(),
            "<f8" => d
                .chunks_exact(8)
                .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")) as f32)
                .collect(),
            "<i4" => d
                .chunks_exact(4)
                .map(|c| i32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f32)
                .collect(),
            "<u4" => d
                .chunks_exact(4)
                .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f32)
                .collect(),
            "<i8" => d
                .chunks_exact(8)
                .map(|c| i64::from_le_bytes(c.try_into().expect("8 bytes")) as f32)
                .collect(),
            "<u8" => d
                .chunks_exact(8)
                .map(|c| u64::from_le_bytes(c.try_into().expect("8 bytes")) as f32)
                .collect(),
            "|i1" => d.iter().map(|&b| b as i8 as f32).collect(),
            _ => d.iter().map(|&b| b as f32).collect(),
        }
    }
}

/// msgpack bytes of `v`.
pub fn encode(v: &Value) -> Vec<u8> {
    let mut out = Vec::new();
    rmpv::encode::write_value(&mut out, v).expect("writing to a Vec cannot fail");
    out
}

/// The msgpack value of `bytes` (the whole buffer).
pub fn decode(bytes: &[u8]) -> Result<Value, WireError> {
    let mut cur = bytes;
    let v = rmpv::decode::read_value(&mut cur).map_err(|e| format!("not msgpack: {e}"))?;
    if !cur.is_empty() {
        return Err(format!("{} bytes after the msgpack value", cur.len()));
    }
    Ok(v)
}

/// Decodes the action chunk of a reply: `actions` as `[H, A]` (or `[A]`, one action) with A ≥ 7;
/// the first 7 values of each row are the action.
pub fn read_actions(reply: &Value) -> Result<Vec<[f32; 7]>, WireError> {
    let Value::Map(_) = reply else {
        return Err(format!("the reply is not a map but {}", kind(reply)));
    };
    let arr = get(reply, "actions").ok_or("the reply has no `actions`")?;
    let a = read_ndarray(arr, "actions")?;
    let (h, width) = match a.shape.as_slice() {
        [h, w] => (*h, *w),
        [w] => (1, *w),
        s => return Err(format!("`actions` has shape {s:?}, expected [H, 7]")),
    };
    if width < 7 || h == 0 {
        return Err(format!(
            "`actions` has shape {:?}, expected [H ≥ 1, 7]",
            a.shape
        ));
    }
    let v = a.to_f32();
    for i in 0..h {
        for j in 0..7 {
            let x = v[i * width + j];
            if !x.is_finite() {
                return Err(format!("`actions`[{i}, {j}] is {x}, not a finite number"));
            }
        }
    }
    Ok((0..h)
        .map(|i| std::array::from_fn(|j| v[i * width + j]))
        .collect())
}

/// A short name of a value's msgpack type, for errors.
pub fn kind(v: &Value) -> &'static str {
    match v {
        Value::Nil => "nil",
        Value::Boolean(_) => "a boolean",
        Value::Integer(_) => "an integer",
        Value::F32(_) | Value::F64(_) => "a float",
        Value::String(_) => "a string",
        Value::Binary(_) => "bytes",
        Value::Array(_) => "a list",
        Value::Map(_) => "a map",
        Value::Ext(..) => "an extension",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arrays_are_encoded_as_python_packs_them() {
        // msgpack of {b"__ndarray__": True, b"data": b"\x01\x02", b"dtype": "|u1", b"shape": (2,)}
        // as openpi_client's Packer (use_bin_type) writes it, byte for byte.
        let mut want = vec![0x84, 0xc4, 11];
        want.extend_from_slice(b"__ndarray__");
        want.push(0xc3);
        want.extend_from_slice(&[0xc4, 4]);
        want.extend_from_slice(b"data");
        want.extend_from_slice(&[0xc4, 2, 1, 2]);
        want.extend_from_slice(&[0xc4, 5]);
        want.extend_from_slice(b"dtype");
        want.extend_from_slice(&[0xa3]);
        want.extend_from_slice(b"|u1");
        want.extend_from_slice(&[0xc4, 5]);
        want.extend_from_slice(b"shape");
        want.extend_from_slice(&[0x91, 0x02]);
        let v = u8_array(&[2], vec![1, 2]);
        assert_eq!(encode(&v), want);
        let back = read_ndarray(&decode(&want).unwrap(), "x").unwrap();
        assert_eq!(back.shape, [2]);
        assert_eq!(back.to_f32(), [1.0, 2.0]);
    }

    #[test]
    fn str_keys_and_every_float_width_are_read() {
        let f64s: Vec<u8> = [0.5f64, -2.0, 3.0, 0.0, 0.0, 0.0, 1.0, 9.0]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        // One action of 8 values with str marker keys (another packer's choice).
        let arr = Value::Map(vec![
            (Value::from("__ndarray__"), Value::Boolean(true)),
            (Value::from("data"), Value::Binary(f64s)),
            (Value::from("dtype"), Value::from("<f8")),
            (
                Value::from("shape"),
                Value::Array(vec![Value::from(1), Value::from(8)]),
            ),
        ]);
        let reply = map(vec![("actions", arr)]);
        let acts = read_actions(&decode(&encode(&reply)).unwrap()).unwrap();
        assert_eq!(acts, vec![[0.5, -2.0, 3.0, 0.0, 0.0, 0.0, 1.0]]);
        let chunk = f32_array(&[2, 7], &[0.25; 14]);
        let acts = read_actions(&map(vec![("actions", chunk)])).unwrap();
        assert_eq!(acts.len(), 2);
        assert_eq!(acts[1][6], 0.25);
    }

    #[test]
    fn malformed_replies_are_named() {
        let e = read_actions(&Value::from("boom")).unwrap_err();
        assert!(e.contains("not a map but a string"), "{e}");
        let e = read_actions(&map(vec![])).unwrap_err();
        assert!(e.contains("no `actions`"), "{e}");
        let e = read_actions(&map(vec![("actions", f32_array(&[2, 3], &[0.0; 6]))])).unwrap_err();
        assert!(e.contains("shape [2, 3], expected [H ≥ 1, 7]"), "{e}");
        let short = ndarray("<f4", &[1, 7], vec![0; 12]);
        let e = read_actions(&map(vec![("actions", short)])).unwrap_err();
        assert!(
            e.contains("12 bytes for shape [1, 7] of `<f4` (28 expected)"),
            "{e}"
        );
        let odd = ndarray("<c8", &[1], vec![0; 8]);
        let e = read_ndarray(&odd, "x").unwrap_err();
        assert!(e.contains("dtype `<c8` is not supported"), "{e}");
        let e = decode(&[0x91]).unwrap_err();
        assert!(e.starts_with("not msgpack"), "{e}");
        let e = decode(&[0xc0, 0xc0]).unwrap_err();
        assert!(e.contains("1 bytes after"), "{e}");
    }
}
