//! Player-style client proxies, so the Player tutorials translate line by line.
//!
//! ```no_run
//! use troupe_client::{Client, LaserProxy, Position2dProxy};
//! # fn main() -> Result<(), troupe_client::ClientError> {
//! let robot = Client::connect(&Default::default(), 6665)?; // PlayerClient robot("localhost", 6665)
//! let pp = Position2dProxy::new(&robot, 0)?;               // Position2dProxy pp(&robot, 0)
//! let lp = LaserProxy::new(&robot, 0)?;
//! pp.set_motor_enable(true)?;
//! for _ in 0..100 {
//!     robot.read()?;                                       // robot.Read()
//!     let turn = if lp.min_range().unwrap_or(10.0) < 0.5 { 0.5 } else { 0.0 };
//!     pp.set_speed(0.3, turn)?;                            // pp.SetSpeed(0.3, turn)
//! }
//! # Ok(()) }
//! ```
//!
//! The API is blocking, as libplayerc++'s is. Each proxy keeps the latest
//! sample of its device, updated in the background; [`Client::read`] waits
//! until some proxy got new data. Requests wait for their answer (5 s, as
//! libplayerc) and turn a refusal into [`ClientError::Nack`] with its reason.
#![warn(missing_docs)]

mod client;
pub mod na;
mod proxies;

pub use client::{now, Client, ClientError, Result};
pub use nalgebra;
pub use proxies::*;
pub use troupe_msgs as msgs;
