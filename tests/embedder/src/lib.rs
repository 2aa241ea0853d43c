//! Nothing of its own: this crate is an app that embeds wgcloth, and its
//! test (`tests/default_limits.rs`) is what such an app does.
