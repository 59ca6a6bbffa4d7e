//! The GPU backend against the CPU.
//!
//! - Always (no GPU needed): naga parses and validates every assembled WGSL
//!   module, every `.wgsl` file under `shaders/` belongs to one, and the
//!   `#[repr(C)]` mirrors have the sizes and field offsets the shaders'
//!   structs have.

mod common;

use std::path::Path;

use lantern::gpu::mirrors::{GpuAccum, GpuCamera, GpuLight, GpuMedium, GpuPassParams, GpuScene};
use lantern::gpu::shaders::{ModuleSource, MODULES};

/// Parses and validates one assembled module, naming the file and line of
/// the first error.
fn validate(module: &ModuleSource) -> (naga::Module, naga::valid::ModuleInfo) {
    let text = module.assemble();
    let parsed = naga::front::wgsl::parse_str(&text).unwrap_or_else(|e| {
        let line = e.location(&text).map(|l| l.line_number as usize);
        panic!(
            "{}: WGSL parse error at {:?}:\n{}",
            module.name,
            line.and_then(|l| module.locate(l)),
            e.emit_to_string(&text)
        )
    });
    let info = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::default(),
    )
    .validate(&parsed)
    .unwrap_or_else(|e| {
        panic!(
            "{}: WGSL validation error:\n{}",
            module.name,
            e.emit_to_string(&text)
        )
    });
    assert!(
        parsed
            .entry_points
            .iter()
            .any(|ep| ep.name == module.entry_point),
        "{}: no entry point {}",
        module.name,
        module.entry_point
    );
    (parsed, info)
}

#[test]
fn every_wgsl_module_validates() {
    for m in MODULES {
        validate(m);
    }
}

fn wgsl_files(dir: &Path, out: &mut Vec<String>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            wgsl_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "wgsl") {
            let rel = path.strip_prefix(common::root().join("shaders")).unwrap();
            out.push(rel.to_string_lossy().replace('\\', "/"));
        }
    }
}

/// A WGSL file that no module includes would never be validated.
#[test]
fn every_wgsl_file_is_in_a_validated_module() {
    let mut files = Vec::new();
    wgsl_files(&common::root().join("shaders"), &mut files);
    assert!(!files.is_empty());
    for f in files {
        let part = MODULES
            .iter()
            .flat_map(|m| m.parts)
            .find(|p| p.path == f)
            .unwrap_or_else(|| panic!("shaders/{f} is in no module of gpu::shaders::MODULES"));
        let on_disk = std::fs::read_to_string(common::root().join("shaders").join(&f)).unwrap();
        assert_eq!(part.source, on_disk, "shaders/{f}: embedded copy is stale");
    }
}

/// The size and the offset of every field of a Rust mirror equal those of
/// the WGSL struct of the same name, as naga lays it out.
macro_rules! check_layout {
    ($module:expr, $wgsl:literal, $rust:ty, [$($field:ident),* $(,)?]) => {{
        let module: &naga::Module = $module;
        let (members, span) = module
            .types
            .iter()
            .find_map(|(_, t)| match &t.inner {
                naga::TypeInner::Struct { members, span } if t.name.as_deref() == Some($wgsl) => {
                    Some((members.clone(), *span))
                }
                _ => None,
            })
            .unwrap_or_else(|| panic!("no WGSL struct {}", $wgsl));
        assert_eq!(span as usize, std::mem::size_of::<$rust>(), "size of {}", $wgsl);
        let rust: Vec<(&str, usize)> = vec![$((stringify!($field), std::mem::offset_of!($rust, $field))),*];
        assert_eq!(members.len(), rust.len(), "field count of {}", $wgsl);
        for (m, (name, offset)) in members.iter().zip(rust) {
            assert_eq!(m.name.as_deref(), Some(name), "field order of {}", $wgsl);
            assert_eq!(m.offset as usize, offset, "offset of {}.{}", $wgsl, name);
        }
    }};
}

#[test]
fn mirrors_match_wgsl_layout() {
    let (module, _) = validate(&lantern::gpu::shaders::REFERENCE_MODULE);
    check_layout!(
        &module,
        "Camera",
        GpuCamera,
        [
            eye,
            width,
            forward,
            height,
            right_scaled,
            _pad0,
            up_scaled,
            _pad1
        ]
    );
    check_layout!(
        &module,
        "Medium",
        GpuMedium,
        [
            sigma_t,
            density_kind,
            albedo,
            g,
            bounds_min,
            _pad0,
            bounds_max,
            _pad1,
            shape_a,
            radius,
            shape_b,
            _pad2,
            grid_dims,
            _pad3,
            majorant_res,
            _pad4,
            majorant_min,
            _pad5,
            majorant_max,
            _pad6
        ]
    );
    check_layout!(
        &module,
        "Scene",
        GpuScene,
        [camera, medium, sun_count, point_count, _pad0, _pad1]
    );
    check_layout!(
        &module,
        "PassParams",
        GpuPassParams,
        [seed_lo, seed_hi, pass_index, sample_count]
    );
    check_layout!(&module, "Light", GpuLight, [vector, kind, power, _pad0]);
    check_layout!(&module, "Accum", GpuAccum, [mean, m2, single_mean]);
}
