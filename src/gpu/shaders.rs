//! WGSL sources and how modules are assembled from them.
//!
//! WGSL has no `#include`. The shaders in `shaders/` are split like
//! `src/physics/` (one file per topic: `rng`, `volume`, `majorant`,
//! `tracking`, `phase`, `lights`, `reference`, …) and a module is the plain
//! concatenation of named parts, in dependency order, with a comment line
//! naming each part so that a compiler message can be traced back to its
//! file. Every part is embedded at compile time with `include_str!`, so the
//! binary needs no shader files at run time. The integration tests run naga
//! over every assembled module and check that every `.wgsl` file under
//! `shaders/` belongs to at least one of them.
//!
//! The constants and tags that Rust and WGSL share are not written in the
//! shaders: [`WGSL_CONSTANTS`] lists them with the Rust items they come
//! from, and [`ModuleSource::assemble`] puts them first in every module as
//! WGSL `const` declarations ([`prelude`]), their floats written so that
//! they read back to the same bits. A test fails if a `.wgsl` file declares
//! one of them by hand.

/// One WGSL file, embedded in the binary.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ShaderPart {
    /// Path relative to `shaders/`.
    pub path: &'static str,
    /// The file's text.
    pub source: &'static str,
}

macro_rules! part {
    ($path:literal) => {
        ShaderPart {
            path: $path,
            source: include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/shaders/", $path)),
        }
    };
}

/// PCG random streams (`physics/rng.rs`).
pub const RNG: ShaderPart = part!("common/rng.wgsl");
/// Orthonormal frames (`physics/frame.rs`).
pub const FRAME: ShaderPart = part!("common/frame.wgsl");
/// Henyey–Greenstein (`physics/phase.rs`).
pub const PHASE: ShaderPart = part!("common/phase.wgsl");
/// Scene data and its bindings 0–4 (`gpu/mirrors.rs`).
pub const SCENE: ShaderPart = part!("common/scene.wgsl");
/// Density lookup and ray–box clipping (`physics/volume.rs`,
/// `scene/grid.rs`).
pub const VOLUME: ShaderPart = part!("common/volume.wgsl");
/// The majorant grid's DDA (`physics/majorant.rs`).
pub const MAJORANT: ShaderPart = part!("common/majorant.wgsl");
/// Delta/spectral and ratio tracking (`physics/tracking.rs`).
pub const TRACKING: ShaderPart = part!("common/tracking.wgsl");
/// External lights (`physics/lights.rs`).
pub const LIGHTS: ShaderPart = part!("common/lights.wgsl");
/// Camera rays (`scene/camera.rs`).
pub const CAMERA: ShaderPart = part!("common/camera.wgsl");
/// Progressive accumulation (`render/film.rs`).
pub const ACCUMULATE: ShaderPart = part!("common/accumulate.wgsl");
/// The reference estimator (`physics/reference.rs`).
pub const REFERENCE: ShaderPart = part!("common/reference.wgsl");
/// The reference renderer's entry point (`cpu/mod.rs`, reference method).
pub const REFERENCE_MAIN: ShaderPart = part!("reference/main.wgsl");
/// Real spherical harmonics (`physics/sh.rs`).
pub const SH: ShaderPart = part!("common/sh.wgsl");
/// The cached internal lights' bindings 6–8 (`gpu/gather.rs`).
pub const INTERNAL_DATA: ShaderPart = part!("common/internal_data.wgsl");
/// The path-length clock and the time-gated walk
/// (`physics/internal/walk.rs`).
pub const GATED_WALK: ShaderPart = part!("common/gated_walk.wgsl");
/// Light grids (`physics/internal/light_index.rs`).
pub const LIGHT_INDEX: ShaderPart = part!("common/light_index.wgsl");
/// Evaluating the internal lights (`physics/internal/sources.rs`).
pub const INTERNAL: ShaderPart = part!("common/internal.wgsl");
/// The final gather (`physics/internal/gather.rs`).
pub const GATHER: ShaderPart = part!("common/gather.wgsl");
/// The internal-lights renderer's entry point (`cpu/mod.rs`, internal
/// method).
pub const GATHER_MAIN: ShaderPart = part!("gather/main.wgsl");

/// Placement of the internal lights (`physics/internal/placement.rs`).
pub const PLACEMENT: ShaderPart = part!("common/placement.wgsl");
/// The placement's entry point (`physics/internal/placement.rs`, `sample_lights`).
pub const PLACEMENT_MAIN: ShaderPart = part!("placement/main.wgsl");
/// The walks' entry point (`physics/internal/sources.rs`, the walk loop of
/// `InternalLights::build_at`).
pub const WALKS_MAIN: ShaderPart = part!("walks/main.wgsl");
/// Display transforms (`render/tonemap.rs`).
pub const TONEMAP: ShaderPart = part!("common/tonemap.wgsl");
/// The previewer's display pass: parameters, bindings, heatmap ramp
/// (`gpu/display.rs`, `ui/viewport.rs`).
pub const DISPLAY_MAIN: ShaderPart = part!("display/main.wgsl");
/// The display pass's image entry point.
pub const DISPLAY_IMAGE: ShaderPart = part!("display/image.wgsl");
/// The display pass's statistics (reduction) entry point.
pub const DISPLAY_STATS: ShaderPart = part!("display/stats.wgsl");

/// The value of a constant of the WGSL prelude.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum WgslValue {
    /// An `f32`.
    F32(f32),
    /// A `u32`.
    U32(u32),
    /// An `array<f32, N>`.
    F32Array(&'static [f32]),
}

/// A constant that the shaders take from Rust: its WGSL name, its value and
/// the Rust expression the value comes from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WgslConst {
    /// The name the shaders use.
    pub name: &'static str,
    /// The value, read from the Rust item.
    pub value: WgslValue,
    /// The Rust expression (written into the prelude as a comment).
    pub rust: &'static str,
}

/// A [`WgslConst`] of kind `$kind` named `$name`, from the Rust expression
/// `$value` (whose text is kept as [`WgslConst::rust`]); or, written
/// `shared!(KIND, NAME in path::to::module)`, from the Rust item of the
/// same name, `path::to::module::NAME`.
macro_rules! shared {
    ($kind:ident, $name:ident in $($module:ident)::+) => {
        WgslConst {
            name: stringify!($name),
            value: WgslValue::$kind($($module)::+ :: $name),
            rust: concat!($(stringify!($module), "::",)+ stringify!($name)),
        }
    };
    ($name:literal, $kind:ident, $($value:tt)+) => {
        WgslConst {
            name: $name,
            value: WgslValue::$kind($($value)+),
            rust: stringify!($($value)+),
        }
    };
}

/// Every constant and tag that Rust and the WGSL share, generated into
/// every module by [`prelude`]. The shaders must not declare these names
/// themselves (a test checks every file under `shaders/`).
pub const WGSL_CONSTANTS: &[WgslConst] = &[
    // Scene data tags (`gpu/mirrors.rs`, `shaders/common/scene.wgsl`).
    shared!(U32, DENSITY_SPHERE in crate::gpu::mirrors),
    shared!(U32, DENSITY_BOX in crate::gpu::mirrors),
    shared!(U32, DENSITY_GRID in crate::gpu::mirrors),
    shared!(U32, LIGHT_SUN in crate::gpu::mirrors),
    shared!(U32, LIGHT_POINT in crate::gpu::mirrors),
    shared!(U32, ENV_NONE in crate::gpu::mirrors),
    shared!(U32, ENV_CONSTANT in crate::gpu::mirrors),
    shared!(U32, ENV_MAP in crate::gpu::mirrors),
    // The settings' enums (`scene/settings.rs`).
    shared!("CLOCK_GEOMETRIC", U32, crate::scene::Clock::Geometric.tag()),
    shared!(
        "CLOCK_OPTICAL_DEPTH",
        U32,
        crate::scene::Clock::OpticalDepth.tag()
    ),
    shared!("L1_FIELD", U32, crate::scene::L1Form::Field.tag()),
    shared!("L1_POINTS", U32, crate::scene::L1Form::Points.tag()),
    // The display pass (`gpu/display.rs`).
    shared!(U32, VIEW_CLAMP in crate::gpu::mirrors),
    shared!(U32, VIEW_FILMIC in crate::gpu::mirrors),
    shared!(U32, MODE_SINGLE in crate::gpu::mirrors),
    shared!(U32, MODE_SPLIT in crate::gpu::mirrors),
    shared!(U32, MODE_HEAT in crate::gpu::mirrors),
    // Workgroup sizes the dispatches count with.
    shared!(U32, WORKGROUP_SIDE in crate::gpu::mirrors),
    shared!(U32, WALK_LANES in crate::gpu::mirrors),
    shared!(U32, PLACEMENT_LANES in crate::gpu::mirrors),
    // The walks' private array of gates, `N + 1` for the largest `N`.
    shared!(
        "GPU_MAX_GATES",
        U32,
        crate::physics::internal::clock::RESOLVED_TERMS + 1
    ),
    // The random streams (`physics/rng.rs`, `shaders/common/rng.wgsl`).
    shared!("RNG_MULTIPLIER", U32, crate::physics::rng::MULTIPLIER),
    shared!(
        "RNG_INVERSE_MULTIPLIER",
        U32,
        crate::physics::rng::INVERSE_MULTIPLIER
    ),
    shared!("RNG_INCREMENT", U32, crate::physics::rng::INCREMENT),
    shared!("R2_STEP_X", U32, crate::physics::rng::R2_STEPS[0]),
    shared!("R2_STEP_Y", U32, crate::physics::rng::R2_STEPS[1]),
    shared!(U32, PIXEL_OFFSET_STREAM in crate::physics::rng),
    // Random stream tags.
    shared!(U32, PLACEMENT_STREAM in crate::physics::internal::placement),
    shared!(U32, WALK_STREAM in crate::physics::internal::sources),
    // The estimators' constants.
    shared!("PI", F32, std::f32::consts::PI),
    shared!(
        "HG_ISOTROPIC_EPS",
        F32,
        crate::physics::phase::ISOTROPIC_EPS
    ),
    shared!(F32, MIN_DIST2 in crate::physics::lights),
    shared!(F32, FAR_LIGHT in crate::physics::lights),
    shared!(U32, RR_START_DEPTH in crate::physics::reference),
    shared!(F32, RR_MAX_SURVIVAL in crate::physics::reference),
    shared!(F32, GATE_PHASE_ROULETTE in crate::physics::reference),
    shared!("SH_MAX_ORDER", U32, crate::physics::sh::MAX_ORDER),
    shared!("SH_NORM", F32Array, &crate::physics::sh::NORM),
    shared!(F32, CLOCK_SPLIT_WINDOW in crate::physics::internal::clock),
    shared!(F32, CLOCK_MAX_STEPS in crate::physics::internal::clock),
    shared!(U32, PHASE_DROPPED_BITS in crate::physics::internal::clock),
    shared!(F32, COLLISION_FLOOR in crate::physics::internal::chances),
    shared!(F32, COLLISION_DEPTH in crate::physics::internal::chances),
    shared!(U32, GUIDED_COLLISIONS in crate::physics::internal::guiding),
    shared!(U32, COLLISION_TAIL_AFTER in crate::physics::internal::walk),
    shared!(F32, COLLISION_TAIL_MIN_G in crate::physics::internal::walk),
    shared!(F32, GUIDE_PROBABILITY in crate::physics::internal::guiding),
    shared!(F32, GUIDE_G in crate::physics::internal::guiding),
    shared!(F32, SECOND_FLIGHT_MIN_G in crate::physics::internal::guiding),
    shared!(F32, SECOND_FLIGHT_MAX_DEPTH in crate::physics::internal::guiding),
    shared!(F32, GOLDEN_ANGLE in crate::physics::internal::sources),
    shared!(
        "GATHER_TRANSMITTANCE",
        F32,
        crate::physics::internal::gather::GATHER_TRANSMITTANCE.wgsl_rate()
    ),
    shared!(
        "TRANSMITTANCE_MARCHED",
        F32,
        crate::physics::tracking::Transmittance::Marched.wgsl_rate()
    ),
    shared!(F32, MARCH_SEGMENT_DEPTH in crate::physics::tracking),
    shared!(F32, MARCH_STRIDE_DEPTH in crate::physics::tracking),
    shared!(U32, MARCH_MAX_TERMS in crate::physics::tracking),
    shared!(
        "SEGMENT_PIECES",
        U32,
        crate::physics::internal::segment_pdf::PIECES as u32
    ),
    shared!(
        "SEGMENT_DEFENSIVE",
        F32,
        crate::physics::internal::segment_pdf::DEFENSIVE
    ),
];

/// The first line of [`prelude`].
const PRELUDE_HEADER: &str = "// ---- generated from Rust: gpu::shaders::WGSL_CONSTANTS ----\n";

/// What [`ModuleSource::locate`] names the generated prelude's lines by.
pub const PRELUDE_PATH: &str = "<generated prelude>";

/// A WGSL literal of `x` that reads back to the same `f32`: WGSL reads an
/// unsuffixed literal as an abstract (f64) float and then rounds it to
/// `f32`, so the shortest decimal of `x` is used when that double rounding
/// returns `x`, and otherwise the shortest decimal of `x` widened to `f64`
/// (exact in `f64`, so it rounds back exactly).
pub fn wgsl_f32(x: f32) -> String {
    let short = format!("{x:?}");
    match short.parse::<f64>() {
        Ok(v) if (v as f32).to_bits() == x.to_bits() => short,
        _ => format!("{:?}", f64::from(x)),
    }
}

/// The WGSL declaration of one constant, on one line.
fn declaration(c: &WgslConst) -> String {
    let value = match c.value {
        WgslValue::F32(x) => format!("const {}: f32 = {};", c.name, wgsl_f32(x)),
        WgslValue::U32(x) => format!("const {}: u32 = {x}u;", c.name),
        WgslValue::F32Array(xs) => {
            let items: Vec<String> = xs.iter().map(|&x| wgsl_f32(x)).collect();
            format!(
                "const {}: array<f32, {n}> = array<f32, {n}>({});",
                c.name,
                items.join(", "),
                n = xs.len()
            )
        }
    };
    format!("{value} // {}\n", c.rust)
}

/// The WGSL declarations of [`WGSL_CONSTANTS`], one line each after a
/// header line: the start of every assembled module.
pub fn prelude() -> String {
    let mut out = String::from(PRELUDE_HEADER);
    for c in WGSL_CONSTANTS {
        out.push_str(&declaration(c));
    }
    out
}

/// A shader module: a name and its parts in dependency order.
#[derive(Clone, Copy, Debug)]
pub struct ModuleSource {
    /// Label of the module (also used in error messages).
    pub name: &'static str,
    /// The parts, each after those it uses.
    pub parts: &'static [ShaderPart],
    /// The compute entry point.
    pub entry_point: &'static str,
}

/// The reference path tracer, one pass per dispatch.
pub const REFERENCE_MODULE: ModuleSource = ModuleSource {
    name: "reference",
    parts: &[
        RNG,
        FRAME,
        PHASE,
        SCENE,
        VOLUME,
        MAJORANT,
        TRACKING,
        LIGHTS,
        CAMERA,
        ACCUMULATE,
        REFERENCE,
        REFERENCE_MAIN,
    ],
    entry_point: "reference_pass",
};

/// The internal-lights gather with lights built on the CPU, one pass per
/// dispatch.
pub const GATHER_MODULE: ModuleSource = ModuleSource {
    name: "gather",
    parts: &[
        RNG,
        FRAME,
        PHASE,
        SCENE,
        VOLUME,
        MAJORANT,
        TRACKING,
        LIGHTS,
        CAMERA,
        ACCUMULATE,
        REFERENCE,
        SH,
        INTERNAL_DATA,
        GATED_WALK,
        LIGHT_INDEX,
        INTERNAL,
        GATHER,
        GATHER_MAIN,
    ],
    entry_point: "gather_pass",
};

/// Placement of the internal lights, one invocation per light.
pub const PLACEMENT_MODULE: ModuleSource = ModuleSource {
    name: "placement",
    parts: &[SCENE, RNG, VOLUME, PLACEMENT, PLACEMENT_MAIN],
    entry_point: "place_lights",
};

/// The internal lights' time-gated walks and SH projection, one workgroup
/// per light and one walk per invocation per dispatch.
pub const WALKS_MODULE: ModuleSource = ModuleSource {
    name: "walks",
    parts: &[
        RNG, FRAME, PHASE, SCENE, VOLUME, MAJORANT, TRACKING, LIGHTS, REFERENCE, SH, GATED_WALK,
        ACCUMULATE, WALKS_MAIN,
    ],
    entry_point: "walk_lights",
};

/// The previewer's display pass: accumulation buffers to the shown image.
pub const DISPLAY_MODULE: ModuleSource = ModuleSource {
    name: "display",
    parts: &[ACCUMULATE, TONEMAP, DISPLAY_MAIN, DISPLAY_IMAGE],
    entry_point: "display_image",
};

/// The previewer's statistics: accumulation buffers to four means.
pub const DISPLAY_STATS_MODULE: ModuleSource = ModuleSource {
    name: "display statistics",
    parts: &[ACCUMULATE, DISPLAY_MAIN, DISPLAY_STATS],
    entry_point: "display_stats",
};

/// Every module the backend builds (the tests validate each).
pub const MODULES: &[ModuleSource] = &[
    REFERENCE_MODULE,
    GATHER_MODULE,
    PLACEMENT_MODULE,
    WALKS_MODULE,
    DISPLAY_MODULE,
    DISPLAY_STATS_MODULE,
];

impl ModuleSource {
    /// The module's WGSL text: the [`prelude`], then its parts
    /// concatenated, each preceded by a comment naming its file.
    pub fn assemble(&self) -> String {
        let mut out = prelude();
        for p in self.parts {
            out.push_str("// ---- shaders/");
            out.push_str(p.path);
            out.push_str(" ----\n");
            out.push_str(p.source);
            if !p.source.ends_with('\n') {
                out.push('\n');
            }
        }
        out
    }

    /// The part (file) and line within it of `line` (1-based) of
    /// [`ModuleSource::assemble`]'s text, for error messages; the
    /// prelude's constants are named [`PRELUDE_PATH`] and counted from 1.
    pub fn locate(&self, line: usize) -> Option<(&'static str, usize)> {
        // The prelude: one header line, then one line per constant.
        let mut start = 1;
        if line > start && line <= start + WGSL_CONSTANTS.len() {
            return Some((PRELUDE_PATH, line - start));
        }
        start += WGSL_CONSTANTS.len() + 1;
        for p in self.parts {
            // One header line, then the part's lines.
            let lines = p.source.lines().count();
            if line > start && line <= start + lines {
                return Some((p.path, line - start));
            }
            start += lines + 1;
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashSet;
    use std::path::Path;

    #[test]
    fn locate_maps_assembled_lines_to_files() {
        let m = REFERENCE_MODULE;
        let text = m.assemble();
        let lines: Vec<&str> = text.lines().collect();
        let prelude_lines = WGSL_CONSTANTS.len() + 1;
        // The first line of the second part.
        let first = prelude_lines + m.parts[0].source.lines().count() + 3;
        assert_eq!(m.locate(first), Some((m.parts[1].path, 1)));
        assert_eq!(lines[first - 1], m.parts[1].source.lines().next().unwrap());
        // The header lines, and the prelude's first constant.
        assert_eq!(m.locate(1), None);
        assert_eq!(m.locate(prelude_lines + 1), None);
        assert_eq!(m.locate(2), Some((PRELUDE_PATH, 1)));
        assert!(lines[1].starts_with(&format!("const {}:", WGSL_CONSTANTS[0].name)));
    }

    #[test]
    fn generated_names_are_unique() {
        let mut seen = HashSet::new();
        for c in WGSL_CONSTANTS {
            assert!(seen.insert(c.name), "{} is generated twice", c.name);
        }
    }

    /// Every float of the prelude reads back to the Rust value's bits, as
    /// WGSL reads it (an abstract float rounded to `f32`) and as `f32`.
    #[test]
    fn generated_floats_round_trip() {
        let floats = WGSL_CONSTANTS.iter().flat_map(|c| match c.value {
            WgslValue::F32(x) => vec![(c.name, x)],
            WgslValue::F32Array(xs) => xs.iter().map(|&x| (c.name, x)).collect(),
            WgslValue::U32(_) => vec![],
        });
        for (name, x) in floats {
            assert!(x.is_finite(), "{name}: {x} has no WGSL literal");
            let lit = wgsl_f32(x);
            assert!(lit.contains(['.', 'e']), "{name}: {lit} is not a float");
            let back = lit.parse::<f64>().unwrap() as f32;
            assert_eq!(back.to_bits(), x.to_bits(), "{name}: {lit}");
            assert_eq!(lit.parse::<f32>().unwrap().to_bits(), x.to_bits());
        }
        // A value whose shortest decimal would round twice is still exact.
        for bits in [0x3e99_999a_u32, 0x3f80_0001, 0x0000_0001, 0x7f7f_ffff] {
            let x = f32::from_bits(bits);
            assert_eq!((wgsl_f32(x).parse::<f64>().unwrap() as f32).to_bits(), bits);
        }
    }

    /// naga reads the prelude's constants back to the Rust values.
    #[test]
    fn naga_reads_the_prelude_back() {
        use naga::{Expression, Literal};
        let text = prelude();
        let module = naga::front::wgsl::parse_str(&text).unwrap();
        let literal = |h: naga::Handle<Expression>| match module.global_expressions[h] {
            Expression::Literal(Literal::F32(x)) => WgslValue::F32(x),
            Expression::Literal(Literal::U32(x)) => WgslValue::U32(x),
            ref e => panic!("not a literal: {e:?}"),
        };
        for c in WGSL_CONSTANTS {
            let (_, k) = module
                .constants
                .iter()
                .find(|(_, k)| k.name.as_deref() == Some(c.name))
                .unwrap_or_else(|| panic!("{} is not in the prelude", c.name));
            match (c.value, &module.global_expressions[k.init]) {
                (WgslValue::F32Array(xs), Expression::Compose { components, .. }) => {
                    let got: Vec<WgslValue> = components.iter().map(|&h| literal(h)).collect();
                    let want: Vec<WgslValue> = xs.iter().map(|&x| WgslValue::F32(x)).collect();
                    assert_eq!(got, want, "{}", c.name);
                }
                (WgslValue::F32(x), _) => {
                    let WgslValue::F32(y) = literal(k.init) else {
                        panic!("{} is not an f32", c.name)
                    };
                    assert_eq!(x.to_bits(), y.to_bits(), "{}", c.name);
                }
                (v, _) => assert_eq!(literal(k.init), v, "{}", c.name),
            }
        }
    }

    fn wgsl_files(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                wgsl_files(&path, out);
            } else if path.extension().is_some_and(|e| e == "wgsl") {
                out.push(path);
            }
        }
    }

    /// No shader writes by hand a constant that the prelude generates from
    /// Rust (it would fail to compile as a redefinition, or, in a file of
    /// no module, drift silently).
    #[test]
    fn no_shader_declares_a_generated_constant() {
        let generated: HashSet<&str> = WGSL_CONSTANTS.iter().map(|c| c.name).collect();
        let mut files = Vec::new();
        wgsl_files(
            &Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders"),
            &mut files,
        );
        assert!(files.len() >= MODULES.iter().map(|m| m.parts.len()).max().unwrap());
        let mut found = Vec::new();
        for f in &files {
            let text = std::fs::read_to_string(f).unwrap();
            for (i, line) in text.lines().enumerate() {
                let line = line.trim_start();
                let Some(rest) = ["const ", "override ", "alias ", "var<private> "]
                    .iter()
                    .find_map(|k| line.strip_prefix(k))
                else {
                    continue;
                };
                let name: String = rest
                    .trim_start()
                    .chars()
                    .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                    .collect();
                if generated.contains(name.as_str()) {
                    found.push(format!("{}:{}: {name}", f.display(), i + 1));
                }
            }
        }
        assert!(
            found.is_empty(),
            "constants generated from Rust (gpu::shaders::WGSL_CONSTANTS) declared by hand:\n{}",
            found.join("\n")
        );
    }

    /// The prelude itself, for inspection (`--nocapture`).
    #[test]
    fn prelude_is_one_line_per_constant() {
        let text = prelude();
        assert_eq!(text.lines().count(), WGSL_CONSTANTS.len() + 1);
        println!("{text}");
    }
}
