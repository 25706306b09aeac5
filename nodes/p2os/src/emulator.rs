//! An emulated Pioneer (ARCOS firmware) on a pseudo-terminal.
//!
//! It answers SYNC0/1/2 with echoes and a SYNC2 reply naming the robot,
//! opens on OPEN, then sends a standard SIP every 100 ms: odometry from
//! differential-drive kinematics in an 8 m × 6 m room (the robot starts in
//! the middle facing +x and stalls against the walls), wheel velocities,
//! battery, stall bits and, when on, its sonar ring's ranges to the walls.
//! It obeys ENABLE, SETO, VEL2, VEL/RVEL, SONAR, STOP and CLOSE, and
//! stops the wheels when nothing arrives for 2 s, as ARCOS's watchdog does.
//! It has a gripper (GRIPPER open, close, stop: the paddles take a second
//! to move) and a gyro (GYRO on: a gyro packet after each SIP).
//!
//! The robot lives in a [`Body`]: the room by default ([`room`]), or any
//! other, such as a robot in a simulator.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use troupe_geom::{Body, DiffDrive, Pose};
use troupe_serial::{EmuLine, Framer, LineEvent, LineOptions};

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
/// How long the gripper's paddles take to open or close.
const PADDLES: Duration = Duration::from_secs(1);

/// The emulator's own world: a robot in the middle of an 8 m × 6 m room.
pub fn room() -> DiffDrive {
    DiffDrive::new(ROOM, RADIUS)
}

/// The gripper's paddles, as the SIP reports them (Player's bits).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Paddles {
    Open,
    Closed,
    /// Moving; open (`true`) or closed after this many more cycles.
    Moving(bool, u32),
    /// Stopped between open and closed.
    Halted,
}

impl Paddles {
    /// The state byte: 0x01 open, 0x02 closed, 0x04 moving.
    fn bits(self) -> u8 {
        match self {
            Paddles::Open => 0x01,
            Paddles::Closed => 0x02,
            Paddles::Moving(..) => 0x04,
            Paddles::Halted => 0x00,
        }
    }

    fn step(self) -> Paddles {
        match self {
            Paddles::Moving(true, 0) => Paddles::Open,
            Paddles::Moving(false, 0) => Paddles::Closed,
            Paddles::Moving(open, n) => Paddles::Moving(open, n - 1),
            other => other,
        }
    }
}

/// What the emulator is told.
#[derive(Debug, Clone)]
pub struct EmulatorOptions {
    /// The line: its link, faults and capture.
    pub line: LineOptions,
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
    gyro: bool,
    paddles: Paddles,
    /// Wheel speeds commanded, mm/s.
    left: f64,
    right: f64,
}

impl Robot {
    /// The robot as it powers up, its odometry at zero.
    fn power_up(params: &'static Params, body: &mut dyn Body) -> Robot {
        body.reset_odometry();
        Robot {
            params,
            state: State::Unsynced,
            enabled: false,
            sonar: false,
            gyro: false,
            paddles: Paddles::Open,
            left: 0.0,
            right: 0.0,
        }
    }

    fn wheels_from(&mut self, speed: f64, turn_deg: f64) {
        let rot = turn_deg.to_radians() / self.params.diff_conv;
        self.left = speed - rot;
        self.right = speed + rot;
    }

    /// The wheel speeds the robot runs at, mm/s: those commanded, none
    /// while its motors are disabled or it is `stalled`.
    fn wheels(&self, stalled: bool) -> (f64, f64) {
        if self.enabled && !stalled {
            (self.left, self.right)
        } else {
            (0.0, 0.0)
        }
    }

    /// The turn rate of wheel speeds `(l, r)`, rad/s.
    fn turn_rate(&self, (l, r): (f64, f64)) -> f64 {
        (r - l) * self.params.diff_conv / 2.0
    }

    /// Moves `body` for `dt`.
    fn step(&mut self, body: &mut dyn Body, dt: f64) {
        let (l, r) = self.wheels(false);
        body.drive((l + r) / 2.0 / 1000.0, self.turn_rate((l, r)), dt);
        self.paddles = self.paddles.step();
    }

    /// One gyro reading of `body`: 512 when still, less when turning
    /// counter-clockwise, one unit per degree per second.
    fn gyro_packet(&self, body: &dyn Body) -> Vec<u8> {
        let turning = self.turn_rate(self.wheels(body.stalled()));
        let rate = (512.0 - turning.to_degrees()).round().clamp(0.0, 1023.0) as u16;
        packet::gyro_packet(&[(rate, 30)])
    }

    fn sip(&self, body: &mut dyn Body) -> Sip {
        let p = self.params;
        let counter = |m: f64| ((m * 1000.0 / p.dist_conv).round() as i64).rem_euclid(32768) as u16;
        let odometry = body.odometry();
        let stalled = body.stalled();
        let th = ((odometry.yaw / p.angle_conv).round() as i64 + 2048).rem_euclid(4096) - 2048;
        let (l, r) = self.wheels(stalled);
        let sonars = if self.sonar {
            p.sonars
                .iter()
                .enumerate()
                .map(|(i, &(sx, sy, sa))| {
                    let at = Pose::new(
                        f64::from(sx) / 1000.0,
                        f64::from(sy) / 1000.0,
                        f64::from(sa).to_radians(),
                    );
                    let d = body.range(i, at, SONAR_MAX);
                    (i as u8, (d * 1000.0 / p.range_conv).round() as u16)
                })
                .collect()
        } else {
            Vec::new()
        };
        let paddles = self.paddles.bits();
        Sip {
            kind: if l != 0.0 || r != 0.0 { 0x33 } else { 0x32 },
            xpos: counter(odometry.x),
            ypos: counter(odometry.y),
            th: th as i16,
            lvel: (l / p.vel_conv).round() as i16,
            rvel: (r / p.vel_conv).round() as i16,
            battery: 123,
            lstall: u8::from(stalled),
            rstall: u8::from(stalled),
            control: 0,
            flags: u16::from(self.enabled),
            compass: 0,
            sonars,
            // ARCOS reports the gripper in the byte after the sonars;
            // Player's driver reads the one after that (the high byte of
            // P2OS's timer word). Both carry it, so both readers agree.
            grip: paddles,
            anport: paddles,
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
    body: &mut dyn Body,
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
    let mut line = EmuLine::open(&opts.line, "p2os robot")?;
    linked();
    // A Pioneer's serial port speaks 9600 baud unless its FLASH says otherwise.
    let baud = 9600;
    let mut robot = Robot::power_up(params, body);
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
                    obey(&mut robot, body, &p, &mut line, baud, opts)?;
                }
            }
            LineEvent::Replugged => {
                robot = Robot::power_up(params, body);
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
            robot.step(body, CYCLE.as_secs_f64());
            line.send(&robot.sip(body).encode(), baud)?;
            stats.sips += 1;
            if robot.gyro {
                line.send(&robot.gyro_packet(body), baud)?;
            }
            next_sip += CYCLE;
            if next_sip < now {
                next_sip = now + CYCLE;
            }
        } else if robot.state != State::Open {
            next_sip = now + CYCLE;
        }
    }
    // The driver's goodbye (last commands, STOP, CLOSE) is obeyed.
    line.obey_leftover(baud, CYCLE, &mut framer, |line, p| {
        stats.packets += 1;
        obey(&mut robot, body, &p, line, baud, opts)
    })?;
    let _counts = line.counts_span().entered();
    tracing::info!(
        packets = stats.packets,
        sips = stats.sips,
        odometry = ?body.odometry(),
        "emulated p2os robot stopped"
    );
    Ok(stats)
}

fn obey(
    robot: &mut Robot,
    body: &mut dyn Body,
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
            body.reset_odometry();
            Ok(())
        }
        (State::Open, cmd::GYRO) => {
            robot.gyro = packet::argument(p) != 0;
            Ok(())
        }
        (State::Open, cmd::GRIPPER) => {
            let cycles = (PADDLES.as_millis() / CYCLE.as_millis()) as u32;
            robot.paddles = match packet::argument(p) {
                packet::grip::OPEN => Paddles::Moving(true, cycles),
                packet::grip::CLOSE => Paddles::Moving(false, cycles),
                packet::grip::STOP if matches!(robot.paddles, Paddles::Moving(..)) => {
                    Paddles::Halted
                }
                _ => robot.paddles,
            };
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
        let mut room = room();
        let mut r = Robot::power_up(params::find("p3dx").unwrap(), &mut room);
        r.enabled = true;
        r.wheels_from(500.0, 0.0);
        for _ in 0..10 {
            r.step(&mut room, 0.1);
        }
        let sip = r.sip(&mut room);
        // 0.5 m at 0.485 mm per tick.
        assert_eq!(
            (sip.kind, sip.xpos, sip.lvel, sip.rvel),
            (0x33, 1031, 500, 500)
        );
        for _ in 0..200 {
            r.step(&mut room, 0.1);
        }
        let sip = r.sip(&mut room);
        assert_eq!((sip.lstall & 1, sip.lvel), (1, 0));
    }

    #[test]
    fn the_gripper_takes_a_second_and_the_gyro_reads_the_turn() {
        let mut room = room();
        let mut r = Robot::power_up(params::find("p3dx").unwrap(), &mut room);
        r.enabled = true;
        assert_eq!(r.sip(&mut room).anport, 0x01);
        r.paddles = Paddles::Moving(false, 10);
        for _ in 0..10 {
            r.step(&mut room, 0.1);
            assert_eq!(r.sip(&mut room).grip, 0x04);
        }
        r.step(&mut room, 0.1);
        assert_eq!(r.sip(&mut room).anport, 0x02);
        // 30°/s counter-clockwise: 30 units under 512.
        r.wheels_from(0.0, 30.0);
        r.step(&mut room, 0.1);
        let g = r.gyro_packet(&room);
        assert_eq!(packet::parse_gyro(&g[3..g.len() - 2]), Ok(482));
    }
}
