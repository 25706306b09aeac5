//! The driver's line thread against a captured session: the device's side
//! of `tests/captures/p3dx-sh.txt` is played back over a pseudo-terminal,
//! and the driver must send exactly the captured bytes, at the captured
//! baud rates, and decode every captured SIP.
//!
//! The capture was recorded from Troupe's emulated Pioneer (no capture of
//! a real one is available); `TROUPE_BLESS=1` records it afresh.
#![allow(clippy::unwrap_used)] // test helpers outside #[test] fns

mod common;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use common::{emulate, settings};
use troupe_node::Waker;
use troupe_p2os::device::{self, Order, Update};
use troupe_p2os::packet::{PacketCodec, Sip};
use troupe_serial::capture::{self, Capture};
use troupe_serial::Faults;

/// SIPs the session runs for.
const SIPS: usize = 10;

fn capture_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/captures/p3dx-sh.txt")
}

/// The robot's name, class and subclass (or type and revision).
type Names = (String, String, String);

/// What the driver made of a session: the robot's names, then its SIPs.
fn session(link: &Path) -> Result<(Names, Vec<Sip>), String> {
    let line = device::spawn(settings(link), Waker::none()).unwrap();
    let deadline = Instant::now() + Duration::from_secs(20);
    let (mut name, mut sips) = (None, Vec::new());
    while sips.len() < SIPS {
        let left = deadline.saturating_duration_since(Instant::now());
        match line.updates().recv_timeout(left) {
            Ok(Update::Ready { name: n, .. }) => name = Some(n),
            Ok(Update::Sip(s)) => sips.push(s),
            Ok(u) => {
                line.stop(Order::Stop);
                return Err(format!("unexpected {u:?}"));
            }
            Err(e) => {
                line.stop(Order::Stop);
                return Err(format!("{} SIPs within 20 s: {e}", sips.len()));
            }
        }
    }
    line.stop(Order::Stop);
    Ok((name.unwrap(), sips))
}

/// Records the capture from the emulated robot.
fn record(path: &Path) {
    let emu = emulate("record", Faults::default(), Some(path.to_owned()));
    session(emu.link()).unwrap();
    emu.stop().unwrap();
}

#[test]
fn a_captured_pioneer_session_replays_byte_for_byte() {
    let cap = Capture::blessed(&capture_path(), record).unwrap();
    // The SIPs in the capture, decoded here independently of the driver.
    let captured: Vec<Sip> = cap
        .device_frames(PacketCodec)
        .into_iter()
        .filter(|d| Sip::is_standard(d))
        .map(|d| Sip::decode(&d).unwrap())
        .collect();
    assert!(captured.len() >= SIPS, "{} SIPs captured", captured.len());

    let emu = capture::replay_on_thread("p2os", cap).unwrap();
    let outcome = session(emu.link());
    // The replay ends well only once every entry of the capture was played
    // and every byte it expects was matched; a difference ends it with an
    // error that says where.
    let report = emu.stop().unwrap();
    let (name, sips) = outcome.unwrap();
    assert_eq!(
        (name.0.as_str(), name.1.as_str(), name.2.as_str()),
        ("Troupe", "Pioneer", "p3dx-sh")
    );
    assert_eq!(sips[..], captured[..SIPS], "the SIPs, decoded as captured");
    // SYNC0, SYNC1, SYNC2, OPEN, PULSE and SONAR: 6 + 6 + 6 + 6 + 6 + 9.
    assert_eq!(report.matched, 39, "{report:?}");
}
