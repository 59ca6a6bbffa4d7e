//! The procedural cloud: fractal gradient noise carved by an ellipsoid,
//! baked into a voxel grid at load time.
//!
//! Baking makes the procedural cloud a grid like any other, so both
//! renderers, the majorant grid and an exported `.vol` for another renderer
//! all see exactly the same `ρ` ([method §1](crate::doc::method): a procedural field or a voxel
//! grid, trilinearly interpolated).

use std::path::Path;

use glam::{UVec3, Vec3};
use rayon::prelude::*;

use super::{CloudParams, SceneError, VoxelGrid};

/// Largest accepted bake resolution along the longest axis.
pub const MAX_CLOUD_RESOLUTION: u32 = 512;

/// Checks the cloud's knobs; `path` names the scene in the error.
pub fn validate(p: &CloudParams, path: &Path) -> Result<(), SceneError> {
    let field = |name: &str| format!("medium.density.Cloud.{name}");
    if !(p.center.is_finite() && p.size.is_finite() && p.size.min_element() > 0.0) {
        return Err(SceneError::invalid(
            path,
            &field("size"),
            "centre must be finite and size positive on every axis",
        ));
    }
    if !(2..=MAX_CLOUD_RESOLUTION).contains(&p.resolution) {
        return Err(SceneError::invalid(
            path,
            &field("resolution"),
            format!("{} is outside 2..={MAX_CLOUD_RESOLUTION}", p.resolution),
        ));
    }
    if !(1..=10).contains(&p.octaves) {
        return Err(SceneError::invalid(
            path,
            &field("octaves"),
            format!("{} is outside 1..=10", p.octaves),
        ));
    }
    for (name, v, lo, hi) in [
        ("coverage", p.coverage, 0.0, 1.0),
        ("frequency", p.frequency, 0.01, 64.0),
        ("roughness", p.roughness, 0.0, 4.0),
        ("softness", p.softness, 0.0, 1.0),
        ("flat_base", p.flat_base, 0.0, 1.0),
    ] {
        if !(v.is_finite() && v >= lo && v <= hi) {
            return Err(SceneError::invalid(
                path,
                &field(name),
                format!("{v} is outside [{lo}, {hi}]"),
            ));
        }
    }
    Ok(())
}

/// Bakes the cloud into a grid whose longest axis has `resolution` voxels.
pub fn bake(p: &CloudParams) -> VoxelGrid {
    let longest = p.size.max_element();
    let dims = (p.size / longest * p.resolution as f32)
        .ceil()
        .max(Vec3::splat(2.0))
        .as_uvec3();
    let bounds_min = p.center - p.size * 0.5;
    let bounds_max = p.center + p.size * 0.5;
    let noise = Noise::new(p.seed);
    let voxel = p.size / dims.as_vec3();
    let n = dims.x as usize * dims.y as usize * dims.z as usize;
    let mut data = vec![0.0f32; n];
    let plane = dims.x as usize * dims.y as usize;
    data.par_chunks_mut(plane)
        .enumerate()
        .for_each(|(k, slab)| {
            for j in 0..dims.y as usize {
                for i in 0..dims.x as usize {
                    let centre = bounds_min
                        + voxel * (UVec3::new(i as u32, j as u32, k as u32).as_vec3() + 0.5);
                    // Unit-ellipsoid coordinates.
                    let q = (centre - p.center) / (p.size * 0.5);
                    slab[i + dims.x as usize * j] = density_at(p, &noise, q);
                }
            }
        });
    VoxelGrid {
        dims,
        bounds_min,
        bounds_max,
        data,
    }
}

/// Cloud density at unit-ellipsoid coordinates `q` (|q| = 1 on the surface).
fn density_at(p: &CloudParams, noise: &Noise, q: Vec3) -> f32 {
    // Squash the lower half so the base flattens.
    let mut s = q;
    if s.y < 0.0 {
        s.y *= 1.0 + 2.5 * p.flat_base;
    }
    let shape = 1.0 - s.length();
    let mut sum = 0.0;
    let mut amp = 0.5;
    let mut freq = p.frequency;
    for _ in 0..p.octaves {
        sum += amp * noise.gradient(q * freq);
        amp *= 0.5;
        freq *= 2.0;
    }
    // Billowy: the noise pushes the surface in and out.
    let v = shape + p.roughness * sum - (1.0 - p.coverage) * 0.6;
    let edge = p.softness.max(1e-4);
    let x = (v / edge).clamp(0.0, 1.0);
    // Keep the outer shell of voxels empty so the grid is clean at its box.
    let fade = ((1.0 - q.abs().max_element()) * 8.0).clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x) * fade
}

/// Perlin-style gradient noise with a seeded permutation.
struct Noise {
    perm: [u8; 512],
}

impl Noise {
    fn new(seed: u32) -> Self {
        let mut p: [u8; 256] = std::array::from_fn(|i| i as u8);
        let mut state = seed as u64 ^ 0x9E37_79B9_7F4A_7C15;
        for i in (1..256).rev() {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let j = ((state >> 33) % (i as u64 + 1)) as usize;
            p.swap(i, j);
        }
        let mut perm = [0u8; 512];
        for i in 0..512 {
            perm[i] = p[i & 255];
        }
        Self { perm }
    }

    fn grad(hash: u8, x: f32, y: f32, z: f32) -> f32 {
        let h = hash & 15;
        let u = if h < 8 { x } else { y };
        let v = if h < 4 {
            y
        } else if h == 12 || h == 14 {
            x
        } else {
            z
        };
        (if h & 1 == 0 { u } else { -u }) + (if h & 2 == 0 { v } else { -v })
    }

    /// Noise in roughly [-1, 1].
    fn gradient(&self, p: Vec3) -> f32 {
        let f = p.floor();
        let (xi, yi, zi) = (
            (f.x as i32 & 255) as usize,
            (f.y as i32 & 255) as usize,
            (f.z as i32 & 255) as usize,
        );
        let r = p - f;
        let fade = |t: f32| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
        let (u, v, w) = (fade(r.x), fade(r.y), fade(r.z));
        let pm = &self.perm;
        let a = pm[xi] as usize + yi;
        let aa = pm[a] as usize + zi;
        let ab = pm[a + 1] as usize + zi;
        let b = pm[xi + 1] as usize + yi;
        let ba = pm[b] as usize + zi;
        let bb = pm[b + 1] as usize + zi;
        let lerp = |t: f32, a: f32, b: f32| a + t * (b - a);
        let (x, y, z) = (r.x, r.y, r.z);
        lerp(
            w,
            lerp(
                v,
                lerp(
                    u,
                    Self::grad(pm[aa], x, y, z),
                    Self::grad(pm[ba], x - 1.0, y, z),
                ),
                lerp(
                    u,
                    Self::grad(pm[ab], x, y - 1.0, z),
                    Self::grad(pm[bb], x - 1.0, y - 1.0, z),
                ),
            ),
            lerp(
                v,
                lerp(
                    u,
                    Self::grad(pm[aa + 1], x, y, z - 1.0),
                    Self::grad(pm[ba + 1], x - 1.0, y, z - 1.0),
                ),
                lerp(
                    u,
                    Self::grad(pm[ab + 1], x, y - 1.0, z - 1.0),
                    Self::grad(pm[bb + 1], x - 1.0, y - 1.0, z - 1.0),
                ),
            ),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_cloud_is_a_cloud() {
        let p = CloudParams {
            resolution: 48,
            ..CloudParams::default()
        };
        let g = bake(&p);
        let filled = g.data.iter().filter(|&&v| v > 0.01).count() as f32 / g.data.len() as f32;
        // Neither empty nor a solid block, zero at the border, in [0, 1].
        assert!(filled > 0.05 && filled < 0.6, "filled fraction {filled}");
        assert!(g.data.iter().all(|v| (0.0..=1.0).contains(v)));
        assert_eq!(g.data[0], 0.0);
        // Same seed, same cloud; another seed, another cloud.
        assert_eq!(bake(&p).data, g.data);
        let other = bake(&CloudParams { seed: 8, ..p });
        assert_ne!(other.data, g.data);
    }
}
