//! Troupe's launcher: what `troupe launch robot.cfg` does, as a library.
//!
//! - [`cfg`]: Player's `.cfg` language, parsed with file:line:column errors;
//! - [`plan`]: launch plans, one node per driver section, each driver's
//!   `requires` wired to another's `provides`, checked and ordered;
//! - [`catalog`]: the drivers a launcher can start, handed to it by whoever
//!   links them (the `troupe` binary links them all);
//! - [`supervisor`]: runs a plan, one child process per node, with the
//!   embedded router and the Player bridge for the plan's robots;
//! - [`node`]: `troupe node`, the other end of the supervisor's children;
//! - [`router`]: `troupe router`, a Zenoh router alone for a fleet's host.
//!
//! Depends on troupe-msgs, troupe-node and troupe-bridge (the launcher
//! serves Player clients itself); never on a driver or a tool.

pub mod catalog;
pub mod cfg;
pub mod node;
pub mod plan;
pub mod router;
pub mod supervisor;
