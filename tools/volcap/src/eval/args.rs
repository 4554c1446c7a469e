//! `volcap eval`'s command line: what is evaluated, on which images, and how it is read.

use super::{Apart, Framing, parse_apart};
use anyhow::{Context, anyhow, bail};
use clap::Args;
use std::path::PathBuf;
use volcap_engine::grid::GridSpec;
use volcap_engine::localize::{Method, default_coarse};

#[derive(Args, Debug, Clone)]
pub struct EvalArgs {
    /// What runs the networks: tract, onnxruntime or auto (the daemon's `compute.runtime`;
    /// accuracy is the same on both, tests/runtimes.rs; the ms columns are the runtime's).
    #[arg(long, default_value = "tract")]
    pub runtime: String,
    /// Where the networks run, comma-separated (a row set each): cpu (with --runtime) or
    /// wgpu (the GPU backend: the networks, the series and the hierarchical localizations on
    /// the adapter; build with `--features wgpu`).
    #[arg(long, value_delimiter = ',', default_value = "cpu")]
    pub backend: Vec<String>,
    /// `--backend wgpu`: the adapter, auto or a substring of its name or driver.
    #[arg(long, default_value = "auto")]
    pub adapter: String,
    /// Human assets: a MakeHuman folder or a pack file (default: the embedded pack), so other
    /// asset folders can be evaluated.
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// The dataset manifest holding the subject identities (`volcap sim dataset` writes it;
    /// the one the committed models were trained with is models/dataset.json).
    #[arg(long, default_value = "models/dataset.json")]
    pub manifest: PathBuf,
    /// Subjects: ids from the manifest (s000,...), or `val` / `train` for a whole split.
    #[arg(long, value_delimiter = ',', default_value = "val")]
    pub subjects: Vec<String>,
    /// Poses per subject (procedural, drawn from --seed; not the training poses).
    #[arg(long, default_value_t = 2)]
    pub poses: usize,
    /// Views per pose, evenly around the subject.
    #[arg(long, default_value_t = 3)]
    pub views: usize,
    /// Grid resolutions (each 2^L + 1) for localization and meshing, comma-separated: every
    /// model gets a row per resolution (named `-rRES` when more than one is given).
    #[arg(long, value_delimiter = ',', default_value = "257")]
    pub res: Vec<usize>,
    /// Surface localization methods, comma-separated (`volcap bench localize`'s names:
    /// hierarchical, the product's; hierarchical-tight, hierarchical-no-conflict,
    /// hierarchical-unseeded, demo-faster, mise, octree-threshold[@T], dense): every model gets
    /// a row per method (named for it when more than one is given), scored against the truth
    /// as the product's is. On `--backend wgpu` the hierarchical family runs on the adapter,
    /// the others on the CPU's localizer.
    #[arg(long, value_delimiter = ',', default_value = "hierarchical")]
    pub method: Vec<String>,
    /// Models: NAME or NAME@int8 (files models/shape-NAME.*), comma-separated; `truth-kK`
    /// is the ground-truth Fourier field of order K (crop from the true mask): the Fourier
    /// family's upper bound at that truncation; `truth-cosN` the ground-truth half-range
    /// cosine series of N terms (N odd; FOF-X's basis) at the same channel count 2K + 1 = N.
    #[arg(long, value_delimiter = ',', default_value = volcap_engine::model::DEFAULT_MODEL)]
    pub model: Vec<String>,
    /// Folder of the ONNX models.
    #[arg(long, default_value = "models")]
    pub models_dir: PathBuf,
    #[arg(long, default_value_t = 100)]
    pub seed: u64,
    /// Diagnostic: crop and encode with the simulator's true person mask instead of the
    /// segmentation (separates segmentation errors from shape errors).
    #[arg(long)]
    pub gt_mask: bool,
    /// JSON Lines on stdout (one object per image, then one per model).
    #[arg(long)]
    pub json: bool,
    /// Write `turntable-MODEL.png` per model: the first image's reconstruction rendered
    /// mesh-free at yaw 0/90/180/270 above the oracle's from the same views.
    #[arg(long)]
    pub turntable: bool,
    /// `--turntable`: the image to turn, by its place in the report's per-image table
    /// (0: the first; subjects, then poses, then views). The images are drawn for the whole
    /// set, so another image of the same set is picked here, not by narrowing `--subjects`.
    #[arg(long, default_value_t = 0, requires = "turntable")]
    pub turntable_image: usize,
    /// Grid resolution of the turntable renders (pixels per tile).
    #[arg(long, default_value_t = 129)]
    pub turntable_res: usize,
    /// Grid resolution (pixels a side) of the colour columns' renders: each image's field at
    /// the input view, turned to the side and to the back, against the oracle's colours
    /// (`0`: no colour columns).
    #[arg(long, default_value_t = 129)]
    pub colour_res: usize,
    /// Folder for eval.md, eval.json and eval.png.
    #[arg(long, default_value = "docs/eval")]
    pub out: PathBuf,
    /// Draw OUT/eval.png again from OUT/eval.json (no measurement; a packed `eval.json.xz`
    /// unpacked first).
    #[arg(long)]
    pub replot: bool,
    /// Depth frame of the comparison: `auto` (each model's own, `volcap.depth_frame`: a
    /// `body` model places the person's mean depth at the crop's z = 0, so the truth is moved
    /// there too; everything else, the ground-truth rows included, as the camera saw it),
    /// or `body` / `camera` for every model.
    #[arg(long, value_enum, default_value_t = FrameArg::Auto)]
    pub depth_frame: FrameArg,
    /// Series levels read as the surface, comma-separated, each in (0, 1): every Fourier
    /// model is evaluated at each (rows `NAME-f32-iso0.40`) instead of its own
    /// `volcap.iso_level`, to calibrate or show the knob. Other families ignore it.
    #[arg(long, value_delimiter = ',')]
    pub iso_level: Vec<f32>,
    /// Experimental, Fourier models: read a pixel's surface at FRAC of its series' peak
    /// where that peak is under the surface level but at least MIN (thin parts that a
    /// smooth fit blurs under the level), `FRAC,MIN[,GATE]` (e.g. 0.5,0.2): with GATE, only
    /// on map pixels whose person mask (averaged over the pixel) reaches GATE.
    #[arg(long, value_delimiter = ',')]
    pub peak_level: Option<Vec<f32>>,
    /// Experimental, Fourier models: `MIN_LEN,MAX_LEN,AWAY`: a pixel whose series peaks under
    /// the surface level but holds at least MIN_LEN of inside (zeta; the depth range is 2),
    /// and lies AWAY map pixels beyond every pixel that decodes (or joins such a pixel), is
    /// read as one interval of its own inside length (at most MAX_LEN) at its own depth
    /// centre (`FourierMaps::with_moment_fill`; e.g. 0.02,0.1,4; the daemon's `[model]
    /// thin_parts = "moment-fill"`). Each Fourier model gets a row as predicted and one with
    /// the fill (`NAME-f32-fill...`), side by side.
    #[arg(long, value_delimiter = ',')]
    pub moment_fill: Option<Vec<f32>>,
    /// Experimental, Fourier models: `LEVEL,ERODE`: the surface read at LEVEL instead of the
    /// model's own on the map pixels inside the person mask eroded by ERODE map pixels
    /// (`FourierMaps::with_level_in`; the silhouette's blurred halo keeps the model's level).
    #[arg(long, value_delimiter = ',')]
    pub interior_level: Option<Vec<f32>>,
    /// Experimental, Fourier models: `LEVEL,RADIUS`: the surface read at LEVEL instead of the
    /// model's own on the thin parts only: the person mask's map pixels that an opening by
    /// RADIUS map pixels removes (hands, wrists, arms edge-on; `fourier::thin_gate`).
    #[arg(long, value_delimiter = ',')]
    pub thin_level: Option<Vec<f32>>,
    /// Segmentation passes, comma-separated, each 1 or 2 (`Models::person_mask`; the
    /// daemon's `[model] segment_passes`): 2 segments the person's crop again. Every model
    /// gets a row per value, side by side, named for the count where it is not the one the
    /// model was trained on (`NAME-f32-seg2`, `NAME-f32-seg1`). Unset: each model as it was
    /// trained (its file's `volcap.segment_passes`), as `volcapd` runs it.
    #[arg(long, value_delimiter = ',')]
    pub segment_passes: Vec<u8>,
    /// Fourier models: passes of smoothing across the maps' pixels, comma-separated, each 0
    /// to 4 (`FourierMaps::smoothed`; the daemon's `[model] map_smooth`). Every Fourier model
    /// gets a row per value, side by side, named `-sN` where it is not the engine's default
    /// (`fourier::DEFAULT_SMOOTH_PASSES`). Unset: the default, as `volcapd` runs it.
    #[arg(long, value_delimiter = ',')]
    pub map_smooth: Vec<u8>,
    /// Localization's coarsest levels (`2^l + 1` points a side; the boards' `render.coarse_level`
    /// is 4), comma-separated (a row each, named `-cL` when more than one is given): unset,
    /// the engine's for the grid (3 at 257^3: 9^3 seeds).
    #[arg(long, value_delimiter = ',')]
    pub coarse_level: Vec<u32>,
    /// Framing of the test images: `whole` (the whole person in the frame, as the dataset) or
    /// `upper` (a person close to the camera, cut by the frame's lower edge between the hips
    /// and the knees: a webcam's view, where a close-range model takes over). Either way the
    /// truth is what the frame shows: the oracle and the ground-truth surface outside it are
    /// left out.
    #[arg(long, value_enum, default_value_t = Framing::Whole)]
    pub framing: Framing,
    /// The test people's hands: `rest` (the rest pose's, as every report before 2026-12-02)
    /// or `varied` (the same images' poses with drawn forearm twists, wrist flexions and finger
    /// curls, from a stream of their own: the bodies, views and framing are `rest`'s).
    #[arg(long, default_value = "rest")]
    pub hands: volcap_sim::pose::Hands,
    /// The true surface Chamfer, P2S and the per-part distances are measured against:
    /// `clothed` (the body and its garments' meshes whole, the body under the clothes
    /// included, as every report before 2026-11-29 was) or `seen` (only what a view can show:
    /// `distances::seen_surface`).
    #[arg(long, value_enum, default_value_t = TruthSurface::Clothed)]
    pub truth_surface: TruthSurface,
    /// `XY,Z`: drop inside pieces farther than XY across and Z in depth (fractions of the
    /// grid's side) from the largest before IoU and mesh, as the product does (`pieces`; the
    /// render and the meshes at `pieces::DEFAULT_GAP` on every axis, the default here; its
    /// time in the mesh column); `off` keeps every piece.
    #[arg(long, default_value = "0.1,0.1", value_parser = parse_apart)]
    pub drop_apart: Apart,
}

#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum TruthSurface {
    Clothed,
    Seen,
}

#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameArg {
    Auto,
    Body,
    Camera,
}

/// One grid of `--res` x `--coarse-level`: its spec, the coarse level it starts from (the
/// engine's default for the grid where none is given) and the rows' name parts.
pub(super) struct GridKnob {
    pub spec: GridSpec,
    pub coarse: u32,
    pub label: String,
    pub coarse_label: String,
}

/// The grids `--res` and `--coarse-level` name, each checked (a resolution 2^L + 1, a coarse
/// level within it) with the flag and value in the error.
pub(super) fn grid_knobs(a: &EvalArgs) -> anyhow::Result<Vec<GridKnob>> {
    let coarse: Vec<Option<u32>> = if a.coarse_level.is_empty() {
        vec![None]
    } else {
        a.coarse_level.iter().map(|&l| Some(l)).collect()
    };
    fn twice<T: PartialEq + Copy>(v: &[T]) -> Option<T> {
        (1..v.len()).find(|&i| v[..i].contains(&v[i])).map(|i| v[i])
    }
    if let Some(r) = twice(&a.res) {
        bail!("--res {r}: given twice");
    }
    if let Some(l) = twice(&a.coarse_level) {
        bail!("--coarse-level {l}: given twice");
    }
    let mut out = Vec::new();
    for &r in &a.res {
        let spec = GridSpec::from_resolution(r).with_context(|| format!("--res {r}"))?;
        for &l in &coarse {
            let l = l.unwrap_or_else(|| default_coarse(spec));
            volcap_engine::localize::check_coarse(spec, l)
                .map_err(|e| anyhow!("--coarse-level {l} at --res {r}: {e}"))?;
            out.push(GridKnob {
                spec,
                coarse: l,
                label: if a.res.len() > 1 {
                    format!("-r{r}")
                } else {
                    String::new()
                },
                coarse_label: if coarse.len() > 1 {
                    format!("-c{l}")
                } else {
                    String::new()
                },
            });
        }
    }
    if out.is_empty() {
        bail!("--res: at least one grid resolution");
    }
    Ok(out)
}

/// `--method`'s localization methods (`octree-threshold` expands to its thresholds), each
/// once.
pub(super) fn methods_of(given: &[String]) -> anyhow::Result<Vec<Method>> {
    let mut out: Vec<Method> = Vec::new();
    for m in Method::parse_list(given).map_err(|e| anyhow!("--method: {e}"))? {
        if !out.contains(&m) {
            out.push(m);
        }
    }
    if out.is_empty() {
        bail!("--method: at least one localization method");
    }
    Ok(out)
}
