//! [`Ctx`]: a driver's handle on the world during a hook.

use std::collections::{HashMap, HashSet};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use troupe_msgs::{codec, Command, Device, Message, Request};

use crate::clock::Clock;
use crate::error::{NodeError, Result};
use crate::event::RequestId;
use crate::inbox::Inbox;

/// The smallest payload encoded straight into memory the bus lends (one
/// batch of Zenoh's): below it, a sample is one write to a socket, and
/// Zenoh copies one of 3 KB or more into shared memory itself
/// (ARCHITECTURE.md, "Big samples").
const LEND_FROM: usize = 64 * 1024;

/// How long a request waits for its answer: libplayerc's default.
pub const REQUEST_TIMEOUT: Duration = Duration::from_secs(5);

/// The transport under a [`Ctx`]: Zenoh in a node, a recorder in the harness.
pub(crate) trait Bus: Send {
    fn publish(&mut self, dev: &Device, payload: Vec<u8>) -> Result<()>;
    /// Publishes a payload of `len` bytes that `write` fills in memory the
    /// bus lends (Zenoh's shared-memory pool), saving a copy of a large
    /// sample. `Ok(false)`: nothing lent, nothing sent.
    fn publish_lent(
        &mut self,
        _dev: &Device,
        _len: usize,
        _write: &mut dyn FnMut(&mut [u8]) -> bool,
    ) -> Result<bool> {
        Ok(false)
    }
    fn subscribe(&mut self, dev: &Device) -> Result<()>;
    fn publish_clock(&mut self, payload: Vec<u8>) -> Result<()>;
    fn command(&mut self, dev: &Device, name: &str, payload: Vec<u8>) -> Result<()>;
    fn request(
        &mut self,
        id: RequestId,
        dev: &Device,
        name: &str,
        payload: Vec<u8>,
        timeout: Duration,
    ) -> Result<()>;
}

/// The answers drivers keep ready ([`Ctx::answer_always`],
/// [`Ctx::answer_always_to`]), by device, request name and request body:
/// shared by the [`Ctx`] that keeps them and whatever receives requests,
/// which answers with them instead of delivering the request.
#[derive(Default)]
pub(crate) struct ReadyAnswers(Mutex<HashMap<Device, Vec<Kept>>>);

/// A request name, the request body it answers (`None`: any), and the
/// encoded answer.
type Kept = (&'static str, Option<Vec<u8>>, Vec<u8>);

impl ReadyAnswers {
    /// Keeps `reply` for request `name` to `dev` whose payload is `request`
    /// (`None`: any request), both as `codec::encode` made them.
    pub(crate) fn set(
        &self,
        dev: &Device,
        name: &'static str,
        request: Option<&[u8]>,
        reply: Vec<u8>,
    ) {
        let body = request.and_then(|r| codec::split(r).ok().map(|(_, _, b)| b.to_vec()));
        let mut all = self.0.lock().unwrap_or_else(|p| p.into_inner());
        let answers = all.entry(*dev).or_default();
        match answers
            .iter_mut()
            .find(|(n, b, _)| *n == name && *b == body)
        {
            Some(slot) => slot.2 = reply,
            None => answers.push((name, body, reply)),
        }
    }

    /// The kept answer to request `name` to `dev` whose payload is
    /// `request` (as `codec::encode` made it), stamped `now`.
    pub(crate) fn get(
        &self,
        dev: &Device,
        name: &str,
        request: &[u8],
        now: f64,
    ) -> Option<Vec<u8>> {
        let all = self.0.lock().unwrap_or_else(|p| p.into_inner());
        let kept = all.get(dev)?;
        let body = codec::split(request).map(|(_, _, b)| b).ok();
        let (_, _, reply) = kept
            .iter()
            .find(|(n, b, _)| *n == name && b.as_deref().is_none_or(|b| Some(b) == body))?;
        let mut reply = reply.clone();
        codec::restamp(&mut reply, now).ok()?;
        Some(reply)
    }
}

/// What a driver may do from inside a hook: publish, subscribe, command,
/// request, read the clock and set its tick.
pub struct Ctx {
    driver: &'static str,
    clock: Clock,
    bus: Box<dyn Bus>,
    provided: Vec<Device>,
    /// The same, to look up: a simulator of 4,000 robots publishes 8,000
    /// devices a step, and a scan of the list made it quadratic.
    provides: HashSet<Device>,
    next_id: u64,
    answers: Arc<ReadyAnswers>,
    pub(crate) tick: Option<Duration>,
    pub(crate) stop: bool,
    pub(crate) ready: bool,
    inbox: Option<Arc<Inbox>>,
}

/// Delivers [`crate::Event::Wake`] to a driver from any thread: how a
/// driver's own I/O thread tells it that input is waiting.
#[derive(Clone, Default)]
pub struct Waker(Option<Arc<Inbox>>);

impl Waker {
    /// A waker that wakes nobody: for code that runs a driver's I/O
    /// without a driver (tests, benchmarks).
    pub fn none() -> Self {
        Waker(None)
    }

    /// Queues one [`crate::Event::Wake`] (none if one is already queued).
    pub fn wake(&self) {
        if let Some(inbox) = &self.0 {
            inbox.push(crate::Event::Wake);
        }
    }
}

impl std::fmt::Debug for Waker {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Waker")
    }
}

impl Ctx {
    pub(crate) fn new(
        driver: &'static str,
        clock: Clock,
        bus: Box<dyn Bus>,
        provided: Vec<Device>,
        inbox: Option<Arc<Inbox>>,
        answers: Arc<ReadyAnswers>,
    ) -> Self {
        Ctx {
            driver,
            clock,
            bus,
            provides: provided.iter().copied().collect(),
            provided,
            next_id: 0,
            answers,
            tick: None,
            stop: false,
            ready: true,
            inbox,
        }
    }

    /// The node's time in seconds: simulation time under a simulator, else wall time.
    pub fn now(&self) -> f64 {
        self.clock.now()
    }

    /// The node's clock, to hand to code that needs time outside a hook.
    pub fn clock(&self) -> &Clock {
        &self.clock
    }

    /// Publishes `msg` as data of the provided device `dev`, stamped now.
    ///
    /// # Errors
    ///
    /// [`NodeError::NotProvided`] if `dev` is not in the section's `provides`;
    /// [`NodeError::Zenoh`] if the sample could not be sent.
    pub fn publish<M: Message>(&mut self, dev: &Device, msg: &M) -> Result<()> {
        let now = self.clock.now();
        self.publish_at(dev, msg, now)
    }

    /// [`Ctx::publish`] stamped `stamp`: a driver that turns another's data
    /// into its own keeps the time the data was taken, not the time it was
    /// passed on (a scan restamped a step late misplaces the robot by the
    /// distance it drove in that step).
    ///
    /// # Errors
    ///
    /// As [`Ctx::publish`].
    pub fn publish_at<M: Message>(&mut self, dev: &Device, msg: &M, stamp: f64) -> Result<()> {
        self.check_provided(dev)?;
        let len = codec::encoded_len(msg);
        if len >= LEND_FROM
            && self
                .bus
                .publish_lent(dev, len, &mut |out| codec::encode_into(msg, stamp, out))?
        {
            return Ok(());
        }
        self.bus.publish(dev, codec::encode_sized(msg, stamp, len))
    }

    /// Publishes an already encoded sample (its schema tag and stamp
    /// included, as [`troupe_msgs::encode`] makes them) as data of the
    /// provided device `dev`: for drivers that replay what was recorded.
    ///
    /// # Errors
    ///
    /// As [`Ctx::publish`].
    pub fn publish_encoded(&mut self, dev: &Device, payload: Vec<u8>) -> Result<()> {
        self.check_provided(dev)?;
        self.bus.publish(dev, payload)
    }

    /// Ok if `dev` is in the section's `provides`.
    fn check_provided(&self, dev: &Device) -> Result<()> {
        if self.provides.contains(dev) {
            Ok(())
        } else {
            Err(NodeError::NotProvided {
                driver: self.driver.to_owned(),
                device: *dev,
            })
        }
    }

    /// Answers every `R` sent to the provided device `dev` with `reply`,
    /// stamped when it is sent, straight from the thread that receives the
    /// request: the driver's thread is not woken and the request never
    /// reaches [`crate::Driver::on_event`]. For answers that depend neither
    /// on the request nor on the moment (a device's geometry, a map's
    /// info), which clients ask often and expect fast. Call it again when
    /// the answer changes.
    ///
    /// # Errors
    ///
    /// [`NodeError::NotProvided`] if `dev` is not in the section's `provides`.
    pub fn answer_always<R: Request>(&mut self, dev: &Device, reply: &R::Reply) -> Result<()> {
        self.check_provided(dev)?;
        self.answers
            .set(dev, R::NAME, None, codec::encode(reply, 0.0));
        Ok(())
    }

    /// Answers every request equal to `request` sent to the provided device
    /// `dev` with `reply`, as [`Ctx::answer_always`] does for every `R`:
    /// for answers that depend on what is asked, and change only when the
    /// driver says (a named model's pose between simulation steps). Call it
    /// again whenever the answer changes, before answering anything that
    /// changed it, so a client that waits for each answer never sees an old
    /// one.
    ///
    /// # Errors
    ///
    /// [`NodeError::NotProvided`] if `dev` is not in the section's `provides`.
    pub fn answer_always_to<R: Request>(
        &mut self,
        dev: &Device,
        request: &R,
        reply: &R::Reply,
    ) -> Result<()> {
        self.check_provided(dev)?;
        let asked = codec::encode(request, 0.0);
        self.answers
            .set(dev, R::NAME, Some(&asked), codec::encode(reply, 0.0));
        Ok(())
    }

    /// Delivers `dev`'s data as [`crate::Event::Data`] from now on (and its
    /// latest sample, if its driver keeps one).
    ///
    /// # Errors
    ///
    /// [`NodeError::Zenoh`] if the subscription could not be declared.
    pub fn subscribe(&mut self, dev: &Device) -> Result<()> {
        self.bus.subscribe(dev)
    }

    /// Sends command `cmd` to `dev`.
    ///
    /// # Errors
    ///
    /// [`NodeError::Zenoh`] if it could not be sent.
    pub fn command<C: Command>(&mut self, dev: &Device, cmd: &C) -> Result<()> {
        self.bus
            .command(dev, C::NAME, codec::encode(cmd, self.clock.now()))
    }

    /// Sends request `req` to `dev`; its answer arrives as [`crate::Event::Reply`]
    /// with the returned id, within [`REQUEST_TIMEOUT`].
    ///
    /// # Errors
    ///
    /// [`NodeError::Zenoh`] if it could not be sent.
    pub fn request<R: Request>(&mut self, dev: &Device, req: &R) -> Result<RequestId> {
        let payload = codec::encode(req, self.clock.now());
        self.forward_request(dev, R::NAME, payload)
    }

    /// Sends an already encoded request `name` to `dev`, as a driver that
    /// passes its clients' requests through does; the answer arrives as
    /// [`crate::Event::Reply`] (see [`crate::Responder::forward`]).
    ///
    /// # Errors
    ///
    /// [`NodeError::Zenoh`] if it could not be sent.
    pub fn forward_request(
        &mut self,
        dev: &Device,
        name: &str,
        payload: Vec<u8>,
    ) -> Result<RequestId> {
        self.next_id += 1;
        let id = RequestId(self.next_id);
        self.bus.request(id, dev, name, payload, REQUEST_TIMEOUT)?;
        Ok(id)
    }

    /// Delivers [`crate::Event::Tick`] every `period` of the node's clock (`None` stops it).
    pub fn set_tick(&mut self, period: Option<Duration>) {
        self.tick = period.filter(|p| !p.is_zero());
    }

    /// Sets the node's time (simulation time) and publishes it on `sim/clock`.
    /// Only for a [`crate::Driver::CLOCK_SOURCE`] driver; others get an error.
    ///
    /// # Errors
    ///
    /// [`NodeError::Config`] when the driver is not a clock source;
    /// [`NodeError::Zenoh`] if the clock sample could not be sent.
    pub fn set_time(&mut self, time: f64) -> Result<()> {
        if !self.clock.is_manual() {
            return Err(NodeError::config(
                self.driver,
                "only a clock-source driver sets the time",
            ));
        }
        self.clock.set(time);
        let msg = troupe_msgs::sim::Clock { time };
        self.bus.publish_clock(codec::encode(&msg, time))
    }

    /// Asks the runtime to stop this node once the current hook returns
    /// (`shutdown` runs, the process exits cleanly).
    pub fn request_stop(&mut self) {
        self.stop = true;
    }

    /// A handle that wakes this driver from another thread (see
    /// [`crate::Event::Wake`]). Under the test harness it does nothing:
    /// deliver `Event::Wake` by hand.
    pub fn waker(&self) -> Waker {
        Waker(self.inbox.clone())
    }

    /// Says whether the driver's devices can serve: a hardware driver that
    /// lost its device (or has not reached it yet) sets `false`, and its
    /// devices' liveliness tokens are withdrawn, so `troupe list` and every
    /// waiting `requires` see them as not ready, until it sets `true` again.
    /// A driver is ready by default.
    pub fn set_ready(&mut self, ready: bool) {
        self.ready = ready;
    }

    /// Whether the driver last said it is ready ([`Ctx::set_ready`]).
    pub fn is_ready(&self) -> bool {
        self.ready
    }

    /// The devices this driver provides.
    pub fn provided(&self) -> &[Device] {
        &self.provided
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use troupe_msgs::{simulation, Interface};

    #[test]
    fn ready_answers_match_the_request_they_were_kept_for() {
        let ready = ReadyAnswers::default();
        let dev = Device::new(6665, Interface::Simulation, 0);
        let ask = |name: &str| codec::encode(&simulation::GetPose2d { name: name.into() }, 3.0);
        let answer = |x: f64| codec::encode(&common_pose("r0", x), 0.0);
        ready.set(&dev, "get_pose2d", Some(&ask("r0")), answer(1.0));
        let got = ready.get(&dev, "get_pose2d", &ask("r0"), 7.5).unwrap();
        let got = codec::decode::<simulation::Pose2dOf>(&got).unwrap();
        assert_eq!((got.stamp, got.msg.pose.x), (7.5, 1.0));
        // Another body, another name or another device: not this answer.
        assert!(ready.get(&dev, "get_pose2d", &ask("r1"), 0.0).is_none());
        assert!(ready.get(&dev, "set_pose2d", &ask("r0"), 0.0).is_none());
        let other = Device::new(6665, Interface::Simulation, 1);
        assert!(ready.get(&other, "get_pose2d", &ask("r0"), 0.0).is_none());
        // Kept again: replaced, not added.
        ready.set(&dev, "get_pose2d", Some(&ask("r0")), answer(2.0));
        assert_eq!(x_of(ready.get(&dev, "get_pose2d", &ask("r0"), 0.0)), 2.0);
        // An answer kept for any body answers them all.
        ready.set(&dev, "get_pose2d", None, answer(9.0));
        assert_eq!(x_of(ready.get(&dev, "get_pose2d", &ask("r1"), 0.0)), 9.0);
    }

    /// The x of a kept pose answer.
    fn x_of(answer: Option<Vec<u8>>) -> f64 {
        let answer = answer.unwrap();
        codec::decode::<simulation::Pose2dOf>(&answer)
            .unwrap()
            .msg
            .pose
            .x
    }

    fn common_pose(name: &str, x: f64) -> simulation::Pose2dOf {
        simulation::Pose2dOf {
            name: name.into(),
            pose: troupe_msgs::Pose2d::new(x, 0.0, 0.0),
        }
    }
}
