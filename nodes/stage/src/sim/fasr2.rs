//! `fasr2` (examples/ctrl/fasr2.cc): robots that take on tasks — carry
//! flags from a `NAME_source` zone to its `NAME_sink`, for the NAMEs of
//! `ctrl "fasr2 red green …"` — and find their way by A* over a 32×32
//! raster of the model named `cave`, and when their pack runs low (under a
//! fifth, or when tired of waiting at a source) go to the zone named
//! `fuel_zone` and dock at a charger their fiducial finder sees.
//!
//! A robot's whole update runs in series (its flags move between models),
//! once per its position model's update; the speeds it sets drive the
//! moves that follow.

use std::collections::HashMap;
use std::f64::consts::PI;

use troupe_geom::{normalize, Pose};

use super::ctrl::Charger;
use super::{Ctrl, Mind, Mode, Sim};
use crate::world::World;

/// The planner's raster of the `cave`, cells across and up.
const CELLS: usize = 32;
/// A cell's cost: free, and never entered.
pub(super) const FREE: u8 = 1;
const WALL: u8 = 9;

/// One task: where flags come from and where they go.
#[derive(Debug, Clone)]
struct Task {
    source: usize,
    sink: usize,
}

/// What a `fasr2` robot keeps besides its [`Mind`].
#[derive(Debug, Clone, Default)]
struct Robot {
    task: usize,
    /// The zone it heads for, and where that was when it last planned.
    goal: usize,
    cached_goal: (f64, f64),
    /// Its plan: the start and goal cells, a key of the shared cache.
    plan: Option<(usize, usize)>,
    /// Simulated second it began waiting at an empty source (-1: not).
    wait_started: i64,
    /// Sent to recharge, tired of waiting.
    force_recharge: bool,
    /// Its heading when it docked.
    docked_angle: f64,
}

/// The robots of a world that run `fasr2`, and what they share.
#[derive(Debug, Default)]
pub struct Fasr2 {
    tasks: Vec<Task>,
    fuel: usize,
    /// The `cave`'s size, and its raster (row by row from the bottom).
    size: (f64, f64),
    map: Vec<u8>,
    /// Plans by (start cell, goal cell): the path's cell centres from the
    /// goal back to the start (a node's value is its index).
    plans: HashMap<(usize, usize), Vec<(f64, f64)>>,
    /// Each base's state, for those that run it.
    robots: Vec<Option<Robot>>,
    /// Plans that found no path, said once with a count.
    failed: usize,
}

/// Why a world's `fasr2` robots cannot run, or what they share.
pub fn setup(world: &World, line: &str) -> Result<Fasr2, String> {
    let model = |name: &str| {
        world
            .names
            .get(name)
            .copied()
            .ok_or_else(|| format!("\"fasr2\" needs a model named \"{name}\""))
    };
    let mut tasks = Vec::new();
    for name in line.split_whitespace().skip(1) {
        tasks.push(Task {
            source: model(&format!("{name}_source"))?,
            sink: model(&format!("{name}_sink"))?,
        });
    }
    if tasks.is_empty() {
        return Err("\"fasr2\" takes the names of its tasks (`fasr2 red green`)".into());
    }
    let fuel = model("fuel_zone")?;
    let cave = model("cave")?;
    let def = &world.models[cave];
    let size = (def.size[0], def.size[1]);
    Ok(Fasr2 {
        tasks,
        fuel,
        size,
        map: raster(&def.blocks, size),
        plans: HashMap::new(),
        robots: Vec::new(),
        failed: 0,
    })
}

/// Stage's Model::Rasterize as fasr2 calls it: each block's outline drawn
/// (every edge as a line of cells) into a `CELLS`² raster of a model of
/// `size`, walls `WALL`, the rest `FREE`.
fn raster(blocks: &[Vec<(f64, f64)>], size: (f64, f64)) -> Vec<u8> {
    outline(blocks, size, (CELLS, CELLS))
}

/// Stage's Model::Rasterize: each block's outline drawn (every edge as a
/// line of cells) into a `w`×`h` raster (row by row from the bottom) of a
/// model of `size`, `WALL` where drawn, `FREE` elsewhere.
pub(super) fn outline(
    blocks: &[Vec<(f64, f64)>],
    size: (f64, f64),
    (w, h): (usize, usize),
) -> Vec<u8> {
    let mut map = vec![FREE; w * h];
    let (cw, ch) = (size.0 / w as f64, size.1 / h as f64);
    for poly in blocks {
        for (k, &a) in poly.iter().enumerate() {
            let b = poly[(k + 1) % poly.len()];
            // Along the edge at a quarter cell's steps: every cell it crosses.
            let len = ((b.0 - a.0) / cw).abs().max(((b.1 - a.1) / ch).abs());
            let n = (len * 4.0).ceil().max(1.0) as usize;
            for i in 0..=n {
                let t = i as f64 / n as f64;
                let x = ((a.0 + (b.0 - a.0) * t + size.0 / 2.0) / cw).floor();
                let y = ((a.1 + (b.1 - a.1) * t + size.1 / 2.0) / ch).floor();
                if (0.0..w as f64).contains(&x) && (0.0..h as f64).contains(&y) {
                    map[y as usize * w + x as usize] = WALL;
                }
            }
        }
    }
    map
}

/// Whether `n` is 10, 100, 1000…
fn power_of_ten(n: usize) -> bool {
    let mut n = n;
    while n >= 10 && n % 10 == 0 {
        n /= 10;
    }
    n == 1
}

/// fasr2's MetersToCell: metres from the map's centre to a cell index
/// (off the map: a cell that is not on it).
fn cell(m: f64, size: f64) -> usize {
    let c = ((m + size / 2.0) / (size / CELLS as f64)).floor();
    if c < 0.0 {
        usize::MAX
    } else {
        c as usize
    }
}

/// fasr2's CellToMeters: a cell's centre.
fn centre(c: usize, size: f64) -> f64 {
    let w = size / CELLS as f64;
    c as f64 * w - size / 2.0 + w / 2.0
}

/// The A* of fasr2's `astar` (stlastar's): four neighbours, a step
/// costing the cell it leaves, the Manhattan distance as the estimate,
/// cells off the map walls. The path from `start` to `goal`, both
/// included; `None` when there is none.
fn astar(map: &[u8], start: (usize, usize), goal: (usize, usize)) -> Option<Vec<(usize, usize)>> {
    use std::cmp::Reverse;
    use std::collections::BinaryHeap;
    let at = |(x, y): (usize, usize)| {
        if x < CELLS && y < CELLS {
            map[y * CELLS + x]
        } else {
            WALL
        }
    };
    let h = |(x, y): (usize, usize)| x.abs_diff(goal.0) + y.abs_diff(goal.1);
    let mut cost: HashMap<(usize, usize), usize> = HashMap::from([(start, 0)]);
    let mut from: HashMap<(usize, usize), (usize, usize)> = HashMap::new();
    let mut open = BinaryHeap::from([Reverse((h(start), 0usize, start))]);
    while let Some(Reverse((_, g, c))) = open.pop() {
        if c == goal {
            let mut path = vec![c];
            let mut k = c;
            while let Some(&p) = from.get(&k) {
                path.push(p);
                k = p;
            }
            path.reverse();
            return Some(path);
        }
        if cost.get(&c).is_some_and(|&best| g > best) {
            continue;
        }
        let (x, y) = c;
        let steps = [
            (x.wrapping_sub(1), y),
            (x, y.wrapping_sub(1)),
            (x + 1, y),
            (x, y + 1),
        ];
        for n in steps {
            if at(n) >= WALL {
                continue;
            }
            let g2 = g + usize::from(at(c));
            if cost.get(&n).is_none_or(|&best| g2 < best) {
                cost.insert(n, g2);
                from.insert(n, c);
                open.push(Reverse((g2 + h(n), g2, n)));
            }
        }
    }
    None
}

impl Fasr2 {
    /// Makes room for base `bi` with its first task (Stage: a random one).
    pub fn join(&mut self, bases: usize, bi: usize, draw: f64) {
        self.robots.resize(bases, None);
        let task = ((draw * self.tasks.len() as f64) as usize).min(self.tasks.len() - 1);
        self.robots[bi] = Some(Robot {
            task,
            goal: self.tasks[task].source,
            wait_started: -1,
            ..Robot::default()
        });
    }

    /// The zone base `bi` heads for.
    pub fn goal(&self, bi: usize) -> usize {
        self.robots[bi].as_ref().map_or(0, |r| r.goal)
    }

    /// The key of the plan from `from` to `to` (metres), planned if it is
    /// not yet.
    fn plan(&mut self, from: (f64, f64), to: (f64, f64)) -> (usize, usize) {
        let (sx, sy) = self.size;
        let start = (cell(from.0, sx), cell(from.1, sy));
        let goal = (cell(to.0, sx), cell(to.1, sy));
        let key = (
            start.1.wrapping_mul(CELLS).wrapping_add(start.0),
            goal.1.wrapping_mul(CELLS).wrapping_add(goal.0),
        );
        if !self.plans.contains_key(&key) {
            let path = astar(&self.map, start, goal).unwrap_or_else(|| {
                // Said the first time, then at every power of ten, counted.
                self.failed += 1;
                if self.failed == 1 {
                    tracing::warn!(
                        "fasr2: no path from ({:.2}, {:.2}) to ({:.2}, {:.2}) on the `cave`'s raster; the robot heads nowhere in particular until it is elsewhere",
                        from.0,
                        from.1,
                        to.0,
                        to.1
                    );
                } else if power_of_ten(self.failed) {
                    tracing::warn!("fasr2: {} plans have found no path", self.failed);
                }
                Vec::new()
            });
            let nodes = path
                .iter()
                .rev()
                .map(|&(x, y)| (centre(x, sx), centre(y, sy)))
                .collect();
            self.plans.insert(key, nodes);
        }
        key
    }

    /// fasr2's GoodDirection: the heading toward the node of `plan`
    /// within `range` of `at` that is nearest the goal, turned a quarter
    /// radian left (to keep right of oncoming robots).
    fn good_direction(&self, plan: (usize, usize), at: (f64, f64), range: f64) -> Option<f64> {
        let nodes = self.plans.get(&plan)?;
        let best = nodes
            .iter()
            .find(|n| (n.0 - at.0).hypot(n.1 - at.1) < range)?;
        Some(normalize((best.1 - at.1).atan2(best.0 - at.0) + 0.25))
    }
}

impl Sim {
    /// fasr2's position update of base `bi` (fasr2.cc's Update): looks
    /// for chargers, loads or unloads flags, then works, docks or undocks.
    pub(super) fn fasr2_update(&mut self, bi: usize, f: &mut Fasr2) {
        let Some(Ctrl::Fasr2 {
            laser,
            sonar,
            fiducial,
        }) = self.bases[bi].ctrl
        else {
            return;
        };
        let Some(mut r) = f.robots.get_mut(bi).and_then(Option::take) else {
            return;
        };
        let m = self.bases[bi].model;
        let mut mind = self.bases[bi].mind;
        let g = self.global(m);
        let pose = (g.x, g.y);
        let fraction = self.energy.pack(m).map_or(1.0, |p| p.fraction());
        // The finder is read while fasr2 subscribes to it: when hungry,
        // docking and undocking.
        // (fasr2.cc takes the nearest charger.)
        if r.force_recharge || fraction < 0.2 || mind.mode != Mode::Work {
            self.look_for_charger(fiducial, &mut mind.charger, |c| {
                c.iter().copied().min_by(|a, b| a.range.total_cmp(&b.range))
            });
        } else {
            mind.charger.seen = false;
        }
        let task = f.tasks[r.task].clone();
        let zone = |z: usize| {
            let zg = self.global(z);
            let near = (zg.x - pose.0).hypot(zg.y - pose.1) < self.world.models[z].size[0] / 2.0;
            (near, (zg.x, zg.y))
        };
        if r.goal == task.source {
            let (near, _) = zone(task.source);
            if near && r.wait_started < 0 && self.energy.flags[m] == 0 {
                r.wait_started = self.time as i64;
            }
            if r.wait_started > 0 && self.chance(m, 2) < 0.0005 {
                // Tired of waiting: off to recharge.
                r.force_recharge = true;
                r.wait_started = -1;
                self.bases[bi].mind = mind;
                f.robots[bi] = Some(r);
                return;
            }
            if near && self.energy.flags[m] < 1 {
                self.energy.pass_flag(task.source, m);
                if self.energy.flags[m] == 1 {
                    r.wait_started = -1;
                    self.set_goal(f, &mut r, m, task.sink);
                }
            }
        } else if r.goal == task.sink {
            let (near, _) = zone(task.sink);
            if near && self.energy.flags[m] > 0 {
                self.energy.pass_flag(m, task.sink);
                if self.energy.flags[m] == 0 {
                    self.set_goal(f, &mut r, m, task.source);
                }
            }
        }
        let hungry = r.force_recharge || fraction < 0.2;
        let full = fraction > 0.95;
        let scan = self.scan(laser).map(<[f64]>::to_vec).unwrap_or_default();
        let avoid = |me: &Sim, mind: &mut Mind| me.avoid(bi, &scan, 4, 0.7, 0.5, mind);
        let Charger {
            seen: ahoy,
            range,
            bearing,
            heading,
        } = mind.charger;
        match mind.mode {
            Mode::Work => {
                if !avoid(self, &mut mind) {
                    if hungry {
                        self.set_goal(f, &mut r, m, f.fuel);
                    }
                    let goal_at = {
                        let zg = self.global(r.goal);
                        (zg.x, zg.y)
                    };
                    let moved =
                        (goal_at.0 - r.cached_goal.0).hypot(goal_at.1 - r.cached_goal.1) > 0.5;
                    let mut a_goal = 0.0;
                    let good = r.plan.and_then(|p| f.good_direction(p, pose, 5.0));
                    if let Some(a) = good {
                        a_goal = a;
                    }
                    if good.is_none() || moved {
                        r.plan = Some(f.plan(pose, goal_at));
                        r.cached_goal = goal_at;
                    }
                    if hungry && ahoy {
                        mind.mode = Mode::Dock;
                    }
                    mind.want = Pose::new(0.4, 0.0, normalize(a_goal - g.yaw));
                }
            }
            Mode::Dock => {
                if ahoy {
                    let orient = normalize(PI - (bearing - heading));
                    let a_goal = normalize(bearing - 2.0 * orient);
                    if range > 0.5 {
                        if !avoid(self, &mut mind) {
                            mind.want = Pose::new(0.4, 0.0, a_goal);
                        }
                    } else {
                        mind.want = Pose::new(0.02, 0.0, a_goal);
                        if range < 0.08 {
                            mind.want = Pose::default();
                            r.docked_angle = g.yaw;
                        }
                        if self.bases[bi].stall {
                            mind.want.x = -0.01;
                        }
                    }
                } else {
                    mind.want = Pose::default();
                    mind.mode = Mode::Work;
                }
                if full {
                    mind.mode = Mode::Undock;
                    r.force_recharge = false;
                }
            }
            Mode::Undock => {
                if range < 0.2 {
                    mind.want.x = -0.02;
                    // Waits while its back sonars (10–13) see anything near.
                    let back = self.readings[sonar]
                        .iter()
                        .skip(10)
                        .take(4)
                        .any(|rd| rd.ranges.first().is_none_or(|&v| v < 0.2));
                    if back {
                        mind.want.x = 0.0;
                    }
                } else {
                    let err = normalize(g.yaw - (r.docked_angle + PI));
                    if err.abs() > 0.05 {
                        mind.want = Pose::new(0.0, 0.0, -0.3 * err.signum());
                    } else {
                        mind.mode = Mode::Work;
                        if self.energy.flags[m] == 0 {
                            let draw = self.chance(m, 3);
                            r.task =
                                ((draw * f.tasks.len() as f64) as usize).min(f.tasks.len() - 1);
                            let source = f.tasks[r.task].source;
                            self.set_goal(f, &mut r, m, source);
                        } else {
                            let sink = f.tasks[r.task].sink;
                            self.set_goal(f, &mut r, m, sink);
                        }
                    }
                }
            }
        }
        self.bases[bi].mind = mind;
        f.robots[bi] = Some(r);
    }

    /// fasr2's SetGoal: a new goal is planned for at once, and the robot
    /// takes its colour.
    fn set_goal(&mut self, f: &mut Fasr2, r: &mut Robot, m: usize, goal: usize) {
        if goal == r.goal {
            return;
        }
        r.goal = goal;
        let (here, there) = (self.global(m), self.global(goal));
        r.plan = Some(f.plan((here.x, here.y), (there.x, there.y)));
        self.colors[m] = self.colors[goal];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn astar_goes_around_walls_and_fails_when_walled_in() {
        let mut map = vec![FREE; CELLS * CELLS];
        // A wall across x = 5 from y = 0 to 9.
        for y in 0..10 {
            map[y * CELLS + 5] = WALL;
        }
        let path = astar(&map, (2, 2), (8, 2)).unwrap();
        assert_eq!(path.first(), Some(&(2, 2)));
        assert_eq!(path.last(), Some(&(8, 2)));
        assert!(
            path.iter().any(|&(_, y)| y >= 10),
            "goes round the wall's end"
        );
        assert!(path.iter().all(|&(x, y)| map[y * CELLS + x] == FREE));
        // Each step to a neighbour.
        assert!(path
            .windows(2)
            .all(|w| w[0].0.abs_diff(w[1].0) + w[0].1.abs_diff(w[1].1) == 1));
        for x in 0..CELLS {
            map[10 * CELLS + x] = WALL;
        }
        assert_eq!(astar(&map, (2, 2), (8, 2)), None);
    }

    #[test]
    fn failures_are_counted_at_powers_of_ten() {
        let said: Vec<usize> = (2..=1000).filter(|&n| power_of_ten(n)).collect();
        assert_eq!(said, [10, 100, 1000]);
    }

    #[test]
    fn the_raster_marks_outlines_in_cells() {
        // A 100 m map; one block from (-50, -50) to (-40, 50): its left
        // and right edges and the ends.
        let block = vec![(-50.0, -50.0), (-40.0, -50.0), (-40.0, 50.0), (-50.0, 50.0)];
        let map = raster(&[block], (100.0, 100.0));
        let at = |x: usize, y: usize| map[y * CELLS + x];
        assert_eq!(at(0, 16), WALL);
        assert_eq!(at(3, 16), WALL);
        assert_eq!(at(1, 16), FREE, "inside, not on the outline");
        assert_eq!(at(20, 16), FREE);
        assert_eq!((cell(-50.0, 100.0), cell(49.9, 100.0)), (0, 31));
        // rasterize's 40×20 of a 4×2 m box: its border.
        let square = vec![(-1.95, -0.95), (1.95, -0.95), (1.95, 0.95), (-1.95, 0.95)];
        let box_map = outline(&[square], (4.0, 2.0), (40, 20));
        let drawn = box_map.iter().filter(|&&c| c == WALL).count();
        assert_eq!(drawn, 2 * 40 + 2 * 18);
        assert!((centre(0, 100.0) + 48.4375).abs() < 1e-9);
    }
}
