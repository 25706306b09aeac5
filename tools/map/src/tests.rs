//! The builder end to end, on logs the simulator makes: Troupe's office
//! (worlds/wander.world: bitmaps/office.png and a robot with its own
//! `wander`) driven with odometry that reads its turns wrong, the map
//! judged against the world's own walls.

use std::path::Path;

use super::*;
use crate::simulate::{simulate, Driver, Run, Setup};

fn run(name: &str, seconds: f64, yaw_error: f64) -> (Run, Recording) {
    let dir = std::env::temp_dir().join(format!("troupe-map-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../worlds/wander.world");
    let world = troupe_stage::world::load(&path).unwrap();
    let run = simulate(
        world,
        &Setup {
            robot: "r0".into(),
            seconds,
            odom_error: [0.02, 0.0, yaw_error],
            every: 0.1,
            driver: Driver::Explore,
        },
    )
    .unwrap();
    let log = dir.join("run.log");
    std::fs::write(&log, &run.log).unwrap();
    let rec = source::read(&[log], &Select::default()).unwrap();
    (run, rec)
}

#[test]
fn a_wander_through_the_office_makes_an_accurate_map() {
    let (run, rec) = run("office", 600.0, 0.04);
    assert!(run.driven > 60.0, "the robot drove {} m", run.driven);
    let built = build(&rec, Params::default(), |_, _| {});
    let occupied = built.grid.occupied();
    let s = eval::score(&occupied, &run.obstacles, &run.seen, run.frame(&rec), 0.1);
    eprintln!(
        "office, 600 s, {:.0} m driven: accuracy {:.3}, coverage {:.3}, {} keyframes, {} closures",
        run.driven,
        s.accuracy,
        s.coverage,
        built.slam.keyframes.len(),
        built.slam.closures
    );
    assert!(s.accuracy >= 0.9, "accuracy {:.3}", s.accuracy);
    assert!(s.coverage >= 0.75, "coverage {:.3}", s.coverage);
    // Odometry reads distance 2% and turns 4% long: the builder learnt it.
    let c = built.slam.calibration;
    eprintln!(
        "calibration: distance x{:.4}, turns x{:.4}",
        c.distance(),
        c.turn()
    );
    assert!(
        (c.distance() * 1.02 - 1.0).abs() < 0.01,
        "distance x{}",
        c.distance()
    );
    assert!((c.turn() * 1.04 - 1.0).abs() < 0.01, "turns x{}", c.turn());

    // The same log with odometry alone is far worse: the test can fail.
    let odometry = odometry_map(&rec, 0.05);
    let raw = eval::score(
        &odometry.occupied(),
        &run.obstacles,
        &run.seen,
        run.frame(&rec),
        0.1,
    );
    eprintln!("odometry alone: accuracy {:.3}", raw.accuracy);
    assert!(raw.accuracy < 0.8, "odometry alone {:.3}", raw.accuracy);

    // And what it writes is a map mapfile serves.
    let dir = std::env::temp_dir().join(format!("troupe-map-{}-out", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let yaml = dir.join("office.yaml");
    let png = built.grid.save(&yaml).unwrap();
    assert!(png.exists());
    let served = troupe_mapfile::load_any(&yaml).unwrap();
    assert_eq!(served.size(), built.grid.size());
    let (ox, oy) = built.grid.origin();
    assert!((served.info.origin.x - ox).abs() < 1e-3 && (served.info.origin.y - oy).abs() < 1e-3);
}

#[test]
fn a_loop_odometry_misses_by_half_a_metre_closes() {
    let (run, rec) = run("loop", 300.0, 0.06);
    let built = build(&rec, Params::default(), |_, _| {});
    let f = run.frame(&rec);
    let (t_end, truth_end) = *run.truth.last().unwrap();
    let end_odom = rec.odom_at(t_end).unwrap();
    let miss = |p: Pose| {
        let w = f.compose(&p);
        (w.x - truth_end.x).hypot(w.y - truth_end.y)
    };
    let raw = miss(end_odom);
    let slam = miss(built.slam.corrected(t_end, end_odom));
    eprintln!(
        "loop: odometry ends {raw:.2} m off, the map's trajectory {slam:.2} m; {} closures",
        built.slam.closures
    );
    assert!(raw >= 0.5, "odometry alone ends {raw:.2} m off");
    assert!(slam < 0.2, "the map's trajectory ends {slam:.2} m off");
    assert!(built.slam.closures > 0);
}
