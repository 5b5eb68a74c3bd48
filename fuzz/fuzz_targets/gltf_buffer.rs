//! Fuzz target: a .gltf with an external buffer file. The bytes up to the first NUL are the
//! JSON (`scene.gltf`), the rest the buffer (`buffer.bin`), both written to a temporary folder
//! and imported from there (see `tw_io::fuzz::gltf_with_buffer`).
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = tw_io::fuzz::gltf_with_buffer(data);
});
