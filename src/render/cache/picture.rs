//! The moving picture as shown: the samples' colours through the chosen filter, and pixels
//! still without a sample filled from coarser averages of their neighbourhood (pull-push).

use glam::Vec3;
use rayon::prelude::*;

use super::{MovingFilter, RenderCache, wavelet};

impl RenderCache {
    /// The picture, RGBA8: the colours through `filter` (one sample per pixel is noisy: see
    /// [`MovingFilter`]), holes filled from the nearest filled pixels around them (pull-push),
    /// black in an empty cache.
    pub fn to_rgba8(&mut self, filter: MovingFilter) -> Vec<u8> {
        let mut out = match filter {
            MovingFilter::Off => self.colours.as_flattened().to_vec(),
            MovingFilter::Neighbours => self.smoothed(true),
            MovingFilter::Wavelet => wavelet::Guides {
                width: self.width as usize,
                height: self.height as usize,
                points: &self.points,
                normals: &self.normals,
                albedos: &self.albedos,
                colours: &self.colours,
            }
            .filter(&mut self.wavelet),
        };
        if self.holes == 0 {
            return out;
        }
        let (w, h) = (self.width, self.height);
        let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
        let colours = &self.colours;
        let coarse = halve(w, h, 4096, |i| {
            let [r, g, b, a] = colours[i];
            (a != 0).then(|| Vec3::new(r as f32, g as f32, b as f32))
        });
        let coarse = pull_push(&coarse, cw, ch);
        out.par_chunks_mut(4 * 4096).enumerate().for_each(|(c, o)| {
            for (k, px) in o.chunks_exact_mut(4).enumerate() {
                if px[3] == 0 {
                    let i = (c * 4096 + k) as u32;
                    let (x, y) = (i % w, i / w);
                    let v = coarse[((y / 2) * cw + x / 2) as usize];
                    px.copy_from_slice(&[v.x as u8, v.y as u8, v.z as u8, 255]);
                }
            }
        });
        out
    }
}

/// The picture of half the size (rounded up) whose pixels average the filled pixels (`pixel(i)`
/// some) of each 2 x 2 block of a `w x h` one; a block with none stays empty.
fn halve(
    w: u32,
    h: u32,
    min_len: usize,
    pixel: impl Fn(usize) -> Option<Vec3> + Sync,
) -> Vec<Option<Vec3>> {
    let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
    (0..cw * ch)
        .into_par_iter()
        .with_min_len(min_len)
        .map(|c| {
            let (cx, cy) = (c % cw, c / cw);
            let mut sum = Vec3::ZERO;
            let mut n = 0;
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let (x, y) = (2 * cx + dx, 2 * cy + dy);
                if x < w
                    && y < h
                    && let Some(p) = pixel((y * w + x) as usize)
                {
                    sum += p;
                    n += 1;
                }
            }
            (n > 0).then(|| sum / n as f32)
        })
        .collect()
}

/// Fills the holes of a picture from coarser averages of its filled pixels (Gortler et al.,
/// "The Lumigraph", 1996): each level halves the size, averaging the filled pixels of each 2 x 2
/// block; going back up, a hole takes its block's average.
fn pull_push(pixels: &[Option<Vec3>], w: u32, h: u32) -> Vec<Vec3> {
    if w <= 1 && h <= 1 || pixels.iter().all(Option::is_some) {
        return pixels.iter().map(|p| p.unwrap_or(Vec3::ZERO)).collect();
    }
    let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
    let coarse = halve(w, h, 1024, |i| pixels[i]);
    let coarse = pull_push(&coarse, cw, ch);
    pixels
        .par_iter()
        .enumerate()
        .with_min_len(4096)
        .map(|(i, p)| {
            p.unwrap_or_else(|| {
                let (x, y) = (i as u32 % w, i as u32 / w);
                coarse[((y / 2) * cw + x / 2) as usize]
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pull_push_fills_holes_and_keeps_filled_pixels() {
        let mut p = vec![None; 8 * 8];
        p[0] = Some(Vec3::ONE);
        p[63] = Some(Vec3::splat(3.0));
        let out = pull_push(&p, 8, 8);
        assert_eq!(out[0], Vec3::ONE);
        assert_eq!(out[63], Vec3::splat(3.0));
        assert!(out.iter().all(|v| v.x >= 1.0 && v.x <= 3.0));
    }
}
