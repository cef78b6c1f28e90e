//! The builders' own test: building takes no denormal operand (the others, in `tests/`, compare
//! trees with brute force and across thread counts).

use super::*;
use crate::cpu::take_denormal_flag;
use crate::geometry::shapes;

/// Building takes no denormal operand: the triangle indices kept in the references' `w`
/// lanes read as denormals, and one multiplication of them per reference made every build
/// several times slower on an Intel Xeon (a microcode assist each). The builds run on a pool of one
/// thread, whose MXCSR the check reads, the triangles first so that loading them is not
/// counted.
#[test]
fn building_takes_no_denormal_operand() {
    let mut tris = shapes::icosphere(5);
    tris.extend(shapes::random_soup(20_000, 4.0, 7));
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a pool of one thread");
    for options in [BuildOptions::sah(), BuildOptions::median()] {
        let took = pool.install(|| {
            take_denormal_flag();
            let bvh = build(&tris, &options);
            assert!(bvh.stats.leaves > 1);
            take_denormal_flag()
        });
        assert!(!took, "a {options:?} build took a denormal operand");
    }
}

/// The Cornell box's 32 triangles cost more by the SAH as the tree of four leaves its leaf
/// size allows than as one leaf, so they are laid out as one root leaf, which finds the hits
/// the tree's layout finds; a mesh of many triangles keeps its tree.
#[test]
fn a_room_of_a_few_triangles_is_one_root_leaf() {
    let tris = crate::scene::Scene::cornell_box().mesh.triangles;
    assert_eq!(tris.len(), 32);
    let bvh = build(&tris, &BuildOptions::sah());
    assert!(!bvh.nodes[0].is_leaf() && bvh.stats.leaves > 1);
    assert!(
        bvh.stats.sah_cost > sah::leaf_tests(tris.len()),
        "{}",
        bvh.stats.sah_cost
    );
    assert_eq!(bvh.wide.root_leaf, Some((0, 8)));
    assert!(bvh.wide.nodes.is_empty());
    // The same hits as the tree's layout, on rays from inside the room and from outside.
    let (tree, leaf_blocks) = crate::bvh::wide::collapse(&bvh.nodes, &tris, &bvh.prim_ids, false);
    assert!(!tree.nodes.is_empty() && tree.root_leaf.is_none());
    let as_tree = Bvh {
        wide: tree,
        nodes: bvh.nodes.clone(),
        leaf_blocks,
        prim_ids: bvh.prim_ids.clone(),
        stats: bvh.stats,
        options: bvh.options,
    };
    let mut seed = 99u32;
    let mut next = move || {
        seed = seed.wrapping_mul(1664525).wrapping_add(1013904223);
        (seed >> 8) as f32 / (1 << 24) as f32
    };
    let (mut hits, mut misses) = (0, 0);
    for k in 0..4000 {
        let inside = Vec3::new(0.5, 0.5, 0.5) + 4.5 * Vec3::new(next(), next(), next());
        let outside = Vec3::new(2.8, 2.7, -8.0) + Vec3::new(next(), next(), next());
        let origin = if k % 2 == 0 { inside } else { outside };
        let dir = Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5);
        let ray = crate::geometry::Ray::new(origin, dir);
        let got = bvh.intersect(&ray, f32::INFINITY);
        assert_eq!(got, as_tree.intersect(&ray, f32::INFINITY), "{ray:?}");
        assert_eq!(
            bvh.occluded(&ray, 3.0),
            as_tree.occluded(&ray, 3.0),
            "{ray:?}"
        );
        if got.is_some() {
            hits += 1;
        } else {
            misses += 1;
        }
    }
    assert!(hits > 1000 && misses > 100, "{hits} hits, {misses} misses");
    let sphere = shapes::icosphere(3);
    let bvh = build(&sphere, &BuildOptions::sah());
    assert!(bvh.wide.root_leaf.is_none() && !bvh.wide.nodes.is_empty());
}
