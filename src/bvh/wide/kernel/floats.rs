//! The watertight triangle test written once over float vectors of any width: four lanes in
//! 128-bit registers (SSE2), eight in 256-bit ones (AVX2) and sixteen in 512-bit ones (AVX-512).
//!
//! The kernels use it three ways: a block's four triangles against one ray (every kernel's
//! single-ray leaf test), and one triangle against eight or sixteen rays of a packet. Only how
//! the lanes are filled differs (a block's rows loaded, or one vertex broadcast against the
//! rays' origins); from the sheared vertices on, [`watertight`] is the one sequence of
//! operations of [`crate::geometry::intersect_triangle`], in its order and without fused
//! multiply-adds, so every lane's distance has the scalar test's bits at every width.
//!
//! [`Floats`] is the little each width must say: its arithmetic, its comparisons (a vector of
//! all-ones lanes up to AVX2, a mask register on AVX-512) and how a comparison becomes lane
//! bits.
#![allow(
    unsafe_code,
    reason = "SIMD intrinsics on registers: the float operations of each width"
)]

use std::arch::x86_64::*;

use super::{G2, G3, G5};
use crate::bvh::wide::TriBlock;

/// Float lanes of one width, and the operations the triangle test needs of them. Comparisons
/// are ordered (false when a lane is NaN) unless named "not" (`neq`, `nle`, `nlt`: true then).
pub(crate) trait Floats: Copy {
    /// A comparison's answer per lane.
    type Mask: Copy;
    fn splat(x: f32) -> Self;
    fn add(self, o: Self) -> Self;
    fn sub(self, o: Self) -> Self;
    fn mul(self, o: Self) -> Self;
    fn div(self, o: Self) -> Self;
    /// As `minps`: the second operand where either is NaN (the test never depends on it).
    fn min(self, o: Self) -> Self;
    /// As `maxps` (see [`Floats::min`]).
    fn max(self, o: Self) -> Self;
    /// Clears the sign bit, as `f32::abs`.
    fn abs(self) -> Self;
    fn eq(self, o: Self) -> Self::Mask;
    fn lt(self, o: Self) -> Self::Mask;
    fn gt(self, o: Self) -> Self::Mask;
    fn neq(self, o: Self) -> Self::Mask;
    fn nle(self, o: Self) -> Self::Mask;
    fn nlt(self, o: Self) -> Self::Mask;
    fn and(a: Self::Mask, b: Self::Mask) -> Self::Mask;
    fn or(a: Self::Mask, b: Self::Mask) -> Self::Mask;
    /// Bit `k` set where lane `k` is true.
    fn bits(m: Self::Mask) -> u32;
}

/// A [`Floats`] implementation for a width whose comparisons give vectors (SSE2, AVX2).
macro_rules! vector_mask_floats {
    ($t:ty, $set1:ident, $add:ident, $sub:ident, $mul:ident, $div:ident, $min:ident,
     $max:ident, $and:ident, $or:ident, $andnot:ident, $movemask:ident,
     eq $eq:expr, lt $lt:expr, gt $gt:expr, neq $neq:expr, nle $nle:expr, nlt $nlt:expr) => {
        impl Floats for $t {
            type Mask = $t;
            // SAFETY (every block below): register-only intrinsics of this width, reached only
            // inside entry points compiled for it (SSE2 is the x86-64 baseline; AVX2 runs in
            // the AVX2 and AVX-512 kernels' `#[target_feature]` functions, made after the
            // CPU was found to have the features).
            #[inline(always)]
            fn splat(x: f32) -> Self {
                // SAFETY: see above.
                unsafe { $set1(x) }
            }
            #[inline(always)]
            fn add(self, o: Self) -> Self {
                // SAFETY: see above.
                unsafe { $add(self, o) }
            }
            #[inline(always)]
            fn sub(self, o: Self) -> Self {
                // SAFETY: see above.
                unsafe { $sub(self, o) }
            }
            #[inline(always)]
            fn mul(self, o: Self) -> Self {
                // SAFETY: see above.
                unsafe { $mul(self, o) }
            }
            #[inline(always)]
            fn div(self, o: Self) -> Self {
                // SAFETY: see above.
                unsafe { $div(self, o) }
            }
            #[inline(always)]
            fn min(self, o: Self) -> Self {
                // SAFETY: see above.
                unsafe { $min(self, o) }
            }
            #[inline(always)]
            fn max(self, o: Self) -> Self {
                // SAFETY: see above.
                unsafe { $max(self, o) }
            }
            #[inline(always)]
            fn abs(self) -> Self {
                // SAFETY: see above.
                unsafe { $andnot($set1(-0.0), self) }
            }
            #[inline(always)]
            fn eq(self, o: Self) -> Self {
                // SAFETY: see above.
                unsafe { $eq(self, o) }
            }
            #[inline(always)]
            fn lt(self, o: Self) -> Self {
                // SAFETY: see above.
                unsafe { $lt(self, o) }
            }
            #[inline(always)]
            fn gt(self, o: Self) -> Self {
                // SAFETY: see above.
                unsafe { $gt(self, o) }
            }
            #[inline(always)]
            fn neq(self, o: Self) -> Self {
                // SAFETY: see above.
                unsafe { $neq(self, o) }
            }
            #[inline(always)]
            fn nle(self, o: Self) -> Self {
                // SAFETY: see above.
                unsafe { $nle(self, o) }
            }
            #[inline(always)]
            fn nlt(self, o: Self) -> Self {
                // SAFETY: see above.
                unsafe { $nlt(self, o) }
            }
            #[inline(always)]
            fn and(a: Self, b: Self) -> Self {
                // SAFETY: see above.
                unsafe { $and(a, b) }
            }
            #[inline(always)]
            fn or(a: Self, b: Self) -> Self {
                // SAFETY: see above.
                unsafe { $or(a, b) }
            }
            #[inline(always)]
            fn bits(m: Self) -> u32 {
                // SAFETY: see above.
                unsafe { $movemask(m) as u32 }
            }
        }
    };
}

vector_mask_floats!(
    __m128, _mm_set1_ps, _mm_add_ps, _mm_sub_ps, _mm_mul_ps, _mm_div_ps, _mm_min_ps,
    _mm_max_ps, _mm_and_ps, _mm_or_ps, _mm_andnot_ps, _mm_movemask_ps,
    eq _mm_cmpeq_ps, lt _mm_cmplt_ps, gt _mm_cmpgt_ps, neq _mm_cmpneq_ps,
    nle _mm_cmpnle_ps, nlt _mm_cmpnlt_ps
);

vector_mask_floats!(
    __m256, _mm256_set1_ps, _mm256_add_ps, _mm256_sub_ps, _mm256_mul_ps, _mm256_div_ps,
    _mm256_min_ps, _mm256_max_ps, _mm256_and_ps, _mm256_or_ps, _mm256_andnot_ps,
    _mm256_movemask_ps,
    eq _mm256_cmp_ps::<_CMP_EQ_OQ>, lt _mm256_cmp_ps::<_CMP_LT_OQ>,
    gt _mm256_cmp_ps::<_CMP_GT_OQ>, neq _mm256_cmp_ps::<_CMP_NEQ_UQ>,
    nle _mm256_cmp_ps::<_CMP_NLE_UQ>, nlt _mm256_cmp_ps::<_CMP_NLT_UQ>
);

/// Sixteen lanes: comparisons into mask registers.
impl Floats for __m512 {
    type Mask = __mmask16;
    // SAFETY (every block below): register-only AVX-512 F and DQ intrinsics, reached only
    // inside the AVX-512 kernel's `#[target_feature]` functions, made after the CPU was found
    // to have those features.
    #[inline(always)]
    fn splat(x: f32) -> Self {
        // SAFETY: see above.
        unsafe { _mm512_set1_ps(x) }
    }
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        // SAFETY: see above.
        unsafe { _mm512_add_ps(self, o) }
    }
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        // SAFETY: see above.
        unsafe { _mm512_sub_ps(self, o) }
    }
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        // SAFETY: see above.
        unsafe { _mm512_mul_ps(self, o) }
    }
    #[inline(always)]
    fn div(self, o: Self) -> Self {
        // SAFETY: see above.
        unsafe { _mm512_div_ps(self, o) }
    }
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        // SAFETY: see above.
        unsafe { _mm512_min_ps(self, o) }
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        // SAFETY: see above.
        unsafe { _mm512_max_ps(self, o) }
    }
    #[inline(always)]
    fn abs(self) -> Self {
        // SAFETY: see above (DQ provides the float `andnot`).
        unsafe { _mm512_andnot_ps(_mm512_set1_ps(-0.0), self) }
    }
    #[inline(always)]
    fn eq(self, o: Self) -> __mmask16 {
        // SAFETY: see above.
        unsafe { _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(self, o) }
    }
    #[inline(always)]
    fn lt(self, o: Self) -> __mmask16 {
        // SAFETY: see above.
        unsafe { _mm512_cmp_ps_mask::<_CMP_LT_OQ>(self, o) }
    }
    #[inline(always)]
    fn gt(self, o: Self) -> __mmask16 {
        // SAFETY: see above.
        unsafe { _mm512_cmp_ps_mask::<_CMP_GT_OQ>(self, o) }
    }
    #[inline(always)]
    fn neq(self, o: Self) -> __mmask16 {
        // SAFETY: see above.
        unsafe { _mm512_cmp_ps_mask::<_CMP_NEQ_UQ>(self, o) }
    }
    #[inline(always)]
    fn nle(self, o: Self) -> __mmask16 {
        // SAFETY: see above.
        unsafe { _mm512_cmp_ps_mask::<_CMP_NLE_UQ>(self, o) }
    }
    #[inline(always)]
    fn nlt(self, o: Self) -> __mmask16 {
        // SAFETY: see above.
        unsafe { _mm512_cmp_ps_mask::<_CMP_NLT_UQ>(self, o) }
    }
    #[inline(always)]
    fn and(a: __mmask16, b: __mmask16) -> __mmask16 {
        a & b
    }
    #[inline(always)]
    fn or(a: __mmask16, b: __mmask16) -> __mmask16 {
        a | b
    }
    #[inline(always)]
    fn bits(m: __mmask16) -> u32 {
        m as u32
    }
}

/// A vertex relative to the ray's origin, then sheared: `a = v - o` (both in the ray's axis
/// order), `(a[x] - sx a[z], a[y] - sy a[z], a[z])`.
#[inline(always)]
pub(crate) fn sheared<F: Floats>(v: [F; 3], o: &[F; 3], sx: F, sy: F) -> [F; 3] {
    let x = v[0].sub(o[0]);
    let y = v[1].sub(o[1]);
    let z = v[2].sub(o[2]);
    [x.sub(sx.mul(z)), y.sub(sy.mul(z)), z]
}

/// `max(|a|, |b|, |c|)` per lane (never used where a lane is NaN: a NaN coordinate makes the
/// lane's distance NaN, which fails its range test first).
#[inline(always)]
fn max3_abs<F: Floats>(a: F, b: F, c: F) -> F {
    a.abs().max(b.abs()).max(c.abs())
}

/// What [`watertight`] found: the lanes hit at `0 < t < limit`, the lanes the scalar test must
/// decide (an edge function exactly zero, or the distance or its error bound beyond f32's
/// range), and, unless no lane was inside all three edges, the distance and the barycentric
/// weights of the second and third vertex per lane (meaningful in the lanes hit only).
pub(crate) struct Found<F> {
    pub hits: u32,
    pub exact: u32,
    pub tuv: Option<[F; 3]>,
}

/// The watertight test on every lane in `lanes`, from the three vertices sheared
/// ([`sheared`]) and the ray's `sz`, in the operations and order of
/// [`crate::geometry::intersect_triangle`].
#[inline(always)]
pub(crate) fn watertight<F: Floats>(
    [ax, ay, az]: [F; 3],
    [bx, by, bz]: [F; 3],
    [cx, cy, cz]: [F; 3],
    [sx, sy, sz]: [F; 3],
    limit: F,
    lanes: u32,
) -> Found<F> {
    let u = cx.mul(by).sub(cy.mul(bx));
    let v = ax.mul(cy).sub(ay.mul(cx));
    let w = bx.mul(ay).sub(by.mul(ax));
    let zero = F::splat(0.0);
    let exact = if cfg!(feature = "no-watertight-fallback") {
        0
    } else {
        F::bits(F::or(F::or(u.eq(zero), v.eq(zero)), w.eq(zero))) & lanes
    };
    // Some edge function negative and some positive: outside. As min < 0 and max > 0 (a NaN
    // lane may decide differently from the scalar test's comparisons here, but its distance
    // is NaN, so it misses either way).
    let neg = u.min(v).min(w).lt(zero);
    let pos = u.max(v).max(w).gt(zero);
    let inside = !F::bits(F::and(neg, pos)) & lanes & !exact;
    if inside == 0 {
        return Found {
            hits: 0,
            exact,
            tuv: None,
        };
    }
    let det = u.add(v).add(w);
    let t_scaled = u.mul(az).add(v.mul(bz)).add(w.mul(cz)).mul(sz);
    let inv = F::splat(1.0).div(det);
    let t = t_scaled.mul(inv);
    let in_range = F::and(det.neq(zero), F::and(t.gt(zero), t.lt(limit)));
    // The distance error bound, in the order of `t_error_bound`; `2 |sx|` and `2 |sy|` as
    // sums (doubling is exact).
    let (abs_sx, abs_sy) = (sx.abs(), sy.abs());
    let max_z = max3_abs(az, bz, cz);
    let max_zt = max_z.mul(sz.abs());
    let max_x = max3_abs(ax, bx, cx);
    let max_y = max3_abs(ay, by, cy);
    let delta_z = F::splat(G3).mul(max_zt);
    let delta_x = F::splat(G5).mul(max_x.add(abs_sx.add(abs_sx).mul(max_z)));
    let delta_y = F::splat(G5).mul(max_y.add(abs_sy.add(abs_sy).mul(max_z)));
    let delta_e = F::splat(2.0).mul(
        F::splat(G2)
            .mul(max_x)
            .mul(max_y)
            .add(delta_y.mul(max_x))
            .add(delta_x.mul(max_y)),
    );
    let max_e = max3_abs(u, v, w);
    let bound = F::splat(3.0)
        .mul(
            F::splat(G3)
                .mul(max_e)
                .mul(max_zt)
                .add(delta_e.mul(max_zt))
                .add(delta_z.mul(max_e)),
        )
        .mul(inv.abs());
    // Kept unless `t <= bound`.
    let ok = F::and(in_range, t.nle(bound));
    // A distance or bound that is infinite or NaN (products beyond f32's range): the scalar
    // test's f64 path decides, as it does in the scalar test.
    let inf = F::splat(f32::INFINITY);
    let overflow = F::bits(F::or(t_scaled.abs().nlt(inf), bound.nlt(inf))) & inside;
    Found {
        hits: F::bits(ok) & inside & !overflow,
        exact: exact | overflow,
        tuv: Some([t, v.mul(inv), w.mul(inv)]),
    }
}

/// One triangle of `b` (lane `tri`) against a packet's rays, one ray per lane, all sharing the
/// axis permutation `k`: `o` their origins in that order, `shear` their `sx`, `sy`, `sz`.
#[inline(always)]
pub(crate) fn triangle_rays<F: Floats>(
    b: &TriBlock,
    tri: usize,
    k: [usize; 3],
    o: &[F; 3],
    shear: &[F; 3],
    limit: F,
    lanes: u32,
) -> Found<F> {
    let [sx, sy, _] = *shear;
    watertight(
        broadcast_sheared(b, tri, 0, k, o, sx, sy),
        broadcast_sheared(b, tri, 1, k, o, sx, sy),
        broadcast_sheared(b, tri, 2, k, o, sx, sy),
        *shear,
        limit,
        lanes,
    )
}

/// One vertex of a triangle in every lane, relative to the rays' origins, then sheared by each
/// ray's constants (lanes being rays instead of a block's triangles).
#[inline(always)]
fn broadcast_sheared<F: Floats>(
    b: &TriBlock,
    tri: usize,
    vertex: usize,
    k: [usize; 3],
    o: &[F; 3],
    sx: F,
    sy: F,
) -> [F; 3] {
    // No closure (`k.map`): it would be a function of its own, compiled without the caller's
    // target features unless inlined.
    let row = &b.v[vertex];
    let v = [
        F::splat(row[k[0]][tri]),
        F::splat(row[k[1]][tri]),
        F::splat(row[k[2]][tri]),
    ];
    sheared(v, o, sx, sy)
}
