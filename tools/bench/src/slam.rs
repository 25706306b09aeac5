//! `troupe bench slam`: `troupe map build` on logs the simulator makes, a
//! robot wandering with odometry that reads its turns wrong: the map's
//! accuracy and coverage against the world's own walls (beside what
//! odometry alone gives), and how much faster than the log's own pace it
//! is built, on one core; and the online `slam` driver fed the same log
//! scan by scan (through the node harness, as a launched stack feeds it
//! less the network): how many scans a second it takes on one core, and
//! its slowest.
//!
//! With `--datasets DIR`, real robots' CARMEN logs too (the corrected
//! logs of the classic datasets): each mapped from its odometry made
//! wrong, against the trajectory it carries, its RMS error printed.
//!
//! The worlds: Troupe's office (worlds/wander.world, its robot driven by
//! the simulator's `explore`: Stage's `wander` wedges itself in the
//! office's doorways), Troupe's long loop (worlds/loop.world, driven round
//! and round with the wall on its left), and where ../shared/compat is, Stage's own
//! simple.world (the cave, its r0 with its own `wander`) and autolab.world
//! (cbr0 with its own `wander` among thirty others).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use clap::Args;
use troupe_geom::Pose;
use troupe_map::eval;
use troupe_map::simulate::{simulate, Driver, Setup};
use troupe_map::slam::Params;
use troupe_map::source::{self, Recording, Select};

/// Flags of `troupe bench slam`.
#[derive(Debug, Args)]
pub struct SlamBenchArgs {
    /// Simulated seconds each robot wanders.
    #[arg(long, default_value_t = 900.0, value_name = "SECS", value_parser = troupe_node::args::seconds)]
    pub seconds: f64,
    /// Odometry's error in yaw (0.05: it reads turns 5% long).
    #[arg(long, default_value_t = 0.05, value_parser = troupe_node::args::finite)]
    pub yaw_error: f64,
    /// Where Stage's sample worlds are (simple.world, autolab.world).
    #[arg(long, value_name = "DIR")]
    pub stage_worlds: Option<PathBuf>,
    /// Keep the logs and maps here (default: a temporary directory, removed).
    #[arg(long, value_name = "DIR")]
    pub keep: Option<PathBuf>,
    /// Real robots' datasets too: the CARMEN logs in DIR whose scans carry
    /// the corrected trajectory (`*-corrected.log.gz`, `*.gfs.log`), each
    /// mapped from that trajectory with odometry made wrong: distance 3%
    /// long, turns 5% large, 2% random a step.
    #[arg(long, value_name = "DIR")]
    pub datasets: Option<PathBuf>,
    /// Raw logs judged as the SLAM papers judge them: each log in DIR
    /// (`intel.clf`, as CARMEN wrote it, odometry and all) beside the
    /// relations of Kümmerle et al.'s benchmark for it (`intel.relations`),
    /// mapped from its own odometry, its trajectory's error on each relation
    /// printed beside what Cartographer and Graph Mapping reach.
    #[arg(long, value_name = "DIR")]
    pub relations: Option<PathBuf>,
    /// A log the real Player and Stage wrote of Stage's simple.world
    /// (tools/bench/real-player-log.sh writes one: r0 alone, odometry 3%
    /// long), mapped and judged against the cave it was made in.
    #[arg(long, value_name = "LOG")]
    pub player_log: Option<PathBuf>,
    /// The world --player-log was written in, its walls the truth (default:
    /// Stage's simple.world; the script writes one of worlds/slam.world).
    #[arg(long, value_name = "WORLD", requires = "player_log")]
    pub player_world: Option<PathBuf>,
    /// Seeds of the random part of the made-wrong odometry, per dataset.
    #[arg(long, default_value_t = 3, value_name = "N")]
    pub seeds: u64,
    /// The simulated worlds to run, by name (office, loop, cave, autolab);
    /// `none` for only the logs given by --datasets, --relations and
    /// --player-log.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "office,loop,cave,autolab",
        value_name = "NAMES",
        value_parser = ["office", "loop", "cave", "autolab", "none"]
    )]
    pub worlds: Vec<String>,
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
    let mut worlds = vec![
        (
            "office",
            root.join("worlds/wander.world"),
            "r0",
            Driver::Own,
        ),
        (
            "loop",
            root.join("worlds/loop.world"),
            "r0",
            Driver::FollowLeft,
        ),
    ];
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
    worlds.retain(|w| a.worlds.iter().any(|n| n == w.0));
    let mut out = std::io::stdout().lock();
    if !worlds.is_empty() {
        writeln!(
            out,
            "troupe bench slam: {:.0} simulated s a world, odometry {:+.0}% in yaw and +2% in x; accuracy = occupied cells within 10 cm of a wall, coverage = seen walls mapped",
            a.seconds,
            a.yaw_error * 100.0
        )?;
    }
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
        troupe_mapfile::save(
            &built.grid.to_occmap(),
            &dir.join(format!("{name}.yaml")),
            "`troupe bench slam`",
        )?;
        let t_first = rec.scans[0].t;
        let (s, raw) = judged(&rec, &built, &run.obstacles, &run.seen, run.frame(&rec));
        let span = rec.scans.last().map_or(0.0, |l| l.t) - t_first;
        let live = online(&rec)?;
        let ls = eval::score(
            &live.occupied,
            &run.obstacles,
            &run.seen,
            run.frame(&rec),
            0.1,
        );
        writeln!(
            out,
            "  {name:<8} accuracy {:>5.1}% (odometry alone {:>5.1}%)  coverage {:>5.1}% ({:>5.1}%)  built {:>5.0}x the log's pace ({span:.0} s of log in {took:.2} s)  {} keyframes, {} loop closures, {:.0} m driven (simulated in {sim_s:.1} s; {} beam ends on walls, {} on other robots left out)",
            100.0 * s.accuracy,
            100.0 * raw.accuracy,
            100.0 * s.coverage,
            100.0 * raw.coverage,
            span / took.max(1e-9),
            built.slam.keyframes.len(),
            built.slam.closures(),
            run.driven,
            run.seen.len(),
            run.on_movers,
        )?;
        let rate = live.scans as f64 / live.busy.as_secs_f64().max(1e-9);
        let pace = live.scans as f64 / span.max(1e-9);
        writeln!(
            out,
            "  {:<8} online: accuracy {:>5.1}%  coverage {:>5.1}%; the slam driver took {} scans at {rate:.0} a second on one core ({:.0}x the log's {pace:.1} Hz; 10 Hz at 10x real time needs 100), the slowest {:.1} ms, p99 {:.1} ms",
            "",
            100.0 * ls.accuracy,
            100.0 * ls.coverage,
            live.scans,
            rate / pace.max(1e-9),
            live.worst.as_secs_f64() * 1e3,
            live.p99.as_secs_f64() * 1e3,
        )?;
    }
    if let Some(log) = &a.player_log {
        let world = a
            .player_world
            .clone()
            .unwrap_or_else(|| stage.join("simple.world"));
        player_log(log, &world, &dir, &mut out)?;
    }
    if let Some(d) = &a.datasets {
        datasets(d, a.seeds, &dir, &mut out)?;
    }
    if let Some(d) = &a.relations {
        relations(d, &mut out)?;
    }
    if a.keep.is_none() {
        let _ = std::fs::remove_dir_all(&dir);
    } else {
        writeln!(out, "  logs and maps kept in {}", dir.display())?;
    }
    Ok(())
}

/// What the online driver made of a log.
struct Online {
    scans: usize,
    /// Its time in the scans and odometry it was given.
    busy: Duration,
    worst: Duration,
    p99: Duration,
    /// The occupied cells of the map it served at the end.
    occupied: Vec<(f64, f64)>,
}

/// The online `slam` driver fed `rec` as a launched stack feeds it: each
/// scan after the odometry that places it, on this thread.
fn online(rec: &Recording) -> anyhow::Result<Online> {
    let mut times = Vec::with_capacity(rec.scans.len());
    let h = troupe_slam_node::replay(rec.sensor, rec.placed(), |d| times.push(d))?;
    let occupied = h.driver().map().occupied();
    let busy = times.iter().sum();
    times.sort();
    Ok(Online {
        scans: times.len(),
        busy,
        worst: times.last().copied().unwrap_or_default(),
        p99: crate::harness::percentile(&times, 0.99),
        occupied,
    })
}

/// A real Player + Stage log of `world` (Stage's cave, or a world of
/// ours), mapped: its accuracy against the world's walls after the best
/// rigid alignment (Stage's odometry frame is the world's: simple.world
/// and slam.world set `localization_origin [0 0 0 0]`), its coverage of
/// the world's wall faces that face the space the robot set off in,
/// offline and online. The map and its picture against the walls are
/// written to `work` as `player-WORLD.yaml` and
/// `player-WORLD-against-truth.png`.
fn player_log(log: &Path, world: &Path, work: &Path, out: &mut impl Write) -> anyhow::Result<()> {
    let w = troupe_stage::world::load(world).map_err(|e| anyhow::anyhow!("{e}"))?;
    let statics = troupe_map::simulate::statics(&w)?;
    let t0 = Instant::now();
    let rec = source::read(&[log.to_owned()], &Select::default())
        .map_err(|e| anyhow::anyhow!("{}: {e}", log.display()))?;
    // Odometry starts where the robot does (the world's frame).
    let start = rec.placed().first().map_or((0.0, 0.0), |(o, _)| (o.x, o.y));
    let faces = statics.facing(start);
    let obstacles = statics.all;
    let built = troupe_map::build(&rec, Params::default(), |_, _| {});
    let took = t0.elapsed().as_secs_f64();
    let span = rec.scans.last().map_or(0.0, |l| l.t) - rec.scans[0].t;
    let same = Pose::new(0.0, 0.0, 0.0);
    let (s, raw) = judged(&rec, &built, &obstacles, &faces, same);
    let live = online(&rec)?;
    let ls = eval::score(&live.occupied, &obstacles, &faces, same, 0.1);
    let stem = world
        .file_stem()
        .map_or("world".into(), |s| s.to_string_lossy());
    troupe_mapfile::save(
        &built.grid.to_occmap(),
        &work.join(format!("player-{stem}.yaml")),
        "`troupe bench slam`",
    )?;
    overlay(
        &work.join(format!("player-{stem}-against-truth.png")),
        &built.grid.occupied(),
        &obstacles,
        s.alignment,
    )?;
    writeln!(
        out,
        "troupe bench slam: {} (the real Player + Stage, {}): {} scans, {span:.0} s; coverage = the wall faces facing the robot's space mapped\n  \
         player   accuracy {:>5.1}% (odometry alone {:>5.1}%, online {:>5.1}%)  coverage {:>5.1}% ({:>5.1}%, online {:>5.1}%)  built {:>5.0}x the log's pace ({span:.0} s of log in {took:.2} s)  {} keyframes, {}",
        log.display(),
        world.display(),
        rec.scans.len(),
        100.0 * s.accuracy,
        100.0 * raw.accuracy,
        100.0 * ls.accuracy,
        100.0 * s.coverage,
        100.0 * raw.coverage,
        100.0 * ls.coverage,
        span / took.max(1e-9),
        built.slam.keyframes.len(),
        closures(&built.slam),
    )?;
    Ok(())
}

/// Writes `path`, a picture of a map against its truth, 5 cm a pixel: the
/// true walls grey, the map's occupied cells (laid in the truth's frame by
/// `frame`) black where within 10 cm of a wall and red where not.
fn overlay(
    path: &Path,
    occupied: &[(f64, f64)],
    walls: &[(f64, f64)],
    frame: Pose,
) -> anyhow::Result<()> {
    const RES: f64 = 0.05;
    let place = frame.applier();
    let map: Vec<(f64, f64)> = occupied.iter().map(|&(x, y)| place(x, y)).collect();
    let (mut lo, mut hi) = ((f64::MAX, f64::MAX), (f64::MIN, f64::MIN));
    for &(x, y) in walls.iter().chain(&map) {
        lo = (lo.0.min(x), lo.1.min(y));
        hi = (hi.0.max(x), hi.1.max(y));
    }
    let w = (((hi.0 - lo.0) / RES).ceil() as u32 + 1).min(8000);
    let h = (((hi.1 - lo.1) / RES).ceil() as u32 + 1).min(8000);
    let mut img = image::RgbImage::from_pixel(w, h, image::Rgb([255, 255, 255]));
    let mut put = |x: f64, y: f64, c: [u8; 3]| {
        let i = ((x - lo.0) / RES) as u32;
        let j = ((y - lo.1) / RES) as u32;
        if i < w && j < h {
            img.put_pixel(i, h - 1 - j, image::Rgb(c));
        }
    };
    for &(x, y) in walls {
        put(x, y, [190, 190, 190]);
    }
    let near = eval::Near::new(walls, 0.1);
    for &(x, y) in &map {
        let c = if near.within(x, y, 0.1) {
            [0, 0, 0]
        } else {
            [220, 0, 0]
        };
        put(x, y, c);
    }
    img.save(path)?;
    Ok(())
}

/// The loop closures `slam` made and how far they moved the graph.
fn closures(slam: &troupe_map::slam::Slam) -> String {
    let mut shifts: Vec<f64> = slam.loops.iter().map(|l| l.shift).collect();
    shifts.sort_by(f64::total_cmp);
    match shifts.last() {
        None => "no loop closures".to_owned(),
        Some(max) => format!(
            "{} loop closures (shifting the graph {:.2} m at the median, {max:.2} m at most; {} taken back)",
            shifts.len(),
            shifts[shifts.len() / 2],
            slam.rejected
        ),
    }
}

/// The table of real robots' datasets: each CARMEN log of `dir` read with
/// its scans' poses (the corrected trajectory) as odometry, which is the
/// reference, then mapped from that odometry made wrong.
fn datasets(dir: &Path, seeds: u64, work: &Path, out: &mut impl Write) -> anyhow::Result<()> {
    let logs: Vec<PathBuf> = files(dir, "--datasets")?
        .into_iter()
        .filter(|p| is_log(p))
        .collect();
    writeln!(
        out,
        "troupe bench slam: real robots' datasets in {} (CARMEN logs; reference: the corrected trajectory the log carries); \
         accuracy = the map's occupied cells within 10 cm of a hit at the reference poses, \
         coverage = the reference map's walls (every scan traced at the reference poses, as the builder traces: what stays occupied) within 10 cm of the map's, \
         beside it the share of every hit (people and a blurred reference's spread included), \
         trajectory = RMS distance from the reference after the best rigid alignment",
        dir.display()
    )?;
    for path in logs {
        let name = stem(&path);
        let name = name.strip_suffix("-corrected").unwrap_or(&name).to_owned();
        let text =
            source::read_bytes(&path).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
        let text = String::from_utf8_lossy(&text);
        let reference_log = work.join(format!("{name}-reference.clf"));
        let kept: String = text
            .lines()
            .filter(|l| !l.starts_with("ODOM"))
            .flat_map(|l| [l, "\n"])
            .collect();
        std::fs::write(&reference_log, kept)?;
        let reference = source::read(std::slice::from_ref(&reference_log), &Select::default())
            .map_err(|e| anyhow::anyhow!("{name}: {e}"))?;
        let truth = Truth::of(&reference);
        let span = reference.scans.last().map_or(0.0, |l| l.t) - reference.scans[0].t;
        writeln!(
            out,
            "  {name}: {} scans, {span:.0} s, {:.0} m of reference trajectory",
            reference.scans.len(),
            truth.length
        )?;
        // Not from the logs' own ODOM lines: in these corrected logs
        // GMapping re-anchored them at each corrected scan pose (the ODOM
        // stamped 0 after each FLASER), a jump at every scan. The made-wrong
        // odometry starts where the reference does: the frames are one.
        // Seed 0 maps from the reference itself: what the builder makes of
        // the data where odometry is as good as the reference, the ceiling
        // the seeds are held to.
        for seed in 0..=seeds {
            let (what, rec) = match seed {
                0 => ("the reference as odometry".to_owned(), reference.clone()),
                _ => (
                    format!("wrong odometry, seed {seed}"),
                    made_wrong(&reference, seed),
                ),
            };
            let t0 = Instant::now();
            let built = troupe_map::build(&rec, Params::default(), |_, _| {});
            let took = t0.elapsed().as_secs_f64();
            let same = Pose::new(0.0, 0.0, 0.0);
            let (s, raw) = judged(&rec, &built, &truth.walls, &truth.map, same);
            let hits = eval::coverage(&built.grid.occupied(), s.alignment, &truth.walls, 0.1);
            let (rms, raw_rms) = truth.trajectory_error(&rec, &built.slam);
            let sharp = filled(&rec, |t, odom| built.slam.corrected(t, odom));
            let live = online(&rec)?;
            let ls = eval::score(&live.occupied, &truth.walls, &truth.map, same, 0.1);
            writeln!(
                out,
                "    {what:<25} accuracy {:>5.1}% (odometry alone {:>5.1}%, online {:>5.1}%)  coverage {:>5.1}% (online {:>5.1}%; of every hit {:>5.1}%)  trajectory {:.2} m (odometry alone {:.2} m)  hits fill {} cells (the reference's {})  built {:>4.0}x the log's pace  {}",
                100.0 * s.accuracy,
                100.0 * raw.accuracy,
                100.0 * ls.accuracy,
                100.0 * s.coverage,
                100.0 * ls.coverage,
                100.0 * hits,
                rms,
                raw_rms,
                sharp,
                truth.filled,
                span / took.max(1e-9),
                closures(&built.slam),
            )?;
            let stem = format!("{name}-{}", what.replace([' ', ','], "-"));
            let yaml = work.join(format!("{stem}.yaml"));
            troupe_mapfile::save(&built.grid.to_occmap(), &yaml, "`troupe bench slam`")?;
            overlay(
                &work.join(format!("{stem}-against-truth.png")),
                &built.grid.occupied(),
                &truth.walls,
                s.alignment,
            )?;
        }
    }
    Ok(())
}

/// The files in `dir`, in order; `flag` names the directory in the error.
fn files(dir: &Path, flag: &str) -> anyhow::Result<Vec<PathBuf>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| anyhow::anyhow!("{flag} {}: {e}", dir.display()))?
        .flatten()
        .map(|e| e.path())
        .collect();
    files.sort();
    Ok(files)
}

/// Whether `path` is a log `troupe map build` reads (`.clf`, `.log`, `.gz`).
fn is_log(path: &Path) -> bool {
    let n = path.to_string_lossy();
    n.ends_with(".log") || n.ends_with(".clf") || n.ends_with(".gz")
}

/// A log's name before its first dot: `intel` of `intel.clf.gz`.
fn stem(path: &Path) -> String {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    name.split('.').next().unwrap_or("?").to_owned()
}

/// How `built` scores against `obstacles` and the walls `seen`, and how
/// the map of odometry alone would, the map's frame at `frame` in theirs.
fn judged(
    rec: &Recording,
    built: &troupe_map::Built,
    obstacles: &[(f64, f64)],
    seen: &[(f64, f64)],
    frame: Pose,
) -> (eval::Score, eval::Score) {
    let odometry = troupe_map::odometry_map(rec, 0.05);
    (
        eval::score(&built.grid.occupied(), obstacles, seen, frame, 0.1),
        eval::score(&odometry.occupied(), obstacles, seen, frame, 0.1),
    )
}

/// A dataset's reference: its poses at each scan and the walls they saw.
struct Truth {
    /// (time, pose) of each scan.
    poses: Vec<(f64, Pose)>,
    /// The scans' hits at the reference poses, one per 2.5 cm.
    walls: Vec<(f64, f64)>,
    /// The occupied cells of every scan traced at the reference poses, as
    /// the builder traces its keyframes: the walls, without what moved
    /// (a visitor's legs, seen once and passed through after).
    map: Vec<(f64, f64)>,
    /// Metres the reference trajectory runs.
    length: f64,
    /// The 5 cm cells its hits fill (see [`filled`]).
    filled: usize,
}

impl Truth {
    fn of(rec: &Recording) -> Truth {
        let poses: Vec<(f64, Pose)> = rec.placed().iter().map(|&(p, s)| (s.t, p)).collect();
        let mut seen = std::collections::HashSet::new();
        let walls = hits(rec, |_, odom| odom)
            .filter(|&(x, y)| seen.insert(cell(x, y, 0.025)))
            .collect();
        let length = poses
            .windows(2)
            .map(|w| (w[1].1.x - w[0].1.x).hypot(w[1].1.y - w[0].1.y))
            .sum();
        Truth {
            poses,
            walls,
            map: troupe_map::odometry_map(rec, 0.05).occupied(),
            length,
            filled: filled(rec, |_, odom| odom),
        }
    }

    /// The RMS error of the built trajectory (and of odometry alone) at
    /// the reference's scan times.
    fn trajectory_error(&self, rec: &Recording, slam: &troupe_map::slam::Slam) -> (f64, f64) {
        let (mut built, mut odom, mut truth) = (Vec::new(), Vec::new(), Vec::new());
        for &(t, p) in &self.poses {
            let Some(o) = rec.odom_at(t) else { continue };
            let c = slam.corrected(t, o);
            built.push((c.x, c.y));
            odom.push((o.x, o.y));
            truth.push((p.x, p.y));
        }
        (
            eval::rms_after_alignment(&built, &truth).0,
            eval::rms_after_alignment(&odom, &truth).0,
        )
    }
}

/// How many 5 cm cells the scans' hits (to 30 m) fill when each scan is
/// placed where `pose` (of its time and odometric pose) says: a trajectory's
/// consistency with its own scans, needing no reference. A wall seen from
/// many poses fills one band of cells where the poses agree and several
/// where they do not, so the fewer the better. A dataset's reference is
/// itself a SLAM result (GMapping's, for the corrected CARMEN logs); where
/// the built trajectory fills fewer cells than the reference's, the
/// reference is the blurrier of the two, and agreement with it is bounded
/// by its own error, not the builder's.
fn filled(rec: &Recording, pose: impl Fn(f64, Pose) -> Pose) -> usize {
    let cells: std::collections::HashSet<_> =
        hits(rec, pose).map(|(x, y)| cell(x, y, 0.05)).collect();
    cells.len()
}

/// Where the scans' hits (to 30 m) land, each scan placed where `pose`
/// (of its time and odometric pose) says.
fn hits<'a>(
    rec: &'a Recording,
    pose: impl Fn(f64, Pose) -> Pose + 'a,
) -> impl Iterator<Item = (f64, f64)> + 'a {
    rec.placed().into_iter().flat_map(move |(odom, scan)| {
        let place = pose(scan.t, odom).compose(&rec.sensor).applier();
        scan.hits()
            .filter(|&(r, _)| r <= 30.0)
            .map(move |(r, a)| place(r * a.cos(), r * a.sin()))
    })
}

/// The cell of `size` metres (x, y) lies in.
fn cell(x: f64, y: f64, size: f64) -> (i64, i64) {
    ((x / size).floor() as i64, (y / size).floor() as i64)
}

/// `rec` with its odometry made wrong as a wrong wheel diameter and
/// wheelbase make it (each step's distance 3% long, its turn 5% large)
/// and 2% random on each step's distance and turn, seeded.
fn made_wrong(rec: &Recording, seed: u64) -> Recording {
    use rand::{Rng, SeedableRng};
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut noise = || 1.0 + 0.02 * (rng.gen::<f64>() * 2.0 - 1.0) * 3f64.sqrt();
    let mut out = rec.clone();
    let mut at = rec
        .odom
        .first()
        .map_or(Pose::new(0.0, 0.0, 0.0), |o| o.pose);
    for (i, o) in out.odom.iter_mut().enumerate().skip(1) {
        let d = rec.odom[i - 1].pose.inverse().compose(&rec.odom[i].pose);
        let (k, turn) = (1.03 * noise(), 1.05 * noise());
        at = at.compose(&Pose::new(d.x * k, d.y * k, d.yaw * turn));
        o.pose = at;
    }
    out
}

/// A relation of Kümmerle et al.'s benchmark: the pose at time `b` in the
/// frame of the pose at time `a`, as people who knew the building judged it.
struct Relation {
    a: f64,
    b: f64,
    rel: Pose,
}

/// Reads a `.relations` file.
fn read_relations(path: &Path) -> anyhow::Result<Vec<Relation>> {
    let text =
        std::fs::read_to_string(path).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    parse_relations(&text, &path.display().to_string())
}

/// The relations of a `.relations` file's `text`: one a line, `t1 t2 x y z
/// roll pitch yaw` (metres and radians), `#` comments; `place` names the
/// file in errors.
fn parse_relations(text: &str, place: &str) -> anyhow::Result<Vec<Relation>> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let f: Vec<f64> = line
            .split_whitespace()
            .map(str::parse)
            .collect::<Result<_, _>>()
            .map_err(|e| anyhow::anyhow!("{place}:{}: {e}", i + 1))?;
        let [a, b, x, y, _, _, _, yaw] = f[..] else {
            anyhow::bail!(
                "{place}:{}: {} numbers where a relation has 8 (t1 t2 x y z roll pitch yaw)",
                i + 1,
                f.len()
            );
        };
        out.push(Relation {
            a,
            b,
            rel: Pose::new(x, y, yaw),
        });
    }
    Ok(out)
}

/// Mean and (sample) standard deviation.
fn mean_std(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n.max(1.0);
    let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
    (mean, var.sqrt())
}

/// The errors of a trajectory (`pose` of a time) on `relations`: the
/// translational (m) and rotational (rad) size of each relation's
/// difference from what the trajectory says, for those whose two times it
/// has a pose for.
fn relation_errors(
    relations: &[Relation],
    pose: impl Fn(f64) -> Option<Pose>,
) -> (Vec<f64>, Vec<f64>) {
    let (mut trans, mut rot) = (Vec::new(), Vec::new());
    for r in relations {
        let (Some(a), Some(b)) = (pose(r.a), pose(r.b)) else {
            continue;
        };
        // As Cartographer's relations metrics compute it: what is left of
        // the trajectory's relative pose once the relation's is undone.
        let e = a.inverse().compose(&b).compose(&r.rel.inverse());
        trans.push(e.x.hypot(e.y));
        rot.push(troupe_geom::normalize(e.yaw).abs());
    }
    (trans, rot)
}

/// What the papers report on the benchmark's datasets: the absolute
/// translational (m) and rotational (°) error on their relations, mean ±
/// standard deviation. Hess et al., "Real-Time Loop Closure in 2D LIDAR
/// SLAM" (ICRA 2016), Table II: Cartographer beside Graph Mapping as
/// Kümmerle et al. (2009) measured it.
const PUBLISHED: [(&str, &str); 5] = [
    (
        "aces",
        "Cartographer 0.0375 ± 0.0426 m, 0.373 ± 0.469°; Graph Mapping 0.044 ± 0.044 m, 0.4 ± 0.4°",
    ),
    (
        "fr079",
        "Cartographer 0.0452 ± 0.0354 m, 0.538 ± 0.718°; Graph Mapping 0.056 ± 0.042 m, 0.6 ± 0.6°",
    ),
    (
        "intel",
        "Cartographer 0.0229 ± 0.0239 m, 0.453 ± 1.335°; Graph Mapping 0.031 ± 0.026 m, 1.3 ± 4.7°",
    ),
    (
        "mit-csail",
        "Cartographer 0.0319 ± 0.0363 m, 0.369 ± 0.365°; Graph Mapping 0.004 ± 0.009 m, 0.05 ± 0.08°",
    ),
    (
        "mit-killian",
        "Cartographer 0.0395 ± 0.0488 m, 0.352 ± 0.353°; Graph Mapping 0.050 ± 0.056 m, 0.5 ± 0.5°",
    ),
];

/// The table of raw logs with their relations: each log of `dir` mapped
/// from its own odometry, as recorded, and its trajectory judged on the
/// relations of the file of the same name (`intel.clf`, `intel.relations`).
fn relations(dir: &Path, out: &mut impl Write) -> anyhow::Result<()> {
    let all = files(dir, "--relations")?;
    let logs: Vec<(PathBuf, PathBuf)> = all
        .iter()
        .filter(|p| is_log(p))
        .filter_map(|p| {
            let rel = p.with_file_name(format!("{}.relations", stem(p)));
            all.contains(&rel).then(|| (p.clone(), rel))
        })
        .collect();
    let alone: Vec<String> = all
        .iter()
        .filter(|p| p.extension().is_some_and(|x| x == "relations"))
        .filter(|p| !logs.iter().any(|(_, r)| r == *p))
        .map(|p| p.display().to_string())
        .collect();
    if !alone.is_empty() {
        let _ = writeln!(
            std::io::stderr(),
            "bench slam: no log beside {}: left out",
            alone.join(", ")
        );
    }
    if logs.is_empty() {
        anyhow::bail!(
            "--relations {}: no log (.clf, .log, .gz) with a .relations file of its name beside it",
            dir.display()
        );
    }
    writeln!(
        out,
        "troupe bench slam: raw logs with Kümmerle et al.'s relations in {}; each mapped from its own odometry; \
         error of a relation = how far the relative pose between its two times, on the built trajectory, is from the relation's (mean ± std over the relations, as the SLAM papers give it)",
        dir.display()
    )?;
    for (log, rel) in logs {
        let name = stem(&log);
        let relations = read_relations(&rel)?;
        let rec = source::read(std::slice::from_ref(&log), &Select::default())
            .map_err(|e| anyhow::anyhow!("{name}: {e}"))?;
        let span = rec.scans.last().map_or(0.0, |l| l.t) - rec.scans.first().map_or(0.0, |s| s.t);
        let t0 = Instant::now();
        let built = troupe_map::build(&rec, Params::default(), |_, _| {});
        let took = t0.elapsed().as_secs_f64();
        let (trans, rot) = relation_errors(&relations, |t| {
            Some(built.slam.corrected(t, rec.odom_at(t)?))
        });
        let (odom_trans, odom_rot) = relation_errors(&relations, |t| rec.odom_at(t));
        let (t, ts) = mean_std(&trans);
        let (r, rs) = mean_std(&rot);
        let (ot, ots) = mean_std(&odom_trans);
        let (or, ors) = mean_std(&odom_rot);
        writeln!(
            out,
            "  {name:<11} {} scans, {span:.0} s; {} of {} relations: translation {t:.3} ± {ts:.3} m (odometry alone {ot:.3} ± {ots:.3}), rotation {:.2} ± {:.2}° ({:.2} ± {:.2}°)  built {:.0}x the log's pace  {}",
            rec.scans.len(),
            trans.len(),
            relations.len(),
            r.to_degrees(),
            rs.to_degrees(),
            or.to_degrees(),
            ors.to_degrees(),
            span / took.max(1e-9),
            closures(&built.slam),
        )?;
        if let Some((_, said)) = PUBLISHED.iter().find(|(n, _)| *n == name) {
            writeln!(
                out,
                "              published (Hess et al. 2016, Table II): {said}"
            )?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, PI};

    #[test]
    fn a_trajectory_is_judged_on_its_relative_poses_not_where_it_lies() {
        // Straight on 1 m, then a quarter turn on the spot.
        let rel = parse_relations(
            "# timestamp1 timestamp2 x y z roll pitch yaw\n\
             1.0 2.0 1.0 0.0 0 0 0 0.0\n\
             2.0 3.0 0.0 0.0 0 0 0 1.5707963\n\
             9.0 10.0 1.0 0.0 0 0 0 0.0\n",
            "t.relations",
        )
        .unwrap();
        assert_eq!(rel.len(), 3);
        // The same motion, started elsewhere and heading north, its first
        // step 10 cm long; nothing known at 9 and 10 s.
        let pose = |t: f64| match t {
            1.0 => Some(Pose::new(5.0, 5.0, FRAC_PI_2)),
            2.0 => Some(Pose::new(5.0, 6.1, FRAC_PI_2)),
            3.0 => Some(Pose::new(5.0, 6.1, PI)),
            _ => None,
        };
        let (trans, rot) = relation_errors(&rel, pose);
        assert_eq!(trans.len(), 2, "the relation of unknown times is left out");
        assert!(
            (trans[0] - 0.1).abs() < 1e-9 && trans[1] < 1e-6,
            "{trans:?}"
        );
        assert!(rot.iter().all(|r| *r < 1e-6), "{rot:?}");

        let err = parse_relations("1.0 2.0 1.0 0.0\n", "t.relations")
            .err()
            .unwrap()
            .to_string();
        assert!(
            err.contains("t.relations:1") && err.contains("4 numbers"),
            "{err}"
        );
        let err = parse_relations("1.0 2.0 x 0 0 0 0 0\n", "t.relations")
            .err()
            .unwrap()
            .to_string();
        assert!(err.contains("t.relations:1"), "{err}");
    }
}
