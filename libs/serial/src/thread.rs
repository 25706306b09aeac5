//! The thread a hardware driver runs its line on.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, Sender};
use std::sync::Arc;
use std::thread::JoinHandle;

/// A driver's line thread: it takes orders of type `O` and can be cut
/// short. The body receives the orders and an abort flag that long waits
/// should check.
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
