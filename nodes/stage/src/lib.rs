//! Troupe's Stage: the 2D multi-robot simulator as one node.
//!
//! - [`worldfile`]: Stage's world-file language (includes, macros, entities);
//! - [`world`]: typed models, bodies stretched to size, sensors;
//! - [`sim`]: the simulation (kinematics, collisions, ranger ray casting);
//! - [`movers`]: moving bodies as rays meet them, exactly.
#![warn(missing_docs)]

pub mod colors;
mod crew;
pub mod movers;
mod node;
pub mod sim;
pub mod world;
pub mod worldfile;

pub use node::{ModelMap, Options, Stage};
