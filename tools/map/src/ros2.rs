//! ROS 2 bags in MCAP (what `ros2 bag record -s mcap` writes, and
//! `troupe record --format ros2`): `sensor_msgs/msg/LaserScan` and
//! `nav_msgs/msg/Odometry` in CDR, and the laser's mount on the robot from
//! `/tf_static`.
//!
//! A topic named as Troupe names its devices (`/robot_6665/laser_0`) is
//! that device; any other (`/scan`, `/odom`) becomes one of robot 6665,
//! numbered in the order the bag first shows it, and is chosen by its
//! name (`--scan /scan`). Scans and odometry become Troupe's as `troupe
//! play` makes them (`troupe_ros2::back`): a LaserScan's readings by ROS's
//! rules (REP 117), `+inf` or above `range_max` no return, `-inf`, NaN or
//! below `range_min` no reading.

use std::collections::BTreeMap;

use troupe_geom::Pose;
use troupe_msgs::{AnyMsg, Device, Interface, DEFAULT_ROBOT};
use troupe_ros2::msg::{LaserScan, Odometry, TfMessage, Transform};
use troupe_ros2::{back, Type};

use crate::source::{Entry, Problems};

/// The encoding of a ROS 2 message in MCAP.
pub(crate) const CDR: &str = "cdr";

/// What a bag says beyond its messages: which device each topic is, the
/// frames the scans and the odometry are in, and the static transforms.
#[derive(Debug, Default)]
pub(crate) struct Bag {
    /// Topic → device.
    pub(crate) topics: BTreeMap<String, Device>,
    /// A scan's `frame_id` or an odometry's `child_frame_id`, by device.
    frames: BTreeMap<Device, String>,
    /// Child frame → (parent frame, its pose in the parent).
    tf: BTreeMap<String, (String, Pose)>,
}

impl Bag {
    /// The device topic `topic` of interface `interface` is.
    fn device(&mut self, topic: &str, interface: Interface) -> Device {
        if let Some(d) = self.topics.get(topic) {
            return *d;
        }
        let named = troupe_ros2::back::key_of_topic(topic)
            .and_then(|k| troupe_msgs::keys::parse_data(&k).ok())
            .filter(|d| d.interface == interface);
        let d = named.unwrap_or_else(|| Device {
            robot: DEFAULT_ROBOT,
            interface,
            index: self
                .topics
                .values()
                .filter(|d| d.robot == DEFAULT_ROBOT && d.interface == interface)
                .count() as u32,
        });
        self.topics.insert(topic.to_owned(), d);
        d
    }

    /// The topic of device `d`, where it came from a bag.
    pub(crate) fn topic_of(&self, d: Device) -> Option<&str> {
        self.topics
            .iter()
            .find(|(_, v)| **v == d)
            .map(|(t, _)| t.as_str())
    }

    /// Where the sensor of `scan` sits on the robot whose odometry is
    /// `odom`: the static transforms from the odometry's child frame to the
    /// scan's frame. `None` if the bag does not hold them; `Err` says why
    /// for a bag that names the frames but lacks the chain.
    pub(crate) fn mount(&self, odom: Device, scan: Device) -> Option<Result<Pose, String>> {
        let base = self.frames.get(&odom)?;
        let sensor = self.frames.get(&scan)?;
        // Up from the sensor's frame until the robot's.
        let mut pose = Pose::default();
        let mut at = sensor.as_str();
        for _ in 0..32 {
            if at == base {
                return Some(Ok(pose));
            }
            let Some((parent, p)) = self.tf.get(at) else {
                break;
            };
            pose = p.compose(&pose);
            at = parent;
        }
        Some(Err(format!(
            "no chain of /tf_static transforms from the odometry's `{base}` to the scans' `{sensor}`"
        )))
    }
}

fn planar(t: &Transform) -> Pose {
    Pose::new(t.translation.x, t.translation.y, t.rotation.yaw())
}

/// Takes one ROS 2 message (`schema`, CDR `data`, on `topic`): a scan or
/// odometry becomes an entry, a static transform is kept; anything else
/// is passed over.
pub(crate) fn message(
    bag: &mut Bag,
    topic: &str,
    schema: &str,
    data: &[u8],
    place: impl FnOnce() -> String,
    out: &mut Vec<Entry>,
    problems: &mut Problems,
) {
    let Some(ty) = Type::from_name(schema) else {
        return;
    };
    let bad = |problems: &mut Problems, e: cdr::Error, place: String| {
        problems.add(&format!("cdr {schema}"), || {
            format!("{place} on {topic}: not a {schema} in CDR ({e}); skipped")
        });
    };
    match ty {
        Type::LaserScan => match cdr::deserialize::<LaserScan>(data) {
            Ok(s) => {
                let device = bag.device(topic, Interface::Laser);
                bag.frames.insert(device, s.header.frame_id.clone());
                out.push(Entry {
                    t: s.header.stamp.secs(),
                    device,
                    msg: AnyMsg::LaserScan(back::laser_scan(&s)),
                    place: format!("{} on {topic}", place()),
                });
            }
            Err(e) => bad(problems, e, place()),
        },
        Type::Odometry => match cdr::deserialize::<Odometry>(data) {
            Ok(o) => {
                let device = bag.device(topic, Interface::Position2d);
                bag.frames.insert(device, o.child_frame_id.clone());
                out.push(Entry {
                    t: o.header.stamp.secs(),
                    device,
                    msg: AnyMsg::Position2dData(back::odometry(&o)),
                    place: format!("{} on {topic}", place()),
                });
            }
            Err(e) => bad(problems, e, place()),
        },
        Type::TfMessage if topic == "/tf_static" => match cdr::deserialize::<TfMessage>(data) {
            Ok(m) => {
                for t in m.transforms {
                    bag.tf
                        .insert(t.child_frame_id, (t.header.frame_id, planar(&t.transform)));
                }
            }
            Err(e) => bad(problems, e, place()),
        },
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;
    use std::path::{Path, PathBuf};

    use troupe_ros2::msg::{Header, Quaternion, Time, TransformStamped, Vector3};

    use super::*;
    use crate::simulate::{simulate, Driver, Setup};
    use crate::source::{self, Pick, Recording, Scan, Select};

    fn stamp(t: f64) -> Time {
        Time::from_ns((t * 1e9).round() as u64)
    }

    /// `rec` as a ROS 2 robot's bag holds it: `/odom` of `base_footprint`,
    /// `/scan` in `laser`, the laser mounted through `base_link` on
    /// `/tf_static`, no-return beams as `+inf`; and a second laser.
    fn write_bag(path: &Path, rec: &Recording) {
        let mut w = mcap::Writer::new(std::io::BufWriter::new(
            std::fs::File::create(path).unwrap(),
        ))
        .unwrap();
        let channel = |w: &mut mcap::Writer<_>, ty: Type, topic: &str| {
            let schema = w
                .add_schema(ty.name(), "ros2msg", ty.definition().as_bytes())
                .unwrap();
            w.add_channel(schema, topic, CDR, &BTreeMap::new()).unwrap()
        };
        let (odom, scan, rear_scan, tf) = (
            channel(&mut w, Type::Odometry, "/odom"),
            channel(&mut w, Type::LaserScan, "/scan"),
            channel(&mut w, Type::LaserScan, "/rear_scan"),
            channel(&mut w, Type::TfMessage, "/tf_static"),
        );
        let mut seq = 0;
        let mut put = |w: &mut mcap::Writer<_>, channel_id: u16, t: f64, data: Vec<u8>| {
            seq += 1;
            let ns = (t * 1e9).round() as u64;
            w.write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id,
                    sequence: seq,
                    log_time: ns,
                    publish_time: ns,
                },
                &data,
            )
            .unwrap();
        };
        let link = |parent: &str, child: &str, x: f64, y: f64, yaw: f64| TransformStamped {
            header: Header {
                stamp: stamp(0.0),
                frame_id: parent.into(),
            },
            child_frame_id: child.into(),
            transform: Transform {
                translation: Vector3 { x, y, z: 0.1 },
                rotation: Quaternion::from_rpy(0.0, 0.0, yaw),
            },
        };
        let s = rec.sensor;
        let mounts = TfMessage {
            transforms: vec![
                link("base_footprint", "base_link", 0.05, 0.0, 0.0),
                link("base_link", "laser", s.x - 0.05, s.y, s.yaw),
            ],
        };
        put(&mut w, tf, 0.0, troupe_ros2::cdr(&mounts));
        let (mut o, mut k) = (rec.odom.iter().peekable(), rec.scans.iter().peekable());
        loop {
            let odom_first = match (o.peek(), k.peek()) {
                (Some(a), Some(b)) => a.t <= b.t,
                (a, _) => a.is_some(),
            };
            if odom_first {
                let Some(x) = o.next() else { break };
                let mut m = Odometry {
                    header: Header {
                        stamp: stamp(x.t),
                        frame_id: "odom".into(),
                    },
                    child_frame_id: "base_footprint".into(),
                    ..Default::default()
                };
                m.pose.pose.position = Vector3 {
                    x: x.pose.x,
                    y: x.pose.y,
                    z: 0.0,
                };
                m.pose.pose.orientation = Quaternion::from_rpy(0.0, 0.0, x.pose.yaw);
                put(&mut w, odom, x.t, troupe_ros2::cdr(&m));
            } else {
                let Some(x) = k.next() else { break };
                let beams = x.ranges.len() as f64;
                let m = LaserScan {
                    header: Header {
                        stamp: stamp(x.t),
                        frame_id: "laser".into(),
                    },
                    angle_min: x.min_angle as f32,
                    angle_max: (x.min_angle + x.step * (beams - 1.0)) as f32,
                    angle_increment: x.step as f32,
                    range_min: 0.02,
                    range_max: x.max_range as f32,
                    ranges: x
                        .ranges
                        .iter()
                        .map(|&r| {
                            if f64::from(r) >= x.max_range {
                                f32::INFINITY
                            } else {
                                r
                            }
                        })
                        .collect(),
                    ..Default::default()
                };
                put(&mut w, scan, x.t, troupe_ros2::cdr(&m));
                let rear = LaserScan {
                    header: Header {
                        stamp: stamp(x.t),
                        frame_id: "rear_laser".into(),
                    },
                    ..m
                };
                put(&mut w, rear_scan, x.t, troupe_ros2::cdr(&rear));
            }
        }
        w.finish().unwrap();
    }

    fn dir() -> PathBuf {
        let d = std::env::temp_dir().join(format!("troupe-map-ros2-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn a_ros2_bag_reads_as_the_player_log_of_the_same_run() {
        let world = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../worlds/wander.world");
        let run = simulate(
            troupe_stage::world::load(&world).unwrap(),
            &Setup {
                robot: "r0".into(),
                seconds: 120.0,
                odom_error: [0.02, 0.0, 0.04],
                every: 0.1,
                driver: Driver::Own,
            },
        )
        .unwrap();
        let d = dir();
        let log = d.join("run.log");
        std::fs::write(&log, &run.log).unwrap();
        let mut player = source::read(&[log], &Select::default()).unwrap();
        // A laser mounted ahead of the centre, a little left and turned.
        player.sensor = Pose::new(0.13, 0.02, 0.05);
        assert!(player
            .scans
            .iter()
            .any(|s| s.ranges.iter().any(|&r| f64::from(r) >= s.max_range)));
        let bag = d.join("run.mcap");
        write_bag(&bag, &player);

        // Two LaserScan topics: the choice is the user's, by name.
        let err = source::read(std::slice::from_ref(&bag), &Select::default()).unwrap_err();
        assert!(
            err.to_string().contains("several scanning devices"),
            "{err}"
        );
        let pick = |t: &str| Some(t.parse::<Pick>().unwrap());
        let wrong = Select {
            odom: None,
            scan: pick("/front"),
        };
        let err = source::read(std::slice::from_ref(&bag), &wrong).unwrap_err();
        assert!(
            err.to_string().contains("--scan /front")
                && err.to_string().contains("/odom, /rear_scan, /scan"),
            "{err}"
        );
        let select = Select {
            odom: pick("/odom"),
            scan: pick("/scan"),
        };
        let ros = source::read(std::slice::from_ref(&bag), &select).unwrap();
        assert_eq!(ros.odom.len(), player.odom.len());
        assert_eq!(ros.scans.len(), player.scans.len());
        for (a, b) in ros.odom.iter().zip(&player.odom) {
            assert!((a.t - b.t).abs() < 1e-6);
            let d = a.pose.inverse().compose(&b.pose);
            assert!(d.x.hypot(d.y) < 1e-6 && d.yaw.abs() < 1e-6, "{a:?} {b:?}");
        }
        // +inf read as no return, at the scan's maximum, as Player logs it.
        for (a, b) in ros.scans.iter().zip(&player.scans) {
            assert!((a.t - b.t).abs() < 1e-6, "scan at {} read at {}", b.t, a.t);
            let same = Scan {
                t: b.t,
                step: b.step,
                ..a.clone()
            };
            assert!(
                same == *b && (a.step - b.step).abs() < 1e-6,
                "the scan at {} reads otherwise",
                b.t
            );
        }
        // The mount, through base_link.
        let (a, b) = (ros.sensor, player.sensor);
        assert!(
            (a.x - b.x).abs() < 1e-6 && (a.y - b.y).abs() < 1e-6 && (a.yaw - b.yaw).abs() < 1e-6,
            "{a:?} {b:?}"
        );
        assert!(ros.warnings.is_empty(), "{:?}", ros.warnings);
        assert!(
            ros.describe().contains("/scan as 6665:laser:0"),
            "{}",
            ros.describe()
        );

        // The rear laser's frame has no transform: said once, and read at
        // the robot's centre.
        let rear = Select {
            odom: pick("/odom"),
            scan: pick("/rear_scan"),
        };
        let ros = source::read(std::slice::from_ref(&bag), &rear).unwrap();
        assert_eq!(ros.sensor, Pose::default());
        assert_eq!(ros.warnings.len(), 1, "{:?}", ros.warnings);
        assert!(
            ros.warnings[0].contains("`rear_laser`"),
            "{:?}",
            ros.warnings
        );
    }

    #[test]
    fn a_bad_message_is_said_once_with_its_count() {
        let (mut bag, mut out, mut problems) = (Bag::default(), Vec::new(), Problems::default());
        for n in 0..3 {
            message(
                &mut bag,
                "/scan",
                Type::LaserScan.name(),
                &[0, 1, 0, 0, 7],
                || format!("bag.mcap: message {n}"),
                &mut out,
                &mut problems,
            );
        }
        assert!(out.is_empty());
        let lines = problems.lines();
        assert_eq!(lines.len(), 1, "{lines:?}");
        assert!(
            lines[0].starts_with("bag.mcap: message 0 on /scan: not a sensor_msgs/msg/LaserScan")
                && lines[0].ends_with("(and 2 more like it)"),
            "{lines:?}"
        );
    }
}
