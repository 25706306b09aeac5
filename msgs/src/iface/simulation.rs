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

/// Asks for the whole world as a viewer draws it: every model's body and
/// colour, and which model serves which device (a Troupe extension, for
/// `troupe view`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct GetWorld;
message!(GetWorld, "simulation/get_world@1", req "world" -> World);

/// The simulated world, for viewers.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct World {
    /// Every model, in the world file's order (a model's id is its place here).
    pub models: Vec<Model>,
    /// The devices the simulator serves, each with its model.
    pub devices: Vec<DeviceModel>,
    /// Metres per cell of the simulator's grid.
    pub resolution: f64,
}
message!(World, "simulation/world@1");

/// One model of a [`World`].
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Model {
    /// Its name (`r0`, `r0.ranger:1`).
    pub name: String,
    /// Its parent's id, for a model mounted on another.
    pub parent: Option<u32>,
    /// Its colour.
    pub color: Color,
    /// Its body: polygons in its own frame, metres.
    pub polys: Vec<Vec<[f32; 2]>>,
    /// Whether it moves (a robot and what it carries); the others stand still.
    pub moves: bool,
    /// Where it stands now (x, y, yaw; world frame).
    pub pose: [f32; 3],
}

/// A device the simulator serves, and where its readings come from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DeviceModel {
    /// The device.
    pub device: crate::Device,
    /// The model serving it.
    pub model: u32,
    /// For range sensors: each sensor's pose in the model's frame (x, y,
    /// yaw), its field of view and its longest range, in the order of the
    /// device's readings.
    pub sensors: Vec<Sensor>,
}

/// One range sensor of a [`DeviceModel`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Sensor {
    /// Pose in the model's frame (x, y, yaw).
    pub pose: [f32; 3],
    /// Field of view, radians.
    pub fov: f32,
    /// Longest range, metres.
    pub range: f32,
    /// Readings it makes.
    pub samples: u32,
}

/// The poses of every model that moves, in the world frame, published on
/// the simulation device as the simulation runs (a Troupe extension, for
/// viewers; at most about 30 times a second of wall time).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Poses {
    /// Simulation time, seconds.
    pub time: f64,
    /// Model id (its place in [`World::models`]) and pose (x, y, yaw).
    pub poses: Vec<(u32, [f32; 3])>,
}
message!(Poses, "simulation/poses@1");
