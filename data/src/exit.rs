//! The exit-code contract of every binary of the workspace (`sim`, `data`, `train`, `eval`):
//! 0 on success, 2 for bad input (arguments, configs, tasks, files that are missing or
//! malformed: the message names the file and the place), 1 for anything else. The error is
//! printed once on stderr as `error: <context>: <cause>`.

use std::io::Write;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};

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

/// The one-line message of `err`: its chain of causes joined by `: `, each cause left out when the
/// text before it already ends with it (error types that print their source themselves would
/// otherwise say "No such file or directory (os error 2)" twice).
pub fn message(err: &anyhow::Error) -> String {
    let mut msg = String::new();
    for cause in err.chain() {
        let text = cause.to_string();
        if msg.is_empty() {
            msg = text;
        } else if !msg.ends_with(&text) {
            msg.push_str(": ");
            msg.push_str(&text);
        }
    }
    msg
}

/// Prints `err` once and returns the process exit code of the contract.
pub fn report<E: BadInput + std::error::Error + 'static>(err: &anyhow::Error) -> ExitCode {
    eprintln!("error: {}", message(err));
    ExitCode::from(status(is_bad_input::<E>(err)))
}

/// Set once stdout's reader has gone away (`… | head`): later output is dropped.
static STDOUT_CLOSED: AtomicBool = AtomicBool::new(false);

/// Writes to stdout and flushes, as `print!` does, except that a closed pipe is not an error: the
/// output is dropped from then on and the program goes on (and writes its files) to a normal exit.
/// Other write errors are reported once on stderr. Used through [`out!`](crate::out) and
/// [`outln!`](crate::outln).
pub fn write_stdout(args: std::fmt::Arguments) {
    if STDOUT_CLOSED.load(Ordering::Relaxed) {
        return;
    }
    let mut out = std::io::stdout().lock();
    if let Err(e) = out.write_fmt(args).and_then(|()| out.flush()) {
        STDOUT_CLOSED.store(true, Ordering::Relaxed);
        if e.kind() != std::io::ErrorKind::BrokenPipe {
            eprintln!("error: writing to stdout: {e} (further output dropped)");
        }
    }
}

/// `print!` that ends quietly on a closed pipe ([`write_stdout`]).
#[macro_export]
macro_rules! out {
    ($($arg:tt)*) => { $crate::exit::write_stdout(format_args!($($arg)*)) };
}

/// `println!` that ends quietly on a closed pipe ([`write_stdout`]).
#[macro_export]
macro_rules! outln {
    () => { $crate::exit::write_stdout(format_args!("\n")) };
    ($($arg:tt)*) => { $crate::exit::write_stdout(format_args!("{}\n", format_args!($($arg)*))) };
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

    #[test]
    fn message_says_each_cause_once() {
        let io = DataError::Io {
            path: "runs/x/state.json".into(),
            source: std::io::Error::from(std::io::ErrorKind::NotFound),
        };
        let e = anyhow::Error::new(io).context("loading the checkpoint");
        assert_eq!(
            message(&e),
            "loading the checkpoint: runs/x/state.json: entity not found"
        );
        let plain = anyhow::anyhow!("disk full").context("writing out.json");
        assert_eq!(message(&plain), "writing out.json: disk full");
    }
}
