//! Internal lights placed where the camera reads them (a choice beyond the
//! note, which places them by density alone; the method's `M` points
//! and their weights are otherwise unchanged).
//!
//! The final gather reads the multiply scattered source `J` only inside
//! the window of each camera ray: a clock of `s*` from where the ray
//! enters the medium. In a dense medium that window is a thin skin on
//! the side facing the camera (at `σ_t ρ` = 40 per unit and `s*` half a
//! mean free path, 0.0125 units deep), while lights placed by density fill
//! the whole volume: almost none of them stand where `L₀` reads `J`, the
//! kernel reconstruction there rests on a handful of lights or on none
//! (it is then zero), and the image is dark with bright blobs where a
//! light happens to stand near the surface. On a procedural cumulus of
//! optical depth ≈ 30 the image mean came out 25 % (kernel 0.15) to 63 %
//! (kernel 0.05) low.
//!
//! [`place_in_view`] draws a share of the lights in those windows instead:
//! a camera ray through a uniformly random point of the image, and a
//! point on its window at a clock drawn from `e^{−τ}` on `[0, s*]` (the
//! transmittance that weights what the camera sees of `J` there). The
//! reconstruction `Ĵ = Σ K J_i / Σ K` is a normalised kernel average, a
//! consistent estimate of `J` for any placement density that covers the
//! points it is evaluated at, so it needs no pdf of these lights; they
//! carry no volume weight `V_i` (0), and the terms' energies and the point
//! form of `L₁`, which do need one, come from the lights placed by density.
//!
//! `L₁`'s field form (method §6.3) reads `J` off the camera ray too: at a
//! source point a phase-function direction and at most the rest of the
//! window away from a point of the window. Where the camera stands inside
//! the medium the windows fill a narrow cone from the eye, and most of
//! those source points lie outside it, where the kernel found no light
//! and read zero (a fog seen from inside: 29–36 % of `L₁`'s reads, its
//! multiply scattered part 6.7 % dark; validation §3.20). So a share
//! `scattered_share` of these lights takes that one more step from its
//! window point, drawn as `L₁` draws its source point.
//!
//! Their kernel radius cannot come from the volume per light, since they
//! fill a skin and not the box: [`knn_kernel_radius`] takes the median
//! distance from a light to its `k`-th nearest neighbour instead, which
//! holds about `k` lights in the kernel's support in any geometry.

use glam::Vec3;
use rayon::prelude::*;

use super::clock::{march_clock, Clock, ClockMarch, ClockRay};
use crate::physics::phase;
use crate::physics::rng::Rng;
use crate::physics::volume::{DensityField, Volume};

/// Stream index of the placement in the camera's windows (apart from the
/// density placement's, the walks' and the renders').
pub const VIEW_PLACEMENT_STREAM: u32 = 0x7669_6577;

/// Camera rays tried per light before it falls back to no position (most
/// images show the medium over a good part of their area).
const TRIES: u32 = 64;

/// The pinhole camera as the view placement needs it: where rays start and
/// how a point of the image `[−1, 1]²` maps to a direction (the scene
/// camera's frame; `physics` does not depend on `scene`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ViewFrame {
    /// The eye.
    pub eye: Vec3,
    /// The unit viewing direction.
    pub forward: Vec3,
    /// Right, scaled by the half-width of the image plane at distance 1.
    pub right_scaled: Vec3,
    /// Up, scaled by the half-height of the image plane at distance 1.
    pub up_scaled: Vec3,
}

impl ViewFrame {
    /// The unit direction through the image point `(sx, sy)`, both in
    /// `[−1, 1]` (`sy` up).
    pub fn ray_dir(&self, sx: f32, sy: f32) -> Vec3 {
        (self.forward + self.right_scaled * sx + self.up_scaled * sy).normalize_or_zero()
    }
}

/// Draws `count` points in the windows of the camera's rays (see the module
/// doc), point `i` from stream `i` of `seed`. A point whose `TRIES` rays
/// all miss the medium, or whose rays all leave it before the drawn clock,
/// is `None`. With probability `scattered_share` a point then moves to a
/// source point of `L₁` about it ([`scattered_source`]).
pub fn place_in_view<D: DensityField>(
    vol: &Volume<D>,
    frame: &ViewFrame,
    (clock, s_star): (Clock, f32),
    scattered_share: f32,
    count: usize,
    seed: u64,
) -> Vec<Option<Vec3>> {
    // `e^{−τ}` truncated to `[0, s*]` by inversion.
    let norm = 1.0 - (-s_star).exp();
    (0..count)
        .into_par_iter()
        .map(|i| {
            let mut rng = Rng::for_sample(seed, i as u32, VIEW_PLACEMENT_STREAM);
            for _ in 0..TRIES {
                let sx = 2.0 * rng.next_f32() - 1.0;
                let sy = 2.0 * rng.next_f32() - 1.0;
                let dir = frame.ray_dir(sx, sy);
                let Some((t_in, t_out)) = vol.clip(frame.eye, dir) else {
                    continue;
                };
                let u = rng.next_f32();
                let budget = match clock {
                    Clock::OpticalDepth => -(1.0 - u * norm).ln(),
                    Clock::Geometric => u * s_star,
                };
                let origin = frame.eye + dir * t_in;
                let span = t_out - t_in;
                let ray = ClockRay {
                    clock,
                    s_star,
                    origin,
                    dir,
                    t_exit: span,
                };
                if let ClockMarch::Reached(t) = march_clock(vol, &ray, 0.0, span, budget) {
                    let y = origin + dir * t;
                    if rng.next_f32() < scattered_share {
                        let left = s_star - budget;
                        return Some(scattered_source(
                            vol,
                            (clock, s_star),
                            y,
                            -dir,
                            left,
                            &mut rng,
                        ));
                    }
                    return Some(y);
                }
            }
            None
        })
        .collect()
}

/// A source point of `L₁`'s field form (method §6.3) about the window point
/// `y` seen along `towards` (towards the eye), with `left` of the window's
/// clock still to spend: light travelling along a direction drawn from the
/// phase function about `towards` arrives at `y` from a point whose clock
/// from `y` is uniform in `[0, left]`, as `L₁` draws it. `y` itself where
/// that line leaves the medium before the drawn clock.
fn scattered_source<D: DensityField>(
    vol: &Volume<D>,
    (clock, s_star): (Clock, f32),
    y: Vec3,
    towards: Vec3,
    left: f32,
    rng: &mut Rng,
) -> Vec3 {
    let travel = phase::sample_hg(vol.optics.g, towards, rng.next_f32(), rng.next_f32());
    let back = -travel;
    let budget = rng.next_f32() * left.max(0.0);
    let Some((_, exit)) = vol.clip(y, back) else {
        return y;
    };
    let ray = ClockRay {
        clock,
        s_star,
        origin: y,
        dir: back,
        t_exit: exit,
    };
    match march_clock(vol, &ray, 0.0, exit, budget) {
        ClockMarch::Reached(r) => y + back * r,
        ClockMarch::Exhausted(_) => y,
    }
}

/// The median, over up to `samples` of `positions` spread evenly through
/// the list, of the distance to the `k`-th nearest other position (`None`
/// with fewer than `k + 1` positions).
pub fn knn_kernel_radius(positions: &[Vec3], k: usize, samples: usize) -> Option<f32> {
    let n = positions.len();
    if k == 0 || n <= k {
        return None;
    }
    let step = (n / samples.max(1)).max(1);
    let mut radii: Vec<f32> = (0..n)
        .step_by(step)
        .collect::<Vec<_>>()
        .par_iter()
        .map(|&i| {
            let p = positions[i];
            let mut d2: Vec<f32> = positions
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .map(|(_, q)| (*q - p).length_squared())
                .collect();
            let (_, kth, _) = d2.select_nth_unstable_by(k - 1, f32::total_cmp);
            kth.sqrt()
        })
        .collect();
    let mid = radii.len() / 2;
    let (_, median, _) = radii.select_nth_unstable_by(mid, f32::total_cmp);
    Some(*median)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::testing::Ball;
    use crate::physics::volume::Optics;

    fn frame() -> ViewFrame {
        let half = (20.0f32).to_radians().tan();
        ViewFrame {
            eye: Vec3::new(0.0, 0.0, 4.0),
            forward: Vec3::NEG_Z,
            right_scaled: Vec3::X * half,
            up_scaled: Vec3::Y * half,
        }
    }

    #[test]
    fn view_points_lie_in_the_windows_with_the_transmittance_profile() {
        // σ_t 40 and s* = 2 mean free paths: the window is 0.05 deep along
        // each ray. 32 majorant cells across the ball: the clock's
        // quadrature steps are at most s*/4 = 0.5 mean free paths, so a
        // point's clock is exact to a quarter of one at the ball's edge.
        let optics = Optics {
            sigma_t: Vec3::splat(40.0),
            albedo: Vec3::splat(0.9),
            g: 0.0,
        };
        let vol = Volume::new(Ball { radius: 1.0 }, optics, 32);
        let s_star = 2.0;
        let pts = place_in_view(&vol, &frame(), (Clock::OpticalDepth, s_star), 0.0, 4000, 3);
        let placed: Vec<Vec3> = pts.iter().flatten().copied().collect();
        assert_eq!(placed.len(), pts.len(), "the ball fills the image's centre");
        let eye = frame().eye;
        let mut depth_sum = 0.0f64;
        for p in &placed {
            // Optical depth from where the ray from the eye enters the ball.
            let dir = (*p - eye).normalize();
            let b = eye.dot(dir);
            let c = eye.length_squared() - 1.0;
            let t_in = -b - (b * b - c).sqrt();
            let tau = 40.0 * ((*p - eye).length() - t_in);
            assert!(
                (-0.25..=s_star + 0.25).contains(&tau),
                "clock {tau} outside [0, s*]"
            );
            depth_sum += tau as f64;
        }
        // The mean of e^{−τ} truncated to [0, s*] is
        // 1 − s* e^{−s*} / (1 − e^{−s*}) = 0.687; a uniform clock's would
        // be 1. Its standard deviation is about 0.5 / √4000 = 0.008.
        let expect = 1.0 - s_star * (-s_star).exp() / (1.0 - (-s_star).exp());
        let mean = depth_sum / placed.len() as f64;
        assert!(
            (mean - expect as f64).abs() < 0.06,
            "mean clock {mean} against {expect}"
        );
    }

    #[test]
    fn knn_radius_of_a_lattice_is_its_spacing() {
        // A 10³ lattice of spacing 0.1: each interior point's 6th nearest
        // neighbour is at 0.1, its 18th at 0.1·√2.
        let mut pts = Vec::new();
        for k in 0..10 {
            for j in 0..10 {
                for i in 0..10 {
                    pts.push(Vec3::new(i as f32, j as f32, k as f32) * 0.1);
                }
            }
        }
        let r6 = knn_kernel_radius(&pts, 6, 1000).unwrap();
        assert!((r6 - 0.1).abs() < 1e-4, "{r6}");
        let r18 = knn_kernel_radius(&pts, 18, 1000).unwrap();
        assert!((r18 - 0.1 * 2f32.sqrt()).abs() < 1e-4, "{r18}");
        assert_eq!(knn_kernel_radius(&pts[..5], 6, 10), None);
    }
}
