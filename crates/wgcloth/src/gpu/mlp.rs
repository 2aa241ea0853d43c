//! A collision network on the GPU (stages "mlp" and "batch"): the weights,
//! activations and dispatches of one network for batches of up to
//! `capacity` contacts. The batch's inputs, size and outputs live in
//! buffers the caller owns (the step's contact stage, a benchmark, a test),
//! and the size is read on the GPU, so a batch needs no readback.
//!
//! Two kernels evaluate it: `layer`, one tiled matrix product per layer
//! through workgroup memory, for GPUs; and `per_contact`, one contact per
//! invocation without barriers, for CPU adapters such as lavapipe, which
//! run it about 3× faster than `layer` on small networks.

use std::ops::Range;

use bytemuck::{Pod, Zeroable};
use wgpu::util::DeviceExt;

use crate::error::{Error, Result};
use crate::gpu::constants::{BATCH_GROUP, MLP_MAX_LAYERS, MLP_MAX_WIDTH, WORKGROUP};
#[cfg(not(target_arch = "wasm32"))]
use crate::gpu::context::read_buffer;
use crate::gpu::kernels::{Bound, Entry, Kernels};
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
}

/// Mirrors `BatchParams` in wgsl/batch.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct BatchParams {
    /// Chunks of the tiled kernel (0 with `per_contact`).
    pub n_chunks: u32,
    /// Layers of the network.
    pub n_layers: u32,
    /// Most contacts per chunk.
    pub chunk_contacts: u32,
    /// Rows per contact: 1 + the Jacobian columns.
    pub rows_per_contact: u32,
    /// Rows per workgroup of the `layer` kernel (its tile).
    pub rows_per_group: u32,
    /// `per_contact`'s workgroup size.
    pub threads_per_network_group: u32,
    /// Workgroup size of the caller's per-contact pass after the network.
    pub threads_per_contact_group: u32,
    /// Padding to the WGSL size.
    pub pad: u32,
}

/// The widest layer `per_contact` holds.
pub const PER_CONTACT_MAX_WIDTH: usize = MLP_MAX_WIDTH as usize;
/// The most layers `per_contact` holds.
pub const PER_CONTACT_MAX_LAYERS: usize = MLP_MAX_LAYERS as usize;

/// Mesa's llvmpipe ends an invocation after this many loop iterations
/// (`LP_MAX_TGSI_LOOP_ITERATIONS`), silently.
const LAVAPIPE_LOOP_LIMIT: usize = 65_535;

/// Loop iterations of one `per_contact` invocation (an upper bound): the
/// forward pass and one reverse pass per output, each touching every
/// weight quad once plus a few loops per unit.
fn per_contact_iterations(net: &Mlp, rows: usize) -> usize {
    let per_pass: usize = net
        .layers
        .iter()
        .map(|l| l.outputs * (l.inputs.div_ceil(4) + 2) + l.inputs + l.inputs.div_ceil(4))
        .sum();
    (1 + net.outputs()) * (net.inputs() + net.outputs() + per_pass) + rows
}

/// Every layer's weights, row-major with rows `align`-padded (the padding
/// zero), then its biases, padded so the next layer starts aligned; and
/// per layer (inputs, outputs, weight offset, bias offset).
fn pack(net: &Mlp, align: usize) -> (Vec<f32>, Vec<u32>) {
    let (mut weights, mut table) = (Vec::new(), Vec::new());
    for l in &net.layers {
        let offset = weights.len();
        for row in l.weight.chunks_exact(l.inputs) {
            weights.extend(row);
            weights.resize(
                weights.len() + l.inputs.next_multiple_of(align) - l.inputs,
                0.0,
            );
        }
        table.extend([l.inputs, l.outputs, offset, weights.len()].map(|v| v as u32));
        weights.extend(&l.bias);
        weights.resize(weights.len().next_multiple_of(align), 0.0);
    }
    // Whole vec4s, as `weight_quads` binds the buffer too.
    weights.resize(weights.len().next_multiple_of(4), 0.0);
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
    outputs: usize,
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
        let fits_per_contact = widest <= PER_CONTACT_MAX_WIDTH
            && net.layers.len() <= PER_CONTACT_MAX_LAYERS
            && (!kernels.software() || per_contact_iterations(net, rows) <= LAVAPIPE_LOOP_LIMIT);
        let kernel = match shape.kernel {
            NetworkKernel::Auto if kernels.software() && fits_per_contact => {
                NetworkKernel::PerContact
            }
            NetworkKernel::Auto => NetworkKernel::Tiled,
            NetworkKernel::PerContact if !fits_per_contact => {
                return Err(Error::Gpu(format!(
                    "the per-contact kernel holds networks up to {PER_CONTACT_MAX_WIDTH} wide and {PER_CONTACT_MAX_LAYERS} layers deep, and on a CPU adapter {LAVAPIPE_LOOP_LIMIT} loop iterations per contact"
                )));
            }
            chosen => chosen,
        };
        let (weights, table) = match kernel {
            // `per_contact` reads whole vec4s of a row.
            NetworkKernel::PerContact => pack(net, 4),
            _ => pack(net, 1),
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
        // Contacts per chunk: the activations of the widest layer must bind,
        // and one dispatch must cover the chunk's rows.
        let tile = kernels.mlp_tile() as u64;
        let per_contact = (rows * widest * 4) as u64;
        let by_binding = bindable / per_contact;
        let by_dispatch = limits.max_compute_workgroups_per_dimension as u64 * tile / rows as u64;
        let chunk = (capacity.max(1).min(shape.max_chunk) as u64)
            .min(by_binding)
            .min(by_dispatch) as usize;
        if chunk == 0 && kernel == NetworkKernel::Tiled {
            return Err(Error::Gpu(format!(
                "the network's {widest}-wide layers need {per_contact} bytes of activations per contact, more than this adapter binds ({bindable} bytes)"
            )));
        }
        let chunks = match kernel {
            NetworkKernel::Tiled => capacity.max(1).div_ceil(chunk),
            _ => 0,
        };
        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        let weights_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("network weights"),
            contents: bytemuck::cast_slice(&weights),
            usage,
        });
        let activations = [0, 1].map(|i| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(&format!("network activations {i}")),
                size: (chunks.min(1) as u64 * chunk as u64 * per_contact).max(16),
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            })
        });
        let n_layers = net.layers.len();
        // Tiled layers, then `per_contact`, then the caller's pass.
        let entries = (chunks * n_layers + 2) as u32;
        // y: output tiles of each entry's layer; the plan fills in x.
        let mut args = Vec::with_capacity(3 * entries as usize);
        for _ in 0..chunks {
            for l in &net.layers {
                args.extend([0, l.outputs.div_ceil(tile as usize) as u32, 1]);
            }
        }
        args.extend([0, 1, 1, 0, 1, 1]);
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
                n_layers: n_layers as u32,
                chunk_contacts: chunk as u32,
                rows_per_contact: rows as u32,
                rows_per_group: tile as u32,
                threads_per_network_group: BATCH_GROUP,
                // The caller's per-contact pass after the network.
                threads_per_contact_group: WORKGROUP,
                pad: 0,
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
        let mut layers = Vec::with_capacity(chunks * n_layers + 1);
        let entry = match kernel {
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
        if kernel == NetworkKernel::PerContact {
            let params = uniform("network params", bytemuck::bytes_of(&base));
            layers.push(group(&params, io.inputs, io.outputs, &buffers));
            buffers.push(params);
        }
        for c in 0..chunks {
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
            outputs: net.outputs(),
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

    /// Multiply-adds of one contact as the chosen kernel does them: one
    /// pass per row in forward mode (tiled), one forward pass and one back
    /// per output in reverse mode (per-contact).
    pub fn multiply_adds_per_contact(&self) -> usize {
        match self.kernel {
            NetworkKernel::PerContact => self.multiply_adds * (1 + self.outputs),
            _ => self.multiply_adds * self.rows_per_contact,
        }
    }

    /// Records the batch: the dispatch sizes, then `per_contact` once or
    /// every layer of every chunk (chunks past the batch size dispatch
    /// nothing). Returns the number of dispatches.
    pub fn record(&self, pass: &mut wgpu::ComputePass) -> u32 {
        self.plan.dispatch(pass, self.entries, BATCH_GROUP);
        if self.kernel == NetworkKernel::PerContact {
            self.layers[0].set(pass);
            pass.dispatch_workgroups_indirect(&self.dispatch, 12 * (self.entries as u64 - 2));
            return 2;
        }
        for (e, layer) in self.layers.iter().enumerate() {
            layer.set(pass);
            pass.dispatch_workgroups_indirect(&self.dispatch, 12 * e as u64);
        }
        1 + self.layers.len() as u32
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
    pub fn record(&self, pass: &mut wgpu::ComputePass) -> u32 {
        self.net.record(pass)
    }

    /// Records and submits the network over the uploaded batch.
    pub fn run(&self, device: &wgpu::Device, queue: &wgpu::Queue) {
        let mut encoder = device.create_command_encoder(&Default::default());
        self.record(&mut encoder.begin_compute_pass(&Default::default()));
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
