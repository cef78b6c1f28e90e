//! Resizing RGBA8 pictures for display: a reduced-resolution preview is stretched over the
//! window (bilinear), an image traced at a lower resolution scale is shown with square pixels
//! (nearest). Both run on all cores; an image already at the target size is passed through.

use rayon::prelude::*;

/// How a picture is resized.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Filter {
    /// Each target pixel takes the source pixel it falls in.
    Nearest,
    /// Each target pixel blends the four source pixels around its centre (edges clamped).
    Bilinear,
}

/// Resizes a `sw`x`sh` RGBA8 picture to `dw`x`dh`. Returns `src` itself when the sizes are equal.
///
/// # Panics
/// If `src` does not hold `sw * sh` pixels or a size is zero.
pub fn resize_rgba8(src: Vec<u8>, sw: u32, sh: u32, dw: u32, dh: u32, filter: Filter) -> Vec<u8> {
    assert!(sw > 0 && sh > 0 && dw > 0 && dh > 0, "empty picture");
    assert_eq!(src.len(), sw as usize * sh as usize * 4, "picture size");
    if (sw, sh) == (dw, dh) {
        return src;
    }
    match filter {
        Filter::Nearest => nearest(&src, sw, sh, dw, dh),
        Filter::Bilinear => bilinear(&src, sw, sh, dw, dh),
    }
}

/// The source index under each target index along one axis (pixel centres mapped).
fn nearest_index(src: u32, dst: u32) -> Vec<usize> {
    (0..dst)
        .map(|d| ((u64::from(d) * 2 + 1) * u64::from(src) / (u64::from(dst) * 2)) as usize)
        .collect()
}

fn nearest(src: &[u8], sw: u32, sh: u32, dw: u32, dh: u32) -> Vec<u8> {
    let xs = nearest_index(sw, dw);
    let ys = nearest_index(sh, dh);
    let (sw, dw) = (sw as usize, dw as usize);
    let mut out = vec![0u8; dw * dh as usize * 4];
    out.par_chunks_mut(dw * 4).enumerate().for_each(|(y, row)| {
        let s = &src[ys[y] * sw * 4..(ys[y] + 1) * sw * 4];
        for (px, &x) in row.chunks_exact_mut(4).zip(&xs) {
            px.copy_from_slice(&s[x * 4..x * 4 + 4]);
        }
    });
    out
}

/// For each target index along one axis: the two source indices to blend and the weight of
/// the second, in 1/256ths.
fn bilinear_taps(src: u32, dst: u32) -> Vec<(usize, usize, u32)> {
    let scale = src as f32 / dst as f32;
    let last = src as usize - 1;
    (0..dst)
        .map(|d| {
            let f = ((d as f32 + 0.5) * scale - 0.5).max(0.0);
            let i = (f as usize).min(last);
            let w = ((f - i as f32) * 256.0).round() as u32;
            (i, (i + 1).min(last), w.min(256))
        })
        .collect()
}

fn bilinear(src: &[u8], sw: u32, sh: u32, dw: u32, dh: u32) -> Vec<u8> {
    let xs = bilinear_taps(sw, dw);
    let ys = bilinear_taps(sh, dh);
    let (sw, dw) = (sw as usize, dw as usize);
    // Horizontal pass on the (few) source rows, kept at 8 extra bits of precision.
    let mut wide = vec![0u32; dw * 4 * sh as usize];
    wide.par_chunks_mut(dw * 4)
        .enumerate()
        .for_each(|(y, row)| {
            let s = &src[y * sw * 4..(y + 1) * sw * 4];
            for (px, &(a, b, w)) in row.chunks_exact_mut(4).zip(&xs) {
                for c in 0..4 {
                    px[c] = u32::from(s[a * 4 + c]) * (256 - w) + u32::from(s[b * 4 + c]) * w;
                }
            }
        });
    // Vertical pass: a blend of two wide rows per target row.
    let mut out = vec![0u8; dw * dh as usize * 4];
    out.par_chunks_mut(dw * 4).enumerate().for_each(|(y, row)| {
        let (a, b, w) = ys[y];
        let ra = &wide[a * dw * 4..(a + 1) * dw * 4];
        let rb = &wide[b * dw * 4..(b + 1) * dw * 4];
        for ((o, &va), &vb) in row.iter_mut().zip(ra).zip(rb) {
            *o = ((va * (256 - w) + vb * w + (1 << 15)) >> 16) as u8;
        }
    });
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn picture(w: u32, h: u32, f: impl Fn(u32, u32) -> [u8; 4]) -> Vec<u8> {
        (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .flat_map(|(x, y)| f(x, y))
            .collect()
    }

    #[test]
    fn same_size_is_passed_through() {
        let p = picture(3, 2, |x, y| [x as u8, y as u8, 7, 255]);
        for f in [Filter::Nearest, Filter::Bilinear] {
            assert_eq!(resize_rgba8(p.clone(), 3, 2, 3, 2, f), p);
        }
    }

    #[test]
    fn nearest_doubling_repeats_each_pixel() {
        let p = picture(3, 2, |x, y| [x as u8 * 10, y as u8 * 10, 1, 255]);
        let big = resize_rgba8(p, 3, 2, 6, 4, Filter::Nearest);
        let at = |x: usize, y: usize| &big[(y * 6 + x) * 4..(y * 6 + x) * 4 + 4];
        for y in 0..4 {
            for x in 0..6 {
                assert_eq!(at(x, y), [(x / 2) as u8 * 10, (y / 2) as u8 * 10, 1, 255]);
            }
        }
    }

    #[test]
    fn bilinear_keeps_a_constant_picture() {
        let p = picture(5, 3, |_, _| [200, 13, 0, 255]);
        let big = resize_rgba8(p, 5, 3, 37, 21, Filter::Bilinear);
        assert!(big.chunks_exact(4).all(|px| px == [200, 13, 0, 255]));
    }

    #[test]
    fn bilinear_follows_a_ramp_and_clamps_at_the_edges() {
        // A horizontal ramp 0, 100, 200 stretched to 12 pixels: pixel centres map back to
        // x = (d + 0.5) / 4 - 0.5, so values rise by 25 per pixel between the clamped ends.
        let p = picture(3, 1, |x, _| [x as u8 * 100, 0, 0, 255]);
        let big = resize_rgba8(p, 3, 1, 12, 2, Filter::Bilinear);
        let reds: Vec<u8> = big.chunks_exact(4).take(12).map(|px| px[0]).collect();
        assert_eq!(reds, [0, 0, 13, 38, 63, 88, 113, 138, 163, 188, 200, 200]);
        // Both target rows come from the single source row.
        assert_eq!(big[..48], big[48..]);
    }

    #[test]
    fn shrinking_works_too() {
        let p = picture(8, 8, |x, y| [(x * 30) as u8, (y * 30) as u8, 0, 255]);
        let small = resize_rgba8(p, 8, 8, 2, 2, Filter::Nearest);
        assert_eq!(small.len(), 16);
        assert_eq!(&small[..4], &[60, 60, 0, 255]);
        assert_eq!(&small[12..], &[180, 180, 0, 255]);
    }
}
