//! The Driver trait, and how its options are read.

use std::fmt;

use serde::de::DeserializeOwned;

use crate::ctx::Ctx;
use crate::error::Result;
use crate::event::{Event, Request};
use crate::section::Section;

/// A Player driver, run as one node process by the runtime.
///
/// The runtime owns the session, the loop, signals and logging; a driver only
/// reacts to [`Event`]s through its hooks and talks to the world through
/// [`Ctx`]. Hooks are plain synchronous calls made one at a time, so a
/// driver needs no locks; a hook must not block for long (use a tick or a
/// request whose reply arrives as an event instead of waiting). They run on
/// the driver's own thread, save requests that find the driver idle (see
/// [`Driver::quick`]).
pub trait Driver: Sized + Send + 'static {
    /// The Player driver name (`"sicklms200"`, `"rangertolaser"`…).
    const NAME: &'static str;

    /// Typed options under Player's names; `Default` gives Player's defaults.
    type Options: DeserializeOwned + Default + fmt::Debug;

    /// Options that Player reads as lengths or angles (`ReadLength`,
    /// `ReadAngle`, `ReadTupleLength`…): the `.cfg` translator scales them by
    /// the file's `unit_length`/`unit_angle` so that options arrive in metres
    /// and radians.
    const UNITS: &'static [(&'static str, Unit)] = &[];

    /// True for the driver that is the simulation clock (Stage): its node's
    /// clock is set by the driver through [`Ctx::set_time`] and published on
    /// `sim/clock`, instead of following wall time.
    const CLOCK_SOURCE: bool = false;

    /// Builds the driver from its section and options.
    ///
    /// Called once, before any network activity. Fail here on anything wrong
    /// with the section (a missing `requires`, a bad option value): the error
    /// is reported and the node exits without having declared any device.
    fn new(section: &Section, options: Self::Options) -> Result<Self>;

    /// Starts the driver.
    ///
    /// Called once, after every required device is live and the provided
    /// devices' command and request routes are declared, and before any
    /// event. Subscribe to inputs, set a tick, send first requests here. The
    /// provided devices are announced (liveliness) when `setup` returns `Ok`.
    fn setup(&mut self, ctx: &mut Ctx) -> Result<()> {
        let _ = ctx;
        Ok(())
    }

    /// Handles one event. Called for each event in arrival order.
    ///
    /// Returning [`crate::NodeError::Decode`] is not fatal: the runtime logs
    /// and counts the malformed input and goes on. Any other error stops the
    /// node (and the supervisor may restart it).
    fn on_event(&mut self, ctx: &mut Ctx, event: Event) -> Result<()>;

    /// True when `request`'s hook returns quickly (the default, as every
    /// hook should), so that the runtime may run it at once on the thread
    /// that received it while the driver is idle with nothing queued: the
    /// answer then skips a thread wake. Return false for a request whose
    /// hook does long work (stepping a simulation, planning a path); it
    /// then always waits its turn on the driver's thread. Either way hooks
    /// run one at a time, in arrival order.
    fn quick(request: &Request) -> bool {
        let _ = request;
        true
    }

    /// Stops the driver: stop the motors, close the device.
    ///
    /// Called once on SIGINT/SIGTERM or after a fatal error, before the
    /// session closes, so what it publishes still goes out.
    fn shutdown(&mut self, ctx: &mut Ctx) -> Result<()> {
        let _ = ctx;
        Ok(())
    }
}

/// How the `.cfg` translator converts an option to SI units.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Unit {
    /// A length: scaled by `unit_length` (default metres).
    Length,
    /// An angle: scaled by `unit_angle` (default degrees).
    Angle,
    /// A tuple whose elements have these units, e.g. a pose `[Length, Length, Angle]`.
    Tuple(&'static [Unit]),
    /// A tuple of any length, every element a length.
    Lengths,
    /// A tuple of any length, every element an angle.
    Angles,
    /// A file name (Player's `ReadFilename`): a relative path is made
    /// absolute against the directory of the `.cfg` that names it.
    Path,
}
