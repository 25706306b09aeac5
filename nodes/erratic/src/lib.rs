//! Player's `erratic`: the Videre Erratic robot over a serial line.
//!
//! ```text
//! driver ( name "erratic" port "/dev/erratic"
//!          provides ["position2d:0" "power:0" "aio:0" "ir:0" "sonar:0" "ptz:0" "tilt:::ptz:1"] )
//! ```
//!
//! | | |
//! |---|---|
//! | provides | `position2d`, `power`, `aio`, `ir`, `sonar`, `ptz` (pan-tilt on servos 2 and 1), `tilt:::ptz` (tilt on servo 0) |
//! | requires | none |
//! | options | Player's: `port` ("/dev/erratic"), `direct_wheel_vel_control` (0), `max_trans_vel` (0.5 m/s), `max_rot_vel` (100°/s), `trans_acc`, `trans_decel`, `rot_acc`, `rot_decel` (0: the robot's), `pid_trans_p/v/i`, `pid_rot_p/v/i` (−1: the robot's), `motor_pwm_frequency`, `motor_pwm_max_on` (unset: the robot's), `save_settings_in_robot` (0); Troupe's `watchdog` (2 s) |
//!
//! # Behavior
//!
//! - The line runs on its own thread ([`device`]): the configuration
//!   request at 38400 then 115200 baud (Player's table had a bug that read
//!   past its two rates), OPEN, the cfg's settings, sonar and analog on
//!   when provided. Motor packets publish odometry (12-bit counters,
//!   heading 4096 per turn), velocities, stall and battery; sonar packets
//!   the 8 sonars (sticky); analog packets `aio` (the ADC channels in volts
//!   and 4 digital bits) and `ir` (the two floor sensors: 0.1 m over floor,
//!   1 m over a drop).
//! - Motors start disabled until a client asks (`motor_power`); velocity
//!   commands become VEL + RVEL or VEL2 within `max_trans_vel`/`max_rot_vel`;
//!   the newest command always goes out (Player dropped commands within
//!   50 ms of the last, even a final stop). `watchdog`: no velocity command
//!   for that long while moving stops the robot. Shutdown sends STOP and
//!   CLOSE (Player's `Disconnect`, which it never called).
//! - `ptz` commands move the servos (6.5 counts per degree around 1650,
//!   clamped to 1100–2300) and the commanded pan and tilt are published.
//! - Not ready (liveliness withdrawn) until open, and whenever the line is
//!   lost; reconnects every 2 s, logging why. Nothing panics.
//! - Fixed from Player: `set_odom` sets the pose (Player's reported the
//!   negated pose); settings it never meant to send (PWM values from a −1
//!   default) are not sent; analog packets are read with their own channel
//!   count (Player's wrote past its arrays).

pub mod device;
pub mod emulator;
pub mod packet;
pub mod params;

use std::path::PathBuf;

use serde::Deserialize;
use troupe_geom::{Odometry, Pose};
use troupe_msgs::{
    aio, common, ir, position2d, power, ptz, sonar, Device, Interface, Pose2d, Pose3d, Size3d,
};
use troupe_node::{Ctx, Driver, Event, NodeError, Result, Section, Unit};
use troupe_serial::{CommandWatchdog, HeldLine};

use crate::device::{Line, Order, Settings, Update};
use crate::packet::{cmd, command_int, frame, kind, Motor};
use crate::params::Params;

/// Options, by Player's names (and Troupe's `watchdog`).
#[derive(Debug, Deserialize)]
#[serde(default)]
#[allow(missing_docs)]
pub struct Options {
    pub port: PathBuf,
    pub direct_wheel_vel_control: i64,
    pub max_trans_vel: f64,
    pub max_rot_vel: f64,
    pub trans_acc: f64,
    pub trans_decel: f64,
    pub rot_acc: f64,
    pub rot_decel: f64,
    pub pid_trans_p: i64,
    pub pid_trans_v: i64,
    pub pid_trans_i: i64,
    pub pid_rot_p: i64,
    pub pid_rot_v: i64,
    pub pid_rot_i: i64,
    pub motor_pwm_frequency: i64,
    pub motor_pwm_max_on: f64,
    pub save_settings_in_robot: i64,
    pub watchdog: f64,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            port: "/dev/erratic".into(),
            direct_wheel_vel_control: 0,
            max_trans_vel: 0.5,
            max_rot_vel: 100f64.to_radians(),
            trans_acc: 0.0,
            trans_decel: 0.0,
            rot_acc: 0.0,
            rot_decel: 0.0,
            pid_trans_p: -1,
            pid_trans_v: -1,
            pid_trans_i: -1,
            pid_rot_p: -1,
            pid_rot_v: -1,
            pid_rot_i: -1,
            motor_pwm_frequency: -1,
            motor_pwm_max_on: -1.0,
            save_settings_in_robot: 0,
            watchdog: 2.0,
        }
    }
}

/// The settings Player writes after OPEN, in its order, each only when set.
fn startup(o: &Options) -> Result<Vec<Vec<u8>>> {
    let bad = |why: String| NodeError::config("erratic", why);
    let mut out = Vec::new();
    let mut acc = |c: u8, acc: f64, decel: f64| {
        let (a, d) = (acc.round() as i32, decel.abs().round() as i32);
        if a != 0 {
            out.push(command_int(c, a));
        }
        match (d, a) {
            (0, 0) => {}
            (0, a) => out.push(command_int(c, -a)),
            (d, _) => out.push(command_int(c, -d)),
        }
    };
    acc(cmd::TRANS_ACC, o.trans_acc * 1000.0, o.trans_decel * 1000.0);
    acc(
        cmd::ROT_ACC,
        o.rot_acc.to_degrees(),
        o.rot_decel.to_degrees(),
    );
    let pids = [
        o.pid_trans_p,
        o.pid_trans_v,
        o.pid_trans_i,
        o.pid_rot_p,
        o.pid_rot_v,
        o.pid_rot_i,
    ];
    for (c, v) in cmd::PID.into_iter().zip(pids) {
        if v > i64::from(u16::MAX) {
            return Err(bad(format!(
                "PID gain {v} does not fit the robot's 16 bits"
            )));
        }
        if v >= 0 {
            out.push(command_int(c, v as i32));
        }
    }
    match o.motor_pwm_frequency {
        f if f > 0 && f <= i64::from(u16::MAX) => out.push(command_int(cmd::PWM_FREQ, f as i32)),
        f if f > 0 => return Err(bad(format!("motor_pwm_frequency {f} does not fit 16 bits"))),
        _ => {}
    }
    match o.motor_pwm_max_on {
        m if m > 0.0 && m <= 1.0 => {
            out.push(command_int(cmd::PWM_MAX_ON, (m * 1000.0).round() as i32))
        }
        m if m > 1.0 => {
            return Err(bad(format!(
                "motor_pwm_max_on {m} is a duty cycle: at most 1"
            )))
        }
        _ => {}
    }
    if o.save_settings_in_robot != 0 {
        out.push(frame(&[cmd::SAVE, 0, 0, 0]));
    }
    Ok(out)
}

#[derive(Debug, Default)]
struct Devices {
    position: Option<Device>,
    power: Option<Device>,
    aio: Option<Device>,
    ir: Option<Device>,
    sonar: Option<Device>,
    /// Pan on servo 2, tilt on servo 1.
    ptz: Option<Device>,
    /// Tilt on servo 0.
    tilt: Option<Device>,
}

/// Player's erratic geometry: the body, centred on the axle offset.
fn base_geom() -> position2d::Geom {
    position2d::Geom {
        pose: Pose3d::planar(-params::AXLE_OFFSET, 0.0, 0.0),
        size: Size3d {
            length: params::SIZE.0,
            width: params::SIZE.1,
            height: 0.0,
        },
    }
}

fn ir_geom() -> ir::Geom {
    ir::Geom {
        poses: params::IR_POSES
            .iter()
            .map(|&(x, y)| Pose3d::planar(x, y, 0.0))
            .collect(),
    }
}

/// The erratic driver.
pub struct Erratic {
    dev: Devices,
    settings: Settings,
    watchdog: CommandWatchdog,
    line: Option<Line>,
    params: Option<&'static Params>,
    odom: Odometry,
    pose: Pose,
    sonar: Vec<f32>,
}

impl Driver for Erratic {
    const NAME: &'static str = "erratic";
    type Options = Options;
    const UNITS: &'static [(&'static str, Unit)] = &[
        ("max_trans_vel", Unit::Length),
        ("max_rot_vel", Unit::Angle),
        ("trans_acc", Unit::Length),
        ("trans_decel", Unit::Length),
        ("rot_acc", Unit::Angle),
        ("rot_decel", Unit::Angle),
    ];

    fn new(section: &Section, o: Options) -> Result<Self> {
        let bad = |why: String| NodeError::config(Self::NAME, why);
        if o.max_trans_vel <= 0.0 || o.max_rot_vel <= 0.0 {
            return Err(bad("max_trans_vel and max_rot_vel must be positive".into()));
        }
        let mut dev = Devices::default();
        for slot in section.provided() {
            let d = slot.device;
            let place = match (d.interface, slot.key.as_deref()) {
                (Interface::Position2d, _) => &mut dev.position,
                (Interface::Power, _) => &mut dev.power,
                (Interface::Aio, _) => &mut dev.aio,
                (Interface::Ir, _) => &mut dev.ir,
                (Interface::Sonar, _) => &mut dev.sonar,
                (Interface::Ptz, Some("tilt")) => &mut dev.tilt,
                (Interface::Ptz, _) => &mut dev.ptz,
                (i, _) => {
                    return Err(bad(format!(
                        "erratic does not provide {i} ({d}); it provides position2d, power, aio, ir, sonar, ptz and tilt:::ptz"
                    )))
                }
            };
            if place.is_some() {
                return Err(bad(format!("{d}: erratic provides one such device")));
            }
            *place = Some(d);
        }
        Ok(Erratic {
            settings: Settings {
                port: o.port.clone(),
                direct_wheel: o.direct_wheel_vel_control != 0,
                max_speed: (o.max_trans_vel * 1000.0).round() as i32,
                max_turn: o.max_rot_vel.to_degrees().round() as i32,
                sonar: dev.sonar.is_some(),
                analog: dev.aio.is_some() || dev.ir.is_some(),
                startup: startup(&o)?,
            },
            dev,
            watchdog: CommandWatchdog::new(o.watchdog),
            line: None,
            params: None,
            odom: Odometry::new(12),
            pose: Pose::default(),
            sonar: vec![0.0; 8],
        })
    }

    fn setup(&mut self, ctx: &mut Ctx) -> Result<()> {
        ctx.set_ready(false);
        // Every Erratic has the same body and IR sensors, answered without
        // waking this thread; its sonars are the first revision's until the
        // robot says which it is.
        if let Some(d) = self.dev.position {
            ctx.answer_always::<position2d::GetGeom>(&d, &base_geom())?;
        }
        if let Some(d) = self.dev.ir {
            ctx.answer_always::<ir::GetGeom>(&d, &ir_geom())?;
        }
        self.keep_sonar_geometry(ctx, &params::REVISIONS[0])?;
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
            Event::Command(c) if c.is::<ptz::Cmd>() => {
                let target = c.decode::<ptz::Cmd>()?.msg.target;
                let dev = c.device;
                if Some(dev) == self.dev.tilt {
                    self.line.order(Order::Servo(0, f64::from(target.tilt)));
                } else {
                    self.line.order(Order::Servo(2, f64::from(target.pan)));
                    self.line.order(Order::Servo(1, f64::from(target.tilt)));
                }
                let clamp = |a: f32| {
                    let deg = f64::from(a).to_degrees().trunc();
                    let lim = (f64::from(packet::SERVO_RANGE.1) - packet::SERVO_NEUTRAL)
                        / packet::SERVO_PER_DEG;
                    let low = (f64::from(packet::SERVO_RANGE.0) - packet::SERVO_NEUTRAL)
                        / packet::SERVO_PER_DEG;
                    deg.clamp(low, lim).to_radians() as f32
                };
                ctx.publish(
                    &dev,
                    &ptz::Data {
                        pan: if Some(dev) == self.dev.tilt {
                            0.0
                        } else {
                            clamp(target.pan)
                        },
                        tilt: clamp(target.tilt),
                        ..Default::default()
                    },
                )?;
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
                self.odom.set(self.pose, Pose::default());
                self.pose = Pose::default();
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

impl Erratic {
    /// The sonar ring of a revision, answered without waking this thread.
    fn keep_sonar_geometry(&self, ctx: &mut Ctx, p: &params::Params) -> Result<()> {
        let Some(d) = self.dev.sonar else {
            return Ok(());
        };
        let geom = sonar::Geom {
            poses: p
                .sonars
                .iter()
                .map(|&(x, y, a)| Pose3d::planar(x, y, a.to_radians()))
                .collect(),
        };
        ctx.answer_always::<sonar::GetGeom>(&d, &geom)
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
                    self.keep_sonar_geometry(ctx, params)?;
                    self.odom = Odometry::new(12);
                    ctx.set_ready(true);
                }
                Update::Lost(why) => {
                    if ctx.is_ready() {
                        tracing::warn!("robot lost: {why}");
                    }
                    ctx.set_ready(false);
                }
                Update::Packet(p) => self.publish(ctx, &p)?,
            }
        }
        Ok(())
    }

    fn publish(&mut self, ctx: &mut Ctx, p: &[u8]) -> Result<()> {
        let Some(params) = self.params else {
            return Ok(());
        };
        match p.first() {
            Some(k) if kind::MOTOR.contains(k) => {
                let m = match Motor::decode(p) {
                    Ok(m) => m,
                    Err(e) => {
                        tracing::warn!("motor packet dropped: {e}");
                        return Ok(());
                    }
                };
                let yaw = f64::from(m.th) * std::f64::consts::PI / 2048.0;
                self.pose = self.odom.update(m.x, m.y, yaw, params.dist_conv);
                if let Some(d) = self.dev.position {
                    let (l, r) = (
                        f64::from(m.lvel) * params::VEL_CONV,
                        f64::from(m.rvel) * params::VEL_CONV,
                    );
                    ctx.publish(
                        &d,
                        &position2d::Data {
                            pose: self.pose.into(),
                            vel: Pose2d {
                                x: (l + r) / 2.0 / 1000.0,
                                y: 0.0,
                                yaw: (r - l) * params::DIFF_CONV / 2.0,
                            },
                            stall: (m.lstall | m.rstall) & 1 != 0,
                        },
                    )?;
                }
                if let Some(d) = self.dev.power {
                    let volts = f32::from(m.battery) / 10.0;
                    ctx.publish(&d, &power::Data::battery(volts, 12.0))?;
                }
            }
            Some(&kind::SONAR) => match packet::decode_sonar(p) {
                Ok(readings) => {
                    for (c, mm) in readings {
                        if let Some(slot) = self.sonar.get_mut(usize::from(c)) {
                            *slot = f32::from(mm) / 1000.0;
                        }
                    }
                    if let Some(d) = self.dev.sonar {
                        ctx.publish(
                            &d,
                            &sonar::Ranges {
                                ranges: self.sonar.clone(),
                            },
                        )?;
                    }
                }
                Err(e) => tracing::warn!("sonar packet dropped: {e}"),
            },
            Some(&kind::ANALOG) => match packet::decode_analog(p) {
                Ok((words, dig)) => {
                    let bit = |k: usize| {
                        if (dig >> (4 + k)) & 1 == 1 {
                            1.0f32
                        } else {
                            0.0
                        }
                    };
                    if let Some(d) = self.dev.aio {
                        let mut voltages: Vec<f32> = words
                            .iter()
                            .map(|&w| (f64::from(w) * params::ADC_VOLTS) as f32)
                            .collect();
                        voltages.extend((0..4).map(bit));
                        ctx.publish(&d, &aio::Data { voltages })?;
                    }
                    if let Some(d) = self.dev.ir {
                        let voltages: Vec<f32> = (0..params::IR_POSES.len()).map(bit).collect();
                        let ranges = voltages
                            .iter()
                            .map(|&v| if v >= 0.9 { 0.1 } else { 1.0 })
                            .collect();
                        ctx.publish(&d, &ir::Data { voltages, ranges })?;
                    }
                }
                Err(e) => tracing::warn!("analog packet dropped: {e}"),
            },
            _ => {}
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn startup_settings_are_players_and_only_when_set() {
        assert!(
            startup(&Options::default()).unwrap().is_empty(),
            "nothing by default"
        );
        let o = Options {
            trans_acc: 0.5,
            rot_acc: 100f64.to_radians(),
            pid_trans_p: 40,
            pid_rot_v: 100,
            motor_pwm_frequency: 16000,
            motor_pwm_max_on: 0.7,
            ..Options::default()
        };
        let s = startup(&o).unwrap();
        assert_eq!(
            s,
            vec![
                command_int(cmd::TRANS_ACC, 500),
                command_int(cmd::TRANS_ACC, -500),
                command_int(cmd::ROT_ACC, 100),
                command_int(cmd::ROT_ACC, -100),
                command_int(80, 40),
                command_int(84, 100),
                command_int(cmd::PWM_FREQ, 16000),
                command_int(cmd::PWM_MAX_ON, 700),
            ]
        );
        let too_much = Options {
            motor_pwm_max_on: 1.5,
            ..Options::default()
        };
        assert!(startup(&too_much).is_err());
    }
}
