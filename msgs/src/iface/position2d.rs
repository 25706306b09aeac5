//! `position2d`: a planar mobile base (odometry, velocity and position control).

use serde::{Deserialize, Serialize};

use crate::iface::common::Ack;
use crate::{message, Pose2d, Pose3d, Size3d};

/// State of the base (Player's `PLAYER_POSITION2D_DATA_STATE`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Data {
    /// Odometric pose, metres and radians.
    pub pose: Pose2d,
    /// Velocity in the robot frame: m/s, m/s, rad/s.
    pub vel: Pose2d,
    /// True when the motors are stalled (a collision in simulation).
    pub stall: bool,
}
message!(Data, "position2d/data@1");

/// Geometry of the base (reply to [`GetGeom`], also Player's DATA_GEOM).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Geom {
    /// Pose of the base's centre in the robot frame.
    pub pose: Pose3d,
    /// Size of the base.
    pub size: Size3d,
}
message!(Geom, "position2d/geom@1");

/// Velocity command (`PLAYER_POSITION2D_CMD_VEL`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct CmdVel {
    /// Forward, sideways (m/s) and turn (rad/s) speeds.
    pub vel: Pose2d,
    /// Motor state Player sends along (true = on).
    pub state: bool,
}
message!(CmdVel, "position2d/cmd_vel@1", cmd "vel");

/// Position command, Player's GoTo (`PLAYER_POSITION2D_CMD_POS`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct CmdPos {
    /// Target pose in the odometric frame.
    pub pos: Pose2d,
    /// Speed limits to get there (0 = driver default).
    pub vel: Pose2d,
    /// Motor state (true = on).
    pub state: bool,
}
message!(CmdPos, "position2d/cmd_pos@1", cmd "pos");

/// Car-like command (`PLAYER_POSITION2D_CMD_CAR`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct CmdCar {
    /// Forward speed, m/s.
    pub velocity: f64,
    /// Steering angle, radians.
    pub angle: f64,
}
message!(CmdCar, "position2d/cmd_car@1", cmd "car");

/// Asks for the base's [`Geom`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct GetGeom;
message!(GetGeom, "position2d/get_geom@1", req "geom" -> Geom);

/// Enables or disables the motors.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct MotorPower {
    /// True = enabled.
    pub state: bool,
}
message!(MotorPower, "position2d/motor_power@1", req "motor_power" -> Ack);

/// Sets the odometric pose.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct SetOdom {
    /// The new odometric pose.
    pub pose: Pose2d,
}
message!(SetOdom, "position2d/set_odom@1", req "set_odom" -> Ack);

/// Resets odometry to the origin.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct ResetOdom;
message!(ResetOdom, "position2d/reset_odom@1", req "reset_odom" -> Ack);

/// Chooses the velocity control mode (driver-specific, as in Player).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct VelocityMode {
    /// Driver-specific mode number.
    pub value: u32,
}
message!(VelocityMode, "position2d/velocity_mode@1", req "velocity_mode" -> Ack);

/// Chooses velocity (false) or position (true) control.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct PositionMode {
    /// True = position control.
    pub state: bool,
}
message!(PositionMode, "position2d/position_mode@1", req "position_mode" -> Ack);
