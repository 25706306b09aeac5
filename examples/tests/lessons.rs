//! Every tutorial program against its own launched stack: `troupe launch` on
//! the lesson's cfg (faster than real time), the example binary as a second
//! process, and the lesson's outcome checked from outside, through the
//! simulator's true poses and the devices themselves.
//!
//! Each test prints its wall time: `cargo test -p troupe-examples -- --nocapture`.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus};
use std::time::{Duration, Instant};

use troupe_client::{Client, GripperProxy, LocalizeProxy, Position2dProxy, SimulationProxy};
use troupe_msgs::Pose2d;
use troupe_tests::Proc;

/// The lesson's stack: `troupe launch worlds/CFG`, and a client of it.
struct Stack {
    launcher: Proc,
    endpoint: String,
    ns: String,
    client: Client,
    started: Instant,
}

impl Stack {
    /// Launches `worlds/<cfg>` (the simulator at `speedup` times real time,
    /// when the cfg has one) and waits until `devices` are live.
    fn launch(cfg: &str, speedup: Option<f64>, devices: &[&str]) -> Stack {
        let started = Instant::now();
        let ns = troupe_tests::unique_namespace(cfg.trim_end_matches(".cfg"));
        let path = worlds().join(cfg);
        let speedup = speedup.map(|x| x.to_string());
        let mut extra = vec!["--no-bridge"];
        if let Some(x) = &speedup {
            extra.extend(["--speedup", x]);
        }
        let mut launcher = troupe_tests::launch(&ns, &path, &extra);
        let endpoint = launcher.endpoint("troupe launch: router listening on");
        let session = troupe_tests::client_at(&endpoint, &ns);
        troupe_tests::wait_live(&session, devices);
        Stack {
            launcher,
            endpoint,
            ns,
            client: Client::with_session(session, 6665),
            started,
        }
    }

    /// Starts `cargo run --example NAME -- ARGS` on this stack's network.
    fn example(&self, name: &str, args: &[&str]) -> Example {
        let mut cmd = Command::new(troupe_tests::example_bin(name));
        cmd.args([
            "--connect",
            &self.endpoint,
            "--namespace",
            &self.ns,
            "--no-multicast",
        ])
        .args(args);
        let mut proc = Proc::start(name, &mut cmd);
        let mut out = proc.child.stdout.take().expect("stdout");
        let stdout = std::thread::spawn(move || {
            let mut s = String::new();
            let _ = out.read_to_string(&mut s);
            s
        });
        Example {
            proc,
            stdout: Some(stdout),
            status: None,
        }
    }

    /// Calls `watch` on every new sample until `ex` exits (or `limit` passes,
    /// which fails the test); then its stdout.
    fn follow(&self, ex: &mut Example, limit: Duration, mut watch: impl FnMut()) -> String {
        let deadline = Instant::now() + limit;
        while ex.running() {
            assert!(
                Instant::now() < deadline,
                "{} still running after {limit:?}\nstack: {}",
                ex.proc.name,
                self.describe()
            );
            if self.client.read_timeout(Duration::from_millis(200)).is_ok() {
                watch();
            }
        }
        ex.finish()
    }

    fn describe(&self) -> String {
        format!(
            "(namespace {}, launched {:?} ago)",
            self.ns,
            self.started.elapsed()
        )
    }

    /// Stops the stack, checks it stopped cleanly, prints the lesson's wall time.
    fn stop(mut self, lesson: &str) {
        let status = self.launcher.terminate();
        assert!(status.success(), "{}", self.launcher.stderr());
        eprintln!(
            "lesson {lesson}: {:.1} s wall",
            self.started.elapsed().as_secs_f64()
        );
    }
}

/// A running example program.
struct Example {
    proc: Proc,
    stdout: Option<std::thread::JoinHandle<String>>,
    status: Option<ExitStatus>,
}

impl Example {
    fn running(&mut self) -> bool {
        if self.status.is_none() {
            self.status = self.proc.child.try_wait().expect("try_wait");
        }
        self.status.is_none()
    }

    /// Waits for the exit (the child has exited or is killed), asserts it
    /// succeeded, and returns its stdout.
    fn finish(&mut self) -> String {
        let status = match self.status {
            Some(s) => s,
            None => self.proc.wait(),
        };
        let out = self
            .stdout
            .take()
            .map(|h| h.join().unwrap_or_default())
            .unwrap_or_default();
        if !status.success() {
            let err = self.proc.stderr();
            panic!("{} failed ({status}):\n{out}\n{err}", self.proc.name);
        }
        out
    }
}

fn worlds() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds")
}

/// Numbers after `key` in `text`'s lines: `number_after("zapped 8 of", …)`.
fn number_after(text: &str, key: &str) -> Option<f64> {
    text.lines().rev().find_map(|l| {
        let rest = &l[l.find(key)? + key.len()..];
        rest.split_whitespace().next()?.parse().ok()
    })
}

fn dist(a: Pose2d, b: Pose2d) -> f64 {
    (a.x - b.x).hypot(a.y - b.y)
}

#[test]
fn wander_roams_simple_world_without_stalling() {
    let stack = Stack::launch(
        "simple.cfg",
        Some(5.0),
        &["6665:position2d:0", "6665:ranger:0", "6665:simulation:0"],
    );
    let sim = SimulationProxy::new(&stack.client, 0);
    let base = Position2dProxy::new(&stack.client, 0).unwrap();
    let start = sim.get_pose2d("r0").unwrap();
    let mut ex = stack.example("wander", &["--for", "40"]);
    let (mut path, mut last, mut stalls) = (0.0, None::<(f64, f64)>, 0);
    let out = stack.follow(&mut ex, Duration::from_secs(60), || {
        if let Some(d) = base.data() {
            if let Some((x, y)) = last {
                path += (d.pose.x - x).hypot(d.pose.y - y);
            }
            last = Some((d.pose.x, d.pose.y));
            stalls += usize::from(d.stall);
        }
    });
    let end = sim.get_pose2d("r0").unwrap();
    eprintln!(
        "wander: {path:.1} m driven, {:.1} m from the start",
        dist(start, end)
    );
    assert!(out.contains("wandering"), "{out}");
    assert_eq!(stalls, 0, "r0 stalled {stalls} times\n{out}");
    assert!(path > 5.0, "only {path:.1} m in 40 s\n{out}");
    assert!(
        dist(start, end) > 1.0,
        "r0 ended {:.2} m from its start",
        dist(start, end)
    );
    stack.stop("wander");
}

#[test]
fn goto_reaches_the_target_pose() {
    let stack = Stack::launch(
        "simple.cfg",
        Some(5.0),
        &["6665:position2d:0", "6665:simulation:0"],
    );
    let sim = SimulationProxy::new(&stack.client, 0);
    let start = sim.get_pose2d("r0").unwrap();
    let mut ex = stack.example(
        "goto",
        &["--x", "2", "--y", "1", "--yaw", "90", "--for", "60"],
    );
    let out = stack.follow(&mut ex, Duration::from_secs(40), || {});
    // (2, 1) and 90 degrees in the odometry frame, which starts at r0's start pose.
    let (s, c) = start.yaw.sin_cos();
    let want = Pose2d {
        x: start.x + 2.0 * c - s,
        y: start.y + 2.0 * s + c,
        yaw: start.yaw + std::f64::consts::FRAC_PI_2,
    };
    let end = sim.get_pose2d("r0").unwrap();
    assert!(out.contains("arrived after"), "{out}");
    assert!(
        dist(end, want) < 0.15,
        "ended at {end:?}, wanted {want:?}\n{out}"
    );
    assert!(
        (end.yaw - want.yaw).sin().abs() < 0.1,
        "heading {end:?}, wanted {want:?}"
    );
    stack.stop("goto");
}

#[test]
fn laser_prints_the_scan_geometry_and_ranges() {
    let stack = Stack::launch("simple.cfg", None, &["6665:laser:0"]);
    let mut ex = stack.example("laser", &[]);
    let out = stack.follow(&mut ex, Duration::from_secs(20), || {});
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines.len(), 10, "{out}");
    assert!(
        lines[0]
            .starts_with("180 beams from -1.571 to 1.571 rad, every 0.0175 rad, max range 8.0 m"),
        "{out}"
    );
    // r0 stands in the south-west corner facing north-east: beam 0 looks
    // south-east along the south wall, 1.4 m above it.
    let r0: f64 = lines[1]
        .split_whitespace()
        .nth(1)
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no range in {:?}", lines[1]));
    assert!(r0 > 0.0 && r0 <= 8.0, "{out}");
    stack.stop("laser");
}

#[test]
fn map_draws_the_office_floor_plan() {
    let stack = Stack::launch("map.cfg", None, &["6665:map:0", "6665:map:1", "6665:map:2"]);
    let mut ex = stack.example("map", &["--columns", "64"]);
    let out = stack.follow(&mut ex, Duration::from_secs(20), || {});
    assert!(
        out.starts_with(
            "map: 320 x 320 cells of 0.050 m (16.0 m x 16.0 m), cell (0,0) at (-8.00, -8.00)"
        ),
        "{out}"
    );
    let drawing: Vec<&str> = out.lines().skip(1).filter(|l| !l.contains(' ')).collect();
    assert_eq!(drawing.len(), 32, "{out}");
    assert!(drawing.iter().all(|l| l.len() == 64), "{out}");
    // The outer walls frame the drawing; the inside is mostly free.
    assert!(drawing[0].chars().all(|c| c == 'X'), "{out}");
    assert!(
        drawing
            .iter()
            .all(|l| l.starts_with('X') && l.ends_with('X')),
        "{out}"
    );
    let (free, occupied) = counts_of(&out);
    assert!(free > 80_000.0 && occupied > 4_000.0, "{out}");
    assert_eq!(
        free + occupied,
        320.0 * 320.0,
        "every cell is free or occupied: {out}"
    );
    // map:1, mapcspace's: the same grid, walls grown by 0.25 m (5 cells a
    // side: a thin wall gets 10 cells thicker), so far more occupied.
    let mut ex = stack.example("map", &["--index", "1"]);
    let grown = stack.follow(&mut ex, Duration::from_secs(20), || {});
    assert!(
        grown.starts_with("map: 320 x 320 cells of 0.050 m"),
        "{grown}"
    );
    let (free1, occupied1) = counts_of(&grown);
    assert_eq!(free1 + occupied1, free + occupied, "{grown}");
    assert!(
        occupied1 > 2.0 * occupied,
        "{occupied} then {occupied1}: {grown}"
    );
    // map:2, mapscale's: 10 cm cells over the same 16 m, the same corner.
    let mut ex = stack.example("map", &["--index", "2"]);
    let coarse = stack.follow(&mut ex, Duration::from_secs(20), || {});
    assert!(
        coarse.starts_with(
            "map: 160 x 160 cells of 0.100 m (16.0 m x 16.0 m), cell (0,0) at (-8.00, -8.00)"
        ),
        "{coarse}"
    );
    stack.stop("map");
}

/// The example's closing line: "N free cells, M occupied".
fn counts_of(out: &str) -> (f64, f64) {
    let counts: Vec<f64> = out
        .lines()
        .last()
        .unwrap_or("")
        .split_whitespace()
        .filter_map(|w| w.parse().ok())
        .collect();
    match counts.as_slice() {
        &[free, occupied] => (free, occupied),
        _ => panic!("no cell counts: {out}"),
    }
}

#[test]
fn planner_takes_r0_across_the_office() {
    let stack = Stack::launch(
        "nav.cfg",
        Some(8.0),
        &["6665:planner:0", "6665:localize:0", "6665:simulation:0"],
    );
    let sim = SimulationProxy::new(&stack.client, 0);
    let base = Position2dProxy::new(&stack.client, 0).unwrap();
    let mut ex = stack.example("planner", &["--x", "5", "--y", "0", "--for", "200"]);
    let mut stalls = 0;
    let out = stack.follow(&mut ex, Duration::from_secs(90), || {
        stalls += usize::from(base.stall());
    });
    let end = sim.get_pose2d("r0").unwrap();
    let goal = Pose2d {
        x: 5.0,
        y: 0.0,
        yaw: 0.0,
    };
    eprintln!("planner: {}", out.lines().last().unwrap_or(""));
    assert!(out.contains("a path of"), "{out}");
    assert!(out.contains("arrived at"), "{out}");
    assert!(dist(end, goal) < 0.6, "r0 stopped at {end:?}\n{out}");
    assert_eq!(stalls, 0, "r0 collided on the way\n{out}");
    stack.stop("planner");
}

#[test]
fn localize_converges_on_the_true_pose() {
    let stack = Stack::launch(
        "nav.cfg",
        Some(8.0),
        &["6665:localize:0", "6665:position2d:0", "6665:simulation:0"],
    );
    let sim = SimulationProxy::new(&stack.client, 0);
    let amcl = LocalizeProxy::new(&stack.client, 0).unwrap();
    // Half a metre and 15 degrees off, with a metre of doubt.
    let mut ex = stack.example(
        "localize",
        &[
            "--x",
            "-5.5",
            "--y",
            "-6.5",
            "--yaw",
            "30",
            "--spread",
            "1",
            "--seconds",
            "30",
        ],
    );
    let out = stack.follow(&mut ex, Duration::from_secs(60), || {});
    let truth = sim.get_pose2d("r0").unwrap();
    let best = amcl.hypoths()[0];
    let off = dist(best.mean, truth);
    let spread = (best.cov[0] + best.cov[1]).sqrt();
    eprintln!("localize: {off:.2} m off the true pose, std dev {spread:.2} m");
    assert!(out.contains("told amcl"), "{out}");
    assert!(
        off < 0.3,
        "amcl's best guess {:?} is {off:.2} m from {truth:?}\n{out}",
        best.mean
    );
    assert!(spread < 0.5, "still unsure: std dev {spread:.2} m\n{out}");
    assert!(
        (best.mean.yaw - truth.yaw).sin().abs() < 0.2,
        "{best:?} vs {truth:?}"
    );
    stack.stop("localize");
}

/// Both robots of two.world moved more than a metre and never stalled.
fn two_robots(cfg: &str, example: &str, bases: [(u32, u32); 2]) {
    let stack = Stack::launch(
        cfg,
        Some(5.0),
        &[
            &format!("{}:position2d:{}", bases[0].0, bases[0].1),
            &format!("{}:position2d:{}", bases[1].0, bases[1].1),
            "6665:simulation:0",
        ],
    );
    let sim = SimulationProxy::new(&stack.client, 0);
    let proxies: Vec<(Client, Position2dProxy)> = bases
        .iter()
        .map(|&(port, i)| {
            let c = Client::with_session(stack.client.session().clone(), port);
            let p = Position2dProxy::new(&c, i).expect("position2d proxy");
            (c, p)
        })
        .collect();
    let pose = |name: &str| sim.get_pose2d(name).expect("the simulator's pose");
    let starts = [pose("r0"), pose("r1")];
    let mut ex = stack.example(example, &["--for", "20"]);
    let mut stalls = 0;
    let out = stack.follow(&mut ex, Duration::from_secs(40), || {
        stalls += proxies.iter().filter(|(_, p)| p.stall()).count();
    });
    for (name, start) in ["r0", "r1"].iter().zip(starts) {
        let end = pose(name);
        assert!(
            dist(start, end) > 1.0,
            "{name} only moved to {end:?} from {start:?}\n{out}"
        );
    }
    assert_eq!(stalls, 0, "{out}");
    stack.stop(example);
}

#[test]
fn two_robots_on_two_ports_both_wander() {
    two_robots("two_ports.cfg", "two_robots_ports", [(6665, 0), (6666, 0)]);
}

#[test]
fn two_robots_on_one_port_both_wander() {
    two_robots("two_index.cfg", "two_robots_index", [(6665, 0), (6665, 1)]);
}

#[test]
fn bigbob_zaps_the_trash() {
    let stack = Stack::launch(
        "bigbob.cfg",
        Some(10.0),
        &["6665:blobfinder:0", "6665:ranger:1", "6665:simulation:0"],
    );
    let sim = SimulationProxy::new(&stack.client, 0);
    let items = [
        "orange1", "orange2", "orange3", "orange4", "carton1", "carton2", "carton3", "carton4",
    ];
    let mut ex = stack.example("bigbob", &["--for", "300"]);
    let out = stack.follow(&mut ex, Duration::from_secs(80), || {});
    // Zapped trash is far outside the 10 m yard.
    let gone = items
        .iter()
        .filter(|i| sim.get_pose2d(i).unwrap().x < -50.0)
        .count();
    eprintln!("bigbob: {}", out.lines().last().unwrap_or(""));
    assert_eq!(
        number_after(&out, "zapped").map(|n| n as usize),
        Some(gone),
        "{out}"
    );
    assert!(gone >= 6, "only {gone} of 8 zapped\n{out}");
    stack.stop("bigbob");
}

#[test]
fn gripper_drags_the_box_back() {
    let stack = Stack::launch(
        "gripper.cfg",
        Some(5.0),
        &["6665:gripper:0", "6665:position2d:0", "6665:simulation:0"],
    );
    let sim = SimulationProxy::new(&stack.client, 0);
    let gripper = GripperProxy::new(&stack.client, 0).unwrap();
    let before = sim.get_pose2d("box").unwrap();
    let mut ex = stack.example("gripper", &["--back", "1.5", "--for", "60"]);
    let out = stack.follow(&mut ex, Duration::from_secs(40), || {});
    assert!(out.contains("holding it: closed after moving"), "{out}");
    stack.client.read().unwrap();
    // As Stage's: closed on the box, which breaks both beams; nothing
    // counted as stored; the box held is at 0 0 0 on the gripper.
    assert_eq!(
        (gripper.state(), gripper.beams(), gripper.stored()),
        (troupe_msgs::gripper::State::Closed, 0x0c, 0),
        "{out}"
    );
    let held = sim.get_pose2d("box").unwrap();
    assert_eq!((held.x, held.y, held.yaw), (0.0, 0.0, 0.0), "{held:?}");
    // Let go: the box is where it was dragged to.
    gripper.open().unwrap();
    while gripper.state() == troupe_msgs::gripper::State::Closed {
        stack.client.read().unwrap();
    }
    let after = sim.get_pose2d("box").unwrap();
    assert!(
        before.x - after.x > 1.3 && (after.y - before.y).abs() < 0.1,
        "the box went from {before:?} to {after:?}\n{out}"
    );
    stack.stop("gripper");
}
