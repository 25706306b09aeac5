//! `aio`: analog inputs and outputs.

use serde::{Deserialize, Serialize};

use crate::message;

/// Analog inputs, volts.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Data {
    /// Volts, one per input.
    pub voltages: Vec<f32>,
}
message!(Data, "aio/data@1");

/// Sets analog output `id`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Cmd {
    /// Output number.
    pub id: u32,
    /// Volts.
    pub voltage: f32,
}
message!(Cmd, "aio/cmd@1", cmd "state");
