//! The internal lights built on the GPU ([method §4–§5](crate::doc::method)): placement of the
//! `M` lights with density `p ∝ (1 − u) ρ̃/Z + u/|B|` and their weights
//! `V_i = 1/(M p(x_i))`, then `K` time-gated walks per light estimating
//! `J_N(x_i, ·)` with both clocks, projected onto real SH, with the per-term
//! energies `E_k` and the light arriving from each external light. The same
//! estimators as [`InternalLights::build`] (`physics::internal::placement`,
//! `physics::internal::walk`, `physics::internal::sources`), with other random streams.
//!
//! - Placement: the placement grid (`ρ` at the cell corners) and an alias
//!   table over its cells depend on the medium only and are built on the
//!   CPU (`PlacementDensity`, kept with the prepared scene) and uploaded;
//!   the sampling runs on the GPU, one invocation per light
//!   (`shaders/placement/main.wgsl`), deterministic for a seed. Procedural
//!   and voxel media alike.
//! - Walks: one workgroup of [`WALK_LANES`] invocations per light, one walk
//!   per invocation and dispatch; `⌈K/64⌉` dispatches add their sums to
//!   one output buffer (`shaders/walks/main.wgsl`). Splitting `K` over
//!   dispatches keeps each invocation short: lavapipe caps an invocation's
//!   loop iterations (see [the GPU page](crate::doc::gpu)), and hardware drivers time out long
//!   dispatches.
//!
//!   With view walks (`InternalParams::view_walks`) each light's walks
//!   `K .. K + view_walks` all go towards the eye and add one more value
//!   per light ("Walks towards the eye" in `physics::internal`); in a
//!   medium of `|g|` ≥ `PHASE_WALKS_MIN_G` the next [`phase_walks`] start
//!   towards the eye turned by the phase function and add one more
//!   (`L₁`'s source, [`InternalLights::reconstruct_phase_view`]).
//!
//!   With a deadline (`InternalParams::walk_deadline`: a render with a
//!   time limit shorter than a whole set's walks) the lights are
//!   dispatched in chunks, timed, and each chunk walks the share of the
//!   walks that the time left allows (`walk_within`); each light's sums
//!   are weighed by its own dispatch's counts, so the set stays unbiased.
//!
//! Positions, weights, SH coefficients, arriving light and term energies
//! are read back (a few MiB) and the CPU's [`InternalLights::assemble`]
//! builds the kernel radius and the spatial indices.
//!
//! The scene's bindings 0–4 are those of `SceneBuffers` (shared with the
//! renderers); this module's own buffers are at bindings 5–8.

use std::time::Instant;

use glam::Vec3;
use wgpu::util::DeviceExt;

use super::context::{GpuContext, GpuError};
use super::mirrors::{
    GpuPassParams, GpuPlacementParams, GpuWalkParams, PLACEMENT_LANES, WALK_LANES,
};
use super::renderer::{bind_group, compute_pipeline, read_buffer, storage_buffer, SceneBuffers};
use super::shaders::{PLACEMENT_MODULE, WALKS_MODULE};
use crate::physics::internal::clock::term_slots;
use crate::physics::internal::sources::{
    kernel_radius_for, phase_walks, place_internal_lights, within_view_reach, InternalLight,
    InternalLights, InternalParams, LightSources,
};
use crate::physics::reference::RR_START_DEPTH;
use crate::physics::sh::{sh_count, MAX_ORDER};
use crate::render::PreparedScene;

/// One vec4 of a GPU buffer, read back.
type Vec4 = [f32; 4];

/// Most workgroups per dispatch along x (WebGPU's guaranteed limit).
const MAX_GROUPS: u32 = 65_535;

/// The lights as placed on the GPU, before the walks.
#[derive(Clone, Debug)]
pub struct GpuPlacement {
    /// Positions, densities and weights `V_i`.
    pub lights: Vec<InternalLight>,
    /// The pdf `p(x_i)` of each light.
    pub pdfs: Vec<f32>,
    /// `∫ρ̃`, the placement's estimate of `∫ρ`.
    pub density_integral: f32,
}

/// Buffers and pipelines of one build.
struct Build {
    ctx: GpuContext,
    scene: SceneBuffers,
    /// Two vec4 per light: (x, ρ(x)), (V, p, 0, 0).
    placed: wgpu::Buffer,
    light_count: u32,
    density_integral: f32,
}

/// Places `params.lights` lights on the GPU for `prepared`'s medium with
/// `params.uniform_mix` and `params.seed`, and reads them back (the first
/// half of [`build_internal_lights_gpu`]; the tests check it against
/// [`PlacementDensity`](crate::physics::internal::placement::PlacementDensity)).
pub fn place_lights_gpu(
    ctx: &GpuContext,
    prepared: &PreparedScene,
    params: &InternalParams,
) -> Result<GpuPlacement, GpuError> {
    let build = place(ctx, prepared, params)?;
    let raw: Vec<[f32; 4]> = read_buffer(ctx, &build.placed, "the placed lights")?;
    let (lights, pdfs) = unpack_placed(&raw, build.light_count as usize);
    Ok(GpuPlacement {
        lights,
        pdfs,
        density_integral: build.density_integral,
    })
}

fn unpack_placed(raw: &[[f32; 4]], m: usize) -> (Vec<InternalLight>, Vec<f32>) {
    raw.chunks_exact(2)
        .take(m)
        .map(|p| {
            (
                InternalLight {
                    position: Vec3::new(p[0][0], p[0][1], p[0][2]),
                    density: p[0][3],
                    weight: p[1][0],
                },
                p[1][1],
            )
        })
        .unzip()
}

/// Builds the internal lights of `prepared` with `params` on the GPU:
/// placement and walks there, then [`InternalLights::assemble`] on the CPU.
/// `timings.placement` covers the placement grid (CPU), its upload and the
/// GPU sampling; `timings.walks` the walks and the read-back.
pub fn build_internal_lights_gpu(
    ctx: &GpuContext,
    prepared: &PreparedScene,
    params: &InternalParams,
) -> Result<InternalLights, GpuError> {
    // Refuse before any work if the results cannot be bound.
    let n_ext = prepared.lights.suns.len() + prepared.lights.points.len();
    let phase = gpu_phase_walks(params, prepared);
    let stride = record_stride(params, n_ext, phase) as usize;
    ctx.check_storage_size(
        "internal-light walk results",
        params.lights.max(1) as u64 * stride as u64 * 16,
    )?;
    let start = Instant::now();
    let build = place(ctx, prepared, params)?;
    ctx.wait_idle()?;
    let t_place = start.elapsed().as_secs_f64();

    let start = Instant::now();
    let (placed_raw, out, walked) = walk(&build, prepared, params)?;
    let t_walk = start.elapsed().as_secs_f64();

    let m = build.light_count as usize;
    let (lights, _) = unpack_placed(&placed_raw, m);
    let count = sh_count(params.sh_order.min(MAX_ORDER));
    let gates = term_slots(params.terms);
    let v3 = |v: &[f32; 4]| Vec3::new(v[0], v[1], v[2]);
    let mut sources = LightSources::with_capacity(lights, count, n_ext, gates);
    let mut cut_short_walks = 0u64;
    for record in out.chunks_exact(stride).take(m) {
        cut_short_walks += record.first().map_or(0, |v| v[3] as u64);
        let (sh, rest) = record.split_at(3 * count);
        let (arrival, rest) = rest.split_at(n_ext);
        let (energy, view) = rest.split_at(gates);
        if let Some(v) = view.first() {
            sources.view.push(v3(v));
        }
        if let Some(v) = view.get(1).filter(|_| phase > 0) {
            sources.phase_view.push(v3(v));
        }
        sources.push(
            sh[..count].iter().map(v3),
            sh[count..2 * count].iter().map(v3),
            sh[2 * count..].iter().map(v3),
            arrival.iter().map(v3),
            energy.iter().map(v3),
        );
    }
    // The GPU walked towards the eye from every light; those out of the
    // camera's reach take their harmonics' value, as on the CPU.
    if params.view_walks > 0 {
        let reach = kernel_radius_for(&prepared.volume, params, &sources.lights);
        sources.kernel_radius = Some(reach);
        let reached = within_view_reach(&prepared.volume, params, reach, &sources.lights);
        sources.view_from_harmonics_outside(
            params.sh_order.min(MAX_ORDER),
            params.eye,
            prepared.volume.optics.g,
            &reached,
        );
    }
    let mut lights_out = InternalLights::assemble(
        &prepared.volume,
        &prepared.lights,
        params,
        sources,
        build.density_integral,
    );
    lights_out.timings.placement = t_place;
    lights_out.timings.walks = t_walk;
    lights_out.cut_short_walks = cut_short_walks;
    lights_out.walked = walked.spread;
    lights_out.walk_share = walked.share;
    Ok(lights_out)
}

/// Phase walks per light on the GPU: [`phase_walks`] where there are view
/// walks.
fn gpu_phase_walks(params: &InternalParams, prepared: &PreparedScene) -> u32 {
    if params.view_walks > 0 {
        phase_walks(params, prepared.volume.optics.g)
    } else {
        0
    }
}

/// The vec4 per light of the walks' output (see
/// `shaders/walks/main.wgsl`): the three SH sets, the arrival from each of
/// `n_ext` external lights, the energies of `k = 1..=N` after `E_0` (those
/// past [`RESOLVED_TERMS`](crate::physics::internal::clock::RESOLVED_TERMS)
/// summed in the last), with view walks their value, and with phase walks
/// theirs (`phase`: [`phase_walks`] per light).
fn record_stride(params: &InternalParams, n_ext: usize, phase: u32) -> u32 {
    let count = sh_count(params.sh_order.min(MAX_ORDER)) as u32;
    3 * count
        + n_ext as u32
        + term_slots(params.terms) as u32
        + u32::from(params.view_walks > 0)
        + u32::from(phase > 0)
}

/// A uniform buffer holding `value`.
fn uniform<T: bytemuck::Pod>(ctx: &GpuContext, label: &str, value: &T) -> wgpu::Buffer {
    ctx.device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: bytemuck::bytes_of(value),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        })
}

/// Runs `groups` workgroups of `pipeline` with `bind_group`.
fn dispatch(
    ctx: &GpuContext,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    bind_group: &wgpu::BindGroup,
    groups: u32,
) {
    let mut encoder = ctx
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) });
    {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some(label),
            timestamp_writes: None,
        });
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, bind_group, &[]);
        pass.dispatch_workgroups(groups, 1, 1);
    }
    ctx.queue.submit([encoder.finish()]);
}

/// Uploads the scene and the placement grid and enqueues the placement.
fn place(
    ctx: &GpuContext,
    prepared: &PreparedScene,
    params: &InternalParams,
) -> Result<Build, GpuError> {
    let m = params.lights.max(1);
    let light_count = u32::try_from(m)
        .ok()
        .filter(|&m| m.div_ceil(PLACEMENT_LANES) <= MAX_GROUPS)
        .ok_or(GpuError::Unsupported {
            what: "M (internal lights) of the GPU placement",
            value: m as u64,
            max: (MAX_GROUPS * PLACEMENT_LANES) as u64,
        })?;
    let density = prepared.placement_density(params.uniform_mix);
    if params.view_share > 0.0 {
        // The share placed in the camera's windows marches camera rays
        // through the medium: the CPU places all the lights (the same ones
        // as the CPU backend's for this seed) and they go up as they are.
        let (lights, density_integral) = place_internal_lights(&prepared.volume, params, &density);
        let raw: Vec<[f32; 4]> = lights
            .iter()
            .flat_map(|l| {
                let p = l.position;
                [[p.x, p.y, p.z, l.density], [l.weight, 0.0, 0.0, 0.0]]
            })
            .collect();
        let placed = storage_buffer(
            ctx,
            "placed internal lights",
            bytemuck::cast_slice(&raw),
            wgpu::BufferUsages::COPY_SRC,
        )?;
        return Ok(Build {
            ctx: ctx.clone(),
            scene: SceneBuffers::new(ctx, prepared)?,
            placed,
            light_count: lights.len() as u32,
            density_integral,
        });
    }
    let (threshold, alias) = density.alias_table();
    let mut table: Vec<[u32; 2]> = threshold
        .iter()
        .zip(&alias)
        .map(|(t, a)| [t.to_bits(), *a])
        .collect();
    if table.is_empty() {
        // Z = 0: the placement is uniform and never reads the table.
        table.push([0; 2]);
    }
    let (lo, hi) = density.bounds();
    let res = density.resolution();
    let placement_params = GpuPlacementParams {
        grid_min: lo.to_array(),
        u_mix: density.u_mix(),
        grid_max: hi.to_array(),
        integral: density.density_integral(),
        cell: density.cell_size().to_array(),
        box_volume: density.box_volume(),
        res: res.to_array(),
        cell_count: res.x * res.y * res.z,
        light_count,
        inv_light_count: 1.0 / light_count as f32,
        ..Default::default()
    };
    let placed_bytes = light_count as u64 * 32;
    ctx.check_storage_size("placed internal lights", placed_bytes)?;
    let pipeline = compute_pipeline(ctx, &PLACEMENT_MODULE)?;
    let scene = SceneBuffers::new(ctx, prepared)?;
    let alias_buf = storage_buffer(
        ctx,
        "placement alias table",
        bytemuck::cast_slice(&table),
        wgpu::BufferUsages::empty(),
    )?;
    let corners = storage_buffer(
        ctx,
        "placement grid corners",
        bytemuck::cast_slice(density.corners()),
        wgpu::BufferUsages::empty(),
    )?;
    let seed = GpuPassParams {
        seed_lo: params.seed as u32,
        seed_hi: (params.seed >> 32) as u32,
        pass_index: 0,
        sample_count: 0,
    };
    ctx.queue
        .write_buffer(&scene.pass, 0, bytemuck::bytes_of(&seed));
    let placed = ctx.scoped("placing the internal lights", || {
        let params_buf = uniform(ctx, "placement uniform", &placement_params);
        let placed = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("placed internal lights"),
            size: placed_bytes,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let group = bind_group(
            ctx,
            "placement",
            &pipeline,
            &scene,
            &[
                (5, &params_buf),
                (6, &alias_buf),
                (7, &corners),
                (8, &placed),
            ],
        );
        dispatch(
            ctx,
            "placement",
            &pipeline,
            &group,
            light_count.div_ceil(PLACEMENT_LANES),
        );
        placed
    })?;
    Ok(Build {
        ctx: ctx.clone(),
        scene,
        placed,
        light_count,
        density_integral: density.density_integral(),
    })
}

/// Runs the walks for the placed lights; returns the placed lights and the
/// per-light records, read back.
fn walk(
    build: &Build,
    prepared: &PreparedScene,
    params: &InternalParams,
) -> Result<(Vec<Vec4>, Vec<Vec4>, Walked), GpuError> {
    let ctx = &build.ctx;
    let order = params.sh_order.min(MAX_ORDER);
    let count = sh_count(order) as u32;
    let n_ext = (prepared.lights.suns.len() + prepared.lights.points.len()) as u32;
    let phase = gpu_phase_walks(params, prepared);
    let stride = record_stride(params, n_ext as usize, phase);
    let walks = params.walks.max(1);
    let out_bytes = build.light_count as u64 * stride as u64 * 16;
    ctx.check_storage_size("internal-light walk results", out_bytes)?;
    let pipeline = compute_pipeline(ctx, &WALKS_MODULE)?;
    let mut walk_params = GpuWalkParams {
        s_star: params.s_star,
        n_terms: params.terms,
        clock: params.clock.tag(),
        rr_start: RR_START_DEPTH,
        walks,
        sh_order: order,
        sh_count: count,
        tr_estimates: (walks / 4).clamp(4, 64),
        light_count: build.light_count,
        light_offset: 0,
        walk_offset: 0,
        record_stride: stride,
        eye: params.eye.to_array(),
        view_walks: params.view_walks,
        phase_walks: phase,
        majorant_peak: prepared.volume.majorants.peak,
        _pad1: 0,
        _pad2: 0,
    };
    let (params_buf, out, group) = ctx.scoped("setting up the internal-light walks", || {
        let params_buf = uniform(ctx, "walk uniform", &walk_params);
        let out = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("internal-light walk results"),
            size: out_bytes.max(16),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let group = bind_group(
            ctx,
            "walks",
            &pipeline,
            &build.scene,
            &[(5, &params_buf), (6, &build.placed), (7, &out)],
        );
        (params_buf, out, group)
    })?;
    let full = WalkCounts {
        spread: walks,
        view: params.view_walks,
        phase,
    };
    // One dispatch per block of 64 walks and of at most MAX_GROUPS lights;
    // each adds its sums to `out` (zeroed at creation).
    let mut run = |lights: std::ops::Range<u32>, counts: WalkCounts| {
        walk_params.walks = counts.spread;
        walk_params.view_walks = counts.view;
        walk_params.phase_walks = counts.phase;
        for walk_offset in (0..counts.total()).step_by(WALK_LANES as usize) {
            for light_offset in lights.clone().step_by(MAX_GROUPS as usize) {
                walk_params.walk_offset = walk_offset;
                walk_params.light_offset = light_offset;
                ctx.queue
                    .write_buffer(&params_buf, 0, bytemuck::bytes_of(&walk_params));
                let groups = (lights.end - light_offset).min(MAX_GROUPS);
                dispatch(ctx, "walks", &pipeline, &group, groups);
            }
        }
    };
    let walked = match params.walk_deadline {
        None => {
            ctx.scoped("running the internal-light walks", || {
                run(0..build.light_count, full)
            })?;
            Walked {
                spread: full.spread,
                share: 1.0,
            }
        }
        Some(deadline) => walk_within(ctx, build.light_count, full, deadline, |lights, counts| {
            ctx.scoped("running the internal-light walks", || run(lights, counts))
        })?,
    };
    let placed = read_buffer(ctx, &build.placed, "the placed lights")?;
    let records = read_buffer(ctx, &out, "the internal-light walk results")?;
    Ok((placed, records, walked))
}

/// Walks of each kind per light in one dispatch: spread (the harmonics,
/// `F`, the energies), towards the eye, phase-turned. The shader weighs
/// each light's sums by its dispatch's counts (`4π/K`, `1/K_v`, `1/K_p`),
/// so lights walked with fewer are unbiased, only noisier.
#[derive(Clone, Copy, Debug, PartialEq)]
struct WalkCounts {
    spread: u32,
    view: u32,
    phase: u32,
}

impl WalkCounts {
    /// Walks per light in all.
    fn total(self) -> u32 {
        self.spread + self.view + self.phase
    }

    /// These counts scaled by `share` (`0 ..= 1`), rounded, each kind
    /// keeping at least one walk where it has any: the records keep their
    /// layout and every light its estimates.
    fn scaled(self, share: f64) -> Self {
        let scale = |k: u32| {
            if k == 0 {
                0
            } else {
                ((f64::from(k) * share).round() as u32).clamp(1, k)
            }
        };
        Self {
            spread: scale(self.spread),
            view: scale(self.view),
            phase: scale(self.phase),
        }
    }
}

/// What a build walked: the fewest spread walks of any light, and the
/// share of a whole set's walks.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Walked {
    spread: u32,
    share: f64,
}

/// Lights in each of the first two dispatches of a build with a deadline,
/// as a share of the set (at least [`WALK_LANES`] lights): their times
/// tell what the rest may walk.
const DEADLINE_FIRST_SHARE: u32 = 64;

/// Dispatches over which the rest of a build with a deadline is spread.
const DEADLINE_CHUNKS: u32 = 16;

/// A dispatch's seconds per light against its walks per light, fitted as
/// `f + w · walks` over the dispatches timed so far (least squares,
/// weighted by their lights): a light costs more than its walks (its
/// arriving light, the workgroup's sums over the terms; on lavapipe about
/// a fifth of a thick cumulus's whole set).
#[derive(Default)]
struct LightCost {
    /// Σ n, Σ n x, Σ n y, Σ n x², Σ n x y over the dispatches (`n` lights,
    /// `x` walks per light, `y` seconds per light).
    sums: [f64; 5],
}

impl LightCost {
    fn add(&mut self, lights: u32, walks: u32, secs: f64) {
        let (n, x) = (f64::from(lights), f64::from(walks));
        let y = secs / n.max(1.0);
        for (s, v) in self
            .sums
            .iter_mut()
            .zip([n, n * x, n * y, n * x * x, n * x * y])
        {
            *s += v;
        }
    }

    /// `(f, w)`: seconds per light and per walk; with one kind of dispatch
    /// so far, all of it per walk.
    fn fit(&self) -> (f64, f64) {
        let [n, sx, sy, sxx, sxy] = self.sums;
        let det = n * sxx - sx * sx;
        if n > 0.0 && det > 1e-9 * n * sxx {
            let w = ((n * sxy - sx * sy) / det).max(0.0);
            let f = ((sy - w * sx) / n).max(0.0);
            (f, w)
        } else {
            (0.0, sy / sx.max(f64::MIN_POSITIVE))
        }
    }
}

/// The walks of `lights` lights with `full` counts, as `run(range,
/// counts)` dispatches them, to end near `deadline`
/// ([`InternalParams::walk_deadline`]: a render with a time limit shorter
/// than a whole set's walks, as on a software driver, where the thick
/// cumulus's set takes 30 s). The first lights walk whole and are timed;
/// where the rest would end in time whole they walk so, in one dispatch;
/// otherwise the next as many walk one of each kind, and from the two a
/// cost per light and per walk
/// ([`LightCost`]) tells each later dispatch's share of `full`, at least
/// one walk of each kind per light. The CPU stops its rounds at the
/// deadline instead (every light then has the same walks); here a
/// dispatch's lights share its counts, and each light's sums are weighed
/// by its own. A set cannot take less than its lights' own cost: on
/// lavapipe the cumulus's 4096 lights take about 6 s however few walks.
fn walk_within(
    ctx: &GpuContext,
    lights: u32,
    full: WalkCounts,
    deadline: Instant,
    mut run: impl FnMut(std::ops::Range<u32>, WalkCounts) -> Result<(), GpuError>,
) -> Result<Walked, GpuError> {
    let first = (lights / DEADLINE_FIRST_SHARE).max(WALK_LANES);
    let chunk = (lights / DEADLINE_CHUNKS).max(WALK_LANES);
    let least = full.scaled(0.0);
    let mut cost = LightCost::default();
    let mut start = 0u32;
    let mut walked_walks = 0u64;
    let mut fewest = full.spread;
    let mut dispatches = 0u32;
    while start < lights {
        let left = deadline
            .saturating_duration_since(Instant::now())
            .as_secs_f64();
        let remaining = f64::from(lights - start);
        let (f, w) = cost.fit();
        let (counts, size) = match dispatches {
            0 => (full, first),
            // Whole from here on fits: the rest in one go, as without a
            // deadline. (A hardware GPU, which a small dispatch leaves
            // mostly idle, takes about as long for all the lights as for
            // the first few: there chunks would only add waits.)
            _ if remaining * (f + w * f64::from(full.total())) <= left => (full, lights - start),
            1 => (least, first),
            _ => {
                // The most walks per light the time left allows.
                let walks = (left / remaining - f) / w.max(f64::MIN_POSITIVE);
                (full.scaled(walks / f64::from(full.total())), chunk)
            }
        };
        let end = (start + size).min(lights);
        let t = Instant::now();
        run(start..end, counts)?;
        ctx.wait_idle()?;
        let secs = t.elapsed().as_secs_f64();
        cost.add(end - start, counts.total(), secs);
        walked_walks += u64::from(end - start) * u64::from(counts.total());
        fewest = fewest.min(counts.spread);
        start = end;
        dispatches += 1;
    }
    let whole = u64::from(lights) * u64::from(full.total());
    Ok(Walked {
        spread: fewest,
        share: if whole == 0 {
            1.0
        } else {
            walked_walks as f64 / whole as f64
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Scaled counts keep one walk of each kind a light has, and no walk
    /// of a kind it has none of; a share of one is the whole.
    #[test]
    fn scaled_counts_keep_each_kind() {
        let full = WalkCounts {
            spread: 16,
            view: 16,
            phase: 0,
        };
        assert_eq!(full.scaled(1.0), full);
        assert_eq!(full.scaled(2.0), full);
        let half = full.scaled(0.5);
        assert_eq!((half.spread, half.view, half.phase), (8, 8, 0));
        for share in [0.0, -3.0, f64::NAN, 0.01] {
            let least = full.scaled(share);
            assert_eq!(
                (least.spread, least.view, least.phase),
                (1, 1, 0),
                "{share}"
            );
        }
    }

    /// The cost fit recovers a cost per light and per walk from dispatches
    /// of two sizes of walks, and puts all of it on the walks while it has
    /// seen one size only.
    #[test]
    fn light_cost_fits_per_light_and_per_walk() {
        let (f, w) = (1.0e-3, 0.15e-3);
        let secs = |lights: u32, walks: u32| f64::from(lights) * (f + w * f64::from(walks));
        let mut cost = LightCost::default();
        cost.add(64, 36, secs(64, 36));
        let (f0, w0) = cost.fit();
        assert_eq!(f0, 0.0);
        assert!((w0 * 36.0 - (f + 36.0 * w)).abs() < 1e-12);
        cost.add(64, 3, secs(64, 3));
        cost.add(256, 7, secs(256, 7));
        let (f1, w1) = cost.fit();
        assert!((f1 - f).abs() < 1e-9 && (w1 - w).abs() < 1e-9, "{f1} {w1}");
    }
}
