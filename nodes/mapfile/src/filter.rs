//! Player's map filters: `mapscale` (the map at another resolution) and
//! `mapcspace` (obstacles grown by the robot's radius). Each reads the whole
//! map of the `map` device it requires, once, and serves the result.
//!
//! ```text
//! driver ( name "mapscale" requires ["map:0"] provides ["map:1"] resolution 0.5 )
//! driver ( name "mapcspace" requires ["map:1"] provides ["map:2"] robot_radius 0.25 )
//! ```
//!
//! | | |
//! |---|---|
//! | provides | one `map` |
//! | requires | one `map` |
//! | options | mapscale: `resolution` (m/cell, required); mapcspace: `robot_radius` (m, required), `robot_shape` (`"circle"`, the only one) |
//!
//! # Behavior
//!
//! - At setup the source's `info` is asked, then its whole grid. Requests
//!   that come before the result is ready wait for it (a client starting
//!   with the filter is answered, not refused); a source that refuses or
//!   answers garbage stops the filter, naming it.
//! - `mapscale` draws the map as Player does, free 255, unknown 127,
//!   occupied 0, resizes the picture to `rint(size * old / new)` cells
//!   (gdk-pixbuf's `GDK_INTERP_HYPER` there; here each new cell averages
//!   the old cells it covers, weighted by the area covered, which is what
//!   that filter does when shrinking), and reads it back: above 0.66 × 255
//!   free, below 0.33 × 255 occupied, unknown between. The origin stays.
//! - `mapcspace` grows every occupied and unknown cell to the cells within
//!   `rint(robot_radius / resolution)` (distance rounded as Player rounds
//!   it), never turning occupied into unknown.

use serde::Deserialize;
use troupe_geom::occmap::{OccMap, FREE, OCCUPIED, UNKNOWN};
use troupe_msgs::{map, Device, Interface};
use troupe_node::{Ctx, Driver, Event, MapFetch, NodeError, Request, Result, Section, Unit};

/// One map filter's transform.
pub trait Transform: Sized + Send + 'static {
    /// The driver's name.
    const NAME: &'static str;
    /// Its options' units.
    const UNITS: &'static [(&'static str, Unit)];
    /// Its options, by Player's names.
    type Options: serde::de::DeserializeOwned + Default + std::fmt::Debug;
    /// Checks the options.
    ///
    /// # Errors
    ///
    /// An option missing or out of range, with Player's reason.
    fn new(o: Self::Options) -> Result<Self>;
    /// The map served, from the source's.
    fn apply(&self, source: &OccMap) -> OccMap;
}

/// A map filter driver: fetches the source, applies `T`, serves the result.
pub struct MapFilter<T> {
    transform: T,
    input: Device,
    output: Device,
    state: State,
    /// Requests that came before the result was ready.
    waiting: Vec<Request>,
}

enum State {
    /// Before setup.
    Idle,
    Fetching(MapFetch),
    Ready(OccMap),
}

/// `mapscale`.
pub type MapScale = MapFilter<Scale>;
/// `mapcspace`.
pub type MapCspace = MapFilter<Cspace>;

impl<T: Transform> Driver for MapFilter<T> {
    const NAME: &'static str = T::NAME;
    type Options = T::Options;
    const UNITS: &'static [(&'static str, Unit)] = T::UNITS;

    fn new(section: &Section, o: T::Options) -> Result<Self> {
        Ok(MapFilter {
            transform: T::new(o)?,
            input: section.required_one(Interface::Map, None)?,
            output: section.provided_one(Interface::Map, None)?,
            state: State::Idle,
            waiting: Vec::new(),
        })
    }

    fn setup(&mut self, ctx: &mut Ctx) -> Result<()> {
        self.state = State::Fetching(MapFetch::start(ctx, self.input)?);
        Ok(())
    }

    fn on_event(&mut self, ctx: &mut Ctx, event: Event) -> Result<()> {
        match event {
            Event::Request(r) => match &self.state {
                State::Ready(m) => crate::serve(m, &self.output, r),
                _ => {
                    self.waiting.push(r);
                    Ok(())
                }
            },
            Event::Reply(r) => self.on_reply(ctx, r),
            Event::Command(c) => {
                tracing::debug!("map takes no commands; ignored `{}`", c.key);
                Ok(())
            }
            Event::Data(_) | Event::Tick | Event::Wake => Ok(()),
        }
    }
}

impl<T: Transform> MapFilter<T> {
    fn on_reply(&mut self, ctx: &mut Ctx, r: troupe_node::Reply) -> Result<()> {
        let State::Fetching(fetch) = &mut self.state else {
            return Ok(());
        };
        let Some((info, cells)) = fetch.on_reply(ctx, &r, T::NAME)? else {
            return Ok(());
        };
        let source = OccMap::from_tile(info, &cells)
            .map_err(|e| NodeError::config(T::NAME, e.to_string()))?;
        let out = self.transform.apply(&source);
        tracing::info!(
            "{}: {} x {} map at {:.3} m/cell from {}'s {} x {} at {:.3}",
            self.output,
            out.info.width,
            out.info.height,
            out.info.resolution,
            self.input,
            info.width,
            info.height,
            info.resolution
        );
        ctx.answer_always::<map::GetInfo>(&self.output, &out.info)?;
        for q in std::mem::take(&mut self.waiting) {
            crate::serve(&out, &self.output, q)?;
        }
        self.state = State::Ready(out);
        Ok(())
    }
}

/// `mapscale`'s options.
#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub struct ScaleOptions {
    /// The new metres per cell (required, > 0).
    pub resolution: Option<f64>,
}

/// `mapscale`'s transform.
pub struct Scale {
    resolution: f64,
}

impl Transform for Scale {
    const NAME: &'static str = "mapscale";
    const UNITS: &'static [(&'static str, Unit)] = &[("resolution", Unit::Length)];
    type Options = ScaleOptions;

    fn new(o: ScaleOptions) -> Result<Self> {
        match o.resolution {
            Some(r) if r > 0.0 && r.is_finite() => Ok(Scale { resolution: r }),
            _ => Err(NodeError::config(
                Self::NAME,
                "must specify positive map resolution (resolution 0.5)",
            )),
        }
    }

    fn apply(&self, source: &OccMap) -> OccMap {
        scale(source, self.resolution)
    }
}

/// `source` at `resolution` metres per cell (see the module's docs).
pub fn scale(source: &OccMap, resolution: f64) -> OccMap {
    let (w, h) = source.size();
    let factor = f64::from(source.info.resolution) / resolution;
    // Player's rint: halves to even.
    let (nw, nh) = (
        (w as f64 * factor).round_ties_even().max(0.0) as usize,
        (h as f64 * factor).round_ties_even().max(0.0) as usize,
    );
    let grey = |c: i8| match c {
        FREE => 255.0,
        UNKNOWN => 127.0,
        _ => 0.0,
    };
    // The old cells' span [a, b) in old-cell units covered by new cell k
    // along an axis of `n` old and `m` new cells, with each one's weight.
    let spans = |n: usize, m: usize| -> Vec<Vec<(usize, f64)>> {
        let step = n as f64 / m as f64;
        (0..m)
            .map(|k| {
                let (a, b) = (k as f64 * step, (k + 1) as f64 * step);
                let first = a.floor() as usize;
                let last = (b.ceil() as usize).min(n);
                (first..last)
                    .map(|i| (i, (b.min(i as f64 + 1.0) - a.max(i as f64)).max(0.0)))
                    .filter(|&(_, wt)| wt > 0.0)
                    .collect()
            })
            .collect()
    };
    let (xs, ys) = (spans(w, nw), spans(h, nh));
    let info = map::Info {
        width: nw as u32,
        height: nh as u32,
        resolution: resolution as f32,
        origin: source.info.origin,
    };
    OccMap::from_fn(info, |i, j| {
        let (mut sum, mut area) = (0.0, 0.0);
        for &(y, wy) in &ys[j] {
            for &(x, wx) in &xs[i] {
                sum += grey(source.cells[y * w + x]) * wx * wy;
                area += wx * wy;
            }
        }
        let v = if area > 0.0 { sum / area } else { 127.0 };
        if v > 0.66 * 255.0 {
            FREE
        } else if v < 0.33 * 255.0 {
            OCCUPIED
        } else {
            UNKNOWN
        }
    })
}

/// `mapcspace`'s options.
#[derive(Debug, Default, Deserialize)]
#[serde(default)]
pub struct CspaceOptions {
    /// The robot's radius (required, ≥ 0).
    pub robot_radius: Option<f64>,
    /// The robot's shape: `"circle"` (required by Player).
    pub robot_shape: Option<String>,
}

/// `mapcspace`'s transform.
pub struct Cspace {
    radius: f64,
}

impl Transform for Cspace {
    const NAME: &'static str = "mapcspace";
    const UNITS: &'static [(&'static str, Unit)] = &[("robot_radius", Unit::Length)];
    type Options = CspaceOptions;

    fn new(o: CspaceOptions) -> Result<Self> {
        let bad = |why: String| NodeError::config(Self::NAME, why);
        let radius = match o.robot_radius {
            Some(r) if r >= 0.0 && r.is_finite() => r,
            _ => {
                return Err(bad(
                    "must specify positive robot radius (robot_radius 0.25)".into(),
                ))
            }
        };
        match o.robot_shape.as_deref() {
            Some("circle") => Ok(Cspace { radius }),
            None => Err(bad(
                "must specify robot shape (robot_shape \"circle\")".into()
            )),
            Some(other) => Err(bad(format!(
                "unknown robot shape \"{other}\" (\"circle\" is the only one)"
            ))),
        }
    }

    fn apply(&self, source: &OccMap) -> OccMap {
        cspace(source, self.radius)
    }
}

/// `source` with its occupied and unknown cells grown by `radius` metres
/// (see the module's docs).
pub fn cspace(source: &OccMap, radius: f64) -> OccMap {
    let (w, h) = source.size();
    let r = (radius / source.resolution()).round_ties_even() as i64;
    // The disc's offsets, as Player tests them: rint(√(di² + dj²)) ≤ r.
    let disc: Vec<(i64, i64)> = (-r..=r)
        .flat_map(|dj| (-r..=r).map(move |di| (di, dj)))
        .filter(|&(di, dj)| (((di * di + dj * dj) as f64).sqrt().round_ties_even() as i64) <= r)
        .collect();
    let mut out = source.clone();
    for j in 0..h {
        for i in 0..w {
            let state = source.cells[j * w + i];
            if state < UNKNOWN {
                continue;
            }
            for &(di, dj) in &disc {
                let (x, y) = (i as i64 + di, j as i64 + dj);
                if x < 0 || y < 0 || x >= w as i64 || y >= h as i64 {
                    continue;
                }
                let c = &mut out.cells[y as usize * w + x as usize];
                if *c < state {
                    *c = state;
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use troupe_msgs::Pose2d;
    use troupe_node::testing::Harness;

    /// A map from rows written top row first: `#` occupied, `.` free, `?` unknown.
    fn map(res: f32, rows: &[&str]) -> OccMap {
        let h = rows.len();
        let w = rows[0].len();
        let info = map::Info {
            width: w as u32,
            height: h as u32,
            resolution: res,
            origin: Pose2d::new(-1.0, -2.0, 0.0),
        };
        OccMap::from_fn(info, |i, j| match rows[h - 1 - j].as_bytes()[i] {
            b'#' => OCCUPIED,
            b'.' => FREE,
            _ => UNKNOWN,
        })
    }

    fn rows(m: &OccMap) -> Vec<String> {
        let (w, h) = m.size();
        (0..h)
            .rev()
            .map(|j| {
                (0..w)
                    .map(|i| match m.cells[j * w + i] {
                        OCCUPIED => '#',
                        FREE => '.',
                        _ => '?',
                    })
                    .collect()
            })
            .collect()
    }

    #[test]
    fn mapscale_averages_the_cells_each_new_cell_covers() {
        // 2 x 2 blocks: all occupied (0) → occupied; half and half (127.5)
        // → unknown; three free and one occupied (191) → free; three
        // unknown and one free (159) → unknown.
        let m = map(0.1, &["##.#", "##..", "#???", ".??."]);
        let s = scale(&m, 0.2);
        assert_eq!(
            (s.info.width, s.info.height, s.info.resolution),
            (2, 2, 0.2)
        );
        assert_eq!(s.info.origin, m.info.origin);
        assert_eq!(rows(&s), ["#.", "??"]);
        // 3 cells to 2: rint(3 × 0.1 / 0.15) = 2; each new cell covers one
        // and a half old ones.
        let m = map(0.1, &["#..", "#..", "..."]);
        let s = scale(&m, 0.15);
        assert_eq!((s.info.width, s.info.height), (2, 2));
        // Top left: 1 + 0.5 + 0.5 + 0.25 of (occ, occ, free, free) cells…
        // (0·1 + 0·0.5 + 255·0.5 + 255·0.25) / 2.25 = 85 → unknown.
        assert_eq!(rows(&s), ["?.", ".."]);
    }

    #[test]
    fn mapcspace_grows_occupied_and_unknown_cells_by_the_radius() {
        let m = map(
            0.1,
            &[
                ".......", ".......", ".......", "...#...", ".......", "?......", ".......",
            ],
        );
        // 0.2 m = 2 cells; (2, 1) is in the disc (rint(√5) = 2), (2, 2) is
        // not (rint(√8) = 3). Where the grown cells meet, occupied wins.
        let c = cspace(&m, 0.2);
        assert_eq!(
            rows(&c),
            [".......", "..###..", ".#####.", "?#####.", "?#####.", "??###..", "???...."]
        );
        // Occupied grows over unknown, never unknown over occupied; a
        // radius under half a cell grows nothing.
        let m = map(0.1, &["#?", ".."]);
        assert_eq!(rows(&cspace(&m, 0.1)), ["##", "##"]);
        assert_eq!(rows(&cspace(&m, 0.04)), ["#?", ".."]);
    }

    #[test]
    fn options_are_checked_with_player_s_reasons() {
        let e = |json: &str| {
            Harness::<MapCspace>::from_json(json)
                .err()
                .unwrap()
                .to_string()
        };
        let base = r#""name":"mapcspace","requires":["map:0"],"provides":["map:1"]"#;
        assert!(e(&format!("{{{base}}}")).contains("must specify positive robot radius"));
        assert!(
            e(&format!(r#"{{{base},"options":{{"robot_radius":0.2}}}}"#))
                .contains("must specify robot shape")
        );
        assert!(e(&format!(
            r#"{{{base},"options":{{"robot_radius":0.2,"robot_shape":"square"}}}}"#
        ))
        .contains("unknown robot shape \"square\""));
        let e = Harness::<MapScale>::from_json(
            r#"{"name":"mapscale","requires":["map:0"],"provides":["map:1"],"options":{"resolution":-1}}"#,
        )
        .err()
        .unwrap()
        .to_string();
        assert!(e.contains("must specify positive map resolution"), "{e}");
    }

    #[test]
    fn a_filter_fetches_the_source_then_answers_what_waited() {
        let mut h = Harness::<MapCspace>::from_json(
            r#"{"name":"mapcspace","requires":["map:0"],"provides":["map:1"],"options":{"robot_radius":0.1,"robot_shape":"circle"}}"#,
        )
        .unwrap();
        let (src, out) = (
            Device::new(6665, Interface::Map, 0),
            Device::new(6665, Interface::Map, 1),
        );
        let m = map(0.1, &["...", ".#.", "..."]);
        // A client asks before the source has answered: it waits.
        let early = h
            .request(
                out,
                &map::GetData {
                    col: 0,
                    row: 0,
                    width: 3,
                    height: 3,
                },
            )
            .unwrap();
        assert!(h.reply::<map::Data>(early).is_none(), "it waits");
        let asked = h.requests_sent();
        assert!(asked[0].is::<map::GetInfo>() && asked[0].device == src);
        h.answer(asked[0].id, &m.info).unwrap();
        let asked = h.requests_sent();
        let q = asked.last().unwrap();
        assert!(q.is::<map::GetData>());
        h.answer(q.id, &m.tile(0, 0, 3, 3).0).unwrap();
        let got = h.reply::<map::Data>(early).unwrap().unwrap();
        // One cell: the diagonal neighbours too (rint(√2) = 1).
        assert_eq!(got.cells, vec![OCCUPIED; 9]);
        let info = h.request(out, &map::GetInfo).unwrap();
        let info = h.reply::<map::Info>(info).unwrap().unwrap();
        assert_eq!((info.width, info.height), (3, 3));
    }
}
