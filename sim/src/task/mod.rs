//! Tasks without physics: the BDDL parser ([`bddl`]), the shipped task files and their registry
//! ([`registry`]), and the LIBERO-Mem goal tracker ([`goal`]).
//!
//! Nothing here touches MuJoCo or rendering: predicates reach the tracker through a caller-supplied
//! oracle (`&mut dyn FnMut(&Atom) -> bool`), so the whole module is testable with predicate traces.
//! The LIBERO pack's BDDL files are found through [`crate::cache`] (paths only); `tests/layers.rs`
//! checks that no file here reaches `engine`, `world` or `pack`. The domain words are closed enums:
//! [`Predicate`] (LIBERO's registry) and [`Category`] (the categories whose facts the crate knows).
//!
//! ```
//! use sim::task::{bddl::Atom, registry};
//!
//! let spec = registry::resolve("t3").unwrap(); // or "libero_mem/t3", "t3@12", a path to a .bddl
//! assert_eq!((spec.goal_len, spec.max_steps), (3, 320));
//! let mut tracker = spec.tracker();
//! let bowl_on_plate = Atom::new("on", &["akita_black_bowl_1", "plate_1"]);
//! // Once on the first state after settling, then after every env.step:
//! let progress = tracker.step(&mut |a: &Atom| *a == bowl_on_plate);
//! assert!(!progress.done);
//! assert_eq!(tracker.pending_text().as_deref(), Some("bowl 1 on plate 1"));
//! ```

pub mod bddl;
pub mod goal;
pub mod registry;

pub use bddl::{
    Atom, BddlError, Category, Goal, Instance, Predicate, Problem, ProblemClass, Region, Span,
    parse, parse_named, print,
};
pub use goal::{Debounce, GoalError, GoalTracker, Progress};
pub use registry::{Suite, TaskError, TaskSpec, list, resolve, resolve_with_repeats};
