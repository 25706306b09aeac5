//! A pose graph and its least-squares optimisation (Grisetti et al., "A
//! Tutorial on Graph-Based SLAM", 2010): nodes are the robot's poses at its
//! keyframes, edges say where one was seen from another (by odometry and
//! scan matching along the way, by a loop closure across it), and
//! Gauss-Newton moves the nodes until the edges agree as well as their
//! information lets them.
//!
//! The normal equations are sparse (3×3 blocks: one per node, one per
//! edge) and are solved by conjugate gradients with a block-Jacobi
//! preconditioner. A direct sparse Cholesky without a fill-reducing
//! ordering (nalgebra-sparse has none) fills the whole band a loop spans:
//! ARCHITECTURE.md gives the figures.

use nalgebra::{Matrix3, Vector3};
use troupe_geom::{normalize, Pose};

/// A measurement of node `to` seen from node `from`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Edge {
    /// The node it is seen from.
    pub from: usize,
    /// The node seen.
    pub to: usize,
    /// Where `to` is in `from`'s frame.
    pub z: Pose,
    /// The measurement's information (its covariance's inverse) in x, y
    /// and yaw, in the frame of `to` as `from` sees it (where its error is
    /// measured).
    pub info: Matrix3<f64>,
}

impl Edge {
    /// An edge whose x, y and yaw are independent, of these inverse variances.
    pub fn diagonal(from: usize, to: usize, z: Pose, info: [f64; 3]) -> Edge {
        Edge {
            from,
            to,
            z,
            info: Matrix3::from_diagonal(&Vector3::from(info)),
        }
    }

    /// This edge's error at `poses`, weighted by its information.
    pub fn chi2(&self, poses: &[Pose]) -> f64 {
        let (err, _, _) = linearize(poses[self.from], poses[self.to], self.z);
        err.dot(&(self.info * err))
    }
}

/// Poses and the edges between them; node 0 stays where it is.
#[derive(Debug, Clone, Default)]
pub struct Graph {
    /// Each node's pose.
    pub poses: Vec<Pose>,
    /// The measurements.
    pub edges: Vec<Edge>,
}

fn rot(a: f64) -> nalgebra::Matrix2<f64> {
    let (s, c) = a.sin_cos();
    nalgebra::Matrix2::new(c, -s, s, c)
}

/// An edge's error and its Jacobians by the `from` and `to` poses.
fn linearize(xi: Pose, xj: Pose, z: Pose) -> (Vector3<f64>, Matrix3<f64>, Matrix3<f64>) {
    let ri_t = rot(xi.yaw).transpose();
    let rz_t = rot(z.yaw).transpose();
    let dt = nalgebra::Vector2::new(xj.x - xi.x, xj.y - xi.y);
    let exy = rz_t * (ri_t * dt - nalgebra::Vector2::new(z.x, z.y));
    let eyaw = normalize(xj.yaw - xi.yaw - z.yaw);
    let (s, c) = xi.yaw.sin_cos();
    let dri_t = nalgebra::Matrix2::new(-s, c, -c, -s);
    let a_xy = -(rz_t * ri_t);
    let a_yaw = rz_t * dri_t * dt;
    let a = Matrix3::new(
        a_xy[(0, 0)],
        a_xy[(0, 1)],
        a_yaw[0],
        a_xy[(1, 0)],
        a_xy[(1, 1)],
        a_yaw[1],
        0.0,
        0.0,
        -1.0,
    );
    let b_xy = rz_t * ri_t;
    let b = Matrix3::new(
        b_xy[(0, 0)],
        b_xy[(0, 1)],
        0.0,
        b_xy[(1, 0)],
        b_xy[(1, 1)],
        0.0,
        0.0,
        0.0,
        1.0,
    );
    (Vector3::new(exy[0], exy[1], eyaw), a, b)
}

/// The normal equations' matrix: a block row per node, its blocks by column.
struct Blocks {
    rows: Vec<Vec<(usize, Matrix3<f64>)>>,
}

impl Blocks {
    fn add(&mut self, i: usize, j: usize, m: Matrix3<f64>) {
        let row = &mut self.rows[i];
        match row.iter_mut().find(|(c, _)| *c == j) {
            Some((_, b)) => *b += m,
            None => row.push((j, m)),
        }
    }

    /// `H x`, node 0's rows and columns left out (it is held fixed).
    fn mul(&self, x: &[Vector3<f64>], out: &mut [Vector3<f64>]) {
        for (i, row) in self.rows.iter().enumerate() {
            out[i] = Vector3::zeros();
            if i == 0 {
                continue;
            }
            for &(j, m) in row {
                if j != 0 {
                    out[i] += m * x[j];
                }
            }
        }
    }
}

fn dot(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x.dot(y)).sum()
}

impl Graph {
    /// The weighted squared error of every edge.
    pub fn chi2(&self) -> f64 {
        self.edges.iter().map(|e| e.chi2(&self.poses)).sum()
    }

    /// Up to `iterations` Gauss-Newton steps (damped as Levenberg and
    /// Marquardt do where a step would raise the error, which is then not
    /// taken), stopping when a step lowers the error by less than a
    /// millionth; returns the final error.
    pub fn optimize(&mut self, iterations: usize) -> f64 {
        let n = self.poses.len();
        let mut chi2 = self.chi2();
        let mut damping = 0.0;
        if n < 2 {
            return chi2;
        }
        for _ in 0..iterations {
            let mut h = Blocks {
                rows: vec![Vec::with_capacity(4); n],
            };
            let mut b = vec![Vector3::<f64>::zeros(); n];
            for e in &self.edges {
                let (err, a, bj) = linearize(self.poses[e.from], self.poses[e.to], e.z);
                let o = e.info;
                let (ato, bto) = (a.transpose() * o, bj.transpose() * o);
                h.add(e.from, e.from, ato * a);
                h.add(e.from, e.to, ato * bj);
                h.add(e.to, e.from, bto * a);
                h.add(e.to, e.to, bto * bj);
                b[e.from] += ato * err;
                b[e.to] += bto * err;
            }
            // Levenberg-Marquardt: the diagonal raised by `damping` of
            // itself, more after a step that made the error worse.
            if damping > 0.0 {
                for (i, row) in h.rows.iter_mut().enumerate() {
                    if let Some((_, m)) = row.iter_mut().find(|(j, _)| *j == i) {
                        let d = m.diagonal() * damping;
                        *m += Matrix3::from_diagonal(&d);
                    }
                }
            }
            let dx = solve(&h, &b);
            let before = self.poses.clone();
            for (p, d) in self.poses.iter_mut().zip(&dx).skip(1) {
                *p = Pose::new(p.x + d[0], p.y + d[1], normalize(p.yaw + d[2]));
            }
            let next = self.chi2();
            if next > chi2 {
                self.poses = before;
                damping = (damping * 10.0).max(1e-4);
                continue;
            }
            damping /= 10.0;
            let done = (chi2 - next) <= 1e-6 * chi2.max(1e-12);
            chi2 = next;
            if done {
                break;
            }
        }
        chi2
    }
}

/// Solves `H dx = -b` by preconditioned conjugate gradients (node 0 fixed).
fn solve(h: &Blocks, b: &[Vector3<f64>]) -> Vec<Vector3<f64>> {
    let n = b.len();
    let pre: Vec<Matrix3<f64>> = h
        .rows
        .iter()
        .enumerate()
        .map(|(i, row)| {
            let d = row
                .iter()
                .find(|(j, _)| *j == i)
                .map_or(Matrix3::identity(), |(_, m)| *m);
            d.try_inverse().unwrap_or_else(Matrix3::identity)
        })
        .collect();
    let mut x = vec![Vector3::zeros(); n];
    let mut r: Vec<Vector3<f64>> = b.iter().map(|v| -v).collect();
    r[0] = Vector3::zeros();
    let mut z: Vec<Vector3<f64>> = r.iter().zip(&pre).map(|(r, m)| m * r).collect();
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    let stop = 1e-20 * dot(&r, &r).max(1e-30);
    let mut hp = vec![Vector3::zeros(); n];
    for _ in 0..(10 * n).max(100) {
        if dot(&r, &r) <= stop {
            break;
        }
        h.mul(&p, &mut hp);
        let php = dot(&p, &hp);
        if php <= 0.0 {
            break;
        }
        let alpha = rz / php;
        for i in 1..n {
            x[i] += alpha * p[i];
            r[i] -= alpha * hp[i];
        }
        for i in 1..n {
            z[i] = pre[i] * r[i];
        }
        let rz_next = dot(&r, &z);
        let beta = rz_next / rz;
        rz = rz_next;
        for i in 1..n {
            p[i] = z[i] + beta * p[i];
        }
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Ten steps of 1 m along x, then a closure from the first to the last
    /// that says the last is 1 m farther and 0.5 m to the left: with no
    /// information along x (a match along a wall) it moves the last pose
    /// across, not along.
    #[test]
    fn a_closure_pulls_only_where_it_has_information() {
        let run = |along: f64| {
            let mut g = Graph {
                poses: (0..=10).map(|k| Pose::new(k as f64, 0.0, 0.0)).collect(),
                ..Default::default()
            };
            for k in 1..=10 {
                g.edges.push(Edge::diagonal(
                    k - 1,
                    k,
                    Pose::new(1.0, 0.0, 0.0),
                    [100.0, 100.0, 100.0],
                ));
            }
            g.edges.push(Edge::diagonal(
                0,
                10,
                Pose::new(11.0, 0.5, 0.0),
                [along, 1e4, 1e4],
            ));
            g.optimize(20);
            g.poses[10]
        };
        let blind = run(0.0);
        assert!((blind.x - 10.0).abs() < 0.05, "{blind:?}");
        assert!((blind.y - 0.5).abs() < 0.05, "{blind:?}");
        let sighted = run(1e4);
        assert!(sighted.x > 10.8, "{sighted:?}");
    }

    /// A square driven four times round: odometry that turns a little too
    /// little each corner, and one edge that says the end is the start.
    #[test]
    fn a_loop_closure_pulls_a_drifting_square_back() {
        let mut g = Graph::default();
        let truth: Vec<Pose> = (0..=16)
            .map(|k| {
                let side = (k / 4) % 4;
                let along = (k % 4) as f64;
                let (x, y) = match side {
                    0 => (along, 0.0),
                    1 => (4.0, along),
                    2 => (4.0 - along, 4.0),
                    _ => (0.0, 4.0 - along),
                };
                Pose::new(x, y, normalize(side as f64 * std::f64::consts::FRAC_PI_2))
            })
            .collect();
        let info = [100.0, 100.0, 400.0];
        let mut pose = truth[0];
        g.poses.push(pose);
        for k in 1..truth.len() {
            let mut z = truth[k - 1].inverse().compose(&truth[k]);
            z.yaw -= 0.03; // the gyro under-reads
            pose = pose.compose(&z);
            g.poses.push(pose);
            g.edges.push(Edge::diagonal(k - 1, k, z, info));
        }
        let last = truth.len() - 1;
        let miss = |g: &Graph| {
            let p = g.poses[last];
            (p.x - truth[last].x).hypot(p.y - truth[last].y)
        };
        let before = miss(&g);
        assert!(before > 0.5, "odometry alone misses by {before}");
        g.edges.push(Edge::diagonal(
            0,
            last,
            truth[0].inverse().compose(&truth[last]),
            [1e4, 1e4, 1e4],
        ));
        g.optimize(20);
        let after = miss(&g);
        assert!(after < 0.05, "after the closure it misses by {after}");
        assert_eq!(g.poses[0], truth[0], "node 0 stays");
    }
}
