//! `troupe bench`: benchmarks that print numbers.
//!
//! `latency` measures what a sample costs between two Troupe processes: this
//! process runs a router on an ephemeral loopback port (as `troupe launch`
//! embeds one), starts `troupe bench pong` as a child peer, and times
//! laser-scan-sized messages through the full codec (encode, put, decode,
//! re-encode, put back, decode) and through a request/reply.

use std::io::{Read, Write};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Args;
use troupe_msgs::{codec, keys, laser};
use troupe_node::zenoh::Wait;
use troupe_node::{Mode, ZenohArgs};

use crate::cli::BenchCmd;

/// Flags of `troupe bench latency`.
#[derive(Debug, Args)]
pub struct LatencyArgs {
    /// Payload size in bytes (a laser scan with as many beams as fit).
    #[arg(long, default_value_t = 1500)]
    pub size: usize,
    /// Timed round trips of each kind.
    #[arg(long, default_value_t = 5000)]
    pub samples: usize,
    /// Untimed round trips first.
    #[arg(long, default_value_t = 500)]
    pub warmup: usize,
}

/// Runs a `troupe bench` subcommand.
pub fn run(cmd: BenchCmd, z: &ZenohArgs) -> anyhow::Result<()> {
    match cmd {
        BenchCmd::Latency(a) => latency(&a),
        BenchCmd::Pong => pong(z),
        BenchCmd::Launch(a) => launch_bench(&a),
    }
}

/// A scan whose encoded payload is about `size` bytes.
fn scan_of_size(size: usize) -> laser::Scan {
    let base = codec::encode(&laser::Scan::default(), 0.0).len();
    let beams = size.saturating_sub(base + 2) / 4;
    laser::Scan {
        ranges: vec![4.2; beams],
        ..Default::default()
    }
}

fn percentile(sorted: &[Duration], q: f64) -> Duration {
    if sorted.is_empty() {
        return Duration::ZERO;
    }
    let i = ((sorted.len() - 1) as f64 * q).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

fn us(d: Duration) -> String {
    format!("{:.0} µs", d.as_secs_f64() * 1e6)
}

fn latency(a: &LatencyArgs) -> anyhow::Result<()> {
    let ns = format!("bench-{}", std::process::id());
    let zr = ZenohArgs {
        listen: vec!["tcp/127.0.0.1:0".into()],
        no_multicast: true,
        namespace: Some(ns.clone()),
        ..Default::default()
    };
    let session = zr.open(Mode::Router)?;
    let locator = session
        .info()
        .locators()
        .wait()
        .first()
        .map(ToString::to_string)
        .context("the bench router has no locator")?;

    let ready = session
        .liveliness()
        .declare_subscriber(keys::BENCH_READY)
        .history(true)
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let mut child = Command::new(std::env::current_exe()?)
        .args([
            "bench",
            "pong",
            "--connect",
            &locator,
            "--no-multicast",
            "--namespace",
            &ns,
        ])
        .stdin(Stdio::piped())
        .spawn()
        .context("starting `troupe bench pong`")?;
    let result = (|| {
        ready
            .recv_timeout(Duration::from_secs(20))
            .map_err(|e| anyhow::anyhow!("{e}"))?
            .context("`troupe bench pong` did not come up within 20 s")?;

        let replies = session
            .declare_subscriber(keys::BENCH_PONG)
            .wait()
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        let publisher = session
            .declare_publisher(keys::BENCH_PING)
            .express(true)
            .wait()
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        let msg = scan_of_size(a.size);
        let size = codec::encode(&msg, 0.0).len();
        let total = a.warmup + a.samples;

        let mut pubsub = Vec::with_capacity(a.samples);
        for i in 0..total {
            let payload = codec::encode(&msg, i as f64);
            let t0 = Instant::now();
            publisher
                .put(payload)
                .wait()
                .map_err(|e| anyhow::anyhow!("{e}"))?;
            loop {
                let s = replies
                    .recv_timeout(Duration::from_secs(5))
                    .map_err(|e| anyhow::anyhow!("{e}"))?
                    .context("no echo within 5 s")?;
                let back = codec::decode::<laser::Scan>(&s.payload().to_bytes())?;
                if back.stamp == i as f64 {
                    break;
                }
            }
            if i >= a.warmup {
                pubsub.push(t0.elapsed());
            }
        }

        let mut getreply = Vec::with_capacity(a.samples);
        for i in 0..total {
            let payload = codec::encode(&msg, i as f64);
            let t0 = Instant::now();
            let rx = session
                .get(keys::BENCH_REQ)
                .payload(payload)
                .timeout(Duration::from_secs(5))
                .wait()
                .map_err(|e| anyhow::anyhow!("{e}"))?;
            let r = rx.recv().map_err(|e| anyhow::anyhow!("no reply: {e}"))?;
            let s = r
                .into_result()
                .map_err(|e| anyhow::anyhow!("refused: {e:?}"))?;
            codec::decode::<laser::Scan>(&s.payload().to_bytes())?;
            if i >= a.warmup {
                getreply.push(t0.elapsed());
            }
        }
        pubsub.sort();
        getreply.sort();
        let mut out = std::io::stdout().lock();
        writeln!(out, "troupe bench latency: {size}-byte laser/scan@1 payload, {} samples (+{} warm-up), two processes, Zenoh over tcp/127.0.0.1", a.samples, a.warmup)?;
        let row = |out: &mut std::io::StdoutLock, name: &str, v: &[Duration], half: bool| {
            let f = |d: Duration| if half { d / 2 } else { d };
            writeln!(
                out,
                "  {name:<26} p50 {:>7}  p90 {:>7}  p99 {:>7}  max {:>7}",
                us(f(percentile(v, 0.5))),
                us(f(percentile(v, 0.9))),
                us(f(percentile(v, 0.99))),
                us(f(percentile(v, 1.0)))
            )
        };
        row(&mut out, "put/sub round trip", &pubsub, false)?;
        row(&mut out, "one sample (round trip/2)", &pubsub, true)?;
        row(&mut out, "get/reply round trip", &getreply, false)?;
        Ok(())
    })();
    // Closing the child's stdin tells it to exit; kill it if it does not.
    drop(child.stdin.take());
    match child.wait_timeout_or_kill(Duration::from_secs(5)) {
        Ok(()) => {}
        Err(e) => tracing::warn!("bench pong: {e}"),
    }
    result
}

trait WaitOrKill {
    fn wait_timeout_or_kill(&mut self, t: Duration) -> std::io::Result<()>;
}

impl WaitOrKill for std::process::Child {
    fn wait_timeout_or_kill(&mut self, t: Duration) -> std::io::Result<()> {
        let deadline = Instant::now() + t;
        while Instant::now() < deadline {
            if self.try_wait()?.is_some() {
                return Ok(());
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        self.kill()?;
        self.wait().map(|_| ())
    }
}

/// The echo side: decodes each ping as a node would, re-encodes it and sends it back.
fn pong(z: &ZenohArgs) -> anyhow::Result<()> {
    let session = z.open(Mode::Peer)?;
    let back = session
        .declare_publisher(keys::BENCH_PONG)
        .express(true)
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let _sub = session
        .declare_subscriber(keys::BENCH_PING)
        .callback(
            move |s| match codec::decode::<laser::Scan>(&s.payload().to_bytes()) {
                Ok(m) => {
                    if let Err(e) = back.put(codec::encode(&m.msg, m.stamp)).wait() {
                        tracing::warn!("pong: {e}");
                    }
                }
                Err(e) => tracing::warn!("pong: {e}"),
            },
        )
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let _q = session
        .declare_queryable(keys::BENCH_REQ)
        .callback(|q| {
            let bytes = q
                .payload()
                .map(|p| p.to_bytes().into_owned())
                .unwrap_or_default();
            let sent = match codec::decode::<laser::Scan>(&bytes) {
                Ok(m) => q
                    .reply(q.key_expr().clone(), codec::encode(&m.msg, m.stamp))
                    .wait(),
                Err(e) => q.reply_err(e.to_string()).wait(),
            };
            if let Err(e) = sent {
                tracing::warn!("pong: {e}");
            }
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let _token = session
        .liveliness()
        .declare_token(keys::BENCH_READY)
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    // Runs until the parent closes our stdin (or dies).
    let mut sink = Vec::new();
    let _ = std::io::stdin().read_to_end(&mut sink);
    let _ = session.close().wait();
    Ok(())
}

/// Flags of `troupe bench launch`.
#[derive(Debug, Args)]
pub struct LaunchBenchArgs {
    /// Launches to time.
    #[arg(long, default_value_t = 5)]
    pub runs: usize,
}

/// The 5-node plan `bench launch` times: two ranger→laser pipelines and a base.
const FIVE_NODES: &str = "\
driver ( name \"dummy\" provides [\"ranger:0\"] rate 10 )
driver ( name \"rangertolaser\" requires [\"ranger:0\"] provides [\"laser:0\"] )
driver ( name \"dummy\" provides [\"ranger:1\"] rate 10 )
driver ( name \"rangertolaser\" requires [\"ranger:1\"] provides [\"laser:1\"] )
driver ( name \"dummy\" provides [\"position2d:0\"] rate 10 )
";

/// Child processes of `parent` that run `troupe node`, with their cmdline.
fn node_children(parent: u32) -> Vec<(u32, String)> {
    let mut out = Vec::new();
    let Ok(dir) = std::fs::read_dir("/proc") else {
        return out;
    };
    for e in dir.flatten() {
        let Ok(pid) = e.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let Ok(stat) = std::fs::read_to_string(format!("/proc/{pid}/stat")) else {
            continue;
        };
        let Some((_, rest)) = stat.rsplit_once(") ") else {
            continue;
        };
        let mut f = rest.split(' ');
        let (state, ppid) = (f.next(), f.next().and_then(|p| p.parse::<u32>().ok()));
        let cmd = std::fs::read_to_string(format!("/proc/{pid}/cmdline")).unwrap_or_default();
        if ppid == Some(parent) && state != Some("Z") && cmd.contains("\0node\0") {
            out.push((pid, cmd.replace('\0', " ")));
        }
    }
    out
}

fn median(v: &mut [Duration]) -> Duration {
    v.sort();
    v.get(v.len() / 2).copied().unwrap_or_default()
}

fn ms(d: Duration) -> String {
    format!("{:.0} ms", d.as_secs_f64() * 1e3)
}

/// `troupe bench launch`: launch-to-live and kill-to-live times of a 5-node plan.
pub fn launch_bench(a: &LaunchBenchArgs) -> anyhow::Result<()> {
    use std::io::BufRead;
    use troupe_node::zenoh::sample::SampleKind;
    let dir = std::env::temp_dir().join(format!("troupe-bench-launch-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let cfg = dir.join("five.cfg");
    std::fs::write(&cfg, FIVE_NODES)?;
    let exe = std::env::current_exe()?;
    let (mut ups, mut restarts, mut stops) = (Vec::new(), Vec::new(), Vec::new());
    for run in 0..a.runs.max(1) {
        let ns = format!("bench-launch-{}-{run}", std::process::id());
        let t0 = Instant::now();
        let mut child = Command::new(&exe)
            .args(["--namespace", &ns, "launch"])
            .arg(&cfg)
            .args(["--listen", "tcp/127.0.0.1:0"])
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()?;
        let result = (|| -> anyhow::Result<()> {
            let out = child.stdout.take().context("launcher stdout")?;
            let mut line = String::new();
            std::io::BufReader::new(out).read_line(&mut line)?;
            let endpoint = line
                .trim()
                .strip_prefix("troupe launch: router listening on ")
                .and_then(|l| l.split(' ').next())
                .with_context(|| format!("unexpected launcher output {line:?}"))?
                .to_owned();
            let probe = ZenohArgs {
                connect: vec![endpoint],
                namespace: Some(ns.clone()),
                no_multicast: true,
                ..Default::default()
            }
            .open(Mode::Client)?;
            let tokens = probe
                .liveliness()
                .declare_subscriber(keys::tokens(None))
                .history(true)
                .wait()
                .map_err(|e| anyhow::anyhow!("{e}"))?;
            let deadline = Instant::now() + Duration::from_secs(30);
            let mut live = std::collections::BTreeSet::new();
            while live.len() < 5 {
                let t = tokens
                    .recv_deadline(deadline)
                    .map_err(|e| anyhow::anyhow!("{e}"))?
                    .context("the 5 devices did not come up within 30 s")?;
                if t.kind() == SampleKind::Put {
                    live.insert(t.key_expr().to_string());
                }
            }
            ups.push(t0.elapsed());
            // Kill one node (a different one each run) and time its device's return.
            let kids = node_children(child.id());
            let (pid, cmd) = kids
                .get(run % kids.len().max(1))
                .cloned()
                .context("no node children")?;
            let token = live
                .iter()
                .find(|k| {
                    keys::parse_token(k).is_ok_and(|(d, _)| cmd.contains(&format!("\"{}\"", d)))
                })
                .cloned()
                .with_context(|| format!("which device does `{cmd}` serve?"))?;
            let t1 = Instant::now();
            let p = nix::unistd::Pid::from_raw(i32::try_from(pid)?);
            nix::sys::signal::kill(p, nix::sys::signal::Signal::SIGKILL)?;
            let mut dropped = false;
            loop {
                let t = tokens
                    .recv_deadline(deadline)
                    .map_err(|e| anyhow::anyhow!("{e}"))?
                    .context("the killed node did not come back within 30 s")?;
                if t.key_expr().as_str() == token {
                    match t.kind() {
                        SampleKind::Delete => dropped = true,
                        SampleKind::Put if dropped => break,
                        SampleKind::Put => {}
                    }
                }
            }
            restarts.push(t1.elapsed());
            Ok(())
        })();
        let t2 = Instant::now();
        if let Ok(p) = i32::try_from(child.id()) {
            let _ = nix::sys::signal::kill(
                nix::unistd::Pid::from_raw(p),
                nix::sys::signal::Signal::SIGTERM,
            );
        }
        let status = child.wait()?;
        stops.push(t2.elapsed());
        result?;
        if !status.success() {
            anyhow::bail!("the launcher did not stop cleanly: {status}");
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "troupe bench launch: 5-node plan (3 dummy + 2 rangertolaser), {} runs, embedded router",
        ups.len()
    )?;
    let list = |v: &[Duration]| v.iter().map(|d| ms(*d)).collect::<Vec<_>>().join(" ");
    writeln!(
        out,
        "  launch → all 5 devices live   median {:>7}   ({})",
        ms(median(&mut ups.clone())),
        list(&ups)
    )?;
    writeln!(
        out,
        "  SIGKILL a node → device back  median {:>7}   ({})",
        ms(median(&mut restarts.clone())),
        list(&restarts)
    )?;
    writeln!(
        out,
        "  SIGTERM → launcher exited     median {:>7}   ({})",
        ms(median(&mut stops.clone())),
        list(&stops)
    )?;
    Ok(())
}
