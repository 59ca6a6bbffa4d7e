// Random numbers: PCG-RXS-M-XS-32 with one stream per (seed, pixel, pass).
// Mirrors src/physics/rng.rs (same constants, same seeding), so a GPU
// stream yields the same numbers as the CPU stream with the same inputs.

// One stream of uniform random numbers (`Rng` in rng.rs).
struct Rng {
    state: u32,
}

// A 32-bit integer hash (`pcg_hash` in rng.rs).
fn pcg_hash(v: u32) -> u32 {
    let state = v * 747796405u + 2891336453u;
    let word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
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
    (*rng).state = old * 747796405u + 2891336453u;
    let word = ((old >> ((old >> 28u) + 4u)) ^ old) * 277803737u;
    return (word >> 22u) ^ word;
}

// The number before the stream's current position, stepping the stream
// back over it (`Rng::previous_u32`): the LCG run backwards, its
// multiplier's inverse modulo 2³² being 3425435293.
fn rng_previous_u32(rng: ptr<function, Rng>) -> u32 {
    let old = ((*rng).state - 2891336453u) * 3425435293u;
    (*rng).state = old;
    let word = ((old >> ((old >> 28u) + 4u)) ^ old) * 277803737u;
    return (word >> 22u) ^ word;
}

// `rng_previous_u32` as a uniform number in [0, 1) (`Rng::previous_f32`).
fn rng_previous_f32(rng: ptr<function, Rng>) -> f32 {
    return f32(rng_previous_u32(rng) >> 8u) * (1.0 / 16777216.0);
}

// A uniform number in [0, 1) (`Rng::next_f32`).
fn rng_next_f32(rng: ptr<function, Rng>) -> f32 {
    return f32(rng_next_u32(rng) >> 8u) * (1.0 / 16777216.0);
}
