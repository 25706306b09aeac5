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
//!
//! This module holds the world's state and the step that runs it; each
//! concern of the step lives in a module of its own, as an `impl Sim` with
//! what it keeps:
//! - [`motion`]: commands, bases, a step's moves (kinematics, odometry);
//! - [`bodies`]: bodies in the grid and among the movers, collisions;
//! - [`sensors`]: rangers' readings and the rays that make them;
//! - [`gripper`]: Stage's gripper, and what it carries;
//! - [`finders`]: blobfinders and fiducial finders;
//! - [`energy`]: power packs and chargers;
//! - [`camera`]: Stage's camera, drawn by rays;
//! - [`ctrl`] and [`fasr2`]: Stage's built-in controllers;
//! - [`snapshot`]: the world as a picture, a model as a map.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Mutex, PoisonError, RwLock};

use troupe_geom::occmap::{FREE, OCCUPIED};
use troupe_geom::raster::{self, Raster};
use troupe_geom::{bounds, normalize, Grid, Hit, InTile, Lattice, OccMap, Pose, Transform, EMPTY};
use troupe_msgs::{map, Color};

use crate::crew::{wait_for, Crew, Job};
use crate::movers::{Body, Fan, Movers, Outline, Sweep};
use crate::world::{Drive, Kind, Localization, Sensor, World};

mod bodies;
mod camera;
mod ctrl;
mod energy;
mod fasr2;
mod finders;
mod gripper;
mod motion;
mod sensors;
mod snapshot;
pub use camera::Image;
pub use ctrl::{Charger, Ctrl, Mind, Mode};
pub use energy::Pack;
pub use gripper::{GripperState, Paddles};
pub use motion::{Base, Command};
pub use sensors::{Reading, Readings};

use bodies::Placed;
use motion::{Motion, Plan};
use sensors::{fan, first_where, nearest, Fans, Look, Rays, Seen, FAN};

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
    /// Each model's circles in its own frame (see [`Outline`]).
    outlines: Vec<Outline>,
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
    /// The floor: the box around every body at start (Stage draws its
    /// floor under the world's extent).
    extent: [f64; 4],
    /// The bodies as Stage draws them for its rays (the static ones by
    /// id, the moving ones counted in the regions they touch), when rays
    /// read as Stage's rather than against the exact bodies
    /// ([`Sim::stage_ranges`]).
    raster: Option<Raster>,
    /// The raster cells each model is drawn in now (a static one in the
    /// cells, a moving one in the moving layer).
    drawn: Vec<Vec<(i32, i32)>>,
    /// Moving bodies, for sensors and collisions.
    movers: Movers,
    /// Each model's sensors' rays.
    fans: Vec<Fans>,
    /// Each base's plan for the step, kept for its buffers.
    plans: Vec<Plan>,
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
    /// Whether obstacles or rangers meet its body (see [`Sim::in_grid`]).
    met: bool,
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
        let body = !d.blocks.is_empty();
        Frame {
            parent: d
                .parent
                .and_then(|p| u32::try_from(p).ok())
                .unwrap_or(Frame::ROOT),
            body,
            obstacle: d.obstacle_return,
            met: body && (d.obstacle_return || d.ranger_return >= 0.0),
            z: d.z,
            stack: if d.stack_children { d.size[2] } else { 0.0 },
            every: d.update_interval,
        }
    }
}

/// Model `m`'s body from its lowest block's base to its highest block's
/// top, above the floor (where its parents' poses and stacking put it).
fn height(world: &World, poses: &[Pose], m: usize) -> (f64, f64) {
    let (_, z) = world.global(poses, m);
    let (lo, hi) = world.models[m].body_span();
    (z + lo, z + hi)
}

/// `items` cut at `cuts` (where each run starts, then the end), each run
/// behind a lock of its own.
fn cut<'a, T>(mut items: &'a mut [T], cuts: &[usize]) -> Vec<Mutex<&'a mut [T]>> {
    cuts.windows(2)
        .map(|w| {
            let (run, rest) = std::mem::take(&mut items).split_at_mut(w[1] - w[0]);
            items = rest;
            Mutex::new(run)
        })
        .collect()
}

/// Locks `m`, through a panic elsewhere.
fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
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

/// A world the simulation cannot take as it is.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimError {
    /// More models than a grid cell can name.
    #[error("the world has {0} models; at most 65534 are supported")]
    TooManyModels(usize),
    /// A model drawn as a map with no positive cell size.
    #[error("{pos}: model `{model}` has map_resolution {res}; a map needs a positive cell size")]
    MapResolution {
        /// Where the model is declared.
        pos: String,
        /// The model.
        model: String,
        /// Its `map_resolution`.
        res: f64,
    },
}

impl Sim {
    /// Builds the simulation of `world`.
    ///
    /// # Errors
    ///
    /// A world with more models than a grid cell can name.
    pub fn new(world: World) -> Result<Sim, SimError> {
        let n = world.models.len();
        if n >= usize::from(u16::MAX) {
            return Err(SimError::TooManyModels(n));
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
        let extent = bounds((0..n).flat_map(|m| {
            let apply = world.global(&poses, m).0.applier();
            world.models[m]
                .blocks
                .iter()
                .flatten()
                .map(move |&(x, y)| apply(x, y))
        }))
        .unwrap_or([-1.0, -1.0, 1.0, 1.0]);
        let [x0, y0, x1, y1] = extent;
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
            .map(|b| {
                let cfg = world.models[b.model].position.as_ref();
                cfg.map(|c| Motion::of(c, b.model))
            })
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
        let outlines = world
            .models
            .iter()
            .map(|m| Outline::of(&m.blocks))
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
            outlines,
            frames,
            movable,
            written_at: vec![None; n],
            raster: None,
            drawn: vec![Vec::new(); n],
            movers: Movers::new(n, statics.tiles_wide(), statics.tile_count()),
            statics,
            extent,
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
        let threads = sim.world.threads.clamp(1, cores);
        // A large map's clearance is drawn on the threads the world may use.
        sim.statics.refresh_clearance_on(threads);
        sim.set_threads(threads);
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
    /// are rangers sensed, and one when a step casts fewer than a thousand
    /// rays (threads pay off only then: Stage's benchmark/cave.world, 1,600
    /// sonar rays a step, ran 1.78x as fast on two threads as on one).
    fn set_threads(&mut self, threads: usize) {
        let jobs = self.jobs();
        let rays: usize = jobs.iter().map(|j| j.rays).sum();
        let threads = if rays < 1000 { 1 } else { threads };
        self.crew = Crew::new(threads.min(jobs.len()).max(1), self.bases.len(), &jobs);
    }

    /// Whether model `m` moves (a robot, or what it carries).
    pub fn moves(&self, m: usize) -> bool {
        self.movable[m]
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
        self.crosses(m, self.time, self.time + self.world.interval_sim)
    }

    /// Whether a multiple of model `m`'s `update_interval` lies in
    /// `(from, to]` (Stage updates a model at those multiples).
    fn crosses(&self, m: usize, from: f64, to: f64) -> bool {
        let every = self.frames[m].every;
        let k = |t: f64| (t / every + 1e-9).floor();
        k(to) > k(from)
    }

    /// Whether model `m` updated in the last step (or the world has not
    /// stepped yet): what Stage's models that update on their own clock
    /// (a camera draws every `update_interval`) publish after.
    pub fn updated(&self, m: usize) -> bool {
        self.steps == 0 || self.crosses(m, self.time - self.world.interval_sim, self.time)
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
        kept.resize_with(self.bases.len(), Plan::default);
        let moves = dt.is_some();
        let dt = dt.unwrap_or(0.0);
        // The plans and each ranger's readings (moved out of the simulator
        // while its rays are cast), in the crew's runs.
        let cuts = crew.base_cuts();
        let plans = cut(&mut kept, cuts);
        let work: Vec<Mutex<Vec<(usize, Readings)>>> = crew
            .ranger_runs()
            .map(|run| Mutex::new(run.iter().map(|&r| (r, Readings::default())).collect()))
            .collect();
        let (to_plan, to_sense) = (crew.bases_to_plan(), crew.rangers_to_sense());
        let sensing = AtomicBool::new(false);
        let over = AtomicBool::new(false);
        let plan = |me: &Sim| {
            while let Some(k) = to_plan.take().filter(|_| moves) {
                for (bi, plan) in (cuts[k]..).zip(lock(&plans[k]).iter_mut()) {
                    me.plan(bi, dt, plan);
                }
            }
        };
        let sense = |me: &Sim| {
            let mut sweep = Sweep::default();
            while let Some(k) = to_sense.take() {
                // The most rays first, as the runs are taken.
                for (r, out) in lock(&work[k]).iter_mut().rev() {
                    // As Stage, a ranger senses every `update_interval`
                    // (100 ms), however short the steps; in between it
                    // keeps its readings.
                    if moves && !me.due(*r) {
                        continue;
                    }
                    me.sense_one(*r, out, &mut sweep);
                    if me.noisy[*r] {
                        me.add_noise(*r, out.sensor_mut(0).0);
                    }
                }
            }
        };
        let sim = RwLock::new(&mut *self);
        let read = || sim.read().unwrap_or_else(PoisonError::into_inner);
        let helper = || {
            plan(&read());
            // Spinning while the moves are carried out: a sleeping thread
            // would wake after they end.
            wait_for(|| sensing.load(Ordering::Acquire) || over.load(Ordering::Acquire));
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
                    for (k, run) in plans.iter().enumerate() {
                        for (bi, plan) in (cuts[k]..).zip(lock(run).iter_mut()) {
                            me.apply(bi, dt, plan);
                        }
                    }
                    me.carry(dt);
                }
                me.statics.refresh_clearance();
                if let Some(r) = &mut me.raster {
                    r.refresh();
                }
                for run in &work {
                    for (r, out) in lock(run).iter_mut() {
                        *out = std::mem::take(&mut me.readings[*r]);
                    }
                }
            }
            sensing.store(true, Ordering::Release);
            sense(&read());
        };
        crew.run(helper, main);
        for run in work {
            for (r, out) in run.into_inner().unwrap_or_else(PoisonError::into_inner) {
                self.readings[r] = out;
            }
        }
        drop(plans);
        self.plans = kept;
        self.crew = crew;
    }

    /// The model at the root of model `m`'s tree (a held box's is its
    /// gripper's robot).
    fn root(&self, m: usize) -> usize {
        self.looks[m].root as usize
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
            // (A root needs no sine and cosine to be placed.)
            Frame::ROOT => (self.poses[m], f.z),
            _ => {
                let (g, z, _) = self.global_turned(m);
                (g, z)
            }
        }
    }

    /// [`Sim::global_z`] with the sine and cosine of the global yaw,
    /// worked out once down the tree: a model not turned on its parent (a
    /// ranger on its robot, most often) shares its parent's.
    pub(super) fn global_turned(&self, m: usize) -> (Pose, f64, (f64, f64)) {
        let f = &self.frames[m];
        match f.parent {
            Frame::ROOT => {
                let g = self.poses[m];
                (g, f.z, g.yaw.sin_cos())
            }
            p => {
                let p = p as usize;
                let (gp, gz, turn_p) = self.global_turned(p);
                let g = gp.compose_by(turn_p, &self.poses[m]);
                let turn = if g.yaw == gp.yaw {
                    turn_p
                } else {
                    g.yaw.sin_cos()
                };
                (g, gz + f.z + self.frames[p].stack, turn)
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
}

#[cfg(test)]
mod compat;
#[cfg(test)]
mod tests;
