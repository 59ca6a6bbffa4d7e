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
//! multiply scattered part 6.7 % dark; validation §3.20). So where a
//! pilot of those source points finds too many without a light
//! ([`UNSERVED_READS`]), a share ([`SCATTERED_VIEW_SHARE`]) of these lights
//! takes that one more step from its window point, drawn as `L₁` draws its
//! source point.
//!
//! Their kernel radius cannot come from the volume per light, since they
//! fill a skin and not the box: [`knn_kernel_radius`] takes the median
//! distance from a light to its `k`-th nearest neighbour instead, which
//! holds about `k` lights in the kernel's support in any geometry.

use glam::Vec3;
use rayon::prelude::*;

use super::clock::{march_clock, Clock, ClockMarch, ClockRay};
use super::light_index::LightGrid;
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

/// The share of the lights placed in the camera's windows that move on to
/// a source point of `L₁` ([`place_in_view`]) where the windows' lights
/// leave `L₁`'s reads without a light ([`UNSERVED_READS`]). Half, as `L₁`
/// reads the lights about as often as `L₀` does (once per point of the
/// window, and its further scatterings by roulette). A fog seen from
/// inside (validation §3.20): its multiply scattered part −6.7 % with
/// none, −3.5 % with a quarter, −1.9 % with half.
pub const SCATTERED_VIEW_SHARE: f32 = 0.5;

/// The share of `L₁`'s source points (a pilot of [`PILOT_POINTS`], in the
/// medium) with no light of the windows within their kernel radius above
/// which [`SCATTERED_VIEW_SHARE`] of the lights move. A fog seen from
/// inside: 29–36 %; the same fog seen from outside 1.6–4 %, the suite's
/// media 0.01–0.8 % (validation §3.20). Moved there, half the lights were
/// taken from the windows for nothing: the smoke plumes' per-pixel error
/// at 8 s rose by 6–7 %.
pub const UNSERVED_READS: f32 = 0.1;

/// Points of the pilot that decides whether lights move
/// ([`UNSERVED_READS`]).
pub const PILOT_POINTS: usize = 512;

/// Lights the pilot's kernel radius is measured over (the median of their
/// distances to their `k`-th neighbour): a quarter of the pilot, since
/// each costs a pass over all the windows' lights and the placement is
/// redone for every light set (with 512 the smoke plume's placement took
/// 0.015 s against 0.005 s without the pilot).
const PILOT_RADIUS_SAMPLES: usize = PILOT_POINTS / 4;

/// Stream index of the pilot's source points ([`UNSERVED_READS`]).
const PILOT_STREAM: u32 = 0x7069_6c74;

/// Stream index of the choice of the lights that move on from the windows
/// ([`SCATTERED_VIEW_SHARE`]): apart from the windows' own, so that where
/// none move the lights are where they were.
const SCATTERED_STREAM: u32 = 0x7363_6174;

/// The kernel the pilot of [`place_in_view`] measures `L₁`'s reads with: the
/// automatic one, holding about this many lights, or a radius the user set.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PilotKernel {
    /// The automatic kernel's neighbours (its radius measured over the
    /// windows' lights, as [`knn_kernel_radius`] does).
    Neighbours(u32),
    /// A fixed radius.
    Radius(f32),
}

/// A point of a camera ray's window: where it lies, the direction of the
/// ray and the clock left in the window after it.
#[derive(Clone, Copy)]
struct WindowPoint {
    position: Vec3,
    dir: Vec3,
    left: f32,
}

/// Draws `count` points in the windows of the camera's rays (see the module
/// doc), point `i` from stream `i` of `seed`. A point whose `TRIES` rays
/// all miss the medium, or whose rays all leave it before the drawn clock,
/// is `None`.
///
/// With `scattered` (the kernel, where `L₁`'s field form reads the lights
/// off the camera ray), a pilot of `L₁`'s source points about
/// the window points measures how many find no light within the windows'
/// kernel radius; above [`UNSERVED_READS`], [`SCATTERED_VIEW_SHARE`] of the
/// points move on to a source point of `L₁` about them, drawn as `L₁`
/// draws it (method §6.3).
pub fn place_in_view<D: DensityField>(
    vol: &Volume<D>,
    frame: &ViewFrame,
    window: (Clock, f32),
    scattered: Option<PilotKernel>,
    count: usize,
    seed: u64,
) -> Vec<Option<Vec3>> {
    let points: Vec<Option<WindowPoint>> = (0..count)
        .into_par_iter()
        .map(|i| window_point(vol, frame, window, seed, i as u32))
        .collect();
    let share = match scattered {
        Some(kernel) if unserved_share(vol, window, &points, kernel, seed) > UNSERVED_READS => {
            SCATTERED_VIEW_SHARE
        }
        _ => 0.0,
    };
    points
        .into_par_iter()
        .enumerate()
        .map(|(i, point)| {
            let p = point?;
            if share > 0.0 {
                let mut rng = Rng::for_sample(seed, i as u32, SCATTERED_STREAM);
                if rng.next_f32() < share {
                    return Some(scattered_source(vol, window, p, &mut rng).unwrap_or(p.position));
                }
            }
            Some(p.position)
        })
        .collect()
}

/// Window point `i` of [`place_in_view`], from stream `i` of `seed`.
fn window_point<D: DensityField>(
    vol: &Volume<D>,
    frame: &ViewFrame,
    (clock, s_star): (Clock, f32),
    seed: u64,
    i: u32,
) -> Option<WindowPoint> {
    // `e^{−τ}` truncated to `[0, s*]` by inversion.
    let norm = 1.0 - (-s_star).exp();
    let mut rng = Rng::for_sample(seed, i, VIEW_PLACEMENT_STREAM);
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
            return Some(WindowPoint {
                position: origin + dir * t,
                dir,
                left: s_star - budget,
            });
        }
    }
    None
}

/// The share of `L₁`'s source points about [`PILOT_POINTS`] of the window
/// points, those in the medium, with no window point within the
/// `kernel`'s radius (for the automatic kernel, the radius that holds its
/// neighbours among them, [`knn_kernel_radius`]); 0 where there are too
/// few.
fn unserved_share<D: DensityField>(
    vol: &Volume<D>,
    window: (Clock, f32),
    points: &[Option<WindowPoint>],
    kernel: PilotKernel,
    seed: u64,
) -> f32 {
    let positions: Vec<Vec3> = points.iter().flatten().map(|p| p.position).collect();
    let radius = match kernel {
        PilotKernel::Neighbours(k) => {
            knn_kernel_radius(&positions, k as usize, PILOT_RADIUS_SAMPLES)
        }
        PilotKernel::Radius(h) => (h > 0.0 && !positions.is_empty()).then_some(h),
    };
    let Some(h) = radius else {
        return 0.0;
    };
    // The windows' lights bucketed as the reconstruction's own index
    // buckets every light (cells of about the kernel's radius).
    let grid = LightGrid::build(&positions, |_| true, vol.bounds, h, 96);
    let step = (points.len() / PILOT_POINTS).max(1);
    let pilot: Vec<usize> = (0..points.len()).step_by(step).collect();
    let (reads, unserved) = pilot
        .par_iter()
        .filter_map(|&i| {
            let mut rng = Rng::for_sample(seed, i as u32, PILOT_STREAM);
            let x = scattered_source(vol, window, points[i]?, &mut rng)?;
            (vol.density.density(x) > 0.0).then(|| {
                let mut served = false;
                grid.for_each_near_run(x, h, |run| {
                    served = served
                        || grid.ids()[run]
                            .iter()
                            .any(|&i| (positions[i as usize] - x).length_squared() < h * h);
                });
                (1u32, u32::from(!served))
            })
        })
        .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    if reads == 0 {
        0.0
    } else {
        unserved as f32 / reads as f32
    }
}

/// A source point of `L₁`'s field form (method §6.3) about the window point
/// `p`: light travelling along a direction drawn from the phase function
/// about the direction towards the eye arrives at `p` from a point whose
/// clock from `p` is uniform in what is left of the window, as `L₁` draws
/// it. `None` where that line leaves the medium's box before the drawn
/// clock.
fn scattered_source<D: DensityField>(
    vol: &Volume<D>,
    (clock, s_star): (Clock, f32),
    p: WindowPoint,
    rng: &mut Rng,
) -> Option<Vec3> {
    let travel = phase::sample_hg(vol.optics.g, -p.dir, rng.next_f32(), rng.next_f32());
    let back = -travel;
    let budget = rng.next_f32() * p.left.max(0.0);
    let (_, exit) = vol.clip(p.position, back)?;
    let ray = ClockRay {
        clock,
        s_star,
        origin: p.position,
        dir: back,
        t_exit: exit,
    };
    match march_clock(vol, &ray, 0.0, exit, budget) {
        ClockMarch::Reached(r) => Some(p.position + back * r),
        ClockMarch::Exhausted(_) => None,
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

    /// The unit ball of extinction `sigma_t`, albedo 0.9 and asymmetry `g`,
    /// 32 majorant cells across.
    fn ball(sigma_t: f32, g: f32) -> Volume<Ball> {
        let optics = Optics {
            sigma_t: Vec3::splat(sigma_t),
            albedo: Vec3::splat(0.9),
            g,
        };
        Volume::new(Ball { radius: 1.0 }, optics, 32)
    }

    #[test]
    fn view_points_lie_in_the_windows_with_the_transmittance_profile() {
        // σ_t 40 and s* = 2 mean free paths: the window is 0.05 deep along
        // each ray. 32 majorant cells across the ball: the clock's
        // quadrature steps are at most s*/4 = 0.5 mean free paths, so a
        // point's clock is exact to a quarter of one at the ball's edge.
        let vol = ball(40.0, 0.0);
        let s_star = 2.0;
        let pts = place_in_view(&vol, &frame(), (Clock::OpticalDepth, s_star), None, 4000, 3);
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

    /// Lights move on from the windows to `L₁`'s source points where the
    /// camera stands inside the medium (the windows a narrow cone from the
    /// eye, which most source points leave) and not where it looks at it
    /// from outside: there the lights stay exactly where they were.
    #[test]
    fn lights_move_to_l1_sources_only_where_the_windows_leave_them_unserved() {
        let vol = ball(1.0, 0.3);
        let window = (Clock::OpticalDepth, 0.5);
        let windows_only = |frame: &ViewFrame| place_in_view(&vol, frame, window, None, 4000, 3);
        let points = |frame: &ViewFrame| -> Vec<Option<WindowPoint>> {
            (0..4000)
                .map(|i| window_point(&vol, frame, window, 3, i))
                .collect()
        };

        let automatic = PilotKernel::Neighbours(64);
        let pilot =
            |frame: &ViewFrame, kernel| unserved_share(&vol, window, &points(frame), kernel, 3);
        let with_pilot =
            |frame: &ViewFrame| place_in_view(&vol, frame, window, Some(automatic), 4000, 3);

        let outside = frame();
        let unserved = pilot(&outside, automatic);
        assert!(unserved < UNSERVED_READS, "outside: {unserved}");
        let placed = with_pilot(&outside);
        assert_eq!(placed, windows_only(&outside), "outside, the lights stay");

        let inside = ViewFrame {
            eye: Vec3::new(0.0, 0.0, 0.3),
            ..frame()
        };
        let unserved = pilot(&inside, automatic);
        assert!(unserved > UNSERVED_READS, "inside: {unserved}");
        // A kernel set as wide as the ball holds a window light at every
        // read.
        let wide = pilot(&inside, PilotKernel::Radius(2.0));
        assert_eq!(wide, 0.0, "inside, a kernel of radius 2");
        let placed = with_pilot(&inside);
        let stayed = windows_only(&inside);
        let moved = placed.iter().zip(&stayed).filter(|(a, b)| a != b).count();
        // Half of 4000 chosen (sd 32), less the few whose step leaves
        // the ball: on the camera ray's far side it is 1.3 away.
        let share = moved as f32 / placed.len() as f32;
        assert!(
            (0.4..=SCATTERED_VIEW_SHARE + 0.03).contains(&share),
            "inside: {moved} of {} moved",
            placed.len()
        );
        for (p, w) in placed.iter().zip(&stayed) {
            let (p, w) = (p.expect("placed"), w.expect("placed"));
            // A source point lies within what is left of the window (at
            // most half a unit of a unit density) of its window point.
            assert!((p - w).length() <= 0.5 + 1e-3, "{p} from {w}");
        }
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
