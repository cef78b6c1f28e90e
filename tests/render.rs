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
    use tracery::color::{srgb8, srgb8_fast};
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

/// The render traces camera rays in 8 x 8 tiles of packets, and the path integrator advances a
/// tile's paths together; each pixel must still get exactly what tracing it alone gives (its
/// own sample stream, its own single-ray hits), on an image whose sides are not multiples of
/// the tile (partial tiles and a partial last band), with and without the thin lens, through
/// mirrors and glass (the paths' stacks of waiting vertices) and transparent shadows, with both
/// integrators.
#[test]
fn tiled_render_equals_each_pixel_traced_alone() {
    use tracery::camera::CameraRays;
    use tracery::render::Integrator;
    use tracery::render::{EnvironmentMap, RayCounts, RenderPlan, Tracer};
    use tracery::sampling::{PathSampler, PixelSampler, concentric_disk, dim};
    let scenes = [
        "assets/scenes/cornell_mirror_glass.toml",
        "assets/scenes/depth_of_field.toml",
        "assets/scenes/transparent_shadow.toml",
    ];
    for (path, integrator) in scenes
        .into_iter()
        .flat_map(|p| [(p, Integrator::Direct), (p, Integrator::Path)])
    {
        let mut scene = Scene::load(std::path::Path::new(path)).unwrap();
        scene.integrator = integrator;
        let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
        let settings = RenderSettings {
            width: 37,
            height: 21,
            spp: 2,
            seed: 5,
            ..RenderSettings::default()
        };
        let film = render(&scene, &bvh, &settings, &|_| {}).unwrap().film;

        let plan = RenderPlan::new(&scene, &settings);
        let env = EnvironmentMap::load(&scene.environment, plan.environment).unwrap();
        let tracer = Tracer::new(&scene, &bvh, plan, settings.max_depth, &env);
        let cam = CameraRays::new(&scene.camera, settings.width, settings.height);
        let thin_lens = plan.thin_lens && cam.lens_radius > 0.0;
        for y in 0..settings.height {
            for x in 0..settings.width {
                let pixel = (y * settings.width + x) as u64;
                let mut sum = glam::Vec3::ZERO;
                for s in 0..settings.spp {
                    let sampler =
                        PixelSampler::new(settings.sampler, settings.seed, pixel, 0).with_index(s);
                    let j = sampler.get_2d(dim::PIXEL);
                    let (px, py) = (x as f32 + j.x, y as f32 + j.y);
                    let ray = if thin_lens {
                        cam.thin_lens(px, py, concentric_disk(sampler.get_2d(dim::LENS)))
                    } else {
                        cam.pinhole(px, py)
                    };
                    let mut counts = RayCounts::default();
                    sum += tracer.radiance(&ray, &mut PathSampler::new(sampler), &mut counts);
                }
                assert_eq!(
                    film.sum[pixel as usize], sum,
                    "{path}, {integrator:?}: pixel ({x}, {y})"
                );
            }
        }
    }
}
