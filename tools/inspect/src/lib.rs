//! Looking at a running system from any host, as Player's tools did:
//! `troupe list` (Player's "Available devices"), `echo` (playerprint),
//! `hz`, `ready` (a container's health check), and what this build knows:
//! `drivers`, `interfaces`. Each is a Zenoh client; none changes anything
//! but `cmd` and `call` (module `act`), which command and ask devices.

use std::io::Write;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Args;
use troupe_launch::catalog::{self, Catalog};
use troupe_msgs::{decode_any, keys, AddrError, DevAddr, Interface};
use troupe_node::zenoh::Wait;
use troupe_node::{Mode, ZenohArgs};

mod act;
pub use act::{call, cmd, CallArgs, CmdArgs};

/// Flags of `troupe list`.
#[derive(Debug, Args)]
pub struct ListArgs {
    /// Only this robot (port).
    #[arg(short = 'p', long = "robot", value_name = "PORT")]
    pub robot: Option<u32>,
    /// One JSON object per device.
    #[arg(long)]
    pub json: bool,
    /// Seconds to wait for answers.
    #[arg(long, value_name = "SECS", default_value_t = 2.0, value_parser = troupe_node::args::seconds)]
    pub wait: f64,
    /// Keep running and print each device as it comes (`+`) and goes (`-`).
    #[arg(long)]
    pub watch: bool,
}

/// Flags of `troupe ready`.
#[derive(Debug, Args)]
pub struct ReadyArgs {
    /// Devices that must be live (`laser:0`, `6666:position2d:0`).
    #[arg(value_name = "DEVICE")]
    pub devices: Vec<DevAddr>,
    /// Robot (port) for a device that names none.
    #[arg(short = 'p', long = "robot", value_name = "PORT", default_value_t = troupe_msgs::DEFAULT_ROBOT)]
    pub robot: u32,
    /// Seconds to wait for them to come up (0: look once).
    #[arg(long, value_name = "SECS", default_value_t = 0.0, value_parser = troupe_node::args::seconds)]
    pub wait: f64,
}

/// Flags of `troupe echo`.
#[derive(Debug, Args)]
pub struct EchoArgs {
    /// A device (`laser:0`, `6666:position2d:0`) or a key (`robot/6665/laser/0`, `sim/clock`).
    pub target: String,
    /// Robot (port) for a device that names none.
    #[arg(short = 'p', long = "robot", value_name = "PORT", default_value_t = troupe_msgs::DEFAULT_ROBOT)]
    pub robot: u32,
    /// One JSON object per sample, arrays in full.
    #[arg(long)]
    pub json: bool,
    /// Stop after N samples.
    #[arg(short = 'n', long, value_name = "N")]
    pub count: Option<u64>,
    /// Give up after this many seconds without a sample (default: wait forever).
    #[arg(long, value_name = "SECS", value_parser = troupe_node::args::seconds)]
    pub timeout: Option<f64>,
}

/// Flags of `troupe hz`.
#[derive(Debug, Args)]
pub struct HzArgs {
    /// A device (`laser:0`) or a key.
    pub target: String,
    /// Robot (port) for a device that names none.
    #[arg(short = 'p', long = "robot", value_name = "PORT", default_value_t = troupe_msgs::DEFAULT_ROBOT)]
    pub robot: u32,
    /// Samples in the moving window.
    #[arg(long, value_name = "N", default_value_t = 100)]
    pub window: usize,
    /// Stop after N reports (one a second).
    #[arg(short = 'n', long, value_name = "N")]
    pub count: Option<u64>,
}

/// A live device, from its liveliness token.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, serde::Serialize)]
struct Live {
    #[serde(skip)]
    order: (u32, u16, u32),
    robot: u32,
    device: String,
    driver: String,
    state: &'static str,
}

fn list_devices(z: &ZenohArgs, robot: Option<u32>, wait: Duration) -> anyhow::Result<Vec<Live>> {
    let session = z.open(Mode::Client)?;
    let replies = session
        .liveliness()
        .get(keys::tokens(robot))
        .timeout(wait)
        .wait()
        .map_err(|e| anyhow::anyhow!("asking for liveliness tokens: {e}"))?;
    let mut out = Vec::new();
    while let Ok(r) = replies.recv() {
        let Ok(sample) = r.result() else { continue };
        match keys::parse_token(sample.key_expr().as_str()) {
            Ok((d, driver)) => out.push(Live {
                order: (d.robot, d.interface.code(), d.index),
                robot: d.robot,
                device: format!("{}:{}", d.interface, d.index),
                driver,
                state: "ready",
            }),
            Err(e) => tracing::warn!("ignored a token: {e}"),
        }
    }
    out.sort();
    out.dedup();
    let _ = session.close().wait();
    Ok(out)
}

/// `troupe list --watch`: one line per device that comes or goes.
fn watch(robot: Option<u32>, z: &ZenohArgs) -> anyhow::Result<()> {
    let session = z.open(Mode::Client)?;
    let sub = session
        .liveliness()
        .declare_subscriber(keys::tokens(robot))
        .history(true)
        .wait()
        .map_err(|e| anyhow::anyhow!("watching liveliness: {e}"))?;
    let mut out = std::io::stdout().lock();
    while let Ok(s) = sub.recv() {
        let Ok((d, driver)) = keys::parse_token(s.key_expr().as_str()) else {
            continue;
        };
        let sign = match s.kind() {
            troupe_node::zenoh::sample::SampleKind::Put => '+',
            troupe_node::zenoh::sample::SampleKind::Delete => '-',
        };
        // Fixed columns: the devices to come are not known yet.
        writeln!(
            out,
            "{sign} robot/{:<5} {:<16} {driver}",
            d.robot,
            format!("{}:{}", d.interface, d.index)
        )?;
        out.flush()?;
    }
    Ok(())
}

/// `troupe list`.
pub fn list(a: ListArgs, z: &ZenohArgs) -> anyhow::Result<()> {
    if a.watch {
        return watch(a.robot, z);
    }
    let devices = list_devices(z, a.robot, Duration::from_secs_f64(a.wait.max(0.01)))?;
    let mut out = std::io::stdout().lock();
    if a.json {
        for d in &devices {
            writeln!(out, "{}", serde_json::to_string(d)?)?;
        }
        return Ok(());
    }
    if devices.is_empty() {
        let _ = writeln!(
            std::io::stderr(),
            "no devices found{} (is a router running? nodes connect to {} unless --connect says otherwise)",
            a.robot.map(|r| format!(" on robot {r}")).unwrap_or_default(),
            troupe_node::DEFAULT_ROUTER
        );
        return Ok(());
    }
    let w = devices.iter().map(|d| d.device.len()).max().unwrap_or(0);
    let wd = devices.iter().map(|d| d.driver.len()).max().unwrap_or(0);
    for d in &devices {
        writeln!(
            out,
            "robot/{:<5} {:<w$}  {:<wd$}  {}",
            d.robot, d.device, d.driver, d.state
        )?;
    }
    Ok(())
}

/// `troupe ready`: succeeds once every device named is live; with none,
/// once the router answers.
pub fn ready(a: ReadyArgs, z: &ZenohArgs) -> anyhow::Result<()> {
    let said = wait_ready(a, z)?;
    writeln!(std::io::stdout().lock(), "{said}")?;
    Ok(())
}

/// What `troupe ready` does, saying nothing: the line it would print.
pub fn wait_ready(a: ReadyArgs, z: &ZenohArgs) -> anyhow::Result<String> {
    use std::collections::BTreeSet;
    let want: BTreeSet<troupe_msgs::Device> = a.devices.iter().map(|d| d.device(a.robot)).collect();
    let session = z.open(Mode::Client)?;
    // Subscribe before asking, so a device that comes up in between is seen.
    let sub = session
        .liveliness()
        .declare_subscriber(keys::tokens(None))
        .wait()
        .map_err(|e| anyhow::anyhow!("watching liveliness: {e}"))?;
    let mut live = BTreeSet::new();
    let note = |live: &mut BTreeSet<troupe_msgs::Device>, key: &str, put: bool| {
        if let Ok((d, _)) = keys::parse_token(key) {
            if put {
                live.insert(d);
            } else {
                live.remove(&d);
            }
        }
    };
    let replies = session
        .liveliness()
        .get(keys::tokens(None))
        .timeout(Duration::from_secs(2))
        .wait()
        .map_err(|e| anyhow::anyhow!("asking for liveliness tokens: {e}"))?;
    while let Ok(r) = replies.recv() {
        if let Ok(s) = r.result() {
            note(&mut live, s.key_expr().as_str(), true);
        }
    }
    let deadline = Instant::now() + Duration::from_secs_f64(a.wait.clamp(0.0, 86_400.0));
    loop {
        let missing: Vec<String> = want
            .iter()
            .filter(|d| !live.contains(d))
            .map(ToString::to_string)
            .collect();
        if missing.is_empty() {
            return Ok(match (want.len(), want.iter().next()) {
                (0, _) => "ready: the router answers".to_owned(),
                (1, Some(d)) => format!("ready: {d} is live"),
                (n, _) => format!("ready: all {n} devices live"),
            });
        }
        match sub.recv_deadline(deadline) {
            Ok(Some(s)) => note(
                &mut live,
                s.key_expr().as_str(),
                s.kind() == troupe_node::zenoh::sample::SampleKind::Put,
            ),
            _ => anyhow::bail!(
                "not live: {} ({} of {} devices live)",
                troupe_launch::supervisor::listed(&missing, 8),
                want.len() - missing.len(),
                want.len()
            ),
        }
    }
}

/// Resolves a command-line target to a key: a device address or a key.
fn target_key(target: &str, robot: u32) -> anyhow::Result<String> {
    if target == keys::SIM_CLOCK {
        return Ok(target.to_owned());
    }
    if target.contains('/') {
        keys::parse_data(target)
            .or_else(|_| keys::parse_named(target, "cmd").map(|(d, _)| d))
            .map_err(|_| AddrError::NotADeviceKey {
                text: target.to_owned(),
                rest: " or …/cmd/<name>, or sim/clock",
            })?;
        return Ok(target.to_owned());
    }
    let a: DevAddr = target.parse()?;
    Ok(keys::data(&a.device(robot)))
}

/// Shortens arrays for humans: the first 8 elements, then a count.
fn abbreviate(v: &mut serde_json::Value) {
    match v {
        serde_json::Value::Array(a) => {
            if a.len() > 8 {
                let more = a.len() - 8;
                a.truncate(8);
                a.push(serde_json::Value::String(format!("… {more} more")));
            }
            a.iter_mut().for_each(abbreviate);
        }
        serde_json::Value::Object(o) => o.values_mut().for_each(abbreviate),
        _ => {}
    }
}

/// One sample, printed.
fn print_sample(
    out: &mut impl Write,
    key: &str,
    payload: &[u8],
    json: bool,
) -> anyhow::Result<bool> {
    let s = match decode_any(payload) {
        Ok(s) => s,
        Err(e) => {
            let _ = writeln!(
                std::io::stderr(),
                "troupe echo: malformed sample on `{key}`: {e}"
            );
            return Ok(false);
        }
    };
    let mut v = serde_json::to_value(&s.msg)?;
    let (kind, mut body) = match v.as_object_mut().and_then(|o| o.iter_mut().next()) {
        Some((k, b)) => (k.clone(), b.take()),
        None => (v.to_string(), serde_json::Value::Null),
    };
    if json {
        let rec = serde_json::json!({"key": key, "stamp": s.stamp, "type": kind, "msg": body});
        writeln!(out, "{rec}")?;
    } else {
        abbreviate(&mut body);
        writeln!(out, "{key}  t={:.3}  {kind} {body}", s.stamp)?;
    }
    Ok(true)
}

/// Before waiting in silence: is the device there at all, or only quiet?
fn say_what_echo_waits_for(session: &troupe_node::zenoh::Session, key: &str) {
    let Ok(dev) = keys::parse_data(key) else {
        return;
    };
    let live = session
        .liveliness()
        .get(keys::token_any(&dev))
        .timeout(Duration::from_millis(500))
        .wait()
        .map(|replies| replies.recv().is_ok())
        .unwrap_or(false);
    let why = if live {
        format!("{dev} is live but has sent nothing yet (it may publish only on change); waiting")
    } else {
        format!(
            "{dev} is not live; waiting for it to come up (`troupe list` shows the live devices)"
        )
    };
    let _ = writeln!(std::io::stderr(), "troupe echo: {why}");
}

/// `troupe echo`.
pub fn echo(a: EchoArgs, z: &ZenohArgs) -> anyhow::Result<()> {
    let key = target_key(&a.target, a.robot)?;
    let session = z.open(Mode::Client)?;
    let sub = session
        .declare_subscriber(&key)
        .wait()
        .map_err(|e| anyhow::anyhow!("subscribing to {key}: {e}"))?;
    let mut out = std::io::stdout().lock();
    let mut printed = 0u64;
    let done = |n: u64| a.count.is_some_and(|c| n >= c);
    // The latest samples the provider holds come first, as Player gave new
    // subscribers the current state.
    if !key.contains("/cmd/") {
        let latest = session
            .get(&key)
            .timeout(Duration::from_secs(1))
            .wait()
            .map_err(|e| anyhow::anyhow!("asking {key} for its latest samples: {e}"))?;
        while let Ok(r) = latest.recv() {
            if done(printed) {
                break;
            }
            if let Ok(s) = r.result() {
                if print_sample(
                    &mut out,
                    s.key_expr().as_str(),
                    &s.payload().to_bytes(),
                    a.json,
                )? {
                    printed += 1;
                }
            }
        }
    }
    if printed == 0 {
        say_what_echo_waits_for(&session, &key);
    }
    let timeout = a.timeout.map(Duration::from_secs_f64);
    while !done(printed) {
        let s = match timeout {
            None => sub.recv().map_err(|e| anyhow::anyhow!("{e}"))?,
            Some(t) => sub
                .recv_timeout(t)
                .map_err(|e| anyhow::anyhow!("{e}"))?
                .with_context(|| format!("no sample on `{key}` within {t:?}"))?,
        };
        if print_sample(
            &mut out,
            s.key_expr().as_str(),
            &s.payload().to_bytes(),
            a.json,
        )? {
            printed += 1;
        }
        out.flush()?;
    }
    Ok(())
}

/// Rate statistics over a window of inter-arrival gaps.
#[derive(Debug, Clone, PartialEq)]
pub struct Rate {
    /// Samples per second.
    pub hz: f64,
    /// Shortest gap, seconds.
    pub min: f64,
    /// Longest gap, seconds.
    pub max: f64,
    /// Standard deviation of the gaps, seconds.
    pub std_dev: f64,
    /// Gaps in the window.
    pub window: usize,
}

/// The rate of samples whose gaps (seconds) are `gaps`; `None` without gaps.
pub fn rate(gaps: &[f64]) -> Option<Rate> {
    if gaps.is_empty() {
        return None;
    }
    let n = gaps.len() as f64;
    let mean = gaps.iter().sum::<f64>() / n;
    let var = gaps.iter().map(|g| (g - mean).powi(2)).sum::<f64>() / n;
    Some(Rate {
        hz: if mean > 0.0 {
            1.0 / mean
        } else {
            f64::INFINITY
        },
        min: gaps.iter().copied().fold(f64::INFINITY, f64::min),
        max: gaps.iter().copied().fold(0.0, f64::max),
        std_dev: var.sqrt(),
        window: gaps.len(),
    })
}

/// `troupe hz`.
pub fn hz(a: HzArgs, z: &ZenohArgs) -> anyhow::Result<()> {
    let key = target_key(&a.target, a.robot)?;
    let session = z.open(Mode::Client)?;
    let sub = session
        .declare_subscriber(&key)
        .wait()
        .map_err(|e| anyhow::anyhow!("subscribing to {key}: {e}"))?;
    let window = a.window.max(2);
    let mut kinds: std::collections::BTreeMap<String, Updates> = Default::default();
    let mut reports = 0u64;
    let mut next_report = Instant::now() + Duration::from_secs(1);
    let mut out = std::io::stdout().lock();
    loop {
        match sub.recv_deadline(next_report) {
            Ok(Some(s)) => {
                let bytes = s.payload().to_bytes();
                let (kind, stamp) = match troupe_msgs::codec::split(&bytes) {
                    Ok((tag, stamp, _)) => (tag.split('@').next().unwrap_or(tag).to_owned(), stamp),
                    Err(_) => ("(malformed)".to_owned(), f64::NAN),
                };
                kinds.entry(kind).or_default().sample(stamp, window);
            }
            Ok(None) => {
                next_report += Duration::from_secs(1);
                let mut any = false;
                for (kind, u) in &mut kinds {
                    let g: Vec<f64> = u.gaps.iter().copied().collect();
                    if let (Some(r), true) = (rate(&g), u.fresh > 0) {
                        any = true;
                        let per = if u.updates > 0 && u.samples > u.updates {
                            format!(
                                " ({:.1} samples an update, counted once)",
                                u.samples as f64 / u.updates as f64
                            )
                        } else {
                            String::new()
                        };
                        writeln!(
                            out,
                            "rate: {:.3} Hz  min: {:.4} s  max: {:.4} s  std dev: {:.5} s  window: {}  {kind}{per}",
                            r.hz, r.min, r.max, r.std_dev, r.window
                        )?;
                    }
                    u.fresh = 0;
                }
                if !any {
                    writeln!(out, "no new samples on `{key}`")?;
                }
                out.flush()?;
                reports += 1;
                if a.count.is_some_and(|c| reports >= c) {
                    return Ok(());
                }
            }
            Err(e) => anyhow::bail!("subscription to {key} ended: {e}"),
        }
    }
}

/// The updates of one message kind on a key: samples that carry the same
/// stamp as the one before (a laser's ranges and then its intensities, as
/// Player's rangertolaser sends them) are one update.
#[derive(Default)]
struct Updates {
    gaps: std::collections::VecDeque<f64>,
    last: Option<(Instant, f64)>,
    fresh: usize,
    samples: u64,
    updates: u64,
}

impl Updates {
    fn sample(&mut self, stamp: f64, window: usize) {
        self.samples += 1;
        let now = Instant::now();
        if let Some((_, last_stamp)) = self.last {
            if last_stamp == stamp {
                return;
            }
        }
        self.updates += 1;
        if let Some((l, _)) = self.last {
            if self.gaps.len() == window {
                self.gaps.pop_front();
            }
            self.gaps.push_back((now - l).as_secs_f64());
        }
        self.last = Some((now, stamp));
        self.fresh += 1;
    }
}

/// `troupe drivers`.
pub fn print_drivers(catalog: &Catalog, all: bool) -> anyhow::Result<()> {
    let mut out = std::io::stdout().lock();
    for e in catalog.entries() {
        writeln!(out, "{:<16} {}", e.name, e.about)?;
    }
    if all {
        for (name, about, instead) in catalog::MISSING {
            let what = catalog::missing_about(about, instead);
            writeln!(out, "{name:<16} not available {what}")?;
        }
    }
    Ok(())
}

/// `troupe interfaces`.
pub fn print_interfaces() -> anyhow::Result<()> {
    let mut out = std::io::stdout().lock();
    for i in Interface::ALL {
        writeln!(out, "{:>3}  {}", i.code(), i.name())?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn targets_resolve_to_keys_or_say_why_not() {
        assert_eq!(target_key("laser:0", 6665).unwrap(), "robot/6665/laser/0");
        assert_eq!(
            target_key("6666:ranger:1", 6665).unwrap(),
            "robot/6666/ranger/1"
        );
        assert_eq!(target_key("robot/7/map/0", 6665).unwrap(), "robot/7/map/0");
        assert_eq!(target_key("sim/clock", 6665).unwrap(), "sim/clock");
        let e = target_key("foo/bar", 6665).unwrap_err().to_string();
        assert!(e.contains("`foo/bar` is not a device key"), "{e}");
        let e = target_key("laser:x", 6665).unwrap_err().to_string();
        assert!(e.contains("`x`"), "{e}");
    }

    #[test]
    fn rate_of_regular_gaps() {
        let r = rate(&[0.1, 0.1, 0.1, 0.1]).unwrap();
        assert!((r.hz - 10.0).abs() < 1e-9);
        assert!(r.std_dev < 1e-12);
        assert_eq!(r.window, 4);
        let r = rate(&[0.05, 0.15]).unwrap();
        assert!((r.std_dev - 0.05).abs() < 1e-12 && r.min == 0.05 && r.max == 0.15);
        assert!(rate(&[]).is_none());
    }

    #[test]
    fn long_arrays_are_abbreviated_for_humans() {
        let mut v = serde_json::json!({"ranges": (0..20).collect::<Vec<_>>()});
        abbreviate(&mut v);
        assert_eq!(v["ranges"].as_array().unwrap().len(), 9);
        assert_eq!(v["ranges"][8], "… 12 more");
    }
}
