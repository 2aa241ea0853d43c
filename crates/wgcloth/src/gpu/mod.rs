//! The GPU path: every stage of the step as a WGSL compute pass on wgpu.
//! Kernels (pipelines, built once per device: `kernels`) live apart from a
//! scene's state (buffers: `buffers`), as in wgsparkl; each stage's module
//! in `stages` binds the one to the other and records itself, and
//! [`GpuSim`] runs them as a step.

pub mod budget;
pub(crate) mod buffers;
pub mod constants;
pub mod context;
pub mod kernels;
pub mod layout;
pub mod mlp;
pub mod pass;
pub mod readback;
pub mod shaders;
pub mod sim;
pub(crate) mod stages;
pub mod worlds;

pub use budget::CgBudget;
#[cfg(not(target_arch = "wasm32"))]
pub use budget::SolvedSteps;
pub use context::{GpuContext, OPTIONAL_FEATURES};
pub use kernels::Kernels;
pub use mlp::GpuMlp;
pub use pass::Pass;
pub use readback::Readback;
pub use sim::GpuSim;
