//! From the s-expression tree to a typed [`Problem`], with positions and "expected ..." in every error.

use std::collections::HashMap;

use super::ast::{Atom, Goal, Instance, Problem, ProblemClass, Region};
use super::error::{BddlError, Span};
use super::lex::Sexp;
use super::predicate::Predicate;

type Result<T> = std::result::Result<T, BddlError>;

/// Sections we accept, in the order error messages list them.
const SECTIONS: [&str; 10] = [
    ":domain",
    ":requirements",
    ":language",
    ":regions",
    ":fixtures",
    ":objects",
    ":obj_of_interest",
    ":init",
    ":goal",
    ":scene_properties",
];

fn err(span: Span, msg: impl Into<String>) -> BddlError {
    BddlError::at(span, msg)
}

/// The symbol's lowercased text, or an error saying what was expected instead.
fn sym<'a>(s: &'a Sexp, expected: &str) -> Result<&'a str> {
    match s {
        Sexp::Sym { text, .. } => Ok(text),
        other => Err(err(
            other.span(),
            format!("expected {expected}, found {}", other.describe()),
        )),
    }
}

/// The list's items, or an error saying what was expected instead.
fn list<'a>(s: &'a Sexp, expected: &str) -> Result<&'a [Sexp]> {
    match s {
        Sexp::List { items, .. } => Ok(items),
        other => Err(err(
            other.span(),
            format!("expected {expected}, found {}", other.describe()),
        )),
    }
}

/// A list whose first item is a symbol: (head, rest, span of the `(`).
fn headed<'a>(s: &'a Sexp, expected: &str) -> Result<(&'a str, &'a [Sexp], Span)> {
    let items = list(s, expected)?;
    match items.first() {
        Some(Sexp::Sym { text, .. }) => Ok((text, &items[1..], s.span())),
        Some(other) => Err(err(
            other.span(),
            format!("expected {expected}, found {}", other.describe()),
        )),
        None => Err(err(
            s.span(),
            format!("expected {expected}, found an empty list `()`"),
        )),
    }
}

/// Parses a whole problem from its top-level expression.
pub(crate) fn problem(root: &Sexp) -> Result<Problem> {
    const TOP: &str = "`(define (problem <ProblemClass>) <section>...)`";
    let items = list(root, TOP)?;
    match items.first() {
        Some(Sexp::Sym { text, .. }) if text == "define" => {}
        Some(other) => {
            return Err(err(
                other.span(),
                format!("expected {TOP}, found {}", other.describe()),
            ));
        }
        None => {
            return Err(err(
                root.span(),
                format!("expected {TOP}, found an empty list `()`"),
            ));
        }
    }
    let head = items.get(1).ok_or_else(|| {
        err(
            root.span(),
            "expected `(problem <ProblemClass>)` after `define`",
        )
    })?;
    let (kw, rest, head_span) = headed(head, "`(problem <ProblemClass>)`")?;
    if kw != "problem" {
        return Err(err(
            head_span,
            format!(
                "expected `(problem <ProblemClass>)`, found {}",
                head.describe()
            ),
        ));
    }
    let [class] = rest else {
        return Err(err(
            head_span,
            "expected exactly one problem class in `(problem <ProblemClass>)`",
        ));
    };
    let class_name = sym(class, "a problem class name")?;
    let problem_class = ProblemClass::from_name(class_name).ok_or_else(|| {
        let known: Vec<&str> = ProblemClass::ALL.iter().map(|c| c.name()).collect();
        err(
            class.span(),
            format!(
                "unknown problem class `{class_name}`; expected one of {}",
                known.join(", ")
            ),
        )
    })?;

    // Collect sections by name; order does not matter.
    let mut sections: HashMap<&str, (&[Sexp], Span)> = HashMap::new();
    for s in &items[2..] {
        let (name, body, span) = headed(s, "a section such as `(:objects ...)`")?;
        let Some(known) = SECTIONS.iter().find(|k| **k == name) else {
            return Err(err(
                span,
                format!(
                    "unknown section `{name}`; expected one of {}",
                    SECTIONS.join(", ")
                ),
            ));
        };
        if let Some((_, first)) = sections.get(known) {
            return Err(err(
                span,
                format!(
                    "duplicate section `{name}` (first at line {}, column {})",
                    first.line, first.col
                ),
            ));
        }
        sections.insert(known, (body, span));
    }

    let domain = match sections.get(":domain") {
        None => "robosuite".to_string(),
        Some((body, span)) => {
            let [d] = body else {
                return Err(err(*span, "expected `(:domain robosuite)`"));
            };
            let d = sym(d, "the domain `robosuite`")?;
            if d != "robosuite" {
                return Err(err(
                    body[0].span(),
                    format!("expected the domain `robosuite`, found `{d}`"),
                ));
            }
            d.to_string()
        }
    };

    let (mut language, mut language_raw) = (Vec::new(), Vec::new());
    if let Some((body, _)) = sections.get(":language") {
        for w in *body {
            match w {
                Sexp::Sym { text, raw, .. } => {
                    language.push(text.as_str());
                    language_raw.push(raw.as_str());
                }
                other => {
                    return Err(err(
                        other.span(),
                        format!("expected words, found {}", other.describe()),
                    ));
                }
            }
        }
    }

    let mut regions = Vec::new();
    let mut names: HashMap<String, Span> = HashMap::new();
    if let Some((body, _)) = sections.get(":regions") {
        for r in *body {
            let region = region(r)?;
            let key = region.key();
            if let Some(first) = names.get(&key) {
                return Err(err(
                    region.span,
                    format!(
                        "duplicate region key `{key}` (first at line {}, column {})",
                        first.line, first.col
                    ),
                ));
            }
            names.insert(key, region.span);
            regions.push(region);
        }
    }
    let fixtures = match sections.get(":fixtures") {
        Some((body, _)) => typed_list(body, "fixture", &mut names)?,
        None => Vec::new(),
    };
    let objects = match sections.get(":objects") {
        Some((body, _)) => typed_list(body, "object", &mut names)?,
        None => Vec::new(),
    };

    let mut obj_of_interest = Vec::new();
    if let Some((body, _)) = sections.get(":obj_of_interest") {
        // Visualisation only in LIBERO, so names are not checked against the declarations.
        for n in *body {
            obj_of_interest.push(sym(n, "a name")?.to_string());
        }
    }
    let mut init = Vec::new();
    if let Some((body, _)) = sections.get(":init") {
        for a in *body {
            init.push(atom(a, &names)?);
        }
    }
    let goal = match sections.get(":goal") {
        None => return Err(err(root.span(), "missing section `(:goal ...)`")),
        Some((body, span)) => {
            let [g] = body else {
                return Err(err(
                    *span,
                    "expected exactly one goal expression in `(:goal ...)`",
                ));
            };
            goal(g, &names)?
        }
    };

    Ok(Problem {
        problem_class,
        domain,
        language: language.join(" "),
        language_raw: language_raw.join(" "),
        regions,
        fixtures,
        objects,
        obj_of_interest,
        init,
        goal,
    })
}

/// `(<name> (:target t) [(:ranges ((x0 y0 x1 y1)...))] [(:yaw_rotation ((lo hi)...))] [(:rgba (r g b a))])`.
fn region(s: &Sexp) -> Result<Region> {
    let (name, attrs, span) = headed(s, "a region `(<name> (:target <entity>) ...)`")?;
    let mut target: Option<String> = None;
    let mut ranges: Option<Vec<[f64; 4]>> = None;
    let mut yaw: Option<Option<[f64; 2]>> = None;
    let mut rgba: Option<[f64; 4]> = None;
    for a in attrs {
        let (key, body, aspan) = headed(
            a,
            "a region attribute `(:target ...)`, `(:ranges ...)`, `(:yaw_rotation ...)` or `(:rgba ...)`",
        )?;
        let dup = match key {
            ":target" => target.is_some(),
            ":ranges" => ranges.is_some(),
            ":yaw_rotation" => yaw.is_some(),
            ":rgba" => rgba.is_some(),
            other => {
                return Err(err(
                    aspan,
                    format!(
                        "unknown region attribute `{other}`; expected `:target`, `:ranges`, `:yaw_rotation` or `:rgba`"
                    ),
                ));
            }
        };
        if dup {
            return Err(err(
                aspan,
                format!("duplicate attribute `{key}` in region `{name}`"),
            ));
        }
        match key {
            ":target" => {
                let [t] = body else {
                    return Err(err(
                        aspan,
                        "expected `(:target <entity>)` with exactly one name",
                    ));
                };
                target = Some(sym(t, "a target name")?.to_string());
            }
            ":ranges" => {
                let [rects] = body else {
                    return Err(err(
                        aspan,
                        "expected `(:ranges ((x_min y_min x_max y_max) ...))`",
                    ));
                };
                let mut out = Vec::new();
                for rect in list(
                    rects,
                    "a list of rectangles `((x_min y_min x_max y_max) ...)`",
                )? {
                    let nums = list(rect, "a rectangle `(x_min y_min x_max y_max)`")?;
                    if nums.len() != 4 {
                        return Err(err(
                            rect.span(),
                            format!(
                                "expected 4 numbers `(x_min y_min x_max y_max)`, found {}",
                                nums.len()
                            ),
                        ));
                    }
                    let mut r = [0.0; 4];
                    for (slot, n) in r.iter_mut().zip(nums) {
                        *slot = number(n)?;
                    }
                    out.push(r);
                }
                ranges = Some(out);
            }
            ":yaw_rotation" => {
                let [pairs] = body else {
                    return Err(err(aspan, "expected `(:yaw_rotation ((lo hi) ...))`"));
                };
                let mut last = None;
                for p in list(pairs, "a list of yaw pairs `((lo hi) ...)`")? {
                    let v = list(p, "a yaw pair `(lo hi)`")?;
                    if v.len() != 2 {
                        return Err(err(
                            p.span(),
                            format!("expected a yaw pair `(lo hi)`, found {} values", v.len()),
                        ));
                    }
                    last = Some([expr_value(&v[0])?, expr_value(&v[1])?]);
                }
                yaw = Some(last);
            }
            _ => {
                let [c] = body else {
                    return Err(err(aspan, "expected `(:rgba (r g b a))`"));
                };
                let nums = list(c, "a colour `(r g b a)`")?;
                if nums.len() != 4 {
                    return Err(err(
                        c.span(),
                        format!("expected 4 numbers `(r g b a)`, found {}", nums.len()),
                    ));
                }
                let mut v = [0.0; 4];
                for (slot, n) in v.iter_mut().zip(nums) {
                    *slot = number(n)?;
                }
                rgba = Some(v);
            }
        }
    }
    let target = target.ok_or_else(|| {
        err(
            span,
            format!("region `{name}` has no `(:target <entity>)`; expected one"),
        )
    })?;
    Ok(Region {
        name: name.to_string(),
        target,
        ranges: ranges.unwrap_or_default(),
        yaw_rotation: yaw.flatten(),
        rgba,
        span,
    })
}

/// A PDDL typed list `a b - cat c - cat2 d`; names without a type get `default`.
fn typed_list(
    items: &[Sexp],
    default: &str,
    names: &mut HashMap<String, Span>,
) -> Result<Vec<Instance>> {
    let mut out = Vec::new();
    let mut pending: Vec<(&str, Span)> = Vec::new();
    let mut i = 0;
    let mut declare =
        |name: &str, span: Span, category: &str, out: &mut Vec<Instance>| -> Result<()> {
            if let Some(first) = names.get(name) {
                return Err(err(
                    span,
                    format!(
                        "duplicate name `{name}` (first declared at line {}, column {})",
                        first.line, first.col
                    ),
                ));
            }
            names.insert(name.to_string(), span);
            out.push(Instance {
                name: name.to_string(),
                category: category.to_string(),
            });
            Ok(())
        };
    while i < items.len() {
        let s = sym(&items[i], "an instance name or `- <category>`")?;
        if s == "-" {
            let dash = items[i].span();
            let cat = items.get(i + 1).ok_or_else(|| {
                err(
                    dash,
                    "expected a category after `-`, found the end of the section",
                )
            })?;
            let cat = sym(cat, "a category after `-`")?;
            if pending.is_empty() {
                return Err(err(
                    dash,
                    format!("expected instance names before `- {cat}`"),
                ));
            }
            for (n, span) in pending.drain(..) {
                declare(n, span, cat, &mut out)?;
            }
            i += 2;
        } else {
            pending.push((s, items[i].span()));
            i += 1;
        }
    }
    for (n, span) in pending {
        declare(n, span, default, &mut out)?;
    }
    Ok(out)
}

/// A name that must be a declared instance or region key.
fn known_name(s: &Sexp, names: &HashMap<String, Span>) -> Result<String> {
    let n = sym(s, "a name")?;
    if names.contains_key(n) {
        Ok(n.to_string())
    } else {
        Err(err(
            s.span(),
            format!("unknown name `{n}`; expected a declared fixture, object or region key"),
        ))
    }
}

/// A ground atom `(pred arg...)` over declared names.
fn atom(s: &Sexp, names: &HashMap<String, Span>) -> Result<Atom> {
    let (pred, args, span) = headed(s, "an atom `(<predicate> <arg>...)`")?;
    let Some(predicate) = Predicate::from_name(pred) else {
        let known: Vec<&str> = Predicate::ALL.iter().map(|p| p.name()).collect();
        return Err(err(
            span,
            format!(
                "unknown predicate `{pred}`; expected one of {}",
                known.join(", ")
            ),
        ));
    };
    let (lo, hi) = predicate.arity();
    if args.len() < lo || args.len() > hi {
        let want = if lo == hi {
            format!("{lo}")
        } else {
            format!("{lo} to {hi}")
        };
        return Err(err(
            span,
            format!(
                "predicate `{pred}` takes {want} argument(s), found {}",
                args.len()
            ),
        ));
    }
    let args = args
        .iter()
        .map(|a| known_name(a, names))
        .collect::<Result<Vec<_>>>()?;
    Ok(Atom {
        predicate,
        args,
        span,
    })
}

/// A goal: `(and g...)`, `(or g...)`, `(sequence g...)` or an atom.
fn goal(s: &Sexp, names: &HashMap<String, Span>) -> Result<Goal> {
    let (head, rest, span) = headed(
        s,
        "a goal `(And ...)`, `(Or ...)`, `(Sequence ...)` or an atom",
    )?;
    let children =
        |rest: &[Sexp]| -> Result<Vec<Goal>> { rest.iter().map(|g| goal(g, names)).collect() };
    match head {
        "and" => Ok(Goal::And(children(rest)?)),
        "or" => Ok(Goal::Or(children(rest)?)),
        "sequence" => Ok(Goal::Sequence(children(rest)?)),
        "not" => Err(err(
            span,
            "`not` is not supported (LIBERO has no negation); expected `And`, `Or`, `Sequence` or an atom",
        )),
        _ => Ok(Goal::Atom(atom(s, names)?)),
    }
}

/// A finite decimal number, as Python's `float()` reads the files' numbers.
fn number(s: &Sexp) -> Result<f64> {
    let t = sym(s, "a number")?;
    match t.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(err(
            s.span(),
            format!("bad number `{t}`: expected a finite decimal number such as `-0.25`"),
        )),
    }
}

/// A yaw value: LIBERO `eval`s it, so accept numbers and simple expressions over `+ - * /` and `pi`
/// (`pi`, `np.pi`, `numpy.pi`, `math.pi`), e.g. `3.141592653589793`, `-np.pi/2`, `pi/4`, `2*np.pi/3`.
fn expr_value(s: &Sexp) -> Result<f64> {
    let t = sym(s, "a yaw value")?;
    match eval_expr(t) {
        Some(v) if v.is_finite() => Ok(v),
        _ => Err(err(
            s.span(),
            format!(
                "bad yaw value `{t}`: expected a number or a simple expression such as `-np.pi/2`"
            ),
        )),
    }
}

/// Evaluates `expr := term (('+'|'-') term)*`, `term := unary (('*'|'/') unary)*`,
/// `unary := ('+'|'-') unary | number | pi-constant`.
pub(crate) fn eval_expr(text: &str) -> Option<f64> {
    struct P<'a> {
        s: &'a [u8],
        i: usize,
    }
    impl P<'_> {
        fn peek(&self) -> Option<u8> {
            self.s.get(self.i).copied()
        }
        fn expr(&mut self) -> Option<f64> {
            let mut v = self.term()?;
            while let Some(op @ (b'+' | b'-')) = self.peek() {
                self.i += 1;
                let r = self.term()?;
                v = if op == b'+' { v + r } else { v - r };
            }
            Some(v)
        }
        fn term(&mut self) -> Option<f64> {
            let mut v = self.unary()?;
            while let Some(op @ (b'*' | b'/')) = self.peek() {
                self.i += 1;
                let r = self.unary()?;
                v = if op == b'*' { v * r } else { v / r };
            }
            Some(v)
        }
        fn unary(&mut self) -> Option<f64> {
            // Signs are read in a loop, not by recursion: `------…1` cannot exhaust the stack.
            let mut sign = 1.0;
            loop {
                match self.peek()? {
                    b'-' => sign = -sign,
                    b'+' => {}
                    _ => return Some(sign * self.atom()?),
                }
                self.i += 1;
            }
        }
        fn atom(&mut self) -> Option<f64> {
            let rest = &self.s[self.i..];
            for name in ["numpy.pi", "math.pi", "np.pi", "pi"] {
                if rest.starts_with(name.as_bytes()) {
                    self.i += name.len();
                    return Some(std::f64::consts::PI);
                }
            }
            let start = self.i;
            while matches!(self.peek(), Some(b'0'..=b'9' | b'.')) {
                self.i += 1;
            }
            if self.i > start && matches!(self.peek(), Some(b'e' | b'E')) {
                let save = self.i;
                self.i += 1;
                if matches!(self.peek(), Some(b'+' | b'-')) {
                    self.i += 1;
                }
                let digits = self.i;
                while matches!(self.peek(), Some(b'0'..=b'9')) {
                    self.i += 1;
                }
                if self.i == digits {
                    self.i = save;
                }
            }
            std::str::from_utf8(&self.s[start..self.i])
                .ok()?
                .parse()
                .ok()
        }
    }
    let mut p = P {
        s: text.as_bytes(),
        i: 0,
    };
    let v = p.expr()?;
    (p.i == text.len()).then_some(v)
}

#[cfg(test)]
mod tests {
    use super::eval_expr;
    use std::f64::consts::PI;

    #[test]
    fn yaw_expressions() {
        assert_eq!(eval_expr("3.141592653589793"), Some(PI));
        assert_eq!(eval_expr("-np.pi/2"), Some(-PI / 2.0));
        assert_eq!(eval_expr("np.pi"), Some(PI));
        assert_eq!(eval_expr("pi/4"), Some(PI / 4.0));
        assert_eq!(eval_expr("2*np.pi/3"), Some(2.0 * PI / 3.0));
        assert_eq!(eval_expr("1e-3"), Some(1e-3));
        assert_eq!(eval_expr("-0.5+1"), Some(0.5));
        assert_eq!(eval_expr("0.0"), Some(0.0));
        assert_eq!(eval_expr("--1"), Some(1.0));
        assert_eq!(eval_expr("-+-+-2"), Some(-2.0));
        // A long chain of signs is a loop, not a recursion.
        assert_eq!(eval_expr(&format!("{}1", "-".repeat(100_001))), Some(-1.0));
        assert_eq!(eval_expr(&"-".repeat(100_000)), None);
        assert_eq!(eval_expr("abc"), None);
        assert_eq!(eval_expr("1/"), None);
        assert_eq!(eval_expr(""), None);
    }
}
