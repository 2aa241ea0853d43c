//! The learned collision models (thesis 2.4, 2.6–2.7): the network and its
//! input Jacobian, and the weights file. The declared input domains,
//! recording data and training live in the `wgcloth-learn` crate.

pub mod mlp;
pub mod weights;

pub use mlp::{Layer, Mlp};
