//! `volcapd`: the appliance daemon. Captures frames (today: the embedded scene simulator),
//! runs the real-time pipeline on dedicated threads and publishes the renders over HTTP.
//! Until the trained models land (issue #6) the field is the simulator's ground truth,
//! labelled `oracle` everywhere: it is never presented as a reconstruction.

use volcapd::{capture, config, http, pipeline};

use clap::Parser;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
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
    let mode = cfg.field().name();
    tracing::info!(config = %cli.config.display(), board = %cfg.description, "starting");
    let (factory, source) = match camera_factory(&cfg) {
        Ok(f) => f,
        Err(e) => {
            eprintln!(
                "volcapd: {} ({}): {e}",
                cfg.camera.backend.name(),
                cli.config.display()
            );
            return ExitCode::from(EXIT_CONFIG);
        }
    };
    if cli.check_config {
        println!(
            "{}: ok ({}; camera {source}, mode {mode})",
            cli.config.display(),
            cfg.description,
        );
        return ExitCode::SUCCESS;
    }
    let (tx, _rx) = tokio::sync::watch::channel(None);
    let shared = Arc::new(pipeline::Shared {
        stats: Default::default(),
        e2e: Default::default(),
        state: std::sync::Mutex::new(pipeline::PipelineState::Starting),
        camera: std::sync::Mutex::new(pipeline::CameraStatus {
            source: source.clone(),
            state: "opening",
            ..Default::default()
        }),
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
    let threads = pipeline::start(&cfg, factory, shared.clone());
    let app = Arc::new(http::App::new(
        shared.clone(),
        cfg.http.client_limit,
        cfg.http.token.clone(),
    ));
    println!(
        "volcapd: viewer at http://{addr}/ (mode: {mode}, {}^3, camera {source})",
        cfg.render.resolution.0,
    );
    let served = rt.block_on(async move {
        axum::serve(
            listener,
            http::router(app).into_make_service_with_connect_info::<SocketAddr>(),
        )
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

/// The configured camera backend, checked as far as it can be before the thread starts (the
/// scene parses, the recording exists, the backend is built in). Returns the factory that
/// builds it on the capture thread and a description.
fn camera_factory(cfg: &config::Config) -> Result<(pipeline::CameraFactory, String), String> {
    use capture::Camera;
    match cfg.camera.backend {
        config::Backend::Sim => {
            let scene_path = cfg.scene_path().ok_or("camera.scene is required")?;
            let assets = volcap_sim::HumanAssets::embedded().map_err(|e| e.to_string())?;
            let sim = volcap_sim::Scene::load(&scene_path)
                .map_err(|e| format!("scene error: {e}"))
                .and_then(|s| {
                    volcap_sim::Simulator::new(s, Arc::new(assets))
                        .map_err(|e| format!("scene error: {e}"))
                })?;
            let cam = capture::sim::SimCamera::new(sim, scene_path.display().to_string());
            let source = cam.describe();
            Ok((
                Box::new(move || Ok(Box::new(cam) as Box<dyn Camera>)),
                source,
            ))
        }
        config::Backend::File => {
            let path = cfg
                .camera
                .path
                .as_deref()
                .map(|p| cfg.resolve(p))
                .ok_or("camera.path is required")?;
            if !path.exists() {
                return Err(format!("camera.path: {} does not exist", path.display()));
            }
            let cam = capture::file::FileCamera::new(
                path,
                cfg.camera.fps.unwrap_or(15.0),
                cfg.camera.looping.unwrap_or(true),
            );
            let source = cam.describe();
            Ok((
                Box::new(move || Ok(Box::new(cam) as Box<dyn Camera>)),
                source,
            ))
        }
        config::Backend::V4l2 => v4l2_factory(cfg),
        config::Backend::Depthai => depthai_factory(cfg),
    }
}

#[cfg(feature = "v4l2")]
fn v4l2_factory(cfg: &config::Config) -> Result<(pipeline::CameraFactory, String), String> {
    use capture::v4l2::{DeviceSpec, V4l2Camera, V4l2Settings, sys::V4lDevice};
    let c = &cfg.camera;
    let settings = V4l2Settings {
        device: DeviceSpec::parse(c.device.as_deref().unwrap_or("/dev/video0")),
        format: c.format.unwrap_or_default(),
        size: (c.width.unwrap_or(640), c.height.unwrap_or(480)),
        fps: c.fps.unwrap_or(30.0).round() as u32,
    };
    let cam = V4l2Camera::new(V4lDevice::default(), settings);
    let source = capture::Camera::describe(&cam);
    Ok((
        Box::new(move || Ok(Box::new(cam) as Box<dyn capture::Camera>)),
        source,
    ))
}

#[cfg(not(feature = "v4l2"))]
fn v4l2_factory(_: &config::Config) -> Result<(pipeline::CameraFactory, String), String> {
    Err("this volcapd was built without V4L2 support; rebuild with `--features v4l2` (needs libclang-dev)".into())
}

#[cfg(feature = "depthai")]
fn depthai_factory(cfg: &config::Config) -> Result<(pipeline::CameraFactory, String), String> {
    let c = &cfg.camera;
    let (size, fps) = (
        (c.width.unwrap_or(640), c.height.unwrap_or(400)),
        c.fps.unwrap_or(30.0),
    );
    let source = format!("depthai:CAM_A {}x{}@{fps}", size.0, size.1);
    Ok((
        Box::new(move || {
            Ok(Box::new(capture::depthai::DepthaiCamera::new(size, fps))
                as Box<dyn capture::Camera>)
        }),
        source,
    ))
}

#[cfg(not(feature = "depthai"))]
fn depthai_factory(_: &config::Config) -> Result<(pipeline::CameraFactory, String), String> {
    Err("this volcapd was built without DepthAI support; rebuild with `--features depthai`, or run an OAK camera in UVC mode with backend \"v4l2\"".into())
}
