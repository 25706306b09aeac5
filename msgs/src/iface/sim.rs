//! The simulation clock (`sim/clock`), published by the simulator.

use serde::{Deserialize, Serialize};

use crate::message;

/// Simulation time, published on `sim/clock` every simulation step.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Clock {
    /// Seconds since the simulation started.
    pub time: f64,
}
message!(Clock, "sim/clock@1");
