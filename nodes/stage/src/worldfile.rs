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
use std::path::{Path, PathBuf};
use std::sync::Arc;

pub use troupe_node::syntax::Pos;
use troupe_node::syntax::{lex, SyntaxError, Tok, Token};

/// A malformed world file: where, and what was expected.
pub type WorldError = SyntaxError;

/// One value of a property. Its text is shared with the token it was
/// read from: a macro's body is read again for every model made with it
/// (Stage's hospital.world: 1000 robots of 13 sections each); copying
/// each word and number there, and each token read, made its load take
/// 115 ms where it takes 89.
#[derive(Debug, Clone, PartialEq)]
pub enum Val {
    /// A number, as written.
    Num(Arc<str>),
    /// A quoted string.
    Str(Arc<str>),
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
    pub props: Props,
    /// Where the instance was written.
    pub pos: Pos,
}

/// An entity's properties by name, in the order first set: a list
/// searched from the front. An entity has a few (a Pioneer's sections
/// fifteen at most), and the hospital's 14 000 sections each built,
/// grew and freed a hash table: a list is one allocation, and comparing
/// a few short names costs less than hashing one.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Props(Vec<(Arc<str>, Prop)>);

impl Props {
    /// The property `name`, if set.
    pub fn get(&self, name: &str) -> Option<&Prop> {
        self.0.iter().find(|(k, _)| **k == *name).map(|(_, p)| p)
    }

    /// Whether `name` is set.
    pub fn contains_key(&self, name: &str) -> bool {
        self.get(name).is_some()
    }

    /// Sets `name` to `prop`, replacing what it was.
    pub fn insert(&mut self, name: Arc<str>, prop: Prop) {
        match self.0.iter_mut().find(|(k, _)| *k == name) {
            Some((_, p)) => *p = prop,
            None => self.0.push((name, prop)),
        }
    }
}

impl std::ops::Index<&str> for Props {
    type Output = Prop;

    /// The property `name`; panics when it is not set.
    fn index(&self, name: &str) -> &Prop {
        self.get(name)
            .unwrap_or_else(|| panic!("property `{name}` is not set"))
    }
}

/// A parsed world file: entities in pre-order, 0 being the global section.
#[derive(Debug, Clone)]
pub struct WorldFile {
    /// The entities.
    pub entities: Vec<Entity>,
    /// The top-level file.
    pub path: PathBuf,
}

const MAX_INCLUDE_DEPTH: usize = 16;
const MAX_MACRO_DEPTH: usize = 64;

fn err(pos: &Pos, msg: impl Into<String>) -> WorldError {
    SyntaxError::at(pos, msg)
}

const INCLUDE_FORM: &str = "`include` takes a quoted file name: include \"pioneer.inc\"";

/// Tokens of `path` with every `include "file"` replaced by that file's
/// tokens (looked up next to the including file, then in the world's directory).
fn lex_file(
    path: &Path,
    world_dir: &Path,
    out: &mut Vec<Token>,
    depth: usize,
    from: Option<&Pos>,
) -> Result<(), WorldError> {
    let text = std::fs::read(path).map_err(|e| {
        let at = from.cloned().unwrap_or_else(|| Pos::start(path));
        err(&at, format!("cannot read {}: {e}", path.display()))
    })?;
    let mut toks = lex(&String::from_utf8_lossy(&text), path, "")?.into_iter();
    while let Some(t) = toks.next() {
        if t.tok != Tok::Word("include".into()) {
            out.push(t);
            continue;
        }
        // Only blanks may separate `include` from its file name.
        let Some(Token {
            tok: Tok::Str(s), ..
        }) = toks.next()
        else {
            return Err(err(&t.pos, INCLUDE_FORM));
        };
        if depth >= MAX_INCLUDE_DEPTH {
            return Err(err(
                &t.pos,
                format!(
                    "includes nest deeper than {MAX_INCLUDE_DEPTH}: is `{s}` including itself?"
                ),
            ));
        }
        let here = path.parent().unwrap_or(Path::new(".")).join(&s);
        let target = if here.exists() {
            here
        } else {
            world_dir.join(&s)
        };
        lex_file(&target, world_dir, out, depth + 1, Some(&t.pos))?;
    }
    Ok(())
}

struct Macro {
    base: String,
    /// Index of the first token after the body's `(`.
    body: usize,
}

struct Parser {
    toks: Vec<Token>,
    /// The text of each word, number and string token (empty for the
    /// others), shared by every value and name read from it.
    texts: Vec<Arc<str>>,
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
            let last = self
                .toks
                .last()
                .map_or_else(|| Pos::start(Path::new("")), |t| t.pos.clone());
            err(&last, "unexpected end of file")
        })
    }

    /// Parses a value starting at `i` (on the property's line); returns the values and the next index.
    fn value(&self, name: &Token, i: usize) -> Result<(Vec<Val>, usize), WorldError> {
        let t = self.tok(i)?;
        match &t.tok {
            Tok::Num(_) => Ok((vec![Val::Num(self.texts[i].clone())], i + 1)),
            Tok::Str(_) => Ok((vec![Val::Str(self.texts[i].clone())], i + 1)),
            Tok::TupleOpen => {
                let mut vals = Vec::new();
                let mut j = i + 1;
                loop {
                    let t = self.tok(j)?;
                    match &t.tok {
                        Tok::Num(_) => vals.push(Val::Num(self.texts[j].clone())),
                        Tok::Str(_) => vals.push(Val::Str(self.texts[j].clone())),
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
            let Some(t) = self.toks.get(i) else {
                return Err(err(open, "missing `)`: this section is never closed"));
            };
            match &t.tok {
                Tok::Close => return Ok(i + 1),
                Tok::Word(_) => {
                    let j = self.skip_blank(i + 1);
                    if matches!(self.toks.get(j).map(|t| &t.tok), Some(Tok::Open)) {
                        let (w, at) = (self.texts[i].clone(), t.pos.clone());
                        i = self.instance(&w, &at, Some(e), j + 1, 0)?;
                    } else {
                        let (values, next) = self.value(t, i + 1)?;
                        let pos = t.pos.clone();
                        self.entities[e]
                            .props
                            .insert(self.texts[i].clone(), Prop { values, pos });
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
            props: Props::default(),
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
                    self.texts[i].clone(),
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
    let none: Arc<str> = Arc::from("");
    let texts = toks
        .iter()
        .map(|t| match &t.tok {
            Tok::Word(s) | Tok::Num(s) | Tok::Str(s) => Arc::from(s.as_str()),
            _ => none.clone(),
        })
        .collect();
    let mut p = Parser {
        toks,
        texts,
        macros: HashMap::new(),
        entities: vec![Entity {
            kind: String::new(),
            macro_name: None,
            parent: None,
            children: Vec::new(),
            props: Props::default(),
            pos: Pos::start(path),
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
