//! What the benchmarks share: the worlds and stacks they run (the
//! 100-Pioneer world among them), where Stage's bitmaps are, reading a
//! child's announced address, and the statistics they print.

use std::process::Command;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context;
use troupe_node::ZenohArgs;

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

/// The world-file definition of robot model `name`: `size` m across, with
/// a ring of 12 one-beam IR rangers on its edge, one every 30° (`range`
/// m, `fov`°), driven by controller `ctrl`.
pub(crate) fn ir_ring_robot(name: &str, size: f64, range: f64, fov: f64, ctrl: &str) -> String {
    let r = size / 2.0;
    let sensors: Vec<String> = (0..12)
        .map(|k| {
            let deg = if k > 6 { 30 * k - 360 } else { 30 * k };
            let a = f64::from(deg).to_radians();
            format!(
                "{name}_ir( pose [{:.3} {:.3} 0 {deg}] )",
                r * a.cos(),
                r * a.sin()
            )
        })
        .collect();
    format!(
        "define {name}_ir sensor ( size [0.01 0.01 0.01] range [0 {range}] fov {fov} samples 1 )\n\
         define {name}_ring ranger ( {} )\n\
         define {name} position ( size [{size} {size} 0.1] drive \"diff\" ctrl \"{ctrl}\" {name}_ring( pose [0 0 -0.05 0] ) )\n",
        sensors.join(" ")
    )
}

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
    p100_stack_with(dir, bitmaps, speedup, &[])
}

/// [`p100_stack`], launched with `extra` flags (`--ros2`).
pub(crate) fn p100_stack_with(
    dir: &std::path::Path,
    bitmaps: &std::path::Path,
    speedup: f64,
    extra: &[&str],
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
    let (mut launcher, router, z) = launched(&dir.join("p100.cfg"), extra)?;
    let devices = (0..100u32)
        .flat_map(|i| ["position2d:0", "ranger:0", "ranger:1"].map(|d| format!("{}:{d}", 6665 + i)))
        .map(|d| d.parse::<troupe_msgs::DevAddr>())
        .collect::<Result<Vec<_>, _>>()?;
    let ready = troupe_inspect::wait_ready(
        troupe_inspect::ReadyArgs {
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

/// `troupe launch CFG EXTRA…` with an embedded router on an ephemeral
/// loopback port and no bridge: the launcher, the router's endpoint, and
/// the flags that join it.
pub(crate) fn launched(
    cfg: &std::path::Path,
    extra: &[&str],
) -> anyhow::Result<(std::process::Child, String, ZenohArgs)> {
    let mut launcher = Command::new(std::env::current_exe()?)
        .args(["--no-multicast", "launch"])
        .arg(cfg)
        .args(["--no-bridge", "--listen", "tcp/127.0.0.1:0"])
        .args(extra)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .context("starting `troupe launch`")?;
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
    Ok((launcher, router, z))
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
            w.push_str(&ir_ring_robot("bench_small", 0.2, 1.0, 10.0, "wander"));
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

/// CPU time of the whole process so far (every thread): the particle
/// filter weighs large particle sets on both cores, and its target is CPU
/// time, not wall time.
pub(crate) fn cpu_time() -> Duration {
    use nix::time::{clock_gettime, ClockId};
    clock_gettime(ClockId::CLOCK_PROCESS_CPUTIME_ID).map_or(Duration::ZERO, Duration::from)
}

/// Robots in the 100-Pioneer world.
pub(crate) const ROBOTS: u32 = 100;

/// A process killed when dropped.
pub(crate) struct Kid(pub(crate) std::process::Child);

impl Drop for Kid {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// CPU time of process `pid` so far.
pub(crate) fn cpu_of(pid: u32) -> Duration {
    use nix::time::{clock_getcpuclockid, clock_gettime};
    let pid = nix::unistd::Pid::from_raw(i32::try_from(pid).unwrap_or(0));
    clock_getcpuclockid(pid)
        .and_then(clock_gettime)
        .map_or(Duration::ZERO, Duration::from)
}

/// What a row measures, from its start: the view server's CPU and the
/// robots' data.
pub(crate) struct Window {
    pid: Option<u32>,
    cpu: Duration,
    odometry: u64,
    ranges: u64,
    t: Instant,
}

/// A row's figures: the server's share of a core, odometry Hz per robot,
/// ranger samples a second; and the wall seconds they cover.
pub(crate) struct Figures {
    pub(crate) cpu: f64,
    pub(crate) odometry: f64,
    pub(crate) ranges: f64,
    pub(crate) wall: f64,
}

impl Window {
    pub(crate) fn start(pid: Option<u32>, odometry: &AtomicU64, ranges: &AtomicU64) -> Window {
        Window {
            pid,
            cpu: pid.map_or(Duration::ZERO, cpu_of),
            odometry: odometry.load(Ordering::Relaxed),
            ranges: ranges.load(Ordering::Relaxed),
            t: Instant::now(),
        }
    }

    pub(crate) fn end(&self, odometry: &AtomicU64, ranges: &AtomicU64) -> Figures {
        let wall = self.t.elapsed().as_secs_f64();
        Figures {
            cpu: self
                .pid
                .map_or(0.0, |p| (cpu_of(p) - self.cpu).as_secs_f64() / wall),
            odometry: (odometry.load(Ordering::Relaxed) - self.odometry) as f64
                / wall
                / f64::from(ROBOTS),
            ranges: (ranges.load(Ordering::Relaxed) - self.ranges) as f64 / wall,
            wall,
        }
    }
}

/// Counts the samples of every device of interface `i`, while the
/// subscriber lives.
pub(crate) fn count(
    session: &troupe_node::zenoh::Session,
    i: troupe_msgs::Interface,
) -> anyhow::Result<(
    troupe_node::zenoh::pubsub::Subscriber<()>,
    std::sync::Arc<AtomicU64>,
)> {
    use troupe_node::zenoh::Wait;
    let n = std::sync::Arc::new(AtomicU64::new(0));
    let c = n.clone();
    let sub = session
        .declare_subscriber(troupe_msgs::keys::data_of(i))
        .callback(move |_| {
            c.fetch_add(1, Ordering::Relaxed);
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("subscribing to {i}: {e}"))?;
    Ok((sub, n))
}

/// Plain loopback TCP between this process and a child of its own (`troupe
/// bench echo`, which sends each message back): the floor any middleware
/// between two processes stands on. A bench times its round trips in turn
/// with what it compares with them, so both meet the machine alike (an
/// idle core wakes slower than a busy one: alone, the same round trip
/// measured 20-60 µs from run to run). `TCP_NODELAY` on both ends.
pub(crate) struct TcpEcho {
    /// Held to be killed with the echo.
    _child: Kid,
    stream: std::net::TcpStream,
    msg: Vec<u8>,
    sent: u8,
}

impl TcpEcho {
    /// Starts the child, echoing messages of `size` bytes.
    pub(crate) fn start(size: usize) -> anyhow::Result<TcpEcho> {
        let listener =
            std::net::TcpListener::bind("127.0.0.1:0").context("binding the TCP floor")?;
        let addr = listener.local_addr()?;
        let child = Kid(Command::new(std::env::current_exe()?)
            .args(["bench", "echo", "--to", &addr.to_string(), "--size"])
            .arg(size.to_string())
            .spawn()
            .context("starting `troupe bench echo`")?);
        let (stream, _) = listener.accept().context("accepting `troupe bench echo`")?;
        stream.set_nodelay(true)?;
        stream.set_read_timeout(Some(Duration::from_secs(5)))?;
        Ok(TcpEcho {
            _child: child,
            stream,
            msg: vec![0; size.max(1)],
            sent: 0,
        })
    }

    /// One message there and back.
    pub(crate) fn round_trip(&mut self) -> anyhow::Result<Duration> {
        use std::io::{Read, Write};
        self.sent = self.sent.wrapping_add(1);
        self.msg[0] = self.sent;
        let t0 = Instant::now();
        self.stream.write_all(&self.msg)?;
        self.stream
            .read_exact(&mut self.msg)
            .context("no TCP echo within 5 s")?;
        let took = t0.elapsed();
        anyhow::ensure!(
            self.msg[0] == self.sent,
            "the TCP echo sent back another message"
        );
        Ok(took)
    }
}

/// `v`'s median over `floor`'s, as a ratio (both sorted).
pub(crate) fn times_floor(v: &[Duration], floor: &[Duration]) -> f64 {
    percentile(v, 0.5).as_secs_f64() / percentile(floor, 0.5).as_secs_f64().max(1e-9)
}

/// A server of the 100-Pioneer world's (`troupe view`, `troupe foxglove`)
/// started as a client of `router` with `args`, and what follows
/// `announce` on the first line of its standard output that starts so.
pub(crate) fn server(router: &str, args: &[&str], announce: &str) -> anyhow::Result<(Kid, String)> {
    let mut kid = Kid(Command::new(std::env::current_exe()?)
        .args(["--no-multicast", "--connect", router])
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .with_context(|| format!("starting `troupe {}`", args.join(" ")))?);
    let line = line_after(&mut kid.0, announce)?;
    Ok((kid, line))
}

/// `troupe bench echo`: sends back every `size`-byte message it reads
/// from `to`, until the socket closes.
pub(crate) fn echo(to: &str, size: usize) -> anyhow::Result<()> {
    use std::io::{Read, Write};
    let mut s = std::net::TcpStream::connect(to).with_context(|| format!("connecting to {to}"))?;
    s.set_nodelay(true)?;
    let mut msg = vec![0u8; size.max(1)];
    while s.read_exact(&mut msg).is_ok() {
        s.write_all(&msg)?;
    }
    Ok(())
}

/// A field of `/proc/self/status` given in kB, in MB (0 where unknown).
pub(crate) fn status_mb(field: &str) -> f64 {
    status_mb_of("self", field)
}

/// A field of `/proc/PID/status` given in kB, in MB (0 where unknown).
pub(crate) fn status_mb_of(pid: &str, field: &str) -> f64 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
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

/// The pid of `parent`'s child that runs a node of `driver` (the
/// simulator: `stage`).
pub(crate) fn node_pid(parent: u32, driver: &str) -> Option<u32> {
    let marker = format!("\0node\0{driver}\0");
    std::fs::read_dir("/proc").ok()?.flatten().find_map(|e| {
        let pid = e.file_name().to_string_lossy().parse::<u32>().ok()?;
        let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
        let ppid = stat
            .rsplit_once(") ")?
            .1
            .split(' ')
            .nth(1)?
            .parse::<u32>()
            .ok()?;
        let cmd = std::fs::read_to_string(format!("/proc/{pid}/cmdline")).ok()?;
        (ppid == parent && cmd.contains(&marker)).then_some(pid)
    })
}

#[cfg(test)]
mod tests {
    #[test]
    fn an_ir_ring_robot_has_twelve_sensors_on_its_edge() {
        let w = super::ir_ring_robot("small", 0.2, 1.0, 10.0, "wander");
        let poses: Vec<&str> = w
            .split("small_ir( pose [")
            .skip(1)
            .map(|p| p.split(']').next().unwrap_or_default())
            .collect();
        assert_eq!(poses.len(), 12, "{w}");
        assert_eq!(poses[0], "0.100 0.000 0 0");
        assert_eq!(poses[1], "0.087 0.050 0 30");
        assert_eq!(poses[6], "-0.100 0.000 0 180");
        assert_eq!(poses[7], "-0.087 -0.050 0 -150");
        assert!(w.contains("range [0 1] fov 10 samples 1"), "{w}");
        assert!(
            w.contains("size [0.2 0.2 0.1] drive \"diff\" ctrl \"wander\""),
            "{w}"
        );
    }
}
