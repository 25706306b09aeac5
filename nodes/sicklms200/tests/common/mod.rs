//! What the sicklms200 line and replay tests share: an emulated scanner
//! and the driver's settings for it.

use std::path::{Path, PathBuf};

use troupe_geom::Room;
use troupe_serial::{Emulator, Faults, LineOptions};
use troupe_sicklms200::device::Settings;
use troupe_sicklms200::emulator::{self, EmulatorStats};

/// An emulated scanner in its room on a thread, its line linked in a
/// directory of its own, recording to `capture` if given.
pub fn emulate(name: &str, faults: Faults, capture: Option<PathBuf>) -> Emulator<EmulatorStats> {
    Emulator::spawn(&format!("lms-{name}"), move |link, stop, linked| {
        let opts = LineOptions {
            link,
            faults,
            seed: 1,
            capture,
        };
        emulator::run_with(&opts, &mut Room, stop, linked)
    })
    .expect("the emulator links its line")
}

/// Player's connect rates and a 180° scan at `res` hundredths of a degree,
/// in millimetres with intensity, streamed at `transfer` baud.
pub fn settings(link: &Path, res: u16, transfer: u32) -> Settings {
    Settings::scan_180(link.to_owned(), res, transfer)
}
