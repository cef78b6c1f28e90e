//! From the binary tree to 8-wide nodes, in two passes over the binary nodes (linear time).
//!
//! Which binary nodes become wide nodes is chosen to minimise the wide tree's SAH cost (the
//! expected number of nodes a ray visits; [`Plan`]): one pass bottom up finds, for every binary
//! node and lane budget, whether to keep it as one lane or open it, and one pass top down
//! makes the nodes. Binary leaves become wide leaves, their triangles cut into blocks of four.
//! Siblings' nodes and blocks are stored side by side, and subtrees depth first. Each node
//! gets its per-octant visiting order ([`WideNode::order`]). On a large tree both passes run
//! on the rayon pool (the plan by subtrees, `plan_pairs`; the nodes by the top two wide
//! levels' subtrees, [`Part`]), giving the same layout as one thread.
//!
//! The greedy rule it replaced (open the inner child of largest area until eight lanes are
//! filled) left 8,187 of the dragon 202k's 18,718 nodes with two children: a small inner node
//! left over when its parent's lanes ran out became a node of its own. The plan makes 10,870
//! nodes there, its cost 15.02 against 15.81 (node visits 11.24 against 12.03, block tests
//! 3.78 either way).

use glam::{Vec3, Vec4};

use super::{BLOCK, Child, Kernel, TriBlock, WIDTH, WideBvh, WideNode};
use crate::bvh::BvhNode;
use crate::geometry::Aabb;

/// Collapses `nodes` (the binary tree, root at 0) whose leaf slots hold the triangles
/// `triangles[prim_ids[slot]]`, or lays them out as one root leaf with `one_leaf` (the
/// builder found testing them all together cheaper than the tree). Also returns, for every
/// binary leaf, the index of its first block (the blocks of a leaf are consecutive; 0 for
/// inner nodes).
pub fn collapse(
    nodes: &[BvhNode],
    triangles: &[[Vec3; 3]],
    prim_ids: &[u32],
    one_leaf: bool,
) -> (WideBvh, Vec<u32>) {
    let mut out = WideBvh::default();
    out.set_kernel(Kernel::detect())
        .expect("the detected kernel runs here");
    let mut leaf_blocks = vec![0u32; nodes.len()];
    if prim_ids.is_empty() {
        return (out, leaf_blocks);
    }
    if one_leaf || nodes[0].is_leaf() || prim_ids.len() > Child::MAX_FIRST_BLOCK as usize {
        // One root leaf: asked for, the tree is one leaf, or it has more blocks than a leaf
        // word can address (over 500 million triangles, hundreds of gigabytes): every binary
        // leaf's blocks in slot order, tested one after the other (correct if slow for the
        // last).
        let mut sources = Vec::new();
        let mut leaves: Vec<usize> = (0..nodes.len())
            .filter(|&i| i != 1 && nodes[i].is_leaf())
            .collect();
        leaves.sort_by_key(|&i| nodes[i].first);
        for i in leaves {
            leaf_blocks[i] = push_blocks(&mut sources, &nodes[i]);
        }
        out.blocks = fill_blocks(&sources, triangles, prim_ids);
        out.root_leaf = Some((0, out.blocks.len() as u32));
        return (out, leaf_blocks);
    }
    let plan = Plan::new(nodes);
    // The wide nodes, the blocks' sources and the leaves' first blocks, made by the rayon pool
    // for a large tree (its top levels' subtrees at once), and laid out as one thread makes
    // them: siblings side by side, subtrees depth first.
    let parallel = nodes.len() >= PARALLEL_MIN_NODES && rayon::current_num_threads() > 1;
    let part = if parallel {
        Part::top(nodes, &plan, 0, 0)
    } else {
        Part::subtree(nodes, &plan, 0)
    };
    drop(plan);
    let sources = part.into_layout(&mut out.nodes, &mut leaf_blocks);
    out.blocks = fill_blocks(&sources, triangles, prim_ids);
    (out, leaf_blocks)
}

/// Binary trees with at least this many nodes are collapsed on the rayon pool.
const PARALLEL_MIN_NODES: usize = 1 << 14;
/// Wide levels whose subtrees are collapsed at once (the root's level is 0): up to 64
/// subtrees below level 1, for the pool to share.
const PARALLEL_LEVELS: usize = 2;

/// A wide subtree as it is made: its root (local node 0) and the nodes it made itself after
/// it, the blocks' sources it made (local block indices), the binary leaves' first blocks, and
/// the subtrees made apart, each with the local slot its root takes. In the layout its nodes
/// from local 1 come first, then each part's, in order; its blocks likewise.
struct Part {
    nodes: Vec<WideNode>,
    sources: Vec<(u32, u32)>,
    /// (binary leaf, local first block)
    leaves: Vec<(u32, u32)>,
    parts: Vec<(u32, Part)>,
    /// Nodes after the root, and blocks, of the whole subtree (its parts' included).
    descendants: u32,
    blocks: u32,
}

impl Part {
    fn new(made: Made) -> Part {
        Part {
            descendants: made.nodes.len() as u32 - 1,
            blocks: made.sources.len() as u32,
            nodes: made.nodes,
            sources: made.sources,
            leaves: made.leaves,
            parts: Vec::new(),
        }
    }

    /// The wide node of binary inner node `binary`: its lanes, leaves' blocks and leaf
    /// nodes made here, its inner children's subtrees each a part of its own, made at once.
    fn top(nodes: &[BvhNode], plan: &Plan, binary: usize, level: usize) -> Part {
        use rayon::prelude::*;
        let mut made = Made::new();
        let mut inner = Vec::with_capacity(WIDTH);
        made.nodes[0] = made.node(nodes, plan, binary, &mut inner);
        let mut part = Part::new(made);
        part.parts = inner
            .par_iter()
            .map(|&(slot, c)| {
                let sub = if level + 1 < PARALLEL_LEVELS {
                    Part::top(nodes, plan, c, level + 1)
                } else {
                    Part::subtree(nodes, plan, c)
                };
                (slot as u32, sub)
            })
            .collect();
        // (A part's root is one of the slots made here, counted already.)
        for (_, sub) in &part.parts {
            part.descendants += sub.descendants;
            part.blocks += sub.blocks;
        }
        part
    }

    /// The whole wide subtree of binary inner node `binary` on this thread, depth first.
    fn subtree(nodes: &[BvhNode], plan: &Plan, binary: usize) -> Part {
        let mut made = Made::new();
        // (wide node to fill, binary inner node it stands for)
        let mut stack = vec![(0usize, binary)];
        let mut inner = Vec::with_capacity(WIDTH);
        while let Some((wide, binary)) = stack.pop() {
            inner.clear();
            made.nodes[wide] = made.node(nodes, plan, binary, &mut inner);
            // Depth first, the first child next.
            stack.extend(inner.iter().rev());
        }
        Part::new(made)
    }

    /// Writes the layout: the wide nodes into `out` and each binary leaf's first block into
    /// `leaf_blocks`; returns the blocks' sources. A part made on one thread is its layout.
    fn into_layout(self, out: &mut Vec<WideNode>, leaf_blocks: &mut [u32]) -> Vec<(u32, u32)> {
        use rayon::prelude::*;
        self.set_leaf_blocks(0, leaf_blocks);
        if self.parts.is_empty() {
            *out = self.nodes;
            return self.sources;
        }
        // Made on the pool, so that their fresh pages fault in on every thread.
        rayon::iter::repeat_n(WideNode::EMPTY, 1 + self.descendants as usize).collect_into_vec(out);
        let mut sources = Vec::new();
        rayon::iter::repeat_n((0, 0), self.blocks as usize).collect_into_vec(&mut sources);
        let (root, rest) = out.split_at_mut(1);
        self.place(&mut root[0], rest, 1, &mut sources, 0);
        sources
    }

    /// Sets the first block of each binary leaf in the part, its blocks starting at `base`.
    fn set_leaf_blocks(&self, base: u32, leaf_blocks: &mut [u32]) {
        for &(leaf, first) in &self.leaves {
            leaf_blocks[leaf as usize] = base + first;
        }
        let mut base = base + self.sources.len() as u32;
        for (_, sub) in &self.parts {
            sub.set_leaf_blocks(base, leaf_blocks);
            base += sub.blocks;
        }
    }

    /// Writes the part's root to `root`, its other nodes to `rest` (from node `first`), its
    /// blocks' sources to `sources` (from block `block`).
    fn place(
        &self,
        root: &mut WideNode,
        rest: &mut [WideNode],
        first: u32,
        sources: &mut [(u32, u32)],
        block: u32,
    ) {
        use rayon::prelude::*;
        // Local node `k` (1 or more) is node `first + k - 1`; local block `b` is `block + b`.
        let fix = |n: &WideNode| {
            let mut n = *n;
            for lane in 0..WIDTH {
                if n.planes[0][lane] > n.planes[1][lane] {
                    continue; // an empty lane
                }
                let c = Child(n.child[lane]);
                n.child[lane] = if c.is_leaf() {
                    let (b, count) = c.blocks();
                    Child::leaf(block + b, count).0
                } else {
                    first + c.index() - 1
                };
            }
            n
        };
        *root = fix(&self.nodes[0]);
        let own = self.nodes.len() - 1;
        let (mine, mut rest) = rest.split_at_mut(own);
        let (my_sources, mut sources) = sources.split_at_mut(self.sources.len());
        for (dst, &src) in my_sources.iter_mut().zip(&self.sources) {
            *dst = src;
        }
        // Each part's root slot among the nodes made here, and its own ranges after them.
        let mut slots: Vec<Option<&mut WideNode>> = mine.iter_mut().map(Some).collect();
        let (mut next, mut next_block) = (first + own as u32, block + self.sources.len() as u32);
        let mut jobs = Vec::with_capacity(self.parts.len());
        for (slot, sub) in &self.parts {
            let root = slots[*slot as usize - 1].take().expect("one part a slot");
            let (sub_rest, r) = rest.split_at_mut(sub.descendants as usize);
            let (sub_sources, s) = sources.split_at_mut(sub.blocks as usize);
            (rest, sources) = (r, s);
            jobs.push((sub, root, sub_rest, next, sub_sources, next_block));
            next += sub.descendants;
            next_block += sub.blocks;
        }
        for (dst, n) in slots.into_iter().zip(&self.nodes[1..]) {
            if let Some(dst) = dst {
                *dst = fix(n);
            }
        }
        jobs.into_par_iter()
            .for_each(|(sub, root, rest, first, sources, block)| {
                sub.place(root, rest, first, sources, block)
            });
    }
}

/// What one thread makes of a wide subtree: its nodes (the root at 0), the blocks' sources
/// and the binary leaves' first blocks (local indices).
struct Made {
    nodes: Vec<WideNode>,
    sources: Vec<(u32, u32)>,
    /// (binary leaf, first block)
    leaves: Vec<(u32, u32)>,
}

impl Made {
    /// The root's place and nothing else.
    fn new() -> Made {
        Made {
            nodes: vec![WideNode::EMPTY],
            sources: Vec::new(),
            leaves: Vec::new(),
        }
    }

    /// Makes the wide node of binary inner node `binary`: its lanes as the plan picks them,
    /// each leaf's blocks appended to the sources (and its first block to the leaves), a
    /// node appended for each inner child (`inner` gets its place and binary node, in lane
    /// order) and for each leaf of more blocks than a leaf word holds.
    fn node(
        &mut self,
        tree: &[BvhNode],
        plan: &Plan,
        binary: usize,
        inner: &mut Vec<(usize, usize)>,
    ) -> WideNode {
        let mut kids = [0usize; WIDTH];
        let lanes = plan.node_lanes(tree, binary, &mut kids);
        let mut node = WideNode::EMPTY;
        for (lane, &c) in kids[..lanes].iter().enumerate() {
            let n = &tree[c];
            for axis in 0..3 {
                node.planes[2 * axis][lane] = n.min[axis];
                node.planes[2 * axis + 1][lane] = n.max[axis];
            }
            node.child[lane] = if n.is_leaf() {
                let first = push_blocks(&mut self.sources, n);
                self.leaves.push((c as u32, first));
                leaf_child(&mut self.nodes, n, first, self.sources.len() as u32 - first)
            } else {
                let index = self.nodes.len();
                self.nodes.push(WideNode::EMPTY);
                inner.push((index, c));
                Child::inner(index as u32)
            }
            .0;
        }
        node.order = octant_order(&node);
        node
    }
}

/// The SAH-optimal collapse (after Ylitie, Karras and Laine 2017, with the binary leaves kept
/// as they are): for every binary node and lane budget `k`, the least cost of its subtree as
/// at most `k` lanes of its parent, kept as one lane (a node of its own) or opened and its
/// lanes shared between its children. The cost counts node visits (each node's surface area);
/// the leaves' block tests are the same however the tree is collapsed.
struct Plan {
    /// `cost[i][k - 1]` for binary node `i`.
    cost: Vec<[f32; WIDTH]>,
}

impl Plan {
    fn new(nodes: &[BvhNode]) -> Plan {
        let parallel = nodes.len() >= PARALLEL_MIN_NODES && rayon::current_num_threads() > 1;
        parallel
            .then(|| Plan::on_pool(nodes))
            .flatten()
            .unwrap_or_else(|| Plan::in_order(nodes))
    }

    /// Planned in one backward pass (children are stored after their parents).
    fn in_order(nodes: &[BvhNode]) -> Plan {
        let mut cost = vec![[0.0f32; WIDTH]; nodes.len()];
        for i in (2..nodes.len()).rev().chain([0]) {
            let n = &nodes[i];
            cost[i] = if n.is_leaf() {
                leaf_cost(n)
            } else {
                inner_cost(n, &cost[n.first as usize], &cost[n.first as usize + 1])
            };
        }
        Plan { cost }
    }

    /// Planned on the rayon pool, subtrees at once, when the nodes are laid out as the
    /// builder lays them out (each subtree's nodes one range of the array: see `plan_pairs`);
    /// `None` when they are not.
    fn on_pool(nodes: &[BvhNode]) -> Option<Plan> {
        let mut cost = vec![[0.0f32; WIDTH]; nodes.len()];
        if nodes[0].is_leaf() {
            cost[0] = leaf_cost(&nodes[0]);
        } else {
            plan_pairs(nodes, 2, cost.get_mut(2..)?)?;
            cost[0] = inner_cost(&nodes[0], &cost[2], &cost[3]);
        }
        Some(Plan { cost })
    }

    /// How many of `k` lanes (2 or more) the left child of inner node `i` gets when `i` is
    /// opened into them (the lowest count on ties).
    fn share(&self, nodes: &[BvhNode], i: usize, k: usize) -> usize {
        let (l, r) = (
            &self.cost[nodes[i].first as usize],
            &self.cost[nodes[i].first as usize + 1],
        );
        // The first least of the sums `opened` takes its minimum over (a NaN cost, from a box
        // of infinite extent, is never less: any share makes a valid tree).
        let mut best = (f32::INFINITY, 1);
        for j in 1..k {
            let c = l[j - 1] + r[k - j - 1];
            if c < best.0 {
                best = (c, j);
            }
        }
        best.1
    }

    /// Writes the lanes binary node `i` takes when given `k` of them to `out` from `*len`,
    /// advancing it.
    fn lanes(
        &self,
        nodes: &[BvhNode],
        i: usize,
        k: usize,
        out: &mut [usize; WIDTH],
        len: &mut usize,
    ) {
        let n = &nodes[i];
        // Kept as one lane unless opening it into its `k` lanes costs less.
        if k == 1 || n.is_leaf() || self.cost[i][k - 1] >= self.cost[i][0] {
            out[*len] = i;
            *len += 1;
            return;
        }
        let j = self.share(nodes, i, k);
        self.lanes(nodes, n.first as usize, j, out, len);
        self.lanes(nodes, n.first as usize + 1, k - j, out, len);
    }

    /// The lanes of the node made for binary inner node `i` (its children in up to WIDTH),
    /// written to `out`; returns how many.
    fn node_lanes(&self, nodes: &[BvhNode], i: usize, out: &mut [usize; WIDTH]) -> usize {
        let j = self.share(nodes, i, WIDTH);
        let mut len = 0;
        self.lanes(nodes, nodes[i].first as usize, j, out, &mut len);
        self.lanes(nodes, nodes[i].first as usize + 1, WIDTH - j, out, &mut len);
        len
    }
}

/// Plans the sibling pair at `c` and their descendants, whose costs are `cost` (from
/// `c`), on the rayon pool: the nodes of a pair whose first child's children are at `c + 2`
/// (as the builder lays them out) are the pair, the first one's descendants, then the
/// second one's, so the two are planned at once. `None` (the plan unfinished) when the
/// nodes are not laid out so.
fn plan_pairs(nodes: &[BvhNode], c: usize, cost: &mut [[f32; WIDTH]]) -> Option<()> {
    /// Ranges of fewer nodes are planned on one thread.
    const PARALLEL_MIN: usize = 4096;
    let (a, b) = (nodes.get(c)?, nodes.get(c + 1)?);
    let (pair, rest) = cost.split_at_mut_checked(2)?;
    // The first child's descendants: up to the second's children, or to the end.
    let first_len = match (a.is_leaf(), b.is_leaf()) {
        (true, _) => 0,
        (false, true) => rest.len(),
        (false, false) => (b.first as usize).checked_sub(c + 2)?,
    };
    let (ra, rb) = rest.split_at_mut_checked(first_len)?;
    let laid_out = (a.is_leaf() || a.first as usize == c + 2)
        && if b.is_leaf() {
            rb.is_empty()
        } else {
            b.first as usize == c + 2 + first_len
        };
    if !laid_out {
        return None;
    }
    let plan = |n: &BvhNode, at: usize, range: &mut [[f32; WIDTH]]| {
        n.is_leaf() || plan_pairs(nodes, at, range).is_some()
    };
    let b_at = c + 2 + first_len;
    let planned = if ra.len() + rb.len() >= PARALLEL_MIN {
        let (x, y) = rayon::join(|| plan(a, c + 2, &mut *ra), || plan(b, b_at, &mut *rb));
        x && y
    } else {
        plan(a, c + 2, ra) && plan(b, b_at, rb)
    };
    if !planned {
        return None;
    }
    pair[0] = if a.is_leaf() {
        leaf_cost(a)
    } else {
        inner_cost(a, &ra[0], &ra[1])
    };
    pair[1] = if b.is_leaf() {
        leaf_cost(b)
    } else {
        inner_cost(b, &rb[0], &rb[1])
    };
    Some(())
}

/// A binary leaf's cost in any number of lanes: its area times its blocks.
#[inline(always)]
fn leaf_cost(n: &BvhNode) -> [f32; WIDTH] {
    let area = n.aabb().half_area() as f32;
    [area * n.count.div_ceil(BLOCK as u32) as f32; WIDTH]
}

/// A binary inner node's cost in 1 to WIDTH lanes, its children's being `l` and `r`.
#[inline(always)]
fn inner_cost(n: &BvhNode, l: &[f32; WIDTH], r: &[f32; WIDTH]) -> [f32; WIDTH] {
    let area = n.aabb().half_area() as f32;
    let opened = opened(l, r);
    // Kept as one lane: a node of its own, its children in up to WIDTH lanes.
    let own = area + opened[WIDTH - 1];
    let mut c = [own; WIDTH];
    for k in 1..WIDTH {
        c[k] = if opened[k] < own { opened[k] } else { own };
    }
    c
}

/// `[k - 1]`: the least cost of two siblings (costs `l`, `r`) in `k` lanes, each in at least
/// one (infinite for `k = 1`). Without branches: every share is summed and the least kept.
#[inline(always)]
fn opened(l: &[f32; WIDTH], r: &[f32; WIDTH]) -> [f32; WIDTH] {
    let mut best = [f32::INFINITY; WIDTH];
    for j in 1..WIDTH {
        for k in j + 1..=WIDTH {
            let c = l[j - 1] + r[k - j - 1];
            // `min` without `f32::min`'s NaN handling (costs are never NaN).
            best[k - 1] = if c < best[k - 1] { c } else { best[k - 1] };
        }
    }
    best
}

/// The child word of a binary leaf whose blocks are `first..first + count`: one leaf word, or
/// a node of leaf words (same box) when it has more blocks than one word holds.
fn leaf_child(nodes: &mut Vec<WideNode>, leaf: &BvhNode, first: u32, count: u32) -> Child {
    if count <= Child::MAX_BLOCKS {
        return Child::leaf(first, count);
    }
    let mut node = WideNode::EMPTY;
    for (lane, start) in (first..first + count)
        .step_by(Child::MAX_BLOCKS as usize)
        .enumerate()
    {
        for axis in 0..3 {
            node.planes[2 * axis][lane] = leaf.min[axis];
            node.planes[2 * axis + 1][lane] = leaf.max[axis];
        }
        let n = (first + count - start).min(Child::MAX_BLOCKS);
        node.child[lane] = Child::leaf(start, n).0;
    }
    node.order = octant_order(&node);
    nodes.push(node);
    Child::inner(nodes.len() as u32 - 1)
}

/// The visiting order of a node's lanes for each octant: by how far along the octant's
/// diagonal each box starts (its entry corner projected on the diagonal), farthest first;
/// empty lanes first of all.
///
/// Each lane's eight keys (one per octant) are made as two four-lane vectors, and each of the
/// 28 pairs of lanes is compared in all eight octants at once: the comparison's eight bits,
/// spread into the bytes of a word, add one to the octants' ranks of the lane that comes later.
/// Ranking each octant's lanes apart (each lane compared against the other seven, octant by
/// octant) costs the build about half as much again.
fn octant_order(node: &WideNode) -> [u32; WIDTH] {
    // Byte `q` of `SPREAD[m]` is bit `q` of `m`: eight octants' ones, added to eight byte
    // counters at once (a rank never exceeds 7, so no byte carries into the next).
    const SPREAD: [u64; 256] = {
        let mut t = [0u64; 256];
        let mut m = 0;
        while m < 256 {
            let mut q = 0;
            while q < 8 {
                t[m] |= ((m as u64 >> q) & 1) << (8 * q);
                q += 1;
            }
            m += 1;
        }
        t
    };
    // keys[lane]: the lane's key for octants 0-3 and 4-7. Per axis the entry coordinate is `lo`
    // for a positive direction and `-hi` for a negative one (so larger is always farther),
    // summed axis by axis from zero as the scalar definition does; an empty lane's keys are
    // infinite (farthest of all).
    let mut keys = [[Vec4::ZERO; 2]; WIDTH];
    for (lane, k) in keys.iter_mut().enumerate() {
        let side = |a: usize| {
            let (lo, hi) = (node.planes[2 * a][lane], node.planes[2 * a + 1][lane]);
            (lo, -hi)
        };
        if node.planes[0][lane] > node.planes[1][lane] {
            *k = [Vec4::INFINITY; 2];
            continue;
        }
        let ((x0, x1), (y0, y1), (z0, z1)) = (side(0), side(1), side(2));
        // Octant q: x from bit 0, y from bit 1, z from bit 2.
        let xy = Vec4::ZERO + Vec4::new(x0, x1, x0, x1) + Vec4::new(y0, y0, y1, y1);
        *k = [xy + Vec4::splat(z0), xy + Vec4::splat(z1)];
    }
    // ranks[lane], byte q: the lanes before it in octant q's order.
    let mut ranks = [0u64; WIDTH];
    for i in 0..WIDTH {
        for j in i + 1..WIDTH {
            // Octants where lane i comes first: a larger key, or an equal one (the lower lane
            // first). Keys are never NaN.
            let first = keys[i][0].cmpge(keys[j][0]).bitmask()
                | keys[i][1].cmpge(keys[j][1]).bitmask() << 4;
            ranks[j] += SPREAD[first as usize];
            ranks[i] += SPREAD[(!first & 0xff) as usize];
        }
    }
    let mut order = [0u32; WIDTH];
    for (lane, &rank) in ranks.iter().enumerate() {
        for q in 0..8 {
            order[(rank >> (8 * q)) as usize & (WIDTH - 1)] |= (lane as u32) << (3 * q);
        }
    }
    order
}

/// Appends the blocks of a binary leaf; returns the index of its first block.
fn push_blocks(sources: &mut Vec<(u32, u32)>, leaf: &BvhNode) -> u32 {
    let first = sources.len() as u32;
    let (start, end) = (leaf.first, leaf.first + leaf.count);
    for chunk in (start..end).step_by(BLOCK) {
        sources.push((chunk, (chunk + BLOCK as u32).min(end) - chunk));
    }
    first
}

/// The blocks, each made from its `(first leaf slot, count)` source, on the rayon pool.
fn fill_blocks(sources: &[(u32, u32)], triangles: &[[Vec3; 3]], prim_ids: &[u32]) -> Vec<TriBlock> {
    use rayon::prelude::*;
    // The triangles are read in leaf order, scattered over the caller's array: each block
    // asks for the triangles of the block `AHEAD` of it, so that their cache misses overlap,
    // both ends of each (36 bytes cross a cache line more often than not). Asking for the
    // start alone, or only 8 blocks ahead, builds slower (`examples/build_time MESH 20 1 cold`).
    const AHEAD: usize = 24;
    (0..sources.len())
        .into_par_iter()
        .with_min_len(4096)
        .map(|b| {
            if let Some(&(first, count)) = sources.get(b + AHEAD) {
                for slot in first..first + count {
                    let t = &triangles[prim_ids[slot as usize] as usize];
                    super::kernel::prefetch(&t[0].x);
                    super::kernel::prefetch(&t[2].z);
                }
            }
            let (first, count) = sources[b];
            let mut block = TriBlock::EMPTY;
            for lane in 0..count as usize {
                let slot = first as usize + lane;
                for (vertex, p) in triangles[prim_ids[slot] as usize].iter().enumerate() {
                    for axis in 0..3 {
                        block.v[vertex][axis][lane] = p[axis];
                    }
                }
                block.prim[lane] = prim_ids[slot];
            }
            block
        })
        .collect()
}

/// The layout made to fit its triangles after their vertices moved, keeping its shape: every
/// block's lanes read again from `triangles` (by their caller's index); then, children before
/// parents (a node's children follow it in [`WideBvh::nodes`]), every lane's box made again
/// from its blocks' triangles or from its child node's lanes, and each node's visiting order
/// made again. The boxes are the triangles' exact bounds, as [`collapse`] makes them.
pub fn refit(w: &mut WideBvh, triangles: &[[Vec3; 3]]) {
    // The triangles are scattered over the caller's array: each block asks for those of the
    // block `AHEAD` of it, as `fill_blocks` does.
    const AHEAD: usize = 24;
    for b in 0..w.blocks.len() {
        if let Some(ahead) = w.blocks.get(b + AHEAD) {
            for &id in &ahead.prim {
                if let Some(t) = triangles.get(id as usize) {
                    super::kernel::prefetch(&t[0].x);
                    super::kernel::prefetch(&t[2].z);
                }
            }
        }
        let block = &mut w.blocks[b];
        for lane in 0..BLOCK {
            let id = block.prim[lane];
            if id == u32::MAX {
                continue;
            }
            for (vertex, p) in triangles[id as usize].iter().enumerate() {
                for axis in 0..3 {
                    block.v[vertex][axis][lane] = p[axis];
                }
            }
        }
    }
    let blocks_box = |blocks: &[TriBlock]| {
        let mut b = Aabb::EMPTY;
        for block in blocks {
            for lane in 0..BLOCK {
                if block.prim[lane] != u32::MAX {
                    for p in block.triangle(lane) {
                        b.grow_point(p);
                    }
                }
            }
        }
        b
    };
    for i in (0..w.nodes.len()).rev() {
        let mut node = w.nodes[i];
        for lane in 0..WIDTH {
            if node.planes[0][lane] > node.planes[1][lane] {
                continue; // an empty lane
            }
            let child = Child(node.child[lane]);
            let b = if child.is_leaf() {
                let (first, count) = child.blocks();
                blocks_box(&w.blocks[first as usize..(first + count) as usize])
            } else {
                debug_assert!(child.index() as usize > i, "children follow their parent");
                let c = &w.nodes[child.index() as usize];
                let mut b = Aabb::EMPTY;
                for k in 0..WIDTH {
                    if c.planes[0][k] <= c.planes[1][k] {
                        b.grow_point(glam::Vec3A::new(
                            c.planes[0][k],
                            c.planes[2][k],
                            c.planes[4][k],
                        ));
                        b.grow_point(glam::Vec3A::new(
                            c.planes[1][k],
                            c.planes[3][k],
                            c.planes[5][k],
                        ));
                    }
                }
                b
            };
            for axis in 0..3 {
                node.planes[2 * axis][lane] = b.min[axis];
                node.planes[2 * axis + 1][lane] = b.max[axis];
            }
        }
        node.order = octant_order(&node);
        w.nodes[i] = node;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bvh::{BuildOptions, Bvh};
    use glam::Vec3;

    /// The cost a collapse is judged by, read off the wide tree it made: every node's box area
    /// (its visit) and every leaf lane's area times its blocks.
    fn wide_cost(w: &WideBvh, root_area: f32) -> f64 {
        let mut cost = root_area as f64;
        for n in &w.nodes {
            for lane in 0..n.children() {
                let e: [f32; 3] =
                    std::array::from_fn(|a| n.planes[2 * a + 1][lane] - n.planes[2 * a][lane]);
                let area = (e[0] * e[1] + e[1] * e[2] + e[2] * e[0]) as f64;
                let child = Child(n.child[lane]);
                cost += if child.is_leaf() {
                    area * child.blocks().1 as f64
                } else {
                    area
                };
            }
        }
        cost
    }

    /// The least cost over every way of choosing which binary inner nodes become wide nodes
    /// (the root always does; a choice is valid when no node gets more than WIDTH lanes), by
    /// trying them all.
    fn exhaustive_cost(nodes: &[BvhNode]) -> f64 {
        let inner: Vec<usize> = (2..nodes.len()).filter(|&i| !nodes[i].is_leaf()).collect();
        assert!(inner.len() <= 16, "too many subsets to try");
        let area = |i: usize| nodes[i].aabb().half_area() as f32 as f64;
        let mut best = f64::INFINITY;
        for set in 0u32..1 << inner.len() {
            let is_wide = |i: usize| {
                i == 0
                    || inner
                        .iter()
                        .position(|&j| j == i)
                        .is_some_and(|p| set >> p & 1 == 1)
            };
            // Each wide node's lanes: its binary subtree cut at wide nodes and leaves.
            let mut cost = 0.0;
            let mut valid = true;
            for w in (0..nodes.len()).filter(|&i| i != 1 && !nodes[i].is_leaf() && is_wide(i)) {
                cost += area(w);
                let mut open = vec![nodes[w].first as usize, nodes[w].first as usize + 1];
                let mut lanes = 0;
                while let Some(c) = open.pop() {
                    let n = &nodes[c];
                    if n.is_leaf() {
                        lanes += 1;
                        cost += area(c) * n.count.div_ceil(BLOCK as u32) as f64;
                    } else if is_wide(c) {
                        lanes += 1;
                    } else {
                        open.extend([n.first as usize, n.first as usize + 1]);
                    }
                }
                valid &= lanes <= WIDTH;
            }
            if valid {
                best = best.min(cost);
            }
        }
        best
    }

    /// On small trees (up to 13 inner nodes), the plan's cost is the least of every possible
    /// collapse, tried one by one, and the wide tree the collapse makes has that cost.
    #[test]
    fn the_collapse_is_the_cheapest_of_every_possible_one() {
        let mut seed = 777u32;
        let mut next = move || {
            seed = seed.wrapping_mul(1664525).wrapping_add(1013904223);
            (seed >> 8) as f32 / (1 << 24) as f32
        };
        let mut checked = 0;
        for case in 0..200 {
            let count = 9 + case % 6;
            let tris: Vec<[Vec3; 3]> = (0..count)
                .map(|_| {
                    let c = Vec3::new(next(), next(), next()) * 10.0;
                    let s = 0.2 + next();
                    [
                        c,
                        c + Vec3::new(s, 0.0, next()),
                        c + Vec3::new(0.0, s, next()),
                    ]
                })
                .collect();
            let options = BuildOptions {
                max_leaf_size: 1 + case as u32 % 2,
                ..BuildOptions::sah()
            };
            let bvh = Bvh::build(&tris, &options);
            if bvh.nodes[0].is_leaf() {
                continue;
            }
            let plan = Plan::new(&bvh.nodes);
            let root_area = bvh.nodes[0].aabb().half_area() as f32;
            let exhaustive = exhaustive_cost(&bvh.nodes);
            let planned = plan.cost[0][0] as f64;
            // The collapse itself, even where the builder lays the tree out as one leaf.
            let (wide, _) = collapse(&bvh.nodes, &tris, &bvh.prim_ids, false);
            let made = wide_cost(&wide, root_area);
            let tolerance = 1e-5 * exhaustive;
            assert!(
                (planned - exhaustive).abs() <= tolerance,
                "case {case}: plan {planned}, best of all {exhaustive}"
            );
            assert!(
                (made - exhaustive).abs() <= tolerance,
                "case {case}: the tree made costs {made}, best of all {exhaustive}"
            );
            checked += 1;
        }
        assert!(checked > 150, "only {checked} trees had inner nodes");
    }

    /// The plan made on the pool is the one made in order, bit for bit, on a tree large enough
    /// to share; nodes not laid out as the builder lays them out are refused.
    #[test]
    fn the_plan_made_on_the_pool_is_the_plan_made_in_order() {
        let tris = crate::geometry::shapes::icosphere(6);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .expect("a pool");
        for options in [BuildOptions::sah(), BuildOptions::median()] {
            let bvh = pool.install(|| Bvh::build(&tris, &options));
            assert!(bvh.nodes.len() >= PARALLEL_MIN_NODES);
            let shared = pool
                .install(|| Plan::on_pool(&bvh.nodes))
                .expect("the builder's layout");
            let ordered = Plan::in_order(&bvh.nodes);
            let bits =
                |p: &Plan| -> Vec<u32> { p.cost.iter().flatten().map(|c| c.to_bits()).collect() };
            assert!(bits(&shared) == bits(&ordered), "{:?}", options.split);
        }
        // Root 0 over the pair at 2; node 2's children stored after node 3's (a valid tree,
        // not the builder's layout).
        let leaf = |x: f32, slot: u32| BvhNode {
            min: [x, 0.0, 0.0],
            first: slot,
            max: [x + 1.0, 1.0, 1.0],
            count: 1,
        };
        let inner = |x0: f32, x1: f32, first: u32| BvhNode {
            min: [x0, 0.0, 0.0],
            first,
            max: [x1, 1.0, 1.0],
            count: 0,
        };
        let unused = inner(0.0, 0.0, 0);
        let swapped = [
            inner(0.0, 4.0, 2),
            unused,
            inner(0.0, 2.0, 6),
            inner(2.0, 4.0, 4),
            leaf(2.0, 2),
            leaf(3.0, 3),
            leaf(0.0, 0),
            leaf(1.0, 1),
        ];
        assert!(Plan::on_pool(&swapped).is_none());
        let mut laid_out = swapped;
        laid_out[2].first = 4;
        laid_out[3].first = 6;
        laid_out.swap(4, 6);
        laid_out.swap(5, 7);
        let bits =
            |p: &Plan| -> Vec<u32> { p.cost.iter().flatten().map(|c| c.to_bits()).collect() };
        let shared = Plan::on_pool(&laid_out).expect("the builder's layout");
        assert_eq!(bits(&shared), bits(&Plan::in_order(&laid_out)));
    }

    /// The octant order is, per octant, the lanes sorted by entry-corner key (farthest first,
    /// the lower lane first on equal keys, empty lanes first of all), as a plain sort finds it.
    #[test]
    fn octant_order_sorts_lanes_by_their_entry_corner() {
        // A small deterministic generator: boxes on a coarse grid, so that equal keys occur.
        let mut seed = 12345u32;
        let mut next = move || {
            seed = seed.wrapping_mul(1664525).wrapping_add(1013904223);
            (seed >> 28) as f32
        };
        for children in 1..=WIDTH {
            for _ in 0..200 {
                let mut node = WideNode::EMPTY;
                for lane in 0..children {
                    for a in 0..3 {
                        let (x, y) = (next(), next());
                        node.planes[2 * a][lane] = x.min(y);
                        node.planes[2 * a + 1][lane] = x.max(y);
                    }
                }
                node.order = octant_order(&node);
                for q in 0..8u32 {
                    let key = |lane: usize| -> f32 {
                        if lane >= children {
                            return f32::INFINITY;
                        }
                        (0..3)
                            .map(|a| {
                                if q >> a & 1 == 0 {
                                    node.planes[2 * a][lane]
                                } else {
                                    -node.planes[2 * a + 1][lane]
                                }
                            })
                            .fold(0.0, |acc, x| acc + x)
                    };
                    let mut expected: Vec<usize> = (0..WIDTH).collect();
                    expected.sort_by(|&a, &b| {
                        // Keys are never NaN; -0 and +0 are equal keys.
                        key(b).partial_cmp(&key(a)).unwrap().then(a.cmp(&b))
                    });
                    let got: Vec<usize> = (0..WIDTH).map(|i| node.lane_in_order(q, i)).collect();
                    assert_eq!(got, expected, "octant {q}, {children} children");
                }
            }
        }
    }
}
