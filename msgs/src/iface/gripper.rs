//! `gripper`: a gripper with break beams and optional storage.

use serde::{Deserialize, Serialize};

use crate::{message, Pose3d, Size3d};

/// Gripper state, as Player's `PLAYER_GRIPPER_STATE_*`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum State {
    /// Paddles open.
    #[default]
    Open,
    /// Paddles closed.
    Closed,
    /// Moving.
    Moving,
    /// Error.
    Error,
}

/// Gripper data (`PLAYER_GRIPPER_DATA_STATE`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Data {
    /// Paddle state.
    pub state: State,
    /// Break-beam bitmask, bit i = beam i broken.
    pub beams: u32,
    /// Objects held in storage.
    pub stored: u8,
}
message!(Data, "gripper/data@1");

/// Opens the gripper.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Open;
message!(Open, "gripper/open@1", cmd "open");

/// Closes the gripper.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Close;
message!(Close, "gripper/close@1", cmd "close");

/// Stops the gripper.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Stop;
message!(Stop, "gripper/stop@1", cmd "stop");

/// Gripper geometry.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Geom {
    /// Pose in the robot frame.
    pub pose: Pose3d,
    /// Outer size.
    pub outer_size: Size3d,
    /// Inner size.
    pub inner_size: Size3d,
    /// Number of break beams.
    pub num_beams: u8,
    /// Storage capacity.
    pub capacity: u8,
}
message!(Geom, "gripper/geom@1");

/// Asks for the [`Geom`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct GetGeom;
message!(GetGeom, "gripper/get_geom@1", req "geom" -> Geom);
