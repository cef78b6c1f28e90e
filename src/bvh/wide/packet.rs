//! Coherent rays in packets: the closest hits of up to [`PACKET`] rays (a tile of camera
//! rays) found in one walk of the tree, or whether anything lies on each (any hit).
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

use glam::{Vec3A, Vec4};

use super::kernel::stack::SmallStack;
use super::kernel::{FAR_SCALE, Lanes, TriRay};
use super::traverse::{Best, CULL_SLACK, leaf_closest};
use super::{Child, TriBlock, WIDTH, WideBvh, WideNode};
use crate::bvh::tile::{PACKET, RayTile};
use crate::geometry::PreparedRay;

/// The packet's rays, component by component.
pub(crate) struct Rays {
    pub n: usize,
    pub origin: [[f32; PACKET]; 3],
    pub dir: [[f32; PACKET]; 3],
    pub inv: [[f32; PACKET]; 3],
    pub inv_far: [[f32; PACKET]; 3],
    /// Per axis, the near plane's index in [`WideNode::planes`] (the same for every ray).
    pub near: [usize; 3],
    octant: u32,
    /// Interval bounds over the rays: origins and reciprocals (and far reciprocals).
    o_lo: [f32; 3],
    o_hi: [f32; 3],
    inv_lo: [f32; 3],
    inv_hi: [f32; 3],
    far_lo: [f32; 3],
    far_hi: [f32; 3],
}

/// The packet's triangle-test constants per ray, made for every ray at once when the first
/// leaf is reached (most tiles never reach one).
pub(crate) struct Tris {
    /// The constants are made.
    made: bool,
    /// Per ray, the axis permutation `[kx, ky, kz]` as one number (`kx * 9 + ky * 3 + kz`).
    pub perm: [u8; PACKET],
    /// Per ray, the shear constants `[sx, sy, sz]`.
    pub shear: [[f32; PACKET]; 3],
}

impl Tris {
    /// Constants not made yet.
    #[inline(always)]
    fn new() -> Tris {
        Tris {
            made: false,
            perm: [0; PACKET],
            shear: [[0.0; PACKET]; 3],
        }
    }

    /// Makes every ray's constants, as [`PreparedRay::new`] makes them, unless made: the
    /// choices of axes as selects rather than branches, over whole arrays of [`PACKET`] lanes
    /// (eight or sixteen rays per instruction in the SIMD kernels this is inlined into).
    #[inline(always)]
    // One lane index reads and writes nine arrays: clearer than zipping them.
    #[allow(clippy::needless_range_loop)]
    fn make(&mut self, r: &Rays) {
        if self.made {
            return;
        }
        self.made = true;
        let dir = &r.dir;
        for i in 0..PACKET {
            let (dx, dy, dz) = (dir[0][i], dir[1][i], dir[2][i]);
            let (ax, ay, az) = (dx.abs(), dy.abs(), dz.abs());
            // `kz`: the axis where `|dir|` is largest (the first of equals).
            let x = (ax >= ay) & (ax >= az);
            let y = !x & (ay >= az);
            // The direction along `kz`, its reciprocal (as computed for the packet), and the
            // components along `kz + 1` and `kz + 2`.
            let (kz, dkz, sz, next, after) = if x {
                (0u8, dx, r.inv[0][i], dy, dz)
            } else if y {
                (1, dy, r.inv[1][i], dz, dx)
            } else {
                (2, dz, r.inv[2][i], dx, dy)
            };
            // A negative direction along `kz` swaps `kx` and `ky` (keeping the winding).
            let neg = dkz < 0.0;
            let (dkx, dky) = if neg { (after, next) } else { (next, after) };
            let kx = (kz + 1 + neg as u8) % 3;
            let ky = (kz + 2 - neg as u8) % 3;
            self.perm[i] = kx * 9 + ky * 3 + kz;
            self.shear[0][i] = dkx * sz;
            self.shear[1][i] = dky * sz;
            self.shear[2][i] = sz;
        }
    }
}

/// The best hits of a packet's rays, component by component (see [`Best`]).
pub(crate) struct Bests {
    pub t: [f32; PACKET],
    pub prim: [u32; PACKET],
    pub u: [f32; PACKET],
    pub v: [f32; PACKET],
}

impl Bests {
    /// Ray `i`'s best hit.
    #[inline(always)]
    pub fn best(&self, i: usize) -> Best {
        Best {
            t: self.t[i],
            prim: self.prim[i],
            u: self.u[i],
            v: self.v[i],
        }
    }

    /// No hit yet for any ray: every distance `t_max`.
    #[inline(always)]
    pub fn none(t_max: f32) -> Self {
        Bests {
            t: [t_max; PACKET],
            prim: [u32::MAX; PACKET],
            u: [0.0; PACKET],
            v: [0.0; PACKET],
        }
    }

    /// Keeps ray `i`'s hit `(t, prim)` when it is closer, or as close with a lower index.
    #[inline(always)]
    pub fn offer(&mut self, i: usize, t: f32, prim: u32, u: f32, v: f32) {
        if t < self.t[i] || (t == self.t[i] && prim < self.prim[i]) {
            (self.t[i], self.prim[i], self.u[i], self.v[i]) = (t, prim, u, v);
        }
    }
}

/// The `[kx, ky, kz]` of a permutation number.
#[inline(always)]
pub(crate) fn perm_of(id: u8) -> [usize; 3] {
    let id = id as usize;
    [id / 9, id / 3 % 3, id % 3]
}

impl Rays {
    /// A packet of `n` rays in `octant` with every array and bound zero, to be filled in.
    #[inline(always)]
    fn zeroed(n: usize, octant: u32) -> Rays {
        Rays {
            n,
            origin: [[0.0; PACKET]; 3],
            dir: [[0.0; PACKET]; 3],
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
        }
    }

    /// Fills the packet (made by [`Rays::zeroed`] with the tile's length and its first ray's
    /// octant) with the tile's rays; `false` when they do not share an octant, some reciprocal
    /// is infinite, or some ray is not valid (a non-finite origin or direction).
    ///
    /// The rays are copied component by component first (by the kernel's
    /// [`Lanes::load_rays`] where it has one); every other step then runs over whole arrays of
    /// [`PACKET`] lanes with no branch (eight or sixteen lanes per instruction in the SIMD
    /// kernels this is inlined into). Lanes past the packet's end repeat its first ray, which
    /// changes no bound.
    ///
    /// Filled in place in the caller's frame: returned by value (in an `Option`), the 3 KB
    /// packet was copied by a `memcpy` call per packet, behind a `vzeroupper`.
    #[inline(always)]
    fn fill<L: Lanes>(&mut self, tile: &RayTile) -> bool {
        let r = self;
        let n = tile.len();
        let first = tile.rays[0];
        let octant = r.octant;
        let loaded = tile
            .rows_of_eight()
            .is_some_and(|(rays, stride)| L::load_rays(rays, stride, &mut r.origin, &mut r.dir));
        if !loaded {
            tile.for_each(|i, at| {
                let ray = &tile.rays[at];
                for a in 0..3 {
                    r.origin[a][i] = ray.origin[a];
                    r.dir[a][i] = ray.dir[a];
                }
            });
        }
        for i in n..PACKET {
            for a in 0..3 {
                r.origin[a][i] = first.origin[a];
                r.dir[a][i] = first.dir[a];
            }
        }
        let mut bad = false;
        for a in 0..3 {
            // Any lane with a non-finite component or a direction sign off the octant's.
            let sign = (octant >> a & 1) << 31;
            let mut off = 0u32;
            for (&o, &d) in r.origin[a].iter().zip(&r.dir[a]) {
                let (o, d) = (o.to_bits(), d.to_bits());
                let inf = 0x7f80_0000;
                off |= ((o & inf == inf) | (d & inf == inf) | (d & 1 << 31 != sign)) as u32;
            }
            bad |= off != 0;
            // A zero or tiny component has an infinite reciprocal, caught below.
            for ((inv, far), &d) in r.inv[a].iter_mut().zip(&mut r.inv_far[a]).zip(&r.dir[a]) {
                *inv = 1.0 / d;
                *far = *inv * FAR_SCALE;
            }
            (r.o_lo[a], r.o_hi[a]) = lane_range(&r.origin[a]);
            (r.inv_lo[a], r.inv_hi[a]) = lane_range(&r.inv[a]);
            // Rounding is monotonic, so the far reciprocals' range is the range's product.
            (r.far_lo[a], r.far_hi[a]) = (r.inv_lo[a] * FAR_SCALE, r.inv_hi[a] * FAR_SCALE);
            // An infinite reciprocal could meet 0 * inf.
            bad |= !(r.inv_lo[a].is_finite() && r.inv_hi[a].is_finite());
        }
        !bad
    }
}

/// The smallest and largest of a packet array's lanes (which are not NaN), four lanes per
/// instruction (see [`largest`]).
#[inline(always)]
fn lane_range(x: &[f32; PACKET]) -> (f32, f32) {
    let mut lo = Vec4::INFINITY;
    let mut hi = Vec4::NEG_INFINITY;
    for c in x.chunks_exact(4) {
        let v = Vec4::from_slice(c);
        (lo, hi) = (lo.min(v), hi.max(v));
    }
    (lo.min_element(), hi.max_element())
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

/// The rays (bit per ray) that enter the box of lane `lane` of `n` before their own `limit`,
/// each with its own box test (the single ray's operations). This is the readable version;
/// the AVX2 kernel tests eight rays per instruction ([`super::kernel::Lanes::rays_entering`]).
#[inline(always)]
pub(crate) fn rays_entering_scalar(
    n: &WideNode,
    lane: usize,
    r: &Rays,
    limit: &[f32; PACKET],
) -> u64 {
    let mut mask = 0u64;
    for (i, &limit) in limit.iter().enumerate().take(r.n) {
        let mut t_near = 0.0f32;
        let mut t_far = limit;
        for a in 0..3 {
            let lo = (n.planes[r.near[a]][lane] - r.origin[a][i]) * r.inv[a][i];
            let hi = (n.planes[r.near[a] ^ 1][lane] - r.origin[a][i]) * r.inv_far[a][i];
            t_near = if lo > t_near { lo } else { t_near };
            t_far = if hi < t_far { hi } else { t_far };
        }
        mask |= ((t_near <= t_far) as u64) << i;
    }
    mask
}

/// The largest of the 64 limits (which are never NaN) and zero, four lanes per instruction
/// (more where the kernel's instruction set has wider ones: the compiler joins them; a loop
/// over eight scalar maxima was compiled as scalar instructions).
#[inline(always)]
fn largest(limit: &[f32; PACKET]) -> f32 {
    let mut m = Vec4::ZERO;
    for c in limit.chunks_exact(4) {
        m = m.max(Vec4::from_slice(c));
    }
    m.max_element()
}

/// Closest hits of the tile's rays at `0 < t < t_max`, into `bests` (lane `i` for the
/// packet's ray `i`, see [`RayTile`]; `bests` starts as [`Bests::none`]), or `false` when the
/// packet cannot be traced together (see the module docs) and nothing was written. With
/// `ANY`, a ray stops at its first hit before `t_max` (shadow rays): `bests.t[i] < t_max`
/// exactly when something lies on ray `i`, the hit itself being any one of them.
#[inline(always)]
pub(crate) fn trace_packet<L: Lanes, const ANY: bool>(
    w: &WideBvh,
    tile: &RayTile,
    t_max: f32,
    bests: &mut Bests,
) -> bool {
    let octant = Vec3A::from(tile.rays[0].dir).is_negative_bitmask();
    let mut r = Rays::zeroed(tile.len(), octant);
    if !r.fill::<L>(tile) {
        return false;
    }
    let mut tris = Tris::new();
    if w.nodes.is_empty() {
        if let Some((first, count)) = w.root_leaf {
            let all = u64::MAX >> (64 - r.n);
            tris.make(&r);
            leaf_rays::<L>(w, first, count, &r, &tris, all, bests);
        }
    } else {
        walk::<L, ANY>(w, &r, &mut tris, t_max, bests);
    }
    true
}

/// The closest hits of up to [`PACKET`] rays of any directions (the rays in `active`, bit per
/// ray of `rays`), into `bests` (lane `i` for ray `i`; each lane's distance starts at the ray's
/// own limit), when the layout is one root leaf: with no node to walk, the rays need not share
/// an octant, and they are grouped by axis permutation, each group tested against every
/// triangle at once ([`leaf_rays`]), as a packet's rays are at a leaf. Every ray gets exactly
/// the hit it gets alone. Does nothing for a layout with nodes.
#[inline(always)]
pub(crate) fn root_leaf_rays<L: Lanes>(
    w: &WideBvh,
    rays: &[crate::geometry::Ray],
    active: u64,
    bests: &mut Bests,
) {
    let (Some((first, count)), true) = (w.root_leaf, w.nodes.is_empty()) else {
        return;
    };
    debug_assert!(rays.len() <= PACKET && active >> rays.len().min(63) <= 1);
    let mut r = Rays::zeroed(rays.len(), 0);
    // Lanes past the list's end repeat its first ray (their results are never read).
    for i in 0..PACKET {
        let ray = rays.get(i).unwrap_or(&rays[0]);
        for a in 0..3 {
            r.origin[a][i] = ray.origin[a];
            r.dir[a][i] = ray.dir[a];
            r.inv[a][i] = 1.0 / ray.dir[a];
        }
    }
    let mut tris = Tris::new();
    tris.make(&r);
    leaf_rays::<L>(w, first, count, &r, &tris, active, bests);
}

/// The packet's walk of the tree (see the module docs); with `ANY`, rays leave at their
/// first hit before `t_max` and the walk ends when every ray has.
#[inline(always)]
fn walk<L: Lanes, const ANY: bool>(
    w: &WideBvh,
    r: &Rays,
    tris: &mut Tris,
    t_max: f32,
    bests: &mut Bests,
) {
    // The largest of the rays' culling distances: boxes starting beyond it are skipped.
    let mut farthest = t_max * CULL_SLACK;
    // Each ray's culling distance, `best.t * CULL_SLACK` (past the packet's end: -1, so no
    // lane there ever enters a box).
    let mut limit = [-1.0f32; PACKET];
    for l in &mut limit[..r.n] {
        *l = t_max * CULL_SLACK;
    }
    // Entries: (child word, smallest entry distance, parent node * 8 + lane). At most seven
    // pending siblings per level of the current path.
    let mut stack =
        SmallStack::<(u32, f32, u32), { (WIDTH - 1) * crate::bvh::MAX_DEPTH + 1 }>::new();
    stack.push((Child::inner(0).0, 0.0, 0));
    let mut near = [0.0f32; WIDTH];
    // Rays that found a hit (any-hit only): their limit is -1, so they enter no more boxes.
    let all = u64::MAX >> (PACKET - r.n);
    let mut done = 0u64;
    while let Some((word, dist, at)) = stack.pop() {
        let (parent, lane) = (at / WIDTH as u32, at % WIDTH as u32);
        if dist > farthest {
            continue;
        }
        let child = Child(word);
        if child.is_leaf() {
            let n = &w.nodes[parent as usize];
            let active = L::rays_entering(n, lane as usize, r, &limit);
            if active == 0 {
                continue;
            }
            let (first, count) = child.blocks();
            tris.make(r);
            leaf_rays::<L>(w, first, count, r, tris, active, bests);
            let mut m = active;
            while m != 0 {
                let i = m.trailing_zeros() as usize;
                m &= m - 1;
                if ANY && bests.t[i] < t_max {
                    limit[i] = -1.0;
                    done |= 1 << i;
                } else {
                    limit[i] = bests.t[i] * CULL_SLACK;
                }
            }
            if ANY && done == all {
                return;
            }
            farthest = largest(&limit);
            continue;
        }
        let index = child.index();
        let n = &w.nodes[index as usize];
        let mask = node_interval(n, r, farthest, &mut near);
        // Farthest first, so the nearest is popped next.
        for i in 0..WIDTH {
            let k = n.lane_in_order(r.octant, i);
            if mask >> k & 1 == 1 {
                stack.push((n.child[k], near[k], index * WIDTH as u32 + k as u32));
            }
        }
    }
}

/// Up to sixteen of a packet's rays that share one axis permutation, to be tested together.
pub(crate) struct Group {
    /// The rays' indices in the packet (the first `n` are used; the others repeat the first).
    pub idx: [usize; 16],
    pub n: usize,
    /// Their permutation number (see [`Tris::perm`]).
    pub perm: u8,
}

impl Group {
    /// Takes from `todo` the first ray and up to `max - 1` more with its permutation
    /// (`max <= 16`).
    #[inline(always)]
    fn take(todo: &mut u64, tris: &Tris, max: usize) -> Group {
        let first = todo.trailing_zeros() as usize;
        let perm = tris.perm[first];
        let mut g = Group {
            idx: [first; 16],
            n: 0,
            perm,
        };
        let mut m = *todo;
        while m != 0 && g.n < max.min(16) {
            let i = m.trailing_zeros() as usize;
            m &= m - 1;
            if tris.perm[i] == perm {
                g.idx[g.n] = i;
                g.n += 1;
                *todo &= !(1u64 << i);
            }
        }
        g
    }
}

/// The rays in `active` (bit per ray) against a leaf's blocks: in groups of up to
/// [`Lanes::GROUP_MAX`] rays (eight, sixteen with AVX-512) that share an axis permutation, gathered from wherever they sit in the tile (a leaf is
/// entered by a few rays scattered over the tile's rows), each group tested together when the
/// kernel can and it is large enough, else ray by ray.
#[inline(always)]
fn leaf_rays<L: Lanes>(
    w: &WideBvh,
    first: u32,
    count: u32,
    r: &Rays,
    tris: &Tris,
    active: u64,
    bests: &mut Bests,
) {
    let blocks = &w.blocks[first as usize..(first + count) as usize];
    let mut todo = active;
    while todo != 0 {
        let g = Group::take(&mut todo, tris, L::GROUP_MAX);
        if g.n >= L::RAYS_TOGETHER {
            L::group_blocks(blocks, r, tris, &g, bests);
        } else {
            for &i in &g.idx[..g.n] {
                ray_blocks::<L>(blocks, r, tris, i, bests);
            }
        }
    }
}

/// Ray `i` of the packet against `blocks` with the single-ray block test.
#[inline(always)]
pub(crate) fn ray_blocks<L: Lanes>(
    blocks: &[TriBlock],
    r: &Rays,
    tris: &Tris,
    i: usize,
    bests: &mut Bests,
) {
    let tr = TriRay::new(&prepared(r, tris, i));
    let mut best = Best {
        t: bests.t[i],
        prim: bests.prim[i],
        u: bests.u[i],
        v: bests.v[i],
    };
    leaf_closest::<L>(blocks, &tr, &L::tri_ray(&tr), &mut best);
    (bests.t[i], bests.prim[i], bests.u[i], bests.v[i]) = (best.t, best.prim, best.u, best.v);
}

/// Ray `i` of the packet as the triangle test takes it (the box test's parts left neutral).
#[inline(always)]
fn prepared(r: &Rays, tris: &Tris, i: usize) -> PreparedRay {
    PreparedRay::from_parts(
        Vec3A::new(r.origin[0][i], r.origin[1][i], r.origin[2][i]),
        perm_of(tris.perm[i]),
        [tris.shear[0][i], tris.shear[1][i], tris.shear[2][i]],
    )
}

/// The lanes in `exact` (bits of group `g`) against triangle `tri` of `b` with the scalar test
/// (its f64 path and tie rule), each below its own `limit`: what the group tests of the SIMD
/// kernels hand over where an edge function was exactly zero or the distance overflowed.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn group_exact(
    b: &TriBlock,
    tri: usize,
    g: &Group,
    mut exact: u32,
    limit: &[f32],
    r: &Rays,
    tris: &Tris,
    bests: &mut Bests,
) {
    while exact != 0 {
        let j = exact.trailing_zeros() as usize;
        exact &= exact - 1;
        let i = g.idx[j];
        let ray = prepared(r, tris, i);
        if let Some(h) = crate::geometry::intersect_triangle(&ray, &b.triangle(tri), limit[j]) {
            bests.offer(i, h.t, b.prim[tri], h.u, h.v);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Ray;
    use glam::Vec3;

    /// The packet's triangle-test constants are, lane by lane, the single ray's: the same axes
    /// (ties between equal components, negative zeros and negative directions included) and
    /// the same shear bits.
    #[test]
    fn the_packets_triangle_constants_are_the_single_rays() {
        let values = [1.0f32, -1.0, 0.5, -0.5, 2.0, -2.0, 0.0, -0.0, 1e-3, -3.0];
        let mut dirs = Vec::new();
        for &x in &values {
            for &y in &values {
                for &z in &values {
                    if x != 0.0 || y != 0.0 || z != 0.0 {
                        dirs.push(Vec3::new(x, y, z));
                    }
                }
            }
        }
        for (p, d) in dirs.iter().enumerate() {
            let rays: Vec<Ray> = (0..PACKET)
                .map(|i| Ray::new(Vec3::new(i as f32, 0.5, -2.0), *d))
                .collect();
            // Zero components have infinite reciprocals, which `Rays::fill` refuses: the
            // constants are made from the reciprocals directly then.
            let mut r = Rays::zeroed(PACKET, 0);
            for (i, ray) in rays.iter().enumerate() {
                for a in 0..3 {
                    r.dir[a][i] = ray.dir[a];
                    r.inv[a][i] = 1.0 / ray.dir[a];
                }
            }
            let mut tris = Tris::new();
            tris.make(&r);
            let single = PreparedRay::new(&rays[p % PACKET]);
            let i = p % PACKET;
            assert_eq!(perm_of(tris.perm[i]), single.k, "direction {d}");
            for a in 0..3 {
                assert_eq!(
                    tris.shear[a][i].to_bits(),
                    single.shear[a].to_bits(),
                    "direction {d}, shear {a}"
                );
            }
        }
    }
}
