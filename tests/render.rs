//! Rendering: deterministic on any thread count, sane output, bad settings rejected; a render
//! split by samples merges into its bits.

mod common;

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
                let mut sum = tracery::film::Sum::ZERO;
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
                    sum.add_sample(tracer.radiance(
                        &ray,
                        &mut PathSampler::new(sampler),
                        &mut counts,
                    ));
                }
                assert_eq!(
                    film.sum[pixel as usize], sum,
                    "{path}, {integrator:?}: pixel ({x}, {y})"
                );
            }
        }
    }
}

/// A render split by samples merges into the whole render's bits: four even parts, and uneven
/// ones (a part of one sample among them), through the parts' files, on the Cornell box and
/// the dragon scene; parts of another scene, a duplicate range and a gap are refused, naming
/// the files.
#[test]
fn parts_of_a_render_merge_into_its_bits() {
    use std::path::PathBuf;
    use tracery::bvh::Accel;
    use tracery::render::part::{Part, PartKey, merge};
    use tracery::render::{EnvironmentMap, RenderPlan, render_samples};
    let mut scenes = vec![Scene::cornell_box()];
    if let Some(p) = common::external("dragon/dragon_vrip_res2.ply") {
        assert!(p.is_file());
        scenes.push(Scene::load(std::path::Path::new("assets/scenes/dragon.toml")).unwrap());
    }
    let dir = tempfile::tempdir().unwrap();
    let settings = RenderSettings {
        width: 160,
        height: 120,
        spp: 256,
        seed: 7,
        ..RenderSettings::default()
    };
    for scene in &scenes {
        let accel = Accel::for_scene(scene, &BuildOptions::sah()).unwrap();
        let whole = render(scene, &accel, &settings, &|_| {}).unwrap().film;
        let plan = RenderPlan::new(scene, &settings);
        let env = EnvironmentMap::load(&scene.environment, plan.environment).unwrap();
        let key = PartKey::of(scene, &settings);
        let part = |range: std::ops::Range<u32>| -> (PathBuf, Part) {
            let film =
                render_samples(scene, &accel, &env, &settings, plan, range.clone(), &|_| {}).film;
            let path = dir
                .path()
                .join(format!("{}_{}_{}.exr", scene.name, range.start, range.end));
            Part {
                film,
                range,
                key: key.clone(),
            }
            .save(&path)
            .unwrap();
            // Read back from its file, as `tracery merge` reads it.
            let read = Part::load(&path).unwrap();
            (path, read)
        };
        for split in [
            vec![0..64, 64..128, 128..192, 192..256],
            vec![100..256, 0..1, 1..100],
        ] {
            let parts: Vec<_> = split.into_iter().map(part).collect();
            let merged = merge(&parts).unwrap();
            assert_eq!(merged.samples, 256);
            assert!(
                merged.sum == whole.sum,
                "{}: the merged sums differ from the whole render's",
                scene.name
            );
            assert_eq!(merged.mean(), whole.mean());
        }
        let lit = whole
            .mean()
            .iter()
            .filter(|p| p.max_element() > 0.01)
            .count();
        assert!(
            lit * 2 > whole.sum.len(),
            "{}: {lit} lit pixels",
            scene.name
        );
    }

    // Refusals name the files.
    let scene = &scenes[0];
    let accel = Accel::for_scene(scene, &BuildOptions::sah()).unwrap();
    let small = RenderSettings {
        width: 16,
        height: 12,
        spp: 4,
        ..settings.clone()
    };
    let plan = RenderPlan::new(scene, &small);
    let env = EnvironmentMap::load(&scene.environment, plan.environment).unwrap();
    let make = |name: &str, range: std::ops::Range<u32>, key: PartKey| {
        let film = render_samples(scene, &accel, &env, &small, plan, range.clone(), &|_| {}).film;
        (PathBuf::from(name), Part { film, range, key })
    };
    let key = PartKey::of(scene, &small);
    let other = PartKey {
        scene: "0123456789abcdef".into(),
        ..key.clone()
    };
    let built_elsewhere = PartKey {
        build: "0.1.0 (0123456)".into(),
        ..key.clone()
    };
    let cases = [
        (
            vec![make("a.exr", 0..2, key.clone()), make("b.exr", 2..4, other)],
            "a.exr and b.exr are parts of renders of different scenes",
        ),
        (
            vec![
                make("a.exr", 0..2, key.clone()),
                make("e.exr", 2..4, built_elsewhere),
            ],
            "a.exr and e.exr were rendered by different builds of tracery",
        ),
        (
            vec![
                make("a.exr", 0..2, key.clone()),
                make("c.exr", 0..2, key.clone()),
            ],
            "c.exr (0..2) overlaps a.exr",
        ),
        (
            vec![
                make("a.exr", 0..2, key.clone()),
                make("d.exr", 3..4, key.clone()),
            ],
            "samples 2..3 are missing (before d.exr, after a.exr)",
        ),
        (
            vec![make("e.exr", 1..4, key.clone())],
            "samples 0..1 are missing (before e.exr)",
        ),
    ];
    for (parts, want) in cases {
        let e = merge(&parts).unwrap_err().to_string();
        assert!(e.contains(want), "{e}");
    }
}
