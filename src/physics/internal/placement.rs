//! Placement of the `M` internal lights ([method §5](crate::doc::method)): positions `x_i`
//! drawn with density `p(x) ∝ (1 − u) ρ(x)/∫ρ + u/|B|`, each with the
//! volume it stands for, `V_i = 1 / (M p(x_i))`, so that
//! `Σ_i V_i f(x_i)` is an unbiased estimate of `∫_B f`.
//!
//! # The density actually sampled
//!
//! `∫ρ` is not known in closed form, and a pdf that only approximates the
//! sampling density would bias every `V_i`. So the `ρ` part is replaced by
//! a density whose normalisation is exact: the **trilinear interpolant
//! `ρ̃` of `ρ` sampled at the corners of a cell grid** over `B` (with
//! `resolution` cells along the longest axis). Each cell's mass is the
//! integral of `ρ̃` over it, `|cell| · mean(8 corners)` (the trapezoid
//! estimate of `∫_cell ρ`; corners are shared, so the grid costs
//! `(res+1)³` density evaluations). A point is drawn by choosing a cell by
//! its mass (a cumulative table), a corner of the cell by its value, and
//! each coordinate from the linear ramp towards that corner: a trilinear
//! function is such a mixture of ramps, so the point has density exactly
//! `ρ̃(x) / Z` in the cell, `Z = ∫_B ρ̃`. The reported pdf is
//!
//! `p(x) = (1 − u) ρ̃(x) / Z + u / |B|`,
//!
//! the exact density of the procedure (a one-sample mixture: choose the
//! uniform part with probability `u`). `Z` is also the reported estimate of
//! `∫ρ`. For a trilinear voxel grid whose samples coincide with the cell
//! corners, `ρ̃ = ρ`.
//!
//! Rejection against `ρ` inside a cell would follow `ρ` more closely but
//! has density `ρ / ∫_cell ρ`, whose normaliser is unknown; capping the
//! tries does not remove that unknown. The interpolant keeps the pdf exact.
//!
//! **Care**: with `u = 0`, `p = 0` wherever `ρ̃ = 0`, so a feature of `ρ`
//! that falls entirely between corner samples is never sampled and
//! `Σ V_i f(x_i)` misses `∫ f` there. With `u > 0`, `p > 0` on all of `B`
//! and the estimate is unbiased for every `f`. If `Z = 0` (no density on
//! any corner) the placement is uniform, as if `u = 1`.

use glam::{UVec3, Vec3};
use rayon::prelude::*;

use crate::physics::rng::Rng;
use crate::physics::volume::DensityField;

/// Stream index (the `pass` of [`Rng::for_sample`]) used for placement, so
/// that it does not share numbers with renders using the same seed (the
/// WGSL's `PLACEMENT_STREAM` is generated from it).
pub const PLACEMENT_STREAM: u32 = 0x706c_6163;

/// One internal light's position and the volume it stands for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlacedLight {
    /// World-space position `x_i`.
    pub position: Vec3,
    /// The sampling density `p(x_i)` (1/volume).
    pub pdf: f32,
    /// `V_i = 1 / (M p(x_i))` (a volume).
    pub weight: f32,
}

/// The result of [`place_lights`].
#[derive(Clone, Debug)]
pub struct Placement {
    /// The `M` lights, in the order of their random streams.
    pub lights: Vec<PlacedLight>,
    /// Estimate of `∫ρ` over the box: the integral of the interpolant.
    pub density_integral: f32,
    /// `|B|`.
    pub box_volume: f32,
    /// The uniform fraction `u` actually used (1 if `∫ρ̃ = 0`).
    pub u_mix: f32,
}

/// The placement density `p(x) = (1 − u) ρ̃(x)/Z + u/|B|` over a box, with
/// its sampler.
#[derive(Clone, Debug)]
pub struct PlacementDensity {
    min: Vec3,
    max: Vec3,
    res: UVec3,
    cell: Vec3,
    /// `ρ` at the `(res + 1)³` cell corners, x fastest.
    corners: Vec<f32>,
    /// Inclusive prefix sums of the cells' corner sums, x fastest.
    cdf: Vec<f64>,
    /// `∫_B ρ̃`.
    integral: f64,
    u_mix: f32,
}

impl PlacementDensity {
    /// Samples `density` at the corners of a grid over `bounds` with
    /// `resolution` cells along the longest axis (cells about cubic) and
    /// builds the sampler for the mixture weight `u_mix` (clamped to
    /// [0, 1]; 1 if the density vanishes on every corner).
    pub fn build<D: DensityField>(
        density: &D,
        bounds: (Vec3, Vec3),
        resolution: u32,
        u_mix: f32,
    ) -> Self {
        let (min, max) = bounds;
        let size = (max - min).max(Vec3::ZERO);
        let longest = size.max_element().max(1e-30);
        let res = (size / longest * resolution.max(1) as f32)
            .ceil()
            .max(Vec3::ONE)
            .as_uvec3();
        let cell = size / res.as_vec3();
        let (nx, ny, nz) = (res.x as usize + 1, res.y as usize + 1, res.z as usize + 1);
        let mut corners = vec![0.0f32; nx * ny * nz];
        corners
            .par_chunks_mut(nx * ny)
            .enumerate()
            .for_each(|(k, plane)| {
                for j in 0..ny {
                    for i in 0..nx {
                        let p = min + cell * Vec3::new(i as f32, j as f32, k as f32);
                        let v = density.density(p.min(max));
                        plane[i + nx * j] = if v.is_finite() { v.max(0.0) } else { 0.0 };
                    }
                }
            });
        let (rx, ry, rz) = (res.x as usize, res.y as usize, res.z as usize);
        // Corner sums per cell, in parallel over z, then one prefix sum.
        let mut cdf = vec![0.0f64; rx * ry * rz];
        cdf.par_chunks_mut(rx * ry)
            .enumerate()
            .for_each(|(k, plane)| {
                for j in 0..ry {
                    for i in 0..rx {
                        let c = |di: usize, dj: usize, dk: usize| {
                            corners[(i + di) + nx * ((j + dj) + ny * (k + dk))] as f64
                        };
                        plane[i + rx * j] = c(0, 0, 0)
                            + c(1, 0, 0)
                            + c(0, 1, 0)
                            + c(1, 1, 0)
                            + c(0, 0, 1)
                            + c(1, 0, 1)
                            + c(0, 1, 1)
                            + c(1, 1, 1);
                    }
                }
            });
        let mut running = 0.0f64;
        for c in &mut cdf {
            running += *c;
            *c = running;
        }
        let cell_volume = cell.x as f64 * cell.y as f64 * cell.z as f64;
        let integral = running * cell_volume / 8.0;
        let u_mix = if integral > 0.0 && integral.is_finite() {
            u_mix.clamp(0.0, 1.0)
        } else {
            1.0
        };
        Self {
            min,
            max,
            res,
            cell,
            corners,
            cdf,
            integral,
            u_mix,
        }
    }

    /// `Z = ∫_B ρ̃`, the estimate of `∫ρ`.
    pub fn density_integral(&self) -> f32 {
        self.integral as f32
    }

    /// `|B|`.
    pub fn box_volume(&self) -> f32 {
        let s = self.max - self.min;
        s.x * s.y * s.z
    }

    /// The uniform fraction `u` in use.
    pub fn u_mix(&self) -> f32 {
        self.u_mix
    }

    /// The interpolant `ρ̃(x)` (zero outside the box).
    pub fn interpolated_density(&self, x: Vec3) -> f32 {
        if x.cmplt(self.min).any() || x.cmpgt(self.max).any() {
            return 0.0;
        }
        let g = (x - self.min) / self.cell;
        let last = (self.res - UVec3::ONE).as_vec3();
        let c = g.floor().clamp(Vec3::ZERO, last);
        let f = (g - c).clamp(Vec3::ZERO, Vec3::ONE);
        let c = c.as_uvec3();
        let (nx, ny) = (self.res.x as usize + 1, self.res.y as usize + 1);
        let at = |di: u32, dj: u32, dk: u32| {
            self.corners
                [(c.x + di) as usize + nx * ((c.y + dj) as usize + ny * (c.z + dk) as usize)]
        };
        let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
        let x00 = lerp(at(0, 0, 0), at(1, 0, 0), f.x);
        let x10 = lerp(at(0, 1, 0), at(1, 1, 0), f.x);
        let x01 = lerp(at(0, 0, 1), at(1, 0, 1), f.x);
        let x11 = lerp(at(0, 1, 1), at(1, 1, 1), f.x);
        lerp(lerp(x00, x10, f.y), lerp(x01, x11, f.y), f.z)
    }

    /// The sampling density `p(x)` (1/volume; zero outside the box).
    pub fn pdf(&self, x: Vec3) -> f32 {
        if x.cmplt(self.min).any() || x.cmpgt(self.max).any() {
            return 0.0;
        }
        let uniform = self.u_mix / self.box_volume();
        if self.u_mix >= 1.0 {
            return uniform;
        }
        let rho = self.interpolated_density(x) as f64;
        ((1.0 - self.u_mix as f64) * rho / self.integral) as f32 + uniform
    }

    /// The box `(min, max)` the density covers.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        (self.min, self.max)
    }

    /// Cells along each axis.
    pub fn resolution(&self) -> UVec3 {
        self.res
    }

    /// The size of one cell.
    pub fn cell_size(&self) -> Vec3 {
        self.cell
    }

    /// `ρ` at the `(res + 1)³` cell corners, x fastest.
    pub fn corners(&self) -> &[f32] {
        &self.corners
    }

    /// The probability with which the `ρ̃` part of the mixture picks each
    /// cell (x fastest): its share of `Z`. Empty if `Z = 0`.
    pub fn cell_probabilities(&self) -> Vec<f64> {
        let total = self.cdf.last().copied().unwrap_or(0.0);
        if total <= 0.0 || !total.is_finite() {
            return Vec::new();
        }
        let mut prev = 0.0;
        self.cdf
            .iter()
            .map(|&c| {
                let p = (c - prev) / total;
                prev = c;
                p
            })
            .collect()
    }

    /// Walker's alias table of [`PlacementDensity::cell_probabilities`]
    /// (Vose's construction, in f64): cell `i` is picked by drawing `i`
    /// uniformly and keeping it with probability `threshold[i]`, else
    /// taking `alias[i]`. The GPU samples cells with it in O(1), where a
    /// binary search over the f64 cumulative table is not available
    /// (`shaders/common/placement.wgsl`). Empty if `Z = 0`.
    pub fn alias_table(&self) -> (Vec<f32>, Vec<u32>) {
        let probs = self.cell_probabilities();
        let n = probs.len();
        let mut threshold = vec![1.0f32; n];
        let mut alias: Vec<u32> = (0..n as u32).collect();
        let mut scaled: Vec<f64> = probs.iter().map(|p| p * n as f64).collect();
        let (mut small, mut large): (Vec<usize>, Vec<usize>) =
            (0..n).partition(|&i| scaled[i] < 1.0);
        while let (Some(&s), Some(&l)) = (small.last(), large.last()) {
            small.pop();
            threshold[s] = scaled[s] as f32;
            alias[s] = l as u32;
            scaled[l] -= 1.0 - scaled[s];
            if scaled[l] < 1.0 {
                large.pop();
                small.push(l);
            }
        }
        // What is left has probability one up to rounding.
        for i in small.into_iter().chain(large) {
            threshold[i] = 1.0;
            alias[i] = i as u32;
        }
        (threshold, alias)
    }

    /// Draws one point with density [`PlacementDensity::pdf`] and returns
    /// it with its pdf.
    pub fn sample(&self, rng: &mut Rng) -> (Vec3, f32) {
        let x = if rng.next_f32() < self.u_mix {
            self.min
                + (self.max - self.min) * Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32())
        } else {
            self.sample_interpolant(rng)
        };
        let x = x.clamp(self.min, self.max);
        (x, self.pdf(x))
    }

    /// A point with density `ρ̃ / Z`.
    fn sample_interpolant(&self, rng: &mut Rng) -> Vec3 {
        let total = self.cdf.last().copied().unwrap_or(0.0);
        // 64 random bits, so that cells lighter than 2⁻²⁴ of the total are
        // reachable too.
        let u = (rng.next_u32() as f64 + rng.next_u32() as f64 * 4_294_967_296.0)
            / 18_446_744_073_709_551_616.0;
        let target = u * total;
        let idx = self
            .cdf
            .partition_point(|&c| c <= target)
            .min(self.cdf.len().saturating_sub(1));
        let (rx, ry) = (self.res.x as usize, self.res.y as usize);
        let (i, j, k) = (idx % rx, (idx / rx) % ry, idx / (rx * ry));
        let (nx, ny) = (rx + 1, ry + 1);
        let mut values = [0.0f32; 8];
        for (bits, v) in values.iter_mut().enumerate() {
            let (di, dj, dk) = (bits & 1, (bits >> 1) & 1, (bits >> 2) & 1);
            *v = self.corners[(i + di) + nx * ((j + dj) + ny * (k + dk))];
        }
        // A corner with probability ∝ its value, then a ramp towards it
        // along each axis (density 2t or 2(1 − t)).
        let sum: f32 = values.iter().sum();
        let mut pick = rng.next_f32() * sum;
        let mut corner = 7;
        for (bits, &v) in values.iter().enumerate() {
            if pick < v {
                corner = bits;
                break;
            }
            pick -= v;
        }
        // Rounding may leave `pick` past the last corner: take the last
        // one with any weight.
        if values[corner] <= 0.0 {
            corner = values.iter().rposition(|&v| v > 0.0).unwrap_or(0);
        }
        let mut local = Vec3::ZERO;
        for axis in 0..3 {
            let r = rng.next_f32().sqrt();
            local[axis] = if (corner >> axis) & 1 == 1 {
                r
            } else {
                1.0 - r
            };
        }
        self.min + self.cell * (Vec3::new(i as f32, j as f32, k as f32) + local)
    }
}

/// Places `m` internal lights in `bounds` with density
/// `p ∝ (1 − u) ρ̃/Z + u/|B|` (see the module doc for `ρ̃` and why),
/// using a grid of `resolution` cells along the longest axis. Light `i`
/// uses its own random stream of `seed`, so the result depends on
/// `(density, bounds, m, u_mix, seed, resolution)` only.
pub fn place_lights<D: DensityField>(
    density: &D,
    bounds: (Vec3, Vec3),
    m: usize,
    u_mix: f32,
    seed: u64,
    resolution: u32,
) -> Placement {
    let sampler = PlacementDensity::build(density, bounds, resolution, u_mix);
    place_lights_with(&sampler, m, seed)
}

/// [`place_lights`] with the placement density already built (it depends
/// on the density, the box, `u_mix` and the resolution only).
pub fn place_lights_with(sampler: &PlacementDensity, m: usize, seed: u64) -> Placement {
    Placement {
        lights: sample_lights(sampler, m, seed),
        density_integral: sampler.density_integral(),
        box_volume: sampler.box_volume(),
        u_mix: sampler.u_mix(),
    }
}

/// Draws `m` lights from a built [`PlacementDensity`], light `i` from
/// stream `i` of `seed`.
pub fn sample_lights(sampler: &PlacementDensity, m: usize, seed: u64) -> Vec<PlacedLight> {
    let inv_m = 1.0 / m.max(1) as f32;
    (0..m)
        .into_par_iter()
        .map(|i| {
            let mut rng = Rng::for_sample(seed, i as u32, PLACEMENT_STREAM);
            let (position, pdf) = sampler.sample(&mut rng);
            let weight = if pdf > 0.0 { inv_m / pdf } else { 0.0 };
            PlacedLight {
                position,
                pdf,
                weight,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth blob with full support in a non-cubic box.
    struct Blob;

    const BLOB_BOX: (Vec3, Vec3) = (Vec3::new(-1.0, -0.5, -1.0), Vec3::new(1.0, 0.5, 1.0));

    impl DensityField for Blob {
        fn density(&self, p: Vec3) -> f32 {
            let q = (p - Vec3::new(0.2, 0.0, -0.1)) / Vec3::new(0.35, 0.25, 0.4);
            2.0 * (-0.5 * q.length_squared()).exp() + 0.05
        }
        fn bounds(&self) -> (Vec3, Vec3) {
            BLOB_BOX
        }
        fn max_in_box(&self, _: Vec3, _: Vec3) -> f32 {
            2.05
        }
    }

    /// A ball of density 1 with a sharp edge, in a larger box.
    struct Ball;

    impl DensityField for Ball {
        fn density(&self, p: Vec3) -> f32 {
            if p.length_squared() <= 0.5 {
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

    /// `∫_B f` by the midpoint rule on `n` cells along the longest axis, in
    /// f64.
    fn integrate(bounds: (Vec3, Vec3), n: usize, f: impl Fn(Vec3) -> f64) -> f64 {
        let size = bounds.1 - bounds.0;
        let longest = size.max_element();
        let res = (size / longest * n as f32).ceil().as_uvec3();
        let cell = size / res.as_vec3();
        let mut sum = 0.0;
        for k in 0..res.z {
            for j in 0..res.y {
                for i in 0..res.x {
                    let p = bounds.0 + cell * (UVec3::new(i, j, k).as_vec3() + 0.5);
                    sum += f(p);
                }
            }
        }
        sum * (cell.x * cell.y * cell.z) as f64
    }

    /// Mean and standard error over `runs` seeds of `Σ V_i f(x_i)`.
    fn estimate<D: DensityField>(
        density: &D,
        u: f32,
        runs: u64,
        f: impl Fn(Vec3) -> f64,
    ) -> (f64, f64) {
        let sampler = PlacementDensity::build(density, density.bounds(), 24, u);
        let ests: Vec<f64> = (0..runs)
            .map(|seed| {
                sample_lights(&sampler, 1024, seed)
                    .iter()
                    .map(|l| l.weight as f64 * f(l.position))
                    .sum()
            })
            .collect();
        let mean = ests.iter().sum::<f64>() / runs as f64;
        let var = ests.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / (runs - 1) as f64;
        (mean, (var / runs as f64).sqrt())
    }

    fn check(name: &str, (mean, se): (f64, f64), exact: f64) {
        eprintln!(
            "{name}: {mean:.5} ± {se:.5} vs {exact:.5} ({:+.2} σ)",
            (mean - exact) / se
        );
        assert!(
            (mean - exact).abs() < 4.0 * se + 1e-9 * exact.abs(),
            "{name}"
        );
    }

    #[test]
    fn weights_estimate_integrals_without_bias() {
        let blob = Blob;
        let rho = |p: Vec3| blob.density(p) as f64;
        let int_rho = integrate(BLOB_BOX, 400, rho);
        let smooth = |p: Vec3| {
            rho(p) * (1.0 + 0.8 * (3.0 * p.x as f64).sin() * p.y as f64 + p.z as f64 * p.z as f64)
        };
        let int_smooth = integrate(BLOB_BOX, 400, smooth);
        check(
            "blob, f = 1, u = 0.3",
            estimate(&blob, 0.3, 200, |_| 1.0),
            2.0 * 1.0 * 2.0,
        );
        check(
            "blob, f = 1, u = 0",
            estimate(&blob, 0.0, 200, |_| 1.0),
            4.0,
        );
        check(
            "blob, f = ρ, u = 0",
            estimate(&blob, 0.0, 200, rho),
            int_rho,
        );
        check(
            "blob, f = ρ, u = 0.3",
            estimate(&blob, 0.3, 200, rho),
            int_rho,
        );
        check(
            "blob, f = ρ·g, u = 0.1",
            estimate(&blob, 0.1, 200, smooth),
            int_smooth,
        );
        // A sharp-edged ball: the interpolant misses slivers of it, but with
        // u > 0 every point of the box has a positive pdf.
        let ball = Ball;
        let ball_volume = 4.0 / 3.0 * std::f64::consts::PI * 0.5f64.powf(1.5);
        check(
            "ball, f = 1, u = 0.5",
            estimate(&ball, 0.5, 200, |_| 1.0),
            8.0,
        );
        check(
            "ball, f = ρ, u = 0.5",
            estimate(&ball, 0.5, 200, |p| ball.density(p) as f64),
            ball_volume,
        );
    }

    #[test]
    fn reported_pdf_integrates_to_one_and_z_estimates_the_mass() {
        let blob = Blob;
        let s = PlacementDensity::build(&blob, BLOB_BOX, 24, 0.25);
        let total = integrate(BLOB_BOX, 240, |p| s.pdf(p) as f64);
        assert!((total - 1.0).abs() < 1e-3, "∫p = {total}");
        let exact = integrate(BLOB_BOX, 400, |p| blob.density(p) as f64);
        let z = s.density_integral() as f64;
        assert!((z - exact).abs() < 0.01 * exact, "Z = {z}, ∫ρ = {exact}");
    }

    /// Bin counts over 8³ bins against the mass of each bin, both of the
    /// interpolant (the exact sampling density) and of `ρ` itself.
    #[test]
    fn positions_follow_the_density_chi_square() {
        let blob = Blob;
        let m = 200_000;
        for u in [0.0f32, 0.2] {
            let sampler = PlacementDensity::build(&blob, BLOB_BOX, 32, u);
            let lights = sample_lights(&sampler, m, 7);
            let bins = 8usize;
            let size = BLOB_BOX.1 - BLOB_BOX.0;
            let bin = |p: Vec3| {
                let g = ((p - BLOB_BOX.0) / size * bins as f32)
                    .floor()
                    .clamp(Vec3::ZERO, Vec3::splat(bins as f32 - 1.0));
                g.x as usize + bins * (g.y as usize + bins * g.z as usize)
            };
            let mut counts = vec![0.0f64; bins * bins * bins];
            for l in &lights {
                counts[bin(l.position)] += 1.0;
            }
            let mut p_interp = vec![0.0f64; bins * bins * bins];
            let mut p_true = vec![0.0f64; bins * bins * bins];
            let fine = 160usize;
            let cell = size / Vec3::new(fine as f32, (fine / 2) as f32, fine as f32);
            let dv = (cell.x * cell.y * cell.z) as f64;
            let int_rho = integrate(BLOB_BOX, fine, |p| blob.density(p) as f64);
            let vol = (size.x * size.y * size.z) as f64;
            for k in 0..fine {
                for j in 0..fine / 2 {
                    for i in 0..fine {
                        let p = BLOB_BOX.0 + cell * (Vec3::new(i as f32, j as f32, k as f32) + 0.5);
                        p_interp[bin(p)] += sampler.pdf(p) as f64 * dv;
                        p_true[bin(p)] += ((1.0 - u as f64) * blob.density(p) as f64 / int_rho
                            + u as f64 / vol)
                            * dv;
                    }
                }
            }
            for (name, probs) in [("interpolant", &p_interp), ("ρ", &p_true)] {
                let chi2: f64 = counts
                    .iter()
                    .zip(probs.iter())
                    .map(|(&c, &p)| (c - p * m as f64).powi(2) / (p * m as f64))
                    .sum();
                eprintln!("u = {u}: χ² against {name} = {chi2:.1} (511 dof)");
                // 99.9th percentile of χ² with 511 degrees of freedom.
                assert!(chi2 < 614.0, "u = {u}, {name}: χ² = {chi2}");
            }
        }
    }

    #[test]
    fn alias_table_reproduces_cell_probabilities() {
        let sampler = PlacementDensity::build(&Blob, BLOB_BOX, 12, 0.0);
        let probs = sampler.cell_probabilities();
        let (threshold, alias) = sampler.alias_table();
        let n = probs.len();
        let mut got = vec![0.0f64; n];
        for i in 0..n {
            got[i] += threshold[i] as f64 / n as f64;
            got[alias[i] as usize] += (1.0 - threshold[i] as f64) / n as f64;
        }
        for (g, p) in got.iter().zip(&probs) {
            assert!((g - p).abs() < 1e-7 * p.max(1e-3), "{g} vs {p}");
        }
    }

    #[test]
    fn deterministic_for_a_seed() {
        let a = place_lights(&Blob, BLOB_BOX, 500, 0.2, 11, 16);
        let b = place_lights(&Blob, BLOB_BOX, 500, 0.2, 11, 16);
        let c = place_lights(&Blob, BLOB_BOX, 500, 0.2, 12, 16);
        assert_eq!(a.lights, b.lights);
        assert_ne!(a.lights, c.lights);
        assert!(a
            .lights
            .iter()
            .all(|l| l.pdf > 0.0 && (l.weight * l.pdf * 500.0 - 1.0).abs() < 1e-4));
        // An empty field falls back to uniform placement.
        struct Empty;
        impl DensityField for Empty {
            fn density(&self, _: Vec3) -> f32 {
                0.0
            }
            fn bounds(&self) -> (Vec3, Vec3) {
                (Vec3::ZERO, Vec3::ONE)
            }
            fn max_in_box(&self, _: Vec3, _: Vec3) -> f32 {
                0.0
            }
        }
        let e = place_lights(&Empty, (Vec3::ZERO, Vec3::ONE), 10, 0.0, 1, 8);
        assert_eq!(e.u_mix, 1.0);
        assert!(e.lights.iter().all(|l| (l.pdf - 1.0).abs() < 1e-6));
    }
}
