//! The navigation stack as processes: Stage + rangertolaser + mapfile + amcl +
//! vfh + wavefront from the cpp-planner-localize scenario's own
//! nav_headless.cfg (read in place from ../shared/compat). A client sets a
//! goal across the cave with the planner and watches the robot get there,
//! by the simulator's true pose, without a collision, in simulated time.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use troupe_client::{Client, LocalizeProxy, PlannerProxy, Position2dProxy, SimulationProxy};
use troupe_msgs::{keys, position2d, sim, Device, Interface, Pose2d};
use troupe_node::zenoh::Wait;

/// The goal of the reference run, and what Player 3.1 achieved there.
const GOAL: (f64, f64) = (-4.5, -5.5);
const PLAYER_ARRIVAL_SIM_S: f64 = 32.0;
/// wavefront's `distance_epsilon` in nav_headless.cfg: it is done once
/// amcl's estimate is this close to the goal.
const DISTANCE_EPSILON: f64 = 0.5;
/// How far r0 may still roll after wavefront says done and before its zero
/// speed reaches Stage through vfh (one control step at vfh's slow speed
/// near a goal).
const COAST: f64 = 0.05;

fn compat_cfg() -> Option<PathBuf> {
    troupe_tests::compat("player-tcp/cpp-planner-localize/nav_headless.cfg")
}

#[test]
fn planner_drives_r0_across_the_cave_to_the_goal() {
    if let Some(cfg) = compat_cfg() {
        drive_to_goal(&cfg);
    }
}

/// Player's amcl fell behind at 50 000 particles on this route (an update
/// every ~2 simulated s, its output 0.8 m behind the truth on average).
/// Troupe's, as many particles held by pf_min_samples, keeps its accuracy.
#[test]
fn amcl_with_50000_particles_keeps_up_on_the_route() {
    let Some(cfg) = compat_cfg() else { return };
    let text = std::fs::read_to_string(&cfg).unwrap();
    let stage = cfg.parent().unwrap().join("../../stage");
    let text = text
        .replace("\"../../stage/", &format!("\"{}/", stage.display()))
        .replace(
            "init_pose_var [ 0.2 0.2 10 ]",
            "init_pose_var [ 0.2 0.2 10 ]\n  pf_min_samples 50000\n  pf_max_samples 50000",
        );
    assert!(text.contains("pf_min_samples 50000"), "{text}");
    let dir = std::env::temp_dir().join(troupe_tests::unique_namespace("nav50k"));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("nav_50000.cfg");
    std::fs::write(&path, text).unwrap();
    drive_to_goal(&path);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Simulated time, from the simulator's clock: the subscriber to keep, and
/// a reader of the latest time (0 before the first tick).
fn sim_clock(
    session: &troupe_node::zenoh::Session,
) -> (troupe_node::zenoh::pubsub::Subscriber<()>, impl Fn() -> f64) {
    let sim_time = Arc::new(AtomicU64::new(0));
    let t = sim_time.clone();
    let sub = session
        .declare_subscriber(keys::SIM_CLOCK)
        .callback(move |s| {
            if let Ok(c) = troupe_msgs::decode::<sim::Clock>(&s.payload().to_bytes()) {
                t.store(c.msg.time.to_bits(), Ordering::Relaxed);
            }
        })
        .wait()
        .unwrap();
    (sub, move || {
        f64::from_bits(sim_time.load(Ordering::Relaxed))
    })
}

/// Launches `cfg`, sends r0 to the goal with the planner and checks the
/// arrival, the time it took and amcl's error on the way.
fn drive_to_goal(cfg: &Path) {
    let ns = troupe_tests::unique_namespace("nav");
    let mut launcher = troupe_tests::launch(&ns, cfg, &["--no-bridge"]);
    let endpoint = launcher.endpoint("troupe launch: router listening on");
    let session = troupe_tests::client_at(&endpoint, &ns);
    let (_clock, now) = sim_clock(&session);
    // r0's odometry is its true pose (`localization "gps"`, origin 0), and
    // amcl stamps each estimate with the odometry it extends: the two
    // streams, paired by stamp, say how far amcl is from the truth at the
    // same simulated instant.
    let record = |index: u32| {
        let seen: Arc<Mutex<Vec<(f64, Pose2d)>>> = Arc::default();
        let out = seen.clone();
        let dev = Device::new(6665, Interface::Position2d, index);
        let sub = session
            .declare_subscriber(keys::data(&dev))
            .callback(move |s| {
                if let Ok(d) = troupe_msgs::decode::<position2d::Data>(&s.payload().to_bytes()) {
                    out.lock().unwrap().push((d.stamp, d.msg.pose));
                }
            })
            .wait()
            .unwrap();
        (sub, seen)
    };
    let (_truth_sub, truths) = record(0);
    let (_amcl_sub, estimates) = record(2);
    let client = Client::with_session(session.clone(), 6665);
    let planner = PlannerProxy::new(&client, 0).unwrap();
    let localize = LocalizeProxy::new(&client, 0).unwrap();
    let odom = Position2dProxy::new(&client, 0).unwrap();
    let sim = SimulationProxy::new(&client, 0);

    // amcl publishes once it has odometry, a scan and the map; wavefront
    // once it has the map.
    let deadline = Instant::now() + troupe_tests::DEADLINE;
    while localize.hypoths().is_empty() || planner.state().is_none() {
        assert!(
            Instant::now() < deadline,
            "amcl never published: {}",
            launcher.stderr()
        );
        let _ = client.read_timeout(troupe_tests::DEADLINE);
    }
    let start = sim.get_pose2d("r0").unwrap();
    let h = localize.hypoths()[0];
    assert!(
        (h.mean.x - start.x).hypot(h.mean.y - start.y) < 0.25,
        "amcl's first estimate {:?} is far from the true start {start:?}",
        h.mean
    );
    // The same, as nalgebra's types: an isometry near the truth and a
    // symmetric covariance with no negative variance.
    let (mean, cov) = localize.estimate().unwrap();
    let truth = troupe_client::na::ToIsometry::isometry(&start);
    assert!(
        (mean.translation.vector - truth.translation.vector).norm() < 0.25,
        "{mean} against {truth}"
    );
    assert_eq!(cov, cov.transpose());
    assert!((0..3).all(|i| cov[(i, i)] >= 0.0), "{cov}");
    // Odometry as an isometry (r0 stands still: its pose does not change).
    let odo = odom.data().unwrap().pose;
    let back = troupe_client::na::pose_of(&odom.isometry());
    assert!(
        (back.x - odo.x).abs() < 1e-9 && (back.y - odo.y).abs() < 1e-9,
        "{back:?} against {odo:?}"
    );

    let t0 = now();
    planner.set_goal_pose(GOAL.0, GOAL.1, 0.0).unwrap();
    if let Err(e) = planner.set_enable(true) {
        panic!("enable: {e}\n{}", launcher.stderr());
    }
    let mut valid_at = None;
    let route_from = t0;
    let deadline = Instant::now() + troupe_tests::DEADLINE * 3;
    loop {
        assert!(
            Instant::now() < deadline,
            "r0 did not arrive: planner {:?}, at {:?} after {:.1} simulated s\n{}",
            planner.state(),
            sim.get_pose2d("r0"),
            now() - t0,
            launcher.stderr()
        );
        let _ = client.read_timeout(troupe_tests::DEADLINE);
        assert!(!odom.stall(), "r0 collided at {:?}", sim.get_pose2d("r0"));
        let Some(state) = planner.state() else {
            continue;
        };
        if state.valid && valid_at.is_none() && state.goal.x == GOAL.0 {
            valid_at = Some(now() - t0);
        }
        if state.done && state.goal.x == GOAL.0 {
            break;
        }
    }
    let took = now() - t0;
    // amcl follows the robot along the route.
    let truth: std::collections::HashMap<u64, Pose2d> = truths
        .lock()
        .unwrap()
        .iter()
        .map(|&(t, p)| (t.to_bits(), p))
        .collect();
    let errors: Vec<f64> = estimates
        .lock()
        .unwrap()
        .iter()
        .filter(|(t, _)| *t >= route_from)
        .filter_map(|(t, e)| {
            let p = truth.get(&t.to_bits())?;
            Some((e.x - p.x).hypot(e.y - p.y))
        })
        .collect();
    assert!(
        errors.len() > 20,
        "only {} amcl estimates matched an odometry stamp",
        errors.len()
    );
    let worst_amcl = errors.iter().copied().fold(0.0, f64::max);
    let mean_amcl = errors.iter().sum::<f64>() / errors.len() as f64;
    // How often amcl said where r0 is (odometry comes every 0.1 s).
    let gap = estimates
        .lock()
        .unwrap()
        .windows(2)
        .map(|w| w[1].0 - w[0].0)
        .fold(0.0, f64::max);
    let end = sim.get_pose2d("r0").unwrap();
    let off = (end.x - GOAL.0).hypot(end.y - GOAL.1);
    eprintln!(
        "nav: valid path after {:.2} simulated s, arrived after {took:.1} simulated s, \
         {off:.2} m from the goal; amcl's error on the way {mean_amcl:.3} m mean, \
         {worst_amcl:.2} m worst, over {} estimates at most {gap:.1} s apart",
        valid_at.unwrap_or(f64::NAN),
        errors.len()
    );
    // Done means amcl's estimate was within the epsilon: the truth may be
    // as far again as amcl was off, and r0 rolls on a little.
    assert!(
        off < DISTANCE_EPSILON + worst_amcl + COAST,
        "stopped {off:.2} m from the goal at {end:?} (epsilon {DISTANCE_EPSILON} m, \
         amcl off by up to {worst_amcl:.2} m)"
    );
    assert!(
        took <= PLAYER_ARRIVAL_SIM_S,
        "took {took:.1} simulated s; Player's stack took {PLAYER_ARRIVAL_SIM_S}"
    );
    // Player's amcl on this route: 3 cm mean, 8 cm worst, figures known to
    // the centimetre; compared at that precision (a 3.2 cm mean is Player's 3).
    assert!(
        worst_amcl < 0.085 && mean_amcl < 0.035,
        "amcl strayed from the true pose: {mean_amcl:.3} m mean, {worst_amcl:.2} m worst \
         (Player: 0.03 m mean, 0.08 m worst)"
    );
    let wps = planner.request_waypoints().unwrap();
    assert!(wps.len() >= 2, "{wps:?}");
    let last = wps.last().unwrap();
    assert!((last.x - GOAL.0).hypot(last.y - GOAL.1) < 0.1, "{wps:?}");
    assert!(launcher.terminate().success(), "{}", launcher.stderr());
}

/// Player's amcl sonar model (issue 30, item 4b): r0 of Stage's own
/// simple.world wanders the cave with nothing but its 16 sonars; amcl,
/// weighing poses by them against cave.png, keeps within 0.3 m of where
/// the simulator says r0 is.
#[test]
fn amcl_localizes_a_sonar_only_robot_in_the_cave() {
    let Some(stage) = troupe_tests::compat("stage") else {
        return;
    };
    let stage = stage.canonicalize().unwrap();
    let text = format!(
        "driver ( name \"stage\" provides [\"simulation:0\"] worldfile \"{w}\" )\n\
         driver ( name \"stage\" provides [\"position2d:0\" \"sonar:0\"] model \"r0\" )\n\
         driver ( name \"mapfile\" provides [\"map:0\"] filename \"{m}\" resolution 0.032 )\n\
         driver ( name \"amcl\" provides [\"position2d:2\"]\n\
           requires [\"odometry:::position2d:0\" \"sonar:0\" \"sonar:::map:0\"]\n\
           init_pose [-6.946 -6.947 45] init_pose_var [0.2 0.2 10] )\n",
        w = stage.join("simple.world").display(),
        m = stage.join("bitmaps/cave.png").display(),
    );
    let dir = std::env::temp_dir().join(troupe_tests::unique_namespace("sonar-amcl"));
    std::fs::create_dir_all(&dir).unwrap();
    let cfg = dir.join("amcl_sonar.cfg");
    std::fs::write(&cfg, text).unwrap();
    let ns = troupe_tests::unique_namespace("sonar-amcl");
    let mut launcher = troupe_tests::launch(&ns, &cfg, &["--no-bridge", "--speedup", "4"]);
    let endpoint = launcher.endpoint("troupe launch: router listening on");
    let session = troupe_tests::client_at(&endpoint, &ns);
    troupe_tests::wait_live(&session, &["6665:simulation:0", "6665:position2d:2"]);
    let client = Client::with_session(session, 6665);
    let sim = SimulationProxy::new(&client, 0);
    let amcl = Position2dProxy::new(&client, 2).unwrap();
    let deadline = Instant::now() + std::time::Duration::from_secs(120);
    let (mut worst, mut checks, mut next) = (0.0f64, 0, 20.0);
    let start = sim.get_pose2d("r0").unwrap();
    let mut travelled = 0.0;
    let mut last = start;
    while checks < 10 {
        assert!(Instant::now() < deadline, "{checks} checks in time");
        client.read().unwrap();
        let t = client.data_time();
        if t < next || amcl.x() == 0.0 {
            continue;
        }
        next = t + 2.0;
        let truth = sim.get_pose2d("r0").unwrap();
        travelled += (truth.x - last.x).hypot(truth.y - last.y);
        last = truth;
        let err = (amcl.x() - truth.x).hypot(amcl.y() - truth.y);
        worst = worst.max(err);
        checks += 1;
    }
    eprintln!("sonar amcl: worst {worst:.2} m over {checks} checks, r0 wandered {travelled:.1} m");
    assert!(travelled > 3.0, "r0 wandered only {travelled} m");
    assert!(worst < 0.3, "amcl strayed {worst} m from r0");
    assert!(launcher.terminate().success(), "{}", launcher.stderr());
    let _ = std::fs::remove_dir_all(&dir);
}

/// Player's `nd` in a narrow passage (issue 30, item 2): worlds/passage.cfg
/// runs nd with the settings of Stage's own nd.cfg; r0 is sent from the
/// south-west of worlds/passage.world to its south-east, through crates
/// and a doorway 0.6 m wide, and arrives (by the simulator's true pose)
/// without a collision. The same trip with vfh and the cpp-planner-localize
/// scenario's settings (worlds/passage_vfh.cfg) is run beside it and
/// reported, whatever it does: here it does not find the doorway (its
/// 0.22 m radius and 0.1 m safety distance close a gap under 0.64 m), and
/// with the doorway 0.8 m wide both arrive (nd 42.6, vfh 49.7 simulated s).
#[test]
fn nd_takes_r0_through_the_doorway_and_vfh_is_measured_beside_it() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let nd = passage_trip(&root.join("worlds/passage.cfg"), 0.35, "2");
    let vfh = passage_trip(&root.join("worlds/passage_vfh.cfg"), 0.35, "4");
    eprintln!("passage: nd {}; vfh {}", nd.describe(), vfh.describe());
    assert!(nd.arrived.is_some(), "nd did not arrive: {}", nd.describe());
    assert!(!nd.collided, "nd collided: {}", nd.describe());
}

/// The goal of the passage trips, and how long a trip may take (simulated s).
const PASSAGE_GOAL: (f64, f64) = (4.5, -3.0);
const PASSAGE_LIMIT_S: f64 = 150.0;

struct Trip {
    arrived: Option<f64>,
    collided: bool,
    end: Pose2d,
}

impl Trip {
    fn describe(&self) -> String {
        let off = (self.end.x - PASSAGE_GOAL.0).hypot(self.end.y - PASSAGE_GOAL.1);
        match self.arrived {
            Some(t) => format!("arrived after {t:.1} simulated s"),
            None => format!(
                "did not arrive in {PASSAGE_LIMIT_S} simulated s: stopped at ({:.2}, {:.2}), {off:.2} m from the goal{}",
                self.end.x,
                self.end.y,
                if self.collided { ", after a collision" } else { "" }
            ),
        }
    }
}

/// Launches `cfg` (`speedup` × real time: nd at 2, so that a loaded
/// machine's decisions keep up with the robot), sends r0 to [`PASSAGE_GOAL`] on
/// position2d:1 and follows its true pose until it is within `tol` of the
/// goal or [`PASSAGE_LIMIT_S`] simulated seconds have passed.
fn passage_trip(cfg: &Path, tol: f64, speedup: &str) -> Trip {
    let ns = troupe_tests::unique_namespace("passage");
    let mut launcher = troupe_tests::launch(&ns, cfg, &["--no-bridge", "--speedup", speedup]);
    let endpoint = launcher.endpoint("troupe launch: router listening on");
    let session = troupe_tests::client_at(&endpoint, &ns);
    let (_clock, now) = sim_clock(&session);
    let client = Client::with_session(session.clone(), 6665);
    let base = Position2dProxy::new(&client, 0).unwrap();
    let nav = Position2dProxy::new(&client, 1).unwrap();
    let sim = SimulationProxy::new(&client, 0);
    let deadline = Instant::now() + troupe_tests::DEADLINE;
    while nav.data().is_none() || now() == 0.0 {
        assert!(Instant::now() < deadline, "no data: {}", launcher.stderr());
        let _ = client.read_timeout(troupe_tests::DEADLINE);
    }
    // r0's odometry is its true pose (`localization "gps"`).
    nav.go_to(PASSAGE_GOAL.0, PASSAGE_GOAL.1, 0.0).unwrap();
    let t0 = now();
    let mut collided = false;
    let deadline = Instant::now() + troupe_tests::DEADLINE * 4;
    let arrived = loop {
        assert!(
            Instant::now() < deadline,
            "{} s of simulated time in {:?}: {}",
            now() - t0,
            troupe_tests::DEADLINE * 4,
            launcher.stderr()
        );
        let _ = client.read_timeout(troupe_tests::DEADLINE);
        collided |= base.stall();
        let p = sim.get_pose2d("r0").unwrap();
        if (p.x - PASSAGE_GOAL.0).hypot(p.y - PASSAGE_GOAL.1) < tol {
            break Some(now() - t0);
        }
        if now() - t0 > PASSAGE_LIMIT_S {
            break None;
        }
    };
    let end = sim.get_pose2d("r0").unwrap();
    assert!(launcher.terminate().success(), "{}", launcher.stderr());
    Trip {
        arrived,
        collided,
        end,
    }
}
