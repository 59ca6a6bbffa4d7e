//! The CPU backend: rayon-parallel, progressive passes of one sample per
//! pixel. Every pixel's random stream depends only on (seed, pixel, pass),
//! so an image reproduces whatever the number of threads.

pub mod reference;

use glam::Vec3;
use rayon::prelude::*;

use crate::physics::rng::Rng;
use crate::render::{Film, Prepared};
use crate::scene::Method;

/// Renders pass number `pass` (one sample per pixel) with `method`.
pub fn render_pass(prepared: &Prepared, method: Method, seed: u64, pass: u32) -> Vec<Vec3> {
    let cam = &prepared.camera;
    let width = cam.width as usize;
    let mut out = vec![Vec3::ZERO; width * cam.height as usize];
    out.par_chunks_mut(width).enumerate().for_each(|(y, row)| {
        for (x, px) in row.iter_mut().enumerate() {
            let index = (y * width + x) as u32;
            let mut rng = Rng::for_sample(seed, index, pass);
            let (jx, jy) = (rng.next_f32(), rng.next_f32());
            let dir = cam.ray_dir(x as f32 + jx, y as f32 + jy);
            *px = match method {
                Method::Reference => reference::sample(prepared, cam.eye, dir, &mut rng),
            };
        }
    });
    out
}

/// Renders `spp` passes into a new film, calling `on_pass` after each; it
/// returns `false` to stop early (cancellation).
pub fn render(
    prepared: &Prepared,
    method: Method,
    seed: u64,
    spp: u32,
    mut on_pass: impl FnMut(&Film) -> bool,
) -> Film {
    let cam = &prepared.camera;
    let mut film = Film::new(cam.width, cam.height);
    for pass in 0..spp {
        let samples = render_pass(prepared, method, seed, pass);
        film.add_pass(&samples);
        if !on_pass(&film) {
            break;
        }
    }
    film
}
