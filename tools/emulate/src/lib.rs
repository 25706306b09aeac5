//! `troupe emulate`: a device emulator on a pseudo-terminal.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;
use clap::{Args, ValueEnum};
use troupe_serial::{Faults, LineOptions};

/// The devices Troupe can emulate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Emulated {
    /// A SICK LMS200 laser scanner in a room with a drifting pillar.
    Sicklms200,
    /// A Hokuyo URG-04LX laser scanner (SCIP 1.1 and 2.0) in the same room.
    Urglaser,
    /// A Pioneer (ARCOS) robot with a sonar ring, in an 8 m × 6 m room.
    P2os,
    /// A Videre Erratic with sonars, floor IR and servos, in an 8 m × 6 m room.
    Erratic,
    /// White Box Robotics' 914: its M3 board's motion chips, IR and I/O, in the same room.
    Wbr914,
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
    #[arg(long, value_name = "P", default_value_t = 0.0, value_parser = troupe_node::args::finite)]
    pub noise: f64,
    /// Fault: probability of losing each byte sent.
    #[arg(long, value_name = "P", default_value_t = 0.0, value_parser = troupe_node::args::finite)]
    pub drop: f64,
    /// Fault: probability of one flipped bit in each frame sent (bad checksum).
    #[arg(long, value_name = "P", default_value_t = 0.0, value_parser = troupe_node::args::finite)]
    pub corrupt: f64,
    /// Fault: probability of cutting each frame sent short.
    #[arg(long, value_name = "P", default_value_t = 0.0, value_parser = troupe_node::args::finite)]
    pub truncate: f64,
    /// Fault: a device that never answers.
    #[arg(long)]
    pub mute: bool,
    /// Fault: unplug the device (close the line, remove the link) after SECS.
    #[arg(long, value_name = "SECS", value_parser = troupe_node::args::seconds)]
    pub unplug_after: Option<f64>,
    /// Plug it back in (a fresh power-up) SECS after unplugging.
    #[arg(long, value_name = "SECS", requires = "unplug_after", value_parser = troupe_node::args::seconds)]
    pub replug_after: Option<f64>,
    /// p2os: the robot's subclass (p3dx-sh, p3dx, p3at-sh, p3at, p2dx, p2de, p2at, amigo-sh, amigo).
    #[arg(long, default_value = "p3dx-sh")]
    pub subclass: String,
    /// erratic: the robot's revision ("Rev E", "Rev G" or "Rev H").
    #[arg(long, default_value = "Rev H")]
    pub revision: String,
    /// urglaser: the URG is on USB, not RS-232: it answers at any baud
    /// rate, at USB's speed (a cfg's `use_serial 0`).
    #[arg(long)]
    pub usb: bool,
    /// sicklms200, urglaser: take the ranges from this laser of a running stack (a
    /// Stage robot's, say: `6665:laser:1`) instead of the built-in room,
    /// so the hardware path runs in a simulated world. Reached through the
    /// global --connect/--namespace flags.
    #[arg(long, value_name = "ADDR")]
    pub stage_laser: Option<troupe_msgs::DevAddr>,
    /// Be part of this model of a running Stage simulation instead of the
    /// built-in room. p2os, erratic, wbr914: wheel commands drive the model's
    /// position2d, odometry and stall come from it, and the sonars (the
    /// 914's IR) read its sonar (or first ranger) device. sicklms200: the ranges are the
    /// model's laser (or its widest ranger); urglaser: the same. The model's devices are found
    /// through --stage-sim. Reached through the global --connect/--namespace flags.
    #[arg(long, value_name = "MODEL", conflicts_with = "stage_laser")]
    pub stage_model: Option<String>,
    /// The simulation device that knows --stage-model's devices.
    #[arg(long, value_name = "ADDR", default_value = "simulation:0")]
    pub stage_sim: troupe_msgs::DevAddr,
    /// Write what crosses the line, both ways, to FILE: `> HEX` from the
    /// driver, `< HEX` from the device, `baud N` at each rate change. A
    /// capture is a transcript that replay tests play back to a driver.
    #[arg(long, value_name = "FILE")]
    pub capture: Option<PathBuf>,
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
    laser: troupe_client::LaserProxy,
}

impl troupe_geom::Scene for LiveLaser {
    fn ranges(&mut self, _t: f64, angles: &[f64]) -> Vec<f64> {
        let Some(scan) = self.laser.scan() else {
            return vec![f64::INFINITY; angles.len()];
        };
        nearest_beams(
            angles,
            f64::from(scan.min_angle),
            f64::from(scan.resolution),
            f64::from(scan.max_range),
            &scan.ranges,
        )
    }
}

/// For each of `angles`, the range of the nearest of `ranges` (beams
/// `step` apart from `min`), or infinity where that is out of reach or
/// there is no such beam.
fn nearest_beams<R: Copy + Into<f64>>(
    angles: &[f64],
    min: f64,
    step: f64,
    max_range: f64,
    ranges: &[R],
) -> Vec<f64> {
    angles
        .iter()
        .map(|&a| {
            let i = if step > 0.0 {
                ((a - min) / step).round()
            } else {
                -1.0
            };
            match ranges.get(i as usize).map(|&r| r.into()) {
                Some(r) if i >= 0.0 && r < max_range => r,
                _ => f64::INFINITY,
            }
        })
        .collect()
}

/// A robot body that is a Stage model: the emulator's wheel commands go
/// to the model's position2d, its odometry and stall come back from it,
/// and sonar `i` reads range `i` of the model's sonar or ranger device.
struct StageBody {
    position: troupe_client::Position2dProxy,
    sonar: Option<Ranges>,
    /// The command last sent, so only changes go out.
    sent: Option<(f64, f64)>,
    /// Where odometry was last reset, in the model's odometry frame.
    origin: troupe_geom::Pose,
}

/// Where a Stage-backed body reads its sonars.
enum Ranges {
    Sonar(troupe_client::SonarProxy),
    Ranger(troupe_client::RangerProxy),
}

/// The devices a running Stage serves for one model, found by its name
/// through a simulation device, and a client per robot port to reach them
/// (each proxy keeps its own client alive).
struct ModelDevices {
    model: String,
    devices: Vec<troupe_msgs::Device>,
    /// The session every client here shares, and a client per robot.
    session: troupe_node::zenoh::Session,
    clients: Vec<troupe_client::Client>,
}

impl ModelDevices {
    /// Asks the simulation device `sim` for `model`'s devices.
    fn find(
        z: &troupe_node::ZenohArgs,
        model: &str,
        sim: &troupe_msgs::DevAddr,
    ) -> anyhow::Result<Self> {
        use troupe_msgs::simulation::Value;
        let sim = sim.device(troupe_msgs::DEFAULT_ROBOT);
        let client = troupe_client::Client::connect(z, sim.robot)
            .context("connecting to the stack for --stage-model")?;
        let listed = troupe_client::SimulationProxy::new(&client, sim.index)
            .get_property(model, "devices")
            .with_context(|| {
                format!("asking {sim} for the devices of model `{model}` (is the Stage stack running, with {sim} provided?)")
            })?;
        let Value::Text(listed) = listed else {
            anyhow::bail!("{sim} answered the devices of `{model}` with {listed:?}, not a list");
        };
        let devices = listed
            .split_whitespace()
            .map(|d| Ok(d.parse::<troupe_msgs::DevAddr>()?.device(sim.robot)))
            .collect::<anyhow::Result<_>>()?;
        Ok(ModelDevices {
            model: model.to_owned(),
            devices,
            session: client.session().clone(),
            clients: vec![client],
        })
    }

    /// The model's devices of interface `i`, in the stack's order.
    fn of(&self, i: troupe_msgs::Interface) -> Vec<troupe_msgs::Device> {
        self.devices
            .iter()
            .filter(|d| d.interface == i)
            .copied()
            .collect()
    }

    /// An error naming what the model does serve, for when `what` is missing.
    fn missing(&self, what: &str) -> anyhow::Error {
        let list: Vec<String> = self.devices.iter().map(ToString::to_string).collect();
        anyhow::anyhow!(
            "the Stage stack serves no {what} of model `{}` (it serves: {}); give the model's section one",
            self.model,
            if list.is_empty() { "nothing".into() } else { list.join(" ") }
        )
    }

    /// A client of robot (port) `robot`, on the session `find` opened.
    fn client(&mut self, robot: u32) -> troupe_client::Client {
        if let Some(c) = self.clients.iter().find(|c| c.robot() == robot) {
            return c.clone();
        }
        let c = troupe_client::Client::with_session(self.session.clone(), robot);
        self.clients.push(c.clone());
        c
    }
}

impl StageBody {
    /// Finds `model`'s devices through the simulation device `sim` and
    /// subscribes to them.
    fn connect(
        z: &troupe_node::ZenohArgs,
        model: &str,
        sim: &troupe_msgs::DevAddr,
    ) -> anyhow::Result<Self> {
        use troupe_msgs::Interface;
        let mut found = ModelDevices::find(z, model, sim)?;
        let first = |i: Interface| found.of(i).first().copied();
        let Some(pos) = first(Interface::Position2d) else {
            return Err(found.missing("position2d"));
        };
        let (sonar_dev, ranger_dev) = (first(Interface::Sonar), first(Interface::Ranger));
        let mut client_of = |robot: u32| found.client(robot);
        let position = troupe_client::Position2dProxy::new(&client_of(pos.robot), pos.index)?;
        let sonar = match (sonar_dev, ranger_dev) {
            (Some(d), _) => Some(Ranges::Sonar(troupe_client::SonarProxy::new(
                &client_of(d.robot),
                d.index,
            )?)),
            (None, Some(d)) => Some(Ranges::Ranger(troupe_client::RangerProxy::new(
                &client_of(d.robot),
                d.index,
            )?)),
            (None, None) => None,
        };
        tracing::info!(
            "model `{model}`: driving {pos}; sonars from {}",
            sonar_dev
                .or(ranger_dev)
                .map_or("nowhere (they read out of range)".into(), |d| d.to_string())
        );
        Ok(StageBody {
            position,
            sonar,
            sent: None,
            origin: troupe_geom::Pose::default(),
        })
    }

    fn pose(&self) -> troupe_geom::Pose {
        self.position
            .data()
            .map(|d| d.pose.into())
            .unwrap_or_default()
    }
}

impl troupe_geom::Body for StageBody {
    fn drive(&mut self, v: f64, w: f64, _dt: f64) {
        if self.sent != Some((v, w)) {
            match self.position.set_speed(v, w) {
                Ok(()) => self.sent = Some((v, w)),
                Err(e) => tracing::warn!("driving {}: {e}", self.position.device()),
            }
        }
    }

    fn odometry(&self) -> troupe_geom::Pose {
        self.origin.inverse().compose(&self.pose())
    }

    fn reset_odometry(&mut self) {
        self.origin = self.pose();
    }

    fn stalled(&self) -> bool {
        self.position.stall()
    }

    fn range(&mut self, index: usize, _sensor: troupe_geom::Pose, max: f64) -> f64 {
        let r = match &self.sonar {
            Some(Ranges::Sonar(s)) => s.range(index),
            Some(Ranges::Ranger(r)) => r.range(index),
            None => None,
        };
        r.unwrap_or(max).min(max)
    }
}

/// The body of an emulated robot: a Stage model, or the built-in room.
fn body(
    a: &EmulateArgs,
    z: &troupe_node::ZenohArgs,
    room: troupe_geom::DiffDrive,
) -> anyhow::Result<Box<dyn troupe_geom::Body>> {
    Ok(match &a.stage_model {
        Some(model) => Box::new(StageBody::connect(z, model, &a.stage_sim)?),
        None => Box::new(room),
    })
}

/// Ranges from a live ranger device (a Stage laser served as a ranger):
/// each angle reads the nearest beam of the latest ranges, the beams
/// spread evenly over the configured fov.
struct LiveRanger {
    ranger: troupe_client::RangerProxy,
    config: troupe_msgs::ranger::Config,
}

impl troupe_geom::Scene for LiveRanger {
    fn ranges(&mut self, _t: f64, angles: &[f64]) -> Vec<f64> {
        let ranges = self.ranger.ranges();
        let c = &self.config;
        // Stage's `angular_res` is fov/samples; its beams are fov/(samples − 1) apart.
        let step = (c.max_angle - c.min_angle) / (ranges.len().max(2) - 1) as f64;
        nearest_beams(angles, c.min_angle, step, c.max_range, &ranges)
    }
}

/// What the emulated LMS200 sees: a running stack's laser (`--stage-laser`),
/// a Stage model's laser or widest ranger (`--stage-model`), or the room.
fn laser_scene(
    a: &EmulateArgs,
    z: &troupe_node::ZenohArgs,
) -> anyhow::Result<Box<dyn troupe_geom::Scene>> {
    use troupe_msgs::Interface;
    let laser = |client: &troupe_client::Client, dev: troupe_msgs::Device| {
        let laser = troupe_client::LaserProxy::new(client, dev.index)
            .with_context(|| format!("subscribing to {dev}"))?;
        tracing::info!("ranges from {dev}");
        Ok::<_, anyhow::Error>(Box::new(LiveLaser { laser }))
    };
    if let Some(addr) = &a.stage_laser {
        let dev = addr.device(troupe_msgs::DEFAULT_ROBOT);
        let client = troupe_client::Client::connect(z, dev.robot)
            .context("connecting to the stack for --stage-laser")?;
        return Ok(laser(&client, dev)?);
    }
    let Some(model) = &a.stage_model else {
        return Ok(Box::new(troupe_geom::Room));
    };
    let mut found = ModelDevices::find(z, model, &a.stage_sim)?;
    if let Some(&dev) = found.of(Interface::Laser).first() {
        let client = found.client(dev.robot);
        return Ok(laser(&client, dev)?);
    }
    // The laser among the model's rangers: the widest field of view.
    let mut best: Option<(troupe_client::RangerProxy, troupe_msgs::ranger::Config)> = None;
    for dev in found.of(Interface::Ranger) {
        let ranger = troupe_client::RangerProxy::new(&found.client(dev.robot), dev.index)?;
        let config = ranger
            .request_config()
            .with_context(|| format!("asking {dev} for its configuration"))?;
        let fov = |c: &troupe_msgs::ranger::Config| c.max_angle - c.min_angle;
        if best.as_ref().is_none_or(|(_, b)| fov(&config) > fov(b)) {
            tracing::info!("ranges from {dev}");
            best = Some((ranger, config));
        }
    }
    let Some((ranger, config)) = best else {
        return Err(found.missing("laser or ranger"));
    };
    Ok(Box::new(LiveRanger { ranger, config }))
}

/// Runs the emulator until SIGINT or SIGTERM.
pub fn run(a: EmulateArgs, z: &troupe_node::ZenohArgs) -> anyhow::Result<()> {
    let line = LineOptions {
        link: a.link.clone(),
        faults: Faults {
            noise: probability("noise", a.noise)?,
            drop: probability("drop", a.drop)?,
            corrupt: probability("corrupt", a.corrupt)?,
            truncate: probability("truncate", a.truncate)?,
            mute: a.mute,
            unplug_after: seconds("unplug-after", a.unplug_after)?,
            replug_after: seconds("replug-after", a.replug_after)?,
        },
        seed: a.seed,
        capture: a.capture.clone(),
    };
    let laser = matches!(a.device, Emulated::Sicklms200 | Emulated::Urglaser);
    if !laser && a.stage_laser.is_some() {
        anyhow::bail!("--stage-laser is for a laser (sicklms200, urglaser); a robot is backed by a Stage model with --stage-model NAME");
    }
    if a.usb && a.device != Emulated::Urglaser {
        anyhow::bail!("--usb is for a urglaser: the other devices are on RS-232");
    }
    let stop = troupe_node::process::stop_flag().context("catching Ctrl-C and SIGTERM")?;
    match a.device {
        Emulated::Sicklms200 => {
            use troupe_sicklms200::emulator;
            let mut scene = laser_scene(&a, z)?;
            emulator::run_with(&line, scene.as_mut(), &stop, || {
                banner("sicklms200", &a.link);
                tracing::info!("{} emulated; Ctrl-C stops it", emulator::KIND);
            })
            .with_context(|| format!("emulating a sicklms200 at {}", a.link.display()))?;
        }
        Emulated::Urglaser => {
            use troupe_urglaser::emulator;
            let mut scene = laser_scene(&a, z)?;
            let opts = emulator::EmulatorOptions { line, usb: a.usb };
            emulator::run_with(&opts, scene.as_mut(), &stop, || {
                banner("urglaser", &a.link);
                tracing::info!(
                    "a Hokuyo URG-04LX emulated on {}; Ctrl-C stops it",
                    if a.usb {
                        "USB"
                    } else {
                        "RS-232 (19200 baud at power-up)"
                    }
                );
            })
            .with_context(|| format!("emulating a urglaser at {}", a.link.display()))?;
        }
        Emulated::P2os => {
            use troupe_p2os::emulator;
            let opts = emulator::EmulatorOptions {
                line,
                subclass: a.subclass.clone(),
                name: "Troupe".into(),
            };
            let mut body = body(&a, z, emulator::room())?;
            emulator::run_with(&opts, body.as_mut(), &stop, || {
                banner("p2os", &a.link);
                tracing::info!("a Pioneer {} emulated; Ctrl-C stops it", a.subclass);
            })
            .with_context(|| format!("emulating a p2os robot at {}", a.link.display()))?;
        }
        Emulated::Erratic => {
            use troupe_erratic::emulator;
            let opts = emulator::EmulatorOptions {
                line,
                revision: a.revision.clone(),
            };
            let mut body = body(&a, z, emulator::room())?;
            emulator::run_with(&opts, body.as_mut(), &stop, || {
                banner("erratic", &a.link);
                tracing::info!("an Erratic {} emulated; Ctrl-C stops it", a.revision);
            })
            .with_context(|| format!("emulating an erratic at {}", a.link.display()))?;
        }
        Emulated::Wbr914 => {
            use troupe_wbr914::emulator;
            let opts = emulator::EmulatorOptions { line };
            let mut body = body(&a, z, emulator::room())?;
            emulator::run_with(&opts, body.as_mut(), &stop, || {
                banner("wbr914", &a.link);
                tracing::info!("a White Box 914 emulated (416666 baud, 8N2); Ctrl-C stops it");
            })
            .with_context(|| format!("emulating a wbr914 at {}", a.link.display()))?;
        }
    }
    Ok(())
}
