//! `troupe emulate`: a device emulator on a pseudo-terminal.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use clap::{Args, ValueEnum};
use troupe_serial::Faults;

/// The devices Troupe can emulate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Emulated {
    /// A SICK LMS200 laser scanner in a room with a drifting pillar.
    Sicklms200,
    /// A Pioneer (ARCOS) robot with a sonar ring, in an 8 m × 6 m room.
    P2os,
    /// A Videre Erratic with sonars, floor IR and servos, in an 8 m × 6 m room.
    Erratic,
}

#[derive(Debug, Args)]
pub struct EmulateArgs {
    /// The device to play.
    pub device: Emulated,

    /// Where to put the device: a symlink to the pseudo-terminal, for a
    /// `.cfg` to name as its `port`. An old symlink there is replaced; any
    /// other file is left alone (and the emulator refuses to start).
    #[arg(long, value_name = "PATH")]
    pub link: PathBuf,

    /// Fault: probability of random bytes before each frame sent (line noise).
    #[arg(long, value_name = "P", default_value_t = 0.0)]
    pub noise: f64,
    /// Fault: probability of losing each byte sent.
    #[arg(long, value_name = "P", default_value_t = 0.0)]
    pub drop: f64,
    /// Fault: probability of one flipped bit in each frame sent (bad checksum).
    #[arg(long, value_name = "P", default_value_t = 0.0)]
    pub corrupt: f64,
    /// Fault: probability of cutting each frame sent short.
    #[arg(long, value_name = "P", default_value_t = 0.0)]
    pub truncate: f64,
    /// Fault: a device that never answers.
    #[arg(long)]
    pub mute: bool,
    /// Fault: unplug the device (close the line, remove the link) after SECS.
    #[arg(long, value_name = "SECS")]
    pub unplug_after: Option<f64>,
    /// Plug it back in (a fresh power-up) SECS after unplugging.
    #[arg(long, value_name = "SECS", requires = "unplug_after")]
    pub replug_after: Option<f64>,
    /// p2os: the robot's subclass (p3dx-sh, p3dx, p3at-sh, p3at, p2dx, p2de, p2at, amigo-sh, amigo).
    #[arg(long, default_value = "p3dx-sh")]
    pub subclass: String,
    /// erratic: the robot's revision ("Rev E", "Rev G" or "Rev H").
    #[arg(long, default_value = "Rev H")]
    pub revision: String,
    /// sicklms200: take the ranges from this laser of a running stack (a
    /// Stage robot's, say: `6665:laser:1`) instead of the built-in room,
    /// so the hardware path runs in a simulated world. Reached through the
    /// global --connect/--namespace flags.
    #[arg(long, value_name = "ADDR")]
    pub stage_laser: Option<troupe_msgs::DevAddr>,
    /// Seed of the fault generator (runs with the same seed fail alike).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

fn probability(name: &str, p: f64) -> anyhow::Result<f64> {
    anyhow::ensure!(
        (0.0..=1.0).contains(&p),
        "--{name} {p}: a probability is between 0 and 1"
    );
    Ok(p)
}

fn seconds(name: &str, s: Option<f64>) -> anyhow::Result<Option<Duration>> {
    s.map(|s| {
        Duration::try_from_secs_f64(s)
            .with_context(|| format!("--{name} {s}: give a number of seconds ≥ 0"))
    })
    .transpose()
}

/// `troupe emulate: DEVICE at PATH` on stdout, once the device can be
/// opened: what a script or test waits for.
fn banner(device: &str, link: &std::path::Path) {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "troupe emulate: {device} at {}", link.display());
    let _ = out.flush();
}

/// Ranges from a live laser device: each angle reads the nearest beam of
/// the latest scan (out of reach until the first scan arrives).
struct LiveLaser {
    _client: troupe_client::Client,
    laser: troupe_client::LaserProxy,
}

impl troupe_sicklms200::emulator::Scene for LiveLaser {
    fn ranges(&mut self, _t: f64, angles: &[f64]) -> Vec<f64> {
        let Some(scan) = self.laser.scan() else {
            return vec![f64::INFINITY; angles.len()];
        };
        let (min, res) = (f64::from(scan.min_angle), f64::from(scan.resolution));
        angles
            .iter()
            .map(|&a| {
                let i = if res > 0.0 {
                    ((a - min) / res).round()
                } else {
                    -1.0
                };
                match scan.ranges.get(i as usize) {
                    Some(&r) if i >= 0.0 && f64::from(r) < f64::from(scan.max_range) => {
                        f64::from(r)
                    }
                    _ => f64::INFINITY,
                }
            })
            .collect()
    }
}

/// Runs the emulator until SIGINT or SIGTERM.
pub fn run(a: EmulateArgs, z: &troupe_node::ZenohArgs) -> anyhow::Result<()> {
    let faults = Faults {
        noise: probability("noise", a.noise)?,
        drop: probability("drop", a.drop)?,
        corrupt: probability("corrupt", a.corrupt)?,
        truncate: probability("truncate", a.truncate)?,
        mute: a.mute,
        unplug_after: seconds("unplug-after", a.unplug_after)?,
        replug_after: seconds("replug-after", a.replug_after)?,
    };
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    std::thread::Builder::new()
        .name("signals".into())
        .spawn(move || {
            let _ = rt.block_on(crate::supervisor::wait_signal());
            flag.store(true, Ordering::Relaxed);
        })?;
    match a.device {
        Emulated::Sicklms200 => {
            use troupe_sicklms200::emulator;
            let opts = emulator::EmulatorOptions {
                link: a.link.clone(),
                faults,
                seed: a.seed,
            };
            let mut room = emulator::Room;
            let mut live;
            let scene: &mut dyn emulator::Scene = match &a.stage_laser {
                None => &mut room,
                Some(addr) => {
                    let dev = addr.device(troupe_msgs::DEFAULT_ROBOT);
                    let client = troupe_client::Client::connect(z, dev.robot)
                        .context("connecting to the stack for --stage-laser")?;
                    let laser = troupe_client::LaserProxy::new(&client, dev.index)
                        .with_context(|| format!("subscribing to {dev}"))?;
                    tracing::info!("ranges from {dev}");
                    live = LiveLaser {
                        _client: client,
                        laser,
                    };
                    &mut live
                }
            };
            emulator::run_with(&opts, scene, &stop, || {
                banner("sicklms200", &a.link);
                tracing::info!("{} emulated; Ctrl-C stops it", emulator::KIND);
            })
            .with_context(|| format!("emulating a sicklms200 at {}", a.link.display()))?;
        }
        Emulated::P2os => {
            use troupe_p2os::emulator;
            let opts = emulator::EmulatorOptions {
                link: a.link.clone(),
                faults,
                seed: a.seed,
                subclass: a.subclass.clone(),
                name: "Troupe".into(),
            };
            emulator::run_with(&opts, &stop, || {
                banner("p2os", &a.link);
                tracing::info!("a Pioneer {} emulated; Ctrl-C stops it", a.subclass);
            })
            .with_context(|| format!("emulating a p2os robot at {}", a.link.display()))?;
        }
        Emulated::Erratic => {
            use troupe_erratic::emulator;
            let opts = emulator::EmulatorOptions {
                link: a.link.clone(),
                faults,
                seed: a.seed,
                revision: a.revision.clone(),
            };
            emulator::run_with(&opts, &stop, || {
                banner("erratic", &a.link);
                tracing::info!("an Erratic {} emulated; Ctrl-C stops it", a.revision);
            })
            .with_context(|| format!("emulating an erratic at {}", a.link.display()))?;
        }
    }
    Ok(())
}
