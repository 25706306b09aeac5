//! `power`: battery state.

use serde::{Deserialize, Serialize};

use crate::message;

/// [`Data::valid`]: `volts` is set.
pub const VALID_VOLTS: u32 = 1;
/// [`Data::valid`]: `watts` is set.
pub const VALID_WATTS: u32 = 2;
/// [`Data::valid`]: `joules` is set.
pub const VALID_JOULES: u32 = 4;
/// [`Data::valid`]: `percent` is set.
pub const VALID_PERCENT: u32 = 8;
/// [`Data::valid`]: `charging` is set.
pub const VALID_CHARGING: u32 = 16;

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

impl Data {
    /// A battery at `volts`, its charge given as a share of `nominal` volts
    /// (how Player's robot drivers fill it in).
    pub fn battery(volts: f32, nominal: f32) -> Data {
        Data {
            valid: VALID_VOLTS | VALID_PERCENT,
            volts,
            percent: 100.0 * volts / nominal,
            ..Default::default()
        }
    }
}
message!(Data, "power/data@1");
