//! An occupancy grid with a coarse level for fast ray casting.
//!
//! Each cell holds the id of what occupies it (`EMPTY` = nothing). Cells are
//! grouped in `TILE`×`TILE` tiles whose occupied-cell counts let a ray jump
//! over empty tiles: in open space a ray costs one step per tile, not per cell.
//! A grid may also keep each cell's clearance (how far the nearest occupied
//! cell is): a ray that need not visit every tile ([`Grid::cast_open`])
//! leaps by it, as far as the open space reaches, in a few steps.
//! A [`Lattice`] is the cells' geometry alone (which cells a point, polygon
//! or segment covers), for rasterising without a grid's storage.

use std::collections::HashMap;

/// The id of an empty cell.
pub const EMPTY: u16 = 0;

/// Cells per tile side.
const TILE: usize = 16;

/// A tile's id when its cells hold several (see [`Grid`]'s `ids`).
const MIXED: u16 = u16::MAX;

/// Cells per side of the blocks clearance is kept for.
const BLOCK: usize = 4;

/// The most blocks of clearance a grid records (see [`Grid::clearance`]):
/// 61 cells and more, enough to skip the open space around a sensor,
/// small enough that a change to the grid is redrawn in a small window.
const CLEAR: u8 = 16;

/// The fewest blocks a grid has for [`Grid::refresh_clearance_on`] to draw
/// its clearance on several threads: fewer are drawn in under 2 ms on one.
const BANDED: usize = 1 << 20;

/// The least Chebyshev distance in cells from a cell of a block `d` blocks
/// from the nearest occupied one to an occupied cell.
#[inline(always)]
fn least_cells(d: u8) -> u8 {
    match d {
        0 => 0,
        d => (d - 1) * BLOCK as u8 + 1,
    }
}

/// What a ray hit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Metres from the ray's origin to the hit cell's boundary.
    pub range: f64,
    /// The id in the hit cell.
    pub id: u16,
}

/// Square cells over a rectangle of the world: their geometry only (which
/// cell holds a point, which cells a polygon or a segment covers), with no
/// storage, so it costs nothing however fine.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lattice {
    res: f64,
    x0: f64,
    y0: f64,
    w: usize,
    h: usize,
}

/// An occupancy grid over a rectangle of the world.
#[derive(Debug, Clone)]
pub struct Grid {
    lat: Lattice,
    /// One bit per cell, whether occupied, tile by tile: a tile's 16 rows
    /// of 16 bits lie together in 32 bytes. Rays walk these: a grid of
    /// 7000 × 3000 cells (Stage's hospital at 0.02 m) is 2.6 MB of bits,
    /// which the caches hold, where a u16 per cell would be 42 MB.
    bits: Vec<u16>,
    /// Per tile, the id all its occupied cells hold; [`MIXED`] when they
    /// hold several (their ids are then in `mixed`); `EMPTY` when none.
    ids: Vec<u16>,
    /// The cells of the tiles whose cells hold several ids, row by row.
    mixed: HashMap<usize, Box<[u16; TILE * TILE]>>,
    tw: usize,
    tiles: Vec<u32>,
    /// Per block of BLOCK × BLOCK cells, the Chebyshev distance in blocks
    /// to the nearest block with an occupied cell, at most [`CLEAR`]; 0 in
    /// such a block. Empty unless kept. (A byte per block, not per cell:
    /// Stage's large.world, 50000 × 35000 cells, keeps 109 MB, not 1.75 GB.)
    clear: Vec<u8>,
    /// The box (i0, j0, i1, j1) of cells filled or emptied since `clear`
    /// was last brought up to date.
    stale: Option<[usize; 4]>,
}

impl Lattice {
    /// Cells of `res` metres covering `[min_x, max_x] × [min_y, max_y]`
    /// (a non-positive or non-finite `res` is taken as 0.02).
    pub fn new(min_x: f64, min_y: f64, max_x: f64, max_y: f64, res: f64) -> Lattice {
        let res = if res > 0.0 && res.is_finite() {
            res
        } else {
            0.02
        };
        let w = (((max_x - min_x) / res).ceil().max(1.0)) as usize;
        let h = (((max_y - min_y) / res).ceil().max(1.0)) as usize;
        Lattice::of_cells(min_x, min_y, res, w, h)
    }

    /// `w` × `h` cells of `res` metres (positive) from the corner (x0, y0).
    pub fn of_cells(x0: f64, y0: f64, res: f64, w: usize, h: usize) -> Lattice {
        Lattice { res, x0, y0, w, h }
    }

    /// Metres per cell.
    pub fn resolution(&self) -> f64 {
        self.res
    }

    /// Cells along x and y.
    pub fn size(&self) -> (usize, usize) {
        (self.w, self.h)
    }

    /// World coordinates of the corner of cell (0, 0).
    pub fn origin(&self) -> (f64, f64) {
        (self.x0, self.y0)
    }

    /// The cell holding world point (x, y), if inside the grid.
    pub fn cell_of(&self, x: f64, y: f64) -> Option<(usize, usize)> {
        let i = ((x - self.x0) / self.res).floor();
        let j = ((y - self.y0) / self.res).floor();
        (i >= 0.0 && j >= 0.0 && (i as usize) < self.w && (j as usize) < self.h)
            .then_some((i as usize, j as usize))
    }

    /// The corner cells of the world box `[x0, y0, x1, y1]`, clamped to the
    /// grid; `None` when the box misses it.
    pub fn cells_of_box(
        &self,
        [x0, y0, x1, y1]: [f64; 4],
    ) -> Option<((usize, usize), (usize, usize))> {
        let (i0, j0) = ((x0 - self.x0) / self.res, (y0 - self.y0) / self.res);
        let (i1, j1) = ((x1 - self.x0) / self.res, (y1 - self.y0) / self.res);
        if !(i1 >= 0.0 && j1 >= 0.0 && i0 < self.w as f64 && j0 < self.h as f64) {
            return None;
        }
        let clamp = |v: f64, n: usize| (v.max(0.0) as usize).min(n - 1);
        Some((
            (clamp(i0, self.w), clamp(j0, self.h)),
            (clamp(i1, self.w), clamp(j1, self.h)),
        ))
    }

    /// Calls `f(i, j)` for every cell whose centre lies inside the polygon
    /// (even-odd rule) and every cell its outline crosses, so that walls and
    /// polygons thinner than a cell still mark cells. A cell may be reported
    /// more than once.
    pub fn polygon_cells(&self, pts: &[(f64, f64)], mut f: impl FnMut(usize, usize)) {
        if pts.len() < 3 {
            for &(x, y) in pts {
                if let Some((i, j)) = self.cell_of(x, y) {
                    f(i, j);
                }
            }
            return;
        }
        if let Some(rect) = upright_rect(pts) {
            // (Most static bodies: a bitmap's dark runs.) The cells its
            // outline crosses and those whose centres it holds are then
            // the box of cells its corners are in, each reported once.
            if let Some(((i0, j0), (i1, j1))) = self.cells_of_box(rect) {
                for j in j0..=j1 {
                    for i in i0..=i1 {
                        f(i, j);
                    }
                }
            }
            return;
        }
        self.polygon_centres(pts, &mut f);
        // The outline too, so walls thinner than a cell still block rays.
        for k in 0..pts.len() {
            self.segment_cells(pts[k], pts[(k + 1) % pts.len()], &mut f);
        }
    }

    /// Calls `f(i, j)` for every cell whose centre lies inside the polygon
    /// (even-odd rule), once each; returns how many.
    pub fn polygon_centres(&self, pts: &[(f64, f64)], mut f: impl FnMut(usize, usize)) -> usize {
        let mut n = 0;
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for &(_, y) in pts {
            lo = lo.min(y);
            hi = hi.max(y);
        }
        let j0 = (((lo - self.y0) / self.res - 0.5).ceil().max(0.0)) as usize;
        let j1 = (((hi - self.y0) / self.res - 0.5).floor()).min(self.h as f64 - 1.0);
        let mut xs: Vec<f64> = Vec::with_capacity(8);
        if j1 >= 0.0 {
            for j in j0..=(j1 as usize) {
                let yc = self.y0 + (j as f64 + 0.5) * self.res;
                xs.clear();
                for k in 0..pts.len() {
                    let (ax, ay) = pts[k];
                    let (bx, by) = pts[(k + 1) % pts.len()];
                    if (ay <= yc && by > yc) || (by <= yc && ay > yc) {
                        xs.push(ax + (yc - ay) / (by - ay) * (bx - ax));
                    }
                }
                xs.sort_by(f64::total_cmp);
                for pair in xs.chunks_exact(2) {
                    let i0 = (((pair[0] - self.x0) / self.res - 0.5).ceil().max(0.0)) as usize;
                    let i1 = ((pair[1] - self.x0) / self.res - 0.5).floor();
                    if i1 < 0.0 {
                        continue;
                    }
                    for i in i0..=(i1 as usize).min(self.w - 1) {
                        f(i, j);
                        n += 1;
                    }
                }
            }
        }
        n
    }

    /// Calls `f(i, j)` for every cell the segment from `a` to `b` passes through.
    pub fn segment_cells(&self, a: (f64, f64), b: (f64, f64), f: &mut impl FnMut(usize, usize)) {
        let (ax, ay) = ((a.0 - self.x0) / self.res, (a.1 - self.y0) / self.res);
        let (bx, by) = ((b.0 - self.x0) / self.res, (b.1 - self.y0) / self.res);
        let (dx, dy) = (bx - ax, by - ay);
        let (mut i, mut j) = (ax.floor() as i64, ay.floor() as i64);
        let (ei, ej) = (bx.floor() as i64, by.floor() as i64);
        let (si, sj) = (if dx > 0.0 { 1 } else { -1 }, if dy > 0.0 { 1 } else { -1 });
        let next = |c: i64, s: i64, p: f64, d: f64| {
            if d.abs() < 1e-12 {
                f64::INFINITY
            } else {
                ((if s > 0 { c + 1 } else { c }) as f64 - p) / d
            }
        };
        let steps = (ei - i).abs() + (ej - j).abs();
        for _ in 0..=steps {
            if i >= 0 && j >= 0 && (i as usize) < self.w && (j as usize) < self.h {
                f(i as usize, j as usize);
            }
            if i == ei && j == ej {
                break;
            }
            if next(i, si, ax, dx) < next(j, sj, ay, dy) {
                i += si;
            } else {
                j += sj;
            }
        }
    }
}

/// The box `[x0, y0, x1, y1]` of `pts` when they are the four corners of
/// a rectangle with sides along the axes, in either turning order.
fn upright_rect(pts: &[(f64, f64)]) -> Option<[f64; 4]> {
    let &[a, b, c, d] = pts else {
        return None;
    };
    let turns = |a: (f64, f64), b: (f64, f64), c: (f64, f64), d: (f64, f64)| {
        a.0 == b.0 && b.1 == c.1 && c.0 == d.0 && d.1 == a.1
    };
    (turns(a, b, c, d) || turns(b, c, d, a))
        .then(|| [a.0.min(c.0), a.1.min(c.1), a.0.max(c.0), a.1.max(c.1)])
}

impl Grid {
    /// A grid covering `[min_x, max_x] × [min_y, max_y]` with square cells of `res` metres.
    pub fn new(min_x: f64, min_y: f64, max_x: f64, max_y: f64, res: f64) -> Grid {
        let lat = Lattice::new(min_x, min_y, max_x, max_y, res);
        let (w, h) = lat.size();
        let (tw, th) = (w.div_ceil(TILE), h.div_ceil(TILE));
        Grid {
            lat,
            bits: vec![0; tw * th * TILE],
            ids: vec![EMPTY; tw * th],
            mixed: HashMap::new(),
            tw,
            tiles: vec![0; tw * th],
            clear: Vec::new(),
            stale: None,
        }
    }

    /// The grid's cells: their size, place and geometry.
    pub fn lattice(&self) -> &Lattice {
        &self.lat
    }

    /// The id in cell (i, j); `EMPTY` outside the grid.
    pub fn get(&self, i: usize, j: usize) -> u16 {
        if i >= self.lat.w || j >= self.lat.h || !occupied(&self.bits, self.tw, i, j) {
            return EMPTY;
        }
        let t = self.tile_of(i, j);
        match self.ids[t] {
            MIXED => self.mixed.get(&t).map_or(EMPTY, |c| c[in_tile(i, j)]),
            id => id,
        }
    }

    /// Whether the tile holding cell (i, j) holds anything (a lookup in a
    /// small array: checking it first spares reading the cells of empty
    /// space). False outside the grid.
    pub fn tile_occupied(&self, i: usize, j: usize) -> bool {
        i < self.lat.w && j < self.lat.h && self.tiles[self.tile_of(i, j)] != 0
    }

    /// Whether tile `t` (as [`Grid::tile_of`] names tiles) holds anything.
    pub fn tile_holds(&self, t: usize) -> bool {
        self.tiles.get(t).is_some_and(|&n| n != 0)
    }

    /// The id at world point (x, y); `EMPTY` outside the grid.
    pub fn at(&self, x: f64, y: f64) -> u16 {
        self.lat
            .cell_of(x, y)
            .map_or(EMPTY, |(i, j)| self.get(i, j))
    }

    /// Sets cell (i, j) to `id`, keeping tile counts right. Ignores cells
    /// outside, and [`MIXED`] (no model has that id).
    pub fn set(&mut self, i: usize, j: usize, id: u16) {
        let was = self.get(i, j);
        if i >= self.lat.w || j >= self.lat.h || was == id || id == MIXED {
            return;
        }
        let t = self.tile_of(i, j);
        let row = &mut self.bits[bit_row(self.tw, i, j)];
        let bit = 1 << (i % TILE);
        if id == EMPTY {
            *row &= !bit;
            self.tiles[t] -= 1;
            if self.tiles[t] == 0 {
                self.ids[t] = EMPTY;
                self.mixed.remove(&t);
            } else if let Some(cells) = self.mixed.get_mut(&t) {
                cells[in_tile(i, j)] = EMPTY;
            }
        } else {
            *row |= bit;
            if was == EMPTY {
                self.tiles[t] += 1;
            }
            match self.ids[t] {
                EMPTY => self.ids[t] = id,
                one if one == id => {}
                MIXED => {
                    if let Some(cells) = self.mixed.get_mut(&t) {
                        cells[in_tile(i, j)] = id;
                    }
                }
                one if self.tiles[t] == 1 => {
                    // (i, j) was the tile's only cell: it stays one id.
                    debug_assert_eq!(one, was);
                    self.ids[t] = id;
                }
                one => {
                    // A second id: the tile's cells are kept one by one.
                    let mut cells = Box::new([EMPTY; TILE * TILE]);
                    let (ti, tj) = (i / TILE * TILE, j / TILE * TILE);
                    for (k, c) in cells.iter_mut().enumerate() {
                        let (ci, cj) = (ti + k % TILE, tj + k / TILE);
                        if ci < self.lat.w
                            && cj < self.lat.h
                            && occupied(&self.bits, self.tw, ci, cj)
                        {
                            *c = one;
                        }
                    }
                    cells[in_tile(i, j)] = id;
                    self.ids[t] = MIXED;
                    self.mixed.insert(t, cells);
                }
            }
        }
        if (was == EMPTY) != (id == EMPTY) {
            self.mark_stale([i, j, i, j]);
        }
    }

    /// Notes that cells of the box `(i0, j0, i1, j1)` were filled or
    /// emptied, for the next [`Grid::refresh_clearance`] (when the grid
    /// keeps a clearance).
    fn mark_stale(&mut self, [i0, j0, i1, j1]: [usize; 4]) {
        if self.clear.is_empty() {
            return;
        }
        self.stale = Some(match self.stale {
            Some([a, b, c, d]) => [a.min(i0), b.min(j0), c.max(i1), d.max(j1)],
            None => [i0, j0, i1, j1],
        });
    }

    /// The radius of the disc around world point (x, y) that holds no
    /// occupied cell, as far as the grid records it (a little over a metre
    /// at 0.02 m cells): a ray from (x, y) can start its walk that far out.
    /// 0 outside the grid, when the grid does not keep it
    /// ([`Grid::keep_clearance`]), and whenever cells changed since the last
    /// [`Grid::refresh_clearance`].
    pub fn clearance(&self, x: f64, y: f64) -> f64 {
        if self.stale.is_some() || self.clear.is_empty() {
            return 0.0;
        }
        match self.lat.cell_of(x, y) {
            // The free square of cells around (i, j) reaches this far
            // beyond the cell, wherever in it the point lies.
            Some((i, j)) => {
                let d = self.clear[(j / BLOCK) * self.lat.w.div_ceil(BLOCK) + i / BLOCK];
                f64::from(least_cells(d).saturating_sub(1)) * self.lat.res
            }
            None => 0.0,
        }
    }

    /// Starts keeping [`Grid::clearance`] (one byte per block of 4 × 4
    /// cells; a grid does not keep it unless asked).
    pub fn keep_clearance(&mut self) {
        if self.clear.is_empty() {
            let (w, h) = self.lat.size();
            self.clear = vec![CLEAR; w.div_ceil(BLOCK) * h.div_ceil(BLOCK)];
            self.stale = Some([0, 0, w - 1, h - 1]);
        }
    }

    /// Brings [`Grid::clearance`] up to date with the cells changed since
    /// the last call: a window of blocks around them is redrawn.
    pub fn refresh_clearance(&mut self) {
        self.refresh_clearance_on(1);
    }

    /// [`Grid::refresh_clearance`] on up to `threads` threads: a whole
    /// grid of at least [`BANDED`] blocks is drawn in bands of rows side by
    /// side, then the rows around each cut again (a block's clearance
    /// depends on the blocks within [`CLEAR`] of it alone). Stage's
    /// large.world (109 million blocks) is drawn in 0.16 s on one thread,
    /// 0.09 s on two.
    pub fn refresh_clearance_on(&mut self, threads: usize) {
        self.refresh(threads, BANDED);
    }

    /// [`Grid::refresh_clearance_on`], in bands on a grid of at least
    /// `banded` blocks.
    fn refresh(&mut self, threads: usize, banded: usize) {
        let Some([i0, j0, i1, j1]) = self.stale.take() else {
            return;
        };
        let (bw, bh) = (self.lat.w.div_ceil(BLOCK), self.lat.h.div_ceil(BLOCK));
        let cap = usize::from(CLEAR);
        // At least four times CLEAR rows a band, so that redrawing the
        // rows around the cuts stays a small part of the work.
        let bands = threads.min(bh / (4 * cap)).max(1);
        if (i0, j0, i1 / BLOCK, j1 / BLOCK) == (0, 0, bw - 1, bh - 1)
            && bands > 1
            && bw * bh >= banded
        {
            let rows = bh.div_ceil(bands);
            let (bits, tw) = (&self.bits, self.tw);
            std::thread::scope(|s| {
                for (b, band) in self.clear.chunks_mut(rows * bw).enumerate() {
                    s.spawn(move || {
                        fill_rows(bits, tw, b * rows, band, bw);
                        chamfer(band, bw);
                    });
                }
            });
            // Each band saw only its own blocks: the rows within CLEAR of
            // a cut may be nearer something across it.
            for cut in (1..bands).map(|b| b * rows).filter(|&c| c < bh) {
                self.redraw([0, cut, bw - 1, cut]);
            }
            return;
        }
        self.redraw([i0 / BLOCK, j0 / BLOCK, i1 / BLOCK, j1 / BLOCK]);
    }

    /// Redraws the clearance of the blocks within [`CLEAR`] of the box of
    /// blocks `(i0, j0, i1, j1)`, from the blocks within CLEAR of those.
    fn redraw(&mut self, [i0, j0, i1, j1]: [usize; 4]) {
        let (bw, bh) = (self.lat.w.div_ceil(BLOCK), self.lat.h.div_ceil(BLOCK));
        let cap = usize::from(CLEAR);
        let grow = |[i0, j0, i1, j1]: [usize; 4]| {
            [
                i0.saturating_sub(cap),
                j0.saturating_sub(cap),
                (i1 + cap).min(bw - 1),
                (j1 + cap).min(bh - 1),
            ]
        };
        // The blocks whose clearance may have changed, and the blocks that
        // decide it (within CLEAR of them).
        let win = grow([i0, j0, i1, j1]);
        let src = grow(win);
        let (bits, tw) = (&self.bits, self.tw);
        if src == [0, 0, bw - 1, bh - 1] {
            // The whole grid: in place.
            fill_rows(bits, tw, 0, &mut self.clear, bw);
            chamfer(&mut self.clear, bw);
            return;
        }
        let sw = src[2] - src[0] + 1;
        let mut d: Vec<u8> = (src[1]..=src[3])
            .flat_map(|y| (src[0]..src[0] + sw).map(move |x| block_clear(bits, tw, x, y)))
            .collect();
        chamfer(&mut d, sw);
        let n = win[2] - win[0] + 1;
        for y in win[1]..=win[3] {
            let from = (y - src[1]) * sw + win[0] - src[0];
            self.clear[y * bw + win[0]..][..n].copy_from_slice(&d[from..from + n]);
        }
    }

    /// Marks every cell of the polygon with `id` (the cells
    /// [`Lattice::polygon_cells`] reports).
    pub fn fill_polygon(&mut self, pts: &[(f64, f64)], id: u16) {
        if let Some(rect) = upright_rect(pts) {
            if let Some((lo, hi)) = self.lat.cells_of_box(rect) {
                self.fill_box(lo, hi, id);
            }
            return;
        }
        let lat = self.lat;
        lat.polygon_cells(pts, |i, j| self.set(i, j, id));
    }

    /// Marks the cells from `lo` to `hi` (corners included, in the grid)
    /// with `id`: a tile's rows of bits at once where the tile holds
    /// nothing else (a bitmap's dark runs, most of a floorplan: Stage's
    /// large.world, cell by cell, took 0.6 s of its 2 s load).
    fn fill_box(&mut self, lo: (usize, usize), hi: (usize, usize), id: u16) {
        let plain = id != EMPTY && id != MIXED;
        for tj in lo.1 / TILE..=hi.1 / TILE {
            for ti in lo.0 / TILE..=hi.0 / TILE {
                let t = tj * self.tw + ti;
                let (i0, i1) = (lo.0.max(ti * TILE), hi.0.min(ti * TILE + TILE - 1));
                let (j0, j1) = (lo.1.max(tj * TILE), hi.1.min(tj * TILE + TILE - 1));
                if !plain || (self.ids[t] != EMPTY && self.ids[t] != id) {
                    // Emptying, or cells of other ids: cell by cell.
                    for j in j0..=j1 {
                        for i in i0..=i1 {
                            self.set(i, j, id);
                        }
                    }
                    continue;
                }
                let mask = ((1u32 << (i1 - i0 + 1)) - 1) << (i0 % TILE);
                let mask = mask as u16;
                let mut added = 0;
                for j in j0..=j1 {
                    let row = &mut self.bits[bit_row(self.tw, i0, j)];
                    added += (mask & !*row).count_ones();
                    *row |= mask;
                }
                if added > 0 {
                    self.tiles[t] += added;
                    self.ids[t] = id;
                    self.mark_stale([i0, j0, i1, j1]);
                }
            }
        }
    }

    /// Empties the cells of the polygon that hold `id`.
    pub fn clear_polygon(&mut self, pts: &[(f64, f64)], id: u16) {
        let lat = self.lat;
        lat.polygon_cells(pts, |i, j| {
            if self.get(i, j) == id {
                self.set(i, j, EMPTY);
            }
        });
    }

    /// The first cell along the ray from (x, y) at `angle` whose id `accept`s,
    /// within `max_range` metres.
    ///
    /// # Behavior
    ///
    /// A grid walk that jumps over tiles holding nothing: in open space a
    /// ray costs one step per column of tiles, not per cell. A ray
    /// starting outside the grid finds nothing until it enters it. The range
    /// is to the boundary of the hit cell where the ray enters it (0 when the
    /// ray starts in it).
    pub fn cast(
        &self,
        x: f64,
        y: f64,
        angle: f64,
        max_range: f64,
        accept: impl FnMut(u16) -> bool,
    ) -> Option<Hit> {
        let (dy, dx) = angle.sin_cos();
        self.cast_with(x, y, (dx, dy), (0.0, max_range), accept, |_| None)
    }

    /// The tile holding cell (i, j), as [`Grid::cast_with`] names tiles.
    pub fn tile_of(&self, i: usize, j: usize) -> usize {
        (j / TILE) * self.tw + i / TILE
    }

    /// The tiles holding the cells of the box from `lo` to `hi` (corners
    /// included).
    pub fn tiles_of_box(
        &self,
        lo: (usize, usize),
        hi: (usize, usize),
    ) -> impl Iterator<Item = usize> + Clone + '_ {
        self.tile_box(lo, hi).tiles(self.tw)
    }

    /// The box of tiles holding the cells of the box from `lo` to `hi`
    /// (corners included).
    pub fn tile_box(&self, lo: (usize, usize), hi: (usize, usize)) -> TileBox {
        TileBox {
            lo: (lo.0 / TILE, lo.1 / TILE),
            hi: (hi.0 / TILE, hi.1 / TILE),
        }
    }

    /// How many tiles a row of the grid has: [`TileBox::tiles`] numbers
    /// tiles by it.
    pub fn tiles_wide(&self) -> usize {
        self.tw
    }

    /// How many tiles the grid has.
    pub fn tile_count(&self) -> usize {
        self.tiles.len()
    }

    /// [`Grid::cast_with`] with nothing kept outside the grid. On a grid
    /// that keeps its clearance ([`Grid::keep_clearance`]) the ray leaps
    /// over the open space the clearance shows and walks cells only next
    /// to what is there.
    pub fn cast_open(
        &self,
        x: f64,
        y: f64,
        d: (f64, f64),
        range: (f64, f64),
        mut accept: impl FnMut(u16) -> bool,
    ) -> Option<Hit> {
        if self.clear.is_empty() || self.stale.is_some() {
            return self.cast_with(x, y, d, range, accept, |_| None);
        }
        let r = self.aim(x, y, d, range)?;
        let bw = self.lat.w.div_ceil(BLOCK);
        let (mut k, mut v_in) = (0, r.v_in0);
        while k < r.n {
            let c = r.col(k);
            let v = row(v_in);
            let (i, j) = r.cell(c, v);
            let open = least_cells(self.clear[(j / BLOCK) * bw + i / BLOCK]);
            if open >= 2 {
                // The next `open - 1` columns lie in the free square around
                // this cell: the ray moves at most a row per column.
                k += usize::from(open - 1);
                if k >= r.n {
                    return None;
                }
                v_in = r.v_out(k - 1);
                continue;
            }
            let v_o = r.v_out(k);
            let (ib, jb) = r.cell(c, row(v_o));
            if occupied(&self.bits, self.tw, i, j) || occupied(&self.bits, self.tw, ib, jb) {
                let (a, b) = (self.get(i, j), self.get(ib, jb));
                if let Some((t, id)) = r.hit_in(k, (a, b), (v_in, v_o), &mut accept) {
                    return Some(Hit {
                        range: t * r.res,
                        id,
                    });
                }
            }
            v_in = v_o;
            k += 1;
        }
        None
    }

    /// [`Grid::cast`] along the unit vector `(dx, dy)`, with things kept
    /// outside the grid: `in_tile(t)` is called once as the ray enters each
    /// tile `t` on its way and answers the nearest hit (range from the ray's
    /// origin) of what it keeps there, e.g. moving bodies tested exactly
    /// against the ray. The nearest of those and the grid's cells wins.
    /// The ray is looked at from `from` to `max_range` metres: a caller that
    /// knows the first stretch empty (see [`Grid::clearance`]) skips it.
    ///
    /// # Behavior
    ///
    /// The ray advances one column at a time along its major axis (the one
    /// it moves along faster). In one column it crosses at most two cells of
    /// the minor axis, and in one column of tiles at most two tiles, so each
    /// step reads two cells (or two tile counts) and branches only on what it
    /// found: a step costs the same whichever way the ray leans, with none of
    /// the mispredicted "x or y next?" branches of a cell-by-cell walk.
    pub fn cast_with(
        &self,
        x: f64,
        y: f64,
        d: (f64, f64),
        (from, max_range): (f64, f64),
        mut accept: impl FnMut(u16) -> bool,
        mut in_tile: impl InTile,
    ) -> Option<Hit> {
        let r = self.aim(x, y, d, (from, max_range))?;
        let inv_res = 1.0 / r.res;
        // The nearest hit `in_tile` reported, and its parameter.
        let (mut best, mut best_t): (Option<Hit>, f64) = (None, f64::INFINITY);
        let end = |best: Option<Hit>| best.filter(|h| h.range <= max_range);
        let mut k = 0;
        let mut v_in = r.v_in0;
        let shift = TILE.trailing_zeros();
        while k < r.n {
            // The columns of this column of tiles, and the tiles they cross.
            let c = r.col(k);
            let left = if r.forward {
                TILE - c % TILE
            } else {
                c % TILE + 1
            };
            let m = left.min(r.n - k);
            let v_last = r.v_out(k + m - 1);
            let tcol = (c >> shift) * r.tu;
            let (ta, tb) = (
                tcol + (row(v_in) >> shift) * r.tv,
                tcol + (row(v_last) >> shift) * r.tv,
            );
            let mut ask = |t: usize| {
                if let Some(h) = in_tile.in_tile(t) {
                    if h.range * inv_res < best_t {
                        best_t = h.range * inv_res;
                        best = Some(h);
                    }
                }
            };
            ask(ta);
            if tb != ta {
                ask(tb);
            }
            if best.is_some() && r.t_in(k) >= best_t {
                return end(best);
            }
            if self.tiles[ta] | self.tiles[tb] != 0 {
                // Walk the cells of these columns: two per column at most.
                let mut kk = k;
                while kk < k + m {
                    let span = Columns {
                        c: r.col(kk),
                        forward: r.forward,
                        v_in,
                        v_raw: r.vb0 + kk as i64 * r.dvs,
                        dvs: r.dvs,
                        lo: r.lo,
                        hi: r.hi,
                    };
                    let found = if r.x_major {
                        span.scan::<true>(&self.bits, self.tw, k + m - kk)
                    } else {
                        span.scan::<false>(&self.bits, self.tw, k + m - kk)
                    };
                    let (j, v_i, v_o) = match found {
                        Ok(found) => found,
                        Err(v_o) => {
                            v_in = v_o;
                            break;
                        }
                    };
                    let (a, b) = (r.id_at(self, kk + j, v_i), r.id_at(self, kk + j, v_o));
                    kk += j;
                    if let Some((t, id)) = r.hit_in(kk, (a, b), (v_i, v_o), &mut accept) {
                        if t >= best_t {
                            return end(best);
                        }
                        return Some(Hit {
                            range: t * r.res,
                            id,
                        });
                    }
                    v_in = v_o;
                    kk += 1;
                }
            } else {
                v_in = v_last;
            }
            k += m;
        }
        end(best)
    }

    /// A ray from (x, y) along the unit vector `(dx, dy)`, from `from` to
    /// `max_range` metres, clipped to the grid and set up for walking it
    /// column by column; `None` when no stretch of it lies in the grid.
    #[inline(always)]
    fn aim(
        &self,
        x: f64,
        y: f64,
        (dx, dy): (f64, f64),
        (from, max_range): (f64, f64),
    ) -> Option<Aim> {
        let res = self.lat.res;
        let (w, h) = (self.lat.w, self.lat.h);
        let inv_res = 1.0 / res;
        let gx = (x - self.lat.x0) * inv_res;
        let gy = (y - self.lat.y0) * inv_res;
        // Name the axes: u the major one (columns), v the minor one (rows).
        let x_major = dx.abs() >= dy.abs();
        let (gu, gv, du, dv, nu, nv, tu, tv) = if x_major {
            (gx, gy, dx, dy, w, h, 1, self.tw)
        } else {
            (gy, gx, dy, dx, h, w, self.tw, 1)
        };
        if du.is_nan() || du.abs() < 1e-12 {
            return None; // (0, 0) or NaN: no direction.
        }
        let inv_du = 1.0 / du;
        let (mut t0, mut t1) = (from.max(0.0) * inv_res, max_range * inv_res);
        // Clip the ray to the grid box, unless both ends lie in it (most
        // rays); parameters are in cells along the ray. (|du| ≥ √½, so only
        // the minor axis can run parallel to a side.)
        let (ex, ey) = (gx + dx * t1, gy + dy * t1);
        // (A margin far above rounding: clipping would change nothing.)
        let within = |p: f64, n: usize| p >= 1e-6 && p <= n as f64 - 1e-6;
        let inside = within(gx, w) && within(gy, h) && within(ex, w) && within(ey, h);
        if !inside {
            let (a, b) = (-gu * inv_du, (nu as f64 - gu) * inv_du);
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
            if dv.abs() < 1e-12 {
                if gv < 0.0 || gv >= nv as f64 {
                    return None;
                }
            } else {
                let inv_dv = 1.0 / dv;
                let (a, b) = (-gv * inv_dv, (nv as f64 - gv) * inv_dv);
                t0 = t0.max(a.min(b));
                t1 = t1.min(a.max(b));
            }
        }
        if t0 > t1 {
            return None;
        }
        let forward = du > 0.0;
        let cell = |p: f64, n: usize| (p as i64).clamp(0, n as i64 - 1) as usize;
        // The first and last columns the ray is inside of (not just touching).
        let (u0, u1) = (gu + du * t0, gu + du * t1);
        let nudge = if forward { 1e-9 } else { -1e-9 };
        let (first, last) = (cell(u0 + nudge, nu), cell(u1 - nudge, nu));
        let n = if forward {
            last.checked_sub(first)
        } else {
            first.checked_sub(last)
        }? + 1;
        // Column k (counted from the first) is entered at t_in(k) and left at
        // te + k·tc (or t1, the end of the ray).
        let tc = inv_du.abs();
        let te = ((if forward { first + 1 } else { first }) as f64 - gu) * inv_du;
        // Rows are read from v in fixed point (32 fractional bits): a step
        // is then integer adds and shifts, with no float conversions.
        let top = ((nv as i64) << 32) - 1;
        let v_end = ((gv + dv * t1) * ONE) as i64;
        let up = dv >= 0.0;
        let (lo, hi) = if up {
            (0, v_end.min(top))
        } else {
            (v_end.max(0), top)
        };
        Some(Aim {
            res,
            gv,
            dv,
            up,
            t0,
            t1,
            te,
            tc,
            first,
            n,
            forward,
            x_major,
            tu,
            tv,
            vb0: ((gv + dv * te) * ONE) as i64,
            dvs: (dv * tc * ONE) as i64,
            lo,
            hi,
            v_in0: (((gv + dv * t0) * ONE) as i64).clamp(0, top),
        })
    }
}

/// A box of tiles (columns and rows, both corners included), as
/// [`Grid::tile_box`] finds it: what a body's cells span, which changes far
/// less often than the cells.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TileBox {
    /// The first column and row.
    pub lo: (usize, usize),
    /// The last column and row.
    pub hi: (usize, usize),
}

impl TileBox {
    /// Its tiles' numbers (as [`Grid::cast_with`] names tiles) in a grid
    /// `tw` tiles wide, row by row.
    pub fn tiles(self, tw: usize) -> impl Iterator<Item = usize> + Clone {
        let TileBox { lo, hi } = self;
        (lo.1..=hi.1).flat_map(move |r| (lo.0..=hi.0).map(move |c| r * tw + c))
    }
}

/// What [`Grid::cast_with`] asks of each tile a ray enters: the nearest
/// hit among what the caller keeps there. A closure will do; a type of
/// its own can have its answer inlined into the ray's walk.
pub trait InTile {
    /// The nearest hit (range from the ray's origin) among what is kept in
    /// tile `t`.
    fn in_tile(&mut self, t: usize) -> Option<Hit>;
}

impl<F: FnMut(usize) -> Option<Hit>> InTile for F {
    #[inline(always)]
    fn in_tile(&mut self, t: usize) -> Option<Hit> {
        self(t)
    }
}

/// 1 in the fixed point rays read rows in (32 fractional bits).
const ONE: f64 = (1u64 << 32) as f64;

/// The row holding fixed-point v.
#[inline(always)]
fn row(v: i64) -> usize {
    (v >> 32) as usize
}

/// A ray set up for walking the grid column by column along its major
/// axis u, reading rows of the minor axis v (see [`Grid::aim`]). Ray
/// parameters t are in cells along the ray.
struct Aim {
    /// Metres per cell.
    res: f64,
    /// v at the ray's origin, and per unit of t.
    gv: f64,
    dv: f64,
    /// Whether v grows along the ray.
    up: bool,
    /// Where the ray enters and leaves the grid.
    t0: f64,
    t1: f64,
    /// Where the ray leaves its first column, and t per column.
    te: f64,
    tc: f64,
    /// The first column, and how many the ray crosses.
    first: usize,
    n: usize,
    /// Whether the ray walks towards higher columns.
    forward: bool,
    /// Whether columns run along x (rows along y), or the other way.
    x_major: bool,
    /// Index distance between neighbouring tiles along u and along v.
    tu: usize,
    tv: usize,
    /// v (fixed point) where the ray leaves the first column before
    /// clamping, and its change per column.
    vb0: i64,
    dvs: i64,
    /// The clamp keeping v on the ray and in the grid.
    lo: i64,
    hi: i64,
    /// v where the ray enters the first column.
    v_in0: i64,
}

impl Aim {
    /// Where the ray enters column k (counted from the first).
    #[inline(always)]
    fn t_in(&self, k: usize) -> f64 {
        if k == 0 {
            self.t0
        } else {
            self.te + (k - 1) as f64 * self.tc
        }
    }

    /// v where the ray leaves column k, clamped to the ray and the grid.
    #[inline(always)]
    fn v_out(&self, k: usize) -> i64 {
        (self.vb0 + k as i64 * self.dvs).clamp(self.lo, self.hi)
    }

    /// The cell (i, j) in grid column `c` and row `v`.
    #[inline(always)]
    fn cell(&self, c: usize, v: usize) -> (usize, usize) {
        if self.x_major {
            (c, v)
        } else {
            (v, c)
        }
    }

    /// The id in column k (counted from the first) at fixed-point v.
    #[inline(always)]
    fn id_at(&self, grid: &Grid, k: usize, v: i64) -> u16 {
        let (i, j) = self.cell(self.col(k), row(v));
        grid.get(i, j)
    }

    /// The grid column of column k.
    #[inline(always)]
    fn col(&self, k: usize) -> usize {
        if self.forward {
            self.first + k
        } else {
            self.first - k
        }
    }

    /// What the ray meets in column k, whose cells where it enters and
    /// leaves are `a` and `b` (rows of v `v_in` and `v_out`): t and the id,
    /// when one of them holds what `accept`s.
    #[inline(always)]
    fn hit_in(
        &self,
        k: usize,
        (a, b): (u16, u16),
        (v_in, v_out): (i64, i64),
        accept: &mut impl FnMut(u16) -> bool,
    ) -> Option<(f64, u16)> {
        let (ja, jb) = (row(v_in), row(v_out));
        if a != EMPTY && accept(a) {
            Some((self.t_in(k), a))
        } else if jb != ja && b != EMPTY && accept(b) {
            // Where the ray crosses into row jb.
            let edge = if self.up { jb } else { jb + 1 } as f64;
            let t_o = (self.te + k as f64 * self.tc).min(self.t1);
            Some((((edge - self.gv) / self.dv).clamp(self.t_in(k), t_o), b))
        } else {
            None
        }
    }
}

/// The bits of the tile row of cells that block row `j / BLOCK` spans, at
/// cell column `i`'s tile: its BLOCK rows of bits OR'd, each block a nibble.
#[inline(always)]
fn block_bits(bits: &[u16], tw: usize, i: usize, j: usize) -> u16 {
    let at = bit_row(tw, i, j);
    bits[at..at + BLOCK].iter().fold(0, |any, &r| any | r)
}

/// A block's clearance before the chamfer from its nibble of
/// [`block_bits`]: 0 when one of its cells is occupied, [`CLEAR`] when none is.
#[inline(always)]
fn clear_of(nibble: u16) -> u8 {
    if nibble & 0xF != 0 {
        0
    } else {
        CLEAR
    }
}

/// Block (bi, bj)'s clearance before the chamfer (see [`clear_of`]).
#[inline(always)]
fn block_clear(bits: &[u16], tw: usize, bi: usize, bj: usize) -> u8 {
    let (i, j) = (bi * BLOCK, bj * BLOCK);
    clear_of(block_bits(bits, tw, i, j) >> (i % TILE))
}

/// Fills `out`, rows of `bw` blocks from block row `first` on, with each
/// block's [`block_clear`]: a tile's four rows of bits at once for the
/// four blocks side by side in them.
fn fill_rows(bits: &[u16], tw: usize, first: usize, out: &mut [u8], bw: usize) {
    const PER_TILE: usize = TILE / BLOCK;
    for (y, row) in (first..).zip(out.chunks_mut(bw)) {
        for (tc, four) in row.chunks_mut(PER_TILE).enumerate() {
            let m = block_bits(bits, tw, tc * TILE, y * BLOCK);
            for (k, d) in four.iter_mut().enumerate() {
                *d = clear_of(m >> (k * BLOCK));
            }
        }
    }
}

/// Turns `d` (rows of `w` cells: 0 where occupied, [`CLEAR`] where not)
/// into each cell's Chebyshev distance to the nearest 0, at most `CLEAR`:
/// two passes of the 8-neighbour chamfer, which is exact for this metric.
/// Each pass takes a row from its neighbour row at once (three cells of it
/// a cell, with no dependency from cell to cell, which the compiler turns
/// into vector instructions), then runs along the row. (Cell by cell with
/// all four neighbours, and each block's bits read alone, Stage's
/// large.world's clearance took 1.25 s on one thread; now 0.16 s.)
fn chamfer(d: &mut [u8], w: usize) {
    let h = d.len() / w;
    for y in 0..h {
        let (done, rest) = d.split_at_mut(y * w);
        let row = &mut rest[..w];
        if y > 0 {
            from_row(row, &done[(y - 1) * w..]);
        }
        along(row.iter_mut());
    }
    for y in (0..h).rev() {
        let (row, done) = d[y * w..].split_at_mut(w);
        if y + 1 < h {
            from_row(row, &done[..w]);
        }
        along(row.iter_mut().rev());
    }
}

/// Each cell of `row` at most one more than its three neighbours in the
/// row `next` to it.
#[inline]
fn from_row(row: &mut [u8], next: &[u8]) {
    let w = row.len();
    if w == 1 {
        row[0] = row[0].min(next[0] + 1);
        return;
    }
    row[0] = row[0].min(next[0].min(next[1]) + 1);
    row[w - 1] = row[w - 1].min(next[w - 2].min(next[w - 1]) + 1);
    let mid = row[1..w - 1].iter_mut();
    let three = next.iter().zip(&next[1..]).zip(&next[2..w]);
    for (v, ((&a, &b), &c)) in mid.zip(three) {
        *v = (*v).min(a.min(b).min(c) + 1);
    }
}

/// Each cell at most one more than the one before it.
#[inline]
fn along<'a>(cells: impl Iterator<Item = &'a mut u8>) {
    let mut last = CLEAR;
    for v in cells {
        last = (*v).min(last + 1);
        *v = last;
    }
}

/// A run of columns a ray crosses, for a tight scan of their cells' bits.
struct Columns {
    /// The first column, and whether the next is the one after it.
    c: usize,
    forward: bool,
    /// v (fixed point) where the ray enters the first column, and where it
    /// leaves it before clamping; `dvs` per column.
    v_in: i64,
    v_raw: i64,
    dvs: i64,
    /// The clamp keeping v on the ray and in the grid.
    lo: i64,
    hi: i64,
}

/// Where cell (i, j) lies in its tile's cells, row by row.
#[inline(always)]
fn in_tile(i: usize, j: usize) -> usize {
    (j % TILE) * TILE + i % TILE
}

/// Where the row of bits holding cell (i, j) lies in `bits` (see
/// [`Grid`]) of a grid `tw` tiles wide; the cell is its bit `i % TILE`.
#[inline(always)]
fn bit_row(tw: usize, i: usize, j: usize) -> usize {
    ((j / TILE) * tw + i / TILE) * TILE + j % TILE
}

/// Whether cell (i, j) is occupied, in `bits` (see [`Grid`]) of a grid
/// `tw` tiles wide.
#[inline(always)]
fn occupied(bits: &[u16], tw: usize, i: usize, j: usize) -> bool {
    bits[bit_row(tw, i, j)] >> (i % TILE) & 1 != 0
}

impl Columns {
    /// The first of the next `m` columns with something in a cell the ray
    /// crosses: its offset and v where the ray enters and leaves it; or,
    /// when none has, v where the ray leaves the last. Columns run along x
    /// when `X` (rows along y), along y otherwise.
    #[inline]
    fn scan<const X: bool>(
        &self,
        bits: &[u16],
        tw: usize,
        m: usize,
    ) -> Result<(usize, i64, i64), i64> {
        let (mut c, mut v_in, mut v_raw) = (self.c, self.v_in, self.v_raw);
        let at = |c: usize, v: i64| {
            let v = (v >> 32) as usize;
            if X {
                occupied(bits, tw, c, v)
            } else {
                occupied(bits, tw, v, c)
            }
        };
        for j in 0..m {
            let v_o = v_raw.clamp(self.lo, self.hi);
            if at(c, v_in) || at(c, v_o) {
                return Ok((j, v_in, v_o));
            }
            v_in = v_o;
            v_raw += self.dvs;
            c = if self.forward {
                c + 1
            } else {
                c.wrapping_sub(1)
            };
        }
        Err(v_in)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};

    /// Repeatable uniform numbers in [0, 1] (xorshift) from a seed.
    fn uniform(mut x: u32) -> impl FnMut() -> f64 {
        move || {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            f64::from(x) / f64::from(u32::MAX)
        }
    }

    fn walls() -> Grid {
        // A 10 m box with 1 m resolution 0.05, walls one cell thick at x = ±4.
        let mut g = Grid::new(-5.0, -5.0, 5.0, 5.0, 0.05);
        g.fill_polygon(&[(4.0, -5.0), (4.05, -5.0), (4.05, 5.0), (4.0, 5.0)], 7);
        g.fill_polygon(&[(-4.05, -5.0), (-4.0, -5.0), (-4.0, 5.0), (-4.05, 5.0)], 8);
        g
    }

    #[test]
    fn rays_hit_hand_computed_walls() {
        let g = walls();
        let hit = g.cast(0.0, 0.0, 0.0, 10.0, |_| true).unwrap();
        assert!((hit.range - 4.0).abs() < 0.051, "{hit:?}");
        assert_eq!(hit.id, 7);
        let hit = g.cast(1.0, 2.0, PI, 10.0, |_| true).unwrap();
        assert!((hit.range - 5.0).abs() < 0.051, "{hit:?}");
        assert_eq!(hit.id, 8);
        // 45°: the wall at x = 4 is 4·√2 away.
        let hit = g.cast(0.0, 0.0, FRAC_PI_4, 10.0, |_| true).unwrap();
        assert!((hit.range - 4.0 * 2f64.sqrt()).abs() < 0.08, "{hit:?}");
        // Straight up: no wall within range.
        assert!(g.cast(0.0, 0.0, FRAC_PI_2, 10.0, |_| true).is_none());
        // Out of range.
        assert!(g.cast(0.0, 0.0, 0.0, 3.9, |_| true).is_none());
        // A filter that ignores id 7 sees through that wall to nothing.
        assert!(g.cast(0.0, 0.0, 0.0, 10.0, |id| id != 7).is_none());
    }

    #[test]
    fn rays_from_outside_the_grid_enter_it() {
        let g = walls();
        let hit = g.cast(-20.0, 0.0, 0.0, 30.0, |_| true).unwrap();
        assert!((hit.range - 15.95).abs() < 0.051, "{hit:?}");
        assert!(g.cast(-20.0, 20.0, 0.0, 30.0, |_| true).is_none());
    }

    #[test]
    fn tiles_count_what_they_hold() {
        let mut g = Grid::new(0.0, 0.0, 2.0, 2.0, 0.1);
        g.fill_polygon(&[(0.5, 0.5), (1.5, 0.5), (1.5, 1.5), (0.5, 1.5)], 3);
        assert_eq!(g.at(1.0, 1.0), 3);
        assert_eq!(g.at(0.2, 0.2), EMPTY);
        g.clear_polygon(&[(0.5, 0.5), (1.5, 0.5), (1.5, 1.5), (0.5, 1.5)], 3);
        assert_eq!(g.at(1.0, 1.0), EMPTY);
        assert!(g.tiles.iter().all(|&t| t == 0));
        assert!(g.cast(0.0, 1.0, 0.0, 5.0, |_| true).is_none());
    }

    #[test]
    fn a_tile_keeps_several_ids_cell_by_cell() {
        // 0.1 m cells: one tile is 1.6 m, so both boxes share tile 0.
        let mut g = Grid::new(0.0, 0.0, 3.2, 3.2, 0.1);
        let a = [(0.2, 0.2), (0.6, 0.2), (0.6, 0.6), (0.2, 0.6)];
        let b = [(0.9, 0.2), (1.3, 0.2), (1.3, 0.6), (0.9, 0.6)];
        g.fill_polygon(&a, 3);
        assert_eq!((g.ids[0], g.mixed.len()), (3, 0));
        g.fill_polygon(&b, 7);
        assert_eq!((g.ids[0], g.mixed.len()), (MIXED, 1));
        assert_eq!(
            (g.at(0.4, 0.4), g.at(1.1, 0.4), g.at(0.75, 0.4)),
            (3, 7, EMPTY)
        );
        // Rays name what they meet, either way along the row.
        let hit = |x, angle| g.cast(x, 0.45, angle, 5.0, |_| true).map(|h| h.id);
        assert_eq!((hit(0.0, 0.0), hit(3.0, PI)), (Some(3), Some(7)));
        // 7 accepted alone: the ray passes 3's cells.
        let seven = g.cast(0.0, 0.45, 0.0, 5.0, |id| id == 7).map(|h| h.id);
        assert_eq!(seven, Some(7));
        // Overwriting keeps the count; emptying the tile forgets its cells.
        g.fill_polygon(&a, 7);
        assert_eq!(g.at(0.4, 0.4), 7);
        let n = g.tiles[0];
        g.clear_polygon(&b, 7);
        assert!(g.tiles[0] < n && g.tiles[0] > 0);
        g.clear_polygon(&a, 7);
        assert_eq!((g.tiles[0], g.ids[0], g.mixed.len()), (0, EMPTY, 0));
        assert!(g.bits.iter().all(|&r| r == 0));
        // A tile of one cell takes a new id without going cell by cell.
        g.set(3, 3, 5);
        g.set(3, 3, 6);
        assert_eq!((g.ids[0], g.mixed.len(), g.get(3, 3)), (6, 0, 6));
    }

    #[test]
    fn boxes_map_to_clamped_corner_cells() {
        let lat = Lattice::of_cells(0.0, 0.0, 0.5, 4, 2);
        assert_eq!(crate::bounds([]), None);
        let b = crate::bounds([(0.7, 0.2), (-1.0, 0.6), (0.9, -3.0)]).unwrap();
        assert_eq!(b, [-1.0, -3.0, 0.9, 0.6]);
        assert_eq!(lat.cells_of_box(b), Some(((0, 0), (1, 1))));
        assert_eq!(
            lat.cells_of_box([1.2, 0.1, 9.0, 0.2]),
            Some(((2, 0), (3, 0)))
        );
        assert_eq!(lat.cells_of_box([2.5, 0.0, 3.0, 1.0]), None, "beyond x");
        assert_eq!(lat.cells_of_box([0.0, -2.0, 1.0, -0.1]), None, "below");
    }

    #[test]
    fn upright_rectangles_mark_the_cells_any_polygon_would() {
        use std::collections::BTreeSet;
        let lat = Lattice::new(0.0, 0.0, 4.0, 3.0, 0.1);
        let mut rnd = uniform(7);
        let cells = |pts: &[(f64, f64)]| {
            let mut set = BTreeSet::new();
            lat.polygon_cells(pts, |i, j| {
                set.insert((i, j));
            });
            set
        };
        for k in 0..500 {
            // Corners on cell boundaries, off the grid, or anywhere.
            let mut v = |n: f64| match k % 3 {
                0 => (rnd() * n * 10.0).round() / 10.0,
                1 => rnd() * (n + 2.0) - 1.0,
                _ => rnd() * n,
            };
            let (x0, x1, y0, y1) = (v(4.0), v(4.0), v(3.0), v(3.0));
            let rect = [(x0, y0), (x0, y1), (x1, y1), (x1, y0)];
            let turned = [rect[1], rect[2], rect[3], rect[0]];
            // A fifth, repeated corner makes it a polygon like any other.
            let general = cells(&[rect[0], rect[1], rect[2], rect[3], rect[0]]);
            assert_eq!(cells(&rect), general, "{rect:?}");
            assert_eq!(cells(&turned), general, "{turned:?}");
        }
    }

    #[test]
    fn tiny_polygons_still_mark_a_cell() {
        let mut g = Grid::new(0.0, 0.0, 1.0, 1.0, 0.1);
        g.fill_polygon(&[(0.52, 0.52), (0.53, 0.52), (0.53, 0.53)], 9);
        assert_eq!(g.at(0.525, 0.525), 9);
    }

    #[test]
    fn random_rays_agree_with_a_brute_force_march() {
        let mut g = Grid::new(0.0, 0.0, 8.0, 8.0, 0.05);
        let mut rnd = uniform(99);
        for k in 0..40u16 {
            let (cx, cy) = (rnd() * 8.0, rnd() * 8.0);
            g.fill_polygon(
                &[
                    (cx, cy),
                    (cx + 0.2, cy),
                    (cx + 0.2, cy + 0.2),
                    (cx, cy + 0.2),
                ],
                k + 1,
            );
        }
        let (w, h) = g.lattice().size();
        let occupied: Vec<(usize, usize)> = (0..h)
            .flat_map(|j| (0..w).map(move |i| (i, j)))
            .filter(|&(i, j)| g.get(i, j) != EMPTY)
            .collect();
        for _ in 0..3000 {
            // From inside the grid and from around it.
            let (ox, oy) = (rnd() * 10.0 - 1.0, rnd() * 10.0 - 1.0);
            let a = rnd() * std::f64::consts::TAU;
            let fast = g.cast(ox, oy, a, 6.0, |_| true).map(|h| h.range);
            // Exact: the nearest cell box the ray passes through (slab method).
            let (dx, dy) = (a.cos(), a.sin());
            let mut exact: Option<f64> = None;
            for &(i, j) in &occupied {
                let (x0, y0) = (i as f64 * 0.05, j as f64 * 0.05);
                let (mut t0, mut t1) = (0.0f64, 6.0f64);
                for (o, d, lo) in [(ox, dx, x0), (oy, dy, y0)] {
                    if d.abs() < 1e-12 {
                        if o < lo || o >= lo + 0.05 {
                            t1 = -1.0;
                        }
                    } else {
                        let (p, q) = ((lo - o) / d, (lo + 0.05 - o) / d);
                        t0 = t0.max(p.min(q));
                        t1 = t1.min(p.max(q));
                    }
                }
                if t1 > t0 + 1e-9 {
                    exact = Some(exact.map_or(t0, |e: f64| e.min(t0)));
                }
            }
            match (fast, exact) {
                (Some(f), Some(e)) => {
                    assert!((f - e).abs() < 1e-6, "ray {ox} {oy} {a}: {f} vs {e}")
                }
                (None, None) => {}
                (f, e) => panic!("ray {ox} {oy} {a}: {f:?} vs {e:?}"),
            }
        }
    }

    /// Every tile a ray passes through is offered to `in_tile`, once, in
    /// order along the ray, and no other.
    #[test]
    fn rays_offer_exactly_the_tiles_they_cross() {
        // 10 × 7 tiles of 16 cells (the last row and column partly).
        let g = Grid::new(0.0, 0.0, 15.5, 10.5, 0.1);
        let (tw, tsize) = (g.tw, TILE as f64 * 0.1);
        let mut rnd = uniform(7);
        for _ in 0..2000 {
            let (ox, oy) = (rnd() * 19.0 - 2.0, rnd() * 14.0 - 2.0);
            let a = rnd() * std::f64::consts::TAU;
            let (dx, dy) = (a.cos(), a.sin());
            let mut seen = Vec::new();
            let hit = g.cast_with(
                ox,
                oy,
                (dx, dy),
                (0.0, 6.0),
                |_| true,
                |t| {
                    seen.push(t);
                    None
                },
            );
            assert!(hit.is_none());
            // Exact: the tiles whose box the ray's segment crosses, by entry.
            let mut exact: Vec<(f64, usize)> = Vec::new();
            for t in 0..g.tiles.len() {
                let (x0, y0) = ((t % tw) as f64 * tsize, (t / tw) as f64 * tsize);
                let (x1, y1) = ((x0 + tsize).min(15.5), (y0 + tsize).min(10.5));
                let (mut t0, mut t1) = (0.0f64, 6.0f64);
                for (o, d, lo, hi) in [(ox, dx, x0, x1), (oy, dy, y0, y1)] {
                    let (p, q) = ((lo - o) / d, (hi - o) / d);
                    t0 = t0.max(p.min(q));
                    t1 = t1.min(p.max(q));
                }
                if t1 > t0 + 1e-9 {
                    exact.push((t0, t));
                }
            }
            exact.sort_by(|a, b| a.0.total_cmp(&b.0));
            let exact: Vec<usize> = exact.into_iter().map(|(_, t)| t).collect();
            assert_eq!(seen, exact, "ray {ox} {oy} {a}");
        }
    }

    #[test]
    fn rectangles_filled_tile_by_tile_are_the_cells_set_one_by_one() {
        // Upright rectangles of three ids over each other, across tiles
        // and within them, some over cells of another id, then a few
        // emptied: every cell, tile count and clearance as cell by cell.
        let mut rnd = uniform(23);
        let rects: Vec<([(f64, f64); 4], u16)> = (0..60)
            .map(|k| {
                let (x, y) = (rnd() * 3.5, rnd() * 2.5);
                let (w, h) = (rnd() * 0.6 + 0.001, rnd() * 0.6 + 0.001);
                let id = [1, 2, 3][k % 3];
                ([(x, y), (x + w, y), (x + w, y + h), (x, y + h)], id)
            })
            .collect();
        let mut fast = Grid::new(0.0, 0.0, 4.0, 3.0, 0.02);
        let mut slow = fast.clone();
        fast.keep_clearance();
        slow.keep_clearance();
        let lat = slow.lat;
        for (k, (pts, id)) in rects.iter().enumerate() {
            fast.fill_polygon(pts, *id);
            lat.polygon_cells(pts, |i, j| slow.set(i, j, *id));
            if k % 20 == 19 {
                fast.clear_polygon(&rects[k - 5].0, rects[k - 5].1);
                slow.clear_polygon(&rects[k - 5].0, rects[k - 5].1);
            }
        }
        let (w, h) = fast.lat.size();
        for j in 0..h {
            for i in 0..w {
                assert_eq!(fast.get(i, j), slow.get(i, j), "cell ({i}, {j})");
            }
        }
        assert_eq!(fast.tiles, slow.tiles);
        assert_eq!(fast.ids, slow.ids);
        assert!(fast.ids.contains(&MIXED), "some tile holds several ids");
        fast.refresh_clearance();
        slow.refresh_clearance();
        assert_eq!(fast.clear, slow.clear);
    }

    #[test]
    fn clearance_drawn_in_bands_is_the_clearance_drawn_whole() {
        // 16 m × 16 m of 2 cm cells: 200 × 200 blocks (two or three bands
        // of rows), random boxes, a wall along the first cut's row (at
        // 8 m, or 5.36 m in three bands) and one just past it.
        let walls = |g: &mut Grid| {
            let mut rnd = uniform(5);
            for _ in 0..40 {
                let (x, y) = (rnd() * 15.0, rnd() * 15.0);
                let (w, h) = (rnd() * 0.8 + 0.02, rnd() * 0.8 + 0.02);
                g.fill_polygon(&[(x, y), (x + w, y), (x + w, y + h), (x, y + h)], 1);
            }
            for y in [5.36, 8.0] {
                g.fill_polygon(&[(2.0, y), (9.0, y), (9.0, y + 0.02), (2.0, y + 0.02)], 2);
                let y = y + 0.1;
                g.fill_polygon(&[(3.0, y), (3.5, y), (3.5, y + 0.02), (3.0, y + 0.02)], 2);
            }
        };
        let mut whole = Grid::new(0.0, 0.0, 16.0, 16.0, 0.02);
        walls(&mut whole);
        whole.keep_clearance();
        whole.refresh_clearance();
        for threads in [2, 3, 8] {
            let mut banded = Grid::new(0.0, 0.0, 16.0, 16.0, 0.02);
            walls(&mut banded);
            banded.keep_clearance();
            banded.refresh(threads, 0);
            assert!(banded.stale.is_none());
            let differ = (whole.clear.iter().zip(&banded.clear)).filter(|(a, b)| a != b);
            assert_eq!(differ.count(), 0, "{threads} threads");
        }
        // A grid too short for two bands is drawn whole.
        let mut flat = Grid::new(0.0, 0.0, 16.0, 1.0, 0.02);
        flat.keep_clearance();
        flat.refresh(2, 0);
        assert!(flat.clear.iter().all(|&d| d == CLEAR));
    }

    /// The clearance is the exact Chebyshev distance to the nearest
    /// occupied cell (capped), kept right as cells fill and empty.
    #[test]
    fn clearance_follows_the_cells() {
        let mut g = Grid::new(0.0, 0.0, 8.0, 6.0, 0.02);
        g.fill_polygon(&[(1.0, 1.0), (1.5, 1.0), (1.5, 1.2)], 2);
        assert_eq!(g.clearance(4.0, 3.0), 0.0, "not kept unless asked");
        g.keep_clearance();
        g.refresh_clearance();
        // 2.5 m from the triangle: as far as the grid records, 60 cells.
        assert!((g.clearance(4.0, 3.0) - 1.2).abs() < 1e-9);
        // Next to it, no further than the triangle is.
        let near = g.clearance(1.6, 1.1);
        assert!(near > 0.0 && near <= 0.1, "{near}");
        let (w, h) = g.lat.size();
        let bw = w.div_ceil(BLOCK);
        let mut rnd = uniform(11);
        // Each block's distance in blocks to the nearest with an occupied cell.
        let check = |g: &Grid, rnd: &mut dyn FnMut() -> f64| {
            let occupied: Vec<(usize, usize)> = (0..h)
                .flat_map(|j| (0..w).map(move |i| (i, j)))
                .filter(|&(i, j)| g.get(i, j) != EMPTY)
                .map(|(i, j)| (i / BLOCK, j / BLOCK))
                .collect();
            for _ in 0..300 {
                let (i, j) = (
                    (rnd() * (w - 1) as f64) as usize / BLOCK,
                    (rnd() * (h - 1) as f64) as usize / BLOCK,
                );
                let want = occupied
                    .iter()
                    .map(|&(a, b)| a.abs_diff(i).max(b.abs_diff(j)))
                    .min()
                    .unwrap_or(usize::MAX)
                    .min(usize::from(CLEAR));
                assert_eq!(usize::from(g.clear[j * bw + i]), want, "block ({i}, {j})");
            }
        };
        for round in 0..6 {
            // Boxes come and go; a disc around them must stay empty.
            let (x, y) = (rnd() * 7.0, rnd() * 5.0);
            let square = [(x, y), (x + 0.3, y), (x + 0.3, y + 0.2), (x, y + 0.2)];
            if round % 3 == 2 {
                g.clear_polygon(&square, 1);
                for j in 0..h {
                    for i in 0..w {
                        if g.get(i, j) == 1 && rnd() < 0.5 {
                            g.set(i, j, EMPTY);
                        }
                    }
                }
            } else {
                g.fill_polygon(&square, 1);
            }
            assert_eq!(g.clearance(4.0, 3.0), 0.0, "stale until refreshed");
            g.refresh_clearance();
            check(&g, &mut rnd);
        }
        // The disc it promises holds no occupied cell.
        for _ in 0..2000 {
            let (x, y) = (rnd() * 8.0, rnd() * 6.0);
            let r = g.clearance(x, y);
            if r == 0.0 {
                continue;
            }
            let a = rnd() * std::f64::consts::TAU;
            let (px, py) = (x + r * 0.999 * a.cos(), y + r * 0.999 * a.sin());
            assert_eq!(g.at(px, py), EMPTY, "({px}, {py}) within {r} of ({x}, {y})");
        }
    }

    /// A ray looked at from `from` finds what lies beyond, at the same range.
    #[test]
    fn a_ray_from_a_distance_sees_what_lies_beyond() {
        let g = walls();
        let full = g.cast(0.0, 0.0, 0.0, 10.0, |_| true).unwrap();
        let part = g
            .cast_with(0.0, 0.0, (1.0, 0.0), (2.5, 10.0), |_| true, |_| None)
            .unwrap();
        assert_eq!(full, part);
        let none = g.cast_with(0.0, 0.0, (1.0, 0.0), (4.5, 10.0), |_| true, |_| None);
        assert_eq!(none, None, "the wall lies before the stretch looked at");
    }

    /// Rays that leap by the clearance find exactly what rays walking every
    /// column find, as boxes come and go (and while the clearance is stale),
    /// with one id the rays pass through.
    #[test]
    fn leaping_rays_find_what_walking_rays_find() {
        let mut g = Grid::new(0.0, 0.0, 8.0, 6.0, 0.02);
        let mut rnd = uniform(5);
        g.keep_clearance();
        let mut boxes: Vec<([(f64, f64); 3], u16)> = Vec::new();
        let mut hits = 0;
        for round in 0..8 {
            for _ in 0..25 {
                let (x, y, id) = (rnd() * 8.0, rnd() * 6.0, 1 + (rnd() * 3.0) as u16);
                let b = [(x, y), (x + rnd() * 0.6, y), (x + 0.3, y + rnd() * 0.6)];
                g.fill_polygon(&b, id);
                boxes.push((b, id));
            }
            if round % 2 == 1 {
                for (b, id) in boxes.drain(..15) {
                    g.clear_polygon(&b, id);
                }
            }
            if round != 5 {
                g.refresh_clearance();
            }
            for _ in 0..3000 {
                let (x, y) = (rnd() * 10.0 - 1.0, rnd() * 8.0 - 1.0);
                let a = rnd() * std::f64::consts::TAU;
                let d = (a.cos(), a.sin());
                let range = (rnd() * 0.5, rnd() * 9.0);
                let see = |id: u16| id != 3;
                let walked = g.cast_with(x, y, d, range, see, |_| None);
                assert_eq!(
                    g.cast_open(x, y, d, range, see),
                    walked,
                    "round {round}: {x} {y} {a}"
                );
                hits += usize::from(walked.is_some());
            }
        }
        assert!(hits > 8_000, "{hits}");
    }
}

#[cfg(test)]
mod thin {
    use super::*;

    #[test]
    fn walls_thinner_than_a_cell_still_block_rays() {
        let mut g = Grid::new(0.0, 0.0, 4.0, 4.0, 0.02);
        g.fill_polygon(&[(2.0, 0.0), (2.005, 0.0), (2.005, 4.0), (2.0, 4.0)], 5);
        let hit = g.cast(0.5, 1.0, 0.0, 3.0, |_| true).expect("thin wall hit");
        assert!((hit.range - 1.5).abs() < 0.021, "{hit:?}");
        // A diagonal segment marks a connected run of cells.
        let mut n = 0;
        g.lattice()
            .segment_cells((0.01, 0.01), (0.99, 0.5), &mut |_, _| n += 1);
        assert!(n >= 49 + 25 - 1, "{n}");
    }
}
