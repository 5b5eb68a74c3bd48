//! Fuzz target: arbitrary bytes as a `scene.tw` store, written to a temporary file, opened
//! (memory-mapped), verified, every page decoded and every group's links read; and the same
//! through the in-memory reader.
//! Checksums are not enforced under `cfg(fuzzing)`, so the fuzzer reaches the parsers.
#![no_main]
use std::io::Write;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let mut file = tempfile::NamedTempFile::new().expect("temp file");
    file.write_all(data).expect("write temp file");
    let from_file = tw_store::Store::open(file.path());
    if let Ok(store) = &from_file {
        let _ = store.verify(|_, _| {});
        for i in 0..store.pages().len() as u32 {
            let _ = store.page(i);
        }
        // The group links (one index past the table too).
        for g in 0..=store.groups().len() as u32 {
            let _ = (store.group_sources(g), store.group_parents(g));
        }
    }
    // The mmap reader and the in-memory reader must agree on whether the bytes are a store.
    let from_bytes = tw_store::Store::from_bytes(data.to_vec());
    assert_eq!(from_file.is_ok(), from_bytes.is_ok());
    tw_store::fuzz_bytes(data);
});
