//! `troupe._native`: the Rust half of the Python package.
//!
//! It is small on purpose. It opens a Zenoh session (the CLI's defaults and
//! flags), subscribes to devices, sends commands and requests, and hands
//! every message to Python as plain objects (dicts, lists, floats) through
//! serde: the message types of `troupe-msgs` are the only schema, so a new
//! interface reaches Python without a line here. The proxies Python users
//! see (`troupe.Laser`, `playerc.playerc_laser`…) are written in Python on top.
//!
//! Samples are decoded on Zenoh's threads without the GIL and kept as Rust
//! values; they become Python objects only when Python asks. Every call that
//! waits (opening, reading, requests) releases the GIL.

use std::collections::{HashMap, VecDeque};
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyTimeoutError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyBytes;
use troupe_client::{Client, ClientError};
use troupe_msgs::{decode_any, encode_from, keys, schema_for, AnyMsg, Device, Interface, Stamped};
use troupe_node::zenoh::pubsub::Subscriber;
use troupe_node::zenoh::sample::SampleKind;
use troupe_node::zenoh::{Session as ZenohSession, Wait};
use troupe_node::{Mode, ZenohArgs};

create_exception!(
    troupe,
    TroupeError,
    PyException,
    "Base of the errors Troupe raises: no router, a bad address, a bad message."
);
create_exception!(
    troupe,
    RequestRefused,
    TroupeError,
    "A device refused a request (Player's NACK); the message says why."
);
create_exception!(
    troupe,
    NoAnswer,
    TroupeError,
    "No device answered a request in time: is it live? (`troupe list`)"
);
create_exception!(
    troupe,
    ReadTimeout,
    PyTimeoutError,
    "No new data arrived in time."
);

/// Feeds with new data, in arrival order: what `read()` waits on.
#[derive(Default)]
struct Events {
    queue: Mutex<VecDeque<u64>>,
    ready: Condvar,
}

/// Arrivals kept for a reader that does not read: a burst of 4096 samples.
const EVENTS_KEPT: usize = 4096;

/// Messages a feed keeps for its streams: 25 s of a 10 Hz laser.
const RECENT_KEPT: usize = 256;

impl Events {
    fn push(&self, feed: u64) {
        let mut q = lock(&self.queue);
        if q.len() == EVENTS_KEPT {
            q.pop_front();
        }
        q.push_back(feed);
        self.ready.notify_all();
    }

    /// Waits until `take` finds something in the queue, at most `timeout`.
    fn wait<T>(
        &self,
        timeout: Duration,
        mut take: impl FnMut(&mut VecDeque<u64>) -> Option<T>,
    ) -> Option<T> {
        let deadline = Instant::now() + timeout;
        let mut q = lock(&self.queue);
        loop {
            if let Some(t) = take(&mut q) {
                return Some(t);
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return None;
            }
            q = self
                .ready
                .wait_timeout(q, left)
                .unwrap_or_else(|p| p.into_inner())
                .0;
        }
    }
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

fn seconds(s: f64, what: &str) -> PyResult<Duration> {
    Duration::try_from_secs_f64(s)
        .map_err(|_| PyValueError::new_err(format!("{what} must be seconds ≥ 0, not {s}")))
}

fn client_error(e: ClientError) -> PyErr {
    match e {
        ClientError::Nack { .. } => RequestRefused::new_err(e.to_string()),
        ClientError::NoAnswer { .. } => NoAnswer::new_err(e.to_string()),
        ClientError::ReadTimeout(_) => ReadTimeout::new_err(e.to_string()),
        other => TroupeError::new_err(other.to_string()),
    }
}

fn interface(name: &str) -> PyResult<Interface> {
    name.parse::<Interface>()
        .map_err(|e| PyValueError::new_err(e.to_string()))
}

/// A message as Python sees it: its fields, without the enum's tag.
struct Body<'a>(&'a AnyMsg);

impl serde::Serialize for Body<'_> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        self.0.serialize_body(s)
    }
}

fn to_python<'py>(py: Python<'py>, msg: &AnyMsg) -> PyResult<Bound<'py, PyAny>> {
    Ok(pythonize::pythonize(py, &Body(msg))?)
}

/// The kind of a schema tag: `laser/scan@1` → `laser/scan`.
fn kind_of(schema: &'static str) -> &'static str {
    schema.split_once('@').map_or(schema, |(k, _)| k)
}

/// Encodes `payload` (a dict, or None for a message without fields) as the
/// message of `kind`.
fn encode(kind: &str, payload: &Bound<'_, PyAny>) -> PyResult<Vec<u8>> {
    let schema = schema_for(kind)
        .ok_or_else(|| PyValueError::new_err(format!("no message kind `{kind}`")))?;
    let mut de = pythonize::Depythonizer::from_object(payload);
    encode_from(schema, &mut de, troupe_client::now())
        .map_err(|e| PyValueError::new_err(format!("not a `{kind}`: {e}")))?
        .ok_or_else(|| PyValueError::new_err(format!("no message kind `{kind}`")))
}

/// A Zenoh session: the way to every robot of the network it joins.
#[pyclass(frozen, module = "troupe._native")]
struct Session {
    zenoh: ZenohSession,
    events: Arc<Events>,
    ids: Arc<AtomicU64>,
}

#[pymethods]
impl Session {
    /// Joins the Zenoh network as a client, as the CLI does: the router at
    /// `connect` (default: the local one, tcp/127.0.0.1:7447), a JSON5
    /// `config` file (TLS, authentication), keys under `namespace`.
    #[new]
    #[pyo3(signature = (connect = None, config = None, namespace = None))]
    fn new(
        py: Python<'_>,
        connect: Option<Vec<String>>,
        config: Option<PathBuf>,
        namespace: Option<String>,
    ) -> PyResult<Self> {
        let args = ZenohArgs {
            connect: connect.unwrap_or_default(),
            zenoh_config: config,
            namespace,
            ..Default::default()
        };
        let zenoh = py
            .detach(|| args.open(Mode::Client))
            .map_err(|e| TroupeError::new_err(e.to_string()))?;
        Ok(Session {
            zenoh,
            events: Arc::default(),
            ids: Arc::new(AtomicU64::new(1)),
        })
    }

    /// Robot `port` of this network.
    fn robot(&self, port: u32) -> Robot {
        Robot {
            client: Client::with_session(self.zenoh.clone(), port),
            events: self.events.clone(),
            ids: self.ids.clone(),
        }
    }

    /// The live devices, `(robot, interface, index, driver)`, of one robot
    /// or all, as their drivers' liveliness tokens say.
    #[pyo3(signature = (robot = None, timeout = 1.0))]
    fn devices(
        &self,
        py: Python<'_>,
        robot: Option<u32>,
        timeout: f64,
    ) -> PyResult<Vec<(u32, String, u32, String)>> {
        let wait = seconds(timeout, "timeout")?;
        py.detach(|| {
            let key = keys::tokens(robot);
            // The router answers a subscriber's history before the query
            // sent after it, on the same link: the two together, since a
            // query alone once missed a token the history had just shown.
            let history = self
                .zenoh
                .liveliness()
                .declare_subscriber(&key)
                .history(true)
                .wait()
                .map_err(|e| TroupeError::new_err(format!("watching devices: {e}")))?;
            let replies = self
                .zenoh
                .liveliness()
                .get(&key)
                .timeout(wait)
                .wait()
                .map_err(|e| TroupeError::new_err(format!("asking for devices: {e}")))?;
            let mut live = Vec::new();
            while let Ok(r) = replies.recv() {
                if let Ok(sample) = r.result() {
                    live.push(sample.key_expr().to_string());
                }
            }
            while let Ok(Some(sample)) = history.try_recv() {
                let key = sample.key_expr().to_string();
                match sample.kind() {
                    SampleKind::Put => live.push(key),
                    SampleKind::Delete => live.retain(|k| *k != key),
                }
            }
            let mut out = Vec::new();
            for key in &live {
                if let Ok((d, driver)) = keys::parse_token(key) {
                    out.push((d.robot, d.interface.to_string(), d.index, driver));
                }
            }
            out.sort_by_key(|(r, i, n, _)| (*r, Interface::from_name(i).map(|i| i.code()), *n));
            out.dedup();
            Ok(out)
        })
    }

    /// Waits until every device of `devices` (`"6665:laser:0"`) is live, at
    /// most `timeout` s; raises `ReadTimeout` naming the missing ones.
    #[pyo3(signature = (devices, timeout = 10.0))]
    fn wait_live(&self, py: Python<'_>, devices: Vec<String>, timeout: f64) -> PyResult<()> {
        let t = seconds(timeout, "timeout")?;
        let mut missing = devices;
        py.detach(|| {
            let tokens = self
                .zenoh
                .liveliness()
                .declare_subscriber(keys::tokens(None))
                .history(true)
                .wait()
                .map_err(|e| TroupeError::new_err(format!("watching devices: {e}")))?;
            let deadline = Instant::now() + t;
            while !missing.is_empty() {
                let left = deadline.saturating_duration_since(Instant::now());
                let Ok(Some(sample)) = tokens.recv_timeout(left) else {
                    return Err(ReadTimeout::new_err(format!(
                        "not live within {timeout} s: {}",
                        missing.join(", ")
                    )));
                };
                if sample.kind() != SampleKind::Put {
                    continue;
                }
                if let Ok((d, _)) = keys::parse_token(sample.key_expr().as_str()) {
                    let d = d.to_string();
                    missing.retain(|m| *m != d);
                }
            }
            Ok(())
        })
    }

    /// Waits at most `timeout` s for new data on any feed, then returns
    /// the ids of every feed that got some since the last call (in order
    /// of arrival, each once). Raises `ReadTimeout` when none came.
    fn wait(&self, py: Python<'_>, timeout: f64) -> PyResult<Vec<u64>> {
        let t = seconds(timeout, "timeout")?;
        py.detach(|| {
            self.events.wait(t, |q| {
                let mut ids: Vec<u64> = Vec::new();
                for id in q.drain(..) {
                    if !ids.contains(&id) {
                        ids.push(id);
                    }
                }
                (!ids.is_empty()).then_some(ids)
            })
        })
        .ok_or_else(|| ReadTimeout::new_err(format!("no new data within {timeout} s")))
    }

    /// Waits at most `timeout` s for the next arrival and returns its
    /// feed's id: one message at a time, as Player's PUSH mode reads.
    fn next(&self, py: Python<'_>, timeout: f64) -> PyResult<u64> {
        let t = seconds(timeout, "timeout")?;
        py.detach(|| self.events.wait(t, VecDeque::pop_front))
            .ok_or_else(|| ReadTimeout::new_err(format!("no new data within {timeout} s")))
    }

    /// Forgets the arrivals not read yet.
    fn clear(&self) {
        lock(&self.events.queue).clear();
    }

    /// Leaves the network; feeds stop.
    fn close(&self, py: Python<'_>) -> PyResult<()> {
        py.detach(|| self.zenoh.close().wait())
            .map_err(|e| TroupeError::new_err(format!("closing the session: {e}")))
    }
}

/// A map as `Robot.map` returns it: width, height, resolution, origin, cells.
type WholeMap<'py> = (u32, u32, f64, (f64, f64, f64), Bound<'py, PyBytes>);

/// One robot (a port) on a session.
#[pyclass(frozen, module = "troupe._native")]
struct Robot {
    client: Client,
    events: Arc<Events>,
    ids: Arc<AtomicU64>,
}

impl Robot {
    fn device(&self, iface: &str, index: u32) -> PyResult<Device> {
        Ok(self.client.device(interface(iface)?, index))
    }
}

#[pymethods]
impl Robot {
    /// The robot's port.
    #[getter]
    fn port(&self) -> u32 {
        self.client.robot()
    }

    /// The newest sample stamp any of this robot's feeds received (the
    /// simulation's clock under Stage), 0 before the first.
    #[getter]
    fn data_time(&self) -> f64 {
        self.client.data_time()
    }

    /// Subscribes to `interface:index`; the feed starts with the device's
    /// latest sample where its driver keeps one.
    fn subscribe(&self, py: Python<'_>, interface: &str, index: u32) -> PyResult<Feed> {
        let dev = self.device(interface, index)?;
        let id = self.ids.fetch_add(1, Ordering::Relaxed);
        let state = Arc::new(FeedState::default());
        let (st, events) = (state.clone(), self.events.clone());
        let client = self.client.clone();
        let sub = py
            .detach(move || {
                client.subscribe(dev, move |bytes| {
                    st.take(bytes);
                    events.push(id);
                })
            })
            .map_err(client_error)?;
        Ok(Feed {
            id,
            dev,
            state,
            sub: Mutex::new(Some(sub)),
        })
    }

    /// Sends command `name` (the last key chunk: `vel`) of message kind
    /// `kind` (`position2d/cmd_vel`) to `interface:index`.
    fn command(
        &self,
        py: Python<'_>,
        interface: &str,
        index: u32,
        name: &str,
        kind: &str,
        payload: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let dev = self.device(interface, index)?;
        let bytes = encode(kind, payload)?;
        py.detach(|| self.client.command_payload(dev, name, bytes))
            .map_err(client_error)
    }

    /// Fetches map `index` whole (its info, then its cells in tiles):
    /// `(width, height, resolution, (x, y, yaw) of cell (0, 0), cells)`, the
    /// cells as bytes (int8, row by row from row 0).
    fn map<'py>(&self, py: Python<'py>, index: u32) -> PyResult<WholeMap<'py>> {
        let mut proxy = troupe_client::MapProxy::new(&self.client, index);
        py.detach(|| proxy.request_map()).map_err(client_error)?;
        let o = proxy.origin();
        let bytes: Vec<u8> = proxy.cells().iter().map(|c| c.to_ne_bytes()[0]).collect();
        Ok((
            proxy.width(),
            proxy.height(),
            proxy.resolution(),
            (o.x, o.y, o.yaw),
            PyBytes::new(py, &bytes),
        ))
    }

    /// Sends request `name` of kind `kind` to `interface:index` and waits at
    /// most `timeout` s: the answer's `(kind, stamp, fields)`.
    #[pyo3(signature = (interface, index, name, kind, payload, timeout = 5.0))]
    #[allow(clippy::too_many_arguments)]
    fn request<'py>(
        &self,
        py: Python<'py>,
        interface: &str,
        index: u32,
        name: &str,
        kind: &str,
        payload: &Bound<'py, PyAny>,
        timeout: f64,
    ) -> PyResult<(&'static str, f64, Bound<'py, PyAny>)> {
        let dev = self.device(interface, index)?;
        let bytes = encode(kind, payload)?;
        let wait = seconds(timeout, "timeout")?;
        let reply = py
            .detach(|| self.client.request_payload(dev, name, bytes, wait))
            .map_err(client_error)?;
        let got = decode_any(&reply)
            .map_err(|e| TroupeError::new_err(format!("the answer of {dev} to `{name}`: {e}")))?;
        Ok((
            kind_of(got.msg.schema()),
            got.stamp,
            to_python(py, &got.msg)?,
        ))
    }
}

/// A message kept by a feed, with its arrival number.
type Kept = (u64, Arc<Stamped<AnyMsg>>);

#[derive(Default)]
struct FeedData {
    seq: u64,
    latest: HashMap<&'static str, Kept>,
    recent: VecDeque<Kept>,
    dropped: u64,
    last_error: Option<String>,
}

#[derive(Default)]
struct FeedState {
    data: Mutex<FeedData>,
    fresh: Condvar,
}

impl FeedState {
    fn take(&self, bytes: &[u8]) {
        let mut d = lock(&self.data);
        match decode_any(bytes) {
            Ok(msg) => {
                d.seq += 1;
                let kept = (d.seq, Arc::new(msg));
                d.latest.insert(kind_of(kept.1.msg.schema()), kept.clone());
                if d.recent.len() == RECENT_KEPT {
                    d.recent.pop_front();
                }
                d.recent.push_back(kept);
                self.fresh.notify_all();
            }
            Err(e) => {
                d.dropped += 1;
                d.last_error = Some(e.to_string());
            }
        }
    }
}

/// The samples of one device: the latest of each kind, and the recent ones
/// in order for streams.
#[pyclass(frozen, module = "troupe._native")]
struct Feed {
    id: u64,
    dev: Device,
    state: Arc<FeedState>,
    sub: Mutex<Option<Subscriber<()>>>,
}

#[pymethods]
impl Feed {
    /// This feed's number: what `Session.wait` and `Session.next` return.
    #[getter]
    fn id(&self) -> u64 {
        self.id
    }

    /// The device, `6665:laser:0`.
    #[getter]
    fn device(&self) -> String {
        self.dev.to_string()
    }

    /// How many messages arrived so far.
    #[getter]
    fn seq(&self) -> u64 {
        lock(&self.state.data).seq
    }

    /// Samples that did not decode, and why the last one did not.
    #[getter]
    fn dropped(&self) -> (u64, Option<String>) {
        let d = lock(&self.state.data);
        (d.dropped, d.last_error.clone())
    }

    /// The latest message of `kind` (`laser/scan`): `(seq, stamp, fields)`;
    /// None before the first, or when it is not newer than arrival
    /// `newer_than` (what a caller that keeps the last one converts once).
    #[pyo3(signature = (kind, newer_than = 0))]
    fn latest<'py>(
        &self,
        py: Python<'py>,
        kind: &str,
        newer_than: u64,
    ) -> PyResult<Option<(u64, f64, Bound<'py, PyAny>)>> {
        let kept = lock(&self.state.data).latest.get(kind).cloned();
        kept.filter(|(seq, _)| *seq > newer_than)
            .map(|(seq, m)| Ok((seq, m.stamp, to_python(py, &m.msg)?)))
            .transpose()
    }

    /// The first message after arrival `after`, waiting at most `timeout`
    /// s: `(seq, kind, stamp, fields)`. A reader that fell more than 256
    /// messages behind gets the oldest still kept (its `seq` says how many
    /// it missed). Raises `ReadTimeout` when none came.
    fn next<'py>(
        &self,
        py: Python<'py>,
        after: u64,
        timeout: f64,
    ) -> PyResult<(u64, &'static str, f64, Bound<'py, PyAny>)> {
        let t = seconds(timeout, "timeout")?;
        let found = py.detach(|| {
            let deadline = Instant::now() + t;
            let mut d = lock(&self.state.data);
            loop {
                if let Some(k) = d.recent.iter().find(|(seq, _)| *seq > after) {
                    return Some(k.clone());
                }
                let left = deadline.saturating_duration_since(Instant::now());
                if left.is_zero() {
                    return None;
                }
                d = self
                    .state
                    .fresh
                    .wait_timeout(d, left)
                    .unwrap_or_else(|p| p.into_inner())
                    .0;
            }
        });
        let (seq, m) = found.ok_or_else(|| {
            ReadTimeout::new_err(format!("no data from {} within {timeout} s", self.dev))
        })?;
        Ok((
            seq,
            kind_of(m.msg.schema()),
            m.stamp,
            to_python(py, &m.msg)?,
        ))
    }

    /// Unsubscribes; the latest messages stay readable.
    fn close(&self, py: Python<'_>) {
        let sub = lock(&self.sub).take();
        if let Some(s) = sub {
            py.detach(|| drop(s.undeclare().wait()));
        }
    }
}

/// Every interface this build knows: `(name, Player's code)`.
#[pyfunction]
fn interfaces() -> Vec<(&'static str, u16)> {
    Interface::ALL
        .iter()
        .map(|i| (i.name(), i.code()))
        .collect()
}

/// The module: `troupe._native`.
/// A JPEG file's pixels, as `playerc_camera_decompress` gives them:
/// `(width, height, channels, pixels)`, the pixels row by row from the
/// top, 3 channels (R, G, B) or 1 (grey).
#[pyfunction]
fn jpeg_decode<'py>(py: Python<'py>, data: &[u8]) -> PyResult<(u32, u32, u8, Bound<'py, PyBytes>)> {
    let img = py
        .detach(|| image::load_from_memory_with_format(data, image::ImageFormat::Jpeg))
        .map_err(|e| PyValueError::new_err(format!("not a JPEG this can decode: {e}")))?;
    let (w, h) = (img.width(), img.height());
    Ok(match img {
        image::DynamicImage::ImageLuma8(g) => (w, h, 1, PyBytes::new(py, g.as_raw())),
        other => (w, h, 3, PyBytes::new(py, other.to_rgb8().as_raw())),
    })
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add_class::<Session>()?;
    m.add_class::<Robot>()?;
    m.add_class::<Feed>()?;
    m.add_function(wrap_pyfunction!(interfaces, m)?)?;
    m.add_function(wrap_pyfunction!(jpeg_decode, m)?)?;
    m.add("TroupeError", py.get_type::<TroupeError>())?;
    m.add("RequestRefused", py.get_type::<RequestRefused>())?;
    m.add("NoAnswer", py.get_type::<NoAnswer>())?;
    m.add("ReadTimeout", py.get_type::<ReadTimeout>())?;
    Ok(())
}
