//! Tokens of the pbrt-v4 scene format, each with the file and line it came from.

use super::{Loc, SceneError};
use std::path::Path;
use std::sync::Arc;

/// One token.
#[derive(Debug, Clone, PartialEq)]
pub enum Tok {
    /// A bare word: a directive name, or `true`/`false`.
    Word(String),
    /// A quoted string.
    Str(String),
    /// A number.
    Num(f64),
    /// `[`.
    Open,
    /// `]`.
    Close,
}

/// A token and where it is.
#[derive(Debug, Clone)]
pub struct Token {
    /// The token.
    pub tok: Tok,
    /// Its location.
    pub loc: Loc,
}

/// Splits `src` (the contents of `file`) into tokens.
pub fn tokenize(src: &str, file: &Path) -> Result<Vec<Token>, SceneError> {
    let file: Arc<Path> = Arc::from(file);
    let mut tokens = Vec::new();
    let mut chars = src.char_indices().peekable();
    let mut line = 1u32;
    while let Some(&(start, c)) = chars.peek() {
        let loc = Loc { file: file.clone(), line };
        match c {
            '\n' => {
                line += 1;
                chars.next();
            }
            c if c.is_whitespace() => {
                chars.next();
            }
            '#' => {
                while chars.peek().is_some_and(|(_, c)| *c != '\n') {
                    chars.next();
                }
            }
            '[' | ']' => {
                chars.next();
                tokens.push(Token { tok: if c == '[' { Tok::Open } else { Tok::Close }, loc });
            }
            '"' => {
                chars.next();
                let mut s = String::new();
                loop {
                    match chars.next() {
                        None => return Err(SceneError::at(&loc, "unterminated string")),
                        Some((_, '\n')) => return Err(SceneError::at(&loc, "newline inside a string")),
                        Some((_, '"')) => break,
                        Some((_, '\\')) => match chars.next() {
                            Some((_, 'n')) => s.push('\n'),
                            Some((_, 't')) => s.push('\t'),
                            Some((_, c)) => s.push(c),
                            None => return Err(SceneError::at(&loc, "unterminated string")),
                        },
                        Some((_, c)) => s.push(c),
                    }
                }
                tokens.push(Token { tok: Tok::Str(s), loc });
            }
            c if c.is_ascii_digit() || c == '-' || c == '+' || c == '.' => {
                let mut end = start;
                while let Some(&(i, c)) = chars.peek() {
                    if c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | '+') {
                        end = i + c.len_utf8();
                        chars.next();
                    } else {
                        break;
                    }
                }
                let text = &src[start..end];
                let value: f64 = text.parse().map_err(|_| SceneError::at(&loc, format!("{text:?} is not a number")))?;
                tokens.push(Token { tok: Tok::Num(value), loc });
            }
            c if c.is_ascii_alphabetic() => {
                let mut end = start;
                while let Some(&(i, c)) = chars.peek() {
                    if c.is_ascii_alphanumeric() || c == '_' {
                        end = i + c.len_utf8();
                        chars.next();
                    } else {
                        break;
                    }
                }
                tokens.push(Token { tok: Tok::Word(src[start..end].to_string()), loc });
            }
            other => return Err(SceneError::at(&loc, format!("unexpected character {other:?}"))),
        }
    }
    Ok(tokens)
}
