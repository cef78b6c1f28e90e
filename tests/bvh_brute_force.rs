//! Both builders, with every traversal kernel the CPU runs (scalar, SSE2, AVX2, AVX-512) and
//! both closest-hit walks (coherent and incoherent), against brute force: random rays, the
//! canonical camera rays and a diffuse bounce from each of their hits on the Cornell box, the
//! generated meshes and (fetched) the Stanford dragon.

mod common;

use glam::Vec3;
use tracery::bench::secondary::secondary_rays;
use tracery::bench::{HitRecord, canonical_rays};
use tracery::bvh::{BuildOptions, Bvh, SplitMethod};
use tracery::geometry::shapes;
use tracery::scene::{Mesh, Scene};

/// Checks `random` random rays, every `canonical_step`-th canonical camera ray and at most
/// `max_bounces` diffuse bounces from the canonical hits. Brute force costs a test of every
/// triangle per ray: the small meshes take every canonical ray, the dragon a sample across the
/// whole image.
fn check_mesh(
    name: &str,
    tris: &[[Vec3; 3]],
    random: usize,
    canonical_step: usize,
    max_bounces: usize,
) {
    let rays = common::random_rays(tris, random, 0xC0FFEE ^ tris.len() as u64);
    let bounds = Mesh::from_triangles(tris.to_vec(), 0).bounds();
    let camera: Vec<_> = canonical_rays(&bounds)
        .into_iter()
        .step_by(canonical_step)
        .collect();
    let all = common::all_bvhs(tris);
    let bvhs: Vec<&Bvh> = all.iter().map(|(_, b)| b).collect();
    let names: Vec<&str> = all.iter().map(|(n, _)| n.as_str()).collect();
    common::assert_matches_brute_force(
        &format!("{name}, {names:?}, random rays"),
        tris,
        &bvhs,
        &rays,
    );
    common::assert_matches_brute_force(
        &format!("{name}, {names:?}, canonical rays"),
        tris,
        &bvhs,
        &camera,
    );
    // Rays that start just off the surfaces (a diffuse bounce from each canonical hit), as a
    // path tracer's do: inside the boxes of the leaves they leave. The hits they start from are
    // the first tree's, just checked against brute force.
    let hits: Vec<HitRecord> = camera
        .iter()
        .map(|r| match bvhs[0].intersect(r, f32::INFINITY) {
            Some(h) => HitRecord {
                t: h.t,
                prim: h.prim,
            },
            None => HitRecord::MISS,
        })
        .collect();
    let bounce = secondary_rays(tris, &camera, &hits, &bounds).bounce;
    let bounce: Vec<_> = bounce
        .iter()
        .step_by(bounce.len() / max_bounces + 1)
        .copied()
        .collect();
    common::assert_matches_brute_force(
        &format!("{name}, {names:?}, bounces from the canonical hits"),
        tris,
        &bvhs,
        &bounce,
    );
}

#[test]
fn cornell_box_matches_brute_force() {
    let scene = Scene::cornell_box();
    check_mesh("cornell box", &scene.mesh.triangles, 100_000, 1, 50_000);
}

#[test]
fn icosphere_matches_brute_force() {
    check_mesh("icosphere", &shapes::icosphere(4), 100_000, 1, 50_000);
}

#[test]
fn grid_of_tiny_triangles_matches_brute_force() {
    check_mesh("grid", &shapes::grid(64, 1.0), 100_000, 1, 50_000);
}

#[test]
fn needle_triangles_match_brute_force() {
    check_mesh("needles", &shapes::needles(500, 1e4), 100_000, 1, 50_000);
}

#[test]
fn random_soup_matches_brute_force() {
    check_mesh(
        "soup",
        &shapes::random_soup(3000, 0.1, 7),
        100_000,
        1,
        50_000,
    );
}

#[test]
fn other_leaf_sizes_and_bins_match_brute_force() {
    let tris = shapes::random_soup(2000, 0.2, 11);
    let rays = common::random_rays(&tris, 20_000, 5);
    for split in [SplitMethod::Sah, SplitMethod::Median] {
        for (bins, leaf) in [(2, 1), (4, 2), (32, 8), (64, 255)] {
            let o = BuildOptions {
                split,
                bins,
                max_leaf_size: leaf,
            };
            let bvh = Bvh::build(&tris, &o);
            assert!(bvh.stats.max_leaf_size <= leaf);
            let all = common::every_kernel(&bvh);
            let bvhs: Vec<&Bvh> = all.iter().map(|(_, b)| b).collect();
            common::assert_matches_brute_force(&format!("{o:?}"), &tris, &bvhs, &rays);
        }
    }
}

#[test]
fn dragon_202k_matches_brute_force() {
    let Some(path) = common::external("dragon/dragon_vrip_res2.ply") else {
        return;
    };
    let scene = Scene::load(&path).expect("dragon loads");
    assert_eq!(scene.triangle_count(), 202_520);
    // Every 13th canonical ray (a prime stride, so the sample does not line up with the image's
    // rows or the packets' tiles) covers the whole image: about 80,000 camera rays.
    check_mesh("dragon", &scene.mesh.triangles, 20_000, 13, 10_000);
}

#[test]
fn ties_in_t_go_to_the_lowest_index() {
    // The same triangle three times, far apart in the list, with others in between.
    let mut tris = shapes::random_soup(500, 0.05, 3);
    let dup = [
        Vec3::new(-1.0, -1.0, 5.0),
        Vec3::new(1.0, -1.0, 5.0),
        Vec3::new(0.0, 1.0, 5.0),
    ];
    tris.insert(17, dup);
    tris.insert(300, dup);
    tris.push(dup);
    for (name, bvh) in common::all_bvhs(&tris) {
        let hit = bvh
            .intersect(
                &tracery::geometry::Ray::new(Vec3::new(0.0, -0.2, 10.0), Vec3::NEG_Z),
                f32::INFINITY,
            )
            .expect("hits the duplicated triangle");
        assert_eq!(hit.prim, 17, "{name}");
    }
}

/// Rays aimed exactly at triangle vertices graze the corners of the boxes that hold them,
/// where the slab test's far distance can round below its near distance: without Ize's
/// conservative scaling the BVH would skip boxes whose triangles brute force hits.
#[test]
fn rays_aimed_at_vertices_and_edges_match_brute_force() {
    let tris = shapes::random_soup(4000, 0.3, 77);
    let mut rng = tracery::rng::SplitMix64::new(4);
    let mut rays = Vec::new();
    for (k, t) in tris.iter().enumerate().take(4000) {
        for target in [t[k % 3], (t[0] + t[1]) * 0.5] {
            for _ in 0..20 {
                let from = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 4.0
                    - Vec3::splat(1.5);
                rays.push(tracery::geometry::Ray::new(from, target - from));
            }
        }
    }
    // The default trees, and trees of one and of four triangles a leaf: a vertex aimed at lies
    // on its leaf's box, where only the conservative far distance keeps the box entered (the
    // default trees alone stopped catching a plain slab test once leaves held eight triangles).
    let mut all = common::all_bvhs(&tris);
    for leaf in [1, 4] {
        let options = BuildOptions {
            max_leaf_size: leaf,
            ..BuildOptions::sah()
        };
        all.extend(common::every_kernel(&Bvh::build(&tris, &options)));
    }
    let bvhs: Vec<&Bvh> = all.iter().map(|(_, b)| b).collect();
    common::assert_matches_brute_force("vertex rays", &tris, &bvhs, &rays);
}
