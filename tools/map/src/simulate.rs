//! Logs to build maps from, made with Troupe's Stage: a robot of a world
//! wanders (its own controller, `ctrl "wander"` or given here) with its
//! odometry off by a fixed error, and its odometry and laser are written
//! as Player's `writelog` writes them. Beside the log: the truth to judge
//! a map by — the robot's true poses, where its beams truly ended, and the
//! world's static obstacles.
//!
//! The simulator has no randomness of its own here (no `lasernoise`), so a
//! world, a robot and a duration always give the same log.

use troupe_geom::Pose;
use troupe_msgs::{laser, position2d, AnyMsg, Interface, Pose2d, Pose3d, Size3d};
use troupe_stage::sim::{Command, Sim};
use troupe_stage::world::{Kind, Localization, World};

/// A simulated run: its log and its truth.
#[derive(Debug, Clone)]
pub struct Run {
    /// The Player text log (odometry on `6665:position2d:0`, the laser on
    /// `6665:laser:0`).
    pub log: String,
    /// The robot's true pose at each logged scan.
    pub truth: Vec<(f64, Pose)>,
    /// Where the true beams ended on a static obstacle (the walls the
    /// robot saw), one point per 5 cm.
    pub seen: Vec<(f64, f64)>,
    /// Beam ends (one per 5 cm) on what moves (another robot): no wall,
    /// and not in [`Run::seen`].
    pub on_movers: usize,
    /// The static obstacles, one point per cell of the world's raster.
    pub obstacles: Vec<(f64, f64)>,
    /// Metres the robot truly drove.
    pub driven: f64,
}

impl Run {
    /// Where the frame of `rec`'s map (its odometry's frame at the first
    /// scan) lies in the world: the robot's true pose there, less its
    /// odometry.
    pub fn frame(&self, rec: &crate::source::Recording) -> Pose {
        let Some(first) = rec.scans.first() else {
            return Pose::default();
        };
        let truth = self
            .truth
            .iter()
            .find(|(t, _)| *t >= first.t)
            .map_or_else(Pose::default, |x| x.1);
        truth.compose(&rec.odom_at(first.t).unwrap_or_default().inverse())
    }
}

/// What to simulate.
#[derive(Debug, Clone)]
pub struct Setup {
    /// The robot's name in the world.
    pub robot: String,
    /// Simulated seconds.
    pub seconds: f64,
    /// Odometry's error in x, y and yaw (a fraction: 0.05 reads 5% long).
    pub odom_error: [f64; 3],
    /// Seconds between logged scans (and odometry).
    pub every: f64,
    /// Who drives the robot.
    pub driver: Driver,
}

/// Who drives the simulated robot.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Driver {
    /// Its own controller, as the world file says (`ctrl "explore"`).
    Own,
    /// [`follow_left`]: round a building, the wall on its left.
    FollowLeft,
}

/// Keeps the wall on the left 1.2 m away at 0.45 m/s, turning right where
/// something is ahead: a robot on its way round a corridor that circles
/// a block (worlds/loop.world) drives round it, rather than back and
/// forth. The velocity (forward m/s, turn rad/s) for a scan of beams
/// evenly over `fov` radians, rightmost first.
pub fn follow_left(ranges: &[f64], fov: f64) -> (f64, f64) {
    let n = ranges.len().max(2);
    let angle = |i: usize| -fov / 2.0 + fov * i as f64 / (n - 1) as f64;
    let nearest = |lo: f64, hi: f64| {
        ranges
            .iter()
            .enumerate()
            .filter(|&(i, _)| (lo..=hi).contains(&angle(i)))
            .fold(f64::INFINITY, |a, (_, &r)| a.min(r))
    };
    if nearest(-0.35, 0.35) < 1.0 {
        return (0.05, -0.8);
    }
    let left = nearest(0.9, 1.9);
    (0.45, (0.8 * (left - 1.2)).clamp(-0.5, 0.5))
}

/// Runs `world` and logs `setup.robot`'s odometry and laser.
///
/// # Errors
///
/// No such robot, no laser on it (a ranger of many beams), or a world the
/// simulator refuses.
pub fn simulate(mut world: World, setup: &Setup) -> anyhow::Result<Run> {
    let Some(&robot) = world.names.get(&setup.robot) else {
        anyhow::bail!("the world has no model `{}`", setup.robot);
    };
    let Some(pos) = world.models[robot].position.as_mut() else {
        anyhow::bail!("`{}` is not a position model", setup.robot);
    };
    pos.localization = Localization::Odom;
    pos.odom_error = Some(setup.odom_error);
    match &setup.driver {
        Driver::Own => {}
        Driver::FollowLeft => world.models[robot].ctrl.clear(),
    }
    let laser = world.models[robot]
        .children
        .iter()
        .copied()
        .find(|&c| {
            world.models[c].kind == Kind::Ranger
                && world.models[c]
                    .sensors
                    .first()
                    .is_some_and(|s| s.samples > 1)
        })
        .ok_or_else(|| {
            anyhow::anyhow!("`{}` has no laser (a ranger of many beams)", setup.robot)
        })?;
    let sensor = world.models[laser].sensors[0].clone();
    let on_robot = world.models[laser].pose.compose(&sensor.pose);
    let (fov, samples) = (sensor.fov, sensor.samples);
    let obstacles = statics(&world)?.all;
    let mut sim = Sim::new(world)?;
    let base = sim
        .bases
        .iter()
        .position(|b| b.model == robot)
        .ok_or_else(|| anyhow::anyhow!("`{}` is not a base the simulator drives", setup.robot))?;
    sim.sense_only([laser]);
    let step = sim.world().interval_sim;
    let every = (setup.every / step).round().max(1.0) as u64;
    let steps = (setup.seconds / step).round() as u64;
    let mut log = troupe_log::text::header();
    let geom = AnyMsg::LaserGeom(laser::Geom {
        pose: Pose3d {
            x: on_robot.x,
            y: on_robot.y,
            yaw: on_robot.yaw,
            ..Pose3d::default()
        },
        size: Size3d::default(),
    });
    push(&mut log, 0.0, Interface::Laser, &geom);
    let res = fov / (samples.max(2) - 1) as f64;
    let mut run = Run {
        log: String::new(),
        truth: Vec::new(),
        seen: Vec::new(),
        on_movers: 0,
        obstacles,
        driven: 0.0,
    };
    let mut seen = std::collections::HashSet::new();
    let mut last: Option<Pose> = None;
    for k in 1..=steps {
        if let (Driver::FollowLeft, Some(r)) = (&setup.driver, sim.readings[laser].first()) {
            let (v, w) = follow_left(r.ranges, fov);
            sim.bases[base].cmd = Some(Command::Vel(Pose::new(v, 0.0, w)));
        }
        sim.step();
        let truth = sim.global(robot);
        if let Some(l) = last {
            run.driven += (truth.x - l.x).hypot(truth.y - l.y);
        }
        last = Some(truth);
        if k % every != 0 {
            continue;
        }
        let t = sim.time;
        let b = &sim.bases[base];
        let odom = AnyMsg::Position2dData(position2d::Data {
            pose: Pose2d::new(b.odom.x, b.odom.y, b.odom.yaw),
            vel: Pose2d::new(b.vel.x, b.vel.y, b.vel.yaw),
            stall: b.stall,
        });
        push(&mut log, t, Interface::Position2d, &odom);
        let Some(reading) = sim.readings[laser].first() else {
            continue;
        };
        let ranges: Vec<f32> = reading.ranges.iter().map(|&r| r as f32).collect();
        let at = truth.compose(&on_robot);
        for (i, &r) in reading.ranges.iter().enumerate() {
            if r < sensor.range.1 - 0.01 {
                let a = at.yaw - fov / 2.0 + i as f64 * res;
                let (x, y) = (at.x + r * a.cos(), at.y + r * a.sin());
                if seen.insert(((x / 0.05).floor() as i64, (y / 0.05).floor() as i64)) {
                    run.seen.push((x, y));
                }
            }
        }
        let scan = AnyMsg::LaserScan(laser::Scan {
            min_angle: (-fov / 2.0) as f32,
            max_angle: (fov / 2.0) as f32,
            resolution: res as f32,
            max_range: sensor.range.1 as f32,
            ranges,
            intensity: Vec::new(),
            id: k as u32,
        });
        push(&mut log, t, Interface::Laser, &scan);
        run.truth.push((t, truth));
    }
    run.log = log;
    // The walls seen: a beam's end within a cell of an obstacle. Another
    // robot wandering by leaves a trail of new ends wherever it goes (in
    // Stage's cave, r1's outnumbered the walls' two to one).
    let walls = crate::eval::Near::new(&run.obstacles, 0.1);
    let before = run.seen.len();
    run.seen.retain(|&(x, y)| walls.within(x, y, 0.1));
    run.on_movers = before - run.seen.len();
    Ok(run)
}

fn push(log: &mut String, t: f64, iface: Interface, msg: &AnyMsg) {
    if let Some(line) = troupe_log::text::line(t, 6665, iface, 0, msg) {
        log.push_str(&line);
    }
}

/// A world's static obstacles (what a laser sees and nothing moves), one
/// point per 5 cm cell of their rasters (the cell's centre, world frame).
#[derive(Debug, Clone, Default)]
pub struct Statics {
    /// Every cell of them.
    pub all: Vec<(f64, f64)>,
    /// The cells on a wall's face (a side open to a cell without obstacle):
    /// the part a laser can see.
    pub faces: Vec<(f64, f64)>,
}

impl Statics {
    /// The faces that face the space around `from` (world frame): those
    /// open to a cell that cell-to-cell steps through free space reach from
    /// it. A wall's far side, outside the world, is left out: no laser in
    /// the world sees it.
    pub fn facing(&self, from: (f64, f64)) -> Vec<(f64, f64)> {
        const CELL: f64 = 0.05;
        let at = |(x, y): (f64, f64)| ((x / CELL).floor() as i64, (y / CELL).floor() as i64);
        // The obstacles' cells and the start, and a cell round them all,
        // so the fill goes round the outside too.
        let (mut lo, mut hi) = (at(from), at(from));
        for &p in &self.all {
            let (i, j) = at(p);
            lo = (lo.0.min(i - 1), lo.1.min(j - 1));
            hi = (hi.0.max(i + 1), hi.1.max(j + 1));
        }
        let (w, h) = ((hi.0 - lo.0 + 1) as usize, (hi.1 - lo.1 + 1) as usize);
        let index = |(i, j): (i64, i64)| {
            let (x, y) = (i - lo.0, j - lo.1);
            (x >= 0 && y >= 0 && (x as usize) < w && (y as usize) < h)
                .then(|| y as usize * w + x as usize)
        };
        let mut solid = vec![false; w * h];
        for k in self.all.iter().filter_map(|&p| index(at(p))) {
            solid[k] = true;
        }
        let around = |(i, j): (i64, i64)| [(i + 1, j), (i - 1, j), (i, j + 1), (i, j - 1)];
        let mut reached = vec![false; w * h];
        let mut todo = vec![at(from)];
        if let Some(k) = index(at(from)) {
            reached[k] = true;
        }
        while let Some(c) = todo.pop() {
            for n in around(c) {
                if let Some(k) = index(n).filter(|&k| !solid[k] && !reached[k]) {
                    reached[k] = true;
                    todo.push(n);
                }
            }
        }
        self.faces
            .iter()
            .copied()
            .filter(|&p| {
                around(at(p))
                    .into_iter()
                    .any(|n| index(n).is_some_and(|k| reached[k]))
            })
            .collect()
    }
}

/// The static obstacles of `world`.
///
/// # Errors
///
/// A world the simulator refuses.
pub fn statics(world: &World) -> anyhow::Result<Statics> {
    let mut world = world.clone();
    for m in &mut world.models {
        m.map_resolution = 0.05;
    }
    let sim = Sim::new(world.clone())?;
    let (mut all, mut faces) = (Vec::new(), Vec::new());
    for (m, def) in world.models.iter().enumerate() {
        let moving = def.position.is_some() || def.parent.is_some();
        // What the laser sees: Stage's own floorplans have no obstacle_return.
        if moving || def.blocks.is_empty() || def.ranger_return < 0.0 {
            continue;
        }
        let map = sim.model_map(m)?;
        let (w, h) = map.size();
        let solid = |i: i64, j: i64| map.get(i, j).is_some_and(|c| c > 0);
        // The body's raster lies in its own frame: a model turned in the
        // world (slam.world's box, 30°) is turned here too.
        let (o, r) = (map.info.origin, f64::from(map.info.resolution));
        let place = Pose::new(o.x, o.y, o.yaw).applier();
        for j in 0..h as i64 {
            for i in 0..w as i64 {
                if solid(i, j) {
                    let at = place((i as f64 + 0.5) * r, (j as f64 + 0.5) * r);
                    all.push(at);
                    if !(solid(i - 1, j) && solid(i + 1, j) && solid(i, j - 1) && solid(i, j + 1)) {
                        faces.push(at);
                    }
                }
            }
        }
    }
    Ok(Statics { all, faces })
}
