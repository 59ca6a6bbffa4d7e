//! The command line's shared argument types: the backend, an image size,
//! the internal lights' presets and parameter overrides (method §3–§6's
//! `s*`, `M`, `N`, `K`, …), and `render`'s time limit. Imports no command.

use std::path::PathBuf;

use clap::ValueEnum;

use crate::scene::{Clock, InternalSettings, L1Form, Quality};

/// An image size on the command line: `N` (square) or `WxH`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ImageSize {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
}

impl std::str::FromStr for ImageSize {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        let parse = |v: &str| {
            v.trim()
                .parse::<u32>()
                .map_err(|_| format!("{s:?}: expected N or WIDTHxHEIGHT in pixels"))
        };
        let (width, height) = match s.split_once(['x', 'X', '×']) {
            Some((w, h)) => (parse(w)?, parse(h)?),
            None => {
                let n = parse(s)?;
                (n, n)
            }
        };
        Ok(Self { width, height })
    }
}

/// The internal lights' presets on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum QualityArg {
    /// Fewer walks and gather points: fast light sets for live edits.
    Preview,
    /// The settings the accuracy targets are measured with (the default).
    Final,
}

impl From<QualityArg> for Quality {
    fn from(q: QualityArg) -> Self {
        match q {
            QualityArg::Preview => Quality::Preview,
            QualityArg::Final => Quality::Final,
        }
    }
}

/// `--help`'s heading of the artist's knobs of the internal lights.
const KNOBS: &str = "Internal lights: the artist's knobs";
/// `--help`'s heading of the preset.
const PRESET: &str = "Internal lights: the preset";
/// `--help`'s heading of the expert settings.
const EXPERT: &str = "Internal lights: expert settings (the preset chooses them)";

/// Overrides of the internal-lights parameters (default: the scene's),
/// under `--help` headings that follow
/// [`crate::scene::InternalSettings`]' nesting: the
/// knobs, the preset, the expert settings.
#[derive(Clone, Debug, Default, clap::Args)]
pub struct InternalArgs {
    /// Window length s* (distance, or mean free paths for the optical-depth clock).
    #[arg(long, help_heading = KNOBS)]
    pub s_star: Option<f32>,
    /// Number of internal lights M.
    #[arg(long = "lights", help_heading = KNOBS)]
    pub lights: Option<u32>,
    /// Series truncation N (terms k = 0..=N).
    #[arg(long, help_heading = KNOBS)]
    pub terms: Option<u32>,
    /// Preset of the internal lights' settings: replaces the scene's, and
    /// the flags of the knobs and the expert settings override
    /// it.
    #[arg(long, value_enum, help_heading = PRESET)]
    pub quality: Option<QualityArg>,
    /// Time-gated walks per light K.
    #[arg(long, help_heading = EXPERT)]
    pub walks: Option<u32>,
    /// Spherical-harmonics order of F and J.
    #[arg(long, help_heading = EXPERT)]
    pub sh_order: Option<u32>,
    /// Kernel radius h (world units; default: 2.5 x the mean light spacing).
    #[arg(long, help_heading = EXPERT)]
    pub kernel_radius: Option<f32>,
    /// Uniform fraction u of the light placement.
    #[arg(long, help_heading = EXPERT)]
    pub uniform_mix: Option<f32>,
    /// What the path-length clock counts.
    #[arg(long, value_enum, help_heading = EXPERT)]
    pub clock: Option<Clock>,
    /// The form of the gather's L1 (single scatter of the internal lights).
    #[arg(long, value_enum, help_heading = EXPERT)]
    pub l1: Option<L1Form>,
    /// Scatterings inside the final window that the field form of L1
    /// follows (1: the note's single-scatter kernel; 2, 3: the next terms).
    #[arg(long, help_heading = EXPERT)]
    pub window_scatters: Option<u32>,
    /// Walks per light towards the camera, for the view's L0 (0: none;
    /// L0 then reads the lights' spherical harmonics).
    #[arg(long, help_heading = EXPERT)]
    pub view_walks: Option<u32>,
    /// Internal-light samples per camera sample.
    #[arg(long, help_heading = EXPERT)]
    pub light_samples: Option<u32>,
    /// Share of the lights placed in the camera rays' windows instead of
    /// by density (0..=1).
    #[arg(long, help_heading = EXPERT)]
    pub view_share: Option<f32>,
    /// Passes per set of internal lights; a fresh set (the seed's next)
    /// after each such run of passes, so the walk noise averages out
    /// (0: one set for the whole render).
    #[arg(long, help_heading = EXPERT)]
    pub resample_every: Option<u32>,
}

impl InternalArgs {
    /// Writes the given overrides into `settings`.
    pub fn apply(&self, settings: &mut InternalSettings) {
        if let Some(q) = self.quality {
            *settings = Quality::from(q).settings();
        }
        if let Some(v) = self.s_star {
            settings.knobs.s_star = Some(v);
        }
        if let Some(v) = self.lights {
            settings.knobs.lights = v;
        }
        if let Some(v) = self.terms {
            settings.knobs.terms = v;
        }
        if let Some(v) = self.walks {
            settings.expert.walks = v;
        }
        if let Some(v) = self.sh_order {
            settings.expert.sh_order = v;
        }
        if let Some(v) = self.kernel_radius {
            settings.expert.kernel_radius = Some(v);
        }
        if let Some(v) = self.uniform_mix {
            settings.expert.uniform_mix = v;
        }
        if let Some(v) = self.clock {
            settings.expert.clock = v;
        }
        if let Some(v) = self.l1 {
            settings.expert.l1 = v;
        }
        if let Some(v) = self.window_scatters {
            settings.expert.window_scatters = v;
        }
        if let Some(v) = self.view_walks {
            settings.expert.view_walks = v;
        }
        if let Some(v) = self.light_samples {
            settings.expert.light_samples = v;
        }
        if let Some(v) = self.view_share {
            settings.expert.view_share = v;
        }
        if let Some(v) = self.resample_every {
            settings.expert.resample_every = v;
        }
    }
}

/// `lantern render`'s time limit and variance output.
#[derive(Clone, Debug, Default, clap::Args)]
pub struct TimedArgs {
    /// Render passes until this many seconds are spent (the internal
    /// lights' build included), at least one; `--spp` is then an upper
    /// bound (without it the scene's spp is ignored). The spp reached and
    /// the seconds are printed and stored in the EXR header.
    #[arg(long, value_name = "SECONDS")]
    pub time: Option<f64>,
    /// Also write the variance of each pixel's mean (sample variance /
    /// spp) to this EXR, as `converge --converged` and `equal-time` read
    /// it next to a converged image (`NAME_var.exr` beside `NAME.exr`).
    #[arg(long, value_name = "FILE.exr")]
    pub variance: Option<PathBuf>,
    /// With `--time`, renew the internal lights' set every
    /// `resample_every` passes as a render of fixed spp does, instead of
    /// balancing the sets' length and kernel against the passes from the
    /// noise and the costs measured while rendering (both backends; the
    /// GPU's balanced schedule reads its accumulated moments back once per
    /// set).
    #[arg(long)]
    pub fixed_renewal: bool,
}
