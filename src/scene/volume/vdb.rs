//! OpenVDB `.vdb` files (the OpenVDB file format, versions 218 and later as
//! written by OpenVDB 3 to 12), read with the `vdb-rs` crate: one float grid
//! (stored as float32 or half), densified over the bounding box of its
//! active voxels and tiles.
//!
//! OpenVDB index coordinates are voxel centres, so the dense grid's world
//! box runs from `transform(index_min − ½)` to `transform(index_max + ½)`;
//! inactive voxels are zero. Only axis-aligned scale + translate transforms
//! (`UniformScaleMap`, `UniformScaleTranslateMap`, `ScaleTranslateMap`) are
//! supported; a negative scale flips that axis.
//!
//! `vdb-rs` trusts its input: byte counts read from the file drive
//! allocations, Blosc's C decompressor is given buffers sized by the file,
//! and malformed data hits `panic!`/`assert!`/`todo!`. An allocation of
//! exabytes or an out-of-bounds read in C would abort the process, which
//! `catch_unwind` cannot stop. So before `vdb-rs` sees the file, [`prescan`]
//! walks the same structure `vdb-rs` will read (archive header, grid
//! descriptors, the chosen grid's metadata, transform, tree topology and
//! leaf buffers), checking every length and offset against the file's size
//! and every Blosc block header against its payload, and every top-level
//! node's origin against the alignment that `vdb-rs`'s `i32` coordinate
//! arithmetic relies on, and reporting truncation with the part of the
//! file that is cut. `vdb-rs` then runs inside `catch_unwind` in case
//! anything was missed.

use std::io::{BufReader, Read, Seek, SeekFrom};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;

use glam::{DVec3, UVec3};
use vdb_rs::{Map, VdbLevel, VdbReader};

use super::{
    bad_voxel_reason, check_bounds, first_bad_voxel, io_error, open, try_vec, voxel_count,
};
use crate::scene::{SceneError, VoxelGrid};

/// `OPENVDB_MAGIC` (0x56444220) written as a little-endian int64.
const MAGIC: [u8; 8] = [0x20, 0x42, 0x44, 0x56, 0, 0, 0, 0];
/// Oldest file version `vdb-rs` reads without hitting a `todo!()`
/// (`OPENVDB_FILE_VERSION_BOOST_UUID`).
const MIN_VERSION: u32 = 218;
/// From this version the header carries a per-file compression flag.
const VERSION_SELECTIVE_COMPRESSION: u32 = 220;
/// From this version compression is per grid and nodes carry a metadata
/// byte describing how inactive values are stored.
const VERSION_NODE_MASK_COMPRESSION: u32 = 222;

/// Compression flags (`openvdb::io::COMPRESS_*`).
const COMPRESS_ZIP: u32 = 0x1;
const COMPRESS_ACTIVE_MASK: u32 = 0x2;
const COMPRESS_BLOSC: u32 = 0x4;

/// The only tree configuration read: a float tree with 32³/16³/8³ nodes.
const FLOAT_TREE: &str = "Tree_float_5_4_3";
/// The same tree saved with half-float values.
const HALF_TREE: &str = "Tree_float_5_4_3_HalfFloat";

/// Voxels along each axis of a top-level (32³ × 16³ × 8³) node. OpenVDB
/// writes a top-level node's origin as a multiple of this; `vdb-rs` adds
/// its children's offsets (up to 31 × 128) to the origin in `i32`, which
/// overflows (a panic) for an origin within 4096 of `i32::MAX` that is not
/// one.
const TOP_NODE_SPAN: i32 = 4096;

/// Reads the float grid `grid_name` of the `.vdb` file at `path` into a
/// dense grid over its active bounding box (inactive voxels are 0).
///
/// Errors (all naming the file): missing or unreadable file; not an OpenVDB
/// file; unsupported version; truncated or corrupt data (naming the part);
/// no grid of that name (listing the grids present); a grid that is not a
/// float grid; a transform that is not an axis-aligned scale + translate;
/// a dense size over [`super::MAX_VOXELS`] voxels or [`super::MAX_BYTES`];
/// a grid without active voxels; non-finite or negative values.
pub fn read_vdb(path: &Path, grid_name: &str) -> Result<VoxelGrid, SceneError> {
    let (file, len) = open(path)?;
    let plan = prescan(path, BufReader::new(file), len, grid_name)?;
    if !plan.half || plan.insertions.is_empty() {
        let (file, _) = open(path)?;
        return contain_panics(path, || read_checked(path, BufReader::new(file), grid_name));
    }
    // A half-float grid with empty value arrays: give vdb-rs a copy of the
    // file with the size fields it expects (see `Plan::insertions`).
    let bytes = std::fs::read(path).map_err(|e| io_error(path, e))?;
    if bytes.len() as u64 != len {
        return Err(SceneError::volume(
            path,
            "the file changed while it was being read",
        ));
    }
    let bytes = plan.patch(bytes).map_err(|r| SceneError::volume(path, r))?;
    contain_panics(path, || {
        read_checked(path, std::io::Cursor::new(bytes), grid_name)
    })
}

/// Runs `f`, turning a panic into a [`SceneError::Volume`] on `path`.
fn contain_panics<T>(
    path: &Path,
    f: impl FnOnce() -> Result<T, SceneError>,
) -> Result<T, SceneError> {
    catch_unwind(AssertUnwindSafe(f)).unwrap_or_else(|panic| {
        let what = panic
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| panic.downcast_ref::<&str>().copied())
            .unwrap_or("unknown failure");
        Err(SceneError::volume(
            path,
            format!("corrupt or unsupported OpenVDB data: the OpenVDB reader failed ({what})"),
        ))
    })
}

/// Reads the grid with `vdb-rs` (after [`prescan`] accepted the file) and
/// densifies it.
fn read_checked<R: Read + Seek>(
    path: &Path,
    stream: R,
    grid_name: &str,
) -> Result<VoxelGrid, SceneError> {
    let bad = |reason: String| SceneError::volume(path, reason);
    let corrupt = |e: vdb_rs::ParseError| {
        let what = match e {
            vdb_rs::ParseError::IoError(io) => format!("read error: {io}"),
            other => other.to_string(),
        };
        bad(format!(
            "corrupt or unsupported OpenVDB data in grid {grid_name:?}: {what}"
        ))
    };
    let mut reader = VdbReader::new(stream).map_err(corrupt)?;
    let grid = reader.read_grid::<f32>(grid_name).map_err(corrupt)?;

    let (scale, translation) = match &grid.transform {
        Map::ScaleTranslateMap {
            scale_values,
            translation,
            ..
        } => (
            DVec3::new(scale_values.x, scale_values.y, scale_values.z),
            DVec3::new(translation.x, translation.y, translation.z),
        ),
        Map::UniformScaleMap { scale_values, .. } => (
            DVec3::new(scale_values.x, scale_values.y, scale_values.z),
            DVec3::ZERO,
        ),
    };
    if !(scale.is_finite() && translation.is_finite() && scale.cmpne(DVec3::ZERO).all()) {
        return Err(bad(format!(
            "grid {grid_name:?}: transform scale {:?} / translation {:?} must be finite with a \
             non-zero scale on every axis",
            scale.to_array(),
            translation.to_array()
        )));
    }

    // First pass: the index-space box of everything active. Coordinates are
    // exact integers (stored as f32 by vdb-rs).
    let mut lo = [i64::MAX; 3];
    let mut hi = [i64::MIN; 3];
    for (pos, _, level) in grid.iter() {
        let p = [pos.x as i64, pos.y as i64, pos.z as i64];
        let e = level_extent(level);
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a] + e - 1);
        }
    }
    if lo[0] > hi[0] {
        return Err(bad(format!(
            "grid {grid_name:?} has no active voxels: nothing to load"
        )));
    }
    let size = [0, 1, 2].map(|a| hi[a].saturating_sub(lo[a]).saturating_add(1));
    let n = voxel_count(size).map_err(|r| {
        bad(format!(
            "grid {grid_name:?}: the active bounding box [{:?}, {:?}] densifies to {r}",
            lo, hi
        ))
    })?;
    let dims = UVec3::new(size[0] as u32, size[1] as u32, size[2] as u32);
    let flip = [scale.x < 0.0, scale.y < 0.0, scale.z < 0.0];

    // Second pass: fill. An axis with a negative scale is stored reversed,
    // so that x (y, z) increases with the dense index.
    let mut data: Vec<f32> = try_vec(n).map_err(&bad)?;
    data.resize(n, 0.0);
    let (nx, ny) = (size[0], size[1]);
    for (pos, value, level) in grid.iter() {
        let p = [pos.x as i64, pos.y as i64, pos.z as i64];
        let e = level_extent(level);
        let range = |a: usize| {
            let (a0, a1) = (p[a] - lo[a], p[a] - lo[a] + e - 1);
            if flip[a] {
                (size[a] - 1 - a1, size[a] - 1 - a0)
            } else {
                (a0, a1)
            }
        };
        let ((i0, i1), (j0, j1), (k0, k1)) = (range(0), range(1), range(2));
        for k in k0..=k1 {
            for j in j0..=j1 {
                let row = nx * (j + ny * k);
                let cells = usize::try_from(row + i0)
                    .ok()
                    .zip(usize::try_from(row + i1).ok())
                    .and_then(|(a, b)| data.get_mut(a..=b))
                    .ok_or_else(|| bad("internal error: voxel outside the dense grid".into()))?;
                cells.fill(value);
            }
        }
    }
    if let Some((ijk, v)) = first_bad_voxel(dims, &data) {
        let index = [0, 1, 2].map(|a| {
            let d = ijk[a] as i64;
            if flip[a] {
                hi[a] - d
            } else {
                lo[a] + d
            }
        });
        return Err(bad(format!(
            "grid {grid_name:?}: {} (OpenVDB index coordinate {index:?})",
            bad_voxel_reason(ijk, v)
        )));
    }

    let world = |idx: [f64; 3]| DVec3::from_array(idx) * scale + translation;
    let a = world([0, 1, 2].map(|a| lo[a] as f64 - 0.5));
    let b = world([0, 1, 2].map(|a| hi[a] as f64 + 0.5));
    let (bounds_min, bounds_max) = (a.min(b).as_vec3(), a.max(b).as_vec3());
    check_bounds(bounds_min, bounds_max).map_err(|r| bad(format!("grid {grid_name:?}: {r}")))?;
    Ok(VoxelGrid {
        dims,
        bounds_min,
        bounds_max,
        data,
    })
}

/// Voxels along each axis covered by an item at `level`.
fn level_extent(level: VdbLevel) -> i64 {
    match level {
        VdbLevel::Voxel => 1,
        VdbLevel::Node3 => 8,
        VdbLevel::Node4 => 128,
    }
}

// ---------------------------------------------------------------------------
// Prescan: the structure vdb-rs reads, with every size checked.

/// A reader that knows the file's length and what it is reading, so that a
/// short file is reported as "truncated in <part>".
struct Scan<'a, R> {
    r: R,
    path: &'a Path,
    pos: u64,
    len: u64,
    /// The part of the file being read, for messages.
    part: String,
    /// See [`Plan::insertions`].
    insertions: Vec<u64>,
    /// See [`Plan::offset_fields`].
    offset_fields: Vec<u64>,
}

impl<R: Read + Seek> Scan<'_, R> {
    fn err(&self, reason: String) -> SceneError {
        SceneError::volume(self.path, format!("in the {}: {reason}", self.part))
    }

    fn truncated(&self, n: u64, what: &str) -> SceneError {
        SceneError::volume(
            self.path,
            format!(
                "file is truncated in the {}: reading {what} needs {n} bytes at offset {}, \
                 but the file ends at {}",
                self.part, self.pos, self.len
            ),
        )
    }

    /// Fails unless `n` more bytes are present.
    fn need(&self, n: u64, what: &str) -> Result<(), SceneError> {
        if self.len.saturating_sub(self.pos) < n {
            Err(self.truncated(n, what))
        } else {
            Ok(())
        }
    }

    fn bytes<const N: usize>(&mut self, what: &str) -> Result<[u8; N], SceneError> {
        self.need(N as u64, what)?;
        let mut b = [0u8; N];
        self.r.read_exact(&mut b).map_err(|e| {
            if e.kind() == std::io::ErrorKind::UnexpectedEof {
                self.truncated(N as u64, what)
            } else {
                io_error(self.path, e)
            }
        })?;
        self.pos += N as u64;
        Ok(b)
    }

    fn u8(&mut self, what: &str) -> Result<u8, SceneError> {
        self.bytes::<1>(what).map(|[b]| b)
    }

    fn u32(&mut self, what: &str) -> Result<u32, SceneError> {
        self.bytes::<4>(what).map(u32::from_le_bytes)
    }

    fn u64(&mut self, what: &str) -> Result<u64, SceneError> {
        self.bytes::<8>(what).map(u64::from_le_bytes)
    }

    fn i32(&mut self, what: &str) -> Result<i32, SceneError> {
        self.bytes::<4>(what).map(i32::from_le_bytes)
    }

    fn i64(&mut self, what: &str) -> Result<i64, SceneError> {
        self.bytes::<8>(what).map(i64::from_le_bytes)
    }

    fn skip(&mut self, n: u64, what: &str) -> Result<(), SceneError> {
        self.need(n, what)?;
        // `need` bounds n by the file's length, far below i64::MAX.
        let step = i64::try_from(n).map_err(|_| self.truncated(n, what))?;
        // A relative seek keeps a BufReader's buffer.
        self.r
            .seek_relative(step)
            .map_err(|e| io_error(self.path, e))?;
        self.pos += n;
        Ok(())
    }

    fn seek_to(&mut self, to: u64, what: &str) -> Result<(), SceneError> {
        if to > self.len {
            return Err(SceneError::volume(
                self.path,
                format!(
                    "file is truncated or corrupt in the {}: {what} is at offset {to}, past the \
                     end of the file ({} bytes)",
                    self.part, self.len
                ),
            ));
        }
        self.r
            .seek(SeekFrom::Start(to))
            .map_err(|e| io_error(self.path, e))?;
        self.pos = to;
        Ok(())
    }

    /// A length-prefixed string, as vdb-rs decodes it (one char per byte).
    fn string(&mut self, what: &str) -> Result<String, SceneError> {
        let n = self.u32(&format!("the length of {what}"))?;
        self.need(u64::from(n), what)?;
        let mut out = String::new();
        let mut left = u64::from(n);
        let mut buf = [0u8; 256];
        while left > 0 {
            let k = left.min(buf.len() as u64) as usize;
            let chunk = &mut buf[..k];
            self.r.read_exact(chunk).map_err(|e| {
                if e.kind() == std::io::ErrorKind::UnexpectedEof {
                    self.truncated(left, what)
                } else {
                    io_error(self.path, e)
                }
            })?;
            out.extend(chunk.iter().map(|&b| b as char));
            self.pos += k as u64;
            left -= k as u64;
        }
        Ok(out)
    }

    /// A node mask of `bits` bits, as little-endian 64-bit words.
    fn mask(&mut self, bits: usize, what: &str) -> Result<Vec<u64>, SceneError> {
        let words = bits.div_ceil(64);
        self.need(words as u64 * 8, what)?;
        (0..words).map(|_| self.u64(what)).collect()
    }

    /// A metadata table; returns whether it marks the grid as saved as half
    /// float (the last `is_saved_as_half_float` entry being a true bool, as
    /// vdb-rs decides).
    fn metadata(&mut self) -> Result<bool, SceneError> {
        let count = self.u32("the metadata count")?;
        let mut half = false;
        for m in 0..count {
            let name = self.string(&format!("the name of metadata entry {m}"))?;
            let ty = self.string(&format!("the type of metadata {name:?}"))?;
            let len = self.u32(&format!("the size of metadata {name:?}"))?;
            let what = format!("the value of metadata {name:?}");
            // vdb-rs reads the known types by their own size, whatever the
            // stored size says, and skips the others.
            let is_half = match ty.as_str() {
                "string" => {
                    self.skip(u64::from(len), &what)?;
                    false
                }
                "bool" => self.u8(&what)? != 0,
                "int32" | "float" => {
                    self.skip(4, &what)?;
                    false
                }
                "int64" => {
                    self.skip(8, &what)?;
                    false
                }
                "vec3i" => {
                    self.skip(12, &what)?;
                    false
                }
                _ => {
                    self.skip(u64::from(len), &what)?;
                    false
                }
            };
            if name == "is_saved_as_half_float" {
                half = is_half;
            }
        }
        Ok(half)
    }
}

/// What [`prescan`] found: how to present the file to `vdb-rs`.
#[derive(Debug, Default)]
struct Plan {
    /// Whether the grid's values are stored as half floats.
    half: bool,
    /// Offsets (ascending) where OpenVDB wrote an empty half-float value
    /// array as nothing at all while `vdb-rs` reads an 8-byte size field
    /// there (vdb-rs 0.6 misreads such files). An 8-byte zero, which vdb-rs
    /// reads as "0 bytes follow", is inserted at each.
    insertions: Vec<u64>,
    /// Offsets of the 64-bit file positions stored in the grid descriptors,
    /// which move when bytes are inserted.
    offset_fields: Vec<u64>,
}

impl Plan {
    /// Where byte `p` of the original file lands after the insertions. An
    /// insertion at `p` itself comes before it: a grid that ends with an
    /// empty array has its end offset at the insertion point.
    fn shifted(&self, p: u64) -> u64 {
        p + 8 * self.insertions.partition_point(|&i| i <= p) as u64
    }

    /// The file with the insertions made and the descriptor offsets fixed.
    fn patch(&self, mut bytes: Vec<u8>) -> Result<Vec<u8>, String> {
        let corrupt = || "internal error: OpenVDB patch offset outside the file".to_owned();
        for &f in &self.offset_fields {
            let at = usize::try_from(f).map_err(|_| corrupt())?;
            let field = bytes.get_mut(at..at + 8).ok_or_else(corrupt)?;
            let mut v = [0u8; 8];
            v.copy_from_slice(field);
            field.copy_from_slice(&self.shifted(u64::from_le_bytes(v)).to_le_bytes());
        }
        let mut out = try_vec(bytes.len() + 8 * self.insertions.len())?;
        let mut last = 0usize;
        for &i in &self.insertions {
            let i = usize::try_from(i).map_err(|_| corrupt())?;
            out.extend_from_slice(bytes.get(last..i).ok_or_else(corrupt)?);
            out.extend_from_slice(&[0u8; 8]);
            last = i;
        }
        out.extend_from_slice(bytes.get(last..).ok_or_else(corrupt)?);
        Ok(out)
    }
}

/// One grid descriptor of the archive.
struct Descriptor {
    name: String,
    grid_type: String,
    instance_parent: String,
    grid_pos: u64,
    block_pos: u64,
    compression: u32,
    half: bool,
}

/// How a grid's node values are stored.
struct Layout {
    version: u32,
    compression: u32,
    /// Bytes per stored value: 2 for half floats, else 4.
    value_bytes: u64,
}

/// Walks everything `vdb-rs` will read for grid `grid_name`, checking each
/// size and offset. Returns how to present the file to `vdb-rs`, or an
/// error naming the file, the part and the problem.
fn prescan<R: Read + Seek>(
    path: &Path,
    r: R,
    len: u64,
    grid_name: &str,
) -> Result<Plan, SceneError> {
    let mut s = Scan {
        r,
        path,
        pos: 0,
        len,
        part: "archive header".into(),
        insertions: Vec::new(),
        offset_fields: Vec::new(),
    };
    let magic = s.bytes::<8>("the magic number")?;
    if magic != MAGIC {
        return Err(s.err(format!(
            "not an OpenVDB file: bad magic number {magic:02x?} (expected {MAGIC:02x?})"
        )));
    }
    let version = s.u32("the file format version")?;
    if version < MIN_VERSION {
        return Err(s.err(format!(
            "OpenVDB file format version {version} is not supported (need {MIN_VERSION} or \
             later, i.e. files from OpenVDB 3 on)"
        )));
    }
    s.skip(8, "the library version")?;
    if s.u8("the grid-offsets flag")? != 1 {
        return Err(s.err(
            "the file has no grid offsets (written without random access), which the reader \
             does not support"
                .into(),
        ));
    }
    // Archive-wide compression, used by files before per-grid compression.
    let mut archive_compression = if version < 223 {
        COMPRESS_ZIP | COMPRESS_ACTIVE_MASK
    } else {
        COMPRESS_BLOSC | COMPRESS_ACTIVE_MASK
    };
    if (VERSION_SELECTIVE_COMPRESSION..VERSION_NODE_MASK_COMPRESSION).contains(&version) {
        archive_compression = if s.u8("the compression flag")? == 1 {
            COMPRESS_ZIP
        } else {
            0
        };
    }
    s.skip(36, "the file UUID")?;
    s.part = "file metadata".into();
    s.metadata()?;
    s.part = "archive header".into();
    let grid_count = s.u32("the grid count")?;

    // Grid descriptors: vdb-rs reads all of them.
    let mut grids: Vec<Descriptor> = Vec::new();
    for g in 0..grid_count {
        s.part = format!("descriptor of grid {g}");
        let name = s.string("the grid name")?;
        s.part = format!("descriptor of grid {name:?}");
        let grid_type = s.string("the grid type")?;
        let instance_parent = s.string("the instance parent")?;
        s.offset_fields.extend([s.pos, s.pos + 8, s.pos + 16]);
        let grid_pos = s.u64("the grid offset")?;
        let block_pos = s.u64("the data-block offset")?;
        let end_pos = s.u64("the end offset")?;
        s.seek_to(grid_pos, "the grid")?;
        let compression = if version >= VERSION_NODE_MASK_COMPRESSION {
            let c = s.u32("the compression flags")?;
            check_compression(&s, c)?;
            c
        } else {
            archive_compression
        };
        s.part = format!("metadata of grid {name:?}");
        let half = s.metadata()?;
        s.part = format!("descriptor of grid {name:?}");
        if grids.iter().any(|d| d.name == name) {
            return Err(s.err(format!("a second grid is named {name:?} (corrupt data)")));
        }
        s.seek_to(end_pos, "the next grid descriptor")?;
        grids.push(Descriptor {
            name,
            grid_type,
            instance_parent,
            grid_pos,
            block_pos,
            compression,
            half,
        });
    }

    let Some(d) = grids.iter().find(|d| d.name == grid_name) else {
        let present: Vec<String> = grids
            .iter()
            .map(|d| format!("{:?} ({})", d.name, d.grid_type))
            .collect();
        let present = if present.is_empty() {
            "none".to_owned()
        } else {
            present.join(", ")
        };
        return Err(SceneError::volume(
            path,
            format!("no grid named {grid_name:?} (grid not found); grids present: {present}"),
        ));
    };
    let quoted = format!("{grid_name:?}");
    if d.grid_type != FLOAT_TREE && d.grid_type != HALF_TREE {
        return Err(SceneError::volume(
            path,
            format!(
                "grid {quoted} has type {}, but only float grids ({FLOAT_TREE}, or \
                 {HALF_TREE}) can be read as a density",
                d.grid_type
            ),
        ));
    }
    if (d.grid_type == HALF_TREE) != d.half {
        return Err(SceneError::volume(
            path,
            format!(
                "grid {quoted} has type {} but its is_saved_as_half_float metadata says {}: \
                 corrupt or inconsistent grid",
                d.grid_type, d.half
            ),
        ));
    }
    if !d.instance_parent.is_empty() {
        return Err(SceneError::volume(
            path,
            format!(
                "grid {quoted} is an instance sharing the tree of grid {:?}; instanced grids \
                 are not supported (read {:?} instead)",
                d.instance_parent, d.instance_parent
            ),
        ));
    }
    let layout = Layout {
        version,
        compression: d.compression,
        value_bytes: if d.half { 2 } else { 4 },
    };

    // The grid itself: compression, metadata (again), transform, topology.
    s.part = format!("header of grid {quoted}");
    s.seek_to(d.grid_pos, "the grid")?;
    if version >= VERSION_NODE_MASK_COMPRESSION {
        let c = s.u32("the compression flags")?;
        check_compression(&s, c)?;
    }
    s.metadata()?;
    s.part = format!("transform of grid {quoted}");
    let map = s.string("the transform type")?;
    let doubles = match map.as_str() {
        "UniformScaleMap" => 15,
        "UniformScaleTranslateMap" | "ScaleTranslateMap" => 18,
        "AffineMap" | "UnitaryMap" | "NonlinearFrustumMap" => {
            return Err(s.err(format!(
                "the transform is a {map}, which is not an axis-aligned scale + translate map: \
                 only UniformScaleMap, UniformScaleTranslateMap and ScaleTranslateMap are \
                 supported (resample the grid to an axis-aligned transform)"
            )))
        }
        other => {
            return Err(s.err(format!(
                "unsupported transform type {other:?}: only the axis-aligned scale + translate \
                 maps UniformScaleMap, UniformScaleTranslateMap and ScaleTranslateMap are \
                 supported"
            )))
        }
    };
    s.skip(doubles * 8, "the transform's values")?;

    s.part = format!("tree topology of grid {quoted}");
    let buffers = s.u32("the buffer count")?;
    if buffers != 1 {
        return Err(s.err(format!(
            "{buffers} buffers per leaf: only single-buffer trees are supported (corrupt or unsupported data)"
        )));
    }
    s.skip(4, "the background value")?;
    let tiles = s.u32("the root tile count")?;
    let roots = s.u32("the root child count")?;
    s.need(u64::from(tiles) * 17, "the root tiles")?;
    for _ in 0..tiles {
        s.skip(16, "a root tile")?;
        if s.u8("a root tile's active flag")? != 0 {
            return Err(s.err(
                "an active root-level tile covers 4096³ voxels, beyond the 1024³ limit of a \
                 dense grid"
                    .into(),
            ));
        }
    }
    let mut leaves: u64 = 0;
    for root in 0..roots {
        s.part = format!("tree topology of grid {quoted} (top-level node {root})");
        let what = "the node origin";
        let origin = [s.i32(what)?, s.i32(what)?, s.i32(what)?];
        if origin.iter().any(|&c| c & (TOP_NODE_SPAN - 1) != 0) {
            return Err(s.err(format!(
                "the node origin {origin:?} is not a multiple of {TOP_NODE_SPAN} on every axis \
                 (corrupt data)"
            )));
        }
        let children = internal_node(&mut s, &layout, 5)?;
        for _ in children {
            let grandchildren = internal_node(&mut s, &layout, 4)?;
            for _ in grandchildren {
                s.skip(64, "a leaf's value mask")?;
                leaves += 1;
            }
        }
    }

    s.part = format!("voxel data of grid {quoted}");
    s.seek_to(d.block_pos, "the voxel data")?;
    for leaf in 0..leaves {
        s.part = format!("voxel data of grid {quoted} (leaf {leaf} of {leaves})");
        let mask = s.mask(512, "a leaf's value mask")?;
        if version < VERSION_NODE_MASK_COMPRESSION {
            s.skip(12, "a leaf's origin")?;
            let n = s.u8("a leaf's buffer count")?;
            if n != 1 {
                return Err(s.err(format!(
                    "a leaf has {n} buffers; only 1 is supported (corrupt or unsupported data)"
                )));
            }
        }
        values(&mut s, &layout, 512, &mask)?;
    }
    Ok(Plan {
        half: d.half,
        insertions: s.insertions,
        offset_fields: s.offset_fields,
    })
}

fn check_compression<R: Read + Seek>(s: &Scan<'_, R>, c: u32) -> Result<(), SceneError> {
    if c & !(COMPRESS_ZIP | COMPRESS_ACTIVE_MASK | COMPRESS_BLOSC) != 0 {
        Err(s.err(format!("invalid compression flags {c:#x} (corrupt data)")))
    } else {
        Ok(())
    }
}

/// Reads an internal node header (child mask, value mask, tile values) of
/// `1 << (3 log2)` entries; returns the indices of its children.
fn internal_node<R: Read + Seek>(
    s: &mut Scan<'_, R>,
    layout: &Layout,
    log2: u32,
) -> Result<Vec<usize>, SceneError> {
    let entries = 1usize << (3 * log2);
    let child = s.mask(entries, "a node's child mask")?;
    let value = s.mask(entries, "a node's value mask")?;
    let ones: usize = child.iter().map(|w| w.count_ones() as usize).sum();
    let tiles = if layout.version < VERSION_NODE_MASK_COMPRESSION {
        entries - ones
    } else {
        entries
    };
    values(s, layout, tiles, &value)?;
    Ok((0..entries)
        .filter(|&i| child.get(i / 64).is_some_and(|w| w >> (i % 64) & 1 == 1))
        .collect())
}

/// Reads one compressed value array of `count` entries whose active mask is
/// `mask` (OpenVDB's `readCompressedValues`, as vdb-rs implements it).
fn values<R: Read + Seek>(
    s: &mut Scan<'_, R>,
    layout: &Layout,
    count: usize,
    mask: &[u64],
) -> Result<(), SceneError> {
    // Node metadata: how inactive values are stored.
    let meta = if layout.version >= VERSION_NODE_MASK_COMPRESSION {
        let m = s.u8("a node's value-compression byte")?;
        if m > 6 {
            return Err(s.err(format!(
                "invalid node value-compression byte {m} (corrupt data)"
            )));
        }
        m
    } else {
        6
    };
    if matches!(meta, 2 | 4 | 5) {
        s.skip(4, "an inactive value")?;
    }
    if meta == 5 {
        s.skip(4, "a second inactive value")?;
    }
    if matches!(meta, 3..=5) {
        s.skip(count.div_ceil(64) as u64 * 8, "a selection mask")?;
    }
    let stored = if layout.compression & COMPRESS_ACTIVE_MASK != 0
        && meta != 6
        && layout.version >= VERSION_NODE_MASK_COMPRESSION
    {
        mask.iter().map(|w| w.count_ones() as u64).sum()
    } else {
        count as u64
    };
    let want = stored * layout.value_bytes;
    if layout.value_bytes == 2 && stored == 0 {
        // OpenVDB's HalfWriter writes nothing at all for an empty array
        // (not even a size field), where vdb-rs reads one.
        if layout.compression & (COMPRESS_BLOSC | COMPRESS_ZIP) != 0 {
            s.insertions.push(s.pos);
        }
        return Ok(());
    }

    if layout.compression & (COMPRESS_BLOSC | COMPRESS_ZIP) != 0 {
        let blosc = layout.compression & COMPRESS_BLOSC != 0;
        let codec = if blosc { "Blosc" } else { "zip" };
        let n = s.i64(&format!("the size of a {codec} block"))?;
        if n <= 0 {
            // Stored uncompressed: -n bytes follow.
            let raw = n.unsigned_abs();
            if raw != want {
                return Err(s.err(format!(
                    "an uncompressed value block holds {raw} bytes but {want} are expected \
                     (corrupt data)"
                )));
            }
            return s.skip(raw, "an uncompressed value block");
        }
        let n = n.unsigned_abs();
        s.need(n, &format!("a {codec} block of {n} bytes"))?;
        if blosc && stored > 0 {
            if n < 16 {
                return Err(s.err(format!(
                    "a Blosc block of {n} bytes is shorter than its 16-byte header (corrupt data)"
                )));
            }
            let h = s.bytes::<16>("a Blosc block header")?;
            let nbytes = u64::from(u32::from_le_bytes([h[4], h[5], h[6], h[7]]));
            let cbytes = u64::from(u32::from_le_bytes([h[12], h[13], h[14], h[15]]));
            if nbytes != want || cbytes < 16 || cbytes > n {
                return Err(s.err(format!(
                    "a Blosc block header says {nbytes} bytes compressed into {cbytes}, but the \
                     block holds {n} bytes for {want} bytes of values (corrupt data)"
                )));
            }
            return s.skip(n - 16, "a Blosc block");
        }
        return s.skip(n, &format!("a {codec} block"));
    }
    s.skip(want, "an uncompressed value block")
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Cursor;
    use std::path::PathBuf;

    fn fixture(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data/volumes")
            .join(name)
    }

    fn scan(bytes: &[u8], grid: &str) -> Result<Plan, String> {
        prescan(
            Path::new("mem.vdb"),
            Cursor::new(bytes),
            bytes.len() as u64,
            grid,
        )
        .map_err(|e| e.to_string())
    }

    #[test]
    fn panics_are_contained() {
        let r: Result<(), _> = contain_panics(Path::new("boom.vdb"), || panic!("index 7 of 3"));
        let e = r.unwrap_err().to_string();
        assert!(e.contains("boom.vdb") && e.contains("index 7 of 3"), "{e}");
        let r: Result<(), _> =
            contain_panics(Path::new("boom.vdb"), || std::panic::panic_any(42u8));
        assert!(r.unwrap_err().to_string().contains("unknown failure"));
    }

    #[test]
    fn prescan_accepts_fixtures() {
        let full = std::fs::read(fixture("cloud.vdb")).unwrap();
        let p = scan(&full, "density").unwrap();
        assert!(!p.half && p.insertions.is_empty());
        assert_eq!(p.offset_fields.len(), 9); // three grids
        assert!(!scan(&full, "temperature").unwrap().half);
        let half = std::fs::read(fixture("cloud_half.vdb")).unwrap();
        let p = scan(&half, "density").unwrap();
        assert!(p.half);
        // Internal nodes without active tiles store nothing in half files.
        assert!(!p.insertions.is_empty());
    }

    #[test]
    fn unaligned_top_level_origin_is_refused() {
        // fuzz_vdb_half: the x of the first top-level node's origin (bytes
        // 816..820, -4096) set to i32::MAX made vdb-rs overflow adding a
        // child's offset to it.
        let half = std::fs::read(fixture("cloud_half.vdb")).unwrap();
        assert_eq!(half[816..820], (-4096i32).to_le_bytes());
        let with_x = |x: i32| {
            let mut b = half.clone();
            b[816..820].copy_from_slice(&x.to_le_bytes());
            scan(&b, "density")
        };
        for x in [i32::MAX, 1, -4095] {
            let e = with_x(x).unwrap_err();
            assert!(
                e.contains("top-level node 0") && e.contains("origin") && e.contains("corrupt"),
                "x = {x}: {e}"
            );
        }
        // Aligned origins pass, the extremes included (their children's
        // coordinates still fit in i32).
        for x in [i32::MIN, i32::MAX - (TOP_NODE_SPAN - 1), 4096] {
            assert!(with_x(x).is_ok(), "x = {x}");
        }
    }

    #[test]
    fn every_prefix_is_truncated() {
        // The density grid is the file's only grid, so any cut removes
        // something the reader needs.
        let full = std::fs::read(fixture("cloud_half.vdb")).unwrap();
        for cut in (0..full.len()).step_by(41) {
            let e = scan(&full[..cut], "density").unwrap_err();
            assert!(e.contains("truncated"), "cut at {cut}: {e}");
        }
    }

    #[test]
    fn bad_blosc_header_is_caught_before_decompression() {
        let mut full = std::fs::read(fixture("cloud.vdb")).unwrap();
        // Find the first Blosc block of the leaf data: its header's nbytes
        // field follows the 8-byte size. Patch every occurrence of the
        // 2048-byte (512 × f32) nbytes field to a huge value.
        let needle = 2048u32.to_le_bytes();
        let mut patched = 0;
        for i in 0..full.len() - 16 {
            if full[i + 12..i + 16] == needle && full[i + 8] == 2 {
                full[i + 12..i + 16].copy_from_slice(&u32::MAX.to_le_bytes());
                patched += 1;
            }
        }
        assert!(patched > 0, "no Blosc headers found");
        let e = scan(&full, "density").unwrap_err();
        assert!(e.contains("Blosc") && e.contains("corrupt"), "{e}");
    }
}
