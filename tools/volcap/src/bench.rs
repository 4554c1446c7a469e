//! `volcap bench localize`: every localization method side by side on the same field and
//! grid, accuracy against dense next to evaluations and time.

use crate::LocalizeArgs;
use anyhow::{Context, bail};
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::PathBuf;
use std::time::Instant;
use volcap_engine::OccupancyField;
use volcap_engine::analytic::{AnalyticScene, SCENES};
use volcap_engine::grid::{Grid, GridSpec};
use volcap_engine::localize::{LocalizeStats, Localizer, Method, default_coarse};
use volcap_engine::metrics::{band_bound, components, iou_bits, lost_components};

/// One row of the benchmark: one (scene, resolution, method, parameter).
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    pub scene: String,
    pub resolution: usize,
    pub coarse_resolution: usize,
    pub method: String,
    pub param: Option<f32>,
    pub evaluations: u64,
    pub dense_evaluations: u64,
    pub band_bound: u64,
    pub iou_vs_dense: f64,
    pub lost_components: usize,
    pub dense_components: usize,
    /// Median wall time of the runs, ms, measured in the same process as dense.
    pub ms: f64,
    /// Median time of the runs spent outside the field (the method's own bookkeeping), ms.
    pub bookkeeping_ms: f64,
    pub dense_ms: f64,
    pub runs: usize,
    pub conflict_rounds: u32,
    /// The method returned nothing (the demo's mode with no inside point at the coarsest
    /// level); the grid counts as all outside.
    pub empty: bool,
}

impl Row {
    pub fn label(&self) -> String {
        match self.param {
            Some(p) => format!("{}@{p}", self.method),
            None => self.method.clone(),
        }
    }
    /// Dense evaluations divided by this method's.
    pub fn eval_speedup(&self) -> f64 {
        self.dense_evaluations as f64 / self.evaluations.max(1) as f64
    }
    pub fn time_speedup(&self) -> f64 {
        self.dense_ms / self.ms.max(1e-9)
    }
    pub fn evals_over_band(&self) -> f64 {
        self.evaluations as f64 / self.band_bound.max(1) as f64
    }
}

/// A field to benchmark, by scene name: an analytic scene, or a simulator scene (a path to a
/// scene file, or a name under `tests/scenes/`) whose frame-0 clothed-human occupancy oracle
/// is the field, in that frame's render view.
fn scene_field(name: &str) -> anyhow::Result<Box<dyn OccupancyField>> {
    if let Some(s) = AnalyticScene::by_name(name) {
        return Ok(Box::new(s));
    }
    let path = if name.ends_with(".toml") {
        PathBuf::from(name)
    } else {
        PathBuf::from(format!("tests/scenes/{name}.toml"))
    };
    if path.exists() {
        let assets =
            std::sync::Arc::new(volcap_sim::HumanAssets::embedded().map_err(anyhow::Error::msg)?);
        let mut sim = crate::simcmd::load_scene(&path, assets)?;
        sim.render(0)
            .with_context(|| format!("{}: frame 0", path.display()))?;
        return Ok(Box::new(sim.oracle(volcap_sim::oracle::DEFAULT_VOXEL_M)));
    }
    bail!(
        "unknown scene '{name}' (analytic scenes: {}; or a simulator scene file / a name under tests/scenes/)",
        SCENES.join(", ")
    )
}

fn timed(
    loc: &mut Localizer,
    m: Method,
    field: &dyn OccupancyField,
    spec: GridSpec,
    coarse: u32,
    grid: &mut Grid,
    a: &LocalizeArgs,
) -> anyhow::Result<(f64, f64, usize, LocalizeStats)> {
    let (runs, budget_s) = (a.runs, a.time_budget);
    let mut times = Vec::new();
    let mut own = Vec::new();
    let mut stats = LocalizeStats::default();
    let start = Instant::now();
    while times.len() < runs.max(1) {
        let t = Instant::now();
        stats = loc
            .run(m, field, spec, coarse, grid)
            .with_context(|| format!("{} failed", m.label()))?;
        let ms = t.elapsed().as_secs_f64() * 1e3;
        times.push(ms);
        own.push((ms - loc.last_field_time().as_secs_f64() * 1e3).max(0.0));
        if start.elapsed().as_secs_f64() > budget_s {
            break;
        }
    }
    let n = times.len();
    Ok((median(&mut times), median(&mut own), n, stats))
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    match n {
        0 => 0.0,
        _ if n % 2 == 1 => v[n / 2],
        _ => 0.5 * (v[n / 2 - 1] + v[n / 2]),
    }
}

/// Network fields: for every `--model NAME[@int8]` and simulator scene (default
/// `front-walk`), frame 0 through segmentation and the encoders; the field is the trained
/// MLP on the input view's crop cube. Scene label `SCENE/NAME-PRECISION`.
type NamedFields = (Vec<String>, Vec<BenchField>);

/// A field to benchmark; a network field on the GPU backend can also be localized wholly on
/// the adapter (`GpuLocalizer`: its rows say `@adapter`).
enum BenchField {
    Dyn(Box<dyn OccupancyField>),
    Model(
        Box<volcap_engine::model::ModelField>,
        #[cfg_attr(not(feature = "wgpu"), allow(dead_code))] Option<std::sync::Arc<AdapterOf>>,
    ),
}

#[cfg(feature = "wgpu")]
type AdapterOf = volcap_engine::gpu::Gpu;
#[cfg(not(feature = "wgpu"))]
type AdapterOf = ();

impl BenchField {
    fn field(&self) -> &dyn OccupancyField {
        match self {
            BenchField::Dyn(f) => f.as_ref(),
            BenchField::Model(f, _) => f.as_ref(),
        }
    }
}

/// The hierarchical methods localized wholly on the adapter of `field` (its grid, index
/// lists and the field's series there), as rows beside the CPU's: median wall time with the
/// values left on the adapter; IoU against dense from the values read back afterwards.
#[cfg(feature = "wgpu")]
#[allow(clippy::too_many_arguments)]
fn adapter_rows(
    field: &BenchField,
    name: &str,
    spec: GridSpec,
    coarse: u32,
    methods: &[Method],
    dense: (&volcap_engine::grid::BitSet, &[Vec<u32>], u64, u64, f64),
    a: &LocalizeArgs,
    rows: &mut Vec<Row>,
) -> anyhow::Result<()> {
    use volcap_engine::gpu::localize::GpuLocalizer;
    use volcap_engine::localize::{HierarchicalMode, RoundWaits};
    let BenchField::Model(model, Some(gpu)) = field else {
        return Ok(());
    };
    let Some(on_gpu) = model.gpu_field() else {
        return Ok(());
    };
    let (dense_bits, comps, band, dense_evals, dense_ms) = dense;
    let per_wait = &a.rounds_per_wait;
    if let Some(bad) = per_wait.iter().find(|n| !(1..=64).contains(*n)) {
        anyhow::bail!("--rounds-per-wait {bad}: must lie in 1..=64");
    }
    let round_waits = crate::backend::by_names(
        "--round-waits",
        &a.round_waits,
        &RoundWaits::ALL,
        RoundWaits::name,
    )?;
    let plans = per_wait
        .iter()
        .flat_map(|p| round_waits.iter().map(move |w| (*p, *w)));
    for (per, waits_kind) in plans {
        let mut gl = GpuLocalizer::new(gpu.clone())
            .map_err(anyhow::Error::msg)?
            .with_rounds_per_wait(per)
            .with_round_waits(waits_kind);
        if let Err(e) = gl.check_size(spec) {
            // A grid over the adapter's buffer limit: the CPU rows stand, the adapter's are
            // left out and said why (the rest of the table still runs).
            eprintln!("{name}: no @adapter rows at {}^3: {e}", spec.n());
            return Ok(());
        }
        for &m in methods {
            let mode = match m {
                Method::Hierarchical => HierarchicalMode::Paper,
                Method::HierarchicalNoConflict => HierarchicalMode::NoConflict,
                Method::HierarchicalTight => HierarchicalMode::Tight,
                _ => continue,
            };
            let mut times = Vec::new();
            let mut stats = LocalizeStats::default();
            let start = Instant::now();
            // One warm-up run (kernels compiled, buffers made), not timed.
            gl.run(&on_gpu, spec, coarse, mode)
                .map_err(anyhow::Error::msg)?;
            let waits0 = gpu.counters().waits;
            while times.len() < a.runs.max(1) {
                let t = Instant::now();
                stats = gl
                    .run(&on_gpu, spec, coarse, mode)
                    .map_err(anyhow::Error::msg)?;
                times.push(t.elapsed().as_secs_f64() * 1e3);
                if start.elapsed().as_secs_f64() > a.time_budget {
                    break;
                }
            }
            let waits = (gpu.counters().waits - waits0) as f64 / times.len().max(1) as f64;
            let mut grid = Grid::new(spec);
            gl.read_grid(&mut grid).map_err(anyhow::Error::msg)?;
            let bits = grid.binarized();
            let runs = times.len();
            let ms = median(&mut times);
            rows.push(Row {
                scene: name.to_string(),
                resolution: spec.n(),
                coarse_resolution: (1usize << coarse) + 1,
                // The adapter's rows name the read-backs each run waited for (and the batch
                // limit, where more than one is measured).
                method: match (waits_kind, per_wait.len() > 1) {
                    (RoundWaits::PerFrame, _) => {
                        format!("{}@adapter (rounds predicted, {waits:.0} waits)", m.name())
                    }
                    (_, true) => {
                        format!("{}@adapter ({per} rounds/wait, {waits:.0} waits)", m.name())
                    }
                    _ => format!("{}@adapter ({waits:.0} waits)", m.name()),
                },
                param: None,
                evaluations: stats.evaluations,
                dense_evaluations: dense_evals,
                band_bound: band,
                iou_vs_dense: iou_bits(dense_bits, &bits),
                lost_components: lost_components(comps, &bits),
                dense_components: comps.len(),
                ms,
                bookkeeping_ms: ms,
                dense_ms,
                runs,
                conflict_rounds: stats.conflict_rounds,
                empty: false,
            });
        }
    }
    Ok(())
}

fn model_fields(a: &LocalizeArgs) -> anyhow::Result<NamedFields> {
    use volcap_engine::model::{ModelView, Models, Precision};
    let scenes: Vec<String> = if a.scenes.is_empty() {
        vec!["front-walk".into()]
    } else {
        a.scenes.clone()
    };
    let assets =
        std::sync::Arc::new(volcap_sim::HumanAssets::embedded().map_err(anyhow::Error::msg)?);
    let (mut names, mut fields): NamedFields = (vec![], vec![]);
    // Each backend's runtime, opened once (the GPU's adapter is shared by its models).
    let backends = a
        .backends
        .iter()
        .map(|b| {
            Ok((
                b.trim().to_string(),
                crate::backend::open(b, "tract", &a.adapter)?.0,
            ))
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    for (m, (backend, runtime)) in a
        .models
        .iter()
        .flat_map(|m| backends.iter().map(move |b| (m, b)))
    {
        let (name, prec) = match m.split_once('@') {
            Some((n, p)) => (
                n,
                Precision::parse(p)
                    .map_err(anyhow::Error::msg)
                    .context("--model")?,
            ),
            None => (m.as_str(), Precision::F32),
        };
        let models = Models::load_on(&a.models_dir, name, prec, runtime)?;
        for sc in &scenes {
            let path = if sc.ends_with(".toml") {
                PathBuf::from(sc)
            } else {
                PathBuf::from(format!("tests/scenes/{sc}.toml"))
            };
            let mut sim = crate::simcmd::load_scene(&path, assets.clone())?;
            let f = sim
                .render(0)
                .with_context(|| format!("{}: frame 0", path.display()))?;
            let (field, _) = models
                .frame(&f.rgb, f.width, f.height, ModelView::default())
                .with_context(|| format!("{} on {}", m, path.display()))?;
            // The CPU rows keep their names; the GPU's say so.
            names.push(match backend.as_str() {
                "cpu" => format!("{sc}/{name}-{}", prec.name()),
                b => format!("{sc}/{name}-{}-{b}", prec.name()),
            });
            #[cfg(feature = "wgpu")]
            let adapter = match runtime {
                volcap_engine::model::Runtime::Wgpu(g) => Some(g.clone()),
                _ => None,
            };
            #[cfg(not(feature = "wgpu"))]
            let adapter = None;
            fields.push(BenchField::Model(Box::new(field), adapter));
        }
    }
    Ok((names, fields))
}

pub fn localize(a: &LocalizeArgs) -> anyhow::Result<()> {
    let scenes: Vec<String> = if a.scenes.is_empty() {
        SCENES.iter().map(|s| s.to_string()).collect()
    } else {
        a.scenes.clone()
    };
    let (scenes, fields) = if a.models.is_empty() {
        let fields = scenes
            .iter()
            .map(|s| scene_field(s).map(BenchField::Dyn))
            .collect::<anyhow::Result<Vec<_>>>()?;
        (scenes, fields)
    } else {
        model_fields(a)?
    };
    let specs = a
        .res
        .iter()
        .map(|&r| GridSpec::from_resolution(r).with_context(|| format!("--res {r}")))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let mut methods = if a.methods.is_empty() {
        Method::all()
    } else {
        Method::parse_list(&a.methods)
            .map_err(anyhow::Error::msg)
            .context("--methods")?
    };
    methods.retain(|m| *m != Method::Dense);
    methods.insert(0, Method::Dense);
    if a.runs == 0 {
        bail!("--runs must be at least 1");
    }

    let total = (scenes.len() * specs.len() * methods.len()) as u64;
    let pb = ProgressBar::new(total);
    pb.set_style(
        ProgressStyle::with_template("{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut rows: Vec<Row> = Vec::new();
    let mut loc = Localizer::new();
    loc.set_threads(a.threads);
    let stdout = std::io::stdout();
    for (name, field) in scenes.iter().zip(&fields) {
        for &spec in &specs {
            let coarse = a
                .coarse_level
                .map(|c| c.min(spec.level()))
                .unwrap_or_else(|| default_coarse(spec));
            pb.set_message(format!("{name} {}^3 dense", spec.n()));
            let mut dense = Grid::new(spec);
            let (dense_ms, dense_own, dense_runs, dstats) = timed(
                &mut loc,
                Method::Dense,
                field.field(),
                spec,
                coarse,
                &mut dense,
                a,
            )?;
            let dense_bits = dense.binarized();
            let comps = components(spec, &dense_bits);
            let band = band_bound(spec, &dense_bits);
            let mut grid = Grid::new(spec);
            for &m in &methods {
                pb.set_message(format!("{name} {}^3 {}", spec.n(), m.label()));
                let (ms, own, runs, stats, iou, lost) = if m == Method::Dense {
                    (dense_ms, dense_own, dense_runs, dstats, 1.0, 0)
                } else {
                    let (ms, own, runs, st) =
                        timed(&mut loc, m, field.field(), spec, coarse, &mut grid, a)?;
                    let bits = grid.binarized();
                    (
                        ms,
                        own,
                        runs,
                        st,
                        iou_bits(&dense_bits, &bits),
                        lost_components(&comps, &bits),
                    )
                };
                let row = Row {
                    scene: name.clone(),
                    resolution: spec.n(),
                    coarse_resolution: (1usize << coarse) + 1,
                    method: m.name().to_string(),
                    param: m.param(),
                    evaluations: stats.evaluations,
                    dense_evaluations: dstats.evaluations,
                    band_bound: band,
                    iou_vs_dense: iou,
                    lost_components: lost,
                    dense_components: comps.len(),
                    ms,
                    bookkeeping_ms: own,
                    dense_ms,
                    runs,
                    conflict_rounds: stats.conflict_rounds,
                    empty: stats.empty,
                };
                if a.json {
                    let mut out = stdout.lock();
                    serde_json::to_writer(&mut out, &row)?;
                    writeln!(out)?;
                    out.flush()?;
                }
                rows.push(row);
                pb.inc(1);
            }
            #[cfg(feature = "wgpu")]
            {
                pb.set_message(format!("{name} {}^3 on the adapter", spec.n()));
                let dense = (&dense_bits, &comps[..], band, dstats.evaluations, dense_ms);
                adapter_rows(field, name, spec, coarse, &methods, dense, a, &mut rows)?;
            }
        }
    }
    pb.finish_and_clear();

    let out_dir = match (&a.out, a.json) {
        (Some(d), _) => Some(d.clone()),
        (None, false) => Some(PathBuf::from("docs/bench")),
        (None, true) => None,
    };
    if let Some(dir) = out_dir {
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        let plot_scene = a
            .plot_scene
            .clone()
            .or_else(|| scenes.iter().find(|s| *s == "capsule-human").cloned())
            .or_else(|| {
                scenes
                    .iter()
                    .find(|s| AnalyticScene::by_name(s).is_none())
                    .cloned()
            })
            .unwrap_or_else(|| scenes[0].clone());
        let md = dir.join("accuracy-vs-time.md");
        let png = dir.join("accuracy-vs-time.png");
        std::fs::write(&md, markdown(&rows, a, &plot_scene))
            .with_context(|| format!("writing {}", md.display()))?;
        crate::plot::accuracy_vs_time(&rows, &plot_scene, &png)
            .with_context(|| format!("writing {}", png.display()))?;
        if !a.json {
            println!("{}", summary_table(&rows));
            println!("wrote {} and {}", md.display(), png.display());
        }
    }
    Ok(())
}

fn summary_table(rows: &[Row]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "| scene | res | method | evaluations | x fewer | evals/band | IoU vs dense | lost | ms | bookkeeping ms | x faster |"
    );
    let _ = writeln!(s, "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    for r in rows {
        let _ = writeln!(
            s,
            "| {} | {} | {}{} | {} | {:.1} | {:.2} | {:.5} | {} | {:.1} | {:.1} | {:.1} |",
            r.scene,
            r.resolution,
            r.label(),
            if r.empty { " (empty result)" } else { "" },
            r.evaluations,
            r.eval_speedup(),
            r.evals_over_band(),
            r.iou_vs_dense,
            r.lost_components,
            r.ms,
            r.bookkeeping_ms,
            r.time_speedup()
        );
    }
    s
}

fn markdown(rows: &[Row], a: &LocalizeArgs, plot_scene: &str) -> String {
    let mut s = String::new();
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|c| {
            c.lines()
                .find(|l| l.starts_with("model name"))
                .map(|l| l.split(':').nth(1).unwrap_or("").trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into());
    let cores = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1);
    let _ = writeln!(s, "# Accuracy vs time: surface localization\n");
    let _ = writeln!(
        s,
        "Generated by `cargo run --release -p volcap -- bench localize{}{}` on {cpu} ({cores} cores), {} \
         evaluation. Every method runs on the same field and grid in the same process; `ms` is the median of \
         up to {} runs (fewer when a row exceeds {} s). Evaluation counts are exact and machine-independent; times \
         include each method's bookkeeping and filling of the full grid, {}\n",
        if a.res.len() == 4 && a.res == [65, 129, 257, 513] {
            String::new()
        } else {
            format!(
                " --res {}",
                a.res
                    .iter()
                    .map(|r| r.to_string())
                    .collect::<Vec<_>>()
                    .join(",")
            )
        },
        // Every flag that changes what was measured.
        a.scenes
            .iter()
            .map(|s| format!(" --scene {s}"))
            .chain(a.models.iter().map(|m| format!(" --model {m}")))
            .chain((!a.methods.is_empty()).then(|| format!(" --methods {}", a.methods.join(","))))
            .chain(a.coarse_level.map(|c| format!(" --coarse-level {c}")))
            .collect::<String>(),
        if a.threads > 1 {
            format!("{}-thread", a.threads)
        } else {
            "single-threaded".to_string()
        },
        a.runs,
        a.time_budget,
        if a.models.is_empty() {
            "and the analytic fields are cheap (tens of ns per point), so time ratios understate what a \
             network field (microseconds per point) gains."
        } else {
            "and the fields are the networks' (`--model`: one frame's, evaluated on the CPU)."
        }
    );
    let _ = writeln!(
        s,
        "Columns: `x fewer` = dense evaluations / evaluations; `evals/band` = evaluations / band bound (points whose \
         3x3x3 neighbourhood holds both sides of 0.5 in the dense result: the least an exact method must evaluate); \
         `IoU` against the dense binarized grid; `lost` = connected components of the dense result with no inside \
         point in the method's; `bookkeeping ms` = ms less the time spent inside the field (the method's own work: upsampling, candidate lists, conflict loop); `x faster` = dense ms / ms.\n"
    );
    let _ = writeln!(s, "![accuracy vs time](accuracy-vs-time.png)\n");
    let _ = writeln!(
        s,
        "Methods: `hierarchical` is the paper's (binarize, upsample, boundary + 1-ring, conflict loop; exact) \
         with the field's seeds (a network field's points known inside along its silhouette and thin parts, \
         evaluated at every level; analytic fields have none); `hierarchical-unseeded` the paper's without them; \
         `hierarchical-no-conflict` the same without the conflict loop; `hierarchical-tight` ours (no dilation, \
         conflict loop with sign-change closure; exact on these scenes); `demo-faster` the public demo's \
         \"faster\" mode as its code runs it (`Seg3dLossless._forward_faster`: continuous trilinear upsampling, \
         9^3 then 7^3 then 3^3 dilation, no conflict loop, the finest level never evaluated, and no result at all \
         when the coarsest grid has no inside point: marked `(empty result)`). The demo samples cell centres \
         (`align_corners=False`), we sample grid corners; the lossless methods are exact either way. Our default \
         coarsest grid is {}^3; the demo's own is {}^3 (`RTL/main.py`: 17, 33, 65, 129, 257), reported in \
         [coarse-17/](coarse-17/accuracy-vs-time.md).\n",
        (1usize << volcap_engine::localize::DEFAULT_COARSE_LEVEL) + 1,
        (1usize << volcap_engine::localize::DEMO_COARSE_LEVEL) + 1,
    );
    let _ = writeln!(
        s,
        "The plot shows `{plot_scene}`: one panel per resolution, IoU against dense vs acceleration (dense evaluations / evaluations).\n"
    );
    let mut scenes: Vec<&str> = rows.iter().map(|r| r.scene.as_str()).collect();
    scenes.dedup();
    for sc in scenes {
        let _ = writeln!(s, "## {sc}\n");
        let sub: Vec<Row> = rows.iter().filter(|r| r.scene == sc).cloned().collect();
        if let Some(r) = sub.first() {
            let _ = writeln!(
                s,
                "Coarsest grid {}^3; dense result has {} connected component(s).\n",
                r.coarse_resolution, r.dense_components
            );
        }
        s.push_str(&summary_table(&sub));
        s.push('\n');
    }
    s
}
