//! PNG plots (plotters, bitmap backend, font embedded so no system fonts are needed).

use crate::bench::Row;
use anyhow::anyhow;
use plotters::prelude::*;
use plotters::style::FontStyle;
use std::path::Path;
use std::sync::Once;

static FONT: &[u8] = include_bytes!("../assets/DejaVuSansMono.ttf");
static REGISTER: Once = Once::new();

pub fn register_font() {
    REGISTER.call_once(|| {
        // The font is compiled in and known to parse; a failure would only lose labels.
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT);
    });
}

fn method_color(method: &str) -> RGBColor {
    match method {
        "dense" => RGBColor(0, 0, 0),
        "mise" => RGBColor(230, 120, 0),
        "octree-threshold" => RGBColor(30, 110, 200),
        "hierarchical" => RGBColor(200, 30, 40),
        "hierarchical-unseeded" => RGBColor(240, 150, 150),
        "hierarchical-no-conflict" => RGBColor(150, 80, 170),
        "hierarchical-tight" => RGBColor(20, 150, 60),
        "demo-faster" => RGBColor(0, 170, 190),
        _ => RGBColor(100, 100, 100),
    }
}

/// The paper's Fig. 5 redrawn from our rows: IoU vs dense over acceleration factor, one
/// panel per resolution, one marker per method/threshold, for `scene`.
pub fn accuracy_vs_time(rows: &[Row], scene: &str, path: &Path) -> anyhow::Result<()> {
    register_font();
    let sub: Vec<&Row> = rows.iter().filter(|r| r.scene == scene).collect();
    let mut res: Vec<usize> = sub.iter().map(|r| r.resolution).collect();
    res.sort();
    res.dedup();
    let cols = if res.len() > 1 { 2 } else { 1 };
    let nrows = res.len().div_ceil(cols).max(1);
    let (w, h) = (560 * cols as u32, 440 * nrows as u32 + 40);
    let root = BitMapBackend::new(path, (w, h)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| anyhow!("{e}"))?;
    let (title, body) = root.split_vertically(40);
    title
        .titled(
            &format!("Surface localization on '{scene}': accuracy vs acceleration"),
            ("sans-serif", 22),
        )
        .map_err(|e| anyhow!("{e}"))?;
    let panels = body.split_evenly((nrows, cols));
    for (panel, &r) in panels.iter().zip(&res) {
        let pts: Vec<&&Row> = sub.iter().filter(|x| x.resolution == r).collect();
        let xmax = pts.iter().map(|p| p.eval_speedup()).fold(1.0, f64::max) * 2.0;
        let ymin = pts.iter().map(|p| p.iou_vs_dense).fold(1.0, f64::min);
        let ylo = (ymin - 0.1 * (1.0 - ymin).max(0.01)).max(0.0);
        let mut chart = ChartBuilder::on(panel)
            .caption(
                format!(
                    "{r}^3 ({} dense evaluations)",
                    pts.first().map(|p| p.dense_evaluations).unwrap_or(0)
                ),
                ("sans-serif", 16),
            )
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d((0.8f64..xmax).log_scale(), ylo..1.0 + (1.0 - ylo) * 0.06)
            .map_err(|e| anyhow!("{e}"))?;
        chart
            .configure_mesh()
            .x_desc("acceleration (dense evals / evals)")
            .y_desc("IoU vs dense")
            .label_style(("sans-serif", 12))
            .draw()
            .map_err(|e| anyhow!("{e}"))?;
        let mut seen = std::collections::HashSet::new();
        for p in &pts {
            let color = method_color(&p.method);
            let x = p.eval_speedup();
            let y = p.iou_vs_dense;
            // MISE often lands on the hierarchical point: draw it as a ring around it.
            let ring = p.method == "mise";
            let style = if ring {
                color.stroke_width(2)
            } else {
                color.filled()
            };
            let radius = if ring { 9 } else { 5 };
            let series = chart
                .draw_series(std::iter::once(Circle::new((x, y), radius, style)))
                .map_err(|e| anyhow!("{e}"))?;
            if seen.insert(p.method.clone()) {
                series
                    .label(p.method.clone())
                    .legend(move |(x, y)| Circle::new((x, y), radius.min(6), style));
            }
            if let Some(t) = p.param {
                let label = EmptyElement::at((x, y))
                    + Text::new(
                        format!("{t}"),
                        (7, -14),
                        ("sans-serif", 11).into_font().color(&color),
                    );
                chart
                    .draw_series(std::iter::once(label))
                    .map_err(|e| anyhow!("{e}"))?;
            }
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::LowerLeft)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 12))
            .draw()
            .map_err(|e| anyhow!("{e}"))?;
    }
    root.present().map_err(|e| anyhow!("{e}"))?;
    Ok(())
}

/// One labelled point of a [`scatter`] plot, with an optional horizontal bar from `x_bar`
/// to `x` (a range, e.g. worst to mean).
pub struct Labelled {
    pub label: String,
    pub x: f64,
    pub y: f64,
    pub x_bar: Option<f64>,
    /// Drawn hollow: a reference (a bound), not a setting.
    pub hollow: bool,
}

/// Axes of a [`scatter`] plot: caption, axis titles and ranges, picture size.
pub struct Axes<'a> {
    pub caption: &'a str,
    pub x_desc: &'a str,
    pub y_desc: &'a str,
    pub x: std::ops::Range<f64>,
    pub y: std::ops::Range<f64>,
    pub size: (u32, u32),
    /// The x axis in powers of ten (`x` then a positive range): times that span orders of
    /// magnitude stay apart at the fast end.
    pub log_x: bool,
}

/// A scatter plot with one legend entry per point (hollow where [`Labelled::hollow`]), the
/// legend in a column beside the chart (so that many points stay readable), and `front` (if
/// any) drawn as a line through its points in order: the trade-off plots of `eval` (its
/// accuracy-against-time front) and `bench temporal`.
pub fn scatter(
    path: &Path,
    axes: &Axes,
    points: &[Labelled],
    front: &[(f64, f64)],
) -> anyhow::Result<()> {
    register_font();
    // The chart keeps 64 % of the asked width; the legend column takes the rest, widened
    // (the picture with it) to its longest label, about 7 px a character at 12 px, up to
    // 4,000 px (a label is a command line's setting: a longer one is cut).
    let chart_w = axes.size.0 * 64 / 100;
    let longest = points
        .iter()
        .map(|p| p.label.chars().count())
        .max()
        .unwrap_or(0) as u32;
    let legend_w = (axes.size.0 - chart_w).max(30 + 7 * longest.min(566));
    let size = (chart_w + legend_w, axes.size.1);
    let root = BitMapBackend::new(path, size).into_drawing_area();
    root.fill(&WHITE).map_err(|e| anyhow!("{e}"))?;
    let (plot, legend) = root.split_horizontally(chart_w);
    // On a log axis the chart's x is log10 of the value, labelled with the value.
    let tx = |x: f64| if axes.log_x { x.max(1e-9).log10() } else { x };
    let mut chart = ChartBuilder::on(&plot)
        .caption(axes.caption, ("sans-serif", 18))
        .margin(14)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(tx(axes.x.start)..tx(axes.x.end), axes.y.clone())
        .map_err(|e| anyhow!("{e}"))?;
    let log_label = |v: &f64| format!("{:.0}", 10f64.powf(*v));
    let mut mesh = chart.configure_mesh();
    mesh.x_desc(axes.x_desc)
        .y_desc(axes.y_desc)
        .label_style(("sans-serif", 12));
    if axes.log_x {
        mesh.x_label_formatter(&log_label);
    }
    mesh.draw().map_err(|e| anyhow!("{e}"))?;
    if front.len() > 1 {
        chart
            .draw_series([PathElement::new(
                front.iter().map(|&(x, y)| (tx(x), y)).collect::<Vec<_>>(),
                BLACK.mix(0.5).stroke_width(2),
            )])
            .map_err(|e| anyhow!("{e}"))?;
    }
    // The legend column: a row per point, as many as fit.
    let row_px = 16i32;
    let top = 40i32;
    let fits = ((axes.size.1 as i32 - top - 8) / row_px).max(1) as usize;
    for (i, p) in points.iter().enumerate() {
        let c = Palette99::pick(i).to_rgba();
        if let Some(lo) = p.x_bar {
            chart
                .draw_series([PathElement::new(
                    vec![(tx(lo), p.y), (tx(p.x), p.y)],
                    c.stroke_width(2),
                )])
                .map_err(|e| anyhow!("{e}"))?;
        }
        let style = if p.hollow {
            c.stroke_width(2)
        } else {
            c.filled()
        };
        chart
            .draw_series([Circle::new((tx(p.x), p.y), 6, style)])
            .map_err(|e| anyhow!("{e}"))?;
        if i < fits {
            let y = top + row_px * i as i32;
            legend
                .draw(&Circle::new((10, y), 5, style))
                .map_err(|e| anyhow!("{e}"))?;
            legend
                .draw(&Text::new(
                    p.label.clone(),
                    (22, y - 7),
                    ("sans-serif", 12).into_font(),
                ))
                .map_err(|e| anyhow!("{e}"))?;
        }
    }
    if points.len() > fits {
        legend
            .draw(&Text::new(
                format!("(and {} more: see the table)", points.len() - fits),
                (22, top + row_px * fits as i32 - 7),
                ("sans-serif", 12).into_font(),
            ))
            .map_err(|e| anyhow!("{e}"))?;
    }
    root.present().map_err(|e| anyhow!("{e}"))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn width_with_label(label: String) -> u32 {
        let path = std::env::temp_dir().join(format!(
            "volcap-scatter-{}-{}.png",
            std::process::id(),
            label.len()
        ));
        let axes = Axes {
            caption: "c",
            x_desc: "x",
            y_desc: "y",
            x: 0.0..1.0,
            y: 0.0..1.0,
            size: (600, 200),
            log_x: false,
        };
        let p = Labelled {
            label,
            x: 0.5,
            y: 0.5,
            x_bar: Some(0.25),
            hollow: false,
        };
        scatter(&path, &axes, &[p], &[]).unwrap();
        let w = image::open(&path).unwrap().width();
        let _ = std::fs::remove_file(&path);
        w
    }

    /// The legend column is as wide as its longest label (no label cut at the picture's
    /// edge), within a bound whatever a command line's setting names.
    #[test]
    fn the_legend_widens_the_picture_to_its_labels_within_a_bound() {
        assert_eq!(width_with_label("short".into()), 600);
        let long = width_with_label("x".repeat(100));
        assert!(long >= 384 + 7 * 100, "{long}");
        let huge = width_with_label("x".repeat(100_000));
        assert!(huge <= 384 + 4_000 + 30, "{huge}");
    }
}
