//! A small, 32-bit random number generator with independent streams.
//!
//! PCG-RXS-M-XS-32 (O'Neill 2014): 32-bit state, so the WGSL mirror can
//! produce the same numbers without 64-bit integers. Each pixel of each
//! pass gets its own stream, seeded by hashing (seed, pixel, pass), so a
//! render reproduces whatever the thread count or the order of work.

/// The LCG's multiplier, its inverse modulo 2³² (to step a stream back)
/// and its increment; mirrored in `shaders/common/rng.wgsl`.
const MULTIPLIER: u32 = 747_796_405;
const INVERSE_MULTIPLIER: u32 = 3_425_435_293;
const INCREMENT: u32 = 2_891_336_453;

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

#[cfg(test)]
mod tests {
    use super::*;

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
