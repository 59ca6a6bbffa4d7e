//! Mitsuba 3's binary `.vol` grid format (the layout read by Mitsuba's
//! `gridvolume` plugin, `VolumeGrid`), single-channel float32 only.
//!
//! Layout, all little-endian:
//!
//! | bytes | content |
//! | --- | --- |
//! | 0..3 | the characters `V`, `O`, `L` |
//! | 3 | file format version, 3 |
//! | 4..8 | `i32` encoding: 1 = float32 (the only one supported here) |
//! | 8..20 | `i32` x, y, z resolution |
//! | 20..24 | `i32` channel count (1 for a density grid) |
//! | 24..48 | six `f32`: bounding box xmin, ymin, zmin, xmax, ymax, zmax |
//! | 48.. | `xres·yres·zres·channels` float32 voxels, x fastest |
//!
//! The grid's world bounds are the file's bounding box.

use std::io::{Read, Write};
use std::path::Path;

use glam::{UVec3, Vec3};

use super::{
    bad_voxel_reason, check_bounds, first_bad_voxel, open, read_f32s, voxel_count, HeaderBytes,
};
use crate::scene::{SceneError, VoxelGrid};

/// Header size in bytes: magic (3) + version (1) + 5 × i32 + 6 × f32.
const HEADER_BYTES: usize = 48;

/// The only `.vol` version that exists in Mitsuba 0.6 and 3.
const VERSION: u8 = 3;

/// Encoding number of float32 data.
const ENCODING_F32: i32 = 1;

/// Reads a single-channel float32 `.vol` file; bounds come from its bounding
/// box. Every field is validated (see the module documentation for the
/// layout); errors name the file.
pub fn read_mitsuba_vol(path: &Path) -> Result<VoxelGrid, SceneError> {
    let (file, file_len) = open(path)?;
    let mut file = std::io::BufReader::new(file);
    let bad = |reason: String| SceneError::volume(path, reason);

    // The header: as much of it as the file has.
    let mut head = Vec::with_capacity(HEADER_BYTES);
    (&mut file)
        .take(HEADER_BYTES as u64)
        .read_to_end(&mut head)
        .map_err(|e| super::io_error(path, e))?;
    let mut h = HeaderBytes::new(path, &head, file_len);

    let magic = h.take::<3>("magic bytes 'VOL'")?;
    if &magic != b"VOL" {
        return Err(bad(format!(
            "not a Mitsuba .vol file: bad magic bytes {:?} (expected \"VOL\")",
            String::from_utf8_lossy(&magic)
        )));
    }
    let [version] = h.take::<1>("version byte")?;
    if version != VERSION {
        return Err(bad(format!(
            "unsupported .vol version {version} (only version {VERSION} exists)"
        )));
    }
    let encoding = h.i32("encoding")?;
    if encoding != ENCODING_F32 {
        let name = match encoding {
            2 => " (float16)",
            3 => " (uint8)",
            4 => " (quantized)",
            _ => "",
        };
        return Err(bad(format!(
            "unsupported encoding {encoding}{name}: only encoding 1 (float32) is supported"
        )));
    }
    let xres = h.i32("x resolution")?;
    let yres = h.i32("y resolution")?;
    let zres = h.i32("z resolution")?;
    let channels = h.i32("channel count")?;
    let mut bbox = [0.0f32; 6];
    for (v, what) in bbox.iter_mut().zip([
        "bounding box xmin",
        "bounding box ymin",
        "bounding box zmin",
        "bounding box xmax",
        "bounding box ymax",
        "bounding box zmax",
    ]) {
        *v = h.f32(what)?;
    }

    if channels != 1 {
        return Err(bad(format!(
            "has {channels} channels, but a density grid needs exactly 1 channel \
             (multi-channel .vol files, e.g. RGB albedo, are not supported)"
        )));
    }
    let n = voxel_count([xres, yres, zres].map(i64::from)).map_err(bad)?;
    let lo = Vec3::new(bbox[0], bbox[1], bbox[2]);
    let hi = Vec3::new(bbox[3], bbox[4], bbox[5]);
    check_bounds(lo, hi).map_err(|r| bad(format!("bounding box: {r}")))?;

    // n ≤ 2³⁰, so this cannot overflow; checked anyway.
    let data_bytes = (n as u64)
        .checked_mul(4)
        .ok_or_else(|| bad("grid size overflows".into()))?;
    let have = file_len.saturating_sub(HEADER_BYTES as u64);
    let dims_txt = format!("{xres}×{yres}×{zres}");
    if have < data_bytes {
        return Err(bad(format!(
            "file is truncated in the voxel data: {dims_txt} float32 voxels need {data_bytes} \
             bytes after the {HEADER_BYTES}-byte header, but only {have} are present"
        )));
    }
    if have > data_bytes {
        return Err(bad(format!(
            "{} unexpected trailing bytes after the {dims_txt} float32 voxels: the header and \
             the data disagree",
            have - data_bytes
        )));
    }
    let data = read_f32s(path, &mut file, n, |got| {
        bad(format!(
            "file is truncated in the voxel data: it ended after {got} of {data_bytes} bytes \
             while being read"
        ))
    })?;

    let dims = UVec3::new(xres as u32, yres as u32, zres as u32);
    if let Some((ijk, v)) = first_bad_voxel(dims, &data) {
        return Err(bad(bad_voxel_reason(ijk, v)));
    }
    Ok(VoxelGrid {
        dims,
        bounds_min: lo,
        bounds_max: hi,
        data,
    })
}

/// Writes `grid` as a single-channel float32 `.vol` file (version 3), with
/// the grid's bounds as the file's bounding box. Refuses a grid whose data
/// length does not match its dimensions or whose dimensions do not fit the
/// format's `i32` fields.
pub fn write_mitsuba_vol(path: &Path, grid: &VoxelGrid) -> Result<(), SceneError> {
    let write_err = |reason: String| SceneError::Write {
        path: path.to_owned(),
        reason,
    };
    let d = grid.dims;
    let dims = [d.x, d.y, d.z].map(i32::try_from);
    let [Ok(x), Ok(y), Ok(z)] = dims else {
        return Err(write_err(format!(
            "dimensions {}×{}×{} do not fit the .vol format's 32-bit fields",
            d.x, d.y, d.z
        )));
    };
    let n = (d.x as u64)
        .checked_mul(d.y as u64)
        .and_then(|n| n.checked_mul(d.z as u64));
    if n != Some(grid.data.len() as u64) || grid.data.is_empty() {
        return Err(write_err(format!(
            "the grid has {} values for {}×{}×{} dimensions",
            grid.data.len(),
            d.x,
            d.y,
            d.z
        )));
    }
    crate::atomic::write_atomically(path, |out| -> std::io::Result<()> {
        out.write_all(b"VOL")?;
        out.write_all(&[VERSION])?;
        for v in [ENCODING_F32, x, y, z, 1] {
            out.write_all(&v.to_le_bytes())?;
        }
        for v in grid
            .bounds_min
            .to_array()
            .into_iter()
            .chain(grid.bounds_max.to_array())
        {
            out.write_all(&v.to_le_bytes())?;
        }
        for v in &grid.data {
            out.write_all(&v.to_le_bytes())?;
        }
        Ok(())
    })
    .map_err(SceneError::from)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A valid `.vol` image: header then `data`.
    fn vol_bytes(enc: i32, dims: [i32; 3], ch: i32, bbox: [f32; 6], data: &[f32]) -> Vec<u8> {
        let mut b = b"VOL\x03".to_vec();
        for v in [enc, dims[0], dims[1], dims[2], ch] {
            b.extend(v.to_le_bytes());
        }
        for v in bbox.iter().chain(data) {
            b.extend(v.to_le_bytes());
        }
        b
    }

    const BOX: [f32; 6] = [-1.0, -2.0, -3.0, 1.0, 2.0, 3.0];

    fn load(bytes: &[u8]) -> Result<VoxelGrid, String> {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("unit.vol");
        std::fs::write(&p, bytes).unwrap();
        read_mitsuba_vol(&p).map_err(|e| e.to_string())
    }

    #[test]
    fn reads_header_and_x_fastest_data() {
        let data: Vec<f32> = (0..24).map(|n| n as f32).collect();
        let g = load(&vol_bytes(1, [2, 3, 4], 1, BOX, &data)).unwrap();
        assert_eq!(g.dims, UVec3::new(2, 3, 4));
        assert_eq!(g.bounds_min, Vec3::new(-1.0, -2.0, -3.0));
        assert_eq!(g.bounds_max, Vec3::new(1.0, 2.0, 3.0));
        // (i, j, k) = (1, 2, 3) is element 1 + 2 (2 + 3·3) = 23.
        assert_eq!(g.data[g.index(1, 2, 3)], 23.0);
    }

    #[test]
    fn every_header_prefix_is_truncated() {
        let full = vol_bytes(1, [1, 1, 1], 1, BOX, &[0.5]);
        for cut in 0..HEADER_BYTES {
            let e = load(&full[..cut]).unwrap_err();
            assert!(e.contains("truncated in the header"), "cut {cut}: {e}");
        }
        let e = load(&full[..HEADER_BYTES]).unwrap_err();
        assert!(e.contains("truncated in the voxel data"), "{e}");
    }

    #[test]
    fn rejects_bad_fields() {
        let one = [0.5f32];
        let cases: Vec<(Vec<u8>, &str)> = vec![
            (vol_bytes(1, [1, 0, 1], 1, BOX, &[]), "at least 1"),
            (vol_bytes(1, [1, -4, 1], 1, BOX, &[]), "at least 1"),
            (vol_bytes(1, [4096, 4096, 4096], 1, BOX, &one), "too large"),
            (vol_bytes(3, [1, 1, 1], 1, BOX, &one), "encoding 3 (uint8)"),
            (
                vol_bytes(1, [1, 1, 1], 3, BOX, &[1.0, 2.0, 3.0]),
                "3 channels",
            ),
            (
                vol_bytes(1, [1, 1, 1], 1, [0.0, 0.0, 0.0, 1.0, 1.0, 0.0], &one),
                "bounding box",
            ),
            (
                vol_bytes(1, [1, 1, 1], 1, [f32::NAN, 0.0, 0.0, 1.0, 1.0, 1.0], &one),
                "finite",
            ),
            (vol_bytes(1, [1, 1, 1], 1, BOX, &[0.5, 0.5]), "trailing"),
            (
                vol_bytes(1, [1, 1, 1], 1, BOX, &[f32::INFINITY]),
                "infinite",
            ),
        ];
        for (bytes, word) in cases {
            let e = load(&bytes).unwrap_err();
            assert!(
                e.contains("unit.vol") && e.contains(word),
                "want {word:?}: {e}"
            );
        }
        let mut v2 = vol_bytes(1, [1, 1, 1], 1, BOX, &one);
        v2[3] = 2;
        assert!(load(&v2).unwrap_err().contains("version 2"));
    }

    #[test]
    fn writer_refuses_inconsistent_grid() {
        let dir = tempfile::tempdir().unwrap();
        let g = VoxelGrid {
            dims: UVec3::new(2, 2, 2),
            bounds_min: Vec3::ZERO,
            bounds_max: Vec3::ONE,
            data: vec![0.0; 7],
        };
        let p = dir.path().join("bad.vol");
        let e = write_mitsuba_vol(&p, &g).unwrap_err().to_string();
        assert!(e.contains("bad.vol") && e.contains("7 values"), "{e}");
    }
}
