//! The reference path tracer on the CPU (METHOD.md §2): one call per
//! camera sample of [`crate::physics::reference::radiance`].

use glam::Vec3;

use crate::physics::reference::radiance;
use crate::physics::rng::Rng;
use crate::render::Prepared;

/// One radiance sample along the camera ray `eye + t dir`.
#[inline]
pub fn sample(prepared: &Prepared, eye: Vec3, dir: Vec3, rng: &mut Rng) -> Vec3 {
    radiance(&prepared.volume, &prepared.lights, eye, dir, u32::MAX, rng)
}
