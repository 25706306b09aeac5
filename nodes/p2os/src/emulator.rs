//! An emulated Pioneer (ARCOS firmware) on a pseudo-terminal.
//!
//! It answers SYNC0/1/2 with echoes and a SYNC2 reply naming the robot,
//! opens on OPEN, then sends a standard SIP every 100 ms: odometry from
//! differential-drive kinematics in an 8 m × 6 m room (the robot starts in
//! the middle facing +x and stalls against the walls), wheel velocities,
//! battery, stall bits and, when on, its sonar ring's ranges to the walls.
//! It obeys ENABLE, SETO, VEL2, VEL/RVEL, SONAR, STOP and CLOSE, and
//! stops the wheels when nothing arrives for 2 s, as ARCOS's watchdog does.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use troupe_geom::DiffDrive;
use troupe_serial::{EmuLine, Faults, Framer, LineEvent};

use crate::packet::{self, cmd, PacketCodec, Sip};
use crate::params::{self, Params};

/// ARCOS's SIP cycle.
pub const CYCLE: Duration = Duration::from_millis(100);
/// ARCOS's default watchdog.
pub const WATCHDOG: Duration = Duration::from_secs(2);
/// The room's walls: x from −4 to 4 m, y from −3 to 3 m.
const ROOM: (f64, f64, f64, f64) = (-4.0, 4.0, -3.0, 3.0);
/// The robot's radius for collisions, m.
const RADIUS: f64 = 0.25;
/// The sonars' reach, m.
const SONAR_MAX: f64 = 5.0;

/// What the emulator is told.
#[derive(Debug, Clone)]
pub struct EmulatorOptions {
    /// The path to link the pseudo-terminal at.
    pub link: PathBuf,
    /// Faults to inject.
    pub faults: Faults,
    /// Seed of the fault generator.
    pub seed: u64,
    /// The subclass to report (a key of Player's robot table).
    pub subclass: String,
    /// The robot's name.
    pub name: String,
}

/// Counts for the log.
#[derive(Debug, Default, Clone, Copy)]
pub struct EmulatorStats {
    /// Packets from the driver.
    pub packets: u64,
    /// SIPs sent.
    pub sips: u64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    Unsynced,
    /// SYNC2 answered: the next `[1]` is OPEN.
    Synced,
    Open,
}

#[derive(Debug)]
struct Robot {
    params: &'static Params,
    state: State,
    enabled: bool,
    sonar: bool,
    /// The robot in its room; odometry since the last SETO.
    body: DiffDrive,
    /// Wheel speeds commanded, mm/s.
    left: f64,
    right: f64,
}

impl Robot {
    fn power_up(params: &'static Params) -> Robot {
        Robot {
            params,
            state: State::Unsynced,
            enabled: false,
            sonar: false,
            body: DiffDrive::new(ROOM, RADIUS),
            left: 0.0,
            right: 0.0,
        }
    }

    fn wheels_from(&mut self, speed: f64, turn_deg: f64) {
        let rot = turn_deg.to_radians() / self.params.diff_conv;
        self.left = speed - rot;
        self.right = speed + rot;
    }

    /// Moves for `dt`, stalling at the walls.
    fn step(&mut self, dt: f64) {
        let (l, r) = if self.enabled {
            (self.left, self.right)
        } else {
            (0.0, 0.0)
        };
        let v = (l + r) / 2.0 / 1000.0;
        let w = (r - l) * self.params.diff_conv / 2.0;
        self.body.step(v, w, dt);
    }

    fn sip(&self) -> Sip {
        let p = self.params;
        let counter = |m: f64| ((m * 1000.0 / p.dist_conv).round() as i64).rem_euclid(32768) as u16;
        let th =
            ((self.body.odometry.yaw / p.angle_conv).round() as i64 + 2048).rem_euclid(4096) - 2048;
        let (l, r) = if self.enabled {
            (self.left, self.right)
        } else {
            (0.0, 0.0)
        };
        let (l, r) = if self.body.stalled {
            (0.0, 0.0)
        } else {
            (l, r)
        };
        let sonars = if self.sonar {
            let (x, y, a) = (self.body.pose.x, self.body.pose.y, self.body.pose.yaw);
            p.sonars
                .iter()
                .enumerate()
                .map(|(i, &(sx, sy, sa))| {
                    let (sx, sy) = (f64::from(sx) / 1000.0, f64::from(sy) / 1000.0);
                    let wx = x + sx * a.cos() - sy * a.sin();
                    let wy = y + sx * a.sin() + sy * a.cos();
                    let d = troupe_geom::ray_to_box(wx, wy, a + f64::from(sa).to_radians(), ROOM)
                        .min(SONAR_MAX);
                    (i as u8, (d * 1000.0 / p.range_conv).round() as u16)
                })
                .collect()
        } else {
            Vec::new()
        };
        Sip {
            kind: if l != 0.0 || r != 0.0 { 0x33 } else { 0x32 },
            xpos: counter(self.body.odometry.x),
            ypos: counter(self.body.odometry.y),
            th: th as i16,
            lvel: (l / p.vel_conv).round() as i16,
            rvel: (r / p.vel_conv).round() as i16,
            battery: 123,
            lstall: u8::from(self.body.stalled),
            rstall: u8::from(self.body.stalled),
            control: 0,
            flags: u16::from(self.enabled),
            compass: 0,
            sonars,
            ..Sip::default()
        }
    }
}

/// Runs the emulated robot until `stop` is set, calling `linked` once its
/// line is linked.
///
/// # Errors
///
/// An unknown subclass, or a pseudo-terminal that cannot be opened or linked.
pub fn run_with(
    opts: &EmulatorOptions,
    stop: &AtomicBool,
    linked: impl FnOnce(),
) -> std::io::Result<EmulatorStats> {
    let params = params::find(&opts.subclass).ok_or_else(|| {
        let known: Vec<&str> = params::ROBOTS.iter().map(|p| p.subclass).collect();
        std::io::Error::other(format!(
            "unknown subclass `{}`; known: {}",
            opts.subclass,
            known.join(", ")
        ))
    })?;
    let mut line = EmuLine::open(&opts.link, opts.faults.clone(), opts.seed)?;
    linked();
    // A Pioneer's serial port speaks 9600 baud unless its FLASH says otherwise.
    let baud = 9600;
    let mut robot = Robot::power_up(params);
    let mut framer = Framer::new(PacketCodec);
    let mut stats = EmulatorStats::default();
    let mut next_sip = Instant::now();
    let mut buf = [0u8; 512];
    while !stop.load(Ordering::Relaxed) {
        let wait = next_sip
            .saturating_duration_since(Instant::now())
            .min(CYCLE);
        match line.recv(&mut buf, baud, wait)? {
            LineEvent::Received(n) => {
                framer.push(&buf[..n]);
                while let Some(p) = framer.next_frame() {
                    stats.packets += 1;
                    obey(&mut robot, &p, &mut line, baud, opts)?;
                }
            }
            LineEvent::Replugged => {
                robot = Robot::power_up(params);
                framer.clear();
            }
            LineEvent::Idle | LineEvent::Unplugged => {}
        }
        let now = Instant::now();
        if robot.state == State::Open && now >= next_sip {
            let moving = robot.left != 0.0 || robot.right != 0.0;
            if moving && line.watchdog(WATCHDOG) {
                robot.left = 0.0;
                robot.right = 0.0;
            }
            robot.step(CYCLE.as_secs_f64());
            line.send(&robot.sip().encode(), baud)?;
            stats.sips += 1;
            next_sip += CYCLE;
            if next_sip < now {
                next_sip = now + CYCLE;
            }
        } else if robot.state != State::Open {
            next_sip = now + CYCLE;
        }
    }
    tracing::info!(
        packets = stats.packets,
        sips = stats.sips,
        wrong_baud_bytes = line.wrong_baud,
        noise = line.injected.noise,
        dropped = line.injected.dropped,
        corrupted = line.injected.corrupted,
        truncated = line.injected.truncated,
        pose = ?robot.body.pose,
        "emulated p2os robot stopped"
    );
    Ok(stats)
}

fn obey(
    robot: &mut Robot,
    p: &[u8],
    line: &mut EmuLine,
    baud: u32,
    opts: &EmulatorOptions,
) -> std::io::Result<()> {
    let Some(&c) = p.first() else {
        return Ok(());
    };
    match (robot.state, c) {
        (State::Unsynced | State::Synced, cmd::SYNC0) => {
            robot.state = State::Unsynced;
            line.send(&packet::command(cmd::SYNC0), baud)
        }
        (State::Unsynced, cmd::SYNC1) => line.send(&packet::command(cmd::SYNC1), baud),
        (State::Unsynced, cmd::SYNC2) => {
            robot.state = State::Synced;
            line.send(
                &packet::sync2_reply(&opts.name, "Pioneer", robot.params.subclass),
                baud,
            )
        }
        (State::Synced, cmd::OPEN) => {
            robot.state = State::Open;
            tracing::info!("opened by the client");
            Ok(())
        }
        (State::Open, cmd::CLOSE) => {
            tracing::info!("closed by the client");
            robot.state = State::Unsynced;
            robot.enabled = false;
            robot.left = 0.0;
            robot.right = 0.0;
            Ok(())
        }
        (State::Open, cmd::ENABLE) => {
            robot.enabled = packet::argument(p) != 0;
            Ok(())
        }
        (State::Open, cmd::SETO) => {
            robot.body.reset_odometry();
            Ok(())
        }
        (State::Open, cmd::SONAR) => {
            robot.sonar = packet::argument(p) != 0;
            Ok(())
        }
        (State::Open, cmd::STOP) => {
            robot.left = 0.0;
            robot.right = 0.0;
            Ok(())
        }
        (State::Open, cmd::VEL) => {
            let turn = (robot.right - robot.left) * robot.params.diff_conv / 2.0;
            robot.wheels_from(f64::from(packet::argument(p)), turn.to_degrees());
            Ok(())
        }
        (State::Open, cmd::RVEL) => {
            let speed = (robot.left + robot.right) / 2.0;
            robot.wheels_from(speed, f64::from(packet::argument(p)));
            Ok(())
        }
        (State::Open, cmd::VEL2) if p.len() >= 4 => {
            robot.right = f64::from(p[2] as i8) * robot.params.vel2_div;
            robot.left = f64::from(p[3] as i8) * robot.params.vel2_div;
            Ok(())
        }
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sips_report_odometry_speeds_and_stall() {
        let mut r = Robot::power_up(params::find("p3dx").unwrap());
        r.enabled = true;
        r.wheels_from(500.0, 0.0);
        for _ in 0..10 {
            r.step(0.1);
        }
        let sip = r.sip();
        // 0.5 m at 0.485 mm per tick.
        assert_eq!(
            (sip.kind, sip.xpos, sip.lvel, sip.rvel),
            (0x33, 1031, 500, 500)
        );
        for _ in 0..200 {
            r.step(0.1);
        }
        let sip = r.sip();
        assert_eq!((sip.lstall & 1, sip.lvel), (1, 0));
    }
}
