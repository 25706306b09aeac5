//! Graph SLAM: scans and odometry in, poses and an occupancy grid out; no
//! network, no logs (the one file it writes is the map, on request). The
//! offline builder (`troupe map build`, tools/map) feeds it from logs; a
//! driver can feed it live, one scan at a time.
//!
//! - [`matcher`]: correlative scan matching on likelihood fields;
//! - [`graph`]: the pose graph and its optimisation;
//! - [`slam`]: keyframes, local matching, loop closures;
//! - [`occupancy`]: the grid the scans are traced into, written as ROS
//!   map_server's PNG and YAML.
//!
//! Depends on troupe-geom and nalgebra only.

pub mod graph;
pub mod matcher;
pub mod occupancy;
pub mod slam;

/// One range scan: beam `i` points at `min_angle + i * step` in the
/// sensor's frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Scan {
    /// Seconds.
    pub t: f64,
    /// Radians, the first beam.
    pub min_angle: f64,
    /// Radians between beams.
    pub step: f64,
    /// Metres: a beam reading this far (or farther) hit nothing.
    pub max_range: f64,
    /// Metres, one per beam.
    pub ranges: Vec<f32>,
}

impl Scan {
    /// The beams that hit something, as (range, bearing in the sensor's
    /// frame): a reading at the maximum is no return, one under 5 cm or
    /// not finite no reading.
    pub fn hits(&self) -> impl Iterator<Item = (f64, f64)> + '_ {
        self.ranges.iter().enumerate().filter_map(|(i, &r)| {
            let r = f64::from(r);
            (r.is_finite() && r > 0.05 && r < self.max_range - 0.01)
                .then_some((r, self.min_angle + i as f64 * self.step))
        })
    }
}
