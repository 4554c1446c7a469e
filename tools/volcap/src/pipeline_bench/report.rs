//! `volcap bench pipeline`'s report: the stages' and parts' tables and the plot.

use super::Row;
use anyhow::anyhow;
use plotters::prelude::*;
use std::fmt::Write as _;
use std::path::Path;
use volcap_engine::model::temporal::TemporalSettings;
use volcapd::config::{RenderDevice, RoundWaits};

/// The label's note on `render.drop_apart` where it is not the daemon's default.
fn apart_note(g: f32) -> String {
    if g == volcap_engine::pieces::DEFAULT_GAP {
        String::new()
    } else if g > 0.0 {
        format!(", pieces {g} apart dropped")
    } else {
        ", pieces apart kept".into()
    }
}

/// The published image's side, "whole px" where its outline is not antialiased
/// (`render.antialias` off, or a row written before the setting).
fn display_label(r: &Row) -> String {
    let side = if r.display_size == 0 {
        r.resolution
    } else {
        r.display_size
    };
    if r.antialias {
        side.to_string()
    } else {
        format!("{side} whole px")
    }
}

/// The temporal filter, with its surface dead band when it has one.
fn temporal_label(r: &Row) -> String {
    match (r.temporal, r.surface_dead_band) {
        (false, _) => "off".into(),
        (true, b) if b > 0.0 => format!("on, surface band {b}"),
        (true, _) => "on".into(),
    }
}

pub(super) fn table(rows: &[Row]) -> String {
    let mut s = String::from(
        "| model | runtime | res | display px | coarse | threads | segment thread | temporal | yaw | fps | x1 | latency p50 / p99 ms | capture | segment | field | render | encode | evaluations | note |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        let _ = writeln!(
            s,
            "| {}{}{} | {} | {} | {} | {} | {} | {} | {} | {} | {:.1} | {} | {:.0} / {:.0} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.0} | {} |",
            r.model,
            match (r.segment_passes > 1, r.segment_full_every > 1) {
                (true, true) => format!(", segmented twice, whole every {}", r.segment_full_every),
                (true, false) => ", segmented twice".to_string(),
                _ => String::new(),
            },
            apart_note(r.drop_apart),
            r.runtime,
            r.resolution,
            display_label(r),
            r.coarse_level,
            r.threads,
            if r.resolution <= r.segment_thread_up_to {
                "yes"
            } else {
                "no"
            },
            temporal_label(r),
            r.yaw_deg,
            r.fps,
            r.speedup_vs_1_thread
                .map(|x| format!("{x:.2}"))
                .unwrap_or_else(|| "-".into()),
            r.latency_p50_ms,
            r.latency_p99_ms,
            r.stage_p50_ms[0],
            r.stage_p50_ms[1],
            r.stage_p50_ms[2],
            r.stage_p50_ms[3],
            r.stage_p50_ms[4],
            r.evaluations,
            with_workers(
                r,
                match (&r.error, r.dispatches_per_frame > 0.0) {
                    (Some(e), _) => e.clone(),
                    // The GPU backend's traffic: what crosses between host and adapter per frame.
                    (None, true) => format!(
                        "adapter per frame: {:.2} MB up, {:.2} MB down, {:.0} dispatches, {:.0} read-backs waited for ({}){}; {} networks planned while measured{}",
                        r.bytes_up_per_frame / 1e6,
                        r.bytes_down_per_frame / 1e6,
                        r.dispatches_per_frame,
                        r.waits_per_frame,
                        if r.predicted_per_frame > 0.0 {
                            format!(
                                "the levels' rounds predicted, one read-back for them; {:.1} % of frames run again",
                                100.0 * r.reruns_per_frame / r.predicted_per_frame
                            )
                        } else {
                            format!("up to {} conflict rounds each", r.rounds_per_wait)
                        },
                        if r.render_device == RenderDevice::Own.name() {
                            "; the render stage on a device of its own"
                        } else {
                            ""
                        },
                        r.net_plans,
                        if r.adapter_ms_per_frame > 0.0 {
                            format!(
                                "; on the adapter's clock: networks {:.1} ms, maps {:.1} ms, localization and render {:.1} ms, display {:.1} ms",
                                r.adapter_ms_per_frame,
                                r.maps_ms_per_frame,
                                r.localize_ms_per_frame,
                                r.display_ms_per_frame
                            )
                        } else {
                            String::new()
                        }
                    ),
                    (None, false) => String::new(),
                }
            ),
        );
    }
    s
}

/// A row's note with the stages' threads first where there are several
/// (`compute.render_workers`, `compute.segment_workers`).
fn with_workers(r: &Row, note: String) -> String {
    let workers = workers_label(r);
    match (workers.is_empty(), note.is_empty()) {
        (true, _) => note,
        (false, true) => workers,
        (false, false) => format!("{workers}; {note}"),
    }
}

/// "2 render workers, 2 segment workers" (each where more than one; empty otherwise).
fn workers_label(r: &Row) -> String {
    let mut parts = Vec::new();
    if r.render_workers > 1 {
        parts.push(format!("{} render workers", r.render_workers));
    }
    if r.segment_workers > 1 {
        parts.push(format!("{} segment workers", r.segment_workers));
    }
    parts.join(", ")
}

/// Model-mode rows: where the segment, field and render stages' time goes, each part's mean
/// ms after its stage's mean (the parts of a stage add up to about its mean; what is left is
/// the thread's bookkeeping). Empty without such rows.
pub(super) fn parts_table(rows: &[Row]) -> String {
    use volcapd::pipeline::part::{NAMES, STAGE_STARTS};
    let rows: Vec<&Row> = rows
        .iter()
        .filter(|r| r.part_mean_ms.len() == NAMES.len() && r.error.is_none())
        .collect();
    if rows.is_empty() {
        return String::new();
    }
    let mut s = String::from(
        "\nWhere the segment, field and render stages' time goes (mean ms per frame; each stage's mean, then its parts):\n\n\
         | model | runtime | res | yaw |",
    );
    for w in STAGE_STARTS.windows(2) {
        let stage = NAMES[w[0]].split(':').next().unwrap_or_default();
        let _ = write!(s, " {stage} |");
        for n in &NAMES[w[0]..w[1]] {
            let _ = write!(s, " {} |", n.split_once(": ").map_or(*n, |(_, p)| p));
        }
    }
    s.push('\n');
    s.push_str(&"|---".repeat(4 + STAGE_STARTS.len() - 1 + NAMES.len()));
    s.push_str("|\n");
    for r in rows {
        let _ = write!(
            s,
            "| {}{} | {} | {} | {} |",
            r.model,
            {
                let mut notes = vec![workers_label(r)];
                if r.segment_passes > 1 && r.segment_full_every > 1 {
                    notes.push(format!("whole every {}", r.segment_full_every));
                }
                if !r.antialias {
                    notes.push("whole px".into());
                }
                if r.temporal
                    && r.surface_dead_band != TemporalSettings::default().surface_dead_band
                {
                    notes.push(format!("surface band {}", r.surface_dead_band));
                }
                notes.retain(|n| !n.is_empty());
                match notes.join(", ") {
                    n if n.is_empty() => n,
                    n => format!(" ({n})"),
                }
            },
            r.runtime,
            r.resolution,
            r.yaw_deg,
        );
        let means = [r.segment_mean_ms, r.field_mean_ms, r.render_mean_ms];
        for (w, mean) in STAGE_STARTS.windows(2).zip(means) {
            let _ = write!(s, " {mean:.2} |");
            for ms in &r.part_mean_ms[w[0]..w[1]] {
                let _ = write!(s, " {ms:.2} |");
            }
        }
        s.push('\n');
    }
    s
}

/// A plotted quantity: its title and how to read it from a row.
type Metric = (&'static str, fn(&Row) -> f64);

/// fps and p99 latency over resolution, one line per (model, coarse level, threads,
/// segment split, display size).
pub(super) fn plot(rows: &[Row], path: &Path) -> anyhow::Result<()> {
    crate::plot::register_font();
    let root = BitMapBackend::new(path, (1100, 460)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| anyhow!("{e}"))?;
    let (left, right) = root.split_horizontally(550);
    let key = |r: &Row| {
        (
            // The GPU backend's knobs, where a row sets them: without them in the key the
            // rows of `--render-device shared,own` or `--rounds-per-wait 1,8` drew one line.
            format!(
                "{}{} {}{}{}{}{}{}",
                r.model,
                apart_note(r.drop_apart),
                r.runtime,
                if r.render_device == RenderDevice::Own.name() {
                    " own device"
                } else {
                    ""
                },
                if r.round_waits == RoundWaits::PerFrame.name() && r.dispatches_per_frame > 0.0 {
                    " rounds predicted"
                } else {
                    ""
                },
                if r.rounds_per_wait > 1 && r.dispatches_per_frame > 0.0 {
                    format!(" rounds<={}", r.rounds_per_wait)
                } else {
                    String::new()
                },
                match workers_label(r) {
                    w if w.is_empty() => w,
                    w => format!(" {w}"),
                },
                if r.antialias { "" } else { " whole px" }
            ),
            r.coarse_level,
            r.threads,
            r.segment_thread_up_to,
            r.display_size,
            r.temporal,
            // Tenths of a degree: a key that sorts.
            (r.yaw_deg * 10.0).round() as i64,
        )
    };
    let mut keys: Vec<(String, u32, usize, usize, usize, bool, i64)> =
        rows.iter().map(key).collect();
    keys.sort();
    keys.dedup();
    let xmax = rows.iter().map(|r| r.resolution).max().unwrap_or(257) as f64 * 1.3;
    let xmin = rows.iter().map(|r| r.resolution).min().unwrap_or(65) as f64 / 1.3;
    let metric: [Metric; 2] = [
        ("frames per second", |r| r.fps),
        ("p99 latency, ms", |r| r.latency_p99_ms),
    ];
    for (area, (what, f)) in [&left, &right].into_iter().zip(metric) {
        // Headroom above the highest point for the legend box (a line of it per series, in
        // the upper right): with eight series the box covered the lines it names.
        let ymax = rows.iter().map(f).fold(1.0, f64::max) * (1.15 + 0.06 * keys.len() as f64);
        let mut chart = ChartBuilder::on(area)
            .caption(what, ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(36)
            .y_label_area_size(50)
            .build_cartesian_2d((xmin..xmax).log_scale(), 0.0..ymax)
            .map_err(|e| anyhow!("{e}"))?;
        chart
            .configure_mesh()
            .x_desc("grid resolution (points per axis)")
            .draw()
            .map_err(|e| anyhow!("{e}"))?;
        for (i, k) in keys.iter().enumerate() {
            let color = Palette99::pick(i).to_rgba();
            let mut pts: Vec<(f64, f64)> = rows
                .iter()
                .filter(|r| r.error.is_none() && key(r) == *k)
                .map(|r| (r.resolution as f64, f(r)))
                .collect();
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            chart
                .draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))
                .map_err(|e| anyhow!("{e}"))?
                .label(format!(
                    "{} c{} x{} seg<={}{}{}{}",
                    k.0,
                    k.1,
                    k.2,
                    k.3,
                    if k.4 == 0 {
                        String::new()
                    } else {
                        format!(" {}px", k.4)
                    },
                    if k.5 { "" } else { " no-temporal" },
                    if k.6 == 0 {
                        String::new()
                    } else {
                        format!(" yaw {}", k.6 as f64 / 10.0)
                    }
                ))
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 16, y)], color.stroke_width(2))
                });
            chart
                .draw_series(pts.iter().map(|p| Circle::new(*p, 4, color.filled())))
                .map_err(|e| anyhow!("{e}"))?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(|e| anyhow!("{e}"))?;
    }
    root.present()
        .map_err(|e| anyhow!("{}: {e}", path.display()))?;
    Ok(())
}
