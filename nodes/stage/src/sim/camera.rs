//! Stage's camera: the 2.5D world drawn in perspective from a model, as
//! Stage draws it with OpenGL, here by casting rays through the grid.

use super::*;

/// Stage's background (`glClearColor(0.7, 0.7, 0.8)`), where nothing is
/// drawn: the sky, and beyond the far clip.
pub const SKY: [u8; 3] = [179, 179, 204];
/// Stage's floor: white, under the world's extent.
pub const FLOOR: [u8; 3] = [255, 255, 255];

/// One image of a camera.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Image {
    /// Pixels across.
    pub width: u32,
    /// Pixels down.
    pub height: u32,
    /// R, G, B bytes, row 0 at the top, column 0 at the left.
    pub rgb: Vec<u8>,
    /// Each pixel's depth along the view's axis (what Stage reads back
    /// from its depth buffer), metres; the far clip where nothing is drawn.
    pub depth: Vec<f32>,
}

/// A pixel's ray: its heading on the floor (a unit vector), and per metre
/// across the floor, how far it climbs and how deep along the view's axis
/// it goes.
#[derive(Debug, Clone, Copy)]
struct Ray {
    heading: (f64, f64),
    slope: f64,
    depth_per_m: f64,
}

/// What a camera's rays need to know of the view and the world.
struct View {
    eye: (f64, f64),
    base: f64,
    range: (f64, f64),
    /// The floor's extent.
    floor: [f64; 4],
    /// The top of the highest body the camera may see.
    top: f64,
    /// The camera's robot (not drawn).
    own: usize,
}

impl View {
    /// What ray `ray` meets at the floor, if it goes down to it before
    /// `upto` metres across: the floor's white where there is floor within
    /// the clip planes, else the background.
    fn floor(&self, ray: &Ray, upto: f64) -> Option<([u8; 3], f64)> {
        if ray.slope >= 0.0 {
            return None;
        }
        let d = self.base / -ray.slope;
        if d > upto {
            return None;
        }
        let depth = d * ray.depth_per_m;
        let (x, y) = (
            self.eye.0 + ray.heading.0 * d,
            self.eye.1 + ray.heading.1 * d,
        );
        let [x0, y0, x1, y1] = self.floor;
        let under = (x0..=x1).contains(&x) && (y0..=y1).contains(&y);
        Some(if under && (self.range.0..=self.range.1).contains(&depth) {
            (FLOOR, depth)
        } else {
            (SKY, self.range.1)
        })
    }
}

impl Sim {
    /// What camera model `m` sees now (an empty frame for other models).
    ///
    /// # Behavior
    ///
    /// As Stage's camera: the eye at the camera's place and base height,
    /// heading as its robot (its parent) less `pan`, looking down by
    /// `tilt`; `fov` is the whole horizontal and vertical angle of a
    /// frustum from `range.0` to `range.1` (depth along the axis), drawn
    /// in `resolution` pixels. Every body is flat in its model's colour
    /// (Stage draws without lighting), sides and tops; the floor is white
    /// under the world's extent, the rest Stage's background. Unlike
    /// Stage, the camera's own robot is not drawn (Stage's near clip
    /// hides it from a camera on top), nor are edges outlined.
    ///
    /// The rays of a column (one ray per pixel of it when the view is
    /// tilted) are followed across the grid from body to body: at each,
    /// the pixels whose rays pass at a height the body spans take its
    /// colour, those that went down to the floor before it take the
    /// floor's, and the others go on; a column ends when every pixel is
    /// drawn, beyond the far clip, or climbing above the highest body.
    pub fn camera(&self, m: usize) -> Image {
        let Some(cfg) = self.world.models[m].camera else {
            return Image::default();
        };
        let (w, h) = cfg.resolution;
        let (wn, hn) = (w as usize, h as usize);
        let (g, base) = self.global_z(m);
        let heading = match self.frames[m].parent {
            Frame::ROOT => g.yaw,
            p => self.global(p as usize).yaw,
        };
        let own = self.root(m);
        let view = View {
            eye: (g.x, g.y),
            base,
            range: cfg.range,
            floor: self.extent,
            top: (0..self.looks.len())
                .filter(|&k| self.root(k) != own)
                .map(|k| self.looks[k].hi)
                .fold(0.0, f64::max),
            own,
        };
        let yaw = unit(heading - cfg.pantilt.0);
        let (sp, cp) = (-cfg.pantilt.1).sin_cos();
        let (tu, tv) = ((cfg.fov.0 / 2.0).tan(), (cfg.fov.1 / 2.0).tan());
        let ray = |col: usize, row: usize| {
            // The ray f - u·left + v·up in the camera's frame, f pitched
            // down by the tilt; image x runs from the left (the view's +y).
            let u = tu * (2.0 * (col as f64 + 0.5) / w as f64 - 1.0);
            let v = tv * (1.0 - 2.0 * (row as f64 + 0.5) / h as f64);
            let (fwd, up) = (cp - v * sp, sp + v * cp);
            let across = fwd.hypot(u);
            Ray {
                heading: turned(yaw, (fwd / across, -u / across)),
                slope: up / across,
                depth_per_m: 1.0 / across,
            }
        };
        let mut frame = Image {
            width: w,
            height: h,
            rgb: vec![0; wn * hn * 3],
            depth: vec![cfg.range.1 as f32; wn * hn],
        };
        let level = sp.abs() < 1e-12;
        let mut pixels: Vec<(usize, Ray)> = Vec::with_capacity(hn);
        for col in 0..wn {
            let mut paint = |row: usize, (color, depth): ([u8; 3], f64)| {
                let i = row * wn + col;
                frame.rgb[i * 3..i * 3 + 3].copy_from_slice(&color);
                frame.depth[i] = depth as f32;
            };
            if level {
                // Every pixel of a column heads the same way.
                pixels.extend((0..hn).map(|row| (row, ray(col, row))));
                self.trace(&view, &mut pixels, &mut paint);
            } else {
                for row in 0..hn {
                    pixels.push((row, ray(col, row)));
                    self.trace(&view, &mut pixels, &mut paint);
                }
            }
        }
        frame
    }

    /// Draws `pixels`, whose rays share a heading, and empties it (see
    /// [`Sim::camera`]).
    fn trace(
        &self,
        view: &View,
        pixels: &mut Vec<(usize, Ray)>,
        paint: &mut impl FnMut(usize, ([u8; 3], f64)),
    ) {
        let Some(&(_, first)) = pixels.first() else {
            return;
        };
        let (near, far) = view.range;
        let d2 = first.heading;
        let accept = |id: u16| self.root(usize::from(id) - 1) != view.own;
        // Horizontal metres to the far clip along the widest ray.
        let reach = pixels
            .iter()
            .map(|(_, r)| far / r.depth_per_m)
            .fold(0.0, f64::max);
        let step = self.world.resolution / 2.0;
        let mut from = 0.0;
        while !pixels.is_empty() && from < reach {
            let o = (view.eye.0 + d2.0 * from, view.eye.1 + d2.1 * from);
            let Some(hit) = self.cast(o, d2, (0.0, reach - from), None, accept, 0) else {
                break;
            };
            let d = from + hit.range;
            let k = usize::from(hit.id) - 1;
            let look = &self.looks[k];
            let color = self.colors[k].rgb8();
            pixels.retain(|&(row, ray)| {
                if let Some(drawn) = view.floor(&ray, d) {
                    paint(row, drawn);
                    return false;
                }
                let depth = d * ray.depth_per_m;
                let z = view.base + ray.slope * d;
                if depth > far || (z > view.top && ray.slope >= 0.0) {
                    // Beyond the far clip, or above everything and climbing.
                    paint(row, (SKY, far));
                    return false;
                }
                if depth >= near && look.spans(z) {
                    paint(row, (color, depth));
                    return false;
                }
                true
            });
            from = d + step;
        }
        for &(row, ray) in pixels.iter() {
            paint(row, view.floor(&ray, f64::INFINITY).unwrap_or((SKY, far)));
        }
        pixels.clear();
    }
}
