//! Planar poses: a rotation then a translation.

use troupe_msgs::Pose2d;

/// A planar pose (x, y in metres, yaw in radians) used as a rigid transform.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Pose {
    /// Metres.
    pub x: f64,
    /// Metres.
    pub y: f64,
    /// Radians.
    pub yaw: f64,
}

/// `a` wrapped into (-π, π].
pub fn normalize(a: f64) -> f64 {
    let mut a = a % std::f64::consts::TAU;
    if a > std::f64::consts::PI {
        a -= std::f64::consts::TAU;
    } else if a <= -std::f64::consts::PI {
        a += std::f64::consts::TAU;
    }
    a
}

impl Pose {
    /// A pose from its parts.
    pub const fn new(x: f64, y: f64, yaw: f64) -> Self {
        Pose { x, y, yaw }
    }

    /// `self ∘ local`: the pose `local`, given in this pose's frame, in the outer frame.
    ///
    /// # Example
    ///
    /// ```
    /// use troupe_geom::Pose;
    /// let robot = Pose::new(1.0, 0.0, std::f64::consts::FRAC_PI_2);
    /// let sensor = robot.compose(&Pose::new(0.5, 0.0, 0.0));
    /// assert!((sensor.x - 1.0).abs() < 1e-12 && (sensor.y - 0.5).abs() < 1e-12);
    /// ```
    pub fn compose(&self, local: &Pose) -> Pose {
        self.compose_by(self.yaw.sin_cos(), local)
    }

    /// [`Pose::compose`] where this pose's yaw's sine and cosine are
    /// known (`self.yaw.sin_cos()`, kept from an earlier step or shared
    /// with a parent).
    pub fn compose_by(&self, (s, c): (f64, f64), local: &Pose) -> Pose {
        Pose {
            x: self.x + c * local.x - s * local.y,
            y: self.y + s * local.x + c * local.y,
            yaw: normalize(self.yaw + local.yaw),
        }
    }

    /// The pose that undoes this one: `p.inverse().compose(&p)` is the identity.
    pub fn inverse(&self) -> Pose {
        let (s, c) = self.yaw.sin_cos();
        Pose {
            x: -c * self.x - s * self.y,
            y: s * self.x - c * self.y,
            yaw: normalize(-self.yaw),
        }
    }

    /// A point given in this pose's frame, in the outer frame.
    pub fn apply(&self, x: f64, y: f64) -> (f64, f64) {
        let (s, c) = self.yaw.sin_cos();
        (self.x + c * x - s * y, self.y + s * x + c * y)
    }

    /// [`Pose::apply`] for many points: the sine and cosine worked out
    /// once.
    pub fn applier(&self) -> impl Fn(f64, f64) -> (f64, f64) + Copy {
        let t = self.transform();
        move |x, y| t.point(x, y)
    }

    /// This pose as a turn and a shift, its sine and cosine worked out
    /// once: for points ([`Transform::point`], as [`Pose::apply`]) and
    /// directions, which a shift leaves as they are ([`Transform::turn`]).
    pub fn transform(&self) -> Transform {
        self.transform_by(self.yaw.sin_cos())
    }

    /// [`Pose::transform`] where the yaw's sine and cosine are known
    /// (`self.yaw.sin_cos()`, kept from an earlier step).
    pub fn transform_by(&self, (s, c): (f64, f64)) -> Transform {
        Transform {
            x0: self.x,
            y0: self.y,
            s,
            c,
        }
    }
}

/// A pose's turn and shift (see [`Pose::transform`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transform {
    x0: f64,
    y0: f64,
    s: f64,
    c: f64,
}

impl Transform {
    /// A point given in the pose's frame, in the outer frame.
    #[inline]
    pub fn point(&self, x: f64, y: f64) -> (f64, f64) {
        let (s, c) = (self.s, self.c);
        (self.x0 + c * x - s * y, self.y0 + s * x + c * y)
    }

    /// A direction given in the pose's frame, in the outer frame.
    #[inline]
    pub fn turn(&self, x: f64, y: f64) -> (f64, f64) {
        (self.c * x - self.s * y, self.s * x + self.c * y)
    }
}

impl From<Pose2d> for Pose {
    fn from(p: Pose2d) -> Self {
        Pose::new(p.x, p.y, p.yaw)
    }
}

impl From<Pose> for Pose2d {
    fn from(p: Pose) -> Self {
        Pose2d::new(p.x, p.y, p.yaw)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, PI};

    #[test]
    fn compose_and_inverse_are_consistent() {
        let a = Pose::new(1.0, 2.0, 0.7);
        let b = Pose::new(-0.3, 0.4, -1.2);
        let ab = a.compose(&b);
        let back = a.inverse().compose(&ab);
        assert!((back.x - b.x).abs() < 1e-12 && (back.y - b.y).abs() < 1e-12);
        assert!((normalize(back.yaw - b.yaw)).abs() < 1e-12);
        let p = Pose::new(0.0, 0.0, FRAC_PI_2).apply(1.0, 0.0);
        assert!(p.0.abs() < 1e-12 && (p.1 - 1.0).abs() < 1e-12);
    }

    #[test]
    fn angles_wrap_into_minus_pi_pi() {
        assert!((normalize(3.0 * PI) - PI).abs() < 1e-12);
        assert!((normalize(-PI) - PI).abs() < 1e-12);
        assert!((normalize(0.5 + 4.0 * PI) - 0.5).abs() < 1e-9);
    }
}

/// Distance from (`x`, `y`) along heading `a` to the inside walls of the
/// axis-aligned box `x0..x1` × `y0..y1` (infinite if the ray never meets
/// one): the room of the device emulators.
pub fn ray_to_box(x: f64, y: f64, a: f64, (x0, x1, y0, y1): (f64, f64, f64, f64)) -> f64 {
    let (dx, dy) = (a.cos(), a.sin());
    let mut d = f64::INFINITY;
    for (den, lim) in [(dx, x0 - x), (dx, x1 - x), (dy, y0 - y), (dy, y1 - y)] {
        if den.abs() > 1e-12 && lim / den > 0.0 {
            d = d.min(lim / den);
        }
    }
    d
}

#[cfg(test)]
mod box_tests {
    use super::*;

    #[test]
    fn rays_meet_the_nearest_wall_ahead() {
        let room = (-4.0, 4.0, -3.0, 3.0);
        assert!((ray_to_box(0.0, 0.0, 0.0, room) - 4.0).abs() < 1e-12);
        assert!((ray_to_box(1.0, 0.0, std::f64::consts::PI, room) - 5.0).abs() < 1e-12);
        assert!((ray_to_box(0.0, 0.0, std::f64::consts::FRAC_PI_2, room) - 3.0).abs() < 1e-12);
        let corner = ray_to_box(0.0, 0.0, 3f64.atan2(4.0), room);
        assert!((corner - 5.0).abs() < 1e-9);
    }
}

/// The box `[min x, min y, max x, max y]` around `pts`; `None` when there
/// are none.
pub fn bounds(pts: impl IntoIterator<Item = (f64, f64)>) -> Option<[f64; 4]> {
    pts.into_iter().fold(None, |b, (x, y)| {
        Some(match b {
            None => [x, y, x, y],
            Some([x0, y0, x1, y1]) => [x0.min(x), y0.min(y), x1.max(x), y1.max(y)],
        })
    })
}
