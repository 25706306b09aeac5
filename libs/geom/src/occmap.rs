//! An occupancy map as Player's map interface serves it: what mapfile loads
//! and what amcl and wavefront plan and localize on.

use troupe_msgs::{map, Pose2d};

/// Cell value: free.
pub const FREE: i8 = -1;
/// Cell value: unknown.
pub const UNKNOWN: i8 = 0;
/// Cell value: occupied.
pub const OCCUPIED: i8 = 1;

/// ROS map_server's default thresholds: above `OCCUPIED_THRESH` a cell's
/// probability of being occupied makes it occupied, below `FREE_THRESH`
/// free, unknown between. The map files Troupe writes say them, and the
/// map builder classifies its cells by them.
pub const OCCUPIED_THRESH: f64 = 0.65;
/// See [`OCCUPIED_THRESH`].
pub const FREE_THRESH: f64 = 0.196;

/// The index (row-major from the origin) of the cell of `info`'s grid that
/// holds world point (x, y); `None` off the grid. One conversion for the
/// map, amcl's distance field and wavefront's planner.
#[inline]
pub fn index_of(info: &map::Info, x: f64, y: f64) -> Option<usize> {
    let r = f64::from(info.resolution);
    let i = ((x - info.origin.x) / r).floor();
    let j = ((y - info.origin.y) / r).floor();
    if i < 0.0 || j < 0.0 || i >= f64::from(info.width) || j >= f64::from(info.height) {
        return None;
    }
    Some(j as usize * info.width as usize + i as usize)
}

/// The world point at the centre of the cell at `index` of `info`'s grid.
pub fn centre(info: &map::Info, index: usize) -> (f64, f64) {
    let r = f64::from(info.resolution);
    let w = info.width.max(1) as usize;
    let (i, j) = ((index % w) as f64, (index / w) as f64);
    (info.origin.x + (i + 0.5) * r, info.origin.y + (j + 0.5) * r)
}

/// A map tile whose cell count does not match its size.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("map tile {width}x{height} at ({col}, {row}) has {cells} cells, expected {expected}")]
pub struct TileError {
    /// Columns the tile says it has.
    pub width: u32,
    /// Rows the tile says it has.
    pub height: u32,
    /// Its first column.
    pub col: u32,
    /// Its first row.
    pub row: u32,
    /// Cells it carries.
    pub cells: usize,
    /// Cells its size calls for.
    pub expected: usize,
}

/// A grid of cells (-1 free, 0 unknown, +1 occupied), row 0 at the bottom
/// (the map's origin), as Player's map interface lays them out.
#[derive(Debug, Clone, PartialEq)]
pub struct OccMap {
    /// Size, resolution and origin.
    pub info: map::Info,
    /// `width * height` cells, row-major from the origin.
    pub cells: Vec<i8>,
}

impl OccMap {
    /// A map of `info`'s size with every cell `value`.
    pub fn filled(info: map::Info, value: i8) -> Self {
        let n = info.width as usize * info.height as usize;
        OccMap {
            info,
            cells: vec![value; n],
        }
    }

    /// A map of `info`'s size whose cell at column `i`, row `j` is `cell(i, j)`.
    pub fn from_fn(info: map::Info, mut cell: impl FnMut(usize, usize) -> i8) -> Self {
        let (w, h) = (info.width as usize, info.height as usize);
        let cells = (0..w * h).map(|k| cell(k % w, k / w)).collect();
        OccMap { info, cells }
    }

    /// A map of `info`'s size from `tile`, cells it does not cover unknown.
    ///
    /// # Errors
    ///
    /// As [`OccMap::put_tile`].
    pub fn from_tile(info: map::Info, tile: &map::Data) -> Result<Self, TileError> {
        let mut m = OccMap::filled(info, UNKNOWN);
        m.put_tile(tile)?;
        Ok(m)
    }

    /// Cells along x and y.
    pub fn size(&self) -> (usize, usize) {
        (self.info.width as usize, self.info.height as usize)
    }

    /// Metres per cell.
    pub fn resolution(&self) -> f64 {
        f64::from(self.info.resolution)
    }

    /// The cell at column `i`, row `j`; `None` off the map.
    pub fn get(&self, i: i64, j: i64) -> Option<i8> {
        let (w, h) = self.size();
        if i < 0 || j < 0 || i as usize >= w || j as usize >= h {
            return None;
        }
        Some(self.cells[j as usize * w + i as usize])
    }

    /// The index of the cell holding world point (x, y); `None` off the map.
    pub fn index_of(&self, x: f64, y: f64) -> Option<usize> {
        index_of(&self.info, x, y)
    }

    /// The world point at the centre of the cell at `index`.
    pub fn centre(&self, index: usize) -> (f64, f64) {
        centre(&self.info, index)
    }

    /// The tile at (`col`, `row`) of `width` × `height` cells, as a map
    /// `GET_DATA` reply; cells off the map are unknown (0), as Player's
    /// mapfile answers them. Returns the tile and how many cells were off.
    pub fn tile(&self, col: u32, row: u32, width: u32, height: u32) -> (map::Data, usize) {
        let mut cells = Vec::with_capacity(width as usize * height as usize);
        let mut off = 0;
        for j in 0..i64::from(height) {
            for i in 0..i64::from(width) {
                match self.get(i64::from(col) + i, i64::from(row) + j) {
                    Some(c) => cells.push(c),
                    None => {
                        off += 1;
                        cells.push(UNKNOWN);
                    }
                }
            }
        }
        let data = map::Data {
            col,
            row,
            width,
            height,
            cells,
        };
        (data, off)
    }

    /// Copies a tile received from a map device into place; cells outside
    /// the map are ignored.
    ///
    /// # Errors
    ///
    /// [`TileError`] when the tile's cell count does not match its size.
    pub fn put_tile(&mut self, tile: &map::Data) -> Result<(), TileError> {
        let expected = tile.width as usize * tile.height as usize;
        if tile.cells.len() != expected {
            return Err(TileError {
                width: tile.width,
                height: tile.height,
                col: tile.col,
                row: tile.row,
                cells: tile.cells.len(),
                expected,
            });
        }
        let (w, h) = self.size();
        for tj in 0..tile.height as usize {
            let j = tile.row as usize + tj;
            if j >= h {
                break;
            }
            for ti in 0..tile.width as usize {
                let i = tile.col as usize + ti;
                if i >= w {
                    break;
                }
                self.cells[j * w + i] = tile.cells[tj * tile.width as usize + ti];
            }
        }
        Ok(())
    }

    /// Metres from each cell's centre to the nearest obstacle cell's
    /// (state ≥ 0: occupied or unknown), 0 on obstacles; row-major. Exact
    /// Euclidean distance transform, linear in the cells.
    pub fn distance_field(&self) -> Vec<f32> {
        let (w, h) = self.size();
        const FAR: f64 = 1e12;
        let mut g: Vec<f64> = self
            .cells
            .iter()
            .map(|&c| if c >= 0 { 0.0 } else { FAR })
            .collect();
        let n = w.max(h);
        let (mut f, mut d) = (vec![0.0; n], vec![0.0; n]);
        let (mut v, mut z) = (vec![0usize; n], vec![0.0; n + 1]);
        if w > 0 && h > 0 {
            for i in 0..w {
                for j in 0..h {
                    f[j] = g[j * w + i];
                }
                edt_1d(&f[..h], &mut d[..h], &mut v, &mut z);
                for j in 0..h {
                    g[j * w + i] = d[j];
                }
            }
            for j in 0..h {
                f[..w].copy_from_slice(&g[j * w..(j + 1) * w]);
                edt_1d(&f[..w], &mut d[..w], &mut v, &mut z);
                g[j * w..(j + 1) * w].copy_from_slice(&d[..w]);
            }
        }
        let res = self.resolution();
        g.iter().map(|&s| (s.sqrt() * res) as f32).collect()
    }

    /// The centres of its occupied cells, world frame.
    pub fn occupied(&self) -> Vec<(f64, f64)> {
        (0..self.cells.len())
            .filter(|&k| self.cells[k] == OCCUPIED)
            .map(|k| centre(&self.info, k))
            .collect()
    }

    /// The world pose of the map's origin corner.
    pub fn origin(&self) -> Pose2d {
        self.info.origin
    }
}

/// Exact 1-D squared distance transform (Felzenszwalb & Huttenlocher) of `f`
/// into `d`, with scratch space `v`, `z`.
fn edt_1d(f: &[f64], d: &mut [f64], v: &mut [usize], z: &mut [f64]) {
    let n = f.len();
    let parabola = |q: usize, p: usize| {
        ((f[q] + (q * q) as f64) - (f[p] + (p * p) as f64)) / (2.0 * (q - p) as f64)
    };
    let mut k = 0;
    v[0] = 0;
    z[0] = f64::NEG_INFINITY;
    z[1] = f64::INFINITY;
    for q in 1..n {
        let mut s = parabola(q, v[k]);
        // z[0] is -inf, so this stops at k = 0.
        while s <= z[k] {
            k -= 1;
            s = parabola(q, v[k]);
        }
        k += 1;
        v[k] = q;
        z[k] = s;
        z[k + 1] = f64::INFINITY;
    }
    k = 0;
    for (q, out) in d.iter_mut().enumerate() {
        while z[k + 1] < q as f64 {
            k += 1;
        }
        let p = v[k];
        let dq = q as f64 - p as f64;
        *out = dq * dq + f[p];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn info(w: u32, h: u32) -> map::Info {
        map::Info {
            width: w,
            height: h,
            resolution: 0.5,
            origin: Pose2d::new(-1.0, -2.0, 0.0),
        }
    }

    #[test]
    fn world_and_cells_agree() {
        let m = OccMap::filled(info(4, 8), FREE);
        assert_eq!(m.index_of(-1.0, -2.0), Some(0));
        // Cell (1, 1).
        assert_eq!(m.index_of(-0.01, -1.49), Some(4 + 1));
        // Cell (-1, 4).
        assert_eq!(m.index_of(-1.01, 0.0), None);
        assert_eq!(m.centre(4 + 1), (-0.25, -1.25));
        assert_eq!(m.get(-1, 0), None);
        assert_eq!(m.get(3, 7), Some(FREE));
        assert_eq!(m.get(4, 7), None);
    }

    #[test]
    fn tiles_round_trip_and_clip() {
        let m = OccMap::from_fn(
            info(3, 2),
            |i, j| if (i, j) == (1, 1) { OCCUPIED } else { FREE },
        );
        assert_eq!(m.cells[4], OCCUPIED);
        let (t, off) = m.tile(1, 1, 3, 2);
        assert_eq!(off, 4);
        assert_eq!(t.cells, vec![OCCUPIED, FREE, 0, 0, 0, 0]);
        let mut n = OccMap::filled(info(3, 2), UNKNOWN);
        n.put_tile(&m.tile(0, 0, 3, 2).0).unwrap();
        assert_eq!(n, m);
        let bad = map::Data {
            width: 2,
            height: 2,
            cells: vec![0; 3],
            ..Default::default()
        };
        assert!(n
            .put_tile(&bad)
            .unwrap_err()
            .to_string()
            .contains("3 cells, expected 4"));
        // A tile hanging off the map writes only what is on it.
        n.put_tile(&map::Data {
            col: 2,
            row: 1,
            width: 2,
            height: 2,
            cells: vec![OCCUPIED; 4],
        })
        .unwrap();
        assert_eq!(n.get(2, 1), Some(OCCUPIED));
    }
}
