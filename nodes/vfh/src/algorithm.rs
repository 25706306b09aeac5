//! VFH+ (Ulrich & Borenstein) as Player's `vfh` computes it, pure.
//!
//! Angles are degrees in the robot's polar frame of Player's code: 0° to the
//! right, 90° straight ahead, 180° to the left. Lengths are millimetres and
//! speeds mm/s inside, so that Player's histogram thresholds (2 000 000 by
//! default, magnitudes `(3000 − d)⁴ / 1e8`) mean what they meant there.
//!
//! One [`Vfh::update`]:
//! 1. the window's cells (`window_diameter` × `cell_size`, front half) that
//!    lie at or beyond the measured range in their direction are occupied;
//!    an occupied cell closer than robot radius + safety distance stops the
//!    robot;
//! 2. each occupied cell adds its magnitude to the sectors its direction
//!    ± the enlargement angle `asin((radius + safety) / d)` overlaps;
//! 3. a binary histogram with hysteresis (`free_space_cutoff`,
//!    `obs_cutoff`, interpolated by speed);
//! 4. a mask for what the robot cannot reach at its turning radius;
//! 5. openings between blocked sectors give candidate directions (narrow:
//!    the middle; wide: the middle, 40° in from each side, and the goal's
//!    direction if it lies between), scored by
//!    `weight_desired_dir·|Δgoal| + weight_current_dir·|Δlast|`;
//! 6. speed rises by `max_acceleration` per second up to the opening's
//!    limit (falls if the goal lies inside a turning circle); the turn rate
//!    is `(picked − 90) / 75 · max_turnrate`.

/// Parameters (Player's option values in SI; converted inside).
#[derive(Debug, Clone, Copy)]
pub struct Params {
    /// Cell size, m.
    pub cell_size: f64,
    /// Cells across the window.
    pub window_diameter: usize,
    /// Sector width, degrees.
    pub sector_angle: u32,
    /// Safety distance at 0 m/s, m.
    pub safety_dist_0ms: f64,
    /// Safety distance at 1 m/s, m.
    pub safety_dist_1ms: f64,
    /// Top speed, m/s.
    pub max_speed: f64,
    /// Top speed through a narrow opening, m/s.
    pub max_speed_narrow_opening: f64,
    /// Top speed through a wide opening, m/s.
    pub max_speed_wide_opening: f64,
    /// m/s².
    pub max_acceleration: f64,
    /// Slowest turn when turning on the spot at the goal, rad/s.
    pub min_turnrate: f64,
    /// Fastest turn at 0 m/s, rad/s.
    pub max_turnrate_0ms: f64,
    /// Fastest turn at 1 m/s, rad/s.
    pub max_turnrate_1ms: f64,
    /// Scales the minimum turning radius.
    pub min_turn_radius_safety_factor: f64,
    /// Histogram value below which a sector is free, at 0 m/s.
    pub free_space_cutoff_0ms: f64,
    /// Histogram value above which a sector is blocked, at 0 m/s.
    pub obs_cutoff_0ms: f64,
    /// Free threshold at 1 m/s.
    pub free_space_cutoff_1ms: f64,
    /// Blocked threshold at 1 m/s.
    pub obs_cutoff_1ms: f64,
    /// Weight of the goal direction.
    pub weight_desired_dir: f64,
    /// Weight of the current direction.
    pub weight_current_dir: f64,
    /// The robot's radius, m.
    pub robot_radius: f64,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            cell_size: 0.1,
            window_diameter: 61,
            sector_angle: 5,
            safety_dist_0ms: 0.1,
            safety_dist_1ms: 0.1,
            max_speed: 0.2,
            max_speed_narrow_opening: 0.2,
            max_speed_wide_opening: 0.2,
            max_acceleration: 0.2,
            min_turnrate: 10f64.to_radians(),
            max_turnrate_0ms: 40f64.to_radians(),
            max_turnrate_1ms: 40f64.to_radians(),
            min_turn_radius_safety_factor: 1.0,
            free_space_cutoff_0ms: 2_000_000.0,
            obs_cutoff_0ms: 2_000_000.0,
            free_space_cutoff_1ms: 2_000_000.0,
            obs_cutoff_1ms: 2_000_000.0,
            weight_desired_dir: 5.0,
            weight_current_dir: 3.0,
            robot_radius: 0.0,
        }
    }
}

/// `a2 − a1` in degrees, wrapped into [−180, 180].
fn delta(a1: f64, a2: f64) -> f64 {
    let d = a2 - a1;
    if d > 180.0 {
        d - 360.0
    } else if d < -180.0 {
        d + 360.0
    } else {
        d
    }
}

struct Cell {
    dist: f64,
    dir: f64,
    mag: f64,
}

/// The VFH+ state between updates.
pub struct Vfh {
    p: Params,
    cells: Vec<Cell>,
    hist_size: usize,
    last_binary: Vec<bool>,
    last_picked: f64,
    last_speed: f64,
    blocked_radius: f64,
}

/// What one update decided.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Motion {
    /// Forward speed, m/s (≥ 0).
    pub speed: f64,
    /// Turn rate, rad/s, counter-clockwise.
    pub turnrate: f64,
    /// Direction picked, degrees (90 = ahead).
    pub picked: f64,
}

impl Vfh {
    /// A fresh state for `p`.
    pub fn new(p: Params) -> Self {
        let w = p.window_diameter.max(3);
        let c = (w / 2) as f64;
        let cw = p.cell_size * 1000.0;
        let mut cells = Vec::new();
        // Rows 0..=c are in front of (or level with) the robot.
        for y in 0..=(w / 2) {
            for x in 0..w {
                let (dx, dy) = (x as f64 - c, c - y as f64);
                if dx == 0.0 && dy == 0.0 {
                    continue;
                }
                let dist = dx.hypot(dy) * cw;
                let dir = dy.atan2(dx).to_degrees().rem_euclid(360.0);
                let m = 3000.0 - dist;
                cells.push(Cell {
                    dist,
                    dir,
                    mag: m * m * m * m / 1e8,
                });
            }
        }
        let hist_size = (360.0 / f64::from(p.sector_angle.max(1))).round() as usize;
        Vfh {
            p,
            cells,
            hist_size,
            last_binary: vec![true; hist_size],
            last_picked: 90.0,
            last_speed: 0.0,
            blocked_radius: 0.0,
        }
    }

    /// The parameters.
    pub fn params(&self) -> &Params {
        &self.p
    }

    /// Sets the robot's radius, m.
    pub fn set_robot_radius(&mut self, r: f64) {
        self.p.robot_radius = r;
    }

    /// Fastest turn at `v` mm/s, deg/s.
    pub fn max_turnrate(&self, v: f64) -> f64 {
        let t0 = self.p.max_turnrate_0ms.to_degrees();
        let t1 = self.p.max_turnrate_1ms.to_degrees();
        (t0 - v * (t0 - t1) / 1000.0).max(0.0)
    }

    fn safety(&self, v: f64) -> f64 {
        let s0 = self.p.safety_dist_0ms * 1000.0;
        let s1 = self.p.safety_dist_1ms * 1000.0;
        (s0 + v * (s1 - s0) / 1000.0).max(0.0)
    }

    /// Decides speed and turn rate. `range(deg)` is the measured range (mm)
    /// in a direction of the polar frame (0°..180°); `speed` is the robot's
    /// forward speed (mm/s); `goal_dir` the goal's direction (deg) and
    /// `goal_dist` its distance (mm); `tol` the goal tolerance (mm); `dt`
    /// the seconds since the last update.
    pub fn update(
        &mut self,
        range: impl Fn(f64) -> f64,
        speed: f64,
        goal_dir: f64,
        goal_dist: f64,
        tol: f64,
        dt: f64,
    ) -> Motion {
        let max_speed = self.p.max_speed * 1000.0;
        let cps = speed.max(self.last_speed).clamp(0.0, max_speed);
        let r = self.p.robot_radius * 1000.0 + self.safety(cps);
        let half_cell = self.p.cell_size * 500.0;
        let sa = f64::from(self.p.sector_angle.max(1));
        let n = self.hist_size;

        // 1-2. Primary polar histogram; abort when something is too close.
        let mut hist = vec![0.0f64; n];
        let mut occupied = Vec::new();
        let mut too_close = false;
        for (k, c) in self.cells.iter().enumerate() {
            if c.dist + half_cell <= range(c.dir) {
                continue;
            }
            if c.dist < r {
                too_close = true;
                break;
            }
            occupied.push(k);
            if c.dist <= r {
                continue;
            }
            let enl = (r / c.dist).asin().to_degrees();
            let (lo, hi) = (c.dir - enl, c.dir + enl);
            let first = (lo / sa).floor() as i64;
            let last = (hi / sa).floor() as i64;
            for s in first..=last {
                hist[s.rem_euclid(n as i64) as usize] += c.mag;
            }
        }
        let (picked, limit) = if too_close {
            (self.last_picked, 0.0)
        } else {
            // 3. Binary histogram with hysteresis.
            let f = cps / 1000.0;
            let low = self.p.free_space_cutoff_0ms
                - f * (self.p.free_space_cutoff_0ms - self.p.free_space_cutoff_1ms);
            let high = self.p.obs_cutoff_0ms - f * (self.p.obs_cutoff_0ms - self.p.obs_cutoff_1ms);
            let binary: Vec<bool> = hist
                .iter()
                .zip(&self.last_binary)
                .map(|(&h, &last)| {
                    if h > high {
                        true
                    } else if h < low {
                        false
                    } else {
                        last
                    }
                })
                .collect();
            self.last_binary.clone_from(&binary);
            // 4. Mask what the turning circles block.
            let omega = self.max_turnrate(cps).to_radians();
            let turn_r = if omega > 0.0 {
                cps / omega * self.p.min_turn_radius_safety_factor
            } else {
                f64::INFINITY
            };
            self.blocked_radius = turn_r + r;
            let (mut phi_right, mut phi_left) = (0.0f64, 180.0f64);
            for &k in &occupied {
                let c = &self.cells[k];
                let (x, y) = (
                    c.dist * c.dir.to_radians().cos(),
                    c.dist * c.dir.to_radians().sin(),
                );
                if delta(c.dir, 90.0) > 0.0 && delta(c.dir, phi_right) <= 0.0 {
                    if (x - turn_r).hypot(y) < self.blocked_radius {
                        phi_right = c.dir;
                    }
                } else if delta(c.dir, 90.0) <= 0.0
                    && delta(c.dir, phi_left) > 0.0
                    && (x + turn_r).hypot(y) < self.blocked_radius
                {
                    phi_left = c.dir;
                }
            }
            let masked: Vec<bool> = (0..n)
                .map(|i| {
                    let a = i as f64 * sa;
                    binary[i] || !(a >= phi_right && a <= phi_left)
                })
                .collect();
            self.select(&masked, goal_dir, max_speed)
        };
        // 6. Speed and turn rate.
        let mut incr = if !(0.0..=0.3).contains(&dt) {
            10.0
        } else {
            (self.p.max_acceleration * 1000.0 * dt).trunc()
        };
        if self.cant_turn_to_goal(goal_dir, goal_dist, tol) {
            incr = -incr;
        }
        let mut speed = (self.last_speed + incr).min(limit);
        let mx = self.max_turnrate(cps);
        let turn = if speed <= 0.0 {
            speed = 0.0;
            mx
        } else if picked > 270.0 && picked < 360.0 {
            -mx
        } else if picked > 180.0 && picked < 270.0 {
            mx
        } else {
            ((picked - 90.0) / 75.0 * mx).round().clamp(-mx, mx)
        };
        self.last_speed = speed;
        Motion {
            speed: speed / 1000.0,
            turnrate: turn.to_radians(),
            picked,
        }
    }

    /// Picks a direction from the masked histogram; returns it and the
    /// speed limit (mm/s) through its opening.
    fn select(&mut self, masked: &[bool], desired: f64, cms: f64) -> (f64, f64) {
        let n = masked.len();
        let sa = f64::from(self.p.sector_angle.max(1));
        let Some(start) = (0..n / 2).find(|&i| masked[i]) else {
            self.last_picked = desired;
            return (desired, cms);
        };
        let narrow_speed = cms.min(self.p.max_speed_narrow_opening * 1000.0);
        let wide_speed = cms.min(self.p.max_speed_wide_opening * 1000.0);
        let mut openings = Vec::new();
        let mut left = true;
        let mut first = 0.0;
        for i in start..=start + n {
            let j = i % n;
            if !masked[j] && left {
                first = j as f64 * sa;
                left = false;
            }
            if masked[j] && !left {
                let mut second = (j as f64 - 1.0) * sa;
                if second < 0.0 {
                    second += 360.0;
                }
                openings.push((first, second));
                left = true;
            }
        }
        let mut candidates: Vec<(f64, f64)> = Vec::new();
        for &(first, second) in &openings {
            let w = delta(first, second).abs();
            if w < 10.0 {
                continue;
            }
            let mid = first + (second - first) / 2.0;
            if w < 80.0 {
                candidates.push((mid, narrow_speed));
            } else {
                let c2 = (first + 40.0) % 360.0;
                let mut c3 = second - 40.0;
                if c3 < 0.0 {
                    c3 += 360.0;
                }
                candidates.push((mid, cms));
                candidates.push((c2, wide_speed));
                candidates.push((c3, wide_speed));
                if delta(desired, c2) < 0.0 && delta(desired, c3) > 0.0 {
                    candidates.push((desired, wide_speed));
                }
            }
        }
        if candidates.is_empty() {
            return (self.last_picked, 0.0);
        }
        let (mut picked, mut limit, mut best) = (90.0, 0.0, f64::INFINITY);
        for &(c, v) in &candidates {
            let cost = self.p.weight_desired_dir * delta(desired, c).abs()
                + self.p.weight_current_dir * delta(self.last_picked, c).abs();
            if cost < best {
                (best, picked, limit) = (cost, c, v);
            }
        }
        self.last_picked = picked;
        (picked, limit)
    }

    /// True when the goal lies inside one of the turning circles.
    fn cant_turn_to_goal(&self, goal_dir: f64, goal_dist: f64, tol: f64) -> bool {
        let b = self.blocked_radius;
        let (gx, gy) = (
            goal_dist * goal_dir.to_radians().cos(),
            goal_dist * goal_dir.to_radians().sin(),
        );
        (gx - b).hypot(gy) + tol < b || (-gx - b).hypot(gy) + tol < b
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(v: &mut Vfh, range: impl Fn(f64) -> f64 + Copy, goal_dir: f64, n: usize) -> Motion {
        let mut m = Motion {
            speed: 0.0,
            turnrate: 0.0,
            picked: 90.0,
        };
        for _ in 0..n {
            m = v.update(range, m.speed * 1000.0, goal_dir, 5000.0, 300.0, 0.1);
        }
        m
    }

    fn params() -> Params {
        Params {
            robot_radius: 0.25,
            ..Params::default()
        }
    }

    #[test]
    fn open_space_drives_at_the_goal_and_ramps_speed() {
        let mut v = Vfh::new(params());
        let m = v.update(|_| 1e6, 0.0, 90.0, 5000.0, 300.0, 0.1);
        assert!((m.speed - 0.02).abs() < 1e-9, "0.2 m/s² for 0.1 s: {m:?}");
        assert_eq!(m.picked, 90.0);
        assert_eq!(m.turnrate, 0.0);
        let m = run(&mut v, |_| 1e6, 90.0, 30);
        assert!((m.speed - 0.2).abs() < 1e-9, "capped at max_speed: {m:?}");
        // Goal to the left: turns left.
        let m = run(&mut v, |_| 1e6, 150.0, 1);
        assert!(m.turnrate > 0.0, "{m:?}");
    }

    #[test]
    fn a_wall_ahead_is_avoided_and_too_close_stops() {
        let mut v = Vfh::new(params());
        // A wall 1 m ahead across 60°..120°; free elsewhere.
        let wall = |d: f64| {
            if (60.0..=120.0).contains(&d) {
                1000.0
            } else {
                1e6
            }
        };
        let m = run(&mut v, wall, 90.0, 20);
        assert!(
            (m.picked - 90.0).abs() > 20.0,
            "steers round the wall: {m:?}"
        );
        assert!(m.turnrate != 0.0);
        // An obstacle inside the robot's radius + safety: stop (and spin).
        let mut v = Vfh::new(params());
        let m = v.update(|_| 200.0, 0.0, 90.0, 5000.0, 300.0, 0.1);
        assert_eq!(m.speed, 0.0, "{m:?}");
    }

    #[test]
    fn a_closed_corridor_gives_no_candidate() {
        let mut v = Vfh::new(params());
        let m = run(&mut v, |_| 600.0, 90.0, 5);
        assert_eq!(m.speed, 0.0, "{m:?}");
    }
}
