#![warn(missing_docs)]
//! wgcloth: an implicit (backward Euler) mass-spring cloth with a moving
//! rigid body and learned collision response, after Yahya (2023),
//! "Collision resolution for cloth simulations using machine learning".
//! Every stage of a step is a WGSL compute pass that records into your
//! own wgpu command encoder, on your own device, within WebGPU's default
//! limits; each has a CPU twin ([`cpu`]) that validates it and runs where
//! there is no GPU.
//!
//! An app embeds it in a few lines: [`gpu::GpuSim::new`] takes the app's
//! device, queue and a [`Scene`]; [`gpu::GpuSim::encode_step`] records a
//! step with no wait and no readback; the positions and triangle indices
//! are buffers the app binds in its own render pass; [`gpu::Readback`]
//! reads the state back without blocking. The whole program
//! (`examples/embed.rs`, which CI runs on lavapipe):
//!
//! ```no_run
#![doc = include_str!("../examples/embed.rs")]
//! ```
//!
//! A device that cannot run a scene gives an [`Error`] naming the limit,
//! what the scene needs and what the device has; wgcloth enables no wgpu
//! backend itself, so the app's own wgpu dependency picks them.
//!
//! - [`config`]: the run configuration, validated field by field (TOML
//!   files with the `toml` feature).
//! - [`scene`]: cloth grid, springs, rigid body and its motion (OBJ bodies
//!   with the `obj` feature).
//! - [`cpu`]: the reference step, one module per stage.
//! - [`gpu`]: the same stages as WGSL compute passes, and [`gpu::GpuSim`]
//!   (one scene, or a batch of worlds stepped together:
//!   [`gpu::GpuSim::with_worlds`]).
//! - [`nn`]: the contact networks, their weights files and their inputs.
//! - [`render`]: drawing a scene's frames from the simulator's buffers.
//! - [`health`]: what a step must leave, and where divergence started.
//! - [`sensitivity`]: how far two faithful runs of a scene end apart, what
//!   a GPU run is held to against the CPU's.
//! - [`intersections`]: the cloth triangle pairs that pass through each
//!   other; [`cpu::separate`] (and its WGSL twin) holds each step back so
//!   that none does, with `[self_contact]` on.

pub mod bvh;
pub mod config;
pub mod cpu;
pub mod error;
pub mod gpu;
mod grid;
pub mod health;
pub mod intersections;
pub mod math;
pub mod multigrid;
pub mod nn;
mod parallel;
pub mod render;
pub mod scene;
pub mod sensitivity;
pub mod stage;

pub use config::Config;
pub use error::{Error, Result};
pub use gpu::GpuSim;
pub use scene::Scene;
