//! `simulation`: inspect and change the simulated world by model name.

use serde::{Deserialize, Serialize};

use crate::iface::common::Ack;
use crate::{message, Color, Pose2d, Pose3d};

/// Asks for the pose of model `name`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct GetPose2d {
    /// Model name as in the world file.
    pub name: String,
}
message!(GetPose2d, "simulation/get_pose2d@1", req "get_pose2d" -> Pose2dOf);

/// A model's pose.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose2dOf {
    /// Model name.
    pub name: String,
    /// World pose.
    pub pose: Pose2d,
}
message!(Pose2dOf, "simulation/pose2d@1");

/// Moves model `name` to `pose`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SetPose2d {
    /// Model name.
    pub name: String,
    /// New world pose.
    pub pose: Pose2d,
}
message!(SetPose2d, "simulation/set_pose2d@1", req "set_pose2d" -> Ack);

/// Asks for the 3D pose of model `name` (`PLAYER_SIMULATION_REQ_GET_POSE3D`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct GetPose3d {
    /// Model name as in the world file.
    pub name: String,
}
message!(GetPose3d, "simulation/get_pose3d@1", req "get_pose3d" -> Pose3dOf);

/// A model's pose in 3D, and the simulation time it was read at.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose3dOf {
    /// Model name.
    pub name: String,
    /// Pose (Stage: roll and pitch 0).
    pub pose: Pose3d,
    /// Simulation time, microseconds (as Stage's plugin answers).
    pub simtime: f64,
}
message!(Pose3dOf, "simulation/pose3d@1");

/// Moves model `name` to `pose` (x, y, z and yaw; Stage ignores roll and pitch).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SetPose3d {
    /// Model name.
    pub name: String,
    /// New pose.
    pub pose: Pose3d,
}
message!(SetPose3d, "simulation/set_pose3d@1", req "set_pose3d" -> Ack);

/// A property value.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Value {
    /// A colour (`"color"`).
    Color(Color),
    /// A number.
    Number(f64),
    /// An integer.
    Int(i64),
    /// A string.
    Text(String),
}

impl Default for Value {
    fn default() -> Self {
        Value::Number(0.0)
    }
}

/// Asks for property `prop` of model `name`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct GetProperty {
    /// Model name.
    pub name: String,
    /// Property name (`"color"`, …).
    pub prop: String,
}
message!(GetProperty, "simulation/get_property@1", req "get_property" -> Property);

/// A model's property.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Property {
    /// Model name.
    pub name: String,
    /// Property name.
    pub prop: String,
    /// Its value.
    pub value: Value,
}
message!(Property, "simulation/property@1");

/// Sets property `prop` of model `name`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SetProperty {
    /// Model name.
    pub name: String,
    /// Property name.
    pub prop: String,
    /// New value.
    pub value: Value,
}
message!(SetProperty, "simulation/set_property@1", req "set_property" -> Ack);

/// Advances a simulator that steps only when told by `steps` steps
/// (a Troupe extension, for deterministic tests); the reply comes after them.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Step {
    /// Steps of `interval_sim` each.
    pub steps: u32,
}
message!(Step, "simulation/step@1", req "step" -> Ack);
