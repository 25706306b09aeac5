//! CARMEN logs (`.clf`, `.log`): the format of the classic 2D SLAM
//! datasets (Intel Research Lab, ACES, MIT CSAIL, Freiburg 079 …), one
//! message a line, its keyword first, its stamp near its end:
//!
//! ```text
//! PARAM robot_front_laser_max 80.99 <timestamp> <host> <logger_timestamp>
//! ODOM x y theta tv rv accel <timestamp> <host> <logger_timestamp>
//! FLASER n r1 … rn x y theta odom_x odom_y odom_theta <timestamp> <host> <logger_timestamp>
//! ROBOTLASER1 type start_angle fov resolution max_range accuracy remission_mode
//!     n r1 … rn m e1 … em laser_x laser_y laser_theta robot_x robot_y robot_theta
//!     tv rv forward_safety side_safety turn_axis <timestamp> <host> <logger_timestamp>
//! ```
//!
//! They are read as a Player log's devices: the odometry (`ODOM`, or where
//! a log has none the robot pose of each scan) as `6665:position2d:0`, the
//! front laser (`FLASER`, `ROBOTLASER1`) as `6665:laser:0`, the rear
//! (`RLASER`) as `6665:laser:1`. `FLASER` gives no angles or maximum: its
//! beams span 180° from -90° as CARMEN's own `carmen_laser_get_fov` says
//! (179° for 180 beams, 179.5° for 360), and a beam reads nothing at the
//! log's `robot_front_laser_max` or, without it, at the log's largest
//! reading (81.91 m or 50 m in the classic logs: a SICK's "no return").
//! Lines of other kinds (`NEFF`, `TRUEPOS`, `SYNC` …) are passed over.

use std::f64::consts::PI;

use troupe_msgs::{laser, position2d, AnyMsg, Device, Interface, Pose2d, Pose3d, DEFAULT_ROBOT};

use crate::source::{Entry, Problems};

/// The keywords that mark a CARMEN log.
const KEYWORDS: [&str; 10] = [
    "PARAM",
    "SYNC",
    "ODOM",
    "FLASER",
    "RLASER",
    "ROBOTLASER1",
    "ROBOTLASER2",
    "RAWLASER1",
    "TRUEPOS",
    "NEFF",
];

/// Whether `text` reads as a CARMEN log: its first line that is not a
/// comment begins with a CARMEN keyword.
pub fn is_carmen(text: &str) -> bool {
    text.lines()
        .map(str::trim)
        .find(|l| !l.is_empty() && !l.starts_with('#'))
        .and_then(|l| l.split_whitespace().next())
        .is_some_and(|k| KEYWORDS.contains(&k))
}

/// A scan as the line gives it, before the log's maximum is known.
struct Raw {
    t: f64,
    rear: bool,
    /// Start angle and step, where the line says (ROBOTLASER1).
    angles: Option<(f64, f64)>,
    max_range: Option<f64>,
    ranges: Vec<f32>,
    /// The robot's pose when it was taken (odometry where the log has no
    /// ODOM lines).
    robot: Pose2d,
    place: String,
}

/// Reads a CARMEN log's text into `out`; `name` names the file in what is
/// reported.
pub(crate) fn read(name: &str, text: &str, out: &mut Vec<Entry>, problems: &mut Problems) {
    let mut odom = Vec::new();
    let mut scans = Vec::new();
    let mut params = std::collections::HashMap::new();
    // GMapping's corrected logs follow each scan with an ODOM stamped 0.
    let mut clock_started = false;
    let mut unstamped = (0usize, String::new());
    for (n, line) in text.lines().enumerate() {
        let place = || format!("{name}:{}", n + 1);
        let f: Vec<&str> = line.split_whitespace().collect();
        let Some(&kind) = f.first() else { continue };
        let parsed = match kind {
            "PARAM" if f.len() >= 3 => {
                params.insert(f[1].to_owned(), f[2].to_owned());
                Ok(())
            }
            "ODOM" => odom_line(&f).map(|(t, pose)| {
                if t == 0.0 && clock_started {
                    if unstamped.0 == 0 {
                        unstamped.1 = place();
                    }
                    unstamped.0 += 1;
                    return;
                }
                clock_started |= t > 0.0;
                odom.push(odometry(t, pose, place()));
            }),
            "FLASER" | "RLASER" => flaser(&f).map(|(t, ranges, robot)| {
                scans.push(Raw {
                    t,
                    rear: kind == "RLASER",
                    angles: None,
                    max_range: None,
                    ranges,
                    robot,
                    place: place(),
                });
            }),
            "ROBOTLASER1" => robotlaser(&f).map(|(t, angles, max, ranges, robot)| {
                scans.push(Raw {
                    t,
                    rear: false,
                    angles: Some(angles),
                    max_range: Some(max),
                    ranges,
                    robot,
                    place: place(),
                });
            }),
            _ => Ok(()),
        };
        if let Err(e) = parsed {
            problems.add(&format!("carmen {kind}"), || {
                format!("{}: {kind}: {e}; line skipped", place())
            });
        }
    }
    if unstamped.0 > 0 {
        problems.add("carmen unstamped", || {
            format!(
                "{}: {} ODOM lines stamped 0 after the log's clock began (as GMapping's corrected logs write them): skipped",
                unstamped.1, unstamped.0
            )
        });
    }
    let largest = |rear: bool| {
        scans
            .iter()
            .filter(|s| s.rear == rear)
            .flat_map(|s| s.ranges.iter())
            .fold(0f32, |m, &r| if r.is_finite() { m.max(r) } else { m })
    };
    let param = |key: &str| params.get(key).and_then(|v| v.parse::<f64>().ok());
    let max = [
        param("robot_front_laser_max").unwrap_or_else(|| f64::from(largest(false))),
        param("robot_rear_laser_max").unwrap_or_else(|| f64::from(largest(true))),
    ];
    if let Some(x) = param("robot_frontlaser_offset") {
        let y = param("robot_frontlaser_side_offset").unwrap_or(0.0);
        let yaw = param("robot_frontlaser_angular_offset").unwrap_or(0.0);
        out.push(Entry {
            t: 0.0,
            device: device(Interface::Laser, 0),
            msg: AnyMsg::LaserGeom(laser::Geom {
                pose: Pose3d {
                    x,
                    y,
                    yaw,
                    ..Default::default()
                },
                ..Default::default()
            }),
            place: format!("{name}: PARAM robot_frontlaser_offset"),
        });
    }
    let no_odom = odom.is_empty();
    out.extend(odom);
    for s in scans {
        let n = s.ranges.len();
        let (start, step) = s.angles.unwrap_or_else(|| {
            if ![180, 181, 360, 361].contains(&n) {
                problems.add("carmen beams", || {
                    format!("{}: FLASER of {n} beams, a count CARMEN gives no angles for (not 180, 181, 360 or 361): read as 180° from -90°", s.place)
                });
            }
            (-PI / 2.0, flaser_step(n))
        });
        let max_range = s.max_range.unwrap_or(max[usize::from(s.rear)]);
        let index = u32::from(s.rear);
        if no_odom {
            out.push(odometry(s.t, s.robot, s.place.clone()));
        }
        out.push(Entry {
            t: s.t,
            device: device(Interface::Laser, index),
            msg: AnyMsg::LaserScan(laser::Scan {
                min_angle: start as f32,
                max_angle: (start + step * n.saturating_sub(1) as f64) as f32,
                resolution: step as f32,
                max_range: max_range as f32,
                ranges: s.ranges,
                ..Default::default()
            }),
            place: s.place,
        });
    }
}

/// An odometry sample, as `6665:position2d:0`'s data.
fn odometry(t: f64, pose: Pose2d, place: String) -> Entry {
    Entry {
        t,
        device: device(Interface::Position2d, 0),
        msg: AnyMsg::Position2dData(position2d::Data {
            pose,
            ..Default::default()
        }),
        place,
    }
}

/// A FLASER's angle between beams, by CARMEN's `carmen_laser_get_fov`:
/// 181 and 361 beams span 180°, 180 and 360 one step less.
fn flaser_step(n: usize) -> f64 {
    match n {
        0 | 1 => PI,
        n if n % 2 == 1 => PI / (n - 1) as f64,
        n => PI / n as f64,
    }
}

fn device(interface: Interface, index: u32) -> Device {
    Device {
        robot: DEFAULT_ROBOT,
        interface,
        index,
    }
}

/// Field `i` of `f` read as `T` and kept if `ok`; `what` names the field
/// and `kind` what it must be, in the error.
fn field<T: std::str::FromStr>(
    f: &[&str],
    i: usize,
    what: &str,
    kind: &str,
    ok: impl Fn(&T) -> bool,
) -> Result<T, String> {
    let s = f
        .get(i)
        .ok_or_else(|| format!("cut short before its {what}"))?;
    s.parse::<T>()
        .ok()
        .filter(ok)
        .ok_or_else(|| format!("{what} {s:?} is not a {kind}"))
}

/// Field `i` of `f` as a number.
fn num(f: &[&str], i: usize, what: &str) -> Result<f64, String> {
    field(f, i, what, "number", |v: &f64| v.is_finite())
}

/// A count field: how many values follow.
fn count(f: &[&str], i: usize, what: &str) -> Result<usize, String> {
    field(f, i, what, "count", |&n: &usize| n <= 100_000)
}

fn ranges(f: &[&str], from: usize, n: usize) -> Result<Vec<f32>, String> {
    (from..from + n)
        .map(|i| num(f, i, "range").map(|r| r as f32))
        .collect()
}

fn pose(f: &[&str], i: usize) -> Result<Pose2d, String> {
    Ok(Pose2d::new(
        num(f, i, "x")?,
        num(f, i + 1, "y")?,
        num(f, i + 2, "theta")?,
    ))
}

/// `ODOM x y theta tv rv accel timestamp …`.
fn odom_line(f: &[&str]) -> Result<(f64, Pose2d), String> {
    Ok((num(f, 7, "timestamp")?, pose(f, 1)?))
}

/// `FLASER n r… x y theta odom_x odom_y odom_theta timestamp …`.
fn flaser(f: &[&str]) -> Result<(f64, Vec<f32>, Pose2d), String> {
    let n = count(f, 1, "beam count")?;
    let r = ranges(f, 2, n)?;
    let at = 2 + n;
    Ok((num(f, at + 6, "timestamp")?, r, pose(f, at + 3)?))
}

type RobotLaser = (f64, (f64, f64), f64, Vec<f32>, Pose2d);

/// `ROBOTLASER1 type start fov res max accuracy mode n r… m e… laser(3)
/// robot(3) tv rv forward side turn timestamp …`.
fn robotlaser(f: &[&str]) -> Result<RobotLaser, String> {
    let start = num(f, 2, "start angle")?;
    let step = num(f, 4, "angular resolution")?;
    let max = num(f, 5, "maximum range")?;
    let n = count(f, 8, "beam count")?;
    let r = ranges(f, 9, n)?;
    let m = count(f, 9 + n, "remission count")?;
    let at = 10 + n + m;
    Ok((
        num(f, at + 11, "timestamp")?,
        (start, step),
        max,
        r,
        pose(f, at + 3)?,
    ))
}

#[cfg(test)]
mod tests {
    use std::io::Write as _;

    use crate::source::{read, Select};

    use super::*;

    fn write(name: &str, bytes: &[u8]) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("troupe-carmen-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    }

    fn flaser(n: usize, r: f64, x: f64, t: f64) -> String {
        let ranges: Vec<String> = (0..n).map(|_| format!("{r}")).collect();
        format!(
            "FLASER {n} {} {x} 0 0 {x} 0 0 {t} host {t}\n",
            ranges.join(" ")
        )
    }

    fn log() -> String {
        let mut s = String::from("# message formats defined: PARAM ODOM FLASER\n");
        s += "PARAM robot_frontlaser_offset 0.1 nohost 0\n";
        s += "PARAM robot_front_laser_max 50 nohost 0\n";
        s += "ODOM 0 0 0 0 0 0 1.0 host 1.0\n";
        s += &flaser(181, 2.0, 0.0, 1.1);
        s += "ODOM 0.5 0 0 0 0 0 0 host 0\n"; // GMapping's unstamped ODOM
        s += "ODOM 1.0 0 0 0 0 0 2.0 host 2.0\n";
        s += &flaser(181, 81.91, 1.0, 2.1);
        s += "FLASER 181 1 2 3\n"; // cut short
        s += "NEFF 30\n";
        s += "ODOM 2.0 0 0 0 0 0 3.0 host 3.0\n";
        s
    }

    #[test]
    fn a_carmen_log_reads_as_odometry_and_a_laser() {
        let rec = read(&[write("a.clf", log().as_bytes())], &Select::default()).unwrap();
        assert_eq!(rec.odom.len(), 3, "the unstamped ODOM left out");
        assert_eq!(rec.scans.len(), 2);
        let s = &rec.scans[0];
        assert!((s.min_angle + PI / 2.0).abs() < 1e-6);
        assert!((s.step - PI / 180.0).abs() < 1e-6, "181 beams span 180°");
        assert_eq!(s.max_range, 50.0, "robot_front_laser_max");
        assert_eq!(rec.sensor, troupe_geom::Pose::new(0.1, 0.0, 0.0));
        let all = rec.warnings.join("\n");
        assert!(all.contains("a.clf:9: FLASER: cut short"), "{all}");
        assert!(all.contains("a.clf:6: 1 ODOM lines stamped 0"), "{all}");

        // Gzipped, the same.
        let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        gz.write_all(log().as_bytes()).unwrap();
        let rec = read(
            &[write("a.clf.gz", &gz.finish().unwrap())],
            &Select::default(),
        )
        .unwrap();
        assert_eq!((rec.odom.len(), rec.scans.len()), (3, 2));
    }

    #[test]
    fn without_odom_lines_the_scans_carry_the_odometry_and_the_largest_reading_is_no_return() {
        let mut s = String::new();
        s += &flaser(180, 3.0, 0.0, 1.0);
        s += &flaser(180, 81.91, 0.5, 2.0);
        let rec = read(&[write("b.log", s.as_bytes())], &Select::default()).unwrap();
        assert_eq!(rec.odom.len(), 2);
        assert_eq!(rec.odom[1].pose.x, 0.5);
        assert!(
            (rec.scans[0].step - PI / 180.0).abs() < 1e-6,
            "180 beams: 1° apart"
        );
        assert!((rec.scans[0].max_range - 81.91).abs() < 1e-4);
    }

    #[test]
    fn a_robotlaser_line_gives_its_own_angles_and_maximum() {
        let ranges = ["1.5"; 5].join(" ");
        let line = format!(
            "ROBOTLASER1 0 -0.5 1.0 0.25 30 0.01 0 5 {ranges} 0 0.1 0 0 0.3 0.4 0.5 0 0 0 0 0 7.5 host 7.5\n"
        );
        let rec = read(&[write("c.log", line.as_bytes())], &Select::default()).unwrap();
        let s = &rec.scans[0];
        assert_eq!(
            (s.t, s.min_angle, s.step, s.max_range),
            (7.5, -0.5, 0.25, 30.0)
        );
        assert_eq!(rec.odom[0].pose, troupe_geom::Pose::new(0.3, 0.4, 0.5));
        assert!(is_carmen(&line));
        assert!(!is_carmen("## Player version 3.1\n"));
    }
}
