//! Errors of the model crate.

use thiserror::Error;

/// Everything that can go wrong when building, loading or feeding a model.
#[derive(Debug, Error)]
pub enum ModelError {
    /// The configuration is inconsistent (the message says which field and why).
    #[error("invalid model config: {0}")]
    Config(String),
    /// An input has the wrong shape or size.
    #[error("bad input: {0}")]
    Input(String),
    /// A variant name that we do not know.
    #[error("unknown model variant `{0}` (expected e_slotssm, slotvla_h<N>, dense or dense_h<N>)")]
    UnknownVariant(String),
    /// Saving or loading a record failed.
    #[error("record: {0}")]
    Record(String),
}

/// Result alias of this crate.
pub type Result<T> = std::result::Result<T, ModelError>;
