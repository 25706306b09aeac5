//! What the p2os line and replay tests share: an emulated Pioneer and the
//! driver's settings for it.

use std::path::{Path, PathBuf};

use troupe_p2os::device::Settings;
use troupe_p2os::emulator::{self, EmulatorOptions, EmulatorStats};
use troupe_serial::{Emulator, Faults, LineOptions};

/// An emulated p3dx-sh on a thread, its line linked in a directory of its
/// own, recording to `capture` if given.
pub fn emulate(name: &str, faults: Faults, capture: Option<PathBuf>) -> Emulator<EmulatorStats> {
    Emulator::spawn(&format!("p2os-{name}"), move |link, stop, linked| {
        let opts = EmulatorOptions {
            line: LineOptions {
                link,
                faults,
                seed: 2,
                capture,
            },
            subclass: "p3dx-sh".into(),
            name: "Troupe".into(),
        };
        emulator::run_with(&opts, &mut emulator::room(), stop, linked)
    })
    .expect("the emulator links its line")
}

/// Player's defaults, sonars on, for the robot at `link`.
pub fn settings(link: &Path) -> Settings {
    Settings::player_defaults(link.to_owned())
}
