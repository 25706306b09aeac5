//! Bitmaps as obstacles: Stage's `bitmap "file.png"` and map images.

use std::path::Path;

/// Why a bitmap could not be used.
#[derive(Debug, thiserror::Error)]
pub enum BitmapError {
    /// The file could not be read or decoded.
    #[error("cannot load bitmap {path}: {reason}")]
    Load {
        /// The file.
        path: String,
        /// The decoder's reason.
        reason: String,
    },
}

/// A greyscale image, row 0 at the top as in the file.
#[derive(Debug, Clone)]
pub struct Bitmap {
    /// Pixels across.
    pub width: u32,
    /// Pixels down.
    pub height: u32,
    /// Luma, 0 = black, row-major from the top-left.
    pub luma: Vec<u8>,
}

/// A run of dark pixels merged into a rectangle, in pixels from the top-left.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rect {
    /// Left column.
    pub x: u32,
    /// Top row.
    pub y: u32,
    /// Columns.
    pub w: u32,
    /// Rows.
    pub h: u32,
}

impl Bitmap {
    /// Loads a PNG, PNM (PGM/PPM/PBM) or other image `image` can decode.
    ///
    /// # Errors
    ///
    /// [`BitmapError::Load`] naming the file and the decoder's reason.
    pub fn load(path: &Path) -> Result<Bitmap, BitmapError> {
        let img = image::open(path).map_err(|e| BitmapError::Load {
            path: path.display().to_string(),
            reason: e.to_string(),
        })?;
        let (width, height) = (img.width(), img.height());
        // Transparent pixels count as white, as Stage reads them.
        let over_white = |l: u32, a: u8| {
            let a = u32::from(a);
            ((l * a + 255 * (255 - a)) / 255) as u8
        };
        // Grey images (Stage's bitmaps are) are read as they are: through
        // `to_rgba8`, whose colour conversion works in floats, Stage's
        // hospital.png (3117 × 1189) took 31 ms of a 170 ms load.
        let luma = match img {
            image::DynamicImage::ImageLuma8(grey) => grey.into_raw(),
            image::DynamicImage::ImageLumaA8(grey) => grey
                .pixels()
                .map(|p| over_white(u32::from(p.0[0]), p.0[1]))
                .collect(),
            img => img
                .to_rgba8()
                .pixels()
                .map(|p| {
                    let [r, g, b, a] = p.0;
                    let l = (u32::from(r) * 299 + u32::from(g) * 587 + u32::from(b) * 114) / 1000;
                    over_white(l, a)
                })
                .collect(),
        };
        Ok(Bitmap {
            width,
            height,
            luma,
        })
    }

    /// Dark pixels (luma below `threshold`) as rectangles: horizontal runs,
    /// merged with identical runs on the rows below.
    pub fn dark_rects(&self, threshold: u8) -> Vec<Rect> {
        let mut out: Vec<Rect> = Vec::new();
        // Runs still growing downwards, by (x, w) → index in `out`.
        let mut open: std::collections::HashMap<(u32, u32), usize> =
            std::collections::HashMap::new();
        for y in 0..self.height {
            let row = &self.luma[(y * self.width) as usize..((y + 1) * self.width) as usize];
            let mut next = std::collections::HashMap::new();
            let mut x = 0;
            while x < self.width {
                if row[x as usize] >= threshold {
                    x += 1;
                    continue;
                }
                let start = x;
                while x < self.width && row[x as usize] < threshold {
                    x += 1;
                }
                let key = (start, x - start);
                match open.get(&key) {
                    Some(&k) => {
                        out[k].h += 1;
                        next.insert(key, k);
                    }
                    None => {
                        out.push(Rect {
                            x: start,
                            y,
                            w: x - start,
                            h: 1,
                        });
                        next.insert(key, out.len() - 1);
                    }
                }
            }
            open = next;
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A grey PNG, grey with alpha, and the same greys as RGB read alike
    /// (the grey ones straight, the RGB through the colour conversion); a
    /// transparent pixel reads white.
    #[test]
    fn grey_and_colour_images_read_alike() {
        let dir = std::env::temp_dir().join(format!("troupe-bitmap-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let greys: Vec<u8> = (0..=255).collect();
        let save = |name: &str, img: image::DynamicImage| {
            let path = dir.join(name);
            img.save(&path).unwrap();
            Bitmap::load(&path).unwrap()
        };
        let grey = save(
            "grey.png",
            image::GrayImage::from_raw(16, 16, greys.clone())
                .unwrap()
                .into(),
        );
        let rgb: Vec<u8> = greys.iter().flat_map(|&v| [v, v, v]).collect();
        let colour = save(
            "rgb.png",
            image::RgbImage::from_raw(16, 16, rgb).unwrap().into(),
        );
        assert_eq!(grey.luma, greys);
        assert_eq!(colour.luma, greys);
        // Half the pixels fully transparent, half opaque.
        let ga: Vec<u8> = greys
            .iter()
            .enumerate()
            .flat_map(|(i, &v)| [v, if i % 2 == 0 { 0 } else { 255 }])
            .collect();
        let alpha = save(
            "grey-alpha.png",
            image::GrayAlphaImage::from_raw(16, 16, ga).unwrap().into(),
        );
        let want: Vec<u8> = greys
            .iter()
            .enumerate()
            .map(|(i, &v)| if i % 2 == 0 { 255 } else { v })
            .collect();
        assert_eq!(alpha.luma, want);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn runs_merge_into_rectangles() {
        // 4×3: a 2×2 block at the left, a lone pixel at the right of row 2.
        let b = Bitmap {
            width: 4,
            height: 3,
            luma: vec![0, 0, 255, 255, 0, 0, 255, 255, 255, 255, 255, 0],
        };
        let r = b.dark_rects(128);
        assert_eq!(
            r,
            vec![
                Rect {
                    x: 0,
                    y: 0,
                    w: 2,
                    h: 2
                },
                Rect {
                    x: 3,
                    y: 2,
                    w: 1,
                    h: 1
                }
            ]
        );
    }

    #[test]
    fn a_missing_file_is_named() {
        let e = Bitmap::load(Path::new("/nonexistent/cave.png"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("/nonexistent/cave.png"), "{e}");
    }
}
