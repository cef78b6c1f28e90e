//! The x86-64 kernels: SSE2 (every x86-64 CPU), AVX2 + FMA, and the AVX2 kernel compiled for
//! AVX-512 CPUs (chosen at run time).
//!
//! Both share the triangle test ([`block_sse`], 4 lanes in 128-bit registers, VEX-encoded
//! inside the AVX2 functions), which is [`super::floats::watertight`] on a block's lanes, as
//! the AVX2 kernel's test of two blocks at once (`Avx2::block_pair`, 8 lanes in 256-bit
//! registers) is on two blocks' lanes and the packets' eight-ray test ([`triangle_rays8`]) on
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
//! [`super::lanes16`].
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
use super::stack::Stack;
use super::{BlockHits, Lanes, NodeRay, TriRay};
use crate::bvh::wide::packet::{Bests, Group, PACKET, RayTile, Rays, Tris, group_exact, perm_of};
use crate::bvh::wide::traverse::{self, Best};
use crate::bvh::wide::{BLOCK, TriBlock, WIDTH, WideBvh, WideNode};
use crate::geometry::Ray;

/// The triangle test's ray data, broadcast to 4 lanes, in the test's axis order.
#[derive(Clone, Copy)]
pub(crate) struct TriRay4 {
    /// The origin's coordinates along the axes `k` (x, y, z of the sheared frame).
    origin: [__m128; 3],
    /// Byte offsets of the rows `k` within a vertex's `[[f32; 4]; 3]`: `16 * k`, each 0, 16
    /// or 32 (`k` capped at 2, so whatever it held).
    row: [usize; 3],
    sx: __m128,
    sy: __m128,
    sz: __m128,
}

#[inline(always)]
fn tri_ray4(r: &TriRay) -> TriRay4 {
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
fn sheared4(b: &TriBlock, r: &TriRay4, vertex: usize) -> [__m128; 3] {
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
fn block_sse(b: &TriBlock, r: &TriRay4, limit: f32) -> BlockHits {
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

/// The distance and barycentric weights of a pair test's eight lanes, in 256-bit registers
/// (see [`super::LaneValues`]).
#[derive(Clone, Copy)]
pub(crate) struct Tuv8([__m256; 3]);

impl Tuv8 {
    /// Lane `k` of register `x`: one lane permutation by an index in the low lane (the other
    /// lanes' indices do not matter).
    #[inline(always)]
    fn lane(x: __m256, k: usize) -> f32 {
        // SAFETY: only reached inside the AVX2 and AVX-512 entry points (the pair test that
        // makes a `Tuv8` runs only there); register operations.
        unsafe {
            let index = _mm256_castsi128_si256(_mm_cvtsi32_si128(k as i32));
            _mm256_cvtss_f32(_mm256_permutevar8x32_ps(x, index))
        }
    }
}

impl super::LaneValues for Tuv8 {
    #[inline(always)]
    fn t(&self, k: usize) -> f32 {
        Self::lane(self.0[0], k)
    }
    #[inline(always)]
    fn uv(&self, k: usize) -> (f32, f32) {
        (Self::lane(self.0[1], k), Self::lane(self.0[2], k))
    }
}

/// One vertex of two blocks' eight triangles (lanes 0-3 `a`'s, 4-7 `b`'s), sheared.
#[inline(always)]
fn sheared8(
    a: &TriBlock,
    b: &TriBlock,
    r: &TriRay4,
    o: &[__m256; 3],
    sx: __m256,
    sy: __m256,
    vertex: usize,
) -> [__m256; 3] {
    let ra = a.v[vertex].as_ptr().cast::<u8>();
    let rb = b.v[vertex].as_ptr().cast::<u8>();
    // SAFETY: AVX (inside the AVX2 and AVX-512 entry points only); each pair of loads reads a
    // whole `[f32; 4]` row of each block's vertex (offsets 0, 16 or 32, as in `sheared4`).
    let v = unsafe {
        [
            _mm256_loadu2_m128(rb.add(r.row[0]).cast(), ra.add(r.row[0]).cast()),
            _mm256_loadu2_m128(rb.add(r.row[1]).cast(), ra.add(r.row[1]).cast()),
            _mm256_loadu2_m128(rb.add(r.row[2]).cast(), ra.add(r.row[2]).cast()),
        ]
    };
    floats::sheared(v, o, sx, sy)
}

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

/// AVX2 with FMA: one 8-wide box test.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Avx2;

/// The box test's ray data, broadcast to 8 lanes.
#[derive(Clone, Copy)]
pub(crate) struct NodeRay8 {
    origin: [__m256; 3],
    inv: [__m256; 3],
    inv_far: [__m256; 3],
    /// Per axis, the byte offsets in [`WideNode::planes`] of the near and the far plane rows
    /// (`32 * near` and `32 * (near ^ 1)`, `near` capped at 5, so each below 192): no shift per
    /// row and node.
    rows: [(usize, usize); 3],
    octant: u32,
    /// `3 * octant` in every lane: shifts a node's order words to this octant's lane indices.
    shift: __m256i,
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

/// The MXCSR of this thread (SSE, part of the x86-64 baseline).
#[inline(always)]
fn read_mxcsr() -> u32 {
    let mut csr = 0u32;
    // SAFETY: `stmxcsr` stores the 32-bit MXCSR to `csr`, a live local; it reads and writes
    // nothing else.
    unsafe {
        std::arch::asm!("stmxcsr [{}]", in(reg) &raw mut csr, options(nostack, preserves_flags))
    };
    csr
}

/// Loads `csr` into this thread's MXCSR.
///
/// # Safety
/// `csr` must be a valid MXCSR value: one read by [`read_mxcsr`], with at most its flags
/// cleared or its flush-to-zero (bit 15) and denormals-are-zero (bit 6) modes set, which
/// every x86-64 CPU supports (setting a reserved bit would fault).
#[inline(always)]
unsafe fn write_mxcsr(csr: u32) {
    // SAFETY: the caller passes a valid MXCSR value; `ldmxcsr` reads only `csr`.
    unsafe {
        std::arch::asm!("ldmxcsr [{}]", in(reg) &raw const csr, options(nostack, preserves_flags))
    };
}

/// Runs `f` with this thread's flush-to-zero and denormals-are-zero modes on (MXCSR bits 15
/// and 6), and puts the register back afterwards, on unwinding too. Inside, a denormal
/// operand reads as zero and a denormal result is written as zero, so no instruction takes
/// the microcode assist Intel CPUs need for denormals; the compiler's vector code for
/// three-float arithmetic computes spare lanes of whatever the registers and the stack held,
/// often a denormal (see [`crate::render::Tracer::radiance_from_hit`]).
#[inline]
pub(crate) fn with_denormals_flushed<R>(f: impl FnOnce() -> R) -> R {
    const FTZ_DAZ: u32 = (1 << 15) | (1 << 6);
    struct Restore(u32);
    impl Drop for Restore {
        fn drop(&mut self) {
            // SAFETY: the value read on entry.
            unsafe { write_mxcsr(self.0) }
        }
    }
    let saved = read_mxcsr();
    let _restore = Restore(saved);
    // SAFETY: the value read, with the two modes every x86-64 CPU has set.
    unsafe { write_mxcsr(saved | FTZ_DAZ) };
    f()
}

/// Whether an SSE or AVX instruction of this thread took a denormal operand since the last
/// call: the MXCSR's sticky denormal flag (DE, bit 1), which this clears. Arithmetic on
/// denormals costs Intel CPUs a microcode assist per instruction (a hundred cycles or more),
/// so tests check that the fast paths never take one (the flag is architectural: AMD CPUs,
/// which take no such penalty, set it too, so the tests catch it on either).
#[cfg(test)]
pub(crate) fn take_denormal_flag() -> bool {
    const DE: u32 = 1 << 1;
    let csr = read_mxcsr();
    // SAFETY: the value read, with only the sticky DE flag cleared: the rounding mode,
    // exception masks and flush modes stay what they were.
    unsafe { write_mxcsr(csr & !DE) };
    csr & DE != 0
}

/// For each 8-bit mask, the positions of its set bits in increasing order (the rest 0): the
/// permutation that packs the hit lanes to the front.
static COMPACT: [[u32; WIDTH]; 256] = {
    let mut table = [[0u32; WIDTH]; 256];
    let mut m = 0;
    while m < 256 {
        let mut k = 0;
        let mut bit = 0;
        while bit < WIDTH {
            if m >> bit & 1 == 1 {
                table[m][k] = bit as u32;
                k += 1;
            }
            bit += 1;
        }
        m += 1;
    }
    table
};

/// Near and far distances of the eight boxes along axis `a` (no closures around intrinsics: a
/// closure is a function of its own, compiled without the caller's target features unless
/// it happens to be inlined).
#[inline(always)]
fn slab8<const SAFE: bool>(n: &WideNode, r: &NodeRay8, a: usize) -> (__m256, __m256) {
    // SAFETY: only reached inside the AVX2 and AVX-512 entry points (see `Avx2::node_ray`); the
    // loads read whole `[f32; 8]` plane rows: the offsets are multiples of 32 below 192
    // (`Avx2::node_ray`), inside the six rows.
    unsafe {
        let planes = n.planes.as_ptr().cast::<u8>();
        let (near, far) = r.rows[a];
        let lo = _mm256_loadu_ps(planes.add(near).cast());
        let hi = _mm256_loadu_ps(planes.add(far).cast());
        let mut lo = _mm256_mul_ps(_mm256_sub_ps(lo, r.origin[a]), r.inv[a]);
        let mut hi = _mm256_mul_ps(_mm256_sub_ps(hi, r.origin[a]), r.inv_far[a]);
        if SAFE {
            let nan = _mm256_cmp_ps::<_CMP_UNORD_Q>(lo, lo);
            lo = _mm256_blendv_ps(lo, _mm256_set1_ps(f32::NEG_INFINITY), nan);
            let nan = _mm256_cmp_ps::<_CMP_UNORD_Q>(hi, hi);
            hi = _mm256_blendv_ps(hi, _mm256_set1_ps(f32::INFINITY), nan);
        }
        (lo, hi)
    }
}

impl Lanes for Avx2 {
    type NodeRay = NodeRay8;
    type TriRay = TriRay4;

    #[inline(always)]
    fn node_ray(r: &NodeRay) -> NodeRay8 {
        // SAFETY: only reached inside the `#[target_feature]` entry points below (AVX2 + FMA,
        // or those and AVX-512), which run after the CPU was found to have their features.
        let s = |x: f32| unsafe { _mm256_set1_ps(x) };
        NodeRay8 {
            origin: r.origin.map(s),
            inv: r.inv.map(s),
            inv_far: r.inv_far.map(s),
            rows: r.near.map(|near| {
                // At most 5 (it always is): the offsets stay inside the rows whatever the
                // field held (a compare and a move, where `% 6` was a dozen instructions).
                let near = near.min(5);
                (32 * near, 32 * (near ^ 1))
            }),
            octant: r.octant,
            // SAFETY: as above.
            shift: unsafe { _mm256_set1_epi32(3 * r.octant as i32) },
        }
    }

    #[inline(always)]
    fn tri_ray(r: &TriRay) -> TriRay4 {
        tri_ray4(r)
    }

    #[inline(always)]
    fn node<const SAFE: bool>(
        n: &WideNode,
        r: &NodeRay8,
        limit: f32,
        near: &mut [f32; WIDTH],
    ) -> u32 {
        // SAFETY: only reached inside the AVX2 and AVX-512 entry points (see `node_ray`); the store writes
        // the whole `[f32; 8]` of `near`.
        unsafe {
            let (lx, hx) = slab8::<SAFE>(n, r, 0);
            let (ly, hy) = slab8::<SAFE>(n, r, 1);
            let (lz, hz) = slab8::<SAFE>(n, r, 2);
            // Trees of two levels, not chains of three: shorter latency.
            let t_near = _mm256_max_ps(
                _mm256_max_ps(lx, ly),
                _mm256_max_ps(lz, _mm256_setzero_ps()),
            );
            let t_far = _mm256_min_ps(
                _mm256_min_ps(hx, hy),
                _mm256_min_ps(hz, _mm256_set1_ps(limit)),
            );
            _mm256_storeu_ps(near.as_mut_ptr(), t_near);
            _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(t_near, t_far)) as u32
        }
    }

    #[inline(always)]
    fn octant(r: &NodeRay8) -> u32 {
        r.octant
    }

    /// Without a branch per child: the hit lanes are put in the octant's order and packed to
    /// the front with two lane permutations, and all but the last (the nearest) pushed with
    /// two stores.
    #[inline(always)]
    fn push_others_in_order<const DIST: bool>(
        n: &WideNode,
        r: &NodeRay8,
        mask: u32,
        near: &[f32; WIDTH],
        stack: &mut Stack<'_>,
    ) {
        // SAFETY: only reached inside the AVX2 and AVX-512 entry points (see `node_ray`); the
        // loads read whole `[u32; 8]` / `[f32; 8]` rows; the transmutes reinterpret 32-byte
        // vectors as 32-byte arrays of the same lane type.
        unsafe {
            let order = _mm256_srlv_epi32(_mm256_loadu_si256(n.order.as_ptr().cast()), r.shift);
            let bits = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
            let hit =
                _mm256_cmpeq_epi32(_mm256_and_si256(_mm256_set1_epi32(mask as i32), bits), bits);
            let hit_in_order = _mm256_permutevar8x32_epi32(hit, order);
            let m = _mm256_movemask_ps(_mm256_castsi256_ps(hit_in_order)) as usize;
            let packed = _mm256_loadu_si256(COMPACT[m].as_ptr().cast());
            let lanes = _mm256_permutevar8x32_epi32(order, packed);
            let child =
                _mm256_permutevar8x32_epi32(_mm256_loadu_si256(n.child.as_ptr().cast()), lanes);
            let child = std::mem::transmute::<__m256i, [u32; WIDTH]>(child);
            if DIST {
                let dist = _mm256_permutevar8x32_ps(_mm256_loadu_ps(near.as_ptr()), lanes);
                stack.push8(
                    child,
                    std::mem::transmute::<__m256, [f32; WIDTH]>(dist),
                    m.count_ones() as usize - 1,
                );
            } else {
                stack.push8_children(child, m.count_ones() as usize - 1);
            }
        }
    }

    #[inline(always)]
    fn block(b: &TriBlock, r: &TriRay4, limit: f32) -> BlockHits {
        block_sse(b, r, limit)
    }

    type Pair = Tuv8;

    /// The watertight test on two blocks' eight lanes in 256-bit registers: each row of the
    /// two blocks joined into one register (`vinsertf128`), then the test of [`block_sse`] at
    /// twice its width, the same operations per lane, so the same bits.
    #[inline(always)]
    fn block_pair(a: &TriBlock, b: &TriBlock, r: &TriRay4, limit: f32) -> BlockHits<Tuv8> {
        // SAFETY: AVX2 (inside the AVX2 and AVX-512 entry points only); the loads read each
        // block's whole `[u32; 4]` of indices.
        unsafe {
            let none = _mm_set1_epi32(-1);
            let ea = _mm_cmpeq_epi32(_mm_loadu_si128(a.prim.as_ptr().cast()), none);
            let eb = _mm_cmpeq_epi32(_mm_loadu_si128(b.prim.as_ptr().cast()), none);
            let empty = _mm_movemask_ps(_mm_castsi128_ps(ea)) as u32
                | (_mm_movemask_ps(_mm_castsi128_ps(eb)) as u32) << 4;
            let valid = !empty & 0xff;
            let o = [
                _mm256_set_m128(r.origin[0], r.origin[0]),
                _mm256_set_m128(r.origin[1], r.origin[1]),
                _mm256_set_m128(r.origin[2], r.origin[2]),
            ];
            let sx = _mm256_set_m128(r.sx, r.sx);
            let sy = _mm256_set_m128(r.sy, r.sy);
            let sz = _mm256_set_m128(r.sz, r.sz);
            let found = floats::watertight(
                sheared8(a, b, r, &o, sx, sy, 0),
                sheared8(a, b, r, &o, sx, sy, 1),
                sheared8(a, b, r, &o, sx, sy, 2),
                [sx, sy, sz],
                __m256::splat(limit),
                valid,
            );
            BlockHits {
                hits: found.hits,
                exact: found.exact,
                tuv: Tuv8(found.tuv.unwrap_or([_mm256_setzero_ps(); 3])),
            }
        }
    }

    /// Eight rays per instruction: the single ray's box test on eight lanes of rays.
    #[inline(always)]
    fn rays_entering(n: &WideNode, lane: usize, r: &Rays, limit: &[f32; PACKET]) -> u64 {
        let mut mask = 0u64;
        // SAFETY: only reached inside the AVX2 and AVX-512 entry points.
        unsafe {
            let pn: [__m256; 3] =
                std::array::from_fn(|a| _mm256_set1_ps(n.planes[r.near[a]][lane]));
            let pf: [__m256; 3] =
                std::array::from_fn(|a| _mm256_set1_ps(n.planes[r.near[a] ^ 1][lane]));
            for c in 0..r.n.div_ceil(8) {
                let base = 8 * c;
                let mut t_near = _mm256_setzero_ps();
                let mut t_far = ld8(limit, base);
                for a in 0..3 {
                    let o = ld8(&r.origin[a], base);
                    let lo = _mm256_mul_ps(_mm256_sub_ps(pn[a], o), ld8(&r.inv[a], base));
                    let hi = _mm256_mul_ps(_mm256_sub_ps(pf[a], o), ld8(&r.inv_far[a], base));
                    t_near = _mm256_max_ps(t_near, lo);
                    t_far = _mm256_min_ps(t_far, hi);
                }
                let m = _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(t_near, t_far)) as u64;
                mask |= m << base;
            }
        }
        // Lanes past the packet's end have limit -1: never entered.
        mask
    }

    const RAYS_TOGETHER: usize = RAYS_TOGETHER;

    /// Each triangle against the group's rays at once, one ray per lane (gathered from their
    /// places in the packet).
    #[inline(always)]
    fn group_blocks(blocks: &[TriBlock], r: &Rays, tris: &Tris, g: &Group, bests: &mut Bests) {
        let k = perm_of(g.perm);
        // Lanes past the group's end repeat its first ray and are masked off.
        let gather = |a: &[f32; PACKET]| -> __m256 {
            let v: [f32; 8] = std::array::from_fn(|j| a[g.idx[j]]);
            // SAFETY: only reached inside the AVX2 and AVX-512 entry points; `v` holds eight floats.
            unsafe { _mm256_loadu_ps(v.as_ptr()) }
        };
        let o = [
            gather(&r.origin[k[0]]),
            gather(&r.origin[k[1]]),
            gather(&r.origin[k[2]]),
        ];
        let shear = [
            gather(&tris.shear[0]),
            gather(&tris.shear[1]),
            gather(&tris.shear[2]),
        ];
        let lanes = (1u32 << g.n) - 1;
        let mut out = [[0.0f32; 8]; 3];
        // The rays' best distances, kept in a register from triangle to triangle (a hit is
        // never farther than the best it beats or ties), read back from `bests` only after
        // the scalar test decided some lane.
        let mut best = gather(&bests.t);
        for b in blocks {
            for tri in 0..BLOCK {
                if b.prim[tri] == u32::MAX {
                    continue;
                }
                // Each ray's limit: the next float above its best distance (ties still count).
                let limit8 = next_up8(best);
                let (mut hits, exact) =
                    triangle_rays8(b, tri, k, &o, &shear, limit8, lanes, &mut out);
                if hits != 0 {
                    // SAFETY: only reached inside the AVX2 and AVX-512 entry points; `out[0]`
                    // holds eight floats.
                    best = unsafe {
                        _mm256_blendv_ps(best, _mm256_loadu_ps(out[0].as_ptr()), lane_mask8(hits))
                    };
                }
                while hits != 0 {
                    let j = hits.trailing_zeros() as usize;
                    hits &= hits - 1;
                    bests.offer(g.idx[j], out[0][j], b.prim[tri], out[1][j], out[2][j]);
                }
                if exact == 0 {
                    continue;
                }
                let mut limit = [0.0f32; 8];
                // SAFETY: only reached inside the AVX2 and AVX-512 entry points; `limit` holds
                // eight floats.
                unsafe { _mm256_storeu_ps(limit.as_mut_ptr(), limit8) };
                group_exact(b, tri, g, exact, &limit, r, tris, bests);
                best = gather(&bests.t);
            }
        }
    }
}

/// [`traverse::next_up`] on eight lanes: the next float above each (infinity stays; the lanes are
/// positive distances, never NaN).
#[inline(always)]
fn next_up8(t: __m256) -> __m256 {
    // SAFETY: only reached inside the AVX2 and AVX-512 entry points.
    unsafe {
        // All ones (-1) where `t` is below infinity: subtracting it adds one to the bits.
        let below = _mm256_castps_si256(_mm256_cmp_ps::<_CMP_LT_OQ>(
            t,
            _mm256_set1_ps(f32::INFINITY),
        ));
        _mm256_castsi256_ps(_mm256_sub_epi32(_mm256_castps_si256(t), below))
    }
}

/// All ones in the lanes whose bit is set in `bits`, zero in the others.
#[inline(always)]
fn lane_mask8(bits: u32) -> __m256 {
    // SAFETY: only reached inside the AVX2 and AVX-512 entry points.
    unsafe {
        let lane_bits = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
        let set = _mm256_and_si256(_mm256_set1_epi32(bits as i32), lane_bits);
        _mm256_castsi256_ps(_mm256_cmpeq_epi32(set, lane_bits))
    }
}

/// The fewest rays of a group tested together per triangle; smaller groups go one by one
/// (four triangles at a time each).
const RAYS_TOGETHER: usize = 3;

/// Eight consecutive lanes of a packet array from `base`.
#[inline(always)]
fn ld8(a: &[f32; PACKET], base: usize) -> __m256 {
    // SAFETY: only reached inside the AVX2 and AVX-512 entry points; the slice `base..base + 8` is
    // bounds-checked before the load reads it.
    unsafe { _mm256_loadu_ps(a[base..base + 8].as_ptr()) }
}

/// The watertight test of one triangle against eight rays sharing one axis permutation
/// ([`floats::triangle_rays`]): returns the rays (lane bits, within `lanes`) hit at
/// `0 < t < limit` and the rays the scalar test must decide, with `t`, `u`, `v` per lane in
/// `out` when some ray was hit.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn triangle_rays8(
    b: &TriBlock,
    tri: usize,
    k: [usize; 3],
    o: &[__m256; 3],
    shear: &[__m256; 3],
    limit: __m256,
    lanes: u32,
    out: &mut [[f32; 8]; 3],
) -> (u32, u32) {
    let found = floats::triangle_rays(b, tri, k, o, shear, limit, lanes);
    if let (true, Some([t, u, v])) = (found.hits != 0, found.tuv) {
        // SAFETY: only reached inside the AVX2 and AVX-512 entry points; the stores write
        // whole `[f32; 8]`s.
        unsafe {
            _mm256_storeu_ps(out[0].as_mut_ptr(), t);
            _mm256_storeu_ps(out[1].as_mut_ptr(), u);
            _mm256_storeu_ps(out[2].as_mut_ptr(), v);
        }
    }
    (found.hits, found.exact)
}

/// Proof that this CPU has AVX2 and FMA (and POPCNT, BMI1, BMI2 and LZCNT, which every AVX2
/// CPU has and the mask bookkeeping uses: BMI2's `shrx` shifts without the flags and from
/// memory, one instruction of the three in each step of the order scan): made only by
/// [`Avx2Cpu::detect`].
#[derive(Clone, Copy, Debug)]
pub(crate) struct Avx2Cpu(());

impl Avx2Cpu {
    /// The proof, when the CPU has both.
    pub fn detect() -> Option<Avx2Cpu> {
        (is_x86_feature_detected!("avx2")
            && is_x86_feature_detected!("fma")
            && is_x86_feature_detected!("popcnt")
            && is_x86_feature_detected!("bmi1")
            && is_x86_feature_detected!("bmi2")
            && is_x86_feature_detected!("lzcnt"))
        .then_some(Avx2Cpu(()))
    }
}

/// Proof that this CPU has AVX-512 F, VL, BW and DQ besides everything [`Avx2Cpu`] proves:
/// made only by [`Avx512Cpu::detect`].
#[derive(Clone, Copy, Debug)]
pub(crate) struct Avx512Cpu(());

impl Avx512Cpu {
    /// The proof, when the CPU has all of them.
    pub fn detect() -> Option<Avx512Cpu> {
        (Avx2Cpu::detect().is_some()
            && is_x86_feature_detected!("avx512f")
            && is_x86_feature_detected!("avx512vl")
            && is_x86_feature_detected!("avx512bw")
            && is_x86_feature_detected!("avx512dq"))
        .then_some(Avx512Cpu(()))
    }
}

/// The traversal's entry points for one instruction set, in a module of their own: the generic
/// loops of [`traverse`] and [`crate::bvh::wide::packet`] over the [`Avx2`] lanes, compiled
/// inside `#[target_feature]` functions with `$features` enabled (such functions are never
/// inlined into callers without the features, so each whole loop, helpers and intrinsics
/// included, is compiled for the set), callable only with the proof `$cpu` that this CPU has
/// them. One definition serves the AVX2 and the AVX-512 kernels, which differ in nothing else.
macro_rules! entry_points {
    ($module:ident, $cpu:ident, $lanes:ty, $features:literal) => {
        pub(crate) mod $module {
            use super::*;

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
        }
    };
}

entry_points!(avx2, Avx2Cpu, Avx2, "avx2,fma,popcnt,bmi1,bmi2,lzcnt");
entry_points!(
    avx512,
    Avx512Cpu,
    super::super::lanes16::Avx512,
    "avx2,fma,popcnt,bmi1,bmi2,lzcnt,avx512f,avx512vl,avx512bw,avx512dq"
);
