//! The scalar kernel: the box and triangle tests one lane at a time. It is the readable
//! statement of what the SIMD kernels compute, and the fallback on any target.

use super::{BlockHits, Lanes, NodeRay, TriRay};
use crate::bvh::wide::{BLOCK, TriBlock, WIDTH, WideNode};
use crate::geometry::intersect_triangle;

/// Plain Rust, one lane at a time.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Scalar;

/// The box test, lane by lane: bit `k` of the result is set when the ray enters child `k`
/// (its entry distance in `near[k]`).
#[inline(always)]
pub(super) fn node_mask<const SAFE: bool>(
    n: &WideNode,
    r: &NodeRay,
    limit: f32,
    near: &mut [f32; WIDTH],
) -> u32 {
    let mut mask = 0;
    for (k, near) in near.iter_mut().enumerate() {
        let mut t_near = 0.0f32;
        let mut t_far = limit;
        for a in 0..3 {
            let lo = (n.planes[r.near[a]][k] - r.origin[a]) * r.inv[a];
            let hi = (n.planes[r.near[a] ^ 1][k] - r.origin[a]) * r.inv_far[a];
            // NaN only as 0 * inf: that slab constrains nothing.
            let lo = if SAFE && lo.is_nan() {
                f32::NEG_INFINITY
            } else {
                lo
            };
            let hi = if SAFE && hi.is_nan() {
                f32::INFINITY
            } else {
                hi
            };
            t_near = if lo > t_near { lo } else { t_near };
            t_far = if hi < t_far { hi } else { t_far };
        }
        *near = t_near;
        mask |= ((t_near <= t_far) as u32) << k;
    }
    mask
}

impl Lanes for Scalar {
    type NodeRay = NodeRay;
    type TriRay = TriRay;

    #[inline(always)]
    fn node_ray(r: &NodeRay) -> NodeRay {
        *r
    }

    #[inline(always)]
    fn tri_ray(r: &TriRay) -> TriRay {
        *r
    }

    #[inline(always)]
    fn node<const SAFE: bool>(
        n: &WideNode,
        r: &NodeRay,
        limit: f32,
        near: &mut [f32; WIDTH],
    ) -> u32 {
        node_mask::<SAFE>(n, r, limit, near)
    }

    #[inline(always)]
    fn octant(r: &NodeRay) -> u32 {
        r.octant
    }

    #[inline(always)]
    fn block(b: &TriBlock, r: &TriRay, limit: f32) -> BlockHits {
        let mut out = BlockHits {
            hits: 0,
            exact: 0,
            tuv: [[0.0; BLOCK]; 3],
        };
        for k in 0..BLOCK {
            if b.prim[k] == u32::MAX {
                continue;
            }
            if let Some(h) = intersect_triangle(&r.ray, &b.triangle(k), limit) {
                (out.tuv[0][k], out.tuv[1][k], out.tuv[2][k]) = (h.t, h.u, h.v);
                out.hits |= 1 << k;
            }
        }
        out
    }

    type Pair = [[f32; 2 * BLOCK]; 3];

    #[inline(always)]
    fn block_pair(a: &TriBlock, b: &TriBlock, r: &TriRay, limit: f32) -> BlockHits<Self::Pair> {
        super::pair_of_blocks::<Self>(a, b, r, limit)
    }
}
