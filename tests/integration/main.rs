#![allow(clippy::unwrap_used)]
//! Troupe's integration tests: several sessions in one process (`sessions`),
//! and several `troupe` processes (`process`). Each test has its own router on
//! an ephemeral loopback port and its own namespace, so they run in parallel.
//!
//! Run with `cargo test -p troupe-tests`.

mod act;
mod bridge;
mod bridge_devices;
mod docker;
mod docs;
mod hosts;
mod import;
mod launch;
mod logs;
mod nav;
mod player;
mod process;
mod python;
mod ros2;
mod serial;
mod sessions;
mod stage;
mod view;
