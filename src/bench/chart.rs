//! `tracery bench --plot`: the one-thread rays per second of every engine on every mesh, as
//! bars (closest hits and occlusion side by side), so the run's comparison reads at a glance.

use std::path::Path;

use anyhow::{Context, Result, anyhow};

use super::EngineResult;

/// Colours of the two queries' bars.
pub const CLOSEST_COLOUR: [u8; 3] = [200, 30, 30];
/// See [`CLOSEST_COLOUR`].
pub const OCCLUDED_COLOUR: [u8; 3] = [30, 60, 200];

/// Draws the one-thread closest-hit and occlusion Mrays/s of each engine in `results` (a row
/// per mesh and engine, in their order; rows of other thread counts are left out), with each
/// bar's figure at its end, to `path` (PNG, 1000 pixels wide, as tall as the rows need).
pub fn plot(path: &Path, results: &[EngineResult]) -> Result<()> {
    use plotters::prelude::*;
    use plotters::style::text_anchor::{HPos, Pos, VPos};
    crate::plot_font::ensure()?;
    let rows: Vec<&EngineResult> = results.iter().filter(|r| r.threads == 1).collect();
    if rows.is_empty() {
        return Err(anyhow!("no one-thread results to plot"));
    }
    let top = rows
        .iter()
        .flat_map(|r| [r.closest_mrays, r.occluded_mrays])
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::max);
    if top <= 0.0 {
        return Err(anyhow!("no rays per second to plot"));
    }
    let n = rows.len();
    let height = (110 + 38 * n) as u32;
    let err = |e: &dyn std::fmt::Display| anyhow!("{}: {e}", path.display());
    let root = BitMapBackend::new(path, (1000, height)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    // Rows run top to bottom in the order given: the chart's first segment is at the bottom.
    let at = |i: usize| n - 1 - i;
    let label = |s: usize| {
        rows.get(at(s))
            .map_or(String::new(), |r| format!("{} · {}", r.mesh, r.engine))
    };
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "Canonical camera rays, one thread (Mrays/s)",
            ("sans-serif", 22),
        )
        .margin(14)
        .x_label_area_size(36)
        .y_label_area_size(250)
        .build_cartesian_2d(0.0..top * 1.18, (0..n - 1).into_segmented())
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .disable_y_mesh()
        .x_desc("million rays per second")
        .y_labels(n)
        .y_label_formatter(&|v| match v {
            SegmentValue::CenterOf(i) => label(*i),
            _ => String::new(),
        })
        .light_line_style(WHITE.mix(0.0))
        .label_style(("sans-serif", 14))
        .draw()
        .map_err(|e| err(&e))?;
    let colour = |c: [u8; 3]| RGBColor(c[0], c[1], c[2]);
    for (query, c, upper) in [
        ("closest hit", colour(CLOSEST_COLOUR), true),
        ("occlusion", colour(OCCLUDED_COLOUR), false),
    ] {
        let value = |r: &EngineResult| {
            if upper {
                r.closest_mrays
            } else {
                r.occluded_mrays
            }
        };
        let bars: Vec<(usize, f64)> = rows
            .iter()
            .enumerate()
            .map(|(i, r)| (at(i), value(r)))
            .filter(|(_, v)| v.is_finite() && *v > 0.0)
            .collect();
        // The closest-hit bar fills the segment's upper half, occlusion its lower half.
        let span = |s: usize| {
            if upper {
                (SegmentValue::Exact(s + 1), SegmentValue::CenterOf(s))
            } else {
                (SegmentValue::CenterOf(s), SegmentValue::Exact(s))
            }
        };
        chart
            .draw_series(bars.iter().map(|&(s, v)| {
                let (a, b) = span(s);
                Rectangle::new([(0.0, a), (v, b)], c.filled())
            }))
            .map_err(|e| err(&e))?
            .label(query)
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 16, y + 5)], c.filled()));
        let text = ("sans-serif", 13).into_font().color(&BLACK);
        chart
            .draw_series(bars.iter().map(|&(s, v)| {
                let (a, _) = span(s);
                Text::new(
                    format!("{v:.1}"),
                    (v + top * 0.01, a),
                    text.clone().pos(Pos::new(HPos::Left, VPos::Top)),
                )
            }))
            .map_err(|e| err(&e))?;
    }
    chart
        .configure_series_labels()
        .border_style(BLACK)
        .background_style(WHITE.mix(0.9))
        .label_font(("sans-serif", 14))
        .position(SeriesLabelPosition::LowerRight)
        .draw()
        .map_err(|e| err(&e))?;
    root.present()
        .with_context(|| format!("{}: cannot write plot", path.display()))
}
