//! The `stage` driver: one process simulates the world and serves the
//! devices of every model the cfg maps.
//!
//! ```text
//! driver ( name "stage" provides ["simulation:0"] worldfile "simple.world" )
//! driver ( name "stage" provides ["position2d:0" "ranger:0" "ranger:1"] model "r0" )
//! ```
//!
//! `troupe plan` merges all stage sections of a cfg into one node whose
//! `models` option lists each section's model and devices.
//!
//! # Device mapping
//!
//! As Player's Stage plugin: each device of a section takes the first not yet
//! used model of its type in a depth-first walk from the named model, in
//! world-file order (so r0's sonar is `ranger:0` and its laser `ranger:1` in
//! simple.world). Beyond Player 3's plugin, `laser:N` takes the first unused
//! one-sensor, many-sample ranger (a scanner) and `sonar:N` the first unused
//! many-sensor ranger, so Player 2 era cfgs need no converter. `map:N`
//! is the named model itself: `provides ["map:0"] model "cave"` serves the
//! cave's body as an occupancy grid at its `map_resolution`, drawn once at
//! start, as Stage 2/3's plugin did.

use std::collections::HashSet;
use std::path::PathBuf;
use std::time::Duration;

use serde::Deserialize;
use troupe_geom::{OccMap, Pose};
use troupe_msgs::{
    camera, common, fiducial, gripper, laser, position2d, ranger, simulation, sonar, DevAddr,
    Device, Interface, Pose3d, Size3d,
};
use troupe_node::{Ctx, Driver, Event, NodeError, Result, Section, Switch};

use crate::sim::{Command, Paddles, Sim};
use crate::world::{self, Kind, Localization};

/// One cfg section's model and the devices it provides.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelMap {
    /// The model's name in the world file.
    pub model: String,
    /// Its devices, in the section's order.
    pub provides: Vec<DevAddr>,
}

/// Options of the stage driver (Player's names).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(default)]
pub struct Options {
    /// The world file (required).
    pub worldfile: Option<PathBuf>,
    /// Player's GUI switch; Troupe's Stage is headless (read, then ignored).
    pub usegui: Option<Switch>,
    /// The model of a single section's devices.
    pub model: Option<String>,
    /// The models of merged sections.
    pub models: Vec<ModelMap>,
    /// Overrides the world's `speedup` (1 = real time, ≤ 0 = as fast as possible).
    pub speedup: Option<f64>,
    /// Steps per wall-clock second when the world runs as fast as possible
    /// (`speedup` ≤ 0). Player stepped its Stage plugin once per server
    /// update (`player -u`, 100 Hz), so plans made from a .cfg set 100.
    pub update_rate: Option<f64>,
    /// Overrides the world's `quit_time` (simulated seconds, 0 = never).
    pub quit_time: Option<f64>,
    /// Step only on `simulation` `step` requests (deterministic tests).
    pub step_when_told: Option<Switch>,
    /// Do what Stage's Player plugin did where it ignores the interface:
    /// drive with the motors off, keep odometry a set/reset would change
    /// under `localization "gps"`, and take a car command's angle as a
    /// turn rate; and measure ranges as Stage does, on its raster of the
    /// walls (slower to sense). Off: do what the interface says, and
    /// measure ranges against the exact walls.
    pub stage_quirks: Option<Switch>,
    /// Write a PNG of the world here when the node stops.
    pub snapshot: Option<PathBuf>,
    /// What happens at `quit_time`: `exit` (Stage run alone, the default)
    /// or `pause` (Player's Stage plugin, which plans from a .cfg ask for:
    /// the clock stops and every device is still served).
    pub at_quit_time: Option<AtQuitTime>,
}

/// What the stage node does when the world's `quit_time` passes.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AtQuitTime {
    /// The node stops, as `stage` alone exits.
    #[default]
    Exit,
    /// The clock stops; requests are still answered, as under Player.
    Pause,
}

/// What a provided device is served from.
#[derive(Debug, Clone, Copy)]
enum Source {
    Simulation,
    Position { base: usize },
    Ranger { model: usize },
    Laser { model: usize },
    Sonar { model: usize },
    Blobfinder { model: usize },
    Fiducial { model: usize },
    Gripper { model: usize },
    Camera { model: usize },
    Map { model: usize },
}

/// The stage driver.
pub struct Stage {
    sim: Sim,
    devices: Vec<(Device, Source)>,
    /// The maps of `map` devices, by model, drawn once at start.
    maps: Vec<(usize, OccMap)>,
    period: Option<Duration>,
    steps_per_tick: u32,
    quit_time: f64,
    at_quit_time: AtQuitTime,
    /// `quit_time` passed under [`AtQuitTime::Pause`]: no more steps.
    paused: bool,
    snapshot: Option<PathBuf>,
    /// The simulation devices, model names and models whose pose was asked
    /// for: their answers are kept ready, renewed whenever the model may move.
    watched: Vec<(Device, String, usize)>,
    /// The pose of Stage's ground model, which a world file cannot name
    /// (see [`GROUND`]): it has no body, so only the simulation device
    /// sees it.
    ground: troupe_msgs::Pose2d,
    /// `stage_quirks`: Stage's plugin's ways where it ignores the interface.
    quirks: bool,
    /// When the models' poses last went out (viewers get them at most
    /// [`POSES_HZ`] times a wall second).
    poses_sent: std::cell::Cell<Option<std::time::Instant>>,
}

/// How often a running simulation publishes its models' poses for viewers.
const POSES_HZ: f64 = 30.0;

/// The names of the ground model Stage's world makes before any of the
/// file's (libstage/world.cc): unnamed, it is `model:0`, and then it is
/// renamed `_ground_model`; Stage keeps both names. The simulation device
/// answers for it at the origin, as Stage does.
const GROUND: [&str; 2] = ["model:0", "_ground_model"];

/// Models already serving a device of each interface. A laser or sonar may
/// be the same sensor as a ranger device: each interface has its own set.
type Used = HashSet<(Interface, usize)>;

fn resolve(
    sim: &Sim,
    base: usize,
    dev: &Device,
    used: &mut Used,
) -> std::result::Result<Source, String> {
    let w = &sim.world();
    let tree = w.subtree(base);
    let i = dev.interface;
    let free = |pred: &dyn Fn(usize) -> bool, used: &Used| {
        tree.iter()
            .copied()
            .find(|&m| !used.contains(&(i, m)) && pred(m))
    };
    let is_ranger = |m: usize| w.models[m].kind == Kind::Ranger;
    let pick = match dev.interface {
        Interface::Simulation => return Ok(Source::Simulation),
        Interface::Position2d => free(&|m| w.models[m].kind == Kind::Position, used),
        Interface::Ranger => free(&is_ranger, used),
        Interface::Laser => free(&|m| is_ranger(m) && w.models[m].sensors.len() == 1 && w.models[m].sensors[0].samples > 1, used)
            .or_else(|| free(&is_ranger, used)),
        Interface::Sonar => free(&|m| is_ranger(m) && w.models[m].sensors.len() > 1, used).or_else(|| free(&is_ranger, used)),
        Interface::Blobfinder => free(&|m| w.models[m].kind == Kind::Blobfinder, used),
        Interface::Fiducial => free(&|m| w.models[m].kind == Kind::Fiducial, used),
        Interface::Gripper => free(&|m| w.models[m].kind == Kind::Gripper, used),
        Interface::Camera => free(&|m| w.models[m].kind == Kind::Camera, used),
        // The named model itself: `provides ["map:0"] model "cave"`.
        Interface::Map => free(&|m| m == base, used),
        other => return Err(format!("{dev}: Troupe's stage does not simulate {other} devices yet (it serves position2d, ranger, laser, sonar, blobfinder, fiducial, gripper, camera, map and simulation)")),
    };
    let Some(m) = pick else {
        return Err(format!(
            "{dev}: model `{}` has no unused {} model",
            w.models[base].name, dev.interface
        ));
    };
    used.insert((i, m));
    Ok(match dev.interface {
        Interface::Position2d => Source::Position {
            base: sim.bases.iter().position(|b| b.model == m).unwrap_or(0),
        },
        Interface::Ranger => Source::Ranger { model: m },
        Interface::Laser => Source::Laser { model: m },
        Interface::Blobfinder => Source::Blobfinder { model: m },
        Interface::Fiducial => Source::Fiducial { model: m },
        Interface::Gripper => Source::Gripper { model: m },
        Interface::Camera => Source::Camera { model: m },
        Interface::Map => Source::Map { model: m },
        _ => Source::Sonar { model: m },
    })
}

impl Driver for Stage {
    const NAME: &'static str = "stage";
    type Options = Options;
    const CLOCK_SOURCE: bool = true;

    /// Stepping the world on request is long work: it waits its turn on
    /// Stage's thread.
    fn quick(request: &troupe_node::Request) -> bool {
        !request.is::<simulation::Step>()
    }

    fn new(section: &Section, o: Options) -> Result<Self> {
        let cfg_err = |m: String| NodeError::config(Self::NAME, m);
        let path = o.worldfile.clone().ok_or_else(|| {
            cfg_err("`worldfile` is required (e.g. worldfile \"simple.world\")".into())
        })?;
        let w = world::load(&path).map_err(|e| cfg_err(e.to_string()))?;
        let mut sim = Sim::new(w).map_err(|e| cfg_err(e.to_string()))?;
        let quirks = o.stage_quirks.is_some_and(Switch::on);
        sim.stage_ranges(quirks);
        // Which model serves which device.
        let mut maps = o.models.clone();
        let mapped: HashSet<Device> = maps
            .iter()
            .flat_map(|m| m.provides.iter().map(|a| a.device(section.robot)))
            .collect();
        let rest: Vec<DevAddr> = section
            .provides
            .iter()
            .filter(|a| !mapped.contains(&a.device(section.robot)))
            .cloned()
            .collect();
        if !rest.is_empty() {
            match &o.model {
                Some(m) => maps.push(ModelMap {
                    model: m.clone(),
                    provides: rest,
                }),
                None => {
                    let sims: Vec<&DevAddr> = rest
                        .iter()
                        .filter(|a| a.interface == Interface::Simulation)
                        .collect();
                    if sims.len() != rest.len() {
                        return Err(cfg_err(
                            "devices other than simulation need a `model` (e.g. model \"r0\")"
                                .into(),
                        ));
                    }
                    maps.push(ModelMap {
                        model: String::new(),
                        provides: rest,
                    });
                }
            }
        }
        let mut used = Used::new();
        let mut devices = Vec::new();
        for map in &maps {
            for a in &map.provides {
                let dev = a.device(section.robot);
                let src = if a.interface == Interface::Simulation {
                    Source::Simulation
                } else {
                    let base = sim.world().names.get(&map.model).copied().ok_or_else(|| {
                        let mut names: Vec<&str> = sim
                            .world()
                            .names
                            .keys()
                            .filter(|n| !n.contains(':'))
                            .map(String::as_str)
                            .collect();
                        names.sort_unstable();
                        cfg_err(format!(
                            "{}: no model named `{}` (named models: {})",
                            path.display(),
                            map.model,
                            names.join(", ")
                        ))
                    })?;
                    resolve(&sim, base, &dev, &mut used).map_err(cfg_err)?
                };
                devices.push((dev, src));
            }
        }
        // As Stage: a sensor no one reads is not simulated.
        sim.sense_only(devices.iter().filter_map(|&(_, src)| match src {
            Source::Ranger { model } | Source::Laser { model } | Source::Sonar { model } => {
                Some(model)
            }
            _ => None,
        }));
        let mut maps = Vec::new();
        for &(dev, src) in &devices {
            if let Source::Map { model } = src {
                let map = sim.model_map(model).map_err(|e| cfg_err(e.to_string()))?;
                tracing::info!(
                    "{dev}: a {} x {} map at {} m/cell drawn from model `{}`",
                    map.info.width,
                    map.info.height,
                    map.info.resolution,
                    sim.world().models[model].name
                );
                maps.push((model, map));
            }
        }
        let speedup = o.speedup.unwrap_or(sim.world().speedup);
        let interval = sim.world().interval_sim;
        let rate = o.update_rate.filter(|r| r.is_finite() && *r > 0.0);
        let (period, steps_per_tick) = if speedup > 0.0 {
            (Duration::from_secs_f64((interval / speedup).max(1e-4)), 1)
        } else if let Some(rate) = rate {
            (Duration::from_secs_f64((1.0 / rate).max(1e-4)), 1)
        } else {
            // As fast as possible, in small batches so commands and requests interleave.
            (Duration::from_micros(1), 10)
        };
        let told = o.step_when_told.is_some_and(Switch::on);
        Ok(Stage {
            quit_time: o.quit_time.unwrap_or(sim.world().quit_time),
            at_quit_time: o.at_quit_time.unwrap_or_default(),
            paused: false,
            sim,
            devices,
            maps,
            period: (!told).then_some(period),
            steps_per_tick,
            snapshot: o.snapshot.clone(),
            watched: Vec::new(),
            ground: troupe_msgs::Pose2d::default(),
            quirks,
            poses_sent: Default::default(),
        })
    }

    fn setup(&mut self, ctx: &mut Ctx) -> Result<()> {
        self.keep_ready(ctx)?;
        ctx.set_time(self.sim.time)?;
        self.publish(ctx)?;
        ctx.set_tick(self.period);
        Ok(())
    }

    fn on_event(&mut self, ctx: &mut Ctx, event: Event) -> Result<()> {
        match event {
            Event::Tick => self.advance(ctx, self.steps_per_tick),
            Event::Command(c) => {
                let Some(&(_, src)) = self.devices.iter().find(|(d, _)| *d == c.device) else {
                    return Ok(());
                };
                if let Source::Gripper { model } = src {
                    if c.is::<gripper::Open>() {
                        self.sim.grip(model, false);
                    } else if c.is::<gripper::Close>() {
                        self.sim.grip(model, true);
                    } else if !c.is::<gripper::Stop>() {
                        return Err(c.unexpected());
                    }
                    return Ok(());
                }
                let Source::Position { base } = src else {
                    return Err(c.unexpected());
                };
                let b = &mut self.sim.bases[base];
                b.cmd = Some(if c.is::<position2d::CmdVel>() {
                    let v = c.decode::<position2d::CmdVel>()?.msg;
                    Command::Vel(v.vel.into())
                } else if c.is::<position2d::CmdPos>() {
                    Command::GoTo(c.decode::<position2d::CmdPos>()?.msg.pos.into())
                } else if c.is::<position2d::CmdCar>() {
                    let v = c.decode::<position2d::CmdCar>()?.msg;
                    if self.quirks {
                        // Stage's plugin: the angle as a turn rate.
                        Command::Vel(Pose::new(v.velocity, 0.0, v.angle))
                    } else {
                        Command::Car(v.velocity, v.angle)
                    }
                } else {
                    return Err(c.unexpected());
                });
                Ok(())
            }
            Event::Request(r) => {
                let Some(&(_, src)) = self.devices.iter().find(|(d, _)| *d == r.sample.device)
                else {
                    r.nack("no such device");
                    return Ok(());
                };
                if matches!(src, Source::Simulation) && r.is::<simulation::Step>() {
                    let n = r.decode::<simulation::Step>()?.steps;
                    self.advance(ctx, n)?;
                    r.reply(&common::Ack);
                    return Ok(());
                }
                self.request(ctx, src, r)
            }
            Event::Data(_) | Event::Reply(_) | Event::Wake => Ok(()),
        }
    }

    fn shutdown(&mut self, ctx: &mut Ctx) -> Result<()> {
        if let Some(p) = &self.snapshot {
            match self.sim.snapshot(1000).save(p) {
                Ok(()) => tracing::info!(
                    "snapshot of the world at {:.1} s written to {}",
                    self.sim.time,
                    p.display()
                ),
                Err(e) => tracing::error!("cannot write snapshot {}: {e}", p.display()),
            }
        }
        // Stop every robot, as a real base's driver would.
        for b in &mut self.sim.bases {
            b.cmd = Some(Command::Vel(Pose::default()));
            b.vel = Pose::default();
        }
        self.publish(ctx)
    }
}

fn pose3(p: Pose, z: f64) -> Pose3d {
    Pose3d {
        x: p.x,
        y: p.y,
        z,
        roll: 0.0,
        pitch: 0.0,
        yaw: p.yaw,
    }
}

fn size3(s: [f64; 3]) -> Size3d {
    Size3d {
        width: s[1],
        length: s[0],
        height: s[2],
    }
}

impl Stage {
    /// The simulation, for tests and benchmarks.
    pub fn sim(&self) -> &Sim {
        &self.sim
    }

    fn publish(&self, ctx: &mut Ctx) -> Result<()> {
        for &(dev, src) in &self.devices {
            match src {
                Source::Simulation => self.publish_poses(ctx, &dev)?,
                Source::Map { .. } => {}
                Source::Position { base } => {
                    let b = &self.sim.bases[base];
                    ctx.publish(
                        &dev,
                        &position2d::Data {
                            pose: b.odom.into(),
                            vel: b.vel.into(),
                            stall: b.stall,
                        },
                    )?;
                }
                Source::Ranger { model } => {
                    let (ranges, intensities) = self.ranger_data(model);
                    ctx.publish(&dev, &ranger::Ranges { ranges })?;
                    ctx.publish(&dev, &ranger::Intensities { intensities })?;
                }
                Source::Laser { model } => {
                    let m = &self.sim.world().models[model];
                    let (Some(s), Some(rd)) = (m.sensors.first(), self.sim.readings[model].first())
                    else {
                        continue;
                    };
                    let res = if s.samples > 1 {
                        s.fov / (s.samples - 1) as f64
                    } else {
                        0.0
                    };
                    ctx.publish(
                        &dev,
                        &laser::Scan {
                            min_angle: (-s.fov / 2.0) as f32,
                            max_angle: (s.fov / 2.0) as f32,
                            resolution: res as f32,
                            max_range: s.range.1 as f32,
                            ranges: rd.ranges.iter().map(|&r| r as f32).collect(),
                            intensity: rd
                                .intensities
                                .iter()
                                .map(|&i| i.clamp(0.0, 255.0).round() as u8)
                                .collect(),
                            id: self.sim.steps as u32,
                        },
                    )?;
                }
                Source::Sonar { model } => {
                    let ranges = self.sim.readings[model]
                        .iter()
                        .map(|r| r.ranges.first().copied().unwrap_or(0.0) as f32)
                        .collect();
                    ctx.publish(&dev, &sonar::Ranges { ranges })?;
                }
                Source::Blobfinder { model } => ctx.publish(&dev, &self.sim.blobs(model))?,
                Source::Camera { model } if !self.sim.updated(model) => {}
                Source::Camera { model } => {
                    // As Stage's plugin: 24-bit RGB, top row first; the
                    // depth Stage reads back is not sent.
                    let f = self.sim.camera(model);
                    ctx.publish(
                        &dev,
                        &camera::Data {
                            width: f.width,
                            height: f.height,
                            bpp: 24,
                            format: camera::FORMAT_RGB888,
                            fdiv: 0,
                            compression: camera::COMPRESS_RAW,
                            image: f.rgb,
                        },
                    )?;
                }
                Source::Fiducial { model } => ctx.publish(&dev, &self.sim.fiducials(model))?,
                Source::Gripper { model } => {
                    let st = self.sim.grippers[model].clone().unwrap_or_default();
                    let state = match st.paddles {
                        Paddles::Open => gripper::State::Open,
                        Paddles::Closed => gripper::State::Closed,
                        Paddles::Opening | Paddles::Closing => gripper::State::Moving,
                    };
                    // Stage's Player plugin never counts what is stored.
                    ctx.publish(
                        &dev,
                        &gripper::Data {
                            state,
                            beams: st.beams,
                            stored: 0,
                        },
                    )?;
                }
            }
        }
        Ok(())
    }

    /// A ranger's data as Player's plugin sends it: every sample of a
    /// one-sensor ranger, or the first sample of each sensor.
    fn ranger_data(&self, model: usize) -> (Vec<f64>, Vec<f64>) {
        let rd = &self.sim.readings[model];
        if let (1, Some(first)) = (rd.len(), rd.first()) {
            (first.ranges.to_vec(), first.intensities.to_vec())
        } else {
            (
                rd.iter()
                    .map(|r| r.ranges.first().copied().unwrap_or(0.0))
                    .collect(),
                rd.iter()
                    .map(|r| r.intensities.first().copied().unwrap_or(0.0))
                    .collect(),
            )
        }
    }

    /// As Stage's plugin answers: the body's planar pose and footprint
    /// (no height), each element's pose in the body's frame.
    fn ranger_geom(&self, model: usize) -> ranger::Geom {
        let m = &self.sim.world().models[model];
        ranger::Geom {
            pose: pose3(m.pose, 0.0),
            size: troupe_msgs::Size3d {
                height: 0.0,
                ..size3(m.size)
            },
            element_poses: m.sensors.iter().map(|s| pose3(s.pose, s.z)).collect(),
            // Stage's plugin gives an element's x as its width and y as its
            // length (the body's the other way round): clients see that.
            element_sizes: m
                .sensors
                .iter()
                .map(|s| Size3d {
                    width: s.size[0],
                    length: s.size[1],
                    height: s.size[2],
                })
                .collect(),
        }
    }

    fn position_geom(&self, model: usize) -> position2d::Geom {
        let d = &self.sim.world().models[model];
        position2d::Geom {
            pose: pose3(d.origin, 0.0),
            size: size3(d.size),
        }
    }

    fn laser_geom(&self, model: usize) -> laser::Geom {
        let g = self.ranger_geom(model);
        laser::Geom {
            pose: g.pose,
            size: g.size,
        }
    }

    fn laser_config(&self, model: usize) -> Option<laser::Config> {
        let c = self.ranger_config(model)?;
        let s = &self.sim.world().models[model].sensors[0];
        Some(laser::Config {
            min_angle: c.min_angle as f32,
            max_angle: c.max_angle as f32,
            resolution: if s.samples > 1 {
                (s.fov / (s.samples - 1) as f64) as f32
            } else {
                0.0
            },
            max_range: c.max_range as f32,
            range_res: c.range_res as f32,
            intensity: true,
            scanning_frequency: c.frequency as f32,
        })
    }

    /// Keeps ready the answers that cannot change while the world runs
    /// (geometry is the world file's, whatever `set_pose` does later), so
    /// that clients' geometry and map-info requests wait for no step.
    fn keep_ready(&self, ctx: &mut Ctx) -> Result<()> {
        for &(dev, src) in &self.devices {
            match src {
                Source::Position { base } => {
                    let m = self.sim.bases[base].model;
                    ctx.answer_always::<position2d::GetGeom>(&dev, &self.position_geom(m))?;
                }
                Source::Ranger { model } => {
                    ctx.answer_always::<ranger::GetGeom>(&dev, &self.ranger_geom(model))?;
                    if let Some(c) = self.ranger_config(model) {
                        ctx.answer_always::<ranger::GetConfig>(&dev, &c)?;
                    }
                }
                Source::Laser { model } => {
                    ctx.answer_always::<laser::GetGeom>(&dev, &self.laser_geom(model))?;
                    if let Some(c) = self.laser_config(model) {
                        ctx.answer_always::<laser::GetConfig>(&dev, &c)?;
                    }
                }
                Source::Map { model } => {
                    if let Some((_, map)) = self.maps.iter().find(|(m, _)| *m == model) {
                        ctx.answer_always::<troupe_msgs::map::GetInfo>(&dev, &map.info)?;
                    }
                }
                _ => {}
            }
        }
        Ok(())
    }

    fn ranger_config(&self, model: usize) -> Option<ranger::Config> {
        let s = self.sim.world().models[model].sensors.first()?;
        Some(ranger::Config {
            min_angle: -s.fov / 2.0,
            max_angle: s.fov / 2.0,
            angular_res: s.fov / s.samples as f64,
            min_range: s.range.0,
            max_range: s.range.1,
            range_res: self.sim.world().resolution,
            frequency: 1.0 / self.sim.world().interval_sim,
        })
    }

    fn request(&mut self, ctx: &mut Ctx, src: Source, r: troupe_node::Request) -> Result<()> {
        match src {
            Source::Position { base } => {
                let m = self.sim.bases[base].model;
                if r.is::<position2d::GetGeom>() {
                    r.reply(&self.position_geom(m));
                } else if r.is::<position2d::MotorPower>() {
                    let on = r.decode::<position2d::MotorPower>()?.state;
                    if self.quirks {
                        tracing::warn!("Stage ignores motor power state ({})", u8::from(on));
                    } else {
                        self.sim.bases[base].enabled = on;
                    }
                    r.reply(&common::Ack);
                } else if r.is::<position2d::SetOdom>() || r.is::<position2d::ResetOdom>() {
                    let gps = self.sim.world().models[m]
                        .position
                        .as_ref()
                        .is_some_and(|c| c.localization == Localization::Gps);
                    // Stage's plugin sets the estimate, which its next
                    // update overwrites with the true pose under gps.
                    if !(self.quirks && gps) {
                        let pose: Pose = if r.is::<position2d::SetOdom>() {
                            r.decode::<position2d::SetOdom>()?.pose.into()
                        } else {
                            Pose::default()
                        };
                        let g = self.sim.global(m);
                        let b = &mut self.sim.bases[base];
                        b.odom = pose;
                        b.origin = g.compose(&pose.inverse());
                    }
                    r.reply(&common::Ack);
                } else if r.is::<position2d::PositionMode>() {
                    // Stage's plugin acknowledges it and changes nothing.
                    tracing::warn!("stage: set control mode not yet implemented (as Stage)");
                    r.reply(&common::Ack);
                } else if r.is::<position2d::VelocityMode>() {
                    r.nack("Stage's position2d has one velocity controller: it refuses VELOCITY_MODE, as Stage's plugin does");
                } else {
                    let n = r.name.clone();
                    r.nack(format!("stage position2d does not handle `{n}`"));
                }
            }
            Source::Ranger { model } => {
                if r.is::<ranger::GetGeom>() {
                    r.reply(&self.ranger_geom(model));
                } else if r.is::<ranger::GetConfig>() {
                    match self.ranger_config(model) {
                        Some(c) => r.reply(&c),
                        None => r.nack("this ranger has no sensors"),
                    }
                } else {
                    // Stage's plugin refuses POWER and INTNS too.
                    let n = r.name.clone();
                    r.nack(format!("stage ranger does not handle `{n}` (its configuration is the world file's)"));
                }
            }
            Source::Laser { model } => {
                if r.is::<laser::GetGeom>() {
                    r.reply(&self.laser_geom(model));
                } else if r.is::<laser::GetConfig>() {
                    match self.laser_config(model) {
                        Some(c) => r.reply(&c),
                        None => r.nack("this ranger has no sensors"),
                    }
                } else if r.is::<common::Power>() {
                    r.reply(&common::Ack);
                } else {
                    let n = r.name.clone();
                    r.nack(format!(
                        "stage laser does not handle `{n}` (its configuration is the world file's)"
                    ));
                }
            }
            Source::Sonar { model } => {
                if r.is::<sonar::GetGeom>() {
                    // Player's sonar poses are in the robot's frame.
                    let m = &self.sim.world().models[model];
                    r.reply(&sonar::Geom {
                        poses: m
                            .sensors
                            .iter()
                            .map(|s| pose3(m.pose.compose(&s.pose), s.z))
                            .collect(),
                    });
                } else if r.is::<common::Power>() {
                    r.reply(&common::Ack);
                } else {
                    let n = r.name.clone();
                    r.nack(format!("stage sonar does not handle `{n}`"));
                }
            }
            Source::Fiducial { model } => {
                if r.is::<fiducial::GetGeom>() {
                    let m = &self.sim.world().models[model];
                    r.reply(&fiducial::Geom {
                        pose: pose3(m.pose, m.z),
                        size: size3(m.size),
                        fiducial_size: troupe_msgs::Size2d {
                            width: 0.0,
                            length: 0.0,
                        },
                    });
                } else if r.is::<fiducial::GetId>() {
                    // The finder's own model's fiducial_return, as Stage answers.
                    let id = self.sim.world().models[model].fiducial_return;
                    r.reply(&fiducial::Id { id: id as u32 });
                } else if r.is::<fiducial::SetId>() {
                    let id = r.decode::<fiducial::SetId>()?.id;
                    self.sim.set_fiducial_return(model, id as i32);
                    r.reply(&fiducial::Id { id });
                } else {
                    let n = r.name.clone();
                    r.nack(format!("stage fiducial does not handle `{n}`"));
                }
            }
            Source::Gripper { model } => {
                if r.is::<gripper::GetGeom>() {
                    let m = &self.sim.world().models[model];
                    r.reply(&gripper::Geom {
                        pose: pose3(m.pose, m.z),
                        outer_size: size3(m.size),
                        // Stage's plugin leaves these zero.
                        inner_size: troupe_msgs::Size3d::default(),
                        num_beams: 2,
                        capacity: 0,
                    });
                } else {
                    let n = r.name.clone();
                    r.nack(format!("stage gripper does not handle `{n}`"));
                }
            }
            Source::Blobfinder { .. } => {
                let n = r.name.clone();
                r.nack(format!("stage blobfinder does not handle `{n}`"));
            }
            Source::Camera { .. } => {
                let n = r.name.clone();
                r.nack(format!("stage camera does not handle `{n}`"));
            }
            Source::Simulation => self.simulation(ctx, r)?,
            Source::Map { model } => {
                let dev = r.sample.device;
                match self.maps.iter().find(|(m, _)| *m == model) {
                    Some((_, map)) => troupe_mapfile::serve(map, &dev, r)?,
                    None => r.nack("this map was not drawn"),
                }
            }
        }
        Ok(())
    }

    /// Takes up to `steps` steps, publishing after each; stops at quit_time.
    fn advance(&mut self, ctx: &mut Ctx, steps: u32) -> Result<()> {
        if self.paused {
            return Ok(());
        }
        for _ in 0..steps {
            self.sim.step();
            ctx.set_time(self.sim.time)?;
            self.publish(ctx)?;
            self.keep_poses_ready(ctx)?;
            if self.quit_time > 0.0 && self.sim.time >= self.quit_time - 1e-9 {
                tracing::info!(
                    "quit_time {} s reached after {} steps",
                    self.quit_time,
                    self.sim.steps
                );
                if let Some(flags) = self.sim.flags_held() {
                    tracing::info!("flags held: {flags}");
                }
                match self.at_quit_time {
                    AtQuitTime::Exit => ctx.request_stop(),
                    AtQuitTime::Pause => {
                        tracing::info!(
                            "the clock stops here; every device is still served (as under Player)"
                        );
                        self.paused = true;
                        ctx.set_tick(None);
                    }
                }
                break;
            }
        }
        Ok(())
    }

    /// The devices this node serves from model `m` or its sensors, as
    /// `6665:position2d:0 6665:sonar:0`: how a tool outside (an emulator
    /// backed by a Stage robot) finds a model's devices by its name.
    fn devices_of(&self, m: usize) -> String {
        let tree = self.sim.world().subtree(m);
        let list: Vec<String> = self
            .devices
            .iter()
            .filter(|(_, src)| self.model_of(*src).is_some_and(|k| tree.contains(&k)))
            .map(|(d, _)| d.to_string())
            .collect();
        list.join(" ")
    }

    /// The model a device is served from (none for the simulation itself).
    fn model_of(&self, src: Source) -> Option<usize> {
        match src {
            Source::Position { base } => Some(self.sim.bases[base].model),
            Source::Ranger { model }
            | Source::Laser { model }
            | Source::Sonar { model }
            | Source::Blobfinder { model }
            | Source::Fiducial { model }
            | Source::Gripper { model }
            | Source::Camera { model }
            | Source::Map { model } => Some(model),
            Source::Simulation => None,
        }
    }

    /// The world as a viewer draws it (`simulation` `world` request).
    fn world_view(&self) -> simulation::World {
        let w = &self.sim.world();
        let f = |v: f64| v as f32;
        let pose = |p: Pose| [f(p.x), f(p.y), f(p.yaw)];
        let models = (0..w.models.len())
            .map(|m| {
                let d = &w.models[m];
                simulation::Model {
                    name: d.name.clone(),
                    parent: d.parent.map(|p| p as u32),
                    color: self.sim.colors[m],
                    polys: d
                        .blocks
                        .iter()
                        .map(|b| b.iter().map(|&(x, y)| [f(x), f(y)]).collect())
                        .collect(),
                    moves: self.sim.moves(m),
                    pose: pose(self.sim.global(m)),
                }
            })
            .collect();
        let devices = self
            .devices
            .iter()
            .filter_map(|&(device, src)| {
                let m = self.model_of(src)?;
                let sensors = match src {
                    Source::Ranger { .. } | Source::Laser { .. } | Source::Sonar { .. } => w.models
                        [m]
                        .sensors
                        .iter()
                        .map(|s| simulation::Sensor {
                            pose: pose(s.pose),
                            fov: f(s.fov),
                            range: f(s.range.1),
                            samples: s.samples as u32,
                        })
                        .collect(),
                    _ => Vec::new(),
                };
                Some(simulation::DeviceModel {
                    device,
                    model: m as u32,
                    sensors,
                })
            })
            .collect();
        simulation::World {
            models,
            devices,
            resolution: w.resolution,
        }
    }

    /// The poses of every model that moves, on the simulation device: every
    /// step when stepped on request, at most [`POSES_HZ`] a wall second
    /// when running.
    fn publish_poses(&self, ctx: &mut Ctx, dev: &Device) -> Result<()> {
        let now = std::time::Instant::now();
        let due = self.period.is_none()
            || self
                .poses_sent
                .get()
                .is_none_or(|t| now.duration_since(t).as_secs_f64() >= 1.0 / POSES_HZ);
        if !due {
            return Ok(());
        }
        self.poses_sent.set(Some(now));
        let poses = (0..self.sim.world().models.len())
            .filter(|&m| self.sim.moves(m))
            .map(|m| {
                let p = self.sim.global(m);
                (m as u32, [p.x as f32, p.y as f32, p.yaw as f32])
            })
            .collect();
        ctx.publish(
            dev,
            &simulation::Poses {
                time: self.sim.time,
                poses,
            },
        )
    }

    /// The answer to a `GetPose2d` of model `m`, asked for as `name`.
    fn pose_of(&self, m: usize, name: &str) -> simulation::Pose2dOf {
        simulation::Pose2dOf {
            name: name.to_owned(),
            pose: self.sim.reported_pose(m).into(),
        }
    }

    /// Keeps the pose of each watched model ready to answer, as it is now.
    fn keep_poses_ready(&self, ctx: &mut Ctx) -> Result<()> {
        for (dev, name, m) in &self.watched {
            let asked = simulation::GetPose2d { name: name.clone() };
            ctx.answer_always_to(dev, &asked, &self.pose_of(*m, name))?;
        }
        Ok(())
    }

    fn simulation(&mut self, ctx: &mut Ctx, r: troupe_node::Request) -> Result<()> {
        let find = |sim: &Sim, name: &str| sim.world().names.get(name).copied();
        if r.is::<simulation::GetWorld>() {
            r.reply(&self.world_view());
        } else if r.is::<simulation::GetPose2d>() {
            let q = r.decode::<simulation::GetPose2d>()?;
            match find(&self.sim, &q.name) {
                None if GROUND.contains(&q.name.as_str()) => r.reply(&simulation::Pose2dOf {
                    pose: self.ground,
                    name: q.name,
                }),
                Some(m) => {
                    let pose = self.pose_of(m, &q.name);
                    // A pose asked for once is asked for again (a client
                    // following a robot): from now on it waits ready,
                    // renewed after every step, and Stage's thread is not
                    // woken for it.
                    let dev = r.sample.device;
                    if !self
                        .watched
                        .iter()
                        .any(|(d, n, _)| *d == dev && *n == q.name)
                    {
                        ctx.answer_always_to(&dev, &q, &pose)?;
                        self.watched.push((dev, q.name, m));
                    }
                    r.reply(&pose);
                }
                None => r.nack(format!("no model named `{}`", q.name)),
            }
        } else if r.is::<simulation::SetPose2d>() {
            let q = r.decode::<simulation::SetPose2d>()?;
            match find(&self.sim, &q.name) {
                None if GROUND.contains(&q.name.as_str()) => {
                    self.ground = q.pose;
                    r.reply(&common::Ack);
                }
                Some(m) => {
                    self.sim.set_pose(m, q.pose.into());
                    // Renewed before the answer: a client that set a pose
                    // and then asks for it gets the new one.
                    self.keep_poses_ready(ctx)?;
                    r.reply(&common::Ack);
                }
                None => r.nack(format!("no model named `{}`", q.name)),
            }
        } else if r.is::<simulation::GetPose3d>() {
            let q = r.decode::<simulation::GetPose3d>()?;
            match find(&self.sim, &q.name) {
                None if GROUND.contains(&q.name.as_str()) => r.reply(&simulation::Pose3dOf {
                    pose: pose3(self.ground.into(), 0.0),
                    name: q.name,
                    simtime: (self.sim.time * 1e6).round(),
                }),
                Some(m) => r.reply(&simulation::Pose3dOf {
                    pose: pose3(self.sim.poses[m], self.sim.world().models[m].z),
                    name: q.name,
                    simtime: (self.sim.time * 1e6).round(),
                }),
                None => r.nack(format!("no model named `{}`", q.name)),
            }
        } else if r.is::<simulation::SetPose3d>() {
            let q = r.decode::<simulation::SetPose3d>()?;
            match find(&self.sim, &q.name) {
                None if GROUND.contains(&q.name.as_str()) => {
                    let p = q.pose;
                    self.ground = troupe_msgs::Pose2d::new(p.x, p.y, p.yaw);
                    r.reply(&common::Ack);
                }
                Some(m) => {
                    // Roll and pitch are not Stage's.
                    self.sim.set_z(m, q.pose.z);
                    let p = q.pose;
                    self.sim
                        .set_pose(m, troupe_geom::Pose::new(p.x, p.y, p.yaw));
                    self.keep_poses_ready(ctx)?;
                    r.reply(&common::Ack);
                }
                None => r.nack(format!("no model named `{}`", q.name)),
            }
        } else if r.is::<simulation::GetProperty>() {
            let q = r.decode::<simulation::GetProperty>()?;
            match (find(&self.sim, &q.name), q.prop.as_str()) {
                (Some(m), "color") => r.reply(&simulation::Property {
                    name: q.name,
                    prop: q.prop,
                    value: simulation::Value::Color(self.sim.colors[m]),
                }),
                (Some(_), "time") => {
                    // Stage's SimTimeNow: a uint64 of microseconds.
                    let usec = (self.sim.time * 1e6).round() as i64;
                    r.reply(&simulation::Property {
                        name: q.name,
                        prop: q.prop,
                        value: simulation::Value::Int(usec),
                    })
                }
                (Some(m), "devices") => {
                    let value = simulation::Value::Text(self.devices_of(m));
                    r.reply(&simulation::Property {
                        name: q.name,
                        prop: q.prop,
                        value,
                    })
                }
                (Some(_), p) => {
                    let msg = format!(
                        "unknown property `{p}` (stage has \"color\", \"time\" and \"devices\")"
                    );
                    r.nack(msg)
                }
                (None, _) => r.nack(format!("no model named `{}`", q.name)),
            }
        } else if r.is::<simulation::SetProperty>() {
            let q = r.decode::<simulation::SetProperty>()?;
            match (find(&self.sim, &q.name), q.prop.as_str(), &q.value) {
                (Some(m), "color", simulation::Value::Color(c)) => {
                    self.sim.colors[m] = *c;
                    r.reply(&common::Ack);
                }
                (Some(_), "color", _) => r.nack("property \"color\" takes a colour"),
                (Some(_), p, _) => {
                    let msg = format!("cannot set property `{p}` (stage sets \"color\")");
                    r.nack(msg)
                }
                (None, _, _) => r.nack(format!("no model named `{}`", q.name)),
            }
        } else {
            let n = r.name.clone();
            r.nack(format!("stage simulation does not handle `{n}`"));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use troupe_msgs::map;
    use troupe_node::testing::Harness;

    fn world_file(name: &str, text: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("troupe-stage-node-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("t.world");
        std::fs::write(&p, text).unwrap();
        p
    }

    const WORLD: &str = "interval_sim 100\nquit_time 1\n\
        define bot position ( size [0.44 0.38 0.22] origin [-0.04 0 0 0] color \"red\"\n\
          ranger ( sensor ( pose [0.1 0 0 90] range [0 5] ) sensor ( pose [0.1 0 0 -90] range [0 5] ) ) )\n\
        model ( name \"wall\" pose [4 0 0 0] size [0.2 8 1] )\n\
        bot ( name \"r0\" pose [0 0 0 0] ranger ( sensor ( range [0 8] fov 180 samples 181 ) ) acceleration_bounds [-9 9 -9 9 -9 9 -900 900] )\n";

    fn harness(name: &str, provides: &str) -> Harness<Stage> {
        let w = world_file(name, WORLD);
        Harness::from_json(&format!(
            r#"{{"name":"stage","provides":{provides},"options":{{"worldfile":"{}","model":"r0"}}}}"#,
            w.display()
        ))
        .unwrap()
    }

    /// The simulation device's answer to a `GetPose2d` of `name`.
    fn ask_pose(
        h: &mut Harness<Stage>,
        sim: Device,
        name: &str,
    ) -> std::result::Result<simulation::Pose2dOf, String> {
        let p = h
            .request(sim, &simulation::GetPose2d { name: name.into() })
            .unwrap();
        h.reply::<simulation::Pose2dOf>(p).unwrap()
    }

    fn dev(i: Interface, n: u32) -> Device {
        Device::new(6665, i, n)
    }

    #[test]
    fn map_device_draws_the_named_model() {
        // A 4 x 2 m room at (10, 5): a 1 m square in its lower left corner,
        // one in its upper right, and a wall 5 cm thick down the middle.
        let w = world_file(
            "map",
            "model ( name \"room\" pose [10 5 0 0] size [4 2 1] map_resolution 0.5\n\
               block ( points 4 point[0] [0 0] point[1] [1 0] point[2] [1 1] point[3] [0 1] )\n\
               block ( points 4 point[0] [3 1] point[1] [4 1] point[2] [4 2] point[3] [3 2] )\n\
               block ( points 4 point[0] [2 0] point[1] [2.05 0] point[2] [2.05 2] point[3] [2 2] ) )\n",
        );
        let mut h = Harness::<Stage>::from_json(&format!(
            r#"{{"name":"stage","provides":["map:0"],"options":{{"worldfile":"{}","model":"room"}}}}"#,
            w.display()
        ))
        .unwrap();
        let m = dev(Interface::Map, 0);
        let p = h.request(m, &map::GetInfo).unwrap();
        let info: map::Info = h.reply(p).unwrap().unwrap();
        assert_eq!((info.width, info.height, info.resolution), (8, 4, 0.5));
        assert_eq!(
            (info.origin.x, info.origin.y),
            (8.0, 4.0),
            "lower left corner"
        );
        let p = h
            .request(
                m,
                &map::GetData {
                    col: 0,
                    row: 0,
                    width: 8,
                    height: 4,
                },
            )
            .unwrap();
        let tile: map::Data = h.reply(p).unwrap().unwrap();
        let rows: Vec<String> = tile
            .cells
            .chunks(8)
            .map(|r| r.iter().map(|&c| if c > 0 { '#' } else { '.' }).collect())
            .collect();
        assert_eq!(
            rows,
            ["##..#...", "##..#...", "....#.##", "....#.##"],
            "row 0 is the bottom"
        );
        let p = h.request(m, &map::GetVector).unwrap();
        assert!(h.reply::<map::Vector>(p).unwrap().is_err());
        let p = h
            .request(
                m,
                &map::GetData {
                    col: 0,
                    row: 0,
                    width: 9,
                    height: 4,
                },
            )
            .unwrap();
        let e = h.reply::<map::Data>(p).unwrap().unwrap_err();
        assert!(e.contains("larger than the 8x4 map"), "{e}");
        // A bad resolution is named with the model's place.
        let w = world_file(
            "badmap",
            "model ( name \"room\" size [4 2 1] map_resolution 0 )\n",
        );
        let e = Harness::<Stage>::from_json(&format!(
            r#"{{"name":"stage","provides":["map:0"],"options":{{"worldfile":"{}","model":"room"}}}}"#,
            w.display()
        ))
        .err()
        .unwrap()
        .to_string();
        assert!(
            e.contains("t.world:1") && e.contains("map_resolution 0"),
            "{e}"
        );
    }

    #[test]
    fn serves_position_rangers_laser_sonar_and_the_clock() {
        let mut h = harness(
            "serve",
            r#"["simulation:0","position2d:0","ranger:0","ranger:1","laser:0","sonar:0"]"#,
        );
        assert_eq!(
            h.tick_period(),
            Some(Duration::from_millis(100)),
            "speedup 1: real time"
        );
        h.tick().unwrap();
        assert!((h.now() - 0.1).abs() < 1e-9);
        assert_eq!(h.clock_published().last().copied(), Some(h.now()));
        let r0 = h.published::<ranger::Ranges>(dev(Interface::Ranger, 0));
        let r1 = h.published::<ranger::Ranges>(dev(Interface::Ranger, 1));
        assert_eq!(
            r0.last().unwrap().ranges.len(),
            2,
            "ranger:0 is the two-sensor ranger (macro children first)"
        );
        assert_eq!(r1.last().unwrap().ranges.len(), 181);
        // laser:0 is the scanner (also ranger:1); sonar:0 the two-sensor ranger.
        let scan = h
            .published::<laser::Scan>(dev(Interface::Laser, 0))
            .pop()
            .unwrap();
        assert_eq!(scan.ranges.len(), 181);
        assert!(
            (scan.ranges[90] - (3.9 - 0.0)).abs() < 0.03,
            "wall ahead: {}",
            scan.ranges[90]
        );
        // Drive towards the wall: the laser sees it approach.
        h.command(
            dev(Interface::Position2d, 0),
            &position2d::CmdVel {
                vel: troupe_msgs::Pose2d::new(1.0, 0.0, 0.0),
                state: true,
            },
        )
        .unwrap();
        h.tick().unwrap();
        h.tick().unwrap();
        let later = h
            .published::<laser::Scan>(dev(Interface::Laser, 0))
            .pop()
            .unwrap();
        assert!(
            later.ranges[90] < scan.ranges[90] - 0.15,
            "{} then {}",
            scan.ranges[90],
            later.ranges[90]
        );
        let pos = h
            .published::<position2d::Data>(dev(Interface::Position2d, 0))
            .pop()
            .unwrap();
        assert!(pos.pose.x > 0.15 && pos.vel.x == 1.0, "{pos:?}");
    }

    #[test]
    fn geometry_config_and_simulation_requests() {
        let mut h = harness(
            "requests",
            r#"["simulation:0","position2d:0","ranger:0","ranger:1"]"#,
        );
        let p = h
            .request(dev(Interface::Position2d, 0), &position2d::GetGeom)
            .unwrap();
        let g = h.reply::<position2d::Geom>(p).unwrap().unwrap();
        assert_eq!((g.size.length, g.size.width), (0.44, 0.38));
        assert_eq!(g.pose.x, -0.04);
        let p = h
            .request(dev(Interface::Ranger, 1), &ranger::GetConfig)
            .unwrap();
        let c = h.reply::<ranger::Config>(p).unwrap().unwrap();
        assert!((c.max_angle - std::f64::consts::FRAC_PI_2).abs() < 1e-9 && c.max_range == 8.0);
        let p = h
            .request(dev(Interface::Ranger, 0), &ranger::GetGeom)
            .unwrap();
        assert_eq!(
            h.reply::<ranger::Geom>(p)
                .unwrap()
                .unwrap()
                .element_poses
                .len(),
            2
        );
        let sim = dev(Interface::Simulation, 0);
        let p = h
            .request(
                sim,
                &simulation::SetPose2d {
                    name: "r0".into(),
                    pose: troupe_msgs::Pose2d::new(1.0, 2.0, 0.5),
                },
            )
            .unwrap();
        assert!(h.reply::<common::Ack>(p).unwrap().is_ok());
        let p = h
            .request(sim, &simulation::GetPose2d { name: "r0".into() })
            .unwrap();
        assert_eq!(
            h.reply::<simulation::Pose2dOf>(p).unwrap().unwrap().pose,
            troupe_msgs::Pose2d::new(1.0, 2.0, 0.5)
        );
        let p = h
            .request(
                sim,
                &simulation::GetProperty {
                    name: "r0".into(),
                    prop: "color".into(),
                },
            )
            .unwrap();
        let col = h.reply::<simulation::Property>(p).unwrap().unwrap();
        assert_eq!(
            col.value,
            simulation::Value::Color(troupe_msgs::Color {
                r: 1.0,
                g: 0.0,
                b: 0.0,
                a: 1.0
            })
        );
        let p = h
            .request(
                sim,
                &simulation::GetProperty {
                    name: "r0".into(),
                    prop: "devices".into(),
                },
            )
            .unwrap();
        let devices = h.reply::<simulation::Property>(p).unwrap().unwrap();
        assert_eq!(
            devices.value,
            simulation::Value::Text("6665:position2d:0 6665:ranger:0 6665:ranger:1".into())
        );
        let p = h
            .request(
                sim,
                &simulation::GetPose2d {
                    name: "nobody".into(),
                },
            )
            .unwrap();
        assert!(h
            .reply::<simulation::Pose2dOf>(p)
            .unwrap()
            .unwrap_err()
            .contains("no model named `nobody`"));
    }

    /// Stage's ground model, which no world file names, is `model:0` and
    /// `_ground_model` to the simulation device, at the origin; a pose set
    /// on it is the pose it reports (as Player with Stage answers).
    #[test]
    fn the_ground_model_answers_by_stage_s_two_names() {
        let w = world_file("ground", WORLD);
        let mut h = Harness::<Stage>::from_json(&format!(
            r#"{{"name":"stage","provides":["simulation:0"],"options":{{"worldfile":"{}","step_when_told":1}}}}"#,
            w.display()
        ))
        .unwrap();
        let sim = dev(Interface::Simulation, 0);
        let pose_of = |h: &mut Harness<Stage>, name: &str| ask_pose(h, sim, name);
        for name in GROUND {
            assert_eq!(
                pose_of(&mut h, name).unwrap().pose,
                troupe_msgs::Pose2d::default()
            );
        }
        let to = troupe_msgs::Pose2d::new(1.0, 2.0, 0.5);
        let p = h
            .request(
                sim,
                &simulation::SetPose2d {
                    name: "_ground_model".into(),
                    pose: to,
                },
            )
            .unwrap();
        assert!(h.reply::<common::Ack>(p).unwrap().is_ok());
        assert_eq!(pose_of(&mut h, "model:0").unwrap().pose, to);
        assert!(pose_of(&mut h, "model:9").is_err(), "only the ground's");
        // In 3D too: at the ground's height, 0.
        let p = h
            .request(
                sim,
                &simulation::GetPose3d {
                    name: "model:0".into(),
                },
            )
            .unwrap();
        let p3 = h.reply::<simulation::Pose3dOf>(p).unwrap().unwrap().pose;
        assert_eq!((p3.x, p3.y, p3.z, p3.yaw), (1.0, 2.0, 0.0, 0.5));
    }

    #[test]
    fn a_pose_asked_for_is_kept_ready_and_renewed_as_the_model_moves() {
        let w = world_file("watched", WORLD);
        let mut h = Harness::<Stage>::from_json(&format!(
            r#"{{"name":"stage","provides":["simulation:0","position2d:0"],"options":{{"worldfile":"{}","model":"r0","step_when_told":1}}}}"#,
            w.display()
        ))
        .unwrap();
        let (sim, pos) = (dev(Interface::Simulation, 0), dev(Interface::Position2d, 0));
        let pose_of = |h: &mut Harness<Stage>, name: &str| ask_pose(h, sim, name).unwrap().pose;
        let start = pose_of(&mut h, "r0");
        assert_eq!((start.x, start.y), (0.0, 0.0));
        assert_eq!(pose_of(&mut h, "r0"), start, "the kept answer");
        let r0 = h.driver().sim.world().names["r0"];
        assert_eq!(h.driver().watched, [(sim, "r0".to_owned(), r0)]);
        // Set: the kept answer is renewed before the set is acknowledged.
        let to = troupe_msgs::Pose2d::new(1.0, -1.0, 0.5);
        let p = h
            .request(
                sim,
                &simulation::SetPose2d {
                    name: "r0".into(),
                    pose: to,
                },
            )
            .unwrap();
        assert!(h.reply::<common::Ack>(p).unwrap().is_ok());
        assert_eq!(pose_of(&mut h, "r0"), to);
        // Driven for a second: renewed after every step.
        h.command(
            pos,
            &position2d::CmdVel {
                vel: troupe_msgs::Pose2d::new(0.5, 0.0, 0.0),
                state: true,
            },
        )
        .unwrap();
        let p = h.request(sim, &simulation::Step { steps: 10 }).unwrap();
        assert!(h.reply::<common::Ack>(p).unwrap().is_ok());
        let moved = pose_of(&mut h, "r0");
        let gone = (moved.x - to.x).hypot(moved.y - to.y);
        assert!((gone - 0.5).abs() < 0.06, "{moved:?}");
        // Other models are asked for, and kept, separately.
        assert_eq!(pose_of(&mut h, "wall").x, 4.0);
        assert_eq!(h.driver().watched.len(), 2);
    }

    /// `stage_quirks 1` restores what Stage's plugin did where it ignores
    /// the interface; without it the interface is obeyed.
    #[test]
    fn stage_quirks_drive_with_motors_off_keep_gps_odometry_and_turn_cars() {
        let run = |quirks: u8| {
            let w = world_file(&format!("quirks{quirks}"), WORLD);
            let mut h = Harness::<Stage>::from_json(&format!(
                r#"{{"name":"stage","provides":["position2d:0"],"options":{{"worldfile":"{}","model":"r0","stage_quirks":{quirks}}}}}"#,
                w.display()
            ))
            .unwrap();
            let pos = dev(Interface::Position2d, 0);
            h.request(pos, &position2d::MotorPower { state: false })
                .unwrap();
            h.request(
                pos,
                &position2d::SetOdom {
                    pose: troupe_msgs::Pose2d::new(5.0, 5.0, 0.0),
                },
            )
            .unwrap();
            h.command(
                pos,
                &position2d::CmdCar {
                    velocity: 1.0,
                    angle: 0.5,
                },
            )
            .unwrap();
            for _ in 0..5 {
                h.tick().unwrap();
            }
            h.published::<position2d::Data>(pos).pop().unwrap()
        };
        // Stage's ways: it drives, turning at 0.5 rad/s, and the odometry
        // is the true pose whatever was set.
        let stage = run(1);
        assert!(stage.pose.x > 0.3 && stage.pose.x < 1.0, "{stage:?}");
        assert!((stage.vel.yaw - 0.5).abs() < 1e-9, "{stage:?}");
        // The interface's: motors off, so it stays where the odometry was set.
        let own = run(0);
        assert_eq!(
            (own.pose.x, own.pose.y, own.vel.x),
            (5.0, 5.0, 0.0),
            "{own:?}"
        );
    }

    #[test]
    fn step_when_told_steps_only_on_request() {
        let w = world_file("told", WORLD);
        let mut h = Harness::<Stage>::from_json(&format!(
            r#"{{"name":"stage","provides":["simulation:0"],"options":{{"worldfile":"{}","step_when_told":1}}}}"#,
            w.display()
        ))
        .unwrap();
        assert_eq!(h.tick_period(), None);
        let p = h
            .request(
                dev(Interface::Simulation, 0),
                &simulation::Step { steps: 3 },
            )
            .unwrap();
        assert!(h.reply::<common::Ack>(p).unwrap().is_ok());
        assert!((h.now() - 0.3).abs() < 1e-9, "{}", h.now());
    }

    #[test]
    fn quit_time_stops_the_node_or_its_clock_and_bad_sections_say_why() {
        let mut h = harness("quit", r#"["simulation:0"]"#);
        for _ in 0..9 {
            h.tick().unwrap();
            assert!(!h.stop_requested());
        }
        h.tick().unwrap();
        assert!(h.stop_requested(), "quit_time 1 s = 10 steps");
        // As Player's plugin: the clock stops, the node serves on.
        let w = world_file("pause", WORLD);
        let mut h = Harness::<Stage>::from_json(&format!(
            r#"{{"name":"stage","provides":["simulation:0"],"options":{{"worldfile":"{}","model":"r0","at_quit_time":"pause"}}}}"#,
            w.display()
        ))
        .unwrap();
        for _ in 0..15 {
            h.tick().unwrap();
        }
        assert!(!h.stop_requested());
        assert!(
            (h.now() - 1.0).abs() < 1e-9,
            "the clock ran on to {}",
            h.now()
        );
        let w = world_file("bad", WORLD);
        let e = |provides: &str, model: &str| {
            Harness::<Stage>::from_json(&format!(
                r#"{{"name":"stage","provides":{provides},"options":{{"worldfile":"{}","model":"{model}"}}}}"#,
                w.display()
            ))
            .err()
            .unwrap()
            .to_string()
        };
        assert!(
            e(r#"["position2d:0"]"#, "r9").contains("no model named `r9` (named models: r0, wall)")
        );
        assert!(e(r#"["position2d:0","position2d:1"]"#, "r0")
            .contains("has no unused position2d model"));
        assert!(e(r#"["power:0"]"#, "r0").contains("does not simulate power devices yet"));
        assert!(e(r#"["blobfinder:0"]"#, "r0").contains("has no unused blobfinder model"));
        let e = Harness::<Stage>::from_json(r#"{"name":"stage","provides":["simulation:0"]}"#)
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("`worldfile` is required"), "{e}");
    }
}
