//! The GPU path: every stage of the step as a WGSL compute pass on wgpu.
//! Kernels (pipelines, built once per device) live apart from a scene's
//! state (buffers), as in wgsparkl.

pub mod constants;
pub mod context;
pub mod kernels;
pub mod layout;
pub mod mlp;
pub mod readback;
pub mod shaders;
pub mod sim;

pub use context::GpuContext;
pub use kernels::Kernels;
pub use mlp::GpuMlp;
pub use readback::Readback;
pub use sim::GpuSim;
