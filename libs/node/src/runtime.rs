//! The node runtime: one driver, one Zenoh session, one event loop.
//!
//! Zenoh's callbacks push [`Event`]s into an [`Inbox`]; the driver's thread
//! pops them and calls the driver's hooks, one at a time, so drivers are
//! plain synchronous code. A request that finds the driver idle with nothing
//! queued runs its hook at once on the receiving thread instead ([`Inline`]).
//! The runtime also declares what the section provides:
//!
//! - a publisher on each data key, and a queryable on the same key that
//!   answers with the latest sample of each message type (late joiners get
//!   geometry, map info or the last scan at once, as Player gave new
//!   subscribers the current state);
//! - a subscriber on `…/cmd/*` and a queryable on `…/req/*` of each device;
//! - after `setup` succeeds, one liveliness token per device that names the
//!   driver: what `troupe list` shows.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use troupe_msgs::{codec, keys, sim, Device};
use zenoh::bytes::ZBytes;
use zenoh::liveliness::LivelinessToken;
use zenoh::pubsub::{Publisher, Subscriber};
use zenoh::query::{Query, Queryable};
use zenoh::{Session, Wait};

use crate::args::{Mode, ZenohArgs};
use crate::clock::Clock;
use crate::ctx::{Bus, Ctx, ReadyAnswers};
use crate::driver::Driver;
use crate::error::{z, NodeError, RequestError, Result};
use crate::event::{nack_reason, Event, Reply, ReplySink, Request, RequestId, Responder, Sample};
use crate::inbox::{Inbox, Popped};
use crate::net::{ask, wait_live};
use crate::ros2::{Face, Ros2};
use crate::section::Section;

/// How a node runs, beyond its section.
#[derive(Debug, Clone)]
pub struct NodeConfig {
    /// Follow `sim/clock` instead of wall time.
    pub sim_time: bool,
    /// How long to wait for each required device before giving up.
    pub requires_timeout: Duration,
    /// Also show the devices to ROS 2 nodes (rmw_zenoh), as this says.
    pub ros2: Option<Ros2>,
    /// How long the driver's thread polls for its next event before it
    /// sleeps (`--spin`).
    pub spin: Duration,
}

impl Default for NodeConfig {
    fn default() -> Self {
        NodeConfig {
            sim_time: false,
            requires_timeout: Duration::from_secs(30),
            ros2: None,
            spin: Duration::ZERO,
        }
    }
}

/// Runs driver `D` in this process until SIGINT or SIGTERM.
///
/// # Errors
///
/// Any error of [`spawn`], or the fatal error that stopped the driver.
pub fn run<D: Driver>(section: Section, zargs: &ZenohArgs, cfg: &NodeConfig) -> Result<()> {
    let session = if cfg.ros2.is_some() {
        zargs.open_timestamped(Mode::Peer)?
    } else {
        zargs.open(Mode::Peer)?
    };
    let stop = Stop::default();
    install_signal_handlers(stop.clone())?;
    exit_on_panic();
    // The node's bus closes the session when the driver is done with it.
    start::<D>(session, section, cfg, stop, true)?.join()
}

/// Ends the process on a panic in any of its threads, after the panic's
/// message, with exit status 101, for the supervisor to restart it.
///
/// A panic on a thread other than the driver's (a request's hook run on
/// Zenoh's thread, a Zenoh callback) would otherwise unwind that thread
/// only: the driver hung with its liveliness tokens up, and nothing would
/// restart it. A driver's state after a panic is unknown, so its
/// `shutdown` is not run; the operating system closes its devices.
fn exit_on_panic() {
    let report = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        report(info);
        tracing::error!("a panic: exiting (status 101) to be restarted");
        std::process::exit(101);
    }));
}

/// A handle that asks a running node to stop.
#[derive(Clone, Default)]
pub struct Stop(Arc<Mutex<Option<Arc<Inbox>>>>, Arc<AtomicBool>);

impl Stop {
    /// Asks the node to stop: it runs `shutdown` and exits its loop.
    pub fn stop(&self) {
        self.1.store(true, Ordering::Release);
        if let Some(inbox) = &*self.0.lock().unwrap_or_else(|p| p.into_inner()) {
            inbox.shutdown();
        }
    }

    /// Whether a stop was asked for.
    fn requested(&self) -> bool {
        self.1.load(Ordering::Acquire)
    }

    fn attach(&self, inbox: Arc<Inbox>) {
        if self.1.load(Ordering::Acquire) {
            inbox.shutdown();
        }
        *self.0.lock().unwrap_or_else(|p| p.into_inner()) = Some(inbox);
    }
}

fn install_signal_handlers(stop: Stop) -> Result<()> {
    use tokio::signal::unix::{signal, SignalKind};
    let io =
        |e: std::io::Error| NodeError::Driver(format!("installing signal handlers: {e}").into());
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(io)?;
    let (mut term, mut int) = {
        let _guard = rt.enter();
        (
            signal(SignalKind::terminate()).map_err(io)?,
            signal(SignalKind::interrupt()).map_err(io)?,
        )
    };
    std::thread::Builder::new()
        .name("signals".into())
        .spawn(move || {
            let name = rt.block_on(async {
                tokio::select! {
                    _ = term.recv() => "SIGTERM",
                    _ = int.recv() => "SIGINT",
                }
            });
            // Stop first: logging may fail if our stderr's reader is gone.
            stop.stop();
            tracing::info!("{name}: stopping");
        })
        .map_err(io)?;
    Ok(())
}

/// A driver running on its own thread.
pub struct NodeHandle {
    thread: JoinHandle<Result<()>>,
    stop: Stop,
}

impl NodeHandle {
    /// Asks the node to stop (as SIGTERM would) and waits for it.
    ///
    /// # Errors
    ///
    /// The error that stopped the driver, if any.
    pub fn stop(self) -> Result<()> {
        self.stop.stop();
        self.join()
    }

    /// Waits for the node to stop.
    ///
    /// # Errors
    ///
    /// The error that stopped the driver, if any.
    pub fn join(self) -> Result<()> {
        self.thread
            .join()
            .unwrap_or_else(|_| Err(NodeError::Driver("the driver panicked".into())))
    }
}

/// Builds driver `D`, waits for its required devices, runs `setup`, announces
/// its devices and returns with the driver running on its own thread.
///
/// # Errors
///
/// [`NodeError::Config`] for a bad section, [`NodeError::RequiresTimeout`]
/// when a required device never appears, or what `setup` returned.
///
/// A node providing more than 16,000 devices is refused before it declares
/// any.
pub fn spawn<D: Driver>(
    session: Session,
    section: Section,
    cfg: &NodeConfig,
    stop: Stop,
) -> Result<NodeHandle> {
    start::<D>(session, section, cfg, stop, false)
}

/// [`spawn`], and with `owns_session` the node closes the session once its
/// driver has stopped (see `ZenohBus::owns_session`).
fn start<D: Driver>(
    session: Session,
    section: Section,
    cfg: &NodeConfig,
    stop: Stop,
    owns_session: bool,
) -> Result<NodeHandle> {
    let driver = build::<D>(&section)?;
    let provided: Vec<Device> = section.provided().into_iter().map(|s| s.device).collect();
    if provided.len() > MAX_DEVICES {
        return Err(NodeError::config(
            D::NAME,
            format!(
                "provides {} devices, more than the {MAX_DEVICES} one process can declare: \
                 each takes {KEYS_PER_DEVICE} of the 65,535 key expressions a Zenoh link can \
                 name, and past that Zenoh 1.10 never finishes declaring \
                 (docs/zenoh-declarations.md); give the devices to several processes",
                provided.len()
            ),
        ));
    }
    // Busy with `setup` until the loop first waits.
    let inbox = Arc::new(Inbox::busy().spinning(cfg.spin));
    stop.attach(inbox.clone());

    let ticks = Arc::new(SimTicks::default());
    let (clock, clock_sub) = if D::CLOCK_SOURCE {
        (Clock::manual(0.0), None)
    } else if cfg.sim_time {
        let clock = Clock::manual(0.0);
        let sub = sim_clock(&session, clock.clone(), inbox.clone(), ticks.clone())?;
        (clock, Some(sub))
    } else {
        (Clock::wall(), None)
    };

    for slot in section.required() {
        tracing::info!("waiting for required device {}", slot.device);
        wait_live(&session, &slot.device, cfg.requires_timeout)?;
    }

    let ready = Arc::<ReadyAnswers>::default();
    let inline = Arc::<Inline>::default();
    let mut bus = ZenohBus {
        session: session.clone(),
        inbox: inbox.clone(),
        inline: inline.clone(),
        publishers: HashMap::new(),
        latest: Arc::new(Mutex::new(HashMap::new())),
        ready: ready.clone(),
        subscribers: Vec::new(),
        queryables: Vec::new(),
        clock_pub: None,
        ros2: None,
        owns_session,
    };
    for (i, dev) in provided.iter().enumerate() {
        // Declaring 20,000 devices takes minutes (ARCHITECTURE.md): a stop
        // asked meanwhile is heard between two.
        if stop.requested() {
            return Err(NodeError::Driver(
                format!(
                    "stopped while declaring its devices ({i} of {})",
                    provided.len()
                )
                .into(),
            ));
        }
        bus.provide(dev, &clock, D::NAME)?;
    }
    if let Some(ros) = &cfg.ros2 {
        bus.ros2 = Some(Face::new(
            &session,
            ros,
            D::NAME,
            &provided,
            &inbox,
            &clock,
            &ready,
        )?);
    }
    let ctx = Ctx::new(
        D::NAME,
        clock,
        Box::new(bus),
        provided.clone(),
        Some(inbox.clone()),
        ready,
    );
    let thread_session = session.clone();
    let thread = std::thread::Builder::new()
        .name(format!("driver {}", D::NAME))
        .spawn(move || {
            // The clock subscription lives as long as the loop.
            let _clock_sub = clock_sub;
            let core = Core {
                driver,
                ctx,
                stats: Stats::default(),
                fatal: None,
            };
            run_loop(core, &inbox, &inline, &ticks, &thread_session, &provided)
        })
        .map_err(|e| NodeError::Driver(format!("starting the driver thread: {e}").into()))?;
    Ok(NodeHandle { thread, stop })
}

/// What a section gives that its driver does not use.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Unused {
    /// Options, by name.
    pub options: Vec<String>,
    /// `requires` entries, as the section spells them.
    pub requires: Vec<String>,
}

/// Checks a section for driver `D` without starting it: builds the driver
/// (which touches no device and no network) and returns what it does not
/// use.
///
/// # Errors
///
/// What building the driver returns: a wrong option type, a missing device.
pub fn check<D: Driver>(section: &Section) -> Result<Unused> {
    let (options, unused) = section.options::<D::Options>()?;
    D::new(section, options)?;
    Ok(Unused {
        options: unused,
        requires: section
            .unused_requires()
            .iter()
            .map(ToString::to_string)
            .collect(),
    })
}

/// The key expressions Zenoh names on a link for each provided device: its
/// data key, and the fixed parts of its commands', requests' and token's.
const KEYS_PER_DEVICE: usize = 4;

/// The most devices one node declares. Zenoh 1.10 names each key expression
/// a link carries by a 16-bit id; the 65,536th on a link makes it search for
/// a free id forever (docs/zenoh-declarations.md). 16,000 devices take
/// 64,000, leaving the rest for what the link's other end declares.
pub const MAX_DEVICES: usize = 16_000;

/// Builds the driver from its section, warning about unused options.
pub(crate) fn build<D: Driver>(section: &Section) -> Result<D> {
    if section.name != D::NAME {
        return Err(NodeError::config(
            D::NAME,
            format!("section is for driver `{}`", section.name),
        ));
    }
    let (options, unused) = section.options::<D::Options>()?;
    for o in unused {
        tracing::warn!(
            driver = D::NAME,
            "option `{o}` is not used by driver `{}`",
            D::NAME
        );
    }
    tracing::debug!(driver = D::NAME, ?options, "options");
    let driver = D::new(section, options)?;
    for r in section.unused_requires() {
        tracing::warn!(
            driver = D::NAME,
            "`{r}` in requires is not used by driver `{}` (it is still waited for)",
            D::NAME
        );
    }
    Ok(driver)
}

/// A driver and what its hooks use: run by one thread at a time, the
/// driver's own or one that claimed it idle (see [`Inline`]).
struct Core<D> {
    driver: D,
    ctx: Ctx,
    stats: Stats,
    /// The error that stopped a hook run away from the driver's thread.
    fatal: Option<NodeError>,
}

impl<D: Driver> Core<D> {
    /// What the loop must act on when a hook changes it.
    fn watched(&self) -> (bool, bool, Option<Duration>) {
        (self.ctx.ready, self.ctx.stop, self.ctx.tick)
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    // A panicking hook leaves the driver as it was; the loop reports the rest.
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// Runs a request's hook at once on the thread that received it (Zenoh's)
/// when [`Driver::quick`] agrees and the driver is idle with nothing queued,
/// instead of waking the driver's thread: a thread wake less per round trip.
/// Hooks stay one at a time and in arrival order ([`Inbox::claim`]).
#[derive(Default)]
struct Inline(std::sync::OnceLock<Box<dyn Fn(Request) -> Option<Request> + Send + Sync>>);

impl Inline {
    /// Runs `request`'s hook here if the driver is free, else queues it.
    fn deliver(&self, inbox: &Inbox, request: Request) {
        let request = match self.0.get() {
            Some(run) => match run(request) {
                Some(r) => r,
                None => return,
            },
            None => request,
        };
        inbox.push(Event::Request(request));
    }

    /// Lets other threads run `core`'s request hooks while the loop is idle.
    fn enable<D: Driver>(&self, core: &Arc<Mutex<Core<D>>>, inbox: &Arc<Inbox>) {
        let (core, inbox) = (Arc::downgrade(core), inbox.clone());
        let run = move |request: Request| {
            if !D::quick(&request) || !inbox.claim() {
                return Some(request);
            }
            // Claimed: the loop waits for `idle` before it drops the core.
            let Some(core) = core.upgrade() else {
                inbox.idle(false);
                return Some(request);
            };
            let mut c = lock(&core);
            let before = c.watched();
            let Core {
                driver, ctx, stats, ..
            } = &mut *c;
            stats.inline += 1;
            let result = dispatch(driver, ctx, Event::Request(request), stats);
            let recheck = result.is_err() || c.watched() != before;
            if let Err(e) = result {
                c.fatal = Some(e);
            }
            drop(c);
            drop(core);
            inbox.idle(recheck);
            None
        };
        if self.0.set(Box::new(run)).is_err() {
            tracing::error!(driver = D::NAME, "inline hooks enabled twice");
        }
    }
}

fn run_loop<D: Driver>(
    core: Core<D>,
    inbox: &Arc<Inbox>,
    inline: &Inline,
    ticks: &SimTicks,
    session: &Session,
    provided: &[Device],
) -> Result<()> {
    let core = Arc::new(Mutex::new(core));
    inline.enable(&core, inbox);
    let mut c = lock(&core);
    let Core { driver, ctx, .. } = &mut *c;
    driver.setup(ctx)?;
    let mut tokens: Vec<LivelinessToken> = Vec::new();
    announce::<D>(ctx.ready, &mut tokens, session, provided)?;
    let mut announced = ctx.ready;
    // The tick, read after each hook while the loop holds the driver (a
    // hook run elsewhere that changes it asks for a recheck, which reads it
    // again); the clock's kind never changes.
    let mut tick = ctx.tick;
    let manual = ctx.clock().is_manual();
    drop(c);
    inbox.idle(false);
    let mut next_tick: Option<Instant> = None;
    let result = loop {
        // Ticks follow sim/clock only for nodes that follow a simulator,
        // not for the simulator itself (whose clock is also set by hand).
        let sim = manual && !D::CLOCK_SOURCE;
        ticks.set_period(if sim { tick } else { None });
        next_tick = match (tick, next_tick) {
            (Some(p), None) if !sim => Some(Instant::now() + p),
            (Some(_), t) if !sim => t,
            _ => None,
        };
        let event = match inbox.pop(next_tick) {
            Popped::Shutdown => break Ok(()),
            Popped::Recheck => None,
            Popped::Timeout => {
                if let (Some(p), Some(t)) = (tick, next_tick) {
                    // Keep the phase; skip ticks missed while a hook ran long.
                    let mut n = t + p;
                    while n <= Instant::now() {
                        n += p;
                    }
                    next_tick = Some(n);
                }
                Some(Event::Tick)
            }
            Popped::Event(e) => Some(e),
        };
        let mut c = lock(&core);
        let Core {
            driver,
            ctx,
            stats,
            fatal,
        } = &mut *c;
        let result = match (fatal.take(), event) {
            (Some(e), _) => Err(e),
            (None, Some(event)) => dispatch(driver, ctx, event, stats),
            (None, None) => Ok(()),
        };
        let step = result.and_then(|()| {
            if ctx.ready != announced {
                announced = ctx.ready;
                announce::<D>(ctx.ready, &mut tokens, session, provided)?;
            }
            Ok(ctx.stop)
        });
        tick = ctx.tick;
        drop(c);
        if !matches!(step, Ok(false)) {
            // No hook runs anywhere after the one that ended the loop.
            inbox.shutdown();
        }
        inbox.idle(false);
        match step {
            Err(e) => break Err(e),
            Ok(true) => {
                tracing::info!(driver = D::NAME, "the driver asked to stop");
                break Ok(());
            }
            Ok(false) => {}
        }
    };
    drop(tokens);
    if let Err(e) = &result {
        tracing::error!(driver = D::NAME, "stopping after a fatal error: {e}");
    }
    let mut c = lock(&core);
    let Core {
        driver, ctx, stats, ..
    } = &mut *c;
    let down = driver.shutdown(ctx);
    tracing::info!(
        driver = D::NAME,
        events = stats.events,
        malformed = stats.malformed,
        inline = stats.inline,
        replaced = inbox.replaced(),
        "stopped"
    );
    result.and(down)
}

#[derive(Default)]
pub(crate) struct Stats {
    pub(crate) events: u64,
    /// Requests whose hook ran on the thread that received them.
    pub(crate) inline: u64,
    pub(crate) malformed: u64,
}

/// Declares the provided devices' liveliness tokens when the driver is
/// ready, withdraws them when it is not.
fn announce<D: Driver>(
    ready: bool,
    tokens: &mut Vec<LivelinessToken>,
    session: &Session,
    provided: &[Device],
) -> Result<()> {
    let list = || {
        provided
            .iter()
            .map(ToString::to_string)
            .collect::<Vec<_>>()
            .join(", ")
    };
    if !ready {
        if !tokens.is_empty() || provided.is_empty() {
            tokens.clear();
            tracing::warn!(driver = D::NAME, "not ready: withdrew {}", list());
        } else {
            tracing::info!(driver = D::NAME, "not ready yet: {}", list());
        }
        return Ok(());
    }
    for dev in provided {
        let key = keys::token(dev, D::NAME);
        let token = session
            .liveliness()
            .declare_token(&key)
            .wait()
            .map_err(z(|| format!("declaring liveliness {key}")))?;
        tokens.push(token);
    }
    if provided.is_empty() {
        tracing::info!(
            driver = D::NAME,
            "ready, providing no device (give it some with --provides, or `provides [...]` in a cfg)"
        );
    } else {
        tracing::info!(driver = D::NAME, "ready: provides {}", list());
    }
    Ok(())
}

/// Calls the driver's hook for one event with the runtime's error policy.
pub(crate) fn dispatch<D: Driver>(
    driver: &mut D,
    ctx: &mut Ctx,
    event: Event,
    stats: &mut Stats,
) -> Result<()> {
    stats.events += 1;
    match driver.on_event(ctx, event) {
        Err(NodeError::Decode { key, source }) => {
            stats.malformed += 1;
            tracing::warn!(
                driver = D::NAME,
                malformed = stats.malformed,
                "dropped a malformed message on `{key}`: {source}"
            );
            Ok(())
        }
        other => other,
    }
}

/// Tick generation on simulation time: `sim/clock` samples push a tick each
/// time the clock crosses the next multiple of the period.
#[derive(Default)]
struct SimTicks {
    period: AtomicU64,
    next: Mutex<f64>,
}

impl SimTicks {
    fn set_period(&self, p: Option<Duration>) {
        let bits = p.map(|p| p.as_secs_f64()).unwrap_or(0.0).to_bits();
        self.period.store(bits, Ordering::Release);
    }

    fn due(&self, now: f64) -> bool {
        let period = f64::from_bits(self.period.load(Ordering::Acquire));
        if period <= 0.0 {
            return false;
        }
        let mut next = self.next.lock().unwrap_or_else(|p| p.into_inner());
        if now + 1e-9 < *next {
            return false;
        }
        *next = if *next == 0.0 || now - *next > period {
            now + period
        } else {
            *next + period
        };
        true
    }
}

fn sim_clock(
    session: &Session,
    clock: Clock,
    inbox: Arc<Inbox>,
    ticks: Arc<SimTicks>,
) -> Result<Subscriber<()>> {
    session
        .declare_subscriber(keys::SIM_CLOCK)
        .callback(
            move |s| match codec::decode::<sim::Clock>(&s.payload().to_bytes()) {
                Ok(c) => {
                    clock.set(c.msg.time);
                    if ticks.due(c.msg.time) {
                        inbox.push(Event::Tick);
                    }
                }
                Err(e) => tracing::warn!("dropped a malformed sim/clock sample: {e}"),
            },
        )
        .wait()
        .map_err(z(|| "subscribing to sim/clock".into()))
}

/// The latest payload of each schema tag, per provided device.
type Latest = Arc<Mutex<HashMap<Device, Vec<(String, ZBytes)>>>>;

struct ZenohBus {
    session: Session,
    inbox: Arc<Inbox>,
    inline: Arc<Inline>,
    publishers: HashMap<Device, Publisher<'static>>,
    /// Latest payload of each schema (by tag) published on each provided device.
    latest: Latest,
    subscribers: Vec<Subscriber<()>>,
    queryables: Vec<Queryable<()>>,
    /// Answered from the receiving thread, without waking the driver.
    ready: Arc<ReadyAnswers>,
    clock_pub: Option<Publisher<'static>>,
    /// The devices as ROS 2 topics (`--ros2`).
    ros2: Option<Face>,
    /// Whether the session is the node's alone (`troupe node`), to close
    /// when the bus goes: that drops every declaration at once. One by one,
    /// each undeclaration looks through all the others (zenoh 1.10), and
    /// 8,000 devices took 4.7 s to stop.
    owns_session: bool,
}

impl Drop for ZenohBus {
    fn drop(&mut self) {
        // Runs before the fields' own drops: their undeclarations then
        // find the session closed and return at once.
        if self.owns_session {
            if let Err(e) = self.session.close().wait() {
                tracing::warn!("closing the session: {e}");
            }
        }
    }
}

struct ZenohSink(Query);

impl ReplySink for ZenohSink {
    fn send(self: Box<Self>, reply: std::result::Result<Vec<u8>, Vec<u8>>) {
        let q = self.0;
        let sent = match reply {
            Ok(p) => q.reply(q.key_expr().clone(), p).wait(),
            Err(p) => q.reply_err(p).wait(),
        };
        if let Err(e) = sent {
            tracing::warn!("could not answer request on `{}`: {e}", q.key_expr());
        }
    }
}

impl ZenohBus {
    fn provide(&mut self, dev: &Device, clock: &Clock, driver: &'static str) -> Result<()> {
        let s = &self.session;
        let data = keys::data(dev);
        let publisher = s
            .declare_publisher(data.clone())
            .express(true)
            .wait()
            .map_err(z(|| format!("declaring publisher {data}")))?;
        self.publishers.insert(*dev, publisher);

        let latest = self.latest.clone();
        let d = *dev;
        let q = s
            .declare_queryable(data.clone())
            .callback(move |q: Query| {
                let held = latest
                    .lock()
                    .unwrap_or_else(|p| p.into_inner())
                    .get(&d)
                    .map(|h| h.iter().map(|(_, b)| b.clone()).collect::<Vec<_>>())
                    .unwrap_or_default();
                for p in held {
                    if let Err(e) = q.reply(q.key_expr().clone(), p).wait() {
                        tracing::debug!("latest-value reply failed: {e}");
                    }
                }
            })
            .wait()
            .map_err(z(|| format!("declaring queryable {data}")))?;
        self.queryables.push(q);

        let inbox = self.inbox.clone();
        let sub = s
            .declare_subscriber(keys::cmd_any(dev))
            .callback(move |sample| {
                let key = sample.key_expr().to_string();
                inbox.push(Event::Command(Sample::new(
                    d,
                    key,
                    sample.payload().clone(),
                )));
            })
            .wait()
            .map_err(z(|| format!("subscribing to commands of {d}")))?;
        self.subscribers.push(sub);

        let (inbox, inline) = (self.inbox.clone(), self.inline.clone());
        let clock = clock.clone();
        let ready = self.ready.clone();
        let q = s
            .declare_queryable(keys::req_any(dev))
            .callback(move |query: Query| {
                let key = query.key_expr().to_string();
                let name = match keys::parse_named(&key, "req") {
                    Ok((_, n)) => n,
                    Err(e) => return tracing::warn!("ignored request: {e}"),
                };
                let payload = query.payload().cloned().unwrap_or_default();
                if let Some(reply) = ready.get(&d, &name, &payload.to_bytes(), clock.now()) {
                    return Box::new(ZenohSink(query)).send(Ok(reply));
                }
                let what = format!("request `{name}` to {d} ({driver})");
                let responder = Responder::new(Box::new(ZenohSink(query)), clock.clone(), what);
                let request = Request {
                    sample: Sample::new(d, key, payload),
                    name,
                    responder,
                };
                inline.deliver(&inbox, request);
            })
            .wait()
            .map_err(z(|| format!("declaring request queryable of {d}")))?;
        self.queryables.push(q);
        Ok(())
    }
}

impl ZenohBus {
    /// Sends `bytes` (an encoded payload) on `dev` and keeps them as the
    /// device's latest of their schema.
    fn send(&mut self, dev: &Device, bytes: ZBytes) -> Result<()> {
        {
            let raw = bytes.to_bytes();
            let tag = codec::schema_of(&raw).unwrap_or("?");
            let mut latest = self.latest.lock().unwrap_or_else(|p| p.into_inner());
            let held = latest.entry(*dev).or_default();
            match held.iter_mut().find(|(t, _)| *t == tag) {
                Some(slot) => slot.1 = bytes.clone(),
                None => held.push((tag.to_owned(), bytes.clone())),
            }
        }
        let publisher = self
            .publishers
            .get(dev)
            .ok_or_else(|| NodeError::config("?", format!("{dev} is not provided")))?;
        let ros2 = self.ros2.as_ref().map(|_| bytes.clone());
        publisher
            .put(bytes)
            .wait()
            .map_err(z(|| format!("publishing on {dev}")))?;
        if let (Some(face), Some(b)) = (&mut self.ros2, ros2) {
            face.publish(Some(dev), &b.to_bytes());
        }
        Ok(())
    }
}

impl Bus for ZenohBus {
    fn publish(&mut self, dev: &Device, payload: Vec<u8>) -> Result<()> {
        self.send(dev, ZBytes::from(payload))
    }

    fn publish_lent(
        &mut self,
        dev: &Device,
        len: usize,
        write: &mut dyn FnMut(&mut [u8]) -> bool,
    ) -> Result<bool> {
        use zenoh::shm::GarbageCollect;
        // The pool Zenoh made for its own copies (none with --no-shm; not
        // yet, while it is being made: the first large samples are copied).
        let Some(pool) = self.session.get_shm_provider().into_option() else {
            return Ok(false);
        };
        // Buffers the receivers have let go of first: the allocator then
        // hands back memory still in the cache, where a pool cycled through
        // before it is collected is cold at every write.
        pool.garbage_collect();
        // A full pool (its buffers held by subscribers) lends nothing.
        let Ok(mut buf) = pool.alloc(len).with_policy::<GarbageCollect>().wait() else {
            return Ok(false);
        };
        if !write(&mut buf) {
            return Ok(false);
        }
        self.send(dev, ZBytes::from(buf))?;
        Ok(true)
    }

    fn publish_clock(&mut self, payload: Vec<u8>) -> Result<()> {
        if self.clock_pub.is_none() {
            let p = self
                .session
                .declare_publisher(keys::SIM_CLOCK)
                .express(true)
                .wait()
                .map_err(z(|| "declaring the sim/clock publisher".into()))?;
            self.clock_pub = Some(p);
        }
        if let Some(face) = &mut self.ros2 {
            face.publish(None, &payload);
        }
        match &self.clock_pub {
            Some(p) => p
                .put(payload)
                .wait()
                .map_err(z(|| "publishing sim/clock".into())),
            None => Ok(()),
        }
    }

    fn subscribe(&mut self, dev: &Device) -> Result<()> {
        let key = keys::data(dev);
        let d = *dev;
        let seen = Arc::new(AtomicBool::new(false));
        let (inbox, live) = (self.inbox.clone(), seen.clone());
        let sub = self
            .session
            .declare_subscriber(key.clone())
            .callback(move |s| {
                live.store(true, Ordering::Release);
                let k = s.key_expr().to_string();
                inbox.push(Event::Data(Sample::new(d, k, s.payload().clone())));
            })
            .wait()
            .map_err(z(|| format!("subscribing to {key}")))?;
        self.subscribers.push(sub);
        // The latest samples the provider holds, unless live data got here first.
        let inbox = self.inbox.clone();
        self.session
            .get(key.clone())
            .callback(move |r| {
                if let Ok(s) = r.result() {
                    if !seen.load(Ordering::Acquire) {
                        let k = s.key_expr().to_string();
                        inbox.push(Event::Data(Sample::new(d, k, s.payload().clone())));
                    }
                }
            })
            .wait()
            .map_err(z(|| format!("fetching the latest {key}")))
    }

    fn command(&mut self, dev: &Device, name: &str, payload: Vec<u8>) -> Result<()> {
        let key = keys::cmd(dev, name);
        self.session
            .put(key.clone(), payload)
            .wait()
            .map_err(z(|| format!("sending command {key}")))
    }

    fn request(
        &mut self,
        id: RequestId,
        dev: &Device,
        name: &str,
        payload: Vec<u8>,
        timeout: Duration,
    ) -> Result<()> {
        let key = keys::req(dev, name);
        let once = ReplyOnce {
            id,
            device: *dev,
            inbox: self.inbox.clone(),
            started: Instant::now(),
            timeout,
            done: AtomicBool::new(false),
        };
        ask(&self.session, &key, timeout)
            .payload(payload)
            .callback(move |r| {
                let k = r
                    .result()
                    .map(|s| s.key_expr().to_string())
                    .unwrap_or_default();
                once.deliver(match r.into_result() {
                    Ok(s) => Ok(Sample::new(once.device, k, s.payload().clone())),
                    Err(e) => Err(RequestError::Nack(nack_reason(&e.payload().to_bytes()))),
                })
            })
            .wait()
            .map_err(z(|| format!("sending request {key}")))
    }
}

/// Delivers exactly one [`Reply`] per request: the first answer, or — when
/// Zenoh drops the callback with no answer — a timeout or "no replier".
struct ReplyOnce {
    id: RequestId,
    device: Device,
    inbox: Arc<Inbox>,
    started: Instant,
    timeout: Duration,
    done: AtomicBool,
}

impl ReplyOnce {
    fn deliver(&self, result: std::result::Result<Sample, RequestError>) {
        if !self.done.swap(true, Ordering::AcqRel) {
            self.inbox.push(Event::Reply(Reply {
                id: self.id,
                result,
            }));
        }
    }
}

impl Drop for ReplyOnce {
    fn drop(&mut self) {
        let err = if self.started.elapsed() + Duration::from_millis(50) >= self.timeout {
            RequestError::Timeout(self.timeout)
        } else {
            RequestError::NoReplier
        };
        self.deliver(Err(err));
    }
}
