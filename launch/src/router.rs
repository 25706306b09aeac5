//! `troupe router`: a Zenoh router alone, for a host of a fleet; the one
//! `troupe launch` embeds is the same router inside the launcher.

use std::io::Write;

use clap::Args;
use troupe_node::zenoh::Wait;
use troupe_node::{Mode, ZenohArgs};

/// Flags of `troupe router` (the network flags are everyone's).
#[derive(Debug, Args)]
pub struct RouterArgs {}

/// `troupe router`: a Zenoh router until SIGINT/SIGTERM.
pub fn run(_: RouterArgs, z: &ZenohArgs) -> anyhow::Result<()> {
    if std::env::var_os(ZENOH_RUNTIME).is_none() {
        // Read once, when Zenoh starts its runtimes (below); no thread of
        // ours runs yet.
        std::env::set_var(ZENOH_RUNTIME, ROUTER_RUNTIME);
    }
    let mut z = z.clone();
    if z.listen.is_empty() && z.zenoh_config.is_none() {
        z.listen.push("tcp/[::]:7447".into());
    }
    let session = z.open(Mode::Router)?;
    let stop = troupe_node::process::stop_receiver()?;
    let list = troupe_node::locators(&session);
    // The first line on stdout is the contract for scripts and tests.
    let mut out = std::io::stdout().lock();
    writeln!(out, "troupe router listening on {}", list.join(" "))?;
    out.flush()?;
    drop(out);
    tracing::info!(zid = %session.zid(), "router up");
    let _ = stop.recv();
    tracing::info!("router stopping");
    session
        .close()
        .wait()
        .map_err(|e| anyhow::anyhow!("closing the router: {e}"))?;
    Ok(())
}

/// Zenoh reads the sizes of its thread pools from this variable.
const ZENOH_RUNTIME: &str = "ZENOH_RUNTIME";

/// A router's thread pools. Zenoh's default is two threads to read every
/// link; a host cut off from the network leaves full queues behind, and
/// messages that must not be dropped (declarations) wait on them for up to
/// 5 s on a reading thread. With two such waits no link is read: in a
/// fleet of seven containers every client's lease then ran out and all 28
/// devices left and came back, when only the cut-off host's 6 should have.
/// With eight readers only the cut-off host's devices leave (4 of 4 runs
/// before, 0 after).
const ROUTER_RUNTIME: &str =
    "(rx: (worker_threads: 8), tx: (worker_threads: 4), net: (worker_threads: 2))";
