//! The queries besides closest hit: any hit, transmittance and the visiting traversal.

mod common;

use glam::Vec3;
use tracery::bvh::{BruteForce, Bvh, Visit};
use tracery::geometry::Ray;
use tracery::scene::shapes;

#[test]
fn occluded_agrees_with_brute_force() {
    let tris = shapes::random_soup(2000, 0.15, 21);
    let bf = BruteForce::new(&tris);
    let rays = common::random_rays(&tris, 20_000, 3);
    for (name, bvh) in common::all_bvhs(&tris) {
        for (i, r) in rays.iter().enumerate() {
            let t_max = 0.05 + (i % 10) as f32 * 0.1;
            assert_eq!(
                bvh.occluded(r, t_max),
                !bf.all_hits(r, t_max).is_empty(),
                "{name}, ray {i}"
            );
        }
    }
}

#[test]
fn for_each_hit_reports_every_hit_once() {
    let tris = shapes::random_soup(1500, 0.2, 5);
    let bf = BruteForce::new(&tris);
    let rays = common::random_rays(&tris, 5000, 17);
    for (name, bvh) in common::all_bvhs(&tris) {
        for r in &rays {
            let mut got = Vec::new();
            bvh.for_each_hit(r, f32::INFINITY, |p, t| {
                got.push((p, t));
                true
            });
            got.sort_by_key(|h| h.0);
            assert_eq!(got, bf.all_hits(r, f32::INFINITY), "{name}");
        }
    }
}

fn layers(k: usize) -> Vec<[Vec3; 3]> {
    common::layers(k, 1.0)
}

#[test]
fn transmittance_through_k_layers_is_t_to_the_k() {
    let tris = layers(8);
    let bvh = Bvh::build(&tris, &tracery::bvh::BuildOptions::sah());
    let t = 0.7f32;
    let ray = Ray::new(Vec3::new(0.3, 0.6, 0.0), Vec3::Z);
    for k in 0..=8 {
        // Stop the shadow ray between layer k and k + 1.
        let through = bvh.transmittance(&ray, k as f32 + 0.5, |_, _| Vec3::splat(t));
        assert!((through.x - t.powi(k)).abs() < 1e-6, "k = {k}: {through}");
    }
    // An opaque layer stops everything, and the walk stops early.
    let mut calls = 0;
    let through = bvh.transmittance(&ray, 100.0, |_, _| {
        calls += 1;
        Vec3::ZERO
    });
    assert_eq!((through, calls), (Vec3::ZERO, 1));
}

#[test]
fn transmittance_counts_a_shared_edge_once() {
    let tris = layers(1);
    let bvh = Bvh::build(&tris, &tracery::bvh::BuildOptions::sah());
    // The squares' diagonal x = y is the edge both triangles share.
    for i in 1..32 {
        let s = i as f32 / 32.0;
        let ray = Ray::new(Vec3::new(s, s, 0.0), Vec3::Z);
        let through = bvh.transmittance(&ray, 10.0, |_, _| Vec3::splat(0.5));
        assert_eq!(through, Vec3::splat(0.5), "s = {s}");
    }
}

#[test]
fn visiting_traversal_finds_the_same_hits_and_reports_its_work() {
    let tris = shapes::icosphere(3);
    let rays = common::random_rays(&tris, 5000, 12);
    for options in common::both_builders() {
        let bvh = Bvh::build(&tris, &options);
        for r in &rays {
            let mut nodes = 0;
            let mut tested = 0;
            let mut last_depth = None;
            let visited = bvh.intersect_visit(r, f32::INFINITY, |v| match v {
                Visit::Node { index, depth } => {
                    assert!((index as usize) < bvh.nodes.len() && index != 1);
                    if last_depth.is_none() {
                        assert_eq!((index, depth), (0, 0), "starts at the root");
                    }
                    last_depth = Some(depth);
                    nodes += 1;
                }
                Visit::Triangle { prim, .. } => {
                    assert!((prim as usize) < tris.len());
                    tested += 1;
                }
            });
            let fast = bvh.intersect(r, f32::INFINITY);
            assert_eq!(visited, fast);
            if fast.is_some() {
                assert!(nodes >= 1 && tested >= 1);
            }
        }
    }
}
