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
    let side = crate::scene::MAX_IMAGE_SIDE as usize;
    let read =
        crate::scene::environment::read_rgb_exr(path, side).map_err(|e| ImageError::Read {
            path: path.to_owned(),
            reason: e.to_string(),
        })?;
    let image = RgbImage {
        width: read.width,
        height: read.height,
        pixels: read.texels,
    };
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

/// Writes linear RGB as a 32-bit float OpenEXR file whose header carries
/// `metadata` as text attributes (key, value; Latin-1 text), for
/// [`read_exr_metadata`] to read back.
pub fn write_exr_with_metadata(
    path: &Path,
    width: u32,
    height: u32,
    pixels: &[Vec3],
    metadata: &[(String, String)],
) -> Result<(), ImageError> {
    use exr::prelude::*;
    let fail = |reason: String| {
        ImageError::Write(WriteError {
            path: path.to_owned(),
            reason,
            kept: path.exists(),
        })
    };
    let (w, n) = (width as usize, width as usize * height as usize);
    if pixels.len() != n {
        return Err(fail(format!(
            "{} pixels for {width}×{height}",
            pixels.len()
        )));
    }
    let mut attributes = LayerAttributes::default();
    for (k, v) in metadata {
        let text = |s: &str| Text::new_or_none(s).ok_or_else(|| fail(format!("not Latin-1: {s}")));
        attributes
            .other
            .insert(text(k)?, AttributeValue::Text(text(v)?));
    }
    let channels = SpecificChannels::rgb(|Vec2(x, y): Vec2<usize>| {
        let p = pixels[y * w + x];
        (p.x, p.y, p.z)
    });
    let layer = Layer::new(
        (w, height as usize),
        attributes,
        Encoding::SMALL_LOSSLESS,
        channels,
    );
    let image = Image::from_layer(layer);
    Ok(write_atomically(path, |out| {
        image.write().to_buffered(out)
    })?)
}

/// The text attributes of an OpenEXR file's first header (those of
/// [`write_exr_with_metadata`]), sorted by key; other attribute types are
/// skipped.
pub fn read_exr_metadata(path: &Path) -> Result<Vec<(String, String)>, ImageError> {
    use exr::meta::attribute::AttributeValue;
    let meta = exr::meta::MetaData::read_from_file(path, false).map_err(|e| ImageError::Read {
        path: path.to_owned(),
        reason: e.to_string(),
    })?;
    let mut out: Vec<(String, String)> = meta
        .headers
        .first()
        .map(|h| {
            h.own_attributes
                .other
                .iter()
                .filter_map(|(k, v)| match v {
                    AttributeValue::Text(t) => Some((k.to_string(), t.to_string())),
                    _ => None,
                })
                .collect()
        })
        .unwrap_or_default();
    out.sort();
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Pixels and text attributes come back as written.
    #[test]
    fn exr_metadata_round_trips() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.exr");
        let pixels: Vec<Vec3> = (0..6)
            .map(|i| Vec3::new(i as f32, 0.5 * i as f32, -1.0))
            .collect();
        let meta = vec![
            ("lantern/spp".to_owned(), "37".to_owned()),
            ("lantern/seconds".to_owned(), "2.5".to_owned()),
            ("lantern/method".to_owned(), "Internal".to_owned()),
        ];
        write_exr_with_metadata(&path, 3, 2, &pixels, &meta).unwrap();
        let back = read_exr(&path).unwrap();
        assert_eq!((back.width, back.height), (3, 2));
        assert_eq!(back.pixels, pixels);
        let mut sorted = meta.clone();
        sorted.sort();
        assert_eq!(read_exr_metadata(&path).unwrap(), sorted);
        // A plain EXR has none of them; a wrong size is refused.
        write_exr(&path, 3, 2, &pixels).unwrap();
        assert!(read_exr_metadata(&path)
            .unwrap()
            .iter()
            .all(|(k, _)| !k.starts_with("lantern/")));
        assert!(write_exr_with_metadata(&path, 2, 2, &pixels, &meta).is_err());
    }
}
