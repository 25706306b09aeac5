//! Player 3's TCP framing: the banner, the 40-byte message header, message
//! types and the `player` interface's own subtypes.

use crate::xdr::{Reader, Writer, XdrError};

/// What the server sends first, NUL-padded to [`BANNER_LEN`] bytes.
/// libplayerc checks the `Player v.` prefix.
pub const BANNER: &str = "Player v.3.1.1-dev";
/// Length of the banner on the wire.
pub const BANNER_LEN: usize = 32;
/// Length of an encoded header.
pub const HEADER_LEN: usize = 40;
/// Player's limit on a whole message, header included (8 MiB).
pub const MAX_MESSAGE: usize = 8 * 1024 * 1024;

pub use troupe_msgs::protocol::{CMD, DATA, REQ, RESP_ACK, RESP_NACK, SYNCH};

/// Interface code of the `player` meta-device.
pub const PLAYER_CODE: u16 = 1;
/// The `player` meta-device's message subtypes, and the modes its
/// requests carry (`player.h`).
pub mod player {
    pub use troupe_msgs::protocol::player::*;

    /// `PLAYER_OPEN_MODE`.
    pub const OPEN: u32 = 1;
    /// `PLAYER_CLOSE_MODE`.
    pub const CLOSE: u32 = 2;
    /// `PLAYER_ERROR_MODE`.
    pub const ERROR: u32 = 3;
    /// `PLAYER_DATAMODE_PUSH`.
    pub const PUSH: u32 = 1;
    /// `PLAYER_DATAMODE_PULL`.
    pub const PULL: u32 = 2;
}

/// The 40-byte header of every message. XDR widens every field to 4 bytes;
/// the narrow C types (`uint16_t interf`, `uint8_t type`) are kept as read.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Header {
    /// The server's IPv4 address as `in_addr.s_addr` read little-endian.
    pub host: u32,
    /// The robot (port) of the device.
    pub robot: u32,
    /// Interface code.
    pub interf: u32,
    /// Device index.
    pub index: u32,
    /// Message type (DATA, CMD, REQ, …).
    pub kind: u32,
    /// Subtype, per interface.
    pub subtype: u32,
    /// Seconds.
    pub timestamp: f64,
    /// Sequence number (Player sends 0).
    pub seq: u32,
    /// Body length.
    pub size: u32,
}

impl Header {
    /// Appends the encoded header to `out`.
    pub fn write(&self, out: &mut Vec<u8>) {
        let mut w = Writer::new();
        w.u32(self.host)
            .u32(self.robot)
            .u32(self.interf)
            .u32(self.index)
            .u32(self.kind)
            .u32(self.subtype)
            .f64(self.timestamp)
            .u32(self.seq)
            .u32(self.size);
        out.extend_from_slice(&w.finish());
    }

    /// Decodes a header from the first [`HEADER_LEN`] bytes of `b`.
    pub fn read(b: &[u8]) -> Result<Header, XdrError> {
        let mut r = Reader::new(b);
        Ok(Header {
            host: r.u32()?,
            robot: r.u32()?,
            interf: r.u32()?,
            index: r.u32()?,
            kind: r.u32()?,
            subtype: r.u32()?,
            timestamp: r.f64()?,
            seq: r.u32()?,
            size: r.u32()?,
        })
    }
}

/// Why a byte stream cannot be split into messages.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    /// The header announces a body larger than Player allows.
    #[error("message of {size} bytes exceeds Player's limit of {MAX_MESSAGE} bytes")]
    Oversized {
        /// Header + announced body.
        size: u64,
    },
}

/// Check-then-parse framing: `Ok(None)` until a whole message is buffered,
/// then its header and total length.
pub fn frame(buf: &[u8]) -> Result<Option<(Header, usize)>, FrameError> {
    if buf.len() < HEADER_LEN {
        return Ok(None);
    }
    let Ok(h) = Header::read(&buf[..HEADER_LEN]) else {
        return Ok(None);
    };
    let total = HEADER_LEN as u64 + u64::from(h.size);
    if total > MAX_MESSAGE as u64 {
        return Err(FrameError::Oversized { size: total });
    }
    let total = total as usize;
    Ok((buf.len() >= total).then_some((h, total)))
}

/// Encodes a whole message: header (with `size` set from `body`) and body.
pub fn message(mut h: Header, body: &[u8]) -> Vec<u8> {
    h.size = u32::try_from(body.len()).unwrap_or(u32::MAX);
    let mut out = Vec::with_capacity(HEADER_LEN + body.len());
    h.write(&mut out);
    out.extend_from_slice(body);
    out
}

/// The banner bytes.
pub fn banner() -> [u8; BANNER_LEN] {
    let mut b = [0; BANNER_LEN];
    b[..BANNER.len()].copy_from_slice(BANNER.as_bytes());
    b
}

/// The `host` field for a server at `ip`, as Player computes it.
pub fn host_of(ip: std::net::IpAddr) -> u32 {
    match ip {
        std::net::IpAddr::V4(v4) => u32::from_le_bytes(v4.octets()),
        std::net::IpAddr::V6(v6) => v6
            .to_ipv4_mapped()
            .map_or(0, |v4| u32::from_le_bytes(v4.octets())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_round_trips_and_host_is_player_s() {
        let h = Header {
            host: host_of("127.0.0.1".parse().unwrap()),
            robot: 6665,
            interf: 4,
            index: 0,
            kind: u32::from(DATA),
            subtype: 1,
            timestamp: 5.8,
            seq: 0,
            size: 52,
        };
        assert_eq!(h.host, 16_777_343);
        let mut b = Vec::new();
        h.write(&mut b);
        assert_eq!(&b[..8], &[1, 0, 0, 0x7f, 0, 0, 0x1a, 0x09]);
        assert_eq!(Header::read(&b).unwrap(), h);
    }

    #[test]
    fn framing_waits_for_whole_messages_and_refuses_huge_ones() {
        let m = message(Header::default(), &[1, 2, 3, 4]);
        assert_eq!(frame(&m[..39]).unwrap(), None);
        assert_eq!(frame(&m[..43]).unwrap(), None);
        assert_eq!(frame(&m).unwrap().unwrap().1, 44);
        let mut big = m.clone();
        big[36..40].copy_from_slice(&(9u32 << 20).to_be_bytes());
        assert!(matches!(frame(&big), Err(FrameError::Oversized { .. })));
    }

    #[test]
    fn banner_is_nul_padded() {
        let b = banner();
        assert!(b.starts_with(b"Player v.3.1.1-dev\0"));
        assert_eq!(b[31], 0);
    }
}
