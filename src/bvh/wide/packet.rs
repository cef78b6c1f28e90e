//! Coherent rays in packets: the closest hits of up to [`PACKET`] rays (a tile of camera
//! rays) found in one walk of the tree.
//!
//! The walk tests each node's eight child boxes once for the whole packet, with interval
//! arithmetic over the packet's origins and reciprocal directions: a child is entered when
//! some ray of the packet might enter it before the farthest best hit so far. Products of
//! rounded values are monotonic in each factor, so the interval's near distance is never above
//! any ray's own computed near distance, nor its far distance below: the packet enters every box
//! any of its rays would. At a leaf each ray first tests the leaf's box on its own (eight rays
//! at a time) against its own best hit, and only the rays that enter test the triangles, with
//! the same kernel and the same tie rule as single rays: every ray gets exactly the hit it
//! would get alone (tests check).
//!
//! Packets need every ray in the same direction octant (so one child order and one near plane
//! per axis serve all) and finite reciprocals; any other packet is traced ray by ray.

use super::kernel::stack::SmallStack;
use super::kernel::{BlockHits, FAR_SCALE, Lanes, TriRay};
use super::traverse::{Best, CULL_SLACK};
use super::{Child, WIDTH, WideBvh, WideNode};
use crate::geometry::{PreparedRay, Ray, intersect_triangle};

/// Rays per packet: an 8 x 8 tile.
pub const PACKET: usize = 64;

/// The packet's rays, component by component.
struct Rays {
    n: usize,
    origin: [[f32; PACKET]; 3],
    inv: [[f32; PACKET]; 3],
    inv_far: [[f32; PACKET]; 3],
    /// Per axis, the near plane's index in [`WideNode::planes`] (the same for every ray).
    near: [usize; 3],
    octant: u32,
    /// Interval bounds over the rays: origins and reciprocals (and far reciprocals).
    o_lo: [f32; 3],
    o_hi: [f32; 3],
    inv_lo: [f32; 3],
    inv_hi: [f32; 3],
    far_lo: [f32; 3],
    far_hi: [f32; 3],
}

impl Rays {
    /// The packet, or `None` when its rays do not share an octant or some reciprocal is
    /// infinite.
    #[inline(always)]
    fn new(rays: &[Ray]) -> Option<Rays> {
        use glam::Vec3A;
        let n = rays.len();
        let octant = Vec3A::from(rays.first()?.dir).is_negative_bitmask();
        let mut r = Rays {
            n,
            origin: [[0.0; PACKET]; 3],
            inv: [[0.0; PACKET]; 3],
            inv_far: [[0.0; PACKET]; 3],
            near: std::array::from_fn(|a| 2 * a + ((octant >> a) & 1) as usize),
            octant,
            o_lo: [0.0; 3],
            o_hi: [0.0; 3],
            inv_lo: [0.0; 3],
            inv_hi: [0.0; 3],
            far_lo: [0.0; 3],
            far_hi: [0.0; 3],
        };
        let (mut o_lo, mut o_hi) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
        let (mut i_lo, mut i_hi) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
        let mut same = true;
        for (i, ray) in rays.iter().enumerate() {
            let (o, d) = (Vec3A::from(ray.origin), Vec3A::from(ray.dir));
            same &= d.is_negative_bitmask() == octant;
            let inv = Vec3A::ONE / d;
            (o_lo, o_hi) = (o_lo.min(o), o_hi.max(o));
            (i_lo, i_hi) = (i_lo.min(inv), i_hi.max(inv));
            let far = inv * FAR_SCALE;
            for a in 0..3 {
                r.origin[a][i] = o[a];
                r.inv[a][i] = inv[a];
                r.inv_far[a][i] = far[a];
            }
        }
        // A zero or tiny component (infinite reciprocal) could meet 0 * inf.
        if !same || !i_lo.is_finite() || !i_hi.is_finite() {
            return None;
        }
        // Rounding is monotonic, so the far reciprocals' range is the range's product.
        (r.o_lo, r.o_hi) = (o_lo.to_array(), o_hi.to_array());
        (r.inv_lo, r.inv_hi) = (i_lo.to_array(), i_hi.to_array());
        let (f_lo, f_hi) = (i_lo * FAR_SCALE, i_hi * FAR_SCALE);
        (r.far_lo, r.far_hi) = (f_lo.to_array(), f_hi.to_array());
        Some(r)
    }
}

/// The smallest and largest of the four products of `[d_lo, d_hi] x [i_lo, i_hi]`.
#[inline(always)]
fn product_range(d_lo: f32, d_hi: f32, i_lo: f32, i_hi: f32) -> (f32, f32) {
    let (a, b, c, d) = (d_lo * i_lo, d_lo * i_hi, d_hi * i_lo, d_hi * i_hi);
    (a.min(b).min(c.min(d)), a.max(b).max(c.max(d)))
}

/// The children of `n` some ray of the packet may enter before `limit`, and for each the
/// smallest entry distance any ray may have.
#[inline(always)]
fn node_interval(n: &WideNode, r: &Rays, limit: f32, near: &mut [f32; WIDTH]) -> u32 {
    let mut t_near = [0.0f32; WIDTH];
    let mut t_far = [limit; WIDTH];
    for a in 0..3 {
        let (pn, pf) = (&n.planes[r.near[a]], &n.planes[r.near[a] ^ 1]);
        for k in 0..WIDTH {
            let (lo, _) = product_range(
                pn[k] - r.o_hi[a],
                pn[k] - r.o_lo[a],
                r.inv_lo[a],
                r.inv_hi[a],
            );
            let (_, hi) = product_range(
                pf[k] - r.o_hi[a],
                pf[k] - r.o_lo[a],
                r.far_lo[a],
                r.far_hi[a],
            );
            t_near[k] = t_near[k].max(lo);
            t_far[k] = t_far[k].min(hi);
        }
    }
    let mut mask = 0;
    for k in 0..WIDTH {
        near[k] = t_near[k];
        mask |= ((t_near[k] <= t_far[k]) as u32) << k;
    }
    mask
}

/// The rays (bit per ray) that enter the box of lane `lane` of `n` before their own best hit.
#[inline(always)]
fn rays_entering(n: &WideNode, lane: usize, r: &Rays, limit: &[f32; PACKET]) -> u64 {
    let pn: [f32; 3] = std::array::from_fn(|a| n.planes[r.near[a]][lane]);
    let pf: [f32; 3] = std::array::from_fn(|a| n.planes[r.near[a] ^ 1][lane]);
    // Eight rays at a time on plain arrays: the compiler turns each chunk into SIMD.
    let mut mask = 0u64;
    for c in 0..r.n.div_ceil(8) {
        let mut t_near = [0.0f32; 8];
        let mut t_far = [0.0f32; 8];
        for j in 0..8 {
            t_far[j] = limit[8 * c + j];
        }
        for a in 0..3 {
            for j in 0..8 {
                let i = 8 * c + j;
                let lo = (pn[a] - r.origin[a][i]) * r.inv[a][i];
                let hi = (pf[a] - r.origin[a][i]) * r.inv_far[a][i];
                t_near[j] = if lo > t_near[j] { lo } else { t_near[j] };
                t_far[j] = if hi < t_far[j] { hi } else { t_far[j] };
            }
        }
        let mut m = 0u64;
        for j in 0..8 {
            m |= ((t_near[j] <= t_far[j]) as u64) << j;
        }
        mask |= m << (8 * c);
    }
    // Lanes past the packet's end hold zeros; they are never asked for.
    mask & (u64::MAX >> (64 - r.n))
}

/// Closest hits of `rays` (at most [`PACKET`], all valid) at `0 < t < t_max`, into `best`
/// (one per ray), or `false` when the packet cannot be traced together (see the module docs)
/// and nothing was written.
#[inline(always)]
pub(crate) fn closest_packet<L: Lanes>(
    w: &WideBvh,
    rays: &[Ray],
    t_max: f32,
    best: &mut [Best],
) -> bool {
    debug_assert!(rays.len() <= PACKET && best.len() == rays.len());
    let Some(r) = Rays::new(rays) else {
        return false;
    };
    best.fill(Best::none(t_max));
    // Each ray's triangle-test constants, made the first time the ray reaches a leaf.
    let mut tri: [Option<(TriRay, L::TriRay)>; PACKET] = [None; PACKET];
    if w.nodes.is_empty() {
        if let Some((first, count)) = w.root_leaf {
            for (i, b) in best.iter_mut().enumerate() {
                leaf_for::<L>(w, &rays[i], &mut tri[i], first, count, b);
            }
        }
        return true;
    }
    // The largest of the rays' culling distances: boxes starting beyond it are skipped.
    let mut farthest = t_max * CULL_SLACK;
    // Each ray's culling distance, `best.t * CULL_SLACK` (past the packet's end: -1, so no
    // lane there ever enters a box).
    let mut limit = [-1.0f32; PACKET];
    for (l, b) in limit.iter_mut().zip(best.iter()) {
        *l = b.t * CULL_SLACK;
    }
    // Entries: (child word, smallest entry distance, parent node * 8 + lane). At most seven
    // pending siblings per level of the current path.
    let mut stack =
        SmallStack::<(u32, f32, u32), { (WIDTH - 1) * crate::bvh::MAX_DEPTH + 1 }>::new();
    stack.push((Child::inner(0).0, 0.0, 0));
    let mut near = [0.0f32; WIDTH];
    while let Some((word, dist, at)) = stack.pop() {
        let (parent, lane) = (at / WIDTH as u32, at % WIDTH as u32);
        if dist > farthest {
            continue;
        }
        let child = Child(word);
        if child.is_leaf() {
            let n = &w.nodes[parent as usize];
            let mut active = rays_entering(n, lane as usize, &r, &limit);
            if active == 0 {
                continue;
            }
            let (first, count) = child.blocks();
            while active != 0 {
                let i = active.trailing_zeros() as usize;
                active &= active - 1;
                leaf_for::<L>(w, &rays[i], &mut tri[i], first, count, &mut best[i]);
                limit[i] = best[i].t * CULL_SLACK;
            }
            farthest = limit.iter().fold(0.0f32, |m, &l| m.max(l));
            continue;
        }
        let index = child.index();
        let n = &w.nodes[index as usize];
        let mask = node_interval(n, &r, farthest, &mut near);
        // Farthest first, so the nearest is popped next.
        for i in 0..WIDTH {
            let k = n.lane_in_order(r.octant, i);
            if mask >> k & 1 == 1 {
                stack.push((n.child[k], near[k], index * WIDTH as u32 + k as u32));
            }
        }
    }
    true
}

/// Ray `ray` against a leaf, its triangle-test constants made on first use into `tri`.
#[inline(always)]
fn leaf_for<L: Lanes>(
    w: &WideBvh,
    ray: &Ray,
    tri: &mut Option<(TriRay, L::TriRay)>,
    first: u32,
    count: u32,
    best: &mut Best,
) {
    if tri.is_none() {
        let tr = TriRay::new(&PreparedRay::new(ray));
        *tri = Some((tr, L::tri_ray(&tr)));
    }
    if let Some((tr, lr)) = tri {
        leaf::<L>(w, first, count, tr, lr, best);
    }
}

/// One ray against a leaf's blocks, keeping its closest hit (lowest index on ties).
#[inline(always)]
fn leaf<L: Lanes>(
    w: &WideBvh,
    first: u32,
    count: u32,
    tr: &TriRay,
    lr: &L::TriRay,
    best: &mut Best,
) {
    let mut out = BlockHits::default();
    for b in first..first + count {
        let block = &w.blocks[b as usize];
        let limit = f32::from_bits(best.t.to_bits() + (best.t < f32::INFINITY) as u32);
        let (mut hits, mut exact) = L::block(block, lr, limit, &mut out);
        while hits != 0 {
            let k = hits.trailing_zeros() as usize;
            hits &= hits - 1;
            best.offer(out.t[k], block.prim[k], out.u[k], out.v[k]);
        }
        while exact != 0 {
            let k = exact.trailing_zeros() as usize;
            exact &= exact - 1;
            if let Some(h) = intersect_triangle(&tr.ray, &block.triangle(k), limit) {
                best.offer(h.t, block.prim[k], h.u, h.v);
            }
        }
    }
}
