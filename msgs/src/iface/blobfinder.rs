//! `blobfinder`: colour blobs in a camera image.

use serde::{Deserialize, Serialize};

use crate::message;

/// One blob; image coordinates in pixels from the top left.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Blob {
    /// Blob id.
    pub id: u32,
    /// Colour as 0xRRGGBB.
    pub color: u32,
    /// Pixels.
    pub area: u32,
    /// Centroid column.
    pub x: u32,
    /// Centroid row.
    pub y: u32,
    /// Bounding box, left column.
    pub left: u32,
    /// Bounding box, right column.
    pub right: u32,
    /// Bounding box, top row.
    pub top: u32,
    /// Bounding box, bottom row.
    pub bottom: u32,
    /// Metres to the blob (0 when unknown).
    pub range: f32,
}

/// The blobs seen, in the order the driver finds them (Stage: from the
/// right edge of the image leftwards).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Data {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// The blobs.
    pub blobs: Vec<Blob>,
}
message!(Data, "blobfinder/data@1");
