//! Image statistics shared by the measuring commands, the previewer and
//! the tests: the image mean's relative error and the relative RMSE of one
//! image against another, the RMSE with the converged image's own noise
//! removed (per pixel and of 8×8 block means), and a per-pixel z-test of
//! two noisy images (in the manner of Mitsuba 3's regression tests). The
//! validation of the method against the reference ([method §7](crate::doc::method))
//! is measured with these.
//!
//! Pure functions on pixel slices; nothing here renders.

use glam::Vec3;

use crate::render::film::image_mean;

/// Relative mean error per channel and relative RMSE of `image` against
/// `reference`.
pub fn compare(image: &[Vec3], reference: &[Vec3]) -> (Vec3, f32) {
    let n = image.len().max(1) as f64;
    let mut mi = [0.0f64; 3];
    let mut mr = [0.0f64; 3];
    for (a, b) in image.iter().zip(reference) {
        for c in 0..3 {
            mi[c] += a[c] as f64;
            mr[c] += b[c] as f64;
        }
    }
    let err = Vec3::new(
        ((mi[0] - mr[0]) / mr[0].max(1e-30)) as f32,
        ((mi[1] - mr[1]) / mr[1].max(1e-30)) as f32,
        ((mi[2] - mr[2]) / mr[2].max(1e-30)) as f32,
    );
    let mean_ref = (mr[0] + mr[1] + mr[2]) / (3.0 * n);
    let rmse = (rmse(image, reference) / mean_ref.max(1e-30)) as f32;
    (err, rmse)
}

/// Root-mean-square difference of `image` and `reference` over pixels and
/// channels (absolute; 0 for empty images).
pub fn rmse(image: &[Vec3], reference: &[Vec3]) -> f64 {
    let n = image.len().max(1) as f64;
    let mut se = 0.0f64;
    for (a, b) in image.iter().zip(reference) {
        for c in 0..3 {
            se += ((a[c] - b[c]) as f64).powi(2);
        }
    }
    (se / (3.0 * n)).sqrt()
}

/// RMSE of `image` against `converged` relative to the converged mean,
/// with the converged image's own noise (`converged_var`, the variance of
/// its per-pixel mean) removed from the mean squared error (clamped at 0).
pub fn rmse_against(image: &[Vec3], converged: &[Vec3], converged_var: &[Vec3]) -> f32 {
    let n = image.len().max(1) as f64 * 3.0;
    let mut se = 0.0f64;
    let mut var = 0.0f64;
    let mut sum = 0.0f64;
    for ((a, b), v) in image.iter().zip(converged).zip(converged_var) {
        for c in 0..3 {
            se += ((a[c] - b[c]) as f64).powi(2);
            var += v[c] as f64;
            sum += b[c] as f64;
        }
    }
    let mean = (sum / n).max(1e-30);
    (((se - var) / n).max(0.0).sqrt() / mean) as f32
}

/// Side of the blocks of [`block_rmse_against`], in pixels.
pub const BLOCK: usize = 8;

/// [`rmse_against`] of the images' [`BLOCK`]×[`BLOCK`] block means (blocks
/// from the top-left corner; a partial block at the right or bottom edge is
/// left out), relative to the converged image's mean over those blocks:
/// how far the image is off at the scale of a block, its pixel noise
/// averaged down. The converged image's noise is removed as the variance
/// of its block means, `Σ Var[pixel] / BLOCK⁴` (independent pixels).
pub fn block_rmse_against(
    image: &[Vec3],
    converged: &[Vec3],
    converged_var: &[Vec3],
    width: usize,
    height: usize,
) -> f32 {
    let means = |img: &[Vec3], scale: f32| {
        let (bw, bh) = (width / BLOCK, height / BLOCK);
        let mut out = vec![Vec3::ZERO; bw * bh];
        for (b, o) in out.iter_mut().enumerate() {
            let (x0, y0) = ((b % bw) * BLOCK, (b / bw) * BLOCK);
            for y in y0..y0 + BLOCK {
                for x in x0..x0 + BLOCK {
                    *o += img[y * width + x];
                }
            }
            *o *= scale;
        }
        out
    };
    let n = (BLOCK * BLOCK) as f32;
    rmse_against(
        &means(image, 1.0 / n),
        &means(converged, 1.0 / n),
        &means(converged_var, 1.0 / (n * n)),
    )
}

/// The outcome of comparing two noisy images.
#[derive(Debug)]
pub struct Comparison {
    /// Image mean of the first image, per channel.
    pub mean_a: Vec3,
    /// Image mean of the second image, per channel.
    pub mean_b: Vec3,
    /// Relative difference of the means, per channel.
    pub rel_mean_diff: Vec3,
    /// Fraction of pixel channels whose |z| is below the threshold.
    pub z_pass_fraction: f64,
    /// RMSE of a against b, relative to b's mean (over channels).
    pub rel_rmse: f64,
}

/// Compares image `a` (variance of its mean per pixel `var_a`) with `b`
/// (`var_b`): per-pixel z = (a − b)/√(var_a + var_b), passing where |z| <
/// `z_max` (pixels where both variances vanish pass if they agree closely).
///
/// # Panics
///
/// If the images differ in size.
pub fn compare_noisy(
    a: &[Vec3],
    var_a: &[Vec3],
    b: &[Vec3],
    var_b: &[Vec3],
    z_max: f32,
) -> Comparison {
    assert_eq!(a.len(), b.len());
    let mean_a = image_mean(a);
    let mean_b = image_mean(b);
    let rel_mean_diff = (mean_a - mean_b).abs() / mean_b.max(Vec3::splat(1e-12));
    let mut pass = 0usize;
    let mut total = 0usize;
    for i in 0..a.len() {
        for c in 0..3 {
            let d = a[i][c] - b[i][c];
            let s = (var_a[i][c] + var_b[i][c]).sqrt();
            let ok = if s > 0.0 {
                (d / s).abs() < z_max
            } else {
                d.abs() <= 1e-6 * (1.0 + b[i][c].abs())
            };
            pass += ok as usize;
            total += 1;
        }
    }
    let rmse = rmse(a, b);
    let mb = (mean_b.x + mean_b.y + mean_b.z) as f64 / 3.0;
    Comparison {
        mean_a,
        mean_b,
        rel_mean_diff,
        z_pass_fraction: pass as f64 / total as f64,
        rel_rmse: rmse / mb.max(1e-12),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn converged_noise_is_removed_from_the_rmse() {
        let converged = vec![Vec3::splat(1.0); 4];
        // Errors of ±0.1 everywhere: RMSE 0.1; a converged variance of
        // 0.0064 explains 0.08² of it, leaving 0.06.
        let image: Vec<Vec3> = (0..4)
            .map(|i| Vec3::splat(if i % 2 == 0 { 1.1 } else { 0.9 }))
            .collect();
        let none = vec![Vec3::ZERO; 4];
        assert!((rmse_against(&image, &converged, &none) - 0.1).abs() < 1e-6);
        let var = vec![Vec3::splat(0.0064); 4];
        assert!((rmse_against(&image, &converged, &var) - 0.06).abs() < 1e-5);
        // Never negative.
        assert_eq!(rmse_against(&converged, &converged, &var), 0.0);
    }

    /// The block RMSE compares 8×8 blocks from the top-left corner: a ±0.2
    /// error on a 4×4 checkerboard cancels in every block (4×4 or 1×1
    /// blocks would see it), one on an 8×8 checkerboard is the whole block
    /// error (16×16 blocks, or 8×8 ones offset by 4, would average it
    /// away), a partial block at the edge is left out, and the converged
    /// image's block variance `Σ Var / 64²` is removed; the per-pixel RMSE
    /// sees both checkerboards alike.
    #[test]
    fn block_rmse_uses_eight_by_eight_blocks() {
        let (w, h) = (36, 24);
        let converged = vec![Vec3::splat(2.0); w * h];
        let none = vec![Vec3::ZERO; w * h];
        let checker = |tile: usize| -> Vec<Vec3> {
            (0..w * h)
                .map(|i| {
                    let (x, y) = (i % w, i / w);
                    if x >= 32 {
                        return Vec3::splat(50.0); // the partial block column
                    }
                    let sign = if (x / tile + y / tile).is_multiple_of(2) {
                        1.0
                    } else {
                        -1.0
                    };
                    Vec3::splat(2.0 + 0.2 * sign)
                })
                .collect()
        };
        let (fine, coarse) = (checker(4), checker(8));
        assert!(block_rmse_against(&fine, &converged, &none, w, h).abs() < 1e-6);
        let b = block_rmse_against(&coarse, &converged, &none, w, h);
        assert!((b - 0.1).abs() < 1e-5, "{b}");
        // Per pixel (the partial column left out too): 0.2 / 2 for both.
        let crop = |img: &[Vec3]| -> Vec<Vec3> {
            img.iter()
                .enumerate()
                .filter(|(i, _)| i % w < 32)
                .map(|(_, v)| *v)
                .collect()
        };
        let (c, z) = (crop(&converged), vec![Vec3::ZERO; 32 * h]);
        for img in [&fine, &coarse] {
            assert!((rmse_against(&crop(img), &c, &z) - 0.1).abs() < 1e-5);
        }
        // A block variance of 0.16² (per pixel 64 × 0.16²) leaves
        // √(0.2² − 0.16²) = 0.12 of the block error: 0.06 of the mean.
        let var = vec![Vec3::splat(64.0 * 0.16 * 0.16); w * h];
        let b = block_rmse_against(&coarse, &converged, &var, w, h);
        assert!((b - 0.06).abs() < 1e-4, "{b}");
    }
}
