//! Voxel-grid loaders: raw little-endian float32 described by a RON header,
//! Mitsuba 3 `.vol` (its `VOL` v3 binary layout), and OpenVDB `.vdb` (one
//! float grid, read with the `vdb-rs` crate).
//!
//! Every loader produces a dense, cell-centred [`VoxelGrid`] ([method §1](crate::doc::method),
//! x fastest) and treats the file as untrusted input:
//!
//! * sizes read from a file are multiplied with checked arithmetic and
//!   compared with the bytes actually present *before* anything is
//!   allocated, and no grid larger than [`MAX_VOXELS`] voxels or
//!   [`MAX_BYTES`] bytes is built;
//! * a file that ends early is reported as truncated, naming the part
//!   (header, voxel data, tree topology, ...) that is cut;
//! * every dimension is at least 1, the bounds are finite with max > min,
//!   and every voxel is finite and non-negative (the first bad voxel is
//!   named by its `(i, j, k)` and value);
//! * nothing here panics; a panic inside the third-party OpenVDB reader is
//!   contained and reported as an error on the file.
//!
//! Errors are [`SceneError::Io`] when the file cannot be read at all and
//! [`SceneError::Volume`] (which names the file) for anything wrong inside
//! it. The writers ([`write_mitsuba_vol`], [`write_raw`]) export baked
//! grids and report [`SceneError::Write`].

mod mitsuba_vol;
mod raw;
mod vdb;

use std::fs::File;
use std::io::Read;
use std::path::Path;

use glam::{UVec3, Vec3};

pub use mitsuba_vol::{read_mitsuba_vol, write_mitsuba_vol};
pub use raw::{read_raw, write_raw, AxisOrder, RawHeader};
pub use vdb::read_vdb;

use super::{GridFormat, SceneError, VoxelGrid};

/// Largest number of voxels a dense grid may have (1024³). Grids of 512³,
/// the size Lantern is tuned for, are well inside it.
pub const MAX_VOXELS: u64 = 1024 * 1024 * 1024;

/// Largest size of the dense `f32` data of a grid, in bytes (4 GiB).
pub const MAX_BYTES: u64 = 4 * 1024 * 1024 * 1024;

/// The OpenVDB grid read when no grid name is given.
pub const DEFAULT_VDB_GRID: &str = "density";

/// Loads the voxel grid at `path`.
///
/// `format` [`GridFormat::Auto`] picks the format from the extension
/// (`.vdb`, `.vol`, or `.ron` for a raw header; see [`resolve_format`]).
/// `grid_name` selects the OpenVDB float grid (default
/// [`DEFAULT_VDB_GRID`]); giving one for another format is an error.
pub fn load_grid(
    path: &Path,
    format: GridFormat,
    grid_name: Option<&str>,
) -> Result<VoxelGrid, SceneError> {
    if path.is_dir() {
        return Err(SceneError::volume(
            path,
            "is a folder, not a volume file: name the .vdb, .vol or .ron (raw header) file \
             inside it",
        ));
    }
    let format = resolve_format(path, format)?;
    if let (Some(name), false) = (grid_name, format == GridFormat::Vdb) {
        return Err(SceneError::volume(
            path,
            format!(
                "grid_name {name:?} only applies to OpenVDB files, but this file is read as {}",
                format_name(format)
            ),
        ));
    }
    let grid = match format {
        GridFormat::Raw => read_raw(path)?,
        GridFormat::MitsubaVol => read_mitsuba_vol(path)?,
        GridFormat::Vdb => read_vdb(path, grid_name.unwrap_or(DEFAULT_VDB_GRID))?,
        GridFormat::Auto => {
            return Err(SceneError::volume(
                path,
                "the grid format could not be determined",
            ))
        }
    };
    // Every loader validates as it reads; this is the last line of defence
    // for the invariants the renderers rely on.
    check_grid(path, &grid)?;
    Ok(grid)
}

/// Resolves [`GridFormat::Auto`] from the extension of `path` (case
/// insensitive): `.vdb` → OpenVDB, `.vol` → Mitsuba, `.ron` → raw header.
/// Any other format is returned unchanged. An unknown or missing extension
/// is an error naming the file and the extension.
pub fn resolve_format(path: &Path, format: GridFormat) -> Result<GridFormat, SceneError> {
    if format != GridFormat::Auto {
        return Ok(format);
    }
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    match ext.as_deref() {
        Some("vdb") => Ok(GridFormat::Vdb),
        Some("vol") => Ok(GridFormat::MitsubaVol),
        Some("ron") => Ok(GridFormat::Raw),
        Some(other) => Err(SceneError::volume(
            path,
            format!(
                "unknown volume file extension '.{other}': expected .vdb (OpenVDB), \
                 .vol (Mitsuba) or .ron (raw float32 header), or set `format` explicitly"
            ),
        )),
        None => Err(SceneError::volume(
            path,
            "the file name has no extension, so the volume format is unknown: use .vdb, \
             .vol or .ron (raw float32 header), or set `format` explicitly",
        )),
    }
}

fn format_name(format: GridFormat) -> &'static str {
    match format {
        GridFormat::Auto => "an unknown format",
        GridFormat::Raw => "a raw float32 grid",
        GridFormat::MitsubaVol => "a Mitsuba .vol grid",
        GridFormat::Vdb => "an OpenVDB file",
    }
}

// ---------------------------------------------------------------------------
// Shared helpers.

/// Maps an I/O failure on `path` to [`SceneError::Io`].
fn io_error(path: &Path, reason: std::io::Error) -> SceneError {
    SceneError::Io {
        path: path.to_owned(),
        reason,
    }
}

/// Opens `path` for reading and returns it with its length in bytes.
fn open(path: &Path) -> Result<(File, u64), SceneError> {
    let file = File::open(path).map_err(|e| io_error(path, e))?;
    let len = file.metadata().map_err(|e| io_error(path, e))?.len();
    Ok((file, len))
}

/// Checks grid dimensions read from a file and returns the voxel count:
/// every dimension at least 1 and at most `u32::MAX`, and the grid within
/// [`MAX_VOXELS`] and [`MAX_BYTES`]. The error is a reason, without the
/// file name.
fn voxel_count(dims: [i64; 3]) -> Result<usize, String> {
    let [x, y, z] = dims;
    if dims.iter().any(|&d| d < 1) {
        return Err(format!(
            "invalid dimensions {x}×{y}×{z}: every dimension must be at least 1"
        ));
    }
    let n = [x, y, z]
        .iter()
        .try_fold(1u64, |acc, &d| acc.checked_mul(u64::try_from(d).ok()?));
    let too_big = || {
        format!(
            "dimensions {x}×{y}×{z} are too large: the limit is {MAX_VOXELS} voxels (1024³) \
             and {} GiB of float32 data",
            MAX_BYTES >> 30
        )
    };
    let n = n.ok_or_else(too_big)?;
    let fits_u32 = dims.iter().all(|&d| u32::try_from(d).is_ok());
    if !fits_u32 || n > MAX_VOXELS || n.checked_mul(4).is_none_or(|b| b > MAX_BYTES) {
        return Err(too_big());
    }
    usize::try_from(n).map_err(|_| too_big())
}

/// Checks that bounds are finite with `max > min` on every axis.
fn check_bounds(lo: Vec3, hi: Vec3) -> Result<(), String> {
    if lo.is_finite() && hi.is_finite() && hi.cmpgt(lo).all() {
        Ok(())
    } else {
        Err(format!(
            "invalid bounds {:?}..{:?}: they must be finite with max > min on every axis",
            lo.to_array(),
            hi.to_array()
        ))
    }
}

/// The first voxel (in x-fastest order) that is not finite and `≥ 0`, as
/// its `(i, j, k)` and value.
fn first_bad_voxel(dims: UVec3, data: &[f32]) -> Option<([u64; 3], f32)> {
    let (nx, ny) = (u64::from(dims.x.max(1)), u64::from(dims.y.max(1)));
    data.iter()
        .position(|v| !(v.is_finite() && *v >= 0.0))
        .and_then(|n| {
            let value = *data.get(n)?;
            let n = n as u64;
            Some(([n % nx, (n / nx) % ny, n / (nx * ny)], value))
        })
}

/// The message for a bad voxel at `ijk`.
fn bad_voxel_reason(ijk: [u64; 3], value: f32) -> String {
    let [i, j, k] = ijk;
    let what = if value.is_nan() {
        "is NaN"
    } else if value.is_infinite() {
        "is infinite"
    } else {
        "is negative"
    };
    format!(
        "voxel (i, j, k) = ({i}, {j}, {k}) holds {value}, which {what}: densities must be \
         finite and non-negative"
    )
}

/// Checks every invariant of a [`VoxelGrid`]: dimensions, data length,
/// bounds and voxel values. Errors name `path`.
fn check_grid(path: &Path, grid: &VoxelGrid) -> Result<(), SceneError> {
    let d = grid.dims;
    let n = voxel_count([d.x, d.y, d.z].map(i64::from)).map_err(|r| SceneError::volume(path, r))?;
    if grid.data.len() != n {
        return Err(SceneError::volume(
            path,
            format!(
                "internal error: {} voxel values for {}×{}×{} dimensions",
                grid.data.len(),
                d.x,
                d.y,
                d.z
            ),
        ));
    }
    check_bounds(grid.bounds_min, grid.bounds_max).map_err(|r| SceneError::volume(path, r))?;
    if let Some((ijk, v)) = first_bad_voxel(d, &grid.data) {
        return Err(SceneError::volume(path, bad_voxel_reason(ijk, v)));
    }
    Ok(())
}

/// An empty vector with room for `n` elements, or an error if the memory
/// cannot be had (instead of aborting the process).
fn try_vec<T>(n: usize) -> Result<Vec<T>, String> {
    let mut v = Vec::new();
    v.try_reserve_exact(n).map_err(|_| {
        format!(
            "cannot allocate memory for {n} values ({} MiB)",
            (n as u64).saturating_mul(std::mem::size_of::<T>() as u64) >> 20
        )
    })?;
    Ok(v)
}

/// Reads exactly `n` little-endian `f32` from `reader`, in chunks (so the
/// bytes are never held twice). `truncated(got)` builds the error for a
/// stream that ends after `got` bytes.
fn read_f32s(
    path: &Path,
    reader: &mut impl Read,
    n: usize,
    truncated: impl Fn(u64) -> SceneError,
) -> Result<Vec<f32>, SceneError> {
    let mut out: Vec<f32> = try_vec(n).map_err(|r| SceneError::volume(path, r))?;
    let mut buf = vec![0u8; 1 << 16];
    let mut got: u64 = 0;
    while out.len() < n {
        let want = ((n - out.len()) * 4).min(buf.len());
        // `want <= buf.len()`, and `filled < want` inside the loop.
        let chunk = &mut buf[..want];
        let mut filled = 0;
        while filled < want {
            match reader.read(&mut chunk[filled..]) {
                Ok(0) => return Err(truncated(got + filled as u64)),
                Ok(k) => filled += k,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(io_error(path, e)),
            }
        }
        got += want as u64;
        out.extend(
            chunk
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])),
        );
    }
    Ok(out)
}

/// A cursor over the bytes of a fixed-size binary header that reports a
/// short read as "truncated in the header" with the field being read.
struct HeaderBytes<'a> {
    path: &'a Path,
    bytes: &'a [u8],
    /// The whole file's length, for the message.
    file_len: u64,
    pos: usize,
}

impl<'a> HeaderBytes<'a> {
    fn new(path: &'a Path, bytes: &'a [u8], file_len: u64) -> Self {
        Self {
            path,
            bytes,
            file_len,
            pos: 0,
        }
    }

    fn take<const N: usize>(&mut self, what: &str) -> Result<[u8; N], SceneError> {
        let end = self.pos + N;
        let out = self
            .bytes
            .get(self.pos..end)
            .and_then(|s| <[u8; N]>::try_from(s).ok())
            .ok_or_else(|| {
                SceneError::volume(
                    self.path,
                    format!(
                        "file is truncated in the header: it is {} bytes long and ends while \
                         reading the {what} (bytes {}..{end})",
                        self.file_len, self.pos
                    ),
                )
            })?;
        self.pos = end;
        Ok(out)
    }

    fn i32(&mut self, what: &str) -> Result<i32, SceneError> {
        self.take::<4>(what).map(i32::from_le_bytes)
    }

    fn f32(&mut self, what: &str) -> Result<f32, SceneError> {
        self.take::<4>(what).map(f32::from_le_bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    #[test]
    fn auto_format_by_extension() {
        let f = |p: &str| resolve_format(Path::new(p), GridFormat::Auto);
        assert_eq!(f("a/b.vdb").unwrap(), GridFormat::Vdb);
        assert_eq!(f("a/b.VDB").unwrap(), GridFormat::Vdb);
        assert_eq!(f("b.vol").unwrap(), GridFormat::MitsubaVol);
        assert_eq!(f("b.ron").unwrap(), GridFormat::Raw);
        let e = f("clouds/puff.nvdb").unwrap_err().to_string();
        assert!(e.contains("puff.nvdb") && e.contains("'.nvdb'"), "{e}");
        let e = f("clouds/puff").unwrap_err().to_string();
        assert!(e.contains("puff") && e.contains("no extension"), "{e}");
        // An explicit format wins over the extension.
        assert_eq!(
            resolve_format(Path::new("x.bin"), GridFormat::Raw).unwrap(),
            GridFormat::Raw
        );
    }

    #[test]
    fn voxel_count_limits() {
        assert_eq!(voxel_count([2, 3, 4]).unwrap(), 24);
        assert_eq!(voxel_count([512, 512, 512]).unwrap(), 512 * 512 * 512);
        assert_eq!(voxel_count([1024, 1024, 1024]).unwrap(), 1 << 30);
        assert!(voxel_count([0, 3, 4]).unwrap_err().contains("at least 1"));
        assert!(voxel_count([-1, 3, 4]).unwrap_err().contains("at least 1"));
        assert!(voxel_count([1025, 1024, 1024])
            .unwrap_err()
            .contains("too large"));
        // Would overflow u64 without checked arithmetic.
        let big = i64::from(i32::MAX);
        assert!(voxel_count([big, big, big])
            .unwrap_err()
            .contains("too large"));
        assert!(voxel_count([1 << 40, 1, 1])
            .unwrap_err()
            .contains("too large"));
    }

    #[test]
    fn first_bad_voxel_is_located() {
        let dims = UVec3::new(3, 2, 2);
        let mut data = vec![1.0f32; 12];
        assert!(first_bad_voxel(dims, &data).is_none());
        data[11] = f32::NAN; // (2, 1, 1)
        let (ijk, v) = first_bad_voxel(dims, &data).unwrap();
        assert_eq!(ijk, [2, 1, 1]);
        assert!(v.is_nan());
        data[2 + 3] = -2.0; // (2, 1, 0): comes first in x-fastest order
        let (ijk, v) = first_bad_voxel(dims, &data).unwrap();
        assert_eq!(ijk, [2, 1, 0]);
        assert_eq!(v, -2.0);
        let r = bad_voxel_reason(ijk, v);
        assert!(r.contains("(2, 1, 0)") && r.contains("negative"), "{r}");
        assert!(bad_voxel_reason([0, 0, 0], f32::NAN).contains("NaN"));
    }

    #[test]
    fn header_cursor_reports_truncation() {
        let path = PathBuf::from("cut.vol");
        let bytes = [1u8, 0, 0, 0, 2, 0];
        let mut h = HeaderBytes::new(&path, &bytes, 6);
        assert_eq!(h.i32("encoding").unwrap(), 1);
        let e = h.i32("x resolution").unwrap_err().to_string();
        assert!(
            e.contains("cut.vol") && e.contains("truncated") && e.contains("x resolution"),
            "{e}"
        );
    }

    #[test]
    fn read_f32s_chunks_and_truncation() {
        let values: Vec<f32> = (0..40_000).map(|i| i as f32 * 0.5).collect();
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        let path = Path::new("x.raw");
        let got = read_f32s(path, &mut &bytes[..], values.len(), |_| {
            SceneError::volume(path, "short")
        })
        .unwrap();
        assert_eq!(got, values);
        let e = read_f32s(path, &mut &bytes[..100], 30, |n| {
            SceneError::volume(path, format!("truncated after {n}"))
        })
        .unwrap_err();
        assert!(e.to_string().contains("truncated after 100"), "{e}");
    }

    #[test]
    fn grid_name_only_for_vdb() {
        let e = load_grid(Path::new("a.vol"), GridFormat::Auto, Some("density"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("a.vol") && e.contains("OpenVDB"), "{e}");
    }
}
