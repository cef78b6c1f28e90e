//! Embree through our FFI (`src/bench/embree.rs`, loaded at run time), the peer every speed
//! figure is measured against, checked as our own BVH is: its single-ray closest hits and
//! occlusion against brute force, its 16-ray packets through the benchmark's agreement column
//! on each instruction set `tracery bench --isa` can hold it to, and its stream queries against
//! its single-ray ones. A wrong field offset in the hand-written ray and hit structs, a misread
//! hit or a packet lane put back in the wrong place shows here as rays that disagree.

mod common;

use glam::Vec3;
use tracery::bench::embree::Embree;
use tracery::bench::{self, BenchConfig, CANONICAL_SIZE};
use tracery::bvh::wide::Kernel;
use tracery::bvh::{BruteForce, BuildOptions};
use tracery::geometry::shapes;
use tracery::scene::{Mesh, Scene};

/// Embree's triangle test is not watertight (ours is): a ray through a shared edge or vertex
/// can slip between two triangles, or name the other one of the two. At most this share of
/// rays may differ from brute force (the benchmark's target is 99.999% on the dragon).
const MAY_DIFFER: f64 = 1e-4;

/// The instruction sets to hold Embree to: its own choice, then each of our kernels'.
fn isas() -> Vec<Option<Kernel>> {
    std::iter::once(None)
        .chain(Kernel::available().into_iter().map(Some))
        .collect()
}

/// Single rays against brute force: the same triangle at the same distance (within 1e-3
/// relative: Embree's distances differ from ours by up to a few 1e-5 on grazing rays), or
/// another triangle at the same point (across a shared edge: within 1e-5 relative plus a
/// millionth of the mesh's size), or both miss; occlusion exactly when brute force hits.
fn check_single_rays(name: &str, tris: &[[Vec3; 3]], isa: Option<Kernel>) {
    let embree = Embree::build_for(tris, 1, isa).expect("Embree builds");
    let reference = BruteForce::new(tris);
    let rays = common::random_rays(tris, 20_000, 0xE3B ^ tris.len() as u64);
    let b = Mesh::from_triangles(tris.to_vec(), 0).bounds();
    let size = (Vec3::from(b.max) - Vec3::from(b.min)).length();
    let mut bad = Vec::new();
    let mut hits = 0;
    for (i, r) in rays.iter().enumerate() {
        let slow = reference.closest(r, f32::INFINITY);
        let fast = embree.intersect1(r);
        let same = match slow {
            None => fast.prim == bench::HitRecord::MISS.prim,
            Some(h) => {
                hits += 1;
                let off = (fast.t - h.t).abs();
                if fast.prim == h.prim {
                    off <= 1e-3 * h.t
                } else {
                    fast.prim != bench::HitRecord::MISS.prim && off <= 1e-5 * h.t + 1e-6 * size
                }
            }
        };
        if !same || embree.occluded1(r) != slow.is_some() {
            bad.push((i, slow.map(|h| (h.prim, h.t)), (fast.prim, fast.t)));
        }
    }
    // The rays test both answers: about half hit (half are aimed at a triangle).
    assert!(
        hits > rays.len() / 3 && hits < rays.len(),
        "{name}: {hits} of {} rays hit",
        rays.len()
    );
    assert!(
        bad.len() as f64 <= MAY_DIFFER * rays.len() as f64,
        "{name}, Embree held to {isa:?}: {} of {} rays differ from brute force, first (ray, brute force, Embree): {:?}",
        bad.len(),
        rays.len(),
        &bad[..bad.len().min(5)]
    );
}

fn meshes() -> Vec<(&'static str, Vec<[Vec3; 3]>)> {
    vec![
        ("cornell box", Scene::cornell_box().mesh.triangles),
        ("icosphere", shapes::icosphere(4)),
        ("soup", shapes::random_soup(3000, 0.1, 7)),
    ]
    // Not the needles of `tests/bvh_brute_force.rs` (10^4 times longer than wide): there
    // Embree's test answers about 1% of these rays otherwise than brute force (hits it misses
    // and misses it hits), its own precision rather than the FFI's.
}

#[test]
fn embree_single_rays_match_brute_force_on_every_isa() {
    if !common::embree() {
        return;
    }
    for (name, tris) in meshes() {
        for isa in isas() {
            check_single_rays(name, &tris, isa);
        }
    }
}

/// The benchmark on a band of the canonical image: Embree's single rays and its packets of
/// 4 x 4 rays agree with tracery-sah (itself checked against brute force, ray for ray, in
/// `tests/bvh_brute_force.rs`), held to each instruction set, and every engine reports the
/// set it ran.
#[test]
fn embree_packets_agree_with_ours_on_every_isa() {
    if !common::embree() {
        return;
    }
    let tris = shapes::icosphere(5);
    let rays = bench::canonical_rays(&Mesh::from_triangles(tris.clone(), 0).bounds());
    let width = CANONICAL_SIZE as usize;
    // The middle 96 rows: the sphere and the background beside it.
    let band = &rays[width * 464..width * 560];
    for isa in isas() {
        let config = BenchConfig {
            threads: vec![1],
            repeat: 1,
            ours: BenchConfig::ours(BuildOptions::sah()),
            obvhs: false,
            embree: true,
            packets: true,
            isa,
        };
        let out = bench::run("icosphere", &tris, band, width, &config, &mut |_| {})
            .expect("the benchmark runs");
        let hit = out
            .sah_hits
            .iter()
            .filter(|h| h.prim != bench::HitRecord::MISS.prim)
            .count();
        assert!(hit > band.len() / 4 && hit < band.len(), "{hit} rays hit");
        let names: Vec<&str> = out.results.iter().map(|r| r.engine.as_str()).collect();
        assert!(
            names.contains(&"embree") && names.contains(&"embree-packet16"),
            "{names:?}"
        );
        for r in &out.results {
            assert!(
                r.agreement >= 1.0 - MAY_DIFFER,
                "{} held to {isa:?}: agreement {}",
                r.engine,
                r.agreement
            );
            let expected = match (r.engine.starts_with("tracery"), isa) {
                (true, Some(k)) => Some(k.name()),
                (true, None) => Some(Kernel::detect().name()),
                (false, Some(k)) => Some(Embree::isa_name(k)),
                (false, None) => None,
            };
            assert_eq!(r.isa.as_deref(), expected, "{}", r.engine);
        }
    }
}

/// Embree's stream queries (`rtcIntersect1M` / `rtcOccluded1M`, the benchmark's batched peer
/// on incoherent rays) give each ray of a stream the answer its single-ray query gives: a
/// wrong stride or record layout would move answers between rays.
#[test]
fn embree_streams_answer_each_ray_as_its_single_query_does() {
    if !common::embree() {
        return;
    }
    for (name, tris) in meshes() {
        let embree = Embree::build(&tris, 1).expect("Embree builds");
        let rays = common::random_rays(&tris, 5_000, 0x57E4 ^ tris.len() as u64);
        for stream in [&rays[..], &rays[..1], &rays[..1000], &rays[1000..1037]] {
            let mut hits = vec![bench::HitRecord::MISS; stream.len()];
            let mut blocked = vec![false; stream.len()];
            embree.intersect_stream(stream, &mut hits);
            embree.occluded_stream(stream, &mut blocked);
            let mut hit = 0;
            for (i, r) in stream.iter().enumerate() {
                let one = embree.intersect1(r);
                // The same triangle at the same distance (Embree's packet test may round the
                // last bits differently from its single-ray one).
                assert!(
                    hits[i].prim == one.prim
                        && (one.prim == bench::HitRecord::MISS.prim
                            || (hits[i].t - one.t).abs() <= 1e-5 * one.t),
                    "{name}: ray {i} of {}: stream {:?}, single {:?}",
                    stream.len(),
                    (hits[i].prim, hits[i].t),
                    (one.prim, one.t)
                );
                assert_eq!(blocked[i], embree.occluded1(r), "{name}: ray {i}");
                hit += usize::from(one.prim != bench::HitRecord::MISS.prim);
            }
            assert!(
                stream.len() < 100 || (hit > 0 && hit < stream.len()),
                "{name}: {hit} hit"
            );
        }
    }
}
