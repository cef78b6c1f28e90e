//! What the x86-64 kernels share: SSE2 (every x86-64 CPU, [`super::sse2`]), AVX2 + FMA
//! ([`super::avx2`]), and the AVX2 kernel compiled for AVX-512 CPUs ([`super::avx512`]), chosen
//! at run time; and the macro that writes each one's `#[target_feature]` entry points.
//!
//! They share the triangle test ([`block_sse`], 4 lanes in 128-bit registers, VEX-encoded
//! inside the AVX2 functions), which is [`super::floats::watertight`] on a block's lanes, as
//! the AVX2 kernel's test of two blocks at once (`Avx2::block_pair`, 8 lanes in 256-bit
//! registers) is on two blocks' lanes and the packets' group test ([`super::group::group_blocks`]) on
//! eight rays' lanes. The box test is 8 lanes in one 256-bit register with AVX2, two
//! 128-bit halves with SSE2. The traversal loops are the generic ones of
//! [`super::super::traverse`], instantiated inside `#[target_feature]` entry points so that
//! the whole loop, helpers and intrinsics included, is compiled for the kernel's instruction
//! set (the helpers are `#[inline(always)]` and carry no target features of their own).
//!
//! The AVX-512 kernel is the AVX2 one ([`Avx2`], the same intrinsics in the same order, so the
//! same bits) compiled with AVX-512 F, VL, BW and DQ enabled: 32 vector registers instead of
//! 16, and EVEX encodings. (More registers did not keep the box test's ray constants in
//! registers: the closest-hit walk still reads them from the stack at every node, as memory
//! operands of its arithmetic, in both kernels.) On an AVX-512 CPU it traces a few percent
//! faster than the AVX2 kernel (`examples/trace_time` against `TRACERY_KERNEL=avx2`). Its
//! one part of its own, a packet's rays tested against a triangle sixteen at a time, is in
//! [`super::avx512`].
//!
//! The single-ray walks use no 512-bit instruction, and must not: with AVX-512 enabled the
//! compiler is free to join scalar and 256-bit memory operations into 512-bit ones, and on
//! an Intel Xeon a closest-hit walk ran 8-9% slower than the AVX2 kernel's for the
//! 12 such instructions it had (zeroing the pair test's answer, reading two of its lanes), all from the pair
//! test's answer written to memory. That answer now stays in registers ([`Tuv8`]); check with
//! `objdump -d` that `avx512::closest_inner` and `each_hit_inner` mention no `zmm` after a
//! change to the walks (the packet walk uses 512-bit registers by design).
//!
//! Every operation mirrors the scalar reference in order and kind: subtract then multiply in
//! the box test (no FMA, so the conservative far scale stays valid), and in the triangle test
//! exactly the multiplications, subtractions and the one division of
//! [`crate::geometry::intersect_triangle`], so each lane's distance has the scalar bits.
#![allow(
    unsafe_code,
    reason = "SIMD intrinsics: loads, stores and target-feature calls"
)]

use std::arch::x86_64::*;

use super::floats::{self, Floats};
use super::{BlockHits, TriRay};
use crate::bvh::wide::{BLOCK, TriBlock};
use crate::geometry::Ray;

/// The triangle test's ray data, broadcast to 4 lanes, in the test's axis order.
#[derive(Clone, Copy)]
pub(crate) struct TriRay4 {
    /// The origin's coordinates along the axes `k` (x, y, z of the sheared frame).
    pub(super) origin: [__m128; 3],
    /// Byte offsets of the rows `k` within a vertex's `[[f32; 4]; 3]`: `16 * k`, each 0, 16
    /// or 32 (`k` capped at 2, so whatever it held).
    pub(super) row: [usize; 3],
    pub(super) sx: __m128,
    pub(super) sy: __m128,
    pub(super) sz: __m128,
}

#[inline(always)]
pub(super) fn tri_ray4(r: &TriRay) -> TriRay4 {
    // SAFETY: `_mm_set1_ps` only needs SSE, part of the x86-64 baseline.
    let s = |x: f32| unsafe { _mm_set1_ps(x) };
    let [sx, sy, sz] = r.ray.shear;
    let o = r.ray.origin.to_array();
    let k = r.ray.k.map(|k| k.min(2));
    TriRay4 {
        origin: k.map(|k| s(o[k])),
        row: k.map(|k| 16 * k),
        sx: s(sx),
        sy: s(sy),
        sz: s(sz),
    }
}

/// One vertex of the block's four triangles, in the ray's axis order, sheared for the ray.
#[inline(always)]
pub(super) fn sheared4(b: &TriBlock, r: &TriRay4, vertex: usize) -> [__m128; 3] {
    let row = b.v[vertex].as_ptr().cast::<u8>();
    // SAFETY: SSE2 baseline loads of whole `[f32; 4]` rows of the vertex's `[[f32; 4]; 3]`
    // (48 bytes): each offset is 0, 16 or 32 (`tri_ray4`), so every load reads 16 bytes inside
    // it.
    let v = unsafe {
        [
            _mm_loadu_ps(row.add(r.row[0]).cast()),
            _mm_loadu_ps(row.add(r.row[1]).cast()),
            _mm_loadu_ps(row.add(r.row[2]).cast()),
        ]
    };
    floats::sheared(v, &r.origin, r.sx, r.sy)
}

/// The watertight test on a block's four lanes (see [`Lanes::block`]).
#[inline(always)]
pub(super) fn block_sse(b: &TriBlock, r: &TriRay4, limit: f32) -> BlockHits {
    // SAFETY: SSE2 baseline operations; the load reads the whole `[u32; 4]` of indices.
    let valid = unsafe {
        // Lanes holding a triangle: index not u32::MAX.
        let empty = _mm_cmpeq_epi32(_mm_loadu_si128(b.prim.as_ptr().cast()), _mm_set1_epi32(-1));
        !(_mm_movemask_ps(_mm_castsi128_ps(empty)) as u32) & 0xf
    };
    let found = floats::watertight(
        sheared4(b, r, 0),
        sheared4(b, r, 1),
        sheared4(b, r, 2),
        [r.sx, r.sy, r.sz],
        __m128::splat(limit),
        valid,
    );
    let [t, u, v] = found.tuv.unwrap_or([__m128::splat(0.0); 3]);
    // SAFETY: a 128-bit register is four `f32` lanes (the same size, any bits valid). No
    // closure (`map`): it could be compiled apart, without the caller's target features.
    let tuv = unsafe { std::mem::transmute::<[__m128; 3], [[f32; BLOCK]; 3]>([t, u, v]) };
    BlockHits {
        hits: found.hits,
        exact: found.exact,
        tuv,
    }
}

/// [`super::check_ray`] in SSE2 (every x86-64 CPU): the six floats read as two overlapping
/// groups of four, checked finite all at once, the direction's three checked for zero and for
/// the NaN rule's tiny size together.
#[inline(always)]
pub(crate) fn check_ray(ray: &Ray) -> Option<bool> {
    let p = (ray as *const Ray).cast::<f32>();
    // SAFETY: `Ray` is `#[repr(C)]`, six `f32`s (origin then direction, 24 bytes): the loads
    // read floats 0-3 and 2-5, inside it; the rest are SSE2 operations on registers.
    let (finite, nonzero, tiny) = unsafe {
        let a = _mm_loadu_ps(p);
        let b = _mm_loadu_ps(p.add(2));
        let abs = _mm_castsi128_ps(_mm_set1_epi32(i32::MAX));
        let (a, b_abs) = (_mm_and_ps(a, abs), _mm_and_ps(b, abs));
        let inf = _mm_set1_ps(f32::INFINITY);
        let finite = _mm_and_ps(_mm_cmplt_ps(a, inf), _mm_cmplt_ps(b_abs, inf));
        (
            _mm_movemask_ps(finite) == 0b1111,
            // Lanes 1-3 of `b` are the direction.
            _mm_movemask_ps(_mm_cmpneq_ps(b, _mm_setzero_ps())) & 0b1110 != 0,
            _mm_movemask_ps(_mm_cmplt_ps(b_abs, _mm_set1_ps(super::TINY_DIRECTION))) & 0b1110 != 0,
        )
    };
    (finite && nonzero).then_some(tiny)
}

/// Asks the CPU to bring the cache line holding `x` into its caches (see [`super::prefetch`]).
#[inline(always)]
pub(crate) fn prefetch<T>(x: &T) {
    // SAFETY: the intrinsic needs SSE, which every x86-64 CPU has; a prefetch reads nothing
    // the program sees and never faults, whatever the address.
    unsafe { _mm_prefetch::<_MM_HINT_T0>((x as *const T).cast()) }
}

/// The traversal's entry points for one instruction set, written into the module that invokes
/// it (which has `WideBvh`, `Ray`, `RayTile`, `Bests`, `Best` and `traverse` in scope): the
/// generic loops of `traverse` and `crate::bvh::wide::packet` over the lanes `$lanes`, compiled
/// inside `#[target_feature]` functions with `$features` enabled (such functions are never
/// inlined into callers without the features, so each whole loop, helpers and intrinsics
/// included, is compiled for the set), callable only with the proof `$cpu` that this CPU has
/// them. One definition serves the AVX2 and the AVX-512 kernels, which differ in nothing else.
macro_rules! entry_points {
    ($cpu:ident, $lanes:ty, $features:literal) => {
        #[target_feature(enable = $features)]
        fn closest_inner<const SAFE: bool, const INCOHERENT: bool>(
            w: &WideBvh,
            ray: &Ray,
            t_max: f32,
        ) -> Best {
            traverse::closest::<$lanes, SAFE, INCOHERENT>(w, ray, t_max)
        }

        #[target_feature(enable = $features)]
        fn each_hit_inner<const SAFE: bool, F: FnMut(u32, f32) -> bool>(
            w: &WideBvh,
            ray: &Ray,
            t_max: f32,
            f: &mut F,
        ) -> bool {
            traverse::each_hit::<$lanes, SAFE>(w, ray, t_max, f)
        }

        #[target_feature(enable = $features)]
        fn trace_packet_inner<const ANY: bool>(
            w: &WideBvh,
            tile: &RayTile,
            t_max: f32,
            bests: &mut Bests,
        ) -> bool {
            crate::bvh::wide::packet::trace_packet::<$lanes, ANY>(w, tile, t_max, bests)
        }

        #[target_feature(enable = $features)]
        fn root_leaf_rays_inner(w: &WideBvh, rays: &[Ray], active: u64, bests: &mut Bests) {
            crate::bvh::wide::packet::root_leaf_rays::<$lanes>(w, rays, active, bests)
        }

        /// Rays of any directions against a root leaf, in groups (see
        /// [`crate::bvh::wide::packet::root_leaf_rays`]).
        #[inline]
        pub(crate) fn root_leaf_rays(
            _cpu: $cpu,
            w: &WideBvh,
            rays: &[Ray],
            active: u64,
            bests: &mut Bests,
        ) {
            // SAFETY: the proof exists only when the CPU has every feature enabled here.
            unsafe { root_leaf_rays_inner(w, rays, active, bests) }
        }

        /// Closest hit (see [`traverse::closest`]), the whole traversal compiled for this
        /// instruction set.
        #[inline]
        pub(crate) fn closest<const SAFE: bool, const INCOHERENT: bool>(
            _cpu: $cpu,
            w: &WideBvh,
            ray: &Ray,
            t_max: f32,
        ) -> Best {
            // SAFETY: the proof exists only when the CPU has every feature enabled here.
            unsafe { closest_inner::<SAFE, INCOHERENT>(w, ray, t_max) }
        }

        /// Every hit (see [`traverse::each_hit`]).
        #[inline]
        pub(crate) fn each_hit<const SAFE: bool, F: FnMut(u32, f32) -> bool>(
            _cpu: $cpu,
            w: &WideBvh,
            ray: &Ray,
            t_max: f32,
            f: &mut F,
        ) -> bool {
            // SAFETY: the proof exists only when the CPU has every feature enabled here.
            unsafe { each_hit_inner::<SAFE, F>(w, ray, t_max, f) }
        }

        /// A packet's closest hits (or, with `ANY`, first hits; see
        /// [`crate::bvh::wide::packet`]).
        #[inline]
        pub(crate) fn trace_packet<const ANY: bool>(
            _cpu: $cpu,
            w: &WideBvh,
            tile: &RayTile,
            t_max: f32,
            bests: &mut Bests,
        ) -> bool {
            // SAFETY: the proof exists only when the CPU has every feature enabled here.
            unsafe { trace_packet_inner::<ANY>(w, tile, t_max, bests) }
        }
    };
}

pub(super) use entry_points;
