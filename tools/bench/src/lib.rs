//! `troupe bench`: the benchmarks that print Troupe's figures, each beside
//! the reference it must beat where one exists (Player's, Stage's, a TCP
//! round trip).
//!
//! One module per `troupe bench` subcommand; [`harness`] holds what they
//! share (the stacks and worlds they run, statistics). They start stacks
//! as a user does, with this binary as a child. ARCHITECTURE.md says why
//! the benchmarks are one crate at the top of the tree.

pub mod bridge;
pub mod camera;
pub mod foxglove;
mod harness;
mod hostile;
pub mod latency;
pub mod launch;
pub mod nav;
pub mod python;
mod raw_player;
mod ray;
pub mod record;
pub mod ros2;
pub mod scale;
pub mod serial;
pub mod slam;
pub mod stage;
pub mod view;
mod vs_stage;

use clap::Subcommand;
use troupe_node::ZenohArgs;

/// `troupe bench`'s subcommands.
#[derive(Debug, Subcommand)]
pub enum BenchCmd {
    /// Latency of one sample between two processes (put/sub round trip and get/reply).
    #[command(after_help = "Example:
  cargo run --release -- bench latency --size 1500 --samples 5000")]
    Latency(latency::LatencyArgs),
    /// What a camera driver spends to deliver VGA frames at 30 Hz to two subscribers, over shared memory and through TCP.
    #[command(after_help = "Example:
  cargo run --release -- bench camera --seconds 10")]
    Camera(camera::CameraArgs),
    /// Time from `troupe launch` to all devices live, and restart after a kill, for a 5-node plan.
    #[command(after_help = "Example:
  cargo run --release -- bench launch --runs 5")]
    Launch(launch::LaunchBenchArgs),
    /// Simulator speed (simulated s per wall s) and peak memory on three worlds.
    #[command(after_help = "Example:
  cargo run --release -- bench stage --bitmaps ../shared/compat/stage/bitmaps")]
    Stage(stage::StageBenchArgs),
    /// Player clients through the bridge to real mapfile and Stage drivers: request round trips, a full map fetch, 100 clients at 10 Hz.
    #[command(after_help = "Example:
  cargo run --release -- bench bridge --map ../shared/compat/stage/bitmaps/cave.png")]
    Bridge(crate::bridge::BridgeBenchArgs),
    /// Navigation cores: amcl updates/s by particle count, wavefront plan time, vfh decision time.
    #[command(after_help = "Example:
  cargo run --release -- bench nav --map ../shared/compat/stage/bitmaps/cave.png")]
    Nav(crate::nav::NavBenchArgs),
    /// Scan rates of the sicklms200 and urglaser drivers against their emulators, at their baud rates.
    #[command(after_help = "Example:
  cargo run --release -- bench serial --seconds 5")]
    Serial(crate::serial::SerialBenchArgs),
    /// Recording the 100-Pioneer world flat out (loss, CPU, bytes/s), alone and with the view and a bridge client attached; playing it back, `log info` on a large file.
    #[command(after_help = "Example:
  cargo run --release -- bench record --seconds 20")]
    Record(crate::record::RecordBenchArgs),
    /// `troupe view` under load: 100 Pioneers in real time, headless browsers on its page: their frame rates, the server's CPU, the robots' data rates.
    #[command(after_help = "Example:
  cargo run --release -- bench view --browsers 0,1,20 --bitmaps ../shared/compat/stage/bitmaps")]
    View(crate::view::ViewBenchArgs),
    /// `troupe foxglove` under load: 100 Pioneers in real time, one client subscribed to every channel: the server's CPU, the robots' data rates with and without it.
    #[command(after_help = "Example:
  cargo run --release -- bench foxglove --seconds 10 --bitmaps ../shared/compat/stage/bitmaps")]
    Foxglove(crate::foxglove::FoxgloveBenchArgs),
    /// Maps built from simulated wanders (office, Stage's cave and autolab): accuracy, coverage, speed.
    #[command(after_help = "Example:
  cargo run --release -- bench slam --seconds 900 --stage-worlds ../shared/compat/stage")]
    Slam(slam::SlamBenchArgs),
    /// The Python package under load: scans/s in a read() loop and with callbacks, a request's round trip against the Rust client's.
    #[command(after_help = "Example:
  pip install ./python && cargo run --release -- bench python --python python3")]
    Python(python::PythonBenchArgs),
    /// ROS 2 (`--ros2`): a laser's latency and throughput to a ROS 2 subscriber against Troupe's own key; 100 Pioneers flat out with and without ROS 2: speed and samples lost.
    #[command(after_help = "Example:
  cargo run --release -- bench ros2 --seconds 3 --bitmaps ../shared/compat/stage/bitmaps")]
    Ros2(ros2::Ros2BenchArgs),
    /// Costs by fleet size: 0, 10, 100, 1,000 and 10,000 robots on one generated map: time until ready, `troupe list`, simulator speed, CPU and memory per robot, samples delivered and lost to a `robot/**` subscriber, the router's CPU.
    #[command(after_help = "Example:
  cargo run --release -- bench scale --robots 10,100,1000,10000 --seconds 10")]
    Scale(scale::ScaleArgs),
    /// The echo side of `bench latency` (started by it).
    #[command(hide = true)]
    Pong {
        /// Where its keys live (`bench`, or a robot's keys under access control).
        #[arg(long, default_value = "bench")]
        prefix: String,
        /// On Zenoh's fastest transport (lowlatency, QoS off).
        #[arg(long)]
        fastest: bool,
        /// Zenoh settings, as `bench latency --zenoh-set` gives them.
        #[arg(long = "zenoh-set", value_name = "KEY=VALUE", value_parser = latency::key_value)]
        set: Vec<(String, String)>,
    },
    /// Runs a command and prints its wall time, CPU and peak memory (started by `bench stage --stage`).
    #[command(hide = true)]
    Measure {
        /// The command and its arguments.
        #[arg(trailing_var_arg = true, allow_hyphen_values = true, required = true)]
        cmd: Vec<std::ffi::OsString>,
    },
    /// The plain TCP echo the latency benches measure their floor with (started by them).
    #[command(hide = true)]
    Echo {
        /// The address to connect to.
        #[arg(long)]
        to: String,
        /// The size of each message in bytes.
        #[arg(long)]
        size: usize,
    },
}

/// Runs a `troupe bench` subcommand.
pub fn run(cmd: BenchCmd, z: &ZenohArgs) -> anyhow::Result<()> {
    match cmd {
        BenchCmd::Latency(a) => latency::run(&latency::LatencyArgs {
            spin: z.spin(),
            ..a
        }),
        BenchCmd::Camera(a) => camera::run(&a),
        BenchCmd::Pong {
            prefix,
            fastest,
            set,
        } => latency::pong(z, &prefix, fastest, &set),
        BenchCmd::Echo { to, size } => harness::echo(&to, size),
        BenchCmd::Measure { cmd } => vs_stage::measure(&cmd),
        BenchCmd::Launch(a) => launch::run(&a),
        BenchCmd::Stage(a) => stage::run(&a),
        BenchCmd::Bridge(a) => bridge::run(&a),
        BenchCmd::Nav(a) => nav::run(&a),
        BenchCmd::Serial(a) => serial::run(&a),
        BenchCmd::Record(a) => record::run(&a),
        BenchCmd::View(a) => view::run(&a),
        BenchCmd::Foxglove(a) => foxglove::run(&a),
        BenchCmd::Slam(a) => slam::run(&a),
        BenchCmd::Python(a) => python::run(&a),
        BenchCmd::Ros2(a) => ros2::run(&a),
        BenchCmd::Scale(a) => scale::run(&a),
    }
}
