//! The SSE2 kernel (every x86-64 CPU): each node's eight boxes as two 4-wide halves, the
//! triangles four at a time ([`super::x86::block_sse`]).
#![allow(
    unsafe_code,
    reason = "SIMD intrinsics on registers and on a node's rows"
)]

use std::arch::x86_64::*;

use super::x86::{TriRay4, block_sse, tri_ray4};
use super::{BlockHits, Lanes, NodeRay, TriRay};
use crate::bvh::wide::{BLOCK, TriBlock, WIDTH, WideNode};

/// SSE2: each node as two 4-wide halves.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Sse2;

/// The box test's ray data, broadcast to 4 lanes.
#[derive(Clone, Copy)]
pub(crate) struct NodeRay4 {
    origin: [__m128; 3],
    inv: [__m128; 3],
    inv_far: [__m128; 3],
    near: [usize; 3],
    octant: u32,
}

/// `x` with its NaN lanes replaced by `fill` (SSE2 has no blend: and / andnot / or).
#[inline(always)]
fn fix_nan4(x: __m128, fill: f32) -> __m128 {
    // SAFETY: SSE2 baseline operations on registers.
    unsafe {
        let nan = _mm_cmpunord_ps(x, x);
        _mm_or_ps(_mm_and_ps(nan, _mm_set1_ps(fill)), _mm_andnot_ps(nan, x))
    }
}

impl Lanes for Sse2 {
    type NodeRay = NodeRay4;
    type TriRay = TriRay4;

    #[inline(always)]
    fn node_ray(r: &NodeRay) -> NodeRay4 {
        // SAFETY: SSE baseline.
        let s = |x: f32| unsafe { _mm_set1_ps(x) };
        NodeRay4 {
            origin: r.origin.map(s),
            inv: r.inv.map(s),
            inv_far: r.inv_far.map(s),
            near: r.near,
            octant: r.octant,
        }
    }

    #[inline(always)]
    fn tri_ray(r: &TriRay) -> TriRay4 {
        tri_ray4(r)
    }

    #[inline(always)]
    fn node<const SAFE: bool>(
        n: &WideNode,
        r: &NodeRay4,
        limit: f32,
        near: &mut [f32; WIDTH],
    ) -> u32 {
        let mut mask = 0;
        for half in 0..2 {
            // SAFETY: SSE baseline; loads read 4 of the 8 floats of a plane row, the store
            // writes 4 of the 8 floats of `near`.
            unsafe {
                let mut t_near = _mm_setzero_ps();
                let mut t_far = _mm_set1_ps(limit);
                for a in 0..3 {
                    let lo = _mm_loadu_ps(n.planes[r.near[a]][4 * half..].as_ptr());
                    let hi = _mm_loadu_ps(n.planes[r.near[a] ^ 1][4 * half..].as_ptr());
                    let mut lo = _mm_mul_ps(_mm_sub_ps(lo, r.origin[a]), r.inv[a]);
                    let mut hi = _mm_mul_ps(_mm_sub_ps(hi, r.origin[a]), r.inv_far[a]);
                    if SAFE {
                        lo = fix_nan4(lo, f32::NEG_INFINITY);
                        hi = fix_nan4(hi, f32::INFINITY);
                    }
                    t_near = _mm_max_ps(t_near, lo);
                    t_far = _mm_min_ps(t_far, hi);
                }
                _mm_storeu_ps(near[4 * half..].as_mut_ptr(), t_near);
                mask |= (_mm_movemask_ps(_mm_cmple_ps(t_near, t_far)) as u32) << (4 * half);
            }
        }
        mask
    }

    #[inline(always)]
    fn octant(r: &NodeRay4) -> u32 {
        r.octant
    }

    #[inline(always)]
    fn block(b: &TriBlock, r: &TriRay4, limit: f32) -> BlockHits {
        block_sse(b, r, limit)
    }

    type Pair = [[f32; 2 * BLOCK]; 3];

    #[inline(always)]
    fn block_pair(a: &TriBlock, b: &TriBlock, r: &TriRay4, limit: f32) -> BlockHits<Self::Pair> {
        super::pair_of_blocks::<Self>(a, b, r, limit)
    }
}
