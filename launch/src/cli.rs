//! The command line: every subcommand, its flags and its help.

use std::path::Path;
use std::time::Duration;

use anyhow::Context;
use clap::{Args, Parser, Subcommand};
use troupe_msgs::DevAddr;
use troupe_node::{NodeConfig, Section, ZenohArgs};

use crate::drivers;

/// Troupe: Player/Stage rebuilt on Zenoh. Every driver is its own process;
/// devices meet on keys like robot/6665/laser/0.
#[derive(Debug, Parser)]
#[command(name = "troupe", version, propagate_version = true)]
#[command(after_help = "Examples:
  troupe launch worlds/simple.cfg                 # a stack from a .cfg (embedded router)
  troupe router                                   # a router for this host (tcp/[::]:7447)
  troupe node dummy --provides ranger:0 -o rate=10
  troupe node rangertolaser --requires ranger:0 --provides laser:0
  troupe list                                     # Player's \"Available devices\"
  troupe echo laser:0 --count 1
  troupe hz laser:0")]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,

    #[command(flatten)]
    pub zenoh: ZenohArgs,

    /// Log filter (e.g. `debug`, `info,troupe_node=trace`); default `info` or $RUST_LOG.
    #[arg(long, global = true, value_name = "FILTER")]
    pub log: Option<String>,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run a robot stack from a Player .cfg or a plan: one process per driver.
    #[command(after_help = "Examples:
  troupe launch worlds/laser.cfg                  # like `player worlds/laser.cfg`
  troupe launch robot.cfg -p 7000                 # default robot port 7000
  troupe launch plan.toml --host hostb --connect tcp/10.0.0.1:7447
  troupe launch robot.cfg --dry-run               # print the plan, start nothing
  troupe launch worlds/simple.cfg --speedup 5     # the simulator at 5x real time

An embedded Zenoh router listens on tcp/127.0.0.1:7447 unless --connect names
another. Ctrl-C stops the nodes in reverse start order.")]
    Launch(crate::supervisor::LaunchArgs),

    /// Translate a Player .cfg into a launch plan (TOML) and print it.
    #[command(after_help = "Example:
  troupe plan robot.cfg > plan.toml && $EDITOR plan.toml && troupe launch plan.toml")]
    Plan(crate::supervisor::PlanArgs),

    /// Run one driver as this process.
    #[command(after_help = "Examples:
  troupe node dummy --provides ranger:0 -o rate=10
  troupe node rangertolaser --requires ranger:0 --provides laser:0
  troupe node rangertolaser --section '{\"name\":\"rangertolaser\",\"requires\":[\"ranger:0\"],\"provides\":[\"laser:0\"]}'
  troupe node stage --world worlds/simple.world      # headless; exits at the world's quit_time
  troupe node stage --world w.world -o quit_time=60 -o speedup=0 --snapshot w.png

The section is what a `driver ( … )` block of a Player .cfg says; flags add to it.
The node waits for every required device to be live, then announces its own.")]
    Node(NodeArgs),

    /// Serve the devices to Player clients (libplayerc, libplayerc++, playerv) over TCP.
    #[command(after_help = "Examples:
  troupe bridge                          # robot 6665 on 127.0.0.1:6665, like `player`
  troupe bridge -p 6665 -p 6666          # two robots, two ports
  troupe bridge -p 6665=127.0.0.1:0      # any free port; the chosen one is printed
  troupe bridge --bind 0.0.0.0           # other hosts too (Player has no authentication)
  troupe bridge --bind 0.0.0.0 --allow 10.1.0.0/16   # other hosts of that network only
  troupe bridge --import robot7:6665     # a running Player server's devices, on Troupe's keys

Each port speaks Player 3 TCP/XDR: DEVLIST lists the live devices of that robot,
subscriptions follow their keys (robot/6665/laser/0), commands and requests go to
their drivers. `troupe launch` starts one for the robots of its plan.")]
    Bridge(crate::bridge::BridgeArgs),

    /// Print the devices live on the network, like Player's "Available devices".
    #[command(after_help = "Example:
  $ troupe list
  robot/6665  laser:0       rangertolaser  ready
  robot/6665  ranger:0      dummy          ready
  $ troupe list --watch          # + and - lines as devices come and go")]
    List(ListArgs),

    /// Print the samples of a device, decoded (like playerprint).
    #[command(after_help = "Examples:
  troupe echo laser:0                 # robot 6665
  troupe echo 6666:position2d:0 --count 1
  troupe echo robot/6665/laser/0 --json | jq .msg")]
    Echo(EchoArgs),

    /// Measure the rate and jitter of a device's samples.
    #[command(after_help = "Example:
  $ troupe hz laser:0
  rate: 10.000 Hz  min: 0.0998 s  max: 0.1003 s  std dev: 0.00012 s  window: 10")]
    Hz(HzArgs),

    /// Exit 0 once the given devices are live (a container's health check).
    #[command(after_help = "Examples:
  troupe ready 6665:laser:0 6665:position2d:0     # exit 0 if both are live now, 1 if not
  troupe ready laser:0 --wait 30                  # wait up to 30 s for it
  troupe --connect tcp/router:7447 ready          # the router answers

With no device it checks that the router answers. As a Docker health check,
in exec form: [\"CMD\", \"/troupe\", \"--connect\", \"tcp/router:7447\", \"ready\", \"6665:laser:0\"].")]
    Ready(ReadyArgs),

    /// Run a Zenoh router, for multi-host setups.
    #[command(after_help = "Examples:
  troupe router                                  # listens on tcp/[::]:7447
  troupe router --listen tcp/127.0.0.1:7447      # this host only
  troupe router --zenoh-config secure.json5      # TLS, auth, ACLs")]
    Router(RouterArgs),

    /// Play a serial device (SICK LMS200, Hokuyo URG, Pioneer, Erratic) on a pseudo-terminal, for its driver to talk to.
    #[command(after_help = "Examples:
  troupe emulate sicklms200 --link /tmp/laser     # then: port \"/tmp/laser\" in the .cfg
  troupe emulate urglaser --link /tmp/urg         # then: port \"/tmp/urg\" use_serial 1 in the .cfg
  troupe emulate urglaser --link /tmp/urg --usb   # a URG on USB: use_serial 0, SCIP 2.0
  troupe emulate p2os --link /tmp/pioneer --subclass p3at
  troupe emulate erratic --link /tmp/erratic --revision \"Rev G\"
  troupe --connect tcp/127.0.0.1:7447 emulate sicklms200 --link /tmp/laser --stage-laser 6665:laser:1
  troupe --connect tcp/127.0.0.1:7447 emulate p2os --link /tmp/pioneer --stage-model r0 --stage-sim 6666:simulation:0
  troupe --connect tcp/127.0.0.1:7447 emulate sicklms200 --link /tmp/laser --stage-model r0 --stage-sim 6666:simulation:0
  troupe emulate p2os --link /tmp/pioneer --capture pioneer.txt   # what crosses the line, both ways
  troupe emulate sicklms200 --link /tmp/laser --corrupt 0.1 --noise 0.1
  troupe emulate sicklms200 --link /tmp/laser --unplug-after 10 --replug-after 2

The emulator speaks the device's side of the protocol at the device's own
speed: it powers up at its default baud rate, ignores bytes sent at another,
and carries each byte in the time the line would. Faults are injected on
what it sends.")]
    Emulate(crate::emulate::EmulateArgs),

    /// Build the Docker image: this binary, the libraries it loads, the sample worlds.
    #[command(after_help = "Examples:
  cargo build --release && target/release/troupe image      # troupe:latest
  troupe image --tag troupe:dev --worlds my/worlds
  troupe image --no-build && docker build -t troupe target/docker

The image starts FROM scratch (no registry is needed): /troupe is the
entrypoint, run as user 10000, with the worlds at /worlds.")]
    Image(crate::docker::ImageArgs),

    /// Write a Docker Compose file that runs a .cfg or plan as a fleet of containers.
    #[command(after_help = "Examples:
  troupe compose worlds/fleet.cfg --in-image /worlds -o docker-compose.yml
  troupe compose robot.cfg -o robot/docker-compose.yml   # mounts robot.cfg's directory at /stack

One service per host of the plan (the host field of the addresses a driver
provides, \"robot1:6665:laser:0\"; a plan without hosts is one service, `stack`),
each running `troupe launch FILE --host NAME`, its nodes still one process each;
a router, and a Player bridge on 127.0.0.1 of this machine. Health checks
(`troupe ready`), restart policies, reconnection and a short lease are set.")]
    Compose(crate::docker::ComposeArgs),

    /// Make a fleet's certificates and each host's Zenoh config (TLS, mutual authentication).
    #[command(after_help = "Example:
  troupe fleet-keys keys --hosts sim,robot1,robot2     # router.json5, sim.json5, …
  troupe --zenoh-config keys/router.json5 router       # listens on tls/[::]:7447 only
  troupe --zenoh-config keys/robot1.json5 launch robot1.cfg

One authority (ca.pem; its key ca-key.pem stays where it was made) signs a
certificate per identity, its common name the identity's name. Each
identity's .json5 holds its key and certificate and the authority's
certificate: a host whose certificate another authority signed, or that has
none, cannot join.")]
    FleetKeys(crate::keys::KeysArgs),

    /// Watch the running world in a browser: walls, robots, their sensors, the live devices.
    #[command(after_help = "Examples:
  troupe launch worlds/simple.cfg &
  troupe view                                 # then open http://127.0.0.1:8080/
  troupe view --port 0                        # any free port; the address is printed
  troupe --connect tcp/sim-host:7447 view     # a fleet's world, from another host

The page (embedded in this binary; nothing is fetched from elsewhere) draws
every simulator's world as Stage's window did: static bodies, robots at their
true poses, laser, ranger and sonar readings, the simulation time and its
speed against real time; and lists the live devices as `troupe list` does.
With a localizer and a planner running it draws amcl's particles and
hypotheses and the planner's goal and path; a click (dragged for the
heading) gives the planner a goal or sets amcl's pose, and the arrow keys
drive a chosen position2d. Drag to pan, scroll to zoom, pick a robot to
follow. URL parameters fix the view: ?x=-4&y=-4&scale=60 (metres, pixels
per metre); ?still draws one moment and opens no stream (for screenshots:
chromium --headless --screenshot URL?still).")]
    View(crate::view::ViewArgs),

    /// Record devices' samples (default: all of them, and the clock) to an MCAP file.
    #[command(after_help = "Examples:
  troupe record -o run.mcap                       # every device and sim/clock, until Ctrl-C
  troupe record 'robot/6665/**' -o r0.mcap --duration 60
  troupe record -o fleet.mcap --split-size 500 --compress zstd   # fleet_0.mcap, fleet_1.mcap, …

Each sample is kept byte for byte (schema tag, stamp, body) on an MCAP
channel named by its key; devices' comings and goings too. A recorder
that falls behind drops, counts and says so, and exits non-zero.

The recorder joins as a Zenoh peer (unless --mode says otherwise): it
finds the publishers through the router and takes their data from them
directly where it can reach them, so nothing waits in the router's queue
(where a burst of a fast simulation would be dropped).")]
    Record(crate::mcaplog::RecordArgs),

    /// Publish a recording back onto its keys, at any speed.
    #[command(after_help = "Examples:
  troupe play run.mcap                            # as recorded, sim/clock included
  troupe play run.mcap --rate 10 --start 5 --end 65
  troupe play run.mcap --remap 6665=7000 --loop
  troupe --namespace replay play run.mcap         # beside a live fleet

The devices the recording saw live are declared live while it plays, so a
stack's `requires` (amcl on laser:0) are met by the replay.")]
    Play(crate::mcaplog::PlayArgs),

    /// Look into a recording: `info`, or `export` it as JSON lines or a Player log.
    #[command(subcommand)]
    Log(crate::mcaplog::LogCmd),

    /// List the drivers this build can run (`--all`: and the Player drivers
    /// sample files name that it cannot, with what to use instead).
    Drivers {
        /// Also the Player drivers Troupe does not have.
        #[arg(long)]
        all: bool,
    },

    /// List Player's interfaces and their codes.
    Interfaces,

    /// Benchmarks that print numbers.
    #[command(subcommand)]
    Bench(BenchCmd),
}

#[derive(Debug, Args)]
pub struct NodeArgs {
    /// The Player driver name (see `troupe drivers`).
    pub driver: String,

    /// The driver's section, as JSON text or a path to a JSON file.
    #[arg(long, value_name = "JSON|FILE")]
    pub section: Option<String>,

    /// A device this driver provides (repeatable), e.g. `laser:0`.
    #[arg(long, value_name = "ADDR")]
    pub provides: Vec<DevAddr>,

    /// A device this driver requires (repeatable), e.g. `odometry:::position2d:0`.
    #[arg(long, value_name = "ADDR")]
    pub requires: Vec<DevAddr>,

    /// An option, by Player's name (repeatable): `-o rate=20`, `-o pose=[0,0,0]`.
    #[arg(short = 'o', long = "option", value_name = "KEY=VALUE")]
    pub options: Vec<String>,

    /// Robot field (port) for addresses that give none, as `player -p PORT`.
    #[arg(short = 'p', long = "robot", value_name = "PORT")]
    pub robot: Option<u32>,

    /// The world file of the `stage` driver (sets its `worldfile` option).
    #[arg(long, value_name = "FILE")]
    pub world: Option<std::path::PathBuf>,

    /// With `stage`: write a PNG of the world when the node stops.
    #[arg(long, value_name = "FILE.png")]
    pub snapshot: Option<std::path::PathBuf>,

    /// Follow the simulator's clock (sim/clock) instead of wall time.
    #[arg(long)]
    pub sim_time: bool,

    /// Seconds to wait for each required device.
    #[arg(long, value_name = "SECS", default_value_t = 30.0)]
    pub requires_timeout: f64,
}

#[derive(Debug, Args)]
pub struct ListArgs {
    /// Only this robot (port).
    #[arg(short = 'p', long = "robot", value_name = "PORT")]
    pub robot: Option<u32>,
    /// One JSON object per device.
    #[arg(long)]
    pub json: bool,
    /// Seconds to wait for answers.
    #[arg(long, value_name = "SECS", default_value_t = 2.0)]
    pub wait: f64,
    /// Keep running and print each device as it comes (`+`) and goes (`-`).
    #[arg(long)]
    pub watch: bool,
}

#[derive(Debug, Args)]
pub struct ReadyArgs {
    /// Devices that must be live (`laser:0`, `6666:position2d:0`).
    #[arg(value_name = "DEVICE")]
    pub devices: Vec<DevAddr>,
    /// Robot (port) for a device that names none.
    #[arg(short = 'p', long = "robot", value_name = "PORT", default_value_t = troupe_msgs::DEFAULT_ROBOT)]
    pub robot: u32,
    /// Seconds to wait for them to come up (0: look once).
    #[arg(long, value_name = "SECS", default_value_t = 0.0)]
    pub wait: f64,
}

#[derive(Debug, Args)]
pub struct EchoArgs {
    /// A device (`laser:0`, `6666:position2d:0`) or a key (`robot/6665/laser/0`, `sim/clock`).
    pub target: String,
    /// Robot (port) for a device that names none.
    #[arg(short = 'p', long = "robot", value_name = "PORT", default_value_t = troupe_msgs::DEFAULT_ROBOT)]
    pub robot: u32,
    /// One JSON object per sample, arrays in full.
    #[arg(long)]
    pub json: bool,
    /// Stop after N samples.
    #[arg(short = 'n', long, value_name = "N")]
    pub count: Option<u64>,
    /// Give up after this many seconds without a sample (default: wait forever).
    #[arg(long, value_name = "SECS")]
    pub timeout: Option<f64>,
}

#[derive(Debug, Args)]
pub struct HzArgs {
    /// A device (`laser:0`) or a key.
    pub target: String,
    /// Robot (port) for a device that names none.
    #[arg(short = 'p', long = "robot", value_name = "PORT", default_value_t = troupe_msgs::DEFAULT_ROBOT)]
    pub robot: u32,
    /// Samples in the moving window.
    #[arg(long, value_name = "N", default_value_t = 100)]
    pub window: usize,
    /// Stop after N reports (one a second).
    #[arg(short = 'n', long, value_name = "N")]
    pub count: Option<u64>,
}

#[derive(Debug, Args)]
pub struct RouterArgs {}

#[derive(Debug, Subcommand)]
pub enum BenchCmd {
    /// Latency of one sample between two processes (put/sub round trip and get/reply).
    #[command(after_help = "Example:
  cargo run --release -- bench latency --size 1500 --samples 5000")]
    Latency(crate::bench::LatencyArgs),
    /// Time from `troupe launch` to all devices live, and restart after a kill, for a 5-node plan.
    #[command(after_help = "Example:
  cargo run --release -- bench launch --runs 5")]
    Launch(crate::bench::LaunchBenchArgs),
    /// Simulator speed (simulated s per wall s) and peak memory on three worlds.
    #[command(after_help = "Example:
  cargo run --release -- bench stage --bitmaps ../shared/compat/stage/bitmaps")]
    Stage(crate::bench::StageBenchArgs),
    /// Player clients through the bridge to real mapfile and Stage drivers: request round trips, a full map fetch, 100 clients at 10 Hz.
    #[command(after_help = "Example:
  cargo run --release -- bench bridge --map ../shared/compat/stage/bitmaps/cave.png")]
    Bridge(crate::bridgebench::BridgeBenchArgs),
    /// Navigation cores: amcl updates/s by particle count, wavefront plan time, vfh decision time.
    #[command(after_help = "Example:
  cargo run --release -- bench nav --map ../shared/compat/stage/bitmaps/cave.png")]
    Nav(crate::navbench::NavBenchArgs),
    /// Scan rates of the sicklms200 and urglaser drivers against their emulators, at their baud rates.
    #[command(after_help = "Example:
  cargo run --release -- bench serial --seconds 5")]
    Serial(crate::serialbench::SerialBenchArgs),
    /// Recording the 100-Pioneer world flat out (loss, CPU, bytes/s), playing it back, `log info` on a large file.
    #[command(after_help = "Example:
  cargo run --release -- bench record --seconds 20")]
    Record(crate::mcaplog::RecordBenchArgs),
    /// `troupe view` under load: 100 Pioneers in real time, headless browsers on its page: their frame rates, the server's CPU, the robots' data rates.
    #[command(after_help = "Example:
  cargo run --release -- bench view --browsers 0,1,20 --bitmaps ../shared/compat/stage/bitmaps")]
    View(crate::viewbench::ViewBenchArgs),
    /// The echo side of `bench latency` (started by it).
    #[command(hide = true)]
    Pong {
        /// Where its keys live (`bench`, or a robot's keys under access control).
        #[arg(long, default_value = "bench")]
        prefix: String,
    },
}

/// `troupe node`: builds the section from flags and runs the driver.
pub fn node(a: NodeArgs, z: &ZenohArgs) -> anyhow::Result<()> {
    let mut section = match &a.section {
        None => Section::new(&a.driver),
        Some(s) => {
            let text = if s.trim_start().starts_with('{') {
                s.clone()
            } else {
                std::fs::read_to_string(Path::new(s))
                    .with_context(|| format!("reading section file {s}"))?
            };
            Section::from_json(&text)?
        }
    };
    if section.name != a.driver {
        anyhow::bail!(
            "the section is for driver `{}`, not `{}`",
            section.name,
            a.driver
        );
    }
    section.provides.extend(a.provides);
    section.requires.extend(a.requires);
    if let Some(r) = a.robot {
        section.robot = r;
    }
    if let Some(w) = &a.world {
        section
            .options
            .insert("worldfile".into(), w.display().to_string().into());
    }
    if let Some(p) = &a.snapshot {
        section
            .options
            .insert("snapshot".into(), p.display().to_string().into());
    }
    for o in &a.options {
        let (k, v) = o
            .split_once('=')
            .with_context(|| format!("option `{o}` is not KEY=VALUE"))?;
        let value = serde_json::from_str(v).unwrap_or_else(|_| serde_json::Value::String(v.into()));
        section.options.insert(k.to_owned(), value);
    }
    supervised()?;
    if !(a.requires_timeout.is_finite() && a.requires_timeout > 0.0) {
        anyhow::bail!("--requires-timeout must be a positive number of seconds");
    }
    let cfg = NodeConfig {
        sim_time: a.sim_time,
        requires_timeout: Duration::from_secs_f64(a.requires_timeout),
    };
    drivers::run(&a.driver, section, z, &cfg)
}

/// Under `troupe launch`: die with the launcher, never outlive it.
pub fn supervised() -> anyhow::Result<()> {
    let Ok(ppid) = std::env::var(crate::supervisor::SUPERVISOR_ENV) else {
        return Ok(());
    };
    nix::sys::prctl::set_pdeathsig(nix::sys::signal::Signal::SIGTERM)
        .context("asking to be stopped with the launcher")?;
    // The launcher may have died before the request took effect.
    if nix::unistd::getppid().as_raw().to_string() != ppid {
        anyhow::bail!("the launcher (pid {ppid}) is gone");
    }
    Ok(())
}
