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
//! stuck page holds no queue and slows no one else.

use std::collections::BTreeMap;
use std::convert::Infallible;
use std::io::Write;
use std::net::{IpAddr, SocketAddr};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use anyhow::Context;
use axum::extract::State;
use axum::http::header;
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Json, Response};
use axum::routing::get;
use axum::Router;
use serde_json::{json, Value};
use tokio::sync::watch;
use troupe_msgs::{codec, keys, laser, ranger, simulation, sonar, Device, Interface};
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
    #[arg(long, default_value_t = 30.0)]
    pub fps: f64,
}

/// How long a simulator has to answer for its world.
const WORLD_TIMEOUT: Duration = Duration::from_secs(5);

/// The page and its script, served as they are.
const INDEX_HTML: &str = include_str!("view/index.html");
const VIEW_JS: &str = include_str!("view/view.js");

/// The newest of everything the page draws.
#[derive(Default)]
struct Latest {
    /// Live devices and their drivers.
    devices: BTreeMap<Device, String>,
    /// Each simulator's world, by its simulation device.
    worlds: BTreeMap<Device, simulation::World>,
    /// Each simulator's newest poses.
    poses: BTreeMap<Device, simulation::Poses>,
    /// Each range device's newest readings.
    scans: BTreeMap<Device, Value>,
    /// Simulated seconds against wall seconds, over the last second or so.
    pace: Pace,
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

struct Shared {
    latest: Mutex<Latest>,
    /// Bumped whenever something drawn changed.
    changed: watch::Sender<u64>,
    fps: f64,
}

impl Shared {
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
        json!({ "worlds": worlds })
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

    /// One frame: the time, the speed, every moving model's pose and every
    /// range device's readings.
    fn frame(&self) -> Value {
        let l = self.latest();
        let time = l
            .poses
            .values()
            .map(|p| p.time)
            .fold(None, |a: Option<f64>, t| Some(a.map_or(t, |a| a.max(t))));
        let poses: serde_json::Map<String, Value> = l
            .poses
            .iter()
            .map(|(sim, p)| {
                let list: serde_json::Map<String, Value> = p
                    .poses
                    .iter()
                    .map(|(m, [x, y, a])| (m.to_string(), json!([round(*x), round(*y), round(*a)])))
                    .collect();
                (addr(sim), Value::Object(list))
            })
            .collect();
        let scans: serde_json::Map<String, Value> =
            l.scans.iter().map(|(d, s)| (addr(d), s.clone())).collect();
        json!({
            "time": time,
            "speed": l.pace.speed,
            "devices": l.devices.len(),
            "poses": poses,
            "scans": scans,
        })
    }
}

/// `6665:laser:0`.
fn addr(d: &Device) -> String {
    format!("{}:{}:{}", d.robot, d.interface, d.index)
}

/// A colour as CSS writes it.
fn css(c: troupe_msgs::Color) -> String {
    let b = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    format!("#{:02x}{:02x}{:02x}", b(c.r), b(c.g), b(c.b))
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
        Interface::Sonar => codec::decode::<sonar::Ranges>(payload).ok().map(|r| {
            json!({ "kind": "ranger", "ranges": ranges(r.msg.ranges.iter().map(|&v| f64::from(v))) })
        }),
        _ => None,
    };
    // (A ranger's intensities share its key: they are not drawn.)
    if let Some(scan) = scan {
        shared.latest().scans.insert(dev, scan);
        shared.touch();
    }
}

/// Asks the simulator of `sim` for its world and keeps it.
async fn fetch_world(session: troupe_node::zenoh::Session, shared: Arc<Shared>, sim: Device) {
    let key = keys::req(&sim, <simulation::GetWorld as troupe_msgs::Request>::NAME);
    let asked = troupe_node::ask(&session, &key, WORLD_TIMEOUT)
        .payload(codec::encode(&simulation::GetWorld, 0.0))
        .await;
    let reply = match asked {
        Ok(replies) => replies.recv_async().await.ok(),
        Err(e) => {
            tracing::warn!("asking {sim} for its world: {e}");
            return;
        }
    };
    let Some(Ok(sample)) = reply.map(|r| r.into_result()) else {
        tracing::warn!("{sim} did not describe its world (not a Troupe simulator?)");
        return;
    };
    match codec::decode::<simulation::World>(&sample.payload().to_bytes()) {
        Ok(w) => {
            tracing::info!("{sim}: a world of {} models", w.msg.models.len());
            shared.latest().worlds.insert(sim, w.msg);
            shared.touch();
        }
        Err(e) => tracing::warn!("{sim}: its world does not decode: {e}"),
    }
}

/// `troupe view`.
pub fn run(a: ViewArgs, z: &ZenohArgs) -> anyhow::Result<()> {
    crate::cli::supervised()?;
    let Some((rt, mut signals, session)) = crate::supervisor::client_runtime(z, 2)? else {
        return Ok(());
    };
    let shared = Arc::new(Shared {
        latest: Mutex::default(),
        changed: watch::channel(0).0,
        fps: a.fps.clamp(0.1, 240.0),
    });
    rt.block_on(async move {
        // Devices come and go; a simulator's world is asked for as it comes.
        let (s, sess) = (shared.clone(), session.clone());
        let handle = tokio::runtime::Handle::current();
        let _tokens = session
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
                    }
                    SampleKind::Delete => {
                        l.devices.remove(&dev);
                        l.worlds.remove(&dev);
                        l.poses.remove(&dev);
                        l.scans.remove(&dev);
                    }
                }
                drop(l);
                s.touch();
            })
            .await
            .map_err(|e| anyhow::anyhow!("watching devices: {e}"))?;
        let mut subs = Vec::new();
        for i in [
            Interface::Simulation,
            Interface::Laser,
            Interface::Ranger,
            Interface::Sonar,
        ] {
            let s = shared.clone();
            subs.push(
                session
                    .declare_subscriber(keys::data_of(i))
                    .callback(move |sample| {
                        if let Ok(dev) = keys::parse_data(sample.key_expr().as_str()) {
                            take(&s, dev, &sample.payload().to_bytes());
                        }
                    })
                    .await
                    .map_err(|e| anyhow::anyhow!("subscribing to {i} data: {e}"))?,
            );
        }
        let app = Router::new()
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
                get(|State(s): State<Arc<Shared>>| async move { Json(s.worlds()) }),
            )
            .route(
                "/api/devices",
                get(|State(s): State<Arc<Shared>>| async move { Json(s.devices()) }),
            )
            .route(
                "/api/frame",
                get(|State(s): State<Arc<Shared>>| async move { Json(s.frame()) }),
            )
            .route("/api/stream", get(stream))
            .with_state(shared.clone());
        let listener = tokio::net::TcpListener::bind(SocketAddr::new(a.bind, a.port))
            .await
            .with_context(|| format!("serving the view on {}:{}", a.bind, a.port))?;
        let at = listener.local_addr()?;
        {
            let mut out = std::io::stdout().lock();
            writeln!(out, "troupe view: http://{at}/")?;
            out.flush()?;
        }
        axum::serve(listener, app)
            .with_graceful_shutdown(async move { signals.recv().await })
            .await
            .context("serving the view")?;
        tracing::info!("view stopped");
        drop(subs);
        anyhow::Ok(())
    })
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
    State(s): State<Arc<Shared>>,
) -> Sse<impl futures::Stream<Item = Result<Event, Infallible>>> {
    let rx = s.changed.subscribe();
    let period = Duration::from_secs_f64(1.0 / s.fps);
    let frames = futures::stream::unfold(
        (s, rx, None::<tokio::time::Instant>),
        move |(s, mut rx, last)| async move {
            if let Some(t) = last {
                tokio::time::sleep_until(t + period).await;
            }
            // Ends with the view (its sender dropped).
            rx.changed().await.ok()?;
            rx.mark_unchanged();
            let event = Event::default().data(s.frame().to_string());
            Some((Ok(event), (s, rx, Some(tokio::time::Instant::now()))))
        },
    );
    Sse::new(frames).keep_alive(KeepAlive::default())
}
