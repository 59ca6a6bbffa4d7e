//! The clock that gates the internal lights' walks: what it counts between
//! gates (distance, or grey optical depth), and how it is marched along a
//! ray ([method §3 and §7](crate::doc::method)).
//!
//! [method §7](crate::doc::method) also allows the clock `dτ = c dℓ`. With RGB extinction one
//! clock must serve all channels; this module uses the **grey extinction
//! `c_g = max(σ_t) ρ`** (the channel that scatters most, which is also what
//! the majorant grid bounds). In a grey medium real collisions are then a
//! Poisson process of rate 1 in `τ`, so each window of length `τ*` holds
//! Poisson(`τ*`) collisions whatever the density. The same derivation with
//! `dℓ = dτ / c_g` gives `L = ∫ dτ E[W(τ) (S₁/c_g)(y(τ))]`, so in τ-time the
//! series is `J^τ_k(z, n) = E[W(kτ*) (S₁/c_g)(z_k, n_k)]`. So that a final
//! gather integrates either clock over geometric distance,
//! `L₀ = ∫_{window} dt T(x, y_t) Ĵ(y_t)`, [`accumulate_j`](super::walk::Walks::accumulate_j) returns
//! `Ĵ_k = c_g(z) J^τ_k = ρ(z) · W · α σ_t (S₁/b)(z_k, n_k)`, which is
//! `S₁(z, n)` for `k = 0` exactly as with the geometric clock, and zero in
//! empty space (in τ-time light crosses empty space instantly). The
//! internal-light term `L₁` uses `Ĵ` in place of `J` for the same reason.
//!
//! The optical depth along a straight flight is integrated by the midpoint
//! rule on a lattice anchored at the start of each flight and of each
//! majorant cell, of steps of at most a quarter of the window `s*` in
//! majorant optical depth (at most [`CLOCK_MAX_STEPS`] per cell, one where
//! the cell is thinner than that: `clock_step`), shifted by a phase hashed
//! from the ray's direction ([`lattice_phase`]). Anchored at the same
//! place on every ray, the lattice's error at a sharp edge was a smooth
//! function of where the edge fell on it, and drew rings about the image's
//! centre on a homogeneous sphere lit from behind the camera; with the
//! phase that error is noise between rays with a mean of zero
//! ([validation](crate::doc::validation) §3.1). The steps must stay short
//! next to the window: a clock whose rate is averaged over longer
//! stretches, even with the stretch's optical depth exact, puts more than
//! `s*` of real optical depth into windows where the density is above the
//! stretch's mean, and the single-scatter window then loses light (§3.12).
//! The clock is that quadrature;
//! the collisions themselves come from spectral tracking against the true
//! `c`, so the walk stays unbiased for `L` whatever the quadrature error.
//! A walk marches its clock only when the next gate may be near: the
//! majorant optical depth that tracking draws anyway bounds the quadrature
//! from above, so flights far from a gate stay pending and are marched
//! only once a gate may come (`LazyClock`), and a walk that leaves the
//! medium before its next gate never marches its last flights.

use glam::Vec3;

use crate::physics::rng::{pcg_hash, unit};
use crate::physics::volume::{DensityField, Volume};

/// What the walk's clock counts between gates: the settings' enum, one
/// for the scene file, the command line, the estimators and the GPU.
pub use crate::scene::settings::Clock;

/// Parameters of the time-gated walk.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GateSettings {
    /// Window length `s*` (a distance, or an optical depth for
    /// [`Clock::OpticalDepth`]).
    pub s_star: f32,
    /// Series truncation `N`: gates `k = 0..=N`.
    pub n_terms: u32,
    /// What the clock counts.
    pub clock: Clock,
    /// Real collisions after which Russian roulette starts.
    pub rr_start: u32,
}

/// Terms of the series a walk's output resolves one by one. A truncation
/// `N` beyond it still runs the walks to gate `N` (the image is the whole
/// series up to `N`), but the terms `k ≥ RESOLVED_TERMS` share the last
/// slot of the per-term outputs ([`GateSettings::term_slots`]): their sum
/// is all that the lights, the gather and the energies' plot need, and it
/// keeps each light's storage (and the GPU walks' private arrays) bounded
/// whatever `N`.
pub const RESOLVED_TERMS: u32 = 256;

impl GateSettings {
    /// Slots of a walk's per-term output, `min(N, RESOLVED_TERMS) + 1`:
    /// slot `k` holds term `k`, except the last one, which holds every term
    /// from it to `N` ([`term_slot`]).
    #[inline]
    pub fn term_slots(&self) -> usize {
        term_slots(self.n_terms)
    }
}

/// Slots of the per-term outputs for a truncation `N` of `n_terms`,
/// `min(N, RESOLVED_TERMS) + 1` ([`GateSettings::term_slots`]).
#[inline]
pub fn term_slots(n_terms: u32) -> usize {
    n_terms.min(RESOLVED_TERMS) as usize + 1
}

/// The slot of a walk's per-term output that term `k` adds to: `k`, or
/// the last slot, [`RESOLVED_TERMS`], for the terms beyond it.
#[inline]
pub fn term_slot(k: u32) -> usize {
    k.min(RESOLVED_TERMS) as usize
}

/// The rate `d(clock)/dℓ` at `p`: 1 for the geometric clock, the grey
/// extinction `max(σ_t) ρ(p)` for the optical-depth clock.
#[inline]
pub fn clock_rate<D: DensityField>(vol: &Volume<D>, clock: Clock, p: Vec3) -> f32 {
    match clock {
        Clock::Geometric => 1.0,
        Clock::OpticalDepth => vol.optics.sigma_t.max_element() * vol.density.density(p),
    }
}

/// The largest majorant optical depth of one step of the optical-depth
/// clock's quadrature, as a fraction of the window `s*` (the WGSL's is
/// generated from it).
pub const CLOCK_SPLIT_WINDOW: f32 = 0.25;

/// The most quadrature steps of the optical-depth clock in one majorant
/// cell (a bound on the work per cell in media far denser than the window;
/// the WGSL's is generated from it).
pub const CLOCK_MAX_STEPS: f32 = 64.0;

/// The smallest extent of a majorant cell: the optical-depth clock's
/// lattice step in a cell thin enough for one step (see [`clock_step`]).
#[inline]
pub(super) fn clock_cell<D: DensityField>(vol: &Volume<D>) -> f32 {
    vol.majorants.cell.min_element().max(1e-12)
}

/// The optical-depth clock's quadrature step in a majorant cell of
/// extinction majorant `m` under the window `s_star`, `cell` being
/// [`clock_cell`]: the cell cut into the fewest equal steps whose majorant
/// optical depth is at most a quarter of the window
/// ([`CLOCK_SPLIT_WINDOW`]; at most [`CLOCK_MAX_STEPS`] of them).
///
/// The midpoint rule takes each step's rate from the density at its
/// middle, so where a step is longer than the window the window's end
/// lands off by a good part of it, and on which side depends on where the
/// lattice (anchored at each flight's start and each cell) happens to
/// fall. With at most two steps per cell, as before, a cumulus of optical
/// depth ≈ 30 (σ_t 40, cells ≈ 3 mean free paths) came out 12 % dark at
/// `s*` 0.5 and 16 % at 0.25, whatever the lights, walks or harmonics;
/// with these steps +0.7 % (128², 8 light sets).
#[inline]
pub(super) fn clock_step(cell: f32, m: f32, s_star: f32) -> f32 {
    let steps = (m * cell / (CLOCK_SPLIT_WINDOW * s_star)).ceil();
    if steps > 1.0 {
        cell / steps.min(CLOCK_MAX_STEPS)
    } else {
        cell
    }
}

/// Low bits of each direction component that [`lattice_phase`] leaves
/// out of its hash: the CPU and the GPU compute a ray's direction to
/// within a few units in the last place (their square roots, sines and
/// cosines differ), and a hash of every bit would give the two backends
/// unrelated lattices for what is one ray, so that the same random
/// numbers would no longer give the same estimate. Without these 8 bits a
/// component still resolves 2⁻¹⁵ of its magnitude, far finer than the
/// directions of two camera samples or two scatterings differ.
pub const PHASE_DROPPED_BITS: u32 = 8;

/// The phase `φ ∈ (0, 1]` of the optical-depth clock's lattice along the
/// ray `origin + t dir`: in each majorant cell `[a, b]` the ray crosses,
/// the steps' ends are `a + (i + φ) h`, `i = 0, 1, …` (cut at `b`).
///
/// A hash of the ray's direction, so that every march along one ray
/// measures the same clock (the window's end and the clock at each gather
/// point agree; a walk's flight that goes on from a gate keeps its
/// lattice), while neighbouring rays and each pass's jittered camera ray
/// get unrelated phases. (Not of its origin: points that two ways of
/// summing the same clock put a rounding error apart would get unrelated
/// lattices.) With a lattice anchored at `a` alone (`φ = 1` on every
/// ray), the midpoint rule's error at a sharp edge, up to the step's
/// optical depth, was a smooth function of where the edge fell on the
/// lattice: on a homogeneous sphere seen from the sun's side it drew
/// concentric rings centred on the image (where the edge's depth along the
/// ray changes slowest). With a phase drawn per ray the same error is
/// noise that averages away over the pixel's rays, and the midpoint
/// rule's expected optical depth over the phase is the exact one in every
/// whole step (see `lattice_phase_leaves_no_bias_at_an_edge`). Mirrored in
/// `shaders/common/gated_walk.wgsl`.
#[inline]
pub fn lattice_phase(dir: Vec3) -> f32 {
    let s = pcg_hash(dir.z.to_bits() >> PHASE_DROPPED_BITS);
    let s = pcg_hash((dir.y.to_bits() >> PHASE_DROPPED_BITS) ^ s);
    let s = pcg_hash((dir.x.to_bits() >> PHASE_DROPPED_BITS) ^ s);
    1.0 - unit(s)
}

/// The `i`-th step of the optical-depth clock's lattice in the cell
/// `[a, b]`, `[a + (i − 1 + φ) h, a + (i + φ) h]` cut to the cell
/// ([`lattice_phase`]), and where its rate is sampled.
///
/// A whole step is sampled at its middle. The two steps that the cell's
/// faces cut are not: the midpoint of `[a, a + φ h]` puts, over the phase,
/// a weight `4 (x − a) / h` on `x ∈ [a, a + h/2]` instead of one, a bias
/// of up to `h/8` of the rate's jump at an edge just inside a cell (a ball
/// whose surface meets a cell face). Sampled at `a + φ² h / 2` the first
/// step weighs every point of `[a, a + h/2]` once, and the last,
/// `[b − ℓ, b]`, at `b − ℓ² / (2h)` every point of `[b − h/2, b]`, so that
/// in a cell longer than `h` the expected clock over the phase is the
/// exact optical depth. A cell shorter than one step keeps its midpoint.
#[inline]
fn lattice_step(a: f32, b: f32, h: f32, phase: f32, i: u32) -> (f32, f32, f32) {
    let end = a + (i as f32 + phase) * h;
    if i == 0 {
        return if end < b {
            (a, end, a + 0.5 * phase * phase * h)
        } else {
            (a, b, 0.5 * (a + b))
        };
    }
    let p0 = a + (i as f32 - 1.0 + phase) * h;
    if end < b {
        (p0, end, 0.5 * (p0 + end))
    } else {
        let l = (b - p0).max(0.0);
        (p0, b, b - 0.5 * l * l / h)
    }
}

/// The optical-depth clock's midpoint lattice along one ray: in each
/// majorant cell `[a, b]` the ray crosses, the steps of [`lattice_step`],
/// each counted at the grey extinction at its sample point — the
/// lattice [`march_clock`] steps through from a flight's start, for a
/// flight that counts its clock stretch by stretch between tentative
/// collisions. It remembers the step it is in, so that a step cut into
/// several stretches is sampled once. (`march_clock` keeps its own plain
/// loop: on the gather's hot path it is 4 % faster than going through
/// this; `lazy_clock_finds_the_same_gates` would see the two disagree.)
pub(super) struct ClockLattice<'v, D> {
    vol: &'v Volume<D>,
    origin: Vec3,
    dir: Vec3,
    cell: f32,
    s_star: f32,
    sigma_g: f32,
    /// The ray's [`lattice_phase`].
    phase: f32,
    /// The step it is in: its cell's start (NaN: none yet), its index in
    /// the cell, its end and its rate.
    cell_start: f32,
    index: u32,
    end: f32,
    rate: f32,
}

impl<'v, D: DensityField> ClockLattice<'v, D> {
    pub(super) fn new(vol: &'v Volume<D>, s_star: f32, origin: Vec3, dir: Vec3) -> Self {
        Self {
            vol,
            origin,
            dir,
            cell: clock_cell(vol),
            s_star,
            sigma_g: vol.optics.sigma_t.max_element(),
            phase: lattice_phase(dir),
            cell_start: f32::NAN,
            index: 0,
            end: 0.0,
            rate: 0.0,
        }
    }

    /// Adds the clock over `[from, to]` of the cell `(a, b, m)` (the stretch
    /// `[a, b]` of the ray, majorant `m`) to `acc`,
    /// `from` being where the previous stretch in the cell ended (or
    /// anywhere, in a new cell); returns where `acc` reaches `budget`, if it
    /// does (`acc` is then left short of it).
    #[inline]
    pub(super) fn advance(
        &mut self,
        (a, b, m): (f32, f32, f32),
        from: f32,
        to: f32,
        acc: &mut f32,
        budget: f32,
    ) -> Option<f32> {
        let h = clock_step(self.cell, m, self.s_star);
        let mut t = from;
        while t < to {
            if self.cell_start != a || self.end <= t {
                // The step holding `t`: stretches within a cell are
                // contiguous, so the next one, or in a new cell the one
                // `t` falls in (and past any step that rounding ends at or
                // before `t`).
                let phase = self.phase;
                let i = if self.cell_start == a {
                    self.index + 1
                } else {
                    let mut i = ((t - a) / h + 1.0 - phase).max(0.0) as u32;
                    while a + (i as f32 + phase) * h <= t {
                        i += 1;
                    }
                    i
                };
                let (_, p1, at) = lattice_step(a, b, h, phase, i);
                let mid = self.origin + self.dir * at;
                self.rate = self.sigma_g * self.vol.density.density(mid);
                (self.cell_start, self.index, self.end) = (a, i, p1);
            }
            let end = self.end.min(to);
            let d = self.rate * (end - t).max(0.0);
            if self.rate > 0.0 && *acc + d >= budget {
                return Some((t + (budget - *acc) / self.rate).min(end));
            }
            *acc += d;
            t = end;
        }
        None
    }
}

/// A ray the clock is marched along: `origin + t dir` from `t = 0` up to
/// `t_exit`, where it leaves the medium's box, with the clock and the
/// window `s_star` (which fixes the optical-depth clock's quadrature
/// lattice).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClockRay {
    /// What the clock counts.
    pub clock: Clock,
    /// The window `s*`.
    pub s_star: f32,
    /// The ray's origin (inside or on the medium's box).
    pub origin: Vec3,
    /// Its unit direction.
    pub dir: Vec3,
    /// Where it leaves the box.
    pub t_exit: f32,
}

/// Where a clock budget runs out along a ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ClockMarch {
    /// The clock reached the budget at this ray parameter.
    Reached(f32),
    /// The ray reached its end first; the clock advanced by this much.
    Exhausted(f32),
}

/// Advances the clock along `ray` from `t0` (inside or on the medium's
/// box) towards `t_stop ≤ ray.t_exit`. Returns where the clock has
/// advanced by `budget`, or how far it advanced by `t_stop`. For the
/// optical-depth clock the quadrature lattice depends on the ray and `t0`
/// only, so calls that differ in `t_stop` or `budget` measure the same
/// clock.
pub fn march_clock<D: DensityField>(
    vol: &Volume<D>,
    ray: &ClockRay,
    t0: f32,
    t_stop: f32,
    budget: f32,
) -> ClockMarch {
    march_clock_rate(vol, ray, t0, t_stop, budget).0
}

/// The optical-depth clock's midpoint lattice along `ray` from `t0` to
/// its exit: in each majorant cell `[a, b]` the ray crosses, the steps of
/// [`lattice_step`] ([`clock_step`] long, at the ray's [`lattice_phase`]),
/// each passed to `step(p0, p1, c)` with `c` the grey extinction at its
/// sample point; a cell
/// whose majorant is zero is one step of rate zero. Stops when `step`
/// returns false. What [`march_clock_rate`] and [`clock_at_each`] count
/// (whatever `ray.clock` says).
#[inline]
fn clock_steps<D: DensityField>(
    vol: &Volume<D>,
    ray: &ClockRay,
    t0: f32,
    mut step: impl FnMut(f32, f32, f32) -> bool,
) {
    let &ClockRay {
        s_star,
        origin,
        dir,
        t_exit,
        ..
    } = ray;
    let cell = clock_cell(vol);
    let sigma_g = vol.optics.sigma_t.max_element();
    let phase = lattice_phase(dir);
    vol.majorants.walk(origin, dir, t0, t_exit, |a, b, m| {
        if m <= 0.0 {
            // The majorant bounds ρ: nothing to count in this cell.
            return step(a, b, 0.0);
        }
        let h = clock_step(cell, m, s_star);
        let mut i = 0u32;
        loop {
            let (p0, p1, at) = lattice_step(a, b, h, phase, i);
            if p0 >= b {
                return true;
            }
            let c = sigma_g * vol.density.density(origin + dir * at);
            if !step(p0, p1, c) {
                return false;
            }
            i += 1;
        }
    });
}

/// [`march_clock`], and where the budget was reached the clock's rate
/// there, `d(clock)/dt` of the quadrature step that holds the point (one
/// for the geometric clock; zero when the budget is not reached or is not
/// positive): the density of the points that a budget drawn uniformly
/// puts along the ray, per unit of the budget's range.
pub fn march_clock_rate<D: DensityField>(
    vol: &Volume<D>,
    ray: &ClockRay,
    t0: f32,
    t_stop: f32,
    budget: f32,
) -> (ClockMarch, f32) {
    let t_stop = t_stop.min(ray.t_exit);
    if ray.clock == Clock::Geometric {
        let span = (t_stop - t0).max(0.0);
        return if span >= budget {
            (ClockMarch::Reached(t0 + budget.max(0.0)), 1.0)
        } else {
            (ClockMarch::Exhausted(span), 0.0)
        };
    }
    if budget <= 0.0 {
        return (ClockMarch::Reached(t0), 0.0);
    }
    let mut acc = 0.0f32;
    let mut result = None;
    clock_steps(vol, ray, t0, |p0, p1, c| {
        if p0 >= t_stop {
            return false;
        }
        let end = p1.min(t_stop);
        let d_tau = c * (end - p0).max(0.0);
        if c > 0.0 && acc + d_tau >= budget {
            result = Some((ClockMarch::Reached((p0 + (budget - acc) / c).min(end)), c));
            return false;
        }
        acc += d_tau;
        p1 < t_stop
    });
    result.unwrap_or((ClockMarch::Exhausted(acc), 0.0))
}

/// The clock from the ray's origin to each of the points
/// `origin + ts[j] dir` (`ts` ascending, within `[0, t_exit]`) in one
/// march: `out[j]` is what `march_clock` with `t0 = 0`, `t_stop = ts[j]`
/// and an unlimited budget returns (the same lattice, anchored at the
/// origin; equal up to rounding). The final gather's points need their
/// clock from the window's start for `L₁`'s budget: one march for all of
/// them instead of one each (stretches between the points, each on its
/// own lattice, had shifted the budgets with the number of points: +2 %
/// in `L₁` at 32 points on the puffs).
pub fn clock_at_each<D: DensityField>(
    vol: &Volume<D>,
    ray: &ClockRay,
    ts: &[f32],
    out: &mut [f32],
) {
    let n = ts.len().min(out.len());
    if ray.clock == Clock::Geometric {
        for (o, &t) in out[..n].iter_mut().zip(ts) {
            *o = t.clamp(0.0, ray.t_exit.max(0.0));
        }
        return;
    }
    let mut acc = 0.0f32;
    let mut k = 0usize;
    clock_steps(vol, ray, 0.0, |p0, p1, c| {
        while k < n && ts[k] <= p1 {
            out[k] = acc + c * (ts[k] - p0).max(0.0);
            k += 1;
        }
        acc += c * (p1 - p0);
        k < n
    });
    for o in &mut out[k..n] {
        *o = acc;
    }
}

/// The clock's advance along the ray from its origin (inside or on the
/// box) over `[0, t]`, `t` clamped to `[0, t_exit]`: one [`march_clock`]
/// with an unlimited budget (what [`clock_at_each`] gives at each of many
/// points).
#[inline]
pub fn clock_to<D: DensityField>(vol: &Volume<D>, ray: &ClockRay, t: f32) -> f32 {
    match march_clock(vol, ray, 0.0, t, f32::INFINITY) {
        ClockMarch::Exhausted(d) => d,
        ClockMarch::Reached(_) => f32::INFINITY,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::rng::Rng;
    use crate::physics::testing::*;
    use crate::physics::volume::Optics;

    /// Rays through a ball of σ_t 10 at one offset `r` from its centre:
    /// each ray's quadrature optical depth through the ball has an error
    /// (its edges fall inside lattice steps), but over rays that differ
    /// only in their direction's last bits that error averages to zero,
    /// whatever `r`. A lattice anchored at the cells alone gives every such
    /// ray the same error, a smooth function of `r`: the rings of a
    /// homogeneous sphere.
    #[test]
    fn lattice_phase_leaves_no_bias_at_an_edge() {
        // ρ = 1 inside the unit ball, 0 outside: edges the midpoint rule
        // cannot resolve.
        let vol = Volume::new(
            Ball { radius: 1.0 },
            Optics {
                sigma_t: Vec3::splat(10.0),
                albedo: Vec3::splat(1.0),
                g: 0.0,
            },
            8,
        );
        let s_star = 0.5;
        let h = clock_step(clock_cell(&vol), 10.0, s_star);
        assert!(h < 0.02, "step {h}: too coarse to test");
        let rays = 400;
        let mut rng = Rng::for_sample(5, 0, 0);
        let mut worst_single = 0.0f32;
        for bin in 0..24 {
            let r = 0.03 + 0.037 * bin as f32;
            let exact = 10.0 * 2.0 * (1.0 - r * r).sqrt();
            let (mut sum, mut sum2) = (0.0f64, 0.0f64);
            for _ in 0..rays {
                // The same ray to within 1e-4 radians: only the hash
                // differs.
                let jitter = Vec3::new(rng.next_f32(), rng.next_f32(), 0.0) * 1e-4;
                let origin = Vec3::new(r, 0.0, -1.0);
                let dir = (Vec3::Z + jitter).normalize();
                let (t0, t1) = vol.clip(origin, dir).unwrap();
                let ray = ClockRay {
                    clock: Clock::OpticalDepth,
                    s_star,
                    origin,
                    dir,
                    t_exit: t1,
                };
                let tau = match march_clock(&vol, &ray, t0, t1, f32::INFINITY) {
                    ClockMarch::Exhausted(tau) => tau,
                    ClockMarch::Reached(_) => unreachable!(),
                };
                let e = (tau - exact) as f64;
                worst_single = worst_single.max(e.abs() as f32);
                sum += e;
                sum2 += e * e;
            }
            let mean = sum / rays as f64;
            let sd_mean = ((sum2 / rays as f64 - mean * mean).max(0.0) / rays as f64).sqrt();
            // Two edges, each off by at most one step's optical depth.
            assert!(
                mean.abs() < 4.5 * sd_mean + 2e-3,
                "r {r}: mean error {mean:.4} (± {sd_mean:.4}) of optical depth {exact}"
            );
        }
        // Single rays do err (or the test would not see a lattice).
        assert!(
            worst_single > 0.02,
            "largest single-ray error {worst_single}"
        );
    }

    /// One march gives every point the clock that a march from the ray's
    /// start to that point gives (the same lattice), for both clocks,
    /// points in the same quadrature step, at the start and at the exit.
    #[test]
    fn clock_at_each_point_is_the_march_to_it() {
        let vol = boxed(1.5, 1.2, 1.0, 3.0, 12);
        let origin = Vec3::new(-3.0, 0.3, 0.2);
        let dir = Vec3::new(1.0, 0.2, -0.1).normalize();
        let (_, t_exit) = vol.clip(origin, dir).unwrap();
        let mut rng = Rng::for_sample(3, 0, 0);
        let mut ts: Vec<f32> = (0..40).map(|_| rng.next_f32() * t_exit).collect();
        ts.extend([0.0, 1e-4, 1.2e-4, t_exit]);
        ts.sort_by(f32::total_cmp);
        for clock in [Clock::OpticalDepth, Clock::Geometric] {
            let mut out = vec![f32::NAN; ts.len()];
            let ray = ClockRay {
                clock,
                s_star: 0.25,
                origin,
                dir,
                t_exit,
            };
            clock_at_each(&vol, &ray, &ts, &mut out);
            for (&t, &got) in ts.iter().zip(&out) {
                let want = clock_to(&vol, &ray, t);
                assert!(
                    (got - want).abs() <= 1e-4 * want.max(1e-3),
                    "{clock:?}, t {t}: one march {got}, march to the point {want}"
                );
            }
            if clock == Clock::OpticalDepth {
                assert!(out[out.len() - 1] > 5.0, "the medium is too thin to test");
            }
        }
    }
}
