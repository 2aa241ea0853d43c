//! The learning side of wgcloth (thesis 2.4–2.7), kept out of the library
//! an app embeds: recording collision data from simulated runs
//! ([`dataset`]) and sampling the networks' declared input domains
//! ([`domain`]), training the contact networks with candle ([`train`]),
//! and scoring a weights file ([`eval`]). The networks themselves, their
//! weights format and their GPU kernels live in `wgcloth::nn`.

pub mod dataset;
pub mod domain;
pub mod eval;
pub mod train;
