//! Fuzz target: see bodies/config_parse.rs (shared with the replay test `tests/fuzz_replay.rs`).
#![no_main]
#[path = "../bodies/config_parse.rs"]
mod body;

libfuzzer_sys::fuzz_target!(|data: &[u8]| body::run(data));
