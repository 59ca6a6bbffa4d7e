//! The environment light in the form the estimators use: its radiance in
//! any direction, importance sampling with an exact pdf, and its share of
//! the first-scatter source `S₁` ([method §1](crate::doc::method), "the
//! environment as part of `S₁`").
//!
//! # The map
//!
//! As in Mitsuba 3's `envmap`, a `W × H` latitude–longitude map is read as
//! the vertices of a bilinear patch: texel column `i` sits at
//! `u = (i + ½)/W` (with a copy of column 0 at `u = 1 + ½/W`, so the patch
//! wraps), row `j` at `v = j/(H − 1)`, `θ = πv` from +y, and the direction
//! towards the sky at `(u, v)` is `(sin 2πu sin θ, cos θ, −cos 2πu sin θ)`
//! in the map's frame, turned about +y by the map's rotation.
//!
//! # Sampling
//!
//! The `W × (H − 1)` cells between the vertices form a piecewise-constant
//! distribution in solid angle: cell `c` weighs `w_c Ω_c`, with `w_c` the
//! largest channel of its four corners (so that the bilinear radiance is
//! never non-zero where the pdf is zero) and `Ω_c` its solid angle
//! `(2π/W)(cos θ_j − cos θ_{j+1})` — the `sin θ` weighting, integrated
//! exactly. A row is drawn from the marginal table, a cell from the row's
//! conditional one, then a direction uniform in solid angle inside the
//! cell (`φ` uniform, `cos θ` uniform), so the pdf is exactly
//! `w_c / Σ w Ω` everywhere in the cell. A constant sky is sampled
//! uniformly (`1/4π`).
//!
//! # `S₁` from the environment
//!
//! `S₁_env(y, n) / b(y) = ∫ P(n·ω) L(−ω) T(y, ∞ along −ω) dω` over the
//! directions `ω` light travels. One sample per call, by one-sample
//! multiple importance sampling: the direction comes from the map with
//! probability `q` ([`Environment::map_share`]) and from the phase
//! function otherwise, and the estimate is `P L T / (q p_map + (1 − q) P)`
//! (the balance heuristic over the mixture), with `T` ratio-tracked. A
//! constant sky uses the phase function alone (`q = 0`): then `P L / P`
//! leaves only the transmittance's noise.

use std::f32::consts::{PI, TAU};

use glam::Vec3;

/// The radiance of the sky in every direction, with its sampling tables.
#[derive(Clone, Debug, PartialEq)]
pub struct Environment {
    /// The sky itself.
    pub kind: EnvironmentKind,
    /// Whether the camera sees it behind the medium.
    pub background: bool,
}

/// A constant sky or a map.
#[derive(Clone, Debug, PartialEq)]
pub enum EnvironmentKind {
    /// The same radiance everywhere.
    Constant(Vec3),
    /// A latitude–longitude map.
    Map(EnvMap),
}

/// A latitude–longitude map with its sampling tables (see the module's
/// documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct EnvMap {
    /// Texels per row of the map (`W`).
    pub width: u32,
    /// Rows (`H`, at least 2).
    pub height: u32,
    /// `(W + 1) × H` vertices (the map, scaled, with column 0 repeated at
    /// the end of each row), row-major.
    pub vertices: Vec<Vec3>,
    /// `cos`, `sin` of the map's rotation about +y.
    pub rotation: (f32, f32),
    /// Per cell `w_c` (the largest channel of its four corners),
    /// `W × (H − 1)`, row-major.
    pub cell_weight: Vec<f32>,
    /// Cumulative `Σ w Ω` over rows, normalised to end at 1 (`H − 1`
    /// entries).
    pub row_cdf: Vec<f32>,
    /// Per row the cumulative `w` over its cells, normalised to end at 1
    /// (`W × (H − 1)` entries; a row of zero weight holds a uniform ramp).
    pub col_cdf: Vec<f32>,
    /// `1 / Σ_c w_c Ω_c` (0 for a black map).
    pub inv_total: f32,
}

/// The map's `u` of local direction `d` before the half-texel shift, in
/// `(−½, ½]`, and `v` in `[0, 1]`.
#[inline]
fn direction_to_uv(d: Vec3) -> (f32, f32) {
    (d.x.atan2(-d.z) / TAU, d.y.clamp(-1.0, 1.0).acos() / PI)
}

impl EnvMap {
    /// Builds the vertices and tables from `width × height` texels (row 0
    /// at +y), multiplied by `scale`, turned by `rotation_deg` about +y.
    pub fn new(width: u32, height: u32, texels: &[Vec3], rotation_deg: f32, scale: f32) -> Self {
        let (w, h) = (width.max(1) as usize, height.max(2) as usize);
        let mut vertices = Vec::with_capacity((w + 1) * h);
        for j in 0..h {
            for i in 0..=w {
                let t = texels.get(j * w + i % w).copied().unwrap_or(Vec3::ZERO);
                vertices.push(t * scale);
            }
        }
        let rad = rotation_deg.to_radians();
        let rows = h - 1;
        let mut cell_weight = vec![0.0f32; w * rows];
        let mut col_cdf = vec![0.0f32; w * rows];
        let mut row_cdf = vec![0.0f32; rows];
        let mut total = 0.0f64;
        let dphi = TAU as f64 / w as f64;
        for j in 0..rows {
            let (c0, c1) = (
                (PI as f64 * j as f64 / rows as f64).cos(),
                (PI as f64 * (j + 1) as f64 / rows as f64).cos(),
            );
            let omega = dphi * (c0 - c1);
            let mut row = 0.0f64;
            for i in 0..w {
                let at = |di: usize, dj: usize| vertices[(j + dj) * (w + 1) + i + di].max_element();
                let wc = at(0, 0).max(at(1, 0)).max(at(0, 1)).max(at(1, 1)).max(0.0);
                cell_weight[j * w + i] = wc;
                row += wc as f64;
                col_cdf[j * w + i] = row as f32;
            }
            let cdf = &mut col_cdf[j * w..(j + 1) * w];
            if row > 0.0 {
                cdf.iter_mut().for_each(|c| *c = (*c as f64 / row) as f32);
            } else {
                for (i, c) in cdf.iter_mut().enumerate() {
                    *c = (i + 1) as f32 / w as f32;
                }
            }
            cdf[w - 1] = 1.0;
            total += row * omega;
            row_cdf[j] = total as f32;
        }
        if total > 0.0 {
            row_cdf
                .iter_mut()
                .for_each(|c| *c = (*c as f64 / total) as f32);
        }
        if let Some(last) = row_cdf.last_mut() {
            *last = 1.0;
        }
        Self {
            width: w as u32,
            height: h as u32,
            vertices,
            rotation: (rad.cos(), rad.sin()),
            cell_weight,
            row_cdf,
            col_cdf,
            inv_total: if total > 0.0 {
                (1.0 / total) as f32
            } else {
                0.0
            },
        }
    }

    /// World direction to the map's frame (the inverse rotation).
    #[inline]
    fn to_local(&self, d: Vec3) -> Vec3 {
        let (c, s) = self.rotation;
        Vec3::new(c * d.x - s * d.z, d.y, s * d.x + c * d.z)
    }

    /// The map's frame to world (rotation about +y).
    #[inline]
    fn to_world(&self, d: Vec3) -> Vec3 {
        let (c, s) = self.rotation;
        Vec3::new(c * d.x + s * d.z, d.y, -s * d.x + c * d.z)
    }

    /// Continuous vertex coordinates `(x, y)` of local direction `d`:
    /// `x ∈ [0, W)`, `y ∈ [0, H − 1]`.
    #[inline]
    fn grid_coords(&self, d: Vec3) -> (f32, f32) {
        let (w, h) = (self.width as f32, self.height as f32);
        let (u, v) = direction_to_uv(d);
        let mut u = u - 0.5 / w;
        u -= u.floor();
        ((u * w).min(w), v * (h - 1.0))
    }

    /// Radiance arriving from world direction `from` (unit, pointing
    /// towards the sky): Mitsuba's bilinear lookup.
    #[inline]
    pub fn radiance(&self, from: Vec3) -> Vec3 {
        let (x, y) = self.grid_coords(self.to_local(from));
        let w = self.width as usize;
        let ix = (x as usize).min(w - 1);
        let iy = (y as usize).min(self.height as usize - 2);
        let (fx, fy) = (x - ix as f32, y - iy as f32);
        let at = |i: usize, j: usize| self.vertices[j * (w + 1) + i];
        let top = at(ix, iy) * (1.0 - fx) + at(ix + 1, iy) * fx;
        let bottom = at(ix, iy + 1) * (1.0 - fx) + at(ix + 1, iy + 1) * fx;
        top * (1.0 - fy) + bottom * fy
    }

    /// Draws a world direction towards the sky from `(u1, u2)` and returns
    /// it with its pdf in solid angle; `None` for a black map.
    #[inline]
    pub fn sample(&self, u1: f32, u2: f32) -> Option<(Vec3, f32)> {
        if self.inv_total <= 0.0 {
            return None;
        }
        let (w, rows) = (self.width as usize, self.height as usize - 1);
        let j = self.row_cdf.partition_point(|&c| c <= u1).min(rows - 1);
        let lo = if j == 0 { 0.0 } else { self.row_cdf[j - 1] };
        let span = self.row_cdf[j] - lo;
        let ru = if span > 0.0 {
            ((u1 - lo) / span).clamp(0.0, 1.0)
        } else {
            0.5
        };
        let cdf = &self.col_cdf[j * w..(j + 1) * w];
        let i = cdf.partition_point(|&c| c <= u2).min(w - 1);
        let clo = if i == 0 { 0.0 } else { cdf[i - 1] };
        let cspan = cdf[i] - clo;
        let cu = if cspan > 0.0 {
            ((u2 - clo) / cspan).clamp(0.0, 1.0)
        } else {
            0.5
        };
        let weight = self.cell_weight[j * w + i];
        if weight <= 0.0 {
            return None;
        }
        let c0 = (PI * j as f32 / rows as f32).cos();
        let c1 = (PI * (j + 1) as f32 / rows as f32).cos();
        let cos_t = (c0 + (c1 - c0) * ru).clamp(-1.0, 1.0);
        let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
        let u = (i as f32 + cu) / w as f32 + 0.5 / w as f32;
        let (sp, cp) = (TAU * u).sin_cos();
        let local = Vec3::new(sp * sin_t, cos_t, -cp * sin_t);
        Some((self.to_world(local), weight * self.inv_total))
    }

    /// The pdf in solid angle of [`EnvMap::sample`] drawing `from`.
    #[inline]
    pub fn pdf(&self, from: Vec3) -> f32 {
        let (x, y) = self.grid_coords(self.to_local(from));
        let w = self.width as usize;
        let i = (x as usize).min(w - 1);
        let j = (y as usize).min(self.height as usize - 2);
        self.cell_weight[j * w + i] * self.inv_total
    }
}

impl Environment {
    /// Radiance arriving from world direction `from` (unit, towards the
    /// sky).
    #[inline]
    pub fn radiance(&self, from: Vec3) -> Vec3 {
        match &self.kind {
            EnvironmentKind::Constant(l) => *l,
            EnvironmentKind::Map(m) => m.radiance(from),
        }
    }

    /// The probability with which [`S₁`'s estimate](crate::physics::reference::environment_source)
    /// draws its direction from the environment rather than from the phase
    /// function: 0 for a constant sky (the phase function is then the
    /// better density), ½ for a map.
    #[inline]
    pub fn map_share(&self) -> f32 {
        match &self.kind {
            EnvironmentKind::Constant(_) => 0.0,
            EnvironmentKind::Map(m) if m.inv_total > 0.0 => 0.5,
            EnvironmentKind::Map(_) => 0.0,
        }
    }

    /// Draws a direction towards the sky, with its pdf in solid angle.
    #[inline]
    pub fn sample(&self, u1: f32, u2: f32) -> Option<(Vec3, f32)> {
        match &self.kind {
            EnvironmentKind::Constant(_) => {
                let z = 1.0 - 2.0 * u1;
                let r = (1.0 - z * z).max(0.0).sqrt();
                let (s, c) = (TAU * u2).sin_cos();
                Some((Vec3::new(r * c, r * s, z), 1.0 / (4.0 * PI)))
            }
            EnvironmentKind::Map(m) => m.sample(u1, u2),
        }
    }

    /// The pdf in solid angle of [`Environment::sample`] drawing `from`.
    #[inline]
    pub fn pdf(&self, from: Vec3) -> f32 {
        match &self.kind {
            EnvironmentKind::Constant(_) => 1.0 / (4.0 * PI),
            EnvironmentKind::Map(m) => m.pdf(from),
        }
    }

    /// Whether the sky is black everywhere.
    pub fn is_black(&self) -> bool {
        match &self.kind {
            EnvironmentKind::Constant(l) => l.max_element() <= 0.0,
            EnvironmentKind::Map(m) => m.inv_total <= 0.0,
        }
    }

    /// `∫ L(ω) dω` over the sphere, RGB (exact for a constant sky; for a
    /// map, the midpoint rule on each cell).
    pub fn integral(&self) -> Vec3 {
        match &self.kind {
            EnvironmentKind::Constant(l) => *l * (4.0 * PI),
            EnvironmentKind::Map(m) => {
                let (w, rows) = (m.width as usize, m.height as usize - 1);
                let mut sum = Vec3::ZERO;
                for j in 0..rows {
                    let c0 = (PI * j as f32 / rows as f32).cos();
                    let c1 = (PI * (j + 1) as f32 / rows as f32).cos();
                    let omega = TAU / w as f32 * (c0 - c1);
                    for i in 0..w {
                        let at = |di: usize, dj: usize| m.vertices[(j + dj) * (w + 1) + i + di];
                        sum += (at(0, 0) + at(1, 0) + at(0, 1) + at(1, 1)) * (0.25 * omega);
                    }
                }
                sum
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::rng::Rng;

    /// A small map with structure: a bright patch, a dark band, colour.
    fn test_map(rotation_deg: f32) -> EnvMap {
        let (w, h) = (16u32, 8u32);
        let texels: Vec<Vec3> = (0..w * h)
            .map(|k| {
                let (i, j) = (k % w, k / w);
                let base = 0.1 + 0.05 * i as f32;
                if (i, j) == (3, 2) {
                    Vec3::new(20.0, 10.0, 5.0)
                } else if j == 5 {
                    Vec3::ZERO
                } else {
                    Vec3::new(base, 0.5 * base, 1.0 - base)
                }
            })
            .collect();
        EnvMap::new(w, h, &texels, rotation_deg, 1.5)
    }

    fn fib(k: usize, n: usize) -> Vec3 {
        let z = 1.0 - (2 * k + 1) as f32 / n as f32;
        let r = (1.0 - z * z).max(0.0).sqrt();
        let phi = k as f32 * 2.399_963;
        Vec3::new(r * phi.cos(), r * phi.sin(), z)
    }

    /// The pdf integrates to one over the sphere, for maps turned or not.
    #[test]
    fn pdf_integrates_to_one() {
        for rot in [0.0, 37.0] {
            let map = test_map(rot);
            let n = 400_000;
            let sum: f64 = (0..n).map(|k| map.pdf(fib(k, n)) as f64).sum();
            let integral = sum * 4.0 * std::f64::consts::PI / n as f64;
            assert!(
                (integral - 1.0).abs() < 2e-3,
                "rotation {rot}: ∫pdf = {integral}"
            );
        }
    }

    /// Sampled directions carry the pdf they are drawn with, and every
    /// direction where the radiance is positive has a positive pdf.
    #[test]
    fn samples_carry_their_pdf() {
        let map = test_map(20.0);
        let mut rng = Rng::for_sample(3, 0, 0);
        for _ in 0..20_000 {
            let (d, pdf) = map
                .sample(rng.next_f32(), rng.next_f32())
                .expect("not black");
            assert!((d.length() - 1.0).abs() < 1e-4);
            let p = map.pdf(d);
            assert!((p - pdf).abs() <= 1e-3 * pdf, "{p} vs {pdf} at {d}");
        }
        for k in 0..100_000 {
            let d = fib(k, 100_000);
            if map.radiance(d).max_element() > 0.0 {
                assert!(map.pdf(d) > 0.0, "radiance without pdf at {d}");
            }
        }
    }

    /// χ² of a histogram of samples over 24 × 12 bins of (φ, cos θ) in
    /// world space against the pdf integrated over each bin.
    #[test]
    fn sample_histogram_matches_pdf() {
        let map = test_map(63.0);
        let (nb_phi, nb_z) = (24usize, 12usize);
        let bin = |d: Vec3| {
            let phi = d.z.atan2(d.x).rem_euclid(TAU);
            let bi = ((phi / TAU) * nb_phi as f32) as usize;
            let bj = (((d.y + 1.0) * 0.5) * nb_z as f32) as usize;
            bi.min(nb_phi - 1) + nb_phi * bj.min(nb_z - 1)
        };
        // Expected probabilities by fine quadrature of the pdf.
        let mut expected = vec![0.0f64; nb_phi * nb_z];
        let q = 240usize;
        for a in 0..q * nb_phi {
            for b in 0..q * nb_z / 4 {
                let phi = (a as f32 + 0.5) / (q * nb_phi) as f32 * TAU;
                let z = -1.0 + 2.0 * (b as f32 + 0.5) / (q * nb_z / 4) as f32;
                let r = (1.0 - z * z).sqrt();
                let d = Vec3::new(r * phi.cos(), z, r * phi.sin());
                let dw = TAU as f64 / (q * nb_phi) as f64 * 2.0 / (q * nb_z / 4) as f64;
                expected[bin(d)] += map.pdf(d) as f64 * dw;
            }
        }
        let n = 400_000usize;
        let mut counts = vec![0u64; nb_phi * nb_z];
        let mut rng = Rng::for_sample(9, 1, 0);
        for _ in 0..n {
            let (d, _) = map
                .sample(rng.next_f32(), rng.next_f32())
                .expect("not black");
            counts[bin(d)] += 1;
        }
        let mut chi2 = 0.0f64;
        let mut dof = 0usize;
        for (c, e) in counts.iter().zip(&expected) {
            let e = e * n as f64;
            if e > 5.0 {
                chi2 += (*c as f64 - e).powi(2) / e;
                dof += 1;
            } else {
                assert!(
                    (*c as f64) < 5.0 * e.max(1.0) + 10.0,
                    "count {c} where {e} expected"
                );
            }
        }
        // dof ≈ 250: the 99.9 % point of χ² is about dof + 4.4 √(2 dof).
        let limit = dof as f64 + 4.4 * (2.0 * dof as f64).sqrt();
        println!("χ² = {chi2:.1} over {dof} bins (limit {limit:.1})");
        assert!(chi2 < limit, "χ² = {chi2} over {dof} bins");
    }

    /// The lookup follows Mitsuba's conventions: texel column `i`, row `j`
    /// is seen exactly at `u = (i + ½)/W`, `v = j/(H − 1)`, and +90° of
    /// rotation turns the map's +z onto +x.
    #[test]
    fn lookup_conventions() {
        let map = test_map(0.0);
        let (w, h) = (16usize, 8usize);
        for (i, j) in [(3usize, 2usize), (10, 4), (0, 1)] {
            let u = (i as f32 + 0.5) / w as f32;
            let v = j as f32 / (h - 1) as f32;
            let (st, ct) = (v * PI).sin_cos();
            let (sp, cp) = (u * TAU).sin_cos();
            let d = Vec3::new(sp * st, ct, -cp * st);
            let want = map.vertices[j * (w + 1) + i];
            assert!((map.radiance(d) - want).length() < 1e-3 * want.length().max(1.0));
        }
        let turned = test_map(90.0);
        for k in 0..50 {
            let d = fib(k, 50);
            // Rotation about +y by 90°: local (x, y, z) → world (z, y, −x).
            let world = Vec3::new(d.z, d.y, -d.x);
            let a = turned.radiance(world);
            let b = map.radiance(d);
            assert!((a - b).length() < 1e-3 * b.length().max(1.0), "{a} vs {b}");
        }
    }

    #[test]
    fn constant_sampling_is_uniform() {
        let env = Environment {
            kind: EnvironmentKind::Constant(Vec3::ONE),
            background: false,
        };
        let mut rng = Rng::for_sample(1, 2, 3);
        let mut mean = Vec3::ZERO;
        for _ in 0..100_000 {
            let (d, pdf) = env.sample(rng.next_f32(), rng.next_f32()).expect("sample");
            assert!((pdf - 1.0 / (4.0 * PI)).abs() < 1e-7);
            mean += d;
        }
        assert!((mean / 100_000.0).length() < 0.01);
        assert!((env.integral() - Vec3::splat(4.0 * PI)).length() < 1e-4);
    }
}
