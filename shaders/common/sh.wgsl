// Real spherical harmonics, orders 0..=4 (src/doc/method.md §5: the angular part
// of the internal lights). Mirrors src/physics/sh.rs: orthonormal real
// basis with the Condon–Shortley phase, coefficient `l(l+1) + m`, evaluated
// without trigonometry from `(x + iy)^m` and the recurrence for
// `P_l^m(z) / sin^m θ`.

// From Rust (the generated prelude, src/gpu/shaders.rs): the highest
// supported order, `SH_MAX_ORDER` (crate::physics::sh::MAX_ORDER), and
// `K_l^|m|` (times √2 for m ≠ 0), indexed by `l(l+1) + m`, `SH_NORM`
// (crate::physics::sh::NORM).

// `Y_i(dir)` for `i < (order + 1)²`, the rest zero (`sh_basis`).
fn sh_basis(order: u32, dir: vec3<f32>) -> array<f32, 25> {
    let ord = min(order, SH_MAX_ORDER);
    var norm = SH_NORM;
    var re: array<f32, 5>;
    var im: array<f32, 5>;
    re[0] = 1.0;
    for (var m = 1u; m <= ord; m++) {
        re[m] = re[m - 1u] * dir.x - im[m - 1u] * dir.y;
        im[m] = re[m - 1u] * dir.y + im[m - 1u] * dir.x;
    }
    var full: array<f32, 25>;
    // Q_m^m = (−1)^m (2m − 1)!!
    var q_mm = 1.0;
    for (var m = 0u; m <= ord; m++) {
        if m > 0u {
            q_mm *= -f32(2u * m - 1u);
        }
        var q_prev = 0.0;
        var q = q_mm;
        for (var l = m; l <= ord; l++) {
            if l == m + 1u {
                q_prev = q;
                q = dir.z * f32(2u * m + 1u) * q_mm;
            } else if l > m + 1u {
                let next = (f32(2u * l - 1u) * dir.z * q - f32(l + m - 1u) * q_prev) / f32(l - m);
                q_prev = q;
                q = next;
            }
            let centre = l * (l + 1u);
            if m == 0u {
                full[centre] = norm[centre] * q;
            } else {
                full[centre + m] = norm[centre + m] * q * re[m];
                full[centre - m] = norm[centre - m] * q * im[m];
            }
        }
    }
    return full;
}
