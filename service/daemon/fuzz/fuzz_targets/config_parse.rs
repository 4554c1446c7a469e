//! Board config parsing: any text gives a config or an error, never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data)
        && let Err(e) = volcapd::config::Config::parse(text, std::path::Path::new("fuzz.toml"))
    {
        assert!(
            e.starts_with("fuzz.toml"),
            "error does not name the file: {e}"
        );
    }
});
