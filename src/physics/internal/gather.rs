//! The final gather of the internal-lights method ([method §6](crate::doc::method)): the
//! radiance at the point `x` where a camera ray enters the medium's box,
//! `L ≈ L₀ + L₁`, from a window of the path-length clock that starts at `x`.
//!
//! One call is one unbiased estimate *given the cached internal lights*,
//! so passes average to the method's image. The window `[0, w]` of the
//! camera ray is cut into `samples` strata with one jittered point `y` each
//! (transmittance `T(x, y)` by ratio tracking): uniform in distance for the
//! geometric clock, and for the optical-depth clock strata of a density
//! that follows where light is stopped along the window ([`SegmentPdf`]:
//! every integrand here carries the extinction at `y` and the
//! transmittance to it; on the puffs at 96², two points per ray, this cut
//! the per-pass variance of the three parts 2.3×, 1.7× and 1.7× for 18 %
//! more time per pass). Its parts are:
//!
//! - **single**: the `k = 0` part of `L₀`, `∫ T b S₁ dt`, with `S₁(y)` by
//!   next-event estimation to the external lights at each point (a
//!   marched single scatter: every sample sees the whole window, where one
//!   collision by free flight sees it with probability `1 − e^{−s*}` only);
//!   and the unscattered part of the `k ≥ 1` terms, the same march over
//!   the rest of the ray up to a clock of `(N+1) s*` at as many stratified
//!   points (`J_k` at `y` holds `T S₁` from `k s*` further along the ray;
//!   over the window these add up to that march).
//! - **reconstructed**: the rest of the `k ≥ 1` part of `L₀`, `∫ T Ĵ dt`
//!   with `Ĵ` the kernel reconstruction
//!   ([`InternalLights::reconstruct_multi`]) of what the walks carried
//!   through a collision ([`Part::Scattered`]: per unit chance of that
//!   collision, times the chance at `y`; the window's points share one
//!   march for their chances, [`super::chances::ChancesAlongRay`]).
//! - **internal**: `L₁`, one scattering inside the window of light that
//!   left a source `J` earlier in the window (clock from `x` to `y` plus
//!   clock from `y` to the source at most `s*`), in one of two forms
//!   ([`L1Form`]):
//!   - *field* (default): `b(y) ∫ dn' P(n·n') ∫ dr T(y, x') J(x', n')`
//!     with `x' = y − r n'` and `J = S₁ + Ĵ` the same reconstructed field as
//!     `L₀`'s. `n'` is drawn from the phase function and `r` up to where
//!     the clock's budget runs out — uniformly in distance for the
//!     geometric clock, uniformly in the clock for the optical-depth one
//!     (so in proportion to the extinction, which `J` carries; on the puffs
//!     at 256² this cut `L₁`'s per-pass variance 11 % and the march to the
//!     budget's end) — so `d³x' = r² dr dn'` cancels the `1/r²` and no
//!     bounded kernel is needed.
//!   - *points* (the note's eq. 23, [method §6](crate::doc::method)): the sum over the
//!     internal lights `Σ V_i b P T T J_i / (r² + h₁²)` with the bounded
//!     kernel (`h₁`: [`InternalLights::softening`]). Each sample draws one
//!     light: a cluster with probability `∝ P_c / (d_c² + h₁²)` (`P_c`: the
//!     cluster's power `Σ V_i J̄_i`, `d_c`: its distance from the window's
//!     segment of the ray), then a light of the cluster `∝ V_i J̄_i`; then a
//!     point on the ray by equiangular sampling about the light, whose
//!     density is proportional to the kernel itself, so that the kernel
//!     cancels; then both transmittances by ratio tracking. Every light
//!     with `J̄_i > 0` has a positive probability, so the estimate is
//!     unbiased for the sum over the cached lights.
//!
//! The two forms estimate the same integral as `M → ∞`, `h → 0`; they
//! differ in their bias at finite settings. The bounded kernel keeps only
//! `1 − (h₁/R) atan(R/h₁)` of the light of lights within `R` of the ray, so
//! when the window is short next to the light spacing (a dense medium at
//! small `s*`) the points form loses much of `L₁`: on the chromatic sphere
//! at `s* = 0.25` mean free paths the red channel came out 11.5 % low with
//! points and 4.5 % low with the field ([validation](crate::doc::validation) §4).

use glam::Vec3;

use super::chances::ChancesAlongRay;

use super::clock::{
    clock_at_each, clock_to, march_clock, march_clock_rate, Clock, ClockMarch, ClockRay,
};
use super::segment_pdf::SegmentPdf;
use super::sources::{InternalLights, L1Form, Part};
use crate::physics::lights::Lights;
use crate::physics::phase;
use crate::physics::reference::{background, single_scatter_source_with};
use crate::physics::rng::Rng;
use crate::physics::tracking::Transmittance;
use crate::physics::volume::{DensityField, Volume};

/// How the gather estimates every transmittance (to the window's points,
/// the shadow rays of `S₁`, `L₁`'s segments, the sky behind the medium),
/// on both backends: the unbiased ray march
/// ([`crate::physics::tracking::transmittance_marched`]; the WGSL
/// `transmittance_marched`, one loop with a single density lookup so that
/// Mesa's software driver, which inlines each of the gather shader's dozen
/// calls, can compile it). Ratio tracking at 8 times the majorant came
/// before it (itself 2.05× less variance per second than plain ratio
/// tracking on the puffs, where a tight majorant makes ratio tracking a
/// yes-or-no estimate); against it the march cut the gather's variance
/// × time 14–29 % on the plumes, the cumulus, the chromatic and the
/// point-lit scenes ([validation](crate::doc::validation) §3.11). The walks
/// keep plain ratio tracking: their noise is their paths'
/// ([validation](crate::doc::validation) §4, "Tried and not kept").
pub const GATHER_TRANSMITTANCE: Transmittance = Transmittance::Marched;

/// The most stratified points per camera ray ([`gather`]'s `samples`;
/// the scene's `light_samples` is validated against it): the settings'
/// bound, defined with them so that the scene layer needs nothing of this
/// one.
pub use crate::scene::settings::MAX_GATHER_POINTS;

/// One gather estimate, by part.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GatherSample {
    /// `L₀`'s `k = 0` part: single scatter inside the window (and, when the
    /// sky is drawn as the background, the sky seen through the medium).
    pub single: Vec3,
    /// `L₀`'s `k ≥ 1` part: the reconstructed `J` along the ray.
    pub reconstructed: Vec3,
    /// `L₁`: single scatter of the internal lights.
    pub internal: Vec3,
}

impl GatherSample {
    /// `L₀ + L₁`.
    pub fn total(&self) -> Vec3 {
        self.single + self.reconstructed + self.internal
    }
}

/// The unscattered part of `L₀`'s `k ≥ 1` terms: `J_k` at `y_t` holds
/// `T(y_t, y') S₁(y', n)` from the point `y'` a clock `k s*` further along
/// the ray, so over the window they add up to the single scatter on the
/// rest of the ray up to a clock of `(N+1) s*`, `∫ T(x, y) S₁(y, n) dt`
/// over `[window, end]`, marched here at `samples` stratified points (the
/// walks keep this part out of what `L₀` reconstructs: see
/// [`Part::Scattered`]).
/// `ray` is the camera ray from where it enters the box, `window` where
/// its window ends.
fn single_beyond_window<D: DensityField>(
    vol: &Volume<D>,
    lights: &Lights,
    cache: &InternalLights,
    ray: &ClockRay,
    window: f32,
    samples: u32,
    rng: &mut Rng,
) -> Vec3 {
    let &ClockRay {
        origin: x,
        dir,
        t_exit: len,
        ..
    } = ray;
    let terms = cache.params.terms;
    if terms == 0 || window >= len {
        return Vec3::ZERO;
    }
    // The clock is at `s*` at the window's end: march on from there (not
    // again from `x`) for the remaining `N s*`.
    let budget = cache.s_star * terms as f32;
    let end = match march_clock(vol, ray, window, len, budget) {
        ClockMarch::Reached(t) => t,
        ClockMarch::Exhausted(_) => len,
    };
    if end <= window {
        return Vec3::ZERO;
    }
    let n = -dir;
    let points = points_along(vol, cache.params.clock, x, dir, window, end);
    let mut sum = Vec3::ZERO;
    for j in 0..samples {
        let (t, inv_pdf) = points.sample((j as f32 + rng.next_f32()) / samples as f32);
        let step = inv_pdf / samples as f32;
        let y = x + dir * t;
        let rho = vol.density.density(y);
        if rho <= 0.0 {
            continue;
        }
        let s1 = cache.scatter
            * rho
            * single_scatter_source_with(vol, lights, y, n, GATHER_TRANSMITTANCE, rng);
        if s1 == Vec3::ZERO {
            continue;
        }
        sum += GATHER_TRANSMITTANCE.estimate(vol, x, dir, t, rng) * s1 * step;
    }
    sum
}

/// Where the gather's points go along `[t0, t1]` of `origin + t dir`:
/// uniformly for the geometric clock, by where light is stopped for the
/// optical-depth clock (see [`SegmentPdf`]).
#[inline]
fn points_along<D: DensityField>(
    vol: &Volume<D>,
    clock: Clock,
    origin: Vec3,
    dir: Vec3,
    t0: f32,
    t1: f32,
) -> SegmentPdf {
    match clock {
        Clock::Geometric => SegmentPdf::uniform(t0, t1),
        Clock::OpticalDepth => SegmentPdf::by_extinction(vol, origin, dir, t0, t1),
    }
}

/// Distance from `p` to the segment `a + t d`, `t ∈ [0, len]` (`d` unit).
#[inline]
fn distance_to_segment(p: Vec3, a: Vec3, d: Vec3, len: f32) -> f32 {
    let t = (p - a).dot(d).clamp(0.0, len);
    (p - (a + d * t)).length()
}

/// One estimate of `L₀ + L₁` for the camera ray `eye + t dir` (`dir` unit),
/// with `samples` stratified points for the reconstructed part and
/// `samples` internal-light samples.
pub fn gather<D: DensityField>(
    vol: &Volume<D>,
    lights: &Lights,
    cache: &InternalLights,
    eye: Vec3,
    dir: Vec3,
    samples: u32,
    rng: &mut Rng,
) -> GatherSample {
    let mut out = GatherSample::default();
    let sky = background(lights, dir);
    let Some((t_in, t_out)) = vol.clip(eye, dir) else {
        out.single = sky;
        return out;
    };
    let x = eye + dir * t_in;
    let len = t_out - t_in;
    if sky != Vec3::ZERO {
        // The sky behind the medium, through all of it.
        out.single = sky * GATHER_TRANSMITTANCE.estimate(vol, x, dir, len, rng);
    }
    let s_star = cache.s_star;
    let clock = cache.params.clock;
    let ray = ClockRay {
        clock,
        s_star,
        origin: x,
        dir,
        t_exit: len,
    };
    // The window's end along the ray.
    let window = match march_clock(vol, &ray, 0.0, len, s_star) {
        ClockMarch::Reached(t) => t,
        ClockMarch::Exhausted(_) => len,
    };
    if window <= 0.0 {
        return out;
    }
    let n = -dir;

    let field = cache.params.l1 == L1Form::Field;
    let samples = samples.clamp(1, MAX_GATHER_POINTS as u32);
    // L₀ (both parts) and, for the field form, L₁: stratified points of
    // the window, ratio-tracked transmittance from `x`; for `L₁`'s budget
    // the clock at each point from `x`, all in one march
    // ([`clock_at_each`]).
    let n_points = samples as usize;
    let points = points_along(vol, clock, x, dir, 0.0, window);
    let mut ts = [0.0f32; MAX_GATHER_POINTS];
    let mut steps = [0.0f32; MAX_GATHER_POINTS];
    for j in 0..n_points {
        let (t, inv_pdf) = points.sample((j as f32 + rng.next_f32()) / samples as f32);
        ts[j] = t;
        steps[j] = inv_pdf / samples as f32;
    }
    let mut clocks = [0.0f32; MAX_GATHER_POINTS];
    if field {
        clock_at_each(vol, &ray, &ts[..n_points], &mut clocks);
    }
    // The strata are visited from the window's far end back, so that the
    // collided part's chances of a collision share one march
    // ([`ChancesAlongRay`]).
    let mut chances = ChancesAlongRay::new(x, dir, len, s_star);
    for j in (0..n_points).rev() {
        let (t, step) = (ts[j], steps[j]);
        let y = x + dir * t;
        let rho = vol.density.density(y);
        let mut j_hat = if cache.has_view() {
            cache.reconstruct_view(y, rho)
        } else {
            cache.reconstruct_multi(y, n, rho, Part::Scattered)
        };
        if j_hat != Vec3::ZERO {
            j_hat *= chances.at(vol, t);
        }
        let (s1, l1) = if rho > 0.0 {
            let s1 = cache.scatter
                * rho
                * single_scatter_source_with(vol, lights, y, n, GATHER_TRANSMITTANCE, rng);
            let l1 = if field {
                let at = WindowPoint {
                    position: y,
                    density: rho,
                    towards: n,
                };
                field_l1_at(vol, lights, cache, &at, s_star - clocks[j], rng)
            } else {
                Vec3::ZERO
            };
            (s1, l1)
        } else {
            (Vec3::ZERO, Vec3::ZERO)
        };
        if j_hat == Vec3::ZERO && l1 == Vec3::ZERO && s1 == Vec3::ZERO {
            continue;
        }
        let tr = GATHER_TRANSMITTANCE.estimate(vol, x, dir, t, rng);
        out.reconstructed += tr * j_hat * step;
        out.internal += tr * l1 * step;
        out.single += tr * s1 * step;
    }
    out.single += single_beyond_window(vol, lights, cache, &ray, window, samples, rng);
    if field {
        return out;
    }

    // L₁ as the note writes it: a sum over the internal lights.
    if cache.live_clusters.is_empty() {
        return out;
    }
    let h = cache.softening;
    let h2 = h * h;
    let grid = &cache.clusters;
    let mut cdf: Vec<(u32, f32)> = Vec::with_capacity(cache.live_clusters.len());
    let mut total = 0.0f32;
    for &c in &cache.live_clusters {
        let (lo, hi) = grid.cell_box(c as usize);
        let centre = 0.5 * (lo + hi);
        let half_diag = 0.5 * (hi - lo).length();
        if clock == Clock::Geometric && (centre - x).length() - half_diag > s_star {
            continue;
        }
        let d = (distance_to_segment(centre, x, dir, window) - half_diag).max(0.0);
        total += cache.cluster_power[c as usize] / (d * d + h2);
        cdf.push((c, total));
    }
    if total <= 0.0 {
        return out;
    }
    let inv_samples = 1.0 / samples as f32;
    for _ in 0..samples {
        // A cluster, then a light in it.
        let u = rng.next_f32() * total;
        let k = cdf.partition_point(|&(_, w)| w <= u).min(cdf.len() - 1);
        let (c, cum) = cdf[k];
        let prev = if k == 0 { 0.0 } else { cdf[k - 1].1 };
        let p_cluster = (cum - prev) / total;
        let range = grid.cell_range(c as usize);
        let powers = &cache.light_power[range.clone()];
        let cluster_power = cache.cluster_power[c as usize];
        let mut pick = rng.next_f32() * cluster_power;
        let mut slot = powers.len() - 1;
        for (s, &p) in powers.iter().enumerate() {
            if pick < p {
                slot = s;
                break;
            }
            pick -= p;
        }
        // Rounding may leave `pick` past the end: the last light with power.
        if powers[slot] <= 0.0 {
            slot = powers.iter().rposition(|&p| p > 0.0).unwrap_or(slot);
        }
        let q = p_cluster * powers[slot] / cluster_power;
        if q <= 0.0 {
            continue;
        }
        let i = grid.ids()[range.start + slot] as usize;
        let light = &cache.lights[i];
        let xi = light.position;

        // Equiangular sampling of t ∈ [0, window] for the kernel
        // 1/(r² + h²) = 1/(D² + h² + (t − t_c)²).
        let t_c = (xi - x).dot(dir);
        let d2 = ((xi - x) - dir * t_c).length_squared() + h2;
        let dd = d2.sqrt();
        let theta_a = ((0.0 - t_c) / dd).atan();
        let theta_b = ((window - t_c) / dd).atan();
        let span = theta_b - theta_a;
        if span <= 0.0 {
            continue;
        }
        let t = (t_c + dd * (theta_a + rng.next_f32() * span).tan()).clamp(0.0, window);
        let y = x + dir * t;
        let rho_y = vol.density.density(y);
        if rho_y <= 0.0 {
            continue;
        }
        let to_y = y - xi;
        let r = to_y.length();
        if r <= 0.0 {
            continue;
        }
        let n_light = to_y / r;
        // The window condition on the total path length.
        let within = match clock {
            Clock::Geometric => t + r <= s_star,
            Clock::OpticalDepth => {
                let a = clock_to(vol, &ray, t);
                if a > s_star {
                    false
                } else {
                    let back = -n_light;
                    match vol.clip(y, back) {
                        Some((_, exit)) => {
                            let to_light = ClockRay {
                                origin: y,
                                dir: back,
                                t_exit: exit,
                                ..ray
                            };
                            a + clock_to(vol, &to_light, r.min(exit)) <= s_star
                        }
                        None => true,
                    }
                }
            }
        };
        if !within {
            continue;
        }
        let j = cache.eval_j(i, n_light);
        if j == Vec3::ZERO {
            continue;
        }
        let tr = GATHER_TRANSMITTANCE.estimate(vol, x, dir, t, rng)
            * GATHER_TRANSMITTANCE.estimate(vol, y, -n_light, r, rng);
        if tr == Vec3::ZERO {
            continue;
        }
        let b = cache.scatter * rho_y;
        let p = phase::hg(cache.g, n_light.dot(n));
        // V_i b P T T J / (r² + h²) / (q · pdf(t)), with
        // 1 / ((r² + h²) pdf(t)) = span / D'.
        out.internal += b * tr * j * (light.weight * p * span / dd / q * inv_samples);
    }
    out
}

/// A point `y` of a camera ray's window: its position, the density there
/// and the direction `n` light leaves it in towards the camera.
struct WindowPoint {
    position: Vec3,
    density: f32,
    towards: Vec3,
}

/// `L₁`'s integrand at the camera-ray point `at`, `y = x + t dir` (without
/// `T(x, y)`; `budget`: `s*` less the clock from `x` to `y`), one
/// sample: `b(y) ∫ dn' P(n·n') ∫ dr T(y, x') Ĵ(x', n')` over the window,
/// with `x' = y − r n'`, `n'` drawn from the phase function and `r` within
/// the clock's remaining budget (uniformly in the clock); with
/// [`InternalParams::window_scatters`] `m > 1`, also the terms of
/// `m − 1` more scatterings inside the window: the same step again from
/// `x'` towards `x''` within what is left of the budget, so that the
/// source at `x''` has travelled `x'' → x' → y` with the clock from `x` to
/// `x''` at most `s*` (the next terms of the expansion of `G(s)` inside
/// the window by number of scatterings, [method §6](crate::doc::method)'s `G ≈ G_SS` being
/// its first two), each further step taken by Russian roulette with the
/// share of a window left in the budget ([method §6.4](crate::doc::method)).
fn field_l1_at<D: DensityField>(
    vol: &Volume<D>,
    lights: &Lights,
    cache: &InternalLights,
    at: &WindowPoint,
    budget: f32,
    rng: &mut Rng,
) -> Vec3 {
    let mut budget = budget;
    let scatters = cache.params.window_scatters.max(1);
    // The scattering point, its density and the direction light leaves it
    // in; the product of `b T / pdf(r)` of the steps so far.
    let (mut point, mut rho_point, mut towards) = (at.position, at.density, at.towards);
    let mut throughput = Vec3::ONE;
    let mut sum = Vec3::ZERO;
    for scattering in 1..=scatters {
        if budget <= 0.0 {
            break;
        }
        if scattering > 1 {
            // Russian roulette on this further scattering, kept with the
            // share of a window still left in the budget: its source is
            // drawn within that budget and weighs it (`1/pdf(r)` is the
            // budget over the rate), so its expected share shrinks with
            // it, and the weight `1/keep` undoes that. The later
            // scatterings of thin media are a few percent of `L₁` for as
            // much work as the first.
            let keep = (budget / cache.s_star).min(1.0);
            if keep < 1.0 {
                if rng.next_f32() >= keep {
                    break;
                }
                throughput /= keep;
            }
        }
        // With phase walks each scattering's multiply scattered source is
        // theirs, read along the direction light leaves the scattering
        // point in (below); the direction drawn here then serves `S₁` and
        // the further scatterings only. The harmonics, read in a direction
        // drawn from a sharp forward peak, ring: a thin smoke with `g` 0.9
        // read its second scattering's share five times too bright
        // (validation §3.16).
        let phase_view = cache.has_phase_view();
        if phase_view {
            sum += throughput * phase_view_l1(vol, cache, (point, rho_point, towards), budget, rng);
        }
        let travel = phase::sample_hg(cache.g, towards, rng.next_f32(), rng.next_f32());
        let back = -travel;
        let Some((r, inv_pdf, used)) = source_distance(vol, cache, (point, back), budget, rng)
        else {
            break;
        };
        let xp = point + back * r;
        let rho = vol.density.density(xp);
        let mut j = if phase_view {
            Vec3::ZERO
        } else {
            cache.reconstruct_multi(xp, travel, rho, Part::All)
        };
        if rho > 0.0 {
            j += cache.scatter
                * rho
                * single_scatter_source_with(vol, lights, xp, travel, GATHER_TRANSMITTANCE, rng);
        }
        let more = scattering < scatters && rho > 0.0;
        if j == Vec3::ZERO && !more {
            break;
        }
        throughput *= cache.scatter
            * rho_point
            * GATHER_TRANSMITTANCE.estimate(vol, point, back, r, rng)
            * inv_pdf;
        sum += throughput * j;
        if !more || throughput == Vec3::ZERO {
            break;
        }
        budget -= used;
        (point, rho_point, towards) = (xp, rho, travel);
    }
    sum
}

/// The distance `r` from `from` along `back` to `L₁`'s source within
/// `budget` of the clock, `1/pdf(r)` and the clock it uses: for the
/// geometric clock uniform up to where the budget or the box ends; for the
/// optical-depth clock where a clock drawn uniformly in `[0, budget]` is
/// reached, `pdf = rate / budget`, so that the points follow the
/// extinction the integrand carries (`J ∝ ρ`) and the march stops at the
/// point instead of the budget's end. `None`: the line misses the box, or
/// the clock is past its exit — no source.
fn source_distance<D: DensityField>(
    vol: &Volume<D>,
    cache: &InternalLights,
    (from, back): (Vec3, Vec3),
    budget: f32,
    rng: &mut Rng,
) -> Option<(f32, f32, f32)> {
    let (_, exit) = vol.clip(from, back)?;
    match cache.params.clock {
        Clock::Geometric => {
            let r_max = budget.min(exit);
            let r = rng.next_f32() * r_max;
            (r_max > 0.0).then_some((r, r_max, r))
        }
        Clock::OpticalDepth => {
            let c = rng.next_f32() * budget;
            let ray = ClockRay {
                clock: Clock::OpticalDepth,
                s_star: cache.s_star,
                origin: from,
                dir: back,
                t_exit: exit,
            };
            match march_clock_rate(vol, &ray, 0.0, exit, c) {
                (ClockMarch::Reached(r), rate) if rate > 0.0 => {
                    let inv_pdf = budget / rate;
                    (inv_pdf > 0.0).then_some((r, inv_pdf, c))
                }
                _ => None,
            }
        }
    }
}

/// One scattering of `L₁` at `y` (density `rho_y`, light leaving along
/// `towards`: the eye for the first, the last step's direction for the
/// further ones) of the multiply scattered source, read from the lights'
/// phase walks ([`super::sources::phase_walks`]): `b(y) ∫ dr T(y, x')
/// J̃(x')` over `x' = y − r n` along `n` = `towards` within `budget`, one
/// sample of `r` as [`field_l1_at`] draws it, with `J̃` the source one
/// more scattering sends towards the eye
/// ([`InternalLights::reconstruct_phase_view`]). The exact integral
/// draws `n'` from the phase function and reads `J(y − r n', n')`; the
/// phase walks turn `n'` at the lights instead, so the point is taken on
/// the line: the two differ by `r` times the angle between `n'` and `n`,
/// at most the window (`s*` mean free paths) across a peak of a few
/// tens of degrees, where the kernel averages over `h` (validation
/// §3.15). A further scattering also takes its own direction for the
/// eye's, within the phase function's peak of it (§3.16).
fn phase_view_l1<D: DensityField>(
    vol: &Volume<D>,
    cache: &InternalLights,
    (y, rho_y, towards): (Vec3, f32, Vec3),
    budget: f32,
    rng: &mut Rng,
) -> Vec3 {
    let back = -towards;
    let Some((r, inv_pdf, _)) = source_distance(vol, cache, (y, back), budget, rng) else {
        return Vec3::ZERO;
    };
    let xp = y + back * r;
    let j = cache.reconstruct_phase_view(xp, vol.density.density(xp));
    if j == Vec3::ZERO {
        return Vec3::ZERO;
    }
    cache.scatter * rho_y * GATHER_TRANSMITTANCE.estimate(vol, y, back, r, rng) * inv_pdf * j
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::internal::sources::{InternalLight, InternalParams, LightSources};
    use crate::physics::sh::sh_count;
    use crate::physics::testing::*;

    /// One isotropic internal light in a homogeneous cube gathers, on
    /// average, to the quadrature of [method §6](crate::doc::method)'s `L₀` (its kernel
    /// reconstruction: `J` within `h` of the light, its collided part times
    /// the chance of a collision before the far face) plus `L₁`, for both
    /// clocks (which agree here: with ρ = 1, τ = σ_t ℓ).
    #[test]
    fn one_isotropic_light_matches_quadrature() {
        let sigma = 0.6f32;
        let albedo = 0.8f32;
        let g = 0.4f32;
        let vol = cube(sigma, albedo, g);
        let xi = Vec3::new(0.2, -0.1, 0.3);
        let v = 0.05f32;
        let j0 = Vec3::new(1.0, 0.5, 0.25);
        let h = 0.3f32;
        let s_geo = 1.6f32;
        let eye = Vec3::new(-3.0, 0.05, 0.1);
        let dir = Vec3::X;

        // Quadrature (f64) over t ∈ [0, s*] from the entry point x.
        let x = Vec3::new(-1.0, 0.05, 0.1);
        let steps = 400_000;
        let dt = s_geo as f64 / steps as f64;
        let (mut l0, mut l1) = (0.0f64, 0.0f64);
        for s in 0..steps {
            let t = (s as f64 + 0.5) * dt;
            let y = x + dir * t as f32;
            let tr = (-(sigma as f64) * t).exp();
            let r = (y - xi).length() as f64;
            if r < h as f64 {
                // The collided part is per unit chance of a collision
                // along the ray's rest (2 − t to the cube's far face).
                l0 += tr * -(-(sigma as f64) * (2.0 - t)).exp_m1() * dt;
            }
            if t + r <= s_geo as f64 {
                let n_light = (y - xi) / r as f32;
                let p = phase::hg(g, n_light.dot(-dir)) as f64;
                let h1 = (h * crate::physics::internal::sources::L1_SOFTENING) as f64;
                l1 += tr * (albedo * sigma) as f64 * p * (-(sigma as f64) * r).exp() * v as f64
                    / (r * r + h1 * h1)
                    * dt;
            }
        }
        let expect = (l0 + l1) as f32 * j0;

        for (clock, s_star) in [
            (Clock::Geometric, s_geo),
            (Clock::OpticalDepth, sigma * s_geo),
        ] {
            let params = sh1_params(clock, s_star, 1, h, L1Form::Points);
            let count = sh_count(1);
            let mut multi = vec![Vec3::ZERO; count];
            multi[0] = j0 * (2.0 * std::f32::consts::PI.sqrt());
            let cache = InternalLights::assemble(
                &vol,
                &Lights::default(),
                &params,
                LightSources {
                    lights: vec![InternalLight {
                        position: xi,
                        density: 1.0,
                        weight: v,
                    }],
                    f_coeffs: vec![Vec3::ZERO; count],
                    multi_coeffs: multi.clone(),
                    scattered_coeffs: multi,
                    arrival: Vec::new(),
                    term_energy: vec![Vec3::ZERO; 2],
                    view: Vec::new(),
                    phase_view: Vec::new(),
                    kernel_radius: None,
                },
                8.0,
            );
            let n = 400_000u32;
            let (mut sum, mut sum2) = (Vec3::ZERO.as_dvec3(), Vec3::ZERO.as_dvec3());
            for i in 0..n {
                let mut rng = Rng::for_sample(17, i, 0);
                let s = gather(&vol, &Lights::default(), &cache, eye, dir, 1, &mut rng);
                assert_eq!(s.single, Vec3::ZERO);
                let v = s.total().as_dvec3();
                sum += v;
                sum2 += v * v;
            }
            let mean = sum / n as f64;
            let var = (sum2 / n as f64 - mean * mean).max(glam::DVec3::ZERO) / n as f64;
            let se = glam::DVec3::new(var.x.sqrt(), var.y.sqrt(), var.z.sqrt());
            eprintln!("{clock:?}: gather {mean:?} ± {se:?}, quadrature {expect:?}");
            for c in 0..3 {
                let e = expect[c] as f64;
                assert!(
                    (mean[c] - e).abs() <= 4.0 * se[c] + 1e-4 * e,
                    "{clock:?} channel {c}: {} ± {} vs {e}",
                    mean[c],
                    se[c]
                );
                assert!(se[c] < 0.01 * e, "too noisy to tell: {} vs {e}", se[c]);
            }
        }
    }

    /// The field form of `L₁` against its closed form: with the camera
    /// inside a homogeneous medium whose reconstructed `J` is the same
    /// isotropic `J₀` everywhere (a lattice of lights, no external lights;
    /// the collided part times the chance of a collision before the face
    /// `D` ahead, `1 − e^{−σ(D − t)}`),
    /// `L₀ = J₀ ((1 − e^{−σ s})/σ − s e^{−σ D})` and
    /// `L₁ = b J₀ ∫₀^s e^{−σt} (1 − e^{−σ(s−t)})/σ dt
    ///     = (b J₀/σ) ((1 − e^{−σ s})/σ − s e^{−σ s})`,
    /// for both clocks (`s` the window as a distance).
    #[test]
    fn field_l1_matches_closed_form() {
        let sigma = 0.6f32;
        let albedo = 0.8f32;
        let vol = cube(sigma, albedo, 0.5);
        let j0 = Vec3::new(1.0, 0.5, 0.25);
        let s_geo = 0.3f32;
        let lights = lattice_lights();
        let (sd, b) = (s_geo as f64, (albedo * sigma) as f64);
        let e = (-(sigma as f64) * sd).exp();
        // The camera at y = −0.02 looks along +y: the face is 1.02 ahead.
        let far = (-(sigma as f64) * 1.02).exp();
        let l0 = j0.as_dvec3() * ((1.0 - e) / sigma as f64 - sd * far);
        let l1 = j0.as_dvec3() * (b / sigma as f64 * ((1.0 - e) / sigma as f64 - sd * e));
        for clock in [Clock::Geometric, Clock::OpticalDepth] {
            let s_star = match clock {
                Clock::Geometric => s_geo,
                Clock::OpticalDepth => s_geo * sigma,
            };
            let params = InternalParams {
                lights: lights.len(),
                ..sh1_params(clock, s_star, 1, 0.25, L1Form::Field)
            };
            let cache = isotropic_cache(&vol, &params, &lights, j0);
            let n = 200_000u32;
            let (mut s0, mut s1, mut q1) =
                (glam::DVec3::ZERO, glam::DVec3::ZERO, glam::DVec3::ZERO);
            for i in 0..n {
                let mut rng = Rng::for_sample(23, i, 0);
                let eye = Vec3::new(0.01, -0.02, 0.03);
                let g = gather(&vol, &Lights::default(), &cache, eye, Vec3::Y, 2, &mut rng);
                assert_eq!(g.single, Vec3::ZERO);
                s0 += g.reconstructed.as_dvec3();
                let v = g.internal.as_dvec3();
                s1 += v;
                q1 += v * v;
            }
            let m0 = s0 / n as f64;
            let m1 = s1 / n as f64;
            let se1 = ((q1 / n as f64 - m1 * m1) / n as f64).max(glam::DVec3::ZERO);
            let se1 = glam::DVec3::new(se1.x.sqrt(), se1.y.sqrt(), se1.z.sqrt());
            eprintln!("{clock:?}: L0 {m0:?} vs {l0:?}; L1 {m1:?} ± {se1:?} vs {l1:?}");
            for c in 0..3 {
                assert!(
                    (m0[c] / l0[c] - 1.0).abs() < 2e-3,
                    "{clock:?} L0 channel {c}"
                );
                assert!(
                    (m1[c] - l1[c]).abs() <= 4.0 * se1[c],
                    "{clock:?} L1 channel {c}"
                );
                assert!(
                    se1[c] < 0.005 * l1[c],
                    "too noisy to tell: {} vs {}",
                    se1[c],
                    l1[c]
                );
            }
        }
    }

    /// The scatterings inside the window, against the transport of a
    /// uniform isotropic source: with `J₀` everywhere in a homogeneous
    /// medium (albedo `a`, any phase function) the light that has scattered
    /// `m` times within a path length `s` carries `e^{−σs} (aσs)^m / m!`, so
    /// with `m = 1 ..= M` scatterings followed the field `L₁` must be
    /// `J₀ Σ_m ∫₀^{s*} e^{−σs} (aσs)^m / m! ds` — and with `M` = 1 it must
    /// miss the `m = 2` term, which at `σ s*` = 1.6 is 29 % of the sum of
    /// the first two.
    /// Both clocks; the window and every scattering stay inside the cube.
    #[test]
    fn window_scatters_follow_the_uniform_source() {
        let (sigma, albedo) = (4.0f32, 0.9f32);
        let vol = cube(sigma, albedo, 0.7);
        let j0 = Vec3::new(1.0, 0.5, 0.25);
        let s_geo = 0.4f32;
        let lights = lattice_lights();
        // `∫₀^{s*} e^{−σs} (aσs)^m / m! ds` by Simpson's rule.
        let term = |m: i32| -> f64 {
            let (steps, top) = (4000, (sigma * s_geo) as f64);
            let f =
                |u: f64| (-u).exp() * (albedo as f64 * u).powi(m) / (1..=m).product::<i32>() as f64;
            let h = top / steps as f64;
            let inner: f64 = (1..steps)
                .map(|i| f(i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 })
                .sum();
            (f(0.0) + inner + f(top)) * h / 3.0 / sigma as f64
        };
        for clock in [Clock::Geometric, Clock::OpticalDepth] {
            let s_star = match clock {
                Clock::Geometric => s_geo,
                Clock::OpticalDepth => s_geo * sigma,
            };
            for scatters in 1..=3u32 {
                let params = InternalParams {
                    lights: lights.len(),
                    window_scatters: scatters,
                    ..sh1_params(clock, s_star, 1, 0.25, L1Form::Field)
                };
                let cache = isotropic_cache(&vol, &params, &lights, j0);
                let n = 100_000u32;
                let (mut s1, mut q1) = (glam::DVec3::ZERO, glam::DVec3::ZERO);
                for i in 0..n {
                    let mut rng = Rng::for_sample(29, i, scatters);
                    let eye = Vec3::new(0.01, -0.02, 0.03);
                    let g = gather(&vol, &Lights::default(), &cache, eye, Vec3::Y, 2, &mut rng);
                    let v = g.internal.as_dvec3();
                    s1 += v;
                    q1 += v * v;
                }
                let m1 = s1 / n as f64;
                let var = (q1 / n as f64 - m1 * m1) / n as f64;
                let expected: f64 = (1..=scatters as i32).map(term).sum();
                let missing = term(scatters as i32 + 1);
                for c in 0..3 {
                    let want = j0[c] as f64 * expected;
                    let se = var[c].max(0.0).sqrt();
                    assert!(
                        (m1[c] - want).abs() <= 4.0 * se && se < 0.01 * want,
                        "{clock:?}, {scatters} scatterings, channel {c}: {} ± {se} against {want}",
                        m1[c]
                    );
                    // The next term is far outside the noise: the test tells
                    // `M` from `M + 1` scatterings.
                    assert!(j0[c] as f64 * missing > 8.0 * se || scatters == 3);
                }
            }
        }
    }

    /// The marched single scatter, window and beyond, against its closed
    /// form: in a homogeneous cube lit by a sun travelling along `−y`, a
    /// camera ray along `+x` at height `y₀` sees `S₁ = b P(0) E
    /// e^{−σ(1−y₀)}` everywhere, so `single` must be
    /// `S₁ (1 − e^{−σ t_end})/σ` with `t_end` where the clock reaches
    /// `(N+1) s*` or the ray leaves the cube: the `k = 0` part of `L₀` plus
    /// the unscattered part of its `k ≥ 1` terms, for both clocks, with the
    /// truncation inside the cube (N = 3) and beyond it (N = 10).
    #[test]
    fn single_scatter_reaches_the_series_end() {
        let sigma = 0.6f32;
        let albedo = 0.8f32;
        let g = 0.3f32;
        let vol = cube(sigma, albedo, g);
        let e_sun = Vec3::new(2.0, 1.0, 0.5);
        let lights = one_sun(-Vec3::Y, e_sun);
        let (y0, z0) = (0.2f32, -0.1f32);
        let eye = Vec3::new(-3.0, y0, z0);
        let s1 = (albedo * sigma) as f64
            * phase::hg(g, 0.0) as f64
            * (-(sigma as f64) * (1.0 - y0 as f64)).exp();
        let s_geo = 0.3f32;
        for terms in [3u32, 10] {
            let t_end = (s_geo as f64 * (terms + 1) as f64).min(2.0);
            let expect =
                e_sun.as_dvec3() * (s1 * (1.0 - (-(sigma as f64) * t_end).exp()) / sigma as f64);
            for (clock, s_star) in [
                (Clock::Geometric, s_geo),
                (Clock::OpticalDepth, sigma * s_geo),
            ] {
                let params = sh1_params(clock, s_star, terms, 0.1, L1Form::Points);
                let count = sh_count(1);
                let cache = InternalLights::assemble(
                    &vol,
                    &lights,
                    &params,
                    LightSources {
                        lights: vec![InternalLight {
                            position: Vec3::new(0.5, 0.5, 0.5),
                            density: 1.0,
                            weight: 1.0,
                        }],
                        f_coeffs: vec![Vec3::ZERO; count],
                        multi_coeffs: vec![Vec3::ZERO; count],
                        scattered_coeffs: vec![Vec3::ZERO; count],
                        arrival: vec![Vec3::ONE],
                        term_energy: vec![Vec3::ZERO; terms as usize + 1],
                        view: Vec::new(),
                        phase_view: Vec::new(),
                        kernel_radius: None,
                    },
                    8.0,
                );
                let n = 100_000u32;
                let (mut sum, mut sum2) = (glam::DVec3::ZERO, glam::DVec3::ZERO);
                for i in 0..n {
                    let mut rng = Rng::for_sample(31, i, terms);
                    let v = gather(&vol, &lights, &cache, eye, Vec3::X, 2, &mut rng)
                        .single
                        .as_dvec3();
                    sum += v;
                    sum2 += v * v;
                }
                let mean = sum / n as f64;
                let var = (sum2 / n as f64 - mean * mean).max(glam::DVec3::ZERO) / n as f64;
                eprintln!("N = {terms}, {clock:?}: single {mean:?} vs {expect:?}");
                for c in 0..3 {
                    let se = var[c].sqrt();
                    assert!(
                        (mean[c] - expect[c]).abs() <= 4.0 * se,
                        "N = {terms}, {clock:?}, channel {c}: {} ± {se} vs {}",
                        mean[c],
                        expect[c]
                    );
                    assert!(se < 0.01 * expect[c], "too noisy to tell");
                }
            }
        }
    }
}
