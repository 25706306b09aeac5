//! `power`: battery state.

use serde::{Deserialize, Serialize};

use crate::message;

/// Battery state (`PLAYER_POWER_DATA_STATE`); `valid` says which fields are set.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Data {
    /// Bitmask of valid fields: 1 volts, 2 watts, 4 joules, 8 percent, 16 charging.
    pub valid: u32,
    /// Volts.
    pub volts: f32,
    /// Percent of full charge.
    pub percent: f32,
    /// Joules left.
    pub joules: f32,
    /// Watts drawn.
    pub watts: f32,
    /// Charging.
    pub charging: bool,
}
message!(Data, "power/data@1");
