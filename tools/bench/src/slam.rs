//! `troupe bench slam`: `troupe map build` on logs the simulator makes, a
//! robot wandering with odometry that reads its turns wrong: the map's
//! accuracy and coverage against the world's own walls (beside what
//! odometry alone gives), and how much faster than the log's own pace it
//! is built, on one core.
//!
//! The worlds: Troupe's office (worlds/wander.world, its robot driven by
//! the map crate's explorer: Stage's `wander` wedges itself in the
//! office's doorways), and where ../shared/compat is, Stage's own
//! simple.world (the cave, its r0 with its own `wander`) and autolab.world
//! (cbr0 with its own `wander` among thirty others).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::Args;
use troupe_map::eval;
use troupe_map::simulate::{simulate, Driver, Setup};
use troupe_map::slam::Params;
use troupe_map::source::{self, Select};

/// Flags of `troupe bench slam`.
#[derive(Debug, Args)]
pub struct SlamBenchArgs {
    /// Simulated seconds each robot wanders.
    #[arg(long, default_value_t = 900.0)]
    pub seconds: f64,
    /// Odometry's error in yaw (0.05: it reads turns 5% long).
    #[arg(long, default_value_t = 0.05)]
    pub yaw_error: f64,
    /// Where Stage's sample worlds are (simple.world, autolab.world).
    #[arg(long, value_name = "DIR")]
    pub stage_worlds: Option<PathBuf>,
    /// Keep the logs and maps here (default: a temporary directory, removed).
    #[arg(long, value_name = "DIR")]
    pub keep: Option<PathBuf>,
}

/// Runs the bench.
///
/// # Errors
///
/// A world that does not load or simulate, a file that cannot be written.
pub fn run(a: &SlamBenchArgs) -> anyhow::Result<()> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let stage = a
        .stage_worlds
        .clone()
        .unwrap_or_else(|| root.join("../shared/compat/stage"));
    let dir = a.keep.clone().unwrap_or_else(|| {
        std::env::temp_dir().join(format!("troupe-bench-slam-{}", std::process::id()))
    });
    std::fs::create_dir_all(&dir)?;
    let mut worlds = vec![(
        "office",
        root.join("worlds/wander.world"),
        "r0",
        Driver::Explore,
    )];
    if stage.join("simple.world").exists() {
        worlds.push(("cave", stage.join("simple.world"), "r0", Driver::Own));
        worlds.push(("autolab", stage.join("autolab.world"), "cbr0", Driver::Own));
    } else {
        let _ = writeln!(
            std::io::stderr(),
            "bench slam: {} is absent: Stage's worlds left out",
            stage.display()
        );
    }
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "troupe bench slam: {:.0} simulated s a world, odometry {:+.0}% in yaw and +2% in x; accuracy = occupied cells within 10 cm of a wall, coverage = seen walls mapped",
        a.seconds,
        a.yaw_error * 100.0
    )?;
    for (name, path, robot, driver) in worlds {
        let world = match troupe_stage::world::load(&path) {
            Ok(w) => w,
            Err(e) => {
                writeln!(out, "  {name:<8} left out: {e}")?;
                continue;
            }
        };
        let t_sim = Instant::now();
        let run = simulate(
            world,
            &Setup {
                robot: robot.into(),
                seconds: a.seconds,
                odom_error: [0.02, 0.0, a.yaw_error],
                every: 0.1,
                driver,
            },
        )
        .map_err(|e| anyhow::anyhow!("{name}: {e}"))?;
        let sim_s = t_sim.elapsed().as_secs_f64();
        let log = dir.join(format!("{name}.log"));
        std::fs::write(&log, &run.log)?;
        let t0 = Instant::now();
        let rec = source::read(std::slice::from_ref(&log), &Select::default())?;
        let built = troupe_map::build(&rec, Params::default(), |_, _| {});
        let took = t0.elapsed().as_secs_f64();
        built.grid.save(&dir.join(format!("{name}.yaml")))?;
        let t_first = rec.scans[0].t;
        let frame = run.frame(&rec);
        let s = eval::score(
            &built.grid.occupied(),
            &run.obstacles,
            &run.seen,
            frame,
            0.1,
        );
        let odometry = troupe_map::odometry_map(&rec, 0.05);
        let raw = eval::score(&odometry.occupied(), &run.obstacles, &run.seen, frame, 0.1);
        let span = rec.scans.last().map_or(0.0, |l| l.t) - t_first;
        let walls = eval::Near::new(&run.obstacles, 0.1);
        let on_walls = run
            .seen
            .iter()
            .filter(|&&(x, y)| walls.within(x, y, 0.1))
            .count();
        writeln!(
            out,
            "  {name:<8} accuracy {:>5.1}% (odometry alone {:>5.1}%)  coverage {:>5.1}% ({:>5.1}%)  built {:>5.0}x the log's pace ({span:.0} s of log in {took:.2} s)  {} keyframes, {} loop closures, {:.0} m driven (simulated in {sim_s:.1} s; truth check: {:.0}% of the beams' ends on the world's raster)",
            100.0 * s.accuracy,
            100.0 * raw.accuracy,
            100.0 * s.coverage,
            100.0 * raw.coverage,
            span / took.max(1e-9),
            built.slam.keyframes.len(),
            built.slam.closures,
            run.driven,
            100.0 * on_walls as f64 / run.seen.len().max(1) as f64,
        )?;
    }
    if a.keep.is_none() {
        let _ = std::fs::remove_dir_all(&dir);
    } else {
        writeln!(out, "  logs and maps kept in {}", dir.display())?;
    }
    Ok(())
}
