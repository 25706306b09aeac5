//! Correlative scan matching (Olson, "Real-Time Correlative Scan Matching",
//! 2009): a scan's points are laid on a likelihood field of what was seen
//! before at every pose of a window, and the pose where they fit best wins.
//!
//! The search is exhaustive, so it cannot be caught in a local optimum the
//! way ICP can, and it says how good the best fit is (the share of points
//! that land on something), which is what a loop closure is accepted on.
//! It runs on two fields: a coarse one (cells 4× larger, blurred wider)
//! over the whole window, then the fine one around the best few coarse
//! poses, then a last look between the fine steps.

use nalgebra::Matrix3;
use troupe_geom::Pose;

/// For each cell, how likely a beam ending there hit something:
/// `exp(-d² / 2σ²)` of its distance `d` to the nearest point seen.
#[derive(Debug, Clone)]
pub struct Field {
    x0: f64,
    y0: f64,
    res: f64,
    w: usize,
    h: usize,
    cells: Vec<f32>,
}

impl Field {
    /// The field of `points` (world frame) with cells of `res` metres and a
    /// falloff of `sigma`, covering the points and `margin` around them.
    pub fn new(points: &[(f64, f64)], res: f64, sigma: f64, margin: f64) -> Field {
        let (mut lo, mut hi) = ((f64::MAX, f64::MAX), (f64::MIN, f64::MIN));
        for &(x, y) in points {
            lo = (lo.0.min(x), lo.1.min(y));
            hi = (hi.0.max(x), hi.1.max(y));
        }
        if points.is_empty() {
            (lo, hi) = ((0.0, 0.0), (0.0, 0.0));
        }
        let (x0, y0) = (lo.0 - margin, lo.1 - margin);
        let w = (((hi.0 + margin - x0) / res).ceil() as usize).max(1);
        let h = (((hi.1 + margin - y0) / res).ceil() as usize).max(1);
        let mut cells = vec![0f32; w * h];
        // Each cell within 3σ of a point takes the likelihood of its centre,
        // exp(k dx²) exp(k dy²): one exp a row and one a column, not one a
        // cell (exp was a fifth of a Freiburg 079 build).
        let reach = (3.0 * sigma / res).ceil() as i64;
        let k = -1.0 / (2.0 * sigma * sigma);
        let mut across = Vec::with_capacity(2 * reach as usize + 1);
        for &(x, y) in points {
            let ci = ((x - x0) / res).floor() as i64;
            let cj = ((y - y0) / res).floor() as i64;
            let (i0, i1) = ((ci - reach).max(0), (ci + reach).min(w as i64 - 1));
            across.clear();
            across.extend((i0..=i1).map(|i| {
                let dx = x0 + (i as f64 + 0.5) * res - x;
                (dx * dx * k).exp()
            }));
            for j in (cj - reach).max(0)..=(cj + reach).min(h as i64 - 1) {
                let dy = y0 + (j as f64 + 0.5) * res - y;
                let down = (dy * dy * k).exp();
                let row = &mut cells[j as usize * w + i0 as usize..=j as usize * w + i1 as usize];
                for (c, a) in row.iter_mut().zip(&across) {
                    *c = c.max((a * down) as f32);
                }
            }
        }
        Field {
            x0,
            y0,
            res,
            w,
            h,
            cells,
        }
    }

    /// Metres per cell.
    pub fn res(&self) -> f64 {
        self.res
    }

    #[inline]
    fn cell(&self, i: i64, j: i64) -> f32 {
        if i >= 0 && j >= 0 && (i as usize) < self.w && (j as usize) < self.h {
            self.cells[j as usize * self.w + i as usize]
        } else {
            0.0
        }
    }

    /// The field at a world point, interpolated between cells.
    pub fn at(&self, x: f64, y: f64) -> f64 {
        let fx = (x - self.x0) / self.res - 0.5;
        let fy = (y - self.y0) / self.res - 0.5;
        let (i, j) = (floor(fx), floor(fy));
        let (u, v) = ((fx - i as f64) as f32, (fy - j as f64) as f32);
        // The four cells at once where all are inside (one bounds check,
        // not four: this is most of a build's time).
        let (c00, c10, c01, c11) =
            if i >= 0 && j >= 0 && (i as usize) + 1 < self.w && (j as usize) + 1 < self.h {
                let k = j as usize * self.w + i as usize;
                let row = &self.cells[k..k + self.w + 2];
                (row[0], row[1], row[self.w], row[self.w + 1])
            } else {
                (
                    self.cell(i, j),
                    self.cell(i + 1, j),
                    self.cell(i, j + 1),
                    self.cell(i + 1, j + 1),
                )
            };
        let a = c00 * (1.0 - u) + c10 * u;
        let b = c01 * (1.0 - u) + c11 * u;
        f64::from(a * (1.0 - v) + b * v)
    }

    /// The mean of the field under `points` (robot frame) placed at `pose`.
    pub fn score(&self, points: &[(f64, f64)], pose: Pose) -> f64 {
        if points.is_empty() {
            return 0.0;
        }
        let place = pose.applier();
        let sum: f64 = points
            .iter()
            .map(|&(x, y)| {
                let (wx, wy) = place(x, y);
                self.at(wx, wy)
            })
            .sum();
        sum / points.len() as f64
    }
}

/// A beam's end point's own error (metres): a laser's noise and the
/// quantisation of the grid its ranges were read on.
const BEAM_NOISE: f64 = 0.02;

/// The share of a scan's points whose errors are independent: neighbouring
/// beams share the surface, its angle and the range quantisation.
const INDEPENDENT: f64 = 0.25;

impl Field {
    /// What `points` (robot frame) fitting at `pose` says of the pose: the
    /// information matrix (the covariance's inverse) of x, y and yaw in the
    /// world frame, by Laplace's approximation (Olson 2009, section IV):
    /// the fit's curvature at `pose`, each point an independent beam of
    /// [`BEAM_NOISE`] for [`INDEPENDENT`] of them. Where the scan cannot
    /// tell (along a corridor, along a lone wall) the fit is flat and the
    /// information nil, so a loop closure there pulls the graph only where
    /// its scan saw something. `reach` is the farthest point's range.
    pub fn information(&self, points: &[(f64, f64)], pose: Pose, reach: f64) -> Matrix3<f64> {
        // A cell's step: the field is interpolated between cell centres, so
        // half a cell either way of a wall lying between two is flat.
        let h = [self.res, self.res, self.res / reach.max(1.0)];
        let at = |d: [f64; 3]| {
            self.score(
                points,
                Pose::new(pose.x + d[0], pose.y + d[1], pose.yaw + d[2]),
            )
        };
        let s0 = at([0.0; 3]);
        let mut hess = Matrix3::zeros();
        for i in 0..3 {
            let mut d = [0.0; 3];
            d[i] = h[i];
            let plus = at(d);
            d[i] = -h[i];
            let minus = at(d);
            hess[(i, i)] = (plus - 2.0 * s0 + minus) / (h[i] * h[i]);
            for j in 0..i {
                let mut c = 0.0;
                for (si, sj) in [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)] {
                    let mut d = [0.0; 3];
                    d[i] = si * h[i];
                    d[j] = sj * h[j];
                    c += si * sj * at(d);
                }
                hess[(i, j)] = c / (4.0 * h[i] * h[j]);
                hess[(j, i)] = hess[(i, j)];
            }
        }
        // The fit's mean over points is a log-likelihood over the points,
        // each of variance sigma_f² against the field's falloff.
        let sigma_f = 1.5 * self.res;
        let k = points.len() as f64 * INDEPENDENT * (sigma_f / BEAM_NOISE).powi(2);
        // Curvature, never negative: a direction the fit falls along is one
        // it says nothing of.
        let eig = (-hess * k).symmetric_eigen();
        let kept = eig.eigenvalues.map(|l| l.max(0.0));
        eig.eigenvectors * Matrix3::from_diagonal(&kept) * eig.eigenvectors.transpose()
    }
}

/// `x` rounded down, without libm's `floor` (a call on baseline x86_64,
/// a tenth of a build's time in `Field::at`).
#[inline]
fn floor(x: f64) -> i64 {
    let i = x as i64;
    if (i as f64) > x {
        i - 1
    } else {
        i
    }
}

/// How far from its guess a pose is looked for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Window {
    /// Metres either way, in x and y.
    pub xy: f64,
    /// Radians either way.
    pub yaw: f64,
}

/// The best pose found and how well the scan fits there (0–1: the mean
/// likelihood of its points).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Match {
    /// The pose.
    pub pose: Pose,
    /// The fit.
    pub score: f64,
}

/// A fine and a coarse field of the same points.
#[derive(Debug, Clone)]
pub struct Matcher {
    fine: Field,
    coarse: Field,
}

/// How many of the best coarse poses are refined.
const CANDIDATES: usize = 6;

/// What odometry says of a pose: a match is charged `weight × ((d /
/// xy)² + (dyaw / yaw)²)` for lying `d` metres and `dyaw` radians from its
/// guess, so where the scan cannot tell (along a corridor) the guess wins.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prior {
    /// Metres at which the charge is `weight`.
    pub xy: f64,
    /// Radians at which the charge is `weight`.
    pub yaw: f64,
    /// The charge there.
    pub weight: f64,
}

impl Prior {
    fn charge(&self, guess: Pose, p: Pose) -> f64 {
        let d2 = (p.x - guess.x).powi(2) + (p.y - guess.y).powi(2);
        let a = troupe_geom::normalize(p.yaw - guess.yaw);
        self.weight * (d2 / (self.xy * self.xy) + a * a / (self.yaw * self.yaw))
    }
}

impl Matcher {
    /// The fields of `points` (world frame) at `res` metres.
    pub fn new(points: &[(f64, f64)], res: f64, margin: f64) -> Matcher {
        Matcher {
            fine: Field::new(points, res, 1.5 * res, margin),
            coarse: Field::new(points, 4.0 * res, 4.0 * res, margin),
        }
    }

    /// The fine field.
    pub fn field(&self) -> &Field {
        &self.fine
    }

    /// The pose within `window` of `guess` where `points` (robot frame)
    /// fit best, less what `prior` charges for straying from the guess;
    /// `reach` is the farthest point's range, which sets the angular step
    /// (a step moves the farthest point about a cell). The match's score
    /// is the fit alone.
    pub fn search(
        &self,
        points: &[(f64, f64)],
        guess: Pose,
        window: Window,
        reach: f64,
        prior: Option<Prior>,
    ) -> Match {
        let reach = reach.max(1.0);
        let inside = |p: Pose| {
            (p.x - guess.x).abs() <= window.xy + 1e-9
                && (p.y - guess.y).abs() <= window.xy + 1e-9
                && troupe_geom::normalize(p.yaw - guess.yaw).abs() <= window.yaw + 1e-9
        };
        let value = |p: Pose, fit: f64| fit - prior.map_or(0.0, |pr| pr.charge(guess, p));
        let coarse_step = self.coarse.res / reach;
        let coarse = grid_search(
            &self.coarse,
            points,
            guess,
            window,
            coarse_step,
            4 * CANDIDATES,
            |_, fit| fit,
        );
        let mut coarse: Vec<(f64, Match)> = coarse
            .into_iter()
            .filter(|m| inside(m.pose))
            .map(|m| (value(m.pose, m.score), m))
            .collect();
        coarse.sort_by(|a, b| b.0.total_cmp(&a.0));
        coarse.truncate(CANDIDATES);
        // Refine each on the fine field, within one coarse step: every
        // pose of the fine lattice there read at the nearest cell (a scan's
        // points turned once a step, then only shifted), the best of each
        // then scored on the interpolated field. Each pose interpolated
        // was two thirds of a build's time (MIT CSAIL, 361 beams).
        let fine_step = self.fine.res / reach;
        let around = Window {
            xy: self.coarse.res,
            yaw: coarse_step,
        };
        let mut best = Match {
            pose: guess,
            score: self.fine.score(points, guess),
        };
        let mut best_value = value(guess, best.score);
        let lattice = |p: Pose, fit: f64| {
            if inside(p) {
                value(p, fit)
            } else {
                f64::MIN
            }
        };
        for (_, c) in coarse {
            for m in grid_search(&self.fine, points, c.pose, around, fine_step, 1, lattice) {
                if !inside(m.pose) {
                    continue;
                }
                let fit = self.fine.score(points, m.pose);
                let v = value(m.pose, fit);
                if v > best_value {
                    (best, best_value) = (
                        Match {
                            pose: m.pose,
                            score: fit,
                        },
                        v,
                    );
                }
            }
        }
        // A last look between the fine steps.
        let (mut dxy, mut dyaw) = (self.fine.res / 2.0, fine_step / 2.0);
        for _ in 0..3 {
            let around = best.pose;
            for (dx, dy, da) in [
                (dxy, 0.0, 0.0),
                (-dxy, 0.0, 0.0),
                (0.0, dxy, 0.0),
                (0.0, -dxy, 0.0),
                (0.0, 0.0, dyaw),
                (0.0, 0.0, -dyaw),
            ] {
                let p = Pose::new(around.x + dx, around.y + dy, around.yaw + da);
                let fit = self.fine.score(points, p);
                let v = value(p, fit);
                if v > best_value && inside(p) {
                    (best, best_value) = (
                        Match {
                            pose: p,
                            score: fit,
                        },
                        v,
                    );
                }
            }
            dxy /= 2.0;
            dyaw /= 2.0;
        }
        best
    }
}

/// The `keep` best poses on a lattice: every `yaw_step` radians and every
/// cell of `field` within `window` of `guess`, ranked by `value` of each
/// pose and its fit (the mean field under the points, read at the nearest
/// cell), which each keeps as its score.
fn grid_search(
    field: &Field,
    points: &[(f64, f64)],
    guess: Pose,
    window: Window,
    yaw_step: f64,
    keep: usize,
    value: impl Fn(Pose, f64) -> f64,
) -> Vec<Match> {
    let res = field.res;
    let n_xy = (window.xy / res).ceil() as i64;
    let n_yaw = (window.yaw / yaw_step).ceil() as i64;
    let mut found: Vec<(f64, Match)> = Vec::new();
    let mut cells: Vec<(i64, i64)> = Vec::with_capacity(points.len());
    let mut sums = vec![0f32; ((2 * n_xy + 1) * (2 * n_xy + 1)) as usize];
    for k in -n_yaw..=n_yaw {
        let yaw = guess.yaw + k as f64 * yaw_step;
        let (s, c) = yaw.sin_cos();
        cells.clear();
        for &(x, y) in points {
            let wx = guess.x + c * x - s * y;
            let wy = guess.y + s * x + c * y;
            cells.push((
                ((wx - field.x0) / res).floor() as i64,
                ((wy - field.y0) / res).floor() as i64,
            ));
        }
        sums.iter_mut().for_each(|v| *v = 0.0);
        let side = (2 * n_xy + 1) as usize;
        for &(ci, cj) in &cells {
            for dj in -n_xy..=n_xy {
                let j = cj + dj;
                if j < 0 || j as usize >= field.h {
                    continue;
                }
                let row = &field.cells[j as usize * field.w..(j as usize + 1) * field.w];
                let out = &mut sums[(dj + n_xy) as usize * side..][..side];
                for (o, di) in out.iter_mut().zip(-n_xy..=n_xy) {
                    let i = ci + di;
                    if i >= 0 && (i as usize) < field.w {
                        *o += row[i as usize];
                    }
                }
            }
        }
        for (idx, &sum) in sums.iter().enumerate() {
            let (di, dj) = ((idx % side) as i64 - n_xy, (idx / side) as i64 - n_xy);
            let score = f64::from(sum) / points.len().max(1) as f64;
            let pose = Pose::new(guess.x + di as f64 * res, guess.y + dj as f64 * res, yaw);
            let v = value(pose, score);
            if found.len() < keep || v > found[found.len() - 1].0 {
                // Keep the best `keep`, at least a cell apart.
                if let Some(near) = found.iter_mut().find(|(_, m)| {
                    (m.pose.x - pose.x).abs() < 2.0 * res
                        && (m.pose.y - pose.y).abs() < 2.0 * res
                        && (m.pose.yaw - pose.yaw).abs() < 2.0 * yaw_step
                }) {
                    if v > near.0 {
                        *near = (v, Match { pose, score });
                    }
                } else {
                    found.push((v, Match { pose, score }));
                }
                found.sort_by(|a, b| b.0.total_cmp(&a.0));
                found.truncate(keep);
            }
        }
    }
    found.into_iter().map(|(_, m)| m).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An L of walls: 4 m along x at y = 2, 3 m along y at x = 3.
    fn walls() -> Vec<(f64, f64)> {
        let mut v: Vec<(f64, f64)> = (0..80).map(|i| (-1.0 + i as f64 * 0.05, 2.0)).collect();
        v.extend((0..60).map(|i| (3.0, -1.0 + i as f64 * 0.05)));
        v
    }

    #[test]
    fn a_lone_wall_says_where_the_robot_is_across_it_and_nothing_along_it() {
        // A wall 8 m long at y = 2; the scan sees its middle 3 m.
        let wall: Vec<(f64, f64)> = (0..160).map(|i| (-4.0 + i as f64 * 0.05, 2.0)).collect();
        let seen: Vec<(f64, f64)> = (0..60).map(|i| (-1.5 + i as f64 * 0.05, 2.0)).collect();
        let m = Matcher::new(&wall, 0.05, 1.0);
        let info = m.field().information(&seen, Pose::new(0.0, 0.0, 0.0), 2.5);
        let (along, across) = (info[(0, 0)], info[(1, 1)]);
        // Across: centimetres (a beam's noise, over the independent beams).
        assert!(across > 1.0 / 0.01f64.powi(2), "across: {across}");
        assert!(
            along < 1e-3 * across,
            "along {along} against across {across}"
        );
    }

    #[test]
    fn a_scan_of_the_walls_is_found_where_it_was_taken() {
        let truth = Pose::new(0.4, -0.3, 0.2);
        let to_robot = truth.inverse();
        let points: Vec<(f64, f64)> = walls()
            .iter()
            .step_by(2)
            .map(|&(x, y)| to_robot.apply(x, y))
            .collect();
        let m = Matcher::new(&walls(), 0.05, 1.0);
        let guess = Pose::new(0.1, 0.0, 0.0);
        let got = m.search(&points, guess, Window { xy: 0.5, yaw: 0.4 }, 4.0, None);
        assert!(
            (got.pose.x - truth.x).abs() < 0.02
                && (got.pose.y - truth.y).abs() < 0.02
                && (got.pose.yaw - truth.yaw).abs() < 0.01,
            "{got:?}"
        );
        assert!(got.score > 0.8, "{got:?}");
        // Out of the window it is not found, and the fit says so.
        let far = m.search(
            &points,
            Pose::new(2.0, 2.0, 1.5),
            Window { xy: 0.2, yaw: 0.1 },
            4.0,
            None,
        );
        assert!(far.score < 0.5, "{far:?}");
    }
}
