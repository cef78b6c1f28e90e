//! The AVX2 + FMA kernel: a node's eight boxes in one 256-bit register, a leaf's two blocks of
//! triangles eight lanes at once, a packet's rays eight at a time against a triangle
//! ([`group::group_blocks`] over [`RayLanes`] of eight lanes); and its entry points, compiled
//! for AVX2.
#![allow(
    unsafe_code,
    reason = "SIMD intrinsics: loads, stores and target-feature calls"
)]

use std::arch::x86_64::*;

use super::floats::{self, Floats};
use super::group::{self, MAX_LANES, RayLanes};
use super::stack::Stack;
use super::x86::{TriRay4, block_sse, tri_ray4};
use super::{BlockHits, Lanes, NodeRay, TriRay};
use crate::bvh::wide::packet::{Bests, Group, Rays, Tris};
use crate::bvh::wide::traverse::{self, Best};
use crate::bvh::wide::{TriBlock, WIDTH, WideBvh, WideNode};
use crate::bvh::{PACKET, RayTile};
use crate::cpu::Avx2Cpu;
use crate::geometry::Ray;

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

    /// Each triangle against the group's rays at once, eight lanes ([`group::group_blocks`]).
    #[inline(always)]
    fn group_blocks(blocks: &[TriBlock], r: &Rays, tris: &Tris, g: &Group, bests: &mut Bests) {
        group::group_blocks::<__m256>(blocks, r, tris, g, bests)
    }
}

/// Eight rays of a group, gathered from their places in the packet one float at a time.
impl RayLanes for __m256 {
    type Picks = [usize; 8];

    #[inline(always)]
    fn picks(g: &Group) -> [usize; 8] {
        std::array::from_fn(|j| g.idx[j])
    }

    #[inline(always)]
    fn gather(a: &[f32; PACKET], p: &[usize; 8]) -> __m256 {
        let v: [f32; 8] = std::array::from_fn(|j| a[p[j]]);
        // SAFETY: only reached inside the AVX2 and AVX-512 entry points; `v` holds eight floats.
        unsafe { _mm256_loadu_ps(v.as_ptr()) }
    }

    #[inline(always)]
    fn next_up(self) -> __m256 {
        next_up8(self)
    }

    #[inline(always)]
    fn select(self, new: __m256, bits: u32) -> __m256 {
        // SAFETY: only reached inside the AVX2 and AVX-512 entry points.
        unsafe { _mm256_blendv_ps(self, new, lane_mask8(bits)) }
    }

    #[inline(always)]
    fn store(self, out: &mut [f32; MAX_LANES]) {
        // SAFETY: only reached inside the AVX2 and AVX-512 entry points; the store writes the
        // first eight of the sixteen floats.
        unsafe { _mm256_storeu_ps(out.as_mut_ptr(), self) }
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

super::x86::entry_points!(Avx2Cpu, Avx2, "avx2,fma,popcnt,bmi1,bmi2,lzcnt");
