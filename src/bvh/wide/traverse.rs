//! The traversal loops over the 8-wide layout, written once for every kernel (`Lanes`).
//!
//! `closest` visits the nearest child first. One child hit: go there with no stack traffic;
//! two: push the farther; more: push all in the node's visiting order for the ray's octant
//! (farthest first, so the nearest ends on top; no sort). A popped entry that starts beyond
//! the best hit so far is skipped, a popped leaf is tested on the spot. `each_hit` tests the
//! leaves a node leads to at once and visits its inner children in lane order, until the caller
//! asks to stop.

use super::kernel::stack::{Slots, Stack};
use super::kernel::{BlockHits, Lanes, NodeRay, TriRay};
use super::{BLOCK, Child, TriBlock, WIDTH, WideBvh};
use crate::geometry::{PreparedRay, Ray, intersect_triangle, intersect_triangle_t};

/// Boxes are culled only when they start clearly beyond the best hit so far: the slack keeps a
/// box whose entry distance rounds a hair past an equally distant hit, so ties in `t` still go
/// to the lowest triangle index exactly as brute force decides them.
pub(crate) const CULL_SLACK: f32 = 1.0 + 1.0 / 65536.0;

/// The best hit of a closest-hit traversal: distance, triangle (caller's index) and the
/// barycentric weights of its second and third vertex; `prim` is `u32::MAX` when nothing was
/// hit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Best {
    pub t: f32,
    pub prim: u32,
    pub u: f32,
    pub v: f32,
}

impl Best {
    pub fn none(t_max: f32) -> Self {
        Self {
            t: t_max,
            prim: u32::MAX,
            u: 0.0,
            v: 0.0,
        }
    }

    /// Keeps the hit `(t, prim)` when it is closer, or as close with a lower index.
    #[inline(always)]
    pub(crate) fn offer(&mut self, t: f32, prim: u32, u: f32, v: f32) {
        if t < self.t || (t == self.t && prim < self.prim) {
            *self = Best { t, prim, u, v };
        }
    }
}

/// The next float above `t`, for `t` in `(0, +inf]` (the best distance always is): one
/// integer add, where `f32::next_up` branches on NaN, zero and sign.
#[inline(always)]
pub(crate) fn next_up(t: f32) -> f32 {
    f32::from_bits(t.to_bits() + (t < f32::INFINITY) as u32)
}

/// The blocks `first..first + count` of `w` (a leaf's).
#[inline(always)]
fn leaf(w: &WideBvh, first: u32, count: u32) -> &[TriBlock] {
    &w.blocks[first as usize..(first + count) as usize]
}

/// Tests a leaf's blocks, keeping the closest hit (lowest index on ties).
#[inline(always)]
pub(crate) fn leaf_closest<L: Lanes>(
    blocks: &[TriBlock],
    r: &TriRay,
    lr: &L::TriRay,
    best: &mut Best,
) {
    let mut out = BlockHits::default();
    for block in blocks {
        // Hits as close as the best so far still count (for the index tie rule).
        let limit = next_up(best.t);
        let (mut hits, mut exact) = L::block(block, lr, limit, &mut out);
        while hits != 0 {
            let k = hits.trailing_zeros() as usize & (BLOCK - 1);
            hits &= hits - 1;
            best.offer(out.t[k], block.prim[k], out.u[k], out.v[k]);
        }
        while exact != 0 {
            let k = exact.trailing_zeros() as usize & (BLOCK - 1);
            exact &= exact - 1;
            if let Some(h) = intersect_triangle(&r.ray, &block.triangle(k), limit) {
                best.offer(h.t, block.prim[k], h.u, h.v);
            }
        }
    }
}

/// Closest hit at `0 < t < t_max` (the best is `t_max` with no triangle when nothing is hit).
#[inline(always)]
pub(crate) fn closest<L: Lanes, const SAFE: bool>(w: &WideBvh, ray: &Ray, t_max: f32) -> Best {
    let mut best = Best::none(t_max);
    if let Some((first, count)) = w.root_leaf {
        let tr = TriRay::new(&PreparedRay::new(ray));
        leaf_closest::<L>(leaf(w, first, count), &tr, &L::tri_ray(&tr), &mut best);
        return best;
    }
    let Some(root) = w.nodes.first() else {
        return best;
    };
    let nr = L::node_ray(&NodeRay::of(ray));
    let mut near = [0.0f32; WIDTH];
    // The cull distance, `best.t * CULL_SLACK`, kept beside the best hit: it changes only at a
    // leaf.
    let mut cull = t_max * CULL_SLACK;
    // The root first, before the triangle test's setup (the axis permutation and shear): many
    // rays of an image enter none of its children and leave here. The others go on from its
    // answer (`node`, `mask`: the node being visited and the children the ray enters).
    let mut node = root;
    let mut mask = L::node::<SAFE>(root, &nr, cull, &mut near);
    if mask == 0 {
        return best;
    }
    let tr = TriRay::new(&PreparedRay::new(ray));
    let lr = L::tri_ray(&tr);
    let mut slots = Slots::new();
    let mut stack = Stack::new(&mut slots);
    // Lane indices masked to the node's width: the compiler then needs no bounds check.
    let lane = |bits: u32| bits.trailing_zeros() as usize & (WIDTH - 1);
    'node: loop {
        // The child to visit next, if this node gives one.
        let next = match mask.count_ones() {
            0 => None,
            1 => Some(lane(mask)),
            2 => {
                let a = lane(mask);
                let b = lane(mask & (mask - 1));
                // A branch, not a select: rays traced in image order take the same side at
                // the same node as their neighbours, so the branch is mostly predicted and the
                // next node's loads start before the distances are compared (a select put the
                // comparison, on distances just stored, in the chain from node to node:
                // hitting rays 3-5% slower).
                if near[b] < near[a] {
                    stack.push(node.child[a], near[a]);
                    Some(b)
                } else {
                    stack.push(node.child[b], near[b]);
                    Some(a)
                }
            }
            _ => {
                L::push_in_order(node, &nr, mask, &near, &mut stack);
                None
            }
        };
        if let Some(k) = next {
            let child = Child(node.child[k]);
            if !child.is_leaf() {
                node = &w.nodes[child.index() as usize];
                mask = L::node::<SAFE>(node, &nr, cull, &mut near);
                continue 'node;
            }
            let (first, count) = child.blocks();
            leaf_closest::<L>(leaf(w, first, count), &tr, &lr, &mut best);
            cull = best.t * CULL_SLACK;
        }
        // Pop, skipping entries that now start beyond the best hit; leaves are tested here.
        loop {
            let Some((child, dist)) = stack.pop() else {
                return best;
            };
            if dist > cull {
                continue;
            }
            let child = Child(child);
            if !child.is_leaf() {
                node = &w.nodes[child.index() as usize];
                mask = L::node::<SAFE>(node, &nr, cull, &mut near);
                continue 'node;
            }
            let (first, count) = child.blocks();
            leaf_closest::<L>(leaf(w, first, count), &tr, &lr, &mut best);
            cull = best.t * CULL_SLACK;
        }
    }
}

/// Calls `f(prim, t)` for every hit in a leaf; false when `f` asked to stop.
#[inline(always)]
fn leaf_each<L: Lanes>(
    w: &WideBvh,
    first: u32,
    count: u32,
    r: &TriRay,
    lr: &L::TriRay,
    t_max: f32,
    f: &mut impl FnMut(u32, f32) -> bool,
) -> bool {
    let mut out = BlockHits::default();
    for b in first..first + count {
        let block = &w.blocks[b as usize];
        let (mut hits, mut exact) = L::block(block, lr, t_max, &mut out);
        while hits != 0 {
            let k = hits.trailing_zeros() as usize & (BLOCK - 1);
            hits &= hits - 1;
            if !f(block.prim[k], out.t[k]) {
                return false;
            }
        }
        while exact != 0 {
            let k = exact.trailing_zeros() as usize & (BLOCK - 1);
            exact &= exact - 1;
            let tk = intersect_triangle_t(&r.ray, &block.triangle(k), t_max);
            if tk < t_max && !f(block.prim[k], tk) {
                return false;
            }
        }
    }
    true
}

/// Calls `f(prim, t)` for every triangle hit at `0 < t < t_max`, in no particular order, until
/// `f` returns false. Returns false when it was stopped.
#[inline(always)]
pub(crate) fn each_hit<L: Lanes, const SAFE: bool>(
    w: &WideBvh,
    ray: &Ray,
    t_max: f32,
    f: &mut impl FnMut(u32, f32) -> bool,
) -> bool {
    if let Some((first, count)) = w.root_leaf {
        let tr = TriRay::new(&PreparedRay::new(ray));
        return leaf_each::<L>(w, first, count, &tr, &L::tri_ray(&tr), t_max, f);
    }
    let Some(root) = w.nodes.first() else {
        return true;
    };
    let nr = L::node_ray(&NodeRay::of(ray));
    // Boxes are culled with the same slack as the closest-hit search: a hit on a box's face
    // just before `t_max` may have a computed entry distance just past it.
    let cull = t_max * CULL_SLACK;
    let mut near = [0.0f32; WIDTH];
    // The root first, before the triangle test's setup, as for the closest hit.
    let mut mask = L::node::<SAFE>(root, &nr, cull, &mut near);
    if mask == 0 {
        return true;
    }
    let tr = TriRay::new(&PreparedRay::new(ray));
    let lr = L::tri_ray(&tr);
    let mut slots = Slots::new();
    let mut stack = Stack::new(&mut slots);
    let mut node = root;
    loop {
        // Leaves are tested as soon as they are found (a shadow ray may stop there); the
        // nearest inner child is visited next (fewer nodes before the first hit: 6.48 against
        // 6.95 a hitting ray for the first in lane order, dragon 202k), the others wait on the
        // stack.
        let mut next: Option<(u32, f32)> = None;
        while mask != 0 {
            let k = mask.trailing_zeros() as usize & (WIDTH - 1);
            mask &= mask - 1;
            let child = Child(node.child[k]);
            if child.is_leaf() {
                let (first, count) = child.blocks();
                if !leaf_each::<L>(w, first, count, &tr, &lr, t_max, f) {
                    return false;
                }
            } else {
                match next {
                    None => next = Some((child.index(), near[k])),
                    Some((n, d)) if near[k] < d => {
                        stack.push(n, 0.0);
                        next = Some((child.index(), near[k]));
                    }
                    Some(_) => stack.push(child.0, 0.0),
                }
            }
        }
        let next = next.map(|(n, _)| n);
        match next.or_else(|| stack.pop().map(|(c, _)| c)) {
            Some(c) => {
                node = &w.nodes[c as usize];
                mask = L::node::<SAFE>(node, &nr, cull, &mut near);
            }
            None => return true,
        }
    }
}

/// [`closest`] as a function of its own, for the dispatch's scalar and SSE2 arms: inlined
/// there, its stack frame (the traversal stack's slots) made the dispatch push registers and
/// probe its stack on every call, the AVX2 and AVX-512 arms included, which only jump to
/// their kernels' own functions.
#[inline(never)]
pub(crate) fn closest_apart<L: Lanes, const SAFE: bool>(
    w: &WideBvh,
    ray: &Ray,
    t_max: f32,
) -> Best {
    closest::<L, SAFE>(w, ray, t_max)
}

/// [`each_hit`] as a function of its own (see [`closest_apart`]).
#[inline(never)]
pub(crate) fn each_hit_apart<L: Lanes, const SAFE: bool, F: FnMut(u32, f32) -> bool>(
    w: &WideBvh,
    ray: &Ray,
    t_max: f32,
    f: &mut F,
) -> bool {
    each_hit::<L, SAFE>(w, ray, t_max, f)
}
