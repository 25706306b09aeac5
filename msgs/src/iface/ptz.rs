//! `ptz`: a pan-tilt-zoom unit.

use serde::{Deserialize, Serialize};

use crate::message;

/// Pan, tilt, zoom and their speeds: radians and rad/s.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Data {
    /// Radians.
    pub pan: f32,
    /// Radians.
    pub tilt: f32,
    /// Field of view, radians.
    pub zoom: f32,
    /// rad/s.
    pub panspeed: f32,
    /// rad/s.
    pub tiltspeed: f32,
}
message!(Data, "ptz/data@1");

/// Commands a pan, tilt and zoom (`PLAYER_PTZ_CMD_STATE`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Cmd {
    /// The wanted state and speeds.
    pub target: Data,
}
message!(Cmd, "ptz/cmd@1", cmd "state");
