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
        // Transparent pixels count as white, as Stage reads them.
        let rgba = img.to_rgba8();
        let (width, height) = rgba.dimensions();
        let luma = rgba
            .pixels()
            .map(|p| {
                let [r, g, b, a] = p.0;
                let l = (u32::from(r) * 299 + u32::from(g) * 587 + u32::from(b) * 114) / 1000;
                let a = u32::from(a);
                ((l * a + 255 * (255 - a)) / 255) as u8
            })
            .collect();
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
