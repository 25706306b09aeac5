//! Check-then-parse framing over a byte stream.

use std::time::{Duration, Instant};

use crate::port::{LineError, Port};

/// What a [`Codec`] made of the front of the buffer.
#[derive(Debug, PartialEq, Eq)]
pub enum Decoded<F> {
    /// A whole frame, and how many bytes it took.
    Frame(F, usize),
    /// The buffer holds the start of a frame; wait for more bytes.
    Incomplete,
    /// The first `n` bytes are not a frame: drop them and look again.
    Skip(usize, Skipped),
}

/// Why bytes were skipped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Skipped {
    /// Bytes before a frame header: line noise, or the tail of a frame whose
    /// start was lost.
    Noise,
    /// A whole frame whose checksum did not match.
    Checksum,
    /// A header whose length or type cannot be right.
    Malformed,
    /// Bytes the protocol sends between frames (a lone acknowledgement):
    /// skipped without counting.
    Filler,
}

/// A device protocol's framing: finds one frame at the front of `buf`.
pub trait Codec {
    /// A decoded frame.
    type Frame;
    /// Looks at the front of `buf`: a frame, not enough bytes yet, or bytes
    /// to skip. Must not consume anything it is unsure of.
    fn decode(&mut self, buf: &[u8]) -> Decoded<Self::Frame>;
}

/// Counts of what a [`Framer`] saw.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct FrameStats {
    /// Frames decoded.
    pub frames: u64,
    /// Noise bytes skipped while looking for a header.
    pub noise: u64,
    /// Frames dropped for a bad checksum.
    pub checksum: u64,
    /// Headers dropped as malformed.
    pub malformed: u64,
}

/// Reads frames of codec `C` from a byte stream, resynchronising on noise.
#[derive(Debug)]
pub struct Framer<C> {
    codec: C,
    buf: Vec<u8>,
    /// What was seen so far.
    pub stats: FrameStats,
}

impl<C: Codec> Framer<C> {
    /// A framer with an empty buffer.
    pub fn new(codec: C) -> Self {
        Framer {
            codec,
            buf: Vec::with_capacity(4096),
            stats: FrameStats::default(),
        }
    }

    /// Appends received bytes.
    pub fn push(&mut self, bytes: &[u8]) {
        self.buf.extend_from_slice(bytes);
    }

    /// The codec, for protocols whose replies are framed by what was asked.
    pub fn codec_mut(&mut self) -> &mut C {
        &mut self.codec
    }

    /// Forgets buffered bytes (after a flush of the line, or a reconnect).
    pub fn clear(&mut self) {
        self.buf.clear();
    }

    /// Bytes buffered and not yet framed.
    pub fn buffered(&self) -> usize {
        self.buf.len()
    }

    /// The next whole frame in the buffer, skipping (and counting) anything
    /// that is not one. `None` when more bytes are needed.
    pub fn next_frame(&mut self) -> Option<C::Frame> {
        let mut used = 0;
        let mut out = None;
        while used < self.buf.len() {
            match self.codec.decode(&self.buf[used..]) {
                Decoded::Frame(f, n) => {
                    used += n;
                    self.stats.frames += 1;
                    out = Some(f);
                    break;
                }
                Decoded::Incomplete => break,
                Decoded::Skip(n, why) => {
                    let n = n.max(1);
                    used += n;
                    match why {
                        Skipped::Noise => self.stats.noise += n as u64,
                        Skipped::Checksum => {
                            self.stats.checksum += 1;
                            tracing::warn!(
                                checksum_errors = self.stats.checksum,
                                "bad checksum: frame dropped"
                            );
                        }
                        Skipped::Filler => {}
                        Skipped::Malformed => {
                            self.stats.malformed += 1;
                            tracing::debug!(
                                malformed = self.stats.malformed,
                                "malformed header skipped"
                            );
                        }
                    }
                }
            }
        }
        self.buf.drain(..used);
        out
    }

    /// Reads from `port` until a whole frame arrives or `timeout` passes
    /// (`Ok(None)`).
    ///
    /// # Errors
    ///
    /// [`LineError::Lost`] when the device goes away.
    pub fn read(
        &mut self,
        port: &mut Port,
        timeout: Duration,
    ) -> Result<Option<C::Frame>, LineError> {
        let deadline = Instant::now() + timeout;
        let mut chunk = [0u8; 1024];
        loop {
            if let Some(f) = self.next_frame() {
                return Ok(Some(f));
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(None);
            }
            let n = port.recv(&mut chunk, left)?;
            if n == 0 {
                return Ok(None);
            }
            self.push(&chunk[..n]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A toy codec: 0xAA, length, payload, xor checksum.
    struct Toy;
    impl Codec for Toy {
        type Frame = Vec<u8>;
        fn decode(&mut self, buf: &[u8]) -> Decoded<Vec<u8>> {
            let Some(start) = buf.iter().position(|&b| b == 0xAA) else {
                return Decoded::Skip(buf.len(), Skipped::Noise);
            };
            if start > 0 {
                return Decoded::Skip(start, Skipped::Noise);
            }
            let Some(&len) = buf.get(1) else {
                return Decoded::Incomplete;
            };
            let n = 2 + len as usize + 1;
            if buf.len() < n {
                return Decoded::Incomplete;
            }
            let body = &buf[2..n - 1];
            if body.iter().fold(0, |a, b| a ^ b) != buf[n - 1] {
                return Decoded::Skip(1, Skipped::Checksum);
            }
            Decoded::Frame(body.to_vec(), n)
        }
    }

    #[test]
    fn frames_survive_noise_split_reads_and_bad_checksums() {
        let mut f = Framer::new(Toy);
        f.push(&[1, 2, 0xAA, 2, 5]);
        assert_eq!(f.next_frame(), None);
        f.push(&[6, 3]);
        assert_eq!(f.next_frame(), Some(vec![5, 6]));
        assert_eq!(f.stats.noise, 2);
        // A bad checksum drops the frame; the next one is found.
        f.push(&[0xAA, 1, 7, 0, 0xAA, 1, 7, 7]);
        assert_eq!(f.next_frame(), Some(vec![7]));
        assert_eq!(f.stats.checksum, 1);
        assert_eq!(f.buffered(), 0);
    }
}
