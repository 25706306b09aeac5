//! The queue between Zenoh's callbacks and the driver's thread.
//!
//! Data and commands are coalesced: a new sample replaces a queued, not yet
//! handled sample of the same device and schema (Player's "replace" rule), so
//! a slow driver always works on fresh data instead of a growing backlog.
//! Requests and replies are never coalesced or dropped.
//!
//! The inbox also knows whether a hook is running (`busy`): the driver's
//! thread marks it when it pops, and a Zenoh callback may [`Inbox::claim`] an
//! idle driver with nothing queued to run a request's hook at once, on its
//! own thread. Hooks so stay one at a time and in arrival order.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use crate::event::{Event, Sample};

#[derive(Default)]
struct State {
    events: VecDeque<Event>,
    shutdown: bool,
    replaced: u64,
    /// A hook is running, on the driver's thread or a claiming one.
    busy: bool,
    /// A hook run by a claiming thread changed what the loop must look at
    /// (readiness, tick, stop, an error).
    recheck: bool,
    /// The driver's thread waits for the condition variable.
    waiting: bool,
}

/// What [`Inbox::pop`] found.
pub(crate) enum Popped {
    Event(Event),
    Timeout,
    /// A hook ran elsewhere and left the loop something to look at.
    Recheck,
    Shutdown,
}

/// Calls `done` on a spinning core until it says true (then true) or
/// `until` has passed (then false): how a node given `--spin` waits
/// before it sleeps.
pub fn spin_until(until: Instant, mut done: impl FnMut() -> bool) -> bool {
    let mut k = 0u32;
    while !done() {
        std::hint::spin_loop();
        // The clock now and then: reading it costs more than a poll.
        k = k.wrapping_add(1);
        if k % 64 == 0 && Instant::now() >= until {
            return false;
        }
    }
    true
}

#[derive(Default)]
pub(crate) struct Inbox {
    state: Mutex<State>,
    ready: Condvar,
    /// How long [`Inbox::pop`] polls for an event before it sleeps (see
    /// `ZenohArgs::spin`); zero: it sleeps at once.
    spin: Duration,
    /// Bumped by every change a polling [`Inbox::pop`] must look at.
    changes: AtomicU64,
}

impl Inbox {
    /// An inbox whose driver is busy (starting) until [`Inbox::idle`].
    pub(crate) fn busy() -> Self {
        let inbox = Inbox::default();
        inbox.lock().busy = true;
        inbox
    }

    /// This inbox, polling `spin` for each event before it sleeps.
    pub(crate) fn spinning(self, spin: Duration) -> Self {
        Inbox { spin, ..self }
    }

    /// Tells a polling [`Inbox::pop`] to look again: called after each
    /// change to the state.
    fn changed(&self) {
        self.changes.fetch_add(1, Ordering::Release);
    }

    /// Polls until something changes, at most `spin` and not past
    /// `deadline`: a thread that sleeps takes tens of microseconds to wake,
    /// most of a round trip on a host (ARCHITECTURE.md, "What a hop costs").
    fn poll(&self, seen: u64, deadline: Option<Instant>) {
        let until = Instant::now() + self.spin;
        let until = deadline.map_or(until, |d| d.min(until));
        spin_until(until, || self.changes.load(Ordering::Acquire) != seen);
    }

    fn lock(&self) -> MutexGuard<'_, State> {
        // A panic in another thread while holding the lock leaves plain data behind.
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    pub(crate) fn push(&self, event: Event) {
        let mut st = self.lock();
        let same = |a: &Sample, b: &Sample| a.key == b.key && a.same_schema(b);
        let slot = match &event {
            Event::Data(new) => st
                .events
                .iter()
                .position(|e| matches!(e, Event::Data(old) if same(old, new))),
            Event::Command(new) => st
                .events
                .iter()
                .position(|e| matches!(e, Event::Command(old) if same(old, new))),
            Event::Wake if st.events.iter().any(|e| matches!(e, Event::Wake)) => return,
            _ => None,
        };
        match slot {
            Some(i) => {
                st.events[i] = event;
                st.replaced += 1;
            }
            None => st.events.push_back(event),
        }
        self.changed();
        let waiting = st.waiting;
        drop(st);
        if waiting {
            self.ready.notify_one();
        }
    }

    pub(crate) fn shutdown(&self) {
        self.lock().shutdown = true;
        self.changed();
        self.ready.notify_all();
    }

    /// Samples replaced by newer ones before the driver saw them.
    pub(crate) fn replaced(&self) -> u64 {
        self.lock().replaced
    }

    /// The next event, waiting until `deadline` (forever if `None`), once
    /// no hook is running; the caller is then the one running hooks until
    /// it calls [`Inbox::idle`]. `Shutdown` comes once no hook is running.
    ///
    /// With a spin (see [`Inbox::spinning`]), it first polls that long for
    /// an event, once a call, and only then sleeps.
    pub(crate) fn pop(&self, deadline: Option<Instant>) -> Popped {
        let mut st = self.lock();
        let mut spun = self.spin.is_zero();
        loop {
            if !st.busy {
                if st.shutdown {
                    return Popped::Shutdown;
                }
                let found = if std::mem::take(&mut st.recheck) {
                    Some(Popped::Recheck)
                } else if let Some(e) = st.events.pop_front() {
                    Some(Popped::Event(e))
                } else if deadline.is_some_and(|d| Instant::now() >= d) {
                    Some(Popped::Timeout)
                } else {
                    None
                };
                if let Some(p) = found {
                    st.busy = true;
                    return p;
                }
            }
            if !spun {
                spun = true;
                let seen = self.changes.load(Ordering::Acquire);
                drop(st);
                self.poll(seen, deadline);
                st = self.lock();
                continue;
            }
            st.waiting = true;
            st = match deadline {
                Some(d) if !st.busy => {
                    let left = d.saturating_duration_since(Instant::now());
                    self.ready
                        .wait_timeout(st, left)
                        .unwrap_or_else(|p| p.into_inner())
                        .0
                }
                _ => self.ready.wait(st).unwrap_or_else(|p| p.into_inner()),
            };
            st.waiting = false;
        }
    }

    /// Marks the driver busy when it is idle with nothing queued and the
    /// inbox is open: the caller may then run one hook, and must call
    /// [`Inbox::idle`] after.
    pub(crate) fn claim(&self) -> bool {
        let mut st = self.lock();
        let free = !st.busy && !st.shutdown && st.events.is_empty();
        st.busy |= free;
        free
    }

    /// Ends what [`Inbox::pop`] or [`Inbox::claim`] started; `recheck`
    /// makes the driver's thread look at its state before the next event.
    pub(crate) fn idle(&self, recheck: bool) {
        let mut st = self.lock();
        st.busy = false;
        st.recheck |= recheck;
        self.changed();
        let waiting = st.waiting;
        drop(st);
        // The driver's thread may be waiting for the hook to end.
        if waiting {
            self.ready.notify_one();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use troupe_msgs::{encode, laser, Device, Interface};

    fn scan(id: u32) -> Event {
        let d = Device::new(6665, Interface::Laser, 0);
        let bytes = encode(
            &laser::Scan {
                id,
                ..Default::default()
            },
            0.0,
        );
        Event::Data(Sample::new(d, "robot/6665/laser/0".into(), bytes))
    }

    #[test]
    fn newer_data_replaces_queued_data_of_the_same_schema() {
        let inbox = Inbox::default();
        inbox.push(scan(1));
        inbox.push(Event::Tick);
        inbox.push(scan(2));
        assert_eq!(inbox.replaced(), 1);
        let Popped::Event(Event::Data(s)) = inbox.pop(None) else {
            panic!("expected data first")
        };
        assert_eq!(s.decode::<laser::Scan>().unwrap().msg.id, 2);
        inbox.idle(false);
        assert!(matches!(inbox.pop(None), Popped::Event(Event::Tick)));
        inbox.idle(false);
        assert!(matches!(inbox.pop(Some(Instant::now())), Popped::Timeout));
        inbox.idle(false);
        inbox.shutdown();
        assert!(matches!(inbox.pop(None), Popped::Shutdown));
    }

    #[test]
    fn only_an_idle_driver_with_nothing_queued_is_claimed() {
        let inbox = Inbox::default();
        assert!(inbox.claim(), "idle and empty");
        assert!(!inbox.claim(), "a hook is already running");
        inbox.idle(false);
        inbox.push(Event::Tick);
        assert!(!inbox.claim(), "a queued event goes first");
        assert!(matches!(inbox.pop(None), Popped::Event(Event::Tick)));
        assert!(!inbox.claim(), "the driver's thread runs a hook");
        inbox.idle(false);
        assert!(inbox.claim());
        inbox.idle(true);
        assert!(matches!(inbox.pop(None), Popped::Recheck));
        inbox.idle(false);
        inbox.shutdown();
        assert!(!inbox.claim(), "a closed inbox runs no more hooks");
    }

    /// A spin far longer than any test: a poll that ended only when it ran
    /// out would make these take minutes.
    const LONG: Duration = Duration::from_secs(600);

    #[test]
    fn a_polling_pop_ends_with_what_comes_while_it_polls() {
        let inbox = std::sync::Arc::new(Inbox::default().spinning(LONG));
        for want in [1, 2] {
            let pusher = {
                let inbox = inbox.clone();
                std::thread::spawn(move || inbox.push(scan(want)))
            };
            let t0 = Instant::now();
            let Popped::Event(Event::Data(s)) = inbox.pop(None) else {
                panic!("expected the scan")
            };
            assert_eq!(s.decode::<laser::Scan>().unwrap().msg.id, want);
            assert!(t0.elapsed() < LONG / 10, "the poll ran out instead");
            inbox.idle(false);
            pusher.join().unwrap();
        }
        let stopper = {
            let inbox = inbox.clone();
            std::thread::spawn(move || inbox.shutdown())
        };
        assert!(matches!(inbox.pop(None), Popped::Shutdown));
        stopper.join().unwrap();
    }

    #[test]
    fn a_polling_pop_keeps_its_deadline() {
        let inbox = Inbox::default().spinning(LONG);
        let t0 = Instant::now();
        let deadline = t0 + Duration::from_millis(20);
        assert!(matches!(inbox.pop(Some(deadline)), Popped::Timeout));
        assert!(Instant::now() >= deadline);
        assert!(t0.elapsed() < LONG / 10, "polled past the deadline");
    }

    #[test]
    fn the_driver_thread_waits_for_a_claimed_hook_to_end() {
        let inbox = std::sync::Arc::new(Inbox::default());
        assert!(inbox.claim());
        inbox.push(Event::Tick);
        inbox.shutdown();
        let (tx, rx) = std::sync::mpsc::channel();
        let waiter = {
            let inbox = inbox.clone();
            std::thread::spawn(move || {
                let first = matches!(inbox.pop(None), Popped::Shutdown);
                tx.send(first).unwrap();
            })
        };
        // Nothing may come out while the claimed hook runs.
        assert!(rx
            .recv_timeout(std::time::Duration::from_millis(50))
            .is_err());
        inbox.idle(false);
        assert!(rx.recv().unwrap(), "shutdown once the hook ended");
        waiter.join().unwrap();
    }
}
