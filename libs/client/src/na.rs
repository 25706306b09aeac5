//! Troupe's poses, covariances and scans as nalgebra's types, the ones
//! Rust robotics code passes them as: a [`Pose2d`] is an [`Isometry2`], a
//! localizer's covariance a [`Matrix3`], a scan's ranges [`Point2`]s.
//!
//! ```
//! use troupe_client::msgs::Pose2d;
//! use troupe_client::na::{pose_of, ToIsometry};
//! use troupe_client::nalgebra::{Point2, Vector2};
//!
//! let robot = Pose2d::new(1.0, 2.0, std::f64::consts::FRAC_PI_2);
//! // A point 1 m ahead of the robot, in the world.
//! let ahead = robot.isometry() * Point2::new(1.0, 0.0);
//! assert!((ahead - Point2::new(1.0, 3.0)).norm() < 1e-12);
//! // Poses compose as isometries do.
//! let moved = pose_of(&(robot.isometry() * Pose2d::new(0.5, 0.0, 0.0).isometry()));
//! assert!((Vector2::new(moved.x, moved.y) - Vector2::new(1.0, 2.5)).norm() < 1e-12);
//! ```

use nalgebra::{Isometry2, Matrix3, Point2};
use troupe_msgs::{laser, localize, Pose2d};

/// A pose, or anything that has one, as an [`Isometry2`].
pub trait ToIsometry {
    /// The rigid transform from the pose's frame to its parent's.
    fn isometry(&self) -> Isometry2<f64>;
}

impl ToIsometry for Pose2d {
    fn isometry(&self) -> Isometry2<f64> {
        Isometry2::new(nalgebra::Vector2::new(self.x, self.y), self.yaw)
    }
}

impl ToIsometry for localize::Hypoth {
    /// The hypothesis's mean.
    fn isometry(&self) -> Isometry2<f64> {
        self.mean.isometry()
    }
}

/// The pose of an isometry (its yaw in (−π, π]).
pub fn pose_of(iso: &Isometry2<f64>) -> Pose2d {
    Pose2d::new(iso.translation.x, iso.translation.y, iso.rotation.angle())
}

/// A covariance in Player's order (xx, yy, yaw-yaw, xy, y-yaw, x-yaw) as
/// the symmetric 3 × 3 matrix over (x, y, yaw).
pub fn covariance(cov: &[f64; 6]) -> Matrix3<f64> {
    let [xx, yy, aa, xy, ya, xa] = *cov;
    Matrix3::new(xx, xy, xa, xy, yy, ya, xa, ya, aa)
}

/// A covariance matrix over (x, y, yaw) in Player's order (xx, yy,
/// yaw-yaw, xy, y-yaw, x-yaw); the lower triangle is read.
pub fn player_covariance(m: &Matrix3<f64>) -> [f64; 6] {
    [
        m[(0, 0)],
        m[(1, 1)],
        m[(2, 2)],
        m[(1, 0)],
        m[(2, 1)],
        m[(2, 0)],
    ]
}

/// A scan's readings as points in the laser's frame (x ahead), leaving out
/// those at or beyond its maximum range (nothing was seen there).
pub fn scan_points(scan: &laser::Scan) -> Vec<Point2<f64>> {
    scan.ranges
        .iter()
        .enumerate()
        .filter(|&(_, &r)| r < scan.max_range && r.is_finite())
        .map(|(i, &r)| {
            let a = f64::from(scan.min_angle) + i as f64 * f64::from(scan.resolution);
            let r = f64::from(r);
            Point2::new(r * a.cos(), r * a.sin())
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pose_goes_to_an_isometry_and_back() {
        for &(x, y, yaw) in &[(0.0, 0.0, 0.0), (1.5, -2.0, 3.0), (-4.0, 7.0, -1.2)] {
            let p = pose_of(&Pose2d::new(x, y, yaw).isometry());
            assert!((p.x - x).abs() < 1e-12 && (p.y - y).abs() < 1e-12);
            assert!((p.yaw - yaw).abs() < 1e-12, "{yaw} came back as {}", p.yaw);
        }
        // A yaw outside (−π, π] comes back normalised.
        let p = pose_of(&Pose2d::new(0.0, 0.0, 3.0 * std::f64::consts::PI / 2.0).isometry());
        assert!((p.yaw + std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    }

    #[test]
    fn a_covariance_keeps_players_order() {
        let cov = [1.0, 2.0, 3.0, 0.1, 0.2, 0.3];
        let m = covariance(&cov);
        assert_eq!(m, m.transpose());
        assert_eq!((m[(0, 0)], m[(1, 1)], m[(2, 2)]), (1.0, 2.0, 3.0));
        assert_eq!((m[(0, 1)], m[(1, 2)], m[(0, 2)]), (0.1, 0.2, 0.3));
        assert_eq!(player_covariance(&m), cov);
    }

    #[test]
    fn a_scan_becomes_points_without_its_misses() {
        let scan = laser::Scan {
            min_angle: -std::f32::consts::FRAC_PI_2,
            max_angle: std::f32::consts::FRAC_PI_2,
            resolution: std::f32::consts::FRAC_PI_2,
            max_range: 8.0,
            ranges: vec![1.0, 8.0, 2.0],
            ..Default::default()
        };
        let pts = scan_points(&scan);
        assert_eq!(pts.len(), 2);
        assert!((pts[0] - Point2::new(0.0, -1.0)).norm() < 1e-6);
        assert!((pts[1] - Point2::new(0.0, 2.0)).norm() < 1e-6);
    }
}
