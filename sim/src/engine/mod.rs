//! The engine layer: MuJoCo 2.2.2 through FFI ([`mujoco`], the only `unsafe`) and offscreen EGL
//! rendering ([`render`]). Knows nothing of robots, tasks or assets.

pub mod mujoco;
pub mod render;
