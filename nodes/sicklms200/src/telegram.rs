//! SICK LMS200 telegrams: framing, CRC and the messages Player's driver uses.
//!
//! ```text
//! STX(0x02) ADDR LEN(u16 LE) CMD DATA… [STATUS] CRC(u16 LE)
//! ```
//! `ADDR` is 0x00 toward the scanner and 0x80 from it; `LEN` counts `CMD`,
//! `DATA` and (in the scanner's replies) `STATUS`; the CRC covers every byte
//! before it. A reply's command byte is the request's with bit 7 set. The
//! scanner sends a lone ACK byte (0x06) before each reply; readers skip it.

use troupe_serial::{Codec, Decoded, Skipped};

/// Start of a telegram.
pub const STX: u8 = 0x02;
/// Address byte of telegrams toward the scanner.
pub const TO_DEVICE: u8 = 0x00;
/// Address byte of telegrams from the scanner.
pub const FROM_DEVICE: u8 = 0x80;
/// The byte the scanner sends before each reply it accepts.
pub const ACK_BYTE: u8 = 0x06;
/// The byte the scanner sends when it cannot parse a request.
pub const NAK_BYTE: u8 = 0x15;
/// The longest `LEN` the LMS200 sends or accepts (a 0.25° status telegram fits).
pub const MAX_LEN: usize = 812;

/// Request commands.
pub mod cmd {
    /// Change operating mode (argument: one of [`super::mode`]).
    pub const MODE: u8 = 0x20;
    /// Request status.
    pub const STATUS: u8 = 0x31;
    /// Request the type string.
    pub const TYPE: u8 = 0x3A;
    /// Set the scan variant (angle width and resolution).
    pub const VARIANT: u8 = 0x3B;
    /// Request the configuration.
    pub const GET_CONFIG: u8 = 0x74;
    /// Write the configuration.
    pub const SET_CONFIG: u8 = 0x77;
    /// Reply bit.
    pub const REPLY: u8 = 0x80;
    /// Scan data, all values (reply to continuous mode 0x24).
    pub const SCAN: u8 = 0xB0;
    /// Scan data, a segment (reply to continuous mode 0x27).
    pub const SCAN_PART: u8 = 0xB7;
    /// "Not acknowledged": the request was understood but refused.
    pub const NACK: u8 = 0x92;
}

/// Arguments of [`cmd::MODE`].
pub mod mode {
    /// Installation (configuration) mode; followed by the password.
    pub const CONFIG: u8 = 0x00;
    /// Continuous output of every value.
    pub const CONTINUOUS: u8 = 0x24;
    /// Stop continuous output.
    pub const STOP: u8 = 0x25;
    /// Continuous output of a segment `first..=last` (1-based, u16 LE each).
    pub const CONTINUOUS_PART: u8 = 0x27;
    /// Switch to 38400 baud.
    pub const BAUD_38400: u8 = 0x40;
    /// Switch to 19200 baud.
    pub const BAUD_19200: u8 = 0x41;
    /// Switch to 9600 baud.
    pub const BAUD_9600: u8 = 0x42;
    /// Switch to 500000 baud.
    pub const BAUD_500000: u8 = 0x48;
}

/// The mode byte that switches the scanner to `baud`.
pub fn baud_mode(baud: u32) -> Option<u8> {
    Some(match baud {
        9600 => mode::BAUD_9600,
        19200 => mode::BAUD_19200,
        38400 => mode::BAUD_38400,
        500000 => mode::BAUD_500000,
        _ => return None,
    })
}

/// The baud rate a mode byte switches to.
pub fn mode_baud(m: u8) -> Option<u32> {
    Some(match m {
        mode::BAUD_9600 => 9600,
        mode::BAUD_19200 => 19200,
        mode::BAUD_38400 => 38400,
        mode::BAUD_500000 => 500000,
        _ => return None,
    })
}

/// SICK's CRC-16 (generator 0x8005) as the LMS200 manual defines it: each
/// step shifts, folds in the polynomial on carry, and xors the current and
/// previous byte as a 16-bit word.
pub fn crc16(bytes: &[u8]) -> u16 {
    let mut crc: u16 = 0;
    let mut prev: u8 = 0;
    for &b in bytes {
        crc = if crc & 0x8000 != 0 {
            ((crc & 0x7fff) << 1) ^ 0x8005
        } else {
            crc << 1
        };
        crc ^= u16::from(b) | (u16::from(prev) << 8);
        prev = b;
    }
    crc
}

/// Frames `body` (command, data and — from the scanner — status) as a telegram.
pub fn frame(addr: u8, body: &[u8]) -> Vec<u8> {
    let mut t = Vec::with_capacity(body.len() + 6);
    t.push(STX);
    t.push(addr);
    t.extend_from_slice(&(body.len() as u16).to_le_bytes());
    t.extend_from_slice(body);
    let crc = crc16(&t);
    t.extend_from_slice(&crc.to_le_bytes());
    t
}

/// A request toward the scanner.
pub fn request(body: &[u8]) -> Vec<u8> {
    frame(TO_DEVICE, body)
}

/// A reply from the scanner: `cmd`, `data`, then `status`.
pub fn reply(cmd: u8, data: &[u8], status: u8) -> Vec<u8> {
    let mut body = Vec::with_capacity(data.len() + 2);
    body.push(cmd);
    body.extend_from_slice(data);
    body.push(status);
    frame(FROM_DEVICE, &body)
}

/// A decoded telegram: what lies between `LEN` and the CRC.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Telegram {
    /// The address byte.
    pub addr: u8,
    /// Command, data and (from the scanner) status.
    pub body: Vec<u8>,
}

impl Telegram {
    /// The command byte.
    pub fn cmd(&self) -> u8 {
        self.body.first().copied().unwrap_or(0)
    }

    /// The data of a scanner's reply: between command and status.
    pub fn reply_data(&self) -> &[u8] {
        match self.body.len() {
            0..=2 => &[],
            n => &self.body[1..n - 1],
        }
    }

    /// The data of a request: everything after the command.
    pub fn request_data(&self) -> &[u8] {
        self.body.get(1..).unwrap_or(&[])
    }
}

/// Finds telegrams in a byte stream; `addr` is the address accepted
/// ([`FROM_DEVICE`] in a driver, [`TO_DEVICE`] in an emulator).
#[derive(Debug, Clone, Copy)]
pub struct TelegramCodec {
    /// The address byte telegrams must carry.
    pub addr: u8,
}

impl Codec for TelegramCodec {
    type Frame = Telegram;

    fn decode(&mut self, buf: &[u8]) -> Decoded<Telegram> {
        match buf[0] {
            STX => {}
            // The scanner's ACK byte before each reply is not noise.
            ACK_BYTE => return Decoded::Skip(1, Skipped::Filler),
            _ => {
                let n = buf
                    .iter()
                    .position(|&b| b == STX || b == ACK_BYTE)
                    .unwrap_or(buf.len());
                return Decoded::Skip(n, Skipped::Noise);
            }
        }
        if buf.len() < 4 {
            return Decoded::Incomplete;
        }
        if buf[1] != self.addr {
            return Decoded::Skip(1, Skipped::Noise);
        }
        let len = usize::from(u16::from_le_bytes([buf[2], buf[3]]));
        if len == 0 || len > MAX_LEN {
            return Decoded::Skip(1, Skipped::Malformed);
        }
        let total = 4 + len + 2;
        if buf.len() < total {
            return Decoded::Incomplete;
        }
        let crc = u16::from_le_bytes([buf[total - 2], buf[total - 1]]);
        if crc16(&buf[..total - 2]) != crc {
            return Decoded::Skip(1, Skipped::Checksum);
        }
        Decoded::Frame(
            Telegram {
                addr: buf[1],
                body: buf[4..4 + len].to_vec(),
            },
            total,
        )
    }
}

/// One scan as the scanner sent it: 13 range bits and 3 flag bits per value.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RawScan {
    /// The values, first segment first.
    pub values: Vec<u16>,
    /// Range unit code from the telegram: 0 = cm, 1 = mm, 2 = 10 cm.
    pub units: u8,
    /// The scanner's status byte.
    pub status: u8,
}

/// Why a scan telegram was refused.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ScanError {
    /// Not a scan telegram.
    NotScan(u8),
    /// The value count does not match the telegram's length.
    Length {
        /// Values announced.
        count: usize,
        /// Bytes that hold values.
        bytes: usize,
    },
}

impl std::fmt::Display for ScanError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ScanError::NotScan(c) => write!(f, "telegram 0x{c:02X} is not scan data"),
            ScanError::Length { count, bytes } => write!(
                f,
                "scan telegram announces {count} values but carries {bytes} bytes of them"
            ),
        }
    }
}

/// Decodes a scan telegram (0xB0 all values, 0xB7 a segment).
///
/// # Errors
///
/// [`ScanError`] for another telegram or an inconsistent length.
pub fn decode_scan(t: &Telegram) -> Result<RawScan, ScanError> {
    let data = t.reply_data();
    let head = match t.cmd() {
        cmd::SCAN => 0,
        cmd::SCAN_PART => 4,
        c => return Err(ScanError::NotScan(c)),
    };
    let Some(word) = data.get(head..head + 2) else {
        return Err(ScanError::Length { count: 0, bytes: 0 });
    };
    let count = usize::from(word[0]) | (usize::from(word[1] & 0x3F) << 8);
    let values = &data[head + 2..];
    if values.len() != 2 * count {
        return Err(ScanError::Length {
            count,
            bytes: values.len(),
        });
    }
    Ok(RawScan {
        values: values
            .chunks_exact(2)
            .map(|v| u16::from_le_bytes([v[0], v[1]]))
            .collect(),
        units: word[1] >> 6,
        status: t.body.last().copied().unwrap_or(0),
    })
}

/// Encodes a full scan (0xB0) as the scanner sends it.
pub fn encode_scan(values: &[u16], units: u8, status: u8) -> Vec<u8> {
    let mut data = Vec::with_capacity(2 + 2 * values.len());
    let count = values.len() as u16 & 0x3FFF;
    data.extend_from_slice(&(count | (u16::from(units & 3) << 14)).to_le_bytes());
    for v in values {
        data.extend_from_slice(&v.to_le_bytes());
    }
    reply(cmd::SCAN, &data, status)
}

/// Encodes a segment scan (0xB7) of values `first..=last` (1-based).
pub fn encode_scan_part(first: u16, last: u16, values: &[u16], units: u8, status: u8) -> Vec<u8> {
    let mut data = Vec::with_capacity(6 + 2 * values.len());
    data.extend_from_slice(&first.to_le_bytes());
    data.extend_from_slice(&last.to_le_bytes());
    let count = values.len() as u16 & 0x3FFF;
    data.extend_from_slice(&(count | (u16::from(units & 3) << 14)).to_le_bytes());
    for v in values {
        data.extend_from_slice(&v.to_le_bytes());
    }
    reply(cmd::SCAN_PART, &data, status)
}

/// The configuration byte for a range resolution in mm (1, 10 or 100), as
/// Player writes it: 0x01 mm, 0x00 cm, 0x02 10 cm.
pub fn units_code(range_res_mm: u32) -> u8 {
    match range_res_mm {
        10 => 0x00,
        100 => 0x02,
        _ => 0x01,
    }
}

/// The range resolution in mm of a units code.
pub fn units_mm(code: u8) -> u32 {
    match code {
        0x00 => 10,
        0x02 => 100,
        _ => 1,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use troupe_serial::Framer;

    fn hex(s: &str) -> Vec<u8> {
        s.split_whitespace()
            .map(|b| u8::from_str_radix(b, 16).unwrap())
            .collect()
    }

    /// Telegrams as printed in SICK's LMS200 telegram listing.
    #[test]
    fn requests_match_the_manuals_bytes() {
        assert_eq!(request(&[0x20, 0x24]), hex("02 00 02 00 20 24 34 08"));
        assert_eq!(request(&[0x20, 0x25]), hex("02 00 02 00 20 25 35 08"));
        assert_eq!(request(&[0x20, 0x40]), hex("02 00 02 00 20 40 50 08"));
        assert_eq!(request(&[0x20, 0x42]), hex("02 00 02 00 20 42 52 08"));
        assert_eq!(request(&[0x20, 0x48]), hex("02 00 02 00 20 48 58 08"));
        assert_eq!(
            request(b"\x20\x00SICK_LMS"),
            hex("02 00 0A 00 20 00 53 49 43 4B 5F 4C 4D 53 BE C5")
        );
    }

    #[test]
    fn scans_round_trip_through_the_framer_past_acks_and_noise() {
        let values: Vec<u16> = (0..181).map(|i| 1000 + i).collect();
        let mut stream = vec![ACK_BYTE, 0xFF, 0x13];
        stream.extend(encode_scan(&values, 1, 0x10));
        stream.push(ACK_BYTE);
        stream.extend(encode_scan_part(11, 20, &values[10..20], 0, 0));
        let mut f = Framer::new(TelegramCodec { addr: FROM_DEVICE });
        f.push(&stream);
        let a = decode_scan(&f.next_frame().unwrap()).unwrap();
        assert_eq!(
            (a.values.clone(), a.units, a.status),
            (values.clone(), 1, 0x10)
        );
        let b = decode_scan(&f.next_frame().unwrap()).unwrap();
        assert_eq!((b.values.as_slice(), b.units), (&values[10..20], 0));
        assert_eq!(f.stats.noise, 2, "two noise bytes; ACK bytes are not noise");
    }

    #[test]
    fn a_corrupt_telegram_is_dropped_and_the_next_one_read() {
        let mut bad = encode_scan(&[1, 2, 3], 1, 0);
        bad[7] ^= 0x40;
        let good = reply(0xA0, &[0], 0x10);
        let mut f = Framer::new(TelegramCodec { addr: FROM_DEVICE });
        f.push(&bad);
        f.push(&good);
        assert_eq!(f.next_frame().unwrap().cmd(), 0xA0);
        assert_eq!(f.stats.checksum, 1);
        // A truncated telegram followed by a good one: the good one is found
        // once the false length is proven wrong by its CRC.
        let mut f = Framer::new(TelegramCodec { addr: FROM_DEVICE });
        let scan = encode_scan(&[7; 20], 1, 0);
        f.push(&scan[..15]);
        for _ in 0..10 {
            f.push(&good);
        }
        let mut got = Vec::new();
        while let Some(t) = f.next_frame() {
            got.push(t.cmd());
        }
        assert!(got.contains(&0xA0), "{got:x?}");
    }

    #[test]
    fn a_scan_with_a_wrong_count_is_refused() {
        let t = Telegram {
            addr: FROM_DEVICE,
            body: vec![cmd::SCAN, 5, 0x40, 1, 0, 2, 0, 0],
        };
        assert_eq!(
            decode_scan(&t),
            Err(ScanError::Length { count: 5, bytes: 4 })
        );
        assert!(decode_scan(&Telegram {
            addr: FROM_DEVICE,
            body: vec![cmd::SCAN]
        })
        .is_err());
    }
}
