//! The moving picture's edge-avoiding à-trous wavelet filter (Dammertz, Sewtz, Hanika and
//! Lensch, "Edge-Avoiding À-Trous Wavelet Transform for fast Global Illumination Filtering",
//! HPG 2010; the spatial filter of SVGF, Schied et al. 2017).
//!
//! [`LEVELS`] passes of a 3 x 3 B-spline kernel (1 2 1 by 1 2 1) whose taps lie 1, 2, 4, ...
//! pixels apart, each pass filtering the last one's output, so one sample per pixel is averaged
//! over a footprint up to `2^LEVELS - 1` pixels to each side. A tap counts only where its pixel
//! shows the same surface as the centre's: both samples left the scene, or their normals agree,
//! the neighbour's point lies on the centre's tangent plane (and the centre's on the
//! neighbour's), and their albedos are alike. Each colour weighs as many samples as it averages
//! (a fresh sample one, a colour carried over from the converged still picture its count), the
//! centre the square of that, so converged colours are kept and fresh ones lean on them.
//! Geometric and material edges stay sharp; light and shadow within one surface are blurred,
//! which the moving picture trades for the noise of one sample a pixel. Colours are filtered in
//! linear light (the sRGB bytes decoded) and encoded again.

use rayon::prelude::*;

use super::NO_NORMAL;

#[cfg(target_arch = "x86_64")]
mod x86;
/// Without x86-64's AVX2 copies: the plain rows.
#[cfg(not(target_arch = "x86_64"))]
mod x86 {
    pub(super) use super::{filter_row, link_row};
}
use crate::color::{srgb8_fast, srgb8_table};

/// Passes of the filter: taps 1, 2 and 4 pixels apart, a footprint of up to 15 x 15 pixels.
pub(super) const LEVELS: u32 = 3;

/// Normals whose dot product is at least this (cos 25 degrees)
/// count as one surface: wider than the four-neighbour smoothing's, since taps lie further
/// apart on curved surfaces.
const SAME_NORMAL: f32 = 0.9;

/// Largest sine of the angle between a surface's tangent plane and the line to a neighbour's
/// point for the two to count as one surface (a step between parallel planes is an edge).
const PLANE: f32 = 0.1;

/// Largest difference of an albedo channel (in 255ths) between samples of one surface.
const SAME_ALBEDO: u32 = 26;

/// A pixel's links to its neighbours `d` pixels away, one bit each: right, down, down-right,
/// down-left. The four other directions are those neighbours' own bits.
const RIGHT: u8 = 1;
const DOWN: u8 = 2;
const DOWN_RIGHT: u8 = 4;
const DOWN_LEFT: u8 = 8;

/// What the filter reads of the render cache: per pixel, the sample's point, packed normal
/// ([`NO_NORMAL`] where it left the scene), albedo (linear, in 255ths) and colour (sRGB RGBA8,
/// alpha 0 where the pixel holds no sample).
pub(super) struct Guides<'a> {
    pub(super) width: usize,
    pub(super) height: usize,
    pub(super) points: &'a [[f32; 3]],
    pub(super) normals: &'a [[i8; 4]],
    pub(super) albedos: &'a [[u8; 4]],
    pub(super) colours: &'a [[u8; 4]],
}

/// The guides of every pixel as planes of floats, padded with `pad` empty pixels before and
/// after, so that every tap of every level lands inside them (a tap past an edge meets an empty
/// pixel or one no link leads to) and the loops over rows run without branches.
#[derive(Debug, Default)]
struct Planes {
    pad: usize,
    /// Unit normal (zero where the sample left the scene or there is none).
    n: [Vec<f32>; 3],
    /// The sample's point.
    p: [Vec<f32>; 3],
    /// The albedo's channels in 255ths in bytes 0 to 2, [`FILLED`] and [`SKY`] in byte 3.
    key: Vec<u32>,
    /// The samples the pixel's colour averages (at least 1): the colour's weight.
    weight: Vec<f32>,
}

/// Flags of a pixel's key: it holds a sample; its sample left the scene.
const FILLED: u32 = 1;
const SKY: u32 = 2;

impl Planes {
    /// Fills the planes from `g` with `pad` empty pixels before and after, reusing their
    /// memory (a picture's worth of fresh pages costs more than the filling).
    /// The colours are decoded from sRGB into `colour`, padded alike, in the same pass.
    fn fill(&mut self, g: &Guides, pad: usize, colour: &mut [Vec<f32>; 3]) {
        let len = g.colours.len() + 2 * pad;
        self.pad = pad;
        for v in self
            .n
            .iter_mut()
            .chain(&mut self.p)
            .chain(colour.iter_mut())
            .chain([&mut self.weight])
        {
            v.resize(len, 0.0);
        }
        self.key.resize(len, 0);
        // One pass over the pixels, in chunks, writing every plane.
        const CHUNK: usize = 4096;
        fn chunks(v: &mut [f32], pad: usize) -> Vec<&mut [f32]> {
            let len = v.len();
            v[pad..len - pad].chunks_mut(CHUNK).collect()
        }
        let [n0, n1, n2] = &mut self.n;
        let [p0, p1, p2] = &mut self.p;
        let [c0, c1, c2] = colour;
        let colours: Vec<_> = chunks(c0, pad)
            .into_iter()
            .zip(chunks(c1, pad))
            .zip(chunks(c2, pad))
            .collect();
        let planes: Vec<_> = chunks(n0, pad)
            .into_iter()
            .zip(chunks(n1, pad))
            .zip(chunks(n2, pad))
            .zip(chunks(p0, pad))
            .zip(chunks(p1, pad))
            .zip(chunks(p2, pad))
            .zip(self.key[pad..len - pad].chunks_mut(CHUNK))
            .zip(chunks(&mut self.weight, pad))
            .zip(colours)
            .enumerate()
            .collect();
        let table = srgb8_table();
        planes.into_par_iter().for_each(
            |(c, ((((((((n0, n1), n2), p0), p1), p2), key), weight), ((c0, c1), c2)))| {
                let from = c * CHUNK;
                for k in 0..key.len() {
                    let i = from + k;
                    let (n, p) = (g.normals[i], g.points[i]);
                    n0[k] = n[0] as f32 * (1.0 / 127.0);
                    n1[k] = n[1] as f32 * (1.0 / 127.0);
                    n2[k] = n[2] as f32 * (1.0 / 127.0);
                    (p0[k], p1[k], p2[k]) = (p[0], p[1], p[2]);
                    let [r, gr, b, _] = g.albedos[i];
                    let flags =
                        ((g.colours[i][3] != 0) as u32 * FILLED) | ((n == NO_NORMAL) as u32 * SKY);
                    key[k] = u32::from_le_bytes([r, gr, b, 0]) | flags << 24;
                    // A pixel without a sample weighs 1 too: no link leads to it, and its
                    // colour (black) divided by its weight stays finite.
                    weight[k] = g.albedos[i][3].max(1) as f32;
                    let px = g.colours[i];
                    c0[k] = table[px[0] as usize];
                    c1[k] = table[px[1] as usize];
                    c2[k] = table[px[2] as usize];
                }
            },
        );
    }

    /// The guides of `w` padded pixels from `start`.
    fn row(&self, start: usize, w: usize) -> Row<'_> {
        let r = start..start + w;
        Row {
            n: [
                &self.n[0][r.clone()],
                &self.n[1][r.clone()],
                &self.n[2][r.clone()],
            ],
            p: [
                &self.p[0][r.clone()],
                &self.p[1][r.clone()],
                &self.p[2][r.clone()],
            ],
            key: &self.key[r],
        }
    }

    /// Each pixel's links (padded like the planes) to its neighbours 1, 2, 4, ... pixels away
    /// in a `w x h` picture, one array a level (see [`RIGHT`] and the others): every level in
    /// one pass over the rows, so the threads meet once.
    fn links(&self, w: usize, h: usize, links: &mut [Vec<u8>; LEVELS as usize]) {
        let pad = self.pad;
        let mut rows: Vec<_> = Vec::new();
        for l in links.iter_mut() {
            l.resize(w * h + 2 * pad, 0);
            rows.push(l[pad..pad + w * h].chunks_mut(w).collect::<Vec<_>>());
        }
        let mut by_row: Vec<Vec<&mut [u8]>> = (0..h).map(|_| Vec::new()).collect();
        for level in rows {
            for (y, row) in level.into_iter().enumerate() {
                by_row[y].push(row);
            }
        }
        by_row
            .into_par_iter()
            .enumerate()
            .with_min_len(8)
            .for_each(|(y, mut rows)| {
                let p0 = pad + y * w;
                let here = self.row(p0, w);
                for (level, row) in rows.iter_mut().enumerate() {
                    row.fill(0);
                    let step = 1usize << level;
                    let q0 = p0 + step * w;
                    // Past a row's ends, or below the last rows, no link is made: the ranges
                    // leave those pixels out.
                    let n = w.saturating_sub(step);
                    x86::link_row(&here, &self.row(p0 + step, w), 0..n, RIGHT, row);
                    if y + step < h {
                        let (right, left) = (q0 + step, q0 - step);
                        x86::link_row(&here, &self.row(q0, w), 0..w, DOWN, row);
                        x86::link_row(&here, &self.row(right, w), 0..n, DOWN_RIGHT, row);
                        let xs = step.min(w)..w;
                        x86::link_row(&here, &self.row(left, w), xs, DOWN_LEFT, row);
                    }
                }
            });
    }
}

/// The guides of one row's worth of pixels (see [`Planes`]), each slice of the same length.
struct Row<'a> {
    n: [&'a [f32]; 3],
    p: [&'a [f32]; 3],
    key: &'a [u32],
}

/// Sets `bit` in `out[x]` for each `x` of `xs` where pixel `x` of `a` and pixel `x` of `b` show
/// the same surface. One pass of plain arithmetic over slices of one length, so that it
/// vectorizes.
#[inline(always)]
fn link_row(a: &Row, b: &Row, xs: std::ops::Range<usize>, bit: u8, out: &mut [u8]) {
    let r = xs.clone();
    let len = xs.len();
    fn cut<T>(s: &[T], r: std::ops::Range<usize>) -> &[T] {
        let len = r.len();
        &s[r][..len]
    }
    let f = |s| cut::<f32>(s, r.clone());
    let (anx, any, anz) = (f(a.n[0]), f(a.n[1]), f(a.n[2]));
    let (bnx, bny, bnz) = (f(b.n[0]), f(b.n[1]), f(b.n[2]));
    let (apx, apy, apz) = (f(a.p[0]), f(a.p[1]), f(a.p[2]));
    let (bpx, bpy, bpz) = (f(b.p[0]), f(b.p[1]), f(b.p[2]));
    let (ak, bk) = (cut(a.key, r.clone()), cut(b.key, r.clone()));
    let out = &mut out[r.clone()][..len];
    for x in 0..len {
        let dot = anx[x] * bnx[x] + any[x] * bny[x] + anz[x] * bnz[x];
        let (dx, dy, dz) = (bpx[x] - apx[x], bpy[x] - apy[x], bpz[x] - apz[x]);
        let off_a = (anx[x] * dx + any[x] * dy + anz[x] * dz).abs();
        let off_b = (bnx[x] * dx + bny[x] * dy + bnz[x] * dz).abs();
        let off = off_a.max(off_b);
        let plane = off * off <= PLANE * PLANE * (dx * dx + dy * dy + dz * dz);
        let (ka, kb) = (ak[x], bk[x]);
        // Albedo bytes 0 to 2, flags in byte 3: each channel's difference, without unpacking
        // to floats.
        let diff = |shift: u32| ((ka >> shift) & 0xff).abs_diff((kb >> shift) & 0xff);
        let albedo =
            (diff(0) <= SAME_ALBEDO) & (diff(8) <= SAME_ALBEDO) & (diff(16) <= SAME_ALBEDO);
        let (fa, fb) = (ka >> 24, kb >> 24);
        let both_filled = (fa & fb & FILLED) != 0;
        let (sky_a, sky_b) = ((fa & SKY) != 0, (fb & SKY) != 0);
        let surface = !sky_a & !sky_b & (dot >= SAME_NORMAL) & albedo & plane;
        out[x] |= ((both_filled & (surface | (sky_a & sky_b))) as u8) * bit;
    }
}

/// One tap of a row of the filter: the colours of the row of pixels it reads, the links that
/// say whether each counts, the link's bit, and the tap's kernel weight.
struct Tap<'a> {
    colour: [&'a [f32]; 3],
    /// The samples each colour averages.
    weight: &'a [f32],
    links: &'a [u8],
    bit: u8,
    k: f32,
}

/// One row of a pass of the filter into `out`: each pixel's centre colour weighed 4 times the
/// square of the samples it averages, and the taps' colours by their kernel weights where
/// linked times the samples each averages (so a colour from the converged still picture
/// outweighs a fresh sample beside it, and is itself kept), divided by the weights counted. One loop of plain arithmetic over slices of one
/// length, so that it vectorizes.
#[inline(always)]
///
/// The three outputs are arguments of their own: references inside an array carry no
/// promise that nothing else reads them, and the compiler would not vectorize the loop.
fn filter_row(
    taps: &[Tap; 8],
    centre: [&[f32]; 3],
    weight: &[f32],
    or: &mut [f32],
    og: &mut [f32],
    ob: &mut [f32],
) {
    let w = centre[0].len();
    let [cr, cg, cb] = centre.map(|c| &c[..w]);
    let weight = &weight[..w];
    let (or, og, ob) = (&mut or[..w], &mut og[..w], &mut ob[..w]);
    // Each tap's slices cut to the row's length, so the loop below indexes them unchecked.
    type Cut<'a> = ([&'a [f32]; 3], &'a [f32], &'a [u8], u8, f32);
    let t: [Cut; 8] = std::array::from_fn(|i| {
        let tap = &taps[i];
        let colour = tap.colour.map(|c| &c[..w]);
        (colour, &tap.weight[..w], &tap.links[..w], tap.bit, tap.k)
    });
    for x in 0..w {
        // The centre by the square of its samples: a colour of many samples is all but kept
        // (blurring a converged colour only adds error), while a fresh one is averaged with
        // its neighbours, the converged ones weighing most.
        let own = weight[x] * weight[x] * 4.0;
        let (mut r, mut g, mut b, mut total) = (cr[x] * own, cg[x] * own, cb[x] * own, own);
        for (colour, weight, links, bit, k) in &t {
            let k = ((links[x] & bit) != 0) as u8 as f32 * k * weight[x];
            r += colour[0][x] * k;
            g += colour[1][x] * k;
            b += colour[2][x] * k;
            total += k;
        }
        or[x] = r / total;
        og[x] = g / total;
        ob[x] = b / total;
    }
}

/// Memory the filter reuses from one picture to the next.
#[derive(Debug, Default)]
pub(super) struct Scratch {
    planes: Planes,
    links: [Vec<u8>; LEVELS as usize],
    colour: [Vec<f32>; 3],
    next: [Vec<f32>; 3],
}

impl Guides<'_> {
    /// The filtered picture, RGBA8; pixels without a sample stay empty (alpha 0).
    pub(super) fn filter(&self, scratch: &mut Scratch) -> Vec<u8> {
        let (w, h) = (self.width, self.height);
        let widest = 1usize << (LEVELS - 1);
        let pad = widest * (w + 1);
        let Scratch {
            planes,
            links,
            colour,
            next,
        } = scratch;
        planes.fill(self, pad, colour);
        let len = w * h + 2 * pad;
        for v in next.iter_mut() {
            v.resize(len, 0.0);
        }
        planes.links(w, h, links);
        for (level, links) in links.iter().enumerate() {
            let s = 1usize << level;
            let src = &*colour;
            let [r, g, b] = next;
            r[pad..pad + w * h]
                .par_chunks_mut(w)
                .zip(g[pad..pad + w * h].par_chunks_mut(w))
                .zip(b[pad..pad + w * h].par_chunks_mut(w))
                .enumerate()
                .with_min_len(8)
                .for_each(|(y, ((ro, go), bo))| {
                    let p0 = pad + y * w;
                    let (up, down) = (p0 - s * w, p0 + s * w);
                    let l = |start: usize| &links[start..start + w];
                    let c = |start: usize| {
                        let r = start..start + w;
                        [&src[0][r.clone()], &src[1][r.clone()], &src[2][r]]
                    };
                    // Each link is kept by the pixel above or to the left of it: the links
                    // from this pixel, from its left neighbour and from three pixels above.
                    let (here, left) = (l(p0), l(p0 - s));
                    let (above, above_left, above_right) = (l(up), l(up - s), l(up + s));
                    // The centre weighs 4, the four nearest taps 2, the corners 1.
                    let weights = |start: usize| &planes.weight[start..start + w];
                    let tap = |start, links, bit, k| Tap {
                        colour: c(start),
                        weight: weights(start),
                        links,
                        bit,
                        k,
                    };
                    let taps = [
                        tap(p0 + s, here, RIGHT, 2.0),
                        tap(down, here, DOWN, 2.0),
                        tap(down + s, here, DOWN_RIGHT, 1.0),
                        tap(down - s, here, DOWN_LEFT, 1.0),
                        tap(p0 - s, left, RIGHT, 2.0),
                        tap(up, above, DOWN, 2.0),
                        tap(up - s, above_left, DOWN_RIGHT, 1.0),
                        tap(up + s, above_right, DOWN_LEFT, 1.0),
                    ];
                    x86::filter_row(&taps, c(p0), weights(p0), ro, go, bo);
                });
            std::mem::swap(colour, next);
        }
        let mut out = vec![0u8; 4 * w * h];
        let [r, g, b] = &*colour;
        out.par_chunks_mut(4 * 4096)
            .zip(self.colours.par_chunks(4096))
            .enumerate()
            .for_each(|(c, (o, src))| {
                for (k, (px, s)) in o.chunks_exact_mut(4).zip(src).enumerate() {
                    if s[3] != 0 {
                        let i = pad + c * 4096 + k;
                        px.copy_from_slice(&[
                            srgb8_fast(r[i]),
                            srgb8_fast(g[i]),
                            srgb8_fast(b[i]),
                            255,
                        ]);
                    }
                }
            });
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `w x h` picture of samples: each pixel's point, normal, albedo and grey level (0 for
    /// no sample).
    struct Picture {
        w: usize,
        h: usize,
        points: Vec<[f32; 3]>,
        normals: Vec<[i8; 4]>,
        albedos: Vec<[u8; 4]>,
        colours: Vec<[u8; 4]>,
    }

    impl Picture {
        /// A floor seen from above: points on the plane y = 0, normals up, albedo grey.
        fn floor(w: usize, h: usize, grey: impl Fn(usize, usize) -> u8) -> Self {
            let mut p = Picture {
                w,
                h,
                points: Vec::new(),
                normals: Vec::new(),
                albedos: Vec::new(),
                colours: Vec::new(),
            };
            for y in 0..h {
                for x in 0..w {
                    let g = grey(x, y);
                    p.points.push([x as f32, 0.0, y as f32]);
                    p.normals.push([0, 127, 0, 0]);
                    p.albedos.push([128, 128, 128, 0]);
                    p.colours.push(if g == 0 { [0; 4] } else { [g, g, g, 255] });
                }
            }
            p
        }

        fn filtered(&self) -> Vec<u8> {
            let g = Guides {
                width: self.w,
                height: self.h,
                points: &self.points,
                normals: &self.normals,
                albedos: &self.albedos,
                colours: &self.colours,
            };
            g.filter(&mut Scratch::default())
                .chunks(4)
                .map(|p| p[0])
                .collect()
        }
    }

    fn spread(v: &[u8]) -> f64 {
        let mean = v.iter().map(|&g| g as f64).sum::<f64>() / v.len() as f64;
        (v.iter().map(|&g| (g as f64 - mean).powi(2)).sum::<f64>() / v.len() as f64).sqrt()
    }

    #[test]
    fn noise_on_one_surface_is_averaged_away() {
        // A checkerboard of two levels: one sample a pixel of a surface lit evenly.
        let p = Picture::floor(40, 30, |x, y| if (x + y) % 2 == 0 { 80 } else { 160 });
        let before: Vec<u8> = p.colours.iter().map(|c| c[0]).collect();
        let after = p.filtered();
        assert!(
            spread(&after) < spread(&before) / 8.0,
            "spread {} -> {}",
            spread(&before),
            spread(&after)
        );
    }

    /// Splits a floor of two levels down the middle by changing the right half's guides with
    /// `change`, and checks that no level crosses over.
    fn kept_apart(change: impl Fn(&mut Picture, usize)) {
        let (w, h) = (24, 16);
        let mut p = Picture::floor(w, h, |x, _| if x < w / 2 { 60 } else { 200 });
        for i in 0..w * h {
            if i % w >= w / 2 {
                change(&mut p, i);
            }
        }
        let after = p.filtered();
        for (i, &g) in after.iter().enumerate() {
            let want = if i % w < w / 2 { 60 } else { 200 };
            assert!(g.abs_diff(want) <= 1, "pixel {i}: {g}, want {want}");
        }
    }

    #[test]
    fn a_fold_between_surfaces_is_kept() {
        kept_apart(|p, i| p.normals[i] = [127, 0, 0, 0]);
    }

    #[test]
    fn a_step_between_parallel_planes_is_kept() {
        kept_apart(|p, i| p.points[i][1] = -3.0);
    }

    #[test]
    fn a_material_edge_is_kept() {
        kept_apart(|p, i| p.albedos[i] = [200, 40, 40, 0]);
    }

    #[test]
    fn the_sky_is_averaged_with_the_sky_only() {
        kept_apart(|p, i| {
            p.normals[i] = NO_NORMAL;
            p.points[i] = [1e30, 1e30, 1e30];
            p.albedos[i] = [0; 4];
        });
    }

    #[test]
    fn colours_of_many_samples_outweigh_a_fresh_one() {
        // A converged floor (255 samples a pixel) with one fresh, much brighter sample in the
        // middle: the filtered middle is the floor's level, not a blur of the two.
        let (w, h) = (9, 9);
        let middle = 4 * w + 4;
        let mut p = Picture::floor(w, h, |x, y| if (x, y) == (4, 4) { 250 } else { 100 });
        for (i, a) in p.albedos.iter_mut().enumerate() {
            a[3] = if i == middle { 1 } else { 255 };
        }
        let after = p.filtered();
        assert!(after[middle].abs_diff(100) <= 2, "middle {}", after[middle]);
        // Weighed alike, the fresh sample would pull the middle well up.
        for a in &mut p.albedos {
            a[3] = 1;
        }
        let alike = p.filtered()[middle];
        assert!(alike > 104, "middle weighed alike {alike}");
    }

    #[test]
    fn a_converged_picture_is_kept() {
        // The checkerboard again, each colour of 255 samples (the still picture's, carried):
        // detail that many samples agree on is not blurred away.
        let mut p = Picture::floor(40, 30, |x, y| if (x + y) % 2 == 0 { 80 } else { 160 });
        for a in &mut p.albedos {
            a[3] = 255;
        }
        for (i, (&g, c)) in p.filtered().iter().zip(&p.colours).enumerate() {
            assert!(g.abs_diff(c[0]) <= 3, "pixel {i}: {} -> {g}", c[0]);
        }
    }

    #[test]
    fn pixels_without_a_sample_stay_empty_and_are_no_neighbours() {
        // Every third pixel empty; the others of one level.
        let p = Picture::floor(17, 9, |x, y| if (x + 2 * y) % 3 == 0 { 0 } else { 120 });
        for (i, &g) in p.filtered().iter().enumerate() {
            let empty = p.colours[i][3] == 0;
            assert!(
                if empty { g == 0 } else { g.abs_diff(120) <= 1 },
                "pixel {i}: {g}"
            );
        }
    }

    #[test]
    fn the_cpus_wider_rows_give_the_plain_rows_bits() {
        // Pseudo-random guides and colours, rows of lengths around the vector widths.
        let mut seed = 99u32;
        let mut next = move || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            seed >> 8
        };
        for w in [1usize, 7, 8, 9, 31, 33] {
            let h = 5;
            let mut p = Picture::floor(w, h, |_, _| 1);
            for i in 0..w * h {
                let r = next();
                p.normals[i] =
                    [[0, 127, 0, 0], [127, 0, 0, 0], [0, 120, 40, 0], NO_NORMAL][r as usize % 4];
                p.points[i][1] = (next() % 3) as f32 * 0.05;
                p.albedos[i][0] = (next() % 60) as u8;
                let g = (next() % 256) as u8;
                p.colours[i] = if next() % 7 == 0 {
                    [0; 4]
                } else {
                    [g, g / 2, 255 - g, 255]
                };
            }
            let g = Guides {
                width: w,
                height: h,
                points: &p.points,
                normals: &p.normals,
                albedos: &p.albedos,
                colours: &p.colours,
            };
            let mut planes = Planes::default();
            planes.fill(&g, 2 * (w + 1), &mut Default::default());
            for step in [1, 2] {
                for y in 0..h - step.min(h - 1) {
                    let p0 = planes.pad + y * w;
                    let (a, b) = (planes.row(p0, w), planes.row(p0 + step * w, w));
                    let (mut plain, mut wide) = (vec![0u8; w], vec![0u8; w]);
                    link_row(&a, &b, 0..w, DOWN, &mut plain);
                    x86::link_row(&a, &b, 0..w, DOWN, &mut wide);
                    assert_eq!(plain, wide, "links, width {w}, step {step}");
                }
            }
            let colour: Vec<f32> = (0..3 * w).map(|_| (next() % 1000) as f32 / 999.0).collect();
            let links: Vec<u8> = (0..w).map(|_| (next() % 16) as u8).collect();
            let weight: Vec<f32> = (0..w).map(|_| (next() % 255 + 1) as f32).collect();
            let taps: [Tap; 8] = std::array::from_fn(|t| Tap {
                colour: [&colour[..w], &colour[w..2 * w], &colour[2 * w..]],
                weight: &weight,
                links: &links,
                bit: 1 << (t % 4),
                k: [2.0, 1.0][t % 2],
            });
            let centre = [&colour[w..2 * w], &colour[2 * w..], &colour[..w]];
            type Row3<'a> = fn(&[Tap; 8], [&[f32]; 3], &[f32], &mut [f32], &mut [f32], &mut [f32]);
            let run = |f: Row3| {
                let mut out = vec![0.0f32; 3 * w];
                let (r, rest) = out.split_at_mut(w);
                let (g, b) = rest.split_at_mut(w);
                f(&taps, centre, &weight, r, g, b);
                out.iter().map(|v| v.to_bits()).collect::<Vec<u32>>()
            };
            assert_eq!(run(filter_row), run(x86::filter_row), "filter, width {w}");
        }
    }
}
