//! `Problem` → BDDL text in LIBERO's layout, such that `parse(print(p)) == p`.
//!
//! Numbers are written with Rust's shortest round-trip formatting (`{:?}`: `0.0`, `-0.25`, `1e-7`), which
//! Python's `float()` also reads, so they read back bit for bit.
//! The printer expects names as the parser produces them (lowercase, no whitespace or parentheses).

use std::fmt::Write;

use super::ast::{Goal, Instance, Problem};

/// Writes `p` as BDDL text.
pub fn print(p: &Problem) -> String {
    let mut s = String::new();
    // `write!` into a String cannot fail.
    let _ = writeln!(s, "(define (problem {})", p.problem_class.name());
    let _ = writeln!(s, "  (:domain {})", p.domain);
    let language = if p.language_raw.to_lowercase() == p.language {
        &p.language_raw
    } else {
        &p.language
    };
    if language.is_empty() {
        s.push_str("  (:language)\n");
    } else {
        let _ = writeln!(s, "  (:language {language})");
    }

    s.push_str("  (:regions\n");
    for r in &p.regions {
        let _ = writeln!(s, "    ({}", r.name);
        let _ = writeln!(s, "      (:target {})", r.target);
        if !r.ranges.is_empty() {
            s.push_str("      (:ranges (\n");
            for [a, b, c, d] in &r.ranges {
                let _ = writeln!(s, "          ({a:?} {b:?} {c:?} {d:?})");
            }
            s.push_str("        )\n      )\n");
        }
        if let Some([lo, hi]) = r.yaw_rotation {
            let _ = writeln!(
                s,
                "      (:yaw_rotation (\n          ({lo:?} {hi:?})\n        )\n      )"
            );
        }
        if let Some([cr, cg, cb, ca]) = r.rgba {
            let _ = writeln!(s, "      (:rgba ({cr:?} {cg:?} {cb:?} {ca:?}))");
        }
        s.push_str("    )\n");
    }
    s.push_str("  )\n\n");

    typed_list(&mut s, ":fixtures", &p.fixtures);
    typed_list(&mut s, ":objects", &p.objects);

    s.push_str("  (:obj_of_interest\n");
    for n in &p.obj_of_interest {
        let _ = writeln!(s, "    {n}");
    }
    s.push_str("  )\n\n");

    s.push_str("  (:init\n");
    for a in &p.init {
        let _ = writeln!(s, "    {a}");
    }
    s.push_str("  )\n\n");

    s.push_str("  (:goal\n");
    goal(&mut s, &p.goal, 4);
    s.push_str("  )\n\n)\n");
    s
}

/// `a b - cat` lines, grouping consecutive instances of one category.
fn typed_list(s: &mut String, section: &str, items: &[Instance]) {
    let _ = writeln!(s, "  ({section}");
    let mut i = 0;
    while i < items.len() {
        let cat = &items[i].category;
        let mut j = i;
        s.push_str("    ");
        while j < items.len() && items[j].category == *cat {
            let _ = write!(s, "{} ", items[j].name);
            j += 1;
        }
        let _ = writeln!(s, "- {cat}");
        i = j;
    }
    s.push_str("  )\n\n");
}

/// A goal, one atom-only `And` per line, nested operators indented.
fn goal(s: &mut String, g: &Goal, indent: usize) {
    let pad = " ".repeat(indent);
    match g {
        Goal::Atom(a) => {
            let _ = writeln!(s, "{pad}{a}");
        }
        Goal::And(v) if v.iter().all(|g| matches!(g, Goal::Atom(_))) => {
            let _ = write!(s, "{pad}(And");
            for g in v {
                if let Goal::Atom(a) = g {
                    let _ = write!(s, " {a}");
                }
            }
            s.push_str(")\n");
        }
        Goal::And(v) | Goal::Or(v) | Goal::Sequence(v) => {
            let op = match g {
                Goal::And(_) => "And",
                Goal::Or(_) => "Or",
                _ => "Sequence",
            };
            let _ = writeln!(s, "{pad}({op}");
            for c in v {
                goal(s, c, indent + 2);
            }
            let _ = writeln!(s, "{pad})");
        }
    }
}
