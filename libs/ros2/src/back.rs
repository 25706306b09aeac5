//! ROS 2 messages back into Troupe samples, for `troupe play` of a bag that
//! a ROS 2 robot (or any ROS 2 tool) wrote: a LaserScan feeds a laser (or a
//! ranger), an Odometry a position2d, a PoseWithCovarianceStamped a
//! localize, `/clock` the simulation clock.

use troupe_msgs::{keys, laser, localize, position2d, ranger, sim, Device, Interface, Pose2d};

use crate::msg::*;

/// The Troupe key of a ROS 2 topic named as [`crate::topic`] names them
/// (`/robot_6665/laser_0`), or `/clock`; `None` for any other name.
pub fn key_of_topic(topic: &str) -> Option<String> {
    if topic == crate::CLOCK {
        return Some(keys::SIM_CLOCK.to_owned());
    }
    let (robot, device) = topic.strip_prefix("/robot_")?.split_once('/')?;
    let (interface, index) = device.rsplit_once('_')?;
    let dev = Device {
        robot: robot.parse().ok()?,
        interface: interface.parse::<Interface>().ok()?,
        index: index.parse().ok()?,
    };
    Some(keys::data(&dev))
}

/// Why a ROS 2 message did not become a sample, a command or a request.
#[derive(Debug, thiserror::Error)]
pub enum BackError {
    /// The payload is not the type its schema names.
    #[error("not a {ty} in CDR: {source}")]
    Cdr {
        /// The schema's type.
        ty: &'static str,
        /// The decoder's complaint.
        source: cdr::Error,
    },
    /// A speed or a pose that is not finite: no robot should act on it.
    #[error("a {ty} with a value that is not finite")]
    NotFinite {
        /// The message's type.
        ty: &'static str,
    },
    /// The type has no form on the key's interface.
    #[error("a {ty} has no form on {key} (a laser or ranger takes LaserScan, a position2d Odometry, a localize PoseWithCovarianceStamped, sim/clock Clock)")]
    NoForm {
        /// The schema's type.
        ty: &'static str,
        /// Where it was to go.
        key: String,
    },
}

fn decode<T: serde::de::DeserializeOwned>(ty: Type, data: &[u8]) -> Result<T, BackError> {
    cdr::deserialize(data).map_err(|source| BackError::Cdr {
        ty: ty.name(),
        source,
    })
}

/// A LaserScan as a laser's scan, its readings by ROS's rules (REP 117)
/// in Player's: `+inf` or above `range_max` is no return, read as
/// `range_max`; `-inf`, NaN or below `range_min` no reading, read as 0.
pub fn laser_scan(s: &LaserScan) -> laser::Scan {
    let (lo, hi) = (s.range_min.max(0.0), s.range_max);
    laser::Scan {
        min_angle: s.angle_min,
        max_angle: s.angle_max,
        resolution: s.angle_increment,
        max_range: hi,
        intensity: s
            .intensities
            .iter()
            .map(|&i| i.clamp(0.0, 255.0) as u8)
            .collect(),
        ranges: s
            .ranges
            .iter()
            .map(|&r| match r {
                r if r.is_nan() || r < lo => 0.0,
                r if r > hi => hi,
                r => r,
            })
            .collect(),
        id: 0,
    }
}

/// An Odometry as a position2d's data: its planar pose and velocities.
pub fn odometry(o: &Odometry) -> position2d::Data {
    let t = o.twist.twist;
    position2d::Data {
        pose: o.pose.pose.planar(),
        vel: Pose2d {
            x: t.linear.x,
            y: t.linear.y,
            yaw: t.angular.z,
        },
        stall: false,
    }
}

/// The sample (payload, as it travels) that carries the ROS 2 message
/// `data` of type `ty` on `key`.
///
/// # Errors
///
/// The payload is not a `ty`, or `key`'s interface has no form for it.
pub fn to_sample(ty: Type, key: &str, data: &[u8]) -> Result<Vec<u8>, BackError> {
    let no_form = || BackError::NoForm {
        ty: ty.name(),
        key: key.to_owned(),
    };
    if key == keys::SIM_CLOCK {
        if ty != Type::Clock {
            return Err(no_form());
        }
        let c: Clock = decode(ty, data)?;
        let time = c.clock.secs();
        return Ok(troupe_msgs::encode(&sim::Clock { time }, time));
    }
    let interface = keys::parse_data(key).map_err(|_| no_form())?.interface;
    Ok(match (ty, interface) {
        (Type::LaserScan, Interface::Laser) => {
            let s: LaserScan = decode(ty, data)?;
            troupe_msgs::encode(&laser_scan(&s), s.header.stamp.secs())
        }
        (Type::LaserScan, Interface::Ranger) => {
            let s: LaserScan = decode(ty, data)?;
            let r = ranger::Ranges {
                ranges: s.ranges.iter().map(|&r| f64::from(r)).collect(),
            };
            troupe_msgs::encode(&r, s.header.stamp.secs())
        }
        (Type::Odometry, Interface::Position2d) => {
            let o: Odometry = decode(ty, data)?;
            troupe_msgs::encode(&odometry(&o), o.header.stamp.secs())
        }
        (Type::PoseWithCovarianceStamped, Interface::Localize) => {
            let p: PoseWithCovarianceStamped = decode(ty, data)?;
            let h = localize::Hypoth {
                mean: p.pose.pose.planar(),
                cov: p.pose.covariance.planar(),
                weight: 1.0,
            };
            let hs = localize::Hypoths {
                hypoths: vec![h],
                ..Default::default()
            };
            troupe_msgs::encode(&hs, p.header.stamp.secs())
        }
        _ => return Err(no_form()),
    })
}
