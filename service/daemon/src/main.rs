//! `volcapd`, the appliance daemon. Capture, the real-time pipeline and LAN publishing land
//! with issue #4 (see ARCHITECTURE.md); until then this binary says so and exits non-zero so
//! that nothing mistakes it for a running service.

use std::process::ExitCode;

fn main() -> ExitCode {
    eprintln!(
        "volcapd: not built yet. The daemon (sim camera, pipeline, viewer on localhost) lands with \
         issue #4. What works today: `cargo run --release -p volcap -- bench localize` (the engine's \
         accuracy-vs-time benchmark)."
    );
    ExitCode::from(2)
}
