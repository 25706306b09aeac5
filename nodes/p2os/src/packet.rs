//! P2OS/ARCOS packets: the commands Player's driver sends and the standard
//! SIP, on the framing of [`troupe_serial::arcos`].

pub use troupe_serial::arcos::{
    argument, checksum, command, command_int, frame, vel2, PacketCodec, ARGINT, ARGNINT,
};

/// Command numbers.
pub mod cmd {
    /// SYNC0, and PULSE once open (keeps the watchdog quiet).
    pub const SYNC0: u8 = 0;
    /// SYNC1, and OPEN once synchronised.
    pub const SYNC1: u8 = 1;
    /// SYNC2, and CLOSE once open.
    pub const SYNC2: u8 = 2;
    /// PULSE: a keep-alive.
    pub const PULSE: u8 = 0;
    /// OPEN: start the SIP stream.
    pub const OPEN: u8 = 1;
    /// CLOSE: stop the SIP stream and forget the client.
    pub const CLOSE: u8 = 2;
    /// ENABLE the motors (1) or not (0).
    pub const ENABLE: u8 = 4;
    /// SETO: odometry back to zero.
    pub const SETO: u8 = 7;
    /// VEL: translational velocity, mm/s.
    pub const VEL: u8 = 11;
    /// RVEL: rotational velocity, deg/s.
    pub const RVEL: u8 = 21;
    /// SONAR on (1) or off (0).
    pub const SONAR: u8 = 28;
    /// STOP: both wheels to zero.
    pub const STOP: u8 = 29;
    /// VEL2: wheel velocities, low byte right, high byte left, in Vel2Divisor mm/s.
    pub const VEL2: u8 = 32;
    /// GRIPPER: one of the [`grip`](super::grip) orders.
    pub const GRIPPER: u8 = 33;
    /// BUMP_STALL: 0–3, which bumpers stall the robot.
    pub const BUMP_STALL: u8 = 44;
    /// GYRO: a gyro packet after each SIP (1) or not (0); ARCOS 1.8.
    pub const GYRO: u8 = 58;
}

/// The arguments of GRIPPER that Player sends.
pub mod grip {
    /// Open the paddles.
    pub const OPEN: i32 = 1;
    /// Close the paddles.
    pub const CLOSE: i32 = 2;
    /// Stop the paddles where they are.
    pub const STOP: i32 = 3;
}

/// The type byte of a gyro packet.
pub const GYROPAC: u8 = 0x98;

/// A gyro packet: the readings of one cycle, each a rate in 0–1023
/// (512: still; below: turning counter-clockwise) and a temperature.
pub fn gyro_packet(readings: &[(u16, u8)]) -> Vec<u8> {
    let mut d = vec![GYROPAC, readings.len() as u8];
    for (rate, temp) in readings {
        d.extend_from_slice(&rate.to_le_bytes());
        d.push(*temp);
    }
    frame(&d)
}

/// The mean rate of a gyro packet's data, as Player's `ParseGyro`.
///
/// # Errors
///
/// [`SipError`] when the packet has no readings or its length does not
/// match its count.
pub fn parse_gyro(d: &[u8]) -> Result<u16, SipError> {
    let (&count, rest) = match d {
        [GYROPAC, rest @ ..] => rest
            .split_first()
            .ok_or_else(|| SipError("gyro packet without a count".into()))?,
        _ => return Err(SipError("not a gyro packet".into())),
    };
    if count == 0 || rest.len() != 3 * usize::from(count) {
        return Err(SipError(format!(
            "gyro packet of {} bytes says {count} readings",
            d.len()
        )));
    }
    let sum: f64 = rest
        .chunks_exact(3)
        .map(|r| f64::from(u16::from_le_bytes([r[0], r[1]])))
        .sum();
    Ok((sum / f64::from(count)).round() as u16)
}

/// The robot's answer to SYNC2: name, class, subclass.
pub fn sync2_reply(name: &str, class: &str, subclass: &str) -> Vec<u8> {
    let mut d = vec![cmd::SYNC2];
    for s in [name, class, subclass] {
        d.extend_from_slice(s.as_bytes());
        d.push(0);
    }
    frame(&d)
}

/// Reads the three strings of a SYNC2 reply's data.
pub fn parse_sync2(data: &[u8]) -> (String, String, String) {
    let mut parts = data
        .get(1..)
        .unwrap_or(&[])
        .split(|&b| b == 0)
        .map(|s| String::from_utf8_lossy(s).into_owned());
    let mut next = || parts.next().unwrap_or_default();
    (next(), next(), next())
}

/// A standard SIP (types 0x30–0x34), raw as the robot sends it.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Sip {
    /// 0x32 stopped, 0x33 moving.
    pub kind: u8,
    /// Raw x position (15 bits).
    pub xpos: u16,
    /// Raw y position.
    pub ypos: u16,
    /// Heading in AngleConv units.
    pub th: i16,
    /// Left wheel, VelConv units.
    pub lvel: i16,
    /// Right wheel.
    pub rvel: i16,
    /// Battery, volts × 10.
    pub battery: u8,
    /// Bit 0 left wheel stalled, bits 1–7 rear bumpers.
    pub lstall: u8,
    /// Bit 0 right wheel stalled, bits 1–7 front bumpers.
    pub rstall: u8,
    /// Control heading.
    pub control: i16,
    /// ARCOS flags: bit 0 motors enabled.
    pub flags: u16,
    /// Compass: 0 none, else degrees / 2 + 1.
    pub compass: u8,
    /// New sonar readings: (index, range in RangeConv units).
    pub sonars: Vec<(u8, u16)>,
    /// Gripper state (ARCOS GRIP_STATE).
    pub grip: u8,
    /// ARCOS ANPORT: the byte Player reads as gripper state.
    pub anport: u8,
    /// Analog input.
    pub analog: u8,
    /// Digital inputs.
    pub digin: u8,
    /// Digital outputs.
    pub digout: u8,
}

/// Why a SIP was refused.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SipError(pub String);

impl std::fmt::Display for SipError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl Sip {
    /// True for the standard SIP types.
    pub fn is_standard(data: &[u8]) -> bool {
        matches!(data.first(), Some(0x30..=0x34))
    }

    /// Decodes a standard SIP's data.
    ///
    /// # Errors
    ///
    /// [`SipError`] when the packet is shorter than its sonar count says.
    pub fn decode(d: &[u8]) -> Result<Sip, SipError> {
        if d.len() < 20 {
            return Err(SipError(format!(
                "SIP of {} bytes: at least 25 expected",
                d.len()
            )));
        }
        let u16at = |i: usize| u16::from_le_bytes([d[i], d[i + 1]]);
        let k = usize::from(d[19]);
        let need = 25 + 3 * k;
        if d.len() < need {
            return Err(SipError(format!(
                "SIP of {} bytes with {k} sonar readings: {need} expected",
                d.len()
            )));
        }
        let sonars = (0..k)
            .map(|i| {
                let o = 20 + 3 * i;
                (d[o], u16at(o + 1))
            })
            .collect();
        let o = 20 + 3 * k;
        Ok(Sip {
            kind: d[0],
            xpos: u16at(1),
            ypos: u16at(3),
            th: u16at(5) as i16,
            lvel: u16at(7) as i16,
            rvel: u16at(9) as i16,
            battery: d[11],
            lstall: d[12],
            rstall: d[13],
            control: u16at(14) as i16,
            flags: u16at(16),
            compass: d[18],
            sonars,
            grip: d[o],
            anport: d[o + 1],
            analog: d[o + 2],
            digin: d[o + 3],
            digout: d[o + 4],
        })
    }

    /// Encodes the SIP as a packet.
    pub fn encode(&self) -> Vec<u8> {
        let mut d = Vec::with_capacity(25 + 3 * self.sonars.len());
        d.push(self.kind);
        d.extend_from_slice(&self.xpos.to_le_bytes());
        d.extend_from_slice(&self.ypos.to_le_bytes());
        d.extend_from_slice(&self.th.to_le_bytes());
        d.extend_from_slice(&self.lvel.to_le_bytes());
        d.extend_from_slice(&self.rvel.to_le_bytes());
        d.push(self.battery);
        d.push(self.lstall);
        d.push(self.rstall);
        d.extend_from_slice(&self.control.to_le_bytes());
        d.extend_from_slice(&self.flags.to_le_bytes());
        d.push(self.compass);
        d.push(self.sonars.len() as u8);
        for (i, r) in &self.sonars {
            d.push(*i);
            d.extend_from_slice(&r.to_le_bytes());
        }
        d.extend_from_slice(&[self.grip, self.anport, self.analog, self.digin, self.digout]);
        frame(&d)
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

    /// Packets as Player's driver and an ARCOS robot put them on the wire.
    #[test]
    fn commands_match_the_wire_bytes() {
        assert_eq!(command(cmd::SYNC0), hex("FA FB 03 00 00 00"));
        assert_eq!(command(cmd::SYNC1), hex("FA FB 03 01 00 01"));
        assert_eq!(command(cmd::STOP), hex("FA FB 03 1D 00 1D"));
        assert_eq!(
            command_int(cmd::ENABLE, 1),
            hex("FA FB 06 04 3B 01 00 05 3B")
        );
        assert_eq!(
            command_int(cmd::SONAR, 0),
            hex("FA FB 06 1C 3B 00 00 1C 3B")
        );
        assert_eq!(
            command_int(cmd::VEL, 200),
            hex("FA FB 06 0B 3B C8 00 D3 3B")
        );
        assert_eq!(
            command_int(cmd::VEL, -200),
            hex("FA FB 06 0B 1B C8 00 D3 1B")
        );
        assert_eq!(
            command_int(cmd::RVEL, -30),
            hex("FA FB 06 15 1B 1E 00 33 1B")
        );
        assert_eq!(vel2(19, 10), hex("FA FB 06 20 3B 13 0A 33 45"));
        assert_eq!(
            sync2_reply("MyRobot", "Pioneer", "p3dx-sh"),
            hex("FA FB 1B 02 4D 79 52 6F 62 6F 74 00 50 69 6F 6E 65 65 72 00 70 33 64 78 2D 73 68 00 B7 74")
        );
        assert_eq!(argument(&[cmd::VEL, ARGNINT, 0xC8, 0]), -200);
    }

    #[test]
    fn a_sip_round_trips_and_matches_an_arcos_capture() {
        let wire = hex(
            "FA FB 21 33 64 00 00 00 00 00 C8 00 C8 00 78 00 00 00 00 01 00 00 02 00 E8 03 01 F4 01 00 00 00 00 00 2E 58",
        );
        let mut f = Framer::new(PacketCodec);
        f.push(&[0x00, 0xFA, 0x13]);
        f.push(&wire);
        let sip = Sip::decode(&f.next_frame().unwrap()).unwrap();
        assert_eq!(
            (sip.kind, sip.xpos, sip.lvel, sip.rvel, sip.battery),
            (0x33, 100, 200, 200, 120)
        );
        assert_eq!(sip.flags, 1);
        assert_eq!(sip.sonars, vec![(0, 1000), (1, 500)]);
        assert_eq!(sip.encode(), wire);
        assert_eq!(f.stats.noise, 3);
    }

    #[test]
    fn gyro_packets_average_their_readings() {
        let p = gyro_packet(&[(500, 30), (503, 30)]);
        assert_eq!(p, hex("FA FB 0A 98 02 F4 01 1E F7 01 1E AC 18"));
        assert_eq!(parse_gyro(&p[3..p.len() - 2]), Ok(502));
        assert!(parse_gyro(&[GYROPAC, 2, 0, 2, 30]).is_err());
        assert!(parse_gyro(&[GYROPAC, 0]).is_err());
        assert!(parse_gyro(&[0x32]).is_err());
    }

    #[test]
    fn bad_checksums_and_short_sips_are_refused() {
        let mut p = command_int(cmd::ENABLE, 1);
        p[5] ^= 1;
        let mut f = Framer::new(PacketCodec);
        f.push(&p);
        f.push(&command(cmd::PULSE));
        assert_eq!(f.next_frame(), Some(vec![0]));
        assert_eq!(f.stats.checksum, 1);
        let mut sip = Sip::default().encode();
        sip.truncate(sip.len() - 4);
        let data = &sip[3..];
        assert!(Sip::decode(data).is_err());
        let many = Sip {
            sonars: vec![(0, 1); 3],
            ..Sip::default()
        };
        let mut d = many.encode()[3..].to_vec();
        d.truncate(d.len() - 5);
        assert!(Sip::decode(&d).unwrap_err().0.contains("3 sonar readings"));
    }
}
