//! Floors: the bytes a Jacobi PCG iteration (wgsl/pcg.wgsl `next` and
//! `update`; the fused loops of src/cpu/pcg.rs), a multigrid one
//! (src/cpu/multigrid.rs) and each other stage of a step must move between
//! memory and the processor if every array they touch crosses once, and
//! the copy bandwidth that moves them; the multiply-adds the contact
//! stage's network must do, and the rate of independent multiply-adds.

use std::time::Instant;

use rayon::prelude::*;
use serde::Serialize;

use wgcloth::config::Smoother;
use wgcloth::error::Result;
use wgcloth::gpu::GpuContext;
use wgcloth::gpu::layout::{self, VectorLayout};
use wgcloth::math::Sym3;
use wgcloth::multigrid::{
    COARSE_SWEEPS, Level, PATCH_BLOCKS, PATCH_UNKNOWNS, STORED_STENCIL, patch_grid,
};
use wgcloth::stage::Stage;

use crate::run::Report;

/// How a backend stores the solver's data, in bytes.
#[derive(Clone, Copy, Debug)]
pub struct Layout {
    /// One vertex's entry of a state vector (positions, velocities: PCG's x).
    pub vector: u64,
    /// One vertex's entry of a solver vector (b, r, z, p, q, P⁻¹, the
    /// multigrid levels').
    pub solver_vector: u64,
    /// A diagonal block of A.
    pub diag_block: u64,
    /// A spring's off-diagonal block of A.
    pub off_block: u64,
    /// A vertex's pinned flag.
    pub flag: u64,
    /// Vector entries one iteration reads or writes per vertex.
    pub vectors_per_iteration: u64,
    /// A multigrid patch's inverse (the patch smoother).
    pub patch_inverse: u64,
    /// A contact slot, its response, and a spring's force and block.
    pub contact: u64,
    pub response: u64,
    pub spring_term: u64,
}

/// What one step's stages work over.
#[derive(Clone, Copy, Debug)]
pub struct Extent {
    pub vertices: u64,
    pub springs: u64,
    pub triangles: u64,
    pub body_vertices: u64,
    /// Contacts per step (the row's mean).
    pub contacts: f64,
    /// A contact's network multiply-adds, forward and reverse-mode
    /// Jacobian (`Network::jacobian_multiply_adds`; 0 for an analytic model).
    pub network_multiply_adds: u64,
}

/// Multiply-adds `stage` must do once per step over `e`: the contact
/// stage's network, by reverse mode (the least of the two modes for these
/// networks: one pass per output, where forward mode takes one per
/// Jacobian input). The other stages' arithmetic is a few operations per
/// byte they move, and is left to the memory floor.
pub fn stage_multiply_adds(stage: Stage, e: &Extent) -> f64 {
    match stage {
        Stage::Contact => e.contacts * e.network_multiply_adds as f64,
        _ => 0.0,
    }
}

/// wgsl/pcg.wgsl: `vec4<f32>` positions and velocities, the solver's
/// vectors as `vectors` lays them out, packed `Sym3` blocks (6 floats), u32
/// flags; the blocks, slots and spring terms as `gpu::layout` holds them.
/// Per vertex `next` reads z and p and writes p' and q; `update` reads and
/// writes x and r, reads p, q and P⁻¹ and writes z: 12 vectors.
pub const fn gpu(vectors: VectorLayout) -> Layout {
    Layout {
        vector: 16,
        solver_vector: vectors.bytes(),
        diag_block: size_of::<Sym3>() as u64,
        off_block: size_of::<Sym3>() as u64,
        flag: 4,
        vectors_per_iteration: 12,
        patch_inverse: PATCH_BLOCKS as u64 * size_of::<Sym3>() as u64,
        contact: size_of::<layout::Contact>() as u64,
        response: size_of::<layout::Response>() as u64,
        // Each spring's force and block is computed where it is gathered.
        spring_term: 0,
    }
}

/// src/cpu/pcg.rs: `Vec3` vectors, `Sym3` blocks, bool flags. Per vertex
/// `spmv` reads p and writes q; `update` reads and writes x and r, reads
/// p, q and P⁻¹ and writes z; `direction` reads z and reads and writes p:
/// 13 vectors.
pub const CPU: Layout = Layout {
    vector: 12,
    solver_vector: 12,
    diag_block: size_of::<Sym3>() as u64,
    off_block: size_of::<Sym3>() as u64,
    flag: 1,
    vectors_per_iteration: 13,
    patch_inverse: (PATCH_UNKNOWNS * PATCH_UNKNOWNS * 4) as u64,
    contact: size_of::<wgcloth::cpu::collide::Contact>() as u64,
    response: size_of::<wgcloth::cpu::contact::Response>() as u64,
    spring_term: 12 + size_of::<Sym3>() as u64,
};

/// The layout a run's report says its backend used: the GPU's with the
/// vectors it names, else the CPU's.
pub fn of(report: &Report) -> Layout {
    let vectors = report.gpu_vectors.as_deref().and_then(VectorLayout::named);
    match (report.backend.as_str(), vectors) {
        ("gpu", Some(vectors)) => gpu(vectors),
        _ => CPU,
    }
}

impl Layout {
    /// Bytes one Jacobi iteration must move for `vertices` and `springs`:
    /// A once ([`Self::matrix_bytes`]) and the vector entries, x's read
    /// and written and the solver vectors' (neighbours' come from cache).
    pub fn iteration_bytes(&self, vertices: u64, springs: u64) -> u64 {
        let entries = 2 * self.vector + (self.vectors_per_iteration - 2) * self.solver_vector;
        self.matrix_bytes(vertices, springs) + vertices * entries
    }

    /// Bytes of A: per vertex its diagonal block, pinned flag and adjacency
    /// offset; per spring its off-diagonal block and its two adjacency
    /// entries (spring and neighbour index, u32 each) at each end.
    fn matrix_bytes(&self, vertices: u64, springs: u64) -> u64 {
        vertices * (self.diag_block + self.flag + 4) + springs * (self.off_block + 2 * 8)
    }

    /// Bytes one multigrid-preconditioned iteration must move: Jacobi's
    /// [`Self::iteration_bytes`] (the cycle's rᵀz pass, r and z read, moves
    /// what Jacobi's P⁻¹ read and z write do), then the V(1,1)-cycle of
    /// src/cpu/multigrid.rs with every array crossing once per pass that
    /// reads it. At each level but the coarsest the operator (A, or the
    /// coarse stencils) crosses twice, once for the residual after
    /// pre-smoothing and once for the post-smoothing sweep, and the
    /// smoother blocks twice; the pre, residual, restriction, guess and post
    /// passes move ten vectors per node and two per coarse node. With the
    /// patch smoother the forward sweeps and the residual after them
    /// together need each block of the operator once (a node's sweep the
    /// colours before its own, its residual the ones after), the backward
    /// sweeps once more, each sweep the patch inverses once, and eleven
    /// vectors per node. The coarsest level
    /// runs its sweeps over its stencils. A V-cycle cannot fuse below two
    /// operator passes per level: each sweep needs its neighbours' result
    /// of the one before.
    pub fn multigrid_iteration_bytes(
        &self,
        levels: &[Level],
        springs: u64,
        smoother: Smoother,
    ) -> u64 {
        let v = self.solver_vector;
        let vertices = levels[0].nodes() as u64;
        let operator = |l: usize| match l {
            0 => self.matrix_bytes(vertices, springs),
            _ => levels[l].nodes() as u64 * STORED_STENCIL as u64 * self.off_block,
        };
        let last = levels.len() - 1;
        let cycle: u64 = (0..last)
            .map(|l| {
                let (n, coarse) = (levels[l].nodes() as u64, levels[l + 1].nodes() as u64);
                let smoothing = match smoother {
                    Smoother::BlockJacobi => 2 * operator(l) + n * (2 * self.diag_block + 10 * v),
                    Smoother::Patches => {
                        let (px, py) = patch_grid(levels[l]);
                        2 * operator(l) + 2 * (px * py) as u64 * self.patch_inverse + n * 11 * v
                    }
                };
                smoothing + coarse * 2 * v
            })
            .sum();
        let coarsest =
            levels[last].nodes() as u64 * (self.diag_block + 2 * v) * COARSE_SWEEPS as u64
                + COARSE_SWEEPS as u64 * operator(last);
        self.iteration_bytes(vertices, springs) + cycle + coarsest
    }

    /// Bytes `stage` must move once per step over `e`, every array it
    /// touches crossing once (`None` for pcg, whose floor is per iteration,
    /// [`Self::iteration_bytes`]):
    /// - rigid: each body vertex and normal read and written placed;
    /// - collide: the positions read, a vertex–face slot written per cloth
    ///   vertex, the cloth's triangles and the placed body read and a
    ///   face–vertex slot written per body vertex;
    /// - contact: each contact's slot read, its response written, the
    ///   velocities of its three vertices read;
    /// - assemble: the positions and v read, b and A's diagonal block
    ///   written, each adjacency offset read; per spring its ends and rest
    ///   length and two adjacency entries read, its off-diagonal block
    ///   written, and where a layout stores spring terms (the CPU's) each
    ///   written once and read twice;
    /// - self_contact: the positions read, two counts written per vertex,
    ///   its carried load read and its bound's scale written, its diagonal
    ///   block and b read and written, each triangle's and spring's vertex
    ///   indices read (the contacts found and the walks not counted);
    /// - load: per vertex its count read and its load written (its
    ///   contacts not counted, as self_contact's are not);
    /// - separate: the step's start and end positions read, a least
    ///   separation and a flag word written per vertex, each triangle's and
    ///   spring's vertex indices read (the walks over the tiles and the
    ///   rounds not counted, as collide's walks are not);
    /// - integrate: x and v read, x written, the pinned flag read;
    /// - measure: the positions read.
    pub fn stage_bytes(&self, stage: Stage, e: &Extent) -> Option<u64> {
        let (n, s, t, m) = (e.vertices, e.springs, e.triangles, e.body_vertices);
        let v = self.vector;
        Some(match stage {
            Stage::Rigid => 4 * m * v,
            Stage::Collide => n * (v + self.contact) + t * 12 + m * (2 * v + self.contact),
            Stage::Contact => (e.contacts * (self.contact + self.response + 3 * v) as f64) as u64,
            Stage::Assemble => {
                n * (2 * v + self.solver_vector + self.diag_block + 4)
                    + s * (12 + 16 + self.off_block + 3 * self.spring_term)
            }
            Stage::SelfContact => {
                n * (v + 2 * self.solver_vector + 16 + 2 * self.diag_block) + t * 12 + s * 8
            }
            Stage::Pcg => return None,
            Stage::Load => n * 8,
            Stage::Separate => n * (2 * v + 8) + t * 12 + s * 8,
            Stage::Integrate => n * (3 * v + self.flag),
            Stage::Measure => n * v,
        })
    }
}

/// Copy bandwidth of one backend, GB/s (read plus write bytes per second).
#[derive(Clone, Debug, Serialize)]
pub struct Bandwidth {
    pub backend: String,
    /// How it was measured.
    pub method: String,
    pub gb_per_s: f64,
}

/// Bytes copied per measurement: well past any cache.
const COPY_BYTES: u64 = 256 << 20;

/// Timed repeats; the best is the achievable bandwidth.
const REPEATS: usize = 5;

/// A parallel copy between two 256 MiB arrays on every rayon thread.
pub fn cpu_bandwidth() -> Bandwidth {
    let n = COPY_BYTES as usize / 4;
    let src = vec![1.0f32; n];
    let mut dst = vec![0.0f32; n];
    let mut best = f64::INFINITY;
    for _ in 0..REPEATS {
        let start = Instant::now();
        dst.par_chunks_mut(1 << 16)
            .zip(src.par_chunks(1 << 16))
            .for_each(|(d, s)| d.copy_from_slice(s));
        best = best.min(start.elapsed().as_secs_f64());
    }
    std::hint::black_box(&dst);
    Bandwidth {
        backend: "cpu".into(),
        method: format!(
            "parallel copy of 256 MiB on {} threads, best of {REPEATS}",
            rayon::current_num_threads()
        ),
        gb_per_s: 2.0 * COPY_BYTES as f64 / best * 1e-9,
    }
}

/// The GPU's copy bandwidth: the faster of `copy_buffer_to_buffer` and a
/// compute-shader copy, four copies of up to 256 MiB per submission each. A
/// hardware GPU's copy engine, behind `copy_buffer_to_buffer`, can be far
/// slower than its shaders (an H200 here: 0.8 TB/s), and the kernels move
/// their bytes with shaders, so the floor is the faster of the two.
pub fn gpu_bandwidth(ctx: &GpuContext) -> Result<Bandwidth> {
    let limits = ctx.device.limits();
    let bytes = COPY_BYTES.min(limits.max_buffer_size) & !15;
    let buffer = |usage, size| {
        ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("bandwidth"),
            size,
            usage,
            mapped_at_creation: false,
        })
    };
    let copies = 4;
    // Best of REPEATS (after one warm-up) of `copy` recording the copies
    // from `src`, written once so they move real data.
    let best = |src: &wgpu::Buffer, copy: &dyn Fn(&mut wgpu::CommandEncoder)| -> Result<f64> {
        let mut best = f64::INFINITY;
        for repeat in 0..=REPEATS {
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            encoder.clear_buffer(src, 0, None);
            ctx.queue.submit([encoder.finish()]);
            ctx.finish()?;
            let start = Instant::now();
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            copy(&mut encoder);
            ctx.queue.submit([encoder.finish()]);
            ctx.finish()?;
            if repeat > 0 {
                best = best.min(start.elapsed().as_secs_f64());
            }
        }
        Ok(best)
    };
    let gb_per_s = |bytes: u64, seconds: f64| 2.0 * (copies as u64 * bytes) as f64 / seconds * 1e-9;

    let src = buffer(
        wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
        bytes,
    );
    let dst = buffer(wgpu::BufferUsages::COPY_DST, bytes);
    let engine = gb_per_s(
        bytes,
        best(&src, &|encoder| {
            for _ in 0..copies {
                encoder.copy_buffer_to_buffer(&src, 0, &dst, 0, bytes);
            }
        })?,
    );
    drop((src, dst));

    let bound = bytes.min(limits.max_storage_buffer_binding_size) & !15;
    let storage = wgpu::BufferUsages::STORAGE;
    let (src, dst) = (
        buffer(storage | wgpu::BufferUsages::COPY_DST, bound),
        buffer(storage, bound),
    );
    let pipeline = pipeline(&ctx.device, GPU_COPY_WGSL, "copy");
    let bind = bind_group(&ctx.device, &pipeline, &[&src, &dst]);
    let groups = (bound / 16)
        .div_ceil(256)
        .min(limits.max_compute_workgroups_per_dimension as u64) as u32;
    let shader = gb_per_s(
        bound,
        best(&src, &|encoder| {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &bind, &[]);
            for _ in 0..copies {
                pass.dispatch_workgroups(groups, 1, 1);
            }
        })?,
    );
    let (engine_mib, shader_mib) = (bytes >> 20, bound >> 20);
    Ok(Bandwidth {
        backend: "gpu".into(),
        method: format!(
            "the faster of copy_buffer_to_buffer ({engine:.1} GB/s, {copies} × {engine_mib} MiB) and a compute-shader copy ({shader:.1} GB/s, {copies} × {shader_mib} MiB), best of {REPEATS}"
        ),
        gb_per_s: engine.max(shader),
    })
}

/// A vec4 copy, each invocation striding over the array.
const GPU_COPY_WGSL: &str = "
@group(0) @binding(0) var<storage, read> src: array<vec4<f32>>;
@group(0) @binding(1) var<storage, read_write> dst: array<vec4<f32>>;

@compute @workgroup_size(256)
fn copy(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    for (var i = id.x; i < arrayLength(&dst); i += groups.x * 256u) {
        dst[i] = src[i];
    }
}
";

/// A compute pipeline of one entry point of `wgsl`, its layout the shader's.
fn pipeline(device: &wgpu::Device, wgsl: &str, entry: &str) -> wgpu::ComputePipeline {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(entry),
        source: wgpu::ShaderSource::Wgsl(wgsl.into()),
    });
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(entry),
        layout: None,
        module: &module,
        entry_point: Some(entry),
        compilation_options: Default::default(),
        cache: None,
    })
}

/// Group 0 of `pipeline`, binding i the i-th buffer.
fn bind_group(
    device: &wgpu::Device,
    pipeline: &wgpu::ComputePipeline,
    buffers: &[&wgpu::Buffer],
) -> wgpu::BindGroup {
    let entries: Vec<wgpu::BindGroupEntry> = buffers
        .iter()
        .enumerate()
        .map(|(i, b)| wgpu::BindGroupEntry {
            binding: i as u32,
            resource: b.as_entire_binding(),
        })
        .collect();
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: None,
        layout: &pipeline.get_bind_group_layout(0),
        entries: &entries,
    })
}

/// Multiply-add rate of one backend: the floor of a stage whose work is
/// arithmetic (the network), as the copy bandwidth is of one that streams.
#[derive(Clone, Debug, Serialize)]
pub struct Arithmetic {
    pub backend: String,
    /// How it was measured.
    pub method: String,
    /// Multiply-adds per second, in billions.
    pub g_multiply_adds_per_s: f64,
}

/// Independent multiply-add chains per CPU thread, one 8-lane vector each:
/// enough in flight to cover the latency on both FMA pipes, few enough to
/// stay in the 16 AVX2 registers.
const CPU_CHAINS: usize = 12;
const CPU_LANES: usize = 8;
const CPU_CHAIN_STEPS: usize = 1 << 23;

/// a ← a m + c along every chain with AVX2's fused multiply-add; the sum
/// keeps the work observable. Written with the intrinsics: the compiler
/// does not vectorise the same loop over arrays.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn chains_avx2_fma(seed: f32) -> f32 {
    use std::arch::x86_64::{__m256, _mm256_add_ps, _mm256_fmadd_ps, _mm256_set1_ps};
    let (m, c) = (_mm256_set1_ps(0.999_999), _mm256_set1_ps(1e-7));
    let mut acc = [_mm256_set1_ps(seed); CPU_CHAINS];
    for _ in 0..CPU_CHAIN_STEPS {
        for a in &mut acc {
            *a = _mm256_fmadd_ps(*a, m, c);
        }
    }
    let sum = acc
        .into_iter()
        .fold(_mm256_set1_ps(0.0), |s, a| _mm256_add_ps(s, a));
    // SAFETY: __m256 is eight f32s.
    let lanes: [f32; CPU_LANES] = unsafe { std::mem::transmute::<__m256, [f32; CPU_LANES]>(sum) };
    lanes.iter().sum()
}

/// The same chains unfused, with whatever vectors the build's baseline has.
fn chains_baseline(seed: f32) -> f32 {
    let mut acc = [[seed; CPU_LANES]; CPU_CHAINS];
    for _ in 0..CPU_CHAIN_STEPS {
        for a in acc.iter_mut().flatten() {
            *a = *a * 0.999_999 + 1e-7;
        }
    }
    acc.iter().flatten().sum()
}

/// The chains with the instructions `nn::Mlp` picks at run time (AVX2 and
/// FMA where the CPU has them), and what they were.
fn cpu_chains(seed: f32) -> (f32, &'static str) {
    #[cfg(target_arch = "x86_64")]
    if wgcloth::nn::mlp::has_avx2_fma() {
        // SAFETY: the CPU has both features, checked just above.
        return (unsafe { chains_avx2_fma(seed) }, "AVX2 fused");
    }
    (chains_baseline(seed), "baseline unfused")
}

/// Independent multiply-add chains on every rayon thread at once.
pub fn cpu_arithmetic() -> Arithmetic {
    let threads = rayon::current_num_threads();
    let mut best = f64::INFINITY;
    let mut instructions = "";
    for _ in 0..REPEATS {
        let start = Instant::now();
        let out = rayon::broadcast(|c| cpu_chains(c.index() as f32 * 1e-6));
        best = best.min(start.elapsed().as_secs_f64());
        instructions = out[0].1;
        std::hint::black_box(out);
    }
    let per_thread = (CPU_CHAINS * CPU_LANES * CPU_CHAIN_STEPS) as f64;
    Arithmetic {
        backend: "cpu".into(),
        method: format!(
            "{CPU_CHAINS} × {CPU_LANES}-lane chains per thread, {instructions}, {threads} threads, best of {REPEATS}"
        ),
        g_multiply_adds_per_s: per_thread * threads as f64 / best * 1e-9,
    }
}

/// Three independent vec4 chains per invocation: on a CPU adapter each
/// lane of a SIMD register is an invocation, so three vec4s are 12 of its
/// 16 AVX2 registers; a GPU hides the latency with other invocations.
const GPU_CHAINS_WGSL: &str = "
@group(0) @binding(0) var<storage, read_write> out: array<vec4<f32>>;

@compute @workgroup_size(64)
fn chains(@builtin(global_invocation_id) id: vec3<u32>) {
    let m = vec4<f32>(0.999999);
    let c = vec4<f32>(1e-7);
    var a = vec4<f32>(f32(id.x) * 1e-9);
    var b = a + 1.0;
    var d = a + 2.0;
    for (var i = 0u; i < 4096u; i++) {
        a = fma(a, m, c);
        b = fma(b, m, c);
        d = fma(d, m, c);
    }
    out[id.x] = a + b + d;
}
";
const GPU_CHAIN_MULTIPLY_ADDS: u64 = 3 * 4 * 4096;
const GPU_GROUPS: u32 = 2048;

/// The chains of `GPU_CHAINS_WGSL` over 131,072 invocations per dispatch,
/// dispatched more times per pass until a pass takes 50 ms.
pub fn gpu_arithmetic(ctx: &GpuContext) -> Result<Arithmetic> {
    let device = &ctx.device;
    let pipeline = pipeline(device, GPU_CHAINS_WGSL, "chains");
    let invocations = GPU_GROUPS as u64 * 64;
    let out = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("arithmetic"),
        size: invocations * 16,
        usage: wgpu::BufferUsages::STORAGE,
        mapped_at_creation: false,
    });
    let bind = bind_group(device, &pipeline, &[&out]);
    let run = |dispatches: u32| {
        let start = Instant::now();
        let mut encoder = device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &bind, &[]);
            for _ in 0..dispatches {
                pass.dispatch_workgroups(GPU_GROUPS, 1, 1);
            }
        }
        ctx.queue.submit([encoder.finish()]);
        ctx.finish()?;
        Ok(start.elapsed().as_secs_f64())
    };
    let mut dispatches = 1;
    while run(dispatches)? < 0.05 && dispatches < 1 << 12 {
        dispatches *= 2;
    }
    let mut best = f64::INFINITY;
    for _ in 0..REPEATS {
        best = best.min(run(dispatches)?);
    }
    let multiply_adds = (dispatches as u64 * invocations * GPU_CHAIN_MULTIPLY_ADDS) as f64;
    Ok(Arithmetic {
        backend: "gpu".into(),
        method: format!(
            "3 vec4 fma chains per invocation, {dispatches} × {invocations} invocations per submission, best of {REPEATS}"
        ),
        g_multiply_adds_per_s: multiply_adds / best * 1e-9,
    })
}
