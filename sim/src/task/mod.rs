//! Tasks without physics: the BDDL parser ([`bddl`]), the shipped task files and their registry
//! ([`registry`]), and the LIBERO-Mem goal tracker ([`goal`]).
//!
//! Nothing here touches MuJoCo or rendering: predicates reach the tracker through a caller-supplied
//! oracle (`&mut dyn FnMut(&Atom) -> bool`), so the whole module is testable with predicate traces.

pub mod bddl;
pub mod goal;
pub mod registry;

pub use bddl::{
    Atom, BddlError, Goal, Instance, Problem, ProblemClass, Region, Span, parse, parse_named, print,
};
pub use goal::{Debounce, GoalError, GoalTracker, Progress};
pub use registry::{Suite, TaskError, TaskSpec, list, resolve, resolve_with_repeats};
