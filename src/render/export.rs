//! Writing and reading still images: 32-bit float linear EXR, and 8-bit
//! sRGB PNG after an exposure and a view transform.

use std::path::{Path, PathBuf};

use glam::Vec3;

use super::tonemap::{to_srgb8, ViewTransform};

/// An image could not be written or read.
#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    /// The file extension is neither `.exr` nor `.png`.
    #[error("{path}: unsupported image format (use .exr or .png)")]
    UnsupportedFormat {
        /// The path given.
        path: PathBuf,
    },
    /// The encoder or the file system failed.
    #[error("cannot write {path}: {reason}")]
    Write {
        /// The destination.
        path: PathBuf,
        /// Why.
        reason: String,
    },
    /// The file could not be read as an RGB EXR image.
    #[error("cannot read {path}: {reason}")]
    Read {
        /// The source.
        path: PathBuf,
        /// Why.
        reason: String,
    },
}

/// Writes linear RGB as a 32-bit float OpenEXR file.
pub fn write_exr(path: &Path, width: u32, height: u32, pixels: &[Vec3]) -> Result<(), ImageError> {
    let w = width as usize;
    exr::prelude::write_rgb_file(path, w, height as usize, |x, y| {
        let p = pixels[y * w + x];
        (p.x, p.y, p.z)
    })
    .map_err(|e| ImageError::Write {
        path: path.to_owned(),
        reason: e.to_string(),
    })
}

/// Writes 8-bit sRGB PNG after `exposure_stops` and `view`.
pub fn write_png(
    path: &Path,
    width: u32,
    height: u32,
    pixels: &[Vec3],
    exposure_stops: f32,
    view: ViewTransform,
) -> Result<(), ImageError> {
    let bytes = to_srgb8(pixels, exposure_stops, view);
    image::save_buffer(path, &bytes, width, height, image::ColorType::Rgb8).map_err(|e| {
        ImageError::Write {
            path: path.to_owned(),
            reason: e.to_string(),
        }
    })
}

/// Writes `.exr` (linear) or `.png` (display-transformed) by extension.
pub fn write_image(
    path: &Path,
    width: u32,
    height: u32,
    pixels: &[Vec3],
    exposure_stops: f32,
    view: ViewTransform,
) -> Result<(), ImageError> {
    match extension(path).as_deref() {
        Some("exr") => write_exr(path, width, height, pixels),
        Some("png") => write_png(path, width, height, pixels, exposure_stops, view),
        _ => Err(ImageError::UnsupportedFormat {
            path: path.to_owned(),
        }),
    }
}

/// The lower-case extension of a path.
pub fn extension(path: &Path) -> Option<String> {
    path.extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
}

/// A linear RGB image read from a file.
#[derive(Clone, Debug)]
pub struct RgbImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Row-major pixels, row 0 at the top.
    pub pixels: Vec<Vec3>,
}

/// Reads the first RGB(A) layer of an OpenEXR file.
pub fn read_exr(path: &Path) -> Result<RgbImage, ImageError> {
    use exr::prelude::*;
    let image = read_first_rgba_layer_from_file(
        path,
        |resolution, _| RgbImage {
            width: resolution.width() as u32,
            height: resolution.height() as u32,
            pixels: vec![Vec3::ZERO; resolution.width() * resolution.height()],
        },
        |img: &mut RgbImage, pos, (r, g, b, _a): (f32, f32, f32, f32)| {
            let i = pos.y() * img.width as usize + pos.x();
            img.pixels[i] = Vec3::new(r, g, b);
        },
    )
    .map_err(|e| ImageError::Read {
        path: path.to_owned(),
        reason: e.to_string(),
    })?;
    Ok(image.layer_data.channel_data.pixels)
}
