//! Stage's own worlds, from ../shared/compat.

use super::*;
use troupe_node::testing::compat;

#[test]
fn ctrl_wander_roams_simple_world_without_leaving_the_cave() {
    let Some(p) = compat("stage/simple.world") else {
        return;
    };
    let mut s = Sim::new(crate::world::load(&p).unwrap()).unwrap();
    assert!(
        s.bases
            .iter()
            .all(|b| matches!(b.ctrl, Some(Ctrl::Wander { .. }))),
        "both robots have ctrl \"wander\""
    );
    let start = s.global(s.bases[0].model);
    let mut travelled = 0.0;
    let mut last = start;
    for _ in 0..3000 {
        s.step();
        let p = s.global(s.bases[0].model);
        travelled += (p.x - last.x).hypot(p.y - last.y);
        last = p;
        for b in &s.bases {
            let g = s.global(b.model);
            assert!(g.x.abs() < 8.0 && g.y.abs() < 8.0, "left the cave at {g:?}");
        }
    }
    assert!(travelled > 20.0, "wandered only {travelled} m in 300 s");
}

#[test]
fn the_cave_map_agrees_with_the_simulated_cave() {
    let Some(p) = compat("stage/simple.world") else {
        return;
    };
    let s = Sim::new(crate::world::load(&p).unwrap()).unwrap();
    let cave = s.world.names["cave"];
    let map = s.model_map(cave).unwrap();
    // 16 m at Stage's default map_resolution 0.1, corner at (-8, -8).
    assert_eq!((map.info.width, map.info.height), (160, 160));
    assert_eq!((map.info.origin.x, map.info.origin.y), (-8.0, -8.0));
    // Cell by cell against the 2 cm grid the robots move in: where that
    // grid holds the cave at a map cell's centre, the cell is occupied;
    // an occupied cell holds the cave somewhere (5 x 5 points a cell).
    let (mut missed, mut extra, mut occupied) = (0, 0, 0);
    for (k, &c) in map.cells.iter().enumerate() {
        let (x, y) = map.centre(k);
        let cave_at = |dx: f64, dy: f64| s.statics.at(x + dx, y + dy) == id(cave);
        missed += usize::from(cave_at(0.0, 0.0) && c != OCCUPIED);
        let near = (0..25).any(|q| {
            let (u, v) = (f64::from(q % 5) - 2.0, f64::from(q / 5) - 2.0);
            cave_at(u * 0.02, v * 0.02)
        });
        extra += usize::from(!near && c == OCCUPIED);
        occupied += usize::from(c == OCCUPIED);
    }
    let n = map.cells.len();
    assert_eq!((missed, extra), (0, 0), "cells the map gets wrong");
    assert!(occupied * 100 > n * 5, "{occupied} of {n} occupied");
    // `boundary 1` (map.inc): the outer ring is wall.
    assert!(map.cells[..160].iter().all(|&c| c == OCCUPIED));
    assert!(map.cells[n - 160..].iter().all(|&c| c == OCCUPIED));
}

/// The issue's case (32, items 4 and 6): r0's SICK sits on top of its
/// Pioneer, so its rays pass over r1's body (0.22 m tall) and meet
/// r1's SICK — four beams in Stage, with that model's default
/// `ranger_return` 1 as their intensity; the cave's walls return 0.5.
#[test]
fn r0_s_laser_meets_r1_s_laser_above_its_body_as_in_stage() {
    let Some(p) = compat("stage/simple_noctrl.world") else {
        return;
    };
    let s = Sim::new(crate::world::load(&p).unwrap()).unwrap();
    let r = &s.readings[s.world.names["r0.ranger:1"]].sensor(0);
    let on_r1: Vec<usize> = (0..r.ranges.len())
        .filter(|&k| r.intensities[k] == 1.0)
        .collect();
    assert_eq!(on_r1, [43, 44, 45, 46]);
    assert!(on_r1.iter().all(|&k| (r.ranges[k] - 2.93).abs() < 0.06));
    assert!(r
        .intensities
        .iter()
        .all(|&i| i == 1.0 || i == 0.5 || i == 0.0));
}

/// Issue 32, item 5: r0's first scan in simple_noctrl.world, as real
/// Stage measured it (the laser:0 data of the c-pull-position-laser
/// transcript), beam for beam. Stage's ranges come from its raster of
/// the cave's outline and its staircase walk; with `stage_ranges` on,
/// every beam that meets a wall or nothing reads the same to 1e-4 m.
/// Against the exact walls (the default) they differ by centimetres.
#[test]
fn stage_ranges_match_real_stage_beam_for_beam() {
    let (Some(world), Some(transcript)) = (
        compat("stage/simple_noctrl.world"),
        compat("player-tcp/c-pull-position-laser/messages.jsonl"),
    ) else {
        return;
    };
    // The first laser DATA message's ranges.
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
    let stage: Vec<f64> = list[..list.find(']').unwrap()]
        .split(',')
        .map(|v| v.trim().parse().unwrap())
        .collect();
    assert_eq!(stage.len(), 180);
    let mut sim = Sim::new(crate::world::load(&world).unwrap()).unwrap();
    let laser = sim.world.names["r0.ranger:1"];
    let exact = sim.readings[laser].clone();
    let exact = exact.sensor(0);
    sim.stage_ranges(true);
    let ours = &sim.readings[laser].sensor(0);
    // Beams on r1's laser (a moving body, drawn into the raster as Stage
    // draws it) read intensity 1; the cave returns 0.5, nothing 0.
    let on_r1: Vec<usize> = (0..180).filter(|&k| ours.intensities[k] == 1.0).collect();
    assert_eq!(on_r1.len(), 4, "{on_r1:?}");
    let walls: Vec<usize> = (0..180).filter(|k| !on_r1.contains(k)).collect();
    let off = |r: &Reading, beams: &[usize]| {
        beams
            .iter()
            .map(|&k| (r.ranges[k] - stage[k]).abs())
            .fold(0.0, f64::max)
    };
    assert!(
        off(ours, &walls) < 1e-4,
        "worst wall beam {} m off Stage's",
        off(ours, &walls)
    );
    // r1's laser box (the only part of r1 at the ray's height), drawn into
    // the raster as Stage draws it, its points in Stage's counter-clockwise
    // order: its four beams read as Stage's to 0.1 mm.
    let on = |r: &Reading| on_r1.iter().map(|&k| r.ranges[k]).collect::<Vec<_>>();
    assert!(
        on_r1
            .iter()
            .all(|&k| (ours.ranges[k] - stage[k]).abs() < 1e-4),
        "beams on r1: {:?} against Stage's {:?}",
        on(ours),
        on_r1.iter().map(|&k| stage[k]).collect::<Vec<_>>()
    );
    // The exact walls: up to a few cells (over the cosine) off.
    assert!(
        (0.02..0.2).contains(&off(&exact, &walls)),
        "exact walls {} m off",
        off(&exact, &walls)
    );
    // And back.
    sim.stage_ranges(false);
    assert_eq!(sim.readings[laser].sensor(0).ranges, exact.ranges);
}

#[test]
fn robot1_of_everything_world_sees_what_player_saw() {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/compat/stage/everything_nocamera.world");
    if !p.exists() {
        eprintln!("skipping: ../shared/compat is absent");
        return;
    }
    let s = Sim::new(crate::world::load(&p).unwrap()).unwrap();
    let bf = s.world.names["robot1.blobfinder:0"];
    let d = s.blobs(bf);
    // The Player transcript (cpp-blob-fiducial-gripper): an 80x60
    // image, five blobs right to left: colour, rows, columns, range.
    // Stage draws bodies into its grid, so an edge may cover one
    // column more there than the exact bodies here do.
    assert_eq!((d.width, d.height), (80, 60));
    let want = [
        (0x00ff00, 30, 26, 34, 60, 60, 3.5375),
        (0xff0000, 30, 26, 34, 36, 42, 4.2550),
        (0xff00ff, 30, 26, 34, 31, 34, 3.6563),
        (0xffff00, 30, 25, 35, 20, 29, 3.1833),
        (0x00ffff, 30, 23, 37, 5, 18, 2.3987),
    ];
    assert_eq!(d.blobs.len(), want.len(), "{:?}", d.blobs);
    for (b, (color, y, top, bottom, left, right, range)) in d.blobs.iter().zip(want) {
        assert_eq!(
            (b.color, b.y, b.top, b.bottom),
            (color, y, top, bottom),
            "{b:?}"
        );
        assert!(
            b.left.abs_diff(left) <= 1 && b.right.abs_diff(right) <= 1,
            "{b:?}"
        );
        assert_eq!(b.area, (b.right - b.left) * (bottom - top), "{b:?}");
        assert!((f64::from(b.range) - range).abs() < 0.03, "{b:?}");
    }
    let f = s.fiducials(s.world.names["robot1.fiducial:0"]);
    // Real Stage's five (the transcript): the robots at the finder's
    // height, not the pucks below it. In the order the world declares
    // them (redrobot_w_camera, p1, p4, p5, p6): Stage lists them in the
    // order of the models' addresses in memory (ModelFiducial::Update
    // intersects two std::set<Model*>), which put p1 first there, and no
    // program can count on from one run or build to the next.
    let seen: Vec<(i32, i64, i64)> = f
        .fiducials
        .iter()
        .map(|i| {
            (
                i.id,
                (i.pose.x * 1e4).round() as i64,
                (i.pose.y * 1e4).round() as i64,
            )
        })
        .collect();
    assert_eq!(
        seen,
        [
            (17, 44285, 283),
            (18, 30882, -5798),
            (17, 23953, 9013),
            (17, 32910, 5825),
            (17, 38255, 4101),
        ]
    );
}

#[test]
fn the_camera_of_stages_camera_world_sees_the_cave_floor_and_sky() {
    let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/compat/stage/camera.world");
    if !p.exists() {
        eprintln!("skipping: ../shared/compat is absent");
        return;
    }
    let s = Sim::new(crate::world::load(&p).unwrap()).unwrap();
    let cam = s.world.names["r0.camera:0"];
    let im = s.camera(cam);
    assert_eq!((im.width, im.height), (100, 100));
    let wall = s.colors[s.world.names["cave"]].rgb8();
    let px = |col: usize, row: usize| {
        let i = (row * 100 + col) * 3;
        [im.rgb[i], im.rgb[i + 1], im.rgb[i + 2]]
    };
    let count = |c: [u8; 3]| im.rgb.chunks(3).filter(|p| *p == c).count();
    // From its corner the robot looks across the cave: floor below,
    // the cave's walls around the horizon, the background above them.
    assert!((0..100).all(|c| px(c, 99) == camera::FLOOR));
    assert!((0..100).all(|c| px(c, 0) == camera::SKY));
    assert!(count(wall) > 1000, "{} wall pixels", count(wall));
    assert_eq!(
        count(wall) + count(camera::FLOOR) + count(camera::SKY),
        100 * 100,
        "nothing else is in view"
    );
    if let Some(out) = std::env::var_os("TROUPE_CAMERA_PNG") {
        image::save_buffer(out, &im.rgb, 100, 100, image::ExtendedColorType::Rgb8).unwrap();
    }
}
