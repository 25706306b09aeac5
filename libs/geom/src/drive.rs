//! A differential-drive body in a box-shaped room: the robot inside the
//! device emulators.

use crate::pose::{normalize, Pose};

/// A round robot of `radius` m driving in the room `x0..x1` × `y0..y1`:
/// its true pose, and its odometry since the last reset (the same motion,
/// from its own origin). A move that would touch a wall does not happen
/// and the robot is stalled.
#[derive(Debug, Clone, Copy)]
pub struct DiffDrive {
    /// The true pose in the room.
    pub pose: Pose,
    /// Odometry: the motion since the last [`DiffDrive::reset_odometry`].
    pub odometry: Pose,
    /// The last step hit a wall.
    pub stalled: bool,
    room: (f64, f64, f64, f64),
    radius: f64,
}

impl DiffDrive {
    /// A robot at the origin of `room`, facing +x.
    pub fn new(room: (f64, f64, f64, f64), radius: f64) -> Self {
        DiffDrive {
            pose: Pose::default(),
            odometry: Pose::default(),
            stalled: false,
            room,
            radius,
        }
    }

    /// The room.
    pub fn room(&self) -> (f64, f64, f64, f64) {
        self.room
    }

    /// Odometry back to zero.
    pub fn reset_odometry(&mut self) {
        self.odometry = Pose::default();
    }

    /// Drives at `v` m/s and `w` rad/s for `dt` s.
    pub fn step(&mut self, v: f64, w: f64, dt: f64) {
        let (x0, x1, y0, y1) = self.room;
        let r = self.radius;
        let p = self.pose;
        let (nx, ny) = (p.x + v * dt * p.yaw.cos(), p.y + v * dt * p.yaw.sin());
        let inside = nx - r > x0 && nx + r < x1 && ny - r > y0 && ny + r < y1;
        self.stalled = v != 0.0 && !inside;
        let d = if self.stalled { 0.0 } else { v * dt };
        self.pose = Pose::new(
            p.x + d * p.yaw.cos(),
            p.y + d * p.yaw.sin(),
            normalize(p.yaw + w * dt),
        );
        let o = self.odometry;
        self.odometry = Pose::new(
            o.x + d * o.yaw.cos(),
            o.y + d * o.yaw.sin(),
            normalize(o.yaw + w * dt),
        );
    }
}

/// The body an emulated robot drives: a room of its own ([`DiffDrive`]) or
/// a robot in a simulator. The emulator turns wheel commands into `drive`
/// calls and reads its packets' odometry, stall and ranges from here.
pub trait Body {
    /// Drives at `v` m/s and `w` rad/s for `dt` s (a simulator may keep
    /// its own time: `dt` is the emulator's cycle).
    fn drive(&mut self, v: f64, w: f64, dt: f64);
    /// The motion since the last [`Body::reset_odometry`].
    fn odometry(&self) -> Pose;
    /// Odometry back to zero.
    fn reset_odometry(&mut self);
    /// The robot is pushing against something.
    fn stalled(&self) -> bool;
    /// The range seen by sensor `index` (a sonar), at `sensor` in the
    /// robot's frame, out to `max` m.
    fn range(&mut self, index: usize, sensor: Pose, max: f64) -> f64;
}

impl Body for DiffDrive {
    fn drive(&mut self, v: f64, w: f64, dt: f64) {
        self.step(v, w, dt);
    }

    fn odometry(&self) -> Pose {
        self.odometry
    }

    fn reset_odometry(&mut self) {
        DiffDrive::reset_odometry(self);
    }

    fn stalled(&self) -> bool {
        self.stalled
    }

    fn range(&mut self, _index: usize, sensor: Pose, max: f64) -> f64 {
        let at = self.pose.compose(&sensor);
        crate::ray_to_box(at.x, at.y, at.yaw, self.room).min(max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drives_turns_and_stalls_at_a_wall() {
        let mut r = DiffDrive::new((-4.0, 4.0, -3.0, 3.0), 0.25);
        for _ in 0..10 {
            r.step(0.5, 0.0, 0.1);
        }
        assert!((r.pose.x - 0.5).abs() < 1e-9 && (r.odometry.x - 0.5).abs() < 1e-9);
        for _ in 0..200 {
            r.step(0.5, 0.0, 0.1);
        }
        assert!(r.stalled && r.pose.x < 4.0 - 0.25);
        for _ in 0..10 {
            r.step(0.0, std::f64::consts::FRAC_PI_2, 0.1);
        }
        assert!((r.pose.yaw - std::f64::consts::FRAC_PI_2).abs() < 1e-9);
        r.reset_odometry();
        r.step(1.0, 0.0, 0.1);
        assert!((r.odometry.x - 0.1).abs() < 1e-9 && (r.pose.y - r.pose.y.round()).abs() > 0.0);
    }
}
