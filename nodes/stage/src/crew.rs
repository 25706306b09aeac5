//! The threads that share a step's work, and how the work is dealt.
//!
//! A step plans every base, then casts every ranger's rays. Each thread of
//! the crew has a share of both, the same share step after step: a
//! ranger's readings and a base's plan are written by the same core every
//! step and read back by it (the wander controller reads its robot's
//! laser), so they stay in that core's caches instead of crossing to the
//! other core (dealing rangers first come, first served made every ray
//! about 8% slower). A thread done with its share takes what is left of
//! the others', from their far end, so that all finish together.
//!
//! The thread that steps the simulation is one of the crew; the others are
//! a pool kept for the simulation's life: starting threads every step cost
//! more than a tenth of a millisecond per step, and new threads land on
//! whichever core.

use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

/// The threads of a simulation and the shares of its work.
///
/// The work is dealt in runs of neighbouring items, not item by item:
/// each item taken and each slot locked is an atomic operation on a cache
/// line the other thread may hold. hospital.world (a thousand bases and a
/// thousand rangers of a dozen rays each) went 6% faster on two threads
/// and 1% on one when dealt in runs.
#[derive(Default)]
pub struct Crew {
    /// The helpers (none for one thread).
    pool: Option<rayon::ThreadPool>,
    /// Where each run of bases starts, then the number of bases.
    base_cuts: Vec<usize>,
    /// Where each thread's runs of bases start in `base_cuts`, then their number.
    base_starts: Vec<usize>,
    /// The rangers, each thread's together, fewest rays first within each
    /// (a thread senses its own from the last: the most rays first).
    rangers: Vec<usize>,
    /// Where each run of rangers starts in `rangers`, then their number.
    ranger_cuts: Vec<usize>,
    /// Where each thread's runs of rangers start in `ranger_cuts`, then
    /// their number.
    ranger_starts: Vec<usize>,
}

/// How many bases a run holds at most (a base's plan takes a microsecond
/// or two, a fancy Pioneer's three).
const BASE_RUN: usize = 8;

/// How many runs a thread's share of bases is cut into at least: the
/// thread that finishes first waits for the other's last run before the
/// moves, and in cave.world (50 bases a thread) runs of eight made that
/// wait a fifth of the moves' time.
const BASE_RUNS: usize = 32;

/// How many rays a run of rangers casts at most, unless one ranger casts
/// more alone: a tenth of a millisecond a run at most, so that the threads
/// still finish together.
const RAY_RUN: usize = 64;

/// A ranger as the crew deals it: its model, its rays per step, and the
/// base it rides on (if any).
pub struct Job {
    pub ranger: usize,
    pub rays: usize,
    pub base: Option<usize>,
}

impl Crew {
    /// A crew of `threads` threads (one if a pool cannot be started) for
    /// `bases` bases and these rangers. Each thread gets bases in a row
    /// with their rangers, about as many rays each (a base counts as a ray
    /// for its planning); rangers on no base are dealt after the bases.
    pub fn new(threads: usize, bases: usize, jobs: &[Job]) -> Crew {
        let pool = (threads > 1)
            .then(|| {
                rayon::ThreadPoolBuilder::new()
                    .num_threads(threads - 1)
                    .thread_name(|i| format!("stage-{}", i + 1))
                    .build()
                    .map_err(|e| tracing::warn!("stage: one thread only: {e}"))
                    .ok()
            })
            .flatten();
        let threads = if pool.is_some() { threads } else { 1 };
        // Units of work: each base with its rangers, then each loose ranger.
        let mut loose = 0;
        let unit: Vec<usize> = jobs
            .iter()
            .map(|j| {
                j.base.unwrap_or_else(|| {
                    loose += 1;
                    bases + loose - 1
                })
            })
            .collect();
        let mut weight = vec![1; bases];
        weight.resize(bases + loose, 0);
        for (j, &u) in jobs.iter().zip(&unit) {
            weight[u] += j.rays;
        }
        // A unit goes to the thread its middle falls in, by running weight.
        let total: usize = weight.iter().sum::<usize>().max(1);
        let mut sum = 0;
        let owners: Vec<usize> = weight
            .iter()
            .map(|&w| {
                let t = (2 * sum + w) * threads / (2 * total);
                sum += w;
                t.min(threads - 1)
            })
            .collect();
        let starts: Vec<usize> = (0..=threads)
            .map(|t| owners.partition_point(|&o| o < t).min(bases))
            .collect();
        let mut order: Vec<usize> = (0..jobs.len()).collect();
        order.sort_by_key(|&k| (owners[unit[k]], jobs[k].rays));
        let mut ranger_ends = vec![0; threads + 1];
        for &u in &unit {
            ranger_ends[owners[u] + 1] += 1;
        }
        for t in 0..threads {
            ranger_ends[t + 1] += ranger_ends[t];
        }
        let rays: Vec<usize> = order.iter().map(|&k| jobs[k].rays).collect();
        let most = (bases / threads / BASE_RUNS).clamp(1, BASE_RUN);
        let (base_cuts, base_starts) = runs(&starts, |_| 1, most);
        let (ranger_cuts, ranger_starts) = runs(&ranger_ends, |k| rays[k].max(1), RAY_RUN);
        Crew {
            pool,
            base_cuts,
            base_starts,
            rangers: order.iter().map(|&k| jobs[k].ranger).collect(),
            ranger_cuts,
            ranger_starts,
        }
    }

    /// How many threads.
    pub fn threads(&self) -> usize {
        self.base_starts.len().saturating_sub(1).max(1)
    }

    /// The rangers in the order their shares take them (see [`Crew::rangers_to_sense`]).
    #[cfg(test)]
    pub fn rangers(&self) -> &[usize] {
        &self.rangers
    }

    /// Where each run of bases starts, then the number of bases: run `k`
    /// is bases `base_cuts()[k]..base_cuts()[k + 1]`.
    pub fn base_cuts(&self) -> &[usize] {
        &self.base_cuts
    }

    /// The rangers of each run, in [`Crew::rangers`].
    pub fn ranger_runs(&self) -> impl Iterator<Item = &[usize]> {
        self.ranger_cuts
            .windows(2)
            .map(|w| &self.rangers[w[0]..w[1]])
    }

    /// The runs of bases to plan this step, dealt: each thread's from its first.
    pub fn bases_to_plan(&self) -> Shares<'_> {
        Shares::new(self, &self.base_starts, false)
    }

    /// The runs of rangers (see [`Crew::ranger_runs`]) to sense this step,
    /// dealt: each thread's from its last, so that the robots its plans
    /// take first next step are the ones it sensed last, still in its
    /// caches (and the first it senses are the last moved).
    pub fn rangers_to_sense(&self) -> Shares<'_> {
        Shares::new(self, &self.ranger_starts, true)
    }

    /// Runs `main` on the calling thread and `helper` on each other thread
    /// of the crew; returns when all have returned.
    pub fn run(&self, helper: impl Fn() + Sync, main: impl FnOnce()) {
        match &self.pool {
            Some(pool) => {
                let running = AtomicUsize::new(self.threads() - 1);
                pool.in_place_scope(|s| {
                    for _ in 1..self.threads() {
                        s.spawn(|_| {
                            {
                                let _done = Done(&running);
                                helper();
                            }
                            // Stays awake for the next step's share: a
                            // sleeping helper takes tens of microseconds to wake.
                            rayon::spawn(stay_awake);
                        });
                    }
                    main();
                    // The helpers finish about when this thread does: spin
                    // for them, or the scope's wait puts this thread to
                    // sleep, and waking it takes longer.
                    wait_for(|| running.load(Ordering::Acquire) == 0);
                })
            }
            None => main(),
        }
    }

    /// Which of the crew the calling thread is: 0 for the one stepping
    /// the simulation (or any thread outside the crew).
    fn me(&self) -> usize {
        self.pool
            .as_ref()
            .and_then(rayon::ThreadPool::current_thread_index)
            .map_or(0, |i| i + 1)
    }
}

/// How long a thread spins waiting for the others (a hundred robots move
/// in a fifth of this), and how long it then sleeps between looks.
const SPIN: Duration = Duration::from_millis(1);
const NAP: Duration = Duration::from_micros(100);

/// Waits until `ready` says so: spinning for [`SPIN`], then napping.
pub fn wait_for(ready: impl Fn() -> bool) {
    if !troupe_node::spin_until(Instant::now() + SPIN, &ready) {
        while !ready() {
            std::thread::park_timeout(NAP);
        }
    }
}

/// Runs the pool's next job if one comes within [`SPIN`].
fn stay_awake() {
    troupe_node::spin_until(Instant::now() + SPIN, || {
        matches!(rayon::yield_now(), Some(rayon::Yield::Executed))
    });
}

/// Cuts each share `starts[t]..starts[t + 1]` into runs of items in a
/// row, each weighing at most `most` (by `weight`) unless one item alone
/// weighs more: where each run starts (then the number of items), and
/// where each share's runs start among them (then the number of runs).
fn runs(
    starts: &[usize],
    weight: impl Fn(usize) -> usize,
    most: usize,
) -> (Vec<usize>, Vec<usize>) {
    let mut cuts = Vec::new();
    let mut run_starts = Vec::with_capacity(starts.len());
    for w in starts.windows(2) {
        run_starts.push(cuts.len());
        let mut load = 0;
        for k in w[0]..w[1] {
            let wk = weight(k);
            if k == w[0] || load + wk > most {
                cuts.push(k);
                load = 0;
            }
            load += wk;
        }
    }
    run_starts.push(cuts.len());
    cuts.push(starts.last().copied().unwrap_or(0));
    (cuts, run_starts)
}

/// Counts a helper out when dropped (when it returns or panics).
struct Done<'a>(&'a AtomicUsize);

impl Drop for Done<'_> {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::Release);
    }
}

/// Items dealt in shares, one per thread of a [`Crew`]: a thread takes its
/// own from one end (the front, or the back when `backward`), then the
/// others' from the other end.
pub struct Shares<'a> {
    crew: &'a Crew,
    /// Per share, its front and back packed in one word.
    left: Vec<AtomicU64>,
    backward: bool,
}

impl<'a> Shares<'a> {
    /// Share `t` is `starts[t]..starts[t + 1]`.
    fn new(crew: &'a Crew, starts: &[usize], backward: bool) -> Shares<'a> {
        let pack = |front: usize, back: usize| ((front as u64) << 32) | back as u64;
        let left = starts
            .windows(2)
            .map(|s| AtomicU64::new(pack(s[0], s[1])))
            .collect();
        Shares {
            crew,
            left,
            backward,
        }
    }

    /// The next item for the calling thread, or `None` when all are taken.
    pub fn take(&self) -> Option<usize> {
        let n = self.left.len();
        let me = self.crew.me();
        (0..n).find_map(|k| {
            let share = &self.left[(me + k) % n];
            let mut now = share.load(Ordering::Relaxed);
            loop {
                let (front, back) = (now >> 32, now & 0xffff_ffff);
                if front >= back {
                    return None;
                }
                let (next, item) = if (k == 0) != self.backward {
                    (now + (1 << 32), front)
                } else {
                    (now - 1, back - 1)
                };
                match share.compare_exchange_weak(now, next, Ordering::Relaxed, Ordering::Relaxed) {
                    Ok(_) => return Some(item as usize),
                    Err(seen) => now = seen,
                }
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn job(ranger: usize, rays: usize, base: Option<usize>) -> Job {
        Job { ranger, rays, base }
    }

    #[test]
    fn each_thread_gets_bases_in_a_row_with_their_rangers() {
        // Four robots with a laser (180) and sonars (16), and a fixed ranger.
        let mut jobs = Vec::new();
        for b in 0..4 {
            jobs.push(job(10 + b, 16, Some(b)));
            jobs.push(job(20 + b, 180, Some(b)));
        }
        jobs.push(job(30, 50, None));
        let crew = Crew::new(2, 4, &jobs);
        assert_eq!(crew.threads(), 2);
        assert_eq!(crew.base_cuts(), [0, 1, 2, 3, 4]);
        assert_eq!(crew.base_starts, [0, 2, 4]);
        // Thread 0: robots 0 and 1; thread 1: robots 2 and 3, then the loose one.
        assert_eq!(crew.rangers, [10, 11, 20, 21, 12, 13, 30, 22, 23]);
        // Runs of up to 64 rays, or one ranger: the sonars go in pairs.
        let runs: Vec<&[usize]> = crew.ranger_runs().collect();
        assert_eq!(
            runs,
            [&[10, 11][..], &[20], &[21], &[12, 13], &[30], &[22], &[23]]
        );
        assert_eq!(crew.ranger_starts, [0, 3, 7]);
    }

    #[test]
    fn one_thread_takes_everything_once_in_order() {
        let jobs: Vec<Job> = (0..5).map(|k| job(k, k + 1, None)).collect();
        let crew = Crew::new(1, 3, &jobs);
        assert_eq!(crew.threads(), 1);
        let plan = crew.bases_to_plan();
        assert_eq!(
            std::iter::from_fn(|| plan.take()).collect::<Vec<_>>(),
            [0, 1, 2]
        );
        assert_eq!(crew.base_cuts(), [0, 1, 2, 3], "few bases: one a run");
        let crew = Crew::new(1, 300, &jobs);
        let cuts = crew.base_cuts();
        assert_eq!(
            (cuts.len(), cuts[1], cuts[37]),
            (39, 8, 296),
            "runs of eight"
        );
        assert_eq!(
            Crew::new(1, 100, &jobs).base_cuts()[1],
            3,
            "32 runs or more"
        );
        let jobs: Vec<Job> = (0..5).map(|k| job(k, 30 - 10 * (k % 3), None)).collect();
        let crew = Crew::new(1, 0, &jobs);
        assert_eq!(crew.rangers, [2, 1, 4, 0, 3], "fewest rays first");
        let sense = crew.rangers_to_sense();
        let got: Vec<usize> = std::iter::from_fn(|| sense.take()).collect();
        assert_eq!(got, [1, 0], "its own from the last");
        let runs: Vec<&[usize]> = crew.ranger_runs().collect();
        assert_eq!(runs, [&[2, 1, 4][..], &[0, 3]], "at most 64 rays a run");
    }

    #[test]
    fn a_thread_done_with_its_share_takes_the_others_from_the_other_end() {
        // The calling thread counts as thread 0.
        let crew = Crew::default();
        let shares = Shares::new(&crew, &[0, 2, 5], false);
        let got: Vec<usize> = std::iter::from_fn(|| shares.take()).collect();
        assert_eq!(got, [0, 1, 4, 3, 2]);
        let shares = Shares::new(&crew, &[0, 2, 5], true);
        let got: Vec<usize> = std::iter::from_fn(|| shares.take()).collect();
        assert_eq!(got, [1, 0, 2, 3, 4]);
        assert_eq!(Shares::new(&crew, &[], false).take(), None);
        assert_eq!(Shares::new(&crew, &[3, 3], true).take(), None);
    }

    #[test]
    fn threads_share_out_every_item_exactly_once() {
        let jobs: Vec<Job> = (0..200).map(|k| job(k, 1 + k % 7, Some(k / 2))).collect();
        let crew = Crew::new(2, 100, &jobs);
        let sense = crew.rangers_to_sense();
        let runs: Vec<&[usize]> = crew.ranger_runs().collect();
        let taken = std::sync::Mutex::new(Vec::new());
        let take = || {
            while let Some(k) = sense.take() {
                taken.lock().unwrap().extend_from_slice(runs[k]);
            }
        };
        crew.run(take, take);
        let mut taken = taken.into_inner().unwrap();
        taken.sort_unstable();
        assert_eq!(taken, (0..200).collect::<Vec<_>>());
    }
}
