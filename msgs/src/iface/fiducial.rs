//! `fiducial`: detected fiducial markers.

use serde::{Deserialize, Serialize};

use crate::{message, Pose3d, Size2d, Size3d};

/// One detected fiducial.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Item {
    /// Fiducial id (-1 when unknown).
    pub id: i32,
    /// Pose relative to the detector.
    pub pose: Pose3d,
    /// Uncertainty of the pose.
    pub upose: Pose3d,
}

/// The fiducials seen.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Data {
    /// Detections.
    pub fiducials: Vec<Item>,
}
message!(Data, "fiducial/data@1");

/// Detector geometry.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Geom {
    /// Pose in the robot frame.
    pub pose: Pose3d,
    /// Size of the detector.
    pub size: Size3d,
    /// Size of the markers.
    pub fiducial_size: Size2d,
}
message!(Geom, "fiducial/geom@1");

/// Asks for the [`Geom`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct GetGeom;
message!(GetGeom, "fiducial/get_geom@1", req "geom" -> Geom);

/// A fiducial ID (`player_fiducial_id_t`): what other fiducial finders
/// read off this device's model.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Id {
    /// The ID.
    pub id: u32,
}
message!(Id, "fiducial/id@1");

/// Asks for the [`Id`] (`PLAYER_FIDUCIAL_REQ_GET_ID`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct GetId;
message!(GetId, "fiducial/get_id@1", req "get_id" -> Id);

/// Sets the ID; the answer is the ID in force (`PLAYER_FIDUCIAL_REQ_SET_ID`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SetId {
    /// The new ID.
    pub id: u32,
}
message!(SetId, "fiducial/set_id@1", req "set_id" -> Id);
