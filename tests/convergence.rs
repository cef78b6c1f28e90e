//! Error against time: random sampling converges as N^-1/2, the low-discrepancy sampler
//! reaches the same error sooner, and the outputs are written.

use std::path::Path;

use tracery::bvh::{BuildOptions, Bvh};
use tracery::convergence::{
    ConvergenceConfig, Peer, least_squares, load_reference, plot, run, tick, time_to, write_csv,
};
use tracery::sampling::SamplerKind;
use tracery::scene::Scene;

#[test]
fn least_squares_recovers_a_line() {
    let pts: Vec<(f64, f64)> = (0..10).map(|i| (i as f64, 3.0 - 0.5 * i as f64)).collect();
    let (slope, intercept) = least_squares(&pts);
    assert!((slope + 0.5).abs() < 1e-12 && (intercept - 3.0).abs() < 1e-12);
}

#[test]
fn depth_of_field_scene_converges_at_the_expected_rates() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/scenes/depth_of_field.toml");
    let scene = Scene::load(&path).unwrap();
    let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
    let config = ConvergenceConfig {
        width: 40,
        height: 30,
        max_spp: 64,
        seeds: 5,
        reference_spp: 64 * 64,
        max_depth: 5,
        samplers: vec![SamplerKind::Random, SamplerKind::Sobol],
        target_rmse: None,
        denoise: false,
    };
    let report = run(&scene, &bvh, &config, None, &mut |_, _| {}).unwrap();
    assert_eq!(report.points.len(), 7 * 5 * 2);
    let random = &report.fits[0];
    let sobol = &report.fits[1];
    assert!(
        (random.slope_spp + 0.5).abs() <= 0.1,
        "random slope {}",
        random.slope_spp
    );
    assert!(
        sobol.slope_spp < random.slope_spp,
        "sobol {} vs random {}",
        sobol.slope_spp,
        random.slope_spp
    );
    // Errors measured per render, not made up: they fall with the sample count.
    let rmse_at = |s: SamplerKind, spp: u32| {
        report
            .means
            .iter()
            .find(|m| m.0 == s && m.1 == spp)
            .unwrap()
            .3
    };
    assert!(rmse_at(SamplerKind::Random, 64) < rmse_at(SamplerKind::Random, 1) / 4.0);

    let dir = tempfile::tempdir().unwrap();
    write_csv(&dir.path().join("c.csv"), &report).unwrap();
    let csv = std::fs::read_to_string(dir.path().join("c.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + report.points.len());
    assert!(csv.starts_with("sampler,spp,seed,seconds,rmse,relmse,denoised"));
    plot(&dir.path().join("c.png"), &report, "test").unwrap();
    let img = image::open(dir.path().join("c.png")).unwrap();
    assert_eq!((img.width(), img.height()), (900, 600));
}

#[test]
fn a_reference_with_too_few_samples_is_refused() {
    let config = ConvergenceConfig {
        width: 8,
        height: 8,
        max_spp: 16,
        seeds: 2,
        reference_spp: 512,
        max_depth: 5,
        samplers: vec![SamplerKind::Random],
        target_rmse: None,
        denoise: false,
    };
    assert!(format!("{:#}", config.validate(false).unwrap_err()).contains("64 x 16"));
    let bad = ConvergenceConfig {
        max_spp: 24,
        reference_spp: 64 * 24,
        ..config.clone()
    };
    assert!(bad.validate(false).is_err());
    // A reference given from elsewhere needs no samples of its own.
    assert!(config.validate(true).is_ok());
}

#[test]
fn axis_labels_are_short_whatever_the_float() {
    assert_eq!(tick(0.009000000000001), "0.009");
    assert_eq!(tick(0.01), "0.01");
    assert_eq!(tick(0.0123456), "0.0123");
    assert_eq!(tick(1.5), "1.5");
    assert_eq!(tick(2.0), "2");
    assert_eq!(tick(20.000001), "20");
    assert_eq!(tick(1234.6), "1235");
}

#[test]
fn time_to_an_error_is_read_between_the_measured_points() {
    // RMSE 0.1 / sqrt(t): 0.05 at t = 4, 0.025 at t = 16.
    let pts: Vec<(f64, f64)> = [1.0, 4.0, 16.0, 64.0]
        .iter()
        .map(|&t: &f64| (t, 0.1 / t.sqrt()))
        .collect();
    let t = time_to(&pts, 0.025).unwrap();
    assert!((t - 16.0).abs() < 1e-9, "{t}");
    let t = time_to(&pts, 0.1 / 8.0f64.sqrt()).unwrap();
    assert!((t - 8.0).abs() < 1e-9, "log-log interpolation: {t}");
    assert_eq!(time_to(&pts, 0.2), Some(1.0), "reached at the first point");
    assert_eq!(time_to(&pts, 0.001), None, "never reached");
}

#[test]
fn a_peer_csv_is_read_and_bad_rows_name_the_line() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("peer.csv");
    std::fs::write(
        &good,
        "# mitsuba 3 llvm_ad_rgb path\nspp,seconds,rmse\n1,0.5,0.4\n4,1.0,0.2\n",
    )
    .unwrap();
    let p = Peer::load(&good).unwrap();
    assert_eq!(p.label, "mitsuba 3 llvm_ad_rgb path");
    assert_eq!(p.points, vec![(1, 0.5, 0.4), (4, 1.0, 0.2)]);
    // Rows of one sample count (several seeds) are averaged.
    let seeds = Peer {
        label: "x".into(),
        points: vec![(4, 1.0, 0.2), (1, 0.5, 0.4), (4, 3.0, 0.1), (1, 0.7, 0.6)],
    };
    let m = seeds.means();
    assert_eq!(m.len(), 2);
    assert!((m[0].0 - 0.6).abs() < 1e-12 && (m[0].1 - 0.5).abs() < 1e-12);
    assert!((m[1].0 - 2.0).abs() < 1e-12 && (m[1].1 - 0.15).abs() < 1e-12);
    let bad = dir.path().join("bad.csv");
    std::fs::write(&bad, "spp,seconds,rmse\n1,0.5,0.4\n4,oops,0.2\n").unwrap();
    let e = format!("{:#}", Peer::load(&bad).unwrap_err());
    assert!(e.contains("bad.csv:3") && e.contains("oops"), "{e}");
    let headless = dir.path().join("headless.csv");
    std::fs::write(&headless, "spp,time\n1,2\n").unwrap();
    let e = format!("{:#}", Peer::load(&headless).unwrap_err());
    assert!(e.contains("headless.csv:1") && e.contains("seconds"), "{e}");
}

#[test]
fn an_external_reference_must_match_the_render_size() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ref.exr");
    let img = image::Rgb32FImage::from_fn(4, 3, |x, y| image::Rgb([x as f32, y as f32, 1.0]));
    img.save(&path).unwrap();
    let px = load_reference(&path, 4, 3).unwrap();
    assert_eq!(px.len(), 12);
    assert_eq!(px[4 + 3], glam::Vec3::new(3.0, 1.0, 1.0));
    let e = format!("{:#}", load_reference(&path, 8, 6).unwrap_err());
    assert!(e.contains("ref.exr") && e.contains("4x3"), "{e}");
}

/// With `denoise`, the first sampler's renders are also measured denoised: a point per render,
/// timed longer than the plain render it came from (layers and denoising included), and
/// closer to the reference in relative error at every sample count.
#[cfg(feature = "denoise")]
#[test]
fn denoised_renders_are_measured_beside_the_plain_ones() {
    let mut scene = Scene::cornell_box();
    scene.integrator = tracery::render::Integrator::Path;
    let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
    let config = ConvergenceConfig {
        width: 160,
        height: 120,
        max_spp: 8,
        seeds: 1,
        reference_spp: 64 * 8,
        max_depth: 5,
        samplers: vec![SamplerKind::Sobol],
        target_rmse: None,
        denoise: true,
    };
    let report = run(&scene, &bvh, &config, None, &mut |_, _| {}).unwrap();
    assert_eq!(report.points.len(), 4 * 2);
    assert_eq!(report.denoised.len(), 4);
    for &(spp, seconds, _, relmse) in &report.denoised {
        let plain = report
            .points
            .iter()
            .find(|p| !p.denoised && p.spp == spp)
            .unwrap();
        assert!(seconds > plain.seconds, "{spp} spp: {seconds} s");
        assert!(
            relmse < plain.relmse,
            "{spp} spp: relMSE {relmse} denoised, {} plain",
            plain.relmse
        );
    }
}
