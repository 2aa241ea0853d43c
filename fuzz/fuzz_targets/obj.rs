//! Fuzzes the obj loader with the checks of tests/common/loaders.rs.
#![no_main]

#[path = "../../tests/common/loaders.rs"]
mod loaders;

libfuzzer_sys::fuzz_target!(|data: &[u8]| loaders::obj(data));
