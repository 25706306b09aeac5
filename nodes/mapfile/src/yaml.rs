//! ROS map_server's map files: a YAML of flat `key: value` lines beside the
//! image it names.
//!
//! ```text
//! image: cave.png
//! resolution: 0.05
//! origin: [-8.0, -8.0, 0.0]
//! negate: 0
//! occupied_thresh: 0.65
//! free_thresh: 0.196
//! ```
//!
//! The format uses one line per key and no nesting, so it is read here
//! line by line, each error naming its line: serde_yaml, the YAML crate
//! serde's authors kept, is archived, and a parser for all of YAML would
//! read these six lines no better.

use std::path::{Path, PathBuf};

use troupe_geom::occmap::{OccMap, FREE_THRESH, OCCUPIED_THRESH};

use crate::{load_with, LoadError};

/// A map_server map file.
#[derive(Debug, Clone, PartialEq)]
pub struct MapYaml {
    /// The image, resolved against the YAML's directory.
    pub image: PathBuf,
    /// Metres per pixel.
    pub resolution: f64,
    /// The pose of the image's lower-left pixel: x, y, yaw.
    pub origin: (f64, f64, f64),
    /// White is occupied.
    pub negate: bool,
    /// Above this occupancy a cell is occupied (0.65 by default).
    pub occupied_thresh: f64,
    /// Below this occupancy a cell is free (0.196 by default).
    pub free_thresh: f64,
}

/// Whether `path` names a map_server YAML (by its extension).
pub fn is_yaml(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("yaml") || e.eq_ignore_ascii_case("yml"))
}

impl MapYaml {
    /// Reads the map file at `path`.
    ///
    /// # Errors
    ///
    /// The file cannot be read, a line is not `key: value`, a value is not
    /// what its key needs, or `image` or `resolution` is missing.
    pub fn read(path: &Path) -> Result<MapYaml, LoadError> {
        let text = std::fs::read_to_string(path).map_err(|e| LoadError {
            path: path.display().to_string(),
            reason: e.to_string(),
        })?;
        Self::parse(&text, path)
    }

    /// Parses map file text; `path` names it in errors and resolves `image`.
    ///
    /// # Errors
    ///
    /// As [`MapYaml::read`].
    pub fn parse(text: &str, path: &Path) -> Result<MapYaml, LoadError> {
        let name = path.display().to_string();
        let fail = |line: usize, reason: String| LoadError {
            path: format!("{name}:{line}"),
            reason,
        };
        let (mut image, mut resolution, mut origin) = (None, None, (0.0, 0.0, 0.0));
        let (mut negate, mut occupied_thresh, mut free_thresh) =
            (false, OCCUPIED_THRESH, FREE_THRESH);
        for (n, raw) in text.lines().enumerate() {
            let line = raw.split('#').next().unwrap_or("").trim();
            if line.is_empty() || line == "---" {
                continue;
            }
            let Some((key, value)) = line.split_once(':') else {
                return Err(fail(n + 1, format!("`{line}` is not `key: value`")));
            };
            let (key, value) = (key.trim(), value.trim().trim_matches(['"', '\'']));
            let number = |v: &str| {
                v.trim()
                    .parse::<f64>()
                    .ok()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| fail(n + 1, format!("{key} `{v}` is not a number")))
            };
            match key {
                "image" => image = Some(value.to_owned()),
                "resolution" => {
                    let r = number(value)?;
                    if r <= 0.0 {
                        return Err(fail(n + 1, format!("resolution must be positive, not {r}")));
                    }
                    resolution = Some(r);
                }
                "origin" => {
                    let inner = value
                        .strip_prefix('[')
                        .and_then(|v| v.strip_suffix(']'))
                        .ok_or_else(|| {
                            fail(n + 1, format!("origin `{value}` is not [x, y, yaw]"))
                        })?;
                    let v = inner
                        .split(',')
                        .map(number)
                        .collect::<Result<Vec<f64>, _>>()?;
                    let [x, y, yaw] = v[..] else {
                        return Err(fail(
                            n + 1,
                            format!("origin has {} values; it takes [x, y, yaw]", v.len()),
                        ));
                    };
                    if yaw != 0.0 {
                        tracing::warn!(
                            "{name}:{}: origin's yaw {yaw} is not used (maps are not turned)",
                            n + 1
                        );
                    }
                    origin = (x, y, yaw);
                }
                "negate" => negate = number(value)? != 0.0,
                "occupied_thresh" => occupied_thresh = number(value)?,
                "free_thresh" => free_thresh = number(value)?,
                "mode" if value == "trinary" => {}
                "mode" => tracing::warn!(
                    "{name}:{}: mode `{value}` is read as trinary (occupied, free, unknown)",
                    n + 1
                ),
                other => tracing::warn!(
                    "{name}:{}: `{other}` is not a map_server key; ignored",
                    n + 1
                ),
            }
        }
        let image =
            image.ok_or_else(|| fail(0, "no `image:` line names the map's image".into()))?;
        let resolution = resolution
            .ok_or_else(|| fail(0, "no `resolution:` line gives metres per pixel".into()))?;
        if free_thresh >= occupied_thresh {
            return Err(fail(
                0,
                format!(
                    "free_thresh {free_thresh} must be below occupied_thresh {occupied_thresh}"
                ),
            ));
        }
        let dir = path.parent().unwrap_or(Path::new("."));
        Ok(MapYaml {
            image: dir.join(image),
            resolution,
            origin,
            negate,
            occupied_thresh,
            free_thresh,
        })
    }

    /// The thresholds as [`load_with`] takes them.
    pub fn thresholds(&self) -> (f64, f64) {
        (self.occupied_thresh, self.free_thresh)
    }

    /// The map this file describes.
    ///
    /// # Errors
    ///
    /// The image cannot be read or decoded.
    pub fn load(&self) -> Result<OccMap, LoadError> {
        load_with(
            &self.image,
            self.resolution,
            self.negate,
            Some((self.origin.0, self.origin.1)),
            self.thresholds(),
        )
    }
}

/// A map from a map_server YAML, or from an image alone (one metre a
/// pixel, centred on the origin, Player's thresholds).
///
/// # Errors
///
/// The file cannot be read or is neither.
pub fn load_any(path: &Path) -> Result<OccMap, LoadError> {
    if is_yaml(path) {
        MapYaml::read(path)?.load()
    } else {
        crate::load(path, 1.0, false, None)
    }
}

/// A map that could not be written.
#[derive(Debug, thiserror::Error)]
#[error("cannot write map {}: {reason}", path.display())]
pub struct SaveError {
    /// The file.
    pub path: PathBuf,
    /// What went wrong.
    pub reason: String,
}

/// Writes `map` as `yaml` and the PNG it names (same stem), in
/// map_server's trinary form: occupied black (0), free white (254),
/// unknown grey (205), the top row the map's highest, with map_server's
/// default thresholds (which the three greys fall well clear of); `by`
/// says on the YAML's first line what wrote it.
///
/// # Errors
///
/// A file cannot be written.
pub fn save(map: &OccMap, yaml: &Path, by: &str) -> Result<PathBuf, SaveError> {
    use std::fmt::Write as _;
    use troupe_geom::occmap::{FREE, OCCUPIED};
    let failed = |path: &Path, e: &dyn std::fmt::Display| SaveError {
        path: path.to_owned(),
        reason: e.to_string(),
    };
    let png = yaml.with_extension("png");
    let (w, h) = map.size();
    let image = image::GrayImage::from_fn(w as u32, h as u32, |x, y| {
        let j = h as i64 - 1 - i64::from(y);
        image::Luma([match map.get(i64::from(x), j) {
            Some(OCCUPIED) => 0,
            Some(FREE) => 254,
            _ => 205,
        }])
    });
    image
        .save_with_format(&png, image::ImageFormat::Png)
        .map_err(|e| failed(&png, &e))?;
    let name = png
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let o = map.origin();
    let mut text = format!("# Written by {by}: an occupancy map in ROS map_server's format.\n");
    let _ = writeln!(text, "image: {name}");
    // As the f32 it travels as: 0.05, not 0.05000000074505806.
    let _ = writeln!(text, "resolution: {}", map.info.resolution);
    let _ = writeln!(text, "origin: [{:.4}, {:.4}, 0.0]", o.x, o.y);
    let _ = writeln!(text, "negate: 0");
    let _ = writeln!(text, "occupied_thresh: {OCCUPIED_THRESH}");
    let _ = writeln!(text, "free_thresh: {FREE_THRESH}");
    std::fs::write(yaml, text).map_err(|e| failed(yaml, &e))?;
    Ok(png)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_saved_map_loads_as_it_was() {
        use troupe_geom::occmap::{FREE, OCCUPIED, UNKNOWN};
        let info = troupe_msgs::map::Info {
            width: 7,
            height: 4,
            resolution: 0.1,
            origin: troupe_msgs::Pose2d::new(-1.25, 2.5, 0.0),
        };
        let map = OccMap::from_fn(info, |i, j| match (i + 2 * j) % 3 {
            0 => OCCUPIED,
            1 => FREE,
            _ => UNKNOWN,
        });
        let dir = std::env::temp_dir().join(format!("troupe-mapfile-save-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let png = save(&map, &dir.join("m.yaml"), "a test").unwrap();
        assert_eq!(png, dir.join("m.png"));
        let back = load_any(&dir.join("m.yaml")).unwrap();
        assert_eq!(back.size(), map.size());
        assert_eq!(back.origin(), map.origin());
        for j in 0..4 {
            for i in 0..7 {
                assert_eq!(back.get(i, j), map.get(i, j), "cell ({i}, {j})");
            }
        }
        let err = save(&map, &dir.join("no/such/dir/m.yaml"), "a test").unwrap_err();
        assert!(err.to_string().starts_with("cannot write map "), "{err}");
    }

    #[test]
    fn a_map_server_file_reads_and_its_mistakes_name_their_line() {
        let p = Path::new("/maps/cave.yaml");
        let y = MapYaml::parse(
            "image: cave.png\nresolution: 0.05\norigin: [-8.0, -7.5, 0.0]\nnegate: 0\n\
             occupied_thresh: 0.65\nfree_thresh: 0.196  # ROS's default\n",
            p,
        )
        .unwrap();
        assert_eq!(y.image, Path::new("/maps/cave.png"));
        assert_eq!(y.origin, (-8.0, -7.5, 0.0));
        assert_eq!(y.thresholds(), (0.65, 0.196));
        let e = MapYaml::parse("image: a.png\nresolution: fine\n", p).unwrap_err();
        assert_eq!(
            e.to_string(),
            "cannot load map /maps/cave.yaml:2: resolution `fine` is not a number"
        );
        let e = MapYaml::parse("image: a.png\norigin: [1, 2]\nresolution: 1\n", p).unwrap_err();
        assert!(e.to_string().contains(":2: origin has 2 values"), "{e}");
        let e = MapYaml::parse("resolution: 1\n", p).unwrap_err();
        assert!(e.to_string().contains("no `image:` line"), "{e}");
        let e = MapYaml::parse("image a.png\n", p).unwrap_err();
        assert!(
            e.to_string()
                .contains(":1: `image a.png` is not `key: value`"),
            "{e}"
        );
    }
}
