//! One module per stage of the step, each beside its kernel
//! (`wgsl/<stage>.wgsl`, CPU twin `cpu/<stage>.rs`), as wgsparkl does: a
//! stage owns its kernels bound to the scene's buffers and records itself
//! with `encode`. The scene's buffers ([`super::buffers`]) and the kernels
//! ([`super::kernels`]) live apart from them.

pub mod assemble;
pub mod collide;
pub mod contact;
pub mod integrate;
pub mod lines;
pub mod load;
pub mod measure;
pub mod multigrid;
pub mod pcg;
pub mod precondition;
pub mod rigid;
pub mod self_contact;
pub mod separate;

use crate::gpu::buffers::Buffers;
use crate::gpu::kernels::Kernels;
use crate::gpu::layout::Params;
use crate::gpu::mlp::GpuMlp;
use crate::gpu::pass::Pass;
use crate::scene::Scene;
use crate::stage::Stage;

/// What recording a stage reads besides its own bindings.
pub(crate) struct Recording<'a> {
    pub(crate) params: &'a Params,
    /// The pass's group 0, the run's constants (the network's kernels
    /// replace it; the contact stage sets it back).
    pub(crate) group0: &'a wgpu::BindGroup,
    /// PCG iterations to record (`gpu::CgBudget`).
    pub(crate) cg_iterations: u32,
}

/// A stage of the step on the GPU, which [`Stages::of`] finds by its
/// [`Stage`]: what it clears before its pass and what it records in it.
pub(crate) trait Record {
    /// Before the pass: the buffers it needs cleared.
    fn clear(&self, _encoder: &mut wgpu::CommandEncoder, _p: &Params) {}

    /// The pass's dispatches.
    fn encode(&self, pass: &mut Pass, r: &Recording);
}

/// Every stage of a step, bound to one scene's buffers.
pub(crate) struct Stages {
    /// Group 0 of every pass: the run's constants, set once per pass.
    pub(crate) params: wgpu::BindGroup,
    pub(crate) rigid: rigid::Rigid,
    pub(crate) collide: collide::Collide,
    pub(crate) contact: contact::Contact,
    pub(crate) assemble: assemble::Assemble,
    pub(crate) self_contact: self_contact::SelfContact,
    pub(crate) pcg: pcg::Pcg,
    pub(crate) load: load::Load,
    pub(crate) separate: separate::Separate,
    pub(crate) integrate: integrate::Integrate,
    pub(crate) measure: measure::Measure,
    pub(crate) lines: lines::Lines,
}

impl Stages {
    /// Starts a pass's work: the run's constants in group 0.
    pub(crate) fn begin(&self, pass: &mut Pass) {
        pass.set_bind_group(0, &self.params);
    }

    /// The GPU side of `stage`.
    pub(crate) fn of(&self, stage: Stage) -> &dyn Record {
        match stage {
            Stage::Rigid => &self.rigid,
            Stage::Collide => &self.collide,
            Stage::Contact => &self.contact,
            Stage::Assemble => &self.assemble,
            Stage::SelfContact => &self.self_contact,
            Stage::Pcg => &self.pcg,
            Stage::Load => &self.load,
            Stage::Integrate => &self.integrate,
            Stage::Measure => &self.measure,
            Stage::Separate => &self.separate,
        }
    }

    pub(crate) fn new(
        kernels: &Kernels,
        device: &wgpu::Device,
        b: &Buffers,
        scene: &Scene,
        network: Option<GpuMlp>,
    ) -> Stages {
        Stages {
            params: kernels.bind_params(device, &b.params, b.batch.as_ref()),
            rigid: rigid::Rigid::new(kernels, device, b),
            collide: collide::Collide::new(kernels, device, b),
            contact: contact::Contact::new(kernels, device, b, network),
            assemble: assemble::Assemble::new(kernels, device, b),
            self_contact: self_contact::SelfContact::new(kernels, device, b),
            pcg: pcg::Pcg::new(kernels, device, b, scene),
            load: load::Load::new(kernels, device, b),
            separate: separate::Separate::new(kernels, device, b),
            integrate: integrate::Integrate::new(kernels, device, b),
            measure: measure::Measure::new(kernels, device, b),
            lines: lines::Lines::new(kernels, device, b),
        }
    }
}
