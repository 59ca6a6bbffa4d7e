// The medium as the estimators see it (src/doc/method.md §1). Mirrors
// src/physics/volume.rs, with the density sources of src/scene/mod.rs
// (`Density`) and the voxel lookup of src/scene/grid.rs.

// A large finite stand-in for infinity (WGSL has no infinity literal).
const BIG: f32 = 3.0e38;

// One voxel of the grid (`VoxelGrid::data`, x fastest), read without filtering: the
// trilinear weights are computed below exactly as on the CPU.
fn voxel(x: u32, y: u32, z: u32) -> f32 {
    return textureLoad(density_voxels, vec3<u32>(x, y, z), 0).x;
}

// Clamped, cell-centred trilinear lookup of the voxel grid at world point
// `p` (`VoxelGrid::sample`): voxel centres sit at integer coordinates.
fn grid_sample(p: vec3<f32>) -> f32 {
    let m = scene.medium;
    let dims = m.grid_dims;
    let top = dims - vec3<u32>(1u);
    let u = clamp(
        (p - m.shape_a) / (m.shape_b - m.shape_a) * vec3<f32>(dims) - vec3<f32>(0.5),
        vec3<f32>(0.0),
        vec3<f32>(top),
    );
    let i0 = min(vec3<u32>(floor(u)), top);
    let i1 = min(i0 + vec3<u32>(1u), top);
    let f = u - vec3<f32>(i0);
    let c00 = voxel(i0.x, i0.y, i0.z) * (1.0 - f.x) + voxel(i1.x, i0.y, i0.z) * f.x;
    let c10 = voxel(i0.x, i1.y, i0.z) * (1.0 - f.x) + voxel(i1.x, i1.y, i0.z) * f.x;
    let c01 = voxel(i0.x, i0.y, i1.z) * (1.0 - f.x) + voxel(i1.x, i0.y, i1.z) * f.x;
    let c11 = voxel(i0.x, i1.y, i1.z) * (1.0 - f.x) + voxel(i1.x, i1.y, i1.z) * f.x;
    let c0 = c00 * (1.0 - f.y) + c10 * f.y;
    let c1 = c01 * (1.0 - f.y) + c11 * f.y;
    return c0 * (1.0 - f.z) + c1 * f.z;
}

// `ρ` at world point `p` (`Density::density`).
fn density(p: vec3<f32>) -> f32 {
    let m = scene.medium;
    switch m.density_kind {
        case DENSITY_SPHERE: {
            let v = p - m.shape_a;
            return select(0.0, 1.0, dot(v, v) <= m.radius * m.radius);
        }
        case DENSITY_BOX: {
            return select(0.0, 1.0, all(p >= m.shape_a) && all(p <= m.shape_b));
        }
        default: {
            if all(p >= m.shape_a) && all(p <= m.shape_b) {
                return grid_sample(p);
            }
            return 0.0;
        }
    }
}

// Extinction `c(p)` per channel (`Volume::sigma_t`).
fn medium_sigma_t(p: vec3<f32>) -> vec3<f32> {
    return scene.medium.sigma_t * density(p);
}

// The interval where a ray is inside a box (`ray_box`).
struct Interval {
    t0: f32,
    t1: f32,
    hit: bool,
}

// Slab test: `[t0, t1]`, `t0 ≥ 0`, where `origin + t dir` is inside
// `[lo, hi]` (`ray_box`). An axis with a zero direction component either
// constrains nothing (origin inside its slab) or misses, as on the CPU where
// IEEE infinities do the same.
fn ray_box(origin: vec3<f32>, dir: vec3<f32>, lo: vec3<f32>, hi: vec3<f32>) -> Interval {
    let zero = dir == vec3<f32>(0.0);
    let inv = 1.0 / select(dir, vec3<f32>(1.0), zero);
    let a = (lo - origin) * inv;
    let b = (hi - origin) * inv;
    let inside = (origin >= lo) & (origin <= hi);
    let near = select(min(a, b), select(vec3<f32>(BIG), vec3<f32>(-BIG), inside), zero);
    let far = select(max(a, b), select(vec3<f32>(-BIG), vec3<f32>(BIG), inside), zero);
    let t0 = max(max(max(near.x, near.y), near.z), 0.0);
    let t1 = min(min(far.x, far.y), far.z);
    return Interval(t0, t1, t1 > t0);
}

// The interval in which the ray is inside the medium's box
// (`Volume::clip`).
fn medium_clip(origin: vec3<f32>, dir: vec3<f32>) -> Interval {
    return ray_box(origin, dir, scene.medium.bounds_min, scene.medium.bounds_max);
}

// The largest of three channels (glam's `max_element`).
fn max_element(v: vec3<f32>) -> f32 {
    return max(max(v.x, v.y), v.z);
}
