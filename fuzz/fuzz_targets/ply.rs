//! Fuzz target: arbitrary bytes through the PLY importer (via format detection on a .ply name).
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = tw_io::fuzz::import_bytes("fuzz.ply", data);
});
