//! `volcap bench queues` (GPU backend): do the stages' waits queue behind each other's work
//! on one device, and does a device of their own avoid it?
//!
//! The daemon's stages share one wgpu device, so one queue: the render stage's localization
//! waits for its counts some ten times a frame, and each wait drains the queue up to its own
//! submission, including the shape network the field stage submitted before it. Whether a
//! stage on a device of its own (a second device on the same adapter: wgpu opens as many as
//! asked) escapes that depends on whether the driver runs two devices' queues side by side
//! or time-slices them, which only a GPU can say (docs/bench/pipeline-gpu.md, item 4). This
//! bench measures it in a few seconds: the hierarchical localization of an analytic scene
//! (a host-tabulated field, so only the localizer's own kernels and waits run) timed run after
//! run, alone, then while another thread runs the shape network back to back on the same
//! device, then on a second device while the network keeps the first one busy.

use clap::Args;
use std::path::PathBuf;

#[derive(Args, Debug, Clone)]
pub struct QueuesArgs {
    /// The shape network run in the background (models/shape-NAME.*, f32).
    #[arg(long, default_value = volcap_engine::model::DEFAULT_MODEL)]
    pub model: String,
    /// Grid resolution of the localization timed (2^L + 1).
    #[arg(long, default_value_t = 129)]
    pub res: usize,
    /// Analytic scene localized (a table the host evaluates once).
    #[arg(long, default_value = "capsule-human")]
    pub scene: String,
    /// Seconds measured per row.
    #[arg(long, default_value_t = 4.0)]
    pub seconds: f64,
    /// The adapter: auto or a substring of its name or driver.
    #[arg(long, default_value = "auto")]
    pub adapter: String,
    /// Folder of the ONNX models.
    #[arg(long, default_value = "models")]
    pub models_dir: PathBuf,
    /// Folder for queues.md (default docs/bench).
    #[arg(long, default_value = "docs/bench")]
    pub out: PathBuf,
}

#[cfg(not(feature = "wgpu"))]
pub fn run(_a: &QueuesArgs) -> anyhow::Result<()> {
    Err(anyhow::anyhow!(
        "bench queues: this volcap is built without the GPU backend (cargo feature `wgpu`: cargo run --release -p volcap --features wgpu -- ...)"
    ))
}

#[cfg(feature = "wgpu")]
pub use imp::run;

#[cfg(feature = "wgpu")]
mod imp {
    use super::QueuesArgs;
    use anyhow::anyhow;
    use indicatif::{ProgressBar, ProgressStyle};
    use std::fmt::Write as _;
    use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
    use std::time::{Duration, Instant};
    use volcap_engine::field::OccupancyField;
    use volcap_engine::gpu::Gpu;
    use volcap_engine::gpu::localize::{GpuField, GpuLocalizer};
    use volcap_engine::grid::GridSpec;
    use volcap_engine::localize::HierarchicalMode;
    use volcap_engine::model::{Models, Precision, Runtime, ShapeModel, preprocess::INPUT_SIZE};

    /// One row: where the localization ran and what ran beside it.
    struct Row {
        what: &'static str,
        /// Localization runs, and their milliseconds' 50th and 90th percentiles.
        runs: usize,
        p50: f64,
        p90: f64,
        /// Read-backs waited for per localization run.
        waits: f64,
        /// The background network's runs per second (None: no background).
        net_rate: Option<f64>,
    }

    fn percentile(sorted: &[f64], p: f64) -> f64 {
        if sorted.is_empty() {
            return f64::NAN;
        }
        let i = ((sorted.len() - 1) as f64 * p).round() as usize;
        sorted[i.min(sorted.len() - 1)]
    }

    pub fn run(a: &QueuesArgs) -> anyhow::Result<()> {
        if !(a.seconds.is_finite() && a.seconds > 0.0) {
            return Err(anyhow!("--seconds {}: must be positive", a.seconds));
        }
        let spec = GridSpec::from_resolution(a.res).map_err(|e| anyhow!("--res {}: {e}", a.res))?;
        let scene = volcap_engine::analytic::AnalyticScene::by_name(&a.scene).ok_or_else(|| {
            anyhow!(
                "--scene {:?}: one of {}",
                a.scene,
                volcap_engine::analytic::SCENES.join(", ")
            )
        })?;
        // Two devices on the one adapter: the networks' and a second one, opened as the
        // daemon opens it for `compute.render_device = "own"` (the counters shared).
        let first = Gpu::open(&a.adapter).map_err(|e| anyhow!("--adapter: {e}"))?;
        let second = first
            .sibling()
            .map_err(|e| anyhow!("a second device: {e}"))?;
        let label = first.adapter.label();
        eprintln!("bench queues: {label}, two devices");
        let models = Models::load_on(
            &a.models_dir,
            &a.model,
            Precision::F32,
            &Runtime::Wgpu(first.clone()),
        )
        .map_err(|e| anyhow!("model {} in {}: {e}", a.model, a.models_dir.display()))?;
        let net = match &models.shape {
            ShapeModel::Fourier(f) => &f.net,
            ShapeModel::Mlp(n) => &n.encoder,
        };
        let s = INPUT_SIZE;
        let x: Vec<f32> = (0..4 * s * s)
            .map(|i| ((i * 37 % 101) as f32 / 50.0) - 1.0)
            .collect();
        let shape = [1, 4, s, s];
        let args: [(&[usize], &[f32]); 1] = [(&shape, &x)];
        net.run(&args).map_err(|e| anyhow!("{}: {e}", a.model))?;

        let pts: Vec<glam::Vec3> = (0..spec.len())
            .map(|q| spec.world(spec.unlinear(q)))
            .collect();
        let mut table = vec![0.0f32; spec.len()];
        scene
            .occupancy(&pts, &mut table)
            .map_err(|e| anyhow!("{}: {e}", a.scene))?;
        let field = GpuField::Table(&table);
        let window = Duration::from_secs_f64(a.seconds);
        let pb = ProgressBar::new(4).with_style(
            ProgressStyle::with_template("rows {bar:30} {pos}/{len} {msg}")
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );

        // The network alone: its rate with nothing beside it.
        pb.set_message("the shape network alone");
        let t = Instant::now();
        let mut alone_runs = 0u64;
        while t.elapsed() < window {
            net.run(&args).map_err(|e| anyhow!("{}: {e}", a.model))?;
            alone_runs += 1;
        }
        let net_alone = alone_runs as f64 / t.elapsed().as_secs_f64();
        pb.inc(1);

        let mut rows = Vec::new();
        for (what, gpu, busy) in [
            ("first device, alone", &first, false),
            ("first device, the network beside it", &first, true),
            ("a second device, the network on the first", &second, true),
        ] {
            pb.set_message(what);
            let mut loc = GpuLocalizer::new(gpu.clone()).map_err(|e| anyhow!("{e}"))?;
            // Buffers made and kernels compiled before timing, and the run's read-backs
            // counted (the same every run: the field is a table; the device's counter counts
            // the background network's too once it runs).
            let waits0 = gpu.counters().waits;
            loc.run(&field, spec, 3, HierarchicalMode::Paper)
                .map_err(|e| anyhow!("{e}"))?;
            let waits = (gpu.counters().waits - waits0) as f64;
            let stop = AtomicBool::new(false);
            let net_runs = AtomicU64::new(0);
            let row = std::thread::scope(|sc| -> anyhow::Result<Row> {
                let bg = busy.then(|| {
                    sc.spawn(|| -> anyhow::Result<()> {
                        while !stop.load(Ordering::Relaxed) {
                            net.run(&args).map_err(|e| anyhow!("{e}"))?;
                            net_runs.fetch_add(1, Ordering::Relaxed);
                        }
                        Ok(())
                    })
                });
                // The background under way before the window opens.
                if busy {
                    let t = Instant::now();
                    while net_runs.load(Ordering::Relaxed) < 2 && t.elapsed() < window {
                        std::thread::sleep(Duration::from_millis(1));
                    }
                }
                let (t, n0) = (Instant::now(), net_runs.load(Ordering::Relaxed));
                let mut ms = Vec::new();
                let mut result = Ok(());
                while t.elapsed() < window {
                    let r = Instant::now();
                    if let Err(e) = loc.run(&field, spec, 3, HierarchicalMode::Paper) {
                        result = Err(anyhow!("{e}"));
                        break;
                    }
                    ms.push(r.elapsed().as_secs_f64() * 1e3);
                }
                let secs = t.elapsed().as_secs_f64();
                let n1 = net_runs.load(Ordering::Relaxed);
                stop.store(true, Ordering::Relaxed);
                if let Some(h) = bg {
                    h.join()
                        .map_err(|_| anyhow!("the background network's thread panicked"))??;
                }
                result?;
                ms.sort_by(f64::total_cmp);
                Ok(Row {
                    what,
                    runs: ms.len(),
                    p50: percentile(&ms, 0.5),
                    p90: percentile(&ms, 0.9),
                    waits,
                    net_rate: busy.then(|| (n1 - n0) as f64 / secs),
                })
            })?;
            rows.push(row);
            pb.inc(1);
        }
        pb.finish_and_clear();

        let mut md = String::new();
        let _ = writeln!(
            md,
            "# Two stages on one device or on two\n\n`volcap bench queues --model {} --res {} \
         --scene {} --seconds {}` on {label}.\n\nThe hierarchical localization of `{}` at \
         {}^3 (a table the host evaluated: only the localizer's kernels and read-backs run) \
         timed run after run: alone; while another thread runs the {} shape network back to \
         back on the same device; on a second device of the same adapter while the network \
         keeps the first busy. The network alone: {net_alone:.1} runs/s.\n",
            a.model, a.res, a.scene, a.seconds, a.scene, a.res, a.model
        );
        let _ = writeln!(
            md,
            "| localization on | runs | ms p50 | ms p90 | read-backs a run | the network's runs/s beside it |"
        );
        let _ = writeln!(md, "|---|---:|---:|---:|---:|---:|");
        for r in &rows {
            let rate = r.net_rate.map_or("-".to_string(), |x| {
                format!("{x:.1} (alone {net_alone:.1})")
            });
            let _ = writeln!(
                md,
                "| {} | {} | {:.2} | {:.2} | {:.1} | {rate} |",
                r.what, r.runs, r.p50, r.p90, r.waits
            );
        }
        let (same, second) = (rows[1].p50 / rows[0].p50, rows[2].p50 / rows[0].p50);
        let _ = writeln!(
            md,
            "\nThe network beside it on the same device makes a localization {same:.2}x as \
             long as alone; on a second device {second:.2}x: {}{}",
            verdict(same, second),
            if label.contains("llvmpipe") {
                " (On lavapipe both devices share the same CPU cores: its figures say nothing \
                 about a GPU.)"
            } else {
                ""
            }
        );
        print!("{md}");
        std::fs::create_dir_all(&a.out)?;
        let path = a.out.join("queues.md");
        std::fs::write(&path, &md).map_err(|e| anyhow!("{}: {e}", path.display()))?;
        eprintln!("wrote {}", path.display());
        Ok(())
    }

    /// What the two slow-downs (same device, second device; 1 = as alone) say.
    pub(super) fn verdict(same: f64, second: f64) -> &'static str {
        if !(same.is_finite() && second.is_finite()) {
            "no reading."
        } else if same < 1.25 {
            "the network beside it costs the localization little; its waits do not queue \
             behind it much, and a second device has little to buy."
        } else if second < 1.0 + (same - 1.0) / 3.0 {
            "the waits queue behind the network on one device, and a second device escapes \
             most of it: a stage on a device of its own pays (`compute.render_device = \"own\"`, \
             if the maps crossing the host cost less)."
        } else {
            "the localization is slowed on either device: the adapter time-slices the two \
             devices (or is busy), and a second device buys little."
        }
    }
}

#[cfg(all(test, feature = "wgpu"))]
mod tests {
    use super::imp::verdict;

    #[test]
    fn the_reading_follows_the_two_slow_downs() {
        assert!(verdict(1.1, 1.05).contains("costs the localization little"));
        // Lavapipe's: 850x on one device, 1.6x on a second.
        assert!(verdict(850.0, 1.6).contains("a second device escapes"));
        assert!(verdict(3.0, 2.7).contains("time-slices"));
        assert!(verdict(3.0, 1.5).contains("a second device escapes"));
        assert!(verdict(f64::NAN, 1.0).contains("no reading"));
    }
}
