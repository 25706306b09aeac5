//! `ranger`: a set of range sensors (laser scanners, sonar and IR arrays).

use serde::{Deserialize, Serialize};

use crate::iface::common::Ack;
use crate::{message, Pose3d, Size3d};

/// Range readings (`PLAYER_RANGER_DATA_RANGE`), metres.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Ranges {
    /// Metres, one per element or beam.
    pub ranges: Vec<f64>,
}
message!(Ranges, "ranger/ranges@1");

/// Intensity readings (`PLAYER_RANGER_DATA_INTNS`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Intensities {
    /// Device-specific units, one per element or beam.
    pub intensities: Vec<f64>,
}
message!(Intensities, "ranger/intensities@1");

/// Geometry: the device and each of its elements.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Geom {
    /// Pose of the device in the robot frame.
    pub pose: Pose3d,
    /// Size of the device.
    pub size: Size3d,
    /// Pose of each element (e.g. each sonar transducer), robot frame.
    pub element_poses: Vec<Pose3d>,
    /// Size of each element.
    pub element_sizes: Vec<Size3d>,
}
message!(Geom, "ranger/geom@1");

/// Configuration (`player_ranger_config_t`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Config {
    /// Radians, first beam.
    pub min_angle: f64,
    /// Radians, last beam.
    pub max_angle: f64,
    /// Radians between beams.
    pub angular_res: f64,
    /// Metres.
    pub min_range: f64,
    /// Metres.
    pub max_range: f64,
    /// Metres.
    pub range_res: f64,
    /// Hz.
    pub frequency: f64,
}
message!(Config, "ranger/config@1");

/// Asks for the [`Geom`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct GetGeom;
message!(GetGeom, "ranger/get_geom@1", req "geom" -> Geom);

/// Asks for the [`Config`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct GetConfig;
message!(GetConfig, "ranger/get_config@1", req "get_config" -> Config);

/// Sets the configuration; the reply is the configuration in force.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct SetConfig {
    /// The wanted configuration.
    pub config: Config,
}
message!(SetConfig, "ranger/set_config@1", req "set_config" -> Config);

/// Turns intensity data on or off.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct IntensityEnable {
    /// True = on.
    pub state: bool,
}
message!(IntensityEnable, "ranger/intns@1", req "intns" -> Ack);
