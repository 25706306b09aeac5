//! The threads of hardware drivers and of device emulators.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, Sender};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// A driver's line thread: it takes orders of type `O` and can be cut
/// short. The body receives the orders and an abort flag for its
/// [`crate::Link`]s.
#[derive(Debug)]
pub struct LineThread<O> {
    orders: Sender<O>,
    abort: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl<O: Send + 'static> LineThread<O> {
    /// Starts `body` on a thread called `name`.
    ///
    /// # Errors
    ///
    /// When the thread cannot be started.
    pub fn spawn(
        name: &str,
        body: impl FnOnce(Receiver<O>, Arc<AtomicBool>) + Send + 'static,
    ) -> std::io::Result<Self> {
        let (orders, rx) = std::sync::mpsc::channel();
        let abort = Arc::new(AtomicBool::new(false));
        let flag = abort.clone();
        let thread = std::thread::Builder::new()
            .name(name.into())
            .spawn(move || body(rx, flag))?;
        Ok(LineThread {
            orders,
            abort,
            thread: Some(thread),
        })
    }

    /// Queues an order; false when the thread has ended.
    pub fn send(&self, order: O) -> bool {
        self.orders.send(order).is_ok()
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

/// How a session with a device ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ended {
    /// The driver is stopping: no more sessions.
    Stopped,
    /// The device failed or went away: try again after the delay.
    Failed,
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
/// [`Emulator::spawn`] returns once the emulated device is linked.
#[derive(Debug)]
pub struct Emulator<T> {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<std::io::Result<T>>>,
}

/// What an emulator's body calls once its device can be opened.
pub type Linked = Box<dyn FnOnce() + Send>;

impl<T: Send + 'static> Emulator<T> {
    /// Runs `body(stop, linked)` on a thread and waits (10 s at most) until
    /// it calls `linked`.
    ///
    /// # Errors
    ///
    /// The body's own error when it ends before linking; a timeout.
    pub fn spawn(
        body: impl FnOnce(&AtomicBool, Linked) -> std::io::Result<T> + Send + 'static,
    ) -> std::io::Result<Self> {
        let stop = Arc::new(AtomicBool::new(false));
        let (tx, rx) = std::sync::mpsc::channel();
        let flag = stop.clone();
        let thread = std::thread::Builder::new()
            .name("emulator".into())
            .spawn(move || {
                body(
                    &flag,
                    Box::new(move || {
                        let _ = tx.send(());
                    }),
                )
            })?;
        match rx.recv_timeout(Duration::from_secs(10)) {
            Ok(()) => Ok(Emulator {
                stop,
                thread: Some(thread),
            }),
            Err(RecvTimeoutError::Disconnected) => match thread.join() {
                Ok(Err(e)) => Err(e),
                _ => Err(std::io::Error::other(
                    "the emulator ended before linking its line",
                )),
            },
            Err(RecvTimeoutError::Timeout) => {
                stop.store(true, Ordering::Relaxed);
                Err(std::io::Error::other(
                    "the emulator did not link its line within 10 s",
                ))
            }
        }
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
    }
}
