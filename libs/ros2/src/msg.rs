//! The ROS 2 messages Troupe writes, field for field as their `.msg` files
//! define them (serde's field order is CDR's), and each one's definition in
//! the `ros2msg` form MCAP readers parse: the message's own fields, then
//! each message it uses after a `MSG:` separator.

// The fields are ROS's, named and documented by its `.msg` files; only
// what Troupe adds or a name does not say is documented here.
#![allow(missing_docs)]

use serde::de::{Deserializer, SeqAccess, Visitor};
use serde::ser::{SerializeTuple, Serializer};
use serde::{Deserialize, Serialize};

/// `builtin_interfaces/msg/Time`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Time {
    /// Whole seconds.
    pub sec: i32,
    /// Nanoseconds into the second.
    pub nanosec: u32,
}

impl Time {
    /// `ns` nanoseconds (since the simulation's start, or the epoch).
    pub fn from_ns(ns: u64) -> Time {
        Time {
            sec: i32::try_from(ns / 1_000_000_000).unwrap_or(i32::MAX),
            nanosec: (ns % 1_000_000_000) as u32,
        }
    }

    /// In seconds.
    pub fn secs(self) -> f64 {
        f64::from(self.sec) + f64::from(self.nanosec) * 1e-9
    }

    /// Back to nanoseconds (a negative time is 0).
    pub fn ns(self) -> u64 {
        u64::try_from(self.sec).unwrap_or(0) * 1_000_000_000 + u64::from(self.nanosec)
    }
}

/// `std_msgs/msg/Header`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// When the data was taken.
    pub stamp: Time,
    /// The frame the data is in.
    pub frame_id: String,
}

/// `geometry_msgs/msg/Vector3`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Vector3 {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

/// `geometry_msgs/msg/Point`: the same fields as [`Vector3`].
pub type Point = Vector3;

/// `geometry_msgs/msg/Quaternion`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Quaternion::from_rpy(0.0, 0.0, 0.0)
    }
}

impl Quaternion {
    /// The rotation by `roll`, then `pitch`, then `yaw` (fixed axes x, y, z).
    pub fn from_rpy(roll: f64, pitch: f64, yaw: f64) -> Quaternion {
        let (sr, cr) = (roll / 2.0).sin_cos();
        let (sp, cp) = (pitch / 2.0).sin_cos();
        let (sy, cy) = (yaw / 2.0).sin_cos();
        Quaternion {
            x: sr * cp * cy - cr * sp * sy,
            y: cr * sp * cy + sr * cp * sy,
            z: cr * cp * sy - sr * sp * cy,
            w: cr * cp * cy + sr * sp * sy,
        }
    }

    /// The heading of this rotation about z, radians.
    pub fn yaw(self) -> f64 {
        (2.0 * (self.w * self.z + self.x * self.y))
            .atan2(1.0 - 2.0 * (self.y * self.y + self.z * self.z))
    }
}

/// `geometry_msgs/msg/Pose`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    pub position: Point,
    pub orientation: Quaternion,
}

impl Pose {
    /// The pose in the plane: x, y and the heading about z.
    pub fn planar(&self) -> troupe_msgs::Pose2d {
        troupe_msgs::Pose2d {
            x: self.position.x,
            y: self.position.y,
            yaw: self.orientation.yaw(),
        }
    }
}

/// A 6x6 covariance, row-major over x, y, z, roll, pitch, yaw
/// (`float64[36]`: a fixed array, no length on the wire).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cov(pub [f64; 36]);

impl Cov {
    /// The planar part in Player's order: xx, yy, yaw-yaw, xy, y-yaw, x-yaw.
    pub fn planar(&self) -> [f64; 6] {
        let c = &self.0;
        [c[0], c[7], c[35], c[1], c[11], c[5]]
    }
}

impl Default for Cov {
    fn default() -> Self {
        Cov([0.0; 36])
    }
}

impl Serialize for Cov {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut t = s.serialize_tuple(36)?;
        for v in &self.0 {
            t.serialize_element(v)?;
        }
        t.end()
    }
}

impl<'de> Deserialize<'de> for Cov {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Cov;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("36 float64")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Cov, A::Error> {
                let mut c = [0.0; 36];
                for (i, v) in c.iter_mut().enumerate() {
                    *v = seq
                        .next_element()?
                        .ok_or_else(|| serde::de::Error::invalid_length(i, &self))?;
                }
                Ok(Cov(c))
            }
        }
        d.deserialize_tuple(36, V)
    }
}

/// `geometry_msgs/msg/PoseWithCovariance`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovariance {
    pub pose: Pose,
    pub covariance: Cov,
}

/// `geometry_msgs/msg/Twist`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Twist {
    pub linear: Vector3,
    pub angular: Vector3,
}

/// `geometry_msgs/msg/TwistWithCovariance`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct TwistWithCovariance {
    pub twist: Twist,
    pub covariance: Cov,
}

/// `nav_msgs/msg/Odometry`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Odometry {
    pub header: Header,
    /// The frame the twist is in (the robot's).
    pub child_frame_id: String,
    pub pose: PoseWithCovariance,
    pub twist: TwistWithCovariance,
}

/// `sensor_msgs/msg/LaserScan`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct LaserScan {
    pub header: Header,
    pub angle_min: f32,
    pub angle_max: f32,
    pub angle_increment: f32,
    pub time_increment: f32,
    pub scan_time: f32,
    pub range_min: f32,
    pub range_max: f32,
    pub ranges: Vec<f32>,
    pub intensities: Vec<f32>,
}

/// `sensor_msgs/msg/Range`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Range {
    pub header: Header,
    /// [`Range::ULTRASOUND`] or [`Range::INFRARED`].
    pub radiation_type: u8,
    pub field_of_view: f32,
    pub min_range: f32,
    pub max_range: f32,
    pub range: f32,
    /// Jazzy's: 0, unknown (Humble's `Range` ends before it).
    pub variance: f32,
}

impl Range {
    /// Sonar.
    pub const ULTRASOUND: u8 = 0;
    /// Infrared.
    pub const INFRARED: u8 = 1;
}

/// `geometry_msgs/msg/PoseWithCovarianceStamped`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovarianceStamped {
    pub header: Header,
    pub pose: PoseWithCovariance,
}

/// `geometry_msgs/msg/PoseStamped`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseStamped {
    pub header: Header,
    pub pose: Pose,
}

/// `geometry_msgs/msg/PoseArray`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseArray {
    pub header: Header,
    pub poses: Vec<Pose>,
}

/// `nav_msgs/msg/Path`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Path {
    pub header: Header,
    pub poses: Vec<PoseStamped>,
}

/// `nav_msgs/msg/MapMetaData`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct MapMetaData {
    pub map_load_time: Time,
    /// Metres per cell.
    pub resolution: f32,
    pub width: u32,
    pub height: u32,
    /// Cell (0, 0)'s corner in the map frame.
    pub origin: Pose,
}

/// `nav_msgs/msg/OccupancyGrid`: cells row-major from (0, 0); 0 free, 100
/// occupied, -1 unknown.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct OccupancyGrid {
    pub header: Header,
    pub info: MapMetaData,
    pub data: Vec<i8>,
}

/// `geometry_msgs/msg/Transform`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Transform {
    pub translation: Vector3,
    pub rotation: Quaternion,
}

/// `geometry_msgs/msg/TransformStamped`: `child_frame_id`'s pose in
/// `header.frame_id`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TransformStamped {
    pub header: Header,
    pub child_frame_id: String,
    pub transform: Transform,
}

/// `tf2_msgs/msg/TFMessage`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TfMessage {
    pub transforms: Vec<TransformStamped>,
}

/// `rosgraph_msgs/msg/Clock`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Clock {
    pub clock: Time,
}

/// `sensor_msgs/msg/Image`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Image {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    /// `rgb8`, `mono8`, `mono16`.
    pub encoding: String,
    pub is_bigendian: u8,
    /// Bytes per row.
    pub step: u32,
    pub data: Vec<u8>,
}

/// `sensor_msgs/msg/CompressedImage`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CompressedImage {
    pub header: Header,
    /// `jpeg`.
    pub format: String,
    pub data: Vec<u8>,
}

/// `std_msgs/msg/String`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Text {
    pub data: String,
}

/// The ROS 2 message types Troupe writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Type {
    /// `sensor_msgs/msg/LaserScan`.
    LaserScan,
    /// `sensor_msgs/msg/Range`.
    Range,
    /// `nav_msgs/msg/Odometry`.
    Odometry,
    /// `nav_msgs/msg/OccupancyGrid`.
    OccupancyGrid,
    /// `nav_msgs/msg/Path`.
    Path,
    /// `geometry_msgs/msg/PoseWithCovarianceStamped`.
    PoseWithCovarianceStamped,
    /// `geometry_msgs/msg/PoseArray`.
    PoseArray,
    /// `tf2_msgs/msg/TFMessage`.
    TfMessage,
    /// `rosgraph_msgs/msg/Clock`.
    Clock,
    /// `sensor_msgs/msg/Image`.
    Image,
    /// `sensor_msgs/msg/CompressedImage`.
    CompressedImage,
    /// `std_msgs/msg/String`: what has no ROS 2 form, as its JSON, in a
    /// rosbag2 directory (whose readers take CDR only).
    String,
    /// `geometry_msgs/msg/Twist`: what ROS 2 nodes drive a base with.
    Twist,
    /// `geometry_msgs/msg/PoseStamped`: a goal, from rviz2 or Nav2.
    PoseStamped,
}

// The definitions, one per message, without the comments of ROS's files.
const TIME: &str = "int32 sec\nuint32 nanosec\n";
const HEADER: &str = "builtin_interfaces/Time stamp\nstring frame_id\n";
const VECTOR3: &str = "float64 x\nfloat64 y\nfloat64 z\n";
const QUATERNION: &str = "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n";
const POSE: &str = "Point position\nQuaternion orientation\n";
const POSE_COV: &str = "Pose pose\nfloat64[36] covariance\n";
const TWIST: &str = "Vector3 linear\nVector3 angular\n";
const TWIST_COV: &str = "Twist twist\nfloat64[36] covariance\n";
const POSE_STAMPED: &str = "std_msgs/Header header\nPose pose\n";
const MAP_META: &str = "builtin_interfaces/Time map_load_time\nfloat32 resolution\nuint32 width\nuint32 height\ngeometry_msgs/Pose origin\n";
const TRANSFORM: &str = "Vector3 translation\nQuaternion rotation\n";
const TRANSFORM_STAMPED: &str =
    "std_msgs/Header header\nstring child_frame_id\nTransform transform\n";

impl Type {
    /// Every type.
    pub const ALL: [Type; 14] = [
        Type::LaserScan,
        Type::Range,
        Type::Odometry,
        Type::OccupancyGrid,
        Type::Path,
        Type::PoseWithCovarianceStamped,
        Type::PoseArray,
        Type::TfMessage,
        Type::Clock,
        Type::Image,
        Type::CompressedImage,
        Type::String,
        Type::Twist,
        Type::PoseStamped,
    ];

    /// Its full name, `sensor_msgs/msg/LaserScan`.
    pub fn name(self) -> &'static str {
        match self {
            Type::LaserScan => "sensor_msgs/msg/LaserScan",
            Type::Range => "sensor_msgs/msg/Range",
            Type::Odometry => "nav_msgs/msg/Odometry",
            Type::OccupancyGrid => "nav_msgs/msg/OccupancyGrid",
            Type::Path => "nav_msgs/msg/Path",
            Type::PoseWithCovarianceStamped => "geometry_msgs/msg/PoseWithCovarianceStamped",
            Type::PoseArray => "geometry_msgs/msg/PoseArray",
            Type::TfMessage => "tf2_msgs/msg/TFMessage",
            Type::Clock => "rosgraph_msgs/msg/Clock",
            Type::Image => "sensor_msgs/msg/Image",
            Type::CompressedImage => "sensor_msgs/msg/CompressedImage",
            Type::String => "std_msgs/msg/String",
            Type::Twist => "geometry_msgs/msg/Twist",
            Type::PoseStamped => "geometry_msgs/msg/PoseStamped",
        }
    }

    /// The type of that name.
    pub fn from_name(name: &str) -> Option<Type> {
        Type::ALL.into_iter().find(|t| t.name() == name)
    }

    /// Its `ros2msg` definition: its fields, then every message it uses.
    pub fn definition(self) -> String {
        let (own, uses): (&str, &[(&str, &str)]) = match self {
            Type::LaserScan => (
                "std_msgs/Header header\nfloat32 angle_min\nfloat32 angle_max\nfloat32 angle_increment\n\
                 float32 time_increment\nfloat32 scan_time\nfloat32 range_min\nfloat32 range_max\n\
                 float32[] ranges\nfloat32[] intensities\n",
                &[("std_msgs/Header", HEADER), ("builtin_interfaces/Time", TIME)],
            ),
            Type::Range => (
                "uint8 ULTRASOUND=0\nuint8 INFRARED=1\nstd_msgs/Header header\nuint8 radiation_type\n\
                 float32 field_of_view\nfloat32 min_range\nfloat32 max_range\nfloat32 range\n\
                 float32 variance\n",
                &[("std_msgs/Header", HEADER), ("builtin_interfaces/Time", TIME)],
            ),
            Type::Odometry => (
                "std_msgs/Header header\nstring child_frame_id\n\
                 geometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n",
                &[
                    ("std_msgs/Header", HEADER),
                    ("builtin_interfaces/Time", TIME),
                    ("geometry_msgs/PoseWithCovariance", POSE_COV),
                    ("geometry_msgs/Pose", POSE),
                    ("geometry_msgs/Point", VECTOR3),
                    ("geometry_msgs/Quaternion", QUATERNION),
                    ("geometry_msgs/TwistWithCovariance", TWIST_COV),
                    ("geometry_msgs/Twist", TWIST),
                    ("geometry_msgs/Vector3", VECTOR3),
                ],
            ),
            Type::OccupancyGrid => (
                "std_msgs/Header header\nMapMetaData info\nint8[] data\n",
                &[
                    ("std_msgs/Header", HEADER),
                    ("builtin_interfaces/Time", TIME),
                    ("nav_msgs/MapMetaData", MAP_META),
                    ("geometry_msgs/Pose", POSE),
                    ("geometry_msgs/Point", VECTOR3),
                    ("geometry_msgs/Quaternion", QUATERNION),
                ],
            ),
            Type::Path => (
                "std_msgs/Header header\ngeometry_msgs/PoseStamped[] poses\n",
                &[
                    ("std_msgs/Header", HEADER),
                    ("builtin_interfaces/Time", TIME),
                    ("geometry_msgs/PoseStamped", POSE_STAMPED),
                    ("geometry_msgs/Pose", POSE),
                    ("geometry_msgs/Point", VECTOR3),
                    ("geometry_msgs/Quaternion", QUATERNION),
                ],
            ),
            Type::PoseWithCovarianceStamped => (
                "std_msgs/Header header\nPoseWithCovariance pose\n",
                &[
                    ("std_msgs/Header", HEADER),
                    ("builtin_interfaces/Time", TIME),
                    ("geometry_msgs/PoseWithCovariance", POSE_COV),
                    ("geometry_msgs/Pose", POSE),
                    ("geometry_msgs/Point", VECTOR3),
                    ("geometry_msgs/Quaternion", QUATERNION),
                ],
            ),
            Type::PoseArray => (
                "std_msgs/Header header\nPose[] poses\n",
                &[
                    ("std_msgs/Header", HEADER),
                    ("builtin_interfaces/Time", TIME),
                    ("geometry_msgs/Pose", POSE),
                    ("geometry_msgs/Point", VECTOR3),
                    ("geometry_msgs/Quaternion", QUATERNION),
                ],
            ),
            Type::TfMessage => (
                "geometry_msgs/TransformStamped[] transforms\n",
                &[
                    ("geometry_msgs/TransformStamped", TRANSFORM_STAMPED),
                    ("std_msgs/Header", HEADER),
                    ("builtin_interfaces/Time", TIME),
                    ("geometry_msgs/Transform", TRANSFORM),
                    ("geometry_msgs/Vector3", VECTOR3),
                    ("geometry_msgs/Quaternion", QUATERNION),
                ],
            ),
            Type::Clock => (
                "builtin_interfaces/Time clock\n",
                &[("builtin_interfaces/Time", TIME)],
            ),
            Type::Image => (
                "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\n\
                 uint8 is_bigendian\nuint32 step\nuint8[] data\n",
                &[("std_msgs/Header", HEADER), ("builtin_interfaces/Time", TIME)],
            ),
            Type::CompressedImage => (
                "std_msgs/Header header\nstring format\nuint8[] data\n",
                &[("std_msgs/Header", HEADER), ("builtin_interfaces/Time", TIME)],
            ),
            Type::String => ("string data\n", &[]),
            Type::Twist => (TWIST, &[("geometry_msgs/Vector3", VECTOR3)]),
            Type::PoseStamped => (
                POSE_STAMPED,
                &[
                    ("std_msgs/Header", HEADER),
                    ("builtin_interfaces/Time", TIME),
                    ("geometry_msgs/Pose", POSE),
                    ("geometry_msgs/Point", VECTOR3),
                    ("geometry_msgs/Quaternion", QUATERNION),
                ],
            ),
        };
        let mut text = own.to_owned();
        for (name, fields) in uses {
            text.push_str(&"=".repeat(80));
            text.push_str("\nMSG: ");
            text.push_str(name);
            text.push('\n');
            text.push_str(fields);
        }
        text
    }
}
