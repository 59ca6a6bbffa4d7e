//! The environment: light from the sky at infinity, arriving at the medium
//! from every direction ([method §1](crate::doc::method), "the
//! environment as part of `S₁`").
//!
//! Conventions follow Mitsuba 3's `constant` and `envmap` emitters: an
//! environment is a radiance `L(ω)` (W/m²/sr, RGB) for each direction `ω`
//! *towards* the sky. A map is in latitude–longitude layout with +y up:
//! row 0 is the zenith (+y), the last row the nadir (−y), and the column at
//! `u` (0 at the left edge, 1 at the right) looks along
//! `(sin 2πu, ·, −cos 2πu)` horizontally, so the map's centre column looks
//! along +z. Texels are the vertices of a bilinear patch as in Mitsuba 3
//! (see [`crate::physics::environment`]). `rotation_deg` turns the map
//! about +y (right-handed; Mitsuba's `to_world = rotate([0, 1, 0], angle)`)
//! and `scale` multiplies it.
//!
//! A clear sky is baked into such a map from the scene's first sun
//! ([`clear_sky_map`], the Preetham–Shirley–Smits daylight model), so that
//! moving the sun moves the sky.
//!
//! Maps are read from OpenEXR (`.exr`, the first RGB(A) layer) or Radiance
//! (`.hdr`) files. A missing or truncated file, a map that is not 2:1, or a
//! texel that is not a finite, non-negative number is refused with an error
//! that names the file and the problem.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::Vec3;
use serde::{Deserialize, Serialize};

use super::error::SceneError;

/// Largest map width accepted (its height is half of it).
pub const MAX_MAP_WIDTH: u32 = 8192;

/// Width of the map a clear sky is baked into (its height is half).
pub const CLEAR_SKY_WIDTH: u32 = 256;

/// The environment of a scene: what the sky is, and whether the camera
/// sees it behind the medium.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Environment {
    /// The sky's radiance.
    pub sky: Sky,
    /// Whether camera rays that leave the medium unscattered see the sky
    /// (Mitsuba's `hide_emitters = false`); otherwise the background is
    /// black and the sky only lights the medium.
    #[serde(default)]
    pub background: bool,
}

fn one() -> f32 {
    1.0
}

fn default_turbidity() -> f32 {
    3.0
}

/// What the sky is.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub enum Sky {
    /// The same radiance from every direction (Mitsuba's `constant`).
    Constant {
        /// Radiance, RGB, W/m²/sr.
        radiance: Vec3,
    },
    /// A latitude–longitude HDR map (Mitsuba's `envmap`).
    Map {
        /// The `.exr` or `.hdr` file, relative to the scene file's folder.
        file: PathBuf,
        /// Rotation of the map about +y, in degrees.
        #[serde(default)]
        rotation_deg: f32,
        /// Factor on the map's texels.
        #[serde(default = "one")]
        scale: f32,
    },
    /// A clear daylight sky (Preetham et al. 1999) for the direction of
    /// the scene's first sun.
    ClearSky {
        /// Atmospheric turbidity, 1.7 (very clear) to 10 (hazy).
        #[serde(default = "default_turbidity")]
        turbidity: f32,
        /// Factor on the model's radiance: at 1 a texel's radiance is the
        /// model's luminance in kcd/m² over 50, a sky that gives a
        /// horizontal surface about a fifth of the light of a sun of
        /// irradiance 3 at 45°.
        #[serde(default = "one")]
        scale: f32,
    },
}

/// A latitude–longitude radiance map as read: `width × height` linear RGB
/// texels, row-major, row 0 at the zenith.
#[derive(Clone, Debug, PartialEq)]
pub struct SkyMap {
    /// Texels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// `width × height` texels, row-major, row 0 at the top (+y).
    pub texels: Vec<Vec3>,
}

/// The environment ready for the estimators to build their tables from:
/// a constant or a map with its rotation and scale.
#[derive(Clone, Debug, PartialEq)]
pub enum LoadedSky {
    /// The same radiance from every direction.
    Constant(Vec3),
    /// A map, its rotation about +y (degrees) and its scale.
    Map {
        /// The texels.
        map: Arc<SkyMap>,
        /// Rotation about +y, degrees.
        rotation_deg: f32,
        /// Factor on the texels.
        scale: f32,
    },
}

impl Environment {
    /// Checks the values of the environment; `path` names the scene and
    /// `sun` is the scene's first sun direction, if it has one (a clear
    /// sky needs it).
    pub fn validate(&self, path: &Path, sun: Option<Vec3>) -> Result<(), SceneError> {
        let bad = |field: &str, reason: String| {
            Err(SceneError::invalid(
                path,
                &format!("environment.sky.{field}"),
                reason,
            ))
        };
        match &self.sky {
            Sky::Constant { radiance } => {
                if !(radiance.is_finite() && radiance.min_element() >= 0.0) {
                    return bad(
                        "Constant.radiance",
                        format!("{:?} must be finite and non-negative", radiance.to_array()),
                    );
                }
            }
            Sky::Map {
                file,
                rotation_deg,
                scale,
            } => {
                if file.as_os_str().is_empty() {
                    return bad("Map.file", "is empty".into());
                }
                if !rotation_deg.is_finite() {
                    return bad("Map.rotation_deg", format!("{rotation_deg} is not finite"));
                }
                if !(scale.is_finite() && *scale >= 0.0) {
                    return bad(
                        "Map.scale",
                        format!("{scale} must be finite and non-negative"),
                    );
                }
            }
            Sky::ClearSky { turbidity, scale } => {
                if !(turbidity.is_finite() && (1.7..=10.0).contains(turbidity)) {
                    return bad(
                        "ClearSky.turbidity",
                        format!("{turbidity} must lie in [1.7, 10]"),
                    );
                }
                if !(scale.is_finite() && *scale >= 0.0) {
                    return bad(
                        "ClearSky.scale",
                        format!("{scale} must be finite and non-negative"),
                    );
                }
                if sun.is_none() {
                    return bad(
                        "ClearSky",
                        "a clear sky follows the scene's first sun, and the scene has no Sun \
                         light"
                            .into(),
                    );
                }
            }
        }
        Ok(())
    }

    /// Loads the map (relative to `scene_dir`) or bakes the clear sky for
    /// the sun travelling along `sun` (the scene's first sun).
    pub fn load(&self, scene_dir: &Path, sun: Option<Vec3>) -> Result<LoadedSky, SceneError> {
        match &self.sky {
            Sky::Constant { radiance } => Ok(LoadedSky::Constant(*radiance)),
            Sky::Map {
                file,
                rotation_deg,
                scale,
            } => Ok(LoadedSky::Map {
                map: Arc::new(load_sky_map(&scene_dir.join(file))?),
                rotation_deg: *rotation_deg,
                scale: *scale,
            }),
            Sky::ClearSky { turbidity, scale } => {
                let sun = sun.unwrap_or(Vec3::NEG_Y);
                Ok(LoadedSky::Map {
                    map: Arc::new(clear_sky_map(sun, *turbidity, CLEAR_SKY_WIDTH)),
                    rotation_deg: 0.0,
                    scale: *scale,
                })
            }
        }
    }
}

/// Reads a latitude–longitude map from an `.exr` or `.hdr` file and checks
/// it: 2:1, at least 4×2 and at most [`MAX_MAP_WIDTH`] wide, every texel
/// finite and non-negative.
pub fn load_sky_map(path: &Path) -> Result<SkyMap, SceneError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase());
    let map = match ext.as_deref() {
        Some("exr") => read_exr_map(path)?,
        Some("hdr") => read_hdr_map(path)?,
        _ => {
            return Err(SceneError::environment(
                path,
                "is neither an OpenEXR (.exr) nor a Radiance (.hdr) file",
            ))
        }
    };
    check_map(path, &map)?;
    Ok(map)
}

/// Checks a map's shape and texels; `path` names it in the error.
pub fn check_map(path: &Path, map: &SkyMap) -> Result<(), SceneError> {
    let (w, h) = (map.width, map.height);
    if w != 2 * h {
        return Err(SceneError::environment(
            path,
            format!(
                "is {w}×{h} pixels: a latitude–longitude map is twice as wide as it is high \
                 (e.g. 64×32)"
            ),
        ));
    }
    if h < 2 {
        return Err(SceneError::environment(
            path,
            format!("is {w}×{h} pixels: a map needs at least 4×2"),
        ));
    }
    if map.texels.len() != w as usize * h as usize {
        return Err(SceneError::environment(
            path,
            format!("holds {} texels for {w}×{h}", map.texels.len()),
        ));
    }
    if let Some(i) = map
        .texels
        .iter()
        .position(|t| !(t.is_finite() && t.min_element() >= 0.0))
    {
        let t = map.texels[i];
        return Err(SceneError::environment(
            path,
            format!(
                "texel (column {}, row {}) is {:?}: radiance must be finite and non-negative",
                i % w as usize,
                i / w as usize,
                t.to_array()
            ),
        ));
    }
    Ok(())
}

/// The first RGB(A) layer of an OpenEXR file, row-major with row 0 at the
/// top. An image wider or taller than `max_side` comes back with its size
/// but no texels, so that the caller refuses it before its pixels are
/// allocated. (The sky's maps and `render::export::read_exr`.)
pub fn read_rgb_exr(path: &Path, max_side: usize) -> exr::error::Result<SkyMap> {
    use exr::prelude::*;
    let image = read_first_rgba_layer_from_file(
        path,
        move |resolution, _| {
            let (w, h) = (resolution.width(), resolution.height());
            let n = if w <= max_side && h <= max_side {
                w * h
            } else {
                0
            };
            SkyMap {
                width: w.min(u32::MAX as usize) as u32,
                height: h.min(u32::MAX as usize) as u32,
                texels: vec![Vec3::ZERO; n],
            }
        },
        |img: &mut SkyMap, pos, (r, g, b, _a): (f32, f32, f32, f32)| {
            let i = pos.y() * img.width as usize + pos.x();
            if let Some(p) = img.texels.get_mut(i) {
                *p = Vec3::new(r, g, b);
            }
        },
    )?;
    Ok(image.layer_data.channel_data.pixels)
}

fn read_exr_map(path: &Path) -> Result<SkyMap, SceneError> {
    if let Err(reason) = std::fs::metadata(path) {
        return Err(SceneError::Io {
            path: path.to_owned(),
            reason,
        });
    }
    let map = read_rgb_exr(path, MAX_MAP_WIDTH as usize).map_err(|e| {
        SceneError::environment(path, format!("is not a readable OpenEXR map: {e}"))
    })?;
    if map.width > MAX_MAP_WIDTH || map.texels.len() != map.width as usize * map.height as usize {
        return Err(SceneError::environment(
            path,
            format!(
                "is {}×{} pixels, more than {MAX_MAP_WIDTH} wide",
                map.width, map.height
            ),
        ));
    }
    Ok(map)
}

fn read_hdr_map(path: &Path) -> Result<SkyMap, SceneError> {
    use image::ImageDecoder;
    let file = std::fs::File::open(path).map_err(|reason| SceneError::Io {
        path: path.to_owned(),
        reason,
    })?;
    let decoder =
        image::codecs::hdr::HdrDecoder::new(std::io::BufReader::new(file)).map_err(|e| {
            SceneError::environment(path, format!("is not a readable Radiance map: {e}"))
        })?;
    let (w, h) = decoder.dimensions();
    if w > MAX_MAP_WIDTH || h > MAX_MAP_WIDTH {
        return Err(SceneError::environment(
            path,
            format!("is {w}×{h} pixels, more than {MAX_MAP_WIDTH} wide"),
        ));
    }
    let image = image::DynamicImage::from_decoder(decoder)
        .map_err(|e| SceneError::environment(path, format!("is not a readable Radiance map: {e}")))?
        .to_rgb32f();
    let texels = image
        .pixels()
        .map(|p| Vec3::new(p.0[0], p.0[1], p.0[2]))
        .collect();
    Ok(SkyMap {
        width: w,
        height: h,
        texels,
    })
}

/// The unit direction towards the sky of map coordinates `(u, v)` (`u`
/// across, `v` down, both in `[0, 1]`), before rotation.
pub fn map_direction(u: f32, v: f32) -> Vec3 {
    let (st, ct) = (v * std::f32::consts::PI).sin_cos();
    let (sp, cp) = (u * std::f32::consts::TAU).sin_cos();
    Vec3::new(sp * st, ct, -cp * st)
}

/// Bakes the Preetham et al. (1999) clear sky, "A Practical Analytic Model
/// for Daylight", for a sun whose light travels along `sun_travel`, into a
/// `width × width/2` latitude–longitude map (texels at Mitsuba's vertex
/// positions). Luminance and chromaticity follow the paper's Perez
/// coefficients and zenith formulas (its appendix), converted from `xyY`
/// to linear sRGB (Rec. 709 primaries); luminance in kcd/m² is scaled by
/// 1/50. Below the horizon the sky is the horizon's colour at a tenth of
/// its brightness (a dark ground).
pub fn clear_sky_map(sun_travel: Vec3, turbidity: f32, width: u32) -> SkyMap {
    let width = width.max(4);
    let height = width / 2;
    let to_sun = (-sun_travel).normalize_or(Vec3::Y);
    // The model needs the sun above the horizon; below, a dim twilight.
    let sun_elev = to_sun.y.clamp(0.01, 1.0);
    let sun = Vec3::new(to_sun.x, sun_elev, to_sun.z).normalize_or(Vec3::Y);
    let theta_s = sun.y.clamp(-1.0, 1.0).acos();
    let t = turbidity;
    let perez = |a: f32, b: f32, c: f32, d: f32, e: f32, theta: f32, gamma: f32| {
        (1.0 + a * (b / theta.cos().max(0.01)).exp())
            * (1.0 + c * (d * gamma).exp() + e * gamma.cos() * gamma.cos())
    };
    let y_coef = [
        0.1787 * t - 1.4630,
        -0.3554 * t + 0.4275,
        -0.0227 * t + 5.3251,
        0.1206 * t - 2.5771,
        -0.0670 * t + 0.3703,
    ];
    let x_coef = [
        -0.0193 * t - 0.2592,
        -0.0665 * t + 0.0008,
        -0.0004 * t + 0.2125,
        -0.0641 * t - 0.8989,
        -0.0033 * t + 0.0452,
    ];
    let yc_coef = [
        -0.0167 * t - 0.2608,
        -0.0950 * t + 0.0092,
        -0.0079 * t + 0.2102,
        -0.0441 * t - 1.6537,
        -0.0109 * t + 0.0529,
    ];
    let chi = (4.0 / 9.0 - t / 120.0) * (std::f32::consts::PI - 2.0 * theta_s);
    let y_zenith = ((4.0453 * t - 4.9710) * chi.tan() - 0.2155 * t + 2.4192).max(0.0);
    let (ts, ts2, ts3) = (theta_s, theta_s * theta_s, theta_s * theta_s * theta_s);
    let zen = |m: [[f32; 4]; 3]| {
        let row = |r: [f32; 4]| r[0] * ts3 + r[1] * ts2 + r[2] * ts + r[3];
        t * t * row(m[0]) + t * row(m[1]) + row(m[2])
    };
    let x_zenith = zen([
        [0.00166, -0.00375, 0.00209, 0.0],
        [-0.02903, 0.06377, -0.03202, 0.00394],
        [0.11693, -0.21196, 0.06052, 0.25886],
    ]);
    let y_zenith_c = zen([
        [0.00275, -0.00610, 0.00317, 0.0],
        [-0.04214, 0.08970, -0.04153, 0.00516],
        [0.15346, -0.26756, 0.06670, 0.26688],
    ]);
    let value = |c: [f32; 5], zenith: f32, theta: f32, gamma: f32| {
        zenith * perez(c[0], c[1], c[2], c[3], c[4], theta, gamma)
            / perez(c[0], c[1], c[2], c[3], c[4], 0.0, theta_s)
    };
    let dim = if to_sun.y < 0.01 {
        // Twilight: fade over the first ten degrees below the horizon.
        (1.0 + (to_sun.y - 0.01) / 0.17).clamp(0.0, 1.0)
    } else {
        1.0
    };
    let mut texels = Vec::with_capacity(width as usize * height as usize);
    for row in 0..height {
        let v = row as f32 / (height - 1) as f32;
        for col in 0..width {
            let u = (col as f32 + 0.5) / width as f32;
            let dir = map_direction(u, v);
            let below = dir.y < 0.0;
            let up = Vec3::new(dir.x, dir.y.max(0.0), dir.z).normalize_or(Vec3::Y);
            let theta = up.y.clamp(-1.0, 1.0).acos().min(1.5533);
            let gamma = up.dot(sun).clamp(-1.0, 1.0).acos();
            let lum = value(y_coef, y_zenith, theta, gamma);
            let cx = value(x_coef, x_zenith, theta, gamma);
            let cy = value(yc_coef, y_zenith_c, theta, gamma).max(1e-4);
            // xyY → XYZ → linear sRGB.
            let big_y = lum / 50.0 * if below { 0.1 } else { 1.0 } * dim;
            let big_x = cx / cy * big_y;
            let big_z = (1.0 - cx - cy) / cy * big_y;
            let rgb = Vec3::new(
                3.2406 * big_x - 1.5372 * big_y - 0.4986 * big_z,
                -0.9689 * big_x + 1.8758 * big_y + 0.0415 * big_z,
                0.0557 * big_x - 0.2040 * big_y + 1.0570 * big_z,
            );
            let rgb = rgb.max(Vec3::ZERO);
            texels.push(if rgb.is_finite() { rgb } else { Vec3::ZERO });
        }
    }
    SkyMap {
        width,
        height,
        texels,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write_exr(
        path: &Path,
        w: usize,
        h: usize,
        f: impl Fn(usize, usize) -> (f32, f32, f32) + Sync,
    ) {
        use exr::prelude::*;
        let channels = SpecificChannels::rgb(|Vec2(x, y): Vec2<usize>| f(x, y));
        Image::from_channels((w, h), channels)
            .write()
            .to_file(path)
            .expect("write exr");
    }

    #[test]
    fn reads_a_good_exr_map() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("sky.exr");
        write_exr(&path, 8, 4, |x, y| (x as f32, y as f32, 1.0));
        let map = load_sky_map(&path).expect("loads");
        assert_eq!((map.width, map.height), (8, 4));
        assert_eq!(map.texels[8 + 3], Vec3::new(3.0, 1.0, 1.0));
    }

    #[test]
    fn reads_a_good_hdr_map() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("sky.hdr");
        let pixels: Vec<image::Rgb<f32>> = (0..32)
            .map(|i| image::Rgb([0.5, 0.25 * (i % 4) as f32, 2.0]))
            .collect();
        let file = std::fs::File::create(&path).expect("create");
        image::codecs::hdr::HdrEncoder::new(file)
            .encode(&pixels, 8, 4)
            .expect("encode");
        let map = load_sky_map(&path).expect("loads");
        assert_eq!((map.width, map.height), (8, 4));
        assert!((map.texels[2] - Vec3::new(0.5, 0.5, 2.0)).length() < 0.02);
    }

    fn message(e: SceneError) -> String {
        format!("{:#}", anyhow::Error::from(e))
    }

    #[test]
    fn missing_map_names_the_file() {
        let e = message(load_sky_map(Path::new("/nonexistent/lantern/sky.exr")).unwrap_err());
        assert!(e.contains("/nonexistent/lantern/sky.exr"), "{e}");
    }

    #[test]
    fn truncated_map_is_refused() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("sky.exr");
        write_exr(&path, 64, 32, |x, _| (x as f32, 0.5, 0.25));
        let bytes = std::fs::read(&path).expect("read");
        std::fs::write(&path, &bytes[..bytes.len() / 2]).expect("truncate");
        let e = message(load_sky_map(&path).unwrap_err());
        assert!(e.contains("sky.exr") && e.contains("OpenEXR"), "{e}");
        let hdr = dir.path().join("sky.hdr");
        std::fs::write(
            &hdr,
            b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 32 +X 64\n\x02\x02",
        )
        .expect("write");
        let e = message(load_sky_map(&hdr).unwrap_err());
        assert!(e.contains("sky.hdr") && e.contains("Radiance"), "{e}");
    }

    #[test]
    fn non_latlong_map_is_refused() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("square.exr");
        write_exr(&path, 16, 16, |_, _| (1.0, 1.0, 1.0));
        let e = message(load_sky_map(&path).unwrap_err());
        assert!(e.contains("square.exr") && e.contains("16×16"), "{e}");
        let e = message(load_sky_map(&dir.path().join("sky.png")).unwrap_err());
        assert!(e.contains("sky.png") && e.contains(".hdr"), "{e}");
    }

    #[test]
    fn nan_and_negative_texels_are_refused() {
        let dir = tempfile::tempdir().expect("tempdir");
        for (name, bad) in [
            ("nan.exr", f32::NAN),
            ("neg.exr", -1.0),
            ("inf.exr", f32::INFINITY),
        ] {
            let path = dir.path().join(name);
            write_exr(&path, 8, 4, |x, y| {
                if (x, y) == (5, 2) {
                    (0.0, bad, 0.0)
                } else {
                    (1.0, 1.0, 1.0)
                }
            });
            let e = message(load_sky_map(&path).unwrap_err());
            assert!(
                e.contains(name) && e.contains("column 5, row 2") && e.contains("non-negative"),
                "{e}"
            );
        }
    }

    #[test]
    fn clear_sky_is_brighter_towards_the_sun_and_blue_overhead() {
        let sun = Vec3::new(-0.5, -0.4, 0.3).normalize();
        let map = clear_sky_map(sun, 3.0, 64);
        assert!(map
            .texels
            .iter()
            .all(|t| t.is_finite() && t.min_element() >= 0.0));
        let zenith = map.texels[0];
        assert!(zenith.z > zenith.x, "zenith {zenith:?} is not blue");
        // Texel nearest the sun against the one opposite it, same height.
        let to_sun = -sun;
        let at = |d: Vec3| {
            let mut best = (f32::MIN, Vec3::ZERO);
            for row in 0..32 {
                for col in 0..64 {
                    let dir = map_direction((col as f32 + 0.5) / 64.0, row as f32 / 31.0);
                    let c = dir.dot(d);
                    if c > best.0 {
                        best = (c, map.texels[row * 64 + col]);
                    }
                }
            }
            best.1
        };
        let away = Vec3::new(-to_sun.x, to_sun.y, -to_sun.z);
        assert!(at(to_sun).y > 2.0 * at(away).y);
    }

    #[test]
    fn clear_sky_needs_a_sun() {
        let env = Environment {
            sky: Sky::ClearSky {
                turbidity: 3.0,
                scale: 1.0,
            },
            background: false,
        };
        let e = message(env.validate(Path::new("s.ron"), None).unwrap_err());
        assert!(e.contains("s.ron") && e.contains("Sun"), "{e}");
        assert!(env.validate(Path::new("s.ron"), Some(Vec3::NEG_Y)).is_ok());
    }
}
