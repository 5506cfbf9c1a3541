//! The world: MuJoCo 2.2.2 through FFI, offscreen rendering, a Franka Panda with LIBERO's OSC_POSE
//! controller, LIBERO's tasks and assets, a scripted expert and dataset collection.
//!
//! Layers, bottom up (a layer uses only those below it):
//! - [`engine`]: [`engine::mujoco`] (the only `unsafe`: raw FFI + safe `Model`/`Data`) and
//!   [`engine::render`] (EGL surfaceless offscreen rendering: RGB, depth, segmentation).
//! - [`task`]: pure task logic: the BDDL parser, the registry of shipped tasks, the goal tracker;
//!   no MuJoCo.
//! - [`cache`]: where the LIBERO pack lies on disk (paths only), read by `task` and `pack`.
//! - [`world`]: robot, controller, built-in assets, scenes, predicates and the environment.
//! - [`pack`]: LIBERO's asset pack: install, init-state (pickle) reader, composition of its XMLs
//!   into scenes.
//! - [`expert`]: the scripted demonstrator, one file per skill.
//! - [`collect`]: episode recording, dataset generation, aliasing measurement.
//! - [`tools`]: benchmark figures and contact sheets for the command line.
//!
//! The old flat paths (`sim::env`, `sim::render`, `sim::scene`, `sim::generate`, …) stay as
//! re-exports of the modules' new homes. `tests/layers.rs` checks that no file-level import cycle
//! exists and that `task` stays pure; every public item is documented (`missing_docs` warns).

#![warn(missing_docs)]

pub mod cache;
pub mod collect;
pub mod engine;
pub mod expert;
pub mod pack;
pub mod task;
pub mod tools;
pub mod world;

pub use collect::{aliasing, generate, labels, record};
pub use engine::{mujoco, render};
pub use tools::{bench, sheet};
pub use world::env::{Env, EnvConfig, EnvError, GoalStatus, ObjectState, Observation, PartPose};
pub use world::{assets, controller, env, predicates, robot, scene};
