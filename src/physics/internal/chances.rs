//! The chance that light leaving a point along a direction collides before
//! it leaves the medium: what the walks divide their collided part by at a
//! light and the gather multiplies back at a camera ray's point, so that the
//! lights' harmonics need not draw the horizon at a medium's surface
//! ([method §5](crate::doc::method), the lights' scattered part).

use glam::Vec3;

use super::clock::{march_clock, Clock, ClockMarch, ClockRay};
use crate::physics::volume::{DensityField, Volume};

/// The chance that light travelling from `p` along `d` collides before it
/// leaves the medium's box, `1 − e^{−τ}` with `τ` the grey optical depth
/// to the exit (the optical-depth clock's quadrature; `s_star` sets its
/// lattice), one past [`COLLISION_DEPTH`] and never below
/// [`COLLISION_FLOOR`]: a walk from a light at the very edge that collides
/// all the same would otherwise weigh `1/P` without bound (any positive
/// factor divided out at the lights and multiplied back at the point is
/// exact in the limit; the floor only leaves the last sliver of the
/// horizon to the harmonics). The walks divide what they carried through
/// a collision by it at the light and the gather multiplies the
/// reconstruction by it at the camera ray's point (see
/// [`super::sources::Part::Scattered`]): near the surface of a medium it
/// falls from nearly one to nothing across the directions that leave it,
/// a horizon that low-order spherical harmonics and a kernel reaching
/// deeper in would smear.
pub fn collision_probability<D: DensityField>(
    vol: &Volume<D>,
    s_star: f32,
    p: Vec3,
    d: Vec3,
) -> f32 {
    let Some((_, exit)) = vol.clip(p, d) else {
        return COLLISION_FLOOR;
    };
    ChancesAlongRay::new(p, d, exit, s_star).at(vol, 0.0)
}

/// [`collision_probability`] at points of one ray `origin + t dir`
/// (`t ∈ [0, t_exit]`, `t_exit` where it leaves the box) asked for from
/// the far end back: each point's optical depth to the exit is the
/// stretch up to the point asked for before it plus what that point had,
/// so a camera ray's window costs one march to [`COLLISION_DEPTH`] and
/// the stretches between its points, not one march per point. The
/// quadrature lattice of each stretch is anchored at its near end, as
/// `collision_probability`'s is at its point: the two agree to the
/// quadrature's second order, not bit for bit.
pub struct ChancesAlongRay {
    /// The ray, with the optical-depth clock of the window's lattice.
    ray: ClockRay,
    /// The nearest point asked for so far and its optical depth to the
    /// exit (`known_t` infinite: none yet).
    known_t: f32,
    known_tau: f32,
    /// The optical depth reached [`COLLISION_DEPTH`]: one from here on.
    saturated: bool,
}

impl ChancesAlongRay {
    /// Chances along `origin + t dir` up to `t_exit`, with the lattice of
    /// the window `s_star`.
    pub fn new(origin: Vec3, dir: Vec3, t_exit: f32, s_star: f32) -> Self {
        Self {
            ray: ClockRay {
                clock: Clock::OpticalDepth,
                s_star,
                origin,
                dir,
                t_exit,
            },
            known_t: f32::INFINITY,
            known_tau: 0.0,
            saturated: false,
        }
    }

    /// The chance at `origin + t dir` of a collision along `dir` before
    /// the exit. Points are asked for from the far end back: a `t` past
    /// one asked for before (rounding of stratified samples) counts as
    /// that one.
    pub fn at<D: DensityField>(&mut self, vol: &Volume<D>, t: f32) -> f32 {
        if self.saturated {
            return 1.0;
        }
        let t_exit = self.ray.t_exit;
        let t = t.min(t_exit).min(self.known_t);
        let (t_stop, budget) = if self.known_t.is_finite() {
            (self.known_t, COLLISION_DEPTH - self.known_tau)
        } else {
            (t_exit, COLLISION_DEPTH)
        };
        match march_clock(vol, &self.ray, t, t_stop, budget) {
            ClockMarch::Reached(_) => {
                self.saturated = true;
                return 1.0;
            }
            ClockMarch::Exhausted(tau) => {
                self.known_tau += tau;
                self.known_t = t;
            }
        }
        (-(-self.known_tau).exp_m1()).max(COLLISION_FLOOR)
    }
}

/// What one walk from `x` with start direction `−n` carried to its gates
/// `k ≥ 1` through a collision, `Σ (out_k − unscattered_k)`, per unit
/// chance of that collision ([`collision_probability`] along `−n`; no
/// march when it carried nothing): the walk's share of what the lights
/// store as [`super::sources::Part::Scattered`].
pub fn collided_per_unit_chance<D: DensityField>(
    vol: &Volume<D>,
    s_star: f32,
    x: Vec3,
    n: Vec3,
    out: &[Vec3],
    unscattered: &[Vec3],
) -> Vec3 {
    let carried = collided(out, unscattered);
    if carried == Vec3::ZERO {
        return carried;
    }
    carried / collision_probability(vol, s_star, x, -n)
}

/// What one walk carried to its gates `k ≥ 1` through a collision,
/// `Σ (out_k − unscattered_k)` ([`collided_per_unit_chance`] before the
/// division by the chance of that collision).
pub fn collided(out: &[Vec3], unscattered: &[Vec3]) -> Vec3 {
    let total: Vec3 = out.iter().skip(1).sum();
    total - unscattered.iter().skip(1).sum::<Vec3>()
}

/// The optical depth past which [`collision_probability`] stops marching
/// and returns one (`1 − e^{−12}` differs from it by 6e-6; the WGSL's is
/// generated from it).
pub const COLLISION_DEPTH: f32 = 12.0;

/// The least [`collision_probability`] returns (the WGSL's is generated
/// from it).
pub const COLLISION_FLOOR: f32 = 0.05;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::testing::*;

    /// The chances along a ray, asked for from its far end back, are the
    /// per-point [`collision_probability`] up to the quadrature (and both
    /// the exact `1 − e^{−τ}` of a fine march), in a medium thin enough
    /// to stay below [`COLLISION_DEPTH`] and one dense enough to reach it;
    /// the floor holds at the exit.
    #[test]
    fn chances_along_a_ray_match_each_point() {
        for base in [0.4f32, 3.0] {
            let vol = boxed(base, 0.6 * base, 1.0, 3.0, 12);
            let origin = Vec3::new(-3.0, 0.3, 0.2);
            let dir = Vec3::new(1.0, 0.2, -0.1).normalize();
            let (_, t_exit) = vol.clip(origin, dir).unwrap();
            let mut chances = ChancesAlongRay::new(origin, dir, t_exit, 0.5);
            let mut saturated = 0;
            for j in (0..=16).rev() {
                let t = t_exit * j as f32 / 16.0;
                let along = chances.at(&vol, t);
                let p = origin + dir * t;
                let single = collision_probability(&vol, 0.5, p, dir);
                let steps = 20_000;
                let dt = (t_exit - t) / steps as f32;
                let tau: f32 = (0..steps)
                    .map(|i| vol.density.density(p + dir * ((i as f32 + 0.5) * dt)) * dt)
                    .sum();
                let exact = if tau >= COLLISION_DEPTH {
                    1.0
                } else {
                    (1.0 - (-tau).exp()).max(COLLISION_FLOOR)
                };
                assert!(
                    (along - exact).abs() <= 0.01 * exact && (single - exact).abs() <= 0.01 * exact,
                    "base {base}, t {t}: along the ray {along}, at the point {single}, exact {exact} (τ {tau})"
                );
                if along == 1.0 {
                    saturated += 1;
                }
            }
            assert_eq!(chances.at(&vol, 0.0) == 1.0, base > 1.0);
            assert!(
                (base > 1.0) == (saturated > 0),
                "base {base}: {saturated} saturated"
            );
        }
        let vol = boxed(0.4, 0.2, 1.0, 3.0, 12);
        let origin = Vec3::new(-3.0, 0.0, 0.0);
        let mut chances = ChancesAlongRay::new(origin, Vec3::X, 6.0, 0.5);
        assert_eq!(chances.at(&vol, 6.0), COLLISION_FLOOR);
    }
}
