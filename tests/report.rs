//! `tracery report scaling`'s growth figure and plot.

use tracery::bench::scaling::{ScalingRow, growth_per_doubling, plot};

#[test]
fn growth_per_doubling_is_the_time_factor_for_each_doubling_of_the_count() {
    // Twice the triangles in 2.2 times the time.
    let g = growth_per_doubling((100, 10.0), 200, 22.0).unwrap();
    assert!((g - 2.2).abs() < 1e-9, "{g}");
    // Four times the triangles (two doublings) in four times the time: 2x a doubling.
    let g = growth_per_doubling((1000, 5.0), 4000, 20.0).unwrap();
    assert!((g - 2.0).abs() < 1e-9, "{g}");
    // No growth of the count, or no time: no figure.
    assert_eq!(growth_per_doubling((1000, 5.0), 1000, 9.0), None);
    assert_eq!(growth_per_doubling((1000, 0.0), 2000, 9.0), None);
}

/// Pixels of `img` within a few levels of `rgb`.
fn pixels_like(img: &image::RgbImage, rgb: [u8; 3]) -> usize {
    img.pixels()
        .filter(|p| (0..3).all(|c| p.0[c].abs_diff(rgb[c]) <= 8))
        .count()
}

#[test]
fn the_scaling_plot_draws_each_engine_measured_and_no_other() {
    let row = |name: &str, n: usize, ms: f64, embree: Option<[f64; 2]>| ScalingRow {
        name: name.into(),
        triangles: n,
        ours: [ms, ms * 0.6],
        embree,
    };
    let dir = tempfile::tempdir().unwrap();
    let both = dir.path().join("both.png");
    let rows = [
        row("small", 70_000, 12.0, Some([25.0, 13.0])),
        row("medium", 200_000, 36.0, Some([78.0, 41.0])),
        row("large", 4_000_000, 900.0, Some([1600.0, 850.0])),
    ];
    plot(&both, &rows, 2).unwrap();
    let img = image::open(&both).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (900, 600));
    // Our one-thread line (deep red) and Embree's (deep blue) are drawn.
    let (ours, embree) = (
        pixels_like(&img, [200, 30, 30]),
        pixels_like(&img, [30, 60, 200]),
    );
    assert!(ours > 200, "{ours} pixels of our line");
    assert!(embree > 200, "{embree} pixels of Embree's line");

    // Without Embree's figures, no line of Embree's colour (its legend entry neither).
    let ours_only = dir.path().join("ours.png");
    let rows: Vec<ScalingRow> = rows
        .iter()
        .map(|r| ScalingRow {
            embree: None,
            ..r.clone()
        })
        .collect();
    plot(&ours_only, &rows, 2).unwrap();
    let img = image::open(&ours_only).unwrap().to_rgb8();
    assert!(pixels_like(&img, [200, 30, 30]) > 200);
    assert_eq!(pixels_like(&img, [30, 60, 200]), 0);

    // Nothing to plot is an error, not an empty picture.
    assert!(plot(&dir.path().join("none.png"), &[], 2).is_err());
}

/// The lengths in pixels of the bars of colour `rgb` in `img`, longest first: runs of
/// picture rows holding that colour, each run's widest first run from the left (the legend's
/// swatch makes one too).
fn bar_lengths(img: &image::RgbImage, rgb: [u8; 3]) -> Vec<usize> {
    let like = |x: u32, y: u32| {
        let p = img.get_pixel(x, y).0;
        (0..3).all(|c| p[c].abs_diff(rgb[c]) <= 8)
    };
    // A row's first run of the colour from the left (a legend swatch further right on the
    // same row is not part of the bar).
    let width = |y: u32| {
        (0..img.width())
            .skip_while(|&x| !like(x, y))
            .take_while(|&x| like(x, y))
            .count()
    };
    let mut runs = Vec::new();
    let mut current = 0;
    for y in 0..img.height() {
        match width(y) {
            0 if current > 0 => {
                runs.push(current);
                current = 0;
            }
            w => current = current.max(w),
        }
    }
    if current > 0 {
        runs.push(current);
    }
    runs.sort_unstable_by(|a, b| b.cmp(a));
    runs
}

#[test]
fn the_bench_chart_has_a_bar_pair_per_one_thread_row_as_long_as_its_figure() {
    use tracery::bench::EngineResult;
    use tracery::bench::chart::{CLOSEST_COLOUR, OCCLUDED_COLOUR, plot};
    let result = |engine: &str, threads: usize, closest: f64, occluded: f64| EngineResult {
        engine: engine.into(),
        mesh: "mesh".into(),
        triangles: 1000,
        threads,
        build_ms: 1.0,
        closest_mrays: closest,
        occluded_mrays: occluded,
        closest_spread: 1.0,
        agreement: 1.0,
        isa: None,
        stats: None,
        split: None,
        secondary: None,
    };
    let results = [
        result("fast", 1, 40.0, 20.0),
        result("fast", 2, 80.0, 40.0),
        result("slow", 1, 10.0, 5.0),
    ];
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bench.png");
    plot(&path, &results).unwrap();
    let img = image::open(&path).unwrap().to_rgb8();
    // Two one-thread rows: the two-thread row is left out.
    assert_eq!(img.dimensions(), (1000, 110 + 38 * 2));
    // Each bar's length follows its figure: 40 against 10 for closest hits, 20 against 5 for
    // occlusion (and the two queries share one scale: 40 against 20).
    let closest = bar_lengths(&img, CLOSEST_COLOUR);
    let occluded = bar_lengths(&img, OCCLUDED_COLOUR);
    assert!(
        closest.len() >= 2 && occluded.len() >= 2,
        "{closest:?} {occluded:?}"
    );
    let ratio = |a: usize, b: usize| a as f64 / b as f64;
    assert!(
        (ratio(closest[0], closest[1]) - 4.0).abs() < 0.2,
        "{closest:?}"
    );
    assert!(
        (ratio(occluded[0], occluded[1]) - 4.0).abs() < 0.2,
        "{occluded:?}"
    );
    assert!(
        (ratio(closest[0], occluded[0]) - 2.0).abs() < 0.1,
        "{closest:?} {occluded:?}"
    );

    // No one-thread row: an error, not an empty picture.
    assert!(plot(&dir.path().join("none.png"), &results[1..2]).is_err());
}
