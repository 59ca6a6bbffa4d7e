//! A small, 32-bit random number generator with independent streams.
//!
//! PCG-RXS-M-XS-32 (O'Neill 2014): 32-bit state, so the WGSL mirror can
//! produce the same numbers without 64-bit integers. Each pixel of each
//! pass gets its own stream, seeded by hashing (seed, pixel, pass), so a
//! render reproduces whatever the thread count or the order of work.

/// The LCG's multiplier, its inverse modulo 2³² (to step a stream back)
/// and its increment; generated into the WGSL (`RNG_MULTIPLIER`, …) by
/// [`crate::gpu::shaders::WGSL_CONSTANTS`].
pub const MULTIPLIER: u32 = 747_796_405;
/// See [`MULTIPLIER`].
pub const INVERSE_MULTIPLIER: u32 = 3_425_435_293;
/// See [`MULTIPLIER`].
pub const INCREMENT: u32 = 2_891_336_453;

/// PCG's output permutation (RXS-M-XS) of one LCG state.
#[inline]
fn permute(state: u32) -> u32 {
    let word = ((state >> ((state >> 28) + 4)) ^ state).wrapping_mul(277_803_737);
    (word >> 22) ^ word
}

/// One stream of uniform random numbers.
#[derive(Clone, Debug)]
pub struct Rng {
    state: u32,
}

/// A 32-bit integer hash (the PCG output permutation applied to an LCG step;
/// Jarzynski & Olano 2020, "Hash Functions for GPU Rendering").
#[inline]
pub fn pcg_hash(v: u32) -> u32 {
    permute(v.wrapping_mul(MULTIPLIER).wrapping_add(INCREMENT))
}

impl Rng {
    /// A stream from a raw 32-bit state.
    pub fn from_state(state: u32) -> Self {
        Self { state }
    }

    /// The stream of sample `index` in `pass` of a render with `seed`:
    /// depends on these three numbers only.
    pub fn for_sample(seed: u64, index: u32, pass: u32) -> Self {
        let s = pcg_hash((seed as u32) ^ pcg_hash((seed >> 32) as u32));
        let s = pcg_hash(index ^ s);
        let s = pcg_hash(pass.wrapping_add(s));
        Self { state: s }
    }

    /// The next 32 random bits.
    #[inline]
    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old.wrapping_mul(MULTIPLIER).wrapping_add(INCREMENT);
        permute(old)
    }

    /// A uniform number in [0, 1).
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        unit(self.next_u32())
    }

    /// The number [`Rng::next_u32`] returned last, stepping the stream back
    /// over it: the LCG run backwards. A pass that draws a block of numbers up front
    /// and uses them in reverse order reads them back this way without
    /// storing them (the GPU gather's jitters).
    #[inline]
    pub fn previous_u32(&mut self) -> u32 {
        self.state = self
            .state
            .wrapping_sub(INCREMENT)
            .wrapping_mul(INVERSE_MULTIPLIER);
        permute(self.state)
    }

    /// [`Rng::previous_u32`] as a uniform number in [0, 1), the same
    /// number [`Rng::next_f32`] made of it.
    #[inline]
    pub fn previous_f32(&mut self) -> f32 {
        unit(self.previous_u32())
    }
}

/// The uniform number in [0, 1) that 32 random bits make (their top 24).
#[inline]
pub(crate) fn unit(bits: u32) -> f32 {
    (bits >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// The steps of the R₂ sequence, `1/φ₂` and `1/φ₂²` (`φ₂` the plastic
/// number, `φ₂³ = φ₂ + 1`; Roberts 2018), in 32-bit fixed point, so that
/// its points wrap exactly on both backends; generated into the WGSL.
pub const R2_STEPS: [u32; 2] = [3_242_174_889, 2_447_445_414];

/// The "pass" of the stream that holds each pixel's offset of
/// [`pixel_jitter`]: one no render reaches; generated into the WGSL.
pub const PIXEL_OFFSET_STREAM: u32 = u32::MAX;

/// Where in pixel `index` (`[0, 1)²`) the camera ray of `pass` goes in a
/// render with `seed`: point `pass` of the R₂ low-discrepancy sequence,
/// shifted (modulo 1) by an offset drawn per seed and pixel.
///
/// Each pass's point is uniform over the pixel (the offset is), so every
/// pass stays an unbiased estimate; over the passes the points spread
/// evenly instead of clumping, so that what the pixel's footprint holds
/// (an edge of a puff, wisps finer than a pixel) averages out faster than
/// with independent points. This matters most to a renderer of few,
/// costly passes: `lantern noise` put the footprint's share of one
/// internal-lights pass's variance at 11 % on the wispy smoke, 21 % on
/// the plume and 28 % on the thick sphere.
#[inline]
pub fn pixel_jitter(seed: u64, index: u32, pass: u32) -> (f32, f32) {
    let mut offset = Rng::for_sample(seed, index, PIXEL_OFFSET_STREAM);
    let (ox, oy) = (offset.next_u32(), offset.next_u32());
    (
        unit(ox.wrapping_add(pass.wrapping_mul(R2_STEPS[0]))),
        unit(oy.wrapping_add(pass.wrapping_mul(R2_STEPS[1]))),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each pass's point is uniform over the pixel (over pixels: 64 cells
    /// of the unit square, χ² at 63 dof), and one pixel's first 64 passes
    /// fill its 8×8 cells far more evenly than independent points (empty
    /// cells over 2000 random offsets: 7–13, median 10; 64 independent
    /// points leave 13–31, median 23).
    #[test]
    fn pixel_jitter_is_uniform_per_pass_and_spread_over_passes() {
        let cell = |(x, y): (f32, f32)| {
            assert!((0.0..1.0).contains(&x) && (0.0..1.0).contains(&y));
            (x * 8.0) as usize * 8 + (y * 8.0) as usize
        };
        for pass in [0u32, 1, 17, 1000] {
            let mut counts = [0u32; 64];
            let n = 64_000u32;
            for index in 0..n {
                counts[cell(pixel_jitter(3, index, pass))] += 1;
            }
            let e = f64::from(n) / 64.0;
            let chi2: f64 = counts.iter().map(|&c| (f64::from(c) - e).powi(2) / e).sum();
            // 63 dof: mean 63, sd 11.2; 120 is beyond 5 sd.
            assert!(chi2 < 120.0, "pass {pass}: chi2 {chi2}");
        }
        for index in [0u32, 5, 999] {
            let mut seen = [false; 64];
            for pass in 0..64 {
                seen[cell(pixel_jitter(3, index, pass))] = true;
            }
            let empty = seen.iter().filter(|&&s| !s).count();
            assert!(empty <= 13, "pixel {index}: {empty} empty cells");
        }
    }

    #[test]
    fn stepping_back_returns_the_same_numbers_in_reverse() {
        let mut r = Rng::for_sample(7, 11, 13);
        let start = r.clone();
        let ahead: Vec<f32> = (0..1000).map(|_| r.next_f32()).collect();
        let mut back = r.clone();
        let behind: Vec<f32> = (0..1000).map(|_| back.previous_f32()).collect();
        assert!(ahead.iter().rev().eq(behind.iter()));
        assert_eq!(back.state, start.state);
        assert_eq!(r.next_u32(), {
            let mut again = back.clone();
            for _ in 0..1000 {
                again.next_u32();
            }
            again.next_u32()
        });
    }

    #[test]
    fn uniform_moments_and_streams_differ() {
        let mut r = Rng::for_sample(1, 2, 3);
        let n = 200_000;
        let (mut s, mut s2) = (0.0f64, 0.0f64);
        for _ in 0..n {
            let x = r.next_f32() as f64;
            assert!((0.0..1.0).contains(&x));
            s += x;
            s2 += x * x;
        }
        let mean = s / n as f64;
        let var = s2 / n as f64 - mean * mean;
        assert!((mean - 0.5).abs() < 0.005, "mean {mean}");
        assert!((var - 1.0 / 12.0).abs() < 0.002, "var {var}");
        let a: Vec<u32> = (0..8)
            .map(|_| Rng::for_sample(1, 2, 3).next_u32())
            .collect();
        assert!(a.windows(2).all(|w| w[0] == w[1]));
        assert_ne!(
            Rng::for_sample(1, 2, 3).next_u32(),
            Rng::for_sample(1, 2, 4).next_u32()
        );
        assert_ne!(
            Rng::for_sample(1, 2, 3).next_u32(),
            Rng::for_sample(1, 3, 3).next_u32()
        );
        assert_ne!(
            Rng::for_sample(1, 2, 3).next_u32(),
            Rng::for_sample(2, 2, 3).next_u32()
        );
    }
}
