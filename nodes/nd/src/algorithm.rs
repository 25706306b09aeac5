//! Nearness Diagram navigation (Minguez and Montano, 2004), as the library
//! inside Player's `nd` driver computes it: 180 sectors of 2°, the nearest
//! obstacle point in each; regions between discontinuities wider than the
//! robot; the region nearest the goal whose free walking area lets the
//! robot through; a situation (goal in region, wide or narrow region, an
//! obstacle within the security distance on one side or both) and its
//! motion law; then Player's corrections for a rectangular robot.
//!
//! Written from reading Player's `nd.cc`. Sector 0 is straight behind and
//! sectors count clockwise (sector 90 is straight ahead). Where Player's
//! code can loop forever (its region search, which overran a fixed array
//! and crashed the driver), the search here stops after one turn of the
//! ring and reports no region; angles are normalised before they are
//! clamped ahead (Player's could turn the wrong way); non-finite points
//! are dropped.

use std::f64::consts::{FRAC_PI_2, PI, TAU};

/// Sectors around the robot.
pub const SECTORS: usize = 180;

/// The robot and its limits, Player's `TParametersND` for a rectangular
/// robot (Player's driver always uses the rectangle).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Params {
    /// Metres from the odometric origin to the front, back and either side.
    pub front: f64,
    /// Metres to the back.
    pub back: f64,
    /// Metres to each side.
    pub left: f64,
    /// Maximum speed, m/s.
    pub vlmax: f64,
    /// Maximum turn rate, rad/s.
    pub vamax: f64,
    /// Accelerations (Player: 0.75 both).
    pub almax: f64,
    /// Angular acceleration.
    pub aamax: f64,
    /// Security distance ahead (`avoid_dist`) and behind (a quarter of it).
    pub dsmax: f64,
    /// Security distance behind.
    pub dsmin: f64,
    /// The band beyond the outline where a rectangular robot turns with care.
    pub enlarge: f64,
    /// The smallest gap the robot fits through.
    pub discontinuity: f64,
    /// Nominal control period (Player: 0.1 s).
    pub t: f64,
}

/// A decision: speed (m/s) and turn rate (rad/s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Motion {
    /// Forward speed.
    pub v: f64,
    /// Turn rate, counter-clockwise.
    pub w: f64,
}

/// What happened when no motion comes out.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refusal {
    /// Something straight ahead within the robot's front corner radius.
    Emergency,
    /// No region lets the robot through toward the goal.
    NoRegion,
}

/// Why the parameters cannot describe a robot.
#[derive(Debug, Clone, PartialEq)]
pub struct BadParams(pub String);

/// The robot's outline and security distance by sector, and its limits.
#[derive(Debug, Clone)]
pub struct Nd {
    p: Params,
    /// Distance from the origin to the outline along each sector.
    e: [f64; SECTORS],
    /// Security distance beyond the outline along each sector.
    ds: [f64; SECTORS],
}

fn sector_angle(s: usize) -> f64 {
    -(TAU / SECTORS as f64) * (s as f64 - (SECTORS / 2) as f64)
}

fn angle_sector(a: f64) -> usize {
    let a = normalize(a);
    let s = (-(SECTORS as f64) / TAU * a + (SECTORS as f64 + 1.0) / 2.0) as usize;
    s % SECTORS
}

fn inc(s: usize) -> usize {
    (s + 1) % SECTORS
}

fn dec(s: usize) -> usize {
    (s + SECTORS - 1) % SECTORS
}

/// Sectors from `s1` to `s2`, clockwise.
fn dist_orient(s1: usize, s2: usize) -> usize {
    if s1 <= s2 {
        s2 - s1
    } else {
        (s2 + SECTORS - s1) % SECTORS
    }
}

fn normalize(a: f64) -> f64 {
    a.sin().atan2(a.cos())
}

fn bisector(l1: f64, l2: f64) -> f64 {
    let m = (l1 + l2) / 2.0;
    if (l1 - l2).abs() <= PI {
        m
    } else {
        normalize(m + PI)
    }
}

/// A point in polar form: distance and angle.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Polar {
    r: f64,
    a: f64,
}

impl Polar {
    fn of(x: f64, y: f64) -> Polar {
        Polar {
            r: x.hypot(y),
            a: y.atan2(x),
        }
    }

    fn xy(self) -> (f64, f64) {
        (self.r * self.a.cos(), self.r * self.a.sin())
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Aim {
    Goal,
    Start,
    End,
}

/// A region: sectors from `start` clockwise to `end`, each side rising
/// (`_asc`: the region is farther than what is beyond) or falling.
#[derive(Debug, Clone, Copy)]
struct Region {
    start: usize,
    end: usize,
    start_asc: bool,
    end_asc: bool,
    aim: Aim,
    dir_angle: f64,
}

/// One decision's working state.
struct Scene<'a> {
    nd: &'a Nd,
    /// Nearest point per sector (r < 0: none).
    d: [Polar; SECTORS],
    /// Distance beyond the outline (< 0: none).
    dr: [f64; SECTORS],
    goal: Polar,
    s_goal: usize,
}

impl Nd {
    /// The outline and security distances of `p`'s rectangle.
    ///
    /// # Errors
    ///
    /// A robot of no size, or security distances that give no contour.
    pub fn new(p: Params) -> Result<Nd, BadParams> {
        if !(p.front + p.back > 0.0 && p.left > 0.0 && p.dsmax > 0.0 && p.vlmax > 0.0) {
            return Err(BadParams(format!(
                "a robot {:.2} m long and {:.2} m wide with avoid_dist {:.2} m and max speed {:.2} m/s cannot be steered",
                p.front + p.back,
                2.0 * p.left,
                p.dsmax,
                p.vlmax
            )));
        }
        let (d0, d1, d2) = (-p.back, p.left, p.front);
        let mut e = [0.0; SECTORS];
        let a_bl = d1.atan2(d0);
        let mut li = angle_sector(a_bl);
        if sector_angle(li) > a_bl {
            li += 1;
        }
        let fl = Polar::of(d2, d1);
        let mut ld = angle_sector(fl.a);
        if sector_angle(ld) > fl.a {
            ld += 1;
        }
        e[0] = -d0;
        for (i, v) in e.iter_mut().enumerate().take(SECTORS / 2 + 1).skip(1) {
            let th = sector_angle(i);
            *v = if i < li {
                d0 / th.cos()
            } else if i < ld {
                d1 / th.sin()
            } else {
                fl.r
            };
        }
        for i in SECTORS / 2 + 1..SECTORS {
            e[i] = e[SECTORS - i];
        }
        // The security contour: dsmin behind, dsmax ahead, the tangent between.
        let (p1, p2) = ((d0, d1), (d2, d1));
        let b = p.dsmax - p.dsmin;
        let c = p2.0 - p1.0;
        let a = (c * c - b * b).max(0.0).sqrt();
        let (cos_, sin_) = (a / c, b / c);
        let q1 = (p1.0 - p.dsmin, p1.1);
        let q2 = (p1.0 - p.dsmin * sin_, p1.1 + p.dsmin * cos_);
        let q3 = (p2.0 - p.dsmax * sin_, p2.1 + p.dsmax * cos_);
        let q4r = fl.r + p.dsmax;
        let lim1 = q1.1.atan2(q1.0);
        let lim2 = q2.1.atan2(q2.0);
        let lim3 = q3.1.atan2(q3.0);
        let lim4 = fl.a;
        let mut ds = [0.0; SECTORS];
        ds[0] = -q1.0 - e[0];
        let m = p1.0 * p1.0 + p1.1 * p1.1 - p.dsmin * p.dsmin;
        let n = p2.0 * p2.0 + p2.1 * p2.1 - p.dsmax * p.dsmax;
        let (bb, cc) = (q3.0 - q2.0, q3.1 - q2.1);
        let aa = bb * q2.1 - cc * q2.0;
        for i in 1..SECTORS / 2 {
            let th = sector_angle(i);
            let around = |px: f64, py: f64, k: f64| {
                let t = px * th.cos() + py * th.sin();
                t + (t * t - k).max(0.0).sqrt()
            };
            let dist = if th >= lim1 {
                q1.0 / th.cos()
            } else if th >= lim2 {
                around(p1.0, p1.1, m)
            } else if th >= lim3 {
                aa / (bb * th.sin() - cc * th.cos())
            } else if th >= lim4 {
                around(p2.0, p2.1, n)
            } else {
                q4r
            };
            ds[i] = dist - e[i];
            ds[SECTORS - i] = ds[i];
        }
        ds[SECTORS / 2] = q4r - e[SECTORS / 2];
        if let Some(i) = ds.iter().position(|v| !(v.is_finite() && *v > 0.0)) {
            return Err(BadParams(format!(
                "avoid_dist {:.2} m gives no security contour around a {:.2} m × {:.2} m robot (sector {i})",
                p.dsmax,
                p.front + p.back,
                2.0 * p.left
            )));
        }
        Ok(Nd { p, e, ds })
    }

    /// The parameters.
    pub fn params(&self) -> &Params {
        &self.p
    }

    /// One decision: the robot at `pose` (x, y, heading) moving at `vel`
    /// (speed, turn rate), obstacle `points` in the same frame, heading for
    /// `goal`. `Ok` with zero motion once within `goal_tol` of the goal.
    ///
    /// # Errors
    ///
    /// An emergency stop, or no way through.
    pub fn decide(
        &self,
        goal: (f64, f64),
        goal_tol: f64,
        pose: (f64, f64, f64),
        vel: Motion,
        points: &[(f64, f64)],
    ) -> Result<Motion, Refusal> {
        let (x, y, th) = pose;
        let (c, s) = (th.cos(), th.sin());
        let to_robot = |(px, py): (f64, f64)| {
            let (dx, dy) = (px - x, py - y);
            (dx * c + dy * s, -dx * s + dy * c)
        };
        let g = to_robot(goal);
        let goal_p = Polar::of(g.0, g.1);
        let mut d = [Polar { r: -1.0, a: 0.0 }; SECTORS];
        for &pt in points {
            let (qx, qy) = to_robot(pt);
            let r2 = qx * qx + qy * qy;
            if !r2.is_finite() {
                continue;
            }
            let a = qy.atan2(qx);
            let j = angle_sector(a);
            if d[j].r < 0.0 || r2 < d[j].r {
                d[j] = Polar { r: r2, a };
            }
        }
        for (i, p) in d.iter_mut().enumerate() {
            if p.r >= 0.0 {
                p.r = p.r.sqrt();
                if i != SECTORS / 2 && p.r < self.e[i] + 0.01 {
                    p.r = self.e[i] + 0.01;
                }
            }
        }
        // Emergency stop: a point ahead within the front corner's radius.
        let fc = Polar::of(self.p.front, self.p.left);
        let ahead = &d[angle_sector(fc.a)..=angle_sector(-fc.a)];
        if ahead
            .iter()
            .any(|p| p.r >= 0.0 && p.r <= fc.r && p.a.abs() <= fc.a)
        {
            return Err(Refusal::Emergency);
        }
        let mut dr = [-1.0; SECTORS];
        for i in 0..SECTORS {
            if d[i].r >= 0.0 {
                dr[i] = d[i].r - self.e[i];
            }
        }
        let scene = Scene {
            nd: self,
            d,
            dr,
            goal: goal_p,
            s_goal: angle_sector(goal_p.a),
        };
        let region = scene.select().ok_or(Refusal::NoRegion)?;
        if (goal.0 - x).hypot(goal.1 - y) < goal_tol {
            return Ok(Motion { v: 0.0, w: 0.0 });
        }
        Ok(scene.motion(&region, vel))
    }
}

impl Scene<'_> {
    fn free(&self, i: usize) -> bool {
        self.d[i].r < 0.0
    }

    /// The next discontinuity from `start`, leftwards or rightwards: the
    /// last sector on the start's side, and whether that side rises.
    fn next_disc(&self, start: usize, left: bool) -> Option<(usize, bool)> {
        let mut j = start;
        let mut dj = self.d[j].r;
        let mut free_j = dj < 0.0;
        loop {
            let (i, di, free_i) = (j, dj, free_j);
            j = if left { dec(i) } else { inc(i) };
            dj = self.d[j].r;
            free_j = dj <= 0.0;
            if !(free_i && free_j) {
                if free_i != free_j {
                    return Some((i, free_i));
                }
                if (di - dj).abs() >= self.nd.p.discontinuity {
                    return Some((i, di > dj));
                }
            }
            if j == start {
                return None;
            }
        }
    }

    /// The free walking area test: aims `r` at the goal or at one of its
    /// edges, and says whether the robot fits all the way there.
    fn reachable(&self, r: &mut Region, aim: Aim) -> bool {
        r.aim = aim;
        let target = match aim {
            Aim::Goal => self.goal,
            Aim::Start | Aim::End => {
                let (edge, aux) = if aim == Aim::Start {
                    (r.start, dec(r.start))
                } else {
                    (r.end, inc(r.end))
                };
                if self.free(edge) || self.free(aux) {
                    // Far along the free side, beside the obstacle's edge.
                    let side = if self.free(aux) {
                        sector_angle(aux)
                    } else {
                        self.d[aux].a
                    };
                    let reach = if self.free(aux) { 0.0 } else { self.d[aux].r };
                    Polar {
                        r: reach + 1e6,
                        a: bisector(sector_angle(edge), side),
                    }
                } else {
                    let (a, b) = (self.d[edge].xy(), self.d[aux].xy());
                    Polar::of((a.0 + b.0) / 2.0, (a.1 + b.1) / 2.0)
                }
            }
        };
        r.dir_angle = target.a;
        let (l, w) = (target.r, self.nd.p.discontinuity);
        let (mut fl, mut fr) = (Vec::new(), Vec::new());
        for p in self.d.iter().filter(|p| p.r >= 0.0) {
            let (px, py) = Polar {
                r: p.r,
                a: p.a - target.a,
            }
            .xy();
            if px < 0.0 || px >= l || py.abs() > w {
                continue;
            }
            if (px - l).powi(2) + py * py < (w / 2.0).powi(2) {
                return false;
            }
            if py > 0.0 {
                fl.push((px, py));
            } else {
                fr.push((px, py));
            }
        }
        !fl.iter().any(|a| {
            fr.iter()
                .any(|b| (a.0 - b.0).powi(2) + (a.1 - b.1).powi(2) < w * w)
        })
    }

    /// Player's `SeleccionarRegion`: the region to head for, if any.
    fn select(&self) -> Option<Region> {
        let visible = self.free(self.s_goal) || self.goal.r <= self.d[self.s_goal].r;
        let whole = Region {
            start: 0,
            end: SECTORS - 1,
            start_asc: false,
            end_asc: false,
            aim: Aim::Goal,
            dir_angle: self.goal.a,
        };
        let Some((start, start_asc)) = self.next_disc(self.s_goal, true) else {
            return visible.then_some(whole);
        };
        let (end, end_asc) = self.next_disc(self.s_goal, false)?;
        let mut r0 = Region {
            start,
            end,
            start_asc,
            end_asc,
            ..whole
        };
        if end == dec(start) {
            if visible {
                return Some(r0);
            }
            return self.reachable(&mut r0, Aim::Start).then_some(r0);
        }
        if visible {
            if !r0.start_asc && !r0.end_asc {
                let mut one = Region {
                    start: self.s_goal,
                    end: self.s_goal,
                    ..r0
                };
                if self.reachable(&mut one, Aim::Goal) {
                    return Some(one);
                }
            } else if self.reachable(&mut r0, Aim::Goal) {
                return Some(r0);
            }
        }
        let (mut l, mut r) = (r0, r0);
        // Player's loop could go round forever; one turn of the ring is enough.
        for _ in 0..SECTORS {
            let dist_l = dist_orient(l.start, self.s_goal);
            let dist_r = dist_orient(self.s_goal, r.end);
            if dist_l <= dist_r {
                if l.start_asc {
                    if self.reachable(&mut l, Aim::Start) {
                        return Some(l);
                    }
                    l.end = dec(l.start);
                    l.end_asc = !l.start_asc;
                    (l.start, l.start_asc) = self.next_disc(l.end, true)?;
                } else {
                    l.end = dec(l.start);
                    l.end_asc = !l.start_asc;
                    (l.start, l.start_asc) = self.next_disc(l.end, true)?;
                    if self.reachable(&mut l, Aim::End) {
                        return Some(l);
                    }
                }
            } else if r.end_asc {
                if self.reachable(&mut r, Aim::End) {
                    return Some(r);
                }
                r.start = inc(r.end);
                r.start_asc = !r.end_asc;
                (r.end, r.end_asc) = self.next_disc(r.start, false)?;
            } else {
                r.start = inc(r.end);
                r.start_asc = !r.end_asc;
                (r.end, r.end_asc) = self.next_disc(r.start, false)?;
                if self.reachable(&mut r, Aim::Start) {
                    return Some(r);
                }
            }
            if !(dist_l < SECTORS / 2 || dist_r < SECTORS / 2) {
                break;
            }
        }
        None
    }

    /// The nearest obstacles inside the security zone, left and right of `beta`.
    fn obstacles(&self, beta: f64) -> (Option<usize>, Option<usize>) {
        // The sector and its closeness (distance beyond the outline over
        // the security distance) of the nearest on each side.
        type Nearest = Option<(usize, f64)>;
        let (mut left, mut right): (Nearest, Nearest) = (None, None);
        for i in 0..SECTORS {
            let (dr, ds) = (self.dr[i], self.nd.ds[i]);
            if dr < 0.0 || dr > ds {
                continue;
            }
            let key = dr / ds;
            let side = if self.d[i].a >= beta {
                &mut left
            } else {
                &mut right
            };
            if side.is_none_or(|(_, k)| key < k) {
                *side = Some((i, key));
            }
        }
        (left.map(|l| l.0), right.map(|r| r.0))
    }

    fn motion(&self, x: &Region, vel: Motion) -> Motion {
        let p = &self.nd.p;
        let end = if x.start > x.end {
            x.end + SECTORS
        } else {
            x.end
        };
        let wide = end - x.start > SECTORS / 4;
        let k = p.discontinuity / 2.0 + self.nd.ds[SECTORS / 2];
        let centre = sector_angle(((x.start + end) / 2) % SECTORS);
        let edge = || {
            if x.aim == Aim::Start {
                let o = self.d[dec(x.start)];
                o.a - k.atan2(o.r)
            } else {
                let o = self.d[inc(x.end)];
                o.a + k.atan2(o.r)
            }
        };
        let (left, right) = self.obstacles(x.dir_angle);
        let closeness = |o: usize| self.dr[o] / self.nd.ds[o];
        let angle = match (left, right) {
            (None, None) if x.aim == Aim::Goal => x.dir_angle,
            (None, None) if wide => edge(),
            (None, None) => centre,
            (Some(l), Some(r)) => {
                let (ci, cd, a) = (closeness(l), closeness(r), x.dir_angle);
                if ci <= cd {
                    a + (ci - cd) / (ci + cd) * (a + FRAC_PI_2)
                } else {
                    a + (ci - cd) / (ci + cd) * (FRAC_PI_2 - a)
                }
            }
            (Some(o), None) | (None, Some(o)) => {
                let partial = if x.aim == Aim::Goal {
                    x.dir_angle
                } else if wide {
                    normalize(edge())
                } else {
                    centre
                };
                let away = normalize(self.d[o].a + PI - partial) + partial;
                let k = closeness(o);
                let t = partial * k + away * (1.0 - k);
                t.clamp(-PI + 0.01, PI - 0.01)
            }
        };
        let angle = normalize(angle).clamp(-FRAC_PI_2, FRAC_PI_2);
        let ci = left.map_or(1.0, closeness);
        let cd = right.map_or(1.0, closeness);
        let c = ci.min(cd).max(0.2);
        let mut v = p.vlmax * c * angle.cos();
        let mut w = p.vamax * c * angle.sin();
        // A rectangular robot with something at its front corners: between
        // two, straight on; beside one, turn on the spot.
        let fc = Polar::of(p.front, p.left);
        let close = |o: Option<usize>| {
            o.is_some_and(|i| self.d[i].a.abs() <= fc.a && self.d[i].r <= fc.r + p.enlarge)
        };
        match (close(left), close(right)) {
            (true, true) => w = 0.0,
            (true, false) | (false, true) => v = 0.0,
            _ => {}
        }
        // Its back corners: no turn that would sweep them into an obstacle.
        let mut seen = (false, false);
        let mut both = false;
        for i in (0..=SECTORS / 4).chain(3 * SECTORS / 4..SECTORS) {
            let o = self.d[i];
            if o.r < 0.0 || o.a.abs() <= FRAC_PI_2 || self.dr[i] > p.enlarge / 2.0 {
                continue;
            }
            let (ox, oy) = o.xy();
            if oy >= p.left {
                seen.0 = true;
            } else if oy <= -p.left {
                seen.1 = true;
            } else if ox <= -p.back {
                both = true;
            }
            if both || (seen.0 && seen.1) {
                both = true;
                break;
            }
        }
        let keep = match (both, seen) {
            (true, _) => false,
            (false, (true, false)) => w >= 0.0,
            (false, (false, true)) => w <= 0.0,
            _ => true,
        };
        if !keep {
            // Straighten up: slow the turn down, then go straight.
            if p.aamax * p.t < vel.w.abs() {
                w = vel.w - vel.w.signum() * p.aamax * p.t;
                v = if p.almax * p.t < vel.v {
                    vel.v - p.almax * p.t
                } else {
                    0.0
                };
            } else {
                v = p.vlmax;
                w = 0.0;
            }
        }
        Motion {
            v: v.clamp(0.0, p.vlmax),
            w: w.clamp(-p.vamax, p.vamax),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Player's driver's parameters for a Stage Pioneer (0.44 × 0.38 m,
    /// origin 4 cm behind the centre), avoid_dist 0.5, max speed 0.3 m/s, 45°/s.
    pub(crate) fn pioneer() -> Nd {
        let dsmax = 0.5;
        Nd::new(Params {
            front: 0.22 - 0.04,
            back: 0.22 + 0.04,
            left: 0.19,
            vlmax: 0.3,
            vamax: 45f64.to_radians(),
            almax: 0.75,
            aamax: 0.75,
            dsmax,
            dsmin: dsmax / 4.0,
            enlarge: dsmax / 4.0 * 0.2,
            discontinuity: 0.38,
            t: 0.1,
        })
        .unwrap()
    }

    #[test]
    fn sectors_count_clockwise_from_behind() {
        assert_eq!(angle_sector(0.0), 90);
        assert_eq!(angle_sector(FRAC_PI_2), 45);
        assert_eq!(angle_sector(-FRAC_PI_2), 135);
        assert_eq!(angle_sector(PI), 0);
        assert_eq!(angle_sector(-PI), 0);
        assert!((sector_angle(45) - FRAC_PI_2).abs() < 1e-12);
    }

    #[test]
    fn outline_and_security_distances_are_players() {
        let nd = pioneer();
        // Player's values for this robot (f32 there).
        for (i, e, ds) in [
            (0, 0.2600, 0.1250),
            (10, 0.2767, 0.1330),
            (19, 0.3086, 0.1402),
            (30, 0.2194, 0.2879),
            (45, 0.1900, 0.4665),
            (59, 0.2152, 0.5322),
            (90, 0.2617, 0.5000),
        ] {
            assert!((nd.e[i] - e).abs() < 5e-4, "E[{i}] {} vs {e}", nd.e[i]);
            assert!((nd.ds[i] - ds).abs() < 5e-4, "ds[{i}] {} vs {ds}", nd.ds[i]);
            assert_eq!(nd.e[SECTORS - i.max(1)], nd.e[i.max(1)]);
        }
    }

    fn decide(points: &[(f64, f64)]) -> Result<Motion, Refusal> {
        pioneer().decide(
            (5.0, 0.0),
            0.5,
            (0.0, 0.0, 0.0),
            Motion { v: 0.0, w: 0.0 },
            points,
        )
    }

    #[test]
    fn single_obstacles_give_players_decisions() {
        let close = |m: Motion, v: f64, w: f64| (m.v - v).abs() < 2e-3 && (m.w - w).abs() < 2e-3;
        assert_eq!(decide(&[(0.2, 0.0)]), Err(Refusal::Emergency));
        assert_eq!(decide(&[(0.0, 0.0)]), Err(Refusal::Emergency));
        let free = decide(&[]).unwrap();
        assert!(close(free, 0.3, 0.0), "{free:?}");
        let m = decide(&[(0.27, 0.0)]).unwrap();
        assert!(close(m, 0.0, 0.157), "{m:?}");
        let m = decide(&[(0.2, 0.1)]).unwrap();
        assert!(close(m, 0.0, -0.157), "{m:?}");
        let m = decide(&[(0.4, 0.3)]).unwrap();
        assert!(close(m, 0.037, -0.361), "{m:?}");
        let m = decide(&[(-0.27, 0.1)]).unwrap();
        assert!(close(m, 0.3, 0.0), "{m:?}");
    }

    /// `f`'s result, or a failure if it takes over 20 s: the code under
    /// test went round forever in Player, and a regression must fail the
    /// test, not hang it (the thread is left behind).
    fn within<T: Send + 'static>(what: &str, f: impl FnOnce() -> T + Send + 'static) -> T {
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let _ = tx.send(f());
        });
        rx.recv_timeout(std::time::Duration::from_secs(20))
            .unwrap_or_else(|_| panic!("{what} did not end within 20 s"))
    }

    #[test]
    fn the_region_search_ends_where_players_went_round_forever() {
        // Obstacles in sectors 31..=170 at 0.2–1.0 m, 8 m beyond; the goal
        // 6.6 m away in sector 55, not visible.
        let mut points = Vec::new();
        for s in 0..SECTORS {
            let a = sector_angle(s);
            let r = if (31..=170).contains(&s) {
                0.6 + 0.4 * ((s as f64) * 0.7).sin()
            } else {
                8.0
            };
            points.push((r * a.cos(), r * a.sin()));
        }
        let g = sector_angle(55);
        let got = within("the region search", move || {
            pioneer().decide(
                (6.6 * g.cos(), 6.6 * g.sin()),
                0.5,
                (0.0, 0.0, 0.0),
                Motion { v: 0.0, w: 0.0 },
                &points,
            )
        });
        // It returns: a way, or none.
        assert!(got.is_ok() || got == Err(Refusal::NoRegion), "{got:?}");
    }

    /// Many random scenes all round the robot (what buffered scans or a
    /// laser with sonars give, where Player's search went round forever):
    /// every decision returns, and every motion is finite and within the limits.
    #[test]
    fn every_random_scene_gets_an_answer() {
        let (moved, refused) = within("5000 random scenes", random_scenes);
        assert!(moved > refused, "{moved} decisions, {refused} refusals");
    }

    fn random_scenes() -> (u32, u32) {
        let nd = pioneer();
        let mut seed = 0x9E37_79B9_7F4A_7C15u64;
        let mut unit = || {
            seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let (mut moved, mut refused) = (0, 0);
        for _ in 0..5000 {
            let walls = 1 + (unit() * 6.0) as usize;
            let mut ranges = [8.0; SECTORS];
            for _ in 0..walls {
                let (from, len, r) = (unit() * 180.0, unit() * 120.0, 0.3 + unit() * 3.0);
                for k in 0..len as usize {
                    ranges[(from as usize + k) % SECTORS] = r;
                }
            }
            let points: Vec<(f64, f64)> = (0..SECTORS * 2)
                .map(|i| {
                    let a = i as f64 * PI / SECTORS as f64;
                    let r = ranges[i / 2];
                    (r * a.cos(), r * a.sin())
                })
                .collect();
            let g = unit() * TAU;
            let gr = 0.5 + unit() * 8.0;
            match nd.decide(
                (gr * g.cos(), gr * g.sin()),
                0.3,
                (0.0, 0.0, 0.0),
                Motion {
                    v: unit() * 0.3,
                    w: unit() - 0.5,
                },
                &points,
            ) {
                Ok(m) => {
                    assert!(m.v.is_finite() && (0.0..=0.3).contains(&m.v), "{m:?}");
                    assert!(m.w.is_finite() && m.w.abs() <= 45f64.to_radians() + 1e-9);
                    moved += 1;
                }
                Err(_) => refused += 1,
            }
        }
        (moved, refused)
    }

    #[test]
    fn non_finite_points_are_ignored() {
        let m = decide(&[(f64::NAN, 1.0), (f64::INFINITY, 0.0)]).unwrap();
        assert!((m.v - 0.3).abs() < 1e-9);
    }
}
