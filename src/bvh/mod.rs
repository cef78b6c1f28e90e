//! The bounding volume hierarchy: built from triangles by a median split or binned SAH, stored
//! as a flat array of 32-byte nodes, traversed with a small fixed stack.
//!
//! - [`build`](Bvh::build) takes the triangles and a [`BuildOptions`].
//! - [`intersect`](Bvh::intersect) finds the closest hit; [`occluded`](Bvh::occluded) answers
//!   whether anything lies on a segment; [`transmittance`](Bvh::transmittance) multiplies the
//!   transparency of everything a shadow ray crosses; [`intersect_visit`](Bvh::intersect_visit)
//!   reports every node entered and triangle tested, for debug drawing and cost heatmaps.
//!
//! Layout: node 0 is the root, slot 1 is unused, and the two children of an inner node sit side
//! by side at an even index, so a pair of siblings shares one 64-byte cache line. A leaf's
//! triangles are its slots `first..first + count`; [`Bvh::prim_ids`] maps a slot back to the
//! caller's index. The queries walk a layout derived from this tree: 8-wide nodes with the
//! triangles in blocks of four ([`wide`]), the only copy of the triangles the tree keeps
//! ([`Bvh::leaf_triangles`] reads a binary leaf's).

mod accel;
mod build;
mod instances;
mod reference;
mod refit;
mod stats;
mod tile;
mod traverse;
pub mod wide;

use glam::{Vec3, Vec3A};

pub use accel::{Accel, Tree};
pub use instances::{Instance, InstanceError, InstanceHit, MAX_PLACED, TwoLevel};
pub use reference::BruteForce;
pub use refit::{REFIT_SAH_BOUND, Refit, RefitError, Update};
pub use stats::{BuildPhases, BvhStats};
pub use tile::{PACKET, RayTile};
pub use traverse::{Hit, Visit};
pub use wide::traverse::Visits;

use crate::geometry::Aabb;

/// How inner nodes are split.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SplitMethod {
    /// Object median on the longest axis of the centroid bounds: fast to build, balanced, but
    /// blind to where the triangles are.
    Median,
    /// Binned surface area heuristic (Wald 2007) along the longest axis of the centroid bounds.
    Sah,
}

impl std::fmt::Display for SplitMethod {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            SplitMethod::Median => "median",
            SplitMethod::Sah => "sah",
        })
    }
}

impl std::str::FromStr for SplitMethod {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "median" => Ok(SplitMethod::Median),
            "sah" => Ok(SplitMethod::Sah),
            other => Err(format!(
                "unknown split method `{other}` (expected median or sah)"
            )),
        }
    }
}

/// Cost constants of the surface area heuristic, used by the SAH builder and in the stats.
///
/// `cost = C_TRAVERSE * sum(A(inner)) / A(root) + C_INTERSECT * sum(A(leaf) * leaf_tests(leaf)) / A(root)`
///
/// A leaf's triangles are tested four at a time ([`wide::BLOCK`]), and the AVX2 and AVX-512
/// kernels test a leaf's blocks two at a time (eight triangles in 256-bit registers), so a
/// leaf costs its tests, not its triangles: 1 to 4 triangles one block test, 5 to 8 one pair
/// test ([`sah::PAIR_TEST`]).
pub mod sah {
    /// Cost of visiting a binary inner node (one of the levels an 8-wide node merges).
    pub const C_TRAVERSE: f64 = 1.0;
    /// Cost of testing one block of four triangles.
    pub const C_INTERSECT: f64 = 1.0;
    /// Cost of testing two blocks together, in block tests. Lower (1.2) makes trees whose
    /// closest hits are slower (more triangles tested a ray), higher (1.8) no better; 1.35 to
    /// 1.65 behave alike. Against leaves of one block, 1.5 with leaves of two blocks halves the
    /// wide nodes, builds faster and answers occlusion faster (`tracery bench` with
    /// `--leaf-size 4` and `8`; docs/benchmarks.md).
    pub const PAIR_TEST: f64 = 1.5;

    /// Cost of testing a leaf of `n` triangles, in block tests: its blocks of
    /// [`super::wide::BLOCK`] triangles in pairs, a last lone block on its own.
    pub fn leaf_tests(n: usize) -> f64 {
        let pair = 2 * super::wide::BLOCK;
        let last = match n % pair {
            0 => 0.0,
            r if r <= super::wide::BLOCK => 1.0,
            _ => PAIR_TEST,
        };
        (n / pair) as f64 * PAIR_TEST + last
    }
}

/// Build settings. The defaults are the ones `tracery report splits` and `tracery report bins`
/// favour (docs/bvh.md).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct BuildOptions {
    /// Median split or binned SAH.
    pub split: SplitMethod,
    /// SAH bins per axis (2..=64) for ranges of 256 triangles or more (smaller ranges use at
    /// most 12). More bins find better splits but cost build time; `tracery report bins`
    /// shows the trade-off (docs/bvh.md). Ignored by the median split.
    pub bins: u32,
    /// Largest number of triangles a leaf may hold (1..=255). The SAH builder may stop earlier
    /// when a leaf is cheaper than any split; the median builder splits down to this size.
    pub max_leaf_size: u32,
}

impl BuildOptions {
    /// Default SAH bin count (see `tracery report bins`).
    pub const DEFAULT_BINS: u32 = 32;
    /// Default maximum leaf size: two blocks, tested together (see [`sah::PAIR_TEST`]).
    pub const DEFAULT_LEAF_SIZE: u32 = 8;

    /// Binned SAH with the default bins and leaf size.
    pub fn sah() -> Self {
        Self {
            split: SplitMethod::Sah,
            bins: Self::DEFAULT_BINS,
            max_leaf_size: Self::DEFAULT_LEAF_SIZE,
        }
    }

    /// Median split with the default leaf size.
    pub fn median() -> Self {
        Self {
            split: SplitMethod::Median,
            ..Self::sah()
        }
    }

    /// The same options with another split method.
    pub fn with_split(self, split: SplitMethod) -> Self {
        Self { split, ..self }
    }

    /// Checks the ranges; the message names the bad setting.
    pub fn validate(&self) -> Result<(), String> {
        if !(2..=64).contains(&self.bins) {
            return Err(format!("bins must be between 2 and 64, got {}", self.bins));
        }
        if !(1..=255).contains(&self.max_leaf_size) {
            return Err(format!(
                "leaf size must be between 1 and 255, got {}",
                self.max_leaf_size
            ));
        }
        Ok(())
    }
}

impl Default for BuildOptions {
    fn default() -> Self {
        Self::sah()
    }
}

/// One node: a box, and either two children (`count == 0`, children at `first` and
/// `first + 1`) or a leaf of `count` triangles starting at leaf slot `first`.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(32))]
pub struct BvhNode {
    /// Box minimum.
    pub min: [f32; 3],
    /// First child (inner node) or first triangle slot (leaf).
    pub first: u32,
    /// Box maximum.
    pub max: [f32; 3],
    /// Number of triangles; zero for an inner node.
    pub count: u32,
}

impl BvhNode {
    /// True for a leaf.
    #[inline(always)]
    pub fn is_leaf(&self) -> bool {
        self.count > 0
    }

    /// The node's box.
    #[inline(always)]
    pub fn aabb(&self) -> Aabb {
        Aabb {
            min: Vec3A::from_array(self.min),
            max: Vec3A::from_array(self.max),
        }
    }

    pub(crate) fn set_aabb(&mut self, b: &Aabb) {
        self.min = b.min.to_array();
        self.max = b.max.to_array();
    }
}

/// The deepest a tree may grow. Past `MAX_DEPTH - 32` the builders switch to splitting by
/// count, which halves every time, so no input (even a million copies of one triangle) can
/// overflow the traversal stack.
pub const MAX_DEPTH: usize = 96;

/// A built BVH over a triangle list.
#[derive(Clone, Debug)]
pub struct Bvh {
    /// Flat node array: root at 0, slot 1 unused, sibling pairs from 2 on.
    pub nodes: Vec<BvhNode>,
    /// For each leaf slot, the index of the triangle in the caller's list.
    pub prim_ids: Vec<u32>,
    /// For each leaf of `nodes`, the first of the blocks in [`wide::WideBvh::blocks`] that
    /// hold its triangles, four to a block in slot order (0 for inner nodes). The triangles
    /// are kept there only; [`Bvh::leaf_triangles`] reads them.
    pub leaf_blocks: Vec<u32>,
    /// The traversal layout derived from `nodes` (see [`wide`]).
    pub wide: wide::WideBvh,
    /// What the build produced and how long it took.
    pub stats: BvhStats,
    /// The options it was built with.
    pub options: BuildOptions,
}

impl Bvh {
    /// Builds a BVH over `triangles` (three vertices each). Triangles with a NaN or infinite
    /// vertex are left out and counted in [`BvhStats::excluded`], zero-area ones likewise in
    /// [`BvhStats::degenerate`]. Never panics or loops, whatever the input.
    pub fn build(triangles: &[[Vec3; 3]], options: &BuildOptions) -> Bvh {
        build::build(triangles, options)
    }

    /// The SIMD kernel the queries use ([`wide::Kernel::detect`] by default).
    pub fn kernel(&self) -> wide::Kernel {
        self.wide.kernel()
    }

    /// Chooses the kernel the queries use; an error when this CPU cannot run it. Every kernel
    /// gives the same hits; tests and benchmarks compare them.
    pub fn set_kernel(&mut self, kernel: wide::Kernel) -> Result<(), String> {
        self.wide.set_kernel(kernel)
    }

    /// Number of triangles in the tree (excluded ones not counted).
    pub fn triangle_count(&self) -> usize {
        self.prim_ids.len()
    }

    /// True when the tree holds no triangle.
    pub fn is_empty(&self) -> bool {
        self.prim_ids.is_empty()
    }

    /// The triangles of leaf `node` (an index into [`Bvh::nodes`]) in slot order, each with
    /// its index in the caller's list; nothing for an inner node.
    pub fn leaf_triangles(&self, node: u32) -> impl Iterator<Item = (u32, [Vec3A; 3])> + '_ {
        let n = &self.nodes[node as usize];
        let first = self.leaf_blocks[node as usize] as usize;
        (0..n.count as usize).map(move |i| {
            let block = &self.wide.blocks[first + i / wide::BLOCK];
            let lane = i % wide::BLOCK;
            (block.prim[lane], block.triangle(lane))
        })
    }

    /// Box around everything in the tree (empty for an empty tree).
    pub fn bounds(&self) -> Aabb {
        if self.is_empty() {
            Aabb::EMPTY
        } else {
            self.nodes[0].aabb()
        }
    }

    /// Visits every node of the tree with its depth (root at 0), parents before children.
    pub fn for_each_node(&self, mut f: impl FnMut(&BvhNode, u32)) {
        if self.is_empty() {
            return;
        }
        // Children are always stored after their parent, so one forward pass knows each
        // node's depth before it reaches the node.
        let mut depth = vec![0u32; self.nodes.len()];
        for (i, n) in self.nodes.iter().enumerate() {
            if i == 1 {
                continue; // the unused slot
            }
            f(n, depth[i]);
            if !n.is_leaf() {
                depth[n.first as usize] = depth[i] + 1;
                depth[n.first as usize + 1] = depth[i] + 1;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::sah::{PAIR_TEST, leaf_tests};

    #[test]
    fn a_leaf_costs_its_blocks_in_pairs_and_a_lone_last_block() {
        let cost: Vec<f64> = (0..=17).map(leaf_tests).collect();
        let p = PAIR_TEST;
        let want = [
            0.0,
            1.0,
            1.0,
            1.0,
            1.0,
            p,
            p,
            p,
            p,
            p + 1.0,
            p + 1.0,
            p + 1.0,
            p + 1.0,
            2.0 * p,
            2.0 * p,
            2.0 * p,
            2.0 * p,
            2.0 * p + 1.0,
        ];
        assert_eq!(cost, want);
    }
}
