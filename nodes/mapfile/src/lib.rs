//! Player's `mapfile`: serves an occupancy map read from an image.
//!
//! ```text
//! driver ( name "mapfile" provides ["map:0"]
//!          filename "bitmaps/cave.png" resolution 0.032 negate 0 origin [-8 -8] )
//! ```
//!
//! | | |
//! |---|---|
//! | provides | one `map` |
//! | requires | nothing |
//! | options | `filename` (required; PNG, PGM/PPM/PBM, gzipped PNM, or a ROS map_server YAML naming one), `resolution` (m/cell, required for an image), `negate` (0), `origin` (centre of the map) |
//!
//! # Behavior
//!
//! - Each pixel's channels are averaged (alpha included, as gdk-pixbuf
//!   hands them to Player); `occ = (255 - avg) / 255`, or `avg / 255` with
//!   `negate`. `occ > 0.95` is occupied, `occ < 0.1` free, the rest unknown.
//! - The image's top row is the map's last row: row 0 is at the origin,
//!   the map's lower-left corner.
//! - Without `origin` the map is centred on (0, 0). Player reads only the
//!   origin's x and y; a third value is ignored, as there.
//! - `info` answers the size, resolution and origin; `data` answers any tile,
//!   cells off the map reading unknown (0), as Player's. A tile larger than
//!   the whole map is refused.
//! - A `filename` ending in `.yaml` or `.yml` is a ROS map_server map (as
//!   `troupe map build` writes it): its image, `resolution`, `origin`,
//!   `negate`, `occupied_thresh` and `free_thresh` are used; the cfg's own
//!   `resolution`, `negate` or `origin`, where given, win.
//! - `filename` is relative to the `.cfg`'s directory (Player's
//!   `ReadFilename`); a file that cannot be read or decoded stops the node
//!   before it provides anything, with the file and the reason.

pub mod filter;
pub mod yaml;

pub use filter::{MapCspace, MapScale};
pub use yaml::{load_any, save, MapYaml, SaveError};

use std::io::Read as _;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use troupe_geom::occmap::{OccMap, FREE, OCCUPIED, UNKNOWN};
use troupe_msgs::{map, Device, Interface, Pose2d};
use troupe_node::{Ctx, Driver, Event, NodeError, Request, Result, Section, Unit};

/// Options, by Player's names.
#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub struct Options {
    /// The image (required).
    pub filename: Option<PathBuf>,
    /// Metres per pixel (required, > 0).
    pub resolution: Option<f64>,
    /// Dark means free instead of occupied.
    pub negate: f64,
    /// World position of the map's lower-left corner; absent = centred.
    pub origin: Option<Vec<f64>>,
}

/// Why a map image could not be used.
#[derive(Debug, thiserror::Error)]
#[error("cannot load map {path}: {reason}")]
pub struct LoadError {
    /// The file.
    pub path: String,
    /// What went wrong.
    pub reason: String,
}

/// Reads an image into map cells with Player's thresholds; `origin` is the
/// lower-left corner (`None` = centred).
///
/// # Errors
///
/// The file cannot be read, ungzipped or decoded.
pub fn load(
    path: &Path,
    resolution: f64,
    negate: bool,
    origin: Option<(f64, f64)>,
) -> std::result::Result<OccMap, LoadError> {
    load_with(path, resolution, negate, origin, PLAYER_THRESHOLDS)
}

/// Player's thresholds: occupied above 0.95, free below 0.1.
pub const PLAYER_THRESHOLDS: (f64, f64) = (0.95, 0.1);

/// [`load`] with other thresholds: a cell whose occupancy (`(255 - avg) /
/// 255`, or `avg / 255` negated) is above `thresholds.0` is occupied, below
/// `thresholds.1` free, unknown between (ROS map_server's
/// `occupied_thresh` and `free_thresh`).
///
/// # Errors
///
/// The file cannot be read, ungzipped or decoded.
pub fn load_with(
    path: &Path,
    resolution: f64,
    negate: bool,
    origin: Option<(f64, f64)>,
    thresholds: (f64, f64),
) -> std::result::Result<OccMap, LoadError> {
    let err = |reason: String| LoadError {
        path: path.display().to_string(),
        reason,
    };
    let mut bytes = std::fs::read(path).map_err(|e| err(e.to_string()))?;
    if bytes.starts_with(&[0x1f, 0x8b]) {
        let mut out = Vec::new();
        flate2::read::MultiGzDecoder::new(bytes.as_slice())
            .read_to_end(&mut out)
            .map_err(|e| err(format!("gzip: {e}")))?;
        bytes = out;
    }
    let img = image::load_from_memory(&bytes).map_err(|e| err(e.to_string()))?;
    let (width, height) = (img.width(), img.height());
    // gdk-pixbuf gives Player RGB or RGBA bytes; average what it would see.
    let avg: Vec<f64> = if img.color().has_alpha() {
        img.to_rgba8()
            .pixels()
            .map(|p| p.0.iter().map(|&c| f64::from(c)).sum::<f64>() / 4.0)
            .collect()
    } else {
        img.to_rgb8()
            .pixels()
            .map(|p| p.0.iter().map(|&c| f64::from(c)).sum::<f64>() / 3.0)
            .collect()
    };
    let (ox, oy) = origin.unwrap_or((
        -(f64::from(width) / 2.0) * resolution,
        -(f64::from(height) / 2.0) * resolution,
    ));
    let info = map::Info {
        width,
        height,
        resolution: resolution as f32,
        origin: Pose2d::new(ox, oy, 0.0),
    };
    // Map row j is image row height - 1 - j: the image's top is the map's far edge.
    let w = width as usize;
    Ok(OccMap::from_fn(info, |i, j| {
        let a = avg[(height as usize - 1 - j) * w + i];
        let occ = if negate {
            a / 255.0
        } else {
            (255.0 - a) / 255.0
        };
        if occ > thresholds.0 {
            OCCUPIED
        } else if occ < thresholds.1 {
            FREE
        } else {
            UNKNOWN
        }
    }))
}

/// Answers a map device's requests from `map`: `GET_DATA` tiles (cells off
/// the map unknown, as Player's mapfile sends them), `GET_INFO` (drivers keep
/// it ready with `Ctx::answer_always`; this answers one that reached the
/// driver before), and a refusal naming anything else. Shared by every
/// driver that serves a grid.
///
/// # Errors
///
/// A `GET_DATA` whose body does not decode.
pub fn serve(map: &OccMap, device: &Device, r: Request) -> Result<()> {
    if r.is::<map::GetInfo>() {
        r.reply(&map.info);
    } else if r.is::<map::GetData>() {
        let q = r.decode::<map::GetData>()?;
        let cells = u64::from(q.width) * u64::from(q.height);
        let whole = u64::from(map.info.width) * u64::from(map.info.height);
        if cells > whole.max(1) {
            r.nack(format!(
                "tile of {}x{} cells is larger than the {}x{} map",
                q.width, q.height, map.info.width, map.info.height
            ));
            return Ok(());
        }
        let (tile, off) = map.tile(q.col, q.row, q.width, q.height);
        if off > 0 {
            tracing::warn!(
                "{off} requested cells of tile ({}, {}) {}x{} are off the map",
                q.col,
                q.row,
                q.width,
                q.height
            );
        }
        r.reply(&tile);
    } else {
        let why = format!("{device} does not handle request `{}`", r.name);
        r.nack(why);
    }
    Ok(())
}

/// The mapfile driver.
pub struct MapFile {
    device: Device,
    map: OccMap,
}

impl MapFile {
    /// The map being served.
    pub fn map(&self) -> &OccMap {
        &self.map
    }
}

impl Driver for MapFile {
    const NAME: &'static str = "mapfile";
    type Options = Options;
    const UNITS: &'static [(&'static str, Unit)] = &[
        ("filename", Unit::Path),
        ("resolution", Unit::Length),
        ("origin", Unit::Lengths),
    ];

    fn new(section: &Section, o: Options) -> Result<Self> {
        let bad = |why: &str| NodeError::config(Self::NAME, why);
        let device = section.provided_one(Interface::Map, None)?;
        let filename = o.filename.ok_or_else(|| {
            bad("must specify map filename (filename \"map.png\" or \"map.yaml\")")
        })?;
        if let Some(r) = o.resolution {
            if !(r > 0.0 && r.is_finite()) {
                return Err(bad(&format!("resolution must be positive, not {r}")));
            }
        }
        let origin = match o.origin.as_deref() {
            None => None,
            Some([x, y, ..]) => Some((*x, *y)),
            Some(other) => {
                return Err(bad(&format!(
                    "origin needs x and y (origin [-8 -8]), not {other:?}"
                )))
            }
        };
        let map = if yaml::is_yaml(&filename) {
            // ROS map_server's YAML names the image and says the rest; what
            // the cfg says as well is taken over it, as Player's options.
            let y = MapYaml::read(&filename).map_err(|e| bad(&e.to_string()))?;
            let resolution = o.resolution.unwrap_or(y.resolution);
            let negate = if o.negate != 0.0 { true } else { y.negate };
            let origin = origin.or(Some((y.origin.0, y.origin.1)));
            load_with(&y.image, resolution, negate, origin, y.thresholds())
                .map_err(|e| bad(&e.to_string()))?
        } else {
            let resolution = o.resolution.ok_or_else(|| {
                bad("must specify the map resolution (resolution 0.05), or give a map_server YAML as filename")
            })?;
            load(&filename, resolution, o.negate != 0.0, origin).map_err(|e| bad(&e.to_string()))?
        };
        let resolution = map.resolution();
        tracing::info!(
            "read a {} x {} map at {resolution:.3} m/pix from {}",
            map.info.width,
            map.info.height,
            filename.display()
        );
        Ok(MapFile { device, map })
    }

    fn setup(&mut self, ctx: &mut Ctx) -> Result<()> {
        // Clients ask for the info first and often: answered without a wake.
        ctx.answer_always::<map::GetInfo>(&self.device, &self.map.info)
    }

    fn on_event(&mut self, _ctx: &mut Ctx, event: Event) -> Result<()> {
        match event {
            Event::Request(r) => serve(&self.map, &self.device, r),
            Event::Command(c) => {
                tracing::debug!("map takes no commands; ignored `{}`", c.key);
                Ok(())
            }
            Event::Data(_) | Event::Reply(_) | Event::Tick | Event::Wake => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use troupe_node::testing::{compat, Harness};

    const MAP: Device = Device::new(6665, Interface::Map, 0);

    fn write_pgm(dir: &Path, name: &str, w: u32, h: u32, px: &[u8]) -> PathBuf {
        let mut bytes = format!("P5\n{w} {h}\n255\n").into_bytes();
        bytes.extend_from_slice(px);
        let p = dir.join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    }

    fn tmpdir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("troupe-mapfile-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn thresholds_flip_and_origin_follow_player() {
        let d = tmpdir("thresholds");
        // Top row: black, white, mid-grey; bottom row: 12 (occ 0.953), 230 (occ 0.098), 13.
        let p = write_pgm(&d, "m.pgm", 3, 2, &[0, 255, 128, 12, 230, 13]);
        let m = load(&p, 0.5, false, None).unwrap();
        assert_eq!(m.info.origin, Pose2d::new(-0.75, -0.5, 0.0));
        // Row 0 is the image's bottom row.
        assert_eq!(
            m.cells,
            vec![OCCUPIED, FREE, UNKNOWN, OCCUPIED, FREE, UNKNOWN]
        );
        let n = load(&p, 0.5, true, Some((1.0, 2.0))).unwrap();
        // Negated: 230 is only 0.90 occupied, 12 and 13 are free.
        assert_eq!(n.cells, vec![FREE, UNKNOWN, FREE, FREE, OCCUPIED, UNKNOWN]);
        assert_eq!(n.info.origin, Pose2d::new(1.0, 2.0, 0.0));
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn gzipped_pnm_loads_and_bad_files_are_named() {
        use std::io::Write as _;
        let d = tmpdir("gz");
        let plain = write_pgm(&d, "m.pgm", 2, 1, &[0, 255]);
        let gz = d.join("m.pnm.gz");
        let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        enc.write_all(&std::fs::read(&plain).unwrap()).unwrap();
        std::fs::write(&gz, enc.finish().unwrap()).unwrap();
        assert_eq!(
            load(&gz, 1.0, false, None).unwrap().cells,
            vec![OCCUPIED, FREE]
        );

        let junk = d.join("junk.png");
        std::fs::write(&junk, b"not a picture").unwrap();
        let e = load(&junk, 1.0, false, None).unwrap_err().to_string();
        assert!(e.contains("junk.png"), "{e}");
        let e = load(&d.join("absent.png"), 1.0, false, None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("absent.png"), "{e}");
    }

    #[test]
    fn options_are_checked_with_reasons() {
        let d = tmpdir("options");
        let p = write_pgm(&d, "m.pgm", 1, 1, &[0]);
        let h = |opts: &str| {
            Harness::<MapFile>::from_json(&format!(
                r#"{{"name":"mapfile","provides":["map:0"],"options":{{{opts}}}}}"#
            ))
        };
        let file = format!(r#""filename":"{}""#, p.display());
        let e = h(r#""resolution":0.1"#).err().unwrap().to_string();
        assert!(e.contains("filename"), "{e}");
        let e = h(&file).err().unwrap().to_string();
        assert!(e.contains("resolution"), "{e}");
        let e = h(&format!(r#"{file},"resolution":-1"#))
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("positive"), "{e}");
        let e = h(&format!(r#"{file},"resolution":1,"origin":[1]"#))
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("origin"), "{e}");
        assert!(h(&format!(r#"{file},"resolution":1,"origin":[1,2,45]"#)).is_ok());
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn a_map_server_yaml_is_served_with_its_own_resolution_origin_and_thresholds() {
        let d = tmpdir("yaml");
        // map_server's trinary values: occupied 0, free 254, unknown 205.
        write_pgm(&d, "built.pgm", 3, 1, &[0, 254, 205]);
        std::fs::write(
            d.join("built.yaml"),
            "image: built.pgm\nresolution: 0.05\norigin: [-1.5, 2.0, 0.0]\nnegate: 0\n\
             occupied_thresh: 0.65\nfree_thresh: 0.196\n",
        )
        .unwrap();
        let h = |opts: &str| {
            Harness::<MapFile>::from_json(&format!(
                r#"{{"name":"mapfile","provides":["map:0"],"options":{{"filename":"{}"{opts}}}}}"#,
                d.join("built.yaml").display()
            ))
        };
        let mut served = h("").unwrap();
        let p = served.request(MAP, &map::GetInfo).unwrap();
        let info: map::Info = served.reply(p).unwrap().unwrap();
        assert_eq!((info.width, info.height, info.resolution), (3, 1, 0.05));
        assert_eq!(info.origin, Pose2d::new(-1.5, 2.0, 0.0));
        assert_eq!(served.driver().map().cells, vec![OCCUPIED, FREE, UNKNOWN]);
        // What the cfg says wins, as Player's options do.
        let over = h(r#","resolution":0.1,"origin":[0,0]"#).unwrap();
        assert_eq!(over.driver().map().info.origin, Pose2d::new(0.0, 0.0, 0.0));
        assert_eq!(over.driver().map().info.resolution, 0.1);
        // A broken YAML names its line.
        std::fs::write(d.join("built.yaml"), "image: built.pgm\nresolution: x\n").unwrap();
        let e = h("").err().unwrap().to_string();
        assert!(
            e.contains("built.yaml:2: resolution `x` is not a number"),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn serves_info_and_tiles_of_cave() {
        let Some(cave) = compat("stage/bitmaps/cave.png") else {
            return;
        };
        let mut h = Harness::<MapFile>::from_json(&format!(
            r#"{{"name":"mapfile","provides":["map:0"],
                "options":{{"filename":"{}","resolution":0.032,"origin":[-8,-8]}}}}"#,
            cave.display()
        ))
        .unwrap();
        let p = h.request(MAP, &map::GetInfo).unwrap();
        let info: map::Info = h.reply(p).unwrap().unwrap();
        assert_eq!((info.width, info.height), (500, 500));
        assert_eq!(info.origin, Pose2d::new(-8.0, -8.0, 0.0));
        let m = h.driver().map();
        let free = m.cells.iter().filter(|&&c| c == FREE).count();
        let occ = m.cells.iter().filter(|&&c| c == OCCUPIED).count();
        assert_eq!(free + occ, 250_000, "cave is black and white");
        assert!(free > 200_000 && occ > 5_000, "free {free}, occupied {occ}");

        let p = h
            .request(
                MAP,
                &map::GetData {
                    col: 490,
                    row: 0,
                    width: 20,
                    height: 2,
                },
            )
            .unwrap();
        let tile: map::Data = h.reply(p).unwrap().unwrap();
        assert_eq!(tile.cells.len(), 40);
        assert_eq!(&tile.cells[10..20], &[UNKNOWN; 10], "off the map");
        let p = h
            .request(
                MAP,
                &map::GetData {
                    col: 0,
                    row: 0,
                    width: 1000,
                    height: 1000,
                },
            )
            .unwrap();
        let e = h.reply::<map::Data>(p).unwrap().unwrap_err();
        assert!(e.contains("larger than"), "{e}");
        let p = h.request(MAP, &map::GetVector).unwrap();
        assert!(h.reply::<map::Vector>(p).unwrap().is_err());
    }
}
