//! The world: MuJoCo 2.2.2 through FFI, offscreen rendering, a Franka Panda with LIBERO's OSC_POSE
//! controller, and a minimal environment.
//!
//! Layers, bottom up: [`mujoco`] (the only `unsafe`, raw FFI + safe `Model`/`Data`), [`render`]
//! (EGL surfaceless offscreen rendering: RGB, depth, segmentation), [`robot`] (the Panda MJCF and its
//! constants), [`controller`] (OSC_POSE and the gripper ramp), [`env`] (reset/step/observe).

pub mod controller;
pub mod env;
pub mod expert;
pub mod mujoco;
pub mod render;
pub mod robot;
pub mod task;

pub use env::{Env, EnvConfig, EnvError, GoalStatus, Observation};
pub mod aliasing;
pub mod assets;
pub mod bench;
pub mod generate;
pub mod pack;
pub mod predicates;
pub mod record;
pub mod scene;
pub mod sheet;
