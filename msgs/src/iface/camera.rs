//! `camera`: images, as a camera driver publishes them.

use serde::{Deserialize, Serialize};

use crate::message;

/// [`Data::format`]: 8-bit greyscale.
pub const FORMAT_MONO8: u32 = 1;
/// [`Data::format`]: 16-bit greyscale (network byte order).
pub const FORMAT_MONO16: u32 = 2;
/// [`Data::format`]: 16-bit RGB 5-6-5.
pub const FORMAT_RGB565: u32 = 4;
/// [`Data::format`]: 24-bit RGB.
pub const FORMAT_RGB888: u32 = 5;
/// [`Data::compression`]: raw pixels.
pub const COMPRESS_RAW: u32 = 0;
/// [`Data::compression`]: a JPEG file's bytes.
pub const COMPRESS_JPEG: u32 = 1;

/// One image (`PLAYER_CAMERA_DATA_STATE`), rows packed byte-aligned.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Data {
    /// Pixels across.
    pub width: u32,
    /// Pixels down.
    pub height: u32,
    /// Bits per pixel.
    pub bpp: u32,
    /// [`FORMAT_MONO8`], [`FORMAT_MONO16`], [`FORMAT_RGB565`] or [`FORMAT_RGB888`].
    pub format: u32,
    /// For images of real values (depth), the divisor that recovers them
    /// from the integers (0: none).
    pub fdiv: u32,
    /// [`COMPRESS_RAW`] or [`COMPRESS_JPEG`].
    pub compression: u32,
    /// The pixels, or the compressed file.
    #[serde(with = "crate::bytes::u8s")]
    pub image: Vec<u8>,
}
message!(Data, "camera/data@1");

/// A [`Data`] read in place ([`crate::codec::decode_view`]): the image
/// borrowed from the payload, not copied. A 1 MB frame that came through
/// shared memory is read where the driver wrote it.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
pub struct DataView<'a> {
    /// Pixels across.
    pub width: u32,
    /// Pixels down.
    pub height: u32,
    /// Bits per pixel.
    pub bpp: u32,
    /// As [`Data::format`].
    pub format: u32,
    /// As [`Data::fdiv`].
    pub fdiv: u32,
    /// As [`Data::compression`].
    pub compression: u32,
    /// The pixels, or the compressed file.
    pub image: &'a [u8],
}

impl<'a> crate::codec::View<'a> for DataView<'a> {
    type Owned = Data;
}

impl DataView<'_> {
    /// The message, its image copied.
    pub fn to_data(&self) -> Data {
        Data {
            width: self.width,
            height: self.height,
            bpp: self.bpp,
            format: self.format,
            fdiv: self.fdiv,
            compression: self.compression,
            image: self.image.to_vec(),
        }
    }
}
