//! The film: f32 radiance sums with a sample count, tone mapped and sRGB-encoded to 8 bits.

use glam::Vec3;

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
        let k = exposure / self.samples.max(1) as f32;
        let mut out = Vec::with_capacity(self.sum.len() * 4);
        for s in &self.sum {
            let c = tone_map(*s * k);
            out.extend_from_slice(&[srgb8(c.x), srgb8(c.y), srgb8(c.z), 255]);
        }
        out
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

/// ACES filmic curve (Narkowicz 2015 fit), input linear radiance, output in `[0, 1]`.
pub fn tone_map(x: Vec3) -> Vec3 {
    let x = x.max(Vec3::ZERO);
    let (a, b, c, d, e) = (2.51, 0.03, 2.43, 0.59, 0.14);
    ((x * (a * x + b)) / (x * (c * x + d) + e)).clamp(Vec3::ZERO, Vec3::ONE)
}

/// Linear `[0, 1]` to an 8-bit sRGB value.
pub fn srgb8(x: f32) -> u8 {
    let x = x.clamp(0.0, 1.0);
    let s = if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}
