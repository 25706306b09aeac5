//! The M3 board's serial line: commands to its two PMD 3410 motion chips
//! (axis 0 drives the right wheel, axis 1 the left) and their replies.
//!
//! A command is `[axis, checksum, 0x00, opcode, argument…]`: the argument
//! is 0, 2 or 4 bytes, big-endian, by opcode, and the checksum makes the
//! bytes sum to zero. A reply is `[status, checksum, data…]`, 0, 2 or 4
//! data bytes by opcode, summing to zero too. Status 0 or 1 is success;
//! any other is the chip's error code, and the driver reads no further
//! (Player's `ReadBuf`). The line runs at 416666 baud, 8N2.

use troupe_serial::{Codec, Decoded, Skipped};

/// The line's rate: the most the motion chips take (an FTDI adapter comes
/// as near as its divisor allows).
pub const BAUD: u32 = 416_666;

/// Opcodes Player's driver sends.
#[allow(missing_docs)]
pub mod op {
    pub const NOOP: u8 = 0x00;
    pub const SETPOS: u8 = 0x10;
    pub const SETVEL: u8 = 0x11;
    pub const UPDATE: u8 = 0x1A;
    pub const GETCMDPOS: u8 = 0x1D;
    pub const GETCMDVEL: u8 = 0x1E;
    pub const GETEVENTSTATUS: u8 = 0x31;
    pub const RESETEVENTSTATUS: u8 = 0x34;
    pub const GETACTUALPOS: u8 = 0x37;
    pub const RESET: u8 = 0x39;
    pub const SETACTUALPOS: u8 = 0x4D;
    pub const GETSAMPLETIME: u8 = 0x61;
    pub const SETPHASECOUNTS: u8 = 0x75;
    pub const SETMOTORCMD: u8 = 0x77;
    pub const SETLIMITSWITCHMODE: u8 = 0x80;
    pub const WRITEDIGITAL: u8 = 0x82;
    pub const READDIGITAL: u8 = 0x83;
    pub const GETVERSION: u8 = 0x8F;
    pub const SETACCEL: u8 = 0x90;
    pub const SETDECEL: u8 = 0x91;
    pub const SETPROFILEMODE: u8 = 0xA0;
    pub const GETACTUALVEL: u8 = 0xAD;
    pub const SETSTOPMODE: u8 = 0xD0;
    pub const SETMOTORMODE: u8 = 0xDC;
    pub const SETOUTPUTMODE: u8 = 0xE0;
    pub const READANALOG: u8 = 0xEF;
}

/// The right wheel's chip.
pub const RIGHT: u8 = 0;
/// The left wheel's chip (its motor turns the other way: the driver
/// negates what it sends and reads).
pub const LEFT: u8 = 1;

/// Profile modes.
pub const TRAPEZOIDAL: i32 = 0;
/// Velocity contouring: the wheel runs at the commanded velocity.
pub const VELOCITY_CONTOURING: i32 = 1;
/// The chip's "invalid instruction" status.
pub const INVALID_INSTRUCTION: u8 = 2;

/// Argument bytes of `opcode`, `None` for one the chips do not know.
pub fn arg_len(opcode: u8) -> Option<usize> {
    use op::*;
    Some(match opcode {
        NOOP | UPDATE | GETCMDPOS | GETCMDVEL | GETEVENTSTATUS | GETACTUALPOS | RESET
        | GETSAMPLETIME | GETVERSION | GETACTUALVEL => 0,
        RESETEVENTSTATUS | SETPHASECOUNTS | SETMOTORCMD | SETLIMITSWITCHMODE | READDIGITAL
        | SETPROFILEMODE | SETSTOPMODE | SETMOTORMODE | SETOUTPUTMODE | READANALOG => 2,
        SETPOS | SETVEL | SETACTUALPOS | WRITEDIGITAL | SETACCEL | SETDECEL => 4,
        _ => return None,
    })
}

/// Data bytes of the reply to `opcode`.
pub fn reply_len(opcode: u8) -> usize {
    use op::*;
    match opcode {
        GETCMDPOS | GETCMDVEL | GETACTUALPOS | GETACTUALVEL | GETVERSION => 4,
        GETSAMPLETIME | READANALOG | READDIGITAL | GETEVENTSTATUS => 2,
        _ => 0,
    }
}

/// `bytes` with byte 1 set so that all of them sum to zero.
fn seal(mut bytes: Vec<u8>) -> Vec<u8> {
    let sum = bytes.iter().fold(0u8, |s, b| s.wrapping_add(*b));
    bytes[1] = sum.wrapping_neg();
    bytes
}

/// The big-endian bytes of `v` in `n` bytes (0, 2 or 4).
fn be(v: i32, n: usize) -> Vec<u8> {
    v.to_be_bytes()[4 - n..].to_vec()
}

/// The signed value of big-endian `data` (2 or 4 bytes; 0 for none).
fn value(data: &[u8]) -> i32 {
    match *data {
        [a, b] => i32::from(i16::from_be_bytes([a, b])),
        [a, b, c, d] => i32::from_be_bytes([a, b, c, d]),
        _ => 0,
    }
}

/// A command to chip `axis`, its argument `arg` cut to the opcode's width
/// (none for an opcode the chips do not know).
pub fn command(axis: u8, opcode: u8, arg: i32) -> Vec<u8> {
    let mut out = vec![axis, 0, 0, opcode];
    out.extend(be(arg, arg_len(opcode).unwrap_or(0)));
    seal(out)
}

/// A successful reply carrying `v` in `reply_len(opcode)` bytes.
pub fn reply(opcode: u8, v: i32) -> Vec<u8> {
    let mut out = vec![0, 0];
    out.extend(be(v, reply_len(opcode)));
    seal(out)
}

/// An error reply: the status and its checksum.
pub fn error_reply(status: u8) -> Vec<u8> {
    seal(vec![status, 0])
}

/// What Player prints for a chip's error status.
pub fn status_text(status: u8) -> &'static str {
    const TEXT: [&str; 15] = [
        "Success",
        "Reset",
        "Invalid Instruction",
        "Invalid Axis",
        "Invalid Parameter",
        "Trace Running",
        "Flash",
        "Block Out of Bounds",
        "Trace buffer zero",
        "Bad checksum",
        "Not primary port",
        "Invalid negative value",
        "Invalid parameter change",
        "Limit event pending",
        "Invalid move into limit",
    ];
    TEXT.get(usize::from(status))
        .copied()
        .unwrap_or("unknown error")
}

/// A command as a chip reads it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Command {
    /// The chip: [`RIGHT`] or [`LEFT`].
    pub axis: u8,
    /// What to do.
    pub opcode: u8,
    /// Its argument, sign-extended (0 when it has none).
    pub arg: i32,
    /// The opcode is not one the chips know.
    pub unknown: bool,
}

/// The chips' side: commands from the driver.
#[derive(Debug, Default)]
pub struct CommandCodec;

impl Codec for CommandCodec {
    type Frame = Command;

    fn decode(&mut self, buf: &[u8]) -> Decoded<Command> {
        if buf.is_empty() {
            return Decoded::Incomplete;
        }
        if buf[0] > LEFT || buf.get(2).is_some_and(|&b| b != 0) {
            return Decoded::Skip(1, Skipped::Noise);
        }
        let Some(&opcode) = buf.get(3) else {
            return Decoded::Incomplete;
        };
        let (n, unknown) = match arg_len(opcode) {
            Some(a) => (4 + a, false),
            None => (4, true),
        };
        let Some(frame) = buf.get(..n) else {
            return Decoded::Incomplete;
        };
        if frame.iter().fold(0u8, |s, b| s.wrapping_add(*b)) != 0 {
            return Decoded::Skip(if unknown { 1 } else { n }, Skipped::Checksum);
        }
        Decoded::Frame(
            Command {
                axis: frame[0],
                opcode,
                arg: value(&frame[4..]),
                unknown,
            },
            n,
        )
    }
}

/// A chip's answer: its value, or its error status.
pub type Reply = Result<i32, u8>;

/// The driver's side: the reply to the command just sent, whose length
/// the driver sets before reading ([`ReplyCodec::expect`]).
#[derive(Debug, Default)]
pub struct ReplyCodec {
    data: usize,
}

impl ReplyCodec {
    /// The next reply answers `opcode`.
    pub fn expect(&mut self, opcode: u8) {
        self.data = reply_len(opcode);
    }
}

impl Codec for ReplyCodec {
    type Frame = Reply;

    fn decode(&mut self, buf: &[u8]) -> Decoded<Reply> {
        match buf.first() {
            None => Decoded::Incomplete,
            Some(&status) if status > 1 => Decoded::Frame(Err(status), 1),
            Some(_) => {
                let n = 2 + self.data;
                let Some(frame) = buf.get(..n) else {
                    return Decoded::Incomplete;
                };
                if frame.iter().fold(0u8, |s, b| s.wrapping_add(*b)) != 0 {
                    return Decoded::Skip(n, Skipped::Checksum);
                }
                Decoded::Frame(Ok(value(&frame[2..])), n)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_are_framed_as_players_send_cmd() {
        // sendCmd32(LEFT_MOTOR, SETVEL, -1): 01 cs 00 11 FF FF FF FF.
        let c = command(LEFT, op::SETVEL, -1);
        assert_eq!(c, [0x01, 0xF2, 0x00, 0x11, 0xFF, 0xFF, 0xFF, 0xFF]);
        assert_eq!(c.iter().fold(0u8, |s, b| s.wrapping_add(*b)), 0);
        // sendCmd16(1, READANALOG, 3) and sendCmd0(0, UPDATE).
        assert_eq!(command(1, op::READANALOG, 3), [1, 0x0D, 0, 0xEF, 0, 3]);
        assert_eq!(command(0, op::UPDATE, 0), [0, 0xE6, 0, 0x1A]);
        let mut codec = CommandCodec;
        let Decoded::Frame(got, 8) = codec.decode(&c) else {
            panic!("not a frame");
        };
        assert_eq!((got.axis, got.opcode, got.arg), (LEFT, op::SETVEL, -1));
        assert_eq!(codec.decode(&c[..5]), Decoded::Incomplete);
        let mut bad = c.clone();
        bad[5] ^= 1;
        assert_eq!(codec.decode(&bad), Decoded::Skip(8, Skipped::Checksum));
    }

    #[test]
    fn replies_carry_big_endian_values_or_a_status() {
        let r = reply(op::GETCMDPOS, -123_456);
        assert_eq!(r.len(), 6);
        let mut codec = ReplyCodec::default();
        codec.expect(op::GETCMDPOS);
        assert_eq!(codec.decode(&r), Decoded::Frame(Ok(-123_456), 6));
        codec.expect(op::READANALOG);
        assert_eq!(
            codec.decode(&reply(op::READANALOG, 0x7FC0)),
            Decoded::Frame(Ok(0x7FC0), 4)
        );
        assert_eq!(codec.decode(&error_reply(9)), Decoded::Frame(Err(9), 1));
        assert_eq!(status_text(9), "Bad checksum");
        let mut bad = reply(op::READANALOG, 5);
        bad[3] ^= 0x10;
        assert_eq!(codec.decode(&bad), Decoded::Skip(4, Skipped::Checksum));
    }
}
