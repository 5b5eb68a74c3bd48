//! Fuzz target: arbitrary bytes as a viewer script (`view --script`), parsed and stepped frame
//! by frame (see `tw_view::script::fuzz_bytes`).
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = tw_view::script::fuzz_bytes(data);
});
