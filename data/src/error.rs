//! Error type of the `data` crate: every error names the file and, where known, the byte offset.

use std::path::{Path, PathBuf};

/// Result alias used throughout the crate.
pub type Result<T, E = DataError> = std::result::Result<T, E>;

/// Errors of the `data` crate.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    /// An operating-system I/O error on a file.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// The file's bytes are damaged or truncated at `offset`.
    #[error("{}: corrupt at byte offset {offset}: {msg}", path.display())]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// Byte offset of the damaged record (or where the file ends early).
        offset: u64,
        /// What is wrong.
        msg: String,
    },
    /// The file is well-formed but does not follow our schema.
    #[error("{}: wrong schema at byte offset {offset}: {msg}", path.display())]
    Schema {
        /// The file.
        path: PathBuf,
        /// Byte offset of the offending record or section.
        offset: u64,
        /// What is wrong.
        msg: String,
    },
    /// Input that is invalid for a reason that has no byte offset (missing files, bad values).
    #[error("{}: {msg}", path.display())]
    Invalid {
        /// The file or directory.
        path: PathBuf,
        /// What is wrong.
        msg: String,
    },
    /// A caller passed arguments that cannot work (not a file problem).
    #[error("invalid argument: {0}")]
    Argument(String),
}

impl DataError {
    /// Builds an [`DataError::Io`] error.
    pub fn io(path: impl AsRef<Path>, source: std::io::Error) -> Self {
        DataError::Io {
            path: path.as_ref().to_path_buf(),
            source,
        }
    }

    /// Builds a [`DataError::Corrupt`] error.
    pub fn corrupt(path: impl AsRef<Path>, offset: u64, msg: impl Into<String>) -> Self {
        DataError::Corrupt {
            path: path.as_ref().to_path_buf(),
            offset,
            msg: msg.into(),
        }
    }

    /// Builds a [`DataError::Schema`] error.
    pub fn schema(path: impl AsRef<Path>, offset: u64, msg: impl Into<String>) -> Self {
        DataError::Schema {
            path: path.as_ref().to_path_buf(),
            offset,
            msg: msg.into(),
        }
    }

    /// Builds a [`DataError::Invalid`] error.
    pub fn invalid(path: impl AsRef<Path>, msg: impl Into<String>) -> Self {
        DataError::Invalid {
            path: path.as_ref().to_path_buf(),
            msg: msg.into(),
        }
    }

    /// True when the error is caused by bad input (exit code 2) rather than the environment.
    pub fn is_bad_input(&self) -> bool {
        match self {
            DataError::Io { source, .. } => matches!(
                source.kind(),
                std::io::ErrorKind::NotFound
                    | std::io::ErrorKind::InvalidData
                    | std::io::ErrorKind::UnexpectedEof
            ),
            _ => true,
        }
    }
}
