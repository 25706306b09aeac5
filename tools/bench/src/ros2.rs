//! `troupe bench ros2`: what ROS 2 costs (`--ros2`, docs/ros2.md).
//!
//! 1. One laser, from a `dummy` driver process to a subscriber in this
//!    process, through a router here: the same scans on Troupe's key and as
//!    a ROS 2 `LaserScan` (a subscriber as rmw_zenoh declares one: its key,
//!    its token), in alternating rounds of the same run. One-way latency is
//!    the receiving wall clock less the scan's stamp (the driver's wall
//!    clock, on this machine); throughput is scans received per second with
//!    the driver publishing flat out. Target (issue 66): ROS 2 within 1.2x
//!    of Troupe's own key, both figures.
//! 2. The 100-Pioneer world as fast as the bench world lets it run (10x
//!    real time on this machine): the simulator's speed and its CPU per
//!    simulated second without
//!    `--ros2`, with it and no ROS 2 subscriber, and with a ROS 2 subscriber
//!    of every robot's laser and odometry, counting the samples lost (gaps
//!    in the attachments' sequence numbers). Target: 0 lost, the speed
//!    within 10%.

use std::collections::HashMap;
use std::io::Write;
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::Context;
use troupe_msgs::{codec, keys, laser, sim};
use troupe_node::zenoh::{Session, Wait};
use troupe_node::{Mode, ZenohArgs};
use troupe_ros2::msg::{LaserScan, Odometry};
use troupe_ros2::rmw::{self, Attachment, Distro, Kind, Qos};

use crate::harness::{percentile, us, Kid};

/// Flags of `troupe bench ros2`.
#[derive(Debug, clap::Args)]
pub struct Ros2BenchArgs {
    /// Seconds of each round (three of each kind, alternating).
    #[arg(long, default_value_t = 3.0, value_name = "SECS", value_parser = troupe_node::args::seconds)]
    pub seconds: f64,
    /// The laser driver's rate, Hz (flat out for the throughput figure).
    #[arg(long, default_value_t = 1000.0, value_parser = troupe_node::args::finite)]
    pub rate: f64,
    /// Seconds the 100-Pioneer world runs for each of its rows (0: skip it).
    #[arg(long, default_value_t = 10.0, value_name = "SECS", value_parser = troupe_node::args::seconds)]
    pub fleet_seconds: f64,
    /// Where Stage's sample bitmaps are (cave.png), for the 100-Pioneer world.
    #[arg(long, value_name = "DIR")]
    pub bitmaps: Option<std::path::PathBuf>,
}

/// Runs `troupe bench ros2`.
pub fn run(a: &Ros2BenchArgs) -> anyhow::Result<()> {
    laser_rounds(a)?;
    if a.fleet_seconds > 0.0 {
        let bitmaps = crate::harness::stage_bitmaps(a.bitmaps.as_deref())?;
        let dir = std::env::temp_dir().join(format!("troupe-bench-ros2-{}", std::process::id()));
        std::fs::create_dir_all(&dir)?;
        let r = fleet(a, &bitmaps, &dir);
        let _ = std::fs::remove_dir_all(&dir);
        r?;
    }
    Ok(())
}

/// Latencies and a count, filled by a subscriber's callback.
#[derive(Default)]
struct Got {
    lat: Mutex<Vec<Duration>>,
    n: AtomicU64,
}

impl Got {
    /// A sample stamped `stamp` arrived at `now` (read before decoding it:
    /// the decoder is the bench's, not the path's; a ROS 2 node's own
    /// CDR decoding copies the arrays whole).
    fn take(&self, stamp: f64, now: f64) {
        let d = Duration::from_secs_f64((now - stamp).max(0.0));
        self.lat.lock().unwrap_or_else(|p| p.into_inner()).push(d);
        self.n.fetch_add(1, Ordering::Relaxed);
    }
}

/// The ROS 2 key and subscription token of `/robot_6665/scan`, as an
/// rmw_zenoh node on `session` declares them.
fn ros_subscription(session: &Session, topic: &str, ty: &str) -> (String, String) {
    let hash = rmw::type_hash(ty, Distro::Jazzy).unwrap_or(rmw::NO_TYPE_HASH);
    let node = rmw::Node {
        domain: 0,
        zid: session.zid().to_string(),
        nid: 0,
        namespace: "/".into(),
        name: "bench".into(),
    };
    (
        rmw::topic_key(0, topic, ty, hash),
        node.entity_token(1, Kind::Subscription, topic, ty, hash, Qos::DEFAULT),
    )
}

fn laser_rounds(a: &Ros2BenchArgs) -> anyhow::Result<()> {
    let router = ZenohArgs {
        listen: vec!["tcp/127.0.0.1:0".into()],
        no_multicast: true,
        ..Default::default()
    }
    .open(Mode::Router)?;
    let endpoint = troupe_node::locators(&router)
        .into_iter()
        .next()
        .context("the router's locator")?;
    let z = ZenohArgs {
        connect: vec![endpoint.clone()],
        listen: vec!["tcp/127.0.0.1:0".into()],
        no_multicast: true,
        ..Default::default()
    };
    let _driver = Kid(Command::new(std::env::current_exe()?)
        .args(z.to_child_args())
        .args(["node", "dummy", "--provides", "laser:0", "-o"])
        .arg(format!("rate={}", a.rate))
        .arg("--ros2")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()?);
    let session = z.open(Mode::Peer)?;
    let laser = troupe_msgs::Device::new(6665, troupe_msgs::Interface::Laser, 0);
    troupe_node::wait_live(&session, &laser, Duration::from_secs(30))?;

    let (ros_key, token) =
        ros_subscription(&session, "/robot_6665/scan", "sensor_msgs/msg/LaserScan");
    let troupe_key = keys::data(&laser);
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "troupe bench ros2: a 361-beam laser from a dummy driver process at {} Hz, one way, {} s rounds",
        a.rate, a.seconds
    )?;
    writeln!(
        out,
        "  {:<34} {:>9} {:>9} {:>12}",
        "", "p50", "p99", "scans/s"
    )?;
    let (mut troupe, mut ros) = (Vec::new(), Vec::new());
    let (mut troupe_rate, mut ros_rate) = (Vec::new(), Vec::new());
    for _ in 0..3 {
        for kind in ["troupe", "ros2"] {
            let got = Arc::new(Got::default());
            let g = got.clone();
            let (sub, _token) = if kind == "troupe" {
                let s = session
                    .declare_subscriber(&troupe_key)
                    .callback(move |s| {
                        let now = troupe_node::Clock::wall().now();
                        if let Ok(m) = codec::decode::<laser::Scan>(&s.payload().to_bytes()) {
                            g.take(m.stamp, now);
                        }
                    })
                    .wait()
                    .map_err(|e| anyhow::anyhow!("subscribing to {troupe_key}: {e}"))?;
                (s, None)
            } else {
                let s = session
                    .declare_subscriber(&ros_key)
                    .callback(move |s| {
                        let now = troupe_node::Clock::wall().now();
                        let has = s
                            .attachment()
                            .and_then(|b| Attachment::parse(&b.to_bytes()))
                            .is_some();
                        let bytes = s.payload().to_bytes();
                        if let (true, Ok(m)) = (has, cdr::deserialize::<LaserScan>(&bytes)) {
                            g.take(m.header.stamp.ns() as f64 * 1e-9, now);
                        }
                    })
                    .wait()
                    .map_err(|e| anyhow::anyhow!("subscribing to {ros_key}: {e}"))?;
                let t = session
                    .liveliness()
                    .declare_token(&token)
                    .wait()
                    .map_err(|e| anyhow::anyhow!("declaring {token}: {e}"))?;
                (s, Some(t))
            };
            // Matched and flowing before the round counts.
            std::thread::sleep(Duration::from_millis(500));
            got.lat.lock().unwrap_or_else(|p| p.into_inner()).clear();
            let n0 = got.n.load(Ordering::Relaxed);
            let t0 = Instant::now();
            std::thread::sleep(Duration::from_secs_f64(a.seconds));
            let rate = (got.n.load(Ordering::Relaxed) - n0) as f64 / t0.elapsed().as_secs_f64();
            drop(sub);
            let lat = std::mem::take(&mut *got.lat.lock().unwrap_or_else(|p| p.into_inner()));
            if kind == "troupe" {
                troupe.extend(lat);
                troupe_rate.push(rate);
            } else {
                ros.extend(lat);
                ros_rate.push(rate);
            }
        }
    }
    troupe.sort();
    ros.sort();
    let med = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(0.0)
    };
    let (tr, rr) = (med(&mut troupe_rate), med(&mut ros_rate));
    for (name, v, r) in [
        ("Troupe's key (robot/6665/laser/0)", &troupe, tr),
        ("ROS 2 (/robot_6665/scan)", &ros, rr),
    ] {
        writeln!(
            out,
            "  {name:<34} {:>9} {:>9} {r:>12.0}",
            us(percentile(v, 0.5)),
            us(percentile(v, 0.99)),
        )?;
    }
    let ratio =
        percentile(&ros, 0.5).as_secs_f64() / percentile(&troupe, 0.5).as_secs_f64().max(1e-9);
    writeln!(
        out,
        "  ROS 2 / Troupe: p50 {ratio:.2}x, throughput {:.2}x (target: latency at most 1.2x, throughput at least 1/1.2)",
        rr / tr.max(1e-9)
    )?;
    Ok(())
}

/// The simulator's speed over `secs` wall seconds: simulated seconds per
/// wall second, read from `sim/clock`.
fn sim_speed(session: &Session, secs: f64) -> anyhow::Result<f64> {
    let last = Arc::new(Mutex::new(0.0f64));
    let l = last.clone();
    let _sub = session
        .declare_subscriber(keys::SIM_CLOCK)
        .callback(move |s| {
            if let Ok(c) = codec::decode::<sim::Clock>(&s.payload().to_bytes()) {
                *l.lock().unwrap_or_else(|p| p.into_inner()) = c.msg.time;
            }
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("subscribing to sim/clock: {e}"))?;
    std::thread::sleep(Duration::from_millis(500));
    let s0 = *last.lock().unwrap_or_else(|p| p.into_inner());
    let t0 = Instant::now();
    std::thread::sleep(Duration::from_secs_f64(secs));
    let s1 = *last.lock().unwrap_or_else(|p| p.into_inner());
    Ok((s1 - s0) / t0.elapsed().as_secs_f64())
}

/// Samples and sequence gaps per publisher (by GID), of ROS 2 samples.
#[derive(Default)]
struct Seqs {
    last: Mutex<HashMap<[u8; 16], i64>>,
    samples: AtomicU64,
    lost: AtomicU64,
    bad: AtomicU64,
}

impl Seqs {
    fn take(&self, a: Option<Attachment>, decodes: bool) {
        let Some(a) = a.filter(|_| decodes) else {
            self.bad.fetch_add(1, Ordering::Relaxed);
            return;
        };
        self.samples.fetch_add(1, Ordering::Relaxed);
        let mut last = self.last.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(prev) = last.insert(a.gid, a.seq) {
            let gap = a.seq - prev - 1;
            if gap > 0 {
                self.lost.fetch_add(gap as u64, Ordering::Relaxed);
            }
        }
    }
}

fn fleet(
    a: &Ros2BenchArgs,
    bitmaps: &std::path::Path,
    dir: &std::path::Path,
) -> anyhow::Result<()> {
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "troupe bench ros2: {} Pioneers at full speed (odometry, 16 sonars, 180-beam laser each), {} s per row",
        crate::harness::ROBOTS,
        a.fleet_seconds
    )?;
    let mut speeds = Vec::new();
    // Without --ros2; with it and no ROS 2 subscriber; with every laser and
    // odometry subscribed.
    for (flag, ros2) in [(false, false), (true, false), (true, true)] {
        let extra: &[&str] = if flag { &["--ros2"] } else { &[] };
        let (launcher, router) = crate::harness::p100_stack_with(dir, bitmaps, -1.0, extra)?;
        let _launcher = Kid(launcher);
        let z = ZenohArgs {
            connect: vec![router],
            no_multicast: true,
            ..Default::default()
        };
        let session = z.open(Mode::Client)?;
        let seqs = Arc::new(Seqs::default());
        let mut subs = Vec::new();
        if ros2 {
            for (topic, ty) in [
                ("/*/ranger_1", "sensor_msgs/msg/LaserScan"),
                ("/*/odom", "nav_msgs/msg/Odometry"),
            ] {
                let (key, _) = ros_subscription(&session, topic, ty);
                let topic = topic.to_owned();
                let s = seqs.clone();
                let is_scan = ty.ends_with("LaserScan");
                subs.push(
                    session
                        .declare_subscriber(key)
                        .callback(move |sample| {
                            let att = sample
                                .attachment()
                                .and_then(|b| Attachment::parse(&b.to_bytes()));
                            let bytes = sample.payload().to_bytes();
                            let decodes = if is_scan {
                                cdr::deserialize::<LaserScan>(&bytes).is_ok()
                            } else {
                                cdr::deserialize::<Odometry>(&bytes).is_ok()
                            };
                            s.take(att, decodes);
                        })
                        .wait()
                        .map_err(|e| anyhow::anyhow!("subscribing to ROS 2 {topic}: {e}"))?,
                );
            }
        }
        let stage = crate::harness::node_pid(_launcher.0.id(), "stage");
        let cpu0 = stage.map(crate::harness::cpu_of);
        let speed = sim_speed(&session, a.fleet_seconds)?;
        let cpu = match (stage, cpu0) {
            (Some(p), Some(c0)) => {
                (crate::harness::cpu_of(p) - c0).as_secs_f64() / (speed * a.fleet_seconds).max(1e-9)
            }
            _ => f64::NAN,
        };
        let (n, lost, bad) = (
            seqs.samples.load(Ordering::Relaxed),
            seqs.lost.load(Ordering::Relaxed),
            seqs.bad.load(Ordering::Relaxed),
        );
        let who = match (flag, ros2) {
            (false, _) => "without --ros2",
            (true, false) => "--ros2, no ROS 2 subscriber",
            (true, true) => "--ros2, every laser and odometry subscribed",
        };
        write!(
            out,
            "  {who:<46} {speed:>7.2}x real time, the simulator {:>5.1} ms CPU per simulated s",
            cpu * 1e3
        )?;
        if ros2 {
            let topics = seqs.last.lock().unwrap_or_else(|p| p.into_inner()).len();
            write!(
                out,
                "  {n} ROS 2 samples on {topics} topics, {lost} lost, {bad} without attachment or undecodable"
            )?;
        }
        writeln!(out)?;
        speeds.push(speed);
        drop(subs);
    }
    if let [without, idle, with] = speeds[..] {
        writeln!(
            out,
            "  with ROS 2 / without: {:.3} subscribed, {:.3} not (target: within 10%, and 0 lost)",
            with / without.max(1e-9),
            idle / without.max(1e-9)
        )?;
    }
    Ok(())
}
