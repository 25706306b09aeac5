//! `troupe bench view`: the view under load. The 100-Pioneer world runs in
//! real time (each robot its own port, odometry, sonars and laser), `troupe
//! view` serves it, and headless browsers (Debian's chromium) keep its page
//! open; each page reports how many frames a second it draws. For each
//! count of browsers: their frame rates, the view server's CPU, and the
//! robots' data rates, which a browser must not slow.

use std::io::{BufRead, Read, Write};
use std::net::TcpStream;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use troupe_msgs::{keys, Interface};
use troupe_node::zenoh::Wait;
use troupe_node::{Mode, ZenohArgs};

/// `troupe bench view` options.
#[derive(Debug, clap::Args)]
pub struct ViewBenchArgs {
    /// Seconds measured for each count of browsers.
    #[arg(long, default_value_t = 10.0)]
    pub seconds: f64,
    /// Counts of browsers to measure with, in turn.
    #[arg(long, value_delimiter = ',', default_value = "0,1,20")]
    pub browsers: Vec<usize>,
    /// Where Stage's sample bitmaps are (cave.png).
    #[arg(long, value_name = "DIR")]
    pub bitmaps: Option<PathBuf>,
    /// The browser to run headless.
    #[arg(long, default_value = "chromium")]
    pub chromium: PathBuf,
    /// Then this many plain readers of the frame stream (no drawing: the
    /// server's own load, without browsers competing for the CPU), and one
    /// stuck reader that never reads.
    #[arg(long, default_value_t = 20)]
    pub streams: usize,
    /// The world's speed against real time.
    #[arg(long, default_value_t = 1.0)]
    pub speedup: f64,
}

/// Robots in the world.
const ROBOTS: u32 = 100;

/// A process killed when dropped.
struct Kid(Child);

impl Drop for Kid {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// CPU time of process `pid` so far.
fn cpu_of(pid: u32) -> Duration {
    use nix::time::{clock_getcpuclockid, clock_gettime};
    let pid = nix::unistd::Pid::from_raw(i32::try_from(pid).unwrap_or(0));
    clock_getcpuclockid(pid)
        .and_then(clock_gettime)
        .map_or(Duration::ZERO, Duration::from)
}

/// GET `path` from the view at `host` (`127.0.0.1:PORT`): the body.
fn get(host: &str, path: &str) -> anyhow::Result<String> {
    let mut s = TcpStream::connect(host)?;
    s.set_read_timeout(Some(Duration::from_secs(10)))?;
    write!(s, "GET {path} HTTP/1.0\r\nHost: {host}\r\n\r\n")?;
    let mut all = String::new();
    s.read_to_string(&mut all)?;
    Ok(all
        .split_once("\r\n\r\n")
        .map(|(_, b)| b.to_owned())
        .unwrap_or_default())
}

/// The first line of `child`'s stdout that starts with `prefix`, less it.
fn line_after(child: &mut Child, prefix: &str) -> anyhow::Result<String> {
    let out = child.stdout.take().context("stdout")?;
    let mut lines = std::io::BufReader::new(out).lines();
    while let Some(Ok(line)) = lines.next() {
        if let Some(rest) = line.strip_prefix(prefix) {
            // Keep draining, so the child never blocks on a full pipe.
            std::thread::spawn(move || lines.for_each(drop));
            return Ok(rest.trim().to_owned());
        }
    }
    anyhow::bail!("no `{prefix}` line")
}

/// Runs `troupe bench view`.
pub fn run(a: &ViewBenchArgs) -> anyhow::Result<()> {
    let bitmaps = crate::bench::stage_bitmaps(a.bitmaps.as_deref())?;
    if a.browsers.iter().any(|&n| n > 0) {
        Command::new(&a.chromium)
            .arg("--version")
            .stdout(Stdio::null())
            .status()
            .with_context(|| {
                format!(
                    "cannot run {} (apt-get install chromium, or --chromium PATH)",
                    a.chromium.display()
                )
            })?;
    }
    let dir = std::env::temp_dir().join(format!("troupe-bench-view-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let result = measure(a, &bitmaps, &dir);
    let _ = std::fs::remove_dir_all(&dir);
    result
}

fn measure(
    a: &ViewBenchArgs,
    bitmaps: &std::path::Path,
    dir: &std::path::Path,
) -> anyhow::Result<()> {
    let (launcher, router) = crate::bench::p100_stack(dir, bitmaps, a.speedup)?;
    let launcher = Kid(launcher);
    let z = ZenohArgs {
        connect: vec![router.clone()],
        no_multicast: true,
        ..Default::default()
    };
    let exe = std::env::current_exe()?;
    let mut view = Kid(Command::new(&exe)
        .args([
            "--no-multicast",
            "--connect",
            &router,
            "view",
            "--port",
            "0",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()?);
    let url = line_after(&mut view.0, "troupe view: ")?;
    let host = url
        .trim_start_matches("http://")
        .trim_end_matches('/')
        .to_owned();

    // The robots' data, counted.
    let session = z.open(Mode::Client)?;
    let count = |i: Interface| -> anyhow::Result<_> {
        let n = Arc::new(AtomicU64::new(0));
        let c = n.clone();
        let sub = session
            .declare_subscriber(keys::data_of(i))
            .callback(move |_| {
                c.fetch_add(1, Ordering::Relaxed);
            })
            .wait()
            .map_err(|e| anyhow::anyhow!("subscribing to {i}: {e}"))?;
        Ok((sub, n))
    };
    let (_odo, odometry) = count(Interface::Position2d)?;
    let (_rng, ranges) = count(Interface::Ranger)?;

    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "troupe bench view: {ROBOTS} Pioneers in real time (odometry, 16 sonars, 180-beam laser each), `troupe view`, headless {}; {} s per row",
        a.chromium.display(),
        a.seconds
    )?;
    writeln!(out, "  browsers  frames/s per page  ms to draw one  view CPU (of a core)  per browser  odometry Hz/robot  ranger samples/s")?;
    for (k, &n) in a.browsers.iter().enumerate() {
        let mut pages = Vec::new();
        for b in 0..n {
            pages.push(Kid(Command::new(&a.chromium)
                .args([
                    "--headless",
                    "--no-sandbox",
                    "--disable-gpu",
                    "--mute-audio",
                    "--window-size=1000,700",
                ])
                .arg(format!(
                    "--user-data-dir={}",
                    dir.join(format!("chromium-{k}-{b}")).display()
                ))
                .arg(format!("{url}?report"))
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
                .context("starting chromium")?));
        }
        // Every page drawing and reporting (twice: its first report may
        // count its loading).
        let deadline = Instant::now() + Duration::from_secs(60);
        let reported = || -> usize {
            get(&host, "/api/report")
                .ok()
                .and_then(|b| {
                    serde_json::from_str::<std::collections::BTreeMap<String, [f64; 2]>>(&b).ok()
                })
                .map_or(0, |m| m.len())
        };
        while reported() < n {
            anyhow::ensure!(
                Instant::now() < deadline,
                "only {} of {n} pages reported within 60 s",
                reported()
            );
            std::thread::sleep(Duration::from_millis(200));
        }
        std::thread::sleep(Duration::from_secs(if n > 0 { 4 } else { 0 }));
        let (cpu0, o0, r0, t0) = (
            cpu_of(view.0.id()),
            odometry.load(Ordering::Relaxed),
            ranges.load(Ordering::Relaxed),
            Instant::now(),
        );
        std::thread::sleep(Duration::from_secs_f64(a.seconds));
        let wall = t0.elapsed().as_secs_f64();
        let cpu = (cpu_of(view.0.id()) - cpu0).as_secs_f64() / wall;
        let odo = (odometry.load(Ordering::Relaxed) - o0) as f64 / wall / f64::from(ROBOTS);
        let rng = (ranges.load(Ordering::Relaxed) - r0) as f64 / wall;
        let reports: Vec<[f64; 2]> = serde_json::from_str::<
            std::collections::BTreeMap<String, [f64; 2]>,
        >(&get(&host, "/api/report")?)
        .unwrap_or_default()
        .into_values()
        .collect();
        let range = |k: usize| {
            let (lo, hi) = reports.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), r| {
                (lo.min(r[k]), hi.max(r[k]))
            });
            if reports.is_empty() {
                "-".to_owned()
            } else {
                format!("{lo:.1}-{hi:.1}")
            }
        };
        let (pages_fps, draw_ms) = (range(0), range(1));
        let per = if n > 0 {
            format!("{:.1}%", 100.0 * cpu / n as f64)
        } else {
            "-".to_owned()
        };
        writeln!(
            out,
            "  {n:>8}  {pages_fps:>17}  {draw_ms:>14}  {:>19.1}%  {per:>11}  {odo:>17.2}  {rng:>16.0}",
            100.0 * cpu
        )?;
        out.flush()?;
        drop(pages);
    }
    if a.streams > 0 {
        let (cpu0, o0, r0, t0) = (
            cpu_of(view.0.id()),
            odometry.load(Ordering::Relaxed),
            ranges.load(Ordering::Relaxed),
            Instant::now(),
        );
        // One stuck reader: asks for the stream, never reads it.
        let mut stuck = TcpStream::connect(&host)?;
        write!(stuck, "GET /api/stream HTTP/1.1\r\nHost: {host}\r\n\r\n")?;
        let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
        let readers: Vec<_> = (0..a.streams)
            .map(|_| {
                let (host, stop) = (host.clone(), stop.clone());
                std::thread::spawn(move || -> anyhow::Result<u64> {
                    let mut s = TcpStream::connect(&host)?;
                    s.set_read_timeout(Some(Duration::from_secs(5)))?;
                    write!(s, "GET /api/stream HTTP/1.1\r\nHost: {host}\r\n\r\n")?;
                    let mut frames = 0;
                    for line in std::io::BufReader::new(s).lines() {
                        if stop.load(Ordering::Relaxed) {
                            break;
                        }
                        if line?.starts_with("data:") {
                            frames += 1;
                        }
                    }
                    Ok(frames)
                })
            })
            .collect();
        std::thread::sleep(Duration::from_secs_f64(a.seconds));
        stop.store(true, Ordering::Relaxed);
        let wall = t0.elapsed().as_secs_f64();
        let cpu = (cpu_of(view.0.id()) - cpu0).as_secs_f64() / wall;
        let odo = (odometry.load(Ordering::Relaxed) - o0) as f64 / wall / f64::from(ROBOTS);
        let rng = (ranges.load(Ordering::Relaxed) - r0) as f64 / wall;
        let frames: Vec<f64> = readers
            .into_iter()
            .filter_map(|r| r.join().ok().and_then(Result::ok))
            .map(|f| f as f64 / wall)
            .collect();
        let (lo, hi) = frames.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &f| {
            (lo.min(f), hi.max(f))
        });
        writeln!(
            out,
            "  {:>8}  {:>17}  {:>14}  {:>19.1}%  {:>11}  {odo:>17.2}  {rng:>16.0}",
            format!("{}+1", a.streams),
            format!("{lo:.1}-{hi:.1}"),
            "(no drawing)",
            100.0 * cpu,
            format!("{:.1}%", 100.0 * cpu / a.streams as f64),
        )?;
        writeln!(
            out,
            "  ({} plain stream readers and one that never reads, instead of browsers)",
            a.streams
        )?;
        drop(stuck);
    }
    drop(view);
    drop(launcher);
    Ok(())
}
