//! The threads of hardware drivers and of device emulators.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, Sender};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::{FrameStats, SessionError};

/// A driver's line thread: it takes orders of type `O`, reports updates
/// of type `U` (each followed by a wake of the driver's loop) and can be
/// cut short. The body receives the orders, its [`Reports`] and an abort
/// flag for its [`crate::Link`]s.
#[derive(Debug)]
pub struct LineThread<O, U> {
    orders: Sender<O>,
    updates: Receiver<U>,
    abort: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

/// A line thread's side of its updates: [`Reports::send`] queues one and
/// wakes the driver.
pub struct Reports<U> {
    tx: Sender<U>,
    wake: Box<dyn Fn() + Send>,
}

impl<U> Reports<U> {
    /// Queues `update` for the driver and wakes it (nothing happens once
    /// the driver has gone).
    pub fn send(&self, update: U) {
        let _ = self.tx.send(update);
        (self.wake)();
    }
}

impl<O: Send + 'static, U: Send + 'static> LineThread<O, U> {
    /// Starts `body` on a thread called `name`; `wake` is called after each
    /// update the body reports.
    ///
    /// # Errors
    ///
    /// When the thread cannot be started.
    pub fn spawn(
        name: &str,
        wake: impl Fn() + Send + 'static,
        body: impl FnOnce(Receiver<O>, Reports<U>, Arc<AtomicBool>) + Send + 'static,
    ) -> std::io::Result<Self> {
        let (orders, rx) = std::sync::mpsc::channel();
        let (tx, updates) = std::sync::mpsc::channel();
        let reports = Reports {
            tx,
            wake: Box::new(wake),
        };
        let abort = Arc::new(AtomicBool::new(false));
        let flag = abort.clone();
        let thread = std::thread::Builder::new()
            .name(name.into())
            .spawn(move || body(rx, reports, flag))?;
        Ok(LineThread {
            orders,
            updates,
            abort,
            thread: Some(thread),
        })
    }

    /// Queues an order; false when the thread has ended.
    pub fn send(&self, order: O) -> bool {
        self.orders.send(order).is_ok()
    }

    /// The updates the thread reports, in order.
    pub fn updates(&self) -> &Receiver<U> {
        &self.updates
    }

    /// Raises the abort flag, sends `last` (the order that says goodbye to
    /// the device) and waits for the thread to end.
    pub fn stop(mut self, last: O) {
        self.abort.store(true, Ordering::Relaxed);
        let _ = self.orders.send(last);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// A driver's hold on its line thread: `None` until the driver is set up
/// (and in tests that never open a port). What every serial driver does
/// with it, said once.
pub trait HeldLine<O, U> {
    /// Queues an order, if there is a thread; false when there is none or
    /// it has ended.
    fn order(&self, order: O) -> bool;
    /// The updates reported since the last call (none without a thread).
    fn updates_now(&self) -> Vec<U>;
    /// Stops the thread, if there is one, with `last` (see
    /// [`LineThread::stop`]).
    fn stop_with(&mut self, last: O);
}

impl<O: Send + 'static, U: Send + 'static> HeldLine<O, U> for Option<LineThread<O, U>> {
    fn order(&self, order: O) -> bool {
        self.as_ref().is_some_and(|l| l.send(order))
    }

    fn updates_now(&self) -> Vec<U> {
        self.as_ref()
            .map(|l| l.updates().try_iter().collect())
            .unwrap_or_default()
    }

    fn stop_with(&mut self, last: O) {
        if let Some(line) = self.take() {
            line.stop(last);
        }
    }
}

/// The next message on `rx` that `want` accepts, the others skipped,
/// within `within`: how tests and tools wait for a line thread's update.
///
/// # Errors
///
/// The time ran out, or the sender is gone.
pub fn recv_where<U>(
    rx: &Receiver<U>,
    within: Duration,
    mut want: impl FnMut(&U) -> bool,
) -> Result<U, RecvTimeoutError> {
    let deadline = Instant::now() + within;
    loop {
        let u = rx.recv_timeout(deadline.saturating_duration_since(Instant::now()))?;
        if want(&u) {
            return Ok(u);
        }
    }
}

/// How a session with a device ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ended {
    /// The driver is stopping: no more sessions.
    Stopped,
    /// The device failed or went away: try again after the delay.
    Failed,
}

/// Ends a session with the device at `port` from its outcome and its
/// line's statistics: a stop ends the thread; a failure is logged as
/// "`what` not ready" with the session's number and the frames the line
/// dropped, handed to `lost` (to tell the driver), and retried after
/// `delay`.
pub fn end_session<E: std::fmt::Display>(
    what: &str,
    port: &Path,
    session: u64,
    (result, stats): (Result<(), SessionError<E>>, FrameStats),
    delay: Duration,
    lost: impl FnOnce(String),
) -> Ended {
    match result {
        Ok(()) | Err(SessionError::Stopped) => Ended::Stopped,
        Err(e) => {
            tracing::warn!(
                port = %port.display(),
                session,
                noise_bytes = stats.noise,
                checksum_errors = stats.checksum,
                malformed = stats.malformed,
                "{what} not ready: {e}; retrying in {} s",
                delay.as_secs()
            );
            lost(e.to_string());
            Ended::Failed
        }
    }
}

/// A line thread's life: sessions with the device, one after another,
/// `delay` apart after each failure. Orders that arrive between sessions go
/// to `between`, which returns false for the one that ends the thread; a
/// closed order channel ends it too.
pub fn run_sessions<S, O>(
    state: &mut S,
    orders: &Receiver<O>,
    delay: Duration,
    mut session: impl FnMut(&mut S) -> Ended,
    mut between: impl FnMut(&mut S, O) -> bool,
) {
    loop {
        if session(state) == Ended::Stopped {
            return;
        }
        let until = Instant::now() + delay;
        loop {
            match orders.recv_timeout(until.saturating_duration_since(Instant::now())) {
                Ok(o) => {
                    if !between(state, o) {
                        return;
                    }
                }
                Err(RecvTimeoutError::Timeout) => break,
                Err(RecvTimeoutError::Disconnected) => return,
            }
        }
    }
}

/// An emulator running on a thread of its own, for tests and benchmarks:
/// [`Emulator::spawn`] returns once the emulated device is linked, in a
/// directory of its own that goes when the emulator does.
#[derive(Debug)]
pub struct Emulator<T> {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<std::io::Result<T>>>,
    dir: PathBuf,
    link: PathBuf,
}

/// What an emulator's body calls once its device can be opened.
pub type Linked = Box<dyn FnOnce() + Send>;

impl<T: Send + 'static> Emulator<T> {
    /// Makes a fresh directory for `name` (in this process), then runs
    /// `body(link, stop, linked)` on a thread, `link` being the path in it
    /// to link the device at, and waits (10 s at most) until it calls
    /// `linked`.
    ///
    /// # Errors
    ///
    /// The directory cannot be made; the body's own error when it ends
    /// before linking; a timeout.
    pub fn spawn(
        name: &str,
        body: impl FnOnce(PathBuf, &AtomicBool, Linked) -> std::io::Result<T> + Send + 'static,
    ) -> std::io::Result<Self> {
        let dir = std::env::temp_dir().join(format!("troupe-emu-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir)?;
        let link = dir.join("device");
        let at = link.clone();
        let stop = Arc::new(AtomicBool::new(false));
        let (tx, rx) = std::sync::mpsc::channel();
        let flag = stop.clone();
        let thread = std::thread::Builder::new()
            .name("emulator".into())
            .spawn(move || {
                body(
                    at,
                    &flag,
                    Box::new(move || {
                        let _ = tx.send(());
                    }),
                )
            })?;
        let failed = match rx.recv_timeout(Duration::from_secs(10)) {
            Ok(()) => {
                return Ok(Emulator {
                    stop,
                    thread: Some(thread),
                    dir,
                    link,
                })
            }
            Err(RecvTimeoutError::Disconnected) => match thread.join() {
                Ok(Err(e)) => e,
                _ => std::io::Error::other("the emulator ended before linking its line"),
            },
            Err(RecvTimeoutError::Timeout) => {
                stop.store(true, Ordering::Relaxed);
                std::io::Error::other("the emulator did not link its line within 10 s")
            }
        };
        let _ = std::fs::remove_dir_all(&dir);
        Err(failed)
    }

    /// Where the emulated device is linked: a cfg's `port`.
    pub fn link(&self) -> &Path {
        &self.link
    }

    /// Stops the emulator and returns what its body returned.
    ///
    /// # Errors
    ///
    /// The body's error, or a panic in it.
    pub fn stop(mut self) -> std::io::Result<T> {
        self.stop.store(true, Ordering::Relaxed);
        match self.thread.take().map(JoinHandle::join) {
            Some(Ok(r)) => r,
            _ => Err(std::io::Error::other("the emulator thread panicked")),
        }
    }
}

impl<T> Drop for Emulator<T> {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}
