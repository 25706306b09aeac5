//! The bridge's own suite: fake devices of every interface on Zenoh, the
//! bridge in this process, and a Player client written here in raw XDR (not
//! Troupe's client API). Data, commands and requests of each interface, many
//! clients with one stuck, and malformed input closing only its connection.

use std::io::{Read, Write};
use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::time::{Duration, Instant};

use troupe_bridge::{Bridge, Config, Limits, Port};
use troupe_msgs::codec::{decode, encode, split};
use troupe_msgs::*;
use troupe_node::zenoh::{Session, Wait};
use troupe_tests::{TestNet, DEADLINE};

use crate::player::{Frame, Player};

const ROBOT: u32 = 6665;

/// Every fake device and the sample it publishes.
fn samples() -> Vec<(Device, Vec<u8>)> {
    let d = |i, n| Device::new(ROBOT, i, n);
    let p = Pose2d::new(1.0, 2.0, 0.5);
    vec![
        (
            d(Interface::Position2d, 0),
            encode(
                &position2d::Data {
                    pose: p,
                    vel: p,
                    stall: true,
                },
                1.0,
            ),
        ),
        (
            d(Interface::Laser, 0),
            encode(
                &laser::Scan {
                    min_angle: -1.0,
                    max_angle: 1.0,
                    resolution: 0.5,
                    max_range: 8.0,
                    ranges: vec![1.0; 5],
                    intensity: vec![1; 5],
                    id: 7,
                },
                1.0,
            ),
        ),
        (
            d(Interface::Ranger, 0),
            encode(
                &ranger::Ranges {
                    ranges: vec![2.0; 3],
                },
                1.0,
            ),
        ),
        (
            d(Interface::Sonar, 0),
            encode(
                &sonar::Ranges {
                    ranges: vec![2.0; 16],
                },
                1.0,
            ),
        ),
        (
            d(Interface::Power, 0),
            encode(
                &power::Data {
                    valid: 1,
                    volts: 12.5,
                    ..Default::default()
                },
                1.0,
            ),
        ),
        (
            d(Interface::Bumper, 0),
            encode(
                &bumper::Data {
                    bumpers: vec![true, false, true],
                },
                1.0,
            ),
        ),
        (
            d(Interface::Ir, 0),
            encode(
                &ir::Data {
                    voltages: vec![1.0; 2],
                    ranges: vec![0.5; 2],
                },
                1.0,
            ),
        ),
        (
            d(Interface::Aio, 0),
            encode(
                &aio::Data {
                    voltages: vec![3.3; 4],
                },
                1.0,
            ),
        ),
        (
            d(Interface::Dio, 0),
            encode(
                &dio::Data {
                    count: 8,
                    bits: 0xa5,
                },
                1.0,
            ),
        ),
        (
            d(Interface::Ptz, 0),
            encode(
                &ptz::Data {
                    pan: 0.5,
                    ..Default::default()
                },
                1.0,
            ),
        ),
        (
            d(Interface::Planner, 0),
            encode(
                &planner::State {
                    valid: true,
                    waypoints_count: 2,
                    ..Default::default()
                },
                1.0,
            ),
        ),
        (
            d(Interface::Localize, 0),
            encode(
                &localize::Hypoths {
                    hypoths: vec![localize::Hypoth {
                        mean: p,
                        cov: [0.1; 6],
                        weight: 1.0,
                    }],
                    ..Default::default()
                },
                1.0,
            ),
        ),
        (
            d(Interface::Gripper, 0),
            encode(
                &gripper::Data {
                    state: gripper::State::Closed,
                    beams: 3,
                    stored: 0,
                },
                1.0,
            ),
        ),
        (
            d(Interface::Blobfinder, 0),
            encode(
                &blobfinder::Data {
                    width: 80,
                    height: 60,
                    blobs: vec![Default::default(); 2],
                },
                1.0,
            ),
        ),
        (
            d(Interface::Fiducial, 0),
            encode(
                &fiducial::Data {
                    fiducials: vec![Default::default(); 3],
                },
                1.0,
            ),
        ),
        (
            d(Interface::Map, 0),
            encode(
                &map::Info {
                    width: 3,
                    height: 2,
                    resolution: 0.5,
                    origin: p,
                },
                1.0,
            ),
        ),
    ]
}

/// Player's DATA subtype and body length for each sample above.
fn expected_data(i: Interface) -> (u32, usize) {
    match i {
        Interface::Position2d => (1, 52),
        Interface::Laser => (1, 16 + 8 + 20 + 4 + 4 + 8 + 4),
        Interface::Ranger => (1, 8 + 24),
        Interface::Sonar => (1, 8 + 64),
        Interface::Power => (1, 24),
        Interface::Bumper => (1, 8 + 4),
        Interface::Ir => (1, 8 + 8 + 8 + 8),
        Interface::Aio => (1, 8 + 16),
        Interface::Dio => (1, 8),
        Interface::Ptz => (1, 24),
        Interface::Planner => (1, 88),
        Interface::Localize => (1, 4 + 8 + 8 + 80),
        Interface::Gripper => (1, 12),
        Interface::Blobfinder => (1, 16 + 80),
        Interface::Fiducial => (1, 8 + 300),
        Interface::Map => (1, 36),
        other => panic!("no expectation for {other}"),
    }
}

/// Answers every request like a driver would.
fn answer(name: &str, payload: &[u8]) -> Result<Vec<u8>, Vec<u8>> {
    let nack = |r: &str| Err(encode(&common::Nack { reason: r.into() }, 0.0));
    let p = Pose2d::new(1.0, 2.0, 0.5);
    Ok(match name {
        "info" => encode(
            &map::Info {
                width: 3,
                height: 2,
                resolution: 0.5,
                origin: p,
            },
            2.0,
        ),
        "data" => {
            let q = decode::<map::GetData>(payload).map_err(|_| vec![])?.msg;
            let n = (q.width * q.height) as usize;
            let cells = (0..n).map(|i| [-1i8, 0, 1][i % 3]).collect();
            encode(
                &map::Data {
                    col: q.col,
                    row: q.row,
                    width: q.width,
                    height: q.height,
                    cells,
                },
                2.0,
            )
        }
        "set_pose" => {
            let q = decode::<localize::SetPose>(payload)
                .map_err(|_| vec![])?
                .msg;
            if q.mean.x == 1.0 {
                encode(&common::Ack, 2.0)
            } else {
                return nack("bad pose");
            }
        }
        "waypoints" => encode(
            &planner::Waypoints {
                waypoints: vec![Pose2d::new(0.0, 0.0, 0.0), Pose2d::new(3.0, 4.0, 0.0)],
            },
            2.0,
        ),
        "geom" if split(payload).map(|(t, _, _)| t) == Ok("sonar/get_geom@1") => encode(
            &sonar::Geom {
                poses: vec![Pose3d::planar(0.1, 0.0, 0.0); 16],
            },
            2.0,
        ),
        "geom" => encode(
            &bumper::Geom {
                bumpers: vec![Default::default(); 2],
            },
            2.0,
        ),
        "pose" => encode(
            &ir::Geom {
                poses: vec![Default::default(); 2],
            },
            2.0,
        ),
        _ => return nack("not served"),
    })
}

/// The fake devices: tokens, a publisher thread, a queryable, a command tap.
struct Devices {
    _session: Session,
    stop: Arc<AtomicBool>,
    commands: mpsc::Receiver<(String, Vec<u8>)>,
    big: Arc<std::sync::Mutex<Option<Vec<u8>>>>,
}

fn devices(net: &TestNet) -> Devices {
    let s = net.peer();
    let (tx, commands) = mpsc::channel();
    let tap = s
        .declare_subscriber(format!("robot/{ROBOT}/*/*/cmd/*"))
        .callback(move |x| {
            let _ = tx.send((x.key_expr().to_string(), x.payload().to_bytes().to_vec()));
        })
        .wait()
        .unwrap();
    let q = s
        .declare_queryable(format!("robot/{ROBOT}/*/*/req/*"))
        .callback(|q| {
            let key = q.key_expr().as_str().to_owned();
            let name = key.rsplit('/').next().unwrap_or("").to_owned();
            let payload = q
                .payload()
                .map(|p| p.to_bytes().to_vec())
                .unwrap_or_default();
            match answer(&name, &payload) {
                Ok(r) => q.reply(q.key_expr().clone(), r).wait().unwrap(),
                Err(e) => q.reply_err(e).wait().unwrap(),
            }
        })
        .wait()
        .unwrap();
    let samples = samples();
    let mut tokens = Vec::new();
    for (d, _) in &samples {
        tokens.push(
            s.liveliness()
                .declare_token(keys::token(d, "fake"))
                .wait()
                .unwrap(),
        );
    }
    let names: Vec<String> = samples.iter().map(|(d, _)| d.to_string()).collect();
    net.wait_live(&names.iter().map(String::as_str).collect::<Vec<_>>());
    let stop = Arc::new(AtomicBool::new(false));
    let big: Arc<std::sync::Mutex<Option<Vec<u8>>>> = Arc::default();
    let (st, b, pubs) = (stop.clone(), big.clone(), s.clone());
    // Like drivers, the devices publish all the time (every 5 ms here).
    std::thread::spawn(move || {
        let _keep = (tap, q, tokens);
        while !st.load(Ordering::Relaxed) {
            for (d, payload) in &samples {
                let big = b.lock().unwrap().clone();
                let payload = match (d.interface, big) {
                    (Interface::Laser, Some(big)) => big,
                    _ => payload.clone(),
                };
                pubs.put(keys::data(d), payload).wait().unwrap();
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    });
    Devices {
        _session: s,
        stop,
        commands,
        big,
    }
}

impl Drop for Devices {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// The bridge in this process, on a free port.
fn bridge(
    net: &TestNet,
) -> (
    SocketAddr,
    std::thread::JoinHandle<()>,
    tokio::sync::oneshot::Sender<()>,
) {
    bridge_with(net, Config::default())
}

/// The bridge in this process, on a free port, configured as `base` says.
fn bridge_with(
    net: &TestNet,
    base: Config,
) -> (
    SocketAddr,
    std::thread::JoinHandle<()>,
    tokio::sync::oneshot::Sender<()>,
) {
    let session = net.client();
    let (addr_tx, addr_rx) = mpsc::channel();
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let t = std::thread::spawn(move || {
        let rt = tokio::runtime::Builder::new_multi_thread()
            // Four workers: a test stalls one on purpose.
            .worker_threads(4)
            .enable_all()
            .build()
            .unwrap();
        rt.block_on(async move {
            let cfg = Config {
                ports: vec![Port {
                    robot: ROBOT,
                    listen: "127.0.0.1:0".parse().unwrap(),
                }],
                ..base
            };
            let b = Bridge::bind(session, cfg).await.unwrap();
            addr_tx.send(b.local_addrs()[0].1).unwrap();
            b.run(async {
                let _ = stop_rx.await;
            })
            .await;
        });
    });
    (addr_rx.recv_timeout(DEADLINE).unwrap(), t, stop_tx)
}

fn be(words: &[u32]) -> Vec<u8> {
    words.iter().flat_map(|w| w.to_be_bytes()).collect()
}

fn f64s(v: &[f64]) -> Vec<u8> {
    v.iter().flat_map(|w| w.to_be_bytes()).collect()
}

#[test]
fn every_interface_s_data_commands_and_requests_cross_the_bridge() {
    let net = TestNet::new("bridge-ifaces");
    let devs = devices(&net);
    let (addr, thread, stop) = bridge(&net);
    let mut c = Player::connect(addr, ROBOT);

    // DEVLIST: every device, by interface code and index.
    c.send(1, 0, 3, 1, &[]);
    let r = c.reply();
    assert_eq!(r.body.len(), 8 + 16 * samples().len());

    // Data: subscribe to everything in PUSH mode; each interface arrives as Player's DATA.
    let mut missing: Vec<Interface> = samples().iter().map(|(d, _)| d.interface).collect();
    for (d, _) in samples() {
        c.open(d);
    }
    let deadline = Instant::now() + DEADLINE;
    while !missing.is_empty() {
        assert!(Instant::now() < deadline, "no DATA from {missing:?}");
        let r = c.recv();
        if r.h[4] != 1 {
            continue;
        }
        let iface = Interface::from_code(r.h[2] as u16).unwrap();
        assert_eq!((r.h[5], r.body.len()), expected_data(iface), "{iface}");
        missing.retain(|i| *i != iface);
    }

    // Commands: each becomes the Troupe command its driver expects.
    let d = |i| Device::new(ROBOT, i, 0);
    let mut vel = f64s(&[0.3, 0.0, 0.2]);
    vel.extend(be(&[1]));
    c.send(4, 0, 2, 1, &vel);
    c.send(44, 0, 2, 1, &f64s(&[-4.5, -5.5, 0.0]));
    c.send(3, 0, 2, 2, &[]);
    c.send(21, 0, 2, 1, &be(&[2, 3.3f32.to_bits()]));
    c.send(20, 0, 2, 1, &be(&[8, 0x0f]));
    c.send(8, 0, 2, 1, &be(&[0.5f32.to_bits(), 0, 0, 0, 0]));
    let mut got = std::collections::HashMap::new();
    while got.len() < 6 {
        let (key, payload) = devs.commands.recv_timeout(DEADLINE).expect("a command");
        got.insert(key, payload);
    }
    let cmd = |i, n| &got[&keys::cmd(&d(i), n)];
    let v = decode::<position2d::CmdVel>(cmd(Interface::Position2d, "vel"))
        .unwrap()
        .msg;
    assert_eq!((v.vel, v.state), (Pose2d::new(0.3, 0.0, 0.2), true));
    let g = decode::<planner::Goal>(cmd(Interface::Planner, "goal"))
        .unwrap()
        .msg;
    assert_eq!(g.goal, Pose2d::new(-4.5, -5.5, 0.0));
    decode::<gripper::Close>(cmd(Interface::Gripper, "close")).unwrap();
    let a = decode::<aio::Cmd>(cmd(Interface::Aio, "state"))
        .unwrap()
        .msg;
    assert_eq!((a.id, a.voltage), (2, 3.3));
    let io = decode::<dio::Cmd>(cmd(Interface::Dio, "values"))
        .unwrap()
        .msg;
    assert_eq!((io.count, io.bits), (8, 0x0f));
    let z = decode::<ptz::Cmd>(cmd(Interface::Ptz, "state"))
        .unwrap()
        .msg;
    assert_eq!(z.target.pan, 0.5);

    // Requests: ACK bodies in Player's layouts, NACK when the driver refuses.
    let r = c.request(d(Interface::Map), 1, &[]);
    assert_eq!(r.h[4], 4);
    assert_eq!(&r.body[..12], &be(&[0.5f32.to_bits(), 3, 2])[..]);
    let r = c.request(d(Interface::Map), 2, &be(&[0, 0, 3, 2, 0, 0, 0]));
    assert_eq!(r.h[4], 4);
    let zlen = u32::from_be_bytes(r.body[16..20].try_into().unwrap()) as usize;
    let mut cells = Vec::new();
    flate2::read::ZlibDecoder::new(&r.body[28..28 + zlen])
        .read_to_end(&mut cells)
        .unwrap();
    assert_eq!(cells, [255, 0, 1, 255, 0, 1]);
    let mut pose = f64s(&[1.0, 2.0, 0.5]);
    pose.extend(f64s(&[0.1; 6]));
    assert_eq!(c.request(d(Interface::Localize), 1, &pose).h[4], 4);
    let mut far = f64s(&[9.0, 2.0, 0.5]);
    far.extend(f64s(&[0.1; 6]));
    let r = c.request(d(Interface::Localize), 1, &far);
    assert_eq!(
        (r.h[4], r.body.len()),
        (6, 0),
        "a refused request is an empty NACK"
    );
    let r = c.request(d(Interface::Planner), 1, &[]);
    assert_eq!(
        f64::from_be_bytes(r.body[..8].try_into().unwrap()),
        5.0,
        "path length"
    );
    assert_eq!(r.body.len(), 8 + 8 + 2 * 24);
    assert_eq!(
        c.request(d(Interface::Sonar), 1, &[]).body.len(),
        8 + 16 * 48
    );
    assert_eq!(
        c.request(d(Interface::Bumper), 1, &[]).body.len(),
        8 + 2 * 56
    );
    assert_eq!(c.request(d(Interface::Ir), 1, &[]).body.len(), 8 + 2 * 48);
    // A subtype Troupe does not serve, and a universal one: empty NACKs.
    assert_eq!(
        c.request(d(Interface::Position2d), 7, &be(&[0, 0, 0])).h[4],
        6
    );
    assert_eq!(
        c.request(d(Interface::Position2d), 255, &be(&[3, 1])).h[4],
        6
    );

    drop(c);
    let _ = stop.send(());
    thread.join().unwrap();
}

#[test]
fn opens_are_counted_per_client_and_commands_to_unopened_devices_are_ignored() {
    let net = TestNet::new("bridge-opens");
    let devs = devices(&net);
    let (addr, thread, stop) = bridge(&net);
    let pos = Device::new(ROBOT, Interface::Position2d, 0);
    let vel = |vx: f64| {
        let mut b = f64s(&[vx, 0.0, 0.0]);
        b.extend(be(&[1]));
        b
    };
    let mut c = Player::connect(addr, ROBOT);
    // Not opened: Player drops it, and so does the bridge.
    c.send(4, 0, 2, 1, &vel(0.1));
    // Two proxies on one device: two opens.
    c.open(pos);
    c.open(pos);
    c.send(4, 0, 2, 1, &vel(0.2));
    let (key, payload) = devs.commands.recv_timeout(DEADLINE).expect("a command");
    assert_eq!(key, keys::cmd(&pos, "vel"));
    let v = decode::<position2d::CmdVel>(&payload).unwrap().msg;
    assert_eq!(
        v.vel.x, 0.2,
        "the command to the unopened device went through"
    );
    // One proxy closes: the other still gets the device's data.
    c.close(pos);
    let deadline = Instant::now() + DEADLINE;
    loop {
        let r = c.recv();
        if r.h[2] == 4 && r.h[4] == 1 {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "no position2d data after one of two closes"
        );
    }
    c.close(pos);
    drop(c);
    let _ = stop.send(());
    thread.join().unwrap();
}

#[test]
fn dozens_of_clients_flow_while_one_is_stuck_and_bad_input_closes_only_its_connection() {
    let net = TestNet::new("bridge-clients");
    let devs = devices(&net);
    // A 40 KB scan every 5 ms: a client that never reads fills its socket and queue.
    let big = encode(
        &laser::Scan {
            ranges: vec![1.0; 10_000],
            ..Default::default()
        },
        1.0,
    );
    *devs.big.lock().unwrap() = Some(big);
    let (addr, thread, stop) = bridge(&net);
    let laser = Device::new(ROBOT, Interface::Laser, 0);

    let mut stuck = Player::connect(addr, ROBOT);
    stuck.open(laser);
    let mut clients: Vec<Player> = (0..30).map(|_| Player::connect(addr, ROBOT)).collect();
    for c in &mut clients {
        c.open(laser);
    }
    // Every reading client gets 100 scans while the stuck one reads nothing.
    for c in &mut clients {
        let mut n = 0;
        while n < 100 {
            let r = c.recv();
            if r.h[2] == 6 && r.h[4] == 1 {
                assert_eq!(r.body.len(), 16 + 8 + 40_000 + 8 + 4);
                n += 1;
            }
        }
    }

    // A truncated command (to a device it opened) closes that connection,
    // and only that one.
    let mut bad = Player::connect(addr, ROBOT);
    bad.open(Device::new(ROBOT, Interface::Position2d, 0));
    bad.send(4, 0, 2, 1, &[0, 0, 0]);
    let mut rest = Vec::new();
    bad.s
        .read_to_end(&mut rest)
        .expect("the bridge closes the connection");
    // An absurd size closes the connection too.
    let mut huge = Player::connect(addr, ROBOT);
    // A header announcing a 64 MiB body, and no body.
    let mut h = Frame::new([0, ROBOT, 1, 0, 3, 1], &[]).encode();
    h[36..40].copy_from_slice(&(64u32 << 20).to_be_bytes());
    huge.s.write_all(&h).unwrap();
    huge.s.read_to_end(&mut rest).expect("closed");
    // The others are served as before.
    let c = &mut clients[0];
    assert_eq!(c.devlist().h[5], 1, "DEVLIST answered");

    drop(stuck);
    drop(clients);
    let _ = stop.send(());
    thread.join().unwrap();
}

/// A device live on `s` that publishes nothing now: what a driver's runtime
/// does for it, its token and the latest sample `state` answered to gets.
fn quiet_device(
    s: &Session,
    dev: Device,
    state: Vec<u8>,
) -> (
    troupe_node::zenoh::liveliness::LivelinessToken,
    troupe_node::zenoh::query::Queryable<()>,
) {
    let token = s
        .liveliness()
        .declare_token(keys::token(&dev, "fake"))
        .wait()
        .unwrap();
    let latest = s
        .declare_queryable(keys::data(&dev))
        .callback(move |q| q.reply(q.key_expr().clone(), state.clone()).wait().unwrap())
        .wait()
        .unwrap();
    (token, latest)
}

/// A PULL client that closes a device after a round: Player answers the
/// close once its driver has run again, with the data on its way ahead of
/// the answer, so the client's next read returns at once (libplayerc keeps
/// what came while it waited for the answer) instead of waiting for a
/// round no device will fill.
#[test]
fn closing_in_pull_mode_brings_the_data_on_its_way_before_the_answer() {
    use crate::player::{DATA, RESP_ACK, SYNCH};
    let net = TestNet::new("bridge-close-pull");
    let s = net.peer();
    let pos = Device::new(ROBOT, Interface::Position2d, 0);
    let state = encode(
        &position2d::Data {
            pose: Pose2d::new(1.0, 2.0, 0.5),
            ..Default::default()
        },
        4.0,
    );
    let _driver = quiet_device(&s, pos, state);
    net.wait_live(&[&pos.to_string()]);
    let (addr, thread, stop) = bridge(&net);
    let mut c = Player::connect(addr, ROBOT);
    // PLAYER_PLAYER_REQ_DATAMODE, PLAYER_DATAMODE_PULL.
    c.send(1, 0, 3, 5, &2u32.to_be_bytes());
    assert_eq!(c.reply().kind(), RESP_ACK);
    c.open(pos);
    // One round: ACK, the state, SYNCH.
    c.send(1, 0, 3, 4, &[]);
    let kinds: Vec<u32> = (0..3).map(|_| c.recv().kind()).collect();
    assert_eq!(kinds, [RESP_ACK, DATA, SYNCH]);
    c.close(pos);
    assert_eq!(c.seen.len(), 1, "the state came before the close's answer");
    let d = &c.seen[0];
    assert_eq!(
        (d.h[2], d.h[4], d.f64_at(0), d.f64_at(8)),
        (u32::from(Interface::Position2d.code()), DATA, 1.0, 2.0)
    );
    drop(c);
    let _ = stop.send(());
    thread.join().unwrap();
}

/// A device that published once, before the client came (amcl's localize
/// at rest): the client that subscribes later gets its latest state at once,
/// after its subscription's answer, as Player's drivers gave their state to
/// the client that set them up.
#[test]
fn a_late_subscriber_gets_the_latest_sample_of_a_quiet_device() {
    let net = TestNet::new("bridge-latest");
    let s = net.peer();
    let loc = Device::new(ROBOT, Interface::Localize, 0);
    let state = encode(
        &localize::Hypoths {
            pending_count: 0,
            pending_time: 3.0,
            hypoths: vec![localize::Hypoth {
                mean: Pose2d::new(-6.0, -6.0, 0.5),
                cov: [0.1, 0.1, 0.05, 0.0, 0.0, 0.0],
                weight: 1.0,
            }],
        },
        3.0,
    );
    let _driver = quiet_device(&s, loc, state);
    net.wait_live(&[&loc.to_string()]);
    let (addr, thread, stop) = bridge(&net);
    let mut c = Player::connect(addr, ROBOT);
    c.open(loc);
    // The first message after the answer: the localize hypotheses (DATA 1).
    let data = c.recv();
    assert_eq!(
        (data.h[2], data.h[3], data.h[4], data.h[5]),
        (u32::from(Interface::Localize.code()), 0, 1, 1),
        "{data:?}"
    );
    drop(c);
    let _ = stop.send(());
    thread.join().unwrap();
}

/// A client that writes requests ahead without reading its answers holds a
/// bounded amount of the bridge: once `MAX_PENDING_REQUESTS` wait and
/// `MAX_UNREAD_ANSWERS` are unread, the bridge reads no more of it and
/// TCP holds it back. Once it reads, every request it sent is answered.
/// (Before, the bridge read them all into an unbounded queue: a client
/// that wrote a million grew the launcher by 240 MB.)
#[test]
fn a_client_sending_requests_ahead_is_held_back_and_each_request_is_answered() {
    let net = TestNet::new("bridge-flood");
    let _devs = devices(&net);
    let (addr, thread, stop) = bridge(&net);
    let pos = Device::new(ROBOT, Interface::Position2d, 0);
    let code = u32::from(Interface::Position2d.code());
    // A device's request (PLAYER_POSITION2D_REQ_GET_GEOM, answered by its
    // driver in turn) and the bridge's own (DEVLIST, answered at once).
    for (what, interf, subtype) in [("GET_GEOM", code, 1), ("DEVLIST", 1, 1)] {
        let mut c = Player::connect(addr, ROBOT);
        c.open(pos);
        // Small socket buffers: the bridge's bound, not the kernel's, shows.
        nix::sys::socket::setsockopt(&c.s, nix::sys::socket::sockopt::SndBuf, &4096).unwrap();
        // 200,000 requests (8 MB).
        let req = Frame::new([0, ROBOT, interf, 0, 3, subtype], &[]).encode();
        const N: usize = 200_000;
        c.s.set_write_timeout(Some(Duration::from_secs(2))).unwrap();
        let (mut sent, mut partial) = (0, 0);
        while sent < N {
            match c.s.write(&req[partial..]) {
                Ok(n) => {
                    partial += n;
                    if partial == req.len() {
                        (sent, partial) = (sent + 1, 0);
                    }
                }
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => break,
                Err(e) => panic!("writing requests: {e}"),
            }
        }
        assert!(
            sent < N / 4,
            "{what}: the bridge took {sent} of {N} requests from a client that read no answer"
        );
        // Now it reads, and finishes the request it had begun.
        let rest = req[partial..].to_vec();
        let mut w = c.s.try_clone().unwrap();
        let finish = std::thread::spawn(move || {
            w.set_write_timeout(None).unwrap();
            w.write_all(&rest).unwrap();
        });
        let expected = sent + usize::from(partial > 0);
        let mut answered = 0;
        while answered < expected {
            let f = c.recv();
            if f.h[2] == interf && f.h[5] == subtype && (f.kind() == 4 || f.kind() == 6) {
                answered += 1;
            }
        }
        finish.join().unwrap();
        // Still served as any client.
        assert_eq!(c.devlist().h[5], 1, "{what}: DEVLIST answered");
    }
    let _ = stop.send(());
    thread.join().unwrap();
}

/// Replace rules are capped per client: a rule with an existing rule's
/// fields changes it (as Player's), a new one past the cap is NACKed.
#[test]
fn replace_rules_past_the_cap_are_refused_and_changing_one_still_works() {
    let net = TestNet::new("bridge-rules");
    let _devs = devices(&net);
    let (addr, thread, stop) = bridge(&net);
    let mut c = Player::connect(addr, ROBOT);
    let rule = |index: i32, replace: i32| {
        let mut b = Vec::new();
        for v in [4, index, 1, -1, replace] {
            b.extend_from_slice(&v.to_be_bytes());
        }
        b
    };
    let max = i32::try_from(troupe_bridge::queue::MAX_RULES).unwrap();
    for index in 0..max {
        c.send(1, 0, 3, 10, &rule(index, 1));
        assert_eq!(c.reply().kind(), 4, "rule {index} accepted");
    }
    c.send(1, 0, 3, 10, &rule(max, 1));
    assert_eq!(c.reply().kind(), 6, "a rule past the cap is NACKed");
    c.send(1, 0, 3, 10, &rule(0, 0));
    assert_eq!(c.reply().kind(), 4, "an existing rule changes");
    let _ = stop.send(());
    thread.join().unwrap();
}

/// Past `max_clients`, a connection is closed before the banner, and the
/// clients already in are served as before.
#[test]
fn connections_past_the_cap_are_closed_before_the_banner() {
    let net = TestNet::new("bridge-cap");
    let _devs = devices(&net);
    let (addr, thread, stop) = bridge_with(
        &net,
        Config {
            max_clients: 3,
            ..Config::default()
        },
    );
    let mut clients: Vec<Player> = (0..3).map(|_| Player::connect(addr, ROBOT)).collect();
    let mut extra = std::net::TcpStream::connect(addr).unwrap();
    extra.set_read_timeout(Some(DEADLINE)).unwrap();
    let mut got = Vec::new();
    extra.read_to_end(&mut got).expect("closed");
    assert!(got.is_empty(), "the fourth client got {} bytes", got.len());
    for c in &mut clients {
        assert_eq!(c.devlist().h[5], 1, "DEVLIST answered");
    }
    let _ = stop.send(());
    thread.join().unwrap();
}

/// A client that connects and sends nothing, one that stops halfway
/// through a message, and one that never reads what it asked for are each
/// dropped after their limit; a client that sent whole messages and then
/// only listens stays, and is served.
#[test]
fn idle_trickling_and_unread_clients_are_dropped_after_their_limits() {
    use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
    use std::os::fd::AsFd;
    let net = TestNet::new("bridge-slow");
    let devs = devices(&net);
    // A 40 KB scan every 5 ms: a client that reads nothing fills its socket.
    *devs.big.lock().unwrap() = Some(encode(
        &laser::Scan {
            ranges: vec![1.0; 10_000],
            ..Default::default()
        },
        1.0,
    ));
    let limit = Duration::from_secs(1);
    let (addr, thread, stop) = bridge_with(
        &net,
        Config {
            limits: Limits {
                first_message: limit,
                message: limit,
                stalled: limit,
            },
            ..Config::default()
        },
    );
    let mut listener = Player::connect(addr, ROBOT);
    assert_eq!(listener.devlist().h[5], 1);

    let mut unread = Player::connect(addr, ROBOT);
    unread.open(Device::new(ROBOT, Interface::Laser, 0));
    let t0 = Instant::now();
    let idle = Player::connect(addr, ROBOT);
    let mut trickle = Player::connect(addr, ROBOT);
    let header = Frame::new([0, ROBOT, 1, 0, 3, 1], &[]).encode();
    trickle.s.write_all(&header[..10]).unwrap();

    for (name, mut c) in [("idle", idle), ("trickling", trickle)] {
        let mut rest = Vec::new();
        c.s.read_to_end(&mut rest)
            .unwrap_or_else(|e| panic!("the {name} client: {e}"));
        assert!(
            rest.is_empty(),
            "the {name} client got {} bytes",
            rest.len()
        );
    }
    // Reset, not closed in order: what it did not read is discarded.
    let mut fds = [PollFd::new(unread.s.as_fd(), PollFlags::empty())];
    let n = poll(&mut fds, PollTimeout::try_from(DEADLINE).unwrap()).unwrap();
    let hup = fds[0].revents().unwrap_or(PollFlags::empty());
    assert!(
        n == 1 && hup.intersects(PollFlags::POLLHUP | PollFlags::POLLERR),
        "the client that reads nothing is still connected: {hup:?}"
    );
    assert!(t0.elapsed() >= limit, "dropped before its limit");

    // The one that only listens is still served.
    assert_eq!(listener.devlist().h[5], 1, "DEVLIST answered");
    let _ = stop.send(());
    thread.join().unwrap();
}

/// Reads until `n` position2d samples came (other messages pass by).
fn position2d_samples(p: &mut Player, n: usize) {
    let code = u32::from(Interface::Position2d.code());
    let mut samples = 0;
    while samples < n {
        let f = p.recv();
        if f.h[2] == code && f.kind() == 1 {
            samples += 1;
        }
    }
}

/// Planted panics: on a DEVLIST to index 7, and in the sonar's feed.
fn faults(what: &str) {
    assert!(what != "message 1:7:3:1", "a planted panic");
    assert!(what != "sample 6665:sonar:0", "a planted panic in a feed");
}

/// A panic in the bridge's code (a bug, planted here) closes only the
/// connection whose message caused it, and a panic in a device's feed
/// drops that sample only: the bridge, inside the launcher, goes on.
#[test]
fn a_panic_in_the_bridge_closes_one_connection_and_the_rest_goes_on() {
    let net = TestNet::new("bridge-panic");
    let _devs = devices(&net);
    let (addr, thread, stop) = bridge_with(
        &net,
        Config {
            fault: Some(faults),
            ..Config::default()
        },
    );
    let pos = Device::new(ROBOT, Interface::Position2d, 0);
    let mut calm = Player::connect(addr, ROBOT);
    calm.open(Device::new(ROBOT, Interface::Sonar, 0));
    calm.open(pos);
    let mut bad = Player::connect(addr, ROBOT);
    bad.open(pos);
    bad.send(1, 7, 3, 1, &[]);
    // Closed (its data flowing until then), within the deadline.
    let until = Instant::now() + DEADLINE;
    let mut chunk = [0u8; 64 * 1024];
    loop {
        assert!(
            Instant::now() < until,
            "the connection that panicked is still open"
        );
        match bad.s.read(&mut chunk) {
            Ok(0) => break,
            Ok(_) => {}
            Err(e) => panic!("reading the connection that panicked: {e}"),
        }
    }
    // The other client still gets position2d's samples and its answers.
    position2d_samples(&mut calm, 20);
    assert_eq!(calm.devlist().h[5], 1, "DEVLIST answered");
    // And a new client is served.
    let mut fresh = Player::connect(addr, ROBOT);
    assert_eq!(fresh.devlist().h[5], 1, "DEVLIST answered");
    let _ = stop.send(());
    thread.join().unwrap();
}

/// The peer whose samples stall where they are queued, and the bell that
/// lets them go on.
static STALLED: (std::sync::Mutex<Option<String>>, std::sync::Condvar) =
    (std::sync::Mutex::new(None), std::sync::Condvar::new());

/// A planted stall: the named client's queueing waits until released (a
/// minute at most, so a failing test ends).
fn stall_one(what: &str) {
    let (peer, bell) = &STALLED;
    let until = Instant::now() + Duration::from_secs(60);
    let mut p = peer.lock().unwrap();
    while p.as_ref().is_some_and(|p| what == format!("queue {p}")) {
        let left = until.saturating_duration_since(Instant::now());
        if left.is_zero() {
            break;
        }
        p = bell.wait_timeout(p, left).unwrap().0;
    }
}

/// A device's feed is shared by all its clients: one client whose
/// queueing stalls (a wait planted where its samples enter its queue,
/// standing for whatever one client costs there) holds up no other client
/// of the device, and gets its own samples once it goes on.
#[test]
fn a_client_whose_queueing_stalls_holds_up_no_other_client_of_a_device() {
    let net = TestNet::new("bridge-inbox");
    let _devs = devices(&net);
    let (addr, thread, stop) = bridge_with(
        &net,
        Config {
            fault: Some(stall_one),
            ..Config::default()
        },
    );
    let pos = Device::new(ROBOT, Interface::Position2d, 0);
    let mut stuck = Player::connect(addr, ROBOT);
    stuck.open(pos);
    let mut calm = Player::connect(addr, ROBOT);
    calm.open(pos);
    // The stall blocks the runtime thread it happens on (as no real
    // queueing would): both clients are in before it, so that a task
    // queued behind it on that thread (a new connection's) is not what
    // the test waits for.
    *STALLED.0.lock().unwrap() = Some(stuck.s.local_addr().unwrap().to_string());
    // The devices publish every 5 ms: 50 samples within the read timeout,
    // while the other client's queueing is stalled.
    position2d_samples(&mut calm, 50);
    *STALLED.0.lock().unwrap() = None;
    STALLED.1.notify_all();
    position2d_samples(&mut stuck, 5);
    let _ = stop.send(());
    thread.join().unwrap();
}

/// A robot stepping as Stage under Player does: every 20 ms of wall time a
/// step of 0.1 simulated s, position2d once and the laser twice (Stage's
/// ranger sends ranges then intensities, and rangertolaser a scan for
/// each), all stamped with the step's time; each device also answers gets
/// with its latest sample, as a driver's runtime does. Stops when dropped.
struct Stepper {
    stop: Arc<AtomicBool>,
    _live: Vec<troupe_node::zenoh::liveliness::LivelinessToken>,
}

impl Drop for Stepper {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

fn stepper(net: &TestNet, pos: Device, laser: Device) -> Stepper {
    let s = net.peer();
    let live = [pos, laser]
        .iter()
        .map(|d| {
            s.liveliness()
                .declare_token(keys::token(d, "fake"))
                .wait()
                .unwrap()
        })
        .collect();
    net.wait_live(&[&pos.to_string(), &laser.to_string()]);
    // The latest sample of each device, answered to gets.
    let latest: Arc<std::sync::Mutex<[Vec<u8>; 2]>> = Arc::default();
    let answers: Vec<Queryable> = [pos, laser]
        .iter()
        .enumerate()
        .map(|(i, d)| {
            let latest = latest.clone();
            s.declare_queryable(keys::data(d))
                .callback(move |q| {
                    let b = latest.lock().unwrap()[i].clone();
                    if !b.is_empty() {
                        q.reply(q.key_expr().clone(), b).wait().unwrap();
                    }
                })
                .wait()
                .unwrap()
        })
        .collect();
    let stop = Arc::new(AtomicBool::new(false));
    let st = stop.clone();
    std::thread::spawn(move || {
        let _answers = answers;
        for k in 1u32.. {
            if st.load(Ordering::Relaxed) {
                break;
            }
            let t = f64::from(k) * 0.1;
            let p = encode(&position2d::Data::default(), t);
            let l = encode(
                &laser::Scan {
                    max_range: 8.0,
                    ranges: vec![1.0; 8],
                    ..Default::default()
                },
                t,
            );
            *latest.lock().unwrap() = [p.clone(), l.clone()];
            s.put(keys::data(&pos), p).wait().unwrap();
            s.put(keys::data(&laser), l.clone()).wait().unwrap();
            s.put(keys::data(&laser), l).wait().unwrap();
            std::thread::sleep(Duration::from_millis(20));
        }
    });
    Stepper { stop, _live: live }
}

type Queryable = troupe_node::zenoh::query::Queryable<()>;

/// libplayerc's `playerc_client_read` in PULL mode: the DATA kept while it
/// waited for an answer, if any; else a data request and the round up to
/// its SYNCH. Returns each message's interface and stamp.
fn libplayerc_read(c: &mut Player) -> Vec<(u32, f64)> {
    use crate::player::{DATA, RESP_ACK, SYNCH};
    if !c.seen.is_empty() {
        return c.seen.drain(..).map(|f| (f.h[2], f.timestamp)).collect();
    }
    c.send(1, 0, 3, 4, &[]);
    assert_eq!(c.reply().kind(), RESP_ACK);
    let mut got: Vec<(u32, f64)> = c.seen.drain(..).map(|f| (f.h[2], f.timestamp)).collect();
    loop {
        let f = c.recv();
        match f.kind() {
            DATA => got.push((f.h[2], f.timestamp)),
            SYNCH => return got,
            k => panic!("a message of type {k} in a round"),
        }
    }
}

/// Player 3.1 with Stage 4.3 (simple.cfg): a PULL client that opens
/// position2d, then the laser, gets every opened device from its second
/// read on, each read a newer step; Troupe's second read carried the laser
/// alone (its sample of the step the client already had).
#[test]
fn every_opened_device_is_in_the_second_pull_read_and_each_read_is_newer() {
    let net = TestNet::new("bridge-pull-second");
    let pos = Device::new(ROBOT, Interface::Position2d, 0);
    let las = Device::new(ROBOT, Interface::Laser, 0);
    let _robot = stepper(&net, pos, las);
    let (addr, thread, stop) = bridge(&net);
    let mut c = Player::connect(addr, ROBOT);
    c.send(1, 0, 3, 5, &2u32.to_be_bytes());
    assert_eq!(c.reply().kind(), crate::player::RESP_ACK);
    c.open(pos);
    c.open(las);
    let (pos_code, las_code) = (
        u32::from(Interface::Position2d.code()),
        u32::from(Interface::Laser.code()),
    );
    let mut newest = f64::NEG_INFINITY;
    let first = libplayerc_read(&mut c);
    for (_, t) in &first {
        newest = newest.max(*t);
    }
    for read in 2..=6 {
        let got = libplayerc_read(&mut c);
        for code in [pos_code, las_code] {
            assert!(
                got.iter().any(|&(i, _)| i == code),
                "read {read} lacks interface {code}: {got:?} (read 1: {first:?})"
            );
        }
        let top = got
            .iter()
            .map(|&(_, t)| t)
            .fold(f64::NEG_INFINITY, f64::max);
        assert!(top > newest, "read {read} brings no newer step: {got:?}");
        newest = top;
    }
    drop(c);
    let _ = stop.send(());
    thread.join().unwrap();
}

/// Player with a replace rule for data (PUSH mode) keeps a device's newest
/// queued message: a client got each of rangertolaser's doubled scans once
/// (287 laser messages in 28.6 simulated s); Troupe passed both (602 in
/// 30.1 s). Without a rule both copies go out, from Player as from Troupe.
#[test]
fn a_replace_rule_leaves_one_scan_of_each_step_in_push_mode() {
    let net = TestNet::new("bridge-push-replace");
    let pos = Device::new(ROBOT, Interface::Position2d, 0);
    let las = Device::new(ROBOT, Interface::Laser, 0);
    let _robot = stepper(&net, pos, las);
    let (addr, thread, stop) = bridge(&net);
    let mut ruled = Player::connect(addr, ROBOT);
    // PLAYER_PLAYER_REQ_ADD_REPLACE_RULE: any interface and index, DATA,
    // any subtype, replace.
    ruled.send(1, 0, 3, 10, &be(&[u32::MAX, u32::MAX, 1, u32::MAX, 1]));
    assert_eq!(ruled.reply().kind(), crate::player::RESP_ACK);
    ruled.open(las);
    let mut plain = Player::connect(addr, ROBOT);
    plain.open(las);
    let stamps = |c: &mut Player, n: usize| -> Vec<f64> {
        let mut v: Vec<f64> = c.seen.drain(..).map(|f| f.timestamp).collect();
        while v.len() < n {
            let f = c.recv();
            assert_eq!(f.kind(), crate::player::DATA, "{f:?}");
            v.push(f.timestamp);
        }
        v
    };
    let got = stamps(&mut ruled, 40);
    let mut distinct = got.clone();
    distinct.dedup();
    assert_eq!(got, distinct, "a step's scan twice under the rule: {got:?}");
    // Without the rule: both copies of every step after the first whole one.
    let got = stamps(&mut plain, 40);
    let twice = got.windows(2).filter(|w| w[0] == w[1]).count();
    assert!(twice >= 15, "{twice} doubled steps in {got:?}");
    drop((ruled, plain));
    let _ = stop.send(());
    thread.join().unwrap();
}

/// Where the bridge is with the late device: (hearing its token, asked
/// the network for it), and the bell that rings at each.
static LATE: (std::sync::Mutex<(bool, bool)>, std::sync::Condvar) = (
    std::sync::Mutex::new((false, false)),
    std::sync::Condvar::new(),
);

/// Waits (a minute at most, so a failing test ends) until `done` says so
/// of [`LATE`]; whether it did.
fn late_until(done: impl Fn(&(bool, bool)) -> bool) -> bool {
    let (state, bell) = &LATE;
    let until = Instant::now() + Duration::from_secs(60);
    let mut s = state.lock().unwrap();
    while !done(&s) {
        let left = until.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return false;
        }
        s = bell.wait_timeout(s, left).unwrap().0;
    }
    true
}

/// A planted delay: the bridge hears fiducial:3's token only once it has
/// asked the network for it.
fn hear_late(what: &str) {
    let (state, bell) = &LATE;
    if what == format!("ask {ROBOT}:fiducial:3") {
        state.lock().unwrap().1 = true;
        bell.notify_all();
    } else if what == format!("token {ROBOT}:fiducial:3") {
        state.lock().unwrap().0 = true;
        bell.notify_all();
        late_until(|s| s.1);
    }
}

/// A device that has just come, which the routers know of and the bridge
/// has not heard of yet (a robot rejoining as a client connects): the
/// client's open is granted, as the device is live, not refused as
/// unknown.
#[test]
fn an_open_of_a_device_the_bridge_has_not_heard_of_yet_asks_the_network() {
    let net = TestNet::new("bridge-late");
    let (addr, thread, stop) = bridge_with(
        &net,
        Config {
            fault: Some(hear_late),
            ..Config::default()
        },
    );
    let mut p = Player::connect(addr, ROBOT);
    let late = Device::new(ROBOT, Interface::Fiducial, 3);
    let driver = net.client();
    let _token = driver
        .liveliness()
        .declare_token(keys::token(&late, "dummy"))
        .wait()
        .unwrap();
    assert!(late_until(|s| s.0), "the bridge never heard the token");
    // Player::open asserts the ACK.
    p.open(late);
    assert!(late_until(|s| s.1), "the network was not asked");
    let _ = stop.send(());
    thread.join().unwrap();
}

/// A goal a Player client sends once, while its planner's token is live but
/// no subscription to its commands has reached the bridge yet (after a
/// partition heals, the token can come seconds before it), is held and
/// reaches the planner when its subscription comes; the client is not held
/// up meanwhile.
#[test]
fn a_command_sent_before_its_driver_subscribes_reaches_it_when_it_does() {
    let net = TestNet::new("bridge-held");
    let s = net.peer();
    let planner = Device::new(ROBOT, Interface::Planner, 0);
    let _token = s
        .liveliness()
        .declare_token(keys::token(&planner, "fake"))
        .wait()
        .unwrap();
    net.wait_live(&[planner.to_string().as_str()]);
    let (addr, thread, stop) = bridge(&net);
    let mut c = Player::connect(addr, ROBOT);
    c.open(planner);
    c.send(
        u32::from(Interface::Planner.code()),
        0,
        2,
        1,
        &f64s(&[1.0, 2.0, 0.5]),
    );
    // Answered by the bridge itself, after it took the goal (a connection's
    // messages are handled in order): the goal has found no one.
    let list = c.devlist();
    assert_eq!(list.kind(), 4, "not an ACK: {list:?}");
    let (tx, rx) = mpsc::channel();
    let _planner = s
        .declare_subscriber(keys::cmd(&planner, "goal"))
        .callback(move |x| {
            let _ = tx.send(x.payload().to_bytes().to_vec());
        })
        .wait()
        .unwrap();
    let got = rx
        .recv_timeout(DEADLINE)
        .expect("the goal, held until the planner subscribed");
    let g = decode::<planner::Goal>(&got).unwrap().msg.goal;
    assert_eq!((g.x, g.y, g.yaw), (1.0, 2.0, 0.5));
    drop(c);
    let _ = stop.send(());
    thread.join().unwrap();
}
