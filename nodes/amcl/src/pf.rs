//! The particle filter: Player's pf library (Fox's KLD-sampling), pure.
//!
//! - [`Filter::init`] draws `max_samples` particles from a Gaussian;
//! - [`Filter::action`] moves every particle by an odometric step plus noise
//!   (Player's drift model);
//! - [`Filter::sensor`] multiplies weights by a likelihood and normalizes;
//! - [`Filter::resample`] draws a new set by low-variance resampling whose
//!   size follows the KLD bound on the number of occupied histogram bins
//!   (0.5 m × 0.5 m × 10°), between `min_samples` and `max_samples`;
//! - [`Filter::clusters`]: connected occupied bins, each a pose hypothesis
//!   with its weight, mean and covariance.

use std::collections::{HashMap, HashSet};
use std::hash::{BuildHasherDefault, Hasher};

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;
use troupe_geom::{normalize, Pose};

/// One particle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Particle {
    /// Pose, world frame.
    pub pose: Pose,
    /// Weight; the set's weights sum to 1.
    pub weight: f64,
}

/// Sizes and the KLD bound.
#[derive(Debug, Clone, Copy)]
pub struct Config {
    /// Fewest particles after resampling (`pf_min_samples`).
    pub min_samples: usize,
    /// Most particles, and the size of a fresh set (`pf_max_samples`).
    pub max_samples: usize,
    /// KLD error bound ε (`pf_err`).
    pub err: f64,
    /// Upper standard normal quantile for 1 − δ (`pf_z`).
    pub z: f64,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            min_samples: 100,
            max_samples: 10_000,
            err: 0.01,
            z: 3.0,
        }
    }
}

/// A pose hypothesis: one cluster of particles.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cluster {
    /// Sum of the cluster's weights (its share of the particles).
    pub weight: f64,
    /// Weighted mean (circular mean for the angle).
    pub mean: Pose,
    /// Covariance in Player's order: xx, yy, θθ, xy, yθ, xθ.
    pub cov: [f64; 6],
    /// Particles in the cluster.
    pub count: usize,
}

/// The histogram bin of a pose: 0.5 m, 0.5 m, 10°.
fn bin(p: &Pose) -> (i32, i32, i32) {
    const XY: f64 = 0.5;
    const A: f64 = 10.0 * std::f64::consts::PI / 180.0;
    (floor(p.x / XY), floor(p.y / XY), wrap_bin(floor(p.yaw / A)))
}

/// ⌊v⌋ as an integer, saturating: f64::floor is a libm call on the
/// baseline x86-64 target, and every particle takes three per update.
#[inline]
fn floor(v: f64) -> i32 {
    let t = v as i32;
    t.saturating_sub(i32::from(f64::from(t) > v))
}

/// An angle bin number wrapped into -18..18.
fn wrap_bin(a: i32) -> i32 {
    (a + ANGLE_BINS / 2).rem_euclid(ANGLE_BINS) - ANGLE_BINS / 2
}

/// Angle bins around the circle.
const ANGLE_BINS: i32 = 36;

/// A multiply-shift hasher for bin keys: the std SipHash costs more than
/// the rest of a resample at 100 000 particles.
#[derive(Default)]
struct BinHasher(u64);

impl Hasher for BinHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }
    fn write_i32(&mut self, v: i32) {
        self.write_u64(u64::from(v as u32));
    }
    fn write_u64(&mut self, v: u64) {
        self.0 = (self.0.rotate_left(21) ^ v).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    }
}

type BinSet = HashSet<(i32, i32, i32), BuildHasherDefault<BinHasher>>;
type BinMap<V> = HashMap<(i32, i32, i32), V, BuildHasherDefault<BinHasher>>;

/// The particle filter.
pub struct Filter {
    config: Config,
    particles: Vec<Particle>,
    spare: Vec<Particle>,
    rng: StdRng,
    bins: BinSet,
    /// The cores weighing may use, read once (std asks the affinity mask
    /// and cgroup files each time).
    cores: usize,
}

/// A sample of N(0, σ²) (ziggurat: a few nanoseconds, where Box–Muller's
/// logarithm, root and cosine cost more than the rest of a motion update).
fn gaussian(rng: &mut StdRng, sigma: f64) -> f64 {
    if sigma <= 0.0 {
        return 0.0;
    }
    sigma * rng.sample::<f64, _>(StandardNormal)
}

/// Lower-triangular L with L Lᵀ = `c` (a covariance); directions with no
/// positive variance get none.
fn cholesky(c: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mut l = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..=i {
            let s: f64 = (0..j).map(|k| l[i][k] * l[j][k]).sum();
            if i == j {
                let d = c[i][i] - s;
                l[i][j] = if d > 0.0 { d.sqrt() } else { 0.0 };
            } else if l[j][j] > 0.0 {
                l[i][j] = (c[i][j] - s) / l[j][j];
            }
        }
    }
    l
}

/// Fox's KLD bound: particles needed for `k` occupied bins.
pub fn kld_limit(config: &Config, k: usize) -> usize {
    if k <= 1 {
        return config.min_samples;
    }
    let k1 = (k - 1) as f64;
    let b = 2.0 / (9.0 * k1);
    let x = 1.0 - b + b.sqrt() * config.z;
    let n = (k1 / (2.0 * config.err) * x * x * x).ceil();
    if n >= config.max_samples as f64 {
        config.max_samples
    } else {
        (n as usize).max(config.min_samples)
    }
}

impl Filter {
    /// An empty filter; `seed` makes runs repeatable.
    pub fn new(config: Config, seed: u64) -> Self {
        let mut config = config;
        config.max_samples = config.max_samples.max(1);
        config.min_samples = config.min_samples.clamp(1, config.max_samples);
        Filter {
            config,
            particles: Vec::new(),
            spare: Vec::new(),
            rng: StdRng::seed_from_u64(seed),
            bins: BinSet::default(),
            cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
        }
    }

    /// The sizes and bound in use.
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// The current particles.
    pub fn particles(&self) -> &[Particle] {
        &self.particles
    }

    /// Replaces the set by `max_samples` particles drawn from N(`mean`, `cov`),
    /// `cov` over (x, y, θ), equally weighted.
    pub fn init(&mut self, mean: Pose, cov: &[[f64; 3]; 3]) {
        let l = cholesky(cov);
        let n = self.config.max_samples;
        let w = 1.0 / n as f64;
        self.particles.clear();
        for _ in 0..n {
            let r = [
                gaussian(&mut self.rng, 1.0),
                gaussian(&mut self.rng, 1.0),
                gaussian(&mut self.rng, 1.0),
            ];
            let d: [f64; 3] = std::array::from_fn(|i| (0..3).map(|k| l[i][k] * r[k]).sum());
            self.particles.push(Particle {
                pose: Pose::new(mean.x + d[0], mean.y + d[1], normalize(mean.yaw + d[2])),
                weight: w,
            });
        }
    }

    /// Moves every particle by the odometric step `delta` (robot frame at the
    /// last update) plus Gaussian noise whose deviations Player's `drift`
    /// matrix scales: σx = D00|δx|, σy = D11|δy|, σθ = D20|δx| + D21|δy| + D22|δθ|.
    /// Weights become uniform.
    pub fn action(&mut self, delta: Pose, drift: &[[f64; 3]; 3]) {
        let sx = drift[0][0] * delta.x.abs();
        let sy = drift[1][1] * delta.y.abs();
        let sa = drift[2][0] * delta.x.abs()
            + drift[2][1] * delta.y.abs()
            + drift[2][2] * delta.yaw.abs();
        let w = 1.0 / self.particles.len().max(1) as f64;
        for p in &mut self.particles {
            let z = Pose::new(
                delta.x + gaussian(&mut self.rng, sx),
                delta.y + gaussian(&mut self.rng, sy),
                delta.yaw + gaussian(&mut self.rng, sa),
            );
            p.pose = p.pose.compose(&z);
            p.weight = w;
        }
    }

    /// Multiplies each weight by `likelihood(pose)` and normalizes; spread
    /// over the available cores for large sets. Returns the total before
    /// normalizing; when it is 0 (no particle explains the data) the
    /// weights become uniform, as Player's.
    pub fn sensor<F>(&mut self, likelihood: F) -> f64
    where
        F: Fn(&Pose) -> f64 + Sync,
    {
        let apply = |chunk: &mut [Particle]| -> f64 {
            let mut total = 0.0;
            for p in chunk {
                p.weight *= likelihood(&p.pose);
                total += p.weight;
            }
            total
        };
        // Threads pay off only for large sets.
        let threads = if self.particles.len() >= 2048 {
            self.cores
        } else {
            1
        };
        let total: f64 = if threads > 1 {
            let size = self.particles.len().div_ceil(threads);
            std::thread::scope(|s| {
                // The calling thread weighs the first chunk itself: one
                // thread fewer to start on every update.
                let mut chunks = self.particles.chunks_mut(size);
                let mine = chunks.next();
                let handles: Vec<_> = chunks.map(|c| s.spawn(move || apply(c))).collect();
                let own = mine.map_or(0.0, apply);
                // A panicking likelihood is a bug; resurface it here.
                own + handles
                    .into_iter()
                    .map(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
                    .sum::<f64>()
            })
        } else {
            apply(&mut self.particles)
        };
        if total > 0.0 && total.is_finite() {
            for p in &mut self.particles {
                p.weight /= total;
            }
        } else {
            let w = 1.0 / self.particles.len().max(1) as f64;
            for p in &mut self.particles {
                p.weight = w;
            }
        }
        total
    }

    /// Draws a new set (low-variance resampling) until it has more particles
    /// than the KLD bound for the bins it occupies; weights become uniform.
    pub fn resample(&mut self) {
        let n_a = self.particles.len();
        if n_a == 0 {
            return;
        }
        let inv = 1.0 / n_a as f64;
        self.spare.clear();
        self.bins.clear();
        let mut r = self.rng.gen::<f64>() * inv;
        let mut c = self.particles[0].weight;
        let mut i = 0;
        let mut m = 0;
        let mut limit = kld_limit(&self.config, 0);
        while self.spare.len() < self.config.max_samples {
            if m == n_a {
                // A full pass drawn: start another with a fresh offset.
                r = self.rng.gen::<f64>() * inv;
                c = self.particles[0].weight;
                i = 0;
                m = 0;
            }
            let u = r + m as f64 * inv;
            while u > c && i + 1 < n_a {
                i += 1;
                c += self.particles[i].weight;
            }
            let pose = self.particles[i].pose;
            self.spare.push(Particle { pose, weight: 1.0 });
            if self.bins.insert(bin(&pose)) {
                limit = kld_limit(&self.config, self.bins.len());
            }
            if self.spare.len() > limit {
                break;
            }
            m += 1;
        }
        let w = 1.0 / self.spare.len() as f64;
        for p in &mut self.spare {
            p.weight = w;
        }
        std::mem::swap(&mut self.particles, &mut self.spare);
    }

    /// The hypotheses: particles grouped by connected occupied bins
    /// (26-neighbourhood, angle bins wrapping), heaviest first.
    pub fn clusters(&self) -> Vec<Cluster> {
        // Each particle's bin as an index into `keys`, so that the sums
        // below need no second lookup.
        let mut index: BinMap<usize> = BinMap::default();
        let mut keys: Vec<(i32, i32, i32)> = Vec::new();
        let of: Vec<usize> = self
            .particles
            .iter()
            .map(|p| {
                let b = bin(&p.pose);
                *index.entry(b).or_insert_with(|| {
                    keys.push(b);
                    keys.len() - 1
                })
            })
            .collect();
        // Each bin's cluster, by its index in `keys`; flood-filled.
        let mut label = vec![usize::MAX; keys.len()];
        let mut count = 0;
        let mut stack = Vec::new();
        for start in 0..keys.len() {
            if label[start] != usize::MAX {
                continue;
            }
            label[start] = count;
            stack.push(keys[start]);
            while let Some((x, y, a)) = stack.pop() {
                for dx in -1..=1 {
                    for dy in -1..=1 {
                        for da in -1..=1 {
                            let n = (x + dx, y + dy, wrap_bin(a + da));
                            if let Some(&k) = index.get(&n) {
                                if label[k] == usize::MAX {
                                    label[k] = count;
                                    stack.push(n);
                                }
                            }
                        }
                    }
                }
            }
            count += 1;
        }
        #[derive(Default, Clone, Copy)]
        struct Acc {
            n: usize,
            w: f64,
            x: f64,
            y: f64,
            c: f64,
            s: f64,
            xx: f64,
            yy: f64,
            xy: f64,
        }
        let mut acc = vec![Acc::default(); count];
        for (p, &b) in self.particles.iter().zip(&of) {
            let a = &mut acc[label[b]];
            let (w, x, y) = (p.weight, p.pose.x, p.pose.y);
            a.n += 1;
            a.w += w;
            a.x += w * x;
            a.y += w * y;
            a.c += w * p.pose.yaw.cos();
            a.s += w * p.pose.yaw.sin();
            a.xx += w * x * x;
            a.yy += w * y * y;
            a.xy += w * x * y;
        }
        let mut out: Vec<Cluster> = acc
            .iter()
            .filter(|a| a.w > 0.0)
            .map(|a| {
                let (mx, my) = (a.x / a.w, a.y / a.w);
                let r = (a.c * a.c + a.s * a.s).sqrt() / a.w;
                Cluster {
                    weight: a.w,
                    mean: Pose::new(mx, my, a.s.atan2(a.c)),
                    cov: [
                        (a.xx / a.w - mx * mx).max(0.0),
                        (a.yy / a.w - my * my).max(0.0),
                        -2.0 * r.clamp(f64::MIN_POSITIVE, 1.0).ln(),
                        a.xy / a.w - mx * my,
                        0.0,
                        0.0,
                    ],
                    count: a.n,
                }
            })
            .collect();
        out.sort_by(|a, b| b.weight.total_cmp(&a.weight));
        out
    }

    /// Weighted mean of x and y over the whole set, and the spread
    /// Σw(x² + y²)/Σw − |mean|² (Player's `pf_get_cep_stats`).
    pub fn cep_stats(&self) -> (f64, f64, f64) {
        let (mut n, mut x, mut y, mut rr) = (0.0, 0.0, 0.0, 0.0);
        for p in &self.particles {
            n += p.weight;
            x += p.weight * p.pose.x;
            y += p.weight * p.pose.y;
            rr += p.weight * (p.pose.x * p.pose.x + p.pose.y * p.pose.y);
        }
        if n <= 0.0 {
            return (0.0, 0.0, 0.0);
        }
        let (mx, my) = (x / n, y / n);
        (mx, my, rr / n - (mx * mx + my * my))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn diag(x: f64, y: f64, a: f64) -> [[f64; 3]; 3] {
        [[x, 0.0, 0.0], [0.0, y, 0.0], [0.0, 0.0, a]]
    }

    fn small() -> Config {
        Config {
            min_samples: 50,
            max_samples: 5000,
            ..Config::default()
        }
    }

    #[test]
    fn kld_bound_grows_with_bins_and_stays_in_limits() {
        let c = Config::default();
        assert_eq!(kld_limit(&c, 1), 100);
        assert_eq!(kld_limit(&c, 0), 100);
        // k = 2: b = 2/9, x = 1 - 2/9 + 3·sqrt(2/9) = 2.1920; n = ceil(50 · x³) = 527.
        assert_eq!(kld_limit(&c, 2), 527);
        assert!(kld_limit(&c, 10) < kld_limit(&c, 100));
        assert_eq!(kld_limit(&c, 100_000), 10_000);
    }

    #[test]
    fn init_draws_the_gaussian_asked_for() {
        let mut f = Filter::new(small(), 1);
        f.init(Pose::new(1.0, -2.0, 0.5), &diag(0.04, 0.09, 0.01));
        assert_eq!(f.particles().len(), 5000);
        let c = f.clusters();
        let best = c[0];
        assert!(c.len() <= 3, "one blob, {} clusters", c.len());
        assert!((best.mean.x - 1.0).abs() < 0.02, "{:?}", best.mean);
        assert!((best.mean.y + 2.0).abs() < 0.02, "{:?}", best.mean);
        assert!((best.mean.yaw - 0.5).abs() < 0.01, "{:?}", best.mean);
        assert!((best.cov[0] - 0.04).abs() < 0.006, "{:?}", best.cov);
        assert!((best.cov[1] - 0.09).abs() < 0.012, "{:?}", best.cov);
        assert!((best.cov[2] - 0.01).abs() < 0.002, "{:?}", best.cov);
        assert!(best.cov[3].abs() < 0.01, "{:?}", best.cov);
    }

    #[test]
    fn action_moves_in_the_robot_frame_with_drift_noise() {
        let mut f = Filter::new(small(), 2);
        f.init(
            Pose::new(0.0, 0.0, std::f64::consts::FRAC_PI_2),
            &diag(0.0, 0.0, 0.0),
        );
        let drift = [[0.2, 0.0, 0.0], [0.0, 0.2, 0.0], [0.2, 0.0, 0.2]];
        f.action(Pose::new(1.0, 0.0, 0.0), &drift);
        let c = f.clusters()[0];
        // Facing +y, a metre forward is +y.
        assert!(
            c.mean.x.abs() < 0.02 && (c.mean.y - 1.0).abs() < 0.02,
            "{:?}",
            c.mean
        );
        // σ forward 0.2 m; sideways spread only from the heading noise.
        assert!((c.cov[1].sqrt() - 0.2).abs() < 0.02, "{:?}", c.cov);
        assert!((c.cov[2].sqrt() - 0.2).abs() < 0.03, "{:?}", c.cov);
        let no_noise = [[0.0; 3]; 3];
        f.init(Pose::default(), &diag(0.0, 0.0, 0.0));
        f.action(Pose::new(0.5, 0.25, 0.1), &no_noise);
        assert!(f
            .particles()
            .iter()
            .all(|p| p.pose == Pose::new(0.5, 0.25, 0.1)));
    }

    #[test]
    fn sensor_and_resample_concentrate_on_the_likely_pose() {
        let mut f = Filter::new(small(), 3);
        f.init(Pose::default(), &diag(4.0, 4.0, 1.0));
        for _ in 0..5 {
            let total = f.sensor(|p| (-((p.x - 1.0).powi(2) + (p.y + 1.0).powi(2)) / 0.02).exp());
            assert!(total > 0.0);
            let sum: f64 = f.particles().iter().map(|p| p.weight).sum();
            assert!((sum - 1.0).abs() < 1e-9);
            f.resample();
            f.action(Pose::default(), &[[0.0; 3]; 3]);
            // Jitter so that resampling is not stuck on copies.
            let n = f.particles().len();
            let drift = [[0.05, 0.0, 0.0], [0.0, 0.05, 0.0], [0.0, 0.0, 0.0]];
            f.action(Pose::new(0.01, 0.01, 0.0), &drift);
            assert!(n >= 50);
        }
        let best = f.clusters()[0];
        assert!(
            (best.mean.x - 1.0).abs() < 0.15 && (best.mean.y + 1.0).abs() < 0.15,
            "{best:?}"
        );
        assert!(
            f.particles().len() < 5000,
            "KLD shrank the set: {}",
            f.particles().len()
        );
        let (mx, my, var) = f.cep_stats();
        assert!((mx - 1.0).abs() < 0.2 && (my + 1.0).abs() < 0.2 && var < 0.1);
    }

    #[test]
    fn zero_likelihood_keeps_uniform_weights_and_two_blobs_make_two_clusters() {
        let mut f = Filter::new(small(), 4);
        f.init(Pose::default(), &diag(0.01, 0.01, 0.001));
        assert_eq!(f.sensor(|_| 0.0), 0.0);
        assert!(f
            .particles()
            .iter()
            .all(|p| (p.weight - 1.0 / 5000.0).abs() < 1e-15));
        // Half the particles 5 m away.
        let n = f.particles.len();
        for p in &mut f.particles[n / 2..] {
            p.pose.x += 5.0;
        }
        let c = f.clusters();
        assert_eq!(c.len(), 2, "{c:?}");
        assert!((c[0].weight - 0.5).abs() < 1e-9 && (c[1].weight - 0.5).abs() < 1e-9);
    }

    #[test]
    fn clusters_join_across_the_angle_wrap() {
        let mut f = Filter::new(small(), 5);
        f.init(
            Pose::new(0.2, 0.2, std::f64::consts::PI),
            &diag(0.0, 0.0, 0.0004),
        );
        let c = f.clusters();
        assert_eq!(c.len(), 1, "{c:?}");
        assert!(c[0].mean.yaw.abs() > 3.1, "{:?}", c[0].mean);
        assert!(c[0].cov[2] < 0.001, "{:?}", c[0].cov);
    }
}
