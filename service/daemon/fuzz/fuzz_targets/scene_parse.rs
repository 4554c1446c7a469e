//! Scene file parsing: any text gives a scene or an error naming the file, never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data)
        && let Err(e) = volcap_sim::Scene::parse(text, std::path::Path::new("fuzz.toml"))
    {
        assert!(
            e.to_string().contains("fuzz.toml"),
            "error does not name the file: {e}"
        );
    }
});
