//! Test media and helpers shared by the physics' unit tests: media with
//! known optics (a sphere, a cube, a smooth unbounded field), hand-built
//! internal-light sets, and the statistics (χ², means with their
//! variance) the tests judge by. (The integration tests' image
//! statistics are [`crate::render::stats`].)

use glam::Vec3;

use super::internal::chances::collided;
use super::internal::clock::{Clock, GateSettings};
use super::internal::sources::{
    InternalLight, InternalLights, InternalParams, L1Form, LightSources,
};
use super::internal::walk::Walks;
use super::lights::Lights;
use super::rng::Rng;
use super::sh::sh_count;
use super::volume::{DensityField, Optics, Volume};

/// A direction drawn uniformly on the unit sphere (two draws of `rng`:
/// the cosine, then the azimuth).
pub(crate) fn uniform_direction(rng: &mut Rng) -> Vec3 {
    let z = 1.0 - 2.0 * rng.next_f32();
    let phi = 2.0 * std::f32::consts::PI * rng.next_f32();
    let r = (1.0 - z * z).max(0.0).sqrt();
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// A homogeneous sphere of density 1 about the origin, its box its
/// bounding cube.
pub(crate) struct Ball {
    pub radius: f32,
}

impl DensityField for Ball {
    fn density(&self, p: Vec3) -> f32 {
        if p.length_squared() <= self.radius * self.radius {
            1.0
        } else {
            0.0
        }
    }
    fn bounds(&self) -> (Vec3, Vec3) {
        (Vec3::splat(-self.radius), Vec3::splat(self.radius))
    }
    fn max_in_box(&self, lo: Vec3, hi: Vec3) -> f32 {
        let q = Vec3::ZERO.clamp(lo, hi);
        if q.length_squared() <= self.radius * self.radius {
            1.0
        } else {
            0.0
        }
    }
}

/// Density `base + amp·sin(x)·sin(y)` in a box so large that no walk
/// leaves it: an unbounded medium.
pub(crate) struct Field {
    base: f32,
    amp: f32,
}

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

pub(crate) const HALF: f32 = 1.0e4;

pub(crate) fn volume(base: f32, amp: f32, albedo: f32) -> Volume<Field> {
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
pub(crate) fn boxed(base: f32, amp: f32, albedo: f32, half: f32, cells: u32) -> Volume<Field> {
    let mut vol = volume(base, amp, albedo);
    vol.bounds = (Vec3::splat(-half), Vec3::splat(half));
    vol.majorants =
        crate::physics::majorant::MajorantGrid::build(vol.bounds.0, vol.bounds.1, cells, |_, _| {
            base + amp
        });
    vol
}

/// χ² of a histogram against Poisson(`mean`), pooling the tail where
/// fewer than 5 are expected; returns (χ², degrees of freedom).
pub(crate) fn chi2_poisson(hist: &[u64], mean: f64) -> (f64, usize) {
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

/// One sun whose light travels along `direction` (normalised here) with
/// `irradiance`, and no other light.
pub(crate) fn one_sun(direction: Vec3, irradiance: Vec3) -> Lights {
    Lights {
        suns: vec![crate::physics::lights::Sun {
            direction: direction.normalize(),
            irradiance,
        }],
        points: Vec::new(),
        environment: None,
    }
}

/// A bounded, forward-scattering (`g` 0.6), heterogeneous medium lit by
/// a sun, the optical-depth clock at `s*` 0.5 with 40 terms, and a walk's
/// start `z` and direction `n` inside it.
pub(crate) fn forward_scattering_walk() -> (Volume<Field>, Lights, GateSettings, Vec3, Vec3) {
    let mut vol = boxed(1.2, 0.8, 0.95, 1.0, 4);
    vol.optics.g = 0.6;
    let lights = one_sun(Vec3::new(0.6, -1.0, -0.5), Vec3::new(3.0, 2.0, 1.0));
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
/// the part before its first collision, by [`Walks::accumulate_j_from`].
pub(crate) fn split_walk(walks: &Walks<Field>, z: Vec3, n: Vec3, rng: &mut Rng) -> (Vec3, Vec3) {
    let mut out = vec![Vec3::ZERO; walks.gates.term_slots()];
    let mut unscattered = vec![Vec3::ZERO; walks.gates.term_slots()];
    walks.accumulate_j_from(z, n, 1, rng, &mut out, Some(&mut unscattered));
    (
        collided(&out, &unscattered),
        unscattered[1..].iter().sum::<Vec3>(),
    )
}

/// The mean of `walks` values of `f` (walk `w` on stream
/// `Rng::for_sample(seed, w, stream)`) and the variance of that mean.
pub(crate) fn mean_and_its_variance(
    walks: u32,
    seed: u64,
    stream: u32,
    mut f: impl FnMut(&mut Rng) -> Vec3,
) -> (Vec3, Vec3) {
    // Summed in f64: a low-variance estimator's `sum2/n − mean²` cancels
    // almost to nothing.
    let (mut sum, mut sum2) = (glam::DVec3::ZERO, glam::DVec3::ZERO);
    for w in 0..walks {
        let mut rng = Rng::for_sample(seed, w, stream);
        let v = f(&mut rng).as_dvec3();
        sum += v;
        sum2 += v * v;
    }
    let mean = sum / walks as f64;
    let var = (sum2 / walks as f64 - mean * mean).max(glam::DVec3::ZERO);
    (mean.as_vec3(), (var / walks as f64).as_vec3())
}

/// Parameters of the tests' hand-built caches: order-1 SH, one light
/// and one walk unless changed, no uniform mix, seed 0.
pub(crate) fn sh1_params(
    clock: Clock,
    s_star: f32,
    terms: u32,
    kernel_radius: f32,
    l1: L1Form,
) -> InternalParams {
    InternalParams {
        s_star,
        lights: 1,
        terms,
        walks: 1,
        sh_order: 1,
        kernel_radius: Some(kernel_radius),
        kernel_neighbours: crate::physics::internal::sources::KERNEL_NEIGHBOURS,
        uniform_mix: 0.0,
        clock,
        l1,
        window_scatters: 1,
        view_walks: 0,
        eye: Vec3::ZERO,
        seed: 0,
        view_share: 0.0,
        view_frame: Default::default(),
        walk_deadline: None,
    }
}

/// Density 1 in the cube [−1, 1]³.
pub(crate) struct Cube;
impl DensityField for Cube {
    fn density(&self, p: Vec3) -> f32 {
        if p.abs().max_element() <= 1.0 {
            1.0
        } else {
            0.0
        }
    }
    fn bounds(&self) -> (Vec3, Vec3) {
        (Vec3::splat(-1.0), Vec3::splat(1.0))
    }
    fn max_in_box(&self, _: Vec3, _: Vec3) -> f32 {
        1.0
    }
}

/// A cache of hand-made lights with the given multiply scattered
/// coefficients (all of them, and the collided part), no `F`, no
/// external lights, `∫ρ = 8` (the cube's).
pub(crate) fn assemble(
    vol: &Volume<Cube>,
    params: &InternalParams,
    lights: &[InternalLight],
    multi_coeffs: Vec<Vec3>,
    scattered_coeffs: Vec<Vec3>,
) -> InternalLights {
    InternalLights::assemble(
        vol,
        &Lights::default(),
        params,
        LightSources {
            lights: lights.to_vec(),
            f_coeffs: vec![Vec3::ZERO; multi_coeffs.len()],
            multi_coeffs,
            scattered_coeffs,
            arrival: Vec::new(),
            term_energy: vec![Vec3::ZERO; 2],
            view: Vec::new(),
            phase_view: Vec::new(),
            kernel_radius: None,
        },
        8.0,
    )
}

/// A lattice of lights 0.1 apart over `[−0.7, 0.7]³`, density 1.
pub(crate) fn lattice_lights() -> Vec<InternalLight> {
    let mut lights = Vec::new();
    for k in -7..=7 {
        for j in -7..=7 {
            for i in -7..=7 {
                lights.push(InternalLight {
                    position: Vec3::new(i as f32, j as f32, k as f32) * 0.1,
                    density: 1.0,
                    weight: 1e-3,
                });
            }
        }
    }
    lights
}

/// A cache (order-1 `params`) whose lights all store the isotropic
/// `J₀`, all of it collided.
pub(crate) fn isotropic_cache(
    vol: &Volume<Cube>,
    params: &InternalParams,
    lights: &[InternalLight],
    j0: Vec3,
) -> InternalLights {
    let count = sh_count(1);
    let mut multi = vec![Vec3::ZERO; count * lights.len()];
    for c in multi.chunks_mut(count) {
        c[0] = j0 * (2.0 * std::f32::consts::PI.sqrt());
    }
    assemble(vol, params, lights, multi.clone(), multi)
}

/// The homogeneous cube with grey `σ_t`, albedo and `g`.
pub(crate) fn cube(sigma: f32, albedo: f32, g: f32) -> Volume<Cube> {
    Volume::new(
        Cube,
        Optics {
            sigma_t: Vec3::splat(sigma),
            albedo: Vec3::splat(albedo),
            g,
        },
        8,
    )
}
