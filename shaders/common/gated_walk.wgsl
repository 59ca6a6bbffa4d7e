// The path-length clock (METHOD.md §3, §7). Mirrors `march_clock` of
// src/physics/gated_walk.rs; the time-gated walks themselves still run on
// the CPU only.

// Lattice steps per majorant cell for the optical-depth quadrature
// (`CLOCK_STEPS_PER_CELL`).
const CLOCK_STEPS_PER_CELL: f32 = 2.0;

// Where a clock budget runs out along a ray (`ClockMarch`): `reached` at
// ray parameter `value`, or the ray ended first and the clock advanced by
// `value`.
struct ClockMarch {
    value: f32,
    reached: bool,
}

// Advances the clock along `origin + t dir` from `t0` (inside or on the box)
// towards `t_stop ≤ t_exit` (`march_clock`).
fn march_clock(
    clock: u32,
    origin: vec3<f32>,
    dir: vec3<f32>,
    t0: f32,
    t_exit: f32,
    t_stop_in: f32,
    budget: f32,
) -> ClockMarch {
    let t_stop = min(t_stop_in, t_exit);
    if clock == CLOCK_GEOMETRIC {
        let span = max(t_stop - t0, 0.0);
        if span >= budget {
            return ClockMarch(t0 + max(budget, 0.0), true);
        }
        return ClockMarch(span, false);
    }
    if budget <= 0.0 {
        return ClockMarch(t0, true);
    }
    let m = scene.medium;
    let cell = (m.majorant_max - m.majorant_min) / vec3<f32>(m.majorant_res);
    let h = max(min(min(cell.x, cell.y), cell.z) / CLOCK_STEPS_PER_CELL, 1e-12);
    let sigma_g = max_element(m.sigma_t);
    var acc = 0.0;
    var it = dda_start(origin, dir, t0, t_exit);
    loop {
        let seg = dda_next(&it);
        if !seg.valid || seg.t0 >= t_stop {
            break;
        }
        if seg.majorant <= 0.0 {
            // The majorant bounds ρ: nothing to count in this cell.
            if seg.t1 < t_stop {
                continue;
            }
            break;
        }
        let a = seg.t0;
        let b = seg.t1;
        var i = 0u;
        loop {
            let p0 = a + f32(i) * h;
            if p0 >= b {
                break;
            }
            let p1 = min(a + f32(i + 1u) * h, b);
            let c = sigma_g * density(origin + dir * (0.5 * (p0 + p1)));
            let end = min(p1, t_stop);
            let d_tau = c * max(end - p0, 0.0);
            if c > 0.0 && acc + d_tau >= budget {
                return ClockMarch(min(p0 + (budget - acc) / c, end), true);
            }
            acc += d_tau;
            if p1 >= t_stop {
                return ClockMarch(acc, false);
            }
            i += 1u;
        }
    }
    return ClockMarch(acc, false);
}
