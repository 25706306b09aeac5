//! What a running Troupe robot looks like to live ROS 2 nodes: the topic
//! names its devices take (as a ROS 2 robot's drivers name theirs), and the
//! messages ROS 2 nodes send it, as Troupe commands and requests.
//!
//! ```text
//! robot/6665/position2d/0   /robot_6665/odom        Odometry, and /tf
//! robot/6665/laser/0        /robot_6665/scan        LaserScan
//! robot/6665/ranger/1       /robot_6665/ranger_1    LaserScan (a scanner) or Range (an array)
//! robot/6665/sonar/0        /robot_6665/sonar       Range, one per transducer
//! robot/6665/localize/0     /robot_6665/amcl_pose   PoseWithCovarianceStamped
//!                           /robot_6665/particle_cloud  PoseArray
//! robot/6665/planner/0      /robot_6665/plan        Path
//! robot/6665/map/0          /robot_6665/map         OccupancyGrid (transient local)
//!                           /robot_6665/map_server/map  GetMap (a service)
//! robot/6665/camera/0       /robot_6665/image_raw   Image (or …/compressed)
//! in:  /robot_6665/cmd_vel Twist, /robot_6665/goal_pose PoseStamped,
//!      /robot_6665/initialpose PoseWithCovarianceStamped
//! ```
//!
//! A device of index 1 or more takes its index after the name
//! (`/robot_6665/scan_1`); a ranger always does (`ranger_0` is Stage's sonar
//! ring, `ranger_1` its laser). `/tf`, `/tf_static` and `/clock` are global.

use troupe_msgs::{codec, localize, planner, position2d, Device, Interface, Pose2d};
use troupe_msgs::{Command as _, Request as _};

use crate::back::BackError;
use crate::msg::{PoseStamped, PoseWithCovarianceStamped, Twist, Type};

/// A robot's namespace from a template: `{robot}` is the robot's port
/// (`/robot_{robot}` gives `/robot_6665`).
pub fn robot_namespace(template: &str, robot: u32) -> String {
    let ns = template.replace("{robot}", &robot.to_string());
    let ns = ns.trim_end_matches('/');
    if ns.starts_with('/') {
        ns.to_owned()
    } else {
        format!("/{ns}")
    }
}

fn indexed(ns: &str, name: &str, index: u32) -> String {
    if index == 0 {
        format!("{ns}/{name}")
    } else {
        format!("{ns}/{name}_{index}")
    }
}

/// The live topic of a translated message: `out_topic` is the name
/// [`crate::Translator`] gave it, `ns` the device's robot namespace.
pub fn topic(ns: &str, dev: &Device, ty: Type, out_topic: &str) -> String {
    if out_topic == crate::TF || out_topic == crate::TF_STATIC || out_topic == crate::CLOCK {
        return out_topic.to_owned();
    }
    let i = dev.index;
    match (dev.interface, ty) {
        (Interface::Position2d, _) => indexed(ns, "odom", i),
        (Interface::Laser, _) => indexed(ns, "scan", i),
        (Interface::Ranger, _) => format!("{ns}/ranger_{i}"),
        (Interface::Sonar, _) => indexed(ns, "sonar", i),
        (Interface::Ir, _) => indexed(ns, "ir", i),
        (Interface::Localize, Type::PoseArray) => indexed(ns, "particle_cloud", i),
        (Interface::Localize, _) => indexed(ns, "amcl_pose", i),
        (Interface::Planner, _) => indexed(ns, "plan", i),
        (Interface::Map, _) => indexed(ns, "map", i),
        (Interface::Camera, Type::CompressedImage) => {
            format!("{}/compressed", indexed(ns, "image_raw", i))
        }
        (Interface::Camera, _) => indexed(ns, "image_raw", i),
        _ => {
            let tail = out_topic.rsplit('/').next().unwrap_or(out_topic);
            format!("{ns}/{tail}")
        }
    }
}

/// What a device takes from ROS 2: the topic it listens on, the ROS type,
/// and what a message becomes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Inbound {
    /// `cmd_vel` (Twist) drives a position2d.
    CmdVel,
    /// `goal_pose` (PoseStamped) is a planner's goal.
    Goal,
    /// `initialpose` (PoseWithCovarianceStamped) sets a localizer.
    InitialPose,
}

impl Inbound {
    /// What `dev` takes, if anything.
    pub fn of(dev: &Device) -> Option<Inbound> {
        match dev.interface {
            Interface::Position2d => Some(Inbound::CmdVel),
            Interface::Planner => Some(Inbound::Goal),
            Interface::Localize => Some(Inbound::InitialPose),
            _ => None,
        }
    }

    /// The ROS type it takes.
    pub fn ros_type(self) -> &'static str {
        match self {
            Inbound::CmdVel => "geometry_msgs/msg/Twist",
            Inbound::Goal => "geometry_msgs/msg/PoseStamped",
            Inbound::InitialPose => "geometry_msgs/msg/PoseWithCovarianceStamped",
        }
    }

    /// Its topic in robot namespace `ns` for device index `index`.
    pub fn topic(self, ns: &str, index: u32) -> String {
        let name = match self {
            Inbound::CmdVel => "cmd_vel",
            Inbound::Goal => "goal_pose",
            Inbound::InitialPose => "initialpose",
        };
        indexed(ns, name, index)
    }

    /// The Troupe command or request (its name and encoded payload,
    /// stamped `now`) that the CDR message `cdr` (with its 4-byte header)
    /// becomes.
    ///
    /// # Errors
    ///
    /// The bytes are not this type's CDR, or carry a value no robot should
    /// act on (a speed or a pose that is not finite).
    pub fn to_troupe(self, cdr: &[u8], now: f64) -> Result<(&'static str, Vec<u8>), BackError> {
        fn de<T: serde::de::DeserializeOwned>(ty: &'static str, b: &[u8]) -> Result<T, BackError> {
            cdr::deserialize(b).map_err(|source| BackError::Cdr { ty, source })
        }
        let finite = |vals: &[f64]| {
            if vals.iter().all(|v| v.is_finite()) {
                Ok(())
            } else {
                Err(BackError::NotFinite {
                    ty: self.ros_type(),
                })
            }
        };
        match self {
            Inbound::CmdVel => {
                let t: Twist = de(self.ros_type(), cdr)?;
                finite(&[t.linear.x, t.linear.y, t.angular.z])?;
                let cmd = position2d::CmdVel {
                    vel: Pose2d {
                        x: t.linear.x,
                        y: t.linear.y,
                        yaw: t.angular.z,
                    },
                    state: true,
                };
                Ok((position2d::CmdVel::NAME, codec::encode(&cmd, now)))
            }
            Inbound::Goal => {
                let p: PoseStamped = de(self.ros_type(), cdr)?;
                let goal = p.pose.planar();
                finite(&[goal.x, goal.y, goal.yaw])?;
                Ok((
                    planner::Goal::NAME,
                    codec::encode(&planner::Goal { goal }, now),
                ))
            }
            Inbound::InitialPose => {
                let p: PoseWithCovarianceStamped = de(self.ros_type(), cdr)?;
                let mean = p.pose.pose.planar();
                finite(&[mean.x, mean.y, mean.yaw])?;
                let set = localize::SetPose {
                    mean,
                    cov: p.pose.covariance.planar(),
                };
                Ok((localize::SetPose::NAME, codec::encode(&set, now)))
            }
        }
    }
}

/// The command that stops a position2d: what a base does when `cmd_vel`
/// goes quiet.
pub fn stop_command(now: f64) -> Vec<u8> {
    codec::encode(
        &position2d::CmdVel {
            vel: Pose2d::default(),
            state: true,
        },
        now,
    )
}

/// A message of type `ty` as `distro`'s definition lays it out: Humble's
/// `Range` ends before Jazzy's `variance`, its last 4 bytes.
pub fn for_distro(ty: Type, distro: crate::rmw::Distro, mut cdr: Vec<u8>) -> Vec<u8> {
    if ty == Type::Range && distro == crate::rmw::Distro::Humble {
        cdr.truncate(cdr.len().saturating_sub(4));
    }
    cdr
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msg::{Header, Pose, PoseWithCovariance, Quaternion, Vector3};

    const LASER: Device = Device::new(6665, Interface::Laser, 0);

    #[test]
    fn devices_take_a_ros_robot_s_names() {
        let ns = robot_namespace("/robot_{robot}", 6665);
        assert_eq!(ns, "/robot_6665");
        assert_eq!(robot_namespace("fleet/r{robot}/", 7), "/fleet/r7");
        let t = |i: Interface, idx, ty| topic(&ns, &Device::new(6665, i, idx), ty, "/x/y");
        assert_eq!(t(Interface::Laser, 0, Type::LaserScan), "/robot_6665/scan");
        assert_eq!(
            t(Interface::Laser, 1, Type::LaserScan),
            "/robot_6665/scan_1"
        );
        assert_eq!(t(Interface::Ranger, 0, Type::Range), "/robot_6665/ranger_0");
        assert_eq!(
            t(Interface::Position2d, 0, Type::Odometry),
            "/robot_6665/odom"
        );
        assert_eq!(
            t(Interface::Localize, 0, Type::PoseArray),
            "/robot_6665/particle_cloud"
        );
        assert_eq!(t(Interface::Map, 0, Type::OccupancyGrid), "/robot_6665/map");
        assert_eq!(
            t(Interface::Camera, 0, Type::CompressedImage),
            "/robot_6665/image_raw/compressed"
        );
        assert_eq!(
            topic(&ns, &LASER, Type::TfMessage, "/tf_static"),
            "/tf_static"
        );
        assert_eq!(Inbound::CmdVel.topic(&ns, 0), "/robot_6665/cmd_vel");
        assert_eq!(Inbound::of(&LASER), None);
    }

    #[test]
    fn a_twist_drives_and_a_bad_one_is_refused() {
        let twist = Twist {
            linear: Vector3 {
                x: 0.3,
                y: 0.0,
                z: 0.0,
            },
            angular: Vector3 {
                x: 0.0,
                y: 0.0,
                z: -0.2,
            },
        };
        let (name, payload) = Inbound::CmdVel.to_troupe(&crate::cdr(&twist), 1.5).unwrap();
        assert_eq!(name, "vel");
        let c = codec::decode::<position2d::CmdVel>(&payload).unwrap();
        assert_eq!((c.msg.vel.x, c.msg.vel.yaw, c.stamp), (0.3, -0.2, 1.5));
        // Too short for a Twist; a NaN speed.
        assert!(Inbound::CmdVel.to_troupe(&[0, 1, 0, 0, 1, 2], 0.0).is_err());
        let nan = Twist {
            linear: Vector3 {
                x: f64::NAN,
                y: 0.0,
                z: 0.0,
            },
            ..twist
        };
        let e = Inbound::CmdVel
            .to_troupe(&crate::cdr(&nan), 0.0)
            .unwrap_err();
        assert!(e.to_string().contains("not finite"), "{e}");
        let stop = codec::decode::<position2d::CmdVel>(&stop_command(2.0)).unwrap();
        assert_eq!(stop.msg.vel, Pose2d::default());
    }

    #[test]
    fn a_goal_and_an_initial_pose_become_player_s() {
        let pose = Pose {
            position: Vector3 {
                x: 1.0,
                y: 2.0,
                z: 0.0,
            },
            orientation: Quaternion::from_rpy(0.0, 0.0, 0.5),
        };
        let header = Header::default();
        let g = PoseStamped {
            header: header.clone(),
            pose,
        };
        let (name, p) = Inbound::Goal.to_troupe(&crate::cdr(&g), 0.0).unwrap();
        assert_eq!(name, planner::Goal::NAME);
        let goal = codec::decode::<planner::Goal>(&p).unwrap().msg.goal;
        assert!((goal.x - 1.0).abs() < 1e-12 && (goal.yaw - 0.5).abs() < 1e-12);
        let mut cov = [0.0; 36];
        cov[0] = 0.25;
        cov[35] = 0.07;
        let i = PoseWithCovarianceStamped {
            header,
            pose: PoseWithCovariance {
                pose,
                covariance: crate::msg::Cov(cov),
            },
        };
        let (name, p) = Inbound::InitialPose
            .to_troupe(&crate::cdr(&i), 0.0)
            .unwrap();
        assert_eq!(name, localize::SetPose::NAME);
        let s = codec::decode::<localize::SetPose>(&p).unwrap().msg;
        assert_eq!((s.cov[0], s.cov[2]), (0.25, 0.07));
    }

    #[test]
    fn humble_s_range_has_no_variance() {
        let jazzy = vec![0u8; 40];
        assert_eq!(
            for_distro(Type::Range, crate::rmw::Distro::Humble, jazzy.clone()).len(),
            36
        );
        assert_eq!(
            for_distro(Type::Range, crate::rmw::Distro::Jazzy, jazzy.clone()).len(),
            40
        );
        assert_eq!(
            for_distro(Type::LaserScan, crate::rmw::Distro::Humble, jazzy).len(),
            40
        );
    }
}
