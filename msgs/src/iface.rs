//! One module per Player interface.

pub mod aio;
pub mod blobfinder;
pub mod bumper;
pub mod camera;
pub mod common;
pub mod dio;
pub mod fiducial;
pub mod gps;
pub mod gripper;
pub mod ir;
pub mod laser;
pub mod localize;
pub mod log;
pub mod map;
pub mod planner;
pub mod position2d;
pub mod power;
pub mod ptz;
pub mod ranger;
pub mod sim;
pub mod simulation;
pub mod sonar;
pub mod wsn;
