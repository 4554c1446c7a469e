//! `volcapd`: the appliance daemon. Captures frames (today: the embedded scene simulator),
//! runs the real-time pipeline on dedicated threads and publishes the renders over HTTP.
//! Until the trained models land (issue #6) the field is the simulator's ground truth,
//! labelled `oracle` everywhere: it is never presented as a reconstruction.

mod config;
mod http;
mod pipeline;

use clap::Parser;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Instant;

#[derive(Parser)]
#[command(name = "volcapd", version, about = "volcap appliance daemon")]
struct Cli {
    /// Board configuration (TOML).
    #[arg(long, default_value = "board-config/sim.toml")]
    config: PathBuf,
    /// Override the HTTP bind address from the config (e.g. 127.0.0.1:0 for any free port).
    #[arg(long)]
    http: Option<SocketAddr>,
    /// Parse and check the configuration (and its scene), then exit.
    #[arg(long)]
    check_config: bool,
}

/// Exit code for configuration and input errors (systemd: do not restart blindly).
const EXIT_CONFIG: u8 = 2;
/// Exit code for runtime faults.
const EXIT_RUNTIME: u8 = 1;

fn main() -> ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into()),
        )
        .with_writer(std::io::stderr)
        .init();
    let cli = Cli::parse();
    let mut cfg = match config::Config::load(&cli.config) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("volcapd: config error: {e}");
            return ExitCode::from(EXIT_CONFIG);
        }
    };
    if let Some(a) = cli.http {
        cfg.http.bind = a;
    }
    let assets = match volcap_sim::HumanAssets::embedded() {
        Ok(a) => Arc::new(a),
        Err(e) => {
            eprintln!("volcapd: {e}");
            return ExitCode::from(EXIT_CONFIG);
        }
    };
    let scene_path = cfg.scene_path();
    // One backend and one field mode exist today; matching keeps new ones from being ignored.
    let config::Backend::Sim = cfg.camera.backend;
    let mode = match cfg.render.field {
        config::FieldMode::Oracle => "oracle",
    };
    tracing::info!(config = %cli.config.display(), board = %cfg.description, "starting");
    let sim = match volcap_sim::Scene::load(&scene_path)
        .map_err(|e| e.to_string())
        .and_then(|s| volcap_sim::Simulator::new(s, assets).map_err(|e| e.to_string()))
    {
        Ok(s) => s,
        Err(e) => {
            eprintln!("volcapd: scene error ({}): {e}", cli.config.display());
            return ExitCode::from(EXIT_CONFIG);
        }
    };
    if cli.check_config {
        println!(
            "{}: ok ({}; scene {}, mode {mode})",
            cli.config.display(),
            cfg.description,
            scene_path.display()
        );
        return ExitCode::SUCCESS;
    }
    let (tx, _rx) = tokio::sync::watch::channel(None);
    let shared = Arc::new(pipeline::Shared {
        stats: Default::default(),
        e2e: Default::default(),
        state: std::sync::Mutex::new(pipeline::PipelineState::Starting),
        view: std::sync::Mutex::new((cfg.render.yaw, cfg.render.pitch)),
        stop: AtomicBool::new(false),
        started: Instant::now(),
        published: tx,
        mode,
        resolution: cfg.render.resolution.0,
        latest_field: std::sync::Mutex::new(None),
        coarse_level: cfg.render.coarse_level,
    });
    let rt = match tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
    {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("volcapd: cannot start the async runtime: {e}");
            return ExitCode::from(EXIT_RUNTIME);
        }
    };
    let listener = match rt.block_on(tokio::net::TcpListener::bind(cfg.http.bind)) {
        Ok(l) => l,
        Err(e) => {
            eprintln!(
                "volcapd: cannot bind {} (http.bind in {}): {e}",
                cfg.http.bind,
                cli.config.display()
            );
            return ExitCode::from(EXIT_CONFIG);
        }
    };
    let addr = listener.local_addr().unwrap_or(cfg.http.bind);
    let threads = pipeline::start(&cfg, sim, shared.clone());
    let app = Arc::new(http::App {
        shared: shared.clone(),
        clients: AtomicUsize::new(0),
        client_limit: cfg.http.client_limit,
        token: cfg.http.token.clone(),
    });
    println!(
        "volcapd: viewer at http://{addr}/ (mode: {mode}, {}^3, scene {})",
        cfg.render.resolution.0,
        scene_path.display()
    );
    let served = rt.block_on(async move {
        axum::serve(listener, http::router(app))
            .with_graceful_shutdown(async {
                let _ = tokio::signal::ctrl_c().await;
            })
            .await
    });
    shared.stop.store(true, Ordering::Relaxed);
    for t in threads {
        let _ = t.join();
    }
    match served {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("volcapd: http server failed: {e}");
            ExitCode::from(EXIT_RUNTIME)
        }
    }
}
