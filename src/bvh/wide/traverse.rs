//! The traversal loops over the 8-wide layout, written once for every kernel (`Lanes`).
//!
//! Both walks take a node's children in the node's visiting order for the ray's octant
//! (`WideNode::order`, nearest last), and find the child to go to next by scanning that order
//! from the nearest end for a lane the box test entered. The scan is the point: its exit is a
//! branch, and rays traced in image order take the same branches as their neighbours, so the
//! CPU predicts the lane and starts loading the next node from the order word, which it has
//! already, instead of waiting for the box test's answer (a lane computed from the hit mask, or
//! picked by comparing entry distances, put the whole box test in the chain from node to node:
//! hitting rays 15-25% slower on the canonical camera).
//!
//! `closest` goes to the nearest child entered; the others are pushed, farthest first (one
//! with a scalar push, more in one vector push). Its incoherent form (`INCOHERENT`, for rays
//! whose neighbours take other paths: a path tracer's bounces) predicts less: a node whose ray
//! entered one child goes to it straight from the box test's mask, and one whose ray entered
//! two goes to the nearer by their entry distances, where the scan's exit would be guessed
//! wrong about as often as right; three or more are scanned as above. The same hits either
//! way (the walk's order never changes the closest hit, see [`Best::offer`]). A popped entry that starts beyond the best hit
//! so far is skipped, a popped leaf is tested on the spot. `each_hit` walks the same way without
//! culling (a leaf tested when reached or popped) until the caller asks to stop: for shadow
//! rays, depth first along the nearest path finds a blocker sooner than testing each node's
//! leaves at once (occlusion 1.5-2% faster on the canonical camera).

use super::kernel::stack::{Slots, Stack};
use super::kernel::{BlockHits, LaneValues, Lanes, NodeRay, TriRay};
use super::{BLOCK, Child, TriBlock, WIDTH, WideBvh, WideNode};
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

/// Tests a leaf's blocks, keeping the closest hit (lowest index on ties): two at a time (see
/// [`Lanes::block_pair`]), a last lone block alone. The best is the same in any order
/// (`Best::offer` keeps the closest, the lowest index on ties).
#[inline(always)]
pub(crate) fn leaf_closest<L: Lanes>(
    blocks: &[TriBlock],
    r: &TriRay,
    lr: &L::TriRay,
    best: &mut Best,
) {
    let mut pairs = blocks.chunks_exact(2);
    for pair in &mut pairs {
        // Hits as close as the best so far still count (for the index tie rule).
        let limit = next_up(best.t);
        let found = L::block_pair(&pair[0], &pair[1], lr, limit);
        offer_lanes(pair, &found, r, limit, best);
    }
    for block in pairs.remainder() {
        let limit = next_up(best.t);
        let found = L::block(block, lr, limit);
        offer_lanes(std::slice::from_ref(block), &found, r, limit, best);
    }
}

/// Offers `best` the lanes a test of `blocks` (one or two) hit, and the lanes the scalar test
/// decides (`exact`); lane `k` is lane `k % 4` of `blocks[k / 4]`.
#[inline(always)]
fn offer_lanes<V: LaneValues>(
    blocks: &[TriBlock],
    out: &BlockHits<V>,
    r: &TriRay,
    limit: f32,
    best: &mut Best,
) {
    let (mut hits, mut exact) = (out.hits, out.exact);
    while hits != 0 {
        let k = hits.trailing_zeros() as usize;
        hits &= hits - 1;
        let (u, v) = out.tuv.uv(k);
        best.offer(out.tuv.t(k), blocks[k / BLOCK].prim[k % BLOCK], u, v);
    }
    while exact != 0 {
        let k = exact.trailing_zeros() as usize;
        exact &= exact - 1;
        let (block, lane) = (&blocks[k / BLOCK], k % BLOCK);
        if let Some(h) = intersect_triangle(&r.ray, &block.triangle(lane), limit) {
            best.offer(h.t, block.prim[lane], h.u, h.v);
        }
    }
}

/// The lane of `node` to visit next among the children `mask` entered (`None` if none): the
/// nearest in the node's order for the ray's octant, found by a scan from the nearest end
/// whose exit is a predicted branch (see the module docs). The others are pushed, farthest
/// first (one by a scalar push, more by the kernel's vector push).
///
/// With `DIST` false the others are pushed without their distances (the any-hit walk, which
/// pops with [`Stack::pop_child`]). With `INCOHERENT`, one child entered is the one, and of
/// two the nearer by entry distance (the lower lane on a tie), without the scan.
#[inline(always)]
fn next_child<L: Lanes, const DIST: bool, const INCOHERENT: bool>(
    node: &WideNode,
    nr: &L::NodeRay,
    mask: u32,
    near: &[f32; WIDTH],
    stack: &mut Stack<'_>,
) -> Option<usize> {
    if mask == 0 {
        return None;
    }
    // Lane indices masked to the node's width: the compiler then needs no bounds check.
    let lane = |bits: u32| bits.trailing_zeros() as usize & (WIDTH - 1);
    if INCOHERENT {
        let rest = mask & (mask - 1);
        if rest == 0 {
            return Some(lane(mask));
        }
        if rest & (rest - 1) == 0 {
            let (a, b) = (lane(mask), lane(rest));
            let (k, f) = if near[b] < near[a] { (b, a) } else { (a, b) };
            if DIST {
                stack.push(node.child[f], near[f]);
            } else {
                stack.push_child(node.child[f]);
            }
            return Some(k);
        }
    }
    let q = L::octant(nr);
    // (The scan always finds a lane: every node's order lists all its lanes.)
    let mut k = lane(mask);
    // The mask in each of its word's four bytes: an order field shifted down keeps the two low
    // bits of the next octant's field above its three, and they only pick a copy, so the test
    // needs no masking of the field (a shift takes its amount modulo 32, as `bt` does).
    let copies = mask * 0x0101_0101;
    for i in (0..WIDTH).rev() {
        let field = node.order[i] >> (3 * q);
        if copies >> (field & 31) & 1 == 1 {
            k = (field & 7) as usize;
            break;
        }
    }
    match mask.count_ones() {
        1 => {}
        2 => {
            let f = lane(mask & !(1 << k));
            if DIST {
                stack.push(node.child[f], near[f]);
            } else {
                stack.push_child(node.child[f]);
            }
        }
        _ => L::push_others_in_order::<DIST>(node, nr, mask, near, stack),
    }
    Some(k)
}

/// What closest-hit walks did: the nodes whose child boxes they tested and the triangle blocks
/// they tested. Every kernel computes the same box and triangle tests, so every kernel walks
/// the same way and these are the same whichever kernel runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Visits {
    /// Nodes whose eight child boxes were tested against the ray.
    pub nodes: u64,
    /// Blocks of four triangles tested against the ray.
    pub blocks: u64,
}

impl std::ops::AddAssign for Visits {
    fn add_assign(&mut self, other: Visits) {
        self.nodes += other.nodes;
        self.blocks += other.blocks;
    }
}

/// Counting for [`closest`]: `()` counts nothing (and compiles to nothing), [`Visits`] counts.
pub(crate) trait Tally {
    fn node(&mut self);
    fn blocks(&mut self, count: u32);
}

impl Tally for () {
    #[inline(always)]
    fn node(&mut self) {}
    #[inline(always)]
    fn blocks(&mut self, _: u32) {}
}

impl Tally for Visits {
    #[inline(always)]
    fn node(&mut self) {
        self.nodes += 1;
    }
    #[inline(always)]
    fn blocks(&mut self, count: u32) {
        self.blocks += count as u64;
    }
}

/// Closest hit at `0 < t < t_max` (the best is `t_max` with no triangle when nothing is hit),
/// by the incoherent walk with `INCOHERENT` (see the module docs).
#[inline(always)]
pub(crate) fn closest<L: Lanes, const SAFE: bool, const INCOHERENT: bool>(
    w: &WideBvh,
    ray: &Ray,
    t_max: f32,
) -> Best {
    closest_tallied::<L, SAFE, INCOHERENT>(w, ray, t_max, &mut ())
}

/// [`closest`], telling `tally` about every node and block it tests.
#[inline(always)]
pub(crate) fn closest_tallied<L: Lanes, const SAFE: bool, const INCOHERENT: bool>(
    w: &WideBvh,
    ray: &Ray,
    t_max: f32,
    tally: &mut impl Tally,
) -> Best {
    let mut best = Best::none(t_max);
    if let Some((first, count)) = w.root_leaf {
        let tr = TriRay::new(&PreparedRay::new(ray));
        tally.blocks(count);
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
    tally.node();
    let mut mask = L::node::<SAFE>(root, &nr, cull, &mut near);
    if mask == 0 {
        return best;
    }
    let tr = TriRay::new(&PreparedRay::new(ray));
    let lr = L::tri_ray(&tr);
    let mut slots = Slots::new();
    let mut stack = Stack::new(&mut slots);
    'node: loop {
        let next = next_child::<L, true, INCOHERENT>(node, &nr, mask, &near, &mut stack);
        if let Some(k) = next {
            let child = Child(node.child[k]);
            if !child.is_leaf() {
                node = &w.nodes[child.index() as usize];
                tally.node();
                mask = L::node::<SAFE>(node, &nr, cull, &mut near);
                continue 'node;
            }
            let (first, count) = child.blocks();
            tally.blocks(count);
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
                tally.node();
                mask = L::node::<SAFE>(node, &nr, cull, &mut near);
                continue 'node;
            }
            let (first, count) = child.blocks();
            tally.blocks(count);
            leaf_closest::<L>(leaf(w, first, count), &tr, &lr, &mut best);
            cull = best.t * CULL_SLACK;
        }
    }
}

/// Calls `f(prim, t)` for every hit in a leaf (its blocks two at a time, as
/// [`leaf_closest`]); false when `f` asked to stop.
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
    let mut pairs = leaf(w, first, count).chunks_exact(2);
    for pair in &mut pairs {
        let found = L::block_pair(&pair[0], &pair[1], lr, t_max);
        if !each_lane(pair, &found, r, t_max, f) {
            return false;
        }
    }
    for block in pairs.remainder() {
        let found = L::block(block, lr, t_max);
        if !each_lane(std::slice::from_ref(block), &found, r, t_max, f) {
            return false;
        }
    }
    true
}

/// Calls `f(prim, t)` for the lanes a test of `blocks` hit and those the scalar test finds hit
/// (see [`offer_lanes`]); false when `f` asked to stop.
#[inline(always)]
fn each_lane<V: LaneValues>(
    blocks: &[TriBlock],
    out: &BlockHits<V>,
    r: &TriRay,
    t_max: f32,
    f: &mut impl FnMut(u32, f32) -> bool,
) -> bool {
    let (mut hits, mut exact) = (out.hits, out.exact);
    while hits != 0 {
        let k = hits.trailing_zeros() as usize;
        hits &= hits - 1;
        if !f(blocks[k / BLOCK].prim[k % BLOCK], out.tuv.t(k)) {
            return false;
        }
    }
    while exact != 0 {
        let k = exact.trailing_zeros() as usize;
        exact &= exact - 1;
        let (block, lane) = (&blocks[k / BLOCK], k % BLOCK);
        let tk = intersect_triangle_t(&r.ray, &block.triangle(lane), t_max);
        if tk < t_max && !f(block.prim[lane], tk) {
            return false;
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
    // Depth first, nearest child first, as the closest hit walks (no culling: any hit will
    // do); a leaf is tested when reached or popped, and the walk stops when the caller asks.
    'node: loop {
        if let Some(k) = next_child::<L, false, false>(node, &nr, mask, &near, &mut stack) {
            let child = Child(node.child[k]);
            if !child.is_leaf() {
                node = &w.nodes[child.index() as usize];
                mask = L::node::<SAFE>(node, &nr, cull, &mut near);
                continue 'node;
            }
            let (first, count) = child.blocks();
            if !leaf_each::<L>(w, first, count, &tr, &lr, t_max, f) {
                return false;
            }
        }
        loop {
            let Some(child) = stack.pop_child() else {
                return true;
            };
            let child = Child(child);
            if !child.is_leaf() {
                node = &w.nodes[child.index() as usize];
                mask = L::node::<SAFE>(node, &nr, cull, &mut near);
                continue 'node;
            }
            let (first, count) = child.blocks();
            if !leaf_each::<L>(w, first, count, &tr, &lr, t_max, f) {
                return false;
            }
        }
    }
}

/// [`closest`] as a function of its own, for the dispatch's scalar and SSE2 arms: inlined
/// there, its stack frame (the traversal stack's slots) made the dispatch push registers and
/// probe its stack on every call, the AVX2 and AVX-512 arms included, which only jump to
/// their kernels' own functions.
#[inline(never)]
pub(crate) fn closest_apart<L: Lanes, const SAFE: bool, const INCOHERENT: bool>(
    w: &WideBvh,
    ray: &Ray,
    t_max: f32,
) -> Best {
    closest::<L, SAFE, INCOHERENT>(w, ray, t_max)
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
