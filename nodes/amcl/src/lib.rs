//! Player's `amcl`: adaptive Monte Carlo localization on a map with odometry
//! and a laser or a sonar ring.
//!
//! ```text
//! driver ( name "amcl" provides ["localize:0" "position2d:2"]
//!          requires ["odometry:::position2d:0" "laser:0" "laser:::map:0"]
//!          init_pose [-6.9 -6.9 45] init_pose_var [0.2 0.2 10] )
//! ```
//!
//! | | |
//! |---|---|
//! | requires | `odometry:::position2d` (odometry), a `laser` and `laser:::map` (the map the laser sees), or a `sonar` and `sonar:::map` |
//! | provides | `localize` (hypotheses, particles, set pose), `position2d` (the best hypothesis) — at least one |
//!
//! Options, Player's names and defaults: `pf_min_samples` 100,
//! `pf_max_samples` 10000, `pf_err` 0.01, `pf_z` 3, `init_pose` [0 0 0],
//! `init_pose_var` [1 1 360] (standard deviations, m m deg), `update_thresh`
//! [0.2 30] (m deg), `laser_max_beams` 6, `laser_range_var` 0.1 (σ, m),
//! `laser_range_bad` 0.1. Troupe adds `laser_model_type` (`beam`, Player's
//! and the default, or `likelihood_field` with `laser_z_hit` 0.95,
//! `laser_z_rand` 0.05, `laser_sigma_hit` 0.2, `laser_likelihood_max_dist` 2
//! as ROS's amcl) and `seed`
//! (42) for repeatable runs. Odometry drift, Player's `odom_drift[0]`,
//! `odom_drift[1]`, `odom_drift[2]` (rows x, y, θ of how much of each
//! motion becomes noise): [0.2 0 0], [0 0.2 0], [0.2 0 0.2].
//!
//! # Behavior
//!
//! - At setup the map comes from the map device (info, then the whole grid)
//!   and the laser's pose on the robot from its geometry (zero, with a
//!   warning, if the laser refuses), or each sonar transducer's (a sonar
//!   that gives none stops amcl: it cannot weigh a pose without them).
//! - With a sonar, each update weighs particles by Player's sonar model
//!   (amcl's `models/sonar.c`, which Player 3's amcl no longer wires up):
//!   every reading within 2 m against the range traced from its transducer
//!   in the map, `0.2 + 0.8 · N(0, 0.2²)` of the difference. The filter starts with `pf_max_samples`
//!   particles drawn around `init_pose`.
//! - The first odometry sample is the reference. Once odometry has moved
//!   more than `update_thresh` (x, y or θ) from the last update, the next
//!   laser scan updates the filter: every particle moves by the odometric
//!   step with noise, is weighted by the scan, and the set is resampled to
//!   the KLD bound. Odometry is always the latest sample and a scan is the
//!   latest one (the runtime replaces queued samples), so a filter slower
//!   than its inputs works on fresh data and never falls behind a backlog.
//! - The update runs on amcl's own filter thread. Meanwhile the driver goes
//!   on taking odometry and publishing the pose carried along by it; a
//!   reading that comes meanwhile is dropped (the next one after the update
//!   is fresher), and `set_pose` and `particles` are answered once the
//!   update is back. (With 50 000 particles on a loaded machine, an update
//!   done on the driver's thread held the pose back by up to 6 simulated s
//!   and r0's trip across the cave took twice as long.)
//! - After each update `localize` publishes every hypothesis (cluster of
//!   particles, heaviest first, at most 100) with its weight, mean and
//!   covariance (Player's six terms); `position2d` publishes the best
//!   hypothesis, and between updates the best hypothesis moved by the
//!   odometry since (one sample per odometry sample). As Player's does,
//!   `localize` also publishes the initial hypotheses at start-up and after
//!   every `set_pose` (the particles as drawn), robot moving or not;
//!   `position2d` waits for the first update.
//! - `set_pose` restarts the filter around the given mean and covariance
//!   (variances, Player's order); `particles` returns every particle with
//!   the set's mean and spread; `position2d` `geom` answers a 1 cm robot.

pub mod laser;
pub mod pf;

use std::sync::{mpsc, Arc};

use serde::Deserialize;
use troupe_geom::occmap::OccMap;
use troupe_geom::Pose;
use troupe_msgs::{
    common, laser as laser_msg, localize, position2d, sonar, Device, Interface, Pose2d, Pose3d,
    Size3d,
};
use troupe_node::{
    Ctx, Driver, Event, MapFetch, NodeError, Request, RequestId, Result, Section, Unit, Waker,
};

use crate::laser::{Beams, DistanceMap, Model};
use crate::pf::Filter;

/// Options, by Player's names (see the crate docs for defaults).
#[derive(Debug, Deserialize)]
#[serde(default)]
pub struct Options {
    /// Fewest particles.
    pub pf_min_samples: usize,
    /// Most particles.
    pub pf_max_samples: usize,
    /// KLD ε.
    pub pf_err: f64,
    /// KLD z.
    pub pf_z: f64,
    /// Initial mean: x, y (m), yaw (rad).
    pub init_pose: Vec<f64>,
    /// Initial standard deviations: x, y (m), yaw (rad).
    pub init_pose_var: Vec<f64>,
    /// Update after this much odometric motion: distance (m), angle (rad).
    pub update_thresh: Vec<f64>,
    /// Beams of a scan used per update.
    pub laser_max_beams: usize,
    /// σ of a range (m), the beam model.
    pub laser_range_var: f64,
    /// Floor for an unexplained range, the beam model.
    pub laser_range_bad: f64,
    /// `beam` or `likelihood_field`.
    pub laser_model_type: String,
    /// Likelihood field: weight of hits.
    pub laser_z_hit: f64,
    /// Likelihood field: weight of random ranges.
    pub laser_z_rand: f64,
    /// Likelihood field: σ of a hit (m).
    pub laser_sigma_hit: f64,
    /// Likelihood field: distances are capped here (m).
    pub laser_likelihood_max_dist: f64,
    /// Random seed.
    pub seed: u64,
    /// Odometry drift, row x: how much of the x, y and θ motion becomes
    /// noise on x (Player's `odom_drift[0]`).
    #[serde(rename = "odom_drift[0]")]
    pub odom_drift_0: Vec<f64>,
    /// Row y (`odom_drift[1]`).
    #[serde(rename = "odom_drift[1]")]
    pub odom_drift_1: Vec<f64>,
    /// Row θ (`odom_drift[2]`).
    #[serde(rename = "odom_drift[2]")]
    pub odom_drift_2: Vec<f64>,
    /// Player's, unused.
    pub odom_init: Option<f64>,
    /// Player's GUI switch, unused.
    pub enable_gui: Option<f64>,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            pf_min_samples: 100,
            pf_max_samples: 10_000,
            pf_err: 0.01,
            pf_z: 3.0,
            init_pose: vec![0.0, 0.0, 0.0],
            init_pose_var: vec![1.0, 1.0, std::f64::consts::TAU],
            update_thresh: vec![0.2, std::f64::consts::PI / 6.0],
            laser_max_beams: 6,
            laser_range_var: 0.1,
            laser_range_bad: 0.1,
            laser_model_type: "beam".into(),
            laser_z_hit: 0.95,
            laser_z_rand: 0.05,
            laser_sigma_hit: 0.2,
            laser_likelihood_max_dist: 2.0,
            seed: 42,
            odom_drift_0: DRIFT[0].to_vec(),
            odom_drift_1: DRIFT[1].to_vec(),
            odom_drift_2: DRIFT[2].to_vec(),
            odom_init: None,
            enable_gui: None,
        }
    }
}

/// Player's default odometry drift.
const DRIFT: [[f64; 3]; 3] = [[0.2, 0.0, 0.0], [0.0, 0.2, 0.0], [0.2, 0.0, 0.2]];

/// Odometry samples kept to pair scans with the pose of their time.
const ODOM_HISTORY: usize = 64;

/// Hypotheses published at most (Player's cluster limit).
const MAX_HYPOTHS: usize = 100;

/// The hypotheses before any update: the clusters of the particles as drawn.
fn prior(filter: &Filter) -> Vec<pf::Cluster> {
    let mut h = filter.clusters();
    h.truncate(MAX_HYPOTHS);
    h
}

/// `a` in the frame of `b` (Player's `coord_sub`).
fn relative(a: &Pose, b: &Pose) -> Pose {
    b.inverse().compose(a)
}

/// The angle between a scan's beams. The first beam looks along
/// `min_angle` and the last along `max_angle`; where `resolution` says
/// otherwise, the ends win. Stage's ranger, through rangertolaser, reports
/// `fov / samples` for samples spread `fov / (samples − 1)` apart: read as
/// given, the last beam of a 180-beam scan is a degree off and the pose
/// estimate is pulled aside.
fn bearing_step(scan: &laser_msg::Scan) -> f64 {
    let (n, lo, hi) = (
        scan.ranges.len(),
        f64::from(scan.min_angle),
        f64::from(scan.max_angle),
    );
    if n > 1 && hi > lo {
        (hi - lo) / (n - 1) as f64
    } else {
        f64::from(scan.resolution)
    }
}

/// The localizer without the network: odometry and scans in, estimates out.
pub struct Localizer {
    /// `None` while an update has it ([`Localizer::start`]).
    filter: Option<Filter>,
    model: Model,
    max_beams: usize,
    thresh: (f64, f64),
    drift: [[f64; 3]; 3],
    map: Option<Arc<DistanceMap>>,
    laser_pose: Pose,
    /// The sonar transducers' poses on the robot, when a sonar is the sensor.
    sonar_poses: Arc<[Pose]>,
    /// Odometry at the last filter update; `None` until the first sample.
    odom_ref: Option<Pose>,
    /// Recent odometry, (stamp, pose), oldest first.
    odom: std::collections::VecDeque<(f64, Pose)>,
    /// A scan waiting for the odometry of its time.
    pending: Option<(f64, Reading)>,
    /// The next scan updates the filter.
    due: bool,
    /// The first update weighs the initial cloud without moving it.
    moved: bool,
    best: Option<Pose>,
    /// The stamp of the scan of the last update.
    updated_at: Option<f64>,
    hypoths: Vec<pf::Cluster>,
    updates: u64,
}

/// An option whose value Player would not accept.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OptionError {
    /// Not a sensor model amcl knows.
    #[error("laser_model_type `{0}` is not known: `beam` (Player's) or `likelihood_field`")]
    LaserModel(String),
    /// A pose option without its three values.
    #[error("{name} needs three values (x y yaw), not {values:?}")]
    NotThree {
        /// The option.
        name: &'static str,
        /// What it holds.
        values: Vec<f64>,
    },
    /// A drift row that is not up to three fractions.
    #[error(
        "odom_drift[{row}] needs up to three non-negative fractions (of x, y and θ motion), not {values:?}"
    )]
    Drift {
        /// Which row.
        row: usize,
        /// What it holds.
        values: Vec<f64>,
    },
    /// `update_thresh` without its two values.
    #[error("update_thresh needs a distance and an angle, not {0:?}")]
    UpdateThresh(Vec<f64>),
    /// The particle counts are the wrong way round or zero.
    #[error(
        "pf_min_samples ({min}) must not exceed pf_max_samples ({max}), which must be positive"
    )]
    Samples {
        /// `pf_min_samples`.
        min: usize,
        /// `pf_max_samples`.
        max: usize,
    },
    /// The KLD bounds are not positive.
    #[error("pf_err and pf_z must be positive")]
    PfBounds,
}

impl Localizer {
    /// A localizer from the driver's options.
    ///
    /// # Errors
    ///
    /// An option has a value Player would not accept.
    pub fn new(o: &Options) -> std::result::Result<Self, OptionError> {
        let model = match o.laser_model_type.as_str() {
            "beam" => Model::Beam {
                sigma: o.laser_range_var,
                bad: o.laser_range_bad,
            },
            "likelihood_field" => Model::LikelihoodField {
                z_hit: o.laser_z_hit,
                z_rand: o.laser_z_rand,
                sigma_hit: o.laser_sigma_hit,
                max_dist: o.laser_likelihood_max_dist,
            },
            other => return Err(OptionError::LaserModel(other.to_owned())),
        };
        let three = |name: &'static str, v: &[f64]| match v {
            [a, b, c] => Ok([*a, *b, *c]),
            _ => Err(OptionError::NotThree {
                name,
                values: v.to_vec(),
            }),
        };
        // Player reads each drift row element by element, a missing one at
        // its default.
        let mut drift = DRIFT;
        for (k, row) in [&o.odom_drift_0, &o.odom_drift_1, &o.odom_drift_2]
            .into_iter()
            .enumerate()
        {
            if row.len() > 3 || row.iter().any(|v| !v.is_finite() || *v < 0.0) {
                return Err(OptionError::Drift {
                    row: k,
                    values: row.clone(),
                });
            }
            drift[k][..row.len()].copy_from_slice(row);
        }
        let mean = three("init_pose", &o.init_pose)?;
        let sd = three("init_pose_var", &o.init_pose_var)?;
        let thresh = match o.update_thresh.as_slice() {
            [d, a] => (*d, *a),
            v => return Err(OptionError::UpdateThresh(v.to_vec())),
        };
        if o.pf_max_samples == 0 || o.pf_min_samples > o.pf_max_samples {
            return Err(OptionError::Samples {
                min: o.pf_min_samples,
                max: o.pf_max_samples,
            });
        }
        if o.pf_err.is_nan() || o.pf_err <= 0.0 || o.pf_z.is_nan() || o.pf_z <= 0.0 {
            return Err(OptionError::PfBounds);
        }
        let config = pf::Config {
            min_samples: o.pf_min_samples,
            max_samples: o.pf_max_samples,
            err: o.pf_err,
            z: o.pf_z,
        };
        let mut filter = Filter::new(config, o.seed);
        filter.init(
            Pose::new(mean[0], mean[1], mean[2]),
            &[
                [sd[0] * sd[0], 0.0, 0.0],
                [0.0, sd[1] * sd[1], 0.0],
                [0.0, 0.0, sd[2] * sd[2]],
            ],
        );
        let hypoths = prior(&filter);
        Ok(Localizer {
            filter: Some(filter),
            model,
            max_beams: o.laser_max_beams,
            thresh,
            drift,
            map: None,
            laser_pose: Pose::default(),
            sonar_poses: Arc::new([]),
            odom_ref: None,
            odom: std::collections::VecDeque::new(),
            pending: None,
            due: false,
            moved: false,
            best: None,
            updated_at: None,
            hypoths,
            updates: 0,
        })
    }

    /// Sets the map the laser sees.
    pub fn set_map(&mut self, map: &OccMap) {
        self.map = Some(Arc::new(DistanceMap::new(map)));
    }

    /// Sets the laser's pose on the robot.
    pub fn set_laser_pose(&mut self, p: Pose) {
        self.laser_pose = p;
    }

    /// Sets the sonar transducers' poses on the robot.
    pub fn set_sonar_poses(&mut self, poses: Vec<Pose>) {
        self.sonar_poses = poses.into();
    }

    /// Restarts the filter around `mean` with covariance `cov` (Player's
    /// six terms). False, and nothing done, while an update is out: call
    /// again once it is back.
    pub fn set_pose(&mut self, mean: Pose, cov: &[f64; 6]) -> bool {
        let Some(filter) = &mut self.filter else {
            return false;
        };
        let c = [
            [cov[0], cov[3], cov[5]],
            [cov[3], cov[1], cov[4]],
            [cov[5], cov[4], cov[2]],
        ];
        filter.init(mean, &c);
        self.hypoths = prior(filter);
        self.updated_at = None;
        self.odom_ref = None;
        self.due = false;
        self.pending = None;
        true
    }

    /// Takes an odometry pose stamped `stamp`; returns the pose estimate
    /// to publish now, if any.
    pub fn odometry(&mut self, odom: Pose, stamp: f64) -> Option<Pose> {
        if self.odom.back().is_some_and(|&(t, _)| t > stamp) {
            self.odom.clear(); // the clock went back: a new run
        }
        if self.odom.len() == ODOM_HISTORY {
            self.odom.pop_front();
        }
        self.odom.push_back((stamp, odom));
        let Some(r) = self.odom_ref else {
            self.odom_ref = Some(odom);
            self.due = true;
            self.moved = false;
            return None;
        };
        let d = relative(&odom, &r);
        if d.x.abs() > self.thresh.0 || d.y.abs() > self.thresh.0 || d.yaw.abs() > self.thresh.1 {
            self.due = true;
            self.moved = true;
        }
        self.now().map(|(_, p)| p)
    }

    /// The pose now: the best hypothesis of the last update carried along by
    /// the odometry since, stamped with the newest odometry. The hypothesis
    /// alone is of the pose when its scan was taken, which a slow update
    /// leaves far behind.
    pub fn now(&self) -> Option<(f64, Pose)> {
        let (b, r, &(t, odom)) = (self.best?, self.odom_ref?, self.odom.back()?);
        Some((t, b.compose(&relative(&odom, &r))))
    }

    /// The stamp of the scan of the last update.
    pub fn updated_at(&self) -> Option<f64> {
        self.updated_at
    }

    /// Takes a scan stamped `stamp` and updates the filter with it at
    /// once; returns true when it did. A scan newer than the latest
    /// odometry waits for odometry of its time (see [`Localizer::poll`]).
    pub fn scan(&mut self, scan: &laser_msg::Scan, stamp: f64) -> bool {
        self.offer_scan(scan, stamp);
        self.poll()
    }

    /// Keeps a scan stamped `stamp` for the next update when one is due
    /// (see [`Localizer::start`]).
    pub fn offer_scan(&mut self, scan: &laser_msg::Scan, stamp: f64) {
        if !self.due {
            return;
        }
        let beams = Beams::pick(
            &scan.ranges,
            f64::from(scan.min_angle),
            bearing_step(scan),
            f64::from(scan.max_range),
            self.max_beams,
        );
        self.pending = Some((stamp, Reading::Laser(beams)));
    }

    /// Takes a sonar ring's ranges stamped `stamp` (one per transducer, in
    /// the order of [`Localizer::set_sonar_poses`]) and updates the filter
    /// with them at once; returns true when it did.
    pub fn sonar(&mut self, ranges: &[f32], stamp: f64) -> bool {
        self.offer_sonar(ranges, stamp);
        self.poll()
    }

    /// Keeps a sonar reading for the next update when one is due.
    pub fn offer_sonar(&mut self, ranges: &[f32], stamp: f64) {
        if self.due {
            let ranges = ranges.iter().map(|&r| f64::from(r)).collect();
            self.pending = Some((stamp, Reading::Sonar(ranges)));
        }
    }

    /// The odometric pose at time `t`, interpolated; `None` while odometry
    /// has not reached `t`.
    fn odom_at(&self, t: f64) -> Option<Pose> {
        let &(last_t, _) = self.odom.back()?;
        if last_t < t - 1e-9 {
            return None;
        }
        // The first sample at or after t; one before it to interpolate from.
        let k = self.odom.iter().position(|&(s, _)| s >= t - 1e-9)?;
        let (t1, p1) = self.odom[k];
        if k == 0 || t1 - t <= 1e-9 {
            return Some(p1);
        }
        let (t0, p0) = self.odom[k - 1];
        let f = ((t - t0) / (t1 - t0)).clamp(0.0, 1.0);
        let d = relative(&p1, &p0);
        Some(p0.compose(&Pose::new(d.x * f, d.y * f, d.yaw * f)))
    }

    /// Updates the filter with a waiting reading once odometry has caught
    /// up with it; returns true when it did. [`Localizer::start`] and
    /// [`Localizer::finish`] with the update run in between.
    pub fn poll(&mut self) -> bool {
        match self.start() {
            Some(update) => {
                self.finish(update.run());
                true
            }
            None => false,
        }
    }

    /// The update a waiting reading makes once odometry has caught up with
    /// it, to run anywhere ([`Update::run`]) and hand back to
    /// [`Localizer::finish`]. It takes the filter along: until it is back,
    /// the pose goes on being the last update's carried along by odometry,
    /// readings wait, and [`Localizer::filter`] is `None`.
    pub fn start(&mut self) -> Option<Update> {
        let stamp = self.pending.as_ref()?.0;
        let (Some(map), Some(odom), Some(r)) = (&self.map, self.odom_at(stamp), self.odom_ref)
        else {
            return None;
        };
        let map = map.clone();
        let filter = self.filter.take()?;
        let (_, reading) = self.pending.take()?;
        Some(Update {
            filter,
            step: self.moved.then(|| (relative(&odom, &r), self.drift)),
            reading,
            map,
            model: self.model,
            laser_pose: self.laser_pose,
            sonar_poses: self.sonar_poses.clone(),
            stamp,
            odom,
        })
    }

    /// Takes back the filter of an update: its hypotheses become the
    /// estimate, and odometry is counted from the pose of its reading.
    pub fn finish(&mut self, done: Updated) {
        self.filter = Some(done.filter);
        self.hypoths = done.hypoths;
        if let Some(h) = self.hypoths.first() {
            self.best = Some(h.mean);
        }
        self.odom_ref = Some(done.odom);
        self.updated_at = Some(done.stamp);
        // What came in meanwhile was weighed against the old reference: the
        // next odometry sample decides afresh.
        self.pending = None;
        self.due = false;
        self.moved = false;
        self.updates += 1;
    }

    /// True while an update has the filter.
    pub fn busy(&self) -> bool {
        self.filter.is_none()
    }

    /// The best hypothesis so far.
    pub fn best(&self) -> Option<Pose> {
        self.best
    }

    /// The hypotheses of the last update, heaviest first.
    pub fn hypotheses(&self) -> &[pf::Cluster] {
        &self.hypoths
    }

    /// The particle filter; `None` while an update has it.
    pub fn filter(&self) -> Option<&Filter> {
        self.filter.as_ref()
    }

    /// Filter updates so far.
    pub fn updates(&self) -> u64 {
        self.updates
    }
}

/// One filter update: the filter with what moves and weighs it. The
/// costly part of amcl, run off the driver's thread.
pub struct Update {
    filter: Filter,
    /// The odometric step since the last update and the drift it adds.
    step: Option<(Pose, [[f64; 3]; 3])>,
    reading: Reading,
    map: Arc<DistanceMap>,
    model: Model,
    laser_pose: Pose,
    sonar_poses: Arc<[Pose]>,
    /// The reading's stamp, and the odometry of that time.
    stamp: f64,
    odom: Pose,
}

impl Update {
    /// Moves every particle by the odometric step, weighs it by the
    /// reading, resamples and clusters.
    pub fn run(mut self) -> Updated {
        if let Some((delta, drift)) = &self.step {
            self.filter.action(*delta, drift);
        }
        let map = &*self.map;
        match &self.reading {
            Reading::Laser(beams) if !beams.beams.is_empty() => {
                let (model, laser) = (self.model, self.laser_pose);
                self.filter
                    .sensor(|p| model.likelihood_on(map, p, &laser, beams));
            }
            Reading::Sonar(ranges) if !self.sonar_poses.is_empty() => {
                let sonars = &*self.sonar_poses;
                self.filter
                    .sensor(|p| laser::sonar_likelihood(map, p, sonars, ranges));
            }
            Reading::Laser(_) | Reading::Sonar(_) => {}
        }
        self.filter.resample();
        let mut hypoths = self.filter.clusters();
        hypoths.truncate(MAX_HYPOTHS);
        Updated {
            filter: self.filter,
            hypoths,
            stamp: self.stamp,
            odom: self.odom,
        }
    }
}

/// An update that has run, for [`Localizer::finish`].
pub struct Updated {
    filter: Filter,
    hypoths: Vec<pf::Cluster>,
    stamp: f64,
    odom: Pose,
}

/// A range reading waiting to update the filter.
enum Reading {
    Laser(Beams),
    Sonar(Vec<f64>),
}

/// The range sensor amcl weighs particles by.
#[derive(Clone, Copy)]
enum Sensor {
    Laser(Device),
    Sonar(Device),
}

impl Sensor {
    fn device(self) -> Device {
        match self {
            Sensor::Laser(d) | Sensor::Sonar(d) => d,
        }
    }
}

/// The amcl driver.
pub struct Amcl {
    localize: Option<Device>,
    position: Option<Device>,
    odom: Device,
    sensor: Sensor,
    map: Device,
    loc: Localizer,
    /// The map, while it is being fetched.
    fetch: Option<MapFetch>,
    geom: Option<RequestId>,
    /// Runs the updates; started by `setup`.
    worker: Option<Worker>,
    /// Requests for the filter that came while an update had it.
    deferred: Vec<Request>,
}

/// amcl's filter thread: runs the updates handed to it, one at a time,
/// and wakes the driver when one is done. Meanwhile the driver goes on
/// answering each odometry sample with the pose carried along by it: a
/// filter slower than the robot's odometry (50 000 particles on a busy
/// machine) delays its corrections, never the pose.
struct Worker {
    updates: mpsc::Sender<Update>,
    done: mpsc::Receiver<Updated>,
}

impl Worker {
    fn spawn(waker: Waker) -> Result<Worker> {
        let (updates, todo) = mpsc::channel::<Update>();
        let (finished, done) = mpsc::channel();
        std::thread::Builder::new()
            .name("amcl-filter".into())
            .spawn(move || {
                // Ends when the driver, and with it `updates`, is gone.
                for update in todo {
                    if finished.send(update.run()).is_err() {
                        break;
                    }
                    waker.wake();
                }
            })
            .map_err(|e| NodeError::Driver(Box::new(e)))?;
        Ok(Worker { updates, done })
    }
}

fn filter_thread_gone() -> NodeError {
    NodeError::Driver("amcl's filter thread has stopped".into())
}

impl Driver for Amcl {
    const NAME: &'static str = "amcl";
    type Options = Options;
    const UNITS: &'static [(&'static str, Unit)] = &[
        (
            "init_pose",
            Unit::Tuple(&[Unit::Length, Unit::Length, Unit::Angle]),
        ),
        (
            "init_pose_var",
            Unit::Tuple(&[Unit::Length, Unit::Length, Unit::Angle]),
        ),
        ("update_thresh", Unit::Tuple(&[Unit::Length, Unit::Angle])),
        ("laser_range_var", Unit::Length),
        ("laser_sigma_hit", Unit::Length),
        ("laser_likelihood_max_dist", Unit::Length),
    ];

    fn new(section: &Section, o: Options) -> Result<Self> {
        let provided = |i: Interface| {
            section
                .provided()
                .into_iter()
                .find(|s| s.device.interface == i)
                .map(|s| s.device)
        };
        let (localize, position) = (
            provided(Interface::Localize),
            provided(Interface::Position2d),
        );
        if localize.is_none() && position.is_none() {
            return Err(NodeError::config(
                Self::NAME,
                "`provides` needs a localize or a position2d device (e.g. [\"localize:0\" \"position2d:2\"])",
            ));
        }
        let loc = Localizer::new(&o).map_err(|e| NodeError::config(Self::NAME, e.to_string()))?;
        let odom = section.required_one(Interface::Position2d, Some("odometry"))?;
        // A laser, else a sonar ring, with the map keyed by it.
        let has = |i: Interface| section.required().iter().any(|s| s.device.interface == i);
        let (sensor, map) = if !has(Interface::Laser) && has(Interface::Sonar) {
            (
                Sensor::Sonar(section.required_one(Interface::Sonar, None)?),
                section.required_one(Interface::Map, Some("sonar"))?,
            )
        } else {
            (
                Sensor::Laser(section.required_one(Interface::Laser, None)?),
                section.required_one(Interface::Map, Some("laser"))?,
            )
        };
        Ok(Amcl {
            localize,
            position,
            odom,
            sensor,
            map,
            loc,
            fetch: None,
            geom: None,
            worker: None,
            deferred: Vec::new(),
        })
    }

    fn setup(&mut self, ctx: &mut Ctx) -> Result<()> {
        self.worker = Some(Worker::spawn(ctx.waker())?);
        self.fetch = Some(MapFetch::start(ctx, self.map)?);
        self.geom = Some(match self.sensor {
            Sensor::Laser(d) => ctx.request(&d, &laser_msg::GetGeom)?,
            Sensor::Sonar(d) => ctx.request(&d, &sonar::GetGeom)?,
        });
        ctx.subscribe(&self.odom)?;
        ctx.subscribe(&self.sensor.device())?;
        // Player's amcl says where it starts at once: a client that opens
        // localize while the robot stands still gets the initial estimate.
        self.publish_hypotheses(ctx)
    }

    fn on_event(&mut self, ctx: &mut Ctx, event: Event) -> Result<()> {
        match event {
            Event::Data(s) if s.device == self.odom && s.is::<position2d::Data>() => {
                let d = s.decode::<position2d::Data>()?;
                self.loc.odometry(d.msg.pose.into(), d.stamp);
                self.start_update()?;
                self.publish_pose(ctx)
            }
            Event::Data(s) if s.device == self.sensor.device() && s.is::<laser_msg::Scan>() => {
                let scan = s.decode::<laser_msg::Scan>()?;
                self.loc.offer_scan(&scan.msg, scan.stamp);
                self.start_update()
            }
            Event::Data(s) if s.device == self.sensor.device() && s.is::<sonar::Ranges>() => {
                let d = s.decode::<sonar::Ranges>()?;
                self.loc.offer_sonar(&d.msg.ranges, d.stamp);
                self.start_update()
            }
            Event::Data(s) => Err(s.unexpected()),
            Event::Reply(r) => self.on_reply(ctx, r),
            Event::Request(r) if r.is::<localize::SetPose>() => {
                let q = r.decode::<localize::SetPose>()?;
                if !self.loc.set_pose(q.mean.into(), &q.cov) {
                    self.deferred.push(r); // an update has the filter: after it
                    return Ok(());
                }
                tracing::info!(
                    "filter reset around ({:.3}, {:.3}, {:.3})",
                    q.mean.x,
                    q.mean.y,
                    q.mean.yaw
                );
                r.reply(&common::Ack);
                self.publish_hypotheses(ctx)
            }
            Event::Request(r) if r.is::<localize::GetParticles>() => {
                let Some(f) = self.loc.filter() else {
                    self.deferred.push(r); // an update has the filter: after it
                    return Ok(());
                };
                let (mx, my, variance) = f.cep_stats();
                r.reply(&localize::Particles {
                    mean: Pose2d::new(mx, my, 0.0),
                    variance,
                    particles: f
                        .particles()
                        .iter()
                        .map(|p| localize::Particle {
                            pose: p.pose.into(),
                            weight: p.weight,
                        })
                        .collect(),
                });
                Ok(())
            }
            Event::Request(r) if r.is::<position2d::GetGeom>() => {
                r.reply(&position2d::Geom {
                    pose: Pose3d::default(),
                    size: Size3d {
                        width: 0.01,
                        length: 0.01,
                        height: 0.0,
                    },
                });
                Ok(())
            }
            Event::Request(r) => {
                r.unhandled(Self::NAME);
                Ok(())
            }
            Event::Command(c) => {
                tracing::debug!("amcl takes no commands; ignored `{}`", c.key);
                Ok(())
            }
            Event::Wake => self.finish_update(ctx),
            Event::Tick => Ok(()),
        }
    }
}

impl Amcl {
    /// Hands the update that is due, if any, to the filter thread.
    fn start_update(&mut self) -> Result<()> {
        let Some(update) = self.loc.start() else {
            return Ok(());
        };
        let worker = self.worker.as_ref().ok_or_else(filter_thread_gone)?;
        worker
            .updates
            .send(update)
            .map_err(|_| filter_thread_gone())
    }

    /// Takes back the update the filter thread woke the driver for,
    /// publishes its estimate and answers the requests that waited for it.
    fn finish_update(&mut self, ctx: &mut Ctx) -> Result<()> {
        if !self.loc.busy() {
            return Ok(());
        }
        let worker = self.worker.as_ref().ok_or_else(filter_thread_gone)?;
        // The thread wakes the driver after sending, so this does not wait
        // (under the test harness, which wakes by hand, it waits for the run).
        let done = worker.done.recv().map_err(|_| filter_thread_gone())?;
        self.loc.finish(done);
        self.publish(ctx)?;
        for r in std::mem::take(&mut self.deferred) {
            self.on_event(ctx, Event::Request(r))?;
        }
        Ok(())
    }

    /// The localizer (tests).
    pub fn localizer(&self) -> &Localizer {
        &self.loc
    }

    fn on_reply(&mut self, ctx: &mut Ctx, r: troupe_node::Reply) -> Result<()> {
        if Some(r.id) == self.geom {
            self.geom = None;
            match self.sensor {
                Sensor::Laser(d) => match r.decode::<laser_msg::Geom>() {
                    Ok(g) => self
                        .loc
                        .set_laser_pose(Pose::new(g.pose.x, g.pose.y, g.pose.yaw)),
                    Err(e) => tracing::warn!(
                        "laser {d} gave no geometry ({e}); assuming it sits at the robot's centre"
                    ),
                },
                Sensor::Sonar(d) => match r.decode::<sonar::Geom>() {
                    Ok(g) => self.loc.set_sonar_poses(
                        g.poses.iter().map(|p| Pose::new(p.x, p.y, p.yaw)).collect(),
                    ),
                    // Without where the transducers are, sonar cannot weigh a pose.
                    Err(e) => {
                        return Err(NodeError::config(
                            Self::NAME,
                            format!("sonar {d} gave no geometry: {e}"),
                        ))
                    }
                },
            }
            return Ok(());
        }
        let Some(fetch) = &mut self.fetch else {
            return Ok(());
        };
        if let Some((info, cells)) = fetch.on_reply(ctx, &r, Self::NAME)? {
            let dev = fetch.device();
            let m = OccMap::from_tile(info, &cells)
                .map_err(|e| NodeError::config(Self::NAME, format!("map {dev}: {e}")))?;
            self.loc.set_map(&m);
            tracing::info!(
                "map {dev}: {} x {} cells at {} m",
                info.width,
                info.height,
                info.resolution
            );
            self.fetch = None;
        }
        Ok(())
    }

    /// The hypotheses of an update, then the pose.
    fn publish(&mut self, ctx: &mut Ctx) -> Result<()> {
        self.publish_hypotheses(ctx)?;
        self.publish_pose(ctx)
    }

    fn publish_hypotheses(&mut self, ctx: &mut Ctx) -> Result<()> {
        if let Some(dev) = self.localize {
            let hypoths = self
                .loc
                .hypotheses()
                .iter()
                .map(|h| localize::Hypoth {
                    mean: h.mean.into(),
                    cov: h.cov,
                    weight: h.weight,
                })
                .collect();
            // Of the time the scan was taken, as Player stamps them.
            let stamp = self.loc.updated_at().unwrap_or_else(|| ctx.now());
            ctx.publish_at(
                &dev,
                &localize::Hypoths {
                    pending_count: 0,
                    pending_time: 0.0,
                    hypoths,
                },
                stamp,
            )?;
        }
        Ok(())
    }

    /// The pose now, stamped with the odometry it extends.
    fn publish_pose(&mut self, ctx: &mut Ctx) -> Result<()> {
        if let (Some(dev), Some((stamp, pose))) = (self.position, self.loc.now()) {
            ctx.publish_at(
                &dev,
                &position2d::Data {
                    pose: pose.into(),
                    ..Default::default()
                },
                stamp,
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use troupe_geom::normalize;
    use troupe_geom::occmap::{FREE, OCCUPIED};
    use troupe_msgs::map;

    /// A 10 m × 10 m room at 0.05 m with walls and two pillars (so that
    /// the room is not symmetric).
    fn room() -> OccMap {
        let info = map::Info {
            width: 200,
            height: 200,
            resolution: 0.05,
            origin: Pose2d::new(-5.0, -5.0, 0.0),
        };
        OccMap::from_fn(info, |i, j| {
            let wall = i < 2 || j < 2 || i >= 198 || j >= 198;
            let pillar = (60..80).contains(&i) && (120..150).contains(&j);
            let block = (140..150).contains(&i) && (40..90).contains(&j);
            if wall || pillar || block {
                OCCUPIED
            } else {
                FREE
            }
        })
    }

    fn converges(model: &str) {
        let m = room();
        let truth_map = DistanceMap::new(&m);
        let o = Options {
            // Wrong by ~0.7 m and 20°, with a wide spread.
            init_pose: vec![-2.5, -1.5, 0.35],
            init_pose_var: vec![1.0, 1.0, 0.6],
            laser_model_type: model.into(),
            pf_max_samples: 5000,
            ..Options::default()
        };
        let mut loc = Localizer::new(&o).unwrap();
        loc.set_map(&m);
        // The robot drives a loop; odometry starts at its own origin.
        let start = Pose::new(-3.0, -2.0, 0.0);
        let mut truth = start;
        let mut worst_late = 0.0f64;
        for step in 0..240 {
            let turn = if (step / 40) % 2 == 1 { 0.05 } else { 0.0 };
            truth = truth.compose(&Pose::new(0.04, 0.0, turn));
            if truth_map.at(truth.x, truth.y) < 0.4 {
                truth = truth.compose(&Pose::new(-0.04, 0.0, 0.3));
            }
            let odom = relative(&truth, &start);
            let est = loc.odometry(odom, step as f64);
            loc.scan(&truth_map.scan(&truth, 8.0), step as f64);
            if step > 120 {
                let e = est.or(loc.best()).unwrap();
                worst_late =
                    worst_late.max(((e.x - truth.x).powi(2) + (e.y - truth.y).powi(2)).sqrt());
            }
        }
        let b = loc.best().unwrap();
        let err = ((b.x - truth.x).powi(2) + (b.y - truth.y).powi(2)).sqrt();
        let aerr = normalize(b.yaw - truth.yaw).abs();
        assert!(
            err < 0.25 && aerr < 10f64.to_radians(),
            "{model}: {b:?} vs {truth:?}"
        );
        assert!(
            worst_late < 0.25,
            "{model}: estimate strayed {worst_late} m along the route"
        );
        assert!(loc.updates() > 20, "{}", loc.updates());
        assert!(
            loc.filter().unwrap().particles().len() < 5000,
            "KLD shrank the set"
        );
        let h = loc.hypotheses();
        assert!(h[0].weight > 0.5 && h.windows(2).all(|w| w[0].weight >= w[1].weight));
    }

    /// A Pioneer's 16 sonars (x, y, heading in degrees).
    const PIONEER_SONARS: [(f64, f64, f64); 16] = [
        (0.075, 0.130, 90.0),
        (0.115, 0.115, 50.0),
        (0.150, 0.080, 30.0),
        (0.170, 0.025, 10.0),
        (0.170, -0.025, -10.0),
        (0.150, -0.080, -30.0),
        (0.115, -0.115, -50.0),
        (0.075, -0.130, -90.0),
        (-0.155, -0.130, -90.0),
        (-0.195, -0.115, -130.0),
        (-0.230, -0.080, -150.0),
        (-0.250, -0.025, -170.0),
        (-0.250, 0.025, 170.0),
        (-0.230, 0.080, 150.0),
        (-0.195, 0.115, 130.0),
        (-0.155, 0.130, 90.0),
    ];

    /// Player's sonar model: a sonar-only robot driving a loop in the room
    /// is tracked from a guess 0.4 m and 10° off.
    #[test]
    fn the_sonar_model_tracks_a_sonar_only_robot() {
        let m = room();
        let truth_map = DistanceMap::new(&m);
        let o = Options {
            init_pose: vec![-2.7, -1.8, 0.17],
            init_pose_var: vec![0.3, 0.3, 0.2],
            pf_max_samples: 5000,
            ..Options::default()
        };
        let mut loc = Localizer::new(&o).unwrap();
        loc.set_map(&m);
        let sonars: Vec<Pose> = PIONEER_SONARS
            .iter()
            .map(|&(x, y, a)| Pose::new(x, y, a.to_radians()))
            .collect();
        loc.set_sonar_poses(sonars.clone());
        let start = Pose::new(-3.0, -2.0, 0.0);
        let mut truth = start;
        let mut worst_late = 0.0f64;
        for step in 0..400 {
            let turn = if (step / 40) % 2 == 1 { 0.05 } else { 0.0 };
            truth = truth.compose(&Pose::new(0.04, 0.0, turn));
            if truth_map.at(truth.x, truth.y) < 0.5 {
                truth = truth.compose(&Pose::new(-0.04, 0.0, 0.3));
            }
            let ranges: Vec<f32> = sonars
                .iter()
                .map(|s| {
                    let at = truth.compose(s);
                    truth_map.range(at.x, at.y, at.yaw, 5.0) as f32
                })
                .collect();
            let est = loc.odometry(relative(&truth, &start), step as f64);
            loc.sonar(&ranges, step as f64);
            if step > 200 {
                let e = est.or(loc.best()).unwrap();
                worst_late = worst_late.max((e.x - truth.x).hypot(e.y - truth.y));
            }
        }
        let b = loc.best().unwrap();
        assert!(
            (b.x - truth.x).hypot(b.y - truth.y) < 0.3,
            "{b:?} vs {truth:?}"
        );
        assert!(worst_late < 0.3, "strayed {worst_late} m along the route");
        assert!(loc.updates() > 20, "{}", loc.updates());
    }

    #[test]
    fn beams_span_the_scan_from_min_to_max_angle() {
        let deg = |d: f64| d.to_radians() as f32;
        let mut scan = laser_msg::Scan {
            min_angle: deg(-90.0),
            max_angle: deg(90.0),
            // Stage's ranger through rangertolaser: fov / samples.
            resolution: deg(1.0),
            ranges: vec![1.0; 180],
            ..Default::default()
        };
        let step = bearing_step(&scan);
        assert!((step - 180f64.to_radians() / 179.0).abs() < 1e-6, "{step}");
        // A SICK's own scan agrees with itself.
        scan.resolution = deg(0.5);
        scan.ranges = vec![1.0; 361];
        assert!((bearing_step(&scan) - 0.5f64.to_radians()).abs() < 1e-6);
        // Without a max_angle, the resolution is all there is.
        scan.max_angle = scan.min_angle;
        assert!((bearing_step(&scan) - 0.5f64.to_radians()).abs() < 1e-6);
    }

    #[test]
    fn beam_model_converges_from_a_wrong_wide_guess() {
        converges("beam");
    }

    #[test]
    fn likelihood_field_converges_from_a_wrong_wide_guess() {
        converges("likelihood_field");
    }

    #[test]
    fn nothing_before_odometry_and_a_scan_and_set_pose_restarts() {
        let m = room();
        let d = DistanceMap::new(&m);
        let mut loc = Localizer::new(&Options::default()).unwrap();
        loc.set_map(&m);
        let p = Pose::new(1.0, 1.0, 0.0);
        assert!(!loc.scan(&d.scan(&p, 8.0), 0.0), "no odometry yet");
        assert_eq!(loc.odometry(Pose::default(), 0.0), None);
        assert!(loc.scan(&d.scan(&p, 8.0), 0.0));
        assert!(!loc.scan(&d.scan(&p, 8.0), 0.0), "no motion, no update");
        // Small motion: no update, but the estimate follows odometry.
        let before = loc.best().unwrap();
        let e = loc.odometry(Pose::new(0.1, 0.0, 0.0), 1.0).unwrap();
        assert!((e.x - before.compose(&Pose::new(0.1, 0.0, 0.0)).x).abs() < 1e-12);
        assert!(!loc.scan(&d.scan(&p, 8.0), 1.0));
        loc.set_pose(
            Pose::new(1.0, 1.0, 0.0),
            &[0.01, 0.01, 0.005, 0.0, 0.0, 0.0],
        );
        assert_eq!(loc.filter().unwrap().particles().len(), 10_000);
        assert_eq!(
            loc.odometry(Pose::new(0.1, 0.0, 0.0), 2.0),
            None,
            "new reference"
        );
        // A scan ahead of odometry waits for it.
        assert!(!loc.scan(&d.scan(&p, 8.0), 3.0));
        loc.odometry(Pose::new(0.2, 0.0, 0.0), 4.0);
        assert!(loc.poll());
        let b = loc.best().unwrap();
        assert!((b.x - 1.0).abs() < 0.1 && (b.y - 1.0).abs() < 0.1, "{b:?}");
        // The update was of the scan at 3 s; odometry has gone on to 4 s and
        // then 5 s: the pose now is the hypothesis carried along by it.
        assert_eq!(loc.updated_at(), Some(3.0));
        loc.odometry(Pose::new(0.7, 0.0, 0.0), 5.0);
        let (t, now) = loc.now().unwrap();
        assert_eq!(t, 5.0);
        let r = loc.odom_at(3.0).unwrap();
        let want = b.compose(&relative(&Pose::new(0.7, 0.0, 0.0), &r));
        assert!((now.x - want.x).abs() < 1e-12 && (now.y - want.y).abs() < 1e-12);
        assert!(now.x - b.x > 0.5, "{now:?} is carried past {b:?}");
    }

    #[test]
    fn the_initial_estimate_is_published_at_start_and_after_set_pose() {
        use troupe_node::testing::Harness;
        let mut h = Harness::<Amcl>::from_json(
            r#"{"name":"amcl","provides":["localize:0","position2d:2"],
                "requires":["odometry::position2d:0","laser:0","laser::map:0"],
                "options":{"init_pose":[-6.0,-1.0,0.0],"init_pose_var":[0.2,0.2,0.17]}}"#,
        )
        .unwrap();
        let dev = Device::new(6665, Interface::Localize, 0);
        let first = h.published::<localize::Hypoths>(dev);
        assert_eq!(first.len(), 1, "published at start, before any data");
        let best = first[0].hypoths[0];
        assert!(
            (best.mean.x + 6.0).abs() < 0.05 && (best.mean.y + 1.0).abs() < 0.05,
            "{best:?}"
        );
        assert!(best.cov[0] > 0.02 && best.cov[0] < 0.06, "{:?}", best.cov);
        let p = h
            .request(
                dev,
                &localize::SetPose {
                    mean: Pose2d::new(2.0, 3.0, 0.5),
                    cov: [0.01, 0.01, 0.01, 0.0, 0.0, 0.0],
                },
            )
            .unwrap();
        assert!(h.reply::<common::Ack>(p).is_some_and(|r| r.is_ok()));
        let all = h.published::<localize::Hypoths>(dev);
        assert_eq!(all.len(), 2, "published again after set_pose");
        let moved = all[1].hypoths[0].mean;
        assert!(
            (moved.x - 2.0).abs() < 0.05 && (moved.y - 3.0).abs() < 0.05,
            "{moved:?}"
        );
        assert!(
            h.published::<position2d::Data>(Device::new(6665, Interface::Position2d, 2))
                .is_empty(),
            "the pose waits for the first update"
        );
    }

    #[test]
    fn while_an_update_is_out_the_pose_follows_odometry_and_readings_wait() {
        let m = room();
        let d = DistanceMap::new(&m);
        let mut loc = Localizer::new(&Options {
            init_pose: vec![1.0, 1.0, 0.0],
            init_pose_var: vec![0.1, 0.1, 0.1],
            ..Options::default()
        })
        .unwrap();
        loc.set_map(&m);
        let p = Pose::new(1.0, 1.0, 0.0);
        loc.odometry(Pose::default(), 0.0);
        loc.offer_scan(&d.scan(&p, 8.0), 0.0);
        let first = loc.start().expect("the first reading is due");
        assert!(loc.busy() && loc.filter().is_none());
        assert!(loc.start().is_none(), "one update at a time");
        // Nothing to carry along yet: no estimate before the first update.
        assert_eq!(loc.odometry(Pose::new(0.05, 0.0, 0.0), 0.5), None);
        loc.finish(first.run());
        assert_eq!(loc.updates(), 1);
        let b = loc.best().unwrap();

        // The robot moves past the threshold; the second update goes out.
        loc.odometry(Pose::new(0.3, 0.0, 0.0), 1.0);
        loc.offer_scan(&d.scan(&Pose::new(1.3, 1.0, 0.0), 8.0), 1.0);
        let second = loc.start().expect("moved 0.3 m: due");
        // Meanwhile each odometry sample still gives a pose: the first
        // update's estimate carried along, from the odometry of its reading.
        let r = Pose::default();
        for (k, x) in [0.4, 0.5, 0.6].into_iter().enumerate() {
            let e = loc.odometry(Pose::new(x, 0.0, 0.0), 1.1 + k as f64 / 10.0);
            let want = b.compose(&relative(&Pose::new(x, 0.0, 0.0), &r));
            let e = e.expect("a pose while the filter is out");
            assert!((e.x - want.x).abs() < 1e-12, "{e:?} against {want:?}");
        }
        // A reading that comes meanwhile is not kept, a reset not taken.
        loc.offer_scan(&d.scan(&Pose::new(1.6, 1.0, 0.0), 8.0), 1.3);
        assert!(!loc.set_pose(Pose::default(), &[0.1, 0.1, 0.1, 0.0, 0.0, 0.0]));
        loc.finish(second.run());
        assert!(!loc.busy());
        assert_eq!((loc.updates(), loc.updated_at()), (2, Some(1.0)));
        assert!(!loc.poll(), "the reading that came meanwhile was dropped");
        // Odometry is now counted from the second update's reading.
        let b2 = loc.best().unwrap();
        let e = loc.odometry(Pose::new(0.7, 0.0, 0.0), 1.4).unwrap();
        assert!((e.x - b2.compose(&Pose::new(0.4, 0.0, 0.0)).x).abs() < 1e-12);
        assert!(
            (b2.x - 1.3).abs() < 0.1 && (b2.y - 1.0).abs() < 0.1,
            "{b2:?}"
        );
    }

    /// The driver with its filter thread: an update runs off the driver's
    /// thread, and until it is back the pose is published on every odometry
    /// sample while the requests that need the filter wait.
    #[test]
    fn the_driver_publishes_poses_while_its_filter_thread_updates() {
        use troupe_node::testing::Harness;
        let mut h = Harness::<Amcl>::from_json(
            r#"{"name":"amcl","provides":["localize:0","position2d:2"],
                "requires":["odometry::position2d:0","laser:0","laser::map:0"],
                "options":{"init_pose":[1.0,1.0,0.0],"init_pose_var":[0.2,0.2,0.17]}}"#,
        )
        .unwrap();
        let (odom, laser) = (
            Device::new(6665, Interface::Position2d, 0),
            Device::new(6665, Interface::Laser, 0),
        );
        let (loc_dev, pos_dev) = (
            Device::new(6665, Interface::Localize, 0),
            Device::new(6665, Interface::Position2d, 2),
        );
        let m = room();
        let d = DistanceMap::new(&m);
        // The map and the laser's geometry, as their drivers answer.
        for q in h.requests_sent() {
            if q.is::<laser_msg::GetGeom>() {
                h.answer(q.id, &laser_msg::Geom::default()).unwrap();
            } else if q.is::<map::GetInfo>() {
                h.answer(q.id, &m.info).unwrap();
            }
        }
        let cells = h
            .requests_sent()
            .into_iter()
            .find(|q| q.is::<map::GetData>());
        let cells = cells.expect("the cells are asked after the info");
        let (tile, _) = m.tile(0, 0, m.info.width, m.info.height);
        h.answer(cells.id, &tile).unwrap();
        let at = |x: f64| position2d::Data {
            pose: Pose2d::new(x, 0.0, 0.0),
            ..Default::default()
        };
        h.input(odom, &at(0.0)).unwrap();
        h.input(laser, &d.scan(&Pose::new(1.0, 1.0, 0.0), 8.0))
            .unwrap();
        assert!(h.published::<position2d::Data>(pos_dev).is_empty());
        h.wake().unwrap();
        assert_eq!(h.published::<localize::Hypoths>(loc_dev).len(), 2);
        // Moved 0.3 m: the next scan sends an update to the filter thread.
        h.set_time(1.0);
        h.input(odom, &at(0.3)).unwrap();
        h.input(laser, &d.scan(&Pose::new(1.3, 1.0, 0.0), 8.0))
            .unwrap();
        assert!(h.driver().localizer().busy());
        let asked = h.request(loc_dev, &localize::GetParticles).unwrap();
        let reset = localize::SetPose {
            mean: Pose2d::new(2.0, 3.0, 0.5),
            cov: [0.01, 0.01, 0.01, 0.0, 0.0, 0.0],
        };
        let reset = h.request(loc_dev, &reset).unwrap();
        let poses = h.published::<position2d::Data>(pos_dev).len();
        for x in [0.4, 0.5, 0.6] {
            h.input(odom, &at(x)).unwrap();
        }
        let published = h.published::<position2d::Data>(pos_dev);
        assert_eq!(published.len(), poses + 3, "a pose per odometry sample");
        let last = published.last().unwrap().pose;
        assert!((last.x - 1.6).abs() < 0.1, "carried along: {last:?}");
        assert_eq!(h.published::<localize::Hypoths>(loc_dev).len(), 2);
        assert!(h.reply::<localize::Particles>(asked).is_none(), "waits");
        assert!(h.reply::<common::Ack>(reset).is_none(), "waits");
        h.wake().unwrap();
        let particles = h.reply::<localize::Particles>(asked).unwrap().unwrap();
        assert!(!particles.particles.is_empty());
        // The update's hypotheses, then the reset's, in the order asked.
        let all = h.published::<localize::Hypoths>(loc_dev);
        assert_eq!(all.len(), 4);
        assert!((all[2].hypoths[0].mean.x - 1.3).abs() < 0.1, "{:?}", all[2]);
        assert!(
            (all[3].hypoths[0].mean.x - 2.0).abs() < 0.05,
            "{:?}",
            all[3]
        );
        assert!(h.reply::<common::Ack>(reset).is_some_and(|r| r.is_ok()));
        assert_eq!(h.driver().localizer().updates(), 2);
    }

    #[test]
    fn bad_options_are_named() {
        let e = |o: Options| Localizer::new(&o).err().unwrap().to_string();
        assert!(e(Options {
            laser_model_type: "x".into(),
            ..Options::default()
        })
        .contains("laser_model_type"));
        assert!(e(Options {
            init_pose: vec![1.0],
            ..Options::default()
        })
        .contains("init_pose"));
        assert!(e(Options {
            pf_min_samples: 10,
            pf_max_samples: 5,
            ..Options::default()
        })
        .contains("pf_min_samples"));
        assert!(e(Options {
            update_thresh: vec![],
            ..Options::default()
        })
        .contains("update_thresh"));
        assert!(e(Options {
            odom_drift_1: vec![0.1, -0.2],
            ..Options::default()
        })
        .contains("odom_drift[1]"));
    }

    #[test]
    fn odom_drift_rows_come_by_players_names_with_missing_values_at_defaults() {
        let o: Options = serde_json::from_value(serde_json::json!({
            "odom_drift[0]": [0.05],
            "odom_drift[2]": [0.0, 0.0, 0.1],
        }))
        .unwrap();
        let loc = Localizer::new(&o).unwrap();
        assert_eq!(
            loc.drift,
            [[0.05, 0.0, 0.0], [0.0, 0.2, 0.0], [0.0, 0.0, 0.1]],
            "row 0 keeps its defaults after the first value"
        );
    }
}
