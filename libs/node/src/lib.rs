//! The runtime every Troupe driver runs on.
//!
//! - [`args`]: the Zenoh flags every process shares ([`ZenohArgs`]) and logging;
//! - [`Section`]: a driver's `.cfg` section (provides, requires, options);
//! - [`Driver`]: the trait a Player driver implements, with its [`Event`]s;
//! - [`Ctx`]: what a driver may do inside a hook (publish, subscribe,
//!   command, request, read the [`Clock`]);
//! - [`run`]/[`spawn`]: the Zenoh-backed runtime (liveliness per provided
//!   device, latest-value queryables, request queryables, sim clock, signals);
//! - [`process`]: how a process lives and dies (stop signals, tied to its
//!   launcher) for the clients and tools that are not drivers;
//! - [`syntax`]: the lexical grammar of Player's .cfg and Stage's world files;
//! - [`testing::Harness`]: the same driver, driven by hand without the network.
//!
//! Depends on troupe-msgs and Zenoh; never on a node crate.
#![warn(missing_docs)]

pub mod args;
mod clock;
mod ctx;
mod driver;
mod error;
mod event;
mod inbox;
mod mapfetch;
mod net;
pub mod process;
mod ros2;
mod runtime;
mod section;
mod setup;
pub mod syntax;
pub mod testing;

pub use args::{init_logging, locators, viewer_of, Mode, ZenohArgs, DEFAULT_ROUTER};
pub use clock::Clock;
pub use ctx::{Ctx, Waker, REQUEST_TIMEOUT};
pub use driver::{Driver, Unit};
pub use error::{BoxError, NodeError, RequestError, Result};
pub use event::{Event, Reply, Request, RequestId, Responder, Sample};
pub use inbox::spin_until;
pub use mapfetch::MapFetch;
pub use net::{ask, wait_live};
pub use ros2::{Ros2, Ros2Args, Ros2Settings, DEFAULT_NAMESPACE as ROS2_NAMESPACE};
pub use runtime::{check, run, spawn, NodeConfig, NodeHandle, Stop, Unused, MAX_DEVICES};
pub use section::{NoOptions, Section, Slot, Switch};
pub use setup::setup_answers;
pub use zenoh;
