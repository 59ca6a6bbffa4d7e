//! The Henyey–Greenstein phase function ([method §1](crate::doc::method)).
//!
//! `P(μ) = (1 − g²) / (4π (1 + g² − 2gμ)^{3/2})`, where `μ` is the cosine
//! between the directions light travels before and after scattering; `g > 0`
//! scatters forward. This is Mitsuba 3's `hg` convention. The function is
//! symmetric under reversal, so a backward path samples its next direction
//! around its current one with the same density.

use std::f32::consts::PI;

use glam::Vec3;

use super::frame;

/// Below this |g| the function is treated as isotropic when sampling.
pub const ISOTROPIC_EPS: f32 = 1e-3;

/// `P(μ)` in 1/sr.
#[inline]
pub fn hg(g: f32, cos_theta: f32) -> f32 {
    let denom = 1.0 + g * g - 2.0 * g * cos_theta;
    (1.0 - g * g) / (4.0 * PI * denom * denom.sqrt())
}

/// Samples the cosine between the incoming and the scattered direction with
/// density proportional to `P(μ)`.
#[inline]
pub fn sample_hg_cos(g: f32, u: f32) -> f32 {
    if g.abs() < ISOTROPIC_EPS {
        return 1.0 - 2.0 * u;
    }
    let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u);
    ((1.0 + g * g - s * s) / (2.0 * g)).clamp(-1.0, 1.0)
}

/// Samples a scattered direction around `dir` (unit). Its pdf in solid
/// angle is `hg(g, dir · result)`, so a path's weight does not change.
#[inline]
pub fn sample_hg(g: f32, dir: Vec3, u1: f32, u2: f32) -> Vec3 {
    let cos_theta = sample_hg_cos(g, u1);
    frame::from_spherical(dir, cos_theta, 2.0 * PI * u2)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::rng::Rng;

    const GS: [f32; 4] = [-0.95, 0.0, 0.5, 0.95];

    /// ∫ P dΩ = 2π ∫ P(μ) dμ by composite Simpson on a grid refined near
    /// the forward (or backward) peak through the substitution μ = 1 − 2x².
    fn integral(g: f32) -> f64 {
        let n = 200_000;
        let f = |mu: f64| {
            let g = g as f64;
            (1.0 - g * g) / (4.0 * std::f64::consts::PI * (1.0 + g * g - 2.0 * g * mu).powf(1.5))
        };
        // μ = 1 − 2x², x ∈ [0, 1]: dμ = −4x dx.
        let h = 1.0 / n as f64;
        let mut s = 0.0;
        for i in 0..=n {
            let x = i as f64 * h;
            let w = if i == 0 || i == n {
                1.0
            } else if i % 2 == 1 {
                4.0
            } else {
                2.0
            };
            s += w * f(1.0 - 2.0 * x * x) * 4.0 * x;
        }
        2.0 * std::f64::consts::PI * s * h / 3.0
    }

    #[test]
    fn hg_integrates_to_one() {
        for g in GS {
            let i = integral(g);
            assert!((i - 1.0).abs() < 1e-4, "g={g}: ∫P dΩ = {i}");
        }
    }

    #[test]
    fn hg_sign_convention_is_forward_for_positive_g() {
        assert!(hg(0.5, 1.0) > hg(0.5, -1.0));
        assert!(hg(-0.5, 1.0) < hg(-0.5, -1.0));
        assert!((hg(0.0, 0.3) - 1.0 / (4.0 * PI)).abs() < 1e-7);
    }

    /// Histogram of sampled μ against the pdf 2π P(μ) integrated over each
    /// bin, with a χ² statistic; and the sampled mean cosine equals g.
    #[test]
    fn sampling_matches_pdf() {
        for g in GS {
            let mut rng = Rng::for_sample(42, 0, (g * 100.0) as i32 as u32);
            let n = 400_000usize;
            let bins = 40usize;
            let mut hist = vec![0usize; bins];
            let mut mean = 0.0f64;
            let dir = Vec3::new(0.2, -0.4, 0.9).normalize();
            for _ in 0..n {
                let w = sample_hg(g, dir, rng.next_f32(), rng.next_f32());
                assert!((w.length() - 1.0).abs() < 1e-4);
                let mu = w.dot(dir).clamp(-1.0, 1.0);
                mean += mu as f64;
                let b = (((mu + 1.0) * 0.5 * bins as f32) as usize).min(bins - 1);
                hist[b] += 1;
            }
            mean /= n as f64;
            assert!((mean - g as f64).abs() < 0.005, "g={g}: mean cos {mean}");
            let mut chi2 = 0.0;
            let mut dof = 0;
            for (b, &count) in hist.iter().enumerate() {
                // Expected probability of the bin from the closed-form CDF
                // F(μ) = (1 − g²)/(2g) · [1/√(1 + g² − 2gμ) − 1/(1 + g)].
                let cdf = |mu: f64| {
                    let g = g as f64;
                    if g.abs() < 1e-6 {
                        0.5 * (mu + 1.0)
                    } else {
                        (1.0 - g * g) / (2.0 * g)
                            * (1.0 / (1.0 + g * g - 2.0 * g * mu).sqrt() - 1.0 / (1.0 + g))
                    }
                };
                let (a, c) = (
                    -1.0 + 2.0 * b as f64 / bins as f64,
                    -1.0 + 2.0 * (b + 1) as f64 / bins as f64,
                );
                let prob = cdf(c) - cdf(a);
                let expected = prob * n as f64;
                if expected < 5.0 {
                    continue;
                }
                chi2 += (count as f64 - expected).powi(2) / expected;
                dof += 1;
            }
            // 99.9th percentile of χ² with ≤ 39 dof is below 73.4.
            assert!(chi2 < 73.4, "g={g}: χ² = {chi2} over {dof} bins");
        }
    }
}
