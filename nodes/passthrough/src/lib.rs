//! Player's `passthrough` as a .cfg driver: devices of a running Player
//! server served as this robot's own, through the bridge's import.
//!
//! ```text
//! driver ( name "passthrough" requires [":192.168.1.15:6665:dio:0"] provides ["dio:0"] )
//! driver ( name "passthrough" provides ["laser:0"]
//!          remote_host "localhost" remote_port 6665 remote_index 0 access "r" )
//! ```
//!
//! | | |
//! |---|---|
//! | provides | the devices served here, any interface |
//! | requires | each one's remote device, `:HOST:PORT:INTERFACE:INDEX` (Player 3's form), in `provides` order; or a device of this stack (`6666:laser:0`, Player 3's local form) |
//! | options | `remote_host`, `remote_port` (override the host and port of every `requires`); without `requires`, Player 2's `remote_host` (localhost), `remote_port` (6665) and `remote_index` (0) name one remote device of the provided interface; `access` (`r`, `w`, `a`: read, as every client of Troupe's bridge, anyway) |
//!
//! # Behavior
//!
//! - The server's devices are taken as a libplayerc client takes them
//!   (banner, DEVLIST, DRIVERINFO, subscribe) and served under the provided
//!   addresses: data in, commands and requests out, the server's answers
//!   back (see `troupe_bridge::import`). One connection per server.
//! - A server that cannot be reached, or goes away, leaves its devices not
//!   live (their liveliness tokens withdrawn); the driver tries again every
//!   second and they are live again once it is back. The first failure is
//!   a warning, the attempts after it are debug lines with their count, and
//!   every connection made is logged with the server's banner.
//! - Player 3's local form (`requires ["6666:laser:0"]`, a device on
//!   this stack's network) relays without a Player hop: data, commands and
//!   requests (answers as they come) pass, and the provided device is live
//!   exactly while the required one is.
//! - With Troupe's `namespace "NS"`, the required devices are those of
//!   another fleet or stack on the same network, in Zenoh namespace NS: a
//!   second session in NS relays them as above (the plan wires nothing to
//!   them: they are not this stack's to start).

use std::time::Duration;

use serde::Deserialize;
use troupe_bridge::import::{self, Select};
use troupe_msgs::{Device, Interface};
use troupe_node::zenoh::sample::SampleKind;
use troupe_node::zenoh::Wait;
use troupe_node::{NodeConfig, NodeError, Result, Section, Unused, ZenohArgs};

/// Options, by Player's names; `remote` is what the plan makes of
/// `requires` addresses that name a host.
#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub struct Options {
    /// `HOST:PORT:INTERFACE:INDEX` of each provided device, in order.
    pub remote: Vec<String>,
    /// Overrides every remote device's host (Player 2: the only one's).
    pub remote_host: Option<String>,
    /// Overrides every remote device's port (Player 2: the only one's).
    pub remote_port: Option<u32>,
    /// Player 2: the remote device's index.
    pub remote_index: Option<u32>,
    /// Player 2: `r`, `w` or `a`.
    pub access: Option<String>,
    /// Troupe: the Zenoh namespace the required devices live in, when not
    /// this stack's.
    pub namespace: Option<String>,
    /// The required devices of another namespace (`6665:laser:0`), in
    /// order: what the plan makes of `requires` when `namespace` is given.
    pub elsewhere: Vec<String>,
}

/// Player's name for this driver.
pub const NAME: &str = "passthrough";

/// Each remote server (`HOST:PORT`) and what to take from it.
type Servers = Vec<(String, Vec<((Interface, u32), Device)>)>;

/// What a section passes through.
#[derive(Debug)]
enum Route {
    /// Devices of Player servers.
    Remote(Servers),
    /// Devices of this stack's network, or of the namespace named:
    /// (interface and index, from, as).
    Local(Vec<((Interface, u32), Device, Device)>, Option<String>),
}

fn bad(why: impl Into<String>) -> NodeError {
    NodeError::config(NAME, why)
}

/// `HOST:PORT:INTERFACE:INDEX`, split from the right (a host may hold colons).
fn parse_remote(text: &str) -> Result<(String, u32, Interface, u32)> {
    let mut parts = text.rsplitn(4, ':');
    let (index, iface, port, host) = (parts.next(), parts.next(), parts.next(), parts.next());
    let what = || {
        bad(format!(
            "`{text}` is not a remote device like :192.168.1.15:6665:laser:0"
        ))
    };
    let (Some(index), Some(iface), Some(port), Some(host)) = (index, iface, port, host) else {
        return Err(what());
    };
    let host = host.trim_start_matches(':');
    let iface = Interface::from_name(iface)
        .ok_or_else(|| bad(format!("`{text}`: no interface `{iface}`")))?;
    match (port.parse(), index.parse(), host.is_empty()) {
        (Ok(port), Ok(index), false) => Ok((host.to_owned(), port, iface, index)),
        _ => Err(what()),
    }
}

/// What a section passes through, and the options it gives that are not used.
fn routes(section: &Section) -> Result<(Route, Vec<String>)> {
    let (o, unused) = section.options::<Options>()?;
    let provided: Vec<Device> = section.provided().iter().map(|s| s.device).collect();
    if provided.is_empty() {
        return Err(bad("`provides` names no device"));
    }
    if let Some(a) = o.access.as_deref().filter(|a| !["r", "w", "a"].contains(a)) {
        return Err(bad(format!("access \"{a}\" is not r, w or a")));
    }
    let mut required: Vec<Device> = section.required().iter().map(|s| s.device).collect();
    for text in &o.elsewhere {
        let a: troupe_msgs::DevAddr = text.parse().map_err(|e| bad(format!("`{text}`: {e}")))?;
        required.push(a.device(section.robot));
    }
    if !o.elsewhere.is_empty() && o.namespace.is_none() {
        return Err(bad("`elsewhere` devices need the `namespace` they live in"));
    }
    if !required.is_empty() {
        if !o.remote.is_empty() || required.len() != provided.len() {
            return Err(bad(format!(
                "Mismatched number of entries in provides and requires ({} and {})",
                provided.len(),
                required.len() + o.remote.len()
            )));
        }
        let mut pairs = Vec::new();
        for (from, to) in required.iter().zip(&provided) {
            if from.interface != to.interface {
                return Err(bad(format!(
                    "{from} passed through as {to}: the interfaces must match"
                )));
            }
            pairs.push(((from.interface, from.index), *from, *to));
        }
        return Ok((Route::Local(pairs, o.namespace), unused));
    }
    let mut wanted = Vec::new();
    if o.remote.is_empty() {
        // Player 2's form: one device, named by options.
        let [local] = provided.as_slice() else {
            return Err(bad(
                "without `requires`, remote_host/remote_port/remote_index name one device: provide one",
            ));
        };
        let host = o.remote_host.clone().unwrap_or_else(|| "localhost".into());
        let port = o.remote_port.unwrap_or(troupe_msgs::DEFAULT_ROBOT);
        wanted.push((
            host,
            port,
            local.interface,
            o.remote_index.unwrap_or(0),
            *local,
        ));
    } else {
        if o.remote.len() != provided.len() {
            return Err(bad(format!(
                "Mismatched number of entries in provides and requires ({} and {})",
                provided.len(),
                o.remote.len()
            )));
        }
        for (text, local) in o.remote.iter().zip(&provided) {
            let (host, port, iface, index) = parse_remote(text)?;
            if iface != local.interface {
                return Err(bad(format!(
                    "`{text}` is a {iface}, passed through as {local}: the interfaces must match"
                )));
            }
            let host = o.remote_host.clone().unwrap_or(host);
            let port = o.remote_port.unwrap_or(port);
            wanted.push((host, port, iface, index, *local));
        }
    }
    let mut out: Servers = Vec::new();
    for (host, port, iface, index, local) in wanted {
        let server = format!("{host}:{port}");
        match out.iter_mut().find(|(s, _)| *s == server) {
            Some((_, pairs)) => pairs.push(((iface, index), local)),
            None => out.push((server, vec![((iface, index), local)])),
        }
    }
    Ok((Route::Remote(out), unused))
}

/// Checks a passthrough section.
///
/// # Errors
///
/// A section [`routes`] refuses.
pub fn check(section: &Section) -> Result<Unused> {
    let (_, options) = routes(section)?;
    Ok(Unused {
        options,
        requires: Vec::new(),
    })
}

/// Runs a passthrough section until SIGTERM/SIGINT.
///
/// # Errors
///
/// The section is refused, or the runtime or session cannot start.
pub fn run(section: Section, z: &ZenohArgs, _: &NodeConfig) -> Result<()> {
    let (route, unused) = routes(&section)?;
    for o in unused {
        tracing::warn!("option `{o}` is not used by driver `{NAME}`");
    }
    let started = troupe_node::process::session_runtime(z, 1, troupe_node::Mode::Client);
    let Some((rt, mut signals, session)) = started.map_err(|e| NodeError::Driver(e.into()))? else {
        return Ok(());
    };
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    rt.block_on(async move {
        let mut tasks = Vec::new();
        match route {
            Route::Remote(servers) => {
                for (server, pairs) in servers {
                    let (session, mut stop) = (session.clone(), stop_rx.clone());
                    tasks.push(tokio::spawn(async move {
                        serve(session, server, Select::Only(pairs), &mut stop).await;
                    }));
                }
            }
            Route::Local(pairs, namespace) => {
                // The required devices' side: this session, or one in
                // their namespace.
                let there = match &namespace {
                    None => session.clone(),
                    Some(ns) => {
                        let z = ZenohArgs {
                            namespace: Some(ns.clone()),
                            ..z.clone()
                        };
                        match z.open_in_background(troupe_node::Mode::Client).await {
                            Ok(s) => s,
                            Err(e) => {
                                tracing::error!("joining namespace `{ns}`: {e}");
                                return;
                            }
                        }
                    }
                };
                for (_, from, to) in pairs {
                    let (here, there) = (session.clone(), there.clone());
                    let stop = stop_rx.clone();
                    let from_ns = namespace.clone();
                    tasks.push(tokio::spawn(async move {
                        if let Err(e) = relay(here, there, from, to, stop).await {
                            let at = from_ns
                                .map(|ns| format!(" (namespace {ns})"))
                                .unwrap_or_default();
                            tracing::error!("passing {from}{at} through as {to}: {e}");
                        }
                    }));
                }
            }
        }
        signals.recv().await;
        let _ = stop_tx.send(true);
        for t in tasks {
            let _ = t.await;
        }
    });
    Ok(())
}

/// Serves `from`, a device seen by session `there`, as `to` on session
/// `here` until `stop`: data and commands relayed as they come, requests
/// asked of `from` and its answers returned, `to` live while `from` is.
async fn relay(
    here: troupe_node::zenoh::Session,
    there: troupe_node::zenoh::Session,
    from: Device,
    to: Device,
    mut stop: tokio::sync::watch::Receiver<bool>,
) -> std::result::Result<(), troupe_node::zenoh::Error> {
    use troupe_msgs::keys;
    let rt = tokio::runtime::Handle::current();
    let (s, key) = (here.clone(), keys::data(&to));
    let _data = there
        .declare_subscriber(keys::data(&from))
        .callback(move |x| {
            let _ = s.put(&key, x.payload().clone()).wait();
        })
        .await?;
    let s = there.clone();
    let _commands = here
        .declare_subscriber(keys::cmd_any(&to))
        .callback(move |x| {
            let name = x.key_expr().as_str().rsplit('/').next().unwrap_or_default();
            let _ = s.put(keys::cmd(&from, name), x.payload().clone()).wait();
        })
        .await?;
    let s = there.clone();
    let _requests = here
        .declare_queryable(keys::req_any(&to))
        .callback(move |q| {
            let s = s.clone();
            // Asked off Zenoh's thread: the answer may take a while.
            rt.spawn(async move {
                let name = q.key_expr().as_str().rsplit('/').next().unwrap_or_default();
                let key = keys::req(&from, name);
                let mut ask = troupe_node::ask(&s, &key, troupe_node::REQUEST_TIMEOUT);
                if let Some(p) = q.payload() {
                    ask = ask.payload(p.clone());
                }
                let answer = match ask.await {
                    Ok(replies) => replies.recv_async().await.ok(),
                    Err(_) => None,
                };
                let _ = match answer.map(|r| r.into_result()) {
                    Some(Ok(sample)) => {
                        q.reply(q.key_expr().clone(), sample.payload().clone())
                            .await
                    }
                    Some(Err(e)) => q.reply_err(e.payload().clone()).await,
                    None => {
                        let nack = troupe_msgs::codec::encode(
                            &troupe_msgs::common::Nack {
                                reason: format!("{from} did not answer `{name}`"),
                            },
                            0.0,
                        );
                        q.reply_err(nack).await
                    }
                };
            });
        })
        .await?;
    // `to` is live while `from` is.
    let lives = there
        .liveliness()
        .declare_subscriber(keys::token_any(&from))
        .history(true)
        .await?;
    let mut drivers = std::collections::BTreeSet::new();
    let mut token = None;
    loop {
        let got = tokio::select! {
            _ = stop.wait_for(|s| *s) => None,
            got = lives.recv_async() => got.ok(),
        };
        let Some(sample) = got else { return Ok(()) };
        let who = sample.key_expr().as_str().to_owned();
        match sample.kind() {
            SampleKind::Put => drivers.insert(who),
            SampleKind::Delete => drivers.remove(&who),
        };
        if drivers.is_empty() {
            if token.take().is_some() {
                tracing::warn!("{from} is gone: {to} is not live");
            }
        } else if token.is_none() {
            token = Some(
                here.liveliness()
                    .declare_token(keys::token(&to, NAME))
                    .await?,
            );
            tracing::info!("passing {from} through as {to}");
        }
    }
}

/// Imports from `server` until `stop`, connecting again a second after
/// every failure.
async fn serve(
    session: troupe_node::zenoh::Session,
    server: String,
    select: Select,
    stop: &mut tokio::sync::watch::Receiver<bool>,
) {
    let mut failures = 0u64;
    while !*stop.borrow() {
        let mut until = stop.clone();
        let stopped = async move {
            let _ = until.wait_for(|s| *s).await;
        };
        match import::run(session.clone(), &server, &select, stopped).await {
            Ok(()) => {
                if *stop.borrow() {
                    return;
                }
                failures += 1;
                tracing::warn!("{server} closed the connection; connecting again");
            }
            Err(e) => {
                failures += 1;
                if failures == 1 {
                    tracing::warn!("{e}; trying again every second");
                } else {
                    tracing::debug!("{e} (attempt {failures})");
                }
            }
        }
        tokio::select! {
            _ = stop.wait_for(|s| *s) => return,
            () = tokio::time::sleep(Duration::from_secs(1)) => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn section(json: &str) -> Section {
        Section::from_json(json).unwrap()
    }

    #[test]
    fn both_of_player_s_forms_name_their_servers() {
        let s = section(
            r#"{"name":"passthrough","provides":["dio:0","laser:3"],"options":{"remote":["192.168.1.15:6665:dio:0","192.168.1.15:6665:laser:1"]}}"#,
        );
        let (Route::Remote(got), _) = routes(&s).unwrap() else {
            panic!("the remote form")
        };
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].0, "192.168.1.15:6665");
        assert_eq!(
            got[0].1,
            [
                ((Interface::Dio, 0), Device::new(6665, Interface::Dio, 0)),
                (
                    (Interface::Laser, 1),
                    Device::new(6665, Interface::Laser, 3)
                ),
            ]
        );
        let s = section(
            r#"{"name":"passthrough","provides":["laser:0"],"options":{"remote_port":7000,"remote_index":2,"access":"r"}}"#,
        );
        let (Route::Remote(got), _) = routes(&s).unwrap() else {
            panic!("Player 2's form")
        };
        assert_eq!(got[0].0, "localhost:7000");
        assert_eq!(got[0].1[0].0, (Interface::Laser, 2));
    }

    #[test]
    fn bad_sections_say_why() {
        let e = |json: &str| routes(&section(json)).unwrap_err().to_string();
        assert!(e(r#"{"name":"passthrough","provides":["dio:0","dio:1"],"options":{"remote":["h:6665:dio:0"]}}"#)
            .contains("Mismatched number of entries in provides and requires (2 and 1)"));
        assert!(e(
            r#"{"name":"passthrough","provides":["dio:0"],"options":{"remote":["h:6665:laser:0"]}}"#
        )
        .contains("the interfaces must match"));
        assert!(e(
            r#"{"name":"passthrough","provides":["dio:0"],"options":{"remote":["h:x:dio:0"]}}"#
        )
        .contains("is not a remote device like"));
        assert!(
            e(r#"{"name":"passthrough","provides":["dio:0"],"requires":["laser:3"]}"#)
                .contains("dio:0: the interfaces must match")
        );
        let s = section(r#"{"name":"passthrough","provides":["dio:0"],"requires":["6666:dio:3"]}"#);
        let (Route::Local(pairs, None), _) = routes(&s).unwrap() else {
            panic!("the local form")
        };
        assert_eq!(pairs[0].1, Device::new(6666, Interface::Dio, 3));
        // Another namespace's devices, as the plan passes them on.
        let s = section(
            r#"{"name":"passthrough","provides":["7000:dio:0"],"options":{"namespace":"a","elsewhere":["6666:dio:3"]}}"#,
        );
        let (Route::Local(pairs, Some(ns)), _) = routes(&s).unwrap() else {
            panic!("the namespace form")
        };
        assert_eq!(
            (pairs[0].1, ns.as_str()),
            (Device::new(6666, Interface::Dio, 3), "a")
        );
        assert!(e(
            r#"{"name":"passthrough","provides":["dio:0"],"options":{"elsewhere":["dio:3"]}}"#
        )
        .contains("need the `namespace`"));
        assert!(
            e(r#"{"name":"passthrough","provides":["dio:0"],"options":{"access":"x"}}"#)
                .contains("access \"x\" is not r, w or a")
        );
    }
}
