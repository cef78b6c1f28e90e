//! Render layers (albedo, normal, depth) of scenes whose answers are known, their EXR file,
//! and the denoiser: it lowers a noisy render's error against a converged one.

use std::path::Path;

use glam::Vec3;
use tracery::bvh::{BuildOptions, Bvh};
use tracery::render::aov::{Aov, AovFilm};
use tracery::render::{EnvironmentMap, RenderPlan, RenderSettings, render_layers};
use tracery::scene::Scene;

/// A scene file written to a temporary folder, loaded.
fn scene(name: &str, toml: &str) -> Scene {
    let dir = std::env::temp_dir().join(format!("tracery-aov-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, toml).unwrap();
    Scene::load(&path).unwrap()
}

fn layers(scene: &Scene, size: (u32, u32), spp: u32) -> AovFilm {
    let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
    let settings = RenderSettings {
        width: size.0,
        height: size.1,
        spp,
        ..RenderSettings::default()
    };
    let plan = RenderPlan::new(scene, &settings);
    render_layers(scene, &bvh, &EnvironmentMap::None, &settings, plan)
}

/// The pixel at the middle of the image.
fn middle<T: Copy>(l: &AovFilm, v: &[T]) -> T {
    v[(l.height / 2 * l.width + l.width / 2) as usize]
}

/// A camera looks at a mirror (tint 0.9); behind the camera a red wall faces it. The mirror's
/// pixels show the wall's albedo tinted by the mirror, and the wall's normal; the depth is the
/// distance to the mirror, the first hit.
#[test]
fn a_mirror_shows_the_albedo_and_normal_of_what_it_reflects() {
    let s = scene(
        "mirror.toml",
        r#"
[camera]
position = [0.0, 0.0, 2.0]
look_at = [0.0, 0.0, 0.0]
fov = 30.0

[materials.mirror]
diffuse = [0.02, 0.02, 0.02]
mirror = [0.9, 0.9, 0.9]

[materials.red]
diffuse = [0.8, 0.1, 0.1]

[[meshes]]
shape = "quad"
rotate = [90.0, 0.0, 0.0]
scale = 4.0
material = "mirror"

[[meshes]]
shape = "quad"
rotate = [-90.0, 0.0, 0.0]
translate = [0.0, 0.0, 6.0]
scale = 20.0
material = "red"

[[lights]]
kind = "point"
position = [0.0, 0.0, 3.0]
intensity = 1.0
"#,
    );
    let l = layers(&s, (32, 24), 4);
    let albedo = middle(&l, &l.albedo_mean());
    let expected = Vec3::new(0.8, 0.1, 0.1) * 0.9;
    assert!(
        (albedo - expected).abs().max_element() < 1e-3,
        "albedo {albedo}, expected the red wall's {expected} through the mirror"
    );
    let normal = middle(&l, &l.normal_mean());
    assert!(
        (normal - Vec3::NEG_Z).length() < 1e-3,
        "normal {normal}, expected the wall's -z"
    );
    let depth = middle(&l, &l.depth_mean());
    assert!((depth - 2.0).abs() < 1e-2, "depth {depth}, expected 2");
    // The mirror itself: with the reflection left out, its own (nearly black) albedo.
    let bvh = Bvh::build(&s.mesh.triangles, &BuildOptions::sah());
    let settings = RenderSettings {
        width: 32,
        height: 24,
        spp: 1,
        ..RenderSettings::default()
    };
    let mut plan = RenderPlan::new(&s, &settings);
    plan.reflections = false;
    let own = render_layers(&s, &bvh, &EnvironmentMap::None, &settings, plan);
    let a = middle(&own, &own.albedo_mean());
    assert!((a - Vec3::splat(0.02)).abs().max_element() < 1e-4, "{a}");
}

/// A plane tilted 30 degrees about z, seen from above: its normal layer is the tilted normal,
/// its albedo the material's diffuse colour.
#[test]
fn normals_of_a_tilted_plane() {
    let s = scene(
        "tilted.toml",
        r#"
[camera]
position = [0.0, 3.0, 0.01]
look_at = [0.0, 0.0, 0.0]
fov = 20.0

[materials.grey]
diffuse = [0.5, 0.4, 0.3]

[[meshes]]
shape = "quad"
rotate = [0.0, 0.0, 30.0]
scale = 4.0
material = "grey"

[[lights]]
kind = "point"
position = [0.0, 3.0, 0.0]
intensity = 1.0
"#,
    );
    let l = layers(&s, (24, 24), 2);
    let (sin, cos) = 30f32.to_radians().sin_cos();
    let expected = Vec3::new(-sin, cos, 0.0);
    for (i, n) in l.normal_mean().iter().enumerate() {
        assert!(
            (*n - expected).length() < 1e-3,
            "pixel {i}: normal {n}, expected {expected}"
        );
    }
    let albedo = middle(&l, &l.albedo_mean());
    assert!((albedo - Vec3::new(0.5, 0.4, 0.3)).abs().max_element() < 1e-4);
}

/// The layers written to an EXR have the channels named, and read back as written.
#[test]
fn layers_round_trip_through_an_exr_file() {
    use exr::prelude::*;
    let s = Scene::cornell_box();
    let l = layers(&s, (16, 12), 2);
    let dir = std::env::temp_dir().join(format!("tracery-aov-exr-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("layers.exr");
    l.save_exr(&path, &Aov::ALL, None).unwrap();
    let image = read_all_flat_layers_from_file(&path).unwrap();
    let layer = &image.layer_data[0];
    let names: Vec<String> = layer
        .channel_data
        .list
        .iter()
        .map(|c| c.name.to_string())
        .collect();
    for name in [
        "albedo.R",
        "albedo.G",
        "albedo.B",
        "normal.X",
        "normal.Y",
        "normal.Z",
        "depth.Z",
        "samples.N",
    ] {
        assert!(
            names.iter().any(|n| n == name),
            "{name} missing in {names:?}"
        );
    }
    let channel = |name: &str| -> Vec<f32> {
        let c = layer
            .channel_data
            .list
            .iter()
            .find(|c| c.name.to_string() == name)
            .unwrap();
        c.sample_data.values_as_f32().collect()
    };
    let green: Vec<f32> = l.albedo_mean().iter().map(|a| a.y).collect();
    assert_eq!(channel("albedo.G"), green);
    assert!(channel("samples.N").iter().all(|&n| n == 2.0));
    std::fs::remove_dir_all(Path::new(&dir)).unwrap();
}

/// The denoiser brings a noisy path-traced Cornell box (8 samples a pixel, 160x120) closer to
/// a converged one (512) than it was, in relative RMSE of linear radiance: to less than half.
/// (At 64x48 the box's walls and blocks are a few pixels across, and the denoiser has little
/// to work with: 0.125 -> 0.090.)
#[cfg(feature = "denoise")]
#[test]
fn the_denoiser_lowers_the_error_of_a_noisy_render() {
    use tracery::denoise::{Denoiser, Inputs};
    use tracery::render::render;
    let mut s = Scene::cornell_box();
    s.integrator = tracery::render::Integrator::Path;
    let bvh = Bvh::build(&s.mesh.triangles, &BuildOptions::sah());
    let at = |spp: u32, seed: u64| {
        let settings = RenderSettings {
            width: 160,
            height: 120,
            spp,
            seed,
            ..RenderSettings::default()
        };
        render(&s, &bvh, &settings, &|_| {}).unwrap().film.mean()
    };
    let reference = at(512, 1);
    let noisy = at(8, 2);
    let l = layers(&s, (160, 120), 8);
    let clean = Denoiser::new()
        .unwrap()
        .run(&Inputs {
            width: 160,
            height: 120,
            color: &noisy,
            albedo: Some(&l.albedo_mean()),
            normal: Some(&l.normal_mean()),
        })
        .unwrap();
    let error = |img: &[Vec3]| tracery::convergence::errors(img, &reference).1.sqrt();
    let (before, after) = (error(&noisy), error(&clean));
    assert!(
        after < 0.5 * before,
        "denoised relative RMSE {after:.4}, noisy {before:.4}"
    );
}
