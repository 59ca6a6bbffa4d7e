//! Orthonormal frames around a direction, for sampling directions relative
//! to it.

use glam::Vec3;

/// Two unit vectors that complete `n` (unit) to a right-handed orthonormal
/// basis (Duff et al. 2017, "Building an Orthonormal Basis, Revisited").
#[inline]
pub fn basis(n: Vec3) -> (Vec3, Vec3) {
    let sign = 1.0f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (
        Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        Vec3::new(b, sign + n.y * n.y * a, -n.y),
    )
}

/// The unit direction with cosine `cos_theta` to `n` and azimuth `phi`.
#[inline]
pub fn from_spherical(n: Vec3, cos_theta: f32, phi: f32) -> Vec3 {
    let (t, b) = basis(n);
    let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
    let (s, c) = phi.sin_cos();
    (t * (sin_theta * c) + b * (sin_theta * s) + n * cos_theta).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn basis_is_orthonormal() {
        for n in [
            Vec3::X,
            Vec3::Y,
            Vec3::Z,
            -Vec3::Z,
            Vec3::new(0.3, -0.5, 0.8).normalize(),
            Vec3::new(1e-7, 0.0, -1.0).normalize(),
        ] {
            let (t, b) = basis(n);
            assert!((t.length() - 1.0).abs() < 1e-5);
            assert!((b.length() - 1.0).abs() < 1e-5);
            assert!(t.dot(b).abs() < 1e-5 && t.dot(n).abs() < 1e-5 && b.dot(n).abs() < 1e-5);
        }
    }
}
