//! `volcap eval`: the full pipeline (segmentation -> shape -> localization -> mesh) on
//! simulator renders of held-out subjects, against the simulator's ground truth.
//!
//! Per image: Chamfer and point-to-surface distance (cm) against the ground-truth clothed
//! mesh, IoU against the occupancy oracle on the same grid, mask IoU of the segmentation,
//! evaluations and time per stage. Per model: means, the 10 worst images' Chamfer / P2S (the
//! paper's starred columns) and ms per frame. Writes `OUT/eval.md`, `OUT/eval.json` and
//! `OUT/eval.png` (Chamfer against time, one point per model).

use anyhow::{Context, anyhow, bail};
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;
use std::sync::Arc;
use std::time::Instant;
use volcap_engine::grid::{Grid, GridSpec};
use volcap_engine::localize::{Method, default_coarse};
use volcap_engine::mesh::marching_cubes;
use volcap_engine::metrics::iou_bits;
use volcap_engine::model::fourier::Basis;
use volcap_engine::model::{DepthFrame, FrameError, ModelView, Models, Precision, ShapeModel};

pub mod apart;
mod args;
mod cases;
mod distances;
mod framing;
mod report;
mod tradeoff;
pub use apart::Apart;
use apart::parse_apart;
pub use args::{EvalArgs, FrameArg, TruthSurface};
use args::{grid_knobs, methods_of};
pub use report::ModelRow;
mod turntable;
pub mod video;
use cases::{Case, render_cases};
use distances::surface_distances;
pub use framing::Framing;
use framing::{OracleInCrop, ToCamera};
use report::report;
use tradeoff::plot;
pub use turntable::TURNTABLE_YAWS;
use turntable::{colour_errors, turntable};

/// The depth frame a model is compared in (ground-truth rows: always the camera's).
fn frame_of(arg: FrameArg, models: &Models, truth_k: Option<(Basis, usize)>) -> DepthFrame {
    match (arg, truth_k, &models.shape) {
        (_, Some(_), _) | (FrameArg::Camera, _, _) => DepthFrame::Camera,
        (FrameArg::Body, _, _) => DepthFrame::Body,
        (FrameArg::Auto, None, ShapeModel::Fourier(f)) => f.depth_frame,
        (FrameArg::Auto, None, ShapeModel::Mlp(_)) => DepthFrame::Camera,
    }
}

#[derive(Debug, Clone, Serialize)]
pub struct ImageRow {
    pub model: String,
    pub subject: String,
    pub pose: usize,
    pub yaw_deg: f32,
    /// "ok" or why there is no reconstruction (counted as the worst images).
    pub status: String,
    pub chamfer_cm: f64,
    pub p2s_cm: f64,
    pub iou: f64,
    pub mask_iou: f64,
    /// Whether the frame's lower edge cuts the person (the true mask reaches the last row:
    /// what switches the daemon to its close-range model).
    pub cut_by_frame: bool,
    pub evaluations: u64,
    pub segment_ms: f64,
    pub encode_ms: f64,
    pub localize_ms: f64,
    pub mesh_ms: f64,
    /// Per body part ([`volcap_sim::parts::Part::ALL`]: head, torso, arms, hands, legs,
    /// feet): mean distance (cm) from the true surface of that part (10k samples, labelled
    /// by the nearest body vertex's bone) to the reconstruction; NaN where the frame shows
    /// none of it. A missing hand is a large hands value.
    pub part_cm: [f64; 6],
    /// Per body part, the share of the P2S (cm) that the reconstruction's samples nearest
    /// that part's body vertices make: the sum of their distances to the true surface over
    /// all samples, so the six add up to the image's P2S. Where spurious surface is (a
    /// blurred fringe, a misplaced hand) rather than what is missing.
    pub part_p2s_cm: [f64; 6],
    /// Per body part, the share (0-1) of that part's true samples within 2 cm
    /// ([`distances::SHOWN_WITHIN_M`]) of the reconstruction: how much of it is there at all
    /// (the hands on eval.md's 21 images: 0.15 for the model whose arms ended at the wrist, 0.72
    /// for the 31-term truth series), where `part_cm`'s mean is led by the farthest samples;
    /// NaN where the frame shows none of it.
    pub part_shown: [f64; 6],
    /// [`distances::Distances::reversed_chamfer_cm`]: the reconstruction turned around in depth.
    pub reversed_chamfer_cm: f64,
    /// A facing error: the reconstruction turned around in depth is nearer the truth than
    /// as it is (`reversed_chamfer_cm < chamfer_cm`): the network put the person's front
    /// where the back is (hands.md section 18's rule, here on the whole pipeline's surface).
    pub facing_error: bool,
    /// Colour error of the views ([`turntable::colour_errors`]; NaN with `--colour-res 0`,
    /// for the ground-truth rows and failed images): the mean absolute RGB difference (0-1)
    /// from the oracle's colours at the input's exposure on the pixels both renders show
    /// (`turntable::exposure_gain`), at the input view (yaw 0: the input's pixels), the side
    /// (yaw 90), the back (yaw 180), and the back with the input's colours (no colour
    /// networks).
    pub colour_l1: [f64; 4],
}

fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    if n == 0 { f64::NAN } else { s / n as f64 }
}

fn worst10(rows: &[&ImageRow], key: impl Fn(&ImageRow) -> f64) -> f64 {
    let mut v: Vec<f64> = rows.iter().map(|r| key(r)).collect();
    v.sort_by(|a, b| b.total_cmp(a));
    mean(v.into_iter().take(10))
}

/// Map size and depth scale of the ground-truth Fourier fields (`truth-kK`), the trained
/// heads' (tools/train/volcap_train/fourier.py).
const TRUTH_MAP_SIZE: usize = 128;
const TRUTH_ZETA_SCALE: f32 = 2.0;

/// `truth-kK` names the ground-truth Fourier field of order K (2K + 1 coefficients, the
/// family's upper bound); `truth-cosN` the ground-truth half-range cosine series of N
/// coefficients (N odd: the same channels as K = (N - 1) / 2).
fn truth_order(name: &str) -> Option<(Basis, usize)> {
    if let Some(n) = name.strip_prefix("truth-cos") {
        return n
            .parse::<usize>()
            .ok()
            .filter(|n| n % 2 == 1)
            .map(|n| (Basis::Cosine, (n - 1) / 2));
    }
    name.strip_prefix("truth-k")
        .and_then(|k| k.parse().ok())
        .map(|k| (Basis::Fourier, k))
}

#[allow(clippy::too_many_arguments)]
fn run_case(
    models: &Models,
    label: &str,
    c: &Case,
    spec: GridSpec,
    method: Method,
    stages: &mut crate::backend::Stages,
    grid: &mut Grid,
    truth: &mut Grid,
    gt_mask: bool,
    truth_k: Option<(Basis, usize)>,
    to_cam: ToCamera,
    drop_apart: Option<[f32; 2]>,
    colour_res: usize,
) -> anyhow::Result<ImageRow> {
    let mut row = ImageRow {
        model: label.into(),
        subject: c.subject.clone(),
        pose: c.pose,
        yaw_deg: c.yaw,
        status: "ok".into(),
        chamfer_cm: f64::NAN,
        p2s_cm: f64::NAN,
        iou: 0.0,
        mask_iou: 0.0,
        cut_by_frame: false,
        evaluations: 0,
        segment_ms: 0.0,
        encode_ms: 0.0,
        localize_ms: 0.0,
        mesh_ms: 0.0,
        part_cm: [f64::NAN; 6],
        part_p2s_cm: [f64::NAN; 6],
        part_shown: [f64::NAN; 6],
        reversed_chamfer_cm: f64::NAN,
        facing_error: false,
        colour_l1: [f64::NAN; 4],
    };
    let s = c.size;
    let truth_mask: Vec<f32> = c.mask.iter().map(|&m| m as f32 / 255.0).collect();
    row.cut_by_frame = volcap_engine::model::preprocess::cut_by_frame(&truth_mask, s, s);
    // Mask IoU of the segmentation (the product's: the most prominent person kept) against
    // the simulator's person mask.
    let img = volcap_engine::model::preprocess::letterbox(&c.rgb, s, s);
    let t = Instant::now();
    let (prob, _) = models.person_mask(&img)?;
    row.segment_ms = t.elapsed().as_secs_f64() * 1e3;
    row.mask_iou = volcap_engine::metrics::mask_iou(
        prob.iter().zip(&c.mask).map(|(p, m)| (*p > 0.5, *m > 127)),
    );
    let prob = if gt_mask || truth_k.is_some() {
        truth_mask
    } else {
        prob
    };
    let Some(crop) = volcap_engine::model::preprocess::Crop::from_mask(&prob, s) else {
        row.status = FrameError::NoPerson.to_string();
        return Ok(row);
    };
    let t = Instant::now();
    let field = match truth_k {
        // The family's upper bound: ground-truth coefficients of 2K + 1 terms in `basis`.
        Some((basis, k)) => {
            let maps = volcap_sim::rays::basis_maps(
                &c.rays,
                &crop,
                basis,
                k,
                TRUTH_MAP_SIZE,
                TRUTH_ZETA_SCALE,
            )
            .ok_or_else(|| anyhow!("ground-truth {} maps", basis.name()))?;
            volcap_engine::model::ModelField::new(
                crop.apply(&prob, 1, s),
                volcap_engine::model::ShapeState::Fourier(maps),
                None,
                crop.apply(&img, 3, s),
                crop,
                ModelView::default(),
            )
        }
        None => models.encode(&img, &prob, crop, ModelView::default())?,
    };
    row.encode_ms = t.elapsed().as_secs_f64() * 1e3;
    let t = Instant::now();
    // On the adapter with `--backend wgpu` (the same evaluated points: tested in gpu_frames).
    let stats = stages.localize_with(method, &field, spec, grid)?;
    row.localize_ms = t.elapsed().as_secs_f64() * 1e3;
    row.evaluations = stats.evaluations;
    let t = Instant::now();
    if let Some(f) = drop_apart {
        let gap = |f| volcap_engine::pieces::gap_points(spec, f);
        volcap_engine::pieces::drop_apart(grid, [gap(f[0]), gap(f[0]), gap(f[1])]);
    }
    let pieces_ms = t.elapsed().as_secs_f64() * 1e3;
    // IoU against the oracle on the same grid (dense oracle: cheap, it is a lookup).
    stages.cpu_localizer().run(
        Method::Dense,
        &OracleInCrop {
            oracle: &c.oracle,
            crop,
            to_cam,
        },
        spec,
        default_coarse(spec),
        truth,
    )?;
    row.iou = iou_bits(&grid.binarized(), &truth.binarized());
    let t = Instant::now();
    let mesh = marching_cubes(grid);
    row.mesh_ms = t.elapsed().as_secs_f64() * 1e3 + pieces_ms;
    match surface_distances(mesh, crop, to_cam, &c.oracle, &c.gt_mesh, Some(&c.parts)) {
        Some(d) => {
            row.chamfer_cm = d.chamfer_cm;
            row.p2s_cm = d.p2s_cm;
            row.part_cm = d.part_cm;
            row.part_p2s_cm = d.part_p2s_cm;
            row.part_shown = d.part_shown;
            row.reversed_chamfer_cm = d.reversed_chamfer_cm;
            row.facing_error = d.reversed_chamfer_cm < d.chamfer_cm;
        }
        None => row.status = "empty surface".into(),
    }
    if colour_res > 0 && truth_k.is_none() && row.status == "ok" {
        row.colour_l1 = colour_errors(
            models,
            c,
            &field,
            (&img, &prob, crop),
            colour_res,
            to_cam,
            drop_apart.map(|g| g[0]),
        )
        .context("the colour columns")?;
    }
    Ok(row)
}

/// A `LEVEL,PIXELS` decode knob (`flag`): LEVEL in (0, 1), then a whole number of map pixels
/// in `px` (named `what` in the error).
fn level_in_pixels(
    flag: &str,
    what: &str,
    m: Option<&[f32]>,
    px: std::ops::RangeInclusive<u16>,
) -> anyhow::Result<()> {
    if let Some(m) = m
        && (m.len() != 2
            || !(m[0] > 0.0 && m[0] < 1.0)
            || !(f32::from(*px.start())..=f32::from(*px.end())).contains(&m[1])
            || m[1].fract() != 0.0)
    {
        bail!(
            "{flag} {m:?}: LEVEL,{what} with LEVEL in (0, 1) and {what} a whole number of map pixels in {}..={}",
            px.start(),
            px.end()
        );
    }
    Ok(())
}

/// Segment (and with `encode`, encode) case `c` once, untimed.
fn warm_up(models: &Models, c: &Case, encode: bool) -> anyhow::Result<()> {
    let img = volcap_engine::model::preprocess::letterbox(&c.rgb, c.size, c.size);
    let (prob, _) = models.person_mask(&img)?;
    if encode && let Some(crop) = volcap_engine::model::preprocess::Crop::from_mask(&prob, c.size) {
        models.encode(&img, &prob, crop, ModelView::default())?;
    }
    Ok(())
}

pub fn eval(a: &EvalArgs) -> anyhow::Result<()> {
    if a.replot {
        return tradeoff::replot(&a.out);
    }
    let grids = grid_knobs(a)?;
    let methods = methods_of(&a.method)?;
    let mut specs = Vec::new();
    for m in &a.model {
        let (name, prec) = match m.split_once('@') {
            Some((n, p)) => (n, Precision::parse(p).map_err(anyhow::Error::msg)?),
            None => (m.as_str(), Precision::F32),
        };
        specs.push((name.to_string(), prec));
    }
    let peak_ok = |pl: &[f32]| {
        (2..=3).contains(&pl.len())
            && pl[0] > 0.0
            && pl[0] < 1.0
            && (0.0..1.0).contains(&pl[1])
            && pl.get(2).is_none_or(|g| *g > 0.0 && *g <= 1.0)
    };
    if let Some(pl) = &a.peak_level
        && !peak_ok(pl)
    {
        bail!(
            "--peak-level {pl:?}: FRAC,MIN[,GATE] with FRAC in (0, 1), MIN in [0, 1) and GATE in (0, 1]"
        );
    }
    if let Some(m) = &a.moment_fill
        && (m.len() != 3
            || !(m[0].is_finite() && m[0] > 0.0 && m[0] <= 2.0)
            || !(m[1] >= m[0] && m[1] <= 2.0)
            || !(1.0..=32.0).contains(&m[2])
            || m[2].fract() != 0.0)
    {
        bail!(
            "--moment-fill {m:?}: MIN_LEN,MAX_LEN,AWAY with 0 < MIN_LEN <= MAX_LEN <= 2 and AWAY a whole number of map pixels in 1..=32"
        );
    }
    level_in_pixels(
        "--interior-level",
        "ERODE",
        a.interior_level.as_deref(),
        0..=32,
    )?;
    level_in_pixels("--thin-level", "RADIUS", a.thin_level.as_deref(), 1..=16)?;
    if a.colour_res != 0 {
        GridSpec::from_resolution(a.colour_res).with_context(|| {
            format!(
                "--colour-res {}: 0 (no colour columns) or a grid resolution",
                a.colour_res
            )
        })?;
    }
    if !a.segment_passes.is_empty() {
        crate::backend::check_segment_passes(&a.segment_passes)?;
    }
    for l in &a.iso_level {
        if !(l.is_finite() && *l > 0.0 && *l < 1.0) {
            anyhow::bail!("--iso-level {l}: each level must lie in (0, 1)");
        }
    }
    let levels: Vec<Option<f32>> = if a.iso_level.is_empty() {
        vec![None]
    } else {
        a.iso_level.iter().map(|l| Some(*l)).collect()
    };
    // Each Fourier model as predicted and, with --moment-fill, with the fill beside it.
    let fills: Vec<Option<(f32, f32, usize)>> = match &a.moment_fill {
        Some(m) if m.len() == 3 => vec![None, Some((m[0], m[1], m[2] as usize))],
        _ => vec![None],
    };
    // Every backend opened before the images are drawn (a missing adapter fails at once).
    let mut runtimes = Vec::new();
    for b in &a.backend {
        if runtimes.iter().any(|(n, _)| n == b.trim()) {
            bail!("--backend {b}: given twice");
        }
        let (runtime, _) = crate::backend::open(b, &a.runtime, &a.adapter)?;
        runtimes.push((b.trim().to_string(), runtime));
    }
    let cases = render_cases(a)?;
    if a.turntable && a.turntable_image >= cases.len() {
        bail!(
            "--turntable-image {}: the set has {} images (0 to {})",
            a.turntable_image,
            cases.len(),
            cases.len().saturating_sub(1)
        );
    }
    // None: the model's own count.
    let passes: Vec<Option<u8>> = if a.segment_passes.is_empty() {
        vec![None]
    } else {
        a.segment_passes.iter().map(|p| Some(*p)).collect()
    };
    // None: the engine's default.
    let smooths: Vec<Option<u8>> = if a.map_smooth.is_empty() {
        vec![None]
    } else {
        let max = volcap_engine::model::fourier::MAX_SMOOTH_PASSES;
        if let Some(p) = a.map_smooth.iter().find(|p| **p > max) {
            bail!("--map-smooth {p}: passes are 0 to {max}");
        }
        a.map_smooth.iter().map(|p| Some(*p)).collect()
    };
    let pb = ProgressBar::new(
        (cases.len()
            * smooths.len()
            * specs.len()
            * levels.len()
            * fills.len()
            * passes.len()
            * grids.len()
            * methods.len()
            * a.backend.len()) as u64,
    );
    // A row's cases, once per grid and method (skipped variants count them all).
    let per_variant = (cases.len() * grids.len() * methods.len()) as u64;
    pb.set_style(
        ProgressStyle::with_template("{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut images = Vec::new();
    let mut summary = Vec::new();
    for (backend, runtime) in &runtimes {
        let mut stages = crate::backend::Stages::new(runtime)?;
        for (((((name, prec), level), fill), seg_passes), smooth) in specs
            .iter()
            .flat_map(|s| levels.iter().map(move |l| (s, *l)))
            .flat_map(|sl| fills.iter().map(move |f| (sl, *f)))
            .flat_map(|slf| passes.iter().map(move |p| (slf, *p)))
            .flat_map(|slfp| smooths.iter().map(move |m| (slfp, *m)))
        {
            let truth_k = truth_order(name);
            // Ground-truth fields still segment (for the mask IoU column) with the default models.
            let mut models = Models::load_on(
                &a.models_dir,
                if truth_k.is_some() { "compact" } else { name },
                *prec,
                runtime,
            )?;
            // The maps' smoothing: Fourier models only (the ground-truth rows' series are the
            // truth), once for the others.
            let smooth = match smooth {
                Some(p) if truth_k.is_none() => {
                    let (m, took) = models.with_map_smooth(p);
                    models = m;
                    if took == 0 && Some(p) != smooths[0] {
                        pb.inc(per_variant);
                        continue;
                    }
                    (took > 0 && p != volcap_engine::model::fourier::DEFAULT_SMOOTH_PASSES)
                        .then_some(p)
                }
                Some(p) if Some(p) != smooths[0] => {
                    pb.inc(per_variant);
                    continue;
                }
                _ => None,
            };
            let own_passes = models.segment_passes;
            let seg_passes = seg_passes.unwrap_or(own_passes);
            models.segment_passes = seg_passes;
            // The Fourier net's decode knobs (not the ground-truth rows' nor other families').
            let knobs = a.peak_level.is_some()
                || a.moment_fill.is_some()
                || level.is_some()
                || a.interior_level.is_some()
                || a.thin_level.is_some();
            let mut fourier = match &mut models.shape {
                ShapeModel::Fourier(f) if truth_k.is_none() && knobs => Some(
                    Arc::get_mut(f).ok_or_else(|| anyhow!("{name}: the Fourier net is shared"))?,
                ),
                _ => None,
            };
            let peak = match (&mut fourier, &a.peak_level) {
                (Some(f), Some(pl)) if pl.len() >= 2 => {
                    f.peak_level = Some((pl[0], pl[1]));
                    f.peak_gate = pl.get(2).copied();
                    Some((pl[0], f.peak_gate))
                }
                _ => None,
            };
            let interior = match (&mut fourier, &a.interior_level) {
                (Some(f), Some(m)) if m.len() == 2 => {
                    f.interior_level = Some((m[0], m[1] as usize));
                    f.interior_level
                }
                _ => None,
            };
            let thin = match (&mut fourier, &a.thin_level) {
                (Some(f), Some(m)) if m.len() == 2 => {
                    f.thin_level = Some((m[0], m[1] as usize));
                    f.thin_level
                }
                _ => None,
            };
            let fill = match (&mut fourier, fill) {
                (Some(f), Some(m)) => {
                    f.moment_fill = Some(m);
                    Some((m.1, m.2))
                }
                // Other families and the ground-truth rows have no series to fill: once.
                (None, Some(_)) => {
                    pb.inc(per_variant);
                    continue;
                }
                _ => None,
            };
            let level = match (&mut fourier, level) {
                (Some(f), Some(l)) => {
                    f.iso_level = l;
                    Some(l)
                }
                // Other families and the ground-truth rows once, at their own rule.
                (_, Some(l)) if Some(l) != levels[0] => {
                    pb.inc(per_variant);
                    continue;
                }
                _ => None,
            };
            let variant = format!(
                "{name}-{}{}{}{}{}{}{}{}{}",
                prec.name(),
                if a.gt_mask { "-gtmask" } else { "" },
                smooth.map(|p| format!("-s{p}")).unwrap_or_default(),
                if seg_passes != own_passes {
                    format!("-seg{seg_passes}")
                } else {
                    String::new()
                },
                level.map(|l| format!("-iso{l:.2}")).unwrap_or_default(),
                peak.map(|(f, g)| format!(
                    "-peak{f:.2}{}",
                    g.map(|g| format!("g{g:.2}")).unwrap_or_default()
                ))
                .unwrap_or_default(),
                fill.map(|(l, d)| format!("-fill{l:.2}x{d}"))
                    .unwrap_or_default(),
                interior
                    .map(|(l, e)| format!("-in{l:.2}e{e}"))
                    .unwrap_or_default(),
                thin.map(|(l, r)| format!("-thin{l:.2}r{r}"))
                    .unwrap_or_default(),
            );
            let backend_label = if a.backend.len() > 1 {
                format!("-{backend}")
            } else {
                String::new()
            };
            let frame = frame_of(a.depth_frame, &models, truth_k);
            if let Some(c) = cases
                .get(a.turntable_image)
                .filter(|_| a.turntable && truth_k.is_none())
            {
                std::fs::create_dir_all(&a.out).with_context(|| format!("{}", a.out.display()))?;
                let label = format!("{variant}{backend_label}{}", a.drop_apart.label());
                let path = a.out.join(format!("turntable-{label}.png"));
                turntable(
                    &models,
                    c,
                    a.turntable_res,
                    ToCamera::new(frame, c, false),
                    a.drop_apart.0.map(|g| g[0]),
                    &path,
                )
                .with_context(|| format!("turntable of {label}"))?;
            }
            // The networks run once before the timed images (the first run of a loaded
            // model pays for its plans and buffers; the rows' times are the frames').
            if let Some(c) = cases.first() {
                warm_up(&models, c, truth_k.is_none())?;
            }
            let variant_rows = summary.len();
            // The model card's figures, read once for the model's rows.
            let card = report::card(&a.models_dir, name);
            for g in &grids {
                // The grids, once per resolution (every method's rows reuse them).
                let (mut grid, mut truth) = (Grid::new(g.spec), Grid::new(g.spec));
                for &method in &methods {
                    let label = format!(
                        "{variant}{}{}{}{backend_label}{}",
                        g.label,
                        if methods.len() > 1 {
                            format!("-{}", method.label())
                        } else {
                            String::new()
                        },
                        g.coarse_label,
                        a.drop_apart.label()
                    );
                    pb.set_message(label.clone());
                    stages.coarse_level = Some(g.coarse);
                    let start = images.len();
                    for c in &cases {
                        let row = run_case(
                            &models,
                            &label,
                            c,
                            g.spec,
                            method,
                            &mut stages,
                            &mut grid,
                            &mut truth,
                            a.gt_mask,
                            truth_k,
                            ToCamera::new(frame, c, truth_k.is_some()),
                            a.drop_apart.0,
                            a.colour_res,
                        )
                        .with_context(|| {
                            format!("{label} on {} pose {} yaw {}", c.subject, c.pose, c.yaw)
                        })?;
                        if a.json {
                            println!("{}", serde_json::to_string(&row)?);
                        }
                        images.push(row);
                        pb.inc(1);
                    }
                    let mut m = ModelRow::summarize(
                        &label,
                        frame.name(),
                        match &models.shape {
                            ShapeModel::Fourier(f) if truth_k.is_none() => Some(f.iso_level),
                            _ => None,
                        },
                        if let Some((basis, k)) = truth_k {
                            format!(
                                "{} series, {} terms (ground truth)",
                                basis.name(),
                                2 * k + 1
                            )
                        } else {
                            models.shape.family().to_string()
                        },
                        seg_passes,
                        card,
                        &images[start..],
                    );
                    m.res = g.spec.n();
                    m.coarse_level = g.coarse;
                    m.localization = method.label();
                    m.backend = runtime.label();
                    m.bound = truth_k.is_some();
                    summary.push(m);
                }
            }
            tradeoff::pool_networks(&mut summary[variant_rows..]);
            if a.json {
                for m in &summary[variant_rows..] {
                    println!("{}", serde_json::to_string(m)?);
                }
            }
        }
    }
    pb.finish_and_clear();
    std::fs::create_dir_all(&a.out).with_context(|| format!("{}", a.out.display()))?;
    let md = report(a, &summary, &images);
    std::fs::write(a.out.join("eval.md"), &md)?;
    std::fs::write(
        a.out.join("eval.json"),
        serde_json::to_string_pretty(&serde_json::json!({"models": summary, "images": images}))?,
    )?;
    plot(&summary, &a.out.join("eval.png"))?;
    if !a.json {
        print!("{md}");
    }
    Ok(())
}
