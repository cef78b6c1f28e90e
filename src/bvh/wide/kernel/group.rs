//! A group of a packet's rays that share an axis permutation against a leaf's triangles, one
//! ray per lane: written once over the lane widths that take groups, eight (AVX2) and sixteen
//! (AVX-512). Each width says in [`RayLanes`] how it fills its lanes from a packet's arrays and
//! how it picks lanes by bits; the triangle test itself is [`floats::triangle_rays`].

use super::floats::{self, Floats};
use crate::bvh::PACKET;
use crate::bvh::wide::packet::{Bests, Group, Rays, Tris, group_exact, perm_of};
use crate::bvh::wide::{BLOCK, TriBlock};

/// The most lanes a width that takes groups has.
pub(crate) const MAX_LANES: usize = 16;

/// Float lanes that hold one ray of a group each: what [`group_blocks`] needs of a width
/// beyond the triangle test's arithmetic.
pub(crate) trait RayLanes: Floats {
    /// Where each lane takes its ray from in the packet, found once per group.
    type Picks;
    /// The picks of `g`'s rays (lanes past the group's end repeat its first ray).
    fn picks(g: &Group) -> Self::Picks;
    /// Lane `j` from the packet array `a` at the `j`-th pick.
    fn gather(a: &[f32; PACKET], p: &Self::Picks) -> Self;
    /// The next float above each lane (infinity stays; the lanes are positive distances,
    /// never NaN), as [`crate::bvh::wide::traverse::next_up`].
    fn next_up(self) -> Self;
    /// `new` in the lanes whose bit is set in `bits`, `self` in the others.
    fn select(self, new: Self, bits: u32) -> Self;
    /// The lanes, in order, into the first lanes of `out`.
    fn store(self, out: &mut [f32; MAX_LANES]);
}

/// Each triangle of `blocks` against the group's rays at once, one ray per lane (lanes past
/// the group's end masked off), the rays' best hits offered to `bests`; lanes the vector test
/// cannot decide go to the scalar test ([`group_exact`]).
#[inline(always)]
pub(crate) fn group_blocks<F: RayLanes>(
    blocks: &[TriBlock],
    r: &Rays,
    tris: &Tris,
    g: &Group,
    bests: &mut Bests,
) {
    let k = perm_of(g.perm);
    let picks = F::picks(g);
    let o = [
        F::gather(&r.origin[k[0]], &picks),
        F::gather(&r.origin[k[1]], &picks),
        F::gather(&r.origin[k[2]], &picks),
    ];
    let shear = [
        F::gather(&tris.shear[0], &picks),
        F::gather(&tris.shear[1], &picks),
        F::gather(&tris.shear[2], &picks),
    ];
    let lanes = ((1u64 << g.n) - 1) as u32;
    let mut out = [[0.0f32; MAX_LANES]; 3];
    // The rays' best distances, kept in a register from triangle to triangle (a hit is never
    // farther than the best it beats or ties), read back from `bests` only after the scalar
    // test decided some lane.
    let mut best = F::gather(&bests.t, &picks);
    for b in blocks {
        for tri in 0..BLOCK {
            if b.prim[tri] == u32::MAX {
                continue;
            }
            // Each ray's limit: the next float above its best distance (ties still count).
            let limit = best.next_up();
            let found = floats::triangle_rays(b, tri, k, &o, &shear, limit, lanes);
            let mut hits = found.hits;
            if let (true, Some([t, u, v])) = (hits != 0, found.tuv) {
                t.store(&mut out[0]);
                u.store(&mut out[1]);
                v.store(&mut out[2]);
                best = best.select(t, hits);
            }
            while hits != 0 {
                let j = hits.trailing_zeros() as usize;
                hits &= hits - 1;
                bests.offer(g.idx[j], out[0][j], b.prim[tri], out[1][j], out[2][j]);
            }
            if found.exact == 0 {
                continue;
            }
            let mut limits = [0.0f32; MAX_LANES];
            limit.store(&mut limits);
            group_exact(b, tri, g, found.exact, &limits, r, tris, bests);
            best = F::gather(&bests.t, &picks);
        }
    }
}
