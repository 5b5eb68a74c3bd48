//! Fuzz target: arbitrary bytes as a camera path file (`bench --path`, `view --path`), parsed,
//! validated and turned into cameras (see `tw_runtime::fuzz::camera_path`).
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = tw_runtime::fuzz::camera_path(data);
});
