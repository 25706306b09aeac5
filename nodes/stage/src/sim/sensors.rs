//! Range sensing: a ranger's readings, its sensors' rays laid out for the
//! cache, and the casts through the static grid and among moving bodies
//! (exact, or as Stage's raster reads them).

use super::*;

/// A ranger's latest readings: its sensors' ranges and intensities, one
/// sensor after another in two arrays. (Two arrays per sensor were, for
/// Stage's hospital.world, 24000 small allocations read and written every
/// step, a cache miss each.)
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Readings {
    pub(super) ranges: Vec<f64>,
    pub(super) intensities: Vec<f64>,
    /// Where each sensor's readings start, then where the last one's end.
    pub(super) starts: Vec<usize>,
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
    pub(super) fn new(sensors: &[Sensor]) -> Readings {
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
    pub(super) fn span(&self, i: usize) -> Option<std::ops::Range<usize>> {
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
    pub(super) fn sensor_mut(&mut self, i: usize) -> (&mut [f64], &mut [f64]) {
        match self.span(i) {
            Some(span) => (&mut self.ranges[span.clone()], &mut self.intensities[span]),
            None => (&mut [], &mut []),
        }
    }
}

/// The moving bodies already tested along one ray or under one body: a
/// body spans a few tiles and is tested once (the first few are
/// remembered; past them a body may be tested again, which is only slower).
#[derive(Default)]
pub(super) struct Seen {
    pub(super) ids: [u16; 8],
    pub(super) n: usize,
}

impl Seen {
    /// True the first time `id` is seen (and remembers it, room allowing).
    pub(super) fn first(&mut self, id: u16) -> bool {
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
pub(super) struct TileBodies<'a, A> {
    pub(super) sim: &'a Sim,
    pub(super) o: (f64, f64),
    pub(super) d: (f64, f64),
    /// The ray's height (`None`: every height).
    pub(super) z: Option<f64>,
    pub(super) accept: A,
    pub(super) own: u16,
    pub(super) tested: Seen,
}

impl<'a, A> TileBodies<'a, A> {
    pub(super) fn new(
        sim: &'a Sim,
        (o, d, z): ((f64, f64), (f64, f64), Option<f64>),
        accept: A,
        own: u16,
    ) -> Self {
        TileBodies {
            sim,
            o,
            d,
            z,
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
            .nearest_body((o, d, self.z), ids, &self.accept, own, &mut self.tested)
    }
}

/// What a ray asks of a model it meets (see `Sim::ranger_sees`).
#[derive(Debug, Clone, Copy)]
pub(super) struct Look {
    /// The model at the root of its tree (kept here alone: a gripper
    /// changes it as it takes and drops).
    pub(super) root: u32,
    /// Its `ranger_return`: rangers see it when this is not negative, and
    /// read it as the intensity of a hit.
    pub(super) ret: f64,
    /// Its body's base and top above the floor.
    pub(super) lo: f64,
    pub(super) hi: f64,
}

impl Look {
    /// Whether rangers see it.
    #[inline]
    pub(super) fn seen(&self) -> bool {
        self.ret >= 0.0
    }

    /// Whether its body spans height `z` (Stage's ray z test).
    #[inline]
    pub(super) fn spans(&self, z: f64) -> bool {
        self.lo <= z && z <= self.hi
    }
}

/// Sensors with at least this many rays look around their origin once, so
/// that their rays start beyond the open space there (for fewer rays the
/// look costs more than it spares).
pub(super) const FAN: usize = 16;

/// A ranger's sensors as its rays and its controllers read them, each
/// in an array of its own: every step reads them for a thousand rangers,
/// so what each reads is laid out to cost it the fewest cache lines.
#[derive(Default)]
pub(super) struct Fans {
    /// The ranger's pose on its parent (its `origin`).
    pub(super) origin: Pose,
    /// What every sensor's rays read: a cache line a sensor.
    pub(super) rays: Vec<Rays>,
    /// Each sensor's turn from one ray to the next (see [`fan`]): as a
    /// unit vector and as an angle. Only sensors of several rays read it.
    pub(super) turns: Vec<((f64, f64), f64)>,
    /// Each sensor's heading on the ranger, which the controllers sum
    /// the first readings along (see `Sim::resultant`).
    pub(super) headings: Vec<(f64, f64)>,
}

/// A sensor's rays as the ranger casts them: the unit vector of the
/// first, relative to the ranger (see [`fan`]), and what of the sensor
/// the rays read, kept beside it in one cache line.
#[repr(align(64))]
pub(super) struct Rays {
    pub(super) first: (f64, f64),
    /// Where the rays start, in the ranger's frame.
    pub(super) at: (f64, f64),
    /// The sensor's range, in metres: nearest and farthest.
    pub(super) range: (f64, f64),
    /// Their height above the ranger's base: the middle of the sensor's.
    pub(super) z: f64,
    /// How many rays.
    pub(super) samples: usize,
}

/// A sensor's rays: the angle of the first relative to the sensor, and
/// the angle from one to the next.
pub(super) fn fan(s: &Sensor) -> (f64, f64) {
    if s.samples > 1 {
        (s.pose.yaw - s.fov / 2.0, s.fov / (s.samples - 1) as f64)
    } else {
        (s.pose.yaw, 0.0)
    }
}

/// The first of `0..n` for which `p` holds, where it holds for all after
/// it too (`n` when there is none).
pub(super) fn first_where(n: usize, p: impl Fn(usize) -> bool) -> usize {
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
pub(super) fn nearest(ranges: &[f64]) -> f64 {
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

impl Sim {
    /// Rays read as Stage's (`true`: Stage's raster of block outlines and
    /// its ray walk; see [`troupe_geom::raster`]) or against the exact
    /// bodies (`false`, the default: the bench worlds run up to 2.5 times
    /// faster).
    /// With Stage's raster, moving bodies are drawn into it too, as
    /// Stage draws them after each move.
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
            self.place(m);
        }
        self.sense();
    }

    /// The first body along the ray from (x, y) along the unit vector
    /// `(dx, dy)`, within `range`, whose id `accept`s: walls and other static
    /// bodies from the static grid, moving bodies tested exactly as the ray
    /// passes their tiles (at height `z`, when given, only the blocks
    /// spanning it: `accept` tests the model's span). The ray is looked at
    /// from `range.0` on: the caller knows nothing it accepts lies nearer.
    /// Body `own` (0 for none), which `accept` refuses, is passed over
    /// untested: a ranger's rays start in their own robot.
    pub(super) fn cast(
        &self,
        (x, y): (f64, f64),
        (dx, dy): (f64, f64),
        range: (f64, f64),
        z: Option<f64>,
        accept: impl Fn(u16) -> bool,
        own: u16,
    ) -> Option<Hit> {
        // A body filed in several tiles the ray crosses is met in each: its
        // circle and a rectangle cost less to test again than to look up
        // among those tested, but a body of many edges is tested once.
        let movers = TileBodies::new(self, ((x, y), (dx, dy), z), &accept, own);
        self.statics
            .cast_with(x, y, (dx, dy), range, &accept, movers)
    }

    /// [`Sim::cast`] of a ray from (x, y) at height z when the moving bodies
    /// it may meet are known: the nearest of them, and the static grid up
    /// to it.
    pub(super) fn cast_among(
        &self,
        (x, y, z): (f64, f64, f64),
        d: (f64, f64),
        (from, max_range): (f64, f64),
        accept: impl Fn(u16) -> bool,
        bodies: impl Iterator<Item = u16>,
    ) -> Option<Hit> {
        let best = self
            .nearest_body(
                ((x, y), d, Some(z)),
                bodies,
                |_| true,
                0,
                &mut Seen::default(),
            )
            .filter(|h| h.range <= max_range);
        let reach = best.map_or(max_range, |b| b.range);
        match self.statics.cast_open(x, y, d, (from, reach), &accept) {
            Some(h) if best.is_none_or(|b| h.range < b.range) => Some(h),
            _ => best,
        }
    }

    /// The first of the moving `bodies` whose id `accept`s met by the ray
    /// from `o` along the unit vector `d` at height `z` (the earliest of
    /// those met equally near); bodies of many edges in `tested` are not
    /// tested again, nor body `own`.
    #[inline(always)]
    pub(super) fn nearest_body(
        &self,
        (o, d, z): ((f64, f64), (f64, f64), Option<f64>),
        bodies: impl Iterator<Item = u16>,
        accept: impl Fn(u16) -> bool,
        own: u16,
        tested: &mut Seen,
    ) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        for k in bodies.filter(|&k| k != own) {
            let once = |k| tested.first(k);
            if let Some(h) = self
                .movers
                .hit(usize::from(k) - 1, k, (o, d, z), &accept, once)
            {
                if best.is_none_or(|b| h.range < b.range) {
                    best = Some(h);
                }
            }
        }
        best
    }

    /// How far from (x, y) nothing `accept`ed lies, in any direction: the
    /// static grid's clearance there, less for a moving body within it.
    pub(super) fn open_around(&self, x: f64, y: f64, accept: impl Fn(u16) -> bool) -> f64 {
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

    /// Whether model `m`'s body spans height `z` (Stage's ray z test).
    pub(super) fn spans(&self, m: usize, z: f64) -> bool {
        self.looks[m].spans(z)
    }

    /// What ranger `r`'s rays at height `z` stop at: anything with a ranger
    /// return at that height that is not part of its own robot.
    pub(super) fn ranger_sees(&self, r: usize, z: f64) -> impl Fn(u16) -> bool + Copy + '_ {
        let root = self.looks[r].root;
        move |c: u16| {
            let o = &self.looks[usize::from(c) - 1];
            o.root != root && o.seen() && o.spans(z)
        }
    }

    /// Ranger `r`'s readings into `out`; `sweep` is room for its fans' look
    /// at the moving bodies, kept from ranger to ranger.
    pub(super) fn sense_one(&self, r: usize, out: &mut Readings, sweep: &mut Sweep) {
        // One sine and cosine per ranger, its robot's when it is not
        // turned on it: its sensors' poses and first rays are turned by it
        // (or by a second, when its origin is turned).
        let (g, gz, (sin, cos)) = self.global_turned(r);
        let fans = &self.fans[r];
        let o = &fans.origin;
        let base = (g.x + cos * o.x - sin * o.y, g.y + sin * o.x + cos * o.y);
        let turn = if o.yaw == 0.0 {
            (cos, sin)
        } else {
            unit(g.yaw + o.yaw)
        };
        // The body the rays start in, which they never stop at.
        let own = u16::try_from(self.looks[r].root + 1).unwrap_or(0);
        // Each sensor's readings follow the last's (`Readings::new` laid
        // them out from these sensors): taken in turn, without looking up
        // where each starts (a cache miss a sensor, for a swarmbot's
        // twelve IRs of one ray each).
        debug_assert!(fans
            .rays
            .iter()
            .enumerate()
            .all(|(i, s)| out.span(i).map(|span| span.len()) == Some(s.samples)));
        let (mut rest, mut rest_i) = (&mut out.ranges[..], &mut out.intensities[..]);
        for (i, s) in fans.rays.iter().enumerate() {
            let (ranges, r_rest) = std::mem::take(&mut rest).split_at_mut(s.samples);
            let (intensities, i_rest) = std::mem::take(&mut rest_i).split_at_mut(s.samples);
            (rest, rest_i) = (r_rest, i_rest);
            let z = gz + s.z;
            let accept = self.ranger_sees(r, z);
            let (ox, oy) = turned(turn, s.at);
            let (ox, oy) = (base.0 + ox, base.1 + oy);
            // A fan of rays shares one look at the moving bodies within
            // reach, so that each ray tests only those in its direction,
            // and (against the exact bodies) one look around its origin,
            // so that none of its rays walks the open space there.
            // (On Stage's raster every body is in the cells: no fan.)
            let fan = s.samples >= FAN && self.raster.is_none();
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
                self.open_around(ox, oy, accept)
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
                    // Every body as Stage sees it: drawn into its raster,
                    // the moving ones where they moved to.
                    (Some(r), _) => r.cast(ox, oy, d, s.range.1, accept),
                    (None, true) => {
                        self.cast_among((ox, oy, z), d, (from, s.range.1), accept, sweep.at(k))
                    }
                    (None, false) => {
                        self.cast((ox, oy), d, (from, s.range.1), Some(z), accept, own)
                    }
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
}
