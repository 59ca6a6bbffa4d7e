//! The progressive film: per-pixel sums of samples and of their squares, so
//! that every pass adds one sample per pixel and the image, its per-pixel
//! variance and its convergence can be read at any time.

use glam::Vec3;

/// Accumulated samples of an image. Row 0 is the top row.
#[derive(Clone, Debug)]
pub struct Film {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Sum of the samples per pixel (f64 so that long renders do not drift).
    sum: Vec<[f64; 3]>,
    /// Sum of the squared samples per pixel.
    sum_sq: Vec<[f64; 3]>,
    /// Samples per pixel accumulated so far.
    pub samples: u32,
}

impl Film {
    /// An empty film.
    pub fn new(width: u32, height: u32) -> Self {
        let n = width as usize * height as usize;
        Self {
            width,
            height,
            sum: vec![[0.0; 3]; n],
            sum_sq: vec![[0.0; 3]; n],
            samples: 0,
        }
    }

    /// A film from per-pixel moments accumulated elsewhere (the GPU's
    /// running means and sums of squared deviations, Welford's form) over
    /// `samples` samples: what [`Film::add_pass`] would have summed.
    pub fn from_moments(width: u32, height: u32, samples: u32, mean: &[Vec3], m2: &[Vec3]) -> Self {
        let n = samples as f64;
        let (sum, sum_sq) = mean
            .iter()
            .zip(m2)
            .map(|(m, d)| {
                let s = |c: usize| m[c] as f64 * n;
                let s2 = |c: usize| d[c].max(0.0) as f64 + n * (m[c] as f64).powi(2);
                ([s(0), s(1), s(2)], [s2(0), s2(1), s2(2)])
            })
            .unzip();
        Self {
            width,
            height,
            sum,
            sum_sq,
            samples,
        }
    }

    /// Number of pixels.
    pub fn len(&self) -> usize {
        self.sum.len()
    }

    /// Whether the film has no pixels.
    pub fn is_empty(&self) -> bool {
        self.sum.is_empty()
    }

    /// Adds one pass: exactly one sample for every pixel, in row-major order.
    /// Non-finite channels are dropped (counted as zero) rather than poisoning
    /// the pixel forever.
    pub fn add_pass(&mut self, pass: &[Vec3]) {
        debug_assert_eq!(pass.len(), self.sum.len());
        for ((s, s2), v) in self.sum.iter_mut().zip(self.sum_sq.iter_mut()).zip(pass) {
            for c in 0..3 {
                let x = if v[c].is_finite() { v[c] as f64 } else { 0.0 };
                s[c] += x;
                s2[c] += x * x;
            }
        }
        self.samples += 1;
    }

    /// Adds another film's samples (same size) to this one.
    pub fn merge(&mut self, other: &Film) {
        for (a, b) in self.sum.iter_mut().zip(&other.sum) {
            for c in 0..3 {
                a[c] += b[c];
            }
        }
        for (a, b) in self.sum_sq.iter_mut().zip(&other.sum_sq) {
            for c in 0..3 {
                a[c] += b[c];
            }
        }
        self.samples += other.samples;
    }

    /// The mean image (zeros before the first pass).
    pub fn mean(&self) -> Vec<Vec3> {
        let inv = 1.0 / self.samples.max(1) as f64;
        self.sum
            .iter()
            .map(|s| {
                Vec3::new(
                    (s[0] * inv) as f32,
                    (s[1] * inv) as f32,
                    (s[2] * inv) as f32,
                )
            })
            .collect()
    }

    /// The variance of each pixel's mean (sample variance / samples); zero
    /// with fewer than two samples.
    pub fn variance_of_mean(&self) -> Vec<Vec3> {
        let n = self.samples as f64;
        if n < 2.0 {
            return vec![Vec3::ZERO; self.sum.len()];
        }
        self.sum
            .iter()
            .zip(&self.sum_sq)
            .map(|(s, s2)| {
                let v = |c: usize| {
                    let mean = s[c] / n;
                    ((s2[c] / n - mean * mean).max(0.0) * n / (n - 1.0) / n) as f32
                };
                Vec3::new(v(0), v(1), v(2))
            })
            .collect()
    }

    /// Mean over all pixels, per channel.
    pub fn image_mean(&self) -> Vec3 {
        image_mean(&self.mean())
    }
}

/// Mean over all pixels of an image, per channel (accumulated in f64).
pub fn image_mean(pixels: &[Vec3]) -> Vec3 {
    let mut s = [0.0f64; 3];
    for p in pixels {
        for c in 0..3 {
            s[c] += p[c] as f64;
        }
    }
    let n = pixels.len().max(1) as f64;
    Vec3::new((s[0] / n) as f32, (s[1] / n) as f32, (s[2] / n) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_and_variance_of_two_passes() {
        let mut f = Film::new(2, 1);
        f.add_pass(&[Vec3::splat(1.0), Vec3::splat(2.0)]);
        f.add_pass(&[Vec3::splat(3.0), Vec3::new(2.0, f32::NAN, 2.0)]);
        let m = f.mean();
        assert_eq!(m[0], Vec3::splat(2.0));
        assert_eq!(m[1], Vec3::new(2.0, 1.0, 2.0));
        let v = f.variance_of_mean();
        // Samples 1 and 3: sample variance 2, variance of the mean 1.
        assert!((v[0].x - 1.0).abs() < 1e-6);
        assert_eq!(v[1].x, 0.0);
    }

    /// Welford moments (as the GPU keeps them) give the film that summing
    /// the samples gives.
    #[test]
    fn from_moments_matches_add_pass() {
        let samples = [1.0f32, 4.0, 2.5, -0.5];
        let mut f = Film::new(1, 1);
        let (mut mean, mut m2) = (0.0f32, 0.0f32);
        for (i, &x) in samples.iter().enumerate() {
            f.add_pass(&[Vec3::splat(x)]);
            let delta = x - mean;
            mean += delta / (i + 1) as f32;
            m2 += delta * (x - mean);
        }
        let g = Film::from_moments(1, 1, 4, &[Vec3::splat(mean)], &[Vec3::splat(m2)]);
        assert_eq!(g.samples, f.samples);
        assert!((g.mean()[0] - f.mean()[0]).abs().max_element() < 1e-6);
        assert!(
            (g.variance_of_mean()[0] - f.variance_of_mean()[0])
                .abs()
                .max_element()
                < 1e-6
        );
    }
}
