//! The node's clock: wall time, simulation time, or a manual clock in tests.
//!
//! Drivers never read the system clock; they call [`crate::Ctx::now`], which
//! follows `sim/clock` when the node runs with `--sim-time`, so a whole stack
//! runs faster than real time under the simulator.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{SystemTime, UNIX_EPOCH};

#[derive(Debug)]
enum Source {
    Wall,
    /// Seconds as f64 bits, set by `sim/clock` samples or by a test.
    Set(AtomicU64),
}

/// A cheap, shareable clock. Cloning shares the time source.
#[derive(Debug, Clone)]
pub struct Clock(Arc<Source>);

impl Clock {
    /// Wall time: seconds since the Unix epoch, as Player stamps messages.
    pub fn wall() -> Self {
        Clock(Arc::new(Source::Wall))
    }

    /// A clock that only moves when [`Clock::set`] is called (sim time, tests).
    pub fn manual(start: f64) -> Self {
        Clock(Arc::new(Source::Set(AtomicU64::new(start.to_bits()))))
    }

    /// True when the time comes from [`Clock::set`] rather than the system.
    pub fn is_manual(&self) -> bool {
        matches!(*self.0, Source::Set(_))
    }

    /// The time now, in seconds.
    pub fn now(&self) -> f64 {
        match &*self.0 {
            Source::Wall => SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map(|d| d.as_secs_f64())
                .unwrap_or(0.0),
            Source::Set(t) => f64::from_bits(t.load(Ordering::Acquire)),
        }
    }

    /// Sets a manual clock; ignored by a wall clock.
    pub fn set(&self, time: f64) {
        if let Source::Set(t) = &*self.0 {
            t.store(time.to_bits(), Ordering::Release);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn manual_clock_moves_only_when_set() {
        let c = Clock::manual(1.5);
        let shared = c.clone();
        assert_eq!(c.now(), 1.5);
        shared.set(2.25);
        assert_eq!(c.now(), 2.25);
        assert!(Clock::wall().now() > 1.0e9);
    }
}
