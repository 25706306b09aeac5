//! `ir`: infrared range sensors.

use serde::{Deserialize, Serialize};

use crate::{message, Pose3d};

/// IR readings.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Data {
    /// Volts, one per sensor.
    pub voltages: Vec<f32>,
    /// Metres, one per sensor.
    pub ranges: Vec<f32>,
}
message!(Data, "ir/data@1");

/// Sensor poses.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Geom {
    /// One per sensor, robot frame.
    pub poses: Vec<Pose3d>,
}
message!(Geom, "ir/geom@1");

/// Asks for the [`Geom`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct GetGeom;
message!(GetGeom, "ir/get_geom@1", req "pose" -> Geom);
