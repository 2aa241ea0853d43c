//! Compute pipelines, built once per device and shared by every scene
//! simulated on it. Each stage file gets one explicit bind group layout
//! (reflected from its WGSL), shared by all its entry points.

use std::collections::BTreeMap;

use crate::error::{Error, Result};
use crate::gpu::shaders::{self, Binding, STAGES};

pub struct Stage {
    pub layout: wgpu::BindGroupLayout,
    pub bindings: BTreeMap<String, Binding>,
    pub pipelines: BTreeMap<String, wgpu::ComputePipeline>,
}

pub struct Kernels {
    stages: BTreeMap<&'static str, Stage>,
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
    pub fn new(device: &wgpu::Device) -> Result<Kernels> {
        let mlp_threads = mlp_threads(&device.limits());
        let mut stages = BTreeMap::new();
        for (name, _) in STAGES {
            let reflected =
                shaders::reflect(name).map_err(|e| Error::Gpu(format!("wgsl/{name}.wgsl: {e}")))?;
            let entries: Vec<wgpu::BindGroupLayoutEntry> = reflected
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
                label: Some(name),
                entries: &entries,
            });
            let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some(name),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(name),
                source: wgpu::ShaderSource::Wgsl(shaders::source_for(name, mlp_threads).into()),
            });
            let pipelines = reflected
                .entry_points
                .iter()
                .map(|entry| {
                    let p = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                        label: Some(&format!("{name}::{entry}")),
                        layout: Some(&pipeline_layout),
                        module: &module,
                        entry_point: Some(entry),
                        compilation_options: Default::default(),
                        cache: None,
                    });
                    (entry.clone(), p)
                })
                .collect();
            stages.insert(
                name,
                Stage {
                    layout,
                    bindings: reflected.bindings,
                    pipelines,
                },
            );
        }
        Ok(Kernels {
            stages,
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

    pub fn pipeline(&self, stage: &str, entry: &str) -> &wgpu::ComputePipeline {
        &self.stages[stage].pipelines[entry]
    }

    /// A bind group for `stage` from (WGSL variable name, buffer) pairs;
    /// every variable the stage declares must be given, and nothing else.
    pub fn bind(
        &self,
        device: &wgpu::Device,
        stage: &str,
        buffers: &[(&str, &wgpu::Buffer)],
    ) -> wgpu::BindGroup {
        let s = &self.stages[stage];
        let mut given: Vec<&str> = buffers.iter().map(|(n, _)| *n).collect();
        given.sort_unstable();
        let wanted: Vec<&str> = s.bindings.keys().map(String::as_str).collect();
        assert_eq!(
            given, wanted,
            "bind group for `{stage}` does not match its WGSL bindings"
        );
        let entries: Vec<wgpu::BindGroupEntry> = buffers
            .iter()
            .map(|(name, buffer)| wgpu::BindGroupEntry {
                binding: s.bindings[*name].binding,
                resource: buffer.as_entire_binding(),
            })
            .collect();
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(stage),
            layout: &s.layout,
            entries: &entries,
        })
    }
}
