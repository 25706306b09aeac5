//! Global path planning on an occupancy map, pure.
//!
//! The configuration space: every cell's distance to the nearest obstacle
//! (occupied or unknown), capped at `max_radius`. Cells closer than the
//! robot's radius plus `safety_dist` are blocked. A step costs its length
//! plus `dist_penalty · (max_radius − distance)` near obstacles, so paths
//! keep clear of walls — Player's wavefront cost. Player floods the whole
//! map from the goal; this searches from the start with A* (the Euclidean
//! distance is a lower bound on that cost), which finds a path of the same
//! cost and touches a fraction of the cells. On large maps A* runs on a
//! grid of 4×4 blocks first, then on the cells of a corridor around that
//! route ([`Planner::plan`]).
//!
//! [`Planner::waypoints`] turns a path into waypoints as Player's does:
//! the start cell, then each farthest path cell still in line of sight
//! (through unblocked cells), the first 0.5 m taken without looking, and
//! the goal cell last.

use troupe_geom::occmap::OccMap;
use troupe_msgs::map;

/// Planning parameters (metres).
#[derive(Debug, Clone, Copy)]
pub struct Params {
    /// Robot radius plus safety distance: cells closer to an obstacle are blocked.
    pub min_radius: f64,
    /// Obstacle distances are capped here; the penalty vanishes beyond.
    pub max_radius: f64,
    /// Weight of the obstacle-proximity cost.
    pub dist_penalty: f64,
}

/// Why there is no path.
#[derive(Debug, Clone, PartialEq)]
pub enum NoPath {
    /// The start is off the map.
    StartOff,
    /// The goal is off the map.
    GoalOff,
    /// The goal lies in an obstacle or too close to one.
    GoalBlocked,
    /// Nothing connects start and goal.
    Unreachable,
}

impl std::fmt::Display for NoPath {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            NoPath::StartOff => "the start is off the map",
            NoPath::GoalOff => "the goal is off the map",
            NoPath::GoalBlocked => "the goal is in or too close to an obstacle",
            NoPath::Unreachable => "no path connects the start to the goal",
        })
    }
}

impl std::error::Error for NoPath {}

/// The open set: a radix heap on the bits of non-negative `f32` keys (their
/// order as integers is their order as numbers). A* with a consistent
/// heuristic pops keys that never decrease, which is all a radix heap asks;
/// a push and a pop cost O(1) amortized instead of a binary heap's O(log n).
struct RadixHeap {
    /// The last key popped; every key held is at least this.
    last: u32,
    /// Bucket b holds keys whose highest bit differing from `last` is b − 1
    /// (bucket 0: equal to `last`).
    buckets: [Vec<(u32, u32)>; 33],
    len: usize,
}

impl Default for RadixHeap {
    fn default() -> Self {
        RadixHeap {
            last: 0,
            buckets: std::array::from_fn(|_| Vec::new()),
            len: 0,
        }
    }
}

impl RadixHeap {
    fn clear(&mut self) {
        for b in &mut self.buckets {
            b.clear();
        }
        self.last = 0;
        self.len = 0;
    }

    fn bucket(&self, key: u32) -> usize {
        32 - (key ^ self.last).leading_zeros() as usize
    }

    /// Pushes `value` at `key`; a key below the last popped (rounding in a
    /// sum) is taken as the last.
    fn push(&mut self, key: f32, value: u32) {
        let k = key.max(0.0).to_bits().max(self.last);
        let b = self.bucket(k);
        self.buckets[b].push((k, value));
        self.len += 1;
    }

    /// The entry with the least key: (key, value).
    fn pop(&mut self) -> Option<(f32, u32)> {
        if self.len == 0 {
            return None;
        }
        if self.buckets[0].is_empty() {
            let i = self.buckets.iter().position(|b| !b.is_empty())?;
            let items = std::mem::take(&mut self.buckets[i]);
            self.last = items.iter().map(|&(k, _)| k).min()?;
            for &(k, v) in &items {
                let b = self.bucket(k);
                self.buckets[b].push((k, v));
            }
            // Keep the allocation for the next time this bucket fills.
            let mut items = items;
            items.clear();
            if self.buckets[i].is_empty() {
                self.buckets[i] = items;
            }
        }
        let (k, v) = self.buckets[0].pop()?;
        self.len -= 1;
        Some((f32::from_bits(k), v))
    }
}

/// A planner over one map.
pub struct Planner {
    /// The map's size, resolution and origin.
    info: map::Info,
    params: Params,
    /// The full-resolution grid.
    fine: Grid,
    /// A grid of [`COARSE`]² blocks of cells, for large maps: a path on it
    /// marks the corridor the fine search keeps to.
    coarse: Option<Grid>,
    heap: RadixHeap,
}

/// Maps with more cells than this are searched coarse, then fine.
const COARSE_ABOVE: usize = 500 * 500;
/// Coarse cells are this many fine cells on a side (a power of two).
const COARSE: usize = 4;

/// The index of the [`COARSE`]² block holding cell (i, j), in a grid of
/// blocks `width` blocks wide.
fn block_of(i: usize, j: usize, width: usize) -> usize {
    (j / COARSE) * width + i / COARSE
}
/// The corridor reaches this many coarse cells to each side of the coarse path.
const CORRIDOR: i64 = 2;

const NONE: u32 = u32::MAX;

/// One cell as the search sees it.
#[derive(Clone, Copy)]
struct Cell {
    /// Cost from the start, valid when `stamp` is the search's generation.
    g: f32,
    /// The generation that set `g` and `parent` (no clearing between plans).
    stamp: u32,
    parent: u32,
    /// What entering the cell costs beyond the step's length: the
    /// proximity penalty, infinite where the cell is blocked.
    enter: f32,
}

impl Cell {
    /// True when no path may enter the cell.
    fn blocked(&self) -> bool {
        self.enter == f32::INFINITY
    }
}

/// A grid the search runs on: its cells (one 16-byte record each, so a
/// step to a neighbour touches one cache line), their size in metres, and
/// the generation that tells this search's records from older ones.
struct Grid {
    cells: Vec<Cell>,
    width: usize,
    height: usize,
    res: f32,
    generation: u32,
}

impl Grid {
    fn new(enter: impl Iterator<Item = f32>, width: usize, height: usize, res: f32) -> Grid {
        let cells = enter
            .map(|enter| Cell {
                g: 0.0,
                stamp: 0,
                parent: NONE,
                enter,
            })
            .collect();
        Grid {
            cells,
            width,
            height,
            res,
            generation: 0,
        }
    }

    /// A grid of [`COARSE`]² blocks: a block may be entered when any of
    /// its cells may, at the least penalty among them. Every path on `fine`
    /// crosses a chain of such blocks, so no path on the fine grid is
    /// missed by this one.
    fn coarsen(fine: &Grid) -> Grid {
        let (w, h) = (fine.width.div_ceil(COARSE), fine.height.div_ceil(COARSE));
        let mut enter = vec![f32::INFINITY; w * h];
        for (n, c) in fine.cells.iter().enumerate() {
            let e = &mut enter[block_of(n % fine.width, n / fine.width, w)];
            *e = e.min(c.enter);
        }
        Grid::new(enter.into_iter(), w, h, fine.res * COARSE as f32)
    }

    /// The next search's generation.
    fn next_generation(&mut self) -> u32 {
        self.generation = self.generation.wrapping_add(1);
        if self.generation == 0 {
            for c in &mut self.cells {
                c.stamp = 0;
            }
            self.generation = 1;
        }
        self.generation
    }

    /// A*: the cheapest path of cells from `s` to `t` through cells that
    /// `allowed` admits, `None` when there is none. A step costs its length
    /// plus the entered cell's penalty; the octile distance to `t` is the
    /// heuristic (a lower bound on the lengths alone).
    fn search(
        &mut self,
        heap: &mut RadixHeap,
        s: usize,
        t: usize,
        allowed: impl Fn(i64, i64) -> bool,
    ) -> Option<Vec<usize>> {
        let gen = self.next_generation();
        let w = self.width as i64;
        let (tx, ty) = ((t % self.width) as i64, (t / self.width) as i64);
        let res = self.res;
        // Octile distance from cell (i, j) to the goal: a lower bound on the
        // step lengths (no division: cells are passed as coordinates).
        let h = |i: i64, j: i64| -> f32 {
            let dx = (i - tx).abs() as f32;
            let dy = (j - ty).abs() as f32;
            (dx.max(dy) + (std::f32::consts::SQRT_2 - 1.0) * dx.min(dy)) * res
        };
        heap.clear();
        let start = &mut self.cells[s];
        (start.stamp, start.g, start.parent) = (gen, 0.0, NONE);
        let (si, sj) = ((s % self.width) as i64, (s / self.width) as i64);
        heap.push(h(si, sj), s as u32);
        const STEPS: [(i64, i64, f32); 8] = [
            (-1, -1, std::f32::consts::SQRT_2),
            (0, -1, 1.0),
            (1, -1, std::f32::consts::SQRT_2),
            (-1, 0, 1.0),
            (1, 0, 1.0),
            (-1, 1, std::f32::consts::SQRT_2),
            (0, 1, 1.0),
            (1, 1, std::f32::consts::SQRT_2),
        ];
        let height = self.height as i64;
        while let Some((f, cell)) = heap.pop() {
            let c = cell as usize;
            let gc = self.cells[c].g;
            let (ci, cj) = ((c % self.width) as i64, (c / self.width) as i64);
            if f > gc + h(ci, cj) + 1e-4 {
                continue; // a stale entry
            }
            if c == t {
                let mut path = vec![t];
                let mut k = t;
                while self.cells[k].parent != NONE {
                    k = self.cells[k].parent as usize;
                    path.push(k);
                }
                path.reverse();
                return Some(path);
            }
            for &(di, dj, len) in &STEPS {
                let (ni, nj) = (ci + di, cj + dj);
                if ni < 0 || nj < 0 || ni >= w || nj >= height || !allowed(ni, nj) {
                    continue;
                }
                let n = (nj * w + ni) as usize;
                let next = &mut self.cells[n];
                if next.blocked() {
                    continue;
                }
                let cost = gc + len * res + next.enter;
                if next.stamp != gen || cost < next.g {
                    (next.stamp, next.g, next.parent) = (gen, cost, c as u32);
                    heap.push(cost + h(ni, nj), n as u32);
                }
            }
        }
        None
    }
}

impl Planner {
    /// Builds the configuration space of `map`.
    pub fn new(map: &OccMap, params: Params) -> Self {
        let (width, height) = map.size();
        let maxr = params.max_radius as f32;
        let min_r = params.min_radius;
        let field = map.distance_field();
        let enter = field.into_iter().map(|d| {
            let d = d.min(maxr);
            if f64::from(d) < min_r {
                f32::INFINITY
            } else if d < maxr {
                (params.dist_penalty * f64::from(maxr - d)) as f32
            } else {
                0.0
            }
        });
        let fine = Grid::new(enter, width, height, map.info.resolution);
        let coarse = (width * height > COARSE_ABOVE).then(|| Grid::coarsen(&fine));
        Planner {
            info: map.info,
            params,
            fine,
            coarse,
            heap: RadixHeap::default(),
        }
    }

    /// The parameters.
    pub fn params(&self) -> &Params {
        &self.params
    }

    /// The cell of world point (x, y) as Player's planner takes it: the
    /// nearest cell corner (plan.h's PLAN_GXWX rounds; its PLAN_WXGX puts
    /// cell i at origin + i × scale), so that a client gets the waypoints
    /// Player gave: (-6.961, -6.951) on the cave's map is (-6.976, -6.944).
    fn cell(&self, x: f64, y: f64) -> Option<usize> {
        let s = self.res();
        let (w, h) = (self.info.width as usize, self.info.height as usize);
        let i = ((x - self.info.origin.x) / s + 0.5).floor();
        let j = ((y - self.info.origin.y) / s + 0.5).floor();
        if !(i >= 0.0 && j >= 0.0 && (i as usize) < w && (j as usize) < h) {
            return None;
        }
        Some(j as usize * w + i as usize)
    }

    /// The world point of cell `k`, as Player's planner places it (see
    /// [`Planner::cell`]).
    pub fn point(&self, k: usize) -> (f64, f64) {
        let (s, w) = (self.res(), self.info.width as usize);
        (
            self.info.origin.x + (k % w) as f64 * s,
            self.info.origin.y + (k / w) as f64 * s,
        )
    }

    fn res(&self) -> f64 {
        f64::from(self.info.resolution)
    }

    /// True where the robot may be: not within `min_radius` of an obstacle.
    fn free(&self, k: usize) -> bool {
        !self.fine.cells[k].blocked()
    }

    /// The cheapest path of cells from `start` to `goal` (world points).
    /// The start cell may be inside the safety margin (the robot is where
    /// it is); the goal may not.
    ///
    /// On a large map the search runs twice: first on the coarse grid,
    /// whose path marks a corridor a few blocks wide; then on the fine grid
    /// within that corridor. The path is then the cheapest within the
    /// corridor, which is the cheapest overall unless a cheaper route
    /// strays outside it; a goal the corridor cannot reach is searched for
    /// over the whole map. No coarse path means no path at all.
    ///
    /// # Errors
    ///
    /// [`NoPath`] says why there is none.
    pub fn plan(&mut self, start: (f64, f64), goal: (f64, f64)) -> Result<Vec<usize>, NoPath> {
        let s = self.cell(start.0, start.1).ok_or(NoPath::StartOff)?;
        let t = self.cell(goal.0, goal.1).ok_or(NoPath::GoalOff)?;
        if !self.free(t) && s != t {
            return Err(NoPath::GoalBlocked);
        }
        if let Some(coarse) = &mut self.coarse {
            let w = self.fine.width;
            let block = |k: usize| block_of(k % w, k / w, coarse.width);
            let route = coarse
                .search(&mut self.heap, block(s), block(t), |_, _| true)
                .ok_or(NoPath::Unreachable)?;
            // The corridor: blocks within CORRIDOR of the route, stamped
            // with a generation of their own.
            let mark = coarse.next_generation();
            let (cw, ch) = (coarse.width as i64, coarse.height as i64);
            for &b in &route {
                let (bi, bj) = ((b % coarse.width) as i64, (b / coarse.width) as i64);
                for j in (bj - CORRIDOR).max(0)..=(bj + CORRIDOR).min(ch - 1) {
                    for i in (bi - CORRIDOR).max(0)..=(bi + CORRIDOR).min(cw - 1) {
                        coarse.cells[(j * cw + i) as usize].stamp = mark;
                    }
                }
            }
            let blocks = &coarse.cells;
            let inside = |i: i64, j: i64| {
                // (The search asks only of cells on the map: i, j ≥ 0.)
                blocks[block_of(i as usize, j as usize, coarse.width)].stamp == mark
            };
            if let Some(path) = self.fine.search(&mut self.heap, s, t, inside) {
                return Ok(path);
            }
        }
        self.fine
            .search(&mut self.heap, s, t, |_, _| true)
            .ok_or(NoPath::Unreachable)
    }

    /// True when the straight line between cells `a` and `b` crosses only
    /// unblocked cells.
    pub fn visible(&self, a: usize, b: usize) -> bool {
        let (ax, ay) = ((a % self.fine.width) as f64, (a / self.fine.width) as f64);
        let (bx, by) = ((b % self.fine.width) as f64, (b / self.fine.width) as f64);
        let n = (bx - ax).abs().max((by - ay).abs()).ceil() as usize * 2;
        (0..=n).all(|s| {
            let t = if n == 0 { 0.0 } else { s as f64 / n as f64 };
            let i = (ax + (bx - ax) * t + 0.5).floor() as usize;
            let j = (ay + (by - ay) * t + 0.5).floor() as usize;
            self.free(j * self.fine.width + i)
        })
    }

    /// Waypoints (world points) along `path`, Player's way: from each
    /// waypoint, the first 0.5 m of path is taken without looking, then the
    /// next waypoint is the farthest path cell still in sight. Player tries
    /// the cells one by one; this gallops (1, 2, 4… cells on) to the first
    /// one out of sight, then halves the gap, so a long straight corridor
    /// costs a few sight lines instead of one per cell. Every waypoint is
    /// in sight of the one before.
    pub fn waypoints(&self, path: &[usize]) -> Vec<(f64, f64)> {
        let Some(&first) = path.first() else {
            return Vec::new();
        };
        let seen = |from: usize, k: usize| self.visible(path[from], path[k]);
        let blind = (0.5 / self.res()).floor() as usize + 1;
        let mut out = vec![self.point(first)];
        let mut at = 0;
        while at + 1 < path.len() {
            let mut k = (at + blind).min(path.len() - 1);
            if k + 1 < path.len() && seen(at, k + 1) {
                // `lo` in sight; `hi` out of sight, or past the end.
                let (mut lo, mut step) = (k + 1, 1);
                let mut hi = loop {
                    let next = lo + step;
                    if next >= path.len() {
                        break path.len();
                    }
                    if !seen(at, next) {
                        break next;
                    }
                    lo = next;
                    step *= 2;
                };
                while hi - lo > 1 {
                    let mid = lo + (hi - lo) / 2;
                    if seen(at, mid) {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                k = lo;
            }
            at = k;
            out.push(self.point(path[at]));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use troupe_geom::occmap::{FREE, OCCUPIED};
    use troupe_msgs::Pose2d;

    /// 10 m × 10 m at 0.1 m, a wall across the middle with a gap at the right.
    fn walled() -> OccMap {
        let info = map::Info {
            width: 100,
            height: 100,
            resolution: 0.1,
            origin: Pose2d::new(0.0, 0.0, 0.0),
        };
        OccMap::from_fn(info, |i, j| {
            if i < 80 && (j == 50 || j == 51) {
                OCCUPIED
            } else {
                FREE
            }
        })
    }

    fn params() -> Params {
        Params {
            min_radius: 0.4,
            max_radius: 1.0,
            dist_penalty: 1.0,
        }
    }

    #[test]
    fn goes_round_the_wall_and_keeps_clear() {
        let m = walled();
        let mut p = Planner::new(&m, params());
        let path = p.plan((1.0, 2.0), (1.0, 8.0)).unwrap();
        let dist = m.distance_field();
        for &k in &path[1..] {
            assert!(dist[k] >= 0.4, "path cell {k} too close: {}", dist[k]);
        }
        // Through the gap (x > 8 m).
        assert!(path.iter().any(|&k| p.point(k).0 > 8.0));
        let wps = p.waypoints(&path);
        assert!(wps.len() >= 3 && wps.len() < 10, "{wps:?}");
        assert_eq!(wps[0], p.point(path[0]));
        assert_eq!(*wps.last().unwrap(), p.point(*path.last().unwrap()));
        // Each leg is in line of sight after the first half metre.
        for w in wps.windows(2).skip(1) {
            let a = p.cell(w[0].0, w[0].1).unwrap();
            let b = p.cell(w[1].0, w[1].1).unwrap();
            assert!(p.visible(a, b), "{w:?}");
        }
    }

    /// Player 3.1's wavefront in cpp-planner-localize's transcript (the
    /// cave's map, 0.032 m cells from (-8, -8)): from amcl's estimate
    /// (-6.96113, -6.951) to the goal (-4.5, -5.5), GET_WAYPOINTS answered
    /// [(-6.976, -6.944), (-4.512, -5.504)], 2.85393 m. The same points,
    /// on an open map of that grid.
    #[test]
    fn waypoints_sit_where_player_s_planner_puts_them() {
        let info = map::Info {
            width: 500,
            height: 500,
            resolution: 0.032,
            origin: Pose2d::new(-8.0, -8.0, 0.0),
        };
        let m = OccMap::from_fn(info, |_, _| FREE);
        let mut p = Planner::new(
            &m,
            Params {
                min_radius: 0.19 + 0.15,
                ..params()
            },
        );
        let path = p.plan((-6.96113, -6.951), (-4.5, -5.5)).unwrap();
        let wps = p.waypoints(&path);
        let near =
            |a: (f64, f64), b: (f64, f64)| (a.0 - b.0).abs() < 1e-6 && (a.1 - b.1).abs() < 1e-6;
        assert_eq!(wps.len(), 2, "{wps:?}");
        assert!(near(wps[0], (-6.976, -6.944)), "{wps:?}");
        assert!(near(wps[1], (-4.512, -5.504)), "{wps:?}");
        let length = (wps[1].0 - wps[0].0).hypot(wps[1].1 - wps[0].1);
        assert!((length - 2.85393).abs() < 5e-6, "{length}");
        // A point just right of a cell's corner, and just left, are that corner's.
        assert_eq!(p.cell(-8.0 + 0.032 * 10.0 + 0.015, -8.0), Some(10));
        assert_eq!(p.cell(-8.0 + 0.032 * 10.0 - 0.015, -8.0), Some(10));
        assert_eq!(p.cell(-8.02, -8.0), None);
    }

    #[test]
    fn the_radix_heap_pops_in_order() {
        let mut q = RadixHeap::default();
        assert_eq!(q.pop(), None);
        // Pseudo-random keys, with pushes between pops at or above the last
        // key popped, as A* makes them.
        let mut x = 12345u32;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            (x % 10_000) as f32 * 0.37
        };
        for i in 0..500 {
            q.push(next(), i);
        }
        let (mut last, mut popped) = (0.0f32, 0);
        while let Some((k, _)) = q.pop() {
            assert!(k >= last, "{k} after {last}");
            last = k;
            popped += 1;
            if popped % 3 == 0 && popped < 900 {
                q.push(last + next() * 0.01, popped);
                q.push(last, popped); // equal keys are fine
            }
        }
        assert!(popped > 500);
        // A key a rounding error below the last is taken as the last.
        q.push(last - 1e-3, 7);
        assert_eq!(q.pop(), Some((last, 7)));
        q.clear();
        assert_eq!(q.pop(), None);
    }

    #[test]
    fn same_cost_as_a_full_flood() {
        // Dijkstra from the goal over the whole map (Player's flood) gives
        // the same cost to the start as A*.
        let m = walled();
        let mut p = Planner::new(&m, params());
        let path = p.plan((2.0, 1.5), (3.0, 9.0)).unwrap();
        // flood[n]: cheapest cost from n to the goal, a step into k costing
        // its length plus k's penalty, as A* counts it.
        let mut flood = vec![f32::INFINITY; 10_000];
        let goal = p.cell(3.0, 9.0).unwrap();
        let start = path[0];
        flood[goal] = 0.0;
        let mut changed = true;
        while changed {
            changed = false;
            for k in 0..10_000usize {
                if !flood[k].is_finite() {
                    continue;
                }
                let (i, j) = ((k % 100) as i64, (k / 100) as i64);
                for (di, dj) in (-1..=1i64).flat_map(|a| (-1..=1i64).map(move |b| (a, b))) {
                    let (ni, nj) = (i + di, j + dj);
                    if (di, dj) == (0, 0) || !(0..100).contains(&ni) || !(0..100).contains(&nj) {
                        continue;
                    }
                    let n = (nj * 100 + ni) as usize;
                    if !p.free(n) && n != start {
                        continue;
                    }
                    let len = if di != 0 && dj != 0 {
                        std::f32::consts::SQRT_2
                    } else {
                        1.0
                    };
                    let c = flood[k] + len * 0.1 + p.fine.cells[k].enter;
                    if c + 1e-5 < flood[n] {
                        flood[n] = c;
                        changed = true;
                    }
                }
            }
        }
        let (a, f) = (path_cost(&p.fine, &path), flood[start]);
        assert!((a - f).abs() < 1e-3 * a, "A* {a} vs flood {f}");
    }

    /// 32 m × 32 m at 0.05 m (over the coarse threshold): four rows of
    /// rooms, walls with doors at different places, so routes zigzag.
    fn building(doors: bool) -> OccMap {
        let info = map::Info {
            width: 640,
            height: 640,
            resolution: 0.05,
            origin: Pose2d::new(0.0, 0.0, 0.0),
        };
        OccMap::from_fn(info, |i, j| {
            let wall = j % 160 == 80 && j < 560;
            let door = doors && (i as i64 - if j % 320 == 80 { 560 } else { 80 }).abs() < 20;
            if wall && !door {
                OCCUPIED
            } else {
                FREE
            }
        })
    }

    fn path_cost(g: &Grid, path: &[usize]) -> f32 {
        path.windows(2)
            .map(|w| {
                let (a, b) = (w[0] as i64, w[1] as i64);
                let straight = (a - b).abs() == 1 || (a - b).abs() == g.width as i64;
                let len = if straight {
                    1.0
                } else {
                    std::f32::consts::SQRT_2
                };
                len * g.res + g.cells[w[1]].enter
            })
            .sum()
    }

    #[test]
    fn large_maps_plan_coarse_then_fine_at_the_cost_of_a_full_search() {
        let mut p = Planner::new(&building(true), params());
        assert!(p.coarse.is_some());
        let (a, b) = ((2.0, 2.0), (30.0, 30.0));
        let path = p.plan(a, b).unwrap();
        let (s, t) = (p.cell(a.0, a.1).unwrap(), p.cell(b.0, b.1).unwrap());
        assert_eq!((path[0], *path.last().unwrap()), (s, t));
        // Consecutive cells are neighbours, and none is blocked.
        assert!(path.windows(2).all(|w| {
            let (i0, j0) = ((w[0] % 640) as i64, (w[0] / 640) as i64);
            let (i1, j1) = ((w[1] % 640) as i64, (w[1] / 640) as i64);
            (i0 - i1).abs() <= 1 && (j0 - j1).abs() <= 1 && p.free(w[1])
        }));
        let full = p.fine.search(&mut p.heap, s, t, |_, _| true).unwrap();
        let (got, best) = (path_cost(&p.fine, &path), path_cost(&p.fine, &full));
        assert!(got <= best * 1.001, "corridor {got} vs full {best}");
        // The waypoints see each other.
        let wps = p.waypoints(&path);
        let cells: Vec<usize> = wps.iter().map(|w| p.cell(w.0, w.1).unwrap()).collect();
        assert!(cells.windows(2).all(|w| p.visible(w[0], w[1])));
        assert!(
            wps.len() >= 5,
            "{} waypoints: start, 3 doors, goal",
            wps.len()
        );
        // Walls without doors: no coarse route, so no path.
        let mut p = Planner::new(&building(false), params());
        assert_eq!(p.plan(a, b), Err(NoPath::Unreachable));
    }

    #[test]
    fn unreachable_blocked_and_off_map_goals_say_why() {
        let mut m = walled();
        for i in 80..100 {
            m.cells[50 * 100 + i] = OCCUPIED;
        }
        let mut p = Planner::new(&m, params());
        assert_eq!(p.plan((1.0, 2.0), (1.0, 8.0)), Err(NoPath::Unreachable));
        assert_eq!(p.plan((1.0, 2.0), (5.0, 5.05)), Err(NoPath::GoalBlocked));
        assert_eq!(p.plan((1.0, 2.0), (11.0, 8.0)), Err(NoPath::GoalOff));
        assert_eq!(p.plan((-1.0, 2.0), (1.0, 3.0)), Err(NoPath::StartOff));
        // A start inside the margin still plans out of it.
        let path = p.plan((0.05, 2.0), (2.0, 2.0)).unwrap();
        assert!(path.len() > 10);
        assert_eq!(p.plan((2.0, 2.0), (2.0, 2.0)).unwrap().len(), 1);
    }
}
