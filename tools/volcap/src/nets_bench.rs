//! `volcap bench nets`: each network of the pipeline on its own, one thread, the same input
//! every run: median milliseconds per network and model, and with `--profile` where tract
//! and the GPU backend spend them (per op kind or kernel, and the slowest nodes).

use anyhow::{Context, anyhow};
use clap::Args;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;
use volcap_engine::model::{
    Models, Precision, Runtime, RuntimeChoice, ShapeModel, preprocess::INPUT_SIZE,
};
use volcap_engine::model::{Net, NodeTime};

#[derive(Args, Debug, Clone)]
pub struct NetsArgs {
    /// Shape models (NAME or NAME@int8, comma-separated).
    #[arg(long = "model", value_delimiter = ',', default_value = volcap_engine::model::DEFAULT_MODEL)]
    pub models: Vec<String>,
    /// Runtimes (comma-separated): tract, onnxruntime (its library as the daemon finds it:
    /// $VOLCAP_ONNXRUNTIME, /usr/lib/volcap/onnxruntime/, target/onnxruntime/), wgpu (the
    /// GPU backend's kernels; build with `--features wgpu`), wgpu-split, wgpu-rows,
    /// wgpu-conv4 (the same with the split convolutions, without them (a CPU adapter's
    /// default), or with conv4 only: every ungrouped convolution four channels per
    /// invocation).
    #[arg(
        long = "runtime",
        value_delimiter = ',',
        default_value = "tract,onnxruntime"
    )]
    pub runtimes: Vec<String>,
    /// Timed runs per network (median reported).
    #[arg(long, default_value_t = 20)]
    pub runs: usize,
    /// Also time every node of tract's optimized plan and every step of the GPU backend's
    /// (the adapter's timestamps): totals per op kind or kernel and the slowest nodes.
    #[arg(long)]
    pub profile: bool,
    /// Slowest nodes listed per network with --profile.
    #[arg(long, default_value_t = 12)]
    pub top: usize,
    /// Folder of the ONNX models.
    #[arg(long, default_value = "models")]
    pub models_dir: PathBuf,
    /// Folder for nets.md (default docs/bench).
    #[arg(long, default_value = "docs/bench")]
    pub out: PathBuf,
}

/// A deterministic input in [-1, 1] of `len` values (a network's time does not depend on
/// its values, but a constant could take shortcuts).
/// A network's input: its shape and values.
type Input<'a> = (Vec<usize>, &'a [f32]);

/// Points of the colour MLP's row: about the surface points of a 257^3 frame of front-walk.
const HITS: usize = 16384;

/// Seconds of every network run in turn before the timed runs (a GPU's clock rises under
/// load).
const WARM_UP_S: f64 = 2.0;

/// One network on one runtime: its input, and its timed runs.
struct Job<'a> {
    row: usize,
    ri: usize,
    file: String,
    net: &'a Net,
    inputs: Vec<Input<'a>>,
    /// Wall milliseconds of each timed run.
    ms: Vec<f64>,
    /// The adapter's nanoseconds over the timed runs (timestamps; 0 off a GPU).
    adapter_ns: u64,
}

impl Job<'_> {
    fn args(&self) -> Vec<(&[usize], &[f32])> {
        self.inputs
            .iter()
            .map(|(d, v)| (d.as_slice(), *v))
            .collect()
    }

    fn run(&self) -> anyhow::Result<()> {
        self.net
            .run(&self.args())
            .map(|_| ())
            .map_err(anyhow::Error::msg)
    }
}

fn input(len: usize) -> Vec<f32> {
    (0..len)
        .map(|i| ((i * 37 % 101) as f32 / 50.0) - 1.0)
        .collect()
}

pub fn run(a: &NetsArgs) -> anyhow::Result<()> {
    let s = INPUT_SIZE;
    let rgb = input(3 * s * s);
    let x = input(4 * s * s);
    // First, on a quiet process (after tract's runs its pool's threads share the cores).
    let filter = temporal_cost(a.runs)? + &smooth_cost(a.runs)?;
    let mut runtimes = Vec::new();
    for r in &a.runtimes {
        if let Some(kernels) = r.trim().strip_prefix("wgpu") {
            // The GPU backend's kernels on the first adapter `auto` picks (the convolution
            // kernels the adapter plans with); wgpu-split, wgpu-rows and wgpu-conv4 each on a
            // device of its own with those kernels (the baselines they are measured against
            // in the same run).
            #[cfg(feature = "wgpu")]
            let kernels = {
                use volcap_engine::gpu::net::plan::ConvKernels as K;
                match kernels {
                    "" => None,
                    "-split" => Some(K::Split),
                    "-rows" => Some(K::Rows),
                    "-conv4" => Some(K::Conv4),
                    other => {
                        return Err(anyhow!(
                            "--runtime wgpu{other}: wgpu, wgpu-split, wgpu-rows or wgpu-conv4"
                        ));
                    }
                }
            };
            let rt = crate::backend::open("wgpu", "tract", "auto")?.0;
            #[cfg(feature = "wgpu")]
            if let (Runtime::Wgpu(g), Some(k)) = (&rt, kernels) {
                g.set_conv_kernels(k);
            }
            #[cfg(not(feature = "wgpu"))]
            let _ = kernels;
            runtimes.push(rt);
            continue;
        }
        let choice = RuntimeChoice::parse(r.trim()).map_err(|e| anyhow!("--runtime: {e}"))?;
        let opened = Runtime::open(choice, None).map_err(|e| anyhow!("--runtime {r}: {e}"))?;
        runtimes.push(opened.runtime);
    }
    // A runtime that is another one over again (wgpu-rows where rows are the adapter's
    // default, as on lavapipe) is measured once.
    let mut seen = std::collections::HashSet::new();
    runtimes.retain(|rt| {
        let fresh = seen.insert(rt.label());
        if !fresh {
            eprintln!(
                "--runtime: {} once (listed twice: the adapter's own kernels)",
                rt.label()
            );
        }
        fresh
    });
    // Every runtime's models loaded first: the runtimes are then timed run by run in turn
    // (below), not one after another.
    let mut loaded: Vec<(usize, Models, [Vec<f32>; 3])> = Vec::new();
    for (ri, rt) in runtimes.iter().enumerate() {
        for m in &a.models {
            let (name, prec) = match m.split_once('@') {
                Some((n, p)) => (n, Precision::parse(p).map_err(anyhow::Error::msg)?),
                None => (m.as_str(), Precision::F32),
            };
            let models = Models::load_on(&a.models_dir, name, prec, rt).map_err(|e| {
                anyhow!(
                    "model {m} in {} on {}: {e}",
                    a.models_dir.display(),
                    rt.label()
                )
            })?;
            // The colour MLP on a frame's surface points (about a 257^3 frame's hits): its
            // features, the input pixel's RGB and the depth.
            let cc = models.color.channels;
            let mlp_in = [input(HITS * cc), input(HITS * 3), input(HITS)];
            loaded.push((ri, models, mlp_in));
        }
    }
    // (network, file) -> ms per runtime, in first-seen order; one job per network and
    // runtime (a file that two models share, the segmentation and the colour networks, once).
    let mut rows: Vec<(String, String, Vec<Option<f64>>)> = Vec::new();
    let mut jobs: Vec<Job> = Vec::new();
    let mlp_what = format!("colour MLP ({HITS} points)");
    for (ri, models, [feat, prgb, z]) in &loaded {
        let shape: &Net = match &models.shape {
            ShapeModel::Fourier(f) => &f.net,
            ShapeModel::Mlp(n) => &n.encoder,
        };
        let cc = models.color.channels;
        let nets: [(&str, &Net, Vec<Input>); 4] = [
            ("segmentation", &models.seg, vec![(vec![1, 3, s, s], &rgb)]),
            ("shape encoder", shape, vec![(vec![1, 4, s, s], &x)]),
            (
                "colour encoder",
                &models.color.encoder,
                vec![(vec![1, 4, s, s], &x)],
            ),
            (
                &mlp_what,
                &models.color.mlp,
                vec![
                    (vec![HITS, cc], feat),
                    (vec![HITS, 3], prgb),
                    (vec![HITS, 1], z),
                ],
            ),
        ];
        for (what, net, inputs) in nets {
            let file = net
                .path()
                .file_name()
                .map(|f| f.to_string_lossy().to_string())
                .unwrap_or_default();
            let row = match rows.iter().position(|r| r.1 == file) {
                Some(i) => i,
                None => {
                    rows.push((what.to_string(), file.clone(), vec![None; runtimes.len()]));
                    rows.len() - 1
                }
            };
            if jobs.iter().any(|j| j.row == row && j.ri == *ri) {
                continue;
            }
            let job = Job {
                row,
                ri: *ri,
                file,
                net,
                inputs,
                ms: Vec::new(),
                adapter_ns: 0,
            };
            // One checked run each.
            job.run()
                .with_context(|| format!("{} on {}", job.file, runtimes[*ri].label()))?;
            jobs.push(job);
        }
    }
    // A GPU raises its clocks only under load: timed one runtime after another, the runtimes
    // measured last ran faster (the fourth H200 run, 2026-12-04: the colour MLP, the same
    // kernels under each convolution set, 0.83 / 0.34 / 0.25 ms on the adapter in the order
    // measured). So every job runs in turn for WARM_UP_S first, then the runtimes take turns
    // run by run within each network, each median over its own runs.
    let warm = Instant::now();
    while warm.elapsed().as_secs_f64() < WARM_UP_S {
        for j in &jobs {
            let _ = j.run();
        }
    }
    for row in 0..rows.len() {
        for _ in 0..a.runs.max(1) {
            for j in jobs.iter_mut().filter(|j| j.row == row) {
                // The inputs' views made before the clock starts.
                let args = j.args();
                let before = crate::backend::adapter_work(&runtimes[j.ri])[3];
                let t = Instant::now();
                let _ = j.net.run(&args);
                let ms = t.elapsed().as_secs_f64() * 1e3;
                let adapter_ns = crate::backend::adapter_work(&runtimes[j.ri])[3] - before;
                j.ms.push(ms);
                j.adapter_ns += adapter_ns;
            }
        }
    }
    let mut profile = String::new();
    let mut adapter = String::new();
    jobs.sort_by_key(|j| (j.ri, j.row));
    for j in &mut jobs {
        let rt = &runtimes[j.ri];
        j.ms.sort_by(f64::total_cmp);
        rows[j.row].2[j.ri] = j.ms.get(j.ms.len() / 2).copied();
        // The GPU backend's own time for the pass (timestamps), beside the wall time.
        if j.adapter_ns > 0 {
            let _ = writeln!(
                adapter,
                "| {} | {} | {:.2} |",
                j.file,
                rt.label(),
                j.adapter_ns as f64 / 1e6 / j.ms.len().max(1) as f64
            );
        }
        // Per node: tract's optimized plan, or the GPU backend's steps on the adapter (ONNX
        // Runtime has none to give).
        let profiled = match rt {
            Runtime::Tract => true,
            #[cfg(feature = "wgpu")]
            Runtime::Wgpu(_) => true,
            #[allow(unreachable_patterns)]
            _ => false,
        };
        if a.profile && profiled {
            let args = j.args();
            match j.net.profile(&args, a.runs) {
                Ok(nodes) => profile.push_str(&profile_md(
                    &format!("{} on {}", j.file, rt.label()),
                    &nodes,
                    a.top,
                )),
                // An adapter without timestamp queries: said, the rest stands.
                Err(e) if !matches!(rt, Runtime::Tract) => {
                    let _ = writeln!(profile, "\n{} on {}: {e}", j.file, rt.label());
                }
                Err(e) => return Err(anyhow::Error::msg(e)),
            }
        }
    }
    let labels: Vec<String> = runtimes.iter().map(|r| r.label()).collect();
    let mut table = format!(
        "| network | file | {} |\n|---|---|{}\n",
        labels
            .iter()
            .map(|l| format!("{l} ms"))
            .collect::<Vec<_>>()
            .join(" | "),
        "---|".repeat(labels.len())
    );
    for (what, file, ms) in &rows {
        let cells: Vec<String> = ms
            .iter()
            .map(|m| m.map_or("-".into(), |m| format!("{m:.2}")))
            .collect();
        let _ = writeln!(table, "| {what} | {file} | {} |", cells.join(" | "));
    }
    let mut md = format!(
        "# The networks one by one\n\n`volcap bench nets --model {} --runtime {}{}` (median of {} \
         runs, one thread each; after {WARM_UP_S} s of every network in turn, the runtimes \
         taking turns run by run, so that a GPU's clock, raised under load, favours none).\n\n{table}",
        a.models.join(","),
        a.runtimes.join(","),
        if a.profile { " --profile" } else { "" },
        a.runs
    );
    if !adapter.is_empty() {
        md.push_str(&format!(
            "\nOn the adapter (timestamps around the network's compute pass, mean over the timed \
             runs; the wall time above adds the upload, submission and read-back):\n\n\
             | file | adapter | ms on the adapter |\n|---|---|---|\n{adapter}"
        ));
    }
    md.push_str(&filter);
    if a.profile {
        md.push_str(
            "\n## Where the time goes, per node (tract: its optimized plan, wall time; the GPU \
             backend: each step in a pass of its own, the adapter's timestamps; ops are then \
             the kernels)\n",
        );
        md.push_str(&profile);
    }
    std::fs::create_dir_all(&a.out).with_context(|| a.out.display().to_string())?;
    let path = a.out.join("nets.md");
    std::fs::write(&path, &md).with_context(|| path.display().to_string())?;
    print!("{md}");
    Ok(())
}

/// The `[temporal]` filter's own cost per frame on fourier-small's maps (128^2 x 31
/// coefficients, interleaved) and the colour features (64^2 x 32, planar): the person still
/// (the crop does not move: the last maps are read in place) and walking (the crop moves
/// every frame: the last maps are resampled into the new crop first).
fn temporal_cost(runs: usize) -> anyhow::Result<String> {
    use volcap_engine::model::preprocess::Crop;
    use volcap_engine::model::temporal::{MapLayout, Temporal, TemporalSettings};
    let shape = MapLayout {
        channels: 31,
        size: 128,
        interleaved: true,
    };
    let color = MapLayout {
        channels: 32,
        size: 64,
        interleaved: false,
    };
    let s = INPUT_SIZE;
    let mut out = String::from("\n| temporal filter, per frame | ms |\n|---|---|\n");
    for (what, step) in [
        ("person still (crop in place)", 0.0f32),
        ("person walking (crop moves)", 0.01),
    ] {
        let mut t = Temporal::new(TemporalSettings::default());
        let mut times = Vec::new();
        let base_s = input(shape.channels * shape.size * shape.size);
        let base_c = input(color.channels * color.size * color.size);
        for k in 0..=runs.max(1) + 1 {
            let mut mask = vec![0.0f32; s * s];
            for y in 40..220 {
                for x in 100..150 {
                    mask[y * s + x] = 0.95;
                }
            }
            let crop = Crop::from_mask(&mask, s).ok_or_else(|| anyhow!("no crop"))?;
            let crop = Crop {
                tx: crop.tx + step * k as f32,
                ..crop
            };
            let mut sm = base_s.clone();
            let mut cm = base_c.clone();
            let v = 0.01 * (k % 2) as f32;
            sm.iter_mut().chain(cm.iter_mut()).for_each(|x| *x += v);
            let start = Instant::now();
            let (Some(c), _) = t.steady_input(k as f64 / 30.0, 1, &mut mask, crop) else {
                anyhow::bail!("the filter lost the person");
            };
            t.steady_maps(c, (shape, &mut sm), Some((color, &mut cm)));
            let total = start.elapsed();
            if k > 1 {
                times.push(total.as_secs_f64() * 1e3);
            }
        }
        times.sort_by(f64::total_cmp);
        let _ = writeln!(out, "| {what} | {:.2} |", times[times.len() / 2]);
    }
    Ok(out)
}

/// The maps smoothed across pixels (`[model] map_smooth`) per frame on maps of
/// fourier-medium's size (128^2 x 31 coefficients): a body's rays (each pixel's the series of
/// one inside interval around [-0.3, 0.1] with its ends moved by up to 0.01 from pixel to
/// pixel, the network's row-to-row noise, and a forearm's patch of rays that also pass a
/// part in front, [-0.75, -0.65]) over a third of the pixels (about the main job's walk in its
/// crop) and over every pixel, then every pixel a person's with coefficients drawn anyhow
/// (rays of many inside runs, each smoothed ray decoded at many depths: the most a frame
/// can cost).
fn smooth_cost(runs: usize) -> anyhow::Result<String> {
    use volcap_engine::model::fourier::{FourierMaps, interval_coeffs};
    let (k, n) = (15, 128);
    let c = 2 * k + 1;
    let body_of = |person: &dyn Fn(usize, usize) -> bool| {
        let mut p = vec![0.0f32; c * n * n];
        for y in 0..n {
            for x in 0..n {
                if !person(x, y) {
                    continue;
                }
                let e = |i: usize| ((i * 37 % 101) as f64 / 101.0 - 0.5) * 0.02;
                let mut ivs = vec![[-0.3 + e(y * n + x), 0.1 + e(y * n + x + 7)]];
                if (60..70).contains(&x) && (40..60).contains(&y) {
                    ivs.push([-0.75, -0.65]);
                }
                for (ch, v) in interval_coeffs(&ivs, k).iter().enumerate() {
                    p[ch * n * n + y * n + x] = *v as f32;
                }
            }
        }
        p
    };
    let mut anyhow_maps = input(c * n * n);
    anyhow_maps[..n * n].fill(0.5);
    let mut out = String::from(
        "\n| maps smoothed across pixels (`map_smooth`, 128^2 x 31), per frame | 1 pass ms | 2 passes ms |\n|---|---|---|\n",
    );
    let third = |x: usize, y: usize| (40..104).contains(&x) && (8..(8 + n * 2 / 3)).contains(&y);
    for (what, planar) in [
        ("a body's rays on a third of the pixels", body_of(&third)),
        ("a body's rays on every pixel", body_of(&|_, _| true)),
        (
            "every pixel a person's, coefficients drawn anyhow",
            anyhow_maps,
        ),
    ] {
        let maps = FourierMaps::from_planar(&planar, k, n, 1.0)
            .ok_or_else(|| anyhow!("the bench's maps are not finite"))?
            .with_iso_level(0.55);
        let mut cells = Vec::new();
        for passes in [1u8, 2] {
            let mut times = Vec::new();
            for _ in 0..runs.max(1) + 1 {
                let m = maps.clone();
                let start = Instant::now();
                std::hint::black_box(m.smoothed(passes));
                times.push(start.elapsed().as_secs_f64() * 1e3);
            }
            times.sort_by(f64::total_cmp);
            cells.push(format!("{:.2}", times[times.len() / 2]));
        }
        let _ = writeln!(out, "| {what} | {} |", cells.join(" | "));
    }
    Ok(out)
}

/// Per op kind the total and share, then the slowest nodes.
fn profile_md(file: &str, nodes: &[NodeTime], top: usize) -> String {
    let total: f64 = nodes.iter().map(|n| n.ms).sum();
    let mut kinds: BTreeMap<&str, (f64, usize)> = BTreeMap::new();
    for n in nodes {
        let e = kinds.entry(n.op.as_str()).or_default();
        e.0 += n.ms;
        e.1 += 1;
    }
    let mut kinds: Vec<_> = kinds.into_iter().collect();
    kinds.sort_by(|a, b| b.1.0.total_cmp(&a.1.0));
    let mut s = format!(
        "\n### {file}: {total:.2} ms over {} nodes\n\n| op | nodes | ms | share |\n|---|---|---|---|\n",
        nodes.len()
    );
    for (op, (ms, n)) in &kinds {
        let _ = writeln!(s, "| {op} | {n} | {ms:.2} | {:.0} % |", 100.0 * ms / total);
    }
    let mut slow: Vec<&NodeTime> = nodes.iter().collect();
    slow.sort_by(|a, b| b.ms.total_cmp(&a.ms));
    s.push_str("\n| slowest nodes | op | ms |\n|---|---|---|\n");
    for n in slow.into_iter().take(top) {
        let _ = writeln!(s, "| {} | {} | {:.3} |", n.name, n.op, n.ms);
    }
    s
}
