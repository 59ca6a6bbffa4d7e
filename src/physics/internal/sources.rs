//! The internal lights ([method §5](crate::doc::method)): `M` points placed by density, each
//! with the volume `V_i` it stands for and the path-length series
//! `J_N(x_i, ·)` estimated by `K` time-gated walks (§4) and stored as real
//! spherical harmonics, with `F = G(s*) S₁` (the `k = 1` term) kept apart.
//!
//! # What a light stores
//!
//! `J_N = S₁ + Σ_{k=1}^{N} J_k`. The first term, `S₁(x_i, n)`, is the
//! single-scatter source: sharply peaked for a forward-scattering phase
//! function, and known in closed form once the light arriving at `x_i` from
//! each external light is known. So each internal light stores that
//! arriving light (irradiance times a transmittance averaged over several
//! ratio-tracking estimates) and evaluates `S₁` exactly in any direction;
//! only the multiply scattered part `Σ_{k≥1} J_k`, which is smooth in
//! angle, goes through the spherical harmonics. (This is where this module
//! goes beyond the note, which projects all of `J`: the SH order then only
//! limits the part it represents well.) The kernel average of the lights'
//! `J_i(n)` is left unclamped, although a truncated SH series and the
//! walks' noise can take it below zero where the function is small: the
//! reconstruction stays linear in the lights' coefficients, so that its
//! average over light sets is the method's expectation
//! ([`InternalLights::reconstruct_multi`]).
//!
//! The multiply scattered part is stored twice: all of it (what `L₁`
//! scatters once more, and what the gizmos and the point form show), and
//! what the walks carried to a gate *through at least one collision*
//! ([`Part::Scattered`], what `L₀` reconstructs along the camera ray).
//! The rest, a walk that reached gate `k` without colliding, is the single
//! scatter `T S₁` from the point `k s*` further along `−n`: over the
//! window it adds up to the single scatter of the rest of the camera ray,
//! which the gather marches exactly (`gather::single_beyond_window`).
//! Through the lights it was the largest error of the method: `S₁`'s
//! phase lobe projected on order-3 SH and averaged over the kernel put the
//! thin sphere's rim pixels +20…35 % high and its lit side 10…20 % low.
//!
//! # Walks towards the eye
//!
//! The camera sees `J` along the camera rays only: at a light, the one
//! direction `n_i = (eye − x_i)/|eye − x_i|`, to within the kernel's
//! angular size `h / |eye − x_i|` for the rays through its support. With
//! `view_walks` `K_v > 0` each light also runs `K_v` walks from `x_i` along
//! `−n_i` and keeps the mean of their collided part per unit chance
//! ([`Part::Scattered`]) as one RGB value (walked by
//! [`Walks::accumulate_collided`], which skips the shadow rays of the gates
//! before a walk's first collision: 7 % of a light set's time on the
//! puffs, the estimator unchanged); `L₀`'s reconstruction averages
//! those ([`InternalLights::reconstruct_view`]). Evaluating an order-`L`
//! series projected from `K` walks in spread directions has about `(L+1)²`
//! times the variance of a walk's value in the one direction it
//! estimates; on the puffs `K_v` = 16 walks towards the eye took the
//! light sets' noise in `L₀` from 31.9 % to 7.5 % of the image mean
//! ([validation](crate::doc::validation) §4). The spherical harmonics still serve
//! `L₁`, `F` and the gizmos.
//!
//! Only the lights within the kernel's reach of the camera rays' windows
//! run view walks ([`within_view_reach`]): `L₀`'s points lie in those
//! windows, a clock of `s*` from where the rays enter the box, so the
//! lights deeper in are never read there. The others keep their
//! harmonics' value towards the eye. On the puffs at `s*` 0.25 a quarter
//! of the lights are within reach, so the same time buys four times the
//! view walks per light read: 64 instead of 16 took the light sets'
//! variance × time from 190 to 76 %² s (128², M 16384, K 16).
//!
//! With the optical-depth clock the walks return `Ĵ_k = c_g(x_i) J^τ_k`
//! (see [`super::walk`]), and everything below uses `Ĵ` in place of
//! `J`; `k = 0` is `S₁` for both clocks.
//!
//! # The energy of each term
//!
//! `E_k = Σ_i V_i ∫ J_k(x_i, n) dn` estimates `∫_B ∫_{S²} J_k`, the power
//! carried by term `k` over the whole medium. It shows how fast the series
//! converges: the terms beyond `N` are what truncation drops.

use std::borrow::Borrow;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;

use super::chances::{collided_per_unit_chance, collision_probability};

use super::clock::{march_clock, Clock, ClockMarch, ClockRay, GateSettings};

use super::light_index::LightGrid;
use super::placement::{place_lights_with, PlacementDensity};
use super::view_placement::{knn_kernel_radius, place_in_view, PilotKernel, ViewFrame};
use super::walk::Walks;
use crate::physics::lights::Lights;
use crate::physics::phase;
use crate::physics::reference::RR_START_DEPTH;
use crate::physics::rng::{pcg_hash, Rng};
use crate::physics::sh::{hg_convolve_basis, sh_basis, sh_count, MAX_COUNT, MAX_ORDER};
use crate::physics::tracking::{transmittance, transmittance_at_rate};
use crate::physics::volume::{DensityField, Volume};

/// Stream index (the `pass` of [`Rng::for_sample`]) of the walks, apart
/// from the placement's and the renders' (the WGSL's `WALK_STREAM` is
/// generated from it).
pub const WALK_STREAM: u32 = 0x7761_6c6b;

/// The stream of a light's walks towards the eye and its phase walks on the
/// CPU, `(seed, light, EYE_WALK_STREAM)`: apart from its spread walks', so
/// that how those walks draw their numbers (the collision tail's, for
/// one) leaves the harmonics' numbers as they were. (The GPU gives every
/// walk a stream of its own.)
pub const EYE_WALK_STREAM: u32 = WALK_STREAM - 1;

/// Stream index of the sky's light arriving at each internal light
/// ([`sky_arrival`]; CPU only, for both backends' light sets).
pub const SKY_STREAM: u32 = 0x736b_7921;

/// Directions per light of [`sky_arrival`]'s estimate, at least.
const SKY_SAMPLES: u32 = 16;

/// Tentative collisions per unit majorant of [`sky_arrival`]'s ratio
/// tracking: at rate 1 a tight majorant (a homogeneous medium) makes each
/// transmittance a yes-or-no estimate, and in the furnace sphere (optical
/// radius 2) the lights' sky part scattered 0.83–1.34× its value at 256
/// directions.
const SKY_TRACKING_RATE: f32 = 4.0;

/// Cells of the placement density along the longest axis of the box.
pub const PLACEMENT_RESOLUTION: u32 = 64;

/// Lights per cluster of the gather's light selection, on average.
const LIGHTS_PER_CLUSTER: f32 = 24.0;

/// Most clusters along an axis.
const MAX_CLUSTER_RES: u32 = 12;

/// The form of the final gather's `L₁` (see [`super::gather`]): the
/// settings' enum, one for the scene file, the command line, the
/// estimators and the GPU.
pub use crate::scene::settings::L1Form;

/// Parameters of the internal lights, resolved (no defaults left open).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InternalParams {
    /// Window length `s*` (a distance, or an optical depth for
    /// [`Clock::OpticalDepth`]).
    pub s_star: f32,
    /// Number of lights `M`.
    pub lights: usize,
    /// Series truncation `N`.
    pub terms: u32,
    /// Walks per light `K`.
    pub walks: u32,
    /// SH order of `F` and the multiply scattered part of `J`.
    pub sh_order: u32,
    /// Kernel radius `h`; `None`: automatic, for about
    /// `kernel_neighbours` lights within it ([`kernel_radius_for`]).
    pub kernel_radius: Option<f32>,
    /// About how many lights the automatic kernel radius holds
    /// ([`KERNEL_NEIGHBOURS`] for a render's first set, fewer for later
    /// ones: [`kernel_neighbours_for_set`]); unused with `kernel_radius`.
    pub kernel_neighbours: u32,
    /// Uniform fraction `u` of the placement density.
    pub uniform_mix: f32,
    /// The path-length clock.
    pub clock: Clock,
    /// The form of the gather's `L₁`.
    pub l1: L1Form,
    /// Scatterings inside the final window that the field form of `L₁`
    /// follows: 1 is [method §6](crate::doc::method)'s single-scatter kernel `G ≈ G_SS`;
    /// each more adds the next term of `G(s)` inside the window
    /// (1 ..= [`MAX_WINDOW_SCATTERS`]).
    pub window_scatters: u32,
    /// Walks per light along the direction from the light towards `eye`
    /// (0: none): an estimate of the collided part of `J_i` in the one
    /// direction the camera sees it in, which `L₀`'s reconstruction then
    /// averages instead of evaluating the lights' spherical harmonics
    /// ([`InternalLights::reconstruct_view`]). Only lights within the
    /// camera's reach walk ([`within_view_reach`]); the others use their
    /// harmonics.
    pub view_walks: u32,
    /// The camera's eye, which the view walks look towards (they make the
    /// lights depend on it: moving the camera re-samples them).
    pub eye: Vec3,
    /// Seed of the placement and the walks.
    pub seed: u64,
    /// The share of the `M` lights placed in the camera's windows rather
    /// than by density ([`super::view_placement`]; 0: the note's placement
    /// alone). Needs `view_frame`, and ties the lights to the camera.
    pub view_share: f32,
    /// The camera, for `view_share` (the default frame when unused).
    pub view_frame: ViewFrame,
    /// When the walks stop early (`None`: never): on the CPU after the
    /// round of walks (one per light) that ends past it, at least one; on
    /// the GPU each dispatch of lights walks the share that the time left
    /// allows, at least one walk of each kind per light
    /// ([`crate::gpu::walks`]). A render with a time limit shorter than a
    /// full set's walks gets its first image in time from fewer walks per
    /// light, each weighted by the walks done (unbiased, noisier). A
    /// matter of scheduling, not of the estimator.
    pub walk_deadline: Option<Instant>,
}

/// The automatic kernel radius of a render's first light set for lights
/// placed by density, in units of the mean light spacing: about 65 lights
/// fall inside the reconstruction kernel's support, which averages out
/// the walks' noise in `J_i` (with 1.5, about 14 lights, the thin sphere
/// showed blotches of ±20 % at `K = 64`). Later sets' kernels are
/// narrower by `(k/`[`KERNEL_NEIGHBOURS`]`)^{1/3}` ([`kernel_radius_for`]).
pub const AUTO_KERNEL_FACTOR: f32 = 2.5;

/// Lights the automatic kernel holds in the first light set of a render
/// where the lights stand in the camera's windows
/// ([`InternalParams::view_share`]): its radius is the median distance
/// from a light to its this-many-th nearest neighbour. Later sets hold
/// fewer ([`kernel_neighbours_for_set`]). Lights placed by density keep
/// [`AUTO_KERNEL_FACTOR`]'s radius in the first set, about 65 lights: a
/// single set of them, which fills the volume sparsely, read the puffs'
/// image 2.8 % dark with it and 3.0 % with 45 (`tests/internal_lights.rs`,
/// the note's settings), where points with no light within the kernel
/// read zero.
///
/// The count trades the kernel's blur, a bias no number of sets removes,
/// against the walks' noise, about `1/k` per set: 64 until the sets grew
/// quieter, 45 since (why, and what 32 would cost: [method
/// §6.2](crate::doc::method),
/// [validation §3.25](crate::doc::validation)).
pub const KERNEL_NEIGHBOURS: u32 = 45;

/// The fewest lights the automatic kernel holds in any set. With 8 the
/// plume's image came out 0.8 % dark and with 4 by 3.2 % (128 sets each):
/// the normalised average reads zero where no light falls within `h`,
/// and that chance grows fast as the kernel holds fewer.
pub const KERNEL_NEIGHBOURS_FLOOR: u32 = 16;

/// The least `|g|` at which the lights that walk towards the eye also run
/// phase walks ([`phase_walks`]). Below it the multiply scattered source
/// is smooth in angle and its harmonics serve `L₁`; above it they ring
/// about its peak (validation §3.15: a cumulus with `g` 0.95 came out
/// 7.5 % bright, a back-lit sphere with `g` 0.85 3.2 % dark).
pub const PHASE_WALKS_MIN_G: f32 = 0.75;

/// View walks per phase walk ([`phase_walks`]). Their value is one more
/// average per light, and a quarter as many walks as the view's cost the
/// cumulus's sets about a tenth more time (validation §3.15).
pub const VIEW_WALKS_PER_PHASE_WALK: u32 = 4;

/// Phase walks per light with `params` in a medium of asymmetry `g`: one
/// per [`VIEW_WALKS_PER_PHASE_WALK`] view walks where `|g|` ≥
/// [`PHASE_WALKS_MIN_G`], otherwise none. A phase walk starts towards the
/// eye turned by one draw of the phase function, `n' ~ P(n_i · n')`, and
/// keeps all of `Σ_{k≥1} J_k(x_i, n')`: their mean estimates the source
/// one more scattering sends towards the eye, `∫ P(n_i·n') J(x_i, n') dn'`,
/// which every scattering of `L₁` reads
/// ([`InternalLights::reconstruct_phase_view`]) instead of the harmonics.
pub fn phase_walks(params: &InternalParams, g: f32) -> u32 {
    if g.abs() >= PHASE_WALKS_MIN_G {
        params.view_walks.div_ceil(VIEW_WALKS_PER_PHASE_WALK)
    } else {
        0
    }
}

/// Where phase walks serve `L₁` a light keeps one in this many of its
/// spread walks `K` ([`walk_split`]).
pub const SPREAD_WALKS_KEPT_WITH_PHASE_WALKS: u32 = 4;

/// Spread walks given up for one more walk towards the eye (with its
/// share of a phase walk) in [`walk_split`]: what one cost on the thick
/// cumulus when the split was made, twelve spread walks taking as long as
/// eight walks towards the eye and their two phase walks (validation
/// §3.21). Since collision tails (method §5.4) a walk towards the eye
/// costs about half of that, but giving the walks towards the eye that
/// time (32 of them instead of 24) read worse at equal time: the
/// cumulus's 8×8 blocks at 8 s 6.71 → 7.39 %, per pixel 16.29 → 17.39 %
/// (12 renders, validation §3.22). So the split stays.
pub const SPREAD_WALKS_PER_VIEW_WALK: f32 = 1.5;

/// How a light's walks are split, `(K, K_v)`, for `walks` spread walks and
/// `view_walks` walks towards the eye asked for, in a medium of asymmetry
/// `g`. Where phase walks serve `L₁` (`|g|` ≥ [`PHASE_WALKS_MIN_G`] with
/// view walks), the image reads no harmonics at all: `L₀` reads the view
/// walks, `L₁` the phase walks, and the spread walks feed only `F`, the
/// energies, the gizmos and the lights out of the camera's reach. There a
/// light keeps a quarter of its spread walks
/// ([`SPREAD_WALKS_KEPT_WITH_PHASE_WALKS`], at least one) and spends the
/// rest's time on walks towards the eye, at
/// [`SPREAD_WALKS_PER_VIEW_WALK`] spread walks each (and their phase
/// walks, [`phase_walks`], follow): the presets' 16 and 16 become 4 and
/// 24, a set of about the same cost whose image is less noisy (the
/// thick cumulus at 8 s: 8×8 blocks 9.96 → 8.98 %, per pixel 22.2 →
/// 20.6 %, validation §3.21; measured before collision tails, which
/// halved the cost of the walks towards the eye).
/// Elsewhere the harmonics serve `L₁` and the split is as asked.
pub fn walk_split(walks: u32, view_walks: u32, g: f32) -> (u32, u32) {
    if view_walks == 0 || g.abs() < PHASE_WALKS_MIN_G {
        return (walks, view_walks);
    }
    let kept = (walks / SPREAD_WALKS_KEPT_WITH_PHASE_WALKS)
        .max(1)
        .min(walks);
    let moved = (walks - kept) as f32 / SPREAD_WALKS_PER_VIEW_WALK;
    let view = view_walks
        .saturating_add(moved.round() as u32)
        .min(crate::scene::settings::MAX_WALKS);
    (kept, view)
}

/// Whether `L₁` reads the lights' harmonics off the camera ray with
/// `params` in a medium of asymmetry `g` (its field form without phase
/// walks), so that lights may move on from the camera's windows to its
/// source points ([`place_in_view`]): with phase walks its first
/// scattering reads on the ray itself, and the points form reads the
/// lights placed by density.
pub fn l1_reads_off_the_ray(params: &InternalParams, g: f32) -> bool {
    params.l1 == L1Form::Field && phase_walks(params, g) == 0
}

/// Lights the automatic kernel holds in light set `set` of a render
/// (0-based): [`KERNEL_NEIGHBOURS`]` / (set + 1)`, at least
/// [`KERNEL_NEIGHBOURS_FLOOR`] — 45, 22, then 16.
///
/// The kernel's average blurs `J` over `h`: a bias that renewed sets do
/// not average away, while the walks' noise they do. So, as progressive
/// photon mapping shrinks its radius pass after pass, the sets shrink the
/// kernel: the first set of a render (all that a single-set render or the
/// previewer's first image has) is smooth, and once several sets share
/// the image their noise is averaged over sets rather than over
/// neighbours ([method §6.2](crate::doc::method)).
pub fn kernel_neighbours_for_set(set: u32) -> u32 {
    (KERNEL_NEIGHBOURS / set.saturating_add(1)).max(KERNEL_NEIGHBOURS_FLOOR)
}

/// Lights the automatic kernel holds in light set `set` of a render whose
/// light sets add more noise than its passes
/// ([`BalancedRenewal::sets_outweigh_passes`](crate::render::renewal::BalancedRenewal::sets_outweigh_passes)):
/// [`KERNEL_NEIGHBOURS`]` / √(set + 1)`, at least
/// [`KERNEL_NEIGHBOURS_FLOOR`] — 45, 31, 25, 22, 20, …, 16 from set 7.
///
/// Where the sets' noise dominates, one set's variance grows about as
/// `1/k` as the kernel narrows, so shrinking it as fast as
/// [`kernel_neighbours_for_set`] multiplies what dominates; but the
/// kernel's blur is a bias the sets never average away. At a surface the
/// camera sees, the lights within `h` stand on one side, inside, and the
/// blur is of first order in `h` (`h ∝ √k` for lights in the camera's
/// windows): the mean squared error after `n` sets is then about
/// `B k + V/(k n)`, least at `k ∝ 1/√n`. On the suite's thick cumulus,
/// kept at 64 lights, the shadowed underside came out 13 % too bright
/// after 45 sets, and 4 % with a kernel of 16
/// ([validation §3.7](crate::doc::validation)).
pub fn kernel_neighbours_for_noisy_set(set: u32) -> u32 {
    let k = f64::from(KERNEL_NEIGHBOURS) / (f64::from(set) + 1.0).sqrt();
    (k as u32).max(KERNEL_NEIGHBOURS_FLOOR)
}

/// The most scatterings inside the final window the gather follows
/// ([`InternalParams::window_scatters`]): the settings' bound, defined with
/// them so that the scene layer needs nothing of this one.
pub use crate::scene::settings::MAX_WINDOW_SCATTERS;

/// `h₁ / h`: `L₁`'s kernel `1/(r² + h₁²)` is softened far less than the
/// reconstruction averages. Its bias ([method §6](crate::doc::method): it vanishes as
/// `h₁ → 0`) is an underestimate of the light within `h₁` of each internal
/// light, which with `h₁ = h` was the largest error at small `s*` (the
/// window's reach `s*` is then comparable to `h`); its variance is cheap,
/// since the equiangular sampling of the gather cancels the kernel.
pub const L1_SOFTENING: f32 = 0.2;

/// Which part of the lights' `Σ_{k≥1} J_k` a reconstruction averages.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Part {
    /// All of it: the source of `L₁`.
    All,
    /// What the walks carried through at least one collision: `L₀`'s
    /// `k ≥ 1` part, whose unscattered rest (single scatter from `k s*`
    /// further along the ray) the gather marches exactly. Stored and
    /// reconstructed **per unit chance of that collision**,
    /// [`super::chances::collision_probability`] along `−n`: the walks
    /// divide by it at the light, and the gather multiplies the
    /// reconstruction by it at the point
    /// ([`super::chances::ChancesAlongRay`]). Near the surface of a
    /// puff that chance drops from nearly one to nothing across the
    /// directions that leave the medium;
    /// projected as it was, order-4 harmonics and a kernel that reaches
    /// lights deeper in smeared that horizon, and the dim edges of the
    /// puffs came out 7…20 % bright at small `s*` ([validation](crate::doc::validation)
    /// §4).
    Scattered,
}

/// One internal light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InternalLight {
    /// Position `x_i`.
    pub position: Vec3,
    /// `ρ(x_i)`.
    pub density: f32,
    /// `V_i = 1 / (M p(x_i))`, the volume the light stands for.
    pub weight: f32,
}

/// Wall-clock times of a build, in seconds.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BuildTimings {
    /// Placement.
    pub placement: f64,
    /// Arriving light and time-gated walks with SH projection.
    pub walks: f64,
    /// Spatial indices.
    pub index: f64,
}

impl BuildTimings {
    /// Seconds the whole build took.
    pub fn total(&self) -> f64 {
        self.placement + self.walks + self.index
    }
}

/// The internal lights of one scene and parameter set.
#[derive(Clone, Debug)]
pub struct InternalLights {
    /// The parameters they were built with.
    pub params: InternalParams,
    /// Window length `s*`.
    pub s_star: f32,
    /// The kernel radius `h` in use (the reconstruction of `L₀`).
    pub kernel_radius: f32,
    /// The softening of `L₁`'s bounded kernel `1/(r² + h₁²)`:
    /// `h₁ = h ·` [`L1_SOFTENING`].
    pub softening: f32,
    /// The lights.
    pub lights: Vec<InternalLight>,
    /// `E_k` for `k = 0..=N` (see the module doc), RGB; where `N` exceeds
    /// [`RESOLVED_TERMS`](super::clock::RESOLVED_TERMS), the last element is
    /// the sum of the terms from it to `N` ([`term_slot`](super::clock::term_slot)).
    pub term_energy: Vec<Vec3>,
    /// `∫ρ` over the box, as estimated by the placement.
    pub density_integral: f32,
    /// How long the build took.
    pub timings: BuildTimings,
    /// Walks whose loops the GPU driver ended before they did (Mesa's
    /// software driver caps one invocation's loop iterations at 65 535 in
    /// all): their light is missing. Zero on the CPU and on hardware GPUs.
    pub cut_short_walks: u64,
    /// Walks per light walked: `params.walks`, or fewer where the build
    /// stopped at [`InternalParams::walk_deadline`] (its sums then weigh
    /// each walk `4π` over the walks done; on the GPU, the fewest any
    /// light walked).
    pub walked: u32,
    /// The share of a whole set's walks that the build walked: 1, or less
    /// where it stopped at [`InternalParams::walk_deadline`]. A schedule
    /// that measured the build's time divides it by this to tell what a
    /// whole set costs.
    pub walk_share: f64,
    pub(crate) sh_order: u32,
    pub(crate) sh_count: usize,
    /// `F_i` SH coefficients, `sh_count` per light.
    pub(crate) f_coeffs: Vec<Vec3>,
    /// `Σ_{k≥1} J_k` SH coefficients, `sh_count` per light.
    pub(crate) multi_coeffs: Vec<Vec3>,
    /// The part of `Σ_{k≥1} J_k` carried through at least one collision
    /// (what `L₀` reconstructs; the rest is single scatter from further
    /// along the ray, which the gather marches exactly), per unit chance of
    /// the collision ([`Part::Scattered`]), `sh_count` per light.
    pub(crate) scattered_coeffs: Vec<Vec3>,
    /// Light arriving at each internal light from each external light,
    /// `T E`, `external_count` per light.
    pub(crate) arrival: Vec<Vec3>,
    /// The sky's light arriving at each internal light, `L(−ω) T` over the
    /// directions `ω` it travels, as SH coefficients (`sh_count` per light;
    /// empty without a sky): [`sky_arrival`].
    pub(crate) sky: Vec<Vec3>,
    pub(crate) external: Lights,
    /// `α σ_t` (per unit density) and `g`.
    pub(crate) scatter: Vec3,
    pub(crate) g: f32,
    /// Per light: the factor that turns its `J` into the quantity the
    /// kernel reconstruction averages (1, or `1/c_g(x_i)` for the
    /// optical-depth clock; 0: left out of the reconstruction).
    pub(crate) recon_scale: Vec<f32>,
    /// Lights near a point, cells of about `h`.
    pub(crate) fine: LightGrid,
    /// Aligned with `fine.ids()` (the lights cell by cell): position and
    /// `recon_scale`, then `sh_count` coefficients each of
    /// `multi_coeffs` and `scattered_coeffs`. Copies in the order the
    /// kernel reconstruction visits the lights, so that it reads them
    /// from contiguous memory rather than all over the light arrays.
    pub(super) fine_points: Vec<[f32; 4]>,
    /// [`LightSources::view`]: per light (empty without view walks).
    pub(crate) view: Vec<Vec3>,
    /// `view` aligned with `fine.ids()`.
    pub(super) fine_view: Vec<Vec3>,
    /// [`LightSources::phase_view`]: per light (empty without phase walks).
    pub(crate) phase_view: Vec<Vec3>,
    /// `phase_view` aligned with `fine.ids()`.
    pub(super) fine_phase_view: Vec<Vec3>,
    /// The standard error of each light's `view` value, from the spread
    /// of its walks towards the eye (per channel; zero for a light that
    /// walked none, or fewer than two, and empty where the walks ran on
    /// the GPU): [`InternalLights::walk_error_lights`].
    pub(crate) view_se: Vec<Vec3>,
    /// The standard error of each light's `phase_view` value, as
    /// `view_se`.
    pub(crate) phase_se: Vec<Vec3>,
    pub(super) fine_multi: Vec<Vec3>,
    pub(super) fine_scattered: Vec<Vec3>,
    /// Light clusters for the gather's light selection.
    pub(crate) clusters: LightGrid,
    /// Per cluster: `Σ` power of its lights.
    pub(crate) cluster_power: Vec<f32>,
    /// Aligned with `clusters.ids()`: each light's power `V_i |J̄_i|`.
    pub(crate) light_power: Vec<f32>,
    /// Clusters with power, for the per-ray selection.
    pub(crate) live_clusters: Vec<u32>,
    /// `max(σ_t)`, the optical-depth clock's rate per unit density.
    pub(crate) sigma_grey: f32,
}

/// The internal lights and their sources, as the walks leave them:
/// [`InternalLights::assemble`] builds the kernel and the spatial indices
/// around them.
#[derive(Clone, Debug, Default)]
pub struct LightSources {
    /// Where the lights are, their density and weight `V_i`.
    pub lights: Vec<InternalLight>,
    /// `F` (the `k = 1` term): `(sh_order+1)²` SH coefficients per light.
    pub f_coeffs: Vec<Vec3>,
    /// `J`'s `k ≥ 1` part, per light, as `f_coeffs`.
    pub multi_coeffs: Vec<Vec3>,
    /// The part of `multi_coeffs` the walks carried through at least one
    /// collision, per unit chance of the collision ([`Part::Scattered`]),
    /// per light, as `f_coeffs`.
    pub scattered_coeffs: Vec<Vec3>,
    /// The light arriving from each external light (in `Lights`' order,
    /// suns first), per light.
    pub arrival: Vec<Vec3>,
    /// The energy each term `k = 0..=N` carries over all lights (the terms
    /// past [`RESOLVED_TERMS`](super::clock::RESOLVED_TERMS) summed in the
    /// last element).
    pub term_energy: Vec<Vec3>,
    /// Per light, the collided part of `J` towards the eye per unit chance
    /// of the collision (see the module doc, "Walks towards the eye");
    /// empty without view walks.
    pub view: Vec<Vec3>,
    /// Per light, the mean of its phase walks ([`phase_walks`]): the
    /// source one more scattering sends towards the eye; empty without
    /// phase walks.
    pub phase_view: Vec<Vec3>,
    /// The kernel radius of these lights, if the walks already chose it
    /// ([`kernel_radius_for`]: the view walks needed it to know which
    /// lights the camera reads); `None`: [`InternalLights::assemble`]
    /// chooses it.
    pub kernel_radius: Option<f32>,
}

impl LightSources {
    /// Room for the sources of `lights`, each with `count` SH coefficients
    /// per set, `n_ext` arrival values and `gates` slots of energy per term
    /// ([`GateSettings::term_slots`]).
    pub fn with_capacity(
        lights: Vec<InternalLight>,
        count: usize,
        n_ext: usize,
        gates: usize,
    ) -> Self {
        let m = lights.len();
        Self {
            lights,
            f_coeffs: Vec::with_capacity(m * count),
            multi_coeffs: Vec::with_capacity(m * count),
            scattered_coeffs: Vec::with_capacity(m * count),
            arrival: Vec::with_capacity(m * n_ext),
            term_energy: vec![Vec3::ZERO; gates],
            view: Vec::new(),
            phase_view: Vec::new(),
            kernel_radius: None,
        }
    }

    /// Appends the next light's `F`, `J`, collided part and arrival, in the
    /// lights' order, and adds its energy per term to the totals.
    pub fn push(
        &mut self,
        f: impl IntoIterator<Item = Vec3>,
        multi: impl IntoIterator<Item = Vec3>,
        scattered: impl IntoIterator<Item = Vec3>,
        arrival: impl IntoIterator<Item = Vec3>,
        energy: impl IntoIterator<Item = Vec3>,
    ) {
        self.f_coeffs.extend(f);
        self.multi_coeffs.extend(multi);
        self.scattered_coeffs.extend(scattered);
        self.arrival.extend(arrival);
        for (e, v) in self.term_energy.iter_mut().zip(energy) {
            *e += v;
        }
    }

    /// Sets the view value of each light with `reached[i]` false to its
    /// harmonics' collided part evaluated towards `eye` (what
    /// `reconstruct_multi(…, Part::Scattered)` reads of the light for a
    /// camera ray), and its phase-walk value to the harmonics of all of
    /// `Σ_{k≥1} J_k` convolved with the phase function (band `l` times
    /// `g^l`) towards `eye`, instead of walks it did not run (see
    /// [`within_view_reach`]). Does nothing without view values.
    pub fn view_from_harmonics_outside(&mut self, order: u32, eye: Vec3, g: f32, reached: &[bool]) {
        let count = sh_count(order);
        if self.view.len() != self.lights.len()
            || self.scattered_coeffs.len() < self.lights.len() * count
            || self.multi_coeffs.len() < self.lights.len() * count
        {
            return;
        }
        let phase = self.phase_view.len() == self.lights.len();
        let mut y = [0.0f32; MAX_COUNT];
        for (i, light) in self.lights.iter().enumerate() {
            if reached.get(i).copied().unwrap_or(true) {
                continue;
            }
            let n = (eye - light.position).try_normalize().unwrap_or(Vec3::Z);
            sh_basis(order, n, &mut y);
            let coeffs = i * count..(i + 1) * count;
            self.view[i] = InternalLights::eval_sh(&self.scattered_coeffs[coeffs.clone()], &y);
            if phase {
                hg_convolve_basis(&mut y[..count], g);
                self.phase_view[i] = InternalLights::eval_sh(&self.multi_coeffs[coeffs], &y);
            }
        }
    }
}

/// The kernel radius `h` of `lights`: [`InternalParams::kernel_radius`],
/// or by default one that holds about [`InternalParams::kernel_neighbours`]
/// lights — with lights in the camera's windows the median distance from
/// a light to its that-many-th nearest neighbour, otherwise
/// [`AUTO_KERNEL_FACTOR`]` · (neighbours / `[`KERNEL_NEIGHBOURS`]`)^{1/3}`
/// times the mean light spacing `median(V_i)^{1/3}` (the box's volume per
/// light if no light has a weight).
pub fn kernel_radius_for<D: DensityField>(
    vol: &Volume<D>,
    params: &InternalParams,
    lights: &[InternalLight],
) -> f32 {
    params.kernel_radius.unwrap_or_else(|| {
        let neighbours = params.kernel_neighbours.max(1);
        if params.view_share > 0.0 {
            let positions: Vec<Vec3> = lights.iter().map(|l| l.position).collect();
            if let Some(r) = knn_kernel_radius(&positions, neighbours as usize, 512) {
                return r;
            }
        }
        let m = lights.len().max(1);
        let mut v: Vec<f32> = lights
            .iter()
            .map(|l| l.weight)
            .filter(|w| *w > 0.0)
            .collect();
        let mid = v.len() / 2;
        let median = if v.is_empty() {
            let (lo, hi) = vol.bounds;
            let s = hi - lo;
            s.x * s.y * s.z / m as f32
        } else {
            *v.select_nth_unstable_by(mid, f32::total_cmp).1
        };
        let factor = AUTO_KERNEL_FACTOR * (neighbours as f32 / KERNEL_NEIGHBOURS as f32).cbrt();
        factor * median.cbrt()
    })
}

/// Which lights the camera's `L₀` can read towards the eye, for
/// [`InternalParams::view_walks`]: light `i` is within reach when the
/// clock along the ray from the eye through `x_i`, from where that ray
/// enters the medium's box up to the point `reach` (the kernel radius)
/// short of `x_i`, stays within `s*` — the light lies within the kernel's
/// support of its own ray's window. `L₀`'s points lie in the camera rays'
/// windows, so a light deeper in reaches none of them unless a
/// neighbouring ray's window ends deeper than its own (a ray that crosses
/// less medium before it): such a light then gives `L₀` its harmonics'
/// value ([`LightSources::view_from_harmonics_outside`]), noisier but
/// of the same quantity. On the puffs, a quarter of the lights are within
/// reach at `s*` 0.25.
pub fn within_view_reach<D: DensityField>(
    vol: &Volume<D>,
    params: &InternalParams,
    reach: f32,
    lights: &[InternalLight],
) -> Vec<bool> {
    lights
        .par_iter()
        .map(|light| {
            let d = light.position - params.eye;
            let dist = d.length();
            if dist <= 0.0 {
                return true;
            }
            let dir = d / dist;
            let Some((t_in, t_out)) = vol.clip(params.eye, dir) else {
                return false;
            };
            let t_stop = dist - reach;
            t_stop <= t_in
                || matches!(
                    march_clock(
                        vol,
                        &ClockRay {
                            clock: params.clock,
                            s_star: params.s_star,
                            origin: params.eye + dir * t_in,
                            dir,
                            t_exit: t_out - t_in,
                        },
                        0.0,
                        t_stop - t_in,
                        params.s_star,
                    ),
                    ClockMarch::Exhausted(_)
                )
        })
        .collect()
}

/// The sky's light arriving at each of `lights`, `A_i(ω) = L(−ω)
/// T(x_i, x_i − ∞ ω)` over the directions `ω` light travels, projected on
/// the real spherical harmonics of `order`: `sh_count(order)` coefficients
/// per light, estimated from `SKY_SAMPLES` (16) (or `K`, if more) directions
/// drawn from the sky's own distribution, each with a ratio-tracked
/// transmittance; empty without a sky. With it, the lights' `S₁`
/// ([`InternalLights::eval_s1`]: the field `L₁`'s points form, the `k = 0`
/// energy and the gizmos' `J`) holds the sky's share as the walks' gates
/// and the gather hold it, `b ∫ P(n·ω) A(ω) dω = b Σ g^l a_lm Y_lm(n)`.
/// The sky is smooth, but a shadowed light's `A` is not: the harmonics
/// keep its broad part.
pub fn sky_arrival<D: DensityField>(
    vol: &Volume<D>,
    external: &Lights,
    params: &InternalParams,
    lights: &[InternalLight],
    order: u32,
) -> Vec<Vec3> {
    let Some(env) = external.sky() else {
        return Vec::new();
    };
    let count = sh_count(order);
    let samples = params.walks.max(SKY_SAMPLES);
    let per_light: Vec<Vec<Vec3>> = lights
        .par_iter()
        .enumerate()
        .map(|(i, light)| {
            let mut rng = Rng::for_sample(params.seed, i as u32, SKY_STREAM);
            let mut c = vec![Vec3::ZERO; count];
            let mut y = [0.0f32; MAX_COUNT];
            for _ in 0..samples {
                let (u1, u2) = (rng.next_f32(), rng.next_f32());
                let Some((from, pdf)) = env.sample(u1, u2) else {
                    continue;
                };
                let radiance = env.radiance(from);
                if pdf.is_nan() || pdf <= 0.0 || radiance == Vec3::ZERO {
                    continue;
                }
                let t = transmittance_at_rate(
                    vol,
                    light.position,
                    from,
                    f32::INFINITY,
                    SKY_TRACKING_RATE,
                    &mut rng,
                );
                let a = radiance * t / (pdf * samples as f32);
                sh_basis(order, -from, &mut y);
                for (ck, &yk) in c.iter_mut().zip(&y[..count]) {
                    *ck += a * yk;
                }
            }
            c
        })
        .collect();
    per_light.into_iter().flatten().collect()
}

/// The placement density of the internal lights in `vol` with uniform
/// fraction `u_mix` (a [`PLACEMENT_RESOLUTION`]-cell table of `ρ`): what
/// [`InternalLights::build`] places by, and all that the placement needs
/// of the medium.
pub fn placement_density<D: DensityField>(vol: &Volume<D>, u_mix: f32) -> PlacementDensity {
    PlacementDensity::build(&vol.density, vol.bounds, PLACEMENT_RESOLUTION, u_mix)
}

/// Places the `M` lights of `params`: the share
/// [`InternalParams::view_share`] in the camera's windows
/// ([`place_in_view`], no volume weight), the rest by `density` (with
/// their weights `V_i`); returns them with the placement's `∫ρ`. Both
/// backends build on these lights (the GPU places by density itself only
/// when no share is placed in the camera's windows).
pub fn place_internal_lights<D: DensityField>(
    vol: &Volume<D>,
    params: &InternalParams,
    density: &PlacementDensity,
) -> (Vec<InternalLight>, f32) {
    let m = params.lights.max(1);
    let share = params.view_share.clamp(0.0, 1.0);
    let m_view = (share * m as f32).round() as usize;
    let in_view = if m_view > 0 {
        place_in_view(
            vol,
            &params.view_frame,
            (params.clock, params.s_star),
            l1_reads_off_the_ray(params, vol.optics.g).then_some(match params.kernel_radius {
                Some(h) => PilotKernel::Radius(h),
                None => PilotKernel::Neighbours(params.kernel_neighbours),
            }),
            m_view,
            params.seed,
        )
    } else {
        Vec::new()
    };
    // Lights whose camera rays all missed the medium are placed by
    // density instead.
    let missed = in_view.iter().filter(|p| p.is_none()).count();
    let placement = place_lights_with(density, m - m_view + missed, params.seed);
    let lights: Vec<InternalLight> = in_view
        .par_iter()
        .flatten()
        .map(|&position| InternalLight {
            position,
            density: vol.density.density(position),
            weight: 0.0,
        })
        .chain(placement.lights.par_iter().map(|l| InternalLight {
            position: l.position,
            density: vol.density.density(l.position),
            weight: l.weight,
        }))
        .collect();
    (lights, placement.density_integral)
}

impl InternalLights {
    /// Places the lights, runs the walks and builds the indices. Returns
    /// `None` if `cancel` is set meanwhile.
    pub fn build<D: DensityField>(
        vol: &Volume<D>,
        external: &Lights,
        params: &InternalParams,
        cancel: &AtomicBool,
    ) -> Option<Self> {
        Self::build_placed(
            vol,
            external,
            params,
            || placement_density(vol, params.uniform_mix),
            cancel,
        )
    }

    /// [`InternalLights::build`] placing by the density `density` gives
    /// ([`placement_density`] of this medium and `params.uniform_mix`: it
    /// depends on nothing else, so a renderer may keep it while the other
    /// parameters change and hand it back here). `timings.placement`
    /// counts getting it.
    pub fn build_placed<D: DensityField, P: Borrow<PlacementDensity>>(
        vol: &Volume<D>,
        external: &Lights,
        params: &InternalParams,
        density: impl FnOnce() -> P,
        cancel: &AtomicBool,
    ) -> Option<Self> {
        let start = Instant::now();
        let (lights, density_integral) = place_internal_lights(vol, params, density().borrow());
        let t_place = start.elapsed().as_secs_f64();
        if cancel.load(Ordering::Relaxed) {
            return None;
        }
        let mut out = Self::build_at(vol, external, params, lights, density_integral, cancel)?;
        out.timings.placement = t_place;
        Some(out)
    }

    /// Runs the walks of [`InternalLights::build`] for lights already
    /// placed (`density_integral`: the placement's `∫ρ`) and builds the
    /// indices; `timings.placement` is left at zero. Returns `None` if
    /// `cancel` is set meanwhile. The GPU tests walk the GPU's lights here.
    pub fn build_at<D: DensityField>(
        vol: &Volume<D>,
        external: &Lights,
        params: &InternalParams,
        lights: Vec<InternalLight>,
        density_integral: f32,
        cancel: &AtomicBool,
    ) -> Option<Self> {
        let start = Instant::now();
        let order = params.sh_order.min(MAX_ORDER);
        let count = sh_count(order);
        let n_ext = external.suns.len() + external.points.len();
        let gate = GateSettings {
            s_star: params.s_star,
            n_terms: params.terms,
            clock: params.clock,
            rr_start: RR_START_DEPTH,
        };
        // Per-term slots: terms past `RESOLVED_TERMS` share the last one.
        let slots = gate.term_slots();
        let walker = Walks::guided(vol, external, gate);
        let walks = params.walks.max(1);
        let tr_estimates = (walks / 4).clamp(4, 64);
        // The lights whose view walks the camera can read.
        let kernel_radius = kernel_radius_for(vol, params, &lights);
        let reached = if params.view_walks > 0 {
            within_view_reach(vol, params, kernel_radius, &lights)
        } else {
            Vec::new()
        };
        let scatter = vol.optics.albedo * vol.optics.sigma_t;
        let mut walked: Vec<Walked> = lights
            .par_iter()
            .enumerate()
            .map(|(i, light)| {
                let mut rng = Rng::for_sample(params.seed, i as u32, WALK_STREAM);
                let x = light.position;
                // Light arriving from each external light.
                let mut arrival = Vec::with_capacity(n_ext);
                external.for_each_at(x, |l| {
                    let mut t = Vec3::ZERO;
                    for _ in 0..tr_estimates {
                        t += transmittance(vol, x, -l.travel, l.distance, &mut rng);
                    }
                    arrival.push(l.irradiance * t / tr_estimates as f32);
                });
                let mut energy = vec![Vec3::ZERO; slots];
                // k = 0: ∫ S₁ dn = b Σ T E, since the phase function is
                // normalised.
                energy[0] = light.weight * light.density * scatter * arrival.iter().sum::<Vec3>();
                // Stratified directions: a spherical Fibonacci lattice of
                // `walks` points under a uniformly random rotation (each
                // direction is still uniform, so the projection stays
                // unbiased, but the set covers the sphere evenly).
                let rotation = random_rotation(&mut rng);
                let phi0 = 2.0 * std::f32::consts::PI * rng.next_f32();
                // Only the lights within the camera's reach walk towards
                // the eye.
                let to_eye = (params.view_walks > 0 && reached[i])
                    .then(|| (params.eye - x).try_normalize().unwrap_or(Vec3::Z));
                Walked {
                    rng,
                    eye_rng: Rng::for_sample(params.seed, i as u32, EYE_WALK_STREAM),
                    rotation,
                    phi0,
                    to_eye,
                    view: Vec3::ZERO,
                    phase: Vec3::ZERO,
                    view_sq: Vec3::ZERO,
                    phase_sq: Vec3::ZERO,
                    f: vec![Vec3::ZERO; count],
                    multi: vec![Vec3::ZERO; count],
                    scattered: vec![Vec3::ZERO; count],
                    arrival,
                    energy,
                }
            })
            .collect();
        // The walks in rounds: in each, every light walks one point of its
        // lattice and one walk towards the eye (while it has them), the
        // lattice's points in an order whose every prefix spreads over the
        // sphere ([`lattice_order`]). A build that stops at
        // `params.walk_deadline` after `r` rounds has `r` uniform
        // directions per light, weighted `4π/r`, and `r` walks towards
        // the eye.
        let lattice: Vec<u32> = lattice_order(walks).collect();
        let view_walks = if walked.iter().any(|w| w.to_eye.is_some()) {
            params.view_walks
        } else {
            0
        };
        let phase_count = if view_walks > 0 {
            phase_walks(params, vol.optics.g)
        } else {
            0
        };
        let total_rounds = walks.max(view_walks);
        let mut rounds = 0;
        while rounds < total_rounds {
            if cancel.load(Ordering::Relaxed) {
                return None;
            }
            let lattice_point = lattice.get(rounds as usize).copied();
            let towards_eye = rounds < view_walks;
            let phase_turned = rounds < phase_count;
            walked.par_iter_mut().zip(&lights).for_each_init(
                || (vec![Vec3::ZERO; slots], vec![Vec3::ZERO; slots]),
                |(per_walk, unscattered), (state, light)| {
                    // A cancelled build stops within a light's walk,
                    // not a round (the previewer cancels on every
                    // edit): the round's check below returns.
                    if cancel.load(Ordering::Relaxed) {
                        return;
                    }
                    let x = light.position;
                    if let Some(w) = lattice_point {
                        let n = lattice_direction(w, walks, state.rotation, state.phi0);
                        walk_direction(
                            &walker,
                            (x, n, light.weight),
                            order,
                            state,
                            per_walk,
                            unscattered,
                        );
                    }
                    if let Some(n) = state.to_eye.filter(|_| towards_eye) {
                        let v = walker.accumulate_collided(x, n, &mut state.eye_rng);
                        state.view += v;
                        state.view_sq += v * v;
                    }
                    if let Some(n) = state.to_eye.filter(|_| phase_turned) {
                        let v = phase_walk(&walker, x, n, &mut state.eye_rng);
                        state.phase += v;
                        state.phase_sq += v * v;
                    }
                },
            );
            if cancel.load(Ordering::Relaxed) {
                return None;
            }
            rounds += 1;
            if params.walk_deadline.is_some_and(|d| Instant::now() >= d) {
                break;
            }
        }
        // Each of the `r` walks done weighs `4π/r` (the sums hold them
        // unweighted); the walks towards the eye are taken per unit chance
        // of a collision (they share `x` and `n`, so the chance divides
        // their sum once).
        let lattice_done = rounds.min(walks);
        let view_done = rounds.min(view_walks);
        let phase_done = rounds.min(phase_count);
        let w_dir = 4.0 * std::f32::consts::PI / lattice_done as f32;
        walked
            .par_iter_mut()
            .zip(&lights)
            .for_each(|(state, light)| {
                let sums = state.f.iter_mut().chain(&mut state.multi);
                let sums = sums.chain(&mut state.scattered);
                sums.chain(state.energy.iter_mut().skip(1))
                    .for_each(|v| *v *= w_dir);
                if phase_done > 0 {
                    state.phase_sq = standard_error(state.phase, state.phase_sq, phase_done);
                    state.phase /= phase_done as f32;
                }
                if let Some(n) = state.to_eye.filter(|_| state.view != Vec3::ZERO) {
                    let x = light.position;
                    let chance = collision_probability(vol, params.s_star, x, -n);
                    state.view_sq = standard_error(state.view, state.view_sq, view_done) / chance;
                    state.view /= view_done as f32 * chance;
                } else {
                    state.view_sq = Vec3::ZERO;
                }
            });
        if cancel.load(Ordering::Relaxed) {
            return None;
        }
        let mut sources = LightSources::with_capacity(lights, count, n_ext, slots);
        sources.kernel_radius = Some(kernel_radius);
        let view_se: Vec<Vec3> = if params.view_walks > 0 {
            walked.iter().map(|w| w.view_sq).collect()
        } else {
            Vec::new()
        };
        let phase_se: Vec<Vec3> = if phase_count > 0 {
            walked.iter().map(|w| w.phase_sq).collect()
        } else {
            Vec::new()
        };
        for w in walked {
            if params.view_walks > 0 {
                sources.view.push(w.view);
            }
            if phase_count > 0 {
                sources.phase_view.push(w.phase);
            }
            sources.push(w.f, w.multi, w.scattered, w.arrival, w.energy);
        }
        sources.view_from_harmonics_outside(order, params.eye, vol.optics.g, &reached);
        let t_walk = start.elapsed().as_secs_f64();

        let mut out = Self::assemble(vol, external, params, sources, density_integral);
        out.timings.walks = t_walk;
        out.walked = lattice_done;
        out.walk_share = f64::from(rounds.min(total_rounds)) / f64::from(total_rounds.max(1));
        out.view_se = view_se;
        out.phase_se = phase_se;
        Some(out)
    }

    /// Builds the kernel radius and the spatial indices around lights whose
    /// sources are known (see [`LightSources`]). [`InternalLights::build`]
    /// calls this after the walks, the GPU walks after theirs; tests call
    /// it with sources of their own.
    pub fn assemble<D: DensityField>(
        vol: &Volume<D>,
        external: &Lights,
        params: &InternalParams,
        sources: LightSources,
        density_integral: f32,
    ) -> Self {
        let LightSources {
            lights,
            f_coeffs,
            multi_coeffs,
            scattered_coeffs,
            arrival,
            term_energy,
            view,
            phase_view,
            kernel_radius,
        } = sources;
        let start = Instant::now();
        let order = params.sh_order.min(MAX_ORDER);
        let count = sh_count(order);
        let scatter = vol.optics.albedo * vol.optics.sigma_t;
        let kernel_radius =
            kernel_radius.unwrap_or_else(|| kernel_radius_for(vol, params, &lights));
        let sigma_grey = vol.optics.sigma_t.max_element();
        let recon_scale: Vec<f32> = lights
            .iter()
            .map(|l| match params.clock {
                Clock::Geometric => 1.0,
                Clock::OpticalDepth => {
                    let c = sigma_grey * l.density;
                    if c > 0.0 {
                        1.0 / c
                    } else {
                        0.0
                    }
                }
            })
            .collect();
        let positions: Vec<Vec3> = lights.iter().map(|l| l.position).collect();
        let fine = LightGrid::build(
            &positions,
            |i| recon_scale[i] > 0.0,
            vol.bounds,
            kernel_radius,
            96,
        );
        let fine_points: Vec<[f32; 4]> = fine
            .ids()
            .iter()
            .map(|&i| {
                let p = positions[i as usize];
                [p.x, p.y, p.z, recon_scale[i as usize]]
            })
            .collect();
        let by_slot = |coeffs: &[Vec3]| -> Vec<Vec3> {
            fine.ids()
                .iter()
                .flat_map(|&i| {
                    let i = i as usize;
                    coeffs[i * count..(i + 1) * count].iter().copied()
                })
                .collect()
        };
        let view = if view.len() == lights.len() {
            view
        } else {
            Vec::new()
        };
        let fine_view: Vec<Vec3> = if view.is_empty() {
            Vec::new()
        } else {
            fine.ids().iter().map(|&i| view[i as usize]).collect()
        };
        let phase_view = if phase_view.len() == lights.len() {
            phase_view
        } else {
            Vec::new()
        };
        let fine_phase_view: Vec<Vec3> = if phase_view.is_empty() {
            Vec::new()
        } else {
            fine.ids().iter().map(|&i| phase_view[i as usize]).collect()
        };
        let fine_multi = by_slot(&multi_coeffs);
        let fine_scattered = by_slot(&scattered_coeffs);
        let sky = sky_arrival(vol, external, params, &lights, order);
        let mut term_energy = term_energy;
        if !sky.is_empty() {
            // k = 0 from the sky: ∫ S₁ dn = b ∫ L T dω, the harmonics'
            // constant term over Y₀₀.
            if let Some(e0) = term_energy.first_mut() {
                for (i, light) in lights.iter().enumerate() {
                    *e0 += light.weight * light.density * scatter * (sky[i * count] / Y00);
                }
            }
        }
        let mut out = Self {
            params: *params,
            s_star: params.s_star,
            kernel_radius,
            softening: kernel_radius * L1_SOFTENING,
            lights,
            term_energy,
            density_integral,
            timings: BuildTimings::default(),
            cut_short_walks: 0,
            walked: params.walks.max(1),
            walk_share: 1.0,
            sh_order: order,
            sh_count: count,
            f_coeffs,
            multi_coeffs,
            scattered_coeffs,
            arrival,
            sky,
            external: external.clone(),
            scatter,
            g: vol.optics.g,
            recon_scale,
            fine,
            fine_points,
            view,
            fine_view,
            phase_view,
            fine_phase_view,
            view_se: Vec::new(),
            phase_se: Vec::new(),
            fine_multi,
            fine_scattered,
            clusters: LightGrid::build(&[], |_| false, vol.bounds, 1.0, 1),
            cluster_power: Vec::new(),
            light_power: Vec::new(),
            live_clusters: Vec::new(),
            sigma_grey,
        };
        out.build_clusters(vol.bounds, &positions);
        out.timings.index = start.elapsed().as_secs_f64();
        out
    }

    /// The cluster grid and the power tables of the light selection.
    fn build_clusters(&mut self, bounds: (Vec3, Vec3), positions: &[Vec3]) {
        let power: Vec<f32> = (0..self.lights.len())
            .map(|i| {
                let j = self.mean_j(i);
                self.lights[i].weight * (j.x + j.y + j.z)
            })
            .collect();
        let (lo, hi) = bounds;
        let size = hi - lo;
        let volume = (size.x * size.y * size.z).max(1e-30);
        let clusters_wanted = (self.lights.len() as f32 / LIGHTS_PER_CLUSTER).max(1.0);
        let cell = (volume / clusters_wanted).cbrt();
        let clusters = LightGrid::build(
            positions,
            |i| power[i] > 0.0 && power[i].is_finite(),
            bounds,
            cell,
            MAX_CLUSTER_RES,
        );
        let mut cluster_power = vec![0.0f32; clusters.cell_count()];
        let light_power: Vec<f32> = clusters.ids().iter().map(|&i| power[i as usize]).collect();
        let mut live = Vec::new();
        for (c, p) in cluster_power.iter_mut().enumerate() {
            *p = light_power[clusters.cell_range(c)].iter().sum();
            if *p > 0.0 {
                live.push(c as u32);
            }
        }
        self.clusters = clusters;
        self.cluster_power = cluster_power;
        self.light_power = light_power;
        self.live_clusters = live;
    }

    /// Number of lights.
    pub fn len(&self) -> usize {
        self.lights.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.lights.is_empty()
    }

    /// The SH order of `F` and of `J`'s multiply scattered part.
    pub fn sh_order(&self) -> u32 {
        self.sh_order
    }

    /// `S₁(x_i, n)`: the single-scatter source at light `i` towards `n`
    /// (the direction light travels after scattering), exact in angle.
    pub fn eval_s1(&self, i: usize, n: Vec3) -> Vec3 {
        let light = &self.lights[i];
        let n_ext = self.arrival.len() / self.lights.len().max(1);
        let arrival = &self.arrival[i * n_ext..(i + 1) * n_ext];
        let mut sum = Vec3::ZERO;
        let mut l = 0;
        self.external.for_each_at(light.position, |s| {
            sum += arrival[l] * phase::hg(self.g, s.travel.dot(n));
            l += 1;
        });
        if !self.sky.is_empty() {
            // Funk–Hecke: the phase function scales the sky's band `l`
            // by `g^l`; the basis is scaled so, and the sky's series
            // evaluated like the lights' own.
            let mut y = [0.0f32; MAX_COUNT];
            sh_basis(self.sh_order, n, &mut y);
            let mut g_l = 1.0;
            for l in 1..=self.sh_order as usize {
                g_l *= self.g;
                for yk in &mut y[l * l..(l + 1) * (l + 1)] {
                    *yk *= g_l;
                }
            }
            let c = &self.sky[i * self.sh_count..(i + 1) * self.sh_count];
            sum += Self::eval_sh(c, &y).max(Vec3::ZERO);
        }
        sum * self.scatter * light.density
    }

    pub(super) fn eval_sh(coeffs: &[Vec3], y: &[f32]) -> Vec3 {
        coeffs
            .iter()
            .zip(y)
            .fold(Vec3::ZERO, |acc, (&c, &yi)| acc + c * yi)
    }

    /// `F_i(n) = J_1(x_i, n)`, the note's internal light source, from its
    /// SH coefficients (clamped at zero).
    pub fn eval_f(&self, i: usize, n: Vec3) -> Vec3 {
        let mut y = [0.0f32; MAX_COUNT];
        sh_basis(self.sh_order, n, &mut y);
        let c = &self.f_coeffs[i * self.sh_count..(i + 1) * self.sh_count];
        Self::eval_sh(c, &y).max(Vec3::ZERO)
    }

    /// `Σ_{k≥1} J_k(x_i, n)` from its SH coefficients, with the basis
    /// `y` of `n` already evaluated (clamped at zero).
    #[inline]
    pub(crate) fn eval_multi_with(&self, i: usize, y: &[f32]) -> Vec3 {
        let c = &self.multi_coeffs[i * self.sh_count..(i + 1) * self.sh_count];
        Self::eval_sh(c, y).max(Vec3::ZERO)
    }

    /// What of `Σ_{k≥1} J_k(x_i, n)` the walks carried through a collision
    /// (the part `L₀` reconstructs), per unit chance of the collision
    /// ([`Part::Scattered`]), with the basis `y` of `n` already evaluated
    /// (clamped at zero).
    #[inline]
    pub(crate) fn eval_scattered_with(&self, i: usize, y: &[f32]) -> Vec3 {
        let c = &self.scattered_coeffs[i * self.sh_count..(i + 1) * self.sh_count];
        Self::eval_sh(c, y).max(Vec3::ZERO)
    }

    /// `J_i(n) = S₁(x_i, n) + Σ_{k≥1} J_k(x_i, n)`.
    pub fn eval_j(&self, i: usize, n: Vec3) -> Vec3 {
        let mut y = [0.0f32; MAX_COUNT];
        sh_basis(self.sh_order, n, &mut y);
        self.eval_s1(i, n) + self.eval_multi_with(i, &y)
    }

    /// Light `i`'s SH coefficients of `F_i` (`(sh_order + 1)²` of them).
    pub fn f_coefficients(&self, i: usize) -> &[Vec3] {
        &self.f_coeffs[i * self.sh_count..(i + 1) * self.sh_count]
    }

    /// Light `i`'s SH coefficients of the multiply scattered part
    /// `Σ_{k≥1} J_k` of `J_i`.
    pub fn multi_coefficients(&self, i: usize) -> &[Vec3] {
        &self.multi_coeffs[i * self.sh_count..(i + 1) * self.sh_count]
    }

    /// Light `i`'s SH coefficients of the part of `Σ_{k≥1} J_k` that the
    /// walks carried through at least one collision, per unit chance of the
    /// collision ([`Part::Scattered`]).
    pub fn scattered_coefficients(&self, i: usize) -> &[Vec3] {
        &self.scattered_coeffs[i * self.sh_count..(i + 1) * self.sh_count]
    }

    /// The light arriving at light `i` from each external light (suns
    /// first), `T E`.
    pub fn arrival(&self, i: usize) -> &[Vec3] {
        let n_ext = self.arrival.len() / self.lights.len().max(1);
        &self.arrival[i * n_ext..(i + 1) * n_ext]
    }

    /// The mean of `F_i` over directions, `∫F_i dn / 4π`.
    pub fn mean_f(&self, i: usize) -> Vec3 {
        self.f_coeffs[i * self.sh_count] * Y00
    }

    /// A copy of the set whose walks towards the eye and phase walks
    /// (the per-light values `L₀` and `L₁` read, method §5.4) are replaced
    /// by `sign` times each light's standard error, itself turned by a
    /// random sign per light (from `draw`); everything else (positions,
    /// harmonics, arrivals) is the set's. The gather is linear in those
    /// values (the reconstruction is not clamped), so a pass with
    /// `sign` 1 minus the same pass (the same pixel streams) with `sign`
    /// −1, halved, is the image of random errors of the lights' values
    /// with their walks' variances: its mean square is the walks' share
    /// of the set's noise, measured from the set alone (`lantern noise`;
    /// validation §3.29). `None` where the set holds no standard errors
    /// (no view walks, or walked on the GPU).
    pub fn walk_error_lights(&self, draw: u32, sign: f32) -> Option<InternalLights> {
        if self.view_se.is_empty() || self.view_se.len() != self.view.len() {
            return None;
        }
        // Independent signs for the two kinds of walks, which are
        // independent of each other.
        let turned = |se: &[Vec3], kind: u32| -> Vec<Vec3> {
            let draw = pcg_hash(draw.wrapping_mul(2).wrapping_add(kind));
            se.iter()
                .enumerate()
                .map(|(i, &e)| {
                    let h = pcg_hash(draw ^ pcg_hash(i as u32));
                    e * if h & 1 == 0 { sign } else { -sign }
                })
                .collect()
        };
        // The fine grid's copies, in its slot order.
        let by_slot = |values: &[Vec3]| -> Vec<Vec3> {
            let ids = self.fine.ids().iter();
            ids.map(|&i| values[i as usize]).collect()
        };
        let mut out = self.clone();
        out.view = turned(&self.view_se, 0);
        out.fine_view = by_slot(&out.view);
        if !self.phase_view.is_empty() && self.phase_se.len() == self.phase_view.len() {
            out.phase_view = turned(&self.phase_se, 1);
            out.fine_phase_view = by_slot(&out.phase_view);
        }
        Some(out)
    }

    /// The mean of `J_i` over directions, `∫J_i dn / 4π`.
    pub fn mean_j(&self, i: usize) -> Vec3 {
        let n_ext = self.arrival.len() / self.lights.len().max(1);
        let sky = if self.sky.is_empty() {
            Vec3::ZERO
        } else {
            self.sky[i * self.sh_count] / Y00
        };
        let s1: Vec3 = (self.arrival[i * n_ext..(i + 1) * n_ext]
            .iter()
            .sum::<Vec3>()
            + sky)
            * self.scatter
            * self.lights[i].density
            / (4.0 * std::f32::consts::PI);
        s1 + self.multi_coeffs[i * self.sh_count] * Y00
    }
}

/// `π (3 − √5)`, the golden angle of the spherical Fibonacci lattice.
pub const GOLDEN_ANGLE: f32 = 2.399_963;

/// One light's sums over its walks while [`InternalLights::build_at`]
/// walks them in rounds, and its random stream between rounds.
struct Walked {
    rng: Rng,
    /// The stream of the walks towards the eye and the phase walks
    /// ([`EYE_WALK_STREAM`]).
    eye_rng: Rng,
    /// The lattice's random rotation and azimuth offset.
    rotation: glam::Quat,
    phi0: f32,
    /// The direction towards the eye, for a light within the camera's
    /// reach ([`within_view_reach`]), which walks that way.
    to_eye: Option<Vec3>,
    /// The walks towards the eye: their collided part, summed.
    view: Vec3,
    /// The phase walks ([`phase_walks`]): all of `Σ_{k≥1} J_k`, summed.
    phase: Vec3,
    /// The squares of the walks towards the eye and of the phase walks,
    /// summed; once the walks are done, the standard errors of `view` and
    /// `phase`.
    view_sq: Vec3,
    phase_sq: Vec3,
    /// `F`, `Σ J_k` and its collided part by direction (spherical
    /// harmonics) and the terms' energies `k ≥ 1`: sums over the walks,
    /// unweighted until the walks are done. `energy[0]` is the `k = 0`
    /// term, exact.
    f: Vec<Vec3>,
    multi: Vec<Vec3>,
    scattered: Vec<Vec3>,
    arrival: Vec<Vec3>,
    energy: Vec<Vec3>,
}

/// The standard error of the mean of `n` values from their sum and the
/// sum of their squares (per channel; zero for fewer than two values).
fn standard_error(sum: Vec3, sum_sq: Vec3, n: u32) -> Vec3 {
    if n < 2 {
        return Vec3::ZERO;
    }
    let n = n as f32;
    let mean = sum / n;
    let variance = ((sum_sq / n - mean * mean) * (n / (n - 1.0))).max(Vec3::ZERO);
    (variance / n).powf(0.5)
}

/// Point `w` of a spherical Fibonacci lattice of `walks` directions under
/// `rotation`, its azimuths offset by `phi0`.
fn lattice_direction(w: u32, walks: u32, rotation: glam::Quat, phi0: f32) -> Vec3 {
    let z = 1.0 - (2 * w + 1) as f32 / walks as f32;
    let phi = phi0 + w as f32 * GOLDEN_ANGLE;
    let s = (1.0 - z * z).max(0.0).sqrt();
    rotation * Vec3::new(s * phi.cos(), s * phi.sin(), z)
}

/// One phase walk from `x` ([`phase_walks`]): the direction towards the
/// eye `n` turned by one draw of the phase function, and all of
/// `Σ_{k≥1} J_k` there ([`Walks::accumulate_sum`]).
fn phase_walk<D: DensityField>(walker: &Walks<'_, D>, x: Vec3, n: Vec3, rng: &mut Rng) -> Vec3 {
    let turned =
        crate::physics::phase::sample_hg(walker.vol.optics.g, n, rng.next_f32(), rng.next_f32());
    walker.accumulate_sum(x, turned, rng)
}

/// Walks from `x` (its volume weight `weight`) in direction `n` and adds
/// the walk to the light's sums, unweighted: `F` (term 1), `Σ J_k` and its
/// collided part projected on the harmonics of `order`, and the terms'
/// energies (`per_walk` and `unscattered` are scratch, one slot per term).
fn walk_direction<D: DensityField>(
    walker: &Walks<'_, D>,
    (x, n, weight): (Vec3, Vec3, f32),
    order: u32,
    state: &mut Walked,
    per_walk: &mut [Vec3],
    unscattered: &mut [Vec3],
) {
    per_walk.iter_mut().for_each(|v| *v = Vec3::ZERO);
    unscattered.iter_mut().for_each(|v| *v = Vec3::ZERO);
    walker.accumulate_j_from(x, n, 1, &mut state.rng, per_walk, Some(unscattered));
    let total: Vec3 = per_walk[1..].iter().sum();
    if total == Vec3::ZERO {
        return;
    }
    let s_star = walker.gates.s_star;
    let after_collision = collided_per_unit_chance(walker.vol, s_star, x, n, per_walk, unscattered);
    let first = per_walk.get(1).copied().unwrap_or(Vec3::ZERO);
    let mut y = [0.0f32; MAX_COUNT];
    sh_basis(order, n, &mut y);
    let sums = state
        .multi
        .iter_mut()
        .zip(&mut state.scattered)
        .zip(&mut state.f);
    for (((multi, scattered), f), &yc) in sums.zip(&y) {
        *multi += total * yc;
        *scattered += after_collision * yc;
        *f += first * yc;
    }
    for (e, v) in state.energy.iter_mut().zip(per_walk.iter()).skip(1) {
        *e += *v * weight;
    }
}

/// The order in which a light's `walks` lattice points are walked, one
/// per round: the bit-reversed (van der Corput) order of their indices,
/// so that the first `r` of them spread over the lattice's rows (for 16:
/// 0, 8, 4, 12, 2, …) and a build stopped early still covers the sphere.
/// Every index below `walks` once.
pub fn lattice_order(walks: u32) -> impl Iterator<Item = u32> {
    let bits = walks.max(1).next_power_of_two().trailing_zeros();
    (0..1u32 << bits)
        .map(move |i| {
            if bits == 0 {
                0
            } else {
                i.reverse_bits() >> (32 - bits)
            }
        })
        .filter(move |&w| w < walks.max(1))
}

/// A uniformly random rotation (Shoemake's uniform unit quaternion).
fn random_rotation(rng: &mut Rng) -> glam::Quat {
    let (u1, u2, u3) = (rng.next_f32(), rng.next_f32(), rng.next_f32());
    let (a, b) = ((1.0 - u1).sqrt(), u1.sqrt());
    let tau = 2.0 * std::f32::consts::PI;
    glam::Quat::from_xyzw(
        a * (tau * u2).sin(),
        a * (tau * u2).cos(),
        b * (tau * u3).sin(),
        b * (tau * u3).cos(),
    )
    .normalize()
}

/// `Y₀₀ = 1 / (2√π)`.
const Y00: f32 = 0.282_094_8;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::testing::*;

    /// The view and phase walks' test scene: a sunlit cube (`σ_t` 1.5,
    /// albedo 0.9, asymmetry `g`, the sun from the camera's side) seen from
    /// `eye`, with 1024 lights placed by density, `walks` spread walks and
    /// 1024 walks towards the eye each, order-4 harmonics.
    fn sunlit_cube_seen(g: f32, walks: u32) -> (Volume<Cube>, Lights, Vec3, InternalParams) {
        let vol = cube(1.5, 0.9, g);
        let sun = one_sun(Vec3::new(0.3, -0.2, -1.0), Vec3::new(1.0, 2.0, 3.0));
        let eye = Vec3::new(0.4, 0.3, 4.0);
        let params = InternalParams {
            lights: 1024,
            walks,
            sh_order: 4,
            kernel_radius: None,
            view_walks: 1024,
            eye,
            view_share: 0.0,
            view_frame: Default::default(),
            ..sh1_params(Clock::OpticalDepth, 0.5, 24, 0.3, L1Form::Field)
        };
        (vol, sun, eye, params)
    }

    /// Each light's standard error of its walks towards the eye and of its
    /// phase walks is the spread its value has over independent walks:
    /// 48 builds of the same 512 lights of a sunlit cube (`g` 0.85, so
    /// phase walks run too), each with walk streams of its own; over the
    /// lights, the mean squared standard error against the mean variance
    /// of the values across the builds, within 7 % (each light's
    /// across-build variance is known to a fifth, their mean over the
    /// lights to a few percent; a standard error of the walks' spread
    /// rather than of their mean, or without the chance of a collision,
    /// misses by a factor; without the `n/(n − 1)` of 12 walks, by 9 %). And
    /// `walk_error_lights` puts exactly `±` those errors in the values'
    /// place, the two signs opposite, the signs of a draw split about
    /// evenly and independent between the two kinds of walks.
    #[test]
    fn walk_errors_are_the_spread_of_the_lights_values() {
        use std::sync::atomic::AtomicBool;
        let (vol, sun, _eye, base) = sunlit_cube_seen(0.85, 4);
        let params = InternalParams {
            lights: 512,
            view_walks: 12,
            ..base
        };
        let density = placement_density(&vol, params.uniform_mix);
        let (lights, integral) = place_internal_lights(&vol, &params, &density);
        let never = AtomicBool::new(false);
        let builds: Vec<InternalLights> = (0..48u64)
            .map(|b| {
                let params = InternalParams {
                    seed: 1000 + b,
                    ..params
                };
                InternalLights::build_at(&vol, &sun, &params, lights.clone(), integral, &never)
                    .expect("not cancelled")
            })
            .collect();
        let n = builds.len() as f64;
        for kind in ["view", "phase"] {
            let values = |l: &InternalLights| match kind {
                "view" => (l.view.clone(), l.view_se.clone()),
                _ => (l.phase_view.clone(), l.phase_se.clone()),
            };
            let (first, first_se) = values(&builds[0]);
            assert_eq!(first_se.len(), first.len(), "{kind}: one error per light");
            let (mut spread, mut se2, mut walked) = (0.0f64, 0.0f64, 0usize);
            for i in 0..first.len() {
                let v: Vec<f64> = builds
                    .iter()
                    .map(|l| f64::from(values(l).0[i].element_sum()))
                    .collect();
                let e: Vec<f64> = builds
                    .iter()
                    .map(|l| f64::from(values(l).1[i].element_sum()))
                    .collect();
                if e.iter().all(|&e| e == 0.0) {
                    continue; // out of the camera's reach: no walks
                }
                walked += 1;
                let mean = v.iter().sum::<f64>() / n;
                spread += v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
                se2 += e.iter().map(|e| e * e).sum::<f64>() / n;
            }
            eprintln!("{kind}: {walked} lights, spread {spread:.5}, errors² {se2:.5}");
            assert!(walked > 128, "{kind}: only {walked} lights walked");
            let ratio = se2 / spread;
            assert!(
                (0.93..1.07).contains(&ratio),
                "{kind}: errors² / spread {ratio:.3} ({se2} against {spread})"
            );
        }
        let set = &builds[0];
        let plus = set.walk_error_lights(3, 1.0).expect("errors kept");
        let minus = set.walk_error_lights(3, -1.0).expect("errors kept");
        let mut positive = 0usize;
        for i in 0..set.view.len() {
            assert_eq!(plus.view[i], -minus.view[i]);
            assert_eq!(plus.view[i].abs(), set.view_se[i]);
            assert_eq!(plus.phase_view[i].abs(), set.phase_se[i]);
            let up = |v: Vec3| v.element_sum() > 0.0;
            positive += usize::from(up(plus.view[i]));
        }
        let walked = set.view_se.iter().filter(|e| e.element_sum() > 0.0).count();
        assert!(
            positive.abs_diff(walked / 2) < walked / 5,
            "{positive} of {walked} positive"
        );
        let both = (0..set.view.len())
            .filter(|&i| set.view_se[i].element_sum() > 0.0 && set.phase_se[i].element_sum() > 0.0)
            .count();
        let same = (0..set.view.len())
            .filter(|&i| set.view_se[i].element_sum() > 0.0 && set.phase_se[i].element_sum() > 0.0)
            .filter(|&i| {
                (plus.view[i].element_sum() > 0.0) == (plus.phase_view[i].element_sum() > 0.0)
            })
            .count();
        assert!(
            same.abs_diff(both / 2) < both / 5,
            "{same} of {both} lights with the same sign for both kinds"
        );
        // The fine grid's copies follow the values.
        for (slot, &i) in plus.fine.ids().iter().enumerate() {
            assert_eq!(plus.fine_view[slot], plus.view[i as usize]);
            assert_eq!(plus.fine_phase_view[slot], plus.phase_view[i as usize]);
        }
    }

    /// The walks towards the eye estimate what the lights' harmonics hold
    /// in that direction: over 1024 lights of a sunlit cube (`g` 0, so the
    /// order-4 series represents `J` closely), the mean of the view walks'
    /// collided part per unit chance matches the mean of the `Part::Scattered`
    /// series evaluated towards the eye, each light's within its own walks'
    /// noise; and towards the eye differs from away from it (the sun comes
    /// from the camera's side), so walks in the wrong direction fail.
    /// `reconstruct_view` is the kernel average of those values.
    #[test]
    fn view_walks_match_the_harmonics_towards_the_eye() {
        use crate::physics::sh::sh_basis;
        use std::sync::atomic::AtomicBool;
        let (vol, sun, eye, params) = sunlit_cube_seen(0.0, 1024);
        let cache = InternalLights::build(&vol, &sun, &params, &AtomicBool::new(false))
            .expect("not cancelled");
        assert!(cache.has_view());
        let count = sh_count(4);
        let mut y = vec![0.0f32; count];
        let (mut view, mut towards, mut away) = (0.0f64, 0.0f64, 0.0f64);
        let mut diff2 = 0.0f64;
        // Only the lights within the camera's reach walk towards the eye;
        // the others hold their harmonics' value there.
        let reached = within_view_reach(&vol, &params, cache.kernel_radius, &cache.lights);
        let mut walked = 0usize;
        for (i, &within) in reached.iter().enumerate() {
            let x = cache.lights[i].position;
            let n = (eye - x).normalize();
            let v = cache.view(i).expect("a view estimate").element_sum() as f64;
            sh_basis(4, n, &mut y);
            let t = cache.eval_scattered_with(i, &y).element_sum() as f64;
            if !within {
                // (The harmonics' value unclamped: compared clamped.)
                let v = cache
                    .view(i)
                    .expect("a view estimate")
                    .max(Vec3::ZERO)
                    .element_sum() as f64;
                assert!(
                    (v - t).abs() <= 1e-5 * t.abs().max(1e-3),
                    "light {i} out of reach: view {v}, harmonics {t}"
                );
                continue;
            }
            walked += 1;
            sh_basis(4, -n, &mut y);
            away += cache.eval_scattered_with(i, &y).element_sum() as f64;
            view += v;
            towards += t;
            diff2 += (v - t) * (v - t);
        }
        assert!(
            walked > 200 && walked < cache.len(),
            "{walked} of {} lights within reach: the test needs both kinds",
            cache.len()
        );
        let m = walked as f64;
        let (view, towards, away) = (view / m, towards / m, away / m);
        let se = (diff2 / m - (view - towards).powi(2)).max(0.0).sqrt() / m.sqrt();
        eprintln!("view walks {view:.5}, harmonics towards the eye {towards:.5} (se {se:.5}), away {away:.5}");
        assert!(
            (view - towards).abs() < 4.0 * se && (view - towards).abs() < 0.05 * towards,
            "view walks {view:.5}, harmonics towards the eye {towards:.5} (se {se:.5})"
        );
        assert!(
            (away - towards).abs() > 0.2 * towards,
            "towards the eye {towards:.5} and away {away:.5} hardly differ: the test cannot tell"
        );
        // The reconstruction is the normalised kernel average of the views.
        let view = |i: usize| cache.view(i).expect("a view estimate");
        assert_kernel_average(&cache, view, |p| cache.reconstruct_view(p, 1.0));
    }

    /// `reconstruct(p)` at a point of the test cube (`σ_t` 1.5, density 1)
    /// is the normalised kernel average of each light's `value`, scaled as
    /// the optical-depth clock's reconstruction scales it.
    fn assert_kernel_average(
        cache: &InternalLights,
        value: impl Fn(usize) -> Vec3,
        reconstruct: impl Fn(Vec3) -> Vec3,
    ) {
        let p = Vec3::new(0.1, -0.2, 0.3);
        let (mut num, mut den) = (Vec3::ZERO, 0.0f32);
        cache.for_each_kernel_weight(p, |i, k| {
            let scale = 1.0 / (1.5 * cache.lights[i].density);
            num += value(i) * (k * scale);
            den += k;
        });
        let want = num / den * 1.5;
        let got = reconstruct(p);
        assert!(
            (got - want).abs().max_element() <= 1e-4 * want.max_element(),
            "reconstruction {got}, kernel average {want}"
        );
    }

    /// Where phase walks serve `L₁` the spread walks give three quarters
    /// of their time to walks towards the eye; elsewhere, or without view
    /// walks, the split is as asked.
    #[test]
    fn walks_move_towards_the_eye_only_where_phase_walks_serve() {
        assert_eq!(walk_split(16, 16, 0.85), (4, 24));
        assert_eq!(walk_split(16, 16, -0.8), (4, 24));
        assert_eq!(walk_split(8, 8, 0.9), (2, 12));
        assert_eq!(walk_split(1, 16, 0.9), (1, 16));
        assert_eq!(walk_split(3, 16, 0.9), (1, 17));
        assert_eq!(walk_split(16, 16, 0.5), (16, 16));
        assert_eq!(walk_split(16, 0, 0.85), (16, 0));
        let max = crate::scene::settings::MAX_WALKS;
        assert_eq!(walk_split(max, max, 0.85), (max / 4, max));
        // The phase walks follow the view walks.
        let (walks, view_walks) = walk_split(16, 16, 0.85);
        let params = InternalParams {
            walks,
            view_walks,
            ..sh1_params(Clock::OpticalDepth, 0.5, 24, 0.3, L1Form::Field)
        };
        assert_eq!(phase_walks(&params, 0.85), 6);
    }

    /// In a medium peaked enough for phase walks, their mean at each light
    /// is the source one more scattering sends towards the eye,
    /// `∫ P(n·n') J(x, n') dn'`: here against the same integral sampled
    /// the other way, walks in uniform directions weighted `4π P(n·n')`,
    /// at 64 of the lights within the camera's reach. Lights out of reach
    /// hold their harmonics of `Σ J_k` with band `l` times `g^l` (the
    /// convolution with the phase function) towards the eye.
    #[test]
    fn phase_walks_estimate_the_phase_weighted_source_towards_the_eye() {
        use crate::physics::sh::sh_basis;
        use std::sync::atomic::AtomicBool;
        let g = 0.75;
        let (vol, sun, eye, params) = sunlit_cube_seen(g, 64);
        assert_eq!(phase_walks(&params, g), 256);
        assert_eq!(phase_walks(&params, -g), 256);
        assert_eq!(phase_walks(&params, 0.7), 0);
        let cache = InternalLights::build(&vol, &sun, &params, &AtomicBool::new(false))
            .expect("not cancelled");
        assert!(cache.has_phase_view());
        let count = sh_count(4);
        let mut y = vec![0.0f32; count];
        let reached = within_view_reach(&vol, &params, cache.kernel_radius, &cache.lights);
        let walker = Walks::guided(
            &vol,
            &sun,
            GateSettings {
                s_star: params.s_star,
                n_terms: params.terms,
                clock: params.clock,
                rr_start: RR_START_DEPTH,
            },
        );
        let mut per_walk = vec![Vec3::ZERO; walker.gates.term_slots()];
        let mut rng = Rng::for_sample(77, 0, 0);
        let (mut compared, mut phase, mut uniform, mut diff2) = (0usize, 0.0f64, 0.0f64, 0.0f64);
        for (i, &within) in reached.iter().enumerate() {
            let x = cache.lights[i].position;
            let n = (eye - x).normalize();
            let v = cache.phase_view[i].element_sum() as f64;
            if !within {
                sh_basis(4, n, &mut y);
                hg_convolve_basis(&mut y, g);
                let t = InternalLights::eval_sh(cache.multi_coefficients(i), &y).element_sum();
                assert!(
                    (v as f32 - t).abs() <= 1e-5 * t.abs().max(1e-3),
                    "light {i} out of reach: {v}, harmonics {t}"
                );
                continue;
            }
            if compared == 64 {
                continue;
            }
            compared += 1;
            let walks = 1024;
            let mut sum = 0.0f64;
            for _ in 0..walks {
                let w = uniform_direction(&mut rng);
                per_walk.iter_mut().for_each(|v| *v = Vec3::ZERO);
                walker.accumulate_j_from(x, w, 1, &mut rng, &mut per_walk, None);
                let weight = 4.0 * std::f32::consts::PI * crate::physics::phase::hg(g, n.dot(w));
                sum += (per_walk[1..].iter().sum::<Vec3>() * weight).element_sum() as f64;
            }
            let t = sum / walks as f64;
            phase += v;
            uniform += t;
            diff2 += (v - t) * (v - t);
        }
        assert_eq!(compared, 64, "too few lights within reach");
        let m = compared as f64;
        let (phase, uniform) = (phase / m, uniform / m);
        let se = (diff2 / m - (phase - uniform).powi(2)).max(0.0).sqrt() / m.sqrt();
        eprintln!("phase walks {phase:.5}, uniform walks weighted by the phase function {uniform:.5} (se {se:.5})");
        assert!(
            (phase - uniform).abs() < 4.5 * se && (phase - uniform).abs() < 0.05 * uniform,
            "phase walks {phase:.5}, uniform walks weighted by the phase function {uniform:.5} (se {se:.5})"
        );
        // The reconstruction is the normalised kernel average of the values.
        assert_kernel_average(
            &cache,
            |i| cache.phase_view[i],
            |p| cache.reconstruct_phase_view(p, 1.0),
        );
    }

    /// The lattice's order visits every point once and spreads its
    /// prefixes: for 16, the first two rows are the top and the middle,
    /// the first four every fourth row.
    #[test]
    fn the_lattice_order_visits_every_point_once() {
        for walks in [1u32, 2, 3, 7, 16, 17, 64] {
            let mut order: Vec<u32> = lattice_order(walks).collect();
            assert_eq!(order.len(), walks as usize, "{walks} walks");
            order.sort_unstable();
            assert!(
                order.iter().copied().eq(0..walks),
                "{walks} walks: {order:?}"
            );
        }
        let first: Vec<u32> = lattice_order(16).take(4).collect();
        assert_eq!(first, [0, 8, 4, 12]);
    }

    /// A build whose walks stop at their deadline after one round (one
    /// lattice point and one walk towards the eye per light) estimates
    /// what the whole build estimates: over the 2048 lights of a sunlit
    /// cube (`g` 0.5), the mean of the lights' `Σ J_k` (its harmonics'
    /// constant term), of their `F` and of their views towards the eye
    /// agree with the full build's (16 walks each) within 4.5 standard
    /// errors, and the terms' energies within 5 %. Sums left unscaled
    /// (1/16 of the full build's) would fail every one.
    #[test]
    fn a_build_stopped_at_its_deadline_keeps_the_mean() {
        use std::sync::atomic::AtomicBool;
        let vol = cube(2.0, 0.95, 0.5);
        let sun = one_sun(Vec3::new(0.3, -0.5, -1.0), Vec3::ONE);
        let base = InternalParams {
            lights: 2048,
            walks: 16,
            sh_order: 2,
            kernel_radius: None,
            view_walks: 16,
            eye: Vec3::new(0.4, 0.3, 4.0),
            ..sh1_params(Clock::OpticalDepth, 0.5, 64, 0.3, L1Form::Field)
        };
        let never = AtomicBool::new(false);
        let full = InternalLights::build(&vol, &sun, &base, &never).expect("not cancelled");
        let stopped = InternalParams {
            seed: 1,
            walk_deadline: Some(Instant::now()),
            ..base
        };
        let early = InternalLights::build(&vol, &sun, &stopped, &never).expect("not cancelled");
        assert_eq!((full.walked, early.walked), (16, 1));
        let count = sh_count(2);
        // Mean and standard error over the lights of one value per light.
        let stats = |values: Vec<f64>| {
            let m = values.len() as f64;
            let mean = values.iter().sum::<f64>() / m;
            let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (m - 1.0);
            (mean, (var / m).sqrt())
        };
        let per_light =
            |c: &InternalLights, what: &dyn Fn(&InternalLights, usize) -> Option<f64>| {
                stats((0..c.len()).filter_map(|i| what(c, i)).collect())
            };
        let multi =
            |c: &InternalLights, i: usize| Some(c.multi_coeffs[i * count].element_sum() as f64);
        let first = |c: &InternalLights, i: usize| Some(c.f_coeffs[i * count].element_sum() as f64);
        let reached_full = within_view_reach(&vol, &base, full.kernel_radius, &full.lights);
        let reached_early = within_view_reach(&vol, &stopped, early.kernel_radius, &early.lights);
        let view_full = |c: &InternalLights, i: usize| {
            reached_full[i]
                .then(|| c.view(i).map(|v| v.element_sum() as f64))
                .flatten()
        };
        let view_early = |c: &InternalLights, i: usize| {
            reached_early[i]
                .then(|| c.view(i).map(|v| v.element_sum() as f64))
                .flatten()
        };
        let checks = [
            ("Σ J_k", per_light(&full, &multi), per_light(&early, &multi)),
            ("F", per_light(&full, &first), per_light(&early, &first)),
            (
                "view",
                per_light(&full, &view_full),
                per_light(&early, &view_early),
            ),
        ];
        for (what, (a, se_a), (b, se_b)) in checks {
            let z = (b - a) / (se_a * se_a + se_b * se_b).sqrt();
            eprintln!("{what}: full {a:.5} ± {se_a:.5}, one round {b:.5} ± {se_b:.5}, z {z:.2}");
            assert!(
                z.abs() < 4.5,
                "{what}: full {a:.5}, one round {b:.5}, z {z:.2}"
            );
            assert!(
                se_b < 0.1 * a.abs(),
                "{what}: too noisy to tell ({se_b} of {a})"
            );
        }
        let energy = |c: &InternalLights| c.term_energy[1..].iter().sum::<Vec3>().element_sum();
        let (a, b) = (energy(&full), energy(&early));
        assert!(
            (b / a - 1.0).abs() < 0.05,
            "terms' energy: full {a}, one round {b}"
        );
    }

    /// A cancelled build returns nothing: its walks stop at the first
    /// light that sees the flag, and the round returns.
    #[test]
    fn a_cancelled_walk_returns_nothing() {
        use std::sync::atomic::AtomicBool;
        let vol = cube(2.0, 0.95, 0.5);
        let sun = one_sun(Vec3::new(0.3, -0.5, -1.0), Vec3::ONE);
        let params = InternalParams {
            lights: 64,
            walks: 4,
            ..sh1_params(Clock::OpticalDepth, 0.5, 64, 0.3, L1Form::Field)
        };
        let density = placement_density(&vol, params.uniform_mix);
        let (lights, integral) = place_internal_lights(&vol, &params, &density);
        let cancelled = AtomicBool::new(true);
        assert!(InternalLights::build_at(
            &vol,
            &sun,
            &params,
            lights.clone(),
            integral,
            &cancelled
        )
        .is_none());
        let never = AtomicBool::new(false);
        let built = InternalLights::build_at(&vol, &sun, &params, lights, integral, &never);
        assert_eq!(built.map(|b| b.walked), Some(4));
    }

    /// A light is within the camera's reach when the clock along its own
    /// ray from the eye, from the box's entry up to `reach` short of it,
    /// stays within `s*`: in a cube of extinction 2 seen along −z, at
    /// `s*` 0.5 and reach 0.1, down to depth 0.35 for the optical-depth
    /// clock (2 (d − 0.1) ≤ 0.5) and 0.6 for the geometric one; lights
    /// the ray meets after crossing the box elsewhere count too.
    #[test]
    fn view_reach_follows_the_window_along_each_ray() {
        let vol = cube(2.0, 0.9, 0.0);
        let at = |depth: f32, x: f32| InternalLight {
            position: Vec3::new(x, 0.1, 1.0 - depth),
            density: 1.0,
            weight: 1.0,
        };
        let lights = [
            at(0.05, 0.0),
            at(0.3, 0.0),
            at(0.4, 0.0),
            at(0.55, 0.3),
            at(0.65, 0.3),
            at(1.9, -0.5),
        ];
        let eye = Vec3::new(0.0, 0.1, 6.0);
        for (clock, want) in [
            (
                Clock::OpticalDepth,
                [true, true, false, false, false, false],
            ),
            (Clock::Geometric, [true, true, true, true, false, false]),
        ] {
            let params = InternalParams {
                view_walks: 4,
                eye,
                ..sh1_params(clock, 0.5, 4, 0.1, L1Form::Field)
            };
            let got = within_view_reach(&vol, &params, 0.1, &lights);
            assert_eq!(got, want, "{clock:?}");
        }
        // Seen from the side the same deep light is near the surface.
        let params = InternalParams {
            view_walks: 4,
            eye: Vec3::new(-6.0, 0.1, 1.0 - 1.9),
            ..sh1_params(Clock::OpticalDepth, 0.5, 4, 0.1, L1Form::Field)
        };
        let side = within_view_reach(&vol, &params, 0.1, &[at(1.9, -0.9)]);
        assert_eq!(side, [true]);
    }

    /// The automatic kernel shrinks over a render's sets (45, 22, then 16
    /// neighbours), and the radius follows the neighbour count: the
    /// `k`-th neighbour's median distance for lights in the camera's
    /// windows (lights in a plane: `h ∝ √k`), the light spacing times
    /// `2.5 (k/K)^{1/3}` for lights placed by density (`K` the first
    /// set's, [`KERNEL_NEIGHBOURS`]). An explicit radius
    /// is kept whatever the set.
    #[test]
    fn the_kernel_shrinks_over_the_sets() {
        let ks: Vec<u32> = (0..6).map(kernel_neighbours_for_set).collect();
        assert_eq!(ks, [45, 22, 16, 16, 16, 16]);
        assert_eq!(kernel_neighbours_for_set(u32::MAX), KERNEL_NEIGHBOURS_FLOOR);
        let noisy: Vec<u32> = [0, 1, 2, 3, 4, 14, 15, 99]
            .into_iter()
            .map(kernel_neighbours_for_noisy_set)
            .collect();
        assert_eq!(noisy, [45, 31, 25, 22, 20, 16, 16, 16]);
        assert_eq!(
            kernel_neighbours_for_noisy_set(u32::MAX),
            KERNEL_NEIGHBOURS_FLOOR
        );

        let vol = cube(2.0, 0.9, 0.0);
        // A 64 × 64 lattice in the plane z = 0, spacing 1/32.
        let lights: Vec<InternalLight> = (0..64 * 64)
            .map(|i| InternalLight {
                position: Vec3::new((i % 64) as f32, (i / 64) as f32, 0.0) / 32.0 - 1.0,
                density: 1.0,
                weight: 0.0,
            })
            .collect();
        let radius = |neighbours: u32, view_share: f32, kernel_radius: Option<f32>| {
            let params = InternalParams {
                kernel_radius,
                kernel_neighbours: neighbours,
                view_share,
                ..sh1_params(Clock::OpticalDepth, 0.5, 4, 0.1, L1Form::Field)
            };
            kernel_radius_for(&vol, &params, &lights)
        };
        let (h64, h16) = (radius(64, 0.9, None), radius(16, 0.9, None));
        // The disc that holds k lattice points has radius about √(k/π)
        // spacings.
        for (h, k) in [(h64, 64.0f32), (h16, 16.0)] {
            let want = (k / std::f32::consts::PI).sqrt() / 32.0;
            assert!((h / want - 1.0).abs() < 0.15, "{k}: {h} against {want}");
        }
        assert!(h16 < 0.6 * h64, "{h16} against {h64}");
        // Without weights the spacing is the box's volume per light.
        let spacing = (8.0f32 / lights.len() as f32).cbrt();
        let dense = radius(KERNEL_NEIGHBOURS, 0.0, None);
        assert!((dense / (AUTO_KERNEL_FACTOR * spacing) - 1.0).abs() < 1e-5);
        let dense16 = radius(16, 0.0, None);
        let want = (16.0 / KERNEL_NEIGHBOURS as f32).cbrt();
        assert!(
            (dense16 / dense - want).abs() < 1e-5,
            "{dense16} against {dense}"
        );
        assert_eq!(radius(16, 0.9, Some(0.3)), 0.3);
    }
}
