//! Where and why BDDL text did not parse: [`BddlError`] with its [`Span`].

use std::fmt;
use std::hash::{Hash, Hasher};

/// A syntax or structure error, with the 1-based line and column (in characters) where it was found.
///
/// `Display` gives `file:line:col: message`, and the message says what was expected.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BddlError {
    /// The file name given to [`parse_named`](super::parse_named) (`<input>` for [`parse`](super::parse())).
    pub file: String,
    /// 1-based line.
    pub line: u32,
    /// 1-based column, counted in characters.
    pub col: u32,
    /// What went wrong and what was expected.
    pub message: String,
}

impl BddlError {
    pub(crate) fn at(span: Span, message: impl Into<String>) -> BddlError {
        BddlError {
            file: String::new(),
            line: span.line,
            col: span.col,
            message: message.into(),
        }
    }

    pub(super) fn in_file(mut self, file: &str) -> BddlError {
        self.file = file.to_string();
        self
    }
}

impl fmt::Display for BddlError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}:{}:{}: {}",
            self.file, self.line, self.col, self.message
        )
    }
}

impl std::error::Error for BddlError {}

/// A position in the source text (1-based line and column, in characters).
///
/// Spans never take part in equality or hashing: two ASTs are equal when they say the same thing, wherever
/// it was written (this is what makes `parse(print(p)) == p` hold).
#[derive(Clone, Copy, Debug, Default)]
pub struct Span {
    /// 1-based line.
    pub line: u32,
    /// 1-based column, in characters.
    pub col: u32,
}

impl PartialEq for Span {
    fn eq(&self, _other: &Span) -> bool {
        true
    }
}

impl Eq for Span {}

impl Hash for Span {
    fn hash<H: Hasher>(&self, _state: &mut H) {}
}
