//! `sonar`: an array of sonar transducers.

use serde::{Deserialize, Serialize};

use crate::{message, Pose3d};

/// Ranges, metres, one per transducer.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Ranges {
    /// Metres.
    pub ranges: Vec<f32>,
}
message!(Ranges, "sonar/ranges@1");

/// Pose of each transducer in the robot frame.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Geom {
    /// One per transducer.
    pub poses: Vec<Pose3d>,
}
message!(Geom, "sonar/geom@1");

/// Asks for the [`Geom`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct GetGeom;
message!(GetGeom, "sonar/get_geom@1", req "geom" -> Geom);
