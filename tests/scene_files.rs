//! Scene files: every example round-trips through RON and loads, and every
//! kind of bad scene input gives an error naming the file and the problem.

mod common;

use std::path::Path;

use lantern::scene::Scene;

/// The `.ron` files under `dir` and its folders (the suite's and the
/// studies' scenes beside the examples).
fn scene_files(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            scene_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "ron") {
            out.push(path);
        }
    }
}

#[test]
fn every_example_scene_round_trips_and_loads() {
    let mut paths = Vec::new();
    scene_files(&common::root().join("assets/scenes"), &mut paths);
    for path in &paths {
        let scene = Scene::load(path).unwrap_or_else(|e| panic!("{e}"));
        let text = scene.to_ron().unwrap();
        let again = Scene::from_ron(&text, path).unwrap_or_else(|e| panic!("{e}\n{text}"));
        assert_eq!(scene, again, "{}", path.display());
        // The density loads (grids read, clouds baked), relative to the
        // scene's own folder.
        let dir = path.parent().unwrap();
        let density = scene.load_density(dir).unwrap_or_else(|e| panic!("{e}"));
        let (lo, hi) = density.bounds();
        assert!(hi.cmpgt(lo).all(), "{}", path.display());
    }
    // 6 examples, 7 suite scenes, 18 studies.
    assert!(paths.len() >= 31, "only {} scene files", paths.len());
}

/// A valid scene with one line replaced.
fn variant(from: &str, to: &str) -> String {
    let base =
        std::fs::read_to_string(common::root().join("assets/scenes/thin_sphere.ron")).unwrap();
    assert!(base.contains(from), "{from}");
    base.replacen(from, to, 1)
}

fn expect_error(text: &str, words: &[&str]) {
    let path = Path::new("bad_scene.ron");
    let err = Scene::from_ron(text, path).expect_err("scene should be rejected");
    let msg = format!("{err:#}");
    assert!(msg.contains("bad_scene.ron"), "no file name in: {msg}");
    for w in words {
        assert!(msg.contains(w), "{w:?} missing in: {msg}");
    }
}

#[test]
fn bad_values_are_rejected_with_a_clear_message() {
    expect_error(
        &variant("sigma_t: (1.0, 1.0, 1.0)", "sigma_t: (NaN, 1.0, 1.0)"),
        &["sigma_t"],
    );
    expect_error(
        &variant("sigma_t: (1.0, 1.0, 1.0)", "sigma_t: (1.0, -2.0, 1.0)"),
        &["sigma_t", "non-negative"],
    );
    expect_error(
        &variant("albedo: (0.9, 0.9, 0.9)", "albedo: (0.9, 1.2, 0.9)"),
        &["albedo", "[0, 1]"],
    );
    expect_error(
        &variant("albedo: (0.9, 0.9, 0.9)", "albedo: (-0.1, 0.9, 0.9)"),
        &["albedo"],
    );
    expect_error(&variant("g: 0.5", "g: 1.0"), &["medium.g"]);
    expect_error(&variant("g: 0.5", "g: -1.5"), &["medium.g"]);
    expect_error(
        &variant("width: 128", "width: 0"),
        &["camera.width", "empty"],
    );
    expect_error(&variant("height: 128", "height: 100000"), &["exceeds"]);
    expect_error(
        &variant("fov_y_deg: 40.0", "fov_y_deg: 0.0"),
        &["fov_y_deg"],
    );
    expect_error(&variant("radius: 1.0", "radius: -1.0"), &["Sphere"]);
    expect_error(
        &variant("irradiance: (3.0, 3.0, 3.0)", "irradiance: (3.0, inf, 3.0)"),
        &["irradiance"],
    );
    expect_error(
        &variant("density_scale: 1.0", "density_scale: NaN"),
        &["density_scale"],
    );
    expect_error(&variant("spp: 64", "spp: 0"), &["render.spp"]);
    expect_error(
        &variant("spp: 64", "spp: 64, internal: (view_walks: 70000)"),
        &["view_walks", "0..=65536"],
    );
    expect_error(
        &variant("spp: 64", "spp: 64, internal: (window_scatters: 0)"),
        &["window_scatters", "1..=3"],
    );
}

#[test]
fn malformed_files_are_rejected_with_a_clear_message() {
    // Unknown field, with its name and position.
    expect_error(&variant("g: 0.5,", "g: 0.5, sparkle: 2.0,"), &["sparkle"]);
    // Syntax error.
    expect_error(&variant("lights: [", "lights: [[["), &[]);
    // Missing field.
    expect_error(&variant("albedo: (0.9, 0.9, 0.9),", ""), &["albedo"]);
    // Truncated file.
    let full = variant("g: 0.5", "g: 0.5");
    expect_error(&full[..full.len() / 2], &[]);
}

#[test]
fn missing_scene_file_names_the_file() {
    let err = Scene::load(Path::new("/nonexistent/dir/cloud.ron")).unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains("/nonexistent/dir/cloud.ron"), "{msg}");
}

#[test]
fn missing_or_corrupt_grid_names_the_grid_file() {
    let dir = tempfile::tempdir().unwrap();
    let text = variant(
        "density: Sphere(center: (0.0, 0.0, 0.0), radius: 1.0)",
        "density: Grid((path: \"missing.vol\"))",
    );
    let scene = Scene::from_ron(&text, Path::new("s.ron")).unwrap();
    let err = scene.load_density(dir.path()).unwrap_err();
    assert!(err.to_string().contains("missing.vol"), "{err}");

    // A .vol cut short.
    let vol = common::root().join("assets/volumes/puffs.vol");
    let bytes = std::fs::read(vol).unwrap();
    std::fs::write(dir.path().join("cut.vol"), &bytes[..bytes.len() / 3]).unwrap();
    let text = variant(
        "density: Sphere(center: (0.0, 0.0, 0.0), radius: 1.0)",
        "density: Grid((path: \"cut.vol\"))",
    );
    let scene = Scene::from_ron(&text, Path::new("s.ron")).unwrap();
    let err = scene.load_density(dir.path()).unwrap_err();
    let msg = err.to_string();
    assert!(
        msg.contains("cut.vol") && msg.contains("truncated"),
        "{msg}"
    );
}
