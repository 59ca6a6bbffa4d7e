//! The time-gated backward walk that estimates the path-length series
//! `J_N = Σ_{k=0}^{N} G(k s*) S₁` at a point ([method §3–§4](crate::doc::method)).
//!
//! # What the walk estimates
//!
//! Let a backward walk start at `z` and fly along `−n` (`n` is the
//! direction light travels at `z`): free flights sample collisions with
//! rate `c` (spectral tracking), each real collision multiplies the weight
//! by the albedo `α` and picks a new direction from the phase function,
//! and leaving the box `B` ends the walk (outside `B` is vacuum, so it never
//! comes back and `S₁ = 0` there). The track-length estimator of the
//! radiance is then
//!
//! `L(z, n) = E[ ∫₀^∞ W(ℓ) S₁(y(ℓ), n(ℓ)) dℓ ]`,
//!
//! where `ℓ` is the walk's geometric path length, `y(ℓ)` its position,
//! `n(ℓ)` minus its direction, and `W(ℓ)` its weight just then (the product
//! of albedos, times the spectral-tracking ratios). Exchanging `E` and `∫`
//! gives `L = ∫₀^∞ dℓ G(ℓ) S₁` with
//!
//! `G(s) S₁ (z, n) = E[ W(s) S₁(y(s), n(s)) ]`.
//!
//! This is exactly the backward (adjoint) form of the time-dependent
//! transport equation `∂_s u + n·∇u = −c u + b ∫P u`, `u(0) = S₁`: a flight
//! of length `s` without real collision keeps the weight with probability
//! `T`, and a collision contributes `b/c = α` times the phase-sampled
//! continuation. So one walk sampled at the gate times `s = k s*` gives an
//! unbiased estimate of every term `J_k = G(k s*) S₁`, and the flights are
//! memoryless, so a flight simply continues past a gate. Note that `S₁`
//! includes the factor `b(y)`: at a gate in empty space it is zero even
//! though the walk carries weight there.
//!
//! # Guided directions
//!
//! The internal lights' walks ([`accumulate_j_from`]) draw their direction
//! after a collision from a mixture: the phase function, or with
//! probability [`GUIDE_PROBABILITY`] a lobe about the direction towards an
//! external light, and multiply the weight by the phase function over the
//! mixture's density ([`guided_direction`]). The expectation above is
//! unchanged (importance sampling of the collision's direction integral);
//! what changes is which walks carry the light: unguided, the few that
//! wander to the lit side carry most of it. Only a walk's first
//! [`GUIDED_COLLISIONS`] collisions are guided: the weight factors of many
//! guided collisions multiply into a heavy tail.
//!
//! # The optical-depth clock
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
//! `L₀ = ∫_{window} dt T(x, y_t) Ĵ(y_t)`, [`accumulate_j`] returns
//! `Ĵ_k = c_g(z) J^τ_k = ρ(z) · W · α σ_t (S₁/b)(z_k, n_k)`, which is
//! `S₁(z, n)` for `k = 0` exactly as with the geometric clock, and zero in
//! empty space (in τ-time light crosses empty space instantly). The
//! internal-light term `L₁` uses `Ĵ` in place of `J` for the same reason.
//!
//! The optical depth along a straight flight is integrated by the midpoint
//! rule on a lattice anchored at the start of each flight and of each
//! majorant cell, of steps of at most a quarter of the window `s*` in
//! majorant optical depth (at most [`CLOCK_MAX_STEPS`] per cell, one where
//! the cell is thinner than that: `clock_step`). Being anchored at the
//! cells on every ray, its error at a sharp edge is a smooth function of
//! where the edge falls on it: on a homogeneous sphere lit from behind the
//! camera it draws faint rings about the image's centre (README, Known
//! problems; a lattice shifted by a phase hashed from each ray removes
//! them but moves the puffs' dim edges at `s*` 0.25 from +3.4 % to +6.1 %,
//! so it is not in).
//! The clock is that quadrature;
//! the collisions themselves come from spectral tracking against the true
//! `c`, so the walk stays unbiased for `L` whatever the quadrature error.
//! A walk marches its clock only when the next gate may be near: the
//! majorant optical depth that tracking draws anyway bounds the quadrature
//! from above, so flights far from a gate stay pending and are marched
//! only once a gate may come (`LazyClock`), and a walk that leaves the
//! medium before its next gate never marches its last flights.

use glam::Vec3;

use super::lights::Lights;
use super::phase;
use super::reference::single_scatter_source;
use super::rng::Rng;
use super::tracking::{free_flight, spectral_event, TentativeEvent, TentativeSteps};
use super::volume::{DensityField, Volume};

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

impl GateSettings {
    /// Number of gates, `N + 1`.
    #[inline]
    pub fn gate_count(&self) -> usize {
        self.n_terms as usize + 1
    }
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
fn clock_cell<D: DensityField>(vol: &Volume<D>) -> f32 {
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
fn clock_step(cell: f32, m: f32, s_star: f32) -> f32 {
    let steps = (m * cell / (CLOCK_SPLIT_WINDOW * s_star)).ceil();
    if steps > 1.0 {
        cell / steps.min(CLOCK_MAX_STEPS)
    } else {
        cell
    }
}

/// The optical-depth clock's midpoint lattice along one ray: in each
/// majorant cell `[a, b]` the ray crosses, steps `[a + i h, a + (i+1) h)`
/// cut at `b`, each counted at the grey extinction at its midpoint — the
/// lattice [`march_clock`] steps through from a flight's start, for a
/// flight that counts its clock stretch by stretch between tentative
/// collisions. It remembers the step it is in, so that a step cut into
/// several stretches is sampled once. (`march_clock` keeps its own plain
/// loop: on the gather's hot path it is 4 % faster than going through
/// this; `lazy_clock_finds_the_same_gates` would see the two disagree.)
struct ClockLattice<'v, D> {
    vol: &'v Volume<D>,
    origin: Vec3,
    dir: Vec3,
    cell: f32,
    s_star: f32,
    sigma_g: f32,
    /// The step it is in: its cell's start (NaN: none yet), its index in
    /// the cell, its end and its rate.
    cell_start: f32,
    index: u32,
    end: f32,
    rate: f32,
}

impl<'v, D: DensityField> ClockLattice<'v, D> {
    fn new(vol: &'v Volume<D>, s_star: f32, origin: Vec3, dir: Vec3) -> Self {
        Self {
            vol,
            origin,
            dir,
            cell: clock_cell(vol),
            s_star,
            sigma_g: vol.optics.sigma_t.max_element(),
            cell_start: f32::NAN,
            index: 0,
            end: 0.0,
            rate: 0.0,
        }
    }

    /// Adds the clock over `[from, to]` of the cell `[a, b]` (majorant `m`) to `acc`,
    /// `from` being where the previous stretch in the cell ended (or
    /// anywhere, in a new cell); returns where `acc` reaches `budget`, if it
    /// does (`acc` is then left short of it).
    #[inline]
    #[allow(clippy::too_many_arguments)] // one cell, one stretch, the clock and its budget
    fn advance(
        &mut self,
        a: f32,
        b: f32,
        m: f32,
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
                let i = if self.cell_start == a {
                    self.index + 1
                } else {
                    let mut i = ((t - a) / h).max(0.0) as u32;
                    while a + (i + 1) as f32 * h <= t {
                        i += 1;
                    }
                    i
                };
                let p0 = a + i as f32 * h;
                let p1 = (a + (i + 1) as f32 * h).min(b);
                let mid = self.origin + self.dir * (0.5 * (p0 + p1));
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

/// Where a clock budget runs out along a ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ClockMarch {
    /// The clock reached the budget at this ray parameter.
    Reached(f32),
    /// The ray reached its end first; the clock advanced by this much.
    Exhausted(f32),
}

/// The chance that light travelling from `p` along `d` collides before it
/// leaves the medium's box, `1 − e^{−τ}` with `τ` the grey optical depth
/// to the exit (the optical-depth clock's quadrature; `s_star` sets its
/// lattice), one past [`COLLISION_DEPTH`] and never below
/// [`COLLISION_FLOOR`]: a walk from a light at the very edge that collides
/// all the same would otherwise weigh `1/P` without bound (any positive
/// factor divided out at the lights and multiplied back at the point is
/// exact in the limit; the floor only leaves the last sliver of the
/// horizon to the harmonics). The walks divide what they carried through
/// a collision by it at the light and the gather multiplies the
/// reconstruction by it at the camera ray's point (see
/// [`super::internal::Part::Scattered`]): near the surface of a medium it
/// falls from nearly one to nothing across the directions that leave it,
/// a horizon that low-order spherical harmonics and a kernel reaching
/// deeper in would smear.
pub fn collision_probability<D: DensityField>(
    vol: &Volume<D>,
    s_star: f32,
    p: Vec3,
    d: Vec3,
) -> f32 {
    let Some((_, exit)) = vol.clip(p, d) else {
        return COLLISION_FLOOR;
    };
    ChancesAlongRay::new(p, d, exit, s_star).at(vol, 0.0)
}

/// [`collision_probability`] at points of one ray `origin + t dir`
/// (`t ∈ [0, t_exit]`, `t_exit` where it leaves the box) asked for from
/// the far end back: each point's optical depth to the exit is the
/// stretch up to the point asked for before it plus what that point had,
/// so a camera ray's window costs one march to [`COLLISION_DEPTH`] and
/// the stretches between its points, not one march per point. The
/// quadrature lattice of each stretch is anchored at its near end, as
/// `collision_probability`'s is at its point: the two agree to the
/// quadrature's second order, not bit for bit.
pub struct ChancesAlongRay {
    origin: Vec3,
    dir: Vec3,
    t_exit: f32,
    s_star: f32,
    /// The nearest point asked for so far and its optical depth to the
    /// exit (`known_t` infinite: none yet).
    known_t: f32,
    known_tau: f32,
    /// The optical depth reached [`COLLISION_DEPTH`]: one from here on.
    saturated: bool,
}

impl ChancesAlongRay {
    /// Chances along `origin + t dir` up to `t_exit`, with the lattice of
    /// the window `s_star`.
    pub fn new(origin: Vec3, dir: Vec3, t_exit: f32, s_star: f32) -> Self {
        Self {
            origin,
            dir,
            t_exit,
            s_star,
            known_t: f32::INFINITY,
            known_tau: 0.0,
            saturated: false,
        }
    }

    /// The chance at `origin + t dir` of a collision along `dir` before
    /// the exit. Points are asked for from the far end back: a `t` past
    /// one asked for before (rounding of stratified samples) counts as
    /// that one.
    pub fn at<D: DensityField>(&mut self, vol: &Volume<D>, t: f32) -> f32 {
        if self.saturated {
            return 1.0;
        }
        let t = t.min(self.t_exit).min(self.known_t);
        let (t_stop, budget) = if self.known_t.is_finite() {
            (self.known_t, COLLISION_DEPTH - self.known_tau)
        } else {
            (self.t_exit, COLLISION_DEPTH)
        };
        match march_clock(
            vol,
            Clock::OpticalDepth,
            self.s_star,
            self.origin,
            self.dir,
            t,
            self.t_exit,
            t_stop,
            budget,
        ) {
            ClockMarch::Reached(_) => {
                self.saturated = true;
                return 1.0;
            }
            ClockMarch::Exhausted(tau) => {
                self.known_tau += tau;
                self.known_t = t;
            }
        }
        (-(-self.known_tau).exp_m1()).max(COLLISION_FLOOR)
    }
}

/// What one walk from `x` with start direction `−n` carried to its gates
/// `k ≥ 1` through a collision, `Σ (out_k − unscattered_k)`, per unit
/// chance of that collision ([`collision_probability`] along `−n`; no
/// march when it carried nothing): the walk's share of what the lights
/// store as [`super::internal::Part::Scattered`].
pub fn collided_per_unit_chance<D: DensityField>(
    vol: &Volume<D>,
    s_star: f32,
    x: Vec3,
    n: Vec3,
    out: &[Vec3],
    unscattered: &[Vec3],
) -> Vec3 {
    let carried = collided(out, unscattered);
    if carried == Vec3::ZERO {
        return carried;
    }
    carried / collision_probability(vol, s_star, x, -n)
}

/// What one walk carried to its gates `k ≥ 1` through a collision,
/// `Σ (out_k − unscattered_k)` ([`collided_per_unit_chance`] before the
/// division by the chance of that collision).
pub fn collided(out: &[Vec3], unscattered: &[Vec3]) -> Vec3 {
    let total: Vec3 = out.iter().skip(1).sum();
    total - unscattered.iter().skip(1).sum::<Vec3>()
}

/// The optical depth past which [`collision_probability`] stops marching
/// and returns one (`1 − e^{−12}` differs from it by 6e-6; the WGSL's is
/// generated from it).
pub const COLLISION_DEPTH: f32 = 12.0;

/// The least [`collision_probability`] returns (the WGSL's is generated
/// from it).
pub const COLLISION_FLOOR: f32 = 0.05;

/// Advances `clock` (gating windows of `s_star`) along `origin + t dir`
/// from `t0` (inside or on the medium's box) towards `t_stop ≤ t_exit`,
/// where `t_exit` is where the ray leaves the box. Returns where the clock
/// has advanced by `budget`, or how far it advanced by `t_stop`. For the
/// optical-depth clock the quadrature lattice depends on `s_star`,
/// `origin`, `dir`, `t0` and `t_exit` only, so calls that differ in
/// `t_stop` or `budget` measure the same clock.
#[allow(clippy::too_many_arguments)] // one ray, its clipped span and its budget
pub fn march_clock<D: DensityField>(
    vol: &Volume<D>,
    clock: Clock,
    s_star: f32,
    origin: Vec3,
    dir: Vec3,
    t0: f32,
    t_exit: f32,
    t_stop: f32,
    budget: f32,
) -> ClockMarch {
    march_clock_rate(vol, clock, s_star, origin, dir, t0, t_exit, t_stop, budget).0
}

/// The optical-depth clock's midpoint lattice along `origin + t dir` from
/// `t0` to `t_exit`: in each majorant cell `[a, b]` the ray crosses, steps
/// `[a + i h, a + (i+1) h)` cut at `b` ([`clock_step`]), each passed to
/// `step(p0, p1, c)` with `c` the grey extinction at its midpoint; a cell
/// whose majorant is zero is one step of rate zero. Stops when `step`
/// returns false. What [`march_clock_rate`] and [`clock_at_each`] count.
#[inline]
fn clock_steps<D: DensityField>(
    vol: &Volume<D>,
    s_star: f32,
    origin: Vec3,
    dir: Vec3,
    t0: f32,
    t_exit: f32,
    mut step: impl FnMut(f32, f32, f32) -> bool,
) {
    let cell = clock_cell(vol);
    let sigma_g = vol.optics.sigma_t.max_element();
    vol.majorants.walk(origin, dir, t0, t_exit, |a, b, m| {
        if m <= 0.0 {
            // The majorant bounds ρ: nothing to count in this cell.
            return step(a, b, 0.0);
        }
        let h = clock_step(cell, m, s_star);
        let mut i = 0u32;
        loop {
            let p0 = a + i as f32 * h;
            if p0 >= b {
                return true;
            }
            let p1 = (a + (i + 1) as f32 * h).min(b);
            let c = sigma_g * vol.density.density(origin + dir * (0.5 * (p0 + p1)));
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
#[allow(clippy::too_many_arguments)] // march_clock's
pub fn march_clock_rate<D: DensityField>(
    vol: &Volume<D>,
    clock: Clock,
    s_star: f32,
    origin: Vec3,
    dir: Vec3,
    t0: f32,
    t_exit: f32,
    t_stop: f32,
    budget: f32,
) -> (ClockMarch, f32) {
    let t_stop = t_stop.min(t_exit);
    if clock == Clock::Geometric {
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
    clock_steps(vol, s_star, origin, dir, t0, t_exit, |p0, p1, c| {
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

/// The clock from `origin` to each of the points `origin + ts[j] dir`
/// (`ts` ascending, within `[0, t_exit]`, `t_exit` where the ray leaves
/// the box) in one march: `out[j]` is what `march_clock` from `origin`
/// with `t0 = 0`, `t_stop = ts[j]` and an unlimited budget returns (the
/// same lattice, anchored at `origin`; equal up to rounding). The final
/// gather's points need their clock from the window's start for `L₁`'s
/// budget: one march for all of them instead of one each (stretches
/// between the points, each on its own lattice, had shifted the budgets
/// with the number of points: +2 % in `L₁` at 32 points on the puffs).
#[allow(clippy::too_many_arguments)] // the ray, its points and the output
pub fn clock_at_each<D: DensityField>(
    vol: &Volume<D>,
    clock: Clock,
    s_star: f32,
    origin: Vec3,
    dir: Vec3,
    t_exit: f32,
    ts: &[f32],
    out: &mut [f32],
) {
    let n = ts.len().min(out.len());
    if clock == Clock::Geometric {
        for (o, &t) in out[..n].iter_mut().zip(ts) {
            *o = t.clamp(0.0, t_exit.max(0.0));
        }
        return;
    }
    let mut acc = 0.0f32;
    let mut k = 0usize;
    clock_steps(vol, s_star, origin, dir, 0.0, t_exit, |p0, p1, c| {
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

/// The clock's advance along the ray from `origin` (inside or on the box)
/// over `[0, t]`, `t` clamped to `[0, t_exit]`: one [`march_clock`] with an
/// unlimited budget (what [`clock_at_each`] gives at each of many points).
#[inline]
pub fn clock_to<D: DensityField>(
    vol: &Volume<D>,
    clock: Clock,
    s_star: f32,
    origin: Vec3,
    dir: Vec3,
    t: f32,
    t_exit: f32,
) -> f32 {
    match march_clock(
        vol,
        clock,
        s_star,
        origin,
        dir,
        0.0,
        t_exit,
        t,
        f32::INFINITY,
    ) {
        ClockMarch::Exhausted(d) => d,
        ClockMarch::Reached(_) => f32::INFINITY,
    }
}

/// Runs one backward walk from `z` along `−n` (`n`: the direction light
/// travels at `z`), calling `on_gate(k, weight, z_k, n_k)` each time the
/// clock reaches `k · s*`, `k = 0..=N`: `z_k` is the walk's position then,
/// `n_k` the direction light travels there, `weight` the walk's RGB weight
/// (so that `E[weight · f(z_k, n_k)] = G(k s*) f (z, n)`). Gate 0 fires at
/// `z` with weight 1. The walk ends after gate `N`, on leaving the medium's
/// box, by Russian roulette, or when its weight vanishes.
pub fn gated_walk<D: DensityField>(
    vol: &Volume<D>,
    z: Vec3,
    n: Vec3,
    settings: &GateSettings,
    rng: &mut Rng,
    mut on_gate: impl FnMut(u32, Vec3, Vec3, Vec3),
) {
    walk(
        vol,
        z,
        n,
        settings,
        None,
        rng,
        |k, w, p, dir, _, _| on_gate(k, w, p, dir),
        None,
    );
}

/// Adds one walk's estimate of `Ĵ_k(z, n)`, `k = 0..out.len()−1` (at most
/// `N`), to `out`: with the geometric clock `Ĵ_k = J_k = G(k s*) S₁`, each
/// gate adding `weight · b(z_k) · (S₁/b)(z_k, n_k)`; with the optical-depth
/// clock `Ĵ_k = c_g(z) J^τ_k`, each gate adding
/// `weight · ρ(z) · α σ_t · (S₁/b)(z_k, n_k)` (see the module doc). `out[1]`
/// is the note's internal light source `F`.
pub fn accumulate_j<D: DensityField>(
    vol: &Volume<D>,
    lights: &Lights,
    z: Vec3,
    n: Vec3,
    settings: &GateSettings,
    rng: &mut Rng,
    out: &mut [Vec3],
) {
    accumulate_j_from(vol, lights, z, n, settings, 0, rng, out, None);
}

/// [`accumulate_j`] for the terms `k ≥ first` only (the others are left
/// untouched and cost no shadow rays): the internal lights evaluate the
/// `k = 0` term, `S₁` itself, exactly and need the walk only for `k ≥ 1`.
/// With `unscattered`, also adds to it the part of each term that the walk
/// carried to its gate without a real collision: the single scatter
/// `T S₁` from `k s*` further along `−n`, which the final gather marches
/// exactly (the single scatter beyond the window) instead of reading it
/// back from the lights' spherical harmonics. The walk's directions after
/// collisions are guided towards the external lights
/// ([`guided_direction`]).
#[allow(clippy::too_many_arguments)] // accumulate_j's, `first` and one more output
pub fn accumulate_j_from<D: DensityField>(
    vol: &Volume<D>,
    lights: &Lights,
    z: Vec3,
    n: Vec3,
    settings: &GateSettings,
    first: u32,
    rng: &mut Rng,
    out: &mut [Vec3],
    unscattered: Option<&mut [Vec3]>,
) {
    accumulate_j_guided(
        vol,
        lights,
        z,
        n,
        settings,
        first,
        true,
        rng,
        out,
        unscattered,
    );
}

/// [`accumulate_j_from`], with the directions after collisions guided
/// towards the lights or (`guided` false) from the phase function alone.
#[allow(clippy::too_many_arguments)] // accumulate_j_from's and the switch
pub fn accumulate_j_guided<D: DensityField>(
    vol: &Volume<D>,
    lights: &Lights,
    z: Vec3,
    n: Vec3,
    settings: &GateSettings,
    first: u32,
    guided: bool,
    rng: &mut Rng,
    out: &mut [Vec3],
    mut unscattered: Option<&mut [Vec3]>,
) {
    let gates = match &unscattered {
        Some(u) => out.len().min(u.len()),
        None => out.len(),
    }
    .min(settings.gate_count());
    if gates == 0 {
        return;
    }
    let limited = GateSettings {
        n_terms: (gates - 1) as u32,
        ..*settings
    };
    gate_sources(
        vol,
        lights,
        z,
        n,
        &limited,
        first,
        guided,
        false,
        rng,
        |k, v, scattered| {
            out[k as usize] += v;
            if let (false, Some(u)) = (scattered, unscattered.as_deref_mut()) {
                u[k as usize] += v;
            }
        },
    );
}

/// What one guided walk from `z` carried to its gates `k = 1..=N` through
/// a collision: [`collided`] of [`accumulate_j_from`]'s two outputs (the
/// same estimator), without the shadow rays of the gates it passes before
/// its first collision, whose share that difference removes again. The
/// walks towards the eye need nothing else: on the puffs at `s* = 0.25`,
/// 128 of them per light within reach, a light set took 1.74 s with
/// every gate's shadow ray and 1.61 s with these (three runs each).
pub fn accumulate_collided<D: DensityField>(
    vol: &Volume<D>,
    lights: &Lights,
    z: Vec3,
    n: Vec3,
    settings: &GateSettings,
    rng: &mut Rng,
) -> Vec3 {
    let mut sum = Vec3::ZERO;
    gate_sources(
        vol,
        lights,
        z,
        n,
        settings,
        1,
        true,
        true,
        rng,
        |_, v, _| sum += v,
    );
    sum
}

/// The walk behind [`accumulate_j_guided`] and [`accumulate_collided`]:
/// calls `add(k, v, scattered)` with each gate's `v = w · α σ_t · ρ ·
/// (S₁/b)(z_k, n_k)` for `k ≥ first` (`scattered`: the walk collided
/// before the gate); with `collided_only`, gates before the first
/// collision are skipped without their shadow rays.
#[allow(clippy::too_many_arguments)] // accumulate_j_guided's and the switch
fn gate_sources<D: DensityField>(
    vol: &Volume<D>,
    lights: &Lights,
    z: Vec3,
    n: Vec3,
    settings: &GateSettings,
    first: u32,
    guided: bool,
    collided_only: bool,
    rng: &mut Rng,
    mut add: impl FnMut(u32, Vec3, bool),
) {
    let scatter = vol.optics.albedo * vol.optics.sigma_t;
    let rho_z = vol.density.density(z);
    if settings.clock == Clock::OpticalDepth && rho_z <= 0.0 {
        return;
    }
    walk(
        vol,
        z,
        n,
        settings,
        guided.then_some(lights),
        rng,
        |k, w, zk, nk, scattered, rng| {
            if k < first || w == Vec3::ZERO || (collided_only && !scattered) {
                return;
            }
            let rho = match settings.clock {
                Clock::Geometric => vol.density.density(zk),
                Clock::OpticalDepth => rho_z,
            };
            if rho <= 0.0 {
                return;
            }
            let source = single_scatter_source(vol, lights, zk, nk, rng);
            add(k, w * scatter * rho * source, scattered);
        },
        None,
    );
}

/// One walk's estimate of `Ĵ_k(z, n)` for `k = 0..=N` (see
/// [`accumulate_j`]).
pub fn estimate_j<D: DensityField>(
    vol: &Volume<D>,
    lights: &Lights,
    z: Vec3,
    n: Vec3,
    settings: &GateSettings,
    rng: &mut Rng,
) -> Vec<Vec3> {
    let mut out = vec![Vec3::ZERO; settings.gate_count()];
    accumulate_j(vol, lights, z, n, settings, rng, &mut out);
    out
}

/// How one flight of a walk ends.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Flight {
    /// A real collision at ray parameter `t`. With the geometric clock, or
    /// when the optical-depth clock was resolved, `advanced` is how far the
    /// clock advanced since the flight's start; `None` when the flight was
    /// left pending in the [`LazyClock`].
    Collision { t: f32, advanced: Option<f32> },
    /// The clock reached the next gate at ray parameter `t` first.
    Gate(f32),
    /// The flight left the box (or can carry no more light) first.
    Exit,
}

/// Pending flights a [`LazyClock`] holds before it resolves them anyway.
const LAZY_CLOCK_PENDING: usize = 16;

/// The optical-depth clock of one walk, marched only when a gate may be
/// near. A flight that ends in a collision while its majorant optical depth
/// (spectral tracking draws it anyway: the sum of the exponential steps)
/// shows that the clock cannot have reached the next gate is kept pending,
/// unmarched: the midpoint quadrature of `c_g` never exceeds the majorant,
/// so `exact + Σ pending ≤ exact + slack`. The pending flights are marched
/// (each with its lattice anchored at its start, as an eager flight's
/// would be) only when a gate may come within the bound, so a walk that
/// leaves the medium before its next gate never marches its last flights
/// at all (the clock's quadrature was about half of the re-sampling time on
/// the puffs before).
struct LazyClock {
    /// The window `s*` (which fixes the quadrature lattice).
    s_star: f32,
    /// The clock at the start of the first pending flight.
    exact: f32,
    /// Upper bound of the pending flights' clock.
    slack: f32,
    /// Pending flights: `(origin, dir, t_start, t_end, t_exit)` (`t_exit`:
    /// where the ray leaves the box, which fixes the quadrature lattice).
    pending: [(Vec3, Vec3, f32, f32, f32); LAZY_CLOCK_PENDING],
    len: usize,
}

impl LazyClock {
    fn new(s_star: f32, exact: f32) -> Self {
        Self {
            s_star,
            exact,
            slack: 0.0,
            pending: [(Vec3::ZERO, Vec3::ZERO, 0.0, 0.0, 0.0); LAZY_CLOCK_PENDING],
            len: 0,
        }
    }

    /// Marches the pending flights; returns the exact clock after them.
    fn resolve<D: DensityField>(&mut self, vol: &Volume<D>) -> f32 {
        for &(origin, dir, t0, t1, t_exit) in &self.pending[..self.len] {
            if let ClockMarch::Exhausted(d) = march_clock(
                vol,
                Clock::OpticalDepth,
                self.s_star,
                origin,
                dir,
                t0,
                t_exit,
                t1,
                f32::INFINITY,
            ) {
                self.exact += d;
            }
        }
        self.len = 0;
        self.slack = 0.0;
        self.exact
    }

    /// Keeps the flight `origin + t dir`, `t ∈ [t0, t1]` (the ray leaving
    /// the box at `t_exit`), whose clock is at most `bound`, pending.
    fn defer<D: DensityField>(
        &mut self,
        vol: &Volume<D>,
        flight: (Vec3, Vec3, f32, f32, f32),
        bound: f32,
    ) {
        if self.len == LAZY_CLOCK_PENDING {
            self.resolve(vol);
        }
        self.pending[self.len] = flight;
        self.len += 1;
        self.slack += bound;
    }
}

/// One flight with the optical-depth clock over `[t_enter, t_exit]` of
/// `origin + t dir`, the next gate at clock `gate_clock`, in one traversal
/// of the majorant cells: spectral tracking's tentative collisions in
/// order and, once a gate may be near, the clock alongside them. While the
/// majorant optical depth says the gate cannot have come (see
/// [`LazyClock`]) nothing is marched; at the first tentative collision
/// where it might have, the pending flights and this one so far are
/// marched ([`march_clock`]), and from there the clock advances with the
/// tracking, on the lattice [`march_clock`] would use from `t_enter`
/// ([`ClockLattice`]: a step's density is sampled once however many
/// tentative collisions fall in it), stopping at the gate if it comes
/// before the next tentative collision. Tentative collisions past the gate
/// are never drawn into the weight, so this is the same estimator as
/// tracking to the gate: flights are memoryless.
#[allow(clippy::too_many_arguments)] // one flight: ray, span, gate, state
fn optical_depth_flight<D: DensityField>(
    vol: &Volume<D>,
    origin: Vec3,
    dir: Vec3,
    t_enter: f32,
    t_exit: f32,
    gate_clock: f32,
    lazy: &mut LazyClock,
    weight: &mut Vec3,
    rng: &mut Rng,
) -> Flight {
    // Bound mode: `bound` is an upper bound of the clock since
    // `lazy.exact`. Exact mode (`resolved`): `clock` is the clock from
    // `t_enter` to the current position on top of `lazy.exact`.
    let mut resolved = false;
    let mut bound = lazy.slack;
    let mut clock = 0.0f32;
    let mut lattice = ClockLattice::new(vol, lazy.s_star, origin, dir);
    let mut outcome = None;
    // Marches the pending flights, then this one from its start to `to`
    // against what is left to the gate.
    let resolve_to = |lazy: &mut LazyClock, to: f32| {
        let exact = lazy.resolve(vol);
        march_clock(
            vol,
            Clock::OpticalDepth,
            lazy.s_star,
            origin,
            dir,
            t_enter,
            t_exit,
            to,
            gate_clock - exact,
        )
    };
    let mut steps = TentativeSteps::new(rng);
    vol.majorants.walk(origin, dir, t_enter, t_exit, |a, b, m| {
        let mut t = a;
        loop {
            let next = steps.next(t, b, m);
            if resolved && m > 0.0 {
                let left = gate_clock - lazy.exact;
                let to = next.unwrap_or(b);
                if let Some(t_gate) = lattice.advance(a, b, m, t, to, &mut clock, left) {
                    outcome = Some(Flight::Gate(t_gate));
                    return false;
                }
            }
            let Some(t_event) = next else {
                return true;
            };
            t = t_event;
            if !resolved {
                bound += steps.depth();
                if lazy.exact + bound >= gate_clock {
                    resolved = true;
                    match resolve_to(lazy, t) {
                        ClockMarch::Reached(t_gate) => {
                            outcome = Some(Flight::Gate(t_gate));
                            return false;
                        }
                        ClockMarch::Exhausted(d) => clock = d,
                    }
                }
            }
            match spectral_event(vol, origin + dir * t, m, weight, rng) {
                TentativeEvent::Real => {
                    outcome = Some(Flight::Collision {
                        t,
                        advanced: resolved.then_some(clock),
                    });
                    return false;
                }
                TentativeEvent::Null => {}
                TentativeEvent::Dead => {
                    outcome = Some(Flight::Exit);
                    return false;
                }
            }
            steps.redraw(rng);
        }
    });
    if let Some(outcome) = outcome {
        if let Flight::Collision { t, advanced: None } = outcome {
            lazy.defer(vol, (origin, dir, t_enter, t, t_exit), bound - lazy.slack);
        }
        return outcome;
    }
    if resolved {
        // The clock was followed to the exit without reaching the gate.
        return Flight::Exit;
    }
    // Bound mode to the exit: is there a gate on the way?
    if lazy.exact + bound + steps.used() < gate_clock {
        return Flight::Exit;
    }
    match resolve_to(lazy, t_exit) {
        ClockMarch::Reached(t_gate) => Flight::Gate(t_gate),
        ClockMarch::Exhausted(_) => Flight::Exit,
    }
}

/// Probability that a walk's direction after a collision is drawn towards
/// an external light ([`guided_direction`]) rather than from the phase
/// function. The walks' values are heavy-tailed: on the puffs two thirds
/// of the walks from a light carry nothing through a collision and the
/// top 1 % carry half the mean (the few that reach the sunlit side;
/// `lantern noise`). At 0.3, with lobes of `g` [`GUIDE_G`], the light sets'
/// noise fell from 42.7 % to 35.7 % of the image mean per set (96², M 16384,
/// K 16, SH 4, 24 sets; 1.43× less variance); 0.2 gave about the same,
/// a narrower lobe (`g` 0.8) and an isotropic one less.
pub const GUIDE_PROBABILITY: f32 = 0.3;

/// The Henyey–Greenstein parameter of the lobes about the directions
/// towards the external lights that [`guided_direction`] mixes in.
pub const GUIDE_G: f32 = 0.5;

/// Collisions of a walk after which its directions are guided
/// ([`guided_direction`]); later ones come from the phase function alone.
/// Each guided direction multiplies the walk's weight by phase / mixture
/// (up to `1/(1 − q)`), unbiased but a factor of its own: over the hundreds
/// of collisions of a walk in a thick cloud the product of those factors is
/// heavy-tailed, and single lights came out tens of times too bright
/// (kernel-sized white discs; on a cumulus of optical depth ≈ 30, albedo
/// 0.999, `g` 0.85 at 128², 8 light sets: block RMSE 484 % guided at every
/// collision, 35 % at the first two only). Near the light where a walk
/// starts, where the guiding pays, two collisions keep its gain (puffs:
/// block RMSE 3.6 % either way).
pub const GUIDED_COLLISIONS: u32 = 2;

/// A backward walk's next direction after a collision at `p`, coming in
/// along `dir`, and the factor its weight takes: with probability
/// `1 − q` (`q` = [`GUIDE_PROBABILITY`]) from the phase function about
/// `dir`, otherwise from a Henyey–Greenstein lobe ([`GUIDE_G`]) about the
/// direction towards one external light, chosen in proportion to its
/// unshadowed irradiance at `p` (largest channel). The factor is the
/// phase function over the mixture's density, at most `1/(1 − q)`, so the
/// walk stays unbiased for any lights and any medium; with no light
/// reaching `p` it is the phase function alone. `u1, u2` place the
/// direction within the chosen lobe; the choice of lobe draws from `rng`.
pub fn guided_direction(
    g: f32,
    lights: &Lights,
    p: Vec3,
    dir: Vec3,
    u1: f32,
    u2: f32,
    rng: &mut Rng,
) -> (Vec3, f32) {
    let mut total = 0.0f32;
    lights.for_each_at(p, |l| total += l.irradiance.max_element().max(0.0));
    if !(total > 0.0 && total.is_finite()) {
        return (phase::sample_hg(g, dir, u1, u2), 1.0);
    }
    let u = rng.next_f32();
    let next = if u < GUIDE_PROBABILITY {
        // A light in proportion to its irradiance, then its lobe.
        let mut pick = u / GUIDE_PROBABILITY * total;
        let mut towards = None;
        let mut last = None;
        lights.for_each_at(p, |l| {
            let w = l.irradiance.max_element().max(0.0);
            if w > 0.0 {
                last = Some(-l.travel);
                if towards.is_none() {
                    if pick < w {
                        towards = Some(-l.travel);
                    }
                    pick -= w;
                }
            }
        });
        match towards.or(last) {
            Some(t) => phase::sample_hg(GUIDE_G, t, u1, u2),
            None => phase::sample_hg(g, dir, u1, u2),
        }
    } else {
        phase::sample_hg(g, dir, u1, u2)
    };
    let p_phase = phase::hg(g, dir.dot(next));
    let mut p_lobes = 0.0f32;
    lights.for_each_at(p, |l| {
        let w = l.irradiance.max_element().max(0.0);
        if w > 0.0 {
            p_lobes += w / total * phase::hg(GUIDE_G, next.dot(-l.travel));
        }
    });
    let mixture = (1.0 - GUIDE_PROBABILITY) * p_phase + GUIDE_PROBABILITY * p_lobes;
    if mixture > 0.0 {
        (next, p_phase / mixture)
    } else {
        (next, 0.0)
    }
}

/// The walk itself; with `guide`, its directions after a collision come
/// from [`guided_direction`] towards those lights. `on_gate(k, weight, z_k,
/// n_k, scattered, rng)` also
/// learns whether the walk has collided yet and receives the random stream,
/// so that the caller can trace shadow rays; `on_collision(clock)`, if
/// given, is called at every real collision with the clock's value there (a
/// hook for tests: it makes the optical-depth clock resolve at every
/// collision).
#[allow(clippy::too_many_arguments)] // the start, the gates, the guide, the stream and two callbacks
fn walk<D: DensityField>(
    vol: &Volume<D>,
    z: Vec3,
    n: Vec3,
    settings: &GateSettings,
    guide: Option<&Lights>,
    rng: &mut Rng,
    mut on_gate: impl FnMut(u32, Vec3, Vec3, Vec3, bool, &mut Rng),
    mut on_collision: Option<&mut dyn FnMut(f32)>,
) {
    let s_star = settings.s_star.max(0.0);
    let last = settings.n_terms;
    let mut weight = Vec3::ONE;
    on_gate(0, weight, z, n, false, rng);
    if last == 0 {
        return;
    }
    let mut next = 1u32;
    let mut origin = z;
    let mut dir = -n;
    // The clock at `origin`: exactly `lazy.exact` with the geometric clock
    // (which is never pending), `lazy.exact` plus the pending flights with
    // the optical-depth clock.
    let mut lazy = LazyClock::new(s_star, 0.0);
    let mut collisions = 0u32;
    // One flight per iteration: from `origin` to the next gate, the next
    // real collision, or the exit of the box, whichever comes first.
    loop {
        let Some((t_enter, t_exit)) = vol.clip(origin, dir) else {
            return;
        };
        let clock_at_enter = match settings.clock {
            Clock::Geometric => lazy.exact + t_enter,
            Clock::OpticalDepth => lazy.exact,
        };
        // Gates in the vacuum before the box (only when `z` is outside it,
        // and only for the geometric clock).
        while settings.clock == Clock::Geometric && next as f32 * s_star <= clock_at_enter {
            let t = next as f32 * s_star - lazy.exact;
            on_gate(next, weight, origin + dir * t, -dir, collisions > 0, rng);
            if next == last {
                return;
            }
            next += 1;
        }
        let gate_clock = next as f32 * s_star;
        let flight = match settings.clock {
            Clock::OpticalDepth => optical_depth_flight(
                vol,
                origin,
                dir,
                t_enter,
                t_exit,
                gate_clock,
                &mut lazy,
                &mut weight,
                rng,
            ),
            Clock::Geometric => {
                // The gate is `budget` further along the ray, the
                // collision wherever tracking puts it before then.
                let budget = gate_clock - clock_at_enter;
                let gate_t = (t_enter + budget <= t_exit).then_some(t_enter + budget);
                match free_flight(
                    vol,
                    origin,
                    dir,
                    t_enter,
                    gate_t.unwrap_or(t_exit),
                    &mut weight,
                    rng,
                ) {
                    Some(t_hit) => Flight::Collision {
                        t: t_hit,
                        advanced: Some(t_hit),
                    },
                    None => gate_t.map_or(Flight::Exit, Flight::Gate),
                }
            }
        };
        match flight {
            Flight::Collision { t: t_hit, advanced } => {
                if let Some(advanced) = advanced {
                    // Rounding must not put the collision past the gate.
                    lazy.exact = (lazy.exact + advanced).min(gate_clock);
                }
                origin += dir * t_hit;
                if let Some(hook) = on_collision.as_deref_mut() {
                    hook(lazy.resolve(vol).min(gate_clock));
                }
                weight *= vol.optics.albedo;
                collisions += 1;
                if collisions >= settings.rr_start {
                    let q = weight.max_element().min(0.95);
                    if q <= 0.0 || rng.next_f32() >= q {
                        return;
                    }
                    weight /= q;
                }
                let (u1, u2) = (rng.next_f32(), rng.next_f32());
                dir = match guide.filter(|_| collisions <= GUIDED_COLLISIONS) {
                    Some(lights) => {
                        let (d, factor) =
                            guided_direction(vol.optics.g, lights, origin, dir, u1, u2, rng);
                        weight *= factor;
                        d
                    }
                    None => phase::sample_hg(vol.optics.g, dir, u1, u2),
                };
            }
            Flight::Exit => return,
            Flight::Gate(t) => {
                if weight == Vec3::ZERO {
                    return;
                }
                origin += dir * t;
                on_gate(next, weight, origin, -dir, collisions > 0, rng);
                if next == last {
                    return;
                }
                next += 1;
                // The flight goes on from the gate: flights are memoryless,
                // and the quadrature lattice is re-anchored here. A gate is
                // only found with the clock resolved: nothing is pending.
                debug_assert_eq!(lazy.len, 0);
                lazy.exact = gate_clock;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::volume::Optics;

    /// Density `base + amp·sin(x)·sin(y)` in a box so large that no walk
    /// leaves it: an unbounded medium.
    struct Field {
        base: f32,
        amp: f32,
    }

    const HALF: f32 = 1.0e4;

    impl DensityField for Field {
        fn density(&self, p: Vec3) -> f32 {
            self.base + self.amp * (p.x.sin() * p.y.sin())
        }
        fn bounds(&self) -> (Vec3, Vec3) {
            (Vec3::splat(-HALF), Vec3::splat(HALF))
        }
        fn max_in_box(&self, _: Vec3, _: Vec3) -> f32 {
            self.base + self.amp
        }
    }

    fn volume(base: f32, amp: f32, albedo: f32) -> Volume<Field> {
        Volume::new(
            Field { base, amp },
            Optics {
                sigma_t: Vec3::splat(1.0),
                albedo: Vec3::splat(albedo),
                g: 0.3,
            },
            // Coarse majorant cells: the geometric clock needs no
            // quadrature; the heterogeneous case below re-grids.
            8,
        )
    }

    /// [`volume`] in the box `[−half, half]³` with `cells` majorant cells
    /// per axis, each bounded by `base + amp`.
    fn boxed(base: f32, amp: f32, albedo: f32, half: f32, cells: u32) -> Volume<Field> {
        let mut vol = volume(base, amp, albedo);
        vol.bounds = (Vec3::splat(-half), Vec3::splat(half));
        vol.majorants = crate::physics::majorant::MajorantGrid::build(
            vol.bounds.0,
            vol.bounds.1,
            cells,
            |_, _| base + amp,
        );
        vol
    }

    /// Collisions per window of the clock for `walks` walks: a histogram of
    /// counts in windows `1..=N` (the windows between consecutive gates).
    fn window_counts(vol: &Volume<Field>, settings: &GateSettings, walks: u32) -> Vec<u64> {
        let mut hist = vec![0u64; 64];
        for w in 0..walks {
            let mut rng = Rng::for_sample(5, w, 0);
            let mut per_window = vec![0usize; settings.n_terms as usize];
            let s = settings.s_star;
            walk(
                vol,
                Vec3::ZERO,
                Vec3::Z,
                settings,
                None,
                &mut rng,
                |_, _, _, _, _, _| {},
                Some(&mut |clock: f32| {
                    let k = (clock / s).floor() as usize;
                    if k < per_window.len() {
                        per_window[k] += 1;
                    }
                }),
            );
            for c in per_window {
                hist[c.min(63)] += 1;
            }
        }
        hist
    }

    /// χ² of a histogram against Poisson(`mean`), pooling the tail where
    /// fewer than 5 are expected; returns (χ², degrees of freedom).
    fn chi2_poisson(hist: &[u64], mean: f64) -> (f64, usize) {
        let n: u64 = hist.iter().sum();
        let mut p = (-mean).exp();
        let mut chi2 = 0.0;
        let mut bins = 0;
        let mut rest_obs = n as f64;
        let mut rest_p = 1.0;
        for (k, &obs) in hist.iter().enumerate() {
            if k > 0 {
                p *= mean / k as f64;
            }
            let expect = p * n as f64;
            if expect < 5.0 || rest_p - p < 1e-9 {
                break;
            }
            chi2 += (obs as f64 - expect).powi(2) / expect;
            rest_obs -= obs as f64;
            rest_p -= p;
            bins += 1;
        }
        let expect = rest_p * n as f64;
        if expect > 0.0 {
            chi2 += (rest_obs - expect).powi(2) / expect;
            bins += 1;
        }
        (chi2, bins - 1)
    }

    /// A bounded, forward-scattering (`g` 0.6), heterogeneous medium lit by
    /// a sun, the optical-depth clock at `s*` 0.5 with 40 terms, and a walk's
    /// start `z` and direction `n` inside it.
    fn forward_scattering_walk() -> (Volume<Field>, Lights, GateSettings, Vec3, Vec3) {
        let mut vol = boxed(1.2, 0.8, 0.95, 1.0, 4);
        vol.optics.g = 0.6;
        let lights = Lights {
            suns: vec![crate::physics::lights::Sun {
                direction: Vec3::new(0.6, -1.0, -0.5).normalize(),
                irradiance: Vec3::new(3.0, 2.0, 1.0),
            }],
            points: Vec::new(),
            environment: None,
        };
        let settings = GateSettings {
            s_star: 0.5,
            n_terms: 40,
            clock: Clock::OpticalDepth,
            rr_start: crate::physics::reference::RR_START_DEPTH,
        };
        let z = Vec3::new(0.1, -0.4, 0.2);
        let n = Vec3::new(0.3, 0.2, -1.0).normalize();
        (vol, lights, settings, z, n)
    }

    /// One walk's collided part of its terms `k ≥ 1` ([`collided`]) and
    /// the part before its first collision, by [`accumulate_j_guided`].
    fn split_walk(
        vol: &Volume<Field>,
        lights: &Lights,
        settings: &GateSettings,
        z: Vec3,
        n: Vec3,
        guided: bool,
        rng: &mut Rng,
    ) -> (Vec3, Vec3) {
        let mut out = vec![Vec3::ZERO; settings.gate_count()];
        let mut unscattered = vec![Vec3::ZERO; settings.gate_count()];
        accumulate_j_guided(
            vol,
            lights,
            z,
            n,
            settings,
            1,
            guided,
            rng,
            &mut out,
            Some(&mut unscattered),
        );
        (
            collided(&out, &unscattered),
            unscattered[1..].iter().sum::<Vec3>(),
        )
    }

    /// The mean of `walks` values of `f` (walk `w` on stream
    /// `Rng::for_sample(seed, w, stream)`) and the variance of that mean.
    fn mean_and_its_variance(
        walks: u32,
        seed: u64,
        stream: u32,
        mut f: impl FnMut(&mut Rng) -> Vec3,
    ) -> (Vec3, Vec3) {
        let (mut sum, mut sum2) = (Vec3::ZERO, Vec3::ZERO);
        for w in 0..walks {
            let mut rng = Rng::for_sample(seed, w, stream);
            let v = f(&mut rng);
            sum += v;
            sum2 += v * v;
        }
        let mean = sum / walks as f32;
        let var = (sum2 / walks as f32 - mean * mean).max(Vec3::ZERO);
        (mean, var / walks as f32)
    }

    /// Guiding the walks towards the light changes their spread, not their
    /// mean: in a bounded, forward-scattering, heterogeneous medium lit by
    /// a sun and a point light, the collided part of every term agrees
    /// with the unguided walk's (summed over `k ≥ 1`, per channel, within
    /// 4.5 standard errors of the difference), and the guided walks' values
    /// are less spread (their standard error lower).
    #[test]
    fn guided_walks_keep_the_mean() {
        let (vol, mut lights, settings, z, n) = forward_scattering_walk();
        lights.points.push(crate::physics::lights::PointLight {
            position: Vec3::new(-2.0, 0.5, 1.5),
            intensity: Vec3::splat(4.0),
        });
        let stats: Vec<(Vec3, Vec3)> = [false, true]
            .into_iter()
            .map(|guided| {
                mean_and_its_variance(400_000, 21, u32::from(guided), |rng| {
                    split_walk(&vol, &lights, &settings, z, n, guided, rng).0
                })
            })
            .collect();
        let ((m0, v0), (m1, v1)) = (stats[0], stats[1]);
        for c in 0..3 {
            let se = (v0[c] + v1[c]).sqrt();
            assert!(
                (m0[c] - m1[c]).abs() < 4.5 * se,
                "channel {c}: unguided {} guided {} (se {se})",
                m0[c],
                m1[c]
            );
            assert!(m0[c] > 10.0 * se, "channel {c}: too noisy to compare");
        }
        eprintln!(
            "unguided {m0} ± {}, guided {m1} ± {}",
            v0.x.sqrt(),
            v1.x.sqrt()
        );
        assert!(v1.x < v0.x, "guided variance {} against {}", v1.x, v0.x);
    }

    /// [`accumulate_collided`] skips the shadow rays of the gates before
    /// the first collision and keeps the estimator: in the medium of
    /// `guided_walks_keep_the_mean`, its mean agrees per channel with
    /// [`collided`] of [`accumulate_j_from`]'s outputs within 4.5 standard
    /// errors of the difference, and both are far from the uncollided
    /// part it leaves out (which would show if it kept or lost a share).
    #[test]
    fn collided_walks_match_the_collided_part() {
        let (vol, lights, settings, z, n) = forward_scattering_walk();
        let walks = 200_000u32;
        let mut uncollided = Vec3::ZERO;
        let (full, full_var) = mean_and_its_variance(walks, 23, 0, |rng| {
            let (collided, before) = split_walk(&vol, &lights, &settings, z, n, true, rng);
            uncollided += before;
            collided
        });
        uncollided /= walks as f32;
        let (skip, skip_var) = mean_and_its_variance(walks, 23, 1, |rng| {
            accumulate_collided(&vol, &lights, z, n, &settings, rng)
        });
        eprintln!("collided {full} (with every gate), {skip} (skipping), uncollided {uncollided}");
        for c in 0..3 {
            let se = (full_var[c] + skip_var[c]).sqrt();
            assert!(
                (full[c] - skip[c]).abs() < 4.5 * se,
                "channel {c}: with every gate {} skipping {} (se {se})",
                full[c],
                skip[c]
            );
            assert!(
                uncollided[c] > 10.0 * se,
                "channel {c}: the test cannot tell a lost share"
            );
        }
    }

    #[test]
    fn collisions_per_window_are_poisson() {
        // Collisions in each of the windows of 20 000 walks against
        // Poisson(s*); the 99.9th percentile of χ² for ≤ 10 degrees of
        // freedom is ≤ 29.6.
        let check = |vol: &Volume<Field>, clock, s_star: f32, n_terms, label: &str| {
            let settings = GateSettings {
                s_star,
                n_terms,
                clock,
                rr_start: u32::MAX,
            };
            let hist = window_counts(vol, &settings, 20_000);
            let (chi2, dof) = chi2_poisson(&hist, s_star as f64);
            eprintln!("{label}: χ² = {chi2:.1} with {dof} dof");
            assert!(dof >= 4 && chi2 < 29.6, "{label}: χ² = {chi2}, dof = {dof}");
        };
        // Homogeneous, geometric clock: Poisson(σ_t s*) per window.
        check(
            &volume(1.0, 0.0, 1.0),
            Clock::Geometric,
            1.7,
            6,
            "geometric",
        );

        // Heterogeneous, optical-depth clock: Poisson(τ*) per window
        // whatever the density (src/doc/method.md §7), on split and whole cells: a
        // dense field (majorant optical depth 0.84 across a cell, over two
        // quarters of τ* = 1.3: three steps per cell) and a thin one (0.26:
        // one step).
        for (base, amp, steps) in [(1.0f32, 0.8f32, 3.0f32), (0.3, 0.25, 1.0)] {
            // Majorant cells of 120/256 ≈ 0.47 resolve sin(x) sin(y), over
            // a box that 5 windows of τ* = 1.3 never leave (a walk of ~7
            // collisions moves a few units where ρ ≈ 1, ~25 where ρ ≈ 0.3).
            let vol = boxed(base, amp, 1.0, 60.0, 256);
            let cell = clock_cell(&vol);
            assert_eq!(clock_step(cell, base + amp, 1.3), cell / steps);
            let label = format!("optical depth, ρ̄ = {base}");
            check(&vol, Clock::OpticalDepth, 1.3, 5, &label);
        }
    }

    #[test]
    fn lazy_clock_finds_the_same_gates() {
        // Marching consumes no random numbers, so a walk that keeps flights
        // pending (no hook) and one that resolves its clock at every
        // collision (the hook) take the same path: they must report the
        // same gates at the same places. A gate that the majorant bound
        // skipped, or a pending flight counted twice, would move them.
        // Unbounded (walks reach every gate) and a small box (walks leave
        // it, through the bound's exit check).
        for half in [60.0f32, 2.0] {
            let vol = boxed(1.0, 0.8, 0.9, half, (half * 4.0) as u32);
            let settings = GateSettings {
                s_star: 2.5,
                n_terms: 8,
                clock: Clock::OpticalDepth,
                rr_start: u32::MAX,
            };
            let (mut gates, mut pending_gates) = (0usize, 0usize);
            for w in 0..4000u32 {
                let run = |resolve_each: bool| {
                    let mut rng = Rng::for_sample(11, w, 0);
                    let mut out = Vec::new();
                    let mut hook = |_: f32| {};
                    walk(
                        &vol,
                        Vec3::new(0.3, -0.2, 0.1),
                        Vec3::Z,
                        &settings,
                        None,
                        &mut rng,
                        |k, _, p, _, scattered, _| out.push((k, p, scattered)),
                        resolve_each.then_some(&mut hook as &mut dyn FnMut(f32)),
                    );
                    out
                };
                let (lazy, eager) = (run(false), run(true));
                assert_eq!(lazy.len(), eager.len(), "walk {w}: {lazy:?} vs {eager:?}");
                for (a, b) in lazy.iter().zip(&eager) {
                    assert_eq!((a.0, a.2), (b.0, b.2), "walk {w}");
                    assert!((a.1 - b.1).length() < 1e-4, "walk {w}: {a:?} vs {b:?}");
                }
                gates += lazy.len();
                pending_gates += lazy.iter().filter(|g| g.2).count();
            }
            eprintln!("box ±{half}: {gates} gates, {pending_gates} after a collision");
            assert!(
                pending_gates > 2000,
                "too few gates after collisions to test"
            );
        }
    }

    #[test]
    fn albedo_one_conserves_the_weight() {
        // With α = 1 and no boundary, every gate is reached, and the weight
        // there is exactly 1 without Russian roulette, and 1 on average
        // with it.
        let vol = volume(0.7, 0.0, 1.0);
        for (rr_start, exact) in [(u32::MAX, true), (2, false)] {
            let settings = GateSettings {
                s_star: 2.0,
                n_terms: 12,
                clock: Clock::Geometric,
                rr_start,
            };
            let walks = 20_000u32;
            let mut sum = [0.0f64; 13];
            let mut sum2 = [0.0f64; 13];
            for w in 0..walks {
                let mut rng = Rng::for_sample(8, w, 1);
                gated_walk(
                    &vol,
                    Vec3::ZERO,
                    Vec3::X,
                    &settings,
                    &mut rng,
                    |k, wt, _, _| {
                        if exact {
                            assert!((wt - Vec3::ONE).abs().max_element() < 1e-5, "{wt}");
                        }
                        sum[k as usize] += wt.x as f64;
                        sum2[k as usize] += (wt.x as f64).powi(2);
                    },
                );
            }
            for k in 0..=12 {
                let mean = sum[k] / walks as f64;
                let var = (sum2[k] / walks as f64 - mean * mean).max(0.0);
                let se = (var / walks as f64).sqrt();
                assert!(
                    (mean - 1.0).abs() <= 4.0 * se + 1e-6,
                    "rr_start {rr_start}, gate {k}: mean weight {mean} ± {se}"
                );
            }
        }
    }

    /// The chances along a ray, asked for from its far end back, are the
    /// per-point [`collision_probability`] up to the quadrature (and both
    /// the exact `1 − e^{−τ}` of a fine march), in a medium thin enough
    /// to stay below [`COLLISION_DEPTH`] and one dense enough to reach it;
    /// the floor holds at the exit.
    #[test]
    fn chances_along_a_ray_match_each_point() {
        for base in [0.4f32, 3.0] {
            let vol = boxed(base, 0.6 * base, 1.0, 3.0, 12);
            let origin = Vec3::new(-3.0, 0.3, 0.2);
            let dir = Vec3::new(1.0, 0.2, -0.1).normalize();
            let (_, t_exit) = vol.clip(origin, dir).unwrap();
            let mut chances = ChancesAlongRay::new(origin, dir, t_exit, 0.5);
            let mut saturated = 0;
            for j in (0..=16).rev() {
                let t = t_exit * j as f32 / 16.0;
                let along = chances.at(&vol, t);
                let p = origin + dir * t;
                let single = collision_probability(&vol, 0.5, p, dir);
                let steps = 20_000;
                let dt = (t_exit - t) / steps as f32;
                let tau: f32 = (0..steps)
                    .map(|i| vol.density.density(p + dir * ((i as f32 + 0.5) * dt)) * dt)
                    .sum();
                let exact = if tau >= COLLISION_DEPTH {
                    1.0
                } else {
                    (1.0 - (-tau).exp()).max(COLLISION_FLOOR)
                };
                assert!(
                    (along - exact).abs() <= 0.01 * exact && (single - exact).abs() <= 0.01 * exact,
                    "base {base}, t {t}: along the ray {along}, at the point {single}, exact {exact} (τ {tau})"
                );
                if along == 1.0 {
                    saturated += 1;
                }
            }
            assert_eq!(chances.at(&vol, 0.0) == 1.0, base > 1.0);
            assert!(
                (base > 1.0) == (saturated > 0),
                "base {base}: {saturated} saturated"
            );
        }
        let vol = boxed(0.4, 0.2, 1.0, 3.0, 12);
        let origin = Vec3::new(-3.0, 0.0, 0.0);
        let mut chances = ChancesAlongRay::new(origin, Vec3::X, 6.0, 0.5);
        assert_eq!(chances.at(&vol, 6.0), COLLISION_FLOOR);
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
            clock_at_each(&vol, clock, 0.25, origin, dir, t_exit, &ts, &mut out);
            for (&t, &got) in ts.iter().zip(&out) {
                let want = clock_to(&vol, clock, 0.25, origin, dir, t, t_exit);
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
