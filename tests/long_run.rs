//! The long run: 10,000 frames of the viewer's windowless app (`MinimalPlugins` and
//! the core plugins) with a random setting change every few frames: camera moves, resolution
//! scale, the still delay, bounce depth, shadows, sampler, the denoiser, depth of field, environment,
//! render mode and level, BVH split, bins and leaf size, and scene switches including a bad
//! file. Nothing may panic, every picture shown must be of a job no older than the last
//! picture's and no newer than the newest sent, and of its size, and memory must stay flat. The only test in its binary, so the resident memory it
//! reads is its own.
#![cfg(feature = "viewer")]

use std::path::PathBuf;

use bevy::prelude::*;
use tracery::bvh::{BuildOptions, SplitMethod};
use tracery::rng::SplitMix64;
use tracery::sampling::SamplerKind;
use tracery::scene::Scene;
use tracery::viewer::CorePlugins;
use tracery::viewer::bvh::{BvhSettings, SceneBvh};
use tracery::viewer::camera::pose_of;
use tracery::viewer::scene::{CurrentScene, LoadScene, ViewerStatus};
use tracery::viewer::trace::{
    Accumulation, EnvChoice, RenderMode, TraceCamera, TraceStats, TracedImage, ViewSettings,
};

const FRAMES: u32 = 10_000;

/// Resident memory of this process in KiB (Linux), if it can be read.
fn rss_kib() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

fn scene_path(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("assets/scenes")
        .join(name)
}

#[test]
fn ten_thousand_frames_of_random_changes_run_flat() {
    let mut app = App::new();
    app.add_plugins(MinimalPlugins).add_plugins(CorePlugins {
        scene: None,
        bvh: BuildOptions::sah(),
        settings: ViewSettings {
            max_samples: 16,
            // Short steps: the run is about state changes, not pictures.
            moving_budget_ms: 1.0,
            ..ViewSettings::default()
        },
        viewport: UVec2::new(48, 32),
        interactive: false,
    });
    let (t, p) = pose_of(&Scene::cornell_box().camera);
    app.world_mut().spawn((t, p, TraceCamera));
    // The denoiser (on by default) starts its library's threads and buffers at its first
    // picture, once: a denoised still picture is waited for before the run, so that what the
    // run measures is its own growth.
    if tracery::denoise::AVAILABLE {
        let start = std::time::Instant::now();
        while !app.world().resource::<TraceStats>().denoised {
            app.update();
            assert!(
                start.elapsed().as_secs() < 60,
                "no denoised picture in 60 s"
            );
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
    }

    let bad = tempfile::NamedTempFile::with_suffix(".obj").unwrap();
    std::fs::write(bad.path(), "v 0 0 0\nv 1 0\nf 1 2 3\n").unwrap();
    let scenes = [
        scene_path("cornell_mirror_glass.toml"),
        scene_path("transparent_shadow.toml"),
        scene_path("cornell_box.toml"),
        // Normal-mapped panels (the normal-map switch above then changes the picture).
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/reference/scenes/normal_map.toml"),
        // One glTF material whose metallic-roughness texture makes mirrors and rough spheres.
        scene_path("gltf_metal_rough.toml"),
        bad.path().to_path_buf(),
    ];

    let mut rng = SplitMix64::new(2026);
    let mut pick = |n: u64| rng.next_u64() % n;
    // Resident memory every 50 frames after the first 1,000, by half of the run.
    let mut halves: [Vec<u64>; 2] = [Vec::new(), Vec::new()];
    let mut images = 0u64;
    let mut errors = 0u32;
    let mut scenes_seen = std::collections::HashSet::new();
    let mut last_version = 0;
    let mut last_generation = 0;
    for frame in 0..FRAMES {
        if frame % 7 == 0 {
            let w = app.world_mut();
            match pick(12) {
                0..=2 => {
                    let mut q = w.query_filtered::<&mut Transform, With<TraceCamera>>();
                    for mut t in q.iter_mut(w) {
                        let step = Vec3::new(
                            pick(21) as f32 - 10.0,
                            pick(21) as f32 - 10.0,
                            pick(21) as f32 - 10.0,
                        ) * 0.05;
                        t.translation += step;
                        t.rotate_y((pick(9) as f32 - 4.0) * 0.05);
                    }
                }
                3 => {
                    let mut s = w.resource_mut::<ViewSettings>();
                    s.scale = [0.25, 0.5, 1.0][pick(3) as usize];
                    s.still_after_ms = [0.0, 5.0, 120.0][pick(3) as usize];
                }
                4 => {
                    let mut s = w.resource_mut::<ViewSettings>();
                    s.max_depth = pick(7) as u32;
                    s.shadows = pick(4) != 0;
                    s.transparent_shadows = pick(2) == 0;
                    s.normal_maps = pick(2) == 0;
                    s.sampler = [SamplerKind::Sobol, SamplerKind::Random][pick(2) as usize];
                    s.denoise = tracery::denoise::AVAILABLE && pick(4) != 0;
                }
                5 => {
                    let mut s = w.resource_mut::<ViewSettings>();
                    s.depth_of_field = pick(2) == 0;
                    s.lens_radius = [0.0, 0.05, 0.5, 1e3][pick(4) as usize];
                    s.focus_distance = [0.5, 5.0, 1e6, f32::INFINITY][pick(4) as usize];
                }
                6 => {
                    let mut s = w.resource_mut::<ViewSettings>();
                    s.environment = [EnvChoice::FromScene, EnvChoice::None, EnvChoice::Sky]
                        [pick(3) as usize]
                        .clone();
                    s.env_intensity = [0.0, 0.5, 4.0][pick(3) as usize];
                    s.env_rotation_deg = pick(360) as f32;
                }
                7 => {
                    let mut s = w.resource_mut::<ViewSettings>();
                    s.mode = [
                        RenderMode::Shaded,
                        RenderMode::TraversalCost,
                        RenderMode::Overlap,
                        RenderMode::Work,
                    ][pick(4) as usize];
                    s.level = pick(12) as u32;
                    s.exposure = [0.25, 1.0, 8.0][pick(3) as usize];
                }
                8 | 9 => {
                    let mut b = w.resource_mut::<BvhSettings>();
                    b.0.split = [SplitMethod::Sah, SplitMethod::Median][pick(2) as usize];
                    b.0.bins = 2 + pick(63) as u32;
                    b.0.max_leaf_size = 1 + pick(16) as u32;
                }
                10 => {
                    let p = scenes[pick(scenes.len() as u64) as usize].clone();
                    w.write_message(LoadScene(p));
                }
                _ => {} // a few frames of plain accumulation
            }
        }
        let newest = app.world().resource::<Accumulation>().generation;
        app.update();
        // Frames of about a millisecond: the worker traces beside them.
        std::thread::sleep(std::time::Duration::from_millis(1));

        let image = app.world().resource::<TracedImage>();
        if image.version != last_version {
            last_version = image.version;
            images += 1;
            // The newest job's picture, or a moving picture a frame late (what it may differ in
            // is checked in viewer_app.rs); never one older than a picture shown.
            assert!(
                image.generation <= newest && image.generation >= last_generation,
                "frame {frame}: a picture of job {} after one of job {last_generation} (newest {newest})",
                image.generation
            );
            last_generation = image.generation;
            assert!(
                image.rgba.is_empty()
                    || image.rgba.len() == (image.width * image.height * 4) as usize,
                "frame {frame}: image buffer does not match its size"
            );
        }
        if let Some(e) = &app.world().resource::<ViewerStatus>().error {
            assert!(
                e.contains(".obj"),
                "frame {frame}: an error that names no file: {e}"
            );
            errors += 1;
        }
        scenes_seen.insert(app.world().resource::<CurrentScene>().scene.name.clone());
        if frame >= 1_000
            && frame % 50 == 0
            && let Some(r) = rss_kib()
        {
            halves[usize::from(frame >= (1_000 + FRAMES) / 2)].push(r);
        }
    }
    assert!(images > 500, "only {images} images over {FRAMES} frames");
    let builds = app.world().resource::<SceneBvh>().builds;
    println!(
        "{images} images, {builds} BVH builds, scenes {scenes_seen:?}, {errors} frames showing an error"
    );
    assert!(builds > 20, "only {builds} BVH builds");
    assert!(scenes_seen.len() >= 3, "scenes seen: {scenes_seen:?}");
    assert!(errors > 0, "the broken file never showed its error");
    if halves.iter().all(|h| !h.is_empty()) {
        // Flat: the films, BVHs and scenes of one state are freed when the next replaces them.
        // The medians of the two halves are compared, not a peak against one reading: the
        // allocator's high-water mark moves by several MB from state to state (the
        // denoiser's threads keep arenas of their own), and a leak moves the median with it.
        // A leak of 2 KB a frame would add 9 MB from one median to the other.
        let median = |h: &mut Vec<u64>| {
            h.sort_unstable();
            h[h.len() / 2]
        };
        let [a, b] = &mut halves;
        let (first, second) = (median(a), median(b));
        println!(
            "resident memory: median {first} KiB over frames 1000-{}, {second} KiB after",
            (1_000 + FRAMES) / 2
        );
        assert!(
            second < first + 8 * 1024,
            "memory grew from a median of {first} KiB to {second} KiB over {FRAMES} frames"
        );
    }
}
