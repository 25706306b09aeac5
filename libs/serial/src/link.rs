//! One session's hold on a line: the open port, its framer, and the abort
//! flag of the driver that owns the line thread.

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::framer::{Codec, FrameStats, Framer};
use crate::port::{LineError, Port};

/// Why a [`Link`] read or write ended early.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// The device went away, or the line failed.
    #[error(transparent)]
    Line(#[from] LineError),
    /// The driver is stopping.
    #[error("stopped")]
    Aborted,
}

/// Why a session with a device ended: the line failed, the driver is
/// stopping, or the device misbehaved in a way only its driver can name
/// (`E`, the driver's own reasons).
#[derive(Debug, thiserror::Error)]
pub enum SessionError<E> {
    /// The device went away, or the line failed.
    #[error(transparent)]
    Line(#[from] LineError),
    /// The driver is stopping.
    #[error("stopped")]
    Stopped,
    /// What the driver has to say about its device.
    #[error("{0}")]
    Device(E),
}

impl<E> From<LinkError> for SessionError<E> {
    fn from(e: LinkError) -> Self {
        match e {
            LinkError::Line(e) => SessionError::Line(e),
            LinkError::Aborted => SessionError::Stopped,
        }
    }
}

/// An open port and the frames of codec `C` on it. Reads wait in slices of
/// at most 100 ms and end with [`LinkError::Aborted`] as soon as the
/// driver raises its abort flag — except after [`Link::closing`], while the
/// driver says goodbye to the device.
#[derive(Debug)]
pub struct Link<C: Codec> {
    /// The serial device.
    pub port: Port,
    /// Frames read from it, and the counts of what was skipped.
    pub framer: Framer<C>,
    abort: Arc<AtomicBool>,
    closing: bool,
}

impl<C: Codec> Link<C> {
    /// Opens `path` at `baud`.
    ///
    /// # Errors
    ///
    /// What [`Port::open`] returns.
    pub fn open(
        path: &Path,
        baud: u32,
        codec: C,
        abort: Arc<AtomicBool>,
    ) -> Result<Self, LineError> {
        Ok(Link {
            port: Port::open(path, baud)?,
            framer: Framer::new(codec),
            abort,
            closing: false,
        })
    }

    /// Opens `path` at `baud` and runs one session with the device on it:
    /// the session's outcome and the line's frame statistics.
    pub fn session<E>(
        path: &Path,
        baud: u32,
        codec: C,
        abort: Arc<AtomicBool>,
        body: impl FnOnce(&mut Link<C>) -> Result<(), SessionError<E>>,
    ) -> (Result<(), SessionError<E>>, FrameStats) {
        match Link::open(path, baud, codec, abort) {
            Ok(mut link) => {
                let result = body(&mut link);
                (result, link.framer.stats)
            }
            Err(e) => (Err(e.into()), FrameStats::default()),
        }
    }

    /// Sends `bytes`.
    ///
    /// # Errors
    ///
    /// [`LineError::Lost`] when the device is gone.
    pub fn send(&mut self, bytes: &[u8]) -> Result<(), LineError> {
        self.port.send(bytes)
    }

    /// Drops whatever was received and not yet read, framed or not.
    pub fn flush(&mut self) {
        self.port.discard_input();
        self.framer.clear();
    }

    /// The next frame within `timeout`; `Ok(None)` when none came.
    ///
    /// # Errors
    ///
    /// [`LinkError::Line`] when the device goes away,
    /// [`LinkError::Aborted`] when the driver stops.
    pub fn read(&mut self, timeout: Duration) -> Result<Option<C::Frame>, LinkError> {
        let deadline = Instant::now() + timeout;
        loop {
            if self.abort.load(Ordering::Relaxed) && !self.closing {
                return Err(LinkError::Aborted);
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(None);
            }
            let slice = left.min(Duration::from_millis(100));
            if let Some(f) = self.framer.read(&mut self.port, slice)? {
                return Ok(Some(f));
            }
        }
    }

    /// From now on reads ignore the abort flag: the driver's last words to
    /// the device (stop the motors, stop the stream) get their answers.
    pub fn closing(&mut self) {
        self.closing = true;
    }
}
