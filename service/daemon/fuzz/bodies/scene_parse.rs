//! Scene file parsing: any text gives a scene or an error naming the file, never a panic.
//!
//! The body of the fuzz target of the same name (fuzz_targets/), shared with the replay test
//! (service/daemon/tests/fuzz_replay.rs) that CI runs.

pub fn run(data: &[u8]) {
    if let Ok(text) = std::str::from_utf8(data)
        && let Err(e) = volcap_sim::Scene::parse(text, std::path::Path::new("fuzz.toml"))
    {
        assert!(
            e.to_string().contains("fuzz.toml"),
            "error does not name the file: {e}"
        );
    }
}
