//! The Erratic's packets, on the ARCOS framing of [`troupe_serial::arcos`]:
//! the commands Player's driver sends, the configuration reply, and the
//! motor, sonar and analog packets the robot streams.

pub use troupe_serial::arcos::{argument, command, command_int, frame, vel2, PacketCodec, ARGINT};

/// Command numbers.
pub mod cmd {
    /// Keep-alive.
    pub const PULSE: u8 = 0;
    /// Start the data stream.
    pub const OPEN: u8 = 1;
    /// Stop the data stream.
    pub const CLOSE: u8 = 2;
    /// Motors on (1) or off (0).
    pub const ENABLE: u8 = 4;
    /// Translational acceleration (positive) or deceleration (negative), mm/s².
    pub const TRANS_ACC: u8 = 5;
    /// Translational velocity, mm/s.
    pub const VEL: u8 = 11;
    /// Ask for the configuration packet (0x20).
    pub const CONFIG: u8 = 18;
    /// Rotational velocity, deg/s.
    pub const RVEL: u8 = 21;
    /// Rotational acceleration or deceleration, deg/s².
    pub const ROT_ACC: u8 = 23;
    /// Sonar on/off.
    pub const SONAR: u8 = 28;
    /// Both wheels to zero.
    pub const STOP: u8 = 29;
    /// Wheel velocities.
    pub const VEL2: u8 = 32;
    /// Analog inputs on/off.
    pub const ANALOG: u8 = 71;
    /// Save the settings in the robot.
    pub const SAVE: u8 = 72;
    /// Motor PWM frequency.
    pub const PWM_FREQ: u8 = 73;
    /// Motor PWM maximum duty cycle × 1000.
    pub const PWM_MAX_ON: u8 = 74;
    /// A servo position: `[75, 0x2B, 3, servo, counts lo, hi]`.
    pub const SERVO: u8 = 75;
    /// PID gains: translation P, V, I; rotation P, V, I.
    pub const PID: [u8; 6] = [80, 81, 82, 83, 84, 85];
}

/// Packet types from the robot.
pub mod kind {
    /// The configuration reply.
    pub const CONFIG: u8 = 0x20;
    /// Motor packets.
    pub const MOTOR: [u8; 3] = [0x80, 0x82, 0x83];
    /// Analog and digital inputs.
    pub const ANALOG: u8 = 0x9A;
    /// Sonar ranges.
    pub const SONAR: u8 = 0x9B;
}

/// Servo counts at 0°, per degree, and their range.
pub const SERVO_NEUTRAL: f64 = 1650.0;
/// Servo counts per degree.
pub const SERVO_PER_DEG: f64 = 6.5;
/// The servos' reach in counts.
pub const SERVO_RANGE: (i32, i32) = (1100, 2300);

/// A servo command to `angle` radians.
pub fn servo(servo: u8, angle: f64) -> Vec<u8> {
    let counts = (angle.to_degrees().trunc() * SERVO_PER_DEG + SERVO_NEUTRAL) as i32;
    let [lo, hi] = (counts.clamp(SERVO_RANGE.0, SERVO_RANGE.1) as u16).to_le_bytes();
    frame(&[cmd::SERVO, 0x2B, 3, servo, lo, hi])
}

/// The configuration reply: name, type and subtype in 20-byte fields.
pub fn config_reply(name: &str, kind: &str, subtype: &str) -> Vec<u8> {
    let mut d = vec![kind::CONFIG, 0];
    for s in [name, kind, subtype] {
        let mut field = [0u8; 20];
        let n = s.len().min(19);
        field[..n].copy_from_slice(&s.as_bytes()[..n]);
        d.extend_from_slice(&field);
    }
    frame(&d)
}

/// Name, type and subtype from a configuration reply's data.
pub fn parse_config(data: &[u8]) -> (String, String, String) {
    let field = |at: usize| {
        let f = data.get(at..).unwrap_or(&[]);
        let end = f
            .iter()
            .take(20)
            .position(|&b| b == 0)
            .unwrap_or(f.len().min(20));
        String::from_utf8_lossy(&f[..end]).into_owned()
    };
    (field(2), field(22), field(42))
}

/// A motor packet (0x80/0x82 stopped/0x83 moving).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Motor {
    /// The packet type.
    pub kind: u8,
    /// Position counters (12 bits used), ticks.
    pub x: u16,
    /// Y counter.
    pub y: u16,
    /// Heading, 4096 per turn.
    pub th: i16,
    /// Left wheel, VelConv units.
    pub lvel: i16,
    /// Right wheel.
    pub rvel: i16,
    /// Battery, decivolts.
    pub battery: u8,
    /// Left wheel stalled (bit 0).
    pub lstall: u8,
    /// Right wheel stalled.
    pub rstall: u8,
}

/// A packet shorter than what it announces.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PacketError {
    /// A motor packet of this many bytes.
    #[error("motor packet of {0} bytes: 18 expected")]
    ShortMotor(usize),
    /// A packet with no count.
    #[error("empty {0} packet")]
    Empty(&'static str),
    /// Fewer bytes than the count calls for.
    #[error("{kind} packet of {len} bytes announces {count} {of}")]
    Short {
        /// The packet's kind.
        kind: &'static str,
        /// Its length.
        len: usize,
        /// What it announces.
        count: usize,
        /// Of what.
        of: &'static str,
    },
}

impl Motor {
    /// Decodes a motor packet's data.
    ///
    /// # Errors
    ///
    /// A packet shorter than 18 bytes, in words.
    pub fn decode(d: &[u8]) -> Result<Motor, PacketError> {
        if d.len() < 18 {
            return Err(PacketError::ShortMotor(d.len()));
        }
        let i16at = |i: usize| i16::from_le_bytes([d[i], d[i + 1]]);
        Ok(Motor {
            kind: d[0],
            x: u16::from(d[1]) | (u16::from(d[2] & 0x0F) << 8),
            y: u16::from(d[4]) | (u16::from(d[5] & 0x0F) << 8),
            th: i16at(7),
            lvel: i16at(9),
            rvel: i16at(11),
            battery: d[13],
            lstall: d[14],
            rstall: d[15],
        })
    }

    /// Encodes it as the robot sends it.
    pub fn encode(&self) -> Vec<u8> {
        let mut d = vec![self.kind];
        for v in [self.x, self.y] {
            let [lo, hi] = (v & 0x0FFF).to_le_bytes();
            d.extend_from_slice(&[lo, hi, 0]);
        }
        for v in [self.th, self.lvel, self.rvel] {
            d.extend_from_slice(&v.to_le_bytes());
        }
        d.extend_from_slice(&[self.battery, self.lstall, self.rstall, 0, 0]);
        frame(&d)
    }
}

/// Decodes a sonar packet: (channel, range mm) pairs.
///
/// # Errors
///
/// A count the packet does not hold.
pub fn decode_sonar(d: &[u8]) -> Result<Vec<(u8, u16)>, PacketError> {
    let n = usize::from(*d.get(1).ok_or(PacketError::Empty("sonar"))?);
    if d.len() < 2 + 3 * n {
        return Err(PacketError::Short {
            kind: "sonar",
            len: d.len(),
            count: n,
            of: "readings",
        });
    }
    Ok((0..n)
        .map(|i| {
            (
                d[2 + 3 * i],
                u16::from_le_bytes([d[3 + 3 * i], d[4 + 3 * i]]),
            )
        })
        .collect())
}

/// Encodes a sonar packet.
pub fn encode_sonar(readings: &[(u8, u16)]) -> Vec<u8> {
    let mut d = vec![kind::SONAR, readings.len() as u8];
    for (c, r) in readings {
        d.push(*c);
        d.extend_from_slice(&r.to_le_bytes());
    }
    frame(&d)
}

/// Decodes an analog packet: the ADC words and the digital byte.
///
/// # Errors
///
/// A count the packet does not hold.
pub fn decode_analog(d: &[u8]) -> Result<(Vec<u16>, u8), PacketError> {
    let n = usize::from(*d.get(1).ok_or(PacketError::Empty("analog"))?);
    if d.len() < 3 + 2 * n {
        return Err(PacketError::Short {
            kind: "analog",
            len: d.len(),
            count: n,
            of: "channels",
        });
    }
    let words = (0..n)
        .map(|i| u16::from_le_bytes([d[2 + 2 * i], d[3 + 2 * i]]))
        .collect();
    Ok((words, d[2 + 2 * n]))
}

/// Encodes an analog packet.
pub fn encode_analog(words: &[u16], digital: u8) -> Vec<u8> {
    let mut d = vec![kind::ANALOG, words.len() as u8];
    for w in words {
        d.extend_from_slice(&w.to_le_bytes());
    }
    d.push(digital);
    frame(&d)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hex(s: &str) -> Vec<u8> {
        s.split_whitespace()
            .map(|b| u8::from_str_radix(b, 16).unwrap())
            .collect()
    }

    #[test]
    fn packets_match_the_wire_bytes() {
        assert_eq!(command(cmd::CONFIG), hex("FA FB 03 12 00 12"));
        assert_eq!(
            command_int(cmd::VEL, 300),
            hex("FA FB 06 0B 3B 2C 01 37 3C")
        );
        assert_eq!(vel2(10, -10), hex("FA FB 06 20 3B 0A F6 2B 31"));
        assert_eq!(servo(2, 0.0), hex("FA FB 08 4B 2B 03 02 72 06 C0 33"));
        let m = Motor::decode(
            &hex("FA FB 14 82 10 00 00 20 00 00 00 04 64 00 64 00 7D 00 00 00 00 A7 55")[3..20],
        );
        assert!(m.is_err(), "17 bytes are too few");
        let wire = hex("FA FB 14 82 10 00 00 20 00 00 00 04 64 00 64 00 7D 00 00 00 00 A7 55");
        let m = Motor::decode(&wire[3..wire.len() - 2]).unwrap();
        assert_eq!(
            (m.x, m.y, m.th, m.lvel, m.rvel, m.battery),
            (16, 32, 1024, 100, 100, 125)
        );
        assert_eq!(
            encode_sonar(&[(0, 1000), (3, 500)]),
            hex("FA FB 0A 9B 02 00 E8 03 03 F4 01 92 EE")
        );
        assert_eq!(
            encode_analog(&[512, 1023], 0x30),
            hex("FA FB 09 9A 02 00 02 FF 03 30 99 37")
        );
        let (w, dig) = decode_analog(&[0x9A, 2, 0, 2, 0xFF, 3, 0x30]).unwrap();
        assert_eq!((w, dig), (vec![512, 1023], 0x30));
        assert!(decode_sonar(&[0x9B, 3, 0, 1, 0]).is_err());
    }

    #[test]
    fn the_config_reply_names_the_robot() {
        let p = config_reply("Erratic", "Erratic", "Rev H");
        assert_eq!(p.len(), 67);
        assert_eq!(
            parse_config(&p[3..p.len() - 2]),
            ("Erratic".into(), "Erratic".into(), "Rev H".into())
        );
    }
}
