//! Replies shared by every interface.

use serde::{Deserialize, Serialize};

use crate::message;

/// Player's RESP_ACK with an empty body.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Ack;
message!(Ack, "ack@1");

/// Player's RESP_NACK, with the reason Player could only log.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Nack {
    /// Why the device refused, for a human.
    pub reason: String,
}
message!(Nack, "nack@1");

/// Switches a device's power (Player's `*_REQ_POWER`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Power {
    /// On (true) or off.
    pub state: bool,
}
message!(Power, "common/power@1", req "power" -> Ack);
