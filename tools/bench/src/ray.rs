//! `troupe bench stage --parry`: the simulator's hand-written grid walk
//! against parry2d, on the same static walls and the same rays. The walls
//! are Stage's sample bitmaps as the bench worlds scale them (the cave at
//! 16 × 16 m, the hospital at 140 × 60 m), rasterised as Stage rasterises
//! them (dark pixels merged into rectangles). Troupe casts on its grid of
//! 2 cm cells, leaping open space by the clearance it keeps
//! (`Grid::cast_open`, what each sensor's ray does on the static world);
//! parry2d casts on a compound of the same rectangles, one cuboid each,
//! under its bounding-volume hierarchy.

use std::io::Write;
use std::time::Instant;

use parry2d::math::{Pose, Vector};
use parry2d::query::Ray;
use parry2d::shape::SharedShape;
use troupe_geom::bitmap::Bitmap;
use troupe_geom::{Grid, EMPTY};

/// Rays cast per world.
const RAYS: usize = 200_000;
/// A laser's reach (Stage's sicklaser: 8 m).
const REACH: f64 = 8.0;
/// The bench worlds' cell size.
const RES: f64 = 0.02;

/// SplitMix64: the same rays on every run.
struct Draws(u64);

impl Draws {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Prints, per world, what building each takes and the time per ray, and
/// how often the two agree (to two cells, or both seeing nothing).
pub fn run(bitmaps: &std::path::Path) -> anyhow::Result<()> {
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "troupe bench stage --parry: static walls, {RAYS} rays of {REACH} m from open cells, one thread"
    )?;
    writeln!(
        out,
        "  {:<10} {:>8}  {:>14} {:>12}  {:>14} {:>12}  {:>9}",
        "world", "rects", "grid build ms", "grid ns/ray", "parry build ms", "parry ns/ray", "agree"
    )?;
    for (name, file, (w, h)) in [
        ("cave", "cave.png", (16.0, 16.0)),
        ("hospital", "hospital_section.png", (140.0, 60.0)),
    ] {
        let path = bitmaps.join(file);
        let bmp = Bitmap::load(&path)?;
        let rects = bmp.dark_rects(128);
        let (sx, sy) = (w / f64::from(bmp.width), h / f64::from(bmp.height));
        // Each rectangle in metres: (x0, y0, x1, y1), the world centred.
        let boxes: Vec<[f64; 4]> = rects
            .iter()
            .map(|r| {
                let x0 = -w / 2.0 + f64::from(r.x) * sx;
                let y1 = h / 2.0 - f64::from(r.y) * sy;
                [x0, y1 - f64::from(r.h) * sy, x0 + f64::from(r.w) * sx, y1]
            })
            .collect();

        let t = Instant::now();
        let mut grid = Grid::new(-w / 2.0, -h / 2.0, w / 2.0, h / 2.0, RES);
        for b in &boxes {
            grid.fill_polygon(&[(b[0], b[1]), (b[2], b[1]), (b[2], b[3]), (b[0], b[3])], 1);
        }
        grid.keep_clearance();
        let grid_build = t.elapsed().as_secs_f64() * 1e3;

        let t = Instant::now();
        let parts: Vec<(Pose, SharedShape)> = boxes
            .iter()
            .map(|b| {
                let centre =
                    Vector::new(((b[0] + b[2]) / 2.0) as f32, ((b[1] + b[3]) / 2.0) as f32);
                let half = (((b[2] - b[0]) / 2.0) as f32, ((b[3] - b[1]) / 2.0) as f32);
                (
                    Pose::from_translation(centre),
                    SharedShape::cuboid(half.0, half.1),
                )
            })
            .collect();
        let walls = SharedShape::compound(parts);
        let parry_build = t.elapsed().as_secs_f64() * 1e3;

        // Rays from open cells, every way.
        let mut draws = Draws(0x5eed);
        let mut rays = Vec::with_capacity(RAYS);
        while rays.len() < RAYS {
            let (x, y) = ((draws.next() - 0.5) * w, (draws.next() - 0.5) * h);
            let a = draws.next() * std::f64::consts::TAU;
            if grid.at(x, y) == EMPTY {
                rays.push((x, y, a.cos(), a.sin()));
            }
        }

        let t = Instant::now();
        let by_grid: Vec<f64> = rays
            .iter()
            .map(|&(x, y, dx, dy)| {
                grid.cast_open(x, y, (dx, dy), (0.0, REACH), |id| id != EMPTY)
                    .map_or(REACH, |hit| hit.range)
            })
            .collect();
        let grid_ns = t.elapsed().as_secs_f64() * 1e9 / RAYS as f64;

        let t = Instant::now();
        let by_parry: Vec<f64> = rays
            .iter()
            .map(|&(x, y, dx, dy)| {
                let ray = Ray::new(
                    Vector::new(x as f32, y as f32),
                    Vector::new(dx as f32, dy as f32),
                );
                walls
                    .cast_ray(&Pose::IDENTITY, &ray, REACH as f32, true)
                    .map_or(REACH, f64::from)
            })
            .collect();
        let parry_ns = t.elapsed().as_secs_f64() * 1e9 / RAYS as f64;

        let agree = by_grid
            .iter()
            .zip(&by_parry)
            .filter(|(g, p)| (*g - *p).abs() <= 2.0 * RES)
            .count();
        writeln!(
            out,
            "  {name:<10} {:>8}  {grid_build:>14.1} {grid_ns:>12.0}  {parry_build:>14.1} {parry_ns:>12.0}  {:>8.2}%",
            rects.len(),
            100.0 * agree as f64 / RAYS as f64
        )?;
    }
    Ok(())
}
