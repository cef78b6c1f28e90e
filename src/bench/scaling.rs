//! Build time against size (`tracery report scaling`): each mesh's build times, ours and
//! Embree's, on one thread and on every thread, and their log-log plot.

use std::path::Path;

use anyhow::{Context, Result, anyhow};

/// One mesh's best build times in milliseconds, `[one thread, every thread]`.
#[derive(Clone, Debug, PartialEq)]
pub struct ScalingRow {
    /// The mesh's name (a file stem, or the generated terrain's size).
    pub name: String,
    /// Triangles in the mesh.
    pub triangles: usize,
    /// Our SAH build with the 8-wide collapse.
    pub ours: [f64; 2],
    /// Embree's scene build, when Embree was measured.
    pub embree: Option<[f64; 2]>,
}

/// The per-doubling growth of build time from `prev` (triangles, ms) to `(n, ms)`: the factor
/// by which the time grows each time the triangle count doubles, or `None` when the count did
/// not grow.
pub fn growth_per_doubling(prev: (usize, f64), n: usize, ms: f64) -> Option<f64> {
    (n > prev.0 && prev.1 > 0.0 && ms > 0.0).then(|| {
        let doublings = (n as f64 / prev.0 as f64).log2();
        (ms / prev.1).powf(1.0 / doublings)
    })
}

/// Draws build time against triangle count on log-log axes: our build and Embree's (when
/// measured), on one thread and (lighter) on `threads` threads, with the
/// line a build proportional to the triangle count would follow through our first point, and
/// writes it to `path` (PNG, 900 x 600).
pub fn plot(path: &Path, rows: &[ScalingRow], threads: usize) -> Result<()> {
    use plotters::prelude::*;
    crate::plot_font::ensure()?;
    let rows: Vec<&ScalingRow> = rows.iter().filter(|r| r.triangles > 0).collect();
    let Some(first) = rows.first() else {
        return Err(anyhow!("no meshes to plot"));
    };
    let times = rows.iter().flat_map(|r| {
        r.ours
            .iter()
            .chain(r.embree.iter().flatten())
            .copied()
            .collect::<Vec<_>>()
    });
    let (tmin, tmax) = times
        .filter(|t| t.is_finite() && *t > 0.0)
        .fold((f64::MAX, f64::MIN), |a, t| (a.0.min(t), a.1.max(t)));
    if tmin > tmax {
        return Err(anyhow!("no build times to plot"));
    }
    let (nmin, nmax) = rows.iter().fold((f64::MAX, f64::MIN), |a, r| {
        (a.0.min(r.triangles as f64), a.1.max(r.triangles as f64))
    });
    let err = |e: &dyn std::fmt::Display| anyhow!("{}: {e}", path.display());
    let root = BitMapBackend::new(path, (900, 600)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption("SAH build time against triangle count", ("sans-serif", 24))
        .margin(16)
        .x_label_area_size(48)
        .y_label_area_size(72)
        .build_cartesian_2d(
            (nmin * 0.7..nmax * 1.4).log_scale(),
            (tmin * 0.7..tmax * 1.4).log_scale(),
        )
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc("triangles")
        .y_desc("build time (ms), best of the rounds")
        .x_label_formatter(&|v| count_label(*v))
        .y_label_formatter(&|v| crate::convergence::tick(*v))
        .x_labels(8)
        .y_labels(8)
        .light_line_style(WHITE.mix(0.0))
        .label_style(("sans-serif", 15))
        .draw()
        .map_err(|e| err(&e))?;
    // Proportional to the triangle count, through our first one-thread point.
    let scale = first.ours[0] / first.triangles as f64;
    chart
        .draw_series(LineSeries::new(
            [nmin * 0.7, nmax * 1.4].map(|n| (n, n * scale)),
            BLACK.mix(0.3),
        ))
        .map_err(|e| err(&e))?
        .label("proportional to the triangles")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.mix(0.3)));
    let ours_colour = RGBColor(200, 30, 30);
    let embree_colour = RGBColor(30, 60, 200);
    // (label, colour, opacity, points)
    struct Series(String, RGBColor, f64, Vec<(f64, f64)>);
    let mut series: Vec<Series> = Vec::new();
    for (k, label) in [
        (0, "1 thread".to_string()),
        (1, format!("{threads} threads")),
    ] {
        let alpha = if k == 0 { 1.0 } else { 0.45 };
        series.push(Series(
            format!("tracery SAH + collapse, {label}"),
            ours_colour,
            alpha,
            rows.iter()
                .map(|r| (r.triangles as f64, r.ours[k]))
                .collect(),
        ));
        let embree: Vec<(f64, f64)> = rows
            .iter()
            .filter_map(|r| r.embree.map(|e| (r.triangles as f64, e[k])))
            .collect();
        if !embree.is_empty() {
            series.push(Series(
                format!("Embree 3, {label}"),
                embree_colour,
                alpha,
                embree,
            ));
        }
    }
    for Series(label, colour, alpha, points) in series {
        let points: Vec<(f64, f64)> = points
            .into_iter()
            .filter(|p| p.1.is_finite() && p.1 > 0.0)
            .collect();
        let style = colour.mix(alpha).stroke_width(2);
        chart
            .draw_series(LineSeries::new(points.clone(), style))
            .map_err(|e| err(&e))?
            .label(label)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style));
        chart
            .draw_series(
                points
                    .iter()
                    .map(|&p| Circle::new(p, 4, colour.mix(alpha).filled())),
            )
            .map_err(|e| err(&e))?;
    }
    chart
        .configure_series_labels()
        .border_style(BLACK)
        .background_style(WHITE.mix(0.9))
        .label_font(("sans-serif", 15))
        .position(SeriesLabelPosition::UpperLeft)
        .draw()
        .map_err(|e| err(&e))?;
    root.present()
        .with_context(|| format!("{}: cannot write plot", path.display()))
}

/// A triangle count for an axis: `70k`, `1.5M`.
fn count_label(v: f64) -> String {
    use crate::convergence::tick;
    if v >= 1e6 {
        format!("{}M", tick(v / 1e6))
    } else if v >= 1e3 {
        format!("{}k", tick(v / 1e3))
    } else {
        tick(v)
    }
}
