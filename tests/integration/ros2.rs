//! ROS 2 nodes on rmw_zenoh see and drive a Troupe robot (`launch --ros2`),
//! checked with an independent implementation of rmw_zenoh's protocol as
//! the ROS 2 peer (hiroz, ZettaScale's): its subscriptions decode the
//! simulated laser and odometry, its Twist drives the robot and Troupe
//! stops it when `cmd_vel` goes quiet, its graph lists Troupe's nodes and
//! topics, a late transient-local subscriber still gets the map, and its
//! service client gets the map by `GetMap`; `troupe record` of the ROS 2
//! traffic reads back as ROS 2 messages. rmw_zenoh's own details that
//! hiroz does not check (the attachment's GID, sequence numbers from 1)
//! are pinned by the golden tests of libs/ros2/src/rmw.rs.

use std::num::NonZeroUsize;
use std::time::Instant;

use hiroz::context::ZContextBuilder;
use hiroz::prelude::*;
use hiroz_msgs::geometry_msgs::{Twist, Vector3};
use hiroz_msgs::nav_msgs::{OccupancyGrid, Odometry};
use hiroz_msgs::sensor_msgs::LaserScan;
use troupe_node::zenoh::Wait;
use troupe_node::{Mode, ZenohArgs};
use troupe_tests::{Proc, DEADLINE};

/// A cfg of the simulated r0 (odometry, sonar, laser) and a map server.
fn robot_cfg() -> std::path::PathBuf {
    let worlds = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds");
    let worlds = worlds.canonicalize().unwrap();
    let dir = std::env::temp_dir().join(troupe_tests::unique_namespace("ros2-cfg"));
    std::fs::create_dir_all(&dir).unwrap();
    let text = format!(
        r#"
driver ( name "stage" provides ["simulation:0"] worldfile "{w}/simple.world" )
driver ( name "stage" provides ["position2d:0" "ranger:0" "ranger:1"] model "r0" )
driver ( name "rangertolaser" requires ["ranger:1"] provides ["laser:0"] )
driver ( name "mapfile" provides ["map:0"] filename "{w}/bitmaps/office.png" resolution 0.05 )
"#,
        w = worlds.display()
    );
    let p = dir.join("robot.cfg");
    std::fs::write(&p, text).unwrap();
    p
}

/// The ROS 2 peer's session settings: the launch's router and namespace,
/// timestamps on as rmw_zenoh's sessions have them.
fn peer_config(endpoint: &str, ns: &str) -> troupe_node::zenoh::Config {
    let mut c = ZenohArgs {
        connect: vec![endpoint.to_owned()],
        listen: vec!["tcp/127.0.0.1:0".into()],
        namespace: Some(ns.to_owned()),
        no_multicast: true,
        ..Default::default()
    }
    .config(Mode::Peer)
    .unwrap();
    c.insert_json5("timestamping/enabled", "true").unwrap();
    c
}

/// Reads a log until a line containing `what`.
fn until_line(lines: &std::sync::mpsc::Receiver<String>, what: &str) -> String {
    let deadline = Instant::now() + DEADLINE;
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        match lines.recv_timeout(left) {
            Ok(l) if l.contains(what) => return l,
            Ok(_) => {}
            Err(_) => panic!("the log never said `{what}`"),
        }
    }
}

#[test]
fn a_ros2_peer_sees_drives_and_maps_a_troupe_robot() {
    let ns = troupe_tests::unique_namespace("ros2");
    let cfg = robot_cfg();
    let mut launcher = troupe_tests::launch(&ns, &cfg, &["--ros2", "--no-bridge"]);
    let endpoint = launcher.endpoint("troupe launch: router listening on");
    let lines = launcher.err_lines();

    let ctx = ZContextBuilder::default()
        .with_zenoh_config(peer_config(&endpoint, &ns))
        .with_domain_id(0)
        .build()
        .unwrap();
    let node = ctx
        .create_node("probe")
        .without_parameters()
        .build()
        .unwrap();

    // The laser, as a ROS 2 LaserScan.
    let scans = node
        .create_sub::<LaserScan>("/robot_6665/scan")
        .build()
        .unwrap();
    let scan = scans
        .recv_timeout(DEADLINE)
        .expect("a LaserScan from Troupe");
    assert_eq!(scan.header.frame_id, "robot_6665/laser_0");
    assert!(
        !scan.ranges.is_empty() && scan.angle_max > scan.angle_min,
        "{scan:?}"
    );
    assert!(scan.ranges.iter().all(|r| r.is_finite() && *r >= 0.0));

    until_line(&lines, "kept for late subscribers");

    // Drive with cmd_vel, paced by odometry as it comes; then go quiet.
    let odom = node
        .create_sub::<Odometry>("/robot_6665/odom")
        .build()
        .unwrap();
    let cmd = node
        .create_pub::<Twist>("/robot_6665/cmd_vel")
        .build()
        .unwrap();
    let first = odom.recv_timeout(DEADLINE).expect("Odometry from Troupe");
    assert_eq!(
        (
            first.header.frame_id.as_str(),
            first.child_frame_id.as_str()
        ),
        ("robot_6665/odom", "robot_6665/base_link")
    );
    let start = first.pose.pose.position;
    let forward = Twist {
        linear: Vector3 {
            x: 0.4,
            y: 0.0,
            z: 0.0,
        },
        angular: Vector3 {
            x: 0.0,
            y: 0.0,
            z: 0.0,
        },
    };
    let deadline = Instant::now() + DEADLINE;
    let (mut moved, mut graph_ok) = (0.0, false);
    while moved < 0.3 || !graph_ok {
        assert!(
            Instant::now() < deadline,
            "moved {moved} m; the graph: {:?} {:?}",
            node.graph().get_node_names(),
            node.graph().get_topic_names_and_types()
        );
        cmd.publish(&forward).unwrap();
        let o = odom.recv_timeout(DEADLINE).expect("odometry while driving");
        let p = &o.pose.pose.position;
        moved = ((p.x - start.x).powi(2) + (p.y - start.y).powi(2)).sqrt();
        // The graph, as `ros2 node list` and `ros2 topic list` read it.
        let g = node.graph();
        let nodes = g.get_node_names();
        let topics = g.get_topic_names_and_types();
        graph_ok = nodes
            .iter()
            .any(|(n, s)| n == "stage" && s == "/robot_6665")
            && nodes
                .iter()
                .any(|(n, s)| n == "rangertolaser" && s == "/robot_6665")
            && topics
                .iter()
                .any(|(t, ty)| t == "/robot_6665/scan" && ty.contains("LaserScan"))
            && topics
                .iter()
                .any(|(t, ty)| t == "/robot_6665/cmd_vel" && ty.contains("Twist"));
    }
    // No more cmd_vel: the base stops by itself.
    let deadline = Instant::now() + DEADLINE;
    loop {
        assert!(Instant::now() < deadline, "the robot never stopped");
        let o = odom
            .recv_timeout(DEADLINE)
            .expect("odometry after cmd_vel stopped");
        if o.twist.twist.linear.x == 0.0 {
            break;
        }
    }
    until_line(&lines, "no cmd_vel for");

    // A late subscriber still gets the map (transient local), published
    // long before (the log said so first).
    let latched = QosProfile {
        durability: QosDurability::TransientLocal,
        reliability: QosReliability::Reliable,
        history: QosHistory::KeepLast(NonZeroUsize::new(1).unwrap()),
        ..Default::default()
    };
    let maps = node
        .create_sub::<OccupancyGrid>("/robot_6665/map")
        .with_qos(latched)
        .build()
        .unwrap();
    let map = maps.recv_timeout(DEADLINE).expect("the map, late");
    // office.png: 320 x 320 pixels of 5 cm.
    assert_eq!((map.info.width, map.info.height), (320, 320));
    assert!((map.info.resolution - 0.05).abs() < 1e-6);
    assert_eq!(map.data.len(), 320 * 320);
    assert!(
        map.data.contains(&100) && map.data.contains(&0),
        "walls and free space"
    );

    // GetMap, as a service client calls it.
    let client = node
        .create_client::<hiroz_msgs::nav_msgs::srv::GetMap>("/robot_6665/map_server/map")
        .build()
        .unwrap();
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .unwrap();
    let got = rt
        .block_on(client.call_with_timeout(&Default::default(), DEADLINE))
        .expect("GetMap's answer");
    assert_eq!(got.map.data, map.data);

    // What ROS 2 nodes hear on the router, recorded, reads as ROS 2 messages.
    let file = std::env::temp_dir().join(format!("{ns}.mcap"));
    let (st, _, err) = troupe_tests::troupe_output(&troupe_tests::strings(&[
        "--namespace",
        &ns,
        "--connect",
        &endpoint,
        "--no-multicast",
        "record",
        "0/**",
        "--duration",
        "2",
        "-o",
        file.to_str().unwrap(),
    ]));
    assert!(st.success(), "{err}");
    let bytes = std::fs::read(&file).unwrap();
    let _ = std::fs::remove_file(&file);
    let mut scans = 0;
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        if m.channel.topic != "/robot_6665/scan" {
            continue;
        }
        let schema = m.channel.schema.as_ref().expect("a schema");
        assert_eq!(
            (
                schema.name.as_str(),
                schema.encoding.as_str(),
                m.channel.message_encoding.as_str()
            ),
            ("sensor_msgs/msg/LaserScan", "ros2msg", "cdr")
        );
        let s: troupe_ros2::msg::LaserScan = cdr::deserialize(&m.data).unwrap();
        assert_eq!(s.ranges.len(), scan.ranges.len());
        scans += 1;
    }
    assert!(scans > 0, "no /robot_6665/scan in the recording: {err}");

    launcher.terminate();
}

#[test]
fn bad_ros2_input_is_counted_and_the_robot_stays_safe() {
    let world = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds/simple.world");
    let net = troupe_tests::TestNet::new("ros2-bad");
    let mut args = net.child_args();
    args.extend(troupe_tests::strings(&[
        "node",
        "stage",
        "--world",
        world.to_str().unwrap(),
        "--provides",
        "position2d:0",
        "--ros2",
        "--ros2-domain",
        "7",
        "-o",
        "model=r0",
    ]));
    let mut stage = Proc::troupe("stage", &args);
    let lines = stage.err_lines();
    net.wait_live(&["6665:position2d:0"]);
    let s = net.peer();
    let key = "7/robot_6665/cmd_vel/geometry_msgs::msg::dds_::Twist_/RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a";
    // Three that are no Twist (too short, garbage, a NaN speed): one warning.
    let mut nan = vec![0u8, 1, 0, 0];
    nan.extend(f64::NAN.to_le_bytes());
    nan.extend([0u8; 40]);
    let publisher = s.declare_publisher(key).wait().unwrap();
    // Sent once the node's subscription is known here, not before.
    let matching = publisher.matching_listener().wait().unwrap();
    if !publisher.matching_status().wait().unwrap().matching() {
        let m = matching
            .recv_timeout(DEADLINE)
            .unwrap()
            .expect("the node's cmd_vel subscription");
        assert!(m.matching());
    }
    for bad in [vec![0u8, 1, 0, 0, 1], vec![0xff; 7], nan] {
        publisher.put(bad).wait().unwrap();
    }
    let warned = until_line(&lines, "dropped a message on /robot_6665/cmd_vel");
    assert!(warned.contains("1 so far"), "{warned}");
    // A flood of good ones: the robot takes them (coalesced), and stays up.
    let mut twist = vec![0u8, 1, 0, 0];
    for v in [0.2f64, 0.0, 0.0, 0.0, 0.0, 0.1] {
        twist.extend(v.to_le_bytes());
    }
    for _ in 0..2000 {
        publisher.put(twist.clone()).wait().unwrap();
    }
    until_line(&lines, "no cmd_vel for");
    net.wait_live(&["6665:position2d:0"]);
    assert!(stage.child.try_wait().unwrap().is_none(), "stage died");
    stage.terminate();
}

/// `troupe bench ros2` times both paths in one run and prints their ratio;
/// both got scans.
#[test]
fn bench_ros2_prints_both_paths_and_their_ratio() {
    let (st, out, err) = troupe_tests::troupe_output(&troupe_tests::strings(&[
        "bench",
        "ros2",
        "--seconds",
        "0.5",
        "--rate",
        "200",
        "--fleet-seconds",
        "0",
    ]));
    assert!(st.success(), "{out}{err}");
    for path in ["Troupe's key", "ROS 2 (/robot_6665/scan)"] {
        let line = out
            .lines()
            .find(|l| l.contains(path))
            .unwrap_or_else(|| panic!("{out}"));
        let rate: f64 = line.split_whitespace().last().unwrap().parse().unwrap();
        assert!(rate > 50.0, "{line}");
    }
    assert!(out.contains("ROS 2 / Troupe: p50"), "{out}");
}
