//! The moving picture's smoothing four pixels at a time with SSE2, which every x86-64 CPU has:
//! the operations of `smooth_pixels` on 16-bit lanes, giving the same bytes (a test compares
//! the two on every pixel of pictures of many widths).
#![allow(unsafe_code, reason = "SSE2 intrinsics on registers and on row slices")]

use std::arch::x86_64::*;
use std::ops::Range;

use super::smooth::{RECIPROCAL, SmoothRows};

/// Smooths the pixels of the row that can go four at a time (both horizontal neighbours
/// inside the row: from 1 while the fourth pixel's right neighbour exists) into `o`, the
/// row's RGBA8; returns them, the caller takes the others one by one.
pub(super) fn middle(r: &SmoothRows, o: &mut [u8]) -> Range<usize> {
    let w = r.c.len();
    if w < 6 {
        return 0..0;
    }
    let end = 1 + (w - 2) / 4 * 4;
    for x in (1..end).step_by(4) {
        four(r, x, &mut o[4 * x..4 * x + 16]);
    }
    1..end
}

/// Pixels `x..x + 4` (with `1 <= x` and `x + 5 <= w`) into `o` (16 bytes).
#[inline(always)]
fn four(r: &SmoothRows, x: usize, o: &mut [u8]) {
    // The four colours from `x` of `p`, and the four link bytes from `x` of `b`, each in a
    // 32-bit lane.
    let colours = |p: &[[u8; 4]], x: usize| -> __m128i {
        let p = &p[x..x + 4];
        // SAFETY: SSE2 is part of x86-64; the load reads the 16 bytes of `p`'s four pixels.
        unsafe { _mm_loadu_si128(p.as_ptr().cast()) }
    };
    let links = |b: &[u8], x: usize| -> __m128i {
        let v = u32::from_le_bytes([b[x], b[x + 1], b[x + 2], b[x + 3]]);
        // SAFETY: SSE2 is part of x86-64; register operations only.
        unsafe {
            let z = _mm_setzero_si128();
            _mm_unpacklo_epi16(_mm_unpacklo_epi8(_mm_cvtsi32_si128(v as i32), z), z)
        }
    };
    let (c, right, left) = (colours(r.c, x), colours(r.c, x + 1), colours(r.c, x - 1));
    let (down, up) = (colours(r.dc, x), colours(r.uc, x));
    let (l, l_left, l_up) = (links(r.l, x), links(r.l, x - 1), links(r.ul, x));
    // SAFETY: SSE2 is part of x86-64; register operations, and the store writes the 16 bytes
    // of `o`.
    unsafe {
        let z = _mm_setzero_si128();
        // All ones in a pixel's lane where bit `bit` of its link byte is set.
        let set = |v: __m128i, bit: i32| {
            let b = _mm_set1_epi32(bit);
            _mm_cmpeq_epi32(_mm_and_si128(v, b), b)
        };
        let m_right = set(l, 1);
        let m_left = set(l_left, 1);
        let m_down = _mm_and_si128(set(l, 2), _mm_set1_epi32(-(r.down as i32)));
        let m_up = _mm_and_si128(set(l_up, 2), _mm_set1_epi32(-(r.up as i32)));
        // Samples per pixel: 1 plus the masks (each -1 where set).
        let n = _mm_sub_epi32(
            _mm_sub_epi32(_mm_set1_epi32(1), _mm_add_epi32(m_right, m_left)),
            _mm_add_epi32(m_down, m_up),
        );
        let neighbours = [
            _mm_and_si128(right, m_right),
            _mm_and_si128(left, m_left),
            _mm_and_si128(down, m_down),
            _mm_and_si128(up, m_up),
        ];
        // Sums in 16-bit lanes: pixels 0-1 (low) and 2-3 (high), a lane per channel.
        let mut lo = _mm_unpacklo_epi8(c, z);
        let mut hi = _mm_unpackhi_epi8(c, z);
        for v in neighbours {
            lo = _mm_add_epi16(lo, _mm_unpacklo_epi8(v, z));
            hi = _mm_add_epi16(hi, _mm_unpackhi_epi8(v, z));
        }
        // Each pixel's count in its four channel lanes.
        let n16 = _mm_packs_epi32(n, n);
        let n16 = _mm_unpacklo_epi16(n16, n16);
        let (n_lo, n_hi) = (_mm_unpacklo_epi32(n16, n16), _mm_unpackhi_epi32(n16, n16));
        // `(sum + n / 2) * RECIPROCAL[n] >> 16`, and the sum itself where n is 1.
        let divide = |sum: __m128i, n: __m128i| {
            // `RECIPROCAL[k]` in the lanes where n is k (2 to 5: each fits 16 bits).
            let pick = |k: usize| {
                let (count, r) = (_mm_set1_epi16(k as i16), RECIPROCAL[k] as u16 as i16);
                _mm_and_si128(_mm_cmpeq_epi16(n, count), _mm_set1_epi16(r))
            };
            let reciprocal = _mm_or_si128(
                _mm_or_si128(pick(2), pick(3)),
                _mm_or_si128(pick(4), pick(5)),
            );
            let q = _mm_mulhi_epu16(_mm_add_epi16(sum, _mm_srli_epi16(n, 1)), reciprocal);
            let alone = _mm_cmpeq_epi16(n, _mm_set1_epi16(1));
            _mm_or_si128(_mm_and_si128(alone, sum), _mm_andnot_si128(alone, q))
        };
        let out = _mm_packus_epi16(divide(lo, n_lo), divide(hi, n_hi));
        _mm_storeu_si128(o[..16].as_mut_ptr().cast(), out);
    }
}
