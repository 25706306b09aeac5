//! Player's `cameracompress`: a camera's images, compressed to JPEG.
//!
//! ```text
//! driver ( name "cameracompress" requires ["camera:0"] provides ["camera:1"] )
//! ```
//!
//! | | |
//! |---|---|
//! | requires | one `camera` |
//! | provides | one `camera` |
//! | option `image_quality` | float in (0, 1], default 0.8: the JPEG quality, × 100 |
//! | option `check_timestamps` | 0/1, default 0: skip an image stamped as the one before |
//! | option `save` | 0/1, default 0: also write each JPEG to `click-NNNN.jpeg` in the working directory |
//!
//! # Behavior
//!
//! As Player's driver:
//! - each raw image becomes a colour JPEG (`compression` 1) stamped as
//!   the image it came from, 24 bits per pixel, format RGB888, the same
//!   size and `fdiv`: 8-bit images are grey in all three colours, 24-bit
//!   ones are taken as R, G, B, and 32-bit ones lose their fourth byte;
//!   16-bit images (MONO16, RGB565) are not compressed (a warning says so
//!   once, with how many were dropped when the driver stops);
//! - an image already compressed goes out as it came;
//! - an image of no pixels (0 wide or high) repeats the last JPEG;
//! - requests go to the camera, and its answers back.
//!
//! Player's `request_only` (compress only when asked for an image) needs
//! the camera's `GET_IMAGE` request, which Troupe does not carry: the
//! option is refused with that reason.
//!
//! Clients decompress with `playerc_camera_decompress`, as under Player.

use std::collections::HashMap;
use std::path::PathBuf;

use serde::Deserialize;
use troupe_msgs::{camera, Device, Interface};
use troupe_node::{Ctx, Driver, Event, NodeError, RequestId, Responder, Result, Section, Switch};

/// Options of the cameracompress driver (Player's names).
#[derive(Debug, Clone, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Options {
    /// JPEG quality in (0, 1].
    pub image_quality: f64,
    /// Skips an image stamped as the one before it.
    pub check_timestamps: Option<Switch>,
    /// Writes each JPEG to `click-NNNN.jpeg`.
    pub save: Option<Switch>,
    /// Player's: compress only on request (refused, see the crate's docs).
    pub request_only: Option<Switch>,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            image_quality: 0.8,
            check_timestamps: None,
            save: None,
            request_only: None,
        }
    }
}

/// The cameracompress driver.
pub struct CameraCompress {
    input: Device,
    output: Device,
    /// JPEG quality, 1–100.
    quality: u8,
    check_timestamps: bool,
    save: bool,
    /// The last image's stamp.
    last_stamp: Option<f64>,
    /// The last JPEG sent, and its stamp.
    last: Option<(camera::Data, f64)>,
    /// Images written by `save`.
    saved: u32,
    /// Images of a depth that cannot be compressed, by depth.
    dropped: HashMap<u32, u64>,
    /// Requests waiting for the camera's answer.
    pending: HashMap<RequestId, Responder>,
}

impl Driver for CameraCompress {
    const NAME: &'static str = "cameracompress";
    type Options = Options;

    fn new(section: &Section, o: Options) -> Result<Self> {
        let err = |m: String| NodeError::config(Self::NAME, m);
        if !(o.image_quality > 0.0 && o.image_quality <= 1.0) {
            return Err(err(format!(
                "option `image_quality` must be in (0, 1] (Player's 0.8 is JPEG quality 80), got {}",
                o.image_quality
            )));
        }
        if o.request_only.is_some_and(Switch::on) {
            return Err(err(
                "option `request_only` needs the camera's GET_IMAGE request, which Troupe's camera devices do not carry yet; leave it out to compress every image".into(),
            ));
        }
        Ok(CameraCompress {
            input: section.required_one(Interface::Camera, None)?,
            output: section.provided_one(Interface::Camera, None)?,
            quality: (o.image_quality * 100.0).round().clamp(1.0, 100.0) as u8,
            check_timestamps: o.check_timestamps.is_some_and(Switch::on),
            save: o.save.is_some_and(Switch::on),
            last_stamp: None,
            last: None,
            saved: 0,
            dropped: HashMap::new(),
            pending: HashMap::new(),
        })
    }

    fn setup(&mut self, ctx: &mut Ctx) -> Result<()> {
        ctx.subscribe(&self.input)
    }

    fn on_event(&mut self, ctx: &mut Ctx, event: Event) -> Result<()> {
        match event {
            Event::Data(s) if s.is::<camera::Data>() => {
                let d = s.decode::<camera::Data>()?;
                self.image(ctx, d.msg, d.stamp)
            }
            Event::Data(s) => Err(s.unexpected()),
            Event::Request(r) => {
                let payload = r.sample.payload().to_bytes().into_owned();
                let id = ctx.forward_request(&self.input, &r.name, payload)?;
                self.pending.insert(id, r.responder);
                Ok(())
            }
            Event::Reply(reply) => {
                if let Some(resp) = self.pending.remove(&reply.id) {
                    resp.forward(reply.result);
                }
                Ok(())
            }
            Event::Command(_) | Event::Tick | Event::Wake => Ok(()),
        }
    }

    fn shutdown(&mut self, _ctx: &mut Ctx) -> Result<()> {
        let mut dropped: Vec<(u32, u64)> = self.dropped.drain().collect();
        dropped.sort_unstable();
        for (bpp, n) in dropped {
            tracing::warn!(
                "{n} images of {bpp} bits per pixel were not compressed (8, 24 and 32 are)"
            );
        }
        Ok(())
    }
}

impl CameraCompress {
    fn image(&mut self, ctx: &mut Ctx, img: camera::Data, stamp: f64) -> Result<()> {
        if self.check_timestamps && self.last_stamp == Some(stamp) {
            return Ok(());
        }
        self.last_stamp = Some(stamp);
        if img.compression != camera::COMPRESS_RAW {
            return ctx.publish_at(&self.output, &img, stamp);
        }
        if img.width == 0 || img.height == 0 {
            if let Some((last, at)) = &self.last {
                ctx.publish_at(&self.output, last, *at)?;
            }
            return Ok(());
        }
        let Some(rgb) = rgb(&img) else {
            let n = self.dropped.entry(img.bpp).or_insert(0);
            if *n == 0 {
                tracing::warn!(
                    "{}: images of {} bits per pixel are not compressed (8, 24 and 32 are, or {} x {} pixels did not fit in {} bytes); they are dropped",
                    self.input,
                    img.bpp,
                    img.width,
                    img.height,
                    img.image.len()
                );
            }
            *n += 1;
            return Ok(());
        };
        let jpeg = match compress(&rgb, img.width, img.height, self.quality) {
            Ok(jpeg) => jpeg,
            Err(e) => {
                // (Only sizes no JPEG holds: the next image may fit.)
                tracing::warn!(
                    "{}: a {} x {} image was not compressed: {e}",
                    self.input,
                    img.width,
                    img.height
                );
                return Ok(());
            }
        };
        if self.save {
            self.write(&jpeg);
        }
        let out = camera::Data {
            width: img.width,
            height: img.height,
            bpp: 24,
            format: camera::FORMAT_RGB888,
            fdiv: img.fdiv,
            compression: camera::COMPRESS_JPEG,
            image: jpeg,
        };
        ctx.publish_at(&self.output, &out, stamp)?;
        self.last = Some((out, stamp));
        Ok(())
    }

    /// Writes `click-NNNN.jpeg`, as Player's `save` does; a failure is
    /// said and the images still go out.
    fn write(&mut self, jpeg: &[u8]) {
        let path = PathBuf::from(format!("click-{:04}.jpeg", self.saved));
        self.saved += 1;
        if let Err(e) = std::fs::write(&path, jpeg) {
            tracing::warn!("cannot write {}: {e}", path.display());
        }
    }
}

/// A raw image's pixels as R, G, B bytes, if its depth is one Player's
/// driver compresses and its bytes hold its pixels.
pub fn rgb(img: &camera::Data) -> Option<Vec<u8>> {
    let n = img.width as usize * img.height as usize;
    let px = img.image.get(..n * (img.bpp as usize / 8))?;
    match img.bpp {
        8 => Some(px.iter().flat_map(|&g| [g, g, g]).collect()),
        24 => Some(px.to_vec()),
        32 => Some(
            px.chunks_exact(4)
                .flat_map(|p| [p[0], p[1], p[2]])
                .collect(),
        ),
        _ => None,
    }
}

/// `rgb` (`width` × `height` pixels, top row first) as a baseline JPEG of
/// `quality` (1–100).
///
/// # Errors
///
/// The encoder's, for sizes a JPEG cannot hold (over 65535 pixels a side).
pub fn compress(rgb: &[u8], width: u32, height: u32, quality: u8) -> image::ImageResult<Vec<u8>> {
    let mut out = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, quality).encode(
        rgb,
        width,
        height,
        image::ExtendedColorType::Rgb8,
    )?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use troupe_node::testing::Harness;

    const SECTION: &str =
        r#"{"name":"cameracompress","requires":["camera:0"],"provides":["camera:1"]}"#;

    fn dev(i: u32) -> Device {
        Device::new(6665, Interface::Camera, i)
    }

    /// A 16 x 8 image: left half red, right half blue.
    fn halves(bpp: u32) -> camera::Data {
        let (w, h) = (16u32, 8u32);
        let mut image = Vec::new();
        for _ in 0..h {
            for x in 0..w {
                let p: [u8; 4] = if x < w / 2 {
                    [255, 0, 0, 9]
                } else {
                    [0, 0, 255, 9]
                };
                match bpp {
                    8 => image.push(if x < w / 2 { 200 } else { 40 }),
                    24 => image.extend_from_slice(&p[..3]),
                    _ => image.extend_from_slice(&p),
                }
            }
        }
        camera::Data {
            width: w,
            height: h,
            bpp,
            format: if bpp == 8 {
                camera::FORMAT_MONO8
            } else {
                camera::FORMAT_RGB888
            },
            fdiv: 0,
            compression: camera::COMPRESS_RAW,
            image,
        }
    }

    fn decode(d: &camera::Data) -> image::RgbImage {
        image::load_from_memory_with_format(&d.image, image::ImageFormat::Jpeg)
            .unwrap()
            .to_rgb8()
    }

    #[test]
    fn raw_images_go_out_as_colour_jpegs_with_their_stamps() {
        let mut h = Harness::<CameraCompress>::from_json(SECTION).unwrap();
        for bpp in [24, 32, 8] {
            h.set_time(12.5);
            h.input(dev(0), &halves(bpp)).unwrap();
        }
        let out = h.published_at::<camera::Data>(dev(1));
        assert_eq!(out.len(), 3);
        for (o, bpp) in out.iter().zip([24, 32, 8]) {
            let d = &o.1;
            assert_eq!(o.0, 12.5);
            assert_eq!(
                (d.width, d.height, d.bpp, d.format, d.compression),
                (16, 8, 24, camera::FORMAT_RGB888, camera::COMPRESS_JPEG),
                "from {bpp} bits"
            );
            let img = decode(d);
            assert_eq!(img.dimensions(), (16, 8));
            let (l, r) = (img.get_pixel(2, 4).0, img.get_pixel(13, 4).0);
            if bpp == 8 {
                assert!(l[0].abs_diff(200) < 8 && l[0].abs_diff(l[2]) < 8, "{l:?}");
                assert!(r[0].abs_diff(40) < 8, "{r:?}");
            } else {
                assert!(l[0] > 230 && l[2] < 30, "red: {l:?}");
                assert!(r[2] > 230 && r[0] < 30, "blue: {r:?}");
            }
        }
    }

    #[test]
    fn compressed_images_pass_and_empty_ones_repeat_the_last() {
        let mut h = Harness::<CameraCompress>::from_json(SECTION).unwrap();
        let jpeg = camera::Data {
            compression: camera::COMPRESS_JPEG,
            image: vec![0xFF, 0xD8, 1, 2],
            ..halves(24)
        };
        h.set_time(1.0);
        h.input(dev(0), &jpeg).unwrap();
        h.set_time(2.0);
        h.input(dev(0), &camera::Data::default()).unwrap();
        let out = h.published_at::<camera::Data>(dev(1));
        assert_eq!(out[0].1, jpeg, "already compressed: as it came");
        assert_eq!(out.len(), 1, "nothing sent yet to repeat");
        h.set_time(3.0);
        h.input(dev(0), &halves(24)).unwrap();
        h.set_time(4.0);
        h.input(dev(0), &camera::Data::default()).unwrap();
        let out = h.published_at::<camera::Data>(dev(1));
        assert_eq!(out.len(), 3);
        assert_eq!(out[2].1, out[1].1);
        assert_eq!(out[2].0, 3.0);
    }

    #[test]
    fn images_it_cannot_compress_are_dropped_and_counted() {
        let mut h = Harness::<CameraCompress>::from_json(
            r#"{"name":"cameracompress","requires":["camera:0"],"provides":["camera:1"],"options":{"check_timestamps":1}}"#,
        )
        .unwrap();
        let mono16 = camera::Data {
            bpp: 16,
            format: camera::FORMAT_MONO16,
            ..halves(24)
        };
        h.set_time(1.0);
        h.input(dev(0), &mono16).unwrap();
        let short = camera::Data {
            image: vec![1, 2, 3],
            ..halves(24)
        };
        h.set_time(2.0);
        h.input(dev(0), &short).unwrap();
        h.set_time(3.0);
        h.input(dev(0), &halves(24)).unwrap();
        h.set_time(3.0);
        h.input(dev(0), &halves(24)).unwrap();
        assert_eq!(h.published::<camera::Data>(dev(1)).len(), 1, "one, once");
    }

    #[test]
    fn bad_options_are_refused_with_reasons() {
        let e = |o: &str| {
            let j = format!(
                r#"{{"name":"cameracompress","requires":["camera:0"],"provides":["camera:1"],"options":{o}}}"#
            );
            Harness::<CameraCompress>::from_json(&j)
                .err()
                .unwrap()
                .to_string()
        };
        assert!(e(r#"{"image_quality":1.5}"#).contains("image_quality"));
        assert!(e(r#"{"request_only":1}"#).contains("GET_IMAGE"));
        let none = Harness::<CameraCompress>::from_json(
            r#"{"name":"cameracompress","provides":["camera:1"]}"#,
        );
        assert!(none.is_err());
    }
}
