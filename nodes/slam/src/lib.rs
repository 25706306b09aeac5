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
//! - Every scan is traced into the occupancy grid from its corrected pose;
//!   after a loop closure the grid is traced anew from the keyframes' scans.
//! - The map device answers `GET_INFO` and `GET_DATA` as `mapfile` does, from
//!   the grid as it stood at the last refresh (every `map_every` scans, and
//!   after a loop closure), and publishes its info at each refresh.
//! - The position2d device, if provided, publishes the odometry carried into
//!   the map's frame (the odometry's own frame at the first scan) by the
//!   graph, with odometry's velocities.

use serde::Deserialize;
use troupe_geom::occmap::{OccMap, FREE, OCCUPIED, UNKNOWN};
use troupe_geom::Pose;
use troupe_msgs::{laser, map, position2d, Device, Interface, Pose2d};
use troupe_node::{Ctx, Driver, Event, NodeError, RequestId, Result, Section, Unit};
use troupe_slam::occupancy::{Cell, Occupancy};
use troupe_slam::slam::{self, Params, Slam};
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
    /// Every scan since the start with its odometry, to trace the grid
    /// anew after a loop closure.
    traced: Vec<(Pose, Scan)>,
    closures: usize,
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
        self.map = to_occmap(&self.grid);
        self.since_refresh = 0;
        ctx.answer_always::<map::GetInfo>(&self.map_dev, &self.map.info)?;
        ctx.publish_at(&self.map_dev, &self.map.info, t)
    }

    fn scan(&mut self, ctx: &mut Ctx, t: f64, s: &laser::Scan) -> Result<()> {
        let (Some(odom), Some(sensor)) = (self.odom, self.sensor) else {
            return Ok(());
        };
        let scan = Scan {
            t,
            min_angle: f64::from(s.min_angle),
            step: f64::from(s.resolution),
            max_range: f64::from(s.max_range),
            ranges: s.ranges.clone(),
        };
        let res = self.slam.params().resolution;
        if self.slam.due(odom) {
            let (pts, reach) = slam::points(&scan, sensor, res);
            self.slam.add(t, odom, pts, reach);
        }
        self.traced.push((odom, scan));
        let place = |sc: &Scan, o: Pose| self.slam.corrected(sc.t, o).compose(&sensor);
        if self.slam.closures != self.closures {
            // The graph moved: trace every scan again from where it now puts it.
            self.closures = self.slam.closures;
            let mut grid = Occupancy::new(res);
            for (o, sc) in &self.traced {
                grid.add_scan(place(sc, *o), sc);
            }
            self.grid = grid;
            return self.refresh(ctx, t);
        }
        if let Some((o, sc)) = self.traced.last() {
            let at = place(sc, *o);
            self.grid.add_scan(at, sc);
        }
        self.since_refresh += 1;
        if self.since_refresh >= self.every {
            self.refresh(ctx, t)?;
        }
        Ok(())
    }
}

/// The grid as a map device serves it.
fn to_occmap(grid: &Occupancy) -> OccMap {
    let (w, h) = grid.size();
    let (x0, y0) = grid.origin();
    let info = map::Info {
        width: w as u32,
        height: h as u32,
        resolution: grid.res() as f32,
        origin: Pose2d::new(x0, y0, 0.0),
    };
    if w == 0 || h == 0 {
        return OccMap::filled(info, UNKNOWN);
    }
    OccMap::from_fn(info, |i, j| match grid.cell(i, j) {
        Cell::Occupied => OCCUPIED,
        Cell::Free => FREE,
        Cell::Unknown => UNKNOWN,
    })
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
            map: to_occmap(&grid),
            grid,
            traced: Vec::new(),
            closures: 0,
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
