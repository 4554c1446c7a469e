//! Fuzz target: see bodies/frame_decode.rs (shared with the replay test `tests/fuzz_replay.rs`).
#![no_main]
#[path = "../bodies/frame_decode.rs"]
mod body;

libfuzzer_sys::fuzz_target!(|data: &[u8]| body::run(data));
