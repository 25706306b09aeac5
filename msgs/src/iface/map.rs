//! `map`: an occupancy grid and a vector map.
//!
//! Cells are `-1` free, `0` unknown, `+1` occupied, row-major from the cell at
//! the map's origin (lower left), as Player's map interface sends them.

use serde::{Deserialize, Serialize};

use crate::{message, Pose2d};

/// Map meta-data (`PLAYER_MAP_REQ_GET_INFO`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Info {
    /// Cells along x.
    pub width: u32,
    /// Cells along y.
    pub height: u32,
    /// Metres per cell.
    pub resolution: f32,
    /// Pose of cell (0, 0)'s corner in the world.
    pub origin: Pose2d,
}
message!(Info, "map/info@1");

/// Asks for the [`Info`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct GetInfo;
message!(GetInfo, "map/get_info@1", req "info" -> Info);

/// A tile of cells (the whole grid is the tile at 0, 0 of the map's size).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Data {
    /// First column.
    pub col: u32,
    /// First row.
    pub row: u32,
    /// Columns in the tile.
    pub width: u32,
    /// Rows in the tile.
    pub height: u32,
    /// `width * height` cells, row-major: -1 free, 0 unknown, +1 occupied.
    #[serde(with = "crate::bytes::i8s")]
    pub cells: Vec<i8>,
}
message!(Data, "map/data@1");

/// Asks for a tile of cells.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct GetData {
    /// First column.
    pub col: u32,
    /// First row.
    pub row: u32,
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
}
message!(GetData, "map/get_data@1", req "data" -> Data);

/// A line segment of a vector map, metres.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Segment {
    /// Start x.
    pub x0: f64,
    /// Start y.
    pub y0: f64,
    /// End x.
    pub x1: f64,
    /// End y.
    pub y1: f64,
}

/// A vector map (`PLAYER_MAP_REQ_GET_VECTOR`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Vector {
    /// Bounds, metres.
    pub min_x: f64,
    /// Bounds, metres.
    pub max_x: f64,
    /// Bounds, metres.
    pub min_y: f64,
    /// Bounds, metres.
    pub max_y: f64,
    /// The segments.
    pub segments: Vec<Segment>,
}
message!(Vector, "map/vector@1");

/// Asks for the [`Vector`] map.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct GetVector;
message!(GetVector, "map/get_vector@1", req "vector" -> Vector);
