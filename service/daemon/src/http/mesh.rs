//! `/mesh.glb`: the current frame as a coloured glTF mesh, bounded and cached.

use super::App;
use axum::body::Bytes;
use axum::extract::State;
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use volcap_engine::field::{FieldError, OccupancyField};

/// The last mesh: its field (a `Weak` keeps the allocation, so a new frame's field can never
/// share its address), what it was made with, and the bytes.
pub type MeshCache = (
    std::sync::Weak<dyn crate::pipeline::MeshField>,
    MeshSettings,
    Bytes,
);

/// The live settings a mesh is made with: resolution, coarse level and `render.drop_apart`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshSettings {
    pub res: usize,
    pub coarse: u32,
    pub apart: Option<f32>,
}

impl MeshSettings {
    pub fn of(live: &crate::config::Live) -> Self {
        Self {
            res: live.resolution,
            coarse: live.coarse_level,
            apart: live.drop_apart(),
        }
    }
}

/// Mesh computations at once. Each holds one grid at the live resolution (4 bytes a point:
/// 68 MB at 257^3, 540 MB at 513^3) and its mesh; the localization is the paper's
/// hierarchical method.
pub const MESH_CONCURRENCY: usize = 1;

/// Niceness of the mesh thread: the pipeline's threads (nice 0) get about ten times its
/// share of a contended core, so a mesh request never starves the render stage or the
/// watchdog's heartbeats; on an idle core it runs at full speed.
pub const MESH_NICE: i32 = 10;

/// The gate of [`MESH_CONCURRENCY`] computations.
pub fn mesh_gate() -> Arc<tokio::sync::Semaphore> {
    Arc::new(tokio::sync::Semaphore::new(MESH_CONCURRENCY))
}

/// A computation handed to the worker.
type Job = Box<dyn FnOnce() + Send>;

/// The mesh worker: one long-lived thread, `volcap-mesh` at [`MESH_NICE`], started by the
/// first request, that runs the computations one after another (the gate lets at most
/// [`MESH_CONCURRENCY`] = 1 be handed over at a time, so its queue of one never fills). One
/// thread for the daemon's life: no thread is created per request, and a computation that
/// ends cannot overlap the next one even while its thread tears down. A computation that
/// panics is caught and counted as failed (its client gets 500); a worker that is gone is
/// started again.
#[derive(Default)]
pub struct MeshWorker {
    tx: Mutex<Option<SyncSender<Job>>>,
    /// Computations that gave a mesh, that stopped because their client left, that failed.
    pub done: AtomicU64,
    pub cancelled: AtomicU64,
    pub failed: AtomicU64,
}

impl MeshWorker {
    fn submit(&self, job: Job) -> Result<(), String> {
        let mut tx = self.tx.lock().unwrap_or_else(|p| p.into_inner());
        let mut job = job;
        for _ in 0..2 {
            if tx.is_none() {
                *tx = Some(Self::start()?);
            }
            let Some(sender) = tx.as_ref() else { break };
            match sender.try_send(job) {
                Ok(()) => return Ok(()),
                Err(TrySendError::Full(_)) => return Err("mesh worker busy".into()),
                Err(TrySendError::Disconnected(j)) => {
                    job = j;
                    *tx = None;
                }
            }
        }
        Err("mesh worker cannot be started".into())
    }

    fn start() -> Result<SyncSender<Job>, String> {
        let (tx, rx) = std::sync::mpsc::sync_channel::<Job>(MESH_CONCURRENCY);
        std::thread::Builder::new()
            .name("volcap-mesh".into())
            .spawn(move || {
                lower_priority();
                // Each job catches its computation's panic (`mesh_glb`).
                while let Ok(job) = rx.recv() {
                    job();
                }
            })
            .map_err(|e| format!("mesh thread: {e}"))?;
        Ok(tx)
    }
}

/// The field, refusing to be evaluated once `cancel` is set: a mesh whose client left
/// stops at its next batch of points (every level of the localization is many batches)
/// instead of running to the end for nobody.
struct Cancellable<'a> {
    field: &'a dyn OccupancyField,
    cancel: &'a AtomicBool,
}

impl OccupancyField for Cancellable<'_> {
    fn occupancy(&self, points: &[glam::Vec3], out: &mut [f32]) -> Result<(), FieldError> {
        if self.cancel.load(Ordering::Relaxed) {
            return Err(FieldError::Backend(CANCELLED.into()));
        }
        self.field.occupancy(points, out)
    }

    fn seeds(&self) -> Vec<glam::Vec3> {
        self.field.seeds()
    }
}

const CANCELLED: &str = "cancelled: the client left";

/// Sets the flag when dropped: the handler's future is dropped when its client leaves.
struct CancelOnDrop(Arc<AtomicBool>);
impl Drop for CancelOnDrop {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Relaxed);
    }
}

/// Lower the calling thread's priority to [`MESH_NICE`] (Linux: a thread's niceness is
/// its own). Best effort: a failure leaves it at the process's priority.
fn lower_priority() {
    // SAFETY: plain system calls on the calling thread's own id.
    unsafe {
        let tid = libc::syscall(libc::SYS_gettid) as libc::id_t;
        libc::setpriority(libc::PRIO_PROCESS, tid, MESH_NICE);
    }
}

/// The mesh of `field` at `set.res` from `set.coarse`, pieces farther than `set.apart` (a
/// fraction of the side, `render.drop_apart`) from the body left out, stopping early when
/// `cancel` is set.
fn compute(
    field: &dyn crate::pipeline::MeshField,
    set: MeshSettings,
    cancel: &AtomicBool,
) -> Result<Bytes, String> {
    let MeshSettings { res, coarse, apart } = set;
    let spec = volcap_engine::grid::GridSpec::from_resolution(res).map_err(|e| e.to_string())?;
    let mut grid = volcap_engine::grid::Grid::new(spec);
    let guarded = Cancellable { field, cancel };
    volcap_engine::localize::Localizer::new()
        .run(
            volcap_engine::localize::Method::Hierarchical,
            &guarded,
            spec,
            coarse,
            &mut grid,
        )
        .map_err(|e| e.to_string())?;
    if cancel.load(Ordering::Relaxed) {
        return Err(CANCELLED.into());
    }
    // Pieces apart from the body (the network's floaters) are left out of the mesh, as
    // they are out of the render.
    if let Some(f) = apart {
        let gap = volcap_engine::pieces::gap_points(spec, f);
        volcap_engine::pieces::drop_apart(&mut grid, [gap; 3]);
    }
    let mut mesh = volcap_engine::mesh::marching_cubes(&grid);
    drop(grid);
    if cancel.load(Ordering::Relaxed) {
        return Err(CANCELLED.into());
    }
    mesh.paint(field).map_err(|e| e.to_string())?;
    Ok(Bytes::from(mesh.to_glb()))
}

/// The current frame as a coloured mesh: hierarchical localization at the render
/// resolution, pieces apart from the body dropped (`volcap_engine::pieces`), marching cubes,
/// glTF binary. Slower than a frame (hundreds of ms): it runs on
/// the mesh worker's thread at a lower priority ([`MeshWorker`], [`MESH_NICE`]),
/// [`MESH_CONCURRENCY`] at a time (others get 503 with Retry-After), and its bytes are cached
/// for the frame, so a repeated request for the same frame costs nothing. The gate's permit
/// moves into the computation and is released only when it ends, so a client that leaves
/// cannot let another one start beside it; leaving cancels the computation at its next batch
/// of points (nobody else can be waiting for it: they were told 503).
pub(super) async fn mesh_glb(State(app): State<Arc<App>>) -> Response {
    let Some(field) = app.shared.latest_field() else {
        return (StatusCode::SERVICE_UNAVAILABLE, "no frame yet\n").into_response();
    };
    let live = app.shared.live();
    let set = MeshSettings::of(&live);
    let glb_response =
        |b: Bytes| ([(header::CONTENT_TYPE, "model/gltf-binary")], b).into_response();
    if let Some(b) = app.cached_mesh(&field, set) {
        return glb_response(b);
    }
    let busy = || {
        (
            StatusCode::SERVICE_UNAVAILABLE,
            [(header::RETRY_AFTER, "1")],
            "a mesh is being computed; retry in a second\n",
        )
            .into_response()
    };
    let Ok(permit) = app.mesh_gate.clone().try_acquire_owned() else {
        return busy();
    };
    // The frame may have been meshed while we waited for the gate.
    if let Some(b) = app.cached_mesh(&field, set) {
        return glb_response(b);
    }
    let cancel = Arc::new(AtomicBool::new(false));
    let (tx, rx) = tokio::sync::oneshot::channel();
    let (app2, flag) = (app.clone(), cancel.clone());
    let submitted = app.mesh_worker.submit(Box::new(move || {
        // Held until the computation ends, whatever became of the request.
        let _permit = permit;
        let key = Arc::downgrade(&field);
        let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            compute(field.as_ref(), set, &flag)
        }))
        .unwrap_or_else(|_| {
            tracing::warn!("a mesh computation panicked; the worker goes on");
            Err("the mesh computation panicked".into())
        });
        drop(field);
        let counter = match &r {
            Ok(_) => &app2.mesh_worker.done,
            Err(_) if flag.load(Ordering::Relaxed) => &app2.mesh_worker.cancelled,
            Err(_) => &app2.mesh_worker.failed,
        };
        counter.fetch_add(1, Ordering::Relaxed);
        if let Ok(bytes) = &r {
            *app2.mesh_cache.lock().unwrap_or_else(|p| p.into_inner()) =
                Some((key, set, bytes.clone()));
        }
        let _ = tx.send(r);
    }));
    if let Err(e) = submitted {
        tracing::warn!("{e}");
        return busy();
    }
    let _cancel_if_gone = CancelOnDrop(cancel);
    match rx.await {
        Ok(Ok(b)) => glb_response(b),
        Ok(Err(e)) => (
            StatusCode::INTERNAL_SERVER_ERROR,
            format!("mesh failed: {e}\n"),
        )
            .into_response(),
        Err(_) => (StatusCode::INTERNAL_SERVER_ERROR, "mesh task failed\n").into_response(),
    }
}

/// HEAD of the mesh: whether one can be had, computing nothing. The length is stated only
/// when the current frame's mesh is cached (a HEAD must not claim a length its GET would
/// not send, and `0` is never the mesh's).
pub(super) async fn mesh_head(State(app): State<Arc<App>>) -> Response {
    let Some(field) = app.shared.latest_field() else {
        return StatusCode::SERVICE_UNAVAILABLE.into_response();
    };
    let live = app.shared.live();
    match app.cached_mesh(&field, MeshSettings::of(&live)) {
        Some(b) => ([(header::CONTENT_TYPE, "model/gltf-binary")], b).into_response(),
        None => Response::builder()
            .header(header::CONTENT_TYPE, "model/gltf-binary")
            .body(axum::body::Body::from_stream(
                futures_util::stream::empty::<Result<Bytes, std::io::Error>>(),
            ))
            .unwrap_or_else(|_| StatusCode::INTERNAL_SERVER_ERROR.into_response()),
    }
}
