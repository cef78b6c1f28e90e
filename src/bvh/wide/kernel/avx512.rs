//! The AVX-512 kernel: the AVX2 kernel's tests, with its own parts, a packet's rays tested
//! against a triangle sixteen at a time and a packet's rays copied component by component
//! sixteen at a time; and its entry points, compiled for AVX-512.
//!
//! The AVX-512 kernel is the AVX2 one compiled with AVX-512 enabled (see [`super::avx2`]), but
//! for two things. A packet's rays, six floats each, become its arrays of origins and
//! directions by two-source lane permutations ([`Avx512::load_rays`]): five instructions per
//! component for sixteen rays, where copying them one float at a time took six loads and six
//! stores per ray. And at a leaf, the rays of a packet that share an axis permutation are
//! taken in groups of up to sixteen instead of eight, and a group of more than eight is tested
//! against each triangle in one 512-bit register per value (the same [`group::group_blocks`]
//! over [`RayLanes`] of sixteen lanes). A leaf is entered by about twelve rays of a tile, so
//! most leaves need one group where eight lanes needed two.
//!
//! The test is [`super::avx2`]'s eight-lane test lane for lane, with masks in place of
//! movemasks: the same multiplications, subtractions and one division in the same order as
//! [`crate::geometry::intersect_triangle`], so each lane's distance has the scalar bits.
#![allow(
    unsafe_code,
    reason = "SIMD intrinsics: loads, stores and target-feature calls"
)]

use std::arch::x86_64::*;

use super::avx2::{Avx2, NodeRay8, Tuv8};
use super::group::{self, MAX_LANES, RayLanes};
use super::stack::Stack;
use super::x86::TriRay4;
use super::{BlockHits, Lanes, NodeRay, TriRay};
use crate::bvh::PACKET;
use crate::bvh::RayTile;
use crate::bvh::wide::WideBvh;
use crate::bvh::wide::packet::{Bests, Group, Rays, Tris};
use crate::bvh::wide::traverse::{self, Best};
use crate::bvh::wide::{TriBlock, WIDTH, WideNode};
use crate::cpu::Avx512Cpu;
use crate::geometry::Ray;

/// The AVX-512 kernel's lanes: [`Avx2`]'s tests, but groups of up to sixteen rays.
pub(crate) struct Avx512;

impl Lanes for Avx512 {
    type NodeRay = NodeRay8;
    type TriRay = TriRay4;

    #[inline(always)]
    fn node_ray(r: &NodeRay) -> NodeRay8 {
        Avx2::node_ray(r)
    }

    #[inline(always)]
    fn tri_ray(r: &TriRay) -> TriRay4 {
        Avx2::tri_ray(r)
    }

    #[inline(always)]
    fn node<const SAFE: bool>(
        n: &WideNode,
        r: &NodeRay8,
        limit: f32,
        near: &mut [f32; WIDTH],
    ) -> u32 {
        Avx2::node::<SAFE>(n, r, limit, near)
    }

    #[inline(always)]
    fn push_others_in_order<const DIST: bool>(
        n: &WideNode,
        r: &NodeRay8,
        mask: u32,
        near: &[f32; WIDTH],
        stack: &mut Stack<'_>,
    ) {
        Avx2::push_others_in_order::<DIST>(n, r, mask, near, stack)
    }

    type Pair = Tuv8;

    #[inline(always)]
    fn block_pair(a: &TriBlock, b: &TriBlock, r: &TriRay4, limit: f32) -> BlockHits<Self::Pair> {
        Avx2::block_pair(a, b, r, limit)
    }

    #[inline(always)]
    fn octant(r: &NodeRay8) -> u32 {
        Avx2::octant(r)
    }

    #[inline(always)]
    fn rays_entering(n: &WideNode, lane: usize, r: &Rays, limit: &[f32; PACKET]) -> u64 {
        Avx2::rays_entering(n, lane, r, limit)
    }

    /// Sixteen rays (two rows of the tile) at a time: six 512-bit loads hold their 96 floats,
    /// three per row; each component's sixteen lanes are picked from the first row's rays
    /// (the first three loads) and the second's (the last three) by two permutations each, and
    /// the halves joined by a blend.
    #[inline(always)]
    fn load_rays(
        rays: &[Ray],
        stride: usize,
        origin: &mut [[f32; PACKET]; 3],
        dir: &mut [[f32; PACKET]; 3],
    ) -> bool {
        if rays.len() < 7 * stride + 8 {
            return false;
        }
        let floats = rays.as_ptr().cast::<f32>();
        // SAFETY: only reached inside the AVX-512 entry points; `Ray` is `repr(C)` of six
        // `f32` (checked below), so row `y` is the 48 floats from `6 * y * stride`, inside
        // `rays` for `y < 8` (checked above); every load reads 16 floats of one row; the
        // stores write 16 floats within one `[f32; PACKET]` row.
        unsafe {
            let mut index = [[_mm512_setzero_si512(); 2]; 6];
            for (c, pair) in index.iter_mut().enumerate() {
                pair[0] = _mm512_loadu_si512(TRANSPOSE[c][0].as_ptr().cast());
                pair[1] = _mm512_loadu_si512(TRANSPOSE[c][1].as_ptr().cast());
            }
            for chunk in 0..PACKET / 16 {
                let first = floats.add(6 * 2 * chunk * stride);
                let second = floats.add(6 * (2 * chunk + 1) * stride);
                let z = [
                    _mm512_loadu_ps(first),
                    _mm512_loadu_ps(first.add(16)),
                    _mm512_loadu_ps(first.add(32)),
                    _mm512_loadu_ps(second),
                    _mm512_loadu_ps(second.add(16)),
                    _mm512_loadu_ps(second.add(32)),
                ];
                for (c, [first, second]) in index.iter().enumerate() {
                    let lo = _mm512_permutex2var_ps(
                        _mm512_permutex2var_ps(z[0], *first, z[1]),
                        *second,
                        z[2],
                    );
                    let hi = _mm512_permutex2var_ps(
                        _mm512_permutex2var_ps(z[3], *first, z[4]),
                        *second,
                        z[5],
                    );
                    let row = if c < 3 {
                        &mut origin[c]
                    } else {
                        &mut dir[c - 3]
                    };
                    let lanes = &mut row[16 * chunk..16 * chunk + 16];
                    _mm512_storeu_ps(lanes.as_mut_ptr(), _mm512_mask_blend_ps(0xff00, lo, hi));
                }
            }
        }
        true
    }

    const RAYS_TOGETHER: usize = Avx2::RAYS_TOGETHER;

    const GROUP_MAX: usize = 16;

    /// Eight rays or fewer as [`Avx2`] tests them, more in sixteen lanes.
    #[inline(always)]
    fn group_blocks(blocks: &[TriBlock], r: &Rays, tris: &Tris, g: &Group, bests: &mut Bests) {
        if g.n <= 8 {
            Avx2::group_blocks(blocks, r, tris, g, bests)
        } else {
            group::group_blocks::<__m512>(blocks, r, tris, g, bests)
        }
    }

    #[inline(always)]
    fn block(b: &TriBlock, r: &TriRay4, limit: f32) -> BlockHits {
        Avx2::block(b, r, limit)
    }
}

// `load_rays` reads a ray as six floats.
const _: () = assert!(std::mem::size_of::<Ray>() == 24 && std::mem::align_of::<Ray>() == 4);

/// For each of a ray's six floats `c` (origin x, y, z, direction x, y, z), the lane indices
/// of the two permutations that pick it from eight rays' 48 floats held in three registers:
/// lane `j` (for ray `j % 8`) wants float `a = 6 (j % 8) + c`. The first permutation takes it
/// from the first two registers (indices 0-31) when `a < 32`; the second keeps that lane
/// (index `j`) or takes float `a` from the third register (index `16 + a - 32`).
const TRANSPOSE: [[[i32; 16]; 2]; 6] = {
    let mut t = [[[0i32; 16]; 2]; 6];
    let mut c = 0;
    while c < 6 {
        let mut j = 0;
        while j < 16 {
            let a = 6 * (j % 8) + c;
            if a < 32 {
                t[c][0][j] = a as i32;
                t[c][1][j] = j as i32;
            } else {
                t[c][1][j] = (a - 16) as i32;
            }
            j += 1;
        }
        c += 1;
    }
    t
};

/// Where a group's sixteen lanes are taken from: the group's ray indices (each below
/// [`PACKET`], 64) as sixteen 32-bit lanes, and the lanes whose ray lies in the packet's upper
/// half.
pub(crate) struct Picks {
    idx: __m512i,
    upper: __mmask16,
}

/// Sixteen rays of a group, picked from the packet's arrays by lane permutations.
impl RayLanes for __m512 {
    type Picks = Picks;

    #[inline(always)]
    fn picks(g: &Group) -> Picks {
        debug_assert!(g.idx.iter().all(|&i| i < PACKET));
        // SAFETY: only reached inside the AVX-512 entry points; each load reads eight of the
        // sixteen `usize` indices (64 bytes).
        unsafe {
            let lo = _mm512_cvtepi64_epi32(_mm512_loadu_si512(g.idx.as_ptr().cast()));
            let hi = _mm512_cvtepi64_epi32(_mm512_loadu_si512(g.idx[8..].as_ptr().cast()));
            let idx = _mm512_inserti64x4::<1>(_mm512_castsi256_si512(lo), hi);
            let upper = _mm512_test_epi32_mask(idx, _mm512_set1_epi32(32));
            Picks { idx, upper }
        }
    }

    /// Each half of the array (32 floats, two registers) permuted by the indices' low five
    /// bits, and the halves blended by their sixth. Copying the floats one by one through
    /// memory, as the eight-lane gather does, compiled to a function the AVX-512 kernel called
    /// fourteen times per group (each call behind a `vzeroupper`, its vector registers saved
    /// around it).
    #[inline(always)]
    fn gather(a: &[f32; PACKET], p: &Picks) -> __m512 {
        // SAFETY: only reached inside the AVX-512 entry points; the four loads read floats
        // 0-15, 16-31, 32-47 and 48-63 of the 64.
        unsafe {
            let at = |k: usize| _mm512_loadu_ps(a[16 * k..16 * k + 16].as_ptr());
            let lo = _mm512_permutex2var_ps(at(0), p.idx, at(1));
            let hi = _mm512_permutex2var_ps(at(2), p.idx, at(3));
            _mm512_mask_blend_ps(p.upper, lo, hi)
        }
    }

    #[inline(always)]
    fn next_up(self) -> __m512 {
        // SAFETY: only reached inside the AVX-512 entry points.
        unsafe {
            let below = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(self, _mm512_set1_ps(f32::INFINITY));
            let bits = _mm512_castps_si512(self);
            _mm512_castsi512_ps(_mm512_mask_add_epi32(
                bits,
                below,
                bits,
                _mm512_set1_epi32(1),
            ))
        }
    }

    #[inline(always)]
    fn select(self, new: __m512, bits: u32) -> __m512 {
        // SAFETY: only reached inside the AVX-512 entry points.
        unsafe { _mm512_mask_blend_ps(bits as __mmask16, self, new) }
    }

    #[inline(always)]
    fn store(self, out: &mut [f32; MAX_LANES]) {
        // SAFETY: only reached inside the AVX-512 entry points; the store writes the sixteen
        // floats.
        unsafe { _mm512_storeu_ps(out.as_mut_ptr(), self) }
    }
}

super::x86::entry_points!(
    Avx512Cpu,
    Avx512,
    "avx2,fma,popcnt,bmi1,bmi2,lzcnt,avx512f,avx512vl,avx512bw,avx512dq"
);
