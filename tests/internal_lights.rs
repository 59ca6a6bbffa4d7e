//! The internal-lights image against the reference image (METHOD.md §7:
//! at generous settings the method converges to the reference).
//!
//! Settings (generous): optical-depth clock, `s* = 0.5` mean free paths,
//! `N = 80` (so `(N+1) s*` covers 40 mean free paths: at `N = 20` the
//! chromatic sphere's red channel, albedo 0.95, lost 6.5 % to truncation),
//! `M = 4096`, `K = 1024`, SH order 3, automatic `h`, the field form of
//! `L₁`; the reference at 8192 and the internal lights at 2048 samples per
//! pixel. Tolerances are the acceptance levels: image mean within
//! 3 % per channel and RMSE within 10 % of the reference's mean. The
//! Monte Carlo noise of the two images at these counts is about 3 % RMSE;
//! the rest is the method's bias.
//!
//! **Status**: these are the acceptance tests of the internal-lights issue
//! and do not all pass yet, so they are `#[ignore]`d (run them with
//! `cargo test --release --test internal_lights -- --ignored`). Last
//! measured with `lantern validate` at these settings: thin sphere mean
//! +0.31 %, RMSE 10.35 %; chromatic sphere (−1.23, −1.11, −1.57) %, RMSE
//! 11.60 %; puffs grid +4.05 %, RMSE 16.32 %. What remains is spatial (the
//! kernel reconstruction of `J` near the silhouette: rim pixels of the thin
//! sphere +7…+10 %, shrinking slowly with `M`), the window's two-scatter
//! error (face-on pixels −4 % at `s* = 0.5`, −2 % at `0.25`), and on the
//! forward-scattering puffs (`g = 0.6`) the SH order; the README's
//! "Validation" section has the numbers.

mod common;

use lantern::scene::{ClockKind, L1Kind, Method};
use lantern::validate::compare;

fn check(rel: &str) {
    let prepared = std::sync::Arc::new(common::prepare_with(rel, |s| {
        s.camera.width = 32;
        s.camera.height = 32;
        let i = &mut s.render.internal;
        i.clock = ClockKind::OpticalDepth;
        i.s_star = Some(0.5);
        i.terms = 80;
        i.lights = 4096;
        i.walks = 1024;
        i.sh_order = 3;
        i.l1 = L1Kind::Field;
    }));
    let reference = common::render(&prepared, Method::Reference, 7, 8192);
    let internal = common::render(&prepared, Method::Internal, 8, 2048);
    let (err, rmse) = compare(&internal.mean(), &reference.mean());
    let name = std::path::Path::new(rel)
        .file_stem()
        .unwrap()
        .to_string_lossy()
        .into_owned();
    common::dump(&format!("{name}_internal"), 32, 32, &internal.mean());
    common::dump(&format!("{name}_reference"), 32, 32, &reference.mean());
    eprintln!("{rel}: mean error {err:?}, RMSE {:.2}%", 100.0 * rmse);
    assert!(err.abs().max_element() < 0.03, "{rel}: mean error {err:?}");
    assert!(rmse < 0.10, "{rel}: RMSE {rmse}");
}

#[test]
#[ignore = "acceptance target of the internal-lights issue, not met yet (see the module doc)"]
fn thin_sphere_agrees_with_reference() {
    check("assets/scenes/thin_sphere.ron");
}

#[test]
#[ignore = "acceptance target of the internal-lights issue, not met yet (see the module doc)"]
fn chromatic_sphere_agrees_with_reference() {
    check("assets/scenes/chromatic_sphere.ron");
}

#[test]
#[ignore = "acceptance target of the internal-lights issue, not met yet (see the module doc)"]
fn puffs_grid_agrees_with_reference() {
    check("assets/scenes/puffs_grid.ron");
}
