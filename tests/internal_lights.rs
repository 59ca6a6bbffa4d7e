//! The internal-lights image against the reference image ([method §7](lantern::doc::method):
//! at generous settings the method converges to the reference): the
//! acceptance tests of the internal-lights issue.
//!
//! Settings (generous): optical-depth clock, `s* = 0.5` mean free paths,
//! `N = 80` (so `(N+1) s*` covers 40 mean free paths: at `N = 20` the
//! chromatic sphere's red channel, albedo 0.95, lost 6.5 % to truncation),
//! `K = 1024`, SH order 3, automatic `h`, the field form of `L₁`;
//! `M = 4096` on the spheres and `M = 16384` on the heterogeneous puffs
//! (at 4096 their RMSE was 10.9 %: the kernel reconstruction's spatial
//! error is the largest part there); the internal lights at 2048 samples
//! per pixel, the reference at 8192 (the spheres) and 32768 (the puffs,
//! whose reference is the noisiest: 4.5 % RMSE of noise at 8192). The
//! tolerances are the issue's: image mean within 3 % per channel and RMSE
//! within 10 % of the reference's mean. The RMSE asserted includes the
//! Monte Carlo noise of both images; the noise-corrected RMSE (the squared
//! error less both images' variance of the mean) is printed beside it.
//!
//! What made them pass: the walks keep apart what they carried to a gate
//! without a collision (single scatter from further along the ray), which
//! the gather marches exactly instead of reconstructing it from the
//! lights' spherical harmonics (`Part::Scattered`, `single_beyond_window`):
//! the thin sphere went from RMSE 10.35 % to 6.4 % and the rim pixels from
//! +20…35 % to a few %.

mod common;

use glam::Vec3;
use lantern::render::stats::compare;
use lantern::scene::{Clock, L1Form, Method};

/// The squared error less both images' variance of the mean, relative to
/// the reference's mean (the RMSE the converged images would have).
fn noise_corrected_rmse(
    image: &lantern::render::film::Film,
    reference: &lantern::render::film::Film,
) -> f64 {
    let (a, b) = (image.mean(), reference.mean());
    let (va, vb) = (image.variance_of_mean(), reference.variance_of_mean());
    let mut se = 0.0f64;
    let mut mean = 0.0f64;
    for i in 0..a.len() {
        let d: Vec3 = a[i] - b[i];
        se += (d * d - va[i] - vb[i])
            .to_array()
            .iter()
            .map(|&v| v as f64)
            .sum::<f64>();
        mean += b[i].to_array().iter().map(|&v| v as f64).sum::<f64>();
    }
    let n = 3.0 * a.len() as f64;
    (se.max(0.0) / n).sqrt() / (mean / n).max(1e-30)
}

/// The scene at 32², optical-depth clock, field form of `L₁`, with these
/// window, truncation, lights, walks and SH order.
fn prepare_32(
    rel: &str,
    s_star: f32,
    terms: u32,
    lights: u32,
    walks: u32,
    sh_order: u32,
) -> std::sync::Arc<lantern::render::prepared::PreparedScene> {
    std::sync::Arc::new(common::prepare_with(rel, |s| {
        s.camera.width = 32;
        s.camera.height = 32;
        let i = &mut s.render.internal;
        i.expert.clock = Clock::OpticalDepth;
        i.knobs.s_star = Some(s_star);
        i.knobs.terms = terms;
        i.knobs.lights = lights;
        i.expert.walks = walks;
        i.expert.sh_order = sh_order;
        i.expert.l1 = L1Form::Field;
        note_placement(i);
    }))
}

/// The settings these generous tests were written for, apart from the
/// ones they set: lights placed by density alone and read through their
/// harmonics, one window scattering, two gather points, one light set
/// (the settings before the defaults of `Quality::Final`; they test the
/// note's estimator converging, the defaults are tested below).
fn note_placement(i: &mut lantern::scene::InternalSettings) {
    i.expert.view_share = 0.0;
    i.expert.view_walks = 0;
    i.expert.window_scatters = 1;
    i.expert.light_samples = 2;
    i.expert.resample_every = 0;
}

fn check(rel: &str, lights: u32, reference_spp: u32) {
    let prepared = prepare_32(rel, 0.5, 80, lights, 1024, 3);
    let reference = common::render(&prepared, Method::Reference, 7, reference_spp);
    let internal = common::render(&prepared, Method::Internal, 8, 2048);
    let (err, rmse) = compare(&internal.mean(), &reference.mean());
    let name = std::path::Path::new(rel)
        .file_stem()
        .unwrap()
        .to_string_lossy()
        .into_owned();
    common::dump(&format!("{name}_internal"), 32, 32, &internal.mean());
    common::dump(&format!("{name}_reference"), 32, 32, &reference.mean());
    eprintln!(
        "{rel}: mean error {err:?}, RMSE {:.2}% (noise-corrected {:.2}%)",
        100.0 * rmse,
        100.0 * noise_corrected_rmse(&internal, &reference)
    );
    assert!(err.abs().max_element() < 0.03, "{rel}: mean error {err:?}");
    assert!(rmse < 0.10, "{rel}: RMSE {rmse}");
}

#[test]
fn thin_sphere_agrees_with_reference() {
    check("assets/scenes/thin_sphere.ron", 4096, 8192);
}

#[test]
fn chromatic_sphere_agrees_with_reference() {
    check("assets/scenes/chromatic_sphere.ron", 4096, 8192);
}

#[test]
fn puffs_grid_agrees_with_reference() {
    check("assets/scenes/puffs_grid.ron", 16384, 32768);
}

/// At a short window (`s* = 0.25` mean free paths) most of the multiply
/// scattered light goes through `L₀`'s reconstruction of the collided
/// part. Near a puff's surface the chance that a walk collides before it
/// leaves falls steeply across directions and depth, and reconstructed
/// as it was the dim edges of the puffs came out bright (+19.5 % / +13.3 %
/// in the two dimmest fifths at 96², historical: lantern::doc::validation
/// §4); stored per unit chance of the collision they follow the
/// reference. The dimmer half of the cloud's pixels (by the reference)
/// is asserted within 5 % in mean, and the image within 3 %.
#[test]
fn puffs_short_window_keeps_the_dim_edges() {
    let prepared = prepare_32("assets/scenes/puffs_grid.ron", 0.25, 160, 16384, 256, 4);
    let reference = common::render(&prepared, Method::Reference, 7, 16384);
    let internal = common::render(&prepared, Method::Internal, 8, 512);
    let (a, b) = (internal.mean(), reference.mean());
    let grey = |v: Vec3| (v.x + v.y + v.z) as f64 / 3.0;
    let mut lit: Vec<(f64, f64)> = a
        .iter()
        .zip(&b)
        .map(|(i, r)| (grey(*r), grey(*i)))
        .filter(|(r, _)| *r > 0.0)
        .collect();
    lit.sort_by(|x, y| x.0.total_cmp(&y.0));
    let dim = &lit[..lit.len() / 2];
    let (sr, si) = dim
        .iter()
        .fold((0.0, 0.0), |(sr, si), (r, i)| (sr + r, si + i));
    let dim_err = si / sr - 1.0;
    let (err, rmse) = compare(&a, &b);
    eprintln!(
        "puffs, s* = 0.25: dimmer half of the cloud {:+.2} %, image mean {err:?}, RMSE {:.2} %",
        100.0 * dim_err,
        100.0 * rmse
    );
    assert!(
        dim_err.abs() < 0.05,
        "dimmer half of the cloud off by {dim_err}"
    );
    assert!(err.abs().max_element() < 0.03, "mean error {err:?}");
}

/// Walks towards the eye (`view_walks`) at the short window, where most
/// of the multiply scattered light goes through `L₀`'s collided part: the
/// image with `L₀` averaging the lights' view estimates agrees with the
/// reference within the targets of the other scenes (3 % in mean per
/// channel, 10 % RMSE), with a quarter of their spread walks (64, which
/// serve `L₁` only) and 256 view walks per light.
#[test]
fn puffs_view_walks_agree_with_reference() {
    let prepared = std::sync::Arc::new(common::prepare_with("assets/scenes/puffs_grid.ron", |s| {
        s.camera.width = 32;
        s.camera.height = 32;
        let i = &mut s.render.internal;
        i.expert.clock = Clock::OpticalDepth;
        i.knobs.s_star = Some(0.25);
        i.knobs.terms = 160;
        i.knobs.lights = 16384;
        i.expert.walks = 64;
        note_placement(i);
        i.expert.view_walks = 256;
        i.expert.sh_order = 4;
        i.expert.l1 = L1Form::Field;
    }));
    let reference = common::render(&prepared, Method::Reference, 7, 32768);
    let internal = common::render(&prepared, Method::Internal, 8, 1024);
    let (err, rmse) = compare(&internal.mean(), &reference.mean());
    common::dump("puffs_view_internal", 32, 32, &internal.mean());
    eprintln!(
        "puffs_grid with view walks: mean error {err:?}, RMSE {:.2}% (noise-corrected {:.2}%)",
        100.0 * rmse,
        100.0 * noise_corrected_rmse(&internal, &reference)
    );
    assert!(err.abs().max_element() < 0.03, "mean error {err:?}");
    assert!(rmse < 0.10, "RMSE {rmse}");
}

/// The image mean error per channel and the RMSE of the 8×8 blocks' grey
/// means, relative to the reference's grey mean.
fn mean_and_block_rmse(
    image: &[Vec3],
    reference: &[Vec3],
    width: usize,
    height: usize,
) -> (Vec3, f64) {
    let n = (width * height) as f32;
    let (ma, mb) = (
        image.iter().sum::<Vec3>() / n,
        reference.iter().sum::<Vec3>() / n,
    );
    let grey = |v: Vec3| (v.x + v.y + v.z) as f64 / 3.0;
    let mut se = 0.0f64;
    let mut blocks = 0usize;
    for by in 0..height / 8 {
        for bx in 0..width / 8 {
            let (mut a, mut b) = (0.0f64, 0.0f64);
            for y in 0..8 {
                for x in 0..8 {
                    let i = (by * 8 + y) * width + bx * 8 + x;
                    a += grey(image[i]);
                    b += grey(reference[i]);
                }
            }
            se += ((a - b) / 64.0).powi(2);
            blocks += 1;
        }
    }
    (ma / mb - Vec3::ONE, (se / blocks as f64).sqrt() / grey(mb))
}

/// Where [`check_defaults`]'s reference comes from: rendered in the test
/// at this many spp, or a committed converged one (48², linear EXR).
enum Reference {
    Rendered(u32),
    File(&'static str),
}

/// What an artist gets: the scene at 48² with every internal-lights
/// setting at its default (`Quality::Final`: `s*` half a mean free path,
/// lights in the camera's windows, renewed sets), against the reference.
/// The targets: image mean within 3 % per channel, 8×8-block RMSE
/// within 5 % of the reference's mean. `spp` passes of the internal lights
/// (a fresh light set every two).
fn check_defaults(rel: &str, reference: Reference, spp: u32) {
    let prepared = std::sync::Arc::new(common::prepare_with(rel, |s| {
        s.camera.width = 48;
        s.camera.height = 48;
        s.render.internal = lantern::scene::InternalSettings::default();
    }));
    let reference = match reference {
        Reference::Rendered(spp) => common::render(&prepared, Method::Reference, 7, spp).mean(),
        Reference::File(path) => {
            let image = lantern::render::export::read_exr(std::path::Path::new(path))
                .unwrap_or_else(|e| panic!("{e}"));
            assert_eq!((image.width, image.height), (48, 48), "{path}");
            image.pixels
        }
    };
    let internal = common::render(&prepared, Method::Internal, 8, spp);
    let (err, block) = mean_and_block_rmse(&internal.mean(), &reference, 48, 48);
    let name = std::path::Path::new(rel)
        .file_stem()
        .unwrap()
        .to_string_lossy()
        .into_owned();
    common::dump(&format!("{name}_defaults"), 48, 48, &internal.mean());
    eprintln!(
        "{rel} at the defaults: mean error {err:?}, 8×8-block RMSE {:.2} %",
        100.0 * block
    );
    assert!(err.abs().max_element() < 0.03, "{rel}: mean error {err:?}");
    assert!(block < 0.05, "{rel}: 8×8-block RMSE {block}");
}

#[test]
fn defaults_agree_with_reference_thin_sphere() {
    check_defaults(
        "assets/scenes/thin_sphere.ron",
        Reference::Rendered(8192),
        64,
    );
}

#[test]
fn defaults_agree_with_reference_chromatic_sphere() {
    check_defaults(
        "assets/scenes/chromatic_sphere.ron",
        Reference::Rendered(8192),
        64,
    );
}

#[test]
fn defaults_agree_with_reference_puffs() {
    check_defaults(
        "assets/scenes/puffs_grid.ron",
        Reference::Rendered(16384),
        64,
    );
}

/// The converged reference of [`defaults_agree_with_reference_thin_smoke_with_a_sharp_forward_peak`]
/// (`tests/data/studies/smoke_g090_48.exr` and its `_var.exr`, the
/// variance of its mean): the scene at 48², the reference renderer at
/// 786 432 spp, seed 7 (about 5 minutes on two cores). Regenerate with
/// `cargo test --release --test internal_lights -- --ignored
/// make_smoke_g090_reference`.
#[test]
#[ignore = "writes the committed reference (minutes)"]
fn make_smoke_g090_reference() {
    let prepared = std::sync::Arc::new(common::prepare_with(SMOKE_G090, |s| {
        s.camera.width = 48;
        s.camera.height = 48;
    }));
    let film = common::render(&prepared, Method::Reference, 7, SMOKE_G090_REFERENCE_SPP);
    let dir = std::path::Path::new("tests/data/studies");
    std::fs::create_dir_all(dir).unwrap();
    let meta = vec![
        ("lantern/seed".to_owned(), "7".to_owned()),
        (
            "lantern/spp".to_owned(),
            SMOKE_G090_REFERENCE_SPP.to_string(),
        ),
        ("lantern/method".to_owned(), "reference".to_owned()),
    ];
    lantern::render::export::write_exr_with_metadata(
        &dir.join("smoke_g090_48.exr"),
        48,
        48,
        &film.mean(),
        &meta,
    )
    .unwrap();
    lantern::render::export::write_exr(
        &dir.join("smoke_g090_48_var.exr"),
        48,
        48,
        &film.variance_of_mean(),
    )
    .unwrap();
}

/// [`make_smoke_g090_reference`]'s scene and sample count.
const SMOKE_G090: &str = "assets/scenes/studies/smoke_g090.ron";
const SMOKE_G090_REFERENCE_SPP: u32 = 786_432;

/// A thin smoke with a sharp forward peak: the suite's wispy smoke with
/// `g` 0.9 (camera rays cross at most 1.8 mean free paths), side-lit, at
/// the defaults. Its multiply scattered source is peaked about the sun's
/// direction, and the window's second scattering read it through the
/// lights' harmonics in a direction drawn from the phase function, where
/// they ring: that part of the image came out 14 % bright, the image
/// 6.5 % (validation §3.16). With phase walks read at every scattering of
/// `L₁`, the targets. Against a committed converged reference
/// ([`make_smoke_g090_reference`]): a reference rendered here at 16 384 spp
/// carried block noise the size of the 5 % target itself (two seeds of it
/// 7.6 % apart in 8×8 blocks; its fireflies), so the test's verdict was
/// the reference's seed (validation §3.23).
#[test]
fn defaults_agree_with_reference_thin_smoke_with_a_sharp_forward_peak() {
    check_defaults(
        SMOKE_G090,
        Reference::File("tests/data/studies/smoke_g090_48.exr"),
        256,
    );
}

/// A fog seen from inside (`assets/scenes/studies/fog_inside.ron`: a
/// homogeneous box, σ_t 0.6, albedo 0.9, `g` 0.3, around the camera), the
/// same targets. `L₁` reads the lights at its source points, a
/// phase-function step off the camera ray; with the camera inside, the
/// windows fill a narrow cone from the eye, and with every light placed on
/// the camera rays most of those points had no light within the kernel
/// (zero): the image mean −4.3 % here (its multiply scattered part −6.7 %
/// at 64²; validation §3.20).
#[test]
fn defaults_agree_with_reference_fog_seen_from_inside() {
    check_defaults(
        "assets/scenes/studies/fog_inside.ron",
        Reference::Rendered(2048),
        32,
    );
}

/// The thin sphere's scene made thick (optical radius 12, albedo 0.99,
/// `g` 0.5) and lit by a sun from just behind the camera, at `side`² and
/// (if given) a narrower field of view, every internal-lights setting at
/// its default.
fn thick_sphere_lit_from_the_camera(
    side: u32,
    fov_y_deg: Option<f32>,
) -> std::sync::Arc<lantern::render::PreparedScene> {
    std::sync::Arc::new(common::prepare_with("assets/scenes/thin_sphere.ron", |s| {
        s.camera.width = side;
        s.camera.height = side;
        if let Some(fov) = fov_y_deg {
            s.camera.fov_y_deg = fov;
        }
        s.medium.sigma_t = Vec3::splat(12.0);
        s.medium.albedo = Vec3::splat(0.99);
        s.lights = vec![lantern::scene::Light::Sun {
            direction: Vec3::new(0.05, -0.1, -1.0),
            irradiance: Vec3::splat(3.0),
        }];
        s.render.internal = lantern::scene::InternalSettings::default();
    }))
}

/// A thick homogeneous sphere (optical radius 12, albedo 0.99, `g` 0.5)
/// lit from behind the camera, at the defaults: the same targets. With
/// the optical-depth clock's quadrature at most two steps per majorant
/// cell (≈ 0.4 mean free paths each here) a cumulus of optical depth ≈ 30
/// came out 12 % dark at these settings.
#[test]
fn defaults_agree_with_reference_thick_sphere_lit_from_the_camera() {
    let prepared = thick_sphere_lit_from_the_camera(48, None);
    let reference = common::render(&prepared, Method::Reference, 7, 4096);
    let internal = common::render(&prepared, Method::Internal, 8, 64);
    let (err, block) = mean_and_block_rmse(&internal.mean(), &reference.mean(), 48, 48);
    common::dump("thick_sphere_defaults", 48, 48, &internal.mean());
    eprintln!(
        "thick sphere at the defaults: mean error {err:?}, 8×8-block RMSE {:.2} %",
        100.0 * block
    );
    assert!(err.abs().max_element() < 0.03, "mean error {err:?}");
    assert!(block < 0.05, "8×8-block RMSE {block}");
}

/// The centre of a thick homogeneous sphere lit from behind the camera
/// (optical radius 12, albedo 0.99, `g` 0.5), seen through a narrow lens
/// (8°, 32²) at the defaults: the image must hold no rings. With the
/// optical-depth clock's quadrature lattice anchored at the majorant
/// cells, the error at the sphere's surface was a smooth function of where
/// the surface fell on the lattice, which changes slowest at the image's
/// centre: rings of ±5 % around it, whatever the light samples, walks or
/// renewal (`physics::internal::clock::lattice_phase`).
///
/// The statistic: the image's annuli one pixel wide, their grey means
/// against a smooth fit in `r²` (the sphere's own fall-off), as a χ² whose
/// variance comes from the two half-annuli's difference (the light sets'
/// noise is correlated between pixels, so the per-pixel variance would
/// understate it); rings are the same on both halves and do not cancel.
#[test]
fn the_centre_of_a_sphere_lit_from_the_camera_has_no_rings() {
    let (w, h) = (32usize, 32usize);
    let prepared = thick_sphere_lit_from_the_camera(w as u32, Some(8.0));
    let internal = common::render(&prepared, Method::Internal, 8, 48);
    let image = internal.mean();
    common::dump("rings_centre_defaults", w as u32, h as u32, &image);
    let rings = w / 2;
    // Per annulus: the sums of the two halves (left, right) and counts.
    let mut sum = vec![[0.0f64; 2]; rings];
    let mut count = vec![[0usize; 2]; rings];
    for y in 0..h {
        for x in 0..w {
            let (dx, dy) = (
                x as f64 + 0.5 - w as f64 / 2.0,
                y as f64 + 0.5 - h as f64 / 2.0,
            );
            let r = (dx * dx + dy * dy).sqrt() as usize;
            if r >= rings {
                continue;
            }
            let v = image[y * w + x];
            let half = usize::from(dx > 0.0);
            sum[r][half] += (v.x + v.y + v.z) as f64 / 3.0;
            count[r][half] += 1;
        }
    }
    // Annuli with pixels on both sides (all but the innermost).
    let used: Vec<usize> = (1..rings).collect();
    let mean: Vec<f64> = used
        .iter()
        .map(|&r| (sum[r][0] + sum[r][1]) / (count[r][0] + count[r][1]) as f64)
        .collect();
    let halves: Vec<f64> = used
        .iter()
        .map(|&r| sum[r][0] / count[r][0] as f64 - sum[r][1] / count[r][1] as f64)
        .collect();
    // Least squares a + b r² + c r⁴ (weights: the annuli's pixel counts).
    let mut ata = [[0.0f64; 3]; 3];
    let mut atb = [0.0f64; 3];
    for (i, &r) in used.iter().enumerate() {
        let q = ((r as f64 + 0.5) / rings as f64).powi(2);
        let basis = [1.0, q, q * q];
        let wgt = (count[r][0] + count[r][1]) as f64;
        for a in 0..3 {
            atb[a] += wgt * basis[a] * mean[i];
            for b in 0..3 {
                ata[a][b] += wgt * basis[a] * basis[b];
            }
        }
    }
    let coef = solve3(ata, atb);
    let grand = mean.iter().sum::<f64>() / mean.len() as f64;
    // Var(mean of an annulus) from its halves: Var(L − R) = Var(L) +
    // Var(R) ≈ 4 Var(mean) for equal halves, and it scales as 1/n: pooled
    // over the annuli as n (L − R)² / 4.
    let pooled = halves
        .iter()
        .zip(&used)
        .map(|(d, &r)| (count[r][0] + count[r][1]) as f64 * d * d / 4.0)
        .sum::<f64>()
        / used.len() as f64;
    let (mut chi2, mut residual2) = (0.0f64, 0.0f64);
    for (i, &r) in used.iter().enumerate() {
        let q = ((r as f64 + 0.5) / rings as f64).powi(2);
        let fit = coef[0] + coef[1] * q + coef[2] * q * q;
        let n = (count[r][0] + count[r][1]) as f64;
        chi2 += (mean[i] - fit).powi(2) / (pooled / n);
        residual2 += (mean[i] - fit).powi(2);
    }
    let dof = (used.len() - 3) as f64;
    let ring_rms = (residual2 / used.len() as f64).sqrt() / grand;
    eprintln!(
        "rings at the centre: χ²/dof {:.2} over {} annuli, residual RMS {:.2} % of the mean",
        chi2 / dof,
        used.len(),
        100.0 * ring_rms
    );
    // χ² over 12 degrees of freedom: 3 per degree is a chance of 1e-4.
    assert!(
        chi2 / dof < 3.0,
        "rings: χ²/dof {} (residual RMS {:.2} %)",
        chi2 / dof,
        100.0 * ring_rms
    );
}

/// The solution of the 3×3 system `a x = b` (Cramer's rule).
fn solve3(a: [[f64; 3]; 3], b: [f64; 3]) -> [f64; 3] {
    let det = |m: [[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(a);
    let mut x = [0.0; 3];
    for (col, xi) in x.iter_mut().enumerate() {
        let mut m = a;
        for row in 0..3 {
            m[row][col] = b[row];
        }
        *xi = det(m) / d;
    }
    x
}
