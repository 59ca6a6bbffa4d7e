//! Voxel-grid loading through the public API (`lantern::scene::volume`):
//! round trips through the writers, the OpenVDB fixtures made by the real
//! OpenVDB library (`tests/data/volumes/make_vdb.py`), and one test per kind
//! of bad input, each checking that the error names the file and the
//! problem.

use std::path::{Path, PathBuf};

use glam::{UVec3, Vec3};
use lantern::scene::volume::{load_grid, write_mitsuba_vol, write_raw};
use lantern::scene::{GridFormat, SceneError, VoxelGrid};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/volumes")
        .join(name)
}

fn load(path: &Path) -> Result<VoxelGrid, SceneError> {
    load_grid(path, GridFormat::Auto, None)
}

/// Loads `path` expecting an error; checks the message names the file and
/// contains every one of `words`; returns the message.
fn expect_err(path: &Path, grid: Option<&str>, words: &[&str]) -> String {
    let e = match load_grid(path, GridFormat::Auto, grid) {
        Ok(g) => panic!("{} loaded ({:?}) but should fail", path.display(), g.dims),
        Err(e) => e.to_string(),
    };
    let name = path.file_name().unwrap().to_string_lossy();
    assert!(e.contains(&*name), "error does not name {name}: {e}");
    for w in words {
        assert!(e.contains(w), "error lacks {w:?}: {e}");
    }
    e
}

/// A 5×4×3 grid whose voxel (i, j, k) holds `i + 10 j + 100 k` (all
/// distinct, so any index mix-up shows).
fn test_grid() -> VoxelGrid {
    let dims = UVec3::new(5, 4, 3);
    let mut data = Vec::new();
    for k in 0..3 {
        for j in 0..4 {
            for i in 0..5 {
                data.push(value(i, j, k));
            }
        }
    }
    VoxelGrid {
        dims,
        bounds_min: Vec3::new(-1.0, -2.0, 0.5),
        bounds_max: Vec3::new(1.5, 2.0, 3.0),
        data,
    }
}

fn value(i: u32, j: u32, k: u32) -> f32 {
    (i + 10 * j + 100 * k) as f32
}

fn at(g: &VoxelGrid, i: u32, j: u32, k: u32) -> f32 {
    g.data[g.index(i, j, k)]
}

fn le_bytes(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// A `.vol` image written field by field (independently of the writer).
fn vol_image(encoding: i32, dims: [i32; 3], channels: i32, data: &[f32]) -> Vec<u8> {
    let mut b = b"VOL".to_vec();
    b.push(3);
    for v in [encoding, dims[0], dims[1], dims[2], channels] {
        b.extend(v.to_le_bytes());
    }
    b.extend(le_bytes(&[0.0, 0.0, 0.0, 1.0, 2.0, 3.0]));
    b.extend(le_bytes(data));
    b
}

fn raw_header(dims: (u32, u32, u32), order: &str, data: &str) -> String {
    format!(
        "(dims: ({}, {}, {}), bounds_min: (-1.0, 0.0, 2.0), bounds_max: (1.0, 4.0, 3.0), \
         axis_order: {order}, data: \"{data}\")",
        dims.0, dims.1, dims.2
    )
}

// ---------------------------------------------------------------------------
// Round trips.

#[test]
fn mitsuba_vol_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("grid.vol");
    let g = test_grid();
    write_mitsuba_vol(&p, &g).unwrap();
    // Header fields at their documented offsets.
    let bytes = std::fs::read(&p).unwrap();
    assert_eq!(bytes.len(), 48 + 60 * 4);
    assert_eq!(&bytes[..4], b"VOL\x03");
    assert_eq!(i32::from_le_bytes(bytes[8..12].try_into().unwrap()), 5);
    assert_eq!(f32::from_le_bytes(bytes[36..40].try_into().unwrap()), 1.5);

    let back = load(&p).unwrap();
    assert_eq!(back, g);
    assert_eq!(at(&back, 4, 3, 2), 234.0);
    assert_eq!(at(&back, 1, 2, 0), 21.0);
    assert_eq!(back.bounds_min, Vec3::new(-1.0, -2.0, 0.5));
    assert_eq!(back.bounds_max, Vec3::new(1.5, 2.0, 3.0));
    // An explicit format works for any extension.
    let q = dir.path().join("grid.bin");
    std::fs::copy(&p, &q).unwrap();
    assert_eq!(load_grid(&q, GridFormat::MitsubaVol, None).unwrap(), g);
}

#[test]
fn raw_round_trip_x_fastest() {
    let dir = tempfile::tempdir().unwrap();
    let header = dir.path().join("cloud.ron");
    let g = test_grid();
    write_raw(&header, &g).unwrap();
    let data_file = dir.path().join("cloud.raw");
    assert_eq!(std::fs::metadata(&data_file).unwrap().len(), 60 * 4);
    let text = std::fs::read_to_string(&header).unwrap();
    assert!(
        text.contains("XFastest") && text.contains("\"cloud.raw\""),
        "{text}"
    );
    // The data file is plain x-fastest float32.
    assert_eq!(std::fs::read(&data_file).unwrap(), le_bytes(&g.data));

    let back = load(&header).unwrap();
    assert_eq!(back, g);
    assert_eq!(at(&back, 3, 1, 2), 213.0);
}

#[test]
fn raw_z_fastest_is_converted() {
    let dir = tempfile::tempdir().unwrap();
    let (nx, ny, nz) = (5u32, 4u32, 3u32);
    // C order of an array indexed [x][y][z]: z fastest.
    let mut c_order = Vec::new();
    for i in 0..nx {
        for j in 0..ny {
            for k in 0..nz {
                c_order.push(value(i, j, k));
            }
        }
    }
    std::fs::write(dir.path().join("c.raw"), le_bytes(&c_order)).unwrap();
    let header = dir.path().join("c.ron");
    std::fs::write(&header, raw_header((nx, ny, nz), "ZFastest", "c.raw")).unwrap();
    let g = load(&header).unwrap();
    assert_eq!(g.dims, UVec3::new(5, 4, 3));
    assert_eq!(g.bounds_min, Vec3::new(-1.0, 0.0, 2.0));
    assert_eq!(g.bounds_max, Vec3::new(1.0, 4.0, 3.0));
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                assert_eq!(at(&g, i, j, k), value(i, j, k), "voxel ({i}, {j}, {k})");
            }
        }
    }
    assert_eq!(g.data, test_grid().data);
}

#[test]
fn raw_data_path_is_relative_to_the_header() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("bin")).unwrap();
    let g = test_grid();
    std::fs::write(dir.path().join("bin/d.raw"), le_bytes(&g.data)).unwrap();
    let header = dir.path().join("h.ron");
    std::fs::write(&header, raw_header((5, 4, 3), "XFastest", "bin/d.raw")).unwrap();
    assert_eq!(load(&header).unwrap().data, g.data);
}

// ---------------------------------------------------------------------------
// OpenVDB fixtures (written by OpenVDB 12; see make_vdb.py).

/// The `density` value of make_vdb.py at index coordinate (x, y, z).
fn vdb_density(x: i32, y: i32, z: i32) -> f32 {
    0.5 + 0.01 * x as f32 + 0.02 * y as f32 + 0.03 * z as f32
}

fn check_cloud_density(g: &VoxelGrid, tol: f32) {
    // Active index box [-3, 23] × [0, 11] × [2, 17].
    assert_eq!(g.dims, UVec3::new(27, 12, 16));
    // World = index · (0.1, 0.2, 0.05) + (1, -2, 0.5), half a voxel out.
    let close = |a: Vec3, b: Vec3| (a - b).abs().max_element() < 1e-5;
    assert!(
        close(g.bounds_min, Vec3::new(0.65, -2.1, 0.575)),
        "{:?}",
        g.bounds_min
    );
    assert!(
        close(g.bounds_max, Vec3::new(3.35, 0.3, 1.375)),
        "{:?}",
        g.bounds_max
    );
    let v = |x: i32, y: i32, z: i32| at(g, (x + 3) as u32, y as u32, (z - 2) as u32);
    let near = |a: f32, b: f32| (a - b).abs() <= tol * b.abs().max(1.0);
    // Leaf voxels.
    for (x, y, z) in [
        (-3, 0, 2),
        (5, 6, 7),
        (16, 9, 10),
        (0, 11, 17),
        (16, 11, 17),
    ] {
        assert!(
            near(v(x, y, z), vdb_density(x, y, z)),
            "({x},{y},{z}): {}",
            v(x, y, z)
        );
    }
    // The 8³ active tile over [16, 23] × [0, 7] × [8, 15], which also
    // replaced the voxels at x = 16 there.
    for (x, y, z) in [(16, 0, 8), (20, 3, 10), (23, 7, 15), (16, 7, 15)] {
        assert!(near(v(x, y, z), 2.0), "tile ({x},{y},{z}): {}", v(x, y, z));
    }
    // Inactive voxel holding 9.0 in the file, and empty space in the box.
    assert_eq!(v(0, 0, 2), 0.0);
    assert_eq!(v(20, 10, 3), 0.0);
    assert_eq!(v(23, 11, 17), 0.0);
    // Every active voxel, and nothing else, is non-zero.
    assert_eq!(g.data.iter().filter(|&&d| d > 0.0).count(), 4287);
    // Sample at a voxel centre in world space: index (5, 6, 7).
    let p = Vec3::new(5.0 * 0.1 + 1.0, 6.0 * 0.2 - 2.0, 7.0 * 0.05 + 0.5);
    assert!(near(g.sample(p), vdb_density(5, 6, 7)));
}

#[test]
fn vdb_fixture_loads() {
    let g = load(&fixture("cloud.vdb")).unwrap();
    check_cloud_density(&g, 1e-6);
    // The same through an explicit format and grid name.
    let h = load_grid(&fixture("cloud.vdb"), GridFormat::Vdb, Some("density")).unwrap();
    assert_eq!(g, h);
}

#[test]
fn vdb_other_grid_and_uniform_scale_map() {
    let g = load_grid(&fixture("cloud.vdb"), GridFormat::Auto, Some("temperature")).unwrap();
    assert_eq!(g.dims, UVec3::ONE);
    assert_eq!(g.data, vec![7.5]);
    // Voxel (1, 2, 3) with voxel size 0.5: centre (0.5, 1, 1.5).
    assert_eq!(g.bounds_min, Vec3::new(0.25, 0.75, 1.25));
    assert_eq!(g.bounds_max, Vec3::new(0.75, 1.25, 1.75));
}

#[test]
fn vdb_half_float_fixture_loads() {
    let g = load(&fixture("cloud_half.vdb")).unwrap();
    // Half floats carry 11 significant bits.
    check_cloud_density(&g, 1e-3);
    let full = load(&fixture("cloud.vdb")).unwrap();
    let worst = g
        .data
        .iter()
        .zip(&full.data)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(worst > 0.0 && worst < 2e-3, "half vs float: {worst}");
}

// ---------------------------------------------------------------------------
// Bad inputs: one test each.

#[test]
fn missing_files() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["nope.vol", "nope.ron", "nope.vdb"] {
        expect_err(&dir.path().join(name), None, &["cannot read"]);
    }
    // A header whose data file is missing names the data file.
    let header = dir.path().join("h.ron");
    std::fs::write(&header, raw_header((2, 2, 2), "XFastest", "gone.raw")).unwrap();
    let e = load(&header).unwrap_err().to_string();
    assert!(e.contains("gone.raw") && e.contains("cannot read"), "{e}");
}

#[test]
fn unknown_extension() {
    expect_err(
        Path::new("clouds/puff.nvdb"),
        None,
        &["extension", "'.nvdb'"],
    );
}

#[test]
fn vol_truncated_header() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("short.vol");
    let full = vol_image(1, [2, 2, 2], 1, &[1.0; 8]);
    std::fs::write(&p, &full[..14]).unwrap();
    expect_err(&p, None, &["truncated", "header", "y resolution"]);
    std::fs::write(&p, &full[..40]).unwrap();
    expect_err(&p, None, &["truncated", "header", "bounding box"]);
    std::fs::write(&p, b"").unwrap();
    expect_err(&p, None, &["truncated", "header", "magic"]);
}

#[test]
fn vol_truncated_data() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("cut.vol");
    let full = vol_image(1, [2, 2, 2], 1, &[1.0; 8]);
    std::fs::write(&p, &full[..full.len() - 3]).unwrap();
    expect_err(&p, None, &["truncated", "voxel data", "32 bytes", "29"]);
}

#[test]
fn vol_wrong_magic() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("magic.vol");
    let mut b = vol_image(1, [1, 1, 1], 1, &[1.0]);
    b[..3].copy_from_slice(b"VOX");
    std::fs::write(&p, &b).unwrap();
    expect_err(&p, None, &["magic", "VOX"]);
}

#[test]
fn vol_unsupported_encoding() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("half.vol");
    std::fs::write(&p, vol_image(2, [1, 1, 1], 1, &[1.0])).unwrap();
    expect_err(&p, None, &["unsupported encoding 2", "float32"]);
}

#[test]
fn vol_multi_channel() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("rgb.vol");
    std::fs::write(&p, vol_image(1, [2, 1, 1], 3, &[0.5; 6])).unwrap();
    expect_err(&p, None, &["3 channels", "exactly 1"]);
}

#[test]
fn vol_oversized_dims_are_refused_before_allocating() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("huge.vol");
    std::fs::write(&p, vol_image(1, [2048, 2048, 2048], 1, &[1.0])).unwrap();
    expect_err(&p, None, &["too large", "2048×2048×2048"]);
}

#[test]
fn raw_size_mismatch() {
    let dir = tempfile::tempdir().unwrap();
    let header = dir.path().join("grid.ron");
    std::fs::write(&header, raw_header((4, 4, 4), "XFastest", "grid.raw")).unwrap();
    let data = dir.path().join("grid.raw");
    std::fs::write(&data, le_bytes(&[1.0; 60])).unwrap();
    let e = load(&header).unwrap_err().to_string();
    for w in [
        "grid.raw",
        "truncated",
        "256 bytes",
        "240 bytes",
        "(4, 4, 4)",
    ] {
        assert!(e.contains(w), "lacks {w:?}: {e}");
    }
    std::fs::write(&data, le_bytes(&[1.0; 65])).unwrap();
    let e = load(&header).unwrap_err().to_string();
    for w in [
        "grid.raw",
        "too long",
        "256 bytes",
        "260 bytes",
        "(4, 4, 4)",
    ] {
        assert!(e.contains(w), "lacks {w:?}: {e}");
    }
}

#[test]
fn raw_header_unknown_field() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("d.raw"), le_bytes(&[1.0; 8])).unwrap();
    let header = dir.path().join("typo.ron");
    let text = raw_header((2, 2, 2), "XFastest", "d.raw").replace(", data:", ", colour: 3, data:");
    std::fs::write(&header, text).unwrap();
    expect_err(&header, None, &["field", "colour"]);
}

#[test]
fn raw_header_truncated() {
    let dir = tempfile::tempdir().unwrap();
    let header = dir.path().join("cut.ron");
    let text = raw_header((2, 2, 2), "XFastest", "d.raw");
    std::fs::write(&header, &text[..text.len() / 2]).unwrap();
    expect_err(&header, None, &["truncated", "header"]);
}

#[test]
fn nan_voxel() {
    let dir = tempfile::tempdir().unwrap();
    let mut g = test_grid();
    let n = g.index(3, 2, 1);
    g.data[n] = f32::NAN;
    let p = dir.path().join("nan.vol");
    write_mitsuba_vol(&p, &g).unwrap();
    expect_err(&p, None, &["(3, 2, 1)", "NaN"]);
    let h = dir.path().join("nan.ron");
    write_raw(&h, &g).unwrap();
    // The raw error names the data file, which holds the bad value.
    let e = load(&h).unwrap_err().to_string();
    assert!(
        e.contains("nan.raw") && e.contains("(3, 2, 1)") && e.contains("NaN"),
        "{e}"
    );
}

#[test]
fn negative_voxel() {
    let dir = tempfile::tempdir().unwrap();
    let mut g = test_grid();
    let n = g.index(4, 0, 2);
    g.data[n] = -0.25;
    let p = dir.path().join("neg.vol");
    write_mitsuba_vol(&p, &g).unwrap();
    expect_err(&p, None, &["(4, 0, 2)", "-0.25", "negative"]);
    let h = dir.path().join("neg.ron");
    write_raw(&h, &g).unwrap();
    let e = load(&h).unwrap_err().to_string();
    assert!(
        e.contains("neg.raw") && e.contains("(4, 0, 2)") && e.contains("negative"),
        "{e}"
    );
}

#[test]
fn bad_bounds() {
    let dir = tempfile::tempdir().unwrap();
    let mut g = test_grid();
    g.bounds_max.y = g.bounds_min.y;
    let p = dir.path().join("flat.vol");
    write_mitsuba_vol(&p, &g).unwrap();
    expect_err(&p, None, &["bounding box", "max > min"]);
    g.bounds_max.y = f32::INFINITY;
    write_mitsuba_vol(&p, &g).unwrap();
    expect_err(&p, None, &["finite"]);
}

#[test]
fn vdb_truncated() {
    let dir = tempfile::tempdir().unwrap();
    let full = std::fs::read(fixture("cloud.vdb")).unwrap();
    let p = dir.path().join("half_gone.vdb");
    std::fs::write(&p, &full[..full.len() / 2]).unwrap();
    expect_err(&p, None, &["truncated"]);
    // Cut inside the archive header and the grid descriptors too.
    for cut in [5, 30, 200, 600] {
        std::fs::write(&p, &full[..cut]).unwrap();
        expect_err(&p, None, &["truncated"]);
    }
}

#[test]
fn vdb_overwritten_middle() {
    let dir = tempfile::tempdir().unwrap();
    let full = std::fs::read(fixture("cloud.vdb")).unwrap();
    let p = dir.path().join("scribbled.vdb");
    let mid = full.len() / 2;
    for fill in [0xffu8, 0xa5, 0x00] {
        let mut b = full.clone();
        b[mid..mid + 512].fill(fill);
        std::fs::write(&p, &b).unwrap();
        let e = expect_err(&p, None, &[]);
        assert!(e.contains("corrupt") || e.contains("truncated"), "{e}");
    }
}

#[test]
fn vdb_corruption_never_panics() {
    // Damage the file in many places, in many ways: every load must return
    // (Ok for damage the format cannot detect, such as a changed value).
    let dir = tempfile::tempdir().unwrap();
    let full = std::fs::read(fixture("cloud.vdb")).unwrap();
    let p = dir.path().join("fuzz.vdb");
    let mut errors = 0;
    let mut tries = 0;
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    for _ in 0..150 {
        let mut b = full.clone();
        let at = (next() % b.len() as u64) as usize;
        let n = 1 + (next() % 16) as usize;
        for byte in b.iter_mut().skip(at).take(n) {
            *byte = next() as u8;
        }
        std::fs::write(&p, &b).unwrap();
        tries += 1;
        if let Err(e) = load(&p) {
            assert!(e.to_string().contains("fuzz.vdb"), "{e}");
            errors += 1;
        }
    }
    assert!(errors > 0 && tries == 150);
}

#[test]
fn vdb_wrong_magic() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("notvdb.vdb");
    std::fs::write(&p, vol_image(1, [1, 1, 1], 1, &[1.0])).unwrap();
    expect_err(&p, None, &["not an OpenVDB file", "magic"]);
}

#[test]
fn vdb_missing_grid_name() {
    let e = expect_err(
        &fixture("cloud.vdb"),
        Some("smoke"),
        &["\"smoke\"", "not found", "\"density\"", "\"temperature\""],
    );
    assert!(e.contains("Tree_vec3s"), "{e}");
}

#[test]
fn vdb_non_float_grid() {
    expect_err(
        &fixture("cloud.vdb"),
        Some("velocity"),
        &["Tree_vec3s_5_4_3", "float grids"],
    );
}

#[test]
fn vdb_rotated_transform() {
    expect_err(
        &fixture("rotated.vdb"),
        None,
        &["AffineMap", "not an axis-aligned"],
    );
}
