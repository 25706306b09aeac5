//! A driver's devices as ROS 2 topics and services, on the driver's own
//! Zenoh session, as rmw_zenoh's nodes speak them ([`troupe_ros2::rmw`]): no
//! bridge process, no extra hop.
//!
//! Each driver process is one ROS 2 node (its token names it: `/robot_6665/amcl`,
//! or `/stage` for a simulator of several robots). What its devices publish
//! is translated ([`troupe_ros2::Translator`]) and sent on the ROS 2 topic
//! of [`troupe_ros2::live`], but only while a ROS 2 subscriber matches that
//! topic: without one, a sample costs a look at an atomic flag. A map is
//! fetched from its own device once it is ready and kept: published
//! transient-local (a late rviz2 gets it) and served by `GetMap`. What ROS 2
//! nodes send (`cmd_vel`, `goal_pose`, `initialpose`) goes into the driver's
//! inbox as a Troupe command or request would; a `cmd_vel` that goes quiet
//! for [`Ros2::cmd_vel_timeout`] stops the base.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use troupe_msgs::{codec, keys, map, Device, Interface};
use troupe_ros2::live::{self, Inbound};
use troupe_ros2::rmw::{self, Attachment, Distro, Kind, Qos};
use troupe_ros2::{Translator, Type};
use zenoh::liveliness::LivelinessToken;
use zenoh::matching::MatchingListener;
use zenoh::pubsub::{Publisher, Subscriber};
use zenoh::qos::{CongestionControl, Reliability};
use zenoh::query::{Query, Queryable};
use zenoh::{Session, Wait};
use zenoh_ext::{AdvancedPublisher, AdvancedPublisherBuilderExt, CacheConfig, MissDetectionConfig};

use crate::clock::Clock;
use crate::ctx::ReadyAnswers;
use crate::error::{z, NodeError, RequestError, Result};
use crate::event::{Event, ReplySink, Request, Responder, Sample};
use crate::inbox::Inbox;

/// How a node shows itself to ROS 2 (`--ros2`).
#[derive(Debug, Clone, PartialEq)]
pub struct Ros2 {
    /// The ROS domain (`ROS_DOMAIN_ID`, 0 by default).
    pub domain: u32,
    /// Whose conventions: Jazzy and later, or Humble.
    pub distro: Distro,
    /// Each robot's namespace, `{robot}` its port: `/robot_{robot}`.
    pub namespace: String,
    /// How long a base keeps the last `cmd_vel` before it stops.
    pub cmd_vel_timeout: Duration,
}

impl Default for Ros2 {
    fn default() -> Self {
        Ros2 {
            domain: 0,
            distro: Distro::Jazzy,
            namespace: DEFAULT_NAMESPACE.to_owned(),
            cmd_vel_timeout: Duration::from_millis(500),
        }
    }
}

/// Each robot's ROS 2 namespace unless told otherwise.
pub const DEFAULT_NAMESPACE: &str = "/robot_{robot}";

/// The flags that turn ROS 2 on (`troupe launch --ros2`, `troupe node --ros2`).
/// A value not given comes from the cfg's `ros2 ( … )` section
/// ([`Ros2Settings`]), else its default.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct Ros2Args {
    /// Show every device to ROS 2 nodes on rmw_zenoh that share this Zenoh
    /// network (`ros2 topic list`, rviz2, Nav2), and take `cmd_vel`,
    /// `goal_pose` and `initialpose` from them. Each robot's topics are in
    /// its namespace: `/robot_6665/scan`, `/robot_6665/odom`,
    /// `/robot_6665/map` (docs/ros2.md). A cfg turns it on with a
    /// `ros2 ( )` section.
    #[arg(long)]
    pub ros2: bool,
    /// The ROS domain, as ROS 2 nodes take it from ROS_DOMAIN_ID [default: 0].
    #[arg(long, value_name = "ID", env = "ROS_DOMAIN_ID",
          value_parser = clap::value_parser!(u32).range(0..=232))]
    pub ros2_domain: Option<u32>,
    /// The ROS 2 distribution of the nodes that listen: jazzy (also kilted
    /// and rolling: keys name each type's hash) or humble (they do not)
    /// [default: jazzy].
    #[arg(long, value_name = "DISTRO")]
    pub ros2_distro: Option<Distro>,
    /// Each robot's namespace; `{robot}` is the robot's port
    /// [default: /robot_{robot}].
    #[arg(long, value_name = "TEMPLATE")]
    pub ros2_namespace: Option<String>,
    /// Seconds a base keeps the last `cmd_vel` before it stops (ROS 2
    /// teleop and Nav2 send it several times a second) [default: 0.5].
    #[arg(long, value_name = "SECS", value_parser = crate::args::seconds)]
    pub ros2_cmd_vel_timeout: Option<f64>,
}

/// A cfg's `ros2 ( domain 0 namespace "/robot_{robot}" … )` section, and a
/// plan's `[launch.ros2]`: ROS 2 on for every node, with these settings.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ros2Settings {
    /// The ROS domain.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub domain: Option<u32>,
    /// `jazzy` or `humble`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distro: Option<String>,
    /// Each robot's namespace template.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub namespace: Option<String>,
    /// Seconds before a quiet `cmd_vel` stops the base.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cmd_vel_timeout: Option<f64>,
}

impl Ros2Args {
    /// The configuration these flags give over a cfg's settings (`file`):
    /// `None` when neither turns ROS 2 on.
    ///
    /// # Errors
    ///
    /// A timeout that is not a positive number of seconds, a namespace that
    /// is no ROS 2 name, an unknown distribution, a domain past 232.
    pub fn config(&self, file: Option<&Ros2Settings>) -> Result<Option<Ros2>> {
        if !self.ros2 && file.is_none() {
            return Ok(None);
        }
        let bad = |why: String| NodeError::config("ros2", why);
        let f = file.cloned().unwrap_or_default();
        let distro = match (&self.ros2_distro, &f.distro) {
            (Some(d), _) => *d,
            (None, Some(d)) => d
                .parse()
                .map_err(|e: rmw::UnknownDistro| bad(format!("distro: {e}")))?,
            (None, None) => Distro::Jazzy,
        };
        let domain = self.ros2_domain.or(f.domain).unwrap_or(0);
        if domain > 232 {
            return Err(bad(format!("domain {domain}: ROS 2 domains are 0-232")));
        }
        let t = self
            .ros2_cmd_vel_timeout
            .or(f.cmd_vel_timeout)
            .unwrap_or(0.5);
        if !(t.is_finite() && t > 0.0 && t < 3600.0) {
            return Err(bad(format!(
                "--ros2-cmd-vel-timeout (cmd_vel_timeout) must be a positive number of seconds, not {t}"
            )));
        }
        let namespace = self
            .ros2_namespace
            .clone()
            .or(f.namespace)
            .unwrap_or_else(|| DEFAULT_NAMESPACE.to_owned());
        let ns = live::robot_namespace(&namespace, 6665);
        if let Some(c) = ns
            .chars()
            .find(|c| !(c.is_ascii_alphanumeric() || *c == '_' || *c == '/'))
        {
            return Err(bad(format!(
                "namespace `{namespace}`: a ROS 2 name takes letters, digits, `_` and `/`, not `{c}`"
            )));
        }
        Ok(Some(Ros2 {
            domain,
            distro,
            namespace,
            cmd_vel_timeout: Duration::from_secs_f64(t),
        }))
    }
}

impl Ros2 {
    /// The command-line flags that give a child node this configuration.
    pub fn to_args(&self) -> Vec<String> {
        vec![
            "--ros2".into(),
            format!("--ros2-domain={}", self.domain),
            format!("--ros2-distro={}", self.distro),
            format!("--ros2-namespace={}", self.namespace),
            format!(
                "--ros2-cmd-vel-timeout={}",
                self.cmd_vel_timeout.as_secs_f64()
            ),
        ]
    }

    fn ns(&self, robot: u32) -> String {
        live::robot_namespace(&self.namespace, robot)
    }

    fn hash(&self, ty: &str) -> &'static str {
        rmw::type_hash(ty, self.distro).unwrap_or(rmw::NO_TYPE_HASH)
    }
}

/// Counts a repeated problem and says it at 1, 10, 100… occurrences.
#[derive(Default)]
struct Counted(AtomicU64);

impl Counted {
    fn warn(&self, what: &str) {
        let n = self.0.fetch_add(1, Ordering::Relaxed) + 1;
        if power_of_ten(n) {
            tracing::warn!(count = n, "ROS 2: {what} ({n} so far)");
        }
    }
}

/// 1, 10, 100…: when a repeated problem is said again.
fn power_of_ten(mut n: u64) -> bool {
    while n >= 10 && n % 10 == 0 {
        n /= 10;
    }
    n == 1
}

/// The node's identity and the entity numbers it hands out.
struct Ident {
    ros: Ros2,
    node: rmw::Node,
    next_eid: AtomicU64,
}

impl Ident {
    fn token(&self, kind: Kind, topic: &str, ty: &str, qos: Qos) -> String {
        let eid = self.next_eid.fetch_add(1, Ordering::Relaxed);
        self.node
            .entity_token(eid, kind, topic, ty, self.ros.hash(ty), qos)
    }

    fn key(&self, topic: &str, ty: &str) -> String {
        rmw::topic_key(self.ros.domain, topic, ty, self.ros.hash(ty))
    }
}

enum Sender {
    Plain(Publisher<'static>),
    /// Transient local: keeps its last samples for late subscribers.
    Latched(AdvancedPublisher<'static>),
}

/// One ROS 2 publisher.
struct RosPub {
    ty: Type,
    sender: Sender,
    gid: [u8; 16],
    seq: i64,
    matched: Arc<AtomicBool>,
    _listener: Option<MatchingListener<()>>,
    _token: LivelinessToken,
}

impl RosPub {
    fn send(&mut self, cdr: Vec<u8>) -> std::result::Result<(), zenoh::Error> {
        self.seq += 1;
        let att = Attachment {
            seq: self.seq,
            stamp_ns: rmw::wall_ns(),
            gid: self.gid,
        }
        .to_bytes()
        .to_vec();
        match &self.sender {
            Sender::Plain(p) => p.put(cdr).attachment(att).wait(),
            Sender::Latched(p) => p.put(cdr).attachment(att).wait(),
        }
    }
}

/// Where each device's (or the clock's: `None`) samples of each schema
/// send their translations, once known.
type Routes = HashMap<Option<Device>, Vec<(String, Vec<usize>)>>;

/// A node's ROS 2 side (see the module's documentation).
pub(crate) struct Face {
    session: Session,
    ident: Arc<Ident>,
    translator: Translator,
    pubs: Vec<RosPub>,
    by_topic: HashMap<String, usize>,
    routes: Routes,
    failed: Counted,
    /// Map publishers, filled by the threads that fetch the maps.
    maps: Vec<Arc<Mutex<RosPub>>>,
    /// What the driver keeps ready to answer: a ranger's configuration
    /// and a sensor's geometry, which the translator needs before its
    /// first sample (the shape of a scan, `/tf_static`).
    answers: Arc<ReadyAnswers>,
    /// Devices whose kept answers were read.
    primed: Vec<Device>,
    _node_token: LivelinessToken,
    _subscribers: Vec<Subscriber<()>>,
    _queryables: Vec<Queryable<()>>,
    _tokens: Vec<LivelinessToken>,
}

impl Face {
    /// Declares the node (named after `driver`, in its robot's namespace
    /// when all of `provided` are one robot's) and what `provided` take
    /// from ROS 2.
    pub(crate) fn new(
        session: &Session,
        ros: &Ros2,
        driver: &str,
        provided: &[Device],
        inbox: &Arc<Inbox>,
        clock: &Clock,
        answers: &Arc<ReadyAnswers>,
    ) -> Result<Face> {
        let robots: std::collections::BTreeSet<u32> = provided.iter().map(|d| d.robot).collect();
        let namespace = match robots.iter().collect::<Vec<_>>()[..] {
            [only] => ros.ns(*only),
            _ => "/".to_owned(),
        };
        let node = rmw::Node {
            domain: ros.domain,
            zid: session.zid().to_string(),
            nid: 0,
            namespace,
            name: driver.replace(|c: char| !c.is_ascii_alphanumeric(), "_"),
        };
        let node_token = node.token();
        let ident = Arc::new(Ident {
            ros: ros.clone(),
            node,
            next_eid: AtomicU64::new(1),
        });
        let _node_token = session
            .liveliness()
            .declare_token(&node_token)
            .wait()
            .map_err(z(|| format!("declaring ROS 2 node token {node_token}")))?;
        let mut face = Face {
            session: session.clone(),
            ident,
            translator: Translator::new(),
            pubs: Vec::new(),
            by_topic: HashMap::new(),
            routes: HashMap::new(),
            failed: Counted::default(),
            maps: Vec::new(),
            answers: answers.clone(),
            primed: Vec::new(),
            _node_token,
            _subscribers: Vec::new(),
            _queryables: Vec::new(),
            _tokens: Vec::new(),
        };
        for dev in provided {
            if let Some(what) = Inbound::of(dev) {
                face.take(dev, what, inbox, clock)?;
            }
            if dev.interface == Interface::Map {
                face.serve_map(dev)?;
            }
        }
        tracing::info!(
            "ROS 2: node {}/{} on domain {} ({})",
            face.ident.node.namespace.trim_end_matches('/'),
            face.ident.node.name,
            ros.domain,
            ros.distro
        );
        Ok(face)
    }

    /// Sends a device's sample (as Troupe encoded it) on its ROS 2 topics,
    /// if anyone listens there.
    /// `dev`: the device, or `None` for the clock.
    pub(crate) fn publish(&mut self, dev: Option<&Device>, payload: &[u8]) {
        if let Some(d) = dev {
            if !self.primed.contains(d) {
                self.primed.push(*d);
                for kept in self.kept_answers(d) {
                    self.publish(Some(d), &kept);
                }
            }
        }
        let tag = codec::schema_of(payload).unwrap_or("?");
        let known = self
            .routes
            .get(&dev.copied())
            .and_then(|r| r.iter().find(|(t, _)| t == tag));
        if let Some((_, to)) = known {
            // Known to go only to these: skip unless one is heard.
            if !to.is_empty()
                && !to
                    .iter()
                    .any(|&i| self.pubs[i].matched.load(Ordering::Relaxed))
            {
                return;
            }
        }
        let tag = tag.to_owned();
        let Ok(s) = troupe_msgs::decode_any(payload) else {
            return;
        };
        let stamp = troupe_ros2::stamp_ns(s.stamp);
        let key = dev.map_or_else(|| keys::SIM_CLOCK.to_owned(), keys::data);
        let Some(outs) = self.translator.translate(&key, stamp, &s.msg) else {
            return;
        };
        let mut used = Vec::with_capacity(outs.len());
        for out in outs {
            if out.ty == Type::OccupancyGrid {
                // A map device's grid is fetched whole and kept (serve_map).
                continue;
            }
            let topic = match dev {
                Some(d) => live::topic(&self.ident.ros.ns(d.robot), d, out.ty, &out.topic),
                None => out.topic.clone(),
            };
            let i = match self.publisher(&topic, out.ty) {
                Ok(i) => i,
                Err(e) => {
                    self.failed.warn(&e.to_string());
                    continue;
                }
            };
            used.push(i);
            let p = &mut self.pubs[i];
            if matches!(p.sender, Sender::Latched(_)) || p.matched.load(Ordering::Relaxed) {
                let cdr = live::for_distro(p.ty, self.ident.ros.distro, out.data);
                if let Err(e) = p.send(cdr) {
                    self.failed.warn(&format!("publishing on {topic}: {e}"));
                }
            }
        }
        let routes = self.routes.entry(dev.copied()).or_default();
        let at = match routes.iter().position(|(t, _)| *t == tag) {
            Some(at) => at,
            None => {
                routes.push((tag, Vec::new()));
                routes.len() - 1
            }
        };
        for i in used {
            if !routes[at].1.contains(&i) {
                routes[at].1.push(i);
            }
        }
    }

    /// The answers `dev`'s driver keeps ready that say how to read its
    /// samples: a ranger's configuration, a sensor's geometry.
    fn kept_answers(&self, dev: &Device) -> Vec<Vec<u8>> {
        use troupe_msgs::{ir, laser, ranger, sonar, Request as R};
        let asks: Vec<(&str, Vec<u8>)> = match dev.interface {
            Interface::Ranger => vec![
                (
                    ranger::GetConfig::NAME,
                    codec::encode(&ranger::GetConfig, 0.0),
                ),
                (ranger::GetGeom::NAME, codec::encode(&ranger::GetGeom, 0.0)),
            ],
            Interface::Laser => vec![(laser::GetGeom::NAME, codec::encode(&laser::GetGeom, 0.0))],
            Interface::Sonar => vec![(sonar::GetGeom::NAME, codec::encode(&sonar::GetGeom, 0.0))],
            Interface::Ir => vec![(ir::GetGeom::NAME, codec::encode(&ir::GetGeom, 0.0))],
            _ => Vec::new(),
        };
        asks.into_iter()
            .filter_map(|(name, asked)| self.answers.get(dev, name, &asked, 0.0))
            .collect()
    }

    /// The publisher of `topic`, declared on first use.
    fn publisher(&mut self, topic: &str, ty: Type) -> Result<usize> {
        if let Some(&i) = self.by_topic.get(topic) {
            return Ok(i);
        }
        let p = declare_pub(&self.session, &self.ident, topic, ty.name(), ty)?;
        self.pubs.push(p);
        self.by_topic.insert(topic.to_owned(), self.pubs.len() - 1);
        Ok(self.pubs.len() - 1)
    }

    /// Subscribes to what `dev` takes from ROS 2 and hands it to the driver.
    fn take(
        &mut self,
        dev: &Device,
        what: Inbound,
        inbox: &Arc<Inbox>,
        clock: &Clock,
    ) -> Result<()> {
        let ns = self.ident.ros.ns(dev.robot);
        let topic = what.topic(&ns, dev.index);
        let ty = what.ros_type();
        let key = self.ident.key(&topic, ty);
        let token = self
            .ident
            .token(Kind::Subscription, &topic, ty, Qos::DEFAULT);
        self._tokens.push(
            self.session
                .liveliness()
                .declare_token(&token)
                .wait()
                .map_err(z(|| {
                    format!("declaring ROS 2 subscription token of {topic}")
                }))?,
        );
        let watchdog = (what == Inbound::CmdVel).then(|| {
            Watchdog::start(
                *dev,
                inbox.clone(),
                clock.clone(),
                self.ident.ros.cmd_vel_timeout,
            )
        });
        let (d, inbox, clock) = (*dev, inbox.clone(), clock.clone());
        let bad = Arc::new(Counted::default());
        let sub = self
            .session
            .declare_subscriber(&key)
            .callback(move |sample| {
                let bytes = sample.payload().to_bytes();
                match what.to_troupe(&bytes, clock.now()) {
                    Ok((name, payload)) => {
                        if let Some(w) = &watchdog {
                            w.fed();
                        }
                        deliver(&inbox, &clock, d, name, payload);
                    }
                    Err(e) => bad.warn(&format!("dropped a message on {topic}: {e}")),
                }
            })
            .wait()
            .map_err(z(|| format!("subscribing to ROS 2 {key}")))?;
        self._subscribers.push(sub);
        Ok(())
    }

    /// A map device: its grid on `<ns>/map` (transient local) and the
    /// `GetMap` service `<ns>/map_server/map`, once the device is ready.
    fn serve_map(&mut self, dev: &Device) -> Result<()> {
        let ns = self.ident.ros.ns(dev.robot);
        let topic = live::topic(&ns, dev, Type::OccupancyGrid, "");
        let latched = declare_pub(
            &self.session,
            &self.ident,
            &topic,
            Type::OccupancyGrid.name(),
            Type::OccupancyGrid,
        )?;
        // The publisher's cache, which late subscribers read, lives with the face.
        let latched = Arc::new(Mutex::new(latched));
        self.maps.push(latched.clone());
        let grid: Arc<Mutex<Option<Vec<u8>>>> = Arc::default();

        let service = format!("{ns}/map_server/map");
        let ty = "nav_msgs/srv/GetMap";
        let key = self.ident.key(&service, ty);
        let token = self.ident.token(Kind::Service, &service, ty, Qos::SERVICES);
        self._tokens.push(
            self.session
                .liveliness()
                .declare_token(&token)
                .wait()
                .map_err(z(|| format!("declaring ROS 2 service token of {service}")))?,
        );
        let held = grid.clone();
        let bad = Arc::new(Counted::default());
        let q = self
            .session
            .declare_queryable(&key)
            .complete(true)
            .callback(move |q: Query| {
                let Some(asked) = q
                    .attachment()
                    .and_then(|a| Attachment::parse(&a.to_bytes()))
                else {
                    return bad.warn(&format!(
                        "a GetMap request without rmw_zenoh's attachment on {service}"
                    ));
                };
                let att = Attachment {
                    seq: asked.seq,
                    stamp_ns: rmw::wall_ns(),
                    gid: asked.gid,
                };
                let grid = held.lock().unwrap_or_else(|p| p.into_inner()).clone();
                let sent = match grid {
                    // GetMap's response is one OccupancyGrid: its CDR is the grid's.
                    Some(cdr) => q
                        .reply(q.key_expr().clone(), cdr)
                        .attachment(att.to_bytes().to_vec())
                        .wait(),
                    None => q.reply_err("the map is not loaded yet").wait(),
                };
                if let Err(e) = sent {
                    bad.warn(&format!("answering GetMap on {service}: {e}"));
                }
            })
            .wait()
            .map_err(z(|| format!("declaring ROS 2 service {key}")))?;
        self._queryables.push(q);

        let (session, d, distro) = (self.session.clone(), *dev, self.ident.ros.distro);
        std::thread::Builder::new()
            .name(format!("ros2 map {d}"))
            .spawn(move || match fetch_grid(&session, &d) {
                Ok(cdr) => {
                    *grid.lock().unwrap_or_else(|p| p.into_inner()) = Some(cdr.clone());
                    let cdr = live::for_distro(Type::OccupancyGrid, distro, cdr);
                    match latched.lock().unwrap_or_else(|p| p.into_inner()).send(cdr) {
                        Ok(()) => {
                            tracing::info!("ROS 2: {d}'s map published, kept for late subscribers")
                        }
                        Err(e) => tracing::warn!("ROS 2: publishing {d}'s map: {e}"),
                    }
                }
                Err(e) => tracing::warn!("ROS 2: no map for {d}: {e}"),
            })
            .map_err(|e| NodeError::Driver(format!("starting the ROS 2 map thread: {e}").into()))?;
        Ok(())
    }
}

/// Declares a ROS 2 publisher of `topic`: transient local for a map and
/// `/tf_static`, else rclcpp's default QoS; its token, GID and a flag that
/// says whether a subscriber matches.
fn declare_pub(
    session: &Session,
    ident: &Ident,
    topic: &str,
    ty_name: &str,
    ty: Type,
) -> Result<RosPub> {
    let latched = ty == Type::OccupancyGrid || topic == troupe_ros2::TF_STATIC;
    let qos = if latched { Qos::LATCHED } else { Qos::DEFAULT };
    let key = ident.key(topic, ty_name);
    let token = ident.token(Kind::Publisher, topic, ty_name, qos);
    let gid = rmw::gid(&token);
    let matched = Arc::new(AtomicBool::new(false));
    let flag = matched.clone();
    let (sender, listener) = if latched {
        let p = session
            .declare_publisher(key.clone())
            .reliability(Reliability::Reliable)
            .congestion_control(CongestionControl::Drop)
            .cache(CacheConfig::default().max_samples(qos.depth))
            .sample_miss_detection(
                MissDetectionConfig::default().heartbeat(Duration::from_millis(500)),
            )
            .publisher_detection()
            .wait()
            .map_err(z(|| format!("declaring ROS 2 publisher {key}")))?;
        (Sender::Latched(p), None)
    } else {
        // Not express, unlike Troupe's own publishers: with 100 Pioneers'
        // lasers and odometry subscribed (`troupe bench ros2`), batched
        // sends cost the simulator 111-125 ms of CPU per simulated second
        // and it ran at 8.7-9.4x real time (10x without ROS 2); express
        // cost 124-136 ms and 7.4-7.8x, for no gain on a laser's latency.
        let p = session
            .declare_publisher(key.clone())
            .reliability(Reliability::Reliable)
            .congestion_control(CongestionControl::Drop)
            .wait()
            .map_err(z(|| format!("declaring ROS 2 publisher {key}")))?;
        let listener = p
            .matching_listener()
            .callback(move |m| flag.store(m.matching(), Ordering::Relaxed))
            .wait()
            .map_err(z(|| format!("watching ROS 2 subscribers of {key}")))?;
        (Sender::Plain(p), Some(listener))
    };
    let token = session
        .liveliness()
        .declare_token(&token)
        .wait()
        .map_err(z(|| format!("declaring ROS 2 publisher token of {topic}")))?;
    tracing::debug!("ROS 2: publishing {topic} on {key}");
    Ok(RosPub {
        ty,
        sender,
        gid,
        seq: 0,
        matched,
        _listener: listener,
        _token: token,
    })
}

/// Asks map device `dev` for its info and every cell, as the other drivers
/// do, and makes its `OccupancyGrid`.
fn fetch_grid(session: &Session, dev: &Device) -> Result<Vec<u8>> {
    // The map answers once it is ready (its token is up).
    tracing::info!("waiting for map {dev}, to show it to ROS 2");
    crate::net::wait_live(session, dev, Duration::from_secs(3600))?;
    let ask = |name: &str, payload: Vec<u8>| -> Result<Vec<u8>> {
        let key = keys::req(dev, name);
        let replies = crate::net::ask(session, &key, crate::REQUEST_TIMEOUT)
            .payload(payload)
            .wait()
            .map_err(z(|| format!("asking {key}")))?;
        let reply = replies.recv().map_err(|_| RequestError::NoReplier)?;
        match reply.into_result() {
            Ok(s) => Ok(s.payload().to_bytes().into_owned()),
            Err(e) => Err(RequestError::Nack(
                String::from_utf8_lossy(&e.payload().to_bytes()).into_owned(),
            )
            .into()),
        }
    };
    let decode_err = |source| NodeError::Decode {
        key: keys::data(dev),
        source,
    };
    use troupe_msgs::Request as _;
    let info_bytes = ask(map::GetInfo::NAME, codec::encode(&map::GetInfo, 0.0))?;
    let info = codec::decode::<map::Info>(&info_bytes).map_err(decode_err)?;
    let q = map::GetData {
        col: 0,
        row: 0,
        width: info.msg.width,
        height: info.msg.height,
    };
    let data = ask(map::GetData::NAME, codec::encode(&q, 0.0))?;
    let mut t = Translator::new();
    let key = keys::data(dev);
    let decoded = |b: &[u8]| troupe_msgs::decode_any(b).map_err(decode_err);
    let _ = t.translate(&key, 0, &decoded(&info_bytes)?.msg);
    let cells = decoded(&data)?;
    let outs = t
        .translate(&key, troupe_ros2::stamp_ns(cells.stamp), &cells.msg)
        .unwrap_or_default();
    outs.into_iter()
        .find(|o| o.ty == Type::OccupancyGrid)
        .map(|o| o.data)
        .ok_or_else(|| NodeError::Driver("the map's cells do not make a whole grid".into()))
}

/// Hands a converted ROS 2 message to the driver: a command as a Troupe
/// command, a request (a localizer's pose) as a request whose answer is
/// only logged.
fn deliver(inbox: &Inbox, clock: &Clock, dev: Device, name: &'static str, payload: Vec<u8>) {
    if name == <troupe_msgs::localize::SetPose as troupe_msgs::Request>::NAME {
        let key = keys::req(&dev, name);
        let what = format!("ROS 2 initialpose to {dev}");
        let responder = Responder::new(Box::new(LogSink(what.clone())), clock.clone(), what);
        inbox.push(Event::Request(Request {
            sample: Sample::new(dev, key, payload),
            name: name.to_owned(),
            responder,
        }));
    } else {
        inbox.push(Event::Command(Sample::new(
            dev,
            keys::cmd(&dev, name),
            payload,
        )));
    }
}

/// Where the answer to a request from ROS 2 goes: a refusal is logged.
struct LogSink(String);

impl ReplySink for LogSink {
    fn send(self: Box<Self>, reply: std::result::Result<Vec<u8>, Vec<u8>>) {
        if let Err(nack) = reply {
            tracing::warn!("{} refused: {}", self.0, crate::event::nack_reason(&nack));
        }
    }
}

/// Stops a base whose `cmd_vel` went quiet: one stop command when no
/// Twist came for the timeout after the last. Its thread ends within a
/// second of the subscription that feeds it.
struct Watchdog(Arc<(Mutex<Option<std::time::Instant>>, std::sync::Condvar)>);

impl Watchdog {
    fn start(dev: Device, inbox: Arc<Inbox>, clock: Clock, timeout: Duration) -> Watchdog {
        let shared: Arc<(Mutex<Option<std::time::Instant>>, std::sync::Condvar)> = Arc::default();
        let weak = Arc::downgrade(&shared);
        let spawned = std::thread::Builder::new()
            .name(format!("ros2 cmd_vel {dev}"))
            .spawn(move || loop {
                let Some(shared) = weak.upgrade() else { return };
                let (last, cv) = &*shared;
                let mut g = last.lock().unwrap_or_else(|p| p.into_inner());
                g = match *g {
                    // Woken by a Twist; looks again each second whether
                    // its subscription is gone.
                    None => {
                        cv.wait_timeout(g, Duration::from_secs(1))
                            .unwrap_or_else(|p| p.into_inner())
                            .0
                    }
                    Some(t) => {
                        let due = t + timeout;
                        let now = std::time::Instant::now();
                        if now >= due {
                            *g = None;
                            drop(g);
                            tracing::info!("ROS 2: no cmd_vel for {timeout:?}: stopping {dev}");
                            inbox.push(Event::Command(Sample::new(
                                dev,
                                keys::cmd(&dev, "vel"),
                                live::stop_command(clock.now()),
                            )));
                            continue;
                        }
                        cv.wait_timeout(g, due - now)
                            .unwrap_or_else(|p| p.into_inner())
                            .0
                    }
                };
                drop(g);
            });
        if let Err(e) = spawned {
            tracing::error!("ROS 2: no cmd_vel watchdog for {dev}: {e}");
        }
        Watchdog(shared)
    }

    fn fed(&self) {
        let (last, cv) = &*self.0;
        *last.lock().unwrap_or_else(|p| p.into_inner()) = Some(std::time::Instant::now());
        cv.notify_one();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_attachment_is_zenoh_ext_s_serialization_of_rmw_zenoh_s_fields() {
        let a = Attachment {
            seq: 5,
            stamp_ns: 1_700_000_000_123_456_789,
            gid: [7; 16],
        };
        let z = zenoh_ext::z_serialize(&(a.seq, a.stamp_ns, a.gid));
        assert_eq!(&z.to_bytes()[..], &a.to_bytes()[..]);
    }

    #[test]
    fn a_repeated_problem_is_said_at_powers_of_ten() {
        let said: Vec<u64> = (1..=1000).filter(|&n| power_of_ten(n)).collect();
        assert_eq!(said, [1, 10, 100, 1000]);
    }

    #[test]
    fn flags_give_a_config_or_say_what_is_wrong() {
        let mut a = Ros2Args::default();
        assert_eq!(a.config(None).unwrap(), None);
        a.ros2 = true;
        let r = a.config(None).unwrap().unwrap();
        assert_eq!(r, Ros2::default());
        assert_eq!(r.ns(7000), "/robot_7000");
        // A cfg's section turns it on; a flag given wins over it.
        let file = Ros2Settings {
            domain: Some(3),
            distro: Some("humble".into()),
            ..Ros2Settings::default()
        };
        a.ros2 = false;
        a.ros2_domain = Some(5);
        let r = a.config(Some(&file)).unwrap().unwrap();
        assert_eq!((r.domain, r.distro), (5, Distro::Humble));
        a.ros2_cmd_vel_timeout = Some(f64::INFINITY);
        let e = a.config(Some(&file)).unwrap_err().to_string();
        assert!(e.contains("--ros2-cmd-vel-timeout"), "{e}");
        a.ros2_cmd_vel_timeout = None;
        a.ros2_namespace = Some("robot-{robot}".into());
        assert!(a
            .config(Some(&file))
            .unwrap_err()
            .to_string()
            .contains("not `-`"));
        let wrong = Ros2Settings {
            distro: Some("foxy".into()),
            ..Ros2Settings::default()
        };
        a.ros2_namespace = None;
        assert!(a
            .config(Some(&wrong))
            .unwrap_err()
            .to_string()
            .contains("humble"));
    }
}
