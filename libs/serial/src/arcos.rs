//! The packet framing of ActivMedia's robot controllers (P2OS, ARCOS, and
//! the Videre Erratic's firmware), shared by the p2os and erratic drivers
//! and their emulators.
//!
//! ```text
//! 0xFA 0xFB N DATA… CK_HI CK_LO        N = data bytes + 2
//! ```
//! The checksum adds the data as big-endian 16-bit words (an odd last
//! byte is xored in) and is sent high byte first; integers inside the data
//! are little-endian. A command's data is `[cmd]` or `[cmd, argtype, lo,
//! hi]`, the argument type carrying the sign (0x3B positive, 0x1B negative).

use crate::{Codec, Decoded, Skipped};

/// The two header bytes.
pub const HEADER: [u8; 2] = [0xFA, 0xFB];
/// Largest count byte Player's driver can take.
pub const MAX_COUNT: u8 = 252;

/// Argument type of a positive (or zero) integer.
pub const ARGINT: u8 = 0x3B;
/// Argument type of a negative integer (the magnitude follows).
pub const ARGNINT: u8 = 0x1B;

/// The checksum of `data`.
pub fn checksum(data: &[u8]) -> u16 {
    let mut pairs = data.chunks_exact(2);
    let mut c: u16 = 0;
    for p in &mut pairs {
        c = c.wrapping_add(u16::from(p[0]) << 8 | u16::from(p[1]));
    }
    if let [last] = pairs.remainder() {
        c ^= u16::from(*last);
    }
    c
}

/// Frames `data` as a packet.
pub fn frame(data: &[u8]) -> Vec<u8> {
    let mut p = Vec::with_capacity(data.len() + 5);
    p.extend_from_slice(&HEADER);
    p.push((data.len() + 2) as u8);
    p.extend_from_slice(data);
    p.extend_from_slice(&checksum(data).to_be_bytes());
    p
}

/// A command without argument.
pub fn command(c: u8) -> Vec<u8> {
    frame(&[c])
}

/// A command with a signed integer argument.
pub fn command_int(c: u8, v: i32) -> Vec<u8> {
    let m = v.unsigned_abs().min(0xFFFF) as u16;
    let t = if v < 0 { ARGNINT } else { ARGINT };
    let [lo, hi] = m.to_le_bytes();
    frame(&[c, t, lo, hi])
}

/// Both controllers' CLOSE: stop the data stream and forget the client.
pub const CLOSE: u8 = 2;
/// Both controllers' STOP: wheels to zero.
pub const STOP: u8 = 29;

/// Player's goodbye to either controller (its `MainQuit`): STOP, then
/// CLOSE, logged either way.
pub fn stop_and_close(port: &mut crate::Port) {
    let stop = port.send(&command(STOP));
    let close = port.send(&command(CLOSE));
    match stop.and(close) {
        Ok(()) => tracing::info!("robot stopped and closed"),
        Err(e) => tracing::warn!("could not stop the robot: {e}"),
    }
}

/// The wheel-velocity command (VEL2) of both controllers.
pub const VEL2: u8 = 32;

/// VEL2 with wheel speeds in Vel2Divisor units (clamped to ±126).
pub fn vel2(right: i32, left: i32) -> Vec<u8> {
    let r = right.clamp(-126, 126) as i8 as u8;
    let l = left.clamp(-126, 126) as i8 as u8;
    frame(&[VEL2, ARGINT, r, l])
}

/// Wheel speeds (left, right) in mm/s for a forward `speed` (mm/s) and a
/// turn rate (deg/s), as Player's drivers compute them for VEL2: the
/// difference is `turn / diff_conv`; a wheel over `max_speed` is cut to it
/// and the other scaled alike; with `vel_band` the wheels never turn in
/// opposite directions (the weaker one stops).
pub fn wheels(speed: f64, turn_deg: f64, diff_conv: f64, max: f64, vel_band: bool) -> (f64, f64) {
    let rot = turn_deg.to_radians() / diff_conv;
    let (mut left, mut right) = (speed - rot, speed + rot);
    if left.abs() > max {
        right *= max / left.abs();
        left = max.copysign(left);
    }
    if right.abs() > max {
        left *= max / right.abs();
        right = max.copysign(right);
    }
    if vel_band && left * right < 0.0 {
        if left + right >= 0.0 {
            if left < 0.0 {
                left = 0.0;
            } else {
                right = 0.0;
            }
        } else if left > 0.0 {
            left = 0.0;
        } else {
            right = 0.0;
        }
    }
    (left, right)
}

/// A command's argument as a signed value (0 when it has none).
pub fn argument(data: &[u8]) -> i32 {
    match data {
        [_, t, lo, hi, ..] => {
            let m = i32::from(u16::from_le_bytes([*lo, *hi]));
            if *t == ARGNINT {
                -m
            } else {
                m
            }
        }
        _ => 0,
    }
}

/// Finds packets in a byte stream.
#[derive(Debug, Default, Clone, Copy)]
pub struct PacketCodec;

impl Codec for PacketCodec {
    /// The packet's data (type or command first), without header, count and checksum.
    type Frame = Vec<u8>;

    fn decode(&mut self, buf: &[u8]) -> Decoded<Vec<u8>> {
        let Some(start) = buf.windows(2).position(|w| w == HEADER) else {
            // Keep a trailing 0xFA: it may start the next header.
            let keep = usize::from(buf.last() == Some(&HEADER[0]));
            return match buf.len() - keep {
                0 => Decoded::Incomplete,
                n => Decoded::Skip(n, Skipped::Noise),
            };
        };
        if start > 0 {
            return Decoded::Skip(start, Skipped::Noise);
        }
        let Some(&n) = buf.get(2) else {
            return Decoded::Incomplete;
        };
        if !(3..=MAX_COUNT).contains(&n) {
            return Decoded::Skip(2, Skipped::Malformed);
        }
        let total = 3 + usize::from(n);
        if buf.len() < total {
            return Decoded::Incomplete;
        }
        let data = &buf[3..total - 2];
        let ck = u16::from_be_bytes([buf[total - 2], buf[total - 1]]);
        if checksum(data) != ck {
            return Decoded::Skip(2, Skipped::Checksum);
        }
        Decoded::Frame(data.to_vec(), total)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn checksums_add_big_endian_words_and_xor_an_odd_byte() {
        assert_eq!(frame(&[0x12]), vec![0xFA, 0xFB, 3, 0x12, 0x00, 0x12]);
        // 0x9A02 + 0x0002 + 0xFF03 wraps to 0x9907; the odd 0x30 is xored in.
        assert_eq!(
            checksum(&[0x9A, 0x02, 0x00, 0x02, 0xFF, 0x03, 0x30]),
            0x9937
        );
        assert_eq!(
            command_int(11, 300),
            vec![0xFA, 0xFB, 6, 0x0B, 0x3B, 0x2C, 0x01, 0x37, 0x3C]
        );
    }
}
