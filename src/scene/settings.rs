//! Render settings stored with the scene: which estimator, how many
//! samples, the seed that makes a render reproducible, and the parameters
//! of the internal-lights method ([method §3–§7](crate::doc::method)).

use serde::{Deserialize, Serialize};

/// Which estimator renders the image: the one enum that the scene file
/// (`method: Reference`), the command line (`--method reference`) and the
/// previewer's streams use. The discriminants index the previewer's
/// per-estimator tables.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum,
)]
pub enum Method {
    /// The unbiased volumetric path tracer ([method §2](crate::doc::method)): the ground truth.
    #[default]
    #[value(help = "The unbiased volumetric path tracer")]
    Reference = 1,
    /// Multiple scatter as internal lights ([method §3–§6](crate::doc::method)).
    #[value(help = "Multiple scatter as internal lights")]
    Internal = 0,
}

/// What the path-length clock of the internal-lights method counts
/// between the walks' gates ([method §3, §7](crate::doc::method)): the one
/// enum that the scene file (`clock: OpticalDepth`), the command line
/// (`--clock optical-depth`), the estimators (`physics::internal::clock`
/// re-exports it) and the GPU ([`Clock::tag`]) use.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
pub enum Clock {
    /// Geometric path length `ℓ`, as in Tessendorf's note: gates at
    /// `ℓ = k s*`, `s*` is a distance.
    #[value(help = "Geometric path length (`s*` is a distance)")]
    Geometric = 0,
    /// Grey optical depth `τ = ∫ max(σ_t) ρ dℓ`: gates at `τ = k s*`, so
    /// `s*` is a number of mean free paths and every window holds on
    /// average `s*` collisions.
    #[default]
    #[value(help = "Optical depth (`s*` is a number of mean free paths)")]
    OpticalDepth = 1,
}

impl Clock {
    /// The tag the shaders switch on (`CLOCK_*` in the generated WGSL
    /// prelude, `gpu::shaders::WGSL_CONSTANTS`).
    pub const fn tag(self) -> u32 {
        self as u32
    }
}

/// The form of the final gather's single-scatter term `L₁` ([method §6](crate::doc::method);
/// §6.3 there says how they differ): the one enum that the scene file
/// (`l1: Field`), the command line (`--l1 field`), the estimators
/// (`physics::internal` re-exports it) and the GPU ([`L1Form::tag`]) use.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
pub enum L1Form {
    /// One scattering of the kernel-reconstructed field `J = S₁ + Ĵ` (no
    /// bounded kernel, so no softening bias).
    #[default]
    #[value(help = "One scattering of the reconstructed field J (default)")]
    Field = 0,
    /// Tessendorf's sum over the point lights with the bounded kernel
    /// `1/(r² + h₁²)`.
    #[value(help = "The note's sum over point lights with a bounded kernel")]
    Points = 1,
}

impl L1Form {
    /// The tag the shaders switch on (`L1_*` in the generated WGSL
    /// prelude, `gpu::shaders::WGSL_CONSTANTS`).
    pub const fn tag(self) -> u32 {
        self as u32
    }
}

/// Parameters of the internal-lights method, nested by who sets them: the
/// artist's [`Knobs`] first, then the preset and the [`Expert`] settings it
/// chooses. Changing any of them re-samples the internal lights.
///
/// In a scene file the fields are written flat (`render.internal.expert.walks`,
/// as always) and every one is optional: the ones given override the
/// preset named by `quality` (default [`Quality::Final`]), the others come
/// from it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(from = "InternalSettingsFile", into = "InternalSettingsFlat")]
pub struct InternalSettings {
    /// The artist's knobs: the window, the number of lights and the series
    /// truncation (the fourth, the phase function's `g`, is the medium's).
    pub knobs: Knobs,
    /// The preset the expert settings started from (see [`Quality`]); the
    /// fields may have been edited since.
    pub quality: Quality,
    /// How the estimator spends its work: what the presets choose.
    pub expert: Expert,
}

/// The internal lights' knobs an artist turns ([method §3–§5](crate::doc::method)).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Knobs {
    /// Window length `s*` (world units for the geometric clock, mean free
    /// paths for the optical-depth clock); `None`: [`DEFAULT_S_STAR`] mean
    /// free paths (for the geometric clock, that many mean free paths at
    /// the medium's mean extinction where it is not empty).
    pub s_star: Option<f32>,
    /// Number of internal lights `M`.
    pub lights: u32,
    /// Series truncation `N`: terms `k = 0..=N`.
    pub terms: u32,
}

/// The internal lights' expert settings: the walks, the lights' harmonics
/// and kernel, the clock, the gather and the light sets' renewal. The
/// presets ([`Quality`]) choose them; the previewer shows them in its
/// expert section and the command line under its own heading.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Expert {
    /// Time-gated walks per light `K`.
    pub walks: u32,
    /// Order of the real spherical harmonics that store `F` and `J`.
    pub sh_order: u32,
    /// Kernel radius `h` (world units); `None`: automatic, about 64
    /// lights within it in a render's first light set and fewer, down to
    /// 16, in later ones (`physics::internal::sources::kernel_neighbours_for_set`:
    /// with lights in the camera's view the median distance to a light's
    /// 64th, 32nd, 21st, then 16th neighbour; otherwise 2.5 × the mean
    /// light spacing, scaled alike); a render with a time limit keeps 64
    /// where its light sets' noise outweighs its passes'
    /// (`render::renewal::BalancedRenewal::kernel_neighbours`).
    pub kernel_radius: Option<f32>,
    /// Uniform fraction `u` of the placement density.
    pub uniform_mix: f32,
    /// What the path-length clock counts.
    pub clock: Clock,
    /// The form of the gather's `L₁`.
    pub l1: L1Form,
    /// Scatterings inside the final window that the field form of `L₁`
    /// follows: 1 is the note's single-scatter kernel ([method §6](crate::doc::method)), 2
    /// and 3 add the next terms of the window's transport ([method
    /// §6.4](crate::doc::method)).
    pub window_scatters: u32,
    /// Walks per light along the direction towards the camera, for the
    /// view's `L₀` (0: none, `L₀` reads the lights' spherical harmonics;
    /// see [method §5.4](crate::doc::method)).
    pub view_walks: u32,
    /// Points per camera ray in the final gather (strata of the window,
    /// each with its `S₁`, reconstruction and `L₁` sample; as many again
    /// for the single scatter beyond the window).
    pub light_samples: u32,
    /// Share of the `M` lights placed in the windows of the camera's rays
    /// rather than by density (0 ..= 1; see [method
    /// §5.2](crate::doc::method)). Ties the lights to the
    /// camera: moving it re-samples them.
    pub view_share: f32,
    /// Passes rendered with one set of internal lights before a fresh set
    /// (same parameters, the next seed of the render's seed) replaces it;
    /// 0 keeps one set for the whole render. One set's walk noise is fixed
    /// for all its passes, so with 0 the passes converge to the image of
    /// those lights; with sets drawn afresh they converge to the method's
    /// expectation over light sets, the walk noise averaging out like
    /// pixel noise.
    pub resample_every: u32,
}

impl Default for InternalSettings {
    fn default() -> Self {
        Quality::default().settings()
    }
}

/// The default window `s*` in mean free paths. The final gather follows
/// at most [`Expert::window_scatters`] scatterings inside the
/// window, and a window of `s*` mean free paths holds more with the
/// Poisson probability `P(n > m)`: at 0.5 with two scatterings 1.4 %, the
/// bias's bound; 0.25 doubles every walk's gates for 1.2 % less.
pub const DEFAULT_S_STAR: f32 = 0.5;

/// The internal lights' presets: how much work each light set and each
/// pass do. Both are the same estimator (the one the method documentation
/// describes) with different numbers; `Final` is what the accuracy targets
/// are measured with, `Preview` re-samples about four times sooner for
/// interactive work, at more noise per pass.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Quality {
    /// Fewer walks and gather points: fast light sets for live edits.
    Preview,
    /// The settings the accuracy targets are measured with.
    #[default]
    Final,
}

impl Quality {
    /// Every preset, in the order a menu lists them.
    pub const ALL: [Quality; 2] = [Quality::Preview, Quality::Final];

    /// The settings of this preset.
    pub fn settings(self) -> InternalSettings {
        let knobs = Knobs {
            s_star: None,
            lights: 4096,
            terms: DEFAULT_TERMS,
        };
        let expert = Expert {
            walks: 16,
            sh_order: 3,
            kernel_radius: None,
            uniform_mix: 0.0,
            clock: Clock::OpticalDepth,
            l1: L1Form::Field,
            window_scatters: 2,
            view_walks: 16,
            // A ray's fixed costs (clipping, the window's march, the
            // strata's density, the chances' march) weigh a third of the
            // ray at 4 points, and finer strata lower the variance faster
            // than 1/points: `lantern noise` measured the gather's
            // variance × time per pass 1.1–1.7× lower with 8 points than 4
            // over the suite (1.5× on the smoke and the plumes; validation
            // §3.2). More points make passes longer and leave fewer light
            // sets in a short render: 12 put two scenes' 8×8 blocks just
            // past 5 % at 2 s, 8 none.
            light_samples: 8,
            view_share: 0.9,
            resample_every: 2,
        };
        match self {
            Quality::Final => InternalSettings {
                knobs,
                quality: self,
                expert,
            },
            Quality::Preview => InternalSettings {
                knobs: Knobs {
                    lights: 2048,
                    ..knobs
                },
                quality: self,
                expert: Expert {
                    walks: 8,
                    view_walks: 8,
                    light_samples: 2,
                    resample_every: 4,
                    ..expert
                },
            },
        }
    }

    /// The preset's name as the command line and the previewer show it.
    pub fn name(self) -> &'static str {
        match self {
            Quality::Preview => "preview",
            Quality::Final => "final",
        }
    }
}

/// [`InternalSettings`] as a scene file holds them: every field optional
/// (given fields override the preset).
#[derive(Deserialize)]
#[serde(default, deny_unknown_fields)]
#[derive(Default)]
struct InternalSettingsFile {
    #[serde(deserialize_with = "given")]
    quality: Option<Quality>,
    #[serde(deserialize_with = "given")]
    s_star: Option<Option<f32>>,
    #[serde(deserialize_with = "given")]
    lights: Option<u32>,
    #[serde(deserialize_with = "given")]
    terms: Option<u32>,
    #[serde(deserialize_with = "given")]
    walks: Option<u32>,
    #[serde(deserialize_with = "given")]
    sh_order: Option<u32>,
    #[serde(deserialize_with = "given")]
    kernel_radius: Option<Option<f32>>,
    #[serde(deserialize_with = "given")]
    uniform_mix: Option<f32>,
    #[serde(deserialize_with = "given")]
    clock: Option<Clock>,
    #[serde(deserialize_with = "given")]
    l1: Option<L1Form>,
    #[serde(deserialize_with = "given")]
    window_scatters: Option<u32>,
    #[serde(deserialize_with = "given")]
    view_walks: Option<u32>,
    #[serde(deserialize_with = "given")]
    light_samples: Option<u32>,
    #[serde(deserialize_with = "given")]
    view_share: Option<f32>,
    #[serde(deserialize_with = "given")]
    resample_every: Option<u32>,
}

/// A field that is present in the file: its value as written (so that
/// `lights: 4096` reads as it always has), wrapped to tell it from an
/// absent one.
fn given<'de, D, T>(d: D) -> Result<Option<T>, D::Error>
where
    D: serde::Deserializer<'de>,
    T: Deserialize<'de>,
{
    T::deserialize(d).map(Some)
}

impl From<InternalSettingsFile> for InternalSettings {
    fn from(f: InternalSettingsFile) -> Self {
        let p = f.quality.unwrap_or_default().settings();
        let (k, e) = (p.knobs, p.expert);
        InternalSettings {
            knobs: Knobs {
                s_star: f.s_star.unwrap_or(k.s_star),
                lights: f.lights.unwrap_or(k.lights),
                terms: f.terms.unwrap_or(k.terms),
            },
            quality: p.quality,
            expert: Expert {
                walks: f.walks.unwrap_or(e.walks),
                sh_order: f.sh_order.unwrap_or(e.sh_order),
                kernel_radius: f.kernel_radius.unwrap_or(e.kernel_radius),
                uniform_mix: f.uniform_mix.unwrap_or(e.uniform_mix),
                clock: f.clock.unwrap_or(e.clock),
                l1: f.l1.unwrap_or(e.l1),
                window_scatters: f.window_scatters.unwrap_or(e.window_scatters),
                view_walks: f.view_walks.unwrap_or(e.view_walks),
                light_samples: f.light_samples.unwrap_or(e.light_samples),
                view_share: f.view_share.unwrap_or(e.view_share),
                resample_every: f.resample_every.unwrap_or(e.resample_every),
            },
        }
    }
}

/// [`InternalSettings`] as a scene file is written: flat, every field
/// given, in the order the file format has always had.
#[derive(Serialize)]
struct InternalSettingsFlat {
    quality: Quality,
    s_star: Option<f32>,
    lights: u32,
    terms: u32,
    walks: u32,
    sh_order: u32,
    kernel_radius: Option<f32>,
    uniform_mix: f32,
    clock: Clock,
    l1: L1Form,
    window_scatters: u32,
    view_walks: u32,
    light_samples: u32,
    view_share: f32,
    resample_every: u32,
}

impl From<InternalSettings> for InternalSettingsFlat {
    fn from(s: InternalSettings) -> Self {
        let (k, e) = (s.knobs, s.expert);
        InternalSettingsFlat {
            quality: s.quality,
            s_star: k.s_star,
            lights: k.lights,
            terms: k.terms,
            walks: e.walks,
            sh_order: e.sh_order,
            kernel_radius: e.kernel_radius,
            uniform_mix: e.uniform_mix,
            clock: e.clock,
            l1: e.l1,
            window_scatters: e.window_scatters,
            view_walks: e.view_walks,
            light_samples: e.light_samples,
            view_share: e.view_share,
            resample_every: e.resample_every,
        }
    }
}

/// Largest accepted number of internal lights (memory: about 1 KiB each
/// at SH order 4).
pub const MAX_INTERNAL_LIGHTS: u32 = 1 << 20;
/// Largest accepted series truncation `N`.
pub const MAX_TERMS: u32 = 1 << 16;
/// The presets' series truncation `N`: with the default `s*` of half a
/// mean free path the series runs to a path length of 2048 mean free paths,
/// long enough for the walks to end on their own (they leave the medium or
/// the roulette ends them) on every medium of the suite. At 256 windows
/// (128 mean free paths) the thick cumulus lost the light of paths longer
/// than that, 3.6 % of its image and 3–6 % of its lit body
/// ([validation §3.8](crate::doc::validation)).
pub const DEFAULT_TERMS: u32 = 4096;
/// Largest accepted number of walks per light `K`.
pub const MAX_WALKS: u32 = 1 << 16;
/// The highest order of the internal lights' spherical harmonics
/// (`sh_order`).
pub const MAX_SH_ORDER: u32 = 4;
/// The most stratified points per camera ray of the final gather
/// (`light_samples`; the estimators size their arrays by it).
pub const MAX_GATHER_POINTS: usize = 256;
/// The most scatterings inside the final window the gather follows
/// (`window_scatters`).
pub const MAX_WINDOW_SCATTERS: u32 = 3;

/// Settings of a render, saved with the scene.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RenderSettings {
    /// The estimator.
    pub method: Method,
    /// Samples per pixel of a finished still.
    pub spp: u32,
    /// Seed of every random stream: the same seed gives the same image.
    pub seed: u64,
    /// Parameters of the internal-lights method.
    pub internal: InternalSettings,
}

impl Default for RenderSettings {
    /// The internal lights (what Lantern is for; their defaults are right
    /// on the suite's media), 64 passes, seed 0.
    fn default() -> Self {
        Self {
            method: Method::Internal,
            spp: 64,
            seed: 0,
            internal: InternalSettings::default(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> InternalSettings {
        ron::from_str(text).unwrap()
    }

    /// A file names a preset and overrides some of its fields; the others
    /// come from the preset, and what the settings write reads back the same.
    #[test]
    fn presets_fill_what_a_file_leaves_out() {
        assert_eq!(parse("()"), Quality::Final.settings());
        assert_eq!(parse("(quality: Preview)"), Quality::Preview.settings());
        let edited =
            parse("(quality: Preview, walks: 64, s_star: Some(0.25), kernel_radius: None)");
        assert_eq!(edited, {
            let mut want = Quality::Preview.settings();
            want.expert.walks = 64;
            want.knobs.s_star = Some(0.25);
            want
        });
        // Files written before the presets: every field plain, as before.
        let old = parse("(s_star: None, lights: 1024, terms: 16, walks: 64, view_walks: 0)");
        assert_eq!(
            (
                old.knobs.lights,
                old.knobs.terms,
                old.expert.walks,
                old.expert.view_walks
            ),
            (1024, 16, 64, 0)
        );
        assert_eq!(old.quality, Quality::Final);
        let text = ron::to_string(&edited).unwrap();
        assert_eq!(parse(&text), edited);
        // Written flat, as the format has always been.
        assert!(
            text.contains("walks:64") && !text.contains("expert"),
            "{text}"
        );
        assert!(ron::from_str::<InternalSettings>("(walkz: 3)").is_err());
    }

    /// The presets differ where they say they do.
    #[test]
    fn preview_does_less_work_than_final() {
        let (p, f) = (Quality::Preview.settings(), Quality::Final.settings());
        assert!(p.expert.walks < f.expert.walks && p.expert.view_walks < f.expert.view_walks);
        assert!(p.expert.light_samples < f.expert.light_samples && p.knobs.lights < f.knobs.lights);
        assert_eq!(
            (p.knobs.s_star, p.knobs.terms, p.expert.clock),
            (f.knobs.s_star, f.knobs.terms, f.expert.clock)
        );
    }
}
