//! Errors of the train crate; [`TrainError::exit_code`] maps them to the binary's exit status.

use std::path::PathBuf;

use thiserror::Error;

/// Everything that can stop a training run.
#[derive(Debug, Error)]
pub enum TrainError {
    /// The config file is unreadable or invalid (the message names the key).
    #[error("config {}: {message}", path.display())]
    Config {
        /// The config file.
        path: PathBuf,
        /// What is wrong, naming the key.
        message: String,
    },
    /// Bad command-line arguments or option values.
    #[error("{0}")]
    Usage(String),
    /// The dataset directory is missing and cannot be generated.
    #[error("dataset missing: {} ({hint})", dir.display())]
    DatasetMissing {
        /// The configured dataset directory.
        dir: PathBuf,
        /// How to make it.
        hint: String,
    },
    /// A checkpoint of another model (variant, sizes, vocabulary) or of a broken format.
    #[error("incompatible checkpoint {}: {message}", path.display())]
    IncompatibleCheckpoint {
        /// The checkpoint directory.
        path: PathBuf,
        /// What differs.
        message: String,
    },
    /// Dataset reading failed.
    #[error(transparent)]
    Data(#[from] data::DataError),
    /// Model building or forward failed.
    #[error(transparent)]
    Model(#[from] model::ModelError),
    /// File-system error on a path.
    #[error("{}: {source}", path.display())]
    Io {
        /// The path.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// The backend could not run a step (e.g. a GPU buffer larger than the device allows, out
    /// of memory): the step and the backend's own words.
    #[error("step {step}: the backend failed to compute {what}: {message}")]
    Device {
        /// The optimiser step being computed (1-based).
        step: u64,
        /// What was being read back (`the loss`, `the gradient norm`).
        what: &'static str,
        /// The backend's error.
        message: String,
    },
    /// A non-finite loss (diverged training).
    #[error("loss is not finite at step {0}")]
    NonFinite(u64),
    /// Anything else (record files, plots).
    #[error("{0}")]
    Other(String),
}

impl TrainError {
    /// `Io` error with its path.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        TrainError::Io {
            path: path.into(),
            source,
        }
    }

    /// Exit status of the binary ([`data::exit`]): 2 for bad input, 1 otherwise.
    pub fn exit_code(&self) -> i32 {
        data::exit::status(data::exit::BadInput::is_bad_input(self)) as i32
    }
}

impl data::exit::BadInput for TrainError {
    /// Config, arguments, a missing dataset, an unavailable backend, an incompatible checkpoint,
    /// a bad run directory, malformed data.
    fn is_bad_input(&self) -> bool {
        match self {
            TrainError::Config { .. }
            | TrainError::Usage(_)
            | TrainError::DatasetMissing { .. }
            | TrainError::IncompatibleCheckpoint { .. }
            | TrainError::Model(
                model::ModelError::BackendUnavailable { .. }
                | model::ModelError::Run { .. }
                | model::ModelError::Config(_),
            ) => true,
            TrainError::Data(d) => d.is_bad_input(),
            _ => false,
        }
    }
}

/// Result alias of this crate.
pub type Result<T> = std::result::Result<T, TrainError>;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_backend_failure_names_the_step_and_is_not_bad_input() {
        let e = TrainError::Device {
            step: 7,
            what: "the gradient norm",
            message: "can't allocate buffer of size: 2147483648".into(),
        };
        assert_eq!(
            e.to_string(),
            "step 7: the backend failed to compute the gradient norm: can't allocate buffer of \
             size: 2147483648"
        );
        assert_eq!(e.exit_code(), 1);
    }
}
