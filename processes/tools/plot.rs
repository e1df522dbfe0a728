//! Renders an experiment's [`Figure`] to SVG with plotters: one panel per row, shared x label,
//! a legend per panel. SVG needs no font files, so plots render the same on any machine.

use afs_shared::experiments::{Figure, Panel};
use anyhow::{Context, Result};
use plotters::prelude::*;
use std::path::Path;

const COLORS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(100, 100, 100),
];

fn bounds(panel: &Panel, log_x: bool) -> Option<((f64, f64), (f64, f64))> {
    let pts = panel
        .series
        .iter()
        .flat_map(|s| s.points.iter())
        .filter(|p| p[0].is_finite() && p[1].is_finite());
    let pts: Vec<&[f64; 2]> = pts.filter(|p| !log_x || p[0] > 0.0).collect();
    if pts.is_empty() {
        return None;
    }
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for p in pts {
        x0 = x0.min(p[0]);
        x1 = x1.max(p[0]);
        y0 = y0.min(p[1]);
        y1 = y1.max(p[1]);
    }
    if x1 <= x0 {
        x1 = x0 + 1.0;
    }
    let pad = ((y1 - y0) * 0.08).max(1e-9);
    Some(((x0, x1), (y0 - pad, y1 + pad)))
}

/// Writes `figure` as an SVG file at `path`.
pub fn render(figure: &Figure, path: &Path) -> Result<()> {
    let height = 260 * figure.panels.len().max(1) as u32 + 40;
    let root = SVGBackend::new(path, (960, height)).into_drawing_area();
    root.fill(&WHITE)?;
    let root = root.titled(&figure.title, ("sans-serif", 18))?;
    let areas = root.split_evenly((figure.panels.len().max(1), 1));
    for (panel, area) in figure.panels.iter().zip(areas.iter()) {
        let Some(((x0, x1), (y0, y1))) = bounds(panel, figure.log_x) else {
            continue;
        };
        let mut builder = ChartBuilder::on(area);
        builder
            .margin(8)
            .x_label_area_size(36)
            .y_label_area_size(64);
        if figure.log_x {
            let mut chart = builder.build_cartesian_2d((x0..x1).log_scale(), y0..y1)?;
            chart
                .configure_mesh()
                .x_desc(panel.x_label.as_deref().unwrap_or(&figure.x_label))
                .y_desc(&panel.y_label)
                .draw()?;
            draw_series(&mut chart, panel, true)?;
        } else {
            let mut chart = builder.build_cartesian_2d(x0..x1, y0..y1)?;
            chart
                .configure_mesh()
                .x_desc(panel.x_label.as_deref().unwrap_or(&figure.x_label))
                .y_desc(&panel.y_label)
                .draw()?;
            draw_series(&mut chart, panel, false)?;
        }
    }
    root.present()
        .with_context(|| format!("writing plot {}", path.display()))?;
    Ok(())
}

fn draw_series<'a, X, Y>(
    chart: &mut ChartContext<'a, SVGBackend<'a>, Cartesian2d<X, Y>>,
    panel: &Panel,
    log_x: bool,
) -> Result<()>
where
    X: plotters::coord::ranged1d::Ranged<ValueType = f64>,
    Y: plotters::coord::ranged1d::Ranged<ValueType = f64>,
{
    for (i, s) in panel.series.iter().enumerate() {
        let color = COLORS[i % COLORS.len()];
        let pts: Vec<(f64, f64)> = s
            .points
            .iter()
            .filter(|p| p[0].is_finite() && p[1].is_finite() && (!log_x || p[0] > 0.0))
            .map(|p| (p[0], p[1]))
            .collect();
        if s.markers {
            chart
                .draw_series(pts.iter().map(|&p| Circle::new(p, 3, color.filled())))?
                .label(s.label.clone())
                .legend(move |(x, y)| Circle::new((x + 10, y), 3, color.filled()));
        } else {
            chart
                .draw_series(LineSeries::new(pts, color.stroke_width(1)))?
                .label(s.label.clone())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color));
        }
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    Ok(())
}
