//! An emulated Videre Erratic on a pseudo-terminal.
//!
//! It answers the configuration request at any time with its name and
//! revision, and after OPEN sends a motor packet every 100 ms (odometry in
//! 12-bit counters, heading 4096 per turn, wheel speeds, battery, stall)
//! from differential-drive kinematics in an 8 m × 6 m room, plus sonar
//! packets (8 channels to the walls) and analog packets (4 ADC channels
//! and the floor IR bits) when those are on. It obeys ENABLE, VEL, RVEL,
//! VEL2, STOP, CLOSE and the servos, takes the settings Player sends and
//! ignores them, and stops its wheels when nothing arrives for 2 s.
//!
//! The robot lives in a [`Body`]: the room by default ([`room`]), or any
//! other, such as a robot in a simulator.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use troupe_geom::{Body, DiffDrive, Pose};
use troupe_serial::{EmuLine, Framer, LineEvent, LineOptions};

use crate::packet::{self, argument, cmd, Motor, PacketCodec};
use crate::params::{self, Params, DIFF_CONV, VEL2_DIV, VEL_CONV};

/// The data cycle.
pub const CYCLE: Duration = Duration::from_millis(100);
/// The firmware's watchdog.
pub const WATCHDOG: Duration = Duration::from_secs(2);
const ROOM: (f64, f64, f64, f64) = (-4.0, 4.0, -3.0, 3.0);
const RADIUS: f64 = 0.22;

/// The emulator's own world: a robot in the middle of an 8 m × 6 m room.
pub fn room() -> DiffDrive {
    DiffDrive::new(ROOM, RADIUS)
}

/// What the emulator is told.
#[derive(Debug, Clone)]
pub struct EmulatorOptions {
    /// The line: its link, faults and capture.
    pub line: LineOptions,
    /// The revision to report: "Rev E", "Rev G" or "Rev H".
    pub revision: String,
}

/// Counts for the log.
#[derive(Debug, Default, Clone, Copy)]
pub struct EmulatorStats {
    /// Packets from the driver.
    pub packets: u64,
    /// Motor packets sent.
    pub motor: u64,
    /// Servo commands obeyed.
    pub servo: u64,
}

#[derive(Debug)]
struct Robot {
    params: &'static Params,
    open: bool,
    enabled: bool,
    sonar: bool,
    analog: bool,
    left: f64,
    right: f64,
    servos: [u16; 3],
}

impl Robot {
    /// The robot as it powers up (or is closed), its odometry at zero.
    fn power_up(params: &'static Params, body: &mut dyn Body) -> Robot {
        body.reset_odometry();
        Robot {
            params,
            open: false,
            enabled: false,
            sonar: false,
            analog: false,
            left: 0.0,
            right: 0.0,
            servos: [1650; 3],
        }
    }

    fn wheels_from(&mut self, speed: f64, turn_deg: f64) {
        let rot = turn_deg.to_radians() / DIFF_CONV;
        self.left = speed - rot;
        self.right = speed + rot;
    }

    /// The wheel speeds the robot reports: none while disabled or stalled.
    fn wheels(&self, stalled: bool) -> (f64, f64) {
        if self.enabled && !stalled {
            (self.left, self.right)
        } else {
            (0.0, 0.0)
        }
    }

    /// Moves `body` for `dt`.
    fn step(&mut self, body: &mut dyn Body, dt: f64) {
        let (l, r) = if self.enabled {
            (self.left, self.right)
        } else {
            (0.0, 0.0)
        };
        body.drive((l + r) / 2.0 / 1000.0, (r - l) * DIFF_CONV / 2.0, dt);
    }

    fn motor(&self, body: &dyn Body) -> Motor {
        let counter =
            |m: f64| ((m * 1000.0 / self.params.dist_conv).round() as i64).rem_euclid(4096) as u16;
        let o = body.odometry();
        // Read once: the speeds and the stall flags of a packet agree.
        let stalled = body.stalled();
        let (l, r) = self.wheels(stalled);
        Motor {
            kind: if l != 0.0 || r != 0.0 { 0x83 } else { 0x82 },
            x: counter(o.x),
            y: counter(o.y),
            th: ((o.yaw * 2048.0 / std::f64::consts::PI).round() as i64).rem_euclid(4096) as i16,
            lvel: (l / VEL_CONV).round() as i16,
            rvel: (r / VEL_CONV).round() as i16,
            battery: 125,
            lstall: u8::from(stalled),
            rstall: u8::from(stalled),
        }
    }

    fn sonar(&self, body: &mut dyn Body) -> Vec<(u8, u16)> {
        self.params
            .sonars
            .iter()
            .enumerate()
            .map(|(i, &(sx, sy, sa))| {
                let d = body.range(i, Pose::new(sx, sy, sa.to_radians()), 5.0);
                (i as u8, (d * 1000.0).round() as u16)
            })
            .collect()
    }
}

/// Runs the emulated Erratic until `stop` is set, calling `linked` once
/// its line is linked.
///
/// # Errors
///
/// An unknown revision, or a pseudo-terminal that cannot be opened or linked.
pub fn run_with(
    opts: &EmulatorOptions,
    body: &mut dyn Body,
    stop: &AtomicBool,
    linked: impl FnOnce(),
) -> std::io::Result<EmulatorStats> {
    let params = params::find(&opts.revision).ok_or_else(|| {
        std::io::Error::other(format!(
            "unknown revision `{}`: Rev E, Rev G or Rev H",
            opts.revision
        ))
    })?;
    let mut line = EmuLine::open(&opts.line, "erratic")?;
    linked();
    let baud = 38400;
    let mut robot = Robot::power_up(params, body);
    let mut framer = Framer::new(PacketCodec);
    let mut stats = EmulatorStats::default();
    let mut next = Instant::now();
    let mut buf = [0u8; 512];
    while !stop.load(Ordering::Relaxed) {
        let wait = next.saturating_duration_since(Instant::now()).min(CYCLE);
        match line.recv(&mut buf, baud, wait)? {
            LineEvent::Received(n) => {
                framer.push(&buf[..n]);
                while let Some(p) = framer.next_frame() {
                    stats.packets += 1;
                    obey(&mut robot, body, &p, &mut line, baud, &mut stats)?;
                }
            }
            LineEvent::Replugged => {
                robot = Robot::power_up(params, body);
                framer.clear();
            }
            LineEvent::Idle | LineEvent::Unplugged => {}
        }
        let now = Instant::now();
        if !robot.open {
            next = now + CYCLE;
            continue;
        }
        if now < next {
            continue;
        }
        let moving = robot.left != 0.0 || robot.right != 0.0;
        if moving && line.watchdog(WATCHDOG) {
            robot.left = 0.0;
            robot.right = 0.0;
        }
        robot.step(body, CYCLE.as_secs_f64());
        line.send(&robot.motor(body).encode(), baud)?;
        stats.motor += 1;
        if robot.sonar {
            line.send(&packet::encode_sonar(&robot.sonar(body)), baud)?;
        }
        if robot.analog {
            // Four ADC channels at a quarter of the range; floor under both IR sensors.
            line.send(&packet::encode_analog(&[256, 256, 256, 256], 0x30), baud)?;
        }
        next += CYCLE;
        if next < now {
            next = now + CYCLE;
        }
    }
    // The driver's goodbye (queued servo commands, STOP, CLOSE) is obeyed.
    line.obey_leftover(baud, CYCLE, &mut framer, |line, p| {
        stats.packets += 1;
        obey(&mut robot, body, &p, line, baud, &mut stats)
    })?;
    let _counts = line.counts_span().entered();
    tracing::info!(
        packets = stats.packets,
        motor_packets = stats.motor,
        servo = stats.servo,
        servos = ?robot.servos,
        "emulated erratic stopped"
    );
    Ok(stats)
}

fn obey(
    robot: &mut Robot,
    body: &mut dyn Body,
    p: &[u8],
    line: &mut EmuLine,
    baud: u32,
    stats: &mut EmulatorStats,
) -> std::io::Result<()> {
    let Some(&c) = p.first() else {
        return Ok(());
    };
    match c {
        cmd::CONFIG => {
            let reply = packet::config_reply("Troupe", "Erratic", robot.params.subtype);
            return line.send(&reply, baud);
        }
        cmd::OPEN if !robot.open => {
            tracing::info!("opened by the client");
            robot.open = true;
        }
        cmd::CLOSE => {
            tracing::info!("closed by the client");
            *robot = Robot::power_up(robot.params, body);
        }
        cmd::ENABLE => robot.enabled = argument(p) != 0,
        cmd::SONAR => robot.sonar = argument(p) != 0,
        cmd::ANALOG => robot.analog = argument(p) != 0,
        cmd::STOP => {
            robot.left = 0.0;
            robot.right = 0.0;
        }
        cmd::VEL => {
            let turn = (robot.right - robot.left) * DIFF_CONV / 2.0;
            robot.wheels_from(f64::from(argument(p)), turn.to_degrees());
        }
        cmd::RVEL => {
            let speed = (robot.left + robot.right) / 2.0;
            robot.wheels_from(speed, f64::from(argument(p)));
        }
        cmd::VEL2 if p.len() >= 4 => {
            robot.right = f64::from(p[2] as i8) * VEL2_DIV;
            robot.left = f64::from(p[3] as i8) * VEL2_DIV;
        }
        cmd::SERVO if p.len() >= 6 => {
            if let Some(s) = robot.servos.get_mut(usize::from(p[3])) {
                *s = u16::from_le_bytes([p[4], p[5]]);
                stats.servo += 1;
            }
        }
        _ => {}
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn motor_packets_report_odometry_and_speeds() {
        let mut room = room();
        let mut r = Robot::power_up(params::find("Rev H").unwrap(), &mut room);
        r.enabled = true;
        r.wheels_from(300.0, 0.0);
        for _ in 0..10 {
            r.step(&mut room, 0.1);
        }
        let m = r.motor(&room);
        // 0.3 m at 0.930 mm per tick; 300 mm/s at 1.20482 mm/s per unit.
        assert_eq!((m.kind, m.x, m.lvel, m.rvel), (0x83, 323, 249, 249));
        assert_eq!(r.sonar(&mut room).len(), 8);
    }
}
