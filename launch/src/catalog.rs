//! The drivers a launcher knows, by Player name: what it needs of each to
//! check and plan a `.cfg` (its options, its units, whether it is the
//! simulator) and to run it as a process of its own.
//!
//! The launcher does not link the drivers: whoever does (the `troupe`
//! binary links them all) hands it a [`Catalog`]. A driver that Player has
//! and Troupe does not is named in [`MISSING`], so a cfg naming it is told
//! what the driver was and what to use instead.

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

impl Entry {
    /// The entry of a [`Driver`], run by the node runtime.
    pub fn of<D: Driver>(about: &'static str) -> Entry {
        Entry {
            name: D::NAME,
            about,
            units: D::UNITS,
            clock_source: D::CLOCK_SOURCE,
            check: troupe_node::check::<D>,
            run: troupe_node::run::<D>,
        }
    }

    /// The entry of a driver that makes its process itself (a client of
    /// other servers, such as `passthrough`) rather than through the runtime.
    pub fn custom(
        name: &'static str,
        about: &'static str,
        check: fn(&Section) -> Result<Unused>,
        run: fn(Section, &ZenohArgs, &NodeConfig) -> Result<()>,
    ) -> Entry {
        Entry {
            name,
            about,
            units: &[],
            clock_source: false,
            check,
            run,
        }
    }
}

/// The drivers a launcher can start, in the order `troupe drivers` lists them.
pub struct Catalog {
    entries: Vec<Entry>,
}

impl Catalog {
    /// A catalog of these drivers.
    pub fn new(entries: Vec<Entry>) -> Catalog {
        Catalog { entries }
    }

    /// Every driver, in order.
    pub fn entries(&self) -> &[Entry] {
        &self.entries
    }

    /// The driver called `name`.
    pub fn find(&self, name: &str) -> Option<&Entry> {
        self.entries.iter().find(|e| e.name == name)
    }

    /// `dummy, rangertolaser, …` for messages.
    pub fn names(&self) -> String {
        let names: Vec<&str> = self.entries.iter().map(|e| e.name).collect();
        names.join(", ")
    }

    /// Why a cfg naming driver `name` cannot run, and what to do instead;
    /// `sections` follows the name (" (2 sections: lines 8, 17)", or "").
    pub fn unavailable(&self, name: &str, sections: &str) -> String {
        match MISSING.iter().find(|m| m.0 == name) {
            Some((_, about, instead)) => format!(
                "driver `{name}`{sections} is not available in Troupe {}",
                missing_about(about, instead)
            ),
            None => {
                let near = self
                    .entries
                    .iter()
                    .map(|e| (strsim::damerau_levenshtein(name, e.name), e.name))
                    .filter(|(d, n)| *d <= 2.max(n.len() / 4))
                    .min();
                let hint = near.map_or(String::new(), |(_, n)| format!(": did you mean `{n}`?"));
                format!(
                    "driver `{name}`{sections} is not available in Troupe{hint}; available: {}",
                    self.names()
                )
            }
        }
    }

    /// Runs driver `name` in this process until SIGINT/SIGTERM.
    ///
    /// # Errors
    ///
    /// No driver has that name, or the driver fails.
    pub fn run(
        &self,
        name: &str,
        section: Section,
        z: &ZenohArgs,
        cfg: &NodeConfig,
    ) -> anyhow::Result<()> {
        let Some(e) = self.find(name) else {
            anyhow::bail!("{}", self.unavailable(name, ""));
        };
        (e.run)(section, z, cfg)?;
        Ok(())
    }
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

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// The launcher's own tests plan with three real drivers: two small
    /// ones and the simulator (the plan's clock).
    pub(crate) fn catalog() -> Catalog {
        Catalog::new(vec![
            Entry::of::<troupe_dummy::Dummy>("fixed data"),
            Entry::of::<troupe_rangertolaser::RangerToLaser>("a ranger as a laser"),
            Entry::of::<troupe_stage::Stage>("the simulator"),
        ])
    }

    #[test]
    fn a_missing_driver_says_what_it_was_or_what_there_is() {
        let c = catalog();
        assert_eq!(c.names(), "dummy, rangertolaser, stage");
        assert!(c.find("stage").is_some_and(|e| e.clock_source));
        assert!(c.find("dummy").is_some_and(|e| !e.clock_source));
        assert_eq!(
            c.unavailable("lazer", ""),
            "driver `lazer` is not available in Troupe; available: dummy, rangertolaser, stage"
        );
        assert_eq!(
            c.unavailable("stagee", ""),
            "driver `stagee` is not available in Troupe: did you mean `stage`?; available: dummy, rangertolaser, stage"
        );
        assert_eq!(
            c.unavailable("festival", " (2 sections: lines 8, 17)"),
            "driver `festival` (2 sections: lines 8, 17) is not available in Troupe \
             (Player's: speech through the Festival synthesizer)"
        );
    }
}
