//! The kernel reconstruction of `J` between the internal lights
//! ([method §6](crate::doc::method)): at a point of a camera ray's window, the
//! lights within the kernel radius `h` are averaged with the weight
//! `K_h(r) = (1 − r²/h²)²`, their spherical-harmonic series summed
//! before the one evaluation towards the camera or towards `L₁`'s sources.
//! With the optical-depth clock the average is taken of `J_i / c_g(x_i)`
//! and multiplied back by `c_g` at the point.

use glam::Vec3;

use super::clock::Clock;
use super::sources::{InternalLights, Part};
use crate::physics::sh::{sh_basis, MAX_COUNT};

impl InternalLights {
    /// The kernel reconstruction of the multiply scattered part of `J` at
    /// `p` towards `n` ([method §6](crate::doc::method)): `Σ K_h J_i / Σ K_h` over the lights
    /// within `h`, with `K_h(r) = (1 − r²/h²)²`; for the optical-depth clock
    /// the average is taken of `J_i / c_g(x_i)` and multiplied by `c_g(p)`.
    /// Zero where no light is within `h`. `part` says which part of
    /// `Σ_{k≥1} J_k`: all of it (`L₁`'s source) or what the walks carried
    /// through a collision (`L₀`'s, beside the marched single scatter).
    /// The average is not clamped at zero: a clamp's
    /// `E[max(X, 0)] ≥ max(E[X], 0)` would bias it upwards wherever `J` is
    /// small next to its walk noise, with renewed sets (puffs at 96², SH
    /// order 4, K 64, a fresh set every 2 passes: bias 8.61 % clamped,
    /// 7.30 % unclamped) and with one set alike (the puffs' dimmer half at
    /// `s*` 0.25, one set, seeds 8–11: +3.6 % clamped, +0.9 % unclamped;
    /// [validation](crate::doc::validation) §4). Unclamped, the
    /// reconstruction is linear in the lights' coefficients.
    pub fn reconstruct_multi(&self, p: Vec3, n: Vec3, density_at_p: f32, part: Part) -> Vec3 {
        let scale_p = self.reconstruction_scale(density_at_p);
        if scale_p <= 0.0 {
            return Vec3::ZERO;
        }
        let coeffs = match part {
            Part::All => &self.fine_multi,
            Part::Scattered => &self.fine_scattered,
        };
        // The lights' SH series are summed unclamped: clamping each
        // light's noisy series at zero would bias the average upwards
        // wherever `J` is small (measured on the forward-scattering puffs
        // at K = 128: +6.8 % clamped per light, +4.5 % clamped after the
        // sum). The series is linear in the
        // coefficients, so the kernel sums them (a contiguous
        // multiply-add the compiler vectorises) and evaluates the sum
        // once: on the puffs at 256² (M 16384, SH order 4) this function
        // took 31 % of a pass evaluating every light's series, and the
        // pass 4 % less time after (what is left is mostly loading the
        // lights' coefficients).
        let width = 3 * self.sh_count;
        let mut sum = [0.0f32; 3 * MAX_COUNT];
        let sum = &mut sum[..width];
        let den = self.kernel_sum(p, bytemuck::cast_slice(coeffs), sum);
        if den <= 0.0 {
            return Vec3::ZERO;
        }
        let mut y = [0.0f32; MAX_COUNT];
        sh_basis(self.sh_order, n, &mut y);
        Self::eval_sh(bytemuck::cast_slice(sum), &y) * (scale_p / den)
    }

    /// Whether the lights carry the view walks' estimates
    /// ([`InternalParams::view_walks`](super::sources::InternalParams::view_walks)).
    pub fn has_view(&self) -> bool {
        !self.view.is_empty()
    }

    /// The view walks' estimate of light `i` ([`LightSources::view`](super::sources::LightSources::view)), if
    /// there were view walks.
    pub fn view(&self, i: usize) -> Option<Vec3> {
        self.view.get(i).copied()
    }

    /// `L₀`'s collided part at `p` as the camera sees it: the kernel
    /// average of the lights’ view-walk estimates ([`super::sources`], "Walks
    /// towards the eye"), in place of
    /// `reconstruct_multi(p, n, density_at_p, Part::Scattered)` for `n`
    /// towards the eye. Zero without view walks.
    pub fn reconstruct_view(&self, p: Vec3, density_at_p: f32) -> Vec3 {
        self.reconstruct_per_light(&self.fine_view, p, density_at_p)
    }

    /// The kernel average at `p` of one value per light (`values` in the
    /// fine grid's slot order), scaled as the harmonics are; zero where
    /// `values` is empty or no light is within `h`.
    fn reconstruct_per_light(&self, values: &[Vec3], p: Vec3, density_at_p: f32) -> Vec3 {
        let scale_p = self.reconstruction_scale(density_at_p);
        if scale_p <= 0.0 || values.is_empty() {
            return Vec3::ZERO;
        }
        let mut sum = [0.0f32; 3];
        let den = self.kernel_sum(p, bytemuck::cast_slice(values), &mut sum);
        if den <= 0.0 {
            return Vec3::ZERO;
        }
        Vec3::from_array(sum) * (scale_p / den)
    }

    /// Whether the lights carry phase walks' values
    /// ([`super::sources::phase_walks`]).
    pub fn has_phase_view(&self) -> bool {
        !self.fine_phase_view.is_empty()
    }

    /// The source one more scattering sends towards the eye at `p`,
    /// `∫ P(n·n') J(p, n') dn'` for `n` towards the eye: the kernel average
    /// of the lights' phase-walk means ([`super::sources::phase_walks`]),
    /// as [`InternalLights::reconstruct_multi`] averages the harmonics
    /// (all of `Σ_{k≥1} J_k`, not per unit chance). Zero without phase
    /// walks.
    pub fn reconstruct_phase_view(&self, p: Vec3, density_at_p: f32) -> Vec3 {
        self.reconstruct_per_light(&self.fine_phase_view, p, density_at_p)
    }

    /// Adds `K_h(p − x_i) / c_i` times each kernel light's row of `table`
    /// (rows of `sum.len()` floats, in the fine grid's slot order) to
    /// `sum` (`1/c_i` the light's reconstruction scale); returns `Σ K_h`.
    /// The rows are summed unclamped, a contiguous multiply-add the
    /// compiler vectorises.
    #[inline]
    fn kernel_sum(&self, p: Vec3, table: &[f32], sum: &mut [f32]) -> f32 {
        let width = sum.len();
        let mut den = 0.0f32;
        self.for_each_kernel_slot(p, |slot, k| {
            let w = k * self.fine_points[slot][3];
            for (s, &c) in sum.iter_mut().zip(&table[slot * width..(slot + 1) * width]) {
                *s += w * c;
            }
            den += k;
        });
        den
    }

    /// The factor that turns the kernel average back into `Ĵ` at a point of
    /// density `density_at_p`: 1, or `c_g(p)` for the optical-depth clock.
    #[inline]
    pub(crate) fn reconstruction_scale(&self, density_at_p: f32) -> f32 {
        match self.params.clock {
            Clock::Geometric => 1.0,
            Clock::OpticalDepth => self.sigma_grey * density_at_p,
        }
    }

    /// Calls `f(i, K_h(p − x_i))` for every light of the reconstruction
    /// within `h` of `p`, `K_h(r) = (1 − r²/h²)²`.
    #[inline]
    pub(crate) fn for_each_kernel_weight(&self, p: Vec3, mut f: impl FnMut(usize, f32)) {
        let ids = self.fine.ids();
        self.for_each_kernel_slot(p, |slot, k| f(ids[slot] as usize, k));
    }

    /// [`InternalLights::for_each_kernel_weight`] by slot of the fine grid
    /// (the index into `fine.ids()` and the copies aligned with it), the
    /// positions read from those copies in the order they are stored.
    #[inline]
    fn for_each_kernel_slot(&self, p: Vec3, mut f: impl FnMut(usize, f32)) {
        let h = self.kernel_radius;
        let inv_h2 = 1.0 / (h * h);
        self.fine.for_each_near_run(p, h, |run| {
            for slot in run {
                let [x, y, z, _] = self.fine_points[slot];
                let q = (Vec3::new(x, y, z) - p).length_squared() * inv_h2;
                if q < 1.0 {
                    f(slot, (1.0 - q) * (1.0 - q));
                }
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::internal::sources::{InternalLight, InternalParams, L1Form};
    use crate::physics::phase;
    use crate::physics::rng::Rng;
    use crate::physics::sh::sh_count;
    use crate::physics::testing::*;

    /// The kernel reconstruction (which reads copies of the lights in the
    /// fine grid's order and sums their coefficients before evaluating
    /// the series) is the normalised kernel average of [method §6](crate::doc::method)
    /// computed light by light over all lights, for both parts, both
    /// clocks (the optical-depth one averages `J_i / c_g(x_i)` and
    /// multiplies by `c_g(p)`) and SH order 4, up to rounding.
    #[test]
    fn reconstruction_is_the_kernel_average_over_all_lights() {
        use crate::physics::sh::sh_basis;
        let vol = cube(2.0, 0.9, 0.5);
        let mut rng = Rng::for_sample(11, 0, 0);
        let mut lights = Vec::new();
        for _ in 0..400 {
            let p = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.0 - 1.0;
            lights.push(InternalLight {
                position: p,
                density: 0.5 + rng.next_f32(),
                weight: 8.0 / 400.0,
            });
        }
        let count = sh_count(4);
        let mut coeffs = || -> Vec<Vec3> {
            (0..lights.len() * count)
                .map(|_| Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 0.3)
                .collect()
        };
        let (multi, scattered) = (coeffs(), coeffs());
        for clock in [Clock::Geometric, Clock::OpticalDepth] {
            let mut params = sh1_params(clock, 0.5, 4, 0.35, L1Form::Field);
            params.sh_order = 4;
            let cache = assemble(&vol, &params, &lights, multi.clone(), scattered.clone());
            let h = cache.kernel_radius;
            for q in 0..200 {
                let p = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 2.2 - 1.1;
                let n = phase::sample_hg(0.0, Vec3::Z, rng.next_f32(), rng.next_f32());
                let rho = if q % 7 == 0 { 0.0 } else { 0.8 };
                let mut y = [0.0f32; crate::physics::sh::MAX_COUNT];
                sh_basis(4, n, &mut y);
                for (part, table) in [(Part::All, &multi), (Part::Scattered, &scattered)] {
                    let (mut num, mut den) = (Vec3::ZERO, 0.0f32);
                    for (i, l) in lights.iter().enumerate() {
                        let r2 = (l.position - p).length_squared() / (h * h);
                        if r2 >= 1.0 {
                            continue;
                        }
                        let k = (1.0 - r2) * (1.0 - r2);
                        let scale = match clock {
                            Clock::Geometric => 1.0,
                            Clock::OpticalDepth => 1.0 / (2.0 * l.density),
                        };
                        let j: Vec3 = (0..count).map(|c| table[i * count + c] * y[c]).sum();
                        num += j * (k * scale);
                        den += k;
                    }
                    let scale_p = match clock {
                        Clock::Geometric => 1.0,
                        Clock::OpticalDepth => 2.0 * rho,
                    };
                    let want = if den > 0.0 {
                        num * (scale_p / den)
                    } else {
                        Vec3::ZERO
                    };
                    let got = cache.reconstruct_multi(p, n, rho, part);
                    assert!(
                        (got - want).abs().max_element() <= 1e-4 * (1.0 + want.abs().max_element()),
                        "{clock:?} {part:?} at {p}: {got} against {want}"
                    );
                }
            }
        }
    }

    /// Passes average the reconstruction over light sets (renewed sets
    /// within one render, or renders with different seeds), so it must be
    /// linear in the lights' coefficients: the average of two sets whose
    /// walk noise is `+D` and `−D` is the reconstruction of the noiseless
    /// sources, negative lobes included. A clamp at zero would bias that
    /// average upwards where `J` is small (the puffs' dimmer half at
    /// `s*` 0.25 with one set: +3.6 % clamped, +0.9 % unclamped).
    #[test]
    fn light_sets_reconstruct_without_clamping() {
        let vol = cube(2.0, 0.9, 0.0);
        let mut lights = Vec::new();
        for i in 0..27 {
            let c = Vec3::new((i % 3) as f32, ((i / 3) % 3) as f32, (i / 9) as f32) - 1.0;
            lights.push(InternalLight {
                position: c * 0.1,
                density: 1.0,
                weight: 1e-3,
            });
        }
        let count = sh_count(1);
        // J(n) = a + b (linear in n): negative over part of the sphere.
        let sources = |a: f32, b: f32| {
            let mut coeffs = vec![Vec3::ZERO; count * lights.len()];
            for c in coeffs.chunks_mut(count) {
                c[0] = Vec3::splat(a);
                c[1] = Vec3::new(b, 0.5 * b, 0.25 * b);
            }
            coeffs
        };
        let build = |a: f32, b: f32| {
            let params = InternalParams {
                lights: lights.len(),
                ..sh1_params(Clock::OpticalDepth, 0.5, 1, 0.5, L1Form::Field)
            };
            assemble(&vol, &params, &lights, sources(a, b), sources(a, b))
        };
        let dirs = [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z];
        let (a, b, da, db) = (1.0, 3.0, 0.5, 2.0);
        let mut negative = 0;
        let mut either_sign = 0;
        for part in [Part::All, Part::Scattered] {
            for n in dirs {
                let at = |c: &InternalLights| c.reconstruct_multi(Vec3::ZERO, n, 1.0, part);
                let truth = at(&build(a, b));
                let plus = at(&build(a + da, b + db));
                let minus = at(&build(a - da, b - db));
                let avg = 0.5 * (plus + minus);
                assert!(
                    (avg - truth).abs().max_element() <= 1e-5 * truth.abs().max_element(),
                    "{n}: two sets average to {avg}, the noiseless sources give {truth}"
                );
                if truth.min_element() < 0.0 {
                    negative += 1;
                }
                for c in 0..3 {
                    if plus[c].min(minus[c]) < 0.0 && plus[c].max(minus[c]) > 0.0 {
                        either_sign += 1;
                    }
                }
            }
        }
        assert!(negative >= 2, "the test needs negative lobes");
        assert!(either_sign >= 2, "the test needs sets of either sign");
    }
}
