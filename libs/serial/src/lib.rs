//! Serial lines for Troupe's hardware drivers and their device emulators.
//!
//! - [`Port`]: a serial device (`/dev/ttyUSB0`, or a pseudo-terminal's
//!   slave) in raw 8N1 (or 8N2) mode at any baud rate the line takes, with reads that time out
//!   and a clear [`LineError::Lost`] when the device goes away.
//! - [`Framer`] and [`Codec`]: check-then-parse framing over a byte stream
//!   that resynchronises on noise and counts what it skipped.
//! - [`Pty`]: a pseudo-terminal whose slave is linked at a path, so that a
//!   `.cfg` names an emulated device as `port "/tmp/laser"`.
//! - [`Pacer`]: writes at the speed a real line would carry the bytes.
//! - [`arcos`]: the packet framing of Pioneer and Erratic controllers.
//! - [`LineThread`], [`run_sessions`], [`end_session`] and [`Link`]: a
//!   hardware driver's line thread — orders in, updates out, sessions with
//!   the device, reconnection, a prompt stop;
//!   [`CommandWatchdog`]: the robot drivers' `watchdog` option.
//! - [`EmuLine`] and [`Emulator`]: the device end of an emulated line, and
//!   an emulator on a thread for tests and benchmarks.
//! - [`capture`]: what crossed a line, both ways, as text; a recorder for
//!   emulators and a replay that checks a driver against a capture.
//!
//! Every call blocks for at most the time it is given: a driver runs its
//! device on a thread of its own and hands results to its event loop.

pub mod arcos;
pub mod capture;
mod emu;
mod faults;
mod framer;
mod link;
mod port;
mod pty;
mod thread;
mod watchdog;

pub use emu::{EmuLine, LineEvent, LineOptions};
pub use faults::{Faults, Injected};
pub use framer::{Codec, Decoded, FrameStats, Framer, Skipped};
pub use link::{Link, LinkError, SessionError};
pub use port::{LineError, Port, StopBits, BAUD_RATES};
pub use pty::{Pacer, Pty};
pub use thread::{
    end_session, recv_where, run_sessions, Emulator, Ended, HeldLine, LineThread, Linked, Reports,
};
pub use watchdog::CommandWatchdog;
