//! The internal-lights image against the reference image (METHOD.md §7:
//! at generous settings the method converges to the reference).
//!
//! Settings: optical-depth clock, `s* = 0.25` mean free paths, `N = 40`
//! (so `(N+1) s*` covers 10 mean free paths), `M = 4096`, `K = 64`, SH
//! order 3, automatic `h`. Tolerances are the acceptance levels:
//! image mean within 3 % per channel and RMSE within 10 % of the
//! reference's mean. They leave room for the method's remaining bias,
//! measured at −0.6 % (thin sphere) with `lantern validate`, plus the
//! Monte Carlo noise of both images at 32×32 (about 2 % RMSE per image at
//! the sample counts below), and they fail for the approximations the
//! method must not make: the note's default window (`s*` = the box's
//! diagonal) is off by −26 % on the thin sphere.
//!
//! **Status**: these are the acceptance tests of the internal-lights issue
//! and do not pass yet, so they are `#[ignore]`d (run them with
//! `cargo test --test internal_lights -- --ignored`). Last measured: thin
//! sphere mean error +0.01 %, RMSE 20.9 %; chromatic sphere mean error
//! (−12.7, −10.4, −4.7) %, RMSE 32.6 %. The README's "Validation" section
//! says where the error comes from.

mod common;

use lantern::scene::{ClockKind, Method};
use lantern::validate::compare;

fn check(rel: &str) {
    let prepared = std::sync::Arc::new(common::prepare_with(rel, |s| {
        s.camera.width = 32;
        s.camera.height = 32;
        let i = &mut s.render.internal;
        i.clock = ClockKind::OpticalDepth;
        i.s_star = Some(0.25);
        i.terms = 40;
        i.lights = 4096;
        i.walks = 64;
        i.sh_order = 3;
    }));
    let reference = common::render(&prepared, Method::Reference, 7, 2048);
    let internal = common::render(&prepared, Method::Internal, 8, 256);
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
