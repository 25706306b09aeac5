//! How good a built map is, against the world it was made in:
//!
//! - **accuracy**: the share of the map's occupied cells within 10 cm of a
//!   true obstacle, after the best rigid alignment of map to world;
//! - **coverage**: the share of the walls the robot saw (where its true
//!   beams ended) that the map has an occupied cell within 10 cm of.
//!
//! The alignment starts where the caller says the map's frame is in the
//! world (the robot's true pose at its first keyframe) and is refined by
//! matching the map's occupied cells against the true obstacles.

use troupe_geom::Pose;

use troupe_slam::matcher::{Matcher, Window};

/// A set of points, filed by cell for "is there one within `d`?".
pub struct Near {
    cell: f64,
    cells: std::collections::HashMap<(i64, i64), Vec<(f64, f64)>>,
}

impl Near {
    /// Files `points` in cells of `cell` metres.
    pub fn new(points: &[(f64, f64)], cell: f64) -> Near {
        let mut cells: std::collections::HashMap<(i64, i64), Vec<(f64, f64)>> =
            std::collections::HashMap::new();
        for &(x, y) in points {
            cells
                .entry(((x / cell).floor() as i64, (y / cell).floor() as i64))
                .or_default()
                .push((x, y));
        }
        Near { cell, cells }
    }

    /// Whether a point lies within `d` (no more than the cell size) of `(x, y)`.
    pub fn within(&self, x: f64, y: f64, d: f64) -> bool {
        let (ci, cj) = (
            (x / self.cell).floor() as i64,
            (y / self.cell).floor() as i64,
        );
        (-1..=1).any(|di| {
            (-1..=1).any(|dj| {
                self.cells.get(&(ci + di, cj + dj)).is_some_and(|v| {
                    v.iter()
                        .any(|&(px, py)| (px - x).powi(2) + (py - y).powi(2) <= d * d)
                })
            })
        })
    }
}

/// A map's figures against the truth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Score {
    /// Share of occupied map cells within the tolerance of an obstacle.
    pub accuracy: f64,
    /// Share of seen wall points with an occupied map cell within the tolerance.
    pub coverage: f64,
    /// The map-to-world transform used.
    pub alignment: Pose,
}

/// Scores `occupied` (map frame) against the true `obstacles` and the
/// `seen` wall points (world frame), the map frame guessed at `guess` in
/// the world; `tolerance` metres (0.1).
pub fn score(
    occupied: &[(f64, f64)],
    obstacles: &[(f64, f64)],
    seen: &[(f64, f64)],
    guess: Pose,
    tolerance: f64,
) -> Score {
    // The best rigid alignment: the map's cells on the obstacles' field.
    let m = Matcher::new(obstacles, 0.05, 1.0);
    let sample: Vec<(f64, f64)> = occupied.iter().step_by(3).copied().collect();
    let reach = sample.iter().map(|&(x, y)| x.hypot(y)).fold(1.0, f64::max);
    let found = m.search(&sample, guess, Window { xy: 0.5, yaw: 0.1 }, reach, None);
    let alignment = if found.score >= m.field().score(&sample, guess) {
        found.pose
    } else {
        guess
    };
    let place = alignment.applier();
    let truth = Near::new(obstacles, tolerance.max(0.05));
    let good = occupied
        .iter()
        .map(|&(x, y)| place(x, y))
        .filter(|&(x, y)| truth.within(x, y, tolerance))
        .count();
    Score {
        accuracy: good as f64 / occupied.len().max(1) as f64,
        coverage: coverage(occupied, alignment, seen, tolerance),
        alignment,
    }
}

/// The share of the wall points `seen` with one of the map's `occupied`
/// cells, laid in their frame by `alignment` ([`Score::alignment`]),
/// within `tolerance` metres: a map's coverage of another set of walls
/// without aligning it again.
pub fn coverage(
    occupied: &[(f64, f64)],
    alignment: Pose,
    seen: &[(f64, f64)],
    tolerance: f64,
) -> f64 {
    let place = alignment.applier();
    let placed: Vec<(f64, f64)> = occupied.iter().map(|&(x, y)| place(x, y)).collect();
    let map = Near::new(&placed, tolerance.max(0.05));
    let covered = seen
        .iter()
        .filter(|&&(x, y)| map.within(x, y, tolerance))
        .count();
    covered as f64 / seen.len().max(1) as f64
}

/// The rigid transform that best lays `a` on `b` (pairs in order, least
/// squares, Kabsch in the plane), and the RMS distance left between the
/// pairs after it: a trajectory's absolute error against a reference.
pub fn rms_after_alignment(a: &[(f64, f64)], b: &[(f64, f64)]) -> (f64, Pose) {
    let n = a.len().min(b.len());
    if n == 0 {
        return (0.0, Pose::new(0.0, 0.0, 0.0));
    }
    let mean = |v: &[(f64, f64)]| {
        let (sx, sy) = v[..n]
            .iter()
            .fold((0.0, 0.0), |(x, y), &(px, py)| (x + px, y + py));
        (sx / n as f64, sy / n as f64)
    };
    let (ma, mb) = (mean(a), mean(b));
    let (mut sxx, mut sxy) = (0.0, 0.0);
    for (&(ax, ay), &(bx, by)) in a[..n].iter().zip(&b[..n]) {
        let (ax, ay, bx, by) = (ax - ma.0, ay - ma.1, bx - mb.0, by - mb.1);
        sxx += ax * bx + ay * by;
        sxy += ax * by - ay * bx;
    }
    let yaw = sxy.atan2(sxx);
    let (s, c) = yaw.sin_cos();
    let t = Pose::new(
        mb.0 - (c * ma.0 - s * ma.1),
        mb.1 - (s * ma.0 + c * ma.1),
        yaw,
    );
    let place = t.applier();
    let sum: f64 = a[..n]
        .iter()
        .zip(&b[..n])
        .map(|(&(ax, ay), &(bx, by))| {
            let (x, y) = place(ax, ay);
            (x - bx).powi(2) + (y - by).powi(2)
        })
        .sum();
    ((sum / n as f64).sqrt(), t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_moved_trajectory_aligns_back_with_no_error_and_noise_shows() {
        let b: Vec<(f64, f64)> = (0..50)
            .map(|i| (f64::from(i) * 0.3, (f64::from(i) * 0.2).sin()))
            .collect();
        let moved = Pose::new(3.0, -2.0, 0.7).applier();
        let a: Vec<(f64, f64)> = b.iter().map(|&(x, y)| moved(x, y)).collect();
        let (rms, t) = rms_after_alignment(&a, &b);
        assert!(rms < 1e-9, "{rms}");
        let back = t.compose(&Pose::new(3.0, -2.0, 0.7));
        assert!(
            back.x.abs() < 1e-9 && back.y.abs() < 1e-9 && back.yaw.abs() < 1e-9,
            "{back:?}"
        );
        // Every point 10 cm off, alternately to either side: an RMS of 10 cm.
        let off: Vec<(f64, f64)> = b
            .iter()
            .enumerate()
            .map(|(i, &(x, y))| (x, y + if i % 2 == 0 { 0.1 } else { -0.1 }))
            .collect();
        let (rms, _) = rms_after_alignment(&off, &b);
        assert!((rms - 0.1).abs() < 0.01, "{rms}");
    }
}
