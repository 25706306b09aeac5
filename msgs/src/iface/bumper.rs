//! `bumper`: contact switches.

use serde::{Deserialize, Serialize};

use crate::{message, Pose3d};

/// Bumper states, true = pressed.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Data {
    /// One per bumper.
    pub bumpers: Vec<bool>,
}
message!(Data, "bumper/data@1");

/// One bumper's geometry.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Define {
    /// Pose in the robot frame.
    pub pose: Pose3d,
    /// Metres.
    pub length: f32,
    /// Metres, radius of curvature.
    pub radius: f32,
}

/// Bumper geometry.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Geom {
    /// One per bumper.
    pub bumpers: Vec<Define>,
}
message!(Geom, "bumper/geom@1");

/// Asks for the [`Geom`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct GetGeom;
message!(GetGeom, "bumper/get_geom@1", req "geom" -> Geom);
