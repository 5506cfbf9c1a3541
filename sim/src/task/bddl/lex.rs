//! Tokens and the s-expression tree, as bddl's `scan_tokens` builds them: comments removed, text
//! lowercased, `(`/`)` or runs of non-space non-paren characters, exactly one top-level expression.

use super::error::{BddlError, Span};

/// A node of the s-expression tree.
#[derive(Clone, Debug)]
pub(crate) enum Sexp {
    /// A parenthesised list; `open` is the position of its `(`.
    List { items: Vec<Sexp>, open: Span },
    /// A symbol: `text` lowercased, `raw` as written.
    Sym {
        text: String,
        raw: String,
        span: Span,
    },
}

impl Sexp {
    pub(crate) fn span(&self) -> Span {
        match self {
            Sexp::List { open, .. } => *open,
            Sexp::Sym { span, .. } => *span,
        }
    }

    /// A short description for "found ..." in error messages.
    pub(crate) fn describe(&self) -> String {
        match self {
            Sexp::List { items, .. } => match items.first() {
                Some(Sexp::Sym { raw, .. }) => format!("a list `({raw} ...)`"),
                Some(_) => "a list `((...) ...)`".to_string(),
                None => "an empty list `()`".to_string(),
            },
            Sexp::Sym { raw, .. } => format!("`{raw}`"),
        }
    }
}

/// The deepest nesting of parentheses accepted. LIBERO's files nest at most 5 levels; the limit
/// keeps the recursive walks over the tree (goals, printing, dropping) far from a stack overflow.
pub const MAX_DEPTH: usize = 64;

/// Reads `text` into its single top-level expression.
pub(crate) fn read_tree(text: &str) -> Result<Sexp, BddlError> {
    let mut stack: Vec<(Vec<Sexp>, Span)> = Vec::new();
    let mut top: Vec<Sexp> = Vec::new();
    let (mut line, mut col) = (1u32, 1u32);
    let mut chars = text.chars().peekable();
    let mut word = String::new();
    let mut word_span = Span::default();

    // Pushes a finished node into the innermost open list (or the top level).
    fn push(stack: &mut [(Vec<Sexp>, Span)], top: &mut Vec<Sexp>, node: Sexp) {
        match stack.last_mut() {
            Some((items, _)) => items.push(node),
            None => top.push(node),
        }
    }
    fn flush(word: &mut String, span: Span, stack: &mut [(Vec<Sexp>, Span)], top: &mut Vec<Sexp>) {
        if !word.is_empty() {
            let raw = std::mem::take(word);
            push(
                stack,
                top,
                Sexp::Sym {
                    text: raw.to_lowercase(),
                    raw,
                    span,
                },
            );
        }
    }

    while let Some(c) = chars.next() {
        let here = Span { line, col };
        match c {
            ';' => {
                flush(&mut word, word_span, &mut stack, &mut top);
                // Comment to the end of the line; the newline itself is handled below.
                while let Some(&n) = chars.peek() {
                    if n == '\n' {
                        break;
                    }
                    chars.next();
                    col += 1;
                }
            }
            '(' => {
                flush(&mut word, word_span, &mut stack, &mut top);
                if stack.len() == MAX_DEPTH {
                    return Err(BddlError::at(
                        here,
                        format!("parentheses nested deeper than {MAX_DEPTH} levels"),
                    ));
                }
                stack.push((Vec::new(), here));
            }
            ')' => {
                flush(&mut word, word_span, &mut stack, &mut top);
                match stack.pop() {
                    Some((items, open)) => push(&mut stack, &mut top, Sexp::List { items, open }),
                    None => {
                        return Err(BddlError::at(
                            here,
                            "unbalanced parentheses: this `)` has no matching `(`",
                        ));
                    }
                }
            }
            c if c.is_whitespace() => flush(&mut word, word_span, &mut stack, &mut top),
            c => {
                if word.is_empty() {
                    word_span = here;
                }
                word.push(c);
            }
        }
        if c == '\n' {
            line += 1;
            col = 1;
        } else {
            col += 1;
        }
    }
    flush(&mut word, word_span, &mut stack, &mut top);
    if let Some((_, open)) = stack.last() {
        return Err(BddlError::at(
            *open,
            "unbalanced parentheses: this `(` is never closed (expected `)` before the end of the file)",
        ));
    }
    let mut top = top.into_iter();
    let first = top.next().ok_or_else(|| {
        BddlError::at(
            Span { line, col },
            "expected `(define (problem ...) ...)`, found the end of the file",
        )
    })?;
    if let Some(second) = top.next() {
        return Err(BddlError::at(
            second.span(),
            format!(
                "expected exactly one top-level expression `(define ...)`, found a second one: {}",
                second.describe()
            ),
        ));
    }
    Ok(first)
}
