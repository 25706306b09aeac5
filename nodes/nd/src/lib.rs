//! Player's `nd`: Nearness Diagram local navigation between a client (or a
//! planner) and a mobile base.
//!
//! ```text
//! driver ( name "nd" provides ["position2d:1"]
//!          requires ["output:::position2d:0" "input:::position2d:0" "laser:0"]
//!          max_speed [0.3 30.0] goal_tol [0.3 15.0] avoid_dist 0.4 )
//! ```
//!
//! | | |
//! |---|---|
//! | requires | `output:::position2d` (the base that is driven; its geometry is the robot's), `input:::position2d` (where the robot is: odometry or a localizer), and a `laser`, a `sonar` or both |
//! | provides | one `position2d` |
//!
//! Options, Player's names and defaults: `goal_tol` [0.5 m, 10°],
//! `max_speed` [0.3 m/s, 45°/s], `min_speed` [0.05 m/s, 10°/s],
//! `avoid_dist` 0.5 m, `safety_dist` 0 m, `rotate_stuck_time` 2 s,
//! `translate_stuck_time` 2 s, `translate_stuck_dist` 0.25 m,
//! `translate_stuck_angle` 20°, `wait_on_stall` 0, `laser_buffer` 10 and
//! `sonar_buffer` 20 scans, `sonar_bad_transducers` [].
//!
//! # Behavior
//!
//! As Player's driver:
//! - Each scan becomes obstacle points in the input's frame, at the pose
//!   of its arrival, kept for the last `laser_buffer` (`sonar_buffer`) scans.
//! - A position command is a goal in the input's frame. At each input pose
//!   while a goal is active: within `goal_tol` (distance and heading) the
//!   robot stops and the goal is done; within the distance only, it turns
//!   on the spot toward the goal's heading; otherwise ND ([`algorithm`])
//!   decides. Speeds below `min_speed` are raised to it.
//! - An emergency stop, no way through, no progress for
//!   `translate_stuck_time` (or, turning on the spot, for
//!   `rotate_stuck_time`) abandons the goal and raises the stall flag of
//!   the provided device until the next goal.
//! - The provided device republishes the input's pose with the output's
//!   velocity; with `wait_on_stall`, a stalled base waits instead.
//! - A velocity command goes straight to the base and cancels the goal; a
//!   negative speed makes later goals be driven to backwards. Requests go
//!   to the output base and its answer comes back.
//!
//! Unlike Player's, the region search cannot go round forever (in Player
//! it overran a fixed array and crashed the driver), points that are not
//! finite are dropped, and angles are normalised before they are limited
//! to the half plane ahead.

pub mod algorithm;

use std::collections::{HashMap, VecDeque};

use serde::Deserialize;
use troupe_geom::{normalize, Pose};
use troupe_msgs::{laser, position2d, sonar, Device, Interface, Pose2d, Pose3d};
use troupe_node::{Ctx, Driver, Event, NodeError, RequestId, Responder, Result, Section, Unit};

use crate::algorithm::{Motion, Nd as Algorithm, Params, Refusal};

/// Options, by Player's names.
#[derive(Debug, Deserialize)]
#[serde(default)]
#[allow(missing_docs)]
pub struct Options {
    pub goal_tol: [f64; 2],
    pub max_speed: [f64; 2],
    pub min_speed: [f64; 2],
    pub avoid_dist: f64,
    pub safety_dist: f64,
    pub rotate_stuck_time: f64,
    pub translate_stuck_time: f64,
    pub translate_stuck_dist: f64,
    pub translate_stuck_angle: f64,
    pub wait_on_stall: i64,
    pub laser_buffer: i64,
    pub sonar_buffer: i64,
    pub sonar_bad_transducers: Vec<i64>,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            goal_tol: [0.5, 10f64.to_radians()],
            max_speed: [0.3, 45f64.to_radians()],
            min_speed: [0.05, 10f64.to_radians()],
            avoid_dist: 0.5,
            safety_dist: 0.0,
            rotate_stuck_time: 2.0,
            translate_stuck_time: 2.0,
            translate_stuck_dist: 0.25,
            translate_stuck_angle: 20f64.to_radians(),
            wait_on_stall: 0,
            laser_buffer: 10,
            sonar_buffer: 20,
            sonar_bad_transducers: Vec::new(),
        }
    }
}

/// Player's `Threshold`: `v` within `lo..=hi` in magnitude, zero kept.
fn threshold(v: f64, lo: f64, hi: f64) -> f64 {
    if v == 0.0 {
        0.0
    } else if v > 0.0 {
        v.min(hi).max(lo)
    } else {
        v.max(-hi).min(-lo)
    }
}

/// A sensor's recent scans, as points in the input's frame.
struct Buffer {
    dev: Device,
    /// The sensor's pose on the robot (laser) or each element's (sonar),
    /// from its geometry.
    poses: Vec<Pose>,
    geom: Option<RequestId>,
    scans: VecDeque<Vec<(f64, f64)>>,
    size: usize,
}

impl Buffer {
    fn push(&mut self, scan: Vec<(f64, f64)>) {
        if self.scans.len() == self.size {
            self.scans.pop_front();
        }
        self.scans.push_back(scan);
    }
}

/// The nd driver.
pub struct Nd {
    o: Options,
    out: Device,
    output: Device,
    input: Device,
    laser: Option<Buffer>,
    sonar: Option<Buffer>,
    bad: Vec<usize>,
    geom: Option<RequestId>,
    /// The base's size and offset: (length, width, x offset).
    shape: Option<(f64, f64, f64)>,
    nd: Option<Algorithm>,
    current_dir: f64,
    dir: f64,
    pose: Pose2d,
    vel: Pose2d,
    goal: Option<Pose2d>,
    stall: bool,
    waiting: bool,
    turning: bool,
    rotate: (f64, f64),
    translate: (f64, Pose2d),
    pending: HashMap<RequestId, Responder>,
}

impl Driver for Nd {
    const NAME: &'static str = "nd";
    type Options = Options;
    const UNITS: &'static [(&'static str, Unit)] = &[
        ("goal_tol", Unit::Tuple(&[Unit::Length, Unit::Angle])),
        ("max_speed", Unit::Tuple(&[Unit::Length, Unit::Angle])),
        ("min_speed", Unit::Tuple(&[Unit::Length, Unit::Angle])),
        ("avoid_dist", Unit::Length),
        ("safety_dist", Unit::Length),
        ("translate_stuck_dist", Unit::Length),
        ("translate_stuck_angle", Unit::Angle),
    ];

    fn new(section: &Section, o: Options) -> Result<Self> {
        let bad = |why: String| NodeError::config(Self::NAME, why);
        if o.laser_buffer < 1 || o.sonar_buffer < 1 {
            return Err(bad(format!(
                "laser_buffer ({}) and sonar_buffer ({}) hold at least one scan",
                o.laser_buffer, o.sonar_buffer
            )));
        }
        if o.max_speed[0] <= 0.0 || o.max_speed[1] <= 0.0 || o.avoid_dist <= 0.0 {
            return Err(bad("max_speed and avoid_dist must be positive".into()));
        }
        let output = section.required_one(Interface::Position2d, Some("output"))?;
        let input = section.required_one(Interface::Position2d, Some("input"))?;
        let buffer = |i: Interface, size: i64| {
            section
                .required_where(|x| x == i)
                .first()
                .map(|&dev| Buffer {
                    dev,
                    poses: Vec::new(),
                    geom: None,
                    scans: VecDeque::new(),
                    size: size as usize,
                })
        };
        let laser = buffer(Interface::Laser, o.laser_buffer);
        let sonar = buffer(Interface::Sonar, o.sonar_buffer);
        if laser.is_none() && sonar.is_none() {
            return Err(bad(
                "nd needs at least one laser or sonar in `requires`".into()
            ));
        }
        Ok(Nd {
            out: section.provided_one(Interface::Position2d, None)?,
            output,
            input,
            laser,
            sonar,
            bad: o
                .sonar_bad_transducers
                .iter()
                .filter_map(|&i| usize::try_from(i).ok())
                .collect(),
            o,
            geom: None,
            shape: None,
            nd: None,
            current_dir: 1.0,
            dir: 1.0,
            pose: Pose2d::default(),
            vel: Pose2d::default(),
            goal: None,
            stall: false,
            waiting: false,
            turning: false,
            rotate: (0.0, 0.0),
            translate: (0.0, Pose2d::default()),
            pending: HashMap::new(),
        })
    }

    fn setup(&mut self, ctx: &mut Ctx) -> Result<()> {
        self.geom = Some(ctx.request(&self.output, &position2d::GetGeom)?);
        ctx.subscribe(&self.output)?;
        if self.input != self.output {
            ctx.subscribe(&self.input)?;
        }
        if let Some(b) = &mut self.laser {
            b.geom = Some(ctx.request(&b.dev, &laser::GetGeom)?);
            ctx.subscribe(&b.dev)?;
        }
        if let Some(b) = &mut self.sonar {
            b.geom = Some(ctx.request(&b.dev, &sonar::GetGeom)?);
            ctx.subscribe(&b.dev)?;
        }
        Ok(())
    }

    fn on_event(&mut self, ctx: &mut Ctx, event: Event) -> Result<()> {
        match event {
            Event::Data(s) if s.is::<position2d::Data>() && s.device == self.output => {
                let d = s.decode::<position2d::Data>()?.msg;
                self.vel = d.vel;
                if self.input == self.output {
                    self.on_input(ctx, &d)?;
                }
                Ok(())
            }
            Event::Data(s) if s.is::<position2d::Data>() && s.device == self.input => {
                let d = s.decode::<position2d::Data>()?.msg;
                self.on_input(ctx, &d)
            }
            Event::Data(s) if s.is::<laser::Scan>() => {
                let scan = s.decode::<laser::Scan>()?.msg;
                let robot = self.robot_pose();
                if let Some(b) = &mut self.laser {
                    if let Some(at) = b.poses.first() {
                        let laser = robot.compose(at);
                        let points = scan
                            .ranges
                            .iter()
                            .enumerate()
                            .map(|(i, &r)| {
                                let a = f64::from(scan.min_angle)
                                    + i as f64 * f64::from(scan.resolution);
                                let r = f64::from(r);
                                laser.apply(r * a.cos(), r * a.sin())
                            })
                            .collect();
                        b.push(points);
                    }
                }
                Ok(())
            }
            Event::Data(s) if s.is::<sonar::Ranges>() => {
                let ranges = s.decode::<sonar::Ranges>()?.msg.ranges;
                let robot = self.robot_pose();
                if let Some(b) = &mut self.sonar {
                    let points = ranges
                        .iter()
                        .zip(&b.poses)
                        .enumerate()
                        .filter(|(i, _)| !self.bad.contains(i))
                        .map(|(_, (&r, at))| robot.compose(at).apply(f64::from(r), 0.0))
                        .collect();
                    b.push(points);
                }
                Ok(())
            }
            Event::Data(_) => Ok(()),
            Event::Command(c) if c.is::<position2d::CmdVel>() => {
                let cmd = c.decode::<position2d::CmdVel>()?.msg;
                self.goal = None;
                self.dir = if cmd.vel.x < 0.0 { -1.0 } else { 1.0 };
                if cmd.state {
                    self.drive(ctx, cmd.vel.x, cmd.vel.yaw)
                } else {
                    self.drive(ctx, 0.0, 0.0)
                }
            }
            Event::Command(c) if c.is::<position2d::CmdPos>() => {
                let cmd = c.decode::<position2d::CmdPos>()?.msg;
                tracing::debug!(
                    "goal ({:.3}, {:.3}, {:.1}°)",
                    cmd.pos.x,
                    cmd.pos.y,
                    cmd.pos.yaw.to_degrees()
                );
                self.goal = Some(cmd.pos);
                self.turning = false;
                self.stall = false;
                self.translate = (ctx.now(), self.pose);
                Ok(())
            }
            Event::Command(c) => {
                tracing::debug!("nd: ignored command `{}`", c.key);
                Ok(())
            }
            Event::Request(r) => {
                let payload = r.sample.payload().to_bytes().into_owned();
                let id = ctx.forward_request(&self.output, &r.name, payload)?;
                self.pending.insert(id, r.responder);
                Ok(())
            }
            Event::Reply(reply) => self.on_reply(reply),
            Event::Tick | Event::Wake => Ok(()),
        }
    }

    fn shutdown(&mut self, ctx: &mut Ctx) -> Result<()> {
        self.drive(ctx, 0.0, 0.0)
    }
}

impl Nd {
    fn robot_pose(&self) -> Pose {
        Pose::new(self.pose.x, self.pose.y, self.pose.yaw)
    }

    fn on_reply(&mut self, reply: troupe_node::Reply) -> Result<()> {
        let pose = |p: &Pose3d| Pose::new(p.x, p.y, p.yaw);
        for b in [&mut self.laser, &mut self.sonar].into_iter().flatten() {
            if b.geom == Some(reply.id) {
                b.geom = None;
                let dev = b.dev;
                let why =
                    |e: NodeError| NodeError::config("nd", format!("{dev} gave no geometry: {e}"));
                b.poses = if dev.interface == Interface::Laser {
                    vec![pose(&reply.decode::<laser::Geom>().map_err(why)?.pose)]
                } else {
                    let g = reply.decode::<sonar::Geom>().map_err(why)?;
                    g.poses.iter().map(pose).collect()
                };
                return Ok(());
            }
        }
        if Some(reply.id) == self.geom {
            self.geom = None;
            let g = reply.decode::<position2d::Geom>().map_err(|e| {
                NodeError::config(
                    "nd",
                    format!(
                        "{} gave no geometry (the robot's size is needed): {e}",
                        self.output
                    ),
                )
            })?;
            self.shape = Some((g.size.length, g.size.width, g.pose.x));
            tracing::info!(
                "robot {:.2} m × {:.2} m, centre {:.2} m ahead of its origin",
                g.size.length,
                g.size.width,
                g.pose.x
            );
            self.set_direction(1.0)?;
            return Ok(());
        }
        if let Some(resp) = self.pending.remove(&reply.id) {
            resp.forward(reply.result);
        }
        Ok(())
    }

    /// Player's `SetDirection`: the robot's front is its back when driving
    /// backwards.
    fn set_direction(&mut self, dir: f64) -> Result<()> {
        if self.nd.is_some() && dir == self.current_dir {
            return Ok(());
        }
        let Some((length, width, px)) = self.shape else {
            return Ok(());
        };
        let o = &self.o;
        let (front, back) = (
            length / 2.0 + dir * px + o.safety_dist,
            length / 2.0 - dir * px + o.safety_dist,
        );
        let left = width / 2.0 + o.safety_dist;
        let dsmin = o.avoid_dist / 4.0;
        let nd = Algorithm::new(Params {
            front,
            back,
            left,
            vlmax: o.max_speed[0],
            vamax: o.max_speed[1],
            almax: 0.75,
            aamax: 0.75,
            dsmax: o.avoid_dist,
            dsmin,
            enlarge: dsmin * 0.2,
            discontinuity: 2.0 * left,
            t: 0.1,
        })
        .map_err(|e| NodeError::config("nd", e.0))?;
        self.nd = Some(nd);
        self.current_dir = dir;
        Ok(())
    }

    fn drive(&mut self, ctx: &mut Ctx, v: f64, w: f64) -> Result<()> {
        let vel = Pose2d::new(v, 0.0, w);
        ctx.command(&self.output, &position2d::CmdVel { vel, state: true })
    }

    /// Abandons the goal: the robot stops and the stall flag stays up.
    fn give_up(&mut self, ctx: &mut Ctx, why: &str) -> Result<()> {
        tracing::warn!("goal abandoned: {why}");
        self.goal = None;
        self.stall = true;
        self.drive(ctx, 0.0, 0.0)
    }

    fn on_input(&mut self, ctx: &mut Ctx, d: &position2d::Data) -> Result<()> {
        self.pose = d.pose;
        let mut out = position2d::Data {
            pose: d.pose,
            vel: self.vel,
            stall: false,
        };
        if d.stall {
            if self.o.wait_on_stall != 0 {
                self.drive(ctx, 0.0, 0.0)?;
                self.waiting = true;
            } else {
                out.stall = true;
            }
        } else {
            self.waiting = false;
        }
        out.stall |= self.stall;
        ctx.publish(&self.out, &out)?;
        if !self.waiting {
            self.step(ctx)?;
        }
        Ok(())
    }

    /// One decision toward the goal, Player's `Main` loop body.
    fn step(&mut self, ctx: &mut Ctx) -> Result<()> {
        let Some(goal) = self.goal else {
            return Ok(());
        };
        if self.nd.is_none() {
            return Ok(()); // the robot's size is not known yet
        }
        let now = ctx.now();
        let p = self.pose;
        let o = &self.o;
        let (dist_eps, ang_eps) = (o.goal_tol[0], o.goal_tol[1]);
        let g_dx = (goal.x - p.x).hypot(goal.y - p.y);
        let g_da = normalize(goal.yaw - p.yaw);
        if g_dx < dist_eps && g_da.abs() < ang_eps {
            tracing::debug!("at goal");
            self.goal = None;
            return self.drive(ctx, 0.0, 0.0);
        }
        let points: Vec<(f64, f64)> = [&self.laser, &self.sonar]
            .into_iter()
            .flatten()
            .flat_map(|b| b.scans.iter().flatten().copied())
            .collect();
        let vel = Motion {
            v: self.vel.x,
            w: self.vel.yaw,
        };
        let (vx, va);
        if g_dx < dist_eps || self.turning {
            let far = (p.x + 10.0 * goal.yaw.cos(), p.y + 10.0 * goal.yaw.sin());
            self.set_direction(1.0)?;
            let decided = self.decide(far, (p.x, p.y, p.yaw), vel, &points);
            let m = match decided {
                Ok(m) => m,
                Err(r) => return self.give_up(ctx, &refusal(r)),
            };
            vx = 0.0;
            va = m.w;
            if !self.turning {
                self.rotate = (now, g_da.abs());
                self.turning = true;
            } else if g_da.abs() < self.rotate.1 {
                self.rotate = (now, g_da.abs());
            } else if now - self.rotate.0 > self.o.rotate_stuck_time {
                return self.give_up(ctx, "ran out of time turning to the goal's heading");
            }
        } else {
            let (t0, last) = self.translate;
            let o_dx = (p.x - last.x).hypot(p.y - last.y);
            let o_da = normalize(p.yaw - last.yaw);
            if o_dx > self.o.translate_stuck_dist || o_da.abs() > self.o.translate_stuck_angle {
                self.translate = (now, p);
            } else if now - t0 > self.o.translate_stuck_time {
                return self.give_up(ctx, "ran out of time getting to the goal (stuck)");
            }
            let mut heading = p.yaw;
            if self.dir < 0.0 {
                heading = normalize(heading + std::f64::consts::PI);
            }
            self.set_direction(self.dir)?;
            match self.decide((goal.x, goal.y), (p.x, p.y, heading), vel, &points) {
                Ok(m) => (vx, va) = (m.v, m.w),
                Err(r) => return self.give_up(ctx, &refusal(r)),
            }
        }
        if vx == 0.0 && va == 0.0 {
            return self.give_up(ctx, "ND found no motion");
        }
        let o = &self.o;
        let vx = threshold(vx, o.min_speed[0], o.max_speed[0]);
        let va = if vx == 0.0 {
            threshold(va, o.min_speed[1], o.max_speed[1])
        } else {
            va
        };
        self.stall = false;
        tracing::debug!(
            "at ({:.2}, {:.2}, {:.0}°): {vx:.2} m/s, {:.0}°/s",
            p.x,
            p.y,
            p.yaw.to_degrees(),
            va.to_degrees()
        );
        self.drive(ctx, vx * self.dir, va)
    }

    fn decide(
        &self,
        goal: (f64, f64),
        pose: (f64, f64, f64),
        vel: Motion,
        points: &[(f64, f64)],
    ) -> std::result::Result<Motion, Refusal> {
        match &self.nd {
            Some(nd) => nd.decide(goal, self.o.goal_tol[0], pose, vel, points),
            None => Err(Refusal::NoRegion),
        }
    }
}

fn refusal(r: Refusal) -> String {
    match r {
        Refusal::Emergency => "emergency stop (an obstacle at the robot's front)".into(),
        Refusal::NoRegion => "no way through toward the goal".into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thresholds_are_players() {
        assert_eq!(threshold(0.0, 0.05, 0.3), 0.0);
        assert_eq!(threshold(0.001, 0.05, 0.3), 0.05);
        assert_eq!(threshold(0.5, 0.05, 0.3), 0.3);
        assert_eq!(threshold(-0.001, 0.05, 0.3), -0.05);
        assert_eq!(threshold(-0.5, 0.05, 0.3), -0.3);
    }
}
