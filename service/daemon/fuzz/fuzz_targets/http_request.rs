//! Fuzz target: see bodies/http_request.rs (shared with the replay test `tests/fuzz_replay.rs`).
#![no_main]
#[path = "../bodies/http_request.rs"]
mod body;

libfuzzer_sys::fuzz_target!(|data: &[u8]| body::run(data));
