//! Stiff and extreme cases, each a named test: triangles swept one ulp at a time,
//! scale, traversal limits, builds from permuted input, and camera and sampling extremes.
//! Other families live beside the code they guard: `geometry.rs` (slab and triangle cases),
//! `bvh_degenerate.rs` (builds), `traversal.rs`, `shading.rs`, `environment.rs`,
//! `corpus.rs` and `mutation.rs` (bad input), `viewer_app.rs` (the long run).

mod common;

use glam::{Affine3A, Vec3};
use tracery::bvh::{BruteForce, BuildOptions, Bvh};
use tracery::camera::CameraRays;
use tracery::geometry::Ray;
use tracery::geometry::shapes;
use tracery::render::{EnvironmentMap, RayCounts, RenderPlan, RenderSettings, Tracer, render};
use tracery::rng::SplitMix64;
use tracery::sampling::{PathSampler, PixelSampler, SamplerKind};
use tracery::scene::{Camera, Environment, Light, Material, Mesh, Scene};

fn tri(a: [f32; 3], b: [f32; 3], c: [f32; 3]) -> [Vec3; 3] {
    [Vec3::from(a), Vec3::from(b), Vec3::from(c)]
}

/// `x` moved by `k` units in the last place (negative: down).
fn ulps(x: f32, k: i32) -> f32 {
    let mut v = x;
    for _ in 0..k.unsigned_abs() {
        v = if k > 0 { v.next_up() } else { v.next_down() };
    }
    v
}

// ---------------------------------------------------------------------------------------
// Triangles
// ---------------------------------------------------------------------------------------

#[test]
fn a_shared_edge_swept_one_ulp_at_a_time_is_hit_once_and_shadows_once() {
    // The unit square as two triangles sharing the diagonal x = y.
    let square = vec![
        tri([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]),
        tri([0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]),
    ];
    let bf = BruteForce::new(&square);
    let bvh = Bvh::build(&square, &BuildOptions::sah());
    for s in [0.125f32, 0.25, 0.5, 0.75, 0.9] {
        for k in -48..=48 {
            let x = ulps(s, k);
            for d in [Vec3::Z, Vec3::new(0.2, -0.1, 1.0)] {
                let ray = Ray::new(Vec3::new(x, s, 0.0) - d, d);
                let hits = bf.all_hits(&ray, f32::INFINITY);
                assert_eq!(hits.len(), 1, "x = s + {k} ulp, s = {s}, d = {d}: {hits:?}");
                assert!(
                    bvh.intersect(&ray, f32::INFINITY).is_some(),
                    "miss at {k} ulp"
                );
                let through = bvh.transmittance(&ray, 10.0, |_, _| Vec3::splat(0.5));
                assert_eq!(
                    through,
                    Vec3::splat(0.5),
                    "shadow at {k} ulp counted the edge twice"
                );
            }
        }
    }
}

#[test]
fn a_fan_vertex_swept_one_ulp_at_a_time_is_hit_once() {
    let c = Vec3::new(0.3, 0.6, 0.0);
    let fan = common::fan(9, c);
    let bf = BruteForce::new(&fan);
    let bvh = Bvh::build(&fan, &BuildOptions::sah());
    for kx in -12..=12 {
        for ky in -12..=12 {
            let p = Vec3::new(ulps(c.x, kx), ulps(c.y, ky), 0.0);
            let ray = Ray::new(p - Vec3::Z, Vec3::Z);
            let hits = bf.all_hits(&ray, f32::INFINITY);
            assert_eq!(hits.len(), 1, "({kx}, {ky}) ulp from the vertex: {hits:?}");
            assert!(bvh.intersect(&ray, f32::INFINITY).is_some());
            let through = bvh.transmittance(&ray, 10.0, |_, _| Vec3::splat(0.5));
            assert_eq!(through, Vec3::splat(0.5));
        }
    }
}

#[test]
fn needle_triangles_of_aspect_1e6_leave_no_crack_and_give_no_false_hit() {
    // A strip 1 long and 1e-6 wide cut along its diagonal: two needles of aspect about 1e6.
    let w = 1e-6f32;
    let strip = vec![
        tri([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, w, 0.0]),
        tri([0.0, 0.0, 0.0], [1.0, w, 0.0], [0.0, w, 0.0]),
    ];
    assert!(tracery::scene::check::aspect_ratio(&strip[0]) > 5e5);
    let bf = BruteForce::new(&strip);
    let bvh = Bvh::build(&strip, &BuildOptions::sah());
    let mut rng = SplitMix64::new(5);
    for _ in 0..20_000 {
        let x = 0.001 + 0.998 * rng.next_f32();
        // Inside the strip, including on the diagonal: exactly one hit.
        let y = w * rng.next_f32();
        let on_diagonal = w * x;
        for y in [y, on_diagonal] {
            if y <= 0.0 || y >= w {
                continue;
            }
            let ray = Ray::new(Vec3::new(x, y, -1.0), Vec3::Z);
            assert_eq!(bf.all_hits(&ray, 2.0).len(), 1, "crack at ({x}, {y})");
            assert!(bvh.intersect(&ray, 2.0).is_some());
        }
        // Outside it by a few ulps: no hit.
        for y in [ulps(w, 4), ulps(0.0, -4)] {
            let ray = Ray::new(Vec3::new(x, y, -1.0), Vec3::Z);
            assert!(bf.all_hits(&ray, 2.0).is_empty(), "false hit at ({x}, {y})");
            assert!(bvh.intersect(&ray, 2.0).is_none());
        }
    }
}

// ---------------------------------------------------------------------------------------
// Traversal limits
// ---------------------------------------------------------------------------------------

#[test]
fn directions_of_length_1e_minus_3_and_1e3_give_the_same_hits_with_t_scaled() {
    let tris = shapes::icosphere(3);
    let bvh = Bvh::build(&tris, &BuildOptions::sah());
    for r in common::random_rays(&tris, 20_000, 31) {
        let base = bvh.intersect(&r, f32::INFINITY);
        // Powers of two scale every product exactly: the same bits. Other lengths round the
        // ray's shear constants differently, which grazing hits amplify (up to 4e-4 of t
        // measured); the triangle found is the same.
        for (s, rel) in [
            (1.0 / 1024.0, 0.0f32),
            (1024.0, 0.0),
            (1e-3, 1e-3),
            (1e3, 1e-3),
        ] {
            let scaled = Ray::new(r.origin, r.dir * s);
            let h = bvh.intersect(&scaled, f32::INFINITY);
            match (base, h) {
                (None, None) => {}
                (Some(a), Some(b)) => {
                    assert_eq!(a.prim, b.prim, "scale {s}: {r:?}");
                    let t = b.t * s;
                    assert!((t - a.t).abs() <= rel * a.t, "scale {s}: {t} vs {}", a.t);
                }
                other => panic!("scale {s} changed hit to miss or back: {other:?} for {r:?}"),
            }
        }
    }
}

#[test]
fn tmax_zero_infinite_negative_and_nan_are_consistent() {
    // The queries take hits with 0 < t < t_max: t_min is 0, so "t_min > t_max" is a negative
    // (or -0, -inf, NaN) t_max, and every query must then report nothing.
    let tris = shapes::icosphere(2);
    let bvh = Bvh::build(&tris, &BuildOptions::sah());
    let bf = BruteForce::new(&tris);
    for r in common::random_rays(&tris, 5_000, 8) {
        let inf = bvh.intersect(&r, f32::INFINITY);
        assert_eq!(
            inf.map(|h| (h.prim, h.t)),
            bf.closest(&r, f32::INFINITY).map(|h| (h.prim, h.t))
        );
        for t_max in [0.0f32, -0.0, -1.0, f32::NEG_INFINITY, f32::NAN] {
            assert!(bvh.intersect(&r, t_max).is_none(), "t_max {t_max}");
            assert!(!bvh.occluded(&r, t_max), "t_max {t_max}");
            assert_eq!(bvh.transmittance(&r, t_max, |_, _| Vec3::ZERO), Vec3::ONE);
        }
        if let Some(h) = inf {
            // A t_max just past the hit finds it, one just short of it does not.
            assert_eq!(
                bvh.intersect(&r, h.t.next_up()).map(|x| x.prim),
                Some(h.prim)
            );
            assert!(bvh.intersect(&r, h.t.next_down()).is_none_or(|x| x.t < h.t));
            assert!(bvh.occluded(&r, h.t.next_up()));
        }
    }
}

// ---------------------------------------------------------------------------------------
// Builds
// ---------------------------------------------------------------------------------------

#[test]
fn a_permuted_input_and_any_thread_count_give_identical_hits() {
    let tris = shapes::icosphere(4);
    let rays = common::random_rays(&tris, 20_000, 77);
    // A fixed shuffle of the triangle order.
    let mut order: Vec<usize> = (0..tris.len()).collect();
    let mut rng = SplitMix64::new(3);
    for i in (1..order.len()).rev() {
        order.swap(i, (rng.next_u64() % (i as u64 + 1)) as usize);
    }
    let permuted: Vec<[Vec3; 3]> = order.iter().map(|&i| tris[i]).collect();
    for options in common::both_builders() {
        let build_on = |threads: usize, t: &[[Vec3; 3]]| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| Bvh::build(t, &options))
        };
        let one = build_on(1, &tris);
        let two = build_on(2, &tris);
        let four = build_on(4, &tris);
        let shuffled = build_on(2, &permuted);
        // The same tree whatever the thread count.
        assert_eq!(one.nodes, two.nodes);
        assert_eq!(one.nodes, four.nodes);
        for r in &rays {
            let a = one.intersect(r, f32::INFINITY);
            let b = shuffled.intersect(r, f32::INFINITY).map(|mut h| {
                h.prim = order[h.prim as usize] as u32;
                h
            });
            assert_eq!(
                a.map(|h| (h.prim, h.t.to_bits())),
                b.map(|h| (h.prim, h.t.to_bits())),
                "{r:?}"
            );
        }
    }
}

/// A tree large enough that the top of its build (the root's split too), its layout into one
/// node array and its collapse into wide nodes all run on the pool (327,680 triangles) is the
/// same, every array of it bit for bit, on one, two and four threads.
#[test]
fn a_large_tree_and_its_wide_layout_are_the_same_on_any_thread_count() {
    // Over `POOL_SPLIT_MIN` (src/bvh/build.rs) triangles.
    let tris = shapes::icosphere(7);
    assert!(tris.len() >= 1 << 18);
    for options in common::both_builders() {
        let build_on = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| Bvh::build(&tris, &options))
        };
        let one = build_on(1);
        assert!(
            // The collapse's threshold (`PARALLEL_MIN_NODES`, src/bvh/wide/collapse.rs).
            one.nodes.len() >= 1 << 14 && one.wide.nodes.len() > 1000,
            "{} binary nodes, {} wide: too small to take the parallel paths",
            one.nodes.len(),
            one.wide.nodes.len()
        );
        // Blocks' unused lanes are NaN: compared as bits.
        let block_bits = |b: &Bvh| -> Vec<u32> {
            b.wide
                .blocks
                .iter()
                .flat_map(|k| {
                    k.v.iter()
                        .flatten()
                        .flatten()
                        .map(|x| x.to_bits())
                        .chain(k.prim)
                })
                .collect()
        };
        for threads in [2, 4] {
            let other = build_on(threads);
            let what = format!("{:?}, {threads} threads", options.split);
            assert_eq!(one.nodes, other.nodes, "{what}: binary nodes");
            assert_eq!(one.prim_ids, other.prim_ids, "{what}: triangle order");
            assert_eq!(one.leaf_blocks, other.leaf_blocks, "{what}: leaves' blocks");
            assert_eq!(one.wide.nodes, other.wide.nodes, "{what}: wide nodes");
            assert_eq!(block_bits(&one), block_bits(&other), "{what}: blocks");
        }
    }
}

#[test]
fn coordinates_of_1e12_1e9_away_and_a_mix_of_1e_minus_3_and_1e7_build_finite_and_exact() {
    let ico = shapes::icosphere(2);
    // An icosphere 1e12 across: the f32 watertight test's products (coordinates cubed, up to
    // 1e36) stay finite, so rays aimed at it hit.
    let huge: Vec<[Vec3; 3]> = ico.iter().map(|t| t.map(|v| v * 1e12)).collect();
    // A unit icosphere 1e9 from the origin (f32 positions there are 64 apart; f64 keeps 1e-7),
    // read through the loaders' local frame (f64 positions placed about their own centre):
    // its rays hit as they do at the origin.
    let far: Vec<glam::DVec3> = ico
        .iter()
        .flatten()
        .map(|v| v.as_dvec3() + glam::DVec3::new(1e9, -1e9, 1e9))
        .collect();
    let (origin, local) = tracery::scene::local_frame(&far);
    assert!(origin.x > 9e8, "placed about its centre: {origin}");
    let far: Vec<[Vec3; 3]> = local.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    // Tiny triangles near the origin next to a few enormous ones far away.
    let mut mixed: Vec<[Vec3; 3]> = ico.iter().map(|t| t.map(|v| v * 1e-3)).collect();
    mixed.extend(
        ico.iter()
            .take(40)
            .map(|t| t.map(|v| v * 1e7 + Vec3::X * 3e7)),
    );
    for (name, tris) in [("1e12", huge), ("1e9 away", far), ("1e-3 and 1e7", mixed)] {
        let bf = BruteForce::new(&tris);
        let mut rays = common::random_rays(&tris, 4_000, 2);
        // Rays at the tiny cluster too (random_rays aims at random triangles).
        rays.extend(common::random_rays(&tris[..80], 2_000, 4));
        // Half the rays are aimed at a triangle: many of them hit (the answer is known), so
        // the comparison with brute force is not one of two misses.
        let hits = rays
            .iter()
            .filter(|r| bf.closest(r, f32::INFINITY).is_some())
            .count();
        assert!(
            hits > rays.len() / 5,
            "{name}: only {hits} of {} rays hit",
            rays.len()
        );
        for options in common::both_builders() {
            let bvh = Bvh::build(&tris, &options);
            assert_eq!(bvh.triangle_count(), tris.len(), "{name}");
            for n in &bvh.nodes {
                assert!(
                    n.min.iter().chain(&n.max).all(|c| !c.is_nan()),
                    "{name}: NaN in a node box"
                );
            }
            assert!(!bvh.stats.sah_cost.is_nan(), "{name}: SAH cost NaN");
            for r in &rays {
                assert_eq!(
                    bvh.intersect(r, f32::INFINITY)
                        .map(|h| (h.prim, h.t.to_bits())),
                    bf.closest(r, f32::INFINITY)
                        .map(|h| (h.prim, h.t.to_bits())),
                    "{name} {:?}: {r:?}",
                    options.split
                );
            }
        }
    }
}

/// An object 1e19 across (the unit icosphere scaled by 2^63): the watertight test's f32
/// products of three coordinates overflow (up to ~1e58), so the f32 distance is infinite and
/// the f64 path measures it. Scaling by a power of two is exact, so the answer is known: every
/// ray hits the triangle it hits at unit scale, at 2^63 times the distance; the BVH agrees with
/// brute force bit for bit, and a fifth of the rays hit at least.
#[test]
fn an_object_1e19_across_is_hit_as_at_unit_scale() {
    const SCALE: f32 = 9_223_372_036_854_775_808.0; // 2^63
    let unit = shapes::icosphere(2);
    let huge: Vec<[Vec3; 3]> = unit.iter().map(|t| t.map(|v| v * SCALE)).collect();
    let rays = common::random_rays(&unit, 4_000, 5);
    let unit_bvh = Bvh::build(&unit, &BuildOptions::sah());
    let bf = BruteForce::new(&huge);
    let mut hits = 0;
    for options in common::both_builders() {
        let bvh = Bvh::build(&huge, &options);
        for r in &rays {
            let big = Ray::new(r.origin * SCALE, r.dir);
            let got = bvh.intersect(&big, f32::INFINITY);
            assert_eq!(
                got.map(|h| (h.prim, h.t.to_bits())),
                bf.closest(&big, f32::INFINITY)
                    .map(|h| (h.prim, h.t.to_bits())),
                "{:?} {big:?}",
                options.split
            );
            let want = unit_bvh.intersect(r, f32::INFINITY);
            assert_eq!(got.map(|h| h.prim), want.map(|h| h.prim), "{r:?}");
            if let (Some(g), Some(w)) = (got, want) {
                let rel = (g.t / SCALE - w.t).abs() / w.t;
                assert!(rel < 1e-5, "t {} vs {} at unit scale", g.t / SCALE, w.t);
                hits += 1;
            }
        }
    }
    assert!(hits > rays.len() * 2 / 5, "only {hits} hits");
}

// ---------------------------------------------------------------------------------------
// Scale
// ---------------------------------------------------------------------------------------

/// A unit cube resting on a floor under a point light, the camera looking at the contact.
fn cube_on_floor(offset: Vec3) -> Scene {
    let white = Material {
        diffuse: Vec3::splat(0.8),
        ..Material::default()
    };
    let mut mesh = Mesh::default();
    let m =
        Affine3A::from_scale_rotation_translation(Vec3::splat(8.0), glam::Quat::IDENTITY, offset);
    let floor: Vec<[Vec3; 3]> = shapes::quad()
        .iter()
        .map(|t| t.map(|v| m.transform_point3(v)))
        .collect();
    mesh.append(Mesh::from_triangles(floor, 0), 0);
    // shapes::cube spans -0.5..0.5: lift it so its bottom face lies exactly on the floor.
    let cube: Vec<[Vec3; 3]> = shapes::cube()
        .iter()
        .map(|t| t.map(|v| v + Vec3::Y * 0.5 + offset))
        .collect();
    mesh.append(Mesh::from_triangles(cube, 0), 0);
    Scene {
        name: "cube on floor".into(),
        mesh,
        materials: vec![white],
        lights: vec![Light::Point {
            position: Vec3::new(-2.0, 1.5, -1.0) + offset,
            color: Vec3::ONE,
            intensity: 20.0,
        }],
        camera: Camera {
            position: Vec3::new(1.5, 2.0, 3.0) + offset,
            look_at: Vec3::new(0.5, 0.0, 0.5) + offset,
            up: Vec3::Y,
            vfov_deg: 40.0,
            lens_radius: 0.0,
            focus_distance: 1.0,
        },
        environment: Environment::None,
        integrator: tracery::scene::Integrator::Direct,
        energy_compensation: true,
        warnings: Vec::new(),
        animation: None,
        instances: Default::default(),
        objects: Vec::new(),
    }
}

/// Render settings of a `w`x`h` image with `spp` samples, the rest default.
fn settings(w: u32, h: u32, spp: u32) -> RenderSettings {
    RenderSettings {
        width: w,
        height: h,
        spp,
        ..RenderSettings::default()
    }
}

/// The mean film of `scene` rendered over its own SAH BVH.
fn render_mean(scene: &Scene, w: u32, h: u32, spp: u32) -> Vec<Vec3> {
    let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
    render(scene, &bvh, &settings(w, h, spp), &|_| {})
        .unwrap()
        .film
        .mean()
}

#[test]
fn a_scene_moved_by_1e5_and_1e6_renders_the_same_image_without_acne_or_leaks() {
    // The stated tolerance: floats are 1/128 apart at 1e5 and 1/16 at 1e6, so edges and
    // shadow borders may move by that much: here (0.026 scene units a pixel) by under one
    // pixel at 1e5 and under three at 1e6. Every pixel of the moved image must lie within
    // the range of the reference's pixels that near it, widened by 5% (a shading point moved
    // by 1/128 half a unit from the light changes its light by 3%) and 2% of the brightest:
    // acne (dark specks on lit floor) and leaks (light inside the cube's shadow) fall outside.
    let (w, h) = (96usize, 72usize);
    let reference = render_mean(&cube_on_floor(Vec3::ZERO), w as u32, h as u32, 4);
    let value: Vec<f32> = reference.iter().map(|p| p.max_element()).collect();
    let top = value.iter().copied().fold(0.0, f32::max);
    let shadowed = value.iter().filter(|&&v| v == 0.0).count();
    assert!(
        shadowed > 200,
        "the view holds the cube's shadow ({shadowed} px)"
    );
    for (offset, radius, max_mean) in [(1e5f32, 1usize, 0.005f32), (1e6, 3, 0.04)] {
        let at = Vec3::new(offset, offset * 0.5, -offset);
        let moved = render_mean(&cube_on_floor(at), w as u32, h as u32, 4);
        let mut outside = Vec::new();
        let mut total = 0.0;
        for y in 0..h {
            for x in 0..w {
                let b = moved[y * w + x];
                assert!(b.is_finite());
                let v = b.max_element();
                total += (v - value[y * w + x]).abs() / top;
                let (mut lo, mut hi) = (f32::INFINITY, 0.0f32);
                for ny in y.saturating_sub(radius)..(y + radius + 1).min(h) {
                    for nx in x.saturating_sub(radius)..(x + radius + 1).min(w) {
                        lo = lo.min(value[ny * w + nx]);
                        hi = hi.max(value[ny * w + nx]);
                    }
                }
                if v < 0.95 * lo - 0.02 * top || v > 1.05 * hi + 0.02 * top {
                    outside.push((x, y, v, lo, hi));
                }
            }
        }
        let mean = total / (w * h) as f32;
        assert!(
            mean <= max_mean,
            "offset {offset}: mean difference {mean} of the brightest"
        );
        assert!(
            outside.is_empty(),
            "offset {offset}: {} pixels unlike any reference pixel near them (acne or leaks), \
             first {:?}",
            outside.len(),
            &outside[..outside.len().min(5)]
        );
    }
}

#[test]
fn a_box_resting_on_a_plane_leaks_no_light_at_the_contact() {
    // Floor points as the renderer finds them (a ray down onto the floor, the point
    // interpolated from the hit's barycentrics, moved off by its error bound) right beside the
    // cube's +x and +z faces, on the side away from the light: every shadow ray must be
    // blocked by the cube, at every offset. Light slipping under the cube would show here.
    for offset in [Vec3::ZERO, Vec3::splat(1e5), Vec3::splat(1e6)] {
        let s = cube_on_floor(offset);
        let tris = &s.mesh.triangles;
        let bvh = Bvh::build(tris, &BuildOptions::sah());
        let Light::Point { position, .. } = s.lights[0] else {
            unreachable!()
        };
        let mut rng = SplitMix64::new(9);
        let mut tested = 0;
        for _ in 0..20_000 {
            let along = 0.8 * rng.next_f32() - 0.4;
            let gap = 0.05 * rng.next_f32();
            let target = if rng.next_f32() < 0.5 {
                Vec3::new(0.5 + gap, 0.0, along)
            } else {
                Vec3::new(along, 0.0, 0.5 + gap)
            } + offset;
            let down = Ray::new(
                target + Vec3::new(0.3, 2.0, 0.2),
                Vec3::new(-0.3, -2.0, -0.2),
            );
            let Some(hit) = bvh.intersect(&down, f32::INFINITY) else {
                continue;
            };
            let t = &tris[hit.prim as usize];
            if tracery::scene::face_normal(t).y.abs() < 0.99 || hit.prim >= 2 {
                continue; // not the floor (the ray met the cube)
            }
            let b = [1.0 - hit.u - hit.v, hit.u, hit.v];
            let p = t[0] * b[0] + t[1] * b[1] + t[2] * b[2];
            let origin = tracery::geometry::offset_ray_origin(
                p,
                tracery::geometry::interpolation_error(t, b),
                Vec3::Y,
            );
            // Only points whose straight line to the light runs through the cube's middle.
            let to = position - p;
            let q = p + to * ((-0.5 + offset.x - p.x) / to.x);
            let (qy, qz) = (q.y - offset.y, q.z - offset.z);
            if !(qy > 0.05 && qy < 0.95 && qz.abs() < 0.45) {
                continue;
            }
            tested += 1;
            let ray = Ray::new(origin, position - origin);
            assert!(
                bvh.occluded(&ray, 1.0 - 1e-4),
                "light leaks to {p} (offset {offset}), shadow ray from {origin}"
            );
        }
        assert!(
            tested > 1000,
            "offset {offset}: only {tested} points in the shadow"
        );
    }
}

// ---------------------------------------------------------------------------------------
// Camera and sampling
// ---------------------------------------------------------------------------------------

fn cornell(w: u32, h: u32, spp: u32) -> (Scene, Bvh, RenderSettings) {
    let s = Scene::cornell_box();
    let bvh = Bvh::build(&s.mesh.triangles, &BuildOptions::sah());
    (s, bvh, settings(w, h, spp))
}

#[test]
fn one_by_one_and_one_by_n_images_render() {
    for (w, h) in [(1, 1), (1, 17), (17, 1), (2, 1)] {
        let (s, bvh, settings) = cornell(w, h, 2);
        let out = render(&s, &bvh, &settings, &|_| {}).unwrap();
        let m = out.film.mean();
        assert_eq!(m.len(), (w * h) as usize);
        assert!(m.iter().all(|p| p.is_finite()), "{w}x{h}");
        assert_eq!(out.rays.camera, u64::from(w * h * 2));
    }
    // The 1x1 image's one ray is the view axis.
    let c = CameraRays::new(&Scene::cornell_box().camera, 1, 1);
    let axis =
        (Scene::cornell_box().camera.look_at - Scene::cornell_box().camera.position).normalize();
    assert!((c.pinhole(0.5, 0.5).dir.normalize() - axis).length() < 1e-6);
}

#[test]
fn a_65536_wide_image_maps_every_column_without_overflow() {
    let (s, bvh, settings) = cornell(65_536, 1, 1);
    let out = render(&s, &bvh, &settings, &|_| {}).unwrap();
    assert_eq!(out.film.mean().len(), 65_536);
    assert!(out.film.mean().iter().all(|p| p.is_finite()));
    // Columns run monotonically across the view; the two edges mirror each other.
    let c = CameraRays::new(&s.camera, 65_536, 65_536);
    let right = (s.camera.look_at - s.camera.position)
        .cross(s.camera.up)
        .normalize();
    let mut last = f32::NEG_INFINITY;
    for x in (0..65_536).step_by(97).chain([65_535]) {
        let d = c.pinhole(x as f32 + 0.5, 32_768.0).dir.normalize();
        let across = d.dot(right);
        assert!(across > last, "column {x}");
        last = across;
    }
    let l = c.pinhole(0.5, 65_535.5).dir.normalize();
    let r = c.pinhole(65_535.5, 0.5).dir.normalize();
    assert!((l.dot(right) + r.dot(right)).abs() < 1e-5);
}

#[test]
fn a_huge_lens_and_focus_at_infinity_stay_finite() {
    for (lens, focus) in [
        (1e6f32, 10.0f32),
        (0.1, f32::INFINITY),
        (0.1, f32::MAX),
        (1e30, f32::INFINITY),
        (f32::NAN, f32::NAN),
        (-1.0, 0.0),
    ] {
        let (mut s, bvh, settings) = cornell(24, 16, 4);
        s.camera.lens_radius = lens;
        s.camera.focus_distance = focus;
        let out = render(&s, &bvh, &settings, &|_| {}).unwrap();
        assert!(
            out.film.mean().iter().all(|p| p.is_finite()),
            "lens {lens}, focus {focus}"
        );
        let c = CameraRays::new(&s.camera, 24, 16);
        let r = c.thin_lens(3.5, 9.5, glam::Vec2::new(0.9, 0.1));
        assert!(r.origin.is_finite() && r.dir.is_finite() && r.dir != Vec3::ZERO);
    }
}

#[test]
fn a_camera_inside_a_closed_mesh_sees_only_the_inside() {
    let sphere = shapes::icosphere(3);
    let mut s = Scene::from_mesh(
        "inside".into(),
        Mesh::from_triangles(sphere.clone(), 0),
        vec![Material::default()],
    );
    s.environment = Environment::Sky {
        intensity: 1.0,
        rotation_deg: 0.0,
    };
    s.camera.position = Vec3::new(0.1, -0.05, 0.2);
    s.camera.look_at = Vec3::new(1.0, 0.3, 0.0);
    s.lights = vec![Light::Point {
        position: Vec3::ZERO,
        color: Vec3::ONE,
        intensity: 1.0,
    }];
    let bvh = Bvh::build(&sphere, &BuildOptions::sah());
    let c = CameraRays::new(&s.camera, 64, 48);
    for r in c.pixel_center_rays() {
        assert!(bvh.intersect(&r, f32::INFINITY).is_some(), "escaped: {r:?}");
    }
    let image = render_mean(&s, 64, 48, 2);
    assert!(image.iter().all(|p| p.is_finite() && p.max_element() > 0.0));
}

#[test]
fn forward_parallel_to_up_falls_back_to_a_valid_basis() {
    let base = Scene::cornell_box().camera;
    for (position, look_at, up) in [
        (Vec3::ZERO, Vec3::Y, Vec3::Y),
        (Vec3::ZERO, -Vec3::Y * 3.0, Vec3::Y),
        (Vec3::ONE, Vec3::ONE, Vec3::Y),   // zero forward
        (Vec3::ZERO, Vec3::X, Vec3::ZERO), // zero up
        (Vec3::ZERO, Vec3::X, Vec3::NAN),  // NaN up
        (Vec3::ZERO, Vec3::NAN, Vec3::Y),  // NaN forward
    ] {
        let cam = Camera {
            position,
            look_at,
            up,
            ..base
        };
        let c = CameraRays::new(&cam, 8, 6);
        for r in c.pixel_center_rays() {
            assert!(
                r.dir.is_finite() && r.dir.length() > 0.0,
                "{position} -> {look_at}, up {up}"
            );
        }
        // Neighbouring pixels still look in different directions (the frame is not flat).
        let a = c.pinhole(0.5, 0.5).dir.normalize();
        let b = c.pinhole(7.5, 5.5).dir.normalize();
        assert!(a.dot(b) < 0.9999, "{position} -> {look_at}, up {up}");
    }
}

#[test]
fn a_zero_or_nan_ray_direction_gives_the_fallback_colour() {
    let mut s = Scene::cornell_box();
    for env in [
        Environment::None,
        Environment::Sky {
            intensity: 1.0,
            rotation_deg: 0.0,
        },
    ] {
        s.environment = env;
        let bvh = Bvh::build(&s.mesh.triangles, &BuildOptions::sah());
        let plan = RenderPlan::everything();
        let map = EnvironmentMap::load(&s.environment, true).unwrap();
        let tracer = Tracer::new(&s, &bvh, plan, 5, &map);
        for dir in [
            Vec3::ZERO,
            Vec3::NAN,
            Vec3::new(f32::INFINITY, 0.0, 1.0),
            -Vec3::ZERO,
        ] {
            for origin in [Vec3::new(2.7, 2.7, -5.0), Vec3::NAN] {
                let mut counts = RayCounts::default();
                let mut sampler = PathSampler::new(PixelSampler::new(SamplerKind::Sobol, 1, 0, 0));
                let l = tracer.radiance(&Ray::new(origin, dir), &mut sampler, &mut counts);
                assert_eq!(
                    l,
                    tracery::render::tracer::FALLBACK,
                    "dir {dir}, origin {origin}"
                );
            }
        }
    }
}

#[test]
fn a_thousand_stacked_transparent_layers_pass_exactly_the_product() {
    let t = 0.99f32;
    let layers = common::layers(1000, 0.01);
    let expected = (0..1000).fold(1.0f32, |acc, _| acc * t);
    for options in common::both_builders() {
        let bvh = Bvh::build(&layers, &options);
        let mut rng = SplitMix64::new(1);
        for _ in 0..200 {
            let (x, y) = (rng.next_f32(), rng.next_f32());
            let ray = Ray::new(Vec3::new(x, y, 0.0), Vec3::Z);
            let through = bvh.transmittance(&ray, 100.0, |_, _| Vec3::splat(t));
            assert_eq!(through, Vec3::splat(expected), "at ({x}, {y})");
        }
        // Through the shared diagonal of every layer too.
        let ray = Ray::new(Vec3::new(0.5, 0.5, 0.0), Vec3::Z);
        assert_eq!(
            bvh.transmittance(&ray, 100.0, |_, _| Vec3::splat(t)),
            Vec3::splat(expected)
        );
    }
}

// ---------------------------------------------------------------------------------------
// Far from the origin
// ---------------------------------------------------------------------------------------

/// The world-space offset the far scenes are moved by.
const FAR: [f64; 3] = [1e6, 1e6, -1e6];

/// Renders a scene file at 160 x 120, 8 spp, direct light, to 8-bit pixels.
fn render_file(path: &std::path::Path) -> Vec<u8> {
    let mut scene = Scene::load(path).unwrap_or_else(|e| panic!("{e:#}"));
    scene.integrator = tracery::render::Integrator::Direct;
    let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
    let settings = RenderSettings {
        width: 160,
        height: 120,
        spp: 8,
        ..RenderSettings::default()
    };
    render(&scene, &bvh, &settings, &|_| {})
        .unwrap()
        .film
        .to_rgba8(1.0)
}

fn mean_levels(a: &[u8], b: &[u8]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| x.abs_diff(*y) as f64)
        .sum::<f64>()
        / a.len() as f64
}

/// `[x, y, z]` of a TOML array moved by `FAR`, written with every digit.
fn far(p: [f64; 3]) -> String {
    format!(
        "[{:?}, {:?}, {:?}]",
        p[0] + FAR[0],
        p[1] + FAR[1],
        p[2] + FAR[2]
    )
}

/// The Cornell box with every vertex of its OBJ written a million units away (read in f64
/// and placed about its centre), and the camera and light moved with it, renders the picture
/// it renders at the origin (f32 world coordinates are 1/16 apart there: blocks of stairs).
#[test]
fn the_cornell_box_a_million_units_away_renders_as_at_the_origin() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    let obj = std::fs::read_to_string(root.join("assets/models/cornell_box.obj")).unwrap();
    let moved: String = obj
        .lines()
        .map(|l| match l.strip_prefix("v ") {
            Some(rest) => {
                let v: Vec<f64> = rest
                    .split_whitespace()
                    .map(|x| x.parse().unwrap())
                    .collect();
                format!(
                    "v {:?} {:?} {:?}\n",
                    v[0] + FAR[0],
                    v[1] + FAR[1],
                    v[2] + FAR[2]
                )
            }
            None => format!("{l}\n"),
        })
        .collect();
    std::fs::write(dir.path().join("far.obj"), moved).unwrap();
    std::fs::copy(
        root.join("assets/models/cornell_box.mtl"),
        dir.path().join("cornell_box.mtl"),
    )
    .unwrap();
    let scene = |obj: &str, at: &dyn Fn([f64; 3]) -> String| {
        format!(
            "[camera]\nposition = {}\nlook_at = {}\nfov = 39.3\n\n[[meshes]]\npath = \"{obj}\"\n\n\
             [[lights]]\nkind = \"rect\"\ncorner = {}\nedge_u = [0.0, 0.0, 1.05]\n\
             edge_v = [-1.30, 0.0, 0.0]\ncolor = [1.0, 0.70588235, 0.23529412]\nintensity = 17.0\n\
             samples = 4\n\n[environment]\nkind = \"none\"\n",
            at([2.78, 2.73, -8.0]),
            at([2.78, 2.73, 0.0]),
            at([3.43, 5.487, 2.27]),
        )
    };
    let here = dir.path().join("here.toml");
    let origin_obj = root.join("assets/models/cornell_box.obj");
    std::fs::write(
        &here,
        scene(origin_obj.to_str().unwrap(), &|p| format!("{p:?}")),
    )
    .unwrap();
    let away = dir.path().join("away.toml");
    std::fs::write(&away, scene("far.obj", &far)).unwrap();
    let s = Scene::load(&away).unwrap();
    assert!(
        (s.mesh.origin - glam::DVec3::from(FAR)).abs().max_element() < 16.0,
        "the mesh is kept about its own origin: {}",
        s.mesh.origin
    );
    let d = mean_levels(&render_file(&here), &render_file(&away));
    eprintln!("Cornell box 1e6 away: mean difference {d:.3} levels");
    assert!(d <= 0.5, "mean difference {d:.3} levels");
}

/// The bunny scene moved by a million units through its scene file (mesh, floor, camera and
/// light) renders the picture it renders at the origin.
#[test]
fn the_bunny_scene_a_million_units_away_renders_as_at_the_origin() {
    let Some(bunny) = common::external("bunny/bunny.obj") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let scene = |at: &dyn Fn([f64; 3]) -> String| {
        format!(
            "[camera]\nposition = {}\nlook_at = {}\nfov = 40.0\n\n\
             [[meshes]]\npath = {:?}\ncrease_angle = 60.0\ntranslate = {}\n\n\
             [[meshes]]\nshape = \"quad\"\ntranslate = {}\nscale = 12.0\n\n\
             [[lights]]\nkind = \"point\"\nposition = {}\nintensity = 60.0\n\n\
             [environment]\nkind = \"sky\"\nintensity = 0.4\n",
            at([0.0, 0.5, 4.2]),
            at([0.0, 0.0, 0.0]),
            bunny.to_str().unwrap(),
            at([0.0, 0.0, 0.0]),
            at([0.0, -0.9913, 0.0]),
            at([2.0, 4.0, 3.0]),
        )
    };
    let here = dir.path().join("here.toml");
    std::fs::write(&here, scene(&|p| format!("{p:?}"))).unwrap();
    let away = dir.path().join("away.toml");
    std::fs::write(&away, scene(&far)).unwrap();
    let d = mean_levels(&render_file(&here), &render_file(&away));
    eprintln!("bunny 1e6 away: mean difference {d:.3} levels");
    assert!(d <= 0.5, "mean difference {d:.3} levels");
}
