//! The queue between Zenoh's callbacks and the driver's thread.
//!
//! Data and commands are coalesced: a new sample replaces a queued, not yet
//! handled sample of the same device and schema (Player's "replace" rule), so
//! a slow driver always works on fresh data instead of a growing backlog.
//! Requests and replies are never coalesced or dropped.

use std::collections::VecDeque;
use std::sync::{Condvar, Mutex, MutexGuard};
use std::time::Instant;

use crate::driver::{Event, Sample};

#[derive(Default)]
struct State {
    events: VecDeque<Event>,
    shutdown: bool,
    replaced: u64,
}

/// What [`Inbox::pop`] found.
pub(crate) enum Popped {
    Event(Event),
    Timeout,
    Shutdown,
}

#[derive(Default)]
pub(crate) struct Inbox {
    state: Mutex<State>,
    ready: Condvar,
}

impl Inbox {
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
        drop(st);
        self.ready.notify_one();
    }

    pub(crate) fn shutdown(&self) {
        self.lock().shutdown = true;
        self.ready.notify_all();
    }

    /// Samples replaced by newer ones before the driver saw them.
    pub(crate) fn replaced(&self) -> u64 {
        self.lock().replaced
    }

    /// The next event, waiting until `deadline` (forever if `None`).
    pub(crate) fn pop(&self, deadline: Option<Instant>) -> Popped {
        let mut st = self.lock();
        loop {
            if st.shutdown {
                return Popped::Shutdown;
            }
            if let Some(e) = st.events.pop_front() {
                return Popped::Event(e);
            }
            st = match deadline {
                None => self.ready.wait(st).unwrap_or_else(|p| p.into_inner()),
                Some(d) => {
                    let now = Instant::now();
                    if now >= d {
                        return Popped::Timeout;
                    }
                    self.ready
                        .wait_timeout(st, d - now)
                        .unwrap_or_else(|p| p.into_inner())
                        .0
                }
            };
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
        assert!(matches!(inbox.pop(None), Popped::Event(Event::Tick)));
        assert!(matches!(inbox.pop(Some(Instant::now())), Popped::Timeout));
        inbox.shutdown();
        assert!(matches!(inbox.pop(None), Popped::Shutdown));
    }
}
