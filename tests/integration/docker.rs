//! The Docker fleet, judged from outside: the image `troupe image` builds and
//! the repository's docker-compose.yml (a router, the simulator, three robot
//! computers each running its navigation stack, the Player bridge). Each
//! test brings up its own compose project (its own network, free host
//! ports), tears it down whatever happens, and prints the containers' logs
//! when it fails. Faults are made from outside with the Docker CLI.
//!
//! Where no Docker engine answers these tests say so and pass; under CI
//! (`CI=true`) that is a failure. They print what they measure:
//! `cargo test -p troupe-tests --test integration docker -- --nocapture`.

use std::collections::{BTreeMap, BTreeSet};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::{mpsc, Mutex, MutexGuard, OnceLock};
use std::time::{Duration, Instant};

use troupe_client::{Client, SimulationProxy};
use troupe_msgs::codec::decode;
use troupe_msgs::{keys, localize, Interface, Pose2d};
use troupe_node::zenoh::sample::SampleKind;
use troupe_node::zenoh::{Session, Wait};
use troupe_node::{Mode, ZenohArgs};
use troupe_tests::{token_events, DEADLINE};

use crate::player::{Player, DATA};

/// The image the tests build and run (`$TROUPE_IMAGE` in the compose file).
const IMAGE: &str = "troupe:test";
/// docker-compose.yml's `--lease`.
const LEASE: Duration = Duration::from_secs(3);
/// The robots of worlds/fleet.cfg.
const ROBOTS: [u32; 3] = [6665, 6666, 6667];
/// What each robot computer provides.
const NAV: [&str; 6] = [
    "laser:0",
    "map:0",
    "localize:0",
    "position2d:1",
    "position2d:2",
    "planner:0",
];

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Every device of the fleet, as `6665:laser:0`.
fn fleet_devices() -> Vec<String> {
    let mut v = vec!["6665:simulation:0".to_owned()];
    for r in ROBOTS {
        for d in ["position2d:0", "ranger:0", "ranger:1"].iter().chain(&NAV) {
            v.push(format!("{r}:{d}"));
        }
    }
    v
}

fn nav_devices(robot: u32) -> Vec<String> {
    NAV.iter().map(|d| format!("{robot}:{d}")).collect()
}

fn run(cmd: &mut Command) -> Output {
    cmd.output()
        .unwrap_or_else(|e| panic!("running {cmd:?}: {e}"))
}

fn ok(cmd: &mut Command) -> String {
    let out = run(cmd);
    assert!(
        out.status.success(),
        "{cmd:?}: {}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).trim().to_owned()
}

/// The compose command (`docker compose` or `docker-compose`), once a
/// Docker engine answers; `None` (skip) where none does, outside CI.
fn engine() -> Option<Vec<String>> {
    static ENGINE: OnceLock<Result<Vec<String>, String>> = OnceLock::new();
    let found = ENGINE.get_or_init(|| {
        let answers = Command::new("docker")
            .args(["info", "--format", "{{.ServerVersion}}"])
            .output()
            .is_ok_and(|o| o.status.success());
        if !answers {
            return Err("no Docker engine answers (`docker info` failed)".into());
        }
        let works = |c: &[&str]| {
            Command::new(c[0])
                .args(&c[1..])
                .arg("version")
                .output()
                .is_ok_and(|o| o.status.success())
        };
        if works(&["docker", "compose"]) {
            Ok(vec!["docker".into(), "compose".into()])
        } else if works(&["docker-compose"]) {
            Ok(vec!["docker-compose".into()])
        } else {
            Err("Docker answers but has no Compose (`docker compose` or `docker-compose`)".into())
        }
    });
    match found {
        Ok(c) => Some(c.clone()),
        Err(why) => {
            troupe_tests::cannot_run(why);
            None
        }
    }
}

/// Builds the image once per test run, from this build's binary.
fn image() {
    static BUILT: OnceLock<()> = OnceLock::new();
    BUILT.get_or_init(|| {
        let context = std::env::temp_dir().join(troupe_tests::unique_namespace("image"));
        let t = Instant::now();
        let out = ok(Command::new(troupe_tests::troupe_bin())
            .args(["image", "--tag", IMAGE, "--context"])
            .arg(&context)
            .arg("--worlds")
            .arg(root().join("worlds")));
        let _ = std::fs::remove_dir_all(&context);
        eprintln!("docker: {out} in {:.1} s", t.elapsed().as_secs_f64());
    });
}

/// One fleet at a time: each is seven containers and some twenty processes,
/// on a two-core machine.
static TURN: Mutex<()> = Mutex::new(());

/// A compose project of the repository's docker-compose.yml.
struct Fleet {
    compose: Vec<String>,
    project: String,
    /// The compose file.
    file: PathBuf,
    /// `--secure`: the viewer's config this machine joins with.
    viewer: Option<PathBuf>,
    /// When `up -d` returned.
    up: Instant,
    _turn: MutexGuard<'static, ()>,
}

impl Fleet {
    /// `docker compose up -d`, with free host ports; `None` where Docker is absent.
    fn up(name: &str) -> Option<Fleet> {
        Fleet::up_with(name, root().join("docker-compose.yml"), None)
    }

    /// `up` of another compose file; `viewer`: the config to join it with.
    fn up_with(name: &str, file: PathBuf, viewer: Option<PathBuf>) -> Option<Fleet> {
        let compose = engine()?;
        let turn = TURN.lock().unwrap_or_else(|p| p.into_inner());
        image();
        let project = troupe_tests::unique_namespace(name).replace('_', "-");
        let mut fleet = Fleet {
            compose,
            project,
            file,
            viewer,
            up: Instant::now(),
            _turn: turn,
        };
        let t = Instant::now();
        fleet.ok(&["up", "-d"]);
        fleet.up = Instant::now();
        eprintln!(
            "docker: `compose up -d` returned in {:.1} s",
            t.elapsed().as_secs_f64()
        );
        Some(fleet)
    }

    fn cmd(&self, args: &[&str]) -> Command {
        let mut c = Command::new(&self.compose[0]);
        c.args(&self.compose[1..])
            .arg("-p")
            .arg(&self.project)
            .arg("-f")
            .arg(&self.file)
            .args(args)
            .env("TROUPE_IMAGE", IMAGE)
            .env("TROUPE_ROUTER_PORT", "");
        for r in ROBOTS {
            c.env(format!("TROUPE_PORT_{r}"), "");
        }
        c
    }

    fn ok(&self, args: &[&str]) -> String {
        ok(&mut self.cmd(args))
    }

    /// The host address a service's port is published on.
    fn published(&self, service: &str, port: u16) -> SocketAddr {
        let out = self.ok(&["port", service, &port.to_string()]);
        out.parse()
            .unwrap_or_else(|_| panic!("`port {service} {port}` said {out:?}"))
    }

    /// A client session of the fleet's router, from this machine.
    fn session(&self) -> Session {
        let at = self.published("router", 7447);
        match &self.viewer {
            None => ZenohArgs {
                connect: vec![format!("tcp/{at}")],
                no_multicast: true,
                ..Default::default()
            },
            // The router's certificate names localhost, not the address.
            Some(cfg) => ZenohArgs {
                connect: vec![format!("tls/localhost:{}", at.port())],
                zenoh_config: Some(cfg.clone()),
                ..Default::default()
            },
        }
        .open(Mode::Client)
        .expect("a session with the fleet's router")
    }

    fn container(&self, service: &str) -> String {
        let id = self.ok(&["ps", "-q", service]);
        assert!(!id.is_empty(), "no container for {service}");
        id
    }

    /// Every container's service, start time and restart count.
    fn starts(&self) -> BTreeMap<String, (String, u32)> {
        let ids = self.ok(&["ps", "-q"]);
        let mut out = BTreeMap::new();
        for id in ids.lines() {
            let line = ok(Command::new("docker").args([
                "inspect",
                "--format",
                "{{index .Config.Labels \"com.docker.compose.service\"}} {{.State.StartedAt}} {{.RestartCount}}",
                id,
            ]));
            let f: Vec<&str> = line.split_whitespace().collect();
            assert_eq!(f.len(), 3, "{line}");
            out.insert(f[0].to_owned(), (f[1].to_owned(), f[2].parse().unwrap()));
        }
        assert_eq!(out.len(), 6, "six services: {out:?}");
        out
    }

    /// The network every service is on.
    fn network(&self) -> String {
        format!("{}_fleet", self.project)
    }
}

impl Drop for Fleet {
    fn drop(&mut self) {
        if std::thread::panicking() {
            let logs = run(&mut self.cmd(&["logs", "--no-color", "--tail", "60"]));
            eprintln!(
                "--- logs of {} ---\n{}",
                self.project,
                String::from_utf8_lossy(&logs.stdout)
            );
        }
        let _ = run(&mut self.cmd(&["down", "-v", "-t", "5", "--remove-orphans"]));
    }
}

/// Devices as they come and go, seen through one session.
struct Tokens {
    sub: troupe_node::zenoh::pubsub::Subscriber<
        troupe_node::zenoh::handlers::FifoChannelHandler<troupe_node::zenoh::sample::Sample>,
    >,
    live: std::collections::BTreeSet<String>,
}

impl Tokens {
    fn new(session: &Session) -> Tokens {
        Tokens {
            sub: token_events(session),
            live: Default::default(),
        }
    }

    /// Waits until every device of `devices` is live (`up`) or gone (`!up`);
    /// the time it took.
    fn until(&mut self, devices: &[String], up: bool, within: Duration) -> Duration {
        let t = Instant::now();
        let deadline = t + within;
        loop {
            if devices.iter().all(|d| self.live.contains(d) == up) {
                return t.elapsed();
            }
            let s = self
                .sub
                .recv_deadline(deadline)
                .expect("liveliness channel")
                .unwrap_or_else(|| {
                    let wrong: Vec<&String> = devices
                        .iter()
                        .filter(|d| self.live.contains(*d) != up)
                        .collect();
                    panic!(
                        "within {within:?}, still {}: {wrong:?}",
                        if up { "not live" } else { "live" }
                    )
                });
            if let Ok((d, _)) = keys::parse_token(s.key_expr().as_str()) {
                let d = d.to_string();
                match s.kind() {
                    SampleKind::Put => self.live.insert(d),
                    SampleKind::Delete => self.live.remove(&d),
                };
            }
        }
    }
}

/// Arrival times of the samples of some devices, for their rates.
struct Rates {
    names: Vec<String>,
    rx: mpsc::Receiver<(usize, Instant)>,
    seen: Vec<Vec<Instant>>,
    _subs: Vec<troupe_node::zenoh::pubsub::Subscriber<()>>,
}

impl Rates {
    fn new(session: &Session, devices: &[&str]) -> Rates {
        let (tx, rx) = mpsc::channel();
        let subs = devices
            .iter()
            .enumerate()
            .map(|(i, d)| {
                let tx = tx.clone();
                let key = keys::data(&d.parse::<troupe_msgs::DevAddr>().unwrap().device(6665));
                session
                    .declare_subscriber(key)
                    .callback(move |_| {
                        let _ = tx.send((i, Instant::now()));
                    })
                    .wait()
                    .unwrap()
            })
            .collect();
        Rates {
            names: devices.iter().map(|d| (*d).to_owned()).collect(),
            rx,
            seen: vec![Vec::new(); devices.len()],
            _subs: subs,
        }
    }

    fn take(&mut self, (i, t): (usize, Instant)) {
        self.seen[i].push(t);
    }

    /// Waits until every device has `n` samples.
    fn until_each_has(&mut self, n: usize) {
        let deadline = Instant::now() + DEADLINE;
        while self.seen.iter().any(|s| s.len() < n) {
            let left = deadline.saturating_duration_since(Instant::now());
            let got = self.rx.recv_timeout(left).unwrap_or_else(|_| {
                panic!(
                    "fewer than {n} samples of {:?} within {DEADLINE:?}",
                    self.names
                )
            });
            self.take(got);
        }
    }

    /// Each device's rate between `from` and `to`, Hz.
    fn between(&mut self, from: Instant, to: Instant) -> Vec<f64> {
        while let Ok(got) = self.rx.try_recv() {
            self.take(got);
        }
        let secs = to.duration_since(from).as_secs_f64();
        self.seen
            .iter()
            .map(|s| s.iter().filter(|t| **t >= from && **t <= to).count() as f64 / secs)
            .collect()
    }

    /// Checks that no device's rate from `since` until about two seconds
    /// later than now fell below 70% of its rate over the `before` window;
    /// prints both. The window runs on past the event so that samples only
    /// delayed by it still count, and so that a short window's rounding
    /// (one sample of eight is 12%) does not decide: what fails is data
    /// lost for most of a second.
    fn held(&mut self, before: (Instant, Instant), since: Instant, what: &str) {
        self.until_each_has(self.seen.iter().map(Vec::len).max().unwrap_or(0) + 20);
        let b = self.between(before.0, before.1);
        let d = self.between(since, Instant::now());
        for ((name, b), d) in self.names.iter().zip(&b).zip(&d) {
            eprintln!("docker: {what}: {name} at {b:.1} Hz before, {d:.1} Hz during");
            assert!(
                *d >= 0.7 * b,
                "{name} dropped from {b:.1} Hz to {d:.1} Hz {what}"
            );
        }
    }
}

/// The fleet's sessions, and the devices live through them.
fn all_live(fleet: &Fleet) -> (Session, Tokens) {
    let session = fleet.session();
    let mut tokens = Tokens::new(&session);
    tokens.until(&fleet_devices(), true, Duration::from_secs(60));
    (session, tokens)
}

/// [`all_live`] just after `up`, printing how long the devices took.
fn live_after_up(fleet: &Fleet, what: &str) -> (Session, Tokens) {
    let live = all_live(fleet);
    eprintln!(
        "docker: {what}all {} devices live {:.2} s after `up -d` returned",
        fleet_devices().len(),
        fleet.up.elapsed().as_secs_f64()
    );
    live
}

/// r1's true pose, from the simulator.
fn truth(session: &Session, model: &str) -> Pose2d {
    let client = Client::with_session(session.clone(), 6665);
    SimulationProxy::new(&client, 0)
        .get_pose2d(model)
        .expect("the simulator's true pose")
}

fn dist(a: Pose2d, b: Pose2d) -> f64 {
    (a.x - b.x).hypot(a.y - b.y)
}

/// Only `changed` restarted between two snapshots (`None`: nothing did).
fn only_restarted(
    before: &BTreeMap<String, (String, u32)>,
    after: &BTreeMap<String, (String, u32)>,
    changed: Option<&str>,
) {
    for (service, was) in before {
        let now = &after[service];
        if Some(service.as_str()) == changed {
            assert_ne!(was, now, "{service} was not restarted");
        } else {
            assert_eq!(was, now, "{service} restarted");
        }
    }
}

/// A Player client on this machine gives robot 6666 a goal 3 m ahead
/// through the bridge at `bridge`; the simulator (through `session`) says
/// whether r1 gets there.
fn drives_to_a_goal(session: &Session, bridge: SocketAddr) {
    let planner = troupe_msgs::Device::new(6666, Interface::Planner, 0);
    // A Player client sends its goal once, here as soon as the planner's
    // token is back: after a cut heals, the token can come back before the
    // planner's command subscription reaches the bridge's router, and a
    // goal sent in between was lost (r1 never moved). The bridge now holds
    // it until the subscription comes.
    let mut player = Player::connect(bridge, 6666);
    player.open(planner);
    player.open(troupe_msgs::Device::new(6666, Interface::Position2d, 0));
    let start = truth(session, "r1");
    let goal = Pose2d::new(start.x + 3.0, start.y, 0.0);
    let body: Vec<u8> = [goal.x, goal.y, goal.yaw]
        .iter()
        .flat_map(|v| v.to_be_bytes())
        .collect();
    player.send(u32::from(Interface::Planner.code()), 0, 2, 1, &body);
    let t = Instant::now();
    let deadline = t + Duration::from_secs(90);
    loop {
        // Paced by r1's odometry, which the bridge sends as it comes.
        let m = player.recv();
        assert_eq!(m.kind(), DATA, "{m:?}");
        let now = truth(session, "r1");
        // wavefront is done within its distance_epsilon (0.5 m) of the
        // goal as amcl has r1, and amcl's estimate is off the truth by
        // up to 0.3 m.
        if dist(now, goal) < 0.8 {
            eprintln!(
                "docker: r1 drove {:.1} m to its goal in {:.1} s",
                dist(start, goal),
                t.elapsed().as_secs_f64()
            );
            return;
        }
        assert!(
            Instant::now() < deadline,
            "r1 is at {now:?}, not at the goal {goal:?}"
        );
    }
}

#[test]
fn docker_fleet_comes_up_drives_a_robot_from_a_player_client_and_goes_down_cleanly() {
    let Some(fleet) = Fleet::up("fleet-up") else {
        return;
    };
    let (session, _tokens) = live_after_up(&fleet, "");

    drives_to_a_goal(&session, fleet.published("bridge", 6666));
    drop(session);

    // `down` is stop then remove: stop, so the exit codes can be read.
    let ids: Vec<String> = fleet.ok(&["ps", "-q"]).lines().map(str::to_owned).collect();
    let t = Instant::now();
    fleet.ok(&["stop", "-t", "10"]);
    eprintln!(
        "docker: `compose stop` (down's SIGTERM) took {:.2} s",
        t.elapsed().as_secs_f64()
    );
    for id in &ids {
        let state = ok(Command::new("docker").args([
            "inspect",
            "--format",
            "{{.Name}} {{.State.ExitCode}} {{.State.OOMKilled}}",
            id,
        ]));
        assert!(state.ends_with(" 0 false"), "not a clean exit: {state}");
    }
}

#[test]
fn docker_a_crashed_robot_computer_restarts_and_localizes_while_the_others_keep_their_rates() {
    let Some(fleet) = Fleet::up("fleet-kill") else {
        return;
    };
    let (session, mut tokens) = all_live(&fleet);
    let before = fleet.starts();
    let mut rates = Rates::new(
        &session,
        &["6665:laser:0", "6667:laser:0", "6665:position2d:0"],
    );
    rates.until_each_has(1);
    let from = Instant::now();
    rates.until_each_has(20);
    let base = (from, Instant::now());

    // A crash: the container's first process killed (`docker kill` counts as
    // a stop by hand, which Docker's restart policies never undo).
    let pid = ok(Command::new("docker").args([
        "inspect",
        "--format",
        "{{.State.Pid}}",
        &fleet.container("robot6666"),
    ]));
    let killed = Instant::now();
    ok(Command::new("kill").args(["-KILL", &pid]));
    let gone = tokens.until(&nav_devices(6666), false, DEADLINE);
    let back = tokens.until(&nav_devices(6666), true, DEADLINE);
    eprintln!(
        "docker: kill robot6666 -> its devices gone in {:.2} s, back {:.2} s after the kill",
        gone.as_secs_f64(),
        (gone + back).as_secs_f64()
    );
    rates.held(base, killed, "while robot6666 restarted and after");

    // Localized again: amcl's estimate (the latest, asked for, since its
    // first update may have come before this test listened; else the next)
    // is where r1 truly is.
    let key = keys::data(&troupe_msgs::Device::new(6666, Interface::Localize, 0));
    let next = session.declare_subscriber(&key).wait().unwrap();
    let latest = session
        .get(&key)
        .wait()
        .unwrap()
        .recv()
        .ok()
        .and_then(|r| r.result().ok().map(|s| s.payload().to_bytes().to_vec()));
    let bytes = latest.unwrap_or_else(|| {
        next.recv_deadline(Instant::now() + DEADLINE)
            .unwrap()
            .expect("an estimate from amcl 6666 after its restart")
            .payload()
            .to_bytes()
            .to_vec()
    });
    let h = decode::<localize::Hypoths>(&bytes).unwrap().msg;
    let r1 = truth(&session, "r1");
    let off = dist(h.hypoths[0].mean, r1);
    eprintln!("docker: restarted amcl 6666 is {off:.2} m off r1's true pose");
    assert!(off < 0.5, "{:?} against {r1:?}", h.hypoths[0]);
    only_restarted(&before, &fleet.starts(), Some("robot6666"));
}

#[test]
fn docker_a_cut_off_robot_computer_leaves_within_the_lease_and_rejoins_without_restarts() {
    let Some(fleet) = Fleet::up("fleet-cut") else {
        return;
    };
    let (session, mut tokens) = all_live(&fleet);
    let before = fleet.starts();
    let mut rates = Rates::new(&session, &["6665:laser:0", "6667:laser:0"]);
    rates.until_each_has(1);
    let from = Instant::now();
    rates.until_each_has(20);
    let base = (from, Instant::now());

    let robot = fleet.container("robot6666");
    let cut = Instant::now();
    ok(Command::new("docker").args(["network", "disconnect", &fleet.network(), &robot]));
    // The link is surely cut once the command returns (maybe earlier).
    let done = Instant::now();
    tokens.until(&nav_devices(6666), false, DEADLINE);
    let cut_for = done.elapsed();
    eprintln!(
        "docker: robot6666 cut off -> its devices left {:.2} s after `network disconnect` returned ({:.2} s after it began; lease {:.0} s)",
        cut_for.as_secs_f64(),
        cut.elapsed().as_secs_f64(),
        LEASE.as_secs_f64()
    );
    assert!(
        cut_for <= LEASE + Duration::from_secs(1),
        "the devices stayed {cut_for:?}, over the lease and a second"
    );
    // The others go on meanwhile.
    rates.held(base, cut, "while robot6666 was cut off");

    let healed = Instant::now();
    ok(Command::new("docker").args(["network", "connect", &fleet.network(), &robot]));
    let back = tokens.until(&nav_devices(6666), true, DEADLINE);
    eprintln!(
        "docker: network healed -> robot6666's devices back in {:.2} s ({:.2} s after `network connect` returned)",
        healed.elapsed().as_secs_f64(),
        back.as_secs_f64()
    );
    only_restarted(&before, &fleet.starts(), None);
}

#[test]
fn docker_a_restarted_router_is_rejoined_by_every_container() {
    let Some(fleet) = Fleet::up("fleet-router") else {
        return;
    };
    let (session, tokens) = all_live(&fleet);
    let before = fleet.starts();
    drop(tokens);
    drop(session);
    let t = Instant::now();
    fleet.ok(&["restart", "-t", "10", "router"]);
    let restarted = Instant::now();
    // Its published port may have changed: ask again.
    let (session, _tokens) = all_live(&fleet);
    eprintln!(
        "docker: router restarted ({:.2} s) -> every device back {:.2} s after it was up",
        restarted.duration_since(t).as_secs_f64(),
        restarted.elapsed().as_secs_f64()
    );
    let after = fleet.starts();
    only_restarted(&before, &after, Some("router"));

    // The bridge rejoined too: a Player client gets r0's odometry.
    reads_through_the_bridge(fleet.published("bridge", 6665), 6665, Interface::Position2d);
    drop(session);
}

#[test]
fn docker_a_secured_fleet_serves_its_viewer_and_player_clients_and_refuses_plain_tcp() {
    if engine().is_none() {
        return;
    }
    // The fleet's keys, readable by the image's user, and its compose file.
    let dir = std::env::temp_dir().join(troupe_tests::unique_namespace("secure-fleet"));
    let keys = dir.join("keys");
    fleet_keys(&keys, &["--viewers", "eye"]);
    for e in std::fs::read_dir(&keys).unwrap() {
        std::os::unix::fs::chown(e.unwrap().path(), Some(10000), Some(10000)).unwrap();
    }
    std::os::unix::fs::chown(&keys, Some(10000), Some(10000)).unwrap();
    let file = dir.join("docker-compose.yml");
    ok(Command::new(troupe_tests::troupe_bin())
        .arg("compose")
        .arg(root().join("worlds/fleet.cfg"))
        .args(["--in-image", "/worlds", "--secure"])
        .arg(&keys)
        .arg("-o")
        .arg(&file));
    let Some(fleet) = Fleet::up_with("fleet-secure", file, Some(keys.join("eye.json5"))) else {
        return;
    };
    // The viewer, from this machine, sees every device.
    let (_session, _tokens) = live_after_up(&fleet, "secured, ");
    // Player clients reach the robots through the bridge, which joins as an operator.
    reads_through_the_bridge(fleet.published("bridge", 6666), 6666, Interface::Position2d);
    // Plain TCP, or TLS without a certificate, does not get in.
    let port = fleet.published("router", 7447).port();
    for (endpoint, cfg) in [
        (format!("tcp/127.0.0.1:{port}"), None),
        (format!("tls/localhost:{port}"), None::<PathBuf>),
    ] {
        let r = ZenohArgs {
            connect: vec![endpoint.clone()],
            zenoh_config: cfg,
            no_multicast: true,
            ..Default::default()
        }
        .open(Mode::Client);
        assert!(r.is_err(), "{endpoint} joined the secured fleet");
    }
    drop(fleet);
    let _ = std::fs::remove_dir_all(&dir);
}

/// A Player client at `at` opens `robot`'s device 0 of `interface`: the
/// first message it gets is that device's data.
fn reads_through_the_bridge(at: SocketAddr, robot: u32, interface: Interface) {
    let mut player = Player::connect(at, robot);
    player.open(troupe_msgs::Device::new(robot, interface, 0));
    let m = player.recv();
    assert_eq!(
        (m.kind(), m.h[2]),
        (DATA, u32::from(interface.code())),
        "{m:?}"
    );
}

/// `troupe fleet-keys` for worlds/fleet.cfg's hosts and the bridge (an
/// operator) into `dir`, with `more` flags.
fn fleet_keys(dir: &Path, more: &[&str]) {
    ok(Command::new(troupe_tests::troupe_bin())
        .arg("fleet-keys")
        .arg(dir)
        .args([
            "--hosts",
            "sim:6665:6666:6667,robot6665:6665,robot6666:6666,robot6667:6667",
            "--operators",
            "bridge",
        ])
        .args(more));
}

/// `troupe compose --k8s` of worlds/fleet.cfg, plain and secured, checked
/// against Kubernetes' own schemas (the `kubernetes-validate` package in
/// the tests' Python environment, strict: no field Kubernetes does not
/// know); a manifest with a field it does not know is refused, so the
/// check can fail. No cluster runs here.
#[test]
fn k8s_manifests_validate_against_kubernetes_own_schemas() {
    let Some(python3) = crate::python::python3() else {
        return;
    };
    let validate = crate::python::environment(&python3).with_file_name("kubernetes-validate");
    let dir = std::env::temp_dir().join(troupe_tests::unique_namespace("k8s"));
    let keys = dir.join("keys");
    fleet_keys(&keys, &[]);
    let compose = |out: &Path, secure: bool| {
        let mut c = Command::new(troupe_tests::troupe_bin());
        c.arg("compose")
            .arg(root().join("worlds/fleet.cfg"))
            .args(["--in-image", "/worlds", "--k8s", "-o"])
            .arg(out);
        if secure {
            c.arg("--secure").arg(&keys);
        }
        ok(&mut c);
        std::fs::read_to_string(out).unwrap()
    };
    let check = |file: &Path| run(Command::new(&validate).arg("--strict").arg(file));
    for secure in [false, true] {
        let file = dir.join(format!("k8s-{secure}.yml"));
        let text = compose(&file, secure);
        let out = check(&file);
        let said = String::from_utf8_lossy(&out.stdout).into_owned()
            + &String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{said}\n{text}");
        // Every resource passed: a Deployment for each router, host and the
        // bridge, a Service for each router and the bridge (secured: one
        // router, whose identities the hosts' configs name).
        let resources = if secure { 6 + 2 } else { 10 + 6 };
        assert_eq!(
            said.matches("passed for resource").count(),
            resources,
            "{said}"
        );
        assert_eq!(text.contains("secretName: troupe-keys"), secure);
    }
    let text = std::fs::read_to_string(dir.join("k8s-false.yml")).unwrap();
    let bad = dir.join("bad.yml");
    std::fs::write(
        &bad,
        text.replacen("  replicas: 1\n", "  replicas: 1\n  replica: 2\n", 1),
    )
    .unwrap();
    assert!(!check(&bad).status.success(), "an unknown field passed");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A one-node swarm this test made: it leaves it when dropped (with the
/// stack it deployed); it touches no swarm it did not make.
struct Swarm {
    stack: String,
    dir: PathBuf,
    _turn: MutexGuard<'static, ()>,
}

impl Swarm {
    /// A fresh swarm of this engine; `None` where Docker is absent or the
    /// engine already belongs to a swarm.
    fn init() -> Option<Swarm> {
        engine()?;
        let turn = TURN.lock().unwrap_or_else(|p| p.into_inner());
        let state =
            ok(Command::new("docker").args(["info", "--format", "{{.Swarm.LocalNodeState}}"]));
        if state != "inactive" {
            troupe_tests::cannot_run(&format!(
                "this Docker engine is in a swarm already ({state}): the test makes its own and touches no other"
            ));
            return None;
        }
        image();
        ok(Command::new("docker").args(["swarm", "init", "--advertise-addr", "127.0.0.1"]));
        let stack = troupe_tests::unique_namespace("swarm").replace('_', "-");
        let dir = std::env::temp_dir().join(&stack);
        std::fs::create_dir_all(&dir).unwrap();
        Some(Swarm {
            stack,
            dir,
            _turn: turn,
        })
    }

    /// Labels this node with every host of worlds/fleet.cfg.
    fn label_all(&self) {
        let node = ok(Command::new("docker").args(["info", "--format", "{{.Swarm.NodeID}}"]));
        let mut c = Command::new("docker");
        c.args(["node", "update"]);
        for h in ["sim", "robot6665", "robot6666", "robot6667"] {
            c.args(["--label-add", &format!("troupe.host.{h}=true")]);
        }
        ok(c.arg(node));
    }

    /// The tasks that ever ran `service` of the stack.
    fn tasks(&self, service: &str) -> usize {
        ok(Command::new("docker").args([
            "service",
            "ps",
            "-q",
            &format!("{}_{service}", self.stack),
        ]))
        .lines()
        .count()
    }

    /// The running container of `service`.
    fn container(&self, service: &str) -> String {
        let id = ok(Command::new("docker").args([
            "ps",
            "-q",
            "--filter",
            &format!(
                "label=com.docker.swarm.service.name={}_{service}",
                self.stack
            ),
        ]));
        assert!(!id.is_empty() && !id.contains('\n'), "{service}: {id:?}");
        id
    }

    /// The process that runs `service` (as the host numbers it) and its
    /// children: a launcher and the nodes it started. A health check's
    /// probe is the shim's child, not among them.
    fn processes(&self, service: &str) -> BTreeSet<u32> {
        let id = self.container(service);
        let main: u32 =
            ok(Command::new("docker").args(["inspect", "--format", "{{.State.Pid}}", &id]))
                .parse()
                .unwrap();
        let top = ok(Command::new("docker").args(["top", &id, "-eo", "pid,ppid"]));
        let out: BTreeSet<u32> = top
            .lines()
            .skip(1)
            .filter_map(|l| {
                let mut f = l.split_whitespace().map(|w| w.parse::<u32>().ok());
                let (pid, ppid) = (f.next()??, f.next()??);
                (pid == main || ppid == main).then_some(pid)
            })
            .collect();
        assert!(out.contains(&main), "{service}: {top}");
        out
    }

    /// The address of `service`'s container on the stack's network.
    fn address(&self, service: &str) -> String {
        ok(Command::new("docker").args([
            "inspect",
            "--format",
            &format!(
                "{{{{(index .NetworkSettings.Networks \"{}_fleet\").IPAddress}}}}",
                self.stack
            ),
            &self.container(service),
        ]))
    }
}

/// A host's router cut off from every other router, its own host's
/// container still beside it: the packet filter of the router's network
/// namespace drops all but loopback and that container, both ways.
struct Cut {
    pid: String,
    rules: [Vec<String>; 2],
}

impl Cut {
    /// Cuts `router` off from all but `host` (services of `swarm`).
    fn new(swarm: &Swarm, router: &str, host: &str) -> Cut {
        let pid = ok(Command::new("docker").args([
            "inspect",
            "--format",
            "{{.State.Pid}}",
            &swarm.container(router),
        ]));
        let keep = swarm.address(host);
        let rule = |chain: &str, dir: &str, peer: &str| {
            troupe_tests::strings(&[chain, "!", dir, "lo", "!", peer, &keep, "-j", "DROP"])
        };
        let cut = Cut {
            pid,
            rules: [rule("INPUT", "-i", "-s"), rule("OUTPUT", "-o", "-d")],
        };
        cut.iptables("-I");
        cut
    }

    fn iptables(&self, op: &str) {
        for r in &self.rules {
            ok(Command::new("nsenter")
                .args(["-t", &self.pid, "-n", "iptables", op])
                .args(r));
        }
    }

    fn heal(self) {
        self.iptables("-D");
    }
}

impl Drop for Swarm {
    fn drop(&mut self) {
        if std::thread::panicking() {
            for s in ["router", "sim", "robot6666", "bridge"] {
                let logs = run(Command::new("docker").args([
                    "service",
                    "logs",
                    "--tail",
                    "30",
                    &format!("{}_{s}", self.stack),
                ]));
                eprintln!(
                    "--- {s} ---\n{}{}",
                    String::from_utf8_lossy(&logs.stdout),
                    String::from_utf8_lossy(&logs.stderr)
                );
            }
        }
        let _ = run(Command::new("docker").args(["stack", "rm", &self.stack]));
        let _ = run(Command::new("docker").args(["swarm", "leave", "--force"]));
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// A port free on this machine now (the swarm publishes on the node's
/// ports, and picks none itself).
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// `troupe compose --swarm` of worlds/fleet.cfg on a one-node swarm: every
/// host beside its own router, placed by its label; every device comes up,
/// a Player client reads a laser through the bridge's published port, a
/// killed task is rescheduled and its devices come back (no other task
/// restarts), a host's router cut off from the others and healed brings
/// its devices back with nothing restarted, and `docker stack rm` takes it
/// all down.
#[test]
fn docker_swarm_runs_the_generated_stack_reschedules_a_killed_host_and_heals_a_cut_router() {
    let Some(swarm) = Swarm::init() else { return };
    swarm.label_all();
    let file = swarm.dir.join("troupe-stack.yml");
    ok(Command::new(troupe_tests::troupe_bin())
        .arg("compose")
        .arg(root().join("worlds/fleet.cfg"))
        .args(["--in-image", "/worlds", "--swarm", "-o"])
        .arg(&file));
    let router_port = free_port();
    let mut deploy = Command::new("docker");
    deploy
        .args(["stack", "deploy", "-c"])
        .arg(&file)
        .arg(&swarm.stack)
        .env("TROUPE_IMAGE", IMAGE)
        .env("TROUPE_ROUTER_PORT", router_port.to_string());
    let mut player_ports = BTreeMap::new();
    for r in ROBOTS {
        let p = free_port();
        deploy.env(format!("TROUPE_PORT_{r}"), p.to_string());
        player_ports.insert(r, p);
    }
    let t = Instant::now();
    ok(&mut deploy);
    let session = ZenohArgs {
        connect: vec![format!("tcp/127.0.0.1:{router_port}")],
        no_multicast: true,
        reconnect: true,
        ..Default::default()
    }
    .open(Mode::Client)
    .expect("a session with the stack's router");
    let mut tokens = Tokens::new(&session);
    tokens.until(&fleet_devices(), true, Duration::from_secs(180));
    eprintln!(
        "docker swarm: every device of the stack ready {:.1} s after `stack deploy`",
        t.elapsed().as_secs_f64()
    );

    // A Player client on this machine reads r0's laser through the bridge.
    reads_through_the_bridge(
        SocketAddr::from(([127, 0, 0, 1], player_ports[&6665])),
        6665,
        Interface::Laser,
    );

    // robot6666's computer dies: the swarm starts it again, its devices
    // return, and no other task was replaced.
    let services = [
        "router",
        "router-sim",
        "sim",
        "router-robot6665",
        "robot6665",
        "router-robot6666",
        "robot6666",
        "router-robot6667",
        "robot6667",
        "bridge",
    ];
    let before: Vec<usize> = services.iter().map(|s| swarm.tasks(s)).collect();
    assert!(before.iter().all(|&n| n == 1), "{before:?}");
    ok(Command::new("docker").args(["kill", &swarm.container("robot6666")]));
    let gone = tokens.until(&nav_devices(6666), false, LEASE * 4);
    let back = tokens.until(&nav_devices(6666), true, Duration::from_secs(120));
    eprintln!(
        "docker swarm: a killed host's devices gone in {:.1} s, back {:.1} s later",
        gone.as_secs_f64(),
        back.as_secs_f64()
    );
    let after: Vec<usize> = services.iter().map(|s| swarm.tasks(s)).collect();
    for (i, s) in services.iter().enumerate() {
        let want = if *s == "robot6666" { 2 } else { 1 };
        assert_eq!(after[i], want, "{s}: {} tasks", after[i]);
    }

    // Two hosts apart: robot6666's router cut off from every other router
    // (its host still reaches it), then healed. r1's drivers are on one
    // side, the simulator that drives it on the other: its devices leave
    // and return, r1 drives to a goal, and no process on either side, nor
    // any task, was started again.
    let sides = [
        "router",
        "router-sim",
        "sim",
        "router-robot6666",
        "robot6666",
    ];
    let processes: Vec<BTreeSet<u32>> = sides.iter().map(|s| swarm.processes(s)).collect();
    let cut = Cut::new(&swarm, "router-robot6666", "robot6666");
    let gone = tokens.until(&nav_devices(6666), false, LEASE * 4);
    cut.heal();
    let back = tokens.until(&nav_devices(6666), true, Duration::from_secs(60));
    eprintln!(
        "docker swarm: robot6666's router cut off -> its devices gone in {:.1} s; link restored -> back in {:.1} s",
        gone.as_secs_f64(),
        back.as_secs_f64()
    );
    drives_to_a_goal(
        &session,
        SocketAddr::from(([127, 0, 0, 1], player_ports[&6666])),
    );
    for (s, was) in sides.iter().zip(&processes) {
        assert_eq!(&swarm.processes(s), was, "{s}: a process was started again");
    }
    let last: Vec<usize> = services.iter().map(|s| swarm.tasks(s)).collect();
    assert_eq!(last, after, "tasks of {services:?}");
    drop(tokens);
    drop(session);

    // Down: every service and the overlay network gone.
    ok(Command::new("docker").args(["stack", "rm", &swarm.stack]));
    let left = ok(Command::new("docker").args([
        "service",
        "ls",
        "-q",
        "--filter",
        &format!("label=com.docker.stack.namespace={}", swarm.stack),
    ]));
    assert!(left.is_empty(), "services left: {left}");
}
