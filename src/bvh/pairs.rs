//! The traversal layout: for every inner node, the boxes of its two children side by side
//! (structure of arrays), so that one 64-byte load and a dozen SIMD operations test both
//! children at once, with no horizontal reductions.
//!
//! The flat [`BvhNode`] array stays the tree of record (statistics, debug drawing, the visiting
//! traversal); this layout is derived from it after the build.

use glam::{Vec4, Vec4Swizzles};

use super::BvhNode;
use crate::geometry::{PreparedRay, gamma};

/// Both children of one inner node.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(64))]
pub struct PairNode {
    /// `[min.x of child 0, min.x of child 1, max.x of child 0, max.x of child 1]`.
    pub x: [f32; 4],
    /// The same for y.
    pub y: [f32; 4],
    /// The same for z.
    pub z: [f32; 4],
    /// Per child: its pair index (inner child) or its first leaf slot (leaf child).
    pub child: [u32; 2],
    /// Per child: 0 for an inner child, else its triangle count.
    pub count: [u32; 2],
}

/// Derives the pair layout from the node tree. Siblings sit at node indices `2k + 2` and
/// `2k + 3`; their pair is `k`, so the pairs keep the builder's depth-first order and one
/// linear pass makes them. Empty when the root is a leaf.
pub(super) fn pair_layout(nodes: &[BvhNode]) -> Vec<PairNode> {
    if nodes[0].is_leaf() {
        return Vec::new();
    }
    nodes[2..]
        .chunks_exact(2)
        .map(|sib| {
            let mut p = PairNode {
                x: [0.0; 4],
                y: [0.0; 4],
                z: [0.0; 4],
                child: [0; 2],
                count: [0; 2],
            };
            for (k, c) in sib.iter().enumerate() {
                p.x[k] = c.min[0];
                p.x[k + 2] = c.max[0];
                p.y[k] = c.min[1];
                p.y[k + 2] = c.max[1];
                p.z[k] = c.min[2];
                p.z[k + 2] = c.max[2];
                p.count[k] = c.count;
                p.child[k] = if c.is_leaf() {
                    c.first
                } else {
                    c.first / 2 - 1
                };
            }
            p
        })
        .collect()
}

/// A ray spread over SIMD lanes for [`test_pair`].
#[derive(Clone, Copy)]
pub(super) struct RayLanes {
    o: [Vec4; 3],
    inv: [Vec4; 3],
}

/// Far distances are scaled up by this (Ize 2013); one more rounding than the scalar slab
/// test because the scale is folded into the reciprocal, hence `gamma(4)`.
const FAR_SCALE: f32 = if cfg!(feature = "no-conservative-slab") {
    1.0
} else {
    1.0 + 2.0 * gamma(4)
};

impl RayLanes {
    pub(super) fn new(ray: &PreparedRay) -> Self {
        let o = ray.origin.to_array();
        let inv = ray.inv_dir.to_array();
        let lanes = |i: f32| Vec4::new(i, i, -i * FAR_SCALE, -i * FAR_SCALE);
        Self {
            o: o.map(Vec4::splat),
            inv: inv.map(lanes),
        }
    }
}

/// Tests both children of `n` for the ray's octant (`NX`: the x direction is negative, ...).
/// Returns `[near0, near1, -far0, -far1]`: child `k` is hit when `near_k <= far_k`, see
/// [`hits`]. Near distances are clamped to `>= 0`, far distances to `<= limit`.
///
/// Robustness: the near plane is chosen by the direction's sign bit, so `+0` and `-0` agree;
/// a lane is NaN only when the origin lies on the plane of a slab the ray runs parallel to,
/// and `max(NaN, acc)` returns `acc` (SSE `maxps` returns its second operand on NaN, and the
/// scalar fallback ignores NaN), so such a slab constrains nothing, which is exact for a
/// closed box.
#[inline(always)]
pub(super) fn test_pair<const NX: bool, const NY: bool, const NZ: bool>(
    n: &PairNode,
    r: &RayLanes,
    limit: f32,
) -> Vec4 {
    let planes = |a: [f32; 4], neg: bool| {
        let v = Vec4::from_array(a);
        if neg { v.zwxy() } else { v }
    };
    let mut acc = Vec4::new(0.0, 0.0, -limit, -limit);
    acc = ((planes(n.x, NX) - r.o[0]) * r.inv[0]).max(acc);
    acc = ((planes(n.y, NY) - r.o[1]) * r.inv[1]).max(acc);
    acc = ((planes(n.z, NZ) - r.o[2]) * r.inv[2]).max(acc);
    acc
}

/// Bit `k` is set when child `k` is hit.
#[inline(always)]
pub(super) fn hits(acc: Vec4) -> u32 {
    acc.cmple(-acc.zwxy()).bitmask() & 3
}

/// Calls `$f::<NX, NY, NZ>` for the octant of `$neg` (a `BVec3A` of sign bits).
macro_rules! by_octant {
    ($neg:expr, $f:ident, $($arg:expr),*) => {{
        let m = $neg.bitmask();
        match m {
            0 => $f::<false, false, false>($($arg),*),
            1 => $f::<true, false, false>($($arg),*),
            2 => $f::<false, true, false>($($arg),*),
            3 => $f::<true, true, false>($($arg),*),
            4 => $f::<false, false, true>($($arg),*),
            5 => $f::<true, false, true>($($arg),*),
            6 => $f::<false, true, true>($($arg),*),
            _ => $f::<true, true, true>($($arg),*),
        }
    }};
}
pub(super) use by_octant;
