//! Samplers and the thin lens.

use glam::Vec2;
use tracery::bvh::{BuildOptions, Bvh};
use tracery::camera::CameraRays;
use tracery::render::{EnvironmentMap, RenderPlan, RenderSettings, render_with_plan};
use tracery::sampling::{PixelSampler, SamplerKind, concentric_disk, dim, sin_cos_octant};
use tracery::scene::Scene;

#[test]
fn sobol_points_fill_every_elementary_interval() {
    // The first 2^k points of each dimension pair: one per cell of every 2^a x 2^(k-a) grid.
    let k = 6;
    let n = 1u32 << k;
    for pixel in [0u64, 7, 12345] {
        for d in [dim::PIXEL, dim::LENS, dim::LIGHT, dim::LIGHT + 5] {
            let base = PixelSampler::new(SamplerKind::Sobol, 3, pixel, 0);
            let pts: Vec<Vec2> = (0..n).map(|i| base.with_index(i).get_2d(d)).collect();
            assert!(
                pts.iter()
                    .all(|p| p.cmpge(Vec2::ZERO).all() && p.cmplt(Vec2::ONE).all())
            );
            for a in 0..=k {
                let (cx, cy) = (1u32 << a, 1u32 << (k - a));
                let mut seen = vec![false; n as usize];
                for p in &pts {
                    let cell = (p.x * cx as f32) as u32 * cy + (p.y * cy as f32) as u32;
                    assert!(
                        !seen[cell as usize],
                        "pixel {pixel} dim {d}: two points in a {cx}x{cy} cell"
                    );
                    seen[cell as usize] = true;
                }
            }
        }
    }
}

#[test]
fn samples_do_not_depend_on_what_was_drawn_before() {
    for kind in [SamplerKind::Random, SamplerKind::Sobol] {
        let s = PixelSampler::new(kind, 9, 42, 5);
        let a = s.get_2d(dim::LIGHT);
        let _ = s.get_2d(dim::LENS);
        assert_eq!(s.get_2d(dim::LIGHT), a);
        assert_ne!(s.get_2d(dim::LIGHT + 1), a);
        assert_ne!(s.with_index(6).get_2d(dim::LIGHT), a);
    }
}

#[test]
fn concentric_map_stays_in_the_disk_and_keeps_the_centre() {
    assert_eq!(concentric_disk(Vec2::splat(0.5)), Vec2::ZERO);
    for i in 0..32 {
        for j in 0..32 {
            let p = concentric_disk(Vec2::new(i as f32 / 31.0, j as f32 / 31.0));
            assert!(p.length() <= 1.0 + 1e-6);
        }
    }
    // The square's edge lands on the circle.
    assert!((concentric_disk(Vec2::new(1.0, 0.5)).length() - 1.0).abs() < 1e-6);
}

/// Distance in units in the last place between `got` and the f64 value `exact`.
fn ulps(got: f32, exact: f64) -> f64 {
    let rounded = exact as f32;
    let ulp = (rounded.next_up() - rounded) as f64;
    (got as f64 - exact).abs() / ulp
}

#[test]
fn the_octant_sine_and_cosine_are_within_one_and_a_half_ulp() {
    let mut worst = (0.0f64, 0.0f64);
    let steps = 1 << 20;
    for i in -steps..=steps {
        let a = std::f32::consts::FRAC_PI_4 * (i as f32 / steps as f32);
        let (sin, cos) = sin_cos_octant(a);
        let (es, ec) = (a as f64).sin_cos();
        worst.0 = worst.0.max(if a == 0.0 {
            sin.abs() as f64
        } else {
            ulps(sin, es)
        });
        worst.1 = worst.1.max(ulps(cos, ec));
    }
    assert!(
        worst.0 <= 1.5 && worst.1 <= 1.5,
        "sine, cosine: {worst:?} ulp"
    );
    // The disk's points have unit radius on its rim, to rounding.
    for i in 0..=64 {
        let p = concentric_disk(Vec2::new(1.0, i as f32 / 64.0));
        assert!((p.length() - 1.0).abs() < 4e-7, "{p}");
    }
}

#[test]
fn lens_radius_zero_gives_the_pinhole_image_bit_for_bit() {
    let scene = Scene::cornell_box();
    let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
    let settings = RenderSettings {
        width: 40,
        height: 40,
        spp: 3,
        ..RenderSettings::default()
    };
    let pinhole = render_with_plan(
        &scene,
        &bvh,
        &EnvironmentMap::None,
        &settings,
        RenderPlan::new(&scene, &settings),
        &|_| {},
    );
    // Thin lens on, radius 0: the lens sample is drawn but changes nothing.
    let lens = render_with_plan(
        &scene,
        &bvh,
        &EnvironmentMap::None,
        &settings,
        RenderPlan {
            thin_lens: true,
            ..RenderPlan::new(&scene, &settings)
        },
        &|_| {},
    );
    assert_eq!(pinhole.film, lens.film);
}

#[test]
fn thin_lens_rays_meet_on_the_focus_plane() {
    let mut camera = Scene::cornell_box().camera;
    camera.lens_radius = 0.3;
    camera.focus_distance = 6.0;
    let cam = CameraRays::new(&camera, 64, 48);
    for (px, py) in [(32.0, 24.0), (3.5, 40.25), (60.0, 2.0)] {
        let pin = cam.pinhole(px, py);
        let t = camera.focus_distance / pin.dir.dot(cam.forward);
        let focus = pin.at(t);
        for lens in [
            Vec2::new(1.0, 0.0),
            Vec2::new(-0.5, 0.7),
            Vec2::new(0.1, -0.9),
        ] {
            let r = cam.thin_lens(px, py, lens);
            assert!((r.origin - cam.eye).length() > 0.0);
            // Walk the lens ray to the focus plane: it arrives at the same point.
            let s = (focus - r.origin).dot(cam.forward) / r.dir.dot(cam.forward);
            assert!(
                (r.at(s) - focus).length() < 1e-4,
                "{px},{py}: {} vs {focus}",
                r.at(s)
            );
            assert!((r.dir.length() - 1.0).abs() < 1e-6);
        }
    }
}

#[test]
fn the_byte_table_sobol_dimension_equals_the_bitwise_one() {
    use tracery::rng::SplitMix64;
    use tracery::sampling::{sobol_dim1, sobol_dim1_bitwise};
    let mut rng = SplitMix64::new(3);
    let edge = [0u32, 1, 2, 255, 256, 0xffff, 0x1_0000, u32::MAX, 1 << 31];
    for i in edge
        .into_iter()
        .chain((0..100_000).map(|_| rng.next_u64() as u32))
    {
        assert_eq!(sobol_dim1(i), sobol_dim1_bitwise(i), "index {i:#x}");
    }
}

/// The Sobol sampler computes its points on bit-reversed values (a 32-bit reversal a point,
/// and one of 64 bits for both axes):
/// every point equals the formula as written, a shuffle of the index, then Owen scrambling
/// of the first dimension (the reversed index) and of the second (`sobol_dim1_bitwise`), for
/// seeds, pixels, sample indices (edges included, and through `with_index`) and dimensions.
#[test]
fn sobol_points_equal_the_straightforward_formula() {
    use tracery::rng::{SplitMix64, mix64};
    use tracery::sampling::{nested_uniform_scramble, sobol_dim1_bitwise};
    let unit = |x: u32| (x >> 8) as f32 * (1.0 / (1u32 << 24) as f32);
    let reference = |seed: u64, pixel: u64, index: u32, d: u32| {
        let s = mix64(seed ^ mix64(pixel.wrapping_add(0x5851_F42D_4C95_7F2D)));
        let h = mix64(s ^ (d as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
        let i = nested_uniform_scramble(index, h as u32);
        let x = nested_uniform_scramble(i.reverse_bits(), (h >> 32) as u32 ^ 0x68bc_21eb);
        let y = nested_uniform_scramble(sobol_dim1_bitwise(i), (h >> 16) as u32 ^ 0x02e5_be93);
        Vec2::new(unit(x), unit(y))
    };
    let mut rng = SplitMix64::new(11);
    let edge = [0u32, 1, 2, 3, 255, 256, 0xffff, 1 << 31, u32::MAX];
    for k in 0..20_000 {
        let (seed, pixel) = (rng.next_u64(), rng.next_u64() % 5_000_000);
        let index = match edge.get(k) {
            Some(&e) => e,
            None => rng.next_u64() as u32,
        };
        let d = (rng.next_u64() % 64) as u32;
        let s = PixelSampler::new(SamplerKind::Sobol, seed, pixel, index);
        let want = reference(seed, pixel, index, d);
        assert_eq!(
            s.get_2d(d),
            want,
            "seed {seed} pixel {pixel} index {index} dim {d}"
        );
        let other = index.wrapping_add(1 + k as u32);
        assert_eq!(
            s.with_index(other).get_2d(d),
            reference(seed, pixel, other, d),
            "with_index({other})"
        );
    }
}
