//! Player's `.cfg` language: a faithful parser with file:line:column errors.
//!
//! ```text
//! # comment
//! include "other.cfg"            # relative to this file
//! unit_length "cm"               # m | cm | mm, applies from here on
//! unit_angle "radians"           # degrees | radians, applies from here on
//! driver
//! (
//!   name "sicklms200"
//!   provides ["laser:0"]
//!   pose [0.15 0 0]              # tuples may span lines and nest
//!   port "/dev/ttyS0"
//! )
//! ```
//!
//! # Behavior
//!
//! Tokens are Player's: words start with a letter and may hold `.-_[]:`
//! (so `spose[3]` is one word), numbers are runs of `+-.0-9`, strings are
//! double-quoted on one line, `true/false/yes/no` are booleans. A field's
//! value starts on the field's line, as Player requires. Beyond Player, bare
//! words are accepted as values and tuples may nest. A field given twice in a
//! section is merged element by element, later values winning, as Player's
//! `AddField`/`AddFieldValue` do. `unit_length`/`unit_angle` are recorded on
//! every field that follows them (Player itself applies the file's last
//! setting everywhere; the two agree whenever a file sets them once, at the
//! top, as every known cfg does).

use std::path::Path;

pub use troupe_node::syntax::Pos;
use troupe_node::syntax::{lex, SyntaxError, Tok, Token};

/// A syntax error, with where it is and what was expected.
pub type CfgError = SyntaxError;

/// A field value.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    /// A number, with its text (integers stay integers).
    Num(String),
    /// A quoted string.
    Str(String),
    /// `true`/`false`/`yes`/`no`.
    Bool(bool),
    /// A bare word (Player would reject it; we read it as a string).
    Word(String),
    /// `[ … ]`.
    Tuple(Vec<Value>),
}

/// Length and angle units in force where a field was read.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Units {
    /// Metres per unit of length.
    pub length: f64,
    /// Radians per unit of angle.
    pub angle: f64,
}

impl Default for Units {
    /// Player's defaults: metres and degrees.
    fn default() -> Self {
        Units {
            length: 1.0,
            angle: std::f64::consts::PI / 180.0,
        }
    }
}

/// `name value` inside a section (or at the top level).
#[derive(Debug, Clone, PartialEq)]
pub struct Field {
    /// The field name.
    pub name: String,
    /// Its value.
    pub value: Value,
    /// Where the name is.
    pub pos: Pos,
    /// Units in force there.
    pub units: Units,
}

/// `kind ( … )`.
#[derive(Debug, Clone, PartialEq)]
pub struct Section {
    /// `driver`, usually.
    pub kind: String,
    /// Where the kind word is.
    pub pos: Pos,
    /// Fields, in file order, repeated names merged.
    pub fields: Vec<Field>,
    /// Sections nested inside.
    pub children: Vec<Section>,
}

impl Section {
    /// The field called `name`.
    pub fn field(&self, name: &str) -> Option<&Field> {
        self.fields.iter().find(|f| f.name == name)
    }
}

/// A parsed cfg file, includes expanded.
#[derive(Debug, Clone, Default)]
pub struct CfgFile {
    /// Top-level sections, in order.
    pub sections: Vec<Section>,
    /// Top-level fields (other than the unit directives).
    pub globals: Vec<Field>,
    /// `plugin "…"` statements (Player loads libraries; Troupe's drivers are built in).
    pub plugins: Vec<(String, Pos)>,
}

/// How deep includes may nest before we call it a cycle.
const MAX_INCLUDE_DEPTH: usize = 16;

struct Parser<'a> {
    toks: &'a [Token],
    i: usize,
}

impl Parser<'_> {
    fn pos(&self, t: &Token) -> Pos {
        t.pos.clone()
    }

    fn err(&self, t: &Token, msg: impl Into<String>) -> CfgError {
        SyntaxError::at(&t.pos, msg)
    }

    fn peek(&self) -> Option<&Token> {
        self.toks.get(self.i)
    }

    /// True when the next token other than line ends opens a section.
    fn section_follows(&self) -> bool {
        self.toks[self.i..]
            .iter()
            .find(|t| t.tok != Tok::Eol)
            .is_some_and(|t| t.tok == Tok::Open)
    }

    fn skip_eols(&mut self) {
        while matches!(self.peek(), Some(Token { tok: Tok::Eol, .. })) {
            self.i += 1;
        }
    }

    /// A value starting at the current token (which must be on the field's line).
    fn value(&mut self, field: &Token) -> Result<Value, CfgError> {
        let Some(t) = self.toks.get(self.i).cloned() else {
            return Err(self.err(field, "expected a value"));
        };
        self.i += 1;
        match t.tok.clone() {
            Tok::Num(n) => {
                if n.parse::<f64>().is_err() {
                    return Err(self.err(&t, format!("`{n}` is not a number")));
                }
                Ok(Value::Num(n))
            }
            Tok::Str(s) => Ok(Value::Str(s)),
            Tok::Word(w) => Ok(match w.as_str() {
                "true" | "yes" => Value::Bool(true),
                "false" | "no" => Value::Bool(false),
                _ => Value::Word(w),
            }),
            Tok::TupleOpen => {
                let mut items = Vec::new();
                loop {
                    self.skip_eols();
                    match self.peek() {
                        Some(Token {
                            tok: Tok::TupleClose,
                            ..
                        }) => {
                            self.i += 1;
                            return Ok(Value::Tuple(items));
                        }
                        Some(Token {
                            tok: Tok::Open | Tok::Close,
                            ..
                        }) => {
                            let t = self.toks[self.i].clone();
                            return Err(self.err(
                                &t,
                                format!(
                                    "expected `]` to close the tuple opened at line {}",
                                    field.pos.line
                                ),
                            ));
                        }
                        Some(_) if self.i + 1 < self.toks.len() => items.push(self.value(field)?),
                        _ => return Err(self.err(&t, "missing `]`: tuple never closed")),
                    }
                }
            }
            Tok::Eol => Err(self.err(
                field,
                "expected a value on the same line as the field name (Player's rule)",
            )),
            Tok::Open | Tok::Close | Tok::TupleClose => {
                Err(self.err(&t, "expected a value (number, \"string\", word or [tuple])"))
            }
        }
    }
}

/// Merges a repeated field into `fields` as Player does: element by element.
fn add_field(fields: &mut Vec<Field>, f: Field) {
    if let Some(old) = fields.iter_mut().find(|o| o.name == f.name) {
        match (&mut old.value, f.value) {
            (Value::Tuple(a), Value::Tuple(b)) => {
                for (i, v) in b.into_iter().enumerate() {
                    match a.get_mut(i) {
                        Some(slot) => *slot = v,
                        None => a.push(v),
                    }
                }
            }
            (Value::Tuple(a), v) => {
                if let Some(slot) = a.first_mut() {
                    *slot = v;
                } else {
                    a.push(v);
                }
            }
            (slot, v) => *slot = v,
        }
        old.pos = f.pos;
        return;
    }
    fields.push(f);
}

/// Parses the cfg file at `path`, expanding includes.
///
/// # Errors
///
/// The first syntax error, as `file:line:column: what was expected`, or an
/// unreadable file.
pub fn parse_file(path: &Path) -> Result<CfgFile, CfgError> {
    let mut out = CfgFile::default();
    let mut units = Units::default();
    parse_into(path, &mut out, &mut units, 0, None)?;
    Ok(out)
}

/// Parses cfg text as if read from `path` (includes resolve relative to it).
///
/// # Errors
///
/// As [`parse_file`].
#[cfg(test)]
pub fn parse_str(text: &str, path: &Path) -> Result<CfgFile, CfgError> {
    let mut out = CfgFile::default();
    let mut units = Units::default();
    parse_text(text, path, &mut out, &mut units, 0)?;
    Ok(out)
}

fn parse_into(
    path: &Path,
    out: &mut CfgFile,
    units: &mut Units,
    depth: usize,
    from: Option<&Pos>,
) -> Result<(), CfgError> {
    let text = std::fs::read_to_string(path).map_err(|e| CfgError {
        pos: from.cloned().unwrap_or_else(|| Pos::start(path)),
        msg: format!("cannot read {}: {e}", path.display()),
    })?;
    parse_text(&text, path, out, units, depth)
}

fn parse_text(
    text: &str,
    path: &Path,
    out: &mut CfgFile,
    units: &mut Units,
    depth: usize,
) -> Result<(), CfgError> {
    let toks = lex(text, path, ":")?;
    let mut p = Parser { toks: &toks, i: 0 };
    loop {
        p.skip_eols();
        let Some(t) = p.peek().cloned() else {
            return Ok(());
        };
        p.i += 1;
        let Tok::Word(word) = &t.tok else {
            return Err(p.err(
                &t,
                "expected a section (`driver ( … )`), a field, `include \"file\"` or a comment",
            ));
        };
        match word.as_str() {
            "include" => {
                let f = match p.value(&t)? {
                    Value::Str(s) => s,
                    _ => {
                        return Err(p.err(
                            &t,
                            "`include` takes a quoted file name: include \"other.cfg\"",
                        ))
                    }
                };
                if depth >= MAX_INCLUDE_DEPTH {
                    return Err(p.err(&t, format!("includes nest deeper than {MAX_INCLUDE_DEPTH}: is `{f}` including itself?")));
                }
                let target = path.parent().unwrap_or(Path::new(".")).join(&f);
                let here = p.pos(&t);
                parse_into(&target, out, units, depth + 1, Some(&here))?;
            }
            "define" => {
                return Err(p.err(&t, "`define` macros are not supported in Troupe .cfg files; write the sections out"));
            }
            _ => match p.section_follows() {
                true => {
                    p.skip_eols();
                    let s = section(&mut p, &t, word, units)?;
                    out.sections.push(s);
                }
                false => {
                    let value = p.value(&t)?;
                    let f = Field {
                        name: word.clone(),
                        value,
                        pos: p.pos(&t),
                        units: *units,
                    };
                    match word.as_str() {
                        "unit_length" => {
                            units.length = match &f.value {
                                Value::Str(s) | Value::Word(s) if s == "m" => 1.0,
                                Value::Str(s) | Value::Word(s) if s == "cm" => 0.01,
                                Value::Str(s) | Value::Word(s) if s == "mm" => 0.001,
                                _ => {
                                    return Err(
                                        p.err(&t, "unit_length must be \"m\", \"cm\" or \"mm\"")
                                    )
                                }
                            }
                        }
                        "unit_angle" => {
                            units.angle = match &f.value {
                                Value::Str(s) | Value::Word(s) if s == "degrees" => {
                                    std::f64::consts::PI / 180.0
                                }
                                Value::Str(s) | Value::Word(s) if s == "radians" => 1.0,
                                _ => {
                                    return Err(
                                        p.err(&t, "unit_angle must be \"degrees\" or \"radians\"")
                                    )
                                }
                            }
                        }
                        "plugin" => match f.value {
                            Value::Str(s) => out.plugins.push((s, f.pos)),
                            _ => return Err(p.err(&t, "`plugin` takes a quoted library name")),
                        },
                        _ => add_field(&mut out.globals, f),
                    }
                }
            },
        }
    }
}

fn section(
    p: &mut Parser<'_>,
    kind_tok: &Token,
    kind: &str,
    units: &Units,
) -> Result<Section, CfgError> {
    // The `(`.
    p.i += 1;
    let mut s = Section {
        kind: kind.to_owned(),
        pos: p.pos(kind_tok),
        fields: Vec::new(),
        children: Vec::new(),
    };
    loop {
        p.skip_eols();
        let Some(t) = p.peek().cloned() else {
            return Err(p.err(
                kind_tok,
                format!("missing `)`: section `{kind}` is never closed"),
            ));
        };
        p.i += 1;
        match &t.tok {
            Tok::Close => return Ok(s),
            Tok::Word(name) => {
                if p.section_follows() {
                    p.skip_eols();
                    let child = section(p, &t, name, units)?;
                    s.children.push(child);
                    continue;
                }
                let value = p.value(&t)?;
                let f = Field {
                    name: name.clone(),
                    value,
                    pos: p.pos(&t),
                    units: *units,
                };
                add_field(&mut s.fields, f);
            }
            Tok::Eol => {
                return Err(p.err(
                    kind_tok,
                    format!("missing `)`: section `{kind}` is never closed"),
                ));
            }
            other => {
                let what = match other {
                    Tok::Num(n) => format!("number `{n}`"),
                    Tok::Str(v) => format!("string \"{v}\""),
                    Tok::Open => "`(`".into(),
                    Tok::TupleOpen => "`[`".into(),
                    _ => "`]`".into(),
                };
                return Err(p.err(&t, format!("expected a field name or `)`, found {what} (is a field name missing, or a value on the next line?)")));
            }
        }
    }
}

impl Value {
    /// The strings of a string or a tuple of strings (for `provides`/`requires`).
    pub fn strings(&self) -> Option<Vec<&str>> {
        match self {
            Value::Str(s) | Value::Word(s) => Some(vec![s.as_str()]),
            Value::Tuple(v) => v
                .iter()
                .map(|x| match x {
                    Value::Str(s) | Value::Word(s) => Some(s.as_str()),
                    _ => None,
                })
                .collect(),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<CfgFile, CfgError> {
        parse_str(text, Path::new("t.cfg"))
    }

    #[test]
    fn sections_fields_tuples_comments() {
        let f = parse(
            "# a robot\ndriver\n(\n  name \"sicklms200\" # the laser\n  provides [\"laser:0\"]\n  pose [0.15 0\n        -90]\n  alwayson yes\n  spose[3] [1 2]\n)\ndriver( name \"x\" nested [[1 2] [3]] mode fast )\n",
        )
        .unwrap();
        assert_eq!(f.sections.len(), 2);
        let s = &f.sections[0];
        assert_eq!(s.kind, "driver");
        assert_eq!(
            s.field("name").unwrap().value,
            Value::Str("sicklms200".into())
        );
        assert_eq!(
            s.field("pose").unwrap().value,
            Value::Tuple(vec![
                Value::Num("0.15".into()),
                Value::Num("0".into()),
                Value::Num("-90".into())
            ])
        );
        assert_eq!(s.field("alwayson").unwrap().value, Value::Bool(true));
        assert!(s.field("spose[3]").is_some());
        assert_eq!(s.field("provides").unwrap().pos.line, 5);
        assert_eq!(s.field("provides").unwrap().pos.col, 3);
        let n = &f.sections[1];
        assert_eq!(n.field("mode").unwrap().value, Value::Word("fast".into()));
        assert!(matches!(&n.field("nested").unwrap().value, Value::Tuple(v) if v.len() == 2));
    }

    #[test]
    fn adjacent_strings_are_two_values() {
        let f = parse("driver( name \"stage\" provides [\"7001:ranger:0\" \"7001:ranger:1 \"\"7001:position2d:0\" ] )").unwrap();
        let v = f.sections[0]
            .field("provides")
            .unwrap()
            .value
            .strings()
            .unwrap();
        assert_eq!(
            v,
            vec!["7001:ranger:0", "7001:ranger:1 ", "7001:position2d:0"]
        );
    }

    #[test]
    fn repeated_fields_merge_element_by_element() {
        let f = parse("driver( provides [\"a:0\" \"b:0\"] provides [\"c:0\"] )").unwrap();
        let v = f.sections[0]
            .field("provides")
            .unwrap()
            .value
            .strings()
            .unwrap();
        assert_eq!(v, vec!["c:0", "b:0"]);
    }

    #[test]
    fn units_apply_from_the_directive_on() {
        let f = parse("driver( a 1 )\nunit_length \"cm\"\nunit_angle \"radians\"\ndriver( b 1 )")
            .unwrap();
        assert_eq!(f.sections[0].fields[0].units, Units::default());
        assert_eq!(
            f.sections[1].fields[0].units,
            Units {
                length: 0.01,
                angle: 1.0
            }
        );
        let e = parse("unit_length \"feet\"").unwrap_err();
        assert_eq!(
            e.to_string(),
            "t.cfg:1:1: unit_length must be \"m\", \"cm\" or \"mm\""
        );
    }

    #[test]
    fn errors_name_the_place_and_the_expectation() {
        let cases = [
            ("driver(\n  name \"x\n)", "t.cfg:2:8: unterminated string"),
            ("driver(\n  name \"x\"\n", "t.cfg:1:1: missing `)`"),
            (
                "driver(\n  provides\n  [\"laser:0\"]\n)",
                "t.cfg:2:3: expected a value on the same line",
            ),
            ("driver( pose [1 2 )", "t.cfg:1:19: expected `]`"),
            (
                "driver( 5 )",
                "t.cfg:1:9: expected a field name or `)`, found number `5`",
            ),
            (
                "driver( a 1 ) @",
                "t.cfg:1:15: syntax error: unexpected character `@`",
            ),
            ("\"x\"", "t.cfg:1:1: expected a section"),
            ("driver( x 1..2 )", "t.cfg:1:11: `1..2` is not a number"),
            (
                "define foo driver ( )",
                "t.cfg:1:1: `define` macros are not supported",
            ),
            ("include \"nope.cfg\"", "t.cfg:1:1: cannot read nope.cfg"),
        ];
        for (text, want) in cases {
            let e = parse(text).unwrap_err().to_string();
            assert!(e.starts_with(want), "{text:?}: got {e}");
        }
    }

    #[test]
    fn includes_resolve_relative_to_the_including_file() {
        let dir = std::env::temp_dir().join(format!("troupe-cfg-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("sub")).unwrap();
        std::fs::write(
            dir.join("sub/inner.cfg"),
            "driver( name \"inner\" )\nunit_length \"mm\"\n",
        )
        .unwrap();
        std::fs::write(
            dir.join("main.cfg"),
            "include \"sub/inner.cfg\"\ndriver( name \"outer\" x 1 )\n",
        )
        .unwrap();
        std::fs::write(dir.join("loop.cfg"), "include \"loop.cfg\"\n").unwrap();
        let f = parse_file(&dir.join("main.cfg")).unwrap();
        assert_eq!(f.sections.len(), 2);
        assert_eq!(f.sections[1].fields[1].units.length, 0.001);
        let e = parse_file(&dir.join("loop.cfg")).unwrap_err().to_string();
        assert!(e.contains("including itself"), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn crlf_and_garbage_never_panic() {
        assert!(parse("driver(\r\n name \"x\"\r\n)\r\n").is_ok());
        let mut x: u32 = 7;
        let alphabet = b"driver( )[]\"#\n 0.5-x:pose";
        for len in 0..400 {
            let s: String = (0..len % 40)
                .map(|_| {
                    x ^= x << 13;
                    x ^= x >> 17;
                    x ^= x << 5;
                    alphabet[(x as usize) % alphabet.len()] as char
                })
                .collect();
            let _ = parse(&s);
        }
    }
}
