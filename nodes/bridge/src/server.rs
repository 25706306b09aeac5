//! The bridge itself: a TCP listener per robot port, three tasks per client
//! (reading, asking devices in order, finishing writes a full socket
//! refused), one Zenoh subscriber per device that at least one client
//! opened. An answer is written by the thread that has it; a device's
//! sample waits in each subscribed client's inbox for that client's writer
//! task, so the feed that every client of a device shares does the same
//! small work whatever any one client does (its replace rules, its full
//! socket, its PULL rounds).

use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

pub use ipnetwork::IpNetwork;
use tokio::io::AsyncReadExt;
use tokio::net::tcp::{OwnedReadHalf, OwnedWriteHalf};
use tokio::net::TcpListener;
use tokio::sync::{mpsc, oneshot, Notify};
use troupe_msgs::codec::{self, schema_of, Message};
use troupe_msgs::{common, decode_any, keys, sim, Device, Interface};
use troupe_node::zenoh::pubsub::{Publisher, Subscriber};
use troupe_node::zenoh::query::Reply;
use troupe_node::zenoh::sample::SampleKind;
use troupe_node::zenoh::{Session, Wait};
use troupe_node::REQUEST_TIMEOUT;

use crate::codec::{from_player, to_player, ReplyFn, ToDevice};
use crate::queue::{Out, Queue, Replace, Rule, DEFAULT_MAXLEN};
use crate::wire::{self, player, Header, PLAYER_CODE, REQ, RESP_ACK, RESP_NACK};
use crate::xdr::{Reader, Writer};

/// Why the bridge could not start.
#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    /// A robot port could not be bound.
    #[error("cannot listen for robot {robot} on {addr}: {source}{hint}")]
    Bind {
        /// Robot port.
        robot: u32,
        /// Address tried.
        addr: SocketAddr,
        /// The OS error.
        source: std::io::Error,
        /// What to do about it.
        hint: &'static str,
    },
    /// Zenoh refused a declaration.
    #[error("{what}: {source}")]
    Zenoh {
        /// What was being declared.
        what: String,
        /// Zenoh's error.
        source: troupe_node::zenoh::Error,
    },
}

/// One robot port to serve.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Port {
    /// The robot, as in keys and in Player's headers (6665).
    pub robot: u32,
    /// Where to listen (`127.0.0.1:6665`; port 0 = any free port).
    pub listen: SocketAddr,
}

/// How to run the bridge.
#[derive(Debug, Clone)]
pub struct Config {
    /// The robot ports to serve.
    pub ports: Vec<Port>,
    /// Device order for DEVLIST (Player lists devices in .cfg order); devices
    /// not named here follow, by interface code and index.
    pub order: Vec<Device>,
    /// Data messages a client's queue holds before it drops (Player: 1024).
    pub maxlen: usize,
    /// Networks clients may connect from; empty = any. Others are refused
    /// before the banner.
    pub allow: Vec<IpNetwork>,
    /// Clients one robot port serves at once; more are closed before the
    /// banner, and counted.
    pub max_clients: usize,
    /// How long the bridge waits for what a client owes it: see [`Limits`].
    pub limits: Limits,
    /// Tests only: called with `message INTERF:INDEX:KIND:SUBTYPE` for each
    /// message a client sends, `sample DEVICE` for each device sample,
    /// `queue PEER` as a client's samples are queued, `token DEVICE` as a
    /// device's liveliness is heard and `ask DEVICE` as the network is
    /// asked for a device, where the bridge's own code runs, to make it
    /// panic or stall there.
    #[doc(hidden)]
    pub fault: Option<fn(&str)>,
    /// For a bridge on a peer session: a client session of the same router,
    /// whose listing of live devices is whole at once (a peer's first query
    /// reaches only the peers it has links to yet). The ports open once
    /// the peer session has heard of every device it lists, its routes to
    /// them made; then it is dropped.
    pub lister: Option<Session>,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            ports: Vec::new(),
            order: Vec::new(),
            maxlen: DEFAULT_MAXLEN,
            allow: Vec::new(),
            max_clients: DEFAULT_MAX_CLIENTS,
            limits: Limits::default(),
            fault: None,
            lister: None,
        }
    }
}

/// Clients a robot port serves at once unless told otherwise.
pub const DEFAULT_MAX_CLIENTS: usize = 256;

/// A client's requests that wait their turn (Player's drivers answer in
/// order): at this many, the bridge reads no more of that client's socket
/// until one is answered, and TCP's flow control holds the client back.
/// Nothing is dropped; Player's server instead drops what overflows a
/// driver's queue, unanswered.
pub const MAX_PENDING_REQUESTS: usize = 64;

/// Answers queued for a client that has not read them: at this many, the
/// bridge reads no more of its socket until it reads (the requests already
/// waiting, [`MAX_PENDING_REQUESTS`] at most, are still answered).
pub const MAX_UNREAD_ANSWERS: usize = 64;

/// How long the bridge waits for a client before it drops the connection.
/// Each bounds what a client that stops halfway can hold: its socket, its
/// slot among [`Config::max_clients`], its queue.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// From connecting to its first whole message (libplayerc sends its
    /// data mode at once).
    pub first_message: Duration,
    /// From a message's first byte to its last (a client trickling bytes).
    pub message: Duration,
    /// With output waiting, the longest the client's socket may take
    /// nothing (a client that never reads). Its data beyond the queue's
    /// length are dropped meanwhile, as Player does.
    pub stalled: Duration,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            first_message: Duration::from_secs(30),
            message: Duration::from_secs(30),
            stalled: Duration::from_secs(30),
        }
    }
}

/// Addresses whose refused connections are counted one by one; the rest
/// are counted together.
const REFUSED_ADDRESSES: usize = 1024;

/// Reads `--allow`'s argument: a network (`10.1.0.0/16`, `fd00::/8`) or
/// one address (`192.168.1.7`).
///
/// # Errors
///
/// [`NetworkError`], naming the text and the expected form.
pub fn parse_network(text: &str) -> Result<IpNetwork, NetworkError> {
    text.trim()
        .parse::<IpNetwork>()
        .map_err(|source| NetworkError {
            text: text.to_owned(),
            source,
        })
}

/// `--allow`'s argument is no network.
#[derive(Debug, thiserror::Error)]
#[error("`{text}` is not a network like 10.1.0.0/16 or an address like 10.1.0.7 ({source})")]
pub struct NetworkError {
    /// The argument.
    pub text: String,
    /// The parser's reason.
    pub source: ipnetwork::IpNetworkError,
}

/// Whether a client at `ip` may connect (an IPv4 client of an IPv6
/// socket is matched as IPv4).
fn allowed(allow: &[IpNetwork], ip: IpAddr) -> bool {
    let ip = ip.to_canonical();
    allow.is_empty() || allow.iter().any(|n| n.contains(ip))
}

/// Runs `f`, the body of a Zenoh callback, so that a panic in it (a bug)
/// ends that call alone: Zenoh's threads are the launcher's router's, and
/// the stack goes on. The panic hook has printed the panic; this says
/// where, once per place.
fn contained(place: impl FnOnce() -> String, f: impl FnOnce()) {
    if std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).is_err() {
        static SAID: Mutex<Vec<String>> = Mutex::new(Vec::new());
        let place = place();
        let mut said = lock(&SAID);
        if !said.contains(&place) {
            tracing::error!(
                "a panic in {place} (a bug): that call is dropped and the bridge goes on (more there are not logged)"
            );
            said.push(place);
        }
    }
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// A client's queue and its socket.
///
/// Whoever queues an answer writes what the socket takes at once, on its own
/// thread: a request's answer goes out from the Zenoh callback that received
/// it, with no task to wake in between. A device's samples come through
/// [`ClientQueue::deliver`] instead: the feed shared by all the device's
/// clients only appends to each one's inbox, and the client's writer task
/// queues them under its rules and writes them. The writer task also
/// finishes what a full socket could not take, so a stuck client holds up
/// no one else.
struct ClientQueue {
    out: Mutex<Outbox>,
    /// Samples from the device feeds, not yet queued (locked after `out`
    /// when both are).
    inbox: Mutex<Vec<Out>>,
    /// Samples the inbox had no room for, not yet counted in the queue.
    inbox_dropped: AtomicU64,
    /// The queue's length, which bounds the inbox too.
    maxlen: usize,
    /// [`Config::fault`], called with `queue PEER` as the inbox is taken.
    fault: Option<fn(&str)>,
    peer: SocketAddr,
    bell: Notify,
    /// Rung when the socket took what waited: answers may queue again.
    room: Notify,
    /// Rung when the writer gives up on a client that does not read.
    gone: Notify,
    wire: OwnedWriteHalf,
}

/// What waits to go to one client.
struct Outbox {
    queue: Queue,
    /// Bytes taken from the queue that the socket has not taken yet.
    unsent: Vec<u8>,
    sent: usize,
    /// The socket failed: nothing more goes out.
    closed: bool,
    /// When the socket last took bytes, or had nothing waiting for it.
    moved: Instant,
    /// The inbox's last contents, emptied (kept for its allocation).
    spare: Vec<Out>,
}

impl ClientQueue {
    fn new(
        maxlen: usize,
        wire: OwnedWriteHalf,
        peer: SocketAddr,
        fault: Option<fn(&str)>,
    ) -> ClientQueue {
        ClientQueue {
            out: Mutex::new(Outbox {
                queue: Queue::new(maxlen),
                // The banner goes before anything else.
                unsent: wire::banner().to_vec(),
                sent: 0,
                closed: false,
                moved: Instant::now(),
                spare: Vec::new(),
            }),
            inbox: Mutex::new(Vec::new()),
            inbox_dropped: AtomicU64::new(0),
            maxlen,
            fault,
            peer,
            bell: Notify::new(),
            room: Notify::new(),
            gone: Notify::new(),
            wire,
        }
    }

    fn push(&self, m: Out) {
        self.with(|q| q.push(m));
    }

    /// A device's latest sample, fetched as the client opened or closed it
    /// (see [`Queue::push_latest`]).
    fn push_latest(&self, m: Out) {
        self.with(|q| q.push_latest(m));
    }

    /// A device's sample, from the feed all its clients share: appended to
    /// the inbox for the writer task, whatever the client's state. Past
    /// the queue's length (a writer that is not run) it is dropped and
    /// counted as the queue's own overflow is.
    fn deliver(&self, m: Out) {
        let mut inbox = lock(&self.inbox);
        if inbox.len() >= self.maxlen {
            drop(inbox);
            self.inbox_dropped.fetch_add(1, Ordering::Relaxed);
            return;
        }
        inbox.push(m);
        // A longer inbox has rung already, and the writer has yet to take
        // it.
        let first = inbox.len() == 1;
        drop(inbox);
        if first {
            self.bell.notify_one();
        }
    }

    /// Moves the inbox into the queue, in arrival order, ahead of whatever
    /// is queued next.
    fn take_inbox(&self, out: &mut Outbox) {
        if let Some(fault) = self.fault {
            fault(&format!("queue {}", self.peer));
        }
        std::mem::swap(&mut *lock(&self.inbox), &mut out.spare);
        for m in out.spare.drain(..) {
            out.queue.push(m);
        }
        let lost = self.inbox_dropped.swap(0, Ordering::Relaxed);
        if lost > 0 {
            out.queue.overflowed(lost);
        }
    }

    /// Changes the queue, then writes what may go now; whatever the socket
    /// cannot take yet is left to the writer task.
    fn with<R>(&self, f: impl FnOnce(&mut Queue) -> R) -> R {
        let mut out = lock(&self.out);
        self.take_inbox(&mut out);
        let r = f(&mut out.queue);
        // The writer task also keeps a PULL round's deadline.
        if !out.flush(&self.wire) || out.queue.deadline().is_some() {
            self.bell.notify_one();
        }
        r
    }

    /// Waits until fewer than [`MAX_UNREAD_ANSWERS`] answers wait for the
    /// client.
    async fn room_for_answers(&self) {
        loop {
            let room = self.room.notified();
            tokio::pin!(room);
            room.as_mut().enable();
            if lock(&self.out).queue.answers() < MAX_UNREAD_ANSWERS {
                return;
            }
            room.await;
        }
    }
}

impl Outbox {
    /// Writes what the queue lets go until the socket would block; `true`
    /// when nothing is left over.
    fn flush(&mut self, wire: &OwnedWriteHalf) -> bool {
        while !self.closed {
            if self.sent == self.unsent.len() {
                self.unsent.clear();
                self.sent = 0;
                while self.unsent.len() < 1 << 20 {
                    match self.queue.pop(Instant::now()) {
                        Some(m) => self.unsent.extend_from_slice(&m.bytes),
                        None => break,
                    }
                }
                if self.unsent.is_empty() {
                    self.moved = Instant::now();
                    return true;
                }
            }
            match wire.try_write(&self.unsent[self.sent..]) {
                Ok(n) if n > 0 => {
                    self.sent += n;
                    self.moved = Instant::now();
                }
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => return false,
                Ok(_) => self.close("the socket took nothing".into()),
                Err(e) => self.close(e.to_string()),
            }
        }
        true
    }

    fn close(&mut self, why: String) {
        tracing::debug!("write failed: {why}");
        self.closed = true;
        self.unsent = Vec::new();
        self.sent = 0;
    }
}

/// Client ids and their queues.
type Clients = Arc<Mutex<Vec<(u64, Arc<ClientQueue>)>>>;

/// The clients subscribed to one device, and the Zenoh subscriber feeding them.
struct DeviceFeed {
    clients: Clients,
    _sub: Subscriber<()>,
}

struct Shared {
    session: Session,
    /// Live devices and their drivers, from liveliness.
    devices: Mutex<HashMap<Device, String>>,
    /// Told whenever liveliness changes `devices`.
    heard: tokio::sync::Notify,
    order: Vec<Device>,
    feeds: Mutex<HashMap<Device, DeviceFeed>>,
    /// Latest simulation time, as f64 bits; NaN until a clock is seen.
    sim_time: AtomicU64,
    maxlen: usize,
    next_client: AtomicU64,
    /// Samples no client was sent, by why (malformed, or a kind Player's
    /// protocol has no message for): said once, with counts, at the end.
    dropped: Mutex<std::collections::BTreeMap<Dropped, u64>>,
    /// `--allow`: networks clients may connect from (empty: any).
    allow: Vec<IpNetwork>,
    /// Connections refused by `allow`, by address: the first from each is
    /// logged, the rest counted.
    refused: Mutex<HashMap<IpAddr, u64>>,
    /// Refused connections from addresses beyond [`REFUSED_ADDRESSES`].
    refused_elsewhere: AtomicU64,
    /// Connections closed because the port served `max_clients` already.
    full: AtomicU64,
    max_clients: usize,
    limits: Limits,
    fault: Option<fn(&str)>,
    /// A publisher for each command key clients have used.
    commanders: Mutex<HashMap<String, Arc<Publisher<'static>>>>,
    /// The latest command to each key no driver subscribes to yet, held
    /// until one does (see [`Shared::command`]).
    held: Mutex<HashMap<String, Vec<u8>>>,
    /// Commands dropped after [`HOLD`] with no driver, by key: the first
    /// of each is logged, the count at the end.
    unheard: Mutex<std::collections::BTreeMap<String, u64>>,
}

/// How long a command waits for a driver to subscribe to its key. After a
/// network partition heals, or right after a driver's device appears, its
/// liveliness token can reach the bridge before its command subscription
/// does (seconds, across routers), and a command put then reached no one: a
/// Player client's goal, sent once, was lost.
const HOLD: Duration = Duration::from_secs(10);

impl Shared {
    /// Sends a client's command `payload` on `key`. Where no driver
    /// subscribes to the key yet, the command is held (a newer one to the
    /// key replaces it, as Player's queue replaces a device's commands) and
    /// sent as soon as one does, for up to [`HOLD`]; the client is not held
    /// up meanwhile.
    async fn command(self: &Arc<Self>, key: String, payload: Vec<u8>) {
        let commander = lock(&self.commanders).get(&key).cloned();
        let commander = match commander {
            Some(c) => c,
            None => match self.session.declare_publisher(key.clone()).await {
                Ok(p) => lock(&self.commanders)
                    .entry(key.clone())
                    .or_insert_with(|| Arc::new(p))
                    .clone(),
                Err(e) => {
                    tracing::warn!("sending {key}: {e}");
                    return;
                }
            },
        };
        let heard = commander
            .matching_status()
            .await
            .is_ok_and(|m| m.matching());
        {
            let mut held = lock(&self.held);
            if let Some(h) = held.get_mut(&key) {
                // Not sent ahead of the one held: it replaces it.
                *h = payload;
                return;
            }
            if !heard {
                held.insert(key.clone(), payload);
                drop(held);
                tokio::spawn(self.clone().hold(key, commander));
                return;
            }
        }
        if let Err(e) = commander.put(payload).await {
            tracing::warn!("sending {key}: {e}");
        }
    }

    /// Sends the command held for `key` once a driver subscribes to it,
    /// or drops it after [`HOLD`].
    async fn hold(self: Arc<Self>, key: String, commander: Arc<Publisher<'static>>) {
        let subscribed = async {
            let listener = commander.matching_listener().await.ok()?;
            // Asked after listening: a subscription that came between is
            // not missed.
            if commander.matching_status().await.ok()?.matching() {
                return Some(());
            }
            while let Ok(m) = listener.recv_async().await {
                if m.matching() {
                    return Some(());
                }
            }
            None
        };
        let heard = matches!(tokio::time::timeout(HOLD, subscribed).await, Ok(Some(())));
        let Some(payload) = lock(&self.held).remove(&key) else {
            return;
        };
        if heard {
            tracing::debug!("{key}: a driver subscribed; the held command is sent");
            if let Err(e) = commander.put(payload).await {
                tracing::warn!("sending {key}: {e}");
            }
            return;
        }
        let mut unheard = lock(&self.unheard);
        let n = unheard.entry(key.clone()).or_insert(0);
        *n += 1;
        if *n == 1 {
            tracing::warn!(
                "a command to {key} was dropped: no driver subscribed to it within {} s",
                HOLD.as_secs()
            );
        }
    }

    /// Player stamps its own replies with the server's time: simulation
    /// time under Stage, the wall clock otherwise.
    fn now(&self) -> f64 {
        let t = f64::from_bits(self.sim_time.load(Ordering::Relaxed));
        if t.is_nan() {
            SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map_or(0.0, |d| d.as_secs_f64())
        } else {
            t
        }
    }

    /// The devices of `robot`, in DEVLIST order.
    fn devlist(&self, robot: u32) -> Vec<Device> {
        let devices = lock(&self.devices);
        let mut list: Vec<Device> = devices
            .keys()
            .filter(|d| d.robot == robot)
            .copied()
            .collect();
        let rank = |d: &Device| {
            let pos = self.order.iter().position(|o| o == d).unwrap_or(usize::MAX);
            (pos, d.interface.code(), d.index)
        };
        list.sort_by_key(rank);
        list
    }

    fn driver(&self, d: &Device) -> Option<String> {
        lock(&self.devices).get(d).cloned()
    }

    fn is_live(&self, d: &Device) -> bool {
        lock(&self.devices).contains_key(d)
    }

    /// Whether some client has opened a device of `dev`'s driver on its
    /// robot: Player sets a driver up at its first subscription and
    /// answers requests to any of its devices from then on.
    fn driver_set_up(&self, dev: &Device) -> bool {
        // (Locked in this order only.)
        let feeds = lock(&self.feeds);
        if feeds.contains_key(dev) {
            return true;
        }
        let devices = lock(&self.devices);
        let Some(driver) = devices.get(dev) else {
            return false;
        };
        feeds
            .keys()
            .any(|d| d.robot == dev.robot && devices.get(d) == Some(driver))
    }
}

/// A bound bridge, ready to [`run`](Bridge::run).
pub struct Bridge {
    shared: Arc<Shared>,
    listeners: Vec<(u32, u32, TcpListener)>,
    _watch: Subscriber<()>,
    _clock: Subscriber<()>,
}

impl Bridge {
    /// Binds every port and starts following the devices on `session`.
    ///
    /// # Errors
    ///
    /// [`BridgeError::Bind`] when a port is taken or not allowed.
    pub async fn bind(session: Session, cfg: Config) -> Result<Bridge, BridgeError> {
        let mut listeners = Vec::new();
        for p in &cfg.ports {
            let l = TcpListener::bind(p.listen)
                .await
                .map_err(|source| BridgeError::Bind {
                    robot: p.robot,
                    addr: p.listen,
                    hint: match source.kind() {
                        std::io::ErrorKind::AddrInUse => {
                            " (another Player server or troupe bridge? pick another port or stop it)"
                        }
                        std::io::ErrorKind::PermissionDenied => " (ports below 1024 need root)",
                        _ => "",
                    },
                    source,
                })?;
            let ip = p.listen.ip();
            if !ip.is_loopback() {
                if cfg.allow.is_empty() {
                    tracing::warn!(
                        "robot {}: Player clients can connect from any host that reaches {} (Player's protocol has no authentication: whoever connects drives the robot); --allow CIDR limits who may",
                        p.robot,
                        p.listen
                    );
                } else {
                    let nets: Vec<String> = cfg.allow.iter().map(ToString::to_string).collect();
                    tracing::info!(
                        "robot {}: on {}, clients from {} only",
                        p.robot,
                        p.listen,
                        nets.join(", ")
                    );
                }
            }
            let host = if ip.is_unspecified() {
                wire::host_of(std::net::Ipv4Addr::LOCALHOST.into())
            } else {
                wire::host_of(ip)
            };
            listeners.push((p.robot, host, l));
        }
        let shared = Arc::new(Shared {
            session: session.clone(),
            devices: Mutex::new(HashMap::new()),
            heard: tokio::sync::Notify::new(),
            order: cfg.order,
            feeds: Mutex::new(HashMap::new()),
            sim_time: AtomicU64::new(f64::NAN.to_bits()),
            maxlen: cfg.maxlen,
            next_client: AtomicU64::new(0),
            dropped: Mutex::default(),
            allow: cfg.allow,
            refused: Mutex::new(HashMap::new()),
            refused_elsewhere: AtomicU64::new(0),
            full: AtomicU64::new(0),
            max_clients: cfg.max_clients,
            limits: cfg.limits,
            fault: cfg.fault,
            commanders: Mutex::default(),
            held: Mutex::default(),
            unheard: Mutex::default(),
        });
        // Changes first, then the current list: no token is missed, and the
        // port opens only once DEVLIST would be complete. The subscriber
        // takes history too: a peer's first query can run before its routes
        // to every publisher exist, and what it missed comes then.
        let s = Arc::downgrade(&shared);
        let fault = cfg.fault;
        let touched = Arc::new(Mutex::new(std::collections::HashSet::new()));
        let t = touched.clone();
        let watch = session
            .liveliness()
            .declare_subscriber(keys::tokens(None))
            .history(true)
            .callback(move |sample| {
                let Some(shared) = s.upgrade() else { return };
                let Ok((dev, driver)) = keys::parse_token(sample.key_expr().as_str()) else {
                    return;
                };
                if let Some(fault) = fault {
                    fault(&format!("token {dev}"));
                }
                lock(&t).insert(dev);
                let mut devices = lock(&shared.devices);
                match sample.kind() {
                    SampleKind::Put => {
                        tracing::debug!("device {dev} ({driver}) is live");
                        devices.insert(dev, driver);
                    }
                    SampleKind::Delete => {
                        tracing::debug!("device {dev} ({driver}) is gone");
                        devices.remove(&dev);
                    }
                }
                drop(devices);
                shared.heard.notify_waiters();
            })
            .await
            .map_err(|source| BridgeError::Zenoh {
                what: "watching device tokens".into(),
                source,
            })?;
        let current = cfg
            .lister
            .as_ref()
            .unwrap_or(&session)
            .liveliness()
            .get(keys::tokens(None))
            .timeout(REQUEST_TIMEOUT)
            .await
            .map_err(|source| BridgeError::Zenoh {
                what: "listing live devices".into(),
                source,
            })?;
        let mut listed = HashMap::new();
        while let Ok(reply) = current.recv_async().await {
            let Ok(sample) = reply.into_result() else {
                continue;
            };
            if let Ok((dev, driver)) = keys::parse_token(sample.key_expr().as_str()) {
                listed.insert(dev, driver);
            }
        }
        if cfg.lister.is_some() {
            wait_to_hear(&touched, &listed, &shared.heard).await;
        }
        for (dev, driver) in listed {
            if !lock(&touched).contains(&dev) {
                lock(&shared.devices).insert(dev, driver);
            }
        }
        let s = Arc::downgrade(&shared);
        let clock = session
            .declare_subscriber(keys::SIM_CLOCK)
            .callback(move |sample| {
                let Some(shared) = s.upgrade() else { return };
                if let Ok(c) = codec::decode::<sim::Clock>(&sample.payload().to_bytes()) {
                    shared
                        .sim_time
                        .store(c.msg.time.to_bits(), Ordering::Relaxed);
                }
            })
            .await
            .map_err(|source| BridgeError::Zenoh {
                what: "following the simulation clock".into(),
                source,
            })?;
        Ok(Bridge {
            shared,
            listeners,
            _watch: watch,
            _clock: clock,
        })
    }

    /// Where each robot port listens: `(robot, address)`.
    pub fn local_addrs(&self) -> Vec<(u32, SocketAddr)> {
        self.listeners
            .iter()
            .filter_map(|(robot, _, l)| l.local_addr().ok().map(|a| (*robot, a)))
            .collect()
    }

    /// Serves clients until `shutdown` completes.
    pub async fn run(self, shutdown: impl std::future::Future<Output = ()>) {
        let mut tasks = tokio::task::JoinSet::new();
        for (robot, host, listener) in self.listeners {
            let shared = self.shared.clone();
            tasks.spawn(accept_loop(shared, robot, host, listener));
        }
        shutdown.await;
        tasks.shutdown().await;
        let dropped = lock(&self.shared.dropped);
        let malformed = dropped.get(&Dropped::Malformed).copied().unwrap_or(0);
        if malformed > 0 {
            tracing::warn!("{malformed} malformed device samples were dropped");
        }
        let unsent: Vec<String> = dropped
            .iter()
            .filter_map(|(why, n)| match why {
                Dropped::NoPlayerForm(kind) => Some(format!("{kind} ×{n}")),
                Dropped::Malformed => None,
            })
            .collect();
        if !unsent.is_empty() {
            tracing::info!(
                "not sent to Player clients, having no Player message: {}",
                unsent.join(", ")
            );
        }
        drop(dropped);
        let unheard = lock(&self.shared.unheard);
        if !unheard.is_empty() {
            let each: Vec<String> = unheard.iter().map(|(k, n)| format!("{k} ×{n}")).collect();
            tracing::warn!(
                "commands dropped, no driver having subscribed within {} s: {}",
                HOLD.as_secs(),
                each.join(", ")
            );
        }
        drop(unheard);
        let refused = lock(&self.shared.refused);
        let elsewhere = self.shared.refused_elsewhere.load(Ordering::Relaxed);
        if !refused.is_empty() {
            tracing::warn!(
                "refused {} connections from {} addresses outside --allow{}",
                refused.values().sum::<u64>() + elsewhere,
                refused.len(),
                if elsewhere > 0 { " and more" } else { "" }
            );
        }
        let full = self.shared.full.load(Ordering::Relaxed);
        if full > 0 {
            tracing::warn!(
                "closed {full} connections that came while {} clients were served (--max-clients)",
                self.shared.max_clients
            );
        }
    }
}

async fn accept_loop(shared: Arc<Shared>, robot: u32, host: u32, listener: TcpListener) {
    let mut clients = tokio::task::JoinSet::new();
    let slots = Arc::new(tokio::sync::Semaphore::new(shared.max_clients));
    loop {
        tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok((stream, peer)) if !allowed(&shared.allow, peer.ip()) => {
                    let ip = peer.ip().to_canonical();
                    let mut refused = lock(&shared.refused);
                    let n = if refused.len() < REFUSED_ADDRESSES || refused.contains_key(&ip) {
                        let n = refused.entry(ip).or_insert(0);
                        *n += 1;
                        *n
                    } else {
                        shared.refused_elsewhere.fetch_add(1, Ordering::Relaxed) + 1
                    };
                    if n == 1 {
                        tracing::warn!(
                            "robot {robot}: refused a client from {ip}: not in --allow (more from it are counted, not logged)",
                        );
                    }
                    // Closed before the banner: the peer learns nothing.
                    drop(stream);
                }
                Ok((stream, peer)) => {
                    let Ok(slot) = slots.clone().try_acquire_owned() else {
                        // Closed before the banner; a client retries later.
                        if shared.full.fetch_add(1, Ordering::Relaxed) == 0 {
                            tracing::warn!(
                                "robot {robot}: closed a connection from {peer}: {} clients are served already (--max-clients; more are counted, not logged)",
                                shared.max_clients
                            );
                        }
                        drop(stream);
                        continue;
                    };
                    let id = shared.next_client.fetch_add(1, Ordering::Relaxed);
                    tracing::info!("robot {robot}: client {id} connected from {peer}");
                    let _ = stream.set_nodelay(true);
                    let (rd, wr) = stream.into_split();
                    let queue = Arc::new(ClientQueue::new(shared.maxlen, wr, peer, shared.fault));
                    let conn = Conn { shared: shared.clone(), robot, host, id, queue, subscribed: Vec::new(), ignored_commands: 0, unanswered: 0, unknown: 0, rules_refused: 0, tasks: Vec::new() };
                    clients.spawn(async move {
                        conn.serve(rd).await;
                        drop(slot);
                    });
                }
                Err(e) => {
                    tracing::warn!("robot {robot}: accept failed: {e}");
                    tokio::time::sleep(Duration::from_millis(50)).await;
                }
            },
            Some(done) = clients.join_next(), if !clients.is_empty() => {
                if let Err(e) = done {
                    if e.is_panic() {
                        // The panic's message is above (the panic hook's);
                        // the client's subscriptions went with its task.
                        tracing::error!("robot {robot}: a client's task panicked (a bug): its connection is closed, the others go on");
                    }
                }
            }
        }
    }
}

/// One client connection.
struct Conn {
    shared: Arc<Shared>,
    robot: u32,
    host: u32,
    id: u64,
    queue: Arc<ClientQueue>,
    /// The devices this client opened, once per open (two proxies on one
    /// device open it twice, and one close leaves the other's feed).
    subscribed: Vec<Device>,
    /// Commands dropped because their device was not opened.
    ignored_commands: u64,
    /// Requests left unanswered because no client had opened a device of
    /// their driver.
    unanswered: u64,
    /// Messages to devices that are not live.
    unknown: u64,
    /// Replace rules refused past [`crate::queue::MAX_RULES`].
    rules_refused: u64,
    /// The client's writer and request tasks, stopped with it.
    tasks: Vec<tokio::task::AbortHandle>,
}

/// However a client's task ends, a panic included, its tasks stop and its
/// devices' feeds forget it.
impl Drop for Conn {
    fn drop(&mut self) {
        for t in &self.tasks {
            t.abort();
        }
        for dev in std::mem::take(&mut self.subscribed) {
            self.unsubscribe(dev);
        }
    }
}

/// A device request waiting for its turn: Player drivers answer in order.
struct Pending {
    header: Header,
    dev: Device,
    name: &'static str,
    payload: Vec<u8>,
    reply: ReplyFn,
}

impl Conn {
    async fn serve(mut self, mut rd: OwnedReadHalf) {
        let limits = self.shared.limits;
        let (req_tx, req_rx) = mpsc::channel(MAX_PENDING_REQUESTS);
        // Both stopped with the connection (`Drop for Conn`).
        let writer = tokio::spawn(write_loop(self.queue.clone(), limits.stalled));
        let requests = tokio::spawn(request_loop(
            self.shared.clone(),
            self.queue.clone(),
            req_rx,
        ));
        self.tasks = vec![writer.abort_handle(), requests.abort_handle()];
        // Small: a client sends requests and commands of tens of bytes,
        // and an idle connection holds these (a large message is
        // gathered in `buf`, which grows).
        let mut buf = Vec::new();
        let mut chunk = vec![0u8; 8 * 1024];
        // What the client owes, and by when: its first message, then the
        // rest of a message begun; nothing once it has sent whole ones.
        let connected = Instant::now();
        let mut owed = Some((connected + limits.first_message, "its first message"));
        let why = 'conn: loop {
            let read = async {
                match owed {
                    Some((at, _)) => tokio::time::timeout_at(at.into(), rd.read(&mut chunk)).await,
                    None => Ok(rd.read(&mut chunk).await),
                }
            };
            let n = tokio::select! {
                r = read => match r {
                    Err(_) => {
                        let (_, what) = owed.unwrap_or((connected, "a message"));
                        break 'conn format!("{what} did not come in time");
                    }
                    Ok(Ok(0)) => break 'conn "closed by the client".to_owned(),
                    Ok(Ok(n)) => n,
                    Ok(Err(e)) => break 'conn format!("read failed: {e}"),
                },
                () = self.queue.gone.notified() => {
                    break 'conn format!("it read nothing for {:?}", limits.stalled);
                }
            };
            buf.extend_from_slice(&chunk[..n]);
            let mut start = 0;
            loop {
                match wire::frame(&buf[start..]) {
                    Ok(Some((h, len))) => {
                        let body = &buf[start + wire::HEADER_LEN..start + len];
                        if let Err(reason) = self.handle(h, body, &req_tx).await {
                            break 'conn reason;
                        }
                        start += len;
                        owed = None;
                    }
                    Ok(None) => break,
                    Err(e) => break 'conn e.to_string(),
                }
            }
            buf.drain(..start);
            if !buf.is_empty() {
                owed.get_or_insert((Instant::now() + limits.message, "the rest of a message"));
            }
        };
        tracing::info!(
            "robot {}: client {} disconnected: {why}",
            self.robot,
            self.id
        );
        // Each was said at its first; the count goes with the client.
        for (n, what) in [
            (
                self.ignored_commands,
                "commands to devices it had not opened (ignored)",
            ),
            (
                self.unanswered,
                "requests to devices no client had opened (not answered)",
            ),
            (
                self.unknown,
                "messages to devices that are not live (skipped)",
            ),
            (self.rules_refused, "replace rules past the limit (refused)"),
        ] {
            if n > 1 {
                tracing::info!("robot {}: client {} sent {n} {what}", self.robot, self.id);
            }
        }
        let dropped = lock(&self.queue.out).queue.dropped_total();
        if dropped > 0 {
            tracing::warn!(
                "robot {}: client {} was too slow: {dropped} data messages dropped",
                self.robot,
                self.id
            );
        }
    }

    fn header(&self, interf: u32, index: u32, kind: u8, subtype: u32) -> Header {
        Header {
            host: self.host,
            robot: self.robot,
            interf,
            index,
            kind: u32::from(kind),
            subtype,
            timestamp: self.shared.now(),
            seq: 0,
            size: 0,
        }
    }

    fn reply(&self, req: &Header, kind: u8, body: &[u8]) {
        let h = self.header(req.interf, req.index, kind, req.subtype);
        self.queue.push(Out::new(h, body));
    }

    /// Handles one message; `Err` closes the connection with that reason.
    async fn handle(
        &mut self,
        h: Header,
        body: &[u8],
        req_tx: &mpsc::Sender<Pending>,
    ) -> Result<(), String> {
        if let Some(fault) = self.shared.fault {
            fault(&format!(
                "message {}:{}:{}:{}",
                h.interf, h.index, h.kind, h.subtype
            ));
        }
        if h.kind == u32::from(REQ) {
            // Every request is answered: with MAX_UNREAD_ANSWERS waiting
            // for a client that does not read, its socket is not read.
            self.queue.room_for_answers().await;
        }
        if h.interf == u32::from(PLAYER_CODE) {
            if h.subtype == u32::from(player::REQ_DEV) {
                let mut r = Reader::new(body);
                if let Some(dev) = read_addr(&mut r)
                    .ok()
                    .and_then(|(interf, index)| self.addr(interf, index))
                {
                    self.catch_up(dev).await;
                }
            }
            return self.handle_player(h, body);
        }
        let Some(dev) = self
            .addr(h.interf, h.index)
            .filter(|d| self.shared.is_live(d))
        else {
            self.unknown += 1;
            if self.unknown == 1 {
                tracing::warn!(
                    "robot {}: client {}: skipping message of type {}:{} to unknown device {}:{} (more are counted, not logged)",
                    self.robot,
                    self.id,
                    h.kind,
                    h.subtype,
                    h.interf,
                    h.index
                );
            }
            return Ok(());
        };
        let kind = u8::try_from(h.kind).unwrap_or(0);
        if kind != REQ && kind != wire::CMD {
            tracing::debug!(
                "client {}: ignoring message type {} to {dev}",
                self.id,
                h.kind
            );
            return Ok(());
        }
        if kind == wire::CMD && !self.subscribed.contains(&dev) {
            // Player drops a command to a device the client has not opened.
            self.ignored_commands += 1;
            if self.ignored_commands == 1 {
                tracing::info!(
                    "robot {}: client {}: ignoring commands to {dev}, which it has not opened (as Player does)",
                    self.robot,
                    self.id
                );
            }
            return Ok(());
        }
        if kind == REQ && !self.shared.driver_set_up(&dev) {
            // Player sets a driver up when its first client subscribes to
            // one of its devices; a request to a driver no client has
            // opened waits in its queue, unanswered.
            self.unanswered += 1;
            if self.unanswered == 1 {
                tracing::info!(
                    "robot {}: client {}: not answering requests to {dev}: no client has opened a device of its driver (Player's driver would not be set up)",
                    self.robot,
                    self.id
                );
            }
            return Ok(());
        }
        let subtype = u8::try_from(h.subtype).unwrap_or(0);
        match from_player(dev.interface, kind, subtype, body, h.timestamp) {
            Err(e) => Err(e.to_string()),
            Ok(None) if kind == REQ => {
                tracing::debug!("{dev}: request subtype {subtype} is not served; NACK");
                self.reply(&h, RESP_NACK, &[]);
                Ok(())
            }
            Ok(None) => {
                tracing::debug!("{dev}: command subtype {subtype} is not served; dropped");
                Ok(())
            }
            Ok(Some(ToDevice::Refuse(why))) => {
                tracing::info!(
                    "robot {}: client {}: {dev} refuses: {why}",
                    self.robot,
                    self.id
                );
                self.reply(&h, RESP_NACK, &[]);
                Ok(())
            }
            Ok(Some(ToDevice::Command { name, payload })) => {
                self.shared.command(keys::cmd(&dev, name), payload).await;
                Ok(())
            }
            Ok(Some(ToDevice::Request {
                name,
                payload,
                reply,
            })) => {
                // Waits while MAX_PENDING_REQUESTS wait: the socket is
                // not read meanwhile.
                let _ = req_tx
                    .send(Pending {
                        header: Header {
                            host: self.host,
                            robot: self.robot,
                            ..h
                        },
                        dev,
                        name,
                        payload,
                        reply,
                    })
                    .await;
                Ok(())
            }
        }
    }

    /// Before an open of a device this bridge has not heard of is refused:
    /// the device may have come (back) an instant ago, heard of by the
    /// routers and not yet here. If the network has its token, waits (at
    /// most [`REQUEST_TIMEOUT`]) for this bridge's own liveliness to say
    /// so; `devices` stays as liveliness tells it.
    async fn catch_up(&self, dev: Device) {
        if self.shared.is_live(&dev) {
            return;
        }
        if let Some(fault) = self.shared.fault {
            fault(&format!("ask {dev}"));
        }
        let live = match self
            .shared
            .session
            .liveliness()
            .get(keys::token_any(&dev))
            .timeout(REQUEST_TIMEOUT)
            .await
        {
            Ok(replies) => replies.recv_async().await.is_ok_and(|r| r.result().is_ok()),
            Err(e) => {
                tracing::debug!("asking the network for {dev}: {e}");
                false
            }
        };
        if !live {
            return;
        }
        let deadline = tokio::time::Instant::now() + REQUEST_TIMEOUT;
        loop {
            let next = self.shared.heard.notified();
            tokio::pin!(next);
            next.as_mut().enable();
            if self.shared.is_live(&dev) {
                tracing::debug!("{dev}: live here too now, as the network said");
                return;
            }
            if tokio::time::timeout_at(deadline, next).await.is_err() {
                tracing::warn!(
                    "robot {}: client {}: {dev} is live on the network but this bridge did not hear of it within {} s",
                    self.robot,
                    self.id,
                    REQUEST_TIMEOUT.as_secs_f64()
                );
                return;
            }
        }
    }

    /// The `player` meta-device, as Player's `HandlePlayerMessage`.
    fn handle_player(&mut self, h: Header, body: &[u8]) -> Result<(), String> {
        let bad = |e: crate::xdr::XdrError| format!("player REQ subtype {}: {e}", h.subtype);
        if h.kind != u32::from(REQ) {
            self.reply(&h, RESP_NACK, &[]);
            return Ok(());
        }
        let mut r = Reader::new(body);
        match u8::try_from(h.subtype).unwrap_or(0) {
            player::REQ_DEVLIST => {
                let list = self.shared.devlist(self.robot);
                let mut w = Writer::new();
                w.array(&list, |w, d| {
                    w.u32(self.host)
                        .u32(self.robot)
                        .u32(u32::from(d.interface.code()))
                        .u32(d.index);
                });
                self.reply(&h, RESP_ACK, &w.finish());
            }
            player::REQ_DRIVERINFO => {
                let (interf, index) = read_addr(&mut r).map_err(bad)?;
                r.bytes().and_then(|_| r.end()).map_err(bad)?;
                match self.device(interf, index) {
                    Some((_, driver)) => {
                        let mut w = Writer::new();
                        w.u32(self.host).u32(self.robot).u32(interf).u32(index);
                        w.string(&driver);
                        self.reply(&h, RESP_ACK, &w.finish());
                    }
                    None => self.reply(&h, RESP_NACK, &[]),
                }
            }
            player::REQ_DEV => {
                let (interf, index) = read_addr(&mut r).map_err(bad)?;
                let access = r.u32().map_err(bad)?;
                r.bytes().and_then(|_| r.end()).map_err(bad)?;
                let mut w = Writer::new();
                w.u32(self.host).u32(self.robot).u32(interf).u32(index);
                match self.device(interf, index) {
                    None => {
                        tracing::warn!(
                            "robot {}: client {}: subscription to unknown device {interf}:{index}",
                            self.robot,
                            self.id
                        );
                        w.u32(player::ERROR).bytes(&[]);
                        self.reply(&h, RESP_NACK, &w.finish());
                    }
                    Some((dev, driver)) => {
                        let granted = match access {
                            // Subscribed after the answer is queued: the
                            // client hears its ACK, then the device's latest
                            // samples, then the live ones, as from Player.
                            player::OPEN => player::OPEN,
                            player::CLOSE if self.subscribed.contains(&dev) => {
                                if let Some(i) = self.subscribed.iter().position(|d| *d == dev) {
                                    self.subscribed.swap_remove(i);
                                }
                                if !self.subscribed.contains(&dev) {
                                    self.unsubscribe(dev);
                                    // Player answers a close once its driver has
                                    // run again, and the data on its way comes
                                    // ahead of the answer: a PULL client's next
                                    // read returns it instead of waiting for a
                                    // round no device will fill.
                                    if self.queue.with(|q| q.pull()) && reads_rounds(dev) {
                                        self.send_latest(dev);
                                    }
                                }
                                player::CLOSE
                            }
                            _ => player::ERROR,
                        };
                        w.u32(granted).string(&driver);
                        self.reply(&h, RESP_ACK, &w.finish());
                        if granted == player::OPEN {
                            self.subscribe(dev);
                        }
                    }
                }
            }
            player::REQ_DATA => {
                let ack = Out::new(self.header(h.interf, h.index, RESP_ACK, h.subtype), &[]);
                self.queue.with(|q| q.request_data(ack));
            }
            player::REQ_DATAMODE => {
                let mode = r.u32().and_then(|m| r.end().map(|()| m)).map_err(bad)?;
                match mode {
                    player::PUSH => self.queue.with(|q| q.set_pull(false)),
                    player::PULL => self.queue.with(|q| q.set_pull(true)),
                    m => tracing::warn!("client {}: unknown data mode {m} requested", self.id),
                }
                self.reply(&h, RESP_ACK, &[]);
            }
            player::REQ_ADD_REPLACE_RULE => {
                let mut f = [0i32; 5];
                for v in &mut f {
                    *v = r.i32().map_err(bad)?;
                }
                r.end().map_err(bad)?;
                let added = self.queue.with(|q| {
                    q.add_rule(Rule {
                        interf: f[0],
                        index: f[1],
                        kind: f[2],
                        subtype: f[3],
                        replace: Replace::from_player(f[4]),
                    })
                });
                if !added {
                    self.rules_refused += 1;
                    if self.rules_refused == 1 {
                        tracing::warn!(
                            "robot {}: client {}: refused a replace rule past its {}th (NACK; more are counted, not logged)",
                            self.robot,
                            self.id,
                            crate::queue::MAX_RULES
                        );
                    }
                }
                self.reply(&h, if added { RESP_ACK } else { RESP_NACK }, &[]);
            }
            other => {
                tracing::debug!("client {}: player request {other} refused", self.id);
                self.reply(&h, RESP_NACK, &[]);
            }
        }
        Ok(())
    }

    /// The device of this robot a header or body names, if its interface exists.
    fn addr(&self, interf: u32, index: u32) -> Option<Device> {
        let iface = u16::try_from(interf).ok().and_then(Interface::from_code)?;
        Some(Device::new(self.robot, iface, index))
    }

    /// A live device of this robot and its driver.
    fn device(&self, interf: u32, index: u32) -> Option<(Device, String)> {
        let dev = self.addr(interf, index)?;
        self.shared.driver(&dev).map(|d| (dev, d))
    }

    fn subscribe(&mut self, dev: Device) {
        let again = self.subscribed.contains(&dev);
        self.subscribed.push(dev);
        if again {
            // Player counts a client's opens of a device; the feed is one.
            return;
        }
        if reads_rounds(dev) {
            let code = u32::from(dev.interface.code());
            self.queue
                .with(|q| q.expect(code, dev.index, Instant::now()));
        }
        self.send_latest(dev);
        let mut feeds = lock(&self.shared.feeds);
        if let Some(feed) = feeds.get(&dev) {
            lock(&feed.clients).push((self.id, self.queue.clone()));
            return;
        }
        let clients: Clients = Arc::new(Mutex::new(vec![(self.id, self.queue.clone())]));
        let (c, shared) = (clients.clone(), Arc::downgrade(&self.shared));
        let host = self.host;
        let fault = self.shared.fault;
        let sub = self
            .shared
            .session
            .declare_subscriber(keys::data(&dev))
            .callback(move |s| {
                // On a thread of the launcher's router: a panic (a bug)
                // ends this sample only.
                contained(
                    || format!("the feed of {dev}"),
                    || {
                        if let Some(fault) = fault {
                            fault(&format!("sample {dev}"));
                        }
                        let bytes = s.payload().to_bytes();
                        match data_message(dev, host, &bytes) {
                            Ok(out) => {
                                for (_, q) in lock(&c).iter() {
                                    q.deliver(out.clone());
                                }
                            }
                            Err(why) => {
                                if let Some(sh) = shared.upgrade() {
                                    *lock(&sh.dropped).entry(why).or_insert(0) += 1;
                                }
                            }
                        }
                    },
                );
            })
            .wait();
        match sub {
            Ok(sub) => {
                feeds.insert(dev, DeviceFeed { clients, _sub: sub });
            }
            Err(e) => tracing::warn!("subscribing to {dev}: {e}"),
        }
    }

    /// The latest samples `dev`'s driver keeps, to this client alone, before
    /// its live ones: Player set a driver up when its first client
    /// subscribed, so a client had the device's state at once, even from a
    /// driver that publishes only on change (amcl's localize at rest).
    fn send_latest(&self, dev: Device) {
        let replies = match self
            .shared
            .session
            .get(keys::data(&dev))
            .timeout(LATEST_WAIT)
            .wait()
        {
            Ok(r) => r,
            Err(e) => {
                tracing::debug!("{dev}: asking for its latest samples: {e}");
                return;
            }
        };
        while let Ok(reply) = replies.recv() {
            if let Ok(sample) = reply.result() {
                if let Ok(out) = data_message(dev, self.host, &sample.payload().to_bytes()) {
                    self.queue.push_latest(out);
                }
            }
        }
    }

    fn unsubscribe(&self, dev: Device) {
        {
            let mut feeds = lock(&self.shared.feeds);
            let empty = feeds.get(&dev).is_some_and(|f| {
                let mut c = lock(&f.clients);
                c.retain(|(id, _)| *id != self.id);
                c.is_empty()
            });
            if empty {
                feeds.remove(&dev);
            }
        }
        self.queue
            .with(|q| q.forget(u32::from(dev.interface.code()), dev.index));
    }
}

/// Waits, at most [`REQUEST_TIMEOUT`], until the peer session has heard of
/// every device in `listed` (or of its end): its routes to their drivers
/// exist then. Those it has not heard of by then are listed all the same,
/// and said once.
async fn wait_to_hear(
    touched: &Mutex<std::collections::HashSet<Device>>,
    listed: &HashMap<Device, String>,
    heard: &tokio::sync::Notify,
) {
    let deadline = tokio::time::Instant::now() + REQUEST_TIMEOUT;
    loop {
        let next = heard.notified();
        tokio::pin!(next);
        next.as_mut().enable();
        let missing: Vec<String> = {
            let touched = lock(touched);
            listed
                .keys()
                .filter(|d| !touched.contains(d))
                .map(ToString::to_string)
                .collect()
        };
        if missing.is_empty() {
            return;
        }
        if tokio::time::timeout_at(deadline, next).await.is_err() {
            tracing::warn!(
                "{} of {} devices not reached directly within {} s ({}): listed all the same; their data may come late",
                missing.len(),
                listed.len(),
                REQUEST_TIMEOUT.as_secs_f64(),
                missing.join(" ")
            );
            return;
        }
    }
}

/// Whether a client's PULL rounds carry `dev`'s data: Player clients read
/// none of a simulation, log or map device's in them.
fn reads_rounds(dev: Device) -> bool {
    !matches!(
        dev.interface,
        Interface::Simulation | Interface::Log | Interface::Map
    )
}

fn read_addr(r: &mut Reader) -> Result<(u32, u32), crate::xdr::XdrError> {
    let _host = r.u32()?;
    let _robot = r.u32()?;
    Ok((r.u32()?, r.u32()?))
}

/// Why a device's sample was not sent to clients.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
enum Dropped {
    /// It did not decode.
    Malformed,
    /// A kind Player's protocol has no message for on this device (the
    /// view's model poses on simulation:0, say).
    NoPlayerForm(&'static str),
}

/// A device's sample as a Player DATA message, or why not.
fn data_message(dev: Device, host: u32, payload: &[u8]) -> Result<Out, Dropped> {
    let m = match decode_any(payload) {
        Ok(m) => m,
        Err(e) => {
            tracing::debug!("{dev}: dropping a sample: {e}");
            return Err(Dropped::Malformed);
        }
    };
    let kind = m.msg.schema();
    let (iface, subtype, body) = to_player(&m.msg).ok_or(Dropped::NoPlayerForm(kind))?;
    if iface != dev.interface {
        tracing::debug!("{dev}: dropping a {iface} sample published on it");
        return Err(Dropped::NoPlayerForm(kind));
    }
    let h = Header {
        host,
        robot: dev.robot,
        interf: u32::from(iface.code()),
        index: dev.index,
        kind: u32::from(wire::DATA),
        subtype: u32::from(subtype),
        timestamp: m.stamp,
        seq: 0,
        size: 0,
    };
    Ok(Out::new(h, &body))
}

/// Queues the samples the feeds left in the inbox and writes them,
/// finishes what a full socket could not take when it was queued, and ends
/// a PULL round whose wait for due devices runs out.
async fn write_loop(q: Arc<ClientQueue>, stalled: Duration) {
    loop {
        let (done, deadline, moved) = {
            let mut out = lock(&q.out);
            q.take_inbox(&mut out);
            (out.flush(&q.wire), out.queue.deadline(), out.moved)
        };
        q.room.notify_waiters();
        if !done {
            tokio::select! {
                w = q.wire.writable() => if w.is_err() {
                    return;
                },
                // Samples come meanwhile: queued, so the queue's length
                // and rules bound them.
                () = q.bell.notified() => {}
                () = tokio::time::sleep_until((moved + stalled).into()) => {
                    if lock(&q.out).moved == moved {
                        // Dropped with a reset: what it did not read is
                        // discarded, not sent after the fact.
                        let _ = q.wire.as_ref().set_zero_linger();
                        lock(&q.out).close(format!("nothing read for {stalled:?}"));
                        q.gone.notify_one();
                        return;
                    }
                }
            }
        } else if let Some(at) = deadline {
            tokio::select! {
                () = q.bell.notified() => {}
                () = tokio::time::sleep_until(at.into()) => {}
            }
        } else {
            q.bell.notified().await;
        }
    }
}

/// Sends a client's device requests one at a time, as Player drivers answer
/// them in order.
///
/// A small answer is turned into Player's and written from the Zenoh
/// callback that receives it; a large one (a map tile to compress) comes
/// back here, off Zenoh's receiving thread.
async fn request_loop(shared: Arc<Shared>, q: Arc<ClientQueue>, mut rx: mpsc::Receiver<Pending>) {
    while let Some(mut p) = rx.recv().await {
        let payload = std::mem::take(&mut p.payload);
        let p = Arc::new(p);
        let key = keys::req(&p.dev, p.name);
        let (tx, back) = oneshot::channel::<Option<Reply>>();
        let tx = Mutex::new(Some(tx));
        // Weak: a client that left closes its socket now, not when a
        // request still in flight times out.
        let (sh, cq, asked) = (shared.clone(), Arc::downgrade(&q), p.clone());
        let sent = troupe_node::ask(&shared.session, &key, REQUEST_TIMEOUT)
            .payload(payload)
            .callback(move |reply| {
                // The first answer counts; a second queryable's is ignored.
                let Some(tx) = lock(&tx).take() else { return };
                let small = reply
                    .result()
                    .map_or(true, |s| s.payload().len() <= INLINE_ANSWER);
                if small {
                    if let Some(cq) = cq.upgrade() {
                        cq.push(answer(&sh, &asked, reply));
                    }
                    let _ = tx.send(None);
                } else {
                    let _ = tx.send(Some(reply));
                }
            })
            .await;
        if let Err(e) = sent {
            tracing::warn!("{key}: {e}");
            q.push(nack(&shared, &p));
            continue;
        }
        match back.await {
            Ok(None) => {}
            Ok(Some(reply)) => q.push(answer(&shared, &p, reply)),
            // The query ended with no answer: Zenoh dropped the callback.
            Err(_) => {
                tracing::info!("{key}: no answer within {REQUEST_TIMEOUT:?}; NACK");
                q.push(nack(&shared, &p));
            }
        }
    }
}

/// Answers above this size are converted off Zenoh's receiving thread.
const INLINE_ANSWER: usize = 16 * 1024;

/// How long a subscription waits for a device's latest samples (drivers
/// keep them and answer at once; a device that keeps none answers nothing).
const LATEST_WAIT: Duration = Duration::from_secs(1);

fn nack(shared: &Shared, p: &Pending) -> Out {
    response(shared, p, (RESP_NACK, Vec::new(), None))
}

/// A device's reply as Player's ACK with its body, or a NACK with none.
fn answer(shared: &Shared, p: &Pending, reply: Reply) -> Out {
    response(shared, p, player_answer(p, reply))
}

/// The response to `p`: its kind and body, stamped with the device's time
/// or else the server's.
fn response(shared: &Shared, p: &Pending, (kind, body, stamp): (u8, Vec<u8>, Option<f64>)) -> Out {
    let h = Header {
        kind: u32::from(kind),
        timestamp: stamp.unwrap_or_else(|| shared.now()),
        size: 0,
        ..p.header
    };
    Out::new(h, &body)
}

fn player_answer(p: &Pending, reply: Reply) -> (u8, Vec<u8>, Option<f64>) {
    let key = || keys::req(&p.dev, p.name);
    let nack = (RESP_NACK, Vec::new(), None);
    match reply.into_result() {
        Ok(s) => {
            let bytes = s.payload().to_bytes();
            if schema_of(&bytes) == Ok(common::Nack::SCHEMA) {
                return nack;
            }
            let stamp = codec::split(&bytes).ok().map(|(_, t, _)| t);
            match (p.reply)(&bytes) {
                Ok(body) => (RESP_ACK, body, stamp),
                Err(e) => {
                    tracing::warn!("{}: {e}; NACK", key());
                    nack
                }
            }
        }
        Err(e) => {
            let reason = codec::decode::<common::Nack>(&e.payload().to_bytes())
                .map(|n| n.msg.reason)
                .unwrap_or_default();
            tracing::debug!("{}: refused: {reason}", key());
            nack
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_allow_list_admits_its_networks_only() {
        let allow: Vec<IpNetwork> = ["10.1.0.0/16", "192.168.7.9", "fd00::/8"]
            .iter()
            .map(|t| parse_network(t).expect("a network"))
            .collect();
        let ip = |t: &str| t.parse::<IpAddr>().expect("an address");
        assert!(allowed(&allow, ip("10.1.200.3")));
        assert!(allowed(&allow, ip("192.168.7.9")));
        assert!(allowed(&allow, ip("fd12::1")));
        // An IPv4 client of a dual-stack socket arrives mapped.
        assert!(allowed(&allow, ip("::ffff:10.1.0.1")));
        assert!(!allowed(&allow, ip("10.2.0.1")));
        assert!(!allowed(&allow, ip("192.168.7.10")));
        assert!(!allowed(&allow, ip("127.0.0.1")));
        assert!(allowed(&[], ip("203.0.113.5")), "no list: anyone");
        let e = parse_network("10.1.0.0/33").unwrap_err().to_string();
        assert!(
            e.contains("`10.1.0.0/33` is not a network like 10.1.0.0/16"),
            "{e}"
        );
    }

    #[test]
    fn samples_without_a_player_form_are_told_from_malformed_ones() {
        use troupe_msgs::{position2d, simulation};
        let sim = Device::new(6665, Interface::Simulation, 0);
        let poses = codec::encode(&simulation::Poses::default(), 1.0);
        assert_eq!(
            data_message(sim, 0, &poses).err(),
            Some(Dropped::NoPlayerForm("simulation/poses@1"))
        );
        assert_eq!(
            data_message(sim, 0, b"\x03abc").err(),
            Some(Dropped::Malformed)
        );
        let pos = Device::new(6665, Interface::Position2d, 0);
        let data = codec::encode(&position2d::Data::default(), 1.0);
        assert!(data_message(pos, 0, &data).is_ok());
    }
}
