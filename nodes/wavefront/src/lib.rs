//! Player's `wavefront`: global path planning on a map, the path driven
//! waypoint by waypoint through a local controller (usually vfh).
//!
//! ```text
//! driver ( name "wavefront" provides ["planner:0"]
//!          requires ["output:::position2d:1" "input:::position2d:2" "map:0"]
//!          safety_dist 0.15 distance_epsilon 0.5 angle_epsilon 10 )
//! ```
//!
//! | | |
//! |---|---|
//! | requires | `output:::position2d` (the controller to drive, e.g. vfh), `input:::position2d` (the robot's pose on the map, e.g. amcl), a `map` |
//! | provides | one `planner` (Player 3's `online:::planner:0` or plain `planner:0`) |
//!
//! Options, Player's names and defaults: `safety_dist` 0.25 m,
//! `max_radius` 1.0 m, `dist_penalty` 1.0, `distance_epsilon` 0.5 m,
//! `angle_epsilon` 10°, `replan_dist_thresh` 2.0 m, `replan_min_time` 2.0 s
//! (either < 0 disables replanning), `update_rate` 10 Hz,
//! `add_rotational_waypoints` 1. Player's `cspace_file`, `request_map` and
//! `force_map_refresh` are accepted and have no effect (the map is always
//! requested at setup; a configuration space takes milliseconds). A `laser`
//! in requires (Player's scans marked on the map) is accepted with a
//! warning and not used: obstacles off the map are the local controller's.
//!
//! # Behavior
//!
//! - At setup: the map (info, then the whole grid), the robot's radius
//!   (half the `output` device's width) and motor power on.
//! - A goal (`goal` command) is planned at once, from the latest `input`
//!   pose — never before one has arrived. The planner state (valid, done,
//!   pose, goal, current waypoint) is published right after each plan and
//!   every 0.25 s.
//! - Each cycle (`update_rate`, on the node's clock) the current waypoint is
//!   sent to `output` as a position command in its odometric frame
//!   (`P + R(oa)(W − L)`, `oa` = odometric minus localized heading). The
//!   next waypoint is taken when the robot is within `distance_epsilon` of
//!   the current one; a waypoint more than 45° off the robot's heading is
//!   preceded by a turn on the spot. Every waypoint carries the goal's
//!   heading. The goal is done when all waypoints are taken and the robot is
//!   within `distance_epsilon` and `angle_epsilon` of it: the robot is
//!   stopped (a zero velocity command, once).
//! - The plan is redone after `replan_dist_thresh` of travel and
//!   `replan_min_time` since the last plan. An unreachable goal reports no
//!   valid path and stops the robot; a failed replan keeps the old path.
//! - `enable` false stops the robot and pauses (goal and plan kept);
//!   `waypoints` returns the path's waypoints.

pub mod plan;

use serde::Deserialize;
use troupe_geom::occmap::OccMap;
use troupe_geom::{normalize, Pose};
use troupe_msgs::{common, planner, position2d, Device, Interface, Pose2d};
use troupe_node::{Ctx, Driver, Event, MapFetch, NodeError, RequestId, Result, Section, Unit};

use crate::plan::{Params, Planner};

/// Options, by Player's names.
#[derive(Debug, Deserialize)]
#[serde(default)]
pub struct Options {
    /// Clearance added to the robot's radius (m).
    pub safety_dist: f64,
    /// Obstacle distance beyond which there is no penalty (m).
    pub max_radius: f64,
    /// Weight of the obstacle-proximity cost.
    pub dist_penalty: f64,
    /// Waypoint and goal tolerance (m).
    pub distance_epsilon: f64,
    /// Goal heading tolerance (rad).
    pub angle_epsilon: f64,
    /// Replan after this much travel (m); < 0 never.
    pub replan_dist_thresh: f64,
    /// Replan at most this often (s); < 0 never.
    pub replan_min_time: f64,
    /// Control cycles per second.
    pub update_rate: f64,
    /// Turn on the spot before a waypoint far off the heading.
    pub add_rotational_waypoints: f64,
    /// Player's; no effect.
    pub request_map: Option<f64>,
    /// Player's; no effect.
    pub force_map_refresh: Option<f64>,
    /// Player's; no effect.
    pub cspace_file: Option<String>,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            safety_dist: 0.25,
            max_radius: 1.0,
            dist_penalty: 1.0,
            distance_epsilon: 0.5,
            angle_epsilon: 10f64.to_radians(),
            replan_dist_thresh: 2.0,
            replan_min_time: 2.0,
            update_rate: 10.0,
            add_rotational_waypoints: 1.0,
            request_map: None,
            force_map_refresh: None,
            cspace_file: None,
        }
    }
}

/// Player's `angle_diff`: `a − b` wrapped into (−π, π].
fn angle_diff(a: f64, b: f64) -> f64 {
    normalize(a - b)
}

fn dist(a: (f64, f64), b: (f64, f64)) -> f64 {
    (a.0 - b.0).hypot(a.1 - b.1)
}

/// How far setup has come.
enum Setup {
    Waiting {
        fetch: MapFetch,
        geom: Option<RequestId>,
        map: Option<OccMap>,
        radius: Option<f64>,
    },
    Ready,
}

/// The wavefront driver.
pub struct Wavefront {
    o: Options,
    online: Device,
    output: Device,
    input: Device,
    map_dev: Device,
    setup: Setup,
    planner: Option<Planner>,
    /// Latest localized pose; none until `input` speaks.
    pose: Option<Pose>,
    odom: Pose,
    target: Pose,
    new_goal: bool,
    atgoal: bool,
    enable: bool,
    waypoints: Vec<(f64, f64)>,
    /// Index of the next waypoint to take; -1 = done or no plan.
    curr: i64,
    waypoint: Pose,
    rotate: bool,
    stopped: bool,
    last_replan: (f64, (f64, f64)),
    last_publish: f64,
    failed_once: bool,
}

impl Driver for Wavefront {
    const NAME: &'static str = "wavefront";
    type Options = Options;
    const UNITS: &'static [(&'static str, Unit)] = &[
        ("safety_dist", Unit::Length),
        ("max_radius", Unit::Length),
        ("distance_epsilon", Unit::Length),
        ("angle_epsilon", Unit::Angle),
        ("replan_dist_thresh", Unit::Length),
        ("cspace_file", Unit::Path),
    ];

    /// Enabling may plan a path (milliseconds on a large map): that waits
    /// its turn on the planner's thread.
    fn quick(request: &troupe_node::Request) -> bool {
        !request.is::<planner::Enable>()
    }

    fn new(section: &Section, o: Options) -> Result<Self> {
        if o.update_rate.is_nan() || o.update_rate <= 0.0 {
            return Err(NodeError::config(
                Self::NAME,
                format!("update_rate must be positive, not {}", o.update_rate),
            ));
        }
        if o.cspace_file.is_some() {
            tracing::warn!("cspace_file is not used: the configuration space is computed at setup");
        }
        // Player's wavefront could also mark laser returns on the map (a
        // `laser` in requires, scans with poses) for its `velocity_control`
        // mode; Troupe's plans on the map alone and leaves obstacles to the
        // local controller (vfh), as Player's default configuration does:
        // a `laser` in requires is warned about as unused.
        Ok(Wavefront {
            online: section.provided_one(Interface::Planner, None)?,
            output: section.required_one(Interface::Position2d, Some("output"))?,
            input: section.required_one(Interface::Position2d, Some("input"))?,
            map_dev: section.required_one(Interface::Map, None)?,
            o,
            setup: Setup::Ready,
            planner: None,
            pose: None,
            odom: Pose::default(),
            target: Pose::default(),
            new_goal: false,
            atgoal: true,
            enable: true,
            waypoints: Vec::new(),
            curr: -1,
            waypoint: Pose::default(),
            rotate: false,
            stopped: true,
            last_replan: (f64::NEG_INFINITY, (0.0, 0.0)),
            last_publish: f64::NEG_INFINITY,
            failed_once: false,
        })
    }

    fn setup(&mut self, ctx: &mut Ctx) -> Result<()> {
        self.setup = Setup::Waiting {
            fetch: MapFetch::start(ctx, self.map_dev)?,
            geom: Some(ctx.request(&self.output, &position2d::GetGeom)?),
            map: None,
            radius: None,
        };
        ctx.request(&self.output, &position2d::MotorPower { state: true })?;
        ctx.subscribe(&self.output)?;
        if self.input != self.output {
            ctx.subscribe(&self.input)?;
        }
        ctx.set_tick(Some(std::time::Duration::from_secs_f64(
            1.0 / self.o.update_rate,
        )));
        Ok(())
    }

    fn on_event(&mut self, ctx: &mut Ctx, event: Event) -> Result<()> {
        match event {
            Event::Data(s) if s.is::<position2d::Data>() => {
                let d = s.decode::<position2d::Data>()?.msg;
                let p: Pose = d.pose.into();
                if s.device == self.output {
                    self.odom = p;
                }
                if s.device == self.input {
                    self.pose = Some(p);
                }
                Ok(())
            }
            Event::Data(s) => Err(s.unexpected()),
            Event::Command(c) if c.is::<planner::Goal>() => {
                let g = c.decode::<planner::Goal>()?.msg.goal;
                self.target = g.into();
                self.new_goal = true;
                self.atgoal = false;
                self.failed_once = false;
                tracing::info!(
                    "new goal ({:.3}, {:.3}, {:.1}°)",
                    g.x,
                    g.y,
                    g.yaw.to_degrees()
                );
                self.cycle(ctx)
            }
            Event::Command(c) => {
                tracing::debug!("planner: ignored command `{}`", c.key);
                Ok(())
            }
            Event::Request(r) if r.is::<planner::GetWaypoints>() => {
                r.reply(&planner::Waypoints {
                    waypoints: self
                        .waypoints
                        .iter()
                        .map(|&(x, y)| Pose2d::new(x, y, 0.0))
                        .collect(),
                });
                Ok(())
            }
            Event::Request(r) if r.is::<planner::Enable>() => {
                self.enable = r.decode::<planner::Enable>()?.state;
                r.reply(&common::Ack);
                self.cycle(ctx)
            }
            Event::Request(r) => {
                r.unhandled(Self::NAME);
                Ok(())
            }
            Event::Reply(r) => self.on_reply(ctx, r),
            Event::Tick => self.cycle(ctx),
            Event::Wake => Ok(()),
        }
    }

    fn shutdown(&mut self, ctx: &mut Ctx) -> Result<()> {
        self.stop(ctx)
    }
}

impl Wavefront {
    fn on_reply(&mut self, ctx: &mut Ctx, r: troupe_node::Reply) -> Result<()> {
        let Setup::Waiting {
            fetch,
            geom,
            map,
            radius,
        } = &mut self.setup
        else {
            return Ok(());
        };
        if let Some((info, cells)) = fetch.on_reply(ctx, &r, "wavefront")? {
            let m = OccMap::from_tile(info, &cells)
                .map_err(|e| NodeError::config("wavefront", e.to_string()))?;
            *map = Some(m);
        } else if *geom == Some(r.id) {
            *geom = None;
            let g = r.decode::<position2d::Geom>().map_err(|e| {
                let why = format!(
                    "{} gave no geometry (the robot's size is needed): {e}",
                    self.output
                );
                NodeError::config("wavefront", why)
            })?;
            *radius = Some(g.size.width / 2.0);
        }
        if let (Some(m), Some(rad)) = (map.as_ref(), *radius) {
            let params = Params {
                min_radius: rad + self.o.safety_dist,
                max_radius: self.o.max_radius,
                dist_penalty: self.o.dist_penalty,
            };
            let t = std::time::Instant::now();
            self.planner = Some(Planner::new(m, params));
            tracing::info!(
                "configuration space of the {} x {} map in {:.1} ms (robot radius {rad:.3} m + safety {:.3} m)",
                m.info.width,
                m.info.height,
                t.elapsed().as_secs_f64() * 1e3,
                self.o.safety_dist
            );
            self.setup = Setup::Ready;
        }
        Ok(())
    }

    /// One control cycle.
    fn cycle(&mut self, ctx: &mut Ctx) -> Result<()> {
        if self.planner.is_none() {
            return Ok(());
        }
        let now = ctx.now();
        let Some(l) = self.pose else {
            return self.publish_due(ctx, now);
        };
        if !self.enable {
            self.stop(ctx)?;
            return self.publish_due(ctx, now);
        }
        let here = (l.x, l.y);
        let replan = self.o.replan_dist_thresh >= 0.0
            && self.o.replan_min_time >= 0.0
            && dist(here, self.last_replan.1) > self.o.replan_dist_thresh
            && now - self.last_replan.0 > self.o.replan_min_time
            && !self.atgoal;
        if self.new_goal || replan {
            self.plan(ctx, l, now)?;
        }
        self.execute(ctx, l)?;
        self.publish_due(ctx, now)
    }

    fn plan(&mut self, ctx: &mut Ctx, l: Pose, now: f64) -> Result<()> {
        let Some(planner) = self.planner.as_mut() else {
            return Ok(());
        };
        let t = std::time::Instant::now();
        match planner.plan((l.x, l.y), (self.target.x, self.target.y)) {
            Ok(path) => {
                self.waypoints = planner.waypoints(&path);
                self.curr = 0;
                self.rotate = false;
                tracing::debug!(
                    "planned {} cells, {} waypoints in {:.2} ms",
                    path.len(),
                    self.waypoints.len(),
                    t.elapsed().as_secs_f64() * 1e3
                );
                self.new_goal = true; // load the first waypoint below
            }
            Err(e) => {
                if !self.failed_once {
                    tracing::warn!(
                        "no path from ({:.2}, {:.2}) to ({:.2}, {:.2}): {e}",
                        l.x,
                        l.y,
                        self.target.x,
                        self.target.y
                    );
                    self.failed_once = true;
                }
                if self.curr < 0 || self.new_goal {
                    self.waypoints.clear();
                    self.curr = -1;
                }
                self.new_goal = false;
            }
        }
        self.last_replan = (now, (l.x, l.y));
        self.publish(ctx, now)
    }

    fn execute(&mut self, ctx: &mut Ctx, l: Pose) -> Result<()> {
        let here = (l.x, l.y);
        let n = self.waypoints.len() as i64;
        let going_for_target = n > 0 && self.curr == n;
        if going_for_target
            && dist(here, (self.target.x, self.target.y)) < self.o.distance_epsilon
            && angle_diff(self.target.yaw, l.yaw).abs() < self.o.angle_epsilon
        {
            if !self.atgoal {
                tracing::info!(
                    "goal reached at ({:.3}, {:.3}, {:.1}°)",
                    l.x,
                    l.y,
                    l.yaw.to_degrees()
                );
            }
            self.stop(ctx)?;
            self.curr = -1;
            self.new_goal = false;
            self.atgoal = true;
            return Ok(());
        }
        if self.curr < 0 {
            return self.stop(ctx);
        }
        let dw = dist(here, (self.waypoint.x, self.waypoint.y));
        let take = self.new_goal
            || (self.rotate
                && angle_diff(self.waypoint.yaw, l.yaw).abs() < std::f64::consts::FRAC_PI_4)
            || (!self.rotate && dw < self.o.distance_epsilon);
        if take && self.curr < n {
            let (x, y) = self.waypoints[self.curr as usize];
            self.curr += 1;
            self.waypoint = Pose::new(x, y, self.target.yaw);
            self.rotate = false;
            if self.o.add_rotational_waypoints != 0.0 || self.curr == 2 {
                let bearing = (y - l.y).atan2(x - l.x);
                if dist((x, y), here) > self.o.distance_epsilon
                    && angle_diff(bearing, l.yaw).abs() > std::f64::consts::FRAC_PI_4
                {
                    self.waypoint = Pose::new(l.x, l.y, bearing);
                    self.curr -= 1;
                    self.rotate = true;
                }
            }
            self.new_goal = false;
        }
        // The waypoint in the controller's odometric frame.
        let oa = angle_diff(self.odom.yaw, l.yaw);
        let (s, c) = oa.sin_cos();
        let (dx, dy) = (self.waypoint.x - l.x, self.waypoint.y - l.y);
        let pos = Pose2d::new(
            self.odom.x + c * dx - s * dy,
            self.odom.y + s * dx + c * dy,
            normalize(self.waypoint.yaw + oa),
        );
        self.stopped = false;
        ctx.command(
            &self.output,
            &position2d::CmdPos {
                pos,
                vel: Pose2d::default(),
                state: true,
            },
        )
    }

    fn stop(&mut self, ctx: &mut Ctx) -> Result<()> {
        if !self.stopped {
            self.stopped = true;
            ctx.command(
                &self.output,
                &position2d::CmdVel {
                    vel: Pose2d::default(),
                    state: true,
                },
            )?;
        }
        Ok(())
    }

    fn publish_due(&mut self, ctx: &mut Ctx, now: f64) -> Result<()> {
        if now - self.last_publish >= 0.25 {
            self.publish(ctx, now)?;
        }
        Ok(())
    }

    fn publish(&mut self, ctx: &mut Ctx, now: f64) -> Result<()> {
        self.last_publish = now;
        let valid = !self.waypoints.is_empty();
        let done = valid && self.curr < 0;
        let p = self.pose.unwrap_or_default();
        let mut s = planner::State {
            valid,
            done,
            pose: p.into(),
            goal: self.target.into(),
            ..Default::default()
        };
        if valid && !done {
            s.waypoint = self.waypoint.into();
            s.waypoint_idx = self.curr as i32;
            s.waypoints_count = self.waypoints.len() as u32;
        }
        ctx.publish(&self.online, &s)
    }
}
