//! Pictures of the world: a PNG of it as it stands, and a model's body as
//! an occupancy map (what `mapfile`-like devices of a model serve).

use super::*;

impl Sim {
    /// A picture of the world: obstacles grey, bodies in their colours,
    /// range readings as light rays, at most `max_px` pixels across.
    pub fn snapshot(&self, max_px: u32) -> image::RgbImage {
        let (w, h) = self.statics.lattice().size();
        let scale = (w.max(h) as f64 / f64::from(max_px.max(16))).max(1.0);
        let (iw, ih) = (
            ((w as f64) / scale).ceil() as u32,
            ((h as f64) / scale).ceil() as u32,
        );
        let mut img = image::RgbImage::from_pixel(iw, ih, image::Rgb([255, 255, 255]));
        let px = |i: usize, j: usize| {
            (
                (i as f64 / scale) as u32,
                ih - 1 - ((j as f64 / scale) as u32).min(ih - 1),
            )
        };
        let rgb = |c: Color| {
            image::Rgb([
                (c.r * 255.0) as u8,
                (c.g * 255.0) as u8,
                (c.b * 255.0) as u8,
            ])
        };
        // Rays first (of the rangers that sense: the others hold their
        // first, full-range readings), bodies over them.
        for (r, rd) in self.readings.iter().enumerate() {
            if rd.is_empty() || !self.sensed[r] {
                continue;
            }
            let base = self.global(r).compose(&self.world.models[r].origin);
            for (s, reading) in self.world.models[r].sensors.iter().zip(rd.iter()) {
                let o = base.compose(&s.pose);
                for (k, &range) in reading.ranges.iter().enumerate() {
                    let a = if s.samples > 1 {
                        o.yaw - s.fov / 2.0 + s.fov * k as f64 / (s.samples - 1) as f64
                    } else {
                        o.yaw
                    };
                    let end = (o.x + range * a.cos(), o.y + range * a.sin());
                    self.statics
                        .lattice()
                        .segment_cells((o.x, o.y), end, &mut |i, j| {
                            let (x, y) = px(i, j);
                            if x < iw {
                                img.put_pixel(x, y, image::Rgb([170, 210, 255]));
                            }
                        });
                }
            }
        }
        for j in 0..h {
            for i in 0..w {
                let c = self.statics.get(i, j);
                if c != EMPTY {
                    let (x, y) = px(i, j);
                    if x < iw {
                        img.put_pixel(x, y, rgb(self.colors[usize::from(c) - 1]));
                    }
                }
            }
        }
        let lat = *self.statics.lattice();
        for m in (0..self.world.models.len()).filter(|&m| self.movable[m]) {
            for p in self.movers.shapes(m) {
                lat.polygon_cells(p, |i, j| {
                    let (x, y) = px(i, j);
                    if x < iw {
                        img.put_pixel(x, y, rgb(self.colors[m]));
                    }
                });
            }
        }
        img
    }

    /// The occupancy map of model `m`'s body, as the Stage plugin's `map`
    /// device drew it: the model's `size` cut into cells of its
    /// `map_resolution`, a cell occupied where a block covers part of it,
    /// free elsewhere. The map's origin is the
    /// body's lower left corner at the model's current pose.
    ///
    /// # Errors
    ///
    /// A `map_resolution` that is not a positive number.
    pub fn model_map(&self, m: usize) -> Result<OccMap, SimError> {
        let d = &self.world.models[m];
        let res = d.map_resolution;
        if !(res > 0.0 && res.is_finite()) {
            return Err(SimError::MapResolution {
                pos: d.pos.to_string(),
                model: d.name.clone(),
                res,
            });
        }
        let (sx, sy) = (d.size[0], d.size[1]);
        let (w, h) = (
            ((sx / res).floor() as u32).max(1),
            ((sy / res).floor() as u32).max(1),
        );
        // The body's box in the model's frame (blocks have the origin applied).
        let (x0, y0) = (d.origin.x - sx / 2.0, d.origin.y - sy / 2.0);
        // Blocks are sampled at four points a cell along each axis, so a
        // cell is occupied when a block covers a sixteenth of it or so, and
        // an edge lying on a cell boundary does not spill into the next one.
        // Lattices are geometry only: no storage, however fine.
        const SUB: usize = 4;
        let (wc, hc) = (w as usize, h as usize);
        let fine = Lattice::of_cells(x0, y0, res / SUB as f64, wc * SUB, hc * SUB);
        let coarse = Lattice::of_cells(x0, y0, res, wc, hc);
        let mut cells = vec![FREE; wc * hc];
        for b in &d.blocks {
            let n = fine.polygon_centres(b, |i, j| cells[(j / SUB) * wc + i / SUB] = OCCUPIED);
            // A block thinner than that still shows, by its outline.
            if n == 0 {
                for k in 0..b.len() {
                    coarse.segment_cells(b[k], b[(k + 1) % b.len()], &mut |i, j| {
                        cells[j * wc + i] = OCCUPIED;
                    });
                }
            }
        }
        let corner = self.global(m).compose(&Pose::new(x0, y0, 0.0));
        Ok(OccMap {
            info: map::Info {
                width: w,
                height: h,
                resolution: res as f32,
                origin: corner.into(),
            },
            cells,
        })
    }
}
