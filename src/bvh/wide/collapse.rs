//! From the binary tree to 8-wide nodes, in one pass over the binary nodes (linear time).
//!
//! Each wide node starts from a binary inner node's two children and repeatedly opens the
//! inner child with the largest surface area (the one a random ray is likeliest to enter),
//! until it has eight children or only leaves are left. Binary leaves become wide leaves, their
//! triangles cut into blocks of four. Siblings' nodes and blocks are stored side by side, and
//! subtrees depth first. Each node gets its per-octant visiting order ([`WideNode::order`]).

use glam::{Vec3A, Vec4};

use super::{BLOCK, Child, Kernel, TriBlock, WIDTH, WideBvh, WideNode};
use crate::bvh::BvhNode;

/// Collapses `nodes` (the binary tree, root at 0) over `tris` (leaf order) and `prim_ids`.
pub fn collapse(nodes: &[BvhNode], tris: &[[Vec3A; 3]], prim_ids: &[u32]) -> WideBvh {
    let mut out = WideBvh::default();
    out.set_kernel(Kernel::detect())
        .expect("the detected kernel runs here");
    if tris.is_empty() {
        return out;
    }
    let root = &nodes[0];
    if root.is_leaf() {
        let mut sources = Vec::new();
        push_blocks(&mut sources, root);
        out.blocks = fill_blocks(&sources, tris, prim_ids);
        out.root_leaf = Some((0, out.blocks.len() as u32));
        return out;
    }
    if tris.len() > Child::MAX_FIRST_BLOCK as usize {
        // More blocks than a leaf word can address (over 500 million triangles, hundreds of
        // gigabytes): every triangle in one root leaf, correct if slow.
        let all = BvhNode {
            count: tris.len() as u32,
            first: 0,
            ..*root
        };
        let mut sources = Vec::new();
        push_blocks(&mut sources, &all);
        out.blocks = fill_blocks(&sources, tris, prim_ids);
        out.root_leaf = Some((0, out.blocks.len() as u32));
        return out;
    }
    out.nodes.reserve(nodes.len() / 4);
    // Where each block's triangles come from; the blocks are made at the end, in parallel.
    let mut sources: Vec<(u32, u32)> = Vec::with_capacity(tris.len() / BLOCK + nodes.len() / 8);
    out.nodes.push(WideNode::EMPTY);
    // (wide node to fill, binary inner node it stands for)
    let mut stack = vec![(0usize, 0usize)];
    let mut kids: Vec<usize> = Vec::with_capacity(WIDTH);
    while let Some((wide, binary)) = stack.pop() {
        let b = &nodes[binary];
        kids.clear();
        kids.extend([b.first as usize, b.first as usize + 1]);
        while kids.len() < WIDTH {
            // The inner child with the largest surface area.
            let open = kids
                .iter()
                .enumerate()
                .filter(|(_, c)| !nodes[**c].is_leaf())
                .max_by(|a, b| {
                    let area = |i: usize| nodes[i].aabb().half_area();
                    area(*a.1).total_cmp(&area(*b.1))
                })
                .map(|(k, _)| k);
            let Some(k) = open else { break };
            let c = &nodes[kids[k]];
            kids[k] = c.first as usize;
            kids.insert(k + 1, c.first as usize + 1);
        }
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
    out.blocks = fill_blocks(&sources, tris, prim_ids);
    out
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
fn octant_order(node: &WideNode) -> [u32; WIDTH] {
    // Bits set in each byte: `count_ones` of the portable build (no POPCNT) is a sequence of
    // shifts and masks, and this loop counts 64 masks a node.
    const BITS_SET: [u8; 256] = {
        let mut t = [0u8; 256];
        let mut i = 0;
        while i < 256 {
            t[i] = (i as u32).count_ones() as u8;
            i += 1;
        }
        t
    };
    // Per axis, each lane's entry coordinate for a positive and a negative direction: `lo`,
    // and `-hi` (so larger is always farther); empty lanes are farthest of all. Lanes 0-3 and
    // 4-7 as two vectors.
    let half = |v: &[f32; WIDTH], h: usize| Vec4::from_slice(&v[4 * h..4 * h + 4]);
    let mut corner = [[[Vec4::ZERO; 2]; 2]; 3];
    for (a, [positive, negative]) in corner.iter_mut().enumerate() {
        for (h, (pos, neg)) in positive.iter_mut().zip(negative.iter_mut()).enumerate() {
            let (lo, hi) = (
                half(&node.planes[2 * a], h),
                half(&node.planes[2 * a + 1], h),
            );
            let empty = lo.cmpgt(hi);
            *pos = Vec4::select(empty, Vec4::INFINITY, lo);
            *neg = Vec4::select(empty, Vec4::INFINITY, -hi);
        }
    }
    let mut order = [0u32; WIDTH];
    for q in 0..8usize {
        // The keys summed axis by axis from zero, as the scalar definition does.
        let mut key = [Vec4::ZERO; 2];
        for (a, side) in corner.iter().enumerate() {
            let s = &side[q >> a & 1];
            key[0] += s[0];
            key[1] += s[1];
        }
        let keys: [f32; WIDTH] = {
            let mut k = [0.0; WIDTH];
            key[0].write_to_slice(&mut k[..4]);
            key[1].write_to_slice(&mut k[4..]);
            k
        };
        // Each lane's rank: how many lanes come before it (larger key, or equal key and lower
        // lane), all eight compared at once; every rank is distinct.
        for (i, &ki) in keys.iter().enumerate() {
            let k = Vec4::splat(ki);
            let larger = key[0].cmpgt(k).bitmask() | key[1].cmpgt(k).bitmask() << 4;
            let equal = key[0].cmpeq(k).bitmask() | key[1].cmpeq(k).bitmask() << 4;
            let rank = BITS_SET[(larger | (equal & ((1 << i) - 1))) as usize] as usize;
            order[rank] |= (i as u32) << (3 * q);
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
fn fill_blocks(sources: &[(u32, u32)], tris: &[[Vec3A; 3]], prim_ids: &[u32]) -> Vec<TriBlock> {
    use rayon::prelude::*;
    sources
        .par_iter()
        .with_min_len(4096)
        .map(|&(first, count)| {
            let mut block = TriBlock::EMPTY;
            for lane in 0..count as usize {
                let slot = first as usize + lane;
                for (vertex, p) in tris[slot].iter().enumerate() {
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
