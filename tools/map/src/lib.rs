//! Maps from logs: `troupe map build` makes an occupancy map from a
//! robot's odometry and laser, as Player's course had users do with
//! GMapping; `troupe map save` writes a live map device's map (the `slam`
//! driver's) to files, and `troupe map show` draws one in the terminal.
//!
//! The algorithm is libs/slam's (troupe-slam); this crate reads the logs,
//! runs it, writes and judges the map:
//!
//! - [`source`]: odometry and scans from Player text logs, MCAP recordings
//!   (Troupe's, and ROS 2 bags: LaserScan, Odometry, `/tf_static`) and
//!   CARMEN logs ([`carmen`]);
//! - [`eval`]: a map's accuracy and coverage against the true world;
//! - [`simulate`]: logs made with Troupe's Stage, with their truth.

pub mod carmen;
pub mod eval;
mod ros2;
pub mod simulate;
pub mod source;

pub use troupe_slam::{graph, matcher, occupancy, slam};

use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::{Args, Subcommand};
use troupe_geom::Pose;
use troupe_msgs::{DevAddr, Interface, DEFAULT_ROBOT};
use troupe_node::ZenohArgs;

use crate::source::{Pick, Recording, Select};
use troupe_slam::occupancy::Occupancy;
use troupe_slam::slam::{Params, Slam};

/// `troupe map`'s subcommands.
#[derive(Debug, Subcommand)]
pub enum MapCmd {
    /// Build an occupancy map from logs of a robot's odometry and laser (SLAM).
    #[command(after_help = "Examples:
  troupe map build run.log -o cave.yaml                 # a Player log (writelog)
  troupe map build run.mcap -o cave.yaml                # a `troupe record` recording
  troupe map build intel.clf.gz -o intel.yaml           # a CARMEN log (the classic datasets), gzipped or not
  troupe map build bag_0.mcap --scan /scan --odom /odom -o lab.yaml   # a ROS 2 bag (MCAP)
  troupe map build a.log b.log --odom 6666:position2d:0 --scan 6666:laser:0 -o r1.yaml
  troupe map build run.log -o cave.yaml --trajectory poses.txt

The map is a PNG beside a YAML in ROS map_server's format (image, resolution,
origin, negate, occupied_thresh, free_thresh): `mapfile` serves it as it is
(driver ( name \"mapfile\" provides [\"map:0\"] filename \"cave.yaml\" )), and
Nav2, slam_toolbox and Foxglove read it. The builder matches each keyframe's
scan against the map the last few made, and closes loops where the robot
comes back to where it has been; the summary says how many.")]
    Build(BuildArgs),
    /// Save a live map (the `slam` driver's as it builds, or any map
    /// device's) as map_server's YAML and PNG.
    #[command(after_help = "Examples:
  troupe map save -o live.yaml                          # map:0 of robot 6665
  troupe map save --map 6666:map:0 -o r1.yaml           # another robot's

It asks the device for its info and its cells as any client does (GET_INFO,
then GET_DATA a tile at a time), so it works on a running stack from any
host that reaches its router (--connect). The map is the one the device
serves now: the `slam` driver refreshes it every `map_every` scans and after
each loop closure.")]
    Save(SaveArgs),
    /// Draw a map (a map_server YAML, or an image) in the terminal.
    #[command(after_help = "Example:
  troupe map show cave.yaml --width 100")]
    Show(ShowArgs),
}

/// Flags of `troupe map build`.
#[derive(Debug, Args)]
pub struct BuildArgs {
    /// Player text logs, MCAP recordings and CARMEN logs (`.clf`, `.log`;
    /// text logs may be gzipped), read together in time order.
    #[arg(required = true, value_name = "LOG")]
    pub logs: Vec<PathBuf>,
    /// Where to write the map's YAML (the PNG goes beside it, same name).
    #[arg(short = 'o', long, value_name = "MAP.yaml")]
    pub output: PathBuf,
    /// Metres per cell.
    #[arg(long, default_value_t = 0.05, value_name = "M", value_parser = troupe_node::args::finite)]
    pub resolution: f64,
    /// The odometry when the log holds several: a position2d
    /// (`6665:position2d:0`), or in a ROS 2 bag an Odometry topic (`/odom`).
    #[arg(long, value_name = "DEVICE|TOPIC")]
    pub odom: Option<Pick>,
    /// The range sensor when the log holds several: a laser or a ranger
    /// (`6665:laser:0`), or in a ROS 2 bag a LaserScan topic (`/scan`).
    #[arg(long, value_name = "DEVICE|TOPIC")]
    pub scan: Option<Pick>,
    /// Also write the corrected trajectory: `time x y yaw` a line, one per scan.
    #[arg(long, value_name = "FILE")]
    pub trajectory: Option<PathBuf>,
}

/// Flags of `troupe map save`.
#[derive(Debug, Args)]
pub struct SaveArgs {
    /// The map device (`map:0` is robot 6665's).
    #[arg(long, default_value = "map:0", value_name = "DEVICE")]
    pub map: DevAddr,
    /// Where to write the map's YAML (the PNG goes beside it, same name).
    #[arg(short = 'o', long, value_name = "MAP.yaml")]
    pub output: PathBuf,
}

/// Flags of `troupe map show`.
#[derive(Debug, Args)]
pub struct ShowArgs {
    /// The map: a map_server YAML, or a PNG/PGM.
    pub map: PathBuf,
    /// Characters across (default: the terminal's width, or 80).
    #[arg(long, value_name = "N")]
    pub width: Option<u32>,
}

/// Runs a `troupe map` subcommand.
///
/// # Errors
///
/// What the subcommand met: an unreadable log, a map that cannot be written.
pub fn run(cmd: MapCmd, z: &ZenohArgs) -> anyhow::Result<()> {
    match cmd {
        MapCmd::Build(a) => build_cmd(&a),
        MapCmd::Save(a) => save(&a, z),
        MapCmd::Show(a) => show(&a),
    }
}

fn save(a: &SaveArgs, z: &ZenohArgs) -> anyhow::Result<()> {
    if a.map.interface != Interface::Map {
        anyhow::bail!("--map {}: not a map device (map:0, 6666:map:0)", a.map);
    }
    let dev = a.map.device(a.map.robot.unwrap_or(DEFAULT_ROBOT));
    let client = troupe_client::Client::connect(z, dev.robot)?;
    let mut proxy = troupe_client::MapProxy::new(&client, dev.index);
    proxy
        .request_map()
        .with_context(|| format!("asking {dev} for its map"))?;
    let map = troupe_geom::occmap::OccMap {
        info: proxy.info(),
        cells: proxy.cells().to_vec(),
    };
    let png = troupe_mapfile::save(&map, &a.output, &format!("`troupe map save` from {dev}"))?;
    let (w, h) = map.size();
    let known = map
        .cells
        .iter()
        .filter(|&&c| c != troupe_geom::occmap::UNKNOWN)
        .count();
    writeln!(
        std::io::stdout().lock(),
        "troupe map: {} ({w} x {h} cells of {} m, {known} known) and {}, from {dev}",
        a.output.display(),
        map.info.resolution,
        png.display()
    )?;
    Ok(())
}

/// A built map and how it was made.
pub struct Built {
    /// The builder, with its keyframes and graph.
    pub slam: Slam,
    /// The map.
    pub grid: Occupancy,
    /// Scans traced into the map.
    pub scans: usize,
    /// Scans outside the odometry's time span, left out.
    pub unplaced: usize,
}

/// Builds the map of `rec`; `progress` is told how many scans are done
/// and the log time reached.
pub fn build(rec: &Recording, params: Params, mut progress: impl FnMut(usize, f64)) -> Built {
    let placed = rec.placed();
    let mut slam = Slam::new(params);
    for (k, (odom, scan)) in placed.iter().enumerate() {
        if !slam.add(*odom, scan, rec.sensor) {
            slam.place(*odom, scan, rec.sensor);
        }
        if k % 50 == 0 {
            progress(k, scan.t);
        }
    }
    slam.finish();
    let mut grid = Occupancy::new(params.resolution);
    slam.trace(&mut grid, 0..slam.keyframes.len());
    grid.trim(10);
    progress(rec.scans.len(), rec.scans.last().map_or(0.0, |s| s.t));
    Built {
        slam,
        grid,
        scans: placed.len(),
        unplaced: rec.scans.len() - placed.len(),
    }
}

/// The map odometry alone makes of `rec`: every scan traced from the
/// odometric pose, uncorrected (what a map is judged against).
pub fn odometry_map(rec: &Recording, resolution: f64) -> Occupancy {
    let mut grid = Occupancy::new(resolution);
    for (odom, scan) in rec.placed() {
        grid.add_scan(odom.compose(&rec.sensor), scan);
    }
    grid
}

fn build_cmd(a: &BuildArgs) -> anyhow::Result<()> {
    if !(a.resolution.is_finite() && a.resolution > 0.0) {
        anyhow::bail!("--resolution must be a positive number of metres");
    }
    let t0 = Instant::now();
    let select = Select {
        odom: a.odom.clone(),
        scan: a.scan.clone(),
    };
    let rec = source::read(&a.logs, &select)?;
    let mut err = std::io::stderr().lock();
    for w in &rec.warnings {
        let _ = writeln!(err, "warning: {w}");
    }
    let _ = writeln!(err, "troupe map: {}", rec.describe());
    let tty = std::io::stderr().is_terminal();
    let total = rec.scans.len();
    let started = Instant::now();
    let mut last_draw = Instant::now() - Duration::from_secs(1);
    let params = Params {
        resolution: a.resolution,
        ..Params::default()
    };
    let built = build(&rec, params, |done, t| {
        if tty && last_draw.elapsed() >= Duration::from_millis(100) {
            last_draw = Instant::now();
            let rate = t / started.elapsed().as_secs_f64().max(1e-3);
            let _ = write!(
                err,
                "\r  {done}/{total} scans  {t:.0} s of log  {rate:.0}x its pace   "
            );
            let _ = err.flush();
        }
    });
    if tty {
        let _ = writeln!(err);
    }
    let png = troupe_mapfile::save(&built.grid.to_occmap(), &a.output, "`troupe map build`")?;
    if let Some(path) = &a.trajectory {
        write_trajectory(path, &rec, &built.slam)?;
    }
    let span = match (rec.scans.first(), rec.scans.last()) {
        (Some(f), Some(l)) => l.t - f.t,
        _ => 0.0,
    };
    let took = t0.elapsed().as_secs_f64();
    let (w, h) = built.grid.size();
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "troupe map: {} ({} x {} cells of {} m) and {}",
        a.output.display(),
        w,
        h,
        a.resolution,
        png.display()
    )?;
    writeln!(
        out,
        "  {} scans used ({} keyframes, {} found only in a wider search, {} kept odometry's guess; {} of the {} between them placed by their own match), {} loop closures, trajectory {:.1} m, {:.1} s of log in {:.2} s ({:.0}x)",
        built.scans,
        built.slam.keyframes.len(),
        built.slam.widened,
        built.slam.unmatched,
        built.slam.placed(),
        built.scans.saturating_sub(built.slam.keyframes.len()),
        built.slam.closures(),
        built.slam.length(),
        span,
        took,
        span / took.max(1e-9)
    )?;
    let cal = built.slam.calibration;
    writeln!(
        out,
        "  odometry's error as the matches found it: distances x{:.4}, turns x{:.4} (1: none)",
        cal.distance(),
        cal.turn()
    )?;
    if built.unplaced > 0 {
        writeln!(
            out,
            "  {} scans outside the odometry's time span were left out",
            built.unplaced
        )?;
    }
    Ok(())
}

fn write_trajectory(path: &std::path::Path, rec: &Recording, slam: &Slam) -> anyhow::Result<()> {
    let mut text = String::from("# time x y yaw: the corrected pose at each scan\n");
    for scan in &rec.scans {
        if let Some(odom) = rec.odom_at(scan.t) {
            let p: Pose = slam.corrected(scan.t, odom);
            text.push_str(&format!(
                "{:.3} {:.4} {:.4} {:.4}\n",
                scan.t, p.x, p.y, p.yaw
            ));
        }
    }
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}

fn show(a: &ShowArgs) -> anyhow::Result<()> {
    let map = troupe_mapfile::load_any(&a.map)?;
    let (w, h) = map.size();
    let cols = a
        .width
        .or_else(|| std::env::var("COLUMNS").ok()?.parse().ok())
        .unwrap_or(80)
        .max(10) as usize;
    // Two rows of cells per character (upper and lower half blocks).
    let step = (w as f64 / cols as f64).max(1.0);
    let rows = (h as f64 / step / 2.0).ceil() as usize;
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "{}: {} x {} cells of {} m, lower-left corner at ({:.2}, {:.2})",
        a.map.display(),
        w,
        h,
        map.info.resolution,
        map.info.origin.x,
        map.info.origin.y
    )?;
    let at = |c: usize, r: usize| -> i8 {
        // Worst of the cells a character covers: occupied, then unknown, then free.
        let (i0, j0) = ((c as f64 * step) as usize, (r as f64 * step) as usize);
        let (i1, j1) = (
            (((c + 1) as f64 * step) as usize).min(w),
            (((r + 1) as f64 * step) as usize).min(h),
        );
        let mut v = troupe_geom::occmap::FREE;
        for j in j0..j1.max(j0 + 1).min(h) {
            for i in i0..i1.max(i0 + 1).min(w) {
                let c = map
                    .get(i as i64, j as i64)
                    .unwrap_or(troupe_geom::occmap::UNKNOWN);
                if c == troupe_geom::occmap::OCCUPIED {
                    return c;
                }
                if c == troupe_geom::occmap::UNKNOWN {
                    v = c;
                }
            }
        }
        v
    };
    let cols = (w as f64 / step).ceil() as usize;
    for r in (0..rows).rev() {
        let line: String = (0..cols)
            .map(|c| {
                let (top, bottom) = (at(c, 2 * r + 1), at(c, 2 * r));
                let occ = |v: i8| v == troupe_geom::occmap::OCCUPIED;
                let free = |v: i8| v == troupe_geom::occmap::FREE;
                match (occ(top), occ(bottom)) {
                    (true, true) => '█',
                    (true, false) => '▀',
                    (false, true) => '▄',
                    _ if free(top) && free(bottom) => ' ',
                    _ => '·',
                }
            })
            .collect();
        writeln!(out, "{}", line.trim_end())?;
    }
    Ok(())
}

#[cfg(test)]
mod tests;
