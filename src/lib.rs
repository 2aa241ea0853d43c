//! wgcloth: an implicit mass-spring cloth simulator with a moving rigid
//! body and learned collision response, after Yahya (2023), "Collision
//! resolution for cloth simulations using machine learning".
//!
//! - [`config`]: the run configuration (TOML and flags), validated.
//! - [`scene`]: cloth grid, springs, rigid body and its motion.
//! - [`cpu`]: the reference step, one module per stage.
//! - [`run`]: running a scene and reporting on it.

pub mod bench;
pub mod bvh;
pub mod config;
pub mod cpu;
pub mod error;
pub mod gpu;
pub mod health;
pub mod math;
pub mod monitor;
pub mod nn;
pub mod plot;
pub mod render;
pub mod run;
pub mod scene;
pub mod stage;

pub use config::Config;
pub use error::{Error, Result};
pub use scene::Scene;
