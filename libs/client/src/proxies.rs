//! One proxy per interface, named and shaped after libplayerc++'s.

use std::sync::{Arc, Mutex, MutexGuard};

use troupe_msgs::{
    blobfinder, codec, common, gripper, laser, localize, map, planner, position2d, ptz, ranger,
    simulation, sonar, DecodeError, Device, Interface, Message, Pose2d,
};
use troupe_node::zenoh::pubsub::Subscriber;

use crate::client::{Client, ClientError, Result};

/// One device of the client's robot: where commands and requests go.
#[derive(Clone)]
struct Link {
    client: Client,
    dev: Device,
}

impl Link {
    fn new(client: &Client, interface: Interface, index: u32) -> Link {
        Link {
            client: client.clone(),
            dev: client.device(interface, index),
        }
    }

    fn request<R: troupe_msgs::Request>(&self, req: &R) -> Result<R::Reply> {
        self.client.request(self.dev, req)
    }

    fn command<C: troupe_msgs::Command>(&self, cmd: &C) -> Result<()> {
        self.client.command(self.dev, cmd)
    }
}

/// A device and its latest data, kept up to date in the background.
struct Feed<S> {
    link: Link,
    state: Arc<Mutex<S>>,
    _sub: Subscriber<()>,
}

impl<S: Default + Send + 'static> Feed<S> {
    fn new(
        client: &Client,
        interface: Interface,
        index: u32,
        update: fn(&mut S, &[u8]) -> Result<(), DecodeError>,
    ) -> Result<Self> {
        let link = Link::new(client, interface, index);
        let dev = link.dev;
        let state = Arc::new(Mutex::new(S::default()));
        let st = state.clone();
        let sub = client.subscribe(dev, move |bytes| {
            let mut s = st.lock().unwrap_or_else(|p| p.into_inner());
            if let Err(e) = update(&mut s, bytes) {
                tracing::warn!("dropped a malformed sample from {dev}: {e}");
            }
        })?;
        Ok(Feed {
            link,
            state,
            _sub: sub,
        })
    }

    fn get(&self) -> MutexGuard<'_, S> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// Stores `bytes` into `slot` if they are an `M`; says whether they were.
fn take<M: Message>(slot: &mut Option<M>, bytes: &[u8]) -> Result<bool, DecodeError> {
    if codec::schema_of(bytes)? != M::SCHEMA {
        return Ok(false);
    }
    *slot = Some(codec::decode::<M>(bytes)?.msg);
    Ok(true)
}

fn only<M: Message>(slot: &mut Option<M>, bytes: &[u8]) -> Result<(), DecodeError> {
    if take(slot, bytes)? {
        Ok(())
    } else {
        Err(DecodeError::UnknownSchema(
            codec::schema_of(bytes)?.to_owned(),
        ))
    }
}

/// A planar mobile base (`Position2dProxy`).
pub struct Position2dProxy {
    feed: Feed<Option<position2d::Data>>,
}

impl Position2dProxy {
    /// Subscribes to `position2d:index` of the client's robot.
    ///
    /// # Errors
    ///
    /// [`ClientError::Node`] if the subscription fails.
    pub fn new(client: &Client, index: u32) -> Result<Self> {
        Ok(Position2dProxy {
            feed: Feed::new(
                client,
                Interface::Position2d,
                index,
                only::<position2d::Data>,
            )?,
        })
    }

    /// The device.
    pub fn device(&self) -> Device {
        self.feed.link.dev
    }

    /// The latest state, if any arrived.
    pub fn data(&self) -> Option<position2d::Data> {
        *self.feed.get()
    }

    fn d(&self) -> position2d::Data {
        self.data().unwrap_or_default()
    }

    /// Odometric x, metres.
    pub fn x(&self) -> f64 {
        self.d().pose.x
    }
    /// Odometric y, metres.
    pub fn y(&self) -> f64 {
        self.d().pose.y
    }
    /// Odometric heading, radians.
    pub fn yaw(&self) -> f64 {
        self.d().pose.yaw
    }
    /// The odometric pose as nalgebra's isometry (the robot's frame to the
    /// odometric one).
    pub fn isometry(&self) -> nalgebra::Isometry2<f64> {
        crate::na::ToIsometry::isometry(&self.d().pose)
    }
    /// Forward speed, m/s.
    pub fn x_speed(&self) -> f64 {
        self.d().vel.x
    }
    /// Sideways speed, m/s.
    pub fn y_speed(&self) -> f64 {
        self.d().vel.y
    }
    /// Turn rate, rad/s.
    pub fn yaw_speed(&self) -> f64 {
        self.d().vel.yaw
    }
    /// True when stalled.
    pub fn stall(&self) -> bool {
        self.d().stall
    }

    /// Drives at `x` m/s forward turning at `yaw` rad/s (`SetSpeed(x, yaw)`).
    ///
    /// # Errors
    ///
    /// [`ClientError::Node`] if the command cannot be sent.
    pub fn set_speed(&self, x: f64, yaw: f64) -> Result<()> {
        self.set_velocity(x, 0.0, yaw)
    }

    /// Drives holonomically (`SetSpeed(x, y, yaw)`).
    ///
    /// # Errors
    ///
    /// [`ClientError::Node`] if the command cannot be sent.
    pub fn set_velocity(&self, x: f64, y: f64, yaw: f64) -> Result<()> {
        let cmd = position2d::CmdVel {
            vel: Pose2d::new(x, y, yaw),
            state: true,
        };
        self.feed.link.command(&cmd)
    }

    /// Drives like a car: speed m/s, steering angle rad (`SetCarlike`).
    ///
    /// # Errors
    ///
    /// [`ClientError::Node`] if the command cannot be sent.
    pub fn set_car_like(&self, velocity: f64, angle: f64) -> Result<()> {
        self.feed
            .link
            .command(&position2d::CmdCar { velocity, angle })
    }

    /// Goes to a pose in the odometric frame (`GoTo`).
    ///
    /// # Errors
    ///
    /// [`ClientError::Node`] if the command cannot be sent.
    pub fn go_to(&self, x: f64, y: f64, yaw: f64) -> Result<()> {
        let cmd = position2d::CmdPos {
            pos: Pose2d::new(x, y, yaw),
            vel: Pose2d::default(),
            state: true,
        };
        self.feed.link.command(&cmd)
    }

    /// Enables or disables the motors (`SetMotorEnable`).
    ///
    /// # Errors
    ///
    /// [`ClientError::Nack`] if the device refuses; [`ClientError::NoAnswer`].
    pub fn set_motor_enable(&self, on: bool) -> Result<()> {
        self.feed
            .link
            .request(&position2d::MotorPower { state: on })
            .map(|_| ())
    }

    /// The base's geometry (`RequestGeom`).
    ///
    /// # Errors
    ///
    /// [`ClientError::Nack`] if the device refuses; [`ClientError::NoAnswer`].
    pub fn request_geom(&self) -> Result<position2d::Geom> {
        self.feed.link.request(&position2d::GetGeom)
    }

    /// Sets the odometric pose (`SetOdometry`).
    ///
    /// # Errors
    ///
    /// [`ClientError::Nack`] if the device refuses; [`ClientError::NoAnswer`].
    pub fn set_odometry(&self, x: f64, y: f64, yaw: f64) -> Result<()> {
        let req = position2d::SetOdom {
            pose: Pose2d::new(x, y, yaw),
        };
        self.feed.link.request(&req).map(|_| ())
    }

    /// Resets odometry to the origin (`ResetOdometry`).
    ///
    /// # Errors
    ///
    /// [`ClientError::Nack`] if the device refuses; [`ClientError::NoAnswer`].
    pub fn reset_odometry(&self) -> Result<()> {
        self.feed.link.request(&position2d::ResetOdom).map(|_| ())
    }
}

/// A scanning range finder (`LaserProxy`).
pub struct LaserProxy {
    feed: Feed<Option<laser::Scan>>,
}

fn laser_update(s: &mut Option<laser::Scan>, b: &[u8]) -> Result<(), DecodeError> {
    let mut pose: Option<laser::ScanPose> = None;
    if take(&mut pose, b)? {
        *s = pose.map(|p| p.scan);
        return Ok(());
    }
    only(s, b)
}

impl LaserProxy {
    /// Subscribes to `laser:index` of the client's robot.
    ///
    /// # Errors
    ///
    /// [`ClientError::Node`] if the subscription fails.
    pub fn new(client: &Client, index: u32) -> Result<Self> {
        Ok(LaserProxy {
            feed: Feed::new(client, Interface::Laser, index, laser_update)?,
        })
    }

    /// The latest scan.
    pub fn scan(&self) -> Option<laser::Scan> {
        self.feed.get().clone()
    }

    /// Beams in the latest scan.
    pub fn count(&self) -> usize {
        self.feed.get().as_ref().map_or(0, |s| s.ranges.len())
    }

    /// What the latest scan saw, as points in the laser's frame (x ahead;
    /// beams at the maximum range saw nothing and are left out).
    pub fn points(&self) -> Vec<nalgebra::Point2<f64>> {
        self.feed
            .get()
            .as_ref()
            .map(crate::na::scan_points)
            .unwrap_or_default()
    }

    /// Range of beam `i`, metres.
    pub fn range(&self, i: usize) -> Option<f64> {
        self.feed
            .get()
            .as_ref()?
            .ranges
            .get(i)
            .map(|&r| f64::from(r))
    }

    /// The shortest range of the latest scan, metres.
    pub fn min_range(&self) -> Option<f64> {
        let s = self.feed.get();
        s.as_ref()?
            .ranges
            .iter()
            .map(|&r| f64::from(r))
            .reduce(f64::min)
    }

    /// Angle of the first beam, radians.
    pub fn min_angle(&self) -> f64 {
        self.feed
            .get()
            .as_ref()
            .map_or(0.0, |s| f64::from(s.min_angle))
    }

    /// Angle of the last beam, radians.
    pub fn max_angle(&self) -> f64 {
        self.feed
            .get()
            .as_ref()
            .map_or(0.0, |s| f64::from(s.max_angle))
    }

    /// Radians between beams.
    pub fn scan_res(&self) -> f64 {
        self.feed
            .get()
            .as_ref()
            .map_or(0.0, |s| f64::from(s.resolution))
    }

    /// Maximum range, metres.
    pub fn max_range(&self) -> f64 {
        self.feed
            .get()
            .as_ref()
            .map_or(0.0, |s| f64::from(s.max_range))
    }

    /// The laser's geometry.
    ///
    /// # Errors
    ///
    /// [`ClientError::Nack`] if the device refuses; [`ClientError::NoAnswer`].
    pub fn request_geom(&self) -> Result<laser::Geom> {
        self.feed.link.request(&laser::GetGeom)
    }

    /// The laser's configuration.
    ///
    /// # Errors
    ///
    /// [`ClientError::Nack`] if the device refuses; [`ClientError::NoAnswer`].
    pub fn request_config(&self) -> Result<laser::Config> {
        self.feed.link.request(&laser::GetConfig)
    }

    /// The laser's serial number (`PLAYER_LASER_REQ_GET_ID`).
    ///
    /// # Errors
    ///
    /// [`ClientError::Nack`] if the device refuses; [`ClientError::NoAnswer`].
    pub fn request_id(&self) -> Result<u32> {
        Ok(self.feed.link.request(&laser::GetId)?.serial_number)
    }

    /// Sets the configuration; returns the configuration in force.
    ///
    /// # Errors
    ///
    /// [`ClientError::Nack`] if the device refuses; [`ClientError::NoAnswer`].
    pub fn configure(&self, config: laser::Config) -> Result<laser::Config> {
        self.feed.link.request(&laser::SetConfig { config })
    }
}

#[derive(Default)]
struct RangerState {
    ranges: Option<ranger::Ranges>,
    intensities: Option<ranger::Intensities>,
}

fn ranger_update(s: &mut RangerState, b: &[u8]) -> Result<(), DecodeError> {
    if take(&mut s.ranges, b)? {
        return Ok(());
    }
    only(&mut s.intensities, b)
}

/// A set of range sensors (`RangerProxy`).
pub struct RangerProxy {
    feed: Feed<RangerState>,
}

impl RangerProxy {
    /// Subscribes to `ranger:index` of the client's robot.
    ///
    /// # Errors
    ///
    /// [`ClientError::Node`] if the subscription fails.
    pub fn new(client: &Client, index: u32) -> Result<Self> {
        Ok(RangerProxy {
            feed: Feed::new(client, Interface::Ranger, index, ranger_update)?,
        })
    }

    /// The latest ranges, metres.
    pub fn ranges(&self) -> Vec<f64> {
        self.feed
            .get()
            .ranges
            .as_ref()
            .map(|r| r.ranges.clone())
            .unwrap_or_default()
    }

    /// Number of ranges in the latest sample.
    pub fn count(&self) -> usize {
        self.feed
            .get()
            .ranges
            .as_ref()
            .map_or(0, |r| r.ranges.len())
    }

    /// Range `i`, metres.
    pub fn range(&self, i: usize) -> Option<f64> {
        self.feed.get().ranges.as_ref()?.ranges.get(i).copied()
    }

    /// The latest intensities.
    pub fn intensities(&self) -> Vec<f64> {
        let s = self.feed.get();
        s.intensities
            .as_ref()
            .map(|r| r.intensities.clone())
            .unwrap_or_default()
    }

    /// Geometry, with the pose of each element.
    ///
    /// # Errors
    ///
    /// [`ClientError::Nack`] if the device refuses; [`ClientError::NoAnswer`].
    pub fn request_geom(&self) -> Result<ranger::Geom> {
        self.feed.link.request(&ranger::GetGeom)
    }

    /// Configuration.
    ///
    /// # Errors
    ///
    /// [`ClientError::Nack`] if the device refuses; [`ClientError::NoAnswer`].
    pub fn request_config(&self) -> Result<ranger::Config> {
        self.feed.link.request(&ranger::GetConfig)
    }
}

/// An array of sonars (`SonarProxy`).
pub struct SonarProxy {
    feed: Feed<Option<sonar::Ranges>>,
}

impl SonarProxy {
    /// Subscribes to `sonar:index` of the client's robot.
    ///
    /// # Errors
    ///
    /// [`ClientError::Node`] if the subscription fails.
    pub fn new(client: &Client, index: u32) -> Result<Self> {
        Ok(SonarProxy {
            feed: Feed::new(client, Interface::Sonar, index, only::<sonar::Ranges>)?,
        })
    }

    /// Number of ranges.
    pub fn count(&self) -> usize {
        self.feed.get().as_ref().map_or(0, |r| r.ranges.len())
    }

    /// Range of transducer `i`, metres.
    pub fn range(&self, i: usize) -> Option<f64> {
        self.feed
            .get()
            .as_ref()?
            .ranges
            .get(i)
            .map(|&r| f64::from(r))
    }

    /// Pose of each transducer.
    ///
    /// # Errors
    ///
    /// [`ClientError::Nack`] if the device refuses; [`ClientError::NoAnswer`].
    pub fn request_geom(&self) -> Result<sonar::Geom> {
        self.feed.link.request(&sonar::GetGeom)
    }
}

/// A GPS receiver (`GpsProxy`).
pub struct GpsProxy {
    feed: Feed<Option<troupe_msgs::gps::Data>>,
}

impl GpsProxy {
    /// Subscribes to `gps:index` of the client's robot.
    ///
    /// # Errors
    ///
    /// [`ClientError::Node`] if the subscription fails.
    pub fn new(client: &Client, index: u32) -> Result<Self> {
        Ok(GpsProxy {
            feed: Feed::new(
                client,
                Interface::Gps,
                index,
                only::<troupe_msgs::gps::Data>,
            )?,
        })
    }

    /// The latest fix, if any arrived.
    pub fn data(&self) -> Option<troupe_msgs::gps::Data> {
        *self.feed.get()
    }

    /// Latitude of the latest fix, degrees (0 before one arrived).
    pub fn latitude(&self) -> f64 {
        self.data().map_or(0.0, |d| d.latitude)
    }

    /// Longitude of the latest fix, degrees (0 before one arrived).
    pub fn longitude(&self) -> f64 {
        self.data().map_or(0.0, |d| d.longitude)
    }

    /// Altitude of the latest fix, metres (0 before one arrived).
    pub fn altitude(&self) -> f64 {
        self.data().map_or(0.0, |d| d.altitude)
    }

    /// Satellites in view at the latest fix.
    pub fn satellites(&self) -> u32 {
        self.data().map_or(0, |d| d.num_sats)
    }

    /// Quality of the latest fix: 0 invalid (or none yet), 1 GPS, 2 DGPS.
    pub fn quality(&self) -> u32 {
        self.data().map_or(0, |d| d.quality)
    }
}

/// A pan-tilt-zoom unit (`PtzProxy`).
pub struct PtzProxy {
    feed: Feed<Option<ptz::Data>>,
}

impl PtzProxy {
    /// Subscribes to `ptz:index` of the client's robot.
    ///
    /// # Errors
    ///
    /// [`ClientError::Node`] if the subscription fails.
    pub fn new(client: &Client, index: u32) -> Result<Self> {
        Ok(PtzProxy {
            feed: Feed::new(client, Interface::Ptz, index, only::<ptz::Data>)?,
        })
    }

    /// The latest state the device reported.
    pub fn data(&self) -> Option<ptz::Data> {
        *self.feed.get()
    }

    /// Points the unit: pan and tilt in radians, zoom as it is (Player's `SetCam`).
    ///
    /// # Errors
    ///
    /// [`ClientError::Node`] if the command could not be sent.
    pub fn set_pan_tilt(&self, pan: f64, tilt: f64) -> Result<()> {
        self.feed.link.command(&ptz::Cmd {
            target: ptz::Data {
                pan: pan as f32,
                tilt: tilt as f32,
                ..Default::default()
            },
        })
    }
}

/// An occupancy grid (`MapProxy`).
pub struct MapProxy {
    link: Link,
    info: map::Info,
    cells: Vec<i8>,
}

/// Rows fetched per request: tiles keep each answer well under Zenoh's fragment budget.
const TILE_CELLS: u32 = 1 << 20;

impl MapProxy {
    /// A proxy for `map:index` of the client's robot (no data until [`MapProxy::request_map`]).
    pub fn new(client: &Client, index: u32) -> Self {
        MapProxy {
            link: Link::new(client, Interface::Map, index),
            info: map::Info::default(),
            cells: Vec::new(),
        }
    }

    /// Fetches the map's info and every cell (`RequestMap`).
    ///
    /// # Errors
    ///
    /// [`ClientError::Nack`] if the device refuses; [`ClientError::NoAnswer`];
    /// [`ClientError::Decode`] if a tile is not the size asked for.
    pub fn request_map(&mut self) -> Result<()> {
        let info = self.link.request(&map::GetInfo)?;
        let (w, h) = (info.width, info.height);
        let mut cells = vec![0i8; w as usize * h as usize];
        let rows = (TILE_CELLS / w.max(1)).max(1);
        let mut row = 0;
        while row < h {
            let height = rows.min(h - row);
            let req = map::GetData {
                col: 0,
                row,
                width: w,
                height,
            };
            let tile = self.link.request(&req)?;
            if tile.cells.len() != (w * height) as usize {
                return Err(ClientError::Decode {
                    device: self.link.dev,
                    source: DecodeError::Body {
                        schema: "map/data@1".into(),
                        reason: format!(
                            "tile of {} cells, asked for {}×{height}",
                            tile.cells.len(),
                            w
                        ),
                    },
                });
            }
            let start = (row * w) as usize;
            cells[start..start + tile.cells.len()].copy_from_slice(&tile.cells);
            row += height;
        }
        self.info = info;
        self.cells = cells;
        Ok(())
    }

    /// Its size, resolution and origin, as the device said them.
    pub fn info(&self) -> map::Info {
        self.info
    }
    /// Cells along x.
    pub fn width(&self) -> u32 {
        self.info.width
    }
    /// Cells along y.
    pub fn height(&self) -> u32 {
        self.info.height
    }
    /// Metres per cell.
    pub fn resolution(&self) -> f64 {
        f64::from(self.info.resolution)
    }
    /// Pose of cell (0, 0) in the world.
    pub fn origin(&self) -> Pose2d {
        self.info.origin
    }
    /// Every cell, row by row from row 0 (the row at the origin's y).
    pub fn cells(&self) -> &[i8] {
        &self.cells
    }
    /// Cell (`i` column, `j` row): -1 free, 0 unknown, +1 occupied; `None` outside the map.
    pub fn cell(&self, i: u32, j: u32) -> Option<i8> {
        if i >= self.info.width || j >= self.info.height {
            return None;
        }
        self.cells.get((j * self.info.width + i) as usize).copied()
    }
}

/// A path planner (`PlannerProxy`).
pub struct PlannerProxy {
    feed: Feed<Option<planner::State>>,
}

impl PlannerProxy {
    /// Subscribes to `planner:index` of the client's robot.
    ///
    /// # Errors
    ///
    /// [`ClientError::Node`] if the subscription fails.
    pub fn new(client: &Client, index: u32) -> Result<Self> {
        Ok(PlannerProxy {
            feed: Feed::new(client, Interface::Planner, index, only::<planner::State>)?,
        })
    }

    /// The latest state.
    pub fn state(&self) -> Option<planner::State> {
        *self.feed.get()
    }

    /// Sets a goal (`SetGoalPose`).
    ///
    /// # Errors
    ///
    /// [`ClientError::Node`] if the command cannot be sent.
    pub fn set_goal_pose(&self, x: f64, y: f64, yaw: f64) -> Result<()> {
        let goal = planner::Goal {
            goal: Pose2d::new(x, y, yaw),
        };
        self.feed.link.command(&goal)
    }

    /// Enables or disables motion (`SetEnable`).
    ///
    /// # Errors
    ///
    /// [`ClientError::Nack`] if the device refuses; [`ClientError::NoAnswer`].
    pub fn set_enable(&self, on: bool) -> Result<()> {
        self.feed
            .link
            .request(&planner::Enable { state: on })
            .map(|_| ())
    }

    /// The current path (`RequestWaypoints`).
    ///
    /// # Errors
    ///
    /// [`ClientError::Nack`] if the device refuses; [`ClientError::NoAnswer`].
    pub fn request_waypoints(&self) -> Result<Vec<Pose2d>> {
        self.feed
            .link
            .request(&planner::GetWaypoints)
            .map(|w| w.waypoints)
    }

    /// A valid path exists (`GetPathValid`).
    pub fn path_valid(&self) -> bool {
        self.state().is_some_and(|s| s.valid)
    }

    /// The goal is reached (`GetPathDone`).
    pub fn path_done(&self) -> bool {
        self.state().is_some_and(|s| s.done)
    }

    /// Index of the current waypoint (-1 when none).
    pub fn waypoint_idx(&self) -> i32 {
        self.state().map_or(-1, |s| s.waypoint_idx)
    }

    /// Waypoints in the path.
    pub fn waypoint_count(&self) -> u32 {
        self.state().map_or(0, |s| s.waypoints_count)
    }
}

/// A localizer (`LocalizeProxy`).
pub struct LocalizeProxy {
    feed: Feed<Option<localize::Hypoths>>,
}

impl LocalizeProxy {
    /// Subscribes to `localize:index` of the client's robot.
    ///
    /// # Errors
    ///
    /// [`ClientError::Node`] if the subscription fails.
    pub fn new(client: &Client, index: u32) -> Result<Self> {
        Ok(LocalizeProxy {
            feed: Feed::new(
                client,
                Interface::Localize,
                index,
                only::<localize::Hypoths>,
            )?,
        })
    }

    /// The best hypothesis as nalgebra's types: its mean as an isometry
    /// and its covariance as a 3 × 3 matrix over (x, y, yaw); `None`
    /// before the localizer has said anything.
    pub fn estimate(&self) -> Option<(nalgebra::Isometry2<f64>, nalgebra::Matrix3<f64>)> {
        use crate::na::ToIsometry;
        let g = self.feed.get();
        let best = g.as_ref()?.hypoths.first()?;
        Some((best.isometry(), crate::na::covariance(&best.cov)))
    }

    /// The latest hypotheses, best first.
    pub fn hypoths(&self) -> Vec<localize::Hypoth> {
        self.feed
            .get()
            .as_ref()
            .map(|h| h.hypoths.clone())
            .unwrap_or_default()
    }

    /// Resets the filter around `mean` with covariance `cov` (`SetPose`): Player's
    /// order, xx, yy, yaw-yaw, xy, y-yaw, x-yaw.
    ///
    /// # Errors
    ///
    /// [`ClientError::Nack`] if the device refuses; [`ClientError::NoAnswer`].
    pub fn set_pose(&self, mean: Pose2d, cov: [f64; 6]) -> Result<()> {
        self.feed
            .link
            .request(&localize::SetPose { mean, cov })
            .map(|_| ())
    }

    /// The particle set.
    ///
    /// # Errors
    ///
    /// [`ClientError::Nack`] if the device refuses; [`ClientError::NoAnswer`].
    pub fn request_particles(&self) -> Result<localize::Particles> {
        self.feed.link.request(&localize::GetParticles)
    }
}

/// The simulator's world, by model name (`SimulationProxy`).
pub struct SimulationProxy {
    link: Link,
}

impl SimulationProxy {
    /// A proxy for `simulation:index` of the client's robot.
    pub fn new(client: &Client, index: u32) -> Self {
        SimulationProxy {
            link: Link::new(client, Interface::Simulation, index),
        }
    }

    /// The pose of model `name` (`GetPose2d`).
    ///
    /// # Errors
    ///
    /// [`ClientError::Nack`] for an unknown model; [`ClientError::NoAnswer`].
    pub fn get_pose2d(&self, name: &str) -> Result<Pose2d> {
        let req = simulation::GetPose2d { name: name.into() };
        self.link.request(&req).map(|r| r.pose)
    }

    /// Moves model `name` (`SetPose2d`).
    ///
    /// # Errors
    ///
    /// [`ClientError::Nack`] for an unknown model; [`ClientError::NoAnswer`].
    pub fn set_pose2d(&self, name: &str, x: f64, y: f64, yaw: f64) -> Result<()> {
        let req = simulation::SetPose2d {
            name: name.into(),
            pose: Pose2d::new(x, y, yaw),
        };
        self.link.request(&req).map(|_| ())
    }

    /// Property `prop` of model `name` (`GetProperty`).
    ///
    /// # Errors
    ///
    /// [`ClientError::Nack`] for an unknown model or property; [`ClientError::NoAnswer`].
    pub fn get_property(&self, name: &str, prop: &str) -> Result<simulation::Value> {
        let req = simulation::GetProperty {
            name: name.into(),
            prop: prop.into(),
        };
        self.link.request(&req).map(|r| r.value)
    }

    /// Sets property `prop` of model `name` (`SetProperty`), e.g. `"color"`.
    ///
    /// # Errors
    ///
    /// [`ClientError::Nack`] for an unknown model or property; [`ClientError::NoAnswer`].
    pub fn set_property(&self, name: &str, prop: &str, value: simulation::Value) -> Result<()> {
        let req = simulation::SetProperty {
            name: name.into(),
            prop: prop.into(),
            value,
        };
        self.link.request(&req).map(|_| ())
    }
}

/// Colour blobs in a camera image (`BlobfinderProxy`).
pub struct BlobfinderProxy {
    feed: Feed<Option<blobfinder::Data>>,
}

impl BlobfinderProxy {
    /// Subscribes to `blobfinder:index` of the client's robot.
    ///
    /// # Errors
    ///
    /// [`ClientError::Node`] if the subscription fails.
    pub fn new(client: &Client, index: u32) -> Result<Self> {
        Ok(BlobfinderProxy {
            feed: Feed::new(
                client,
                Interface::Blobfinder,
                index,
                only::<blobfinder::Data>,
            )?,
        })
    }

    /// The blobs, left to right.
    pub fn blobs(&self) -> Vec<blobfinder::Blob> {
        self.feed
            .get()
            .as_ref()
            .map(|d| d.blobs.clone())
            .unwrap_or_default()
    }

    /// Image width, pixels.
    pub fn width(&self) -> u32 {
        self.feed.get().as_ref().map_or(0, |d| d.width)
    }

    /// Image height, pixels.
    pub fn height(&self) -> u32 {
        self.feed.get().as_ref().map_or(0, |d| d.height)
    }
}

/// A gripper (`GripperProxy`).
pub struct GripperProxy {
    feed: Feed<Option<gripper::Data>>,
}

impl GripperProxy {
    /// Subscribes to `gripper:index` of the client's robot.
    ///
    /// # Errors
    ///
    /// [`ClientError::Node`] if the subscription fails.
    pub fn new(client: &Client, index: u32) -> Result<Self> {
        Ok(GripperProxy {
            feed: Feed::new(client, Interface::Gripper, index, only::<gripper::Data>)?,
        })
    }

    /// Opens the paddles.
    ///
    /// # Errors
    ///
    /// [`ClientError::Node`] if the command cannot be sent.
    pub fn open(&self) -> Result<()> {
        self.feed.link.command(&gripper::Open)
    }

    /// Closes the paddles.
    ///
    /// # Errors
    ///
    /// [`ClientError::Node`] if the command cannot be sent.
    pub fn close(&self) -> Result<()> {
        self.feed.link.command(&gripper::Close)
    }

    /// Stops the paddles.
    ///
    /// # Errors
    ///
    /// [`ClientError::Node`] if the command cannot be sent.
    pub fn stop(&self) -> Result<()> {
        self.feed.link.command(&gripper::Stop)
    }

    /// Paddle state.
    pub fn state(&self) -> gripper::State {
        self.feed.get().map(|d| d.state).unwrap_or_default()
    }

    /// Break-beam bitmask.
    pub fn beams(&self) -> u32 {
        self.feed.get().map_or(0, |d| d.beams)
    }

    /// Objects held.
    pub fn stored(&self) -> u8 {
        self.feed.get().map_or(0, |d| d.stored)
    }

    /// Geometry.
    ///
    /// # Errors
    ///
    /// [`ClientError::Nack`] if the device refuses; [`ClientError::NoAnswer`].
    pub fn request_geom(&self) -> Result<gripper::Geom> {
        self.feed.link.request(&gripper::GetGeom)
    }
}

/// Switches a device's power (any interface with Player's `POWER` request).
///
/// # Errors
///
/// [`ClientError::Nack`] if the device refuses; [`ClientError::NoAnswer`].
pub fn set_power(client: &Client, dev: Device, on: bool) -> Result<()> {
    client
        .request(dev, &common::Power { state: on })
        .map(|_| ())
}
