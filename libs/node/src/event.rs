//! The events a driver receives: samples, commands, requests and their
//! answers, ticks and wakes.

use std::fmt;

use troupe_msgs::{codec, common::Nack, DecodeError, Device, Message, Stamped};
use zenoh::bytes::ZBytes;

use crate::clock::Clock;
use crate::error::{RequestError, Result};

/// Something for a driver to react to.
#[derive(Debug)]
pub enum Event {
    /// A sample from a device the driver subscribed to.
    Data(Sample),
    /// A command to a device the driver provides.
    Command(Sample),
    /// A request to a device the driver provides. Answer it now, or keep its
    /// [`Responder`] and answer later; a request never answered is NACKed.
    Request(Request),
    /// The answer to a request the driver sent with [`crate::Ctx::request`].
    Reply(Reply),
    /// The period set with [`crate::Ctx::set_tick`] has elapsed (on the node's clock).
    Tick,
    /// The driver's own I/O (a serial reader thread, say) called
    /// [`crate::Waker::wake`]: something it produced is waiting. Wakes are
    /// coalesced; drain everything that is ready.
    Wake,
}

/// An encoded message received on a device's key.
#[derive(Clone)]
pub struct Sample {
    /// The device it came from (data) or was sent to (command, request).
    pub device: Device,
    /// The key it arrived on, for error messages.
    pub key: String,
    pub(crate) payload: ZBytes,
}

impl fmt::Debug for Sample {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Sample")
            .field("key", &self.key)
            .field("schema", &self.schema())
            .finish()
    }
}

impl Sample {
    /// A sample from raw payload bytes.
    pub fn new(device: Device, key: String, payload: impl Into<ZBytes>) -> Self {
        Sample {
            device,
            key,
            payload: payload.into(),
        }
    }

    /// The schema tag, or `"?"` when the payload has none.
    pub fn schema(&self) -> String {
        codec::schema_of(&self.payload.to_bytes())
            .unwrap_or("?")
            .to_owned()
    }

    /// True when both payloads carry the same schema tag (no allocation:
    /// the inbox compares every new sample with the queued ones).
    pub fn same_schema(&self, other: &Sample) -> bool {
        let (a, b) = (self.payload.to_bytes(), other.payload.to_bytes());
        matches!((codec::schema_of(&a), codec::schema_of(&b)), (Ok(x), Ok(y)) if x == y)
    }

    /// True when the payload is an `M`.
    pub fn is<M: Message>(&self) -> bool {
        matches!(codec::schema_of(&self.payload.to_bytes()), Ok(s) if s == M::SCHEMA)
    }

    /// Decodes the payload as `M`.
    ///
    /// # Errors
    ///
    /// [`crate::NodeError::Decode`] naming the key: the wrong schema, or a
    /// malformed body.
    pub fn decode<M: Message>(&self) -> Result<Stamped<M>> {
        codec::decode(&self.payload.to_bytes()).map_err(|source| crate::NodeError::Decode {
            key: self.key.clone(),
            source,
        })
    }

    /// The error for a sample of a type the driver does not take; the runtime
    /// logs and counts it like a malformed one.
    pub fn unexpected(&self) -> crate::NodeError {
        let source = match codec::schema_of(&self.payload.to_bytes()) {
            Ok(tag) => DecodeError::UnknownSchema(tag.to_owned()),
            Err(e) => e,
        };
        crate::NodeError::Decode {
            key: self.key.clone(),
            source,
        }
    }

    /// The raw payload.
    pub fn payload(&self) -> &ZBytes {
        &self.payload
    }
}

/// A request to a provided device, with the means to answer it.
#[derive(Debug)]
pub struct Request {
    /// The request's payload and the device it was sent to.
    pub sample: Sample,
    /// The request's name (`geom`, `set_pose`…), the last chunk of its key.
    pub name: String,
    /// Where the answer goes.
    pub responder: Responder,
}

impl Request {
    /// True when the request is an `R`.
    pub fn is<R: troupe_msgs::Request>(&self) -> bool {
        self.name == R::NAME && self.sample.is::<R>()
    }

    /// Decodes the request as `R`.
    ///
    /// # Errors
    ///
    /// As [`Sample::decode`].
    pub fn decode<R: troupe_msgs::Request>(&self) -> Result<R> {
        self.sample.decode::<R>().map(|s| s.msg)
    }

    /// Answers with `reply` (Player's RESP_ACK).
    pub fn reply<M: Message>(self, reply: &M) {
        self.responder.reply(reply)
    }

    /// Refuses with `reason` (Player's RESP_NACK).
    pub fn nack(self, reason: impl Into<String>) {
        self.responder.nack(reason)
    }

    /// Refuses a request `driver` has no answer to, saying which and where
    /// (Player NACKs an unknown request too).
    pub fn unhandled(self, driver: &str) {
        let why = format!(
            "{driver} does not handle request `{}` on {}",
            self.name, self.sample.device
        );
        self.nack(why);
    }
}

/// Where a reply is sent.
pub(crate) trait ReplySink: Send {
    /// Delivers an encoded reply: `Ok` for an ACK, `Err` for a NACK.
    fn send(self: Box<Self>, reply: std::result::Result<Vec<u8>, Vec<u8>>);
}

/// Answers one request, once. Dropping it unanswered sends a NACK, so a
/// client never waits for an answer that will not come.
pub struct Responder {
    sink: Option<Box<dyn ReplySink>>,
    clock: Clock,
    what: String,
}

impl fmt::Debug for Responder {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Responder")
            .field("what", &self.what)
            .finish()
    }
}

impl Responder {
    pub(crate) fn new(sink: Box<dyn ReplySink>, clock: Clock, what: String) -> Self {
        Responder {
            sink: Some(sink),
            clock,
            what,
        }
    }

    /// Answers with `reply`.
    pub fn reply<M: Message>(mut self, reply: &M) {
        if let Some(sink) = self.sink.take() {
            sink.send(Ok(codec::encode(reply, self.clock.now())));
        }
    }

    /// Answers with another device's answer to a forwarded request: its
    /// ACK as it came, or a NACK with its reason.
    pub fn forward(mut self, answer: std::result::Result<Sample, RequestError>) {
        match answer {
            Ok(s) => {
                if let Some(sink) = self.sink.take() {
                    sink.send(Ok(s.payload.to_bytes().into_owned()));
                }
            }
            Err(RequestError::Nack(reason)) => self.nack(reason),
            Err(e) => self.nack(e.to_string()),
        }
    }

    /// Refuses with `reason`.
    pub fn nack(mut self, reason: impl Into<String>) {
        self.send_nack(reason.into());
    }

    fn send_nack(&mut self, reason: String) {
        if let Some(sink) = self.sink.take() {
            sink.send(Err(codec::encode(&Nack { reason }, self.clock.now())));
        }
    }
}

impl Drop for Responder {
    fn drop(&mut self) {
        if self.sink.is_some() {
            let reason = format!("{} was dropped without an answer", self.what);
            self.send_nack(reason);
        }
    }
}

/// Identifies a request the driver sent, to match its [`Reply`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct RequestId(pub u64);

/// The outcome of a request the driver sent.
#[derive(Debug)]
pub struct Reply {
    /// Which request.
    pub id: RequestId,
    /// The reply's payload, or why there is none.
    pub result: std::result::Result<Sample, RequestError>,
}

impl Reply {
    /// Decodes an ACK as `M`.
    ///
    /// # Errors
    ///
    /// The [`RequestError`] as a [`crate::NodeError::Driver`], or a decode error.
    pub fn decode<M: Message>(&self) -> Result<M> {
        match &self.result {
            Ok(s) => s.decode::<M>().map(|s| s.msg),
            Err(e) => Err(crate::NodeError::Request(e.clone())),
        }
    }
}

/// Turns an encoded NACK payload into its reason.
pub(crate) fn nack_reason(payload: &[u8]) -> String {
    match codec::decode::<Nack>(payload) {
        Ok(n) => n.msg.reason,
        Err(e) => format!("(unreadable NACK: {e})"),
    }
}
