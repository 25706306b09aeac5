//! Player's `wbr914`: White Box Robotics' 914 PC-Bot, whose M3 board
//! drives two stepper wheels through PMD motion chips over a serial line.
//!
//! ```text
//! driver ( name "wbr914" provides ["position2d:0" "ir:0" "aio:0" "dio:0"]
//!          port "/dev/ttyUSB0" )
//! ```
//!
//! | | |
//! |---|---|
//! | provides | `position2d`, `ir` (8 Sharp sensors), `aio` (8 inputs of the second I/O board), `dio` (16 inputs and outputs) |
//! | requires | none |
//! | options | Player's: `port` ("/dev/ttyUSB0"), `torque` (75 %, 20–100), `debug` (0: 1 logs every command and reply); Troupe's `watchdog` (2 s) |
//!
//! # Behavior
//!
//! - The line runs on its own thread ([`device`]) at 416666 baud, 8N2
//!   ([`pmd`]), set up as Player's `MainSetup` does, and polled every
//!   100 ms for what the cfg provides (Player polled as fast as the line
//!   went, with a 10 ms pause before each reply).
//! - position2d: odometry from the wheels' counts ([`robot::Odometry`]),
//!   velocities from the chips'; velocity commands within 0.3 m/s a wheel
//!   (the other wheel scaled alike); motors off until a client asks
//!   (`motor_power`), as in Player; `reset_odom`, `set_odom`, the body's
//!   geometry (0.42 × 0.37 m). `watchdog`: no velocity command for that
//!   long while moving stops the robot.
//! - ir: the eight sensors' volts and ranges by Player's fits (0.1–0.8 m,
//!   sensors 5 and 7 0.2–1.5 m), and their poses. aio: eight volts.
//!   dio: 16 inputs (the second board's in the upper byte), commands set
//!   the first `count` outputs and keep the rest.
//! - Not ready (liveliness withdrawn) until the board answers, and
//!   whenever it is lost; reconnects every 2 s, logging why. Missed
//!   replies are counted, the first one logged. Shutdown stops the wheels,
//!   powers the motors off and resets the chips (Player's `MainQuit`).
//! - Fixed from Player: the heading turns the way the robot does (Player's
//!   ran against its own turn commands); `set_odom` keeps the wheel counts
//!   (Player's wrote x and y into the left chip); full torque does not
//!   overflow to a negative one.

pub mod device;
pub mod emulator;
pub mod pmd;
pub mod robot;

use std::path::PathBuf;

use serde::Deserialize;
use troupe_geom::Pose;
use troupe_msgs::{aio, common, dio, ir, position2d, Device, Interface, Pose2d, Pose3d, Size3d};
use troupe_node::{Ctx, Driver, Event, NodeError, Result, Section, Unit};
use troupe_serial::{CommandWatchdog, HeldLine};

use crate::device::{Line, Order, Sample, Settings, Update};

/// Options, by Player's names (and Troupe's `watchdog`).
#[derive(Debug, Deserialize)]
#[serde(default)]
#[allow(missing_docs)]
pub struct Options {
    pub port: PathBuf,
    pub torque: i64,
    pub debug: i64,
    pub watchdog: f64,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            port: "/dev/ttyUSB0".into(),
            torque: robot::DEFAULT_TORQUE,
            debug: 0,
            watchdog: 2.0,
        }
    }
}

#[derive(Debug, Default)]
struct Devices {
    position: Option<Device>,
    ir: Option<Device>,
    aio: Option<Device>,
    dio: Option<Device>,
}

/// The 914's body, centred on its axle.
fn base_geom() -> position2d::Geom {
    let (length, width, height) = robot::SIZE;
    position2d::Geom {
        pose: Pose3d::default(),
        size: Size3d {
            length,
            width,
            height,
        },
    }
}

fn ir_geom() -> ir::Geom {
    ir::Geom {
        poses: robot::IR_POSES
            .iter()
            .map(|&(x, y, a)| Pose3d::planar(x, y, a.to_radians()))
            .collect(),
    }
}

/// The wbr914 driver.
pub struct Wbr914 {
    dev: Devices,
    settings: Settings,
    watchdog: CommandWatchdog,
    line: Option<Line>,
}

impl Driver for Wbr914 {
    const NAME: &'static str = "wbr914";
    type Options = Options;
    const UNITS: &'static [(&'static str, Unit)] = &[];

    fn new(section: &Section, o: Options) -> Result<Self> {
        let bad = |why: String| NodeError::config(Self::NAME, why);
        let mut dev = Devices::default();
        for slot in section.provided() {
            let d = slot.device;
            let place = match d.interface {
                Interface::Position2d => &mut dev.position,
                Interface::Ir => &mut dev.ir,
                Interface::Aio => &mut dev.aio,
                Interface::Dio => &mut dev.dio,
                i => {
                    return Err(bad(format!(
                        "wbr914 does not provide {i} ({d}); it provides position2d, ir, aio and dio"
                    )))
                }
            };
            if place.is_some() {
                return Err(bad(format!("{d}: wbr914 provides one such device")));
            }
            *place = Some(d);
        }
        let torque = o.torque.clamp(20, 100);
        if torque != o.torque {
            tracing::warn!(
                "torque {} is outside 20–100 %: using {torque}, as Player does",
                o.torque
            );
        }
        Ok(Wbr914 {
            settings: Settings {
                port: o.port,
                torque,
                position: dev.position.is_some(),
                ir: dev.ir.is_some(),
                aio: dev.aio.is_some(),
                dio: dev.dio.is_some(),
                debug: o.debug != 0,
            },
            dev,
            watchdog: CommandWatchdog::new(o.watchdog),
            line: None,
        })
    }

    fn setup(&mut self, ctx: &mut Ctx) -> Result<()> {
        ctx.set_ready(false);
        if let Some(d) = self.dev.position {
            ctx.answer_always::<position2d::GetGeom>(&d, &base_geom())?;
        }
        if let Some(d) = self.dev.ir {
            ctx.answer_always::<ir::GetGeom>(&d, &ir_geom())?;
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
                    self.line.order(Order::Vel(0.0, 0.0));
                }
                Ok(())
            }
            Event::Command(c) if c.is::<position2d::CmdVel>() => {
                let v = c.decode::<position2d::CmdVel>()?.msg.vel;
                self.watchdog
                    .commanded(ctx.now(), v.x != 0.0 || v.yaw != 0.0);
                self.line.order(Order::Vel(v.x, v.yaw));
                Ok(())
            }
            Event::Command(c) if c.is::<dio::Cmd>() => {
                let cmd = c.decode::<dio::Cmd>()?.msg;
                self.line.order(Order::Dio(cmd.count, cmd.bits));
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
                r.reply(&common::Ack);
                Ok(())
            }
            Event::Request(r) if r.is::<position2d::SetOdom>() => {
                let pose: Pose = r.decode::<position2d::SetOdom>()?.pose.into();
                self.line.order(Order::SetOdom(pose));
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

impl Wbr914 {
    fn drain(&mut self, ctx: &mut Ctx) -> Result<()> {
        for u in self.line.updates_now() {
            match u {
                Update::Ready { versions, cycle_us } => {
                    tracing::info!(
                        "robot ready: motion chips version {:#X} and {:#X}, cycle {cycle_us} µs; motors off until a client enables them",
                        versions.0,
                        versions.1
                    );
                    ctx.set_ready(true);
                }
                Update::Lost(why) => {
                    if ctx.is_ready() {
                        tracing::warn!("robot lost: {why}");
                    }
                    ctx.set_ready(false);
                }
                Update::Sample(s) => self.publish(ctx, &s)?,
            }
        }
        Ok(())
    }

    fn publish(&mut self, ctx: &mut Ctx, s: &Sample) -> Result<()> {
        if let (Some(d), Some(m)) = (self.dev.position, s.motion) {
            ctx.publish(
                &d,
                &position2d::Data {
                    pose: m.pose.into(),
                    vel: Pose2d {
                        x: m.speed,
                        y: 0.0,
                        yaw: m.turn,
                    },
                    stall: false,
                },
            )?;
        }
        if let (Some(d), Some(counts)) = (self.dev.ir, s.ir) {
            let voltages = counts.iter().map(|&c| robot::volts(c)).collect();
            let ranges = (0..)
                .zip(counts)
                .map(|(i, c)| robot::ir_range(i, c))
                .collect();
            ctx.publish(&d, &ir::Data { voltages, ranges })?;
        }
        if let (Some(d), Some(counts)) = (self.dev.aio, s.aio) {
            let voltages = counts.iter().map(|&c| robot::volts(c)).collect();
            ctx.publish(&d, &aio::Data { voltages })?;
        }
        if let (Some(d), Some(board)) = (self.dev.dio, s.dio) {
            ctx.publish(
                &d,
                &dio::Data {
                    count: 16,
                    bits: robot::digital_in(board),
                },
            )?;
        }
        Ok(())
    }
}
