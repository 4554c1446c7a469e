//! `bench temporal`'s report: the table per setting and per scene, and the plot.

use super::{TemporalArgs, VideoRow, mean, min};
use std::fmt::Write as _;
use std::path::Path;

/// One line per setting over all scenes: still scenes' flicker, moving scenes' accuracy,
/// jitter and lag.
#[derive(Debug, Clone)]
struct Summary {
    setting: String,
    still_side_iou_mean: f64,
    still_side_iou_min: f64,
    moving_chamfer_cm: f64,
    moving_lag_frames: f64,
    mask_iou: f64,
    segment_ms: f64,
    /// Frames segmented in the last crop alone / lost, over all scenes.
    tracked: usize,
    lost: usize,
    frames: usize,
}

fn summarize(rows: &[VideoRow]) -> Vec<Summary> {
    let mut names: Vec<&str> = Vec::new();
    for r in rows {
        if !names.contains(&r.setting.as_str()) {
            names.push(&r.setting);
        }
    }
    names
        .into_iter()
        .map(|s| {
            let of = |kind: &'static str| {
                rows.iter()
                    .filter(move |r| r.setting == s && r.kind == kind)
            };
            // The setting's rows over every scene.
            let mine = || rows.iter().filter(move |r| r.setting == s);
            let f = |v: Vec<f64>| mean(&v);
            Summary {
                setting: s.to_string(),
                still_side_iou_mean: f(of("still").map(|r| r.side_iou_mean).collect()),
                still_side_iou_min: min(&of("still").map(|r| r.side_iou_min).collect::<Vec<_>>()),
                moving_chamfer_cm: f(of("moving").map(|r| r.chamfer_cm).collect()),
                moving_lag_frames: f(of("moving").map(|r| r.lag_frames as f64).collect()),
                mask_iou: f(mine().map(|r| r.mask_iou).collect()),
                segment_ms: f(mine().map(|r| r.segment_ms).collect()),
                tracked: mine().map(|r| r.tracked_frames).sum(),
                lost: mine().map(|r| r.lost_frames).sum(),
                frames: mine().map(|r| r.frames).sum(),
            }
        })
        .collect()
}

pub(super) fn report(a: &TemporalArgs, rows: &[VideoRow]) -> String {
    let mut md = String::new();
    let _ = writeln!(
        md,
        "# A steady render: flicker, accuracy, jitter and lag per temporal setting\n\n\
         `volcap bench temporal --res {} --coarse-level {} --model {} --frames {} --settle {} --drop-apart {}` ({} scenes x {} settings). \
         Flicker is what the display shows (the crop's cube, consecutive frames; flicker and jitter leave out the first {} frames of each scene); accuracy is \
         against the simulator's truth of each frame; jitter is the model's frame-to-frame depth \
         change minus the truth's (camera frame); lag is the shift that best lines the \
         silhouettes up with the unfiltered run's (`off`). Mask IoU is the segmented person \
         (before the filter) against the true mask in the networks' input; segment ms the \
         segment stage's wall time a frame (one thread here, beside nothing else); tracked / \
         lost count the frames segmented in the last frame's crop alone and those where the \
         track lost the person (`segment_full_every`, the daemon's `[model]` key); held points \
         the grid points a frame given out as the last frame's (`surface_dead_band`).\n",
        a.res,
        a.coarse_level,
        a.model,
        a.frames,
        a.settle,
        a.drop_apart,
        a.scenes.len(),
        a.settings.len(),
        a.settle
    );
    let _ = writeln!(md, "## Per setting (means over the scenes of each kind)\n");
    let _ = writeln!(
        md,
        "| setting | still: side IoU mean | still: side IoU worst | moving: Chamfer cm | moving: lag frames | mask IoU | segment ms | tracked / lost of frames |\n|---|---|---|---|---|---|---|---|"
    );
    for s in summarize(rows) {
        let _ = writeln!(
            md,
            "| {} | {:.4} | {:.4} | {:.3} | {:.2} | {:.4} | {:.1} | {} / {} of {} |",
            s.setting,
            s.still_side_iou_mean,
            s.still_side_iou_min,
            s.moving_chamfer_cm,
            s.moving_lag_frames,
            s.mask_iou,
            s.segment_ms,
            s.tracked,
            s.lost,
            s.frames
        );
    }
    display_table(&mut md, a, rows);
    parts_table(&mut md, rows);
    edges_table(&mut md, rows);
    let _ = writeln!(md, "\n## Per scene\n");
    let _ = writeln!(
        md,
        "| scene | kind | setting | front IoU mean / worst | side IoU mean / worst | depth change front / side cm | Chamfer cm | P2S cm | IoU | jitter front / side cm | lag | resets | failed | mask IoU | segment ms | tracked / lost | held points a frame |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for r in rows {
        let _ = writeln!(
            md,
            "| {} | {} | {} | {:.4} / {:.4} | {:.4} / {:.4} | {:.3} / {:.3} | {:.3} | {:.3} | {:.4} | {:+.3} / {:+.3} | {} | {} | {} | {:.4} | {:.1} | {} / {} | {:.0} |",
            r.scene,
            r.kind,
            r.setting,
            r.front_iou_mean,
            r.front_iou_min,
            r.side_iou_mean,
            r.side_iou_min,
            r.front_depth_change_cm,
            r.side_depth_change_cm,
            r.chamfer_cm,
            r.p2s_cm,
            r.iou,
            r.front_jitter_cm,
            r.side_jitter_cm,
            r.lag_frames,
            r.resets,
            r.failed,
            r.mask_iou,
            r.segment_ms,
            r.tracked_frames,
            r.lost_frames,
            r.held_sides
        );
    }
    md
}

/// The still scenes' rows that have what a table shows (`None` when there are none).
fn still_rows(rows: &[VideoRow], has: impl Fn(&VideoRow) -> bool) -> Option<Vec<&VideoRow>> {
    let still: Vec<&VideoRow> = rows
        .iter()
        .filter(|r| r.kind == "still" && has(r))
        .collect();
    (!still.is_empty()).then_some(still)
}

/// Still scenes' flicker by body part ([`super::parts`]): per part the consecutive-frame
/// IoU of its pixels, mean / worst, its share of the changed pixels, and its share of the
/// side pixels changed in the scene's worst side pair.
fn parts_table(md: &mut String, rows: &[VideoRow]) {
    let Some(still) = still_rows(rows, |r| r.part_iou_mean.iter().any(Option::is_some)) else {
        return;
    };
    let names = volcap_sim::parts::Part::ALL.map(|p| p.name());
    let _ = writeln!(
        md,
        "\n## Still scenes: flicker by body part\n\n\
         Every displayed pixel (front and side) labelled with the body part of the true body \
         vertex nearest its hit; per part the consecutive-frame IoU of its pixels, mean / worst, \
         and (in brackets) the part's share of the pixels shown in one frame of a pair only, \
         then in the pair of the scene's worst side IoU the part's share of the side pixels \
         that pair changed. A small part's IoU moves with few pixels; the shares say where \
         the change is.\n"
    );
    let _ = writeln!(
        md,
        "| scene | setting | {} |\n|---|---|{}",
        names.join(" | "),
        "---|".repeat(names.len())
    );
    let f = |v: Option<f64>, digits: usize| v.map_or("-".to_string(), |x| format!("{x:.digits$}"));
    for r in still {
        let cells: Vec<String> = (0..names.len())
            .map(|p| {
                format!(
                    "{} / {} ({} %; worst side pair {} %)",
                    f(r.part_iou_mean[p], 4),
                    f(r.part_iou_min[p], 4),
                    f(r.part_change_share[p].map(|s| 100.0 * s), 0),
                    f(r.part_worst_side_share[p].map(|s| 100.0 * s), 0)
                )
            })
            .collect();
        let _ = writeln!(
            md,
            "| {} | {} | {} |",
            r.scene,
            r.setting,
            cells.join(" | ")
        );
    }
}

/// Still scenes' flicker as the display draws it ([`super::display`]) beside the grid
/// columns' (the figures above).
fn display_table(md: &mut String, a: &TemporalArgs, rows: &[VideoRow]) {
    let Some(still) = still_rows(rows, |r| r.side_display_iou.is_some()) else {
        return;
    };
    let _ = writeln!(
        md,
        "\n## Still scenes: flicker as displayed\n\n\
         The figures above count the grid's columns (a column shows the person or not); the \
         display draws {0} x {0} pixels from the same grid, each blending its four nearest \
         columns' values along its ray (the renderer's rule), so its edges move with the \
         values by fractions of a cell. Consecutive-frame silhouette IoU, mean / worst, and how \
         far the crop (the display's frame: the person moves on the display where it moves) \
         moved between frames, in the grid's cells (the largest of its shift across, down, and \
         its scale's move of the cube's edge). Antialiased: the outline drawn with partial \
         pixels (`render.antialias`, the main job's), the overlap of consecutive coverage maps \
         (the sum of the smaller coverage over the sum of the larger; the IoU of whole \
         pixels):\n",
        a.display_size
    );
    let _ = writeln!(
        md,
        "| scene | setting | side: columns | side: as displayed | side: antialiased | front: columns | front: as displayed | front: antialiased | crop's move, cells: mean / largest |\n|---|---|---|---|---|---|---|---|---|"
    );
    let pair = |v: Option<(f64, f64)>| v.map_or("-".into(), |(m, w)| format!("{m:.4} / {w:.4}"));
    for r in still {
        let _ = writeln!(
            md,
            "| {} | {} | {:.4} / {:.4} | {} | {} | {:.4} / {:.4} | {} | {} | {} |",
            r.scene,
            r.setting,
            r.side_iou_mean,
            r.side_iou_min,
            pair(r.side_display_iou),
            pair(r.side_display_aa_iou),
            r.front_iou_mean,
            r.front_iou_min,
            pair(r.front_display_iou),
            pair(r.front_display_aa_iou),
            r.crop_move_cells
                .map_or("-".into(), |(m, w)| format!("{m:.2} / {w:.2}"))
        );
    }
}

/// Still scenes' worst side pair ([`super::edges`]): per part with a tenth or more of its
/// changed side pixels, where on the silhouette they lie and how deep the changed runs are.
fn edges_table(md: &mut String, rows: &[VideoRow]) {
    let Some(still) = still_rows(rows, |r| r.worst_side_frame.is_some()) else {
        return;
    };
    let classes = super::edges::CLASS_NAMES.join(" / ");
    let _ = writeln!(
        md,
        "\n## Still scenes: the worst side pair, where it changed\n\n\
         The pair of each scene's worst side IoU (frames t, t + 1), its side view (along x; \
         larger depth nearer the camera): per part with 10 % or more of the pair's changed \
         side pixels, that share beside the part's share of the first frame's side outline (the \
         change's yardstick), its changed pixels' shares by where they lie on each row of the silhouette ({classes}: \
         the edge toward the camera moved, the edge away from it, a hole, a span that came \
         or went whole) and the changed runs' mean depth along the camera's axis. The pair's \
         two side views are drawn to worst-side/SCENE-SETTING.png (both grey, t only red, \
         t + 1 only blue, the camera to the right). After t, the crop's move in that pair (cells, \
         as in the table above). The last column is the same scene's pair \
         of the worst front IoU: its first frame, the crop's move, and the parts with 10 % or more of the front \
         pixels it changed (its views drawn to worst-front/).\n"
    );
    let _ = writeln!(
        md,
        "| scene | setting | t | part: share of the pair's change ({classes} %), run depth cm | worst front pair: t, parts' shares of its change |\n|---|---|---|---|---|"
    );
    let names = volcap_sim::parts::Part::ALL.map(|p| p.name());
    for r in still {
        let mut cells = Vec::new();
        for (p, name) in names.iter().enumerate() {
            let (Some(share), Some(e)) = (r.part_worst_side_share[p], r.part_worst_side_edges[p])
            else {
                continue;
            };
            if share < 0.1 {
                continue;
            }
            let e: Vec<String> = e.iter().map(|x| format!("{:.0}", 100.0 * x)).collect();
            let depth = r.part_worst_side_run_cm[p].map_or("-".into(), |d| format!("{d:.2}"));
            let outline =
                r.part_worst_side_outline[p].map_or("-".into(), |o| format!("{:.0}", 100.0 * o));
            cells.push(format!(
                "{name} {:.0} % of the change, {outline} % of the outline ({}), {depth}",
                100.0 * share,
                e.join(" / ")
            ));
        }
        let front: Vec<String> = names
            .iter()
            .zip(&r.part_worst_front_share)
            .filter_map(|(name, share)| {
                share
                    .filter(|s| *s >= 0.1)
                    .map(|s| format!("{name} {:.0} %", 100.0 * s))
            })
            .collect();
        let moved = |m: Option<f64>| m.map_or("-".into(), |m| format!("{m:.2}"));
        let _ = writeln!(
            md,
            "| {} | {} | {} (crop {}) | {} | {} (crop {}): {} |",
            r.scene,
            r.setting,
            r.worst_side_frame.map_or("-".into(), |t| t.to_string()),
            moved(r.worst_side_crop_move),
            cells.join("; "),
            r.worst_front_frame.map_or("-".into(), |t| t.to_string()),
            moved(r.worst_front_crop_move),
            front.join(", ")
        );
    }
}

pub(super) fn plot(rows: &[VideoRow], path: &Path) -> anyhow::Result<()> {
    let pts: Vec<Summary> = summarize(rows)
        .into_iter()
        .filter(|s| s.still_side_iou_mean.is_finite() && s.moving_chamfer_cm.is_finite())
        .collect();
    // Zoomed on the settings' worst frames (a tenth of their span, at least 0.002, to the
    // left of the worst): steady settings differ in the third decimal.
    let worst = pts.iter().map(|s| s.still_side_iou_min).fold(1.0, f64::min);
    let xmin = (worst - 0.1 * (1.0 - worst)).min(worst - 0.002).max(0.0);
    // The settings differ by tenths of a millimetre to a millimetre: zoom on them.
    let ymax = pts.iter().map(|s| s.moving_chamfer_cm).fold(0.1, f64::max) * 1.02;
    let ymin = pts
        .iter()
        .map(|s| s.moving_chamfer_cm)
        .fold(f64::INFINITY, f64::min)
        .min(ymax)
        * 0.98;
    let points: Vec<crate::plot::Labelled> = pts
        .iter()
        .map(|s| crate::plot::Labelled {
            label: format!("{} (lag {:.1} frames)", s.setting, s.moving_lag_frames),
            x: s.still_side_iou_mean,
            y: s.moving_chamfer_cm,
            x_bar: Some(s.still_side_iou_min),
            hollow: false,
        })
        .collect();
    crate::plot::scatter(
        path,
        &crate::plot::Axes {
            caption: "Steadiness vs accuracy per temporal setting (volcap bench temporal)",
            x_desc: "still person: consecutive side-view silhouette IoU (mean; bar to worst)",
            y_desc: "moving: Chamfer cm (lower is better)",
            x: xmin..1.0,
            y: ymin..ymax,
            size: (1180, 500),
            log_x: false,
        },
        &points,
        &[],
    )
}
