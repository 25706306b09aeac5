//! What a robot sees of others: the blobfinder's blobs and the fiducial
//! finder's fiducials, as Stage's models report them.

use super::*;

impl Sim {
    /// What blobfinder `m` sees now, as Stage's blobfinder and its Player
    /// plugin report it.
    ///
    /// # Behavior
    ///
    /// One ray per image column, from the right edge of the view leftwards,
    /// at every height (Stage does not test heights here) and stopped by
    /// anything outside the finder's robot. Runs of columns of one colour
    /// make a blob, which counts if its colour is tracked (any colour when
    /// none is given); as in Stage's loop, the column after a run is not
    /// looked at. A blob is drawn as a 0.6 m tall robot at its columns'
    /// mean range; rows are `fov / height` radians each. Player's plugin
    /// then takes the centre and area from the box's width and height less
    /// one each, and reports an empty image (0 x 0) when there is no blob.
    pub fn blobs(&self, m: usize) -> troupe_msgs::blobfinder::Data {
        use troupe_msgs::blobfinder::{Blob, Data};
        let Some(cfg) = &self.world.models[m].blobfinder else {
            return Data::default();
        };
        let (w, h) = cfg.image;
        let n = w as usize;
        let eye = self.global(m).compose(&self.world.models[m].origin);
        let root = self.root(m);
        let accept = |id: u16| self.root(usize::from(id) - 1) != root;
        let step = cfg.fov / n.saturating_sub(1).max(1) as f64;
        let samples: Vec<Option<(Color, f64)>> = (0..n)
            .map(|s| {
                let a = eye.yaw + cfg.pan - cfg.fov / 2.0 + s as f64 * step;
                self.cast((eye.x, eye.y), unit(a), (0.0, cfg.range), None, accept, 0)
                    .map(|hit| (self.colors[usize::from(hit.id) - 1], hit.range))
            })
            .collect();
        let same = |a: Color, b: Color| {
            (a.r - b.r).abs() < 1e-5 && (a.g - b.g).abs() < 1e-5 && (a.b - b.b).abs() < 1e-5
        };
        let rads_per_row = cfg.fov / f64::from(h);
        let half = i64::from(h / 2);
        let mut blobs = Vec::new();
        let mut s = 0;
        while s < n {
            let Some((col, _)) = samples[s] else {
                s += 1;
                continue;
            };
            let right = s;
            while s < n && samples[s].is_some_and(|(c, _)| same(c, col)) {
                s += 1;
            }
            let left = s - 1;
            s += 1;
            if !cfg.colors.is_empty() && !cfg.colors.iter().any(|&c| same(c, col)) {
                continue;
            }
            let run = &samples[right..=left];
            let range = run.iter().flatten().map(|x| x.1).sum::<f64>() / run.len() as f64;
            // Truncated as C's (int) cast truncates.
            let rows = ((0.3f64).atan2(range) / rads_per_row) as i64;
            let top = (half - rows).max(0);
            let bottom = (half + rows).min(i64::from(h));
            // Image columns run the other way: the right edge is column 0.
            let (bl, br) = ((n - 1 - left) as i64, (n - 1 - right) as i64);
            let (dx, dy) = (br - bl, top - bottom);
            let byte = |v: f32| u32::from((v.clamp(0.0, 1.0) * 255.0) as u8);
            let u = |v: i64| u32::try_from(v).unwrap_or(0);
            blobs.push(Blob {
                id: blobs.len() as u32,
                color: (byte(col.r) << 16) | (byte(col.g) << 8) | byte(col.b),
                area: u((dx * dy).abs()),
                x: u(bl + dx / 2),
                y: u(bottom + dy / 2),
                left: u(bl),
                right: u(br),
                top: u(top),
                bottom: u(bottom),
                range: range as f32,
            });
        }
        let (width, height) = if blobs.is_empty() { (0, 0) } else { (w, h) };
        Data {
            width,
            height,
            blobs,
        }
    }

    /// What fiducial detector `m` sees now.
    pub fn fiducials(&self, m: usize) -> troupe_msgs::fiducial::Data {
        use troupe_msgs::fiducial::{Data, Item};
        let Some(cfg) = &self.world.models[m].fiducial else {
            return Data::default();
        };
        let (g, z) = self.global_z(m);
        let eye = g.compose(&self.world.models[m].origin);
        let root = self.root(m);
        let mut items = Vec::new();
        for (k, target) in self.world.models.iter().enumerate() {
            if target.fiducial_return == 0 || self.root(k) == root {
                continue;
            }
            let rel = eye.inverse().compose(&self.global(k));
            let range = rel.x.hypot(rel.y);
            let bearing = rel.y.atan2(rel.x);
            if range < cfg.range_min || range > cfg.range_max || bearing.abs() > cfg.fov / 2.0 {
                continue;
            }
            // Seen only if the first thing the ray at the finder's height
            // meets is the target itself, as Stage traces it (out to the
            // finder's range): one below or above that height is not seen.
            let accept = |id: u16| {
                let o = usize::from(id) - 1;
                self.root(o) != root && self.spans(o, z)
            };
            let first = self.cast(
                (eye.x, eye.y),
                unit(eye.yaw + bearing),
                (0.0, cfg.range_max),
                Some(z),
                accept,
                0,
            );
            if first.is_none_or(|h| usize::from(h.id) - 1 != k) {
                continue;
            }
            let pose = troupe_msgs::Pose3d::planar(rel.x, rel.y, rel.yaw);
            items.push(Item {
                id: if range <= cfg.range_max_id {
                    target.fiducial_return
                } else {
                    -1
                },
                pose,
                upose: troupe_msgs::Pose3d::default(),
            });
        }
        Data { fiducials: items }
    }
}
