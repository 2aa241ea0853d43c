//! The learned collision models (thesis 2.4, 2.6–2.7): the network and its
//! input Jacobian, the weights file, contact data, and training.

pub mod dataset;
pub mod domain;
pub mod eval;
pub mod mlp;
pub mod plot;
pub mod train;
pub mod weights;

pub use mlp::{Layer, Mlp};
