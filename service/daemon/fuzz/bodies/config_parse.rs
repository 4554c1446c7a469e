//! Board config parsing: any text gives a config or an error, never a panic.
//!
//! The body of the fuzz target of the same name (fuzz_targets/), shared with the replay test
//! (service/daemon/tests/fuzz_replay.rs) that CI runs.

pub fn run(data: &[u8]) {
    if let Ok(text) = std::str::from_utf8(data)
        && let Err(e) = volcapd::config::Config::parse(text, std::path::Path::new("fuzz.toml"))
    {
        assert!(
            e.starts_with("fuzz.toml"),
            "error does not name the file: {e}"
        );
    }
}
