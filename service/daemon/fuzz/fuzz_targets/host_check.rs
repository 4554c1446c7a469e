//! Fuzz target: see bodies/host_check.rs (shared with the replay test `tests/fuzz_replay.rs`).
#![no_main]
#[path = "../bodies/host_check.rs"]
mod body;

libfuzzer_sys::fuzz_target!(|data: &[u8]| body::run(data));
