//! `laser`: a scanning range finder.

use serde::{Deserialize, Serialize};

use crate::{message, Pose2d, Pose3d, Size3d};

/// One scan (`PLAYER_LASER_DATA_SCAN`). Beam `i` points at `min_angle + i * resolution`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Scan {
    /// Radians, first beam.
    pub min_angle: f32,
    /// Radians, last beam.
    pub max_angle: f32,
    /// Radians between beams.
    pub resolution: f32,
    /// Metres, the sensor's maximum range.
    pub max_range: f32,
    /// Metres, one per beam.
    pub ranges: Vec<f32>,
    /// Reflectance per beam (0 = none), Player's `intensity`.
    #[serde(with = "crate::bytes::u8s")]
    pub intensity: Vec<u8>,
    /// Scan counter.
    pub id: u32,
}
message!(Scan, "laser/scan@1");

/// A scan with the pose it was taken at (`PLAYER_LASER_DATA_SCANPOSE`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ScanPose {
    /// The scan.
    pub scan: Scan,
    /// Pose of the laser (odometric frame).
    pub pose: Pose2d,
}
message!(ScanPose, "laser/scanpose@1");

/// Laser geometry.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Geom {
    /// Pose in the robot frame.
    pub pose: Pose3d,
    /// Size of the sensor.
    pub size: Size3d,
}
message!(Geom, "laser/geom@1");

/// Laser configuration (`player_laser_config_t`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Config {
    /// Radians.
    pub min_angle: f32,
    /// Radians.
    pub max_angle: f32,
    /// Radians between beams.
    pub resolution: f32,
    /// Metres.
    pub max_range: f32,
    /// Metres, range resolution.
    pub range_res: f32,
    /// Intensity data on.
    pub intensity: bool,
    /// Hz.
    pub scanning_frequency: f32,
}
message!(Config, "laser/config@1");

/// Asks for the laser's [`Geom`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct GetGeom;
message!(GetGeom, "laser/get_geom@1", req "geom" -> Geom);

/// Asks for the laser's [`Config`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct GetConfig;
message!(GetConfig, "laser/get_config@1", req "get_config" -> Config);

/// Sets the configuration; the reply is the configuration in force.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct SetConfig {
    /// The wanted configuration.
    pub config: Config,
}
message!(SetConfig, "laser/set_config@1", req "set_config" -> Config);

/// The laser's serial number (`player_laser_get_id_config_t`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Id {
    /// The serial number, as the device reports it.
    pub serial_number: u32,
}
message!(Id, "laser/id@1");

/// Asks for the laser's [`Id`] (`PLAYER_LASER_REQ_GET_ID`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct GetId;
message!(GetId, "laser/get_id@1", req "get_id" -> Id);
