//! `log`: starts, stops and rewinds a log being written (`writelog`) or
//! read back (`readlog`).

use serde::{Deserialize, Serialize};

use crate::iface::common::Ack;
use crate::message;

/// Starts (`true`) or stops writing (`PLAYER_LOG_REQ_SET_WRITE_STATE`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SetWriteState {
    /// Write or not.
    pub state: bool,
}
message!(SetWriteState, "log/set_write_state@1", req "set_write_state" -> Ack);

/// Starts (`true`) or pauses playback (`PLAYER_LOG_REQ_SET_READ_STATE`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SetReadState {
    /// Play or not.
    pub state: bool,
}
message!(SetReadState, "log/set_read_state@1", req "set_read_state" -> Ack);

/// What a log device is and whether it runs (`player_log_get_state_t`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct State {
    /// [`TYPE_READ`] or [`TYPE_WRITE`].
    pub kind: u8,
    /// Playing or writing.
    pub state: bool,
}
message!(State, "log/state@1");

/// A device that reads a log back (`PLAYER_LOG_TYPE_READ`).
pub const TYPE_READ: u8 = 1;
/// A device that writes a log (`PLAYER_LOG_TYPE_WRITE`).
pub const TYPE_WRITE: u8 = 2;

/// Asks for the [`State`] (`PLAYER_LOG_REQ_GET_STATE`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct GetState;
message!(GetState, "log/get_state@1", req "get_state" -> State);

/// Goes back to the log's start, playing or not as before
/// (`PLAYER_LOG_REQ_SET_READ_REWIND`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Rewind;
message!(Rewind, "log/rewind@1", req "rewind" -> Ack);

/// Closes the log being written and opens this file instead; refused while
/// writing (`PLAYER_LOG_REQ_SET_FILENAME`).
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SetFilename {
    /// The new file.
    pub filename: String,
}
message!(SetFilename, "log/set_filename@1", req "set_filename" -> Ack);
