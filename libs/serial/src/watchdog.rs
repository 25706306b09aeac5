//! Troupe's `watchdog` option of the robot drivers.

use std::time::Duration;

/// Stops a robot whose client stopped commanding: when the last command
/// that set it moving is older than the limit, [`CommandWatchdog::expired`]
/// says so once (and logs why), and the driver sends a stop.
#[derive(Debug, Clone, Copy)]
pub struct CommandWatchdog {
    limit: Option<f64>,
    /// When the last command came, and whether it set the robot moving.
    last: Option<(f64, bool)>,
}

impl CommandWatchdog {
    /// A watchdog of `seconds` (0 or less: off).
    pub fn new(seconds: f64) -> Self {
        CommandWatchdog {
            limit: (seconds > 0.0).then_some(seconds),
            last: None,
        }
    }

    /// How often to check it (`None` when off).
    pub fn tick(&self) -> Option<Duration> {
        self.limit.map(|_| Duration::from_millis(100))
    }

    /// A velocity command came at `now`; `moving` when it is not a stop.
    pub fn commanded(&mut self, now: f64, moving: bool) {
        self.last = Some((now, moving));
    }

    /// True, once, when the robot was told to move longer than the limit ago.
    pub fn expired(&mut self, now: f64) -> bool {
        let (Some(limit), Some((at, true))) = (self.limit, self.last) else {
            return false;
        };
        if now - at <= limit {
            return false;
        }
        tracing::warn!("no velocity command for {limit:.1} s: stopping the robot (watchdog)");
        self.last = Some((now, false));
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fires_once_after_a_moving_command_goes_stale() {
        let mut w = CommandWatchdog::new(1.0);
        assert!(!w.expired(10.0), "nothing commanded yet");
        w.commanded(10.0, true);
        assert!(!w.expired(10.9));
        assert!(w.expired(11.1));
        assert!(!w.expired(20.0), "once");
        w.commanded(20.0, false);
        assert!(!w.expired(30.0), "a stop needs no watchdog");
        assert!(CommandWatchdog::new(0.0).tick().is_none());
    }
}
