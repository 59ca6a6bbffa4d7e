// Random numbers: PCG-RXS-M-XS-32 with one stream per (seed, pixel, pass).
// Mirrors src/physics/rng.rs (same constants, same seeding), so a GPU
// stream yields the same numbers as the CPU stream with the same inputs.

// One stream of uniform random numbers (`Rng` in rng.rs).
struct Rng {
    state: u32,
}

// The LCG's multiplier, its inverse modulo 2³² and its increment
// (`RNG_MULTIPLIER`, `RNG_INVERSE_MULTIPLIER`, `RNG_INCREMENT`: generated
// from `MULTIPLIER`, `INVERSE_MULTIPLIER`, `INCREMENT` in rng.rs).

// PCG's output permutation of one LCG state (`permute`).
fn rng_permute(state: u32) -> u32 {
    let word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

// The uniform number in [0, 1) that 32 random bits make (`unit`).
fn rng_unit(bits: u32) -> f32 {
    return f32(bits >> 8u) * (1.0 / 16777216.0);
}

// A 32-bit integer hash (`pcg_hash` in rng.rs).
fn pcg_hash(v: u32) -> u32 {
    return rng_permute(v * RNG_MULTIPLIER + RNG_INCREMENT);
}

// The stream of sample `index` in `pass` of a render whose 64-bit seed is
// (`seed_lo`, `seed_hi`) (`Rng::for_sample`).
fn rng_for_sample(seed_lo: u32, seed_hi: u32, index: u32, pass_index: u32) -> Rng {
    var s = pcg_hash(seed_lo ^ pcg_hash(seed_hi));
    s = pcg_hash(index ^ s);
    s = pcg_hash(pass_index + s);
    return Rng(s);
}

// The next 32 random bits (`Rng::next_u32`).
fn rng_next_u32(rng: ptr<function, Rng>) -> u32 {
    let old = (*rng).state;
    (*rng).state = old * RNG_MULTIPLIER + RNG_INCREMENT;
    return rng_permute(old);
}

// The number before the stream's current position, stepping the stream
// back over it (`Rng::previous_u32`): the LCG run backwards.
fn rng_previous_u32(rng: ptr<function, Rng>) -> u32 {
    (*rng).state = ((*rng).state - RNG_INCREMENT) * RNG_INVERSE_MULTIPLIER;
    return rng_permute((*rng).state);
}

// `rng_previous_u32` as a uniform number in [0, 1) (`Rng::previous_f32`).
fn rng_previous_f32(rng: ptr<function, Rng>) -> f32 {
    return rng_unit(rng_previous_u32(rng));
}

// A uniform number in [0, 1) (`Rng::next_f32`).
fn rng_next_f32(rng: ptr<function, Rng>) -> f32 {
    return rng_unit(rng_next_u32(rng));
}

// Where in pixel `index` the camera ray of pass `pass_index` goes: point
// `pass_index` of the R₂ sequence (its steps `R2_STEP_X`, `R2_STEP_Y`,
// generated) shifted by an offset drawn per seed and pixel from the
// stream `PIXEL_OFFSET_STREAM` (`pixel_jitter` in rng.rs).
fn pixel_jitter(seed_lo: u32, seed_hi: u32, index: u32, pass_index: u32) -> vec2<f32> {
    var offset = rng_for_sample(seed_lo, seed_hi, index, PIXEL_OFFSET_STREAM);
    let ox = rng_next_u32(&offset);
    let oy = rng_next_u32(&offset);
    return vec2<f32>(
        rng_unit(ox + pass_index * R2_STEP_X),
        rng_unit(oy + pass_index * R2_STEP_Y),
    );
}
