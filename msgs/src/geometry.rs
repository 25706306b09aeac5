//! Geometry shared by the interfaces: poses and sizes in metres and radians.

use serde::{Deserialize, Serialize};

/// A planar pose or velocity: metres (or m/s) and radians (or rad/s).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose2d {
    /// Metres, x forward.
    pub x: f64,
    /// Metres, y left.
    pub y: f64,
    /// Radians, counter-clockwise.
    pub yaw: f64,
}

impl Pose2d {
    /// A pose from its parts.
    pub const fn new(x: f64, y: f64, yaw: f64) -> Self {
        Pose2d { x, y, yaw }
    }
}

/// A pose in space: metres and radians.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose3d {
    /// Metres.
    pub x: f64,
    /// Metres.
    pub y: f64,
    /// Metres.
    pub z: f64,
    /// Radians.
    pub roll: f64,
    /// Radians.
    pub pitch: f64,
    /// Radians.
    pub yaw: f64,
}

impl Pose3d {
    /// The planar pose `x, y, yaw` at height 0.
    pub const fn planar(x: f64, y: f64, yaw: f64) -> Self {
        Pose3d {
            x,
            y,
            z: 0.0,
            roll: 0.0,
            pitch: 0.0,
            yaw,
        }
    }
}

/// A planar bounding box, metres (Player's `player_bbox2d_t`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Size2d {
    /// Metres, along y.
    pub width: f64,
    /// Metres, along x.
    pub length: f64,
}

/// A bounding box, metres (Player's `player_bbox3d_t`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Size3d {
    /// Metres, along y.
    pub width: f64,
    /// Metres, along x.
    pub length: f64,
    /// Metres, along z.
    pub height: f64,
}

/// An RGBA colour, each channel in 0..=1 (Player's `player_color_t` scaled).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Color {
    /// Red.
    pub r: f32,
    /// Green.
    pub g: f32,
    /// Blue.
    pub b: f32,
    /// Alpha (1 = opaque).
    pub a: f32,
}

impl Color {
    /// Red, green and blue as bytes (each channel clamped, rounded).
    pub fn rgb8(&self) -> [u8; 3] {
        let b = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
        [b(self.r), b(self.g), b(self.b)]
    }
}
