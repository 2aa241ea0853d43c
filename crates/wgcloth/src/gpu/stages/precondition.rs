//! Stage "pcg"'s preconditioners on the GPU (CPU twin:
//! `cpu::precondition`): what the solve asks of one, and Jacobi's.

use crate::gpu::kernels::Bound;
use crate::gpu::pass::Pass;

/// A preconditioner P ≈ A of the GPU's solve, twin of
/// `cpu::precondition::Precondition`: set up once a step, then z = P⁻¹ r with
/// partial rᵀz after `init` and after each iteration's x and r update.
/// `Send + Sync`, so that a simulator can move to, and be shared by, an
/// app's other threads.
pub(crate) trait Precondition: Send + Sync {
    /// P from this step's A, before `init`.
    fn encode_setup(&self, pass: &mut Pass);
    /// z = P⁻¹ r and partial rᵀz, sized on the host (`None`, after `init`)
    /// or from an iteration's `scalars`.
    fn encode_apply(&self, pass: &mut Pass, scalars: Option<&wgpu::Buffer>);
    /// Whether P is the diagonal that `init` forms and applies and
    /// `update` applies in its x and r pass, so that nothing else does.
    fn fused(&self) -> bool {
        false
    }
    /// The whole solve in one dispatch, where P runs one: PCG and P
    /// looped in one workgroup, from `init`'s residual and scalars.
    fn whole(&self) -> Option<&Bound> {
        None
    }
}

/// The thesis's preconditioner, A's diagonal: `init` forms and applies it,
/// `update` applies it in the pass that updates x and r.
pub(crate) struct Jacobi;

impl Precondition for Jacobi {
    fn encode_setup(&self, _: &mut Pass) {}

    fn encode_apply(&self, _: &mut Pass, _: Option<&wgpu::Buffer>) {}

    fn fused(&self) -> bool {
        true
    }
}
