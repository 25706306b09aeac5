//! Captured serial streams: what crossed a line, both ways, in order, as
//! text a person can read and diff.
//!
//! ```text
//! # p2os handshake, captured with `troupe emulate p2os --capture FILE`
//! baud 9600
//! > FA FB 03 00 00 00        bytes from the driver to the device
//! < FA FB 03 00 00 00        bytes from the device to the driver
//! ```
//!
//! [`Recorder`] writes one (an emulator's `--capture`); [`replay`] plays
//! the device's side of one back to a driver over a pseudo-terminal and
//! checks that the driver sends exactly the captured bytes, at the
//! captured baud rates, in the captured order.

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use crate::pty::Pty;
use crate::Emulator;
use crate::{Codec, Framer};

/// One line of a capture.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Entry {
    /// The line's rate from here on.
    Baud(u32),
    /// Bytes the driver sent.
    ToDevice(Vec<u8>),
    /// Bytes the device sent.
    FromDevice(Vec<u8>),
}

/// A capture: its entries, each with its line number in the text.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Capture {
    /// The entries, in order, with their line numbers.
    pub entries: Vec<(usize, Entry)>,
}

/// A capture that cannot be read: where, and why.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{origin}:{line}: {why}")]
pub struct CaptureError {
    /// The file (or other origin) of the text.
    pub origin: String,
    /// The line, from 1.
    pub line: usize,
    /// What is wrong.
    pub why: String,
}

fn hex(bytes: &[u8]) -> String {
    let mut s = String::with_capacity(bytes.len() * 3);
    for (i, b) in bytes.iter().enumerate() {
        if i > 0 {
            s.push(' ');
        }
        let _ = write!(s, "{b:02X}");
    }
    s
}

impl Capture {
    /// Reads a capture's text; `origin` names it in errors.
    ///
    /// # Errors
    ///
    /// [`CaptureError`] at the first line that is not a comment, `baud N`,
    /// or `>`/`<` followed by hex bytes.
    pub fn parse(text: &str, origin: &str) -> Result<Capture, CaptureError> {
        let mut entries = Vec::new();
        for (i, raw) in text.lines().enumerate() {
            let line = i + 1;
            let err = |why: String| CaptureError {
                origin: origin.to_owned(),
                line,
                why,
            };
            let body = raw.split('#').next().unwrap_or("").trim();
            if body.is_empty() {
                continue;
            }
            let bytes = |rest: &str| -> Result<Vec<u8>, CaptureError> {
                rest.split_whitespace()
                    .map(|b| {
                        u8::from_str_radix(b, 16)
                            .ok()
                            .filter(|_| b.len() == 2)
                            .ok_or_else(|| err(format!("`{b}` is not a hex byte like `FA`")))
                    })
                    .collect()
            };
            let entry = if let Some(rest) = body.strip_prefix('>') {
                Entry::ToDevice(bytes(rest)?)
            } else if let Some(rest) = body.strip_prefix('<') {
                Entry::FromDevice(bytes(rest)?)
            } else if let Some(rest) = body.strip_prefix("baud") {
                Entry::Baud(
                    rest.trim()
                        .parse()
                        .map_err(|_| err(format!("`{}` is not a baud rate", rest.trim())))?,
                )
            } else {
                return Err(err(format!(
                    "`{body}`: expected `> HEX` (driver to device), `< HEX` (device to driver) or `baud N`"
                )));
            };
            if matches!(&entry, Entry::ToDevice(b) | Entry::FromDevice(b) if b.is_empty()) {
                return Err(err("no bytes after the direction".into()));
            }
            entries.push((line, entry));
        }
        Ok(Capture { entries })
    }

    /// Reads the capture in file `path`.
    ///
    /// # Errors
    ///
    /// [`CaptureError`] for a file that cannot be read or parsed.
    pub fn load(path: &Path) -> Result<Capture, CaptureError> {
        let origin = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| CaptureError {
            origin: origin.clone(),
            line: 0,
            why: e.to_string(),
        })?;
        Capture::parse(&text, &origin)
    }

    /// The capture at `path`; when the environment sets `TROUPE_BLESS` (as
    /// for the golden files), `record` writes it afresh first, and the
    /// file's own notes (the comment lines heading it below the recorder's
    /// two: where its bytes come from) are kept.
    ///
    /// # Errors
    ///
    /// As [`Capture::load`].
    pub fn blessed(path: &Path, record: impl FnOnce(&Path)) -> Result<Capture, CaptureError> {
        if std::env::var_os("TROUPE_BLESS").is_some() {
            rerecord(path, record)?;
        }
        Capture::load(path)
    }

    /// The frames in the bytes the device sends, as `codec` cuts them.
    pub fn device_frames<C: Codec>(&self, codec: C) -> Vec<C::Frame> {
        let mut framer = Framer::new(codec);
        for bytes in self.from_device() {
            framer.push(bytes);
        }
        std::iter::from_fn(|| framer.next_frame()).collect()
    }

    /// The bytes the device sends, in order.
    pub fn from_device(&self) -> impl Iterator<Item = &[u8]> {
        self.entries.iter().filter_map(|(_, e)| match e {
            Entry::FromDevice(b) => Some(b.as_slice()),
            _ => None,
        })
    }
}

/// Lines the recorder writes at the head of a capture.
const RECORDER_HEAD: usize = 2;

/// Records the capture at `path` afresh with `record`, keeping the notes
/// that headed the old file below the recorder's own lines.
fn rerecord(path: &Path, record: impl FnOnce(&Path)) -> Result<(), CaptureError> {
    let notes: Vec<String> = std::fs::read_to_string(path)
        .map(|t| {
            t.lines()
                .take_while(|l| l.starts_with('#'))
                .skip(RECORDER_HEAD)
                .map(str::to_owned)
                .collect()
        })
        .unwrap_or_default();
    record(path);
    if notes.is_empty() {
        return Ok(());
    }
    let failed = |e: std::io::Error| CaptureError {
        origin: path.display().to_string(),
        line: 0,
        why: format!("keeping its notes: {e}"),
    };
    let text = std::fs::read_to_string(path).map_err(failed)?;
    let mut lines: Vec<&str> = text.lines().collect();
    let at = lines
        .iter()
        .take(RECORDER_HEAD)
        .take_while(|l| l.starts_with('#'))
        .count();
    lines.splice(at..at, notes.iter().map(String::as_str));
    std::fs::write(path, lines.join("\n") + "\n").map_err(failed)
}

/// Writes what crosses an emulated line to a capture file, as it happens.
#[derive(Debug)]
pub struct Recorder {
    out: std::io::BufWriter<std::fs::File>,
    baud: u32,
}

impl Recorder {
    /// Creates (or truncates) the capture file `path`, headed by `title`.
    ///
    /// # Errors
    ///
    /// When the file cannot be written.
    pub fn create(path: &Path, title: &str) -> std::io::Result<Recorder> {
        let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
        writeln!(out, "# {title}")?;
        writeln!(
            out,
            "# > driver to device, < device to driver (hex bytes); baud N: the line's rate"
        )?;
        Ok(Recorder { out, baud: 0 })
    }

    /// Records `bytes` crossing at `baud`, toward the device when `to_device`.
    pub fn record(&mut self, to_device: bool, bytes: &[u8], baud: u32) {
        if bytes.is_empty() {
            return;
        }
        let mut line = String::new();
        if baud != self.baud {
            self.baud = baud;
            line.push_str(&format!("baud {baud}\n"));
        }
        line.push_str(if to_device { "> " } else { "< " });
        line.push_str(&hex(bytes));
        line.push('\n');
        // A capture is a diagnostic: a full disk must not stop the device.
        if let Err(e) = self
            .out
            .write_all(line.as_bytes())
            .and_then(|()| self.out.flush())
        {
            tracing::warn!("capture not written: {e}");
        }
    }
}

/// How a replay went.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ReplayReport {
    /// Bytes the driver sent that the capture has.
    pub matched: usize,
}

/// How long the driver may take to send the next captured bytes.
const PATIENCE: Duration = Duration::from_secs(10);

/// Plays the device's side of `capture` at `link` until the capture ends
/// (then waits for `stop`): each `<` entry is sent once every `>` entry
/// before it has arrived, byte for byte, at the captured baud rate.
/// `linked` is called once the line can be opened.
///
/// # Errors
///
/// The first difference between what the driver sent and the capture (its
/// line, the bytes expected and the bytes seen), a wrong baud rate, a
/// driver that fell silent, or a pseudo-terminal that cannot be had.
pub fn replay(
    link: &Path,
    capture: &Capture,
    stop: &AtomicBool,
    linked: impl FnOnce(),
) -> std::io::Result<ReplayReport> {
    let mut pty = Pty::open()?;
    pty.link(link)?;
    linked();
    let mut report = ReplayReport::default();
    let mut baud = 9600;
    let mut buf = [0u8; 512];
    let mut pending: Vec<u8> = Vec::new();
    let mismatch = |line: usize, why: String| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("capture line {line}: {why}"),
        )
    };
    for (line, entry) in &capture.entries {
        match entry {
            Entry::Baud(b) => baud = *b,
            Entry::FromDevice(bytes) => pty.send(bytes)?,
            Entry::ToDevice(want) => {
                let deadline = Instant::now() + PATIENCE;
                while pending.len() < want.len() {
                    if stop.load(Ordering::Relaxed) || Instant::now() >= deadline {
                        return Err(mismatch(
                            *line,
                            format!(
                                "the driver sent [{}], the capture expects [{}]",
                                hex(&pending),
                                hex(want)
                            ),
                        ));
                    }
                    let n = pty.recv(&mut buf, Duration::from_millis(50))?;
                    if n > 0 && pty.line_baud() != baud {
                        return Err(mismatch(
                            *line,
                            format!(
                                "the driver sent [{}] at {} baud; the capture is at {baud}",
                                hex(&buf[..n]),
                                pty.line_baud()
                            ),
                        ));
                    }
                    pending.extend_from_slice(&buf[..n]);
                }
                let rest = pending.split_off(want.len());
                if pending != *want {
                    return Err(mismatch(
                        *line,
                        format!(
                            "the driver sent [{}], the capture has [{}]",
                            hex(&pending),
                            hex(want)
                        ),
                    ));
                }
                report.matched += want.len();
                pending = rest;
            }
        }
    }
    while !stop.load(Ordering::Relaxed) {
        pty.recv(&mut buf, Duration::from_millis(50))?;
    }
    Ok(report)
}

/// [`replay`] on a thread of its own (see [`Emulator`]), its device
/// linked in a directory named after `name`: for tests.
///
/// # Errors
///
/// The directory cannot be made, or the pseudo-terminal cannot be linked.
pub fn replay_on_thread(name: &str, capture: Capture) -> std::io::Result<Emulator<ReplayReport>> {
    Emulator::spawn(&format!("{name}-replay"), move |link, stop, linked| {
        replay(&link, &capture, stop, linked)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn captures_parse_and_say_where_they_are_wrong() {
        let c = Capture::parse(
            "# hi\nbaud 9600\n> FA FB 03 00 00 00\n\n< 01 02 # echo\n",
            "t",
        )
        .unwrap();
        assert_eq!(
            c.entries,
            vec![
                (2, Entry::Baud(9600)),
                (3, Entry::ToDevice(vec![0xFA, 0xFB, 3, 0, 0, 0])),
                (5, Entry::FromDevice(vec![1, 2])),
            ]
        );
        let e = Capture::parse("> FA\n< FAB\n", "x.txt").unwrap_err();
        assert_eq!(e.to_string(), "x.txt:2: `FAB` is not a hex byte like `FA`");
        let e = Capture::parse("baud fast\n", "x").unwrap_err();
        assert_eq!((e.line, e.why.as_str()), (1, "`fast` is not a baud rate"));
        assert!(Capture::parse("hello\n", "x")
            .unwrap_err()
            .why
            .contains("expected"));
        assert!(Capture::parse(">\n", "x").is_err());
    }

    #[test]
    fn a_recording_reads_back() {
        let path = std::env::temp_dir().join(format!("capture-{}.txt", std::process::id()));
        let mut r = Recorder::create(&path, "test").unwrap();
        r.record(true, &[0xFA, 0xFB], 9600);
        r.record(false, &[0x01], 9600);
        r.record(true, &[0x02], 38400);
        drop(r);
        let c = Capture::load(&path).unwrap();
        let _ = std::fs::remove_file(&path);
        let kinds: Vec<&Entry> = c.entries.iter().map(|(_, e)| e).collect();
        assert_eq!(
            kinds,
            vec![
                &Entry::Baud(9600),
                &Entry::ToDevice(vec![0xFA, 0xFB]),
                &Entry::FromDevice(vec![1]),
                &Entry::Baud(38400),
                &Entry::ToDevice(vec![2]),
            ]
        );
    }

    #[test]
    fn recording_afresh_keeps_the_notes_heading_the_file() {
        let path = std::env::temp_dir().join(format!("capture-notes-{}.txt", std::process::id()));
        let write = |p: &Path, byte: u8| {
            let mut r = Recorder::create(p, "test").unwrap();
            r.record(true, &[byte], 9600);
        };
        write(&path, 1);
        let old = std::fs::read_to_string(&path).unwrap();
        let mut lines: Vec<&str> = old.lines().collect();
        lines.insert(2, "# PROVENANCE: the manual, page 25");
        std::fs::write(&path, lines.join("\n") + "\n").unwrap();
        rerecord(&path, |p| write(p, 2)).unwrap();
        let new = std::fs::read_to_string(&path).unwrap();
        let _ = std::fs::remove_file(&path);
        let head: Vec<&str> = new.lines().take(4).collect();
        assert_eq!(head[2], "# PROVENANCE: the manual, page 25", "{new}");
        assert_eq!(head[0], "# test");
        assert_eq!(head[3], "baud 9600");
        assert!(new.contains("> 02") && !new.contains("> 01"), "{new}");
    }
}
