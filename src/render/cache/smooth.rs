//! The moving picture's four-neighbour smoothing: each sample averaged with those of its four
//! neighbours that show the same surface (normals within about 18 degrees, or both off the
//! scene). Four pixels at a time with SSE2 on x86-64 (`smooth_sse2`), with the same bytes as
//! the plain loop here.

use super::{NO_NORMAL, RenderCache};

impl RenderCache {
    /// Per pixel, whether its sample and its right neighbour's show the same surface (bit 0),
    /// and its sample and its lower neighbour's (bit 1): both left the scene, or both hit
    /// surfaces whose normals agree.
    fn links(&self) -> Vec<u8> {
        let (w, h) = (self.width as usize, self.height as usize);
        let mut links = vec![0u8; w * h];
        // Written as plain loops over rows without branches, so that they vectorize.
        let same = |a: [i8; 4], b: [i8; 4], filled_a: u8, filled_b: u8| -> u8 {
            let dot =
                a[0] as i32 * b[0] as i32 + a[1] as i32 * b[1] as i32 + a[2] as i32 * b[2] as i32;
            let (sky_a, sky_b) = (a == NO_NORMAL, b == NO_NORMAL);
            let surface = (!sky_a & !sky_b & (dot >= SAME_NORMAL)) | (sky_a & sky_b);
            (surface & (filled_a != 0) & (filled_b != 0)) as u8
        };
        for y in 0..h {
            let row = y * w..(y + 1) * w;
            let (n, c) = (&self.normals[row.clone()], &self.colours[row.clone()]);
            let out = &mut links[row];
            for x in 0..w - 1 {
                out[x] = same(n[x], n[x + 1], c[x][3], c[x + 1][3]);
            }
            if y + 1 < h {
                let below = (y + 1) * w..(y + 2) * w;
                let (nb, cb) = (&self.normals[below.clone()], &self.colours[below]);
                for x in 0..w {
                    out[x] |= same(n[x], nb[x], c[x][3], cb[x][3]) << 1;
                }
            }
        }
        links
    }

    /// The colours, each sample averaged with those of its four neighbours that show the same
    /// surface (see [`Self::links`]); holes stay holes. Four pixels at a time with SSE2 on
    /// x86-64 (`simd`), else (and at the rows' ends) one by one.
    pub(super) fn smoothed(&self, simd: bool) -> Vec<u8> {
        let (w, h) = (self.width as usize, self.height as usize);
        let links = self.links();
        let mut out = vec![0u8; 4 * w * h];
        for (y, o) in out.chunks_exact_mut(4 * w).enumerate() {
            let row = y * w..(y + 1) * w;
            let (c, l) = (&self.colours[row.clone()], &links[row.clone()]);
            // Above and below: the neighbouring rows, or this row with no links at the edges.
            let (uc, ul, up) = if y > 0 {
                let above = row.start - w..row.start;
                (&self.colours[above.clone()], &links[above], 1)
            } else {
                (c, l, 0)
            };
            let (dc, down) = if y + 1 < h {
                (&self.colours[row.end..row.end + w], 1)
            } else {
                (c, 0)
            };
            let rows = SmoothRows {
                c,
                l,
                uc,
                ul,
                up,
                dc,
                down,
            };
            #[cfg(target_arch = "x86_64")]
            let done = if simd {
                super::smooth_sse2::middle(&rows, o)
            } else {
                0..0
            };
            #[cfg(not(target_arch = "x86_64"))]
            let done = {
                let _ = simd;
                0..0
            };
            smooth_pixels(&rows, 0..done.start, o);
            smooth_pixels(&rows, done.end..w, o);
        }
        out
    }
}

/// One row of the moving picture to smooth: its colours and links, the row above's (with
/// `up` 0 at the top, where they are this row's and unused) and the row below's colours (with
/// `down` 0 at the bottom).
pub(super) struct SmoothRows<'a> {
    pub c: &'a [[u8; 4]],
    pub l: &'a [u8],
    pub uc: &'a [[u8; 4]],
    pub ul: &'a [u8],
    pub up: u8,
    pub dc: &'a [[u8; 4]],
    pub down: u8,
}

/// Pixels `xs` of a row of [`RenderCache::smoothed`] into `o` (the row's RGBA8), one at a
/// time: the reference the SIMD version is tested against.
fn smooth_pixels(r: &SmoothRows, xs: std::ops::Range<usize>, o: &mut [u8]) {
    let w = r.c.len();
    for x in xs {
        let (xl, xr) = (x.saturating_sub(1), (x + 1).min(w - 1));
        // Links to the right and below are never set past the edges.
        let m = [
            (r.l[x] & 1) as u32,
            ((x > 0) as u8 & r.l[xl] & 1) as u32,
            ((r.l[x] >> 1) & 1 & r.down) as u32,
            ((r.ul[x] >> 1) & 1 & r.up) as u32,
        ];
        let nb = [r.c[xr], r.c[xl], r.dc[x], r.uc[x]];
        let n = 1 + m[0] + m[1] + m[2] + m[3];
        // `sum / n` rounded, by a multiply (n is 1 to 5).
        let (rc, half) = (RECIPROCAL[n as usize], n / 2);
        let px = &mut o[4 * x..4 * x + 4];
        for k in 0..3 {
            let sum = r.c[x][k] as u32
                + nb[0][k] as u32 * m[0]
                + nb[1][k] as u32 * m[1]
                + nb[2][k] as u32 * m[2]
                + nb[3][k] as u32 * m[3];
            px[k] = (((sum + half) * rc) >> 16) as u8;
        }
        px[3] = r.c[x][3];
    }
}

/// `ceil(2^16 / n)` for the averages of 1 to 5 samples: `(s * RECIPROCAL[n]) >> 16` is
/// `s / n` for every sum `s` of `n` bytes.
pub(super) const RECIPROCAL: [u32; 6] = [0, 65536, 32768, 21846, 16384, 13108];

/// Normals whose packed dot product is at least this (about cos 18 degrees) count as one surface.
const SAME_NORMAL: i32 = (0.95 * 127.0 * 127.0) as i32;

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;
    use crate::render::cache::{MovingFilter, NO_COLOUR, pack_normal};

    fn painted(w: u32, h: u32, normals: &[[i8; 4]], grey: &[u8]) -> RenderCache {
        let mut c = RenderCache::new(w, h, 1.0);
        c.normals = normals.to_vec();
        c.colours = grey
            .iter()
            .map(|&g| if g == 0 { NO_COLOUR } else { [g, g, g, 255] })
            .collect();
        c.points = vec![[0.0; 3]; grey.len()];
        c.albedos = vec![[128, 128, 128, 0]; grey.len()];
        c.holes = grey.iter().filter(|&&g| g == 0).count();
        c
    }

    #[test]
    fn smoothing_averages_samples_of_one_surface_and_keeps_edges() {
        let (up, side) = (pack_normal(Vec3::Y), pack_normal(Vec3::X));
        // A row: three floor samples, one of a wall, two that left the scene.
        let mut c = painted(
            6,
            1,
            &[up, up, up, side, NO_NORMAL, NO_NORMAL],
            &[90, 120, 150, 250, 30, 60],
        );
        let grey = |rgba: Vec<u8>| rgba.chunks(4).map(|p| p[0]).collect::<Vec<u8>>();
        assert_eq!(
            grey(c.to_rgba8(MovingFilter::Off)),
            [90, 120, 150, 250, 30, 60]
        );
        // Each floor sample with its floor neighbours, the wall alone, the sky with the sky.
        assert_eq!(
            grey(c.to_rgba8(MovingFilter::Neighbours)),
            [105, 120, 135, 250, 45, 45]
        );
        // A column: the links go down as well; a hole is no neighbour (and is filled after).
        let mut c = painted(1, 4, &[up, up, up, up], &[100, 200, 0, 50]);
        let s = grey(c.to_rgba8(MovingFilter::Neighbours));
        assert_eq!((s[0], s[1], s[3]), (150, 150, 50));
        assert_ne!(s[2], 0, "the hole is filled for display");
    }

    #[test]
    fn smoothing_four_pixels_at_a_time_equals_one_at_a_time() {
        // Pseudo-random colours, holes, sky and two normals, at widths around the four-pixel
        // steps and the rows' ends.
        let mut seed = 12345u32;
        let mut next = move || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            seed >> 8
        };
        let normals = [pack_normal(Vec3::Y), pack_normal(Vec3::X), NO_NORMAL];
        for w in 1..=19u32 {
            for h in 1..=4u32 {
                let n = (w * h) as usize;
                let norms: Vec<[i8; 4]> = (0..n).map(|_| normals[next() as usize % 3]).collect();
                let grey: Vec<u8> = (0..n).map(|_| (next() % 256) as u8).collect();
                let mut c = painted(w, h, &norms, &grey);
                for col in &mut c.colours {
                    if col[3] != 0 {
                        col[1] = (next() % 256) as u8;
                        col[2] = (next() % 256) as u8;
                    }
                }
                assert_eq!(c.smoothed(true), c.smoothed(false), "{w}x{h}");
            }
        }
    }
}
