//! The driver in the harness, in a room of four walls that a laser model
//! casts into: the robot drives loops with odometry that reads its turns
//! 5% long, and the served map and the corrected pose are judged against
//! the room.

use troupe_geom::ray_to_box;
use troupe_node::testing::Harness;

use super::*;
use troupe_msgs::Pose2d;

const ODOM: Device = Device::new(6665, Interface::Position2d, 0);
const LASER: Device = Device::new(6665, Interface::Laser, 0);
const MAP: Device = Device::new(6665, Interface::Map, 0);
const POSE: Device = Device::new(6665, Interface::Position2d, 1);

/// The room: x from -4 to 4, y from -3 to 3, and a pillar.
const ROOM: (f64, f64, f64, f64) = (-4.0, 4.0, -3.0, 3.0);
const PILLAR: (f64, f64, f64, f64) = (1.0, 1.6, -0.5, 0.1);

fn range(x: f64, y: f64, a: f64) -> f64 {
    let wall = ray_to_box(x, y, a, ROOM);
    // The pillar, seen from outside: the nearest crossing of its sides.
    let (x0, x1, y0, y1) = PILLAR;
    let (c, s) = (a.cos(), a.sin());
    let mut best = wall;
    for t in [(x0 - x) / c, (x1 - x) / c] {
        if t > 0.0 && t.is_finite() && (y0..=y1).contains(&(y + t * s)) {
            best = best.min(t);
        }
    }
    for t in [(y0 - y) / s, (y1 - y) / s] {
        if t > 0.0 && t.is_finite() && (x0..=x1).contains(&(x + t * c)) {
            best = best.min(t);
        }
    }
    best
}

fn near_a_wall(x: f64, y: f64) -> bool {
    let d_room = [x - ROOM.0, ROOM.1 - x, y - ROOM.2, ROOM.3 - y]
        .iter()
        .fold(f64::MAX, |a, &b| a.min(b.abs()));
    let (x0, x1, y0, y1) = PILLAR;
    let dx = (x0 - x).max(0.0).max(x - x1);
    let dy = (y0 - y).max(0.0).max(y - y1);
    d_room <= 0.1 || dx.hypot(dy) <= 0.1
}

#[test]
fn the_map_grows_as_the_robot_drives_and_its_pose_is_corrected() {
    let mut h = Harness::<SlamNode>::from_json(
        r#"{"name":"slam","requires":["odometry:::position2d:0","laser:0"],
            "provides":["map:0","position2d:1"],"options":{"laser_pose":[0,0,0],"map_every":5}}"#,
    )
    .unwrap();
    let start = Pose::new(-2.0, -1.5, 0.0);
    let (mut truth, mut odom) = (start, Pose::default());
    let dt = 0.1;
    for k in 0..3000u32 {
        let t = f64::from(k) * dt;
        // Loops around the pillar: 0.4 m/s, turning at 0.25 rad/s.
        let (v, w) = (0.4, 0.25);
        truth = truth.compose(&Pose::new(v * dt, 0.0, w * dt));
        odom = odom.compose(&Pose::new(v * dt, 0.0, w * dt * 1.05));
        h.set_time(t);
        h.input(
            ODOM,
            &position2d::Data {
                pose: odom.into(),
                vel: Pose2d::new(v, 0.0, w),
                stall: false,
            },
        )
        .unwrap();
        let ranges: Vec<f32> = (0..181)
            .map(|i| {
                let a = truth.yaw - std::f64::consts::FRAC_PI_2 + f64::from(i).to_radians();
                range(truth.x, truth.y, a).min(8.0) as f32
            })
            .collect();
        h.input(
            LASER,
            &laser::Scan {
                min_angle: -std::f32::consts::FRAC_PI_2,
                max_angle: std::f32::consts::FRAC_PI_2,
                resolution: 1f32.to_radians(),
                max_range: 8.0,
                ranges,
                ..Default::default()
            },
        )
        .unwrap();
    }
    // The map answers as mapfile does.
    let p = h.request(MAP, &map::GetInfo).unwrap();
    let info: map::Info = h.reply(p).unwrap().unwrap();
    assert!(info.width > 100 && info.height > 80, "{info:?}");
    // And says it grew: its info on its data key at each refresh (every 5
    // scans, and after each closure), the last as served.
    let said: Vec<map::Info> = h.published(MAP);
    assert!(said.len() >= 3000 / 5, "{} refreshes said", said.len());
    assert_eq!(said.last(), Some(&info));
    assert!(said[0].width * said[0].height < info.width * info.height);
    let occupied = h.driver().map().occupied();
    assert!(occupied.len() > 200, "{} occupied cells", occupied.len());
    // In the room's frame (the map's is the odometry's at the start).
    let on_walls = occupied
        .iter()
        .filter(|&&(x, y)| {
            let (wx, wy) = start.apply(x, y);
            near_a_wall(wx, wy)
        })
        .count();
    let accuracy = on_walls as f64 / occupied.len() as f64;
    assert!(accuracy > 0.9, "{accuracy:.3} of the map's cells on a wall");
    // The corrected pose ends where the robot is; odometry does not.
    let last: position2d::Data = h.published(POSE).pop().unwrap();
    let corrected = start.compose(&last.pose.into());
    let raw = start.compose(&odom);
    let miss = |p: Pose| (p.x - truth.x).hypot(p.y - truth.y);
    assert!(miss(raw) > 0.5, "odometry ends {:.2} m off", miss(raw));
    assert!(
        miss(corrected) < 0.15,
        "the corrected pose ends {:.2} m off",
        miss(corrected)
    );
    assert!(h.driver().slam().closures() > 0);
}

#[test]
fn options_are_checked() {
    let h = |opts: &str| {
        Harness::<SlamNode>::from_json(&format!(
            r#"{{"name":"slam","requires":["position2d:0","laser:0"],"provides":["map:0"],"options":{{{opts}}}}}"#
        ))
    };
    assert!(h("").is_ok());
    let e = h(r#""resolution":0"#).err().unwrap().to_string();
    assert!(e.contains("resolution must be a positive"), "{e}");
    let e = h(r#""laser_pose":[1,2]"#).err().unwrap().to_string();
    assert!(e.contains("laser_pose takes [x y yaw]"), "{e}");
}

/// The log the issue asked for, generated: Stage's own simple.world (the
/// 16 m cave, ../shared/compat), r0 driven by its own `wander` for 905
/// simulated s with Stage's error as `odom_error [0.03 0.03 0.00 0.05]`
/// sets it (distance 3% long, turns off by 0.05°), 10 scans a second.
/// Offline the map must have 90% of its occupied cells within 10 cm of a
/// wall and cover 75% of the walls the laser saw; the live driver, fed the
/// same log scan by scan, within 5 points of it on both.
#[test]
fn a_stage_error_log_of_stage_s_cave_maps_offline_and_online_to_the_figures() {
    use troupe_map::eval;
    use troupe_map::simulate::{simulate, Driver, Setup};
    use troupe_map::source::{self, Select};
    let Some(world) = troupe_node::testing::compat("stage/simple.world") else {
        return;
    };
    let run = simulate(
        troupe_stage::world::load(&world).unwrap(),
        &Setup {
            robot: "r0".into(),
            seconds: 905.0,
            odom_error: [0.03, 0.03, 0.05f64.to_radians()],
            every: 0.1,
            driver: Driver::Own,
        },
    )
    .unwrap();
    let dir = std::env::temp_dir().join(format!("troupe-slam-stage-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let log = dir.join("cave.log");
    std::fs::write(&log, &run.log).unwrap();
    let rec = source::read(&[log], &Select::default()).unwrap();
    let f = run.frame(&rec);
    let built = troupe_map::build(&rec, Params::default(), |_, _| {});
    let offline = eval::score(&built.grid.occupied(), &run.obstacles, &run.seen, f, 0.1);
    let raw = eval::score(
        &troupe_map::odometry_map(&rec, 0.05).occupied(),
        &run.obstacles,
        &run.seen,
        f,
        0.1,
    );
    let h = replay(rec.sensor, rec.placed(), |_| {}).unwrap();
    let occupied = h.driver().map().occupied();
    let online = eval::score(&occupied, &run.obstacles, &run.seen, f, 0.1);
    eprintln!(
        "cave, 905 s, {:.0} m: offline accuracy {:.3}, coverage {:.3}; online {:.3}, {:.3}; odometry alone {:.3}, {:.3}; {} closures",
        run.driven,
        offline.accuracy,
        offline.coverage,
        online.accuracy,
        online.coverage,
        raw.accuracy,
        raw.coverage,
        built.slam.closures()
    );
    assert!(run.driven > 100.0, "r0 wandered {:.0} m", run.driven);
    // The test can fail: odometry alone is far from it.
    assert!(raw.accuracy < 0.6, "odometry alone {:.3}", raw.accuracy);
    assert!(offline.accuracy >= 0.9, "accuracy {:.3}", offline.accuracy);
    assert!(offline.coverage >= 0.75, "coverage {:.3}", offline.coverage);
    assert!(
        online.accuracy >= offline.accuracy - 0.05,
        "online {:.3}",
        online.accuracy
    );
    assert!(
        online.coverage >= offline.coverage - 0.05,
        "online {:.3}",
        online.coverage
    );
}
