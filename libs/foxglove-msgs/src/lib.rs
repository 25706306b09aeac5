//! Troupe's samples as Foxglove's messages: [`Translator`] turns each
//! sample into the messages of Foxglove's own schemas (protobuf) that carry
//! it, in the frames of `--format ros2` recordings (troupe-ros2), so a live
//! connection (`troupe foxglove`) and a recording (`--format foxglove`)
//! look alike and both look like a ROS 2 bag of the same run.
//!
//! ```text
//! laser scan, ranger scan      foxglove.LaserScan       in robot_6665/laser_0
//! position2d data              foxglove.PoseInFrame     in robot_6665/odom, and /tf odom -> base_link
//! localize hypotheses          foxglove.PoseInFrame     in map, and /tf map -> odom
//! localize particles           foxglove.PosesInFrame    /robot/6665/localize/0/particles
//! planner waypoints            foxglove.PosesInFrame    /robot/6665/planner/0/path, in map
//! a map (info, then its cells) foxglove.Grid            in map
//! a sensor's geometry          foxglove.FrameTransforms /tf_static: base_link -> the sensor
//! a camera's image             foxglove.RawImage, or foxglove.CompressedImage (JPEG)
//! a simulator's world, poses   foxglove.SceneUpdate     in map: /robot/6665/simulation/0/world (still), …/scene (moving)
//! anything else                JSON                     /robot/6665/ranger/0/intensities: the key and the kind
//! ```
//!
//! Topics are the keys (`/robot/6665/laser/0`); a kind of sample with no
//! Foxglove schema goes as JSON on its device's topic and kind, one schema
//! per topic. The simulator's world frame is drawn as `map`: in a Stage
//! configuration the map server loads the world's own bitmap, so the two
//! coincide.

use std::collections::{BTreeMap, HashMap};

use foxglove::schemas::{
    line_primitive, packed_element_field::NumericType, Color, CompressedImage, FrameTransform,
    FrameTransforms, Grid, LaserScan, LinePrimitive, PackedElementField, Point3, Pose, PoseInFrame,
    PosesInFrame, Quaternion, RawImage, SceneEntity, SceneUpdate, Timestamp, Vector2, Vector3,
};
use foxglove::{Encode, Schema};
use troupe_msgs::{keys, localize, map, position2d, ranger, simulation, AnyMsg, Device};
use troupe_msgs::{Pose2d, Pose3d};
use troupe_ros2::{camera_pixels, device_frame, json_schema, json_topic, odom_in_map, Pixels};
use troupe_ros2::{robot_frame, MAP_FRAME};

pub use foxglove;

/// The topic of moving transforms.
pub const TF: &str = "/tf";
/// The topic of fixed transforms (sensors on their robot), latched.
pub const TF_STATIC: &str = "/tf_static";
/// The message encoding of Foxglove's schemas.
pub const PROTOBUF: &str = "protobuf";
/// The message encoding of the rest.
pub const JSON: &str = "json";

/// What a message is written as: one of Foxglove's schemas, or JSON.
#[derive(Debug, Clone, Copy)]
pub enum Kind {
    /// Protobuf, of the schema this gives.
    Protobuf(fn() -> Option<Schema>),
    /// JSON (a Troupe message's body), of its schema tag.
    Json(&'static str),
}

impl Kind {
    /// `protobuf` or `json`.
    pub fn encoding(&self) -> &'static str {
        match self {
            Kind::Protobuf(_) => PROTOBUF,
            Kind::Json(_) => JSON,
        }
    }

    /// The schema: Foxglove's (name, `protobuf`, a descriptor set), or a
    /// JSON schema titled by the Troupe tag.
    pub fn schema(&self) -> Option<Schema> {
        match self {
            Kind::Protobuf(schema) => schema(),
            Kind::Json(tag) => Some(Schema::new(
                *tag,
                "jsonschema",
                json_schema(tag).into_bytes(),
            )),
        }
    }
}

/// One Foxglove message: its topic, kind and payload.
#[derive(Debug, Clone)]
pub struct Message {
    /// `/robot/6665/laser/0`, `/tf`.
    pub topic: String,
    /// What it is written as.
    pub kind: Kind,
    /// The encoded message.
    pub data: Vec<u8>,
    /// Whether it publishes rarely and stands until the next (a map, the
    /// fixed transforms, an estimate, the world): a late subscriber needs
    /// the last one.
    pub latched: bool,
}

impl Message {
    fn new<T: Encode>(topic: String, m: &T) -> Message {
        let mut data = Vec::with_capacity(m.encoded_len().unwrap_or(64));
        // Encoding into a growing Vec cannot run out of room.
        let _ = m.encode(&mut data);
        Message {
            topic,
            kind: Kind::Protobuf(T::get_schema),
            data,
            latched: false,
        }
    }

    fn latched(mut self) -> Message {
        self.latched = true;
        self
    }
}

/// Nanoseconds as a Foxglove timestamp.
pub fn stamp(ns: u64) -> Timestamp {
    Timestamp::new(
        u32::try_from(ns / 1_000_000_000).unwrap_or(u32::MAX),
        (ns % 1_000_000_000) as u32,
    )
}

fn quaternion(roll: f64, pitch: f64, yaw: f64) -> Quaternion {
    let q = troupe_ros2::msg::Quaternion::from_rpy(roll, pitch, yaw);
    Quaternion {
        x: q.x,
        y: q.y,
        z: q.z,
        w: q.w,
    }
}

fn pose2(p: Pose2d) -> Pose {
    Pose {
        position: Some(Vector3 {
            x: p.x,
            y: p.y,
            z: 0.0,
        }),
        orientation: Some(quaternion(0.0, 0.0, p.yaw)),
    }
}

fn transform(ns: u64, parent: String, child: String, p: &Pose3d) -> FrameTransform {
    FrameTransform {
        timestamp: Some(stamp(ns)),
        parent_frame_id: parent,
        child_frame_id: child,
        translation: Some(Vector3 {
            x: p.x,
            y: p.y,
            z: p.z,
        }),
        rotation: Some(quaternion(p.roll, p.pitch, p.yaw)),
    }
}

fn flat(p: Pose2d) -> Pose3d {
    Pose3d {
        x: p.x,
        y: p.y,
        yaw: p.yaw,
        ..Pose3d::default()
    }
}

/// Turns samples into Foxglove messages, keeping what later samples need:
/// each robot's odometry (for `map -> odom`), a map's info (for its
/// cells), a ranger's configuration (for its angles), every sensor's place
/// (the whole `/tf_static`), a simulator's world (for its moving models).
#[derive(Debug, Default)]
pub struct Translator {
    odom: HashMap<u32, Pose2d>,
    map_info: HashMap<Device, map::Info>,
    ranger_config: HashMap<Device, ranger::Config>,
    /// How many sensors a ranger has: an array (sonar, IR) is no scan.
    ranger_elements: HashMap<Device, usize>,
    /// Every sensor's place on its robot, by the sensor's frame.
    fixed: BTreeMap<String, FrameTransform>,
    worlds: HashMap<Device, simulation::World>,
}

impl Translator {
    /// A translator that has seen nothing yet.
    pub fn new() -> Translator {
        Translator::default()
    }

    /// Forgets what it kept of a device that went.
    pub fn forget(&mut self, dev: &Device) {
        self.map_info.remove(dev);
        self.ranger_config.remove(dev);
        self.ranger_elements.remove(dev);
        self.worlds.remove(dev);
    }

    /// The messages of sample `msg` on `key`, stamped `ns`: none for what
    /// is only kept (a map's info), JSON for what has no Foxglove schema.
    pub fn translate(&mut self, key: &str, ns: u64, msg: &AnyMsg) -> Vec<Message> {
        let Ok(dev) = keys::parse_data(key) else {
            return vec![json(format!("/{key}"), msg)];
        };
        let topic = format!("/{key}");
        let base = robot_frame(dev.robot, "base_link");
        match msg {
            AnyMsg::LaserScan(s)
            | AnyMsg::LaserScanPose(troupe_msgs::laser::ScanPose { scan: s, .. }) => {
                let m = LaserScan {
                    timestamp: Some(stamp(ns)),
                    frame_id: device_frame(&dev),
                    pose: Some(pose2(Pose2d::default())),
                    start_angle: f64::from(s.min_angle),
                    end_angle: f64::from(s.max_angle),
                    ranges: s.ranges.iter().map(|&r| f64::from(r)).collect(),
                    intensities: s.intensity.iter().map(|&i| f64::from(i)).collect(),
                };
                vec![Message::new(topic, &m)]
            }
            AnyMsg::RangerConfig(c) => {
                self.ranger_config.insert(dev, *c);
                vec![json(topic, msg)]
            }
            AnyMsg::RangerRanges(r) => match self.ranger_config.get(&dev) {
                // A scanner (one sensor, many readings): its configuration
                // gives the angles. An array of single-beam sensors has no
                // Foxglove schema.
                Some(c)
                    if !self
                        .ranger_elements
                        .get(&dev)
                        .is_some_and(|&n| n > 1 && n == r.ranges.len()) =>
                {
                    let m = LaserScan {
                        timestamp: Some(stamp(ns)),
                        frame_id: device_frame(&dev),
                        pose: Some(pose2(Pose2d::default())),
                        start_angle: c.min_angle,
                        end_angle: c.max_angle,
                        ranges: r.ranges.clone(),
                        intensities: vec![],
                    };
                    vec![Message::new(topic, &m)]
                }
                _ => vec![json(topic, msg)],
            },
            AnyMsg::CameraData(c) => match camera_pixels(c) {
                Some(Pixels::Raw {
                    encoding,
                    step,
                    data,
                }) => {
                    let m = RawImage {
                        timestamp: Some(stamp(ns)),
                        frame_id: device_frame(&dev),
                        width: c.width,
                        height: c.height,
                        encoding: encoding.to_owned(),
                        step,
                        data: data.into_owned().into(),
                    };
                    vec![Message::new(topic, &m)]
                }
                Some(Pixels::Jpeg(data)) => {
                    let m = CompressedImage {
                        timestamp: Some(stamp(ns)),
                        frame_id: device_frame(&dev),
                        data: data.to_vec().into(),
                        format: "jpeg".to_owned(),
                    };
                    vec![Message::new(topic, &m)]
                }
                None => vec![json(topic, msg)],
            },
            AnyMsg::Position2dData(position2d::Data { pose, .. }) => {
                let odom = robot_frame(dev.robot, "odom");
                let m = PoseInFrame {
                    timestamp: Some(stamp(ns)),
                    frame_id: odom.clone(),
                    pose: Some(pose2(*pose)),
                };
                let mut out = vec![Message::new(topic, &m)];
                if dev.index == 0 {
                    self.odom.insert(dev.robot, *pose);
                    out.push(tf(vec![transform(ns, odom, base, &flat(*pose))]));
                }
                out
            }
            AnyMsg::LocalizeHypoths(hs) => {
                let Some(best) = hs.hypoths.first() else {
                    return vec![];
                };
                let m = PoseInFrame {
                    timestamp: Some(stamp(ns)),
                    frame_id: MAP_FRAME.to_owned(),
                    pose: Some(pose2(best.mean)),
                };
                let mut out = vec![Message::new(topic, &m).latched()];
                if let Some(&odom) = self.odom.get(&dev.robot) {
                    let t = transform(
                        ns,
                        MAP_FRAME.to_owned(),
                        robot_frame(dev.robot, "odom"),
                        &flat(odom_in_map(best.mean, odom)),
                    );
                    out.push(tf(vec![t]));
                }
                out
            }
            AnyMsg::LocalizeParticles(localize::Particles { particles, .. }) => {
                let m = PosesInFrame {
                    timestamp: Some(stamp(ns)),
                    frame_id: MAP_FRAME.to_owned(),
                    poses: particles.iter().map(|p| pose2(p.pose)).collect(),
                };
                vec![Message::new(format!("{topic}/particles"), &m)]
            }
            AnyMsg::PlannerWaypoints(w) => {
                let m = PosesInFrame {
                    timestamp: Some(stamp(ns)),
                    frame_id: MAP_FRAME.to_owned(),
                    poses: w.waypoints.iter().map(|&p| pose2(p)).collect(),
                };
                vec![Message::new(format!("{topic}/path"), &m).latched()]
            }
            AnyMsg::MapInfo(i) => {
                self.map_info.insert(dev, *i);
                vec![]
            }
            AnyMsg::MapData(d) => {
                let whole = self.map_info.get(&dev).copied().filter(|i| {
                    d.col == 0 && d.row == 0 && d.width == i.width && d.height == i.height
                });
                match whole {
                    Some(info) => vec![Message::new(topic, &grid(ns, &info, &d.cells)).latched()],
                    // A tile, or cells of no known shape.
                    None => vec![json(topic, msg)],
                }
            }
            AnyMsg::LaserGeom(troupe_msgs::laser::Geom { pose, .. })
            | AnyMsg::RangerGeom(troupe_msgs::ranger::Geom { pose, .. }) => {
                if let AnyMsg::RangerGeom(g) = msg {
                    self.ranger_elements.insert(dev, g.element_poses.len());
                }
                let t = transform(ns, base, device_frame(&dev), pose);
                self.fixed.insert(t.child_frame_id.clone(), t);
                let transforms = self.fixed.values().cloned().collect();
                vec![Message::new(TF_STATIC.to_owned(), &FrameTransforms { transforms }).latched()]
            }
            AnyMsg::SimulationWorld(w) => {
                let still = w
                    .models
                    .iter()
                    .enumerate()
                    .filter(|(_, m)| !m.moves)
                    .filter_map(|(i, m)| entity(ns, i, m, m.pose))
                    .collect();
                let moving = w
                    .models
                    .iter()
                    .enumerate()
                    .filter(|(_, m)| m.moves)
                    .filter_map(|(i, m)| entity(ns, i, m, m.pose))
                    .collect();
                self.worlds.insert(dev, w.clone());
                vec![
                    Message::new(format!("{topic}/world"), &scene(still)).latched(),
                    Message::new(format!("{topic}/scene"), &scene(moving)),
                ]
            }
            AnyMsg::SimulationPoses(p) => {
                let Some(w) = self.worlds.get(&dev) else {
                    return vec![json(topic, msg)];
                };
                let moving = p
                    .poses
                    .iter()
                    .filter_map(|&(id, pose)| {
                        let m = w.models.get(id as usize)?;
                        entity(ns, id as usize, m, pose)
                    })
                    .collect();
                vec![Message::new(format!("{topic}/scene"), &scene(moving))]
            }
            other => vec![json(topic, other)],
        }
    }
}

/// A sample with no Foxglove schema, as JSON on its device's topic and kind.
fn json(topic: String, msg: &AnyMsg) -> Message {
    let tag = msg.schema();
    let mut data = Vec::new();
    // A message body always serializes to JSON.
    let _ = msg.serialize_body(&mut serde_json::Serializer::new(&mut data));
    Message {
        topic: json_topic(&topic, tag),
        kind: Kind::Json(tag),
        data,
        latched: false,
    }
}

fn tf(transforms: Vec<FrameTransform>) -> Message {
    Message::new(TF.to_owned(), &FrameTransforms { transforms })
}

/// A map's cells as a grid of ROS's occupancy values, which Foxglove's map
/// colour mode reads.
fn grid(ns: u64, info: &map::Info, cells: &[i8]) -> Grid {
    let cells: Vec<u8> = cells
        .iter()
        .map(|&c| match c.signum() {
            -1 => 0u8,
            1 => 100,
            _ => 0xff,
        })
        .collect();
    Grid {
        timestamp: Some(stamp(ns)),
        frame_id: MAP_FRAME.to_owned(),
        pose: Some(pose2(info.origin)),
        column_count: info.width,
        cell_size: Some(Vector2 {
            x: f64::from(info.resolution),
            y: f64::from(info.resolution),
        }),
        row_stride: info.width,
        cell_stride: 1,
        fields: vec![PackedElementField {
            name: "occupancy".into(),
            offset: 0,
            r#type: NumericType::Int8 as i32,
        }],
        data: cells.into(),
    }
}

fn scene(entities: Vec<SceneEntity>) -> SceneUpdate {
    SceneUpdate {
        deletions: vec![],
        entities,
    }
}

/// A model as an entity: its body's edges, in its colour, where it stands.
fn entity(ns: u64, id: usize, m: &simulation::Model, pose: [f32; 3]) -> Option<SceneEntity> {
    if m.polys.is_empty() {
        return None;
    }
    let mut points = Vec::new();
    for poly in &m.polys {
        for (i, a) in poly.iter().enumerate() {
            let b = poly[(i + 1) % poly.len()];
            for p in [a, &b] {
                points.push(Point3 {
                    x: f64::from(p[0]),
                    y: f64::from(p[1]),
                    z: 0.0,
                });
            }
        }
    }
    let c = m.color;
    Some(SceneEntity {
        timestamp: Some(stamp(ns)),
        frame_id: MAP_FRAME.to_owned(),
        id: format!("{id}:{}", m.name),
        lines: vec![LinePrimitive {
            r#type: line_primitive::Type::LineList as i32,
            pose: Some(pose2(Pose2d {
                x: f64::from(pose[0]),
                y: f64::from(pose[1]),
                yaw: f64::from(pose[2]),
            })),
            thickness: 2.0,
            scale_invariant: true,
            points,
            color: Some(Color {
                r: f64::from(c.r),
                g: f64::from(c.g),
                b: f64::from(c.b),
                a: f64::from(c.a),
            }),
            colors: vec![],
            indices: vec![],
        }],
        ..SceneEntity::default()
    })
}

#[cfg(test)]
mod tests;
