//! An emulated 914 on a pseudo-terminal: its M3 board's two motion chips.
//!
//! The chips answer every command of Player's driver at 416666 baud
//! ([`pmd`]): each keeps a commanded position and velocity that follow
//! the velocity given in velocity-contouring mode, ramped at the
//! acceleration and deceleration given (counts per cycle² × 65536, a
//! 154 µs cycle), taking effect on UPDATE as on the real chips. Steppers
//! are open-loop: the counts are what was commanded, and the body moves
//! when the motors are powered (mode on, torque above zero). The eight IR
//! inputs read the walls by the Sharp sensors' curves, the eight analog
//! inputs of the second I/O board read 0, 1/8, … 7/8 of full scale, and
//! the digital inputs are wired to the outputs (a loopback plug), so what
//! the driver writes comes back. An unknown opcode is refused as the
//! chips do (status 2, invalid instruction).
//!
//! The robot lives in a [`Body`]: the room by default ([`room`]), or a
//! robot in a simulator.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use troupe_geom::{Body, DiffDrive, Pose};
use troupe_serial::{EmuLine, Framer, LineEvent, LineOptions};

use crate::pmd::{self, op, Command, CommandCodec};
use crate::robot;

/// What GETVERSION answers.
pub const VERSION: i32 = 0x3410_0A01;
/// The chips' cycle, µs.
pub const CYCLE_US: i32 = robot::DEFAULT_CYCLE_US;
/// How often the body moves while the line is quiet.
const STEP: Duration = Duration::from_millis(20);
const ROOM: (f64, f64, f64, f64) = (-4.0, 4.0, -3.0, 3.0);
const RADIUS: f64 = 0.28;

/// The emulator's own world: a 914 in the middle of an 8 m × 6 m room.
pub fn room() -> DiffDrive {
    DiffDrive::new(ROOM, RADIUS)
}

/// What the emulator is told.
#[derive(Debug, Clone)]
pub struct EmulatorOptions {
    /// The line: its link, faults and capture.
    pub line: LineOptions,
}

/// Counts for the log.
#[derive(Debug, Default, Clone, Copy)]
pub struct EmulatorStats {
    /// Commands from the driver.
    pub commands: u64,
    /// Commands refused (unknown opcodes).
    pub refused: u64,
    /// Digital output writes.
    pub digital_writes: u64,
}

/// A chip's profile parameters: staged by the SET commands, in effect
/// from the next UPDATE.
#[derive(Debug, Clone, Copy, Default)]
struct Profile {
    velocity: i32,
    accel: i32,
    decel: i32,
    mode: i32,
    abrupt_stop: bool,
}

/// One motion chip and its wheel.
#[derive(Debug, Clone, Copy, Default)]
struct Axis {
    /// Commanded position, counts.
    position: f64,
    /// Commanded velocity, counts per cycle × 65536.
    velocity: f64,
    staged: Profile,
    active: Profile,
    motor_on: bool,
    torque: i32,
}

impl Axis {
    fn update(&mut self) {
        self.active = self.staged;
        if self.staged.abrupt_stop {
            self.velocity = 0.0;
            self.active.velocity = 0;
            self.staged.velocity = 0;
            self.staged.abrupt_stop = false;
        }
    }

    /// Follows the profile for `dt` s: the velocity toward its target at
    /// the acceleration (faster) or deceleration (slower), the position by
    /// the mean velocity.
    fn advance(&mut self, dt: f64) {
        let cycle = f64::from(CYCLE_US) * 1e-6;
        let target = if self.active.mode == pmd::VELOCITY_CONTOURING {
            f64::from(self.active.velocity)
        } else {
            0.0
        };
        let before = self.velocity;
        let speeding = target.abs() > before.abs() && target * before >= 0.0;
        let rate = f64::from(if speeding {
            self.active.accel
        } else {
            self.active.decel
        }) / cycle;
        let dv = (target - before).clamp(-rate * dt, rate * dt);
        self.velocity = before + dv;
        self.position += (before + self.velocity) / 2.0 / 65536.0 * dt / cycle;
    }

    /// The wheel's speed (m/s, the chip's sense) when powered.
    fn wheel(&self) -> f64 {
        if self.motor_on && self.torque > 0 {
            self.velocity / robot::velocity_k(CYCLE_US)
        } else {
            0.0
        }
    }
}

#[derive(Debug)]
struct Board {
    axes: [Axis; 2],
    digital: u16,
    last: Instant,
}

impl Board {
    fn power_up() -> Board {
        Board {
            axes: [Axis::default(); 2],
            digital: 0,
            last: Instant::now(),
        }
    }

    /// Moves the wheels, and the body on them, up to `now`.
    fn advance(&mut self, body: &mut dyn Body, now: Instant) {
        let dt = now.saturating_duration_since(self.last).as_secs_f64();
        self.last = now;
        if dt <= 0.0 {
            return;
        }
        // The left motor turns the other way round.
        let wheels = |axes: &[Axis; 2]| {
            (
                -axes[usize::from(pmd::LEFT)].wheel(),
                axes[usize::from(pmd::RIGHT)].wheel(),
            )
        };
        let before = wheels(&self.axes);
        for a in &mut self.axes {
            a.advance(dt);
        }
        let after = wheels(&self.axes);
        let (v, w) = robot::motion((before.0 + after.0) / 2.0, (before.1 + after.1) / 2.0);
        body.drive(v, w, dt);
    }

    /// Carries out `c` and returns the reply.
    fn obey(&mut self, c: &Command, body: &mut dyn Body, stats: &mut EmulatorStats) -> Vec<u8> {
        if c.unknown {
            stats.refused += 1;
            return pmd::error_reply(pmd::INVALID_INSTRUCTION);
        }
        let axis = usize::from(c.axis);
        let a = &mut self.axes[axis];
        let value = match c.opcode {
            op::RESET => {
                *a = Axis::default();
                0
            }
            op::GETVERSION => VERSION,
            op::GETSAMPLETIME => CYCLE_US,
            op::SETVEL => {
                a.staged.velocity = c.arg;
                0
            }
            op::SETACCEL => {
                a.staged.accel = c.arg;
                0
            }
            op::SETDECEL => {
                a.staged.decel = c.arg;
                0
            }
            op::SETPROFILEMODE => {
                a.staged.mode = c.arg;
                0
            }
            op::SETSTOPMODE => {
                a.staged.abrupt_stop = c.arg == 1;
                0
            }
            op::UPDATE => {
                a.update();
                0
            }
            op::SETACTUALPOS => {
                a.position = f64::from(c.arg);
                0
            }
            op::SETMOTORMODE => {
                a.motor_on = c.arg == 1;
                0
            }
            op::SETMOTORCMD => {
                a.torque = c.arg;
                0
            }
            op::GETCMDPOS | op::GETACTUALPOS => a.position.round() as i32,
            op::GETCMDVEL | op::GETACTUALVEL => a.velocity.round() as i32,
            op::READANALOG => i32::from(self.analog(axis, c.arg, body)) << 6,
            op::READDIGITAL => i32::from(self.digital),
            op::WRITEDIGITAL => {
                self.digital = c.arg as u16;
                stats.digital_writes += 1;
                0
            }
            _ => 0,
        };
        pmd::reply(c.opcode, value)
    }

    /// ADC counts of input `channel` of chip `axis`: the IR sensors on the
    /// left chip, the second I/O board on the right.
    fn analog(&self, axis: usize, channel: i32, body: &mut dyn Body) -> u16 {
        let c = channel.clamp(0, 7) as usize;
        if axis == usize::from(pmd::LEFT) {
            let (x, y, a) = robot::IR_POSES[c];
            let m = body.range(c, Pose::new(x, y, a.to_radians()), 1.5);
            robot::ir_counts(c, m)
        } else {
            (c * 128) as u16
        }
    }
}

/// Runs the emulated 914 until `stop` is set, calling `linked` once its
/// line is linked.
///
/// # Errors
///
/// A pseudo-terminal that cannot be opened or linked.
pub fn run_with(
    opts: &EmulatorOptions,
    body: &mut dyn Body,
    stop: &AtomicBool,
    linked: impl FnOnce(),
) -> std::io::Result<EmulatorStats> {
    let mut line = EmuLine::open(&opts.line, "wbr914")?;
    linked();
    let baud = pmd::BAUD;
    let mut board = Board::power_up();
    let mut framer = Framer::new(CommandCodec);
    let mut stats = EmulatorStats::default();
    let mut buf = [0u8; 256];
    while !stop.load(Ordering::Relaxed) {
        let event = line.recv(&mut buf, baud, STEP)?;
        board.advance(body, Instant::now());
        match event {
            LineEvent::Received(n) => {
                framer.push(&buf[..n]);
                while let Some(c) = framer.next_frame() {
                    stats.commands += 1;
                    let reply = board.obey(&c, body, &mut stats);
                    line.send(&reply, baud)?;
                }
            }
            LineEvent::Replugged => {
                board = Board::power_up();
                framer.clear();
            }
            LineEvent::Idle | LineEvent::Unplugged => {}
        }
    }
    // The driver's goodbye (stop, motors off, reset) is answered.
    line.obey_leftover(baud, Duration::from_millis(300), &mut framer, |line, c| {
        stats.commands += 1;
        let reply = board.obey(&c, body, &mut stats);
        line.send(&reply, baud)
    })?;
    let _counts = line.counts_span().entered();
    tracing::info!(
        commands = stats.commands,
        refused = stats.refused,
        digital_writes = stats.digital_writes,
        motors_on = board.axes.iter().any(|a| a.motor_on),
        "emulated wbr914 stopped"
    );
    Ok(stats)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn send(board: &mut Board, body: &mut DiffDrive, axis: u8, opcode: u8, arg: i32) -> Vec<u8> {
        let bytes = pmd::command(axis, opcode, arg);
        let troupe_serial::Decoded::Frame(c, _) =
            troupe_serial::Codec::decode(&mut CommandCodec, &bytes)
        else {
            panic!("not a command");
        };
        board.obey(&c, body, &mut EmulatorStats::default())
    }

    #[test]
    fn wheels_ramp_to_the_velocity_and_drive_the_body() {
        let mut room = room();
        let mut b = Board::power_up();
        let k = robot::velocity_k(CYCLE_US);
        let v = (0.2 * k) as i32;
        for (axis, sign) in [(pmd::LEFT, -1), (pmd::RIGHT, 1)] {
            send(&mut b, &mut room, axis, op::SETACCEL, robot::ACCELERATION);
            send(&mut b, &mut room, axis, op::SETDECEL, robot::DECELERATION);
            send(
                &mut b,
                &mut room,
                axis,
                op::SETPROFILEMODE,
                pmd::VELOCITY_CONTOURING,
            );
            send(&mut b, &mut room, axis, op::SETMOTORCMD, 0x6000);
            send(&mut b, &mut room, axis, op::SETMOTORMODE, 1);
            send(&mut b, &mut room, axis, op::SETVEL, sign * v);
        }
        // Nothing moves before UPDATE.
        let t0 = b.last;
        b.advance(&mut room, t0 + Duration::from_millis(100));
        assert_eq!(room.pose, Pose::default());
        for axis in [pmd::LEFT, pmd::RIGHT] {
            send(&mut b, &mut room, axis, op::UPDATE, 0);
        }
        for i in 1..=30 {
            b.advance(&mut room, t0 + Duration::from_millis(100 + 100 * i));
        }
        // 0.2 m/s reached in 0.5 s at 0.41 m/s²; 3 s make about 0.55 m.
        let x = room.pose.x;
        assert!((x - 0.55).abs() < 0.02 && room.pose.yaw.abs() < 1e-9, "{x}");
        let reply = send(&mut b, &mut room, pmd::RIGHT, op::GETCMDPOS, 0);
        let counts = i32::from_be_bytes(reply[2..6].try_into().unwrap());
        assert!((f64::from(counts) / robot::ticks_per_metre() - x).abs() < 1e-3);
        // An abrupt stop on UPDATE.
        send(&mut b, &mut room, pmd::RIGHT, op::SETSTOPMODE, 1);
        send(&mut b, &mut room, pmd::RIGHT, op::UPDATE, 0);
        let reply = send(&mut b, &mut room, pmd::RIGHT, op::GETCMDVEL, 0);
        assert_eq!(reply, pmd::reply(op::GETCMDVEL, 0));
    }

    #[test]
    fn inputs_read_walls_and_the_loopback() {
        let mut room = room();
        let mut b = Board::power_up();
        // IR 2 looks ahead from 0.21 m: the wall 4 m off is beyond its reach.
        let r = send(&mut b, &mut room, pmd::LEFT, op::READANALOG, 2);
        let counts = robot::analog(i32::from(i16::from_be_bytes([r[2], r[3]])));
        assert_eq!(counts, robot::ir_counts(2, 0.8));
        let r = send(&mut b, &mut room, pmd::RIGHT, op::READANALOG, 3);
        assert_eq!(
            robot::analog(i32::from(i16::from_be_bytes([r[2], r[3]]))),
            384
        );
        send(&mut b, &mut room, pmd::RIGHT, op::WRITEDIGITAL, 0x0102);
        let r = send(&mut b, &mut room, pmd::RIGHT, op::READDIGITAL, 0);
        assert_eq!(r, pmd::reply(op::READDIGITAL, 0x0102));
        let unknown = pmd::command(0, 0x55, 0);
        let troupe_serial::Decoded::Frame(c, 4) =
            troupe_serial::Codec::decode(&mut CommandCodec, &unknown)
        else {
            panic!("an unknown opcode is still a frame");
        };
        let mut stats = EmulatorStats::default();
        assert_eq!(b.obey(&c, &mut room, &mut stats), pmd::error_reply(2));
        assert_eq!(stats.refused, 1);
    }
}
