//! Stage's stock controllers, built into the simulator: a model's `ctrl
//! "name args"` runs here, as Stage's plug-in of that name would run in
//! Stage (its examples/ctrl/ and worlds/benchmark/ sources are the
//! reference).
//!
//! A controller runs at every step, reading its robot's sensors as they
//! were at the step's start, and sets speeds that hold until it sets others
//! (Stage's `SetSpeed`: a controller that returns early leaves them as they
//! were). What a controller keeps from step to step is its [`Mind`]. Its
//! random draws are a fixed function of the model and the step, so a world
//! runs the same on every run and any number of threads.

use troupe_geom::{normalize, Pose};

use super::energy::Energy;
use super::{nearest, Sim};
use crate::colors::unit_draw;
use crate::world::{Kind, World};

/// How many of a ring's readings its controller looks at one by one.
const READ: usize = 16;

/// A controller and the sensors it reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ctrl {
    /// `wander`: ahead at 0.4 m/s; turns in place away from the nearer
    /// side while anything is within 0.6 m of its first fan of rays.
    Wander {
        /// The ranger it steers by: its robot's first with many samples,
        /// else its first (none: it goes straight ahead).
        ranger: Option<usize>,
    },
    /// `explore`: Troupe's own, not Stage's. Cruises at 0.45 m/s steering
    /// towards the more open side, turns away from what is ahead, backs
    /// out of a stall, and every 40 s takes a turn of its own, so it sees
    /// a building's rooms where `wander` wedges itself in a doorway.
    Explore {
        /// The ranger it steers by, chosen as `wander` chooses (none: it
        /// goes straight ahead).
        ranger: Option<usize>,
    },
    /// `expand_pioneer` (worlds/benchmark): steers along the sum of its
    /// first ranger's 16 sonar readings as vectors, ahead at 0.2 m/s when
    /// the front sonars are clear (0.75 m ahead, less to the sides).
    ExpandPioneer {
        /// The sonar ring.
        ranger: usize,
    },
    /// `expand_swarm` (worlds/benchmark): the same over a ring of 12
    /// single-ray sensors, ahead at 0.3 m/s when clear (0.5 m ahead).
    ExpandSwarm {
        /// The ring of sensors.
        ranger: usize,
    },
    /// `wander_accel`: its ranger `ranger:1`'s scan; ahead at 0.4 m/s,
    /// slowing to 0.05 m/s (0 closer than 0.3 m) and turning at 0.5 rad/s
    /// away from the nearer side for 10–19 steps when the middle third of
    /// the scan sees anything within 1 m.
    WanderAccel {
        /// The laser (`ranger:1`).
        laser: usize,
    },
    /// `pioneer_flocking`: expands over its first ranger's 8 front sonars
    /// and, when clear, turns toward the heading of the nearest robot its
    /// fiducial finder sees, ahead at 0.4 m/s.
    Flocking {
        /// The sonars.
        ranger: usize,
        /// The fiducial finder.
        fiducial: usize,
    },
    /// `fasr` (examples/ctrl/fasr.cc): carries flags from the zone named
    /// `source` (near (-7, -7)) to the one named `sink` (near (7, 7)),
    /// heading by fasr.world's cave-shaped lookup tables of 4 m cells,
    /// avoiding what its laser (`ranger:1`) sees, and when its power pack
    /// runs low (under a quarter) heads for the chargers, docks at one
    /// its fiducial finder sees (id 2) and charges until 95% full.
    Fasr {
        /// The laser (`ranger:1`).
        laser: usize,
        /// The fiducial finder that looks for chargers, if any.
        fiducial: Option<usize>,
        /// The zone it takes flags from…
        source: usize,
        /// …and the one it brings them to.
        sink: usize,
    },
    /// `fasr2` (examples/ctrl/fasr2.cc): tasks between named zones, A*
    /// over the `cave`, docking at chargers (see [`super::fasr2`]).
    Fasr2 {
        /// The laser (`ranger:1`).
        laser: usize,
        /// The sonars (`ranger:0`): it backs off a charger by them.
        sonar: usize,
        /// The fiducial finder that looks for chargers.
        fiducial: usize,
    },
}

impl Ctrl {
    /// The sensors it reads besides the ranger it decides by
    /// ([`Sim::ctrl_ranger`]): they run too, as Stage's subscribed models.
    pub fn also_reads(self) -> impl Iterator<Item = usize> {
        let (a, b) = match self {
            Ctrl::Flocking { fiducial, .. } => (Some(fiducial), None),
            Ctrl::Fasr { fiducial, .. } => (fiducial, None),
            Ctrl::Fasr2 {
                sonar, fiducial, ..
            } => (Some(sonar), Some(fiducial)),
            _ => (None, None),
        };
        a.into_iter().chain(b)
    }
}

/// What `fasr` is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Mode {
    /// Carrying flags (or heading for the chargers when hungry).
    #[default]
    Work,
    /// Driving into a charger it sees.
    Dock,
    /// Backing off a charger, charged.
    Undock,
}

/// A charger as `fasr` and `fasr2` see it (a fiducial of id 2).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Charger {
    /// Seen at the last look (else what follows is from an earlier one).
    pub seen: bool,
    /// Metres from the finder…
    pub range: f64,
    /// …in this direction, radians.
    pub bearing: f64,
    /// Its heading relative to the finder's.
    pub heading: f64,
}

/// What a controller keeps from step to step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mind {
    /// The speeds it last set: they hold until it sets others.
    pub want: Pose,
    /// `wander`'s way of turning from obstacles (+1 left, -1 right).
    pub turn: f64,
    /// `wander_accel`'s and `fasr`'s updates left avoiding; `explore`'s
    /// left turning.
    pub avoid: u32,
    /// `explore`'s updates left backing out of a stall…
    pub backing: u32,
    /// …and its updates so far.
    pub updates: u64,
    /// `fasr`'s mode.
    pub mode: Mode,
    /// The charger `fasr` sees now, or the last it saw.
    pub charger: Charger,
    /// `fasr`'s updates spent loading at the source…
    pub work_get: u32,
    /// …and unloading at the sink.
    pub work_put: u32,
}

impl Default for Mind {
    fn default() -> Self {
        Mind {
            want: Pose::default(),
            turn: 1.0,
            avoid: 0,
            backing: 0,
            updates: 0,
            mode: Mode::Work,
            charger: Charger::default(),
            work_get: 0,
            work_put: 0,
        }
    }
}

/// A controller a world names and Troupe builds in, or why it cannot run.
pub enum Found {
    /// Runs on a position model.
    Base(Ctrl),
    /// `lasernoise`: on a ranger, noise on its first sensor's ranges.
    Noise,
    /// `source N`: a zone that gains a flag each update while it holds
    /// fewer than N.
    Source(u32),
    /// `sink`: a zone that takes the flags robots bring.
    Sink,
    /// `dynamic`: done as the world loaded (its 100 boxes were made with
    /// it).
    Loaded,
    /// `rasterize`: says the model's raster once, as it starts.
    Rasterize,
    /// Not built in (a user's own plug-in).
    Unknown,
    /// Built in, but the model lacks what it reads.
    Lacks(String),
}

/// The controller `line` (a `ctrl` string, `"name args…"`) names on model
/// `m`, whose subtree (itself first, depth first) is `tree`.
pub fn find(world: &World, tree: &[usize], m: usize, line: &str) -> Found {
    let name = line.split_whitespace().next().unwrap_or("");
    let model = &world.models[m];
    // Stage's GetUnusedModelOfType: the subtree's first model of a kind,
    // depth first (no controller takes two of one kind).
    let take = |kind: Kind| {
        tree.iter()
            .copied()
            .find(|&k| k != m && world.models[k].kind == kind)
    };
    let position = model.kind == Kind::Position;
    let sonars = |k: usize, n: usize, name: &str| {
        let have = world.models[k].sensors.len();
        if have >= n {
            Ok(k)
        } else {
            Err(Found::Lacks(format!(
                "\"{name}\" reads {n} sensors of `{}`, which has {have}",
                world.models[k].name
            )))
        }
    };
    let on_base =
        |what: &str| Found::Lacks(format!("\"{name}\" runs on a position model, not {what}"));
    let no = |what: &str| Found::Lacks(format!("\"{name}\" needs {what}"));
    match name {
        "wander" | "explore" if position => {
            let mut rangers = tree
                .iter()
                .copied()
                .filter(|&k| !world.models[k].sensors.is_empty());
            let first = rangers.clone().next();
            let ranger = rangers
                .find(|&k| world.models[k].sensors[0].samples > 1)
                .or(first);
            Found::Base(if name == "wander" {
                Ctrl::Wander { ranger }
            } else {
                Ctrl::Explore { ranger }
            })
        }
        "expand_pioneer" | "expand_swarm" | "pioneer_flocking" if !position => {
            on_base(&format!("a {:?}", model.kind).to_lowercase())
        }
        "expand_pioneer" => match take(Kind::Ranger).map(|r| sonars(r, 7, name)) {
            Some(Ok(ranger)) => Found::Base(Ctrl::ExpandPioneer { ranger }),
            Some(Err(e)) => e,
            None => no("a ranger (a Pioneer's sonar ring)"),
        },
        "expand_swarm" => match take(Kind::Ranger).map(|r| sonars(r, 12, name)) {
            Some(Ok(ranger)) => Found::Base(Ctrl::ExpandSwarm { ranger }),
            Some(Err(e)) => e,
            None => no("a ranger (a ring of 12 sensors)"),
        },
        "pioneer_flocking" => {
            let ranger = match take(Kind::Ranger).map(|r| sonars(r, 7, name)) {
                Some(Ok(r)) => r,
                Some(Err(e)) => return e,
                None => return no("a ranger (a Pioneer's front sonars)"),
            };
            match take(Kind::Fiducial) {
                Some(fiducial) => Found::Base(Ctrl::Flocking { ranger, fiducial }),
                None => no("a fiducial finder"),
            }
        }
        "wander_accel" if position => {
            // Stage's GetChild("ranger:1"): the model's second ranger.
            let laser = world
                .names
                .get(&format!("{}.ranger:1", model.name))
                .copied();
            match laser {
                Some(laser) => Found::Base(Ctrl::WanderAccel { laser }),
                None => no("a second ranger (`ranger:1`, Stage's laser on a Pioneer)"),
            }
        }
        "lasernoise" if model.kind == Kind::Ranger => Found::Noise,
        "lasernoise" => Found::Lacks("\"lasernoise\" runs on a ranger".into()),
        "fasr" if !position => on_base(&format!("a {:?}", model.kind).to_lowercase()),
        "fasr" => {
            // fasr.cc: GetChild("ranger:1"), and the world's models named
            // "source" and "sink".
            let laser = world
                .names
                .get(&format!("{}.ranger:1", model.name))
                .copied();
            let zone = |z: &str| {
                world
                    .names
                    .get(z)
                    .copied()
                    .filter(|&k| world.models[k].parent.is_none())
            };
            match (laser, zone("source"), zone("sink")) {
                (None, ..) => no("a second ranger (`ranger:1`, Stage's laser on a Pioneer)"),
                (_, None, _) | (_, _, None) => no("models named \"source\" and \"sink\""),
                (Some(laser), Some(source), Some(sink)) => Found::Base(Ctrl::Fasr {
                    laser,
                    fiducial: take(Kind::Fiducial),
                    source,
                    sink,
                }),
            }
        }
        "fasr2" if !position => on_base(&format!("a {:?}", model.kind).to_lowercase()),
        "fasr2" => {
            let child = |name: &str| world.names.get(&format!("{}.{name}", model.name)).copied();
            match (child("ranger:1"), child("ranger:0"), take(Kind::Fiducial)) {
                (Some(laser), Some(sonar), Some(fiducial)) => Found::Base(Ctrl::Fasr2 {
                    laser,
                    sonar,
                    fiducial,
                }),
                _ => no("sonars (`ranger:0`), a laser (`ranger:1`) and a fiducial finder"),
            }
        }
        // source.cc: its first argument, read as atoi reads it (fasr2.world
        // gives two; Stage's release build reads the first).
        "source" => match line.split_whitespace().nth(1) {
            Some(capacity) => Found::Source(atoi(capacity)),
            None => Found::Lacks(
                "\"source\" takes an argument, its capacity (Stage's source.cc asserts it)".into(),
            ),
        },
        "sink" => Found::Sink,
        "dynamic" => Found::Loaded,
        "rasterize" => Found::Rasterize,
        _ => Found::Unknown,
    }
}

impl Sim {
    /// The speeds base `bi`'s controller sets this step, from what its
    /// sensors read; `mind` is what it keeps.
    pub(super) fn control(&self, bi: usize, ctrl: Ctrl, mind: &mut Mind) -> Pose {
        // Stage runs a controller as the ranger it reads updates (every
        // 100 ms, however short the steps); the speeds it set hold between.
        if self.ctrl_ranger(bi).is_some_and(|r| !self.due(r)) {
            return mind.want;
        }
        match ctrl {
            Ctrl::Wander { ranger } => mind.want = self.wander(ranger, mind),
            Ctrl::Explore { ranger } => mind.want = self.explore(bi, ranger, mind),
            Ctrl::ExpandPioneer { ranger } => {
                // Stage's SAFE_DIST 0.75, SAFE_ANGLE 0.5, VSPEED 0.2, WGAIN 1.
                let s = 0.75;
                self.expand(ranger, mind, |r| {
                    let ahead = r[3] > s && r[4] > s;
                    let sides =
                        r[5] > s / 2.0 && r[6] > s / 4.0 && r[2] > s / 2.0 && r[1] > s / 4.0;
                    (ahead && sides).then_some(0.2)
                });
            }
            Ctrl::ExpandSwarm { ranger } => {
                // SAFE_DIST 0.5, VSPEED 0.3.
                let s = 0.5;
                self.expand(ranger, mind, |r| {
                    let left = r[1] > s / 1.5 && r[2] > s / 3.0 && r[3] > s / 5.0;
                    let right = r[9] > s / 5.0 && r[10] > s / 3.0 && r[11] > s / 1.5;
                    (r[0] > s && left && right).then_some(0.3)
                });
            }
            Ctrl::Flocking { ranger, fiducial } => {
                // EXPAND_WGAIN and FLOCK_WGAIN 0.3, SAFE_DIST 1, VSPEED 0.4.
                let clear = |r: &[f64]| {
                    r[3] > 1.0 && r[4] > 1.0 && r[5] > 1.0 && r[6] > 0.5 && r[2] > 1.0 && r[1] > 0.5
                };
                // (Over the first eight sonars: a Pioneer's front ring.)
                let Some((ang, r)) = self.resultant(ranger, 8) else {
                    return mind.want;
                };
                let mut turn = 0.3 * ang;
                let mut fwd = 0.0;
                if clear(&r) && ang.abs() < 0.5 {
                    fwd = 0.4;
                    // The nearest robot seen: its heading, relative to ours.
                    let seen = self.fiducials(fiducial);
                    let closest = seen
                        .fiducials
                        .iter()
                        .map(|f| (f.pose.x.hypot(f.pose.y), f.pose.yaw))
                        .min_by(|a, b| a.0.total_cmp(&b.0));
                    if let Some((_, heading)) = closest {
                        turn += 0.3 * heading;
                    }
                } else if turn.abs() < 0.1 {
                    // Stage: drand48(), a left turn of up to 1 rad/s.
                    turn = self.chance(self.bases[bi].model, 0);
                }
                mind.want = Pose::new(fwd, 0.0, turn);
            }
            Ctrl::WanderAccel { laser } => {
                let Some(scan) = self.scan(laser) else {
                    return mind.want;
                };
                // Stage's wander_accel: the middle third within 1 m.
                if !self.avoid(bi, scan, 3, 1.0, 0.3, mind) {
                    mind.avoid = 0;
                    mind.want = Pose::new(0.4, 0.0, 0.0);
                }
            }
            // Its update runs in series, after the moves (Sim::chores).
            Ctrl::Fasr2 { .. } => {}
            Ctrl::Fasr {
                laser, fiducial, ..
            } => {
                // Its callbacks run as its sensors update (100 ms apart
                // unless their `update_interval` says otherwise).
                // (fasr.cc takes the first charger its finder reports.)
                if let Some(f) = fiducial.filter(|&f| self.due(f)) {
                    self.look_for_charger(f, &mut mind.charger, |c| c.first().copied());
                }
                if let Some(scan) = self.scan(laser) {
                    self.fasr(bi, scan, mind);
                }
            }
        }
        mind.want
    }

    /// Updates `charger` from what fiducial finder `f` sees: the charger
    /// `pick` picks from those it reports (fiducial id 2), or none seen.
    pub(super) fn look_for_charger(
        &self,
        f: usize,
        charger: &mut Charger,
        pick: impl Fn(&[Charger]) -> Option<Charger>,
    ) {
        let seen: Vec<Charger> = self
            .fiducials(f)
            .fiducials
            .iter()
            .filter(|c| c.id == 2)
            .map(|c| Charger {
                seen: true,
                range: c.pose.x.hypot(c.pose.y),
                bearing: c.pose.y.atan2(c.pose.x),
                heading: c.pose.yaw,
            })
            .collect();
        match pick(&seen) {
            Some(c) => *charger = c,
            None => charger.seen = false,
        }
    }

    /// The first sensor's ranges of ranger `r`, when it has read any.
    pub(super) fn scan(&self, r: usize) -> Option<&[f64]> {
        self.readings[r]
            .first()
            .map(|r| r.ranges)
            .filter(|s| !s.is_empty())
    }

    /// Stage's ObstacleAvoid (wander_accel's and fasr's): when the middle
    /// of the `scan` (all but the `1/part` at each side) sees anything
    /// nearer than `near`, anything is nearer than `stop`, or it is still
    /// avoiding, it creeps (stops, for `stop`) and turns away from the
    /// nearer side at 0.5 rad/s for 10–19 updates, and says so.
    pub(super) fn avoid(
        &self,
        bi: usize,
        scan: &[f64],
        part: usize,
        near: f64,
        stop: f64,
        mind: &mut Mind,
    ) -> bool {
        let n = scan.len();
        let (mut obstruction, mut halt) = (false, false);
        let (mut left, mut right) = (1e6f64, 1e6f64);
        for (i, &r) in scan.iter().enumerate() {
            if i > n / part && i < n - n / part && r < near {
                obstruction = true;
            }
            if r < stop {
                halt = true;
            }
            if i > n / 2 {
                left = left.min(r);
            } else {
                right = right.min(r);
            }
        }
        if !(obstruction || halt || mind.avoid > 0) {
            return false;
        }
        mind.want.x = if halt { 0.0 } else { 0.05 };
        if mind.avoid < 1 {
            // Stage: random() % 10 + 10 updates.
            let draw = self.chance(self.bases[bi].model, 1);
            mind.avoid = 10 + (draw * 10.0) as u32;
            mind.want.yaw = if left < right { -0.5 } else { 0.5 };
        }
        mind.avoid -= 1;
        true
    }

    /// `fasr`'s laser callback: work, dock or undock (fasr.cc).
    fn fasr(&self, bi: usize, scan: &[f64], mind: &mut Mind) {
        let m = self.bases[bi].model;
        let fraction = self.energy.pack(m).map_or(1.0, |p| p.fraction());
        let Charger {
            seen,
            range,
            bearing,
            ..
        } = mind.charger;
        let avoid = |mind: &mut Mind| self.avoid(bi, scan, 4, 0.7, 0.5, mind);
        match mind.mode {
            Mode::Work => {
                if avoid(mind) {
                    return;
                }
                mind.want.x = 0.4;
                let pose = self.global(m);
                // fasr.world's cave in 4 m cells, clamped to it.
                let cell = |v: f64| (((v + 8.0) / 4.0) as i64).clamp(0, 3) as usize;
                let (x, y) = (cell(pose.x), cell(pose.y));
                let mut goal = if self.energy.flags[m] > 0 {
                    HAVE[y][x]
                } else {
                    NEED[y][x]
                };
                if fraction < 0.25 {
                    goal = REFUEL[y][x];
                    if seen {
                        mind.mode = Mode::Dock;
                    }
                }
                mind.want.yaw = normalize(goal.to_radians() - pose.yaw);
            }
            Mode::Dock => {
                if !seen {
                    mind.want = Pose::default();
                    mind.mode = Mode::Work;
                } else if range > 0.5 {
                    if !avoid(mind) {
                        mind.want.x = 0.4;
                        mind.want.yaw = normalize(bearing);
                    }
                } else {
                    // Creeps in; stops close enough; backs off a touch
                    // when it stalls against the charger.
                    mind.want = Pose::new(0.02, 0.0, normalize(bearing));
                    if range < 0.08 {
                        mind.want = Pose::default();
                    }
                    if self.bases[bi].stall {
                        mind.want.x = -0.01;
                    }
                }
                if fraction > 0.95 {
                    mind.mode = Mode::Undock;
                }
            }
            Mode::Undock => {
                // Backs off to 0.3 m from the charger it last saw.
                mind.want.x = if range < 0.3 { -0.05 } else { 0.0 };
                if range > 0.3 {
                    mind.mode = Mode::Work;
                }
            }
        }
    }

    /// The expand controllers: turn toward the resultant of the sensors'
    /// readings (as vectors along each sensor's heading) by its angle
    /// (Stage's WGAIN 1), and go ahead at the speed `clear` gives when the
    /// angle is under 0.5 rad. With no resultant (Stage's `dx == 0 || dy
    /// == 0`) the speeds hold.
    fn expand(&self, ranger: usize, mind: &mut Mind, clear: impl Fn(&[f64]) -> Option<f64>) {
        if let Some((ang, r)) = self.resultant(ranger, usize::MAX) {
            let fwd = clear(&r).filter(|_| ang.abs() < 0.5).unwrap_or(0.0);
            mind.want = Pose::new(fwd, 0.0, ang);
        }
    }

    /// The angle of the sum of the first readings of ranger `r`'s first
    /// `n` sensors as vectors along each sensor's heading, and the first
    /// [`READ`] of those readings; `None` before it has read or when either
    /// sum is exactly 0 (as Stage's controllers test it).
    fn resultant(&self, r: usize, n: usize) -> Option<(f64, [f64; READ])> {
        let readings = &self.readings[r];
        let n = n.min(readings.len());
        if n == 0 {
            return None;
        }
        let (mut dx, mut dy) = (0.0_f64, 0.0);
        let mut read = [0.0; READ];
        for (k, heading) in self.fans[r].headings.iter().take(n).enumerate() {
            let v = readings.first_range(k);
            if let Some(slot) = read.get_mut(k) {
                *slot = v;
            }
            dx += v * heading.0;
            dy += v * heading.1;
        }
        (dx != 0.0 && dy != 0.0).then(|| (dy.atan2(dx), read))
    }

    /// A uniform draw in [0, 1) for model `m` at this step (`salt` tells
    /// draws of one step apart): SplitMix64 of the three.
    pub(super) fn chance(&self, m: usize, salt: u64) -> f64 {
        unit_draw([m as u64, self.steps, salt])
    }

    /// The ranger base `bi`'s controller reads, if any.
    pub(super) fn ctrl_ranger(&self, bi: usize) -> Option<usize> {
        match self.bases[bi].ctrl? {
            Ctrl::Wander { ranger } | Ctrl::Explore { ranger } => ranger,
            Ctrl::ExpandPioneer { ranger }
            | Ctrl::ExpandSwarm { ranger }
            | Ctrl::Flocking { ranger, .. } => Some(ranger),
            Ctrl::WanderAccel { laser } | Ctrl::Fasr { laser, .. } | Ctrl::Fasr2 { laser, .. } => {
                Some(laser)
            }
        }
    }

    /// The built-in `wander` controller steering by `ranger`: the velocity
    /// it asks for; `mind.turn` is the way it turns from obstacles (+1
    /// left, -1 right), kept while both sides are about as near.
    fn wander(&self, ranger: Option<usize>, mind: &mut Mind) -> Pose {
        let Some(r) = ranger else {
            return Pose::new(0.4, 0.0, 0.0);
        };
        let sensors = &self.world.models[r].sensors;
        let (mut left, mut right) = (f64::INFINITY, f64::INFINITY);
        // (A hair over a right angle: the fan's last ray may land on it by
        // rounding.)
        let side = std::f64::consts::FRAC_PI_2 + 1e-9;
        for (s, rd) in sensors.iter().zip(self.readings[r].iter()) {
            // Bearings grow ray by ray: those from -side to 0 are on the
            // right, from 0 to side on the left.
            let (start, step) = super::fan(s);
            let n = rd.ranges.len();
            let at = |k: usize| start + step * k as f64;
            let r0 = super::first_where(n, |k| at(k) >= -side);
            let mid = super::first_where(n, |k| at(k) >= 0.0);
            let l1 = super::first_where(n, |k| at(k) > side);
            right = right.min(nearest(&rd.ranges[r0..mid.max(r0)]));
            left = left.min(nearest(&rd.ranges[mid..l1.max(mid)]));
        }
        if left.min(right) < 0.6 {
            if (left - right).abs() > 0.1 {
                mind.turn = if left < right { -1.0 } else { 1.0 };
            }
            Pose::new(0.0, 0.0, mind.turn)
        } else {
            Pose::new(0.4, 0.0, 0.0)
        }
    }

    /// The built-in `explore` controller of base `bi` steering by `ranger`'s
    /// first sensor: the velocity it asks for.
    fn explore(&self, bi: usize, ranger: Option<usize>, mind: &mut Mind) -> Pose {
        let reading = ranger.and_then(|r| {
            let s = self.world.models[r].sensors.first()?;
            Some((super::fan(s), self.readings[r].first()?.ranges))
        });
        let Some(((start, step), ranges)) = reading else {
            return Pose::new(0.45, 0.0, 0.0);
        };
        mind.updates += 1;
        let over = |lo: f64, hi: f64| {
            let at = |k: usize| start + step * k as f64;
            let n = ranges.len();
            let from = super::first_where(n, |k| at(k) >= lo);
            &ranges[from..super::first_where(n, |k| at(k) > hi).max(from)]
        };
        let front = nearest(over(-0.45, 0.45));
        let left: f64 = over(0.5, 1.6).iter().sum();
        let right: f64 = over(-1.6, -0.5).iter().sum();
        let side = |left_more_open: bool| if left_more_open { 1.0 } else { -1.0 };
        if self.bases[bi].stall && mind.backing == 0 {
            mind.backing = 15;
            mind.turn = side(left > right);
        }
        if mind.backing > 0 {
            mind.backing -= 1;
            return Pose::new(-0.15, 0.0, 0.8 * mind.turn);
        }
        // Every 40 s (400 updates of a 10 Hz ranger) a turn of its own.
        if mind.updates % 400 == 0 {
            mind.avoid = 20;
            mind.turn = side(left > right);
        }
        if front < 0.8 || mind.avoid > 0 {
            mind.avoid = mind.avoid.saturating_sub(1);
            if front < 0.8 && mind.avoid == 0 {
                mind.turn = side(left > right);
            }
            return Pose::new(0.05, 0.0, 0.9 * mind.turn);
        }
        let steer = (0.6 * (left - right) / (left + right).max(1e-6)).clamp(-0.4, 0.4);
        Pose::new(0.45, 0.0, steer)
    }

    /// `lasernoise` on ranger `r`'s readings: each range of its first
    /// sensor times a normal deviate of mean 1 and deviation 0.05, as
    /// Stage's plug-in draws it (the sum of 12 uniform draws, less 6).
    pub(super) fn add_noise(&self, r: usize, ranges: &mut [f64]) {
        const DEVIATION: f64 = 0.05;
        for (k, v) in ranges.iter_mut().enumerate() {
            let sum: f64 = (0..12)
                .map(|j| unit_draw([r as u64, self.steps, 16 + 12 * k as u64 + j]))
                .sum();
            *v *= 1.0 + DEVIATION * (sum - 6.0);
        }
    }
}

/// fasr.world's headings (degrees) by 4 m cell, `[y][x]` from (-8, -8):
/// to the sink with a flag, to the source without, to the chargers.
const HAVE: [[f64; 4]; 4] = [
    [90.0, 180.0, 180.0, 180.0],
    [90.0, -90.0, 180.0, 90.0],
    [90.0, 90.0, 180.0, 90.0],
    [0.0, 45.0, 0.0, 0.0],
];
const NEED: [[f64; 4]; 4] = [
    [-120.0, -180.0, 180.0, 180.0],
    [-90.0, -120.0, 180.0, 90.0],
    [-90.0, -90.0, 180.0, 180.0],
    [-90.0, -180.0, -90.0, -90.0],
];
const REFUEL: [[f64; 4]; 4] = [
    [0.0, 0.0, 45.0, 120.0],
    [0.0, -90.0, -60.0, -160.0],
    [-90.0, -90.0, 180.0, 180.0],
    [-90.0, -180.0, -90.0, -90.0],
];

/// `fasr`'s position callback on robot `m` at (x, y): a robot with no
/// flag within 2 m of the source's spot (-7, -7) takes one from it every
/// 21st update, and one within 1 m of the sink's (7, 7) gives it one
/// every 21st (fasr.cc's workduration).
pub(super) fn fasr_position(
    e: &mut Energy,
    mind: &mut Mind,
    m: usize,
    (x, y): (f64, f64),
    source: usize,
    sink: usize,
) {
    const PAYLOAD: u32 = 1;
    const WORK: u32 = 20;
    if e.flags[m] < PAYLOAD && (-7.0 - x).hypot(-7.0 - y) < 2.0 {
        mind.work_get += 1;
        if mind.work_get > WORK {
            e.pass_flag(source, m);
            mind.work_get = 0;
        }
    }
    if (7.0 - x).hypot(7.0 - y) < 1.0 {
        mind.work_put += 1;
        if mind.work_put > WORK {
            e.pass_flag(m, sink);
            mind.work_put = 0;
        }
    }
}

/// C's `atoi`: the leading digits (after a sign), 0 when there are none;
/// here a count, so a negative one is 0.
fn atoi(text: &str) -> u32 {
    let digits = text.strip_prefix('+').unwrap_or(text);
    let end = digits
        .find(|c: char| !c.is_ascii_digit())
        .unwrap_or(digits.len());
    digits[..end]
        .parse()
        .unwrap_or(if end > 0 { u32::MAX } else { 0 })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A simulator of `text` (a world file that may include the project's
    /// worlds/robots.inc, and gets a 12 m walled room around the origin).
    fn sim(name: &str, text: &str) -> Sim {
        let room = "resolution 0.02\ninterval_sim 100\n\
            model ( name \"n\" pose [0 6 0 0] size [12.2 0.2 0.5] )\n\
            model ( name \"s\" pose [0 -6 0 0] size [12.2 0.2 0.5] )\n\
            model ( name \"e\" pose [6 0 0 0] size [0.2 12.2 0.5] )\n\
            model ( name \"w\" pose [-6 0 0 0] size [0.2 12.2 0.5] )\n";
        sim_in(name, room, text)
    }

    /// A simulator of `room` and `text` (which may include the project's
    /// worlds/robots.inc).
    fn sim_in(name: &str, room: &str, text: &str) -> Sim {
        let dir = std::env::temp_dir().join(format!("troupe-ctrl-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let inc = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../worlds/robots.inc");
        let p = dir.join("t.world");
        std::fs::write(&p, format!("include \"{}\"\n{room}{text}", inc.display())).unwrap();
        let w = crate::world::load(&p).unwrap();
        let _ = std::fs::remove_dir_all(&dir);
        Sim::new(w).unwrap()
    }

    fn steps(s: &mut Sim, n: usize) {
        for _ in 0..n {
            s.step();
        }
    }

    /// Every base's true position.
    fn spots(s: &Sim) -> Vec<(f64, f64)> {
        s.bases
            .iter()
            .map(|b| {
                let g = s.global(b.model);
                (g.x, g.y)
            })
            .collect()
    }

    /// The mean distance from each robot to its nearest neighbour.
    fn spacing(p: &[(f64, f64)]) -> f64 {
        let near = |i: usize| {
            (0..p.len())
                .filter(|&j| j != i)
                .map(|j| (p[i].0 - p[j].0).hypot(p[i].1 - p[j].1))
                .fold(f64::INFINITY, f64::min)
        };
        (0..p.len()).map(near).sum::<f64>() / p.len() as f64
    }

    /// `n`×`n` robots of kind `def`, `gap` metres apart, around the origin,
    /// facing every way.
    fn cluster(def: &str, n: usize, gap: f64) -> String {
        let mut text = String::new();
        for k in 0..n * n {
            let (i, j) = ((k % n) as f64, (k / n) as f64);
            let half = (n as f64 - 1.0) / 2.0;
            text += &format!(
                "{def} ( name \"r{k}\" pose [{} {} 0 {}] )\n",
                (i - half) * gap,
                (j - half) * gap,
                k * 137 % 360
            );
        }
        text
    }

    /// Whether every robot runs a controller `is` accepts and, in 60 s,
    /// they more than double their spacing.
    fn spreads_out(mut s: Sim, is: impl Fn(Option<Ctrl>) -> bool) {
        assert!(s.bases.iter().all(|b| is(b.ctrl)));
        let before = spacing(&spots(&s));
        steps(&mut s, 600);
        let after = spacing(&spots(&s));
        assert!(
            after > 2.0 * before,
            "spacing {before:.2} m → {after:.2} m in 60 s"
        );
    }

    #[test]
    fn expand_pioneer_spreads_a_cluster_out() {
        let text = "define bot tr_robot ( tr_laser() ctrl \"expand_pioneer\" )\n".to_owned()
            + &cluster("bot", 3, 0.6);
        spreads_out(sim("expand_pioneer", &text), |c| {
            matches!(c, Some(Ctrl::ExpandPioneer { .. }))
        });
    }

    #[test]
    fn expand_swarm_spreads_a_swarm_out() {
        // As Stage's hospital.world builds its swarmbots: 10 cm, a ring of
        // 12 single-ray sensors 30° apart, 2 m, lowered into the body.
        let mut ring = String::new();
        for i in 0..12 {
            ring += &format!(
                "sensor ( pose [0 0 0 {}] range [0 2] fov 30 samples 1 ) ",
                i * 30
            );
        }
        let text = format!(
            "define swarmbot position ( size [0.1 0.1 0.1] drive \"diff\" \
             ranger ( pose [0 0 -0.05 0] {ring} ) ctrl \"expand_swarm\" )\n"
        ) + &cluster("swarmbot", 5, 0.25);
        spreads_out(sim("expand_swarm", &text), |c| {
            matches!(c, Some(Ctrl::ExpandSwarm { .. }))
        });
    }

    #[test]
    fn flockers_move_and_come_to_share_a_heading() {
        // Front sonars (ranger:0's first eight), a fiducial finder, seen
        // by each other's.
        let text = "define flocker tr_robot ( fiducial ( range_max 8 ) fiducial_return 1 \
                    ctrl \"pioneer_flocking\" )\n"
            .to_owned()
            + &cluster("flocker", 3, 1.5);
        let mut s = sim("flocking", &text);
        assert!(s
            .bases
            .iter()
            .all(|b| matches!(b.ctrl, Some(Ctrl::Flocking { .. }))));
        // How much the robots agree on a heading: the length of the mean
        // of their headings' unit vectors (1: all alike, ~0: all ways).
        let order = |s: &Sim| {
            let (mut c, mut si) = (0.0, 0.0);
            for b in &s.bases {
                let a = s.global(b.model).yaw;
                c += a.cos();
                si += a.sin();
            }
            c.hypot(si) / s.bases.len() as f64
        };
        let (mut last, aligned) = (spots(&s), order(&s));
        let mut path = 0.0;
        for _ in 0..600 {
            s.step();
            let now = spots(&s);
            path += now
                .iter()
                .zip(&last)
                .map(|(a, b)| (a.0 - b.0).hypot(a.1 - b.1))
                .sum::<f64>();
            last = now;
        }
        let moved = path / last.len() as f64;
        let now = order(&s);
        assert!(moved > 6.0, "moved {moved:.2} m on average in 60 s");
        assert!(
            now > aligned + 0.3,
            "heading agreement {aligned:.2} → {now:.2}"
        );
    }

    /// How r0 of worlds/wander.world (Troupe's office) gets on for 600
    /// simulated s driven by `ctrl`: the square metres it passed through,
    /// and the longest it stayed within a metre of one spot, in seconds.
    fn office_tour(ctrl: &str) -> (usize, f64) {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../worlds/wander.world");
        let mut w = crate::world::load(&path).unwrap();
        let r0 = w.names["r0"];
        w.models[r0].ctrl = vec![ctrl.into()];
        let mut s = Sim::new(w).unwrap();
        let mut cells = std::collections::HashSet::new();
        let (mut anchor, mut since, mut longest) = (spots(&s)[0], 0.0, 0.0_f64);
        for _ in 0..6000 {
            s.step();
            let p = spots(&s)[0];
            cells.insert((p.0.floor() as i64, p.1.floor() as i64));
            if (p.0 - anchor.0).hypot(p.1 - anchor.1) > 1.0 {
                (anchor, since) = (p, s.time);
            }
            longest = longest.max(s.time - since);
        }
        (cells.len(), longest)
    }

    #[test]
    fn explore_tours_the_office_where_wander_wedges_itself() {
        let (wander_cells, wander_still) = office_tour("wander");
        let (cells, still) = office_tour("explore");
        assert!(
            cells >= 100 && cells >= 3 * wander_cells && still < 30.0,
            "explore: {cells} m² passed, {still:.0} s at most in one spot; \
             wander: {wander_cells} m², {wander_still:.0} s"
        );
    }

    #[test]
    fn wander_accel_roams_and_keeps_off_the_walls() {
        let text = "tr_robot ( name \"r0\" pose [-3 -3 0 30] tr_laser() ctrl \"wander_accel\" )\n\
                    model ( name \"box\" pose [1 1 0 20] size [1 1 0.5] )\n";
        let mut s = sim("wander_accel", text);
        assert!(matches!(s.bases[0].ctrl, Some(Ctrl::WanderAccel { .. })));
        let mut last = spots(&s)[0];
        let (mut travelled, mut stalled) = (0.0, 0);
        for _ in 0..1200 {
            s.step();
            let p = spots(&s)[0];
            travelled += (p.0 - last.0).hypot(p.1 - last.1);
            last = p;
            stalled += usize::from(s.bases[0].stall);
        }
        assert!(travelled > 20.0, "wandered only {travelled:.1} m in 120 s");
        assert_eq!(stalled, 0, "stalled against something");
    }

    #[test]
    fn only_rangers_served_or_read_by_a_controller_are_sensed() {
        let text = "tr_robot ( name \"a\" pose [-2 0 0 0] tr_laser() ctrl \"wander_accel\" )\n\
                    tr_robot ( name \"b\" pose [0 -2 0 0] tr_laser() )\n\
                    tr_robot ( name \"c\" pose [0 2 0 180] tr_laser() )\n";
        let mut s = sim("sensed", text);
        let n = |x: &str| s.world.names[x];
        let (a, b, c) = (n("a.ranger:1"), n("b.ranger:1"), n("c.ranger:1"));
        let (b_sonar, c_sonar) = (n("b.ranger:0"), n("c.ranger:0"));
        // b's laser is served; a's laser is what its controller reads.
        s.sense_only([b]);
        let before = s.readings.clone();
        for bi in [1, 2] {
            s.bases[bi].cmd = Some(crate::sim::Command::Vel(Pose::new(0.3, 0.0, 0.5)));
        }
        steps(&mut s, 10);
        for (r, sensed) in [
            (a, true),
            (b, true),
            (c, false),
            (b_sonar, false),
            (c_sonar, false),
        ] {
            assert_eq!(
                s.readings[r] != before[r],
                sensed,
                "{}",
                s.world.models[r].name
            );
        }
    }

    /// fasr's world, as a test writes it: a 16 m room, a source zone
    /// making a flag a second in the south-west corner, a sink in the
    /// north-east, two chargers on the east wall (a block that gives 2 kW
    /// and shows fiducial id 2, on a base) and `n` Pioneer-sized carriers
    /// with `kjoules` each: a laser as `ranger:1`, and in front a bump that
    /// takes 2 kW and carries the fiducial finder.
    fn fasr_world(name: &str, n: usize, kjoules: f64) -> Sim {
        let room = "resolution 0.02\ninterval_sim 100\n\
            model ( name \"n\" pose [0 8 0 0] size [16.2 0.2 0.5] )\n\
            model ( name \"s\" pose [0 -8 0 0] size [16.2 0.2 0.5] )\n\
            model ( name \"e\" pose [8 0 0 0] size [0.2 16.2 0.5] )\n\
            model ( name \"w\" pose [-8 0 0 0] size [0.2 16.2 0.5] )\n";
        let mut text = "define zone model ( size [2 2 0.01] obstacle_return 0 ranger_return -1 )\n\
            zone ( name \"source\" pose [-7 -7 0 0] ctrl \"source 1\" update_interval 1000 )\n\
            zone ( name \"sink\" pose [7 7 0 0] ctrl \"sink\" )\n\
            define charger model ( size [0.1 0.3 0.1] \
              model ( pose [0.01 0 0 0] size [0.05 0.2 0.1] joules -1 give_watts 2000 \
                      fiducial_return 2 alwayson 1 ) )\n\
            charger ( pose [7.85 -2.5 0 0] )\n\
            charger ( pose [7.85 -3.8 0 0] )\n\
            define carrier tr_robot ( mass 23 ctrl \"fasr\" \
              ranger ( pose [0 0 -0.1 0] sensor ( range [0 3] fov 180 samples 32 ) size [0.15 0.15 0.1] ) \
              model ( pose [0.24 0 -0.1 0] size [0.12 0.05 0.1] take_watts 2000 \
                      obstacle_return 0 fiducial ( range_max 5 pose [0 0 -0.1 0] ) ) )\n"
            .to_owned();
        for k in 0..n {
            let (x, y) = (2.0 + 1.2 * (k % 3) as f64, 3.0 + 1.2 * (k / 3) as f64);
            text += &format!(
                "carrier ( name \"r{k}\" pose [{x} {y} 0 {}] kjoules {kjoules} )\n",
                k * 77 % 360
            );
        }
        sim_in(name, room, &text)
    }

    #[test]
    fn fasr_carries_flags_from_the_source_to_the_sink() {
        let mut s = fasr_world("fasr", 6, 1000.0);
        assert!(s.bases.iter().all(|b| matches!(
            b.ctrl,
            Some(Ctrl::Fasr {
                fiducial: Some(_),
                ..
            })
        )));
        let (source, sink) = (s.world.names["source"], s.world.names["sink"]);
        steps(&mut s, 3000);
        let delivered = s.flags(sink);
        let carried: u32 = s.bases.iter().map(|b| s.flags(b.model)).sum();
        assert!(delivered >= 5, "{delivered} flags delivered in 300 s");
        // Flags are moved, never made or lost: each left the source.
        assert!(carried <= 6 && s.flags(source) <= 1);
    }

    #[test]
    fn fasr_goes_to_charge_when_hungry_and_comes_back_full() {
        let mut s = fasr_world("fasr-charge", 3, 40.0);
        let packs = |s: &Sim| -> Vec<f64> {
            s.bases
                .iter()
                .map(|b| s.pack(b.model).map_or(1.0, |p| p.fraction()))
                .collect()
        };
        let (mut hungry, mut recharged) = (vec![false; 3], vec![false; 3]);
        for _ in 0..6000 {
            s.step();
            for (k, f) in packs(&s).into_iter().enumerate() {
                hungry[k] |= f < 0.25;
                recharged[k] |= hungry[k] && f > 0.95;
            }
        }
        assert!(hungry.iter().all(|&h| h), "hungry: {hungry:?}");
        let n = recharged.iter().filter(|&&r| r).count();
        assert!(n >= 2, "{n} of 3 robots recharged: {:?}", packs(&s));
    }

    /// fasr2's world, as a test writes it: a 32 m `cave` with a 6 m
    /// thick block from its south wall to 10 m short of the north one, the
    /// `red` task's source west of it and its sink east (a straight line
    /// meets the block), a fuel zone and a charger in the north-west, and
    /// `n` carriers with `kjoules` each.
    fn fasr2_world(name: &str, n: usize, kjoules: f64) -> Sim {
        let wall = |x0: f64, y0: f64, x1: f64, y1: f64| {
            format!(
                "block ( points 4 point[0] [{x0} {y0}] point[1] [{x1} {y0}] \
                 point[2] [{x1} {y1}] point[3] [{x0} {y1}] z [0 0.5] ) "
            )
        };
        let room = format!(
            "resolution 0.02\ninterval_sim 100\n\
             model ( name \"cave\" size [32 32 0.5] {}{}{}{}{})\n",
            wall(-16.0, -16.0, 16.0, -15.8),
            wall(-16.0, 15.8, 16.0, 16.0),
            wall(-16.0, -16.0, -15.8, 16.0),
            wall(15.8, -16.0, 16.0, 16.0),
            wall(-3.0, -16.0, 3.0, 6.0),
        );
        let mut text = "define zone model ( size [3 3 0.01] obstacle_return 0 ranger_return -1 )\n\
            zone ( name \"red_source\" pose [-10 -10 0 0] color \"red\" ctrl \"source 5\" )\n\
            zone ( name \"red_sink\" pose [10 -10 0 0] color \"DarkRed\" ctrl \"sink\" )\n\
            zone ( name \"fuel_zone\" pose [-13 13 0 0] size [1 1 0.01] )\n\
            model ( name \"charger\" pose [-15.7 13 0 0] size [0.1 0.3 0.3] obstacle_return 0 \
                    ranger_return 0 fiducial_return 2 kjoules -1 give_watts 1000 alwayson 1 )\n\
            define carrier tr_robot ( mass 23 ctrl \"fasr2 red\" \
              ranger ( pose [0 0 -0.1 0] sensor ( range [0 2] fov 180 samples 32 ) size [0.15 0.15 0.1] ) \
              model ( pose [0.24 0 -0.1 0] size [0.12 0.05 0.1] take_watts 1000 \
                      obstacle_return 0 fiducial ( range_max 9 range_max_id 9 pose [0 0 -0.05 0] ) ) )\n"
            .to_owned();
        for k in 0..n {
            let (x, y) = (-12.0 + 1.5 * (k % 3) as f64, -6.0 + 1.5 * (k / 3) as f64);
            text += &format!(
                "carrier ( name \"r{k}\" pose [{x} {y} 0 {}] kjoules {kjoules} )\n",
                k * 77 % 360
            );
        }
        sim_in(name, &room, &text)
    }

    #[test]
    fn fasr2_plans_around_the_wall_to_carry_flags() {
        let mut s = fasr2_world("fasr2", 4, 400.0);
        assert!(s
            .bases
            .iter()
            .all(|b| matches!(b.ctrl, Some(Ctrl::Fasr2 { .. }))));
        let sink = s.world.names["red_sink"];
        let mut east = 0;
        for _ in 0..9000 {
            s.step();
            // Robots reach the sink's side only round the block's north end.
            for b in &s.bases {
                let g = s.global(b.model);
                if g.x > 4.0 && g.y < 0.0 {
                    east += 1;
                }
            }
        }
        let delivered = s.flags(sink);
        assert!(delivered >= 8, "{delivered} flags delivered in 900 s");
        assert!(east > 0);
    }

    #[test]
    fn fasr2_without_its_zones_or_cave_leaves_its_robots_idle() {
        let text = "tr_robot ( name \"r0\" ranger ( sensor ( samples 32 ) ) fiducial ( ) \
                    ctrl \"fasr2 red\" )\n";
        let s = sim("fasr2-lacks", text);
        assert_eq!(s.bases[0].ctrl, None);
        assert!(matches!(
            super::super::fasr2::setup(&s.world, "fasr2 red"),
            Err(why) if why.contains("red_source")
        ));
        assert!(super::super::fasr2::setup(&s.world, "fasr2").is_err());
    }

    #[test]
    fn fasr2_recharges_at_the_fuel_zone() {
        let mut s = fasr2_world("fasr2-charge", 2, 30.0);
        let (mut hungry, mut recharged) = (vec![false; 2], vec![false; 2]);
        for _ in 0..8000 {
            s.step();
            for (k, b) in s.bases.iter().enumerate() {
                let f = s.pack(b.model).map_or(1.0, |p| p.fraction());
                hungry[k] |= f < 0.2;
                recharged[k] |= hungry[k] && f > 0.95;
            }
        }
        assert!(hungry.iter().all(|&h| h), "hungry: {hungry:?}");
        assert!(recharged.iter().all(|&r| r), "recharged: {recharged:?}");
    }

    #[test]
    fn sources_read_their_capacity_as_stage_does() {
        assert_eq!(atoi("200"), 200);
        assert_eq!(atoi("+7x"), 7);
        assert_eq!(atoi("-3"), 0);
        assert_eq!(atoi("many"), 0);
        let mut s = sim(
            "source",
            "model ( name \"a\" pose [-3 0 0 0] size [1 1 0.01] ctrl \"source 2 10\" update_interval 500 )\n\
             model ( name \"b\" pose [3 0 0 0] size [1 1 0.01] ctrl \"source\" )\n",
        );
        let (a, b) = (s.world.names["a"], s.world.names["b"]);
        // One flag each update (0.5 s) up to its capacity; `b` has none.
        steps(&mut s, 4);
        assert_eq!(s.flags(a), 0);
        steps(&mut s, 1);
        assert_eq!(s.flags(a), 1);
        steps(&mut s, 30);
        assert_eq!((s.flags(a), s.flags(b)), (2, 0));
        assert_eq!(s.flags_held().as_deref(), Some("`a` 2"));
    }

    #[test]
    fn lasernoise_scales_ranges_by_a_normal_deviate() {
        let text = "tr_robot ( name \"r0\" pose [3 0 0 0] tr_laser( ctrl \"lasernoise\" ) )\n\
                    tr_robot ( name \"r1\" pose [3 1 0 0] tr_laser() )\n";
        let mut s = sim("lasernoise", text);
        steps(&mut s, 5);
        let laser = |name: &str| s.world.names[name];
        let (noisy, clean) = (laser("r0.ranger:1"), laser("r1.ranger:1"));
        // Both face the east wall, 2.9 m off: the middle beams'.
        let ratios: Vec<f64> = (60..120)
            .map(|k| s.readings[noisy].sensor(0).ranges[k] / s.readings[clean].sensor(0).ranges[k])
            .collect();
        let n = ratios.len() as f64;
        let mean = ratios.iter().sum::<f64>() / n;
        let sd = (ratios.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / n).sqrt();
        assert!((mean - 1.0).abs() < 0.02, "mean ratio {mean}");
        assert!((0.03..0.07).contains(&sd), "deviation {sd}");
        assert!(s.readings[clean].sensor(0).ranges[90] < 3.0);
    }
}
