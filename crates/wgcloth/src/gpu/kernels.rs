//! Compute pipelines, built once per device and shared by every scene
//! simulated on it. Each stage file gets one explicit bind group layout
//! (reflected from its WGSL), shared by all its entry points.

use std::collections::BTreeMap;

use crate::error::{Error, Result};
use crate::gpu::shaders::{self, Binding, STAGES};

/// One entry point's pipeline, with a bind group layout of just the
/// bindings it uses (so it fits WebGPU's per-stage limits).
pub struct Kernel {
    pub pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    bindings: BTreeMap<String, Binding>,
    label: String,
}

impl Kernel {
    /// A bind group from a stage's buffers by WGSL variable name: the ones
    /// this entry point uses, each of which must be among them.
    pub fn bind(
        &self,
        device: &wgpu::Device,
        buffers: &[(&str, &wgpu::Buffer)],
    ) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry> = self
            .bindings
            .iter()
            .map(|(name, b)| {
                let buffer = buffers
                    .iter()
                    .find(|(n, _)| n == name)
                    .unwrap_or_else(|| panic!("{}: no buffer given for `{name}`", self.label))
                    .1;
                wgpu::BindGroupEntry {
                    binding: b.binding,
                    resource: buffer.as_entire_binding(),
                }
            })
            .collect();
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(&self.label),
            layout: &self.layout,
            entries: &entries,
        })
    }
}

pub struct Kernels {
    kernels: BTreeMap<(&'static str, String), Kernel>,
    mlp_threads: u32,
    software: bool,
}

/// Threads per edge of the network layer's tile (wgsl/mlp.wgsl): 16 × 16
/// (64 × 64 outputs) where the adapter allows it, else 8 × 8.
pub fn mlp_threads(limits: &wgpu::Limits) -> u32 {
    let fits = |t: u32| {
        // Two tiles of MLP_K × 4t floats in workgroup memory.
        let storage = 2 * 16 * 4 * t * 4;
        t * t <= limits.max_compute_invocations_per_workgroup
            && t <= limits.max_compute_workgroup_size_x
            && t <= limits.max_compute_workgroup_size_y
            && storage <= limits.max_compute_workgroup_storage_size
    };
    if fits(16) { 16 } else { 8 }
}

impl Kernels {
    /// Compiles every stage for `device`; a device that rejects a kernel
    /// gives an error saying which and why (captured with error scopes).
    pub fn new(device: &wgpu::Device) -> Result<Kernels> {
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let kernels = Self::compile(device);
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(Error::Gpu(format!(
                "compiling the kernels: {}",
                crate::gpu::context::one_line(&e.to_string())
            )));
        }
        kernels
    }

    fn compile(device: &wgpu::Device) -> Result<Kernels> {
        let mlp_threads = mlp_threads(&device.limits());
        let mut kernels = BTreeMap::new();
        for (stage, _) in STAGES {
            let entries = shaders::reflect(stage, mlp_threads)
                .map_err(|e| Error::Gpu(format!("wgsl/{stage}.wgsl: {e}")))?;
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(stage),
                source: wgpu::ShaderSource::Wgsl(shaders::source(stage, mlp_threads).into()),
            });
            for entry in entries {
                let label = format!("{stage}::{}", entry.name);
                let layout_entries: Vec<wgpu::BindGroupLayoutEntry> = entry
                    .bindings
                    .values()
                    .map(|b| wgpu::BindGroupLayoutEntry {
                        binding: b.binding,
                        visibility: wgpu::ShaderStages::COMPUTE,
                        ty: wgpu::BindingType::Buffer {
                            ty: b.ty,
                            has_dynamic_offset: false,
                            min_binding_size: None,
                        },
                        count: None,
                    })
                    .collect();
                let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                    label: Some(&label),
                    entries: &layout_entries,
                });
                let pipeline_layout =
                    device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                        label: Some(&label),
                        bind_group_layouts: &[Some(&layout)],
                        immediate_size: 0,
                    });
                let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some(&label),
                    layout: Some(&pipeline_layout),
                    module: &module,
                    entry_point: Some(&entry.name),
                    compilation_options: Default::default(),
                    cache: None,
                });
                let kernel = Kernel {
                    pipeline,
                    layout,
                    bindings: entry.bindings,
                    label,
                };
                kernels.insert((stage, entry.name), kernel);
            }
        }
        Ok(Kernels {
            kernels,
            mlp_threads,
            software: device.adapter_info().device_type == wgpu::DeviceType::Cpu,
        })
    }

    /// Whether the device is a CPU adapter (lavapipe).
    pub fn software(&self) -> bool {
        self.software
    }

    /// Rows (and outputs) per workgroup tile of the network layer.
    pub fn mlp_tile(&self) -> u32 {
        4 * self.mlp_threads
    }

    /// The kernel of `stage`'s entry point `entry`.
    pub fn kernel(&self, stage: &str, entry: &str) -> &Kernel {
        self.kernels
            .iter()
            .find(|((s, e), _)| *s == stage && e == entry)
            .map(|(_, k)| k)
            .unwrap_or_else(|| panic!("no kernel {stage}::{entry}"))
    }
}
