//! Compute pipelines, built once per device and shared by every scene
//! simulated on it. Each entry point gets a bind group layout of just the
//! bindings it uses (reflected from its WGSL with naga): group 0 the run's
//! `params` for every scene stage, group 1 its own buffers.

use std::collections::BTreeMap;
use std::sync::OnceLock;

use crate::error::{Error, Result};
use crate::gpu::buffers::{Parts, WorldBuffers};
use crate::gpu::constants;
use crate::gpu::layout::{VectorLayout, WorldParams};
use crate::gpu::pass::Pass;
use crate::gpu::shaders::{self, Binding, STAGES};
use crate::gpu::worlds;

/// Declares [`Entry`], [`Entry::ALL`] and [`Entry::wgsl`] from one list:
/// each entry point's variant, its WGSL file (stage) and its name there.
macro_rules! entry_points {
    ($($(#[$doc:meta])* $name:ident => ($file:literal, $entry:literal),)*) => {
        /// Every entry point of every stage: pipelines are found by this,
        /// never by name. Each names its WGSL file and the entry point in
        /// it; a test checks that the files have no other.
        #[derive(Clone, Copy, Debug, PartialEq, Eq)]
        pub enum Entry {
            $($(#[$doc])* $name,)*
        }

        impl Entry {
            /// Every entry point, in declaration order (`Entry as usize`).
            pub const ALL: [Entry; [$($entry),*].len()] = [$(Entry::$name),*];

            /// The WGSL file (stage) and the entry point in it.
            pub const fn wgsl(self) -> (&'static str, &'static str) {
                match self {
                    $(Entry::$name => ($file, $entry),)*
                }
            }
        }
    };
}

// Every `@compute` function of `wgsl/`, found by `build.rs`.
include!(concat!(env!("OUT_DIR"), "/entries.rs"));

impl Entry {
    /// Whether its pipelines are made per kind of level ([`LevelKind`]),
    /// each with the WGSL overrides its file declares without a default:
    /// every multigrid kernel, of the V-cycle and of its setup.
    pub fn by_level(self) -> bool {
        self.wgsl().0 == "multigrid"
    }
}

/// One entry point's pipeline, with a bind group layout of just the
/// bindings it uses (so it fits WebGPU's per-stage limits).
pub struct Kernel {
    pipelines: Pipelines,
    /// The layout of its own bind group (group 1 of a scene stage, whose
    /// group 0 is `params`; group 0 of a standalone one) and what is in it.
    layout: wgpu::BindGroupLayout,
    group: u32,
    bindings: BTreeMap<String, Binding>,
    entry: Entry,
}

enum Pipelines {
    One(wgpu::ComputePipeline),
    /// A multigrid kernel's per [`LevelKind`] ([`Entry::by_level`]), each
    /// made the first time a scene binds one: a scene uses up to two.
    ByLevel {
        module: wgpu::ShaderModule,
        layout: wgpu::PipelineLayout,
        made: [OnceLock<wgpu::ComputePipeline>; LevelKind::COUNT],
    },
}

/// The kind of level a multigrid kernel's dispatches work on, fixed in
/// its pipeline (the WGSL overrides `LEVEL` and `PATCHES`). Lavapipe
/// runs every branch of a kernel, masked, for every 8 invocations, so a
/// kernel that read the kind from its hop paid at every node for the
/// cloth's rows and the coarse stencils both, and for both smoothers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LevelKind {
    /// Which levels.
    pub levels: Levels,
    /// Smoothed by patches, else by block Jacobi (`tail`'s coarsest level
    /// is always block Jacobi, and smoothed by its own code).
    pub patches: bool,
}

/// Which levels a multigrid pipeline works on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Levels {
    /// The cloth, level 0.
    Cloth,
    /// Coarse levels.
    Coarse,
    /// Each hop's own: `solve`, whose V-cycle starts at the cloth.
    Any,
}

impl LevelKind {
    const COUNT: usize = 6;

    fn index(self) -> usize {
        2 * self.levels as usize + usize::from(self.patches)
    }

    /// The overrides' values.
    fn constants(self) -> [(&'static str, f64); 2] {
        let level = match self.levels {
            Levels::Cloth => constants::level::CLOTH,
            Levels::Coarse => constants::level::COARSE,
            Levels::Any => constants::level::ANY,
        };
        [
            ("LEVEL", f64::from(level)),
            ("PATCHES", f64::from(u8::from(self.patches))),
        ]
    }
}

/// A kernel bound to one scene's buffers: ready to record (a scene
/// stage's pass binds `params` once).
pub struct Bound {
    pipeline: wgpu::ComputePipeline,
    index: u32,
    group: wgpu::BindGroup,
}

impl Bound {
    /// Sets the pipeline and bind group, for a dispatch of the caller's.
    pub fn set(&self, pass: &mut Pass) {
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(self.index, &self.group);
    }

    /// Records a dispatch whose workgroup counts the GPU wrote at `offset`
    /// of `args` (three `u32`s).
    pub fn dispatch_indirect(&self, pass: &mut Pass, args: &wgpu::Buffer, offset: u64) {
        self.set(pass);
        pass.dispatch_workgroups_indirect(args, offset);
    }

    /// Records one invocation per `threads`, in workgroups of `workgroup`
    /// (for each world of a batch).
    pub fn dispatch(&self, pass: &mut Pass, threads: u32, workgroup: u32) {
        self.set(pass);
        pass.dispatch_workgroups(threads.div_ceil(workgroup));
    }

    /// [`Bound::dispatch`] once, whatever the worlds
    /// ([`Pass::dispatch_workgroups_once`]).
    pub fn dispatch_once(&self, pass: &mut Pass, threads: u32, workgroup: u32) {
        self.set(pass);
        pass.dispatch_workgroups_once(threads.div_ceil(workgroup));
    }
}

impl Kernel {
    /// Binds a stage's buffers, given by WGSL variable name: the ones this
    /// entry point uses, each of which must be among them.
    pub fn bind(&self, device: &wgpu::Device, buffers: &[(&str, &wgpu::Buffer)]) -> Bound {
        self.bind_parts(device, buffers, &[])
    }

    /// [`Kernel::bind`] with arrays that may be bound in parts
    /// (`gpu::shaders::SPLIT_ARRAYS`), each under its own name.
    pub(crate) fn bind_parts(
        &self,
        device: &wgpu::Device,
        buffers: &[(&str, &wgpu::Buffer)],
        parted: &[&Parts],
    ) -> Bound {
        self.bind_level(device, buffers, parted, None)
    }

    /// [`Kernel::bind_parts`] for a multigrid kernel's dispatches on one
    /// kind of level ([`Entry::by_level`]), with its pipeline for them.
    pub(crate) fn bind_level(
        &self,
        device: &wgpu::Device,
        buffers: &[(&str, &wgpu::Buffer)],
        parted: &[&Parts],
        kind: Option<LevelKind>,
    ) -> Bound {
        let pipeline = match (&self.pipelines, kind) {
            (Pipelines::One(pipeline), None) => pipeline,
            (
                Pipelines::ByLevel {
                    module,
                    layout,
                    made,
                },
                Some(kind),
            ) => made[kind.index()].get_or_init(|| {
                let (stage, name) = self.entry.wgsl();
                Kernels::compute_pipeline(
                    device,
                    (module, layout),
                    &format!("{stage}::{name} {kind:?}"),
                    name,
                    &kind.constants(),
                )
            }),
            _ => panic!("{:?} bound with level kind {kind:?}", self.entry),
        };
        let entries: Vec<wgpu::BindGroupEntry> = self
            .bindings
            .iter()
            .map(|(name, b)| {
                let resource = match parted.iter().find_map(|p| p.binding(name)) {
                    Some(part) => wgpu::BindingResource::Buffer(part),
                    None => buffers
                        .iter()
                        .find(|(n, _)| n == name)
                        .unwrap_or_else(|| panic!("{:?}: no buffer given for `{name}`", self.entry))
                        .1
                        .as_entire_binding(),
                };
                wgpu::BindGroupEntry {
                    binding: b.binding,
                    resource,
                }
            })
            .collect();
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(self.entry.wgsl().1),
            layout: &self.layout,
            entries: &entries,
        });
        Bound {
            pipeline: pipeline.clone(),
            index: self.group,
            group,
        }
    }
}

/// Every entry point's pipeline for one device, and the `params` layout
/// the scene stages share; built once and shared by every scene on it.
pub struct Kernels {
    /// Indexed by `Entry as usize` ([`Entry::ALL`]'s order).
    kernels: Vec<Kernel>,
    /// Group 0 of every scene stage: `params` alone.
    params_layout: wgpu::BindGroupLayout,
    /// What they were compiled for: their tile, whether they bind the
    /// largest arrays in parts, whether they sum through subgroups, how
    /// they lay out the solver's vectors.
    variant: shaders::Variant,
    software: bool,
    /// Whether the device binds enough storage buffers per stage
    /// ([`SPLIT_STORAGE_BUFFERS`]) for kernels that bind in parts.
    splittable: bool,
    /// The same kernels binding them in parts, compiled the first time a
    /// scene on this device needs them ([`Kernels::in_parts`]).
    in_parts: OnceLock<Box<Kernels>>,
    /// Whether each kernel steps a batch of worlds (`gpu::worlds`).
    worlds: bool,
    /// The same kernels for a batch of worlds, compiled the first time a
    /// batch on this device needs them ([`Kernels::for_worlds`]).
    for_worlds: OnceLock<Box<Kernels>>,
}

/// Storage buffers per shader stage a device must allow for kernels that
/// bind the largest arrays in parts (`gpu::shaders::SPLIT_ARRAYS`), which
/// lets a scene pass the per-binding limit: such a kernel takes up to 14
/// (8 bound whole, as at WebGPU's default). Lavapipe and native drivers
/// allow 16 or more; a browser's default device does not. Only a scene
/// that needs them gets them: their choice of binding per read made
/// lavapipe's PCG 1.5× slower on scenes that fit whole.
pub const SPLIT_STORAGE_BUFFERS: u32 = 16;

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
    /// In a browser, await [`Kernels::create`] instead.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn new(device: &wgpu::Device) -> Result<Kernels> {
        pollster::block_on(Self::create(device))
    }

    /// [`Kernels::new`] as a future: on the web the error scope resolves
    /// only once the event loop runs.
    pub async fn create(device: &wgpu::Device) -> Result<Kernels> {
        let vectors = VectorLayout::for_adapter(device.adapter_info().device_type);
        Self::compiled(device, false, vectors, false).await
    }

    /// [`Kernels::new`] with the solver's vectors laid out as `vectors`,
    /// not as suits the adapter ([`VectorLayout::for_adapter`]): to compare
    /// the layouts.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn with_vectors(device: &wgpu::Device, vectors: VectorLayout) -> Result<Kernels> {
        pollster::block_on(Self::compiled(device, false, vectors, false))
    }

    /// The kernels for a scene whose largest arrays pass one binding: these
    /// bound in parts, compiled on first use (see [`SPLIT_STORAGE_BUFFERS`]).
    pub(crate) async fn in_parts(&self, device: &wgpu::Device) -> Result<&Kernels> {
        if self.variant.split {
            return Ok(self);
        }
        if self.in_parts.get().is_none() {
            let parted = Self::compiled(device, true, self.variant.vectors, self.worlds).await?;
            // Another scene may have set it meanwhile: the same kernels.
            let _ = self.in_parts.set(Box::new(parted));
        }
        Ok(self.in_parts.get().expect("set above"))
    }

    /// The kernels for a batch of worlds (`gpu::worlds`), compiled on first
    /// use. A batch binds every array whole.
    pub(crate) async fn for_worlds(&self, device: &wgpu::Device) -> Result<&Kernels> {
        if self.worlds {
            return Ok(self);
        }
        if self.for_worlds.get().is_none() {
            let batched = Self::compiled(device, false, self.variant.vectors, true).await?;
            let _ = self.for_worlds.set(Box::new(batched));
        }
        Ok(self.for_worlds.get().expect("set above"))
    }

    async fn compiled(
        device: &wgpu::Device,
        parted: bool,
        vectors: VectorLayout,
        worlds: bool,
    ) -> Result<Kernels> {
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let kernels = Self::compile(device, parted, vectors, worlds);
        if let Some(e) = scope.pop().await {
            return Err(Error::Gpu(format!(
                "compiling the kernels: {}",
                crate::gpu::context::one_line(&e.to_string())
            )));
        }
        kernels
    }

    fn compile(
        device: &wgpu::Device,
        split: bool,
        vectors: VectorLayout,
        worlds: bool,
    ) -> Result<Kernels> {
        let variant = shaders::Variant::for_device(device, split, vectors);
        let splittable =
            device.limits().max_storage_buffers_per_shader_stage >= SPLIT_STORAGE_BUFFERS;
        let uniform = |binding| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let mut group0 = vec![uniform(shaders::PARAMS_BINDING)];
        if worlds {
            group0.push(uniform(worlds::WORLD_STRIDES_BINDING));
            for k in 0..worlds::WORLD_PARAMS_BINDINGS {
                group0.push(uniform(worlds::WORLD_PARAMS_BINDING + k));
            }
        }
        let params_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("params"),
            entries: &group0,
        });
        let mut compiled = Vec::new();
        for &(stage, _) in STAGES {
            let mut reflected = shaders::reflect(stage, variant)
                .map_err(|e| Error::Gpu(format!("wgsl/{stage}.wgsl: {e}")))?;
            let source = match worlds && !shaders::STANDALONE.contains(&stage) {
                true => crate::gpu::worlds::source(stage, variant)
                    .map_err(|e| Error::Gpu(format!("wgsl/{stage}.wgsl for worlds: {e}")))?,
                false => shaders::source(stage, variant),
            };
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(stage),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            });
            for entry in Entry::ALL.into_iter().filter(|e| e.wgsl().0 == stage) {
                let name = entry.wgsl().1;
                let at = reflected
                    .iter()
                    .position(|r| r.name == name)
                    .ok_or_else(|| {
                        Error::Gpu(format!("wgsl/{stage}.wgsl has no entry point `{name}`"))
                    })?;
                let bindings = reflected.swap_remove(at).bindings;
                let params = (!shaders::STANDALONE.contains(&stage)).then_some(&params_layout);
                let kernel = Self::pipeline(device, (&module, params), entry, bindings);
                compiled.push((entry, kernel));
            }
        }
        if compiled.len() != Entry::ALL.len() {
            return Err(Error::Gpu(format!(
                "{} entry points compiled, {} listed in kernels::Entry",
                compiled.len(),
                Entry::ALL.len()
            )));
        }
        compiled.sort_by_key(|(entry, _)| *entry as usize);
        Ok(Kernels {
            kernels: compiled.into_iter().map(|(_, k)| k).collect(),
            params_layout,
            variant,
            software: device.adapter_info().device_type == wgpu::DeviceType::Cpu,
            splittable,
            in_parts: OnceLock::new(),
            worlds,
            for_worlds: OnceLock::new(),
        })
    }

    /// One entry point's pipeline with a layout of the bindings it uses:
    /// `params_layout` as group 0 and its own as group 1 for a scene stage,
    /// its own as group 0 for a standalone one.
    fn pipeline(
        device: &wgpu::Device,
        (module, params_layout): (&wgpu::ShaderModule, Option<&wgpu::BindGroupLayout>),
        entry: Entry,
        mut bindings: BTreeMap<String, Binding>,
    ) -> Kernel {
        let (stage, name) = entry.wgsl();
        let label = format!("{stage}::{name}");
        let group = params_layout.map_or(0, |_| 1);
        bindings.retain(|_, b| b.group == group);
        let layout_entries: Vec<wgpu::BindGroupLayoutEntry> = bindings
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
        let groups = match params_layout {
            Some(params) => vec![Some(params), Some(&layout)],
            None => vec![Some(&layout)],
        };
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(&label),
            bind_group_layouts: &groups,
            immediate_size: 0,
        });
        let pipelines = match entry.by_level() {
            true => Pipelines::ByLevel {
                module: module.clone(),
                layout: pipeline_layout,
                made: Default::default(),
            },
            false => Pipelines::One(Self::compute_pipeline(
                device,
                (module, &pipeline_layout),
                &label,
                name,
                &[],
            )),
        };
        Kernel {
            pipelines,
            layout,
            group,
            bindings,
            entry,
        }
    }

    /// Entry point `name` of `module` with the overrides `constants`.
    fn compute_pipeline(
        device: &wgpu::Device,
        (module, layout): (&wgpu::ShaderModule, &wgpu::PipelineLayout),
        label: &str,
        name: &str,
        constants: &[(&str, f64)],
    ) -> wgpu::ComputePipeline {
        device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(label),
            layout: Some(layout),
            module,
            entry_point: Some(name),
            compilation_options: wgpu::PipelineCompilationOptions {
                constants,
                ..Default::default()
            },
            cache: None,
        })
    }

    /// Whether the device is a CPU adapter (lavapipe).
    pub fn software(&self) -> bool {
        self.software
    }

    /// Whether the solver's workgroup sums run through subgroup operations
    /// (the device has `wgpu::Features::SUBGROUP`), not workgroup memory alone.
    pub fn subgroups(&self) -> bool {
        self.variant.subgroups
    }

    /// How the solver's vectors lie in memory.
    pub fn vectors(&self) -> VectorLayout {
        self.variant.vectors
    }

    /// Whether the device can bind the largest arrays in parts
    /// ([`SPLIT_STORAGE_BUFFERS`]), so a scene may pass the per-binding limit.
    pub fn splittable(&self) -> bool {
        self.splittable
    }

    /// Rows (and outputs) per workgroup tile of the network layer.
    pub fn mlp_tile(&self) -> u32 {
        4 * self.variant.mlp_threads
    }

    /// Group 0 of every scene stage's pass: the run's constants, and for a
    /// batch each world's own and its regions' sizes (`gpu::worlds`).
    pub(crate) fn bind_params(
        &self,
        device: &wgpu::Device,
        params: &wgpu::Buffer,
        worlds: Option<&WorldBuffers>,
    ) -> wgpu::BindGroup {
        fn entry(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
            wgpu::BindGroupEntry {
                binding,
                resource: buffer.as_entire_binding(),
            }
        }
        let mut entries = vec![entry(shaders::PARAMS_BINDING, params)];
        if let Some(w) = worlds {
            entries.push(entry(worlds::WORLD_STRIDES_BINDING, &w.strides));
            let bytes = (worlds::WORLDS_PER_BINDING as usize * size_of::<WorldParams>()) as u64;
            for k in 0..worlds::WORLD_PARAMS_BINDINGS {
                entries.push(wgpu::BindGroupEntry {
                    binding: worlds::WORLD_PARAMS_BINDING + k,
                    resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: &w.params,
                        offset: k as u64 * bytes,
                        size: std::num::NonZeroU64::new(bytes),
                    }),
                });
            }
        }
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("params"),
            layout: &self.params_layout,
            entries: &entries,
        })
    }

    /// What the kernels were compiled for.
    pub fn variant(&self) -> shaders::Variant {
        self.variant
    }

    /// Whether these kernels step a batch of worlds.
    pub fn worlds(&self) -> bool {
        self.worlds
    }

    /// The kernel of `entry`.
    pub fn kernel(&self, entry: Entry) -> &Kernel {
        &self.kernels[entry as usize]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn entries_are_every_entry_point_of_every_stage_in_order() {
        for (k, entry) in Entry::ALL.into_iter().enumerate() {
            assert_eq!(entry as usize, k, "{entry:?} out of order");
        }
        for &(stage, _) in STAGES {
            let variant = shaders::Variant {
                mlp_threads: 16,
                split: false,
                subgroups: false,
                vectors: VectorLayout::Packed,
            };
            let mut found: Vec<String> = shaders::reflect(stage, variant)
                .unwrap()
                .into_iter()
                .map(|e| e.name)
                .collect();
            let mut listed: Vec<String> = Entry::ALL
                .iter()
                .filter(|e| e.wgsl().0 == stage)
                .map(|e| e.wgsl().1.to_string())
                .collect();
            found.sort();
            listed.sort();
            assert_eq!(found, listed, "wgsl/{stage}.wgsl");
        }
    }
}
