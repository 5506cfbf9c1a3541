//! Errors of evaluation and their exit status ([`data::exit`]).

use std::path::PathBuf;

/// Errors from evaluation.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// The simulator failed.
    #[error(transparent)]
    Env(#[from] sim::EnvError),
    /// A task id could not be resolved.
    #[error(transparent)]
    Task(#[from] sim::task::TaskError),
    /// Bad arguments.
    #[error("{0}")]
    Argument(String),
    /// A run directory that cannot be evaluated (missing, no checkpoint, mismatched model).
    #[error("{}: {message}", path.display())]
    Run {
        /// The offending file or directory.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The model failed on an input.
    #[error("model: {0}")]
    Model(String),
    /// A results file that cannot be read.
    #[error("{}: {message}", path.display())]
    Results {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// An input file (e.g. an experiment file) that is not valid.
    #[error("{}: {message}", path.display())]
    Input {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// Writing an output file failed.
    #[error(transparent)]
    Data(#[from] data::DataError),
    /// A remote policy failed: connection, timeout, or a malformed reply (names the server, the
    /// episode and the step).
    #[error("{0}")]
    Remote(String),
    /// Writing a rollout recording or a visualisation failed.
    #[error("{}: {message}", path.display())]
    Output {
        /// The file.
        path: PathBuf,
        /// What failed.
        message: String,
    },
}

impl EvalError {
    /// Process exit status for this error ([`data::exit`]): 2 for bad input, 1 otherwise.
    pub fn exit_code(&self) -> u8 {
        data::exit::status(data::exit::BadInput::is_bad_input(self))
    }
}

impl data::exit::BadInput for EvalError {
    /// Arguments, tasks, run directories, results files, malformed data, and a remote policy
    /// that cannot be reached or answers out of protocol (the `--policy ws://` given).
    fn is_bad_input(&self) -> bool {
        match self {
            EvalError::Task(_)
            | EvalError::Argument(_)
            | EvalError::Run { .. }
            | EvalError::Results { .. }
            | EvalError::Input { .. }
            | EvalError::Remote(_) => true,
            EvalError::Data(d) => d.is_bad_input(),
            EvalError::Env(e) => e.is_bad_input(),
            _ => false,
        }
    }
}
