//! `volcap bench temporal`: the live model path frame by frame on simulated scenes, once per
//! setting of the temporal filter (`off` is every frame from scratch, as before the filter),
//! to show what steadiness costs in accuracy and lag.
//!
//! Per scene and setting:
//! - **flicker** (what the display shows: the daemon renders the crop's cube): consecutive
//!   frames' silhouettes from the front (along depth) and from the side (yaw 90, along x)
//!   as IoU, mean and worst, and the mean absolute change of the first-hit depth where both
//!   frames show the person (cm);
//! - **accuracy** against the simulator's truth of that frame: Chamfer and P2S (cm) against
//!   the clothed surface, IoU against the oracle in the same crop;
//! - **jitter** (camera frame, crop undone): the model's frame-to-frame depth change minus
//!   the oracle's, so that real motion smoothed away is not counted as stability;
//! - **lag**: the shift (frames) that best lines the filtered silhouettes up with the
//!   unfiltered run's earlier ones (0 when it follows at once);
//! - **flicker by body part** ([`parts`]): the same consecutive pairs, split by the body
//!   part each displayed pixel shows (is it the hands that flicker?), and the pair of the
//!   worst side IoU looked at closely ([`edges`]: near edge, far edge, holes or pieces, how
//!   deep, against each part's share of the outline; its two side views drawn to
//!   OUT/worst-side/, the worst front pair's to OUT/worst-front/);
//! - **as displayed** ([`display`]): the still scenes' silhouettes at `--display-size` by the
//!   renderer's blend of the grid's columns, beside the per-column figures; and how far the
//!   crop, the display's frame, moved between frames ([`compare::crop_move_cells`]).
//!
//! The silhouettes and depths are projections of the localized grid (orthographic, as the
//! daemon's renderer), so they cost no extra field evaluation.

use super::framing::{OracleInCrop, ToCamera};
use super::{FrameArg, frame_of, surface_distances};
use anyhow::{Context, anyhow, bail};
use clap::Args;
use glam::Vec3;
use indicatif::{ProgressBar, ProgressStyle};

mod compare;
mod display;
mod edges;
mod parts;
mod report;
mod row;
mod setting;
use compare::{compare_hits, compare_raster, lag_of};
use report::{plot, report};
pub use row::VideoRow;
use setting::parse_setting;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use volcap_engine::grid::{Grid, GridSpec, is_inside};
use volcap_engine::localize::{Localizer, Method};
use volcap_engine::mesh::Mesh;
use volcap_engine::metrics::iou_bits;
use volcap_engine::model::preprocess::Crop;
use volcap_engine::model::temporal::Temporal;
use volcap_engine::model::{
    DepthFrame, FrameInfo, ModelView, Models, Precision, SegmentTrack, Tracked,
};
use volcap_sim::scene::{MotionSpec, Scene};
use volcap_sim::sim::Simulator;

#[derive(Args, Debug, Clone)]
pub struct TemporalArgs {
    /// Scene files (comma-separated). Still people (the flicker cases) and moving ones (the
    /// accuracy, jitter and lag cases).
    #[arg(
        long = "scene",
        value_delimiter = ',',
        default_value = "tests/scenes/still-rest-noise.toml,tests/scenes/still-tpose-noise.toml,tests/scenes/still-rest.toml,tests/scenes/front-walk.toml,tests/scenes/turn.toml,tests/scenes/arms-overhead.toml,tests/scenes/fast-motion-blur.toml"
    )]
    pub scenes: Vec<PathBuf>,
    /// Frames per scene (from frame 0, at the scene's frame rate).
    #[arg(long, default_value_t = 30)]
    pub frames: u64,
    /// Frames at the start of each scene left out of the flicker figures (the filter's
    /// warm-up from the first frame, the same for every setting): a person standing still
    /// in front of the appliance is still for far longer.
    #[arg(long, default_value_t = 6)]
    pub settle: usize,
    /// Grid resolution (2^L + 1).
    #[arg(long, default_value_t = 257)]
    pub res: usize,
    /// Coarsest localization level of the model's field (the daemon's `render.coarse_level`);
    /// the truth is localized from level 5 (33^3), finer than any body part is thin.
    #[arg(long, default_value_t = 4)]
    pub coarse_level: u32,
    /// Shape model (NAME or NAME@int8).
    #[arg(long, default_value = volcap_engine::model::DEFAULT_MODEL)]
    pub model: String,
    /// Filter settings (comma-separated): `off`, `default` (volcapd's defaults), or
    /// `KEY=VALUE+KEY=VALUE...` over the defaults (`off+segment_full_every=N` or
    /// `default+segment_full_every=N`: the segmentation's track, and `map_smooth=N`: the
    /// passes of smoothing across the maps' pixels, 0 none: `[model]`'s keys; keys of
    /// `[temporal]`: crop_min_cutoff_hz, crop_beta, crop_hold, mask_low, mask_high,
    /// mask_motion, mask_hold_frames, mask_still_hold_frames, mask_dead_band,
    /// surface_dead_band, map_min_cutoff_hz, map_beta, map_change_cutoff_hz,
    /// map_motion_weight, same_person_iou).
    #[arg(
        long = "setting",
        value_delimiter = ',',
        default_value = "off,default,default+segment_full_every=8,map_change_cutoff_hz=1.5,mask_low=0.5+mask_high=0.5"
    )]
    pub settings: Vec<String>,
    /// Inside pieces farther than this fraction of the grid's side from the body are left
    /// out of the model's grid, as the meshes do (`render.drop_apart`; the render drops the
    /// same pieces on its level `L - 1`; 0 keeps them: whether the pass makes pieces come
    /// and go between frames).
    #[arg(long, default_value_t = volcap_engine::pieces::DEFAULT_GAP)]
    pub drop_apart: f32,
    /// Display size (pixels a side) of the silhouettes "as displayed" ([`display`]: the
    /// renderer's blend of the grid's columns; the main job's `render.display_size`); 0
    /// leaves them out.
    #[arg(long, default_value_t = 512)]
    pub display_size: usize,
    /// Folder of the ONNX models.
    #[arg(long, default_value = "models")]
    pub models_dir: PathBuf,
    /// Folder for temporal.md, temporal.json and temporal.png.
    #[arg(long, default_value = "docs/eval-video")]
    pub out: PathBuf,
    /// JSON Lines on stdout (one object per row).
    #[arg(long)]
    pub json: bool,
    /// Write temporal.md and temporal.png again from OUT/temporal.json (no measurement).
    #[arg(long)]
    pub replot: bool,
}

/// One scene's frame with its truth.
struct VFrame {
    rgb: Vec<u8>,
    /// The true person mask, letterboxed as the networks see the frame (`[S, S]`, > 0.5).
    truth_mask: Vec<bool>,
    width: usize,
    height: usize,
    gt_mesh: Mesh,
    oracle: volcap_sim::oracle::SceneField,
    to_cam: ToCamera,
    /// The first subject's body parts ([`parts`]).
    parts: volcap_sim::parts::PartLabeler,
}

/// Coarsest level of the truth's localization (33^3: 0.06 NDC, thinner than any body part).
const TRUTH_COARSE_LEVEL: u32 = 5;

/// Side of the camera-frame rasters (input NDC [-1, 1]^2).
const RASTER: usize = 256;

/// A frame's views: first-hit grid indices in the crop's cube (front: along depth, per
/// column `j n + i`; side: along x, per `j n + k`; -1 where nothing is hit) and the same
/// in the camera frame on [`RASTER`]^2 rasters (metres; `None` where nothing is hit).
struct Views {
    front: Vec<i32>,
    side: Vec<i32>,
    cam_front: Vec<Option<f32>>,
    cam_side: Vec<Option<f32>>,
    /// Per column of `front` / `side`, the body part of its hit ([`parts::label`]; empty
    /// until labelled).
    front_part: Vec<u8>,
    side_part: Vec<u8>,
    /// The silhouettes as displayed, each pixel's coverage with the outline antialiased
    /// ([`display::coverage`]; empty unless drawn).
    front_display: Vec<f32>,
    side_display: Vec<f32>,
}

/// Metres per input-NDC unit across (x, y) and along depth (after `to_cam`).
fn metres_per_ndc(fr: &VFrame) -> (f32, f32) {
    let cam = fr.oracle.camera.projector();
    let o = cam.ndc_to_world(Vec3::ZERO);
    (
        (cam.ndc_to_world(Vec3::X) - o).length(),
        (cam.ndc_to_world(Vec3::Z) - o).length(),
    )
}

fn views(grid: &Grid, spec: GridSpec, crop: Crop, fr: &VFrame) -> Views {
    let n = spec.n();
    let plane = n * n;
    let (mut front, mut side) = (vec![-1i32; plane], vec![-1i32; plane]);
    for k in 0..n {
        for j in 0..n {
            let row = &grid.values[j * n + k * plane..j * n + k * plane + n];
            for (i, &v) in row.iter().enumerate() {
                if is_inside(v) {
                    if front[j * n + i] < 0 {
                        front[j * n + i] = k as i32;
                    }
                    if side[j * n + k] < 0 {
                        side[j * n + k] = i as i32;
                    }
                }
            }
        }
    }
    let (mxy, mz) = metres_per_ndc(fr);
    let px = |ndc: f32| -> Option<usize> {
        let p = ((ndc + 1.0) * 0.5 * (RASTER - 1) as f32).round();
        (p >= 0.0 && p <= (RASTER - 1) as f32).then_some(p as usize)
    };
    let mut cam_front = vec![None; RASTER * RASTER];
    let mut cam_side = vec![None; RASTER * RASTER];
    let keep = |slot: &mut Option<f32>, d: f32| {
        if slot.is_none_or(|o| d < o) {
            *slot = Some(d);
        }
    };
    for j in 0..n {
        for i in 0..n {
            let u = Vec3::new(spec.coord(i), spec.coord(j), 0.0);
            if let Ok(k) = usize::try_from(front[j * n + i]) {
                let p = fr
                    .to_cam
                    .apply(crop.to_input(Vec3::new(u.x, u.y, spec.coord(k))));
                if let (Some(x), Some(y)) = (px(p.x), px(p.y)) {
                    keep(&mut cam_front[y * RASTER + x], p.z * mz);
                }
            }
        }
        for k in 0..n {
            if let Ok(i) = usize::try_from(side[j * n + k]) {
                let p = fr.to_cam.apply(crop.to_input(Vec3::new(
                    spec.coord(i),
                    spec.coord(j),
                    spec.coord(k),
                )));
                if let (Some(z), Some(y)) = (px(p.z), px(p.y)) {
                    keep(&mut cam_side[y * RASTER + z], p.x * mxy);
                }
            }
        }
    }
    Views {
        front,
        side,
        cam_front,
        cam_side,
        front_part: Vec::new(),
        side_part: Vec::new(),
        front_display: Vec::new(),
        side_display: Vec::new(),
    }
}

fn mean(v: &[f64]) -> f64 {
    if v.is_empty() {
        f64::NAN
    } else {
        v.iter().sum::<f64>() / v.len() as f64
    }
}

fn min(v: &[f64]) -> f64 {
    v.iter().copied().fold(f64::NAN, f64::min)
}

/// Lines of a scene's frames and truth.
fn render_scene(
    path: &Path,
    frames: u64,
    depth: DepthFrame,
) -> anyhow::Result<(Vec<VFrame>, f64, bool)> {
    let scene = Scene::load(path).map_err(|e| anyhow!("{e}"))?;
    let still = scene
        .subjects
        .iter()
        .all(|s| matches!(s.motion, MotionSpec::Static { .. }));
    let fps = scene.camera.fps.0 as f64;
    let z_scale = scene.camera.height_m.0 / volcap_sim::dataset::WHOLE_HEIGHT_M;
    let assets = Arc::new(volcap_sim::HumanAssets::embedded().map_err(anyhow::Error::msg)?);
    let vertex_parts = volcap_sim::parts::vertex_parts(&assets);
    let mut sim = Simulator::new(scene, assets).with_context(|| path.display().to_string())?;
    let mut out = Vec::new();
    for i in 0..frames {
        let f = sim.render(i)?;
        let oracle = sim.oracle(volcap_sim::oracle::DEFAULT_VOXEL_M);
        let dz = match depth {
            DepthFrame::Camera => 0.0,
            DepthFrame::Body => volcap_sim::rays::ray_intervals(
                &oracle.oracle,
                &f.camera,
                volcap_sim::rays::DEFAULT_STEP_M,
            )
            .mean_depth()
            .unwrap_or(0.0),
        };
        let truth_rgb: Vec<u8> = f.person_mask().iter().flat_map(|&m| [m; 3]).collect();
        let truth = volcap_engine::model::preprocess::letterbox(&truth_rgb, f.width, f.height);
        let plane = volcap_engine::model::preprocess::INPUT_SIZE.pow(2);
        let parts = {
            let meshes = sim.world_meshes();
            let body = meshes
                .first()
                .and_then(|(closed, _)| closed.first())
                .ok_or_else(|| anyhow!("{}: the scene has no subject", path.display()))?;
            volcap_sim::parts::PartLabeler::new(body.verts, body.tris, &vertex_parts)
        };
        out.push(VFrame {
            truth_mask: truth[..plane].iter().map(|&v| v > 0.5).collect(),
            gt_mesh: volcap_sim::dataset::clothed_surface(&sim),
            oracle,
            rgb: f.rgb,
            width: f.width,
            height: f.height,
            to_cam: ToCamera { dz, z_scale },
            parts,
        });
    }
    Ok((out, fps, still))
}

pub fn run(a: &TemporalArgs) -> anyhow::Result<()> {
    if a.replot {
        let path = a.out.join("temporal.json");
        let text = std::fs::read_to_string(&path).with_context(|| path.display().to_string())?;
        let rows: Vec<VideoRow> =
            serde_json::from_str(&text).with_context(|| path.display().to_string())?;
        return write(a, &rows);
    }
    let spec = GridSpec::from_resolution(a.res).with_context(|| format!("--res {}", a.res))?;
    let coarse = a.coarse_level.min(spec.level());
    let apart = volcap_engine::pieces::gap_setting(a.drop_apart)
        .map_err(|e| anyhow!("--drop-apart {e}"))?;
    let settings = a
        .settings
        .iter()
        .map(|s| parse_setting(s))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let (name, prec) = match a.model.split_once('@') {
        Some((n, p)) => (n, Precision::parse(p).map_err(anyhow::Error::msg)?),
        None => (a.model.as_str(), Precision::F32),
    };
    // The networks once per smoothing the settings ask for (a model's passes are set at
    // load).
    let mut by_smooth: Vec<(u8, Models)> = Vec::new();
    for st in &settings {
        if by_smooth.iter().all(|(p, _)| *p != st.map_smooth) {
            let (m, _) = Models::load(&a.models_dir, name, prec)?.with_map_smooth(st.map_smooth);
            by_smooth.push((st.map_smooth, m));
        }
    }
    let models_for = |passes: u8| {
        by_smooth
            .iter()
            .find(|(p, _)| *p == passes)
            .map(|(_, m)| m)
            .ok_or_else(|| anyhow!("no networks loaded for map_smooth = {passes}"))
    };
    let depth = match settings.first() {
        Some(st) => frame_of(FrameArg::Auto, models_for(st.map_smooth)?, None),
        None => bail!("bench temporal: no --setting"),
    };
    let pb = ProgressBar::new((a.scenes.len() * settings.len()) as u64 * a.frames);
    pb.set_style(
        ProgressStyle::with_template("{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    // One localizer per field: a localizer keeps state between runs of the same field.
    let (mut loc, mut loc_truth) = (Localizer::new(), Localizer::new());
    let (mut grid, mut truth) = (Grid::new(spec), Grid::new(spec));
    let mut rows = Vec::new();
    for path in &a.scenes {
        let label = path
            .file_stem()
            .map(|s| s.to_string_lossy().to_string())
            .unwrap_or_default();
        pb.set_message(format!("{label}: rendering"));
        let (frames, fps, still) = render_scene(path, a.frames, depth)?;
        let (mxy, mz) = frames.first().map(metres_per_ndc).unwrap_or((1.0, 1.0));
        // The unfiltered run's views, the reference of the filtered runs' lag.
        let mut unfiltered: Option<Vec<Option<Views>>> = None;
        for st in &settings {
            let (setting, ts) = (&st.label, &st.filter);
            let models = models_for(st.map_smooth)?;
            pb.set_message(format!("{label}: {setting}"));
            let mut temporal = ts.map(Temporal::new);
            loc.forget_sides();
            let mut held = Vec::new();
            let mut track = SegmentTrack::new(st.segment_full_every);
            // Per frame: the model's views, the truth's, and the crop (the display's frame:
            // a crop that moves moves the person on the display).
            let mut per: Vec<Option<(Views, Views, Crop)>> = Vec::new();
            let (mut chamfer, mut p2s, mut iou) = (Vec::new(), Vec::new(), Vec::new());
            let (mut mask_iou, mut segment_ms, mut tracked) = (Vec::new(), Vec::new(), [0usize; 2]);
            for (i, fr) in frames.iter().enumerate() {
                pb.inc(1);
                let t = i as f64 / fps;
                let mut info = FrameInfo::default();
                let prepared = models.prepare_tracked(
                    &fr.rgb,
                    fr.width,
                    fr.height,
                    &mut info,
                    Some(&mut track),
                );
                segment_ms.push(info.segment_ms);
                match info.tracked {
                    Tracked::Crop => tracked[0] += 1,
                    Tracked::Lost => tracked[1] += 1,
                    Tracked::Off | Tracked::Full => {}
                }
                let Ok((img, mut mask, crop)) = prepared else {
                    if let Some(tf) = temporal.as_mut() {
                        tf.reset();
                    }
                    per.push(None);
                    continue;
                };
                mask_iou.push(volcap_engine::metrics::mask_iou(
                    mask.iter().zip(&fr.truth_mask).map(|(&m, &t)| (m > 0.5, t)),
                ));
                let crop = match temporal.as_mut() {
                    Some(tf) => tf.steady_input(t, info.people, &mut mask, crop).0,
                    None => Some(crop),
                };
                let Some(crop) = crop else {
                    per.push(None);
                    continue;
                };
                let field = models.encode_steady(
                    &img,
                    &mask,
                    crop,
                    ModelView::default(),
                    temporal.as_mut(),
                )?;
                let band = ts.map_or(0.0, |t| t.surface_dead_band);
                loc.hold_sides(band, Some(field.alignment_key()));
                loc.run(Method::Hierarchical, &field, spec, coarse, &mut grid)?;
                held.push(loc.held_sides());
                if let Some(f) = apart {
                    let gap = volcap_engine::pieces::gap_points(spec, f);
                    volcap_engine::pieces::drop_apart(&mut grid, [gap; 3]);
                }
                let oracle = OracleInCrop {
                    oracle: &fr.oracle,
                    crop,
                    to_cam: fr.to_cam,
                };
                loc_truth.run(
                    Method::Hierarchical,
                    &oracle,
                    spec,
                    TRUTH_COARSE_LEVEL.min(spec.level()),
                    &mut truth,
                )?;
                iou.push(iou_bits(&grid.binarized(), &truth.binarized()));
                let mesh = volcap_engine::mesh::marching_cubes(&grid);
                if let Some(d) =
                    surface_distances(mesh, crop, fr.to_cam, &fr.oracle, &fr.gt_mesh, None)
                {
                    chamfer.push(d.chamfer_cm);
                    p2s.push(d.p2s_cm);
                }
                let mut v = views(&grid, spec, crop, fr);
                parts::label(&mut v, spec, crop, fr);
                if still {
                    let size = a.display_size;
                    v.front_display =
                        display::coverage(&grid, &v.front, display::Along::Depth, size);
                    v.side_display = display::coverage(&grid, &v.side, display::Along::X, size);
                }
                per.push(Some((v, views(&truth, spec, crop, fr), crop)));
            }
            // Consecutive pairs of reconstructed frames.
            let cell = spec.spacing() as f64 * 100.0;
            let (mut fi, mut si, mut fd, mut sd, mut jf, mut js) =
                (vec![], vec![], vec![], vec![], vec![], vec![]);
            let mut by_part = parts::PartFlicker::default();
            let (mut fdi, mut sdi, mut fda, mut sda) = (vec![], vec![], vec![], vec![]);
            let moved = |k: usize| match (per.get(k), per.get(k + 1)) {
                (Some(Some((_, _, c0))), Some(Some((_, _, c1)))) => {
                    Some(compare::crop_move_cells(c0, c1, spec.n()))
                }
                _ => None,
            };
            let mut crop_moves = Vec::new();
            for (k, w) in per.windows(2).enumerate() {
                let (Some((m0, o0, c0)), Some((m1, o1, c1))) = (&w[0], &w[1]) else {
                    continue;
                };
                if k + 1 < a.settle {
                    continue;
                }
                by_part.add(m0, m1, k);
                crop_moves.extend(moved(k));
                if !m0.side_display.is_empty() {
                    let iou = |a: &[f32], b: &[f32]| {
                        let (a, b) = (display::shown(a), display::shown(b));
                        volcap_engine::metrics::mask_iou(a.into_iter().zip(b))
                    };
                    fdi.push(iou(&m0.front_display, &m1.front_display));
                    sdi.push(iou(&m0.side_display, &m1.side_display));
                    fda.push(display::soft_iou(&m0.front_display, &m1.front_display));
                    sda.push(display::soft_iou(&m0.side_display, &m1.side_display));
                }
                let s = 0.5 * (c0.s + c1.s) as f64;
                let (a, d) = compare_hits(&m0.front, &m1.front);
                fi.push(a);
                fd.push(d * cell * s * mz as f64 * frames[0].to_cam.z_scale as f64);
                let (a, d) = compare_hits(&m0.side, &m1.side);
                si.push(a);
                sd.push(d * cell * s * mxy as f64);
                let (_, dm) = compare_raster(&m0.cam_front, &m1.cam_front);
                let (_, dorc) = compare_raster(&o0.cam_front, &o1.cam_front);
                jf.push((dm - dorc) * 100.0);
                let (_, dm) = compare_raster(&m0.cam_side, &m1.cam_side);
                let (_, dorc) = compare_raster(&o0.cam_side, &o1.cam_side);
                js.push((dm - dorc) * 100.0);
            }
            // Lag: the shift that best lines this run's camera-frame silhouettes up with
            // the unfiltered run's earlier ones (the `off` setting of the same frames: no
            // filter lag by definition), or with the truth's when `off` is not measured.
            let reference: Vec<Option<&Views>> = match &unfiltered {
                Some(u) => u.iter().map(|v| v.as_ref()).collect(),
                None => per.iter().map(|p| p.as_ref().map(|(_, o, _)| o)).collect(),
            };
            let lag = if ts.is_none() {
                0
            } else {
                lag_of(&per, &reference)
            };
            let (part_iou_mean, part_iou_min, part_change_share, part_worst_side_share) =
                by_part.figures();
            let worst = by_part.worst_pair();
            // The pair's cells along depth to cm: its crop's scale, as the depth change.
            let cm = |frame: usize| {
                let s = per
                    .get(frame)
                    .and_then(|p| p.as_ref())
                    .map_or(1.0, |p| p.2.s as f64);
                cell * s * mz as f64 * frames[0].to_cam.z_scale as f64
            };
            let (part_worst_side_edges, part_worst_side_run_cm, part_worst_side_outline) =
                edges::pair_figures(worst, spec.n(), cm);
            let worst_front = by_part.worst_front();
            if still {
                let file = format!("{label}-{}.png", edges::file_safe(setting));
                if let Some(w) = worst {
                    edges::draw_pair(&a.out.join("worst-side"), &file, w, spec.n())?;
                }
                if let Some((w, _)) = worst_front {
                    edges::draw_pair(&a.out.join("worst-front"), &file, w, spec.n())?;
                }
            }
            let row = VideoRow {
                scene: label.clone(),
                kind: if still { "still" } else { "moving" }.into(),
                setting: setting.clone(),
                frames: per.len(),
                failed: per.iter().filter(|p| p.is_none()).count(),
                front_iou_mean: mean(&fi),
                front_iou_min: min(&fi),
                side_iou_mean: mean(&si),
                side_iou_min: min(&si),
                front_depth_change_cm: mean(&fd),
                side_depth_change_cm: mean(&sd),
                chamfer_cm: mean(&chamfer),
                p2s_cm: mean(&p2s),
                iou: mean(&iou),
                front_jitter_cm: mean(&jf),
                side_jitter_cm: mean(&js),
                lag_frames: lag,
                resets: temporal.as_ref().map_or(0, |t| t.resets),
                mask_iou: mean(&mask_iou),
                segment_ms: mean(&segment_ms),
                tracked_frames: tracked[0],
                lost_frames: tracked[1],
                part_iou_mean,
                part_iou_min,
                part_change_share,
                part_worst_side_share,
                worst_side_frame: worst.map(|w| w.frame),
                part_worst_side_edges,
                part_worst_side_run_cm,
                part_worst_side_outline,
                worst_front_frame: worst_front.map(|(w, _)| w.frame),
                part_worst_front_share: worst_front.map_or([None; parts::PARTS], |(_, s)| s),
                crop_move_cells: (!crop_moves.is_empty()).then(|| {
                    (
                        mean(&crop_moves),
                        crop_moves.iter().copied().fold(0.0, f64::max),
                    )
                }),
                worst_side_crop_move: worst.and_then(|w| moved(w.frame)),
                worst_front_crop_move: worst_front.and_then(|(w, _)| moved(w.frame)),
                front_display_iou: (!fdi.is_empty()).then(|| (mean(&fdi), min(&fdi))),
                side_display_iou: (!sdi.is_empty()).then(|| (mean(&sdi), min(&sdi))),
                front_display_aa_iou: (!fda.is_empty()).then(|| (mean(&fda), min(&fda))),
                side_display_aa_iou: (!sda.is_empty()).then(|| (mean(&sda), min(&sda))),
                held_sides: held.iter().sum::<u64>() as f64 / held.len().max(1) as f64,
            };
            if a.json {
                println!("{}", serde_json::to_string(&row)?);
            }
            rows.push(row);
            if ts.is_none() && st.segment_full_every <= 1 {
                unfiltered = Some(per.into_iter().map(|p| p.map(|(m, _, _)| m)).collect());
            }
        }
    }
    pb.finish_and_clear();
    write(a, &rows)
}

/// temporal.md, temporal.json and temporal.png into `a.out`; the table on stdout unless
/// `--json`.
fn write(a: &TemporalArgs, rows: &[VideoRow]) -> anyhow::Result<()> {
    let rows = rows.to_vec();
    std::fs::create_dir_all(&a.out).with_context(|| a.out.display().to_string())?;
    let md = report(a, &rows);
    std::fs::write(a.out.join("temporal.md"), &md)?;
    std::fs::write(
        a.out.join("temporal.json"),
        serde_json::to_string_pretty(&rows)?,
    )?;
    plot(&rows, &a.out.join("temporal.png"))?;
    if !a.json {
        print!("{md}");
    }
    Ok(())
}

#[cfg(test)]
mod tests;
