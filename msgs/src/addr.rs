//! Player device addresses: `key:host:robot:interface:index`.
//!
//! Player names a device with up to five colon-separated fields, the leading
//! ones optional. [`DevAddr`] is such an address exactly as written in a `.cfg`
//! file (fields may be absent); [`Device`] is the concrete device once the robot
//! field has been filled in, and is what keys are built from.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

/// The robot field Player uses when none is given: the default TCP port.
pub const DEFAULT_ROBOT: u32 = 6665;

macro_rules! interfaces {
    ($( $variant:ident = $code:literal, $name:literal; )*) => {
        /// A Player interface, with Player's numeric code and name.
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub enum Interface {
            $(
                #[doc = concat!("`", $name, "` (Player code ", stringify!($code), ")")]
                $variant,
            )*
        }

        impl Interface {
            /// Every interface Player 3 defines, in code order.
            pub const ALL: &'static [Interface] = &[$(Interface::$variant,)*];

            /// Player's numeric interface code (`PLAYER_*_CODE`).
            pub const fn code(self) -> u16 {
                match self { $(Interface::$variant => $code,)* }
            }

            /// Player's interface name, as written in `.cfg` files and used in keys.
            pub const fn name(self) -> &'static str {
                match self { $(Interface::$variant => $name,)* }
            }

            /// The interface with Player's code `code`, if Player defines one.
            pub fn from_code(code: u16) -> Option<Interface> {
                match code { $($code => Some(Interface::$variant),)* _ => None }
            }

            /// The interface called `name` (exact, as Player's `lookup_interface`).
            pub fn from_name(name: &str) -> Option<Interface> {
                match name { $($name => Some(Interface::$variant),)* _ => None }
            }
        }
    };
}

interfaces! {
    Player = 1, "player";
    Power = 2, "power";
    Gripper = 3, "gripper";
    Position2d = 4, "position2d";
    Sonar = 5, "sonar";
    Laser = 6, "laser";
    Blobfinder = 7, "blobfinder";
    Ptz = 8, "ptz";
    Audio = 9, "audio";
    Fiducial = 10, "fiducial";
    Speech = 12, "speech";
    Gps = 13, "gps";
    Bumper = 14, "bumper";
    Dio = 20, "dio";
    Aio = 21, "aio";
    Ir = 22, "ir";
    Wifi = 23, "wifi";
    Localize = 25, "localize";
    Position3d = 30, "position3d";
    Simulation = 31, "simulation";
    Blinkenlight = 33, "blinkenlight";
    Camera = 40, "camera";
    Map = 42, "map";
    Planner = 44, "planner";
    Log = 45, "log";
    Joystick = 49, "joystick";
    SpeechRecognition = 50, "speech_recognition";
    Opaque = 51, "opaque";
    Position1d = 52, "position1d";
    Actarray = 53, "actarray";
    Limb = 54, "limb";
    Graphics2d = 55, "graphics2d";
    Rfid = 56, "rfid";
    Wsn = 57, "wsn";
    Graphics3d = 58, "graphics3d";
    Health = 59, "health";
    Imu = 60, "imu";
    Pointcloud3d = 61, "pointcloud3d";
    Ranger = 62, "ranger";
    Vectormap = 63, "vectormap";
    Blackboard = 64, "blackboard";
    Stereo = 65, "stereo";
    Coopobject = 66, "coopobject";
}

impl fmt::Display for Interface {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Interface {
    type Err = AddrError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Interface::from_name(s).ok_or_else(|| AddrError::UnknownInterface {
            text: s.to_owned(),
            hint: interface_hint(s),
        })
    }
}

/// Player 2 interface names that Player 3 renamed: the new name, and
/// whether the old one means the same thing (so an address can be read
/// with the new name) or only something close.
fn renamed(s: &str) -> Option<(&'static str, bool)> {
    match s {
        "position" => Some(("position2d", true)),
        "sound" => Some(("audio", true)),
        "truth" => Some(("simulation", false)),
        "laser3d" | "pointcloud" => Some(("pointcloud3d", false)),
        _ => None,
    }
}

/// `text` with a Player 2 interface name that Player 3 only renamed
/// (`sound:0`, `position:1`) spelled the Player 3 way (`audio:0`), or
/// `None` when there is nothing to rename. Player's own sample cfgs still
/// carry such names; a translator reads them this way, with a warning.
pub fn player3_spelling(text: &str) -> Option<String> {
    let mut fields: Vec<&str> = text.split(':').collect();
    let n = fields.len();
    let interface = fields.get_mut(n.checked_sub(2)?)?;
    let (new, same) = renamed(interface)?;
    if !same {
        return None;
    }
    *interface = new;
    Some(fields.join(":"))
}

/// Player 2 names that Player 3 renamed, so an old cfg gets a useful hint.
fn interface_hint(s: &str) -> String {
    if let Some((new, _)) = renamed(s) {
        return format!("`{s}` is a Player 2 interface; Player 3 calls it `{new}`");
    }
    let close: Vec<&str> = Interface::ALL
        .iter()
        .map(|i| i.name())
        .filter(|n| n.starts_with(&s[..s.len().min(3)]) && !s.is_empty())
        .collect();
    if close.is_empty() {
        "run `troupe interfaces` for the list".to_owned()
    } else {
        format!("did you mean {}?", close.join(" or "))
    }
}

/// An error in a device address or a key; every variant quotes the offending text.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AddrError {
    /// The address has no `interface:index` pair.
    #[error("device address `{text}` needs at least `interface:index` (e.g. `laser:0`)")]
    MissingInterface {
        /// The address as written.
        text: String,
    },
    /// The interface field names no Player interface.
    #[error("unknown interface `{text}`: {hint}")]
    UnknownInterface {
        /// The interface field as written.
        text: String,
        /// What the user probably meant.
        hint: String,
    },
    /// The index field is not a non-negative integer.
    #[error("device address `{text}`: index `{index}` is not a non-negative integer")]
    BadIndex {
        /// The address as written.
        text: String,
        /// The index field as written.
        index: String,
    },
    /// The robot (port) field is not an integer.
    #[error("device address `{text}`: robot `{robot}` is not a port number")]
    BadRobot {
        /// The address as written.
        text: String,
        /// The robot field as written.
        robot: String,
    },
    /// More fields than `key:host:robot:interface:index`.
    #[error("device address `{text}` has more than five fields (key:host:robot:interface:index)")]
    TooManyFields {
        /// The address as written.
        text: String,
    },
    /// A key expression that is not one of Troupe's device keys.
    #[error("`{text}` is not a device key (expected robot/<port>/<interface>/<index>{rest})")]
    NotADeviceKey {
        /// The key as given.
        text: String,
        /// What may follow the device part.
        rest: &'static str,
    },
}

/// A device address as written in a `.cfg` file or on a command line.
///
/// # Behavior
///
/// Fields are split from the right, as Player's `ConfigFile::ReadDeviceAddr`
/// does, so leading fields may be omitted: `laser:0`, `6665:laser:0`,
/// `host:6665:laser:0`, `key:host:robot:laser:0`. Empty fields are absent:
/// `odometry:::position2d:0`. One form is Player 2's and is read the way its
/// documentation meant it, not the way Player 3's parser reads it: in
/// `odometry::position2d:0` (four fields, the robot empty) the first field is
/// the key, not a host — Player 3 would try a DNS lookup of `odometry`.
///
/// # Example
///
/// ```
/// use troupe_msgs::{DevAddr, Interface};
/// let a: DevAddr = "odometry::6665:position2d:1".parse().unwrap();
/// assert_eq!(a.key.as_deref(), Some("odometry"));
/// assert_eq!(a.robot, Some(6665));
/// assert_eq!(a.interface, Interface::Position2d);
/// assert_eq!(a.to_string(), "odometry::6665:position2d:1");
/// ```
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct DevAddr {
    /// Role of the device for the driver that names it (`odometry`, `laser`, `input`…).
    pub key: Option<String>,
    /// Host field: where the providing node runs (not where data goes).
    pub host: Option<String>,
    /// Robot field (Player's TCP port); `None` means the cfg's default.
    pub robot: Option<u32>,
    /// The interface.
    pub interface: Interface,
    /// The index among devices of that interface on that robot.
    pub index: u32,
}

impl DevAddr {
    /// A bare `interface:index` address.
    pub fn new(interface: Interface, index: u32) -> Self {
        DevAddr {
            key: None,
            host: None,
            robot: None,
            interface,
            index,
        }
    }

    /// The concrete device, with `default_robot` where the robot field is absent.
    pub fn device(&self, default_robot: u32) -> Device {
        Device {
            robot: self.robot.unwrap_or(default_robot),
            interface: self.interface,
            index: self.index,
        }
    }
}

impl FromStr for DevAddr {
    type Err = AddrError;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let fields: Vec<&str> = text.rsplitn(6, ':').collect();
        if fields.len() > 5 {
            return Err(AddrError::TooManyFields {
                text: text.to_owned(),
            });
        }
        // rsplitn yields the rightmost field first.
        let (index, interface) = match (fields.first(), fields.get(1)) {
            (Some(i), Some(n)) if !n.is_empty() && !i.is_empty() => (*i, *n),
            _ => {
                return Err(AddrError::MissingInterface {
                    text: text.to_owned(),
                })
            }
        };
        let index: u32 = index.parse().map_err(|_| AddrError::BadIndex {
            text: text.to_owned(),
            index: index.to_owned(),
        })?;
        let interface: Interface = interface.parse()?;
        let opt = |s: Option<&&str>| s.filter(|s| !s.is_empty()).map(|s| (*s).to_owned());
        let (key, host, robot) = match fields.len() {
            2 => (None, None, None),
            3 => (None, None, opt(fields.get(2))),
            // `a::iface:i` is Player 2's keyed form; `host:robot:iface:i` otherwise.
            4 if fields[2].is_empty() => (opt(fields.get(3)), None, None),
            4 => (None, opt(fields.get(3)), opt(fields.get(2))),
            _ => (opt(fields.get(4)), opt(fields.get(3)), opt(fields.get(2))),
        };
        let robot = robot
            .map(|r| {
                r.parse::<u32>().map_err(|_| AddrError::BadRobot {
                    text: text.to_owned(),
                    robot: r.clone(),
                })
            })
            .transpose()?;
        Ok(DevAddr {
            key,
            host,
            robot,
            interface,
            index,
        })
    }
}

impl fmt::Display for DevAddr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let tail = format!("{}:{}", self.interface, self.index);
        let robot = self.robot.map(|r| r.to_string()).unwrap_or_default();
        let host = self.host.clone().unwrap_or_default();
        match (&self.key, self.host.is_some(), self.robot.is_some()) {
            (None, false, false) => write!(f, "{tail}"),
            (None, false, true) => write!(f, "{robot}:{tail}"),
            (None, true, _) => write!(f, "{host}:{robot}:{tail}"),
            (Some(k), _, _) => write!(f, "{k}:{host}:{robot}:{tail}"),
        }
    }
}

impl Serialize for DevAddr {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for DevAddr {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        s.parse().map_err(serde::de::Error::custom)
    }
}

/// A concrete device: robot (port), interface and index. Keys are built from it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Device {
    /// Robot id (Player's TCP port).
    pub robot: u32,
    /// The interface.
    pub interface: Interface,
    /// Index among devices of that interface on that robot.
    pub index: u32,
}

impl Device {
    /// The device `interface:index` on `robot`.
    pub const fn new(robot: u32, interface: Interface, index: u32) -> Self {
        Device {
            robot,
            interface,
            index,
        }
    }
}

impl fmt::Display for Device {
    /// `6665:laser:0`, a form [`DevAddr`] parses back.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}:{}", self.robot, self.interface, self.index)
    }
}

impl Serialize for Device {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for Device {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        let a: DevAddr = s.parse().map_err(serde::de::Error::custom)?;
        Ok(a.device(DEFAULT_ROBOT))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(s: &str) -> DevAddr {
        s.parse().unwrap()
    }

    #[test]
    fn player2_names_that_were_only_renamed_are_spelled_the_player3_way() {
        assert_eq!(player3_spelling("sound:0").as_deref(), Some("audio:0"));
        assert_eq!(
            player3_spelling("odometry:::position:0").as_deref(),
            Some("odometry:::position2d:0")
        );
        // `truth` became a different interface; nothing to rename in `laser`.
        assert_eq!(player3_spelling("truth:0"), None);
        assert_eq!(player3_spelling("laser:0"), None);
        assert_eq!(player3_spelling("sound"), None);
    }

    #[test]
    fn player_omission_rules() {
        assert_eq!(p("laser:0"), DevAddr::new(Interface::Laser, 0));
        let a = p("6665:laser:0");
        assert_eq!((a.robot, a.key, a.host), (Some(6665), None, None));
        let a = p("odometry::position2d:0");
        assert_eq!(a.key.as_deref(), Some("odometry"));
        assert_eq!((a.host, a.robot), (None, None));
        let a = p("odometry:::position2d:0");
        assert_eq!(a.key.as_deref(), Some("odometry"));
        assert_eq!((a.host, a.robot), (None, None));
        let a = p("input::6665:position2d:1");
        assert_eq!(a.key.as_deref(), Some("input"));
        assert_eq!(a.robot, Some(6665));
        assert_eq!(a.index, 1);
        let a = p("hostb:6666:ranger:2");
        assert_eq!((a.host.as_deref(), a.robot), (Some("hostb"), Some(6666)));
        let a = p("laser:hosta:7000:map:0");
        assert_eq!(a.key.as_deref(), Some("laser"));
        assert_eq!(a.host.as_deref(), Some("hosta"));
    }

    #[test]
    fn round_trips_through_display() {
        for s in [
            "laser:0",
            "6665:laser:0",
            "odometry:::position2d:0",
            "input::6665:position2d:1",
            "h:6666:ranger:2",
            "k:h:7:map:3",
        ] {
            assert_eq!(p(s).to_string(), s);
            assert_eq!(p(&p(s).to_string()), p(s));
        }
        // Player 2's keyed form prints in Player 3's spelling.
        assert_eq!(
            p("odometry::position2d:0").to_string(),
            "odometry:::position2d:0"
        );
    }

    #[test]
    fn malformed_addresses_quote_the_text() {
        let e = "laser:x".parse::<DevAddr>().unwrap_err();
        assert!(e.to_string().contains("`x`"), "{e}");
        let e = "::".parse::<DevAddr>().unwrap_err();
        assert!(matches!(e, AddrError::MissingInterface { .. }), "{e}");
        assert!(e.to_string().contains("`::`"));
        let e = "lazer:0".parse::<DevAddr>().unwrap_err();
        assert!(e.to_string().contains("`lazer`"), "{e}");
        let e = "position:0".parse::<DevAddr>().unwrap_err();
        assert!(e.to_string().contains("position2d"), "{e}");
        let e = "abc:laser:0".parse::<DevAddr>().unwrap_err();
        assert!(e.to_string().contains("`abc`"), "{e}");
        assert!("a:b:c:d:laser:0".parse::<DevAddr>().is_err());
        assert!("laser:".parse::<DevAddr>().is_err());
        assert!("".parse::<DevAddr>().is_err());
        assert!("laser:-1".parse::<DevAddr>().is_err());
    }

    #[test]
    fn interface_codes_match_player() {
        use Interface::*;
        for (i, c) in [
            (Position2d, 4),
            (Laser, 6),
            (Map, 42),
            (Planner, 44),
            (Ranger, 62),
            (Simulation, 31),
            (Localize, 25),
        ] {
            assert_eq!(i.code(), c);
            assert_eq!(Interface::from_code(c), Some(i));
            assert_eq!(Interface::from_name(i.name()), Some(i));
        }
        assert_eq!(Interface::from_code(11), None);
    }
}
