//! Fuzz target: arbitrary bytes through the MTL material library parser (what an OBJ's
//! `mtllib` reads).
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = tw_io::fuzz::mtl_bytes(data);
});
