//! Troupe's messages as ROS 2 messages, so a recording reads in `ros2 bag`,
//! rosbags, PlotJuggler and Foxglove: [`Translator`] turns each sample into
//! the ROS 2 messages that carry it (CDR payloads, little-endian, with the
//! encapsulation header), on ROS 2 topic names, in frames that one TF tree
//! joins.
//!
//! Names (a ROS 2 name's tokens may not begin with a digit):
//!
//! ```text
//! robot/6665/laser/0        /robot_6665/laser_0            frame robot_6665/laser_0
//! robot/6665/position2d/0   /robot_6665/position2d_0       robot_6665/odom -> robot_6665/base_link
//! robot/6665/localize/0     /robot_6665/localize_0         map -> robot_6665/odom
//!                           /robot_6665/localize_0/particles
//! robot/6665/camera/0       /robot_6665/camera_0           Image, or CompressedImage (JPEG)
//! sim/clock                 /clock
//! ```
//!
//! A device's geometry (which the recorder asks for when the device comes,
//! as a Player client does) becomes `/tf_static` from the robot's
//! `base_link` to the sensor's frame (one frame per sonar or IR element:
//! `robot_6665/sonar_0/3`).

pub mod back;
pub mod live;
pub mod msg;
pub mod rmw;

use std::collections::HashMap;

use serde::Serialize;
use troupe_msgs::{camera, ir, keys, laser, map, position2d, ranger, sonar};
use troupe_msgs::{AnyMsg, Device, Pose2d, Pose3d};

pub use msg::Type;
use msg::*;

/// The topic of the clock.
pub const CLOCK: &str = "/clock";
/// The topic of moving transforms.
pub const TF: &str = "/tf";
/// The topic of fixed transforms.
pub const TF_STATIC: &str = "/tf_static";
/// The frame localizers and maps share.
pub const MAP_FRAME: &str = "map";

/// One ROS 2 message: its topic, type and CDR payload.
#[derive(Debug, Clone, PartialEq)]
pub struct Out {
    /// `/robot_6665/laser_0`.
    pub topic: String,
    /// Its type.
    pub ty: Type,
    /// CDR, little-endian, after the 4-byte encapsulation header.
    pub data: Vec<u8>,
}

/// The ROS 2 topic of a device: `/robot_6665/laser_0`.
pub fn topic(dev: &Device) -> String {
    format!("/robot_{}/{}_{}", dev.robot, dev.interface, dev.index)
}

/// The ROS 2 topic of a Troupe key: a device's [`topic`], `/clock` for the
/// clock, and any other key with its slashes kept and each token that
/// begins with a digit prefixed by `_`.
pub fn topic_of_key(key: &str) -> String {
    if key == keys::SIM_CLOCK {
        return CLOCK.to_owned();
    }
    if let Ok(dev) = keys::parse_data(key) {
        return topic(&dev);
    }
    let mut t = String::with_capacity(key.len() + 4);
    for token in key.split('/').filter(|s| !s.is_empty()) {
        t.push('/');
        if token.starts_with(|c: char| c.is_ascii_digit()) {
            t.push('_');
        }
        t.extend(
            token
                .chars()
                .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' }),
        );
    }
    t
}

/// A robot's frame: `robot_6665/base_link`.
pub fn robot_frame(robot: u32, name: &str) -> String {
    format!("robot_{robot}/{name}")
}

/// A device's own frame: `robot_6665/laser_0`.
pub fn device_frame(dev: &Device) -> String {
    format!("robot_{}/{}_{}", dev.robot, dev.interface, dev.index)
}

/// A camera image's pixels as ROS and Foxglove carry them.
#[derive(Debug, Clone, PartialEq)]
pub enum Pixels<'a> {
    /// Raw rows, top first: `rgb8`, `mono8` or `mono16` (little-endian).
    Raw {
        encoding: &'static str,
        /// Bytes per row.
        step: u32,
        data: std::borrow::Cow<'a, [u8]>,
    },
    /// A JPEG file's bytes.
    Jpeg(&'a [u8]),
}

/// The pixels of Player camera image `c`: RGB888 and MONO8 as they are,
/// 32-bit RGB without its fourth byte, RGB565 (16-bit values, low byte
/// first) widened to `rgb8`, MONO16 (network byte order) turned
/// little-endian; `None` for a format Player does not define or bytes too
/// few for the size.
pub fn camera_pixels(c: &camera::Data) -> Option<Pixels<'_>> {
    use std::borrow::Cow;
    if c.compression == camera::COMPRESS_JPEG {
        return Some(Pixels::Jpeg(&c.image));
    }
    let n = c.width as usize * c.height as usize;
    let bytes = |per: usize| c.image.get(..n * per);
    let raw = |encoding, per: u32, data| Pixels::Raw {
        encoding,
        step: c.width * per,
        data,
    };
    Some(match (c.format, c.bpp) {
        (camera::FORMAT_MONO8, _) => raw("mono8", 1, Cow::Borrowed(bytes(1)?)),
        (camera::FORMAT_MONO16, _) => {
            let swapped = bytes(2)?
                .chunks_exact(2)
                .flat_map(|b| [b[1], b[0]])
                .collect();
            raw("mono16", 2, Cow::Owned(swapped))
        }
        (camera::FORMAT_RGB565, _) => {
            let rgb = bytes(2)?
                .chunks_exact(2)
                .flat_map(|b| {
                    let v = u16::from_le_bytes([b[0], b[1]]);
                    let (r, g, b) = ((v >> 11) & 0x1f, (v >> 5) & 0x3f, v & 0x1f);
                    [
                        (r << 3 | r >> 2) as u8,
                        (g << 2 | g >> 4) as u8,
                        (b << 3 | b >> 2) as u8,
                    ]
                })
                .collect();
            raw("rgb8", 3, Cow::Owned(rgb))
        }
        (camera::FORMAT_RGB888, 32) => {
            let rgb = bytes(4)?
                .chunks_exact(4)
                .flat_map(|p| [p[0], p[1], p[2]])
                .collect();
            raw("rgb8", 3, Cow::Owned(rgb))
        }
        (camera::FORMAT_RGB888, _) => raw("rgb8", 3, Cow::Borrowed(bytes(3)?)),
        _ => return None,
    })
}

/// A stamp in seconds as nanoseconds (a negative or non-finite one is 0).
pub fn stamp_ns(secs: f64) -> u64 {
    if secs.is_finite() && secs > 0.0 {
        (secs * 1e9).round() as u64
    } else {
        0
    }
}

/// Where a message with no ROS 2 type goes, as JSON: its device's topic
/// and its kind (`/robot_6665/ranger_0/intensities` for
/// `ranger/intensities@1`), a topic of one type as ROS 2 requires.
pub fn json_topic(topic: &str, tag: &str) -> String {
    let kind = tag.split(['/', '@']).nth(1).unwrap_or(tag);
    format!("{topic}/{kind}")
}

/// The JSON schema (`jsonschema`) such a message is written with: an
/// object, titled by its schema tag.
pub fn json_schema(tag: &str) -> String {
    format!(r#"{{"title":"{tag}","type":"object"}}"#)
}

/// The pose of odometry's origin in the map (`map -> odom`), from the
/// robot's pose in each.
pub fn odom_in_map(in_map: Pose2d, in_odom: Pose2d) -> Pose2d {
    compose(in_map, inverse(in_odom))
}

fn element_frame(dev: &Device, element: usize) -> String {
    format!("{}/{element}", device_frame(dev))
}

/// CDR with the little-endian encapsulation header, as ROS 2 writes it.
///
/// # Panics
///
/// Never for the types of [`msg`]: CDR can encode every one of them.
pub fn cdr<T: Serialize>(m: &T) -> Vec<u8> {
    #[allow(clippy::expect_used)]
    cdr::serialize::<_, _, cdr::CdrLe>(m, cdr::Infinite).expect("CDR encodes plain structs")
}

fn header(stamp_ns: u64, frame: String) -> Header {
    Header {
        stamp: Time::from_ns(stamp_ns),
        frame_id: frame,
    }
}

fn pose2(p: Pose2d) -> Pose {
    Pose {
        position: Point {
            x: p.x,
            y: p.y,
            z: 0.0,
        },
        orientation: Quaternion::from_rpy(0.0, 0.0, p.yaw),
    }
}

fn transform3(p: &Pose3d) -> Transform {
    Transform {
        translation: Vector3 {
            x: p.x,
            y: p.y,
            z: p.z,
        },
        rotation: Quaternion::from_rpy(p.roll, p.pitch, p.yaw),
    }
}

fn transform2(p: Pose2d) -> Transform {
    let pose = pose2(p);
    Transform {
        translation: pose.position,
        rotation: pose.orientation,
    }
}

/// `a ∘ b`: the pose `b` (given in `a`'s frame) in the frame `a` is given in.
fn compose(a: Pose2d, b: Pose2d) -> Pose2d {
    let (s, c) = a.yaw.sin_cos();
    Pose2d {
        x: a.x + c * b.x - s * b.y,
        y: a.y + s * b.x + c * b.y,
        yaw: a.yaw + b.yaw,
    }
}

fn inverse(a: Pose2d) -> Pose2d {
    let (s, c) = a.yaw.sin_cos();
    Pose2d {
        x: -c * a.x - s * a.y,
        y: s * a.x - c * a.y,
        yaw: -a.yaw,
    }
}

/// Player's planar covariance (xx, yy, yaw-yaw, xy, y-yaw, x-yaw) as ROS's
/// 6x6 over x, y, z, roll, pitch, yaw.
fn cov6(c: &[f64; 6]) -> Cov {
    let mut m = [0.0; 36];
    let (x, y, yaw) = (0, 1, 5);
    let mut set = |i: usize, j: usize, v: f64| {
        m[i * 6 + j] = v;
        m[j * 6 + i] = v;
    };
    set(x, x, c[0]);
    set(y, y, c[1]);
    set(yaw, yaw, c[2]);
    set(x, y, c[3]);
    set(y, yaw, c[4]);
    set(x, yaw, c[5]);
    Cov(m)
}

/// Player's cell (-1 free, 0 unknown, +1 occupied) as ROS's (0, -1, 100).
fn cell(c: i8) -> i8 {
    match c.signum() {
        -1 => 0,
        1 => 100,
        _ => -1,
    }
}

/// Turns Troupe samples into ROS 2 messages, one sample at a time, keeping
/// what later samples need: each robot's odometry (for `map -> odom`), a
/// map's info (for its cells), a ranger's configuration and geometry (for
/// the shape of its scans).
#[derive(Debug, Default)]
pub struct Translator {
    odom: HashMap<u32, Pose2d>,
    /// A localizer's estimate that came before the robot's odometry.
    unjoined: HashMap<u32, Pose2d>,
    map_info: HashMap<Device, map::Info>,
    ranger_config: HashMap<Device, ranger::Config>,
    ranger_elements: HashMap<Device, usize>,
}

impl Translator {
    /// A translator that has seen nothing yet.
    pub fn new() -> Translator {
        Translator::default()
    }

    /// The ROS 2 messages that carry `msg`, a sample on `key` stamped
    /// `stamp_ns` (its own stamp: simulation time under a simulator).
    /// `None`: the message has no ROS 2 form (the caller writes it some
    /// other way); an empty list: it was kept for what it tells about later
    /// samples (a map's info before its cells, a ranger's configuration).
    pub fn translate(&mut self, key: &str, stamp_ns: u64, msg: &AnyMsg) -> Option<Vec<Out>> {
        if let AnyMsg::SimClock(_) = msg {
            let c = Clock {
                clock: Time::from_ns(stamp_ns),
            };
            return Some(vec![out(CLOCK.to_owned(), Type::Clock, &c)]);
        }
        let dev = keys::parse_data(key).ok()?;
        let h = |frame: String| header(stamp_ns, frame);
        Some(match msg {
            AnyMsg::Position2dData(d) => self.odometry(&dev, stamp_ns, d),
            AnyMsg::CameraData(c) => match camera_pixels(c)? {
                Pixels::Raw {
                    encoding,
                    step,
                    data,
                } => {
                    let m = Image {
                        header: h(device_frame(&dev)),
                        height: c.height,
                        width: c.width,
                        encoding: encoding.to_owned(),
                        is_bigendian: 0,
                        step,
                        data: data.into_owned(),
                    };
                    vec![out(topic(&dev), Type::Image, &m)]
                }
                Pixels::Jpeg(data) => {
                    let m = CompressedImage {
                        header: h(device_frame(&dev)),
                        format: "jpeg".to_owned(),
                        data: data.to_vec(),
                    };
                    vec![out(topic(&dev), Type::CompressedImage, &m)]
                }
            },
            AnyMsg::LaserScan(s) | AnyMsg::LaserScanPose(laser::ScanPose { scan: s, .. }) => {
                let m = LaserScan {
                    header: h(device_frame(&dev)),
                    angle_min: s.min_angle,
                    angle_max: s.max_angle,
                    angle_increment: s.resolution,
                    range_min: 0.0,
                    range_max: s.max_range,
                    ranges: s.ranges.clone(),
                    intensities: s.intensity.iter().map(|&i| f32::from(i)).collect(),
                    ..LaserScan::default()
                };
                vec![out(topic(&dev), Type::LaserScan, &m)]
            }
            AnyMsg::RangerConfig(c) => {
                self.ranger_config.insert(dev, *c);
                vec![]
            }
            AnyMsg::RangerRanges(r) => return self.ranger(&dev, stamp_ns, r),
            AnyMsg::SonarRanges(r) => {
                let ranges: Vec<f64> = r.ranges.iter().map(|&v| f64::from(v)).collect();
                ranges_out(
                    &dev,
                    stamp_ns,
                    Range::ULTRASOUND,
                    &ranges,
                    0.0,
                    f32::INFINITY,
                )
            }
            AnyMsg::IrData(d) => {
                let ranges: Vec<f64> = d.ranges.iter().map(|&v| f64::from(v)).collect();
                ranges_out(&dev, stamp_ns, Range::INFRARED, &ranges, 0.0, f32::INFINITY)
            }
            // A base's geometry places the base itself: no frame to join.
            AnyMsg::Position2dGeom(_) => vec![],
            AnyMsg::LaserGeom(g) => static_tf(&dev, stamp_ns, &[g.pose], false),
            AnyMsg::RangerGeom(g) => {
                self.ranger_elements.insert(dev, g.element_poses.len());
                let mut v = static_tf(&dev, stamp_ns, &[g.pose], false);
                if g.element_poses.len() > 1 {
                    v.extend(static_tf(&dev, stamp_ns, &g.element_poses, true));
                }
                v
            }
            AnyMsg::SonarGeom(sonar::Geom { poses }) | AnyMsg::IrGeom(ir::Geom { poses }) => {
                static_tf(&dev, stamp_ns, poses, true)
            }
            AnyMsg::LocalizeHypoths(hs) => {
                let Some(best) = hs.hypoths.first() else {
                    return Some(vec![]);
                };
                let m = PoseWithCovarianceStamped {
                    header: h(MAP_FRAME.to_owned()),
                    pose: PoseWithCovariance {
                        pose: pose2(best.mean),
                        covariance: cov6(&best.cov),
                    },
                };
                let mut v = vec![out(topic(&dev), Type::PoseWithCovarianceStamped, &m)];
                match self.odom.get(&dev.robot) {
                    Some(&odom) => v.push(map_to_odom(dev.robot, stamp_ns, best.mean, odom)),
                    // Joined when the robot's odometry comes.
                    None => {
                        self.unjoined.insert(dev.robot, best.mean);
                    }
                }
                v
            }
            AnyMsg::LocalizeParticles(p) => {
                let m = PoseArray {
                    header: h(MAP_FRAME.to_owned()),
                    poses: p.particles.iter().map(|q| pose2(q.pose)).collect(),
                };
                vec![out(
                    format!("{}/particles", topic(&dev)),
                    Type::PoseArray,
                    &m,
                )]
            }
            AnyMsg::MapInfo(i) => {
                self.map_info.insert(dev, *i);
                vec![]
            }
            AnyMsg::MapData(d) => return self.grid(&dev, stamp_ns, d),
            AnyMsg::PlannerWaypoints(w) => {
                let m = Path {
                    header: h(MAP_FRAME.to_owned()),
                    poses: w
                        .waypoints
                        .iter()
                        .map(|&p| PoseStamped {
                            header: h(MAP_FRAME.to_owned()),
                            pose: pose2(p),
                        })
                        .collect(),
                };
                vec![out(format!("{}/path", topic(&dev)), Type::Path, &m)]
            }
            _ => return None,
        })
    }

    fn odometry(&mut self, dev: &Device, stamp_ns: u64, d: &position2d::Data) -> Vec<Out> {
        let odom = robot_frame(dev.robot, "odom");
        let base = robot_frame(dev.robot, "base_link");
        let m = Odometry {
            header: header(stamp_ns, odom.clone()),
            child_frame_id: base.clone(),
            pose: PoseWithCovariance {
                pose: pose2(d.pose),
                covariance: Cov::default(),
            },
            twist: TwistWithCovariance {
                twist: Twist {
                    linear: Vector3 {
                        x: d.vel.x,
                        y: d.vel.y,
                        z: 0.0,
                    },
                    angular: Vector3 {
                        x: 0.0,
                        y: 0.0,
                        z: d.vel.yaw,
                    },
                },
                covariance: Cov::default(),
            },
        };
        let mut v = vec![out(topic(dev), Type::Odometry, &m)];
        // The robot's base moves in odom by its first position2d: a
        // second one (vfh's, over the base's) reports the same odometry.
        if dev.index == 0 {
            self.odom.insert(dev.robot, d.pose);
            if let Some(fix) = self.unjoined.remove(&dev.robot) {
                v.push(map_to_odom(dev.robot, stamp_ns, fix, d.pose));
            }
            let t = TransformStamped {
                header: header(stamp_ns, odom),
                child_frame_id: base,
                transform: transform2(d.pose),
            };
            v.push(out(
                TF.to_owned(),
                Type::TfMessage,
                &TfMessage {
                    transforms: vec![t],
                },
            ));
        }
        v
    }

    fn ranger(&self, dev: &Device, stamp_ns: u64, r: &ranger::Ranges) -> Option<Vec<Out>> {
        let elements = self.ranger_elements.get(dev).copied();
        let config = self.ranger_config.get(dev);
        // An array of single-beam sensors (sonar, IR): one Range each.
        if elements.is_some_and(|n| n > 1 && n == r.ranges.len()) {
            let (lo, hi) = config.map_or((0.0, f32::INFINITY), |c| {
                (c.min_range as f32, c.max_range as f32)
            });
            return Some(ranges_out(
                dev,
                stamp_ns,
                Range::ULTRASOUND,
                &r.ranges,
                lo,
                hi,
            ));
        }
        // A scanner: its configuration gives the angles.
        let c = config?;
        let m = LaserScan {
            header: header(stamp_ns, device_frame(dev)),
            angle_min: c.min_angle as f32,
            angle_max: c.max_angle as f32,
            angle_increment: c.angular_res as f32,
            scan_time: if c.frequency > 0.0 {
                (1.0 / c.frequency) as f32
            } else {
                0.0
            },
            range_min: c.min_range as f32,
            range_max: c.max_range as f32,
            ranges: r.ranges.iter().map(|&v| v as f32).collect(),
            ..LaserScan::default()
        };
        Some(vec![out(topic(dev), Type::LaserScan, &m)])
    }

    fn grid(&self, dev: &Device, stamp_ns: u64, d: &map::Data) -> Option<Vec<Out>> {
        let info = self.map_info.get(dev)?;
        // Only the whole map makes a grid; tiles of it have no ROS form.
        if d.col != 0 || d.row != 0 || d.width != info.width || d.height != info.height {
            return None;
        }
        let m = OccupancyGrid {
            header: header(stamp_ns, MAP_FRAME.to_owned()),
            info: MapMetaData {
                map_load_time: Time::from_ns(stamp_ns),
                resolution: info.resolution,
                width: info.width,
                height: info.height,
                origin: pose2(info.origin),
            },
            data: d.cells.iter().map(|&c| cell(c)).collect(),
        };
        Some(vec![out(topic(dev), Type::OccupancyGrid, &m)])
    }
}

/// `map -> odom`: where odometry's origin lies in the map, from the robot's
/// pose in each.
fn map_to_odom(robot: u32, stamp_ns: u64, in_map: Pose2d, in_odom: Pose2d) -> Out {
    let t = TransformStamped {
        header: header(stamp_ns, MAP_FRAME.to_owned()),
        child_frame_id: robot_frame(robot, "odom"),
        transform: transform2(odom_in_map(in_map, in_odom)),
    };
    out(
        TF.to_owned(),
        Type::TfMessage,
        &TfMessage {
            transforms: vec![t],
        },
    )
}

fn out<T: Serialize>(topic: String, ty: Type, m: &T) -> Out {
    Out {
        topic,
        ty,
        data: cdr(m),
    }
}

/// One `Range` per element, each in its element's frame.
fn ranges_out(
    dev: &Device,
    stamp_ns: u64,
    radiation: u8,
    ranges: &[f64],
    min: f32,
    max: f32,
) -> Vec<Out> {
    ranges
        .iter()
        .enumerate()
        .map(|(e, &r)| {
            let m = Range {
                header: header(stamp_ns, element_frame(dev, e)),
                radiation_type: radiation,
                field_of_view: 0.0,
                min_range: min,
                max_range: max,
                range: r as f32,
                variance: 0.0,
            };
            out(topic(dev), Type::Range, &m)
        })
        .collect()
}

/// `/tf_static` from the robot's base to the device (or to each element).
fn static_tf(dev: &Device, stamp_ns: u64, poses: &[Pose3d], elements: bool) -> Vec<Out> {
    let base = robot_frame(dev.robot, "base_link");
    let transforms = poses
        .iter()
        .enumerate()
        .map(|(e, p)| TransformStamped {
            header: header(stamp_ns, base.clone()),
            child_frame_id: if elements {
                element_frame(dev, e)
            } else {
                device_frame(dev)
            },
            transform: transform3(p),
        })
        .collect();
    vec![out(
        TF_STATIC.to_owned(),
        Type::TfMessage,
        &TfMessage { transforms },
    )]
}

#[cfg(test)]
mod tests;
