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
    /// Also run over TLS with mutual authentication and the router's access
    /// control, as `troupe fleet-keys` sets them up, and print both.
    #[arg(long)]
    pub secure: bool,
}

/// The bench's keys under `prefix`: ping, pong, req, ready.
fn bench_keys(prefix: &str) -> [String; 4] {
    ["ping", "pong", "req", "ready"].map(|k| format!("{prefix}/{k}"))
}

/// A robot port no stack uses, whose keys the secure bench runs under.
const SECURE_ROBOT: u32 = 65_000;

/// Runs a `troupe bench` subcommand.
pub fn run(cmd: BenchCmd, z: &ZenohArgs) -> anyhow::Result<()> {
    match cmd {
        BenchCmd::Latency(a) => {
            latency(&a, None)?;
            if a.secure {
                let dir =
                    std::env::temp_dir().join(format!("troupe-bench-keys-{}", std::process::id()));
                let r = latency(&a, Some(&dir));
                let _ = std::fs::remove_dir_all(&dir);
                r?;
            }
            Ok(())
        }
        BenchCmd::Pong { prefix } => pong(z, &prefix),
        BenchCmd::Launch(a) => launch_bench(&a),
        BenchCmd::Stage(a) => stage_bench(&a),
        BenchCmd::Bridge(a) => crate::bridgebench::run(&a),
        BenchCmd::Nav(a) => crate::navbench::nav_bench(&a),
        BenchCmd::Serial(a) => crate::serialbench::run(&a),
        BenchCmd::Record(a) => crate::mcaplog::bench(&a),
        BenchCmd::View(a) => crate::viewbench::run(&a),
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

pub(crate) fn percentile(sorted: &[Duration], q: f64) -> Duration {
    if sorted.is_empty() {
        return Duration::ZERO;
    }
    let i = ((sorted.len() - 1) as f64 * q).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

pub(crate) fn us(d: Duration) -> String {
    format!("{:.0} µs", d.as_secs_f64() * 1e6)
}

/// Plain TCP with a namespace, or (`keys`: a directory for them) TLS with
/// mutual authentication and access control, the pong a host of robot
/// `SECURE_ROBOT` whose keys the bench uses.
fn latency(a: &LatencyArgs, keys: Option<&std::path::Path>) -> anyhow::Result<()> {
    let ns = format!("bench-{}", std::process::id());
    let (zr, prefix, pong_net) = match keys {
        None => (
            ZenohArgs {
                listen: vec!["tcp/127.0.0.1:0".into()],
                no_multicast: true,
                namespace: Some(ns.clone()),
                ..Default::default()
            },
            keys::BENCH_PING.trim_end_matches("/ping").to_owned(),
            vec![
                "--no-multicast".to_owned(),
                "--namespace".to_owned(),
                ns.clone(),
            ],
        ),
        Some(dir) => {
            let (router, pong) = crate::keys::bench_configs(dir, SECURE_ROBOT)?;
            (
                ZenohArgs {
                    listen: vec!["tls/127.0.0.1:0".into()],
                    zenoh_config: Some(router),
                    ..Default::default()
                },
                format!("robot/{SECURE_ROBOT}/bench"),
                vec!["--zenoh-config".to_owned(), pong.display().to_string()],
            )
        }
    };
    let [ping_key, pong_key, req_key, ready_key] = bench_keys(&prefix);
    let session = zr.open(Mode::Router)?;
    let locator = troupe_node::locators(&session)
        .into_iter()
        .next()
        .context("the bench router has no locator")?;
    // Certificates name `localhost`, not the address.
    let locator = locator.replace("tls/127.0.0.1", "tls/localhost");

    let ready = session
        .liveliness()
        .declare_subscriber(&ready_key)
        .history(true)
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let mut child = Command::new(std::env::current_exe()?)
        .args(["--connect", &locator])
        .args(&pong_net)
        .args(["bench", "pong", "--prefix", &prefix])
        .stdin(Stdio::piped())
        .spawn()
        .context("starting `troupe bench pong`")?;
    let result = (|| {
        ready
            .recv_timeout(Duration::from_secs(20))
            .map_err(|e| anyhow::anyhow!("{e}"))?
            .context("`troupe bench pong` did not come up within 20 s")?;

        let replies = session
            .declare_subscriber(&pong_key)
            .wait()
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        let publisher = session
            .declare_publisher(&ping_key)
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
                .get(&req_key)
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
        let over = if keys.is_some() {
            "tls/127.0.0.1, mutual authentication and access control"
        } else {
            "tcp/127.0.0.1"
        };
        writeln!(out, "troupe bench latency: {size}-byte laser/scan@1 payload, {} samples (+{} warm-up), two processes, Zenoh over {over}", a.samples, a.warmup)?;
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
fn pong(z: &ZenohArgs, prefix: &str) -> anyhow::Result<()> {
    let [ping_key, pong_key, req_key, ready_key] = bench_keys(prefix);
    let session = z.open(Mode::Peer)?;
    let back = session
        .declare_publisher(pong_key)
        .express(true)
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let _sub = session
        .declare_subscriber(ping_key)
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
        .declare_queryable(req_key)
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
        .declare_token(ready_key)
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
            .args(["--listen", "tcp/127.0.0.1:0", "--bridge-any-port"])
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

/// Flags of `troupe bench stage`.
#[derive(Debug, Args)]
pub struct StageBenchArgs {
    /// Simulated seconds per world.
    #[arg(long, default_value_t = 60.0)]
    pub seconds: f64,
    /// Run only this world (simple, pioneers100, hospital1000) in this process.
    #[arg(long, hide = true)]
    pub only: Option<String>,
    /// Worker threads (the world's `threads`); 1 = one core.
    #[arg(long, default_value_t = 1)]
    pub threads: usize,
    /// Where Stage's sample bitmaps are (cave.png, hospital_section.png).
    #[arg(long, value_name = "DIR")]
    pub bitmaps: Option<std::path::PathBuf>,
    /// Measure ranges as Stage does, on its raster of the walls (what
    /// `stage_quirks 1` turns on), instead of against the exact walls.
    #[arg(long)]
    pub stage_ranges: bool,
    /// Also run Stage's own benchmark worlds from a Stage checkout (its
    /// top directory or its worlds/): benchmark/cave.world and
    /// benchmark/hospital.world, as their authors wrote them, models and
    /// controllers included (`threads` as given here).
    #[arg(long, value_name = "DIR")]
    pub stage_worlds: Option<std::path::PathBuf>,
    /// Run just this world file instead, as its authors wrote it, models
    /// and controllers included (e.g. Stage's worlds/large.world), and
    /// print its row: time to load, time to run, peak memory.
    #[arg(long, value_name = "FILE")]
    pub world: Option<std::path::PathBuf>,
    /// Then cast the same rays on the cave's and the hospital's walls with
    /// the simulator's grid walk and with parry2d, and print both.
    #[arg(long)]
    pub parry: bool,
}

/// A Pioneer with 16 sonars and a 180-beam SICK, wandering (our own
/// definitions). Stage is 2.5D: the sonars sit inside the top of the base,
/// as in Stage's pioneer.inc, and so does the SICK here (Stage's sits on
/// top), so that both see the other robots' bases and the wander
/// controller, which steers by the laser, keeps a crowd moving.
const PIONEER: &str = r#"
define bench_sonar sensor ( size [0.01 0.05 0.01] range [0 5.0] fov 15 samples 1 )
define bench_sonars ranger (
  bench_sonar( pose [ 0.075 0.130 0 90 ] ) bench_sonar( pose [ 0.115 0.115 0 50 ] )
  bench_sonar( pose [ 0.150 0.080 0 30 ] ) bench_sonar( pose [ 0.170 0.025 0 10 ] )
  bench_sonar( pose [ 0.170 -0.025 0 -10 ] ) bench_sonar( pose [ 0.150 -0.080 0 -30 ] )
  bench_sonar( pose [ 0.115 -0.115 0 -50 ] ) bench_sonar( pose [ 0.075 -0.130 0 -90 ] )
  bench_sonar( pose [ -0.155 -0.130 0 -90 ] ) bench_sonar( pose [ -0.195 -0.115 0 -130 ] )
  bench_sonar( pose [ -0.230 -0.080 0 -150 ] ) bench_sonar( pose [ -0.250 -0.025 0 -170 ] )
  bench_sonar( pose [ -0.250 0.025 0 170 ] ) bench_sonar( pose [ -0.230 0.080 0 150 ] )
  bench_sonar( pose [ -0.195 0.115 0 130 ] ) bench_sonar( pose [ -0.155 0.130 0 90 ] )
)
define bench_sick ranger ( sensor( range [0 8.0] fov 180 samples 180 ) size [0.156 0.155 0.19] )
define bench_pioneer position (
  size [0.44 0.38 0.22] origin [-0.04 0 0 0] drive "diff" ctrl "wander"
  bench_sonars( pose [0 0 -0.03 0] ) bench_sick( pose [0 0 -0.1 0] )
)
"#;

/// A small robot with 12 IR rangers around it, wandering.
const SMALL: &str = r#"
define bench_ir sensor ( size [0.01 0.01 0.01] range [0 1.0] fov 10 samples 1 )
define bench_irs ranger (
  bench_ir( pose [0.1 0 0 0] ) bench_ir( pose [0.087 0.05 0 30] ) bench_ir( pose [0.05 0.087 0 60] )
  bench_ir( pose [0 0.1 0 90] ) bench_ir( pose [-0.05 0.087 0 120] ) bench_ir( pose [-0.087 0.05 0 150] )
  bench_ir( pose [-0.1 0 0 180] ) bench_ir( pose [-0.087 -0.05 0 -150] ) bench_ir( pose [-0.05 -0.087 0 -120] )
  bench_ir( pose [0 -0.1 0 -90] ) bench_ir( pose [0.05 -0.087 0 -60] ) bench_ir( pose [0.087 -0.05 0 -30] )
)
define bench_small position ( size [0.2 0.2 0.1] drive "diff" ctrl "wander" bench_irs( pose [0 0 -0.05 0] ) )
"#;

/// The first line of `child`'s stdout that starts with `prefix`, less it.
pub(crate) fn line_after(child: &mut std::process::Child, prefix: &str) -> anyhow::Result<String> {
    let out = child.stdout.take().context("the child's stdout")?;
    let mut lines = std::io::BufRead::lines(std::io::BufReader::new(out));
    while let Some(Ok(line)) = lines.next() {
        if let Some(rest) = line.strip_prefix(prefix) {
            // Keep draining, so the child never blocks on a full pipe.
            std::thread::spawn(move || lines.for_each(drop));
            return Ok(rest.trim().to_owned());
        }
    }
    anyhow::bail!("no `{prefix}` line")
}

/// The 100-Pioneer world as a stack of its own, in `dir`: every robot on
/// its own port (position2d:0, ranger:0, ranger:1), at `speedup` (-1: flat
/// out), launched with an embedded router, every device live. Returns the
/// launcher and the router's endpoint.
pub(crate) fn p100_stack(
    dir: &std::path::Path,
    bitmaps: &std::path::Path,
    speedup: f64,
) -> anyhow::Result<(std::process::Child, String)> {
    let (mut world, _) = bench_world("pioneers100", bitmaps, 1)?;
    world.push_str(&format!("speedup {speedup}\n"));
    std::fs::write(dir.join("p100.world"), world)?;
    let mut cfg = String::from(
        "driver ( name \"stage\" provides [\"simulation:0\"] worldfile \"p100.world\" )\n",
    );
    for i in 0..100 {
        let port = 6665 + i;
        cfg.push_str(&format!(
            "driver ( name \"stage\" provides [\"{port}:position2d:0\" \"{port}:ranger:0\" \"{port}:ranger:1\"] model \"p{i}\" )\n"
        ));
    }
    std::fs::write(dir.join("p100.cfg"), cfg)?;
    let mut launcher = Command::new(std::env::current_exe()?)
        .args(["--no-multicast", "launch"])
        .arg(dir.join("p100.cfg"))
        .args(["--no-bridge", "--listen", "tcp/127.0.0.1:0"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()?;
    let router = line_after(&mut launcher, "troupe launch: router listening on ")?
        .split_whitespace()
        .next()
        .unwrap_or_default()
        .to_owned();
    let z = ZenohArgs {
        connect: vec![router.clone()],
        no_multicast: true,
        ..Default::default()
    };
    let devices = (0..100u32)
        .flat_map(|i| ["position2d:0", "ranger:0", "ranger:1"].map(|d| format!("{}:{d}", 6665 + i)))
        .map(|d| d.parse::<troupe_msgs::DevAddr>())
        .collect::<Result<Vec<_>, _>>()?;
    let ready = crate::tools::ready(
        crate::cli::ReadyArgs {
            devices,
            robot: 6665,
            wait: 120.0,
        },
        &z,
    );
    if let Err(e) = ready {
        let _ = launcher.kill();
        let _ = launcher.wait();
        return Err(e);
    }
    Ok((launcher, router))
}

/// Stage's sample bitmaps (cave.png, …): `given`, or where the repository
/// keeps its neighbour `shared/` (run from the repository's top).
pub(crate) fn stage_bitmaps(given: Option<&std::path::Path>) -> anyhow::Result<std::path::PathBuf> {
    let dir = given.map_or_else(
        || std::path::PathBuf::from("../shared/compat/stage/bitmaps"),
        std::path::Path::to_path_buf,
    );
    dir.canonicalize()
        .ok()
        .filter(|b| b.join("cave.png").exists())
        .with_context(|| {
            format!(
                "no Stage bitmaps at {} (cave.png); pass --bitmaps DIR",
                dir.display()
            )
        })
}

pub(crate) fn bench_world(
    name: &str,
    bitmaps: &std::path::Path,
    threads: usize,
) -> anyhow::Result<(String, String)> {
    let mut w = String::from("resolution 0.02\ninterval_sim 100\n");
    w.push_str(&format!("threads {threads}\n"));
    let map = |file: &str, size: &str| {
        format!(
            "model ( name \"map\" bitmap \"{}\" size [{size} 0.8] color \"gray30\" boundary 1 obstacle_return 0 ranger_return 0.5 )\n",
            bitmaps.join(file).display()
        )
    };
    let what = match name {
        "simple" => {
            w.push_str(PIONEER);
            w.push_str(&map("cave.png", "16 16"));
            w.push_str("bench_pioneer( name \"r0\" pose [-6.946 -6.947 0 45] )\nbench_pioneer( name \"r1\" pose [-3.946 -6.947 0 45] )\n");
            "2 Pioneers (16 sonars + 180-beam laser), 16 m cave"
        }
        "pioneers100" => {
            w.push_str(PIONEER);
            w.push_str(&map("cave.png", "16 16"));
            for i in 0..100 {
                let (x, y) = (-6.75 + 1.5 * (i % 10) as f64, -6.75 + 1.5 * (i / 10) as f64);
                w.push_str(&format!(
                    "bench_pioneer( name \"p{i}\" pose [{x} {y} 0 {}] )\n",
                    (i * 37) % 360
                ));
            }
            "100 Pioneers (16 sonars + 180-beam laser), 16 m cave, all moving"
        }
        "hospital1000" => {
            w.push_str(SMALL);
            w.push_str(&map("hospital_section.png", "140 60"));
            for i in 0..1000 {
                let (x, y) = (-68.0 + 3.4 * (i % 40) as f64, -28.0 + 2.3 * (i / 40) as f64);
                w.push_str(&format!(
                    "bench_small( name \"s{i}\" pose [{x} {y} 0 {}] )\n",
                    (i * 53) % 360
                ));
            }
            "1000 small robots (12 IR rangers), 140x60 m hospital, all moving"
        }
        other => anyhow::bail!("unknown bench world `{other}` (simple, pioneers100, hospital1000)"),
    };
    Ok((w, what.to_owned()))
}

fn peak_rss_mb() -> f64 {
    status_mb("VmHWM:")
}

/// The memory this process holds now that is not mapped from files (the
/// binary's own pages, 7–10 MB, move with its code layout alone): MB.
fn anon_rss_mb() -> f64 {
    status_mb("RssAnon:")
}

/// A field of `/proc/self/status` given in kB, in MB (0 where unknown).
fn status_mb(field: &str) -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines().find(|l| l.starts_with(field)).and_then(|l| {
                l.split_whitespace()
                    .nth(1)
                    .and_then(|v| v.parse::<f64>().ok())
            })
        })
        .map_or(0.0, |kb| kb / 1024.0)
}

/// `troupe bench stage`: simulated seconds per wall second and peak memory.
pub fn stage_bench(a: &StageBenchArgs) -> anyhow::Result<()> {
    if let Some(path) = &a.world {
        let name = path.file_name().unwrap_or_default().to_string_lossy();
        let t_load = Instant::now();
        let mut world = troupe_stage::world::load(path)?;
        world.threads = a.threads;
        let what = format!(
            "{}, as Stage's authors wrote it; sensors sensed as Stage senses them, while its controllers read them",
            path.display()
        );
        return run_world(a, &name, world, t_load, &what, false);
    }
    let bitmaps = a
        .bitmaps
        .clone()
        .unwrap_or_else(|| std::path::PathBuf::from("../shared/compat/stage/bitmaps"));
    let bitmaps = match bitmaps.canonicalize() {
        Ok(b) if b.join("cave.png").exists() => b,
        _ => anyhow::bail!(
            "no Stage bitmaps at {} (cave.png, hospital_section.png); pass --bitmaps DIR",
            bitmaps.display()
        ),
    };
    if let Some(name) = &a.only {
        let (text, what) = bench_world(name, &bitmaps, a.threads)?;
        let dir = std::env::temp_dir().join(format!("troupe-bench-stage-{}", std::process::id()));
        std::fs::create_dir_all(&dir)?;
        let path = dir.join(format!("{name}.world"));
        std::fs::write(&path, text)?;
        let t_load = Instant::now();
        let world = troupe_stage::world::load(&path)?;
        let _ = std::fs::remove_dir_all(&dir);
        return run_world(a, name, world, t_load, &what, true);
    }
    writeln!(
        std::io::stdout().lock(),
        "troupe bench stage: {} simulated s per world, {} thread(s), every sensor every step, wander controllers, ranges {}",
        a.seconds,
        a.threads,
        if a.stage_ranges { "on Stage's raster" } else { "against the exact walls" }
    )?;
    let me = std::env::current_exe()?;
    let run = |what: &[&std::ffi::OsStr]| -> anyhow::Result<()> {
        let status = Command::new(&me)
            .args(["bench", "stage", "--seconds", &a.seconds.to_string()])
            .args(["--threads", &a.threads.to_string(), "--bitmaps"])
            .arg(&bitmaps)
            .args(a.stage_ranges.then_some("--stage-ranges"))
            .args(what)
            .status()?;
        anyhow::ensure!(status.success(), "bench world {what:?} failed: {status}");
        Ok(())
    };
    for name in ["simple", "pioneers100", "hospital1000"] {
        run(&["--only".as_ref(), name.as_ref()])?;
    }
    if let Some(dir) = &a.stage_worlds {
        let worlds = [dir.join("worlds"), dir.clone()]
            .into_iter()
            .find(|d| d.join("benchmark/cave.world").exists())
            .with_context(|| {
                format!(
                    "no benchmark/cave.world in {} or its worlds/: point --stage-worlds at a Stage checkout",
                    dir.display()
                )
            })?;
        for file in ["benchmark/cave.world", "benchmark/hospital.world"] {
            run(&["--world".as_ref(), worlds.join(file).as_os_str()])?;
        }
    }
    if a.parry {
        crate::raybench::run(&bitmaps)?;
    }
    Ok(())
}

/// Runs `world` for the bench's seconds and prints its row; every ranger
/// is sensed every step, or (as Stage does) only those its controllers read.
fn run_world(
    a: &StageBenchArgs,
    name: &str,
    world: troupe_stage::world::World,
    t_load: Instant,
    what: &str,
    every_sensor: bool,
) -> anyhow::Result<()> {
    let mut sim = troupe_stage::sim::Sim::new(world).map_err(|e| anyhow::anyhow!(e))?;
    sim.stage_ranges(a.stage_ranges);
    if !every_sensor {
        // No client: only what the controllers read.
        sim.sense_only([]);
    }
    let load = t_load.elapsed();
    let steps = (a.seconds / sim.world().interval_sim).round() as u64;
    let t0 = Instant::now();
    for _ in 0..steps {
        sim.step();
    }
    let wall = t0.elapsed().as_secs_f64();
    let moving = sim
        .bases
        .iter()
        .filter(|b| b.vel.x != 0.0 || b.vel.yaw != 0.0)
        .count();
    writeln!(
        std::io::stdout().lock(),
        "  {name:<13} {:>8.0}x real time  {:>7.1} MB peak  {:>6.1} MB data  ({what}; {:.0} simulated s in {wall:.2} s, load {:.2} s, {moving}/{} moving at the end)",
        sim.time / wall,
        peak_rss_mb(),
        anon_rss_mb(),
        sim.time,
        load.as_secs_f64(),
        sim.bases.len()
    )?;
    Ok(())
}
