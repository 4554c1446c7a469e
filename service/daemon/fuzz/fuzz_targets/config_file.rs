//! Fuzz target: see bodies/config_file.rs (shared with the replay test `tests/fuzz_replay.rs`).
#![no_main]
#[path = "../bodies/config_file.rs"]
mod body;

libfuzzer_sys::fuzz_target!(|data: &[u8]| body::run(data));
