//! `volcap eval`'s accuracy against time: the rows no other row beats on both (the front),
//! the table of every row's knobs beside its time and accuracy, and the plot.

use super::report::ModelRow;
use std::fmt::Write as _;
use std::path::Path;

/// The rows of one model (one loaded network, its decode knobs) at several grids and
/// methods do the same network work: their segment and encode ms are pooled over all their
/// images, and each row's ms a frame is that plus its own localization (so that the rows
/// differ by what they change, not by the networks' timing noise).
pub(super) fn pool_networks(rows: &mut [ModelRow]) {
    let n: usize = rows.iter().map(|m| m.images).sum();
    if rows.len() < 2 || n == 0 {
        return;
    }
    let pooled = |f: fn(&ModelRow) -> f64| {
        rows.iter()
            .filter(|m| f(m).is_finite())
            .map(|m| f(m) * m.images as f64)
            .sum::<f64>()
            / n as f64
    };
    let (segment, encode) = (pooled(|m| m.segment_ms), pooled(|m| m.encode_ms));
    for m in rows {
        m.segment_ms = segment;
        m.encode_ms = encode;
        m.frame_ms = segment + encode + m.localize_ms;
    }
}

/// Chamfer means closer than this are a tie (the table's last digit, 0.01 cm, rounds them
/// alike; the GPU backend's float sums move a surface by less).
const CHAMFER_TIE_CM: f64 = 0.005;

/// The rows on the accuracy-against-time front: those that no other row (ground-truth
/// series left out: bounds, not settings) beats on both time per frame and Chamfer, sorted
/// by time (a Chamfer within [`CHAMFER_TIE_CM`] counts as equal). Rows without a surface are
/// left out.
pub(super) fn front(summary: &[ModelRow]) -> Vec<&ModelRow> {
    let runs: Vec<&ModelRow> = summary
        .iter()
        .filter(|m| !m.bound && m.chamfer_cm.is_finite() && m.frame_ms.is_finite())
        .collect();
    let beats = |o: &ModelRow, m: &ModelRow| {
        o.frame_ms <= m.frame_ms
            && o.chamfer_cm <= m.chamfer_cm + CHAMFER_TIE_CM
            && (o.frame_ms < m.frame_ms || o.chamfer_cm < m.chamfer_cm - CHAMFER_TIE_CM)
    };
    let mut f: Vec<&ModelRow> = runs
        .iter()
        .copied()
        .filter(|m| !runs.iter().any(|o| beats(o, m)))
        .collect();
    f.sort_by(|a, b| a.frame_ms.total_cmp(&b.frame_ms));
    f
}

/// The accuracy-against-time table: every row's knobs (model, precision, resolution, coarse
/// level, method, backend) beside its time and accuracy, fastest first, the front marked.
pub(super) fn tradeoff_table(s: &mut String, summary: &[ModelRow]) {
    let on_front = front(summary);
    let mut rows: Vec<&ModelRow> = summary.iter().collect();
    rows.sort_by(|a, b| a.frame_ms.total_cmp(&b.frame_ms));
    let _ = writeln!(
        s,
        "\n**Accuracy against time**, fastest first: every row's knobs beside its ms per frame \
         (segment + encode + localize on this machine, the networks warmed up first; a model's \
         network ms pooled over its rows, which run the same networks) and its accuracy. On \
         the front: no other row (ground-truth series aside: bounds, not settings) is both \
         faster and more accurate (lower Chamfer); the plot's line joins them. Rows a few ms \
         apart are within the timing's noise on a shared machine.\n\n\
         | row | res | coarse | localization | networks on | ms/frame | localize ms | evals | Chamfer cm | P2S cm | IoU | front |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for m in rows {
        let mark = if m.bound {
            "bound"
        } else if on_front.iter().any(|f| std::ptr::eq(*f, m)) {
            "yes"
        } else {
            ""
        };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {:.1} | {:.1} | {:.0} | {:.2} | {:.2} | {:.3} | {} |",
            m.model,
            m.res,
            m.coarse_level,
            m.localization,
            m.backend,
            m.frame_ms,
            m.localize_ms,
            m.evaluations,
            m.chamfer_cm,
            m.p2s_cm,
            m.iou,
            mark
        );
    }
    if summary.iter().any(|m| m.backend.contains("llvmpipe")) {
        s.push_str(
            "\nRows on `wgpu llvmpipe` ran the GPU backend's kernels on Mesa's lavapipe, Vulkan \
             emulated on this CPU: their times say nothing about a GPU; their accuracy is the \
             adapter's path's.\n",
        );
    }
}

/// Chamfer against time per frame (a log axis where the times span more than a decade), a
/// point per row, the front's rows joined by a line.
pub(super) fn plot(summary: &[ModelRow], path: &Path) -> anyhow::Result<()> {
    let pts: Vec<&ModelRow> = summary
        .iter()
        .filter(|m| m.chamfer_cm.is_finite() && m.frame_ms.is_finite())
        .collect();
    let xmax = pts.iter().map(|m| m.frame_ms).fold(1.0, f64::max) * 1.1;
    let xmin = pts.iter().map(|m| m.frame_ms).fold(xmax, f64::min) * 0.8;
    // Times that span more than a decade on a log axis (the fast rows stay apart).
    let log_x = xmin > 0.0 && xmax / xmin > 10.0;
    let ymax = pts.iter().map(|m| m.chamfer_cm).fold(0.1, f64::max) * 1.1;
    // The y axis from a little below the best row (differences of a millimetre stay visible).
    let ymin = pts.iter().map(|m| m.chamfer_cm).fold(ymax, f64::min) * 0.9;
    let points: Vec<crate::plot::Labelled> = pts
        .iter()
        .map(|m| crate::plot::Labelled {
            label: m.model.clone(),
            x: m.frame_ms,
            y: m.chamfer_cm,
            x_bar: None,
            hollow: m.bound,
        })
        .collect();
    let line: Vec<(f64, f64)> = front(summary)
        .iter()
        .map(|m| (m.frame_ms, m.chamfer_cm))
        .collect();
    crate::plot::scatter(
        path,
        &crate::plot::Axes {
            caption: "Accuracy vs time per frame (volcap eval)",
            x_desc: "ms per frame (segment + encode + localize)",
            y_desc: "Chamfer cm (lower is better)",
            x: if log_x { xmin..xmax } else { 0.0..xmax },
            y: ymin..ymax,
            // A legend row per point beside the chart.
            size: (1180, (60 + 16 * points.len() as u32).max(520)),
            log_x,
        },
        &points,
        &line,
    )
}

/// `eval --replot`: `out`/eval.png drawn again from `out`/eval.json's summary rows.
pub(super) fn replot(out: &Path) -> anyhow::Result<()> {
    use anyhow::Context;
    let path = out.join("eval.json");
    let text = std::fs::read_to_string(&path).with_context(|| format!("{}", path.display()))?;
    let v: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("{}", path.display()))?;
    let rows = v["models"]
        .as_array()
        .ok_or_else(|| anyhow::anyhow!("{}: no \"models\" list", path.display()))?;
    // What the plot reads: name, time, Chamfer, bound (a null, JSON's NaN, stays NaN).
    let f = |r: &serde_json::Value, k: &str| r[k].as_f64().unwrap_or(f64::NAN);
    let summary: Vec<ModelRow> = rows
        .iter()
        .map(|r| {
            let name = r["model"].as_str().unwrap_or("?");
            let mut m =
                ModelRow::summarize(name, "", None, String::new(), 1, (None, None, None), &[]);
            (m.frame_ms, m.chamfer_cm) = (f(r, "frame_ms"), f(r, "chamfer_cm"));
            // Reports from before the field: the ground-truth rows by their family.
            m.bound = r["bound"].as_bool().unwrap_or_else(|| {
                r["family"]
                    .as_str()
                    .is_some_and(|f| f.contains("ground truth"))
            });
            m
        })
        .collect();
    plot(&summary, &out.join("eval.png"))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A summary row with only what the front reads: name, ms a frame, Chamfer, bound.
    fn row(name: &str, ms: f64, chamfer: f64, bound: bool) -> ModelRow {
        let mut m = ModelRow::summarize(
            name,
            "camera",
            None,
            "fourier".into(),
            1,
            (None, None, None),
            &[],
        );
        (m.frame_ms, m.chamfer_cm, m.bound) = (ms, chamfer, bound);
        m
    }

    /// The front holds the rows no other row beats on both time and Chamfer, fastest first;
    /// a tie on one axis (a Chamfer within a twentieth of a millimetre) is beaten by the better
    /// other; ground-truth bounds and rows without a surface are never on it and beat nothing.
    #[test]
    fn the_front_is_the_rows_nothing_beats_on_both() {
        let rows = [
            row("slow-good", 90.0, 1.4, false),
            row("fast-bad", 40.0, 2.2, false),
            row("mid-dominated", 60.0, 2.3, false),
            row("mid", 60.0, 1.8, false),
            row("tie-slower", 61.0, 1.8, false),
            row("same-ms-worse", 90.0, 1.5, false),
            row("a-hair-better-slower", 70.0, 1.797, false),
            row("truth", 10.0, 1.0, true),
            row("empty", 5.0, f64::NAN, false),
        ];
        let names: Vec<&str> = front(&rows).iter().map(|m| m.model.as_str()).collect();
        assert_eq!(names, ["fast-bad", "mid", "slow-good"]);
        assert!(front(&rows[7..]).is_empty());
    }

    /// Pooling gives every row of a model the images-weighted mean of their network ms, and
    /// each row's ms a frame is that plus its own localization; a single row stays as it is.
    #[test]
    fn pooling_keeps_each_rows_localization() {
        let mut rows = [row("a", 0.0, 1.0, false), row("b", 0.0, 1.0, false)];
        for (m, (seg, enc, loc, images)) in rows
            .iter_mut()
            .zip([(10.0, 20.0, 3.0, 1), (13.0, 26.0, 9.0, 2)])
        {
            (m.segment_ms, m.encode_ms, m.localize_ms, m.images) = (seg, enc, loc, images);
        }
        pool_networks(&mut rows);
        assert_eq!((rows[0].segment_ms, rows[0].encode_ms), (12.0, 24.0));
        assert_eq!((rows[1].segment_ms, rows[1].encode_ms), (12.0, 24.0));
        assert_eq!((rows[0].frame_ms, rows[1].frame_ms), (39.0, 45.0));
        let mut one = [row("c", 7.0, 1.0, false)];
        one[0].segment_ms = 5.0;
        pool_networks(&mut one);
        assert_eq!((one[0].segment_ms, one[0].frame_ms), (5.0, 7.0));
    }
}
