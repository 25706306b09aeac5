//! Player's `vfh`: VFH+ local obstacle avoidance between a client (or a
//! planner) and a mobile base.
//!
//! ```text
//! driver ( name "vfh" provides ["position2d:1"] requires ["position2d:0" "laser:0"]
//!          distance_epsilon 0.3 angle_epsilon 5 )
//! ```
//!
//! | | |
//! |---|---|
//! | requires | one `position2d` (the base), and one `laser`, `sonar` or `ranger` |
//! | provides | one `position2d` |
//!
//! Options, Player's names and defaults: `cell_size` 0.1 m,
//! `window_diameter` 61, `sector_angle` 5°, `safety_dist_0ms` 0.1 m,
//! `safety_dist_1ms` (= 0ms), `max_speed` 0.2 m/s,
//! `max_speed_narrow_opening`/`max_speed_wide_opening` (= max_speed),
//! `max_acceleration` 0.2 m/s², `min_turnrate` 10°/s, `max_turnrate_0ms`
//! 40°/s, `max_turnrate_1ms` (= 0ms), `min_turn_radius_safety_factor` 1,
//! `free_space_cutoff_0ms` 2e6, `obs_cutoff_0ms` (= free), the `_1ms`
//! cutoffs (= 0ms), `weight_desired_dir` 5, `weight_current_dir` 3,
//! `distance_epsilon` 0.5 m, `angle_epsilon` 10°, `escape_speed` 0,
//! `escape_time` 0, `escape_max_turnrate` 0. `synchronous` is accepted and
//! has no effect (every scan is handled as it comes).
//!
//! # Behavior
//!
//! - The base's data is republished unchanged on the provided device;
//!   requests to it go to the base and the base's answer comes back.
//! - A velocity command goes straight to the base and cancels the goal.
//! - A position command is a goal in the base's odometric frame (a goal
//!   equal to the last one, to the millimetre and degree, is ignored, as
//!   Player's). For each laser scan while a goal is active: within
//!   `distance_epsilon` and `angle_epsilon` the robot stops and the goal is
//!   done; within `distance_epsilon` only, it turns on the spot toward the
//!   goal's heading; otherwise VFH+ picks speed and turn rate (half speed
//!   within twice `distance_epsilon`).
//! - The robot's radius is half the larger side of the base's geometry,
//!   asked at setup; no motion is commanded before it is known.
//! - With `escape_speed` and `escape_time` set, a stalled robot backs off
//!   (then drives forward if still stalled) for `escape_time` seconds.
//! - The laser scan may start anywhere: each direction of the half plane
//!   ahead reads the beam nearest to it; directions no beam covers read the
//!   nearest covered one. Sonar and ranger elements (poses from their
//!   geometry) each cover a cone of 30° (sonar) or 50° (ranger) at their
//!   range plus their distance from the robot's centre, as Player's.

pub mod algorithm;

use std::collections::HashMap;

use serde::Deserialize;
use troupe_geom::{normalize, Pose};
use troupe_msgs::{laser, position2d, ranger, sonar, Device, Interface, Pose2d, Pose3d};
use troupe_node::{Ctx, Driver, Event, NodeError, RequestId, Responder, Result, Section, Unit};

use crate::algorithm::{Params, Vfh as Algorithm};

/// Options, by Player's names (`None` = Player's derived default).
#[derive(Debug, Deserialize)]
#[serde(default)]
#[allow(missing_docs)]
pub struct Options {
    pub cell_size: f64,
    pub window_diameter: usize,
    pub sector_angle: u32,
    pub safety_dist_0ms: f64,
    pub safety_dist_1ms: Option<f64>,
    pub max_speed: f64,
    pub max_speed_narrow_opening: Option<f64>,
    pub max_speed_wide_opening: Option<f64>,
    pub max_acceleration: f64,
    pub min_turnrate: f64,
    pub max_turnrate_0ms: f64,
    pub max_turnrate_1ms: Option<f64>,
    pub min_turn_radius_safety_factor: f64,
    pub free_space_cutoff_0ms: f64,
    pub obs_cutoff_0ms: Option<f64>,
    pub free_space_cutoff_1ms: Option<f64>,
    pub obs_cutoff_1ms: Option<f64>,
    pub weight_desired_dir: f64,
    pub weight_current_dir: f64,
    pub distance_epsilon: f64,
    pub angle_epsilon: f64,
    pub escape_speed: f64,
    pub escape_time: f64,
    pub escape_max_turnrate: f64,
    pub synchronous: Option<f64>,
}

impl Default for Options {
    fn default() -> Self {
        let p = Params::default();
        Options {
            cell_size: p.cell_size,
            window_diameter: p.window_diameter,
            sector_angle: p.sector_angle,
            safety_dist_0ms: p.safety_dist_0ms,
            safety_dist_1ms: None,
            max_speed: p.max_speed,
            max_speed_narrow_opening: None,
            max_speed_wide_opening: None,
            max_acceleration: p.max_acceleration,
            min_turnrate: p.min_turnrate,
            max_turnrate_0ms: p.max_turnrate_0ms,
            max_turnrate_1ms: None,
            min_turn_radius_safety_factor: p.min_turn_radius_safety_factor,
            free_space_cutoff_0ms: p.free_space_cutoff_0ms,
            obs_cutoff_0ms: None,
            free_space_cutoff_1ms: None,
            obs_cutoff_1ms: None,
            weight_desired_dir: p.weight_desired_dir,
            weight_current_dir: p.weight_current_dir,
            distance_epsilon: 0.5,
            angle_epsilon: 10f64.to_radians(),
            escape_speed: 0.0,
            escape_time: 0.0,
            escape_max_turnrate: 0.0,
            synchronous: None,
        }
    }
}

impl Options {
    fn params(&self) -> Params {
        let free1 = self
            .free_space_cutoff_1ms
            .unwrap_or(self.free_space_cutoff_0ms);
        Params {
            cell_size: self.cell_size,
            window_diameter: self.window_diameter,
            sector_angle: self.sector_angle,
            safety_dist_0ms: self.safety_dist_0ms,
            safety_dist_1ms: self.safety_dist_1ms.unwrap_or(self.safety_dist_0ms),
            max_speed: self.max_speed,
            max_speed_narrow_opening: self.max_speed_narrow_opening.unwrap_or(self.max_speed),
            max_speed_wide_opening: self.max_speed_wide_opening.unwrap_or(self.max_speed),
            max_acceleration: self.max_acceleration,
            min_turnrate: self.min_turnrate,
            max_turnrate_0ms: self.max_turnrate_0ms,
            max_turnrate_1ms: self.max_turnrate_1ms.unwrap_or(self.max_turnrate_0ms),
            min_turn_radius_safety_factor: self.min_turn_radius_safety_factor,
            free_space_cutoff_0ms: self.free_space_cutoff_0ms,
            obs_cutoff_0ms: self.obs_cutoff_0ms.unwrap_or(self.free_space_cutoff_0ms),
            free_space_cutoff_1ms: free1,
            obs_cutoff_1ms: self.obs_cutoff_1ms.unwrap_or(free1),
            weight_desired_dir: self.weight_desired_dir,
            weight_current_dir: self.weight_current_dir,
            robot_radius: 0.0,
        }
    }
}

/// Ranges (mm) by half degree of the polar frame, 0°..180°, from a scan.
fn polar(scan: &laser::Scan) -> Vec<f64> {
    let mut out = vec![f64::NAN; 361];
    let res = f64::from(scan.resolution);
    let min = f64::from(scan.min_angle);
    let n = scan.ranges.len();
    if n > 0 {
        for (k, slot) in out.iter_mut().enumerate() {
            // Polar 0° is the robot's right: −90° in the scan's frame.
            let a = (k as f64 / 2.0 - 90.0).to_radians();
            let i = if res.abs() > 0.0 {
                ((a - min) / res).round()
            } else {
                0.0
            };
            if i >= 0.0 && (i as usize) < n {
                *slot = f64::from(scan.ranges[i as usize]) * 1000.0;
            }
        }
    }
    fill_gaps(&mut out);
    out
}

/// Ranges (mm) by half degree of the polar frame from sonar or ranger
/// elements at `poses` on the robot, each seeing a `cone`° wide cone (Player:
/// 30° for sonar, 50° for a ranger); later elements overwrite earlier ones.
fn cones_polar(poses: &[Pose], ranges: &[f64], cone: f64) -> Vec<f64> {
    let mut out = vec![f64::NAN; 361];
    for (p, &r) in poses.iter().zip(ranges) {
        let d = (p.x.hypot(p.y) + r) * 1000.0;
        let centre = p.yaw.to_degrees() + 90.0;
        let mut b = centre - cone / 2.0;
        while b < centre + cone / 2.0 {
            let k = (2.0 * b).round();
            if b >= 0.0 && k < 361.0 {
                out[k as usize] = d;
            }
            b += 0.5;
        }
    }
    fill_gaps(&mut out);
    out
}

/// Directions nothing covers read the nearest covered one before them (the
/// first covered one at the start); nothing covered at all reads 1000 m.
fn fill_gaps(out: &mut [f64]) {
    let first = out.iter().position(|v| !v.is_nan());
    let mut last = first.map_or(1e6, |i| out[i]);
    for v in out.iter_mut() {
        if v.is_nan() {
            *v = last;
        } else {
            last = *v;
        }
    }
}

/// What the obstacles are read from.
enum Sensor {
    Laser(Device),
    /// Sonar or ranger elements: poses on the robot (from the geometry,
    /// asked at setup) and the cone each sees, degrees.
    Cones {
        dev: Device,
        poses: Vec<Pose>,
        cone: f64,
        geom: Option<RequestId>,
    },
}

impl Sensor {
    fn device(&self) -> Device {
        match self {
            Sensor::Laser(d) | Sensor::Cones { dev: d, .. } => *d,
        }
    }
}

/// The vfh driver.
pub struct Vfh {
    o: Options,
    vfh: Algorithm,
    base: Device,
    sensor: Sensor,
    out: Device,
    geom: Option<RequestId>,
    radius_known: bool,
    odom: position2d::Data,
    goal: Option<Pose2d>,
    last_goal: (i64, i64, i64),
    motors_on: bool,
    turning: Option<f64>,
    last_update: Option<f64>,
    escape: Option<(f64, f64)>,
    escape_dir: f64,
    /// Requests forwarded to the base, by the base's request id.
    pending: HashMap<RequestId, Responder>,
}

impl Driver for Vfh {
    const NAME: &'static str = "vfh";
    type Options = Options;
    const UNITS: &'static [(&'static str, Unit)] = &[
        ("cell_size", Unit::Length),
        ("safety_dist_0ms", Unit::Length),
        ("safety_dist_1ms", Unit::Length),
        ("max_speed", Unit::Length),
        ("max_speed_narrow_opening", Unit::Length),
        ("max_speed_wide_opening", Unit::Length),
        ("max_acceleration", Unit::Length),
        ("min_turnrate", Unit::Angle),
        ("max_turnrate_0ms", Unit::Angle),
        ("max_turnrate_1ms", Unit::Angle),
        ("distance_epsilon", Unit::Length),
        ("angle_epsilon", Unit::Angle),
        ("escape_speed", Unit::Length),
        ("escape_max_turnrate", Unit::Angle),
    ];

    fn new(section: &Section, o: Options) -> Result<Self> {
        let bad = |why: String| NodeError::config(Self::NAME, why);
        if o.window_diameter < 3
            || o.cell_size <= 0.0
            || o.sector_angle == 0
            || 360 % o.sector_angle != 0
        {
            return Err(bad(format!(
                "window_diameter ({}) must be ≥ 3, cell_size ({}) positive and sector_angle ({}) divide 360",
                o.window_diameter, o.cell_size, o.sector_angle
            )));
        }
        if o.max_speed <= 0.0 {
            return Err(bad(format!(
                "max_speed must be positive, not {}",
                o.max_speed
            )));
        }
        let sensors = section.required_where(|i| {
            matches!(i, Interface::Laser | Interface::Sonar | Interface::Ranger)
        });
        let sensor = match sensors.as_slice() {
            [d] if d.interface == Interface::Laser => Sensor::Laser(*d),
            [d] => Sensor::Cones {
                dev: *d,
                poses: Vec::new(),
                cone: if d.interface == Interface::Sonar {
                    30.0
                } else {
                    50.0
                },
                geom: None,
            },
            _ => {
                return Err(bad(format!(
                    "vfh needs exactly one laser, sonar or ranger in `requires`; it has {}",
                    sensors.len()
                )))
            }
        };
        Ok(Vfh {
            vfh: Algorithm::new(o.params()),
            base: section.required_one(Interface::Position2d, None)?,
            sensor,
            out: section.provided_one(Interface::Position2d, None)?,
            o,
            geom: None,
            radius_known: false,
            odom: position2d::Data::default(),
            goal: None,
            last_goal: (0, 0, 0),
            motors_on: true,
            turning: None,
            last_update: None,
            escape: None,
            escape_dir: 1.0,
            pending: HashMap::new(),
        })
    }

    fn setup(&mut self, ctx: &mut Ctx) -> Result<()> {
        self.geom = Some(ctx.request(&self.base, &position2d::GetGeom)?);
        ctx.subscribe(&self.base)?;
        if let Sensor::Cones { dev, geom, .. } = &mut self.sensor {
            *geom = Some(if dev.interface == Interface::Sonar {
                ctx.request(dev, &sonar::GetGeom)?
            } else {
                ctx.request(dev, &ranger::GetGeom)?
            });
        }
        ctx.subscribe(&self.sensor.device())?;
        Ok(())
    }

    fn on_event(&mut self, ctx: &mut Ctx, event: Event) -> Result<()> {
        match event {
            Event::Data(s) if s.device == self.base && s.is::<position2d::Data>() => {
                self.odom = s.decode::<position2d::Data>()?.msg;
                ctx.publish(&self.out, &self.odom)
            }
            Event::Data(s) if s.device == self.base && s.is::<position2d::Geom>() => {
                let g = s.decode::<position2d::Geom>()?.msg;
                ctx.publish(&self.out, &g)
            }
            Event::Data(s) if s.device == self.sensor.device() && s.is::<laser::Scan>() => {
                let scan = s.decode::<laser::Scan>()?.msg;
                self.step(ctx, &polar(&scan))
            }
            Event::Data(s) if s.device == self.sensor.device() && s.is::<sonar::Ranges>() => {
                let r: Vec<f64> = s
                    .decode::<sonar::Ranges>()?
                    .msg
                    .ranges
                    .iter()
                    .map(|&x| f64::from(x))
                    .collect();
                self.cones(ctx, &r)
            }
            Event::Data(s) if s.device == self.sensor.device() && s.is::<ranger::Ranges>() => {
                let r = s.decode::<ranger::Ranges>()?.msg.ranges;
                self.cones(ctx, &r)
            }
            Event::Data(s) if s.device == self.sensor.device() => Ok(()),
            Event::Data(s) => Err(s.unexpected()),
            Event::Command(c) if c.is::<position2d::CmdVel>() => {
                let cmd = c.decode::<position2d::CmdVel>()?.msg;
                self.goal = None;
                ctx.command(&self.base, &cmd)
            }
            Event::Command(c) if c.is::<position2d::CmdPos>() => {
                let cmd = c.decode::<position2d::CmdPos>()?.msg;
                self.motors_on = cmd.state;
                let key = (
                    (cmd.pos.x * 1000.0).round() as i64,
                    (cmd.pos.y * 1000.0).round() as i64,
                    cmd.pos.yaw.to_degrees().round() as i64,
                );
                if key != self.last_goal {
                    self.last_goal = key;
                    self.goal = Some(cmd.pos);
                    self.turning = None;
                    tracing::debug!(
                        "goal ({:.3}, {:.3}, {:.1}°)",
                        cmd.pos.x,
                        cmd.pos.y,
                        cmd.pos.yaw.to_degrees()
                    );
                }
                Ok(())
            }
            Event::Command(c) => {
                tracing::debug!("vfh: ignored command `{}`", c.key);
                Ok(())
            }
            Event::Request(r) => {
                // The base answers; its reply (or refusal) goes back.
                let payload = r.sample.payload().to_bytes().into_owned();
                let id = ctx.forward_request(&self.base, &r.name, payload)?;
                self.pending.insert(id, r.responder);
                Ok(())
            }
            Event::Reply(reply) => {
                if let Sensor::Cones {
                    dev, poses, geom, ..
                } = &mut self.sensor
                {
                    if *geom == Some(reply.id) {
                        *geom = None;
                        let why = |e: NodeError| {
                            NodeError::config(
                                "vfh",
                                format!(
                                    "{dev} gave no geometry (the element poses are needed): {e}"
                                ),
                            )
                        };
                        let pose = |p: &Pose3d| Pose::new(p.x, p.y, p.yaw);
                        *poses = if dev.interface == Interface::Sonar {
                            reply
                                .decode::<sonar::Geom>()
                                .map_err(why)?
                                .poses
                                .iter()
                                .map(pose)
                                .collect()
                        } else {
                            let g = reply.decode::<ranger::Geom>().map_err(why)?;
                            let base = pose(&g.pose);
                            if g.element_poses.is_empty() {
                                vec![base]
                            } else {
                                g.element_poses
                                    .iter()
                                    .map(|p| base.compose(&pose(p)))
                                    .collect()
                            }
                        };
                        return Ok(());
                    }
                }
                if Some(reply.id) == self.geom {
                    self.geom = None;
                    let g = reply.decode::<position2d::Geom>().map_err(|e| {
                        NodeError::config(
                            Self::NAME,
                            format!(
                                "{} gave no geometry (the robot's size is needed): {e}",
                                self.base
                            ),
                        )
                    })?;
                    let r = g.size.width.max(g.size.length) / 2.0;
                    self.vfh.set_robot_radius(r);
                    self.radius_known = true;
                    tracing::info!("robot radius {r:.3} m");
                    return Ok(());
                }
                if let Some(resp) = self.pending.remove(&reply.id) {
                    resp.forward(reply.result);
                }
                Ok(())
            }
            Event::Tick | Event::Wake => Ok(()),
        }
    }

    fn shutdown(&mut self, ctx: &mut Ctx) -> Result<()> {
        self.drive(ctx, 0.0, 0.0)
    }
}

impl Vfh {
    fn drive(&mut self, ctx: &mut Ctx, speed: f64, turnrate: f64) -> Result<()> {
        let (speed, mut turnrate) = if self.motors_on {
            (speed, turnrate)
        } else {
            (0.0, 0.0)
        };
        if turnrate.abs().to_degrees() > self.vfh.max_turnrate(speed * 1000.0) + 1e-9 {
            tracing::debug!("fast turn at {speed:.2} m/s: turn rate zeroed, as Player's");
            turnrate = 0.0;
        }
        let vel = Pose2d::new(speed, 0.0, turnrate);
        ctx.command(&self.base, &position2d::CmdVel { vel, state: true })
    }

    fn cones(&mut self, ctx: &mut Ctx, ranges: &[f64]) -> Result<()> {
        match &self.sensor {
            Sensor::Cones { poses, cone, .. } if !poses.is_empty() => {
                let polar = cones_polar(poses, ranges, *cone);
                self.step(ctx, &polar)
            }
            _ => Ok(()), // the element poses are not known yet
        }
    }

    /// One decision from ranges (mm) by half degree of the polar frame.
    fn step(&mut self, ctx: &mut Ctx, ranges: &[f64]) -> Result<()> {
        let now = ctx.now();
        let dt = self.last_update.map_or(0.1, |t| now - t);
        self.last_update = Some(now);
        let Some(goal) = self.goal else {
            return Ok(());
        };
        if !self.radius_known {
            return Ok(());
        }
        let o = &self.o;
        let p = self.odom.pose;
        // Escape from a stall.
        if let Some((start, _)) = self.escape {
            if now - start > o.escape_time {
                if self.odom.stall {
                    self.escape_dir = -self.escape_dir;
                }
                self.escape = None;
            }
        }
        if self.escape.is_some()
            || (o.escape_speed != 0.0 && o.escape_time != 0.0 && self.odom.stall)
        {
            let start = self.escape.map_or(now, |e| e.0);
            let speed = -o.escape_speed * self.escape_dir;
            let turn = self.escape.map_or(0.0, |e| e.1);
            self.escape = Some((start, turn));
            self.turning = None;
            return self.drive(ctx, speed, turn);
        }
        let dist = (goal.x - p.x).hypot(goal.y - p.y);
        let angdiff = normalize(goal.yaw - p.yaw);
        if dist < o.distance_epsilon && angdiff.abs() < o.angle_epsilon {
            self.goal = None;
            self.turning = None;
            tracing::debug!("goal reached");
            return self.drive(ctx, 0.0, 0.0);
        }
        if dist > o.distance_epsilon {
            self.turning = None;
            let desired = (90.0 + (goal.y - p.y).atan2(goal.x - p.x).to_degrees()
                - p.yaw.to_degrees())
            .rem_euclid(360.0);
            let range = |deg: f64| {
                let k = (deg * 2.0).round();
                if (0.0..=360.0).contains(&k) {
                    ranges[k as usize]
                } else {
                    f64::INFINITY // behind: the mask blocks it anyway
                }
            };
            let tol = o.distance_epsilon * 1000.0;
            let m = self.vfh.update(
                range,
                self.odom.vel.x * 1000.0,
                desired,
                dist * 1000.0,
                tol,
                dt,
            );
            let mut speed = m.speed;
            if dist < 2.0 * o.distance_epsilon && speed > o.max_speed / 2.0 {
                speed = o.max_speed / 2.0;
            }
            return self.drive(ctx, speed, m.turnrate);
        }
        // At the spot, wrong heading: turn toward the goal's heading.
        let dir = *self
            .turning
            .get_or_insert(if angdiff < 0.0 { -1.0 } else { 1.0 });
        let max0 = self.vfh.max_turnrate(0.0).to_radians();
        let rate = (angdiff.abs() / std::f64::consts::PI * max0).max(o.min_turnrate) * dir;
        self.drive(ctx, 0.0, rate)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scans_map_to_the_polar_frame_wherever_they_start() {
        // A 90° scan centred ahead, 10 beams: 1 m on the right half, 2 m on the left.
        let scan = laser::Scan {
            min_angle: -std::f32::consts::FRAC_PI_4,
            max_angle: std::f32::consts::FRAC_PI_4,
            resolution: std::f32::consts::FRAC_PI_2 / 9.0,
            ranges: vec![1.0, 1.0, 1.0, 1.0, 1.0, 2.0, 2.0, 2.0, 2.0, 2.0],
            ..Default::default()
        };
        let p = polar(&scan);
        assert_eq!(p.len(), 361);
        assert_eq!(p[2 * 50], 1000.0, "50° polar = 40° right");
        assert_eq!(p[2 * 130], 2000.0, "130° polar = 40° left");
        // Uncovered directions read the nearest covered one before them.
        assert_eq!(p[0], 1000.0);
        assert_eq!(p[360], 2000.0);
    }

    #[test]
    fn sonar_cones_cover_their_sectors() {
        // One sonar ahead at 0.2 m from the centre, one to the left.
        let poses = [
            Pose::new(0.2, 0.0, 0.0),
            Pose::new(0.0, 0.1, std::f64::consts::FRAC_PI_2),
        ];
        let p = cones_polar(&poses, &[1.0, 3.0], 30.0);
        assert_eq!(p[2 * 90], 1200.0);
        assert_eq!(p[2 * 76], 1200.0);
        assert_eq!(p[2 * 170], 3100.0);
        // Right of the first cone: nothing covers it before, so the first covered value.
        assert_eq!(p[0], 1200.0);
        // Between the cones: the last covered one before.
        assert_eq!(p[2 * 130], 1200.0);
    }
}
