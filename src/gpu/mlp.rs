//! A collision network on the GPU (stages "mlp" and "batch"): the weights,
//! activations and dispatches of one network for batches of up to
//! `capacity` contacts. The batch's inputs, size and outputs live in
//! buffers the caller owns (the step's contact stage, a benchmark, a test),
//! and the size is read on the GPU, so a batch needs no readback.

use std::ops::Range;
use std::sync::Arc;

use bytemuck::{Pod, Zeroable};
use wgpu::util::DeviceExt;

use crate::error::{Error, Result};
use crate::gpu::kernels::Kernels;
use crate::nn::Mlp;

/// Mirrors `LayerParams` in wgsl/mlp.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct LayerParams {
    pub inputs: u32,
    pub outputs: u32,
    pub weight_offset: u32,
    pub bias_offset: u32,
    pub rows_per_contact: u32,
    pub wrt_start: u32,
    pub first: u32,
    pub chunk_start: u32,
    pub chunk_contacts: u32,
    pub out_row_offset: u32,
    pub negative_slope: f32,
    pub pad: u32,
}

/// Mirrors `BatchParams` in wgsl/batch.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct BatchParams {
    pub n_chunks: u32,
    pub n_layers: u32,
    pub chunk_contacts: u32,
    pub rows_per_contact: u32,
    pub rows_per_group: u32,
    pub threads_per_contact_group: u32,
    pub pad: [u32; 2],
}

/// Workgroup size of the caller's per-contact pass after the network
/// (`WORKGROUP` in wgsl/common.wgsl).
pub const CONTACT_GROUP: u32 = 256;

/// The caller's buffers: inputs [capacity × inputs] f32, the batch size
/// (one u32), outputs [capacity × (1 + |wrt|) × 3] f32.
pub struct BatchBuffers<'a> {
    pub inputs: &'a wgpu::Buffer,
    pub count: &'a wgpu::Buffer,
    pub outputs: &'a wgpu::Buffer,
}

/// Bytes of the outputs buffer for `capacity` contacts.
pub fn output_bytes(capacity: usize, wrt: &Range<usize>) -> u64 {
    (capacity * (1 + wrt.len()) * 3 * 4) as u64
}

pub struct GpuMlp {
    kernels: Arc<Kernels>,
    /// Kept alive for the bind groups.
    _buffers: Vec<wgpu::Buffer>,
    dispatch: wgpu::Buffer,
    plan: wgpu::BindGroup,
    /// Per chunk, per layer.
    layers: Vec<wgpu::BindGroup>,
    entries: u32,
    chunks: u32,
    multiply_adds: usize,
    rows_per_contact: usize,
}

impl GpuMlp {
    /// Uploads `net` for batches of up to `capacity` contacts, with its
    /// Jacobian along inputs `wrt`. Fails with a clear error when the
    /// network or a chunk of one contact does not fit the device's limits.
    pub fn new(
        kernels: Arc<Kernels>,
        device: &wgpu::Device,
        net: &Mlp,
        wrt: Range<usize>,
        capacity: usize,
        io: BatchBuffers,
    ) -> Result<GpuMlp> {
        Self::chunked(kernels, device, net, wrt, capacity, usize::MAX, io)
    }

    /// As [`GpuMlp::new`], with at most `max_chunk` contacts per chunk.
    pub fn chunked(
        kernels: Arc<Kernels>,
        device: &wgpu::Device,
        net: &Mlp,
        wrt: Range<usize>,
        capacity: usize,
        max_chunk: usize,
        io: BatchBuffers,
    ) -> Result<GpuMlp> {
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
        let weights: Vec<f32> = net
            .layers
            .iter()
            .flat_map(|l| l.weight.iter().chain(&l.bias).copied())
            .collect();
        let weight_bytes = 4 * weights.len() as u64;
        if weight_bytes > bindable {
            return Err(Error::Gpu(format!(
                "the network's {} weights need {weight_bytes} bytes, more than this adapter binds ({bindable} bytes)",
                weights.len()
            )));
        }
        if output_bytes(capacity.max(1), &wrt) > bindable
            || io.outputs.size() < output_bytes(capacity, &wrt)
        {
            return Err(Error::Gpu(format!(
                "a batch of {capacity} contacts needs {} bytes of network outputs, more than this adapter binds ({bindable} bytes)",
                output_bytes(capacity, &wrt)
            )));
        }
        // Contacts per chunk: the activations of the widest layer must bind,
        // and one dispatch must cover the chunk's rows.
        let tile = kernels.mlp_tile() as u64;
        let per_contact = (rows * widest * 4) as u64;
        let by_binding = bindable / per_contact;
        let by_dispatch = limits.max_compute_workgroups_per_dimension as u64 * tile / rows as u64;
        let chunk = (capacity.max(1).min(max_chunk) as u64)
            .min(by_binding)
            .min(by_dispatch) as usize;
        if chunk == 0 {
            return Err(Error::Gpu(format!(
                "the network's {widest}-wide layers need {per_contact} bytes of activations per contact, more than this adapter binds ({bindable} bytes)"
            )));
        }
        let chunks = capacity.max(1).div_ceil(chunk);
        let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        let weights_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("network weights"),
            contents: bytemuck::cast_slice(&weights),
            usage,
        });
        let activations = [0, 1].map(|i| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(&format!("network activations {i}")),
                size: (chunk as u64 * per_contact).max(16),
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            })
        });
        let n_layers = net.layers.len();
        let entries = (chunks * n_layers + 1) as u32;
        // y: output tiles of each entry's layer; the plan fills in x.
        let mut args = Vec::with_capacity(3 * entries as usize);
        for _ in 0..chunks {
            for l in &net.layers {
                args.extend([0, l.outputs.div_ceil(tile as usize) as u32, 1]);
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
                n_layers: n_layers as u32,
                chunk_contacts: chunk as u32,
                rows_per_contact: rows as u32,
                rows_per_group: tile as u32,
                threads_per_contact_group: CONTACT_GROUP,
                pad: [0; 2],
            }),
        );
        let plan = kernels.bind(
            device,
            "batch",
            &[
                ("batch", &batch_params),
                ("count", io.count),
                ("dispatch", &dispatch),
            ],
        );
        let mut buffers = vec![weights_buffer, batch_params];
        let mut layers = Vec::with_capacity(chunks * n_layers);
        for c in 0..chunks {
            let mut offset = 0;
            for (l, layer) in net.layers.iter().enumerate() {
                let last = l + 1 == n_layers;
                let params = LayerParams {
                    inputs: layer.inputs as u32,
                    outputs: layer.outputs as u32,
                    weight_offset: offset as u32,
                    bias_offset: (offset + layer.weight.len()) as u32,
                    rows_per_contact: rows as u32,
                    wrt_start: wrt.start as u32,
                    first: (l == 0) as u32,
                    chunk_start: (c * chunk) as u32,
                    chunk_contacts: chunk as u32,
                    out_row_offset: if last { (c * chunk * rows) as u32 } else { 0 },
                    negative_slope: net.negative_slope,
                    pad: 0,
                };
                offset += layer.weight.len() + layer.bias.len();
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
                layers.push(kernels.bind(
                    device,
                    "mlp",
                    &[
                        ("layer_params", &params),
                        ("weights", &buffers[0]),
                        ("z_in", z_in),
                        ("z_out", z_out),
                        ("count", io.count),
                    ],
                ));
                buffers.push(params);
            }
        }
        buffers.extend(activations);
        Ok(GpuMlp {
            kernels,
            _buffers: buffers,
            dispatch,
            plan,
            layers,
            entries,
            chunks: chunks as u32,
            multiply_adds: net.multiply_adds(),
            rows_per_contact: rows,
        })
    }

    /// Chunks the batch runs in (one unless the activations of a whole
    /// batch would exceed the binding limit).
    pub fn chunks(&self) -> u32 {
        self.chunks
    }

    /// Multiply-adds of one contact: the forward pass and its Jacobian rows.
    pub fn multiply_adds_per_contact(&self) -> usize {
        self.multiply_adds * self.rows_per_contact
    }

    /// Records the batch: the dispatch sizes, then every layer of every
    /// chunk (chunks past the batch size dispatch nothing). Returns the
    /// number of dispatches.
    pub fn record(&self, pass: &mut wgpu::ComputePass) -> u32 {
        pass.set_pipeline(self.kernels.pipeline("batch", "plan"));
        pass.set_bind_group(0, &self.plan, &[]);
        pass.dispatch_workgroups(self.entries.div_ceil(64), 1, 1);
        pass.set_pipeline(self.kernels.pipeline("mlp", "layer"));
        for (e, group) in self.layers.iter().enumerate() {
            pass.set_bind_group(0, group, &[]);
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
