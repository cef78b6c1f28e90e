//! `Bvh::intersect_counted`, the closest-hit walk that counts the nodes and triangle blocks it
//! tests (the figures of `tracery report bins`): it finds the hits `intersect` finds, and its
//! counts follow the walk.

use glam::Vec3;
use tracery::bench::canonical_rays;
use tracery::bvh::{BuildOptions, Bvh, Visits};
use tracery::geometry::Ray;
use tracery::geometry::shapes;

#[test]
fn the_counted_walk_finds_the_hits_intersect_finds() {
    let tris = shapes::terrain(64);
    for options in [BuildOptions::sah(), BuildOptions::median()] {
        let bvh = Bvh::build(&tris, &options);
        let mut total = Visits::default();
        let mut hits = 0;
        for ray in canonical_rays(&bvh.bounds()).iter().step_by(5) {
            let mut one = Visits::default();
            let got = bvh.intersect_counted(ray, f32::INFINITY, &mut one);
            assert_eq!(
                got,
                bvh.intersect(ray, f32::INFINITY),
                "{options:?}, {ray:?}"
            );
            // Every node is tested at most once by one walk, every block likewise.
            assert!(one.nodes as usize <= bvh.stats.wide_nodes, "{one:?}");
            assert!(one.blocks as usize <= bvh.stats.blocks, "{one:?}");
            if got.is_some() {
                // The hit's block was tested, below at least the root.
                assert!(one.nodes >= 1 && one.blocks >= 1, "{one:?}");
                hits += 1;
            }
            total += one;
        }
        assert!(hits > 10_000, "{hits} hits");
        // The counts accumulate (the caller's visits are added to, not replaced).
        let ray = Ray::new(Vec3::new(0.3, 0.4, 5.0), Vec3::NEG_Z);
        let mut twice = Visits::default();
        bvh.intersect_counted(&ray, f32::INFINITY, &mut twice);
        let once = twice;
        bvh.intersect_counted(&ray, f32::INFINITY, &mut twice);
        assert_eq!(twice.nodes, 2 * once.nodes);
        assert_eq!(twice.blocks, 2 * once.blocks);
        assert!(total.nodes > total.blocks, "{total:?}");
    }
}

#[test]
fn a_ray_that_enters_no_child_tests_the_root_alone() {
    let tris = shapes::terrain(32);
    let bvh = Bvh::build(&tris, &BuildOptions::sah());
    let b = bvh.bounds();
    // The terrain lies along the xy plane, its heights in z.
    let above = Vec3::new(
        0.5 * (b.min.x + b.max.x),
        0.5 * (b.min.y + b.max.y),
        b.max.z + 1.0,
    );
    // Pointing away from the mesh.
    let mut away = Visits::default();
    assert_eq!(
        bvh.intersect_counted(&Ray::new(above, Vec3::Z), f32::INFINITY, &mut away),
        None
    );
    assert_eq!(
        away,
        Visits {
            nodes: 1,
            blocks: 0
        }
    );
    // Towards it, but ending before the mesh's box: every child is culled by the limit.
    let mut short = Visits::default();
    assert_eq!(
        bvh.intersect_counted(&Ray::new(above, Vec3::NEG_Z), 0.5, &mut short),
        None
    );
    assert_eq!(
        short,
        Visits {
            nodes: 1,
            blocks: 0
        }
    );
    // The same ray with room to reach the mesh goes further.
    let mut long = Visits::default();
    assert!(
        bvh.intersect_counted(&Ray::new(above, Vec3::NEG_Z), f32::INFINITY, &mut long)
            .is_some()
    );
    assert!(long.nodes > 1 && long.blocks >= 1, "{long:?}");
}

#[test]
fn a_tree_of_one_leaf_tests_its_blocks_and_no_node() {
    let bvh = Bvh::build(&shapes::quad(), &BuildOptions::sah());
    assert_eq!(bvh.stats.wide_nodes, 0, "{:?}", bvh.stats);
    let mut v = Visits::default();
    let ray = Ray::new(Vec3::new(0.1, 1.0, 0.2), Vec3::NEG_Y);
    let hit = bvh.intersect_counted(&ray, f32::INFINITY, &mut v);
    assert_eq!(hit, bvh.intersect(&ray, f32::INFINITY));
    assert_eq!(
        v,
        Visits {
            nodes: 0,
            blocks: bvh.stats.blocks as u64
        }
    );
}
