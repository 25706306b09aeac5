//! Moving bodies as range sensors see them.
//!
//! Rays find walls by walking the static grid cell by cell, but a robot's
//! own body and its neighbours would make every ray walk dozens of cells of
//! the moving grid. Instead each moving body keeps its polygons in world
//! coordinates, filed under the grid tiles it touches; a ray tests a body
//! exactly when it enters one of those tiles (a rectangle, the usual body,
//! as a box in its own frame; any other polygon edge by edge), and a
//! robot's own body costs nothing because it is never tested.
//!
//! A fan of rays from one origin (a laser) does better: it looks once at
//! the bodies within its reach ([`Sweep`]), turns each into the run of
//! rays whose directions pass through it, and each ray tests just the
//! bodies of its runs. The ray then walks the static grid only up to the
//! nearest, and without stopping at every tile to ask what is filed there.

use troupe_geom::{bounds, Hit, Pose, TileBox, Transform};

/// The polygons of every moving body, filed by tile.
#[derive(Debug, Clone, Default)]
pub struct Movers {
    /// Each model's body (no polygons when not filed).
    bodies: Vec<Body>,
    /// What rays read of each body (see [`Shape`]), side by side: a cache
    /// line a body where a `Body` spans four.
    shapes: Vec<Shape>,
    /// The box of tiles each model is filed under.
    boxes: Vec<Option<TileBox>>,
    /// How many tiles a row has ([`TileBox::tiles`] numbers them by it).
    tw: usize,
    /// Model ids (index + 1) filed under each tile.
    filed: Vec<Filed>,
    /// The ids of tiles that hold more than [`INLINE`] (see [`Filed`]).
    spilled: Vec<Vec<u16>>,
    /// Lists in `spilled` no tile uses.
    free: Vec<usize>,
    /// One bit per tile: whether anything is filed under it. Most tiles a
    /// ray crosses hold no body, and these bits (1000 × 400 tiles in 50 KB)
    /// stay in cache where the lists' headers would not.
    busy: Vec<u64>,
}

/// How many ids a tile keeps in place (see [`Filed`]).
const INLINE: usize = 7;

/// [`Filed::n`] of a tile whose ids are in a list of their own.
const SPILLED: u16 = u16::MAX;

/// The ids filed under a tile: up to [`INLINE`] in place, 16 bytes a tile
/// read in one go (a tile a body is in holds one to three, most often);
/// more in a list of their own in [`Movers`], whose index the first two
/// hold.
#[derive(Debug, Clone, Copy, Default)]
struct Filed {
    ids: [u16; INLINE],
    /// How many, or [`SPILLED`].
    n: u16,
}

impl Filed {
    /// A tile whose ids are in list `k`.
    fn spilled(k: usize) -> Filed {
        let mut f = Filed {
            ids: [0; INLINE],
            n: SPILLED,
        };
        f.ids[0] = k as u16;
        f.ids[1] = (k >> 16) as u16;
        f
    }

    /// The list its ids are in, when [`SPILLED`].
    fn list(&self) -> usize {
        usize::from(self.ids[0]) | usize::from(self.ids[1]) << 16
    }
}

/// A moving body: its polygons in world coordinates, and what rays and
/// collisions look at first (worked out whenever the polygons change).
#[derive(Debug, Clone)]
pub struct Body {
    /// The polygons.
    polys: Vec<Vec<(f64, f64)>>,
    /// Their box: x0, y0, x1, y1 (`None` when there are no points).
    bounds: Option<[f64; 4]>,
    /// A circle around them (centre x, y, radius; negative when there are
    /// no points): what misses it misses them.
    circle: (f64, f64, f64),
    /// The body as a rectangle, when it is one (most are: a model's
    /// default body is its box): rays test it in its own frame.
    rect: Option<Rect>,
    /// A circle around each polygon, as [`Body::circle`] is around them
    /// all, when there are several: a ray tests the edges only of those
    /// its line meets (Stage's fancy Pioneer is seven polygons, a ray from a
    /// neighbour meets one or two).
    poly_circles: Vec<(f64, f64, f64)>,
    /// Each polygon's base and top above the floor, when there are several
    /// (see [`Body::lift`]): a ray passes under or over those it does not
    /// meet in height, as Stage tests each block (the fancy Pioneer's
    /// wheels and lid are below and above its sonars).
    heights: Vec<(f64, f64)>,
}

impl Default for Body {
    fn default() -> Self {
        Body {
            polys: Vec::new(),
            bounds: None,
            circle: (0.0, 0.0, -1.0),
            rect: None,
            poly_circles: Vec::new(),
            heights: Vec::new(),
        }
    }
}

impl Body {
    /// Becomes `blocks` (polygons in a model's frame) placed at pose `at`,
    /// reusing its buffers.
    pub fn place(&mut self, blocks: &[Vec<(f64, f64)>], at: Pose) {
        self.place_outlined(blocks, at.transform(), &Outline::of(blocks));
    }

    /// [`Body::place`] at the pose whose transform is `t`, for `blocks`
    /// whose circles in their own frame are `outline`
    /// (`Outline::of(blocks)`, kept): the circles are carried there, not
    /// worked out again from the placed points.
    pub fn place_outlined(&mut self, blocks: &[Vec<(f64, f64)>], t: Transform, outline: &Outline) {
        self.polys.resize_with(blocks.len(), Vec::new);
        self.heights.clear();
        let apply = |x, y| t.point(x, y);
        for (poly, b) in self.polys.iter_mut().zip(blocks) {
            poly.clear();
            poly.extend(b.iter().map(|&(x, y)| apply(x, y)));
        }
        self.bounds = bounds(self.polys.iter().flatten().copied());
        // Turns and shifts keep right angles and lengths: the rectangle,
        // like the circles, is carried from the model's frame.
        self.rect = outline.rect.map(|r| Rect {
            c: apply(r.c.0, r.c.1),
            u: t.turn(r.u.0, r.u.1),
            half: r.half,
            radius: r.radius,
        });
        let carry = |&(x, y, r): &(f64, f64, f64)| {
            let (x, y) = apply(x, y);
            (x, y, r)
        };
        self.circle = match self.rect {
            // Centred on the rectangle, so that rays read both from one
            // centre (see [`Shape`]).
            Some(r) => (r.c.0, r.c.1, r.radius),
            None => carry(&outline.circle),
        };
        self.poly_circles.clear();
        self.poly_circles.extend(outline.polys.iter().map(carry));
    }

    /// Gives its polygons (when several) the heights `z` above `base`, one
    /// per polygon in order; a body of one polygon is seen at every height
    /// its model spans, which its model's rays test.
    pub fn lift(&mut self, z: &[(f64, f64)], base: f64) {
        self.heights.clear();
        if self.polys.len() > 1 && z.len() == self.polys.len() {
            self.heights
                .extend(z.iter().map(|&(lo, hi)| (base + lo, base + hi)));
        }
    }

    /// The polygons, in world coordinates.
    pub fn polys(&self) -> &[Vec<(f64, f64)>] {
        &self.polys
    }

    /// The polygons' box: x0, y0, x1, y1 (`None` when there are no points).
    pub fn bounds(&self) -> Option<[f64; 4]> {
        self.bounds
    }

    /// The circle around the polygons: centre x, y and radius (negative
    /// when there are none).
    pub fn circle(&self) -> (f64, f64, f64) {
        self.circle
    }
    /// Whether it overlaps `other`: an edge of one crosses an edge of the
    /// other, or one holds a corner of the other.
    pub fn overlaps(&self, other: &Body) -> bool {
        let ((ax, ay, ar), (bx, by, br)) = (self.circle, other.circle);
        if (ax - bx).powi(2) + (ay - by).powi(2) > (ar + br).powi(2) || ar < 0.0 || br < 0.0 {
            return false;
        }
        // Polygons whose circles do not meet are apart: only the pairs
        // left are tested edge by edge (of two fancy Pioneers' seven
        // polygons each, a few pairs).
        let apart = |(ax, ay, ar): (f64, f64, f64), (bx, by, br): (f64, f64, f64)| {
            (ax - bx).powi(2) + (ay - by).powi(2) > (ar + br).powi(2)
        };
        self.polys.iter().enumerate().any(|(ka, a)| {
            let ca = self.poly_circle(ka);
            !apart(ca, other.circle)
                && other.polys.iter().enumerate().any(|(kb, b)| {
                    !apart(ca, other.poly_circle(kb))
                        && (edges_cross(a, b)
                            || a.first().is_some_and(|&p| inside(b, p))
                            || b.first().is_some_and(|&p| inside(a, p)))
                })
        })
    }

    /// The circle around polygon `k` (around them all when it is the only
    /// one).
    fn poly_circle(&self, k: usize) -> (f64, f64, f64) {
        self.poly_circles.get(k).copied().unwrap_or(self.circle)
    }
}

/// The circles around a model's blocks in its own frame: around them all,
/// and around each when there are several. Turns and shifts keep
/// distances, so a placed body carries them to where it is rather than
/// working them out from its points every step (most of placing Stage's
/// fancy Pioneer, seven polygons of 60 points).
#[derive(Debug, Clone)]
pub struct Outline {
    /// Around them all (negative radius when there are no points).
    circle: (f64, f64, f64),
    /// Around each, when there are several (none otherwise).
    polys: Vec<(f64, f64, f64)>,
    /// The one block as a rectangle, when it is one.
    rect: Option<Rect>,
}

impl Outline {
    /// The outline of `blocks`.
    pub fn of(blocks: &[Vec<(f64, f64)>]) -> Outline {
        let polys = if blocks.len() > 1 {
            blocks
                .iter()
                .map(|p| circle_around(std::slice::from_ref(p), bounds(p.iter().copied())))
                .collect()
        } else {
            Vec::new()
        };
        Outline {
            circle: circle_around(blocks, bounds(blocks.iter().flatten().copied())),
            polys,
            rect: match blocks {
                [one] => Rect::of(one),
                _ => None,
            },
        }
    }
}

impl Movers {
    /// Room for `models` models over a grid of `tiles` tiles.
    /// Room for `models` models, in `tiles` tiles in rows `tw` wide.
    pub fn new(models: usize, tw: usize, tiles: usize) -> Self {
        Movers {
            bodies: vec![Body::default(); models],
            shapes: vec![Shape::of(&Body::default()); models],
            boxes: vec![None; models],
            tw: tw.max(1),
            filed: vec![Filed::default(); tiles],
            spilled: Vec::new(),
            free: Vec::new(),
            busy: vec![0; tiles.div_ceil(64)],
        }
    }

    /// Files model `m` (id `id`), whose body is `body`, under the box of
    /// `tiles` (none: under no tile), replacing where it was. The body is
    /// swapped in, not copied: `body` gets the last filing's buffers back
    /// for the next, so a body that moves every step allocates nothing, and
    /// whoever placed it worked out its circle.
    pub fn file(&mut self, m: usize, id: u16, body: &mut Body, tiles: Option<TileBox>) {
        // Most steps a body stays in its tiles: only its shape moved.
        if tiles != self.boxes[m] {
            self.untile(m, id);
            let tw = self.tw;
            for t in tiles.into_iter().flat_map(|b| b.tiles(tw)) {
                if t < self.filed.len() {
                    self.push(t, id);
                    self.busy[t / 64] |= 1 << (t % 64);
                }
            }
            self.boxes[m] = tiles;
        }
        std::mem::swap(&mut self.bodies[m], body);
        self.shapes[m] = Shape::of(&self.bodies[m]);
    }

    /// Model `m`'s filed polygons, in world coordinates (none when not filed).
    pub fn shapes(&self, m: usize) -> &[Vec<(f64, f64)>] {
        &self.bodies[m].polys
    }

    /// Takes model `m` (id `id`) out of every tile.
    pub fn unfile(&mut self, m: usize, id: u16) {
        self.untile(m, id);
        self.bodies[m] = Body::default();
        self.shapes[m] = Shape::of(&self.bodies[m]);
    }

    /// Takes model `m` (id `id`) out of every tile, keeping its shape.
    fn untile(&mut self, m: usize, id: u16) {
        let tw = self.tw;
        for t in self.boxes[m].take().into_iter().flat_map(|b| b.tiles(tw)) {
            if t < self.filed.len() && self.remove(t, id) {
                self.busy[t / 64] &= !(1 << (t % 64));
            }
        }
    }

    /// Files `id` under tile `t`, after those there.
    fn push(&mut self, t: usize, id: u16) {
        let f = &mut self.filed[t];
        match f.n {
            SPILLED => self.spilled[f.list()].push(id),
            n if usize::from(n) < INLINE => {
                f.ids[usize::from(n)] = id;
                f.n += 1;
            }
            _ => {
                let k = self.free.pop().unwrap_or_else(|| {
                    self.spilled.push(Vec::new());
                    self.spilled.len() - 1
                });
                self.spilled[k].extend_from_slice(&f.ids);
                self.spilled[k].push(id);
                *f = Filed::spilled(k);
            }
        }
    }

    /// Takes `id` out of tile `t`, keeping the others' order: true when
    /// none is left.
    fn remove(&mut self, t: usize, id: u16) -> bool {
        let f = &mut self.filed[t];
        if f.n == SPILLED {
            let k = f.list();
            let list = &mut self.spilled[k];
            list.retain(|&i| i != id);
            if list.len() <= INLINE {
                // Back in place: the list is free for another tile.
                let mut back = Filed::default();
                back.ids[..list.len()].copy_from_slice(list);
                back.n = list.len() as u16;
                list.clear();
                self.free.push(k);
                *f = back;
            }
        } else {
            let n = usize::from(f.n);
            if let Some(at) = f.ids[..n].iter().position(|&i| i == id) {
                f.ids.copy_within(at + 1..n, at);
                f.n -= 1;
            }
        }
        f.n == 0
    }

    /// How far point `p` is from model `m`'s body, at least (the distance to
    /// the circle around it; negative inside the circle).
    pub fn clearance(&self, m: usize, p: (f64, f64)) -> f64 {
        let (cx, cy, r) = self.shapes[m].circle;
        ((cx - p.0).powi(2) + (cy - p.1).powi(2)).sqrt() - r
    }

    /// The ids filed under tile `t`.
    #[inline(always)]
    pub fn in_tile(&self, t: usize) -> &[u16] {
        let busy = self
            .busy
            .get(t / 64)
            .is_some_and(|b| b >> (t % 64) & 1 != 0);
        if !busy {
            return &[];
        }
        match self.filed.get(t) {
            Some(f) if f.n == SPILLED => &self.spilled[f.list()],
            Some(f) => &f.ids[..usize::from(f.n)],
            None => &[],
        }
    }

    /// Whether model `m`'s filed body overlaps `body`.
    pub fn overlaps(&self, m: usize, body: &Body) -> bool {
        self.bodies[m].overlaps(body)
    }

    /// Where the ray from `o` along the unit vector `d`, at height `z`
    /// above the floor (`None`: at every height), first meets model `m`'s
    /// body (id `id`), if it `accept`s that id: metres, 0 when `o` is
    /// inside it. A body that is not a rectangle is tested edge by edge
    /// only if `once(id)` (false: this ray has tested it already), and
    /// only its polygons that span `z`.
    #[inline(always)]
    pub fn hit(
        &self,
        m: usize,
        id: u16,
        (o, d, z): ((f64, f64), (f64, f64), Option<f64>),
        accept: impl Fn(u16) -> bool,
        once: impl FnOnce(u16) -> bool,
    ) -> Option<Hit> {
        // Most rays that pass a body's tiles miss it: the circle says so
        // without testing edges, or asking whether the ray stops at it.
        let shape = &self.shapes[m];
        let (cx, cy, r) = shape.circle;
        let w = (cx - o.0, cy - o.1);
        if (w.0 * d.1 - w.1 * d.0).abs() > r || w.0 * d.0 + w.1 * d.1 < -r || !accept(id) {
            return None;
        }
        if shape.half.0 >= 0.0 {
            return shape.hit_rect(o, d).map(|range| Hit { range, id });
        }
        if !once(id) {
            return None;
        }
        self.hit_edges(m, id, o, d, z)
    }

    /// [`Movers::hit`] by testing the ray against every edge.
    #[inline(never)]
    fn hit_edges(
        &self,
        m: usize,
        id: u16,
        o: (f64, f64),
        d: (f64, f64),
        z: Option<f64>,
    ) -> Option<Hit> {
        let mut best = f64::INFINITY;
        let body = &self.bodies[m];
        for (k, poly) in body.polys.iter().enumerate() {
            if let (Some(z), Some(&(lo, hi))) = (z, body.heights.get(k)) {
                if z < lo || z > hi {
                    continue;
                }
            }
            if let Some(&(cx, cy, r)) = body.poly_circles.get(k) {
                // A polygon whose circle the ray misses, or meets only
                // beyond the nearest crossing yet, is neither crossed
                // first nor around the ray's start.
                let w = (cx - o.0, cy - o.1);
                let along = w.0 * d.0 + w.1 * d.1;
                if (w.0 * d.1 - w.1 * d.0).abs() > r || along < -r || along - r > best {
                    continue;
                }
            }
            // Branch-free: whether the ray crosses an edge is a coin toss
            // a predictor loses, and a miss costs more than the division.
            let mut crossings = 0u32;
            for (a, b) in edges(poly) {
                // The ray o + t·d meets the edge a + u·e where t = tn/den
                // and u = un/den (den turned positive, signs with it).
                let e = (b.0 - a.0, b.1 - a.1);
                let den = d.0 * e.1 - d.1 * e.0;
                let w = (a.0 - o.0, a.1 - o.1);
                let sign = 1.0f64.copysign(den);
                let tn = (w.0 * e.1 - w.1 * e.0) * sign;
                let un = (w.0 * d.1 - w.1 * d.0) * sign;
                let den = den.abs();
                let cross = (un >= 0.0) & (un < den) & (tn >= 0.0) & (den >= 1e-15);
                crossings += u32::from(cross);
                let t = tn / den;
                best = if cross { best.min(t) } else { best };
            }
            if crossings % 2 == 1 {
                // The ray starts inside this polygon.
                return Some(Hit { range: 0.0, id });
            }
        }
        best.is_finite().then_some(Hit { range: best, id })
    }
}

/// A fan of rays: `n` rays from `o`, the first along the unit vector
/// `first`, each next turned `step` radians (anticlockwise) from the one
/// before, looked at to `reach` metres.
#[derive(Debug, Clone, Copy)]
pub struct Fan {
    /// Where the rays start.
    pub o: (f64, f64),
    /// The first ray's direction.
    pub first: (f64, f64),
    /// Radians from one ray to the next.
    pub step: f64,
    /// How many rays.
    pub n: usize,
    /// How far the rays look, in metres.
    pub reach: f64,
}

/// The moving bodies a fan of rays may meet, worked out once for the fan:
/// each body within reach and in front becomes the run of rays whose
/// directions pass through its circle. A ray then tests only the bodies
/// in its direction, not every body filed in the tiles it crosses.
#[derive(Debug, Default)]
pub struct Sweep {
    /// Runs of rays: first, last, body id; by first ray once started.
    runs: Vec<(usize, usize, u16)>,
    /// The next run not yet begun.
    next: usize,
    /// The runs holding the current ray: body id, last ray.
    now: Vec<(u16, usize)>,
}

/// Slack on a run's angles: more than [`atan2`]'s error and the drift of
/// rays turned step by step, far less than rays' spacing.
const SLACK: f64 = 1e-5;

impl Sweep {
    /// Starts over for `fan`, with the bodies `accept`ed among `movers`.
    pub fn start(&mut self, movers: &Movers, fan: &Fan, accept: impl Fn(u16) -> bool) {
        use std::f64::consts::{PI, TAU};
        self.runs.clear();
        self.now.clear();
        self.next = 0;
        let Some(last) = fan.n.checked_sub(1) else {
            return;
        };
        let span = last as f64 * fan.step;
        // Rays all one way, or turning more than once round: every ray
        // tests every body within reach.
        let every = fan.step.is_nan() || fan.step <= 1e-9 || span > TAU + SLACK;
        // A fan of at most half a turn lies on the left of its first ray
        // (give or take rounding: a reach times the slack).
        let half_plane = span <= PI + SLACK;
        let below = -SLACK * fan.reach;
        let (ex, ey) = fan.first;
        for (m, shape) in movers.shapes.iter().enumerate() {
            let (cx, cy, r) = shape.circle;
            // The circle in the fan's frame: x along the first ray.
            let (dx, dy) = (cx - fan.o.0, cy - fan.o.1);
            let (x, y) = (dx * ex + dy * ey, dy * ex - dx * ey);
            let d2 = x * x + y * y;
            if r < 0.0 || d2 > (fan.reach + r).powi(2) || (half_plane && y + r < below) {
                continue;
            }
            let Ok(id) = u16::try_from(m + 1) else {
                break;
            };
            if !accept(id) {
                continue;
            }
            let d = d2.sqrt();
            if every || d <= r * (1.0 + SLACK) {
                self.runs.push((0, last, id));
                continue;
            }
            // The directions through the circle: its bearing ± asin(r/d).
            let half = atan2(r, (d2 - r * r).sqrt()) + SLACK;
            let bearing = atan2(y, x);
            for turn in [0.0, TAU] {
                let (a, b) = (bearing - half + turn, bearing + half + turn);
                if b < 0.0 || a > span {
                    continue;
                }
                // The rays from ⌈a⌉ to ⌊b⌋ (in steps); truncating floors
                // what is not negative.
                let (a, b) = (a.max(0.0) / fan.step, b / fan.step);
                let lo = a as usize + usize::from((a as usize as f64) < a);
                let hi = (b as usize).min(last);
                if lo <= hi {
                    self.runs.push((lo, hi, id));
                }
            }
        }
        self.runs
            .sort_unstable_by_key(|&(first, _, id)| (first << 16) | usize::from(id));
    }

    /// The ids of the bodies ray `k` may meet; call for rays 0, 1, 2, … in
    /// turn.
    pub fn at(&mut self, k: usize) -> impl Iterator<Item = u16> + '_ {
        self.now.retain(|&(_, last)| last >= k);
        while let Some(&(first, last, id)) = self.runs.get(self.next) {
            if first > k {
                break;
            }
            self.next += 1;
            if last >= k {
                self.now.push((id, last));
            }
        }
        self.now.iter().map(|&(id, _)| id)
    }
}

/// The angle of (x, y), within 2e-6 radians: a polynomial, a few times
/// cheaper than `f64::atan2`.
fn atan2(y: f64, x: f64) -> f64 {
    use std::f64::consts::{FRAC_PI_2, PI};
    let (ax, ay) = (x.abs(), y.abs());
    let (lo, hi) = (ax.min(ay), ax.max(ay));
    if hi.is_nan() || hi <= 0.0 {
        return 0.0;
    }
    let t = lo / hi;
    let s = t * t;
    let p = -0.011_721_20;
    let p = p * s + 0.052_653_32;
    let p = p * s - 0.116_432_87;
    let p = p * s + 0.193_543_46;
    let p = p * s - 0.332_623_47;
    let p = p * s + 0.999_977_26;
    let a = p * t;
    let a = if ay > ax { FRAC_PI_2 - a } else { a };
    let a = if x < 0.0 { PI - a } else { a };
    if y < 0.0 {
        -a
    } else {
        a
    }
}

/// A rectangle (in the world, or in a model's frame): its centre, the unit vector along its first
/// side, and its half extents along that side and across it.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Rect {
    c: (f64, f64),
    u: (f64, f64),
    half: (f64, f64),
    /// The radius of the circle about `c` through its corners (padded).
    radius: f64,
}

impl Rect {
    /// The rectangle `poly` is, if it is one (four corners in order, right
    /// angles, to a hair).
    fn of(poly: &[(f64, f64)]) -> Option<Rect> {
        let &[p0, p1, p2, p3] = poly else {
            return None;
        };
        let a = (p1.0 - p0.0, p1.1 - p0.1);
        let b = (p3.0 - p0.0, p3.1 - p0.1);
        let (la, lb) = (a.0.hypot(a.1), b.0.hypot(b.1));
        let tol = 1e-9 * (la + lb);
        let square = (a.0 * b.0 + a.1 * b.1).abs() <= tol * (la + lb);
        let closes =
            (p0.0 + a.0 + b.0 - p2.0).abs() <= tol && (p0.1 + a.1 + b.1 - p2.1).abs() <= tol;
        (la > 0.0 && lb > 0.0 && square && closes).then(|| Rect {
            c: ((p0.0 + p2.0) / 2.0, (p0.1 + p2.1) / 2.0),
            u: (a.0 / la, a.1 / la),
            half: (la / 2.0, lb / 2.0),
            radius: pad((la / 2.0).hypot(lb / 2.0)),
        })
    }
}

/// What a ray reads of a body, in one cache line: the circle around it
/// (centre x, y, radius; negative when it has no points) and, when it is a
/// rectangle, that rectangle about the same centre: the unit vector along
/// its first side and its half extents (negative when it is not one).
#[derive(Debug, Clone, Copy)]
#[repr(align(64))]
struct Shape {
    circle: (f64, f64, f64),
    u: (f64, f64),
    half: (f64, f64),
}

impl Shape {
    /// What a ray reads of `body`.
    fn of(body: &Body) -> Shape {
        let (u, half) = body
            .rect
            .map_or(((1.0, 0.0), (-1.0, -1.0)), |r| (r.u, r.half));
        Shape {
            circle: body.circle,
            u,
            half,
        }
    }

    /// Where the ray from `o` along the unit vector `d` enters the
    /// rectangle (when the body is one): metres, 0 when `o` is inside it. In the rectangle's frame
    /// it is a box: the ray's span in each slab, met.
    #[inline]
    fn hit_rect(&self, o: (f64, f64), d: (f64, f64)) -> Option<f64> {
        let (ux, uy) = self.u;
        let w = (o.0 - self.circle.0, o.1 - self.circle.1);
        // Origin and direction along the sides: u, and v = u turned left.
        let (ox, oy) = (w.0 * ux + w.1 * uy, w.1 * ux - w.0 * uy);
        let (dx, dy) = (d.0 * ux + d.1 * uy, d.1 * ux - d.0 * uy);
        // Parallel to a side, 1/0 is infinite and the slab spans all or none.
        let slab = |o: f64, d: f64, h: f64| {
            let inv = 1.0 / d;
            let (a, b) = ((-h - o) * inv, (h - o) * inv);
            (a.min(b), a.max(b))
        };
        let (x0, x1) = slab(ox, dx, self.half.0);
        let (y0, y1) = slab(oy, dy, self.half.1);
        let (enter, exit) = (x0.max(y0), x1.min(y1));
        (enter <= exit && exit >= 0.0).then_some(enter.max(0.0))
    }
}

/// A circle holding every point of `polys`, whose box is `bounds`: centre
/// and radius (negative when there are no points).
fn circle_around(polys: &[Vec<(f64, f64)>], bounds: Option<[f64; 4]>) -> (f64, f64, f64) {
    let Some([x0, y0, x1, y1]) = bounds else {
        return (0.0, 0.0, -1.0);
    };
    let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
    let r2 = polys
        .iter()
        .flatten()
        .map(|&(x, y)| (x - cx).powi(2) + (y - cy).powi(2))
        .fold(0.0, f64::max);
    (cx, cy, pad(r2.sqrt()))
}

/// Radius `r` and a hair more, so that rays grazing a corner are still
/// tested exactly.
fn pad(r: f64) -> f64 {
    r * (1.0 + 1e-9) + 1e-12
}

/// Whether an edge of polygon `a` crosses an edge of polygon `b`.
fn edges_cross(a: &[(f64, f64)], b: &[(f64, f64)]) -> bool {
    let cross = |o: (f64, f64), p: (f64, f64), q: (f64, f64)| {
        (p.0 - o.0) * (q.1 - o.1) - (p.1 - o.1) * (q.0 - o.0)
    };
    edges(a).any(|(p, q)| {
        edges(b).any(|(r, s)| {
            let (d1, d2) = (cross(p, q, r), cross(p, q, s));
            let (d3, d4) = (cross(r, s, p), cross(r, s, q));
            (d1 > 0.0) != (d2 > 0.0) && (d3 > 0.0) != (d4 > 0.0)
        })
    })
}

/// The edges of a polygon, closing it: (last, first), then each point to
/// the next.
///
/// Each edge starts at the point the last one ended at: a plain loop
/// where a chained iterator asked at every edge which half it was in
/// (cave.world, whose rays meet the fancy Pioneers' edges, 1.5% faster).
fn edges(ps: &[(f64, f64)]) -> impl Iterator<Item = ((f64, f64), (f64, f64))> + '_ {
    ps.iter()
        .scan(ps.last().copied(), |a, &b| Some((a.replace(b)?, b)))
}

/// Whether point `p` is inside polygon `poly` (even-odd rule).
fn inside(poly: &[(f64, f64)], p: (f64, f64)) -> bool {
    let mut odd = false;
    for (a, b) in edges(poly) {
        if (a.1 > p.1) != (b.1 > p.1) && p.0 < a.0 + (p.1 - a.1) / (b.1 - a.1) * (b.0 - a.0) {
            odd = !odd;
        }
    }
    odd
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Tile `t` of a row of tiles.
    fn one(t: usize) -> Option<TileBox> {
        Some(TileBox {
            lo: (t, 0),
            hi: (t, 0),
        })
    }

    fn shape(polys: Vec<Vec<(f64, f64)>>) -> Body {
        let mut b = Body::default();
        b.place(&polys, Pose::default());
        b
    }

    /// [`Movers::hit`] for a ray that stops at every body and tests each
    /// afresh.
    fn hit(m: &Movers, k: usize, id: u16, o: (f64, f64), d: (f64, f64)) -> Option<Hit> {
        m.hit(k, id, (o, d, None), |_| true, |_| true)
    }

    fn square(cx: f64, cy: f64, h: f64) -> Vec<(f64, f64)> {
        vec![
            (cx - h, cy - h),
            (cx + h, cy - h),
            (cx + h, cy + h),
            (cx - h, cy + h),
        ]
    }

    /// A body of several polygons placed with its outline (its circles
    /// carried from its own frame) holds its points in its circles, and
    /// every ray meets it exactly where it meets the body placed from its
    /// points.
    #[test]
    fn an_outlined_body_is_met_where_one_placed_from_its_points_is() {
        let blocks = vec![
            square(0.3, 0.1, 0.2),
            vec![(0.0, 0.0), (0.5, 0.1), (0.2, 0.4)],
            square(-0.2, -0.3, 0.1),
        ];
        let outline = Outline::of(&blocks);
        let inside = |(x, y): (f64, f64), (cx, cy, r): (f64, f64, f64)| (x - cx).hypot(y - cy) <= r;
        let (mut met, mut rays) = (0, 0);
        for k in 0..12 {
            let at = Pose::new(1.0 + 0.1 * f64::from(k), -0.5, 0.7 * f64::from(k));
            let (mut a, mut b) = (Body::default(), Body::default());
            a.place(&blocks, at);
            b.place_outlined(&blocks, at.transform(), &outline);
            assert_eq!(a.polys(), b.polys());
            for (poly, &c) in b.polys().iter().zip(&b.poly_circles) {
                assert!(poly.iter().all(|&p| inside(p, c) && inside(p, b.circle())));
            }
            let mut m = Movers::new(2, 1, 1);
            m.file(0, 1, &mut a, one(0));
            m.file(1, 2, &mut b, one(0));
            for j in 0..72 {
                // From a ring of points 2 m out, aimed past the body's
                // middle by up to 0.45 m either side.
                let turn = f64::from(j) * 0.35;
                let o = (at.x + 2.0 * turn.cos(), at.y + 2.0 * turn.sin());
                let aim = (
                    at.x - o.0 + 0.45 * (f64::from(j % 7) - 3.0) / 3.0 * turn.sin(),
                    at.y - o.1,
                );
                let n = aim.0.hypot(aim.1);
                let d = (aim.0 / n, aim.1 / n);
                let (ha, hb) = (hit(&m, 0, 1, o, d), hit(&m, 1, 2, o, d));
                assert_eq!(
                    ha.map(|h| h.range),
                    hb.map(|h| h.range),
                    "ray {j} at {at:?}"
                );
                met += usize::from(ha.is_some());
                rays += 1;
            }
        }
        // Both hits and misses were tried.
        assert!(met > rays / 4 && met < rays, "{met} of {rays} met");
    }

    #[test]
    fn a_rectangle_carried_from_its_frame_is_the_one_its_placed_corners_make() {
        let blocks = vec![vec![(-0.05, -0.1), (0.35, -0.1), (0.35, 0.1), (-0.05, 0.1)]];
        let outline = Outline::of(&blocks);
        assert!(outline.rect.is_some());
        for k in 0..12 {
            let at = Pose::new(
                60.0 - 9.0 * f64::from(k),
                0.3 * f64::from(k),
                0.55 * f64::from(k),
            );
            let mut b = Body::default();
            b.place_outlined(&blocks, at.transform(), &outline);
            let (Some(carried), Some(made)) = (b.rect, Rect::of(&b.polys()[0])) else {
                panic!("no rectangle at {at:?}");
            };
            let near = |a: (f64, f64), b: (f64, f64)| (a.0 - b.0).abs() + (a.1 - b.1).abs() < 1e-12;
            assert!(near(carried.c, made.c) && near(carried.u, made.u), "{at:?}");
            assert!(near(carried.half, made.half), "{at:?}");
            let (cx, cy, r) = b.circle();
            assert!(
                near((cx, cy), carried.c) && (r - made.radius).abs() < 1e-12,
                "{at:?}"
            );
            // The padded circle still holds every corner placed.
            assert!(b.polys()[0].iter().all(|p| (p.0 - cx).hypot(p.1 - cy) <= r));
        }
    }

    #[test]
    fn a_crowded_tile_keeps_its_ids_in_order_in_a_list_and_back_in_place() {
        let n = INLINE + 3;
        let mut m = Movers::new(n, 2, 2);
        for k in 0..n {
            let id = k as u16 + 1;
            m.file(k, id, &mut shape(vec![square(k as f64, 0.0, 0.4)]), one(1));
        }
        let all: Vec<u16> = (1..=n as u16).collect();
        assert_eq!(m.in_tile(1), all.as_slice());
        assert_eq!(m.spilled.len(), 1);
        // Out of the middle, in order; then few enough to fit in place.
        m.unfile(2, 3);
        assert_eq!(m.in_tile(1)[..3], [1, 2, 4]);
        for k in 3..6 {
            m.unfile(k, k as u16 + 1);
        }
        assert_eq!(m.in_tile(1), [1, 2, 7, 8, 9, 10]);
        assert_eq!(m.filed[1].n, 6, "back in place");
        // The freed list serves the next crowded tile.
        for k in 2..6 {
            m.file(
                k,
                k as u16 + 1,
                &mut shape(vec![square(0.0, 0.0, 0.1)]),
                one(1),
            );
        }
        assert_eq!(m.in_tile(1).len(), 10);
        assert_eq!(m.spilled.len(), 1);
        for k in 0..n {
            m.unfile(k, k as u16 + 1);
        }
        assert!(m.in_tile(1).is_empty() && m.in_tile(0).is_empty());
    }

    #[test]
    fn bodies_overlap_when_they_cross_or_contain() {
        let mut m = Movers::new(2, 1, 1);
        m.file(0, 1, &mut shape(vec![square(0.0, 0.0, 0.5)]), one(0));
        assert!(
            m.overlaps(0, &shape(vec![square(0.9, 0.0, 0.5)])),
            "edges cross"
        );
        assert!(
            m.overlaps(0, &shape(vec![square(0.1, 0.1, 0.1)])),
            "inside it"
        );
        assert!(
            m.overlaps(0, &shape(vec![square(0.0, 0.0, 3.0)])),
            "around it"
        );
        assert!(!m.overlaps(0, &shape(vec![square(1.1, 0.0, 0.5)])), "apart");
        // Diagonal neighbours whose boxes overlap but bodies do not.
        let diamond = vec![(1.0, 0.4), (1.5, 0.9), (1.0, 1.4), (0.5, 0.9)];
        assert!(!m.overlaps(0, &shape(vec![diamond])));
        // Bodies of several polygons: tested pair by pair, whatever the
        // circles around the whole bodies say.
        let mut two = shape(vec![square(10.0, 0.0, 0.5), square(13.0, 0.0, 0.5)]);
        m.file(1, 2, &mut two, one(0));
        let near = shape(vec![square(13.8, 0.0, 0.5), square(20.0, 0.0, 0.5)]);
        assert!(m.overlaps(1, &near), "second polygons cross");
        let far = shape(vec![square(14.2, 0.0, 0.5), square(20.0, 0.0, 0.5)]);
        assert!(!m.overlaps(1, &far), "every pair apart");
        let held = shape(vec![square(20.0, 0.0, 0.5), square(13.0, 0.1, 0.1)]);
        assert!(m.overlaps(1, &held), "a polygon inside another");
        m.unfile(0, 1);
        assert!(
            !m.overlaps(0, &shape(vec![square(0.0, 0.0, 3.0)])),
            "unfiled"
        );
    }

    #[test]
    fn rays_meet_filed_bodies_exactly() {
        let mut m = Movers::new(3, 4, 4);
        let tiles = TileBox {
            lo: (1, 0),
            hi: (3, 0),
        };
        m.file(1, 2, &mut shape(vec![square(2.0, 0.0, 0.5)]), Some(tiles));
        for t in 1..=3 {
            assert_eq!(m.in_tile(t), &[2]);
        }
        assert!(m.in_tile(0).is_empty() && m.in_tile(99).is_empty());
        let h = hit(&m, 1, 2, (0.0, 0.0), (1.0, 0.0)).unwrap();
        assert!((h.range - 1.5).abs() < 1e-12 && h.id == 2);
        // A ray that does not stop at the body passes through it.
        assert!(m
            .hit(1, 2, ((0.0, 0.0), (1.0, 0.0), None), |id| id != 2, |_| true)
            .is_none());
        // Diagonal: enters the square's lower left corner region.
        let s = std::f64::consts::FRAC_1_SQRT_2;
        let h = hit(&m, 1, 2, (1.0, -1.0), (s, s)).unwrap();
        assert!((h.range - 0.5f64.hypot(0.5)).abs() < 1e-9, "{}", h.range);
        assert!(hit(&m, 1, 2, (0.0, 0.0), (-1.0, 0.0)).is_none(), "behind");
        assert!(hit(&m, 1, 2, (0.0, 0.0), (0.0, 1.0)).is_none(), "beside");
        assert_eq!(hit(&m, 1, 2, (2.1, 0.2), (1.0, 0.0)).unwrap().range, 0.0);
        // Moved within its box of tiles: filed where it was, met where it is.
        m.file(1, 2, &mut shape(vec![square(2.5, 0.0, 0.5)]), Some(tiles));
        assert!((1..=3).all(|t| m.in_tile(t) == [2]) && m.in_tile(0).is_empty());
        assert!((hit(&m, 1, 2, (0.0, 0.0), (1.0, 0.0)).unwrap().range - 2.0).abs() < 1e-12);
        // Moving re-files; unfiling empties the tiles.
        m.file(1, 2, &mut shape(vec![square(5.0, 0.0, 0.5)]), one(0));
        assert!(m.in_tile(3).is_empty() && m.in_tile(0) == [2]);
        assert!((hit(&m, 1, 2, (0.0, 0.0), (1.0, 0.0)).unwrap().range - 4.5).abs() < 1e-12);
        m.unfile(1, 2);
        assert!(m.in_tile(0).is_empty() && hit(&m, 1, 2, (0.0, 0.0), (1.0, 0.0)).is_none());
    }

    #[test]
    fn rays_meet_rectangles_and_other_polygons_exactly() {
        // A rotated rectangle (tested in its own frame, either winding) and
        // a kite (tested edge by edge); rays from all around, most near
        // their corners, against the edges alone.
        let rect = vec![(1.0, 0.2), (1.8, 0.6), (1.5, 1.2), (0.7, 0.8)];
        let mut clockwise = rect.clone();
        clockwise.reverse();
        let kite = vec![(1.0, 0.2), (1.9, 0.5), (1.5, 1.2), (0.7, 0.8)];
        for (body, is_rect) in [(rect, true), (clockwise, true), (kite, false)] {
            let mut m = Movers::new(1, 1, 1);
            m.file(0, 1, &mut shape(vec![body.clone()]), one(0));
            assert_eq!(m.bodies[0].rect.is_some(), is_rect, "{body:?}");
            let mut x: u32 = 3;
            let mut rnd = || {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                f64::from(x) / f64::from(u32::MAX)
            };
            let mut hits = 0;
            for _ in 0..5000 {
                let o = (rnd() * 4.0 - 1.0, rnd() * 4.0 - 1.5);
                let (tx, ty) = body[(rnd() * 4.0) as usize % 4];
                let a = (ty - o.1).atan2(tx - o.0) + (rnd() - 0.5) * 0.2;
                let d = (a.cos(), a.sin());
                let mut exact = f64::INFINITY;
                for (p, q) in edges(&body) {
                    let e = (q.0 - p.0, q.1 - p.1);
                    let den = d.0 * e.1 - d.1 * e.0;
                    let w = (p.0 - o.0, p.1 - o.1);
                    let (t, u) = ((w.0 * e.1 - w.1 * e.0) / den, (w.0 * d.1 - w.1 * d.0) / den);
                    if (0.0..1.0).contains(&u) && t >= 0.0 {
                        exact = exact.min(t);
                    }
                }
                let got = hit(&m, 0, 1, o, d).map(|h| h.range);
                if inside(&body, o) {
                    assert_eq!(got, Some(0.0));
                } else if exact.is_finite() {
                    hits += 1;
                    assert!((got.unwrap() - exact).abs() < 1e-12, "{o:?} {a}");
                } else {
                    assert_eq!(got, None, "{o:?} {a}");
                }
            }
            assert!(hits > 1000, "{hits}");
        }
    }

    #[test]
    fn a_ray_along_a_rectangles_side_line_is_judged_by_its_offset() {
        let mut m = Movers::new(1, 1, 1);
        m.file(0, 1, &mut shape(vec![square(2.0, 0.0, 0.5)]), one(0));
        assert!(m.bodies[0].rect.is_some());
        // Parallel to the sides: through the middle, just inside and just
        // outside the side at y = 0.5.
        assert!((hit(&m, 0, 1, (0.0, 0.0), (1.0, 0.0)).unwrap().range - 1.5).abs() < 1e-12);
        assert!((hit(&m, 0, 1, (0.0, 0.49), (1.0, 0.0)).unwrap().range - 1.5).abs() < 1e-12);
        assert!(hit(&m, 0, 1, (0.0, 0.51), (1.0, 0.0)).is_none());
        assert!(
            hit(&m, 0, 1, (2.0, 0.51), (0.0, 1.0)).is_none(),
            "above, going away"
        );
        assert!((hit(&m, 0, 1, (2.0, 1.5), (0.0, -1.0)).unwrap().range - 1.0).abs() < 1e-12);
    }

    #[test]
    fn the_fast_angle_is_within_its_bound() {
        for k in 0..100_000 {
            let a = -std::f64::consts::PI + std::f64::consts::TAU * f64::from(k) / 100_000.0;
            for len in [1e-3, 1.0, 1e3] {
                let (y, x) = (len * a.sin(), len * a.cos());
                let err = (atan2(y, x) - y.atan2(x)).abs();
                // (±π are the same direction.)
                assert!(
                    err < 2e-6 || (err - std::f64::consts::TAU).abs() < 2e-6,
                    "{a}: {err}"
                );
            }
        }
        assert_eq!(atan2(0.0, 0.0), 0.0);
    }

    /// Every ray of a fan that passes through a body's circle, within reach,
    /// is offered that body: fans of every width and heading, bodies all
    /// around them, near and far, some holding the origin.
    #[test]
    fn a_sweep_offers_each_ray_the_bodies_it_may_meet() {
        let mut x = 7u32;
        let mut rnd = move || {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            f64::from(x) / f64::from(u32::MAX)
        };
        let mut sweep = Sweep::default();
        let (mut offered, mut needed) = (0, 0);
        for round in 0..300 {
            let mut m = Movers::new(40, 1, 1);
            for k in 0..40 {
                let (cx, cy) = (rnd() * 12.0 - 6.0, rnd() * 12.0 - 6.0);
                m.file(
                    k,
                    k as u16 + 1,
                    &mut shape(vec![square(cx, cy, 0.05 + rnd() * 0.4)]),
                    one(0),
                );
            }
            let n = 2 + (rnd() * 200.0) as usize;
            let width = [0.3, 1.0, std::f64::consts::PI, 4.7, std::f64::consts::TAU][round % 5];
            let heading = rnd() * 20.0 - 10.0;
            let fan = Fan {
                o: (rnd() * 2.0 - 1.0, rnd() * 2.0 - 1.0),
                first: (heading.cos(), heading.sin()),
                step: width / (n - 1) as f64,
                n,
                reach: 1.0 + rnd() * 6.0,
            };
            // Odd bodies are not wanted.
            sweep.start(&m, &fan, |id| id % 2 == 0);
            for k in 0..n {
                let got: Vec<u16> = sweep.at(k).collect();
                offered += got.len();
                let a = heading + k as f64 * fan.step;
                let d = (a.cos(), a.sin());
                for i in 0..40 {
                    let (cx, cy, r) = m.bodies[i].circle;
                    let w = (cx - fan.o.0, cy - fan.o.1);
                    let along = w.0 * d.0 + w.1 * d.1;
                    let across = (w.0 * d.1 - w.1 * d.0).abs();
                    let inside = w.0.hypot(w.1) <= r;
                    let passes = inside || (across <= r && along >= 0.0);
                    let near = w.0.hypot(w.1) - r <= fan.reach;
                    let id = i as u16 + 1;
                    if passes && near && id % 2 == 0 {
                        needed += 1;
                        assert!(
                            got.contains(&id),
                            "round {round}, ray {k}: body {id} missing"
                        );
                    }
                    assert!(id % 2 == 0 || !got.contains(&id), "body {id} not wanted");
                }
            }
        }
        // Runs are tight: few rays are offered a body they pass by.
        assert!(
            needed > 1000 && offered < needed * 21 / 20,
            "{offered} offered, {needed} needed"
        );
    }
}
