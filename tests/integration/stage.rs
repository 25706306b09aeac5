//! Stage's own simple.cfg (read in place from ../shared/compat) launched as
//! processes: r0's devices come up, a client drives r0 towards a wall and the
//! laser sees it approach.

use std::path::Path;
use std::time::Instant;

use troupe_client::{Client, LaserProxy, Position2dProxy, SimulationProxy};
use troupe_tests::DEADLINE;

#[test]
fn simple_cfg_serves_r0_and_the_laser_sees_the_wall_approach() {
    let Some(cfg) = troupe_tests::compat("stage/simple.cfg") else {
        return;
    };
    let ns = troupe_tests::unique_namespace("stage");
    let mut launcher = troupe_tests::launch(&ns, &cfg, &[]);
    let endpoint = launcher.endpoint("troupe launch: router listening on");
    let client = Client::with_session(troupe_tests::client_at(&endpoint, &ns), 6665);
    // The laser comes from rangertolaser, started once Stage's ranger:1 is live.
    let sim = SimulationProxy::new(&client, 0);
    let pp = Position2dProxy::new(&client, 0).unwrap();
    let lp = LaserProxy::new(&client, 0).unwrap();
    let deadline = Instant::now() + DEADLINE;
    while lp.count() != 180 {
        assert!(
            Instant::now() < deadline,
            "no 180-beam laser from simple.cfg"
        );
        let _ = client.read_timeout(DEADLINE);
    }
    // Stop r0's wander controller and face it into the cave's south-west corner.
    pp.set_speed(0.0, 0.0).unwrap();
    sim.set_pose2d("r0", -6.5, -6.5, -3.0 * std::f64::consts::FRAC_PI_4)
        .unwrap();
    let at = sim.get_pose2d("r0").unwrap();
    assert!(
        (at.x + 6.5).abs() < 0.5 && (at.y + 6.5).abs() < 0.5,
        "{at:?}"
    );
    let ahead = |lp: &LaserProxy| lp.range(90).unwrap_or(0.0);
    let deadline = Instant::now() + DEADLINE;
    while !(0.5..3.0).contains(&ahead(&lp)) {
        assert!(
            Instant::now() < deadline,
            "no wall ahead of r0: {} m",
            ahead(&lp)
        );
        client.read().unwrap();
    }
    let first = ahead(&lp);
    pp.set_speed(0.3, 0.0).unwrap();
    let deadline = Instant::now() + DEADLINE;
    while ahead(&lp) > first - 0.3 {
        assert!(
            Instant::now() < deadline,
            "the wall never came closer than {} m",
            ahead(&lp)
        );
        client.read().unwrap();
    }
    assert!(pp.x_speed() > 0.0, "r0 reports its speed");
    pp.set_speed(0.0, 0.0).unwrap();
    assert!(launcher.terminate().success(), "{}", launcher.stderr());
}

/// Stage's simulation requests in 3D, through the bridge with Player's
/// XDR: GET_POSE3D gives x, y, z, yaw and the simulation time in
/// microseconds; SET_POSE3D moves a model; a heading is wrapped as Stage
/// wraps it (7.0 reads back 7 - 2π).
#[test]
fn simulation_pose3d_requests_answer_as_stage_s_and_headings_wrap() {
    use crate::player::{Player, RESP_ACK};
    let cfg = Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds/simple.cfg");
    let ns = troupe_tests::unique_namespace("pose3d");
    let mut launcher = troupe_tests::launch(&ns, &cfg, &[]);
    let (_, addr) = troupe_tests::launch_ports(&mut launcher);
    let mut player = Player::connect(addr, 6665);
    let sim = troupe_msgs::Device::new(6665, troupe_msgs::Interface::Simulation, 0);
    player.open(sim);
    // name (count, then XDR bytes of "r0\0"), a pose3d and a simtime.
    let body = |pose: [f64; 6]| {
        let mut b = Vec::new();
        b.extend_from_slice(&3u32.to_be_bytes());
        b.extend_from_slice(&3u32.to_be_bytes());
        b.extend_from_slice(b"r0\0\0");
        for v in pose {
            b.extend_from_slice(&v.to_be_bytes());
        }
        b.extend_from_slice(&0f64.to_be_bytes());
        b
    };
    let r = player.request(sim, 4, &body([1.0, 2.0, 0.0, 0.0, 0.0, 7.0]));
    assert_eq!(r.kind(), RESP_ACK, "SET_POSE3D: {r:?}");
    // Once r0's odometry says the simulation has run a while.
    let pos = troupe_msgs::Device::new(6665, troupe_msgs::Interface::Position2d, 0);
    player.open(pos);
    let ran = loop {
        let m = player.recv();
        if m.kind() == crate::player::DATA && m.timestamp >= 0.2 {
            break m.timestamp;
        }
    };
    let r = player.request(sim, 3, &body([0.0; 6]));
    assert_eq!(r.kind(), RESP_ACK, "GET_POSE3D: {r:?}");
    // After the name (12 bytes): x y z roll pitch yaw, then simtime.
    let f = |i: usize| f64::from_be_bytes(r.body[12 + 8 * i..20 + 8 * i].try_into().unwrap());
    assert_eq!((f(0), f(1), f(2)), (1.0, 2.0, 0.0));
    assert!(
        (f(5) - (7.0 - std::f64::consts::TAU)).abs() < 1e-9,
        "yaw {}",
        f(5)
    );
    assert!(
        f(6) >= (ran * 1e6).round() && f(6).fract() == 0.0,
        "simtime {} µs after data at {ran} s",
        f(6)
    );
    assert!(launcher.terminate().success(), "{}", launcher.stderr());
}

/// Stage's fiducial ID requests on everything.cfg's robot1, through the
/// bridge: GET_ID gives the finder's model's `fiducial_return`, SET_ID
/// changes it and answers with the new ID.
#[test]
fn fiducial_ids_are_read_and_set_as_stage_does() {
    use crate::player::{Player, RESP_ACK};
    let Some(cfg) = troupe_tests::compat("stage/everything.cfg") else {
        return;
    };
    let ns = troupe_tests::unique_namespace("fidid");
    let mut launcher = troupe_tests::launch(&ns, &cfg, &[]);
    let (_, addr) = troupe_tests::launch_ports(&mut launcher);
    let mut player = Player::connect(addr, 6665);
    let fid = troupe_msgs::Device::new(6665, troupe_msgs::Interface::Fiducial, 0);
    player.open(fid);
    let id = |r: &crate::player::Frame| u32::from_be_bytes(r.body[..4].try_into().unwrap());
    let r = player.request(fid, 7, &[]);
    assert_eq!(r.kind(), RESP_ACK, "GET_ID: {r:?}");
    let before = id(&r);
    let r = player.request(fid, 8, &42u32.to_be_bytes());
    assert_eq!((r.kind(), id(&r)), (RESP_ACK, 42), "SET_ID: {r:?}");
    let r = player.request(fid, 7, &[]);
    assert_eq!(id(&r), 42, "GET_ID after SET_ID (was {before})");
    assert!(launcher.terminate().success(), "{}", launcher.stderr());
}

/// PULL mode as Player's Stage serves it (issue 32, item 1): a read (REQ
/// DATA … SYNCH) is one moment of the simulation. From the second read
/// after the opening on (as Player's), each read carries every one of them — Stage's
/// position2d and two rangers, and the laser rangertolaser derives in its
/// own process — and reads are paced by the simulation: each brings a
/// newer step than the last.
#[test]
fn a_pull_read_carries_every_subscribed_device_at_one_step() {
    use crate::player::{Player, DATA, RESP_ACK, SYNCH};
    use troupe_msgs::{Device, Interface};
    let cfg = Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds/simple.cfg");
    let ns = troupe_tests::unique_namespace("pull");
    // The bridge says which rounds went without what: a failure shows it.
    let mut launcher = troupe_tests::launch(&ns, &cfg, &["--log", "info,troupe_bridge=debug"]);
    let (_, addr) = troupe_tests::launch_ports(&mut launcher);
    let mut player = Player::connect(addr, 6665);
    // PLAYER_PLAYER_REQ_DATAMODE, PLAYER_DATAMODE_PULL.
    player.send(1, 0, 3, 5, &2u32.to_be_bytes());
    assert_eq!(player.reply().kind(), RESP_ACK);
    let devices = [
        Device::new(6665, Interface::Position2d, 0),
        Device::new(6665, Interface::Ranger, 0),
        Device::new(6665, Interface::Ranger, 1),
        Device::new(6665, Interface::Laser, 0),
    ];
    let code = |d: &Device| (u32::from(d.interface.code()), d.index);
    for d in devices {
        player.open(d);
    }
    // One libplayerc Read(): the devices it brought, and position2d's stamp.
    let mut read = || {
        player.send(1, 0, 3, 4, &[]);
        let mut got = Vec::new();
        let mut stamp = None;
        loop {
            let m = player.recv();
            match m.kind() {
                SYNCH => return (got, stamp),
                DATA => {
                    got.push((m.h[2], m.h[3]));
                    if m.h[2] == 4 {
                        stamp = Some(m.timestamp);
                    }
                }
                _ => {}
            }
        }
    };
    let carries_all = |got: &[(u32, u32)]| devices.iter().all(|d| got.contains(&code(d)));
    // Player's rounds carry every opened device from the second read on
    // (issue 46, item 1): the bridge knows what is due from the opening.
    let mut first = 0;
    let mut last = loop {
        let (got, stamp) = read();
        first += 1;
        assert!(
            first <= 2,
            "read {first} carried only {got:?}\n{}",
            launcher.stderr()
        );
        if carries_all(&got) {
            break stamp.expect("position2d data");
        }
    };
    let t = Instant::now();
    let n = 30;
    for i in 0..n {
        let (got, stamp) = read();
        assert!(
            carries_all(&got),
            "read {i} after the first whole one brought {got:?}\n{}",
            launcher.stderr()
        );
        let stamp = stamp.expect("position2d data");
        assert!(
            stamp > last,
            "read {i} at {stamp} s did not bring a newer step than {last} s"
        );
        last = stamp;
    }
    eprintln!(
        "pull: {n} reads of four devices each in {:.2} s after {first} to fill",
        t.elapsed().as_secs_f64()
    );
    assert!(launcher.terminate().success(), "{}", launcher.stderr());
}

/// Stage's gripper through the bridge (issue 32, item 8), on everything.cfg's
/// robot1: after CLOSE the paddles report MOVING while they travel, a
/// twentieth of the way each 100 ms of simulated time, then CLOSED; the
/// beams are Stage's plugin's bits (0x04, 0x08) and nothing is ever
/// counted as stored.
#[test]
fn the_gripper_moves_its_paddles_in_stage_s_time() {
    use crate::player::{Player, DATA};
    let Some(cfg) = troupe_tests::compat("stage/everything.cfg") else {
        return;
    };
    let ns = troupe_tests::unique_namespace("gripper");
    let mut launcher = troupe_tests::launch(&ns, &cfg, &[]);
    let (_, addr) = troupe_tests::launch_ports(&mut launcher);
    let mut player = Player::connect(addr, 6665);
    let gripper = troupe_msgs::Device::new(6665, troupe_msgs::Interface::Gripper, 0);
    player.open(gripper);
    // state, beams, stored: three XDR words.
    let next = |player: &mut Player| loop {
        let m = player.recv();
        if m.kind() == DATA && m.h[2] == 3 {
            let w = |i: usize| u32::from_be_bytes(m.body[4 * i..4 * i + 4].try_into().unwrap());
            return (m.timestamp, w(0), w(1), w(2));
        }
    };
    let (_, state, _, _) = next(&mut player);
    assert_eq!(state, 1, "open at the start");
    // PLAYER_GRIPPER_CMD_CLOSE.
    player.send(3, 0, 2, 2, &[]);
    let mut seen = Vec::new();
    let closed = loop {
        let d = next(&mut player);
        assert_eq!(d.3, 0, "stored, as Stage's plugin: {d:?}");
        assert_eq!(d.2 & !0x0c, 0, "beams are 0x04 and 0x08: {d:?}");
        seen.push(d);
        if d.1 == 2 {
            break d;
        }
        assert!(
            seen.len() < 400,
            "never closed: {:?}",
            &seen[seen.len() - 3..]
        );
    };
    let moving: Vec<f64> = seen.iter().filter(|d| d.1 == 3).map(|d| d.0).collect();
    let first = moving
        .first()
        .copied()
        .expect("MOVING while the paddles travel");
    let travel = closed.0 - first;
    eprintln!(
        "gripper: MOVING for {travel:.1} simulated s, then CLOSED, beams {:#04x}",
        closed.2
    );
    // Twenty updates, 100 ms each, with nothing between the paddles; fewer
    // when they close on something.
    assert!(travel > 0.3 && travel < 2.25, "MOVING for {travel} s");
    if closed.2 == 0 {
        assert!(travel > 1.75, "closed on nothing in {travel} s");
    }
    assert!(launcher.terminate().success(), "{}", launcher.stderr());
}

/// Issue 32, item 5: with `stage_quirks 1`, r0's laser in Stage's
/// simple_noctrl world reads through the bridge as real Stage's did (the
/// first laser:0 scan of the c-pull-position-laser transcript): every beam,
/// those that meet the cave or nothing and the four on r1's laser (a
/// moving body, drawn into Stage's raster as Stage draws it), to 0.1 mm
/// (issue 46, item 7).
#[test]
fn with_stage_quirks_the_laser_reads_as_real_stage_s() {
    use crate::player::{Player, DATA};
    use troupe_msgs::{Device, Interface};
    let (Some(transcript), Some(world)) = (
        troupe_tests::compat("player-tcp/c-pull-position-laser/messages.jsonl"),
        troupe_tests::compat("stage/simple_noctrl.world"),
    ) else {
        return;
    };
    let text = std::fs::read_to_string(&transcript).unwrap();
    let line = text
        .lines()
        .find(|l| {
            l.contains(r#""dir":"s2c""#)
                && l.contains(r#""interf":6,"#)
                && l.contains(r#""type":1,"#)
        })
        .unwrap();
    let list = line.split(r#""ranges":["#).nth(1).unwrap();
    let stage: Vec<f32> = list[..list.find(']').unwrap()]
        .split(',')
        .map(|v| v.trim().parse().unwrap())
        .collect();
    // The transcript's cfg, with the world's path spelled out and Stage's ways on.
    let dir = std::env::temp_dir().join(format!("troupe-quirks-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cfg = dir.join("simple_noctrl_quirks.cfg");
    std::fs::write(
        &cfg,
        format!(
            "driver ( name \"stage\" provides [ \"simulation:0\" ] plugin \"stageplugin\" \
             worldfile \"{}\" usegui 0 stage_quirks 1 )\n\
             driver ( name \"stage\" provides [ \"position2d:0\" \"ranger:0\" \"ranger:1\" ] model \"r0\" )\n\
             driver ( name \"rangertolaser\" provides [ \"laser:0\" ] requires [ \"ranger:1\" ] )\n",
            world.display()
        ),
    )
    .unwrap();
    let ns = troupe_tests::unique_namespace("quirks");
    let mut launcher = troupe_tests::launch(&ns, &cfg, &[]);
    let (_, addr) = troupe_tests::launch_ports(&mut launcher);
    let mut player = Player::connect(addr, 6665);
    player.open(Device::new(6665, Interface::Laser, 0));
    // PLAYER_LASER_DATA_SCAN: min, max, resolution, max range, then the
    // ranges and the intensities (each a count and an XDR array). As
    // Player's, rangertolaser sends a scan for each of the ranger's two
    // messages, the first without intensities: the one with them.
    let word_of = |b: &[u8], i: usize| u32::from_be_bytes(b[i * 4..i * 4 + 4].try_into().unwrap());
    let scan = loop {
        let m = player.recv();
        if m.kind() == DATA && m.h[2] == 6 && m.h[5] == 1 {
            let n = word_of(&m.body, 4) as usize;
            if word_of(&m.body, 6 + n) as usize == n {
                break m.body;
            }
        }
    };
    let word = |i: usize| word_of(&scan, i);
    let n = word(4) as usize;
    assert_eq!(n, 180);
    let ours: Vec<f32> = (0..n).map(|k| f32::from_bits(word(6 + k))).collect();
    // (uint8 intensities: an XDR opaque, a byte each.)
    let intensity = &scan[(6 + n + 2) * 4..][..n];
    let on_r1: Vec<usize> = (0..n).filter(|&k| intensity[k] == 1).collect();
    assert_eq!(on_r1, [43, 44, 45, 46]);
    for k in 0..n {
        let off = (ours[k] - stage[k]).abs();
        assert!(
            off < 1e-4,
            "beam {k}: {} m, real Stage {} m",
            ours[k],
            stage[k]
        );
    }
    assert!(launcher.terminate().success(), "{}", launcher.stderr());
    let _ = std::fs::remove_dir_all(&dir);
}

/// `troupe bench stage --world FILE` runs one world as written and prints
/// its row: how long it took and its peak memory; a file that is not
/// there is named in the error.
#[test]
fn bench_stage_runs_one_world_file_and_prints_its_row() {
    let world = Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds/simple.world");
    let bench = |world: &str| {
        troupe_tests::troupe_output(&troupe_tests::strings(&[
            "bench",
            "stage",
            "--seconds",
            "2",
            "--world",
            world,
        ]))
    };
    let (status, text, err) = bench(world.to_str().unwrap());
    assert!(status.success(), "{text}{err}");
    let row = text
        .lines()
        .find(|l| l.contains("simple.world"))
        .unwrap_or("");
    for part in [
        "x real time",
        "MB peak",
        "MB data",
        "2 simulated s in",
        "moving at the end",
    ] {
        assert!(row.contains(part), "no {part:?} in {text:?}");
    }
    let (status, _, err) = bench("no/such.world");
    assert!(!status.success() && err.contains("no/such.world"), "{err}");
}

/// `troupe bench stage --world FILE --stage BIN` runs Stage on a copy of
/// the world set to run flat out for the bench's seconds, in turn with
/// Troupe, prints both and their ratio, and removes the copy; a Stage that
/// fails is named, with what it said. (A stand-in plays Stage: it checks
/// the copy it is given.)
#[test]
fn bench_stage_runs_stage_in_turn_and_prints_the_ratio() {
    use std::os::unix::fs::PermissionsExt;
    let dir = std::env::temp_dir().join(troupe_tests::unique_namespace("vs-stage"));
    std::fs::create_dir_all(&dir).unwrap();
    let world = dir.join("tiny.world");
    std::fs::write(
        &world,
        "paused 1\nspeedup 1\ndefine bot position ( size [0.4 0.4 0.2] drive \"diff\" )\n\
         bot ( name \"r0\" pose [0 0 0 0] )\n",
    )
    .unwrap();
    let fake = |name: &str, body: &str| {
        let path = dir.join(name);
        std::fs::write(&path, format!("#!/bin/sh\n{body}\n")).unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
        path
    };
    let good = fake(
        "stage",
        r#"[ "$1" = -g ] && grep -qx 'quit_time 2' "$2" && grep -qx 'threads 1' "$2" \
  && grep -qx 'speedup -1' "$2" && grep -qx 'paused 0' "$2" && ! grep -qx 'paused 1' "$2" \
  || { echo "not set up: $2" >&2; exit 3; }"#,
    );
    let bad = fake("broken-stage", "echo 'libtool error #2' >&2; exit 255");
    let bench = |stage: &std::path::Path| {
        troupe_tests::troupe_output(&troupe_tests::strings(&[
            "bench",
            "stage",
            "--seconds",
            "2",
            "--pairs",
            "2",
            "--world",
            world.to_str().unwrap(),
            "--stage",
            stage.to_str().unwrap(),
        ]))
    };
    let (status, text, err) = bench(&good);
    assert!(status.success(), "{text}{err}");
    let row = text.lines().find(|l| l.contains("vs Stage:")).unwrap_or("");
    for part in [
        "Stage ",
        "MB peak; Troupe ",
        "x as fast",
        "pair by pair",
        "2 pairs",
    ] {
        assert!(row.contains(part), "no {part:?} in {text:?}");
    }
    assert!(text.contains("2 simulated s in"), "Troupe's row: {text:?}");
    let (status, _, err) = bench(&bad);
    assert!(
        !status.success() && err.contains("broken-stage") && err.contains("libtool error #2"),
        "{err}"
    );
    let left: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(".troupe-bench"))
        .collect();
    assert!(left.is_empty(), "copies left behind: {left:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// What Player and Stage's plugin refuse is refused (issue 46, items 4 and 11): position2d's
/// VELOCITY_MODE (POSITION_MODE it acknowledges and ignores), and a
/// property asked with a buffer that cannot hold it. The simulation's
/// `time` property is Stage's uint64 of microseconds (item 9).
#[test]
fn stage_refuses_what_its_plugin_refuses_and_tells_time_in_microseconds() {
    use crate::player::{push_bytes, Player, DATA, RESP_ACK, RESP_NACK};
    use troupe_msgs::{Device, Interface};
    let cfg = Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds/simple.cfg");
    let ns = troupe_tests::unique_namespace("refusals");
    let mut launcher = troupe_tests::launch(&ns, &cfg, &[]);
    let (_, addr) = troupe_tests::launch_ports(&mut launcher);
    let mut player = Player::connect(addr, 6665);
    let pos = Device::new(6665, Interface::Position2d, 0);
    let sim = Device::new(6665, Interface::Simulation, 0);
    player.open(pos);
    player.open(sim);
    // A request to a driver no client opened a device of (rangertolaser's
    // laser) goes unanswered, as Player leaves it in the queue of a driver
    // it has not set up (item 4): the next answer is the one for the
    // opened position2d.
    let laser = Device::new(6665, Interface::Laser, 0);
    player.send(u32::from(laser.interface.code()), 0, 3, 1, &[]);
    let r = player.request(pos, 1, &[]);
    assert_eq!(r.kind(), RESP_ACK, "GET_GEOM: {r:?}");
    let r = player.request(pos, 3, &1u32.to_be_bytes());
    assert_eq!(r.kind(), RESP_NACK, "VELOCITY_MODE: {r:?}");
    let r = player.request(pos, 4, &0u32.to_be_bytes());
    assert_eq!(r.kind(), RESP_ACK, "POSITION_MODE: {r:?}");

    // Once r0's odometry says the simulation has run a while.
    let ran = loop {
        let m = player.recv();
        if m.kind() == DATA && m.timestamp >= 0.2 {
            break m.timestamp;
        }
    };
    // GET_PROPERTY: r0's "time", into a buffer of `size` bytes.
    let mut ask = |prop: &str, size: usize| {
        let mut b = Vec::new();
        push_bytes(&mut b, b"r0\0");
        push_bytes(&mut b, format!("{prop}\0").as_bytes());
        b.extend_from_slice(&0u32.to_be_bytes());
        push_bytes(&mut b, &vec![0; size]);
        player.request(sim, 5, &b)
    };
    let r = ask("time", 8);
    assert_eq!(r.kind(), RESP_ACK, "GET_PROPERTY time: {r:?}");
    // After "r0" (12 bytes), "time" (16) and the index (4): the value's
    // two counts, then the uint64 in the server's byte order.
    assert_eq!(&r.body[32..40], &[0, 0, 0, 8, 0, 0, 0, 8], "{r:?}");
    let usec = u64::from_le_bytes(r.body[40..48].try_into().unwrap());
    assert!(
        usec as f64 >= (ran * 1e6).round() && usec < 3_600_000_000,
        "time {usec} µs after data at {ran} s"
    );
    for (prop, size) in [("time", 4), ("time", 16), ("color", 8)] {
        let r = ask(prop, size);
        assert_eq!(r.kind(), RESP_NACK, "{prop} into {size} bytes: {r:?}");
    }
    assert_eq!(ask("color", 16).kind(), RESP_ACK);
    assert!(launcher.terminate().success(), "{}", launcher.stderr());
}

/// vfh passes its base's odometry through from the start (issue 46, item
/// 3): a PULL client of Stage's vfh.cfg that opens vfh's position2d gets r0's
/// odometry in its first read, not nothing or `0 0 0`.
#[test]
fn vfh_passes_its_base_s_odometry_through_from_the_first_read() {
    use crate::player::{Player, DATA, RESP_ACK, SYNCH};
    use troupe_msgs::{Device, Interface};
    use troupe_node::zenoh::Wait;
    let Some(cfg) = troupe_tests::compat("stage/vfh.cfg") else {
        return;
    };
    let ns = troupe_tests::unique_namespace("vfh-odom");
    let mut launcher = troupe_tests::launch(&ns, &cfg, &[]);
    let (router, addr) = troupe_tests::launch_ports(&mut launcher);
    // A client that comes once the stack is up: vfh has published.
    let session = troupe_tests::client_at(&router, &ns);
    let vfh = Device::new(6665, Interface::Position2d, 1);
    let sub = session
        .declare_subscriber(troupe_msgs::keys::data(&vfh))
        .wait()
        .unwrap();
    sub.recv_timeout(troupe_tests::DEADLINE)
        .unwrap()
        .expect("vfh's data");
    let mut player = Player::connect(addr, 6665);
    player.send(1, 0, 3, 5, &2u32.to_be_bytes());
    assert_eq!(player.reply().kind(), RESP_ACK);
    player.open(Device::new(6665, Interface::Position2d, 1));
    player.open(Device::new(6665, Interface::Position2d, 0));
    player.send(1, 0, 3, 4, &[]);
    // What the client's proxies hold after its first read: the data that
    // came with the answers to its opens, and the read's.
    let mut got = std::mem::take(&mut player.seen);
    loop {
        let m = player.recv();
        match m.kind() {
            SYNCH => break,
            DATA => got.push(m),
            _ => {}
        }
    }
    let mut poses = std::collections::BTreeMap::new();
    for m in got.iter().filter(|m| m.h[2] == 4) {
        poses.insert(m.h[3], (m.f64_at(0), m.f64_at(8)));
    }
    let (Some(vfh), Some(base)) = (poses.get(&1), poses.get(&0)) else {
        panic!("after the first read the client has {poses:?}");
    };
    assert!(vfh.0.hypot(vfh.1) > 1.0, "vfh says r0 is at {vfh:?}");
    assert!(
        (vfh.0 - base.0).hypot(vfh.1 - base.1) < 0.5,
        "vfh {vfh:?}, base {base:?}"
    );
    assert!(launcher.terminate().success(), "{}", launcher.stderr());
}

/// At a world's `quit_time` Player's Stage plugin stops the clock and
/// Player serves on (issue 46, item 6): a client that connects afterwards
/// subscribes to simulation:0 and is answered, and the odometry it gets
/// is the last step's.
#[test]
fn after_quit_time_the_clock_stops_and_the_devices_are_still_served() {
    use crate::player::{push_bytes, Player, DATA, RESP_ACK};
    use troupe_msgs::{Device, Interface};
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let dir = std::env::temp_dir().join(troupe_tests::unique_namespace("quit"));
    std::fs::create_dir_all(&dir).unwrap();
    let world = root.join("worlds/simple.world").canonicalize().unwrap();
    let cfg = dir.join("quit.cfg");
    std::fs::write(
        &cfg,
        format!(
            "driver ( name \"stage\" provides [\"simulation:0\"] plugin \"stageplugin\" worldfile \"{}\" quit_time 1 )\n\
             driver ( name \"stage\" provides [\"position2d:0\"] model \"r0\" )\n",
            world.display()
        ),
    )
    .unwrap();
    let ns = troupe_tests::unique_namespace("quit");
    let mut launcher = troupe_tests::launch(&ns, &cfg, &[]);
    let (_, addr) = troupe_tests::launch_ports(&mut launcher);
    let pos = Device::new(6665, Interface::Position2d, 0);
    let sim = Device::new(6665, Interface::Simulation, 0);
    let mut first = Player::connect(addr, 6665);
    first.open(pos);
    loop {
        let m = first.recv();
        if m.kind() == DATA && m.timestamp >= 1.0 - 1e-6 {
            break;
        }
    }

    let mut late = Player::connect(addr, 6665);
    late.open(sim);
    let mut body = Vec::new();
    push_bytes(&mut body, b"r0\0");
    body.extend_from_slice(&[0; 24]);
    let r = late.request(sim, 1, &body);
    assert_eq!(r.kind(), RESP_ACK, "GET_POSE2D after quit_time: {r:?}");
    late.open(pos);
    let m = late.recv();
    assert_eq!((m.kind(), m.h[2]), (DATA, 4), "{m:?}");
    assert!(
        (m.timestamp - 1.0).abs() < 1e-6,
        "odometry at {} s",
        m.timestamp
    );
    assert!(
        matches!(launcher.child.try_wait(), Ok(None)),
        "the stack stopped at quit_time"
    );
    assert!(launcher.terminate().success(), "{}", launcher.stderr());
    let _ = std::fs::remove_dir_all(&dir);
}

/// A position command is driven by Stage's own position controller (issue
/// 46, item 10): r0 ends within Stage's 2 cm of the goal point, facing the
/// goal's heading to a milliradian, as Player's Stage leaves it.
#[test]
fn a_position_command_stops_where_stage_s_controller_stops() {
    use crate::player::{Player, DATA};
    use troupe_msgs::{Device, Interface};
    let cfg = Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds/simple.cfg");
    let ns = troupe_tests::unique_namespace("goto");
    let mut launcher = troupe_tests::launch(&ns, &cfg, &["--speedup", "4"]);
    let (_, addr) = troupe_tests::launch_ports(&mut launcher);
    let mut player = Player::connect(addr, 6665);
    let pos = Device::new(6665, Interface::Position2d, 0);
    player.open(pos);
    // The goal, in odometry's frame: 0.7 m ahead and 0.7 m to the left of
    // where r0 starts (it faces 45°, into the open room), facing 0.5 rad.
    let start = loop {
        let m = player.recv();
        if m.kind() == DATA && m.h[2] == 4 {
            break [m.f64_at(0), m.f64_at(8)];
        }
    };
    let goal = [start[0] + 0.7, start[1] + 0.7, 0.5];
    // PLAYER_POSITION2D_CMD_POS: the goal, a velocity, the state.
    let mut body = Vec::new();
    for v in goal.iter().chain(&[0.0; 3]) {
        body.extend_from_slice(&f64::to_be_bytes(*v));
    }
    body.extend_from_slice(&1u32.to_be_bytes());
    player.send(4, 0, 2, 2, &body);
    let deadline = Instant::now() + DEADLINE;
    loop {
        let m = player.recv();
        if m.kind() != DATA || m.h[2] != 4 {
            continue;
        }
        let last = [m.f64_at(0), m.f64_at(8), m.f64_at(16)];
        let d = last[2] - goal[2];
        let yaw_err = d.sin().atan2(d.cos()).abs();
        if (last[0] - goal[0]).abs() < 0.02 && (last[1] - goal[1]).abs() < 0.02 && yaw_err < 1e-3 {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "r0 stopped at {last:?}, short of {goal:?}"
        );
    }
    assert!(launcher.terminate().success(), "{}", launcher.stderr());
}

/// Stage's camera through the bridge (issue 46, item 13): camera.cfg from
/// Stage's own samples serves r0's camera as Stage's plugin does, 100 x 100
/// RGB888 uncompressed, top row first, every 100 ms of simulated time: the
/// cave's floor along the bottom row, Stage's background along the top.
#[test]
fn stage_s_camera_cfg_serves_r0_s_camera_as_player_does() {
    use crate::player::{Player, DATA};
    use troupe_msgs::{Device, Interface};
    let Some(cfg) = troupe_tests::compat("stage/camera.cfg") else {
        return;
    };
    let ns = troupe_tests::unique_namespace("camera");
    let mut launcher = troupe_tests::launch(&ns, &cfg, &[]);
    let (_, addr) = troupe_tests::launch_ports(&mut launcher);
    let mut player = Player::connect(addr, 6665);
    let cam = Device::new(6665, Interface::Camera, 0);
    player.open(cam);
    let mut stamps = Vec::new();
    let mut last = None;
    while stamps.len() < 3 {
        let m = player.recv();
        if m.sig() == (40, 0, DATA, 1) {
            stamps.push(m.timestamp);
            last = Some(m);
        }
    }
    let m = last.unwrap();
    // width height bpp format fdiv compression image_count, the bytes' count.
    let head: Vec<u32> = (0..8).map(|i| m.u32_at(4 * i)).collect();
    assert_eq!(head, [100, 100, 24, 5, 0, 0, 30_000, 30_000]);
    let px = |col: usize, row: usize| {
        let i = 32 + (row * 100 + col) * 3;
        [m.body[i], m.body[i + 1], m.body[i + 2]]
    };
    assert_eq!(px(50, 99), [255, 255, 255], "the floor");
    assert_eq!(px(50, 0), [179, 179, 204], "Stage's background");
    for w in stamps.windows(2) {
        assert!((w[1] - w[0] - 0.1).abs() < 1e-6, "{stamps:?}");
    }
    assert!(launcher.terminate().success(), "{}", launcher.stderr());
}

/// Player's dummy.cfg (issue 46, item 13): its camera through
/// `cameracompress` reaches a client as a JPEG of the dummy's 320 x 240
/// grey image, and its `wsn` device serves Player's fixed packet.
#[test]
fn dummy_cfg_s_compressed_camera_and_wsn_reach_a_player_client() {
    use crate::player::{Player, DATA};
    use troupe_msgs::{Device, Interface};
    let Some(cfg) = troupe_tests::compat("player-cfg/dummy.cfg") else {
        return;
    };
    let ns = troupe_tests::unique_namespace("dummycfg");
    let mut launcher = troupe_tests::launch(&ns, &cfg, &[]);
    let (_, addr) = troupe_tests::launch_ports(&mut launcher);
    let mut player = Player::connect(addr, 6665);
    player.open(Device::new(6665, Interface::Camera, 1));
    let m = loop {
        let m = player.recv();
        if m.sig() == (40, 1, DATA, 1) {
            break m;
        }
    };
    let head: Vec<u32> = (0..7).map(|i| m.u32_at(4 * i)).collect();
    assert_eq!(&head[..6], [320, 240, 24, 5, 0, 1], "a JPEG, RGB888");
    let n = head[6] as usize;
    assert_eq!(m.u32_at(28) as usize, n);
    let img = image::load_from_memory_with_format(&m.body[32..32 + n], image::ImageFormat::Jpeg)
        .unwrap()
        .to_rgb8();
    assert_eq!(img.dimensions(), (320, 240));
    let grey = img.get_pixel(160, 120).0;
    assert!(
        img.pixels().all(|p| p.0 == grey),
        "one grey all over, as the dummy sends"
    );
    player.open(Device::new(6665, Interface::Wsn, 0));
    let m = loop {
        let m = player.recv();
        if m.sig() == (57, 0, DATA, 1) {
            break m;
        }
    };
    assert_eq!((m.u32_at(0), m.u32_at(4), m.u32_at(8)), (132, 1, 125));
    let f = |i: usize| f32::from_be_bytes(m.body[12 + 4 * i..16 + 4 * i].try_into().unwrap());
    assert_eq!((f(0), f(9)), (779.0, 489.0), "light and battery");
    assert!(launcher.terminate().success(), "{}", launcher.stderr());
}
