//! Rendering: deterministic on any thread count, sane output, bad settings rejected.

use tracery::bvh::{BuildOptions, Bvh};
use tracery::render::{RenderSettings, render};
use tracery::scene::Scene;

fn render_with_threads(threads: usize, settings: &RenderSettings) -> tracery::film::Film {
    let scene = Scene::cornell_box();
    let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| render(&scene, &bvh, settings, &|_| {}).unwrap().film)
}

#[test]
fn image_is_identical_with_1_and_2_threads() {
    let settings = RenderSettings {
        width: 96,
        height: 64,
        spp: 3,
        seed: 42,
        ..RenderSettings::default()
    };
    let one = render_with_threads(1, &settings);
    let two = render_with_threads(2, &settings);
    assert_eq!(one, two);
    // A different seed gives a different (noisy) image.
    let other = render_with_threads(
        2,
        &RenderSettings {
            seed: 43,
            ..settings
        },
    );
    assert_ne!(one.sum, other.sum);
}

#[test]
fn cornell_box_render_is_lit_and_finite() {
    let settings = RenderSettings {
        width: 64,
        height: 64,
        spp: 4,
        seed: 0,
        ..RenderSettings::default()
    };
    let film = render_with_threads(2, &settings);
    assert_eq!(film.rejected, 0);
    let mean = film.mean();
    assert!(mean.iter().all(|c| c.is_finite() && c.min_element() >= 0.0));
    // The light (top centre) is the brightest thing in view; the walls are lit.
    let px = |x: usize, y: usize| mean[y * 64 + x];
    assert!(px(32, 9).max_element() > 1.0, "light {}", px(32, 9));
    assert!(px(8, 32).x > px(8, 32).y, "the left wall is red");
    assert!(px(56, 32).y > px(56, 32).x, "the right wall is green");
    let rgba = film.to_rgba8(1.0);
    assert_eq!(rgba.len(), 64 * 64 * 4);
}

#[test]
fn empty_images_and_zero_samples_are_rejected() {
    for (w, h, spp) in [(0, 10, 1), (10, 0, 1), (10, 10, 0)] {
        let s = RenderSettings {
            width: w,
            height: h,
            spp,
            ..RenderSettings::default()
        };
        assert!(s.validate().is_err(), "{w}x{h} {spp} spp");
    }
    assert!(RenderSettings::default().validate().is_ok());
}

#[test]
fn fast_srgb_encoding_is_within_one_level_of_the_exact_curve() {
    use tracery::film::{srgb8, srgb8_fast};
    let mut worst = 0;
    for i in 0..=200_000 {
        let x = i as f32 / 200_000.0;
        worst = worst.max(srgb8(x).abs_diff(srgb8_fast(x)));
    }
    assert!(worst <= 1, "off by {worst} levels");
    assert_eq!(srgb8_fast(0.0), 0);
    assert_eq!(srgb8_fast(1.0), 255);
    assert_eq!(srgb8_fast(-3.0), 0);
    assert_eq!(srgb8_fast(7.0), 255);
    assert_eq!(srgb8_fast(f32::NAN), 0);
}
