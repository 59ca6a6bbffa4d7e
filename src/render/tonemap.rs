//! Display transforms: from linear scene radiance to 8-bit sRGB.
//!
//! An exposure in stops scales the radiance by `2^stops`; a view transform
//! then maps it to [0, 1] and the sRGB transfer function encodes it:
//!
//! - `Clamp`: the plain sRGB view — linear values above 1 clip.
//! - `Filmic`: Narkowicz's fit of the ACES filmic curve
//!   `f(x) = x(2.51x + 0.03) / (x(2.43x + 0.59) + 0.14)`, applied per
//!   channel and clamped to 1, which rolls highlights off smoothly
//!   instead of clipping at 1.
//!
//! These are for display and PNG only; EXR export stays linear.

use glam::Vec3;
use serde::{Deserialize, Serialize};

/// How linear radiance is mapped to display values.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
pub enum ViewTransform {
    /// Linear, clipped at 1, sRGB-encoded.
    Clamp,
    /// ACES-like filmic curve (Narkowicz 2015), sRGB-encoded.
    #[default]
    Filmic,
}

/// The sRGB opto-electronic transfer function (IEC 61966-2-1).
#[inline]
pub fn srgb_encode(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// The filmic curve, mapping [0, ∞) onto [0, 1] (the fit overshoots 1
/// above x ≈ 10.4 and is clamped there).
#[inline]
pub fn filmic(x: f32) -> f32 {
    let x = x.max(0.0);
    ((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14)).min(1.0)
}

/// Maps one linear pixel to display-referred sRGB in [0, 1].
#[inline]
pub fn to_display(linear: Vec3, exposure_stops: f32, view: ViewTransform) -> Vec3 {
    let v = linear * exposure_stops.exp2();
    let v = match view {
        ViewTransform::Clamp => v,
        ViewTransform::Filmic => Vec3::new(filmic(v.x), filmic(v.y), filmic(v.z)),
    };
    Vec3::new(srgb_encode(v.x), srgb_encode(v.y), srgb_encode(v.z))
}

/// Maps a linear image to 8-bit sRGB, row-major RGB.
pub fn to_srgb8(pixels: &[Vec3], exposure_stops: f32, view: ViewTransform) -> Vec<u8> {
    let mut out = Vec::with_capacity(pixels.len() * 3);
    for p in pixels {
        let d = to_display(*p, exposure_stops, view);
        for c in 0..3 {
            out.push((d[c] * 255.0 + 0.5) as u8);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn curves_are_monotone_and_bounded() {
        assert_eq!(srgb_encode(0.0), 0.0);
        assert!((srgb_encode(1.0) - 1.0).abs() < 1e-6);
        assert!((srgb_encode(0.18) - 0.4614).abs() < 1e-3);
        let mut last = -1.0;
        for i in 0..1000 {
            let y = filmic(i as f32 * 0.05);
            assert!(y >= last && y <= 1.0);
            last = y;
        }
        // One stop of exposure doubles the linear value.
        let a = to_display(Vec3::splat(0.1), 1.0, ViewTransform::Clamp);
        let b = to_display(Vec3::splat(0.2), 0.0, ViewTransform::Clamp);
        assert!((a - b).length() < 1e-6);
    }
}
