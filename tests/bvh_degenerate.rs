//! Builds that must not crash, loop or overflow, by name.

mod common;

use glam::Vec3;
use tracery::bvh::{BuildOptions, Bvh, MAX_DEPTH};
use tracery::geometry::Ray;
use tracery::geometry::shapes;

fn build_all(tris: &[[Vec3; 3]]) -> Vec<Bvh> {
    common::both_builders()
        .iter()
        .map(|o| Bvh::build(tris, o))
        .collect()
}

fn check_invariants(bvh: &Bvh) {
    let s = &bvh.stats;
    let mut leaf_tris = 0;
    bvh.for_each_node(|n, _| {
        if n.is_leaf() {
            leaf_tris += n.count as usize;
            assert!(n.count <= bvh.options.max_leaf_size || s.levels as usize >= MAX_DEPTH - 32);
        }
    });
    assert_eq!(leaf_tris, bvh.triangle_count());
    assert!((s.levels as usize) <= MAX_DEPTH);
    assert!(s.sah_cost.is_finite());
    let b = bvh.bounds();
    if bvh.triangle_count() > 0 {
        assert!(b.min.is_finite() && b.max.is_finite());
    }
}

#[test]
fn empty_mesh_builds_and_every_ray_misses() {
    for bvh in build_all(&[]) {
        check_invariants(&bvh);
        assert_eq!(bvh.stats.nodes, 0);
        assert!(
            bvh.intersect(&Ray::new(Vec3::ZERO, Vec3::X), f32::INFINITY)
                .is_none()
        );
        assert!(!bvh.occluded(&Ray::new(Vec3::ZERO, Vec3::X), f32::INFINITY));
    }
}

#[test]
fn one_triangle_is_a_single_leaf() {
    let t = [Vec3::ZERO, Vec3::X, Vec3::Y];
    for bvh in build_all(&[t]) {
        check_invariants(&bvh);
        assert_eq!(
            (bvh.stats.nodes, bvh.stats.leaves, bvh.stats.levels),
            (1, 1, 1)
        );
        let hit = bvh.intersect(&Ray::new(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z), f32::INFINITY);
        assert_eq!(hit.map(|h| h.prim), Some(0));
    }
}

#[test]
fn two_triangles_are_found() {
    let tris = [
        [Vec3::ZERO, Vec3::X, Vec3::Y],
        [Vec3::Z, Vec3::Z + Vec3::X, Vec3::Z + Vec3::Y],
    ];
    for bvh in build_all(&tris) {
        check_invariants(&bvh);
        let hit = bvh.intersect(&Ray::new(Vec3::new(0.2, 0.2, 2.0), -Vec3::Z), f32::INFINITY);
        assert_eq!(hit.map(|h| h.prim), Some(1));
    }
}

#[test]
fn all_centroids_equal_builds_bounded() {
    // Triangles rotated about one common centroid: no plane separates them.
    let tris: Vec<[Vec3; 3]> = (0..5000)
        .map(|i| {
            let a = i as f32 * 0.001;
            let (s, c) = a.sin_cos();
            let v = |x: f32, y: f32| {
                Vec3::new(c * x - s * y, s * x + c * y, 0.1 * (i % 7) as f32 - 0.3)
            };
            [v(1.0, 0.0), v(-0.5, 0.866), v(-0.5, -0.866)]
        })
        .collect();
    let rays = common::random_rays(&tris, 2000, 4);
    for bvh in build_all(&tris) {
        check_invariants(&bvh);
        common::assert_matches_brute_force("equal centroids", &tris, &[&bvh], &rays);
    }
}

#[test]
fn a_million_copies_of_one_triangle_build_with_bounded_depth() {
    let t = [Vec3::ZERO, Vec3::X, Vec3::Y];
    let tris = vec![t; 1_000_000];
    for bvh in build_all(&tris) {
        check_invariants(&bvh);
        assert!(bvh.stats.levels as usize <= MAX_DEPTH, "{:?}", bvh.stats);
        let hit = bvh.intersect(&Ray::new(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z), f32::INFINITY);
        assert_eq!(
            hit.map(|h| h.prim),
            Some(0),
            "the lowest index wins the tie"
        );
    }
}

#[test]
fn all_triangles_coplanar_in_an_axis_plane() {
    // Every triangle in the plane x = 2.
    let tris: Vec<[Vec3; 3]> = shapes::grid(40, 1.0)
        .iter()
        .map(|t| t.map(|v| Vec3::new(2.0, v.x, v.y)))
        .collect();
    let rays = common::random_rays(&tris, 20_000, 8);
    for bvh in build_all(&tris) {
        check_invariants(&bvh);
        common::assert_matches_brute_force("plane x = 2", &tris, &[&bvh], &rays);
    }
}

#[test]
fn zero_area_triangles_build_and_are_never_hit() {
    let mut tris = vec![[Vec3::ONE; 3]; 100];
    tris.extend((0..100).map(|i| {
        let p = Vec3::splat(i as f32 * 0.01);
        [p, p + Vec3::X, p + 2.0 * Vec3::X]
    }));
    let rays = common::random_rays(&tris, 5000, 2);
    for bvh in build_all(&tris) {
        check_invariants(&bvh);
        assert!(
            rays.iter()
                .all(|r| bvh.intersect(r, f32::INFINITY).is_none())
        );
    }
}

#[test]
fn nan_and_infinite_vertices_are_left_out_and_counted() {
    let mut tris = shapes::icosphere(2);
    let good = tris.len();
    tris.insert(3, [Vec3::new(f32::NAN, 0.0, 0.0), Vec3::X, Vec3::Y]);
    tris.insert(
        50,
        [Vec3::ZERO, Vec3::new(f32::INFINITY, 0.0, 0.0), Vec3::Y],
    );
    tris.push([Vec3::ZERO, Vec3::X, Vec3::new(0.0, f32::NEG_INFINITY, 1.0)]);
    let rays = common::random_rays(&shapes::icosphere(2), 20_000, 6);
    for bvh in build_all(&tris) {
        check_invariants(&bvh);
        assert_eq!(bvh.stats.excluded, 3);
        assert_eq!(bvh.triangle_count(), good);
        common::assert_matches_brute_force("non-finite left out", &tris, &[&bvh], &rays);
    }
}

#[test]
fn stats_describe_the_tree() {
    let tris = shapes::icosphere(4);
    for bvh in build_all(&tris) {
        let s = bvh.stats;
        assert_eq!(s.triangles, tris.len());
        assert_eq!(s.nodes, 2 * s.leaves - 1, "a binary tree");
        assert!(s.min_leaf_size >= 1 && s.max_leaf_size <= bvh.options.max_leaf_size);
        assert!((s.mean_leaf_size - tris.len() as f64 / s.leaves as f64).abs() < 1e-9);
        assert!(s.sah_cost > 1.0 && s.build_ms >= 0.0);
        assert!(s.levels > (s.leaves as f64).log2().ceil() as u32);
    }
    // SAH beats the median split by its own measure.
    let sah = Bvh::build(&tris, &BuildOptions::sah()).stats.sah_cost;
    let median = Bvh::build(&tris, &BuildOptions::median()).stats.sah_cost;
    assert!(sah < median, "sah {sah} median {median}");
}

/// Triangles at x = 2^-126 13^k up to 1e38 (69 of them, f32's normal range), each as large
/// as its distance from the origin and so 13 times the next, one per leaf: binned SAH with 12
/// bins finds only the largest outside the first bin, and the sweep that splits small ranges
/// finds peeling the largest off alone cheapest (its flat box against the rest's), so the
/// tree peels one triangle per level: 68 levels deep. The builders switch to count splits at
/// depth `MAX_DEPTH - 32` = 64, which this input reaches, the tree stays within `MAX_DEPTH`,
/// and every ray still finds brute force's hit. (Before the bins were fixed, a centroid went
/// to its nearest bin boundary's bin, the two largest were peeled together where their ratio
/// allowed, and a row of unit triangles stopped at 48 levels; unit triangles no longer reach
/// the count split since small ranges are swept: below x = 1 their boxes are all alike and
/// the sweep splits them in blocks.)
#[test]
fn a_geometric_row_of_triangles_reaches_the_count_split_and_stays_within_the_depth() {
    let xs: Vec<f32> = (0..)
        .map(|k| f32::MIN_POSITIVE as f64 * 13f64.powi(k))
        .take_while(|&x| x < 1e38)
        .map(|x| x as f32)
        .collect();
    let tris: Vec<[Vec3; 3]> = xs
        .iter()
        .map(|&x| {
            [
                Vec3::new(x, 0.0, 0.0),
                Vec3::new(x, x, 0.0),
                Vec3::new(x, 0.0, x),
            ]
        })
        .collect();
    // One triangle per leaf: nothing stops the peeling but the depth.
    let options = BuildOptions {
        max_leaf_size: 1,
        ..BuildOptions::sah()
    };
    let bvh = Bvh::build(&tris, &options);
    check_invariants(&bvh);
    let levels = bvh.stats.levels as usize;
    eprintln!("geometric row: {} triangles, {levels} levels", tris.len());
    assert!(
        levels > MAX_DEPTH - 32,
        "the input must reach the count split ({levels} levels)"
    );
    let bf = tracery::bvh::BruteForce::new(&tris);
    for &x in &xs {
        for ray in [
            Ray::new(Vec3::new(x, 0.25 * x, -1.0), Vec3::Z),
            Ray::new(Vec3::new(-1.0, 0.25 * x, 0.25 * x), Vec3::X),
        ] {
            assert_eq!(
                bvh.intersect(&ray, f32::INFINITY).map(|h| h.prim),
                bf.closest(&ray, f32::INFINITY).map(|h| h.prim),
                "{ray:?}"
            );
        }
    }
}
