//! `troupe bench python`: the Python package under load.
//!
//! The bench is the router. A thread publishes 181-beam laser scans on
//! `robot/6665/laser/0` at `--rate` (far above any real laser), a queryable
//! answers the laser's geometry request; a Python process (the package as
//! installed for `--python`) reads scans in a `read()` loop and with
//! callbacks, then times geometry requests, and the Rust client times the
//! same request in the same run.

use std::io::{BufRead, BufReader, Write};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Args;
use troupe_msgs::{codec, keys, laser, Device, Interface, Pose3d, Size3d};
use troupe_node::zenoh::Wait;
use troupe_node::{Mode, ZenohArgs};

use crate::harness::{percentile, us};

/// Flags of `troupe bench python`.
#[derive(Debug, Args)]
pub struct PythonBenchArgs {
    /// The Python interpreter that has the package (`pip install ./python`).
    #[arg(long, default_value = "python3")]
    pub python: String,
    /// Scans published per second.
    #[arg(long, default_value_t = 20_000.0, value_parser = troupe_node::args::finite)]
    pub rate: f64,
    /// Seconds of each reading phase.
    #[arg(long, default_value_t = 3.0, value_name = "SECS", value_parser = troupe_node::args::seconds)]
    pub seconds: f64,
    /// Timed requests, from Python and from Rust.
    #[arg(long, default_value_t = 2000)]
    pub requests: usize,
}

/// Runs the bench.
///
/// # Errors
///
/// When the router cannot open or the Python side fails (the package not
/// installed for `--python`, say).
pub fn run(a: &PythonBenchArgs) -> anyhow::Result<()> {
    let mut out = std::io::stdout().lock();
    let ns = format!("bench-python-{}", std::process::id());
    let z = ZenohArgs {
        listen: vec!["tcp/127.0.0.1:0".into()],
        no_multicast: true,
        namespace: Some(ns.clone()),
        ..Default::default()
    };
    let session = z.open(Mode::Router)?;
    let endpoint = troupe_node::locators(&session)
        .into_iter()
        .next()
        .context("the bench router has no locator")?;
    let dev = Device::new(troupe_msgs::DEFAULT_ROBOT, Interface::Laser, 0);
    let geom = codec::encode(
        &laser::Geom {
            pose: Pose3d::default(),
            size: Size3d {
                width: 0.15,
                length: 0.15,
                height: 0.2,
            },
        },
        0.0,
    );
    let req_key = keys::req(&dev, "geom");
    let _queryable = session
        .declare_queryable(&req_key)
        .callback(move |q| {
            let _ = q.reply(q.key_expr().clone(), geom.clone()).wait();
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("serving {req_key}: {e}"))?;

    writeln!(
        out,
        "troupe bench python: 181-beam scans published at {:.0}/s, {} s per phase, {} requests",
        a.rate, a.seconds, a.requests
    )?;
    out.flush()?;
    let mut child = Command::new(&a.python)
        .arg("-c")
        .arg(include_str!("python_bench.py"))
        .args([
            endpoint.as_str(),
            ns.as_str(),
            &a.seconds.to_string(),
            &a.requests.to_string(),
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .with_context(|| format!("starting {}", a.python))?;
    let mut lines =
        BufReader::new(child.stdout.take().context("the Python side's stdout")?).lines();
    let quiet = lines.next().transpose()?;
    if quiet.as_deref() != Some("requests done") {
        let done = child.wait_with_output()?;
        anyhow::bail!(
            "the Python side failed (is the package installed for {}? `pip install ./python`):\n{}",
            a.python,
            String::from_utf8_lossy(&done.stderr)
        );
    }

    let stop = Arc::new(AtomicBool::new(false));
    let sent = Arc::new(AtomicU64::new(0));
    let started = Instant::now();
    let publisher = {
        let (session, stop, sent, rate) = (session.clone(), stop.clone(), sent.clone(), a.rate);
        let key = keys::data(&dev);
        std::thread::spawn(move || -> anyhow::Result<()> {
            let scan = laser::Scan {
                min_angle: -std::f32::consts::FRAC_PI_2,
                max_angle: std::f32::consts::FRAC_PI_2,
                resolution: std::f32::consts::PI / 180.0,
                max_range: 8.0,
                ranges: (0..181).map(|i| 1.0 + (i as f32) * 0.01).collect(),
                intensity: vec![0; 181],
                id: 0,
            };
            let publisher = session
                .declare_publisher(key)
                .wait()
                .map_err(|e| anyhow::anyhow!("publishing scans: {e}"))?;
            let start = Instant::now();
            let mut n = 0u64;
            while !stop.load(Ordering::Relaxed) {
                let stamp = start.elapsed().as_secs_f64();
                let _ = publisher.put(codec::encode(&scan, stamp)).wait();
                n += 1;
                sent.store(n, Ordering::Relaxed);
                // Pace to `rate`: sleep off any lead over the schedule.
                let due = Duration::from_secs_f64(n as f64 / rate);
                if let Some(ahead) = due.checked_sub(start.elapsed()) {
                    std::thread::sleep(ahead);
                }
            }
            Ok(())
        })
    };
    let last = lines.next().transpose()?.unwrap_or_default();
    let published = sent.load(Ordering::Relaxed) as f64 / started.elapsed().as_secs_f64();
    stop.store(true, Ordering::Relaxed);
    publisher
        .join()
        .map_err(|_| anyhow::anyhow!("the publisher panicked"))??;
    let done = child.wait_with_output()?;
    anyhow::ensure!(
        done.status.success(),
        "the Python side failed:\n{}",
        String::from_utf8_lossy(&done.stderr)
    );
    let figures: serde_json::Value =
        serde_json::from_str(&last).with_context(|| format!("the Python side printed {last:?}"))?;
    let f = |k: &str| figures[k].as_f64().unwrap_or(f64::NAN);

    // The same request from the Rust client, same router, same run.
    let rust = troupe_client::Client::connect(
        &ZenohArgs {
            connect: vec![endpoint.clone()],
            namespace: Some(ns),
            no_multicast: true,
            ..Default::default()
        },
        troupe_msgs::DEFAULT_ROBOT,
    )?;
    let proxy = troupe_client::LaserProxy::new(&rust, 0)?;
    let mut times = Vec::with_capacity(a.requests);
    for _ in 0..a.requests {
        let t = Instant::now();
        proxy.request_geom()?;
        times.push(t.elapsed());
    }
    times.sort();
    let rust_p50 = percentile(&times, 0.5);

    writeln!(
        out,
        "published          {published:>9.0} scans/s (what the Python side could take)"
    )?;
    writeln!(
        out,
        "read() loop        {:>9.0} scans/s  ({} ranges each as {}; the loop used {:.0}% of a core)",
        f("read_per_s"),
        f("beams"),
        if figures["numpy"].as_bool() == Some(true) { "a numpy array" } else { "a list" },
        f("read_cpu") * 100.0
    )?;
    writeln!(
        out,
        "callbacks          {:>9.0} scans/s",
        f("callbacks_per_s")
    )?;
    writeln!(
        out,
        "request round trip  Python p50 {:.0} µs (p99 {:.0} µs), Rust client p50 {}: {:.2}x",
        f("request_p50_us"),
        f("request_p99_us"),
        us(rust_p50),
        f("request_p50_us") / (rust_p50.as_secs_f64() * 1e6)
    )?;
    Ok(())
}
