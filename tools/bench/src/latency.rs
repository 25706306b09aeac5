//! `troupe bench latency`: what a sample costs between two Troupe processes.
//!
//! This process runs a router on an ephemeral loopback port (as `troupe
//! launch` embeds one), starts `troupe bench pong` as a child peer, and
//! times laser-scan-sized messages through the full codec (encode, put,
//! decode, re-encode, put back, decode) and through a request/reply,
//! beside the floor they stand on: the same bytes echoed over plain TCP
//! between two processes, in the same run. It then times Zenoh at its
//! fastest between the same two kinds of process (see [`fastest`]): what
//! no configuration of Troupe's sessions could beat.

use std::io::{Read, Write};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Args;
use troupe_msgs::{camera, codec, keys, laser, Message};
use troupe_node::zenoh::qos::CongestionControl;
use troupe_node::zenoh::{Session, Wait};
use troupe_node::{Mode, ZenohArgs};

use crate::harness::{percentile, us};

/// `troupe bench latency`: plain; a sample large enough to go through
/// shared memory over it too, and beside a 64-byte sample; with
/// `--secure` over TLS too.
pub fn run(a: &LatencyArgs) -> anyhow::Result<()> {
    let size = Msg::of(a.carry, a.size).encode(0.0).len();
    let network = latency(a, None, false)?.context("no one-way times")?;
    if size >= SHM_FROM {
        let shm = latency(a, None, true)?.context("no one-way times")?;
        let small = LatencyArgs {
            size: SMALL,
            carry: Carry::Scan,
            secure: false,
            ..a.clone()
        };
        let small_size = Msg::of(Carry::Scan, SMALL).encode(0.0).len();
        let small = latency(&small, None, false)?.context("no one-way times")?;
        let p50 = |o: &OneWay| percentile(&o.times, 0.5);
        let x = |o: &OneWay| p50(o).as_secs_f64() / p50(&small).as_secs_f64().max(1e-9);
        // A plain memcpy of the payload into memory already written.
        let from = vec![7u8; size];
        let mut to = vec![0u8; size];
        let copy = timed(a.samples, || {
            to.copy_from_slice(std::hint::black_box(&from));
            std::hint::black_box(&to);
            Ok(())
        })?;
        let mb = |o: &OneWay| o.rate * size as f64 / 1e6;
        writeln!(
            std::io::stdout().lock(),
            "troupe bench latency: {size} bytes against {small_size}, same run, one sample one way p50 (throughput): over shared memory {} ({:.1}x; {:.0} MB/s), over the network {} ({:.1}x; {:.0} MB/s); {small_size} bytes {} ({:.0} samples/s); a memcpy of {size} bytes {} (target: 1 MB <= 3x)",
            us(p50(&shm)),
            x(&shm),
            mb(&shm),
            us(p50(&network)),
            x(&network),
            mb(&network),
            us(p50(&small)),
            small.rate,
            us(percentile(&copy, 0.5)),
        )?;
    }
    if a.secure {
        let dir = std::env::temp_dir().join(format!("troupe-bench-keys-{}", std::process::id()));
        let r = latency(a, Some(&dir), false);
        let _ = std::fs::remove_dir_all(&dir);
        r?;
    }
    Ok(())
}

/// The smallest sample Zenoh puts in shared memory (its
/// `transport_optimization/message_size_threshold`).
const SHM_FROM: usize = 3072;

/// The small sample a large one is compared with.
const SMALL: usize = 64;

/// Flags of `troupe bench latency`.
#[derive(Debug, Clone, Args)]
pub struct LatencyArgs {
    /// Payload size in bytes (a laser scan with as many beams as fit, or
    /// with `--carry camera` an RGB image of as many bytes).
    #[arg(long, default_value_t = 1500)]
    pub size: usize,
    /// What the samples carry: a laser scan (numbers, decoded one by one)
    /// or a camera frame (bytes, copied in one piece).
    #[arg(long, value_enum, default_value_t = Carry::Scan)]
    pub carry: Carry,
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
    /// A Zenoh setting for both processes' sessions on Troupe's path, as
    /// KEY=VALUE (a key of Zenoh's configuration, a JSON5 value);
    /// repeatable. `--zenoh-set transport/unicast/lowlatency=true
    /// --zenoh-set transport/unicast/qos/enabled=false` shows what Zenoh's
    /// lowlatency transport would give Troupe's sessions.
    #[arg(long = "zenoh-set", value_name = "KEY=VALUE", value_parser = key_value)]
    pub zenoh_set: Vec<(String, String)>,
    /// How long the near side's reader on Troupe's path polls for each
    /// echo before it sleeps, as a node given `--spin` polls its inbox
    /// (set by the global `--spin`).
    #[arg(skip)]
    pub spin: Duration,
}

/// Takes the next item: polled with `poll` (`Ok(None)`: none yet) for up
/// to `spin`, then waited for with `wait`, as a node's thread waits with
/// `--spin`; nothing within 5 s is an error.
fn next<T, E: std::fmt::Display>(
    spin: Duration,
    mut poll: impl FnMut() -> Result<Option<T>, E>,
    wait: impl FnOnce(Duration) -> Result<Option<T>, E>,
) -> anyhow::Result<T> {
    const WITHIN: Duration = Duration::from_secs(5);
    let t0 = Instant::now();
    if !spin.is_zero() {
        let mut got = Ok(None);
        troupe_node::spin_until(t0 + spin, || {
            got = poll();
            !matches!(got, Ok(None))
        });
        if let Some(t) = got.map_err(|e| anyhow::anyhow!("{e}"))? {
            return Ok(t);
        }
    }
    wait(WITHIN.saturating_sub(t0.elapsed()))
        .map_err(|e| anyhow::anyhow!("{e}"))?
        .context("nothing within 5 s")
}

/// Parses `--zenoh-set`'s KEY=VALUE.
pub fn key_value(s: &str) -> Result<(String, String), String> {
    match s.split_once('=') {
        Some((k, v)) if !k.is_empty() && !v.is_empty() => Ok((k.to_owned(), v.to_owned())),
        _ => Err(format!(
            "`{s}` is not KEY=VALUE (e.g. transport/unicast/qos/enabled=false)"
        )),
    }
}

/// A session of `z`'s in `mode` with `set`'s Zenoh settings on top.
fn open_with(z: &ZenohArgs, mode: Mode, set: &[(String, String)]) -> anyhow::Result<Session> {
    let mut c = z.config(mode)?;
    for (key, value) in set {
        c.insert_json5(key, value).map_err(|e| {
            // Zenoh's message ends with its source's path, and a JSON5
            // parser's runs over lines: kept only when short.
            let why = e.to_string();
            let why = why.split(" at /").next().unwrap_or_default();
            let why = if why.contains('\n') || why.len() > 60 {
                String::new()
            } else {
                format!("{why}; ")
            };
            anyhow::anyhow!(
                "--zenoh-set {key}={value}: not a key of Zenoh's configuration, or not a value for it ({why}the keys and their values: Zenoh's DEFAULT_CONFIG.json5)"
            )
        })?;
    }
    troupe_node::zenoh::open(c)
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))
}

/// The bench's keys under `prefix`: ping, pong, req, ready, and the one-way
/// samples with their acks.
fn bench_keys(prefix: &str) -> [String; 6] {
    ["ping", "pong", "req", "ready", "oneway", "ack"].map(|k| format!("{prefix}/{k}"))
}

/// A robot port no stack uses, whose keys the secure bench runs under.
const SECURE_ROBOT: u32 = 65_000;

/// What the bench's samples carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Carry {
    /// `laser/scan@1`: ranges as numbers.
    Scan,
    /// `camera/data@1`: an RGB image, raw.
    Camera,
}

/// A sample the bench sends: one of [`Carry`]'s messages.
#[derive(Debug, Clone)]
enum Msg {
    Scan(laser::Scan),
    Camera(camera::Data),
}

impl Msg {
    /// A message of `carry` whose payload is about `size` bytes.
    fn of(carry: Carry, size: usize) -> Msg {
        match carry {
            Carry::Scan => {
                let base = codec::encode(&laser::Scan::default(), 0.0).len();
                Msg::Scan(laser::Scan {
                    ranges: vec![4.2; size.saturating_sub(base + 2) / 4],
                    ..Default::default()
                })
            }
            Carry::Camera => {
                let base = codec::encode(&camera::Data::default(), 0.0).len();
                let bytes = size.saturating_sub(base + 3);
                Msg::Camera(camera::Data {
                    width: u32::try_from(bytes / 3).unwrap_or(u32::MAX),
                    height: 1,
                    bpp: 24,
                    format: camera::FORMAT_RGB888,
                    image: vec![7; bytes],
                    ..Default::default()
                })
            }
        }
    }

    fn encode(&self, stamp: f64) -> Vec<u8> {
        match self {
            Msg::Scan(m) => codec::encode(m, stamp),
            Msg::Camera(m) => codec::encode(m, stamp),
        }
    }

    /// Encodes into `out`, exactly [`Msg::encode`]'s length, as a driver
    /// writes into a lent buffer.
    fn encode_into(&self, stamp: f64, out: &mut [u8]) -> bool {
        match self {
            Msg::Scan(m) => codec::encode_into(m, stamp, out),
            Msg::Camera(m) => codec::encode_into(m, stamp, out),
        }
    }

    /// Decodes a payload as the message its schema names, as a node
    /// decodes what it takes: its stamp and the message.
    fn decode(payload: &[u8]) -> anyhow::Result<(f64, Msg)> {
        Ok(match codec::schema_of(payload)? {
            camera::Data::SCHEMA => {
                let m = codec::decode::<camera::Data>(payload)?;
                (m.stamp, Msg::Camera(m.msg))
            }
            _ => {
                let m = codec::decode::<laser::Scan>(payload)?;
                (m.stamp, Msg::Scan(m.msg))
            }
        })
    }

    /// Reads a payload as a subscriber that keeps nothing reads it: a
    /// camera frame in place ([`camera::DataView`]), a scan decoded. Its
    /// stamp.
    fn read(payload: &[u8]) -> anyhow::Result<f64> {
        Ok(match codec::schema_of(payload)? {
            camera::Data::SCHEMA => {
                let frame = codec::decode_view::<camera::DataView>(payload)?;
                std::hint::black_box(frame.msg);
                frame.stamp
            }
            _ => Msg::decode(payload)?.0,
        })
    }
}

/// `n` times (sorted) what `f` takes.
fn timed(n: usize, mut f: impl FnMut() -> anyhow::Result<()>) -> anyhow::Result<Vec<Duration>> {
    let mut times = Vec::with_capacity(n);
    for _ in 0..n.max(1) {
        let t0 = Instant::now();
        f()?;
        times.push(t0.elapsed());
    }
    times.sort();
    Ok(times)
}

/// What decoding `payload` and encoding it again takes, as the round
/// trips do at each end.
fn recode(payload: &[u8]) -> anyhow::Result<()> {
    let (stamp, msg) = Msg::decode(payload)?;
    std::hint::black_box(msg.encode(stamp));
    Ok(())
}

/// The payload's costs in one process, beside the round trips: a copy
/// (the least a sample handed over by value can cost), Troupe's codec on
/// it, and for a scan the codec on a camera frame of its size (bytes,
/// which it copies in one piece: msgs/src/bytes.rs). Rows of `n` sorted
/// times.
fn in_memory(msg: &Msg, n: usize) -> anyhow::Result<Vec<(&'static str, Vec<Duration>)>> {
    let payload = msg.encode(0.0);
    let mut rows = vec![
        (
            "a copy of the payload",
            timed(n, || {
                std::hint::black_box(payload.to_vec());
                Ok(())
            })?,
        ),
        ("decode + encode of it", timed(n, || recode(&payload))?),
    ];
    if let Msg::Scan(_) = msg {
        let frame = Msg::of(Carry::Camera, payload.len()).encode(0.0);
        rows.push(("the same, a camera frame", timed(n, || recode(&frame))?));
    }
    Ok(rows)
}

/// Zenoh's settings for its fastest path: the `lowlatency` transport
/// writes each message from the caller's thread (the default queues it
/// for the link's transmit task), which needs QoS off. Troupe's sessions
/// cannot run so: that transport carries no message larger than one batch
/// (64 KB; a 500×500 map is 250 KB) and closes the link on one.
const FASTEST: [(&str, &str); 2] = [
    ("transport/unicast/lowlatency", "true"),
    ("transport/unicast/qos/enabled", "false"),
];

/// The largest sample (encoded) [`FASTEST`]'s transport carries: one
/// batch of 65,535 bytes, less its headers.
const FASTEST_MAX: usize = 65_000;

/// A session of `z`'s in `mode`, with [`FASTEST`] set.
fn open_fastest(z: &ZenohArgs, mode: Mode) -> anyhow::Result<Session> {
    let set = FASTEST.map(|(k, v)| (k.to_owned(), v.to_owned()));
    open_with(z, mode, &set)
}

/// The first address the bench's router listens on.
fn locator_of(session: &Session) -> anyhow::Result<String> {
    troupe_node::locators(session)
        .into_iter()
        .next()
        .context("the bench router has no locator")
}

/// A `troupe bench pong` child, told to exit (its stdin closed) when dropped.
struct Pong(Child);

impl Pong {
    /// Starts one against `session` (listening on `locator`), joined with
    /// `net`, and waits until it is ready.
    fn start(
        session: &Session,
        locator: &str,
        net: &[String],
        prefix: &str,
        fastest: bool,
        set: &[(String, String)],
    ) -> anyhow::Result<Pong> {
        let [_, _, _, ready_key, ..] = bench_keys(prefix);
        let ready = session
            .liveliness()
            .declare_subscriber(&ready_key)
            .history(true)
            .wait()
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        let mut cmd = Command::new(std::env::current_exe()?);
        cmd.args(["--connect", locator])
            .args(net)
            .args(["bench", "pong", "--prefix", prefix]);
        if fastest {
            cmd.arg("--fastest");
        }
        for (key, value) in set {
            cmd.arg("--zenoh-set").arg(format!("{key}={value}"));
        }
        let pong = Pong(
            cmd.stdin(Stdio::piped())
                .spawn()
                .context("starting `troupe bench pong`")?,
        );
        ready
            .recv_timeout(Duration::from_secs(20))
            .map_err(|e| anyhow::anyhow!("{e}"))?
            .context("`troupe bench pong` did not come up within 20 s")?;
        Ok(pong)
    }
}

impl Drop for Pong {
    fn drop(&mut self) {
        drop(self.0.stdin.take());
        if let Err(e) = self.0.wait_timeout_or_kill(Duration::from_secs(5)) {
            tracing::warn!("bench pong: {e}");
        }
    }
}

/// Plain TCP with a namespace, or (`keys`: a directory for them) TLS with
/// mutual authentication and access control, the pong a host of robot
/// `SECURE_ROBOT` whose keys the bench uses; samples through shared memory
/// if `shm` (and large enough), else through the network. Prints a table
/// and returns one sample's times one way (none over TLS).
fn latency(
    a: &LatencyArgs,
    keys: Option<&std::path::Path>,
    shm: bool,
) -> anyhow::Result<Option<OneWay>> {
    let ns = format!("bench-{}", std::process::id());
    let (zr, prefix, pong_net) = match keys {
        None => (
            ZenohArgs {
                listen: vec!["tcp/127.0.0.1:0".into()],
                no_multicast: true,
                namespace: Some(ns.clone()),
                no_shm: !shm,
                ..Default::default()
            },
            keys::BENCH_PING.trim_end_matches("/ping").to_owned(),
            [
                vec![
                    "--no-multicast".to_owned(),
                    "--namespace".to_owned(),
                    ns.clone(),
                ],
                (!shm).then(|| "--no-shm".to_owned()).into_iter().collect(),
            ]
            .concat(),
        ),
        Some(dir) => {
            let (router, pong) = troupe_fleet::keys::bench_configs(dir, SECURE_ROBOT)?;
            (
                ZenohArgs {
                    listen: vec!["tls/127.0.0.1:0".into()],
                    zenoh_config: Some(router),
                    no_shm: true,
                    ..Default::default()
                },
                format!("robot/{SECURE_ROBOT}/bench"),
                vec![
                    "--zenoh-config".to_owned(),
                    pong.display().to_string(),
                    "--no-shm".to_owned(),
                ],
            )
        }
    };
    let [ping_key, pong_key, req_key, ..] = bench_keys(&prefix);
    let session = open_with(&zr, Mode::Router, &a.zenoh_set)?;
    // Certificates name `localhost`, not the address.
    let locator = locator_of(&session)?.replace("tls/127.0.0.1", "tls/localhost");
    let pong = Pong::start(&session, &locator, &pong_net, &prefix, false, &a.zenoh_set)?;

    let replies = session
        .declare_subscriber(&pong_key)
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let publisher = session
        .declare_publisher(&ping_key)
        .express(true)
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let msg = Msg::of(a.carry, a.size);
    let size = msg.encode(0.0).len();
    let total = a.warmup + a.samples;

    // The floor: the same bytes between two processes over plain TCP,
    // a round trip after each of Zenoh's.
    let mut echo = crate::harness::TcpEcho::start(size)?;
    let mut tcp = Vec::with_capacity(a.samples);
    let mut pubsub = Vec::with_capacity(a.samples);
    for i in 0..total {
        let payload = msg.encode(i as f64);
        let t0 = Instant::now();
        publisher
            .put(payload)
            .wait()
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        loop {
            let s = next(a.spin, || replies.try_recv(), |t| replies.recv_timeout(t))
                .context("no echo")?;
            let (stamp, _) = Msg::decode(&s.payload().to_bytes())?;
            if stamp == i as f64 {
                break;
            }
        }
        if i >= a.warmup {
            pubsub.push(t0.elapsed());
            tcp.push(echo.round_trip()?);
        }
    }

    let mut getreply = Vec::with_capacity(a.samples);
    for i in 0..total {
        let payload = msg.encode(i as f64);
        let t0 = Instant::now();
        let rx = session
            .get(&req_key)
            .payload(payload)
            .timeout(Duration::from_secs(5))
            .wait()
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        let r = next(a.spin, || rx.try_recv(), |t| rx.recv_timeout(t)).context("no reply")?;
        let s = r
            .into_result()
            .map_err(|e| anyhow::anyhow!("refused: {e:?}"))?;
        Msg::decode(&s.payload().to_bytes())?;
        if i >= a.warmup {
            getreply.push(t0.elapsed());
        }
    }
    let one = match keys {
        None => Some(one_way(&session, &prefix, &msg, a, shm)?),
        Some(_) => None,
    };
    drop(pong);
    // Zenoh at its fastest, over plain TCP only (the secure run compares
    // with the plain one).
    let best = match keys {
        None if size <= FASTEST_MAX && !shm => {
            Some(fastest(a, &zr, &prefix, &pong_net, &msg, &mut echo)?)
        }
        _ => None,
    };
    // The payload's own costs do not depend on the transport: measured
    // once, beside the plain run.
    let memory = match keys {
        None if !shm => Some(in_memory(&msg, a.samples)?),
        _ => None,
    };
    pubsub.sort();
    getreply.sort();
    tcp.sort();
    let mut out = std::io::stdout().lock();
    let over = if keys.is_some() {
        "tls/127.0.0.1, mutual authentication and access control"
    } else if shm && size >= SHM_FROM {
        "tcp/127.0.0.1, the samples through shared memory"
    } else {
        "tcp/127.0.0.1"
    };
    let schema = match msg {
        Msg::Scan(_) => laser::Scan::SCHEMA,
        Msg::Camera(_) => camera::Data::SCHEMA,
    };
    let settings = if a.zenoh_set.is_empty() {
        String::new()
    } else {
        let kv: Vec<String> = a
            .zenoh_set
            .iter()
            .map(|(k, v)| format!("{k}={v}"))
            .collect();
        format!(", with {}", kv.join(", "))
    };
    let settings = if a.spin.is_zero() {
        settings
    } else {
        format!(
            "{settings}; the near reader polling {} µs before it sleeps (--spin)",
            a.spin.as_micros()
        )
    };
    writeln!(out, "troupe bench latency: {size}-byte {schema} payload, {} samples (+{} warm-up), two processes, Zenoh over {over}{settings}", a.samples, a.warmup)?;
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
    row(&mut out, "TCP round trip (the floor)", &tcp, false)?;
    row(&mut out, "put/sub round trip", &pubsub, false)?;
    row(&mut out, "one sample (round trip/2)", &pubsub, true)?;
    row(&mut out, "get/reply round trip", &getreply, false)?;
    if let Some(one) = &one {
        row(&mut out, "one sample one way", &one.times, false)?;
        writeln!(
            out,
            "  {:<26} {:.0} samples/s, {:.0} MB/s ({} back to back, each decoded{})",
            "throughput",
            one.rate,
            one.rate * size as f64 / 1e6,
            one.burst,
            if one.copied > 0 {
                format!("; {} not lent by the pool, copied", one.copied)
            } else {
                String::new()
            }
        )?;
    }
    for (name, times) in memory.iter().flatten() {
        row(&mut out, name, times, false)?;
    }
    writeln!(
        out,
        "  p50 against TCP: one sample {:.2}x a TCP one way, get/reply {:.2}x a TCP round trip (target <= 1.3x each)",
        crate::harness::times_floor(&pubsub, &tcp),
        crate::harness::times_floor(&getreply, &tcp),
    )?;
    if best.is_none() && keys.is_none() && !shm {
        writeln!(
            out,
            "  Zenoh at its fastest: not run: its lowlatency transport carries no sample larger than one batch ({FASTEST_MAX} bytes) and closes the link on one"
        )?;
    }
    if let Some((best, beside)) = best {
        writeln!(
            out,
            "  Zenoh at its fastest: the lowlatency transport (writes from the caller's thread; QoS off), callbacks on both sides, the reader spinning on a core"
        )?;
        row(&mut out, "TCP round trip, in turn", &beside, false)?;
        row(&mut out, "put/sub round trip", &best, false)?;
        writeln!(
            out,
            "  p50 against TCP: one sample {:.2}x a TCP one way in turn with it, {:.2}x the floor above (no session of Troupe's can do better: see ARCHITECTURE.md, \"What a hop costs\")",
            crate::harness::times_floor(&best, &beside),
            crate::harness::times_floor(&best, &tcp),
        )?;
        writeln!(
            out,
            "  Troupe's path against Zenoh's fastest, p50, same run: put/sub round trip {:.2}x (target <= 1.2x)",
            percentile(&pubsub, 0.5).as_secs_f64() / percentile(&best, 0.5).as_secs_f64().max(1e-9)
        )?;
    }
    Ok(one)
}

/// One sample one way, as a driver publishes it and a subscriber takes
/// it, timed by the wall clock, which every process of a host reads
/// alike: `msg` stamped, encoded (with `lend`, into a buffer of Zenoh's
/// shared-memory pool, as `Bus::publish_lent` does; else into a `Vec`),
/// put, and decoded by the pong, which acks with what it measured before
/// the next is sent.
struct OneWay {
    /// Sorted, one per timed sample.
    times: Vec<Duration>,
    /// Samples a second sent back to back, none dropped (the publisher
    /// blocks while the link is full), and how many that burst held.
    rate: f64,
    burst: usize,
    /// Samples the pool could not lend, sent from a `Vec` instead.
    copied: usize,
}

fn one_way(
    session: &Session,
    prefix: &str,
    msg: &Msg,
    a: &LatencyArgs,
    lend: bool,
) -> anyhow::Result<OneWay> {
    use troupe_node::zenoh::bytes::ZBytes;
    use troupe_node::zenoh::shm::GarbageCollect;
    let [.., oneway_key, ack_key] = bench_keys(prefix);
    let clock = troupe_node::Clock::wall();
    let acks = session
        .declare_subscriber(&ack_key)
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let publisher = session
        .declare_publisher(&oneway_key)
        .express(true)
        .congestion_control(CongestionControl::Block)
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let len = msg.encode(0.0).len();
    let mut copied = 0;
    let mut send = |stamp: f64| -> anyhow::Result<()> {
        let lent = lend
            .then(|| session.get_shm_provider().into_option())
            .flatten()
            .and_then(|pool| {
                pool.garbage_collect();
                let mut buf = pool
                    .alloc(len)
                    .with_policy::<GarbageCollect>()
                    .wait()
                    .ok()?;
                msg.encode_into(stamp, &mut buf).then_some(buf)
            });
        let payload = match lent {
            Some(buf) => ZBytes::from(buf),
            None => {
                copied += usize::from(lend);
                ZBytes::from(msg.encode(stamp))
            }
        };
        publisher
            .put(payload)
            .wait()
            .map_err(|e| anyhow::anyhow!("{e}"))
    };
    let ack = |wait: Duration| -> anyhow::Result<(f64, f64)> {
        let s = acks
            .recv_timeout(wait)
            .map_err(|e| anyhow::anyhow!("{e}"))?
            .context("no ack within 5 s")?;
        let b = s.payload().to_bytes();
        let word = |i: usize| -> anyhow::Result<f64> {
            let w = b.get(i..i + 8).context("a short ack")?;
            Ok(f64::from_le_bytes(w.try_into()?))
        };
        Ok((word(0)?, word(8)?))
    };
    let mut times = Vec::with_capacity(a.samples);
    for i in 0..a.warmup + a.samples {
        let stamp = clock.now();
        send(stamp)?;
        let took = loop {
            let (answers, took) = ack(Duration::from_secs(5))?;
            if answers == stamp {
                break took;
            }
        };
        if i >= a.warmup {
            times.push(Duration::from_secs_f64(took.max(0.0)));
        }
    }
    times.sort();
    // Throughput: a burst sent back to back, every sample acked.
    let burst = a.samples.min(1000);
    let t0 = Instant::now();
    for _ in 0..burst {
        send(clock.now())?;
    }
    for _ in 0..burst {
        ack(Duration::from_secs(5))?;
    }
    let rate = burst as f64 / t0.elapsed().as_secs_f64().max(1e-9);
    Ok(OneWay {
        times,
        rate,
        burst,
        copied,
    })
}

/// Put/sub round trips at Zenoh's fastest between two processes, each
/// followed by a TCP round trip on `echo` (both sorted), between a
/// router of `zr`'s and a pong joined with `pong_net`: both sessions on the
/// lowlatency transport ([`FASTEST`]), the echo answered from its
/// subscriber's callback, and the reply decoded by a callback that this
/// thread spins on, so that no thread wakes on this side (Troupe's
/// nodes take data on a thread that sleeps until it comes). A bound
/// for what configuration can reach, not a way to run.
fn fastest(
    a: &LatencyArgs,
    zr: &ZenohArgs,
    prefix: &str,
    pong_net: &[String],
    msg: &Msg,
    echo: &mut crate::harness::TcpEcho,
) -> anyhow::Result<(Vec<Duration>, Vec<Duration>)> {
    let [ping_key, pong_key, ..] = bench_keys(prefix);
    let session = open_fastest(zr, Mode::Router)?;
    let _pong = Pong::start(
        &session,
        &locator_of(&session)?,
        pong_net,
        prefix,
        true,
        &[],
    )?;
    let echoed = Arc::new(AtomicU64::new(0));
    let count = echoed.clone();
    let _replies = session
        .declare_subscriber(&pong_key)
        .callback(move |s| {
            // Decoded as the other rounds decode each echo.
            if Msg::decode(&s.payload().to_bytes()).is_ok() {
                count.fetch_add(1, Ordering::Release);
            }
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let publisher = session
        .declare_publisher(&ping_key)
        .express(true)
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let (mut best, mut tcp) = (Vec::with_capacity(a.samples), Vec::with_capacity(a.samples));
    for i in 0..(a.warmup + a.samples) as u64 {
        let payload = msg.encode(i as f64);
        let t0 = Instant::now();
        publisher
            .put(payload)
            .wait()
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        let mut spins = 0u32;
        while echoed.load(Ordering::Acquire) <= i {
            std::hint::spin_loop();
            spins = spins.wrapping_add(1);
            if spins % 4096 == 0 && t0.elapsed() > Duration::from_secs(5) {
                anyhow::bail!("no echo within 5 s on the lowlatency transport");
            }
        }
        let took = t0.elapsed();
        if i >= a.warmup as u64 {
            best.push(took);
            tcp.push(echo.round_trip()?);
        }
    }
    best.sort();
    tcp.sort();
    Ok((best, tcp))
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

/// The echo side: decodes each ping as a node would, re-encodes it and
/// sends it back; with `fastest`, on Zenoh's fastest transport
/// ([`FASTEST`]), as [`fastest`] times it.
pub fn pong(
    z: &ZenohArgs,
    prefix: &str,
    fastest: bool,
    set: &[(String, String)],
) -> anyhow::Result<()> {
    let [ping_key, pong_key, req_key, ready_key, oneway_key, ack_key] = bench_keys(prefix);
    let session = if fastest {
        open_fastest(z, Mode::Peer)?
    } else {
        open_with(z, Mode::Peer, set)?
    };
    let back = session
        .declare_publisher(pong_key)
        .express(true)
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let _sub = session
        .declare_subscriber(ping_key)
        .callback(move |s| match Msg::decode(&s.payload().to_bytes()) {
            Ok((stamp, m)) => {
                if let Err(e) = back.put(m.encode(stamp)).wait() {
                    tracing::warn!("pong: {e}");
                }
            }
            Err(e) => tracing::warn!("pong: {e}"),
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    // One way: the time from the sender's stamp (the wall clock, which
    // both processes read) to the message decoded here, sent back with
    // the stamp it answers.
    let ack = session
        .declare_publisher(ack_key)
        .express(true)
        .congestion_control(CongestionControl::Block)
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let clock = troupe_node::Clock::wall();
    let _one_way = session
        .declare_subscriber(oneway_key)
        .callback(move |s| match Msg::read(&s.payload().to_bytes()) {
            Ok(stamp) => {
                let took = clock.now() - stamp;
                let mut answer = stamp.to_le_bytes().to_vec();
                answer.extend_from_slice(&took.to_le_bytes());
                if let Err(e) = ack.put(answer).wait() {
                    tracing::warn!("pong: {e}");
                }
            }
            Err(e) => tracing::warn!("pong: {e}"),
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let _q = session
        .declare_queryable(req_key)
        .callback(|q| {
            let bytes = q
                .payload()
                .map(|p| p.to_bytes().into_owned())
                .unwrap_or_default();
            let sent = match Msg::decode(&bytes) {
                Ok((stamp, m)) => q.reply(q.key_expr().clone(), m.encode(stamp)).wait(),
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
