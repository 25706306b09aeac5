//! Player's `p2os`: Pioneer robots (P2OS and ARCOS firmware) over a serial line.
//!
//! ```text
//! driver ( name "p2os" port "/dev/ttyUSB0"
//!          provides ["odometry:::position2d:0" "compass:::position2d:1"
//!                    "sonar:0" "power:0" "bumper:0" "aio:0" "dio:0"] )
//! ```
//!
//! | | |
//! |---|---|
//! | provides | `position2d` (the first one, or keyed `odometry`: odometry and velocity commands), `compass:::position2d`, `gyro:::position2d`, `sonar`, `power`, `bumper`, `aio`, `dio`, `gripper:::gripper`; other accessories Player offered (`blobfinder` of a CMUcam, `audio`, the arm…) are declared and stay silent, with a warning |
//! | requires | none |
//! | options | Player's: `port` ("/dev/ttyS0"), `max_xspeed` (0.5 m/s), `max_yawspeed` (100°/s), `direct_wheel_vel_control` (1), `use_vel_band` (0), `pulse` (−1: off), `bumpstall` (−1: leave), `gripper_pose` (6 values, m and rad: 0), `gripper_outersize` (0.315 0.195 0.035 m), `gripper_innersize` (0.205 0.095 0.035 m); Troupe's `watchdog` (2 s) |
//!
//! # Behavior
//!
//! - The line runs on a thread of its own ([`device`]): Player's baud-rate
//!   search and SYNC0/1/2 handshake, OPEN, then the robot's SIPs, ten a
//!   second. Each SIP publishes odometry (x, y, yaw from the wheel encoders'
//!   15-bit counters, velocities, stall), sonar ranges (sticky: each SIP
//!   brings some), battery, bumpers, the analog and digital inputs.
//! - The motors start disabled, as Player leaves them: a client enables
//!   them with the `motor_power` request. Velocity commands become VEL2
//!   wheel commands (or VEL + RVEL), limited by `max_xspeed`/`max_yawspeed`.
//! - `watchdog`: when no velocity command has come for that long while the
//!   robot was told to move, the driver stops it (0 turns this off; the
//!   robot's own firmware watchdog still stops it when the line goes quiet).
//!   On shutdown it sends STOP and CLOSE, as Player's `MainQuit`.
//! - The devices are not ready (liveliness withdrawn) until the robot is
//!   open, and again whenever the line is lost or the robot falls silent
//!   for a second; the driver resynchronises every 2 s, logging why.
//! - Requests: position2d `geom` (Player's pose (−0.1, 0) and the robot's
//!   size), `motor_power`, `set_odom`, `reset_odom` (SETO), `velocity_mode`;
//!   sonar `geom` (the subclass's sonar ring); bumper `geom`; gripper
//!   `geom` (the options' pose and sizes, two beams).
//! - Gyro: with a `gyro:::position2d`, the driver asks for ARCOS's gyro
//!   packets (GYRO 1) and publishes each packet's mean rate as Player did:
//!   the raw reading (0–1023, 512 when still) read as degrees in the yaw
//!   field, so Player clients see the numbers they saw.
//! - Gripper: `open`, `close`, `stop` commands become GRIPPER 1/2/3; each
//!   SIP publishes the paddles (open, closed, moving, or error) from the
//!   byte Player reads and the two break beams from digital inputs 1 and 2
//!   (Player ANDed those two bits into one that was always 0).
//! - Differences from Player, on purpose: positions use all 15 bits of the
//!   counters (Player masked 12 and dropped steps over 100 mm, so above
//!   1 m/s its odometry lost distance); yaw keeps the counter's resolution
//!   instead of whole degrees; every read has a deadline.

pub mod device;
pub mod emulator;
pub mod packet;
pub mod params;

use std::path::PathBuf;
use std::time::Duration;

use serde::Deserialize;
use troupe_geom::{Odometry, Pose};
use troupe_msgs::{
    aio, bumper, common, dio, gripper, position2d, power, sonar, Device, Interface, Pose2d, Pose3d,
    Size3d,
};
use troupe_node::{Ctx, Driver, Event, NodeError, Result, Section, Unit};
use troupe_serial::{CommandWatchdog, HeldLine};

use crate::device::{Line, Order, Settings, Update};
use crate::packet::Sip;
use crate::params::Params;

/// Options, by Player's names (and Troupe's `watchdog`).
#[derive(Debug, Deserialize)]
#[serde(default)]
#[allow(missing_docs)]
pub struct Options {
    pub port: PathBuf,
    pub max_xspeed: f64,
    pub max_yawspeed: f64,
    pub direct_wheel_vel_control: i64,
    pub use_vel_band: i64,
    pub pulse: f64,
    pub bumpstall: i64,
    pub watchdog: f64,
    pub gripper_pose: [f64; 6],
    pub gripper_outersize: [f64; 3],
    pub gripper_innersize: [f64; 3],
}

impl Default for Options {
    fn default() -> Self {
        Options {
            port: "/dev/ttyS0".into(),
            max_xspeed: 0.5,
            max_yawspeed: 100f64.to_radians(),
            direct_wheel_vel_control: 1,
            use_vel_band: 0,
            pulse: -1.0,
            bumpstall: -1,
            watchdog: 2.0,
            gripper_pose: [0.0; 6],
            gripper_outersize: [0.315, 0.195, 0.035],
            gripper_innersize: [0.205, 0.095, 0.035],
        }
    }
}

/// The devices the driver serves.
#[derive(Debug, Default)]
struct Devices {
    odometry: Option<Device>,
    compass: Option<Device>,
    gyro: Option<Device>,
    gripper: Option<Device>,
    sonar: Option<Device>,
    power: Option<Device>,
    bumper: Option<Device>,
    aio: Option<Device>,
    dio: Option<Device>,
    /// Accessories declared but not served (a CMUcam's blobfinder, sound…).
    silent: Vec<Device>,
}

/// Player's p2os geometry of a robot type: its body, 10 cm behind centre.
fn base_geom(p: &Params) -> position2d::Geom {
    position2d::Geom {
        pose: Pose3d::planar(-0.1, 0.0, 0.0),
        size: Size3d {
            length: p.length / 1000.0,
            width: p.width / 1000.0,
            height: 0.0,
        },
    }
}

/// The sonar ring of a robot type, in metres and radians.
fn sonar_geom(p: &Params) -> sonar::Geom {
    sonar::Geom {
        poses: p
            .sonars
            .iter()
            .map(|&(x, y, a)| {
                Pose3d::planar(
                    f64::from(x) / 1000.0,
                    f64::from(y) / 1000.0,
                    f64::from(a).to_radians(),
                )
            })
            .collect(),
    }
}

/// The p2os driver.
pub struct P2os {
    dev: Devices,
    settings: Settings,
    watchdog: CommandWatchdog,
    line: Option<Line>,
    params: Option<&'static Params>,
    odom: Odometry,
    pose: Pose,
    sonar: Vec<f32>,
    gripper_geom: gripper::Geom,
}

fn size([width, length, height]: [f64; 3]) -> Size3d {
    Size3d {
        length,
        width,
        height,
    }
}

/// Player's `FillStandard` gripper: the paddles' state from the high byte
/// of the SIP's timer word, the two break beams from digital inputs 1 and
/// 2. (Player ANDed the two input bits together, which is always 0; here
/// each beam is a bit of its own.)
fn gripper_data(sip: &Sip) -> gripper::Data {
    let g = sip.anport;
    let state = match (g & 0x01 != 0, g & 0x02 != 0, g & 0x04 != 0) {
        (true, true, false) => gripper::State::Error,
        (true, _, _) => gripper::State::Open,
        (false, true, _) => gripper::State::Closed,
        (false, false, true) => gripper::State::Moving,
        (false, false, false) => gripper::State::Error,
    };
    gripper::Data {
        state,
        beams: u32::from((sip.digin >> 1) & 0b11),
        stored: 0,
    }
}

impl Driver for P2os {
    const NAME: &'static str = "p2os";
    type Options = Options;
    const UNITS: &'static [(&'static str, Unit)] =
        &[("max_xspeed", Unit::Length), ("max_yawspeed", Unit::Angle)];

    fn new(section: &Section, o: Options) -> Result<Self> {
        let bad = |why: String| NodeError::config(Self::NAME, why);
        if o.max_xspeed <= 0.0 || o.max_yawspeed <= 0.0 {
            return Err(bad("max_xspeed and max_yawspeed must be positive".into()));
        }
        if o.bumpstall > 3 {
            return Err(bad(format!(
                "bumpstall {} is not one of -1, 0, 1, 2, 3",
                o.bumpstall
            )));
        }
        let mut dev = Devices::default();
        for slot in section.provided() {
            let d = slot.device;
            let key = slot.key.as_deref();
            let place = match (d.interface, key) {
                (Interface::Position2d, Some("compass")) => &mut dev.compass,
                (Interface::Position2d, Some("gyro")) => &mut dev.gyro,
                (Interface::Gripper, Some("gripper") | None) => &mut dev.gripper,
                (Interface::Position2d, Some("odometry") | None) => &mut dev.odometry,
                (Interface::Sonar, _) => &mut dev.sonar,
                (Interface::Power, _) => &mut dev.power,
                (Interface::Bumper, _) => &mut dev.bumper,
                (Interface::Aio, _) => &mut dev.aio,
                (Interface::Dio, _) => &mut dev.dio,
                _ => {
                    // Player's p2os offered these for optional hardware (a
                    // CMUcam, sound, an arm) and served nothing without it;
                    // its sample pioneer.cfg lists them all.
                    tracing::warn!(
                        "{d}{}: no support for this p2os accessory yet; the device is declared and stays silent",
                        key.map(|k| format!(" ({k})")).unwrap_or_default()
                    );
                    dev.silent.push(d);
                    continue;
                }
            };
            if place.is_some() {
                return Err(bad(format!(
                    "{d}: p2os provides one {} of this kind",
                    d.interface
                )));
            }
            *place = Some(d);
        }
        Ok(P2os {
            settings: Settings {
                port: o.port,
                sonar: dev.sonar.is_some(),
                direct_wheel: o.direct_wheel_vel_control != 0,
                max_speed: (o.max_xspeed * 1000.0).round() as i32,
                max_turn: o.max_yawspeed.to_degrees().round() as i32,
                vel_band: o.use_vel_band != 0,
                pulse: (o.pulse > 0.0).then(|| Duration::from_secs_f64(o.pulse)),
                bumpstall: u8::try_from(o.bumpstall).ok(),
                gyro: dev.gyro.is_some(),
            },
            gripper_geom: gripper::Geom {
                pose: Pose3d {
                    x: o.gripper_pose[0],
                    y: o.gripper_pose[1],
                    z: o.gripper_pose[2],
                    roll: o.gripper_pose[3],
                    pitch: o.gripper_pose[4],
                    yaw: o.gripper_pose[5],
                },
                outer_size: size(o.gripper_outersize),
                inner_size: size(o.gripper_innersize),
                num_beams: 2,
                capacity: 0,
            },
            dev,
            watchdog: CommandWatchdog::new(o.watchdog),
            line: None,
            params: None,
            odom: Odometry::new(15),
            pose: Pose::default(),
            sonar: Vec::new(),
        })
    }

    fn setup(&mut self, ctx: &mut Ctx) -> Result<()> {
        ctx.set_ready(false);
        // Player's first robot type until the robot says which it is.
        self.keep_geometry(ctx, &params::ROBOTS[0])?;
        // The gripper's comes from the cfg: the robot's type changes nothing.
        if let Some(d) = self.dev.gripper {
            ctx.answer_always::<gripper::GetGeom>(&d, &self.gripper_geom)?;
        }
        let line = device::spawn(self.settings.clone(), ctx.waker())
            .map_err(|e| NodeError::Driver(format!("starting the line thread: {e}").into()))?;
        tracing::info!("robot initialising ({})", self.settings.port.display());
        self.line = Some(line);
        ctx.set_tick(self.watchdog.tick());
        Ok(())
    }

    fn on_event(&mut self, ctx: &mut Ctx, event: Event) -> Result<()> {
        match event {
            Event::Wake => self.drain(ctx),
            Event::Tick => {
                if self.watchdog.expired(ctx.now()) {
                    self.line.order(Order::Vel { speed: 0, turn: 0 });
                }
                Ok(())
            }
            Event::Command(c) if c.is::<position2d::CmdVel>() => {
                let v = c.decode::<position2d::CmdVel>()?.msg.vel;
                let speed = (v.x * 1000.0).round() as i32;
                let turn = v.yaw.to_degrees().round() as i32;
                self.watchdog.commanded(ctx.now(), speed != 0 || turn != 0);
                self.line.order(Order::Vel { speed, turn });
                Ok(())
            }
            Event::Command(c) if c.is::<gripper::Open>() => {
                self.line.order(Order::Gripper(packet::grip::OPEN));
                Ok(())
            }
            Event::Command(c) if c.is::<gripper::Close>() => {
                self.line.order(Order::Gripper(packet::grip::CLOSE));
                Ok(())
            }
            Event::Command(c) if c.is::<gripper::Stop>() => {
                self.line.order(Order::Gripper(packet::grip::STOP));
                Ok(())
            }
            Event::Command(c) => Err(c.unexpected()),
            Event::Request(r) if r.is::<position2d::MotorPower>() => {
                let on = r.decode::<position2d::MotorPower>()?.state;
                self.line.order(Order::Enable(on));
                r.reply(&common::Ack);
                Ok(())
            }
            Event::Request(r) if r.is::<position2d::ResetOdom>() => {
                self.line.order(Order::ResetOdom);
                self.odom = Odometry::new(15);
                r.reply(&common::Ack);
                Ok(())
            }
            Event::Request(r) if r.is::<position2d::SetOdom>() => {
                let want: Pose = r.decode::<position2d::SetOdom>()?.pose.into();
                self.odom.set(self.pose, want);
                self.pose = want;
                r.reply(&common::Ack);
                Ok(())
            }
            Event::Request(r) if r.is::<position2d::VelocityMode>() => {
                let separate = r.decode::<position2d::VelocityMode>()?.value != 0;
                self.line.order(Order::DirectWheel(!separate));
                r.reply(&common::Ack);
                Ok(())
            }
            Event::Request(r) => {
                r.unhandled(Self::NAME);
                Ok(())
            }
            Event::Data(_) | Event::Reply(_) => Ok(()),
        }
    }

    fn shutdown(&mut self, _: &mut Ctx) -> Result<()> {
        self.line.stop_with(Order::Stop);
        Ok(())
    }
}

impl P2os {
    /// The geometry of the robot's type, answered without waking this
    /// thread ([`Ctx::answer_always`]).
    fn keep_geometry(&self, ctx: &mut Ctx, p: &Params) -> Result<()> {
        if let Some(d) = self.dev.odometry {
            ctx.answer_always::<position2d::GetGeom>(&d, &base_geom(p))?;
        }
        if let Some(d) = self.dev.sonar {
            ctx.answer_always::<sonar::GetGeom>(&d, &sonar_geom(p))?;
        }
        if let Some(d) = self.dev.bumper {
            let n = usize::from(p.front_bumpers + p.rear_bumpers);
            // Player's tables give every bumper a zero geometry.
            let geom = bumper::Geom {
                bumpers: vec![bumper::Define::default(); n],
            };
            ctx.answer_always::<bumper::GetGeom>(&d, &geom)?;
        }
        Ok(())
    }

    fn drain(&mut self, ctx: &mut Ctx) -> Result<()> {
        for u in self.line.updates_now() {
            match u {
                Update::Ready { name, params, baud } => {
                    tracing::info!(
                        "robot ready: {} ({} {}) at {baud} baud; motors off until a client enables them",
                        name.0,
                        name.1,
                        name.2
                    );
                    self.params = Some(params);
                    self.keep_geometry(ctx, params)?;
                    self.odom = Odometry::new(15);
                    self.sonar = vec![0.0; params.sonars.len()];
                    ctx.set_ready(true);
                }
                Update::Lost(why) => {
                    if ctx.is_ready() {
                        tracing::warn!("robot lost: {why}");
                    }
                    ctx.set_ready(false);
                }
                Update::Sip(sip) => self.publish(ctx, &sip)?,
                Update::Gyro(rate) => {
                    if let Some(d) = self.dev.gyro {
                        // Player's `FillGyro`: the raw rate, read as degrees.
                        let yaw = f64::from(rate).to_radians();
                        let pose = Pose2d {
                            x: 0.0,
                            y: 0.0,
                            yaw,
                        };
                        ctx.publish(
                            &d,
                            &position2d::Data {
                                pose,
                                ..Default::default()
                            },
                        )?;
                    }
                }
            }
        }
        Ok(())
    }

    /// Player's `FillStandard`, from one SIP.
    fn publish(&mut self, ctx: &mut Ctx, sip: &Sip) -> Result<()> {
        let Some(p) = self.params else {
            return Ok(());
        };
        self.pose = self.odom.update(
            sip.xpos,
            sip.ypos,
            f64::from(sip.th) * p.angle_conv,
            p.dist_conv,
        );
        if let Some(d) = self.dev.odometry {
            let (l, r) = (
                f64::from(sip.lvel) * p.vel_conv,
                f64::from(sip.rvel) * p.vel_conv,
            );
            ctx.publish(
                &d,
                &position2d::Data {
                    pose: self.pose.into(),
                    vel: Pose2d {
                        x: (l + r) / 2.0 / 1000.0,
                        y: 0.0,
                        yaw: (r - l) * p.diff_conv / 2.0,
                    },
                    stall: (sip.lstall | sip.rstall) & 1 != 0,
                },
            )?;
        }
        if let Some(d) = self.dev.compass {
            if !matches!(sip.compass, 0 | 181 | 255) {
                let deg = (f64::from(sip.compass) - 1.0) * 2.0;
                ctx.publish(
                    &d,
                    &position2d::Data {
                        pose: Pose2d {
                            x: 0.0,
                            y: 0.0,
                            yaw: deg.to_radians(),
                        },
                        ..Default::default()
                    },
                )?;
            }
        }
        if let Some(d) = self.dev.sonar {
            for &(i, range) in &sip.sonars {
                if let Some(slot) = self.sonar.get_mut(usize::from(i)) {
                    *slot = (f64::from(range) * p.range_conv / 1000.0) as f32;
                }
            }
            ctx.publish(
                &d,
                &sonar::Ranges {
                    ranges: self.sonar.clone(),
                },
            )?;
        }
        if let Some(d) = self.dev.gripper {
            ctx.publish(&d, &gripper_data(sip))?;
        }
        if let Some(d) = self.dev.power {
            let volts = f32::from(sip.battery) / 10.0;
            ctx.publish(&d, &power::Data::battery(volts, 12.0))?;
        }
        if let Some(d) = self.dev.bumper {
            let bits = |byte: u8, n: u8| (0..n).rev().map(move |b| (byte >> 1) & (1 << b) != 0);
            let bumpers = bits(sip.rstall, p.front_bumpers)
                .chain(bits(sip.lstall, p.rear_bumpers))
                .collect();
            ctx.publish(&d, &bumper::Data { bumpers })?;
        }
        if let Some(d) = self.dev.dio {
            ctx.publish(
                &d,
                &dio::Data {
                    count: 8,
                    bits: u32::from(sip.digin),
                },
            )?;
        }
        if let Some(d) = self.dev.aio {
            ctx.publish(
                &d,
                &aio::Data {
                    voltages: vec![f32::from(sip.analog) / 255.0 * 5.0],
                },
            )?;
        }
        Ok(())
    }
}
