// Orthonormal frames around a direction. Mirrors src/physics/frame.rs.

// Two unit vectors completing unit `n` to a right-handed orthonormal basis
// (Duff et al. 2017), returned as the columns 0 and 1 of a 2-column matrix.
fn frame_basis(n: vec3<f32>) -> mat2x3<f32> {
    let sign = select(-1.0, 1.0, n.z >= 0.0);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    return mat2x3<f32>(
        vec3<f32>(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        vec3<f32>(b, sign + n.y * n.y * a, -n.y),
    );
}

// The unit direction with cosine `cos_theta` to `n` and azimuth `phi`
// (`from_spherical`).
fn frame_from_spherical(n: vec3<f32>, cos_theta: f32, phi: f32) -> vec3<f32> {
    let tb = frame_basis(n);
    let sin_theta = sqrt(max(1.0 - cos_theta * cos_theta, 0.0));
    let v = tb[0] * (sin_theta * cos(phi)) + tb[1] * (sin_theta * sin(phi)) + n * cos_theta;
    return normalize(v);
}
