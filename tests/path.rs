//! The path integrator against analytic answers and against the direct integrator: a closed
//! glowing box (the furnace) at several depth limits, the Cornell box with no bounce equal to
//! direct lighting, and an emissive quad lighting a floor the same whether a rectangle light
//! stands for it or its triangles are sampled as lights.

use glam::{Affine3A, Vec3};
use tracery::bvh::{BuildOptions, Bvh};
use tracery::geometry::shapes;
use tracery::render::{Integrator, RenderSettings, render};
use tracery::sampling::SamplerKind;
use tracery::scene::{Camera, Environment, Light, Material, Mesh, Scene};

fn scene(parts: Vec<(Vec<[Vec3; 3]>, Material)>, lights: Vec<Light>, camera: Camera) -> Scene {
    let mut mesh = Mesh::default();
    let mut materials = Vec::new();
    for (tris, m) in parts {
        mesh.append(Mesh::from_triangles(tris, 0), materials.len() as u32);
        materials.push(m);
    }
    Scene {
        name: "test".into(),
        mesh,
        materials,
        lights,
        camera,
        environment: Environment::None,
        integrator: Integrator::Path,
        energy_compensation: true,
        warnings: Vec::new(),
        animation: None,
        instances: Default::default(),
        objects: Vec::new(),
    }
}

fn moved(tris: Vec<[Vec3; 3]>, scale: Vec3, at: Vec3) -> Vec<[Vec3; 3]> {
    let m = Affine3A::from_scale_rotation_translation(scale, glam::Quat::IDENTITY, at);
    tris.iter()
        .map(|t| t.map(|v| m.transform_point3(v)))
        .collect()
}

fn camera(position: Vec3, look_at: Vec3, vfov_deg: f32) -> Camera {
    Camera {
        position,
        look_at,
        up: Vec3::Y,
        vfov_deg,
        lens_radius: 0.0,
        focus_distance: 1.0,
    }
}

/// Mean radiance of a render, and of each block of a `b x b` grid over the image.
fn render_means(s: &Scene, w: u32, h: u32, spp: u32, depth: u32, b: u32) -> (Vec3, Vec<Vec3>) {
    let bvh = Bvh::build(&s.mesh.triangles, &BuildOptions::sah());
    let settings = RenderSettings {
        width: w,
        height: h,
        spp,
        seed: 7,
        max_depth: depth,
        sampler: SamplerKind::Sobol,
        soft_terminator: true,
    };
    let out = render(s, &bvh, &settings, &|_| {}).unwrap();
    assert_eq!(out.film.rejected, 0, "no sample may be NaN or infinite");
    let px = out.film.mean();
    let all = px.iter().copied().sum::<Vec3>() / px.len() as f32;
    let mut blocks = vec![Vec3::ZERO; (b * b) as usize];
    let mut n = vec![0u32; (b * b) as usize];
    for y in 0..h {
        for x in 0..w {
            let k = ((y * b / h) * b + x * b / w) as usize;
            blocks[k] += px[(y * w + x) as usize];
            n[k] += 1;
        }
    }
    for (v, c) in blocks.iter_mut().zip(n) {
        *v /= c.max(1) as f32;
    }
    (all, blocks)
}

/// Inside a closed box whose walls all reflect `rho` and emit `le`, every ray sees
/// `le (1 + rho + ... + rho^(D + 1))` with `D` bounces (the last only collecting emission):
/// light samples, bounces, their MIS weights and Russian roulette all take part.
#[test]
fn a_glowing_closed_box_sees_the_geometric_series_of_its_albedo_at_each_depth_limit() {
    let rho = 0.6;
    let le = Vec3::new(1.0, 0.5, 0.25);
    let glow = Material {
        diffuse: Vec3::splat(rho),
        emission: le,
        ..Material::default()
    };
    let s = scene(
        vec![(moved(shapes::cube(), Vec3::splat(2.0), Vec3::ZERO), glow)],
        vec![],
        camera(Vec3::new(0.1, 0.2, 0.3), Vec3::new(1.0, 0.1, -0.4), 80.0),
    );
    for depth in [0u32, 1, 4, 8] {
        let expected = le * (0..=depth + 1).map(|k| rho.powi(k as i32)).sum::<f32>();
        let (mean, _) = render_means(&s, 32, 32, 64, depth, 1);
        let err = ((mean - expected) / expected).abs().max_element();
        assert!(
            err < 0.01,
            "depth {depth}: mean {mean} against {expected} (off by {:.2}%)",
            err * 100.0
        );
    }
}

/// With no bounce beyond the camera's hit, the path integrator computes direct light (light
/// samples and the bounce that finds the light, weighted by MIS): the same picture as the
/// direct integrator, within noise, on the Cornell box.
#[test]
fn the_cornell_box_with_no_bounce_matches_the_direct_integrator() {
    let mut s = Scene::cornell_box();
    assert_eq!(s.integrator, Integrator::Path, "the Cornell box uses path");
    let (path, path_blocks) = render_means(&s, 80, 60, 64, 0, 4);
    s.integrator = Integrator::Direct;
    let (direct, direct_blocks) = render_means(&s, 80, 60, 64, 0, 4);
    let rel = ((path - direct) / direct).abs().max_element();
    assert!(rel < 0.01, "image mean: path {path}, direct {direct}");
    for (i, (p, d)) in path_blocks.iter().zip(&direct_blocks).enumerate() {
        let rel = (*p - *d).abs().max_element() / d.max_element().max(0.05);
        assert!(rel < 0.03, "block {i}: path {p}, direct {d}");
    }
    // And with bounces, light reaches where the light does not shine.
    s.integrator = Integrator::Path;
    let (gi, gi_blocks) = render_means(&s, 80, 60, 16, 5, 4);
    assert!(
        gi.max_element() > direct.max_element() * 1.2,
        "{gi} vs {direct}"
    );
    // The top corners (ceiling and the tops of the walls) are lit by bounced light only.
    for k in [0, 3] {
        let (g, d) = (gi_blocks[k].element_sum(), direct_blocks[k].element_sum());
        assert!(g > 2.0 * d, "block {k}: path {g}, direct {d}");
    }
}

/// An emissive quad above a floor lights it the same whether a rectangle light stands for the
/// quad (its samples weighted against bounces that hit the quad) or the quad's triangles are
/// sampled as lights themselves.
#[test]
fn an_emissive_quad_lights_the_same_as_the_rectangle_light_that_stands_for_it() {
    let le = Vec3::new(4.0, 3.0, 2.0);
    let lamp = Material {
        diffuse: Vec3::ZERO,
        emission: le,
        ..Material::default()
    };
    let white = Material {
        diffuse: Vec3::splat(0.8),
        ..Material::default()
    };
    // A 1 x 1 quad at height 1, facing down (the unit quad faces +y: turn it over).
    let flip = Affine3A::from_rotation_x(std::f32::consts::PI);
    let quad: Vec<[Vec3; 3]> = shapes::quad()
        .iter()
        .map(|t| t.map(|v| flip.transform_point3(v) + Vec3::Y))
        .collect();
    let floor = moved(shapes::quad(), Vec3::splat(6.0), Vec3::ZERO);
    let cam = camera(Vec3::new(0.0, 0.6, 2.5), Vec3::new(0.0, 0.0, 0.0), 60.0);
    let triangles_only = scene(
        vec![(quad.clone(), lamp.clone()), (floor.clone(), white.clone())],
        vec![],
        cam.clone(),
    );
    let rect = Light::Rect {
        corner: Vec3::new(-0.5, 1.0, -0.5),
        edge_u: Vec3::new(1.0, 0.0, 0.0),
        edge_v: Vec3::new(0.0, 0.0, 1.0),
        color: le / 4.0,
        intensity: 4.0,
        samples: 2,
    };
    let with_rect = scene(vec![(quad, lamp), (floor, white)], vec![rect], cam);
    let (a, ab) = render_means(&triangles_only, 64, 48, 64, 2, 4);
    let (b, bb) = render_means(&with_rect, 64, 48, 64, 2, 4);
    assert!(
        ((a - b) / b).abs().max_element() < 0.01,
        "triangles {a}, rectangle {b}"
    );
    for (i, (x, y)) in ab.iter().zip(&bb).enumerate() {
        let rel = (*x - *y).abs().max_element() / y.max_element().max(0.05);
        assert!(rel < 0.03, "block {i}: triangles {x}, rectangle {y}");
    }
}

/// `direct` traces no bounce at all (the plan leaves the path integrator out); `path` does.
#[test]
fn the_direct_integrator_traces_no_bounce_and_path_does() {
    let mut s = Scene::cornell_box();
    let bvh = Bvh::build(&s.mesh.triangles, &BuildOptions::sah());
    let settings = RenderSettings {
        width: 32,
        height: 24,
        spp: 4,
        ..RenderSettings::default()
    };
    s.integrator = Integrator::Direct;
    let direct = render(&s, &bvh, &settings, &|_| {}).unwrap();
    assert_eq!(direct.rays.bounce, 0);
    s.integrator = Integrator::Path;
    let path = render(&s, &bvh, &settings, &|_| {}).unwrap();
    assert!(path.rays.bounce > 0);
    assert_eq!(path.rays.camera, direct.rays.camera);
}

/// Inside a closed glowing box whose walls are white under a white sheen (glTF's sheen over a
/// white Lambertian base), each bounce reflects at most what arrives: the albedo scaling keeps
/// the sheen and the lobe under it to at most 1 together. So every ray sees at most
/// `le (D + 2)` with `D` bounces, and, the pair reflecting over 0.8 of the light from every
/// angle, more than `le (1 + 0.8 + ... + 0.8^(D + 1))`. Light samples, bounces and their MIS
/// weights all take the sheen. Fails with the lobe under the sheen left undimmed (3.29 `le`
/// at one bounce against at most 3; 2.78 as it is, checked).
#[test]
fn a_glowing_box_under_a_white_sheen_gains_no_light() {
    use tracery::scene::pbr::{Dielectric, MetallicRoughness, SheenLayer, Specular, lobes};
    let le = Vec3::new(0.5, 0.25, 0.125);
    let specular = Specular {
        factor: 0.0,
        ..Specular::DEFAULT
    };
    let dielectric = Dielectric {
        weight: 0.0,
        ..Dielectric::DEFAULT
    };
    let l = lobes(Vec3::ONE, 0.0, 1.0, dielectric);
    let velvet = Material {
        diffuse: l.diffuse,
        specular: l.f0,
        emission: le,
        pbr: Some(MetallicRoughness {
            base: Vec3::ONE,
            metallic: 0.0,
            roughness: 1.0,
            map: None,
            clearcoat: None,
            specular,
            sheen: Some(SheenLayer {
                color: Vec3::ONE,
                roughness: 0.5,
                color_map: None,
                roughness_map: None,
            }),
        }),
        ..Material::default()
    };
    let s = scene(
        vec![(moved(shapes::cube(), Vec3::splat(2.0), Vec3::ZERO), velvet)],
        vec![],
        camera(Vec3::new(0.1, 0.2, 0.3), Vec3::new(1.0, 0.1, -0.4), 80.0),
    );
    for depth in [1u32, 4] {
        let most = le * (depth + 2) as f32;
        let least = le * (0..=depth + 1).map(|k| 0.8f32.powi(k as i32)).sum::<f32>();
        let (mean, _) = render_means(&s, 32, 32, 64, depth, 1);
        assert!(
            mean.cmple(most * 1.01).all() && mean.cmpge(least).all(),
            "depth {depth}: mean {mean}, between {least} and {most}"
        );
    }
}
