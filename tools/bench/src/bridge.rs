//! `troupe bench bridge`: Player clients through the bridge to real drivers.
//!
//! The bridge runs as `troupe launch` runs it, on its router's session. The
//! devices are served by the real drivers on a session of their own, as if
//! in another process: `mapfile` serves the map, Stage serves r0 of a world
//! stepped at Player's 100 Hz, so position2d data flows while requests are
//! timed. The clients speak raw XDR over plain sockets, as libplayerc does.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Args;
use troupe_bridge::wire::{self, player};
use troupe_bridge::xdr::{self, Writer};
use troupe_msgs::{codec, keys, map, Device, Interface};
use troupe_node::zenoh::Wait;
use troupe_node::{Mode, NodeConfig, NodeHandle, Section, Stop, ZenohArgs};

use crate::harness::{percentile, us};

/// Flags of `troupe bench bridge`.
#[derive(Debug, Args)]
pub struct BridgeBenchArgs {
    /// Timed requests of each kind.
    #[arg(long, default_value_t = 2000)]
    pub samples: usize,
    /// Full map fetches.
    #[arg(long, default_value_t = 50)]
    pub fetches: usize,
    /// The map image for `mapfile` (500x500 cave.png in the reference);
    /// a synthetic 500x500 cave without it.
    #[arg(long, value_name = "PNG")]
    pub map: Option<PathBuf>,
    /// The world whose r0 Stage serves (the repo's worlds/simple.world
    /// without it).
    #[arg(long, value_name = "FILE")]
    pub world: Option<PathBuf>,
    /// Clients reading position2d at 10 Hz each, all at once.
    #[arg(long, default_value_t = 100)]
    pub clients: usize,
    /// How long the many clients read (and each row of --hostile).
    #[arg(long, default_value_t = 5.0, value_name = "SECS", value_parser = troupe_node::args::seconds)]
    pub seconds: f64,
    /// Instead, 50 well-behaved clients beside hostile ones in turn (idle
    /// connections, clients that never read, a flood of requests, of
    /// replace rules, random bytes): their p99 against a quiet run, their
    /// data, this process's memory, and whether it still serves.
    #[arg(long)]
    pub hostile: bool,
}

use crate::raw_player::{
    connect, header, next, open, open_at, player_req, pull_round, req, request, ROBOT,
};

/// A Player client in PUSH mode (Player's default) with `devices` of
/// robot port `addr` open, reading on a thread of its own until `stop`:
/// the data messages it read.
pub(crate) fn push_reader(
    addr: SocketAddr,
    devices: &[(Interface, u32)],
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
) -> anyhow::Result<std::thread::JoinHandle<u64>> {
    let mut s = TcpStream::connect(addr)?;
    s.set_read_timeout(Some(Duration::from_secs(10)))?;
    let mut banner = [0u8; wire::BANNER_LEN];
    s.read_exact(&mut banner)?;
    for &(i, index) in devices {
        open_at(&mut s, i, index)?;
    }
    Ok(std::thread::spawn(move || {
        let mut n = 0;
        while !stop.load(std::sync::atomic::Ordering::Relaxed) {
            match next(&mut s) {
                Ok((h, _)) if h.kind == u32::from(wire::DATA) => n += 1,
                Ok(_) => {}
                Err(_) => break,
            }
        }
        n
    }))
}

/// `n` timed runs of each of `K` kinds of round trip (`run(k)` makes one
/// of kind `k`), taken in turn so that the machine's drift touches every
/// kind alike, after `n / 10` untimed rounds. Each kind's times, sorted.
fn rounds<const K: usize>(
    n: usize,
    mut run: impl FnMut(usize) -> anyhow::Result<()>,
) -> anyhow::Result<[Vec<Duration>; K]> {
    let mut v: [Vec<Duration>; K] = std::array::from_fn(|_| Vec::with_capacity(n));
    for i in 0..n + n / 10 {
        for (k, times) in v.iter_mut().enumerate() {
            let t0 = Instant::now();
            run(k)?;
            if i >= n / 10 {
                times.push(t0.elapsed());
            }
        }
    }
    for times in &mut v {
        times.sort();
    }
    Ok(v)
}

/// The whole map, as libplayerc fetches it: GET_INFO, then tiles of at
/// most 640x640, each zlib-compressed. Returns its width and height.
fn fetch_map(s: &mut TcpStream) -> anyhow::Result<(u32, u32)> {
    let info = request(s, req(Interface::Map, 1), &[])?;
    // Resolution, then width and height.
    let mut r = xdr::Reader::new(&info);
    r.f32()?;
    let (w, h) = (r.u32()?, r.u32()?);
    let mut got = 0usize;
    for row in (0..h).step_by(640) {
        for col in (0..w).step_by(640) {
            let (tw, th) = ((w - col).min(640), (h - row).min(640));
            let mut q = Writer::new();
            for v in [col, row, tw, th, 0] {
                q.u32(v);
            }
            q.bytes(&[]);
            let b = request(s, req(Interface::Map, 2), &q.finish())?;
            // Column, row, width, height, cell count, then the zlib data.
            let mut r = xdr::Reader::new(&b);
            for _ in 0..5 {
                r.u32()?;
            }
            let mut cells = Vec::with_capacity((tw * th) as usize);
            flate2::read::ZlibDecoder::new(r.bytes()?).read_to_end(&mut cells)?;
            got += cells.len();
        }
    }
    anyhow::ensure!(
        got == (w * h) as usize,
        "map fetch got {got} cells of {}",
        w * h
    );
    Ok((w, h))
}

/// What one of the many clients saw.
#[derive(Default)]
struct Reader {
    /// Each read's round trip: REQ DATA to SYNCH.
    reads: Vec<Duration>,
    /// Reads whose SYNCH said data was dropped.
    overflows: usize,
    /// Reads that brought position2d data.
    with_data: usize,
}

/// A libplayerc client's `playerc_client_read` at 10 Hz for `seconds`.
/// Clients are independent: each starts its 100 ms cycle at `phase`.
fn read_at_10hz(addr: SocketAddr, phase: Duration, seconds: f64) -> anyhow::Result<Reader> {
    let mut s = connect(addr)?;
    open(&mut s, Interface::Position2d)?;
    let mut r = Reader::default();
    let start = Instant::now();
    let period = Duration::from_millis(100);
    let mut due = start + phase;
    while start.elapsed().as_secs_f64() < seconds {
        // Pacing the client, not synchronising with anything.
        std::thread::sleep(due.saturating_duration_since(Instant::now()));
        due += period;
        let t0 = Instant::now();
        let round = pull_round(&mut s)?;
        r.reads.push(t0.elapsed());
        r.overflows += usize::from(round.overflow);
        r.with_data += usize::from(round.data);
    }
    Ok(r)
}

/// What a `Read()` loop saw: libplayerc's `playerc_client_read` in PULL
/// mode, as fast as rounds come, with position2d, both rangers and the
/// laser subscribed.
#[derive(Default)]
struct Pulls {
    /// Reads, from the first that carried every device on.
    reads: usize,
    /// Of those, the reads that carried every device.
    whole: usize,
    /// Of those, the reads whose position2d was a newer step than the last's.
    newer: usize,
    /// Reads before the first whole one.
    filling: usize,
    /// Each read's round trip, sorted.
    times: Vec<Duration>,
    /// Wall-clock seconds the counted reads took.
    seconds: f64,
}

const PULLED: [(Interface, u32); 4] = [
    (Interface::Position2d, 0),
    (Interface::Ranger, 0),
    (Interface::Ranger, 1),
    (Interface::Laser, 0),
];

fn read_loop(addr: SocketAddr, seconds: f64) -> anyhow::Result<Pulls> {
    let mut s = connect(addr)?;
    for (i, k) in PULLED {
        open_at(&mut s, i, k)?;
    }
    let wanted: Vec<(u32, u32)> = PULLED
        .iter()
        .map(|&(i, k)| (u32::from(i.code()), k))
        .collect();
    let req = wire::message(header(player_req(player::REQ_DATA)), &[]);
    let position = u32::from(Interface::Position2d.code());
    let mut p = Pulls::default();
    let mut last = f64::NEG_INFINITY;
    let mut start = None;
    let mut got = Vec::new();
    while start.is_none_or(|t: Instant| t.elapsed().as_secs_f64() < seconds) {
        anyhow::ensure!(
            start.is_some() || p.filling < 1000,
            "no read carried all four devices (the world's r0 needs a position and two rangers)"
        );
        let t0 = Instant::now();
        s.write_all(&req)?;
        got.clear();
        let mut stamp = None;
        loop {
            let (h, _) = next(&mut s)?;
            match u8::try_from(h.kind) {
                Ok(wire::DATA) => {
                    got.push((h.interf, h.index));
                    if h.interf == position {
                        stamp = Some(h.timestamp);
                    }
                }
                Ok(wire::SYNCH) => break,
                _ => {}
            }
        }
        let whole = wanted.iter().all(|w| got.contains(w));
        if start.is_none() && !whole {
            p.filling += 1;
            continue;
        }
        if start.is_none() {
            start = Some(Instant::now());
            last = stamp.unwrap_or(last);
            continue;
        }
        p.times.push(t0.elapsed());
        p.reads += 1;
        p.whole += usize::from(whole);
        if let Some(t) = stamp.filter(|&t| t > last) {
            p.newer += 1;
            last = t;
        }
    }
    p.seconds = start.map_or(0.0, |t| t.elapsed().as_secs_f64());
    p.times.sort();
    Ok(p)
}

/// Velocity commands in [`commands`].
const COMMANDS: usize = 20_000;

/// `n` position2d velocity commands (zero speeds) sent back to back, a
/// hundred a write, as a joystick client or a script can, then a DEVLIST
/// that the bridge answers once it has handled them all: the time to the
/// answer, and how many commands a subscriber of their key on the
/// bridge's own session heard by then (delivered in the put, so all of
/// them unless some were lost).
fn commands(
    s: &mut TcpStream,
    router: &troupe_node::zenoh::Session,
    n: usize,
) -> anyhow::Result<(Duration, usize)> {
    use std::sync::atomic::{AtomicUsize, Ordering};
    let heard = std::sync::Arc::new(AtomicUsize::new(0));
    let h = heard.clone();
    let key = keys::cmd(&Device::new(ROBOT, Interface::Position2d, 0), "vel");
    let _tap = router
        .declare_subscriber(key)
        .callback(move |_| {
            h.fetch_add(1, Ordering::Relaxed);
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let mut vel = Writer::new();
    vel.f64(0.0).f64(0.0).f64(0.0).u32(1);
    let code = u32::from(Interface::Position2d.code());
    let one = wire::message(
        header([0, ROBOT, code, 0, u32::from(wire::CMD), 1]),
        &vel.finish(),
    );
    let batch = one.repeat(100);
    let t0 = Instant::now();
    for _ in 0..n.div_ceil(100) {
        s.write_all(&batch)?;
    }
    request(s, player_req(player::REQ_DEVLIST), &[])?;
    Ok((t0.elapsed(), heard.load(Ordering::Relaxed)))
}

/// A 500x500 cave-like map as a PNG, for runs without `--map`.
fn synthetic_map() -> anyhow::Result<PathBuf> {
    let img = image::GrayImage::from_fn(500, 500, |x, y| {
        let (x, y) = (f64::from(x), f64::from(y));
        let wall = (x / 37.0).sin() * (y / 23.0).cos() > 0.6;
        image::Luma([if wall { 0 } else { 255 }])
    });
    let path = std::env::temp_dir().join(format!("troupe-bench-map-{}.png", std::process::id()));
    img.save(&path)
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(path)
}

fn world_file(given: Option<&Path>) -> anyhow::Result<PathBuf> {
    if let Some(p) = given {
        return Ok(p.to_owned());
    }
    let local = PathBuf::from("worlds/simple.world");
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds/simple.world");
    [local, repo]
        .into_iter()
        .find(|p| p.exists())
        .context("worlds/simple.world not found: run from the repository, or give --world FILE")
}

fn spawn<D: troupe_node::Driver>(
    at: &ZenohArgs,
    json: &serde_json::Value,
) -> anyhow::Result<(NodeHandle, Stop)> {
    let session = at.open(Mode::Peer)?;
    let section = Section::from_json(&json.to_string())?;
    let stop = Stop::default();
    let node = troupe_node::spawn::<D>(session, section, &NodeConfig::default(), stop.clone())?;
    Ok((node, stop))
}

/// Runs `troupe bench bridge`.
pub fn run(a: &BridgeBenchArgs) -> anyhow::Result<()> {
    let ns = format!("bench-bridge-{}", std::process::id());
    let router = ZenohArgs {
        // As `troupe launch` opens its embedded router: in the namespace.
        namespace: Some(ns.clone()),
        listen: vec!["tcp/127.0.0.1:0".into()],
        no_multicast: true,
        ..Default::default()
    }
    .open(Mode::Router)?;
    let at = ZenohArgs {
        connect: troupe_node::locators(&router),
        namespace: Some(ns),
        no_multicast: true,
        ..Default::default()
    };
    let (map, made) = match &a.map {
        Some(p) => (p.clone(), false),
        None => (synthetic_map()?, true),
    };
    let world = world_file(a.world.as_deref())?;
    let mapfile = spawn::<troupe_mapfile::MapFile>(
        &at,
        &serde_json::json!({
            "name": "mapfile", "provides": ["map:0"],
            "options": {"filename": map, "resolution": 0.032},
        }),
    );
    if made {
        let _ = std::fs::remove_file(&map);
    }
    let mapfile = mapfile?;
    // Stepped as Player stepped its Stage plugin: once per server update, 100 Hz.
    let stage = spawn::<troupe_stage::Stage>(
        &at,
        &serde_json::json!({
            "name": "stage",
            "provides": ["simulation:0", "position2d:0", "ranger:0", "ranger:1"],
            "options": {"worldfile": world, "model": "r0", "speedup": -1, "update_rate": 100},
        }),
    )?;
    // r0's laser, as simple.cfg makes it, in a driver of its own.
    let laser = spawn::<troupe_rangertolaser::RangerToLaser>(
        &at,
        &serde_json::json!({
            "name": "rangertolaser", "requires": ["ranger:1"], "provides": ["laser:0"],
        }),
    )?;
    // The drivers announce their devices from their own threads: the
    // bridge lists only devices that are live.
    let live = [(Interface::Map, 0), (Interface::Simulation, 0)]
        .into_iter()
        .chain(PULLED)
        .try_for_each(|(i, k)| {
            let dev = Device::new(ROBOT, i, k);
            troupe_node::wait_live(&router, &dev, Duration::from_secs(30))
        });
    let result = live
        .map_err(anyhow::Error::from)
        .and_then(|()| measure(a, &router));
    for (node, stop) in [mapfile, stage, laser] {
        stop.stop();
        let _ = node.join();
    }
    result
}

fn measure(a: &BridgeBenchArgs, router: &troupe_node::zenoh::Session) -> anyhow::Result<()> {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()?;
    let bridge = rt.block_on(troupe_bridge::Bridge::bind(
        router.clone(),
        troupe_bridge::Config {
            ports: vec![troupe_bridge::Port {
                robot: ROBOT,
                listen: "127.0.0.1:0".parse()?,
            }],
            ..Default::default()
        },
    ))?;
    let addr = bridge.local_addrs()[0].1;
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let server = rt.spawn(bridge.run(async {
        let _ = stop_rx.await;
    }));
    if a.hostile {
        let table = crate::hostile::run(addr, a.seconds, &mut std::io::stdout().lock());
        let _ = stop_tx.send(());
        let _ = rt.block_on(server);
        return table;
    }

    let mut s = connect(addr)?;
    // As Player, the bridge answers a device's requests once a client has
    // opened it.
    for i in [Interface::Position2d, Interface::Map, Interface::Simulation] {
        open(&mut s, i)?;
    }
    let (info, geom) = (req(Interface::Map, 1), req(Interface::Position2d, 1));
    // r0's pose: Stage's thread answers the first ask, then keeps the
    // answer ready, renewed after every step.
    let (get_pose, set_pose) = (req(Interface::Simulation, 1), req(Interface::Simulation, 2));
    let mut pose = Writer::new();
    pose.string("r0").f64(0.0).f64(0.0).f64(0.0);
    let pose = pose.finish();
    // A request only Stage's driver can answer, between steps: setting
    // r0's pose, to where it is (the answer: name, x, y, yaw).
    let at = request(&mut s, get_pose, &pose)?;
    let mut r = xdr::Reader::new(&at);
    r.string()?;
    let mut set = Writer::new();
    set.string("r0").f64(r.f64()?).f64(r.f64()?).f64(r.f64()?);
    let set = set.finish();
    // The GET_INFO as a bare Zenoh get from the bridge's session, as the
    // bridge asks: what the bridge adds on top of Zenoh.
    let info_key = keys::req(&Device::new(ROBOT, Interface::Map, 0), "info");
    let bare = || {
        let replies = troupe_node::ask(router, &info_key, troupe_node::REQUEST_TIMEOUT)
            .payload(codec::encode(&map::GetInfo, 0.0))
            .wait()
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        let reply = replies
            .recv()
            .map_err(|e| anyhow::anyhow!("no reply to {info_key}: {e}"))?;
        anyhow::ensure!(reply.result().is_ok(), "{info_key} refused");
        Ok(())
    };
    // The floor: a request crosses two processes' sockets (client to
    // bridge, bridge to driver), each a round trip at least; a Player
    // request and its reply are some tens of bytes.
    let mut echo = crate::harness::TcpEcho::start(64)?;
    let mut two_tcp = || -> anyhow::Result<()> {
        echo.round_trip()?;
        echo.round_trip().map(drop)
    };
    let [idle, busy, live, moved, raw, two_tcp] = rounds(a.samples, |kind| match kind {
        0 => request(&mut s, info, &[]).map(drop),
        1 => request(&mut s, geom, &[]).map(drop),
        2 => request(&mut s, get_pose, &pose).map(drop),
        3 => request(&mut s, set_pose, &set).map(drop),
        4 => bare(),
        _ => two_tcp(),
    })?;
    let mut fetches = Vec::with_capacity(a.fetches);
    let mut size = (0, 0);
    for _ in 0..a.fetches {
        let t0 = Instant::now();
        size = fetch_map(&mut s)?;
        fetches.push(t0.elapsed());
    }
    fetches.sort();
    let (streamed, heard) = commands(&mut s, router, COMMANDS)?;

    // A program's `Read()` loop: every read one moment of the simulation.
    let pulls = read_loop(addr, a.seconds)?;

    // Many clients at once, and one that opened the device and never reads.
    let mut stuck = connect(addr)?;
    open(&mut stuck, Interface::Position2d)?;
    request(
        &mut stuck,
        player_req(player::REQ_DATAMODE),
        &player::PUSH.to_be_bytes(),
    )?;
    let readers = (0..a.clients)
        .map(|i| {
            let seconds = a.seconds;
            let phase = Duration::from_millis(100) * i as u32 / a.clients as u32;
            std::thread::spawn(move || read_at_10hz(addr, phase, seconds))
        })
        .collect::<Vec<_>>();
    let readers = readers
        .into_iter()
        .map(|t| {
            t.join()
                .map_err(|_| anyhow::anyhow!("a client thread panicked"))?
        })
        .collect::<anyhow::Result<Vec<Reader>>>()?;
    drop(stuck);

    let _ = stop_tx.send(());
    let _ = rt.block_on(server);

    let mut out = std::io::stdout().lock();
    writeln!(out, "troupe bench bridge: Player clients in raw XDR (no TCP_NODELAY, PULL mode) → bridge → Zenoh → mapfile and Stage (r0 at 100 Hz), loopback")?;
    let row = |out: &mut std::io::StdoutLock, name: &str, v: &[Duration], target: &str| {
        writeln!(
            out,
            "  {name:<48} p50 {:>8}  p99 {:>8}   {target}",
            us(percentile(v, 0.5)),
            us(percentile(v, 0.99)),
        )
    };
    row(
        &mut out,
        "map GET_INFO round trip (mapfile)",
        &idle,
        "Player 66 µs; target <= 250 µs",
    )?;
    row(
        &mut out,
        "position2d GET_GEOM round trip (Stage, data flowing)",
        &busy,
        "Player 44 ms; target <= 250 µs",
    )?;
    row(
        &mut out,
        "simulation GET_POSE2D round trip (Stage, kept ready)",
        &live,
        "target <= 250 µs",
    )?;
    row(
        &mut out,
        "simulation SET_POSE2D round trip (Stage's driver)",
        &moved,
        "target <= 250 µs",
    )?;
    row(
        &mut out,
        &format!("full map fetch, {}x{} cells (zlib tiles)", size.0, size.1),
        &fetches,
        "Player 2.1-2.4 ms; target <= 4 ms",
    )?;
    writeln!(
        out,
        "  {:<48} {COMMANDS} in {:.1} ms: {:.0} a second, {heard} of them put on its key",
        "position2d velocity commands, back to back",
        streamed.as_secs_f64() * 1e3,
        COMMANDS as f64 / streamed.as_secs_f64().max(1e-9),
    )?;
    let mut all: Vec<Duration> = readers.iter().flat_map(|r| r.reads.clone()).collect();
    all.sort();
    let mut p50s: Vec<Duration> = readers
        .iter()
        .map(|r| {
            let mut v = r.reads.clone();
            v.sort();
            percentile(&v, 0.5)
        })
        .collect();
    p50s.sort();
    let reads: usize = readers.iter().map(|r| r.reads.len()).sum();
    let with_data: usize = readers.iter().map(|r| r.with_data).sum();
    let overflows: usize = readers.iter().map(|r| r.overflows).sum();
    row(
        &mut out,
        &format!("{} clients reading at 10 Hz: REQ DATA to SYNCH", a.clients),
        &all,
        "target: no overflow, none slowed",
    )?;
    writeln!(
        out,
        "  {:<48} {reads} reads, {with_data} with data, {overflows} overflowed; per-client p50 from {} to {}, one stuck client beside them",
        "",
        us(p50s.first().copied().unwrap_or_default()),
        us(p50s.last().copied().unwrap_or_default()),
    )?;
    row(
        &mut out,
        "Read() loop, 4 devices: REQ DATA to SYNCH",
        &pulls.times,
        "paced by the simulation step (10 ms here)",
    )?;
    let pct = |n: usize| 100.0 * n as f64 / pulls.reads.max(1) as f64;
    writeln!(
        out,
        "  {:<48} {:.0} reads/s; {:.1}% carried all four devices, {:.1}% a newer step than the read before (target 100%); {} reads before the first whole one",
        "",
        pulls.reads as f64 / pulls.seconds.max(1e-9),
        pct(pulls.whole),
        pct(pulls.newer),
        pulls.filling,
    )?;
    row(
        &mut out,
        "for scale: the GET_INFO as a bare Zenoh get",
        &raw,
        "Zenoh alone, no bridge, no TCP client",
    )?;
    row(
        &mut out,
        "the floor: two plain TCP round trips",
        &two_tcp,
        "client -> bridge -> driver over bare sockets",
    )?;
    let times = |v: &[Duration]| crate::harness::times_floor(v, &two_tcp);
    writeln!(
        out,
        "  p50 against the floor: GET_INFO {:.2}x, GET_GEOM {:.2}x, GET_POSE2D {:.2}x, SET_POSE2D {:.2}x (target <= 1.3x)",
        times(&idle),
        times(&busy),
        times(&live),
        times(&moved),
    )?;
    Ok(())
}
