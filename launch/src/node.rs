//! `troupe node`: one driver as this process, its section from a `.cfg`
//! block (as `troupe launch` passes it) or from flags.

use std::path::Path;
use std::time::Duration;

use anyhow::Context;
use clap::Args;
use troupe_msgs::DevAddr;
use troupe_node::{NodeConfig, Section, ZenohArgs};

use crate::catalog::Catalog;

/// Flags of `troupe node`.
#[derive(Debug, Args)]
pub struct NodeArgs {
    /// The Player driver name (see `troupe drivers`).
    pub driver: String,

    /// The driver's section, as JSON text, a path to a JSON file, or `-`
    /// to read it from stdin.
    #[arg(long, value_name = "JSON|FILE|-")]
    pub section: Option<String>,

    /// A device this driver provides (repeatable), e.g. `laser:0`.
    #[arg(long, value_name = "ADDR")]
    pub provides: Vec<DevAddr>,

    /// A device this driver requires (repeatable), e.g. `odometry:::position2d:0`.
    #[arg(long, value_name = "ADDR")]
    pub requires: Vec<DevAddr>,

    /// An option, by Player's name (repeatable): `-o rate=20`, `-o pose=[0,0,0]`.
    #[arg(short = 'o', long = "option", value_name = "KEY=VALUE")]
    pub options: Vec<String>,

    /// Robot field (port) for addresses that give none, as `player -p PORT`.
    #[arg(short = 'p', long = "robot", value_name = "PORT")]
    pub robot: Option<u32>,

    /// The world file of the `stage` driver (sets its `worldfile` option).
    #[arg(long, value_name = "FILE")]
    pub world: Option<std::path::PathBuf>,

    /// With `stage`: write a PNG of the world when the node stops.
    #[arg(long, value_name = "FILE.png")]
    pub snapshot: Option<std::path::PathBuf>,

    /// Follow the simulator's clock (sim/clock) instead of wall time.
    #[arg(long)]
    pub sim_time: bool,

    /// Seconds to wait for each required device.
    #[arg(long, value_name = "SECS", default_value_t = 30.0, value_parser = troupe_node::args::seconds)]
    pub requires_timeout: f64,

    #[command(flatten)]
    pub ros2: troupe_node::Ros2Args,
}

/// `troupe node`: builds the section from flags and runs the driver.
pub fn run(a: NodeArgs, z: &ZenohArgs, catalog: &Catalog) -> anyhow::Result<()> {
    let mut section = match &a.section {
        None => Section::new(&a.driver),
        Some(s) => {
            let text = if s.trim_start().starts_with('{') {
                s.clone()
            } else if s == "-" {
                let mut text = String::new();
                std::io::Read::read_to_string(&mut std::io::stdin(), &mut text)
                    .context("reading the section from stdin")?;
                text
            } else {
                std::fs::read_to_string(Path::new(s))
                    .with_context(|| format!("reading section file {s}"))?
            };
            Section::from_json(&text)?
        }
    };
    if section.name != a.driver {
        anyhow::bail!(
            "the section is for driver `{}`, not `{}`",
            section.name,
            a.driver
        );
    }
    section.provides.extend(a.provides);
    section.requires.extend(a.requires);
    if let Some(r) = a.robot {
        section.robot = r;
    }
    if let Some(w) = &a.world {
        section
            .options
            .insert("worldfile".into(), w.display().to_string().into());
    }
    if let Some(p) = &a.snapshot {
        section
            .options
            .insert("snapshot".into(), p.display().to_string().into());
    }
    for o in &a.options {
        let (k, v) = o
            .split_once('=')
            .with_context(|| format!("option `{o}` is not KEY=VALUE"))?;
        let value = serde_json::from_str(v).unwrap_or_else(|_| serde_json::Value::String(v.into()));
        section.options.insert(k.to_owned(), value);
    }
    troupe_node::process::supervised()?;
    if !(a.requires_timeout.is_finite() && a.requires_timeout > 0.0) {
        anyhow::bail!("--requires-timeout must be a positive number of seconds");
    }
    let cfg = NodeConfig {
        sim_time: a.sim_time,
        requires_timeout: Duration::from_secs_f64(a.requires_timeout),
        ros2: a.ros2.config(None)?,
        spin: z.spin(),
    };
    catalog.run(&a.driver, section, z, &cfg)
}
