//! The reprojection's projection compiled once more with AVX2 enabled, chosen at run time
//! when the CPU has it: the same Rust loop ([`super::project_points`]) in 8-wide vectors
//! instead of SSE2's 4. The same operations in the same order (no fused multiply-adds), so
//! the same bits on either path.
#![allow(
    unsafe_code,
    reason = "calling a function compiled for AVX2 once the CPU has it"
)]

use super::Projection;

/// [`super::project_points`] with AVX2 if the CPU has it, else with the baseline's SSE2.
pub(super) fn project_points(
    to: &Projection,
    points: &[[f32; 3]],
    pixel: &mut [u32],
    depth: &mut [u32],
) {
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (checked just above), all the function needs.
        unsafe { avx2(to, points, pixel, depth) }
    } else {
        super::project_points(to, points, pixel, depth);
    }
}

#[target_feature(enable = "avx2")]
fn avx2(to: &Projection, points: &[[f32; 3]], pixel: &mut [u32], depth: &mut [u32]) {
    super::project_points(to, points, pixel, depth);
}
