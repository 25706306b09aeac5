//! `slam`: a map built as the robot drives — the online side of
//! `troupe map build`, on the same algorithm (libs/slam).
//!
//! ```text
//! driver ( name "slam" requires ["odometry:::position2d:0" "laser:0"]
//!          provides ["map:0" "position2d:1"] resolution 0.05 )
//! ```
//!
//! | | |
//! |---|---|
//! | requires | a `position2d` (the odometry; key `odometry` where there are two) and a `laser` |
//! | provides | a `map` (the growing map), and optionally a `position2d` (the corrected pose) |
//! | options | `resolution` (0.05 m), `laser_pose` (the laser on the robot; default: asked of the laser), `map_every` (scans between refreshes of the served map, 10) |
//!
//! # Behavior
//!
//! - Each laser scan, with the latest odometry, goes to the SLAM front end:
//!   a keyframe every 0.3 m or 0.3 rad, matched against the last ones, loop
//!   closures with a graph optimisation (see libs/slam).
//! - Each keyframe's scan is traced into the occupancy grid from its pose
//!   in the graph, as `troupe map build` traces them; after a loop closure
//!   the grid is traced anew by the graph as it then stands, 100 keyframes
//!   at each new scan (the served grid grows meanwhile), and served when
//!   done.
//! - The map device answers `GET_INFO` and `GET_DATA` as `mapfile` does, from
//!   the grid as it stood at the last refresh (every `map_every` scans, and
//!   when a rebuild is done), and publishes its info at each refresh.
//! - The position2d device, if provided, publishes the odometry carried into
//!   the map's frame (the odometry's own frame at the first scan) by the
//!   graph, with odometry's velocities.

use serde::Deserialize;
use troupe_geom::occmap::OccMap;
use troupe_geom::Pose;
use troupe_msgs::{laser, map, position2d, Device, Interface};
use troupe_node::{Ctx, Driver, Event, NodeError, RequestId, Result, Section, Unit};
use troupe_slam::occupancy::Occupancy;
use troupe_slam::slam::{Params, Slam};
use troupe_slam::Scan;

/// Options, by name.
#[derive(Debug, Deserialize)]
#[serde(default)]
pub struct Options {
    /// Metres per cell.
    pub resolution: f64,
    /// The laser's pose on the robot, `[x y yaw]`; absent: asked of the laser.
    pub laser_pose: Option<Vec<f64>>,
    /// Scans between refreshes of the served map.
    pub map_every: u32,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            resolution: 0.05,
            laser_pose: None,
            map_every: 10,
        }
    }
}

/// Keyframes traced anew at each scan while the grid is rebuilt after a
/// loop closure: the served grid keeps growing meanwhile, and no scan waits
/// for the whole run to be traced again (a 900 s run is about 1,300
/// keyframes; 100 take about 11 ms, so a rebuild of that run is done 13
/// scans later).
const REBUILD_SHARE: usize = 100;

/// A grid being traced anew from the scans, by the graph as it now stands.
#[derive(Debug)]
struct Rebuild {
    grid: Occupancy,
    /// The next scan to trace.
    next: usize,
    /// The graph moved again since this rebuild began: another follows.
    again: bool,
}

impl Rebuild {
    fn new(res: f64) -> Rebuild {
        Rebuild {
            grid: Occupancy::new(res),
            next: 0,
            again: false,
        }
    }
}

/// The slam driver.
pub struct SlamNode {
    odom_dev: Device,
    laser_dev: Device,
    map_dev: Device,
    pose_dev: Option<Device>,
    sensor: Option<Pose>,
    geom_request: Option<RequestId>,
    odom: Option<Pose>,
    slam: Slam,
    grid: Occupancy,
    closures: usize,
    /// The grid being traced anew since the last loop closure.
    rebuild: Option<Rebuild>,
    since_refresh: u32,
    every: u32,
    map: OccMap,
}

impl SlamNode {
    /// The map as served now.
    pub fn map(&self) -> &OccMap {
        &self.map
    }

    /// The builder (keyframes, graph, closures).
    pub fn slam(&self) -> &Slam {
        &self.slam
    }

    /// Serves the grid as it stands, and says so on the map's data key (its
    /// info, Player's `PLAYER_MAP_DATA_INFO`): a view redraws the map.
    fn refresh(&mut self, ctx: &mut Ctx, t: f64) -> Result<()> {
        self.map = self.grid.to_occmap();
        self.since_refresh = 0;
        ctx.answer_always::<map::GetInfo>(&self.map_dev, &self.map.info)?;
        ctx.publish_at(&self.map_dev, &self.map.info, t)
    }

    fn scan(&mut self, ctx: &mut Ctx, t: f64, s: &laser::Scan) -> Result<()> {
        let (Some(odom), Some(sensor)) = (self.odom, self.sensor) else {
            return Ok(());
        };
        let scan = Scan::of_laser(t, s);
        let res = self.slam.params().resolution;
        let n = self.slam.keyframes.len();
        if self.slam.add(odom, &scan, sensor) {
            self.slam.trace(&mut self.grid, n..n + 1);
        }
        if self.slam.closures() != self.closures {
            // The graph moved: trace every keyframe again from where it now
            // puts it, a share at each scan; one more round if it moves
            // again meanwhile.
            self.closures = self.slam.closures();
            match &mut self.rebuild {
                Some(r) => r.again = true,
                None => self.rebuild = Some(Rebuild::new(res)),
            }
        }
        if let Some(r) = self.rebuild.as_mut() {
            let all = self.slam.keyframes.len();
            let end = (r.next + REBUILD_SHARE).min(all);
            self.slam.trace(&mut r.grid, r.next..end);
            r.next = end;
            if end == all {
                let done = std::mem::replace(r, Rebuild::new(res));
                self.grid = done.grid;
                if !done.again {
                    self.rebuild = None;
                }
                return self.refresh(ctx, t);
            }
        }
        self.since_refresh += 1;
        if self.since_refresh >= self.every {
            self.refresh(ctx, t)?;
        }
        Ok(())
    }
}

/// The driver fed a log as a launched stack feeds it, less the network:
/// each scan (at its stamp) after the odometry that places it, the laser
/// at `sensor` on the robot. `took` hears how long the driver spent on
/// each scan with its odometry. For the benchmark and the tests that hold
/// the online map against the offline build of the same log.
///
/// # Errors
///
/// What the driver returned for a message.
pub fn replay<'a>(
    sensor: Pose,
    placed: impl IntoIterator<Item = (Pose, &'a Scan)>,
    mut took: impl FnMut(std::time::Duration),
) -> Result<troupe_node::testing::Harness<SlamNode>> {
    const ODOM: Device = Device::new(6665, Interface::Position2d, 0);
    const LASER: Device = Device::new(6665, Interface::Laser, 0);
    let mut h = troupe_node::testing::Harness::<SlamNode>::from_json(&format!(
        r#"{{"name":"slam","requires":["odometry:::position2d:0","laser:0"],"provides":["map:0"],"options":{{"laser_pose":[{},{},{}]}}}}"#,
        sensor.x, sensor.y, sensor.yaw
    ))?;
    for (odom, s) in placed {
        let beams = s.ranges.len().max(1) as f64;
        let scan = laser::Scan {
            min_angle: s.min_angle as f32,
            max_angle: (s.min_angle + s.step * (beams - 1.0)) as f32,
            resolution: s.step as f32,
            max_range: s.max_range as f32,
            ranges: s.ranges.clone(),
            ..Default::default()
        };
        let data = position2d::Data {
            pose: odom.into(),
            ..Default::default()
        };
        h.set_time(s.t);
        let t0 = std::time::Instant::now();
        h.input(ODOM, &data)?;
        h.input(LASER, &scan)?;
        took(t0.elapsed());
    }
    Ok(h)
}

impl Driver for SlamNode {
    const NAME: &'static str = "slam";
    type Options = Options;
    const UNITS: &'static [(&'static str, Unit)] = &[
        ("resolution", Unit::Length),
        (
            "laser_pose",
            Unit::Tuple(&[Unit::Length, Unit::Length, Unit::Angle]),
        ),
    ];

    fn new(section: &Section, o: Options) -> Result<Self> {
        let bad = |why: String| NodeError::config(Self::NAME, why);
        if !(o.resolution > 0.0 && o.resolution.is_finite()) {
            return Err(bad(format!(
                "resolution must be a positive number of metres, not {}",
                o.resolution
            )));
        }
        let sensor = match o.laser_pose.as_deref() {
            None => None,
            Some([x, y, yaw]) => Some(Pose::new(*x, *y, *yaw)),
            Some(other) => return Err(bad(format!("laser_pose takes [x y yaw], not {other:?}"))),
        };
        let map_dev = section.provided_one(Interface::Map, None)?;
        let pose_dev = section
            .provided()
            .into_iter()
            .find(|s| s.device.interface == Interface::Position2d)
            .map(|s| s.device);
        let odom_dev = match section.required_one(Interface::Position2d, Some("odometry")) {
            Ok(d) => d,
            Err(_) => section.required_one(Interface::Position2d, None)?,
        };
        let params = Params {
            resolution: o.resolution,
            ..Params::default()
        };
        let grid = Occupancy::new(o.resolution);
        Ok(SlamNode {
            odom_dev,
            laser_dev: section.required_one(Interface::Laser, None)?,
            map_dev,
            pose_dev,
            sensor,
            geom_request: None,
            odom: None,
            slam: Slam::new(params),
            map: grid.to_occmap(),
            grid,
            closures: 0,
            rebuild: None,
            since_refresh: 0,
            every: o.map_every.max(1),
        })
    }

    fn setup(&mut self, ctx: &mut Ctx) -> Result<()> {
        ctx.subscribe(&self.odom_dev)?;
        ctx.subscribe(&self.laser_dev)?;
        if self.sensor.is_none() {
            self.geom_request = Some(ctx.request(&self.laser_dev, &laser::GetGeom)?);
        }
        ctx.answer_always::<map::GetInfo>(&self.map_dev, &self.map.info)
    }

    fn on_event(&mut self, ctx: &mut Ctx, event: Event) -> Result<()> {
        match event {
            Event::Data(s) if s.device == self.odom_dev && s.is::<position2d::Data>() => {
                let d = s.decode::<position2d::Data>()?;
                let odom: Pose = d.msg.pose.into();
                self.odom = Some(odom);
                if let Some(dev) = self.pose_dev {
                    let at = self.slam.pose_of(odom);
                    let out = position2d::Data {
                        pose: at.into(),
                        ..d.msg
                    };
                    ctx.publish_at(&dev, &out, d.stamp)?;
                }
                Ok(())
            }
            Event::Data(s) if s.device == self.laser_dev && s.is::<laser::Scan>() => {
                let d = s.decode::<laser::Scan>()?;
                self.scan(ctx, d.stamp, &d.msg)
            }
            Event::Data(s) => Err(s.unexpected()),
            Event::Reply(r) if Some(r.id) == self.geom_request => {
                self.geom_request = None;
                let pose = match r.decode::<laser::Geom>() {
                    Ok(g) => Pose::new(g.pose.x, g.pose.y, g.pose.yaw),
                    Err(e) => {
                        tracing::warn!(
                            "the laser's geometry: {e}; taking it at the robot's centre (set laser_pose)"
                        );
                        Pose::default()
                    }
                };
                self.sensor = Some(pose);
                Ok(())
            }
            Event::Request(r) if r.sample.device == self.map_dev => {
                troupe_mapfile::serve(&self.map, &self.map_dev, r)
            }
            Event::Request(r) => {
                r.unhandled(Self::NAME);
                Ok(())
            }
            Event::Command(c) => {
                tracing::debug!("slam takes no commands; ignored `{}`", c.key);
                Ok(())
            }
            Event::Reply(_) | Event::Tick | Event::Wake => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests;
