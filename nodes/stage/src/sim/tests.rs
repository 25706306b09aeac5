use super::*;
use std::f64::consts::FRAC_PI_2;

fn sim(name: &str, text: &str) -> Sim {
    let dir = std::env::temp_dir().join(format!("troupe-sim-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("t.world");
    std::fs::write(&p, text).unwrap();
    let w = crate::world::load(&p).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    Sim::new(w).unwrap()
}

const ROOM: &str = "resolution 0.02\ninterval_sim 100\n\
    model ( name \"wall\" pose [5 0 0 0] size [0.2 10 1] )\n";

fn steps(s: &mut Sim, n: usize) {
    for _ in 0..n {
        s.step();
    }
}

/// A ranger's readings lie sensor after sensor: each sensor reads and
/// writes its own stretch, a sensor of no rays included, whether the
/// sensors have a ray each or many.
#[test]
fn readings_keep_each_sensor_to_its_own_stretch() {
    let sensor = |samples: usize, far: f64| Sensor {
        pose: Pose::default(),
        z: 0.0,
        size: [0.1; 3],
        range: (0.0, far),
        fov: 1.0,
        samples,
    };
    let mut rd = Readings::new(&[
        sensor(3, 8.0),
        sensor(1, 5.0),
        sensor(0, 4.0),
        sensor(2, 2.0),
    ]);
    assert_eq!(rd.len(), 4);
    assert_eq!(rd.sensor(0).ranges, &[8.0; 3]);
    assert_eq!(rd.sensor(2).ranges, &[] as &[f64]);
    assert_eq!(rd.get(4), None);
    let (ranges, intensities) = rd.sensor_mut(3);
    ranges.copy_from_slice(&[1.5, 1.25]);
    intensities[1] = 0.5;
    assert_eq!(rd.sensor(3).ranges, &[1.5, 1.25]);
    assert_eq!(rd.sensor(3).intensities, &[0.0, 0.5]);
    assert_eq!(rd.sensor(1).ranges, &[5.0]);
    let firsts: Vec<f64> = (0..5).map(|i| rd.first_range(i)).collect();
    assert_eq!(firsts, [8.0, 5.0, 0.0, 1.5, 0.0]);
    assert_eq!(
        rd.iter().map(|r| r.ranges.len()).collect::<Vec<_>>(),
        [3, 1, 0, 2]
    );
    // A ray each: sensor k's reading is the k-th.
    let mut ring = Readings::new(&[sensor(1, 2.0), sensor(1, 2.0), sensor(1, 2.0)]);
    ring.sensor_mut(1).0[0] = 0.75;
    let firsts: Vec<f64> = (0..4).map(|i| ring.first_range(i)).collect();
    assert_eq!(firsts, [2.0, 0.75, 2.0, 0.0]);
    // As many rays as sensors, but not one each: the second has none.
    let uneven = Readings::new(&[sensor(2, 3.0), sensor(0, 1.0)]);
    assert_eq!([uneven.first_range(0), uneven.first_range(1)], [3.0, 0.0]);
    assert!(Readings::default().is_empty());
}

/// Fans start their rays beyond the open space around them; every
/// reading stays what a ray walked from its origin reads, with robots
/// crowding each other, a box and the wall nearby.
#[test]
fn fans_read_as_rays_walked_from_their_origin() {
    let mut text = format!("{ROOM}model ( name \"box\" pose [2 1 0 30] size [0.5 0.3 0.5] )\n");
    for k in 0..12 {
        let (x, y, a) = (
            1.0 + 0.35 * f64::from(k % 4 * 3),
            0.45 * f64::from(k / 4) - 0.5,
            37 * k,
        );
        text += &format!(
            "position ( name \"r{k}\" pose [{x} {y} 0 {a}] size [0.3 0.3 0.2] \
            ranger ( sensor ( pose [0.1 0 0 0] range [0.02 6] fov 270 samples 271 ) ) \
            acceleration_bounds [-9 9 -9 9 -9 9 -900 900] )\n"
        );
    }
    let mut s = sim("fans", &text);
    let rangers = s.crew.rangers().to_vec();
    let mut skipped = 0.0;
    for round in 0..4 {
        for (i, b) in s.bases.iter_mut().enumerate() {
            let turn = if (i + round) % 2 == 0 { 0.6 } else { -0.6 };
            b.cmd = Some(Command::Vel(Pose::new(0.3, 0.0, turn)));
        }
        steps(&mut s, 3);
        for &r in &rangers {
            let (g, z) = s.world.global(&s.poses, r);
            let sensor = &s.world.models[r].sensors[0];
            let rz = z + sensor.z + sensor.size[2] / 2.0;
            let accept = s.ranger_sees(r, rz);
            let o = g.compose(&s.world.models[r].origin).compose(&sensor.pose);
            skipped += s.open_around(o.x, o.y, accept);
            for (k, &got) in s.readings[r].sensor(0).ranges.iter().enumerate() {
                let a = o.yaw - sensor.fov / 2.0 + sensor.fov * k as f64 / 270.0;
                let want = s
                    .cast(
                        (o.x, o.y),
                        unit(a),
                        (0.0, sensor.range.1),
                        Some(rz),
                        accept,
                        0,
                    )
                    .map_or(sensor.range.1, |h| h.range.max(sensor.range.0));
                assert!(
                    (got - want).abs() < 1e-9,
                    "ranger {r} ray {k}: {got} vs {want}"
                );
            }
        }
    }
    assert!(skipped > 1.0, "the fans skipped only {skipped} m in all");
}

#[test]
fn diff_drive_moves_as_commanded() {
    let mut s = sim("diff", &format!("{ROOM}position ( name \"r\" pose [0 0 0 0] size [0.4 0.4 0.2] acceleration_bounds [-9 9 -9 9 -9 9 -900 900] )\n"));
    s.bases[0].cmd = Some(Command::Vel(Pose::new(0.5, 0.3, 0.0)));
    steps(&mut s, 10);
    let p = s.global(s.bases[0].model);
    // 1 s at 0.5 m/s; a diff drive ignores the sideways speed.
    assert!((p.x - 0.5).abs() < 1e-9 && p.y.abs() < 1e-9, "{p:?}");
    s.bases[0].cmd = Some(Command::Vel(Pose::new(0.0, 0.0, FRAC_PI_2)));
    steps(&mut s, 10);
    assert!((s.global(s.bases[0].model).yaw - FRAC_PI_2).abs() < 1e-9);
    assert!(
        (s.bases[0].odom.yaw - FRAC_PI_2).abs() < 1e-9,
        "gps odometry follows"
    );
}

#[test]
fn omni_drive_moves_sideways_and_car_turns() {
    let mut s = sim("omni", &format!("{ROOM}position ( name \"r\" drive \"omni\" size [0.4 0.4 0.2] acceleration_bounds [-9 9 -9 9 -9 9 -900 900] )\n"));
    s.bases[0].cmd = Some(Command::Vel(Pose::new(0.0, 0.5, 0.0)));
    steps(&mut s, 10);
    let p = s.global(s.bases[0].model);
    assert!(p.x.abs() < 1e-9 && (p.y - 0.5).abs() < 1e-9, "{p:?}");
    let mut c = sim("car", &format!("{ROOM}position ( name \"r\" drive \"car\" wheelbase 1 size [0.4 0.4 0.2] acceleration_bounds [-9 9 -9 9 -9 9 -900 900] velocity_bounds [-1 1 -1 1 -1 1 -900 900] )\n"));
    c.bases[0].cmd = Some(Command::Car(0.5, std::f64::consts::FRAC_PI_4));
    steps(&mut c, 10);
    // yaw rate = v·tan(steer)/wheelbase = 0.5 rad/s.
    assert!((c.global(c.bases[0].model).yaw - 0.5).abs() < 1e-9);
}

#[test]
fn velocity_bounds_hold_and_speeds_are_taken_at_once() {
    // As Stage's velocity control: acceleration bounds do not apply.
    let mut s = sim("bounds", &format!("{ROOM}position ( name \"r\" size [0.4 0.4 0.2] velocity_bounds [-0.5 0.5 0 0 0 0 -90 90] acceleration_bounds [-1 1 0 0 0 0 -90 90] )\n"));
    s.bases[0].cmd = Some(Command::Vel(Pose::new(2.0, 0.0, -3.0)));
    s.step();
    assert!((s.bases[0].vel.x - 0.5).abs() < 1e-9, "capped at 0.5 m/s");
    let quarter = -std::f64::consts::FRAC_PI_2;
    assert!(
        (s.bases[0].vel.yaw - quarter).abs() < 1e-9,
        "capped at 90°/s"
    );
    s.bases[0].cmd = Some(Command::Vel(Pose::new(0.1, 0.0, 0.0)));
    s.step();
    assert!((s.bases[0].vel.x - 0.1).abs() < 1e-9, "slowed at once");
}

/// What a base reports as its pose: under `gps`, its true pose in the
/// frame of `localization_origin`; under `odom`, its commanded moves with
/// their `odom_error`, summed while it moves and frozen while it stalls.
#[test]
fn odometry_reports_each_localization_as_stage_does() {
    let bot = |name: &str, y: f64, settings: &str| {
        format!("position ( name \"{name}\" pose [3 {y} 0 0] size [0.4 0.4 0.2] {settings} )\n")
    };
    let world = format!(
        "{ROOM}{}{}{}{}",
        bot(
            "gps",
            0.0,
            "localization \"gps\" localization_origin [1 2 0 90]"
        ),
        bot(
            "odom",
            2.0,
            "localization \"odom\" odom_error [0.1 0 0 0.2]"
        ),
        bot("d1", -2.0, "localization \"odom\""),
        bot("d2", -4.0, "localization \"odom\""),
    );
    let mut s = sim("odometry", &world);
    for b in &mut s.bases {
        b.cmd = Some(Command::Vel(Pose::new(1.0, 0.0, 0.1)));
    }
    s.step();
    let origin = Pose::new(1.0, 2.0, FRAC_PI_2);
    let truth = s.global(s.bases[0].model);
    let want = origin.inverse().compose(&truth);
    let got = s.bases[0].odom;
    assert!(
        (got.x - want.x).abs() < 1e-12 && (got.y - want.y).abs() < 1e-12,
        "gps: {got:?}, not {want:?}"
    );
    assert!((got.yaw - want.yaw).abs() < 1e-12);
    // From (0, 0, 0) in its own frame: 0.1 m forward at 110%, and 0.01
    // rad turned with the error on turns, which Stage reads as an angle
    // (`Pose::Load`'s "llla": 0.2 is 0.2°).
    let odom = s.bases[1].odom;
    assert!(
        (odom.x - 0.11).abs() < 1e-12 && odom.y.abs() < 1e-12,
        "{odom:?}"
    );
    let turned = 0.01 * (1.0 + 0.2f64.to_radians());
    assert!((odom.yaw - turned).abs() < 1e-12, "{odom:?}");
    // Without `odom_error`, each robot's is drawn as Stage draws it:
    // within ±1.5% on distances and ±2.5% on turns, robot by robot.
    let (d1, d2) = (s.bases[2].odom, s.bases[3].odom);
    for d in [d1, d2] {
        assert!((d.x / 0.1 - 1.0).abs() <= 0.015, "{d:?}");
        assert!((d.yaw / 0.01 - 1.0).abs() <= 0.025, "{d:?}");
    }
    assert_ne!(d1.x, d2.x, "each robot draws its own error");
    let again = sim("odometry-again", &world);
    assert_eq!(
        again.motions[2].map(|m| m.odom_error),
        s.motions[2].map(|m| m.odom_error),
        "the same on every load"
    );
    // Into the wall at x = 4.9: the odometry stops where the robot stalls.
    steps(&mut s, 40);
    assert!(s.bases[1].stall, "stalled");
    let stalled = s.bases[1].odom;
    s.step();
    assert_eq!(s.bases[1].odom, stalled, "a stalled base reports no move");
    let gps = s.bases[0].odom;
    let want = origin.inverse().compose(&s.global(s.bases[0].model));
    assert!((gps.x - want.x).abs() < 1e-12 && (gps.y - want.y).abs() < 1e-12);
}

#[test]
fn a_robot_stops_and_stalls_at_a_wall() {
    let mut s = sim("stall", &format!("{ROOM}position ( name \"r\" pose [3 0 0 0] size [0.4 0.4 0.2] acceleration_bounds [-9 9 -9 9 -9 9 -900 900] )\n"));
    s.bases[0].cmd = Some(Command::Vel(Pose::new(1.0, 0.0, 0.0)));
    steps(&mut s, 40);
    let p = s.global(s.bases[0].model);
    assert!(s.bases[0].stall, "stalled");
    // The wall's face is at x = 4.9; the robot's front at x + 0.2.
    assert!(p.x + 0.2 < 4.92 && p.x > 4.5, "{p:?}");
    assert_eq!(s.bases[0].vel, Pose::default());
}

#[test]
fn rangers_sense_every_100_ms_however_short_the_steps() {
    // 20 ms steps, as Stage's fasr.world takes them: the ranger reads
    // at every fifth, and holds its readings in between.
    let room = ROOM.replace("interval_sim 100", "interval_sim 20");
    let mut s = sim("interval", &format!("{room}position ( name \"r\" pose [0 0 0 0] size [0.4 0.4 0.2] ranger ( sensor ( range [0 8] samples 1 ) ) )\n"));
    s.bases[0].cmd = Some(Command::Vel(Pose::new(0.5, 0.0, 0.0)));
    let r = s.world.names["r.ranger:0"];
    let mut seen = vec![s.readings[r].sensor(0).ranges[0]];
    for _ in 0..10 {
        s.step();
        seen.push(s.readings[r].sensor(0).ranges[0]);
    }
    let changed: Vec<usize> = (1..seen.len())
        .filter(|&k| seen[k] != seen[k - 1])
        .collect();
    assert_eq!(changed, [5, 10], "{seen:?}");
    // Each time, 5 cm nearer the wall (0.5 m/s for 0.1 s).
    assert!((seen[5] - seen[10] - 0.05).abs() < 1e-6, "{seen:?}");
}

#[test]
fn controllers_decide_as_their_rangers_update() {
    // 20 ms steps: `wander` first decides when its laser first reads,
    // at 100 ms, and its speeds hold between its decisions.
    let room = ROOM.replace("interval_sim 100", "interval_sim 20");
    let mut s = sim("ctrl-interval", &format!("{room}position ( name \"r\" pose [0 0 0 0] size [0.4 0.4 0.2] ctrl \"wander\" ranger ( sensor ( range [0 8] fov 180 samples 31 ) ) )\n"));
    steps(&mut s, 4);
    assert_eq!(s.bases[0].vel, Pose::default());
    s.step();
    assert!((s.bases[0].vel.x - 0.4).abs() < 1e-9);
    steps(&mut s, 3);
    assert!(
        (s.bases[0].vel.x - 0.4).abs() < 1e-9,
        "held between decisions"
    );
}

#[test]
fn a_robot_with_a_fan_stalls_where_one_without_does() {
    // A fan makes the grid keep its clearance, which spares most moves
    // their cell-by-cell test: the stall must not move.
    let robot = |fan: &str| {
        format!("{ROOM}position ( name \"r\" pose [3 0.3 0 10] size [0.4 0.4 0.2] acceleration_bounds [-9 9 -9 9 -9 9 -900 900] {fan} )\n")
    };
    let mut stops = Vec::new();
    for fan in ["", "ranger ( sensor ( range [0 4] fov 180 samples 181 ) )"] {
        let mut s = sim("fanstall", &robot(fan));
        s.bases[0].cmd = Some(Command::Vel(Pose::new(0.7, 0.0, 0.0)));
        steps(&mut s, 40);
        assert!(s.bases[0].stall, "stalled ({fan})");
        stops.push(s.global(s.bases[0].model));
    }
    assert_eq!(stops[0], stops[1]);
    assert!(stops[0].x > 4.4 && stops[0].x < 4.7, "{:?}", stops[0]);
}

#[test]
fn two_threads_read_and_move_as_one_does() {
    let world = |threads: usize| {
        let mut text = format!("threads {threads}\n{ROOM}");
        for k in 0..12 {
            let (x, y, a) = (
                0.6 * f64::from(k % 4) - 1.0,
                0.7 * f64::from(k / 4) - 0.7,
                41 * k,
            );
            text += &format!(
                "position ( name \"r{k}\" pose [{x} {y} 0 {a}] size [0.3 0.3 0.2] ctrl \"wander\" \
                ranger ( sensor ( pose [0.1 0 0 0] range [0.02 6] fov 270 samples 271 ) ) )\n"
            );
        }
        sim("threads", &text)
    };
    let (mut one, mut two) = (world(1), world(2));
    assert_eq!(one.crew.threads(), 1);
    // (Two even on a machine of one core.)
    two.set_threads(2);
    for _ in 0..30 {
        one.step();
        two.step();
        assert_eq!(one.poses, two.poses);
        assert_eq!(one.readings, two.readings);
    }
    assert!(
        one.bases.iter().any(|b| b.odom != Pose::default()),
        "nobody moved"
    );
}

/// With Stage's ranges, the raster follows the robots as they move:
/// readings after some steps equal those of a raster drawn afresh at
/// the same poses.
#[test]
fn stage_ranges_follow_moving_robots() {
    let mut text = String::from(
        "resolution 0.02\n\
         model ( name \"n\" size [8 0.1 1] pose [0 3.95 0 0] )\n\
         model ( name \"s\" size [8 0.1 1] pose [0 -3.95 0 0] )\n\
         model ( name \"e\" size [0.1 8 1] pose [3.95 0 0 0] )\n\
         model ( name \"w\" size [0.1 8 1] pose [-3.95 0 0 10] )\n",
    );
    for k in 0..6 {
        let (x, y) = (-2.5 + f64::from(k), -1.0 + 0.4 * f64::from(k % 3));
        text += &format!(
            "position ( name \"r{k}\" pose [{x} {y} 0 {}] size [0.4 0.3 0.2] ctrl \"wander\" \
             ranger ( sensor ( samples 90 fov 180 range [0 6] ) size [0.1 0.1 0.1] ) )\n",
            30 * k
        );
    }
    let mut s = sim("follow", &text);
    s.stage_ranges(true);
    let start: Vec<Pose> = s.bases.iter().map(|b| s.global(b.model)).collect();
    steps(&mut s, 40);
    let moved: Vec<Readings> = s.readings.clone();
    s.stage_ranges(false);
    s.stage_ranges(true);
    assert_eq!(s.readings, moved);
    for (b, p) in s.bases.iter().zip(start) {
        let now = s.global(b.model);
        assert!((now.x - p.x).hypot(now.y - p.y) > 0.1, "{now:?} from {p:?}");
    }
}

#[test]
fn nearest_and_first_where_cover_every_length() {
    assert_eq!(nearest(&[]), f64::INFINITY);
    for n in 1..12 {
        let ranges: Vec<f64> = (0..n).map(|k| 10.0 - k as f64).collect();
        assert_eq!(nearest(&ranges), 11.0 - n as f64, "{n}");
    }
    assert_eq!(first_where(0, |_| true), 0);
    assert_eq!(first_where(10, |k| k >= 7), 7);
    assert_eq!(first_where(10, |_| false), 10);
}

#[test]
fn robots_meeting_head_on_stall_apart() {
    let mut s = sim("headon", &format!("{ROOM}position ( name \"a\" pose [-1 0 0 0] size [0.4 0.4 0.2] acceleration_bounds [-9 9 -9 9 -9 9 -900 900] )\nposition ( name \"b\" pose [1 0.1 0 180] size [0.4 0.4 0.2] acceleration_bounds [-9 9 -9 9 -9 9 -900 900] )\n"));
    for b in &mut s.bases {
        b.cmd = Some(Command::Vel(Pose::new(0.5, 0.0, 0.0)));
    }
    steps(&mut s, 40);
    let (a, b) = (s.global(s.bases[0].model), s.global(s.bases[1].model));
    assert!(s.bases[0].stall && s.bases[1].stall, "both stalled");
    // Fronts at a.x + 0.2 and b.x - 0.2: touching within a step (5 cm).
    let gap = (b.x - 0.2) - (a.x + 0.2);
    assert!((0.0..0.06).contains(&gap), "gap {gap}: {a:?} {b:?}");
    // Turned away, a is free to go.
    s.bases[0].cmd = Some(Command::Vel(Pose::new(-0.5, 0.0, 0.0)));
    steps(&mut s, 5);
    assert!(!s.bases[0].stall && s.global(s.bases[0].model).x < a.x - 0.1);
}

#[test]
fn rangers_see_hand_computed_walls() {
    let mut s = sim(
        "ranger",
        &format!("{ROOM}position ( name \"r\" pose [1 0 0 0] size [0.4 0.4 0.2]\n  ranger ( sensor ( range [0 8] fov 180 samples 181 ) sensor ( pose [0 0 0 90] range [0 5] ) ) )\n"),
    );
    s.step();
    let r = s.world.names["r.ranger:0"];
    let laser = &s.readings[r].sensor(0);
    // Straight ahead: the wall face at x = 4.9, from x = 1.
    assert!(
        (laser.ranges[90] - 3.9).abs() < 0.03,
        "{}",
        laser.ranges[90]
    );
    assert_eq!(laser.intensities[90], 1.0);
    // 45° left: 3.9 / cos 45° ≈ 5.515 (the wall reaches y = ±5).
    assert!(
        (laser.ranges[135] - 3.9 * 2f64.sqrt()).abs() < 0.05,
        "{}",
        laser.ranges[135]
    );
    // Straight left: nothing within 8 m.
    assert_eq!(laser.ranges[180], 8.0);
    assert_eq!(laser.intensities[180], 0.0);
    // The second sensor looks left: max range 5.
    assert_eq!(s.readings[r].sensor(1).ranges[0], 5.0);
}

/// The steps' poses and heights (from the models' frames) are the
/// world's own, through a tree three deep, stacked and not, after the
/// simulation interface lifts a model.
#[test]
fn frames_place_models_as_the_world_does() {
    let mut s = sim(
        "frames",
        &format!(
            "{ROOM}position ( name \"a\" pose [1 2 0.1 30] size [0.4 0.4 0.2]\n\
               model ( name \"deck\" pose [0.1 0 0.05 45] size [0.2 0.2 0.1]\n\
                 model ( name \"cup\" pose [0 0.05 0 -20] size [0.05 0.05 0.05] ) )\n\
               model ( name \"loose\" pose [-0.1 0 0 0] size [0.1 0.1 0.1] stack_children 0\n\
                 model ( name \"flag\" pose [0 0 0.2 0] size [0.01 0.01 0.3] ) ) )\n"
        ),
    );
    let cup = s.world.names["a.deck.cup"];
    s.set_z(cup, 0.02);
    s.step();
    for m in 0..s.world.models.len() {
        let ((p, z), (q, w)) = (s.global_z(m), s.world.global(&s.poses, m));
        assert_eq!(
            (p.x, p.y, p.yaw, z),
            (q.x, q.y, q.yaw, w),
            "{}",
            s.world.models[m].name
        );
    }
    let flag = s.world.names["a.loose.flag"];
    // `loose` stands on `a` (0.1 + 0.2); `flag` 0.2 over its base, not on top.
    assert!(
        (s.global_z(flag).1 - 0.5).abs() < 1e-12,
        "stacked on `loose`"
    );
    assert!((s.global_z(cup).1 - (0.1 + 0.2 + 0.05 + 0.1 + 0.02)).abs() < 1e-12);
}

/// A ranger's rays leave from its `origin` on its parent, turned by it:
/// a robot facing +y with a ranger whose origin is half a metre ahead
/// and turned back by 90° looks along +x from (0, 0.5), onto a post.
#[test]
fn a_rangers_rays_leave_from_its_turned_origin() {
    let mut s = sim(
        "origin",
        &format!(
            "{ROOM}position ( name \"a\" pose [0 0 0 90] size [0.4 0.4 0.2]\n\
               ranger ( origin [0.5 0 0 -90] sensor ( range [0 8] ) ) )\n\
             model ( name \"post\" pose [1 0.5 0 0] size [0.2 0.2 1] )\n"
        ),
    );
    s.step();
    let r = s.world.names["a.ranger:0"];
    let got = s.readings[r].sensor(0).ranges[0];
    assert!((got - 0.9).abs() < 0.03, "read {got}, not the post's 0.9");
}

/// Stage tests each block of a body at its own height: a ray passes
/// over a robot's low block (a wheel) and meets the block above it, and
/// with the robot lifted, meets the wheel; the rays of a fan (a laser's
/// 180) read as one ray cast alone does.
#[test]
fn rays_meet_the_blocks_of_a_moving_body_at_their_heights() {
    let wheeled = "position ( name \"b\" pose [2 0 0 0] size [0.6 0.2 0.5]\n\
          block ( points 4 point[0] [-0.3 -0.1] point[1] [-0.1 -0.1] point[2] [-0.1 0.1] point[3] [-0.3 0.1] z [0 0.1] )\n\
          block ( points 4 point[0] [-0.1 -0.1] point[1] [0.3 -0.1] point[2] [0.3 0.1] point[3] [-0.1 0.1] z [0.1 0.5] ) )\n";
    let one = |samples: usize| {
        let mut s = sim(
            &format!("blockz{samples}"),
            &format!(
                "{ROOM}position ( name \"a\" pose [0 0 0 0] size [0.4 0.4 0.2]\n\
                   ranger ( sensor ( range [0 8] samples {samples} fov 10 ) ) )\n{wheeled}"
            ),
        );
        let b = s.world.names["b"];
        assert_eq!(s.world.models[b].block_z, [(0.0, 0.1), (0.1, 0.5)]);
        s.step();
        let r = s.world.names["a.ranger:0"];
        // The ray at 0.2 m + half the sensor's 0.02: over the wheel (its
        // face at 1.7 m), onto the body's at 1.9 m.
        let middle = s.readings[r].sensor(0).ranges[samples / 2];
        assert!((middle - 1.9).abs() < 1e-6, "{samples} rays: {middle}");
        s.set_z(b, 0.15);
        s.set_pose(b, Pose::new(2.0, 0.0, 0.0));
        steps(&mut s, 1);
        let middle = s.readings[r].sensor(0).ranges[samples / 2];
        assert!(
            (middle - 1.7).abs() < 1e-6,
            "{samples} rays, lifted: {middle}"
        );
    };
    one(1);
    one(181);
}

/// Stage is 2.5D: a ray at a sensor's height passes over what is
/// lower and under what is higher; a fiducial finder sees only what its
/// ray at its own height meets first.
#[test]
fn sensors_see_only_what_spans_their_height() {
    let mut s = sim(
        "heights",
        &format!(
            "{ROOM}position ( name \"a\" pose [0 0 0 0] size [0.4 0.4 0.2]\n\
               ranger ( sensor ( range [0 8] ) )\n\
               fiducial ( range_max 8 ) )\n\
             model ( name \"low\" pose [1 0 0 0] size [0.2 0.2 0.1] fiducial_return 3 )\n\
             model ( name \"shelf\" pose [2 0 0.5 0] size [0.2 0.2 0.3] fiducial_return 4 )\n\
             model ( name \"tall\" pose [3 0 0 0] size [0.2 0.2 1] fiducial_return 5 )\n"
        ),
    );
    s.step();
    let r = s.world.names["a.ranger:0"];
    // The ray leaves at 0.2 m + half the sensor's height: over `low`,
    // under `shelf` (0.5 to 0.8 m), onto `tall`'s face at 2.9 m.
    assert!(
        (s.readings[r].sensor(0).ranges[0] - 2.9).abs() < 0.03,
        "{}",
        s.readings[r].sensor(0).ranges[0]
    );
    let f = s.world.names["a.fiducial:0"];
    let ids: Vec<i32> = s.fiducials(f).fiducials.iter().map(|i| i.id).collect();
    assert_eq!(ids, [5], "only the model at the finder's height");
    // Lifted to the finder's height, `low` hides `tall` behind it.
    let low = s.world.names["low"];
    s.set_z(low, 0.15);
    s.set_pose(low, Pose::new(1.0, 0.0, 0.0));
    let ids: Vec<i32> = s.fiducials(f).fiducials.iter().map(|i| i.id).collect();
    assert_eq!(ids, [3]);
}

#[test]
fn robots_see_each_other_but_not_themselves() {
    let mut s = sim(
        "robots",
        // a's ranger sits on top of it (0.2 m up): b is taller.
        "position ( name \"a\" pose [0 0 0 0] size [0.4 0.4 0.2] ranger ( sensor ( range [0 8] ) ) )\n\
         position ( name \"b\" pose [2 0 0 0] size [0.4 0.4 0.5] )\n",
    );
    s.step();
    let r = s.world.names["a.ranger:0"];
    // Moving bodies are met exactly, not at a grid cell's edge.
    assert!(
        (s.readings[r].sensor(0).ranges[0] - 1.8).abs() < 1e-9,
        "{}",
        s.readings[r].sensor(0).ranges[0]
    );
    // Move b away through the simulation interface: a sees nothing.
    let b = s.world.names["b"];
    s.set_pose(b, Pose::new(2.0, 3.0, 0.0));
    s.step();
    assert_eq!(s.readings[r].sensor(0).ranges[0], 8.0);
}

#[test]
fn blobs_come_right_to_left_with_their_colours() {
    let s = sim(
        "blobs",
        "position ( name \"r\" size [0.4 0.4 0.2] blobfinder ( colors_count 2 colors [\"red\" \"green\"] image [80 60] range 8 fov 60 ) )\n\
         model ( name \"a\" pose [3 1 0 0] size [0.3 0.3 0.5] color \"red\" )\n\
         model ( name \"b\" pose [3 -1 0 0] size [0.3 0.3 0.5] color \"green\" )\n\
         model ( name \"c\" pose [3 0 0 0] size [0.3 0.3 0.5] color \"blue\" )\n",
    );
    let bf = s.world.names["r.blobfinder:0"];
    let d = s.blobs(bf);
    assert_eq!((d.width, d.height), (80, 60));
    let colors: Vec<u32> = d.blobs.iter().map(|b| b.color).collect();
    // Left of the image is the robot's left (+y); Stage's scan starts
    // at the right: green first, blue untracked.
    assert_eq!(colors, vec![0x00FF00, 0xFF0000]);
    assert!(d.blobs[1].right < d.blobs[0].left);
    assert!((d.blobs[0].range - 2.99).abs() < 0.2, "{:?}", d.blobs[0]);
    // Nothing in view: Player's plugin reports an empty image.
    let r = s.world.names["r"];
    let mut s = s;
    s.set_pose(r, Pose::new(0.0, 0.0, std::f64::consts::PI));
    assert_eq!(s.blobs(bf), troupe_msgs::blobfinder::Data::default());
}

#[test]
fn fiducials_in_range_and_sight_are_reported() {
    let s = sim(
        "fiducials",
        "position ( name \"r\" size [0.4 0.4 0.2] fiducial ( range_max 8 range_max_id 3 fov 180 ) )\n\
         model ( name \"near\" pose [2 0 0 0] size [0.2 0.2 0.5] fiducial_return 7 )\n\
         model ( name \"far\" pose [0 4 0 0] size [0.2 0.2 0.5] fiducial_return 9 )\n\
         model ( name \"behind\" pose [-2 0 0 0] size [0.2 0.2 0.5] fiducial_return 5 )\n\
         model ( name \"hidden\" pose [5 0 0 0] size [0.2 0.2 0.5] fiducial_return 3 )\n",
    );
    let f = s.fiducials(s.world.names["r.fiducial:0"]);
    let mut ids: Vec<i32> = f.fiducials.iter().map(|i| i.id).collect();
    ids.sort();
    // near: identified; far: seen but beyond range_max_id; behind: outside the fov; hidden: behind near.
    assert_eq!(ids, vec![-1, 7]);
    let near = f.fiducials.iter().find(|i| i.id == 7).unwrap();
    assert!((near.pose.x - 2.0).abs() < 1e-9 && near.pose.y.abs() < 1e-9);
}

#[test]
fn a_gripper_picks_up_carries_and_drops_a_box() {
    // The gripper hangs in front of r, 0.05 m up (its base is 0.2 m
    // tall): the box between its paddles spans that height.
    let mut s = sim(
        "gripper",
        "position ( name \"r\" size [0.4 0.4 0.2] acceleration_bounds [-9 9 -9 9 -9 9 -900 900] gripper ( pose [0.3 0 -0.15 0] size [0.2 0.3 0.1] ) )\n\
         model ( name \"box\" pose [0.38 0 0 0] size [0.1 0.1 0.1] gripper_return 1 obstacle_return 1 )\n",
    );
    let g = s.world.names["r.gripper:0"];
    let bx = s.world.names["box"];
    let st = |s: &Sim| s.grippers[g].clone().unwrap();
    s.step();
    assert_eq!(st(&s).beams, 0x08, "the box breaks the outer beam");
    assert_eq!(st(&s).paddles, Paddles::Open);
    // The paddles move a twentieth a step, until they touch the box
    // (0.1 m wide, between paddles 0.24 m apart) and close on it.
    s.grip(g, true);
    let mut moving = 0;
    while st(&s).paddles != Paddles::Closed {
        s.step();
        moving += 1;
        assert!(moving < 30, "{:?}", st(&s));
    }
    assert_eq!(moving, 13, "12 steps closing, the 13th stops on the box");
    assert!((st(&s).position - 0.6).abs() < 1e-9, "{:?}", st(&s));
    assert_eq!(st(&s).held.map(|h| h.0), Some(bx));
    // Held, the box is part of r: r's rays pass it, as its own body.
    let r = s.world.names["r"];
    assert!(!s.ranger_sees(r, 0.05)(id(bx)), "held: r's own");
    assert_ne!(
        st(&s).beams & 0x04,
        0,
        "held at the centre, across the inner beam"
    );
    assert!((s.global(bx).x - 0.3).abs() < 1e-9, "taken to the centre");
    assert_eq!(
        s.reported_pose(bx),
        Pose::default(),
        "Stage reports a held box on its gripper"
    );
    s.bases[0].cmd = Some(Command::Vel(Pose::new(0.5, 0.0, 0.0)));
    for _ in 0..10 {
        s.step();
    }
    assert!(!s.bases[0].stall, "a held box is part of the robot");
    let p = s.global(bx);
    assert!((p.x - 0.8).abs() < 0.02, "carried 0.5 m: {p:?}");
    // Opening lets go at once (the paddles leave the box).
    s.grip(g, false);
    s.bases[0].cmd = Some(Command::Vel(Pose::new(-0.5, 0.0, 0.0)));
    s.step();
    assert_eq!((st(&s).paddles, st(&s).held), (Paddles::Opening, None));
    assert!(s.ranger_sees(r, 0.05)(id(bx)), "dropped: seen again");
    for _ in 0..13 {
        s.step();
    }
    assert!((s.global(bx).x - 0.8).abs() < 0.06, "dropped where it was");
    assert_eq!(
        s.reported_pose(bx),
        s.poses[bx],
        "dropped: on the world again"
    );
    assert_eq!(
        st(&s).paddles,
        Paddles::Open,
        "open 1.4 s after the command"
    );
}

#[test]
fn a_static_box_moved_leaves_no_cells_behind() {
    // Two boxes overlapping by 0.1 m; "a" moves away and back.
    let mut s = sim(
        "moved",
        "model ( name \"a\" pose [0 0 0 0] size [0.4 0.4 0.2] obstacle_return 1 )\n\
         model ( name \"b\" pose [0.3 0 0 0] size [0.4 0.4 0.2] obstacle_return 1 )\n",
    );
    let (a, b) = (s.world.names["a"], s.world.names["b"]);
    let at = |s: &Sim, x: f64| s.statics.at(x, 0.01);
    assert_eq!((at(&s, -0.1), at(&s, 0.4)), (id(a), id(b)));
    s.set_pose(a, Pose::new(2.0, 0.0, 0.0));
    assert_eq!((at(&s, -0.1), at(&s, 2.0)), (EMPTY, id(a)));
    // Where they overlapped, b's cells: a's were taken, b's stay.
    assert_eq!((at(&s, 0.15), at(&s, 0.4)), (id(b), id(b)));
    s.set_pose(a, Pose::new(-1.0, 0.0, 0.0));
    assert_eq!((at(&s, 2.0), at(&s, -1.0)), (EMPTY, id(a)));
}

#[test]
fn snapshots_show_walls_robots_and_rays() {
    let mut s = sim("snap", &format!("{ROOM}position ( name \"r\" color \"red\" size [0.4 0.4 0.2] ranger ( sensor ( range [0 8] fov 90 samples 10 ) ) )\n"));
    s.step();
    let img = s.snapshot(200);
    assert!(img.width() <= 200 && img.height() <= 200 && img.width() > 100);
    let count = |c: [u8; 3]| img.pixels().filter(|p| p.0 == c).count();
    assert!(count([255, 0, 0]) > 0, "the red robot");
    assert!(count([170, 210, 255]) > 0, "its rays");
    assert!(count([255, 0, 0]) < count([255, 255, 255]));
}

#[test]
fn goto_reaches_the_goal_as_stage_s_controller_does() {
    let mut s = sim("goto", "position ( name \"r\" size [0.4 0.4 0.2] )\n");
    s.bases[0].cmd = Some(Command::GoTo(Pose::new(1.0, 1.0, 0.0)));
    steps(&mut s, 300);
    // Stage's: within 2 cm of the point, then the heading's error closed
    // by a tenth a step.
    let o = s.bases[0].odom;
    assert!(
        (o.x - 1.0).abs() < 0.02 && (o.y - 1.0).abs() < 0.02 && o.yaw.abs() < 1e-3,
        "{o:?}"
    );
    // Facing away, it turns before it drives: at most 0.4 m/s, and only
    // within π/16 of the goal's bearing.
    let v = motion::stage_position_control(
        Drive::Diff,
        Pose::new(0.0, 0.0, 0.0),
        Pose::new(-2.0, 0.0, 0.0),
    );
    assert_eq!((v.x, v.y), (0.0, 0.0), "{v:?}");
    assert!(v.yaw > 1.0, "Stage does not clamp a positive turn: {v:?}");
    let v = motion::stage_position_control(
        Drive::Diff,
        Pose::new(0.0, 0.0, 0.1),
        Pose::new(2.0, 0.0, 0.0),
    );
    assert_eq!(v.x, 0.4, "{v:?}");
}

/// A robot whose camera (41 x 31 pixels, 60° x 40°) stands 0.3 m above
/// the floor, a low green box 1.5 m ahead and a red wall 3 m ahead.
fn camera_world(camera: &str) -> Sim {
    sim(
        &format!("camera{}", camera.len()),
        &format!(
            "resolution 0.02\n\
             model ( name \"wall\" pose [3 0 0 0] size [0.2 10 1] color \"red\" )\n\
             model ( name \"box\" pose [1.5 0 0 0] size [0.2 0.2 0.1] color \"green\" )\n\
             model ( name \"aside\" pose [0 -2 0 0] size [0.4 0.4 2] color \"blue\" )\n\
             position ( name \"r0\" size [0.4 0.4 0.2] color \"yellow\"\n\
               camera ( pose [0 0 0.1 0] resolution [41 31] fov [60 40] range [0.2 8] {camera} ) )\n"
        ),
    )
}

/// The colour and depth of pixel (col, row) of an image.
fn pixel(im: &Image, col: usize, row: usize) -> ([u8; 3], f32) {
    let i = row * im.width as usize + col;
    let mut c = [0; 3];
    c.copy_from_slice(&im.rgb[i * 3..i * 3 + 3]);
    (c, im.depth[i])
}

#[test]
fn a_camera_draws_sides_tops_floor_and_sky_as_stage_does() {
    let s = camera_world("");
    let cam = s.world().names["r0.camera:0"];
    let im = s.camera(cam);
    assert_eq!((im.width, im.height, im.rgb.len()), (41, 31, 41 * 31 * 3));
    let (red, green) = ([255, 0, 0], [0, 255, 0]);
    // The centre pixel passes over the box and meets the wall's face.
    let (c, d) = pixel(&im, 20, 15);
    assert_eq!(c, red);
    assert!((d - 2.9).abs() < 0.03, "{d}");
    // The top row passes over the 1 m wall: the background.
    assert_eq!(pixel(&im, 20, 0), (camera::SKY, 8.0));
    // The bottom row meets the floor 0.3 / tan 20° ahead.
    let v = (20f64.to_radians()).tan() * (1.0 - 61.0 / 31.0);
    let (c, d) = pixel(&im, 20, 30);
    assert_eq!(c, camera::FLOOR);
    assert!((f64::from(d) - 0.3 / -v).abs() < 1e-3, "{d}");
    // Lower rows meet the box's face at 1.4 m; one above passes the face
    // and comes down on its top.
    let (c, d) = pixel(&im, 20, 22);
    assert_eq!(c, green);
    assert!((d - 1.4).abs() < 0.03, "{d}");
    let v = (20f64.to_radians()).tan() * (1.0 - 43.0 / 31.0);
    let (c, d) = pixel(&im, 20, 21);
    assert_eq!(c, green, "the box's top");
    assert!((f64::from(d) - 0.2 / -v).abs() < 0.02, "{d}");
    // Its own robot is not drawn: nothing yellow.
    assert!(!im.rgb.chunks(3).any(|p| p == [255, 255, 0]));
    // The image's left is the robot's left: the wall fills both edges,
    // the blue pillar on the right (-y) is outside a 60° view.
    assert!(!im.rgb.chunks(3).any(|p| p == [0, 0, 255]));
}

#[test]
fn a_camera_pans_right_and_tilts_down() {
    let s = camera_world("pantilt [90 0]");
    let cam = s.world().names["r0.camera:0"];
    let (c, d) = pixel(&s.camera(cam), 20, 15);
    assert_eq!(c, [0, 0, 255], "panned 90°, it faces the pillar at -y");
    assert!((d - 1.8).abs() < 0.03, "{d}");
    let s = camera_world("pantilt [0 30]");
    let (c, d) = pixel(&s.camera(cam), 20, 15);
    assert_eq!(c, camera::FLOOR);
    assert!((d - 0.6).abs() < 1e-3, "tilted 30° down from 0.3 m: {d}");
}
