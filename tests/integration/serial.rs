//! Hardware drivers against their emulators, as processes: `troupe emulate`
//! plays the device on a pseudo-terminal, `troupe launch` runs the driver
//! from a .cfg naming the emulator's link as its `port`, and a client reads
//! the devices over Zenoh.

use std::path::{Path, PathBuf};
use std::time::Instant;

use troupe_client::{Client, LaserProxy};
use troupe_tests::{client_at, strings, token_events, Proc, DEADLINE};

struct Rig {
    dir: PathBuf,
}

impl Rig {
    fn new(name: &str) -> Rig {
        let dir = std::env::temp_dir().join(troupe_tests::unique_namespace(name));
        std::fs::create_dir_all(&dir).unwrap();
        Rig { dir }
    }

    /// `troupe emulate DEVICE --link DIR/DEVICE FLAGS…`, once its line is linked.
    fn emulate(&self, device: &str, flags: &[&str]) -> (Proc, PathBuf) {
        self.emulate_on(&[], device, flags)
    }

    /// [`Rig::emulate`] after the global flags `on` (`--connect …`).
    fn emulate_on(&self, on: &[&str], device: &str, flags: &[&str]) -> (Proc, PathBuf) {
        let link = self.dir.join(device);
        let mut args = strings(on);
        args.extend(strings(&[
            "emulate",
            device,
            "--link",
            link.to_str().unwrap(),
        ]));
        args.extend(strings(flags));
        let mut p = Proc::troupe("emulate", &args);
        let line = p.first_line();
        assert!(
            line.starts_with("troupe emulate: "),
            "{line:?} {}",
            p.stderr()
        );
        (p, link)
    }

    fn cfg(&self, text: &str) -> PathBuf {
        let p = self.dir.join("robot.cfg");
        std::fs::write(&p, text).unwrap();
        p
    }
}

impl Drop for Rig {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

fn launch(cfg: &Path) -> (Proc, troupe_node::zenoh::Session) {
    let ns = troupe_tests::unique_namespace("serial");
    let mut launcher = troupe_tests::launch(&ns, cfg, &["--no-bridge"]);
    let endpoint = launcher.endpoint("troupe launch: router listening on");
    let session = client_at(&endpoint, &ns);
    (launcher, session)
}

/// The laser's token: up once it scans, withdrawn when its device is
/// unplugged, up again when it is back.
fn laser_goes_away_and_back(session: &troupe_node::zenoh::Session, launcher: &mut Proc) {
    let tokens = token_events(session);
    let deadline = Instant::now() + DEADLINE * 2;
    let mut events = Vec::new();
    while events.len() < 3 {
        let Ok(Some(t)) = tokens.recv_deadline(deadline) else {
            panic!("token events so far {events:?}: {}", launcher.stderr());
        };
        if t.key_expr().as_str().contains("laser") {
            events.push(t.kind());
        }
    }
    use troupe_node::zenoh::sample::SampleKind::{Delete, Put};
    assert_eq!(events, vec![Put, Delete, Put]);
}

fn sick_cfg(link: &Path, extra: &str) -> String {
    format!(
        "driver ( name \"sicklms200\" provides [\"laser:0\"] port \"{}\" {extra} )\n",
        link.display()
    )
}

#[test]
fn sicklms200_reads_scans_from_the_emulated_scanner() {
    let rig = Rig::new("sick");
    let (_emu, link) = rig.emulate("sicklms200", &[]);
    let cfg = rig.cfg(&sick_cfg(
        &link,
        "transfer_rate 500000 resolution 100 pose [0.1 0 0]",
    ));
    let (mut launcher, session) = launch(&cfg);
    let client = Client::with_session(session, 6665);
    let laser = LaserProxy::new(&client, 0).unwrap();
    let deadline = Instant::now() + DEADLINE;
    let mut ids = Vec::new();
    while ids.len() < 5 {
        assert!(Instant::now() < deadline, "no scans: {}", launcher.stderr());
        let _ = client.read_timeout(DEADLINE);
        if let Some(s) = laser.scan() {
            if ids.last() != Some(&s.id) {
                ids.push(s.id);
            }
        }
    }
    assert!(ids.windows(2).all(|w| w[1] > w[0]), "ids count up: {ids:?}");
    let s = laser.scan().unwrap();
    assert_eq!(s.ranges.len(), 181);
    assert!((s.min_angle + 90f32.to_radians()).abs() < 1e-4);
    assert!((s.max_angle - 90f32.to_radians()).abs() < 1e-4);
    assert!((s.resolution - 1f32.to_radians()).abs() < 1e-6);
    // The emulated room: side walls 3 m to the right and left.
    assert!((s.ranges[0] - 3.0).abs() < 0.002, "{}", s.ranges[0]);
    assert!((s.ranges[180] - 3.0).abs() < 0.002, "{}", s.ranges[180]);
    let geom = laser.request_geom().unwrap();
    assert!((geom.pose.x - 0.1).abs() < 1e-9);
    let mut config = laser.request_config().unwrap();
    assert_eq!(config.max_range, 8.0);
    assert!((config.scanning_frequency - 75.0).abs() < 1e-3);

    // A client asks for 0.5°: the scanner is reconfigured, scans get 361 values.
    config.resolution = 0.5f32.to_radians();
    let now = laser.configure(config).unwrap();
    assert!((now.resolution - 0.5f32.to_radians()).abs() < 1e-6);
    let deadline = Instant::now() + DEADLINE;
    while laser.count() != 361 {
        assert!(
            Instant::now() < deadline,
            "no 0.5° scans: {}",
            launcher.stderr()
        );
        let _ = client.read_timeout(DEADLINE);
    }
    launcher.terminate();
    let log = launcher.stderr();
    assert!(log.contains("switched to 500000 baud"), "{log}");
}

#[test]
fn sicklms200_keeps_reading_through_line_faults() {
    let rig = Rig::new("sick-faults");
    let (mut emu, link) = rig.emulate(
        "sicklms200",
        &[
            "--corrupt",
            "0.2",
            "--noise",
            "0.2",
            "--truncate",
            "0.05",
            "--seed",
            "3",
        ],
    );
    let cfg = rig.cfg(&sick_cfg(&link, "transfer_rate 500000 resolution 100"));
    let (mut launcher, session) = launch(&cfg);
    let client = Client::with_session(session, 6665);
    let laser = LaserProxy::new(&client, 0).unwrap();
    scans(&client, &laser, 40, 181, &mut launcher);
    launcher.terminate();
    let log = launcher.stderr();
    assert!(
        log.contains("bad checksum"),
        "checksum errors are logged: {log}"
    );
    emu.terminate();
    let emu_log = emu.stderr();
    assert!(emu_log.contains("corrupted="), "{emu_log}");
}

#[test]
fn an_unplugged_sicklms200_is_not_ready_until_it_is_back() {
    let rig = Rig::new("sick-unplug");
    let (_emu, link) = rig.emulate(
        "sicklms200",
        &["--unplug-after", "3", "--replug-after", "1"],
    );
    let cfg = rig.cfg(&sick_cfg(&link, "transfer_rate 38400 resolution 100"));
    let (mut launcher, session) = launch(&cfg);
    laser_goes_away_and_back(&session, &mut launcher);
    launcher.terminate();
    let log = launcher.stderr();
    assert!(log.contains("laser lost"), "{log}");
    assert!(log.contains("not ready: withdrew 6665:laser:0"), "{log}");
}

fn urg_cfg(link: &Path, extra: &str) -> String {
    format!(
        "driver ( name \"urglaser\" provides [\"laser:0\"] port \"{}\" \
         min_angle -115.0 max_angle 115.0 {extra} )\n",
        link.display()
    )
}

/// Waits for `n` scans of the laser, each whole (`count` ranges).
fn scans(client: &Client, laser: &LaserProxy, n: usize, count: usize, launcher: &mut Proc) {
    let deadline = Instant::now() + DEADLINE;
    let mut ids = std::collections::BTreeSet::new();
    while ids.len() < n {
        assert!(Instant::now() < deadline, "no scans: {}", launcher.stderr());
        let _ = client.read_timeout(DEADLINE);
        if let Some(s) = laser.scan() {
            assert_eq!(s.ranges.len(), count, "every published scan is whole");
            ids.insert(s.id);
        }
    }
}

/// urglaser.cfg as Player's sample writes it (RS-232 at 115200, ±115°),
/// and the same URG on USB: Player's scan window, the room's walls where
/// they are, the URG's serial number, and the protocol each line speaks.
#[test]
fn urglaser_reads_scans_from_the_emulated_urg_over_rs232_and_usb() {
    for (usb, line, max_range) in [(false, "use_serial 1 baud 115200", 4.095), (true, "", 5.6)] {
        let rig = Rig::new("urg");
        let flags: &[&str] = if usb { &["--usb"] } else { &[] };
        let (_emu, link) = rig.emulate("urglaser", flags);
        let cfg = rig.cfg(&urg_cfg(&link, &format!("{line} pose [0.1 0 0]")));
        let (mut launcher, session) = launch(&cfg);
        let client = Client::with_session(session, 6665);
        let laser = LaserProxy::new(&client, 0).unwrap();
        // Steps 57 to 711 of 0..768, 360°/1024 apart: 654 ranges.
        scans(&client, &laser, 3, 654, &mut launcher);
        let s = laser.scan().unwrap();
        let res = (360.0f32 / 1024.0).to_radians();
        assert!((s.resolution - res).abs() < 1e-6);
        assert!(
            (s.min_angle.to_degrees() + 114.96).abs() < 0.01,
            "{}",
            s.min_angle
        );
        assert!(
            (s.max_angle.to_degrees() - 114.96).abs() < 0.01,
            "{}",
            s.max_angle
        );
        assert!((s.max_range - max_range).abs() < 1e-6, "{}", s.max_range);
        // The room's side walls, 3 m away at ±90° (steps 128 and 640).
        for i in [128 - 57, 640 - 57] {
            assert!((s.ranges[i] - 3.0).abs() < 0.002, "{i}: {}", s.ranges[i]);
        }
        // Straight behind is out of the URG's view; the back wall 2 m away
        // at ±114.96° is not, so nothing reads as out of reach there.
        assert!(s.ranges.iter().all(|&r| r > 0.5 && r <= max_range));
        let geom = laser.request_geom().unwrap();
        assert!((geom.pose.x - 0.1).abs() < 1e-9);
        let config = laser.request_config().unwrap();
        assert!((config.max_range - max_range).abs() < 1e-6);
        assert!((config.scanning_frequency - 10.0).abs() < 1e-6);
        assert_eq!(laser.request_id().unwrap(), 508_486);
        assert!(laser.configure(config).is_err(), "set_config is refused");
        launcher.terminate();
        let log = launcher.stderr();
        let spoke = if usb {
            "SCIP 2.0 over USB"
        } else {
            "SCIP 1.1 at 115200 baud"
        };
        assert!(log.contains(spoke), "{log}");
    }
}

/// A URG on USB whose line corrupts, cuts and garbles what it sends, and
/// which is unplugged and plugged back in: every published scan is whole,
/// damage is found by SCIP 2.0's checksums and logged, and the laser is not
/// live while the URG is away.
#[test]
fn urglaser_keeps_reading_through_line_faults_and_an_unplug() {
    let rig = Rig::new("urg-faults");
    let (mut emu, link) = rig.emulate(
        "urglaser",
        &[
            "--usb",
            "--corrupt",
            "0.2",
            "--noise",
            "0.2",
            "--truncate",
            "0.05",
            "--unplug-after",
            "3",
            "--replug-after",
            "1",
            "--seed",
            "5",
        ],
    );
    let cfg = rig.cfg(&urg_cfg(&link, ""));
    let (mut launcher, session) = launch(&cfg);
    let client = Client::with_session(session.clone(), 6665);
    let laser = LaserProxy::new(&client, 0).unwrap();
    laser_goes_away_and_back(&session, &mut launcher);
    scans(&client, &laser, 20, 654, &mut launcher);
    launcher.terminate();
    let log = launcher.stderr();
    assert!(log.contains("laser lost"), "{log}");
    assert!(log.contains("scan dropped: bad checksum"), "{log}");
    emu.terminate();
    let emu_log = emu.stderr();
    assert!(emu_log.contains("corrupted="), "{emu_log}");
}

/// A Pioneer with a SICK laser, as Player's pioneer.cfg lays it out, both
/// emulated: the client reads a scan, enables the motors, drives, and sees
/// odometry and sonar; when it stops commanding, the watchdog stops the robot.
#[test]
fn p2os_drives_the_emulated_pioneer_and_its_watchdog_stops_it() {
    use troupe_client::{Position2dProxy, SonarProxy};
    let rig = Rig::new("pioneer");
    let (_robot, robot_link) = rig.emulate("p2os", &[]);
    let (_laser, laser_link) = rig.emulate("sicklms200", &[]);
    let cfg = rig.cfg(&format!(
        "driver ( name \"p2os\" port \"{}\" watchdog 1.0\n  provides [\"odometry:::position2d:0\" \"compass:::position2d:1\" \"gyro:::position2d:2\" \"sonar:0\" \"power:0\" \"bumper:0\" \"aio:0\" \"dio:0\" \"gripper:::gripper:0\"] )\n{}",
        robot_link.display(),
        sick_cfg(&laser_link, "")
    ));
    let (mut launcher, session) = launch(&cfg);
    let client = Client::with_session(session, 6665);
    let base = Position2dProxy::new(&client, 0).unwrap();
    let sonar = SonarProxy::new(&client, 0).unwrap();
    let laser = LaserProxy::new(&client, 0).unwrap();
    let deadline = Instant::now() + DEADLINE;
    while base.data().is_none() || sonar.count() == 0 || laser.count() == 0 {
        assert!(Instant::now() < deadline, "no data: {}", launcher.stderr());
        let _ = client.read_timeout(DEADLINE);
    }
    assert_eq!(sonar.count(), 16, "a p3dx-sh's ring");
    assert_eq!(laser.count(), 361, "0.5° by default");
    assert_eq!(base.x(), 0.0);

    base.set_motor_enable(true).unwrap();
    let deadline = Instant::now() + DEADLINE;
    while base.x() < 0.5 {
        assert!(
            Instant::now() < deadline,
            "odometry stuck at {}: {}",
            base.x(),
            launcher.stderr()
        );
        base.set_speed(0.4, 0.0).unwrap();
        let _ = client.read_timeout(DEADLINE);
    }
    assert!((base.x_speed() - 0.4).abs() < 0.03, "{}", base.x_speed());
    assert!(base.y().abs() < 0.01 && base.yaw().abs() < 0.01);
    // Silence from the client: within the watchdog period (1 s) the robot stops.
    let deadline = Instant::now() + DEADLINE;
    while base.x_speed() != 0.0 {
        assert!(
            Instant::now() < deadline,
            "never stopped: {}",
            launcher.stderr()
        );
        let _ = client.read_timeout(DEADLINE);
    }
    launcher.terminate();
    let log = launcher.stderr();
    assert!(log.contains("watchdog"), "{log}");
    assert!(log.contains("robot stopped and closed"), "{log}");
}

/// The Erratic with the sample erratic.cfg's devices and settings, emulated:
/// the client drives it, reads odometry, sonar, IR, and points the pan-tilt.
#[test]
fn erratic_drives_the_emulated_robot_and_moves_its_servos() {
    use troupe_client::{Position2dProxy, SonarProxy};
    let rig = Rig::new("erratic");
    let (mut robot, link) = rig.emulate("erratic", &[]);
    let cfg = rig.cfg(&format!(
        "driver ( name \"erratic\" port \"{}\"\n  provides [\"position2d:0\" \"power:0\" \"aio:0\" \"ir:0\" \"sonar:0\" \"ptz:0\" \"tilt:::ptz:1\"]\n  max_trans_vel 0.5 max_rot_vel 200 trans_acc 0.5 rot_acc 100\n  pid_trans_p 40 pid_trans_v 100 pid_rot_p 40 pid_rot_v 100\n  motor_pwm_frequency 16000 motor_pwm_max_on 0.7 direct_wheel_vel_control 0 )\n",
        link.display()
    ));
    let (mut launcher, session) = launch(&cfg);
    let client = Client::with_session(session.clone(), 6665);
    let base = Position2dProxy::new(&client, 0).unwrap();
    let sonar = SonarProxy::new(&client, 0).unwrap();
    let deadline = Instant::now() + DEADLINE;
    while base.data().is_none() || sonar.count() == 0 {
        assert!(Instant::now() < deadline, "no data: {}", launcher.stderr());
        let _ = client.read_timeout(DEADLINE);
    }
    assert_eq!(sonar.count(), 8);
    // Rev H's sonar 3 looks straight ahead from 0.21 m: the wall is 4 m away.
    assert!(
        (sonar.range(3).unwrap() - 3.79).abs() < 0.01,
        "{:?}",
        sonar.range(3)
    );

    base.set_motor_enable(true).unwrap();
    let deadline = Instant::now() + DEADLINE;
    while base.x() < 0.3 || base.yaw() < 0.2 {
        assert!(
            Instant::now() < deadline,
            "pose {:?}: {}",
            base.data(),
            launcher.stderr()
        );
        base.set_speed(0.3, 0.3).unwrap();
        let _ = client.read_timeout(DEADLINE);
    }
    base.set_speed(0.0, 0.0).unwrap();

    // Pan-tilt: a command moves the servos and the commanded angles come back.
    let ptz = troupe_client::PtzProxy::new(&client, 0).unwrap();
    ptz.set_pan_tilt(0.3, -0.2).unwrap();
    let deadline = Instant::now() + DEADLINE;
    while ptz.data().is_none() {
        assert!(
            Instant::now() < deadline,
            "no ptz data: {}",
            launcher.stderr()
        );
        let _ = client.read_timeout(DEADLINE);
    }
    let d = ptz.data().unwrap();
    assert!(
        (f64::from(d.pan) - 17f64.to_radians()).abs() < 1e-3,
        "{d:?}"
    );
    launcher.terminate();
    robot.terminate();
    let log = robot.stderr();
    assert!(
        log.contains("servo=2"),
        "two servo commands reached the robot: {log}"
    );
}

/// The whole hardware path in a simulated world: Stage's r0 laser feeds the
/// emulated LMS200 (`--stage-laser`), whose telegrams the sicklms200 driver
/// reads over the pseudo-terminal and publishes; the client sees the same
/// ranges on the driver's laser as on Stage's.
#[test]
fn an_emulated_lms200_backed_by_stage_sees_the_simulated_world() {
    let rig = Rig::new("sick-stage");
    let link = rig.dir.join("sicklms200");
    let world = Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds/simple.world");
    let cfg = rig.cfg(&format!(
        "driver ( name \"stage\" provides [\"simulation:0\"] worldfile \"{}\" )\n\
         driver ( name \"stage\" provides [\"position2d:0\" \"ranger:0\" \"ranger:1\"] model \"r0\" )\n\
         driver ( name \"rangertolaser\" requires [\"ranger:1\"] provides [\"laser:1\"] )\n{}",
        world.display(),
        sick_cfg(&link, "transfer_rate 500000 resolution 100")
    ));
    let ns = troupe_tests::unique_namespace("sick-stage");
    let mut launcher = troupe_tests::launch(&ns, &cfg, &["--no-bridge"]);
    let endpoint = launcher.endpoint("troupe launch: router listening on");
    let mut args = strings(&["--connect", &endpoint, "--namespace", &ns, "--no-multicast"]);
    args.extend(strings(&[
        "emulate",
        "sicklms200",
        "--link",
        link.to_str().unwrap(),
        "--stage-laser",
        "6665:laser:1",
    ]));
    let mut emu = Proc::troupe("emulate", &args);
    assert!(emu.first_line().starts_with("troupe emulate: "));

    let client = Client::with_session(client_at(&endpoint, &ns), 6665);
    let serial = LaserProxy::new(&client, 0).unwrap();
    let stage = LaserProxy::new(&client, 1).unwrap();
    let deadline = Instant::now() + DEADLINE * 2;
    let mut last = String::new();
    loop {
        if Instant::now() >= deadline {
            emu.terminate();
            panic!(
                "the serial laser never matched Stage's: {last}\n{}\n{}",
                emu.stderr(),
                launcher.stderr()
            );
        }
        let _ = client.read_timeout(DEADLINE);
        let (Some(a), Some(b)) = (serial.scan(), stage.scan()) else {
            continue;
        };
        if a.ranges.len() != 181 || b.ranges.is_empty() {
            continue;
        }
        // Each 1° value against Stage's nearest beam: the same range to the
        // millimetre, or out of reach on both (r1 wanders through the view,
        // so most, not all, must agree).
        let near = |i: usize| {
            let angle = f64::from(a.min_angle) + i as f64 * f64::from(a.resolution);
            let j = ((angle - f64::from(b.min_angle)) / f64::from(b.resolution)).round() as usize;
            b.ranges.get(j).copied()
        };
        let same = |i: usize| {
            near(i).is_some_and(|r| {
                if r >= b.max_range {
                    a.ranges[i] >= 8.0
                } else {
                    (a.ranges[i] - r).abs() < 0.01
                }
            })
        };
        let agree = (0..181).filter(|&i| same(i)).count();
        if agree >= 170 {
            break;
        }
        let off: Vec<(usize, f32, Option<f32>)> = (0..181)
            .map(|i| (i, a.ranges[i], near(i)))
            .filter(|&(i, _, _)| !same(i))
            .take(8)
            .collect();
        last = format!(
            "{agree} of 181 agree; off: {off:?}; {} beams from {} by {}, max {}",
            b.ranges.len(),
            b.min_angle,
            b.resolution,
            b.max_range
        );
    }
    // What both saw, as points in the laser's frame (the client API's
    // nalgebra view): the walls within range, the same ones on both.
    let (a, b) = (serial.points(), stage.points());
    assert!(!a.is_empty() && !b.is_empty());
    let max = stage.max_range();
    assert!(b.iter().all(|p| p.coords.norm() < max), "{b:?}");
    let nearest = |p: &troupe_client::nalgebra::Point2<f64>| {
        b.iter()
            .map(|q| (p - q).norm())
            .fold(f64::INFINITY, f64::min)
    };
    let close = a.iter().filter(|p| nearest(p) < 0.1).count();
    assert!(
        close * 10 >= a.len() * 9,
        "{close} of {} serial points on Stage's",
        a.len()
    );
    launcher.terminate();
    emu.terminate();
}

/// The whole robot path in a simulated world: `troupe emulate p2os
/// --stage-model r0` and `troupe emulate sicklms200 --stage-model r0` are
/// Stage's r0 (on robot port 6666) to the p2os and sicklms200 drivers (on
/// 6665), as a Pioneer with a SICK laser. A client on 6665 drives through
/// p2os → serial → emulator → Stage, and reads r0's sonars, laser and
/// odometry back the same way; the gripper's paddles close through the
/// same line.
#[test]
fn an_emulated_pioneer_backed_by_stage_drives_the_simulated_robot() {
    use troupe_client::{GripperProxy, Position2dProxy, RangerProxy, SonarProxy};
    let rig = Rig::new("p2os-stage");
    let link = rig.dir.join("p2os");
    let laser_link = rig.dir.join("sicklms200");
    let world = Path::new(env!("CARGO_MANIFEST_DIR")).join("../worlds/simple.world");
    let cfg = rig.cfg(&format!(
        "driver ( name \"stage\" provides [\"6666:simulation:0\"] worldfile \"{}\" )\n\
         driver ( name \"stage\" provides [\"6666:position2d:0\" \"6666:ranger:0\" \"6666:ranger:1\"] model \"r0\" )\n\
         driver ( name \"p2os\" provides [\"odometry:::position2d:0\" \"sonar:0\" \"gripper:::gripper:0\"] port \"{}\" )\n{}",
        world.display(),
        link.display(),
        sick_cfg(&laser_link, "transfer_rate 500000 resolution 100")
    ));
    let ns = troupe_tests::unique_namespace("p2os-stage");
    let mut launcher = troupe_tests::launch(&ns, &cfg, &["--no-bridge"]);
    let endpoint = launcher.endpoint("troupe launch: router listening on");
    let sim = Client::with_session(client_at(&endpoint, &ns), 6666);
    let truth = Position2dProxy::new(&sim, 0).unwrap();
    let stage_sonar = RangerProxy::new(&sim, 0).unwrap();
    // Stage is up once r0 reports.
    let deadline = Instant::now() + DEADLINE;
    while truth.data().is_none() {
        assert!(Instant::now() < deadline, "no Stage: {}", launcher.stderr());
        let _ = sim.read_timeout(DEADLINE);
    }
    let on = ["--connect", &endpoint, "--namespace", &ns, "--no-multicast"];
    let backed = ["--stage-model", "r0", "--stage-sim", "6666:simulation:0"];
    let (mut emu, _) = rig.emulate_on(&on, "p2os", &backed);
    let (mut laser_emu, _) = rig.emulate_on(&on, "sicklms200", &backed);

    let client = Client::with_session(client_at(&endpoint, &ns), 6665);
    let laser = LaserProxy::new(&client, 0).unwrap();
    let stage_laser = RangerProxy::new(&sim, 1).unwrap();
    let base = Position2dProxy::new(&client, 0).unwrap();
    let sonar = SonarProxy::new(&client, 0).unwrap();
    let gripper = GripperProxy::new(&client, 0).unwrap();
    let fail = |what: &str, emu: &mut Proc, launcher: &mut Proc| -> ! {
        emu.terminate();
        panic!("{what}\n{}\n{}", emu.stderr(), launcher.stderr());
    };

    // The sonars through the serial line are Stage's, to the millimetre
    // (r1 wanders and may pass through a beam: most, not all, agree).
    let deadline = Instant::now() + DEADLINE * 2;
    loop {
        if Instant::now() >= deadline {
            let seen = format!("{:?} vs {:?}", sonar.count(), stage_sonar.ranges());
            fail(
                &format!("sonars never matched: {seen}"),
                &mut emu,
                &mut launcher,
            );
        }
        let _ = client.read_timeout(DEADLINE);
        let stage = stage_sonar.ranges();
        if sonar.count() != 16 || stage.len() != 16 {
            continue;
        }
        let agree = (0..16)
            .filter(|&i| sonar.range(i).is_some_and(|r| (r - stage[i]).abs() < 0.002))
            .count();
        if agree >= 14 {
            break;
        }
    }

    // The laser through its serial line is Stage's ranger:1 (180 beams
    // over 180°) read at each whole degree, to the millimetre (most beams:
    // r1 wanders).
    let deadline = Instant::now() + DEADLINE * 2;
    loop {
        if Instant::now() >= deadline {
            laser_emu.terminate();
            let seen = format!("{:?}", laser.scan().map(|s| s.ranges.len()));
            let why = format!("the laser never matched: {seen}\n{}", laser_emu.stderr());
            fail(&why, &mut emu, &mut launcher);
        }
        let _ = client.read_timeout(DEADLINE);
        let (Some(scan), stage) = (laser.scan(), stage_laser.ranges()) else {
            continue;
        };
        if scan.ranges.len() != 181 || stage.len() != 180 {
            continue;
        }
        let step = std::f64::consts::PI / 179.0;
        let agree = (0..181)
            .filter(|&i| {
                let j = ((i as f64).to_radians() / step).round() as usize;
                let (a, b) = (f64::from(scan.ranges[i]), stage[j.min(179)]);
                (a >= 8.0 && b >= 8.0) || (a - b).abs() < 0.002
            })
            .count();
        if agree >= 170 {
            break;
        }
    }

    // Drive forward through p2os: Stage's r0 moves, and the odometry that
    // comes back over the line moved as far.
    let start = truth.data().unwrap().pose;
    let odom0 = base.x();
    base.set_motor_enable(true).unwrap();
    base.set_speed(0.3, 0.0).unwrap();
    gripper.close().unwrap();
    let deadline = Instant::now() + DEADLINE * 2;
    loop {
        if Instant::now() >= deadline {
            fail("r0 did not move 0.5 m", &mut emu, &mut launcher);
        }
        let _ = client.read_timeout(DEADLINE);
        let p = truth.data().unwrap().pose;
        if (p.x - start.x).hypot(p.y - start.y) >= 0.5 && base.x() - odom0 >= 0.5 {
            break;
        }
    }
    base.set_speed(0.0, 0.0).unwrap();
    let moved = |p: troupe_msgs::Pose2d| (p.x - start.x).hypot(p.y - start.y);
    let deadline = Instant::now() + DEADLINE;
    loop {
        if Instant::now() >= deadline {
            fail("r0 did not stop", &mut emu, &mut launcher);
        }
        let _ = client.read_timeout(DEADLINE);
        let (p, v) = (truth.data().unwrap(), base.data().unwrap());
        if p.vel.x == 0.0
            && v.vel.x == 0.0
            && gripper.state() == troupe_msgs::gripper::State::Closed
        {
            // Stopped on both sides: the serial odometry agrees with Stage's
            // travel to the counters' resolution (and one SIP of lag).
            let serial = v.pose.x - odom0;
            if (serial - moved(p.pose)).abs() < 0.01 {
                break;
            }
        }
    }
    launcher.terminate();
    emu.terminate();
    laser_emu.terminate();
}

/// Player's own wbr914.cfg, its port pointed at `troupe emulate wbr914`: a
/// Player client through the bridge reads the IR, analog and digital
/// inputs, enables the motors and drives, and sets digital outputs that
/// the emulated board's loopback brings back.
#[test]
fn players_wbr914_cfg_drives_the_emulated_914_through_the_bridge() {
    use crate::player::{Frame, Player, DATA, RESP_ACK};
    use troupe_msgs::{Device, Interface};
    let Some(sample) = troupe_tests::compat("player-cfg/wbr914.cfg") else {
        return;
    };
    let rig = Rig::new("wbr914");
    let (mut robot, link) = rig.emulate("wbr914", &[]);
    let text = std::fs::read_to_string(&sample).unwrap();
    let text = text.replace("/dev/ttyUSB0", link.to_str().unwrap());
    assert!(text.contains(link.to_str().unwrap()), "{text}");
    let cfg = rig.cfg(&text);
    let ns = troupe_tests::unique_namespace("wbr914");
    let mut launcher = troupe_tests::launch(&ns, &cfg, &[]);
    let (_, addr) = troupe_tests::launch_ports(&mut launcher);
    let mut p = Player::connect(addr, 6665);
    let dev = |i: Interface| Device::new(6665, i, 0);
    let code = |i: Interface| u32::from(i.code());
    for i in [
        Interface::Position2d,
        Interface::Ir,
        Interface::Aio,
        Interface::Dio,
    ] {
        p.open(dev(i));
    }
    let next_data = |p: &mut Player, i: Interface, want: &dyn Fn(&Frame) -> bool| loop {
        let m = if p.seen.is_empty() {
            p.recv()
        } else {
            p.seen.remove(0)
        };
        if m.sig() == (code(i), 0, DATA, 1) && want(&m) {
            return m;
        }
    };
    let f32_at = |m: &Frame, at: usize| f32::from_be_bytes(m.body[at..at + 4].try_into().unwrap());
    // IR: 8 volts then 8 ranges; sensor 2 looks at a wall out of its reach.
    let ir = next_data(&mut p, Interface::Ir, &|_| true);
    assert_eq!((ir.u32_at(0), ir.u32_at(40)), (8, 8), "{ir:?}");
    let range2 = f32_at(&ir, 48 + 2 * 4);
    assert!((0.75..0.85).contains(&range2), "{range2}");
    let aio = next_data(&mut p, Interface::Aio, &|_| true);
    assert_eq!(aio.u32_at(0), 8);
    assert!((f32_at(&aio, 8 + 4) - 128.0 * 5.0 / 1023.0).abs() < 1e-4);

    // Motors on, then forward at 0.2 m/s.
    let r = p.request(dev(Interface::Position2d), 2, &1u32.to_be_bytes());
    assert_eq!(r.kind(), RESP_ACK, "motor power: {r:?}");
    let mut vel = Vec::new();
    for v in [0.2f64, 0.0, 0.0] {
        vel.extend_from_slice(&v.to_be_bytes());
    }
    vel.extend_from_slice(&1u32.to_be_bytes());
    p.send(code(Interface::Position2d), 0, 2, 1, &vel);
    let pos = next_data(&mut p, Interface::Position2d, &|m| m.f64_at(0) > 0.1);
    assert!(
        (pos.f64_at(24) - 0.2).abs() < 0.01,
        "speed {}",
        pos.f64_at(24)
    );

    // Digital outputs 0–7 to 0x5A; the loopback brings them back as inputs.
    let mut bits = 8u32.to_be_bytes().to_vec();
    bits.extend_from_slice(&0x5Au32.to_be_bytes());
    p.send(code(Interface::Dio), 0, 2, 1, &bits);
    next_data(&mut p, Interface::Dio, &|m| {
        (m.u32_at(0), m.u32_at(4)) == (16, 0x5A)
    });

    assert!(launcher.terminate().success(), "{}", launcher.stderr());
    let log = launcher.stderr();
    assert!(log.contains("robot stopped, motors off"), "{log}");
    robot.terminate();
    let log = robot.stderr();
    assert!(log.contains("motors_on=false"), "{log}");
}
