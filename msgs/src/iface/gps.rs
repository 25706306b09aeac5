//! `gps`: a global position fix, as a GPS receiver reports it.

use serde::{Deserialize, Serialize};

use crate::message;

/// A fix (`PLAYER_GPS_DATA_STATE`). Player carries latitude and longitude
/// in 1e-7 degrees, altitude in millimetres and the dilutions times ten;
/// here they are degrees, metres and the dilutions themselves.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Data {
    /// GPS (UTC) time, seconds since the epoch.
    pub time: f64,
    /// Degrees, positive north of the equator.
    pub latitude: f64,
    /// Degrees, positive east of the prime meridian.
    pub longitude: f64,
    /// Metres above the reference (e.g. sea level).
    pub altitude: f64,
    /// Speed over ground, m/s.
    pub speed: f64,
    /// Course made good, radians.
    pub course: f64,
    /// UTM (WGS84) easting, metres.
    pub utm_e: f64,
    /// UTM (WGS84) northing, metres.
    pub utm_n: f64,
    /// Quality of the fix: 0 invalid, 1 GPS, 2 DGPS.
    pub quality: u32,
    /// Satellites in view.
    pub num_sats: u32,
    /// Horizontal dilution of position.
    pub hdop: f64,
    /// Vertical dilution of position.
    pub vdop: f64,
    /// Horizontal error, metres.
    pub err_horz: f64,
    /// Vertical error, metres.
    pub err_vert: f64,
}
message!(Data, "gps/data@1");
