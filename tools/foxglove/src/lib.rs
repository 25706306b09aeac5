//! `troupe foxglove`: the fleet live in Foxglove, over Foxglove's WebSocket
//! protocol, served by the official Foxglove SDK.
//!
//! Every device of the namespace is a channel named by its key
//! (`/robot/6665/laser/0`), with one of Foxglove's schemas where one fits
//! (troupe-foxglove-msgs says which: LaserScan, PoseInFrame, PosesInFrame,
//! Grid, FrameTransforms on `/tf` and `/tf_static`, SceneUpdate for a
//! simulator's world), JSON otherwise: what `--format foxglove` recordings
//! hold, so a file plays as the live connection looked. What publishes
//! rarely (a map, the fixed transforms, a localizer's estimate, the world's
//! still models) is given again to each client that subscribes, as a
//! latched topic. The server's time is the simulation's.
//! Devices that go are unadvertised. A client may publish (JSON) a velocity
//! on `/robot/6665/position2d/0/cmd_vel` (`{"linear": {"x": …}, "angular":
//! {"z": …}}`, as Foxglove's teleop panel sends) or a goal on
//! `/robot/6665/planner/0/goal` (`{"pose": {"position": …, "orientation":
//! …}}`), or a pose estimate on `/robot/6665/localize/0/set_pose` (a
//! `PoseWithCovarianceStamped`: amcl starts again there); they go out as this process's commands, so a fleet's access rules
//! decide whether they pass.

pub mod front;

use std::collections::HashMap;
use std::sync::mpsc::SyncSender;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::Context as _;
use clap::Args;
use foxglove::websocket::{Capability, Client, ClientChannel, ServerListener};
use foxglove::{Context, PartialMetadata, RawChannel};
use troupe_foxglove_msgs::{Message, Translator};
use troupe_msgs::{
    codec, decode_any, keys, localize, planner, position2d, AnyMsg, Device, Interface, Pose2d,
    Request,
};
use troupe_node::zenoh::{sample::SampleKind, Session, Wait};
use troupe_node::ZenohArgs;
use troupe_ros2::stamp_ns;

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

/// The newest message of each topic that publishes rarely (a map, the fixed
/// transforms, a localizer's estimate), given again to each client that
/// subscribes, as a latched ROS topic would: the protocol has no history.
type Latched = Arc<Mutex<HashMap<String, (Arc<RawChannel>, Vec<u8>, u64)>>>;

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// What the server hears from the network.
enum Heard {
    Sample {
        key: String,
        payload: Vec<u8>,
    },
    /// A planner's waypoints, asked for this state of it, did not come.
    Unanswered(Device, PathState),
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
    // A peer, as `troupe record` is: it takes the whole fleet's data, from
    // the publishers directly where it can reach them.
    let session = z.open_peer()?;
    let ctx = Context::new();
    let latched = Latched::default();
    // A fleet's viewer may look, not command: its clients are not offered
    // publishing (the router would drop the commands unseen).
    let looking_only = session
        .config()
        .get_typed::<serde_json::Value>("metadata")
        .ok()
        .and_then(|m| troupe_node::viewer_of(&m));
    let capabilities = match &looking_only {
        Some(me) => {
            tracing::info!(
                "joined as the viewer `{me}`: Foxglove clients may look, not command (no client publishing)"
            );
            vec![Capability::Time]
        }
        None => vec![Capability::ClientPublish, Capability::Time],
    };
    // The SDK's sockets on one thread of their own: its default runtime
    // (a worker per core) woke another thread for nearly every message. A
    // one-worker runtime, not a current-thread one: the listener holds a
    // Zenoh session, and Zenoh panics when a session closes on a
    // current-thread runtime (it did at Ctrl-C, when the server's tasks
    // dropped the last clone).
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .thread_name("foxglove-ws")
        .enable_all()
        .build()
        .context("starting the WebSocket server's thread")?;
    let sockets = rt.handle().clone();
    std::thread::Builder::new()
        .name("foxglove-ws".into())
        .spawn(move || rt.block_on(std::future::pending::<()>()))
        .context("starting the WebSocket server's thread")?;
    // The public port is the front's (classic clients: front.rs); the
    // SDK's server listens on loopback behind it.
    let public = std::net::TcpListener::bind((a.bind.as_str(), a.port))
        .with_context(|| format!("serving Foxglove on {}:{}", a.bind, a.port))?;
    public.set_nonblocking(true)?;
    let port = public.local_addr()?.port();
    let server = ctx
        .websocket_server()
        .tokio_runtime(&sockets)
        .name("troupe")
        .bind("127.0.0.1", 0)
        .capabilities(capabilities)
        .supported_encodings(["json"])
        .listener(Arc::new(Commands::new(session.clone(), latched.clone())))
        .start_blocking()
        .context("starting the Foxglove SDK's server on loopback")?;
    {
        let _in = sockets.enter();
        let inner = std::net::SocketAddr::from(([127, 0, 0, 1], server.port()));
        let listener = tokio::net::TcpListener::from_std(public)?;
        sockets.spawn(front::run(listener, inner));
    }

    let (tx, rx) = std::sync::mpsc::sync_channel::<Heard>(10_000);
    let live = Arc::new(Mutex::new(Live::new(
        ctx,
        session.clone(),
        tx.clone(),
        latched,
    )));
    // The devices' samples are translated and sent on the thread that
    // receives them (a hop to another thread per sample cost more than the
    // work: a quarter of the server's time went to waking it); the clock
    // goes to this thread, which holds the server.
    let data = {
        let live = live.clone();
        session
            .declare_subscriber(keys::data_all())
            .callback(move |s| {
                lock(&live).heard(s.key_expr().as_str(), &s.payload().to_bytes());
            })
            .wait()
            .map_err(|err| anyhow::anyhow!("subscribing to {}: {err}", keys::data_all()))?
    };
    let clock = {
        let tx = tx.clone();
        session
            .declare_subscriber(keys::SIM_CLOCK)
            .callback(move |s| {
                // A full queue drops the newest: the next one comes.
                let _ = tx.try_send(Heard::Sample {
                    key: s.key_expr().as_str().to_owned(),
                    payload: s.payload().to_bytes().into_owned(),
                });
            })
            .wait()
            .map_err(|err| anyhow::anyhow!("subscribing to {}: {err}", keys::SIM_CLOCK))?
    };
    let tokens = {
        let tx = tx.clone();
        session
            .liveliness()
            .declare_subscriber(keys::tokens(None))
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
        troupe_node::process::on_stop_signal(move || {
            let _ = tx.send(Heard::Stop);
        })
        .context("catching Ctrl-C and SIGTERM")?;
    }
    // On stdout once the port is bound: a script may connect when it appears.
    println_out(&format!(
        "troupe foxglove: ws://{}:{} (open it in Foxglove: Open connection, Foxglove WebSocket; Ctrl-C stops)",
        a.bind, port
    ));
    drop(tx);
    for h in rx {
        match h {
            Heard::Stop => break,
            Heard::Came(dev) => lock(&live).ask(dev),
            Heard::Went(dev) => lock(&live).close(&dev),
            Heard::Unanswered(dev, path) => lock(&live).unanswered(dev, path),
            Heard::Sample { key, payload } if key == keys::SIM_CLOCK => {
                if let Ok(s) = decode_any(&payload) {
                    server.broadcast_time(stamp_ns(s.stamp));
                }
            }
            Heard::Sample { key, payload } => lock(&live).heard(&key, &payload),
        }
    }
    drop((data, clock, tokens));
    let _ = server.stop();
    // Closed here, whichever clone goes last.
    session
        .close()
        .wait()
        .map_err(|e| anyhow::anyhow!("closing the session: {e}"))?;
    Ok(())
}

#[allow(clippy::print_stdout)]
fn println_out(line: &str) {
    println!("{line}");
}

/// The channels and what later samples need to know.
struct Live {
    ctx: Arc<Context>,
    session: Session,
    tx: SyncSender<Heard>,
    channels: HashMap<String, Arc<RawChannel>>,
    translator: Translator,
    latched: Latched,
    /// Each planner's last path, asked for.
    paths: HashMap<Device, PathState>,
}

/// A planner's path as its state tells it: valid, goal, waypoints.
type PathState = (bool, [f64; 3], u32);

impl Live {
    fn new(ctx: Arc<Context>, session: Session, tx: SyncSender<Heard>, latched: Latched) -> Live {
        Live {
            ctx,
            session,
            tx,
            channels: HashMap::new(),
            translator: Translator::new(),
            latched,
            paths: HashMap::new(),
        }
    }

    /// A device's sample, `payload` on `key`: translated and sent.
    fn heard(&mut self, key: &str, payload: &[u8]) {
        let Ok(s) = decode_any(payload) else {
            return;
        };
        let ns = stamp_ns(s.stamp);
        if let AnyMsg::PlannerState(st) = &s.msg {
            self.planned(key, st);
        }
        for m in self.translator.translate(key, ns, &s.msg) {
            self.log(m, ns);
        }
    }

    /// What a Player client asks once (a map's grid, a sensor's
    /// geometry, a simulator's world), asked off this thread; the answers
    /// come back as samples.
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

    /// A planner's state: a new goal, validity or count of waypoints is a
    /// new path, asked for off this thread (its waypoints come back as a
    /// sample, drawn as the planner's path).
    fn planned(&mut self, key: &str, st: &planner::State) {
        let Ok(dev) = keys::parse_data(key) else {
            return;
        };
        let path = (
            st.valid,
            [st.goal.x, st.goal.y, st.goal.yaw],
            st.waypoints_count,
        );
        if self.paths.insert(dev, path) == Some(path) {
            return;
        }
        let (session, tx) = (self.session.clone(), self.tx.clone());
        std::thread::spawn(move || {
            let key = keys::req(&dev, planner::GetWaypoints::NAME);
            let asked = troupe_node::ask(&session, &key, Duration::from_secs(2))
                .payload(codec::encode(&planner::GetWaypoints, 0.0))
                .wait();
            let answer = asked
                .ok()
                .and_then(|r| r.recv().ok())
                .and_then(|reply| reply.into_result().ok());
            let _ = tx.send(match answer {
                Some(answer) => Heard::Sample {
                    key: keys::data(&dev),
                    payload: answer.payload().to_bytes().into_owned(),
                },
                None => Heard::Unanswered(dev, path),
            });
        });
    }

    /// The waypoints asked for at `path` did not come (the planner's
    /// queryable not yet known here, a timeout): forgotten, so that the
    /// planner's next state (four a second) asks again, where the path
    /// would otherwise stay undrawn until the planner's state changed.
    fn unanswered(&mut self, dev: Device, path: PathState) {
        if self.paths.get(&dev) == Some(&path) {
            self.paths.remove(&dev);
        }
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
        self.translator.forget(dev);
        self.paths.remove(dev);
    }

    /// Logs `m` on its channel (made, and advertised, with its first
    /// message), and keeps it for the clients that subscribe later if it
    /// stands until the next.
    fn log(&mut self, m: Message, ns: u64) {
        let ch = match self.channels.get(&m.topic) {
            Some(c) => c.clone(),
            None => {
                let built = self
                    .ctx
                    .channel_builder(&m.topic)
                    .message_encoding(m.kind.encoding())
                    .schema(m.kind.schema())
                    .build_raw();
                match built {
                    Ok(c) => {
                        self.channels.insert(m.topic.clone(), c.clone());
                        c
                    }
                    Err(e) => {
                        tracing::warn!("{}: {e}", m.topic);
                        return;
                    }
                }
            }
        };
        let meta = PartialMetadata { log_time: Some(ns) };
        if m.latched {
            // Logged and kept under one lock, the one a subscription's
            // `on_subscribe` takes to give the kept message. A client that
            // subscribes meanwhile gets this message from one or the other
            // (at worst twice). Logged first and kept after, a subscription
            // that came between got the message before this one only: a
            // planner's new path, sent at the moment Foxglove subscribed,
            // never drawn.
            let mut latched = lock(&self.latched);
            ch.log_with_meta(&m.data, meta);
            latched.insert(m.topic, (ch, m.data, ns));
        } else {
            ch.log_with_meta(&m.data, meta);
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
        let sent = command_of(&channel.topic, &channel.encoding, payload).and_then(|c| {
            let sent = if c.request {
                // Its answer (an Ack) is not awaited: the estimate shows it.
                self.session
                    .get(&c.key)
                    .payload(c.payload)
                    .callback(|_| {})
                    .wait()
            } else {
                self.session.put(&c.key, c.payload).wait()
            };
            sent.map_err(|e| CommandError::Send {
                key: c.key,
                reason: e.to_string(),
            })
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

/// What a client's message becomes: a command put on a key, or a request.
#[derive(Debug, Clone, PartialEq)]
pub struct Command {
    /// The key: `robot/6665/position2d/0/cmd/vel`.
    pub key: String,
    /// The encoded message.
    pub payload: Vec<u8>,
    /// Whether it is a request (a query), not a command (a put).
    pub request: bool,
}

/// A pose a client publishes, in map coordinates: a ROS `PoseStamped`
/// (`{"pose": {"position", "orientation"}}`), a `PoseWithCovarianceStamped`
/// (`{"pose": {"pose": …}}`) or a Foxglove `PoseInFrame`, all read alike.
fn published_pose(v: &serde_json::Value) -> Pose2d {
    let pose = v
        .pointer("/pose/pose")
        .or_else(|| v.get("pose"))
        .unwrap_or(v);
    let f = |p: &str| pose.pointer(p).and_then(serde_json::Value::as_f64);
    let q = troupe_ros2::msg::Quaternion {
        x: f("/orientation/x").unwrap_or(0.0),
        y: f("/orientation/y").unwrap_or(0.0),
        z: f("/orientation/z").unwrap_or(0.0),
        w: f("/orientation/w").unwrap_or(1.0),
    };
    Pose2d {
        x: f("/position/x").unwrap_or(0.0),
        y: f("/position/y").unwrap_or(0.0),
        yaw: q.yaw(),
    }
}

/// The spread a pose estimate set from a client gets (RViz's and
/// Foxglove's "pose estimate": 0.5 m, 15 degrees), in Player's order.
const SET_POSE_COV: [f64; 6] = [0.25, 0.25, 0.068_538_923_266_547_87, 0.0, 0.0, 0.0];

/// Why a client's message makes no command, said for the client's user.
#[derive(Debug, thiserror::Error)]
pub enum CommandError {
    /// Not JSON.
    #[error("`{0}` messages are not read: publish JSON")]
    Encoding(String),
    /// A topic with no device in it.
    #[error("expected /robot/PORT/INTERFACE/INDEX/cmd_vel, …/goal or …/set_pose")]
    Topic,
    /// The topic's device is no device.
    #[error("{device}: {source}")]
    Device {
        /// The topic's device part.
        device: String,
        /// Why it is none.
        source: troupe_msgs::AddrError,
    },
    /// The payload does not parse.
    #[error("not JSON: {0}")]
    Json(serde_json::Error),
    /// A topic that takes no commands.
    #[error(
        "{0}: only a position2d's …/cmd_vel, a planner's …/goal and a localizer's …/set_pose take commands"
    )]
    NotACommand(String),
    /// Zenoh would not send it.
    #[error("sending on {key}: {reason}")]
    Send {
        /// Where.
        key: String,
        /// Zenoh's reason.
        reason: String,
    },
}

/// The command a client's message on `topic` makes.
///
/// # Errors
///
/// Why it makes none, said for the client's user.
pub fn command_of(topic: &str, encoding: &str, payload: &[u8]) -> Result<Command, CommandError> {
    if encoding != "json" {
        return Err(CommandError::Encoding(encoding.to_owned()));
    }
    let (device, what) = topic
        .trim_start_matches('/')
        .rsplit_once('/')
        .ok_or(CommandError::Topic)?;
    let dev = keys::parse_data(device).map_err(|source| CommandError::Device {
        device: device.to_owned(),
        source,
    })?;
    let v: serde_json::Value = serde_json::from_slice(payload).map_err(CommandError::Json)?;
    let f = |path: &[&str]| {
        path.iter()
            .try_fold(&v, |v, k| v.get(k))
            .and_then(serde_json::Value::as_f64)
            .unwrap_or(0.0)
    };
    let now = troupe_node::Clock::wall().now();
    let put = |name: &str, payload| Command {
        key: keys::cmd(&dev, name),
        payload,
        request: false,
    };
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
            Ok(put("vel", codec::encode(&cmd, now)))
        }
        (Interface::Planner, "goal") => {
            let goal = planner::Goal {
                goal: published_pose(&v),
            };
            Ok(put("goal", codec::encode(&goal, now)))
        }
        (Interface::Localize, "set_pose") => {
            let set = localize::SetPose {
                mean: published_pose(&v),
                cov: SET_POSE_COV,
            };
            Ok(Command {
                key: keys::req(&dev, localize::SetPose::NAME),
                payload: codec::encode(&set, now),
                request: true,
            })
        }
        _ => Err(CommandError::NotACommand(topic.to_owned())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_teleop_twist_is_a_velocity_command() {
        let Command {
            key, payload: cmd, ..
        } = command_of(
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
        let Command {
            key, payload: cmd, ..
        } = command_of(
            "/robot/6665/planner/0/goal",
            "json",
            br#"{"pose": {"position": {"x": 5, "y": -1}, "orientation": {"z": 0.7071067811865476, "w": 0.7071067811865476}}}"#,
        )
        .unwrap();
        assert_eq!(key, "robot/6665/planner/0/cmd/goal");
        let g: planner::Goal = codec::decode(&cmd).unwrap().msg;
        assert_eq!((g.goal.x, g.goal.y), (5.0, -1.0));
        assert!((g.goal.yaw - std::f64::consts::FRAC_PI_2).abs() < 1e-9);
        let set = command_of(
            "/robot/6665/localize/0/set_pose",
            "json",
            br#"{"header": {}, "pose": {"pose": {"position": {"x": -6, "y": -6}, "orientation": {"w": 1}}, "covariance": []}}"#,
        )
        .unwrap();
        assert_eq!(
            (set.key.as_str(), set.request),
            ("robot/6665/localize/0/req/set_pose", true)
        );
        let s: localize::SetPose = codec::decode(&set.payload).unwrap().msg;
        assert_eq!((s.mean.x, s.mean.y, s.mean.yaw), (-6.0, -6.0, 0.0));
        let refused = command_of("/robot/6665/laser/0/cmd_vel", "json", b"{}").unwrap_err();
        assert!(
            refused.to_string().contains("only a position2d"),
            "{refused}"
        );
        assert!(command_of("/robot/6665/position2d/0/cmd_vel", "cdr", b"").is_err());
        assert!(command_of("/robot/6665/position2d/0/cmd_vel", "json", b"{")
            .unwrap_err()
            .to_string()
            .contains("not JSON"));
    }
}
