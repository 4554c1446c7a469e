//! `volcap reconstruct IMAGE... --out DIR`: the offline single-image path.
//!
//! Per image `NAME.ext`: segmentation (the most prominent person), crop, encoders, then
//! * `NAME.mask.png`: the person mask at the image's own size (0 / 255, greyscale);
//! * `NAME.glb`: the surface (hierarchical localization at `--res`, marching cubes, vertex
//!   colours from the colour field; glTF binary, metres, +Y up, +Z towards the camera);
//! * `NAME.yaw000.png` .. `NAME.yaw270.png`: mesh-free renders at yaw 0/90/180/270 about the
//!   person's crop centre, shaded, transparent background.
//!
//! Inputs: PNG or JPEG; greyscale, greyscale + alpha, RGBA and 16-bit images are converted to
//! RGB8 (alpha dropped). Refused with a message naming the file: unreadable, non-regular or
//! non-image files, files over [`MAX_FILE_BYTES`], and images over `preprocess::MAX_FRAME_SIDE` pixels a side or `MAX_FRAME_PIXELS` pixels in all (the daemon's limits, one rule for both; the
//! header is read first; nothing that large is decoded). A failed image does not stop the
//! others; the exit status is non-zero when any failed.

use anyhow::{Context, anyhow, bail};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use std::path::{Path, PathBuf};
use std::time::Instant;
use volcap_engine::grid::{Grid, GridSpec};
use volcap_engine::mesh::marching_cubes;
use volcap_engine::model::preprocess::unletterbox_mask;
use volcap_engine::model::{FrameError, FrameInfo, ModelView, Models, Precision};
use volcap_engine::render::{RenderOptions, Renderer};

#[derive(Args, Debug, Clone)]
pub struct ReconstructArgs {
    /// Images (PNG or JPEG).
    #[arg(required = true, value_name = "IMAGE")]
    pub images: Vec<PathBuf>,
    /// Output folder (created).
    #[arg(long)]
    pub out: PathBuf,
    /// Shape model: NAME or NAME@int8 (files models/shape-NAME.*).
    #[arg(long, default_value = volcap_engine::model::DEFAULT_MODEL)]
    pub model: String,
    /// Close-range shape model (e.g. `fourier-small-upper`): used instead of --model on
    /// images whose person the image's lower edge cuts (an upper body), as `volcapd`'s
    /// `[model] close_range`.
    #[arg(long, value_name = "NAME")]
    pub close_range: Option<String>,
    /// Segmentation passes: 1, or 2 to segment the person's crop again (`volcapd`'s `[model]
    /// segment_passes`); unset: as the model was trained (its file's `volcap.segment_passes`).
    #[arg(long, value_parser = segment_passes)]
    pub segment_passes: Option<u8>,
    /// Passes of smoothing across a Fourier model's map pixels, 0 to 4 (`volcapd`'s `[model]
    /// map_smooth`; 0: the maps as the network gives them).
    #[arg(long, default_value_t = volcap_engine::model::fourier::DEFAULT_SMOOTH_PASSES,
          value_parser = clap::value_parser!(u8).range(0..=volcap_engine::model::fourier::MAX_SMOOTH_PASSES as i64))]
    pub map_smooth: u8,
    /// Folder of the ONNX models.
    #[arg(long, default_value = "models")]
    pub models_dir: PathBuf,
    /// Grid resolution (2^L + 1) of the mesh; the renders are this many pixels a side.
    #[arg(long, default_value_t = 257)]
    pub res: usize,
    /// One JSON object per image on stdout (people found, mask fraction, ms per stage, files).
    #[arg(long)]
    pub json: bool,
    /// Also write a contact sheet (PNG): a row per reconstructed image with the photo, its
    /// mask and the four renders, each tile --res pixels, on grey.
    #[arg(long, value_name = "PNG")]
    pub sheet: Option<PathBuf>,
    /// Where the networks run: cpu (tract) or wgpu (the GPU backend; build with `--features
    /// wgpu`).
    #[arg(long, default_value = "cpu")]
    pub backend: String,
    /// `--backend wgpu`: the adapter, auto or a substring of its name or driver.
    #[arg(long, default_value = "auto")]
    pub adapter: String,
}

#[derive(Debug, Default, serde::Serialize)]
struct ImageReport {
    image: String,
    ok: bool,
    error: Option<String>,
    width: u32,
    height: u32,
    people: usize,
    mask_fraction: f32,
    /// The image cuts the person at its lower edge and --close-range encoded it.
    close_range: bool,
    decode_ms: f64,
    segment_ms: f64,
    encode_ms: f64,
    localize_ms: f64,
    mesh_ms: f64,
    render_ms: f64,
    triangles: usize,
    files: Vec<String>,
}

/// Largest image file read, bytes (a 40 MP PNG fits).
pub const MAX_FILE_BYTES: u64 = 256 << 20;

/// Read an image as RGB8, refusing what is not an image or too large, by name. The file is
/// read once (a regular file, bounded: `volcap_sim::files::read_regular`); its header is
/// checked against the size limits before anything is decoded.
pub fn read_rgb(path: &Path) -> anyhow::Result<(Vec<u8>, u32, u32)> {
    let bytes = volcap_sim::files::read_regular(path, MAX_FILE_BYTES)
        .map_err(|e| anyhow!("{}: cannot read: {e}", path.display()))?;
    // The format from the content, else from the name (as `ImageReader::open` does).
    let by_name = image::ImageFormat::from_path(path).ok();
    let reader = || -> anyhow::Result<_> {
        let mut r = image::ImageReader::new(std::io::Cursor::new(bytes.as_slice()))
            .with_guessed_format()
            .with_context(|| format!("{}: cannot read", path.display()))?;
        if r.format().is_none()
            && let Some(f) = by_name
        {
            r.set_format(f);
        }
        Ok(r)
    };
    let Some(format) = reader()?.format() else {
        bail!("{}: not a PNG or JPEG image", path.display());
    };
    let (w, h) = reader()?
        .into_dimensions()
        .map_err(|e| anyhow!("{}: not a readable {format:?} image: {e}", path.display()))?;
    volcap_engine::model::preprocess::check_frame_size(w as u64, h as u64)
        .map_err(|e| anyhow!("{}: {e}", path.display()))?;
    let img = reader()?
        .decode()
        .map_err(|e| anyhow!("{}: cannot decode: {e}", path.display()))?;
    Ok((img.to_rgb8().into_raw(), w, h))
}

/// `--segment-passes`: one count in the engine's range.
fn segment_passes(s: &str) -> Result<u8, String> {
    let n: u8 = s.parse().map_err(|e| format!("{s:?}: {e}"))?;
    crate::backend::check_segment_passes(&[n]).map_err(|e| e.to_string())?;
    Ok(n)
}

fn stem(path: &Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "image".into())
}

/// One row of the contact sheet: photo, mask, renders (RGBA tiles of any size).
type SheetRow = Vec<image::RgbaImage>;

#[allow(clippy::too_many_arguments)]
fn one(
    models: &Models,
    stages: &mut crate::backend::Stages,
    path: &Path,
    a: &ReconstructArgs,
    spec: GridSpec,
    rep: &mut ImageReport,
    row: &mut SheetRow,
) -> anyhow::Result<()> {
    let t = Instant::now();
    let (rgb, w, h) = read_rgb(path)?;
    rep.decode_ms = t.elapsed().as_secs_f64() * 1e3;
    (rep.width, rep.height) = (w, h);
    let (w, h) = (w as usize, h as usize);
    let name = stem(path);
    let mut info = FrameInfo::default();
    let prepared = models.prepare(&rgb, w, h, &mut info);
    (
        rep.people,
        rep.mask_fraction,
        rep.segment_ms,
        rep.close_range,
    ) = (
        info.people,
        info.mask_fraction,
        info.segment_ms,
        info.close_range,
    );
    let save = |file: String, r: image::ImageResult<()>, rep: &mut ImageReport| {
        r.with_context(|| format!("writing {}", a.out.join(&file).display()))?;
        rep.files.push(file);
        anyhow::Ok(())
    };
    // The mask is written whatever follows, an empty one included.
    let (img, mask, crop) = match prepared {
        Ok(p) => p,
        Err(FrameError::NoPerson) => {
            let file = format!("{name}.mask.png");
            let m = image::GrayImage::from_raw(w as u32, h as u32, vec![0; w * h])
                .ok_or_else(|| anyhow!("mask buffer"))?;
            save(file.clone(), m.save(a.out.join(&file)), rep)?;
            bail!("{}: no person found (mask written empty)", path.display());
        }
        Err(e) => return Err(e.into()),
    };
    let file = format!("{name}.mask.png");
    let m = image::GrayImage::from_raw(w as u32, h as u32, unletterbox_mask(&mask, w, h))
        .ok_or_else(|| anyhow!("mask buffer"))?;
    save(file.clone(), m.save(a.out.join(&file)), rep)?;
    if a.sheet.is_some() {
        let photo = image::RgbImage::from_raw(w as u32, h as u32, rgb)
            .ok_or_else(|| anyhow!("image buffer"))?;
        row.push(image::DynamicImage::ImageRgb8(photo).to_rgba8());
        row.push(image::DynamicImage::ImageLuma8(m).to_rgba8());
    }

    let t = Instant::now();
    let field = models.encode(&img, &mask, crop, ModelView::default())?;
    rep.encode_ms = t.elapsed().as_secs_f64() * 1e3;
    let t = Instant::now();
    let mut grid = Grid::new(spec);
    stages.localize(&field, spec, &mut grid)?;
    rep.localize_ms = t.elapsed().as_secs_f64() * 1e3;
    let t = Instant::now();
    // Pieces apart from the body (the network's floaters) are left out of the mesh.
    let gap = volcap_engine::pieces::gap_points(spec, volcap_engine::pieces::DEFAULT_GAP);
    volcap_engine::pieces::drop_apart(&mut grid, [gap; 3]);
    let mut mesh = marching_cubes(&grid);
    mesh.paint(&field)?;
    rep.triangles = mesh.triangles.len();
    rep.mesh_ms = t.elapsed().as_secs_f64() * 1e3;
    let file = format!("{name}.glb");
    std::fs::write(a.out.join(&file), mesh.to_glb())
        .with_context(|| format!("writing {}", a.out.join(&file).display()))?;
    rep.files.push(file);

    let t = Instant::now();
    let opts = RenderOptions {
        background: [0.0; 4],
        shade: true,
        drop_apart: Some(volcap_engine::pieces::DEFAULT_GAP),
        ..Default::default()
    };
    let mut r = Renderer::new();
    let n = spec.n() as u32;
    for yaw in crate::eval::TURNTABLE_YAWS {
        let view = ModelView {
            yaw_deg: yaw,
            ..Default::default()
        };
        // The input view's field is the one meshed above; other views are encoded anew.
        let turned;
        let field = if view == ModelView::default() {
            &field
        } else {
            turned = models.encode(&img, &mask, crop, view)?;
            &turned
        };
        stages.render(&mut r, field, spec, &opts)?;
        let tile = image::RgbaImage::from_raw(n, n, r.rgba().to_vec())
            .ok_or_else(|| anyhow!("render buffer size"))?;
        let file = format!("{name}.yaw{:03}.png", yaw as u32);
        save(file.clone(), tile.save(a.out.join(&file)), rep)?;
        if a.sheet.is_some() {
            row.push(tile);
        }
    }
    rep.render_ms = t.elapsed().as_secs_f64() * 1e3;
    Ok(())
}

pub fn reconstruct(a: &ReconstructArgs) -> anyhow::Result<()> {
    let spec = GridSpec::from_resolution(a.res).map_err(|e| anyhow!("--res {}: {e}", a.res))?;
    let (name, precision) = match a.model.split_once('@') {
        Some((n, "int8")) => (n, Precision::Int8),
        Some((_, p)) => bail!(
            "--model {}: unknown precision {p:?} (int8 or none)",
            a.model
        ),
        None => (a.model.as_str(), Precision::F32),
    };
    let (runtime, _) = crate::backend::open(&a.backend, "tract", &a.adapter)?;
    let models = Models::load_on(&a.models_dir, name, precision, &runtime)?;
    // Localization and the render where the networks run (the adapter with `--backend wgpu`).
    let mut stages = crate::backend::Stages::new(&runtime)?;
    let mut models = match &a.close_range {
        Some(close) => models.with_close_range(&a.models_dir, close)?,
        None => models,
    };
    if let Some(passes) = a.segment_passes {
        models.segment_passes = passes;
    }
    let (models, _) = models.with_map_smooth(a.map_smooth);
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {}", a.out.display()))?;
    let bar = if a.json {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(a.images.len() as u64)
    };
    bar.set_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} {msg} [{elapsed} < {eta}]")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut failed = 0usize;
    let mut names = std::collections::HashSet::new();
    let (mut row, mut rows) = (SheetRow::new(), Vec::<SheetRow>::new());
    for path in &a.images {
        bar.set_message(path.display().to_string());
        let mut rep = ImageReport {
            image: path.display().to_string(),
            ..Default::default()
        };
        row.clear();
        let r = if !names.insert(stem(path)) {
            Err(anyhow!(
                "{}: another input has the same name {:?}; its outputs would overwrite each other",
                path.display(),
                stem(path)
            ))
        } else {
            one(&models, &mut stages, path, a, spec, &mut rep, &mut row)
        };
        match r {
            Ok(()) => {
                rep.ok = true;
                rows.push(std::mem::take(&mut row));
            }
            Err(e) => {
                failed += 1;
                rep.error = Some(format!("{e:#}"));
                bar.suspend(|| eprintln!("error: {e:#}"));
            }
        }
        if a.json {
            println!("{}", serde_json::to_string(&rep)?);
        } else if rep.ok {
            bar.suspend(|| {
                println!(
                    "{}: {} people, mask {:.1} %{}, seg {:.0} ms, encode {:.0} ms, localize {:.0} ms, mesh {:.0} ms ({} triangles), renders {:.0} ms -> {}",
                    rep.image,
                    rep.people,
                    100.0 * rep.mask_fraction,
                    if rep.close_range { ", cut by the frame: close-range model" } else { "" },
                    rep.segment_ms,
                    rep.encode_ms,
                    rep.localize_ms,
                    rep.mesh_ms,
                    rep.triangles,
                    rep.render_ms,
                    a.out.display()
                )
            });
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    if let Some(path) = &a.sheet {
        write_sheet(&rows, spec.n() as u32, path)?;
    }
    if failed > 0 {
        bail!("{failed} of {} images failed", a.images.len());
    }
    Ok(())
}

/// Tiles of `tile` pixels (aspect kept, centred), a row per image, over grey.
fn write_sheet(rows: &[SheetRow], tile: u32, path: &Path) -> anyhow::Result<()> {
    let cols = rows.iter().map(|r| r.len()).max().unwrap_or(0) as u32;
    if cols == 0 {
        bail!(
            "{}: no image was reconstructed, no sheet written",
            path.display()
        );
    }
    let mut sheet = image::RgbaImage::from_pixel(
        cols * tile,
        rows.len() as u32 * tile,
        image::Rgba([128, 128, 128, 255]),
    );
    for (j, row) in rows.iter().enumerate() {
        for (i, t) in row.iter().enumerate() {
            let k = tile as f32 / t.width().max(t.height()) as f32;
            let (tw, th) = (
                ((t.width() as f32 * k).round() as u32).max(1),
                ((t.height() as f32 * k).round() as u32).max(1),
            );
            let t = image::imageops::resize(t, tw, th, image::imageops::FilterType::Triangle);
            image::imageops::overlay(
                &mut sheet,
                &t,
                (i as u32 * tile + (tile - tw) / 2) as i64,
                (j as u32 * tile + (tile - th) / 2) as i64,
            );
        }
    }
    sheet
        .save(path)
        .with_context(|| format!("writing {}", path.display()))
}
