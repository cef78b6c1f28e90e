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
