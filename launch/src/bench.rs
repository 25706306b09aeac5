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
