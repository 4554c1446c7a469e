//! `volcapd`: the appliance daemon. Captures frames from the configured camera backend,
//! runs the real-time pipeline on dedicated threads, publishes the renders over HTTP,
//! reports health and takes control over D-Bus, and talks to systemd (READY, STATUS,
//! watchdog). Until the trained models land (issue #6) the field is the simulator's ground
//! truth (`oracle`) or the camera frame itself (`camera`), labelled everywhere: never
//! presented as a reconstruction.

use clap::Parser;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use volcapd::{capture, config, dbus, http, notify, pipeline, rtsp};

#[derive(Parser)]
#[command(name = "volcapd", version, about = "volcap appliance daemon")]
struct Cli {
    /// Board configuration (TOML).
    #[arg(long, default_value = "board-config/sim.toml")]
    config: PathBuf,
    /// Override the HTTP bind address from the config (e.g. 127.0.0.1:0 for any free port).
    #[arg(long)]
    http: Option<SocketAddr>,
    /// Override the D-Bus bus from the config: session, system or none.
    #[arg(long)]
    bus: Option<String>,
    /// Parse and check the configuration (and its camera source), then exit.
    #[arg(long)]
    check_config: bool,
    /// Print the D-Bus introspection XML generated from the code, then exit.
    #[arg(long, hide = true)]
    print_introspection: bool,
}

/// Exit code for configuration and input errors: systemd does not restart on it
/// (`RestartPreventExitStatus=2`), a person has to fix the file.
const EXIT_CONFIG: u8 = 2;
/// Exit code for runtime faults (restarted by systemd).
const EXIT_RUNTIME: u8 = 1;

fn main() -> ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into()),
        )
        .with_writer(std::io::stderr)
        // Colour on a terminal only: the journal (and a log file) gets plain text.
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
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
    if let Some(b) = &cli.bus {
        cfg.dbus.bus = match b.as_str() {
            "session" => config::Bus::Session,
            "system" => config::Bus::System,
            "none" => config::Bus::None,
            other => {
                eprintln!("volcapd: --bus {other:?}: one of session, system, none");
                return ExitCode::from(EXIT_CONFIG);
            }
        };
    }
    let mode = cfg.field().name();
    // [compute] backend: the adapter the networks run on, or the CPU.
    let (gpu_runtime, compute) = match volcapd::compute::open(
        &cfg.compute,
        cfg.field() == config::FieldMode::Model,
        cfg.model.precision == config::Precision::Int8,
    ) {
        Ok(o) => o,
        Err(e) => {
            eprintln!("volcapd: compute.backend in {}: {e}", cli.config.display());
            return ExitCode::from(EXIT_CONFIG);
        }
    };
    // Model mode: the networks' runtime (label) and why `auto` fell back to tract.
    let mut runtime: Option<(String, Option<String>)> = None;
    let models = if cfg.field() == config::FieldMode::Model {
        let dir = cfg.resolve(&cfg.model.dir);
        let prec = match cfg.model.precision {
            config::Precision::F32 => volcap_engine::model::Precision::F32,
            config::Precision::Int8 => volcap_engine::model::Precision::Int8,
        };
        let lib = cfg.compute.onnxruntime_lib.as_ref().map(|p| cfg.resolve(p));
        let opened = match gpu_runtime {
            Some(runtime) => Ok(volcap_engine::model::runtime::Opened {
                runtime,
                fallback: None,
            }),
            None => volcap_engine::model::Runtime::open(cfg.compute.runtime, lib.as_deref()),
        };
        let opened = match opened {
            Ok(o) => o,
            Err(e) => {
                eprintln!("volcapd: compute.runtime in {}: {e}", cli.config.display());
                return ExitCode::from(EXIT_CONFIG);
            }
        };
        if let Some(why) = &opened.fallback {
            tracing::warn!(%why, "compute.runtime = auto: the networks run on tract");
            if prec == volcap_engine::model::Precision::Int8 {
                tracing::warn!(
                    "model.precision = int8 on tract runs slower than f32 (docs/bench/nets.md): \
                     install ONNX Runtime (tools/onnxruntime.sh) or set precision = \"f32\""
                );
            }
        }
        runtime = Some((opened.runtime.label(), opened.fallback.clone()));
        let loaded =
            volcap_engine::model::Models::load_on(&dir, &cfg.model.name, prec, &opened.runtime)
                .and_then(|m| match &cfg.model.close_range {
                    Some(close) => m.with_close_range(&dir, close),
                    None => Ok(m),
                });
        match loaded {
            Ok(m) => {
                let fill = cfg.model.thin_parts.moment_fill();
                let (m, took) = m.with_moment_fill(fill);
                let (mut m, smoothed) = m.with_map_smooth(cfg.model.map_smooth);
                if let Some(passes) = cfg.model.segment_passes {
                    m.segment_passes = passes;
                }
                if fill.is_some() && took == 0 {
                    tracing::warn!(
                        "model.thin_parts = \"moment-fill\": {} is not a Fourier model; read as predicted",
                        cfg.model.name
                    );
                }
                if cfg.model.map_smooth > 0 && smoothed == 0 {
                    tracing::info!(
                        "model.map_smooth = {}: {} has no maps to smooth",
                        cfg.model.map_smooth,
                        cfg.model.name
                    );
                }
                Some(Arc::new(m))
            }
            Err(e) => {
                eprintln!("volcapd: [model] in {}: {e}", cli.config.display());
                return ExitCode::from(EXIT_CONFIG);
            }
        }
    } else {
        None
    };
    let summary = |source: &str| {
        format!(
            "{}: ok ({}; camera {source}, mode {mode}, model {} {:?}{}, bus {:?})",
            cli.config.display(),
            cfg.description,
            cfg.model.name,
            cfg.model.precision,
            runtime
                .as_ref()
                .map(|(l, _)| format!(" on {l}"))
                .unwrap_or_default(),
            cfg.dbus.bus,
        )
    };
    let (factory, source) = match capture::factory(&cfg) {
        Ok(f) => f,
        Err(e) => {
            // Everything else in the file is checked; a camera backend this build lacks is
            // a note for the check, an error for a run.
            if cli.check_config
                && let Some(feature) = capture::missing_feature(cfg.camera.backend)
            {
                println!(
                    "{}\nnote: this volcapd was built without the `{feature}` feature, so it cannot run this board's camera; build the daemon with `--features {feature}` for it",
                    summary(cfg.camera.backend.name())
                );
                return ExitCode::SUCCESS;
            }
            eprintln!(
                "volcapd: camera {} ({}): {e}",
                cfg.camera.backend.name(),
                cli.config.display()
            );
            return ExitCode::from(EXIT_CONFIG);
        }
    };
    if cli.check_config {
        match rtsp::missing_feature(&cfg) {
            Some(feature) => println!(
                "{}\nnote: this volcapd was built without the `{feature}` feature, so it cannot serve this board's [rtsp]; build the daemon with `--features {feature}` for it",
                summary(&source)
            ),
            None => println!("{}", summary(&source)),
        }
        return ExitCode::SUCCESS;
    }
    if let Some(feature) = rtsp::missing_feature(&cfg) {
        eprintln!(
            "volcapd: [rtsp] in {}: this volcapd was built without the `{feature}` feature; rebuild with `--features {feature}` (needs libgstreamer1.0-dev, libgstrtspserver-1.0-dev) or remove [rtsp]",
            cli.config.display()
        );
        return ExitCode::from(EXIT_CONFIG);
    }
    tracing::info!(config = %cli.config.display(), board = %cfg.description, "starting");
    let (tx, _rx) = tokio::sync::watch::channel(None);
    let mut shared = pipeline::Shared::new(&cfg, source.clone(), tx);
    if let Some(m) = &models {
        shared.set_segment_passes(m.segment_passes);
        shared.set_map_smooth(m.map_smooth());
    }
    if let Some((label, fallback)) = runtime {
        shared.set_runtime(label, fallback);
    }
    shared.compute = compute;
    let shared = Arc::new(shared);
    let rtsp_status = Arc::new(rtsp::Status::new(&cfg));
    let mut app = http::App::new(
        shared.clone(),
        cfg.http.client_limit,
        cfg.http.token.clone(),
        &cfg.http.allowed_hosts,
        cfg.http.bind.ip().is_loopback(),
    );
    app.rtsp = rtsp_status.clone();
    let app = Arc::new(app);
    let ctl = Arc::new(dbus::Control {
        shared: shared.clone(),
        app: app.clone(),
        config: Mutex::new(cfg.clone()),
        backend: Mutex::new(source.clone()),
        make_camera: capture::factory,
        http_override: cli.http,
        bus_override: cli.bus.as_ref().map(|_| cfg.dbus.bus),
        reloading: Default::default(),
    });
    if cli.print_introspection {
        print!("{}", dbus::introspection_xml(ctl));
        return ExitCode::SUCCESS;
    }
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
            let from = match cli.http {
                Some(_) => "--http on the command line".to_string(),
                None => format!("http.bind in {}", cli.config.display()),
            };
            eprintln!("volcapd: cannot bind {} ({from}): {e}", cfg.http.bind);
            return ExitCode::from(EXIT_CONFIG);
        }
    };
    let addr = listener.local_addr().unwrap_or(cfg.http.bind);
    let mut threads = pipeline::start(&cfg, factory, shared.clone(), models);
    match rtsp::start(&cfg, shared.clone(), rtsp_status.clone()) {
        Ok(r) => threads.extend(r.threads),
        Err(e) => {
            shared.stop.store(true, Ordering::Relaxed);
            eprintln!("volcapd: {e}");
            return ExitCode::from(EXIT_CONFIG);
        }
    }

    let notifier = notify::spawn(shared.clone());
    if let Err(e) = &notifier {
        tracing::warn!("no systemd notifier thread: {e}");
    }
    // One line: tests and scripts read the address from the first.
    println!(
        "volcapd: viewer at http://{addr}/ (mode: {mode}, {}^3, camera {source}){}",
        cfg.render.resolution.0,
        rtsp_status
            .url()
            .map(|u| format!("; H.264 over RTSP at {u}"))
            .unwrap_or_default()
    );
    let bus = cfg.dbus.bus;
    let limits = http::Limits::new(&cfg.http);
    let served = rt.block_on(async move {
        tokio::spawn(signals(ctl.clone()));
        tokio::spawn(dbus::serve(ctl, bus));
        http::serve(listener, app, limits, shutdown_signal()).await
    });
    shared.stop.store(true, Ordering::Relaxed);
    // Join the pipeline, but do not wait on a thread stuck in a driver call.
    let deadline = Instant::now() + Duration::from_secs(3);
    for t in threads {
        while !t.is_finished() && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(20));
        }
        if t.is_finished() {
            let _ = t.join();
        }
    }
    rt.shutdown_timeout(Duration::from_millis(500));
    match served {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("volcapd: http server failed: {e}");
            ExitCode::from(EXIT_RUNTIME)
        }
    }
}

/// SIGHUP reloads the config file like D-Bus `Reload` (the daemon convention; the unit's
/// `ExecReload=` sends it); a bad file is logged and the running config kept. SIGUSR1 and
/// SIGUSR2 are logged and otherwise ignored (their default action would end the daemon).
async fn signals(ctl: Arc<dbus::Control>) {
    use tokio::signal::unix::{SignalKind, signal};
    let (Ok(mut hup), Ok(mut usr1), Ok(mut usr2)) = (
        signal(SignalKind::hangup()),
        signal(SignalKind::user_defined1()),
        signal(SignalKind::user_defined2()),
    ) else {
        tracing::warn!("cannot install the SIGHUP/SIGUSR handlers");
        return;
    };
    loop {
        tokio::select! {
            _ = hup.recv() => {
                let ctl = ctl.clone();
                match tokio::task::spawn_blocking(move || ctl.reload()).await {
                    Ok(Ok(what)) => tracing::info!("SIGHUP: reloaded: {what}"),
                    Ok(Err(e)) => tracing::error!("SIGHUP: reload refused, running config kept: {e}"),
                    Err(e) => tracing::error!("SIGHUP: reload task failed: {e}"),
                }
            }
            _ = usr1.recv() => tracing::warn!("SIGUSR1 received: ignored (SIGHUP reloads, SIGTERM stops)"),
            _ = usr2.recv() => tracing::warn!("SIGUSR2 received: ignored (SIGHUP reloads, SIGTERM stops)"),
        }
    }
}

/// SIGTERM (systemd stop) or SIGINT (Ctrl-C).
async fn shutdown_signal() {
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    tokio::select! {
        _ = tokio::signal::ctrl_c() => {}
        _ = term => {}
    }
    tracing::info!("stopping");
}
