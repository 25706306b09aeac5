//! The laser sensor model: how likely a scan is from a pose on the map.
//!
//! The map becomes a distance field (metres from each cell's centre to the
//! nearest obstacle cell's; unknown and off-map count as obstacles, as
//! Player's amcl treats them). Two models use it:
//!
//! - **beam** (Player's, the default): each used beam's range is compared
//!   with the range ray-cast on the map,
//!   `pz = bad + (1 - bad)·exp(-(obs - map)² / (2σ²))`, `p = Π pz`; a beam
//!   at maximum range that the map also sees at maximum range has `pz = 1`.
//!   Rays march through the distance field (sphere tracing), a few steps
//!   per ray instead of one per cell.
//! - **likelihood_field** (from ROS's amcl, which grew out of Player's):
//!   each beam's end point is scored by its distance `d` to the nearest
//!   obstacle, `pz = z_hit·exp(-d²/(2σ_hit²)) + z_rand / max_range`,
//!   `p = 1 + Σ pz³`, `d` capped at a maximum that is also the distance of
//!   a point off the map; no ray casting at all.

use troupe_geom::occmap::OccMap;
use troupe_geom::Pose;
use troupe_msgs::laser;

/// Distance from every cell to the nearest obstacle cell.
pub struct DistanceMap {
    /// In cells, row-major; 0 on obstacles. Rays march in grid units.
    cells: Vec<f32>,
    /// How far a ray may march from anywhere in each cell without entering
    /// an obstacle cell: the distance minus a cell diagonal, at least half a
    /// cell; 0 on obstacles. Kept beside `cells` so that a march step is
    /// one load and one add.
    steps: Vec<f32>,
    /// Metres per cell and its inverse; the origin; the size in cells.
    res: f64,
    inv_res: f64,
    origin: (f64, f64),
    size: (usize, usize),
}

impl DistanceMap {
    /// The distance field of `map`: cells with a state ≥ 0 (occupied or
    /// unknown) are obstacles.
    pub fn new(map: &OccMap) -> Self {
        let res = f64::from(map.info.resolution);
        let inv_res = if res > 0.0 { 1.0 / res } else { 0.0 };
        let cells: Vec<f32> = map
            .distance_field()
            .iter()
            .map(|&d| (f64::from(d) * inv_res) as f32)
            .collect();
        let steps = cells
            .iter()
            .map(|&d| {
                if d <= 0.0 {
                    0.0
                } else {
                    (d - std::f32::consts::SQRT_2).max(0.5)
                }
            })
            .collect();
        DistanceMap {
            cells,
            steps,
            res,
            inv_res,
            origin: (map.info.origin.x, map.info.origin.y),
            size: (map.info.width as usize, map.info.height as usize),
        }
    }

    /// World point (x, y) in grid units.
    #[inline]
    fn grid(&self, x: f64, y: f64) -> (f64, f64) {
        (
            (x - self.origin.0) * self.inv_res,
            (y - self.origin.1) * self.inv_res,
        )
    }

    /// The distance in cells at grid point (gx, gy); `None` off the map.
    /// Truncation is the floor there: the coordinates on the map are positive.
    #[inline]
    fn cells_at(&self, gx: f64, gy: f64) -> Option<f64> {
        let (w, h) = self.size;
        (gx >= 0.0 && gy >= 0.0 && gx < w as f64 && gy < h as f64)
            .then(|| f64::from(self.cells[gy as usize * w + gx as usize]))
    }

    /// Distance at world point (x, y); 0 off the map (an obstacle).
    #[inline]
    pub fn at(&self, x: f64, y: f64) -> f64 {
        self.at_or(x, y, 0.0)
    }

    /// Distance at world point (x, y); `off` off the map.
    #[inline]
    pub fn at_or(&self, x: f64, y: f64, off: f64) -> f64 {
        let (gx, gy) = self.grid(x, y);
        self.cells_at(gx, gy).map_or(off, |d| d * self.res)
    }

    /// Range from (x, y) along `angle` to the first obstacle cell, at most
    /// `max`. Marches by the clearance the field guarantees (the distance
    /// minus a cell diagonal), at least half a cell at a time.
    pub fn range(&self, x: f64, y: f64, angle: f64, max: f64) -> f64 {
        let (s, c) = angle.sin_cos();
        let mut out = [max];
        self.ranges_along(x, y, &[(c, s)], max, &mut out);
        out[0]
    }

    /// [`DistanceMap::range`] for up to [`LANES`] rays from one point at
    /// once: `out[k]` is the range along the unit vector `dirs[k]` (cos, sin).
    ///
    /// One ray's march is a chain of dependent loads; marching several in
    /// lockstep lets the processor overlap their latencies. A ray takes 3–6
    /// steps on a cave map, so what surrounds the march counts as much: the
    /// exit from the map is computed once per ray, and every ray shares the
    /// first step.
    pub fn ranges_along(&self, x: f64, y: f64, dirs: &[(f64, f64)], max: f64, out: &mut [f64]) {
        let n = dirs.len().min(LANES).min(out.len());
        let (gx, gy) = self.grid(x, y);
        let (w, h) = self.size;
        let (wf, hf) = (w as f64, h as f64);
        let tmax = max * self.inv_res;
        if tmax <= 0.0 || !(gx >= 0.0 && gy >= 0.0 && gx < wf && gy < hf) {
            // Off the map is an obstacle (Player's map_calc_range): a ray
            // that starts there ends there.
            out[..n].fill(if tmax <= 0.0 { max } else { 0.0 });
            return;
        }
        // Per ray, in cells: where it leaves the map, and where the march
        // stops (the exit or the maximum range, whichever is nearer).
        let leave = |p: f64, v: f64, size: f64| {
            if v > 1e-12 {
                (size - p) / v
            } else if v < -1e-12 {
                -p / v
            } else {
                f64::INFINITY
            }
        };
        let mut exit = [0.0f64; LANES];
        let mut stop = [0.0f32; LANES];
        let mut dir = [(0.0f32, 0.0f32); LANES];
        for (k, &(c, s)) in dirs[..n].iter().enumerate() {
            exit[k] = leave(gx, c, wf).min(leave(gy, s, hf));
            stop[k] = exit[k].min(tmax) as f32;
            dir[k] = (c as f32, s as f32);
        }
        // The march runs in f32 (a cell is found to a ten-thousandth on a
        // 2000-cell map).
        let (fx, fy) = (gx as f32, gy as f32);
        // Every ray's first step is from the same cell: one load for all.
        let first = self.step_at(fx, fy);
        if first <= 0.0 {
            out[..n].fill(0.0);
            return;
        }
        // A ray that marched to its stop ends at the map's edge or at `max`.
        let end = |k: usize| {
            if exit[k] < tmax {
                exit[k] * self.res
            } else {
                max
            }
        };
        let mut t = [first; LANES];
        let mut live: u32 = (1 << n) - 1;
        while live != 0 {
            for k in 0..n {
                if live & (1 << k) == 0 {
                    continue;
                }
                if t[k] >= stop[k] {
                    out[k] = end(k);
                    live &= !(1 << k);
                    continue;
                }
                let (c, s) = dir[k];
                let step = self.step_at(fx + t[k] * c, fy + t[k] * s);
                if step <= 0.0 {
                    let face = f64::from(self.boundary((fx, fy), dir[k], t[k]));
                    out[k] = face * self.res;
                    live &= !(1 << k);
                    continue;
                }
                t[k] += step;
            }
        }
    }

    /// The march step at grid point (gx, gy), which a ray reaches only short
    /// of its exit from the map: on the map but for rounding at the edge,
    /// which the clamp absorbs.
    #[inline]
    fn step_at(&self, gx: f32, gy: f32) -> f32 {
        let (w, h) = self.size;
        self.steps[(gy as usize).min(h - 1) * w + (gx as usize).min(w - 1)]
    }

    /// Where the ray from grid point `from` along `dir` enters the
    /// obstacle it reached at `t` cells, to a sixteenth of a cell: the march
    /// lands up to half a cell inside, and a range that long on every beam
    /// biases the pose away from walls. (An exact cell walk was tried: it
    /// finds the face to the float, yet amcl's error on the nav route rose
    /// from 1.6–2.0 cm to 2.1–3.2 cm mean against Stage's ranges, which are
    /// cast on a finer grid; the bisection stays.)
    fn boundary(&self, (gx, gy): (f32, f32), (c, s): (f32, f32), t: f32) -> f32 {
        let blocked = |t: f32| self.step_at(gx + t * c, gy + t * s) <= 0.0;
        let (mut free, mut hit) = ((t - 0.5).max(0.0), t);
        if blocked(free) {
            return t;
        }
        for _ in 0..3 {
            let mid = 0.5 * (free + hit);
            if blocked(mid) {
                hit = mid;
            } else {
                free = mid;
            }
        }
        hit
    }

    /// The scan of 181 beams over 180° that a laser at `p` sees, ranges
    /// capped at `max_range` (for tests and benchmarks).
    pub fn scan(&self, p: &Pose, max_range: f64) -> laser::Scan {
        use std::f64::consts::{FRAC_PI_2, PI};
        let res = PI / 180.0;
        laser::Scan {
            min_angle: -FRAC_PI_2 as f32,
            max_angle: FRAC_PI_2 as f32,
            resolution: res as f32,
            max_range: max_range as f32,
            ranges: (0..181)
                .map(|i| {
                    self.range(p.x, p.y, p.yaw - FRAC_PI_2 + f64::from(i) * res, max_range) as f32
                })
                .collect(),
            ..Default::default()
        }
    }
}

/// e^x for x ≤ 0, to 1e-11 relative: libm's `exp` is a call the compiler
/// cannot inline or overlap, and the models take one per beam per particle.
#[inline]
fn exp_neg(x: f64) -> f64 {
    use std::f64::consts::{LN_2, LOG2_E};
    // Below this e^x is subnormal; weights that small are 0 to the filter.
    let x = x.clamp(-708.0, 0.0);
    // x = n·ln 2 + r, |r| ≤ ln 2 / 2, n rounded by the 2^52 + 2^51 trick
    // (f64::round is a libm call on the baseline x86-64 target).
    const ROUND: f64 = 6_755_399_441_055_744.0;
    let n = (x * LOG2_E + ROUND) - ROUND;
    let r = x - n * LN_2;
    // e^r by its Taylor series to r⁹/9!: the next term is under 1e-11.
    let mut p = 1.0 / 362_880.0;
    for k in (1..=8).rev() {
        p = p * r + 1.0 / FACTORIALS[k];
    }
    p = p * r + 1.0;
    p * f64::from_bits(((n as i64 + 1023) as u64) << 52)
}

/// k! for k = 0..=8.
const FACTORIALS: [f64; 9] = [1.0, 1.0, 2.0, 6.0, 24.0, 120.0, 720.0, 5040.0, 40320.0];

/// Rays [`DistanceMap::ranges_along`] marches together.
pub const LANES: usize = 8;

/// Which model scores a scan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Model {
    /// Player's beam model.
    Beam {
        /// Standard deviation of a range, m (`laser_range_var`).
        sigma: f64,
        /// Floor probability of a bad range (`laser_range_bad`).
        bad: f64,
    },
    /// ROS amcl's likelihood field.
    LikelihoodField {
        /// Weight of the hit Gaussian (`laser_z_hit`).
        z_hit: f64,
        /// Weight of random ranges (`laser_z_rand`).
        z_rand: f64,
        /// Standard deviation of the hit, m (`laser_sigma_hit`).
        sigma_hit: f64,
        /// Distances are capped here; an end point off the map is this far
        /// (`laser_likelihood_max_dist`).
        max_dist: f64,
    },
}

/// A scan reduced to the beams the model uses.
#[derive(Debug, Clone, Default)]
pub struct Beams {
    /// (range, bearing in the laser frame) of each used beam.
    pub beams: Vec<(f64, f64)>,
    /// (cos, sin) of each bearing: a particle turns them with one rotation
    /// instead of a sine and cosine per beam.
    dirs: Vec<(f64, f64)>,
    /// The laser's maximum range.
    pub max_range: f64,
}

impl Beams {
    /// Picks `max_beams` beams evenly from a scan, first and last included
    /// (Player's step `(n − 1) / (max_beams − 1)`, at least 1).
    pub fn pick(
        ranges: &[f32],
        min_angle: f64,
        resolution: f64,
        max_range: f64,
        max_beams: usize,
    ) -> Self {
        let n = ranges.len();
        let mut beams = Vec::new();
        if n > 0 && max_beams >= 2 {
            let step = ((n - 1) / (max_beams - 1)).max(1);
            let mut i = 0;
            while i < n {
                beams.push((f64::from(ranges[i]), min_angle + i as f64 * resolution));
                i += step;
            }
        }
        let dirs = beams.iter().map(|&(_, b)| (b.cos(), b.sin())).collect();
        Beams {
            beams,
            dirs,
            max_range,
        }
    }
}

impl Model {
    /// The likelihood of `beams` seen by a laser at world pose `laser`.
    pub fn likelihood(&self, map: &DistanceMap, laser: &Pose, beams: &Beams) -> f64 {
        self.likelihood_on(map, laser, &Pose::default(), beams)
    }

    /// The likelihood of `beams` seen by a laser mounted at `mount` on a
    /// robot at world pose `robot`: the particle filter's inner loop, with
    /// one sine and cosine per particle.
    pub fn likelihood_on(
        &self,
        map: &DistanceMap,
        robot: &Pose,
        mount: &Pose,
        beams: &Beams,
    ) -> f64 {
        let (rs, rc) = robot.yaw.sin_cos();
        let laser = Pose {
            x: robot.x + rc * mount.x - rs * mount.y,
            y: robot.y + rs * mount.x + rc * mount.y,
            yaw: 0.0, // unused: (lc, ls) below carry the heading
        };
        let (ls, lc) = if mount.yaw == 0.0 {
            (rs, rc)
        } else {
            let (ms, mc) = mount.yaw.sin_cos();
            (rs * mc + rc * ms, rc * mc - rs * ms)
        };
        let max = beams.max_range;
        match *self {
            Model::Beam { sigma, bad } => {
                let k = 1.0 / (2.0 * sigma * sigma);
                let mut p = 1.0;
                let mut dirs = [(0.0, 0.0); LANES];
                let mut sims = [0.0; LANES];
                for (obs, rel) in beams.beams.chunks(LANES).zip(beams.dirs.chunks(LANES)) {
                    for (d, &(bc, bs)) in dirs.iter_mut().zip(rel) {
                        *d = (lc * bc - ls * bs, ls * bc + lc * bs);
                    }
                    let n = rel.len();
                    map.ranges_along(laser.x, laser.y, &dirs[..n], max + 1.0, &mut sims[..n]);
                    for (&(obs, _), &sim) in obs.iter().zip(&sims[..n]) {
                        let pz = if obs >= max && sim >= max {
                            1.0
                        } else {
                            let z = obs - sim;
                            bad + (1.0 - bad) * exp_neg(-z * z * k)
                        };
                        p *= pz;
                    }
                }
                p
            }
            Model::LikelihoodField {
                z_hit,
                z_rand,
                sigma_hit,
                max_dist,
            } => {
                let k = 1.0 / (2.0 * sigma_hit * sigma_hit);
                let rand = if max > 0.0 { z_rand / max } else { 0.0 };
                let mut p = 1.0;
                for (&(obs, _), &(bc, bs)) in beams.beams.iter().zip(&beams.dirs) {
                    if obs >= max {
                        continue;
                    }
                    let (c, s) = (lc * bc - ls * bs, ls * bc + lc * bs);
                    let d = map
                        .at_or(laser.x + obs * c, laser.y + obs * s, max_dist)
                        .min(max_dist);
                    let pz = z_hit * exp_neg(-d * d * k) + rand;
                    p += pz * pz * pz;
                }
                p
            }
        }
    }
}

/// Player's sonar model (amcl's `models/sonar.c`): each reading within
/// 2 m weighs the pose by `0.2 + 0.8 · N(observed − expected; σ² 0.04)`,
/// the expected range traced from the transducer's pose in the map out to
/// 8 m, both ranges rounded to the centimetre as Player's table rounds them.
pub fn sonar_likelihood(map: &DistanceMap, p: &Pose, sonars: &[Pose], ranges: &[f64]) -> f64 {
    const RANGE_MAX: f64 = 2.0;
    const COV: f64 = 0.20 * 0.20;
    const BAD: f64 = 0.20;
    const TRACE: f64 = 8.0;
    let cm = |r: f64| (r / 0.01 + 0.5).floor().min(TRACE / 0.01 - 1.0) * 0.01;
    let norm = 1.0 / (2.0 * std::f64::consts::PI * COV).sqrt();
    let mut w = 1.0;
    for (s, &obs) in sonars.iter().zip(ranges) {
        if !(0.0..=RANGE_MAX).contains(&obs) {
            continue;
        }
        let at = p.compose(s);
        let expected = map.range(at.x, at.y, at.yaw, TRACE);
        let z = cm(obs) - cm(expected);
        w *= BAD + (1.0 - BAD) * norm * (-(z * z) / (2.0 * COV)).exp();
    }
    w
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, PI};
    use troupe_geom::occmap::{FREE, OCCUPIED};
    use troupe_msgs::{map, Pose2d};

    /// A 10 m × 10 m room at 0.1 m, walls on the border, origin at (0, 0).
    fn room() -> OccMap {
        let info = map::Info {
            width: 100,
            height: 100,
            resolution: 0.1,
            origin: Pose2d::new(0.0, 0.0, 0.0),
        };
        OccMap::from_fn(info, |i, j| {
            if i == 0 || j == 0 || i == 99 || j == 99 {
                OCCUPIED
            } else {
                FREE
            }
        })
    }

    #[test]
    fn the_fast_exponential_is_the_exponential() {
        let mut x = 0.0;
        while x > -720.0 {
            let (got, want) = (exp_neg(x), x.exp());
            let tol = 1e-11 * want + if x < -708.0 { 1e-307 } else { 0.0 };
            assert!((got - want).abs() <= tol, "e^{x}: {got} vs {want}");
            x -= 0.0137;
        }
        assert_eq!(exp_neg(0.0), 1.0);
    }

    #[test]
    fn rays_end_on_the_face_a_fine_march_finds() {
        // Scattered single-cell and block obstacles; the march's face
        // against a walk in thousandths of a cell: at most a sixteenth of a
        // cell beyond it, but where a half-cell step cut a corner.
        let mut m = room();
        for &(i, j) in &[(30, 40), (70, 20), (55, 55), (56, 55), (56, 56), (20, 80)] {
            m.cells[j * 100 + i] = OCCUPIED;
        }
        let d = DistanceMap::new(&m);
        let fine = |x: f64, y: f64, a: f64| {
            let (s, c) = a.sin_cos();
            let mut t = 0.0;
            while t < 20.0 && d.at(x + t * c, y + t * s) > 0.0 {
                t += 0.0001;
            }
            t
        };
        let (mut close, mut all) = (0, 0);
        for (x, y) in [(5.0, 5.0), (2.5, 2.5), (7.7, 3.1), (4.4, 6.6)] {
            for k in 0..90 {
                let a = f64::from(k) * 0.0698;
                let (got, want) = (d.range(x, y, a, 20.0), fine(x, y, a));
                assert!(
                    (-0.0005..0.05).contains(&(got - want)),
                    "from ({x}, {y}) at {a}: {got} vs {want}"
                );
                all += 1;
                close += usize::from(got - want < 0.1 / 16.0 + 0.0005);
            }
        }
        assert!(close * 100 >= all * 90, "{close} of {all} within 1/16 cell");
    }

    #[test]
    fn distance_field_is_euclidean() {
        let d = DistanceMap::new(&room());
        assert_eq!(d.at(0.05, 0.05), 0.0);
        // Cell (10, 50): 10 cells from the left wall.
        assert!((d.at(1.05, 5.05) - 1.0).abs() < 1e-6);
        // Cell (3, 4) from corner cell... nearest wall cell is (0, 4): 3 cells.
        assert!((d.at(0.35, 0.45) - 0.3).abs() < 1e-6);
        assert_eq!(d.at(-1.0, 5.0), 0.0, "off the map is an obstacle");
        // Against brute force on a map with scattered obstacles.
        let mut m = room();
        for &(i, j) in &[(30, 40), (70, 20), (55, 55)] {
            m.cells[j * 100 + i] = OCCUPIED;
        }
        let d = DistanceMap::new(&m);
        let obstacles: Vec<(f64, f64)> = (0..10_000)
            .filter(|&k| m.cells[k] >= 0)
            .map(|k| ((k % 100) as f64, (k / 100) as f64))
            .collect();
        for &(i, j) in &[(31, 42), (60, 61), (12, 88), (50, 50)] {
            let want = obstacles
                .iter()
                .map(|&(a, b)| ((a - i as f64).powi(2) + (b - j as f64).powi(2)).sqrt())
                .fold(f64::INFINITY, f64::min)
                * 0.1;
            let got = d.at(i as f64 * 0.1 + 0.05, j as f64 * 0.1 + 0.05);
            assert!((got - want).abs() < 1e-5, "({i}, {j}) {got} vs {want}");
        }
    }

    #[test]
    fn rays_stop_at_walls() {
        let d = DistanceMap::new(&room());
        // From the centre to the right wall (its cell starts at x = 9.9).
        let r = d.range(5.0, 5.0, 0.0, 20.0);
        assert!(
            (r - 4.9).abs() < 0.01,
            "ends at the wall's face, not inside: {r}"
        );
        let r = d.range(5.0, 5.0, std::f64::consts::FRAC_PI_4, 20.0);
        assert!((r - 4.9 * std::f64::consts::SQRT_2).abs() < 0.1, "{r}");
        assert_eq!(d.range(5.0, 5.0, 0.0, 2.0), 2.0);
        assert_eq!(d.range(0.05, 0.05, 0.0, 2.0), 0.0);
    }

    #[test]
    fn rays_stop_at_the_edge_of_a_map_without_walls() {
        // 10 m × 10 m, all free but one cell at the far corner: the field
        // says the corner cell is far from everything, yet off the map is
        // an obstacle (Player's map_calc_range) and Stage draws a boundary.
        let info = map::Info {
            width: 100,
            height: 100,
            resolution: 0.1,
            origin: Pose2d::new(0.0, 0.0, 0.0),
        };
        let m = OccMap::from_fn(
            info,
            |i, j| if (i, j) == (99, 99) { OCCUPIED } else { FREE },
        );
        let d = DistanceMap::new(&m);
        // From (1, 1) straight down and left: 1 m to the edge.
        let r = d.range(1.0, 1.0, -std::f64::consts::FRAC_PI_2, 8.0);
        assert!((r - 1.0).abs() < 0.01, "{r}");
        let r = d.range(1.0, 1.0, std::f64::consts::PI, 8.0);
        assert!((r - 1.0).abs() < 0.01, "{r}");
        let r = d.range(1.0, 1.0, -3.0 * std::f64::consts::FRAC_PI_4, 8.0);
        assert!((r - std::f64::consts::SQRT_2).abs() < 0.01, "{r}");
    }

    #[test]
    fn lockstep_rays_agree_with_single_rays() {
        let d = DistanceMap::new(&room());
        for (x, y) in [(5.0, 5.0), (0.5, 9.3), (9.8, 0.2), (3.3, 7.1), (-1.0, 5.0)] {
            for max in [0.0, 1.0, 20.0] {
                let dirs: Vec<(f64, f64)> = (0..LANES)
                    .map(|k| {
                        let a = 0.1 + k as f64 * 0.77;
                        (a.cos(), a.sin())
                    })
                    .collect();
                let mut out = [f64::NAN; LANES];
                d.ranges_along(x, y, &dirs, max, &mut out);
                for (k, &lane) in out.iter().enumerate() {
                    let one = d.range(x, y, 0.1 + k as f64 * 0.77, max);
                    assert_eq!(lane, one, "ray {k} from ({x}, {y}), max {max}");
                }
            }
        }
    }

    #[test]
    fn a_mounted_laser_sees_what_the_same_laser_placed_in_the_world_sees() {
        let m = room();
        let d = DistanceMap::new(&m);
        let scan = d.scan(&Pose::new(4.2, 5.5, 0.6), 8.0);
        let beams = Beams::pick(&scan.ranges, -FRAC_PI_2, PI / 180.0, 8.0, 6);
        let model = Model::Beam {
            sigma: 0.15,
            bad: 0.01,
        };
        let (robot, mount) = (Pose::new(4.0, 5.4, 0.5), Pose::new(0.2, 0.05, 0.1));
        let placed = model.likelihood(&d, &robot.compose(&mount), &beams);
        let mounted = model.likelihood_on(&d, &robot, &mount, &beams);
        assert!(
            (placed - mounted).abs() <= 1e-9 * placed.abs().max(1e-300),
            "{placed} vs {mounted}"
        );
    }

    #[test]
    fn models_prefer_the_true_pose() {
        let m = room();
        let d = DistanceMap::new(&m);
        let truth = Pose::new(3.0, 4.0, 0.3);
        // A 181-beam scan simulated from the truth.
        let ranges = d.scan(&truth, 8.0).ranges;
        let beams = Beams::pick(
            &ranges,
            -std::f64::consts::FRAC_PI_2,
            std::f64::consts::PI / 180.0,
            8.0,
            6,
        );
        assert_eq!(beams.beams.len(), 6);
        assert!((beams.beams[5].1 - std::f64::consts::FRAC_PI_2).abs() < 1e-9);
        for model in [
            Model::Beam {
                sigma: 0.1,
                bad: 0.1,
            },
            Model::LikelihoodField {
                z_hit: 0.95,
                z_rand: 0.05,
                sigma_hit: 0.2,
                max_dist: 2.0,
            },
        ] {
            let at = |p: Pose| model.likelihood(&d, &p, &beams);
            let good = at(truth);
            for wrong in [
                Pose::new(3.5, 4.0, 0.3),
                Pose::new(3.0, 3.5, 0.3),
                Pose::new(3.0, 4.0, 0.6),
                Pose::new(7.0, 6.0, -2.0),
            ] {
                assert!(
                    good > at(wrong),
                    "{model:?}: {good} vs {} at {wrong:?}",
                    at(wrong)
                );
            }
        }
        // Too few beams in the scan: every beam used, never a zero step.
        let b = Beams::pick(&ranges[..3], 0.0, 0.1, 8.0, 6);
        assert_eq!(b.beams.len(), 3);
        assert!(Beams::pick(&ranges, 0.0, 0.1, 8.0, 1).beams.is_empty());
    }
}
