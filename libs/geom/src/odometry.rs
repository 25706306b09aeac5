//! Dead reckoning from a robot controller's wrapping position counters.

use crate::pose::Pose;

/// Odometry integrated from x/y counters that wrap at `2^bits` ticks (a
/// Pioneer's 15 bits, an Erratic's 12) and a heading read directly. The
/// first sample is the origin; [`Odometry::set`] re-frames the pose the
/// way Player's `set_odom` request means it.
#[derive(Debug, Clone, Copy)]
pub struct Odometry {
    bits: u32,
    raw: Option<(u16, u16)>,
    x: f64,
    y: f64,
    /// The reported pose = frame ⊕ (x, y, heading).
    frame: Pose,
}

impl Odometry {
    /// Odometry on `bits`-bit counters, not yet started.
    pub fn new(bits: u32) -> Self {
        Odometry {
            bits,
            raw: None,
            x: 0.0,
            y: 0.0,
            frame: Pose::default(),
        }
    }

    /// The signed change between two counter values, the short way round.
    pub fn change(&self, from: u16, to: u16) -> i32 {
        let m = 1i32 << self.bits;
        let d = (i32::from(to) - i32::from(from)).rem_euclid(m);
        if d >= m / 2 {
            d - m
        } else {
            d
        }
    }

    /// Takes new counters (`mm_per_tick` each) and the heading (radians);
    /// returns the pose in metres.
    pub fn update(&mut self, x: u16, y: u16, yaw: f64, mm_per_tick: f64) -> Pose {
        let mask = ((1u32 << self.bits) - 1) as u16;
        let raw = (x & mask, y & mask);
        if let Some((x0, y0)) = self.raw {
            self.x += f64::from(self.change(x0, raw.0)) * mm_per_tick;
            self.y += f64::from(self.change(y0, raw.1)) * mm_per_tick;
        }
        self.raw = Some(raw);
        self.frame
            .compose(&Pose::new(self.x / 1000.0, self.y / 1000.0, yaw))
    }

    /// Makes the pose that reads `now` read `want` from here on.
    pub fn set(&mut self, now: Pose, want: Pose) {
        let local = self.frame.inverse().compose(&now);
        self.frame = want.compose(&local.inverse());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counters_wrap_and_set_reframes() {
        let o = Odometry::new(15);
        assert_eq!(o.change(100, 150), 50);
        assert_eq!(o.change(32760, 10), 18);
        assert_eq!(o.change(10, 32760), -18);
        let twelve = Odometry::new(12);
        assert_eq!(twelve.change(4090, 5), 11);

        let mut o = Odometry::new(15);
        // The first sample is the origin, whatever its counters say.
        assert_eq!(o.update(5000, 0, 0.0, 0.485), Pose::new(0.0, 0.0, 0.0));
        let pose = o.update(5000 + 2062, 0, 0.0, 0.485);
        assert!((pose.x - 1.000_07).abs() < 1e-4, "{pose:?}");
        o.set(pose, Pose::new(10.0, 5.0, 0.0));
        let moved = o.update(5000 + 2 * 2062, 0, 0.0, 0.485);
        assert!(
            (moved.x - 11.0).abs() < 1e-3 && (moved.y - 5.0).abs() < 1e-9,
            "{moved:?}"
        );
    }
}
