//! The film: f32 radiance sums with a sample count, tone mapped and sRGB-encoded to 8 bits.

use glam::Vec3;

use crate::color::{srgb8_lookup, srgb8_lut};

/// Accumulated radiance of an image.
#[derive(Clone, Debug, PartialEq)]
pub struct Film {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Sum of the radiance samples of each pixel, row 0 at the top.
    pub sum: Vec<Vec3>,
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
            sum: vec![Vec3::ZERO; width as usize * height as usize],
            samples: 0,
            rejected: 0,
        }
    }

    /// Mean radiance of each pixel (linear).
    pub fn mean(&self) -> Vec<Vec3> {
        let k = 1.0 / self.samples.max(1) as f32;
        self.sum.iter().map(|s| *s * k).collect()
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
pub fn encode_rgba8(sums: &[Vec3], k: f32, out: &mut [u8]) {
    use rayon::prelude::*;
    const CHUNK: usize = 4096;
    out.par_chunks_mut(CHUNK * 4)
        .zip(sums.par_chunks(CHUNK))
        .for_each(|(o, s)| {
            for (px, v) in o.chunks_exact_mut(4).zip(s) {
                px.copy_from_slice(&encode_pixel(*v, k));
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
