//! Stage's own raster of bodies and its ray walk, so that ranges read as
//! Stage reads them.
//!
//! Stage does not measure a ray against the walls' geometry. It draws each
//! block's outline into square cells (vertices floored to whole cells,
//! edges as 4-connected lines), groups the cells in regions of 32 × 32,
//! and walks a ray as a staircase of whole-cell steps from its origin,
//! leaping over regions that hold nothing. A cell is looked up by
//! truncating toward zero, so cell 0 spans (−1, 1) and every cell below
//! zero sits one cell lower than where it was drawn. The range it reports
//! is the staircase's progress along the ray's major axis divided by the
//! cosine (or sine) of the heading. Each of these moves a range by up to
//! a cell, and the division by the cosine stretches that on oblique rays:
//! against the exact geometry Stage's ranges differ by several
//! centimetres. [`Raster`] reproduces the cells, the walk and the formula
//! (Stage 4.3's `World::Raytrace` and `World::MapPoly`), so a simulated
//! scan matches Stage's to the float.
//!
//! Moving bodies are drawn into a layer of their own
//! ([`Raster::set_moving`]), as Stage redraws a model after it moves: a
//! ray meets them as Stage's does, and a region holding any body is walked
//! cell by cell where an empty one is leapt over (the two give different
//! staircases).

use crate::{Hit, EMPTY};

/// Bits of a region's side in cells (Stage's `RBITS`).
const RBITS: u32 = 5;
/// Cells per region side.
const RW: i32 = 1 << RBITS;
/// Cells per region.
const CELLS: usize = (RW * RW) as usize;

/// One region of 32 × 32 cells.
#[derive(Debug, Clone, Default)]
struct Region {
    /// Cells holding a static body's id.
    statics: u32,
    /// Ids by cell, row-major; allocated once a static body is drawn here.
    cells: Option<Box<[u16; CELLS]>>,
    /// Per cell, the Chebyshev distance in cells to the nearest static
    /// cell of this region (0 on one): a staircase that stays in the
    /// region passes that many cells less one without meeting any.
    clear: Option<Box<[u8; CELLS]>>,
    /// Cells changed since `clear` was worked out.
    stale: bool,
    /// Ids of the moving bodies drawn in each cell, as Stage draws them
    /// each step (see [`Raster::set_moving`]); allocated once one is
    /// drawn here.
    moving: Option<Box<[Moving; CELLS]>>,
    /// Ids held in `moving`.
    moving_ids: u32,
}

/// The moving bodies drawn in one cell: a robot's base and the laser on
/// top of it share most of their cells, and a ray at the laser's height
/// must still meet the laser there.
type Moving = [u16; MOVING_PER_CELL];
/// Moving bodies a cell keeps (a fourth replaces the last).
const MOVING_PER_CELL: usize = 3;

/// A region's cells where nothing static is drawn.
static NO_CELLS: [u16; CELLS] = [EMPTY; CELLS];

impl Region {
    /// Works out `clear` from the cells anew (two passes of a chamfer
    /// over 8 neighbours, which gives Chebyshev distances exactly).
    fn refresh(&mut self) {
        self.stale = false;
        let Some(cells) = &self.cells else {
            self.clear = None;
            return;
        };
        let clear = self.clear.get_or_insert_with(|| Box::new([0; CELLS]));
        let far = u8::MAX;
        for (c, &id) in clear.iter_mut().zip(cells.iter()) {
            *c = if id == EMPTY { far } else { 0 };
        }
        let at = |x: i32, y: i32| (y * RW + x) as usize;
        let ahead = [(-1, 0), (-1, -1), (0, -1), (1, -1)];
        for (order, dirs) in [(false, ahead), (true, ahead.map(|(dx, dy)| (-dx, -dy)))] {
            for k in 0..CELLS as i32 {
                let k = if order { CELLS as i32 - 1 - k } else { k };
                let (x, y) = (k % RW, k / RW);
                let mut best = clear[at(x, y)];
                for (dx, dy) in dirs {
                    let (u, v) = (x + dx, y + dy);
                    if (0..RW).contains(&u) && (0..RW).contains(&v) {
                        best = best.min(clear[at(u, v)].saturating_add(1));
                    }
                }
                clear[at(x, y)] = best;
            }
        }
    }
}

impl Region {
    fn empty(&self) -> bool {
        self.statics == 0 && self.moving_ids == 0
    }
}

/// Stage's cells over a rectangle of the world: static bodies drawn by id,
/// moving bodies in a layer of their own. Outside the rectangle every region is
/// empty.
#[derive(Debug, Clone)]
pub struct Raster {
    /// Cells per metre.
    ppm: f64,
    /// The first region's coordinates, and how many regions across and up.
    rx0: i32,
    ry0: i32,
    nx: i32,
    ny: i32,
    regions: Vec<Region>,
}

/// Calls `f(x, y)` for each cell (integer cell coordinates) Stage draws for
/// the closed polygon `pts` (world metres) at `ppm` cells per metre: each
/// vertex floored, each edge a 4-connected line from its first vertex up
/// to (not including) its second. A cell may be reported twice.
pub fn outline(ppm: f64, pts: &[(f64, f64)], mut f: impl FnMut(i32, i32)) {
    let cell = |p: &(f64, f64)| ((p.0 * ppm).floor() as i32, (p.1 * ppm).floor() as i32);
    for (k, a) in pts.iter().enumerate() {
        let (x0, y0) = cell(a);
        let (x1, y1) = cell(&pts[(k + 1) % pts.len()]);
        let (dx, dy) = (x1 - x0, y1 - y0);
        let (sx, sy) = (dx.signum(), dy.signum());
        let (ax, ay) = (dx.abs(), dy.abs());
        let (bx, by) = (2 * ax, 2 * ay);
        let mut exy = ay - ax;
        let (mut x, mut y) = (x0, y0);
        for _ in 0..ax + ay {
            f(x, y);
            if exy < 0 {
                x += sx;
                exy += by;
            } else {
                y += sy;
                exy -= bx;
            }
        }
    }
}

impl Raster {
    /// Regions covering `[x0, x1] × [y0, y1]` (metres) at `res` metres per
    /// cell (a non-positive or non-finite `res` is taken as 0.02).
    pub fn new(x0: f64, y0: f64, x1: f64, y1: f64, res: f64) -> Raster {
        let res = if res.is_finite() && res > 0.0 {
            res
        } else {
            0.02
        };
        let ppm = 1.0 / res;
        let reg = |v: f64| ((v * ppm).floor() as i32) >> RBITS;
        let (rx0, ry0) = (reg(x0.min(x1)), reg(y0.min(y1)));
        let (nx, ny) = (reg(x0.max(x1)) - rx0 + 1, reg(y0.max(y1)) - ry0 + 1);
        Raster {
            ppm,
            rx0,
            ry0,
            nx,
            ny,
            regions: vec![Region::default(); (nx as usize) * (ny as usize)],
        }
    }

    /// Cells per metre.
    pub fn ppm(&self) -> f64 {
        self.ppm
    }

    /// The index of the region holding cell (x, y), if it is covered.
    #[inline]
    pub fn region_of(&self, x: i32, y: i32) -> Option<usize> {
        let (rx, ry) = ((x >> RBITS) - self.rx0, (y >> RBITS) - self.ry0);
        ((0..self.nx).contains(&rx) && (0..self.ny).contains(&ry))
            .then(|| (ry * self.nx + rx) as usize)
    }

    /// Draws `id` into cell (x, y) (ignored outside the raster).
    pub fn set(&mut self, x: i32, y: i32, id: u16) {
        let Some(r) = self.region_of(x, y) else {
            return;
        };
        let reg = &mut self.regions[r];
        let cells = reg.cells.get_or_insert_with(|| Box::new([EMPTY; CELLS]));
        let c = &mut cells[((y & (RW - 1)) * RW + (x & (RW - 1))) as usize];
        match (*c == EMPTY, id == EMPTY) {
            (true, false) => reg.statics += 1,
            (false, true) => reg.statics -= 1,
            _ => {}
        }
        reg.stale |= (*c == EMPTY) != (id == EMPTY);
        *c = id;
    }

    /// The id drawn in cell (x, y); `EMPTY` outside the raster.
    pub fn get(&self, x: i32, y: i32) -> u16 {
        self.region_of(x, y)
            .and_then(|r| self.regions[r].cells.as_ref())
            .map_or(EMPTY, |c| {
                c[((y & (RW - 1)) * RW + (x & (RW - 1))) as usize]
            })
    }

    /// Brings the regions' clearance up to date with their cells: call
    /// after drawing, before casting (a stale region's rays walk cell by
    /// cell, which finds the same).
    pub fn refresh(&mut self) {
        for r in self.regions.iter_mut().filter(|r| r.stale) {
            r.refresh();
        }
    }

    /// Draws moving body `id` into cell (x, y) of the moving layer, as
    /// Stage draws a moving model's outline after each move (ignored
    /// outside the raster). Rays meet it there, as they meet static cells.
    pub fn set_moving(&mut self, x: i32, y: i32, id: u16) {
        let Some(r) = self.region_of(x, y) else {
            return;
        };
        let reg = &mut self.regions[r];
        let cells = reg
            .moving
            .get_or_insert_with(|| Box::new([[EMPTY; MOVING_PER_CELL]; CELLS]));
        let c = &mut cells[((y & (RW - 1)) * RW + (x & (RW - 1))) as usize];
        if id == EMPTY || c.contains(&id) {
            return;
        }
        match c.iter_mut().find(|k| **k == EMPTY) {
            Some(k) => {
                *k = id;
                reg.moving_ids += 1;
            }
            None => c[MOVING_PER_CELL - 1] = id,
        }
    }

    /// Takes moving body `id` out of cell (x, y).
    pub fn unset_moving(&mut self, x: i32, y: i32, id: u16) {
        let Some(r) = self.region_of(x, y) else {
            return;
        };
        let reg = &mut self.regions[r];
        let Some(cells) = reg.moving.as_mut() else {
            return;
        };
        let c = &mut cells[((y & (RW - 1)) * RW + (x & (RW - 1))) as usize];
        if let Some(k) = c.iter_mut().find(|k| **k == id) {
            *k = EMPTY;
            reg.moving_ids -= 1;
        }
    }

    /// Stage's ray: the first drawn cell whose id `accept`s along the ray
    /// from (x, y) (metres) along the unit vector `(cos, sin)` within
    /// `range` metres, and the range Stage reports for it.
    pub fn cast(
        &self,
        x: f64,
        y: f64,
        (cos, sin): (f64, f64),
        range: f64,
        mut accept: impl FnMut(u16) -> bool,
    ) -> Option<Hit> {
        let ppm = self.ppm;
        // Stage turns a heading of exactly 0 into 1e-12 rad; its sine and
        // cosine are never exactly 0 at other headings either.
        let (sina, cosa) = match (sin == 0.0, cos == 0.0) {
            (true, _) if cos > 0.0 => (1e-12, 1.0),
            (true, _) => (1.2246467991473532e-16, cos),
            (_, true) => (sin, 6.123233995736766e-17),
            _ => (sin, cos),
        };
        let tana = sina / cosa;
        let mut w = Walk::new((x * ppm, y * ppm), (ppm * range * cosa, ppm * range * sina));
        let (x0, y0) = (w.gx, w.gy);
        let reach = |w: &Walk| {
            if w.stairs.ax > w.stairs.ay {
                ((w.gx - x0) / cosa).abs() / ppm
            } else {
                ((w.gy - y0) / sina).abs() / ppm
            }
        };
        let rw = f64::from(RW);
        let (sx, sy) = (f64::from(w.sx), f64::from(w.sy));
        let (xjumpx, xjumpy) = (sx * rw, sx * rw * tana);
        let (yjumpx, yjumpy) = (sy * rw / tana, sy * rw);
        let xjumpdist = xjumpx.abs() + xjumpy.abs();
        let yjumpdist = yjumpx.abs() + yjumpy.abs();
        let (mut xcx, mut xcy, mut ycx, mut ycy) = (0.0, 0.0, 0.0, 0.0);
        let (mut dist_x, mut dist_y) = (0.0, 0.0);
        let mut crossings = true;
        while w.n > 0 {
            // (Truncation toward zero, as Stage converts to int32.)
            let (ix, iy) = (w.gx as i32, w.gy as i32);
            let reg = self
                .region_of(ix, iy)
                .map(|r| &self.regions[r])
                .filter(|r| !r.empty());
            if let Some(reg) = reg {
                crossings = true;
                let (cx0, cy0) = (ix & (RW - 1), iy & (RW - 1));
                (w.cx, w.cy) = (cx0, cy0);
                let moving = reg.moving.as_deref().filter(|_| reg.moving_ids > 0);
                let hit = match (&reg.cells, moving) {
                    // Only moving bodies here, not drawn: the staircase
                    // passes to the region's edge at once.
                    (None, None) => {
                        w.leap();
                        None
                    }
                    (cells, Some(moving)) => {
                        let cells = cells.as_deref().unwrap_or(&NO_CELLS);
                        w.through(cells, None, Some(moving), &mut accept)
                    }
                    (Some(cells), None) => {
                        let clear = reg.clear.as_deref().filter(|_| !reg.stale);
                        w.through(cells, clear, None, &mut accept)
                    }
                };
                // The staircase moved by whole cells.
                w.gx += f64::from(w.cx - cx0);
                w.gy += f64::from(w.cy - cy0);
                if let Some(id) = hit {
                    return Some(Hit {
                        range: reach(&w),
                        id,
                    });
                }
            } else {
                let (gx, gy) = (w.gx, w.gy);
                if crossings {
                    crossings = false;
                    // The lower-left corner of this region, in cells.
                    let mut regx = f64::from(ix / RW * RW);
                    let mut regy = f64::from(iy / RW * RW);
                    if gx < 0.0 && ix % RW != 0 {
                        regx -= rw;
                    }
                    if gy < 0.0 && iy % RW != 0 {
                        regy -= rw;
                    }
                    let xdx = if w.sx < 0 {
                        regx - gx - 1.0
                    } else {
                        regx + rw - gx
                    };
                    let xdy = xdx * tana;
                    let ydy = if w.sy < 0 {
                        regy - gy - 1.0
                    } else {
                        regy + rw - gy
                    };
                    let ydx = ydy / tana;
                    (xcx, xcy, ycx, ycy) = (gx + xdx, gy + xdy, gx + ydx, gy + ydy);
                    dist_x = xdx.abs() + xdy.abs();
                    dist_y = ydx.abs() + ydy.abs();
                }
                // (Stage's int32 `n -= dist`: a NaN ends the ray.)
                if dist_x < dist_y {
                    (w.gx, w.gy) = (xcx, xcy);
                    w.n = (f64::from(w.n) - dist_x) as i32;
                    xcx += xjumpx;
                    xcy += xjumpy;
                    dist_y -= dist_x;
                    dist_x = xjumpdist;
                } else {
                    (w.gx, w.gy) = (ycx, ycy);
                    w.n = (f64::from(w.n) - dist_y) as i32;
                    ycx += yjumpx;
                    ycy += yjumpy;
                    dist_x -= dist_y;
                    dist_y = yjumpdist;
                }
            }
        }
        None
    }
}

/// Where a ray's staircase stands: in cells (global, fractional as Stage
/// keeps them, as of its region's first cell), in its region, its error
/// term and the steps left.
struct Walk {
    gx: f64,
    gy: f64,
    cx: i32,
    cy: i32,
    exy: i32,
    n: i32,
    sx: i32,
    sy: i32,
    stairs: Stairs,
}

impl Walk {
    /// At `g` (cells), to go `d` cells along x and y.
    fn new(g: (f64, f64), d: (f64, f64)) -> Walk {
        // (As Stage's int32s: truncated.)
        let (ax, ay) = (d.0.abs() as i32, d.1.abs() as i32);
        Walk {
            gx: g.0,
            gy: g.1,
            cx: 0,
            cy: 0,
            exy: ay - ax,
            n: ax + ay,
            sx: d.0.signum() as i32,
            sy: d.1.signum() as i32,
            stairs: Stairs { ax, ay },
        }
    }

    /// Walks the staircase through a region holding static cells, from
    /// its cell (cx, cy), to the first cell whose id `accept`s (its id),
    /// or out of the region or to the ray's end (`None`). Where `clear`
    /// shows open cells around, it passes them in one go. Leaves `gx`,
    /// `gy` to the caller.
    fn through(
        &mut self,
        cells: &[u16; CELLS],
        clear: Option<&[u8; CELLS]>,
        moving: Option<&[Moving; CELLS]>,
        mut accept: impl FnMut(u16) -> bool,
    ) -> Option<u16> {
        let (mut cx, mut cy, mut exy, mut n) = (self.cx, self.cy, self.exy, self.n);
        let (sx, sy) = (self.sx, self.sy);
        let (bx, by) = (2 * self.stairs.ax, 2 * self.stairs.ay);
        let found = loop {
            if !((0..RW).contains(&cx) && (0..RW).contains(&cy)) || n <= 0 {
                break None;
            }
            let k = (cy * RW + cx) as usize;
            let open = match clear {
                Some(c) => c[k],
                None => u8::from(cells[k] == EMPTY),
            };
            if let Some(moving) = moving {
                // Static first, then moving, as the cell's blocks were
                // drawn; no leaps past open cells (`clear` knows statics only).
                let hit = std::iter::once(cells[k])
                    .chain(moving[k])
                    .find(|&id| id != EMPTY && accept(id));
                if hit.is_some() {
                    break hit;
                }
            } else if open == 0 {
                if accept(cells[k]) {
                    break Some(cells[k]);
                }
            } else if open > 2 {
                // Past the open cells around, staying in the region.
                let to_x = if sx > 0 { RW - 1 - cx } else { cx };
                let to_y = if sy > 0 { RW - 1 - cy } else { cy };
                let s = i32::from(open - 1).min(to_x).min(to_y).min(n);
                if s > 1 {
                    let i = self.stairs.xs(exy, s);
                    cx += sx * i;
                    cy += sy * (s - i);
                    exy = self.stairs.after(exy, s, i);
                    n -= s;
                    continue;
                }
            }
            if exy < 0 {
                cx += sx;
                exy += by;
            } else {
                cy += sy;
                exy -= bx;
            }
            n -= 1;
        };
        (self.cx, self.cy, self.exy, self.n) = (cx, cy, exy, n);
        found
    }

    /// The steps out of the region, from its cell (cx, cy), in one go, or
    /// to the ray's end.
    #[inline]
    fn leap(&mut self) {
        let (cx, cy) = (self.cx, self.cy);
        let kx = if self.sx > 0 { RW - cx } else { cx + 1 };
        let ky = if self.sy > 0 { RW - cy } else { cy + 1 };
        let (s, i) = self.stairs.leave(self.exy, kx, ky, self.n);
        self.cx += self.sx * i;
        self.cy += self.sy * (s - i);
        self.exy = self.stairs.after(self.exy, s, i);
        self.n -= s;
    }
}

/// Stage's staircase (a 4-connected line of `ax` steps along x and `ay`
/// along y, stepping x while its error term `exy` is negative), advanced
/// many steps at once.
///
/// The error term starts at `ay − ax` and each step keeps it in
/// [−2ax, 2ay): an x step adds 2ay to it, a y step takes 2ax. So after `s`
/// steps of which `i` along x it is `exy − 2ax·s + 2(ax + ay)·i`, and only
/// one `i` puts that in the range: the staircase's course is known in
/// closed form.
#[derive(Debug, Clone, Copy)]
struct Stairs {
    ax: i32,
    ay: i32,
}

impl Stairs {
    /// How many of the next `s` steps go along x, from error term `exy`.
    #[inline]
    fn xs(self, exy: i32, s: i32) -> i32 {
        let (ax, ay) = (i64::from(self.ax), i64::from(self.ay));
        let d = 2 * (ax + ay);
        let l = 2 * ax * i64::from(s) - 2 * ax - i64::from(exy);
        // ⌈l / d⌉, with l > −d.
        if l <= 0 {
            0
        } else {
            ((l + d - 1) / d) as i32
        }
    }

    /// The error term after `s` steps from `exy`, `i` of them along x.
    #[inline]
    fn after(self, exy: i32, s: i32, i: i32) -> i32 {
        let (ax, ay) = (i64::from(self.ax), i64::from(self.ay));
        (i64::from(exy) - 2 * ax * i64::from(s) + 2 * (ax + ay) * i64::from(i)) as i32
    }

    /// The steps until the `kx`-th step along x or the `ky`-th along y
    /// (both at least 1), at most `n`; and how many of them go along x.
    #[inline]
    fn leave(self, exy: i32, kx: i32, ky: i32, n: i32) -> (i32, i32) {
        let (ax, ay) = (i64::from(self.ax), i64::from(self.ay));
        let (e, d) = (i64::from(exy), 2 * (ax + ay));
        let mut s = i64::from(n);
        if ax > 0 {
            // The first s with xs(s) ≥ kx.
            s = s.min((d * i64::from(kx - 1) + 2 * ax + e) / (2 * ax) + 1);
        }
        if ay > 0 {
            // The first s with s − xs(s) ≥ ky.
            let num = d * i64::from(ky) - 2 * ax - e;
            s = s.min((num + 2 * ay - 1) / (2 * ay));
        }
        let s = s as i32;
        (s, self.xs(exy, s))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn drawn(r: &Raster, pts: &[(f64, f64)], id: u16) -> Raster {
        let mut r = r.clone();
        outline(r.ppm(), pts, |x, y| r.set(x, y, id));
        r
    }

    #[test]
    fn the_staircase_in_closed_form_is_the_staircase_stepped() {
        // Lines of every lean, from various starting errors.
        let mut seed = 12345u64;
        let mut next = |m: u64| {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 33) % m) as i32
        };
        for _ in 0..2000 {
            let (ax, ay) = (next(500), next(500));
            if ax + ay == 0 {
                continue;
            }
            let st = Stairs { ax, ay };
            let (bx, by) = (2 * ax, 2 * ay);
            // Walk some steps to get a reachable error term.
            let mut exy = ay - ax;
            for _ in 0..next(100) {
                if exy < 0 {
                    exy += by
                } else {
                    exy -= bx
                }
            }
            let (kx, ky, n) = (1 + next(32), 1 + next(32), next(200));
            // Stepped: until the kx-th x step or ky-th y step, or n steps.
            let (mut e, mut s, mut i) = (exy, 0, 0);
            while s < n && i < kx && s - i < ky {
                if e < 0 {
                    e += by;
                    i += 1;
                } else {
                    e -= bx;
                }
                s += 1;
            }
            assert_eq!(
                st.leave(exy, kx, ky, n),
                (s, i),
                "ax {ax} ay {ay} exy {exy} kx {kx} ky {ky} n {n}"
            );
            assert_eq!(st.after(exy, s, i), e);
        }
    }

    #[test]
    fn outlines_floor_their_vertices_and_close() {
        let mut cells = Vec::new();
        // A 3 × 2 cell box at 0.1 m cells, its corners inside cells.
        outline(
            10.0,
            &[(0.05, 0.05), (0.35, 0.05), (0.35, 0.25), (0.05, 0.25)],
            |x, y| cells.push((x, y)),
        );
        cells.sort_unstable();
        cells.dedup();
        let want: Vec<(i32, i32)> = vec![
            (0, 0),
            (0, 1),
            (0, 2),
            (1, 0),
            (1, 2),
            (2, 0),
            (2, 2),
            (3, 0),
            (3, 1),
            (3, 2),
        ];
        assert_eq!(cells, want);
    }

    /// A wall one cell wide drawn in column `col` at 0.01 m cells.
    fn wall(col: i32) -> Raster {
        let x = f64::from(col) / 100.0;
        drawn(
            &Raster::new(-1.0, -1.0, 1.0, 1.0, 0.01),
            &[(x, -0.5), (x + 0.005, -0.5), (x + 0.005, 0.5), (x, 0.5)],
            7,
        )
    }

    #[test]
    fn a_ray_counts_whole_steps_and_leaps_to_region_edges() {
        // From x = 0.1234 (12.34 cells) the staircase takes whole steps in
        // the wall's region: it stands in column 20 after 8, 0.08 m (the
        // drawn cell's edge is 0.0766 m away).
        let h = wall(20)
            .cast(0.1234, 0.0, (1.0, 0.0), 2.0, |_| true)
            .unwrap();
        assert_eq!(h.id, 7);
        assert!((h.range - 0.08).abs() < 1e-9, "{h:?}");
        // With the wall in the next region, the empty one is leapt over
        // to its edge (32.0 cells) and the steps go on from there: column
        // 50 at 50.0 cells, 0.3766 m.
        let h = wall(50)
            .cast(0.1234, 0.0, (1.0, 0.0), 2.0, |_| true)
            .unwrap();
        assert!((h.range - 0.3766).abs() < 1e-9, "{h:?}");
        // Rejected: nothing; out of reach: nothing.
        assert_eq!(wall(50).cast(0.1234, 0.0, (1.0, 0.0), 2.0, |_| false), None);
        assert_eq!(wall(50).cast(0.1234, 0.0, (1.0, 0.0), 0.3, |_| true), None);
    }

    #[test]
    fn below_zero_cells_sit_one_lower_and_cell_zero_spans_two() {
        // Column −20 is drawn over [−0.20, −0.19) but looked up by
        // truncation over (−0.21, −0.20]: from −7.66 cells the ray meets
        // it after 13 steps, 0.13 m (the drawn edge is 0.1134 m away).
        let h = wall(-20)
            .cast(-0.0766, 0.0, (-1.0, 0.0), 2.0, |_| true)
            .unwrap();
        assert!((h.range - 0.13).abs() < 1e-9, "{h:?}");
        // Column −1, with something in region 0 so that the ray walks it:
        // from 0.5 cells, one step lands at −0.5, still cell 0; the
        // second at −1.5 meets the wall.
        let mut r = wall(-1);
        r.set(5, 20, 9);
        let h = r.cast(0.005, 0.0, (-1.0, 0.0), 2.0, |_| true).unwrap();
        assert!((h.range - 0.02).abs() < 1e-9, "{h:?}");
    }

    #[test]
    fn moving_bodies_fill_regions_and_so_change_the_staircase() {
        // An oblique ray towards a wall; a body far off its path but in a
        // region it crosses turns a leap into a walk, which may end
        // elsewhere on the wall, never before it.
        let base = drawn(
            &Raster::new(-3.0, -3.0, 3.0, 3.0, 0.02),
            &[(2.0, -3.0), (2.1, -3.0), (2.1, 3.0), (2.0, 3.0)],
            1,
        );
        let d = (0.3f64.cos(), 0.3f64.sin());
        let open = base.cast(-2.5, -0.7, d, 8.0, |_| true).unwrap();
        // (The ray passes the body, which it does not accept.)
        let sees = |id: u16| id != 2;
        let mut busy = base.clone();
        let mut body = Vec::new();
        let square = [(0.0, 0.0), (0.1, 0.0), (0.1, 0.1), (0.0, 0.1)];
        outline(busy.ppm(), &square, |x, y| body.push((x, y)));
        assert!(!body.is_empty());
        for &(x, y) in &body {
            busy.set_moving(x, y, 2);
        }
        let walked = busy.cast(-2.5, -0.7, d, 8.0, sees).unwrap();
        let exact = (2.0 + 2.5) / d.0;
        for h in [open, walked] {
            assert!(
                (h.range - exact).abs() < 2.0 * 0.02 / d.0,
                "{h:?} against {exact}"
            );
        }
        for &(x, y) in &body {
            busy.unset_moving(x, y, 2);
        }
        assert_eq!(busy.cast(-2.5, -0.7, d, 8.0, |_| true), Some(open));
    }
}
