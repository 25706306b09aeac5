//! `troupe bench stage`: the simulator's speed (simulated s per wall s) and
//! peak memory on the bench worlds and on Stage's own.

use std::io::Write;
use std::process::Command;
use std::time::Instant;

use anyhow::Context;
use clap::Args;

use crate::harness::bench_world;

/// Flags of `troupe bench stage`.
#[derive(Debug, Args)]
pub struct StageBenchArgs {
    /// Simulated seconds per world.
    #[arg(long, default_value_t = 60.0, value_name = "SECS", value_parser = troupe_node::args::seconds)]
    pub seconds: f64,
    /// Run only this world (simple, pioneers100, hospital1000) in this process.
    #[arg(long, hide = true)]
    pub only: Option<String>,
    /// With `--world`: the row's name and what it says the world is, for
    /// a copy the bench wrote (the cave with `wander`).
    #[arg(long, hide = true, num_args = 2, value_names = ["NAME", "WHAT"])]
    pub label: Vec<String>,
    /// Worker threads (the world's `threads`); 1 = one core.
    #[arg(long, default_value_t = 1)]
    pub threads: usize,
    /// Where Stage's sample bitmaps are (cave.png, hospital_section.png).
    #[arg(long, value_name = "DIR")]
    pub bitmaps: Option<std::path::PathBuf>,
    /// Measure ranges as Stage does, on its raster of the walls (what
    /// `stage_quirks 1` turns on), instead of against the exact walls.
    #[arg(long)]
    pub stage_ranges: bool,
    /// Also run Stage's own benchmark worlds from a Stage checkout (its
    /// top directory or its worlds/): benchmark/cave.world and
    /// benchmark/hospital.world, as their authors wrote them, models and
    /// controllers included (`threads` as given here), and the cave with
    /// every robot's controller Stage's `wander`, which reads its laser
    /// every step (a copy written beside cave.world, removed after).
    #[arg(long, value_name = "DIR")]
    pub stage_worlds: Option<std::path::PathBuf>,
    /// Run just this world file instead, as its authors wrote it, models
    /// and controllers included (e.g. Stage's worlds/large.world), and
    /// print its row: time to load, time to run, peak memory (and, for a
    /// world with cameras, the time each takes to draw an image).
    #[arg(long, value_name = "FILE")]
    pub world: Option<std::path::PathBuf>,
    /// Stage's own `stage` program: run each world of `--world` or
    /// `--stage-worlds` with it too, in turn with Troupe, and print both
    /// and their ratio (Stage's copy of the world runs flat out, unpaused,
    /// on `--threads`, until `quit_time` = `--seconds`). Its controllers
    /// need LD_LIBRARY_PATH on Stage's lib/ and STAGEPATH on its plugins.
    #[arg(long, value_name = "BIN")]
    pub stage: Option<std::path::PathBuf>,
    /// With `--stage`: how many pairs of runs (Stage, then Troupe).
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..))]
    pub pairs: u32,
    /// Then cast the same rays on the cave's and the hospital's walls with
    /// the simulator's grid walk and with parry2d, and print both.
    #[arg(long)]
    pub parry: bool,
}

/// What the comparison with Stage takes of the flags.
fn runs(a: &StageBenchArgs) -> crate::vs_stage::Runs {
    crate::vs_stage::Runs {
        seconds: a.seconds,
        threads: a.threads,
        pairs: a.pairs,
    }
}

fn peak_rss_mb() -> f64 {
    crate::harness::status_mb("VmHWM:")
}

/// The memory this process holds now that is not mapped from files (the
/// binary's own pages, 7–10 MB, move with its code layout alone): MB.
fn anon_rss_mb() -> f64 {
    crate::harness::status_mb("RssAnon:")
}

/// `troupe bench stage`: simulated seconds per wall second and peak memory.
pub fn run(a: &StageBenchArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        a.stage.is_none() || a.world.is_some() || a.stage_worlds.is_some(),
        "--stage runs Stage on --world FILE or on --stage-worlds DIR: give one"
    );
    if let (Some(path), Some(stage)) = (&a.world, &a.stage) {
        return crate::vs_stage::compare(&runs(a), stage, path, None);
    }
    if let Some(path) = &a.world {
        let (name, what) = match &a.label[..] {
            [name, what] => (name.clone(), what.clone()),
            _ => (
                path.file_name()
                    .unwrap_or_default()
                    .to_string_lossy()
                    .into_owned(),
                format!("{}, as Stage's authors wrote it", path.display()),
            ),
        };
        let t_load = Instant::now();
        let mut world = troupe_stage::world::load(path)?;
        world.threads = a.threads;
        let what =
            format!("{what}; sensors sensed as Stage senses them, while its controllers read them");
        return run_world(a, &name, world, t_load, &what, false);
    }
    let bitmaps = crate::harness::stage_bitmaps(a.bitmaps.as_deref())?;
    if let Some(name) = &a.only {
        let (text, what) = bench_world(name, &bitmaps, a.threads)?;
        let dir = std::env::temp_dir().join(format!("troupe-bench-stage-{}", std::process::id()));
        std::fs::create_dir_all(&dir)?;
        let path = dir.join(format!("{name}.world"));
        std::fs::write(&path, text)?;
        let t_load = Instant::now();
        let world = troupe_stage::world::load(&path)?;
        let _ = std::fs::remove_dir_all(&dir);
        return run_world(a, name, world, t_load, &what, true);
    }
    writeln!(
        std::io::stdout().lock(),
        "troupe bench stage: {} simulated s per world, {} thread(s), every sensor every step, wander controllers, ranges {}",
        a.seconds,
        a.threads,
        if a.stage_ranges { "on Stage's raster" } else { "against the exact walls" }
    )?;
    let me = std::env::current_exe()?;
    let run = |what: &[&std::ffi::OsStr]| -> anyhow::Result<()> {
        let status = Command::new(&me)
            .args(["bench", "stage", "--seconds", &a.seconds.to_string()])
            .args(["--threads", &a.threads.to_string(), "--bitmaps"])
            .arg(&bitmaps)
            .args(a.stage_ranges.then_some("--stage-ranges"))
            .args(what)
            .status()?;
        anyhow::ensure!(status.success(), "bench world {what:?} failed: {status}");
        Ok(())
    };
    for name in ["simple", "pioneers100", "hospital1000"] {
        run(&["--only".as_ref(), name.as_ref()])?;
    }
    if let Some(dir) = &a.stage_worlds {
        let worlds = [dir.join("worlds"), dir.clone()]
            .into_iter()
            .find(|d| d.join("benchmark/cave.world").exists())
            .with_context(|| {
                format!(
                    "no benchmark/cave.world in {} or its worlds/: point --stage-worlds at a Stage checkout",
                    dir.display()
                )
            })?;
        let cave = worlds.join("benchmark/cave.world");
        let hospital = worlds.join("benchmark/hospital.world");
        let wander = crate::vs_stage::WanderCave::write(&cave)?;
        let label = Some(crate::vs_stage::WanderCave::LABEL);
        for (world, label) in [(&*cave, None), (&*hospital, None), (wander.path(), label)] {
            match &a.stage {
                Some(stage) => crate::vs_stage::compare(&runs(a), stage, world, label)?,
                None => {
                    let mut args = vec!["--world".as_ref(), world.as_os_str()];
                    args.extend(crate::vs_stage::label_args(label));
                    run(&args)?
                }
            }
        }
    }
    if a.parry {
        crate::ray::run(&bitmaps)?;
    }
    Ok(())
}

/// Runs `world` for the bench's seconds and prints its row; every ranger
/// is sensed every step, or (as Stage does) only those its controllers read.
fn run_world(
    a: &StageBenchArgs,
    name: &str,
    world: troupe_stage::world::World,
    t_load: Instant,
    what: &str,
    every_sensor: bool,
) -> anyhow::Result<()> {
    let mut sim = troupe_stage::sim::Sim::new(world).map_err(|e| anyhow::anyhow!(e))?;
    sim.stage_ranges(a.stage_ranges);
    if !every_sensor {
        // No client: only what the controllers read.
        sim.sense_only([]);
    }
    let load = t_load.elapsed();
    let steps = (a.seconds / sim.world().interval_sim).round() as u64;
    let t0 = Instant::now();
    for _ in 0..steps {
        sim.step();
    }
    let wall = t0.elapsed().as_secs_f64();
    let moving = sim
        .bases
        .iter()
        .filter(|b| b.vel.x != 0.0 || b.vel.yaw != 0.0)
        .count();
    writeln!(
        std::io::stdout().lock(),
        "  {name:<13} {:>8.0}x real time  {:>7.1} MB peak  {:>6.1} MB data  ({what}; {:.0} simulated s in {wall:.2} s, load {:.2} s, {moving}/{} moving at the end)",
        sim.time / wall,
        peak_rss_mb(),
        anon_rss_mb(),
        sim.time,
        load.as_secs_f64(),
        sim.bases.len()
    )?;
    // Its cameras, each drawn as its device would draw it, where the
    // robots ended up.
    for m in 0..sim.world().models.len() {
        let Some(cfg) = sim.world().models[m].camera else {
            continue;
        };
        let runs = 50;
        let t0 = Instant::now();
        for _ in 0..runs {
            std::hint::black_box(sim.camera(m));
        }
        let each = t0.elapsed().as_secs_f64() / f64::from(runs);
        let (w, h) = cfg.resolution;
        writeln!(
            std::io::stdout().lock(),
            "  camera `{}`: {w} x {h} pixels in {:.2} ms ({:.0} images/s on one core; Stage's default update_interval asks 10 a simulated second)",
            sim.world().models[m].name,
            each * 1e3,
            1.0 / each
        )?;
    }
    Ok(())
}
