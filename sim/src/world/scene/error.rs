//! What can go wrong while composing or placing a scene.

use crate::engine::mujoco::MjError;

/// Errors while composing or placing a scene.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The task names a category the asset library lacks.
    #[error(
        "unknown object category '{category}' for '{instance}' (the asset library has: {known})"
    )]
    UnknownCategory {
        /// Instance name.
        instance: String,
        /// Category name.
        category: String,
        /// Known categories.
        known: String,
    },
    /// The problem class is not one we build.
    #[error(
        "unsupported problem class '{0}' (supported: libero_tabletop_manipulation, libero_kitchen_tabletop_manipulation, libero_living_room_tabletop_manipulation, libero_study_tabletop_manipulation, libero_floor_manipulation, libero_coffee_table_manipulation)"
    )]
    ProblemClass(String),
    /// An `:init` atom this composer cannot realise.
    #[error("cannot realise init atom ({0})")]
    Init(String),
    /// Placement failed after many tries.
    #[error("could not place '{0}' without collisions after {1} tries")]
    Placement(String, usize),
    /// MuJoCo failed.
    #[error(transparent)]
    Mujoco(#[from] MjError),
}
