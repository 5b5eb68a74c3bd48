//! Fuzz target: a store written from fuzzed geometry (extreme grid coordinates, steps and
//! origins, degenerate triangles, non-finite spheres), then bytes of the file flipped; opened,
//! verified, decoded and selected from (see `tw_runtime::fuzz::store_geometry`).
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    tw_runtime::fuzz::store_geometry(data);
});
