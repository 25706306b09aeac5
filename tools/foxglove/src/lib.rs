//! `troupe foxglove`: the fleet live in Foxglove, over Foxglove's WebSocket
//! protocol, served by the official Foxglove SDK.
//!
//! Every device of the namespace is a channel named by its key
//! (`/robot/6665/laser/0`), with one of Foxglove's schemas where one fits:
//!
//! ```text
//! laser scan                 foxglove.LaserScan       in robot_6665/laser_0
//! position2d data            foxglove.PoseInFrame     in robot_6665/odom, and /tf odom -> base_link
//! localize hypotheses        foxglove.PoseInFrame     in map, and /tf map -> odom
//! localize particles         foxglove.PosesInFrame    /robot/6665/localize/0/particles
//! a map (asked as it comes)  foxglove.Grid            in map
//! a sensor's geometry        foxglove.FrameTransforms /tf_static: base_link -> the sensor
//! anything else              JSON                     /robot/6665/ranger/0/ranges: the key and the kind
//! ```
//!
//! Frames are those of `--format ros2` recordings (troupe-ros2), so a live
//! view and a recording look alike. What publishes rarely (a map, the fixed
//! transforms, a localizer's estimate) is given again to each client that
//! subscribes, as a latched topic. The server's time is the simulation's.
//! Devices that go are unadvertised. A client may publish (JSON) a velocity
//! on `/robot/6665/position2d/0/cmd_vel` (`{"linear": {"x": …}, "angular":
//! {"z": …}}`, as Foxglove's teleop panel sends) or a goal on
//! `/robot/6665/planner/0/goal` (`{"pose": {"position": …, "orientation":
//! …}}`); they go out as this process's commands, so a fleet's access rules
//! decide whether they pass.

use std::collections::HashMap;
use std::sync::mpsc::{Receiver, SyncSender};
use std::sync::{Arc, Mutex};

use anyhow::Context as _;
use clap::Args;
use foxglove::schemas::{
    packed_element_field::NumericType, FrameTransform, FrameTransforms, Grid, LaserScan,
    PackedElementField, Pose, PoseInFrame, PosesInFrame, Quaternion, Timestamp, Vector2, Vector3,
};
use foxglove::websocket::{Capability, Client, ClientChannel, ServerListener};
use foxglove::{Context, Encode, PartialMetadata, RawChannel, Schema};
use troupe_msgs::{
    codec, decode_any, keys, localize, map, planner, position2d, AnyMsg, Device, Interface, Pose2d,
    Pose3d,
};
use troupe_node::zenoh::{sample::SampleKind, Session, Wait};
use troupe_node::{Mode, ZenohArgs};
use troupe_ros2::{
    device_frame, json_schema, json_topic, odom_in_map, robot_frame, stamp_ns, MAP_FRAME,
};

/// Flags of `troupe foxglove`.
#[derive(Debug, Args)]
pub struct FoxgloveArgs {
    /// The address to listen on. The protocol has no authentication: keep
    /// it on loopback unless the network is yours.
    #[arg(long, default_value = "127.0.0.1")]
    pub bind: String,
    /// The port (0: any free one, printed).
    #[arg(long, default_value_t = 8765)]
    pub port: u16,
}

/// The topic of moving transforms.
pub const TF: &str = "/tf";
/// The topic of fixed transforms (sensors on their robot), latched.
pub const TF_STATIC: &str = "/tf_static";

/// The newest message of each topic that publishes rarely (a map, the fixed
/// transforms, a localizer's estimate), given again to each client that
/// subscribes, as a latched ROS topic would: the protocol has no history.
type Latched = Arc<Mutex<HashMap<String, (Arc<RawChannel>, Vec<u8>, u64)>>>;

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// What the server hears from the network.
enum Heard {
    Sample { key: String, payload: Vec<u8> },
    Came(Device),
    Went(Device),
    Stop,
}

/// `troupe foxglove`: serves until Ctrl-C or SIGTERM.
///
/// # Errors
///
/// The network cannot be joined or the port cannot be bound.
pub fn serve(a: &FoxgloveArgs, z: &ZenohArgs) -> anyhow::Result<()> {
    let session = z.open(Mode::Client)?;
    let ctx = Context::new();
    let latched = Latched::default();
    let server = ctx
        .websocket_server()
        .name("troupe")
        .bind(a.bind.clone(), a.port)
        .capabilities([Capability::ClientPublish, Capability::Time])
        .supported_encodings(["json"])
        .listener(Arc::new(Commands::new(session.clone(), latched.clone())))
        .start_blocking()
        .with_context(|| format!("serving Foxglove on {}:{}", a.bind, a.port))?;

    let (tx, rx) = std::sync::mpsc::sync_channel::<Heard>(10_000);
    let mut subs = Vec::new();
    for e in ["robot/*/*/*", keys::SIM_CLOCK] {
        let tx = tx.clone();
        let sub = session
            .declare_subscriber(e)
            .callback(move |s| {
                // A full queue drops the newest: live data, the next one comes.
                let _ = tx.try_send(Heard::Sample {
                    key: s.key_expr().as_str().to_owned(),
                    payload: s.payload().to_bytes().into_owned(),
                });
            })
            .wait()
            .map_err(|err| anyhow::anyhow!("subscribing to {e}: {err}"))?;
        subs.push(sub);
    }
    let tokens = {
        let tx = tx.clone();
        session
            .liveliness()
            .declare_subscriber("robot/**")
            .history(true)
            .callback(move |s| {
                if let Ok((dev, _)) = keys::parse_token(s.key_expr().as_str()) {
                    let h = if s.kind() == SampleKind::Put {
                        Heard::Came(dev)
                    } else {
                        Heard::Went(dev)
                    };
                    // Blocking: a device's coming or going is not to be lost.
                    let _ = tx.send(h);
                }
            })
            .wait()
            .map_err(|e| anyhow::anyhow!("watching liveliness: {e}"))?
    };
    {
        let tx = tx.clone();
        std::thread::spawn(move || {
            let _ = troupe_node::process::wait_for_signal();
            let _ = tx.send(Heard::Stop);
        });
    }
    // On stdout once the port is bound: a script may connect when it appears.
    println_out(&format!(
        "troupe foxglove: ws://{}:{} (open it in Foxglove: Open connection, Foxglove WebSocket; Ctrl-C stops)",
        a.bind,
        server.port()
    ));
    let mut live = Live::new(ctx, session.clone(), tx, latched);
    live.run(&rx, &server);
    drop(subs);
    drop(tokens);
    let _ = server.stop();
    Ok(())
}

#[allow(clippy::print_stdout)]
fn println_out(line: &str) {
    println!("{line}");
}

fn stamp(ns: u64) -> Timestamp {
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

/// The channels and what later samples need to know.
struct Live {
    ctx: Arc<Context>,
    session: Session,
    tx: SyncSender<Heard>,
    channels: HashMap<String, Arc<RawChannel>>,
    odom: HashMap<u32, Pose2d>,
    map_info: HashMap<Device, map::Info>,
    /// Every sensor's place on its robot, by the sensor's frame.
    fixed: HashMap<String, FrameTransform>,
    latched: Latched,
    buf: Vec<u8>,
}

impl Live {
    fn new(ctx: Arc<Context>, session: Session, tx: SyncSender<Heard>, latched: Latched) -> Live {
        Live {
            ctx,
            session,
            tx,
            channels: HashMap::new(),
            odom: HashMap::new(),
            map_info: HashMap::new(),
            fixed: HashMap::new(),
            latched,
            buf: Vec::new(),
        }
    }

    fn run(&mut self, rx: &Receiver<Heard>, server: &foxglove::WebSocketServerHandle) {
        for h in rx {
            match h {
                Heard::Stop => return,
                Heard::Came(dev) => self.ask(dev),
                Heard::Went(dev) => self.close(&dev),
                Heard::Sample { key, payload } => {
                    let Ok(s) = decode_any(&payload) else {
                        continue;
                    };
                    let ns = stamp_ns(s.stamp);
                    if let AnyMsg::SimClock(_) = s.msg {
                        server.broadcast_time(ns);
                        continue;
                    }
                    self.sample(&key, ns, &s.msg);
                }
            }
        }
    }

    /// What a Player client asks once (a map's grid, a sensor's
    /// geometry), asked off this thread; the answers come back as samples.
    fn ask(&self, dev: Device) {
        let (session, tx) = (self.session.clone(), self.tx.clone());
        std::thread::spawn(move || {
            for payload in troupe_node::setup_answers(&session, &dev) {
                let _ = tx.send(Heard::Sample {
                    key: keys::data(&dev),
                    payload,
                });
            }
        });
    }

    /// Unadvertises every channel of a device that went.
    fn close(&mut self, dev: &Device) {
        let topic = format!("/{}", keys::data(dev));
        let prefix = format!("{topic}/");
        let gone = |t: &str| t == topic || t.starts_with(&prefix);
        self.channels.retain(|t, c| {
            if gone(t) {
                c.close();
            }
            !gone(t)
        });
        lock(&self.latched).retain(|t, _| !gone(t));
        self.map_info.remove(dev);
    }

    /// Logs `msg` and keeps it for the clients that subscribe later.
    fn log_latched<T: Encode>(&mut self, topic: &str, msg: &T, ns: u64) {
        self.log(topic, msg, ns);
        if let Some(ch) = self.channels.get(topic) {
            lock(&self.latched).insert(topic.to_owned(), (ch.clone(), self.buf.clone(), ns));
        }
    }

    /// The channel of `topic`, made (and advertised) with its first
    /// message, of the encoding and schema `kind` gives.
    fn channel(
        &mut self,
        topic: &str,
        kind: impl FnOnce() -> (String, Option<Schema>),
    ) -> Option<Arc<RawChannel>> {
        if let Some(c) = self.channels.get(topic) {
            return Some(c.clone());
        }
        let (encoding, schema) = kind();
        let built = self
            .ctx
            .channel_builder(topic)
            .message_encoding(encoding)
            .schema(schema)
            .build_raw();
        match built {
            Ok(c) => {
                self.channels.insert(topic.to_owned(), c.clone());
                Some(c)
            }
            Err(e) => {
                tracing::warn!("{topic}: {e}");
                None
            }
        }
    }

    fn log<T: Encode>(&mut self, topic: &str, msg: &T, ns: u64) {
        let Some(ch) = self.channel(topic, || (T::get_message_encoding(), T::get_schema())) else {
            return;
        };
        self.buf.clear();
        if msg.encode(&mut self.buf).is_ok() {
            ch.log_with_meta(&self.buf, PartialMetadata { log_time: Some(ns) });
        }
    }

    fn json(&mut self, topic: &str, tag: &'static str, msg: &AnyMsg, ns: u64) {
        let kind = || {
            let schema = Schema::new(tag, "jsonschema", json_schema(tag).into_bytes());
            ("json".to_owned(), Some(schema))
        };
        let Some(ch) = self.channel(topic, kind) else {
            return;
        };
        self.buf.clear();
        if msg
            .serialize_body(&mut serde_json::Serializer::new(&mut self.buf))
            .is_ok()
        {
            ch.log_with_meta(&self.buf, PartialMetadata { log_time: Some(ns) });
        }
    }

    fn tf(&mut self, ns: u64, transforms: Vec<FrameTransform>) {
        self.log(TF, &FrameTransforms { transforms }, ns);
    }

    /// A sensor's place on its robot: the whole set of them, latched.
    fn fixed(&mut self, ns: u64, t: FrameTransform) {
        self.fixed.insert(t.child_frame_id.clone(), t);
        let mut transforms: Vec<FrameTransform> = self.fixed.values().cloned().collect();
        transforms.sort_by(|a, b| a.child_frame_id.cmp(&b.child_frame_id));
        self.log_latched(TF_STATIC, &FrameTransforms { transforms }, ns);
    }

    fn sample(&mut self, key: &str, ns: u64, msg: &AnyMsg) {
        let Ok(dev) = keys::parse_data(key) else {
            return;
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
                self.log(&topic, &m, ns);
            }
            AnyMsg::Position2dData(position2d::Data { pose, .. }) => {
                let odom = robot_frame(dev.robot, "odom");
                let m = PoseInFrame {
                    timestamp: Some(stamp(ns)),
                    frame_id: odom.clone(),
                    pose: Some(pose2(*pose)),
                };
                self.log(&topic, &m, ns);
                if dev.index == 0 {
                    self.odom.insert(dev.robot, *pose);
                    self.tf(ns, vec![transform(ns, odom, base, &flat(*pose))]);
                }
            }
            AnyMsg::LocalizeHypoths(hs) => {
                let Some(best) = hs.hypoths.first() else {
                    return;
                };
                let m = PoseInFrame {
                    timestamp: Some(stamp(ns)),
                    frame_id: MAP_FRAME.to_owned(),
                    pose: Some(pose2(best.mean)),
                };
                self.log_latched(&topic, &m, ns);
                if let Some(&odom) = self.odom.get(&dev.robot) {
                    let t = transform(
                        ns,
                        MAP_FRAME.to_owned(),
                        robot_frame(dev.robot, "odom"),
                        &flat(odom_in_map(best.mean, odom)),
                    );
                    self.tf(ns, vec![t]);
                }
            }
            AnyMsg::LocalizeParticles(localize::Particles { particles, .. }) => {
                let m = PosesInFrame {
                    timestamp: Some(stamp(ns)),
                    frame_id: MAP_FRAME.to_owned(),
                    poses: particles.iter().map(|p| pose2(p.pose)).collect(),
                };
                self.log(&format!("{topic}/particles"), &m, ns);
            }
            AnyMsg::MapInfo(i) => {
                self.map_info.insert(dev, *i);
            }
            AnyMsg::MapData(d) => {
                let Some(info) = self.map_info.get(&dev).copied() else {
                    return;
                };
                if d.col != 0 || d.row != 0 || d.width != info.width || d.height != info.height {
                    return;
                }
                // ROS's occupancy values, which Foxglove's map color mode reads.
                let cells = d.cells.iter().map(|&c| match c.signum() {
                    -1 => 0u8,
                    1 => 100,
                    _ => 0xff,
                });
                let m = Grid {
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
                    data: cells.collect::<Vec<u8>>().into(),
                };
                self.log_latched(&topic, &m, ns);
            }
            AnyMsg::LaserGeom(troupe_msgs::laser::Geom { pose, .. })
            | AnyMsg::RangerGeom(troupe_msgs::ranger::Geom { pose, .. }) => {
                let t = transform(ns, base, device_frame(&dev), pose);
                self.fixed(ns, t);
            }
            other => {
                let tag = other.schema();
                self.json(&json_topic(&topic, tag), tag, other, ns);
            }
        }
    }
}

/// What clients publish, turned into commands: a velocity (Foxglove's
/// teleop panel) or a planner goal (its 3D panel's published pose).
struct Commands {
    session: Session,
    latched: Latched,
    refused: Mutex<HashMap<String, u64>>,
}

impl Commands {
    fn new(session: Session, latched: Latched) -> Commands {
        Commands {
            session,
            latched,
            refused: Mutex::new(HashMap::new()),
        }
    }
}

impl ServerListener for Commands {
    fn on_subscribe(&self, client: Client, channel: foxglove::websocket::ChannelView) {
        if let Some((ch, bytes, ns)) = lock(&self.latched).get(channel.topic()) {
            ch.log_with_meta_to_sink(
                bytes,
                PartialMetadata {
                    log_time: Some(*ns),
                },
                client.sink_id(),
            );
        }
    }

    fn on_message_data(&self, _client: Client, channel: &ClientChannel, payload: &[u8]) {
        let sent = command_of(&channel.topic, &channel.encoding, payload).and_then(|(key, cmd)| {
            self.session
                .put(&key, cmd)
                .wait()
                .map_err(|e| format!("sending on {key}: {e}"))
        });
        if let Err(why) = sent {
            let mut refused = lock(&self.refused);
            let n = refused.entry(channel.topic.clone()).or_default();
            *n += 1;
            // Said once per topic: a panel publishes many times a second.
            if *n == 1 {
                tracing::warn!(
                    "a Foxglove client's message on {} left out: {why}",
                    channel.topic
                );
            }
        }
    }
}

/// The command key and payload a client's message on `topic` makes.
///
/// # Errors
///
/// Why it makes none, said for the client's user.
pub fn command_of(
    topic: &str,
    encoding: &str,
    payload: &[u8],
) -> Result<(String, Vec<u8>), String> {
    if encoding != "json" {
        return Err(format!("`{encoding}` messages are not read: publish JSON"));
    }
    let (device, what) = topic
        .trim_start_matches('/')
        .rsplit_once('/')
        .ok_or_else(|| "expected /robot/PORT/INTERFACE/INDEX/cmd_vel or …/goal".to_owned())?;
    let dev = keys::parse_data(device).map_err(|e| format!("{device}: {e}"))?;
    let v: serde_json::Value =
        serde_json::from_slice(payload).map_err(|e| format!("not JSON: {e}"))?;
    let f = |path: &[&str]| {
        path.iter()
            .try_fold(&v, |v, k| v.get(k))
            .and_then(serde_json::Value::as_f64)
            .unwrap_or(0.0)
    };
    let now = troupe_node::Clock::wall().now();
    match (dev.interface, what) {
        (Interface::Position2d, "cmd_vel") => {
            let cmd = position2d::CmdVel {
                vel: Pose2d {
                    x: f(&["linear", "x"]),
                    y: f(&["linear", "y"]),
                    yaw: f(&["angular", "z"]),
                },
                state: true,
            };
            Ok((keys::cmd(&dev, "vel"), codec::encode(&cmd, now)))
        }
        (Interface::Planner, "goal") => {
            let q = troupe_ros2::msg::Quaternion {
                x: f(&["pose", "orientation", "x"]),
                y: f(&["pose", "orientation", "y"]),
                z: f(&["pose", "orientation", "z"]),
                w: v.pointer("/pose/orientation/w")
                    .and_then(serde_json::Value::as_f64)
                    .unwrap_or(1.0),
            };
            let goal = planner::Goal {
                goal: Pose2d {
                    x: f(&["pose", "position", "x"]),
                    y: f(&["pose", "position", "y"]),
                    yaw: q.yaw(),
                },
            };
            Ok((keys::cmd(&dev, "goal"), codec::encode(&goal, now)))
        }
        _ => Err(format!(
            "{topic}: only a position2d's …/cmd_vel and a planner's …/goal take commands"
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_teleop_twist_is_a_velocity_command() {
        let (key, cmd) = command_of(
            "/robot/6665/position2d/0/cmd_vel",
            "json",
            br#"{"linear": {"x": 0.3, "y": 0, "z": 0}, "angular": {"x": 0, "y": 0, "z": 0.2}}"#,
        )
        .unwrap();
        assert_eq!(key, "robot/6665/position2d/0/cmd/vel");
        let c: position2d::CmdVel = codec::decode(&cmd).unwrap().msg;
        assert_eq!((c.vel.x, c.vel.yaw, c.state), (0.3, 0.2, true));
    }

    #[test]
    fn a_published_pose_is_a_goal_and_nothing_else_commands() {
        let (key, cmd) = command_of(
            "/robot/6665/planner/0/goal",
            "json",
            br#"{"pose": {"position": {"x": 5, "y": -1}, "orientation": {"z": 0.7071067811865476, "w": 0.7071067811865476}}}"#,
        )
        .unwrap();
        assert_eq!(key, "robot/6665/planner/0/cmd/goal");
        let g: planner::Goal = codec::decode(&cmd).unwrap().msg;
        assert_eq!((g.goal.x, g.goal.y), (5.0, -1.0));
        assert!((g.goal.yaw - std::f64::consts::FRAC_PI_2).abs() < 1e-9);
        let refused = command_of("/robot/6665/laser/0/cmd_vel", "json", b"{}").unwrap_err();
        assert!(refused.contains("only a position2d"), "{refused}");
        assert!(command_of("/robot/6665/position2d/0/cmd_vel", "cdr", b"").is_err());
        assert!(command_of("/robot/6665/position2d/0/cmd_vel", "json", b"{")
            .unwrap_err()
            .contains("not JSON"));
    }

    #[test]
    fn map_to_odom_puts_odometry_s_origin_in_the_map() {
        let in_map = Pose2d {
            x: 2.0,
            y: 1.0,
            yaw: 1.0,
        };
        let in_odom = Pose2d {
            x: 0.5,
            y: -0.2,
            yaw: 0.3,
        };
        let o = odom_in_map(in_map, in_odom);
        // The odom origin composed with the odometric pose is the map pose.
        let (s, c) = o.yaw.sin_cos();
        let x = o.x + c * in_odom.x - s * in_odom.y;
        let y = o.y + s * in_odom.x + c * in_odom.y;
        assert!((x - 2.0).abs() < 1e-12 && (y - 1.0).abs() < 1e-12);
    }
}
