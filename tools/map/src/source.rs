//! What a map is built from: a robot's odometry and its range scans, read
//! from Player text logs (as Player's `writelog` writes them), Troupe's
//! MCAP recordings (`troupe record`) or CARMEN logs (the classic datasets',
//! [`crate::carmen`]); a text log may be gzipped.
//!
//! A log may hold several robots and sensors: [`Select`] names the two
//! devices to use, and without it the only position2d and the only laser
//! (or, in a Player log, the only ranger whose configuration it holds) are
//! taken. Lines that cannot be read are skipped and counted, the first of
//! each kind reported with its file and line; stamps that go back are
//! reported the same way and put in order.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use troupe_geom::Pose;
use troupe_msgs::{decode_any, keys, AnyMsg, DevAddr, Device, Interface, DEFAULT_ROBOT};
pub use troupe_slam::Scan;

use crate::ros2::Bag;

/// A pose of the robot's odometry, at a time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Odom {
    /// Seconds (the log's clock: simulated time under Stage).
    pub t: f64,
    /// The odometric pose.
    pub pose: Pose,
}

/// Which devices of a log to build from.
#[derive(Debug, Clone, Default)]
pub struct Select {
    /// The odometry: a position2d (`6665:position2d:0`), or an Odometry topic.
    pub odom: Option<Pick>,
    /// The range sensor: a laser, or a ranger read as a laser; or a
    /// LaserScan topic.
    pub scan: Option<Pick>,
}

/// A device of a log: by its address (`6665:laser:0`), or in a ROS 2 bag
/// by its topic (`/scan`).
#[derive(Debug, Clone, PartialEq)]
pub enum Pick {
    /// A Troupe or Player device.
    Device(DevAddr),
    /// A ROS 2 topic.
    Topic(String),
}

impl std::str::FromStr for Pick {
    type Err = troupe_msgs::AddrError;

    fn from_str(s: &str) -> Result<Pick, Self::Err> {
        if s.starts_with('/') {
            return Ok(Pick::Topic(s.to_owned()));
        }
        s.parse().map(Pick::Device)
    }
}

/// What a log gave: odometry and scans in time order, the sensor's pose on
/// the robot, and what was skipped.
#[derive(Debug, Clone, Default)]
pub struct Recording {
    /// The odometry device.
    pub odom_device: Option<Device>,
    /// The scanning device.
    pub scan_device: Option<Device>,
    /// Odometry, by time.
    pub odom: Vec<Odom>,
    /// Scans, by time.
    pub scans: Vec<Scan>,
    /// The sensor's pose on the robot (its geometry, where the log has it).
    pub sensor: Pose,
    /// Problems met and passed over, one line each, with counts.
    pub warnings: Vec<String>,
    /// The ROS 2 topics the two devices were read from (`/scan as 6665:laser:0`).
    pub topics: Vec<String>,
}

/// Why a log gives no map.
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    /// The file cannot be read.
    #[error("reading {path}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The file is neither a Player text log, an MCAP recording nor a CARMEN log.
    #[error("{0}: neither a Player text log (`## Player version …`, then `time host robot interface …` lines), an MCAP recording nor a CARMEN log (`ODOM …`, `FLASER …` lines)")]
    Format(PathBuf),
    /// An MCAP file that cannot be read at all.
    #[error("{path}: {why}")]
    Mcap {
        /// The file.
        path: PathBuf,
        /// Why.
        why: String,
    },
    /// No device of the kind needed, or several and no choice.
    #[error("{0}")]
    Devices(String),
}

/// A problem repeated across a log: the first place and how many.
#[derive(Default)]
pub(crate) struct Problems(BTreeMap<String, (String, usize)>);

impl Problems {
    pub(crate) fn add(&mut self, kind: &str, first: impl FnOnce() -> String) {
        let e = self
            .0
            .entry(kind.to_owned())
            .or_insert_with(|| (first(), 0));
        e.1 += 1;
    }

    pub(crate) fn lines(self) -> Vec<String> {
        self.0
            .into_values()
            .map(|(first, n)| match n {
                1 => first,
                n => format!("{first} (and {} more like it)", n - 1),
            })
            .collect()
    }
}

/// One message of a log: where it came from and what it is.
pub(crate) struct Entry {
    pub(crate) t: f64,
    pub(crate) device: Device,
    pub(crate) msg: AnyMsg,
    /// `file:line` (text) or `file: message N` (MCAP).
    pub(crate) place: String,
}

/// Reads `paths` (Player text logs and MCAP recordings, in any mix) and
/// keeps the selected devices' odometry and scans.
///
/// # Errors
///
/// A file that cannot be read or is of neither format, no odometry or no
/// scans, or a choice to make between several devices.
pub fn read(paths: &[PathBuf], select: &Select) -> Result<Recording, SourceError> {
    let mut problems = Problems::default();
    let mut entries = Vec::new();
    let mut bag = Bag::default();
    for path in paths {
        read_file(path, &mut entries, &mut bag, &mut problems)?;
    }
    let mut rec = choose(&entries, &bag, select)?;
    collect(&entries, &mut rec, &mut problems);
    if let (Some(o), Some(s)) = (rec.odom_device, rec.scan_device) {
        match bag.mount(o, s) {
            Some(Ok(pose)) => rec.sensor = pose,
            Some(Err(why)) => problems.add("mount", || {
                format!("{why}: the scans are taken at the robot's centre")
            }),
            None => {}
        }
        rec.topics = [o, s]
            .iter()
            .filter_map(|&d| Some(format!("{} as {d}", bag.topic_of(d)?)))
            .collect();
    }
    rec.warnings = problems.lines();
    if rec.odom.is_empty() {
        return Err(SourceError::Devices(format!(
            "{} has no odometry data",
            device_name(rec.odom_device)
        )));
    }
    if rec.scans.is_empty() {
        return Err(SourceError::Devices(format!(
            "{} has no scans",
            device_name(rec.scan_device)
        )));
    }
    Ok(rec)
}

fn device_name(d: Option<Device>) -> String {
    d.map_or_else(|| "the log".to_owned(), |d| d.to_string())
}

/// A text log's bytes, gunzipped where it is gzipped.
///
/// # Errors
///
/// The file cannot be read, or its gzip stream is broken.
pub fn read_bytes(path: &Path) -> std::io::Result<Vec<u8>> {
    let bytes = std::fs::read(path)?;
    if !bytes.starts_with(&[0x1f, 0x8b]) {
        return Ok(bytes);
    }
    let mut text = Vec::new();
    std::io::Read::read_to_end(
        &mut flate2::read::MultiGzDecoder::new(&bytes[..]),
        &mut text,
    )?;
    Ok(text)
}

fn read_file(
    path: &Path,
    out: &mut Vec<Entry>,
    bag: &mut Bag,
    problems: &mut Problems,
) -> Result<(), SourceError> {
    let io = |source| SourceError::Io {
        path: path.to_owned(),
        source,
    };
    if troupe_record::is_mcap(path).map_err(io)? {
        return read_mcap(path, out, bag, problems);
    }
    let bytes = read_bytes(path).map_err(io)?;
    let Ok(text) = std::str::from_utf8(&bytes) else {
        return Err(SourceError::Format(path.to_owned()));
    };
    let name = path.display().to_string();
    if crate::carmen::is_carmen(text) {
        crate::carmen::read(&name, text, out, problems);
        return Ok(());
    }
    let mut read_any = false;
    for (n, line) in text.lines().enumerate() {
        let place = || format!("{name}:{}", n + 1);
        let parsed = match troupe_log::text::parse(line) {
            Ok(None) => continue,
            Ok(Some(l)) => l,
            Err(e) => {
                if !read_any && n > 20 {
                    return Err(SourceError::Format(path.to_owned()));
                }
                problems.add("line", || format!("{}: {e}; line skipped", place()));
                continue;
            }
        };
        read_any = true;
        if !wanted(parsed.interface) {
            continue;
        }
        let device = Device {
            robot: parsed.robot,
            interface: parsed.interface,
            index: parsed.index,
        };
        match troupe_log::text::message(&parsed) {
            Ok(msg) => out.push(Entry {
                t: parsed.time,
                device,
                msg,
                place: place(),
            }),
            Err(troupe_log::text::LineError::Unsupported { .. }) => {}
            Err(e) => problems.add(&format!("payload {}", parsed.interface), || {
                format!("{}: {e}; line skipped", place())
            }),
        }
    }
    if !read_any {
        return Err(SourceError::Format(path.to_owned()));
    }
    Ok(())
}

/// The interfaces a map is built from.
fn wanted(i: Interface) -> bool {
    matches!(
        i,
        Interface::Position2d | Interface::Laser | Interface::Ranger
    )
}

fn read_mcap(
    path: &Path,
    out: &mut Vec<Entry>,
    bag: &mut Bag,
    problems: &mut Problems,
) -> Result<(), SourceError> {
    let name = path.display().to_string();
    let mut n = 0u64;
    troupe_record::each_message(path, |m| {
        n += 1;
        if m.encoding == crate::ros2::CDR {
            let place = || format!("{name}: message {n}");
            crate::ros2::message(bag, m.topic, m.schema, m.data, place, out, problems);
            return Ok(true);
        }
        if m.encoding != troupe_record::ENCODING {
            return Ok(true);
        }
        let Ok(device) = keys::parse_data(m.topic) else {
            return Ok(true);
        };
        if !wanted(device.interface) {
            return Ok(true);
        }
        match decode_any(m.data) {
            Ok(s) => out.push(Entry {
                t: s.stamp,
                device,
                msg: s.msg,
                place: format!("{name}: message {n}"),
            }),
            Err(e) => problems.add(&format!("decode {}", device.interface), || {
                format!("{name}: message {n} on {}: {e}; skipped", m.topic)
            }),
        }
        Ok(true)
    })
    .map_err(|e| SourceError::Mcap {
        path: path.to_owned(),
        why: format!("{e:#}"),
    })
}

/// What each device of the log carries.
#[derive(Default)]
struct Seen {
    odometry: BTreeSet<Device>,
    lasers: BTreeSet<Device>,
    /// Rangers with ranges, and those whose configuration (angles) the log holds.
    rangers: BTreeSet<Device>,
    configured: BTreeSet<Device>,
}

fn seen(entries: &[Entry]) -> Seen {
    let mut s = Seen::default();
    for e in entries {
        match &e.msg {
            AnyMsg::Position2dData(_) => {
                s.odometry.insert(e.device);
            }
            AnyMsg::LaserScan(_) | AnyMsg::LaserScanPose(_) => {
                s.lasers.insert(e.device);
            }
            AnyMsg::RangerRanges(_) => {
                s.rangers.insert(e.device);
            }
            AnyMsg::RangerConfig(_) => {
                s.configured.insert(e.device);
            }
            _ => {}
        }
    }
    s
}

fn list(devices: impl IntoIterator<Item = Device>) -> String {
    let v: Vec<String> = devices.into_iter().map(|d| d.to_string()).collect();
    if v.is_empty() {
        "none".to_owned()
    } else {
        v.join(", ")
    }
}

fn choose(entries: &[Entry], bag: &Bag, select: &Select) -> Result<Recording, SourceError> {
    let s = seen(entries);
    let robot = |flag: &str, a: &Pick| picked(bag, flag, a);
    let odom = match &select.odom {
        Some(a) => {
            let d = robot("--odom", a)?;
            if d.interface != Interface::Position2d {
                return Err(SourceError::Devices(format!(
                    "--odom {d}: odometry comes from a position2d device"
                )));
            }
            if !s.odometry.contains(&d) {
                return Err(SourceError::Devices(format!(
                    "--odom {d}: the log has no data of it; position2d devices with data: {}",
                    list(s.odometry.iter().copied())
                )));
            }
            d
        }
        None => match s.odometry.len() {
            0 => {
                return Err(SourceError::Devices(
                    "the log holds no odometry (position2d data); a map needs it".to_owned(),
                ))
            }
            1 => *s
                .odometry
                .iter()
                .next()
                .ok_or_else(|| SourceError::Devices("no odometry".into()))?,
            _ => {
                return Err(SourceError::Devices(format!(
                    "the log holds several position2d devices ({}): choose one with --odom",
                    list(s.odometry.iter().copied())
                )))
            }
        },
    };
    let scanners: Vec<Device> = s
        .lasers
        .iter()
        .copied()
        .chain(s.rangers.intersection(&s.configured).copied())
        .collect();
    let scan =
        match &select.scan {
            Some(a) => {
                let d = robot("--scan", a)?;
                match d.interface {
                    Interface::Laser if s.lasers.contains(&d) => d,
                    Interface::Ranger if s.rangers.contains(&d) && s.configured.contains(&d) => d,
                    Interface::Ranger if s.rangers.contains(&d) => {
                        return Err(SourceError::Devices(format!(
                            "--scan {d}: the log has its ranges but not its configuration (the \
                         angles of its beams); a Player log written by writelog has it, a \
                         recording does not: record the laser (rangertolaser) instead"
                        )))
                    }
                    Interface::Laser | Interface::Ranger => {
                        return Err(SourceError::Devices(format!(
                            "--scan {d}: the log has no scans of it; devices with scans: {}",
                            list(scanners.iter().copied())
                        )))
                    }
                    _ => {
                        return Err(SourceError::Devices(format!(
                            "--scan {d}: scans come from a laser or a ranger"
                        )))
                    }
                }
            }
            None => {
                // A laser beside the ranger it is made from (rangertolaser) is
                // the same scan: prefer the lasers.
                let pool: Vec<Device> = if s.lasers.is_empty() {
                    scanners.clone()
                } else {
                    s.lasers.iter().copied().collect()
                };
                let same_robot: Vec<Device> = pool
                    .iter()
                    .copied()
                    .filter(|d| d.robot == odom.robot)
                    .collect();
                match (pool.len(), same_robot.len()) {
                    (0, _) if s.rangers.is_empty() => return Err(SourceError::Devices(
                        "the log holds no range scans (laser, or ranger with its configuration); \
                         a map needs them"
                            .to_owned(),
                    )),
                    (0, _) => {
                        return Err(SourceError::Devices(format!(
                            "the log holds ranger ranges ({}) but not their configuration (the \
                         angles of their beams): record a laser (rangertolaser) too",
                            list(s.rangers.iter().copied())
                        )))
                    }
                    (1, _) => pool[0],
                    (_, 1) => same_robot[0],
                    _ => {
                        return Err(SourceError::Devices(format!(
                            "the log holds several scanning devices ({}): choose one with --scan",
                            list(pool.iter().copied())
                        )))
                    }
                }
            }
        };
    Ok(Recording {
        odom_device: Some(odom),
        scan_device: Some(scan),
        ..Recording::default()
    })
}

/// The device `a` names: an address, or a topic the bag read.
fn picked(bag: &Bag, flag: &str, a: &Pick) -> Result<Device, SourceError> {
    match a {
        Pick::Device(a) => Ok(a.device(a.robot.unwrap_or(DEFAULT_ROBOT))),
        Pick::Topic(t) => bag.topics.get(t).copied().ok_or_else(|| {
            let read: Vec<&str> = bag.topics.keys().map(String::as_str).collect();
            let read = if read.is_empty() {
                "none".to_owned()
            } else {
                read.join(", ")
            };
            SourceError::Devices(format!(
                "{flag} {t}: the log has no LaserScan or Odometry on that topic; topics read: {read}"
            ))
        }),
    }
}

/// Notes a stamp `t` that goes back from the latest seen, `last`.
fn out_of_order(problems: &mut Problems, t: f64, last: &mut f64, place: &str, what: &str) {
    if t < *last {
        let before = *last;
        problems.add(&format!("order {what}"), || {
            format!(
                "{place}: {what} stamped {t:.3} s, before the one at {before:.3} s; put in order"
            )
        });
    }
    *last = last.max(t);
}

fn collect(entries: &[Entry], rec: &mut Recording, problems: &mut Problems) {
    let (Some(od), Some(sd)) = (rec.odom_device, rec.scan_device) else {
        return;
    };
    let mut config: Option<troupe_msgs::ranger::Config> = None;
    let mut last = (f64::NEG_INFINITY, f64::NEG_INFINITY);
    for e in entries {
        if e.device == od {
            if let AnyMsg::Position2dData(d) = &e.msg {
                out_of_order(problems, e.t, &mut last.0, &e.place, "odometry");
                rec.odom.push(Odom {
                    t: e.t,
                    pose: d.pose.into(),
                });
            }
            continue;
        }
        if e.device != sd {
            continue;
        }
        match &e.msg {
            AnyMsg::LaserScan(s) => {
                out_of_order(problems, e.t, &mut last.1, &e.place, "scan");
                rec.scans.push(Scan::of_laser(e.t, s));
            }
            AnyMsg::LaserScanPose(s) => {
                out_of_order(problems, e.t, &mut last.1, &e.place, "scan");
                rec.scans.push(Scan::of_laser(e.t, &s.scan));
            }
            AnyMsg::LaserGeom(g) => rec.sensor = Pose::new(g.pose.x, g.pose.y, g.pose.yaw),
            AnyMsg::RangerGeom(g) => rec.sensor = Pose::new(g.pose.x, g.pose.y, g.pose.yaw),
            AnyMsg::RangerConfig(c) => config = Some(*c),
            AnyMsg::RangerRanges(r) => {
                let Some(c) = config else {
                    problems.add("ranger before config", || {
                        format!(
                            "{}: ranges before the ranger's configuration; skipped",
                            e.place
                        )
                    });
                    continue;
                };
                out_of_order(problems, e.t, &mut last.1, &e.place, "scan");
                rec.scans.push(Scan {
                    t: e.t,
                    min_angle: c.min_angle,
                    step: c.angular_res,
                    max_range: c.max_range,
                    ranges: r.ranges.iter().map(|&x| x as f32).collect(),
                });
            }
            _ => {}
        }
    }
    rec.odom.sort_by(|a, b| a.t.total_cmp(&b.t));
    rec.scans.sort_by(|a, b| a.t.total_cmp(&b.t));
    // Player's writelog (and so Troupe's) often logs a scan twice: the
    // same stamp, the same ranges. Traced twice, it would count double.
    let before = rec.scans.len();
    rec.scans
        .dedup_by(|b, a| a.t == b.t && a.ranges == b.ranges);
    let twice = before - rec.scans.len();
    if twice > 0 {
        problems.add("twice", || {
            format!("{twice} scans logged twice (the same stamp and ranges): each counted once")
        });
    }
}

impl Recording {
    /// The odometric pose at time `t`, interpolated between the samples
    /// around it; `None` before the first or after the last.
    pub fn odom_at(&self, t: f64) -> Option<Pose> {
        let i = self.odom.partition_point(|o| o.t < t);
        let after = self.odom.get(i)?;
        if after.t == t || i == 0 {
            return (after.t == t).then_some(after.pose);
        }
        let before = self.odom[i - 1];
        let f = (t - before.t) / (after.t - before.t).max(1e-9);
        let d = before.pose.inverse().compose(&after.pose);
        Some(before.pose.compose(&Pose::new(d.x * f, d.y * f, d.yaw * f)))
    }

    /// Each scan within the odometry's time span, with the odometric pose
    /// it was taken at.
    pub fn placed(&self) -> Vec<(Pose, &Scan)> {
        self.scans
            .iter()
            .filter_map(|s| Some((self.odom_at(s.t)?, s)))
            .collect()
    }

    /// One line on what was read: the devices, how many of each, the time span.
    pub fn describe(&self) -> String {
        let mut s = String::new();
        let span = match (self.scans.first(), self.scans.last()) {
            (Some(a), Some(b)) => format!("{:.1}–{:.1} s", a.t, b.t),
            _ => "—".to_owned(),
        };
        let _ = write!(
            s,
            "{} odometry samples of {}, {} scans of {} ({})",
            self.odom.len(),
            device_name(self.odom_device),
            self.scans.len(),
            device_name(self.scan_device),
            span
        );
        if !self.topics.is_empty() {
            let _ = write!(s, "; ROS 2 topics {}", self.topics.join(", "));
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(name: &str, text: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("troupe-map-src-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    const HEAD: &str = "## Player version 3.1.1-dev \n## File version 0.3.0 \n";

    fn pos(t: f64, x: f64) -> String {
        format!("{t:014.3} 16777343 6665 position2d 00 001 001 {x:+07.3} +00.000 +0.000 +00.000 +00.000 +00.000 0\n")
    }

    fn laser(t: f64, r: f64) -> String {
        format!("{t:014.3} 16777343 6665 laser 00 001 001 0000 -1.5708 +1.5708 +1.57079633 +8.0000 0003 {r:.3} 0 {r:.3} 0 {r:.3} 0\n")
    }

    #[test]
    fn a_player_log_gives_odometry_and_scans_in_order() {
        let mut text = HEAD.to_owned();
        text += "0000000000.100 16777343 6665 laser 00 004 001 +0.130 +0.000 0.000 0.156 0.155\n";
        text += &pos(0.1, 0.0);
        text += &laser(0.2, 2.0);
        text += &pos(0.3, 0.1);
        text += &laser(0.15, 2.1); // goes back
        let p = write("ok.log", &text);
        let rec = read(&[p], &Select::default()).unwrap();
        assert_eq!(rec.odom.len(), 2);
        assert_eq!(rec.scans.len(), 2);
        assert!(rec.scans[0].t < rec.scans[1].t, "sorted");
        assert!((rec.sensor.x - 0.13).abs() < 1e-9, "{:?}", rec.sensor);
        assert_eq!(rec.warnings.len(), 1, "{:?}", rec.warnings);
        assert!(
            rec.warnings[0].contains("ok.log:7: scan stamped 0.150 s, before the one at 0.200 s"),
            "{:?}",
            rec.warnings
        );
        let mid = rec.odom_at(0.2).unwrap();
        assert!((mid.x - 0.05).abs() < 1e-9, "{mid:?}");
        assert!(rec.odom_at(0.05).is_none());
    }

    #[test]
    fn a_scan_logged_twice_counts_once() {
        let mut text = HEAD.to_owned();
        text += &pos(0.1, 0.0);
        text += &laser(0.2, 2.0);
        text += &laser(0.2, 2.0); // writelog's second copy
        text += &laser(0.2, 2.5); // same stamp, other ranges: kept
        text += &laser(0.3, 2.0);
        text += &laser(0.3, 2.0);
        text += &pos(0.4, 0.1);
        let rec = read(&[write("twice.log", &text)], &Select::default()).unwrap();
        let stamps: Vec<f64> = rec.scans.iter().map(|s| s.t).collect();
        assert_eq!(stamps, [0.2, 0.2, 0.3]);
        assert!(
            rec.warnings
                .iter()
                .any(|w| w.starts_with("2 scans logged twice")),
            "{:?}",
            rec.warnings
        );
    }

    #[test]
    fn bad_lines_are_counted_and_named_once() {
        let mut text = HEAD.to_owned();
        text += &pos(0.1, 0.0);
        text += &laser(0.2, 2.0);
        text += "0000000000.300 16777343 6665 laser 00 001 001 0000 -1.5708\n"; // cut
        text += "0000000000.400 16777343 6665 laser 00 001 001 0000 -1.5708 +1.5\n"; // cut
        text += "0000000000.500 16777343 66\n"; // cut header
        let p = write("cut.log", &text);
        let rec = read(&[p], &Select::default()).unwrap();
        assert_eq!(rec.scans.len(), 1);
        let all = rec.warnings.join("\n");
        assert!(all.contains("cut.log:5:"), "{all}");
        assert!(all.contains("(and 1 more like it)"), "{all}");
        assert!(all.contains("cut.log:7: incomplete line"), "{all}");
    }

    #[test]
    fn a_log_without_what_a_map_needs_says_so() {
        let p = write("noodom.log", &format!("{HEAD}{}", laser(0.2, 2.0)));
        let e = read(&[p], &Select::default()).unwrap_err().to_string();
        assert!(e.contains("no odometry"), "{e}");
        let p = write("noscan.log", &format!("{HEAD}{}", pos(0.2, 0.0)));
        let e = read(&[p], &Select::default()).unwrap_err().to_string();
        assert!(e.contains("no range scans"), "{e}");
        let p = write("junk.log", "hello\nworld\n");
        let e = read(&[p], &Select::default()).unwrap_err().to_string();
        assert!(e.contains("neither a Player text log"), "{e}");
        let p = write("two.log", &format!("{HEAD}{}{}{}", pos(0.1, 0.0), laser(0.2, 1.0),
            "0000000000.300 16777343 6666 position2d 00 001 001 +00.000 +00.000 +0.000 +00.000 +00.000 +00.000 0\n"));
        let e = read(std::slice::from_ref(&p), &Select::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("several position2d devices (6665:position2d:0, 6666:position2d:0): choose one with --odom"), "{e}");
        let sel = Select {
            odom: Some("6665:position2d:0".parse().unwrap()),
            scan: None,
        };
        assert!(read(&[p], &sel).is_ok());
    }

    #[test]
    fn a_recording_gives_what_the_player_log_would() {
        use troupe_msgs::{laser, position2d, Message, Pose2d};
        let dir = std::env::temp_dir().join(format!("troupe-map-mcap-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("run.mcap");
        let mut files =
            troupe_record::Files::new(path.clone(), false, troupe_record::Compress::None);
        files.open(0).unwrap();
        for k in 1..=3u32 {
            let t = f64::from(k) * 0.1;
            let odom = position2d::Data {
                pose: Pose2d::new(t, 0.0, 0.0),
                ..Default::default()
            };
            let scan = laser::Scan {
                min_angle: -1.0,
                max_angle: 1.0,
                resolution: 1.0,
                max_range: 8.0,
                ranges: vec![2.0; 3],
                ..Default::default()
            };
            let ns = (t * 1e9) as u64;
            for (key, schema, data) in [
                (
                    "robot/6665/position2d/0",
                    position2d::Data::SCHEMA,
                    troupe_msgs::encode(&odom, t),
                ),
                (
                    "robot/6665/laser/0",
                    laser::Scan::SCHEMA,
                    troupe_msgs::encode(&scan, t),
                ),
            ] {
                files
                    .write(
                        key,
                        troupe_record::Schema::troupe(schema, troupe_record::ENCODING),
                        troupe_record::ENCODING,
                        &data,
                        ns,
                        ns,
                    )
                    .unwrap();
            }
        }
        files.close().unwrap();
        let rec = read(&[path], &Select::default()).unwrap();
        assert_eq!(rec.odom.len(), 3);
        assert_eq!(rec.scans.len(), 3);
        assert_eq!(rec.scans[2].ranges, vec![2.0; 3]);
        assert!((rec.odom[2].pose.x - 0.3).abs() < 1e-9);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_ranger_reads_as_a_laser_where_the_log_holds_its_configuration() {
        let p = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../../shared/compat/player-log/simple-r0.log");
        if !p.exists() {
            eprintln!("skipping: ../shared/compat is absent");
            return;
        }
        let sel = Select {
            odom: None,
            scan: Some("6665:ranger:1".parse().unwrap()),
        };
        let rec = read(std::slice::from_ref(&p), &sel).unwrap();
        assert_eq!(
            rec.scan_device.map(|d| d.interface),
            Some(Interface::Ranger)
        );
        assert_eq!(rec.scans.len(), 337);
        let s = &rec.scans[0];
        assert_eq!(s.ranges.len(), 180);
        assert!(
            (s.min_angle + std::f64::consts::FRAC_PI_2).abs() < 1e-3,
            "{}",
            s.min_angle
        );
        assert!((s.max_range - 8.0).abs() < 1e-9);
        // The sonar ring has its configuration too, but one beam a sensor.
        let sel = Select {
            odom: None,
            scan: Some("6665:position2d:0".parse().unwrap()),
        };
        let e = read(&[p], &sel).unwrap_err().to_string();
        assert!(e.contains("scans come from a laser or a ranger"), "{e}");
    }

    #[test]
    fn players_own_log_reads_its_laser_and_odometry() {
        let p = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../../shared/compat/player-log/simple-r0.log");
        if !p.exists() {
            eprintln!("skipping: ../shared/compat is absent");
            return;
        }
        let rec = read(&[p], &Select::default()).unwrap();
        assert_eq!(rec.scan_device.map(|d| d.interface), Some(Interface::Laser));
        assert_eq!(rec.odom.len(), 337);
        // Of its 349 laser lines, 11 repeat the scan before them.
        assert_eq!(rec.scans.len(), 338);
        assert_eq!(rec.scans[0].ranges.len(), 180);
        assert_eq!(
            rec.warnings,
            ["11 scans logged twice (the same stamp and ranges): each counted once"]
        );
    }
}
