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
//! The clock it is gated by is [`super::clock`]'s, its directions after a
//! collision are guided by [`super::guiding`], or, where the phase
//! function's forward peak is sharp, each collision also takes a second
//! flight towards a light ([`super::guiding::second_flight`]). There, a
//! walk whose caller sums its terms (the walks towards the eye and the
//! phase walks) reads the rest of its path once per flight after a few
//! collisions, without the clock ([`COLLISION_TAIL_AFTER`]).

use glam::Vec3;

use super::clock::{march_clock, Clock, ClockLattice, ClockMarch, ClockRay, GateSettings};
use super::guiding::{
    guided_direction, second_flight, SecondFlight, GUIDED_COLLISIONS, SECOND_FLIGHT_MIN_G,
};
use super::sources::PHASE_WALKS_MIN_G;
use crate::physics::lights::Lights;
use crate::physics::phase;
use crate::physics::reference::{gate_scatter_source, roulette};
use crate::physics::rng::{pcg_hash, Rng};
use crate::physics::tracking::{
    free_flight, free_flight_probed, spectral_event, TentativeEvent, TentativeSteps,
};
use crate::physics::volume::{DensityField, Volume};

/// Runs one backward walk from `z` along `−n` (`n`: the direction light
/// travels at `z`), calling `on_gate(k, weight, z_k, n_k)` each time the
/// clock reaches `k · s*`, `k = 0..=N`: `z_k` is the walk's position then,
/// `n_k` the direction light travels there, `weight` the walk's RGB weight
/// (so that `E[weight · f(z_k, n_k)] = G(k s*) f (z, n)`). Gate 0 fires at
/// `z` with weight 1. The walk ends after gate `N`, on leaving the medium's
/// box, by Russian roulette, or when its weight vanishes. Its directions
/// come from the phase function alone.
pub fn gated_walk<D: DensityField>(
    vol: &Volume<D>,
    z: Vec3,
    n: Vec3,
    settings: &GateSettings,
    rng: &mut Rng,
    mut on_gate: impl FnMut(u32, Vec3, Vec3, Vec3),
) {
    let no_lights = Lights::default();
    let walks = Walks {
        vol,
        lights: &no_lights,
        gates: *settings,
        guided: false,
    };
    walks.walk(
        z,
        n,
        rng,
        false,
        |k, w, p, dir, _, _| on_gate(k, w, p, dir),
        None,
    );
}

/// What the walks of one light set share: the medium, the external lights
/// whose single scatter `S₁` the gates read, the gates, and whether a
/// walk's directions after its first collisions are guided towards those
/// lights ([`guided_direction`]; in a medium of `g` ≥
/// [`SECOND_FLIGHT_MIN_G`], a second flight towards them at every
/// collision instead, [`second_flight`]) or come from the phase function
/// alone (all unbiased; the internal lights guide them).
pub struct Walks<'a, D> {
    /// The medium.
    pub vol: &'a Volume<D>,
    /// The external lights.
    pub lights: &'a Lights,
    /// The window, the series truncation and the clock.
    pub gates: GateSettings,
    /// Whether directions after a collision are guided (or, in a medium of
    /// `g` ≥ [`SECOND_FLIGHT_MIN_G`], second flights taken).
    pub guided: bool,
}

impl<'a, D: DensityField> Walks<'a, D> {
    /// Guided walks in `vol` under `lights`, gated by `gates`: what the
    /// internal lights run.
    pub fn guided(vol: &'a Volume<D>, lights: &'a Lights, gates: GateSettings) -> Self {
        Self {
            vol,
            lights,
            gates,
            guided: true,
        }
    }

    /// Adds one walk's estimate of `Ĵ_k(z, n)`, `k = 0..=N`, to `out`, the
    /// terms from `out.len() − 1` on summed in its last element (as
    /// [`term_slot`](super::clock::term_slot) folds them): with the geometric clock
    /// `Ĵ_k = J_k = G(k s*) S₁`, each gate adding
    /// `weight · b(z_k) · (S₁/b)(z_k, n_k)`; with the optical-depth clock
    /// `Ĵ_k = c_g(z) J^τ_k`, each gate adding
    /// `weight · ρ(z) · α σ_t · (S₁/b)(z_k, n_k)` (see the module doc).
    /// `out[1]` is the note's internal light source `F`.
    pub fn accumulate_j(&self, z: Vec3, n: Vec3, rng: &mut Rng, out: &mut [Vec3]) {
        self.accumulate_j_from(z, n, 0, rng, out, None);
    }

    /// [`Walks::accumulate_j`] for the terms `k ≥ first` only (the others
    /// are left untouched and cost no shadow rays): the internal lights
    /// evaluate the `k = 0` term, `S₁` itself, exactly and need the walk
    /// only for `k ≥ 1`. With `unscattered`, also adds to it the part of
    /// each term that the walk carried to its gate without a real
    /// collision: the single scatter `T S₁` from `k s*` further along
    /// `−n`, which the final gather marches exactly (the single scatter
    /// beyond the window) instead of reading it back from the lights'
    /// spherical harmonics.
    pub fn accumulate_j_from(
        &self,
        z: Vec3,
        n: Vec3,
        first: u32,
        rng: &mut Rng,
        out: &mut [Vec3],
        mut unscattered: Option<&mut [Vec3]>,
    ) {
        let slots = match &unscattered {
            Some(u) => out.len().min(u.len()),
            None => out.len(),
        };
        if slots == 0 {
            return;
        }
        // Terms past the last slot add to it (`term_slot`'s folding, for
        // any length of `out`).
        let last_slot = slots - 1;
        self.gate_sources(z, n, first, false, false, rng, |k, v, collisions| {
            let slot = (k as usize).min(last_slot);
            out[slot] += v;
            if let (0, Some(u)) = (collisions, unscattered.as_deref_mut()) {
                u[slot] += v;
            }
        });
    }

    /// What one walk from `z` carried to its gates `k = 1..=N` through a
    /// collision: [`collided`](super::chances::collided) of
    /// [`Walks::accumulate_j_from`]'s two outputs (the same estimator),
    /// without the shadow rays of the gates it passes before its first
    /// collision, whose share that difference removes again. The walks
    /// towards the eye need nothing else: on the puffs at `s* = 0.25`, 128
    /// of them per light within reach, a light set took 1.74 s with every
    /// gate's shadow ray and 1.61 s with these (three runs each).
    ///
    /// After [`COLLISION_TAIL_AFTER`] collisions the walk reads its source
    /// once per flight instead of at its gates ([`COLLISION_TAIL_AFTER`]):
    /// the same sum in expectation, without the clock's quadrature.
    pub fn accumulate_collided(&self, z: Vec3, n: Vec3, rng: &mut Rng) -> Vec3 {
        let mut sum = Vec3::ZERO;
        self.collided_readings(z, n, rng, |_, v| sum += v);
        sum
    }

    /// The walk of [`Walks::accumulate_collided`], calling
    /// `reading(collisions, v)` with each of its readings and the number of
    /// real collisions the walk made before it (at least one): where a
    /// walk's value comes from, for `lantern noise`.
    pub fn collided_readings(
        &self,
        z: Vec3,
        n: Vec3,
        rng: &mut Rng,
        mut reading: impl FnMut(u32, Vec3),
    ) {
        self.gate_sources(z, n, 1, true, true, rng, |_, v, collisions| {
            reading(collisions, v)
        });
    }

    /// One walk's `Σ_{k≥1} Ĵ_k(z, n)`, the sum of what
    /// [`Walks::accumulate_j_from`] adds from term 1 on: what a phase walk
    /// keeps. After [`COLLISION_TAIL_AFTER`] collisions it reads once per
    /// flight instead of at its gates ([`COLLISION_TAIL_AFTER`]).
    pub fn accumulate_sum(&self, z: Vec3, n: Vec3, rng: &mut Rng) -> Vec3 {
        let mut sum = Vec3::ZERO;
        self.gate_sources(z, n, 1, false, true, rng, |_, v, _| sum += v);
        sum
    }

    /// [`Walks::accumulate_collided`] (`collided_only`) or
    /// [`Walks::accumulate_sum`] by the gates all the way, as before the
    /// collision tail: what the tests hold the tail to.
    #[cfg(test)]
    fn sum_by_gates(&self, z: Vec3, n: Vec3, collided_only: bool, rng: &mut Rng) -> Vec3 {
        let mut sum = Vec3::ZERO;
        self.gate_sources(z, n, 1, collided_only, false, rng, |_, v, _| sum += v);
        sum
    }

    /// One walk's estimate of `Ĵ_k(z, n)` for `k = 0..=N` (see
    /// [`Walks::accumulate_j`]).
    pub fn estimate_j(&self, z: Vec3, n: Vec3, rng: &mut Rng) -> Vec<Vec3> {
        let mut out = vec![Vec3::ZERO; self.gates.term_slots()];
        self.accumulate_j(z, n, rng, &mut out);
        out
    }

    /// The walk behind [`Walks::accumulate_j_from`] and
    /// [`Walks::accumulate_collided`]: calls `add(k, v, collisions)` with
    /// each gate's `v = w · α σ_t · ρ · (S₁/b)(z_k, n_k)` for `k ≥ first`
    /// (`collisions`: the walk's real collisions before the gate); with
    /// `collided_only`, gates before the first collision are skipped
    /// without their shadow rays. With `tail` (a caller that sums the
    /// terms) the walk hands over to [`Walks::collision_tail`] on the
    /// optical-depth clock.
    #[allow(clippy::too_many_arguments)]
    fn gate_sources(
        &self,
        z: Vec3,
        n: Vec3,
        first: u32,
        collided_only: bool,
        tail: bool,
        rng: &mut Rng,
        mut add: impl FnMut(u32, Vec3, u32),
    ) {
        let (vol, lights, clock) = (self.vol, self.lights, self.gates.clock);
        let scatter = vol.optics.albedo * vol.optics.sigma_t;
        let rho_z = vol.density.density(z);
        if clock == Clock::OpticalDepth && rho_z <= 0.0 {
            return;
        }
        // Only a caller that sums the terms may trade the gates for the
        // tail's one reading per flight ([`Walks::collision_tail`]), only on
        // the optical-depth clock, whose rate is the grey extinction, and
        // only where it pays ([`COLLISION_TAIL_MIN_G`]).
        let tail =
            tail && clock == Clock::OpticalDepth && vol.optics.g.abs() >= COLLISION_TAIL_MIN_G;
        self.walk(
            z,
            n,
            rng,
            tail,
            |k, w, zk, nk, collisions, rng| {
                if k < first || w == Vec3::ZERO || (collided_only && collisions == 0) {
                    return;
                }
                let rho = match clock {
                    Clock::Geometric => vol.density.density(zk),
                    Clock::OpticalDepth => rho_z,
                };
                if rho <= 0.0 {
                    return;
                }
                let source = gate_scatter_source(vol, lights, zk, nk, rng);
                add(k, w * scatter * rho * source, collisions);
            },
            None,
        );
    }
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
    /// The clock at the start of the first pending flight.
    exact: f32,
    /// Upper bound of the pending flights' clock.
    slack: f32,
    /// Pending flights: `(ray, t_start, t_end)` (the ray, its exit and
    /// the window fix the quadrature lattice).
    pending: [(ClockRay, f32, f32); LAZY_CLOCK_PENDING],
    len: usize,
}

impl LazyClock {
    fn new(exact: f32) -> Self {
        let none = ClockRay {
            clock: Clock::OpticalDepth,
            s_star: 0.0,
            origin: Vec3::ZERO,
            dir: Vec3::ZERO,
            t_exit: 0.0,
        };
        Self {
            exact,
            slack: 0.0,
            pending: [(none, 0.0, 0.0); LAZY_CLOCK_PENDING],
            len: 0,
        }
    }

    /// Marches the pending flights; returns the exact clock after them.
    fn resolve<D: DensityField>(&mut self, vol: &Volume<D>) -> f32 {
        for (ray, t0, t1) in &self.pending[..self.len] {
            if let ClockMarch::Exhausted(d) = march_clock(vol, ray, *t0, *t1, f32::INFINITY) {
                self.exact += d;
            }
        }
        self.len = 0;
        self.slack = 0.0;
        self.exact
    }

    /// Keeps the flight `(ray, t0, t1)`, `t ∈ [t0, t1]` along the ray,
    /// whose clock is at most `bound`, pending.
    fn defer<D: DensityField>(
        &mut self,
        vol: &Volume<D>,
        flight: (ClockRay, f32, f32),
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
/// `ray` (`origin + t dir`, with its window), the next gate at clock
/// `gate_clock`, in one traversal of the majorant cells: spectral
/// tracking's tentative collisions in
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
fn optical_depth_flight<D: DensityField>(
    vol: &Volume<D>,
    ray: &ClockRay,
    t_enter: f32,
    gate_clock: f32,
    lazy: &mut LazyClock,
    weight: &mut Vec3,
    rng: &mut Rng,
) -> Flight {
    let &ClockRay {
        origin,
        dir,
        t_exit,
        ..
    } = ray;
    // Bound mode: `bound` is an upper bound of the clock since
    // `lazy.exact`. Exact mode (`resolved`): `clock` is the clock from
    // `t_enter` to the current position on top of `lazy.exact`.
    let mut resolved = false;
    let mut bound = lazy.slack;
    let mut clock = 0.0f32;
    let mut lattice = ClockLattice::new(vol, ray.s_star, origin, dir);
    let mut outcome = None;
    // Marches the pending flights, then this one from its start to `to`
    // against what is left to the gate.
    let resolve_to = |lazy: &mut LazyClock, to: f32| {
        let exact = lazy.resolve(vol);
        march_clock(vol, ray, t_enter, to, gate_clock - exact)
    };
    let mut steps = TentativeSteps::new(rng);
    vol.majorants.walk(origin, dir, t_enter, t_exit, |a, b, m| {
        let mut t = a;
        loop {
            let next = steps.next(t, b, m);
            if resolved && m > 0.0 {
                let left = gate_clock - lazy.exact;
                let to = next.unwrap_or(b);
                if let Some(t_gate) = lattice.advance((a, b, m), t, to, &mut clock, left) {
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
            lazy.defer(vol, (*ray, t_enter, t), bound - lazy.slack);
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

/// Own collisions after which a walk that sums its terms
/// ([`Walks::accumulate_collided`], [`Walks::accumulate_sum`]) reads its
/// source once per flight, at one of the flight's tentative collisions
/// ([`free_flight_probed`]), instead of at its gates, and no longer
/// marches the clock (method §5.4, "Collision tails"). The gates sit at
/// whole windows of the clock from the walk's start; a sum over them from
/// a collision on equals the tail's integral (divided by `s*`) only where
/// the collision's clock falls evenly between two gates. After one
/// collision it does not quite (the clock there is `Exp(1)` from the
/// start: the gate after it comes 0.54 `s*` later on average at `s*` 0.5,
/// not 0.5), and reading from the first collision on made the suite's
/// wispy smoke 2.3 % bright (measured with readings at the collisions,
/// validation §3.22); each
/// collision's exponential flight evens it out by a factor `|1 + 2πi/s*|`
/// (12.6 at `s*` 0.5), so after three the difference is 2000 times
/// smaller than after one.
pub const COLLISION_TAIL_AFTER: u32 = 3;

/// The least `|g|` at which the walks that sum their terms take a
/// collision tail ([`COLLISION_TAIL_AFTER`]): where phase walks serve
/// `L₁` ([`PHASE_WALKS_MIN_G`]), the walks towards the eye and the phase
/// walks are most of a light set's time and their clock most of theirs
/// (the suite's thick cumulus, `g` 0.85: a set 3.5 → 1.7 s, its noise per
/// second 1.8 times lower). In the suite's thick sphere (`g` 0.5), whose
/// light comes from a layer a mean free path deep, one reading per
/// collision is noisier than two gates per mean free path by more than
/// the clock costs: its 8×8 blocks at 4 s read 3.03 → 3.32 % (12
/// renders). There the gates stay.
pub const COLLISION_TAIL_MIN_G: f32 = PHASE_WALKS_MIN_G;

/// Where a walk hands its gates over to [`Walks::collision_tail`], or the
/// tail hands the walk back: at a collision, with the walk's new direction
/// and weight (the albedo and the roulette applied), that collision's
/// second flight if it takes one, the exact clock there and the
/// collisions so far.
#[derive(Clone, Copy)]
struct TailState {
    origin: Vec3,
    dir: Vec3,
    weight: Vec3,
    second: Option<SecondFlight>,
    clock: f32,
    collisions: u32,
}

/// What one collision of [`Walks::collision_tail`]'s path read and did
/// ([`Walks::tail_step`]): the second flight's and the own flight's
/// readings (weight times `Σ σ_g ρ/m̄`, the probe's position, the direction
/// of flight; [`free_flight_probed`]), the own flight for
/// the clock's march and a bound of its clock (the medium's largest
/// majorant times its length), and whether the walk ended.
struct TailStep {
    second: Option<(Vec3, Vec3, Vec3)>,
    own: Option<(Vec3, Vec3, Vec3)>,
    flight: Option<(ClockRay, f32, f32)>,
    depth: f32,
    ended: bool,
}

/// A walk's own state at a collision, kept while the collision's second
/// flight ([`second_flight`]) runs.
struct Resume {
    origin: Vec3,
    dir: Vec3,
    weight: Vec3,
    /// The next gate.
    next: u32,
    /// The exact clock at the collision.
    clock: f32,
}

impl Resume {
    /// The walk's position, direction, weight, next gate and clock, to go
    /// on with its own flight from the collision.
    fn restore(self) -> (Vec3, Vec3, Vec3, u32, LazyClock) {
        (
            self.origin,
            self.dir,
            self.weight,
            self.next,
            LazyClock::new(self.clock),
        )
    }
}

impl<D: DensityField> Walks<'_, D> {
    /// The rest of a walk that sums its terms (or their collided part),
    /// from a collision `at` (after [`COLLISION_TAIL_AFTER`] of them) on, by
    /// a track-length estimator with one reading per flight instead of the
    /// gates.
    ///
    /// On the optical-depth clock the gates read `W (S₁/b)` every `s*` of
    /// the clock `τ`, and their sum from a collision on is, in
    /// expectation, `(1/s*) ∫ W (S₁/b) dτ` over the rest of the walk (see
    /// [`COLLISION_TAIL_AFTER`] for why only after a few collisions). The
    /// clock's rate is the grey extinction `c_g = σ_g ρ`, `σ_g` the largest
    /// channel of `σ_t`, so over one flight that integral is
    /// `(1/s*) ∫ W σ_g ρ (S₁/b) dt` along its track, which
    /// [`free_flight_probed`] estimates with the flight's own tentative
    /// collisions: one of them drawn with a chance `∝ σ_g ρ/m̄`, read there
    /// in the direction of flight, times `Σ σ_g ρ/m̄` over them. Each flight
    /// is read once — also the last one, which leaves the medium, where a
    /// reading at real collisions would have read nothing (that collision
    /// estimator, `(1/s*) W (σ_g/σ_t)(S₁/b)` at the collision ending each
    /// flight, left the light sets' variance per second 6–11 % higher on the
    /// clouds of `g` 0.85–0.95;
    /// [validation §3.23](crate::doc::validation)) — and the clock, a
    /// quadrature of about eight density lookups per mean free path, is not
    /// needed. A second flight ([`second_flight`]) is read with its factor,
    /// the walk's own flight with the other.
    ///
    /// The series ends at gate `N`, where the sum's integral ends at
    /// `(N + ½) s*`. The tail counts an upper bound of the clock (the
    /// medium's largest majorant times its flights' lengths) and reads a
    /// collision's flights only while the bound plus the majorant depth to
    /// the box's exit stays below that end. Where it does not, the tail walks its
    /// path again from `at` — its flights, directions and roulette draw
    /// from a stream of their own, so the path comes out the same — and
    /// marches the clock over its own flights this time, to return the
    /// collision it stopped at with the exact clock there, for the gates
    /// to go on from (`None`: the walk ended). Only walks that come near
    /// the series' end pay that, not the many that end long before it.
    /// `on_gate` receives the readings as gates whose weight carries
    /// `Σ (σ_g ρ/m̄)/s*`; the probes are drawn from `rng`, the walk's stream,
    /// so that they leave the path's stream alone.
    fn collision_tail(
        &self,
        at: TailState,
        guide: Option<&Lights>,
        rng: &mut Rng,
        on_gate: &mut impl FnMut(u32, Vec3, Vec3, Vec3, u32, &mut Rng),
    ) -> Option<TailState> {
        let (vol, settings) = (self.vol, &self.gates);
        let s_star = settings.s_star.max(1e-12);
        let per_gate = 1.0 / s_star;
        let end = (settings.n_terms as f32 + 0.5) * s_star;
        // The gate index the readings are reported under: the first gate
        // after the hand-over (the callers sum them).
        let k = ((at.clock / s_star).floor() as u32 + 1).min(settings.n_terms);
        let path_start = pcg_hash(rng.next_u32());
        let mut path = Rng::from_state(path_start);
        let mut state = at;
        let mut bound = at.clock;
        let mut steps = 0u32;
        loop {
            // Can a flight from here reach the series' end?
            let reach = |d: Vec3| {
                vol.clip(state.origin, d).map_or(0.0, |(a, b)| {
                    let crude = vol.majorants.peak * (b - a);
                    if bound + crude < end {
                        crude
                    } else {
                        vol.majorants.depth(state.origin, d, a, b, end - bound)
                    }
                })
            };
            let near = bound + reach(state.dir) >= end
                || state.second.is_some_and(|s| bound + reach(s.dir) >= end);
            if near {
                return Some(self.replay_tail(at, steps, guide, Rng::from_state(path_start)));
            }
            // Both flights of a step leave from the collision the walk is at.
            let collisions = state.collisions;
            let step = self.tail_step(&mut state, guide, &mut path, rng);
            if let Some((w, p, d)) = step.second {
                on_gate(k, w * per_gate, p, -d, collisions, rng);
            }
            if let Some((w, p, d)) = step.own {
                on_gate(k, w * per_gate, p, -d, collisions, rng);
            }
            bound += step.depth;
            if step.ended {
                return None;
            }
            steps += 1;
        }
    }

    /// One collision of [`Walks::collision_tail`]'s path: the second flight
    /// of the collision `state` is at, if it takes one, then the walk's own
    /// flight to its next collision and what happens there (the albedo,
    /// the roulette, the next direction and second flight), every choice
    /// drawn from `path`, the flights' probes from `pick`
    /// ([`free_flight_probed`]). Returns what the two flights read — weight
    /// (the own flight's with its balance factor), position, direction — and
    /// a bound of the own flight's clock; the own flight is read also where
    /// it leaves the medium and the walk ends.
    fn tail_step(
        &self,
        state: &mut TailState,
        guide: Option<&Lights>,
        path: &mut Rng,
        pick: &mut Rng,
    ) -> TailStep {
        let (vol, settings) = (self.vol, &self.gates);
        let mut step = TailStep {
            second: None,
            own: None,
            flight: None,
            depth: 0.0,
            ended: true,
        };
        if let Some(s) = state.second {
            if let Some(span) = vol.clip(state.origin, s.dir) {
                let mut w = state.weight * s.factor;
                let f = free_flight_probed(vol, state.origin, s.dir, span, &mut w, path, pick);
                if let Some((t, w)) = f.probe {
                    step.second = Some((w * f.depth, state.origin + s.dir * t, s.dir));
                }
            }
        }
        let own_factor = state.second.map_or(1.0, |s| s.own_factor);
        let Some(span) = vol.clip(state.origin, state.dir) else {
            return step;
        };
        let f = free_flight_probed(
            vol,
            state.origin,
            state.dir,
            span,
            &mut state.weight,
            path,
            pick,
        );
        if let Some((t, w)) = f.probe {
            step.own = Some((
                w * own_factor * f.depth,
                state.origin + state.dir * t,
                state.dir,
            ));
        }
        let Some(t_hit) = f.hit else {
            return step;
        };
        let start = state.origin;
        step.flight = Some((
            ClockRay {
                clock: Clock::OpticalDepth,
                s_star: settings.s_star.max(0.0),
                origin: start,
                dir: state.dir,
                t_exit: span.1,
            },
            span.0,
            t_hit,
        ));
        step.depth = vol.majorants.peak * (t_hit - span.0);
        state.origin += state.dir * t_hit;
        state.weight *= vol.optics.albedo;
        state.collisions += 1;
        if state.collisions >= settings.rr_start && !roulette(&mut state.weight, path) {
            return step;
        }
        let (u1, u2) = (path.next_f32(), path.next_f32());
        let incoming = state.dir;
        state.dir = match guide.filter(|_| state.collisions <= GUIDED_COLLISIONS) {
            Some(lights) => {
                let (d, factor) =
                    guided_direction(vol.optics.g, lights, state.origin, incoming, u1, u2, path);
                state.weight *= factor;
                d
            }
            None => phase::sample_hg(vol.optics.g, incoming, u1, u2),
        };
        state.second = if self.guided && vol.optics.g >= SECOND_FLIGHT_MIN_G {
            let (u, v1, v2) = (path.next_f32(), path.next_f32(), path.next_f32());
            second_flight(
                vol,
                self.lights,
                state.origin,
                incoming,
                state.dir,
                u,
                v1,
                v2,
            )
        } else {
            None
        };
        step.ended = false;
        step
    }

    /// [`Walks::collision_tail`]'s path from `at` again, `steps` collisions
    /// of it drawn from `path` (the same stream from its start), reading
    /// nothing but marching the clock over the walk's own flights: the
    /// collision the tail stopped at, with the exact clock there.
    fn replay_tail(
        &self,
        at: TailState,
        steps: u32,
        guide: Option<&Lights>,
        mut path: Rng,
    ) -> TailState {
        let mut state = at;
        let mut clock = at.clock;
        let mut pick = Rng::from_state(0);
        for _ in 0..steps {
            let step = self.tail_step(&mut state, guide, &mut path, &mut pick);
            if let Some((ray, t0, t1)) = step.flight {
                if let ClockMarch::Exhausted(d) = march_clock(self.vol, &ray, t0, t1, f32::INFINITY)
                {
                    clock += d;
                }
            }
        }
        state.clock = clock;
        state
    }

    /// The walk itself ([`gated_walk`]); when guided, its directions after a
    /// collision come from [`guided_direction`] towards the lights, or, in a
    /// medium of `g` ≥ [`SECOND_FLIGHT_MIN_G`], each collision also takes a
    /// [`second_flight`]: it runs right after the collision, up to its own
    /// first collision, with the gates on the way weighted by its factor
    /// (the walk's weight carries it), and then the walk resumes its own
    /// flight from the collision, whose gates take the other factor.
    /// `on_gate(k, weight, z_k, n_k, collisions, rng)` also learns how many
    /// real collisions the walk has made and receives the random stream,
    /// so that the caller can trace shadow rays; `on_collision(clock)`, if given, is
    /// called at every real collision with the clock's value there (a hook
    /// for tests: it makes the optical-depth clock resolve at every
    /// collision).
    fn walk(
        &self,
        z: Vec3,
        n: Vec3,
        rng: &mut Rng,
        tail: bool,
        mut on_gate: impl FnMut(u32, Vec3, Vec3, Vec3, u32, &mut Rng),
        mut on_collision: Option<&mut dyn FnMut(f32)>,
    ) {
        let (vol, settings) = (self.vol, &self.gates);
        let seconds = self.guided && vol.optics.g >= SECOND_FLIGHT_MIN_G;
        let guide = (self.guided && !seconds).then_some(self.lights);
        let s_star = settings.s_star.max(0.0);
        let last = settings.n_terms;
        let mut weight = Vec3::ONE;
        on_gate(0, weight, z, n, 0, rng);
        if last == 0 {
            return;
        }
        let mut next = 1u32;
        let mut origin = z;
        let mut dir = -n;
        // The clock at `origin`: exactly `lazy.exact` with the geometric clock
        // (which is never pending), `lazy.exact` plus the pending flights with
        // the optical-depth clock.
        let mut lazy = LazyClock::new(0.0);
        let mut collisions = 0u32;
        // The factor of the gates of the walk's own flight since its last
        // collision (a second flight's balance weight; 1 without one).
        let mut own_factor = 1.0f32;
        // While a second flight runs: the walk's own state at the collision
        // it resumes from.
        let mut resume: Option<Resume> = None;
        // One flight per iteration: from `origin` to the next gate, the next
        // real collision, or the exit of the box, whichever comes first.
        'flights: loop {
            let Some((t_enter, t_exit)) = vol.clip(origin, dir) else {
                // Leaving the box ends a second flight, or the walk.
                let Some(own) = resume.take() else {
                    return;
                };
                (origin, dir, weight, next, lazy) = own.restore();
                continue;
            };
            let clock_at_enter = match settings.clock {
                Clock::Geometric => lazy.exact + t_enter,
                Clock::OpticalDepth => lazy.exact,
            };
            // Gates in the vacuum before the box (only when `z` is outside it,
            // and only for the geometric clock), or at a flight's start where
            // rounding put the clock on the gate.
            while settings.clock == Clock::Geometric && next as f32 * s_star <= clock_at_enter {
                let t = next as f32 * s_star - lazy.exact;
                let factor = if resume.is_some() { 1.0 } else { own_factor };
                on_gate(
                    next,
                    weight * factor,
                    origin + dir * t,
                    -dir,
                    collisions,
                    rng,
                );
                if next == last {
                    let Some(own) = resume.take() else {
                        return;
                    };
                    (origin, dir, weight, next, lazy) = own.restore();
                    continue 'flights;
                }
                next += 1;
            }
            let gate_clock = next as f32 * s_star;
            let flight = match settings.clock {
                Clock::OpticalDepth => {
                    let ray = ClockRay {
                        clock: Clock::OpticalDepth,
                        s_star,
                        origin,
                        dir,
                        t_exit,
                    };
                    optical_depth_flight(
                        vol,
                        &ray,
                        t_enter,
                        gate_clock,
                        &mut lazy,
                        &mut weight,
                        rng,
                    )
                }
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
            // A second flight ends where its flight does (a collision, the
            // box's exit, its last gate); the walk resumes from its collision.
            let ends_second = match flight {
                Flight::Collision { .. } | Flight::Exit => true,
                Flight::Gate(_) => false,
            };
            if let Some(own) = resume.take_if(|_| ends_second) {
                (origin, dir, weight, next, lazy) = own.restore();
                continue;
            }
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
                    if collisions >= settings.rr_start && !roulette(&mut weight, rng) {
                        return;
                    }
                    let (u1, u2) = (rng.next_f32(), rng.next_f32());
                    let incoming = dir;
                    dir = match guide.filter(|_| collisions <= GUIDED_COLLISIONS) {
                        Some(lights) => {
                            let (d, factor) =
                                guided_direction(vol.optics.g, lights, origin, dir, u1, u2, rng);
                            weight *= factor;
                            d
                        }
                        None => phase::sample_hg(vol.optics.g, dir, u1, u2),
                    };
                    own_factor = 1.0;
                    let second = if seconds {
                        let (u, v1, v2) = (rng.next_f32(), rng.next_f32(), rng.next_f32());
                        second_flight(vol, self.lights, origin, incoming, dir, u, v1, v2)
                    } else {
                        None
                    };
                    if tail && collisions >= COLLISION_TAIL_AFTER {
                        let at = TailState {
                            origin,
                            dir,
                            weight,
                            second,
                            clock: lazy.resolve(vol).min(gate_clock),
                            collisions,
                        };
                        let Some(back) = self.collision_tail(at, guide, rng, &mut on_gate) else {
                            return;
                        };
                        // The series' end is near: the gates take the walk
                        // over again from the collision the tail stopped at.
                        let first = (back.clock / s_star).floor() as u32 + 1;
                        if first > last {
                            return;
                        }
                        (origin, dir, weight, next, collisions) =
                            (back.origin, back.dir, back.weight, first, back.collisions);
                        lazy = LazyClock::new(back.clock);
                        own_factor = 1.0;
                        if let Some(second) = back.second {
                            own_factor = second.own_factor;
                            resume = Some(Resume {
                                origin,
                                dir,
                                weight,
                                next,
                                clock: back.clock,
                            });
                            dir = second.dir;
                            weight *= second.factor;
                        }
                        continue;
                    }
                    if let Some(second) = second {
                        // The second flight starts from the exact clock.
                        let clock = lazy.resolve(vol).min(gate_clock);
                        own_factor = second.own_factor;
                        resume = Some(Resume {
                            origin,
                            dir,
                            weight,
                            next,
                            clock,
                        });
                        dir = second.dir;
                        weight *= second.factor;
                        lazy = LazyClock::new(clock);
                    }
                }
                Flight::Exit => return,
                Flight::Gate(t) => {
                    if weight == Vec3::ZERO {
                        let Some(own) = resume.take() else {
                            return;
                        };
                        (origin, dir, weight, next, lazy) = own.restore();
                        continue;
                    }
                    origin += dir * t;
                    // A second flight's weight carries its factor.
                    let factor = if resume.is_some() { 1.0 } else { own_factor };
                    on_gate(next, weight * factor, origin, -dir, collisions, rng);
                    if next == last {
                        let Some(own) = resume.take() else {
                            return;
                        };
                        (origin, dir, weight, next, lazy) = own.restore();
                        continue;
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::internal::clock::{clock_cell, clock_step};
    use crate::physics::testing::*;
    use glam::DVec3;

    /// Collisions per window of the clock for `walks` walks: a histogram of
    /// counts in windows `1..=N` (the windows between consecutive gates).
    fn window_counts(vol: &Volume<Field>, settings: &GateSettings, walks: u32) -> Vec<u64> {
        let mut hist = vec![0u64; 64];
        for w in 0..walks {
            let mut rng = Rng::for_sample(5, w, 0);
            let mut per_window = vec![0usize; settings.n_terms as usize];
            let s = settings.s_star;
            let walks = Walks {
                vol,
                lights: &Lights::default(),
                gates: *settings,
                guided: false,
            };
            walks.walk(
                Vec3::ZERO,
                Vec3::Z,
                &mut rng,
                false,
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

    /// [`Walks::accumulate_collided`] skips the shadow rays of the gates before
    /// the first collision and keeps the estimator: in the medium of
    /// `guided_walks_keep_the_mean`, its mean agrees per channel with
    /// [`collided`](super::chances::collided) of [`Walks::accumulate_j_from`]'s outputs within 4.5 standard
    /// errors of the difference, and both are far from the uncollided
    /// part it leaves out (which would show if it kept or lost a share).
    #[test]
    fn collided_walks_match_the_collided_part() {
        let (vol, lights, settings, z, n) = forward_scattering_walk();
        let walks = Walks::guided(&vol, &lights, settings);
        let count = 200_000u32;
        let mut uncollided = Vec3::ZERO;
        let (full, full_var) = mean_and_its_variance(count, 23, 0, |rng| {
            let (collided, before) = split_walk(&walks, z, n, rng);
            uncollided += before;
            collided
        });
        uncollided /= count as f32;
        let (skip, skip_var) =
            mean_and_its_variance(count, 23, 1, |rng| walks.accumulate_collided(z, n, rng));
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

    /// The collision tail reads what the gates read: the collided part
    /// (the walks towards the eye) and the whole sum (the phase walks) of
    /// walks in a box of optical depth 4–16 across, with grey and chromatic
    /// extinction (`σ_g/σ_t` differs per channel), with and without second
    /// flights (`g` 0.85 takes them, −0.8 does not), a series long enough for
    /// the tail to run to the walks' end (`N` 40) and one short enough that
    /// most tails hand the walk back to the gates before its end (`N` 8: the
    /// end at a clock of 4.25). The same random streams make the two agree
    /// exactly where a walk ends before its third collision; the test also
    /// asserts that a third of the walks or more took the tail (49–81 %
    /// do), so that it cannot pass by never taking it, and that 4.5
    /// standard errors are below 6 % of the mean.
    #[test]
    fn collision_tail_reads_what_the_gates_read() {
        let count = 400_000u32;
        for (case, (g, sigma_t, n_terms)) in [
            (0.85, Vec3::new(1.0, 0.7, 0.4), 40),
            (-0.8, Vec3::ONE, 40),
            (0.85, Vec3::new(1.0, 0.7, 0.4), 8),
        ]
        .into_iter()
        .enumerate()
        {
            let (_, lights, mut settings, z, n) = forward_scattering_walk();
            let mut vol = boxed(2.4, 1.6, 0.99, 2.0, 4);
            vol.optics.g = g;
            vol.optics.sigma_t = sigma_t;
            settings.n_terms = n_terms;
            let walks = Walks::guided(&vol, &lights, settings);
            // (The phase walks' sum only where second flights are taken.)
            for collided_only in [true, false].into_iter().filter(|&c| c || g > 0.0) {
                let seed = 31 + 2 * case as u64 + collided_only as u64;
                // Both estimators on each walk's stream, summed in f64.
                let (mut sums, mut sums2) = ([DVec3::ZERO; 2], [DVec3::ZERO; 2]);
                let mut differ = 0usize;
                for w in 0..count {
                    let gates =
                        walks.sum_by_gates(z, n, collided_only, &mut Rng::for_sample(seed, w, 0));
                    let mut rng = Rng::for_sample(seed, w, 0);
                    let tail = if collided_only {
                        walks.accumulate_collided(z, n, &mut rng)
                    } else {
                        walks.accumulate_sum(z, n, &mut rng)
                    };
                    differ += usize::from(gates != tail);
                    for (i, v) in [gates, tail].into_iter().enumerate() {
                        sums[i] += v.as_dvec3();
                        sums2[i] += v.as_dvec3() * v.as_dvec3();
                    }
                }
                let m = count as f64;
                let mean = |i: usize| sums[i] / m;
                let var_of_mean = |i: usize| (sums2[i] / m - mean(i) * mean(i)) / m;
                let (gates, tail) = (mean(0), mean(1));
                eprintln!(
                    "g {g}, σ_t {sigma_t}, N {n_terms}, collided only {collided_only}: \
                     gates {gates}, tail {tail}, {differ} of {count} walks differ"
                );
                assert!(differ > count as usize / 3, "the tail was seldom taken");
                for c in 0..3 {
                    let se = (var_of_mean(0)[c] + var_of_mean(1)[c]).sqrt();
                    assert!(
                        (gates[c] - tail[c]).abs() < 4.5 * se,
                        "g {g}, N {n_terms}, channel {c}: gates {} tail {} (se {se})",
                        gates[c],
                        tail[c]
                    );
                    assert!(
                        4.5 * se < 0.06 * gates[c],
                        "too noisy to tell a bias of 6 % (se {se} of {})",
                        gates[c]
                    );
                }
            }
        }
    }

    /// A truncation past [`RESOLVED_TERMS`](super::super::clock::RESOLVED_TERMS)
    /// still walks to gate `N`: with the same random numbers, an output
    /// of `N + 1` slots and one of [`GateSettings::term_slots`] agree on
    /// every resolved term, and the last slot holds the sum of the rest
    /// (which the walks here do reach).
    #[test]
    fn terms_past_the_resolved_ones_fold_into_the_last_slot() {
        use super::super::clock::{term_slot, RESOLVED_TERMS};
        let (vol, lights, mut settings, z, n) = forward_scattering_walk();
        settings.s_star = 0.005;
        settings.n_terms = RESOLVED_TERMS + 120;
        let walks = Walks::guided(&vol, &lights, settings);
        let slots = settings.term_slots();
        assert_eq!(slots, RESOLVED_TERMS as usize + 1);
        assert_eq!(term_slot(RESOLVED_TERMS + 7), slots - 1);
        let mut folded_walks = 0;
        for w in 0..400 {
            let mut full = vec![Vec3::ZERO; settings.n_terms as usize + 1];
            let mut full_u = full.clone();
            let mut folded = vec![Vec3::ZERO; slots];
            let mut folded_u = folded.clone();
            walks.accumulate_j_from(
                z,
                n,
                1,
                &mut Rng::for_sample(3, w, 0),
                &mut full,
                Some(&mut full_u),
            );
            walks.accumulate_j_from(
                z,
                n,
                1,
                &mut Rng::for_sample(3, w, 0),
                &mut folded,
                Some(&mut folded_u),
            );
            let last = slots - 1;
            assert_eq!(full[..last], folded[..last], "walk {w}");
            assert_eq!(full_u[..last], folded_u[..last], "walk {w}");
            let rest: Vec3 = full[last..].iter().sum();
            let rest_u: Vec3 = full_u[last..].iter().sum();
            let tol = 1e-5 * rest.abs().max_element().max(1e-30);
            assert!(
                (folded[last] - rest).abs().max_element() <= tol,
                "walk {w}: {} vs {rest}",
                folded[last]
            );
            assert!(
                (folded_u[last] - rest_u).abs().max_element() <= tol,
                "walk {w}"
            );
            if full[last + 1..].iter().any(|v| *v != Vec3::ZERO) {
                folded_walks += 1;
            }
        }
        assert!(
            folded_walks > 40,
            "only {folded_walks} walks reached past the resolved terms"
        );
    }

    /// The presets' series runs until the walks end, even in a thick
    /// cloud: a slab 40 mean free paths thick of albedo 0.999 that scatters
    /// isotropically (so light diffuses through hundreds of collisions),
    /// lit from above, its `J` read just under the lit face towards the
    /// sky, with the default `s*` and truncation. Walks carried to gate
    /// [`MAX_TERMS`](crate::scene::settings::MAX_TERMS) show that the
    /// terms past the default `N` hold less than half a percent of the
    /// light, while those past 256 windows — the default before — hold
    /// more than two percent (the medium is one where the truncation
    /// shows).
    #[test]
    fn the_default_series_keeps_a_thick_clouds_long_paths() {
        use crate::scene::settings::{Quality, DEFAULT_S_STAR, MAX_TERMS};
        let mut vol = boxed(1.0, 0.0, 0.999, 20.0, 4);
        vol.optics.g = 0.0;
        let lights = one_sun(Vec3::NEG_Y, Vec3::ONE);
        let default_terms = Quality::Final.settings().knobs.terms;
        let settings = GateSettings {
            s_star: DEFAULT_S_STAR,
            n_terms: MAX_TERMS,
            clock: Clock::OpticalDepth,
            rr_start: crate::physics::reference::RR_START_DEPTH,
        };
        let walks = Walks::guided(&vol, &lights, settings);
        let z = Vec3::new(0.0, 19.0, 0.0);
        let scatter = vol.optics.albedo * vol.optics.sigma_t;
        // Per walk: all its light, that past 256 windows, that past the
        // default truncation.
        let count = 20_000u32;
        let (mut sum, mut sum2) = ([0.0f64; 3], [0.0f64; 3]);
        for w in 0..count {
            let mut rng = Rng::for_sample(41, w, 0);
            let mut v = [0.0f64; 3];
            walks.walk(
                z,
                Vec3::Y,
                &mut rng,
                false,
                |k, wt, zk, nk, _, rng| {
                    if k == 0 || wt == Vec3::ZERO {
                        return;
                    }
                    let s = (wt
                        * scatter
                        * crate::physics::reference::single_scatter_source(
                            &vol, &lights, zk, nk, rng,
                        ))
                    .x as f64;
                    v[0] += s;
                    if k > 256 {
                        v[1] += s;
                    }
                    if k > default_terms {
                        v[2] += s;
                    }
                },
                None,
            );
            for i in 0..3 {
                sum[i] += v[i];
                sum2[i] += v[i] * v[i];
            }
        }
        let n = count as f64;
        let mean = sum.map(|s| s / n);
        let se: Vec<f64> = (0..3)
            .map(|i| ((sum2[i] / n - mean[i] * mean[i]).max(0.0) / n).sqrt())
            .collect();
        let share = |i: usize| (mean[i] / mean[0], se[i] / mean[0]);
        let (past_256, past_256_se) = share(1);
        let (past_default, past_default_se) = share(2);
        eprintln!(
            "J {:.4e} ± {:.1e}; past 256 windows {:.2} ± {:.2} %, past N = {default_terms}: {:.3} ± {:.3} %",
            mean[0], se[0], 100.0 * past_256, 100.0 * past_256_se, 100.0 * past_default, 100.0 * past_default_se
        );
        assert!(
            past_default + 2.0 * past_default_se < 0.005,
            "the default truncation drops light"
        );
        assert!(
            past_256 - 4.0 * past_256_se > 0.02,
            "the test's medium does not show truncation"
        );
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
                    let walks = Walks {
                        vol: &vol,
                        lights: &Lights::default(),
                        gates: settings,
                        guided: false,
                    };
                    walks.walk(
                        Vec3::new(0.3, -0.2, 0.1),
                        Vec3::Z,
                        &mut rng,
                        false,
                        |k, _, p, _, collisions, _| out.push((k, p, collisions > 0)),
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
}
