//! `planner`: a global path planner such as wavefront.

use serde::{Deserialize, Serialize};

use crate::iface::common::Ack;
use crate::{message, Pose2d};

/// Planner state (`PLAYER_PLANNER_DATA_STATE`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct State {
    /// A valid path to the goal exists.
    pub valid: bool,
    /// The goal has been reached.
    pub done: bool,
    /// Current robot pose.
    pub pose: Pose2d,
    /// The goal.
    pub goal: Pose2d,
    /// The waypoint being driven to.
    pub waypoint: Pose2d,
    /// Index of that waypoint; -1 when there is none.
    pub waypoint_idx: i32,
    /// Waypoints in the path.
    pub waypoints_count: u32,
}
message!(State, "planner/state@1");

/// Sets a new goal (`PLAYER_PLANNER_CMD_GOAL`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Goal {
    /// Goal pose, world frame.
    pub goal: Pose2d,
}
message!(Goal, "planner/goal@1", cmd "goal");

/// Enables or disables the robot's motion.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Enable {
    /// True = the planner drives the robot.
    pub state: bool,
}
message!(Enable, "planner/enable@1", req "enable" -> Ack);

/// The current path.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Waypoints {
    /// Waypoints, world frame, first to last.
    pub waypoints: Vec<Pose2d>,
}
message!(Waypoints, "planner/waypoints@1");

/// Asks for the [`Waypoints`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct GetWaypoints;
message!(GetWaypoints, "planner/get_waypoints@1", req "waypoints" -> Waypoints);
