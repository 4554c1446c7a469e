//! The test images of `volcap eval`: held-out subjects from the manifest rendered by the
//! simulator with their ground truth (clothed mesh, occupancy oracle, ray intervals, body
//! parts).

use super::EvalArgs;
use anyhow::{Context, anyhow, bail};
use rand::{Rng, SeedableRng};
use std::path::Path;
use std::sync::Arc;
use volcap_engine::mesh::Mesh;
use volcap_sim::pose::Style;
use volcap_sim::scene::Scene;
use volcap_sim::sim::Simulator;

pub(super) struct Case {
    pub(super) subject: String,
    pub(super) pose: usize,
    pub(super) yaw: f32,
    pub(super) rgb: Vec<u8>,
    pub(super) mask: Vec<u8>,
    pub(super) size: usize,
    /// Ground truth: world mesh (clothed, or with `--truth-surface seen` only what a view can
    /// show), occupancy oracle, the frame's camera.
    pub(super) gt_mesh: Mesh,
    pub(super) oracle: volcap_sim::oracle::SceneField,
    /// Inside intervals along every pixel ray (the Fourier ground truth).
    pub(super) rays: volcap_sim::rays::RayIntervals,
    /// The frame's height span over the dataset's ([`ToCamera`]).
    pub(super) z_scale: f32,
    /// Body part of a point of the true surface.
    pub(super) parts: volcap_sim::parts::PartLabeler,
}

fn subjects(a: &EvalArgs) -> anyhow::Result<Vec<(String, String)>> {
    let text = std::fs::read_to_string(&a.manifest)
        .with_context(|| format!("{}: cannot read the dataset manifest", a.manifest.display()))?;
    let m: serde_json::Value = serde_json::from_str(&text)
        .with_context(|| format!("{}: not JSON", a.manifest.display()))?;
    let tables = m["subject_tables"]
        .as_object()
        .ok_or_else(|| anyhow!("{}: no subject_tables", a.manifest.display()))?;
    let split = m["split"].as_object();
    let mut out = Vec::new();
    for want in &a.subjects {
        let ids: Vec<&String> = if want == "val" || want == "train" {
            let mut v: Vec<&String> = tables
                .keys()
                .filter(|id| split.and_then(|s| s.get(*id)).and_then(|v| v.as_str()) == Some(want))
                .collect();
            v.sort();
            v
        } else {
            vec![tables.keys().find(|k| *k == want).ok_or_else(|| {
                anyhow!(
                    "--subjects: {want:?} is not in {} (ids: {})",
                    a.manifest.display(),
                    tables.keys().cloned().collect::<Vec<_>>().join(", ")
                )
            })?]
        };
        for id in ids {
            let t = tables[id].as_str().unwrap_or_default().to_string();
            out.push((id.clone(), t));
        }
    }
    if out.is_empty() {
        bail!("--subjects selected no subject");
    }
    Ok(out)
}

pub(super) fn render_cases(a: &EvalArgs) -> anyhow::Result<Vec<Case>> {
    let assets = Arc::new(match &a.data {
        Some(p) => volcap_sim::HumanAssets::load(p).map_err(anyhow::Error::msg)?,
        None => volcap_sim::HumanAssets::embedded().map_err(anyhow::Error::msg)?,
    });
    let subs = subjects(a)?;
    let vertex_parts = volcap_sim::parts::vertex_parts(&assets);
    let mut r = rand_chacha::ChaCha8Rng::seed_from_u64(a.seed);
    let mut cases = Vec::new();
    let size = volcap_engine::model::preprocess::INPUT_SIZE;
    for (id, table) in &subs {
        for pose in 0..a.poses {
            let style = Style::ALL[r.random_range(0..Style::ALL.len())];
            let frame: u64 = r.random_range(0..60);
            let seed = r.random::<u32>();
            let (height_m, look_y) = a.framing.camera(&mut r);
            let text = volcap_sim::dataset::scene_text_framed(
                size,
                table,
                volcap_sim::dataset::Motion::new(style, seed).with_hands(a.hands),
                height_m,
                look_y,
                volcap_sim::dataset::STUDIO_LIGHTING,
            );
            // The held-out subjects are dressed from the whole MakeHuman wardrobe; the
            // embedded pack holds the runtime's few assets.
            let hint = |e: String| {
                if a.data.is_none() {
                    anyhow!(
                        "{e} (subject {id} of {}: the embedded pack holds only the runtime's \
                         assets; pass --data with the MakeHuman folder, e.g. --data \
                         ../shared/data/makehuman)",
                        a.manifest.display()
                    )
                } else {
                    anyhow!("{e}")
                }
            };
            let scene =
                Scene::parse(&text, Path::new("<eval>")).map_err(|e| hint(e.to_string()))?;
            let mut sim =
                Simulator::new(scene, assets.clone()).map_err(|e| hint(format!("{e:#}")))?;
            for v in 0..a.views {
                let yaw = 360.0 * v as f32 / a.views as f32;
                sim.set_view_yaw(yaw);
                let f = sim.render(frame)?;
                let gt_mesh = volcap_sim::dataset::clothed_surface(&sim);
                let parts = {
                    let meshes = sim.world_meshes();
                    let body = meshes
                        .first()
                        .and_then(|(closed, _)| closed.first())
                        .ok_or_else(|| anyhow!("{id}: the scene has no subject"))?;
                    volcap_sim::parts::PartLabeler::new(body.verts, body.tris, &vertex_parts)
                };
                let oracle = sim.oracle(volcap_sim::oracle::DEFAULT_VOXEL_M);
                let gt_mesh = match a.truth_surface {
                    super::TruthSurface::Clothed => gt_mesh,
                    super::TruthSurface::Seen => {
                        super::distances::seen_surface(gt_mesh, &oracle.oracle)
                    }
                };
                let rays = volcap_sim::rays::ray_intervals(
                    &oracle.oracle,
                    &f.camera,
                    volcap_sim::rays::DEFAULT_STEP_M,
                );
                cases.push(Case {
                    subject: id.clone(),
                    pose,
                    yaw,
                    mask: f.person_mask(),
                    rgb: f.rgb.clone(),
                    size: f.width,
                    gt_mesh,
                    oracle,
                    rays,
                    z_scale: height_m / volcap_sim::dataset::WHOLE_HEIGHT_M,
                    parts,
                });
            }
        }
    }
    Ok(cases)
}
