//! The film: radiance sums with a sample count, tone mapped and sRGB-encoded to 8 bits.
//!
//! Sums are kept in fixed point ([`Sum`]): integers add the same in any order, so a render
//! split by sample ranges and merged gives the bits of the whole render
//! ([`crate::render::part`]).

use glam::Vec3;

use crate::color::{srgb8_lookup, srgb8_lut};

/// A pixel's sum of radiance samples, each channel in fixed point: integer units of
/// [`Sum::UNIT`]` = 2^-24`. Each sample is rounded to a whole number of units once, as it is
/// added (a sample of 1 or more loses nothing: an f32 that large is a whole number of units
/// already), and integers add exactly, so a pixel's sum is the same bits in whatever groups
/// and order its samples were added. A channel holds sums up to about 5.5e11 (past that it
/// saturates).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Sum(pub [i64; 3]);

impl Sum {
    /// No samples.
    pub const ZERO: Sum = Sum([0; 3]);
    /// Units per radiance unit.
    pub const SCALE: f32 = 16_777_216.0;
    /// The radiance of one unit.
    pub const UNIT: f64 = 1.0 / 16_777_216.0;

    /// The sum of the one sample `v` (finite).
    #[inline]
    pub fn of(v: Vec3) -> Sum {
        // Scaling by a power of two is exact; rounding to a whole number of units is the
        // only rounding, and the cast saturates.
        let fixed = |x: f32| (x * Self::SCALE).round_ties_even() as i64;
        Sum([fixed(v.x), fixed(v.y), fixed(v.z)])
    }

    /// Adds another sum (saturating).
    #[inline]
    pub fn add(&mut self, other: Sum) {
        for (a, b) in self.0.iter_mut().zip(other.0) {
            *a = a.saturating_add(b);
        }
    }

    /// Adds the sample `v` (finite).
    #[inline]
    pub fn add_sample(&mut self, v: Vec3) {
        self.add(Sum::of(v));
    }

    /// The sum as radiance.
    #[inline]
    pub fn to_vec3(self) -> Vec3 {
        let f = |x: i64| (x as f64 * Self::UNIT) as f32;
        Vec3::new(f(self.0[0]), f(self.0[1]), f(self.0[2]))
    }
}

impl From<Sum> for Vec3 {
    fn from(s: Sum) -> Vec3 {
        s.to_vec3()
    }
}

/// Accumulated radiance of an image.
#[derive(Clone, Debug, PartialEq)]
pub struct Film {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Sum of the radiance samples of each pixel, row 0 at the top.
    pub sum: Vec<Sum>,
    /// Samples added to every pixel.
    pub samples: u32,
    /// Samples that were NaN or infinite and were left out (counted, never added).
    pub rejected: u64,
}

impl Film {
    /// A black film with no samples.
    pub fn new(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            sum: vec![Sum::ZERO; width as usize * height as usize],
            samples: 0,
            rejected: 0,
        }
    }

    /// Mean radiance of each pixel (linear).
    pub fn mean(&self) -> Vec<Vec3> {
        let k = 1.0 / self.samples.max(1) as f32;
        self.sum.iter().map(|s| s.to_vec3() * k).collect()
    }

    /// Tone maps (ACES fit of Narkowicz 2015, after `exposure`) and encodes sRGB to RGBA8.
    pub fn to_rgba8(&self, exposure: f32) -> Vec<u8> {
        let mut out = vec![0u8; self.sum.len() * 4];
        let k = exposure / self.samples.max(1) as f32;
        encode_rgba8(&self.sum, k, &mut out);
        out
    }

    /// Writes the image by the file's extension ([`OutputKind`]): `.exr` (32-bit float) and
    /// `.hdr` (Radiance RGBE) hold the mean linear radiance, unscaled; `.png` the tone-mapped
    /// picture after `exposure`.
    pub fn save(&self, path: &std::path::Path, exposure: f32) -> anyhow::Result<()> {
        match OutputKind::of(path)? {
            OutputKind::Linear => self.save_linear(path),
            OutputKind::ToneMapped => self.save_png(path, exposure),
        }
    }

    /// Writes the mean linear radiance as EXR or HDR (by the extension); non-finite values
    /// (never added, but a film can be built by hand) are written as 0.
    pub fn save_linear(&self, path: &std::path::Path) -> anyhow::Result<()> {
        use anyhow::Context;
        let data: Vec<f32> = self
            .mean()
            .iter()
            .flat_map(|v| v.to_array())
            .map(|x| if x.is_finite() { x.max(0.0) } else { 0.0 })
            .collect();
        image::Rgb32FImage::from_raw(self.width, self.height, data)
            .context("film size does not match its pixels")?
            .save(path)
            .with_context(|| format!("{}: cannot write linear image", path.display()))
    }

    /// Writes the tone-mapped image as PNG.
    pub fn save_png(&self, path: &std::path::Path, exposure: f32) -> anyhow::Result<()> {
        use anyhow::Context;
        image::save_buffer(
            path,
            &self.to_rgba8(exposure),
            self.width,
            self.height,
            image::ColorType::Rgba8,
        )
        .with_context(|| format!("{}: cannot write PNG", path.display()))
    }
}

/// What an output file holds, by its extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputKind {
    /// `.png`: tone mapped and sRGB encoded, 8 bits.
    ToneMapped,
    /// `.exr` or `.hdr`: linear radiance in floats.
    Linear,
}

impl OutputKind {
    /// The kind of `path`, or an error naming it when the extension is none of these (checked
    /// before a render starts, so a long render is not lost to a typo).
    pub fn of(path: &std::path::Path) -> anyhow::Result<OutputKind> {
        let ext = path.extension().and_then(|e| e.to_str());
        match ext.map(|e| e.to_ascii_lowercase()).as_deref() {
            Some("png") => Ok(OutputKind::ToneMapped),
            Some("exr" | "hdr") => Ok(OutputKind::Linear),
            _ => anyhow::bail!(
                "{}: unknown image type (expected .png, .exr or .hdr)",
                path.display()
            ),
        }
    }
}

/// ACES filmic curve (Narkowicz 2015 fit), input linear radiance, output in `[0, 1]`.
pub fn tone_map(x: Vec3) -> Vec3 {
    let x = x.max(Vec3::ZERO);
    let (a, b, c, d, e) = (2.51, 0.03, 2.43, 0.59, 0.14);
    ((x * (a * x + b)) / (x * (c * x + d) + e)).clamp(Vec3::ZERO, Vec3::ONE)
}

/// Tone maps `sums * k` and writes sRGB RGBA8 into `out` (four bytes per value), on all
/// cores: the encoding every picture of a film goes through, in the viewer as in PNGs.
pub fn encode_rgba8<T: Copy + Sync + Into<Vec3>>(sums: &[T], k: f32, out: &mut [u8]) {
    use rayon::prelude::*;
    const CHUNK: usize = 4096;
    out.par_chunks_mut(CHUNK * 4)
        .zip(sums.par_chunks(CHUNK))
        .for_each(|(o, s)| {
            for (px, v) in o.chunks_exact_mut(4).zip(s) {
                px.copy_from_slice(&encode_pixel((*v).into(), k));
            }
        });
}

/// Tone maps `v * k` and encodes it as sRGB RGBA8 (opaque): one pixel of [`encode_rgba8`].
#[inline]
pub fn encode_pixel(v: Vec3, k: f32) -> [u8; 4] {
    let lut = srgb8_lut();
    let c = tone_map(v * k);
    [
        srgb8_lookup(lut, c.x),
        srgb8_lookup(lut, c.y),
        srgb8_lookup(lut, c.z),
        255,
    ]
}

/// Root mean square difference of the colour channels (alpha left out) of two RGBA8 pictures
/// of the same size, in 8-bit levels.
pub fn rmse_levels(a: &[u8], b: &[u8]) -> f64 {
    let (mut sum, mut n) = (0.0f64, 0u64);
    for (p, q) in a.chunks_exact(4).zip(b.chunks_exact(4)) {
        for c in 0..3 {
            let d = p[c] as f64 - q[c] as f64;
            sum += d * d;
            n += 1;
        }
    }
    (sum / n.max(1) as f64).sqrt()
}
