//! What the erratic line and replay tests share: an emulated Erratic and
//! the driver's settings for it.

use std::path::{Path, PathBuf};

use troupe_erratic::device::Settings;
use troupe_erratic::emulator::{self, EmulatorOptions, EmulatorStats};
use troupe_serial::{Emulator, Faults, LineOptions};

/// An emulated Rev H Erratic on a thread, its line linked in a directory of
/// its own, recording to `capture` if given.
pub fn emulate(name: &str, faults: Faults, capture: Option<PathBuf>) -> Emulator<EmulatorStats> {
    Emulator::spawn(&format!("erratic-{name}"), move |link, stop, linked| {
        let opts = EmulatorOptions {
            line: LineOptions {
                link,
                faults,
                seed: 3,
                capture,
            },
            revision: "Rev H".into(),
        };
        emulator::run_with(&opts, &mut emulator::room(), stop, linked)
    })
    .expect("the emulator links its line")
}

/// Player's defaults, sonars on, no settings written, for the robot at `link`.
pub fn settings(link: &Path) -> Settings {
    Settings {
        port: link.to_owned(),
        direct_wheel: true,
        max_speed: 500,
        max_turn: 100,
        sonar: true,
        analog: false,
        startup: Vec::new(),
    }
}
