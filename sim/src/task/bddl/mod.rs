//! BDDL problem files as LIBERO reads them (libero.md §1), plus LIBERO-Mem's nested goals.
//!
//! [`parse`] turns the text into a typed [`Problem`]; [`print()`] turns a `Problem` back into BDDL text such
//! that `parse(print(p)) == p`.
//!
//! What LIBERO does and we do too:
//! * `;` starts a comment that runs to the end of the line;
//! * the whole text is lowercased before it is read (names, predicates, `:language`); the original-case
//!   `:language` is kept as well, in [`Problem::language_raw`];
//! * a token is `(`, `)` or a run of characters that are neither whitespace nor parentheses, and there is
//!   exactly one top-level expression, `(define (problem <Class>) <section>...)`;
//! * sections come in any order; `:requirements` and `:scene_properties` are accepted and ignored;
//! * a region's key is `<target>_<name>`; `:yaw_rotation` is a list of pairs whose last pair wins, and its
//!   values may be Python expressions such as `-np.pi/2`;
//! * typed lists `a b - cat c - cat2`, where names without a type get the category `fixture` (in
//!   `:fixtures`) or `object` (in `:objects`).
//!
//! Where we are stricter than LIBERO (LIBERO warns, ignores or crashes later): an unknown section, a
//! duplicated section, region attribute, region key or instance name, a region without `:target`, an
//! unknown problem class, a domain other than `robosuite`, a predicate outside LIBERO's registry or with
//! the wrong number of arguments, and an atom argument (in `:init` or `:goal`) that names neither a
//! declared instance nor a declared region key are all errors (`:obj_of_interest`, used only for
//! visualisation, is not checked). LIBERO lets a later `a - cat` line
//! replace an earlier line of the same category; we keep every instance, in file order.
//!
//! Goals: LIBERO's `(And atom...)` or a single atom, and LIBERO-Mem's `(Sequence g...)`, `(Or g...)` and
//! `(And g...)` nested freely (the [goal tracker](crate::task::goal) decides which shapes it can run).

mod ast;
mod category;
mod error;
mod lex;
mod parse;
mod predicate;
mod print;

pub use ast::{Atom, Goal, Instance, Problem, ProblemClass, Region};
pub use category::{Category, WORKSPACE_CATEGORIES, short_words};
pub use error::{BddlError, Span};
pub use lex::MAX_DEPTH;
pub use predicate::{PREDICATES, Predicate};
pub use print::print;

/// Parses BDDL text. Errors name the file as `<input>`; use [`parse_named`] to give it a name.
pub fn parse(text: &str) -> Result<Problem, BddlError> {
    parse_named("<input>", text)
}

/// Parses BDDL text read from `file` (the name is only used in error messages).
pub fn parse_named(file: &str, text: &str) -> Result<Problem, BddlError> {
    let root = lex::read_tree(text).map_err(|e| e.in_file(file))?;
    parse::problem(&root).map_err(|e| e.in_file(file))
}

/// What a scene needs beyond the syntax, checked before a task file is used: a `(:fixtures ...)`
/// section (the workspace lives there in every LIBERO file) and placement rectangles with
/// `x_min ≤ x_max` and `y_min ≤ y_max` (an inverted one has no point to sample). Errors name the
/// file and the region's line.
pub fn check_scene(file: &str, p: &Problem) -> Result<(), BddlError> {
    if p.fixtures.is_empty() {
        return Err(BddlError::at(
            Span { line: 1, col: 1 },
            "no `(:fixtures ...)` section: a scene needs its workspace fixture (for example \
             `(:fixtures main_table - table)`)",
        )
        .in_file(file));
    }
    for r in &p.regions {
        for &[x0, y0, x1, y1] in &r.ranges {
            if x0 > x1 || y0 > y1 {
                return Err(BddlError::at(
                    r.span,
                    format!(
                        "region `{}`: inverted rectangle ({x0} {y0} {x1} {y1}); expected \
                         (x_min y_min x_max y_max) with x_min ≤ x_max and y_min ≤ y_max",
                        r.name
                    ),
                )
                .in_file(file));
            }
        }
    }
    Ok(())
}
