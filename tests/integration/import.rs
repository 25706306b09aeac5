//! `troupe bridge --import`: a Player server's devices on Troupe's keys. The
//! Player server here is Troupe's own bridge in front of simple.cfg — it
//! speaks Player 3 TCP byte for byte (the transcripts prove it) — and the
//! import republishes its robot 6665 as robot 7000 on the same network:
//! data, commands and requests all go through two Player hops.

use std::collections::HashMap;
use std::path::Path;
use std::time::Instant;

use troupe_client::{Client, Position2dProxy, RangerProxy, SimulationProxy};
use troupe_msgs::{keys, laser, Device, Interface};
use troupe_node::zenoh::Wait;
use troupe_tests::{Proc, DEADLINE};

#[test]
fn an_imported_player_server_streams_and_obeys_on_troupe_keys() {
    let ns = troupe_tests::unique_namespace("import");
    let cfg = Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds/simple.cfg");
    let mut launcher = troupe_tests::launch(&ns, &cfg, &["--speedup", "2"]);
    // Its router, then its Player port, from its stdout.
    let (router, player) = troupe_tests::launch_ports(&mut launcher);
    let player = player.to_string();
    let mut import = Proc::troupe(
        "import",
        &[
            "--connect",
            &router,
            "--namespace",
            &ns,
            "--no-multicast",
            "bridge",
            "--import",
            &player,
            "--as",
            "7000",
        ]
        .map(str::to_owned),
    );
    let session = troupe_tests::client_at(&router, &ns);
    troupe_tests::wait_live(&session, &["7000:laser:0", "7000:position2d:0"]);

    // The same scans on both robots, stamp for stamp.
    let (tx, rx) = std::sync::mpsc::channel::<(u32, u64, Vec<f32>)>();
    let record = |robot: u32| {
        let tx = tx.clone();
        let dev = Device::new(robot, Interface::Laser, 0);
        session
            .declare_subscriber(keys::data(&dev))
            .callback(move |s| {
                if let Ok(d) = troupe_msgs::decode::<laser::Scan>(&s.payload().to_bytes()) {
                    let _ = tx.send((robot, d.stamp.to_bits(), d.msg.ranges));
                }
            })
            .wait()
            .unwrap()
    };
    let (_s1, _s2) = (record(6665), record(7000));
    let mut seen: HashMap<(u32, u64), Vec<f32>> = HashMap::new();
    let deadline = Instant::now() + DEADLINE;
    let common = loop {
        let left = deadline.saturating_duration_since(Instant::now());
        let (robot, t, ranges) = rx.recv_timeout(left).unwrap_or_else(|_| {
            panic!("no imported scan matched an original: {}", import.stderr())
        });
        let other = if robot == 7000 { 6665 } else { 7000 };
        if let Some(o) = seen.get(&(other, t)) {
            let (imported, original) = if robot == 7000 {
                (ranges, o.clone())
            } else {
                (o.clone(), ranges)
            };
            break (f64::from_bits(t), imported, original);
        }
        seen.insert((robot, t), ranges);
    };
    assert_eq!(common.1, common.2, "the scan at {} differs", common.0);
    assert_eq!(common.1.len(), 180);

    // Requests go to the server and its answers come back.
    let client = Client::with_session(session.clone(), 7000);
    let base = Position2dProxy::new(&client, 0).unwrap();
    let original = Client::with_session(session.clone(), 6665);
    assert_eq!(
        base.request_geom().unwrap(),
        Position2dProxy::new(&original, 0)
            .unwrap()
            .request_geom()
            .unwrap()
    );
    let ranger = RangerProxy::new(&client, 1)
        .unwrap()
        .request_geom()
        .unwrap();
    assert_eq!(
        ranger,
        RangerProxy::new(&original, 1)
            .unwrap()
            .request_geom()
            .unwrap()
    );
    assert!(!ranger.element_poses.is_empty());

    // A command to the imported robot drives the simulated one.
    let sim = SimulationProxy::new(&original, 0);
    let start = sim.get_pose2d("r0").unwrap();
    let deadline = Instant::now() + DEADLINE;
    loop {
        base.set_speed(0.4, 0.0).unwrap();
        let now = sim.get_pose2d("r0").unwrap();
        if (now.x - start.x).hypot(now.y - start.y) > 0.2 {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "r0 did not move from {start:?}: {}",
            import.stderr()
        );
        let _ = client.read_timeout(DEADLINE);
    }
    base.set_speed(0.0, 0.0).unwrap();
    assert!(import.terminate().success(), "{}", import.stderr());
    let log = import.stderr();
    assert!(
        log.contains("importing 7000:laser:0 (rangertolaser)"),
        "{log}"
    );
    assert!(launcher.terminate().success(), "{}", launcher.stderr());
}

/// Something that is not a Player server is named as such, and the import
/// fails instead of publishing nothing forever.
#[test]
fn importing_something_that_is_not_player_says_so() {
    let net = troupe_tests::TestNet::new("import-bad");
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    std::thread::spawn(move || {
        use std::io::Write;
        if let Ok((mut s, _)) = listener.accept() {
            let _ = s.write_all(b"SSH-2.0-OpenSSH_9.2p1 Debian-2\r\n");
        }
    });
    let mut args = net.args().to_child_args();
    args.extend(["bridge", "--import", &addr].map(str::to_owned));
    let (status, _, err) = troupe_tests::troupe_output(&args);
    assert!(!status.success());
    assert!(err.contains("is not a Player server"), "{err}");
    assert!(err.contains(&addr), "{err}");
}

/// Player's `passthrough` as a .cfg driver (issue 30, item 1): a second
/// stack serves robot A's position2d, reached through A's Player bridge,
/// as its own. Data flows, a velocity command moves A's robot, and when A
/// goes away the device leaves, back once A is.
#[test]
fn a_passthrough_device_follows_its_player_server_away_and_back() {
    use troupe_client::{Client, Position2dProxy, SimulationProxy};
    use troupe_node::zenoh::sample::SampleKind;
    // A's robot number is its Player port: a free one, so A can come back on it.
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let ns_a = troupe_tests::unique_namespace("pass-a");
    let cfg_a = Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds/simple.cfg");
    let start_a = || {
        let mut a = Proc::troupe(
            "remote stack",
            &troupe_tests::strings(&[
                "--namespace",
                &ns_a,
                "launch",
                cfg_a.to_str().unwrap(),
                "--listen",
                "tcp/127.0.0.1:0",
                "-p",
                &port.to_string(),
            ]),
        );
        // The router's line, then the bridge's once every device is live.
        let lines = a.lines();
        let deadline = Instant::now() + DEADLINE;
        let mut router = None;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let line = lines
                .recv_timeout(left)
                .expect("A's router and bridge lines");
            if let Some(rest) = line.strip_prefix("troupe launch: router listening on ") {
                router = rest.split_whitespace().next().map(str::to_owned);
            }
            if line.starts_with(&format!("troupe bridge: robot {port} on")) {
                break;
            }
        }
        (a, router.expect("A's router line"))
    };
    let (mut a, router_a) = start_a();

    let dir = std::env::temp_dir().join(troupe_tests::unique_namespace("pass-cfg"));
    std::fs::create_dir_all(&dir).unwrap();
    let cfg_b = dir.join("passthrough.cfg");
    std::fs::write(
        &cfg_b,
        format!(
            "driver ( name \"passthrough\" requires [\":127.0.0.1:{port}:position2d:0\"] provides [\"position2d:0\"] )\n"
        ),
    )
    .unwrap();
    let ns_b = troupe_tests::unique_namespace("pass-b");
    let mut b = troupe_tests::launch(&ns_b, &cfg_b, &["--no-bridge"]);
    let router_b = b.endpoint("troupe launch: router listening on");
    let session_b = troupe_tests::client_at(&router_b, &ns_b);
    troupe_tests::wait_live(&session_b, &["6665:position2d:0"]);
    let tokens = troupe_tests::token_events(&session_b);

    // Data flows, and a command through B moves A's robot.
    let client = Client::with_session(session_b.clone(), 6665);
    let pp = Position2dProxy::new(&client, 0).unwrap();
    let deadline = Instant::now() + DEADLINE;
    while client.data_time() <= 0.0 {
        assert!(Instant::now() < deadline, "no position2d data through B");
        client.read().unwrap();
    }
    let sim_a = SimulationProxy::new(
        &Client::with_session(troupe_tests::client_at(&router_a, &ns_a), port.into()),
        0,
    );
    let before = sim_a.get_pose2d("r0").unwrap();
    pp.set_speed(0.3, 0.0).unwrap();
    let deadline = Instant::now() + DEADLINE;
    loop {
        client.read().unwrap();
        let now = sim_a.get_pose2d("r0").unwrap();
        if (now.x - before.x).hypot(now.y - before.y) > 0.2 {
            break;
        }
        assert!(Instant::now() < deadline, "r0 of A never moved: {now:?}");
    }
    pp.set_speed(0.0, 0.0).unwrap();

    // A goes: B's device leaves. A comes back: it returns.
    assert!(a.terminate().success(), "{}", a.stderr());
    let gone = |kind: SampleKind| {
        let deadline = Instant::now() + DEADLINE;
        loop {
            let s = tokens
                .recv_deadline(deadline)
                .expect("liveliness")
                .unwrap_or_else(|| panic!("no {kind:?} of B's position2d:0"));
            let dev = troupe_msgs::keys::parse_token(s.key_expr().as_str()).map(|(d, _)| d);
            if s.kind() == kind && dev.is_ok_and(|d| d.to_string() == "6665:position2d:0") {
                return;
            }
        }
    };
    gone(SampleKind::Delete);
    let (mut a, _) = start_a();
    gone(SampleKind::Put);
    assert!(a.terminate().success(), "{}", a.stderr());
    assert!(b.terminate().success(), "{}", b.stderr());
    let _ = std::fs::remove_dir_all(&dir);
}
