//! Real spherical harmonics for the angular part of the internal lights
//! ([method §5](crate::doc::method): `J_i(n')` and `F_i(n')` are projected onto real SH of a
//! chosen order, because the multiple-scatter part is smooth in angle).
//!
//! The basis is the usual orthonormal real basis with the Condon–Shortley
//! phase, as tabulated in Sloan's "Stupid Spherical Harmonics (SH) Tricks"
//! (2008): coefficient `i = l(l+1) + m`, `Y₀₀ = 1/(2√π)`,
//! `Y₁₋₁ = −√(3/4π) y`, `Y₁₀ = √(3/4π) z`, `Y₁₁ = −√(3/4π) x`, and
//!
//! - `Y_lm = √2 K_l^m P_l^m(z) cos(mφ)` for `m > 0`,
//! - `Y_lm = √2 K_l^|m| P_l^|m|(z) sin(|m|φ)` for `m < 0`,
//! - `Y_l0 = K_l^0 P_l^0(z)`,
//!
//! with `K_l^m = √((2l+1)/(4π) · (l−m)!/(l+m)!)`. It is orthonormal over the
//! sphere: `∫ Y_i Y_j dω = δ_ij`. Evaluation avoids trigonometry:
//! `sinᵐθ cos(mφ)` and `sinᵐθ sin(mφ)` are the real and imaginary parts of
//! `(x + iy)ᵐ`, and `P_l^m(z) / sinᵐθ` follows the usual three-term
//! recurrence in `l`.
//!
//! Orders `0..=4` are supported (at most 25 coefficients).

use glam::Vec3;

/// The highest supported order `l` (the settings' bound on `sh_order`,
/// defined with them so that the scene layer needs nothing of this one).
pub use crate::scene::settings::MAX_SH_ORDER as MAX_ORDER;

/// Number of coefficients of the highest supported order, `(MAX_ORDER+1)²`.
pub const MAX_COUNT: usize = ((MAX_ORDER + 1) * (MAX_ORDER + 1)) as usize;

/// `K_l^|m|` (times `√2` for `m ≠ 0`), indexed by `l(l+1) + m`; checked
/// against the factorial formula in the tests.
pub const NORM: [f32; MAX_COUNT] = [
    0.282_094_8,   // l=0, m=0
    0.488_602_5,   // l=1, m=-1
    0.488_602_5,   // l=1, m=0
    0.488_602_5,   // l=1, m=1
    0.182_091_4,   // l=2, m=-2
    0.364_182_8,   // l=2, m=-1
    0.630_783_1,   // l=2, m=0
    0.364_182_8,   // l=2, m=1
    0.182_091_4,   // l=2, m=2
    0.039_336_24,  // l=3, m=-3
    0.096_353_71,  // l=3, m=-2
    0.304_697_2,   // l=3, m=-1
    0.746_352_7,   // l=3, m=0
    0.304_697_2,   // l=3, m=1
    0.096_353_71,  // l=3, m=2
    0.039_336_24,  // l=3, m=3
    0.005_960_34,  // l=4, m=-4
    0.016_858_388, // l=4, m=-3
    0.063_078_31,  // l=4, m=-2
    0.267_618_6,   // l=4, m=-1
    0.846_284_4,   // l=4, m=0
    0.267_618_6,   // l=4, m=1
    0.063_078_31,  // l=4, m=2
    0.016_858_388, // l=4, m=3
    0.005_960_34,  // l=4, m=4
];

/// Number of coefficients of order `order`: `(order + 1)²` (orders above
/// [`MAX_ORDER`] are clamped to it).
#[inline]
pub fn sh_count(order: u32) -> usize {
    let l = order.min(MAX_ORDER) as usize + 1;
    l * l
}

/// Writes the basis functions `Y_i(dir)`, `i < sh_count(order)`, into the
/// front of `out` (orders above [`MAX_ORDER`] are clamped; if `out` is
/// shorter, only its length is written). `dir` should be unit length.
pub fn sh_basis(order: u32, dir: Vec3, out: &mut [f32]) {
    let order = order.min(MAX_ORDER) as usize;
    let count = sh_count(order as u32).min(out.len());
    let (x, y, z) = (dir.x, dir.y, dir.z);
    // (x + iy)^m for m = 0..=order: sinᵐθ (cos mφ, sin mφ).
    let mut re = [0.0f32; MAX_ORDER as usize + 1];
    let mut im = [0.0f32; MAX_ORDER as usize + 1];
    re[0] = 1.0;
    for m in 1..=order {
        re[m] = re[m - 1] * x - im[m - 1] * y;
        im[m] = re[m - 1] * y + im[m - 1] * x;
    }
    let mut full = [0.0f32; MAX_COUNT];
    // Q_l^m(z) = P_l^m(z) / sinᵐθ, with the Condon–Shortley phase.
    let mut q_mm = 1.0f32; // Q_m^m = (−1)^m (2m − 1)!!
    for m in 0..=order {
        if m > 0 {
            q_mm *= -((2 * m - 1) as f32);
        }
        let mut q_prev = 0.0f32; // Q_{l−2}^m
        let mut q = q_mm; // Q_l^m, starting at l = m
        for l in m..=order {
            if l == m + 1 {
                q_prev = q;
                q = z * (2 * m + 1) as f32 * q_mm;
            } else if l > m + 1 {
                let next =
                    ((2 * l - 1) as f32 * z * q - (l + m - 1) as f32 * q_prev) / (l - m) as f32;
                q_prev = q;
                q = next;
            }
            let centre = l * (l + 1);
            if m == 0 {
                full[centre] = NORM[centre] * q;
            } else {
                full[centre + m] = NORM[centre + m] * q * re[m];
                full[centre - m] = NORM[centre - m] * q * im[m];
            }
        }
    }
    out[..count].copy_from_slice(&full[..count]);
}

/// Multiplies each basis value `Y_i(n)` in `basis` by `g^l`, `l` its band
/// (index `l(l+1) + m` is band `⌊√index⌋`): the Henyey–Greenstein phase
/// function's Legendre coefficients. A series `f = Σ c_i Y_i` evaluated
/// with the scaled basis at `n` is then `∫ P(n·n') f(n') dn'` (Funk–Hecke):
/// the series convolved with the phase function.
pub fn hg_convolve_basis(basis: &mut [f32], g: f32) {
    for (index, y) in basis.iter_mut().enumerate() {
        *y *= g.powi((index as f32).sqrt().floor() as i32);
    }
}

/// An RGB function on the sphere as real SH coefficients of one order.
#[derive(Clone, Debug, PartialEq)]
pub struct ShRgb {
    /// The order `l_max` (at most [`MAX_ORDER`]).
    pub order: u32,
    /// `sh_count(order)` RGB coefficients, indexed by `l(l+1) + m`.
    pub coeffs: Vec<Vec3>,
}

impl ShRgb {
    /// The zero function of order `order` (clamped to [`MAX_ORDER`]).
    pub fn new(order: u32) -> Self {
        let order = order.min(MAX_ORDER);
        Self {
            order,
            coeffs: vec![Vec3::ZERO; sh_count(order)],
        }
    }

    /// Adds one Monte Carlo sample of the projection
    /// `c_i = ∫ f(ω) Y_i(ω) dω`: `c_i += value · Y_i(dir) · weight`, where
    /// `weight` is `1 / (K · pdf(dir))` for `K` samples drawn with density
    /// `pdf` (in 1/sr); for example `4π / K` for uniform directions.
    pub fn add_sample(&mut self, dir: Vec3, value: Vec3, weight: f32) {
        let mut y = [0.0f32; MAX_COUNT];
        sh_basis(self.order, dir, &mut y);
        let v = value * weight;
        for (c, &yi) in self.coeffs.iter_mut().zip(y.iter()) {
            *c += v * yi;
        }
    }

    /// The represented function at `dir`: `Σ_i c_i Y_i(dir)`.
    pub fn eval(&self, dir: Vec3) -> Vec3 {
        let mut y = [0.0f32; MAX_COUNT];
        sh_basis(self.order, dir, &mut y);
        self.coeffs
            .iter()
            .zip(y.iter())
            .fold(Vec3::ZERO, |acc, (&c, &yi)| acc + c * yi)
    }

    /// Multiplies every coefficient by `s`.
    pub fn scale(&mut self, s: f32) {
        for c in &mut self.coeffs {
            *c *= s;
        }
    }

    /// Adds another function of the same order, coefficient by coefficient
    /// (the shorter coefficient list bounds the sum).
    pub fn add(&mut self, other: &ShRgb) {
        for (c, &o) in self.coeffs.iter_mut().zip(other.coeffs.iter()) {
            *c += o;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::rng::Rng;
    use crate::physics::testing::uniform_direction;
    use std::f64::consts::PI;

    /// A Fibonacci lattice of `n` directions with equal weights `4π/n`.
    fn fibonacci(n: usize) -> impl Iterator<Item = Vec3> {
        let golden = PI * (3.0 - 5.0f64.sqrt());
        (0..n).map(move |i| {
            let z = 1.0 - (2.0 * i as f64 + 1.0) / n as f64;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = golden * i as f64;
            Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32)
        })
    }

    fn factorial(n: u32) -> f64 {
        (1..=n).map(f64::from).product()
    }

    #[test]
    fn normalisation_table_matches_formula() {
        for l in 0..=MAX_ORDER {
            for m in -(l as i32)..=(l as i32) {
                let am = m.unsigned_abs();
                let mut k = ((2 * l + 1) as f64 / (4.0 * PI) * factorial(l - am)
                    / factorial(l + am))
                .sqrt();
                if m != 0 {
                    k *= 2.0f64.sqrt();
                }
                let i = (l * (l + 1)) as i32 + m;
                let table = NORM[i as usize] as f64;
                assert!((table - k).abs() < 1e-6 * k, "l={l} m={m}: {table} vs {k}");
            }
        }
    }

    /// Sloan's closed forms for l ≤ 2 (with the Condon–Shortley phase).
    #[test]
    fn matches_sloan_closed_forms() {
        let d = Vec3::new(0.3, -0.5, 0.7).normalize();
        let (x, y, z) = (d.x, d.y, d.z);
        let expected = [
            0.282_094_8,
            -0.488_602_5 * y,
            0.488_602_5 * z,
            -0.488_602_5 * x,
            1.092_548_4 * x * y,
            -1.092_548_4 * y * z,
            0.315_391_57 * (3.0 * z * z - 1.0),
            -1.092_548_4 * x * z,
            0.546_274_2 * (x * x - y * y),
        ];
        let mut out = [0.0f32; 9];
        sh_basis(2, d, &mut out);
        for (i, (&a, &b)) in out.iter().zip(expected.iter()).enumerate() {
            assert!((a - b).abs() < 1e-5, "Y_{i}: {a} vs {b}");
        }
        assert_eq!(sh_count(0), 1);
        assert_eq!(sh_count(3), 16);
        assert_eq!(sh_count(4), 25);
        assert_eq!(sh_count(9), 25);
    }

    /// `∫ Y_i Y_j dω = δ_ij` on a Fibonacci lattice of 100 000 directions.
    #[test]
    fn orthonormal_over_the_sphere() {
        let n = 100_000;
        let mut gram = vec![0.0f64; MAX_COUNT * MAX_COUNT];
        let mut y = [0.0f32; MAX_COUNT];
        for d in fibonacci(n) {
            sh_basis(MAX_ORDER, d, &mut y);
            for i in 0..MAX_COUNT {
                for j in 0..MAX_COUNT {
                    gram[i * MAX_COUNT + j] += y[i] as f64 * y[j] as f64;
                }
            }
        }
        let w = 4.0 * PI / n as f64;
        let mut worst = 0.0f64;
        for i in 0..MAX_COUNT {
            for j in 0..MAX_COUNT {
                let g = gram[i * MAX_COUNT + j] * w;
                let expect = if i == j { 1.0 } else { 0.0 };
                worst = worst.max((g - expect).abs());
                assert!((g - expect).abs() < 1e-3, "∫Y_{i} Y_{j} = {g}");
            }
        }
        eprintln!("orthonormality: worst |∫Y_iY_j − δ_ij| = {worst:.2e}");
    }

    /// Projecting a known combination of basis functions recovers its
    /// coefficients, and evaluating reproduces the function.
    #[test]
    fn round_trip() {
        let mut truth = ShRgb::new(4);
        for (i, c) in truth.coeffs.iter_mut().enumerate() {
            let f = i as f32;
            *c = Vec3::new((0.7 * f).sin(), (1.3 * f + 0.5).cos(), 0.1 * f - 1.0);
        }
        let n = 100_000;
        let mut proj = ShRgb::new(4);
        for d in fibonacci(n) {
            proj.add_sample(d, truth.eval(d), (4.0 * PI / n as f64) as f32);
        }
        for (i, (a, b)) in proj.coeffs.iter().zip(truth.coeffs.iter()).enumerate() {
            assert!((*a - *b).abs().max_element() < 2e-3, "c_{i}: {a} vs {b}");
        }
        let d = Vec3::new(-0.2, 0.9, 0.1).normalize();
        assert!((proj.eval(d) - truth.eval(d)).abs().max_element() < 1e-2);
        let mut half = proj.clone();
        half.scale(0.5);
        half.add(&half.clone());
        assert!((half.eval(d) - proj.eval(d)).abs().max_element() < 1e-5);
    }

    /// Exact zonal coefficients of the clamped cosine `max(0, a·ω)`:
    /// `2π ∫₀¹ μ P_l(μ) dμ · √((2l+1)/4π)` = π, 2π/3, π/4, 0, −π/24 times
    /// the `Y_l0` normalisation.
    fn clamped_cosine_zonal() -> [f64; 5] {
        let base = [PI, 2.0 * PI / 3.0, PI / 4.0, 0.0, -PI / 24.0];
        let mut out = [0.0; 5];
        for l in 0..5 {
            out[l] = base[l] * ((2 * l + 1) as f64 / (4.0 * PI)).sqrt();
        }
        out
    }

    #[test]
    fn clamped_cosine_projection() {
        let zonal = clamped_cosine_zonal();
        // About +z: only the m = 0 coefficients are non-zero.
        let n = 200_000;
        let mut proj = ShRgb::new(4);
        let w = (4.0 * PI / n as f64) as f32;
        for d in fibonacci(n) {
            proj.add_sample(d, Vec3::splat(d.z.max(0.0)), w);
        }
        for (l, &zonal_l) in zonal.iter().enumerate() {
            for m in -(l as i32)..=(l as i32) {
                let i = (l * (l + 1)) as i32 + m;
                let c = proj.coeffs[i as usize].x as f64;
                let expect = if m == 0 { zonal_l } else { 0.0 };
                assert!((c - expect).abs() < 1e-3, "l={l} m={m}: {c} vs {expect}");
            }
        }
        // About a tilted axis, by Monte Carlo with uniform directions: the
        // projection evaluates (addition theorem) to
        // Σ_l c_l √((2l+1)/4π) P_l(a·ω).
        let axis = Vec3::new(0.4, -0.3, 0.6).normalize();
        let mut rng = Rng::for_sample(9, 0, 0);
        let k = 400_000;
        let mut mc = ShRgb::new(2);
        for _ in 0..k {
            let d = uniform_direction(&mut rng);
            mc.add_sample(
                d,
                Vec3::splat(axis.dot(d).max(0.0)),
                (4.0 * PI / k as f64) as f32,
            );
        }
        for d in [axis, -axis, Vec3::X, Vec3::new(0.0, 0.6, 0.8)] {
            let mu = axis.dot(d) as f64;
            let p = [1.0, mu, 0.5 * (3.0 * mu * mu - 1.0)];
            let expect: f64 = (0..3)
                .map(|l| zonal[l] * ((2 * l + 1) as f64 / (4.0 * PI)).sqrt() * p[l])
                .sum();
            let got = mc.eval(d).x as f64;
            assert!((got - expect).abs() < 0.01, "at {d}: {got} vs {expect}");
        }
    }

    /// The scaled basis is the basis convolved with the phase function:
    /// for directions `n'` drawn from `P(n·n')` about `n`, the mean of
    /// `Y_i(n')` is `g^l Y_i(n)` (Funk–Hecke), for every `i` of order 4, at
    /// `g` 0.85 and −0.4.
    #[test]
    fn hg_convolved_basis_is_the_phase_functions_average() {
        let n = Vec3::new(0.3, -0.5, 0.8).normalize();
        let count = sh_count(4);
        let mut rng = Rng::for_sample(21, 0, 0);
        for g in [0.85f32, -0.4] {
            let k = 200_000;
            let mut mean = vec![0.0f64; count];
            let mut y = [0.0f32; 25];
            for _ in 0..k {
                let d = crate::physics::phase::sample_hg(g, n, rng.next_f32(), rng.next_f32());
                sh_basis(4, d, &mut y);
                for (m, v) in mean.iter_mut().zip(&y) {
                    *m += f64::from(*v) / k as f64;
                }
            }
            let mut want = [0.0f32; 25];
            sh_basis(4, n, &mut want);
            hg_convolve_basis(&mut want[..count], g);
            for (i, (m, w)) in mean.iter().zip(&want).enumerate() {
                // Each |Y_i| ≤ 1.5 at order 4: the mean's sd is below 1.5/√k.
                assert!(
                    (m - f64::from(*w)).abs() < 0.015,
                    "g {g}, index {i}: {m} vs {w}"
                );
            }
        }
    }
}
