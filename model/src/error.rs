//! Errors of the model crate.

use std::path::PathBuf;

use thiserror::Error;

/// Everything that can go wrong when building, loading or feeding a model, or reading a run.
#[derive(Debug, Error)]
pub enum ModelError {
    /// The configuration is inconsistent (the message says which field and why).
    #[error("invalid model config: {0}")]
    Config(String),
    /// An input has the wrong shape or size.
    #[error("bad input: {0}")]
    Input(String),
    /// A variant name that we do not know.
    #[error(
        "unknown model variant `{0}` (expected e_slotssm, e_slotssm_oracle, slotvla_h<N>, dense or dense_h<N>)"
    )]
    UnknownVariant(String),
    /// Saving or loading a record failed.
    #[error("record: {0}")]
    Record(String),
    /// A backend that this build does not include.
    #[error(
        "backend `{name}` is not compiled in: rebuild with `--features train/{feature}` (training) or `--features eval/{feature}` (evaluation)"
    )]
    BackendUnavailable {
        /// The backend asked for.
        name: String,
        /// The cargo feature that provides it.
        feature: String,
    },
    /// A run directory (or one of its files) is missing, unreadable or inconsistent.
    #[error("{}: {message}", path.display())]
    Run {
        /// The file or directory.
        path: PathBuf,
        /// What is wrong with it.
        message: String,
    },
}

impl ModelError {
    /// A [`ModelError::Run`] about `path`.
    pub fn run(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        ModelError::Run {
            path: path.into(),
            message: message.into(),
        }
    }
}

/// Result alias of this crate.
pub type Result<T> = std::result::Result<T, ModelError>;
