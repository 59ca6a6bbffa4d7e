//! The pinhole camera: where the image is seen from and how pixels map to rays.
//!
//! Conventions (shared with Mitsuba 3's `perspective` sensor with
//! `fov_axis = "y"` and a `box` reconstruction filter): row 0 is the top
//! row, x grows to the right, the vertical field of view is in degrees, and a
//! pixel's value is the plain average of the radiance over its square.

use glam::Vec3;
use serde::{Deserialize, Serialize};

/// A pinhole camera looking from `eye` towards `target`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Camera {
    /// Position of the pinhole in world space.
    pub eye: Vec3,
    /// Point the camera looks at, in world space.
    pub target: Vec3,
    /// Approximate up direction; re-orthogonalised against the view direction.
    pub up: Vec3,
    /// Vertical field of view in degrees, in (0, 180).
    pub fov_y_deg: f32,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
}

impl Default for Camera {
    fn default() -> Self {
        Self {
            eye: Vec3::new(0.0, 0.0, 4.0),
            target: Vec3::ZERO,
            up: Vec3::Y,
            fov_y_deg: 40.0,
            width: 256,
            height: 256,
        }
    }
}

/// The camera's orthonormal frame and image-plane scale, precomputed once per
/// render so that ray generation is a few multiply-adds.
#[derive(Clone, Copy, Debug)]
pub struct CameraFrame {
    /// Pinhole position.
    pub eye: Vec3,
    /// Unit view direction.
    pub forward: Vec3,
    /// Unit vector to the right of the image, scaled by the half-width of the
    /// image plane at distance one.
    pub right_scaled: Vec3,
    /// Unit vector to the top of the image, scaled by the half-height.
    pub up_scaled: Vec3,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
}

impl Camera {
    /// The frame used for ray generation. The camera must have been
    /// validated (eye ≠ target, up not parallel to the view).
    pub fn frame(&self) -> CameraFrame {
        let forward = (self.target - self.eye).normalize_or_zero();
        let right = forward.cross(self.up).normalize_or_zero();
        let up = right.cross(forward);
        let half_h = (self.fov_y_deg.to_radians() * 0.5).tan();
        let aspect = self.width as f32 / self.height.max(1) as f32;
        CameraFrame {
            eye: self.eye,
            forward,
            right_scaled: right * half_h * aspect,
            up_scaled: up * half_h,
            width: self.width,
            height: self.height,
        }
    }
}

impl CameraFrame {
    /// Unit direction of the ray through image position (`px`, `py`) in
    /// pixel units: (0, 0) is the top-left corner of the image, (width,
    /// height) the bottom-right.
    pub fn ray_dir(&self, px: f32, py: f32) -> Vec3 {
        let sx = 2.0 * px / self.width as f32 - 1.0;
        let sy = 1.0 - 2.0 * py / self.height as f32;
        (self.forward + self.right_scaled * sx + self.up_scaled * sy).normalize()
    }

    /// Projects a world point to image position in pixel units (same
    /// convention as [`CameraFrame::ray_dir`]); `None` behind the camera.
    pub fn project(&self, p: Vec3) -> Option<(f32, f32)> {
        let v = p - self.eye;
        let z = v.dot(self.forward);
        if z <= 1e-6 {
            return None;
        }
        let sx = v.dot(self.right_scaled) / self.right_scaled.length_squared() / z;
        let sy = v.dot(self.up_scaled) / self.up_scaled.length_squared() / z;
        Some((
            (sx + 1.0) * 0.5 * self.width as f32,
            (1.0 - sy) * 0.5 * self.height as f32,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centre_pixel_looks_at_target_and_projection_inverts() {
        let cam = Camera {
            width: 64,
            height: 32,
            ..Camera::default()
        };
        let f = cam.frame();
        let d = f.ray_dir(32.0, 16.0);
        assert!((d - Vec3::new(0.0, 0.0, -1.0)).length() < 1e-6);
        // +x in world is to the right, +y is up (towards row 0).
        let right = f.ray_dir(60.0, 16.0);
        assert!(right.x > 0.0);
        let top = f.ray_dir(32.0, 1.0);
        assert!(top.y > 0.0);
        let p = f.eye + f.ray_dir(10.5, 7.25) * 3.0;
        let (x, y) = f.project(p).unwrap();
        assert!((x - 10.5).abs() < 1e-3 && (y - 7.25).abs() < 1e-3);
    }
}
