//! `troupe cmd` and `troupe call` as a user types them, against a launched
//! simple.cfg and nav.cfg: the robot moves and stops, a goal gives a path,
//! a refused request prints the device's reason.

use std::path::PathBuf;
use std::time::Instant;

use troupe_client::{Client, PlannerProxy, Position2dProxy, SimulationProxy};
use troupe_tests::{client_at, strings, troupe_output, wait_live, DEADLINE};

fn world(cfg: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the workspace")
        .join("worlds")
        .join(cfg)
}

/// `troupe --connect EP --namespace NS ARGS…`: status, stdout, stderr.
fn troupe(endpoint: &str, ns: &str, args: &[&str]) -> (bool, String, String) {
    let mut all = strings(&["--connect", endpoint, "--namespace", ns, "--no-multicast"]);
    all.extend(strings(args));
    let (st, out, err) = troupe_output(&all);
    (st.success(), out, err)
}

#[test]
fn cmd_drives_the_base_and_stops_it_and_call_asks_and_explains_refusals() {
    let ns = troupe_tests::unique_namespace("act");
    let mut launcher = troupe_tests::launch(&ns, &world("simple.cfg"), &["--no-bridge"]);
    let endpoint = launcher.endpoint("troupe launch: router listening on");
    let session = client_at(&endpoint, &ns);
    wait_live(&session, &["6665:position2d:0", "6665:simulation:0"]);
    let client = Client::with_session(session, 6665);
    let sim = SimulationProxy::new(&client, 0);
    let base = Position2dProxy::new(&client, 0).unwrap();
    let start = sim.get_pose2d("r0").unwrap();

    let (ok, _, err) = troupe(
        &endpoint,
        &ns,
        &["cmd", "position2d:0", "vel", "0.3", "0", "0", "--for", "1"],
    );
    assert!(ok, "{err}");
    assert!(
        err.contains("for 1 s") && err.contains("stopped 6665:position2d:0"),
        "{err}"
    );
    // The stop was the last command: the base's velocity reads zero from the next step on.
    let deadline = Instant::now() + DEADLINE;
    while base.x_speed() != 0.0 {
        assert!(Instant::now() < deadline, "r0 never stopped");
        client.read().unwrap();
    }
    let end = sim.get_pose2d("r0").unwrap();
    let moved = (end.x - start.x).hypot(end.y - start.y);
    assert!(moved > 0.1, "r0 moved {moved} m");

    let (ok, out, err) = troupe(
        &endpoint,
        &ns,
        &["call", "simulation:0", "get_pose2d", "r0"],
    );
    assert!(ok, "{err}");
    assert!(
        out.starts_with("simulation/pose2d@1 {\"name\":\"r0\",\"pose\":{\"x\":"),
        "{out}"
    );

    let (ok, _, err) = troupe(
        &endpoint,
        &ns,
        &[
            "call",
            "simulation:0",
            "set_pose2d",
            "r0",
            "-5",
            "-5",
            "-0.5",
        ],
    );
    assert!(ok, "{err}");
    let moved_to = sim.get_pose2d("r0").unwrap();
    assert!(
        (moved_to.x + 5.0).abs() < 1e-6 && (moved_to.yaw + 0.5).abs() < 1e-6,
        "{moved_to:?}"
    );

    let (ok, _, err) = troupe(
        &endpoint,
        &ns,
        &["call", "simulation:0", "get_pose2d", "nope"],
    );
    assert!(!ok);
    assert!(
        err.contains("refused `get_pose2d`") && err.contains("nope"),
        "{err}"
    );

    // `hz` counts updates, not samples: the laser's ranges and intensities
    // of one step (one stamp) are one update, as the base's odometry is.
    let rate = |out: &str, kind: &str| -> f64 {
        let line = out
            .lines()
            .rev()
            .find(|l| l.contains(kind))
            .unwrap_or_else(|| panic!("no {kind} in {out}"));
        line.strip_prefix("rate: ")
            .and_then(|r| r.split(' ').next())
            .and_then(|r| r.parse().ok())
            .unwrap_or_else(|| panic!("no rate in {line}"))
    };
    let (ok, laser, err) = troupe(&endpoint, &ns, &["hz", "laser:0", "--count", "2"]);
    assert!(ok, "{err}");
    assert!(
        laser.contains("laser/scan (2.0 samples an update, counted once)"),
        "{laser}"
    );
    let (ok, base, err) = troupe(&endpoint, &ns, &["hz", "position2d:0", "--count", "2"]);
    assert!(ok, "{err}");
    let (l, b) = (rate(&laser, "laser/scan"), rate(&base, "position2d/data"));
    assert!(
        (l / b - 1.0).abs() < 0.2,
        "laser {l} Hz, base {b} Hz\n{laser}{base}"
    );

    // Waiting in silence says what for; one device is one.
    let (ok, _, err) = troupe(&endpoint, &ns, &["echo", "laser:7", "--timeout", "0.5"]);
    assert!(
        !ok && err.contains("6665:laser:7 is not live; waiting for it"),
        "{err}"
    );
    let (ok, out, err) = troupe(&endpoint, &ns, &["ready", "laser:0"]);
    assert!(ok, "{err}");
    assert_eq!(out.trim(), "ready: 6665:laser:0 is live");

    let (ok, _, err) = troupe(&endpoint, &ns, &["cmd", "position2d:0", "velo", "1"]);
    assert!(!ok);
    assert!(
        err.contains(
            "position2d has no command `velo`; its commands (`troupe cmd`): vel, pos, car"
        ),
        "{err}"
    );
    let (ok, _, err) = troupe(&endpoint, &ns, &["cmd", "position2d:0", "vel", "fast"]);
    assert!(
        !ok && err.contains("`fast` is not a number (vel.x)"),
        "{err}"
    );
    launcher.terminate();
}

#[test]
fn cmd_gives_the_planner_a_goal() {
    let ns = troupe_tests::unique_namespace("act-nav");
    let mut launcher =
        troupe_tests::launch(&ns, &world("nav.cfg"), &["--no-bridge", "--speedup", "8"]);
    let endpoint = launcher.endpoint("troupe launch: router listening on");
    let session = client_at(&endpoint, &ns);
    wait_live(&session, &["6665:planner:0", "6665:localize:0"]);
    let client = Client::with_session(session, 6665);
    let planner = PlannerProxy::new(&client, 0).unwrap();
    let (ok, _, err) = troupe(&endpoint, &ns, &["cmd", "planner:0", "goal", "5", "0", "0"]);
    assert!(ok, "{err}");
    assert!(err.contains("sent goal"), "{err}");
    let deadline = Instant::now() + DEADLINE;
    while !(planner.path_valid()
        && planner
            .state()
            .is_some_and(|s| (s.goal.x - 5.0).abs() < 1e-9))
    {
        assert!(
            Instant::now() < deadline,
            "no path to the goal: {:?}",
            planner.state()
        );
        client.read().unwrap();
    }
    launcher.terminate();
}
