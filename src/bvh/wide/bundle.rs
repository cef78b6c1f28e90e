//! Incoherent rays sixteen at a time: a path tracer's bounces and shadow rays walked through
//! the tree as bundles, a ray a SIMD lane, where the single-ray walks test one ray against a
//! node's eight boxes or a block's four triangles.
//!
//! A bundle's rays need not share an octant or anything else. At a node, each child box is
//! tested against all sixteen rays at once (each ray its own near planes, entry distance and
//! cull distance), and a child is pushed with the lanes that enter it; at a leaf, each
//! triangle is tested against the bundle's live lanes at once
//! ([`crate::geometry::intersect_triangle_lanes`]). This pays where the rays of a bundle go
//! through the same nodes: in a small closed scene (a room, the Cornell box) every ray enters
//! nearly every leaf, and a triangle tested against sixteen rays costs about what the
//! single-ray kernels spend on one. In a large mesh, rays leaving different surfaces in
//! different directions share few nodes and the lanes run mostly empty, so the batch queries
//! use bundles only for small trees ([`WideBvh::bundles_pay`]).
//!
//! Every lane gets exactly the answer its ray gets alone: the box test computes the same
//! distances as the single-ray kernels (a NaN from `0 * inf` constrains nothing), the cull
//! distance is the same function of the lane's best hit, the triangle test is the same
//! operation for operation, its undecided lanes go to the scalar test, and the closest hit is
//! kept by the same rule (nearest, then lowest index), which no visiting order changes.

use super::kernel::{FAR_SCALE, check_ray};
use super::traverse::{Best, CULL_SLACK, next_up};
use super::{BLOCK, Child, TriBlock, WIDTH, WideBvh, WideNode};
use crate::geometry::{PreparedRay, Ray, RayLanes, intersect_triangle, intersect_triangle_lanes};

/// Rays in a bundle.
pub(crate) const LANES: usize = 16;

/// The most wide nodes a tree may have for the batch queries to walk bundles (see
/// [`WideBvh::bundles_pay`]).
pub(crate) const MAX_BUNDLE_NODES: usize = 64;

/// A bundle's rays, component by component.
struct Bundle {
    /// Lanes holding a ray to trace (bit `i` for lane `i`).
    live: u32,
    origin: [[f32; LANES]; 3],
    inv: [[f32; LANES]; 3],
    /// `inv * FAR_SCALE`, as the single-ray box test scales its far distances.
    inv_far: [[f32; LANES]; 3],
    /// The direction's sign bit, per axis: the near plane is the box's high one.
    neg: [[bool; LANES]; 3],
    /// The octant of the first live ray: the children's visiting order.
    octant: u32,
    tris: RayLanes<LANES>,
    prepared: [PreparedRay; LANES],
}

impl Bundle {
    /// A bundle of `rays` (at most [`LANES`]); lane `i` is live when `rays[i]` is a ray a query
    /// walks the tree for and `t_max[i]` is positive.
    #[inline(always)]
    fn new(rays: impl Iterator<Item = (Ray, f32)>) -> Bundle {
        let zero = PreparedRay::new(&Ray::new(glam::Vec3::ZERO, glam::Vec3::X));
        let mut b = Bundle {
            live: 0,
            origin: [[0.0; LANES]; 3],
            inv: [[1.0; LANES]; 3],
            inv_far: [[1.0; LANES]; 3],
            neg: [[false; LANES]; 3],
            octant: 0,
            tris: RayLanes::EMPTY,
            prepared: [zero; LANES],
        };
        let mut first = true;
        for (i, (ray, t_max)) in rays.enumerate().take(LANES) {
            if check_ray(&ray).is_none() || t_max.is_nan() || t_max <= 0.0 {
                continue;
            }
            let p = PreparedRay::new(&ray);
            b.live |= 1 << i;
            for a in 0..3 {
                b.origin[a][i] = ray.origin[a];
                b.inv[a][i] = p.inv_dir[a];
                b.inv_far[a][i] = p.inv_dir[a] * FAR_SCALE;
                b.neg[a][i] = ray.dir[a].is_sign_negative();
            }
            if first {
                b.octant = (0..3).map(|a| (b.neg[a][i] as u32) << a).sum();
                first = false;
            }
            b.tris.set(i, &p);
            b.prepared[i] = p;
        }
        b
    }
}

/// The lanes whose `near` is at most `cull`.
#[inline(always)]
fn within(near: &[f32; LANES], cull: &[f32; LANES]) -> u32 {
    let mut m = 0;
    for i in 0..LANES {
        m |= ((near[i] <= cull[i]) as u32) << i;
    }
    m
}

/// Tests the node's eight child boxes against every lane for `0 <= t <= cull`: the lanes (of
/// `lanes`) entering child `k`, and their entry distances in `near[k]`.
#[inline(always)]
fn node_lanes(
    n: &WideNode,
    b: &Bundle,
    cull: &[f32; LANES],
    lanes: u32,
    near: &mut [[f32; LANES]; WIDTH],
) -> [u32; WIDTH] {
    let mut masks = [0; WIDTH];
    for k in 0..WIDTH {
        let mut enter = 0;
        for i in 0..LANES {
            let mut t_near = 0.0f32;
            let mut t_far = cull[i];
            for a in 0..3 {
                let (lo_plane, hi_plane) = (n.planes[2 * a][k], n.planes[2 * a + 1][k]);
                let neg = b.neg[a][i];
                let near_plane = if neg { hi_plane } else { lo_plane };
                let far_plane = if neg { lo_plane } else { hi_plane };
                let lo = (near_plane - b.origin[a][i]) * b.inv[a][i];
                let hi = (far_plane - b.origin[a][i]) * b.inv_far[a][i];
                // A NaN (0 * inf: the ray runs in the slab's plane) fails both comparisons and
                // constrains nothing.
                t_near = if lo > t_near { lo } else { t_near };
                t_far = if hi < t_far { hi } else { t_far };
            }
            near[k][i] = t_near;
            enter |= ((t_near <= t_far) as u32) << i;
        }
        masks[k] = enter & lanes;
    }
    masks
}

/// A bundle's best hits, component by component (see [`Best`]).
struct Bests {
    t: [f32; LANES],
    prim: [u32; LANES],
    u: [f32; LANES],
    v: [f32; LANES],
}

impl Bests {
    /// Keeps lane `i`'s hit when it is closer, or as close with a lower index ([`Best::offer`]).
    #[inline(always)]
    fn offer(&mut self, i: usize, t: f32, prim: u32, u: f32, v: f32) {
        if t < self.t[i] || (t == self.t[i] && prim < self.prim[i]) {
            (self.t[i], self.prim[i], self.u[i], self.v[i]) = (t, prim, u, v);
        }
    }
}

/// Tests a leaf's triangles against `lanes`, keeping each lane's closest hit.
#[inline(always)]
fn leaf_closest(blocks: &[TriBlock], b: &Bundle, lanes: u32, best: &mut Bests) {
    for block in blocks {
        for j in 0..BLOCK {
            let prim = block.prim[j];
            if prim == u32::MAX {
                continue;
            }
            let tri = block.triangle(j);
            // Hits as close as the best so far still count (for the index tie rule).
            let limit: [f32; LANES] = std::array::from_fn(|i| next_up(best.t[i]));
            let found = intersect_triangle_lanes(&b.tris, &tri, &limit, lanes);
            let mut hits = found.hit;
            while hits != 0 {
                let i = hits.trailing_zeros() as usize;
                hits &= hits - 1;
                best.offer(i, found.t[i], prim, found.u[i], found.v[i]);
            }
            let mut exact = found.exact;
            while exact != 0 {
                let i = exact.trailing_zeros() as usize;
                exact &= exact - 1;
                if let Some(h) = intersect_triangle(&b.prepared[i], &tri, limit[i]) {
                    best.offer(i, h.t, prim, h.u, h.v);
                }
            }
        }
    }
}

/// The lanes (of `lanes`) that some triangle of the leaf blocks before `t_max`.
#[inline(always)]
fn leaf_any(blocks: &[TriBlock], b: &Bundle, lanes: u32, t_max: &[f32; LANES]) -> u32 {
    let mut blocked = 0;
    for block in blocks {
        for j in 0..BLOCK {
            if block.prim[j] == u32::MAX {
                continue;
            }
            let tri = block.triangle(j);
            let found = intersect_triangle_lanes(&b.tris, &tri, t_max, lanes & !blocked);
            blocked |= found.hit;
            let mut exact = found.exact & !blocked;
            while exact != 0 {
                let i = exact.trailing_zeros() as usize;
                exact &= exact - 1;
                if intersect_triangle(&b.prepared[i], &tri, t_max[i]).is_some() {
                    blocked |= 1 << i;
                }
            }
            if blocked == lanes {
                return blocked;
            }
        }
    }
    blocked
}

/// An entry of the walk's stack: a child word, the lanes that entered it and their entry
/// distances.
#[derive(Clone, Copy)]
struct Entry {
    child: u32,
    lanes: u32,
    near: [f32; LANES],
}

/// The blocks of a leaf child word.
#[inline(always)]
fn leaf_blocks(w: &WideBvh, child: Child) -> &[TriBlock] {
    let (first, count) = child.blocks();
    &w.blocks[first as usize..(first + count) as usize]
}

/// Pushes the children of `node` that some lane entered, farthest first in the octant's order
/// (so the nearest is popped first).
#[inline(always)]
fn push_children(
    node: &WideNode,
    octant: u32,
    masks: &[u32; WIDTH],
    near: &[[f32; LANES]; WIDTH],
    stack: &mut Vec<Entry>,
) {
    for i in 0..WIDTH {
        let k = node.lane_in_order(octant, i);
        if masks[k] != 0 {
            stack.push(Entry {
                child: node.child[k],
                lanes: masks[k],
                near: near[k],
            });
        }
    }
}

/// The closest hits of a bundle's live lanes at `0 < t < best.t` (`best` starts at each
/// lane's `t_max` with no triangle).
#[inline(always)]
fn closest(w: &WideBvh, b: &Bundle, best: &mut Bests, stack: &mut Vec<Entry>) {
    if b.live == 0 {
        return;
    }
    if let Some((first, count)) = w.root_leaf {
        let blocks = &w.blocks[first as usize..(first + count) as usize];
        leaf_closest(blocks, b, b.live, best);
        return;
    }
    let Some(root) = w.nodes.first() else {
        return;
    };
    let mut cull: [f32; LANES] = std::array::from_fn(|i| best.t[i] * CULL_SLACK);
    let mut near = [[0.0f32; LANES]; WIDTH];
    stack.clear();
    let mut node = root;
    let mut lanes = b.live;
    loop {
        let masks = node_lanes(node, b, &cull, lanes, &mut near);
        push_children(node, b.octant, &masks, &near, stack);
        // Pop, dropping lanes whose entry now lies beyond their best hit; leaves are tested
        // here.
        loop {
            let Some(e) = stack.pop() else {
                return;
            };
            lanes = e.lanes & within(&e.near, &cull);
            if lanes == 0 {
                continue;
            }
            let child = Child(e.child);
            if !child.is_leaf() {
                node = &w.nodes[child.index() as usize];
                break;
            }
            leaf_closest(leaf_blocks(w, child), b, lanes, best);
            cull = std::array::from_fn(|i| best.t[i] * CULL_SLACK);
        }
    }
}

/// The live lanes of a bundle that something blocks at `0 < t < t_max`.
#[inline(always)]
fn occluded(w: &WideBvh, b: &Bundle, t_max: &[f32; LANES], stack: &mut Vec<Entry>) -> u32 {
    if b.live == 0 {
        return 0;
    }
    if let Some((first, count)) = w.root_leaf {
        let blocks = &w.blocks[first as usize..(first + count) as usize];
        return leaf_any(blocks, b, b.live, t_max);
    }
    let Some(root) = w.nodes.first() else {
        return 0;
    };
    // The same slack as the single-ray any-hit walk: a hit on a box's face just before
    // `t_max` may have a computed entry distance just past it.
    let cull: [f32; LANES] = std::array::from_fn(|i| t_max[i] * CULL_SLACK);
    let mut near = [[0.0f32; LANES]; WIDTH];
    stack.clear();
    let mut blocked = 0;
    let mut node = root;
    let mut lanes = b.live;
    loop {
        let masks = node_lanes(node, b, &cull, lanes, &mut near);
        push_children(node, b.octant, &masks, &near, stack);
        loop {
            let Some(e) = stack.pop() else {
                return blocked;
            };
            lanes = e.lanes & !blocked;
            if lanes == 0 {
                continue;
            }
            let child = Child(e.child);
            if !child.is_leaf() {
                node = &w.nodes[child.index() as usize];
                break;
            }
            blocked |= leaf_any(leaf_blocks(w, child), b, lanes, t_max);
            if blocked == b.live {
                return blocked;
            }
        }
    }
}

/// [`WideBvh::closest_batch`]'s loop, inlined into each instruction set's copy.
#[inline(always)]
pub(super) fn closest_batch_in(w: &WideBvh, rays: &[Ray], t_max: f32, out: &mut [Best]) {
    let mut stack = Vec::with_capacity(64);
    for (rays, out) in rays.chunks(LANES).zip(out.chunks_mut(LANES)) {
        let b = Bundle::new(rays.iter().map(|r| (*r, t_max)));
        let mut best = Bests {
            t: [t_max; LANES],
            prim: [u32::MAX; LANES],
            u: [0.0; LANES],
            v: [0.0; LANES],
        };
        closest(w, &b, &mut best, &mut stack);
        for (i, o) in out.iter_mut().enumerate() {
            *o = Best {
                t: best.t[i],
                prim: best.prim[i],
                u: best.u[i],
                v: best.v[i],
            };
        }
    }
}

/// [`WideBvh::occluded_batch`]'s loop, inlined into each instruction set's copy.
#[inline(always)]
pub(super) fn occluded_batch_in(w: &WideBvh, rays: &[(Ray, f32)], out: &mut [bool]) {
    let mut stack = Vec::with_capacity(64);
    for (rays, out) in rays.chunks(LANES).zip(out.chunks_mut(LANES)) {
        let b = Bundle::new(rays.iter().copied());
        let mut t_max = [0.0; LANES];
        for (t, (_, r)) in t_max.iter_mut().zip(rays) {
            *t = *r;
        }
        let blocked = occluded(w, &b, &t_max, &mut stack);
        for (i, o) in out.iter_mut().enumerate() {
            *o = blocked >> i & 1 == 1;
        }
    }
}

impl WideBvh {
    /// Whether the batch queries walk bundles: for trees of at most [`MAX_BUNDLE_NODES`] wide
    /// nodes (a room of a few hundred triangles), whose leaves most rays of a bundle enter.
    pub(crate) fn bundles_pay(&self) -> bool {
        self.nodes.len() <= MAX_BUNDLE_NODES
    }

    /// The closest hit of each ray at `0 < t < t_max`, walked as bundles (`out[i]` for
    /// `rays[i]`; `prim` is `u32::MAX` when it hits nothing): each the hit the single-ray walk
    /// finds.
    pub(crate) fn closest_batch(&self, rays: &[Ray], t_max: f32, out: &mut [Best]) {
        assert_eq!(rays.len(), out.len(), "one result per ray");
        super::bundle_x86::closest_batch(self, rays, t_max, out);
    }

    /// Whether anything lies on each ray at `0 < t < t_max` (its own), walked as bundles.
    pub(crate) fn occluded_batch(&self, rays: &[(Ray, f32)], out: &mut [bool]) {
        assert_eq!(rays.len(), out.len(), "one result per ray");
        super::bundle_x86::occluded_batch(self, rays, out);
    }
}
