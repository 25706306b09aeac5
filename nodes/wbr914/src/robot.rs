//! The 914's body in numbers: its wheels and motors, how wheel counts
//! become odometry, how its Sharp IR sensors' voltages become ranges, and
//! how its I/O boards' digital bits are laid out (Player's constants and
//! formulas).

use std::f64::consts::{PI, TAU};

use troupe_geom::Pose;

/// Wheel diameter, m.
pub const WHEEL_DIAMETER: f64 = 0.125;
/// Motor revolutions per wheel revolution.
pub const GEAR_RATIO: f64 = 4.8;
/// Counts per motor revolution: 200 steps of 64 microsteps.
pub const TICKS_PER_REV: f64 = 200.0 * 64.0;
/// Microsteps per step, as the chips are told (× 4: phase counts).
pub const PHASE_COUNTS: i32 = 64 * 4;
/// Between the wheels, m.
pub const AXLE: f64 = 0.301;
/// The fastest a wheel may turn before its stepper stalls, m/s.
pub const MAX_WHEEL_SPEED: f64 = 0.3;
/// The chips' acceleration and deceleration (counts/cycle² × 65536).
pub const ACCELERATION: i32 = 100;
/// See [`ACCELERATION`].
pub const DECELERATION: i32 = 250;
/// The chips' cycle when they do not say, µs.
pub const DEFAULT_CYCLE_US: i32 = 154;
/// Length, width and height of the body, m.
pub const SIZE: (f64, f64, f64) = (0.42, 0.37, 0.3);
/// Player's torque when the cfg gives none, percent.
pub const DEFAULT_TORQUE: i64 = 75;

/// The IR sensors: x, y, heading in degrees (5–7 look 30° down from 0.35 m,
/// which Player's pose cannot say).
pub const IR_POSES: [(f64, f64, f64); 8] = [
    (0.030, -0.190, -90.0),
    (0.190, -0.090, -30.0),
    (0.210, 0.0, 0.0),
    (0.190, 0.090, 30.0),
    (0.030, 0.190, 90.0),
    (0.200, -0.060, -60.0),
    (0.210, 0.0, 0.0),
    (0.200, 0.060, 60.0),
];

/// Wheel counts per metre (about 156456).
pub fn ticks_per_metre() -> f64 {
    GEAR_RATIO * TICKS_PER_REV / (PI * WHEEL_DIAMETER)
}

/// A chip's velocity unit (counts per cycle × 65536) per m/s, for a cycle
/// of `cycle_us` µs.
pub fn velocity_k(cycle_us: i32) -> f64 {
    ticks_per_metre() * f64::from(cycle_us) * 65536.0 / 1e6
}

/// Left and right wheel speeds (m/s) for `speed` m/s and `turn` rad/s,
/// each within [`MAX_WHEEL_SPEED`], the other scaled by as much so the
/// turn keeps its rate (Player's `HandleVelocityCommand`).
pub fn wheels(speed: f64, turn: f64) -> (f64, f64) {
    let rot = turn * AXLE / 2.0;
    let (mut l, mut r) = (speed - rot, speed + rot);
    if l.abs() > MAX_WHEEL_SPEED {
        let scale = l.abs() / MAX_WHEEL_SPEED;
        l = MAX_WHEEL_SPEED.copysign(l);
        r /= scale;
    }
    if r.abs() > MAX_WHEEL_SPEED {
        let scale = r.abs() / MAX_WHEEL_SPEED;
        r = MAX_WHEEL_SPEED.copysign(r);
        l /= scale;
    }
    (l, r)
}

/// Forward speed (m/s) and turn rate (rad/s) of wheels at `l` and `r` m/s.
pub fn motion(l: f64, r: f64) -> (f64, f64) {
    ((l + r) / 2.0, (r - l) / AXLE)
}

/// Dead reckoning from the wheel counts, as Player's `GetPositionData`
/// does it: the average of the two wheels' travel forward, half their
/// difference over half the axle as the turn, the heading kept in
/// [0, 2π), and the step taken along the new heading.
///
/// One difference: Player turned by (left − right), the opposite of the
/// command it sent (a positive turn rate raised the right wheel's speed),
/// so its heading ran against its robot's turns. Here a left turn raises
/// the heading, as every other driver's does.
#[derive(Debug, Clone, Default)]
pub struct Odometry {
    last: (i64, i64),
    /// The pose so far.
    pub pose: Pose,
}

impl Odometry {
    /// Moves the pose by the wheels' counts since the last update (left
    /// counts forward-positive).
    pub fn update(&mut self, left: i32, right: i32) -> Pose {
        let (left, right) = (i64::from(left), i64::from(right));
        let (cl, cr) = (left - self.last.0, right - self.last.1);
        self.last = (left, right);
        let metres = |t: i64| t as f64 / ticks_per_metre();
        let trans = metres((cl + cr) >> 1);
        let rot = metres((cr - cl) >> 1);
        let mut yaw = self.pose.yaw + rot / (AXLE / 2.0);
        if yaw < 0.0 {
            yaw += TAU;
        }
        if yaw > TAU {
            yaw -= TAU;
        }
        self.pose = Pose::new(
            self.pose.x + trans * yaw.cos(),
            self.pose.y + trans * yaw.sin(),
            yaw,
        );
        self.pose
    }

    /// The wheels' counts are zero again, and so is the pose.
    pub fn reset(&mut self) {
        *self = Odometry::default();
    }
}

/// Volts of an ADC reading (10 bits over 5 V).
pub fn volts(counts: u16) -> f32 {
    (f64::from(counts) * 5.0 / 1023.0) as f32
}

/// The ADC reading in a READANALOG reply: its top 10 bits.
pub fn analog(reply: i32) -> u16 {
    ((reply as u16) >> 6) & 0x3FF
}

/// Sensors 5 and 7 are long-range Sharp GP2Y0A02s (0.2–1.5 m); the rest
/// GP2Y0A21s (0.1–0.8 m).
fn long_range(index: usize) -> bool {
    index == 5 || index == 7
}

/// Metres of IR sensor `index` reading `counts` (Player's fits; readings
/// under 80 counts, beyond the sensor's reach, read as 80).
pub fn ir_range(index: usize, counts: u16) -> f32 {
    let v = f64::from(counts.max(80));
    let m = if long_range(index) {
        (16933.0 / (v - 8.0) - 13.0) / 100.0
    } else {
        (6787.0 / (v - 3.0) - 4.0) / 100.0
    };
    m as f32
}

/// The counts IR sensor `index` reads with something `metres` away: the
/// inverse of [`ir_range`], for the emulator.
pub fn ir_counts(index: usize, metres: f64) -> u16 {
    let (near, far) = if long_range(index) {
        (0.2, 1.5)
    } else {
        (0.1, 0.8)
    };
    let cm = metres.clamp(near, far) * 100.0;
    let counts = if long_range(index) {
        16933.0 / (cm + 13.0) + 8.0
    } else {
        6787.0 / (cm + 4.0) + 3.0
    };
    counts.round().clamp(0.0, 1023.0) as u16
}

/// Player's `SetDigitalData`: the 16 outputs after setting the low `count`
/// of them to `bits`, the rest as they were.
pub fn digital_out(last: u16, count: u32, bits: u32) -> u16 {
    let data = (bits & 0xFFFF) as u16;
    if count >= 16 {
        return data;
    }
    let keep = 0xFFFFu16 << count;
    (last & keep) | (data & !keep)
}

/// Player's `GetDigitalData`: the board's inputs with its bytes swapped,
/// so the second I/O board's inputs are the upper byte.
pub fn digital_in(board: u16) -> u32 {
    u32::from(board.swap_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_are_players() {
        assert!((ticks_per_metre() - 156_455.7).abs() < 0.1);
        // 0.3 m/s at the chips' 154 µs cycle.
        assert_eq!((0.3 * velocity_k(154)) as i32, 473_710);
        // A wheel past 0.3 m/s is held there and the other scaled alike.
        let (l, r) = wheels(0.5, 0.0);
        assert_eq!((l, r), (0.3, 0.3));
        let (l, r) = wheels(0.3, 1.0);
        assert!((r - 0.3).abs() < 1e-12 && (l - 0.1495 * 0.3 / 0.4505).abs() < 1e-9);
        assert_eq!(motion(0.1, 0.1), (0.1, 0.0));
    }

    #[test]
    fn odometry_integrates_wheel_counts() {
        let mut o = Odometry::default();
        let t = ticks_per_metre();
        // One metre straight on.
        let p = o.update(t as i32, t as i32);
        assert!(
            (p.x - 1.0).abs() < 1e-5 && p.y == 0.0 && p.yaw == 0.0,
            "{p:?}"
        );
        // The right wheel forward, the left back: a left turn of a quarter.
        let arc = (AXLE / 2.0 * std::f64::consts::FRAC_PI_2 * t) as i32;
        let p = o.update(t as i32 - arc, t as i32 + arc);
        assert!((p.yaw - std::f64::consts::FRAC_PI_2).abs() < 1e-4, "{p:?}");
        // A right turn of 100° wraps into [0, 2π).
        let e = arc / 9;
        let p = o.update(t as i32 + e, t as i32 - e);
        assert!((p.yaw - (TAU - 10f64.to_radians())).abs() < 1e-3, "{p:?}");
        o.reset();
        assert_eq!(o.update(0, 0), Pose::default());
    }

    #[test]
    fn ir_counts_and_ranges_are_inverse_within_reach() {
        for i in [0, 5] {
            for m in [0.2, 0.4, 0.7] {
                let r = f64::from(ir_range(i, ir_counts(i, m)));
                assert!((r - m).abs() < 0.02, "sensor {i} at {m}: {r}");
            }
        }
        // Beyond reach: the 80-count floor (about 0.84 m for the short ones).
        assert!((ir_range(0, 10) - 0.8414).abs() < 1e-3);
        assert_eq!(analog(0x7FC0), 0x1FF);
        assert!((volts(1023) - 5.0).abs() < 1e-6);
    }

    #[test]
    fn digital_outputs_keep_the_bits_not_set() {
        assert_eq!(digital_out(0xABCD, 16, 0x1234), 0x1234);
        assert_eq!(digital_out(0xABCD, 4, 0x0002), 0xABC2);
        assert_eq!(digital_out(0xABCD, 0, 0xFFFF), 0xABCD);
        assert_eq!(digital_in(0x0102), 0x0201);
    }
}
