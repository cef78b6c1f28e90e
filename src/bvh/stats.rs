use std::time::Duration;

use super::{Bvh, sah};

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
    /// that meets the root box, in units of one triangle test.
    pub sah_cost: f64,
    /// Wall-clock build time in milliseconds.
    pub build_ms: f64,
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
    pub(super) fn measure(
        bvh: &Bvh,
        excluded: usize,
        degenerate: usize,
        build_time: Duration,
    ) -> Self {
        let mut s = BvhStats {
            wide_nodes: bvh.wide.nodes.len(),
            blocks: bvh.wide.blocks.len(),
            binary_bytes: std::mem::size_of_val(&bvh.nodes[..])
                + std::mem::size_of_val(&bvh.prim_ids[..])
                + std::mem::size_of_val(&bvh.leaf_blocks[..]),
            wide_bytes: bvh.wide.bytes(),
            triangles: bvh.triangle_count(),
            excluded,
            degenerate,
            build_ms: build_time.as_secs_f64() * 1e3,
            min_leaf_size: u32::MAX,
            ..Default::default()
        };
        let root_area = bvh.bounds().half_area();
        let mut inner_area = 0.0;
        let mut leaf_area = 0.0;
        bvh.for_each_node(|n, depth| {
            s.nodes += 1;
            s.levels = s.levels.max(depth + 1);
            let a = n.aabb().half_area();
            if n.is_leaf() {
                s.leaves += 1;
                s.min_leaf_size = s.min_leaf_size.min(n.count);
                s.max_leaf_size = s.max_leaf_size.max(n.count);
                leaf_area += a * sah::blocks(n.count as usize);
            } else {
                inner_area += a;
            }
        });
        if s.leaves == 0 {
            s.min_leaf_size = 0;
        } else {
            s.mean_leaf_size = s.triangles as f64 / s.leaves as f64;
        }
        s.sah_cost = if root_area > 0.0 {
            (sah::C_TRAVERSE * inner_area + sah::C_INTERSECT * leaf_area) / root_area
        } else {
            // A flat or point-like scene: every ray meeting the root tests everything.
            sah::C_INTERSECT * sah::blocks(s.triangles)
        };
        s
    }
}
