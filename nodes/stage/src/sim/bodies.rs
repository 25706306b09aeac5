//! Where bodies stand and what they meet: static models written into the
//! grid (and Stage's raster), moving ones filed by tile, a tree's bodies
//! placed at a pose and tested against both before it moves there.

use super::*;

/// A body as it would stand at a global pose: in world coordinates, with
/// the cells of its box (`None` off the grid), made once (by the thread
/// that plans the move) for both the collision tests and the filing.
#[derive(Default)]
pub(super) struct Placed {
    pub(super) model: usize,
    pub(super) body: Body,
    pub(super) cells: Option<((usize, usize), (usize, usize))>,
}

impl Sim {
    /// Whether model `m`'s body is written into the static grid or filed
    /// with the moving bodies: it has blocks, and obstacles or rangers meet
    /// them.
    pub(super) fn in_grid(&self, m: usize) -> bool {
        self.frames[m].met
    }

    /// (Re)writes model `m`'s body at its current pose: into the static
    /// grid, or filed with the moving bodies.
    pub(super) fn place(&mut self, m: usize) {
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
    pub(super) fn draw(&mut self, m: usize) {
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

    /// Draws moving model `m`'s outline, as placed in `body`, into the
    /// raster's moving layer in place of where it was, as Stage redraws a
    /// model that moved: other robots' rays then meet it on the raster.
    fn draw_moving(&mut self, m: usize, body: &Placed) {
        self.undraw_moving(m);
        let mut drawn = std::mem::take(&mut self.drawn[m]);
        if let Some(r) = &mut self.raster {
            for pts in body.body.polys() {
                raster::outline(r.ppm(), pts, |x, y| drawn.push((x, y)));
            }
            for &(x, y) in &drawn {
                r.set_moving(x, y, id(m));
            }
        }
        self.drawn[m] = drawn;
    }

    /// Takes moving model `m`'s outline out of the raster's moving layer.
    fn undraw_moving(&mut self, m: usize) {
        if let Some(r) = &mut self.raster {
            for &(x, y) in &self.drawn[m] {
                r.unset_moving(x, y, id(m));
            }
        }
        self.drawn[m].clear();
    }

    /// Model `m`'s body at global pose `at`.
    pub(super) fn placed(&self, m: usize, at: Pose) -> Placed {
        let mut body = Placed::default();
        self.place_into(m, at.transform(), &mut body);
        body
    }

    /// [`Sim::placed`] at the pose whose transform is `at`, into `body`,
    /// reusing its buffers.
    pub(super) fn place_into(&self, m: usize, at: Transform, body: &mut Placed) {
        body.model = m;
        let model = &self.world.models[m];
        body.body
            .place_outlined(&model.blocks, at, &self.outlines[m]);
        // The blocks' heights are above the model's base: its look's
        // lowest less its lowest block's.
        let base = self.looks[m].lo - model.body_span().0;
        body.body.lift(&model.block_z, base);
        body.cells = body
            .body
            .bounds()
            .and_then(|b| self.statics.lattice().cells_of_box(b));
    }

    /// Files a moving body under the tiles it touches (taking its polygons,
    /// and leaving it buffers to reuse).
    pub(super) fn file(&mut self, body: &mut Placed) {
        let m = body.model;
        self.draw_moving(m, body);
        let tiles = body.cells.map(|(lo, hi)| self.statics.tile_box(lo, hi));
        self.movers.file(m, id(m), &mut body.body, tiles);
    }

    /// Moves static model `m`'s body in the grid from where it was to the
    /// global pose `at`.
    pub(super) fn occupy(&mut self, m: usize, at: Pose) {
        self.unplace(m);
        for pts in self.placed(m, at).body.polys() {
            self.statics.fill_polygon(pts, id(m));
        }
        self.written_at[m] = Some(at);
    }

    /// Every body in the tree of `m` (itself and what it carries) as it
    /// would be if `m` were at the global pose `at`, whose yaw's sine and
    /// cosine are `turn`, into `bodies` (whose buffers are reused).
    pub(super) fn tree_at(
        &self,
        m: usize,
        (at, turn): (Pose, (f64, f64)),
        bodies: &mut Vec<Placed>,
    ) {
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
                at.transform_by(turn)
            } else {
                shift
                    .get_or_insert_with(|| at.compose(&self.global(m).inverse()))
                    .compose(&self.global(k))
                    .transform()
            };
            self.place_into(k, to, &mut bodies[n]);
            n += 1;
        }
        bodies.truncate(n);
    }

    /// Whether model `other` blocks the bodies of the tree of `root`.
    pub(super) fn blocks(&self, root: usize, other: usize) -> bool {
        self.root(other) != root && self.frames[other].obstacle
    }

    /// Whether model `m`'s body meets obstacles when it moves: as in
    /// Stage, one with no `obstacle_return` (a charging bump on a robot's
    /// nose) passes through them as they pass through it.
    pub(super) fn collides(&self, m: usize) -> bool {
        self.frames[m].obstacle
    }

    /// True when the `bodies` (of the tree of `root`) would overlap an
    /// unrelated static obstacle.
    pub(super) fn hits_statics(&self, root: usize, bodies: &[Placed]) -> bool {
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
    pub(super) fn hits_movers(&self, root: usize, bodies: &[Placed]) -> bool {
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
    pub(super) fn in_the_open(&self, body: &Body) -> bool {
        let (cx, cy, reach) = body.circle();
        // A cell's width to spare: a polygon's outline marks the cells it
        // touches, even those it only grazes.
        reach < 0.0 || self.statics.clearance(cx, cy) > reach + self.statics.lattice().resolution()
    }

    /// Files the `bodies` (from `tree_at` of a robot: all movable, as
    /// everything on a robot and everything it carries is) where they were
    /// placed.
    pub(super) fn commit(&mut self, bodies: &mut [Placed]) {
        for body in bodies {
            debug_assert!(self.movable[body.model], "a static body in a robot's tree");
            if self.in_grid(body.model) {
                self.file(body);
            }
        }
    }

    /// Takes model `m`'s body out: its cells from the static grid, or its
    /// filing with the moving bodies.
    pub(super) fn unplace(&mut self, m: usize) {
        if self.movable[m] {
            self.movers.unfile(m, id(m));
            self.undraw_moving(m);
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
            for pts in self.placed(m, at).body.polys() {
                self.statics.clear_polygon(pts, id(m));
            }
        }
    }
}
