//! The command line: every subcommand and its help; each subcommand's
//! flags are defined by the crate that runs it.

use clap::{Parser, Subcommand};
use troupe_node::ZenohArgs;

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

An embedded Zenoh router listens on tcp/127.0.0.1:7447 (--listen ENDPOINT moves
it, e.g. --listen tcp/0.0.0.0:7447 for other hosts) unless --connect names
another router; the nodes join it as peers (--mode client: as clients).
Ctrl-C stops the nodes in reverse start order.")]
    Launch(troupe_launch::supervisor::LaunchArgs),

    /// Translate a Player .cfg into a launch plan (TOML) and print it.
    #[command(args = offline(&[]))]
    #[command(after_help = "Example:
  troupe plan robot.cfg > plan.toml && $EDITOR plan.toml && troupe launch plan.toml")]
    Plan(troupe_launch::supervisor::PlanArgs),

    /// Run one driver as this process.
    #[command(after_help = "Examples:
  troupe node dummy --provides ranger:0 -o rate=10
  troupe node rangertolaser --requires ranger:0 --provides laser:0
  troupe node rangertolaser --section '{\"name\":\"rangertolaser\",\"requires\":[\"ranger:0\"],\"provides\":[\"laser:0\"]}'
  troupe node stage --world worlds/simple.world      # headless; exits at the world's quit_time
  troupe node stage --world w.world -o quit_time=60 -o speedup=0 --snapshot w.png

The section is what a `driver ( … )` block of a Player .cfg says; flags add to it.
The node waits for every required device to be live, then announces its own.")]
    Node(troupe_launch::node::NodeArgs),

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
    Bridge(troupe_bridge::command::BridgeArgs),

    /// Print the devices live on the network, like Player's "Available devices".
    #[command(after_help = "Example:
  $ troupe list
  robot/6665  laser:0       rangertolaser  ready
  robot/6665  ranger:0      dummy          ready
  $ troupe list --watch          # + and - lines as devices come and go")]
    List(troupe_inspect::ListArgs),

    /// Print the samples of a device, decoded (like playerprint).
    #[command(after_help = "Examples:
  troupe echo laser:0                 # robot 6665
  troupe echo 6666:position2d:0 --count 1
  troupe echo robot/6665/laser/0 --json | jq .msg")]
    Echo(troupe_inspect::EchoArgs),

    /// Measure the rate and jitter of a device's updates, per message kind.
    #[command(after_help = "Example:
  $ troupe hz laser:0
  rate: 10.000 Hz  min: 0.0998 s  max: 0.1003 s  std dev: 0.00012 s  window: 10  laser/scan (2.0 samples an update, counted once)

Each message kind of the device gets its own line. Samples of one kind that
carry the same stamp are one update (rangertolaser sends a scan's ranges and
then its intensities, as Player's does).")]
    Hz(troupe_inspect::HzArgs),

    /// Send a command to a device: drive a base, give a planner a goal.
    #[command(after_help = "Examples:
  troupe cmd position2d:0 vel 0.3 0 0.2            # forward 0.3 m/s, turning 0.2 rad/s, until Ctrl-C (then stop)
  troupe cmd position2d:0 vel 0.3 0 0 --for 2      # for 2 s, then stop
  troupe cmd planner:0 goal 5 0 0                  # plan to (5, 0), facing 0 rad
  troupe cmd 6666:gripper:0 close
  troupe cmd position2d:0 pos --json '{\"pos\": {\"x\": 1, \"y\": 0, \"yaw\": 0}}'

VALUES fill the message's fields in order (SI units, radians); a wrong
command name lists the ones the device takes. The fleet's access rules hold:
a viewer's identity cannot command.")]
    Cmd(troupe_inspect::CmdArgs),

    /// Make a request of a device and print the answer.
    #[command(after_help = "Examples:
  troupe call simulation:0 get_pose2d r0           # simulation/pose2d@1 {\"name\":\"r0\",\"pose\":{…}}
  troupe call simulation:0 set_pose2d r0 -6 -6 0.5
  troupe call localize:0 set_pose -6 -6 0.5 0.25 0.25 0.07 0 0 0
  troupe call laser:0 geom
  troupe call position2d:0 motor_power true

A refused request prints the device's reason and exits 1.")]
    Call(troupe_inspect::CallArgs),

    /// Exit 0 once the given devices are live (a container's health check).
    #[command(after_help = "Examples:
  troupe ready 6665:laser:0 6665:position2d:0     # exit 0 if both are live now, 1 if not
  troupe ready laser:0 --wait 30                  # wait up to 30 s for it
  troupe --connect tcp/router:7447 ready          # the router answers

With no device it checks that the router answers. As a Docker health check,
in exec form: [\"CMD\", \"/troupe\", \"--connect\", \"tcp/router:7447\", \"ready\", \"6665:laser:0\"].")]
    Ready(troupe_inspect::ReadyArgs),

    /// Run a Zenoh router, for multi-host setups.
    #[command(after_help = "Examples:
  troupe router                                  # listens on tcp/[::]:7447
  troupe router --listen tcp/127.0.0.1:7447      # this host only
  troupe router --zenoh-config secure.json5      # TLS, auth, ACLs")]
    Router(troupe_launch::router::RouterArgs),

    /// Play a serial device (SICK LMS200, Hokuyo URG, Pioneer, Erratic) on a pseudo-terminal, for its driver to talk to.
    #[command(after_help = "Examples:
  troupe emulate sicklms200 --link /tmp/laser     # then: port \"/tmp/laser\" in the .cfg
  troupe emulate urglaser --link /tmp/urg         # then: port \"/tmp/urg\" use_serial 1 in the .cfg
  troupe emulate urglaser --link /tmp/urg --usb   # a URG on USB: use_serial 0, SCIP 2.0
  troupe emulate p2os --link /tmp/pioneer --subclass p3at
  troupe emulate erratic --link /tmp/erratic --revision \"Rev G\"
  troupe emulate wbr914 --link /tmp/914           # then: port \"/tmp/914\" in Player's wbr914.cfg
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
    Emulate(troupe_emulate::EmulateArgs),

    /// Build the Docker image: this binary, the libraries it loads, the sample worlds.
    #[command(args = offline(&[]))]
    #[command(after_help = "Examples:
  cargo build --release && target/release/troupe image      # troupe:latest
  troupe image --tag troupe:dev --worlds my/worlds
  troupe image --no-build && docker build -t troupe target/docker

The image starts FROM scratch (no registry is needed): /troupe is the
entrypoint, run as user 10000, with the worlds at /worlds.")]
    Image(troupe_fleet::docker::ImageArgs),

    /// Write a Docker Compose file (or a Swarm stack, or Kubernetes manifests) that runs a .cfg or plan as a fleet of containers.
    #[command(args = offline(&["lease"]))]
    #[command(after_help = "Examples:
  troupe compose worlds/fleet.cfg --in-image /worlds -o docker-compose.yml
  troupe compose robot.cfg -o robot/docker-compose.yml   # mounts robot.cfg's directory at /stack
  troupe compose worlds/fleet.cfg --in-image /worlds --swarm -o troupe-stack.yml
  troupe compose worlds/fleet.cfg --in-image /worlds --k8s -o troupe-k8s.yml

One service per host of the plan (the host field of the addresses a driver
provides, \"robot1:6665:laser:0\"; a plan without hosts is one service, `stack`),
each running `troupe launch FILE --host NAME`, its nodes still one process each;
a router, and a Player bridge on 127.0.0.1 of this machine. Health checks
(`troupe ready`), restart policies, reconnection and a short lease are set.
With --swarm or --k8s, the fleet spans machines: each host runs on the
nodes labelled for it (troupe.host.HOST=true, troupe.host/HOST=true) beside
a router of its own, linked to the fleet's router (docs/fleets.md).")]
    Compose(troupe_fleet::docker::ComposeArgs),

    /// Make a fleet's certificates and each host's Zenoh config (TLS, mutual authentication).
    #[command(args = offline(&["namespace"]))]
    #[command(
        after_help = "Example (on one machine; across machines --router names the router's host):
  troupe fleet-keys keys --router localhost --hosts sim:6665:6666,robot1:6665 --viewers eye
  troupe --zenoh-config keys/localhost.json5 router    # the router's config is named after it; tls/[::]:7447 only
  troupe --zenoh-config keys/robot1.json5 launch worlds/laser.cfg --no-bridge
  troupe --zenoh-config keys/eye.json5 echo 6665:laser:0

One authority (ca.pem; its key ca-key.pem stays where it was made) signs a
certificate per identity, its common name the identity's name. Each
identity's .json5 holds its key and certificate and the authority's
certificate: a host whose certificate another authority signed, or that has
none, cannot join."
    )]
    FleetKeys(troupe_fleet::keys::KeysArgs),

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
    View(troupe_view::ViewArgs),

    /// Record devices' samples (default: all of them, and the clock) to an MCAP file.
    #[command(after_help = "Examples:
  troupe record -o run.mcap                       # every device and sim/clock, until Ctrl-C
  troupe record 'robot/6665/**' -o r0.mcap --duration 60
  troupe record -o fleet.mcap --split-size 500 --compress zstd   # fleet_0.mcap, fleet_1.mcap, …
  troupe record --format ros2 -o run-ros2.mcap    # ROS 2 messages: ros2 bag, rosbags, Foxglove

Each sample is kept byte for byte (schema tag, stamp, body) on an MCAP
channel named by its key; devices' comings and goings too. A recorder
that falls behind drops, counts and says so, and exits non-zero.

The recorder joins as a Zenoh peer (unless --mode says otherwise): it
finds the publishers through the router and takes their data from them
directly where it can reach them, so nothing waits in the router's queue
(where a burst of a fast simulation would be dropped).")]
    Record(troupe_record::RecordArgs),

    /// The fleet live in Foxglove: a Foxglove WebSocket server on 127.0.0.1:8765.
    #[command(after_help = "Examples:
  troupe foxglove                                 # then in Foxglove: Open connection, ws://127.0.0.1:8765
  troupe foxglove --port 0                        # any free port, printed
  troupe --namespace lab foxglove --bind 0.0.0.0  # for another machine: the protocol has no authentication

Every device is a channel named by its key (/robot/6665/laser/0), in
Foxglove's schemas where one fits (LaserScan, PoseInFrame, PosesInFrame,
Grid, FrameTransforms on /tf), JSON otherwise; the server's time is the
simulation's. Foxglove's teleop panel drives a position2d when it publishes
on /robot/6665/position2d/0/cmd_vel; a pose published on
/robot/6665/planner/0/goal is a planner goal.")]
    Foxglove(troupe_foxglove::FoxgloveArgs),

    /// Publish a recording back onto its keys, at any speed.
    #[command(after_help = "Examples:
  troupe play run.mcap                            # as recorded, sim/clock included
  troupe play run.mcap --rate 10 --start 5 --end 65
  troupe play run.mcap --remap 6665=7000 --loop
  troupe play ros.mcap --remap /scan=robot/6665/laser/0 --remap /odom=robot/6665/position2d/0
  troupe --namespace replay play run.mcap         # beside a live fleet

The devices the recording saw live are declared live while it plays, so a
stack's `requires` (amcl on laser:0) are met by the replay. A ROS 2 bag's
MCAP plays too: LaserScan, Odometry, PoseWithCovarianceStamped and Clock,
onto the devices their topics name (/robot_6665/laser_0, as `--format ros2`
names them) or their --remap gives.")]
    Play(troupe_record::PlayArgs),

    /// Look into a recording: `info`, or `export` it as JSON lines, a Player log or ROS 2 messages.
    #[command(args = offline(&[]))]
    #[command(
        subcommand,
        after_help = "Examples:
  troupe log info run.mcap
  troupe log export run.mcap | jq 'select(.key == \"robot/6665/laser/0\")'
  troupe log export run.mcap --format player > run.log     # what Player's readlog replays
  troupe log export run.mcap --format ros2 -o run-ros2.mcap  # ROS 2 messages, for ROS tools

A Player text log (writelog's) is not MCAP: replay it with the readlog
driver, or build a map from it with `troupe map build`."
    )]
    Log(troupe_record::LogCmd),

    /// Maps from logs: `build` one with SLAM from a robot's odometry and laser, `show` one.
    #[command(args = offline(&[]))]
    #[command(subcommand)]
    Map(troupe_map::MapCmd),

    /// List the drivers this build can run (`--all`: and the Player drivers
    /// sample files name that it cannot, with what to use instead).
    #[command(args = offline(&[]))]
    #[command(after_help = "Examples:
  troupe drivers
  troupe drivers --all | grep -i camera      # is there a camera driver?")]
    Drivers {
        /// Also the Player drivers Troupe does not have.
        #[arg(long)]
        all: bool,
    },

    /// List Player's interfaces and their codes.
    #[command(args = offline(&[]))]
    #[command(after_help = "Example:
  $ troupe interfaces | head -3
  1  player
  2  power
  3  gripper")]
    Interfaces,

    /// Benchmarks that print numbers.
    #[command(
        subcommand,
        after_help = "Examples:
  cargo run --release -- bench latency
  cargo run --release -- bench stage --bitmaps ../shared/compat/stage/bitmaps
  cargo run --release -- bench python --python python3

Each prints its figures beside the originals' where they exist;
docs/measured.md lists what each measured on the development machine."
    )]
    Bench(troupe_bench::BenchCmd),
}

/// The network flags again, hidden, for the commands that never join the
/// network: defined on such a command, they keep the global ones out of its
/// `--help` (and a `log` or `map` subcommand refuses them). `own`: the
/// flags the command defines for itself (`compose --lease`).
fn offline(own: &[&str]) -> Vec<clap::Arg> {
    use clap::{Arg, ArgAction};
    let valued = [
        ("connect", "connect"),
        ("listen", "listen"),
        ("mode", "mode"),
        ("namespace", "namespace"),
        ("zenoh_config", "zenoh-config"),
        ("lease", "lease"),
    ];
    let flags = [("no_multicast", "no-multicast"), ("reconnect", "reconnect")];
    let valued = valued.map(|(id, long)| Arg::new(id).long(long).action(ArgAction::Append));
    let flags = flags.map(|(id, long)| Arg::new(id).long(long).action(ArgAction::SetTrue));
    valued
        .into_iter()
        .chain(flags)
        .filter(|a| !own.contains(&a.get_id().as_str()))
        .map(|a| a.hide(true))
        .collect()
}

#[cfg(test)]
mod tests {
    use clap::CommandFactory;

    use super::Cli;

    /// Every command's path and its options that take a value.
    fn options(cmd: &clap::Command, path: &mut Vec<String>, out: &mut Vec<(Vec<String>, String)>) {
        for arg in cmd.get_arguments() {
            let takes = arg.get_num_args().is_none_or(|n| n.takes_values());
            if let (Some(long), true) = (arg.get_long(), takes) {
                if long != "help" && long != "version" {
                    out.push((path.clone(), long.to_owned()));
                }
            }
        }
        for sub in cmd.get_subcommands() {
            path.push(sub.get_name().to_owned());
            options(sub, path, out);
            path.pop();
        }
    }

    /// The command tree with nothing required, so that one flag parses alone.
    fn lenient(cmd: clap::Command) -> clap::Command {
        let ids: Vec<_> = cmd.get_arguments().map(|a| a.get_id().clone()).collect();
        let mut cmd = cmd.subcommand_required(false).arg_required_else_help(false);
        for id in ids {
            cmd = cmd.mut_arg(id, |a| a.required(false));
        }
        let subs: Vec<_> = cmd
            .get_subcommands()
            .map(|s| s.get_name().to_owned())
            .collect();
        for s in subs {
            cmd = cmd.mut_subcommand(s, lenient);
        }
        cmd
    }

    /// The value `long` parsed to in the innermost matched command.
    fn parsed_f64(m: &clap::ArgMatches, path: &[String], long: &str) -> Option<f64> {
        let mut m = m;
        for p in path {
            m = m.subcommand_matches(p)?;
        }
        let id = long.replace('-', "_");
        m.try_get_one::<f64>(&id).ok().flatten().copied()
    }

    /// No flag of any command takes a number it would panic on or misuse:
    /// `inf`, `NaN` and the like are refused while parsing (exit 2, with a
    /// message), and every duration refuses a negative value.
    #[test]
    fn no_flag_takes_a_non_finite_number_and_no_duration_a_negative_one() {
        let cmd = lenient(Cli::command());
        let mut all = Vec::new();
        options(&cmd, &mut Vec::new(), &mut all);
        assert!(all.len() > 100, "only {} options found", all.len());
        let mut accepted = Vec::new();
        let mut floats = 0;
        for (path, long) in &all {
            for value in ["2.5", "inf", "-inf", "NaN", "1e999", "-1", "1e300"] {
                let mut argv = vec!["troupe".to_owned()];
                argv.extend(path.iter().cloned());
                argv.push(format!("--{long}={value}"));
                let Ok(m) = cmd.clone().try_get_matches_from(&argv) else {
                    continue;
                };
                let Some(v) = parsed_f64(&m, path, long) else {
                    continue;
                };
                if value == "2.5" {
                    floats += 1;
                    continue;
                }
                let duration = cmd_arg_is_seconds(&cmd, path, long);
                if !v.is_finite() || (duration && !(0.0..=1e12).contains(&v)) {
                    accepted.push(argv[1..].join(" "));
                }
            }
        }
        assert!(
            floats > 0 || !accepted.is_empty(),
            "no number flags were found"
        );
        assert!(accepted.is_empty(), "accepted: {accepted:#?}");
    }

    /// Whether a flag's value names seconds (`value_name = "SECS"`).
    fn cmd_arg_is_seconds(cmd: &clap::Command, path: &[String], long: &str) -> bool {
        let mut c = cmd;
        for p in path {
            match c.find_subcommand(p) {
                Some(s) => c = s,
                None => return false,
            }
        }
        c.get_arguments()
            .find(|a| a.get_long() == Some(long))
            .and_then(|a| a.get_value_names())
            .is_some_and(|n| n.iter().any(|n| n.as_str() == "SECS"))
    }
}
