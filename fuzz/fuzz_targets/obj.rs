//! Fuzz target: arbitrary bytes through the OBJ importer (via format detection on a .obj name).
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = tw_io::fuzz::import_bytes("fuzz.obj", data);
});
