//! The medium as the estimators see it: a density field with its box,
//! RGB extinction and albedo, the phase function's `g`, and a majorant grid
//! ([method §1](crate::doc::method)).

use glam::Vec3;

use super::majorant::MajorantGrid;

/// A scalar density field `ρ(x) ≥ 0`, zero outside [`DensityField::bounds`].
pub trait DensityField: Send + Sync {
    /// `ρ` at world point `p`.
    fn density(&self, p: Vec3) -> f32;
    /// The box outside which `ρ = 0`, as (min, max).
    fn bounds(&self) -> (Vec3, Vec3);
    /// An upper bound of `ρ` over the box `[lo, hi]`.
    fn max_in_box(&self, lo: Vec3, hi: Vec3) -> f32;
}

/// Optical properties of the medium, per unit density.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Optics {
    /// Extinction per unit density, RGB (density scale already applied).
    pub sigma_t: Vec3,
    /// Single-scattering albedo, RGB.
    pub albedo: Vec3,
    /// Henyey–Greenstein asymmetry.
    pub g: f32,
}

/// A medium ready for tracking.
#[derive(Clone)]
pub struct Volume<D> {
    /// The density field.
    pub density: D,
    /// Optical properties.
    pub optics: Optics,
    /// Box outside which the medium is vacuum.
    pub bounds: (Vec3, Vec3),
    /// Piecewise-constant upper bound of the largest channel's extinction.
    pub majorants: MajorantGrid,
}

impl<D: DensityField> Volume<D> {
    /// Builds the volume and its majorant grid with at most
    /// `majorant_cells` cells along the longest axis.
    pub fn new(density: D, optics: Optics, majorant_cells: u32) -> Self {
        let bounds = density.bounds();
        let scale = optics.sigma_t.max_element();
        let majorants = MajorantGrid::build(bounds.0, bounds.1, majorant_cells, |lo, hi| {
            density.max_in_box(lo, hi) * scale
        });
        Self {
            density,
            optics,
            bounds,
            majorants,
        }
    }

    /// Extinction `c(p)` per channel.
    #[inline]
    pub fn sigma_t(&self, p: Vec3) -> Vec3 {
        self.optics.sigma_t * self.density.density(p)
    }

    /// The parametric interval `[t0, t1]` (t0 ≥ 0) in which the ray
    /// `origin + t dir` is inside the medium's box, if any.
    #[inline]
    pub fn clip(&self, origin: Vec3, dir: Vec3) -> Option<(f32, f32)> {
        ray_box(origin, dir, self.bounds.0, self.bounds.1)
    }
}

/// Slab test: the interval `[t0, t1]`, `t0 ≥ 0`, where the ray is inside the
/// box; `None` when it misses or the box is behind.
#[inline]
pub fn ray_box(origin: Vec3, dir: Vec3, lo: Vec3, hi: Vec3) -> Option<(f32, f32)> {
    let inv = dir.recip();
    let a = (lo - origin) * inv;
    let b = (hi - origin) * inv;
    // NaN (0 · ∞ for a ray in a slab plane) is dropped by min/max.
    let t0 = a.min(b).max_element().max(0.0);
    let t1 = a.max(b).min_element();
    (t1 > t0).then_some((t0, t1))
}
