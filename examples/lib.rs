//! What the tutorial programs share: their flags and the wander rule.
//!
//! Each example is one file a student can read top to bottom; only the flags
//! every one of them takes, and the obstacle-avoidance rule three of them
//! drive with, live here.

use clap::Parser;
use troupe_client::{Client, Position2dProxy, RangerProxy};
use troupe_node::ZenohArgs;

/// The flags every example takes: `--robot PORT`, `--for SECS` and Troupe's network flags.
#[derive(Debug, Parser)]
pub struct Common {
    /// The robot (Player's port).
    #[arg(short = 'p', long, default_value_t = 6665)]
    pub robot: u32,
    /// Stop after this many seconds of the robot's clock (simulated time
    /// under Stage); 0 runs until the lesson is over or Ctrl-C.
    #[arg(long = "for", value_name = "SECS", default_value_t = 0.0)]
    pub run_for: f64,
    /// Network flags, as for every `troupe` command.
    #[command(flatten)]
    pub zenoh: ZenohArgs,
}

impl Common {
    /// Whether `--for` has run out, by the newest data's clock, counted from `t0`.
    pub fn time_is_up(&self, client: &Client, t0: f64) -> bool {
        self.run_for > 0.0 && client.data_time() - t0 >= self.run_for
    }
}

/// Closer than this ahead: stop and turn on the spot.
pub const AVOID: f64 = 0.4;
/// Closer than this ahead: slow down and turn away.
pub const CAUTION: f64 = 0.7;
/// Cruising speed, m/s.
pub const CRUISE: f64 = 0.4;

/// The classic wander rule over a ring of sonars (or any ranger): from the
/// ranges and their bearings, a forward speed (m/s) and a turn rate (rad/s).
///
/// `turning` remembers which way the robot turned last time it had to, so
/// it keeps turning the same way until the way ahead is clear: a robot that
/// changes its mind at every reading can dither in a corner forever.
pub fn wander(ranges: &[f64], bearings: &[f64], turning: &mut f64) -> (f64, f64) {
    let (mut ahead, mut left, mut right) = (f64::INFINITY, 0.0, 0.0);
    for (&r, &b) in ranges.iter().zip(bearings) {
        // Beams within 60 degrees of straight ahead decide; the sides vote
        // on which way to turn, by how much room they see.
        if b.abs() <= 60f64.to_radians() {
            ahead = ahead.min(r);
        }
        if b > 0.0 && b < 100f64.to_radians() {
            left += r.min(3.0);
        } else if b < 0.0 && b > -100f64.to_radians() {
            right += r.min(3.0);
        }
    }
    if ahead >= CAUTION {
        *turning = 0.0;
        return (CRUISE, 0.0);
    }
    if *turning == 0.0 {
        *turning = if left >= right { 1.0 } else { -1.0 };
    }
    if ahead < AVOID {
        (0.0, *turning * 40f64.to_radians())
    } else {
        (0.1, *turning * 20f64.to_radians())
    }
}

/// A base and its sonar ring, driven by [`wander`]: what `wander.rs`
/// does, packaged for the lessons that wander several robots.
pub struct Wanderer {
    /// The base.
    pub base: Position2dProxy,
    /// Its sonars.
    pub sonar: RangerProxy,
    bearings: Vec<f64>,
    turning: f64,
}

impl Wanderer {
    /// Base `position2d:base` and sonars `ranger:sonar` of `client`'s robot;
    /// asks the sonars where they point and switches the motors on.
    pub fn new(client: &Client, base: u32, sonar: u32) -> anyhow::Result<Self> {
        let base = Position2dProxy::new(client, base)?;
        let sonar = RangerProxy::new(client, sonar)?;
        let bearings = sonar
            .request_geom()?
            .element_poses
            .iter()
            .map(|p| p.yaw)
            .collect();
        base.set_motor_enable(true)?;
        Ok(Wanderer {
            base,
            sonar,
            bearings,
            turning: 0.0,
        })
    }

    /// Steers by the newest sonar ranges (call after `Client::read`).
    pub fn step(&mut self) -> anyhow::Result<()> {
        let ranges = self.sonar.ranges();
        if ranges.len() == self.bearings.len() {
            let (v, w) = wander(&ranges, &self.bearings, &mut self.turning);
            self.base.set_speed(v, w)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clear_ahead_goes_straight() {
        let mut t = 0.0;
        assert_eq!(wander(&[5.0, 5.0], &[0.2, -0.2], &mut t), (CRUISE, 0.0));
    }

    #[test]
    fn a_near_wall_stops_and_turns_toward_the_open_side_and_keeps_turning() {
        let mut t = 0.0;
        // Room on the right.
        let (v, w) = wander(&[0.3, 0.3, 0.5, 3.0], &[0.1, -0.1, 1.2, -1.2], &mut t);
        assert_eq!(v, 0.0);
        assert!(w < 0.0);
        // The left now looks better, but the robot keeps its turn.
        let (_, w) = wander(&[0.3, 0.3, 3.0, 0.5], &[0.1, -0.1, 1.2, -1.2], &mut t);
        assert!(w < 0.0);
        // Clear again: straight on, and the next obstacle decides afresh.
        assert_eq!(wander(&[2.0], &[0.0], &mut t), (CRUISE, 0.0));
        assert_eq!(t, 0.0);
    }

    #[test]
    fn caution_zone_slows_and_turns_gently() {
        let mut t = 0.0;
        let (v, w) = wander(&[0.6], &[0.0], &mut t);
        assert!(v > 0.0 && v < CRUISE);
        assert!(w.abs() > 0.0 && w.abs() < 40f64.to_radians());
    }
}
