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
/// (`physics/gated_walk.rs`).
pub const GATED_WALK: ShaderPart = part!("common/gated_walk.wgsl");
/// Light grids (`physics/light_index.rs`).
pub const LIGHT_INDEX: ShaderPart = part!("common/light_index.wgsl");
/// Evaluating the internal lights (`physics/internal.rs`).
pub const INTERNAL: ShaderPart = part!("common/internal.wgsl");
/// The final gather (`physics/gather.rs`).
pub const GATHER: ShaderPart = part!("common/gather.wgsl");
/// The internal-lights renderer's entry point (`cpu/mod.rs`, internal
/// method).
pub const GATHER_MAIN: ShaderPart = part!("gather/main.wgsl");

/// Placement of the internal lights (`physics/placement.rs`).
pub const PLACEMENT: ShaderPart = part!("common/placement.wgsl");
/// The placement's entry point (`physics/placement.rs`, `sample_lights`).
pub const PLACEMENT_MAIN: ShaderPart = part!("placement/main.wgsl");
/// The walks' entry point (`physics/internal.rs`, the walk loop of
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
        WALKS_MAIN,
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
    /// The module's WGSL text: its parts concatenated, each preceded by a
    /// comment naming its file.
    pub fn assemble(&self) -> String {
        let mut out = String::new();
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
    /// [`ModuleSource::assemble`]'s text, for error messages.
    pub fn locate(&self, line: usize) -> Option<(&'static str, usize)> {
        let mut start = 1;
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

    #[test]
    fn locate_maps_assembled_lines_to_files() {
        let m = REFERENCE_MODULE;
        let text = m.assemble();
        let lines: Vec<&str> = text.lines().collect();
        // The first line of the second part.
        let first = m.parts[0].source.lines().count() + 3;
        assert_eq!(m.locate(first), Some((m.parts[1].path, 1)));
        assert_eq!(lines[first - 1], m.parts[1].source.lines().next().unwrap());
        assert_eq!(m.locate(1), None);
    }

    /// The value of `const NAME: TYPE = VALUE;` in `part`, as a number.
    fn wgsl_const(part: ShaderPart, name: &str) -> f64 {
        let key = format!("const {name}:");
        let line = part
            .source
            .lines()
            .find(|l| l.trim_start().starts_with(&key))
            .unwrap_or_else(|| panic!("{} has no {name}", part.path));
        let value = line.split('=').nth(1).unwrap().trim().trim_end_matches(';');
        value.trim_end_matches('u').parse().unwrap()
    }

    /// The constants that the WGSL estimators repeat agree with the CPU's.
    #[test]
    fn wgsl_constants_mirror_the_cpu() {
        use crate::physics::{gated_walk, gather, segment_pdf};
        let pairs = [
            (GATHER, "TRACKING_RATE", gather::TRACKING_RATE as f64),
            (GATHER, "SEGMENT_PIECES", segment_pdf::PIECES as f64),
            (GATHER, "SEGMENT_DEFENSIVE", segment_pdf::DEFENSIVE as f64),
            (
                GATED_WALK,
                "COLLISION_FLOOR",
                gated_walk::COLLISION_FLOOR as f64,
            ),
            (
                GATED_WALK,
                "COLLISION_DEPTH",
                gated_walk::COLLISION_DEPTH as f64,
            ),
            (
                GATED_WALK,
                "GUIDE_PROBABILITY",
                gated_walk::GUIDE_PROBABILITY as f64,
            ),
            (GATED_WALK, "GUIDE_G", gated_walk::GUIDE_G as f64),
            (
                GATED_WALK,
                "CLOCK_MAX_STEPS",
                gated_walk::CLOCK_MAX_STEPS as f64,
            ),
            (
                GATED_WALK,
                "GUIDED_COLLISIONS",
                gated_walk::GUIDED_COLLISIONS as f64,
            ),
        ];
        for (part, name, cpu) in pairs {
            let gpu = wgsl_const(part, name);
            assert!(
                (gpu - cpu).abs() <= 1e-6 * cpu.abs(),
                "{}: {name} = {gpu}, the CPU's is {cpu}",
                part.path
            );
        }
    }
}
