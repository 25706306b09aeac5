//! `dio`: digital inputs and outputs.

use serde::{Deserialize, Serialize};

use crate::message;

/// Digital inputs.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Data {
    /// Number of valid bits.
    pub count: u32,
    /// Bit i = input i.
    pub bits: u32,
}
message!(Data, "dio/data@1");

/// Sets the digital outputs.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Cmd {
    /// Number of outputs to set.
    pub count: u32,
    /// Bit i = output i.
    pub bits: u32,
}
message!(Cmd, "dio/cmd@1", cmd "values");
