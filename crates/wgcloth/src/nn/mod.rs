//! The learned collision models (thesis 2.4, 2.6–2.7): the network and its
//! input Jacobian, the weights file, and the domain its inputs are drawn
//! from. Recording data and training live in the `wgcloth-learn` crate.

pub mod domain;
pub mod mlp;
pub mod weights;

pub use mlp::{Layer, Mlp};
