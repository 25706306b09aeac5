//! `troupe bridge`: the bridge as a process of its own, serving robot
//! ports or (`--import`) bringing a Player server's devices in.

use std::io::Write;
use std::net::{IpAddr, SocketAddr};

use anyhow::Context;
use clap::Args;
use troupe_node::ZenohArgs;

use crate::{Bridge, Config, Port};

/// Flags of `troupe bridge`.
#[derive(Debug, Args)]
pub struct BridgeArgs {
    /// Robot ports to serve, like `player -p`: `6665`, or `6665=ADDR:PORT`
    /// to listen elsewhere (port 0 = any free port). Repeat for more robots.
    #[arg(
        short = 'p',
        long = "port",
        value_name = "ROBOT[=ADDR:PORT]",
        default_value = "6665"
    )]
    pub ports: Vec<String>,

    /// Address the robot ports listen on. Player clients have no
    /// authentication: open other addresses only on a trusted network.
    #[arg(long, value_name = "ADDR", default_value = "127.0.0.1")]
    pub bind: IpAddr,

    /// Accept Player clients only from this network or address (repeatable,
    /// e.g. `--allow 10.1.0.0/16 --allow 10.2.0.7`); others are closed
    /// before the banner. Default: anyone who reaches --bind.
    #[arg(long, value_name = "CIDR", value_parser = crate::parse_network)]
    pub allow: Vec<crate::IpNetwork>,

    /// Data messages a client's queue holds before dropping (Player's 1024).
    #[arg(long, value_name = "N", default_value_t = crate::queue::DEFAULT_MAXLEN)]
    pub queue_len: usize,

    /// Clients each robot port serves at once; more are closed before the
    /// banner (and counted). A client that sends nothing for 30 s after
    /// connecting, takes over 30 s to send one message, or reads nothing
    /// for 30 s while output waits is dropped.
    #[arg(long, value_name = "N", default_value_t = crate::DEFAULT_MAX_CLIENTS,
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..))]
    pub max_clients: usize,

    /// The other way round: connect to the Player server at HOST:PORT as a
    /// client and publish its devices on Troupe's keys (commands sent to them
    /// go back to the server), so a robot still running Player joins the
    /// fleet. Serves no port.
    #[arg(
        long,
        value_name = "HOST:PORT",
        conflicts_with_all = ["ports", "bind", "queue_len", "allow", "max_clients"]
    )]
    pub import: Option<String>,

    /// With --import: publish the devices as this robot instead of the
    /// server's own number (two servers both on port 6665).
    #[arg(long = "as", value_name = "ROBOT", requires = "import")]
    pub as_robot: Option<u32>,
}

/// Parses `6665` or `6665=127.0.0.1:0`.
fn port(spec: &str, bind: IpAddr) -> anyhow::Result<Port> {
    let (robot, listen) = match spec.split_once('=') {
        None => (spec, None),
        Some((r, a)) => (r, Some(a)),
    };
    let robot: u32 = robot
        .trim()
        .parse()
        .with_context(|| format!("robot port `{robot}` in `{spec}` is not a number"))?;
    let listen = match listen {
        None => SocketAddr::new(
            bind,
            u16::try_from(robot).with_context(|| {
                format!("robot {robot} is not a TCP port; use {robot}=ADDR:PORT")
            })?,
        ),
        Some(a) => a
            .trim()
            .parse()
            .with_context(|| format!("`{a}` in `{spec}` is not ADDR:PORT (e.g. 127.0.0.1:0)"))?,
    };
    Ok(Port { robot, listen })
}

/// `troupe bridge`: serves robot ports, or with `--import` brings a Player
/// server's devices in. Either way a Zenoh peer, as the recorder is: the
/// router introduces it to the drivers, and their data and answers come
/// from them directly, not through the router's process.
pub fn run(a: BridgeArgs, z: &ZenohArgs) -> anyhow::Result<()> {
    let ports = match a.import {
        Some(_) => Vec::new(),
        None => a
            .ports
            .iter()
            .map(|s| port(s, a.bind))
            .collect::<anyhow::Result<Vec<_>>>()?,
    };
    troupe_node::process::supervised()?;
    let Some((rt, mut signals, session)) =
        troupe_node::process::session_runtime(z, 2, troupe_node::Mode::Peer)?
    else {
        return Ok(());
    };
    // A peer's first listing of the ports is a client's: whole at once (see
    // Config::lister); with --reconnect it waits for the router too, and a
    // signal still stops it. A bridge joined as a client (`--mode client`,
    // as in containers) lists on its own session.
    let peer = session
        .config()
        .get_typed::<Option<String>>("mode")
        .is_ok_and(|m| m.as_deref() == Some("peer"));
    let lister = if peer && a.import.is_none() {
        tracing::debug!("joined as a peer: the first listing goes through a client session");
        let open = z.open_in_background(troupe_node::Mode::Client);
        match rt.block_on(signals.unless_stopped(open))? {
            Some(s) => Some(s),
            None => return Ok(()),
        }
    } else {
        None
    };
    let stop = async move { signals.recv().await };
    if let Some(server) = &a.import {
        rt.block_on(crate::import::run(
            session,
            server,
            &crate::import::Select::All {
                as_robot: a.as_robot,
            },
            stop,
        ))?;
        return Ok(());
    }
    rt.block_on(async move {
        let cfg = Config {
            ports,
            maxlen: a.queue_len.max(1),
            allow: a.allow,
            max_clients: a.max_clients,
            lister,
            ..Config::default()
        };
        let bridge = Bridge::bind(session, cfg).await?;
        announce(&bridge);
        bridge.run(stop).await;
        tracing::info!("bridge stopped");
        anyhow::Ok(())
    })
}

/// `troupe bridge: robot 6665 on ADDR:PORT` on stdout for each robot port,
/// for scripts and tests that let the ports be chosen.
pub fn announce(bridge: &Bridge) {
    let mut out = std::io::stdout().lock();
    for (robot, addr) in bridge.local_addrs() {
        let _ = writeln!(out, "troupe bridge: robot {robot} on {addr}");
    }
    let _ = out.flush();
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn port_specs() {
        let lo: IpAddr = "127.0.0.1".parse().unwrap();
        assert_eq!(
            port("6665", lo).unwrap(),
            Port {
                robot: 6665,
                listen: "127.0.0.1:6665".parse().unwrap()
            }
        );
        assert_eq!(
            port("6666=0.0.0.0:0", lo).unwrap().listen,
            "0.0.0.0:0".parse().unwrap()
        );
        let e = port("x", lo).unwrap_err().to_string();
        assert!(e.contains("`x`"), "{e}");
        let e = format!("{:#}", port("70000", lo).unwrap_err());
        assert!(e.contains("70000=ADDR:PORT"), "{e}");
    }

    #[test]
    fn import_serves_no_port_so_it_refuses_one() {
        use clap::Parser;
        #[derive(Debug, Parser)]
        struct Bridge {
            #[command(flatten)]
            args: BridgeArgs,
        }
        let parse = |args: &[&str]| Bridge::try_parse_from(args);
        assert!(parse(&["bridge", "--import", "robot7:6665"]).is_ok());
        assert!(parse(&["bridge", "-p", "6666"]).is_ok());
        let e = parse(&["bridge", "--import", "robot7:6665", "-p", "6666"])
            .unwrap_err()
            .to_string();
        assert!(e.contains("--port"), "{e}");
    }
}
