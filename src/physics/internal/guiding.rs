//! Guided directions for the internal lights' walks: after a collision a
//! walk may turn towards an external light rather than follow the phase
//! function, its weight corrected so that it stays unbiased
//! ([method §4](crate::doc::method); a choice beyond the note).
//!
//! The internal lights' walks
//! ([`accumulate_j_from`](super::walk::Walks::accumulate_j_from)) draw
//! their direction after a collision from a mixture: the phase function,
//! or with probability [`GUIDE_PROBABILITY`] a lobe about the direction
//! towards an external light, and multiply the weight by the phase
//! function over the mixture's density ([`guided_direction`]). The walk's
//! expectation ([`super::walk`]) is unchanged (importance sampling of the
//! collision's direction integral); what changes is which walks carry the light: unguided, the few that
//! wander to the lit side carry most of it. Only a walk's first
//! [`GUIDED_COLLISIONS`] collisions are guided: the weight factors of many
//! guided collisions multiply into a heavy tail.
//!
//! In a medium whose phase function has a sharp forward peak
//! (`g` ≥ [`SECOND_FLIGHT_MIN_G`]) the walks take a **second flight** at
//! each collision instead of guided directions ([`second_flight`]):
//! besides its own direction, drawn from the phase function, a walk draws
//! one from a lobe about the direction towards a light and follows it to
//! its next collision for the gates on the way only, both flights' gates
//! weighted by the balance heuristic. A gate reads the phase function
//! between the walk's direction and the light's, up to 1800 times larger
//! towards the light than away from it at `g` 0.85, so the walks' mean
//! rests on the few flights that happen to head for the light; the second
//! flight reads that peak at every collision where the light may still
//! reach, and the walk itself goes on as before, so no weight factor
//! accumulates ([validation §3.13](crate::doc::validation)).
//!

use glam::Vec3;

use crate::physics::lights::{LightSample, Lights};
use crate::physics::phase;
use crate::physics::rng::Rng;
use crate::physics::volume::{DensityField, Volume};

/// Probability that a walk's direction after a collision is drawn towards
/// an external light ([`guided_direction`]) rather than from the phase
/// function. The walks' values are heavy-tailed: on the puffs two thirds
/// of the walks from a light carry nothing through a collision and the
/// top 1 % carry half the mean (the few that reach the sunlit side;
/// `lantern noise`). At 0.3, with lobes of `g` [`GUIDE_G`], the light sets'
/// noise fell from 42.7 % to 35.7 % of the image mean per set (96², M 16384,
/// K 16, SH 4, 24 sets; 1.43× less variance); 0.2 gave about the same,
/// a narrower lobe (`g` 0.8) and an isotropic one less.
pub const GUIDE_PROBABILITY: f32 = 0.3;

/// The Henyey–Greenstein parameter of the lobes about the directions
/// towards the external lights that [`guided_direction`] mixes in.
pub const GUIDE_G: f32 = 0.5;

/// Collisions of a walk after which its directions are guided
/// ([`guided_direction`]); later ones come from the phase function alone.
/// Each guided direction multiplies the walk's weight by phase / mixture
/// (up to `1/(1 − q)`), unbiased but a factor of its own: over the hundreds
/// of collisions of a walk in a thick cloud the product of those factors is
/// heavy-tailed, and single lights came out tens of times too bright
/// (kernel-sized white discs; on a cumulus of optical depth ≈ 30, albedo
/// 0.999, `g` 0.85 at 128², 8 light sets: block RMSE 484 % guided at every
/// collision, 35 % at the first two only). Near the light where a walk
/// starts, where the guiding pays, two collisions keep its gain (puffs:
/// block RMSE 3.6 % either way).
pub const GUIDED_COLLISIONS: u32 = 2;

/// The external lights' unshadowed irradiance at `p` summed (largest
/// channel of each), or `None` where none shines (or the sum is not
/// finite): what [`guided_direction`] and [`second_flight`] choose a
/// light in proportion to.
fn irradiance_total(lights: &Lights, p: Vec3) -> Option<f32> {
    let mut total = 0.0f32;
    lights.for_each_at(p, |l| total += l.irradiance.max_element().max(0.0));
    (total > 0.0 && total.is_finite()).then_some(total)
}

/// The external light chosen at `p` in proportion to its unshadowed
/// irradiance by `u ∈ [0, 1)`, `total` being [`irradiance_total`]: the
/// first whose share holds `u · total`, or the last that shines where
/// rounding leaves it past the end.
fn light_by_irradiance(lights: &Lights, p: Vec3, total: f32, u: f32) -> Option<LightSample> {
    let mut pick = u * total;
    let (mut chosen, mut last) = (None, None);
    lights.for_each_at(p, |l| {
        let w = l.irradiance.max_element().max(0.0);
        if w > 0.0 {
            last = Some(l);
            if chosen.is_none() && pick < w {
                chosen = Some(l);
            }
            pick -= w;
        }
    });
    chosen.or(last)
}

/// A backward walk's next direction after a collision at `p`, coming in
/// along `dir`, and the factor its weight takes: with probability
/// `1 − q` (`q` = [`GUIDE_PROBABILITY`]) from the phase function about
/// `dir`, otherwise from a Henyey–Greenstein lobe ([`GUIDE_G`]) about the
/// direction towards one external light, chosen in proportion to its
/// unshadowed irradiance at `p` (largest channel). The factor is the
/// phase function over the mixture's density, at most `1/(1 − q)`, so the
/// walk stays unbiased for any lights and any medium; with no light
/// reaching `p` it is the phase function alone. `u1, u2` place the
/// direction within the chosen lobe; the choice of lobe draws from `rng`.
pub fn guided_direction(
    g: f32,
    lights: &Lights,
    p: Vec3,
    dir: Vec3,
    u1: f32,
    u2: f32,
    rng: &mut Rng,
) -> (Vec3, f32) {
    let Some(total) = irradiance_total(lights, p) else {
        return (phase::sample_hg(g, dir, u1, u2), 1.0);
    };
    let u = rng.next_f32();
    let next = if u < GUIDE_PROBABILITY {
        // A light in proportion to its irradiance, then its lobe.
        match light_by_irradiance(lights, p, total, u / GUIDE_PROBABILITY) {
            Some(l) => phase::sample_hg(GUIDE_G, -l.travel, u1, u2),
            None => phase::sample_hg(g, dir, u1, u2),
        }
    } else {
        phase::sample_hg(g, dir, u1, u2)
    };
    let p_phase = phase::hg(g, dir.dot(next));
    let mut p_lobes = 0.0f32;
    lights.for_each_at(p, |l| {
        let w = l.irradiance.max_element().max(0.0);
        if w > 0.0 {
            p_lobes += w / total * phase::hg(GUIDE_G, next.dot(-l.travel));
        }
    });
    let mixture = (1.0 - GUIDE_PROBABILITY) * p_phase + GUIDE_PROBABILITY * p_lobes;
    if mixture > 0.0 {
        (next, p_phase / mixture)
    } else {
        (next, 0.0)
    }
}

/// The least Henyey–Greenstein `g` at which the internal lights' walks
/// take a [`second_flight`] at their collisions (instead of the guided
/// directions of [`guided_direction`]). Measured on the suite's cumulus
/// with its `g` changed (`lantern noise --size 48 --passes 8`, the sets'
/// variance × time): at `g` 0.5 the second flight cost more than it
/// saved (292 against 243 %² s), at 0.7 about even (430 against 414), at
/// 0.85 1.55× less (1236 against 1914); on the smoke plume (`g` 0.3) 35
/// against 25. The peak it reads grows as `(1 + g)/(1 − g)²` times the
/// phase function's mean (6 at 0.5, 82 at 0.85).
pub const SECOND_FLIGHT_MIN_G: f32 = 0.75;

/// The majorant optical depth towards a light at and beyond which a
/// collision takes no [`second_flight`] towards it: the light cannot reach
/// there, and the flight would read nothing at its gates. A walk over the
/// majorant grid's cells, without a density lookup, decides it. On the
/// suite's cumulus (`g` 0.85; sets' variance × time, %² s): a second
/// flight at every collision 1729, below a depth of 8 1523, of 12 1371,
/// of 20 1236, of 30 1491.
pub const SECOND_FLIGHT_MAX_DEPTH: f32 = 20.0;

/// A collision's second flight ([`second_flight`]): its direction and the
/// balance-heuristic weights of the two flights' gates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SecondFlight {
    /// The second flight's direction (of the backward walk).
    pub dir: Vec3,
    /// The factor of the second flight's gates, up to the collision that
    /// ends it: `P/(P + q)` at its direction.
    pub factor: f32,
    /// The factor of the gates of the walk's own flight, up to its next
    /// collision: `P/(P + q)` at the walk's own direction.
    pub own_factor: f32,
}

/// The second flight of a backward walk at a collision at `p`, where it
/// came in along `dir` and drew its own next direction `own` from the
/// phase function (`g` the medium's). One external light is chosen in
/// proportion to its unshadowed irradiance at `p` (largest channel) by
/// `u`; where the majorant's optical depth from `p` towards it reaches
/// [`SECOND_FLIGHT_MAX_DEPTH`] (up to the box's edge, or to a point light)
/// or no light shines, there is none (`None`: the walk's own gates keep
/// their weight). Otherwise `u1, u2` draw its direction from a
/// Henyey–Greenstein lobe of the medium's `g` about the direction towards
/// the light.
///
/// Why it is unbiased: what the gates of the flight after a collision add
/// up to is an integral over the flight's direction of the phase function
/// `P` times what the gates read. Given the light, the two directions are
/// one sample of each of two techniques, the phase function `P` and the
/// lobe `q`, and the balance heuristic weighs each flight's gates by
/// `P/(P + q)` at its direction; where the light cannot reach, the lobe is
/// not sampled and the walk's own gates keep the weight 1. The light's
/// choice and the test depend on the collision alone, so the estimate is
/// unbiased whatever they decide. The walk goes on from its own direction:
/// what it carries after its next collision does not change.
#[allow(clippy::too_many_arguments)]
pub fn second_flight<D: DensityField>(
    vol: &Volume<D>,
    lights: &Lights,
    p: Vec3,
    dir: Vec3,
    own: Vec3,
    u: f32,
    u1: f32,
    u2: f32,
) -> Option<SecondFlight> {
    let total = irradiance_total(lights, p)?;
    let light = light_by_irradiance(lights, p, total, u)?;
    let towards = -light.travel;
    let (t_enter, t_exit) = vol.clip(p, towards)?;
    let depth = vol.majorants.depth(
        p,
        towards,
        t_enter,
        t_exit.min(light.distance),
        SECOND_FLIGHT_MAX_DEPTH,
    );
    if depth >= SECOND_FLIGHT_MAX_DEPTH {
        return None;
    }
    let g = vol.optics.g;
    let balance = |d: Vec3| {
        let p_phase = phase::hg(g, dir.dot(d));
        let q = phase::hg(g, d.dot(towards));
        if p_phase + q > 0.0 {
            p_phase / (p_phase + q)
        } else {
            0.0
        }
    };
    let second = phase::sample_hg(g, towards, u1, u2);
    Some(SecondFlight {
        dir: second,
        factor: balance(second),
        own_factor: balance(own),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::internal::clock::Clock;
    use crate::physics::internal::walk::Walks;
    use crate::physics::testing::*;

    /// The mean of `f` over `walks` walks and its variance, from
    /// [`forward_scattering_walk`] with the phase function's `g`, the
    /// `clock` and a point light beside its sun: plain walks (directions
    /// from the phase function alone) first, then the internal lights'
    /// ([`Walks::guided`]).
    fn plain_then_lights_walks(
        g: f32,
        clock: Clock,
        walks: u32,
        seed: u64,
        f: impl Fn(&Walks<Field>, Vec3, Vec3, &mut Rng) -> Vec3,
    ) -> [(Vec3, Vec3); 2] {
        let (mut vol, mut lights, mut settings, z, n) = forward_scattering_walk();
        vol.optics.g = g;
        settings.clock = clock;
        lights.points.push(crate::physics::lights::PointLight {
            position: Vec3::new(-2.0, 0.5, 1.5),
            intensity: Vec3::splat(4.0),
        });
        [false, true].map(|guided| {
            mean_and_its_variance(walks, seed, u32::from(guided), |rng| {
                let walks = Walks {
                    guided,
                    ..Walks::guided(&vol, &lights, settings)
                };
                f(&walks, z, n, rng)
            })
        })
    }

    /// Asserts that the internal lights' walks (`what`) keep the plain
    /// walks' mean in each of the three `parts` of [`plain_then_lights_walks`]'s
    /// `stats` (within 4.5 standard errors of the difference, the plain
    /// mean at least 10 of them: precise enough to tell) and spread the
    /// first part less.
    fn assert_same_means_less_spread(what: &str, parts: [&str; 3], stats: [(Vec3, Vec3); 2]) {
        let [(m0, v0), (m1, v1)] = stats;
        for (c, part) in parts.iter().enumerate() {
            let se = (v0[c] + v1[c]).sqrt();
            assert!(
                (m0[c] - m1[c]).abs() < 4.5 * se,
                "{what}, {part}: plain {} against {} (se {se})",
                m0[c],
                m1[c]
            );
            assert!(m0[c] > 10.0 * se, "{what}, {part}: too noisy to compare");
        }
        eprintln!(
            "{what}: plain {m0} ± {:?}, {m1} ± {:?}",
            v0.to_array().map(f32::sqrt),
            v1.to_array().map(f32::sqrt)
        );
        assert!(v1.x < v0.x, "{what}: variance {} against {}", v1.x, v0.x);
    }

    /// Guiding the walks towards the light changes their spread, not their
    /// mean: in a bounded, forward-scattering, heterogeneous medium lit by
    /// a sun and a point light, the collided part of every term agrees
    /// with the unguided walk's (summed over `k ≥ 1`, per channel, within
    /// 4.5 standard errors of the difference), and the guided walks' values
    /// are less spread (their standard error lower).
    #[test]
    fn guided_walks_keep_the_mean() {
        let g = forward_scattering_walk().0.optics.g;
        assert!(g < SECOND_FLIGHT_MIN_G);
        let stats =
            plain_then_lights_walks(g, Clock::OpticalDepth, 400_000, 21, |walks, z, n, rng| {
                split_walk(walks, z, n, rng).0
            });
        assert_same_means_less_spread("guided", ["red", "green", "blue"], stats);
    }

    /// The second flight goes only where the light can still reach, and
    /// its two factors are the balance heuristic's `P/(P + q)`: in a box of
    /// majorant 30 per unit lit from above, none from its centre (a depth
    /// of 30 to the top), one from a tenth of a unit below the top; none
    /// without a light.
    #[test]
    fn second_flights_go_where_the_light_reaches() {
        let mut vol = boxed(30.0, 0.0, 0.99, 1.0, 8);
        vol.optics.g = 0.85;
        let lights = one_sun(Vec3::new(0.0, -1.0, 0.0), Vec3::ONE);
        let (dir, own) = (Vec3::new(0.6, 0.0, 0.8), Vec3::new(0.0, 0.6, 0.8));
        let deep = second_flight(&vol, &lights, Vec3::ZERO, dir, own, 0.5, 0.3, 0.7);
        assert_eq!(deep, None);
        let near = Vec3::new(0.0, 0.9, 0.0);
        let none = Lights::default();
        assert_eq!(
            second_flight(&vol, &none, near, dir, own, 0.5, 0.3, 0.7),
            None
        );
        let Some(f) = second_flight(&vol, &lights, near, dir, own, 0.5, 0.3, 0.7) else {
            panic!("no second flight a depth of 3 from the light");
        };
        let towards = Vec3::Y;
        assert_eq!(f.dir, phase::sample_hg(0.85, towards, 0.3, 0.7));
        for (d, factor) in [(f.dir, f.factor), (own, f.own_factor)] {
            let (p, q) = (phase::hg(0.85, dir.dot(d)), phase::hg(0.85, d.dot(towards)));
            assert!(
                (factor - p / (p + q)).abs() < 1e-6,
                "{factor} against {}",
                p / (p + q)
            );
        }
        // Towards the light the lobe dominates: the flight's own gates
        // there take a small factor.
        assert!(f.factor < 0.5, "{}", f.factor);
    }

    /// Second flights (a medium of `g` 0.85, so the guided walks take them,
    /// lit by a sun and a point light) change the walks' spread, not their
    /// mean, with either clock: the collided part summed over `k ≥ 1`, of
    /// term 1 (`F`) alone and of the terms from 4 on agree with the plain walks' (directions
    /// from the phase function alone, no second flight) within 4.5
    /// standard errors of the difference, and the sum is less spread.
    #[test]
    fn second_flights_keep_the_mean() {
        let g = 0.85;
        assert!(g >= SECOND_FLIGHT_MIN_G);
        for clock in [Clock::OpticalDepth, Clock::Geometric] {
            let stats = plain_then_lights_walks(g, clock, 1_000_000, 23, |walks, z, n, rng| {
                let slots = walks.gates.term_slots();
                let (mut out, mut unscattered) = (vec![Vec3::ZERO; slots], vec![Vec3::ZERO; slots]);
                walks.accumulate_j_from(z, n, 1, rng, &mut out, Some(&mut unscattered));
                let collided: Vec<f32> = out
                    .iter()
                    .zip(&unscattered)
                    .map(|(o, u)| (*o - *u).element_sum() / 3.0)
                    .collect();
                Vec3::new(
                    collided[1..].iter().sum(),
                    collided[1],
                    collided[4..].iter().sum(),
                )
            });
            assert_same_means_less_spread(
                &format!("{clock:?}, second flights"),
                ["the sum", "term 1", "terms from 4"],
                stats,
            );
        }
    }
}
