use std::time::Duration;

use super::{Bvh, BvhNode, sah};

/// What a build produced.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct BvhStats {
    /// Triangles in the tree.
    pub triangles: usize,
    /// Triangles left out because a vertex was NaN or infinite.
    pub excluded: usize,
    /// Triangles left out because their area is exactly zero (nothing to hit).
    pub degenerate: usize,
    /// Nodes in the tree, leaves included.
    pub nodes: usize,
    /// Leaf nodes.
    pub leaves: usize,
    /// Levels: the depth of the deepest leaf plus one (a lone root leaf is one level).
    pub levels: u32,
    /// Fewest triangles in a leaf.
    pub min_leaf_size: u32,
    /// Mean triangles per leaf.
    pub mean_leaf_size: f64,
    /// Most triangles in a leaf.
    pub max_leaf_size: u32,
    /// SAH cost of the tree with the constants of [`sah`]: expected cost of a random ray
    /// that meets the root box, in units of one test of a block of four triangles.
    pub sah_cost: f64,
    /// Wall-clock build time in milliseconds.
    pub build_ms: f64,
    /// Where the build time went.
    pub phases: BuildPhases,
    /// Nodes of the 8-wide traversal layout.
    pub wide_nodes: usize,
    /// Triangle blocks (four triangles each) of the traversal layout.
    pub blocks: usize,
    /// Bytes of the binary tree of record: its nodes, the map from leaf slots back to the
    /// caller's indices and each leaf's first block (its triangles are the wide layout's).
    pub binary_bytes: usize,
    /// Bytes of the traversal layout: 8-wide nodes and triangle blocks (which carry the
    /// caller's indices).
    pub wide_bytes: usize,
}

/// Where a build's time went, in milliseconds, phase by phase (together
/// [`BvhStats::build_ms`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct BuildPhases {
    /// The triangles' references (box and index), the root's boxes, the left-out triangles
    /// counted and dropped.
    pub references_ms: f64,
    /// The binary tree (every split) and its node array.
    pub tree_ms: f64,
    /// The traversal layout: the collapse into 8-wide nodes and the triangle blocks.
    pub layout_ms: f64,
}

impl BvhStats {
    /// Bytes per triangle of the binary tree of record (see [`BvhStats::binary_bytes`]).
    pub fn binary_bytes_per_triangle(&self) -> f64 {
        self.binary_bytes as f64 / self.triangles.max(1) as f64
    }

    /// Bytes per triangle of the traversal layout (see [`BvhStats::wide_bytes`]).
    pub fn wide_bytes_per_triangle(&self) -> f64 {
        self.wide_bytes as f64 / self.triangles.max(1) as f64
    }
}

impl BvhStats {
    /// The statistics of `bvh`, from what its builder counted (`counts`) as it made the tree.
    pub(super) fn new(
        bvh: &Bvh,
        counts: &TreeCounts,
        excluded: usize,
        degenerate: usize,
        build_time: Duration,
        phases: BuildPhases,
    ) -> Self {
        let triangles = bvh.triangle_count();
        let root_area = bvh.bounds().half_area();
        BvhStats {
            wide_nodes: bvh.wide.nodes.len(),
            blocks: bvh.wide.blocks.len(),
            binary_bytes: std::mem::size_of_val(&bvh.nodes[..])
                + std::mem::size_of_val(&bvh.prim_ids[..])
                + std::mem::size_of_val(&bvh.leaf_blocks[..]),
            wide_bytes: bvh.wide.bytes(),
            triangles,
            excluded,
            degenerate,
            build_ms: build_time.as_secs_f64() * 1e3,
            phases,
            // Every node but the unused slot 1 (see `BvhNode`); none in an empty tree.
            nodes: if bvh.is_empty() {
                0
            } else {
                bvh.nodes.len() - 1
            },
            leaves: counts.leaves,
            levels: counts.levels,
            min_leaf_size: if counts.leaves == 0 {
                0
            } else {
                counts.min_leaf
            },
            mean_leaf_size: if counts.leaves == 0 {
                0.0
            } else {
                triangles as f64 / counts.leaves as f64
            },
            max_leaf_size: counts.max_leaf,
            sah_cost: counts.sah_cost(root_area, triangles),
        }
    }
}

/// What the builder counts as it makes a tree, for [`BvhStats`]: a walk over the finished
/// tree ([`TreeCounts::walk`], the tests' reference) costs about a millisecond of a
/// 200k-triangle build, which counting as the tree is made avoids.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct TreeCounts {
    /// Leaf nodes.
    pub leaves: usize,
    /// The deepest leaf's depth plus one.
    pub levels: u32,
    /// Fewest and most triangles in a leaf (`u32::MAX` and 0 before the first leaf).
    pub min_leaf: u32,
    pub max_leaf: u32,
    /// The inner nodes' half areas, summed.
    pub inner_area: f64,
    /// The leaves' half areas, each times its blocks, summed.
    pub leaf_area: f64,
}

impl TreeCounts {
    /// Nothing counted yet.
    pub const EMPTY: TreeCounts = TreeCounts {
        leaves: 0,
        levels: 0,
        min_leaf: u32::MAX,
        max_leaf: 0,
        inner_area: 0.0,
        leaf_area: 0.0,
    };

    /// Counts leaf `n` at `depth` (the root's is 0).
    #[inline]
    pub fn leaf(&mut self, n: &BvhNode, depth: u32) {
        self.leaves += 1;
        self.levels = self.levels.max(depth + 1);
        self.min_leaf = self.min_leaf.min(n.count);
        self.max_leaf = self.max_leaf.max(n.count);
        self.leaf_area += n.aabb().half_area() * sah::leaf_tests(n.count as usize);
    }

    /// Counts inner node `n`.
    #[inline]
    pub fn inner(&mut self, n: &BvhNode) {
        self.inner_area += n.aabb().half_area();
    }

    /// Adds what another part of the tree counted.
    pub fn add(&mut self, other: &TreeCounts) {
        self.leaves += other.leaves;
        self.levels = self.levels.max(other.levels);
        self.min_leaf = self.min_leaf.min(other.min_leaf);
        self.max_leaf = self.max_leaf.max(other.max_leaf);
        self.inner_area += other.inner_area;
        self.leaf_area += other.leaf_area;
    }

    /// The tree's SAH cost from these counts: [`BvhStats::sah_cost`] for a tree of
    /// `triangles` whose root box has half area `root_area`.
    pub fn sah_cost(&self, root_area: f64, triangles: usize) -> f64 {
        if root_area > 0.0 {
            (sah::C_TRAVERSE * self.inner_area + sah::C_INTERSECT * self.leaf_area) / root_area
        } else {
            // A flat or point-like scene: every ray meeting the root tests everything.
            sah::C_INTERSECT * sah::leaf_tests(triangles)
        }
    }

    /// The counts of a finished tree, by walking it.
    pub fn walk(bvh: &Bvh) -> TreeCounts {
        let mut c = TreeCounts::EMPTY;
        bvh.for_each_node(|n, depth| {
            if n.is_leaf() {
                c.leaf(n, depth);
            } else {
                c.inner(n);
            }
        });
        c
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bvh::BuildOptions;
    use crate::geometry::shapes;

    /// The statistics the builder counts as it goes are those a walk over the finished tree
    /// finds (the SAH cost up to the order of the sums), for both builders, on one thread and
    /// on two (where the top of the tree is built in parallel and the halves' counts added).
    #[test]
    fn counted_statistics_match_a_walk_of_the_tree() {
        let mut tris = shapes::icosphere(6);
        tris.extend(shapes::random_soup(30_000, 4.0, 11));
        let small = shapes::icosphere(1);
        for threads in [1, 2] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("a pool");
            for options in [BuildOptions::sah(), BuildOptions::median()] {
                for mesh in [&tris, &small, &tris[..1], &tris[..0]] {
                    let bvh = pool.install(|| Bvh::build(mesh, &options));
                    let s = bvh.stats;
                    let walked = BvhStats::new(
                        &bvh,
                        &TreeCounts::walk(&bvh),
                        s.excluded,
                        s.degenerate,
                        Duration::from_secs_f64(s.build_ms / 1e3),
                        s.phases,
                    );
                    let what = format!(
                        "{threads} thread(s), {:?}, {} triangles",
                        options.split,
                        mesh.len()
                    );
                    assert!(
                        (s.sah_cost - walked.sah_cost).abs() <= 1e-12 * walked.sah_cost,
                        "{what}: SAH cost {} counted, {} walked",
                        s.sah_cost,
                        walked.sah_cost
                    );
                    assert_eq!(
                        BvhStats {
                            sah_cost: walked.sah_cost,
                            build_ms: walked.build_ms,
                            ..s
                        },
                        walked,
                        "{what}"
                    );
                    if mesh.is_empty() {
                        assert!(s.nodes == 0 && s.leaves == 0, "{what}: {s:?}");
                    } else {
                        assert!(s.leaves >= 1 && s.levels >= 1, "{what}: {s:?}");
                    }
                    if mesh.len() > 1000 {
                        assert!(
                            s.levels > 10 && s.nodes == 2 * s.leaves - 1,
                            "{what}: {s:?}"
                        );
                    }
                }
            }
        }
    }
}
