//! `troupe bench record`: the recorder and the player under the
//! 100-Pioneer world run flat out, and `log info` on a large file.

use std::collections::{BTreeMap, HashMap};
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Args;
use std::io::Write;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use troupe_msgs::{codec, keys};
use troupe_node::zenoh::Wait;
use troupe_node::{Mode, ZenohArgs};
use troupe_record::{each_message, record, Compress, Files, RecordArgs, Schema, ENCODING};

/// Flags of `troupe bench record`.
#[derive(Debug, Args)]
pub struct RecordBenchArgs {
    /// Wall seconds to record the 100-Pioneer world.
    #[arg(long, default_value_t = 20.0, value_name = "SECS", value_parser = troupe_node::args::seconds)]
    pub seconds: f64,
    /// Size of the file `log info` is timed on, MB.
    #[arg(long, value_name = "MB", default_value_t = 1000)]
    pub info_mb: u64,
    /// Where Stage's sample bitmaps are (cave.png).
    #[arg(long, value_name = "DIR")]
    pub bitmaps: Option<PathBuf>,
}

/// `troupe bench record`: the 100-Pioneer world (100 lasers, 100 sonar
/// rings, 100 odometries every 100 simulated ms) run flat out and recorded
/// whole; what was lost, the recorder's CPU and bytes per second; the file
/// played back as fast as a subscriber takes it; `log info` on a large file.
pub fn run(a: &RecordBenchArgs) -> anyhow::Result<()> {
    let bitmaps = crate::harness::stage_bitmaps(a.bitmaps.as_deref())?;
    let dir = std::env::temp_dir().join(format!("troupe-bench-record-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let mut out = std::io::stdout().lock();
    writeln!(out, "troupe bench record: 100 Pioneers (16 sonars, 180-beam laser, odometry) flat out, recorded for {} s", a.seconds)?;
    let (mut launcher, router) = crate::harness::p100_stack(&dir, &bitmaps, -1.0)?;
    let z = ZenohArgs {
        connect: vec![router.clone()],
        no_multicast: true,
        ..Default::default()
    };
    let result = (|| -> anyhow::Result<()> {
        // The world's own speed, before anything records it.
        let alone = {
            let watcher = z.open(Mode::Client)?;
            // The first tick heard and the last: (wall, simulated).
            type Ticks = Option<((Instant, f64), (Instant, f64))>;
            let clock = Arc::new(std::sync::Mutex::new(Ticks::None));
            let seen = clock.clone();
            let sub = watcher
                .declare_subscriber(keys::SIM_CLOCK)
                .callback(move |s| {
                    if let Ok(t) = codec::decode::<troupe_msgs::sim::Clock>(&s.payload().to_bytes())
                    {
                        let now = (Instant::now(), t.msg.time);
                        let mut c = seen
                            .lock()
                            .unwrap_or_else(std::sync::PoisonError::into_inner);
                        *c = Some((c.map_or(now, |(first, _)| first), now));
                    }
                })
                .wait()
                .map_err(|e| anyhow::anyhow!("watching the clock: {e}"))?;
            std::thread::sleep(Duration::from_secs(3));
            drop(sub);
            let c = clock
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            match *c {
                Some((a, b)) if b.0 > a.0 => (b.1 - a.1) / (b.0 - a.0).as_secs_f64(),
                _ => 0.0,
            }
        };
        let file = dir.join("p100.mcap");
        let wall = recorded(
            &mut out,
            &z,
            launcher.id(),
            a.seconds,
            &file,
            alone,
            "record",
        )?;
        // Again with a live view and a Player client through the bridge:
        // what they take goes out of the simulator beside the recorder's.
        {
            let (_view, _) =
                crate::harness::server(&router, &["view", "--port", "0"], "troupe view: ")?;
            let (_bridge, addr) = crate::harness::server(
                &router,
                &["bridge", "--port", "6665=127.0.0.1:0"],
                "troupe bridge: robot 6665 on ",
            )?;
            let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
            let reader = crate::bridge::push_reader(
                addr.parse()?,
                &[
                    (troupe_msgs::Interface::Position2d, 0),
                    (troupe_msgs::Interface::Ranger, 0),
                    (troupe_msgs::Interface::Ranger, 1),
                ],
                stop.clone(),
            )?;
            let attached = dir.join("p100-attached.mcap");
            let took = recorded(
                &mut out,
                &z,
                launcher.id(),
                a.seconds,
                &attached,
                alone,
                "record, view and bridge",
            )?;
            stop.store(true, std::sync::atomic::Ordering::Relaxed);
            let got = reader.join().unwrap_or(0);
            writeln!(
                out,
                "    meanwhile a Player client (PUSH, robot 6665's position2d and two rangers) read {got} messages through the bridge ({:.0}/s), and `troupe view` served its page",
                got as f64 / took
            )?;
            std::fs::remove_file(&attached)?;
        }

        // Played back as fast as a subscriber takes it.
        let sink = ZenohArgs {
            namespace: Some("benchplay".into()),
            ..z.clone()
        }
        .open(Mode::Client)?;
        let got = Arc::new(AtomicU64::new(0));
        let counter = got.clone();
        let _sub = sink
            .declare_subscriber("**")
            .callback(move |_| {
                counter.fetch_add(1, Ordering::Relaxed);
            })
            .wait()
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        let player = std::process::Command::new(std::env::current_exe()?)
            .args(z.to_child_args())
            .args(["--namespace", "benchplay", "play"])
            .arg(&file)
            .args(["--rate", "0"])
            .output()?;
        let played = String::from_utf8_lossy(&player.stdout);
        anyhow::ensure!(
            player.status.success(),
            "play failed: {}",
            String::from_utf8_lossy(&player.stderr)
        );
        // The player has sent everything when it exits; the last of it may
        // still be on its way through the router to the subscriber (reading
        // the count at once said 219 of 717,698 were missing).
        let n: u64 = played
            .split_whitespace()
            .nth(1)
            .and_then(|w| w.parse().ok())
            .context("play's count of messages")?;
        let deadline = Instant::now() + Duration::from_secs(10);
        while got.load(Ordering::Relaxed) < n && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(10));
        }
        let received = got.load(Ordering::Relaxed);
        writeln!(
            out,
            "  play --rate 0, into a subscriber: {} ({received} received{})",
            played.trim(),
            if received < n {
                ", the rest not within 10 s of the end: LOST"
            } else {
                ""
            }
        )?;
        drop(sink);

        // `log info` on a large file, made of this recording over and over.
        let big = dir.join("big.mcap");
        {
            let mut files = Files::new(big.clone(), false, Compress::None);
            files.open(0)?;
            let mut shift = 0u64;
            while files.bytes() < a.info_mb * 1_000_000 {
                each_message(&file, |m| {
                    files.write(
                        m.topic,
                        Schema::troupe(m.schema, m.encoding),
                        m.encoding,
                        m.data,
                        m.log_time + shift,
                        m.publish_time,
                    )?;
                    Ok(true)
                })?;
                shift += (wall * 1e9) as u64;
            }
            files.close()?;
        }
        let size = std::fs::metadata(&big)?.len();
        let t = Instant::now();
        let info = std::process::Command::new(std::env::current_exe()?)
            .args(["log", "info"])
            .arg(&big)
            .output()?;
        let took = t.elapsed().as_secs_f64();
        anyhow::ensure!(
            info.status.success(),
            "log info failed: {}",
            String::from_utf8_lossy(&info.stderr)
        );
        writeln!(
            out,
            "  log info on a {:.0} MB file: {:.3} s (the summary only; target under 1 s)",
            size as f64 / 1e6,
            took
        )?;

        // The recording as ROS 2 and as Foxglove messages, converted whole.
        let messages = message_count(&file)?;
        let from = std::fs::metadata(&file)?.len();
        for format in ["ros2", "foxglove"] {
            let to_file = dir.join(format!("{format}.mcap"));
            let t = Instant::now();
            let export = std::process::Command::new(std::env::current_exe()?)
                .args(["log", "export", "--format", format, "-o"])
                .arg(&to_file)
                .arg(&file)
                .output()?;
            let took = t.elapsed().as_secs_f64().max(1e-9);
            anyhow::ensure!(
                export.status.success(),
                "log export --format {format} failed: {}",
                String::from_utf8_lossy(&export.stderr)
            );
            let to = std::fs::metadata(&to_file)?.len();
            writeln!(
                out,
                "  log export --format {format}: {messages} messages, {:.1} MB to {:.1} MB in {took:.2} s: \
                 {:.0} messages/s, {:.1} MB/s read (the process's start included)",
                from as f64 / 1e6,
                to as f64 / 1e6,
                messages as f64 / took,
                from as f64 / 1e6 / took
            )?;
        }
        Ok(())
    })();
    let _ = nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(i32::try_from(launcher.id()).unwrap_or(0)),
        nix::sys::signal::Signal::SIGTERM,
    );
    let _ = launcher.wait();
    let _ = std::fs::remove_dir_all(&dir);
    result
}

/// Records the running 100-Pioneer world to `file` for `seconds` and prints
/// its row under `label`: messages, bytes, what was lost, the recorder's
/// CPU and the launcher's (the router). Returns the wall seconds taken.
fn recorded(
    out: &mut impl Write,
    z: &ZenohArgs,
    launcher: u32,
    seconds: f64,
    file: &std::path::Path,
    alone: f64,
    label: &str,
) -> anyhow::Result<f64> {
    // The launcher holds the router: what it forwards, it pays for.
    let router_cpu0 = crate::harness::cpu_of(launcher);
    let (cpu0, t0) = (crate::harness::cpu_time(), Instant::now());
    record(
        RecordArgs {
            keys: Vec::new(),
            output: file.to_path_buf(),
            duration: Some(seconds),
            split_size: None,
            split_duration: None,
            compress: Compress::None,
            queue: 100_000,
            format: troupe_record::RecordFormat::Troupe,
            rosbag2: false,
        },
        z,
    )?;
    let (cpu, wall) = (
        crate::harness::cpu_time()
            .saturating_sub(cpu0)
            .as_secs_f64(),
        t0.elapsed().as_secs_f64(),
    );
    let router_cpu = crate::harness::cpu_of(launcher)
        .saturating_sub(router_cpu0)
        .as_secs_f64();

    // What was lost: each device publishes once per step, so between its
    // first and last stamp it owes one message per 100 ms. (Not the
    // simulator's poses for viewers: it sends those at most 30 times a
    // wall second by design.)
    let mut stamps: HashMap<String, (f64, f64, u64)> = HashMap::new();
    let (mut count, mut bytes) = (0u64, 0u64);
    each_message(file, |m| {
        if m.encoding != ENCODING || m.schema == "simulation/poses@1" {
            return Ok(true);
        }
        count += 1;
        bytes += m.data.len() as u64;
        let t = m.publish_time as f64 / 1e9;
        let e = stamps
            .entry(format!("{}#{}", m.topic, m.schema))
            .or_insert((t, t, 0));
        e.0 = e.0.min(t);
        e.1 = e.1.max(t);
        e.2 += 1;
        Ok(true)
    })?;
    let owed: u64 = stamps
        .values()
        .map(|(first, last, _)| ((last - first) / 0.1).round() as u64 + 1)
        .sum();
    let sim = stamps
        .get("sim/clock#sim/clock@1")
        .map_or(0.0, |(f, l, _)| l - f);
    // Where the losses are, by message kind.
    let mut by_kind: BTreeMap<&str, (u64, u64)> = BTreeMap::new();
    for (key, (first, last, n)) in &stamps {
        let kind = key.rsplit_once('#').map_or("?", |(_, k)| k);
        let e = by_kind.entry(kind).or_default();
        e.0 += ((last - first) / 0.1).round() as u64 + 1;
        e.1 += n;
    }
    writeln!(
        out,
        "  {label}: {count} messages, {:.1} MB in {wall:.1} s ({:.0} messages/s, {:.1} MB/s); the world ran {:.1}x real time ({alone:.1}x before the recorder joined); lost {} of {owed}; recorder CPU {cpu:.1} s = {:.0}% of one core; the launcher (its router) meanwhile {router_cpu:.2} s = {:.1}%",
        bytes as f64 / 1e6,
        count as f64 / wall,
        bytes as f64 / 1e6 / wall,
        sim / wall,
        owed.saturating_sub(count),
        100.0 * cpu / wall,
        100.0 * router_cpu / wall
    )?;
    for (kind, (owed, got)) in &by_kind {
        writeln!(out, "    {kind:<24} {got:>8} of {owed:>8}")?;
    }

    Ok(wall)
}

/// The messages of a recording, counted one by one.
fn message_count(file: &std::path::Path) -> anyhow::Result<u64> {
    let mut n = 0;
    each_message(file, |_| {
        n += 1;
        Ok(true)
    })?;
    Ok(n)
}
