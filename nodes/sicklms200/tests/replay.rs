//! The driver's line thread against a captured session: the scanner's side
//! of `tests/captures/lms200-38400.txt` is played back over a
//! pseudo-terminal, and the driver must send exactly the captured
//! telegrams, at the captured baud rates (9600, then 38400), and decode
//! every captured scan.
//!
//! The capture was recorded from Troupe's emulated LMS200 (no capture of a
//! real one is available); `TROUPE_BLESS=1` records it afresh.
#![allow(clippy::unwrap_used)] // test helpers outside #[test] fns

mod common;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use common::{emulate, settings};
use troupe_node::Waker;
use troupe_serial::capture::{self, Capture, Entry};
use troupe_serial::Faults;
use troupe_sicklms200::device::{self, Order, Update};
use troupe_sicklms200::telegram::RawScan;

/// Scans the session runs for.
const SCANS: usize = 5;

fn capture_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/captures/lms200-38400.txt")
}

/// What the driver made of a session: the scanner's type and baud, then its scans.
fn session(link: &Path) -> Result<((String, u32), Vec<RawScan>), String> {
    let line = device::spawn(settings(link, 100, 38400), Waker::none()).unwrap();
    let deadline = Instant::now() + Duration::from_secs(30);
    let (mut ready, mut scans) = (None, Vec::new());
    while scans.len() < SCANS {
        let left = deadline.saturating_duration_since(Instant::now());
        match line.updates().recv_timeout(left) {
            Ok(Update::Ready { kind, baud }) => ready = Some((kind, baud)),
            Ok(Update::Scan(s, _)) => scans.push(s),
            Ok(u) => {
                line.stop(Order::Stop);
                return Err(format!("unexpected {u:?}"));
            }
            Err(e) => {
                line.stop(Order::Stop);
                return Err(format!("{} scans within 30 s: {e}", scans.len()));
            }
        }
    }
    line.stop(Order::Stop);
    Ok((ready.unwrap(), scans))
}

fn record(path: &Path) {
    let emu = emulate("record", Faults::default(), Some(path.to_owned()));
    session(emu.link()).unwrap();
    emu.stop().unwrap();
}

#[test]
fn a_captured_lms200_session_replays_byte_for_byte() {
    let cap = Capture::blessed(&capture_path(), record).unwrap();
    let bauds: Vec<u32> = cap
        .entries
        .iter()
        .filter_map(|(_, e)| match e {
            Entry::Baud(b) => Some(*b),
            _ => None,
        })
        .collect();
    assert_eq!(bauds, [9600, 38400], "the capture switches rate once");

    let emu = capture::replay_on_thread("lms", cap).unwrap();
    let outcome = session(emu.link());
    // The replay ends well only once every entry of the capture was played
    // and every byte it expects was matched; a difference ends it with an
    // error that says where.
    emu.stop().unwrap();
    let ((kind, baud), scans) = outcome.unwrap();
    assert_eq!(baud, 38400);
    assert!(kind.starts_with("LMS200"), "{kind}");
    assert!(scans.iter().all(|s| s.values.len() == 181 && s.units == 1));
}
