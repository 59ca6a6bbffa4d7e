//! Raw little-endian float32 voxels described by a small RON header file
//! (Lantern's own format, for grids exported from numpy, Houdini, ...).
//!
//! The header names the dimensions, the world bounds, the storage order and
//! the data file, relative to the header's folder; unknown fields are
//! errors:
//!
//! ```ron
//! (
//!     dims: (64, 32, 48),
//!     bounds_min: (-1.0, -0.5, -0.75),
//!     bounds_max: (1.0, 0.5, 0.75),
//!     axis_order: XFastest,
//!     data: "cloud.raw",
//! )
//! ```
//!
//! The data file holds exactly `nx·ny·nz` little-endian `f32`, nothing else.
//! `XFastest` stores voxel `(i, j, k)` at `i + nx (j + ny k)` (Fortran order,
//! as Mitsuba and Lantern do); `ZFastest` at `k + nz (j + ny i)` (C order of a
//! numpy array indexed `[x][y][z]`, e.g. `a.astype('<f4').tofile(...)`). Grids
//! are converted to x fastest on load.

use std::io::BufReader;
use std::path::{Path, PathBuf};

use glam::{UVec3, Vec3};
use serde::{Deserialize, Serialize};

use super::{
    bad_voxel_reason, check_bounds, first_bad_voxel, open, read_f32s, try_vec, voxel_count,
};
use crate::scene::{SceneError, VoxelGrid};

/// Largest header file accepted: a header is a few hundred bytes, so a big
/// file is almost certainly the data file given by mistake.
const MAX_HEADER_BYTES: u64 = 64 * 1024;

/// Which index varies fastest in the data file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum AxisOrder {
    /// `i + nx (j + ny k)`: Fortran order, as Mitsuba and Lantern store grids.
    XFastest,
    /// `k + nz (j + ny i)`: C order of an array indexed `[x][y][z]`.
    ZFastest,
}

/// The header file of a raw grid.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawHeader {
    /// Voxels along x, y, z (each ≥ 1).
    pub dims: (u32, u32, u32),
    /// Minimum corner of the world box.
    pub bounds_min: Vec3,
    /// Maximum corner of the world box.
    pub bounds_max: Vec3,
    /// Storage order of the data file.
    pub axis_order: AxisOrder,
    /// Data file, relative to the header's folder (an absolute path is used
    /// as is).
    pub data: String,
}

/// Reads the RON header at `path` and the float32 data file it names.
///
/// Errors: the header unreadable, not RON, truncated, with an unknown or
/// missing field (naming the header); the data file missing (naming it);
/// the data file's size not exactly `nx·ny·nz·4` bytes (naming the data
/// file, the expected and actual byte counts and the header's dims); bad
/// dims, bounds or voxel values.
pub fn read_raw(path: &Path) -> Result<VoxelGrid, SceneError> {
    let header = read_header(path)?;
    let bad_header = |reason: String| SceneError::volume(path, reason);
    let (nx, ny, nz) = header.dims;
    let n =
        voxel_count([nx, ny, nz].map(i64::from)).map_err(|r| bad_header(format!("dims: {r}")))?;
    check_bounds(header.bounds_min, header.bounds_max)
        .map_err(|r| bad_header(format!("bounds_min/bounds_max: {r}")))?;
    if header.data.trim().is_empty() {
        return Err(bad_header(
            "the `data` field (the data file's name) is empty".into(),
        ));
    }
    let data_path = data_path(path, &header.data);
    if data_path == path {
        return Err(bad_header(
            "the `data` field names the header file itself".into(),
        ));
    }

    let (file, actual) = open(&data_path)?;
    let bad_data = |reason: String| SceneError::volume(&data_path, reason);
    let expected = (n as u64) * 4; // n ≤ 2³⁰: no overflow.
    if actual != expected {
        let problem = if actual < expected {
            "is truncated: it"
        } else {
            "is too long: it"
        };
        return Err(bad_data(format!(
            "data file {problem} has {actual} bytes, but the header {} gives dims \
             ({nx}, {ny}, {nz}), i.e. {nx}×{ny}×{nz}×4 = {expected} bytes of float32",
            path.display()
        )));
    }
    let values = read_f32s(&data_path, &mut BufReader::new(file), n, |got| {
        bad_data(format!(
            "data file is truncated: it ended after {got} of {expected} bytes while being read"
        ))
    })?;
    let data = match header.axis_order {
        AxisOrder::XFastest => values,
        AxisOrder::ZFastest => z_fastest_to_x_fastest(&values, [nx, ny, nz]).map_err(bad_data)?,
    };
    let dims = UVec3::new(nx, ny, nz);
    if let Some((ijk, v)) = first_bad_voxel(dims, &data) {
        return Err(bad_data(bad_voxel_reason(ijk, v)));
    }
    Ok(VoxelGrid {
        dims,
        bounds_min: header.bounds_min,
        bounds_max: header.bounds_max,
        data,
    })
}

/// Reads and parses a raw header file.
fn read_header(path: &Path) -> Result<RawHeader, SceneError> {
    let (file, len) = open(path)?;
    let bad = |reason: String| SceneError::volume(path, reason);
    if len > MAX_HEADER_BYTES {
        return Err(bad(format!(
            "is {len} bytes, too large for a raw-grid header: the path must name the RON \
             header, not the float32 data"
        )));
    }
    let mut bytes = Vec::new();
    std::io::Read::read_to_end(&mut std::io::Read::take(file, MAX_HEADER_BYTES), &mut bytes)
        .map_err(|e| super::io_error(path, e))?;
    let text = String::from_utf8(bytes).map_err(|_| {
        bad(
            "the raw-grid header is not UTF-8 text (is this the data file rather than the \
             RON header?)"
                .into(),
        )
    })?;
    ron::from_str::<RawHeader>(&text).map_err(|e| {
        let what = if e.code == ron::Error::Eof || at_end(&text, e.position) {
            "the raw-grid header is truncated (the text ends before the header is complete)"
        } else {
            "invalid raw-grid header (syntax, unknown or missing field, or wrong type)"
        };
        bad(format!(
            "{what}: {e}; expected ( dims: (nx, ny, nz), bounds_min: (x, y, z), \
             bounds_max: (x, y, z), axis_order: XFastest | ZFastest, data: \"file.raw\" )"
        ))
    })
}

/// Whether a parse error at `pos` lies at (or past) the end of the text's
/// last non-blank character: the text stopped before the header was
/// complete.
fn at_end(text: &str, pos: ron::error::Position) -> bool {
    let trimmed = text.trim_end();
    let line = trimmed.lines().count().max(1);
    let col = trimmed.lines().last().map_or(0, |l| l.chars().count()) + 1;
    (pos.line, pos.col) >= (line, col)
}

/// The data file named by a header at `header_path`.
fn data_path(header_path: &Path, data: &str) -> PathBuf {
    header_path.parent().unwrap_or(Path::new("")).join(data)
}

/// Reorders C-order (`k + nz (j + ny i)`) values to x fastest.
fn z_fastest_to_x_fastest(values: &[f32], [nx, ny, nz]: [u32; 3]) -> Result<Vec<f32>, String> {
    let (nx, ny, nz) = (nx as usize, ny as usize, nz as usize);
    let mut out = try_vec(values.len())?;
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                let v = values
                    .get(k + nz * (j + ny * i))
                    .ok_or("internal error: voxel index out of range")?;
                out.push(*v);
            }
        }
    }
    Ok(out)
}

/// Writes `grid` as a RON header at `header_path` plus the data file
/// `<stem>.raw` beside it (x fastest, little-endian float32). The header's
/// `data` field is the data file's bare name, so the pair can be moved
/// together.
pub fn write_raw(header_path: &Path, grid: &VoxelGrid) -> Result<(), SceneError> {
    let write_err = |p: &Path, reason: String| SceneError::Write {
        path: p.to_owned(),
        reason,
    };
    let d = grid.dims;
    let n = (d.x as u64)
        .checked_mul(d.y as u64)
        .and_then(|n| n.checked_mul(d.z as u64));
    if n != Some(grid.data.len() as u64) || grid.data.is_empty() {
        return Err(write_err(
            header_path,
            format!(
                "the grid has {} values for {}×{}×{} dimensions",
                grid.data.len(),
                d.x,
                d.y,
                d.z
            ),
        ));
    }
    let stem = header_path
        .file_stem()
        .and_then(|s| s.to_str())
        .filter(|s| !s.is_empty())
        .ok_or_else(|| {
            write_err(
                header_path,
                "the header path needs a UTF-8 file name to derive the data file's name".into(),
            )
        })?;
    let data_name = format!("{stem}.raw");
    let data_file = data_path(header_path, &data_name);
    if data_file == header_path {
        return Err(write_err(
            header_path,
            "the header path must not end in .raw: the data file would overwrite it".into(),
        ));
    }
    let header = RawHeader {
        dims: (d.x, d.y, d.z),
        bounds_min: grid.bounds_min,
        bounds_max: grid.bounds_max,
        axis_order: AxisOrder::XFastest,
        data: data_name,
    };
    let text = ron::ser::to_string_pretty(&header, ron::ser::PrettyConfig::new())
        .map_err(|e| write_err(header_path, e.to_string()))?;
    // Data first, then the header that names it: each whole or not at all.
    crate::atomic::write_atomically(&data_file, |out| -> std::io::Result<()> {
        for v in &grid.data {
            std::io::Write::write_all(out, &v.to_le_bytes())?;
        }
        Ok(())
    })?;
    crate::atomic::write_bytes(header_path, (text + "\n").as_bytes()).map_err(SceneError::from)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn z_fastest_reorder() {
        // dims 2×3×4, C-order value = 100 i + 10 j + k.
        let (nx, ny, nz) = (2usize, 3usize, 4usize);
        let mut c = vec![0.0f32; nx * ny * nz];
        for i in 0..nx {
            for j in 0..ny {
                for k in 0..nz {
                    c[k + nz * (j + ny * i)] = (100 * i + 10 * j + k) as f32;
                }
            }
        }
        let x = z_fastest_to_x_fastest(&c, [2, 3, 4]).unwrap();
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    assert_eq!(x[i + nx * (j + ny * k)], (100 * i + 10 * j + k) as f32);
                }
            }
        }
    }

    #[test]
    fn header_errors_name_the_problem() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("h.ron");
        let cases = [
            // Truncated text.
            ("(dims: (2, 2, 2), bounds_min: (0, 0", "truncated"),
            // Missing field.
            (
                "(dims: (2, 2, 2), bounds_min: (0, 0, 0), bounds_max: (1, 1, 1), data: \"d.raw\")",
                "axis_order",
            ),
            // Bad enum value.
            (
                "(dims: (2, 2, 2), bounds_min: (0, 0, 0), bounds_max: (1, 1, 1), \
                 axis_order: YFastest, data: \"d.raw\")",
                "YFastest",
            ),
            // Negative dimension.
            (
                "(dims: (2, -2, 2), bounds_min: (0, 0, 0), bounds_max: (1, 1, 1), \
                 axis_order: XFastest, data: \"d.raw\")",
                "invalid raw-grid header",
            ),
            (
                "(dims: (2, 0, 2), bounds_min: (0, 0, 0), bounds_max: (1, 1, 1), \
                 axis_order: XFastest, data: \"d.raw\")",
                "at least 1",
            ),
            (
                "(dims: (2, 2, 2), bounds_min: (0, 0, 0), bounds_max: (1, -1, 1), \
                 axis_order: XFastest, data: \"d.raw\")",
                "max > min",
            ),
            (
                "(dims: (2, 2, 2), bounds_min: (0, 0, 0), bounds_max: (1, 1, 1), \
                 axis_order: XFastest, data: \"\")",
                "empty",
            ),
        ];
        for (text, word) in cases {
            std::fs::write(&p, text).unwrap();
            let e = read_raw(&p).unwrap_err().to_string();
            assert!(
                e.contains("h.ron") && e.contains(word),
                "want {word:?}: {e}"
            );
        }
        std::fs::write(&p, [0xffu8, 0xfe, 0x00, 0x41]).unwrap();
        let e = read_raw(&p).unwrap_err().to_string();
        assert!(e.contains("h.ron") && e.contains("not UTF-8"), "{e}");
    }

    #[test]
    fn writer_refuses_raw_extension_for_header() {
        let dir = tempfile::tempdir().unwrap();
        let g = VoxelGrid {
            dims: UVec3::ONE,
            bounds_min: Vec3::ZERO,
            bounds_max: Vec3::ONE,
            data: vec![1.0],
        };
        let e = write_raw(&dir.path().join("x.raw"), &g)
            .unwrap_err()
            .to_string();
        assert!(e.contains("x.raw") && e.contains("overwrite"), "{e}");
    }
}
