//! Spatial indices over the internal lights ([method §6](crate::doc::method): "the window `s*`
//! is also a locality radius"): a uniform grid that lists the lights near a
//! point, for the kernel reconstruction of `J` along a camera ray, and a
//! coarse grid of light clusters with their power, from which the final
//! gather draws one light per sample with a known probability.
//!
//! Both are bucket grids built by a counting sort: `starts[c]..starts[c+1]`
//! indexes `ids`, the lights of cell `c`. Cells are x-fastest.

use glam::{UVec3, Vec3};

/// A uniform grid of light indices over a box.
#[derive(Clone, Debug)]
pub struct LightGrid {
    min: Vec3,
    cell: Vec3,
    res: UVec3,
    starts: Vec<u32>,
    ids: Vec<u32>,
}

impl LightGrid {
    /// Buckets the lights whose `include(i)` is true into a grid over
    /// `bounds` with cells of about `cell_size` (at most `max_res` cells
    /// along an axis, at least one).
    pub fn build(
        positions: &[Vec3],
        include: impl Fn(usize) -> bool,
        bounds: (Vec3, Vec3),
        cell_size: f32,
        max_res: u32,
    ) -> Self {
        let (min, max) = bounds;
        let size = (max - min).max(Vec3::splat(1e-30));
        let res = (size / cell_size.max(1e-30))
            .ceil()
            .clamp(Vec3::ONE, Vec3::splat(max_res.max(1) as f32))
            .as_uvec3();
        let cell = size / res.as_vec3();
        let mut grid = Self {
            min,
            cell,
            res,
            starts: Vec::new(),
            ids: Vec::new(),
        };
        let cells = (res.x * res.y * res.z) as usize;
        let mut counts = vec![0u32; cells + 1];
        let cell_of: Vec<Option<usize>> = positions
            .iter()
            .enumerate()
            .map(|(i, &p)| include(i).then(|| grid.cell_index(p)))
            .collect();
        for c in cell_of.iter().flatten() {
            counts[*c + 1] += 1;
        }
        for c in 0..cells {
            counts[c + 1] += counts[c];
        }
        let mut fill = counts.clone();
        let mut ids = vec![0u32; counts[cells] as usize];
        for (i, c) in cell_of.iter().enumerate() {
            if let Some(c) = c {
                ids[fill[*c] as usize] = i as u32;
                fill[*c] += 1;
            }
        }
        grid.starts = counts;
        grid.ids = ids;
        grid
    }

    /// The grid's minimum corner.
    pub fn min(&self) -> Vec3 {
        self.min
    }

    /// The size of one cell.
    pub fn cell_size(&self) -> Vec3 {
        self.cell
    }

    /// Where each cell's lights start in [`LightGrid::ids`] (one entry per
    /// cell, then the total).
    pub fn starts(&self) -> &[u32] {
        &self.starts
    }

    /// Cells along each axis.
    pub fn resolution(&self) -> UVec3 {
        self.res
    }

    /// Number of cells.
    pub fn cell_count(&self) -> usize {
        self.starts.len() - 1
    }

    /// The (clamped) cell coordinates of `p`.
    #[inline]
    fn cell_coords(&self, p: Vec3) -> UVec3 {
        ((p - self.min) / self.cell)
            .floor()
            .clamp(Vec3::ZERO, (self.res - UVec3::ONE).as_vec3())
            .as_uvec3()
    }

    /// The index of the (clamped) cell containing `p`.
    #[inline]
    pub fn cell_index(&self, p: Vec3) -> usize {
        let c = self.cell_coords(p);
        (c.x + self.res.x * (c.y + self.res.y * c.z)) as usize
    }

    /// The lights of cell `c`.
    #[inline]
    pub fn cell_lights(&self, c: usize) -> &[u32] {
        &self.ids[self.starts[c] as usize..self.starts[c + 1] as usize]
    }

    /// Range of `ids` positions of cell `c` (for tables aligned with
    /// [`LightGrid::ids`]).
    #[inline]
    pub fn cell_range(&self, c: usize) -> std::ops::Range<usize> {
        self.starts[c] as usize..self.starts[c + 1] as usize
    }

    /// All bucketed light indices, cell by cell.
    pub fn ids(&self) -> &[u32] {
        &self.ids
    }

    /// The box of cell `c`, as (min, max).
    pub fn cell_box(&self, c: usize) -> (Vec3, Vec3) {
        let (rx, ry) = (self.res.x as usize, self.res.y as usize);
        let v = Vec3::new(
            (c % rx) as f32,
            ((c / rx) % ry) as f32,
            (c / (rx * ry)) as f32,
        );
        let lo = self.min + v * self.cell;
        (lo, lo + self.cell)
    }

    /// Calls `f(range)` for every run of [`LightGrid::ids`] positions
    /// whose cells overlap the box `[p − r, p + r]` (one run per row of
    /// cells along x), for tables aligned with the ids: the same lights
    /// as [`LightGrid::for_each_near`], read from contiguous memory.
    #[inline]
    pub fn for_each_near_run(&self, p: Vec3, r: f32, mut f: impl FnMut(std::ops::Range<usize>)) {
        let lo = self.cell_coords(p - Vec3::splat(r));
        let hi = self.cell_coords(p + Vec3::splat(r));
        for z in lo.z..=hi.z {
            for y in lo.y..=hi.y {
                let row = self.res.x * (y + self.res.y * z);
                let a = self.starts[(row + lo.x) as usize] as usize;
                let b = self.starts[(row + hi.x + 1) as usize] as usize;
                if a < b {
                    f(a..b);
                }
            }
        }
    }

    /// Calls `f(i)` for every bucketed light in the cells that overlap the
    /// box `[p − r, p + r]` (a superset of the lights within `r` of `p`).
    #[inline]
    pub fn for_each_near(&self, p: Vec3, r: f32, mut f: impl FnMut(u32)) {
        self.for_each_near_run(p, r, |run| self.ids[run].iter().for_each(|&i| f(i)));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::rng::Rng;

    #[test]
    fn near_query_finds_every_light_within_reach() {
        let mut rng = Rng::for_sample(3, 0, 0);
        let bounds = (Vec3::new(-1.0, 0.0, -2.0), Vec3::new(1.0, 0.5, 2.0));
        let pts: Vec<Vec3> = (0..2000)
            .map(|_| {
                bounds.0
                    + (bounds.1 - bounds.0)
                        * Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32())
            })
            .collect();
        let grid = LightGrid::build(&pts, |i| i % 7 != 0, bounds, 0.13, 64);
        assert_eq!(grid.ids().len(), pts.len() - pts.len().div_ceil(7));
        for q in 0..50 {
            let p = pts[q * 13] + Vec3::new(0.05, -0.02, 0.1);
            let r = 0.05 + 0.01 * q as f32;
            let mut found = Vec::new();
            grid.for_each_near(p, r, |i| found.push(i as usize));
            let mut dedup = found.clone();
            dedup.sort_unstable();
            dedup.dedup();
            assert_eq!(dedup.len(), found.len(), "a light listed twice");
            for (i, &x) in pts.iter().enumerate() {
                if i % 7 != 0 && (x - p).length() <= r {
                    assert!(found.contains(&i), "light {i} missed");
                }
                if i % 7 == 0 {
                    assert!(!found.contains(&i), "excluded light {i} listed");
                }
            }
        }
        // Every light sits in the cell whose box contains it.
        for c in 0..grid.cell_count() {
            let (lo, hi) = grid.cell_box(c);
            for &i in grid.cell_lights(c) {
                let p = pts[i as usize];
                assert!(p.cmpge(lo - 1e-5).all() && p.cmple(hi + 1e-5).all());
            }
        }
    }
}
