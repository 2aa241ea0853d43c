//! A collision network on the GPU (stages "mlp" and "batch"): the weights,
//! activations and dispatches of one network for batches of up to
//! `capacity` contacts. The batch's inputs, size and outputs live in
//! buffers the caller owns (the step's contact stage, a benchmark, a test),
//! and the size is read on the GPU, so a batch needs no readback.
//!
//! Two kernels evaluate it: `layer`, one tiled matrix product per layer
//! through workgroup memory, for GPUs; and `per_contact`, one contact per
//! invocation without barriers, its Jacobian in forward mode with the
//! tangents in the lanes of each unit's vec4, for CPU adapters such as
//! lavapipe, which run it 2.8× (the thesis-size network) to 13× faster
//! than `layer`.

use std::ops::Range;

use bytemuck::{Pod, Zeroable};
use wgpu::util::DeviceExt;

use crate::error::{Error, Result};
use crate::gpu::constants::{BATCH_GROUP, WORKGROUP};
#[cfg(not(target_arch = "wasm32"))]
use crate::gpu::context::read_buffer;
use crate::gpu::kernels::{Bound, Entry, Kernels};
use crate::gpu::pass::Pass;
use crate::nn::Mlp;

/// Mirrors `LayerParams` in wgsl/mlp.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct LayerParams {
    /// This layer's inputs.
    pub inputs: u32,
    /// This layer's outputs.
    pub outputs: u32,
    /// Where the layer's weights start in the weights buffer, in `f32`s.
    pub weight_offset: u32,
    /// Where its biases start.
    pub bias_offset: u32,
    /// R = 1 + T: the value row and one tangent row per Jacobian input.
    pub rows_per_contact: u32,
    /// The first input the Jacobian is taken along.
    pub wrt_start: u32,
    /// Nonzero for the first layer, which loads the batch inputs and unit seeds.
    pub first: u32,
    /// The chunk's first contact in the batch.
    pub chunk_start: u32,
    /// Most contacts per chunk.
    pub chunk_contacts: u32,
    /// Last layer: the output row the chunk's rows start at; 0 otherwise.
    pub out_row_offset: u32,
    /// Slope of the activation for negative inputs (leaky ReLU).
    pub negative_slope: f32,
    /// Layers of the network.
    pub n_layers: u32,
    /// `per_contact`: the unit slots of a layer's inputs, where its
    /// outputs start (the other half).
    pub units_half: u32,
    /// Padding to the WGSL size.
    pub pad: [u32; 3],
}

/// Mirrors `BatchParams` in wgsl/batch.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct BatchParams {
    /// Chunks of the batch.
    pub n_chunks: u32,
    /// Dispatches per chunk: the network's layers (tiled) or one
    /// (`per_contact`).
    pub per_chunk: u32,
    /// Most contacts per chunk.
    pub chunk_contacts: u32,
    /// Rows per contact: 1 + the Jacobian columns (tiled), or 1
    /// (`per_contact`, one invocation a contact).
    pub rows_per_contact: u32,
    /// Rows per workgroup of a chunk's dispatches: the `layer` kernel's
    /// tile, or `per_contact`'s workgroup size.
    pub rows_per_group: u32,
    /// Workgroup size of the caller's per-contact pass after the network.
    pub threads_per_contact_group: u32,
    /// Padding to the WGSL size.
    pub pad: [u32; 2],
}

/// Most Jacobian columns `per_contact_wide` carries: two vec4s a unit,
/// less the value.
const PER_CONTACT_MAX_COLUMNS: usize = 7;

/// Most contacts in one `per_contact` dispatch, whose activations it
/// holds: a CPU adapter's threads stay busy with far fewer, and the
/// thesis-size network's take 64 MiB.
const PER_CONTACT_CHUNK: usize = 4096;

/// Mesa's llvmpipe ends an invocation after this many loop iterations
/// (`LP_MAX_TGSI_LOOP_ITERATIONS`), silently.
const LAVAPIPE_LOOP_LIMIT: usize = 65_535;

/// Vec4s per unit of `per_contact` for `rows` rows: 1, or 2 (`per_contact_wide`).
fn quads_per_unit(rows: usize) -> usize {
    rows.div_ceil(4)
}

/// Loop iterations of one `per_contact` invocation (an upper bound): the
/// seeds, then per quad of outputs one iteration per input and four to
/// store them, and each output's rows.
fn per_contact_iterations(net: &Mlp, rows: usize) -> usize {
    let layers: usize = net
        .layers
        .iter()
        .map(|l| 1 + l.outputs.div_ceil(4) * (l.inputs + 5))
        .sum();
    net.inputs() + layers + net.outputs() * rows
}

/// `per_contact`'s unit slots for one contact: a layer's inputs, then
/// from the half its outputs (whole quads of them), `quads_per_unit`
/// vec4s a unit.
fn per_contact_half(net: &Mlp, rows: usize) -> usize {
    let widest = net
        .layers
        .iter()
        .map(|l| l.inputs.max(l.outputs.next_multiple_of(4)))
        .max()
        .unwrap_or(0);
    widest * quads_per_unit(rows)
}

/// Why `per_contact` cannot evaluate `net` with `rows` rows here, if it
/// cannot.
fn per_contact_misfit(net: &Mlp, rows: usize, bindable: u64, software: bool) -> Option<String> {
    if rows > 1 + PER_CONTACT_MAX_COLUMNS {
        return Some(format!(
            "the per-contact kernel carries up to {PER_CONTACT_MAX_COLUMNS} Jacobian columns, not {}",
            rows - 1
        ));
    }
    let units = units_bytes(net, rows);
    if units > bindable {
        return Some(format!(
            "the per-contact kernel's activations need {units} bytes per contact, more than this adapter binds ({bindable} bytes)"
        ));
    }
    let iterations = per_contact_iterations(net, rows);
    (software && iterations > LAVAPIPE_LOOP_LIMIT).then(|| {
        format!(
            "the per-contact kernel takes {iterations} loop iterations per contact for this network, more than the {LAVAPIPE_LOOP_LIMIT} a CPU adapter runs"
        )
    })
}

/// Bytes of `per_contact`'s activations per contact: both halves of its
/// unit slots.
fn units_bytes(net: &Mlp, rows: usize) -> u64 {
    (2 * per_contact_half(net, rows) * 16) as u64
}

/// The tiled kernel's packing: every layer's weights, row-major, then its
/// biases; and per layer (inputs, outputs, weight offset, bias offset).
fn pack(net: &Mlp) -> (Vec<f32>, Vec<u32>) {
    let (mut weights, mut table) = (Vec::new(), Vec::new());
    for l in &net.layers {
        let offset = weights.len();
        weights.extend(&l.weight);
        table.extend([l.inputs, l.outputs, offset, weights.len()].map(|v| v as u32));
        weights.extend(&l.bias);
    }
    (weights, table)
}

/// `per_contact`'s packing: per layer, for each quad of outputs its
/// weights input by input (one vec4 of four outputs' weights per input),
/// then the biases by quads, outputs past the layer's zero; and per layer
/// (inputs, outputs, weight offset, bias offset), offsets in vec4s.
fn pack_quads(net: &Mlp) -> (Vec<f32>, Vec<u32>) {
    let (mut weights, mut table) = (Vec::new(), Vec::new());
    for l in &net.layers {
        let quads = l.outputs.div_ceil(4);
        let offset = weights.len() / 4;
        for q in 0..quads {
            for k in 0..l.inputs {
                weights.extend((4 * q..4 * q + 4).map(|o| {
                    if o < l.outputs {
                        l.weight[o * l.inputs + k]
                    } else {
                        0.0
                    }
                }));
            }
        }
        table.extend([l.inputs, l.outputs, offset, weights.len() / 4].map(|v| v as u32));
        weights.extend(&l.bias);
        weights.resize(weights.len() + 4 * quads - l.outputs, 0.0);
    }
    (weights, table)
}

/// Which kernel evaluates the network.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NetworkKernel {
    /// `per_contact` on a CPU adapter when the network fits it, else `layer`.
    Auto,
    /// `layer`: one tiled matrix product per layer, for GPUs.
    Tiled,
    /// `per_contact`: one contact per invocation, for CPU adapters.
    PerContact,
}

impl NetworkKernel {
    /// Its name in reports: "auto", "tiled" or "per-contact".
    pub fn name(self) -> &'static str {
        match self {
            NetworkKernel::Auto => "auto",
            NetworkKernel::Tiled => "tiled",
            NetworkKernel::PerContact => "per-contact",
        }
    }
}

/// How large a batch is and how it runs.
#[derive(Clone, Copy, Debug)]
pub struct BatchShape {
    /// Most contacts a batch holds.
    pub capacity: usize,
    /// Most contacts per chunk of the tiled kernel (the limits may lower it).
    pub max_chunk: usize,
    /// Which kernel evaluates the network.
    pub kernel: NetworkKernel,
}

impl BatchShape {
    /// Up to `capacity` contacts, chunked only as the limits require, the
    /// kernel chosen automatically.
    pub fn new(capacity: usize) -> BatchShape {
        BatchShape {
            capacity,
            max_chunk: usize::MAX,
            kernel: NetworkKernel::Auto,
        }
    }
}

/// The caller's buffers: inputs [capacity × inputs] f32, the batch size
/// (one u32), outputs [capacity × (1 + |wrt|) × outputs] f32.
pub struct BatchBuffers<'a> {
    /// The network inputs, [capacity × inputs] `f32`.
    pub inputs: &'a wgpu::Buffer,
    /// The batch size: one `u32`.
    pub count: &'a wgpu::Buffer,
    /// The outputs, [capacity × (1 + |wrt|) × outputs] `f32`.
    pub outputs: &'a wgpu::Buffer,
}

/// Bytes of the outputs buffer of `net` for `capacity` contacts.
pub fn output_bytes(net: &Mlp, capacity: usize, wrt: &Range<usize>) -> u64 {
    (capacity * (1 + wrt.len()) * net.outputs() * 4) as u64
}

/// One network uploaded for batches in the caller's buffers: its weights,
/// activations and the bound dispatches of its chosen kernel.
pub struct GpuMlp {
    /// Kept alive for the bind groups.
    _buffers: Vec<wgpu::Buffer>,
    dispatch: wgpu::Buffer,
    plan: Bound,
    /// Per chunk, per layer (tiled), or the one `per_contact` group.
    layers: Vec<Bound>,
    kernel: NetworkKernel,
    entries: u32,
    chunks: u32,
    multiply_adds: usize,
    rows_per_contact: usize,
}

impl GpuMlp {
    /// Uploads `net` for batches of `shape`, with its Jacobian along inputs
    /// `wrt`. Fails with a clear error when the network or a chunk of one
    /// contact does not fit the device's limits.
    pub fn new(
        kernels: &Kernels,
        device: &wgpu::Device,
        net: &Mlp,
        wrt: Range<usize>,
        shape: BatchShape,
        io: BatchBuffers,
    ) -> Result<GpuMlp> {
        let capacity = shape.capacity;
        if wrt.is_empty() || wrt.end > net.inputs() {
            return Err(Error::Gpu(format!(
                "a Jacobian along inputs {wrt:?} of a network with {} inputs",
                net.inputs()
            )));
        }
        let limits = device.limits();
        let bindable = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        let rows = 1 + wrt.len();
        let widest = net.layers.iter().map(|l| l.outputs).max().unwrap_or(1);
        let misfit = per_contact_misfit(net, rows, bindable, kernels.software());
        let kernel = match (shape.kernel, misfit) {
            (NetworkKernel::Auto, None) if kernels.software() => NetworkKernel::PerContact,
            (NetworkKernel::Auto, _) => NetworkKernel::Tiled,
            (NetworkKernel::PerContact, Some(why)) => return Err(Error::Gpu(why)),
            (chosen, _) => chosen,
        };
        let (weights, table) = match kernel {
            NetworkKernel::PerContact => pack_quads(net),
            _ => pack(net),
        };
        let weight_bytes = 4 * weights.len() as u64;
        if weight_bytes > bindable {
            return Err(Error::Gpu(format!(
                "the network's {} weights need {weight_bytes} bytes, more than this adapter binds ({bindable} bytes)",
                weights.len()
            )));
        }
        if output_bytes(net, capacity.max(1), &wrt) > bindable
            || io.outputs.size() < output_bytes(net, capacity, &wrt)
        {
            return Err(Error::Gpu(format!(
                "a batch of {capacity} contacts needs {} bytes of network outputs, more than this adapter binds ({bindable} bytes)",
                output_bytes(net, capacity, &wrt)
            )));
        }
        // Contacts per chunk: a chunk's activations must bind, and one
        // dispatch must cover its rows (tiled) or its contacts.
        let tile = kernels.mlp_tile() as u64;
        let groups = limits.max_compute_workgroups_per_dimension as u64;
        let (per_contact, by_dispatch, most) = match kernel {
            NetworkKernel::PerContact => (
                units_bytes(net, rows),
                groups * BATCH_GROUP as u64,
                PER_CONTACT_CHUNK,
            ),
            _ => (
                (rows * widest * 4) as u64,
                groups * tile / rows as u64,
                usize::MAX,
            ),
        };
        let chunk = (capacity.max(1).min(shape.max_chunk).min(most) as u64)
            .min(bindable / per_contact)
            .min(by_dispatch) as usize;
        if chunk == 0 {
            return Err(Error::Gpu(format!(
                "the network's {widest}-wide layers need {per_contact} bytes of activations per contact, more than this adapter binds ({bindable} bytes)"
            )));
        }
        let chunks = capacity.max(1).div_ceil(chunk);
        let n_layers = net.layers.len();
        // Per chunk: its dispatches, and the rows of a contact each covers
        // in workgroups of how many (tiled: every layer, every row a
        // contact has, a tile's rows; `per_contact`: one, one invocation).
        let (per_chunk, dispatch_rows, rows_per_group) = match kernel {
            NetworkKernel::PerContact => (1, 1, BATCH_GROUP as u64),
            _ => (n_layers, rows, tile),
        };
        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        let weights_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("network weights"),
            contents: bytemuck::cast_slice(&weights),
            usage,
        });
        // A chunk's two layers (tiled), or its units (`per_contact`).
        let activations = [0, 1].map(|i| {
            let size = match kernel {
                NetworkKernel::PerContact if i == 1 => 16,
                _ => chunk as u64 * per_contact,
            };
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(&format!("network activations {i}")),
                size,
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            })
        });
        // Each chunk's dispatches, then the caller's pass.
        let entries = (chunks * per_chunk + 1) as u32;
        // y: output tiles of each entry's layer (tiled); the plan fills in x.
        let mut args = Vec::with_capacity(3 * entries as usize);
        for _ in 0..chunks {
            match kernel {
                NetworkKernel::PerContact => args.extend([0, 1, 1]),
                _ => {
                    for l in &net.layers {
                        args.extend([0, l.outputs.div_ceil(tile as usize) as u32, 1]);
                    }
                }
            }
        }
        args.extend([0, 1, 1]);
        let dispatch = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("network dispatches"),
            contents: bytemuck::cast_slice(&args),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::INDIRECT,
        });
        let uniform = |label: &str, bytes: &[u8]| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytes,
                usage: wgpu::BufferUsages::UNIFORM,
            })
        };
        let batch_params = uniform(
            "batch params",
            bytemuck::bytes_of(&BatchParams {
                n_chunks: chunks as u32,
                per_chunk: per_chunk as u32,
                chunk_contacts: chunk as u32,
                rows_per_contact: dispatch_rows as u32,
                rows_per_group: rows_per_group as u32,
                threads_per_contact_group: WORKGROUP,
                pad: [0; 2],
            }),
        );
        let plan = kernels.kernel(Entry::BatchPlan).bind(
            device,
            &[
                ("batch", &batch_params),
                ("count", io.count),
                ("dispatch", &dispatch),
            ],
        );
        let layer_table = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("network layers"),
            contents: bytemuck::cast_slice(&table),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let mut buffers = vec![weights_buffer, batch_params, layer_table];
        let mut layers = Vec::with_capacity(chunks * per_chunk);
        let entry = match kernel {
            NetworkKernel::PerContact if quads_per_unit(rows) > 1 => Entry::MlpPerContactWide,
            NetworkKernel::PerContact => Entry::MlpPerContact,
            _ => Entry::MlpLayer,
        };
        let group = |params: &wgpu::Buffer, z_in, z_out, buffers: &[wgpu::Buffer]| {
            kernels.kernel(entry).bind(
                device,
                &[
                    ("layer_params", params),
                    ("weights", &buffers[0]),
                    ("weight_quads", &buffers[0]),
                    ("z_in", z_in),
                    ("z_out", z_out),
                    ("count", io.count),
                    ("layer_table", &buffers[2]),
                    ("units", &activations[0]),
                ],
            )
        };
        let base = LayerParams {
            rows_per_contact: rows as u32,
            wrt_start: wrt.start as u32,
            negative_slope: net.negative_slope,
            n_layers: n_layers as u32,
            ..Default::default()
        };
        for c in 0..chunks {
            if kernel == NetworkKernel::PerContact {
                let params = LayerParams {
                    chunk_start: (c * chunk) as u32,
                    chunk_contacts: chunk as u32,
                    units_half: per_contact_half(net, rows) as u32,
                    ..base
                };
                let params = uniform("network params", bytemuck::bytes_of(&params));
                layers.push(group(&params, io.inputs, io.outputs, &buffers));
                buffers.push(params);
                continue;
            }
            for (l, layer) in net.layers.iter().enumerate() {
                let last = l + 1 == n_layers;
                let params = LayerParams {
                    inputs: layer.inputs as u32,
                    outputs: layer.outputs as u32,
                    weight_offset: table[4 * l + 2],
                    bias_offset: table[4 * l + 3],
                    first: (l == 0) as u32,
                    chunk_start: (c * chunk) as u32,
                    chunk_contacts: chunk as u32,
                    out_row_offset: if last { (c * chunk * rows) as u32 } else { 0 },
                    ..base
                };
                let params = uniform("layer params", bytemuck::bytes_of(&params));
                let z_in = if l == 0 {
                    io.inputs
                } else {
                    &activations[(l + 1) % 2]
                };
                let z_out = if last {
                    io.outputs
                } else {
                    &activations[l % 2]
                };
                layers.push(group(&params, z_in, z_out, &buffers));
                buffers.push(params);
            }
        }
        buffers.extend(activations);
        Ok(GpuMlp {
            _buffers: buffers,
            dispatch,
            plan,
            layers,
            kernel,
            entries,
            chunks: chunks as u32,
            multiply_adds: net.multiply_adds(),
            rows_per_contact: rows,
        })
    }

    /// Chunks the tiled kernel runs the batch in (one unless the
    /// activations of a whole batch would exceed the binding limit).
    pub fn chunks(&self) -> u32 {
        self.chunks
    }

    /// The kernel chosen.
    pub fn kernel(&self) -> NetworkKernel {
        self.kernel
    }

    /// Multiply-adds of one contact as the kernels do them: forward mode,
    /// each weight meeting the value and every tangent row.
    pub fn multiply_adds_per_contact(&self) -> usize {
        self.multiply_adds * self.rows_per_contact
    }

    /// Dispatches [`GpuMlp::record`] records: the plan, then each chunk's.
    pub fn dispatches(&self) -> u32 {
        1 + self.layers.len() as u32
    }

    /// Records the batch: the dispatch sizes, then each chunk's
    /// `per_contact` or every layer of every chunk (chunks past the batch
    /// size dispatch nothing).
    pub fn record(&self, pass: &mut Pass) {
        self.plan.dispatch_once(pass, self.entries, BATCH_GROUP);
        for (e, layer) in self.layers.iter().enumerate() {
            layer.dispatch_indirect(pass, &self.dispatch, 12 * e as u64);
        }
    }

    /// Indirect arguments for one thread per contact of the batch (the
    /// caller's per-contact pass after the network), as buffer and offset.
    pub fn per_contact_dispatch(&self) -> (&wgpu::Buffer, u64) {
        (&self.dispatch, 12 * (self.entries as u64 - 1))
    }
}

/// A network with batch buffers of its own: for apps that evaluate it on
/// contacts of their own, and for the benchmarks and tests.
pub struct NetworkBatch {
    inputs: wgpu::Buffer,
    count: wgpu::Buffer,
    outputs: wgpu::Buffer,
    net: GpuMlp,
    width: usize,
    capacity: usize,
}

impl NetworkBatch {
    /// Room for a batch of `shape`.
    pub fn new(
        kernels: &Kernels,
        device: &wgpu::Device,
        net: &Mlp,
        wrt: Range<usize>,
        shape: BatchShape,
    ) -> Result<NetworkBatch> {
        let capacity = shape.capacity;
        let storage = |label: &str, size: u64| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: size.max(16),
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_DST
                    | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            })
        };
        let width = net.inputs();
        let inputs = storage("batch inputs", (capacity * width * 4) as u64);
        let count = storage("batch size", 4);
        let outputs = storage("batch outputs", output_bytes(net, capacity, &wrt));
        let io = BatchBuffers {
            inputs: &inputs,
            count: &count,
            outputs: &outputs,
        };
        let net = GpuMlp::new(kernels, device, net, wrt, shape, io)?;
        Ok(NetworkBatch {
            inputs,
            count,
            outputs,
            net,
            width,
            capacity,
        })
    }

    /// Uploads a batch, row-major [contacts × inputs].
    pub fn upload(&self, queue: &wgpu::Queue, inputs: &[f32]) -> Result<()> {
        let n = inputs.len() / self.width;
        if n * self.width != inputs.len() || n > self.capacity {
            return Err(Error::Gpu(format!(
                "a batch of {} floats is not up to {} contacts of {} inputs",
                inputs.len(),
                self.capacity,
                self.width
            )));
        }
        queue.write_buffer(&self.inputs, 0, bytemuck::cast_slice(inputs));
        queue.write_buffer(&self.count, 0, bytemuck::bytes_of(&(n as u32)));
        Ok(())
    }

    /// Records the network over the uploaded batch.
    pub fn record(&self, pass: &mut Pass) {
        self.net.record(pass);
    }

    /// Records and submits the network over the uploaded batch.
    pub fn run(&self, device: &wgpu::Device, queue: &wgpu::Queue) {
        let mut encoder = device.create_command_encoder(&Default::default());
        self.record(&mut Pass::new(
            encoder.begin_compute_pass(&Default::default()),
        ));
        queue.submit([encoder.finish()]);
    }

    #[cfg(not(target_arch = "wasm32"))]
    /// The outputs, [contacts × (1 + |wrt|) × 3]: per contact the output,
    /// then its derivative along each input of `wrt`.
    pub fn read_outputs(&self, device: &wgpu::Device, queue: &wgpu::Queue) -> Result<Vec<f32>> {
        read_buffer(device, queue, self.outputs())
    }

    /// The outputs' buffer, laid out as [`NetworkBatch::read_outputs`]
    /// returns it, for an asynchronous read ([`crate::gpu::Readback`]).
    pub fn outputs(&self) -> &wgpu::Buffer {
        &self.outputs
    }

    /// The uploaded network (its kernel, chunks and cost).
    pub fn network(&self) -> &GpuMlp {
        &self.net
    }
}
