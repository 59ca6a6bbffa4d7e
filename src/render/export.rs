//! Writing and reading still images: 32-bit float linear EXR, and 8-bit
//! sRGB PNG after an exposure and a view transform.
//!
//! Images are written whole or not at all ([`crate::atomic`]): a failed
//! write leaves the previous file unchanged.

use std::path::{Path, PathBuf};

use crate::atomic::{write_atomically, WriteError};

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
    /// The encoder or the file system failed (the previous file, if any,
    /// is unchanged).
    #[error(transparent)]
    Write(#[from] WriteError),
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
    use exr::prelude::*;
    let w = width as usize;
    let channels = SpecificChannels::rgb(|Vec2(x, y)| {
        let p = pixels.get(y * w + x).copied().unwrap_or(Vec3::ZERO);
        (p.x, p.y, p.z)
    });
    let image = Image::from_channels((w, height as usize), channels);
    Ok(write_atomically(path, |out| {
        image.write().to_buffered(out)
    })?)
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
    Ok(write_png_bytes(
        path,
        &bytes,
        width,
        height,
        image::ExtendedColorType::Rgb8,
    )?)
}

/// Writes 8-bit pixels (`color`: RGB or RGBA) as a PNG file, whole or not
/// at all.
pub fn write_png_bytes(
    path: &Path,
    bytes: &[u8],
    width: u32,
    height: u32,
    color: image::ExtendedColorType,
) -> Result<(), WriteError> {
    use image::ImageEncoder;
    write_atomically(path, |out| {
        image::codecs::png::PngEncoder::new(out).write_image(bytes, width, height, color)
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

/// Reads the first RGB(A) layer of an OpenEXR file. An image larger than
/// [`crate::scene::MAX_IMAGE_SIDE`] on a side is refused before its pixels
/// are allocated.
pub fn read_exr(path: &Path) -> Result<RgbImage, ImageError> {
    use exr::prelude::*;
    let side = crate::scene::MAX_IMAGE_SIDE as usize;
    let image = read_first_rgba_layer_from_file(
        path,
        move |resolution, _| {
            let (w, h) = (resolution.width(), resolution.height());
            // Too large: no pixels, reported below.
            let n = if w <= side && h <= side { w * h } else { 0 };
            RgbImage {
                width: w.min(u32::MAX as usize) as u32,
                height: h.min(u32::MAX as usize) as u32,
                pixels: vec![Vec3::ZERO; n],
            }
        },
        |img: &mut RgbImage, pos, (r, g, b, _a): (f32, f32, f32, f32)| {
            let i = pos.y() * img.width as usize + pos.x();
            if let Some(p) = img.pixels.get_mut(i) {
                *p = Vec3::new(r, g, b);
            }
        },
    )
    .map_err(|e| ImageError::Read {
        path: path.to_owned(),
        reason: e.to_string(),
    })?;
    let image = image.layer_data.channel_data.pixels;
    if image.pixels.len() != image.width as usize * image.height as usize {
        return Err(ImageError::Read {
            path: path.to_owned(),
            reason: format!(
                "the image is {}×{} pixels, more than {side} on a side",
                image.width, image.height
            ),
        });
    }
    Ok(image)
}
