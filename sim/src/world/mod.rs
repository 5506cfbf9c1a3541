//! The world layer: what stands on the engine. The Panda ([`robot`]) and its OSC_POSE controller
//! ([`controller`]), the built-in asset library ([`assets`]), BDDL → MJCF scenes with seeded placement
//! ([`scene`]), LIBERO's predicates on the simulator state ([`predicates`]) and the environment
//! ([`env`](mod@env): reset, step, observe).

pub mod assets;
pub mod controller;
pub mod env;
pub mod predicates;
pub mod robot;
pub mod scene;
