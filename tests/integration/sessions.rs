//! Drivers as threads with their own Zenoh sessions, a client in another
//! session, all through a real router on loopback.

use std::time::{Duration, Instant};

use serde::Deserialize;
use troupe_client::{Client, ClientError, LaserProxy, Position2dProxy, RangerProxy};
use troupe_msgs::{
    codec, common, keys, laser, position2d, ranger, Device, Interface, Pose2d, Pose3d, Size3d,
};
use troupe_node::zenoh::Wait;
use troupe_node::{
    spawn, Ctx, Driver, Event, NodeConfig, NodeError, NodeHandle, Result, Section, Stop,
};
use troupe_tests::{TestNet, DEADLINE};

fn start<D: Driver>(net: &TestNet, section: &str) -> NodeHandle {
    let section = Section::from_json(section).expect("section");
    spawn::<D>(net.peer(), section, &NodeConfig::default(), Stop::default()).expect("node starts")
}

fn dummy_and_converter(net: &TestNet) -> (NodeHandle, NodeHandle) {
    let d = start::<troupe_dummy::Dummy>(
        net,
        r#"{"name":"dummy","provides":["ranger:0"],"options":{"rate":50}}"#,
    );
    let r = start::<troupe_rangertolaser::RangerToLaser>(
        net,
        r#"{"name":"rangertolaser","requires":["ranger:0"],"provides":["laser:0"]}"#,
    );
    net.wait_live(&["6665:ranger:0", "6665:laser:0"]);
    (d, r)
}

/// Reads until `ok` holds, within the deadline.
fn read_until(client: &Client, what: &str, ok: impl Fn() -> bool) {
    let deadline = Instant::now() + DEADLINE;
    while !ok() {
        assert!(Instant::now() < deadline, "timed out waiting for {what}");
        client.read_timeout(DEADLINE).expect("data keeps coming");
    }
}

#[test]
fn ranger_data_flows_through_rangertolaser_to_a_laser_client() {
    let net = TestNet::new("flow");
    let (d, r) = dummy_and_converter(&net);
    let client = Client::with_session(net.client(), 6665);
    let lp = LaserProxy::new(&client, 0).unwrap();
    let rp = RangerProxy::new(&client, 0).unwrap();
    read_until(&client, "a laser scan", || {
        lp.count() == 361 && rp.count() == 361
    });
    assert_eq!(lp.range(360), Some(8.0));
    // The dummy refuses the config request, so angles are zero, as in Player.
    assert_eq!(lp.max_angle(), 0.0);
    r.stop().unwrap();
    d.stop().unwrap();
}

#[test]
fn nodes_that_poll_before_they_sleep_pass_data_and_replies_and_stop() {
    let net = TestNet::new("spin");
    let cfg = NodeConfig {
        spin: Duration::from_millis(2),
        ..Default::default()
    };
    let spawn_polling = |section: &str| {
        let section = Section::from_json(section).expect("section");
        spawn::<troupe_dummy::Dummy>(net.peer(), section, &cfg, Stop::default())
    };
    let d = spawn_polling(r#"{"name":"dummy","provides":["ranger:0"],"options":{"rate":50}}"#)
        .expect("dummy starts");
    let section = r#"{"name":"rangertolaser","requires":["ranger:0"],"provides":["laser:0"]}"#;
    let r = spawn::<troupe_rangertolaser::RangerToLaser>(
        net.peer(),
        Section::from_json(section).unwrap(),
        &cfg,
        Stop::default(),
    )
    .expect("converter starts");
    net.wait_live(&["6665:ranger:0", "6665:laser:0"]);
    let client = Client::with_session(net.client(), 6665);
    let lp = LaserProxy::new(&client, 0).unwrap();
    read_until(
        &client,
        "a laser scan through the polling converter",
        || lp.count() == 361,
    );
    // The converter asks the dummy, which refuses: the refusal comes back
    // through the converter's polling inbox to the client.
    match lp.request_geom() {
        Err(ClientError::Nack { reason, .. }) => {
            assert!(reason.contains("dummy driver refuses"), "{reason}")
        }
        other => panic!("expected a NACK, got {other:?}"),
    }
    r.stop().unwrap();
    d.stop().unwrap();
}

#[test]
fn liveliness_lists_every_device_with_its_driver() {
    let net = TestNet::new("list");
    let (_d, _r) = dummy_and_converter(&net);
    let s = net.client();
    let replies = s
        .liveliness()
        .get(keys::tokens(Some(6665)))
        .timeout(DEADLINE)
        .wait()
        .unwrap();
    let mut found = Vec::new();
    while let Ok(r) = replies.recv() {
        let key = r.result().unwrap().key_expr().to_string();
        found.push(keys::parse_token(&key).unwrap());
    }
    found.sort();
    assert_eq!(
        found,
        vec![
            (
                Device::new(6665, Interface::Laser, 0),
                "rangertolaser".to_owned()
            ),
            (Device::new(6665, Interface::Ranger, 0), "dummy".to_owned()),
        ]
    );
}

#[test]
fn a_nack_travels_back_with_its_reason() {
    let net = TestNet::new("nack");
    let (_d, _r) = dummy_and_converter(&net);
    let client = Client::with_session(net.client(), 6665);
    let lp = LaserProxy::new(&client, 0).unwrap();
    // rangertolaser forwards geom to the dummy ranger, which refuses.
    match lp.request_geom() {
        Err(ClientError::Nack { reason, .. }) => {
            assert!(reason.contains("dummy driver refuses"), "{reason}")
        }
        other => panic!("expected a NACK, got {other:?}"),
    }
}

#[test]
fn a_request_to_no_device_says_so() {
    let net = TestNet::new("noreply");
    let client = Client::with_session(net.client(), 6665);
    let p = Position2dProxy::new(&client, 3).unwrap();
    let e = p.request_geom().unwrap_err().to_string();
    assert!(e.contains("6665:position2d:3"), "{e}");
}

#[test]
fn a_missing_requirement_times_out_naming_the_device() {
    let net = TestNet::new("missing");
    let section = Section::from_json(
        r#"{"name":"rangertolaser","requires":["ranger:4"],"provides":["laser:0"]}"#,
    )
    .unwrap();
    let cfg = NodeConfig {
        requires_timeout: Duration::from_millis(300),
        ..Default::default()
    };
    let e =
        spawn::<troupe_rangertolaser::RangerToLaser>(net.peer(), section, &cfg, Stop::default())
            .err()
            .expect("must time out");
    assert!(matches!(e, NodeError::RequiresTimeout { .. }), "{e}");
    assert!(e.to_string().contains("6665:ranger:4"), "{e}");
}

#[test]
fn malformed_samples_are_dropped_and_the_node_lives_on() {
    let net = TestNet::new("malformed");
    // rangertolaser alone; the test plays the ranger.
    let s = net.peer();
    let ranger_dev = Device::new(6665, Interface::Ranger, 0);
    let _token = s
        .liveliness()
        .declare_token(keys::token(&ranger_dev, "test"))
        .wait()
        .unwrap();
    let _cfg = s
        .declare_queryable(keys::req(&ranger_dev, "get_config"))
        .callback(|q| {
            let c = ranger::Config {
                max_range: 5.0,
                ..Default::default()
            };
            q.reply(q.key_expr().clone(), troupe_msgs::encode(&c, 0.0))
                .wait()
                .unwrap();
        })
        .wait()
        .unwrap();
    let r = start::<troupe_rangertolaser::RangerToLaser>(
        &net,
        r#"{"name":"rangertolaser","requires":["ranger:0"],"provides":["laser:0"]}"#,
    );
    net.wait_live(&["6665:laser:0"]);
    let client = Client::with_session(net.client(), 6665);
    let lp = LaserProxy::new(&client, 0).unwrap();
    let data = keys::data(&ranger_dev);
    let publisher = s.declare_publisher(data).wait().unwrap();
    let deadline = Instant::now() + DEADLINE;
    // Garbage, a wrong schema, then good data, until a scan comes out.
    while lp.count() != 3 {
        assert!(Instant::now() < deadline, "no scan after malformed input");
        publisher.put(vec![0xffu8, 1, 2]).wait().unwrap();
        publisher
            .put(troupe_msgs::encode(&laser::Scan::default(), 0.0))
            .wait()
            .unwrap();
        publisher
            .put(troupe_msgs::encode(
                &ranger::Ranges {
                    ranges: vec![1.0, 2.0, 3.0],
                },
                0.0,
            ))
            .wait()
            .unwrap();
        let _ = client.read_timeout(Duration::from_millis(200));
    }
    assert_eq!(lp.max_range(), 5.0);
    r.stop().unwrap();
}

/// A unicycle base for tests: integrates velocity commands on each tick.
struct TestBase {
    dev: Device,
    state: position2d::Data,
    motors: bool,
    last: f64,
}

#[derive(Debug, Default, Deserialize)]
struct NoOpts {}

impl Driver for TestBase {
    const NAME: &'static str = "testbase";
    type Options = NoOpts;

    fn new(section: &Section, _: NoOpts) -> Result<Self> {
        Ok(TestBase {
            dev: section.provided_one(Interface::Position2d, None)?,
            state: position2d::Data::default(),
            motors: false,
            last: 0.0,
        })
    }

    fn setup(&mut self, ctx: &mut Ctx) -> Result<()> {
        self.last = ctx.now();
        ctx.set_tick(Some(Duration::from_millis(10)));
        ctx.publish(&self.dev, &self.state)
    }

    fn on_event(&mut self, ctx: &mut Ctx, event: Event) -> Result<()> {
        match event {
            Event::Command(c) if c.is::<position2d::CmdVel>() => {
                let v = c.decode::<position2d::CmdVel>()?.msg.vel;
                self.state.vel = if self.motors { v } else { Pose2d::default() };
            }
            Event::Command(c) => return Err(c.unexpected()),
            Event::Request(r) if r.is::<position2d::MotorPower>() => {
                self.motors = r.decode::<position2d::MotorPower>()?.state;
                r.reply(&common::Ack);
            }
            Event::Request(r) if r.is::<position2d::GetGeom>() => r.reply(&position2d::Geom {
                pose: Pose3d::default(),
                size: Size3d {
                    width: 0.4,
                    length: 0.5,
                    height: 0.2,
                },
            }),
            Event::Request(r) => r.nack("not supported"),
            Event::Tick => {
                let now = ctx.now();
                let dt = now - self.last;
                self.last = now;
                let p = &mut self.state.pose;
                p.x += self.state.vel.x * p.yaw.cos() * dt;
                p.y += self.state.vel.x * p.yaw.sin() * dt;
                p.yaw += self.state.vel.yaw * dt;
                ctx.publish(&self.dev, &self.state)?;
            }
            Event::Data(_) | Event::Reply(_) | Event::Wake => {}
        }
        Ok(())
    }

    fn shutdown(&mut self, ctx: &mut Ctx) -> Result<()> {
        self.state.vel = Pose2d::default();
        ctx.publish(&self.dev, &self.state)
    }
}

#[test]
fn a_client_drives_a_position2d_device_and_reads_its_state_back() {
    let net = TestNet::new("drive");
    let base = start::<TestBase>(&net, r#"{"name":"testbase","provides":["position2d:0"]}"#);
    net.wait_live(&["6665:position2d:0"]);
    let client = Client::with_session(net.client(), 6665);
    let pp = Position2dProxy::new(&client, 0).unwrap();
    // The latest state arrives with the subscription (late joiner).
    assert!(pp.data().is_some(), "no latest value for a late joiner");
    let g = pp.request_geom().unwrap();
    assert_eq!(g.size.length, 0.5);
    // Motors off: commands do not move the base.
    pp.set_speed(1.0, 0.0).unwrap();
    pp.set_motor_enable(true).unwrap();
    pp.set_speed(1.0, 0.0).unwrap();
    read_until(&client, "the base to move 5 cm", || pp.x() > 0.05);
    assert!(pp.x_speed() > 0.99 && !pp.stall());
    pp.set_speed(0.0, 0.0).unwrap();
    read_until(&client, "the base to stop", || pp.x_speed() == 0.0);
    let e = pp.reset_odometry().unwrap_err().to_string();
    assert!(e.contains("refused `reset_odom`: not supported"), "{e}");
    base.stop().unwrap();
}

#[test]
fn namespaces_keep_tests_apart_on_one_router() {
    let net = TestNet::new("ns-a");
    let _a = start::<troupe_dummy::Dummy>(&net, r#"{"name":"dummy","provides":["laser:5"]}"#);
    net.wait_live(&["6665:laser:5"]);
    let other = TestNet {
        router: net.router.clone(),
        endpoint: net.endpoint.clone(),
        namespace: troupe_tests::unique_namespace("ns-b"),
    };
    let s = other.client();
    let replies = s
        .liveliness()
        .get(keys::tokens(None))
        .timeout(Duration::from_millis(500))
        .wait()
        .unwrap();
    let seen: Vec<String> = std::iter::from_fn(|| replies.recv().ok())
        .filter_map(|r| r.result().ok().map(|s| s.key_expr().to_string()))
        .collect();
    assert!(seen.is_empty(), "namespace leaked: {seen:?}");
}

#[test]
fn under_sim_time_ticks_and_stamps_follow_sim_clock() {
    let net = TestNet::new("simtime");
    let section =
        Section::from_json(r#"{"name":"dummy","provides":["power:0"],"options":{"rate":10}}"#)
            .unwrap();
    let cfg = NodeConfig {
        sim_time: true,
        ..Default::default()
    };
    let node = spawn::<troupe_dummy::Dummy>(net.peer(), section, &cfg, Stop::default()).unwrap();
    net.wait_live(&["6665:power:0"]);
    let s = net.peer();
    let data = s
        .declare_subscriber(keys::data(&Device::new(6665, Interface::Power, 0)))
        .wait()
        .unwrap();
    let clock = s.declare_publisher(keys::SIM_CLOCK).wait().unwrap();
    // 0.1 s of sim time per sample at 10 Hz, however fast the clock runs.
    let mut stamps = Vec::new();
    let deadline = Instant::now() + DEADLINE;
    let mut t = 0.0;
    while stamps.len() < 3 {
        assert!(
            Instant::now() < deadline,
            "no ticks on sim time: {stamps:?}"
        );
        t += 0.05;
        clock
            .put(troupe_msgs::encode(&troupe_msgs::sim::Clock { time: t }, t))
            .wait()
            .unwrap();
        while let Ok(Some(sample)) = data.recv_timeout(Duration::from_millis(20)) {
            let d = troupe_msgs::decode::<troupe_msgs::power::Data>(&sample.payload().to_bytes())
                .unwrap();
            stamps.push(d.stamp);
        }
    }
    for w in stamps.windows(2) {
        assert!(
            (w[1] - w[0] - 0.1).abs() < 0.051,
            "stamps not 0.1 s apart in sim time: {stamps:?}"
        );
    }
    assert!(
        stamps[0] < 1.0,
        "stamps are wall time, not sim time: {stamps:?}"
    );
    node.stop().unwrap();
}

/// Requests that reached [`Ready`]'s thread.
static READY_SAW: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// A driver that keeps its geometry ready, and would answer it wrongly
/// (and count it) if a geometry request ever reached it.
struct Ready {
    dev: Device,
}

impl Driver for Ready {
    const NAME: &'static str = "ready";
    type Options = NoOpts;

    fn new(section: &Section, _: NoOpts) -> Result<Self> {
        Ok(Ready {
            dev: section.provided_one(Interface::Position2d, None)?,
        })
    }

    fn setup(&mut self, ctx: &mut Ctx) -> Result<()> {
        let geom = position2d::Geom {
            size: Size3d {
                width: 0.3,
                length: 0.4,
                height: 0.2,
            },
            ..Default::default()
        };
        ctx.answer_always::<position2d::GetGeom>(&self.dev, &geom)
    }

    fn on_event(&mut self, _: &mut Ctx, event: Event) -> Result<()> {
        if let Event::Request(r) = event {
            READY_SAW.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
            if r.is::<position2d::GetGeom>() {
                r.reply(&position2d::Geom::default());
            } else {
                r.nack("only geometry here");
            }
        }
        Ok(())
    }
}

#[test]
fn answers_kept_ready_skip_the_driver_and_are_stamped_when_sent() {
    let net = TestNet::new("ready");
    let node = start::<Ready>(&net, r#"{"name":"ready","provides":["position2d:0"]}"#);
    net.wait_live(&["6665:position2d:0"]);
    let dev = Device::new(6665, Interface::Position2d, 0);
    let session = net.client();
    let ask = |name: &str, payload: Vec<u8>| {
        let replies = troupe_node::ask(&session, &keys::req(&dev, name), DEADLINE)
            .payload(payload)
            .wait()
            .unwrap();
        replies.recv().expect("an answer").into_result()
    };
    for _ in 0..3 {
        let before = troupe_node::Clock::wall().now();
        let s = ask("geom", codec::encode(&position2d::GetGeom, 0.0)).expect("an ACK");
        let got = codec::decode::<position2d::Geom>(&s.payload().to_bytes()).unwrap();
        assert_eq!(
            got.msg.size.width, 0.3,
            "the ready answer, not the driver's"
        );
        assert!(
            got.stamp >= before && got.stamp <= troupe_node::Clock::wall().now(),
            "stamped when sent: {} not after {before}",
            got.stamp
        );
    }
    // Any other request still reaches the driver.
    assert!(ask(
        "motor_power",
        codec::encode(&position2d::MotorPower { state: true }, 0.0)
    )
    .is_err());
    node.stop().unwrap();
    assert_eq!(READY_SAW.load(std::sync::atomic::Ordering::SeqCst), 1);
}

/// Held by a test to keep a [`Turns`] command hook running.
static TURNS_GATE: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// A driver that ticks fast, remembers the last commanded speed (holding
/// [`TURNS_GATE`] while it takes a negative one) and answers a geometry
/// request with that speed as width and, as length, 1 when its own thread
/// ran the hook, 0 when another did.
struct Turns {
    speed: f64,
}

impl Driver for Turns {
    const NAME: &'static str = "turns";
    type Options = NoOpts;

    fn new(_: &Section, _: NoOpts) -> Result<Self> {
        Ok(Turns { speed: 0.0 })
    }

    fn setup(&mut self, ctx: &mut Ctx) -> Result<()> {
        ctx.set_tick(Some(Duration::from_millis(1)));
        Ok(())
    }

    fn on_event(&mut self, _: &mut Ctx, event: Event) -> Result<()> {
        match event {
            Event::Command(c) => {
                self.speed = c.decode::<position2d::CmdVel>()?.msg.vel.x;
                if self.speed < 0.0 {
                    drop(TURNS_GATE.lock());
                }
            }
            Event::Request(r) => {
                let own = std::thread::current().name() == Some("driver turns");
                r.reply(&position2d::Geom {
                    size: Size3d {
                        width: self.speed,
                        length: if own { 1.0 } else { 0.0 },
                        height: 0.0,
                    },
                    ..Default::default()
                });
            }
            _ => {}
        }
        Ok(())
    }
}

/// Asks [`Turns`] for its geometry: (speed seen, answered on its own thread).
fn ask_turns(session: &troupe_node::zenoh::Session) -> (f64, bool) {
    let dev = Device::new(6665, Interface::Position2d, 0);
    let replies = troupe_node::ask(session, &keys::req(&dev, "geom"), DEADLINE)
        .payload(codec::encode(&position2d::GetGeom, 0.0))
        .wait()
        .unwrap();
    let s = replies.recv().expect("an answer").into_result().unwrap();
    let g = codec::decode::<position2d::Geom>(&s.payload().to_bytes()).unwrap();
    (g.msg.size.width, g.msg.size.length == 1.0)
}

#[test]
fn requests_to_an_idle_driver_run_at_once_on_the_receiving_thread() {
    let net = TestNet::new("inline");
    let node = start::<Turns>(&net, r#"{"name":"turns","provides":["position2d:0"]}"#);
    net.wait_live(&["6665:position2d:0"]);
    // Two clients asking at once, while the driver ticks at 1 kHz: a
    // request that finds the driver between ticks runs at once, the others
    // wait their turn on its thread; each is answered once.
    let asks = || {
        let session = net.client();
        move || {
            (0..100)
                .map(|_| ask_turns(&session))
                .filter(|&(speed, own)| speed == 0.0 && !own)
                .count()
        }
    };
    let other = std::thread::spawn(asks());
    let here = asks()();
    let there = other.join().unwrap();
    node.stop().unwrap();
    assert!(
        here + there > 0,
        "no request was answered off the driver's thread"
    );
}

#[test]
fn a_request_behind_a_running_hook_waits_and_sees_its_effect() {
    let net = TestNet::new("behind");
    let node = start::<Turns>(&net, r#"{"name":"turns","provides":["position2d:0"]}"#);
    net.wait_live(&["6665:position2d:0"]);
    let session = net.client();
    let dev = Device::new(6665, Interface::Position2d, 0);
    for speed in [-2.5, 0.5, -1.0] {
        let gate = TURNS_GATE.lock().unwrap();
        let cmd = position2d::CmdVel {
            vel: Pose2d::new(speed, 0.0, 0.0),
            state: true,
        };
        session
            .put(keys::cmd(&dev, "vel"), codec::encode(&cmd, 0.0))
            .wait()
            .unwrap();
        // Asked while the command's hook may still hold the gate.
        let dev_key = keys::req(&dev, "geom");
        let replies = troupe_node::ask(&session, &dev_key, DEADLINE)
            .payload(codec::encode(&position2d::GetGeom, 0.0))
            .wait()
            .unwrap();
        drop(gate);
        let s = replies.recv().expect("an answer").into_result().unwrap();
        let g = codec::decode::<position2d::Geom>(&s.payload().to_bytes()).unwrap();
        assert_eq!(
            g.msg.size.width, speed,
            "the request saw the command before it"
        );
    }
    node.stop().unwrap();
}

#[test]
fn a_node_with_more_devices_than_zenoh_can_name_is_refused_with_the_reason() {
    let net = TestNet::new("toomany");
    let provides: Vec<String> = (0..16_001).map(|i| format!("\"ranger:{i}\"")).collect();
    let section = Section::from_json(&format!(
        r#"{{"name":"dummy","provides":[{}]}}"#,
        provides.join(",")
    ))
    .unwrap();
    let err = match spawn::<troupe_dummy::Dummy>(
        net.peer(),
        section,
        &NodeConfig::default(),
        Stop::default(),
    ) {
        Ok(_) => panic!("a node of 16,001 devices started"),
        Err(e) => e.to_string(),
    };
    assert!(
        err.contains("16001 devices") && err.contains("65,535"),
        "{err}"
    );
}
