//! Geometry for Troupe's simulator and map drivers.
//!
//! - [`Pose`]: planar rigid transforms (compose, invert, transform points);
//! - [`Grid`]: an occupancy grid whose cells hold the id of what occupies
//!   them, with a coarse level of per-tile counts so rays skip empty space;
//! - [`Grid::fill_polygon`]: rasterises convex or concave polygons;
//! - [`Grid::cast`]: the first occupied cell along a ray (a grid walk);
//! - [`bitmap`]: loads an image and turns dark pixels into obstacle rectangles;
//! - [`raster`]: Stage's own raster of block outlines and its ray walk, so
//!   simulated ranges read as Stage's;
//! - [`Scene`] and [`Room`]: what an emulated range finder sees;
//! - [`OccMap`]: a Player map (-1 free, 0 unknown, +1 occupied) with world↔cell
//!   conversions and tiles.
//!
//! Depends on troupe-msgs and image only.
#![warn(missing_docs)]

pub mod bitmap;
mod drive;
mod grid;
pub mod occmap;
mod odometry;
mod pose;
pub mod raster;
mod scene;

pub use drive::{Body, DiffDrive};
pub use grid::{Grid, Hit, InTile, Lattice, TileBox, EMPTY};
pub use occmap::{OccMap, TileError};
pub use odometry::Odometry;
pub use pose::{bounds, normalize, ray_to_box, Pose, Transform};
pub use scene::{Room, Scene};
