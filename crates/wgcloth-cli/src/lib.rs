//! The `wgcloth` command's own code, beside the library it drives: the run
//! loop with its reports and GPU-fault fallback, frames and OBJ files,
//! soak monitoring, the benchmark suite and its plots.

pub mod bench;
pub mod frames;
pub mod in_flight;
pub mod loss_plot;
pub mod monitor;
pub mod plot;
pub mod run;
pub mod sweep;
