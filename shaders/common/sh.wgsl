// Real spherical harmonics, orders 0..=4 (src/doc/method.md §5: the angular part
// of the internal lights). Mirrors src/physics/sh.rs: orthonormal real
// basis with the Condon–Shortley phase, coefficient `l(l+1) + m`, evaluated
// without trigonometry from `(x + iy)^m` and the recurrence for
// `P_l^m(z) / sin^m θ`.
//
// Written out without loops: Mesa's llvmpipe (lavapipe, the CI's GPU) ends
// every loop of an invocation once their iterations add up to 65 535
// (`LP_MAX_TGSI_LOOP_ITERATIONS`, shared by all loops), and the kernel
// reconstruction evaluates a light's series for every light near every
// point of the gather (src/doc/gpu.md, "Software drivers").

// From Rust (the generated prelude, src/gpu/shaders.rs): the highest
// supported order, `SH_MAX_ORDER` (crate::physics::sh::MAX_ORDER), and
// `K_l^|m|` (times √2 for m ≠ 0), indexed by `l(l+1) + m`, `SH_NORM`
// (crate::physics::sh::NORM).

// `Y_i(dir)` for `i < (order + 1)²`, the rest zero (`sh_basis`).
fn sh_basis(order: u32, dir: vec3<f32>) -> array<f32, 25> {
    let ord = min(order, SH_MAX_ORDER);
    let norm = SH_NORM;
    let x = dir.x;
    let y = dir.y;
    let z = dir.z;
    // (x + iy)^m = sinᵐθ (cos mφ, sin mφ).
    let re1 = x;
    let im1 = y;
    let re2 = re1 * x - im1 * y;
    let im2 = re1 * y + im1 * x;
    let re3 = re2 * x - im2 * y;
    let im3 = re2 * y + im2 * x;
    let re4 = re3 * x - im3 * y;
    let im4 = re3 * y + im3 * x;
    // Q_l^m = P_l^m(z) / sinᵐθ: Q_m^m = (−1)^m (2m − 1)!!,
    // Q_{m+1}^m = (2m + 1) z Q_m^m, then
    // Q_l^m = ((2l − 1) z Q_{l−1}^m − (l + m − 1) Q_{l−2}^m) / (l − m).
    let q00 = 1.0;
    let q10 = z * 1.0 * q00;
    let q20 = (3.0 * z * q10 - 1.0 * q00) / 2.0;
    let q30 = (5.0 * z * q20 - 2.0 * q10) / 3.0;
    let q40 = (7.0 * z * q30 - 3.0 * q20) / 4.0;
    let q11 = -1.0;
    let q21 = z * 3.0 * q11;
    let q31 = (5.0 * z * q21 - 3.0 * q11) / 2.0;
    let q41 = (7.0 * z * q31 - 4.0 * q21) / 3.0;
    let q22 = 3.0;
    let q32 = z * 5.0 * q22;
    let q42 = (7.0 * z * q32 - 5.0 * q22) / 2.0;
    let q33 = -15.0;
    let q43 = z * 7.0 * q33;
    let q44 = 105.0;
    // Bands above `ord` are zero.
    let on1 = select(0.0, 1.0, ord >= 1u);
    let on2 = select(0.0, 1.0, ord >= 2u);
    let on3 = select(0.0, 1.0, ord >= 3u);
    let on4 = select(0.0, 1.0, ord >= 4u);
    var full: array<f32, 25>;
    full[0] = norm[0] * q00;
    full[1] = on1 * norm[1] * q11 * im1;
    full[2] = on1 * norm[2] * q10;
    full[3] = on1 * norm[3] * q11 * re1;
    full[4] = on2 * norm[4] * q22 * im2;
    full[5] = on2 * norm[5] * q21 * im1;
    full[6] = on2 * norm[6] * q20;
    full[7] = on2 * norm[7] * q21 * re1;
    full[8] = on2 * norm[8] * q22 * re2;
    full[9] = on3 * norm[9] * q33 * im3;
    full[10] = on3 * norm[10] * q32 * im2;
    full[11] = on3 * norm[11] * q31 * im1;
    full[12] = on3 * norm[12] * q30;
    full[13] = on3 * norm[13] * q31 * re1;
    full[14] = on3 * norm[14] * q32 * re2;
    full[15] = on3 * norm[15] * q33 * re3;
    full[16] = on4 * norm[16] * q44 * im4;
    full[17] = on4 * norm[17] * q43 * im3;
    full[18] = on4 * norm[18] * q42 * im2;
    full[19] = on4 * norm[19] * q41 * im1;
    full[20] = on4 * norm[20] * q40;
    full[21] = on4 * norm[21] * q41 * re1;
    full[22] = on4 * norm[22] * q42 * re2;
    full[23] = on4 * norm[23] * q43 * re3;
    full[24] = on4 * norm[24] * q44 * re4;
    return full;
}
