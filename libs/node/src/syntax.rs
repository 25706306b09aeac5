//! The lexical grammar Player's `.cfg` files and Stage's world files share
//! (Player's config reader began as Stage's): `#` comments to the end of the
//! line, `\r\n`/`\n\r` counted as one line end, words that start with a
//! letter and may hold `.-_[]` (and more, per language), numbers as runs of
//! `+-.0-9`, `"strings"` on one line, `(` `)` sections and `[` `]` tuples.
//! Line ends are tokens: both languages put a value on its name's line.

use std::fmt;
use std::path::Path;
use std::sync::Arc;

/// A place in a source file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Pos {
    /// The file (shared by every place in it: a world of a thousand
    /// models holds a place for each of their properties).
    pub file: Arc<Path>,
    /// 1-based line.
    pub line: u32,
    /// 1-based column.
    pub col: u32,
}

impl Pos {
    /// The start of `file`.
    pub fn start(file: &Path) -> Pos {
        Pos {
            file: Arc::from(file),
            line: 1,
            col: 1,
        }
    }
}

impl fmt::Display for Pos {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}:{}", self.file.display(), self.line, self.col)
    }
}

/// A malformed file: where, and what is wrong or was expected.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{pos}: {msg}")]
pub struct SyntaxError {
    /// Where.
    pub pos: Pos,
    /// What is wrong and what was expected.
    pub msg: String,
}

impl SyntaxError {
    /// An error at `pos`.
    pub fn at(pos: &Pos, msg: impl Into<String>) -> SyntaxError {
        SyntaxError {
            pos: pos.clone(),
            msg: msg.into(),
        }
    }
}

/// A token.
#[derive(Debug, Clone, PartialEq)]
pub enum Tok {
    /// A bare word (`driver`, `spose[3]`, `odometry::position2d:0`).
    Word(String),
    /// A number as written.
    Num(String),
    /// A quoted string, without its quotes.
    Str(String),
    /// `(`.
    Open,
    /// `)`.
    Close,
    /// `[`.
    TupleOpen,
    /// `]`.
    TupleClose,
    /// A line end (also one at the end of the text).
    Eol,
}

/// A token and where it starts.
#[derive(Debug, Clone)]
pub struct Token {
    /// The token.
    pub tok: Tok,
    /// Its first character.
    pub pos: Pos,
}

const NUMBER: &str = "+-.0123456789";
const UNTERMINATED: &str = "unterminated string: a string ends with `\"` on its own line";

/// Splits `text` (the contents of `file`) into tokens. Words may hold
/// `.-_[]` and the characters of `word_extra` after their first letter.
///
/// # Errors
///
/// An unterminated string or a character the grammar has no place for.
pub fn lex(text: &str, file: &Path, word_extra: &str) -> Result<Vec<Token>, SyntaxError> {
    let chars: Vec<char> = text.chars().collect();
    let file: Arc<Path> = Arc::from(file);
    let mut out = Vec::new();
    let (mut i, mut line, mut col) = (0usize, 1u32, 1u32);
    // Advances past the run of characters matching `pred`, returning it.
    let run = |i: &mut usize, col: &mut u32, pred: &dyn Fn(char) -> bool| {
        let start = *i;
        while *i < chars.len() && pred(chars[*i]) {
            *i += 1;
        }
        *col += (*i - start) as u32;
        chars[start..*i].iter().collect::<String>()
    };
    while i < chars.len() {
        let c = chars[i];
        let pos = Pos {
            file: file.clone(),
            line,
            col,
        };
        let tok = match c {
            '#' => {
                while i < chars.len() && chars[i] != '\n' && chars[i] != '\r' {
                    i += 1;
                }
                continue;
            }
            '\r' | '\n' => {
                i += 1;
                if i < chars.len() && (chars[i] == '\r' || chars[i] == '\n') && chars[i] != c {
                    i += 1;
                }
                line += 1;
                col = 1;
                Tok::Eol
            }
            ' ' | '\t' => {
                i += 1;
                col += 1;
                continue;
            }
            '(' | ')' | '[' | ']' => {
                i += 1;
                col += 1;
                match c {
                    '(' => Tok::Open,
                    ')' => Tok::Close,
                    '[' => Tok::TupleOpen,
                    _ => Tok::TupleClose,
                }
            }
            '"' => {
                let start = i + 1;
                let end = chars[start..]
                    .iter()
                    .position(|&c| c == '"' || c == '\n' || c == '\r')
                    .map(|n| start + n)
                    .filter(|&e| chars[e] == '"')
                    .ok_or_else(|| SyntaxError::at(&pos, UNTERMINATED))?;
                col += (end + 1 - i) as u32;
                i = end + 1;
                Tok::Str(chars[start..end].iter().collect())
            }
            c if c.is_ascii_alphabetic() => Tok::Word(run(&mut i, &mut col, &|c| {
                c.is_ascii_alphanumeric() || ".-_[]".contains(c) || word_extra.contains(c)
            })),
            c if NUMBER.contains(c) => Tok::Num(run(&mut i, &mut col, &|c| NUMBER.contains(c))),
            other => {
                return Err(SyntaxError::at(
                    &pos,
                    format!(
                        "syntax error: unexpected character `{}`",
                        other.escape_default()
                    ),
                ))
            }
        };
        out.push(Token { tok, pos });
    }
    out.push(Token {
        tok: Tok::Eol,
        pos: Pos { file, line, col },
    });
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn toks(text: &str, extra: &str) -> Vec<Tok> {
        lex(text, Path::new("f"), extra)
            .unwrap()
            .into_iter()
            .map(|t| t.tok)
            .collect()
    }

    #[test]
    fn words_numbers_strings_and_line_ends() {
        use Tok::*;
        assert_eq!(
            toks("a spose[3] -1.5 \"x y\" ( ) [ ] # c\r\nb", ""),
            [
                Word("a".into()),
                Word("spose[3]".into()),
                Num("-1.5".into()),
                Str("x y".into()),
                Open,
                Close,
                TupleOpen,
                TupleClose,
                Eol,
                Word("b".into()),
                Eol
            ]
        );
        assert_eq!(toks("laser:0", ":")[0], Word("laser:0".into()));
        let e = lex("laser:0", Path::new("f"), "").unwrap_err();
        assert_eq!(e.pos.col, 6, "`:` is no word character without it");
    }

    #[test]
    fn positions_are_where_tokens_start() {
        let t = lex("ab \"cd\"\n\n  9", Path::new("f"), "").unwrap();
        let at: Vec<(u32, u32)> = t.iter().map(|t| (t.pos.line, t.pos.col)).collect();
        assert_eq!(at, [(1, 1), (1, 4), (1, 8), (2, 1), (3, 3), (3, 4)]);
    }

    #[test]
    fn errors_name_the_place() {
        let e = lex("a \"open\nb", Path::new("f.cfg"), "").unwrap_err();
        assert_eq!(e.pos.col, 3);
        assert!(
            e.to_string().starts_with("f.cfg:1:3: unterminated string"),
            "{e}"
        );
        let e = lex("a\n @", Path::new("f.cfg"), "").unwrap_err();
        assert_eq!(
            e.to_string(),
            "f.cfg:2:2: syntax error: unexpected character `@`"
        );
    }
}
