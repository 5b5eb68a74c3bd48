//! Fuzz target: arbitrary bytes as a `scene.tw` store, opened through the memory-mapped and the
//! in-memory reader, verified, every page decoded, every group's links read, then cuts selected
//! from it (see `tw_runtime::fuzz::store_bytes`).
//! Checksums are not enforced under `cfg(fuzzing)`, so the fuzzer reaches the parsers.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    tw_runtime::fuzz::store_bytes(data);
});
