//! An occupancy map as Player's map interface serves it: what mapfile loads
//! and what amcl and wavefront plan and localize on.

use troupe_msgs::{map, Pose2d};

/// Cell value: free.
pub const FREE: i8 = -1;
/// Cell value: unknown.
pub const UNKNOWN: i8 = 0;
/// Cell value: occupied.
pub const OCCUPIED: i8 = 1;

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

    /// The (column, row) holding world point (x, y); may be off the map.
    pub fn cell_of(&self, x: f64, y: f64) -> (i64, i64) {
        let r = self.resolution();
        let o = self.info.origin;
        (
            ((x - o.x) / r).floor() as i64,
            ((y - o.y) / r).floor() as i64,
        )
    }

    /// The world point at the centre of cell (i, j).
    pub fn centre_of(&self, i: i64, j: i64) -> (f64, f64) {
        let r = self.resolution();
        let o = self.info.origin;
        (o.x + (i as f64 + 0.5) * r, o.y + (j as f64 + 0.5) * r)
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
    /// The tile's cell count does not match its size.
    pub fn put_tile(&mut self, tile: &map::Data) -> Result<(), String> {
        let n = tile.width as usize * tile.height as usize;
        if tile.cells.len() != n {
            return Err(format!(
                "map tile {}x{} at ({}, {}) has {} cells, expected {n}",
                tile.width,
                tile.height,
                tile.col,
                tile.row,
                tile.cells.len()
            ));
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

    /// The world pose of the map's origin corner.
    pub fn origin(&self) -> Pose2d {
        self.info.origin
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
        assert_eq!(m.cell_of(-1.0, -2.0), (0, 0));
        assert_eq!(m.cell_of(-0.01, -1.49), (1, 1));
        assert_eq!(m.cell_of(-1.01, 0.0), (-1, 4));
        assert_eq!(m.centre_of(1, 1), (-0.25, -1.25));
        assert_eq!(m.get(-1, 0), None);
        assert_eq!(m.get(3, 7), Some(FREE));
        assert_eq!(m.get(4, 7), None);
    }

    #[test]
    fn tiles_round_trip_and_clip() {
        let mut m = OccMap::filled(info(3, 2), FREE);
        m.cells[4] = OCCUPIED; // (1, 1)
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
