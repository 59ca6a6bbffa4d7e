// The majorant grid and the 3D-DDA walk through it. Mirrors
// src/physics/majorant.rs (`MajorantGrid::walk`). WGSL has no closures, so
// the walk is an iterator (as pbrt-v4's `DDAMajorantIterator` on the GPU):
// `dda_start` sets it up, each `dda_next` returns the next segment in order.

// One piece of the ray with a constant majorant.
struct MajorantSegment {
    t0: f32,
    t1: f32,
    majorant: f32,
    valid: bool,
}

// The state of a walk through the cells a ray crosses.
struct DdaIterator {
    cell: vec3<i32>,
    step: vec3<i32>,
    t_next: vec3<f32>,
    dt: vec3<f32>,
    t: f32,
    t_max: f32,
    done: bool,
}

// Starts the walk over `[t_min, t_max]` (already clipped to the grid's box).
fn dda_start(origin: vec3<f32>, dir: vec3<f32>, t_min: f32, t_max: f32) -> DdaIterator {
    let m = scene.medium;
    let res_f = vec3<f32>(m.majorant_res);
    let cell_size = (m.majorant_max - m.majorant_min) / res_f;
    let p = origin + dir * t_min;
    let c = floor((p - m.majorant_min) / cell_size);
    var it: DdaIterator;
    it.cell = vec3<i32>(clamp(c, vec3<f32>(0.0), res_f - vec3<f32>(1.0)));
    it.t = t_min;
    it.t_max = t_max;
    it.done = t_max <= t_min;
    for (var a = 0; a < 3; a++) {
        let d = dir[a];
        if abs(d) < 1e-30 {
            it.t_next[a] = BIG;
            it.dt[a] = BIG;
            it.step[a] = 0;
        } else if d > 0.0 {
            let edge = m.majorant_min[a] + f32(it.cell[a] + 1) * cell_size[a];
            it.t_next[a] = t_min + (edge - p[a]) / d;
            it.dt[a] = cell_size[a] / d;
            it.step[a] = 1;
        } else {
            let edge = m.majorant_min[a] + f32(it.cell[a]) * cell_size[a];
            it.t_next[a] = t_min + (edge - p[a]) / d;
            it.dt[a] = -cell_size[a] / d;
            it.step[a] = -1;
        }
    }
    return it;
}

// The next non-empty segment, or one with `valid = false` at the end.
fn dda_next(it: ptr<function, DdaIterator>) -> MajorantSegment {
    let res = vec3<i32>(scene.medium.majorant_res);
    loop {
        if (*it).done {
            return MajorantSegment(0.0, 0.0, 0.0, false);
        }
        let tn = (*it).t_next;
        var axis = 2;
        if tn.x < tn.y {
            if tn.x < tn.z {
                axis = 0;
            }
        } else if tn.y < tn.z {
            axis = 1;
        }
        let t_enter = (*it).t;
        let t_exit = min(tn[axis], (*it).t_max);
        let cell = (*it).cell;
        let m = majorant_values[u32(cell.x + res.x * (cell.y + res.y * cell.z))];
        if t_exit >= (*it).t_max {
            (*it).done = true;
        } else {
            (*it).t = t_exit;
            (*it).cell[axis] += (*it).step[axis];
            let c = (*it).cell[axis];
            if c < 0 || c >= res[axis] {
                (*it).done = true;
            }
            (*it).t_next[axis] += (*it).dt[axis];
        }
        if t_exit > t_enter {
            return MajorantSegment(t_enter, t_exit, m, true);
        }
    }
    // Unreachable: the loop only returns.
    return MajorantSegment(0.0, 0.0, 0.0, false);
}

// The majorant optical depth along `origin + t dir` over `[t0, t1]`,
// summed cell by cell until it reaches `cap` (then some value ≥ `cap`):
// `MajorantGrid::depth`.
fn majorant_depth(origin: vec3<f32>, dir: vec3<f32>, t0: f32, t1: f32, cap: f32) -> f32 {
    var it = dda_start(origin, dir, t0, t1);
    var depth = 0.0;
    loop {
        let seg = dda_next(&it);
        if !seg.valid || depth >= cap {
            break;
        }
        depth += seg.majorant * (seg.t1 - seg.t0);
    }
    return depth;
}
