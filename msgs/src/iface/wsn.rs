//! `wsn`: a wireless sensor network's nodes, one reading at a time.

use serde::{Deserialize, Serialize};

use crate::message;

/// What one node of the network measured (`player_wsn_node_data_t`), in
/// the units its driver reports (raw counts, or engineering units).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Readings {
    /// Light.
    pub light: f32,
    /// Microphone.
    pub mic: f32,
    /// Acceleration along x.
    pub accel_x: f32,
    /// Acceleration along y.
    pub accel_y: f32,
    /// Acceleration along z.
    pub accel_z: f32,
    /// Magnetic field along x.
    pub magn_x: f32,
    /// Magnetic field along y.
    pub magn_y: f32,
    /// Magnetic field along z.
    pub magn_z: f32,
    /// Temperature.
    pub temperature: f32,
    /// Battery.
    pub battery: f32,
}

/// One node's packet (`PLAYER_WSN_DATA_STATE`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Data {
    /// The kind of node.
    pub node_type: u32,
    /// The node.
    pub node_id: u32,
    /// The node it reports through.
    pub node_parent_id: u32,
    /// What it measured.
    pub readings: Readings,
}
message!(Data, "wsn/data@1");
