//! The drivers this binary can run, by Player name.

use troupe_node::{Driver, NodeConfig, Result, Section, ZenohArgs};

/// A driver this build carries.
pub struct Entry {
    /// Player's name.
    pub name: &'static str,
    /// One line on what it does.
    pub about: &'static str,
    run: fn(Section, &ZenohArgs, &NodeConfig) -> Result<()>,
}

fn entry<D: Driver>(about: &'static str) -> Entry {
    Entry {
        name: D::NAME,
        about,
        run: troupe_node::run::<D>,
    }
}

/// Every driver of this build, by name.
pub fn all() -> Vec<Entry> {
    vec![
        entry::<troupe_dummy::Dummy>("fixed data at a fixed rate on many interfaces (testing)"),
        entry::<troupe_rangertolaser::RangerToLaser>("republishes a ranger as a laser"),
    ]
}

/// Runs driver `name` in this process until SIGINT/SIGTERM.
pub fn run(name: &str, section: Section, z: &ZenohArgs, cfg: &NodeConfig) -> anyhow::Result<()> {
    let all = all();
    let Some(e) = all.iter().find(|e| e.name == name) else {
        let names: Vec<&str> = all.iter().map(|e| e.name).collect();
        anyhow::bail!(
            "driver `{name}` is not available in Troupe; available: {}",
            names.join(", ")
        );
    };
    (e.run)(section, z, cfg)?;
    Ok(())
}
