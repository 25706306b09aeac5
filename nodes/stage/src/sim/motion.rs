//! How bases move: the commands a position model takes, each base's
//! state and settings, and a step's move — planned on the crew's threads,
//! applied in model order (Stage's kinematics, odometry error, stalls).

use super::*;
use crate::colors::unit_draw;

/// What a position model was last told to do.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Command {
    /// Velocity: forward, sideways (m/s), turn (rad/s).
    Vel(Pose),
    /// Car-like: speed (m/s) and steering angle (rad).
    Car(f64, f64),
    /// Go to a pose of the odometric frame.
    GoTo(Pose),
}

/// A mobile base's state.
#[derive(Debug, Clone)]
pub struct Base {
    /// Its model.
    pub model: usize,
    /// The last command (`None`: idle, or under its `ctrl`).
    pub cmd: Option<Command>,
    /// Velocity in the robot frame, m/s and rad/s.
    pub vel: Pose,
    /// Blocked by an obstacle on the last step.
    pub stall: bool,
    /// The reported pose (odometry or GPS).
    pub odom: Pose,
    /// The frame of the reported pose.
    pub origin: Pose,
    /// Motors enabled.
    pub enabled: bool,
    /// Its built-in controller (its model's `ctrl`), if any: it drives
    /// the base while no command has come.
    pub ctrl: Option<Ctrl>,
    /// What that controller keeps from step to step.
    pub mind: Mind,
}

/// What a base's move reads of its `position` settings, side by side
/// with the other bases' (see [`Frame`]).
#[derive(Debug, Clone, Copy)]
pub(super) struct Motion {
    pub(super) drive: Drive,
    pub(super) localization: Localization,
    pub(super) wheelbase: f64,
    /// Its velocity bounds on x, y and yaw: least, most.
    pub(super) bounds: [f64; 6],
    pub(super) odom_error: [f64; 3],
}

impl Motion {
    /// Model `m`'s motion under `c`. Without an `odom_error`, its errors
    /// are drawn as Stage draws each robot's at its start: uniform within
    /// ±0.015 on x and y, ±0.025 on turns (half of `INTEGRATION_ERROR_MAX_X`
    /// 0.03 and `_A` 0.05), the same on every run.
    pub(super) fn of(c: &crate::world::PositionCfg, m: usize) -> Motion {
        let vb = &c.velocity_bounds;
        let draw = |k: u64, max: f64| (unit_draw([m as u64, k]) - 0.5) * max;
        Motion {
            drive: c.drive,
            localization: c.localization,
            wheelbase: c.wheelbase,
            bounds: [vb[0], vb[1], vb[2], vb[3], vb[6], vb[7]],
            odom_error: c
                .odom_error
                .unwrap_or_else(|| [draw(0, 0.03), draw(1, 0.03), draw(2, 0.05)]),
        }
    }
}

/// What a base does in a step (see [`Sim::plan`]); kept from step to step
/// for its buffers.
#[derive(Default)]
pub(super) struct Plan {
    /// Its velocity this step, its pose at the end of it, and the pose it
    /// then reports (worked out here, on every thread, rather than while
    /// the bases move one by one; `None`: only once it has moved).
    pub(super) v: Pose,
    pub(super) next: Pose,
    pub(super) odom: Option<Pose>,
    /// Whether it moves, and what its controller keeps after this step.
    pub(super) moving: bool,
    pub(super) mind: Mind,
    /// Its tree's bodies where it would move to, and whether they would
    /// meet a static obstacle.
    pub(super) bodies: Vec<Placed>,
    pub(super) walled: bool,
    /// A yaw and its sine and cosine: where the last plan moved to, which
    /// the next plan starts from (one `sin_cos` a step where there were
    /// two).
    pub(super) turn: Option<(f64, (f64, f64))>,
}

impl Sim {
    /// Works out what base `bi` does in a step of `dt`, from the poses at
    /// the step's start, into `plan`.
    ///
    /// # Behavior
    ///
    /// Bases move one after another, each seeing those before it where they
    /// moved to; but what a base asks for and whether it would meet a wall
    /// depend on it alone, so every base is planned at once (on every
    /// thread), and only the test against the other robots and the move
    /// itself are left for [`Sim::apply`], in order. A base on another
    /// model's back is planned there too, as it stands once that has moved.
    pub(super) fn plan(&self, bi: usize, dt: f64, plan: &mut Plan) {
        let m = self.bases[bi].model;
        let Some(cfg) = &self.motions[bi] else {
            return;
        };
        plan.mind = self.bases[bi].mind;
        let want = match self.bases[bi].cmd {
            _ if !self.bases[bi].enabled => Pose::default(),
            Some(Command::Vel(v)) => v,
            Some(Command::Car(speed, steer)) => {
                Pose::new(speed, 0.0, speed * steer.tan() / cfg.wheelbase.max(1e-6))
            }
            Some(Command::GoTo(goal)) => {
                stage_position_control(cfg.drive, self.bases[bi].odom, goal)
            }
            None => match self.bases[bi].ctrl {
                Some(c) => self.control(bi, c, &mut plan.mind),
                None => Pose::default(),
            },
        };
        // As Stage's velocity control: the speeds asked for, within the
        // velocity bounds (its acceleration bounds are for its
        // acceleration control, which no controller here uses).
        let vb = &cfg.bounds;
        let mut v = Pose::new(
            want.x.clamp(vb[0], vb[1]),
            want.y.clamp(vb[2], vb[3]),
            want.yaw.clamp(vb[4], vb[5]),
        );
        if cfg.drive != Drive::Omni {
            v.y = 0.0;
        }
        let here = self.poses[m];
        let step = Pose::new(v.x * dt, v.y * dt, v.yaw * dt);
        let turn = match plan.turn {
            Some((yaw, turn)) if yaw == here.yaw => turn,
            _ => here.yaw.sin_cos(),
        };
        let next = here.compose_by(turn, &step);
        let root_parent = self.frames[m].parent == Frame::ROOT;
        let g_next = if root_parent {
            next
        } else {
            self.global(m).compose(&step)
        };
        plan.v = v;
        plan.next = next;
        plan.moving = v.x != 0.0 || v.y != 0.0 || v.yaw != 0.0;
        let b = &self.bases[bi];
        plan.odom = match cfg.localization {
            // Where a base on another's back ends up is known only once
            // that one has moved: `apply` works it out then.
            Localization::Gps if root_parent => Some(b.origin.inverse().compose(&next)),
            Localization::Gps => None,
            Localization::Odom => {
                let e = cfg.odom_error;
                Some(b.odom.compose(&Pose::new(
                    step.x * (1.0 + e[0]),
                    step.y * (1.0 + e[1]),
                    step.yaw * (1.0 + e[2]),
                )))
            }
        };
        if plan.moving {
            let turn = g_next.yaw.sin_cos();
            plan.turn = Some((g_next.yaw, turn));
            self.tree_at(m, (g_next, turn), &mut plan.bodies);
            plan.walled = self.hits_statics(self.root(m), &plan.bodies);
        }
    }

    /// Carries out base `bi`'s `plan` (see [`Sim::plan`]).
    pub(super) fn apply(&mut self, bi: usize, dt: f64, plan: &mut Plan) {
        let m = self.bases[bi].model;
        if self.root(m) != m {
            // On another model's back: planned where that one moved to.
            self.plan(bi, dt, plan);
        }
        let Some(cfg) = &self.motions[bi] else {
            return;
        };
        // `gps` reports where a base moved to, `odom` integrates every step.
        let reports = plan.moving || cfg.localization == Localization::Odom;
        let v = plan.v;
        self.bases[bi].mind = plan.mind;
        if plan.moving {
            if plan.walled || self.hits_movers(self.root(m), &plan.bodies) {
                let b = &mut self.bases[bi];
                b.stall = true;
                b.vel = Pose::default();
                return;
            }
            self.poses[m] = plan.next;
            self.commit(&mut plan.bodies);
        }
        if reports {
            let b = &self.bases[bi];
            let odom = plan
                .odom
                .unwrap_or_else(|| b.origin.inverse().compose(&self.global(m)));
            self.bases[bi].odom = odom;
        }
        self.bases[bi].stall = false;
        self.bases[bi].vel = v;
    }
}

/// Stage's position controller (`ModelPosition::Update`, `CONTROL_POSITION`),
/// as it is, on the odometric pose `o`: an omni base closes each axis's
/// error at up to 0.4 m/s and 1 rad/s; a differential one turns toward the
/// goal point, drives at up to 0.4 m/s once within π/16 of it, and within
/// 2 cm turns on the spot to the goal's heading. The turn rate is the
/// error, held above -1 rad/s but not below 1 (Stage clamps it one way
/// only); the velocity bounds clamp it after.
pub(super) fn stage_position_control(drive: Drive, o: Pose, goal: Pose) -> Pose {
    let (dx, dy) = (goal.x - o.x, goal.y - o.y);
    let heading = normalize(goal.yaw - o.yaw);
    const MAX_XY: f64 = 0.4;
    const MAX_A: f64 = 1.0;
    const CLOSE_ENOUGH: f64 = 0.02;
    if drive == Drive::Omni {
        return Pose::new(dx.min(MAX_XY), dy.min(MAX_XY), heading.min(MAX_A));
    }
    if dx.abs() < CLOSE_ENOUGH && dy.abs() < CLOSE_ENOUGH {
        return Pose::new(0.0, 0.0, heading.max(-MAX_A));
    }
    let err = normalize(dy.atan2(dx) - o.yaw);
    let forward = if err.abs() < std::f64::consts::PI / 16.0 {
        dx.hypot(dy).min(MAX_XY)
    } else {
        0.0
    };
    Pose::new(forward, 0.0, err.max(-MAX_A))
}
