//! The evaluation's report: the Markdown tables (models side by side, per part, per image);
//! the accuracy-against-time table and plot are `tradeoff`'s.

use super::{EvalArgs, Framing, ImageRow, mean, worst10};
use serde::Serialize;
use std::fmt::Write as _;
use std::path::Path;

/// One model's summary line of the report (its table row, its JSON object).
#[derive(Debug, Clone, Serialize)]
pub struct ModelRow {
    pub model: String,
    /// "mlp" (encoder + point MLP) or "fourier".
    pub family: String,
    /// The depth frame of the comparison: "camera" or "body" (see `--depth-frame`).
    pub depth_frame: String,
    /// The series level read as the surface (Fourier models: `--iso-level` or the file's
    /// `volcap.iso_level`; none for the other families and the ground-truth rows).
    pub iso_level: Option<f32>,
    pub images: usize,
    pub failed: usize,
    pub chamfer_cm: f64,
    pub p2s_cm: f64,
    pub worst10_chamfer_cm: f64,
    pub worst10_p2s_cm: f64,
    pub iou: f64,
    pub mask_iou: f64,
    pub evaluations: f64,
    pub segment_ms: f64,
    pub encode_ms: f64,
    pub localize_ms: f64,
    /// segment + encode + localize (the per-frame cost without meshing).
    pub frame_ms: f64,
    pub gmacs_frame: Option<f64>,
    pub macs_point: Option<f64>,
    pub params: Option<u64>,
    /// [`ImageRow::part_cm`] averaged over the images that show the part.
    pub part_cm: [f64; 6],
    /// [`ImageRow::part_p2s_cm`] averaged over the images (they add up to the P2S).
    pub part_p2s_cm: [f64; 6],
    /// [`ImageRow::part_shown`] averaged over the images that show the part.
    pub part_shown: [f64; 6],
    /// How many times each frame was segmented (`Models::segment_passes`).
    pub segment_passes: u8,
    /// Images whose reconstruction faces the wrong way ([`ImageRow::facing_error`]).
    pub facing_errors: usize,
    /// Chamfer, P2S and IoU over the reconstructed images that face the right way: what the
    /// facing errors cost the means above.
    pub facing_right: [f64; 3],
    /// [`ImageRow::colour_l1`] averaged over the images that have it (NaN: none).
    pub colour_l1: [f64; 4],
    /// The grid's resolution (`--res`).
    pub res: usize,
    /// The localization's coarsest level (`--coarse-level`, else the engine's for the grid).
    pub coarse_level: u32,
    /// The localization method (`--method`; `hierarchical`: the product's).
    pub localization: String,
    /// What ran the networks (`--backend`, `--runtime`): "tract", "onnxruntime 1.32.0",
    /// "wgpu ADAPTER".
    pub backend: String,
    /// A ground-truth series (`truth-*`): a bound, not a setting the product can run, so off
    /// the accuracy-against-time front.
    pub bound: bool,
}

impl ModelRow {
    /// One model's summary over its image rows (`card`: GMACs a frame, MACs a point and
    /// parameters from models.json). A failed image counts in the worst 10 as infinitely
    /// far; distances average over the reconstructed ones.
    pub(super) fn summarize(
        label: &str,
        depth_frame: &str,
        iso_level: Option<f32>,
        family: String,
        segment_passes: u8,
        card: (Option<f64>, Option<f64>, Option<u64>),
        rows: &[ImageRow],
    ) -> Self {
        let ok: Vec<&ImageRow> = rows.iter().filter(|r| r.status == "ok").collect();
        let dist = |r: &ImageRow, f: fn(&ImageRow) -> f64| {
            if r.status == "ok" {
                f(r)
            } else {
                f64::INFINITY
            }
        };
        let all: Vec<&ImageRow> = rows.iter().collect();
        let right: Vec<&&ImageRow> = ok.iter().filter(|r| !r.facing_error).collect();
        let part = |f: fn(&ImageRow) -> [f64; 6]| -> [f64; 6] {
            std::array::from_fn(|i| mean(ok.iter().map(|r| f(r)[i]).filter(|v| v.is_finite())))
        };
        Self {
            model: label.to_string(),
            family,
            depth_frame: depth_frame.to_string(),
            iso_level,
            images: rows.len(),
            failed: rows.len() - ok.len(),
            chamfer_cm: mean(ok.iter().map(|r| r.chamfer_cm)),
            p2s_cm: mean(ok.iter().map(|r| r.p2s_cm)),
            worst10_chamfer_cm: worst10(&all, |r| dist(r, |r| r.chamfer_cm)),
            worst10_p2s_cm: worst10(&all, |r| dist(r, |r| r.p2s_cm)),
            iou: mean(rows.iter().map(|r| r.iou)),
            mask_iou: mean(rows.iter().map(|r| r.mask_iou)),
            evaluations: mean(ok.iter().map(|r| r.evaluations as f64)),
            segment_ms: mean(rows.iter().map(|r| r.segment_ms)),
            encode_ms: mean(ok.iter().map(|r| r.encode_ms)),
            localize_ms: mean(ok.iter().map(|r| r.localize_ms)),
            frame_ms: mean(
                ok.iter()
                    .map(|r| r.segment_ms + r.encode_ms + r.localize_ms),
            ),
            gmacs_frame: card.0,
            macs_point: card.1,
            params: card.2,
            part_cm: part(|r| r.part_cm),
            part_p2s_cm: part(|r| r.part_p2s_cm),
            part_shown: part(|r| r.part_shown),
            segment_passes,
            facing_errors: ok.iter().filter(|r| r.facing_error).count(),
            facing_right: [
                mean(right.iter().map(|r| r.chamfer_cm)),
                mean(right.iter().map(|r| r.p2s_cm)),
                mean(right.iter().map(|r| r.iou)),
            ],
            colour_l1: std::array::from_fn(|i| {
                mean(ok.iter().map(|r| r.colour_l1[i]).filter(|v| v.is_finite()))
            }),
            res: 0,
            coarse_level: 0,
            localization: String::new(),
            backend: String::new(),
            bound: false,
        }
    }
}

/// The options that change what was measured, as they were given (so that the report's
/// command line reproduces it): framing, mask, surface levels, the experimental readings,
/// backend.
fn knobs(a: &EvalArgs) -> String {
    let list = |v: &[f32]| {
        v.iter()
            .map(|x| x.to_string())
            .collect::<Vec<_>>()
            .join(",")
    };
    let mut k = String::new();
    if a.framing == Framing::Upper {
        let _ = write!(k, " --framing {}", a.framing.name());
    }
    if a.hands != volcap_sim::pose::Hands::Rest {
        let _ = write!(k, " --hands {}", a.hands.name());
    }
    if a.gt_mask {
        k.push_str(" --gt-mask");
    }
    if !a.iso_level.is_empty() {
        let _ = write!(k, " --iso-level {}", list(&a.iso_level));
    }
    if let Some(p) = &a.peak_level {
        let _ = write!(k, " --peak-level {}", list(p));
    }
    if let Some(m) = &a.moment_fill {
        let _ = write!(k, " --moment-fill {}", list(m));
    }
    if let Some(m) = &a.interior_level {
        let _ = write!(k, " --interior-level {}", list(m));
    }
    if let Some(m) = &a.thin_level {
        let _ = write!(k, " --thin-level {}", list(m));
    }
    match a.drop_apart {
        d if d == super::Apart::PRODUCT => {}
        super::Apart(Some(g)) => {
            let _ = write!(k, " --drop-apart {}", list(&g));
        }
        super::Apart(None) => k.push_str(" --drop-apart off"),
    }
    if !a.segment_passes.is_empty() {
        let passes: Vec<String> = a.segment_passes.iter().map(|p| p.to_string()).collect();
        let _ = write!(k, " --segment-passes {}", passes.join(","));
    }
    if !a.map_smooth.is_empty() {
        let passes: Vec<String> = a.map_smooth.iter().map(|p| p.to_string()).collect();
        let _ = write!(k, " --map-smooth {}", passes.join(","));
    }
    if a.truth_surface == super::TruthSurface::Seen {
        k.push_str(" --truth-surface seen");
    }
    if a.colour_res != 129 {
        let _ = write!(k, " --colour-res {}", a.colour_res);
    }
    let joined = |v: &[String]| v.iter().map(|x| x.trim()).collect::<Vec<_>>().join(",");
    if !a.coarse_level.is_empty() {
        let levels: Vec<String> = a.coarse_level.iter().map(|l| l.to_string()).collect();
        let _ = write!(k, " --coarse-level {}", levels.join(","));
    }
    if a.method != ["hierarchical"] {
        let _ = write!(k, " --method {}", joined(&a.method));
    }
    if a.backend != ["cpu"] {
        let _ = write!(k, " --backend {}", joined(&a.backend));
    }
    k
}

pub(super) fn report(a: &EvalArgs, summary: &[ModelRow], images: &[ImageRow]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# Evaluation: full pipeline on held-out simulator subjects\n\n\
         `volcap eval --subjects {} --poses {} --views {} --res {} --model {} --seed {}{}` (manifest `{}`, assets {}).\n\
         Pipeline: segmentation -> crop -> shape encoder -> {} localization at {}{} -> marching cubes.\n\
         Chamfer / P2S in cm against the ground-truth clothed mesh{} (10k surface samples each); IoU against the\n\
         simulator's occupancy oracle on the same grid; mask IoU of the segmentation; worst-10 = mean of the 10\n\
         worst images (a failed image counts as infinitely far). Times are per frame on this machine.\n\n\
         Depth frame: `camera` compares depth as the camera saw it; `body` first moves the truth so that\n\
         its mean occupied depth is at the crop's z = 0, where a body-frame model places the person (a\n\
         weak-perspective crop does not show where the camera stood along depth).\n",
        a.subjects.join(","),
        a.poses,
        a.views,
        a.res
            .iter()
            .map(|r| r.to_string())
            .collect::<Vec<_>>()
            .join(","),
        a.model.join(","),
        a.seed,
        knobs(a),
        a.manifest.display(),
        a.data
            .as_ref()
            .map(|p| p.display().to_string())
            .unwrap_or_else(|| "embedded pack".into()),
        a.method
            .iter()
            .map(|m| m.trim())
            .collect::<Vec<_>>()
            .join(" / "),
        a.res
            .iter()
            .map(|r| format!("{r}^3"))
            .collect::<Vec<_>>()
            .join(" / "),
        if a.drop_apart.0.is_some() {
            " -> pieces apart from the body dropped"
        } else {
            ""
        },
        if a.truth_surface == super::TruthSurface::Seen {
            ", only what a view can show (`--truth-surface seen`: the body under the clothes left out)"
        } else {
            " (the body under the clothes included)"
        },
    );
    if a.framing == Framing::Upper {
        let _ = writeln!(
            s,
            "Framing `upper`: a person close to the camera, the frame's lower edge between the hips and the\n\
             knees (weak perspective spanning {:.1} to {:.1} m, top at {:.2} m above the floor). The truth is\n\
             what the frame shows: the oracle and the ground-truth surface below the edge are left out, and\n\
             so is the reconstruction's surface there.\n",
            super::framing::UPPER_SPAN_M.0,
            super::framing::UPPER_SPAN_M.1,
            super::framing::UPPER_TOP_M,
        );
    }
    if a.hands == volcap_sim::pose::Hands::Varied {
        let _ = writeln!(
            s,
            "Hands `varied`: the same images' bodies, views and framing with drawn forearm twists, wrist\n\
             flexions and finger curls (open hand to fist; `service/sim/src/hands.rs`), not the rest pose's\n\
             open hands.\n",
        );
    }
    let _ = writeln!(
        s,
        "| model | family | params | GMACs/frame | MACs/point | ms/frame | seg ms | enc ms | localize ms | evals | Chamfer cm | P2S cm | worst-10 Chamfer | worst-10 P2S | IoU | mask IoU | failed |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    let opt =
        |v: Option<f64>, p: usize| v.map(|x| format!("{x:.p$}")).unwrap_or_else(|| "-".into());
    for m in summary {
        let _ = writeln!(
            s,
            "| {} | {}, {} frame{}{} | {} | {} | {} | {:.0} | {:.1} | {:.1} | {:.0} | {:.0} | {:.2} | {:.2} | {:.2} | {:.2} | {:.3} | {:.3} | {}/{} |",
            m.model,
            m.family,
            m.depth_frame,
            m.iso_level
                .map(|l| format!(", iso {l:.2}"))
                .unwrap_or_default(),
            if m.segment_passes > 1 {
                ", segmented twice"
            } else {
                ""
            },
            m.params
                .map(|p| p.to_string())
                .unwrap_or_else(|| "-".into()),
            opt(m.gmacs_frame, 3),
            opt(m.macs_point, 0),
            m.frame_ms,
            m.segment_ms,
            m.encode_ms,
            m.localize_ms,
            m.evaluations,
            m.chamfer_cm,
            m.p2s_cm,
            m.worst10_chamfer_cm,
            m.worst10_p2s_cm,
            m.iou,
            m.mask_iou,
            m.failed,
            m.images
        );
    }
    if summary.len() > 1 {
        super::tradeoff::tradeoff_table(&mut s, summary);
    }
    let _ = writeln!(
        s,
        "\nFor reference only (different data: RenderPeople scans, GPU-trained for days, 512x512 input): the \
         paper's Table 1 reports Chamfer about 1.3 to 1.6 cm and P2S about 1.2 to 1.5 cm for PIFu-style models \
         and MonoPort; FOF (NeurIPS 2022) reports comparable figures at real-time rates. Our numbers are on \
         MakeHuman subjects held out by identity, at the resolution above.\n"
    );
    let _ = writeln!(
        s,
        "**Per body part** (completeness): mean distance in cm from the true surface of each part (its \
         samples labelled by the nearest body vertex's bone: hands = wrist, metacarpals and fingers; \
         feet = foot and toes) to the reconstruction; a part the reconstruction misses (hands that end \
         at the wrist) shows as a large value.\n\n| model | head | torso | arms | hands | legs | feet |\n|---|---|---|---|---|---|---|"
    );
    // The six parts' cells: each value times `scale` to `digits` decimals, "-" where not finite.
    let cells = |v: &[f64; 6], scale: f64, digits: usize| {
        v.iter()
            .map(|v| {
                if v.is_finite() {
                    format!("{:.*}", digits, v * scale)
                } else {
                    "-".into()
                }
            })
            .collect::<Vec<_>>()
            .join(" | ")
    };
    for m in summary {
        let _ = writeln!(s, "| {} | {} |", m.model, cells(&m.part_cm, 1.0, 2));
    }
    let _ = writeln!(
        s,
        "\n**Per body part** (accuracy): each part's share of the P2S in cm, the reconstruction's samples \
         labelled by the body vertex nearest them, their distances to the true surface summed by part over \
         all samples (the six add up to the P2S): where spurious or misplaced surface is.\n\n\
         | model | head | torso | arms | hands | legs | feet | P2S |\n|---|---|---|---|---|---|---|---|"
    );
    for m in summary {
        let _ = writeln!(
            s,
            "| {} | {} | {:.2} |",
            m.model,
            cells(&m.part_p2s_cm, 1.0, 2),
            m.p2s_cm
        );
    }
    let _ = writeln!(
        s,
        "\n**Per body part** (shown): the share of each part's true surface samples within {:.0} cm of \
         the reconstruction, in %: how much of the part is there at all (a hand that ends at the wrist \
         shows its wrist only), where the mean distance above is led by the farthest samples.\n\n\
         | model | head | torso | arms | hands | legs | feet |\n|---|---|---|---|---|---|---|",
        super::distances::SHOWN_WITHIN_M * 100.0
    );
    for m in summary {
        let _ = writeln!(s, "| {} | {} |", m.model, cells(&m.part_shown, 100.0, 1));
    }
    let _ = writeln!(
        s,
        "\n**Facing errors**: images whose reconstruction is nearer the truth turned around in depth \
         (its surface reflected through the plane across the view axis at its mean depth: the same \
         silhouette, front and back swapped) than as it is; and the means over the images that face the \
         right way, what the facing errors cost.\n\n\
         | model | facing errors | Chamfer cm (facing right) | P2S cm (facing right) | IoU (facing right) |\n|---|---|---|---|---|"
    );
    for m in summary {
        let ok = m.images - m.failed;
        let _ = writeln!(
            s,
            "| {} | {}/{} ({:.1} %) | {:.2} | {:.2} | {:.3} |",
            m.model,
            m.facing_errors,
            ok,
            100.0 * m.facing_errors as f64 / ok.max(1) as f64,
            m.facing_right[0],
            m.facing_right[1],
            m.facing_right[2]
        );
    }
    let coloured: Vec<&ModelRow> = summary
        .iter()
        .filter(|m| m.colour_l1.iter().any(|v| v.is_finite()))
        .collect();
    if !coloured.is_empty() {
        let _ = writeln!(
            s,
            "\n**Colour of the views**: each image's field at the input view (yaw 0), turned to the side \
             (yaw 90) and to the back (yaw 180), rendered mesh-free and unshaded at {}^2, against the \
             simulator's colours from the same views at the input's exposure (its albedo times the \
             per-channel gain that best maps it onto the input view's pixels): the mean absolute RGB \
             difference (0-1) on the pixels both show. The input view takes the input's pixels (its error is the floor that \
             the input's lighting and the surface's misfit leave); the side and the back are the colour \
             networks'; the last column is the back with the input's pixels too (every point the colour \
             of the input pixel it projects to, no colour networks): what the networks must beat.\n\n\
             | model | front (input's pixels) | side | back | back, input's pixels |\n|---|---|---|---|---|",
            a.colour_res
        );
        for m in coloured {
            let _ = writeln!(
                s,
                "| {} | {:.3} | {:.3} | {:.3} | {:.3} |",
                m.model, m.colour_l1[0], m.colour_l1[1], m.colour_l1[2], m.colour_l1[3]
            );
        }
    }
    let _ = writeln!(s);
    let turntables: Vec<&ModelRow> = summary
        .iter()
        .filter(|m| !m.family.contains("truth"))
        .collect();
    if a.turntable {
        let which = if a.turntable_image == 0 {
            "The first image's".to_string()
        } else {
            format!(
                "Image {} of the per-image table's (counted from 0)",
                a.turntable_image
            )
        };
        let _ = writeln!(
            s,
            "## Turntables\n\n{which} reconstruction, rendered mesh-free at yaw 0/90/180/270 (top) \
             above the simulator's ground truth from the same views (bottom).\n"
        );
        for m in turntables {
            let _ = writeln!(
                s,
                "**{}**\n\n![{}](turntable-{}.png)\n",
                m.model, m.model, m.model
            );
        }
    }
    let _ = writeln!(
        s,
        "\n![Chamfer against time per frame](eval.png)\n\n## Per image\n"
    );
    let _ = writeln!(
        s,
        "| model | subject | pose | yaw | status | Chamfer cm | P2S cm | IoU | mask IoU | facing | evals | localize ms |\n|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for r in images {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {:.0} | {} | {:.2} | {:.2} | {:.3} | {:.3} | {} | {} | {:.0} |",
            r.model,
            r.subject,
            r.pose,
            r.yaw_deg,
            r.status,
            r.chamfer_cm,
            r.p2s_cm,
            r.iou,
            r.mask_iou,
            if r.facing_error { "reversed" } else { "" },
            r.evaluations,
            r.localize_ms
        );
    }
    s
}

/// A model's GMACs per frame, MACs per point and parameters from its card in models.json.
pub(super) fn card(models_dir: &Path, name: &str) -> (Option<f64>, Option<f64>, Option<u64>) {
    let idx = std::fs::read_to_string(models_dir.join("models.json"))
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok());
    let Some(c) = idx.as_ref().map(|v| &v[format!("shape-{name}")]) else {
        return (None, None, None);
    };
    (
        c["gmacs_frame"].as_f64(),
        c["macs_point"].as_f64(),
        c["params"].as_u64(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        a: EvalArgs,
    }

    /// The report's command line gives back the options that changed the measurement, and
    /// nothing for the defaults.
    #[test]
    fn the_reports_command_line_names_the_options_given() {
        let plain = Cli::parse_from(["eval"]).a;
        assert_eq!(knobs(&plain), "");
        let a = Cli::parse_from([
            "eval",
            "--gt-mask",
            "--iso-level",
            "0.5,0.55",
            "--moment-fill",
            "0.02,0.1,4",
            "--peak-level",
            "0.5,0.2",
            "--framing",
            "upper",
            "--hands",
            "varied",
            "--coarse-level",
            "3,4",
            "--method",
            "hierarchical,mise",
            "--backend",
            "cpu,wgpu",
        ])
        .a;
        assert_eq!(
            knobs(&a),
            " --framing upper --hands varied --gt-mask --iso-level 0.5,0.55 --peak-level 0.5,0.2 --moment-fill 0.02,0.1,4 --coarse-level 3,4 --method hierarchical,mise --backend cpu,wgpu"
        );
    }
}
