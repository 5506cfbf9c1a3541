//! What can go wrong reading LIBERO's XMLs and meshes.

use std::path::PathBuf;

/// Errors composing an object.
#[derive(Debug, thiserror::Error)]
pub enum ComposeError {
    /// No asset of that category in the pack.
    #[error("the LIBERO pack has no asset for category `{0}`")]
    Unknown(String),
    /// The XML cannot be read or lacks what LIBERO expects.
    #[error("{}: {message}", path.display())]
    Xml {
        /// The asset file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}
