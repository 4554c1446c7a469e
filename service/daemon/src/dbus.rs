//! D-Bus health and control: `org.volcap.Capture1` at `/org/volcap/Capture1`, on the system
//! bus in production and the session bus for development and tests. The object is
//! registered before the name is requested (zbus's builder does it in that order). Without
//! a bus the daemon keeps running: it logs once and health stays on HTTP.

use crate::capture::CameraFactory;
use crate::config::{Bus, Config};
use crate::http::App;
use crate::pipeline::Shared;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use zbus::fdo;

pub const NAME: &str = "org.volcap.Capture1";
pub const PATH: &str = "/org/volcap/Capture1";

/// Builds a camera from a config (the daemon's `capture::factory`).
pub type MakeCamera = fn(&Config) -> Result<(CameraFactory, String), String>;

/// What D-Bus (and reload) acts on.
pub struct Control {
    pub shared: Arc<Shared>,
    pub app: Arc<App>,
    pub config: Mutex<Config>,
    pub backend: Mutex<String>,
    pub make_camera: MakeCamera,
    /// Command-line overrides, applied to every reloaded file too.
    pub http_override: Option<std::net::SocketAddr>,
    pub bus_override: Option<Bus>,
    /// A reload is running (SIGHUP and D-Bus `Reload` do not start a second one beside it).
    pub reloading: std::sync::atomic::AtomicBool,
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

impl Control {
    /// Re-read the config file. A bad file keeps everything as it is and returns the error
    /// (file, line, key). What can change live changes; the rest is named as needing a
    /// restart.
    pub fn reload(&self) -> Result<String, String> {
        if self.reloading.swap(true, Ordering::SeqCst) {
            return Err("a reload is already in progress; try again when it ends".into());
        }
        struct Done<'a>(&'a std::sync::atomic::AtomicBool);
        impl Drop for Done<'_> {
            fn drop(&mut self) {
                self.0.store(false, Ordering::SeqCst);
            }
        }
        let _done = Done(&self.reloading);
        let file = lock(&self.config).file.clone();
        let mut new = Config::load(&file)?;
        if let Some(a) = self.http_override {
            new.http.bind = a;
        }
        if let Some(b) = self.bus_override {
            new.dbus.bus = b;
        }
        let old = lock(&self.config).clone();
        let mut applied = Vec::new();
        let mut restart = Vec::new();
        if new.camera != old.camera {
            let (factory, source) = (self.make_camera)(&new)?;
            *lock(&self.shared.camera_swap) = Some(factory);
            *lock(&self.backend) = source.clone();
            applied.push(format!("camera ({source})"));
        }
        let render_new = crate::config::Live::from_config(&new);
        let render_old = crate::config::Live::from_config(&old);
        if render_new != render_old {
            let paused = self.shared.live().paused;
            self.shared.update_live(|l| {
                *l = render_new;
                l.paused = paused;
            })?;
            applied.push("render".to_string());
        }
        if new.http.client_limit != old.http.client_limit {
            self.app
                .client_limit
                .store(new.http.client_limit, Ordering::SeqCst);
            applied.push("http.client_limit".into());
        }
        if new.http.token != old.http.token {
            *lock(&self.app.token) = new.http.token.clone();
            applied.push("http.token".into());
        }
        if new.http.bind != old.http.bind {
            restart.push("http.bind");
        }
        if new.field() != old.field() {
            restart.push("render.field");
        }
        if new.render.oracle_voxel_m != old.render.oracle_voxel_m {
            restart.push("render.oracle_voxel_m");
        }
        if new.dbus != old.dbus {
            restart.push("dbus");
        }
        // The networks are loaded (and checked) at start.
        if new.model != old.model {
            restart.push("model");
        }
        // Server limits are set when the listener starts.
        if new.http.header_timeout_s != old.http.header_timeout_s {
            restart.push("http.header_timeout_s");
        }
        if new.http.write_timeout_s != old.http.write_timeout_s {
            restart.push("http.write_timeout_s");
        }
        if new.http.per_address_limit != old.http.per_address_limit {
            restart.push("http.per_address_limit");
        }
        if new.http.allowed_hosts != old.http.allowed_hosts {
            restart.push("http.allowed_hosts");
        }
        if new.http.reserved_for != old.http.reserved_for {
            restart.push("http.reserved_for");
        }
        if new.compute.threads != old.compute.threads {
            restart.push("compute.threads");
        }
        if (
            new.compute.backend,
            &new.compute.adapter,
            new.compute.fallback,
        ) != (
            old.compute.backend,
            &old.compute.adapter,
            old.compute.fallback,
        ) {
            restart.push("compute.backend");
        }
        if new.rtsp != old.rtsp {
            restart.push("rtsp");
        }
        if new.rtsp.bind.is_some() && new.http.token != old.http.token {
            // The RTSP server's credentials are set when it starts.
            restart.push("http.token (for RTSP)");
        }
        // Keep what is running, take the rest of the new file.
        let mut keep = new;
        keep.http.bind = old.http.bind;
        keep.http.header_timeout_s = old.http.header_timeout_s;
        keep.http.write_timeout_s = old.http.write_timeout_s;
        keep.http.per_address_limit = old.http.per_address_limit;
        keep.http.allowed_hosts = old.http.allowed_hosts.clone();
        keep.http.reserved_for = old.http.reserved_for.clone();
        keep.compute.threads = old.compute.threads;
        keep.compute.backend = old.compute.backend;
        keep.compute.adapter = old.compute.adapter.clone();
        keep.compute.fallback = old.compute.fallback;
        keep.render.field = old.render.field;
        keep.render.oracle_voxel_m = old.render.oracle_voxel_m;
        keep.dbus = old.dbus;
        keep.model = old.model.clone();
        *lock(&self.config) = keep;
        let mut msg = if applied.is_empty() {
            "no change".to_string()
        } else {
            format!("applied: {}", applied.join(", "))
        };
        if !restart.is_empty() {
            msg.push_str(&format!(
                "; needs a restart to take effect: {}",
                restart.join(", ")
            ));
        }
        tracing::info!("config reloaded from {}: {msg}", file.display());
        Ok(msg)
    }

    /// The current frame as PNG (RGBA, transparent background where the config says so).
    pub fn snapshot_png(&self) -> Result<Vec<u8>, String> {
        let f = self
            .shared
            .published
            .borrow()
            .clone()
            .ok_or("no frame published yet")?;
        f.to_png()
    }
}

/// The D-Bus object.
pub struct Capture1 {
    pub ctl: Arc<Control>,
}

fn bad_arg(msg: impl Into<String>) -> fdo::Error {
    fdo::Error::InvalidArgs(msg.into())
}

/// Every property value, read at once (for change detection).
#[derive(Debug, Clone, PartialEq)]
pub struct Snapshot {
    pub state: String,
    pub reason: String,
    pub camera_connected: bool,
    pub backend: String,
    pub model: String,
    pub resolution: u32,
    pub fps: f64,
    pub p50: f64,
    pub p99: f64,
    pub processed: u64,
    pub superseded: u64,
    pub dropped: u64,
    pub clients: u32,
}

impl Control {
    pub fn snapshot(&self) -> Snapshot {
        let sh = &self.shared;
        let (state, reason) = lock(&sh.state).name_reason();
        let (p50, p99) = sh.e2e.percentiles();
        Snapshot {
            state: state.to_string(),
            reason,
            camera_connected: lock(&sh.camera).state == "running",
            backend: lock(&self.backend).clone(),
            model: sh.field_label.clone(),
            resolution: sh.live().resolution as u32,
            fps: (sh.e2e.recent_fps() * 10.0).round() / 10.0,
            p50: p50.round(),
            p99: p99.round(),
            processed: sh.e2e.frames.load(Ordering::Relaxed),
            superseded: sh
                .stats
                .iter()
                .map(|s| s.superseded.load(Ordering::Relaxed))
                .sum(),
            dropped: sh
                .stats
                .iter()
                .map(|s| s.lost.load(Ordering::Relaxed))
                .sum(),
            clients: self.app.clients.load(Ordering::SeqCst) as u32,
        }
    }
}

#[zbus::interface(name = "org.volcap.Capture1")]
impl Capture1 {
    /// starting, running, degraded, paused or failed.
    #[zbus(property)]
    fn state(&self) -> String {
        self.ctl.snapshot().state
    }

    /// Why the state is not running (empty when running).
    #[zbus(property)]
    fn reason(&self) -> String {
        self.ctl.snapshot().reason
    }

    #[zbus(property)]
    fn camera_connected(&self) -> bool {
        self.ctl.snapshot().camera_connected
    }

    /// Capture backend and device, e.g. `v4l2:/dev/video0 MJPG 1280x720@30`.
    #[zbus(property)]
    fn backend(&self) -> String {
        self.ctl.snapshot().backend
    }

    /// What produces the field: `reconstruction: NAME (PRECISION, RUNTIME)` (the trained
    /// networks and what runs them; `thin parts: moment-fill` before the runtime when
    /// `[model] thin_parts` says so), or `oracle` / `camera` (labelled debugging modes, not
    /// reconstructions).
    #[zbus(property)]
    fn model(&self) -> String {
        self.ctl.snapshot().model
    }

    /// `[compute] backend`: `cpu`, `cpu (wgpu fell back: WHY)` or `wgpu: ADAPTER; on the
    /// adapter: STAGES; on the CPU: STAGES`.
    #[zbus(property)]
    fn compute(&self) -> String {
        self.ctl.shared.compute.summary()
    }

    /// H.264 over RTSP (`[rtsp]`): `off`, or where it is served and how many clients are
    /// admitted, the push's target and state, and the encoder.
    #[zbus(property)]
    fn rtsp(&self) -> String {
        self.ctl.app.rtsp.summary()
    }

    /// Grid points per axis (2^level + 1).
    #[zbus(property)]
    fn resolution(&self) -> u32 {
        self.ctl.snapshot().resolution
    }

    /// Published frames per second over the last few seconds.
    #[zbus(property)]
    fn fps(&self) -> f64 {
        self.ctl.snapshot().fps
    }

    /// Capture-to-publish latency, median, ms.
    #[zbus(property)]
    fn latency_p50_ms(&self) -> f64 {
        self.ctl.snapshot().p50
    }

    #[zbus(property)]
    fn latency_p99_ms(&self) -> f64 {
        self.ctl.snapshot().p99
    }

    #[zbus(property)]
    fn frames_processed(&self) -> u64 {
        self.ctl.snapshot().processed
    }

    /// Frames a stage failed on (an error), all stages: frames lost.
    #[zbus(property)]
    fn frames_dropped(&self) -> u64 {
        self.ctl.snapshot().dropped
    }

    /// Frames replaced in a latest-wins slot by a newer one before the next stage needed
    /// them, all stages: work nobody needed, not frames lost.
    #[zbus(property)]
    fn frames_superseded(&self) -> u64 {
        self.ctl.snapshot().superseded
    }

    /// Connected stream clients.
    #[zbus(property)]
    fn clients(&self) -> u32 {
        self.ctl.snapshot().clients
    }

    /// Seconds since start (not signalled: it changes all the time).
    #[zbus(property(emits_changed_signal = "false"))]
    fn uptime(&self) -> f64 {
        (self.ctl.shared.started.elapsed().as_secs_f64() * 10.0).round() / 10.0
    }

    /// Orbit the render view: yaw in degrees (any finite value), pitch in [-80, 80],
    /// distance in metres (0 keeps the camera's own, else 0.5..=10).
    fn set_view(&self, yaw: f64, pitch: f64, distance: f64) -> fdo::Result<()> {
        if !(yaw.is_finite() && pitch.is_finite() && distance.is_finite()) {
            return Err(bad_arg(format!(
                "yaw {yaw}, pitch {pitch}, distance {distance}: need finite numbers"
            )));
        }
        self.ctl
            .shared
            .update_live(|l| {
                l.set_yaw(yaw as f32);
                l.pitch = pitch as f32;
                l.distance = distance as f32;
            })
            .map(|_| ())
            .map_err(bad_arg)
    }

    /// Grid level 5..=9: resolution 2^level + 1 (33 .. 513) points per axis.
    fn set_resolution(&self, level: u32) -> fdo::Result<()> {
        if !(5..=9).contains(&level) {
            return Err(bad_arg(format!(
                "level {level}: need 5..=9 (resolution 33 .. 513)"
            )));
        }
        self.ctl
            .shared
            .update_live(|l| {
                l.set_resolution((1usize << level) + 1);
            })
            .map(|_| ())
            .map_err(bad_arg)
    }

    /// Stop rendering (the camera keeps running so its state stays live).
    fn pause(&self) -> fdo::Result<()> {
        self.ctl
            .shared
            .update_live(|l| l.paused = true)
            .map(|_| ())
            .map_err(fdo::Error::Failed)
    }

    fn resume(&self) -> fdo::Result<()> {
        self.ctl
            .shared
            .update_live(|l| l.paused = false)
            .map(|_| ())
            .map_err(fdo::Error::Failed)
    }

    /// Re-read the config file. A bad file keeps the running configuration and fails with
    /// the file, line and key; returns what was applied and what needs a restart.
    async fn reload(&self) -> fdo::Result<String> {
        // File I/O and maybe a new camera (a scene load): off the async runtime.
        let ctl = self.ctl.clone();
        tokio::task::spawn_blocking(move || ctl.reload())
            .await
            .map_err(|e| fdo::Error::Failed(format!("reload task: {e}")))?
            .map_err(fdo::Error::Failed)
    }

    /// The current frame as PNG bytes.
    async fn snapshot(&self) -> fdo::Result<Vec<u8>> {
        // PNG encoding is CPU work: off the async runtime.
        let ctl = self.ctl.clone();
        tokio::task::spawn_blocking(move || ctl.snapshot_png())
            .await
            .map_err(|e| fdo::Error::Failed(format!("snapshot task: {e}")))?
            .map_err(fdo::Error::Failed)
    }
}

/// The interface's introspection XML, generated from the code (snapshot-tested).
pub fn introspection_xml(ctl: Arc<Control>) -> String {
    use zbus::object_server::Interface;
    let mut s = String::from(
        "<!DOCTYPE node PUBLIC \"-//freedesktop//DTD D-BUS Object Introspection 1.0//EN\"\n \"http://www.freedesktop.org/standards/dbus/1.0/introspect.dtd\">\n<!-- Generated from service/daemon/src/dbus.rs by `volcapd --print-introspection`;\n     a test keeps this file equal to the code. -->\n<node name=\"/org/volcap/Capture1\">\n",
    );
    Capture1 { ctl }.introspect_to_writer(&mut s, 2);
    s.push_str("</node>\n");
    s
}

/// Connect, serve the object, request the name, then signal property changes once a
/// second. Returns when the connection is lost (or never made: logged once).
pub async fn serve(ctl: Arc<Control>, bus: Bus) {
    let builder = match bus {
        Bus::None => return,
        Bus::System => zbus::connection::Builder::system(),
        Bus::Session => zbus::connection::Builder::session(),
    };
    let conn = builder
        .serve_at(PATH, Capture1 { ctl: ctl.clone() })
        .name(NAME)
        .build()
        .await;
    let conn = match conn {
        Ok(c) => c,
        Err(e) => {
            tracing::warn!(
                "D-Bus ({bus:?} bus) unavailable, going on without it (health stays on HTTP): {e}"
            );
            return;
        }
    };
    tracing::info!("D-Bus: {NAME} at {PATH} on the {bus:?} bus");
    let iface = match conn.object_server().interface::<_, Capture1>(PATH).await {
        Ok(i) => i,
        Err(e) => {
            tracing::warn!("D-Bus object lookup failed: {e}");
            return;
        }
    };
    let mut last = ctl.snapshot();
    let mut tick = tokio::time::interval(std::time::Duration::from_secs(1));
    loop {
        tick.tick().await;
        let now = ctl.snapshot();
        let e = iface.signal_emitter();
        let i = iface.get().await;
        let r = async {
            if now.state != last.state {
                i.state_changed(e).await?;
            }
            if now.reason != last.reason {
                i.reason_changed(e).await?;
            }
            if now.camera_connected != last.camera_connected {
                i.camera_connected_changed(e).await?;
            }
            if now.backend != last.backend {
                i.backend_changed(e).await?;
            }
            if now.model != last.model {
                i.model_changed(e).await?;
            }
            if now.resolution != last.resolution {
                i.resolution_changed(e).await?;
            }
            if now.fps != last.fps {
                i.fps_changed(e).await?;
            }
            if now.p50 != last.p50 {
                i.latency_p50_ms_changed(e).await?;
            }
            if now.p99 != last.p99 {
                i.latency_p99_ms_changed(e).await?;
            }
            if now.processed != last.processed {
                i.frames_processed_changed(e).await?;
            }
            if now.dropped != last.dropped {
                i.frames_dropped_changed(e).await?;
            }
            if now.superseded != last.superseded {
                i.frames_superseded_changed(e).await?;
            }
            if now.clients != last.clients {
                i.clients_changed(e).await?;
            }
            zbus::Result::Ok(())
        }
        .await;
        drop(i);
        if let Err(e) = r {
            tracing::warn!("D-Bus signal failed: {e}");
        }
        last = now;
    }
}
