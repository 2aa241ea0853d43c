//! A compute pass that counts the dispatches recorded into it: a step's
//! dispatch count (`--report`, the per-step figure of issue 67) comes from
//! the dispatches themselves, not from sums kept beside each stage's code.

/// A `wgpu::ComputePass` that counts its dispatches. Stages record through
/// it ([`crate::gpu::kernels::Bound::dispatch`]), so no dispatch goes
/// uncounted.
pub struct Pass<'e> {
    pass: wgpu::ComputePass<'e>,
    dispatches: u32,
    /// Rows of workgroups of each dispatch: one per world of a batch
    /// (`gpu::worlds`).
    worlds: u32,
}

impl<'e> Pass<'e> {
    /// Wraps a pass begun on the caller's encoder.
    pub fn new(pass: wgpu::ComputePass<'e>) -> Pass<'e> {
        Self::for_worlds(pass, 1)
    }

    /// Wraps a pass whose kernels step `worlds` worlds, each dispatch a row
    /// of workgroups per world (`gpu::worlds`).
    pub fn for_worlds(pass: wgpu::ComputePass<'e>, worlds: u32) -> Pass<'e> {
        Pass {
            pass,
            dispatches: 0,
            worlds,
        }
    }

    /// The dispatches recorded so far.
    pub fn dispatches(&self) -> u32 {
        self.dispatches
    }

    /// The pipeline of the next dispatches.
    pub fn set_pipeline(&mut self, pipeline: &wgpu::ComputePipeline) {
        self.pass.set_pipeline(pipeline);
    }

    /// Bind group `index` of the next dispatches (no dynamic offsets).
    pub fn set_bind_group(&mut self, index: u32, group: &wgpu::BindGroup) {
        self.pass.set_bind_group(index, group, &[]);
    }

    /// A dispatch of `groups` workgroups for each world.
    pub fn dispatch_workgroups(&mut self, groups: u32) {
        self.pass.dispatch_workgroups(groups, self.worlds, 1);
        self.dispatches += 1;
    }

    /// A dispatch of `groups` workgroups once, whatever the worlds: a
    /// kernel that covers every world's work itself (the network's batch).
    pub fn dispatch_workgroups_once(&mut self, groups: u32) {
        self.pass.dispatch_workgroups(groups, 1, 1);
        self.dispatches += 1;
    }

    /// A dispatch whose workgroup counts the GPU wrote at `offset` of
    /// `args` (three `u32`s), once: the GPU sized it for every world's
    /// work (the network's batch).
    pub fn dispatch_workgroups_indirect(&mut self, args: &wgpu::Buffer, offset: u64) {
        self.pass.dispatch_workgroups_indirect(args, offset);
        self.dispatches += 1;
    }
}
