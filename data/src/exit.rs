//! The exit-code contract of every binary of the workspace (`sim`, `data`, `train`, `eval`):
//! 0 on success, 2 for bad input (arguments, configs, tasks, files that are missing or
//! malformed: the message names the file and the place), 1 for anything else. The error is
//! printed once on stderr as `error: <context>: <cause>`.

use std::process::ExitCode;

/// Exit status of bad input.
pub const BAD_INPUT: u8 = 2;
/// Exit status of every other failure.
pub const FAILURE: u8 = 1;

/// An error that knows whether the user's input caused it.
pub trait BadInput {
    /// True when the input (arguments, config, files) is at fault, not the machine.
    fn is_bad_input(&self) -> bool;
}

impl crate::DataError {
    /// Process exit code for this error: 2 for bad input, 1 otherwise.
    pub fn exit_code(&self) -> i32 {
        status(self.is_bad_input()) as i32
    }
}

impl BadInput for crate::DataError {
    fn is_bad_input(&self) -> bool {
        crate::DataError::is_bad_input(self)
    }
}

/// The exit status of an error that is (or is not) bad input.
pub fn status(bad_input: bool) -> u8 {
    if bad_input { BAD_INPUT } else { FAILURE }
}

/// Whether any error in `err`'s chain is bad input, asking the binary's own error type `E` and
/// [`crate::DataError`].
pub fn is_bad_input<E: BadInput + std::error::Error + 'static>(err: &anyhow::Error) -> bool {
    err.chain().any(|cause| {
        cause
            .downcast_ref::<E>()
            .map(BadInput::is_bad_input)
            .or_else(|| {
                cause
                    .downcast_ref::<crate::DataError>()
                    .map(BadInput::is_bad_input)
            })
            .unwrap_or(false)
    })
}

/// Prints `err` once and returns the process exit code of the contract.
pub fn report<E: BadInput + std::error::Error + 'static>(err: &anyhow::Error) -> ExitCode {
    eprintln!("error: {err:#}");
    ExitCode::from(status(is_bad_input::<E>(err)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::DataError;

    #[test]
    fn bad_input_anywhere_in_the_chain_is_exit_2() {
        let missing = DataError::invalid("ep.mcap", "truncated");
        let e = anyhow::Error::new(missing).context("reading the dataset");
        assert!(is_bad_input::<DataError>(&e));
        let io = DataError::Io {
            path: "out".into(),
            source: std::io::Error::other("disk full"),
        };
        assert!(!is_bad_input::<DataError>(&anyhow::Error::new(io)));
        assert!(!is_bad_input::<DataError>(&anyhow::anyhow!("plain")));
        assert_eq!((status(true), status(false)), (2, 1));
    }
}
