//! From the binary tree to 8-wide nodes, in two passes over the binary nodes (linear time).
//!
//! Which binary nodes become wide nodes is chosen to minimise the wide tree's SAH cost (the
//! expected number of nodes a ray visits; [`Plan`]): one pass bottom up finds, for every binary
//! node and lane budget, whether to keep it as one lane or open it, and one pass top down
//! makes the nodes. Binary leaves become wide leaves, their triangles cut into blocks of four.
//! Siblings' nodes and blocks are stored side by side, and subtrees depth first. Each node
//! gets its per-octant visiting order ([`WideNode::order`]).
//!
//! The greedy rule it replaced (open the inner child of largest area until eight lanes are
//! filled) left 8,187 of the dragon 202k's 18,718 nodes with two children: a small inner node
//! left over when its parent's lanes ran out became a node of its own. The plan makes 10,870
//! nodes there, its cost 15.02 against 15.81 (node visits 11.24 against 12.03, block tests
//! 3.78 either way).

use glam::{Vec3, Vec4};

use super::{BLOCK, Child, Kernel, TriBlock, WIDTH, WideBvh, WideNode};
use crate::bvh::BvhNode;

/// Collapses `nodes` (the binary tree, root at 0) whose leaf slots hold the triangles
/// `triangles[prim_ids[slot]]`. Also returns, for every binary leaf, the index of its first
/// block (the blocks of a leaf are consecutive; 0 for inner nodes).
pub fn collapse(
    nodes: &[BvhNode],
    triangles: &[[Vec3; 3]],
    prim_ids: &[u32],
) -> (WideBvh, Vec<u32>) {
    let mut out = WideBvh::default();
    out.set_kernel(Kernel::detect())
        .expect("the detected kernel runs here");
    let mut leaf_blocks = vec![0u32; nodes.len()];
    if prim_ids.is_empty() {
        return (out, leaf_blocks);
    }
    if nodes[0].is_leaf() || prim_ids.len() > Child::MAX_FIRST_BLOCK as usize {
        // One root leaf: the tree is one leaf, or it has more blocks than a leaf word can
        // address (over 500 million triangles, hundreds of gigabytes): every binary leaf's
        // blocks in slot order, tested one after the other, correct if slow.
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
    out.nodes.reserve(nodes.len() / 8);
    // Where each block's triangles come from; the blocks are made at the end, in parallel.
    let mut sources: Vec<(u32, u32)> = Vec::with_capacity(prim_ids.len() / BLOCK + nodes.len() / 8);
    out.nodes.push(WideNode::EMPTY);
    // (wide node to fill, binary inner node it stands for)
    let mut stack = vec![(0usize, 0usize)];
    let mut kids: Vec<usize> = Vec::with_capacity(WIDTH);
    let plan = Plan::new(nodes);
    while let Some((wide, binary)) = stack.pop() {
        kids.clear();
        plan.node_lanes(nodes, binary, &mut kids);
        let mut node = WideNode::EMPTY;
        let mut inner = [(0usize, 0usize); WIDTH];
        let mut inner_count = 0;
        for (lane, &c) in kids.iter().enumerate() {
            let n = &nodes[c];
            for axis in 0..3 {
                node.planes[2 * axis][lane] = n.min[axis];
                node.planes[2 * axis + 1][lane] = n.max[axis];
            }
            node.child[lane] = if n.is_leaf() {
                let first = push_blocks(&mut sources, n);
                leaf_blocks[c] = first;
                leaf_child(&mut out.nodes, n, first, sources.len() as u32 - first)
            } else {
                let index = out.nodes.len();
                out.nodes.push(WideNode::EMPTY);
                inner[inner_count] = (index, c);
                inner_count += 1;
                Child::inner(index as u32)
            }
            .0;
        }
        node.order = octant_order(&node);
        out.nodes[wide] = node;
        // Depth first, the first child next.
        stack.extend(inner[..inner_count].iter().rev());
    }
    out.blocks = fill_blocks(&sources, triangles, prim_ids);
    (out, leaf_blocks)
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
        let mut cost = vec![[0.0f32; WIDTH]; nodes.len()];
        // Children are stored after their parents: one backward pass sees them first.
        for i in (2..nodes.len()).rev().chain([0]) {
            let n = &nodes[i];
            let area = n.aabb().half_area() as f32;
            cost[i] = if n.is_leaf() {
                [area * n.count.div_ceil(BLOCK as u32) as f32; WIDTH]
            } else {
                let opened = opened(&cost[n.first as usize], &cost[n.first as usize + 1]);
                // Kept as one lane: a node of its own, its children in up to WIDTH lanes.
                let own = area + opened[WIDTH - 1];
                let mut c = [own; WIDTH];
                for k in 1..WIDTH {
                    c[k] = if opened[k] < own { opened[k] } else { own };
                }
                c
            };
        }
        Plan { cost }
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

    /// Appends the lanes binary node `i` takes when given `k` of them.
    fn lanes(&self, nodes: &[BvhNode], i: usize, k: usize, out: &mut Vec<usize>) {
        let n = &nodes[i];
        // Kept as one lane unless opening it into its `k` lanes costs less.
        if k == 1 || n.is_leaf() || self.cost[i][k - 1] >= self.cost[i][0] {
            out.push(i);
            return;
        }
        let j = self.share(nodes, i, k);
        self.lanes(nodes, n.first as usize, j, out);
        self.lanes(nodes, n.first as usize + 1, k - j, out);
    }

    /// The lanes of the node made for binary inner node `i`: its children in up to WIDTH.
    fn node_lanes(&self, nodes: &[BvhNode], i: usize, out: &mut Vec<usize>) {
        let j = self.share(nodes, i, WIDTH);
        self.lanes(nodes, nodes[i].first as usize, j, out);
        self.lanes(nodes, nodes[i].first as usize + 1, WIDTH - j, out);
    }
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
/// Session 25: ranking each octant's lanes apart (each lane compared against the other seven,
/// octant by octant) took 3.6% of a bunny build's samples, this 2.2%.
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
    // both ends of each (36 bytes cross a cache line more often than not). Session 25,
    // `examples/build_time` alternating: the start alone and 8 blocks ahead took about 0.5 ms
    // more of a dragon 202k build (fill 3.7-4.5 ms against 3.3-3.8, cold).
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
            let made = wide_cost(&bvh.wide, root_area);
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
