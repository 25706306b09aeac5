//! `troupe bench camera`: what a camera driver spends to deliver its
//! frames.
//!
//! Player's `dummy` sends `--width` × `--height` RGB frames at `--rate` Hz,
//! launched as a user launches it (`troupe launch`, the embedded router),
//! and `--subscribers` processes of `troupe hz camera:0` take them. Over
//! `--seconds`, once every subscriber has had frames, the bench reads the
//! CPU time of the driver's process, of the launcher (the router is in it)
//! and of each subscriber: once with samples between processes over shared
//! memory, Troupe's default, and once through the network (`--no-shm`).

use std::io::Write;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Args;

use crate::harness::{cpu_of, launched, line_after, node_pid, Kid};

/// Flags of `troupe bench camera`.
#[derive(Debug, Args)]
pub struct CameraArgs {
    /// Pixels across.
    #[arg(long, default_value_t = 640)]
    pub width: u32,
    /// Pixels down.
    #[arg(long, default_value_t = 480)]
    pub height: u32,
    /// Frames a second.
    #[arg(long, default_value_t = 30.0, value_name = "HZ", value_parser = troupe_node::args::finite)]
    pub rate: f64,
    /// Processes taking every frame.
    #[arg(long, default_value_t = 2)]
    pub subscribers: usize,
    /// Wall seconds each path is measured for.
    #[arg(long, default_value_t = 10.0, value_name = "SECS", value_parser = troupe_node::args::seconds)]
    pub seconds: f64,
}

/// One path's CPU, as fractions of a core.
struct Row {
    driver: f64,
    launcher: f64,
    subscribers: Vec<f64>,
}

/// Runs `troupe bench camera`.
pub fn run(a: &CameraArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        a.seconds > 0.0 && a.rate > 0.0 && a.subscribers > 0,
        "--seconds, --rate and --subscribers must be positive"
    );
    let dir = std::env::temp_dir().join(format!("troupe-bench-camera-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let cfg = dir.join("camera.cfg");
    std::fs::write(
        &cfg,
        format!(
            "driver ( name \"dummy\" provides [\"camera:0\"] rate {} image_size [{} {}] )\n",
            a.rate, a.width, a.height
        ),
    )?;
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "troupe bench camera: {} x {} RGB ({} bytes) at {} Hz from Player's dummy to {} `troupe hz` processes, {} s a path",
        a.width,
        a.height,
        u64::from(a.width) * u64::from(a.height) * 3,
        a.rate,
        a.subscribers,
        a.seconds
    )?;
    for (path, extra) in [
        ("over shared memory", &[][..]),
        ("through TCP (--no-shm)", &["--no-shm"][..]),
    ] {
        let r = measure(a, &cfg, extra)?;
        let subs: Vec<String> = r
            .subscribers
            .iter()
            .map(|s| format!("{:.1}%", s * 100.0))
            .collect();
        let all = r.driver + r.launcher + r.subscribers.iter().sum::<f64>();
        writeln!(
            out,
            "  {path:<24} the driver {:>5.1}% of a core (target < 5%), the launcher and its router {:.1}%, subscribers {}; all {:.1}%",
            r.driver * 100.0,
            r.launcher * 100.0,
            subs.join(" "),
            all * 100.0
        )?;
    }
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}

/// Launches `cfg` with `extra`, starts the subscribers, and measures.
fn measure(a: &CameraArgs, cfg: &std::path::Path, extra: &[&str]) -> anyhow::Result<Row> {
    let (launcher, router, _) = launched(cfg, extra)?;
    let launcher = Kid(launcher);
    let mut subs = Vec::with_capacity(a.subscribers);
    for _ in 0..a.subscribers {
        let mut sub = Kid(Command::new(std::env::current_exe()?)
            .args(["--no-multicast", "--connect", &router])
            .args(extra)
            .args(["hz", "camera:0"])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .context("starting `troupe hz camera:0`")?);
        // Its first line comes once frames have.
        line_after(&mut sub.0, "rate:").context("`troupe hz camera:0` printed no rate")?;
        subs.push(sub);
    }
    let driver =
        node_pid(launcher.0.id(), "dummy").context("no dummy process under the launcher")?;
    let cpu = |subs: &[Kid]| -> (Duration, Duration, Vec<Duration>) {
        (
            cpu_of(driver),
            cpu_of(launcher.0.id()),
            subs.iter().map(|s| cpu_of(s.0.id())).collect(),
        )
    };
    let (t0, c0) = (Instant::now(), cpu(&subs));
    std::thread::sleep(Duration::from_secs_f64(a.seconds));
    let (wall, c1) = (t0.elapsed().as_secs_f64(), cpu(&subs));
    let share = |t1: Duration, t0: Duration| t1.saturating_sub(t0).as_secs_f64() / wall;
    Ok(Row {
        driver: share(c1.0, c0.0),
        launcher: share(c1.1, c0.1),
        subscribers: c1.2.iter().zip(&c0.2).map(|(&b, &a)| share(b, a)).collect(),
    })
}
