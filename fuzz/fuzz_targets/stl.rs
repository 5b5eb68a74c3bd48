//! Fuzz target: arbitrary bytes through the STL importer (via format detection on a .stl name).
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = tw_io::fuzz::import_bytes("fuzz.stl", data);
});
