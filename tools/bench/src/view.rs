//! `troupe bench view`: the view under load. The 100-Pioneer world runs in
//! real time (each robot its own port, odometry, sonars and laser), `troupe
//! view` serves it, and headless browsers (Debian's chromium) keep its page
//! open; each page reports how many frames a second it draws. For each
//! count of browsers: their frame rates, the view server's CPU, and the
//! robots' data rates, which a browser must not slow.

use std::io::{BufRead, Read, Write};
use std::net::TcpStream;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;

use crate::harness::{Figures, Kid, Window, ROBOTS};
use troupe_msgs::Interface;
use troupe_node::{Mode, ZenohArgs};

/// `troupe bench view` options.
#[derive(Debug, clap::Args)]
pub struct ViewBenchArgs {
    /// Seconds measured for each count of browsers.
    #[arg(long, default_value_t = 10.0, value_name = "SECS", value_parser = troupe_node::args::seconds)]
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
    #[arg(long, default_value_t = 1.0, value_parser = troupe_node::args::finite)]
    pub speedup: f64,
    /// Run the browsers under SCHED_IDLE (`chrt --idle 0`): they get only
    /// the CPU the fleet and the view server leave, as browsers on other
    /// machines would take none of this one's. Without it, on a small
    /// machine, the browsers' own drawing competes with the simulator.
    #[arg(long)]
    pub idle_browsers: bool,
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

/// "lo-hi" of `values`, or "-" for none.
fn spread(values: impl Iterator<Item = f64>) -> String {
    let (lo, hi, n) = values.fold((f64::INFINITY, 0.0f64, 0), |(lo, hi, n), v| {
        (lo.min(v), hi.max(v), n + 1)
    });
    if n == 0 {
        "-".to_owned()
    } else {
        format!("{lo:.1}-{hi:.1}")
    }
}

/// One row of the table: `who` read the view, `pages` of them.
fn row(
    out: &mut impl Write,
    (who, pages): (&str, usize),
    fps: &str,
    draw_ms: &str,
    f: &Figures,
) -> std::io::Result<()> {
    let per = if pages > 0 {
        format!("{:.1}%", 100.0 * f.cpu / pages as f64)
    } else {
        "-".to_owned()
    };
    writeln!(
        out,
        "  {who:>8}  {fps:>17}  {draw_ms:>14}  {:>19.1}%  {per:>11}  {:>17.2}  {:>16.0}",
        100.0 * f.cpu,
        f.odometry,
        f.ranges
    )?;
    out.flush()
}

/// Runs `troupe bench view`.
pub fn run(a: &ViewBenchArgs) -> anyhow::Result<()> {
    let bitmaps = crate::harness::stage_bitmaps(a.bitmaps.as_deref())?;
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
    let (launcher, router) = crate::harness::p100_stack(dir, bitmaps, a.speedup)?;
    let launcher = Kid(launcher);
    let z = ZenohArgs {
        connect: vec![router.clone()],
        no_multicast: true,
        ..Default::default()
    };
    let (view, url) = crate::harness::server(&router, &["view", "--port", "0"], "troupe view: ")?;
    let host = url
        .trim_start_matches("http://")
        .trim_end_matches('/')
        .to_owned();

    // The robots' data, counted.
    let session = z.open(Mode::Client)?;
    let (_odo, odometry) = crate::harness::count(&session, Interface::Position2d)?;
    let (_rng, ranges) = crate::harness::count(&session, Interface::Ranger)?;

    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "troupe bench view: {ROBOTS} Pioneers in real time (odometry, 16 sonars, 180-beam laser each), `troupe view`, headless {}{}; {} s per row",
        a.chromium.display(),
        if a.idle_browsers { " at idle priority" } else { "" },
        a.seconds
    )?;
    writeln!(out, "  browsers  frames/s per page  ms to draw one  view CPU (of a core)  per browser  odometry Hz/robot  ranger samples/s")?;
    for (k, &n) in a.browsers.iter().enumerate() {
        let mut pages = Vec::new();
        for b in 0..n {
            let mut browser = if a.idle_browsers {
                let mut c = Command::new("chrt");
                c.args(["--idle", "0"]).arg(&a.chromium);
                c
            } else {
                Command::new(&a.chromium)
            };
            pages.push(Kid(browser
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
                .with_context(|| {
                    if a.idle_browsers {
                        "starting `chrt --idle 0 chromium` (chrt is util-linux's)"
                    } else {
                        "starting chromium"
                    }
                })?));
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
        let window = Window::start(Some(view.0.id()), &odometry, &ranges);
        std::thread::sleep(Duration::from_secs_f64(a.seconds));
        let figures = window.end(&odometry, &ranges);
        let reports: Vec<[f64; 2]> = serde_json::from_str::<
            std::collections::BTreeMap<String, [f64; 2]>,
        >(&get(&host, "/api/report")?)
        .unwrap_or_default()
        .into_values()
        .collect();
        row(
            &mut out,
            (&n.to_string(), n),
            &spread(reports.iter().map(|r| r[0])),
            &spread(reports.iter().map(|r| r[1])),
            &figures,
        )?;
        drop(pages);
    }
    if a.streams > 0 {
        let window = Window::start(Some(view.0.id()), &odometry, &ranges);
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
        let figures = window.end(&odometry, &ranges);
        let frames = readers
            .into_iter()
            .filter_map(|r| r.join().ok().and_then(Result::ok))
            .map(|f| f as f64 / figures.wall);
        row(
            &mut out,
            (&format!("{}+1", a.streams), a.streams),
            &spread(frames),
            "(no drawing)",
            &figures,
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
