//! Player's protocol numbers, each named once: the message types of
//! `libplayerinterface/player.h` and each interface's message subtypes, as
//! its `libplayerinterface/interfaces/NNN_<name>.def` declares them
//! (`message { DATA, SCAN, 1, ... }` is `laser::DATA_SCAN`). The bridge's
//! codec and the Player log reader and writer both use these; interface
//! codes are [`crate::Interface::code`].

/// `PLAYER_MSGTYPE_DATA`: a device's data.
pub const DATA: u8 = 1;
/// `PLAYER_MSGTYPE_CMD`: a command to a device.
pub const CMD: u8 = 2;
/// `PLAYER_MSGTYPE_REQ`: a request.
pub const REQ: u8 = 3;
/// `PLAYER_MSGTYPE_RESP_ACK`: a request's positive answer.
pub const RESP_ACK: u8 = 4;
/// `PLAYER_MSGTYPE_SYNCH`: the end of a PULL round.
pub const SYNCH: u8 = 5;
/// `PLAYER_MSGTYPE_RESP_NACK`: a request refused.
pub const RESP_NACK: u8 = 6;

/// `player`: `interfaces/001_player.def`.
pub mod player {
    /// `PLAYER_PLAYER_REQ_DEVLIST`.
    pub const REQ_DEVLIST: u8 = 1;
    /// `PLAYER_PLAYER_REQ_DRIVERINFO`.
    pub const REQ_DRIVERINFO: u8 = 2;
    /// `PLAYER_PLAYER_REQ_DEV`.
    pub const REQ_DEV: u8 = 3;
    /// `PLAYER_PLAYER_REQ_DATA`.
    pub const REQ_DATA: u8 = 4;
    /// `PLAYER_PLAYER_REQ_DATAMODE`.
    pub const REQ_DATAMODE: u8 = 5;
    /// `PLAYER_PLAYER_REQ_AUTH`.
    pub const REQ_AUTH: u8 = 7;
    /// `PLAYER_PLAYER_REQ_NAMESERVICE`.
    pub const REQ_NAMESERVICE: u8 = 8;
    /// `PLAYER_PLAYER_REQ_ADD_REPLACE_RULE`.
    pub const REQ_ADD_REPLACE_RULE: u8 = 10;
    /// `PLAYER_PLAYER_SYNCH_OK`.
    pub const SYNCH_OK: u8 = 1;
    /// `PLAYER_PLAYER_SYNCH_OVERFLOW`.
    pub const SYNCH_OVERFLOW: u8 = 2;
}

/// `power`: `interfaces/002_power.def`.
pub mod power {
    /// `PLAYER_POWER_DATA_STATE`.
    pub const DATA_STATE: u8 = 1;
    /// `PLAYER_POWER_REQ_SET_CHARGING_POLICY`.
    pub const REQ_SET_CHARGING_POLICY: u8 = 1;
}

/// `gripper`: `interfaces/003_gripper.def`.
pub mod gripper {
    /// `PLAYER_GRIPPER_DATA_STATE`.
    pub const DATA_STATE: u8 = 1;
    /// `PLAYER_GRIPPER_REQ_GET_GEOM`.
    pub const REQ_GET_GEOM: u8 = 1;
    /// `PLAYER_GRIPPER_CMD_OPEN`.
    pub const CMD_OPEN: u8 = 1;
    /// `PLAYER_GRIPPER_CMD_CLOSE`.
    pub const CMD_CLOSE: u8 = 2;
    /// `PLAYER_GRIPPER_CMD_STOP`.
    pub const CMD_STOP: u8 = 3;
    /// `PLAYER_GRIPPER_CMD_STORE`.
    pub const CMD_STORE: u8 = 4;
    /// `PLAYER_GRIPPER_CMD_RETRIEVE`.
    pub const CMD_RETRIEVE: u8 = 5;
}

/// `position2d`: `interfaces/004_position2d.def`.
pub mod position2d {
    /// `PLAYER_POSITION2D_REQ_GET_GEOM`.
    pub const REQ_GET_GEOM: u8 = 1;
    /// `PLAYER_POSITION2D_REQ_MOTOR_POWER`.
    pub const REQ_MOTOR_POWER: u8 = 2;
    /// `PLAYER_POSITION2D_REQ_VELOCITY_MODE`.
    pub const REQ_VELOCITY_MODE: u8 = 3;
    /// `PLAYER_POSITION2D_REQ_POSITION_MODE`.
    pub const REQ_POSITION_MODE: u8 = 4;
    /// `PLAYER_POSITION2D_REQ_SET_ODOM`.
    pub const REQ_SET_ODOM: u8 = 5;
    /// `PLAYER_POSITION2D_REQ_RESET_ODOM`.
    pub const REQ_RESET_ODOM: u8 = 6;
    /// `PLAYER_POSITION2D_REQ_SPEED_PID`.
    pub const REQ_SPEED_PID: u8 = 7;
    /// `PLAYER_POSITION2D_REQ_POSITION_PID`.
    pub const REQ_POSITION_PID: u8 = 8;
    /// `PLAYER_POSITION2D_REQ_SPEED_PROF`.
    pub const REQ_SPEED_PROF: u8 = 9;
    /// `PLAYER_POSITION2D_DATA_STATE`.
    pub const DATA_STATE: u8 = 1;
    /// `PLAYER_POSITION2D_DATA_GEOM`.
    pub const DATA_GEOM: u8 = 2;
    /// `PLAYER_POSITION2D_CMD_VEL`.
    pub const CMD_VEL: u8 = 1;
    /// `PLAYER_POSITION2D_CMD_POS`.
    pub const CMD_POS: u8 = 2;
    /// `PLAYER_POSITION2D_CMD_CAR`.
    pub const CMD_CAR: u8 = 3;
    /// `PLAYER_POSITION2D_CMD_VEL_HEAD`.
    pub const CMD_VEL_HEAD: u8 = 4;
}

/// `sonar`: `interfaces/005_sonar.def`.
pub mod sonar {
    /// `PLAYER_SONAR_REQ_GET_GEOM`.
    pub const REQ_GET_GEOM: u8 = 1;
    /// `PLAYER_SONAR_REQ_POWER`.
    pub const REQ_POWER: u8 = 2;
    /// `PLAYER_SONAR_DATA_RANGES`.
    pub const DATA_RANGES: u8 = 1;
    /// `PLAYER_SONAR_DATA_GEOM`.
    pub const DATA_GEOM: u8 = 2;
}

/// `laser`: `interfaces/006_laser.def`.
pub mod laser {
    /// `PLAYER_LASER_DATA_SCAN`.
    pub const DATA_SCAN: u8 = 1;
    /// `PLAYER_LASER_DATA_SCANPOSE`.
    pub const DATA_SCANPOSE: u8 = 2;
    /// `PLAYER_LASER_DATA_SCANANGLE`.
    pub const DATA_SCANANGLE: u8 = 3;
    /// `PLAYER_LASER_REQ_GET_GEOM`.
    pub const REQ_GET_GEOM: u8 = 1;
    /// `PLAYER_LASER_REQ_SET_CONFIG`.
    pub const REQ_SET_CONFIG: u8 = 2;
    /// `PLAYER_LASER_REQ_GET_CONFIG`.
    pub const REQ_GET_CONFIG: u8 = 3;
    /// `PLAYER_LASER_REQ_POWER`.
    pub const REQ_POWER: u8 = 4;
    /// `PLAYER_LASER_REQ_GET_ID`.
    pub const REQ_GET_ID: u8 = 5;
    /// `PLAYER_LASER_REQ_SET_FILTER`.
    pub const REQ_SET_FILTER: u8 = 6;
}

/// `blobfinder`: `interfaces/007_blobfinder.def`.
pub mod blobfinder {
    /// `PLAYER_BLOBFINDER_DATA_BLOBS`.
    pub const DATA_BLOBS: u8 = 1;
    /// `PLAYER_BLOBFINDER_REQ_SET_COLOR`.
    pub const REQ_SET_COLOR: u8 = 1;
    /// `PLAYER_BLOBFINDER_REQ_SET_IMAGER_PARAMS`.
    pub const REQ_SET_IMAGER_PARAMS: u8 = 2;
    /// `PLAYER_BLOBFINDER_REQ_GET_COLOR`.
    pub const REQ_GET_COLOR: u8 = 3;
}

/// `ptz`: `interfaces/008_ptz.def`.
pub mod ptz {
    /// `PLAYER_PTZ_REQ_GENERIC`.
    pub const REQ_GENERIC: u8 = 1;
    /// `PLAYER_PTZ_REQ_CONTROL_MODE`.
    pub const REQ_CONTROL_MODE: u8 = 2;
    /// `PLAYER_PTZ_REQ_GEOM`.
    pub const REQ_GEOM: u8 = 4;
    /// `PLAYER_PTZ_REQ_STATUS`.
    pub const REQ_STATUS: u8 = 5;
    /// `PLAYER_PTZ_DATA_STATE`.
    pub const DATA_STATE: u8 = 1;
    /// `PLAYER_PTZ_DATA_GEOM`.
    pub const DATA_GEOM: u8 = 2;
    /// `PLAYER_PTZ_CMD_STATE`.
    pub const CMD_STATE: u8 = 1;
}

/// `fiducial`: `interfaces/010_fiducial.def`.
pub mod fiducial {
    /// `PLAYER_FIDUCIAL_DATA_SCAN`.
    pub const DATA_SCAN: u8 = 1;
    /// `PLAYER_FIDUCIAL_REQ_GET_GEOM`.
    pub const REQ_GET_GEOM: u8 = 1;
    /// `PLAYER_FIDUCIAL_REQ_GET_FOV`.
    pub const REQ_GET_FOV: u8 = 2;
    /// `PLAYER_FIDUCIAL_REQ_SET_FOV`.
    pub const REQ_SET_FOV: u8 = 3;
    /// `PLAYER_FIDUCIAL_REQ_GET_ID`.
    pub const REQ_GET_ID: u8 = 7;
    /// `PLAYER_FIDUCIAL_REQ_SET_ID`.
    pub const REQ_SET_ID: u8 = 8;
}

/// `gps`: `interfaces/013_gps.def`.
pub mod gps {
    /// `PLAYER_GPS_DATA_STATE`.
    pub const DATA_STATE: u8 = 1;
}

/// `bumper`: `interfaces/014_bumper.def`.
pub mod bumper {
    /// `PLAYER_BUMPER_DATA_STATE`.
    pub const DATA_STATE: u8 = 1;
    /// `PLAYER_BUMPER_DATA_GEOM`.
    pub const DATA_GEOM: u8 = 2;
    /// `PLAYER_BUMPER_REQ_GET_GEOM`.
    pub const REQ_GET_GEOM: u8 = 1;
}

/// `dio`: `interfaces/020_dio.def`.
pub mod dio {
    /// `PLAYER_DIO_DATA_VALUES`.
    pub const DATA_VALUES: u8 = 1;
    /// `PLAYER_DIO_CMD_VALUES`.
    pub const CMD_VALUES: u8 = 1;
}

/// `aio`: `interfaces/021_aio.def`.
pub mod aio {
    /// `PLAYER_AIO_CMD_STATE`.
    pub const CMD_STATE: u8 = 1;
    /// `PLAYER_AIO_DATA_STATE`.
    pub const DATA_STATE: u8 = 1;
}

/// `ir`: `interfaces/022_ir.def`.
pub mod ir {
    /// `PLAYER_IR_REQ_POSE`.
    pub const REQ_POSE: u8 = 1;
    /// `PLAYER_IR_REQ_POWER`.
    pub const REQ_POWER: u8 = 2;
    /// `PLAYER_IR_DATA_RANGES`.
    pub const DATA_RANGES: u8 = 1;
}

/// `localize`: `interfaces/025_localize.def`.
pub mod localize {
    /// `PLAYER_LOCALIZE_DATA_HYPOTHS`.
    pub const DATA_HYPOTHS: u8 = 1;
    /// `PLAYER_LOCALIZE_REQ_SET_POSE`.
    pub const REQ_SET_POSE: u8 = 1;
    /// `PLAYER_LOCALIZE_REQ_GET_PARTICLES`.
    pub const REQ_GET_PARTICLES: u8 = 2;
}

/// `simulation`: `interfaces/031_simulation.def`.
pub mod simulation {
    /// `PLAYER_SIMULATION_REQ_GET_POSE2D`.
    pub const REQ_GET_POSE2D: u8 = 1;
    /// `PLAYER_SIMULATION_REQ_SET_POSE2D`.
    pub const REQ_SET_POSE2D: u8 = 2;
    /// `PLAYER_SIMULATION_REQ_GET_POSE3D`.
    pub const REQ_GET_POSE3D: u8 = 3;
    /// `PLAYER_SIMULATION_REQ_SET_POSE3D`.
    pub const REQ_SET_POSE3D: u8 = 4;
    /// `PLAYER_SIMULATION_REQ_GET_PROPERTY`.
    pub const REQ_GET_PROPERTY: u8 = 5;
    /// `PLAYER_SIMULATION_REQ_SET_PROPERTY`.
    pub const REQ_SET_PROPERTY: u8 = 6;
    /// `PLAYER_SIMULATION_CMD_PAUSE`.
    pub const CMD_PAUSE: u8 = 1;
    /// `PLAYER_SIMULATION_CMD_RESET`.
    pub const CMD_RESET: u8 = 2;
    /// `PLAYER_SIMULATION_CMD_SAVE`.
    pub const CMD_SAVE: u8 = 3;
}

/// `camera`: `interfaces/040_camera.def`.
pub mod camera {
    /// `PLAYER_CAMERA_DATA_STATE`.
    pub const DATA_STATE: u8 = 1;
    /// `PLAYER_CAMERA_REQ_GET_SOURCE`.
    pub const REQ_GET_SOURCE: u8 = 1;
    /// `PLAYER_CAMERA_REQ_SET_SOURCE`.
    pub const REQ_SET_SOURCE: u8 = 2;
    /// `PLAYER_CAMERA_REQ_GET_IMAGE`.
    pub const REQ_GET_IMAGE: u8 = 3;
}

/// `map`: `interfaces/042_map.def`.
pub mod map {
    /// `PLAYER_MAP_DATA_INFO`.
    pub const DATA_INFO: u8 = 1;
    /// `PLAYER_MAP_REQ_GET_INFO`.
    pub const REQ_GET_INFO: u8 = 1;
    /// `PLAYER_MAP_REQ_GET_DATA`.
    pub const REQ_GET_DATA: u8 = 2;
    /// `PLAYER_MAP_REQ_GET_VECTOR`.
    pub const REQ_GET_VECTOR: u8 = 3;
}

/// `planner`: `interfaces/044_planner.def`.
pub mod planner {
    /// `PLAYER_PLANNER_DATA_STATE`.
    pub const DATA_STATE: u8 = 1;
    /// `PLAYER_PLANNER_CMD_GOAL`.
    pub const CMD_GOAL: u8 = 1;
    /// `PLAYER_PLANNER_CMD_START`.
    pub const CMD_START: u8 = 2;
    /// `PLAYER_PLANNER_REQ_GET_WAYPOINTS`.
    pub const REQ_GET_WAYPOINTS: u8 = 1;
    /// `PLAYER_PLANNER_REQ_ENABLE`.
    pub const REQ_ENABLE: u8 = 2;
}

/// `log`: `interfaces/045_log.def`.
pub mod log {
    /// `PLAYER_LOG_REQ_SET_WRITE_STATE`.
    pub const REQ_SET_WRITE_STATE: u8 = 1;
    /// `PLAYER_LOG_REQ_SET_READ_STATE`.
    pub const REQ_SET_READ_STATE: u8 = 2;
    /// `PLAYER_LOG_REQ_GET_STATE`.
    pub const REQ_GET_STATE: u8 = 3;
    /// `PLAYER_LOG_REQ_SET_READ_REWIND`.
    pub const REQ_SET_READ_REWIND: u8 = 4;
    /// `PLAYER_LOG_REQ_SET_FILENAME`.
    pub const REQ_SET_FILENAME: u8 = 5;
}

/// `wsn`: `interfaces/057_wsn.def`.
pub mod wsn {
    /// `PLAYER_WSN_DATA_STATE`.
    pub const DATA_STATE: u8 = 1;
    /// `PLAYER_WSN_CMD_DEVSTATE`.
    pub const CMD_DEVSTATE: u8 = 1;
    /// `PLAYER_WSN_REQ_POWER`.
    pub const REQ_POWER: u8 = 1;
    /// `PLAYER_WSN_REQ_DATATYPE`.
    pub const REQ_DATATYPE: u8 = 2;
    /// `PLAYER_WSN_REQ_DATAFREQ`.
    pub const REQ_DATAFREQ: u8 = 3;
}

/// `ranger`: `interfaces/062_ranger.def`.
pub mod ranger {
    /// `PLAYER_RANGER_DATA_RANGE`.
    pub const DATA_RANGE: u8 = 1;
    /// `PLAYER_RANGER_DATA_RANGESTAMPED`.
    pub const DATA_RANGESTAMPED: u8 = 2;
    /// `PLAYER_RANGER_DATA_INTNS`.
    pub const DATA_INTNS: u8 = 3;
    /// `PLAYER_RANGER_DATA_INTNSSTAMPED`.
    pub const DATA_INTNSSTAMPED: u8 = 4;
    /// `PLAYER_RANGER_DATA_GEOM`.
    pub const DATA_GEOM: u8 = 5;
    /// `PLAYER_RANGER_REQ_GET_GEOM`.
    pub const REQ_GET_GEOM: u8 = 1;
    /// `PLAYER_RANGER_REQ_POWER`.
    pub const REQ_POWER: u8 = 2;
    /// `PLAYER_RANGER_REQ_INTNS`.
    pub const REQ_INTNS: u8 = 3;
    /// `PLAYER_RANGER_REQ_SET_CONFIG`.
    pub const REQ_SET_CONFIG: u8 = 4;
    /// `PLAYER_RANGER_REQ_GET_CONFIG`.
    pub const REQ_GET_CONFIG: u8 = 5;
}
