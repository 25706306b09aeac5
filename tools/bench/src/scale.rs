//! `troupe bench scale`: how Troupe's costs grow with the number of robots.
//!
//! Each row launches a generated world as a user would: `troupe launch` of
//! a cfg that gives every robot its own port (position2d:0 and ranger:0),
//! with the launcher's embedded router. The robots are swarmbot-like (0.1
//! m, a ring of 12 one-beam IR rangers, Stage's `expand_swarm`
//! controller), in rooms of one large generated bitmap, the same map in
//! every row, so that what grows from row to row is the robots alone; the
//! first row has none, and what a robot adds to the simulator's memory is
//! read against it. A subscriber of `robot/**` in this process takes every
//! sample and counts what was lost: a device publishes once a step, so
//! between its first and last stamp in the window a key owes one sample
//! per `interval_sim`. Printed per row: how long until every device was
//! ready, how long `troupe list` took (a process of its own, as a user
//! runs it) and what it listed, the simulator's speed and CPU per
//! simulated second, its memory, samples delivered and lost, and the
//! launcher's CPU (the router is in it).

use std::collections::HashMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Args;
use troupe_client::{Client, SimulationProxy};
use troupe_msgs::{codec, keys, simulation};
use troupe_node::zenoh::Wait;

use crate::harness::{cpu_of, launched, node_pid, status_mb_of, Kid};

/// Flags of `troupe bench scale`.
#[derive(Debug, Args)]
pub struct ScaleArgs {
    /// Robots in each row, after a row of none (the map alone).
    #[arg(long, value_delimiter = ',', default_value = "10,100,1000,10000")]
    pub robots: Vec<u32>,
    /// Wall seconds each row is measured for, once every device is ready.
    #[arg(long, default_value_t = 10.0, value_name = "SECS", value_parser = troupe_node::args::seconds)]
    pub seconds: f64,
    /// The simulator's threads.
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// The world's `speedup`: 1 is real time, as a fleet runs; -1 flat out.
    #[arg(long, default_value_t = 1.0, allow_hyphen_values = true, value_parser = troupe_node::args::finite)]
    pub speedup: f64,
    /// Seconds to wait for every device of a row to be ready.
    #[arg(long, default_value_t = 600.0, value_name = "SECS", value_parser = troupe_node::args::seconds)]
    pub ready_within: f64,
}

/// Simulated ms per step, the world's `interval_sim`.
const STEP_MS: u32 = 100;
/// A room's side in metres; walls are 0.2 m, doors 2 m in the middle of
/// every inner wall.
const ROOM: f64 = 10.0;
/// Robots a room holds, 8 x 8 at 1 m from each other.
const PER_ROOM: u32 = 64;
/// Bitmap pixels per metre.
const PX_PER_M: f64 = 10.0;

/// Rooms along each side of a map that holds `robots`.
fn rooms_for(robots: u32) -> u32 {
    let rooms = robots.div_ceil(PER_ROOM).max(1);
    f64::from(rooms).sqrt().ceil() as u32
}

/// Draws a map of `side` x `side` rooms into `path`: white floor, black
/// walls, every room joined to its neighbours by a door.
fn draw_map(side: u32, path: &Path) -> anyhow::Result<()> {
    let room_px = (ROOM * PX_PER_M) as u32;
    let n = side * room_px;
    let (wall, door) = (2, (2.0 * PX_PER_M) as u32);
    let mid = |i: u32| (room_px - door) / 2 <= i && i < (room_px + door) / 2;
    let mut img = image::GrayImage::from_pixel(n, n, image::Luma([255]));
    for y in 0..n {
        for x in 0..n {
            let (ix, iy) = (x % room_px, y % room_px);
            let outer = x < wall || y < wall || x >= n - wall || y >= n - wall;
            let v_wall = ix < wall && !mid(iy);
            let h_wall = iy < wall && !mid(ix);
            if outer || v_wall || h_wall {
                img.put_pixel(x, y, image::Luma([0]));
            }
        }
    }
    img.save(path)
        .with_context(|| format!("writing the generated map {}", path.display()))
}

/// The world and cfg of `robots` robots on a map of `side` rooms, in `dir`.
fn write_stack(
    dir: &Path,
    map: &Path,
    side: u32,
    robots: u32,
    a: &ScaleArgs,
) -> anyhow::Result<PathBuf> {
    let size = f64::from(side) * ROOM;
    // Our own swarmbot: 0.1 m, 12 IR rangers around it (2 m, 30°).
    let mut w = format!(
        "resolution 0.02\ninterval_sim {STEP_MS}\nthreads {}\nspeedup {}\n{}",
        a.threads,
        a.speedup,
        crate::harness::ir_ring_robot("scale_bot", 0.1, 2.0, 30.0, "expand_swarm")
    );
    w.push_str(&format!(
        "model ( name \"map\" bitmap \"{}\" size [{size} {size} 0.5] color \"gray30\" boundary 1 )\n",
        map.display()
    ));
    for i in 0..robots {
        let (room, k) = (i / PER_ROOM, i % PER_ROOM);
        let (rx, ry) = (f64::from(room % side), f64::from(room / side));
        let x = -size / 2.0 + rx * ROOM + 1.5 + f64::from(k % 8);
        let y = -size / 2.0 + ry * ROOM + 1.5 + f64::from(k / 8);
        w.push_str(&format!(
            "scale_bot( name \"b{i}\" pose [{x:.2} {y:.2} 0 {}] )\n",
            (i * 53) % 360
        ));
    }
    let world = dir.join(format!("scale{robots}.world"));
    std::fs::write(&world, w)?;
    let mut cfg = format!(
        "driver ( name \"stage\" provides [\"simulation:0\"] worldfile \"{}\" )\n",
        world.display()
    );
    for i in 0..robots {
        let port = 6665 + i;
        cfg.push_str(&format!(
            "driver ( name \"stage\" provides [\"{port}:position2d:0\" \"{port}:ranger:0\"] model \"b{i}\" )\n"
        ));
    }
    let path = dir.join(format!("scale{robots}.cfg"));
    std::fs::write(&path, cfg)?;
    Ok(path)
}

/// Per key, per schema on it (odometry and geometry share a key): the
/// first and last stamps taken, and how many.
type Seen = HashMap<String, Vec<(String, Stamps)>>;

/// A stream's first and last stamps, and how many samples it brought.
#[derive(Clone, Copy)]
struct Stamps(f64, f64, u64);

impl Stamps {
    fn take(&mut self, stamp: f64) {
        self.0 = self.0.min(stamp);
        self.1 = self.1.max(stamp);
        self.2 += 1;
    }
}

/// One row's figures.
struct Row {
    robots: u32,
    ready: f64,
    /// From ready until every device's data came.
    flowing: f64,
    list: f64,
    listed: usize,
    speed: f64,
    sim_cpu_per_s: f64,
    sim_mb: f64,
    delivered: u64,
    lost: u64,
    undecodable: u64,
    per_s: f64,
    launcher_cpu: f64,
}

/// `troupe bench scale`.
pub fn run(a: &ScaleArgs) -> anyhow::Result<()> {
    anyhow::ensure!(a.threads >= 1, "--threads must be at least 1");
    let dir = std::env::temp_dir().join(format!("troupe-bench-scale-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let r = rows(a, &dir);
    let _ = std::fs::remove_dir_all(&dir);
    r
}

fn rows(a: &ScaleArgs, dir: &Path) -> anyhow::Result<()> {
    let most = a.robots.iter().copied().max().unwrap_or(0);
    let side = rooms_for(most);
    let map = dir.join("rooms.png");
    draw_map(side, &map)?;
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "troupe bench scale: swarmbot-like robots (0.1 m, 12 IR rangers, expand_swarm), each on its own port (position2d:0, ranger:0), in {side} x {side} rooms of {ROOM} m ({} m square, the same map in every row); speedup {}, {} simulator threads; a subscriber of robot/** here; {} s a row",
        f64::from(side) * ROOM,
        a.speedup,
        a.threads,
        a.seconds
    )?;
    writeln!(
        out,
        "  {:>6} {:>8} {:>8} {:>13} {:>8} {:>14} {:>8} {:>9} {:>10} {:>19} {:>9}",
        "robots",
        "ready",
        "data",
        "troupe list",
        "speed",
        "sim CPU/sim s",
        "sim RSS",
        "KB/robot",
        "samples/s",
        "lost",
        "launcher"
    )?;
    writeln!(
        out,
        "  (ready: from launch until every device was live; data: from then until every device's data reached the subscriber; KB/robot: the simulator's memory beside the row of none; launcher: its CPU, the router's included)"
    )?;
    let mut base_mb = None;
    for robots in std::iter::once(0).chain(a.robots.iter().copied()) {
        // Each robot gives the simulator two devices, and the map one.
        let devices = 2 * robots as usize + 1;
        if devices > troupe_node::MAX_DEVICES {
            writeln!(
                out,
                "  {robots:>6} not run: {devices} devices in one simulator, more than the {} a process can declare (Zenoh names at most 65,535 keys on a link; docs/zenoh-declarations.md)",
                troupe_node::MAX_DEVICES
            )?;
            continue;
        }
        let row = row(a, dir, &map, side, robots)?;
        let base = *base_mb.get_or_insert(row.sim_mb);
        let per_robot = if robots == 0 {
            "-".to_owned()
        } else {
            format!("{:.1}", (row.sim_mb - base) * 1024.0 / f64::from(robots))
        };
        writeln!(
            out,
            "  {:>6} {:>7.1}s {:>7.1}s {:>6.2}s {:>5} {:>7.2}x {:>11.0} ms {:>6.0}MB {:>9} {:>10.0} {:>8} of {:<8} {:>8.0}%{}",
            row.robots,
            row.ready,
            row.flowing,
            row.list,
            row.listed,
            row.speed,
            row.sim_cpu_per_s * 1e3,
            row.sim_mb,
            per_robot,
            row.per_s,
            row.lost,
            row.delivered + row.lost,
            row.launcher_cpu * 100.0,
            if row.undecodable > 0 {
                format!(" ({} undecodable)", row.undecodable)
            } else {
                String::new()
            }
        )?;
        out.flush()?;
    }
    Ok(())
}

/// The simulator's time, from a request: its reply is written when the
/// simulator takes it, so data queued on the link does not make it late,
/// as it makes `sim/clock`'s samples late (by seconds under 60,000
/// samples/s).
fn sim_time(sim: &SimulationProxy) -> anyhow::Result<f64> {
    match sim.get_property("map", "time")? {
        simulation::Value::Int(us) => Ok(us as f64 / 1e6),
        other => anyhow::bail!("the simulator's time came as {other:?}"),
    }
}

/// Launches `robots` robots, waits until all are ready, and measures.
fn row(a: &ScaleArgs, dir: &Path, map: &Path, side: u32, robots: u32) -> anyhow::Result<Row> {
    let cfg = write_stack(dir, map, side, robots, a)?;
    let t0 = Instant::now();
    let (launcher, router, z) = launched(&cfg, &[])?;
    let launcher = Kid(launcher);
    let mut devices = vec!["simulation:0".parse::<troupe_msgs::DevAddr>()?];
    for i in 0..robots {
        for d in ["position2d:0", "ranger:0"] {
            devices.push(format!("{}:{d}", 6665 + i).parse()?);
        }
    }
    troupe_inspect::wait_ready(
        troupe_inspect::ReadyArgs {
            devices,
            robot: 6665,
            wait: a.ready_within,
        },
        &z,
    )
    .with_context(|| {
        format!(
            "{robots} robots: not every device was ready within {} s",
            a.ready_within
        )
    })?;
    let ready = t0.elapsed().as_secs_f64();

    let t1 = Instant::now();
    let listed = Command::new(std::env::current_exe()?)
        .args(["--no-multicast", "--connect", &router, "list", "--json"])
        .stderr(Stdio::null())
        .output()
        .context("running `troupe list`")?;
    let list = t1.elapsed().as_secs_f64();
    let listed = String::from_utf8_lossy(&listed.stdout).lines().count();

    // A peer, as tools that stay up join (ARCHITECTURE.md): samples come
    // straight from the simulator, not through the router.
    let session = z.open_peer()?;
    let seen = Arc::new(Mutex::new((Seen::new(), 0u64)));
    let s = seen.clone();
    let _sub = session
        .declare_subscriber(keys::all())
        .callback(move |sample| {
            let key = sample.key_expr().as_str();
            if keys::parse_data(key).is_err() {
                return;
            }
            let bytes = sample.payload().to_bytes();
            let mut g = s.lock().unwrap_or_else(|p| p.into_inner());
            let (seen, undecodable) = &mut *g;
            let Ok((schema, stamp, _)) = codec::split(&bytes) else {
                *undecodable += 1;
                return;
            };
            let first = || (schema.to_owned(), Stamps(stamp, stamp, 1));
            match seen.get_mut(key) {
                None => {
                    seen.insert(key.to_owned(), vec![first()]);
                }
                Some(streams) => match streams.iter_mut().find(|(s, _)| s == schema) {
                    Some((_, e)) => e.take(stamp),
                    None => streams.push(first()),
                },
            }
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("subscribing to robot/**: {e}"))?;
    // The window opens once every device's data reaches the subscriber
    // (its subscription reached every publisher); counts start afresh.
    let t2 = Instant::now();
    let devices = 2 * robots as usize;
    loop {
        let have = seen.lock().unwrap_or_else(|p| p.into_inner()).0.len();
        if have >= devices {
            break;
        }
        if t2.elapsed().as_secs_f64() > a.ready_within {
            anyhow::bail!(
                "{robots} robots: data from only {have} of {devices} devices within {} s",
                a.ready_within
            );
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    let flowing = t2.elapsed().as_secs_f64();
    // The simulation device, once this session sees it: with no robots,
    // nothing above waited for the session to join.
    let simulation = "6665:simulation:0".parse::<troupe_msgs::DevAddr>()?;
    troupe_node::wait_live(
        &session,
        &simulation.device(6665),
        Duration::from_secs_f64(a.ready_within),
    )?;
    let sim = SimulationProxy::new(&Client::with_session(session.clone(), 6665), 0);
    let stage =
        node_pid(launcher.0.id(), "stage").context("no simulator process under the launcher")?;
    let pid = launcher.0.id();
    *seen.lock().unwrap_or_else(|p| p.into_inner()) = (Seen::new(), 0);
    let (w0, cpu0, lcpu0) = (Instant::now(), cpu_of(stage), cpu_of(pid));
    let sim0 = sim_time(&sim)?;
    std::thread::sleep(Duration::from_secs_f64(a.seconds));
    let (wall, cpu1, lcpu1) = (w0.elapsed().as_secs_f64(), cpu_of(stage), cpu_of(pid));
    let sim1 = sim_time(&sim)?;
    let (seen, undecodable) = std::mem::take(&mut *seen.lock().unwrap_or_else(|p| p.into_inner()));
    let sim_mb = status_mb_of(&stage.to_string(), "VmRSS:");
    drop(_sub);
    let _ = session.close().wait();
    drop(launcher);

    let step = f64::from(STEP_MS) / 1e3;
    let streams = || seen.values().flatten().map(|(_, e)| *e);
    let delivered: u64 = streams().map(|e| e.2).sum();
    let owed: u64 = streams()
        .map(|Stamps(first, last, _)| ((last - first) / step).round() as u64 + 1)
        .sum();
    let simulated = (sim1 - sim0).max(1e-9);
    Ok(Row {
        robots,
        ready,
        flowing,
        list,
        listed,
        speed: simulated / wall,
        sim_cpu_per_s: (cpu1 - cpu0).as_secs_f64() / simulated,
        sim_mb,
        delivered,
        lost: owed.saturating_sub(delivered),
        undecodable,
        per_s: delivered as f64 / wall,
        launcher_cpu: (lcpu1 - lcpu0).as_secs_f64() / wall,
    })
}
