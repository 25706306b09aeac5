//! Stage's world-file language: tokens, `include`, `define` macros, entities.
//!
//! ```text
//! include "pioneer.inc"             # inlined where it stands
//! define bot position ( size [0.4 0.4 0.2] drive "diff" )
//! resolution 0.02                   # a world property
//! bot ( name "r0" pose [1 2 0 45] ranger( sensor( range [0 5] ) ) )
//! ```
//!
//! # Behavior
//!
//! As Stage 4.3's `worldfile.cc`: words start with a letter and may hold
//! `.-_[]` (so `point[3]` is one name); numbers are runs of `+-.0-9`;
//! strings are double-quoted on one line; a property's value starts on the
//! property's line. A macro's body is parsed when the macro is used, base
//! first: later (derived, then instance) property values win, children of
//! every level are appended. The first definition of a macro name wins. An
//! entity's type is the innermost built-in word of its macro chain.
//! Beyond Stage: tuples may span lines, includes resolve against the
//! including file first (then the world's directory), and errors carry the
//! true file, line and column.

use std::collections::HashMap;
use std::fmt;
use std::path::{Path, PathBuf};

/// A place in a world file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Pos {
    /// The file.
    pub file: PathBuf,
    /// 1-based line.
    pub line: u32,
    /// 1-based column.
    pub col: u32,
}

impl fmt::Display for Pos {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}:{}", self.file.display(), self.line, self.col)
    }
}

/// A malformed world file: where, and what was expected.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{pos}: {msg}")]
pub struct WorldError {
    /// Where.
    pub pos: Pos,
    /// What is wrong and what was expected.
    pub msg: String,
}

/// One value of a property.
#[derive(Debug, Clone, PartialEq)]
pub enum Val {
    /// A number, as written.
    Num(String),
    /// A quoted string.
    Str(String),
}

impl Val {
    /// The value as text.
    pub fn text(&self) -> &str {
        match self {
            Val::Num(s) | Val::Str(s) => s,
        }
    }

    /// The value as a number, as C's `atof` reads it (`"1.2.3"` → 1.2).
    pub fn num(&self) -> f64 {
        let t = self.text().trim();
        let mut end = 0;
        let b = t.as_bytes();
        let mut seen_dot = false;
        if end < b.len() && (b[end] == b'+' || b[end] == b'-') {
            end += 1;
        }
        while end < b.len() && (b[end].is_ascii_digit() || (b[end] == b'.' && !seen_dot)) {
            seen_dot |= b[end] == b'.';
            end += 1;
        }
        t[..end].parse().unwrap_or(0.0)
    }
}

/// A property: its values (one for a scalar) and where it was last set.
#[derive(Debug, Clone, PartialEq)]
pub struct Prop {
    /// The values.
    pub values: Vec<Val>,
    /// Where.
    pub pos: Pos,
}

/// A section of the world: `type ( … )`, or the global section (index 0).
#[derive(Debug, Clone)]
pub struct Entity {
    /// The built-in type (`model`, `position`, `ranger`, `sensor`, `block`, `window`…).
    pub kind: String,
    /// The macro the instance was written with, if any (`pioneer2dx`).
    pub macro_name: Option<String>,
    /// The parent entity (`None` for the global section).
    pub parent: Option<usize>,
    /// Children in file order (base macros' children first).
    pub children: Vec<usize>,
    /// Properties by name.
    pub props: HashMap<String, Prop>,
    /// Where the instance was written.
    pub pos: Pos,
}

/// A parsed world file: entities in pre-order, 0 being the global section.
#[derive(Debug, Clone)]
pub struct WorldFile {
    /// The entities.
    pub entities: Vec<Entity>,
    /// The top-level file.
    pub path: PathBuf,
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Word(String),
    Num(String),
    Str(String),
    Open,
    Close,
    TupleOpen,
    TupleClose,
    Eol,
}

#[derive(Debug, Clone)]
struct Token {
    tok: Tok,
    pos: Pos,
}

const MAX_INCLUDE_DEPTH: usize = 16;
const MAX_MACRO_DEPTH: usize = 64;

fn err(pos: &Pos, msg: impl Into<String>) -> WorldError {
    WorldError {
        pos: pos.clone(),
        msg: msg.into(),
    }
}

fn lex_file(
    path: &Path,
    world_dir: &Path,
    out: &mut Vec<Token>,
    depth: usize,
    from: Option<&Pos>,
) -> Result<(), WorldError> {
    let text = std::fs::read(path).map_err(|e| {
        let at = from.cloned().unwrap_or(Pos {
            file: path.to_owned(),
            line: 1,
            col: 1,
        });
        err(&at, format!("cannot read {}: {e}", path.display()))
    })?;
    let text = String::from_utf8_lossy(&text);
    let chars: Vec<char> = text.chars().collect();
    let (mut i, mut line, mut col) = (0usize, 1u32, 1u32);
    let mut pending_include: Option<Pos> = None;
    while i < chars.len() {
        let c = chars[i];
        let pos = Pos {
            file: path.to_owned(),
            line,
            col,
        };
        let push = |tok: Tok, out: &mut Vec<Token>| {
            out.push(Token {
                tok,
                pos: pos.clone(),
            })
        };
        match c {
            '#' => {
                while i < chars.len() && chars[i] != '\n' && chars[i] != '\r' {
                    i += 1;
                }
            }
            '\r' | '\n' => {
                i += 1;
                if i < chars.len() && (chars[i] == '\r' || chars[i] == '\n') && chars[i] != c {
                    i += 1;
                }
                push(Tok::Eol, out);
                line += 1;
                col = 1;
            }
            ' ' | '\t' => {
                i += 1;
                col += 1;
            }
            '(' | ')' | '[' | ']' => {
                push(
                    match c {
                        '(' => Tok::Open,
                        ')' => Tok::Close,
                        '[' => Tok::TupleOpen,
                        _ => Tok::TupleClose,
                    },
                    out,
                );
                i += 1;
                col += 1;
            }
            '"' => {
                let start = i + 1;
                let mut j = start;
                while j < chars.len() && chars[j] != '"' {
                    if chars[j] == '\n' || chars[j] == '\r' {
                        return Err(err(
                            &pos,
                            "unterminated string: a string ends with `\"` on its own line",
                        ));
                    }
                    j += 1;
                }
                if j >= chars.len() {
                    return Err(err(
                        &pos,
                        "unterminated string: a string ends with `\"` on its own line",
                    ));
                }
                let s: String = chars[start..j].iter().collect();
                col += (j + 1 - i) as u32;
                i = j + 1;
                if let Some(at) = pending_include.take() {
                    if depth >= MAX_INCLUDE_DEPTH {
                        return Err(err(&at, format!("includes nest deeper than {MAX_INCLUDE_DEPTH}: is `{s}` including itself?")));
                    }
                    let here = path.parent().unwrap_or(Path::new(".")).join(&s);
                    let target = if here.exists() {
                        here
                    } else {
                        world_dir.join(&s)
                    };
                    lex_file(&target, world_dir, out, depth + 1, Some(&at))?;
                    continue;
                }
                push(Tok::Str(s), out);
            }
            c if c.is_ascii_alphabetic() => {
                let start = i;
                while i < chars.len()
                    && (chars[i].is_ascii_alphanumeric() || ".-_[]".contains(chars[i]))
                {
                    i += 1;
                }
                let w: String = chars[start..i].iter().collect();
                col += (i - start) as u32;
                if w == "include" && pending_include.is_none() {
                    pending_include = Some(pos.clone());
                    continue;
                }
                if let Some(at) = &pending_include {
                    return Err(err(
                        at,
                        "`include` takes a quoted file name: include \"pioneer.inc\"",
                    ));
                }
                push(Tok::Word(w), out);
            }
            c if "+-.0123456789".contains(c) => {
                let start = i;
                while i < chars.len() && "+-.0123456789".contains(chars[i]) {
                    i += 1;
                }
                col += (i - start) as u32;
                push(Tok::Num(chars[start..i].iter().collect()), out);
            }
            other => {
                return Err(err(
                    &pos,
                    format!(
                        "syntax error: unexpected character `{}`",
                        other.escape_default()
                    ),
                ));
            }
        }
        if pending_include.is_some() && !matches!(c, ' ' | '\t') {
            // Only blanks may separate `include` from its file name.
            if let Some(at) = pending_include.take() {
                return Err(err(
                    &at,
                    "`include` takes a quoted file name: include \"pioneer.inc\"",
                ));
            }
        }
    }
    if let Some(at) = pending_include {
        return Err(err(
            &at,
            "`include` takes a quoted file name: include \"pioneer.inc\"",
        ));
    }
    out.push(Token {
        tok: Tok::Eol,
        pos: Pos {
            file: path.to_owned(),
            line,
            col,
        },
    });
    Ok(())
}

struct Macro {
    base: String,
    /// Index of the first token after the body's `(`.
    body: usize,
}

struct Parser {
    toks: Vec<Token>,
    macros: HashMap<String, Macro>,
    entities: Vec<Entity>,
}

impl Parser {
    fn skip_blank(&self, mut i: usize) -> usize {
        while i < self.toks.len() && self.toks[i].tok == Tok::Eol {
            i += 1;
        }
        i
    }

    fn tok(&self, i: usize) -> Result<&Token, WorldError> {
        self.toks.get(i).ok_or_else(|| {
            let last = self.toks.last().map(|t| t.pos.clone()).unwrap_or(Pos {
                file: PathBuf::new(),
                line: 1,
                col: 1,
            });
            err(&last, "unexpected end of file")
        })
    }

    /// Parses a value starting at `i` (on the property's line); returns the values and the next index.
    fn value(&self, name: &Token, i: usize) -> Result<(Vec<Val>, usize), WorldError> {
        let t = self.tok(i)?;
        match &t.tok {
            Tok::Num(n) => Ok((vec![Val::Num(n.clone())], i + 1)),
            Tok::Str(s) => Ok((vec![Val::Str(s.clone())], i + 1)),
            Tok::TupleOpen => {
                let mut vals = Vec::new();
                let mut j = i + 1;
                loop {
                    let t = self.tok(j)?;
                    match &t.tok {
                        Tok::Num(n) => vals.push(Val::Num(n.clone())),
                        Tok::Str(s) => vals.push(Val::Str(s.clone())),
                        Tok::Eol => {}
                        Tok::TupleClose => return Ok((vals, j + 1)),
                        _ => return Err(err(&t.pos, "expected a number, a \"string\" or `]` inside a tuple")),
                    }
                    j += 1;
                }
            }
            Tok::Word(w) => Err(err(
                &t.pos,
                format!("`{w}` is not a value: text values are quoted (`\"{w}\"`) and a model needs `(`"),
            )),
            Tok::Eol => Err(err(&name.pos, "expected a value on the same line as the property name")),
            _ => Err(err(&t.pos, "expected a value: a number, a \"string\" or a [tuple]")),
        }
    }

    /// Parses entity body tokens from `i` (after `(`) into entity `e`; returns the index after `)`.
    fn body(&mut self, mut i: usize, e: usize, open: &Pos) -> Result<usize, WorldError> {
        loop {
            i = self.skip_blank(i);
            let Some(t) = self.toks.get(i).cloned() else {
                return Err(err(open, "missing `)`: this section is never closed"));
            };
            match &t.tok {
                Tok::Close => return Ok(i + 1),
                Tok::Word(w) => {
                    let j = self.skip_blank(i + 1);
                    if matches!(self.toks.get(j).map(|t| &t.tok), Some(Tok::Open)) {
                        i = self.instance(w, &t.pos, Some(e), j + 1, 0)?;
                    } else {
                        let (values, next) = self.value(&t, i + 1)?;
                        self.entities[e].props.insert(
                            w.clone(),
                            Prop {
                                values,
                                pos: t.pos.clone(),
                            },
                        );
                        i = next;
                    }
                }
                _ => return Err(err(&t.pos, "expected a property name, a model or `)`")),
            }
        }
    }

    /// Creates an entity for `word ( … )` whose body starts at `body`; returns the index after its `)`.
    fn instance(
        &mut self,
        word: &str,
        at: &Pos,
        parent: Option<usize>,
        body: usize,
        depth: usize,
    ) -> Result<usize, WorldError> {
        // The macro chain, outermost first.
        let mut chain: Vec<usize> = Vec::new();
        let mut kind = word.to_owned();
        let mut seen = vec![word.to_owned()];
        while let Some(m) = self.macros.get(&kind) {
            chain.push(m.body);
            kind = m.base.clone();
            if seen.contains(&kind) || seen.len() > MAX_MACRO_DEPTH + depth {
                return Err(err(
                    at,
                    format!(
                        "macro `{word}` is defined in terms of itself ({})",
                        seen.join(" → ")
                    ),
                ));
            }
            seen.push(kind.clone());
        }
        let e = self.entities.len();
        self.entities.push(Entity {
            kind,
            macro_name: (seen.len() > 1).then(|| word.to_owned()),
            parent,
            children: Vec::new(),
            props: HashMap::new(),
            pos: at.clone(),
        });
        if let Some(p) = parent {
            self.entities[p].children.push(e);
        }
        for &b in chain.iter().rev() {
            let open = self.toks[b.saturating_sub(1)].pos.clone();
            self.body(b, e, &open)?;
        }
        let open = self.toks[body.saturating_sub(1)].pos.clone();
        self.body(body, e, &open)
    }

    /// Skips a balanced `( … )` starting after `(`; returns the index after `)`.
    fn skip_section(&self, mut i: usize, open: &Pos) -> Result<usize, WorldError> {
        let mut depth = 1;
        while depth > 0 {
            let t = self
                .toks
                .get(i)
                .ok_or_else(|| err(open, "missing `)`: this definition is never closed"))?;
            match t.tok {
                Tok::Open => depth += 1,
                Tok::Close => depth -= 1,
                _ => {}
            }
            i += 1;
        }
        Ok(i)
    }

    fn file(&mut self) -> Result<(), WorldError> {
        let mut i = 0;
        loop {
            i = self.skip_blank(i);
            let Some(t) = self.toks.get(i).cloned() else {
                return Ok(());
            };
            let Tok::Word(w) = &t.tok else {
                return Err(err(
                    &t.pos,
                    "expected a world property, a model, `define` or `include`",
                ));
            };
            if w == "define" {
                let name = self.tok(i + 1)?.clone();
                let base = self.tok(i + 2)?.clone();
                let (Tok::Word(n), Tok::Word(b)) = (&name.tok, &base.tok) else {
                    return Err(err(&t.pos, "expected `define NAME BASE ( … )`"));
                };
                let open = self.skip_blank(i + 3);
                if !matches!(self.tok(open)?.tok, Tok::Open) {
                    return Err(err(&t.pos, format!("expected `(` after `define {n} {b}`")));
                }
                let end = self.skip_section(open + 1, &self.toks[open].pos.clone())?;
                // The first definition of a name wins, as in Stage.
                self.macros.entry(n.clone()).or_insert(Macro {
                    base: b.clone(),
                    body: open + 1,
                });
                i = end;
                continue;
            }
            let j = self.skip_blank(i + 1);
            if matches!(self.toks.get(j).map(|t| &t.tok), Some(Tok::Open)) {
                i = self.instance(w, &t.pos, Some(0), j + 1, 0)?;
            } else {
                let (values, next) = self.value(&t, i + 1)?;
                self.entities[0].props.insert(
                    w.clone(),
                    Prop {
                        values,
                        pos: t.pos.clone(),
                    },
                );
                i = next;
            }
        }
    }
}

/// Parses the world file at `path`, with its includes and macros.
///
/// # Errors
///
/// The first problem, as `file:line:column: what was expected`.
pub fn parse(path: &Path) -> Result<WorldFile, WorldError> {
    let world_dir = path.parent().unwrap_or(Path::new(".")).to_owned();
    let mut toks = Vec::new();
    lex_file(path, &world_dir, &mut toks, 0, None)?;
    let mut p = Parser {
        toks,
        macros: HashMap::new(),
        entities: vec![Entity {
            kind: String::new(),
            macro_name: None,
            parent: None,
            children: Vec::new(),
            props: HashMap::new(),
            pos: Pos {
                file: path.to_owned(),
                line: 1,
                col: 1,
            },
        }],
    };
    p.file()?;
    // Top-level entities are children of the global section; present them without a parent.
    for e in p.entities.iter_mut().skip(1) {
        if e.parent == Some(0) {
            e.parent = None;
        }
    }
    Ok(WorldFile {
        entities: p.entities,
        path: path.to_owned(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse_text(name: &str, text: &str) -> Result<WorldFile, WorldError> {
        let dir = std::env::temp_dir().join(format!("troupe-wf-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("t.world");
        std::fs::write(&p, text).unwrap();
        let r = parse(&p);
        let _ = std::fs::remove_dir_all(&dir);
        r
    }

    #[test]
    fn macros_inherit_override_and_append_children() {
        let w = parse_text(
            "macros",
            "define base position ( size [1 1 1] color \"red\" block( points 0 ) )\n\
             define bot base ( color \"blue\" ranger( ) )\n\
             bot ( name \"r0\" color \"green\" pose [1 2 0 90] )\n\
             resolution 0.05\n",
        )
        .unwrap();
        let r0 = &w.entities[1];
        assert_eq!(r0.kind, "position");
        assert_eq!(r0.macro_name.as_deref(), Some("bot"));
        assert_eq!(r0.props["color"].values, vec![Val::Str("green".into())]);
        assert_eq!(r0.props["size"].values.len(), 3);
        let kids: Vec<&str> = r0
            .children
            .iter()
            .map(|&c| w.entities[c].kind.as_str())
            .collect();
        assert_eq!(kids, vec!["block", "ranger"]);
        assert_eq!(w.entities[0].props["resolution"].values[0].num(), 0.05);
        assert_eq!(r0.parent, None);
    }

    #[test]
    fn first_definition_wins_and_recursion_is_an_error() {
        let w = parse_text(
            "first",
            "define a model ( size [1 1 1] )\ndefine a model ( size [2 2 2] )\na ( )\n",
        )
        .unwrap();
        assert_eq!(w.entities[1].props["size"].values[0].num(), 1.0);
        let e = parse_text("rec", "define a b ( )\ndefine b a ( )\na ( )\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("defined in terms of itself"), "{e}");
    }

    #[test]
    fn errors_carry_file_line_and_column() {
        let cases = [
            ("model (\n  name r0\n)", ":2:8: `r0` is not a value"),
            (
                "model (\n  size\n [1 1 1]\n)",
                ":2:3: expected a value on the same line",
            ),
            ("model ( name \"x )", ":1:14: unterminated string"),
            ("model ( size [1 2 )", ":1:19: expected a number"),
            ("model ( pose [1 2 3 4]", ":1:7: missing `)`"),
            ("include \"nope.inc\"", ":1:1: cannot read"),
            (
                "model ( x 1 ) ; ",
                ":1:15: syntax error: unexpected character `;`",
            ),
            ("5", ":1:1: expected a world property"),
        ];
        for (text, want) in cases {
            let e = parse_text("errors", text).unwrap_err().to_string();
            assert!(e.contains(want), "{text:?}: {e}");
        }
    }

    #[test]
    fn atof_reads_numbers_like_c() {
        assert_eq!(Val::Num("1.2.3".into()).num(), 1.2);
        assert_eq!(Val::Num("-".into()).num(), 0.0);
        assert_eq!(Val::Num("+3".into()).num(), 3.0);
        assert_eq!(Val::Num("-0.5".into()).num(), -0.5);
    }
}
