//! Rays, boxes and triangles: the slab-test cases and the watertight triangle test, by name.

mod common;

use glam::{Vec3, Vec3A};
use tracery::bvh::{BruteForce, BuildOptions, Bvh};
use tracery::geometry::shapes;
use tracery::geometry::{
    Aabb, PreparedRay, Ray, interpolation_error, intersect_triangle_t, offset_ray_origin,
};

fn unit_box() -> Aabb {
    Aabb::new(Vec3::ZERO, Vec3::ONE)
}

fn slab_hit(b: &Aabb, o: Vec3, d: Vec3) -> Option<f32> {
    b.intersect(&PreparedRay::new(&Ray::new(o, d)), f32::INFINITY)
}

/// The same question through the BVH's own box test: a BVH over one triangle spanning the
/// box's diagonal face, so the root box is `b`... reported as whether the root is entered.
fn bvh_enters(tris: &[[Vec3; 3]], o: Vec3, d: Vec3) -> bool {
    let bvh = Bvh::build(tris, &BuildOptions::sah());
    let mut entered = false;
    bvh.intersect_visit(&Ray::new(o, d), f32::INFINITY, |_| entered = true);
    entered
}

#[test]
fn slab_plus_and_minus_zero_components_give_the_same_answer() {
    let b = unit_box();
    let origins = [
        Vec3::new(0.5, 0.5, -1.0),
        Vec3::new(0.0, 0.5, -1.0),
        Vec3::new(1.0, 0.5, -1.0),
        Vec3::new(1.5, 0.5, -1.0),
        Vec3::new(-0.5, 0.5, -1.0),
        Vec3::new(0.5, 1.0, -1.0),
    ];
    for o in origins {
        for d in [Vec3::new(0.0, 0.0, 1.0), Vec3::new(0.0, -0.0, 1.0)] {
            let plus = slab_hit(&b, o, d);
            let minus = slab_hit(&b, o, Vec3::new(-0.0, d.y, d.z));
            assert_eq!(plus, minus, "origin {o}");
            assert!(plus.is_none_or(|t| t.is_finite()));
        }
    }
}

#[test]
fn slab_origin_on_a_slab_plane_with_a_zero_component_is_inside() {
    let b = unit_box();
    // The ray runs in the plane x = 0 (and x = 1): a closed box is met.
    for x in [0.0f32, 1.0] {
        for sign in [0.0f32, -0.0] {
            let t = slab_hit(&b, Vec3::new(x, 0.5, -1.0), Vec3::new(sign, 0.0, 1.0));
            assert_eq!(t, Some(1.0), "x = {x}, sign {sign:?}");
        }
    }
    // Just outside the plane: missed.
    let t = slab_hit(
        &b,
        Vec3::new(1.0 + 1e-6, 0.5, -1.0),
        Vec3::new(0.0, 0.0, 1.0),
    );
    assert_eq!(t, None);
}

#[test]
fn slab_flat_box_is_hit_head_on() {
    let flat = Aabb::new(Vec3::new(0.0, 0.0, 2.0), Vec3::new(1.0, 1.0, 2.0));
    assert_eq!(
        slab_hit(&flat, Vec3::new(0.5, 0.5, 0.0), Vec3::Z),
        Some(2.0)
    );
    assert_eq!(
        slab_hit(&flat, Vec3::new(0.5, 0.5, 4.0), -Vec3::Z),
        Some(2.0)
    );
    assert_eq!(slab_hit(&flat, Vec3::new(1.5, 0.5, 0.0), Vec3::Z), None);
}

#[test]
fn slab_flat_box_is_hit_grazing() {
    // The ray runs inside the plane of a zero-thickness box.
    let flat = Aabb::new(Vec3::new(0.0, 0.0, 2.0), Vec3::new(1.0, 1.0, 2.0));
    let t = slab_hit(&flat, Vec3::new(-1.0, 0.5, 2.0), Vec3::X);
    assert_eq!(t, Some(1.0));
    let t = slab_hit(&flat, Vec3::new(-1.0, 0.5, 2.0), Vec3::new(1.0, 0.0, -0.0));
    assert_eq!(t, Some(1.0));
    // The BVH agrees: a flat triangle in z = 2 is entered by a grazing ray.
    let tri = [
        Vec3::new(0.0, 0.0, 2.0),
        Vec3::new(1.0, 0.0, 2.0),
        Vec3::new(0.0, 1.0, 2.0),
    ];
    assert!(bvh_enters(&[tri], Vec3::new(-1.0, 0.25, 2.0), Vec3::X));
    assert!(bvh_enters(
        &[tri],
        Vec3::new(-1.0, 0.25, 2.0),
        Vec3::new(1.0, -0.0, 0.0)
    ));
}

#[test]
fn slab_direction_components_of_1e30_do_not_miss() {
    let b = unit_box();
    for d in [
        Vec3::new(1e-30, 1e-30, 1.0),
        Vec3::new(-1e-30, 1e-30, 1.0),
        Vec3::new(1e-30, -1e-30, -1.0),
        Vec3::new(1e-45, -1e-40, 1.0), // subnormals
    ] {
        let o = Vec3::new(0.5, 0.5, if d.z > 0.0 { -1.0 } else { 2.0 });
        let t = slab_hit(&b, o, d).expect("hits");
        assert!((t - 1.0).abs() < 1e-6, "d = {d}: t = {t}");
    }
}

#[test]
fn slab_entry_is_clamped_to_zero_inside_the_box() {
    assert_eq!(slab_hit(&unit_box(), Vec3::splat(0.5), Vec3::X), Some(0.0));
    assert_eq!(
        slab_hit(&unit_box(), Vec3::new(2.0, 0.5, 0.5), Vec3::X),
        None
    );
}

fn tri(a: [f32; 3], b: [f32; 3], c: [f32; 3]) -> [Vec3; 3] {
    [Vec3::from(a), Vec3::from(b), Vec3::from(c)]
}

#[test]
fn ray_through_a_shared_edge_hits_exactly_one_triangle() {
    // A unit square as two triangles, both windings of the second one.
    for flip in [false, true] {
        let a = tri([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]);
        let mut b = tri([0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]);
        if flip {
            b.swap(1, 2);
        }
        let bf = BruteForce::new(&[a, b]);
        for i in 1..64 {
            let s = i as f32 / 64.0; // exactly on the diagonal x = y
            for d in [Vec3::Z, -Vec3::Z, Vec3::new(0.3, -0.2, 1.0)] {
                let o = Vec3::new(s, s, 0.0) - d * 2.0;
                let hits = bf.all_hits(&Ray::new(o, d), f32::INFINITY);
                assert_eq!(hits.len(), 1, "s = {s}, d = {d}, flip {flip}: {hits:?}");
            }
        }
    }
}

#[test]
fn ray_through_a_fan_vertex_hits_exactly_one_triangle() {
    let c = Vec3::new(0.25, 0.5, 0.0);
    let bf = BruteForce::new(&common::fan(7, c));
    for d in [
        Vec3::Z,
        -Vec3::Z,
        Vec3::new(0.1, 0.7, 1.0),
        Vec3::new(-0.4, 0.0, -1.0),
    ] {
        let hits = bf.all_hits(&Ray::new(c - d * 3.0, d), f32::INFINITY);
        assert_eq!(hits.len(), 1, "d = {d}: {hits:?}");
    }
}

#[test]
fn rays_from_inside_a_closed_icosphere_never_escape() {
    let sphere = shapes::icosphere(3);
    let bvh = Bvh::build(&sphere, &BuildOptions::sah());
    let rays = common::random_rays(&sphere, 1_000_000, 99);
    let mut rng = tracery::rng::SplitMix64::new(1);
    for r in &rays {
        let o = Vec3::new(
            rng.next_f32() - 0.5,
            rng.next_f32() - 0.5,
            rng.next_f32() - 0.5,
        ) * 0.5;
        let ray = Ray::new(o, r.dir);
        assert!(
            bvh.intersect(&ray, f32::INFINITY).is_some(),
            "escaped: {ray:?}"
        );
    }
}

#[test]
fn ray_in_the_plane_of_a_triangle_misses_without_nan() {
    let t = tri([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]).map(Vec3A::from);
    for d in [Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::new(1.0, 1.0, 1e-7)] {
        let r = PreparedRay::new(&Ray::new(Vec3::new(-1.0, 0.25, 0.0), d));
        let hit = intersect_triangle_t(&r, &t, f32::INFINITY);
        assert!(!hit.is_nan());
        // In the plane (or crossing it only at the origin, t = 0): no hit at all.
        assert_eq!(hit, f32::INFINITY, "direction {d}");
    }
}

#[test]
fn zero_area_triangles_are_never_hit() {
    let point = tri([1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [1.0, 1.0, 0.0]);
    let line = tri([0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [2.0, 2.0, 0.0]);
    let bf = BruteForce::new(&[point, line]);
    for d in [Vec3::Z, Vec3::new(0.2, 0.1, 1.0)] {
        assert!(
            bf.all_hits(&Ray::new(Vec3::new(1.0, 1.0, -1.0), d), f32::INFINITY)
                .is_empty()
        );
    }
}

#[test]
fn origin_on_the_triangle_gives_no_hit_at_t_zero() {
    let t = tri([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]);
    let bf = BruteForce::new(&[t]);
    for d in [Vec3::Z, -Vec3::Z, Vec3::new(0.3, 0.3, 1.0)] {
        let hits = bf.all_hits(&Ray::new(Vec3::new(0.25, 0.25, 0.0), d), f32::INFINITY);
        assert!(hits.iter().all(|(_, t)| *t > 0.0), "{hits:?}");
    }
}

#[test]
fn offset_origin_leaves_the_surface_at_every_magnitude() {
    for scale in [1e-3f32, 1.0, 1e3, 1e5, 1e6, 1e7] {
        let c = Vec3::new(0.37, 0.61, 0.2) * scale;
        let quad = tri([-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]).map(|v| c + v * scale);
        let bf = BruteForce::new(&[quad]);
        let n = Vec3::Z;
        // Points as the renderer makes them: interpolated from the vertices.
        for b in [[0.25f32, 0.25, 0.5], [0.25, 0.35, 0.4], [0.9, 0.05, 0.05]] {
            let p = quad[0] * b[0] + quad[1] * b[1] + quad[2] * b[2];
            let o = offset_ray_origin(p, interpolation_error(&quad, b), n);
            assert!(o.z > p.z, "scale {scale}: not moved off the plane");
            // Leaving the surface upward, steeply or grazing, must not hit the surface itself.
            for d in [Vec3::new(0.3, 0.2, 1.0), Vec3::new(1.0, 0.5, 1e-3)] {
                let hits = bf.all_hits(&Ray::new(o, d), f32::INFINITY);
                assert!(hits.is_empty(), "scale {scale}, b {b:?}: self-hit {hits:?}");
            }
            // And the step is a few floats at the point's magnitude, not more.
            let ulp =
                (p.abs().max_element().next_up() - p.abs().max_element()).max(f32::MIN_POSITIVE);
            assert!(
                (o - p).length() <= 32.0 * ulp,
                "scale {scale}: moved {}",
                (o - p).length()
            );
        }
    }
}

/// Rays leaving a surface from [`offset_ray_origin`] in every direction of the hemisphere
/// (steep and grazing, with the plane's normal the major axis or not) never hit the surface
/// they leave: planes through 0 on each axis (where the point has no rounding error and the
/// origin moves a single float) and planes away from it. Before the distance error bound in the
/// triangle test, rays whose major axis was not the plane's normal hit the plane at `x = 0`
/// through the rounding of the sheared coordinates (the Cornell box's green wall).
#[test]
fn rays_leaving_a_surface_never_hit_it_whatever_their_major_axis() {
    let mut rng = 0x9e3779b97f4a7c15u64;
    let mut next = move || {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        (rng >> 40) as f32 / (1u64 << 24) as f32
    };
    let mut rays = 0;
    for axis in 0..3 {
        for offset in [0.0f32, 5.592, -3.3e-3, 1e4] {
            for sign in [1.0f32, -1.0] {
                // A triangle in the plane `p[axis] = offset`, wound so its normal is `sign`.
                let corner = |a: f32, b: f32| {
                    let mut v = Vec3::ZERO;
                    v[axis] = offset;
                    v[(axis + 1) % 3] = a;
                    v[(axis + 2) % 3] = b;
                    v
                };
                let mut t = [corner(0.0, 0.0), corner(5.488, 0.0), corner(0.0, 5.592)];
                let mut n = Vec3::ZERO;
                n[axis] = sign;
                if tracery::scene::face_normal(&t).dot(n) < 0.0 {
                    t.swap(1, 2);
                }
                let bf = BruteForce::new(&[t]);
                for _ in 0..2000 {
                    let (u, v) = (next(), next());
                    let (u, v) = if u + v > 1.0 {
                        (1.0 - u, 1.0 - v)
                    } else {
                        (u, v)
                    };
                    let b = [1.0 - u - v, u, v];
                    let p = t[0] * b[0] + t[1] * b[1] + t[2] * b[2];
                    let o = offset_ray_origin(p, interpolation_error(&t, b), n);
                    // A direction on the side of n, from grazing (1e-4) to along the normal.
                    let mut d =
                        Vec3::new(next() * 2.0 - 1.0, next() * 2.0 - 1.0, next() * 2.0 - 1.0);
                    d[axis] = sign * (next() * next()).max(1e-4) * 1.5;
                    let hits = bf.all_hits(&Ray::new(o, d), f32::INFINITY);
                    assert!(
                        hits.is_empty(),
                        "plane {axis} = {offset} ({sign}): ray from {o} along {d} hits it at {hits:?}"
                    );
                    rays += 1;
                }
            }
        }
    }
    assert_eq!(rays, 3 * 4 * 2 * 2000);
}
