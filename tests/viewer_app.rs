//! The viewer's ECS without a window (`MinimalPlugins`, `app.update()`): the BVH is rebuilt
//! exactly when its settings or the scene change, accumulation starts over when the camera
//! moves, a stale job's picture is never shown, a pure pan carries every still-valid pixel
//! over, a bad file keeps the old scene and shows its error, a debug ray's hits are the
//! core's closest hits, the traced image equals the headless render of the same view, and the
//! denoised still picture is the headless render denoised.
#![cfg(feature = "viewer")]

mod common;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use bevy::prelude::*;
use tracery::bvh::{BuildOptions, Bvh, SplitMethod};
use tracery::render::cache::MovingFilter;
use tracery::render::{RenderSettings, render};
use tracery::scene::Scene;
use tracery::viewer::CorePlugins;
use tracery::viewer::bvh::{BvhSettings, SceneBvh};
use tracery::viewer::camera::pose_of;
use tracery::viewer::debug_ray::{DebugRay, ShootRay, ray_through};
use tracery::viewer::scene::{CurrentScene, LoadScene, SceneLoading, ViewerStatus};
use tracery::viewer::trace::{
    Accumulation, TraceCamera, TraceStats, TraceWorker, TracedImage, ViewSettings, ViewportSize,
    camera_rays,
};

const SIZE: UVec2 = UVec2::new(64, 48);

fn app(scene: Option<&str>) -> App {
    let mut app = App::new();
    app.add_plugins(MinimalPlugins).add_plugins(CorePlugins {
        scene: scene.map(PathBuf::from),
        bvh: BuildOptions::sah(),
        settings: ViewSettings {
            max_samples: 64,
            // The pictures shown are the traced ones (the denoised still has a test of its own).
            denoise: false,
            ..ViewSettings::default()
        },
        viewport: SIZE,
        interactive: false,
    });
    let camera = match scene {
        Some(p) => Scene::load(Path::new(p)).unwrap().camera,
        None => Scene::cornell_box().camera,
    };
    let (t, p) = pose_of(&camera);
    app.world_mut().spawn((t, p, TraceCamera));
    app
}

/// Updates until `done` holds (panics after 60 s).
fn settle(app: &mut App, what: &str, done: impl Fn(&World) -> bool) {
    let start = Instant::now();
    loop {
        app.update();
        if done(app.world()) {
            return;
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "timed out: {what}"
        );
        std::thread::sleep(Duration::from_millis(1));
    }
}

fn builds(app: &App) -> u64 {
    app.world().resource::<SceneBvh>().builds
}

fn idle(w: &World) -> bool {
    w.resource::<SceneLoading>().current().is_none()
}

#[test]
fn bvh_is_rebuilt_exactly_when_its_settings_or_the_scene_change() {
    let mut app = app(None);
    settle(&mut app, "first build", |w| {
        w.resource::<SceneBvh>().builds == 1
    });
    for _ in 0..20 {
        app.update();
    }
    assert_eq!(builds(&app), 1, "nothing changed: no rebuild");

    // Writing the same settings again (change detection fires, the value is the same).
    let same = app.world().resource::<BvhSettings>().0;
    app.world_mut().resource_mut::<BvhSettings>().0 = same;
    for _ in 0..20 {
        app.update();
    }
    assert_eq!(builds(&app), 1, "same settings: no rebuild");

    for (n, change) in [
        (
            2,
            BuildOptions {
                max_leaf_size: 1,
                ..BuildOptions::sah()
            },
        ),
        (
            3,
            BuildOptions {
                bins: 4,
                max_leaf_size: 1,
                ..BuildOptions::sah()
            },
        ),
        (4, BuildOptions::median()),
    ] {
        app.world_mut().resource_mut::<BvhSettings>().0 = change;
        settle(&mut app, "rebuild", |w| {
            w.resource::<SceneBvh>().builds == n
        });
        for _ in 0..10 {
            app.update();
        }
        assert_eq!(builds(&app), n, "one rebuild per change");
        let bvh = app.world().resource::<SceneBvh>();
        assert_eq!(bvh.bvh.as_ref().unwrap().options, change);
        assert_eq!(bvh.key.unwrap().options.split, change.split);
    }
    assert_eq!(
        app.world().resource::<BvhSettings>().0.split,
        SplitMethod::Median
    );

    // A new scene: exactly one more build, for the new scene.
    app.world_mut()
        .write_message(LoadScene("assets/scenes/cornell_mirror_glass.toml".into()));
    settle(&mut app, "scene load", |w| {
        w.resource::<CurrentScene>().generation == 1
    });
    settle(&mut app, "build for the new scene", |w| {
        w.resource::<SceneBvh>().builds == 5
    });
    for _ in 0..10 {
        app.update();
    }
    assert_eq!(builds(&app), 5);
    let w = app.world();
    let gen_ = w.resource::<CurrentScene>().generation;
    assert!(w.resource::<SceneBvh>().for_scene(gen_).is_some());
}

#[test]
fn accumulation_resets_when_the_camera_moves_and_only_then() {
    let mut app = app(None);
    settle(&mut app, "3 samples", |w| {
        w.resource::<Accumulation>().full_passes() >= 3
    });
    let resets = app.world().resource::<Accumulation>().resets;
    let passes = app.world().resource::<Accumulation>().full_passes();
    app.update();
    let acc = app.world().resource::<Accumulation>();
    assert_eq!(acc.resets, resets, "a still camera keeps accumulating");
    assert!(acc.full_passes() >= passes);

    // Exposure only re-maps the picture: the passes go on.
    app.world_mut().resource_mut::<ViewSettings>().exposure = 2.0;
    app.update();
    assert_eq!(app.world().resource::<Accumulation>().resets, resets);
    settle(&mut app, "the re-mapped picture", |w| {
        let (i, a) = (w.resource::<TracedImage>(), w.resource::<Accumulation>());
        i.generation == a.generation && i.samples >= passes
    });

    // Moving the camera starts over, with the moving picture shown first (the still one waits
    // for the view to stay put).
    app.world_mut()
        .resource_mut::<ViewSettings>()
        .still_after_ms = 1e6;
    let mut q = app
        .world_mut()
        .query_filtered::<&mut Transform, With<TraceCamera>>();
    q.single_mut(app.world_mut()).unwrap().translation.x += 0.01;
    app.update();
    let acc = app.world().resource::<Accumulation>();
    assert_eq!(acc.resets, resets + 1);
    assert_eq!(acc.full_passes(), 0);
    settle(&mut app, "the moving picture", |w| {
        w.resource::<TracedImage>().generation == w.resource::<Accumulation>().generation
    });
    let image = app.world().resource::<TracedImage>();
    assert!(image.preview);
    assert_eq!((image.width, image.height), (SIZE.x, SIZE.y), "full size");

    // The still picture follows once the view has stayed put.
    app.world_mut()
        .resource_mut::<ViewSettings>()
        .still_after_ms = 0.0;
    settle(&mut app, "the still picture", |w| {
        let i = w.resource::<TracedImage>();
        !i.preview && i.samples >= 1
    });
    let resets = app.world().resource::<Accumulation>().resets;
    assert_eq!(resets, app.world().resource::<Accumulation>().resets);

    // Turning the camera, or a render setting, also starts over.
    q.single_mut(app.world_mut()).unwrap().rotate_y(0.01);
    app.update();
    assert_eq!(app.world().resource::<Accumulation>().resets, resets + 1);
    app.world_mut().resource_mut::<ViewSettings>().max_depth = 1;
    app.update();
    assert_eq!(app.world().resource::<Accumulation>().resets, resets + 2);
}

/// Every frame changes the view or a setting (the worker has to drop what it was doing). A
/// picture taken is of the newest job's settings: of the newest job, or of one sent after the
/// last change of settings whose view alone is out of date (a moving picture a frame late);
/// pictures never go back in time, and some jobs were abandoned.
#[test]
fn a_stale_jobs_picture_is_never_shown() {
    let mut app = app(Some("assets/scenes/cornell_mirror_glass.toml"));
    app.world_mut().resource_mut::<ViewportSize>().0 = UVec2::new(320, 240);
    settle(&mut app, "scene and BVH", |w| {
        let g = w.resource::<CurrentScene>().generation;
        g == 1 && w.resource::<SceneBvh>().for_scene(g).is_some()
    });
    let (mut shown, mut late, mut last_shown) = (0, 0, 0);
    // The first job of the newest settings.
    let mut settings_from = app.world().resource::<Accumulation>().generation;
    for frame in 0..300u32 {
        let settings_changed = {
            let w = app.world_mut();
            match frame % 4 {
                0 => {
                    let mut q = w.query_filtered::<&mut Transform, With<TraceCamera>>();
                    q.single_mut(w).unwrap().rotate_y(0.003);
                    false
                }
                1 => {
                    w.resource_mut::<ViewSettings>().seed = frame as u64;
                    true
                }
                2 => {
                    w.resource_mut::<ViewSettings>().max_depth = 1 + frame % 5;
                    true
                }
                _ => false, // the same job for one more frame
            }
        };
        let newest = app.world().resource::<Accumulation>().generation;
        let version = app.world().resource::<TracedImage>().version;
        app.update();
        let image = app.world().resource::<TracedImage>();
        if image.version != version {
            shown += 1;
            // Pictures are taken before this frame's job is sent.
            assert!(
                image.generation >= settings_from && image.generation <= newest,
                "frame {frame}: the picture of job {} shown, but the settings changed with job {settings_from} (newest {newest})",
                image.generation
            );
            assert!(
                image.generation >= last_shown,
                "frame {frame}: the picture of job {} shown after one of job {last_shown}",
                image.generation
            );
            late += usize::from(image.generation != newest);
            last_shown = image.generation;
        }
        if settings_changed {
            settings_from = app.world().resource::<Accumulation>().generation;
        }
        std::thread::sleep(Duration::from_millis(frame as u64 % 7));
    }
    assert!(
        shown > 10,
        "only {shown} pictures shown ({late} a frame late)"
    );
    let w = app.world().resource::<TraceWorker>().0.shared.stats();
    assert!(w.abandoned > 0, "no job was ever abandoned: {w:?}");
    // And the last job's picture comes.
    settle(&mut app, "the last job's picture", |w| {
        w.resource::<TracedImage>().generation == w.resource::<Accumulation>().generation
    });
}

/// The moving picture of a camera that turned in place (a pure pan), with nothing traced
/// after the turn: every pixel that one earlier pixel clearly falls on holds that pixel's
/// value, byte for byte.
#[test]
fn reprojection_of_a_pure_pan_keeps_every_still_valid_pixel() {
    let mut app = app(None);
    {
        let mut settings = app.world_mut().resource_mut::<ViewSettings>();
        settings.still_after_ms = 1e6;
        // The carried samples themselves, not averaged with their neighbours for display.
        settings.moving_filter = MovingFilter::Off;
    }
    settle(&mut app, "a complete moving picture", |w| {
        let (i, s) = (w.resource::<TracedImage>(), w.resource::<TraceStats>());
        i.preview && s.holes == 0 && i.generation == w.resource::<Accumulation>().generation
    });
    // From now on nothing is traced: the pictures only carry the samples over.
    app.world_mut()
        .resource_mut::<ViewSettings>()
        .moving_budget_ms = 0.0;
    let picture = |app: &mut App| {
        settle(app, "the picture of the newest job", |w| {
            w.resource::<TracedImage>().generation == w.resource::<Accumulation>().generation
        });
        let w = app.world_mut();
        let rgba = w.resource::<TracedImage>().rgba.clone();
        let mut q = w.query_filtered::<(&Transform, &Projection), With<TraceCamera>>();
        let (t, p) = q.single(w).unwrap();
        let settings = w.resource::<ViewSettings>();
        (rgba, camera_rays(t, p, SIZE, settings))
    };
    app.update();
    let (before, from) = picture(&mut app);
    let mut q = app
        .world_mut()
        .query_filtered::<&mut Transform, With<TraceCamera>>();
    q.single_mut(app.world_mut()).unwrap().rotate_y(0.06);
    app.update();
    let (after, to) = picture(&mut app);
    assert_ne!(before, after, "the view turned");

    // Where each pixel centre's direction lands in the new view, and whether it lands clear
    // of the pixel's edges.
    let mut sources: std::collections::HashMap<usize, Vec<(usize, bool)>> = Default::default();
    for y in 0..SIZE.y {
        for x in 0..SIZE.x {
            let d = from.direction(x as f32 + 0.5, y as f32 + 0.5);
            let Some((px, py)) = to.pixel_of(d) else {
                continue;
            };
            let clear = |v: f32| v - v.floor() > 0.01 && v - v.floor() < 0.99;
            let inside = px >= 0.0 && py >= 0.0 && px < SIZE.x as f32 && py < SIZE.y as f32;
            if inside {
                let to_pixel = py as usize * SIZE.x as usize + px as usize;
                sources
                    .entry(to_pixel)
                    .or_default()
                    .push(((y * SIZE.x + x) as usize, clear(px) && clear(py)));
            }
        }
    }
    let mut kept = 0;
    for (to_pixel, from_pixels) in &sources {
        if let [(from_pixel, true)] = from_pixels[..] {
            assert_eq!(
                after[to_pixel * 4..to_pixel * 4 + 4],
                before[from_pixel * 4..from_pixel * 4 + 4],
                "pixel {to_pixel} should hold the sample of pixel {from_pixel}"
            );
            kept += 1;
        }
    }
    let total = (SIZE.x * SIZE.y) as usize;
    assert!(kept > total / 2, "only {kept} of {total} pixels checked");
}

#[test]
fn a_bad_file_keeps_the_old_scene_and_shows_its_error() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("broken.obj");
    std::fs::write(&bad, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n").unwrap();
    let missing = dir.path().join("missing.ply");

    let mut app = app(None);
    settle(&mut app, "first build", |w| {
        w.resource::<SceneBvh>().builds == 1
    });
    for path in [&bad, &missing] {
        app.world_mut().write_message(LoadScene(path.clone()));
        app.update();
        settle(&mut app, "load attempt", idle);
        let w = app.world();
        let current = w.resource::<CurrentScene>();
        assert_eq!(current.generation, 0, "the old scene stays");
        assert_eq!(current.scene.name, Scene::cornell_box().name);
        let error = w
            .resource::<ViewerStatus>()
            .error
            .clone()
            .expect("an error");
        assert!(
            error.contains(&path.display().to_string()),
            "the error names the file: {error}"
        );
        for _ in 0..5 {
            app.update();
        }
        assert_eq!(builds(&app), 1, "no rebuild for a failed load");
    }
    let error = app
        .world()
        .resource::<ViewerStatus>()
        .error
        .clone()
        .unwrap();
    assert!(error.contains("missing.ply"));
    // The OBJ error also gives the line.
    app.world_mut().write_message(LoadScene(bad.clone()));
    app.update();
    settle(&mut app, "load attempt", idle);
    let error = app
        .world()
        .resource::<ViewerStatus>()
        .error
        .clone()
        .unwrap();
    assert!(error.contains("broken.obj:4"), "{error}");

    // A good file afterwards clears the error.
    app.world_mut()
        .write_message(LoadScene("assets/scenes/cornell_box.toml".into()));
    app.update();
    settle(&mut app, "good load", |w| {
        w.resource::<CurrentScene>().generation == 1
    });
    assert!(app.world().resource::<ViewerStatus>().error.is_none());
}

#[test]
fn debug_ray_hits_equal_the_cores_closest_hits() {
    let scene = "assets/scenes/cornell_mirror_glass.toml";
    let mut app = app(Some(scene));
    settle(&mut app, "scene and BVH", |w| {
        let g = w.resource::<CurrentScene>().generation;
        g == 1 && w.resource::<SceneBvh>().for_scene(g).is_some()
    });
    let mut q = app
        .world_mut()
        .query_filtered::<(&Transform, &Projection), With<TraceCamera>>();
    let (mut segments, mut bounces) = (0, 0);
    for y in (2..SIZE.y).step_by(7) {
        for x in (2..SIZE.x).step_by(7) {
            let p = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
            app.world_mut().write_message(ShootRay(p));
            app.update();
            let w = app.world();
            let debug = w.resource::<DebugRay>();
            assert_eq!(debug.pixel, Some(p));
            let tree = w.resource::<SceneBvh>().bvh.clone().unwrap();
            let (t, proj) = q.single(w).unwrap();
            let settings = w.resource::<ViewSettings>();
            let camera_ray = ray_through(t, proj, w.resource::<ViewportSize>().0, settings, p);
            assert_eq!(debug.path.segments[0].ray.origin, camera_ray.origin);
            assert!((debug.path.segments[0].ray.dir - camera_ray.dir.normalize()).length() < 1e-6);
            for seg in &debug.path.segments {
                let core = tree.intersect(&seg.ray, f32::INFINITY);
                assert_eq!(
                    seg.hit.map(|h| (h.t, h.prim)),
                    core.map(|h| (h.t, h.prim)),
                    "pixel {p}"
                );
                segments += 1;
            }
            bounces += debug.path.segments.len() - 1;
        }
    }
    assert!(
        segments > 50 && bounces > 0,
        "{segments} segments, {bounces} bounces"
    );
}

#[test]
fn traced_image_equals_the_headless_render_of_the_same_view() {
    traced_equals_headless(None, |_| true);
}

/// The same with normal maps (the normal-mapped panels of the reference scene).
#[test]
fn traced_image_with_normal_maps_equals_the_headless_render() {
    traced_equals_headless(Some("tests/reference/scenes/normal_map.toml"), |m| {
        m.normal_map.is_some()
    });
}

/// The same with height maps (the bump-mapped panels of the reference scene).
#[test]
fn traced_image_with_height_maps_equals_the_headless_render() {
    traced_equals_headless(Some("tests/reference/scenes/height_map.toml"), |m| {
        m.height_map.is_some()
    });
}

/// The same with a glTF material's metallic-roughness texture (the five spheres, path
/// traced), seen by a camera that looks down on them.
#[test]
fn traced_image_with_metallic_roughness_textures_equals_the_headless_render() {
    traced_equals_headless(Some("assets/scenes/gltf_metal_rough.toml"), |m| {
        m.pbr.as_ref().is_some_and(|p| p.map.is_some())
    });
}

/// The viewer's still picture of `scene` (the built-in Cornell box for `None`) at 4 samples
/// per pixel, from the scene's camera, against the headless render of the same scene, which
/// must have a material that `has` accepts.
fn traced_equals_headless(path: Option<&str>, has: fn(&tracery::scene::Material) -> bool) {
    let mut app = app(path);
    app.world_mut().resource_mut::<ViewSettings>().max_samples = 4;
    settle(&mut app, "4 samples", |w| {
        let i = w.resource::<TracedImage>();
        !i.preview && i.samples == 4 && i.generation == w.resource::<Accumulation>().generation
    });
    let shown = app.world().resource::<TracedImage>().rgba.clone();

    let scene = match path {
        Some(p) => Scene::load(Path::new(p)).unwrap(),
        None => Scene::cornell_box(),
    };
    assert!(
        scene.materials.iter().any(has),
        "{path:?}: no such material"
    );
    let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
    let settings = RenderSettings {
        width: SIZE.x,
        height: SIZE.y,
        spp: 4,
        ..RenderSettings::default()
    };
    let headless = render(&scene, &bvh, &settings, &|_| {})
        .unwrap()
        .film
        .to_rgba8(1.0);
    assert_eq!(shown.len(), headless.len());
    // Exactly: the viewer's camera pose (a rotation quaternion) gives the headless look-at
    // frame's rays bit for bit at the scene's camera, and the samples are the same.
    let differ = shown.iter().zip(&headless).filter(|(a, b)| a != b).count();
    assert_eq!(differ, 0, "{differ} of {} bytes differ", shown.len());
}

#[test]
fn the_camera_ignores_input_while_the_inspector_has_it() {
    use bevy::camera_controller::free_camera::FreeCameraState;
    use tracery::viewer::UiFocus;
    use tracery::viewer::camera::{FlyCamera, FlyCameraPlugin};

    let mut app = app(None);
    app.add_plugins((bevy::input::InputPlugin, FlyCameraPlugin));
    let cam = app
        .world_mut()
        .query_filtered::<Entity, With<TraceCamera>>()
        .single(app.world())
        .unwrap();
    app.world_mut().entity_mut(cam).insert(FlyCamera);
    app.update();
    app.update();
    let enabled = |app: &App| app.world().get::<FreeCameraState>(cam).unwrap().enabled;
    assert!(enabled(&app), "free to fly with the inspector idle");
    for focus in [
        UiFocus {
            pointer: true,
            keyboard: false,
        },
        UiFocus {
            pointer: false,
            keyboard: true,
        },
    ] {
        *app.world_mut().resource_mut::<UiFocus>() = focus;
        app.update();
        assert!(
            !enabled(&app),
            "{focus:?}: the camera leaves the input to the inspector"
        );
        *app.world_mut().resource_mut::<UiFocus>() = UiFocus::default();
        app.update();
        assert!(enabled(&app));
    }
}

/// With the denoiser on, the still picture shown at its sample limit is the headless render of
/// the same samples denoised with the same render layers (to within OIDN's own rounding), and
/// differs from the picture as traced.
#[cfg(feature = "denoise")]
#[test]
fn the_denoised_still_picture_is_the_headless_render_denoised() {
    use tracery::denoise::{Denoiser, Inputs};
    use tracery::film::rmse_levels;
    use tracery::render::{EnvironmentMap, RenderPlan, render_layers};
    use tracery::viewer::still_denoise::LAYER_SAMPLES;

    let mut app = app(None);
    {
        let mut s = app.world_mut().resource_mut::<ViewSettings>();
        s.max_samples = 4;
        s.integrator = Some(tracery::render::Integrator::Path);
        s.denoise = true;
    }
    settle(&mut app, "4 samples, denoised", |w| {
        let (i, s) = (w.resource::<TracedImage>(), w.resource::<TraceStats>());
        !i.preview
            && i.samples == 4
            && s.denoised
            && i.generation == w.resource::<Accumulation>().generation
    });
    let shown = app.world().resource::<TracedImage>().rgba.clone();

    let mut scene = Scene::cornell_box();
    scene.integrator = tracery::render::Integrator::Path;
    let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
    let settings = RenderSettings {
        width: SIZE.x,
        height: SIZE.y,
        spp: 4,
        ..RenderSettings::default()
    };
    let plain = render(&scene, &bvh, &settings, &|_| {}).unwrap().film;
    let plan = RenderPlan::new(&scene, &settings);
    let layer_settings = RenderSettings {
        spp: LAYER_SAMPLES,
        ..settings.clone()
    };
    let layers = render_layers(&scene, &bvh, &EnvironmentMap::None, &layer_settings, plan);
    let clean = Denoiser::new()
        .unwrap()
        .run(&Inputs {
            width: SIZE.x,
            height: SIZE.y,
            color: &plain.mean(),
            albedo: Some(&layers.albedo_mean()),
            normal: Some(&layers.normal_mean()),
        })
        .unwrap();
    let mut expected = vec![0u8; clean.len() * 4];
    tracery::film::encode_rgba8(&clean, 1.0, &mut expected);
    let against_denoised = rmse_levels(&shown, &expected);
    let against_plain = rmse_levels(&shown, &plain.to_rgba8(1.0));
    assert!(
        against_denoised < 0.5,
        "the shown picture is {against_denoised:.2} levels from the headless render denoised"
    );
    assert!(
        against_plain > 2.0,
        "the shown picture is only {against_plain:.2} levels from the picture as traced"
    );
}

fn current_triangles(app: &App) -> Vec<[Vec3; 3]> {
    app.world()
        .resource::<CurrentScene>()
        .scene
        .mesh
        .triangles
        .clone()
}

/// A glTF's animation plays in the viewer: the file opens at the timeline's start, scrubbing
/// shows the instant asked for (the scene at that time, its BVH rebuilt, the camera left
/// where it is; the tree refitted, not built again), and playing moves the time on and loads
/// the instants it reaches.
#[test]
fn the_timeline_shows_and_plays_the_animation() {
    use tracery::viewer::animation::Timeline;
    let Some(skin) = common::external("gltf/simple_skin/simple_skin.gltf") else {
        return;
    };
    let mut app = app(Some(skin.to_str().unwrap()));
    settle(&mut app, "the first instant", |w| {
        w.resource::<CurrentScene>().time == Some(0.0) && idle(w)
    });
    // Its tree built, so the next instant's can be this one refitted.
    settle(&mut app, "the first instant's BVH", |w| {
        let generation = w.resource::<CurrentScene>().generation;
        w.resource::<SceneBvh>().for_scene(generation).is_some()
    });
    let at = |app: &App| app.world().resource::<CurrentScene>().scene.clone();
    let start = at(&app);
    assert_eq!(start.animation, Some(5.5));
    assert_eq!(
        start.mesh.triangles,
        Scene::load_at(&skin, Some(0.0)).unwrap().mesh.triangles
    );

    app.world_mut().resource_mut::<Timeline>().time = 1.25;
    settle(&mut app, "the instant scrubbed to", |w| {
        w.resource::<CurrentScene>().time == Some(1.25) && idle(w)
    });
    let current = app.world().resource::<CurrentScene>();
    assert!(!current.reframe, "another instant keeps the camera");
    assert_eq!(
        current.scene.mesh.triangles,
        Scene::load_at(&skin, Some(1.25)).unwrap().mesh.triangles
    );
    assert_ne!(current.scene.mesh.triangles, start.mesh.triangles);
    let generation = current.generation;
    settle(&mut app, "the BVH of the instant", |w| {
        w.resource::<SceneBvh>().for_scene(generation).is_some()
    });
    // The instants' trees are the first tree refitted, and answer as trees built for them.
    let trees = app.world().resource::<SceneBvh>();
    assert!(trees.refits >= 1, "{} refits", trees.refits);
    let tree = trees.for_scene(generation).unwrap();
    let built = Bvh::build(&current_triangles(&app), &BuildOptions::sah());
    let scene = app.world().resource::<CurrentScene>().scene.clone();
    for ray in tracery::bench::canonical_rays(&scene.mesh.bounds())
        .iter()
        .step_by(97)
    {
        assert_eq!(
            tree.intersect(ray, f32::INFINITY),
            built.intersect(ray, f32::INFINITY)
        );
    }

    {
        let mut t = app.world_mut().resource_mut::<Timeline>();
        t.playing = true;
        t.speed = 4.0;
    }
    settle(&mut app, "playing on", |w| {
        w.resource::<CurrentScene>().time.is_some_and(|t| t != 1.25)
    });
}

/// A floor placed once and a grid of nine cubes, its trees built.
fn grid_app() -> (App, tempfile::TempDir) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("grid.toml");
    std::fs::write(
        &path,
        "[camera]\nposition = [1.5, 4.0, 6.0]\nlook_at = [1.5, 0.0, -1.5]\n\n\
         [[meshes]]\nshape = \"quad\"\nscale = 10.0\n\n\
         [[meshes]]\nshape = \"cube\"\nscale = 0.3\n\
         grid = { count = [3, 1, 3], step = [1.5, 0.0, -1.5] }\n",
    )
    .unwrap();
    let mut app = app(Some(path.to_str().unwrap()));
    let ready = |w: &World| {
        let current = w.resource::<CurrentScene>();
        current.source.is_some()
            && w.resource::<SceneBvh>()
                .tracing(current.generation)
                .is_some()
    };
    settle(&mut app, "the grid and its trees", ready);
    (app, dir)
}

/// Settles after a move, until the scene it installs has its trees.
fn settle_move(app: &mut App, before: u64) {
    settle(app, "the move installed", |w| {
        let current = w.resource::<CurrentScene>();
        current.generation > before
            && w.resource::<SceneBvh>().key.map(|k| k.scene) == Some(current.generation)
    });
    for _ in 0..20 {
        app.update();
    }
}

/// A scene that places a mesh many times has one entity per object (the floor, and each
/// placement); changing one placement's `Transform` rebuilds the top level only, once (every
/// mesh's tree kept), and rays meet the object where it was moved to.
#[test]
fn moving_an_object_rebuilds_the_top_level_only_once() {
    use tracery::scene::Place;
    use tracery::viewer::objects::SceneObject;
    let (mut app, _dir) = grid_app();
    let full = builds(&app);
    let mut q = app
        .world_mut()
        .query::<(Entity, &SceneObject, &Transform)>();
    let scene = app.world().resource::<CurrentScene>().scene.clone();
    let objects: Vec<(Entity, Place, Vec3)> = q
        .iter(app.world())
        .map(|(e, o, t)| (e, scene.objects[o.object].place, t.translation))
        .collect();
    assert_eq!(
        objects.len(),
        10,
        "one entity per object: the floor and nine cubes"
    );
    let placement = 4;
    let &(e, _, at) = objects
        .iter()
        .find(|o| o.1 == Place::Placed(placement))
        .unwrap();
    assert!((at - Vec3::new(1.5, 0.0, -1.5)).length() < 1e-5, "{at}");
    let before = app.world().resource::<CurrentScene>().generation;
    let to = at + Vec3::new(0.4, 1.0, 0.0);
    app.world_mut().get_mut::<Transform>(e).unwrap().translation = to;
    settle_move(&mut app, before);
    let bvh = app.world().resource::<SceneBvh>();
    assert_eq!(bvh.top_builds, 1, "the top level built once");
    assert_eq!(builds(&app), full, "no mesh's tree built again");
    let current = app.world().resource::<CurrentScene>();
    assert_eq!(
        current.generation,
        before + 1,
        "one scene installed for the move"
    );
    let moved = current.scene.instances.placements()[placement].to_world;
    assert!((Vec3::from(moved.translation) - to).length() < 1e-5);
    // A ray straight down onto the new place meets that placement's triangles (numbered
    // after the floor's two), and one onto the old place meets the floor.
    let tree = bvh.tracing(current.generation).unwrap();
    let down = |p: Vec3| tracery::geometry::Ray::new(p + Vec3::Y * 5.0, Vec3::NEG_Y);
    let own = current.scene.mesh.triangles.len() as u32;
    let first = own + current.scene.instances.first_triangle(placement);
    let hit = tree.intersect(&down(to), f32::INFINITY).expect("a hit");
    assert!((first..first + 12).contains(&hit.prim), "{hit:?}");
    // (Off the floor's diagonal, which runs through the old place.)
    let hit = tree
        .intersect(&down(at + Vec3::new(0.05, 0.0, 0.1)), f32::INFINITY)
        .expect("the floor");
    assert!(hit.prim < own, "{hit:?}");
}

/// Moving an object of the scene's own triangles (the grid's floor) lifts it into a mesh of
/// its own, placed once: one build of the trees that changed (the cubes' tree kept), the
/// entities kept; moving it again rebuilds the top level only.
#[test]
fn moving_an_object_of_the_scenes_own_lifts_it_once() {
    use tracery::scene::Place;
    use tracery::viewer::objects::SceneObject;
    let (mut app, _dir) = grid_app();
    let full = builds(&app);
    let cube_tree = app
        .world()
        .resource::<SceneBvh>()
        .placed
        .as_ref()
        .unwrap()
        .meshes[1]
        .clone();
    let mut q = app
        .world_mut()
        .query::<(Entity, &SceneObject, &Transform)>();
    let (floor, object, at) = q
        .iter(app.world())
        .find(|(_, o, _)| o.object == 0)
        .map(|(e, o, t)| (e, o.object, t.translation))
        .unwrap();
    let scene = app.world().resource::<CurrentScene>().scene.clone();
    assert_eq!(
        scene.objects[object].place,
        Place::Own { first: 0, count: 2 }
    );
    let entities = q.iter(app.world()).count();

    let before = app.world().resource::<CurrentScene>().generation;
    let to = at + Vec3::new(0.0, -0.25, 0.0);
    app.world_mut()
        .get_mut::<Transform>(floor)
        .unwrap()
        .translation = to;
    settle_move(&mut app, before);
    let current = app.world().resource::<CurrentScene>();
    assert!(current.lifted);
    assert_eq!(
        current.generation,
        before + 1,
        "one scene installed for the move"
    );
    assert_eq!(current.scene.objects[object].place, Place::Placed(9));
    assert!(
        current.scene.mesh.triangles.is_empty(),
        "the floor was the only own object"
    );
    let bvh = app.world().resource::<SceneBvh>();
    assert_eq!(builds(&app), full + 1, "one build for the lift");
    assert_eq!(bvh.top_builds, 0);
    let two = bvh.placed.as_ref().unwrap();
    assert!(
        std::sync::Arc::ptr_eq(&two.meshes[0], &cube_tree),
        "the cubes' tree kept"
    );
    // A ray down between the cubes meets the floor where it was moved to.
    let tree = bvh.tracing(current.generation).unwrap();
    let ray = tracery::geometry::Ray::new(Vec3::new(0.75, 5.0, 0.75), Vec3::NEG_Y);
    let hit = tree.intersect(&ray, f32::INFINITY).expect("the floor");
    assert_eq!(current.scene.object_of(hit.prim), Some(object));
    assert!((5.0 - hit.t - to.y).abs() < 1e-4, "{hit:?}");
    assert_eq!(
        app.world_mut()
            .query::<&SceneObject>()
            .iter(app.world())
            .count(),
        entities,
        "the entities kept"
    );

    // Moved again: a placement now, so the top level alone is built.
    let before = app.world().resource::<CurrentScene>().generation;
    app.world_mut()
        .get_mut::<Transform>(floor)
        .unwrap()
        .translation = at;
    settle_move(&mut app, before);
    assert_eq!(builds(&app), full + 1);
    assert_eq!(app.world().resource::<SceneBvh>().top_builds, 1);
}
