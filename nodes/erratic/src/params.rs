//! The Erratic's revisions (Player's `robot_params` for the erratic driver).

/// One revision.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Params {
    /// The subtype string in the configuration reply.
    pub subtype: &'static str,
    /// mm per position tick.
    pub dist_conv: f64,
    /// Sonars: x m, y m, heading degrees, by channel.
    pub sonars: &'static [(f64, f64, f64); 8],
}

/// mm/s per wheel velocity unit.
pub const VEL_CONV: f64 = 1.20482;
/// Wheel-speed difference (mm/s) to rotation (rad/s): rot = diff · DIFF_CONV / 2.
/// Player's table says 0.011 and its driver scales the measured rate by
/// 0.596; the product is used both ways here, so commanded and reported
/// turn rates agree.
pub const DIFF_CONV: f64 = 0.011 * 0.596;
/// mm/s per VEL2 unit.
pub const VEL2_DIV: f64 = 20.0;
/// Length and width, m.
pub const SIZE: (f64, f64) = (0.392, 0.415);
/// The axle is this far ahead of the centre, m.
pub const AXLE_OFFSET: f64 = 0.061;
/// The two floor-facing IR sensors: x, y in m.
pub const IR_POSES: [(f64, f64); 2] = [(0.1, 0.1), (0.1, -0.1)];
/// Volts per ADC count (10 bits over 3.5 V).
pub const ADC_VOLTS: f64 = 3.5 / 1024.0;

const SONARS_E: [(f64, f64, f64); 8] = [
    (0.180, 0.110, 90.0),
    (0.200, 0.085, 0.0),
    (0.190, 0.065, -53.0),
    (0.170, 0.045, -24.0),
    (0.180, -0.110, -90.0),
    (0.200, -0.085, 0.0),
    (0.190, -0.065, 53.0),
    (0.170, -0.045, 24.0),
];

const SONARS_GH: [(f64, f64, f64); 8] = [
    (0.180, 0.120, 90.0),
    (0.200, 0.100, 53.0),
    (0.205, 0.065, 24.0),
    (0.210, 0.045, 0.0),
    (0.210, -0.045, 0.0),
    (0.205, -0.065, -24.0),
    (0.200, -0.100, -53.0),
    (0.180, -0.120, -90.0),
];

/// Rev E, Rev G and Rev H; Rev E is Player's choice for anything else.
pub const REVISIONS: [Params; 3] = [
    Params {
        subtype: "Rev E",
        dist_conv: 0.780,
        sonars: &SONARS_E,
    },
    Params {
        subtype: "Rev G",
        dist_conv: 0.780,
        sonars: &SONARS_GH,
    },
    Params {
        subtype: "Rev H",
        dist_conv: 0.930,
        sonars: &SONARS_GH,
    },
];

/// The revision named `subtype`, if known.
pub fn find(subtype: &str) -> Option<&'static Params> {
    REVISIONS.iter().find(|p| p.subtype == subtype)
}
