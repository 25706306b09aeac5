//! The driver's line thread against a captured session: the device's side
//! of `tests/captures/rev-h.txt` is played back over a pseudo-terminal,
//! and the driver must send exactly the captured bytes, at the captured
//! baud rates, and pass on every captured motor packet.
//!
//! The capture was recorded from Troupe's emulated Erratic (no capture of
//! a real one is available); `TROUPE_BLESS=1` records it afresh.
#![allow(clippy::unwrap_used)] // test helpers outside #[test] fns

mod common;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use common::{emulate, settings};
use troupe_erratic::device::{self, Order, Update};
use troupe_erratic::packet::PacketCodec;
use troupe_node::Waker;
use troupe_serial::capture::{self, Capture};
use troupe_serial::Faults;

/// Motor packets the session runs for (under the driver's 1 s PULSE).
const MOTOR: usize = 5;

fn capture_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/captures/rev-h.txt")
}

fn is_motor(p: &[u8]) -> bool {
    matches!(p.first(), Some(0x80..=0x8F))
}

/// The robot's name, class and subclass (or type and revision).
type Names = (String, String, String);

/// What the driver made of a session: the robot's names, then its motor packets.
fn session(link: &Path) -> Result<(Names, Vec<Vec<u8>>), String> {
    let line = device::spawn(settings(link), Waker::none()).unwrap();
    let deadline = Instant::now() + Duration::from_secs(20);
    let (mut name, mut motor) = (None, Vec::new());
    while motor.len() < MOTOR {
        let left = deadline.saturating_duration_since(Instant::now());
        match line.updates().recv_timeout(left) {
            Ok(Update::Ready { name: n, .. }) => name = Some(n),
            Ok(Update::Packet(p)) if is_motor(&p) => motor.push(p),
            Ok(Update::Packet(_)) => {}
            Ok(u) => {
                line.stop(Order::Stop);
                return Err(format!("unexpected {u:?}"));
            }
            Err(e) => {
                line.stop(Order::Stop);
                return Err(format!("{} motor packets within 20 s: {e}", motor.len()));
            }
        }
    }
    line.stop(Order::Stop);
    Ok((name.unwrap(), motor))
}

fn record(path: &Path) {
    let emu = emulate("record", Faults::default(), Some(path.to_owned()));
    session(emu.link()).unwrap();
    emu.stop().unwrap();
}

#[test]
fn a_captured_erratic_session_replays_byte_for_byte() {
    let cap = Capture::blessed(&capture_path(), record).unwrap();
    let captured: Vec<Vec<u8>> = cap
        .device_frames(PacketCodec)
        .into_iter()
        .filter(|d| is_motor(d))
        .collect();
    assert!(captured.len() >= MOTOR, "{} captured", captured.len());

    let emu = capture::replay_on_thread("erratic", cap).unwrap();
    let outcome = session(emu.link());
    // The replay ends well only once every entry of the capture was played
    // and every byte it expects was matched; a difference ends it with an
    // error that says where.
    emu.stop().unwrap();
    let (name, motor) = outcome.unwrap();
    assert_eq!(name.2, "Rev H", "{name:?}");
    assert_eq!(
        motor[..],
        captured[..MOTOR],
        "the motor packets, as captured"
    );
}
