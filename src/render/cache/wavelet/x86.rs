//! The wavelet filter's row loops compiled once more with AVX2 enabled, chosen at run time
//! when the CPU has it: the same Rust loops ([`super::link_row`], [`super::filter_row`]) in
//! 8-wide vectors instead of SSE2's 4. The same operations in the same order (no fused
//! multiply-adds), so the same bits on either path.
#![allow(
    unsafe_code,
    reason = "calling functions compiled for AVX2 once the CPU has it"
)]

use std::ops::Range;

use super::{Row, Tap};

/// Whether the CPU has AVX2, asked once.
fn has_avx2() -> bool {
    static AVX2: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *AVX2.get_or_init(|| std::arch::is_x86_feature_detected!("avx2"))
}

/// [`super::link_row`] with AVX2 if the CPU has it, else with the baseline's SSE2.
pub(super) fn link_row(a: &Row, b: &Row, xs: Range<usize>, bit: u8, out: &mut [u8]) {
    if has_avx2() {
        // SAFETY: the CPU has AVX2 (checked just above), all the function needs.
        unsafe { link_row_avx2(a, b, xs, bit, out) }
    } else {
        super::link_row(a, b, xs, bit, out);
    }
}

#[target_feature(enable = "avx2")]
fn link_row_avx2(a: &Row, b: &Row, xs: Range<usize>, bit: u8, out: &mut [u8]) {
    super::link_row(a, b, xs, bit, out);
}

/// [`super::filter_row`] with AVX2 if the CPU has it, else with the baseline's SSE2.
pub(super) fn filter_row(
    taps: &[Tap; 8],
    centre: [&[f32]; 3],
    weight: &[f32],
    or: &mut [f32],
    og: &mut [f32],
    ob: &mut [f32],
) {
    if has_avx2() {
        // SAFETY: the CPU has AVX2 (checked just above), all the function needs.
        unsafe { filter_row_avx2(taps, centre, weight, or, og, ob) }
    } else {
        super::filter_row(taps, centre, weight, or, og, ob);
    }
}

#[target_feature(enable = "avx2")]
fn filter_row_avx2(
    taps: &[Tap; 8],
    centre: [&[f32]; 3],
    weight: &[f32],
    or: &mut [f32],
    og: &mut [f32],
    ob: &mut [f32],
) {
    super::filter_row(taps, centre, weight, or, og, ob);
}
