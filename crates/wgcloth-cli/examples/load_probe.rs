//! What a storage-buffer load costs the adapter, against the bytes it
//! moves: a probe for BENCHMARKS.md "What a load costs lavapipe".
//!
//! Mesa's llvmpipe (lavapipe) runs 8 invocations a SIMD row, and compiles a
//! load whose address differs between invocations as a loop over them
//! with a branch and a bounds check each; so a load costs per instruction,
//! not per byte. The kernels below time that on a cloth-sized problem:
//! - `empty`: a dispatch's fixed cost;
//! - `vec4 ×K` and `f32 ×K`: K loads an invocation from addresses that
//!   differ between invocations (all in cache), K = 4, 8, 16;
//! - `row, as next`: one row of A p' as `pcg.wgsl`'s `next` reads it on a
//!   grid cloth (12 springs a vertex inside): the spring and neighbour
//!   indices, the packed 6-float block, z and p at each neighbour;
//! - `row, least`: the fewest loads a row of a sparse A can take: both
//!   indices in one `vec2<u32>`, the block in two `vec4`s, p read.
//!
//! and, in the same run, `copy_buffer_to_buffer` of 64 MiB for the copy
//! rate the benchmarks' floors use. `cargo run --release --example
//! load_probe -- [GRID]` (default 128) prints each kernel's median ms per
//! dispatch and the ns a load costs per invocation.

use std::time::Instant;

use wgcloth::gpu::context::{GpuContext, describe, wait};
use wgpu::util::DeviceExt;

const SHADER: &str = r#"
struct Block { a: vec4<f32>, b: vec4<f32> }
struct PackedBlock { xx_yy: vec2<f32>, zz_xy: vec2<f32>, xz_yz: vec2<f32> }
@group(0) @binding(0) var<storage, read> topology: array<u32>;
@group(0) @binding(1) var<storage, read> pairs: array<vec2<u32>>;
@group(0) @binding(2) var<storage, read> packed: array<PackedBlock>;
@group(0) @binding(3) var<storage, read> blocks: array<Block>;
@group(0) @binding(4) var<storage, read> z: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read> p: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> q: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read> scalars: array<f32>;

override N: u32;
override LOADS: u32 = 4u;
const BETA: f32 = 0.5;

fn mul(m: Block, v: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(m.a.x * v.x + m.a.w * v.y + m.b.x * v.z,
                     m.a.w * v.x + m.a.y * v.y + m.b.y * v.z,
                     m.b.x * v.x + m.b.y * v.y + m.a.z * v.z);
}
fn unpack(m: PackedBlock) -> Block {
    return Block(vec4<f32>(m.xx_yy, m.zz_xy), vec4<f32>(m.xz_yz, 0.0, 0.0));
}
// An address every invocation reads differently, spread over the array.
fn spread(i: u32, k: u32) -> u32 {
    return (i * 7u + k * 131u) % N;
}

@compute @workgroup_size(256)
fn empty(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x < N && scalars[0] < 0.0 {
        q[id.x] = vec4<f32>(0.0);
    }
}

@compute @workgroup_size(256)
fn vec4_loads(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= N { return; }
    var acc = vec4<f32>(0.0);
    for (var k = 0u; k < LOADS; k++) {
        acc += z[spread(i, k)];
    }
    q[i] = acc;
}

@compute @workgroup_size(256)
fn f32_loads(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= N { return; }
    var acc = 0.0;
    for (var k = 0u; k < LOADS; k++) {
        acc += scalars[spread(i, k)];
    }
    q[i] = vec4<f32>(acc);
}

fn direction(j: u32) -> vec3<f32> {
    return z[j].xyz + BETA * p[j].xyz;
}

@compute @workgroup_size(256)
fn row_as_next(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= N { return; }
    var acc = mul(unpack(packed[i]), direction(i));
    for (var k = topology[i]; k < topology[i + 1u]; k++) {
        let spring = topology[N + 1u + 2u * k];
        let j = topology[N + 2u + 2u * k];
        acc += mul(unpack(packed[N + spring]), direction(j));
    }
    q[i] = vec4<f32>(acc, 0.0);
}

@compute @workgroup_size(256)
fn row_least(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= N { return; }
    var acc = mul(blocks[i], p[i].xyz);
    for (var k = topology[i]; k < topology[i + 1u]; k++) {
        let e = pairs[k];
        acc += mul(blocks[N + e.x], p[e.y].xyz);
    }
    q[i] = vec4<f32>(acc, 0.0);
}
"#;

/// A grid cloth's springs (structural, shear, bend), as the cloth has them.
fn grid_springs(n: usize) -> Vec<(u32, u32)> {
    let mut springs = Vec::new();
    for r in 0..n {
        for c in 0..n {
            for (dc, dr) in [(1i64, 0i64), (0, 1), (1, 1), (-1, 1), (2, 0), (0, 2)] {
                let (c2, r2) = (c as i64 + dc, r as i64 + dr);
                if (0..n as i64).contains(&c2) && (0..n as i64).contains(&r2) {
                    springs.push(((r * n + c) as u32, (r2 as usize * n + c2 as usize) as u32));
                }
            }
        }
    }
    springs
}

/// CSR offsets and, per entry, (spring, neighbour), neighbours ascending.
fn adjacency(vertices: usize, springs: &[(u32, u32)]) -> (Vec<u32>, Vec<[u32; 2]>) {
    let mut rows = vec![Vec::new(); vertices];
    for (s, &(a, b)) in springs.iter().enumerate() {
        rows[a as usize].push([s as u32, b]);
        rows[b as usize].push([s as u32, a]);
    }
    let mut offsets = vec![0u32];
    let mut entries = Vec::new();
    for mut row in rows {
        row.sort_by_key(|e| e[1]);
        entries.extend(row);
        offsets.push(entries.len() as u32);
    }
    (offsets, entries)
}

fn main() -> Result<(), wgcloth::Error> {
    let grid: usize = match std::env::args().nth(1) {
        Some(a) => a.parse().map_err(|_| wgcloth::Error::Config {
            field: "GRID".into(),
            reason: format!("{a:?} is not a whole number"),
        })?,
        None => 128,
    };
    let ctx = GpuContext::headless_with(wgpu::Features::empty())?;
    let (device, queue) = (&ctx.device, &ctx.queue);
    let n = grid * grid;
    let springs = grid_springs(grid);
    let (offsets, entries) = adjacency(n, &springs);
    let blocks = n + springs.len();
    println!(
        "{} — {grid}² ({n} vertices, {} springs)",
        describe(&ctx.adapter),
        springs.len()
    );

    let mut topology = offsets;
    topology.extend(entries.iter().flatten());
    let block = |k: usize| {
        if k < n {
            [4.0, 4.1, 4.2, 0.01, 0.02, 0.03]
        } else {
            [-0.3, -0.2, -0.1, 0.01, 0.02, 0.03]
        }
    };
    let packed: Vec<f32> = (0..blocks).flat_map(block).collect();
    let full: Vec<f32> = (0..blocks)
        .flat_map(|k| block(k).into_iter().chain([0.0, 0.0]))
        .collect();
    let vectors: Vec<f32> = (0..4 * n).map(|k| (k % 7) as f32 * 0.1).collect();
    let storage = |contents: &[u8]| {
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: None,
            contents,
            usage: wgpu::BufferUsages::STORAGE,
        })
    };
    let buffers = [
        storage(bytemuck::cast_slice(&topology)),
        storage(bytemuck::cast_slice(&entries)),
        storage(bytemuck::cast_slice(&packed)),
        storage(bytemuck::cast_slice(&full)),
        storage(bytemuck::cast_slice(&vectors)),
        storage(bytemuck::cast_slice(&vectors)),
        storage(bytemuck::cast_slice(&vectors)),
        storage(bytemuck::cast_slice(&vectors)),
    ];
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("load_probe"),
        source: wgpu::ShaderSource::Wgsl(SHADER.into()),
    });
    let reps = 20;
    let rounds = 9;
    let time = |entry: &str, loads: u32| -> Result<f64, wgcloth::Error> {
        let constants = [("N", n as f64), ("LOADS", loads as f64)];
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(entry),
            layout: None,
            module: &module,
            entry_point: Some(entry),
            compilation_options: wgpu::PipelineCompilationOptions {
                constants: &constants,
                ..Default::default()
            },
            cache: None,
        });
        let layout = pipeline.get_bind_group_layout(0);
        // The automatic layout holds only what the entry point uses.
        let used: &[u32] = match entry {
            "empty" => &[6, 7],
            "vec4_loads" => &[4, 6],
            "f32_loads" => &[6, 7],
            "row_as_next" => &[0, 2, 4, 5, 6],
            _ => &[0, 1, 3, 5, 6],
        };
        let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &layout,
            entries: &used
                .iter()
                .map(|&b| wgpu::BindGroupEntry {
                    binding: b,
                    resource: buffers[b as usize].as_entire_binding(),
                })
                .collect::<Vec<_>>(),
        });
        let mut times = (0..rounds)
            .map(|_| {
                let mut encoder = device.create_command_encoder(&Default::default());
                {
                    let mut pass = encoder.begin_compute_pass(&Default::default());
                    pass.set_pipeline(&pipeline);
                    pass.set_bind_group(0, &bind, &[]);
                    for _ in 0..reps {
                        pass.dispatch_workgroups(n.div_ceil(256) as u32, 1, 1);
                    }
                }
                let start = Instant::now();
                queue.submit([encoder.finish()]);
                wait(device)?;
                Ok(start.elapsed().as_secs_f64() * 1e3 / reps as f64)
            })
            .collect::<Result<Vec<f64>, wgcloth::Error>>()?;
        times.sort_by(f64::total_cmp);
        Ok(times[rounds / 2])
    };

    let empty = time("empty", 0)?;
    println!("{:<14} {:>9} {:>13}", "kernel", "ms", "ns/load/inv");
    println!("{:<14} {empty:>9.3}", "empty");
    for entry in ["vec4_loads", "f32_loads"] {
        for loads in [4, 8, 16] {
            let ms = time(entry, loads)?;
            let per_load = (ms - empty) * 1e6 / (n as f64 * loads as f64);
            let name = format!("{} ×{loads}", entry.trim_end_matches("_loads"));
            println!("{name:<14} {ms:>9.3} {per_load:>13.2}");
        }
    }
    // Loads per row: z and p at 12 neighbours, 2 indices, 3 vec2 of the
    // block (or the 1 index pair, 2 vec4s and p) and the diagonal's.
    for (entry, name, loads) in [
        ("row_as_next", "row, as next", 5 + 12 * 7),
        ("row_least", "row, least", 5 + 12 * 4),
    ] {
        let ms = time(entry, 0)?;
        let per_load = (ms - empty) * 1e6 / (n as f64 * loads as f64);
        println!("{name:<14} {ms:>9.3} {per_load:>13.2}   ({loads} loads a vertex inside)");
    }

    let bytes = 64u64 << 20;
    let buffer = |usage| {
        device.create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size: bytes,
            usage,
            mapped_at_creation: false,
        })
    };
    let (from, to) = (
        buffer(wgpu::BufferUsages::COPY_SRC),
        buffer(wgpu::BufferUsages::COPY_DST),
    );
    let mut copies = (0..rounds)
        .map(|_| {
            let mut encoder = device.create_command_encoder(&Default::default());
            encoder.copy_buffer_to_buffer(&from, 0, &to, 0, bytes);
            let start = Instant::now();
            queue.submit([encoder.finish()]);
            wait(device)?;
            Ok(start.elapsed().as_secs_f64())
        })
        .collect::<Result<Vec<f64>, wgcloth::Error>>()?;
    copies.sort_by(f64::total_cmp);
    println!(
        "copy           {:.1} GB/s (64 MiB read and written)",
        2.0 * bytes as f64 / copies[rounds / 2] / 1e9
    );
    Ok(())
}
