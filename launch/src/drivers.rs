//! The drivers this binary can run, by Player name.

use troupe_node::{Driver, NodeConfig, Result, Section, Unit, Unused, ZenohArgs};

/// A driver this build carries.
pub struct Entry {
    /// Player's name.
    pub name: &'static str,
    /// One line on what it does.
    pub about: &'static str,
    /// Options read as lengths or angles.
    pub units: &'static [(&'static str, Unit)],
    /// The simulator: other nodes of its plan follow its clock.
    pub clock_source: bool,
    /// Checks a section without starting anything; returns what it gives
    /// that the driver does not use.
    pub check: fn(&Section) -> Result<Unused>,
    run: fn(Section, &ZenohArgs, &NodeConfig) -> Result<()>,
}

fn entry<D: Driver>(about: &'static str) -> Entry {
    Entry {
        name: D::NAME,
        about,
        units: D::UNITS,
        clock_source: D::CLOCK_SOURCE,
        check: troupe_node::check::<D>,
        run: troupe_node::run::<D>,
    }
}

/// Every driver of this build, by name.
pub fn all() -> Vec<Entry> {
    vec![
        entry::<troupe_dummy::Dummy>("fixed data at a fixed rate on many interfaces (testing)"),
        entry::<troupe_rangertolaser::RangerToLaser>("republishes a ranger as a laser"),
        entry::<troupe_amcl::Amcl>("adaptive Monte Carlo localization on a map (odometry + laser)"),
        entry::<troupe_mapfile::MapFile>("serves an occupancy map read from an image"),
        entry::<troupe_mapfile::MapScale>("a map device's map at another resolution"),
        entry::<troupe_mapfile::MapCspace>(
            "a map device's map with obstacles grown by the robot's radius",
        ),
        entry::<troupe_vfh::Vfh>(
            "VFH+ obstacle avoidance: velocity and goto commands past obstacles",
        ),
        entry::<troupe_nd::Nd>(
            "Nearness Diagram navigation: goals reached through narrow gaps and clutter",
        ),
        entry::<troupe_wavefront::Wavefront>(
            "global path planner feeding waypoints to a position2d",
        ),
        entry::<troupe_sicklms200::SickLms200>("the SICK LMS200 laser over a serial line"),
        entry::<troupe_urglaser::UrgLaser>(
            "the Hokuyo URG-04LX laser over RS-232 or USB (SCIP 1.1 and 2.0)",
        ),
        entry::<troupe_p2os::P2os>("Pioneer robots (P2OS/ARCOS) over a serial line"),
        entry::<troupe_erratic::Erratic>("the Videre Erratic robot over a serial line"),
        entry::<troupe_log::WriteLog>("writes its required devices' data to a Player text log"),
        entry::<troupe_log::ReadLog>(
            "replays a Player text log as live devices, and is its stack's clock",
        ),
        entry::<troupe_stage::Stage>(
            "the 2D multi-robot simulator: a Stage world's robots and sensors",
        ),
        Entry {
            name: "passthrough",
            about: "devices of a Player server, or of another robot, served as this robot's own",
            units: &[],
            clock_source: false,
            check: crate::passthrough::check,
            run: crate::passthrough::run,
        },
    ]
}

/// The driver called `name`.
pub fn find(name: &str) -> Option<Entry> {
    all().into_iter().find(|e| e.name == name)
}

/// `dummy, rangertolaser, …` for messages.
pub fn names() -> String {
    all().iter().map(|e| e.name).collect::<Vec<_>>().join(", ")
}

/// Player drivers that Player's and Stage's sample files name and Troupe
/// does not have: the name, what the driver is in Player, and what to use
/// instead where Troupe has something.
pub const MISSING: &[(&str, &str, &str)] = &[
    (
        "p2os_position",
        "Player 1's name for a Pioneer's base",
        "use `p2os`, which provides position2d and the rest of the robot",
    ),
    (
        "rflex",
        "RWI and iRobot robots on the rFLEX controller (B21r, ATRV, Magellan)",
        "",
    ),
    ("wbr914", "White Box Robotics' 914 PC-Bot", ""),
    (
        "cameracompress",
        "compresses a camera's images to JPEG",
        "Troupe has no camera interface yet",
    ),
    ("ptu46", "the Directed Perception PTU-46 pan-tilt unit", ""),
    ("linuxwifi", "Linux wireless link statistics", ""),
    ("festival", "speech through the Festival synthesizer", ""),
    ("bumper_safe", "stops a base whose bumpers are pressed", ""),
];

/// What a driver in [`MISSING`] is: "(Player's: …); what to use instead".
pub fn missing_about(about: &str, instead: &str) -> String {
    if instead.is_empty() {
        format!("(Player's: {about})")
    } else {
        format!("(Player's: {about}); {instead}")
    }
}

/// Why a cfg naming driver `name` cannot run, and what to do instead;
/// `sections` follows the name (" (2 sections: lines 8, 17)", or "").
pub fn unavailable(name: &str, sections: &str) -> String {
    match MISSING.iter().find(|m| m.0 == name) {
        Some((_, about, instead)) => format!(
            "driver `{name}`{sections} is not available in Troupe {}",
            missing_about(about, instead)
        ),
        None => format!(
            "driver `{name}`{sections} is not available in Troupe; available: {}",
            names()
        ),
    }
}

/// Runs driver `name` in this process until SIGINT/SIGTERM.
pub fn run(name: &str, section: Section, z: &ZenohArgs, cfg: &NodeConfig) -> anyhow::Result<()> {
    let Some(e) = find(name) else {
        anyhow::bail!("{}", unavailable(name, ""));
    };
    (e.run)(section, z, cfg)?;
    Ok(())
}
