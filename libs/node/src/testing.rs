//! A harness that runs one [`Driver`] in a test, without the network.
//!
//! Inputs, commands, requests, replies and ticks are delivered by hand; what
//! the driver publishes, subscribes to, commands and requests is recorded.
//! The clock is manual and starts at 0.
//!
//! ```
//! # use troupe_node::{testing::Harness, Driver, Ctx, Event, NoOptions, Section, Result};
//! # struct Nop;
//! # impl Driver for Nop {
//! #     const NAME: &'static str = "nop";
//! #     type Options = NoOptions;
//! #     fn new(_: &Section, _: NoOptions) -> Result<Self> { Ok(Nop) }
//! #     fn on_event(&mut self, _: &mut Ctx, _: Event) -> Result<()> { Ok(()) }
//! # }
//! let mut h = Harness::<Nop>::from_json(r#"{"name": "nop"}"#).unwrap();
//! h.tick().unwrap();
//! ```

use std::collections::HashMap;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use troupe_msgs::{codec, keys, Command, Device, Message, Request};

use crate::clock::Clock;
use crate::ctx::{Bus, Ctx, ReadyAnswers};
use crate::driver::Driver;
use crate::error::{NodeError, RequestError, Result};
use crate::event::{nack_reason, Event, Reply, ReplySink, RequestId, Responder, Sample};
use crate::runtime::{build, dispatch, Stats};
use crate::section::Section;

type Answer = std::result::Result<Vec<u8>, Vec<u8>>;

/// The file `rel` of the Player and Stage projects' samples, read in place
/// from the workspace's sibling `../shared/compat` (`stage/simple.cfg`);
/// `None` when it is absent, for the test to skip ([`cannot_run`]: under
/// `CI=true` the test fails instead).
pub fn compat(rel: &str) -> Option<std::path::PathBuf> {
    // This crate is libs/node in the workspace: any crate's tests find the
    // samples from here.
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/compat")
        .join(rel);
    if path.exists() {
        Some(path)
    } else {
        cannot_run(&format!("{} is absent", path.display()));
        None
    }
}

/// True under `CI=true` (`.ci/run` sets it).
pub fn in_ci() -> bool {
    std::env::var("CI").is_ok_and(|v| v == "true")
}

/// Says why a test cannot run here, on one line, for it to return early;
/// under `CI=true` it panics instead, so that no test passes in CI without
/// running.
///
/// # Panics
///
/// Under `CI=true`.
pub fn cannot_run(why: &str) {
    assert!(!in_ci(), "CI=true, and {why}: this test must run in CI");
    eprintln!("skipping: {why}");
}

#[derive(Default)]
struct Recorder {
    published: Vec<(Device, Vec<u8>)>,
    subscribed: Vec<Device>,
    commands: Vec<(Device, String, Vec<u8>)>,
    requests: Vec<SentRequest>,
    answers: HashMap<u64, Answer>,
    clock: Vec<Vec<u8>>,
}

/// A request the driver sent.
#[derive(Debug, Clone)]
pub struct SentRequest {
    /// Its id, to answer it with [`Harness::answer`].
    pub id: RequestId,
    /// The device it went to.
    pub device: Device,
    /// The request name.
    pub name: String,
    payload: Vec<u8>,
}

impl SentRequest {
    /// True when the request is an `R`.
    pub fn is<R: Request>(&self) -> bool {
        self.name == R::NAME && codec::schema_of(&self.payload).ok() == Some(R::SCHEMA)
    }
}

/// Identifies a request made with [`Harness::request`].
#[derive(Debug, Clone, Copy)]
pub struct Pending(u64);

#[derive(Clone)]
struct Rec(Arc<Mutex<Recorder>>);

impl Rec {
    fn lock(&self) -> MutexGuard<'_, Recorder> {
        self.0.lock().unwrap_or_else(|p| p.into_inner())
    }
}

impl Bus for Rec {
    fn publish(&mut self, dev: &Device, payload: Vec<u8>) -> Result<()> {
        self.lock().published.push((*dev, payload));
        Ok(())
    }
    fn subscribe(&mut self, dev: &Device) -> Result<()> {
        self.lock().subscribed.push(*dev);
        Ok(())
    }
    fn publish_clock(&mut self, payload: Vec<u8>) -> Result<()> {
        self.lock().clock.push(payload);
        Ok(())
    }
    fn command(&mut self, dev: &Device, name: &str, payload: Vec<u8>) -> Result<()> {
        self.lock().commands.push((*dev, name.to_owned(), payload));
        Ok(())
    }
    fn request(
        &mut self,
        id: RequestId,
        dev: &Device,
        name: &str,
        payload: Vec<u8>,
        _: Duration,
    ) -> Result<()> {
        self.lock().requests.push(SentRequest {
            id,
            device: *dev,
            name: name.to_owned(),
            payload,
        });
        Ok(())
    }
}

struct RecSink(Rec, u64);

impl ReplySink for RecSink {
    fn send(self: Box<Self>, reply: Answer) {
        self.0.lock().answers.insert(self.1, reply);
    }
}

/// Runs one driver by hand. See the module docs.
pub struct Harness<D: Driver> {
    driver: D,
    ctx: Ctx,
    rec: Rec,
    /// The answers the driver keeps ready, as the runtime shares them.
    ready: Arc<ReadyAnswers>,
    clock: Clock,
    stats: Stats,
    next_pending: u64,
}

impl<D: Driver> Harness<D> {
    /// Builds the driver from `section` and runs its `setup`.
    ///
    /// # Errors
    ///
    /// What building or `setup` returned.
    pub fn new(section: Section) -> Result<Self> {
        let mut driver = build::<D>(&section)?;
        let rec = Rec(Arc::default());
        let clock = Clock::manual(0.0);
        let provided = section.provided().into_iter().map(|s| s.device).collect();
        let ready = Arc::<ReadyAnswers>::default();
        let mut ctx = Ctx::new(
            D::NAME,
            clock.clone(),
            Box::new(rec.clone()),
            provided,
            None,
            ready.clone(),
        );
        driver.setup(&mut ctx)?;
        Ok(Harness {
            driver,
            ctx,
            rec,
            ready,
            clock,
            stats: Stats::default(),
            next_pending: 0,
        })
    }

    /// [`Harness::new`] from a section in JSON.
    ///
    /// # Errors
    ///
    /// A malformed section, or what building or `setup` returned.
    pub fn from_json(json: &str) -> Result<Self> {
        Self::new(Section::from_json(json)?)
    }

    /// Sets the clock.
    pub fn set_time(&mut self, t: f64) {
        self.clock.set(t);
    }

    /// The driver, to inspect its state.
    pub fn driver(&self) -> &D {
        &self.driver
    }

    /// The tick period the driver asked for.
    pub fn tick_period(&self) -> Option<Duration> {
        self.ctx.tick
    }

    fn deliver(&mut self, ev: Event) -> Result<()> {
        dispatch(&mut self.driver, &mut self.ctx, ev, &mut self.stats)
    }

    /// Delivers `msg` as data from `dev`.
    ///
    /// # Errors
    ///
    /// What the driver's `on_event` returned, malformed input aside.
    pub fn input<M: Message>(&mut self, dev: Device, msg: &M) -> Result<()> {
        self.input_raw(dev, codec::encode(msg, self.clock.now()))
    }

    /// Delivers raw bytes as data from `dev` (to test malformed input).
    ///
    /// # Errors
    ///
    /// What the driver's `on_event` returned, malformed input aside.
    pub fn input_raw(&mut self, dev: Device, payload: Vec<u8>) -> Result<()> {
        self.deliver(Event::Data(Sample::new(dev, keys::data(&dev), payload)))
    }

    /// Delivers command `cmd` to the provided device `dev`.
    ///
    /// # Errors
    ///
    /// What the driver's `on_event` returned, malformed input aside.
    pub fn command<C: Command>(&mut self, dev: Device, cmd: &C) -> Result<()> {
        let p = codec::encode(cmd, self.clock.now());
        self.deliver(Event::Command(Sample::new(
            dev,
            keys::cmd(&dev, C::NAME),
            p,
        )))
    }

    /// Delivers request `req` to the provided device `dev`; see [`Harness::reply`].
    ///
    /// # Errors
    ///
    /// What the driver's `on_event` returned, malformed input aside.
    pub fn request<R: Request>(&mut self, dev: Device, req: &R) -> Result<Pending> {
        self.next_pending += 1;
        let id = self.next_pending;
        // An answer the driver keeps ready never reaches it, as on the network.
        let p = codec::encode(req, self.clock.now());
        if let Some(reply) = self.ready.get(&dev, R::NAME, &p, self.clock.now()) {
            self.rec.lock().answers.insert(id, Ok(reply));
            return Ok(Pending(id));
        }
        let sink = Box::new(RecSink(self.rec.clone(), id));
        let what = format!("request `{}` to {dev}", R::NAME);
        let responder = Responder::new(sink, self.clock.clone(), what);
        self.deliver(Event::Request(crate::event::Request {
            sample: Sample::new(dev, keys::req(&dev, R::NAME), p),
            name: R::NAME.to_owned(),
            responder,
        }))?;
        Ok(Pending(id))
    }

    /// The answer to a request: `None` while unanswered, `Err(reason)` for a NACK.
    pub fn reply<M: Message>(&self, p: Pending) -> Option<std::result::Result<M, String>> {
        let rec = self.rec.lock();
        Some(match rec.answers.get(&p.0)? {
            Ok(b) => codec::decode::<M>(b)
                .map(|s| s.msg)
                .map_err(|e| e.to_string()),
            Err(b) => Err(nack_reason(b)),
        })
    }

    /// Delivers a tick.
    ///
    /// # Errors
    ///
    /// What the driver's `on_event` returned.
    pub fn tick(&mut self) -> Result<()> {
        self.deliver(Event::Tick)
    }

    /// Delivers [`Event::Wake`], as a [`crate::Waker`] would from the
    /// driver's own thread (the harness's wakers wake nobody).
    ///
    /// # Errors
    ///
    /// What the driver's `on_event` returned.
    pub fn wake(&mut self) -> Result<()> {
        self.deliver(Event::Wake)
    }

    /// Everything of type `M` the driver published on `dev`, oldest first.
    pub fn published<M: Message>(&self, dev: Device) -> Vec<M> {
        self.published_at(dev).into_iter().map(|(_, m)| m).collect()
    }

    /// [`Harness::published`] with each sample's stamp.
    pub fn published_at<M: Message>(&self, dev: Device) -> Vec<(f64, M)> {
        self.rec
            .lock()
            .published
            .iter()
            .filter(|(d, _)| *d == dev)
            .filter_map(|(_, b)| codec::decode::<M>(b).ok().map(|s| (s.stamp, s.msg)))
            .collect()
    }

    /// The devices the driver subscribed to.
    pub fn subscriptions(&self) -> Vec<Device> {
        self.rec.lock().subscribed.clone()
    }

    /// The commands of type `C` the driver sent to `dev`.
    pub fn commands_sent<C: Command>(&self, dev: Device) -> Vec<C> {
        self.rec
            .lock()
            .commands
            .iter()
            .filter(|(d, n, _)| *d == dev && n == C::NAME)
            .filter_map(|(_, _, b)| codec::decode::<C>(b).ok().map(|s| s.msg))
            .collect()
    }

    /// The requests the driver sent, oldest first.
    pub fn requests_sent(&self) -> Vec<SentRequest> {
        self.rec.lock().requests.clone()
    }

    /// Answers the driver's request `id` with `reply`.
    ///
    /// # Errors
    ///
    /// What the driver's `on_event` returned.
    pub fn answer<M: Message>(&mut self, id: RequestId, reply: &M) -> Result<()> {
        let (dev, key) = self.request_target(id)?;
        let p = codec::encode(reply, self.clock.now());
        self.deliver(Event::Reply(Reply {
            id,
            result: Ok(Sample::new(dev, key, p)),
        }))
    }

    /// Fails the driver's request `id` with `err`.
    ///
    /// # Errors
    ///
    /// What the driver's `on_event` returned.
    pub fn fail(&mut self, id: RequestId, err: RequestError) -> Result<()> {
        self.request_target(id)?;
        self.deliver(Event::Reply(Reply {
            id,
            result: Err(err),
        }))
    }

    fn request_target(&self, id: RequestId) -> Result<(Device, String)> {
        let rec = self.rec.lock();
        let r = rec
            .requests
            .iter()
            .find(|r| r.id == id)
            .ok_or_else(|| NodeError::Driver(format!("no request {id:?} was sent").into()))?;
        Ok((r.device, keys::req(&r.device, &r.name)))
    }

    /// The `sim/clock` times a clock-source driver published.
    pub fn clock_published(&self) -> Vec<f64> {
        self.rec
            .lock()
            .clock
            .iter()
            .filter_map(|b| {
                codec::decode::<troupe_msgs::sim::Clock>(b)
                    .ok()
                    .map(|s| s.msg.time)
            })
            .collect()
    }

    /// The driver's current time.
    pub fn now(&self) -> f64 {
        self.clock.now()
    }

    /// True once the driver asked to stop.
    pub fn stop_requested(&self) -> bool {
        self.ctx.stop
    }

    /// Malformed inputs the runtime dropped.
    pub fn malformed(&self) -> u64 {
        self.stats.malformed
    }

    /// Runs the driver's `shutdown`.
    ///
    /// # Errors
    ///
    /// What `shutdown` returned.
    pub fn shutdown(&mut self) -> Result<()> {
        self.driver.shutdown(&mut self.ctx)
    }
}
