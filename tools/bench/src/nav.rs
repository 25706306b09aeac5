//! `troupe bench nav`: the navigation cores without the network — amcl
//! updates, wavefront plans, vfh decisions — on cave.png or a synthetic map.

use std::time::{Duration, Instant};

use clap::Args;
use troupe_amcl::laser::DistanceMap;
use troupe_amcl::{Localizer, Options as AmclOptions};
use troupe_geom::occmap::{OccMap, FREE, OCCUPIED};
use troupe_geom::Pose;
use troupe_msgs::{map, Pose2d};
use troupe_wavefront::plan::{Params, Planner};

use crate::harness::cpu_time;

/// Flags of `troupe bench nav`.
#[derive(Debug, Args)]
pub struct NavBenchArgs {
    /// The map image (cave.png, 500x500 at 0.032 m, origin -8 -8 in the reference);
    /// a synthetic 16 m cave without it.
    #[arg(long, value_name = "PNG")]
    pub map: Option<std::path::PathBuf>,
    /// Stage's hospital_section.png, to time wavefront on it scaled to 2000
    /// cells across (140 m at 0.07 m, as in the reference), end to end.
    #[arg(long, value_name = "PNG")]
    pub hospital: Option<std::path::PathBuf>,
    /// Particle counts to time amcl at.
    #[arg(long, value_delimiter = ',', default_value = "1000,5000,100000")]
    pub particles: Vec<usize>,
}

#[allow(clippy::print_stdout)]
fn say(line: &str) {
    println!("{line}");
}

fn synthetic() -> OccMap {
    let info = map::Info {
        width: 500,
        height: 500,
        resolution: 0.032,
        origin: Pose2d::new(-8.0, -8.0, 0.0),
    };
    OccMap::from_fn(info, |i, j| {
        let wall = i < 5 || j < 5 || i >= 495 || j >= 495;
        let block = (i / 60 + j / 45) % 4 == 0 && (i % 60) < 20 && (j % 45) < 15;
        if wall || block {
            OCCUPIED
        } else {
            FREE
        }
    })
}

/// The free cell centre nearest to (x, y) with at least `clear` metres of room.
fn nearest_clear(m: &OccMap, dist: &[f32], x: f64, y: f64, clear: f32) -> (f64, f64) {
    let (w, _) = m.size();
    let target = m.index_of(x, y).unwrap_or(0);
    let (ci, cj) = ((target % w) as i64, (target / w) as i64);
    let best = dist
        .iter()
        .enumerate()
        .filter(|(_, &d)| d >= clear)
        .min_by_key(|(k, _)| {
            let (i, j) = ((k % w) as i64, (k / w) as i64);
            (i - ci).pow(2) + (j - cj).pow(2)
        })
        .map_or(0, |(k, _)| k);
    m.centre(best)
}

fn per(total: Duration, n: usize) -> f64 {
    total.as_secs_f64() / n.max(1) as f64
}

fn amcl(m: &OccMap, start: Pose, counts: &[usize]) -> anyhow::Result<()> {
    let field = DistanceMap::new(m);
    for (model, beams) in [("beam", 6), ("likelihood_field", 6), ("beam", 181)] {
        for &n in counts {
            let o = AmclOptions {
                pf_min_samples: n,
                pf_max_samples: n,
                init_pose: vec![start.x, start.y, start.yaw],
                init_pose_var: vec![0.3, 0.3, 0.2],
                laser_model_type: model.into(),
                laser_max_beams: beams,
                ..AmclOptions::default()
            };
            let mut loc = Localizer::new(&o).map_err(anyhow::Error::msg)?;
            loc.set_map(m);
            // Back and forth along 0.25 m so that every scan updates.
            let updates = (2_000_000 / (n * beams.min(30))).clamp(5, 400);
            let (mut took, mut cpu) = (Duration::ZERO, Duration::ZERO);
            let mut t = 0.0;
            loc.odometry(Pose::default(), t);
            loc.scan(&field.scan(&start, 8.0), t);
            for k in 0..updates {
                t += 1.0;
                let along = if k % 2 == 0 { 0.25 } else { 0.0 };
                let truth = start.compose(&Pose::new(along, 0.0, 0.0));
                let scan = field.scan(&truth, 8.0);
                loc.odometry(Pose::new(along, 0.0, 0.0), t);
                let (t0, c0) = (Instant::now(), cpu_time());
                let updated = loc.scan(&scan, t);
                took += t0.elapsed();
                cpu += cpu_time().saturating_sub(c0);
                anyhow::ensure!(updated, "amcl did not update on a 0.25 m step");
            }
            let s = per(took, updates);
            let c = per(cpu, updates);
            say(&format!(
                "amcl {model:>16}, {beams:>3} of 181 beams, {n:>6} particles: {:>8.1} updates/s, {:>8.3} ms/update, CPU {:.3} ms per 1000 particles",
                1.0 / s,
                s * 1e3,
                c * 1e3 / (n as f64 / 1000.0)
            ));
        }
    }
    Ok(())
}

fn wavefront(name: &str, m: &OccMap, from: (f64, f64), to: (f64, f64)) -> anyhow::Result<()> {
    let params = Params {
        min_radius: 0.22 + 0.15,
        max_radius: 1.0,
        dist_penalty: 1.0,
    };
    let t0 = Instant::now();
    let mut p = Planner::new(m, params);
    let cspace = t0.elapsed();
    let dist = m.distance_field();
    let from = nearest_clear(m, &dist, from.0, from.1, 0.4);
    let to = nearest_clear(m, &dist, to.0, to.1, 0.4);
    let runs = 20;
    let mut took = Duration::ZERO;
    let mut path = Vec::new();
    for _ in 0..runs {
        let t0 = Instant::now();
        path = p
            .plan(from, to)
            .map_err(|e| anyhow::anyhow!("{name}: {e}"))?;
        let wps = p.waypoints(&path);
        took += t0.elapsed();
        anyhow::ensure!(wps.len() >= 2);
    }
    let length: f64 = path
        .windows(2)
        .map(|w| {
            let (a, b) = (p.point(w[0]), p.point(w[1]));
            (a.0 - b.0).hypot(a.1 - b.1)
        })
        .sum();
    say(&format!(
        "wavefront {name}: {:>6.2} ms per plan + waypoints ({length:.1} m path), configuration space {:.1} ms once",
        per(took, runs) * 1e3,
        cspace.as_secs_f64() * 1e3
    ));
    Ok(())
}

fn vfh() {
    use troupe_vfh::algorithm::{Params, Vfh};
    let mut v = Vfh::new(Params {
        robot_radius: 0.25,
        ..Params::default()
    });
    // A corridor with a wall ahead-left.
    let range = |deg: f64| {
        if (100.0..140.0).contains(&deg) {
            1200.0
        } else if !(30.0..=150.0).contains(&deg) {
            900.0
        } else {
            4000.0
        }
    };
    let runs = 20_000;
    let t0 = Instant::now();
    let mut speed = 0.0;
    for _ in 0..runs {
        speed = v
            .update(range, speed * 1000.0, 100.0, 5000.0, 300.0, 0.1)
            .speed;
    }
    say(&format!(
        "vfh: {:.1} µs per decision (61x61 window, 5° sectors)",
        per(t0.elapsed(), runs) * 1e6
    ));
}

/// `troupe bench nav`.
pub fn run(a: &NavBenchArgs) -> anyhow::Result<()> {
    let m = match &a.map {
        Some(p) => troupe_mapfile::load(p, 0.032, false, Some((-8.0, -8.0)))?,
        None => synthetic(),
    };
    say(&format!(
        "map: {} x {} cells at {} m{}",
        m.info.width,
        m.info.height,
        m.info.resolution,
        if a.map.is_some() { "" } else { " (synthetic)" }
    ));
    amcl(
        &m,
        Pose::new(-6.946, -6.947, std::f64::consts::FRAC_PI_4),
        &a.particles,
    )?;
    wavefront("500x500", &m, (-6.946, -6.947), (-4.5, -5.5))?;
    wavefront("500x500 across", &m, (-6.946, -6.947), (6.5, 6.5))?;
    // 2000 x 2000: the map tiled 4 x 4.
    let (w, h) = m.size();
    let big = OccMap::from_fn(
        map::Info {
            width: (w * 4) as u32,
            height: (h * 4) as u32,
            ..m.info
        },
        |i, j| m.cells[(j % h) * w + (i % w)],
    );
    let span = f64::from(m.info.resolution) * (w * 4) as f64;
    let o = m.info.origin;
    wavefront(
        &format!("{}x{}", w * 4, h * 4),
        &big,
        (o.x + 1.0, o.y + 1.0),
        (o.x + span - 1.0, o.y + span - 1.0),
    )?;
    if let Some(png) = &a.hospital {
        let src = troupe_mapfile::load(png, 0.07, false, Some((0.0, 0.0)))?;
        let (sw, sh) = src.size();
        let (w, h) = (2000usize, (sh * 2000 + sw / 2) / sw);
        let big = OccMap::from_fn(
            map::Info {
                width: w as u32,
                height: h as u32,
                resolution: 0.07,
                origin: Pose2d::new(0.0, 0.0, 0.0),
            },
            |i, j| src.cells[(j * sh / h) * sw + i * sw / w],
        );
        let (span, mid) = (0.07 * w as f64, 0.07 * h as f64 / 2.0);
        wavefront(
            &format!("hospital {w}x{h}"),
            &big,
            (3.0, mid),
            (span - 3.0, mid),
        )?;
    }
    vfh();
    nd()
}

/// nd's decision on one laser scan: the corridor vfh's figure uses, as a
/// 361-beam laser (0.5°, 8 m) on a Pioneer-sized robot.
fn nd() -> anyhow::Result<()> {
    use troupe_nd::algorithm::{Motion, Nd, Params};
    let nd = Nd::new(Params {
        front: 0.18,
        back: 0.26,
        left: 0.19,
        vlmax: 0.3,
        vamax: 30f64.to_radians(),
        almax: 0.75,
        aamax: 0.75,
        dsmax: 0.4,
        dsmin: 0.1,
        enlarge: 0.02,
        discontinuity: 0.38,
        t: 0.1,
    })
    .map_err(|e| anyhow::anyhow!(e.0))?;
    let points: Vec<(f64, f64)> = (0..361)
        .map(|i| {
            let deg = f64::from(i) * 0.5;
            let r = if (100.0..140.0).contains(&deg) {
                1.2
            } else if !(30.0..=150.0).contains(&deg) {
                0.9
            } else {
                4.0
            };
            let a = (deg - 90.0).to_radians();
            (r * a.cos(), r * a.sin())
        })
        .collect();
    let runs = 20_000;
    let t0 = Instant::now();
    let mut v = Motion { v: 0.0, w: 0.0 };
    for _ in 0..runs {
        v = nd
            .decide((5.0, 1.0), 0.3, (0.0, 0.0, 0.0), v, &points)
            .unwrap_or(Motion { v: 0.0, w: 0.0 });
    }
    say(&format!(
        "nd: {:.1} µs per decision (a 361-beam scan, 180 sectors of 2°)",
        per(t0.elapsed(), runs) * 1e6
    ));
    Ok(())
}
