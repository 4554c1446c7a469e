//! Board config files as the daemon reads them (`Config::load`: regular file, bounded,
//! opened without blocking) from arbitrary bytes, including non-UTF-8 and sizes around the
//! limit: a config or an error naming the file, never a panic.
//!
//! The body of the fuzz target of the same name (fuzz_targets/), shared with the replay test
//! (service/daemon/tests/fuzz_replay.rs) that CI runs.
use std::path::PathBuf;
use std::sync::OnceLock;
use volcapd::config::{Config, MAX_CONFIG_BYTES};

fn path() -> &'static PathBuf {
    static P: OnceLock<PathBuf> = OnceLock::new();
    P.get_or_init(|| std::env::temp_dir().join(format!("volcapd-fuzz-{}.toml", std::process::id())))
}

pub fn run(data: &[u8]) {
    let p = path();
    // The first byte pads the file toward the size limit (so both sides of it are tried).
    let Some((&pad, rest)) = data.split_first() else {
        return;
    };
    let mut bytes = rest.to_vec();
    if pad > 250 {
        bytes.resize(MAX_CONFIG_BYTES as usize + (pad as usize - 253), b'#');
    }
    if std::fs::write(p, &bytes).is_err() {
        return;
    }
    match Config::load(p) {
        Ok(c) => assert!(bytes.len() as u64 <= MAX_CONFIG_BYTES && c.file == *p),
        Err(e) => assert!(
            e.starts_with(&p.display().to_string()),
            "error does not name the file: {e}"
        ),
    }
}
