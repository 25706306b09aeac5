//! What an emulated range finder sees.

/// Where ranges come from: distances in metres along `angles` (radians,
/// counter-clockwise from the scanner's axis) at time `t` seconds.
pub trait Scene: Send {
    /// One range per angle; anything beyond the scanner's reach as is.
    fn ranges(&mut self, t: f64, angles: &[f64]) -> Vec<f64>;
}

/// A rectangular room, 8 m × 6 m, the scanner 2 m from its back wall and
/// centred across it, with a round pillar (0.3 m radius) that drifts
/// sideways between 1 m left and right, 2 m ahead, once every 10 s.
#[derive(Debug, Default, Clone, Copy)]
pub struct Room;

impl Scene for Room {
    fn ranges(&mut self, t: f64, angles: &[f64]) -> Vec<f64> {
        let (x0, x1, y0, y1) = (-2.0, 6.0, -3.0, 3.0);
        let (px, py, r) = (2.0, (t * std::f64::consts::TAU / 10.0).sin(), 0.3);
        angles
            .iter()
            .map(|&a| {
                let (dx, dy) = (a.cos(), a.sin());
                let mut d = crate::ray_to_box(0.0, 0.0, a, (x0, x1, y0, y1));
                // Ray–circle: |s·u − p|² = r².
                let b = dx * px + dy * py;
                let c = px * px + py * py - r * r;
                let disc = b * b - c;
                if disc >= 0.0 {
                    let s = b - disc.sqrt();
                    if s > 0.0 {
                        d = d.min(s);
                    }
                }
                d
            })
            .collect()
    }
}
