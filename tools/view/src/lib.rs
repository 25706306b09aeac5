//! `troupe view`: the running world in a browser, as Stage's window showed
//! it — the walls, every robot at its true pose, its laser, ranger and sonar
//! readings — and the live devices, as `troupe list` prints them.
//!
//! The binary serves one page (HTML and JavaScript embedded, nothing fetched
//! from elsewhere) and is a Zenoh client like any tool, so it works from any
//! host of a fleet. It asks each simulator for its world once
//! (`simulation` `world`), then keeps only the newest sample of each thing
//! it draws: the models' poses (`simulation` data) and the range readings.
//! Each page gets a stream of frames (server-sent events), one at a time,
//! made when the page can take it and at most `--fps` a second: a slow or
//! stuck page holds no queue and slows no one else. A page says what part
//! of the world it shows, and its frames carry only what lies there (and
//! the range devices whose rays may reach into it).

use std::collections::BTreeMap;
use std::convert::Infallible;
use std::io::Write;
use std::net::{IpAddr, SocketAddr};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use anyhow::Context;
use axum::extract::{Query, State};
use axum::http::header;
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Json, Response};
use axum::routing::get;
use axum::Router;
use serde_json::{json, Value};
use tokio::sync::watch;
use troupe_msgs::{
    codec, keys, laser, localize, map, planner, position2d, power, ranger, simulation, sonar,
    Command as _, Device, Interface, Pose2d,
};
use troupe_node::zenoh::sample::SampleKind;
use troupe_node::ZenohArgs;

/// `troupe view` options.
#[derive(Debug, Clone, clap::Args)]
pub struct ViewArgs {
    /// Address to serve the page on. Loopback by default: the page has no
    /// login of its own.
    #[arg(long, default_value = "127.0.0.1")]
    pub bind: IpAddr,
    /// Port to serve the page on (0: any free one; the address is printed).
    #[arg(long, default_value_t = 8080)]
    pub port: u16,
    /// Frames a second sent to each page, at most.
    #[arg(long, default_value_t = 30.0, value_parser = troupe_node::args::finite)]
    pub fps: f64,
    /// Watch these namespaces instead of the session's one (comma-separated;
    /// `-` for keys under no namespace): the page lists each one's devices
    /// and draws the world of the one chosen.
    #[arg(long, value_name = "NS,…", value_delimiter = ',')]
    pub namespaces: Vec<String>,
}

/// How long a simulator has to answer for its world (and a driver a request).
const WORLD_TIMEOUT: Duration = Duration::from_secs(5);

/// How far outside a page's box a model's pose is still sent (a body
/// reaching into the box is drawn whole).
const POSE_MARGIN: f64 = 1.0;

/// How often localizers are asked for their particles, and how many of
/// them a frame carries at most.
const PARTICLES_EVERY: Duration = Duration::from_millis(500);
const PARTICLES_SHOWN: usize = 400;

/// How long a page's report of its frame rate counts (pages report every 2 s).
const REPORTS_KEPT: Duration = Duration::from_secs(5);

/// What the page's handlers share: each namespace the view watches.
type App = Arc<View>;

/// The namespaces the view watches, each with its newest samples and its
/// session, and what pages say of themselves.
struct View {
    spaces: Vec<(Arc<Shared>, troupe_node::zenoh::Session)>,
    /// The frame rates pages opened with `?report` say they draw at, and
    /// when they said it.
    reports: Mutex<BTreeMap<String, (Instant, [f64; 2])>>,
    /// True once the view stops: the pages' streams end, so the server's
    /// graceful shutdown does not wait on them.
    stopping: watch::Receiver<bool>,
}

impl View {
    /// Namespace `ns` (an index into `--namespaces`; the first when none is
    /// asked for), or the page's error.
    fn space(
        &self,
        ns: Option<usize>,
    ) -> Result<&(Arc<Shared>, troupe_node::zenoh::Session), (axum::http::StatusCode, String)> {
        let k = ns.unwrap_or(0);
        self.spaces.get(k).ok_or_else(|| {
            (
                axum::http::StatusCode::NOT_FOUND,
                format!(
                    "no namespace {k}: this view watches {} (0 to {})",
                    self.spaces.len(),
                    self.spaces.len() - 1
                ),
            )
        })
    }

    /// The frame rates pages reported in the last [`REPORTS_KEPT`], with
    /// the milliseconds a frame took them to draw.
    fn reports(&self) -> BTreeMap<String, [f64; 2]> {
        let r = self.reports.lock().unwrap_or_else(PoisonError::into_inner);
        r.iter()
            .filter(|(_, (at, _))| at.elapsed() < REPORTS_KEPT)
            .map(|(page, &(_, fps))| (page.clone(), fps))
            .collect()
    }
}

/// `?ns=K`: which namespace a request is about.
#[derive(Debug, Default, serde::Deserialize)]
struct Ns {
    ns: Option<usize>,
}

/// The page and its script, served as they are.
const INDEX_HTML: &str = include_str!("page/index.html");
const VIEW_JS: &str = include_str!("page/view.js");

/// The newest of everything the page draws.
#[derive(Default)]
struct Latest {
    /// Live devices and their drivers.
    devices: BTreeMap<Device, String>,
    /// Each simulator's world, by its simulation device.
    worlds: BTreeMap<Device, simulation::World>,
    /// Each map device's grid and its picture (PNG).
    maps: BTreeMap<Device, (map::Info, Arc<Vec<u8>>)>,
    /// Pictures of maps made so far: a page reloads them when it changes
    /// (a map that grows, as the slam driver's, publishes its info anew).
    map_version: u64,
    /// Each simulator's newest poses.
    poses: BTreeMap<Device, simulation::Poses>,
    /// The newest readings of each device the page shows: ranges,
    /// odometry, power.
    readings: BTreeMap<Device, Value>,
    /// Each localizer's newest hypotheses and particles, each planner's
    /// newest state and path.
    nav: BTreeMap<Device, Value>,
    /// Simulated seconds against wall seconds, over the last second or so.
    pace: Pace,
    /// Each device's updates (samples with a stamp of their own: a
    /// ranger's ranges and intensities are one update) so far, the last
    /// stamp, and the count at the last reckoning.
    updates: BTreeMap<Device, (f64, u64, u64)>,
    /// Each device's updates a wall second, reckoned every second.
    rates: BTreeMap<Device, f64>,
    /// What each page shows of the world ([x0, y0, x1, y1], metres): its
    /// frames carry only what lies there.
    boxes: BTreeMap<String, [f64; 4]>,
}

/// The simulation's speed against real time.
#[derive(Default)]
struct Pace {
    /// (wall, simulated) at the start of the window and now.
    from: Option<(Instant, f64)>,
    now: Option<(Instant, f64)>,
    speed: Option<f64>,
}

impl Pace {
    fn at(&mut self, time: f64) {
        let now = (Instant::now(), time);
        let from = *self.from.get_or_insert(now);
        let wall = now.0.duration_since(from.0).as_secs_f64();
        if wall >= 1.0 {
            self.speed = Some((now.1 - from.1) / wall);
            self.from = Some(now);
        }
        self.now = Some(now);
    }
}

/// The frames made since change `version`, by the box they show.
#[derive(Default)]
struct Made {
    version: u64,
    frames: Vec<(Option<[f64; 4]>, Arc<str>)>,
}

struct Shared {
    latest: Mutex<Latest>,
    /// Bumped whenever something drawn changed (in any namespace watched).
    changed: Arc<watch::Sender<u64>>,
    /// The frames made since the last change, by the box they show: pages
    /// that show the same share one.
    made: Mutex<Made>,
    fps: f64,
    /// The namespace the view watches (its session's), if any.
    namespace: Option<String>,
    /// The viewer identity the view joins a fleet as, if it is one: it
    /// offers no commands (the fleet's rules would drop them unseen).
    looking_only: Option<String>,
}

impl Shared {
    /// A namespace's state, empty: who the view joins as and where, as
    /// `session`'s config has them (a fleet's config may name both).
    fn of(
        session: &troupe_node::zenoh::Session,
        changed: Arc<watch::Sender<u64>>,
        fps: f64,
    ) -> Shared {
        let config = session.config();
        Shared {
            latest: Mutex::default(),
            changed,
            made: Mutex::default(),
            fps,
            namespace: config
                .get_typed::<Option<String>>("namespace")
                .ok()
                .flatten(),
            looking_only: config
                .get_typed::<Value>("metadata")
                .ok()
                .and_then(|m| troupe_node::viewer_of(&m)),
        }
    }

    fn latest(&self) -> std::sync::MutexGuard<'_, Latest> {
        self.latest.lock().unwrap_or_else(PoisonError::into_inner)
    }

    fn touch(&self) {
        self.changed.send_modify(|v| *v += 1);
    }

    /// Every world, as the page draws it.
    fn worlds(&self) -> Value {
        let l = self.latest();
        let worlds: Vec<Value> = l
            .worlds
            .iter()
            .map(|(sim, w)| {
                let models: Vec<Value> = w
                    .models
                    .iter()
                    .map(|m| {
                        json!({
                            "name": m.name,
                            "parent": m.parent,
                            "color": css(m.color),
                            "polys": m.polys,
                            "moves": m.moves,
                            "pose": m.pose,
                        })
                    })
                    .collect();
                let devices: Vec<Value> = w
                    .devices
                    .iter()
                    .map(|d| {
                        json!({
                            "device": addr(&d.device),
                            "model": d.model,
                            "sensors": d.sensors.iter().map(|s| json!({
                                "pose": s.pose, "fov": s.fov, "range": s.range, "samples": s.samples,
                            })).collect::<Vec<_>>(),
                        })
                    })
                    .collect();
                json!({ "simulation": addr(sim), "resolution": w.resolution, "models": models, "devices": devices })
            })
            .collect();
        let maps: Vec<Value> = l
            .maps
            .iter()
            .map(|(d, (info, _))| {
                json!({
                    "device": addr(d),
                    "width": info.width,
                    "height": info.height,
                    "resolution": info.resolution,
                    "origin": pose(&info.origin),
                })
            })
            .collect();
        json!({
            "worlds": worlds,
            "maps": maps,
            "namespace": self.namespace,
            "looking_only": self.looking_only,
        })
    }

    /// The live devices, as `troupe list --json` prints them.
    fn devices(&self) -> Value {
        let l = self.latest();
        Value::Array(
            l.devices
                .iter()
                .map(|(d, driver)| {
                    json!({ "robot": d.robot, "device": format!("{}:{}", d.interface, d.index), "driver": driver })
                })
                .collect(),
        )
    }

    /// The frame for `page` after change `version`, as text: made once for
    /// every page that shows the same box.
    fn frame_text(&self, version: u64, page: Option<&str>) -> Arc<str> {
        let seen = page.and_then(|p| self.latest().boxes.get(p).copied());
        let mut made = self.made.lock().unwrap_or_else(PoisonError::into_inner);
        if made.version != version {
            *made = Made {
                version,
                frames: Vec::new(),
            };
        }
        if let Some((_, text)) = made.frames.iter().find(|(b, _)| *b == seen) {
            return text.clone();
        }
        let text: Arc<str> = self.frame(seen).to_string().into();
        made.frames.push((seen, text.clone()));
        text
    }

    /// One frame of what lies in `seen` (a box of the world, metres; all
    /// of it if `None`): the time, the speed, every moving model's pose and
    /// every range device's readings.
    fn frame(&self, seen: Option<[f64; 4]>) -> Value {
        let l = self.latest();
        let inside = |(x, y): (f64, f64), margin: f64| {
            seen.is_none_or(|[x0, y0, x1, y1]| {
                x >= x0 - margin && x <= x1 + margin && y >= y0 - margin && y <= y1 + margin
            })
        };
        // A range device is sent when its rays may reach into the box.
        let mut unseen = std::collections::BTreeSet::new();
        if seen.is_some() {
            for (sim, w) in &l.worlds {
                let live = l.poses.get(sim);
                for d in &w.devices {
                    let Some(reach) = d
                        .sensors
                        .iter()
                        .map(|s| f64::from(s.range))
                        .reduce(f64::max)
                    else {
                        continue;
                    };
                    let at = live
                        .and_then(|p| p.poses.iter().find(|(m, _)| *m == d.model))
                        .map(|(_, p)| *p)
                        .or_else(|| w.models.get(d.model as usize).map(|m| m.pose));
                    if let Some([x, y, _]) = at {
                        if !inside((f64::from(x), f64::from(y)), reach) {
                            unseen.insert(d.device);
                        }
                    }
                }
            }
        }
        let time = l
            .poses
            .values()
            .map(|p| p.time)
            .fold(None, |a: Option<f64>, t| Some(a.map_or(t, |a| a.max(t))));
        // Each simulator's time: the page glides its models from one set
        // of poses to the next.
        let times: serde_json::Map<String, Value> = l
            .poses
            .iter()
            .map(|(sim, p)| (addr(sim), json!(p.time)))
            .collect();
        let poses: serde_json::Map<String, Value> = l
            .poses
            .iter()
            .map(|(sim, p)| {
                let list: serde_json::Map<String, Value> = p
                    .poses
                    .iter()
                    .filter(|(_, [x, y, _])| inside((f64::from(*x), f64::from(*y)), POSE_MARGIN))
                    .map(|(m, [x, y, a])| (m.to_string(), json!([round(*x), round(*y), round(*a)])))
                    .collect();
                (addr(sim), Value::Object(list))
            })
            .collect();
        let readings: serde_json::Map<String, Value> = l
            .readings
            .iter()
            .filter(|(d, _)| !unseen.contains(*d))
            .map(|(d, s)| (addr(d), s.clone()))
            .collect();
        let nav: serde_json::Map<String, Value> =
            l.nav.iter().map(|(d, s)| (addr(d), s.clone())).collect();
        let rates: serde_json::Map<String, Value> = l
            .rates
            .iter()
            .map(|(d, r)| (addr(d), json!((r * 10.0).round() / 10.0)))
            .collect();
        json!({
            "time": time,
            "times": times,
            "rates": rates,
            "speed": l.pace.speed,
            "devices": l.devices.len(),
            // The worlds /api/world holds: a pose names a model of its
            // simulator's world, which may come a moment after the poses.
            "worlds": l.worlds.len(),
            "maps": l.maps.len(),
            "map_version": l.map_version,
            "poses": poses,
            "readings": readings,
            "nav": nav,
        })
    }
}

/// `6665:laser:0`.
fn addr(d: &Device) -> String {
    format!("{}:{}:{}", d.robot, d.interface, d.index)
}

/// A colour as CSS writes it.
fn css(c: troupe_msgs::Color) -> String {
    let [r, g, b] = c.rgb8();
    format!("#{r:02x}{g:02x}{b:02x}")
}

/// Millimetres are enough on screen, and keep frames small.
fn round(v: f32) -> f64 {
    (f64::from(v) * 1000.0).round() / 1000.0
}

fn ranges(v: impl IntoIterator<Item = f64>) -> Vec<f64> {
    v.into_iter()
        .map(|r| (r * 1000.0).round() / 1000.0)
        .collect()
}

fn pose(p: &Pose2d) -> Value {
    json!([round(p.x as f32), round(p.y as f32), round(p.yaw as f32)])
}

/// Keeps a navigation sample: a localizer's hypotheses, a planner's state.
/// Returns the planner whose path changed (its waypoints are to be asked).
fn take_nav(shared: &Shared, dev: Device, payload: &[u8]) -> Option<Device> {
    let mut l = shared.latest();
    let mut ask = None;
    match dev.interface {
        Interface::Localize => {
            let h = codec::decode::<localize::Hypoths>(payload).ok()?.msg;
            let entry = l.nav.entry(dev).or_insert_with(|| json!({}));
            entry["kind"] = json!("localize");
            entry["hypoths"] = h
                .hypoths
                .iter()
                .map(|h| json!({ "mean": pose(&h.mean), "cov": h.cov, "weight": h.weight }))
                .collect();
        }
        Interface::Planner => {
            let st = codec::decode::<planner::State>(payload).ok()?.msg;
            let entry = l.nav.entry(dev).or_insert_with(|| json!({}));
            // A new goal or a new count of waypoints: a new path.
            let path = json!([st.valid, pose(&st.goal), st.waypoints_count]);
            if entry["path_of"] != path {
                entry["path_of"] = path;
                ask = Some(dev);
            }
            entry["kind"] = json!("planner");
            entry["valid"] = json!(st.valid);
            entry["done"] = json!(st.done);
            entry["pose"] = pose(&st.pose);
            entry["goal"] = pose(&st.goal);
            entry["waypoint_idx"] = json!(st.waypoint_idx);
            entry["waypoints_count"] = json!(st.waypoints_count);
            entry["path"] = remaining_path(entry);
        }
        _ => return None,
    }
    drop(l);
    shared.touch();
    ask
}

/// What is left of a planner's path: from the robot to the waypoint it
/// drives to, then on to the goal. As Player's wavefront counts, the
/// waypoint driven to is `waypoint_idx - 1` (it moves on the moment it
/// takes a waypoint); before the first, the path starts at waypoint 0.
/// Empty without a valid path, once done, or before the waypoints came.
fn remaining_path(planner: &Value) -> Value {
    let waypoints = planner["waypoints"].as_array();
    let driving = planner["valid"] == true && planner["done"] != true;
    match (waypoints, driving) {
        (Some(w), true) if !w.is_empty() => {
            let idx = planner["waypoint_idx"].as_i64().unwrap_or(0);
            let from = usize::try_from(idx - 1).unwrap_or(0).min(w.len() - 1);
            std::iter::once(planner["pose"].clone())
                .chain(w[from..].iter().cloned())
                .collect()
        }
        _ => json!([]),
    }
}

/// Asks `dev` (a planner) for its waypoints, or (a localizer) for its
/// particles, and keeps them with its state.
async fn ask_nav(session: troupe_node::zenoh::Session, shared: Arc<Shared>, dev: Device) {
    let (field, value) = if dev.interface == Interface::Planner {
        let Ok(w) = request(&session, dev, &planner::GetWaypoints).await else {
            return;
        };
        ("waypoints", w.waypoints.iter().map(pose).collect())
    } else {
        let Ok(p) = request(&session, dev, &localize::GetParticles).await else {
            return;
        };
        // A few hundred show the cloud as well as thousands do.
        let every = p.particles.len().div_ceil(PARTICLES_SHOWN).max(1);
        let shown = p.particles.iter().step_by(every);
        ("particles", shown.map(|q| pose(&q.pose)).collect::<Value>())
    };
    let mut l = shared.latest();
    let entry = l.nav.entry(dev).or_insert_with(|| json!({}));
    entry[field] = value;
    if dev.interface == Interface::Planner {
        entry["path"] = remaining_path(entry);
    }
    entry["kind"] = json!(if dev.interface == Interface::Planner {
        "planner"
    } else {
        "localize"
    });
    drop(l);
    shared.touch();
}

/// The interfaces whose data the page draws.
const DRAWN: [Interface; 8] = [
    Interface::Position2d,
    Interface::Power,
    Interface::Simulation,
    Interface::Laser,
    Interface::Ranger,
    Interface::Sonar,
    Interface::Localize,
    Interface::Planner,
];

/// Takes a sample of a device the page draws: its reading, or its
/// navigation state (asking a planner for its new path, on `rt`).
fn ingest(
    shared: &Arc<Shared>,
    session: &troupe_node::zenoh::Session,
    rt: &tokio::runtime::Handle,
    dev: Device,
    payload: &[u8],
) {
    match dev.interface {
        Interface::Localize | Interface::Planner => {
            if let Some(planner) = take_nav(shared, dev, payload) {
                rt.spawn(ask_nav(session.clone(), shared.clone(), planner));
            }
        }
        _ => take(shared, dev, payload),
    }
}

/// Takes the newest samples `dev`'s driver keeps (a device that publishes
/// only on change, such as a localizer at rest, is drawn at once).
async fn fetch_latest(session: troupe_node::zenoh::Session, shared: Arc<Shared>, dev: Device) {
    let Ok(replies) = troupe_node::ask(&session, &keys::data(&dev), WORLD_TIMEOUT).await else {
        return;
    };
    let rt = tokio::runtime::Handle::current();
    while let Ok(reply) = replies.recv_async().await {
        if let Ok(sample) = reply.into_result() {
            ingest(&shared, &session, &rt, dev, &sample.payload().to_bytes());
        }
    }
}

/// Takes one sample of a device the page draws.
fn take(shared: &Shared, dev: Device, payload: &[u8]) {
    let scan = match dev.interface {
        Interface::Simulation => match codec::decode::<simulation::Poses>(payload) {
            Ok(p) => {
                let mut l = shared.latest();
                l.pace.at(p.msg.time);
                l.poses.insert(dev, p.msg);
                drop(l);
                shared.touch();
                return;
            }
            Err(_) => return,
        },
        Interface::Laser => codec::decode::<laser::Scan>(payload).ok().map(|s| {
            let s = s.msg;
            json!({ "kind": "laser", "min": s.min_angle, "res": s.resolution,
                    "ranges": ranges(s.ranges.iter().map(|&r| f64::from(r))) })
        }),
        Interface::Ranger => codec::decode::<ranger::Ranges>(payload)
            .ok()
            .map(|r| json!({ "kind": "ranger", "ranges": ranges(r.msg.ranges) })),
        Interface::Position2d => codec::decode::<position2d::Data>(payload).ok().map(|d| {
            let d = d.msg;
            json!({ "kind": "position2d", "pose": pose(&d.pose), "vel": pose(&d.vel), "stall": d.stall })
        }),
        Interface::Power => codec::decode::<power::Data>(payload).ok().map(|d| {
            let d = d.msg;
            json!({ "kind": "power", "valid": d.valid, "volts": d.volts, "percent": d.percent, "charging": d.charging })
        }),
        Interface::Sonar => codec::decode::<sonar::Ranges>(payload).ok().map(|r| {
            json!({ "kind": "ranger", "ranges": ranges(r.msg.ranges.iter().map(|&v| f64::from(v))) })
        }),
        _ => None,
    };
    // (A ranger's intensities share its key: they are not drawn.)
    if let Some(scan) = scan {
        shared.latest().readings.insert(dev, scan);
        shared.touch();
    }
}

/// Asks the simulator of `sim` for its world and keeps it.
async fn fetch_world(session: troupe_node::zenoh::Session, shared: Arc<Shared>, sim: Device) {
    match request_on_arrival(&session, sim, &simulation::GetWorld).await {
        Ok(w) => {
            tracing::info!("{sim}: a world of {} models", w.models.len());
            shared.latest().worlds.insert(sim, w);
            shared.touch();
        }
        Err(e) => tracing::warn!("no world from {sim} (not a Troupe simulator?): {e}"),
    }
}

/// How many times a device just come is asked before it counts as not
/// answering, a second apart (see [`request_on_arrival`]).
const ARRIVAL_ASKS: u32 = 5;

/// Sends request `req` to `dev` and waits (at most [`WORLD_TIMEOUT`]) for
/// its answer; the error says what went wrong, naming the device.
async fn request<R: troupe_msgs::Request>(
    session: &troupe_node::zenoh::Session,
    dev: Device,
    req: &R,
) -> anyhow::Result<R::Reply> {
    ask_once(session, dev, req).await?.ok_or_else(|| {
        anyhow::anyhow!("{dev} did not answer (no such device, or this identity may not ask it)")
    })
}

/// [`request`] of a device whose token has just come: the token can reach
/// this session before the device's queryable does (declarations travel
/// apart), and an ask then finds no one to answer. Asked again, a second
/// apart, up to [`ARRIVAL_ASKS`] times, while nothing answers.
async fn request_on_arrival<R: troupe_msgs::Request>(
    session: &troupe_node::zenoh::Session,
    dev: Device,
    req: &R,
) -> anyhow::Result<R::Reply> {
    for _ in 1..ARRIVAL_ASKS {
        if let Some(reply) = ask_once(session, dev, req).await? {
            return Ok(reply);
        }
        tracing::debug!("{dev} did not answer yet; asking again");
        tokio::time::sleep(Duration::from_secs(1)).await;
    }
    request(session, dev, req).await
}

/// Sends request `req` to `dev` once: its answer, `None` when no one
/// answered (within [`WORLD_TIMEOUT`]), or what went wrong.
async fn ask_once<R: troupe_msgs::Request>(
    session: &troupe_node::zenoh::Session,
    dev: Device,
    req: &R,
) -> anyhow::Result<Option<R::Reply>> {
    let key = keys::req(&dev, R::NAME);
    let replies = troupe_node::ask(session, &key, WORLD_TIMEOUT)
        .payload(codec::encode(req, troupe_node::Clock::wall().now()))
        .await
        .map_err(|e| anyhow::anyhow!("asking {key}: {e}"))?;
    let Ok(reply) = replies.recv_async().await else {
        return Ok(None);
    };
    let reply = reply.into_result().map_err(|e| {
        let reason = codec::decode::<troupe_msgs::common::Nack>(&e.payload().to_bytes())
            .map_or_else(|_| "no reason given".to_owned(), |n| n.msg.reason);
        anyhow::anyhow!("{dev} refused: {reason}")
    })?;
    codec::decode::<R::Reply>(&reply.payload().to_bytes())
        .map(|s| Some(s.msg))
        .map_err(|e| anyhow::anyhow!("{dev}'s answer does not decode: {e}"))
}

/// Asks map device `dev` for its info and every cell, and keeps its
/// picture: free cells white, unknown grey, occupied black, north up.
async fn fetch_map(session: troupe_node::zenoh::Session, shared: Arc<Shared>, dev: Device) {
    let picture = async {
        let info = request_on_arrival(&session, dev, &map::GetInfo).await?;
        let whole = map::GetData {
            col: 0,
            row: 0,
            width: info.width,
            height: info.height,
        };
        let tile = request(&session, dev, &whole).await?;
        let grid = troupe_geom::OccMap::from_tile(info, &tile)?;
        let (w, h) = grid.size();
        let img = image::GrayImage::from_fn(w as u32, h as u32, |x, y| {
            let v = grid.get(i64::from(x), h as i64 - 1 - i64::from(y));
            image::Luma([match v {
                Some(c) if c < 0 => 255,
                Some(0) | None => 200,
                Some(_) => 0,
            }])
        });
        let mut png = Vec::new();
        img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)?;
        anyhow::Ok((info, png))
    };
    match picture.await {
        Ok((info, png)) => {
            tracing::info!("{dev}: a map of {}x{} cells", info.width, info.height);
            let mut l = shared.latest();
            l.maps.insert(dev, (info, Arc::new(png)));
            l.map_version += 1;
            drop(l);
            shared.touch();
        }
        Err(e) => tracing::warn!("cannot draw map {dev}: {e:#}"),
    }
}

/// `GET /api/map/6665:map:0`: a map device's picture.
async fn map_picture(
    State(v): State<App>,
    Query(q): Query<Ns>,
    axum::extract::Path(dev): axum::extract::Path<String>,
) -> Response {
    let s = match v.space(q.ns) {
        Ok((s, _)) => s,
        Err(r) => return r.into_response(),
    };
    let found = dev
        .parse::<troupe_msgs::DevAddr>()
        .ok()
        .map(|a| a.device(troupe_msgs::DEFAULT_ROBOT))
        .and_then(|d| s.latest().maps.get(&d).map(|(_, png)| png.clone()));
    match found {
        Some(png) => ([(header::CONTENT_TYPE, "image/png")], png.as_ref().clone()).into_response(),
        None => (axum::http::StatusCode::NOT_FOUND, format!("no map `{dev}`")).into_response(),
    }
}

/// `troupe view`.
pub fn run(a: ViewArgs, z: &ZenohArgs) -> anyhow::Result<()> {
    troupe_node::process::supervised()?;
    // The namespaces watched: the session's, or those asked for.
    let namespaces: Vec<Option<String>> = if a.namespaces.is_empty() {
        vec![z.namespace.clone()]
    } else {
        a.namespaces
            .iter()
            .map(|n| (n != "-").then(|| n.clone()))
            .collect()
    };
    let joining = |ns: &Option<String>| ZenohArgs {
        namespace: ns.clone(),
        ..z.clone()
    };
    let Some((rt, mut signals, session)) = troupe_node::process::session_runtime(
        &joining(&namespaces[0]),
        2,
        troupe_node::Mode::Peer,
    )?
    else {
        return Ok(());
    };
    let changed = Arc::new(watch::channel(0).0);
    let fps = a.fps.clamp(0.1, 240.0);
    rt.block_on(async move {
        let mut sessions = vec![session];
        for ns in &namespaces[1..] {
            let Some(s) = signals
                .unless_stopped(joining(ns).open_in_background(troupe_node::Mode::Peer))
                .await?
            else {
                return Ok(());
            };
            sessions.push(s);
        }
        let mut spaces = Vec::new();
        let mut held = Vec::new();
        for (session, asked) in sessions.into_iter().zip(&namespaces) {
            let shared = Arc::new(Shared::of(&session, changed.clone(), fps));
            if asked.is_none() && shared.namespace.is_some() && !a.namespaces.is_empty() {
                anyhow::bail!(
                    "--namespaces -: the Zenoh config puts this view's sessions in namespace `{}`; \
                     it cannot watch keys under none",
                    shared.namespace.as_deref().unwrap_or_default()
                );
            }
            // (Every session has the same config: said once.)
            if let (true, Some(me)) = (spaces.is_empty(), &shared.looking_only) {
                tracing::info!("joining as the viewer `{me}`: the page offers no commands");
            }
            held.push(watch_space(shared.clone(), session.clone()).await?);
            spaces.push((shared, session));
        }
        let (stop, stopping) = watch::channel(false);
        let app: App = Arc::new(View {
            spaces,
            reports: Mutex::default(),
            stopping,
        });
        let routes = Router::new()
            .route(
                "/",
                get(|| async { page(INDEX_HTML, "text/html; charset=utf-8") }),
            )
            .route(
                "/view.js",
                get(|| async { page(VIEW_JS, "text/javascript; charset=utf-8") }),
            )
            .route(
                "/api/world",
                get(|State(v): State<App>, Query(q): Query<Ns>| async move {
                    v.space(q.ns).map(|(s, _)| {
                        let mut w = s.worlds();
                        w["namespaces"] =
                            v.spaces.iter().map(|(s, _)| json!(s.namespace)).collect();
                        Json(w)
                    })
                }),
            )
            .route(
                "/api/devices",
                get(|State(v): State<App>, Query(q): Query<Ns>| async move {
                    v.space(q.ns).map(|(s, _)| Json(s.devices()))
                }),
            )
            .route(
                "/api/frame",
                get(|State(v): State<App>, Query(q): Query<Ns>| async move {
                    v.space(q.ns).map(|(s, _)| Json(s.frame(None)))
                }),
            )
            .route("/api/stream", get(stream))
            .route("/api/map/{device}", get(map_picture))
            .route("/api/command", axum::routing::post(command))
            .route(
                "/api/view",
                axum::routing::post(|State(v): State<App>, Json(b): Json<ViewBox>| async move {
                    v.space(b.ns).map(|(s, _)| {
                        s.latest().boxes.insert(b.page, b.area);
                        s.touch();
                        "noted"
                    })
                }),
            )
            .route(
                "/api/report",
                axum::routing::post(|State(v): State<App>, Json(r): Json<Report>| async move {
                    v.reports
                        .lock()
                        .unwrap_or_else(PoisonError::into_inner)
                        .insert(r.page, (Instant::now(), [r.fps, r.ms]));
                    "noted"
                })
                .get(|State(v): State<App>| async move { Json(v.reports()) }),
            )
            .with_state(app);
        let listener = tokio::net::TcpListener::bind(SocketAddr::new(a.bind, a.port))
            .await
            .with_context(|| format!("serving the view on {}:{}", a.bind, a.port))?;
        let at = listener.local_addr()?;
        {
            let mut out = std::io::stdout().lock();
            writeln!(out, "troupe view: http://{at}/")?;
            out.flush()?;
        }
        axum::serve(listener, routes)
            .with_graceful_shutdown(async move {
                signals.recv().await;
                // Open streams (a page left open) end now.
                let _ = stop.send(true);
            })
            .await
            .context("serving the view")?;
        tracing::info!("view stopped");
        drop(held);
        anyhow::Ok(())
    })
}

/// Subscriptions that feed a namespace's [`Shared`], held while the view
/// runs.
type Held = (
    troupe_node::zenoh::pubsub::Subscriber<()>,
    troupe_node::zenoh::pubsub::Subscriber<()>,
);

/// Feeds `shared` from `session`: the live devices (a simulator's world
/// and a map's picture asked for as they come), every drawn device's
/// samples, the devices' rates each second, localizers' particles twice a
/// second.
async fn watch_space(
    shared: Arc<Shared>,
    session: troupe_node::zenoh::Session,
) -> anyhow::Result<Held> {
    let (s, sess) = (shared.clone(), session.clone());
    let handle = tokio::runtime::Handle::current();
    let tokens = session
        .liveliness()
        .declare_subscriber(keys::tokens(None))
        .history(true)
        .callback(move |sample| {
            let Ok((dev, driver)) = keys::parse_token(sample.key_expr().as_str()) else {
                return;
            };
            let mut l = s.latest();
            match sample.kind() {
                SampleKind::Put => {
                    l.devices.insert(dev, driver);
                    if dev.interface == Interface::Simulation {
                        handle.spawn(fetch_world(sess.clone(), s.clone(), dev));
                    }
                    if dev.interface == Interface::Map {
                        handle.spawn(fetch_map(sess.clone(), s.clone(), dev));
                    }
                    if DRAWN.contains(&dev.interface) {
                        handle.spawn(fetch_latest(sess.clone(), s.clone(), dev));
                    }
                }
                SampleKind::Delete => {
                    l.devices.remove(&dev);
                    l.worlds.remove(&dev);
                    l.maps.remove(&dev);
                    l.updates.remove(&dev);
                    l.poses.remove(&dev);
                    l.readings.remove(&dev);
                }
            }
            drop(l);
            s.touch();
        })
        .await
        .map_err(|e| anyhow::anyhow!("watching devices: {e}"))?;
    // Every device's samples: counted (their rates reckoned each second),
    // and taken where the page draws them.
    let (s, sess) = (shared.clone(), session.clone());
    let rt = tokio::runtime::Handle::current();
    let data = session
        .declare_subscriber(keys::data_all())
        .callback(move |sample| {
            let Ok(dev) = keys::parse_data(sample.key_expr().as_str()) else {
                return;
            };
            let bytes = sample.payload().to_bytes();
            let Ok((_, stamp, _)) = codec::split(&bytes) else {
                return;
            };
            {
                let mut l = s.latest();
                let u = l.updates.entry(dev).or_insert((f64::NAN, 0, 0));
                if u.0 != stamp {
                    (u.0, u.1) = (stamp, u.1 + 1);
                }
            }
            if DRAWN.contains(&dev.interface) {
                ingest(&s, &sess, &rt, dev, &bytes);
            } else if dev.interface == Interface::Map
                && codec::schema_of(&bytes)
                    .is_ok_and(|t| t == <map::Info as troupe_msgs::Message>::SCHEMA)
            {
                // A map that says it changed: draw it again.
                rt.spawn(fetch_map(sess.clone(), s.clone(), dev));
            }
        })
        .await
        .map_err(|e| anyhow::anyhow!("subscribing to the devices' data: {e}"))?;
    let s = shared.clone();
    tokio::spawn(async move {
        let mut every = tokio::time::interval(Duration::from_secs(1));
        let mut then = Instant::now();
        loop {
            every.tick().await;
            let wall = then.elapsed().as_secs_f64().max(1e-3);
            then = Instant::now();
            let mut l = s.latest();
            let Latest {
                updates,
                rates,
                devices,
                ..
            } = &mut *l;
            rates.clear();
            for (d, u) in updates.iter_mut() {
                if devices.contains_key(d) {
                    rates.insert(*d, (u.1 - u.2) as f64 / wall);
                }
                u.2 = u.1;
            }
            drop(l);
            s.touch();
        }
    });
    // Localizers' particles, twice a second.
    tokio::spawn(async move {
        let mut every = tokio::time::interval(PARTICLES_EVERY);
        loop {
            every.tick().await;
            let localizers: Vec<Device> = shared
                .latest()
                .devices
                .keys()
                .copied()
                .filter(|d| d.interface == Interface::Localize)
                .collect();
            for d in localizers {
                ask_nav(session.clone(), shared.clone(), d).await;
            }
        }
    });
    Ok((tokens, data))
}

fn page(body: &'static str, kind: &'static str) -> Response {
    (
        [
            (header::CONTENT_TYPE, kind),
            (header::CACHE_CONTROL, "no-cache"),
        ],
        body,
    )
        .into_response()
}

/// A page's stream of frames: the next frame is made only once the page
/// took the last one, something changed, and 1/fps has passed.
async fn stream(
    State(v): State<App>,
    Query(q): Query<StreamQuery>,
) -> Result<
    Sse<impl futures::Stream<Item = Result<Event, Infallible>>>,
    (axum::http::StatusCode, String),
> {
    let s = v.space(q.ns)?.0.clone();
    let rx = s.changed.subscribe();
    let period = Duration::from_secs_f64(1.0 / s.fps);
    // The page's box goes with its stream.
    let page = q.page.map(|page| PageBox {
        shared: s.clone(),
        page,
    });
    let stopping = v.stopping.clone();
    let frames = futures::stream::unfold(
        (s, rx, None::<tokio::time::Instant>, page, stopping),
        move |(s, mut rx, last, page, mut stopping)| async move {
            let next = async {
                if let Some(t) = last {
                    tokio::time::sleep_until(t + period).await;
                }
                rx.changed().await
            };
            // Ends with the view (its sender dropped, or it stops).
            tokio::select! {
                changed = next => changed.ok()?,
                _ = stopping.wait_for(|stop| *stop) => return None,
            }
            let version = *rx.borrow_and_update();
            // (The period runs from when a frame is begun: making it is
            // part of the frame's time.)
            let begun = tokio::time::Instant::now();
            let frame = s.frame_text(version, page.as_ref().map(|p| p.page.as_str()));
            let event = Event::default().data(&*frame);
            Some((Ok(event), (s, rx, Some(begun), page, stopping)))
        },
    );
    Ok(Sse::new(frames).keep_alive(KeepAlive::default()))
}

/// `/api/stream?page=ID&ns=K`: the page that reads the stream, for its
/// box, and the namespace it shows.
#[derive(Debug, serde::Deserialize)]
struct StreamQuery {
    page: Option<String>,
    ns: Option<usize>,
}

/// A page's box, forgotten when its stream ends.
struct PageBox {
    shared: Arc<Shared>,
    page: String,
}

impl Drop for PageBox {
    fn drop(&mut self) {
        self.shared.latest().boxes.remove(&self.page);
    }
}

/// `POST /api/view`: what a page shows of the world.
#[derive(Debug, serde::Deserialize)]
struct ViewBox {
    page: String,
    /// The namespace the page shows (an index into `--namespaces`).
    ns: Option<usize>,
    /// x0, y0, x1, y1 (metres).
    #[serde(rename = "box")]
    area: [f64; 4],
}

/// A page's word on how fast it draws (pages opened with `?report`, as
/// `troupe bench view` opens them).
#[derive(Debug, serde::Deserialize)]
struct Report {
    page: String,
    /// Frames drawn a second.
    fps: f64,
    /// Milliseconds a frame took to draw, on average.
    ms: f64,
}

/// What the page asks of a device: a planner's goal, a localizer's pose
/// (rviz's "2D Goal" and "2D Pose Estimate"), a base's speeds (teleop).
#[derive(Debug, serde::Deserialize)]
struct Order {
    /// The namespace of the device (an index into `--namespaces`).
    ns: Option<usize>,
    /// `6665:planner:0`.
    device: String,
    goal: Option<[f64; 3]>,
    pose: Option<[f64; 3]>,
    vel: Option<[f64; 3]>,
}

/// `POST /api/command`: sends the page's order. 200 once sent (a command)
/// or acknowledged (a request); 400 for an order that makes no sense, 403
/// from a view that joins as a viewer, 502 with the reason when the driver
/// refused or did not answer.
async fn command(State(v): State<App>, Json(o): Json<Order>) -> Response {
    use axum::http::StatusCode;
    let (s, session) = match v.space(o.ns) {
        Ok(space) => space,
        Err(r) => return r.into_response(),
    };
    if let Some(me) = &s.looking_only {
        return (
            StatusCode::FORBIDDEN,
            format!(
                "this view joins the fleet as the viewer `{me}`, which may look, not command \
                 (the fleet's access rules would drop the order)"
            ),
        )
            .into_response();
    }
    let bad = |why: String| (StatusCode::BAD_REQUEST, why).into_response();
    let dev: Device = match o.device.parse::<troupe_msgs::DevAddr>() {
        Ok(a) => a.device(troupe_msgs::DEFAULT_ROBOT),
        Err(e) => return bad(format!("`{}`: {e}", o.device)),
    };
    let p = |v: [f64; 3]| Pose2d::new(v[0], v[1], v[2]);
    let gone = |why: String| (StatusCode::BAD_GATEWAY, why).into_response();
    // A command goes out; a request is answered.
    let stamp = troupe_node::Clock::wall().now();
    match (dev.interface, o.goal, o.pose, o.vel) {
        (Interface::Planner, Some(g), None, None) => {
            let goal = planner::Goal { goal: p(g) };
            put(
                session,
                keys::cmd(&dev, planner::Goal::NAME),
                codec::encode(&goal, stamp),
            )
            .await
        }
        (Interface::Position2d, None, None, Some(v)) => {
            let vel = position2d::CmdVel {
                vel: p(v),
                state: true,
            };
            put(
                session,
                keys::cmd(&dev, position2d::CmdVel::NAME),
                codec::encode(&vel, stamp),
            )
            .await
        }
        (Interface::Localize, None, Some(m), None) => {
            let set = localize::SetPose {
                mean: p(m),
                // As playerv sets it: half a metre and 10° of doubt.
                cov: [0.25, 0.25, 10f64.to_radians().powi(2), 0.0, 0.0, 0.0],
            };
            match request(session, dev, &set).await {
                Ok(_) => (StatusCode::OK, "acknowledged").into_response(),
                Err(e) => gone(format!("{e:#}")),
            }
        }
        _ => bad(format!(
            "{dev}: a planner takes a goal, a localizer a pose, a position2d a vel"
        )),
    }
}

/// Puts a command: 200 once sent, 502 if it could not be.
async fn put(session: &troupe_node::zenoh::Session, key: String, payload: Vec<u8>) -> Response {
    use axum::http::StatusCode;
    match session.put(&key, payload).await {
        Ok(()) => (StatusCode::OK, "sent").into_response(),
        Err(e) => (StatusCode::BAD_GATEWAY, format!("sending {key}: {e}")).into_response(),
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_path_drawn_starts_at_the_waypoint_driven_to() {
        let mut p = json!({"valid": true, "done": false, "pose": [0.0, 0.0, 0.0],
            "waypoints": [[1.0, 0.0, 0.0], [2.0, 1.0, 0.0], [3.0, 1.0, 0.0]], "waypoint_idx": 2});
        // Wavefront drives to waypoints[1] once it reports index 2.
        assert_eq!(
            super::remaining_path(&p),
            json!([[0.0, 0.0, 0.0], [2.0, 1.0, 0.0], [3.0, 1.0, 0.0]])
        );
        p["waypoint_idx"] = json!(-1);
        assert_eq!(super::remaining_path(&p).as_array().map(Vec::len), Some(4));
        p["done"] = json!(true);
        assert_eq!(super::remaining_path(&p), json!([]));
    }

    use super::*;

    fn shared() -> Shared {
        Shared {
            latest: Mutex::default(),
            changed: Arc::new(watch::channel(0).0),
            made: Mutex::default(),
            fps: 30.0,
            namespace: None,
            looking_only: None,
        }
    }

    #[test]
    fn pages_that_show_the_same_share_one_frame_until_the_next_change() {
        let s = shared();
        {
            let mut l = s.latest();
            l.boxes.insert("a".into(), [0.0, 0.0, 1.0, 1.0]);
            l.boxes.insert("b".into(), [0.0, 0.0, 1.0, 1.0]);
            l.boxes.insert("far".into(), [5.0, 5.0, 6.0, 6.0]);
        }
        let a = s.frame_text(1, Some("a"));
        // Same box, same change: the very same text, made once.
        assert!(Arc::ptr_eq(&a, &s.frame_text(1, Some("b"))));
        // Another box, or no box: a frame of its own.
        assert!(!Arc::ptr_eq(&a, &s.frame_text(1, Some("far"))));
        assert!(!Arc::ptr_eq(&a, &s.frame_text(1, None)));
        // The next change: made anew, with what changed.
        s.latest().devices.insert(
            "6665:laser:0"
                .parse::<troupe_msgs::DevAddr>()
                .unwrap()
                .device(6665),
            "sicklms200".into(),
        );
        let after = s.frame_text(2, Some("b"));
        assert!(!Arc::ptr_eq(&a, &after));
        let f: Value = serde_json::from_str(&after).unwrap();
        assert_eq!(f["devices"], 1);
        assert_eq!(s.made.lock().unwrap().frames.len(), 1);
    }
}
