//! The connection: a Zenoh session, a robot, and the "fresh data" signal.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

use troupe_msgs::{codec, keys, Command, DecodeError, Device, Interface, Message, Request};
use troupe_node::zenoh::pubsub::Subscriber;
use troupe_node::zenoh::{Session, Wait};
use troupe_node::{Mode, NodeError, ZenohArgs, REQUEST_TIMEOUT};

/// What can go wrong talking to devices.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    /// Opening the session or a Zenoh operation failed.
    #[error(transparent)]
    Node(#[from] NodeError),
    /// The device refused the request (Player's RESP_NACK).
    #[error("{device} refused `{request}`: {reason}")]
    Nack {
        /// The device.
        device: Device,
        /// The request name.
        request: String,
        /// Its reason.
        reason: String,
    },
    /// No device answered the request.
    #[error("no answer from {device} to `{request}` within {waited:?}: is the device live? (`troupe list`)")]
    NoAnswer {
        /// The device.
        device: Device,
        /// The request name.
        request: String,
        /// How long we waited.
        waited: Duration,
    },
    /// [`Client::read`] saw no new data in time.
    #[error("no new data within {0:?}")]
    ReadTimeout(Duration),
    /// An answer or sample did not decode.
    #[error("from {device}: {source}")]
    Decode {
        /// The device.
        device: Device,
        /// Why.
        #[source]
        source: DecodeError,
    },
    /// A proxy has no data yet.
    #[error("{0} has sent no data yet; call read() first")]
    NoData(Device),
}

/// The client's result type.
pub type Result<T, E = ClientError> = std::result::Result<T, E>;

#[derive(Default)]
struct Fresh {
    generation: Mutex<u64>,
    changed: Condvar,
}

struct Inner {
    session: Session,
    robot: u32,
    fresh: Fresh,
    seen: Mutex<u64>,
    /// The newest data stamp, as f64 bits.
    data_time: AtomicU64,
}

/// A connection to the robots on a Zenoh network, like libplayerc++'s `PlayerClient`.
#[derive(Clone)]
pub struct Client(Arc<Inner>);

impl Client {
    /// Connects to `robot` (a port number, as `PlayerClient("localhost", 6665)`).
    ///
    /// The session is a Zenoh client of the router the flags name (by
    /// default the local one at tcp/127.0.0.1:7447).
    ///
    /// # Errors
    ///
    /// [`ClientError::Node`] when no router answers.
    pub fn connect(z: &ZenohArgs, robot: u32) -> Result<Self> {
        let session = z.open(Mode::Client)?;
        Ok(Self::with_session(session, robot))
    }

    /// A client over an open session.
    pub fn with_session(session: Session, robot: u32) -> Self {
        Client(Arc::new(Inner {
            session,
            robot,
            fresh: Fresh::default(),
            seen: Mutex::new(0),
            data_time: AtomicU64::new(0),
        }))
    }

    /// The stamp of the newest sample any proxy received, in seconds: the
    /// simulator's clock under Stage, like libplayerc's `datatime`. 0 before
    /// the first sample.
    pub fn data_time(&self) -> f64 {
        f64::from_bits(self.0.data_time.load(Ordering::Relaxed))
    }

    /// The robot (port) this client talks to.
    pub fn robot(&self) -> u32 {
        self.0.robot
    }

    /// The underlying session.
    pub fn session(&self) -> &Session {
        &self.0.session
    }

    /// Waits until some proxy received data since the last `read`, like
    /// `PlayerClient::Read`, for at most [`REQUEST_TIMEOUT`] × 2.
    ///
    /// # Errors
    ///
    /// [`ClientError::ReadTimeout`] when nothing arrived in time.
    pub fn read(&self) -> Result<()> {
        self.read_timeout(REQUEST_TIMEOUT * 2)
    }

    /// [`Client::read`] with a deadline.
    ///
    /// # Errors
    ///
    /// [`ClientError::ReadTimeout`] when nothing arrived in time.
    pub fn read_timeout(&self, timeout: Duration) -> Result<()> {
        let deadline = Instant::now() + timeout;
        let mut seen = self.0.seen.lock().unwrap_or_else(|p| p.into_inner());
        let mut g = self
            .0
            .fresh
            .generation
            .lock()
            .unwrap_or_else(|p| p.into_inner());
        while *g == *seen {
            let now = Instant::now();
            if now >= deadline {
                return Err(ClientError::ReadTimeout(timeout));
            }
            g = self
                .0
                .fresh
                .changed
                .wait_timeout(g, deadline - now)
                .unwrap_or_else(|p| p.into_inner())
                .0;
        }
        *seen = *g;
        Ok(())
    }

    fn bump(&self) {
        *self
            .0
            .fresh
            .generation
            .lock()
            .unwrap_or_else(|p| p.into_inner()) += 1;
        self.0.fresh.changed.notify_all();
    }

    /// The device `interface:index` of this client's robot.
    pub fn device(&self, interface: Interface, index: u32) -> Device {
        Device::new(self.0.robot, interface, index)
    }

    /// Calls `on_sample` with every sample of `dev` (and first its latest
    /// sample, if its driver keeps one), then marks data fresh for `read`.
    /// The proxies are built on this; so are clients that take samples of
    /// any kind (the Python package).
    ///
    /// # Errors
    ///
    /// [`ClientError::Node`] if Zenoh refuses the subscription.
    pub fn subscribe(
        &self,
        dev: Device,
        on_sample: impl Fn(&[u8]) + Send + Sync + 'static,
    ) -> Result<Subscriber<()>> {
        let key = keys::data(&dev);
        let on_sample = Arc::new(on_sample);
        let (me, f) = (Arc::downgrade(&self.0), on_sample.clone());
        let sub = self
            .0
            .session
            .declare_subscriber(&key)
            .callback(move |s| {
                let bytes = s.payload().to_bytes();
                f(&bytes);
                if let Some(inner) = me.upgrade() {
                    // Non-negative floats order as their bit patterns do.
                    if let Ok((_, stamp, _)) = codec::split(&bytes) {
                        if stamp.is_finite() && stamp >= 0.0 {
                            inner
                                .data_time
                                .fetch_max(stamp.to_bits(), Ordering::Relaxed);
                        }
                    }
                    Client(inner).bump();
                }
            })
            .wait()
            .map_err(|e| NodeError::zenoh(format!("subscribing to {key}"), e))?;
        let latest = self
            .0
            .session
            .get(&key)
            .timeout(REQUEST_TIMEOUT)
            .wait()
            .map_err(|e| NodeError::zenoh(format!("fetching the latest {key}"), e))?;
        while let Ok(r) = latest.recv() {
            if let Ok(s) = r.result() {
                on_sample(&s.payload().to_bytes());
            }
        }
        Ok(sub)
    }

    /// Sends command `cmd` to `dev`.
    pub(crate) fn command<C: Command>(&self, dev: Device, cmd: &C) -> Result<()> {
        self.command_payload(dev, C::NAME, codec::encode(cmd, now()))
    }

    /// Sends an encoded command (`payload`, from [`codec::encode`]) named
    /// `name` to `dev`.
    ///
    /// # Errors
    ///
    /// [`ClientError::Node`] if Zenoh refuses to send it.
    pub fn command_payload(&self, dev: Device, name: &str, payload: Vec<u8>) -> Result<()> {
        let key = keys::cmd(&dev, name);
        self.0
            .session
            .put(&key, payload)
            .wait()
            .map_err(|e| NodeError::zenoh(format!("sending {key}"), e).into())
    }

    /// Sends request `req` to `dev` and waits for its answer.
    pub(crate) fn request<R: Request>(&self, dev: Device, req: &R) -> Result<R::Reply> {
        let reply =
            self.request_payload(dev, R::NAME, codec::encode(req, now()), REQUEST_TIMEOUT)?;
        decode::<R::Reply>(dev, &reply)
    }

    /// Sends an encoded request named `name` to `dev` and waits at most
    /// `timeout` for its answer: the reply's payload.
    ///
    /// # Errors
    ///
    /// [`ClientError::Nack`] with the device's reason when it refuses,
    /// [`ClientError::NoAnswer`] when none answers in time.
    pub fn request_payload(
        &self,
        dev: Device,
        name: &str,
        payload: Vec<u8>,
        timeout: Duration,
    ) -> Result<Vec<u8>> {
        let key = keys::req(&dev, name);
        let replies = troupe_node::ask(&self.0.session, &key, timeout)
            .payload(payload)
            .wait()
            .map_err(|e| NodeError::zenoh(format!("sending {key}"), e))?;
        let reply = replies.recv().map_err(|_| ClientError::NoAnswer {
            device: dev,
            request: name.to_owned(),
            waited: timeout,
        })?;
        match reply.into_result() {
            Ok(s) => Ok(s.payload().to_bytes().into_owned()),
            Err(e) => Err(ClientError::Nack {
                device: dev,
                request: name.to_owned(),
                reason: match codec::decode::<troupe_msgs::common::Nack>(&e.payload().to_bytes()) {
                    Ok(n) => n.msg.reason,
                    Err(_) => String::from_utf8_lossy(&e.payload().to_bytes()).into_owned(),
                },
            }),
        }
    }
}

pub(crate) fn decode<M: Message>(dev: Device, bytes: &[u8]) -> Result<M> {
    codec::decode::<M>(bytes)
        .map(|s| s.msg)
        .map_err(|source| ClientError::Decode {
            device: dev,
            source,
        })
}

/// Client-side stamps are wall time: the client has no simulator clock.
pub fn now() -> f64 {
    troupe_node::Clock::wall().now()
}
