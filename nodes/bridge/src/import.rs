//! The bridge the other way round: Troupe as a client of a running Player
//! server, its devices published on Troupe's keys, so a robot still running
//! Player joins a Troupe fleet (`troupe bridge --import HOST:PORT`).
//!
//! It does what libplayerc does at start: reads the banner, asks DEVLIST,
//! DRIVERINFO for each device and subscribes to each (PUSH mode, Player's
//! default). Then every DATA the server sends is published on the device's
//! data key ([`codec::data_from_player`]), stamped with the server's time,
//! and every command Troupe clients send to an imported device goes to the
//! server as a Player CMD ([`codec::command_to_player`]). Each device gets a
//! liveliness token naming its Player driver as `player-DRIVER`.
//!
//! Requests go the same way ([`codec::request_to_player`]): a Troupe get on
//! an imported device becomes a REQ, and the server's ACK the reply (its
//! NACK, a refusal). Player answers a device's requests in order, so the
//! answer to a REQ is the oldest one pending for that device and subtype.

use std::collections::{HashMap, VecDeque};
use std::pin::Pin;
use std::time::{Duration, Instant};

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio::sync::mpsc;
use troupe_msgs::common;
use troupe_msgs::{keys, Device, Interface};
use troupe_node::zenoh::liveliness::LivelinessToken;
use troupe_node::zenoh::pubsub::Subscriber;
use troupe_node::zenoh::query::{Query, Queryable};
use troupe_node::zenoh::Session;

use crate::codec;
use crate::wire::{self, player, Header, BANNER_LEN, DATA, HEADER_LEN, REQ, RESP_ACK, RESP_NACK};
use crate::xdr::{Reader, Writer, XdrError};

/// How long the server may take to answer one of the start-up requests.
const ANSWER_TIMEOUT: Duration = Duration::from_secs(10);

/// Why an import stopped.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    /// The server could not be reached or the connection failed.
    #[error("Player server at {server}: {source}")]
    Io {
        /// HOST:PORT.
        server: String,
        /// The OS error.
        source: std::io::Error,
    },
    /// The server said something that is not Player 3's protocol.
    #[error("Player server at {server}: {reason}")]
    Protocol {
        /// HOST:PORT.
        server: String,
        /// What was wrong.
        reason: String,
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

/// One imported device: where it is on the server, where it is on Troupe.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Imported {
    /// The server's address of it: (host, robot, interface code, index).
    addr: (u32, u32, u32, u32),
    /// Its Troupe device.
    dev: Device,
}

impl Imported {
    /// The header of a message of `kind` and `subtype` to it.
    fn header(&self, kind: u8, subtype: u8) -> Header {
        let (host, robot, interf, index) = self.addr;
        Header {
            host,
            robot,
            interf,
            index,
            kind: u32::from(kind),
            subtype: u32::from(subtype),
            ..Header::default()
        }
    }

    /// Whether `h` is the server's answer to a request of `subtype` to it.
    fn answers(&self, subtype: u8, h: &Header) -> bool {
        (self.addr.2, self.addr.3, u32::from(subtype)) == (h.interf, h.index, h.subtype)
    }
}

/// A Troupe request asked of the server and not answered yet.
struct Asked {
    to: Imported,
    subtype: u8,
    reply: codec::ReplyFromServer,
    query: Query,
    at: Instant,
}

fn zenoh_error(what: String) -> impl FnOnce(troupe_node::zenoh::Error) -> ImportError {
    move |source| ImportError::Zenoh { what, source }
}

/// A Player connection: the socket and what was read past the last message.
struct Conn {
    server: String,
    stream: TcpStream,
    buf: Vec<u8>,
}

impl Conn {
    fn io(&self, source: std::io::Error) -> ImportError {
        ImportError::Io {
            server: self.server.clone(),
            source,
        }
    }

    fn protocol(&self, reason: impl Into<String>) -> ImportError {
        ImportError::Protocol {
            server: self.server.clone(),
            reason: reason.into(),
        }
    }

    async fn send(&mut self, h: Header, body: &[u8]) -> Result<(), ImportError> {
        let bytes = wire::message(h, body);
        self.stream.write_all(&bytes).await.map_err(|e| self.io(e))
    }

    /// The next whole message.
    async fn next(&mut self) -> Result<(Header, Vec<u8>), ImportError> {
        loop {
            match wire::frame(&self.buf) {
                Ok(Some((h, len))) => {
                    let body = self.buf[HEADER_LEN..len].to_vec();
                    self.buf.drain(..len);
                    return Ok((h, body));
                }
                Ok(None) => {}
                Err(e) => return Err(self.protocol(e.to_string())),
            }
            let mut chunk = [0u8; 64 * 1024];
            let n = self.stream.read(&mut chunk).await.map_err(|e| self.io(e))?;
            if n == 0 {
                return Err(self.protocol("closed the connection"));
            }
            self.buf.extend_from_slice(&chunk[..n]);
        }
    }

    /// Sends a `player` request and waits for its answer (DATA that comes
    /// meanwhile is handed to `data`): the ACK's body, or `None` for a NACK.
    async fn ask(
        &mut self,
        subtype: u8,
        body: &[u8],
        data: &mut impl FnMut(Header, &[u8]),
    ) -> Result<Option<Vec<u8>>, ImportError> {
        let h = Header {
            interf: u32::from(wire::PLAYER_CODE),
            kind: u32::from(REQ),
            subtype: u32::from(subtype),
            ..Header::default()
        };
        self.send(h, body).await?;
        let answer = async {
            loop {
                let (r, body) = self.next().await?;
                let kind = u8::try_from(r.kind).unwrap_or(0);
                if r.interf == h.interf && r.subtype == h.subtype {
                    match kind {
                        RESP_ACK => return Ok(Some(body)),
                        RESP_NACK => return Ok(None),
                        _ => {}
                    }
                }
                if kind == DATA {
                    data(r, &body);
                }
            }
        };
        match tokio::time::timeout(ANSWER_TIMEOUT, answer).await {
            Ok(r) => r,
            Err(_) => Err(self.protocol(format!(
                "no answer to player request {subtype} within {ANSWER_TIMEOUT:?}"
            ))),
        }
    }

    /// Connects to the Player server at `server` and checks its banner.
    async fn open(server: &str) -> Result<Conn, ImportError> {
        let stream = TcpStream::connect(server)
            .await
            .map_err(|source| ImportError::Io {
                server: server.to_owned(),
                source,
            })?;
        let _ = stream.set_nodelay(true);
        let mut conn = Conn {
            server: server.to_owned(),
            stream,
            buf: Vec::new(),
        };
        conn.read_banner().await?;
        Ok(conn)
    }

    /// Reads the banner a server greets with: it must be Player's.
    async fn read_banner(&mut self) -> Result<(), ImportError> {
        let mut banner = [0u8; BANNER_LEN];
        self.stream
            .read_exact(&mut banner)
            .await
            .map_err(|e| self.io(e))?;
        if !banner.starts_with(b"Player v.") {
            let shown = String::from_utf8_lossy(&banner);
            return Err(self.protocol(format!(
                "is not a Player server (banner {:?})",
                shown.trim_end_matches('\0')
            )));
        }
        let version = String::from_utf8_lossy(&banner);
        tracing::info!(
            "connected to {}: {}",
            self.server,
            version.trim_end_matches('\0')
        );
        Ok(())
    }

    /// The addresses of the server's devices, as DEVLIST gives them.
    async fn device_list(&mut self) -> Result<Vec<(u32, u32, u32, u32)>, ImportError> {
        let mut ignore = |_: Header, _: &[u8]| {};
        // DEVLIST: libplayerc's request carries an empty list.
        let mut w = Writer::new();
        w.u32(0).array(&[] as &[u32], |_, _| {});
        let list = self
            .ask(player::REQ_DEVLIST, &w.finish(), &mut ignore)
            .await?
            .ok_or_else(|| self.protocol("refused DEVLIST"))?;
        let mut r = Reader::new(&list);
        r.array(16, r_addr)
            .map_err(|e| self.protocol(format!("DEVLIST reply: {e}")))
    }

    /// The driver DRIVERINFO names for the server's device `a` (or "unknown").
    async fn driver_of(
        &mut self,
        a: (u32, u32, u32, u32),
        dev: Device,
    ) -> Result<String, ImportError> {
        let mut ignore = |_: Header, _: &[u8]| {};
        let mut w = Writer::new();
        w_addr(&mut w, a);
        w.bytes(&[]);
        match self
            .ask(player::REQ_DRIVERINFO, &w.finish(), &mut ignore)
            .await?
        {
            Some(b) => {
                let mut r = Reader::new(&b);
                r_addr(&mut r)
                    .and_then(|_| r.string())
                    .map_err(|e| self.protocol(format!("DRIVERINFO reply for {dev}: {e}")))
            }
            None => Ok("unknown".to_owned()),
        }
    }

    /// Subscribes to the server's device `a` (OPEN): whether it agreed.
    async fn subscribe(&mut self, a: (u32, u32, u32, u32)) -> Result<bool, ImportError> {
        let mut ignore = |_: Header, _: &[u8]| {};
        let mut w = Writer::new();
        w_addr(&mut w, a);
        w.u32(player::OPEN).bytes(&[]);
        Ok(self
            .ask(player::REQ_DEV, &w.finish(), &mut ignore)
            .await?
            .is_some())
    }
}

fn w_addr(w: &mut Writer, a: (u32, u32, u32, u32)) {
    w.u32(a.0).u32(a.1).u32(a.2).u32(a.3);
}

fn r_addr(r: &mut Reader) -> Result<(u32, u32, u32, u32), XdrError> {
    Ok((r.u32()?, r.u32()?, r.u32()?, r.u32()?))
}

/// Which of a server's devices an import takes, and the device each becomes.
#[derive(Debug, Clone, PartialEq)]
pub enum Select {
    /// Every device, under the server's robot number or `as_robot` (two
    /// servers on port 6665 of two hosts).
    All {
        /// The robot to publish them under.
        as_robot: Option<u32>,
    },
    /// Only these of the server's devices (interface and index), each as
    /// the given device: Player's `passthrough`.
    Only(Vec<((Interface, u32), Device)>),
}

impl Select {
    /// The device the server's `iface`:`index` of robot `robot` becomes.
    fn local(&self, robot: u32, iface: Interface, index: u32) -> Option<Device> {
        match self {
            Select::All { as_robot } => Some(Device::new(as_robot.unwrap_or(robot), iface, index)),
            Select::Only(pairs) => pairs
                .iter()
                .find(|(r, _)| *r == (iface, index))
                .map(|&(_, d)| d),
        }
    }
}

/// Imports the devices `select` names of the Player server at `server`
/// (HOST:PORT) onto `session` until `shutdown` completes or the server goes.
///
/// # Errors
///
/// [`ImportError`]: the server is unreachable, speaks something else, or
/// closed the connection; Zenoh refused a declaration.
pub async fn run(
    session: Session,
    server: &str,
    select: &Select,
    shutdown: impl std::future::Future<Output = ()>,
) -> Result<(), ImportError> {
    let mut conn = Conn::open(server).await?;
    let addrs = conn.device_list().await?;
    let (devices, tokens) = import_devices(&mut conn, &session, select, addrs).await?;
    check_imported(&conn, select, &devices)?;
    let (cmd_rx, subs) = follow_commands(&session, &devices).await?;
    let (req_rx, queryables) = answer_requests(&session, &devices).await?;

    let mut relay = Relay::new(&session, conn, &devices, cmd_rx, req_rx);
    tokio::pin!(shutdown);
    let outcome = relay.until(shutdown).await;
    tracing::info!(
        "import of {server} ended: {} samples published, {} malformed",
        relay.published,
        relay.bad
    );
    drop(subs);
    drop(queryables);
    drop(tokens);
    outcome
}

/// Imports the devices at `addrs` that `select` takes, with their tokens.
async fn import_devices(
    conn: &mut Conn,
    session: &Session,
    select: &Select,
    addrs: Vec<(u32, u32, u32, u32)>,
) -> Result<(Vec<Imported>, Vec<LivelinessToken>), ImportError> {
    let mut devices: Vec<Imported> = Vec::new();
    let mut tokens = Vec::new();
    for a in addrs {
        let Some(iface) = u16::try_from(a.2).ok().and_then(Interface::from_code) else {
            tracing::warn!(
                "device {}:{} of {}: interface code unknown to Troupe; skipped",
                a.2,
                a.3,
                conn.server
            );
            continue;
        };
        let Some(dev) = select.local(a.1, iface, a.3) else {
            continue;
        };
        let driver = conn.driver_of(a, dev).await?;
        if !conn.subscribe(a).await? {
            tracing::warn!(
                "{} refused the subscription to {dev} ({driver}); skipped",
                conn.server
            );
            continue;
        }
        let token = declare_token(session, dev, &driver).await?;
        tracing::info!("importing {dev} ({driver})");
        tokens.push(token);
        devices.push(Imported { addr: a, dev });
    }
    Ok((devices, tokens))
}

/// Declares `dev`'s liveliness token, naming its Player `driver`.
async fn declare_token(
    session: &Session,
    dev: Device,
    driver: &str,
) -> Result<LivelinessToken, ImportError> {
    // A key chunk: no separators or wildcards from a driver's name.
    let name: String = driver
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect();
    session
        .liveliness()
        .declare_token(keys::token(&dev, &format!("player-{name}")))
        .await
        .map_err(zenoh_error(format!("declaring {dev}")))
}

/// Fails if `select` names a device that was not imported, or none was.
fn check_imported(conn: &Conn, select: &Select, devices: &[Imported]) -> Result<(), ImportError> {
    if let Select::Only(pairs) = select {
        for ((iface, index), dev) in pairs {
            if !devices.iter().any(|d| d.dev == *dev) {
                return Err(
                    conn.protocol(format!("has no {iface}:{index} to pass through as {dev}"))
                );
            }
        }
    }
    if devices.is_empty() {
        return Err(conn.protocol("serves no device Troupe can import"));
    }
    Ok(())
}

/// A command from Troupe's side, for the connection to write as a CMD.
type Command = (Imported, u8, Vec<u8>);

/// A request from Troupe's side, for the connection to ask of the server.
type Request = (Imported, codec::ToServer, Query);

/// Follows the commands Troupe clients send to `devices`, onto the receiver.
async fn follow_commands(
    session: &Session,
    devices: &[Imported],
) -> Result<(mpsc::UnboundedReceiver<Command>, Vec<Subscriber<()>>), ImportError> {
    let (cmd_tx, cmd_rx) = mpsc::unbounded_channel::<Command>();
    let mut subs = Vec::new();
    for &d in devices {
        let tx = cmd_tx.clone();
        let sub = session
            .declare_subscriber(keys::cmd_any(&d.dev))
            .callback(move |sample| {
                let payload = sample.payload().to_bytes();
                match codec::command_to_player(&payload) {
                    Some((subtype, body)) => {
                        let _ = tx.send((d, subtype, body));
                    }
                    None => tracing::debug!(
                        "{}: {} has no Player CMD; dropped",
                        d.dev,
                        sample.key_expr()
                    ),
                }
            })
            .await
            .map_err(zenoh_error(format!("following commands to {}", d.dev)))?;
        subs.push(sub);
    }
    drop(cmd_tx);
    Ok((cmd_rx, subs))
}

/// Queues the requests to `devices` the server can answer; refuses the rest.
async fn answer_requests(
    session: &Session,
    devices: &[Imported],
) -> Result<(mpsc::UnboundedReceiver<Request>, Vec<Queryable<()>>), ImportError> {
    let (req_tx, req_rx) = mpsc::unbounded_channel::<Request>();
    let mut queryables = Vec::new();
    for &d in devices {
        let tx = req_tx.clone();
        let q = session
            .declare_queryable(keys::req_any(&d.dev))
            .callback(move |q| {
                let payload = q
                    .payload()
                    .map(|p| p.to_bytes().to_vec())
                    .unwrap_or_default();
                match codec::request_to_player(d.dev.interface, &payload) {
                    Some(out) => {
                        let _ = tx.send((d, out, q));
                    }
                    None => {
                        let nack = troupe_msgs::codec::encode(
                            &common::Nack {
                                reason: format!(
                                    "{} is not forwarded to Player servers",
                                    q.key_expr()
                                ),
                            },
                            0.0,
                        );
                        let _ = troupe_node::zenoh::Wait::wait(q.reply_err(nack));
                    }
                }
            })
            .await
            .map_err(zenoh_error(format!("answering requests to {}", d.dev)))?;
        queryables.push(q);
    }
    drop(req_tx);
    Ok((req_rx, queryables))
}

/// An import under way: the connection, what it relays and what it counted.
struct Relay<'a> {
    session: &'a Session,
    /// The imported devices by the server's (interface code, index).
    by_addr: HashMap<(u32, u32), Imported>,
    /// Samples published.
    published: u64,
    /// DATA dropped as malformed.
    bad: u64,
    /// Asked and not yet answered, oldest first.
    pending: VecDeque<Asked>,
    req_rx: mpsc::UnboundedReceiver<Request>,
    cmd_rx: mpsc::UnboundedReceiver<Command>,
    conn: Conn,
}

impl<'a> Relay<'a> {
    /// A relay of `devices` between `session` and `conn`, nothing done yet.
    fn new(
        session: &'a Session,
        conn: Conn,
        devices: &[Imported],
        cmd_rx: mpsc::UnboundedReceiver<Command>,
        req_rx: mpsc::UnboundedReceiver<Request>,
    ) -> Self {
        Relay {
            session,
            by_addr: devices.iter().map(|d| ((d.addr.2, d.addr.3), *d)).collect(),
            published: 0,
            bad: 0,
            pending: VecDeque::new(),
            req_rx,
            cmd_rx,
            conn,
        }
    }

    /// Relays until `shutdown` completes (`Ok`) or the connection fails.
    async fn until(
        &mut self,
        mut shutdown: Pin<&mut impl std::future::Future<Output = ()>>,
    ) -> Result<(), ImportError> {
        loop {
            tokio::select! {
                () = &mut shutdown => return Ok(()),
                cmd = self.cmd_rx.recv() => {
                    let Some((d, subtype, body)) = cmd else { continue };
                    self.conn.send(d.header(wire::CMD, subtype), &body).await?;
                }
                req = self.req_rx.recv() => {
                    let Some(req) = req else { continue };
                    self.forward_request(req).await?;
                }
                msg = self.conn.next() => {
                    let (h, body) = msg?;
                    self.receive(h, &body).await;
                }
            }
        }
    }

    /// Sends a Troupe request to the server, to be answered when it answers.
    async fn forward_request(&mut self, (d, out, query): Request) -> Result<(), ImportError> {
        self.conn
            .send(d.header(REQ, out.subtype), &out.body)
            .await?;
        // The asker has long given up on what the server never answered.
        self.pending.retain(|p| p.at.elapsed() < STALE);
        self.pending.push_back(Asked {
            to: d,
            subtype: out.subtype,
            reply: out.reply,
            query,
            at: Instant::now(),
        });
        Ok(())
    }

    /// Handles a message from the server: an answer, or DATA to publish.
    async fn receive(&mut self, h: Header, body: &[u8]) {
        let kind = u8::try_from(h.kind).unwrap_or(0);
        if kind == RESP_ACK || kind == RESP_NACK {
            self.answer_pending(kind, &h, body).await;
        } else if kind == DATA {
            self.publish(&h, body).await;
        }
    }

    /// Answers the oldest pending request that the server's ACK or NACK `h` is for.
    async fn answer_pending(&mut self, kind: u8, h: &Header, body: &[u8]) {
        let at = self.pending.iter().position(|p| p.to.answers(p.subtype, h));
        if let Some(p) = at.and_then(|i| self.pending.remove(i)) {
            answer(&p, kind, body, h.timestamp).await;
        }
    }

    /// Publishes an imported device's DATA, counting published and malformed.
    async fn publish(&mut self, h: &Header, body: &[u8]) {
        let Some(&d) = self.by_addr.get(&(h.interf, h.index)) else {
            return;
        };
        let subtype = u8::try_from(h.subtype).unwrap_or(0);
        match codec::data_from_player(d.dev.interface, subtype, body, h.timestamp) {
            Ok(Some(payload)) => {
                if let Err(e) = self.session.put(keys::data(&d.dev), payload).await {
                    tracing::warn!("publishing {}: {e}", d.dev);
                }
                self.published += 1;
            }
            Ok(None) => {}
            Err(e) => {
                self.bad += 1;
                tracing::warn!("{}: dropped: {e}", d.dev);
            }
        }
    }
}

/// Requests unanswered this long are forgotten.
const STALE: Duration = Duration::from_secs(60);

/// Replies to `query` with the server's answer to it.
async fn answer(p: &Asked, kind: u8, body: &[u8], stamp: f64) {
    let (d, query) = (&p.to, &p.query);
    let nack = |reason: String| troupe_msgs::codec::encode(&common::Nack { reason }, stamp);
    let sent = if kind == RESP_ACK {
        match (p.reply)(body, stamp) {
            Ok(payload) => query.reply(query.key_expr().clone(), payload).await,
            Err(e) => {
                tracing::warn!(
                    "{}: the server's answer to {}: {e}",
                    d.dev,
                    query.key_expr()
                );
                query
                    .reply_err(nack(format!(
                        "malformed answer from the Player server: {e}"
                    )))
                    .await
            }
        }
    } else {
        query
            .reply_err(nack("refused by the Player server".into()))
            .await
    };
    if let Err(e) = sent {
        tracing::debug!("{}: replying: {e}", d.dev);
    }
}
