//! Robot parameters by P2OS subclass (Player's `robot_params`): the
//! conversion factors, sonar ring and footprint the driver needs.

/// One robot type.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Params {
    /// The subclass string the robot reports in its SYNC2 reply.
    pub subclass: &'static str,
    /// Radians per heading unit.
    pub angle_conv: f64,
    /// mm per position unit.
    pub dist_conv: f64,
    /// mm/s per wheel velocity unit.
    pub vel_conv: f64,
    /// mm per sonar range unit.
    pub range_conv: f64,
    /// Wheel-speed difference (mm/s) to rotation (rad/s): rot = diff · conv / 2.
    pub diff_conv: f64,
    /// mm/s per VEL2 unit.
    pub vel2_div: f64,
    /// Sonars: x mm, y mm, heading degrees, in SIP index order.
    pub sonars: &'static [(i16, i16, i16)],
    /// Front bumper segments.
    pub front_bumpers: u8,
    /// Rear bumper segments.
    pub rear_bumpers: u8,
    /// Width, mm.
    pub width: f64,
    /// Length, mm.
    pub length: f64,
}

const P2DX_SONARS: [(i16, i16, i16); 16] = [
    (69, 136, 90),
    (114, 119, 50),
    (148, 78, 30),
    (166, 27, 10),
    (166, -27, -10),
    (148, -78, -30),
    (114, -119, -50),
    (69, -136, -90),
    (-157, -136, -90),
    (-203, -119, -130),
    (-237, -78, -150),
    (-255, -27, -170),
    (-255, 27, 170),
    (-237, 78, 150),
    (-203, 119, 130),
    (-157, 136, 90),
];

const P3AT_SONARS: [(i16, i16, i16); 16] = [
    (147, 136, 90),
    (193, 119, 50),
    (227, 79, 30),
    (245, 27, 10),
    (245, -27, -10),
    (227, -79, -30),
    (193, -119, -50),
    (147, -136, -90),
    (-144, -136, -90),
    (-189, -119, -130),
    (-223, -79, -150),
    (-241, -27, -170),
    (-241, 27, 170),
    (-223, 79, 150),
    (-189, 119, 130),
    (-144, 136, 90),
];

const AMIGO_SONARS: [(i16, i16, i16); 8] = [
    (70, 100, 90),
    (125, 75, 41),
    (144, 30, 15),
    (144, -30, -15),
    (120, -75, -41),
    (70, -100, -90),
    (-146, -58, -145),
    (-146, 58, 145),
];

/// What every Pioneer of the table shares.
const PIONEER: Params = Params {
    subclass: "",
    angle_conv: 0.001534,
    dist_conv: 1.0,
    vel_conv: 1.0,
    range_conv: 1.0,
    diff_conv: 0.0056,
    vel2_div: 20.0,
    sonars: &P2DX_SONARS,
    front_bumpers: 5,
    rear_bumpers: 5,
    width: 425.0,
    length: 511.0,
};

const AMIGO: Params = Params {
    diff_conv: 0.011,
    sonars: &AMIGO_SONARS,
    width: 279.0,
    length: 330.0,
    ..PIONEER
};

const AT: Params = Params {
    diff_conv: 0.0034,
    sonars: &P3AT_SONARS,
    width: 505.0,
    length: 626.0,
    ..PIONEER
};

/// The robots this driver knows; the first is Player's fallback for an
/// unknown subclass.
pub const ROBOTS: [Params; 9] = [
    Params {
        subclass: "amigo-sh",
        ..AMIGO
    },
    Params {
        subclass: "amigo",
        dist_conv: 0.5083,
        vel_conv: 0.6154,
        ..AMIGO
    },
    Params {
        subclass: "p2at",
        dist_conv: 1.32,
        range_conv: 0.268,
        ..AT
    },
    Params {
        subclass: "p2de",
        dist_conv: 0.969,
        range_conv: 0.268,
        ..PIONEER
    },
    Params {
        subclass: "p2dx",
        dist_conv: 0.84,
        range_conv: 0.268,
        ..PIONEER
    },
    Params {
        subclass: "p3at-sh",
        ..AT
    },
    Params {
        subclass: "p3at",
        dist_conv: 0.465,
        ..AT
    },
    Params {
        subclass: "p3dx-sh",
        ..PIONEER
    },
    Params {
        subclass: "p3dx",
        dist_conv: 0.485,
        ..PIONEER
    },
];

/// The parameters of `subclass` (case-insensitive), or `None`.
pub fn find(subclass: &str) -> Option<&'static Params> {
    ROBOTS
        .iter()
        .find(|p| p.subclass.eq_ignore_ascii_case(subclass))
}
