//! Fuzz target: arbitrary bytes as a cull server connection's stream (`terawalk cull-server`,
//! `bench --cull-server`): every message decoded in turn and the deltas applied to a visible
//! set (see `tw_net::fuzz_decode`).
#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = tw_net::fuzz_decode(data);
});
