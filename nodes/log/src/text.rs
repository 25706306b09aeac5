//! Player's text log format (file version 0.3.0), both ways.
//!
//! A log is a header of `##` lines, then one message per line:
//!
//! ```text
//! time           host     robot interface index type subtype payload…
//! 0000000000.300 16777343 6665  laser     00    001  001     0000 -1.5708 …
//! ```
//!
//! `time` is the message's stamp (`%014.3f`), `host` the IPv4 address as
//! Player packs it, `type` 1 for data and 4 for a request's answer (the
//! geometry a `writelog` asks for first). Payloads are written with the
//! exact `printf` formats of Player's `writelog.cc`, and read back as
//! Player's `readlog.cc` reads them, field by field.

use std::fmt::Write as _;

use troupe_msgs::{
    aio, blobfinder, bumper, camera, dio, fiducial, gps, ir, laser, localize, position2d, power,
    ptz, ranger, sonar, AnyMsg, Interface, Pose2d, Pose3d, Size2d, Size3d,
};

use troupe_msgs::protocol as p;
pub use troupe_msgs::protocol::{DATA, RESP_ACK};
/// 127.0.0.1 as Player packs a host address (the host field of every line
/// Troupe writes: Troupe's devices have no host of their own).
pub const LOCALHOST: u32 = 16_777_343;
/// The Player version Troupe's logs name (the bridge's banner says the same).
pub const PLAYER_VERSION: &str = "3.1.1-dev";

/// The header `writelog` puts at the top of every log.
pub fn header() -> String {
    format!(
        "## Player version {PLAYER_VERSION} \n\
         ## File version 0.3.0 \n\
         ## Format: \n\
         ## - Messages are newline-separated\n\
         ## - Common header to each message is:\n\
         ##   time     host   robot  interface index  type   subtype\n\
         ##   (double) (uint) (uint) (string)  (uint) (uint) (uint)\n\
         ## - Following the common header is the message payload \n"
    )
}

/// The line for `msg`, a message of `iface` device `robot`:`index`
/// stamped `time`, newline included; `None` for a message this format has
/// no layout for.
pub fn line(time: f64, robot: u32, iface: Interface, index: u32, msg: &AnyMsg) -> Option<String> {
    let (kind, subtype, body) = payload(msg)?;
    Some(format!(
        "{time:014.3} {LOCALHOST} {robot} {} {index:02} {kind:03} {subtype:03} {body}\n",
        iface.name()
    ))
}

/// A count (`%04d` when `padded`, else `%u`), then each value `%.3f`.
fn values<T: Into<f64> + Copy>(s: &mut String, padded: bool, v: &[T]) {
    let _ = if padded {
        write!(s, "{:04} ", v.len())
    } else {
        write!(s, "{} ", v.len())
    };
    for x in v {
        let _ = write!(s, "{:.3} ", (*x).into());
    }
}

fn pose2d_line(s: &mut String, p: &Pose2d) {
    let _ = write!(s, "{:+07.3} {:+07.3} {:+04.3} ", p.x, p.y, p.yaw);
}

fn beams(s: &mut String, ranges: &[f32], intensity: &[u8]) {
    for (i, r) in ranges.iter().enumerate() {
        let _ = write!(s, "{r:.3} {:2} ", intensity.get(i).copied().unwrap_or(0));
    }
}

fn pose3d6(s: &mut String, p: &Pose3d) {
    let _ = write!(
        s,
        "{:+07.3} {:+07.3} {:+07.3} {:+07.3} {:+07.3} {:+07.3} ",
        p.x, p.y, p.z, p.roll, p.pitch, p.yaw
    );
}

fn size3(s: &mut String, z: &Size3d) {
    let _ = write!(
        s,
        "{:+07.3} {:+07.3} {:+07.3} ",
        z.width, z.length, z.height
    );
}

fn planar_poses(s: &mut String, poses: &[Pose3d]) {
    let _ = write!(s, "{} ", poses.len());
    for p in poses {
        let _ = write!(s, "{:+07.3} {:+07.3} {:+07.4} ", p.x, p.y, p.yaw);
    }
}

/// Type, subtype and payload text of `msg`, as `writelog` prints them.
fn payload(msg: &AnyMsg) -> Option<(u8, u8, String)> {
    let mut s = String::new();
    let (kind, subtype) = match msg {
        AnyMsg::LaserScan(scan) => {
            let _ = write!(
                s,
                "{:04} {:+07.4} {:+07.4} {:+.8} {:+07.4} {:04} ",
                scan.id,
                scan.min_angle,
                scan.max_angle,
                scan.resolution,
                scan.max_range,
                scan.ranges.len()
            );
            beams(&mut s, &scan.ranges, &scan.intensity);
            (DATA, p::laser::DATA_SCAN)
        }
        AnyMsg::LaserScanPose(sp) => {
            let (scan, p) = (&sp.scan, &sp.pose);
            let _ = write!(
                s,
                "{:04} {:+07.3} {:+07.3} {:+07.3} {:+07.4} {:+07.4} {:+.8} {:+07.4} {:04} ",
                scan.id,
                p.x,
                p.y,
                p.yaw,
                scan.min_angle,
                scan.max_angle,
                scan.resolution,
                scan.max_range,
                scan.ranges.len()
            );
            beams(&mut s, &scan.ranges, &scan.intensity);
            (DATA, p::laser::DATA_SCANPOSE)
        }
        AnyMsg::LaserGeom(g) => {
            let _ = write!(
                s,
                "{:+7.3} {:+7.3} {:7.3} {:7.3} {:7.3}",
                g.pose.x, g.pose.y, g.pose.yaw, g.size.length, g.size.width
            );
            (RESP_ACK, p::laser::REQ_GET_GEOM)
        }
        AnyMsg::RangerRanges(r) => {
            values(&mut s, true, &r.ranges);
            (DATA, p::ranger::DATA_RANGE)
        }
        AnyMsg::RangerIntensities(r) => {
            values(&mut s, true, &r.intensities);
            (DATA, p::ranger::DATA_INTNS)
        }
        AnyMsg::RangerGeom(g) => {
            pose3d6(&mut s, &g.pose);
            size3(&mut s, &g.size);
            let _ = write!(s, "{:04} ", g.element_poses.len());
            for p in &g.element_poses {
                pose3d6(&mut s, p);
            }
            let _ = write!(s, "{:04} ", g.element_sizes.len());
            for z in &g.element_sizes {
                size3(&mut s, z);
            }
            (RESP_ACK, p::ranger::REQ_GET_GEOM)
        }
        AnyMsg::RangerConfig(c) => {
            let _ = write!(
                s,
                "{:.6} {:.6} {:.6} {:.6} {:.6} {:.6} {:.6} ",
                c.min_angle,
                c.max_angle,
                c.angular_res,
                c.min_range,
                c.max_range,
                c.range_res,
                c.frequency
            );
            (RESP_ACK, p::ranger::REQ_GET_CONFIG)
        }
        AnyMsg::Position2dData(d) => {
            pose2d_line(&mut s, &d.pose);
            let _ = write!(
                s,
                "{:+07.3} {:+07.3} {:+07.3} {}",
                d.vel.x,
                d.vel.y,
                d.vel.yaw,
                u8::from(d.stall)
            );
            (DATA, p::position2d::DATA_STATE)
        }
        AnyMsg::Position2dGeom(g) => {
            let _ = write!(
                s,
                "{:+07.3} {:+07.3} {:+04.3} {:+07.3} {:+07.3}",
                g.pose.x, g.pose.y, g.pose.yaw, g.size.length, g.size.width
            );
            (RESP_ACK, p::position2d::REQ_GET_GEOM)
        }
        AnyMsg::SonarRanges(r) => {
            values(&mut s, false, &r.ranges);
            (DATA, p::sonar::DATA_RANGES)
        }
        AnyMsg::SonarGeom(g) => {
            planar_poses(&mut s, &g.poses);
            (RESP_ACK, p::sonar::REQ_GET_GEOM)
        }
        AnyMsg::LocalizeHypoths(h) => {
            let _ = write!(
                s,
                "{:10} {:+07.3} {:2} ",
                h.pending_count,
                h.pending_time,
                h.hypoths.len()
            );
            for h in &h.hypoths {
                let c = &h.cov;
                let _ = write!(
                    s,
                    "{:+7.3} {:+7.3} {:7.3} {:7.3} {:7.3} {:7.3} {:7.3} {:7.3} {:7.3} {:7.3} ",
                    h.mean.x, h.mean.y, h.mean.yaw, c[0], c[1], c[2], c[3], c[4], c[5], h.weight
                );
            }
            (DATA, p::localize::DATA_HYPOTHS)
        }
        AnyMsg::LocalizeParticles(p) => {
            let _ = write!(
                s,
                "{:+7.3} {:+7.3} {:7.3} {:7.3} {:10} ",
                p.mean.x,
                p.mean.y,
                p.mean.yaw,
                p.variance,
                p.particles.len()
            );
            for q in &p.particles {
                let _ = write!(
                    s,
                    "{:+7.3} {:+7.3} {:7.3} {:7.3} ",
                    q.pose.x, q.pose.y, q.pose.yaw, q.weight
                );
            }
            (RESP_ACK, p::localize::REQ_GET_PARTICLES)
        }
        AnyMsg::PtzData(d) => {
            let _ = write!(
                s,
                "{:+07.3} {:+07.3} {:+04.3} {:+07.3} {:+07.3}",
                d.pan, d.tilt, d.zoom, d.panspeed, d.tiltspeed
            );
            (DATA, p::ptz::DATA_STATE)
        }
        AnyMsg::PowerData(d) => {
            let on = |mask: u32, v: f32| if d.valid & mask != 0 { v } else { 0.0 };
            let _ = write!(
                s,
                "{:.3} {:.3} {:.3} {:.3} {} {}",
                on(power::VALID_VOLTS, d.volts),
                on(power::VALID_PERCENT, d.percent),
                on(power::VALID_JOULES, d.joules),
                on(power::VALID_WATTS, d.watts),
                u8::from(d.valid & power::VALID_CHARGING != 0 && d.charging),
                d.valid
            );
            (DATA, p::power::DATA_STATE)
        }
        AnyMsg::GpsData(d) => {
            // The fields Player's readlog reads (21 tokens, speed and
            // course last), in writelog's formats. (Player 3.1's writelog
            // has a stray comma in its format string: its quality and
            // satellite fields come out wrong, speed and course are never
            // written, and its time adds the seconds where the
            // microseconds belong. This is the line its readlog reads.)
            let _ = write!(
                s,
                "{:.3} {:.7} {:.7} {:.7} {:.3} {:.3} {:.3} {:.3} {:.3} {:.3} {} {} {:.3} {:.3}",
                d.time,
                d.latitude,
                d.longitude,
                d.altitude,
                d.utm_e,
                d.utm_n,
                d.hdop,
                d.vdop,
                d.err_horz,
                d.err_vert,
                d.quality,
                d.num_sats,
                d.speed,
                d.course
            );
            (DATA, p::gps::DATA_STATE)
        }
        AnyMsg::CameraData(d) => {
            // writelog's fields (no fdiv), then the image as upper-case hex
            // (Player's EncodeHex).
            let _ = write!(
                s,
                "{} {} {} {} {} {} ",
                d.width,
                d.height,
                d.bpp,
                d.format,
                d.compression,
                d.image.len()
            );
            s.reserve(2 * d.image.len());
            for b in &d.image {
                s.push(char::from(HEX[usize::from(b >> 4)]));
                s.push(char::from(HEX[usize::from(b & 0x0f)]));
            }
            (DATA, p::camera::DATA_STATE)
        }
        AnyMsg::AioData(d) => {
            values(&mut s, true, &d.voltages);
            (DATA, p::aio::DATA_STATE)
        }
        AnyMsg::DioData(d) => {
            let count = d.count.min(32);
            let _ = write!(s, "{count:04} ");
            for i in 0..count {
                let _ = write!(s, "{} ", (d.bits >> i) & 1);
            }
            (DATA, p::dio::DATA_VALUES)
        }
        AnyMsg::IrData(d) => {
            let _ = write!(s, "{} ", d.ranges.len());
            for v in &d.ranges {
                let _ = write!(s, "{v:3.3} ");
            }
            (DATA, p::ir::DATA_RANGES)
        }
        AnyMsg::IrGeom(g) => {
            planar_poses(&mut s, &g.poses);
            (RESP_ACK, p::ir::REQ_POSE)
        }
        AnyMsg::BumperData(d) => {
            let _ = write!(s, "{} ", d.bumpers.len());
            for b in &d.bumpers {
                let _ = write!(s, "{} ", u8::from(*b));
            }
            (DATA, p::bumper::DATA_STATE)
        }
        AnyMsg::BumperGeom(g) => {
            let _ = write!(s, "{} ", g.bumpers.len());
            for b in &g.bumpers {
                let _ = write!(
                    s,
                    "{:+07.3} {:+07.3} {:+07.4} {:+07.4} {:+07.4} ",
                    b.pose.x, b.pose.y, b.pose.yaw, b.length, b.radius
                );
            }
            (RESP_ACK, p::bumper::REQ_GET_GEOM)
        }
        AnyMsg::FiducialData(d) => {
            let _ = write!(s, "{}", d.fiducials.len());
            for f in &d.fiducials {
                let _ = write!(s, " {}", f.id);
                for p in [&f.pose, &f.upose] {
                    let _ = write!(
                        s,
                        " {:+07.3} {:+07.3} {:+07.3} {:+07.3} {:+07.3} {:+07.3}",
                        p.x, p.y, p.z, p.roll, p.pitch, p.yaw
                    );
                }
            }
            (DATA, p::fiducial::DATA_SCAN)
        }
        AnyMsg::FiducialGeom(g) => {
            // Player's format strings meet without a space between pitch and yaw.
            let (p, z) = (&g.pose, &g.size);
            let _ = write!(
                s,
                "{:+7.3} {:+7.3} {:+7.3} {:+7.3} {:+7.3}{:+7.3} {:+7.3} {:+7.3} {:+7.3} {:+7.3} {:+7.3}",
                p.x,
                p.y,
                p.z,
                p.roll,
                p.pitch,
                p.yaw,
                z.length,
                z.width,
                z.height,
                g.fiducial_size.length,
                g.fiducial_size.width
            );
            (RESP_ACK, p::fiducial::REQ_GET_GEOM)
        }
        AnyMsg::BlobfinderData(d) => {
            let _ = write!(s, "{} {} {}", d.width, d.height, d.blobs.len());
            for b in &d.blobs {
                let _ = write!(
                    s,
                    " {} {} {} {} {} {} {} {} {} {:.6}",
                    b.id, b.color, b.area, b.x, b.y, b.left, b.right, b.top, b.bottom, b.range
                );
            }
            (DATA, p::blobfinder::DATA_BLOBS)
        }
        _ => return None,
    };
    Some((kind, subtype, s))
}

/// One message line of a log, its payload still text.
#[derive(Debug, Clone, PartialEq)]
pub struct Line<'a> {
    /// The stamp, seconds.
    pub time: f64,
    /// The host field.
    pub host: u32,
    /// The robot (port).
    pub robot: u32,
    /// The interface.
    pub interface: Interface,
    /// The device index.
    pub index: u32,
    /// [`DATA`] or [`RESP_ACK`] (or another Player message type).
    pub kind: u8,
    /// The message subtype.
    pub subtype: u8,
    /// The payload's fields.
    pub fields: Vec<&'a str>,
}

/// Why a line could not be read; the reader adds the file and line number.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum LineError {
    /// Fewer than the seven header fields.
    #[error("incomplete line: {0} fields, a message has at least 7 (time host robot interface index type subtype)")]
    Short(usize),
    /// A header field that is not what it should be.
    #[error("{field} `{text}` is not {want}")]
    Header {
        /// Which field.
        field: &'static str,
        /// What it holds.
        text: String,
        /// What it should be.
        want: &'static str,
    },
    /// An interface Player does not know.
    #[error("unknown interface `{0}`")]
    Interface(String),
    /// A type/subtype this reader has no layout for.
    #[error("no layout for {interface} message type {kind} subtype {subtype}")]
    Unsupported {
        /// The interface.
        interface: &'static str,
        /// The message type.
        kind: u8,
        /// The subtype.
        subtype: u8,
    },
    /// A payload field that is not a number.
    #[error("{interface} payload field {n} `{text}` is not a number")]
    Number {
        /// The interface.
        interface: &'static str,
        /// Its position in the payload, from 1.
        n: usize,
        /// What it holds.
        text: String,
    },
    /// The payload ends before its counts say.
    #[error("{interface} payload has {got} fields, its counts need {want}")]
    Truncated {
        /// The interface.
        interface: &'static str,
        /// Fields present.
        got: usize,
        /// Fields needed.
        want: usize,
    },
    /// A camera image field that is not hex digits, two per byte.
    #[error("camera payload field {n} `{text}…` is not an image in hex (two digits a byte)")]
    Hex {
        /// Its position in the payload, from 1.
        n: usize,
        /// Its start.
        text: String,
    },
    /// A camera image of another size than its count says.
    #[error("camera image of {got} bytes, its count says {count}")]
    Image {
        /// The count the line gives.
        count: usize,
        /// The bytes its hex holds.
        got: usize,
    },
}

/// Player's EncodeHex digits.
const HEX: &[u8; 16] = b"0123456789ABCDEF";

/// Splits a line into its header and payload fields; `Ok(None)` for a
/// blank line, a `#` comment or a `##` header line.
///
/// # Errors
///
/// [`LineError`] for a line whose header is not a message header.
pub fn parse(text: &str) -> Result<Option<Line<'_>>, LineError> {
    let mut tokens = text.split_ascii_whitespace();
    let Some(first) = tokens.clone().next() else {
        return Ok(None);
    };
    if first.starts_with('#') {
        return Ok(None);
    }
    let all: Vec<&str> = tokens.by_ref().collect();
    if all.len() < 7 {
        return Err(LineError::Short(all.len()));
    }
    fn num<T: std::str::FromStr>(
        text: &str,
        field: &'static str,
        want: &'static str,
    ) -> Result<T, LineError> {
        text.parse().map_err(|_| LineError::Header {
            field,
            text: text.to_owned(),
            want,
        })
    }
    let time: f64 = num(all[0], "time", "a number of seconds")?;
    if !time.is_finite() {
        return Err(LineError::Header {
            field: "time",
            text: all[0].to_owned(),
            want: "a finite number of seconds",
        });
    }
    Ok(Some(Line {
        time,
        host: num(all[1], "host", "an unsigned integer")?,
        robot: num(all[2], "robot", "a port number")?,
        interface: Interface::from_name(all[3])
            .ok_or_else(|| LineError::Interface(all[3].to_owned()))?,
        index: num(all[4], "index", "a device index")?,
        kind: num(all[5], "type", "a message type (0-255)")?,
        subtype: num(all[6], "subtype", "a message subtype (0-255)")?,
        fields: all[7..].to_vec(),
    }))
}

/// The first `n` numbers of a line's payload whose fields may run together
/// (`+0.000+1.500`, as Player's fiducial geometry prints two of them).
fn signed_numbers(line: &Line<'_>, n: usize) -> Result<Vec<f64>, LineError> {
    let interface = line.interface.name();
    let mut out = Vec::with_capacity(n);
    for text in &line.fields {
        let b = text.as_bytes();
        let mut start = 0;
        for k in 1..=b.len() {
            let next_sign =
                k < b.len() && (b[k] == b'+' || b[k] == b'-') && !matches!(b[k - 1], b'e' | b'E');
            if k == b.len() || next_sign {
                let part = &text[start..k];
                let v = part
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| LineError::Number {
                        interface,
                        n: out.len() + 1,
                        text: part.to_owned(),
                    })?;
                out.push(v);
                start = k;
            }
        }
    }
    if out.len() < n {
        return Err(LineError::Truncated {
            interface,
            got: out.len(),
            want: n,
        });
    }
    Ok(out)
}

/// Reads payload fields in order.
struct Fields<'a, 'b> {
    line: &'b Line<'a>,
    at: usize,
}

impl<'a> Fields<'a, '_> {
    /// The next field as it is written.
    fn next(&mut self) -> Result<&'a str, LineError> {
        let text = self.line.fields.get(self.at).ok_or(LineError::Truncated {
            interface: self.line.interface.name(),
            got: self.line.fields.len(),
            want: self.at + 1,
        })?;
        self.at += 1;
        Ok(text)
    }

    fn f64(&mut self) -> Result<f64, LineError> {
        let interface = self.line.interface.name();
        let text = self.next()?;
        text.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| LineError::Number {
                interface,
                n: self.at,
                text: (*text).to_owned(),
            })
    }

    fn f32(&mut self) -> Result<f32, LineError> {
        Ok(self.f64()? as f32)
    }

    /// A field of hex digits (Player's EncodeHex: two per byte, either
    /// case read) as bytes.
    fn hex(&mut self) -> Result<Vec<u8>, LineError> {
        let text = self.next()?;
        let digit = |c: u8| char::from(c).to_digit(16).map(|d| d as u8);
        let bytes = text.as_bytes();
        let bad = || LineError::Hex {
            n: self.at,
            text: text.chars().take(16).collect(),
        };
        if bytes.len() % 2 != 0 {
            return Err(bad());
        }
        bytes
            .chunks(2)
            .map(|p| Some(digit(p[0])? << 4 | digit(p[1])?))
            .collect::<Option<Vec<u8>>>()
            .ok_or_else(bad)
    }

    /// Fields not read yet.
    fn left(&self) -> usize {
        self.line.fields.len().saturating_sub(self.at)
    }

    /// A count; at most what the rest of the line can hold at `per` fields each.
    fn count(&mut self, per: usize) -> Result<usize, LineError> {
        let v = self.f64()?;
        let left = self.line.fields.len() - self.at;
        if v < 0.0 || v.fract() != 0.0 {
            return Err(LineError::Number {
                interface: self.line.interface.name(),
                n: self.at,
                text: self.line.fields[self.at - 1].to_owned(),
            });
        }
        let n = v as usize;
        if n.saturating_mul(per) > left {
            return Err(LineError::Truncated {
                interface: self.line.interface.name(),
                got: self.line.fields.len(),
                want: self.at + n * per,
            });
        }
        Ok(n)
    }

    fn pose2d(&mut self) -> Result<Pose2d, LineError> {
        Ok(Pose2d::new(self.f64()?, self.f64()?, self.f64()?))
    }

    fn pose3d(&mut self) -> Result<Pose3d, LineError> {
        Ok(Pose3d {
            x: self.f64()?,
            y: self.f64()?,
            z: self.f64()?,
            roll: self.f64()?,
            pitch: self.f64()?,
            yaw: self.f64()?,
        })
    }

    fn size3(&mut self) -> Result<Size3d, LineError> {
        Ok(Size3d {
            width: self.f64()?,
            length: self.f64()?,
            height: self.f64()?,
        })
    }

    fn planar(&mut self) -> Result<Pose3d, LineError> {
        Ok(Pose3d {
            x: self.f64()?,
            y: self.f64()?,
            yaw: self.f64()?,
            ..Pose3d::default()
        })
    }

    /// A body's planar pose and footprint: x y yaw length width.
    fn planar_body(&mut self) -> Result<(Pose3d, Size3d), LineError> {
        let pose = self.planar()?;
        let (length, width) = (self.f64()?, self.f64()?);
        Ok((
            pose,
            Size3d {
                width,
                length,
                height: 0.0,
            },
        ))
    }

    fn beams(&mut self, scan: &mut laser::Scan) -> Result<(), LineError> {
        let n = self.count(2)?;
        scan.ranges.reserve(n);
        scan.intensity.reserve(n);
        for _ in 0..n {
            scan.ranges.push(self.f32()?);
            scan.intensity.push(self.f64()?.clamp(0.0, 255.0) as u8);
        }
        Ok(())
    }
}

/// The message a line holds, read as `readlog` reads it.
///
/// # Errors
///
/// [`LineError`] for a layout this reader does not have, a field that is
/// not a number, or counts the line does not hold.
pub fn message(line: &Line<'_>) -> Result<AnyMsg, LineError> {
    use Interface as I;
    let mut f = Fields { line, at: 0 };
    let msg = match (line.interface, line.kind, line.subtype) {
        (I::Laser, DATA, p::laser::DATA_SCAN) => {
            let mut scan = laser::Scan {
                id: f.f64()? as u32,
                min_angle: f.f32()?,
                max_angle: f.f32()?,
                resolution: f.f32()?,
                max_range: f.f32()?,
                ..laser::Scan::default()
            };
            f.beams(&mut scan)?;
            AnyMsg::LaserScan(scan)
        }
        (I::Laser, DATA, p::laser::DATA_SCANPOSE) => {
            let id = f.f64()? as u32;
            let pose = f.pose2d()?;
            let mut scan = laser::Scan {
                id,
                min_angle: f.f32()?,
                max_angle: f.f32()?,
                resolution: f.f32()?,
                max_range: f.f32()?,
                ..laser::Scan::default()
            };
            f.beams(&mut scan)?;
            AnyMsg::LaserScanPose(laser::ScanPose { scan, pose })
        }
        (I::Laser, RESP_ACK, p::laser::REQ_GET_GEOM) => {
            let (pose, size) = f.planar_body()?;
            AnyMsg::LaserGeom(laser::Geom { pose, size })
        }
        (I::Ranger, DATA, p::ranger::DATA_RANGE) => {
            let n = f.count(1)?;
            let ranges = (0..n).map(|_| f.f64()).collect::<Result<_, _>>()?;
            AnyMsg::RangerRanges(ranger::Ranges { ranges })
        }
        (I::Ranger, DATA, p::ranger::DATA_INTNS) => {
            let n = f.count(1)?;
            let intensities = (0..n).map(|_| f.f64()).collect::<Result<_, _>>()?;
            AnyMsg::RangerIntensities(ranger::Intensities { intensities })
        }
        (I::Ranger, RESP_ACK, p::ranger::REQ_GET_GEOM) => {
            let pose = f.pose3d()?;
            let size = f.size3()?;
            let n = f.count(6)?;
            let element_poses = (0..n).map(|_| f.pose3d()).collect::<Result<_, _>>()?;
            let n = f.count(3)?;
            let element_sizes = (0..n).map(|_| f.size3()).collect::<Result<_, _>>()?;
            AnyMsg::RangerGeom(ranger::Geom {
                pose,
                size,
                element_poses,
                element_sizes,
            })
        }
        (I::Ranger, RESP_ACK, p::ranger::REQ_GET_CONFIG) => AnyMsg::RangerConfig(ranger::Config {
            min_angle: f.f64()?,
            max_angle: f.f64()?,
            angular_res: f.f64()?,
            min_range: f.f64()?,
            max_range: f.f64()?,
            range_res: f.f64()?,
            frequency: f.f64()?,
        }),
        (I::Position2d, DATA, p::position2d::DATA_STATE) => {
            AnyMsg::Position2dData(position2d::Data {
                pose: f.pose2d()?,
                vel: f.pose2d()?,
                stall: f.f64()? != 0.0,
            })
        }
        (I::Position2d, RESP_ACK, p::position2d::REQ_GET_GEOM) => {
            let (pose, size) = f.planar_body()?;
            AnyMsg::Position2dGeom(position2d::Geom { pose, size })
        }
        (I::Sonar, DATA, p::sonar::DATA_RANGES) => {
            let n = f.count(1)?;
            let ranges = (0..n).map(|_| f.f32()).collect::<Result<_, _>>()?;
            AnyMsg::SonarRanges(sonar::Ranges { ranges })
        }
        // The geometry as data (2) or as the answer to a request (1).
        (I::Sonar, DATA, p::sonar::DATA_GEOM) | (I::Sonar, RESP_ACK, p::sonar::REQ_GET_GEOM) => {
            let n = f.count(3)?;
            let poses = (0..n).map(|_| f.planar()).collect::<Result<_, _>>()?;
            AnyMsg::SonarGeom(sonar::Geom { poses })
        }
        (I::Localize, DATA, p::localize::DATA_HYPOTHS) => {
            let pending_count = f.f64()? as u32;
            let pending_time = f.f64()?;
            let n = f.count(10)?;
            let hypoths = (0..n)
                .map(|_| {
                    let mean = f.pose2d()?;
                    let mut cov = [0.0; 6];
                    for c in &mut cov {
                        *c = f.f64()?;
                    }
                    Ok(localize::Hypoth {
                        mean,
                        cov,
                        weight: f.f64()?,
                    })
                })
                .collect::<Result<_, LineError>>()?;
            AnyMsg::LocalizeHypoths(localize::Hypoths {
                pending_count,
                pending_time,
                hypoths,
            })
        }
        (I::Localize, RESP_ACK, p::localize::REQ_GET_PARTICLES) => {
            let mean = f.pose2d()?;
            let variance = f.f64()?;
            let n = f.count(4)?;
            let particles = (0..n)
                .map(|_| {
                    Ok(localize::Particle {
                        pose: f.pose2d()?,
                        weight: f.f64()?,
                    })
                })
                .collect::<Result<_, LineError>>()?;
            AnyMsg::LocalizeParticles(localize::Particles {
                mean,
                variance,
                particles,
            })
        }
        (I::Ptz, DATA, p::ptz::DATA_STATE) => AnyMsg::PtzData(ptz::Data {
            pan: f.f32()?,
            tilt: f.f32()?,
            zoom: f.f32()?,
            panspeed: f.f32()?,
            tiltspeed: f.f32()?,
        }),
        (I::Power, DATA, p::power::DATA_STATE) => {
            let (volts, percent, joules, watts) = (f.f32()?, f.f32()?, f.f32()?, f.f32()?);
            let charging = f.f64()? != 0.0;
            AnyMsg::PowerData(power::Data {
                valid: f.f64()? as u32,
                volts,
                percent,
                joules,
                watts,
                charging,
            })
        }
        (I::Gps, DATA, p::gps::DATA_STATE) => {
            let time = f.f64()?;
            let (latitude, longitude, altitude) = (f.f64()?, f.f64()?, f.f64()?);
            let (utm_e, utm_n) = (f.f64()?, f.f64()?);
            let (hdop, vdop) = (f.f64()?, f.f64()?);
            let (err_horz, err_vert) = (f.f64()?, f.f64()?);
            let (quality, num_sats) = (f.f64()? as u32, f.f64()? as u32);
            // Player 3.0's lines end here; 3.1's add speed and course.
            let (speed, course) = if f.left() >= 2 {
                (f.f64()?, f.f64()?)
            } else {
                (0.0, 0.0)
            };
            AnyMsg::GpsData(gps::Data {
                time,
                latitude,
                longitude,
                altitude,
                speed,
                course,
                utm_e,
                utm_n,
                quality,
                num_sats,
                hdop,
                vdop,
                err_horz,
                err_vert,
            })
        }
        (I::Camera, DATA, p::camera::DATA_STATE) => {
            let (width, height, bpp) = (f.f64()? as u32, f.f64()? as u32, f.f64()? as u32);
            let (format, compression) = (f.f64()? as u32, f.f64()? as u32);
            let count = f.f64()? as usize;
            let image = f.hex()?;
            if image.len() != count {
                return Err(LineError::Image {
                    count,
                    got: image.len(),
                });
            }
            AnyMsg::CameraData(camera::Data {
                width,
                height,
                bpp,
                format,
                fdiv: 0,
                compression,
                image,
            })
        }
        (I::Aio, DATA, p::aio::DATA_STATE) => {
            let n = f.count(1)?;
            let voltages = (0..n).map(|_| f.f32()).collect::<Result<_, _>>()?;
            AnyMsg::AioData(aio::Data { voltages })
        }
        (I::Dio, DATA, p::dio::DATA_VALUES) => {
            let n = f.count(1)?.min(32);
            let mut bits = 0u32;
            for i in 0..n {
                if f.f64()? != 0.0 {
                    bits |= 1 << i;
                }
            }
            AnyMsg::DioData(dio::Data {
                count: n as u32,
                bits,
            })
        }
        (I::Fiducial, DATA, p::fiducial::DATA_SCAN) => {
            let n = f.count(13)?;
            let mut fiducials = Vec::with_capacity(n);
            for _ in 0..n {
                let id = f.f64()? as i32;
                let mut pose = || -> Result<Pose3d, LineError> {
                    Ok(Pose3d {
                        x: f.f64()?,
                        y: f.f64()?,
                        z: f.f64()?,
                        roll: f.f64()?,
                        pitch: f.f64()?,
                        yaw: f.f64()?,
                    })
                };
                let (pose, upose) = (pose()?, pose()?);
                fiducials.push(fiducial::Item { id, pose, upose });
            }
            AnyMsg::FiducialData(fiducial::Data { fiducials })
        }
        (I::Fiducial, RESP_ACK, p::fiducial::REQ_GET_GEOM) => {
            let v = signed_numbers(line, 11)?;
            AnyMsg::FiducialGeom(fiducial::Geom {
                pose: Pose3d {
                    x: v[0],
                    y: v[1],
                    z: v[2],
                    roll: v[3],
                    pitch: v[4],
                    yaw: v[5],
                },
                size: Size3d {
                    length: v[6],
                    width: v[7],
                    height: v[8],
                },
                fiducial_size: Size2d {
                    length: v[9],
                    width: v[10],
                },
            })
        }
        (I::Blobfinder, DATA, p::blobfinder::DATA_BLOBS) => {
            let (width, height) = (f.f64()? as u32, f.f64()? as u32);
            let n = f.count(10)?;
            let mut blobs = Vec::with_capacity(n);
            for _ in 0..n {
                let mut u = || f.f64().map(|v| v as u32);
                blobs.push(blobfinder::Blob {
                    id: u()?,
                    color: u()?,
                    area: u()?,
                    x: u()?,
                    y: u()?,
                    left: u()?,
                    right: u()?,
                    top: u()?,
                    bottom: u()?,
                    range: f.f32()?,
                });
            }
            AnyMsg::BlobfinderData(blobfinder::Data {
                width,
                height,
                blobs,
            })
        }
        (I::Ir, DATA, p::ir::DATA_RANGES) => {
            let n = f.count(1)?;
            let ranges = (0..n).map(|_| f.f32()).collect::<Result<_, _>>()?;
            AnyMsg::IrData(ir::Data {
                voltages: Vec::new(),
                ranges,
            })
        }
        (I::Ir, RESP_ACK, p::ir::REQ_POSE) => {
            let n = f.count(3)?;
            let poses = (0..n).map(|_| f.planar()).collect::<Result<_, _>>()?;
            AnyMsg::IrGeom(ir::Geom { poses })
        }
        (I::Bumper, DATA, p::bumper::DATA_STATE) => {
            let n = f.count(1)?;
            let bumpers = (0..n)
                .map(|_| f.f64().map(|v| v != 0.0))
                .collect::<Result<_, _>>()?;
            AnyMsg::BumperData(bumper::Data { bumpers })
        }
        (I::Bumper, DATA, p::bumper::DATA_GEOM)
        | (I::Bumper, RESP_ACK, p::bumper::REQ_GET_GEOM) => {
            let n = f.count(5)?;
            let bumpers = (0..n)
                .map(|_| {
                    Ok(bumper::Define {
                        pose: f.planar()?,
                        length: f.f32()?,
                        radius: f.f32()?,
                    })
                })
                .collect::<Result<_, LineError>>()?;
            AnyMsg::BumperGeom(bumper::Geom { bumpers })
        }
        (i, kind, subtype) => {
            return Err(LineError::Unsupported {
                interface: i.name(),
                kind,
                subtype,
            })
        }
    };
    Ok(msg)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The log a real Player 3.1 wrote, from ../shared/compat.
    fn player_log() -> Option<String> {
        let p = troupe_node::testing::compat("player-log/simple-r0.log")?;
        Some(std::fs::read_to_string(p).expect("the Player log"))
    }

    /// Every line a real Player wrote reads, and writes back byte for
    /// byte: the same fields and the same number formatting.
    #[test]
    fn a_real_player_log_reads_and_writes_back_byte_for_byte() {
        let Some(log) = player_log() else { return };
        let mut kinds = std::collections::BTreeMap::<String, usize>::new();
        for (n, original) in log.split_inclusive('\n').enumerate() {
            let Some(l) = parse(original).unwrap_or_else(|e| panic!("line {}: {e}", n + 1)) else {
                assert!(original.starts_with("##"), "line {}: {original}", n + 1);
                continue;
            };
            let msg = message(&l).unwrap_or_else(|e| panic!("line {}: {e}", n + 1));
            let again = line(l.time, l.robot, l.interface, l.index, &msg).unwrap();
            assert_eq!(again, original, "line {}", n + 1);
            *kinds
                .entry(format!("{} {} {}", l.interface.name(), l.kind, l.subtype))
                .or_default() += 1;
        }
        // What the compat README says the log holds.
        assert_eq!(kinds["position2d 1 1"], 337);
        assert_eq!(kinds["laser 1 1"], 349);
        assert_eq!(kinds["ranger 1 1"], 674);
        assert_eq!(kinds["ranger 1 3"], 674);
        assert_eq!(kinds["ranger 4 5"], 2);
    }

    #[test]
    fn the_header_is_player_s() {
        let h = header();
        assert_eq!(h.lines().count(), 8);
        assert!(h.starts_with("## Player version 3.1.1-dev \n## File version 0.3.0 \n"));
        assert!(h.lines().all(|l| parse(l).unwrap().is_none()));
    }

    /// Messages Troupe writes come back equal, to the format's precision.
    #[test]
    fn every_layout_round_trips() {
        let msgs = [
            AnyMsg::SonarRanges(sonar::Ranges {
                ranges: vec![0.5, 1.25],
            }),
            AnyMsg::SonarGeom(sonar::Geom {
                poses: vec![Pose3d {
                    x: 0.1,
                    y: -0.2,
                    yaw: 1.5,
                    ..Pose3d::default()
                }],
            }),
            AnyMsg::LocalizeHypoths(localize::Hypoths {
                pending_count: 0,
                pending_time: 1.5,
                hypoths: vec![localize::Hypoth {
                    mean: Pose2d::new(1.0, -2.0, 0.5),
                    cov: [0.25, 0.25, 0.125, 0.0, 0.0, 0.0],
                    weight: 1.0,
                }],
            }),
            AnyMsg::PtzData(ptz::Data {
                pan: 0.5,
                tilt: -0.25,
                zoom: 1.0,
                panspeed: 0.0,
                tiltspeed: 0.0,
            }),
            AnyMsg::PowerData(power::Data {
                valid: power::VALID_VOLTS | power::VALID_PERCENT,
                volts: 12.5,
                percent: 80.0,
                joules: 0.0,
                watts: 0.0,
                charging: false,
            }),
            AnyMsg::GpsData(gps::Data {
                time: 1_700_000_000.5,
                latitude: 43.653_225_1,
                longitude: -79.383_184_2,
                altitude: 76.125,
                speed: 1.25,
                course: 0.5,
                utm_e: 630_084.25,
                utm_n: 4_833_438.5,
                quality: 2,
                num_sats: 9,
                hdop: 1.5,
                vdop: 2.0,
                err_horz: 0.75,
                err_vert: 1.5,
            }),
            AnyMsg::AioData(aio::Data {
                voltages: vec![1.0, 2.5],
            }),
            AnyMsg::DioData(dio::Data {
                count: 4,
                bits: 0b1010,
            }),
            AnyMsg::IrData(ir::Data {
                voltages: Vec::new(),
                ranges: vec![0.25],
            }),
            AnyMsg::BumperData(bumper::Data {
                bumpers: vec![true, false],
            }),
            AnyMsg::FiducialData(fiducial::Data {
                fiducials: vec![fiducial::Item {
                    id: 17,
                    pose: Pose3d::planar(3.088, -0.58, 2.934),
                    upose: Pose3d::default(),
                }],
            }),
            AnyMsg::FiducialGeom(fiducial::Geom {
                pose: Pose3d::planar(0.1, 0.0, -1.5),
                size: Size3d {
                    length: 0.2,
                    width: 0.25,
                    height: 0.1,
                },
                fiducial_size: Size2d {
                    length: 0.05,
                    width: 0.5,
                },
            }),
            AnyMsg::BlobfinderData(blobfinder::Data {
                width: 80,
                height: 60,
                blobs: vec![blobfinder::Blob {
                    id: 0,
                    color: 0xff0000,
                    area: 48,
                    x: 39,
                    y: 30,
                    left: 36,
                    right: 42,
                    top: 26,
                    bottom: 34,
                    range: 4.25,
                }],
            }),
            AnyMsg::LaserScanPose(laser::ScanPose {
                scan: laser::Scan {
                    min_angle: -1.5,
                    max_angle: 1.5,
                    resolution: 1.5,
                    max_range: 8.0,
                    ranges: vec![1.0, 2.0, 3.0],
                    intensity: vec![0, 1, 0],
                    id: 7,
                },
                pose: Pose2d::new(1.0, 2.0, 0.5),
            }),
        ];
        for m in msgs {
            let text = line(12.5, 6666, iface_of(&m), 1, &m).unwrap();
            let l = parse(&text).unwrap().unwrap();
            assert_eq!((l.time, l.robot, l.index), (12.5, 6666, 1), "{text}");
            assert_eq!(message(&l).unwrap(), m, "{text}");
        }
    }

    fn iface_of(m: &AnyMsg) -> Interface {
        use Interface as I;
        match m {
            AnyMsg::SonarRanges(_) | AnyMsg::SonarGeom(_) => I::Sonar,
            AnyMsg::LocalizeHypoths(_) => I::Localize,
            AnyMsg::PtzData(_) => I::Ptz,
            AnyMsg::PowerData(_) => I::Power,
            AnyMsg::GpsData(_) => I::Gps,
            AnyMsg::CameraData(_) => I::Camera,
            AnyMsg::AioData(_) => I::Aio,
            AnyMsg::DioData(_) => I::Dio,
            AnyMsg::IrData(_) => I::Ir,
            AnyMsg::BumperData(_) => I::Bumper,
            AnyMsg::FiducialData(_) | AnyMsg::FiducialGeom(_) => I::Fiducial,
            AnyMsg::BlobfinderData(_) => I::Blobfinder,
            _ => I::Laser,
        }
    }

    /// A camera line is writelog's: six numbers, then the image in
    /// upper-case hex; read back byte for byte, lower case too; a count
    /// that does not match or a digit that is not hex is refused.
    #[test]
    fn camera_lines_carry_the_image_in_hex() {
        let image = camera::Data {
            width: 2,
            height: 1,
            bpp: 24,
            format: camera::FORMAT_RGB888,
            fdiv: 0,
            compression: camera::COMPRESS_RAW,
            image: vec![0x00, 0x7f, 0xff, 0x10, 0xab, 0x01],
        };
        let text = line(
            1.5,
            6665,
            Interface::Camera,
            0,
            &AnyMsg::CameraData(image.clone()),
        )
        .unwrap();
        assert_eq!(
            text,
            "0000000001.500 16777343 6665 camera 00 001 001 2 1 24 5 0 6 007FFF10AB01\n"
        );
        let back = message(&parse(&text).unwrap().unwrap()).unwrap();
        assert_eq!(back, AnyMsg::CameraData(image.clone()));
        let lower = text.replace("007FFF10AB01", "007fff10ab01");
        assert_eq!(
            message(&parse(&lower).unwrap().unwrap()).unwrap(),
            AnyMsg::CameraData(image)
        );
        let short = text.replace(" 6 007FFF", " 7 007FFF");
        let e = message(&parse(&short).unwrap().unwrap())
            .unwrap_err()
            .to_string();
        assert!(e.contains("6 bytes, its count says 7"), "{e}");
        let bad = text.replace("007FFF", "0G7FFF");
        let e = message(&parse(&bad).unwrap().unwrap())
            .unwrap_err()
            .to_string();
        assert!(e.contains("not an image in hex"), "{e}");
    }

    /// A gps line has the 21 fields Player's readlog reads, in writelog's
    /// formats; a Player 3.0 line (19 fields: no speed or course) reads too,
    /// and a line cut before the satellites is refused.
    #[test]
    fn gps_lines_are_what_player_s_readlog_reads() {
        let fix = gps::Data {
            time: 1_700_000_000.25,
            latitude: 43.653_225_1,
            longitude: -79.383_184_2,
            altitude: 76.5,
            speed: 1.25,
            course: -0.5,
            utm_e: 630_084.25,
            utm_n: 4_833_438.5,
            quality: 1,
            num_sats: 7,
            hdop: 0.9,
            vdop: 1.4,
            err_horz: 2.5,
            err_vert: 4.0,
        };
        let text = line(3.0, 6665, Interface::Gps, 0, &AnyMsg::GpsData(fix)).unwrap();
        assert_eq!(
            text,
            "0000000003.000 16777343 6665 gps 00 001 001 1700000000.250 43.6532251 -79.3831842 76.5000000 \
             630084.250 4833438.500 0.900 1.400 2.500 4.000 1 7 1.250 -0.500\n"
        );
        assert_eq!(text.split_whitespace().count(), 21);
        let old = "0000000003.000 16777343 6665 gps 00 001 001 1700000000.250 43.6532251 -79.3831842 76.5000000 \
                   630084.250 4833438.500 0.900 1.400 2.500 4.000 1 7\n";
        let l = parse(old).unwrap().unwrap();
        assert_eq!(
            message(&l).unwrap(),
            AnyMsg::GpsData(gps::Data {
                speed: 0.0,
                course: 0.0,
                ..fix
            })
        );
        let cut =
            "0000000003.000 16777343 6665 gps 00 001 001 1700000000.250 43.6532251 -79.3831842\n";
        let e = message(&parse(cut).unwrap().unwrap())
            .unwrap_err()
            .to_string();
        assert!(e.contains("gps"), "{e}");
    }

    /// Player's own printf layouts, character for character.
    #[test]
    fn fiducial_and_blobfinder_lines_are_player_s() {
        let f = AnyMsg::FiducialData(fiducial::Data {
            fiducials: vec![fiducial::Item {
                id: 17,
                pose: Pose3d::planar(3.0881, -0.5797, 2.9341),
                upose: Pose3d::default(),
            }],
        });
        assert_eq!(
            line(6.1, 6665, Interface::Fiducial, 0, &f).unwrap(),
            "0000000006.100 16777343 6665 fiducial 00 001 001 1 17 +03.088 -00.580 +00.000 +00.000 +00.000 +02.934 +00.000 +00.000 +00.000 +00.000 +00.000 +00.000\n"
        );
        // `%+7.3f %+7.3f …%+7.3f%+7.3f …`: pitch and yaw run together
        // when both fill their seven places; the reader splits them.
        let g = AnyMsg::FiducialGeom(fiducial::Geom {
            pose: Pose3d {
                pitch: 10.0,
                yaw: -12.0,
                ..Pose3d::default()
            },
            ..Default::default()
        });
        let text = line(0.0, 6665, Interface::Fiducial, 0, &g).unwrap();
        assert!(
            text.ends_with(
                "004 001  +0.000  +0.000  +0.000  +0.000 +10.000-12.000  +0.000  +0.000  +0.000  +0.000  +0.000\n"
            ),
            "{text}"
        );
        assert_eq!(message(&parse(&text).unwrap().unwrap()).unwrap(), g);
        let b = AnyMsg::BlobfinderData(blobfinder::Data {
            width: 80,
            height: 60,
            blobs: vec![blobfinder::Blob {
                color: 0xff00,
                x: 60,
                y: 30,
                left: 60,
                right: 60,
                top: 26,
                bottom: 34,
                range: 3.5375,
                ..Default::default()
            }],
        });
        assert_eq!(
            line(6.1, 6665, Interface::Blobfinder, 0, &b).unwrap(),
            "0000000006.100 16777343 6665 blobfinder 00 001 001 80 60 1 0 65280 0 60 30 60 60 26 34 3.537500\n"
        );
    }

    #[test]
    fn bad_lines_say_what_is_wrong() {
        let e = parse("0.1 16777343 6665 laser").unwrap_err();
        assert!(e.to_string().contains("incomplete line: 4 fields"), "{e}");
        let e = parse("0.1 16777343 6665 lazer 00 001 001").unwrap_err();
        assert_eq!(e.to_string(), "unknown interface `lazer`");
        let e = parse("x 16777343 6665 laser 00 001 001").unwrap_err();
        assert!(e.to_string().starts_with("time `x` is not"), "{e}");
        // A scan cut short: its count says more beams than the line holds.
        let cut = "0.3 16777343 6665 laser 00 001 001 0000 -1.5708 +1.5708 +0.01745329 +8.0000 0180 1.529  0 1.546";
        let e = message(&parse(cut).unwrap().unwrap()).unwrap_err();
        assert_eq!(
            e.to_string(),
            "laser payload has 9 fields, its counts need 366"
        );
        let e = message(
            &parse("0.3 1 6665 position2d 00 001 001 +0.1 zz")
                .unwrap()
                .unwrap(),
        )
        .unwrap_err();
        assert_eq!(
            e.to_string(),
            "position2d payload field 2 `zz` is not a number"
        );
        let e = message(&parse("0.3 1 6665 laser 00 001 009").unwrap().unwrap()).unwrap_err();
        assert_eq!(
            e.to_string(),
            "no layout for laser message type 1 subtype 9"
        );
    }
}
