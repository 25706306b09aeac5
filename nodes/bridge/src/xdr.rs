//! XDR (RFC 4506) as Player's `playerxdrgen` writes it.
//!
//! Every integer is 4 bytes big-endian (`uint8_t` and `uint16_t` included),
//! `float` 4 and `double` 8. A variable array carries its count twice: the
//! struct's own `*_count` field, then `xdr_array`'s count. Byte arrays are
//! `xdr_bytes`: a count, the bytes, zero padding to a multiple of 4.

/// Why an XDR body could not be read.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum XdrError {
    /// The body ended inside a field.
    #[error("body ends at byte {len}, but a field at byte {at} needs {need} bytes")]
    Truncated {
        /// Offset of the field.
        at: usize,
        /// Bytes the field needs.
        need: usize,
        /// Length of the body.
        len: usize,
    },
    /// An array's count is larger than its struct count or than the body.
    #[error("array at byte {at} claims {count} elements; at most {max} fit")]
    BadCount {
        /// Offset of the count.
        at: usize,
        /// The count read.
        count: u32,
        /// The largest count that makes sense here.
        max: usize,
    },
    /// Bytes are left after the last field.
    #[error("{extra} unexpected bytes after the last field (body of {len} bytes)")]
    Trailing {
        /// Bytes left over.
        extra: usize,
        /// Length of the body.
        len: usize,
    },
}

/// Builds an XDR body.
#[derive(Debug, Default)]
pub struct Writer {
    buf: Vec<u8>,
}

impl Writer {
    /// An empty body.
    pub fn new() -> Self {
        Writer::default()
    }

    /// The bytes written.
    pub fn finish(self) -> Vec<u8> {
        self.buf
    }

    /// A `uint32_t` (also `uint8_t`, `uint16_t`: widened).
    pub fn u32(&mut self, v: u32) -> &mut Self {
        self.buf.extend_from_slice(&v.to_be_bytes());
        self
    }

    /// An `int32_t` (also `int8_t`, `int16_t`: widened).
    pub fn i32(&mut self, v: i32) -> &mut Self {
        self.buf.extend_from_slice(&v.to_be_bytes());
        self
    }

    /// A boolean as Player's `uint8_t` flag.
    pub fn flag(&mut self, v: bool) -> &mut Self {
        self.u32(u32::from(v))
    }

    /// A `float`.
    pub fn f32(&mut self, v: f32) -> &mut Self {
        self.buf.extend_from_slice(&v.to_be_bytes());
        self
    }

    /// A `double`.
    pub fn f64(&mut self, v: f64) -> &mut Self {
        self.buf.extend_from_slice(&v.to_be_bytes());
        self
    }

    /// A count for an array of `n` elements (lengths are bounded by Player's
    /// 8 MiB message limit, so they fit).
    fn count(&mut self, n: usize) -> &mut Self {
        self.u32(u32::try_from(n).unwrap_or(u32::MAX))
    }

    /// A variable byte array: its struct count, then `xdr_bytes`.
    pub fn bytes(&mut self, b: &[u8]) -> &mut Self {
        self.count(b.len()).xdr_bytes(b)
    }

    /// `xdr_bytes` alone: a count, the bytes, zero padding.
    pub fn xdr_bytes(&mut self, b: &[u8]) -> &mut Self {
        self.count(b.len());
        self.buf.extend_from_slice(b);
        let pad = (4 - b.len() % 4) % 4;
        self.buf.extend_from_slice(&[0; 3][..pad]);
        self
    }

    /// A string as libplayerc sends one: its bytes and a trailing NUL.
    pub fn string(&mut self, s: &str) -> &mut Self {
        let mut b = Vec::with_capacity(s.len() + 1);
        b.extend_from_slice(s.as_bytes());
        b.push(0);
        self.bytes(&b)
    }

    /// A variable array: its struct count, `xdr_array`'s count, the elements.
    pub fn array<T>(&mut self, items: &[T], mut each: impl FnMut(&mut Self, &T)) -> &mut Self {
        self.count(items.len()).count(items.len());
        for it in items {
            each(self, it);
        }
        self
    }
}

/// Reads an XDR body, front to back.
#[derive(Debug)]
pub struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    /// A reader at the start of `buf`.
    pub fn new(buf: &'a [u8]) -> Self {
        Reader { buf, pos: 0 }
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8], XdrError> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.buf.len());
        match end {
            Some(end) => {
                let s = &self.buf[self.pos..end];
                self.pos = end;
                Ok(s)
            }
            None => Err(XdrError::Truncated {
                at: self.pos,
                need: n,
                len: self.buf.len(),
            }),
        }
    }

    fn word(&mut self) -> Result<[u8; 4], XdrError> {
        let mut w = [0; 4];
        w.copy_from_slice(self.take(4)?);
        Ok(w)
    }

    /// A `uint32_t` (or a widened `uint8_t`/`uint16_t`).
    pub fn u32(&mut self) -> Result<u32, XdrError> {
        self.word().map(u32::from_be_bytes)
    }

    /// An `int32_t`.
    pub fn i32(&mut self) -> Result<i32, XdrError> {
        self.word().map(i32::from_be_bytes)
    }

    /// A `uint8_t` flag: anything but 0 is true, as in C.
    pub fn flag(&mut self) -> Result<bool, XdrError> {
        self.u32().map(|v| v != 0)
    }

    /// A `float`.
    pub fn f32(&mut self) -> Result<f32, XdrError> {
        self.word().map(f32::from_be_bytes)
    }

    /// A `double`.
    pub fn f64(&mut self) -> Result<f64, XdrError> {
        let mut w = [0; 8];
        w.copy_from_slice(self.take(8)?);
        Ok(f64::from_be_bytes(w))
    }

    /// The two counts of a variable array whose elements take at least
    /// `min_size` bytes each; the second (XDR's) may not exceed the first.
    fn counts(&mut self, min_size: usize) -> Result<usize, XdrError> {
        let _declared = self.u32()?;
        let at = self.pos;
        let count = self.u32()?;
        let max = (self.buf.len() - self.pos) / min_size.max(1);
        match usize::try_from(count) {
            Ok(n) if n <= max => Ok(n),
            _ => Err(XdrError::BadCount { at, count, max }),
        }
    }

    /// A variable byte array (struct count + `xdr_bytes`).
    pub fn bytes(&mut self) -> Result<&'a [u8], XdrError> {
        let _declared = self.u32()?;
        self.xdr_bytes()
    }

    /// `xdr_bytes` alone: a count, the bytes, zero padding.
    pub fn xdr_bytes(&mut self) -> Result<&'a [u8], XdrError> {
        let at = self.pos;
        let count = self.u32()?;
        let n = usize::try_from(count)
            .ok()
            .filter(|&n| n <= self.buf.len() - self.pos)
            .ok_or(XdrError::BadCount {
                at,
                count,
                max: self.buf.len() - self.pos,
            })?;
        let b = self.take(n)?;
        self.take((4 - n % 4) % 4)?;
        Ok(b)
    }

    /// A string: the bytes up to the first NUL, lossily as UTF-8.
    pub fn string(&mut self) -> Result<String, XdrError> {
        let b = self.bytes()?;
        let end = b.iter().position(|&c| c == 0).unwrap_or(b.len());
        Ok(String::from_utf8_lossy(&b[..end]).into_owned())
    }

    /// A variable array of elements at least `min_size` bytes long.
    pub fn array<T>(
        &mut self,
        min_size: usize,
        mut each: impl FnMut(&mut Self) -> Result<T, XdrError>,
    ) -> Result<Vec<T>, XdrError> {
        let n = self.counts(min_size)?;
        (0..n).map(|_| each(self)).collect()
    }

    /// Checks that the whole body was read.
    pub fn end(&self) -> Result<(), XdrError> {
        match self.buf.len() - self.pos {
            0 => Ok(()),
            extra => Err(XdrError::Trailing {
                extra,
                len: self.buf.len(),
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scalars_are_big_endian_words() {
        let mut w = Writer::new();
        w.u32(1).i32(-1).flag(true).f32(1.0).f64(-2.0);
        let b = w.finish();
        assert_eq!(
            b,
            [
                0, 0, 0, 1, 255, 255, 255, 255, 0, 0, 0, 1, 0x3f, 0x80, 0, 0, 0xc0, 0, 0, 0, 0, 0,
                0, 0
            ]
        );
        let mut r = Reader::new(&b);
        assert_eq!(r.u32().unwrap(), 1);
        assert_eq!(r.i32().unwrap(), -1);
        assert!(r.flag().unwrap());
        assert_eq!(r.f32().unwrap(), 1.0);
        assert_eq!(r.f64().unwrap(), -2.0);
        r.end().unwrap();
    }

    #[test]
    fn strings_count_their_nul_twice_and_pad() {
        // "r0" as libplayerc sends it: count 3, xdr count 3, "r0\0" + 1 pad.
        let mut w = Writer::new();
        w.string("r0");
        let b = w.finish();
        assert_eq!(b, [0, 0, 0, 3, 0, 0, 0, 3, b'r', b'0', 0, 0]);
        let mut r = Reader::new(&b);
        assert_eq!(r.string().unwrap(), "r0");
        r.end().unwrap();
    }

    #[test]
    fn arrays_carry_two_counts() {
        let mut w = Writer::new();
        w.array(&[1.5f64, 2.5], |w, v| {
            w.f64(*v);
        });
        let b = w.finish();
        assert_eq!(b.len(), 8 + 16);
        let mut r = Reader::new(&b);
        assert_eq!(r.array(8, |r| r.f64()).unwrap(), vec![1.5, 2.5]);
    }

    #[test]
    fn absurd_counts_and_short_bodies_are_errors_not_allocations() {
        let b = [0, 0, 0, 1, 0xff, 0xff, 0xff, 0xff];
        let e = Reader::new(&b).array(8, |r| r.f64()).unwrap_err();
        assert!(matches!(e, XdrError::BadCount { at: 4, .. }), "{e}");
        let e = Reader::new(&[0, 0]).u32().unwrap_err();
        assert_eq!(
            e.to_string(),
            "body ends at byte 2, but a field at byte 0 needs 4 bytes"
        );
        let mut r = Reader::new(&[0, 0, 0, 0, 1]);
        r.u32().unwrap();
        assert!(r.end().is_err());
    }
}
