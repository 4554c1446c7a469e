//! The per-view half of [`crate::dataset::generate`]: a rendered view of a labelled pose to
//! its shard file, on the calling thread or on worker threads.
//!
//! What a view costs is its own (the rays' inside intervals, the seen surface and its
//! colours: three quarters of a dataset's time); what a pose costs (the oracle, the labelled
//! points) comes from one random stream whose draws depend on the oracle's answers, so poses
//! stay on the calling thread, in order, and the views go to the workers. Every view's
//! randomness is fixed before it is queued, so the files are the same, byte for byte, on any
//! number of threads.

use crate::dataset::DatasetError;
use crate::dataset::seen_surface;
use crate::oracle::SceneField;
use crate::rays::{DEFAULT_STEP_M, ray_intervals};
use crate::sim::SimFrame;
use glam::Vec3;
use safetensors::Dtype;
use safetensors::tensor::TensorView;
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::JoinHandle;
use std::time::Duration;

/// One view of a labelled pose, everything random already drawn.
pub struct ViewJob {
    /// The shard's final path (written as `.part` beside, then renamed).
    pub path: PathBuf,
    pub frame: SimFrame,
    /// The pose's oracle and colours, shared by its views.
    pub field: Arc<SceneField>,
    /// The pose's labelled points (world metres) and labels, shared by its views.
    pub points: Arc<Vec<Vec3>>,
    pub labels: Arc<Vec<f32>>,
    pub surface_points: usize,
    pub surface_seed: u64,
    /// The `volcap` metadata (sorted JSON).
    pub info: String,
}

fn tensor<'a>(
    dtype: Dtype,
    shape: Vec<usize>,
    data: &'a [u8],
) -> Result<TensorView<'a>, DatasetError> {
    TensorView::new(dtype, shape, data).map_err(|e| DatasetError::Config(format!("tensor: {e}")))
}

fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// Label the view and write its shard.
pub fn write_view(job: ViewJob) -> Result<(), DatasetError> {
    let f = &job.frame;
    let view = f.camera.projector();
    let to_ndc = |v: &[Vec3]| -> Vec<f32> {
        v.iter()
            .flat_map(|p| view.world_to_ndc(*p).to_array())
            .collect()
    };
    let pts = f32_bytes(&to_ndc(&job.points));
    let occ = f32_bytes(&job.labels);
    let mask = f.person_mask();
    let (h, w) = (f.height, f.width);
    let rays = ray_intervals(&job.field.oracle, &f.camera, DEFAULT_STEP_M);
    let surface = seen_surface(&rays, &view, job.surface_points, job.surface_seed);
    let surface_rgb: Vec<f32> = surface
        .iter()
        .flat_map(|p| job.field.colors.color(*p))
        .collect();
    let sp = f32_bytes(&to_ndc(&surface));
    let sc = f32_bytes(&surface_rgb);
    let roff: Vec<u8> = rays.offsets.iter().flat_map(|x| x.to_le_bytes()).collect();
    let rz = f32_bytes(rays.z.as_flattened());
    let meta: HashMap<String, String> = [("volcap".to_string(), job.info)].into_iter().collect();
    let tensors = vec![
        ("image", tensor(Dtype::U8, vec![h, w, 3], &f.rgb)?),
        ("mask", tensor(Dtype::U8, vec![h, w], &mask)?),
        ("occ", tensor(Dtype::F32, vec![job.labels.len()], &occ)?),
        (
            "points",
            tensor(Dtype::F32, vec![job.points.len(), 3], &pts)?,
        ),
        ("surface", tensor(Dtype::F32, vec![surface.len(), 3], &sp)?),
        ("ray_offsets", tensor(Dtype::U32, vec![w * h + 1], &roff)?),
        ("ray_z", tensor(Dtype::F32, vec![rays.z.len(), 2], &rz)?),
        (
            "surface_rgb",
            tensor(Dtype::F32, vec![surface.len(), 3], &sc)?,
        ),
    ];
    let werr = DatasetError::write;
    // Written beside, then renamed: a generator stopped mid-write (the training recipe's
    // clock, a kill) leaves a `.part` file, never a torn shard.
    let part = job.path.with_extension("safetensors.part");
    safetensors::serialize_to_file(tensors, Some(meta), &part).map_err(|e| werr(&part, &e))?;
    std::fs::rename(&part, &job.path).map_err(|e| werr(&job.path, &e))?;
    Ok(())
}

struct Pool {
    tx: Option<SyncSender<ViewJob>>,
    workers: Vec<JoinHandle<()>>,
    done: Arc<AtomicU64>,
    /// The first failed view's error; the workers skip what is queued after it.
    error: Arc<Mutex<Option<DatasetError>>>,
}

/// Writes views' shards: on the calling thread (`threads` <= 1) or on `threads` workers fed
/// through a queue of at most `threads` views (the caller blocks while it is full).
pub struct ShardWriter {
    pool: Option<Pool>,
    done: u64,
}

fn take_error(e: &Mutex<Option<DatasetError>>) -> Option<DatasetError> {
    e.lock().unwrap_or_else(PoisonError::into_inner).take()
}

impl ShardWriter {
    pub fn new(threads: usize) -> Self {
        if threads <= 1 {
            return Self {
                pool: None,
                done: 0,
            };
        }
        let (tx, rx) = sync_channel::<ViewJob>(threads);
        let rx: Arc<Mutex<Receiver<ViewJob>>> = Arc::new(Mutex::new(rx));
        let done = Arc::new(AtomicU64::new(0));
        let error: Arc<Mutex<Option<DatasetError>>> = Arc::new(Mutex::new(None));
        let workers = (0..threads)
            .map(|_| {
                let (rx, done, error) = (rx.clone(), done.clone(), error.clone());
                std::thread::spawn(move || {
                    loop {
                        let job = rx.lock().unwrap_or_else(PoisonError::into_inner).recv();
                        let Ok(job) = job else { break };
                        if error
                            .lock()
                            .unwrap_or_else(PoisonError::into_inner)
                            .is_some()
                        {
                            continue;
                        }
                        match write_view(job) {
                            Ok(()) => {
                                done.fetch_add(1, Ordering::Relaxed);
                            }
                            Err(e) => {
                                error
                                    .lock()
                                    .unwrap_or_else(PoisonError::into_inner)
                                    .get_or_insert(e);
                            }
                        }
                    }
                })
            })
            .collect();
        Self {
            pool: Some(Pool {
                tx: Some(tx),
                workers,
                done,
                error,
            }),
            done: 0,
        }
    }

    /// Write (or queue) one view. Fails with the first error of any view before it.
    pub fn write(
        &mut self,
        job: ViewJob,
        progress: &mut impl FnMut(u64),
    ) -> Result<(), DatasetError> {
        let Some(pool) = &mut self.pool else {
            write_view(job)?;
            self.done += 1;
            progress(self.done);
            return Ok(());
        };
        if let Some(e) = take_error(&pool.error) {
            return Err(e);
        }
        let sent = pool.tx.as_ref().map(|tx| tx.send(job).is_ok());
        if sent != Some(true) {
            return Err(DatasetError::Config(
                "the shard writers stopped (a worker thread panicked)".into(),
            ));
        }
        progress(pool.done.load(Ordering::Relaxed));
        Ok(())
    }

    /// Wait for every queued view; the number written, or the first error.
    pub fn finish(mut self, progress: &mut impl FnMut(u64)) -> Result<u64, DatasetError> {
        let Some(mut pool) = self.pool.take() else {
            return Ok(self.done);
        };
        drop(pool.tx.take());
        while !pool.workers.iter().all(|w| w.is_finished()) {
            progress(pool.done.load(Ordering::Relaxed));
            std::thread::sleep(Duration::from_millis(50));
        }
        let panicked = pool.workers.drain(..).any(|w| w.join().is_err());
        if let Some(e) = take_error(&pool.error) {
            return Err(e);
        }
        if panicked {
            return Err(DatasetError::Config(
                "a shard writer thread panicked".into(),
            ));
        }
        let done = pool.done.load(Ordering::Relaxed);
        progress(done);
        Ok(done)
    }
}

impl Drop for ShardWriter {
    /// Stopped before [`ShardWriter::finish`] (an error of the caller's): the workers skip
    /// what is queued and are joined.
    fn drop(&mut self) {
        if let Some(mut pool) = self.pool.take() {
            pool.error
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .get_or_insert(DatasetError::Config("stopped".into()));
            drop(pool.tx.take());
            for w in pool.workers.drain(..) {
                let _ = w.join();
            }
        }
    }
}

/// Worker threads for `requested` (0: every core the process may use).
pub fn threads(requested: usize) -> usize {
    if requested > 0 {
        return requested;
    }
    std::thread::available_parallelism().map_or(1, |n| n.get())
}
