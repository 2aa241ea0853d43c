//! Fuzzes the config loader with the checks of crates/wgcloth/tests/common/loaders.rs.
#![no_main]

#[path = "../../crates/wgcloth/tests/common/loaders.rs"]
mod loaders;

libfuzzer_sys::fuzz_target!(|data: &[u8]| loaders::config(data));
