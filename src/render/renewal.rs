//! How often a time-limited render renews the internal lights' set
//! ([method §7](crate::doc::method): the walk noise of one set averages out
//! only over fresh sets), balanced from what the render measures while it
//! runs.
//!
//! With `a` the per-pixel variance of one gather pass with one set, `b` the
//! variance that one set adds to every pass it renders (its walk noise),
//! `c` a pass's time and `d` a set's, a fresh set every `P` passes leaves
//! `(a + bP)(c + d/P)/T` of variance after `T` seconds, least at
//! `P* = √(ad/(bc))`. Thin media have small `b` and want long sets (the
//! suite's wispy smoke ≈ 19 passes), a thick cumulus's walks are noisy and
//! want a set every pass or two. [`BalancedRenewal`] estimates `a` from the
//! spread of the passes within each set and `b` from the spread of the
//! sets' means, pooled over the image's pixels, and sets `P` to `P*` after
//! each set once three are done (the first sets last the settings'
//! `resample_every` passes), but never so long that the sets' builds take
//! less than a tenth of the time ([`MIN_SET_SHARE`]: a small `b` is hard
//! to measure, and a period far too long costs more than one a little
//! short).
//!
//! The measured times make the schedule depend on the machine, so it is
//! for renders that stop at a time limit (which do anyway); a render of a
//! fixed sample count keeps the fixed `resample_every` and reproduces.
//!
//! Such a render's sets last unequal numbers of passes; [`WeightedSets`]
//! makes its image with each set's mean weighed by the inverse of its
//! predicted variance instead of each pass alike
//! ([method §5.5](crate::doc::method)).

use std::time::{Duration, Instant};

use glam::Vec3;

use crate::physics::internal::sources::{
    kernel_neighbours_for_noisy_set, kernel_neighbours_for_set, KERNEL_NEIGHBOURS,
};

/// The longest set a balanced schedule chooses, in passes.
pub const MAX_PERIOD: u32 = 64;

/// The least share of a pass's time that a balanced schedule spends on
/// sets: the period is at most `d / (MIN_SET_SHARE · c)` passes.
///
/// `b` is estimated from the spread of the sets' means, `b + a/n_s`, and
/// where `b` is a percent or two of `a` (thin smoke) the first sets' few
/// means cannot tell it from zero: the estimate read ≤ 0 on the suite's
/// wispy smoke and the sets grew to 64 passes, where `lantern noise`
/// measured `P* ≈ 7–18`, leaving 1.2–1.75× the variance of the best
/// period. At the best period the sets' share of the time is
/// `d/(P* c) = √(bd/(ac))` (0.14 on the wispy smoke, 0.4 on the plume), so
/// a floor of 0.1 costs at most 10 % where the sets add no noise at all.
pub const MIN_SET_SHARE: f64 = 0.1;

/// The share of a render's time limit after which its first light set's
/// walks stop ([`InternalParams::walk_deadline`](crate::physics::internal::sources::InternalParams::walk_deadline)):
/// a set that would take longer (the thick cumulus's 2.9 s against a
/// limit of 2 s) is built from fewer walks per light, leaving the rest
/// of the time for its first passes. The set's noise dominates such
/// media, so most of the time goes to it.
pub const FIRST_SET_SHARE: f64 = 0.75;

/// When the first light set's walks of a render that started at `start`
/// with a time limit of `limit` seconds stop: [`FIRST_SET_SHARE`] of the
/// limit later (`None` without a limit).
pub fn first_set_deadline(start: Instant, limit: Option<f64>) -> Option<Instant> {
    limit.map(|t| start + Duration::from_secs_f64(FIRST_SET_SHARE * t.max(0.0)))
}

/// The least share of a whole set's walks that a set begun near a
/// render's time limit walks ([`BalancedRenewal::fresh_set_share`]): where
/// a whole set and a pass no longer fit before the limit, a fresh set's
/// walks may stop after [`FIRST_SET_SHARE`] of the time left, as the first
/// set's do, if that leaves it at least this share of its walks and the
/// predicted variance says it pays.
///
/// Before, such a render ran on with the set in hand, whose passes then
/// outweighed the other sets'. The thick cumulus at `--time 16` (sets of
/// 3.4–4.3 s on two cores; seeds 31–40, each run before and after in
/// turn): 8×8 blocks 9.50 → 7.88 %, per pixel 20.62 → 18.25 %, half of
/// the renders ending with a set walked to 60–72 %
/// ([validation §3.19](crate::doc::validation)). The floor keeps a set's
/// walk noise within twice a whole one's, where the variance model (walk
/// noise `1/share`) is least sure.
pub const MIN_PARTIAL_SHARE: f64 = 0.5;

/// What a whole light set's build takes, from `secs` measured for a
/// build that walked `share` of its walks
/// ([`InternalLights::walk_share`](crate::physics::internal::sources::InternalLights::walk_share)):
/// what a balanced schedule weighs later sets by.
pub fn whole_set_secs(secs: f64, share: f64) -> f64 {
    secs / share.max(f64::EPSILON)
}

/// Sets that must be complete before the period is balanced.
const SETS_BEFORE_BALANCING: u32 = 3;

/// Sets that must be complete before a set's kernel follows the measured
/// noise ([`BalancedRenewal::kernel_neighbours`]): the fewest whose means
/// have a spread. The decision compares variances that differ by tens
/// of times on the media where it matters, which the first two sets'
/// spread over the image's pixels tells apart.
const SETS_BEFORE_KERNEL: u32 = 2;

/// The variance components and costs a balanced schedule is chosen from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenewalEstimates {
    /// Per-pixel variance of one pass with one set, averaged over the image
    /// (of the pixels' channel mean).
    pub pass_variance: f64,
    /// Per-pixel variance a set adds to each of its passes (may read
    /// slightly negative where it is small next to `pass_variance`).
    pub set_variance: f64,
    /// Seconds per pass (the set's build and the render's first pass
    /// not included: [`BalancedRenewal::add_pass`]).
    pub pass_secs: f64,
    /// Seconds per set's build.
    pub set_secs: f64,
}

impl RenewalEstimates {
    /// `P* = √(ad/(bc))` rounded and clamped to `1..=`[`longest_period`](Self::longest_period)
    /// (the longest where the sets add no measurable variance).
    pub fn best_period(&self) -> u32 {
        let (a, b, c, d) = (
            self.pass_variance,
            self.set_variance,
            self.pass_secs,
            self.set_secs,
        );
        let longest = self.longest_period();
        if b.is_nan() || b <= 0.0 || c.is_nan() || c <= 0.0 {
            return longest;
        }
        let p = (a.max(0.0) * d.max(0.0) / (b * c)).sqrt();
        if p.is_finite() {
            (p.round() as u32).clamp(1, longest)
        } else {
            longest
        }
    }

    /// The longest period these costs allow: sets take at least
    /// [`MIN_SET_SHARE`] of the passes' time (`d / (MIN_SET_SHARE · c)`
    /// rounded), between 1 and [`MAX_PERIOD`].
    pub fn longest_period(&self) -> u32 {
        let (c, d) = (self.pass_secs, self.set_secs);
        if c.is_nan() || c <= 0.0 || d.is_nan() {
            return MAX_PERIOD;
        }
        let p = (d.max(0.0) / (MIN_SET_SHARE * c)).round();
        if p.is_finite() {
            (p as u32).clamp(1, MAX_PERIOD)
        } else {
            MAX_PERIOD
        }
    }
}

/// A light-set schedule balanced while the render runs (see the module).
/// Feed it every pass ([`BalancedRenewal::add_pass`]) and every set's build
/// time ([`BalancedRenewal::add_set_build`], set 0's included); before
/// each pass after the first ask [`BalancedRenewal::next_starts_set`]. A
/// renderer that accumulates its passes elsewhere (the GPU) gives their
/// times ([`BalancedRenewal::add_pass_secs`]) and, once the set is
/// complete ([`BalancedRenewal::set_is_complete`]), the set's sums
/// ([`BalancedRenewal::replace_set_sums`]).
#[derive(Clone, Debug)]
pub struct BalancedRenewal {
    period: u32,
    /// The current set's per-pixel sum and sum of squares, and its passes.
    sum: Vec<f64>,
    squares: Vec<f64>,
    passes_in_set: u32,
    /// Pooled within-set sum of squared deviations and its degrees of
    /// freedom.
    within: f64,
    within_dof: f64,
    /// Per pixel the sum and the sum of squares of the complete sets'
    /// means.
    set_means: Vec<f64>,
    set_mean_squares: Vec<f64>,
    /// Each complete set's passes, kernel (lights it held) and share of a
    /// whole set's walks: what [`WeightedSets`] weighs it by, and what the
    /// noise model's sums over the sets (`Σ 1/n_s`, `Σ n_s²`, `Σ K/k_s`)
    /// come from.
    closed: Vec<ClosedSet>,
    /// Time spent in passes and in builds, and their counts: every pass
    /// but the render's first is timed ([`BalancedRenewal::add_pass`]).
    pass_secs: f64,
    timed_passes: u32,
    passes: u32,
    build_secs: f64,
    builds: u32,
    /// The current set's kernel (lights it holds).
    kernel: u32,
    /// [`BalancedRenewal::sets_outweigh_passes`] as decided for the
    /// current set.
    outweigh: Option<bool>,
    /// The estimates when the current set began (what the passes' spread
    /// within sets and the sets' means give; they change only as a set
    /// closes), kept for [`BalancedRenewal::noise_inflation`].
    at_set_start: Option<RenewalEstimates>,
    /// The share of a whole set's walks the current set was begun to walk
    /// ([`BalancedRenewal::fresh_set_share`]).
    planned_share: f64,
}

impl BalancedRenewal {
    /// A schedule for an image of `pixels` pixels whose first sets last
    /// `first_period` passes (at least 2, so that a set's passes measure
    /// the gather's own noise).
    pub fn new(pixels: usize, first_period: u32) -> Self {
        Self {
            period: first_period.max(2),
            sum: vec![0.0; pixels],
            squares: vec![0.0; pixels],
            passes_in_set: 0,
            within: 0.0,
            within_dof: 0.0,
            set_means: vec![0.0; pixels],
            set_mean_squares: vec![0.0; pixels],
            closed: Vec::new(),
            pass_secs: 0.0,
            timed_passes: 0,
            passes: 0,
            build_secs: 0.0,
            builds: 0,
            kernel: kernel_neighbours_for_set(0),
            outweigh: None,
            at_set_start: None,
            planned_share: 1.0,
        }
    }

    /// The pixels of the image the schedule measures.
    pub fn pixels(&self) -> usize {
        self.sum.len()
    }

    /// The current set's length in passes.
    pub fn period(&self) -> u32 {
        self.period
    }

    /// Passes of the current set so far (more than its
    /// [`period`](BalancedRenewal::period) where it ran on to a time limit,
    /// [`BalancedRenewal::next_starts_set_within`]).
    pub fn passes_in_set(&self) -> u32 {
        self.passes_in_set
    }

    /// Sets complete so far.
    pub fn complete_sets(&self) -> u32 {
        // Sets of a render: far fewer than `u32::MAX`.
        self.closed.len() as u32
    }

    /// `Σ f(s)` over the complete sets.
    fn sum_over_sets(&self, f: impl Fn(&ClosedSet) -> f64) -> f64 {
        self.closed.iter().map(f).sum()
    }

    /// Adds one pass of the current set: its image (one value per pixel)
    /// and the seconds it took.
    ///
    /// The render's first pass counts for the noise but not for the time:
    /// it holds what only a first pass pays. A GPU driver may compile the
    /// pipeline at its first dispatch (lavapipe with a cold shader cache:
    /// 11 s for the thick cumulus's first pass at 32², 0.12–0.16 s for each
    /// after it), and a mean pass time ten times too long turned the
    /// schedule's decisions around (`b d/(a c)` 0.3 against 4 with the
    /// cache warm).
    pub fn add_pass(&mut self, image: &[Vec3], secs: f64) {
        for ((s, q), v) in self.sum.iter_mut().zip(&mut self.squares).zip(image) {
            let x = f64::from(v.x + v.y + v.z) / 3.0;
            *s += x;
            *q += x * x;
        }
        self.add_pass_secs(secs);
    }

    /// Adds one pass of the current set whose image is accumulated
    /// elsewhere (on the GPU), and the seconds it took: the set's per-pixel
    /// sums come at its end from [`BalancedRenewal::replace_set_sums`].
    /// As in [`BalancedRenewal::add_pass`], the render's first pass is not
    /// timed.
    pub fn add_pass_secs(&mut self, secs: f64) {
        if self.passes > 0 {
            self.pass_secs += secs;
            self.timed_passes += 1;
        }
        self.passes_in_set += 1;
        self.passes += 1;
    }

    /// Whether the current set has its passes: the next
    /// [`BalancedRenewal::next_starts_set`] closes it.
    pub fn set_is_complete(&self) -> bool {
        self.passes_in_set >= self.period
    }

    /// Gives the current set's per-pixel sum and sum of squares over its
    /// passes (of the channels' mean, one pair per pixel), as a GPU
    /// renderer's accumulated moments tell them
    /// ([`crate::gpu::GpuImage::grey_sums`], the difference between the
    /// read-backs at the set's ends), in place of the images
    /// [`BalancedRenewal::add_pass`] would have summed. A slice of the wrong
    /// length is ignored.
    pub fn replace_set_sums(&mut self, sums: &[(f64, f64)]) {
        if sums.len() != self.sum.len() {
            return;
        }
        for ((s, q), &(sum, squares)) in self.sum.iter_mut().zip(&mut self.squares).zip(sums) {
            *s = sum;
            *q = squares;
        }
    }

    /// Adds the seconds one set's build took.
    pub fn add_set_build(&mut self, secs: f64) {
        self.build_secs += secs;
        self.builds += 1;
    }

    /// Whether the next pass starts a new set: the current one has its
    /// passes. If so, the current set's statistics are closed, the period
    /// rebalanced and the new set's kernel chosen
    /// ([`BalancedRenewal::kernel_neighbours`]).
    pub fn next_starts_set(&mut self) -> bool {
        self.begin_set(1.0)
    }

    /// [`BalancedRenewal::next_starts_set`] for a set planned to walk
    /// `share` of a whole set's walks (as
    /// [`BalancedRenewal::fresh_set_share`] chose;
    /// [`BalancedRenewal::planned_share`] then tells it).
    pub fn begin_set(&mut self, share: f64) -> bool {
        if self.passes_in_set < self.period {
            return false;
        }
        self.close_set();
        // One pass over the pixels for both choices: the period waits for
        // more sets than the kernel.
        let estimates = self.estimates_after(SETS_BEFORE_KERNEL);
        if let Some(e) = estimates.filter(|_| self.complete_sets() >= SETS_BEFORE_BALANCING) {
            self.period = e.best_period();
        }
        self.outweigh = estimates.map(|e| self.outweighs(&e));
        self.at_set_start = estimates;
        self.kernel = self.scheduled_kernel(self.complete_sets());
        self.planned_share = share;
        true
    }

    /// [`BalancedRenewal::next_starts_set`] for a render that stops
    /// `remaining` seconds from now (`None`: no limit): a set that has its
    /// passes runs on instead of closing where a fresh one does not pay
    /// before the limit, and a fresh set may be planned to walk part of its
    /// walks ([`BalancedRenewal::fresh_set_share`],
    /// [`BalancedRenewal::planned_share`]). Without it a render that stops
    /// at a time overshoots by a whole set's build when it begins one just
    /// before the limit (2.8 s on the thick cumulus).
    pub fn next_starts_set_within(&mut self, remaining: Option<f64>) -> bool {
        if self.passes_in_set < self.period {
            return false;
        }
        let share = match remaining {
            None => 1.0,
            Some(r) => match self.fresh_set_share(r) {
                Some(share) => share,
                None => return false,
            },
        };
        self.begin_set(share)
    }

    /// Whether a fresh set begun now, `remaining` seconds before a render's
    /// limit, leaves a less noisy image at the limit than the current set
    /// running on to it, and what share of a whole set's walks it walks:
    /// `Some(1.0)` for a whole set, `Some(share)` for one whose walks stop
    /// early, `None` where the current set should run on. From the mean
    /// build and pass times measured so far (`d`, `c`):
    ///
    /// - where a whole set and a pass fit, the set is whole; where they do
    ///   not, its walks stop after [`FIRST_SET_SHARE`] of the time left
    ///   (`share = ¾ · remaining / d`), and no set begins where that share
    ///   is below [`MIN_PARTIAL_SHARE`], leaves no time for a pass, or
    ///   cannot be weighed (no estimates yet);
    /// - the set begins where its walks and a whole period fit (the
    ///   balanced schedule's own choice); in between, the variance of the
    ///   image as [`WeightedSets`] will make it, `1/Σ_s 1/v_s` with each
    ///   set's `v_s = a/n_s + b_K (K/k_s)/f_s` ([`SetNoise`]), is compared
    ///   for the two ways of spending the time: the current set's passes
    ///   run on, or it closes and the fresh set (its kernel the schedule's
    ///   next, its walks `share`) takes the passes that fit after its
    ///   build; `a` and `b_K` are the estimates of when the current set
    ///   began. Without them (before two sets are complete) a whole fresh
    ///   set begins and a partial one does not: where `b` is small (thin
    ///   smoke at 1–2 s) a partial set only takes passes away (validation
    ///   §3.19).
    ///
    /// (Until the sets were weighed by their noise this predicted the
    /// passes' mean, `a/n + b Σ n_s²/n²`, in which a fresh set of one or
    /// two passes counts for little however noisy the sets are.)
    pub fn fresh_set_share(&self, remaining: f64) -> Option<f64> {
        let (c, d) = self.mean_secs();
        let share = if d + c <= remaining {
            1.0
        } else if d > 0.0 && self.at_set_start.is_some() {
            (FIRST_SET_SHARE * remaining / d).min(1.0)
        } else {
            return None;
        };
        if share < MIN_PARTIAL_SHARE || share * d + c > remaining {
            return None;
        }
        if c <= 0.0 || remaining >= share * d + f64::from(self.period) * c {
            return Some(share);
        }
        let Some(e) = self.at_set_start else {
            return Some(share);
        };
        let noise = SetNoise {
            pass_variance: e.pass_variance.max(0.0),
            set_variance: (e.set_variance / self.narrowing()).max(0.0),
        };
        // Passes of at most a few thousand: the casts cannot overflow.
        let kept = (remaining / c).floor().min(f64::from(u32::MAX)) as u32;
        let fresh = ((remaining - share * d) / c)
            .floor()
            .clamp(1.0, f64::from(u32::MAX)) as u32;
        let current = self.passes_in_set;
        let next_kernel = self.scheduled_kernel(self.complete_sets() + 1);
        let keeping = self.weighed_variance(
            &noise,
            &[ClosedSet {
                passes: current + kept,
                kernel: self.kernel,
                share: self.planned_share,
            }],
        );
        let renewing = self.weighed_variance(
            &noise,
            &[
                ClosedSet {
                    passes: current,
                    kernel: self.kernel,
                    share: self.planned_share,
                },
                ClosedSet {
                    passes: fresh,
                    kernel: next_kernel,
                    share,
                },
            ],
        );
        (renewing < keeping).then_some(share)
    }

    /// The per-pixel variance of the image [`WeightedSets`] makes of the
    /// complete sets and `more`, each set's mean weighed by the inverse of
    /// its variance under `noise`: `1/Σ_s 1/v_s`. Where the sets add no
    /// noise (`b` = 0) it is `a/n`, the passes' mean over all `n` passes.
    fn weighed_variance(&self, noise: &SetNoise, more: &[ClosedSet]) -> f64 {
        let inverse: f64 = self
            .closed
            .iter()
            .chain(more)
            .filter(|s| s.passes > 0)
            .map(|s| 1.0 / noise.set_mean_variance(s.passes, s.kernel, s.share))
            .filter(|w| w.is_finite())
            .sum();
        if inverse > 0.0 {
            1.0 / inverse
        } else {
            f64::INFINITY
        }
    }

    /// The share of a whole set's walks the current set was planned to
    /// walk: 1, or less where it began near a render's time limit
    /// ([`BalancedRenewal::next_starts_set_within`]).
    pub fn planned_share(&self) -> f64 {
        self.planned_share
    }

    /// When the walks of the current set, whose build begins at `start`,
    /// stop: its [`planned_share`](BalancedRenewal::planned_share) of the
    /// mean build time measured so far; `None` for a whole set.
    pub fn walk_deadline(&self, start: Instant) -> Option<Instant> {
        let (share, d) = (self.planned_share, self.mean_secs().1);
        (share < 1.0).then(|| start + Duration::from_secs_f64((share * d).max(0.0)))
    }

    /// Lights the automatic kernel of the current set holds: set 0 and
    /// every set while two are not yet complete, as every render's
    /// ([`kernel_neighbours_for_set`]); later sets likewise where the
    /// passes' noise outweighs the sets', but a kernel that shrinks more
    /// slowly ([`kernel_neighbours_for_noisy_set`], `64/√(j+1)`) where the
    /// sets' noise outweighs the passes'
    /// ([`BalancedRenewal::sets_outweigh_passes`]).
    ///
    /// The kernel shrinks over a render's sets because its blur is a bias
    /// that the sets' average keeps while their noise averages away
    /// ([method §6.2](crate::doc::method)); a narrower kernel holds fewer
    /// lights and each set is noisier (about `1/k`). Where the walks are
    /// quiet next to the gather (thin smoke) the image's error is the
    /// passes' noise and the blur, and shrinking pays. Where they are not
    /// (a thick cumulus: one set's sd was 170 % of the image mean per
    /// pixel against 60 % for a pass), the image's error is the sets' noise
    /// for a long while, and a kernel holding 16 lights had 1.8× the
    /// per-pixel error of one holding 64 at 8 s; but after tens of sets the
    /// blur of a kernel kept at 64 was what remained (the cumulus's
    /// shadowed underside 13 % too bright), hence the slower shrink there.
    pub fn kernel_neighbours(&self) -> u32 {
        self.kernel
    }

    /// The kernel set `set` (from 0) holds under the current decision
    /// whether the sets outweigh the passes: the slow schedule where they
    /// do, the fixed one otherwise.
    fn scheduled_kernel(&self, set: u32) -> u32 {
        match self.outweigh {
            Some(true) => kernel_neighbours_for_noisy_set(set),
            _ => kernel_neighbours_for_set(set),
        }
    }

    /// Whether the light sets add more noise to the image than the passes
    /// at the balanced period, `b d ≥ a c` (`b P* ≥ a` at `P* = √(ad/(bc))`:
    /// the set variance `b/n` of the mean of `n` sets against the passes'
    /// `a/(n P*)`), with `b` scaled to the first set's kernel (`b` grows as
    /// `1/k`: the sets measured may have had narrower ones), as decided
    /// when the current set began, from the sets complete then (what its
    /// kernel follows; kept, so that asking costs nothing). `None` while
    /// fewer than two sets were complete.
    pub fn sets_outweigh_passes(&self) -> Option<bool> {
        self.outweigh
    }

    /// Why the current set's kernel holds what it holds, in words (for the
    /// command line's summary).
    pub fn kernel_reason(&self) -> &'static str {
        match self.sets_outweigh_passes() {
            Some(true) => "shrinking slowly: the sets' noise outweighs the passes'",
            Some(false) => "shrunk: the passes' noise outweighs the sets'",
            None => "as scheduled",
        }
    }

    /// [`BalancedRenewal::sets_outweigh_passes`] for estimates `e` of the
    /// complete sets.
    fn outweighs(&self, e: &RenewalEstimates) -> bool {
        let b = e.set_variance / self.narrowing();
        b * e.set_secs >= e.pass_variance * e.pass_secs
    }

    fn close_set(&mut self) {
        let n = f64::from(self.passes_in_set);
        if n == 0.0 {
            return;
        }
        let pixels = self.sum.len();
        for i in 0..pixels {
            let (s, q) = (self.sum[i], self.squares[i]);
            let m = s / n;
            self.within += (q - s * m).max(0.0);
            self.set_means[i] += m;
            self.set_mean_squares[i] += m * m;
        }
        self.within_dof += pixels as f64 * (n - 1.0);
        self.closed.push(ClosedSet {
            passes: self.passes_in_set,
            kernel: self.kernel,
            share: self.planned_share,
        });
        self.sum.fill(0.0);
        self.squares.fill(0.0);
        self.passes_in_set = 0;
    }

    /// How much the image's noise exceeds what its passes' spread says:
    /// the factor on the variance of a pixel's mean over all passes so far.
    ///
    /// A pixel's passes spread by their own noise `a` and, across sets, by
    /// the sets' `b`; passes of one set share its lights. After `n` passes
    /// in sets of `n_s`, the mean's variance is `a/n + b Σn_s²/n²`, but
    /// the spread of all the passes, `s²`, is on average
    /// `a + b (n − Σn_s²/n)/(n − 1)` (one-way analysis of variance), and
    /// `s²/n` is what a noise figure from the passes reads. The ratio is 1
    /// for a fresh set every pass and `1 + b n/a` for one set throughout.
    /// `None` until two sets are complete (with `b` clamped at 0).
    /// Asked after every pass (the previewer's overlay), it reads the
    /// estimates kept when the set began rather than going over the pixels.
    pub fn noise_inflation(&self) -> Option<f64> {
        let e = self.at_set_start?;
        let n = f64::from(self.passes);
        if n < 2.0 {
            return None;
        }
        let (a, b) = (e.pass_variance, e.set_variance.max(0.0));
        let current = f64::from(self.passes_in_set);
        let squares = self.sum_over_sets(|s| f64::from(s.passes).powi(2)) + current * current;
        let truth = a + b * squares / n;
        let spread = a + b * (n - squares / n) / (n - 1.0);
        (spread > 0.0 && truth.is_finite()).then(|| (truth / spread).max(1.0))
    }

    /// The estimates once three sets are complete, at least one with two
    /// passes, and a build has been timed. The set means' spread is
    /// `b + a · mean(1/n_s)` (independent sets of `n_s` passes, each
    /// mean's variance `b + a/n_s`), which gives `b`.
    pub fn estimates(&self) -> Option<RenewalEstimates> {
        self.estimates_after(SETS_BEFORE_BALANCING)
    }

    /// What a light set's mean is weighed by in the image
    /// ([`WeightedSets`]): the per-pixel variance of one pass `a` and the
    /// variance a set of [`KERNEL_NEIGHBOURS`] lights adds `b_K` (the
    /// measured `b` scaled as [`BalancedRenewal::sets_outweigh_passes`]
    /// scales it), from the sets complete so far; `None` while fewer than
    /// two are.
    pub fn set_noise(&self) -> Option<SetNoise> {
        let e = self.estimates_after(SETS_BEFORE_KERNEL)?;
        Some(SetNoise {
            pass_variance: e.pass_variance.max(0.0),
            set_variance: (e.set_variance / self.narrowing()).max(0.0),
        })
    }

    /// How much noisier the complete sets were for their kernels than sets
    /// of [`KERNEL_NEIGHBOURS`] lights: the mean of `K/k` over them (a set's
    /// noise grows as `1/k`), at least 1.
    fn narrowing(&self) -> f64 {
        let factors =
            self.sum_over_sets(|s| f64::from(KERNEL_NEIGHBOURS) / f64::from(s.kernel.max(1)));
        (factors / f64::from(self.complete_sets().max(1))).max(1.0)
    }

    /// [`BalancedRenewal::set_noise`] as if the current set closed now
    /// with its passes so far: what an image read now weighs its sets by
    /// ([`WeightedSets::mean`]). A render that stops at a limit often ends
    /// in its second set, and from the first set alone there is no `b`.
    pub fn set_noise_now(&self) -> Option<SetNoise> {
        if self.passes_in_set == 0 {
            return self.set_noise();
        }
        let mut closed = self.clone();
        closed.close_set();
        closed.set_noise()
    }

    /// [`BalancedRenewal::set_noise_now`] for a renderer that accumulates
    /// its passes elsewhere (the GPU): `sums` are the current set's per-pixel
    /// sums so far, as [`BalancedRenewal::replace_set_sums`] takes them.
    pub fn set_noise_now_with(&self, sums: &[(f64, f64)]) -> Option<SetNoise> {
        if self.passes_in_set == 0 {
            return self.set_noise();
        }
        let mut closed = self.clone();
        closed.replace_set_sums(sums);
        closed.close_set();
        closed.set_noise()
    }

    /// [`BalancedRenewal::estimates`] once `sets` sets are complete.
    fn estimates_after(&self, sets: u32) -> Option<RenewalEstimates> {
        if self.complete_sets() < sets.max(2)
            || self.within_dof <= 0.0
            || self.builds == 0
            || self.timed_passes == 0
            || self.sum.is_empty()
        {
            return None;
        }
        let k = f64::from(self.complete_sets());
        let a = self.within / self.within_dof;
        let spread: f64 = self
            .set_means
            .iter()
            .zip(&self.set_mean_squares)
            .map(|(&s, &q)| (q - s * s / k).max(0.0))
            .sum::<f64>()
            / (self.sum.len() as f64 * (k - 1.0));
        let (pass_secs, set_secs) = self.mean_secs();
        Some(RenewalEstimates {
            pass_variance: a,
            set_variance: spread - a * self.sum_over_sets(|s| 1.0 / f64::from(s.passes)) / k,
            pass_secs,
            set_secs,
        })
    }

    /// The mean seconds of a timed pass and of a set's build (0 before
    /// any).
    fn mean_secs(&self) -> (f64, f64) {
        let mean = |total: f64, count: u32| {
            if count > 0 {
                total / f64::from(count)
            } else {
                0.0
            }
        };
        (
            mean(self.pass_secs, self.timed_passes),
            mean(self.build_secs, self.builds),
        )
    }
}

/// A complete light set as [`WeightedSets`] weighs it: its passes, the
/// lights its kernel held and the share of a whole set's walks it walked.
#[derive(Clone, Copy, Debug, PartialEq)]
struct ClosedSet {
    passes: u32,
    kernel: u32,
    share: f64,
}

/// The noise model a set's weight comes from ([`BalancedRenewal::set_noise`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SetNoise {
    /// Per-pixel variance of one pass with one set, `a`.
    pub pass_variance: f64,
    /// Per-pixel variance one set of [`KERNEL_NEIGHBOURS`] lights, walked
    /// to all of its walks, adds to each of its passes, `b_K` (`K` =
    /// [`KERNEL_NEIGHBOURS`]).
    pub set_variance: f64,
}

impl SetNoise {
    /// The variance of the mean of a set's `passes` passes, for a set whose
    /// kernel holds `kernel` lights and whose walks stopped at `share` of a
    /// whole set's: `a/n + b_K (K/k)/share` (a set's noise grows as `1/k`
    /// as its kernel narrows, [method §6.2](crate::doc::method), and as
    /// `1/share` as its walks are cut, §5.5).
    pub fn set_mean_variance(&self, passes: u32, kernel: u32, share: f64) -> f64 {
        let narrowing = f64::from(KERNEL_NEIGHBOURS) / f64::from(kernel.max(1));
        self.pass_variance / f64::from(passes.max(1))
            + self.set_variance * narrowing / share.clamp(f64::EPSILON, 1.0)
    }
}

/// One light set's passes: their per-pixel sums, how many, and what the
/// set's weight depends on.
#[derive(Clone, Debug)]
struct SetSums {
    sum: Vec<[f64; 3]>,
    passes: u32,
    kernel: u32,
    share: f64,
}

impl SetSums {
    fn new(pixels: usize, kernel: u32, share: f64) -> Self {
        Self {
            sum: vec![[0.0; 3]; pixels],
            passes: 0,
            kernel,
            share,
        }
    }
}

/// The image of a render whose light sets last unequal numbers of passes
/// (a balanced schedule's first sets, the set that runs on to a time
/// limit, [`BalancedRenewal::next_starts_set_within`]): each set's mean
/// weighed by the inverse of its variance ([`SetNoise`]), instead of each
/// pass alike.
///
/// Where the sets' noise outweighs the passes' (the thick cumulus), a
/// set's mean is about as noisy after two passes as after eight, and a
/// mean over passes gives a set that ran on four times the weight of the
/// others: at `--time 7` the cumulus's three sets of 2, 2 and 7–8 passes,
/// weighed by their passes, read 8×8 blocks 8.00 %, per pixel 17.85 %;
/// weighed by their variance 7.29 / 16.62 % (the same eight renders,
/// [validation §3.24](crate::doc::validation)). Where the passes' noise
/// dominates (thin smoke) the weights are the passes' counts, as before.
/// Any weights fixed apart from the sets' own pixels keep the image's
/// expectation (every set's mean is unbiased); these come from the noise
/// pooled over the whole image and all sets.
///
/// A set that closes before the schedule can weigh it (the first: the
/// sets' noise needs two) is held and weighed when it can; an image read
/// during the second set is weighed with the noise as if that set closed
/// as it stands ([`BalancedRenewal::set_noise_now`]); before that, and
/// where the noise cannot weigh a set, the image is the mean of the
/// passes.
#[derive(Clone, Debug)]
pub struct WeightedSets {
    /// `Σ w_s mean_s` per pixel over the sets weighed so far, and `Σ w_s`.
    weighed: Vec<[f64; 3]>,
    weight: f64,
    /// Sets closed before they could be weighed.
    held: Vec<SetSums>,
    /// The set whose passes are being added.
    current: SetSums,
}

impl WeightedSets {
    /// An image of `pixels` pixels whose first set's kernel holds `kernel`
    /// lights and whose walks stopped at `share` of a whole set's.
    pub fn new(pixels: usize, kernel: u32, share: f64) -> Self {
        Self {
            weighed: vec![[0.0; 3]; pixels],
            weight: 0.0,
            held: Vec::new(),
            current: SetSums::new(pixels, kernel, share),
        }
    }

    /// Adds one pass of the current set (non-finite channels count as
    /// zero, as [`Film::add_pass`](crate::render::Film::add_pass) counts
    /// them).
    pub fn add_pass(&mut self, image: &[Vec3]) {
        for (s, v) in self.current.sum.iter_mut().zip(image) {
            for c in 0..3 {
                s[c] += if v[c].is_finite() {
                    f64::from(v[c])
                } else {
                    0.0
                };
            }
        }
        self.current.passes += 1;
    }

    /// Replaces the current set's sums with `sum` over `passes` passes
    /// (per pixel, summed elsewhere: the GPU's accumulated moments read
    /// back at the set's ends). A slice of the wrong length is ignored.
    pub fn replace_current(&mut self, sum: Vec<[f64; 3]>, passes: u32) {
        if sum.len() == self.current.sum.len() {
            self.current.sum = sum;
            self.current.passes = passes;
        }
    }

    /// Passes of the current set so far.
    pub fn current_passes(&self) -> u32 {
        self.current.passes
    }

    /// Closes the current set, weighed with `noise` (or held until a
    /// later call has it), and begins one whose kernel holds `kernel`
    /// lights and whose walks stopped at `share` of a whole set's.
    pub fn next_set(&mut self, noise: Option<SetNoise>, kernel: u32, share: f64) {
        let pixels = self.current.sum.len();
        let done = std::mem::replace(&mut self.current, SetSums::new(pixels, kernel, share));
        if done.passes > 0 {
            self.held.push(done);
        }
        if let Some(noise) = noise {
            for set in std::mem::take(&mut self.held) {
                let w = 1.0 / noise.set_mean_variance(set.passes, set.kernel, set.share);
                if !(w.is_finite() && w > 0.0) {
                    // No variance to weigh by: the passes' counts.
                    self.held.push(set);
                    continue;
                }
                let per_pass = w / f64::from(set.passes);
                for (acc, s) in self.weighed.iter_mut().zip(&set.sum) {
                    for c in 0..3 {
                        acc[c] += per_pass * s[c];
                    }
                }
                self.weight += w;
            }
        }
    }

    /// The image: the weighed sets' means, and the held sets' and the
    /// current set's weighed with `noise` where it is known (by their
    /// passes otherwise).
    pub fn mean(&self, noise: Option<SetNoise>) -> Vec<Vec3> {
        let weight_of = |set: &SetSums| -> f64 {
            noise
                .map(|n| 1.0 / n.set_mean_variance(set.passes, set.kernel, set.share))
                .filter(|w| w.is_finite() && *w > 0.0)
                .unwrap_or(f64::from(set.passes))
        };
        let open: Vec<(&SetSums, f64)> = self
            .held
            .iter()
            .chain(std::iter::once(&self.current))
            .filter(|s| s.passes > 0)
            .map(|s| (s, weight_of(s)))
            .collect();
        // Without the noise every set weighs its passes (`weight` is then
        // 0: nothing was weighed), and the image is the passes' mean.
        let total = self.weight + open.iter().map(|(_, w)| w).sum::<f64>();
        if total <= 0.0 {
            return vec![Vec3::ZERO; self.weighed.len()];
        }
        (0..self.weighed.len())
            .map(|i| {
                let mut v = self.weighed[i];
                for (set, w) in &open {
                    let per_pass = w / f64::from(set.passes);
                    for (acc, s) in v.iter_mut().zip(set.sum[i]) {
                        *acc += per_pass * s;
                    }
                }
                Vec3::new(
                    (v[0] / total) as f32,
                    (v[1] / total) as f32,
                    (v[2] / total) as f32,
                )
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::rng::Rng;

    /// A standard normal draw (Box–Muller).
    fn normal(rng: &mut Rng) -> f64 {
        let (u1, u2) = (rng.next_f32().max(1e-7) as f64, rng.next_f32() as f64);
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }

    /// One pass's image: 1 plus the set's per-pixel `effect` plus
    /// independent noise of variance `a`.
    fn pass_image(effect: &[f64], a: f64, rng: &mut Rng) -> Vec<Vec3> {
        effect
            .iter()
            .map(|&e| Vec3::splat((1.0 + e + a.sqrt() * normal(rng)) as f32))
            .collect()
    }

    /// Runs a balanced schedule over `passes` passes of `pixels` pixels
    /// made as [`pass_image`] makes them, each set with a fresh effect of
    /// variance `b`, passes taking `c` seconds and sets `d`; `each` sees
    /// every pass's image. Returns the schedule and the period chosen at
    /// each new set.
    fn run_schedule(
        pixels: usize,
        passes: u32,
        (a, b, c, d): (f64, f64, f64, f64),
        rng: &mut Rng,
        mut each: impl FnMut(&[Vec3]),
    ) -> (BalancedRenewal, Vec<u32>) {
        let mut renewal = BalancedRenewal::new(pixels, 2);
        renewal.add_set_build(d);
        let mut effect: Vec<f64> = (0..pixels).map(|_| b.sqrt() * normal(rng)).collect();
        let mut periods = Vec::new();
        for pass in 0..passes {
            if pass > 0 && renewal.next_starts_set() {
                periods.push(renewal.period());
                for e in &mut effect {
                    *e = b.sqrt() * normal(rng);
                }
                renewal.add_set_build(d);
            }
            let image = pass_image(&effect, a, rng);
            each(&image);
            renewal.add_pass(&image, c);
        }
        (renewal, periods)
    }

    /// A schedule in the middle of a render: three complete sets of ten
    /// passes and a fourth with its ten, passes of 0.1 s, builds of 1 s,
    /// and estimates `a` = 1 and `b`.
    fn mid_render(b: f64) -> BalancedRenewal {
        let mut r = BalancedRenewal::new(4, 10);
        r.closed = vec![
            ClosedSet {
                passes: 10,
                kernel: KERNEL_NEIGHBOURS,
                share: 1.0,
            };
            3
        ];
        r.passes = 40;
        r.passes_in_set = 10;
        r.pass_secs = 3.9;
        r.timed_passes = 39;
        r.build_secs = 4.0;
        r.builds = 4;
        r.at_set_start = Some(RenewalEstimates {
            pass_variance: 1.0,
            set_variance: b,
            pass_secs: 0.1,
            set_secs: 1.0,
        });
        r
    }

    /// A render's image weighs each light set's mean by the inverse of its
    /// variance `a/n + b (K/k)/share` (`K` the first set's kernel,
    /// [`KERNEL_NEIGHBOURS`]) once the noise is known, and by the
    /// passes before: sets closed before it are held and weighed at the
    /// first close that knows it, and the current set is weighed as it
    /// stands. Here `a = b = 1` (one pixel, each pass of set `s` reading
    /// `s + 1`): sets of 2, 2 and 8 passes with `K` lights weigh `2/3`,
    /// `2/3` and `8/9`, where their passes would weigh 2, 2 and 8; a set
    /// of `K/2` lights walked to half of its walks adds about `4 b`.
    #[test]
    fn light_sets_are_weighed_by_their_noise() {
        let noise = SetNoise {
            pass_variance: 1.0,
            set_variance: 1.0,
        };
        let (k, half) = (KERNEL_NEIGHBOURS, KERNEL_NEIGHBOURS / 2);
        let narrow = 0.25 + f64::from(k) / f64::from(half) / 0.5;
        assert_eq!(noise.set_mean_variance(2, k, 1.0), 1.5);
        assert!((noise.set_mean_variance(4, half, 0.5) - narrow).abs() < 1e-12);
        let pass = |v: f32| [Vec3::splat(v)];
        let mut sets = WeightedSets::new(1, k, 1.0);
        for _ in 0..2 {
            sets.add_pass(&pass(1.0));
        }
        // Before the noise is known: the mean of the passes.
        sets.next_set(None, k, 1.0);
        for _ in 0..2 {
            sets.add_pass(&pass(2.0));
        }
        assert_eq!(sets.mean(None), vec![Vec3::splat(1.5)]);
        sets.next_set(Some(noise), k, 1.0);
        assert!(sets.held.is_empty(), "the held sets are weighed");
        for _ in 0..8 {
            sets.add_pass(&pass(3.0));
        }
        assert_eq!(sets.current_passes(), 8);
        let (w1, w3) = (2.0 / 3.0, 8.0 / 9.0);
        let want = (w1 * 1.0 + w1 * 2.0 + w3 * 3.0) / (2.0 * w1 + w3);
        let got = sets.mean(Some(noise))[0];
        assert!(
            (f64::from(got.x) - want).abs() < 1e-6,
            "{got} against {want}"
        );
        let by_passes = (2.0 + 4.0 + 24.0) / 12.0;
        assert!((f64::from(got.x) - by_passes).abs() > 0.1);
        // Sums given whole (the GPU's read-backs) replace the passes'.
        sets.replace_current(vec![[12.0; 3]], 4);
        let w = 1.0 / 1.25;
        let want = (w1 * 1.0 + w1 * 2.0 + w * 3.0) / (2.0 * w1 + w);
        let got = sets.mean(Some(noise))[0];
        assert!(
            (f64::from(got.y) - want).abs() < 1e-6,
            "{got} against {want}"
        );
        // A narrower kernel and a partial set weigh less.
        sets.next_set(Some(noise), half, 0.5);
        for _ in 0..4 {
            sets.add_pass(&pass(5.0));
        }
        let w4 = 1.0 / narrow;
        let want = (w1 * 1.0 + w1 * 2.0 + w * 3.0 + w4 * 5.0) / (2.0 * w1 + w + w4);
        let got = sets.mean(Some(noise))[0];
        assert!(
            (f64::from(got.z) - want).abs() < 1e-6,
            "{got} against {want}"
        );
    }

    /// On a schedule of noisy sets whose last set runs on (sets of 2, 2
    /// and 8 passes, `b = a`), the sets weighed by their noise keep the
    /// image's mean and leave less variance than the passes' mean, as the
    /// model says: `1/Σ(1/v_s)` = 0.45 against `Σ (n_s/n)² v_s` = 0.583,
    /// with `v_s = a/n_s + b`. 4000 images of one pixel each, within 10 %;
    /// the schedule's prediction near a time limit is the same 0.45.
    #[test]
    fn weighed_sets_keep_the_mean_and_lower_the_variance() {
        let noise = SetNoise {
            pass_variance: 1.0,
            set_variance: 1.0,
        };
        let mut rng = Rng::for_sample(17, 0, 0);
        let (mut weighed, mut by_passes) = (Vec::new(), Vec::new());
        for _ in 0..4000 {
            let mut sets = WeightedSets::new(1, KERNEL_NEIGHBOURS, 1.0);
            let mut all = 0.0;
            for (s, n) in [2u32, 2, 8].into_iter().enumerate() {
                if s > 0 {
                    sets.next_set(Some(noise), KERNEL_NEIGHBOURS, 1.0);
                }
                let effect = normal(&mut rng);
                for _ in 0..n {
                    let v = (1.0 + effect + normal(&mut rng)) as f32;
                    sets.add_pass(&[Vec3::splat(v)]);
                    all += f64::from(v);
                }
            }
            weighed.push(f64::from(sets.mean(Some(noise))[0].x));
            by_passes.push(all / 12.0);
        }
        let stats = |x: &[f64]| {
            let m = x.iter().sum::<f64>() / x.len() as f64;
            let v = x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (x.len() - 1) as f64;
            (m, v)
        };
        let ((mw, vw), (mp, vp)) = (stats(&weighed), stats(&by_passes));
        // 1/Σ(1/v_s) = 1/(2/1.5 + 1/1.125); (4·1.5 + 4·1.5 + 64·1.125)/144.
        for (m, v) in [(mw, vw), (mp, vp)] {
            assert!((m - 1.0).abs() < 4.0 * (v / 4000.0).sqrt(), "mean {m}");
        }
        assert!((vw / 0.45 - 1.0).abs() < 0.1, "weighed variance {vw}");
        // What a schedule predicts for the same sets, near a time limit
        // (`BalancedRenewal::fresh_set_share`), is that variance.
        let set = |passes| ClosedSet {
            passes,
            kernel: KERNEL_NEIGHBOURS,
            share: 1.0,
        };
        let mut schedule = BalancedRenewal::new(1, 2);
        schedule.closed = vec![set(2), set(2)];
        let predicted = schedule.weighed_variance(&noise, &[set(8)]);
        assert!((predicted - 0.45).abs() < 1e-12, "predicted {predicted}");
        assert!((vp / 0.583 - 1.0).abs() < 0.1, "passes' variance {vp}");
    }

    /// Near a time limit a fresh set begins only if it pays: always where
    /// its build and its period fit, by the predicted variance of the
    /// weighed sets where only its build and a pass do, and where not even
    /// those fit, walked to a share of its walks (¾ of the time left over a
    /// whole set's build) if that share is at least half and pays. Three
    /// sets of ten passes and a fourth with its ten, all of 45 lights (`a`
    /// = 1): with 1.5 s left, running on gives the fourth set 15 more
    /// passes (`v = 1/25 + b`), a fresh set, whose kernel holds 16 lights,
    /// 5 passes of its own (`1/5 + 2.8125 b`); the weighed sets' variance
    /// `1/Σ 1/v_s` is lower with the fresh set where `b` is 0.3 (0.0913
    /// against 0.0958), not where it is 0.01 (0.0245 against 0.0212).
    /// With 1.05 s left a whole set and a pass do not fit; a set walked to
    /// 0.7875 of its walks leaves 2 passes (`1/2 + 2.8125 b / 0.7875`
    /// against 10 more passes of the fourth set): it pays at 0.3 (0.0940
    /// against 0.0966), not at 0.01. With 0.6 s left the share would be
    /// 0.45.
    #[test]
    fn a_fresh_set_begins_near_the_limit_only_where_it_pays() {
        let noisy_sets = mid_render(0.3);
        let quiet_sets = mid_render(0.01);
        for r in [&noisy_sets, &quiet_sets] {
            assert_eq!(
                r.fresh_set_share(2.05),
                Some(1.0),
                "a build and a period fit"
            );
            assert_eq!(r.fresh_set_share(0.6), None, "less than half a set fits");
        }
        assert_eq!(noisy_sets.fresh_set_share(1.5), Some(1.0));
        assert_eq!(quiet_sets.fresh_set_share(1.5), None);
        // At `b` 0.1 the passes' mean, `a/n + b Σn_s²/n²`, would have
        // renewed (`a/45 + 425 b/45²` against `a/55 + 925 b/55²`), but in
        // the weighed image the fresh set's five noisier passes add less
        // than fifteen more passes of the set in hand (0.04529 against
        // 0.04516).
        assert_eq!(mid_render(0.1).fresh_set_share(1.5), None);
        let partial = noisy_sets.fresh_set_share(1.05);
        assert!(
            partial.is_some_and(|f| (f - 0.7875).abs() < 1e-12),
            "{partial:?}"
        );
        assert_eq!(quiet_sets.fresh_set_share(1.05), None);
        let mut limited = mid_render(0.01);
        assert!(!limited.next_starts_set_within(Some(1.5)));
        assert_eq!(limited.passes_in_set, 10, "the set runs on");
        assert!(limited.next_starts_set_within(None));
        assert_eq!((limited.passes_in_set, limited.complete_sets()), (0, 4));
        assert_eq!(limited.planned_share(), 1.0);
        let mut unmeasured = mid_render(0.3);
        unmeasured.at_set_start = None;
        assert_eq!(
            unmeasured.fresh_set_share(1.05),
            None,
            "no estimates: runs on"
        );
        assert_eq!(unmeasured.fresh_set_share(1.5), Some(1.0));
        let mut cut = mid_render(0.3);
        assert!(cut.next_starts_set_within(Some(1.05)));
        assert!((cut.planned_share() - 0.7875).abs() < 1e-12);
        let start = Instant::now();
        let deadline = cut.walk_deadline(start);
        assert_eq!(deadline, Some(start + Duration::from_secs_f64(0.7875)));
        assert_eq!(limited.walk_deadline(start), None, "a whole set");
    }

    /// A render to a limit of 8 s whose sets take 2.8 s to build and whose
    /// passes 0.07 s (the thick cumulus on two cores) ends within a pass of
    /// the limit: the set in hand runs on where a whole fresh one would
    /// end past it (at 5.88 s one set is complete, too few to tell whether
    /// a set walked to part of its walks would pay). Asked without the
    /// limit, the same schedule begins a third set at 5.88 s and ends at
    /// 8.75 s.
    #[test]
    fn a_timed_render_ends_within_a_pass_of_its_limit() {
        let (c, d, limit) = (0.07, 2.8, 8.0);
        let mut rng = Rng::for_sample(5, 0, 0);
        for bounded in [true, false] {
            let mut r = BalancedRenewal::new(16, 2);
            r.add_set_build(d);
            let mut t = d;
            let mut passes = 0;
            let mut shares = Vec::new();
            while passes == 0 || t < limit {
                let remaining = bounded.then_some(limit - t);
                if passes > 0 && r.next_starts_set_within(remaining) {
                    // The set's build as measured, and as a whole set's.
                    t += d * r.planned_share();
                    r.add_set_build(d);
                    shares.push(r.planned_share());
                }
                let image = pass_image(&[0.0; 16], 1.0, &mut rng);
                r.add_pass(&image, c);
                t += c;
                passes += 1;
            }
            if bounded {
                assert!(t < limit + c + 1e-9, "ended at {t} s");
                assert_eq!(shares, [1.0], "a second, whole set began");
            } else {
                assert!(t > limit + 0.7, "ended at {t} s without the limit");
                assert_eq!(shares, [1.0, 1.0]);
            }
        }
    }

    /// A first pass that took 100× the others (a driver compiling its
    /// pipeline at the first dispatch) does not count for the pass time,
    /// for passes given as images or as times: it is counted as a pass,
    /// untimed, and the estimates read the other passes' time (0.1 s; a
    /// timed first pass would make it 0.595 s).
    #[test]
    fn the_first_pass_is_not_timed() {
        let image = [Vec3::ONE; 4];
        let mut by_images = BalancedRenewal::new(4, 2);
        let mut by_times = BalancedRenewal::new(4, 2);
        for r in [&mut by_images, &mut by_times] {
            r.add_set_build(1.0);
        }
        by_images.add_pass(&image, 10.0);
        by_times.add_pass_secs(10.0);
        for r in [&mut by_images, &mut by_times] {
            assert_eq!(r.timed_passes, 0);
        }
        for pass in 1..20 {
            if by_images.next_starts_set() {
                by_images.add_set_build(1.0);
            }
            // Passes of one set differ, so that the spread within sets is
            // measured.
            let x = if pass % 2 == 0 { 1.0 } else { 2.0 };
            by_images.add_pass(&[Vec3::splat(x); 4], 0.1);
            if by_times.next_starts_set() {
                by_times.add_set_build(1.0);
            }
            by_times.add_pass_secs(0.1);
            by_times.replace_set_sums(&[(3.0, 5.0); 4]);
        }
        for r in [&by_images, &by_times] {
            let e = r.estimates().expect("estimates after ten sets");
            assert!((e.pass_secs - 0.1).abs() < 1e-9, "{e:?}");
            assert_eq!(r.passes, 20);
        }
    }

    /// Passes made of a per-pixel set effect of variance `b`, shared by a
    /// set's passes, plus independent pass noise of variance `a`: the
    /// schedule recovers both (within 10 %) and chooses `√(ad/(bc))`.
    #[test]
    fn recovers_the_variance_components_and_the_best_period() {
        let (a, b, c, d) = (4.0f64, 0.25f64, 0.1f64, 0.4f64);
        let mut rng = Rng::for_sample(5, 0, 0);
        let (renewal, periods) = run_schedule(4096, 200, (a, b, c, d), &mut rng, |_| {});
        let e = renewal.estimates().expect("estimates after 200 passes");
        assert!((e.pass_variance / a - 1.0).abs() < 0.1, "{e:?}");
        assert!((e.set_variance / b - 1.0).abs() < 0.1, "{e:?}");
        assert!((e.pass_secs - c).abs() < 1e-9 && (e.set_secs - d).abs() < 1e-9);
        // √(4 · 0.4 / (0.25 · 0.1)) = 8.
        assert_eq!(e.best_period(), 8, "{e:?}");
        assert_eq!(
            &periods[..2],
            &[2, 2],
            "the first sets keep the given period"
        );
        assert!(
            periods[periods.len() - 3..]
                .iter()
                .all(|&p| (7..=9).contains(&p)),
            "{periods:?}"
        );
    }

    /// The noise of the image's mean against what its passes' spread
    /// says, on passes made as in
    /// [`recovers_the_variance_components_and_the_best_period`] (sets of
    /// about 8 passes): the passes' spread reads about 0.7 of the mean
    /// squared error over the pixels, the spread times
    /// [`BalancedRenewal::noise_inflation`] the error itself (within 10 %);
    /// with a fresh set every pass the factor is 1.
    #[test]
    fn noise_inflation_accounts_for_the_sets() {
        let (a, b, c, d) = (4.0f64, 0.25f64, 0.1f64, 0.4f64);
        let pixels = 4096;
        let mut rng = Rng::for_sample(9, 0, 0);
        let (mut sum, mut squares) = (vec![0.0f64; pixels], vec![0.0f64; pixels]);
        let passes = 200;
        let (renewal, _) = run_schedule(pixels, passes, (a, b, c, d), &mut rng, |image| {
            for ((s, q), v) in sum.iter_mut().zip(&mut squares).zip(image) {
                let x = f64::from(v.x);
                *s += x;
                *q += x * x;
            }
        });
        let n = f64::from(passes);
        // The truth is 1 in every pixel.
        let error: f64 = sum.iter().map(|s| (s / n - 1.0).powi(2)).sum::<f64>() / pixels as f64;
        let spread: f64 = sum
            .iter()
            .zip(&squares)
            .map(|(s, q)| (q - s * s / n) / (n - 1.0) / n)
            .sum::<f64>()
            / pixels as f64;
        let inflation = renewal.noise_inflation().expect("two sets complete");
        println!(
            "spread / error {:.3}, inflation {inflation:.3}",
            spread / error
        );
        assert!(spread / error < 0.8, "{spread} {error}");
        assert!(
            (spread * inflation / error - 1.0).abs() < 0.1,
            "{spread} × {inflation} against {error}"
        );

        // Free sets: after the first three (two passes each, the least a
        // schedule starts with) a fresh set every pass.
        let (every_pass, _) = run_schedule(1024, 60, (a, b, c, 0.0), &mut rng, |_| {});
        assert_eq!(every_pass.period(), 1);
        // Σn_s² = 3·4 + 54 against n = 60: a factor of about 1.003.
        let f = every_pass.noise_inflation().expect("sets complete");
        assert!((1.0..1.02).contains(&f), "{f}");
    }

    /// Without set noise the sets grow to the longest period the costs
    /// allow; with set noise that dominates, one pass per set.
    #[test]
    fn the_period_follows_the_balance() {
        let none = RenewalEstimates {
            pass_variance: 1.0,
            set_variance: -0.001,
            pass_secs: 0.1,
            set_secs: 0.4,
        };
        // 0.4 / (0.1 · 0.1) = 40 passes: sets take a tenth of the time.
        assert_eq!(none.best_period(), 40);
        let long_builds = RenewalEstimates {
            set_secs: 4.0,
            ..none
        };
        assert_eq!(long_builds.best_period(), MAX_PERIOD);
        let light = RenewalEstimates {
            set_variance: 1e-4,
            ..none
        };
        // P* = √(0.4 / (1e-4 · 0.1)) = 200, held at 40.
        assert_eq!(light.best_period(), 40);
        let heavy = RenewalEstimates {
            set_variance: 10.0,
            ..none
        };
        assert_eq!(heavy.best_period(), 1);
        let cheap_sets = RenewalEstimates {
            set_variance: 0.01,
            set_secs: 0.0,
            ..none
        };
        assert_eq!(cheap_sets.best_period(), 1, "free sets: renew every pass");
    }

    /// The kernels a balanced schedule gives its sets, on passes made as in
    /// [`recovers_the_variance_components_and_the_best_period`] but with
    /// each set's effect of variance `b_K · K/k` for the kernel of `k`
    /// lights it was given (a kernel average of independent lights; `K`
    /// the first set's, [`KERNEL_NEIGHBOURS`]). The first two sets always
    /// take the schedule's `K` and `K/2`; then where the sets' noise
    /// outweighs the passes' (`b_K d ≥ a c`) the kernel shrinks slowly
    /// ([`kernel_neighbours_for_noisy_set`]), and where it does not as
    /// [`kernel_neighbours_for_set`] — also when the narrower kernels'
    /// sets, measured unscaled, would outweigh the passes (`b_K` 0.6
    /// against `a c/d` 1, the sets at 16 lights 1.7).
    #[test]
    fn the_kernel_shrinks_slowly_where_the_sets_outweigh_the_passes() {
        let kernels = |a: f64, b_k: f64, c: f64, d: f64| {
            let pixels = 4096;
            let mut rng = Rng::for_sample(9, 0, 0);
            let mut renewal = BalancedRenewal::new(pixels, 2);
            renewal.add_set_build(d);
            let mut kernels = vec![renewal.kernel_neighbours()];
            let mut effect = vec![0.0f64; pixels];
            let draw = |k: u32, effect: &mut Vec<f64>, rng: &mut Rng| {
                let sd = (b_k * f64::from(KERNEL_NEIGHBOURS) / f64::from(k)).sqrt();
                for e in effect.iter_mut() {
                    *e = sd * normal(rng);
                }
            };
            draw(kernels[0], &mut effect, &mut rng);
            for pass in 0..120 {
                if pass > 0 && renewal.next_starts_set() {
                    kernels.push(renewal.kernel_neighbours());
                    draw(renewal.kernel_neighbours(), &mut effect, &mut rng);
                    renewal.add_set_build(d);
                }
                renewal.add_pass(&pass_image(&effect, a, &mut rng), c);
            }
            (kernels, renewal.sets_outweigh_passes())
        };
        let (noisy_sets, outweigh) = kernels(1.0, 4.0, 0.1, 0.4);
        let first_two = [0, 1].map(kernel_neighbours_for_set);
        assert_eq!(&noisy_sets[..2], &first_two, "{noisy_sets:?}");
        assert!(noisy_sets.len() > 6, "{noisy_sets:?}");
        for (j, &k) in noisy_sets.iter().enumerate().skip(2) {
            assert_eq!(
                k,
                kernel_neighbours_for_noisy_set(j as u32),
                "{noisy_sets:?}"
            );
        }
        assert_eq!(outweigh, Some(true));
        let shrunk =
            |sets: usize| -> Vec<u32> { (0..sets as u32).map(kernel_neighbours_for_set).collect() };
        assert_eq!(shrunk(4), [45, 22, 16, 16]);
        let (quiet_sets, outweigh) = kernels(4.0, 0.25, 0.1, 0.4);
        assert_eq!(quiet_sets, shrunk(quiet_sets.len()));
        assert_eq!(outweigh, Some(false));
        let (scaled, outweigh) = kernels(1.0, 0.6, 1.0, 1.0);
        assert_eq!(scaled, shrunk(scaled.len()));
        assert_eq!(outweigh, Some(false));
    }

    /// A schedule given each set's sums at its end, as differences of
    /// running sums ([`BalancedRenewal::replace_set_sums`]: what a GPU
    /// renderer's read-backs give), chooses what one fed every pass's
    /// image chooses: the same periods and kernels, the same estimates to
    /// rounding. The noise an image read mid-set weighs its sets by
    /// ([`BalancedRenewal::set_noise_now`], `…_with` the set's sums so far)
    /// is known from the second set on, is the same both ways, and is what
    /// the schedule's own [`BalancedRenewal::set_noise`] reads once that
    /// set closes.
    #[test]
    fn set_sums_from_running_moments_match_the_passes() {
        let (a, b, c, d) = (1.0f64, 2.0f64, 0.1f64, 0.4f64);
        let pixels = 1024;
        let mut rng = Rng::for_sample(3, 0, 0);
        let mut by_pass = BalancedRenewal::new(pixels, 2);
        let mut by_sums = BalancedRenewal::new(pixels, 2);
        by_pass.add_set_build(d);
        by_sums.add_set_build(d);
        let mut running = vec![(0.0f64, 0.0f64); pixels];
        let mut at_set_start = running.clone();
        let mut effect: Vec<f64> = (0..pixels).map(|_| b.sqrt() * normal(&mut rng)).collect();
        let mut schedules = Vec::new();
        for pass in 0..100 {
            if pass > 0 {
                let set: Vec<(f64, f64)> = running
                    .iter()
                    .zip(&at_set_start)
                    .map(|(r, s)| (r.0 - s.0, r.1 - s.1))
                    .collect();
                let (now, now_with) = (by_pass.set_noise_now(), by_sums.set_noise_now_with(&set));
                assert_eq!(now.is_some(), by_pass.complete_sets() >= 1, "pass {pass}");
                if let (Some(n), Some(m)) = (now, now_with) {
                    assert!((n.pass_variance / m.pass_variance - 1.0).abs() < 1e-9);
                    assert!((n.set_variance / m.set_variance - 1.0).abs() < 1e-9);
                }
                if by_sums.set_is_complete() {
                    by_sums.replace_set_sums(&set);
                    at_set_start.clone_from(&running);
                }
                let (p, q) = (by_pass.next_starts_set(), by_sums.next_starts_set());
                assert_eq!(p, q, "pass {pass}");
                if p {
                    assert_eq!(by_pass.set_noise(), now, "pass {pass}");
                    schedules.push((by_pass.period(), by_pass.kernel_neighbours()));
                    assert_eq!(
                        (by_sums.period(), by_sums.kernel_neighbours()),
                        schedules[schedules.len() - 1]
                    );
                    for e in &mut effect {
                        *e = b.sqrt() * normal(&mut rng);
                    }
                    by_pass.add_set_build(d);
                    by_sums.add_set_build(d);
                }
            }
            let image = pass_image(&effect, a, &mut rng);
            for (r, v) in running.iter_mut().zip(&image) {
                let x = f64::from(v.x + v.y + v.z) / 3.0;
                *r = (r.0 + x, r.1 + x * x);
            }
            by_pass.add_pass(&image, c);
            by_sums.add_pass_secs(c);
        }
        let (e, f) = (by_pass.estimates(), by_sums.estimates());
        let (e, f) = (e.expect("estimates"), f.expect("estimates"));
        assert!(
            (e.pass_variance / f.pass_variance - 1.0).abs() < 1e-9,
            "{e:?} {f:?}"
        );
        assert!(
            (e.set_variance / f.set_variance - 1.0).abs() < 1e-9,
            "{e:?} {f:?}"
        );
        assert!(schedules.len() > 10, "{schedules:?}");
        // `schedules[i]` is set `i + 1`'s; from set 2 the sets outweigh
        // the passes and the kernel shrinks slowly.
        for (i, &(_, k)) in schedules.iter().enumerate().skip(1) {
            assert_eq!(
                k,
                kernel_neighbours_for_noisy_set(i as u32 + 1),
                "{schedules:?}"
            );
        }
    }
}
