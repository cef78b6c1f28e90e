//! Error against time: random sampling converges as N^-1/2, the low-discrepancy sampler
//! reaches the same error sooner, and the outputs are written.

use std::path::Path;

use tracery::bvh::{BuildOptions, Bvh};
use tracery::convergence::{ConvergenceConfig, least_squares, plot, run, write_csv};
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
        samplers: vec![SamplerKind::Random, SamplerKind::Sobol],
        target_rmse: None,
    };
    let report = run(&scene, &bvh, &config, &mut |_, _| {}).unwrap();
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
    assert!(csv.starts_with("sampler,spp,seed,seconds,rmse,relmse"));
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
        samplers: vec![SamplerKind::Random],
        target_rmse: None,
    };
    assert!(format!("{:#}", config.validate().unwrap_err()).contains("64 x 16"));
    let bad = ConvergenceConfig {
        max_spp: 24,
        reference_spp: 64 * 24,
        ..config
    };
    assert!(bad.validate().is_err());
}
