// Ray generation. Mirrors `CameraFrame::ray_dir` in src/scene/camera.rs:
// (0, 0) is the top-left corner of the image, (width, height) the
// bottom-right, in pixel units.

// Unit direction of the camera ray through image position (`px`, `py`).
fn camera_ray_dir(px: f32, py: f32) -> vec3<f32> {
    let c = scene.camera;
    let sx = 2.0 * px / f32(c.width) - 1.0;
    let sy = 1.0 - 2.0 * py / f32(c.height);
    return normalize(c.forward + c.right_scaled * sx + c.up_scaled * sy);
}
