//! The simulation: poses, kinematics, collisions and range sensing.
//!
//! Static models (trees without a position model) are rasterised once into
//! a grid whose cells hold `model index + 1`. Models that move are kept as
//! polygons filed by grid tile ([`crate::movers`]), refiled as they move:
//! no rasterising per step. Robots collide with unrelated models whose
//! `obstacle_return` is set (static cells under the body, moving polygons
//! that overlap it), and then stop and report a stall, as in Stage. Rays
//! walk the static grid (skipping empty tiles) and meet moving bodies
//! exactly: a robot's own body costs its rays nothing.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Mutex, PoisonError, RwLock};

use troupe_geom::occmap::{FREE, OCCUPIED};
use troupe_geom::raster::{self, Raster};
use troupe_geom::{bounds, normalize, Grid, Hit, InTile, Lattice, OccMap, Pose, EMPTY};
use troupe_msgs::{map, Color};

use crate::crew::{spin_until, Crew, Job};
use crate::movers::{Body, Fan, Movers, Sweep};
use crate::world::{Drive, Kind, Localization, Sensor, World};

mod ctrl;
mod energy;
mod fasr2;
pub use ctrl::{Charger, Ctrl, Mind, Mode};
pub use energy::Pack;

/// What a position model was last told to do.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Command {
    /// Velocity: forward, sideways (m/s), turn (rad/s).
    Vel(Pose),
    /// Car-like: speed (m/s) and steering angle (rad).
    Car(f64, f64),
    /// Go to a pose of the odometric frame.
    GoTo(Pose),
}

/// A mobile base's state.
#[derive(Debug, Clone)]
pub struct Base {
    /// Its model.
    pub model: usize,
    /// The last command (`None`: idle, or under its `ctrl`).
    pub cmd: Option<Command>,
    /// Velocity in the robot frame, m/s and rad/s.
    pub vel: Pose,
    /// Blocked by an obstacle on the last step.
    pub stall: bool,
    /// The reported pose (odometry or GPS).
    pub odom: Pose,
    /// The frame of the reported pose.
    pub origin: Pose,
    /// Motors enabled.
    pub enabled: bool,
    /// Its built-in controller (its model's `ctrl`), if any: it drives
    /// the base while no command has come.
    pub ctrl: Option<Ctrl>,
    /// What that controller keeps from step to step.
    pub mind: Mind,
}

/// Where a gripper's paddles are going, as Stage's gripper keeps them.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Paddles {
    /// Fully open.
    #[default]
    Open,
    /// Closed as far as they go (on what they hold, if anything).
    Closed,
    /// On their way open.
    Opening,
    /// On their way closed.
    Closing,
}

/// A gripper's state: Stage's gripper model with its default paddles (0.66
/// of the gripper's length, 0.1 of its width each).
///
/// # Behavior
///
/// Every 100 ms of simulated time (Stage's update interval) the paddles
/// move a twentieth of their travel towards the last command. Two break
/// beams cross the gap between them (3/4 and 1/4 of the paddles' length
/// from their tips) and two contact rays run along their inner faces, at
/// the gripper's height; they meet models with `gripper_return`. Closing
/// paddles that touch something take it: it moves to the gripper's centre
/// and goes with it, and the paddles close no further than its width
/// lets them. Opening lets go of it where it is.
#[derive(Debug, Clone, PartialEq)]
pub struct GripperState {
    /// The paddles.
    pub paddles: Paddles,
    /// How far closed: 0 open, 1 closed.
    pub position: f64,
    /// Where closing stops: 1, or less on a held object.
    close_limit: f64,
    /// The last command, kept as Stage keeps it: close (`true`) or open.
    command: Option<bool>,
    /// The model it holds, and that model's pose in the gripper's frame.
    pub held: Option<(usize, Pose)>,
    /// Break beams as Stage's Player plugin reports them: 0x04 the inner
    /// beam, 0x08 the outer one.
    pub beams: u32,
    /// Simulated seconds since the paddles last moved.
    since: f64,
}

impl Default for GripperState {
    fn default() -> Self {
        GripperState {
            paddles: Paddles::Open,
            position: 0.0,
            close_limit: 1.0,
            command: None,
            held: None,
            beams: 0,
            since: 0.0,
        }
    }
}

/// Stage's gripper: paddles' share of the gripper's length and width,
/// where the beams cross them (from the paddles' base), and how far the
/// paddles move per update.
const PADDLE_X: f64 = 0.66;
const PADDLE_Y: f64 = 0.1;
const BEAM_INSET: [f64; 2] = [0.75 * PADDLE_X, 0.25 * PADDLE_X];
const PADDLE_STEP: f64 = 0.05;
const GRIPPER_INTERVAL: f64 = 0.1;

/// A ranger's latest readings: its sensors' ranges and intensities, one
/// sensor after another in two arrays. (Two arrays per sensor were, for
/// Stage's hospital.world, 24000 small allocations read and written every
/// step, a cache miss each.)
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Readings {
    ranges: Vec<f64>,
    intensities: Vec<f64>,
    /// Where each sensor's readings start, then where the last one's end.
    starts: Vec<usize>,
}

/// One sensor's latest readings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reading<'a> {
    /// Metres, one per sample.
    pub ranges: &'a [f64],
    /// The hit model's `ranger_return` (0 when nothing was hit).
    pub intensities: &'a [f64],
}

impl Readings {
    /// `sensors`' readings before they sense: every range the farthest,
    /// every intensity 0.
    fn new(sensors: &[Sensor]) -> Readings {
        let mut starts = vec![0];
        let mut ranges = Vec::new();
        for s in sensors {
            ranges.extend(std::iter::repeat_n(s.range.1, s.samples));
            starts.push(ranges.len());
        }
        let intensities = vec![0.0; ranges.len()];
        Readings {
            ranges,
            intensities,
            starts,
        }
    }

    /// How many sensors.
    pub fn len(&self) -> usize {
        self.starts.len().saturating_sub(1)
    }

    /// Whether there are no sensors.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Where sensor `i`'s readings lie in the arrays, if there is such a
    /// sensor.
    fn span(&self, i: usize) -> Option<std::ops::Range<usize>> {
        Some(*self.starts.get(i)?..*self.starts.get(i + 1)?)
    }

    /// Sensor `i`'s readings, if there is such a sensor.
    pub fn get(&self, i: usize) -> Option<Reading<'_>> {
        let span = self.span(i)?;
        Some(Reading {
            ranges: &self.ranges[span.clone()],
            intensities: &self.intensities[span],
        })
    }

    /// Sensor `i`'s readings.
    ///
    /// # Panics
    ///
    /// When there is no sensor `i`.
    pub fn sensor(&self, i: usize) -> Reading<'_> {
        match self.get(i) {
            Some(rd) => rd,
            None => panic!("sensor {i} of a ranger of {}", self.len()),
        }
    }

    /// The first sensor's readings.
    pub fn first(&self) -> Option<Reading<'_>> {
        self.get(0)
    }

    /// Each sensor's readings, in order.
    pub fn iter(&self) -> impl Iterator<Item = Reading<'_>> + '_ {
        (0..self.len()).filter_map(|i| self.get(i))
    }

    /// Sensor `i`'s first range (0 when it has none).
    pub(crate) fn first_range(&self, i: usize) -> f64 {
        self.span(i)
            .and_then(|span| self.ranges[span].first().copied())
            .unwrap_or(0.0)
    }

    /// Sensor `i`'s ranges and intensities, to write (none when there is no
    /// such sensor).
    fn sensor_mut(&mut self, i: usize) -> (&mut [f64], &mut [f64]) {
        match self.span(i) {
            Some(span) => (&mut self.ranges[span.clone()], &mut self.intensities[span]),
            None => (&mut [], &mut []),
        }
    }
}

/// The simulated world.
pub struct Sim {
    /// The loaded world, read through [`Sim::world`]: the steps read copies
    /// of parts of it ([`Frame`], [`Motion`], [`Fans`]), so what changes at
    /// run time changes through `Sim` ([`Sim::set_z`],
    /// [`Sim::set_fiducial_return`]).
    world: World,
    /// Simulated seconds.
    pub time: f64,
    /// Steps taken.
    pub steps: u64,
    /// Pose of each model relative to its parent.
    pub poses: Vec<Pose>,
    /// Colour of each model (changeable through the simulation interface).
    pub colors: Vec<Color>,
    /// Mobile bases.
    pub bases: Vec<Base>,
    /// Each base's `position` settings as its moves read them (see
    /// [`Motion`]).
    motions: Vec<Option<Motion>>,
    /// Latest readings of each ranger model, one per sensor (empty for other models).
    pub readings: Vec<Readings>,
    /// Gripper state of each gripper model (`None` for other models).
    pub grippers: Vec<Option<GripperState>>,
    /// What a ray asks of each model, side by side (one cache line, not
    /// three): its tree, whether rangers see it, and its body from its base
    /// to its top above the floor (Stage is 2.5D: a sensor sees only what
    /// spans the height of its rays).
    looks: Vec<Look>,
    /// What a step reads of each model's place in its tree (see [`Frame`]).
    frames: Vec<Frame>,
    /// The threads that plan moves and cast rays, and the models with
    /// range sensors among them.
    crew: Crew,
    /// Each model's subtree (itself first), depth-first.
    trees: Vec<Vec<usize>>,
    /// Rangers under `lasernoise`: noise on their first sensor's ranges.
    noisy: Vec<bool>,
    /// The rangers each step senses (all, unless [`Sim::sense_only`]).
    sensed: Vec<bool>,
    /// What the controllers read or run on besides the bases and rangers
    /// (fiducial finders, zones): they run, as Stage's subscribed models.
    used: Vec<bool>,
    /// Power packs and flags.
    energy: energy::Energy,
    /// The `fasr2` robots' shared state, in a world that has them.
    fasr2: Option<Box<fasr2::Fasr2>>,
    movable: Vec<bool>,
    /// The global pose each static model's body was written into the
    /// grid at (`None`: not written). Taking it out writes the same cells
    /// again, emptied: a floorplan covers millions of cells, and keeping
    /// their list cost 16 bytes each (1.6 GB for Stage's large.world).
    written_at: Vec<Option<Pose>>,
    statics: Grid,
    /// The bodies as Stage draws them for its rays (the static ones by
    /// id, the moving ones counted in the regions they touch), when rays
    /// read as Stage's rather than against the exact bodies
    /// ([`Sim::stage_ranges`]).
    raster: Option<Raster>,
    /// The raster cells each static model is drawn in now.
    drawn: Vec<Vec<(i32, i32)>>,
    /// The raster regions each moving model's outline touches now, with
    /// its cells there.
    touches: Vec<Vec<(usize, i32)>>,
    /// Room for a moving model's regions while it is filed.
    touched: Vec<(usize, i32)>,
    /// Moving bodies, for sensors and collisions.
    movers: Movers,
    /// Each model's sensors' rays.
    fans: Vec<Fans>,
    /// Each base's plan for the step, kept for its buffers.
    plans: Vec<Mutex<Plan>>,
}

/// Stage's `rasterize` controller: model `m`'s outline drawn into 40×20
/// cells, said row by row from the top (`O` drawn, `.` not).
fn rasterize(world: &World, m: usize) {
    const W: usize = 40;
    const H: usize = 20;
    let def = &world.models[m];
    let cells = fasr2::outline(&def.blocks, (def.size[0], def.size[1]), (W, H));
    tracing::info!("[Rasterize] Raster of model \"{}\":", def.name);
    for row in cells.chunks(W).rev() {
        let line: String = row
            .iter()
            .map(|&c| if c == fasr2::FREE { '.' } else { 'O' })
            .collect();
        tracing::info!("[Rasterize] {line}");
    }
}

/// A body as it would stand at a global pose: in world coordinates, with
/// the cells of its box (`None` off the grid), made once (by the thread
/// that plans the move) for both the collision tests and the filing.
#[derive(Default)]
struct Placed {
    model: usize,
    body: Body,
    cells: Option<((usize, usize), (usize, usize))>,
}

/// The moving bodies already tested along one ray or under one body: a
/// body spans a few tiles and is tested once (the first few are
/// remembered; past them a body may be tested again, which is only slower).
#[derive(Default)]
struct Seen {
    ids: [u16; 8],
    n: usize,
}

impl Seen {
    /// True the first time `id` is seen (and remembers it, room allowing).
    fn first(&mut self, id: u16) -> bool {
        if self.ids[..self.n].contains(&id) {
            return false;
        }
        if self.n < self.ids.len() {
            self.ids[self.n] = id;
            self.n += 1;
        }
        true
    }
}

/// The moving bodies a ray from `o` along `d` meets in each tile it
/// enters, nearest first (see [`Sim::cast`]): a type of its own, so that
/// the test is inlined into the ray's walk, not called tile by tile.
struct TileBodies<'a, A> {
    sim: &'a Sim,
    o: (f64, f64),
    d: (f64, f64),
    accept: A,
    own: u16,
    tested: Seen,
}

impl<'a, A> TileBodies<'a, A> {
    fn new(sim: &'a Sim, o: (f64, f64), d: (f64, f64), accept: A, own: u16) -> Self {
        TileBodies {
            sim,
            o,
            d,
            accept,
            own,
            tested: Seen::default(),
        }
    }
}

impl<A: Fn(u16) -> bool> InTile for TileBodies<'_, A> {
    #[inline(always)]
    fn in_tile(&mut self, t: usize) -> Option<Hit> {
        let ids = self.sim.movers.in_tile(t).iter().copied();
        let (o, d, own) = (self.o, self.d, self.own);
        self.sim
            .nearest_body(o, d, ids, &self.accept, own, &mut self.tested)
    }
}

/// What a step reads of a model's definition, side by side with the
/// other models' (a `ModelDef` spans eleven cache lines, and reading a
/// field or two of each of 2000 of them, pass after pass, was a tenth of
/// Stage's hospital.world): where it sits in its tree, how often it
/// updates, whether it has a body and blocks others.
#[derive(Debug, Clone, Copy)]
struct Frame {
    /// Its parent, or [`Frame::ROOT`].
    parent: u32,
    /// Whether it has blocks.
    body: bool,
    /// Its `obstacle_return`.
    obstacle: bool,
    /// Its height above its parent's top (`ModelDef::z`).
    z: f64,
    /// How far above its base its children stand: its height when it
    /// stacks them, else 0.
    stack: f64,
    /// Its `update_interval`, in seconds.
    every: f64,
}

impl Frame {
    /// [`Frame::parent`] of a model at the root of its tree.
    const ROOT: u32 = u32::MAX;

    fn of(d: &crate::world::ModelDef) -> Frame {
        Frame {
            parent: d
                .parent
                .and_then(|p| u32::try_from(p).ok())
                .unwrap_or(Frame::ROOT),
            body: !d.blocks.is_empty(),
            obstacle: d.obstacle_return,
            z: d.z,
            stack: if d.stack_children { d.size[2] } else { 0.0 },
            every: d.update_interval,
        }
    }
}

/// What a base's move reads of its `position` settings, side by side
/// with the other bases' (see [`Frame`]).
#[derive(Debug, Clone, Copy)]
struct Motion {
    drive: Drive,
    localization: Localization,
    wheelbase: f64,
    /// Its velocity bounds on x, y and yaw: least, most.
    bounds: [f64; 6],
    odom_error: [f64; 3],
}

impl Motion {
    fn of(c: &crate::world::PositionCfg) -> Motion {
        let vb = &c.velocity_bounds;
        Motion {
            drive: c.drive,
            localization: c.localization,
            wheelbase: c.wheelbase,
            bounds: [vb[0], vb[1], vb[2], vb[3], vb[6], vb[7]],
            odom_error: c.odom_error,
        }
    }
}

/// What a ray asks of a model it meets (see `Sim::ranger_sees`).
#[derive(Debug, Clone, Copy)]
struct Look {
    /// The model at the root of its tree (kept here alone: a gripper
    /// changes it as it takes and drops).
    root: u32,
    /// Its `ranger_return`: rangers see it when this is not negative, and
    /// read it as the intensity of a hit.
    ret: f64,
    /// Its body's base and top above the floor.
    lo: f64,
    hi: f64,
}

impl Look {
    /// Whether rangers see it.
    #[inline]
    fn seen(&self) -> bool {
        self.ret >= 0.0
    }

    /// Whether its body spans height `z` (Stage's ray z test).
    #[inline]
    fn spans(&self, z: f64) -> bool {
        self.lo <= z && z <= self.hi
    }
}

/// Sensors with at least this many rays look around their origin once, so
/// that their rays start beyond the open space there (for fewer rays the
/// look costs more than it spares).
const FAN: usize = 16;

/// A ranger's sensors as its rays and its controllers read them, each
/// in an array of its own: every step reads them for a thousand rangers,
/// so what each reads is laid out to cost it the fewest cache lines.
#[derive(Default)]
struct Fans {
    /// The ranger's pose on its parent (its `origin`).
    origin: Pose,
    /// What every sensor's rays read: a cache line a sensor.
    rays: Vec<Rays>,
    /// Each sensor's turn from one ray to the next (see [`fan`]): as a
    /// unit vector and as an angle. Only sensors of several rays read it.
    turns: Vec<((f64, f64), f64)>,
    /// Each sensor's heading on the ranger, which the controllers sum
    /// the first readings along (see `Sim::resultant`).
    headings: Vec<(f64, f64)>,
}

/// A sensor's rays as the ranger casts them: the unit vector of the
/// first, relative to the ranger (see [`fan`]), and what of the sensor
/// the rays read, kept beside it in one cache line.
#[repr(align(64))]
struct Rays {
    first: (f64, f64),
    /// Where the rays start, in the ranger's frame.
    at: (f64, f64),
    /// The sensor's range, in metres: nearest and farthest.
    range: (f64, f64),
    /// Their height above the ranger's base: the middle of the sensor's.
    z: f64,
    /// How many rays.
    samples: usize,
}

/// A sensor's rays: the angle of the first relative to the sensor, and
/// the angle from one to the next.
fn fan(s: &Sensor) -> (f64, f64) {
    if s.samples > 1 {
        (s.pose.yaw - s.fov / 2.0, s.fov / (s.samples - 1) as f64)
    } else {
        (s.pose.yaw, 0.0)
    }
}

/// The first of `0..n` for which `p` holds, where it holds for all after
/// it too (`n` when there is none).
fn first_where(n: usize, p: impl Fn(usize) -> bool) -> usize {
    let (mut lo, mut hi) = (0, n);
    while lo < hi {
        let mid = (lo + hi) / 2;
        if p(mid) {
            hi = mid;
        } else {
            lo = mid + 1;
        }
    }
    lo
}

/// The least of `ranges` (infinite when there are none), four at a time.
fn nearest(ranges: &[f64]) -> f64 {
    let mut least = [f64::INFINITY; 4];
    let fours = ranges.chunks_exact(4);
    let rest = fours.remainder();
    for four in fours {
        for (l, &r) in least.iter_mut().zip(four) {
            *l = l.min(r);
        }
    }
    rest.iter()
        .chain(&least)
        .fold(f64::INFINITY, |a, &b| a.min(b))
}

/// Model `m`'s body from its base to its top, above the floor (where its
/// parents' poses and stacking put it).
fn height(world: &World, poses: &[Pose], m: usize) -> (f64, f64) {
    let (_, z) = world.global(poses, m);
    (z, z + world.models[m].size[2])
}

/// Locks `m`, through a panic elsewhere.
fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// What a base does in a step (see [`Sim::plan`]); kept from step to step
/// for its buffers.
#[derive(Default)]
struct Plan {
    /// Its velocity this step, and its pose at the end of it.
    v: Pose,
    next: Pose,
    /// Whether it moves, and what its controller keeps after this step.
    moving: bool,
    mind: Mind,
    /// Its tree's bodies where it would move to, and whether they would
    /// meet a static obstacle.
    bodies: Vec<Placed>,
    walled: bool,
}

/// Sets its flag when dropped.
struct Release<'a>(&'a AtomicBool);

impl Drop for Release<'_> {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Release);
    }
}

/// `v` turned by the angle whose unit vector is `by`.
fn turned(by: (f64, f64), v: (f64, f64)) -> (f64, f64) {
    (by.0 * v.0 - by.1 * v.1, by.1 * v.0 + by.0 * v.1)
}

/// The unit vector at angle `a`.
fn unit(a: f64) -> (f64, f64) {
    let (s, c) = a.sin_cos();
    (c, s)
}

fn id(m: usize) -> u16 {
    // INVARIANT: worlds hold fewer than 65535 models (checked in `new`).
    (m + 1) as u16
}

impl Sim {
    /// Builds the simulation of `world`.
    ///
    /// # Errors
    ///
    /// A world with more models than a grid cell can name.
    pub fn new(world: World) -> Result<Sim, String> {
        let n = world.models.len();
        if n >= usize::from(u16::MAX) {
            return Err(format!(
                "the world has {n} models; at most {} are supported",
                u16::MAX - 1
            ));
        }
        let poses: Vec<Pose> = world.models.iter().map(|m| m.pose).collect();
        let roots: Vec<usize> = (0..n).map(|m| world.root(m)).collect();
        let mut movable = vec![false; n];
        for (m, root) in roots.iter().enumerate() {
            if world.models[m].kind == Kind::Position {
                for k in world.subtree(*root) {
                    movable[k] = true;
                }
            }
        }
        // The grids cover every body, with a margin for robots that wander off.
        let [x0, y0, x1, y1] = bounds((0..n).flat_map(|m| {
            let apply = world.global(&poses, m).0.applier();
            world.models[m]
                .blocks
                .iter()
                .flatten()
                .map(move |&(x, y)| apply(x, y))
        }))
        .unwrap_or([-1.0, -1.0, 1.0, 1.0]);
        let margin = 2.0;
        let res = world.resolution;
        let mut statics = Grid::new(x0 - margin, y0 - margin, x1 + margin, y1 + margin, res);
        // Fans of rays start beyond the open space around them (see
        // `open_around`): the grid keeps its clearance for them.
        if world
            .models
            .iter()
            .any(|m| m.sensors.iter().any(|s| s.samples >= FAN))
        {
            statics.keep_clearance();
        }
        // Each model's controllers: built in, or said once each (with how
        // many models stay idle for it, and the first of them).
        let trees: Vec<Vec<usize>> = (0..n).map(|m| world.subtree(m)).collect();
        let mut ctrls = vec![None; n];
        let mut noisy = vec![false; n];
        let mut used = vec![false; n];
        let mut energy = energy::Energy::new(&world);
        let mut fasr2: Option<Result<Box<fasr2::Fasr2>, String>> = None;
        let mut missing: std::collections::BTreeMap<String, (usize, usize)> = Default::default();
        for m in 0..n {
            for c in &world.models[m].ctrl {
                let why = match ctrl::find(&world, &trees[m], m, c) {
                    ctrl::Found::Base(found) if ctrls[m].is_none() => {
                        if let Ctrl::Fasr2 { .. } = found {
                            // The tasks are the first robot's, as in Stage.
                            let setup =
                                fasr2.get_or_insert_with(|| fasr2::setup(&world, c).map(Box::new));
                            if let Err(why) = setup {
                                missing.entry(why.clone()).or_insert((m, 0)).1 += 1;
                                continue;
                            }
                        }
                        for k in found.also_reads() {
                            used[k] = true;
                        }
                        ctrls[m] = Some(found);
                        continue;
                    }
                    ctrl::Found::Base(_) => format!(
                        "\"{c}\" is a second controller of one base; the first one drives it"
                    ),
                    ctrl::Found::Noise => {
                        noisy[m] = true;
                        continue;
                    }
                    ctrl::Found::Source(capacity) => {
                        used[m] = true;
                        energy.sources.push((m, capacity));
                        continue;
                    }
                    ctrl::Found::Loaded => continue,
                    ctrl::Found::Rasterize => {
                        rasterize(&world, m);
                        continue;
                    }
                    ctrl::Found::Sink => {
                        used[m] = true;
                        energy.sinks.push(m);
                        continue;
                    }
                    ctrl::Found::Unknown => format!(
                        "controller \"{}\" is not built into Troupe",
                        c.split_whitespace().next().unwrap_or("")
                    ),
                    ctrl::Found::Lacks(why) => why,
                };
                missing.entry(why).or_insert((m, 0)).1 += 1;
            }
        }
        for (why, (first, count)) in missing {
            let (pos, model) = (&world.models[first].pos, &world.models[first].name);
            if count == 1 {
                tracing::warn!("{pos}: {why}; model `{model}` stays idle");
            } else {
                tracing::warn!("{pos}: {why}; {count} models stay idle (the first: `{model}`)");
            }
        }
        // What Troupe does not simulate, once per world.
        let mut cameras = (0..n).filter(|&m| world.models[m].kind == Kind::Camera);
        if let Some(first) = cameras.next() {
            let (pos, model) = (&world.models[first].pos, &world.models[first].name);
            tracing::warn!(
                "{pos}: camera models are not simulated (Stage renders them with OpenGL); {} in this world (the first: `{model}`)",
                1 + cameras.count()
            );
        }
        let bases = (0..n)
            .filter(|&m| world.models[m].kind == Kind::Position)
            .map(|m| {
                let (g, _) = world.global(&poses, m);
                let cfg = world.models[m].position.as_ref();
                let origin = cfg.and_then(|c| c.localization_origin).unwrap_or(g);
                Base {
                    model: m,
                    cmd: None,
                    vel: Pose::default(),
                    stall: false,
                    odom: origin.inverse().compose(&g),
                    origin,
                    enabled: true,
                    ctrl: ctrls[m],
                    mind: Mind::default(),
                }
            })
            .collect::<Vec<Base>>();
        let motions = bases
            .iter()
            .map(|b| world.models[b.model].position.as_ref().map(Motion::of))
            .collect();
        let readings = world
            .models
            .iter()
            .map(|m| Readings::new(&m.sensors))
            .collect();
        let colors = world.models.iter().map(|m| m.color).collect();
        let grippers = world
            .models
            .iter()
            .map(|m| (m.kind == Kind::Gripper).then(GripperState::default))
            .collect();
        let looks = (0..n)
            .map(|m| {
                let (lo, hi) = height(&world, &poses, m);
                Look {
                    root: roots[m] as u32,
                    ret: world.models[m].ranger_return,
                    lo,
                    hi,
                }
            })
            .collect();
        let frames = world.models.iter().map(Frame::of).collect();
        let fans = world
            .models
            .iter()
            .map(|m| {
                let mut fans = Fans {
                    origin: m.origin,
                    ..Fans::default()
                };
                for s in &m.sensors {
                    let (first, step) = fan(s);
                    fans.rays.push(Rays {
                        first: unit(first),
                        at: (s.pose.x, s.pose.y),
                        range: s.range,
                        // As Stage: rays leave from the middle of the
                        // sensor's height.
                        z: s.z + s.size[2] / 2.0,
                        samples: s.samples,
                    });
                    fans.turns.push((unit(step), step));
                    fans.headings.push(unit(s.pose.yaw));
                }
                fans
            })
            .collect();
        let mut sim = Sim {
            fans,
            plans: Vec::new(),
            world,
            time: 0.0,
            steps: 0,
            poses,
            colors,
            bases,
            motions,
            readings,
            grippers,
            trees,
            noisy,
            sensed: vec![true; n],
            used,
            energy,
            fasr2: fasr2.and_then(Result::ok),
            crew: Crew::default(),
            looks,
            frames,
            movable,
            written_at: vec![None; n],
            raster: None,
            drawn: vec![Vec::new(); n],
            touches: vec![Vec::new(); n],
            touched: Vec::new(),
            movers: Movers::new(n, statics.tile_count()),
            statics,
        };
        for m in 0..n {
            sim.place(m);
        }
        if let Some(mut f) = sim.fasr2.take() {
            let n = sim.bases.len();
            for bi in 0..n {
                if matches!(sim.bases[bi].ctrl, Some(Ctrl::Fasr2 { .. })) {
                    let m = sim.bases[bi].model;
                    f.join(n, bi, sim.chance(m, 4));
                    // A robot wears the colour of the zone it heads for.
                    sim.colors[m] = sim.colors[f.goal(bi)];
                }
            }
            sim.fasr2 = Some(f);
        }
        // No more threads than cores: the helpers spin while the bases
        // move, and one without a core of its own would slow the moves.
        let cores = std::thread::available_parallelism().map_or(1, usize::from);
        sim.set_threads(sim.world.threads.clamp(1, cores));
        sim.sense();
        Ok(sim)
    }

    /// From now on senses only the rangers `served` (those whose devices
    /// a client is given) and those the built-in controllers read, as
    /// Stage updates only the sensors someone subscribes to; the others
    /// keep their last readings.
    pub fn sense_only(&mut self, served: impl IntoIterator<Item = usize>) {
        let mut on = vec![false; self.world.models.len()];
        for r in served {
            on[r] = true;
        }
        for bi in 0..self.bases.len() {
            let also = self.bases[bi].ctrl.into_iter().flat_map(Ctrl::also_reads);
            for r in self.ctrl_ranger(bi).into_iter().chain(also) {
                on[r] = true;
            }
        }
        self.sensed = on;
        // (Fewer rangers never want more threads than the crew has.)
        self.set_threads(self.crew.threads());
    }

    /// Every ranger, as the crew deals them.
    fn jobs(&self) -> Vec<Job> {
        let mut base_of = vec![None; self.world.models.len()];
        for (bi, b) in self.bases.iter().enumerate() {
            base_of[b.model] = Some(bi);
        }
        (0..self.world.models.len())
            .filter(|&r| self.sensed[r] && !self.world.models[r].sensors.is_empty())
            .map(|r| Job {
                ranger: r,
                rays: self.world.models[r].sensors.iter().map(|s| s.samples).sum(),
                base: base_of[self.root(r)],
            })
            .collect()
    }

    /// Plans moves and casts rays on `threads` threads: no more than there
    /// are rangers sensed, and one when a step casts fewer than a few
    /// thousand rays (threads pay off only then).
    fn set_threads(&mut self, threads: usize) {
        let jobs = self.jobs();
        let rays: usize = jobs.iter().map(|j| j.rays).sum();
        let threads = if rays < 2000 { 1 } else { threads };
        self.crew = Crew::new(threads.min(jobs.len()).max(1), self.bases.len(), &jobs);
    }

    fn in_grid(&self, m: usize) -> bool {
        let d = &self.world.models[m];
        !d.blocks.is_empty() && (d.obstacle_return || d.ranger_return >= 0.0)
    }

    /// Calls `f(grid, i, j)` with the static grid for each cell model
    /// `m`'s body covers at the global pose `at` (a cell may come more than
    /// once).
    fn body_cells(&mut self, m: usize, at: Pose, mut f: impl FnMut(&mut Grid, usize, usize)) {
        let body = self.placed(m, at);
        let lat = *self.statics.lattice();
        for pts in body.body.polys() {
            lat.polygon_cells(pts, |i, j| f(&mut self.statics, i, j));
        }
    }

    /// (Re)writes model `m`'s body at its current pose: into the static
    /// grid, or filed with the moving bodies.
    fn place(&mut self, m: usize) {
        if !self.in_grid(m) {
            return;
        }
        if self.movable[m] {
            self.file(&mut self.placed(m, self.global(m)));
        } else {
            self.occupy(m, self.global(m));
            self.draw(m);
        }
    }

    /// Draws static model `m`'s body into the raster as Stage draws it.
    fn draw(&mut self, m: usize) {
        let Some(ppm) = self.raster.as_ref().map(Raster::ppm) else {
            return;
        };
        let mut drawn = std::mem::take(&mut self.drawn[m]);
        drawn.clear();
        for pts in self.placed(m, self.global(m)).body.polys() {
            raster::outline(ppm, pts, |x, y| drawn.push((x, y)));
        }
        if let Some(r) = &mut self.raster {
            for &(x, y) in &drawn {
                r.set(x, y, id(m));
            }
        }
        self.drawn[m] = drawn;
    }

    /// Whether model `m` moves (a robot, or what it carries).
    pub fn moves(&self, m: usize) -> bool {
        self.movable[m]
    }

    /// Rays read as Stage's (`true`: Stage's raster of block outlines and
    /// its ray walk; see [`troupe_geom::raster`]) or against the exact
    /// bodies (`false`, the default: the bench worlds run up to 2.5 times
    /// faster).
    /// Ranges to moving bodies are exact either way.
    pub fn stage_ranges(&mut self, on: bool) {
        if on == self.raster.is_some() {
            return;
        }
        let lat = self.statics.lattice();
        let ((x0, y0), (w, h)) = (lat.origin(), lat.size());
        let res = lat.resolution();
        self.raster =
            on.then(|| Raster::new(x0, y0, x0 + w as f64 * res, y0 + h as f64 * res, res));
        for m in 0..self.world.models.len() {
            self.drawn[m].clear();
            self.touches[m].clear();
            self.place(m);
        }
        self.sense();
    }

    /// Model `m`'s body at global pose `at`.
    fn placed(&self, m: usize, at: Pose) -> Placed {
        let mut body = Placed::default();
        self.place_into(m, at, &mut body);
        body
    }

    /// [`Sim::placed`] into `body`, reusing its buffers.
    fn place_into(&self, m: usize, at: Pose, body: &mut Placed) {
        body.model = m;
        body.body.place(&self.world.models[m].blocks, at);
        body.cells = body
            .body
            .bounds()
            .and_then(|b| self.statics.lattice().cells_of_box(b));
    }

    /// Files a moving body under the tiles it touches (taking its polygons,
    /// and leaving it buffers to reuse).
    fn file(&mut self, body: &mut Placed) {
        let m = body.model;
        if let Some(r) = &self.raster {
            // (Most steps a body's outline stays in the same regions.)
            let mut now = std::mem::take(&mut self.touched);
            r.regions_of(body.body.polys(), &mut now);
            if now != self.touches[m] {
                self.count_touches(m, -1);
                std::mem::swap(&mut now, &mut self.touches[m]);
                self.count_touches(m, 1);
            }
            self.touched = now;
        }
        let tiles = body
            .cells
            .into_iter()
            .flat_map(|(lo, hi)| self.statics.tiles_of_box(lo, hi));
        self.movers.file(m, id(m), &mut body.body, tiles);
    }

    /// Adds (`sign` 1) or takes away (−1) moving model `m`'s outline in
    /// the raster's regions.
    fn count_touches(&mut self, m: usize, sign: i32) {
        if let Some(raster) = &mut self.raster {
            for &(r, n) in &self.touches[m] {
                raster.count_movers(r, sign * n);
            }
        }
    }

    /// Moves static model `m`'s body in the grid from where it was to the
    /// global pose `at`.
    fn occupy(&mut self, m: usize, at: Pose) {
        self.unplace(m);
        self.body_cells(m, at, |g, i, j| g.set(i, j, id(m)));
        self.written_at[m] = Some(at);
    }

    /// Every body in the tree of `m` (itself and what it carries) as it
    /// would be if `m` were at the global pose `at`, into `bodies` (whose
    /// buffers are reused).
    fn tree_at(&self, m: usize, at: Pose, bodies: &mut Vec<Placed>) {
        // The move from where the tree is to `at`, worked out for the
        // tree's other bodies (most trees have one: `m`, which goes to `at`).
        let mut shift = None;
        let mut n = 0;
        for &k in &self.trees[m] {
            if !self.frames[k].body {
                continue;
            }
            if bodies.len() == n {
                bodies.push(Placed::default());
            }
            let to = if k == m {
                at
            } else {
                shift
                    .get_or_insert_with(|| at.compose(&self.global(m).inverse()))
                    .compose(&self.global(k))
            };
            self.place_into(k, to, &mut bodies[n]);
            n += 1;
        }
        bodies.truncate(n);
    }

    /// Whether model `other` blocks the bodies of the tree of `root`.
    fn blocks(&self, root: usize, other: usize) -> bool {
        self.root(other) != root && self.frames[other].obstacle
    }

    /// Whether model `m`'s body meets obstacles when it moves: as in
    /// Stage, one with no `obstacle_return` (a charging bump on a robot's
    /// nose) passes through them as they pass through it.
    fn collides(&self, m: usize) -> bool {
        self.frames[m].obstacle
    }

    /// True when the `bodies` (of the tree of `root`) would overlap an
    /// unrelated static obstacle.
    fn hits_statics(&self, root: usize, bodies: &[Placed]) -> bool {
        let blocks = |c: usize| self.blocks(root, c - 1);
        for body in bodies.iter().filter(|b| self.collides(b.model)) {
            let (polys, Some((lo, hi))) = (body.body.polys(), body.cells) else {
                continue;
            };
            // Static cells, rasterised only where a tile holds any (reading
            // the cells of a large world is what costs: cache misses) and
            // the open space around the body does not hold all of it.
            if !self.in_the_open(&body.body)
                && self
                    .statics
                    .tiles_of_box(lo, hi)
                    .any(|t| self.statics.tile_holds(t))
            {
                let mut hit = false;
                let lat = *self.statics.lattice();
                for p in polys {
                    lat.polygon_cells(p, |i, j| {
                        if !hit && self.statics.tile_occupied(i, j) {
                            let c = self.statics.get(i, j);
                            hit = c != EMPTY && blocks(usize::from(c));
                        }
                    });
                }
                if hit {
                    return true;
                }
            }
        }
        false
    }

    /// True when the `bodies` (of the tree of `root`) would overlap an
    /// unrelated moving body.
    fn hits_movers(&self, root: usize, bodies: &[Placed]) -> bool {
        let blocks = |c: usize| self.blocks(root, c - 1);
        for body in bodies.iter().filter(|b| self.collides(b.model)) {
            let Some((lo, hi)) = body.cells else {
                continue;
            };
            // The body itself is filed in these tiles: only other blockers
            // are tested, each once (the first few, at least), as in `cast`.
            let mut tested = Seen::default();
            for t in self.statics.tiles_of_box(lo, hi) {
                for &c in self.movers.in_tile(t) {
                    if !blocks(usize::from(c)) || !tested.first(c) {
                        continue;
                    }
                    if self.movers.overlaps(usize::from(c) - 1, &body.body) {
                        return true;
                    }
                }
            }
        }
        false
    }

    /// True when the static grid's clearance shows no static cell under
    /// `body` (false when the grid does not keep it).
    fn in_the_open(&self, body: &Body) -> bool {
        let (cx, cy, reach) = body.circle();
        // A cell's width to spare: a polygon's outline marks the cells it
        // touches, even those it only grazes.
        reach < 0.0 || self.statics.clearance(cx, cy) > reach + self.statics.lattice().resolution()
    }

    /// Files the `bodies` (from `tree_at` of a robot: all movable, as
    /// everything on a robot and everything it carries is) where they were
    /// placed.
    fn commit(&mut self, bodies: &mut [Placed]) {
        for body in bodies {
            debug_assert!(self.movable[body.model], "a static body in a robot's tree");
            if self.in_grid(body.model) {
                self.file(body);
            }
        }
    }

    /// Moves model `m` (and what it carries) to `pose`, relative to its parent.
    pub fn set_pose(&mut self, m: usize, pose: Pose) {
        // As Stage's SetPose: the heading wrapped into (-π, π].
        let pose = Pose {
            yaw: normalize(pose.yaw),
            ..pose
        };
        self.poses[m] = pose;
        for k in self.trees[m].clone() {
            // Its height too: a 3D pose may have lifted it.
            (self.looks[k].lo, self.looks[k].hi) = height(&self.world, &self.poses, k);
            self.place(k);
        }
        let g = self.global(m);
        if let Some(b) = self.bases.iter_mut().find(|b| b.model == m) {
            if self.world.models[m]
                .position
                .as_ref()
                .is_some_and(|c| c.localization == Localization::Gps)
            {
                b.odom = b.origin.inverse().compose(&g);
            }
        }
    }

    /// Whether model `m` updates in the step from `self.time`: Stage
    /// updates a model every `update_interval`, at its multiples.
    fn due(&self, m: usize) -> bool {
        let every = self.frames[m].every;
        let k = |t: f64| (t / every + 1e-9).floor();
        k(self.time + self.world.interval_sim) > k(self.time)
    }

    /// What is done in series once the bases have moved and the rangers
    /// read: `fasr`'s robots load and unload, `fasr2`'s take their whole
    /// update (their flags change hands), then sources refill and packs
    /// are used and charged.
    fn chores(&mut self) {
        let mut fasr2 = self.fasr2.take();
        for bi in 0..self.bases.len() {
            let m = self.bases[bi].model;
            match (self.bases[bi].ctrl, &mut fasr2) {
                (Some(Ctrl::Fasr { source, sink, .. }), _) if self.due(m) => {
                    let g = self.global(m);
                    let mind = &mut self.bases[bi].mind;
                    ctrl::fasr_position(&mut self.energy, mind, m, (g.x, g.y), source, sink);
                }
                (Some(Ctrl::Fasr2 { .. }), Some(f)) if self.due(m) => self.fasr2_update(bi, f),
                _ => {}
            }
        }
        self.fasr2 = fasr2;
        self.update_energy();
    }

    /// Advances the world by one `interval_sim`.
    pub fn step(&mut self) {
        let dt = self.world.interval_sim;
        self.run(Some(dt));
        self.chores();
        self.time += dt;
        self.steps += 1;
    }

    /// Works out what base `bi` does in a step of `dt`, from the poses at
    /// the step's start, into `plan`.
    ///
    /// # Behavior
    ///
    /// Bases move one after another, each seeing those before it where they
    /// moved to; but what a base asks for and whether it would meet a wall
    /// depend on it alone, so every base is planned at once (on every
    /// thread), and only the test against the other robots and the move
    /// itself are left for [`Sim::apply`], in order. A base on another
    /// model's back is planned there too, as it stands once that has moved.
    fn plan(&self, bi: usize, dt: f64, plan: &mut Plan) {
        let m = self.bases[bi].model;
        let Some(cfg) = &self.motions[bi] else {
            return;
        };
        plan.mind = self.bases[bi].mind;
        let want = match self.bases[bi].cmd {
            _ if !self.bases[bi].enabled => Pose::default(),
            Some(Command::Vel(v)) => v,
            Some(Command::Car(speed, steer)) => {
                Pose::new(speed, 0.0, speed * steer.tan() / cfg.wheelbase.max(1e-6))
            }
            Some(Command::GoTo(goal)) => {
                let o = self.bases[bi].odom;
                let (dx, dy) = (goal.x - o.x, goal.y - o.y);
                let dist = dx.hypot(dy);
                if dist > 0.05 {
                    let err = normalize(dy.atan2(dx) - o.yaw);
                    let (s, c) = o.yaw.sin_cos();
                    match cfg.drive {
                        Drive::Omni => Pose::new(
                            (c * dx + s * dy).clamp(-1.0, 1.0),
                            (-s * dx + c * dy).clamp(-1.0, 1.0),
                            (2.0 * normalize(goal.yaw - o.yaw)).clamp(-1.0, 1.0),
                        ),
                        _ => Pose::new(
                            dist.min(1.0) * err.cos().max(0.0),
                            0.0,
                            (2.0 * err).clamp(-1.5, 1.5),
                        ),
                    }
                } else {
                    let err = normalize(goal.yaw - o.yaw);
                    Pose::new(
                        0.0,
                        0.0,
                        if err.abs() > 0.02 {
                            (2.0 * err).clamp(-1.0, 1.0)
                        } else {
                            0.0
                        },
                    )
                }
            }
            None => match self.bases[bi].ctrl {
                Some(c) => self.control(bi, c, &mut plan.mind),
                None => Pose::default(),
            },
        };
        // As Stage's velocity control: the speeds asked for, within the
        // velocity bounds (its acceleration bounds are for its
        // acceleration control, which no controller here uses).
        let vb = &cfg.bounds;
        let mut v = Pose::new(
            want.x.clamp(vb[0], vb[1]),
            want.y.clamp(vb[2], vb[3]),
            want.yaw.clamp(vb[4], vb[5]),
        );
        if cfg.drive != Drive::Omni {
            v.y = 0.0;
        }
        let here = self.poses[m];
        let next = here.compose(&Pose::new(v.x * dt, v.y * dt, v.yaw * dt));
        let root_parent = self.frames[m].parent == Frame::ROOT;
        let g_next = if root_parent {
            next
        } else {
            self.global(m)
                .compose(&Pose::new(v.x * dt, v.y * dt, v.yaw * dt))
        };
        plan.v = v;
        plan.next = next;
        plan.moving = v.x != 0.0 || v.y != 0.0 || v.yaw != 0.0;
        if plan.moving {
            self.tree_at(m, g_next, &mut plan.bodies);
            plan.walled = self.hits_statics(self.root(m), &plan.bodies);
        }
    }

    /// Carries out base `bi`'s `plan` (see [`Sim::plan`]).
    fn apply(&mut self, bi: usize, dt: f64, plan: &mut Plan) {
        let m = self.bases[bi].model;
        if self.root(m) != m {
            // On another model's back: planned where that one moved to.
            self.plan(bi, dt, plan);
        }
        let Some(cfg) = &self.motions[bi] else {
            return;
        };
        let (localization, e) = (cfg.localization, cfg.odom_error);
        let v = plan.v;
        self.bases[bi].mind = plan.mind;
        if plan.moving {
            if plan.walled || self.hits_movers(self.root(m), &plan.bodies) {
                let b = &mut self.bases[bi];
                b.stall = true;
                b.vel = Pose::default();
                return;
            }
            self.poses[m] = plan.next;
            self.commit(&mut plan.bodies);
            if localization == Localization::Gps {
                let g = self.global(m);
                let b = &mut self.bases[bi];
                b.odom = b.origin.inverse().compose(&g);
            }
        }
        self.bases[bi].stall = false;
        self.bases[bi].vel = v;
        if localization == Localization::Odom {
            let b = &mut self.bases[bi];
            b.odom = b.odom.compose(&Pose::new(
                v.x * dt * (1.0 + e[0]),
                v.y * dt * (1.0 + e[1]),
                v.yaw * dt * (1.0 + e[2]),
            ));
        }
    }

    /// Updates every ranger's readings, on the crew's threads.
    pub fn sense(&mut self) {
        self.run(None);
    }

    /// Moves every base by a step of `dt` (none when `None`), then updates
    /// every ranger's readings, on the crew's threads.
    ///
    /// # Behavior
    ///
    /// Every thread plans bases (see [`Sim::plan`]); one thread then
    /// carries the plans out in order, while the others wait for it,
    /// spinning (a sleeping thread wakes later than the moves end). Then
    /// every thread casts rays. Each thread takes the bases and rangers of
    /// its share of the robots first (see [`crate::crew`]). With one
    /// thread, none waits; a helper that starts late finds the bases
    /// planned.
    fn run(&mut self, dt: Option<f64>) {
        let crew = std::mem::take(&mut self.crew);
        let mut kept = std::mem::take(&mut self.plans);
        kept.resize_with(self.bases.len(), Mutex::default);
        let moves = dt.is_some();
        let dt = dt.unwrap_or(0.0);
        // Each ranger's readings, moved out of the simulator while its rays
        // are cast.
        let work: Vec<Mutex<(usize, Readings)>> = crew
            .rangers()
            .iter()
            .map(|&r| Mutex::new((r, Readings::default())))
            .collect();
        let (to_plan, to_sense) = (crew.bases_to_plan(), crew.rangers_to_sense());
        let sensing = AtomicBool::new(false);
        let over = AtomicBool::new(false);
        let plan = |me: &Sim| {
            while let Some(bi) = to_plan.take().filter(|_| moves) {
                me.plan(bi, dt, &mut lock(&kept[bi]));
            }
        };
        let sense = |me: &Sim| {
            let mut sweep = Sweep::default();
            while let Some(k) = to_sense.take() {
                let mut slot = lock(&work[k]);
                let (r, out) = &mut *slot;
                // As Stage, a ranger senses every `update_interval` (100
                // ms), however short the steps; in between it keeps its
                // readings.
                if moves && !me.due(*r) {
                    continue;
                }
                me.sense_one(*r, out, &mut sweep);
                if me.noisy[*r] {
                    me.add_noise(*r, out.sensor_mut(0).0);
                }
            }
        };
        let sim = RwLock::new(&mut *self);
        let read = || sim.read().unwrap_or_else(PoisonError::into_inner);
        let helper = || {
            plan(&read());
            // Spinning while the moves are carried out: a sleeping thread
            // would wake after they end.
            spin_until(|| sensing.load(Ordering::Acquire) || over.load(Ordering::Acquire));
            if sensing.load(Ordering::Acquire) {
                sense(&read());
            }
        };
        let main = || {
            // However this ends (a panic too), the helpers stop waiting.
            let _release = Release(&over);
            plan(&read());
            {
                // Waits for helpers still planning a base.
                let mut me = sim.write().unwrap_or_else(PoisonError::into_inner);
                let me: &mut Sim = &mut me;
                if moves {
                    for (bi, slot) in kept.iter().enumerate() {
                        me.apply(bi, dt, &mut lock(slot));
                    }
                    me.carry(dt);
                }
                me.statics.refresh_clearance();
                if let Some(r) = &mut me.raster {
                    r.refresh();
                }
                for slot in &work {
                    let mut slot = lock(slot);
                    slot.1 = std::mem::take(&mut me.readings[slot.0]);
                }
            }
            sensing.store(true, Ordering::Release);
            sense(&read());
        };
        crew.run(helper, main);
        for slot in work {
            let (r, out) = slot.into_inner().unwrap_or_else(PoisonError::into_inner);
            self.readings[r] = out;
        }
        self.plans = kept;
        self.crew = crew;
    }

    /// The first body along the ray from (x, y) along the unit vector
    /// `(dx, dy)`, within `range`, whose id `accept`s: walls and other static
    /// bodies from the static grid, moving bodies tested exactly as the ray
    /// passes their tiles. The ray is looked at from `range.0` on: the
    /// caller knows nothing it accepts lies nearer. Body `own` (0 for
    /// none), which `accept` refuses, is passed over untested: a ranger's
    /// rays start in their own robot.
    fn cast(
        &self,
        x: f64,
        y: f64,
        (dx, dy): (f64, f64),
        range: (f64, f64),
        accept: impl Fn(u16) -> bool,
        own: u16,
    ) -> Option<Hit> {
        // A body filed in several tiles the ray crosses is met in each: its
        // circle and a rectangle cost less to test again than to look up
        // among those tested, but a body of many edges is tested once.
        let movers = TileBodies::new(self, (x, y), (dx, dy), &accept, own);
        self.statics
            .cast_with(x, y, (dx, dy), range, &accept, movers)
    }

    /// [`Sim::cast`] when the moving bodies the ray may meet are known: the
    /// nearest of them, and the static grid up to it.
    fn cast_among(
        &self,
        x: f64,
        y: f64,
        d: (f64, f64),
        (from, max_range): (f64, f64),
        accept: impl Fn(u16) -> bool,
        bodies: impl Iterator<Item = u16>,
    ) -> Option<Hit> {
        let best = self
            .nearest_body((x, y), d, bodies, |_| true, 0, &mut Seen::default())
            .filter(|h| h.range <= max_range);
        let reach = best.map_or(max_range, |b| b.range);
        match self.statics.cast_open(x, y, d, (from, reach), &accept) {
            Some(h) if best.is_none_or(|b| h.range < b.range) => Some(h),
            _ => best,
        }
    }

    /// The first moving body whose id `accept`s along the ray from (x, y)
    /// along the unit vector `d`, within `reach`: the static grid's tiles
    /// name the bodies to test.
    fn cast_movers(
        &self,
        x: f64,
        y: f64,
        d: (f64, f64),
        reach: f64,
        accept: impl Fn(u16) -> bool,
    ) -> Option<Hit> {
        let movers = TileBodies::new(self, (x, y), d, accept, 0);
        self.statics
            .cast_with(x, y, d, (0.0, reach), |_| false, movers)
    }

    /// The first of the moving `bodies` whose id `accept`s met by the ray
    /// from `o` along the unit vector `d` (the earliest of those met
    /// equally near); bodies of many edges in `tested` are not tested
    /// again, nor body `own`.
    #[inline(always)]
    fn nearest_body(
        &self,
        o: (f64, f64),
        d: (f64, f64),
        bodies: impl Iterator<Item = u16>,
        accept: impl Fn(u16) -> bool,
        own: u16,
        tested: &mut Seen,
    ) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        for k in bodies.filter(|&k| k != own) {
            let once = |k| tested.first(k);
            if let Some(h) = self.movers.hit(usize::from(k) - 1, k, o, d, &accept, once) {
                if best.is_none_or(|b| h.range < b.range) {
                    best = Some(h);
                }
            }
        }
        best
    }

    /// How far from (x, y) nothing `accept`ed lies, in any direction: the
    /// static grid's clearance there, less for a moving body within it.
    fn open_around(&self, x: f64, y: f64, accept: impl Fn(u16) -> bool) -> f64 {
        let free = self.statics.clearance(x, y);
        if free <= 0.0 {
            return 0.0;
        }
        let disc = [x - free, y - free, x + free, y + free];
        let Some((lo, hi)) = self.statics.lattice().cells_of_box(disc) else {
            return 0.0;
        };
        let mut open = free;
        for t in self.statics.tiles_of_box(lo, hi) {
            for &k in self.movers.in_tile(t) {
                if accept(k) {
                    open = open.min(self.movers.clearance(usize::from(k) - 1, (x, y)));
                }
            }
        }
        open.max(0.0)
    }

    /// The model at the root of model `m`'s tree (a held box's is its
    /// gripper's robot).
    fn root(&self, m: usize) -> usize {
        self.looks[m].root as usize
    }

    /// Whether model `m`'s body spans height `z` (Stage's ray z test).
    fn spans(&self, m: usize, z: f64) -> bool {
        self.looks[m].spans(z)
    }

    /// What ranger `r`'s rays at height `z` stop at: anything with a ranger
    /// return at that height that is not part of its own robot.
    fn ranger_sees(&self, r: usize, z: f64) -> impl Fn(u16) -> bool + Copy + '_ {
        let root = self.looks[r].root;
        move |c: u16| {
            let o = &self.looks[usize::from(c) - 1];
            o.root != root && o.seen() && o.spans(z)
        }
    }

    /// Ranger `r`'s readings into `out`; `sweep` is room for its fans' look
    /// at the moving bodies, kept from ranger to ranger.
    fn sense_one(&self, r: usize, out: &mut Readings, sweep: &mut Sweep) {
        let (g, gz) = self.global_z(r);
        let fans = &self.fans[r];
        // One sine and cosine per ranger: it is placed on its parent by
        // it, and its sensors' poses and first rays are turned by it (or
        // by a second, when its origin is turned).
        let o = &fans.origin;
        let (sin, cos) = g.yaw.sin_cos();
        let base = (g.x + cos * o.x - sin * o.y, g.y + sin * o.x + cos * o.y);
        let turn = if o.yaw == 0.0 {
            (cos, sin)
        } else {
            unit(g.yaw + o.yaw)
        };
        // The body the rays start in, which they never stop at.
        let own = u16::try_from(self.looks[r].root + 1).unwrap_or(0);
        for (i, s) in fans.rays.iter().enumerate() {
            let (ranges, intensities) = out.sensor_mut(i);
            let accept = self.ranger_sees(r, gz + s.z);
            let (ox, oy) = turned(turn, s.at);
            let (ox, oy) = (base.0 + ox, base.1 + oy);
            // A fan of rays shares one look at the moving bodies within
            // reach, so that each ray tests only those in its direction,
            // and (against the exact bodies) one look around its origin,
            // so that none of its rays walks the open space there.
            let fan = s.samples >= FAN;
            let from = if fan {
                sweep.start(
                    &self.movers,
                    &Fan {
                        o: (ox, oy),
                        first: turned(turn, s.first),
                        step: fans.turns[i].1,
                        n: s.samples,
                        reach: s.range.1,
                    },
                    accept,
                );
                match self.raster {
                    Some(_) => 0.0,
                    None => self.open_around(ox, oy, accept),
                }
            } else {
                0.0
            };
            // Sample directions by rotating the first one step by step
            // (no trigonometry per ray).
            let mut d = turned(turn, s.first);
            for k in 0..s.samples {
                if k > 0 {
                    d = turned(fans.turns[i].0, d);
                }
                let hit = match (&self.raster, fan) {
                    // Static bodies as Stage sees them; moving bodies
                    // exactly, up to the wall.
                    (Some(r), _) => {
                        let wall = r.cast(ox, oy, d, s.range.1, accept);
                        let reach = wall.map_or(s.range.1, |h| h.range);
                        let body = if fan {
                            self.nearest_body(
                                (ox, oy),
                                d,
                                sweep.at(k),
                                |_| true,
                                0,
                                &mut Seen::default(),
                            )
                            .filter(|h| h.range <= reach)
                        } else {
                            self.cast_movers(ox, oy, d, reach, accept)
                        };
                        body.or(wall)
                    }
                    (None, true) => {
                        self.cast_among(ox, oy, d, (from, s.range.1), accept, sweep.at(k))
                    }
                    (None, false) => self.cast(ox, oy, d, (from, s.range.1), accept, own),
                };
                let (range, intensity) = match hit {
                    Some(h) => (
                        h.range.max(s.range.0),
                        self.looks[usize::from(h.id) - 1].ret,
                    ),
                    None => (s.range.1, 0.0),
                };
                ranges[k] = range;
                intensities[k] = intensity;
            }
        }
    }

    /// Gives gripper `g` Stage's command: close (`true`) or open. The
    /// paddles move at its next updates.
    pub fn grip(&mut self, g: usize, close: bool) {
        if let Some(st) = &mut self.grippers[g] {
            st.command = Some(close);
        }
    }

    /// The first model with `gripper_return`, other than gripper `g`, on
    /// the ray from `(x, y)` (in `g`'s frame) along `yaw` for `len` metres,
    /// at the gripper's height.
    fn gripper_ray(&self, g: usize, (x, y, yaw): (f64, f64, f64), len: f64) -> Option<usize> {
        if len <= 0.0 {
            return None;
        }
        let (at, z) = self.global_z(g);
        let o = at.compose(&self.world.models[g].origin).apply(x, y);
        let accept = |id: u16| {
            let k = usize::from(id) - 1;
            k != g && self.world.models[k].gripper_return && self.spans(k, z)
        };
        let d = unit(at.yaw + yaw);
        self.cast(o.0, o.1, d, (0.0, len), accept, 0)
            .map(|h| usize::from(h.id) - 1)
    }

    /// One update of gripper `g`, as Stage's gripper model makes it.
    fn update_gripper(&mut self, g: usize) {
        let Some(mut st) = self.grippers[g].clone() else {
            return;
        };
        match st.command {
            Some(true) if st.paddles != Paddles::Closed => st.paddles = Paddles::Closing,
            Some(false) if st.paddles != Paddles::Open => st.paddles = Paddles::Opening,
            _ => {}
        }
        match st.paddles {
            Paddles::Opening => {
                st.position -= PADDLE_STEP;
                if st.position < 0.0 {
                    st.position = 0.0;
                    st.paddles = Paddles::Open;
                }
                if st.position == 0.0 || st.position < st.close_limit {
                    if let Some((k, _)) = st.held.take() {
                        // Let go where it is (Stage puts it at the
                        // gripper's pose: it is there already).
                        for t in self.trees[k].clone() {
                            self.looks[t].root = self.world.root(t) as u32;
                        }
                    }
                    st.close_limit = 1.0;
                }
            }
            Paddles::Closing => {
                st.position += PADDLE_STEP;
                if st.position > st.close_limit {
                    st.position = st.close_limit;
                    st.paddles = Paddles::Closed;
                }
            }
            Paddles::Open | Paddles::Closed => {}
        }
        let [sx, sy, _] = self.world.models[g].size;
        // The paddles' inner faces, from the centre line.
        let face = (1.0 - st.position) * (sy / 2.0 - sy * PADDLE_Y);
        let gap = (1.0 - st.position) * (sy - 2.0 * sy * PADDLE_Y);
        st.beams = 0;
        for (bit, inset) in [0x04, 0x08].into_iter().zip(BEAM_INSET) {
            let x = sx * (1.0 - inset) - sx / 2.0;
            if self
                .gripper_ray(g, (x, face, -std::f64::consts::FRAC_PI_2), gap)
                .is_some()
            {
                st.beams |= bit;
            }
        }
        let base = sx * (1.0 - PADDLE_X) - sx / 2.0;
        let touched = [face, -face]
            .into_iter()
            .find_map(|y| self.gripper_ray(g, (base, y, 0.0), PADDLE_X * sx));
        if let (Some(k), Paddles::Closing, None) = (touched, st.paddles, st.held) {
            // Taken: to the gripper's centre, and along with it from now on.
            st.held = Some((k, Pose::default()));
            st.close_limit = (1.0 - self.world.models[k].size[1] / (sy - PADDLE_Y / 2.0)).max(0.0);
            self.looks[k].root = self.looks[g].root;
            if !self.movable[k] {
                for t in self.trees[k].clone() {
                    self.unplace(t);
                    self.movable[t] = true;
                    self.place(t);
                }
            }
        }
        self.grippers[g] = Some(st);
    }

    /// Takes model `m`'s body out: its cells from the static grid, or its
    /// filing with the moving bodies.
    fn unplace(&mut self, m: usize) {
        if self.movable[m] {
            self.movers.unfile(m, id(m));
            self.count_touches(m, -1);
            self.touches[m].clear();
            return;
        }
        if let Some(r) = &mut self.raster {
            for &(x, y) in &self.drawn[m] {
                if r.get(x, y) == id(m) {
                    r.set(x, y, EMPTY);
                }
            }
        }
        self.drawn[m].clear();
        if let Some(at) = self.written_at[m].take() {
            self.body_cells(m, at, |g, i, j| {
                if g.get(i, j) == id(m) {
                    g.set(i, j, EMPTY);
                }
            });
        }
    }

    /// Updates the grippers every 100 ms of simulated time, and moves
    /// what they hold with them.
    fn carry(&mut self, dt: f64) {
        for g in 0..self.grippers.len() {
            let Some(st) = &mut self.grippers[g] else {
                continue;
            };
            st.since += dt;
            // (Less a hair: steps of 0.1 s add up to a little less.)
            if st.since >= GRIPPER_INTERVAL - 1e-9 {
                st.since -= GRIPPER_INTERVAL;
                self.update_gripper(g);
            }
            if let Some((k, rel)) = self.grippers[g].as_ref().and_then(|s| s.held) {
                let to = self.global(g).compose(&rel);
                self.set_pose(k, to);
            }
        }
    }

    /// What blobfinder `m` sees now, as Stage's blobfinder and its Player
    /// plugin report it.
    ///
    /// # Behavior
    ///
    /// One ray per image column, from the right edge of the view leftwards,
    /// at every height (Stage does not test heights here) and stopped by
    /// anything outside the finder's robot. Runs of columns of one colour
    /// make a blob, which counts if its colour is tracked (any colour when
    /// none is given); as in Stage's loop, the column after a run is not
    /// looked at. A blob is drawn as a 0.6 m tall robot at its columns'
    /// mean range; rows are `fov / height` radians each. Player's plugin
    /// then takes the centre and area from the box's width and height less
    /// one each, and reports an empty image (0 x 0) when there is no blob.
    pub fn blobs(&self, m: usize) -> troupe_msgs::blobfinder::Data {
        use troupe_msgs::blobfinder::{Blob, Data};
        let Some(cfg) = &self.world.models[m].blobfinder else {
            return Data::default();
        };
        let (w, h) = cfg.image;
        let n = w as usize;
        let eye = self.global(m).compose(&self.world.models[m].origin);
        let root = self.root(m);
        let accept = |id: u16| self.root(usize::from(id) - 1) != root;
        let step = cfg.fov / n.saturating_sub(1).max(1) as f64;
        let samples: Vec<Option<(Color, f64)>> = (0..n)
            .map(|s| {
                let a = eye.yaw + cfg.pan - cfg.fov / 2.0 + s as f64 * step;
                self.cast(eye.x, eye.y, unit(a), (0.0, cfg.range), accept, 0)
                    .map(|hit| (self.colors[usize::from(hit.id) - 1], hit.range))
            })
            .collect();
        let same = |a: Color, b: Color| {
            (a.r - b.r).abs() < 1e-5 && (a.g - b.g).abs() < 1e-5 && (a.b - b.b).abs() < 1e-5
        };
        let rads_per_row = cfg.fov / f64::from(h);
        let half = i64::from(h / 2);
        let mut blobs = Vec::new();
        let mut s = 0;
        while s < n {
            let Some((col, _)) = samples[s] else {
                s += 1;
                continue;
            };
            let right = s;
            while s < n && samples[s].is_some_and(|(c, _)| same(c, col)) {
                s += 1;
            }
            let left = s - 1;
            s += 1;
            if !cfg.colors.is_empty() && !cfg.colors.iter().any(|&c| same(c, col)) {
                continue;
            }
            let run = &samples[right..=left];
            let range = run.iter().flatten().map(|x| x.1).sum::<f64>() / run.len() as f64;
            // Truncated as C's (int) cast truncates.
            let rows = ((0.3f64).atan2(range) / rads_per_row) as i64;
            let top = (half - rows).max(0);
            let bottom = (half + rows).min(i64::from(h));
            // Image columns run the other way: the right edge is column 0.
            let (bl, br) = ((n - 1 - left) as i64, (n - 1 - right) as i64);
            let (dx, dy) = (br - bl, top - bottom);
            let byte = |v: f32| u32::from((v.clamp(0.0, 1.0) * 255.0) as u8);
            let u = |v: i64| u32::try_from(v).unwrap_or(0);
            blobs.push(Blob {
                id: blobs.len() as u32,
                color: (byte(col.r) << 16) | (byte(col.g) << 8) | byte(col.b),
                area: u((dx * dy).abs()),
                x: u(bl + dx / 2),
                y: u(bottom + dy / 2),
                left: u(bl),
                right: u(br),
                top: u(top),
                bottom: u(bottom),
                range: range as f32,
            });
        }
        let (width, height) = if blobs.is_empty() { (0, 0) } else { (w, h) };
        Data {
            width,
            height,
            blobs,
        }
    }

    /// What fiducial detector `m` sees now.
    pub fn fiducials(&self, m: usize) -> troupe_msgs::fiducial::Data {
        use troupe_msgs::fiducial::{Data, Item};
        let Some(cfg) = &self.world.models[m].fiducial else {
            return Data::default();
        };
        let (g, z) = self.global_z(m);
        let eye = g.compose(&self.world.models[m].origin);
        let root = self.root(m);
        let mut items = Vec::new();
        for (k, target) in self.world.models.iter().enumerate() {
            if target.fiducial_return == 0 || self.root(k) == root {
                continue;
            }
            let rel = eye.inverse().compose(&self.global(k));
            let range = rel.x.hypot(rel.y);
            let bearing = rel.y.atan2(rel.x);
            if range < cfg.range_min || range > cfg.range_max || bearing.abs() > cfg.fov / 2.0 {
                continue;
            }
            // Seen only if the first thing the ray at the finder's height
            // meets is the target itself, as Stage traces it (out to the
            // finder's range): one below or above that height is not seen.
            let accept = |id: u16| {
                let o = usize::from(id) - 1;
                self.root(o) != root && self.spans(o, z)
            };
            let first = self.cast(
                eye.x,
                eye.y,
                unit(eye.yaw + bearing),
                (0.0, cfg.range_max),
                accept,
                0,
            );
            if first.is_none_or(|h| usize::from(h.id) - 1 != k) {
                continue;
            }
            let pose = troupe_msgs::Pose3d::planar(rel.x, rel.y, rel.yaw);
            items.push(Item {
                id: if range <= cfg.range_max_id {
                    target.fiducial_return
                } else {
                    -1
                },
                pose,
                upose: troupe_msgs::Pose3d::default(),
            });
        }
        Data { fiducials: items }
    }

    /// A picture of the world: obstacles grey, bodies in their colours,
    /// range readings as light rays, at most `max_px` pixels across.
    pub fn snapshot(&self, max_px: u32) -> image::RgbImage {
        let (w, h) = self.statics.lattice().size();
        let scale = (w.max(h) as f64 / f64::from(max_px.max(16))).max(1.0);
        let (iw, ih) = (
            ((w as f64) / scale).ceil() as u32,
            ((h as f64) / scale).ceil() as u32,
        );
        let mut img = image::RgbImage::from_pixel(iw, ih, image::Rgb([255, 255, 255]));
        let px = |i: usize, j: usize| {
            (
                (i as f64 / scale) as u32,
                ih - 1 - ((j as f64 / scale) as u32).min(ih - 1),
            )
        };
        let rgb = |c: Color| {
            image::Rgb([
                (c.r * 255.0) as u8,
                (c.g * 255.0) as u8,
                (c.b * 255.0) as u8,
            ])
        };
        // Rays first (of the rangers that sense: the others hold their
        // first, full-range readings), bodies over them.
        for (r, rd) in self.readings.iter().enumerate() {
            if rd.is_empty() || !self.sensed[r] {
                continue;
            }
            let base = self.global(r).compose(&self.world.models[r].origin);
            for (s, reading) in self.world.models[r].sensors.iter().zip(rd.iter()) {
                let o = base.compose(&s.pose);
                for (k, &range) in reading.ranges.iter().enumerate() {
                    let a = if s.samples > 1 {
                        o.yaw - s.fov / 2.0 + s.fov * k as f64 / (s.samples - 1) as f64
                    } else {
                        o.yaw
                    };
                    let end = (o.x + range * a.cos(), o.y + range * a.sin());
                    self.statics
                        .lattice()
                        .segment_cells((o.x, o.y), end, &mut |i, j| {
                            let (x, y) = px(i, j);
                            if x < iw {
                                img.put_pixel(x, y, image::Rgb([170, 210, 255]));
                            }
                        });
                }
            }
        }
        for j in 0..h {
            for i in 0..w {
                let c = self.statics.get(i, j);
                if c != EMPTY {
                    let (x, y) = px(i, j);
                    if x < iw {
                        img.put_pixel(x, y, rgb(self.colors[usize::from(c) - 1]));
                    }
                }
            }
        }
        let lat = *self.statics.lattice();
        for m in (0..self.world.models.len()).filter(|&m| self.movable[m]) {
            for p in self.movers.shapes(m) {
                lat.polygon_cells(p, |i, j| {
                    let (x, y) = px(i, j);
                    if x < iw {
                        img.put_pixel(x, y, rgb(self.colors[m]));
                    }
                });
            }
        }
        img
    }

    /// The global pose of model `m`.
    pub fn global(&self, m: usize) -> Pose {
        self.global_z(m).0
    }

    /// The global pose of model `m` and its base's height above the floor
    /// (as [`World::global`], from the models' frames).
    fn global_z(&self, m: usize) -> (Pose, f64) {
        let f = &self.frames[m];
        match f.parent {
            Frame::ROOT => (self.poses[m], f.z),
            p => {
                let p = p as usize;
                let (gp, gz) = self.global_z(p);
                (gp.compose(&self.poses[m]), gz + f.z + self.frames[p].stack)
            }
        }
    }

    /// Sets model `m`'s height above its parent's top (`z` of its pose):
    /// in its definition and in the frame the steps read (see [`Frame`]),
    /// so set it here, not in `world`.
    pub fn set_z(&mut self, m: usize, z: f64) {
        self.world.models[m].z = z;
        self.frames[m].z = z;
    }

    /// The loaded world.
    pub fn world(&self) -> &World {
        &self.world
    }

    /// Sets the id fiducial finders read of model `m` (Stage's
    /// `fiducial_return`).
    pub fn set_fiducial_return(&mut self, m: usize, id: i32) {
        self.world.models[m].fiducial_return = id;
    }

    /// The occupancy map of model `m`'s body, as the Stage plugin's `map`
    /// device drew it: the model's `size` cut into cells of its
    /// `map_resolution`, a cell occupied where a block covers part of it,
    /// free elsewhere. The map's origin is the
    /// body's lower left corner at the model's current pose.
    ///
    /// # Errors
    ///
    /// A `map_resolution` that is not a positive number.
    pub fn model_map(&self, m: usize) -> Result<OccMap, String> {
        let d = &self.world.models[m];
        let res = d.map_resolution;
        if !(res > 0.0 && res.is_finite()) {
            return Err(format!(
                "{}: model `{}` has map_resolution {res}; a map needs a positive cell size",
                d.pos, d.name
            ));
        }
        let (sx, sy) = (d.size[0], d.size[1]);
        let (w, h) = (
            ((sx / res).floor() as u32).max(1),
            ((sy / res).floor() as u32).max(1),
        );
        // The body's box in the model's frame (blocks have the origin applied).
        let (x0, y0) = (d.origin.x - sx / 2.0, d.origin.y - sy / 2.0);
        // Blocks are sampled at four points a cell along each axis, so a
        // cell is occupied when a block covers a sixteenth of it or so, and
        // an edge lying on a cell boundary does not spill into the next one.
        // Lattices are geometry only: no storage, however fine.
        const SUB: usize = 4;
        let (wc, hc) = (w as usize, h as usize);
        let fine = Lattice::of_cells(x0, y0, res / SUB as f64, wc * SUB, hc * SUB);
        let coarse = Lattice::of_cells(x0, y0, res, wc, hc);
        let mut cells = vec![FREE; wc * hc];
        for b in &d.blocks {
            let n = fine.polygon_centres(b, |i, j| cells[(j / SUB) * wc + i / SUB] = OCCUPIED);
            // A block thinner than that still shows, by its outline.
            if n == 0 {
                for k in 0..b.len() {
                    coarse.segment_cells(b[k], b[(k + 1) % b.len()], &mut |i, j| {
                        cells[j * wc + i] = OCCUPIED;
                    });
                }
            }
        }
        let corner = self.global(m).compose(&Pose::new(x0, y0, 0.0));
        Ok(OccMap {
            info: map::Info {
                width: w,
                height: h,
                resolution: res as f32,
                origin: corner.into(),
            },
            cells,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;

    fn sim(name: &str, text: &str) -> Sim {
        let dir = std::env::temp_dir().join(format!("troupe-sim-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("t.world");
        std::fs::write(&p, text).unwrap();
        let w = crate::world::load(&p).unwrap();
        let _ = std::fs::remove_dir_all(&dir);
        Sim::new(w).unwrap()
    }

    const ROOM: &str = "resolution 0.02\ninterval_sim 100\n\
        model ( name \"wall\" pose [5 0 0 0] size [0.2 10 1] )\n";

    fn steps(s: &mut Sim, n: usize) {
        for _ in 0..n {
            s.step();
        }
    }

    /// A ranger's readings lie sensor after sensor: each sensor reads and
    /// writes its own stretch, a sensor of no rays included, whether the
    /// sensors have a ray each or many.
    #[test]
    fn readings_keep_each_sensor_to_its_own_stretch() {
        let sensor = |samples: usize, far: f64| Sensor {
            pose: Pose::default(),
            z: 0.0,
            size: [0.1; 3],
            range: (0.0, far),
            fov: 1.0,
            samples,
        };
        let mut rd = Readings::new(&[
            sensor(3, 8.0),
            sensor(1, 5.0),
            sensor(0, 4.0),
            sensor(2, 2.0),
        ]);
        assert_eq!(rd.len(), 4);
        assert_eq!(rd.sensor(0).ranges, &[8.0; 3]);
        assert_eq!(rd.sensor(2).ranges, &[] as &[f64]);
        assert_eq!(rd.get(4), None);
        let (ranges, intensities) = rd.sensor_mut(3);
        ranges.copy_from_slice(&[1.5, 1.25]);
        intensities[1] = 0.5;
        assert_eq!(rd.sensor(3).ranges, &[1.5, 1.25]);
        assert_eq!(rd.sensor(3).intensities, &[0.0, 0.5]);
        assert_eq!(rd.sensor(1).ranges, &[5.0]);
        let firsts: Vec<f64> = (0..5).map(|i| rd.first_range(i)).collect();
        assert_eq!(firsts, [8.0, 5.0, 0.0, 1.5, 0.0]);
        assert_eq!(
            rd.iter().map(|r| r.ranges.len()).collect::<Vec<_>>(),
            [3, 1, 0, 2]
        );
        // A ray each: sensor k's reading is the k-th.
        let mut ring = Readings::new(&[sensor(1, 2.0), sensor(1, 2.0), sensor(1, 2.0)]);
        ring.sensor_mut(1).0[0] = 0.75;
        let firsts: Vec<f64> = (0..4).map(|i| ring.first_range(i)).collect();
        assert_eq!(firsts, [2.0, 0.75, 2.0, 0.0]);
        // As many rays as sensors, but not one each: the second has none.
        let uneven = Readings::new(&[sensor(2, 3.0), sensor(0, 1.0)]);
        assert_eq!([uneven.first_range(0), uneven.first_range(1)], [3.0, 0.0]);
        assert!(Readings::default().is_empty());
    }

    /// Fans start their rays beyond the open space around them; every
    /// reading stays what a ray walked from its origin reads, with robots
    /// crowding each other, a box and the wall nearby.
    #[test]
    fn fans_read_as_rays_walked_from_their_origin() {
        let mut text = format!("{ROOM}model ( name \"box\" pose [2 1 0 30] size [0.5 0.3 0.5] )\n");
        for k in 0..12 {
            let (x, y, a) = (
                1.0 + 0.35 * f64::from(k % 4 * 3),
                0.45 * f64::from(k / 4) - 0.5,
                37 * k,
            );
            text += &format!(
                "position ( name \"r{k}\" pose [{x} {y} 0 {a}] size [0.3 0.3 0.2] \
                ranger ( sensor ( pose [0.1 0 0 0] range [0.02 6] fov 270 samples 271 ) ) \
                acceleration_bounds [-9 9 -9 9 -9 9 -900 900] )\n"
            );
        }
        let mut s = sim("fans", &text);
        let rangers = s.crew.rangers().to_vec();
        let mut skipped = 0.0;
        for round in 0..4 {
            for (i, b) in s.bases.iter_mut().enumerate() {
                let turn = if (i + round) % 2 == 0 { 0.6 } else { -0.6 };
                b.cmd = Some(Command::Vel(Pose::new(0.3, 0.0, turn)));
            }
            steps(&mut s, 3);
            for &r in &rangers {
                let (g, z) = s.world.global(&s.poses, r);
                let sensor = &s.world.models[r].sensors[0];
                let accept = s.ranger_sees(r, z + sensor.z + sensor.size[2] / 2.0);
                let o = g.compose(&s.world.models[r].origin).compose(&sensor.pose);
                skipped += s.open_around(o.x, o.y, accept);
                for (k, &got) in s.readings[r].sensor(0).ranges.iter().enumerate() {
                    let a = o.yaw - sensor.fov / 2.0 + sensor.fov * k as f64 / 270.0;
                    let want = s
                        .cast(o.x, o.y, unit(a), (0.0, sensor.range.1), accept, 0)
                        .map_or(sensor.range.1, |h| h.range.max(sensor.range.0));
                    assert!(
                        (got - want).abs() < 1e-9,
                        "ranger {r} ray {k}: {got} vs {want}"
                    );
                }
            }
        }
        assert!(skipped > 1.0, "the fans skipped only {skipped} m in all");
    }

    #[test]
    fn diff_drive_moves_as_commanded() {
        let mut s = sim("diff", &format!("{ROOM}position ( name \"r\" pose [0 0 0 0] size [0.4 0.4 0.2] acceleration_bounds [-9 9 -9 9 -9 9 -900 900] )\n"));
        s.bases[0].cmd = Some(Command::Vel(Pose::new(0.5, 0.3, 0.0)));
        steps(&mut s, 10);
        let p = s.global(s.bases[0].model);
        // 1 s at 0.5 m/s; a diff drive ignores the sideways speed.
        assert!((p.x - 0.5).abs() < 1e-9 && p.y.abs() < 1e-9, "{p:?}");
        s.bases[0].cmd = Some(Command::Vel(Pose::new(0.0, 0.0, FRAC_PI_2)));
        steps(&mut s, 10);
        assert!((s.global(s.bases[0].model).yaw - FRAC_PI_2).abs() < 1e-9);
        assert!(
            (s.bases[0].odom.yaw - FRAC_PI_2).abs() < 1e-9,
            "gps odometry follows"
        );
    }

    #[test]
    fn omni_drive_moves_sideways_and_car_turns() {
        let mut s = sim("omni", &format!("{ROOM}position ( name \"r\" drive \"omni\" size [0.4 0.4 0.2] acceleration_bounds [-9 9 -9 9 -9 9 -900 900] )\n"));
        s.bases[0].cmd = Some(Command::Vel(Pose::new(0.0, 0.5, 0.0)));
        steps(&mut s, 10);
        let p = s.global(s.bases[0].model);
        assert!(p.x.abs() < 1e-9 && (p.y - 0.5).abs() < 1e-9, "{p:?}");
        let mut c = sim("car", &format!("{ROOM}position ( name \"r\" drive \"car\" wheelbase 1 size [0.4 0.4 0.2] acceleration_bounds [-9 9 -9 9 -9 9 -900 900] velocity_bounds [-1 1 -1 1 -1 1 -900 900] )\n"));
        c.bases[0].cmd = Some(Command::Car(0.5, std::f64::consts::FRAC_PI_4));
        steps(&mut c, 10);
        // yaw rate = v·tan(steer)/wheelbase = 0.5 rad/s.
        assert!((c.global(c.bases[0].model).yaw - 0.5).abs() < 1e-9);
    }

    #[test]
    fn velocity_bounds_hold_and_speeds_are_taken_at_once() {
        // As Stage's velocity control: acceleration bounds do not apply.
        let mut s = sim("bounds", &format!("{ROOM}position ( name \"r\" size [0.4 0.4 0.2] velocity_bounds [-0.5 0.5 0 0 0 0 -90 90] acceleration_bounds [-1 1 0 0 0 0 -90 90] )\n"));
        s.bases[0].cmd = Some(Command::Vel(Pose::new(2.0, 0.0, -3.0)));
        s.step();
        assert!((s.bases[0].vel.x - 0.5).abs() < 1e-9, "capped at 0.5 m/s");
        let quarter = -std::f64::consts::FRAC_PI_2;
        assert!(
            (s.bases[0].vel.yaw - quarter).abs() < 1e-9,
            "capped at 90°/s"
        );
        s.bases[0].cmd = Some(Command::Vel(Pose::new(0.1, 0.0, 0.0)));
        s.step();
        assert!((s.bases[0].vel.x - 0.1).abs() < 1e-9, "slowed at once");
    }

    #[test]
    fn a_robot_stops_and_stalls_at_a_wall() {
        let mut s = sim("stall", &format!("{ROOM}position ( name \"r\" pose [3 0 0 0] size [0.4 0.4 0.2] acceleration_bounds [-9 9 -9 9 -9 9 -900 900] )\n"));
        s.bases[0].cmd = Some(Command::Vel(Pose::new(1.0, 0.0, 0.0)));
        steps(&mut s, 40);
        let p = s.global(s.bases[0].model);
        assert!(s.bases[0].stall, "stalled");
        // The wall's face is at x = 4.9; the robot's front at x + 0.2.
        assert!(p.x + 0.2 < 4.92 && p.x > 4.5, "{p:?}");
        assert_eq!(s.bases[0].vel, Pose::default());
    }

    #[test]
    fn rangers_sense_every_100_ms_however_short_the_steps() {
        // 20 ms steps, as Stage's fasr.world takes them: the ranger reads
        // at every fifth, and holds its readings in between.
        let room = ROOM.replace("interval_sim 100", "interval_sim 20");
        let mut s = sim("interval", &format!("{room}position ( name \"r\" pose [0 0 0 0] size [0.4 0.4 0.2] ranger ( sensor ( range [0 8] samples 1 ) ) )\n"));
        s.bases[0].cmd = Some(Command::Vel(Pose::new(0.5, 0.0, 0.0)));
        let r = s.world.names["r.ranger:0"];
        let mut seen = vec![s.readings[r].sensor(0).ranges[0]];
        for _ in 0..10 {
            s.step();
            seen.push(s.readings[r].sensor(0).ranges[0]);
        }
        let changed: Vec<usize> = (1..seen.len())
            .filter(|&k| seen[k] != seen[k - 1])
            .collect();
        assert_eq!(changed, [5, 10], "{seen:?}");
        // Each time, 5 cm nearer the wall (0.5 m/s for 0.1 s).
        assert!((seen[5] - seen[10] - 0.05).abs() < 1e-6, "{seen:?}");
    }

    #[test]
    fn controllers_decide_as_their_rangers_update() {
        // 20 ms steps: `wander` first decides when its laser first reads,
        // at 100 ms, and its speeds hold between its decisions.
        let room = ROOM.replace("interval_sim 100", "interval_sim 20");
        let mut s = sim("ctrl-interval", &format!("{room}position ( name \"r\" pose [0 0 0 0] size [0.4 0.4 0.2] ctrl \"wander\" ranger ( sensor ( range [0 8] fov 180 samples 31 ) ) )\n"));
        steps(&mut s, 4);
        assert_eq!(s.bases[0].vel, Pose::default());
        s.step();
        assert!((s.bases[0].vel.x - 0.4).abs() < 1e-9);
        steps(&mut s, 3);
        assert!(
            (s.bases[0].vel.x - 0.4).abs() < 1e-9,
            "held between decisions"
        );
    }

    #[test]
    fn a_robot_with_a_fan_stalls_where_one_without_does() {
        // A fan makes the grid keep its clearance, which spares most moves
        // their cell-by-cell test: the stall must not move.
        let robot = |fan: &str| {
            format!("{ROOM}position ( name \"r\" pose [3 0.3 0 10] size [0.4 0.4 0.2] acceleration_bounds [-9 9 -9 9 -9 9 -900 900] {fan} )\n")
        };
        let mut stops = Vec::new();
        for fan in ["", "ranger ( sensor ( range [0 4] fov 180 samples 181 ) )"] {
            let mut s = sim("fanstall", &robot(fan));
            s.bases[0].cmd = Some(Command::Vel(Pose::new(0.7, 0.0, 0.0)));
            steps(&mut s, 40);
            assert!(s.bases[0].stall, "stalled ({fan})");
            stops.push(s.global(s.bases[0].model));
        }
        assert_eq!(stops[0], stops[1]);
        assert!(stops[0].x > 4.4 && stops[0].x < 4.7, "{:?}", stops[0]);
    }

    #[test]
    fn two_threads_read_and_move_as_one_does() {
        let world = |threads: usize| {
            let mut text = format!("threads {threads}\n{ROOM}");
            for k in 0..12 {
                let (x, y, a) = (
                    0.6 * f64::from(k % 4) - 1.0,
                    0.7 * f64::from(k / 4) - 0.7,
                    41 * k,
                );
                text += &format!(
                    "position ( name \"r{k}\" pose [{x} {y} 0 {a}] size [0.3 0.3 0.2] ctrl \"wander\" \
                    ranger ( sensor ( pose [0.1 0 0 0] range [0.02 6] fov 270 samples 271 ) ) )\n"
                );
            }
            sim("threads", &text)
        };
        let (mut one, mut two) = (world(1), world(2));
        assert_eq!(one.crew.threads(), 1);
        // (Two even on a machine of one core.)
        two.set_threads(2);
        for _ in 0..30 {
            one.step();
            two.step();
            assert_eq!(one.poses, two.poses);
            assert_eq!(one.readings, two.readings);
        }
        assert!(
            one.bases.iter().any(|b| b.odom != Pose::default()),
            "nobody moved"
        );
    }

    /// With Stage's ranges, the raster follows the robots as they move:
    /// readings after some steps equal those of a raster drawn afresh at
    /// the same poses.
    #[test]
    fn stage_ranges_follow_moving_robots() {
        let mut text = String::from(
            "resolution 0.02\n\
             model ( name \"n\" size [8 0.1 1] pose [0 3.95 0 0] )\n\
             model ( name \"s\" size [8 0.1 1] pose [0 -3.95 0 0] )\n\
             model ( name \"e\" size [0.1 8 1] pose [3.95 0 0 0] )\n\
             model ( name \"w\" size [0.1 8 1] pose [-3.95 0 0 10] )\n",
        );
        for k in 0..6 {
            let (x, y) = (-2.5 + f64::from(k), -1.0 + 0.4 * f64::from(k % 3));
            text += &format!(
                "position ( name \"r{k}\" pose [{x} {y} 0 {}] size [0.4 0.3 0.2] ctrl \"wander\" \
                 ranger ( sensor ( samples 90 fov 180 range [0 6] ) size [0.1 0.1 0.1] ) )\n",
                30 * k
            );
        }
        let mut s = sim("follow", &text);
        s.stage_ranges(true);
        let start: Vec<Pose> = s.bases.iter().map(|b| s.global(b.model)).collect();
        steps(&mut s, 40);
        let moved: Vec<Readings> = s.readings.clone();
        s.stage_ranges(false);
        s.stage_ranges(true);
        assert_eq!(s.readings, moved);
        for (b, p) in s.bases.iter().zip(start) {
            let now = s.global(b.model);
            assert!((now.x - p.x).hypot(now.y - p.y) > 0.1, "{now:?} from {p:?}");
        }
    }

    #[test]
    fn nearest_and_first_where_cover_every_length() {
        assert_eq!(nearest(&[]), f64::INFINITY);
        for n in 1..12 {
            let ranges: Vec<f64> = (0..n).map(|k| 10.0 - k as f64).collect();
            assert_eq!(nearest(&ranges), 11.0 - n as f64, "{n}");
        }
        assert_eq!(first_where(0, |_| true), 0);
        assert_eq!(first_where(10, |k| k >= 7), 7);
        assert_eq!(first_where(10, |_| false), 10);
    }

    #[test]
    fn robots_meeting_head_on_stall_apart() {
        let mut s = sim("headon", &format!("{ROOM}position ( name \"a\" pose [-1 0 0 0] size [0.4 0.4 0.2] acceleration_bounds [-9 9 -9 9 -9 9 -900 900] )\nposition ( name \"b\" pose [1 0.1 0 180] size [0.4 0.4 0.2] acceleration_bounds [-9 9 -9 9 -9 9 -900 900] )\n"));
        for b in &mut s.bases {
            b.cmd = Some(Command::Vel(Pose::new(0.5, 0.0, 0.0)));
        }
        steps(&mut s, 40);
        let (a, b) = (s.global(s.bases[0].model), s.global(s.bases[1].model));
        assert!(s.bases[0].stall && s.bases[1].stall, "both stalled");
        // Fronts at a.x + 0.2 and b.x - 0.2: touching within a step (5 cm).
        let gap = (b.x - 0.2) - (a.x + 0.2);
        assert!((0.0..0.06).contains(&gap), "gap {gap}: {a:?} {b:?}");
        // Turned away, a is free to go.
        s.bases[0].cmd = Some(Command::Vel(Pose::new(-0.5, 0.0, 0.0)));
        steps(&mut s, 5);
        assert!(!s.bases[0].stall && s.global(s.bases[0].model).x < a.x - 0.1);
    }

    #[test]
    fn rangers_see_hand_computed_walls() {
        let mut s = sim(
            "ranger",
            &format!("{ROOM}position ( name \"r\" pose [1 0 0 0] size [0.4 0.4 0.2]\n  ranger ( sensor ( range [0 8] fov 180 samples 181 ) sensor ( pose [0 0 0 90] range [0 5] ) ) )\n"),
        );
        s.step();
        let r = s.world.names["r.ranger:0"];
        let laser = &s.readings[r].sensor(0);
        // Straight ahead: the wall face at x = 4.9, from x = 1.
        assert!(
            (laser.ranges[90] - 3.9).abs() < 0.03,
            "{}",
            laser.ranges[90]
        );
        assert_eq!(laser.intensities[90], 1.0);
        // 45° left: 3.9 / cos 45° ≈ 5.515 (the wall reaches y = ±5).
        assert!(
            (laser.ranges[135] - 3.9 * 2f64.sqrt()).abs() < 0.05,
            "{}",
            laser.ranges[135]
        );
        // Straight left: nothing within 8 m.
        assert_eq!(laser.ranges[180], 8.0);
        assert_eq!(laser.intensities[180], 0.0);
        // The second sensor looks left: max range 5.
        assert_eq!(s.readings[r].sensor(1).ranges[0], 5.0);
    }

    /// The steps' poses and heights (from the models' frames) are the
    /// world's own, through a tree three deep, stacked and not, after the
    /// simulation interface lifts a model.
    #[test]
    fn frames_place_models_as_the_world_does() {
        let mut s = sim(
            "frames",
            &format!(
                "{ROOM}position ( name \"a\" pose [1 2 0.1 30] size [0.4 0.4 0.2]\n\
                   model ( name \"deck\" pose [0.1 0 0.05 45] size [0.2 0.2 0.1]\n\
                     model ( name \"cup\" pose [0 0.05 0 -20] size [0.05 0.05 0.05] ) )\n\
                   model ( name \"loose\" pose [-0.1 0 0 0] size [0.1 0.1 0.1] stack_children 0\n\
                     model ( name \"flag\" pose [0 0 0.2 0] size [0.01 0.01 0.3] ) ) )\n"
            ),
        );
        let cup = s.world.names["a.deck.cup"];
        s.set_z(cup, 0.02);
        s.step();
        for m in 0..s.world.models.len() {
            let ((p, z), (q, w)) = (s.global_z(m), s.world.global(&s.poses, m));
            assert_eq!(
                (p.x, p.y, p.yaw, z),
                (q.x, q.y, q.yaw, w),
                "{}",
                s.world.models[m].name
            );
        }
        let flag = s.world.names["a.loose.flag"];
        // `loose` stands on `a` (0.1 + 0.2); `flag` 0.2 over its base, not on top.
        assert!(
            (s.global_z(flag).1 - 0.5).abs() < 1e-12,
            "stacked on `loose`"
        );
        assert!((s.global_z(cup).1 - (0.1 + 0.2 + 0.05 + 0.1 + 0.02)).abs() < 1e-12);
    }

    /// A ranger's rays leave from its `origin` on its parent, turned by it:
    /// a robot facing +y with a ranger whose origin is half a metre ahead
    /// and turned back by 90° looks along +x from (0, 0.5), onto a post.
    #[test]
    fn a_rangers_rays_leave_from_its_turned_origin() {
        let mut s = sim(
            "origin",
            &format!(
                "{ROOM}position ( name \"a\" pose [0 0 0 90] size [0.4 0.4 0.2]\n\
                   ranger ( origin [0.5 0 0 -90] sensor ( range [0 8] ) ) )\n\
                 model ( name \"post\" pose [1 0.5 0 0] size [0.2 0.2 1] )\n"
            ),
        );
        s.step();
        let r = s.world.names["a.ranger:0"];
        let got = s.readings[r].sensor(0).ranges[0];
        assert!((got - 0.9).abs() < 0.03, "read {got}, not the post's 0.9");
    }

    /// Stage is 2.5D: a ray at a sensor's height passes over what is
    /// lower and under what is higher; a fiducial finder sees only what its
    /// ray at its own height meets first.
    #[test]
    fn sensors_see_only_what_spans_their_height() {
        let mut s = sim(
            "heights",
            &format!(
                "{ROOM}position ( name \"a\" pose [0 0 0 0] size [0.4 0.4 0.2]\n\
                   ranger ( sensor ( range [0 8] ) )\n\
                   fiducial ( range_max 8 ) )\n\
                 model ( name \"low\" pose [1 0 0 0] size [0.2 0.2 0.1] fiducial_return 3 )\n\
                 model ( name \"shelf\" pose [2 0 0.5 0] size [0.2 0.2 0.3] fiducial_return 4 )\n\
                 model ( name \"tall\" pose [3 0 0 0] size [0.2 0.2 1] fiducial_return 5 )\n"
            ),
        );
        s.step();
        let r = s.world.names["a.ranger:0"];
        // The ray leaves at 0.2 m + half the sensor's height: over `low`,
        // under `shelf` (0.5 to 0.8 m), onto `tall`'s face at 2.9 m.
        assert!(
            (s.readings[r].sensor(0).ranges[0] - 2.9).abs() < 0.03,
            "{}",
            s.readings[r].sensor(0).ranges[0]
        );
        let f = s.world.names["a.fiducial:0"];
        let ids: Vec<i32> = s.fiducials(f).fiducials.iter().map(|i| i.id).collect();
        assert_eq!(ids, [5], "only the model at the finder's height");
        // Lifted to the finder's height, `low` hides `tall` behind it.
        let low = s.world.names["low"];
        s.set_z(low, 0.15);
        s.set_pose(low, Pose::new(1.0, 0.0, 0.0));
        let ids: Vec<i32> = s.fiducials(f).fiducials.iter().map(|i| i.id).collect();
        assert_eq!(ids, [3]);
    }

    #[test]
    fn robots_see_each_other_but_not_themselves() {
        let mut s = sim(
            "robots",
            // a's ranger sits on top of it (0.2 m up): b is taller.
            "position ( name \"a\" pose [0 0 0 0] size [0.4 0.4 0.2] ranger ( sensor ( range [0 8] ) ) )\n\
             position ( name \"b\" pose [2 0 0 0] size [0.4 0.4 0.5] )\n",
        );
        s.step();
        let r = s.world.names["a.ranger:0"];
        // Moving bodies are met exactly, not at a grid cell's edge.
        assert!(
            (s.readings[r].sensor(0).ranges[0] - 1.8).abs() < 1e-9,
            "{}",
            s.readings[r].sensor(0).ranges[0]
        );
        // Move b away through the simulation interface: a sees nothing.
        let b = s.world.names["b"];
        s.set_pose(b, Pose::new(2.0, 3.0, 0.0));
        s.step();
        assert_eq!(s.readings[r].sensor(0).ranges[0], 8.0);
    }

    #[test]
    fn blobs_come_right_to_left_with_their_colours() {
        let s = sim(
            "blobs",
            "position ( name \"r\" size [0.4 0.4 0.2] blobfinder ( colors_count 2 colors [\"red\" \"green\"] image [80 60] range 8 fov 60 ) )\n\
             model ( name \"a\" pose [3 1 0 0] size [0.3 0.3 0.5] color \"red\" )\n\
             model ( name \"b\" pose [3 -1 0 0] size [0.3 0.3 0.5] color \"green\" )\n\
             model ( name \"c\" pose [3 0 0 0] size [0.3 0.3 0.5] color \"blue\" )\n",
        );
        let bf = s.world.names["r.blobfinder:0"];
        let d = s.blobs(bf);
        assert_eq!((d.width, d.height), (80, 60));
        let colors: Vec<u32> = d.blobs.iter().map(|b| b.color).collect();
        // Left of the image is the robot's left (+y); Stage's scan starts
        // at the right: green first, blue untracked.
        assert_eq!(colors, vec![0x00FF00, 0xFF0000]);
        assert!(d.blobs[1].right < d.blobs[0].left);
        assert!((d.blobs[0].range - 2.99).abs() < 0.2, "{:?}", d.blobs[0]);
        // Nothing in view: Player's plugin reports an empty image.
        let r = s.world.names["r"];
        let mut s = s;
        s.set_pose(r, Pose::new(0.0, 0.0, std::f64::consts::PI));
        assert_eq!(s.blobs(bf), troupe_msgs::blobfinder::Data::default());
    }

    #[test]
    fn fiducials_in_range_and_sight_are_reported() {
        let s = sim(
            "fiducials",
            "position ( name \"r\" size [0.4 0.4 0.2] fiducial ( range_max 8 range_max_id 3 fov 180 ) )\n\
             model ( name \"near\" pose [2 0 0 0] size [0.2 0.2 0.5] fiducial_return 7 )\n\
             model ( name \"far\" pose [0 4 0 0] size [0.2 0.2 0.5] fiducial_return 9 )\n\
             model ( name \"behind\" pose [-2 0 0 0] size [0.2 0.2 0.5] fiducial_return 5 )\n\
             model ( name \"hidden\" pose [5 0 0 0] size [0.2 0.2 0.5] fiducial_return 3 )\n",
        );
        let f = s.fiducials(s.world.names["r.fiducial:0"]);
        let mut ids: Vec<i32> = f.fiducials.iter().map(|i| i.id).collect();
        ids.sort();
        // near: identified; far: seen but beyond range_max_id; behind: outside the fov; hidden: behind near.
        assert_eq!(ids, vec![-1, 7]);
        let near = f.fiducials.iter().find(|i| i.id == 7).unwrap();
        assert!((near.pose.x - 2.0).abs() < 1e-9 && near.pose.y.abs() < 1e-9);
    }

    #[test]
    fn a_gripper_picks_up_carries_and_drops_a_box() {
        // The gripper hangs in front of r, 0.05 m up (its base is 0.2 m
        // tall): the box between its paddles spans that height.
        let mut s = sim(
            "gripper",
            "position ( name \"r\" size [0.4 0.4 0.2] acceleration_bounds [-9 9 -9 9 -9 9 -900 900] gripper ( pose [0.3 0 -0.15 0] size [0.2 0.3 0.1] ) )\n\
             model ( name \"box\" pose [0.38 0 0 0] size [0.1 0.1 0.1] gripper_return 1 obstacle_return 1 )\n",
        );
        let g = s.world.names["r.gripper:0"];
        let bx = s.world.names["box"];
        let st = |s: &Sim| s.grippers[g].clone().unwrap();
        s.step();
        assert_eq!(st(&s).beams, 0x08, "the box breaks the outer beam");
        assert_eq!(st(&s).paddles, Paddles::Open);
        // The paddles move a twentieth a step, until they touch the box
        // (0.1 m wide, between paddles 0.24 m apart) and close on it.
        s.grip(g, true);
        let mut moving = 0;
        while st(&s).paddles != Paddles::Closed {
            s.step();
            moving += 1;
            assert!(moving < 30, "{:?}", st(&s));
        }
        assert_eq!(moving, 13, "12 steps closing, the 13th stops on the box");
        assert!((st(&s).position - 0.6).abs() < 1e-9, "{:?}", st(&s));
        assert_eq!(st(&s).held.map(|h| h.0), Some(bx));
        // Held, the box is part of r: r's rays pass it, as its own body.
        let r = s.world.names["r"];
        assert!(!s.ranger_sees(r, 0.05)(id(bx)), "held: r's own");
        assert_ne!(
            st(&s).beams & 0x04,
            0,
            "held at the centre, across the inner beam"
        );
        assert!((s.global(bx).x - 0.3).abs() < 1e-9, "taken to the centre");
        s.bases[0].cmd = Some(Command::Vel(Pose::new(0.5, 0.0, 0.0)));
        for _ in 0..10 {
            s.step();
        }
        assert!(!s.bases[0].stall, "a held box is part of the robot");
        let p = s.global(bx);
        assert!((p.x - 0.8).abs() < 0.02, "carried 0.5 m: {p:?}");
        // Opening lets go at once (the paddles leave the box).
        s.grip(g, false);
        s.bases[0].cmd = Some(Command::Vel(Pose::new(-0.5, 0.0, 0.0)));
        s.step();
        assert_eq!((st(&s).paddles, st(&s).held), (Paddles::Opening, None));
        assert!(s.ranger_sees(r, 0.05)(id(bx)), "dropped: seen again");
        for _ in 0..13 {
            s.step();
        }
        assert!((s.global(bx).x - 0.8).abs() < 0.06, "dropped where it was");
        assert_eq!(
            st(&s).paddles,
            Paddles::Open,
            "open 1.4 s after the command"
        );
    }

    #[test]
    fn a_static_box_moved_leaves_no_cells_behind() {
        // Two boxes overlapping by 0.1 m; "a" moves away and back.
        let mut s = sim(
            "moved",
            "model ( name \"a\" pose [0 0 0 0] size [0.4 0.4 0.2] obstacle_return 1 )\n\
             model ( name \"b\" pose [0.3 0 0 0] size [0.4 0.4 0.2] obstacle_return 1 )\n",
        );
        let (a, b) = (s.world.names["a"], s.world.names["b"]);
        let at = |s: &Sim, x: f64| s.statics.at(x, 0.01);
        assert_eq!((at(&s, -0.1), at(&s, 0.4)), (id(a), id(b)));
        s.set_pose(a, Pose::new(2.0, 0.0, 0.0));
        assert_eq!((at(&s, -0.1), at(&s, 2.0)), (EMPTY, id(a)));
        // Where they overlapped, b's cells: a's were taken, b's stay.
        assert_eq!((at(&s, 0.15), at(&s, 0.4)), (id(b), id(b)));
        s.set_pose(a, Pose::new(-1.0, 0.0, 0.0));
        assert_eq!((at(&s, 2.0), at(&s, -1.0)), (EMPTY, id(a)));
    }

    #[test]
    fn snapshots_show_walls_robots_and_rays() {
        let mut s = sim("snap", &format!("{ROOM}position ( name \"r\" color \"red\" size [0.4 0.4 0.2] ranger ( sensor ( range [0 8] fov 90 samples 10 ) ) )\n"));
        s.step();
        let img = s.snapshot(200);
        assert!(img.width() <= 200 && img.height() <= 200 && img.width() > 100);
        let count = |c: [u8; 3]| img.pixels().filter(|p| p.0 == c).count();
        assert!(count([255, 0, 0]) > 0, "the red robot");
        assert!(count([170, 210, 255]) > 0, "its rays");
        assert!(count([255, 0, 0]) < count([255, 255, 255]));
    }

    #[test]
    fn goto_reaches_the_goal() {
        let mut s = sim("goto", "position ( name \"r\" size [0.4 0.4 0.2] )\n");
        s.bases[0].cmd = Some(Command::GoTo(Pose::new(1.0, 1.0, 0.0)));
        steps(&mut s, 200);
        let o = s.bases[0].odom;
        assert!(
            (o.x - 1.0).abs() < 0.06 && (o.y - 1.0).abs() < 0.06 && o.yaw.abs() < 0.05,
            "{o:?}"
        );
    }
}
/// Stage's own simple.world, from ../shared/compat.
#[cfg(test)]
mod compat {
    use super::*;

    #[test]
    fn ctrl_wander_roams_simple_world_without_leaving_the_cave() {
        let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../../shared/compat/stage/simple.world");
        if !p.exists() {
            eprintln!("skipping: ../shared/compat is absent");
            return;
        }
        let mut s = Sim::new(crate::world::load(&p).unwrap()).unwrap();
        assert!(
            s.bases
                .iter()
                .all(|b| matches!(b.ctrl, Some(Ctrl::Wander { .. }))),
            "both robots have ctrl \"wander\""
        );
        let start = s.global(s.bases[0].model);
        let mut travelled = 0.0;
        let mut last = start;
        for _ in 0..3000 {
            s.step();
            let p = s.global(s.bases[0].model);
            travelled += (p.x - last.x).hypot(p.y - last.y);
            last = p;
            for b in &s.bases {
                let g = s.global(b.model);
                assert!(g.x.abs() < 8.0 && g.y.abs() < 8.0, "left the cave at {g:?}");
            }
        }
        assert!(travelled > 20.0, "wandered only {travelled} m in 300 s");
    }

    #[test]
    fn the_cave_map_agrees_with_the_simulated_cave() {
        let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../../shared/compat/stage/simple.world");
        if !p.exists() {
            eprintln!("skipping: ../shared/compat is absent");
            return;
        }
        let s = Sim::new(crate::world::load(&p).unwrap()).unwrap();
        let cave = s.world.names["cave"];
        let map = s.model_map(cave).unwrap();
        // 16 m at Stage's default map_resolution 0.1, corner at (-8, -8).
        assert_eq!((map.info.width, map.info.height), (160, 160));
        assert_eq!((map.info.origin.x, map.info.origin.y), (-8.0, -8.0));
        // Cell by cell against the 2 cm grid the robots move in: where that
        // grid holds the cave at a map cell's centre, the cell is occupied;
        // an occupied cell holds the cave somewhere (5 x 5 points a cell).
        let (mut missed, mut extra, mut occupied) = (0, 0, 0);
        for (k, &c) in map.cells.iter().enumerate() {
            let (x, y) = map.centre(k);
            let cave_at = |dx: f64, dy: f64| s.statics.at(x + dx, y + dy) == id(cave);
            missed += usize::from(cave_at(0.0, 0.0) && c != OCCUPIED);
            let near = (0..25).any(|q| {
                let (u, v) = (f64::from(q % 5) - 2.0, f64::from(q / 5) - 2.0);
                cave_at(u * 0.02, v * 0.02)
            });
            extra += usize::from(!near && c == OCCUPIED);
            occupied += usize::from(c == OCCUPIED);
        }
        let n = map.cells.len();
        assert_eq!((missed, extra), (0, 0), "cells the map gets wrong");
        assert!(occupied * 100 > n * 5, "{occupied} of {n} occupied");
        // `boundary 1` (map.inc): the outer ring is wall.
        assert!(map.cells[..160].iter().all(|&c| c == OCCUPIED));
        assert!(map.cells[n - 160..].iter().all(|&c| c == OCCUPIED));
    }

    /// The issue's case (32, items 4 and 6): r0's SICK sits on top of its
    /// Pioneer, so its rays pass over r1's body (0.22 m tall) and meet
    /// r1's SICK — four beams in Stage, with that model's default
    /// `ranger_return` 1 as their intensity; the cave's walls return 0.5.
    #[test]
    fn r0_s_laser_meets_r1_s_laser_above_its_body_as_in_stage() {
        let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../../shared/compat/stage/simple_noctrl.world");
        if !p.exists() {
            eprintln!("skipping: ../shared/compat is absent");
            return;
        }
        let s = Sim::new(crate::world::load(&p).unwrap()).unwrap();
        let r = &s.readings[s.world.names["r0.ranger:1"]].sensor(0);
        let on_r1: Vec<usize> = (0..r.ranges.len())
            .filter(|&k| r.intensities[k] == 1.0)
            .collect();
        assert_eq!(on_r1, [43, 44, 45, 46]);
        assert!(on_r1.iter().all(|&k| (r.ranges[k] - 2.93).abs() < 0.06));
        assert!(r
            .intensities
            .iter()
            .all(|&i| i == 1.0 || i == 0.5 || i == 0.0));
    }

    /// Issue 32, item 5: r0's first scan in simple_noctrl.world, as real
    /// Stage measured it (the laser:0 data of the c-pull-position-laser
    /// transcript), beam for beam. Stage's ranges come from its raster of
    /// the cave's outline and its staircase walk; with `stage_ranges` on,
    /// every beam that meets a wall or nothing reads the same to 1e-4 m.
    /// Against the exact walls (the default) they differ by centimetres.
    #[test]
    fn stage_ranges_match_real_stage_beam_for_beam() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/compat");
        let world = dir.join("stage/simple_noctrl.world");
        let transcript = dir.join("player-tcp/c-pull-position-laser/messages.jsonl");
        if !world.exists() || !transcript.exists() {
            eprintln!("skipping: ../shared/compat is absent");
            return;
        }
        // The first laser DATA message's ranges.
        let text = std::fs::read_to_string(&transcript).unwrap();
        let line = text
            .lines()
            .find(|l| {
                l.contains(r#""dir":"s2c""#)
                    && l.contains(r#""interf":6,"#)
                    && l.contains(r#""type":1,"#)
            })
            .unwrap();
        let list = line.split(r#""ranges":["#).nth(1).unwrap();
        let stage: Vec<f64> = list[..list.find(']').unwrap()]
            .split(',')
            .map(|v| v.trim().parse().unwrap())
            .collect();
        assert_eq!(stage.len(), 180);
        let mut sim = Sim::new(crate::world::load(&world).unwrap()).unwrap();
        let laser = sim.world.names["r0.ranger:1"];
        let exact = sim.readings[laser].clone();
        let exact = exact.sensor(0);
        sim.stage_ranges(true);
        let ours = &sim.readings[laser].sensor(0);
        // Beams on r1's laser (a moving body, measured exactly either way)
        // read intensity 1; the cave returns 0.5, nothing 0.
        let walls: Vec<usize> = (0..180).filter(|&k| ours.intensities[k] != 1.0).collect();
        assert_eq!(walls.len(), 176);
        let off = |r: &Reading| {
            walls
                .iter()
                .map(|&k| (r.ranges[k] - stage[k]).abs())
                .fold(0.0, f64::max)
        };
        assert!(off(ours) < 1e-4, "worst beam {} m off Stage's", off(ours));
        // The exact walls: up to a few cells (over the cosine) off.
        assert!(
            (0.02..0.2).contains(&off(&exact)),
            "exact walls {} m off",
            off(&exact)
        );
        // And back.
        sim.stage_ranges(false);
        assert_eq!(sim.readings[laser].sensor(0).ranges, exact.ranges);
    }

    #[test]
    fn robot1_of_everything_world_sees_what_player_saw() {
        let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../../shared/compat/stage/everything_nocamera.world");
        if !p.exists() {
            eprintln!("skipping: ../shared/compat is absent");
            return;
        }
        let s = Sim::new(crate::world::load(&p).unwrap()).unwrap();
        let bf = s.world.names["robot1.blobfinder:0"];
        let d = s.blobs(bf);
        // The Player transcript (cpp-blob-fiducial-gripper): an 80x60
        // image, five blobs right to left: colour, rows, columns, range.
        // Stage draws bodies into its grid, so an edge may cover one
        // column more there than the exact bodies here do.
        assert_eq!((d.width, d.height), (80, 60));
        let want = [
            (0x00ff00, 30, 26, 34, 60, 60, 3.5375),
            (0xff0000, 30, 26, 34, 36, 42, 4.2550),
            (0xff00ff, 30, 26, 34, 31, 34, 3.6563),
            (0xffff00, 30, 25, 35, 20, 29, 3.1833),
            (0x00ffff, 30, 23, 37, 5, 18, 2.3987),
        ];
        assert_eq!(d.blobs.len(), want.len(), "{:?}", d.blobs);
        for (b, (color, y, top, bottom, left, right, range)) in d.blobs.iter().zip(want) {
            assert_eq!(
                (b.color, b.y, b.top, b.bottom),
                (color, y, top, bottom),
                "{b:?}"
            );
            assert!(
                b.left.abs_diff(left) <= 1 && b.right.abs_diff(right) <= 1,
                "{b:?}"
            );
            assert_eq!(b.area, (b.right - b.left) * (bottom - top), "{b:?}");
            assert!((f64::from(b.range) - range).abs() < 0.03, "{b:?}");
        }
        let f = s.fiducials(s.world.names["robot1.fiducial:0"]);
        // Real Stage's five (the transcript): the robots at the finder's
        // height, not the pucks below it.
        let mut seen: Vec<(i32, i64, i64)> = f
            .fiducials
            .iter()
            .map(|i| {
                (
                    i.id,
                    (i.pose.x * 1e4).round() as i64,
                    (i.pose.y * 1e4).round() as i64,
                )
            })
            .collect();
        seen.sort_unstable();
        assert_eq!(
            seen,
            [
                (17, 23953, 9013),
                (17, 32910, 5825),
                (17, 38255, 4101),
                (17, 44285, 283),
                (18, 30882, -5798)
            ]
        );
    }
}
