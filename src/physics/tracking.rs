//! Free-flight sampling and transmittance estimation against a majorant
//! grid: the one tracking loop that every estimator calls ([method §2](crate::doc::method),
//! §4), in the manner of pbrt-v4's `SampleT_maj`.
//!
//! - [`sample_tentative`]: exponential steps ([`TentativeSteps`]) against
//!   the local majorant, calling back at each tentative collision.
//! - [`free_flight`]: spectral tracking (Kutz et al. 2017, with the
//!   "max" probabilities of its history-aware variant) for RGB extinction;
//!   reduces to plain delta tracking when the channels agree.
//! - [`transmittance`]: ratio tracking (Novák et al. 2014) with an unbiased
//!   Russian roulette once the estimate is small.
//!
//! ## Bounded on any finite input
//!
//! Each tentative collision advances the ray by at least one `f32` step
//! ([`advance`]): where a mean free path is shorter than the spacing of
//! representable distances (a camera far from a dense medium), the
//! position could otherwise stop moving while null collisions went on
//! forever. With the majorant finite (the renderers clamp media denser
//! than `render::prepared::MAX_DEPTH_PER_VOXEL`), a flight over `[t0, t1]`
//! therefore takes at most about `majorant · (t1 − t0)` steps on average
//! and never more than the number of `f32` values in between. A ray or
//! interval that is not finite is refused: no tentative collision, and
//! [`non_finite_flights`] counts it so that the caller can say so.

use std::sync::atomic::{AtomicU64, Ordering};

use glam::Vec3;

use super::majorant::MajorantGrid;
use super::rng::Rng;
use super::volume::{DensityField, Volume};

/// Samples tentative collisions along `origin + t dir` for `t ∈ [t0, t1]`
/// (inside the grid's box) with rate equal to the local majorant, calling
/// `event(t, majorant, rng)` at each in order; `event` returns `false` to
/// stop. Returns `true` if the ray reached `t1` without being stopped.
#[inline]
pub fn sample_tentative(
    grid: &MajorantGrid,
    origin: Vec3,
    dir: Vec3,
    t0: f32,
    t1: f32,
    rng: &mut Rng,
    event: impl FnMut(f32, f32, &mut Rng) -> bool,
) -> bool {
    sample_tentative_at_rate(grid, origin, dir, (t0, t1), 1.0, rng, event)
}

/// [`sample_tentative`] over the interval `(t0, t1)` with the rate `rate`
/// times the local majorant (`rate ≥ 1`): `event` receives that rate as
/// its majorant.
#[inline]
pub fn sample_tentative_at_rate(
    grid: &MajorantGrid,
    origin: Vec3,
    dir: Vec3,
    (t0, t1): (f32, f32),
    rate: f32,
    rng: &mut Rng,
    mut event: impl FnMut(f32, f32, &mut Rng) -> bool,
) -> bool {
    let finite = origin.is_finite() && dir.is_finite() && t0.is_finite() && t1.is_finite();
    if !(finite && rate.is_finite() && rate > 0.0) {
        NON_FINITE.fetch_add(1, Ordering::Relaxed);
        return true;
    }
    let mut steps = TentativeSteps::new(rng);
    grid.walk(origin, dir, t0, t1, |a, b, m| {
        let m = m * rate;
        let mut t = a;
        while let Some(t_event) = steps.next(t, b, m) {
            if !event(t_event, m, rng) {
                return false;
            }
            steps.redraw(rng);
            t = t_event;
        }
        true
    })
}

/// Flights refused because their ray or interval was not finite.
static NON_FINITE: AtomicU64 = AtomicU64::new(0);

/// How many flights (free flights and transmittance estimates) this
/// process refused because their ray or interval was not finite: zero for
/// every validated scene; the command line reports any as an error in the
/// image.
pub fn non_finite_flights() -> u64 {
    NON_FINITE.load(Ordering::Relaxed)
}

/// The position `t + step` of the next tentative collision, at least one
/// `f32` step beyond `t` (and beyond the smallest normal `f32`), and at
/// most `end`. Where `step` is below the spacing of `f32` values at `t` the
/// exact position cannot be represented anyway; moving on guarantees that
/// the walk ends. The WGSL `tentative_advance` is the same.
#[inline]
pub fn advance(t: f32, step: f32, end: f32) -> f32 {
    (t + step).max(t.max(f32::MIN_POSITIVE).next_up()).min(end)
}

/// The exponential steps between tentative collisions against a majorant
/// that is constant in each cell: the state [`sample_tentative`] keeps
/// while it walks the cells, for a loop that walks them itself (the walks'
/// flights, which count their clock in the same traversal).
#[derive(Clone, Copy, Debug)]
pub struct TentativeSteps {
    /// The majorant optical depth of the current step.
    drawn: f32,
    /// What is left of it.
    left: f32,
}

impl TentativeSteps {
    /// The first step.
    #[inline]
    pub fn new(rng: &mut Rng) -> Self {
        let drawn = -(1.0 - rng.next_f32()).ln();
        Self { drawn, left: drawn }
    }

    /// The next tentative collision in the stretch `[t, b]` of a cell of
    /// majorant `m`, or `None` having used up the stretch.
    #[inline]
    pub fn next(&mut self, t: f32, b: f32, m: f32) -> Option<f32> {
        if m.is_nan() || m <= 0.0 {
            return None;
        }
        let seg = m * (b - t);
        if self.left >= seg {
            self.left -= seg;
            None
        } else {
            Some(advance(t, self.left / m, b))
        }
    }

    /// Draws the step after a tentative collision.
    #[inline]
    pub fn redraw(&mut self, rng: &mut Rng) {
        self.drawn = -(1.0 - rng.next_f32()).ln();
        self.left = self.drawn;
    }

    /// The majorant optical depth of the current step: at a tentative
    /// collision, from the previous one (or the start) to it — an upper
    /// bound of the optical depth there.
    #[inline]
    pub fn depth(&self) -> f32 {
        self.drawn
    }

    /// The majorant optical depth used since the last tentative collision
    /// (or the start).
    #[inline]
    pub fn used(&self) -> f32 {
        self.drawn - self.left
    }
}

/// Spectral tracking from `origin` along `dir` over `[t0, t1]`. Returns the
/// distance of a real collision, or `None` if the flight leaves the
/// interval. `weight` (the path throughput) is updated so that the
/// estimator stays unbiased per channel; it is set to zero if the path can
/// carry no more light.
#[inline]
pub fn free_flight<D: DensityField>(
    vol: &Volume<D>,
    origin: Vec3,
    dir: Vec3,
    t0: f32,
    t1: f32,
    weight: &mut Vec3,
    rng: &mut Rng,
) -> Option<f32> {
    let mut hit = None;
    sample_tentative(
        &vol.majorants,
        origin,
        dir,
        t0,
        t1,
        rng,
        |t, m, rng| match spectral_event(vol, origin + dir * t, m, weight, rng) {
            TentativeEvent::Real => {
                hit = Some(t);
                false
            }
            TentativeEvent::Null => true,
            TentativeEvent::Dead => false,
        },
    );
    hit
}

/// A free flight ([`free_flight_probed`]) and one point of its track,
/// drawn for a track-length reading.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProbedFlight {
    /// The distance of the real collision that ended the flight, if any.
    pub hit: Option<f32>,
    /// The probe: its distance and the flight's weight on arriving there,
    /// or `None` where the flight met no tentative collision.
    pub probe: Option<(f32, Vec3)>,
    /// `Σ σ_g ρ/m̄` over the flight's tentative collisions (the real one
    /// included): the probe's reading times this, with the weight on
    /// arriving, estimates `∫ W σ_g ρ f dt` over the track.
    pub depth: f32,
}

/// [`free_flight`] that also draws one of its tentative collisions (the
/// real one included), each with a chance proportional to `σ_g ρ/m̄` there
/// (`σ_g ρ` the largest channel of the extinction, `m̄` the majorant), from
/// `pick` — a stream apart from the flight's own, so the flight comes out
/// the same. The tentative collisions are a Poisson process of rate `m̄`
/// along the track and a reading taken on arriving at each does not see
/// the choice made there, so `Σ_i W_i (σ_g ρ_i/m̄_i) f(x_i)` over them has
/// the expectation `∫ T σ_g ρ f dt` over the track (per channel, `T` the
/// transmittance); the probe's `W f` times [`ProbedFlight::depth`] is an
/// unbiased estimate of that sum — a track-length estimator with one
/// reading, which unlike a reading at the collision also reads a flight
/// that leaves the medium.
#[inline]
pub fn free_flight_probed<D: DensityField>(
    vol: &Volume<D>,
    origin: Vec3,
    dir: Vec3,
    (t0, t1): (f32, f32),
    weight: &mut Vec3,
    rng: &mut Rng,
    pick: &mut Rng,
) -> ProbedFlight {
    let mut flight = ProbedFlight {
        hit: None,
        probe: None,
        depth: 0.0,
    };
    sample_tentative(&vol.majorants, origin, dir, t0, t1, rng, |t, m, rng| {
        let sigma_t = vol.sigma_t(origin + dir * t);
        let c = sigma_t.max_element() / m;
        if c > 0.0 {
            flight.depth += c;
            if pick.next_f32() * flight.depth < c {
                flight.probe = Some((t, *weight));
            }
        }
        match spectral_event_with(sigma_t, m, weight, rng) {
            TentativeEvent::Real => {
                flight.hit = Some(t);
                false
            }
            TentativeEvent::Null => true,
            TentativeEvent::Dead => false,
        }
    });
    flight
}

/// What spectral tracking made of a tentative collision.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TentativeEvent {
    /// A real collision (the weight was updated).
    Real,
    /// A null collision: the flight goes on (the weight was updated).
    Null,
    /// The path can carry no more light (the weight was set to zero).
    Dead,
}

/// Spectral tracking's choice at a tentative collision at `p` under the
/// majorant `m`: real with probability `p_real / (p_real + p_null)`, the
/// weight updated so that the estimate stays unbiased per channel.
#[inline]
pub fn spectral_event<D: DensityField>(
    vol: &Volume<D>,
    p: Vec3,
    m: f32,
    weight: &mut Vec3,
    rng: &mut Rng,
) -> TentativeEvent {
    spectral_event_with(vol.sigma_t(p), m, weight, rng)
}

/// [`spectral_event`] with the extinction `sigma_t` at the tentative
/// collision already looked up.
#[inline]
pub fn spectral_event_with(
    sigma_t: Vec3,
    m: f32,
    weight: &mut Vec3,
    rng: &mut Rng,
) -> TentativeEvent {
    let sigma_n = (Vec3::splat(m) - sigma_t).max(Vec3::ZERO);
    let p_real = (*weight * sigma_t).max_element();
    let p_null = (*weight * sigma_n).max_element();
    let total = p_real + p_null;
    if total <= 0.0 {
        *weight = Vec3::ZERO;
        return TentativeEvent::Dead;
    }
    if rng.next_f32() * total < p_real {
        *weight *= sigma_t * (total / (m * p_real));
        TentativeEvent::Real
    } else {
        *weight *= sigma_n * (total / (m * p_null));
        TentativeEvent::Null
    }
}

/// Ratio-tracking estimate of the transmittance `T` from `origin` along
/// `dir` up to distance `t_max` (clipped to the medium), per channel.
#[inline]
pub fn transmittance<D: DensityField>(
    vol: &Volume<D>,
    origin: Vec3,
    dir: Vec3,
    t_max: f32,
    rng: &mut Rng,
) -> Vec3 {
    transmittance_at_rate(vol, origin, dir, t_max, 1.0, rng)
}

/// [`transmittance`] with tentative collisions at `rate` times the
/// majorant (`rate ≥ 1`). Still unbiased; each tentative collision then
/// keeps at least `1 − 1/rate` of the estimate, so the estimate no longer
/// drops to zero at one tentative collision where the majorant is tight.
/// In a homogeneous stretch of optical depth `τ` under a tight majorant the
/// relative variance of ratio tracking is `e^{τ/rate} − 1`, for `rate`
/// times the density lookups: `e^τ − 1` at rate 1 is the variance of a
/// yes-or-no estimate, which is what ratio tracking becomes where the
/// majorant grid is tight.
#[inline]
pub fn transmittance_at_rate<D: DensityField>(
    vol: &Volume<D>,
    origin: Vec3,
    dir: Vec3,
    t_max: f32,
    rate: f32,
    rng: &mut Rng,
) -> Vec3 {
    let Some((t0, t1)) = in_medium(vol, origin, dir, t_max) else {
        return Vec3::ONE;
    };
    let mut tr = Vec3::ONE;
    let rate = rate.max(1.0);
    sample_tentative_at_rate(
        &vol.majorants,
        origin,
        dir,
        (t0, t1),
        rate,
        rng,
        |t, m, rng| {
            let sigma_t = vol.sigma_t(origin + dir * t);
            tr *= (Vec3::ONE - sigma_t / m).max(Vec3::ZERO);
            roulette_small(&mut tr, rng)
        },
    );
    tr
}

/// The stretch `[t0, t1]` of the ray `origin + t dir`, `t ≤ t_max`, inside
/// the medium's box, if it is not empty: what every transmittance
/// estimate integrates over.
#[inline]
fn in_medium<D: DensityField>(
    vol: &Volume<D>,
    origin: Vec3,
    dir: Vec3,
    t_max: f32,
) -> Option<(f32, f32)> {
    let (t0, t1) = vol.clip(origin, dir)?;
    let t1 = t1.min(t_max);
    (t1 > t0).then_some((t0, t1))
}

/// Russian roulette on a running transmittance estimate `tr`: once its
/// largest channel (in magnitude) is below 0.1 it survives with
/// probability 1/2 and is doubled. Returns `false`, with `tr` zero, where
/// it was dropped or carries nothing (or is not a number).
#[inline]
fn roulette_small(tr: &mut Vec3, rng: &mut Rng) -> bool {
    let largest = tr.abs().max_element();
    if largest.is_nan() || largest <= 0.0 {
        *tr = Vec3::ZERO;
        return false;
    }
    if largest < 0.1 {
        if rng.next_f32() < 0.5 {
            *tr = Vec3::ZERO;
            return false;
        }
        *tr *= 2.0;
    }
    true
}

/// Majorant optical depth of one segment of [`transmittance_marched`]
/// (a ray that holds less is one segment of its own depth): each
/// segment's estimate is independent of the others', and the running
/// product is rouletted between segments once it is small, so that a
/// march into a thick medium stops about where ratio tracking would.
pub const MARCH_SEGMENT_DEPTH: f32 = 4.0;

/// Majorant optical depth between the points of one march of
/// [`transmittance_marched`] (at most: a segment is split evenly; it
/// divides [`MARCH_SEGMENT_DEPTH`]).
pub const MARCH_STRIDE_DEPTH: f32 = 0.5;

/// Longest series [`transmittance_marched`] sums in one segment: a bound
/// on the work of a segment, never reached in practice (the terms after
/// the first are rouletted by their size, and the `k`-th is divided by
/// `k!`).
pub const MARCH_MAX_TERMS: u32 = 32;

/// One jittered march of the optical depth `∫ σ_t dt` over `[ta, tb]`
/// (per channel): points `stride` apart in majorant optical depth from a
/// uniform random offset, at most `depth` of it (the stretch's majorant
/// optical depth). Unbiased: each point stands for the stride it falls
/// in.
#[inline]
fn march_depth<D: DensityField>(
    vol: &Volume<D>,
    origin: Vec3,
    dir: Vec3,
    (ta, tb): (f32, f32),
    (stride, depth): (f32, f32),
    rng: &mut Rng,
) -> Vec3 {
    let mut x = Vec3::ZERO;
    let mut next = rng.next_f32() * stride;
    let mut s = 0.0f32;
    vol.majorants.walk(origin, dir, ta, tb, |a, b, m| {
        if m <= 0.0 {
            return true;
        }
        let sb = s + m * (b - a);
        let lim = sb.min(depth);
        while next < lim {
            x += vol.sigma_t(origin + dir * (a + (next - s) / m)) / m;
            next += stride;
        }
        s = sb;
        next < depth
    });
    x * stride
}

/// The transmittance of one segment `span` from two independent marches
/// of its optical depth, `x0` and `x1`: `e^{−τ} = e^{−x0} e^{x0 − τ}`, the
/// second factor by its power series `Σ_k Π_{j≤k} (x0 − x_j) / k!` with
/// each factor from a march of its own (so that, given `x0`, its
/// expectation is `x0 − τ`). The first term is always taken; each later
/// one with probability `min(1, 4 |term|)` (and divided by it). Unbiased
/// given `x0`, hence unbiased.
#[inline]
fn close_segment<D: DensityField>(
    vol: &Volume<D>,
    origin: Vec3,
    dir: Vec3,
    span: (f32, f32),
    march: (f32, f32),
    (x0, x1): (Vec3, Vec3),
    rng: &mut Rng,
) -> Vec3 {
    let mut term = x0 - x1;
    let mut sum = Vec3::ONE + term;
    for k in 2..MARCH_MAX_TERMS {
        let p = (term.abs().max_element() * 4.0).min(1.0);
        if p <= 0.0 || rng.next_f32() >= p {
            break;
        }
        let xk = march_depth(vol, origin, dir, span, march, rng);
        term *= (x0 - xk) / (k as f32 * p);
        sum += term;
    }
    (-x0).exp() * sum
}

/// An unbiased ray-marched estimate of the transmittance from `origin`
/// along `dir` up to distance `t_max` (clipped to the medium), per
/// channel, in the manner of Kettunen et al. 2021 ("An unbiased
/// ray-marching transmittance estimator"; [method §6](crate::doc::method)).
///
/// The ray is cut into segments of majorant optical depth
/// [`MARCH_SEGMENT_DEPTH`] (one segment, if it holds less). In each, two jittered marches estimate its
/// optical depth (points [`MARCH_STRIDE_DEPTH`] of majorant depth apart:
/// about two density lookups per majorant mean free path each), and a
/// rouletted power series about the first turns them into an unbiased
/// transmittance (the series of [method §6.1](crate::doc::method)). Where the density varies little
/// over a stride, the marches agree and the estimate is nearly exact,
/// where ratio tracking's relative variance grows with the optical depth
/// (`e^{τ/rate} − 1`). The estimate can fall below zero or above one;
/// its expectation is the transmittance. The running product is
/// rouletted as ratio tracking's is once below 0.1.
///
/// Bounded as tracking is: a pass over the majorant grid's cells (and a
/// first one over at most a segment's worth), the marches' points a
/// fixed majorant depth apart, counted from each segment's start (so
/// they never stall on the spacing of `f32` values).
pub fn transmittance_marched<D: DensityField>(
    vol: &Volume<D>,
    origin: Vec3,
    dir: Vec3,
    t_max: f32,
    rng: &mut Rng,
) -> Vec3 {
    if !(origin.is_finite() && dir.is_finite() && !t_max.is_nan()) {
        NON_FINITE.fetch_add(1, Ordering::Relaxed);
        return Vec3::ONE;
    }
    let Some((t0, t1)) = in_medium(vol, origin, dir, t_max) else {
        return Vec3::ONE;
    };
    // A ray of at most one segment's majorant depth is marched as one
    // segment, its strides split evenly; a longer one in segments of
    // exactly `MARCH_SEGMENT_DEPTH`, the last cut short where the ray
    // ends (each march then drops the points past the end: still
    // unbiased). The first walk stops as soon as the ray is known to be
    // long, so that a shadow ray into a thick cloud, which the roulette
    // ends early, is not walked to its end twice.
    let mut total = 0.0f32;
    let short = vol.majorants.walk(origin, dir, t0, t1, |a, b, m| {
        total += m * (b - a);
        total <= MARCH_SEGMENT_DEPTH
    });
    if !total.is_finite() {
        NON_FINITE.fetch_add(1, Ordering::Relaxed);
        return Vec3::ONE;
    }
    let (depth, stride) = if short {
        if total <= 0.0 {
            return Vec3::ONE;
        }
        (total, total / (total / MARCH_STRIDE_DEPTH).ceil().max(1.0))
    } else {
        let depth = MARCH_SEGMENT_DEPTH;
        (depth, depth / (depth / MARCH_STRIDE_DEPTH).ceil().max(1.0))
    };

    let mut tr = Vec3::ONE;
    // The segment's start, and the two marches' sums and next points
    // (majorant depth from the segment's start).
    let mut seg_t = t0;
    let mut x = [Vec3::ZERO; 2];
    let mut next = [rng.next_f32() * stride, rng.next_f32() * stride];
    // Majorant depth from the segment's start to the cell's entry.
    let mut s = 0.0f32;
    let alive = vol.majorants.walk(origin, dir, t0, t1, |a, b, m| {
        if m <= 0.0 {
            return true;
        }
        let mut sb = s + m * (b - a);
        loop {
            let lim = sb.min(depth);
            for (xj, nj) in x.iter_mut().zip(next.iter_mut()) {
                while *nj < lim {
                    *xj += vol.sigma_t(origin + dir * (a + (*nj - s) / m)) / m;
                    *nj += stride;
                }
            }
            if short || sb < depth {
                break;
            }
            // Always past `seg_t`: a segment holds `depth` (4) of majorant
            // depth, and a prepared medium at most `MAX_DEPTH_PER_VOXEL`
            // (100) over its feature length (a voxel, or a 32nd of the box
            // for the analytic shapes), so the segment is at least 4 % of
            // that long, while `t` is at most the box's diagonal (the
            // gather marches from where its rays enter the box), whose
            // rounding step is some 10⁻⁷ of it: only a grid of millions of
            // voxels a side could stall here.
            let t_end = (a + (depth - s) / m).clamp(seg_t, b);
            tr *= close_segment(
                vol,
                origin,
                dir,
                (seg_t, t_end),
                (stride, depth),
                (x[0] * stride, x[1] * stride),
                rng,
            );
            if !roulette_small(&mut tr, rng) {
                return false;
            }
            seg_t = t_end;
            s -= depth;
            sb -= depth;
            x = [Vec3::ZERO; 2];
            next = [rng.next_f32() * stride, rng.next_f32() * stride];
        }
        s = sb;
        true
    });
    if !alive {
        return tr;
    }
    tr * close_segment(
        vol,
        origin,
        dir,
        (seg_t, t1),
        (stride, depth),
        (x[0] * stride, x[1] * stride),
        rng,
    )
}

/// How a transmittance is estimated: the choice that the estimators pass
/// down to every shadow ray and view segment they trace.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Transmittance {
    /// Ratio tracking with tentative collisions at this many times the
    /// majorant ([`transmittance_at_rate`]; 1 is plain ratio tracking).
    Ratio(f32),
    /// The unbiased ray march ([`transmittance_marched`]).
    Marched,
}

impl Transmittance {
    /// Plain ratio tracking: what the reference path tracer and the walks
    /// use.
    pub const RATIO: Self = Self::Ratio(1.0);

    /// How the WGSL names this choice to `transmittance_by`: the rate for
    /// ratio tracking, `0` (`TRANSMITTANCE_MARCHED`) for the march.
    pub const fn wgsl_rate(self) -> f32 {
        match self {
            // Ratio tracking below the majorant's rate is ratio tracking
            // at it (`transmittance_at_rate`), never the march's tag.
            Self::Ratio(rate) if rate >= 1.0 => rate,
            Self::Ratio(_) => 1.0,
            Self::Marched => 0.0,
        }
    }

    /// One estimate of the transmittance from `origin` along `dir` up to
    /// distance `t_max` (clipped to the medium), per channel.
    #[inline]
    pub fn estimate<D: DensityField>(
        self,
        vol: &Volume<D>,
        origin: Vec3,
        dir: Vec3,
        t_max: f32,
        rng: &mut Rng,
    ) -> Vec3 {
        match self {
            Self::Ratio(rate) => transmittance_at_rate(vol, origin, dir, t_max, rate, rng),
            Self::Marched => transmittance_marched(vol, origin, dir, t_max, rng),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::testing::Ball;
    use crate::physics::volume::Optics;

    fn ball(sigma_t: Vec3) -> Volume<Ball> {
        Volume::new(
            Ball { radius: 1.0 },
            Optics {
                sigma_t,
                albedo: Vec3::ONE,
                g: 0.0,
            },
            8,
        )
    }

    /// [`free_flight_probed`]'s probe, its weight on arriving times
    /// `Σ σ_g ρ/m̄` times a function `f` read there, estimates
    /// `∫ T σ_g ρ f dt` over the flight's track per channel — on a chord of
    /// a chromatic sphere whose edge cells hold null collisions where the
    /// density is zero, with `f` growing along the chord; the flight itself
    /// (its collision and weight) is `free_flight`'s on the same stream.
    #[test]
    fn probed_flights_read_the_track_length_integral() {
        let sigma = Vec3::new(0.5, 1.0, 2.0);
        let vol = ball(sigma);
        let (origin, dir) = (Vec3::new(-2.0, 0.3, 0.1), Vec3::X);
        let span = vol.clip(origin, dir).unwrap();
        let half = (1.0f64 - 0.09 - 0.01).sqrt();
        let t_in = 2.0 - half;
        let f = |t: f32| 1.0 + 0.5 * t;
        // ∫ σ_g e^{−σ_c (t − t_in)} f(t) dt over the chord, by the midpoint
        // rule.
        let steps = 20_000;
        let mut want = [0.0f64; 3];
        for i in 0..steps {
            let t = t_in + (i as f64 + 0.5) / steps as f64 * 2.0 * half;
            for (c, w) in want.iter_mut().enumerate() {
                let tr = (-f64::from(sigma[c]) * (t - t_in)).exp();
                *w += 2.0 * tr * f64::from(f(t as f32)) * 2.0 * half / steps as f64;
            }
        }
        let n = 400_000;
        let (mut rng, mut pick) = (Rng::for_sample(9, 0, 0), Rng::for_sample(9, 1, 0));
        let (mut sum, mut squares) = ([0.0f64; 3], [0.0f64; 3]);
        let mut probed = 0;
        for _ in 0..n {
            let mut twin_rng = rng.clone();
            let mut twin_w = Vec3::ONE;
            let twin = free_flight(
                &vol,
                origin,
                dir,
                span.0,
                span.1,
                &mut twin_w,
                &mut twin_rng,
            );
            let mut w = Vec3::ONE;
            let flight = free_flight_probed(&vol, origin, dir, span, &mut w, &mut rng, &mut pick);
            assert_eq!(flight.hit, twin);
            assert_eq!(w, twin_w);
            let mut v = Vec3::ZERO;
            if let Some((t, w_probe)) = flight.probe {
                assert!(t >= span.0 && t <= span.1 && flight.depth > 0.0);
                v = w_probe * flight.depth * f(t);
                probed += 1;
            }
            for c in 0..3 {
                sum[c] += f64::from(v[c]);
                squares[c] += f64::from(v[c]) * f64::from(v[c]);
            }
        }
        for c in 0..3 {
            let mean = sum[c] / n as f64;
            let se = ((squares[c] / n as f64 - mean * mean) / n as f64).sqrt();
            assert!(se < 0.01 * want[c], "ch {c}: se {se} of {}", want[c]);
            assert!(
                (mean - want[c]).abs() < 4.0 * se,
                "ch {c}: {mean} against {} (se {se})",
                want[c]
            );
        }
        // Flights that left the sphere were read too.
        assert!(probed > n * 9 / 10, "{probed} of {n} flights probed");
    }

    /// Ratio tracking through a homogeneous sphere matches `exp(−σ L)`
    /// for chords of several lengths and a chromatic σ.
    #[test]
    fn transmittance_matches_beer_lambert() {
        let sigma = Vec3::new(0.5, 1.5, 3.0);
        let vol = ball(sigma);
        let mut rng = Rng::for_sample(3, 0, 0);
        for offset in [0.0f32, 0.4, 0.8] {
            let origin = Vec3::new(-2.0, offset, 0.0);
            let chord = 2.0 * (1.0 - offset * offset).sqrt();
            let n = 100_000;
            let mut sum = Vec3::ZERO;
            let mut sum2 = Vec3::ZERO;
            for _ in 0..n {
                let t = transmittance(&vol, origin, Vec3::X, f32::INFINITY, &mut rng);
                sum += t;
                sum2 += t * t;
            }
            let mean = sum / n as f32;
            let stderr = ((sum2 / n as f32 - mean * mean) / n as f32)
                .max(Vec3::ZERO)
                .powf(0.5);
            let exact = (-sigma * chord).exp();
            for c in 0..3 {
                let err = (mean[c] - exact[c]).abs();
                assert!(
                    err < 4.0 * stderr[c] + 1e-4,
                    "offset {offset} ch {c}: {} vs {} (stderr {})",
                    mean[c],
                    exact[c],
                    stderr[c]
                );
            }
        }
    }

    /// Ratio tracking at a rate above the majorant stays unbiased and, where
    /// the majorant is tight (the homogeneous ball), its variance falls as
    /// `e^{τ/rate} − 1` instead of `e^τ − 1` (τ = 2 on the diameter).
    #[test]
    fn transmittance_at_a_higher_rate_is_unbiased_with_less_variance() {
        let vol = ball(Vec3::ONE);
        let origin = Vec3::new(-2.0, 0.0, 0.0);
        let exact = (-2.0f32).exp();
        let n = 100_000;
        let mut rel_var = Vec::new();
        for rate in [1.0f32, 8.0] {
            let mut rng = Rng::for_sample(5, rate as u32, 0);
            let (mut sum, mut sum2) = (0.0f64, 0.0f64);
            for _ in 0..n {
                let t =
                    transmittance_at_rate(&vol, origin, Vec3::X, f32::INFINITY, rate, &mut rng).x;
                sum += t as f64;
                sum2 += (t as f64).powi(2);
            }
            let mean = sum / n as f64;
            let var = sum2 / n as f64 - mean * mean;
            let stderr = (var / n as f64).sqrt();
            assert!(
                (mean - exact as f64).abs() < 4.0 * stderr,
                "rate {rate}: {mean} vs {exact} (stderr {stderr})"
            );
            rel_var.push(var / (exact as f64).powi(2));
        }
        // Expected e² − 1 = 6.39 (Russian roulette adds a little) and
        // e^{1/4} − 1 = 0.28.
        assert!(rel_var[0] > 5.0, "rate 1: relative variance {}", rel_var[0]);
        assert!(rel_var[1] < 0.4, "rate 8: relative variance {}", rel_var[1]);
    }

    /// The mean of `n` estimates by `f`, its standard error and the
    /// estimates' relative variance.
    fn moments(n: u32, seed: u64, f: impl FnMut(&mut Rng) -> Vec3) -> (Vec3, Vec3, Vec3) {
        let (mean, var_of_mean) = crate::physics::testing::mean_and_its_variance(n, seed, 0, f);
        let rel_var = var_of_mean * n as f32 / (mean * mean);
        (mean, var_of_mean.powf(0.5), rel_var)
    }

    /// The ray march through a homogeneous sphere matches `exp(−σ L)` per
    /// channel on chords of several lengths, with a small fraction of
    /// ratio tracking's variance at 8 times the majorant (which is
    /// `e^{τ/8} − 1`: 1.1 on the blue channel's diameter, τ = 6). Exact
    /// through the centre, where the majorant is tight along the whole
    /// chord; off it the chord's ends share majorant cells with empty
    /// space (measured 0.14–0.18 of ratio tracking's).
    #[test]
    fn marched_transmittance_matches_beer_lambert_with_little_variance() {
        let sigma = Vec3::new(0.5, 1.5, 3.0);
        let vol = ball(sigma);
        for (i, offset) in [0.0f32, 0.4, 0.8].into_iter().enumerate() {
            let origin = Vec3::new(-2.0, offset, 0.0);
            let chord = 2.0 * (1.0 - offset * offset).sqrt();
            let exact = (-sigma * chord).exp();
            let (mean, stderr, rel_var) = moments(50_000, 11 + i as u64, |rng| {
                transmittance_marched(&vol, origin, Vec3::X, f32::INFINITY, rng)
            });
            let (_, _, ratio_rel_var) = moments(50_000, 21 + i as u64, |rng| {
                transmittance_at_rate(&vol, origin, Vec3::X, f32::INFINITY, 8.0, rng)
            });
            for c in 0..3 {
                assert!(
                    (mean[c] - exact[c]).abs() < 4.0 * stderr[c] + 1e-5,
                    "offset {offset} ch {c}: {} vs {} (stderr {})",
                    mean[c],
                    exact[c],
                    stderr[c]
                );
                assert!(
                    rel_var[c] < 0.25 * ratio_rel_var[c],
                    "offset {offset} ch {c}: relative variance {} against ratio tracking's {}",
                    rel_var[c],
                    ratio_rel_var[c]
                );
            }
        }
    }

    /// Through a heterogeneous medium over several segments (majorant
    /// depth 7.15: two segments, Russian roulette between them), up to
    /// `t_max`, the march is unbiased against the analytic optical depth of
    /// `base + amp sin x sin y`, with under 1 % of the variance of ratio
    /// tracking at 8 times the majorant (measured: 1.2e-4 against 6.2,
    /// relative; ratio tracking's includes its Russian roulette).
    #[test]
    fn marched_transmittance_is_unbiased_over_segments_of_a_varying_medium() {
        let (base, amp) = (0.3f32, 0.25f32);
        let vol = crate::physics::testing::boxed(base, amp, 1.0, 10.0, 16);
        let y = 0.7f32;
        let origin = Vec3::new(-10.0, y, 0.2);
        let length = 13.0f32;
        let tau = base as f64 * length as f64
            + amp as f64 * (y as f64).sin() * ((-10.0f64).cos() - 3.0f64.cos());
        let exact = (-tau).exp() as f32;
        let (mean, stderr, rel_var) = moments(100_000, 5, |rng| {
            transmittance_marched(&vol, origin, Vec3::X, length, rng)
        });
        let (_, _, ratio_rel_var) = moments(100_000, 6, |rng| {
            transmittance_at_rate(&vol, origin, Vec3::X, length, 8.0, rng)
        });
        assert!(
            (mean.x - exact).abs() < 4.0 * stderr.x,
            "{} vs {exact} (stderr {})",
            mean.x,
            stderr.x
        );
        assert!(
            rel_var.x < 0.01 * ratio_rel_var.x,
            "relative variance {} against ratio tracking's {}",
            rel_var.x,
            ratio_rel_var.x
        );
    }

    /// The march refuses a ray that is not finite (and counts it), and
    /// through empty space under a majorant of 10⁶ seen from 10⁷ away —
    /// two million majorant mean free paths, where the segments are
    /// shorter than the spacing of `f32` distances — it ends, with all the
    /// light.
    #[test]
    fn marched_transmittance_ends_and_refuses_non_finite_rays() {
        let before = non_finite_flights();
        let vol = ball(Vec3::ONE);
        let mut rng = Rng::for_sample(0, 0, 0);
        let t = transmittance_marched(&vol, Vec3::new(f32::NAN, 0.0, 0.0), Vec3::X, 1.0, &mut rng);
        assert_eq!(t, Vec3::ONE);
        assert!(non_finite_flights() > before);
        let tr = within_10_s(|| {
            let vol = Volume::new(
                EmptyUnderDenseMajorant,
                Optics {
                    sigma_t: Vec3::ONE,
                    albedo: Vec3::ONE,
                    g: 0.0,
                },
                4,
            );
            let mut rng = Rng::for_sample(1, 2, 3);
            transmittance_marched(
                &vol,
                Vec3::new(-1e7, 0.1, 0.2),
                Vec3::X,
                f32::INFINITY,
                &mut rng,
            )
        });
        assert_eq!(tr, Vec3::ONE);
    }

    /// Empty space under a majorant of 10⁶: the null collisions that a
    /// far ray's `f32` parameter cannot separate.
    struct EmptyUnderDenseMajorant;

    impl DensityField for EmptyUnderDenseMajorant {
        fn density(&self, _: Vec3) -> f32 {
            0.0
        }
        fn bounds(&self) -> (Vec3, Vec3) {
            (Vec3::splat(-1.0), Vec3::splat(1.0))
        }
        fn max_in_box(&self, _: Vec3, _: Vec3) -> f32 {
            1e6
        }
    }

    /// Runs `f` on a thread; fails if it takes more than 10 s.
    fn within_10_s<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let _ = tx.send(f());
        });
        rx.recv_timeout(std::time::Duration::from_secs(10))
            .expect("the flight never ended")
    }

    /// From 10⁷ away a mean free path of 10⁻⁶ is below the spacing of `f32`
    /// values (1 at 10⁷): `t + step` rounded to `t` and the null collisions
    /// went on forever. Each now moves the ray on by at least one step.
    #[test]
    fn flights_end_where_f32_cannot_resolve_a_mean_free_path() {
        let (tr, hit) = within_10_s(|| {
            let vol = Volume::new(
                EmptyUnderDenseMajorant,
                Optics {
                    sigma_t: Vec3::ONE,
                    albedo: Vec3::ONE,
                    g: 0.0,
                },
                4,
            );
            let origin = Vec3::new(-1e7, 0.1, 0.2);
            let mut rng = Rng::for_sample(1, 2, 3);
            let tr = transmittance(&vol, origin, Vec3::X, f32::INFINITY, &mut rng);
            let (t0, t1) = vol.clip(origin, Vec3::X).unwrap();
            let mut w = Vec3::ONE;
            let hit = free_flight(&vol, origin, Vec3::X, t0, t1, &mut w, &mut rng);
            (tr, hit)
        });
        // Nothing there: all light passes.
        assert_eq!(tr, Vec3::ONE);
        assert_eq!(hit, None);
    }

    /// A ray that is not finite is refused at once (no tentative collision)
    /// and counted, so that the command line can report it.
    #[test]
    fn non_finite_rays_are_refused_and_counted() {
        let before = non_finite_flights();
        let vol = ball(Vec3::ONE);
        let mut rng = Rng::for_sample(0, 0, 0);
        let mut called = false;
        let reached = sample_tentative(
            &vol.majorants,
            Vec3::new(f32::NAN, 0.0, 0.0),
            Vec3::X,
            0.0,
            1.0,
            &mut rng,
            |_, _, _| {
                called = true;
                true
            },
        );
        assert!(reached && !called);
        let reached = sample_tentative(
            &vol.majorants,
            Vec3::ZERO,
            Vec3::X,
            0.0,
            f32::INFINITY,
            &mut rng,
            |_, _, _| true,
        );
        assert!(reached);
        assert!(non_finite_flights() >= before + 2);
    }

    /// `advance` moves on by at least one `f32` step and never past `end`.
    #[test]
    fn advance_always_moves_on() {
        assert_eq!(advance(1e7, 1e-6, 2e7), 1e7f32.next_up());
        assert_eq!(advance(0.0, 0.0, 1.0), f32::MIN_POSITIVE.next_up());
        assert_eq!(advance(1.0, 0.5, 1.25), 1.25);
        assert_eq!(advance(1.0, 0.125, 2.0), 1.125);
    }

    /// The probability that a spectral-tracking flight crosses the sphere,
    /// weighted, equals the transmittance per channel.
    #[test]
    fn free_flight_escape_weight_is_transmittance() {
        let sigma = Vec3::new(0.5, 1.0, 2.0);
        let vol = ball(sigma);
        let mut rng = Rng::for_sample(4, 0, 0);
        let origin = Vec3::new(-2.0, 0.0, 0.0);
        let (t0, t1) = vol.clip(origin, Vec3::X).unwrap();
        let n = 200_000;
        let mut escaped = Vec3::ZERO;
        let mut collided_weight = Vec3::ZERO;
        for _ in 0..n {
            let mut w = Vec3::ONE;
            match free_flight(&vol, origin, Vec3::X, t0, t1, &mut w, &mut rng) {
                None => escaped += w,
                Some(_) => collided_weight += w,
            }
        }
        let exact = (-sigma * 2.0).exp();
        let est = escaped / n as f32;
        let real = collided_weight / n as f32;
        for c in 0..3 {
            assert!(
                (est[c] - exact[c]).abs() < 0.01,
                "ch {c}: {} vs {}",
                est[c],
                exact[c]
            );
            // Collision weight estimates 1 − T (the probability of any
            // interaction), per channel.
            assert!(
                (real[c] - (1.0 - exact[c])).abs() < 0.01,
                "ch {c}: {}",
                real[c]
            );
        }
    }
}
