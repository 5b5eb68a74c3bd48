//! Fuzz target: arbitrary bytes through the glTF importer, as a .glb and as a .gltf.
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = tw_io::fuzz::import_bytes("fuzz.glb", data);
    let _ = tw_io::fuzz::import_bytes("fuzz.gltf", data);
});
