//! Image textures: decoded once (PNG or JPEG, through `image`), sampled with bilinear filtering
//! and a wrap mode per axis.
//!
//! Texels are kept as 8-bit RGBA, as the file has them (a quarter of the memory of f32), and
//! turned to linear values when sampled: colour maps (base colour, emission, OBJ `map_Kd`) hold
//! sRGB-encoded values and are decoded through a 256-entry table before filtering, so the
//! filter blends light, not encoded values; the alpha channel is always linear.

use std::path::Path;

use anyhow::{Context, Result};
use glam::{Affine2, Vec2, Vec4};

/// What a texture coordinate outside `[0, 1]` reads (glTF's sampler wrap modes).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Wrap {
    /// The image tiles (`fract`).
    #[default]
    Repeat,
    /// The image tiles, every other copy mirrored.
    MirroredRepeat,
    /// The edge texels extend outwards.
    ClampToEdge,
}

impl Wrap {
    /// The texel index for integer coordinate `i` of an axis `n` texels long.
    fn index(self, i: i64, n: u32) -> usize {
        let n = n as i64;
        let j = match self {
            Wrap::Repeat => i.rem_euclid(n),
            Wrap::ClampToEdge => i.clamp(0, n - 1),
            Wrap::MirroredRepeat => {
                let m = i.rem_euclid(2 * n);
                if m < n { m } else { 2 * n - 1 - m }
            }
        };
        j as usize
    }
}

/// A decoded image with its sampling rules.
#[derive(Clone, PartialEq)]
pub struct Texture {
    /// Where it came from (a file, or `file#images[2]` for an embedded image), for messages.
    pub name: String,
    width: u32,
    height: u32,
    texels: Vec<[u8; 4]>,
    /// Whether the colour channels are sRGB-encoded (decoded when sampled).
    pub srgb: bool,
    /// Wrap mode along `u` (glTF `wrapS`).
    pub wrap_u: Wrap,
    /// Wrap mode along `v` (glTF `wrapT`).
    pub wrap_v: Wrap,
    /// Applied to texture coordinates before the lookup (glTF `KHR_texture_transform`).
    pub transform: Option<Affine2>,
    /// Which of the mesh's texture coordinate sets it reads: 0, or 1 for glTF's `TEXCOORD_1`
    /// (see [`crate::scene::Mesh::uv_at`]).
    pub uv_set: u8,
}

impl std::fmt::Debug for Texture {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "Texture({}, {}x{}, srgb {}, wrap {:?}/{:?})",
            self.name, self.width, self.height, self.srgb, self.wrap_u, self.wrap_v
        )
    }
}

impl Texture {
    /// A texture from RGBA8 texels, row by row from the top (`v = 0` is the first row, as in
    /// glTF and in OBJ files read with their `v` flipped).
    ///
    /// # Panics
    /// When `texels` does not hold `width * height` entries or either size is 0.
    pub fn from_rgba8(
        name: String,
        width: u32,
        height: u32,
        texels: Vec<[u8; 4]>,
        srgb: bool,
    ) -> Self {
        assert!(width > 0 && height > 0, "a texture has texels");
        assert_eq!(texels.len(), width as usize * height as usize);
        Self {
            name,
            width,
            height,
            texels,
            srgb,
            wrap_u: Wrap::Repeat,
            wrap_v: Wrap::Repeat,
            transform: None,
            uv_set: 0,
        }
    }

    /// Decodes PNG or JPEG bytes (the format is found from the bytes). `name` is used in
    /// messages.
    pub fn decode(name: &str, bytes: &[u8], srgb: bool) -> Result<Self> {
        let img = image::load_from_memory(bytes)
            .with_context(|| format!("{name}: cannot decode image"))?
            .to_rgba8();
        let (w, h) = img.dimensions();
        anyhow::ensure!(w > 0 && h > 0, "{name}: empty image");
        let texels = img.pixels().map(|p| p.0).collect();
        Ok(Self::from_rgba8(name.to_string(), w, h, texels, srgb))
    }

    /// Reads and decodes an image file.
    pub fn load(path: &Path, srgb: bool) -> Result<Self> {
        let bytes = super::read_file(path)?;
        Self::decode(&path.display().to_string(), &bytes, srgb)
    }

    /// True when every texel's red, green and blue are equal (a grey image: a height map,
    /// not a normal map).
    pub fn is_grey(&self) -> bool {
        self.texels.iter().all(|[r, g, b, _]| r == g && g == b)
    }

    /// The texels' bytes, RGBA8 row by row from the top.
    pub fn texel_bytes(&self) -> &[u8] {
        self.texels.as_flattened()
    }

    /// Width and height in texels.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// One texel in linear values.
    fn texel(&self, x: usize, y: usize) -> Vec4 {
        let [r, g, b, a] = self.texels[y * self.width as usize + x];
        let alpha = a as f32 / 255.0;
        if self.srgb {
            let t = crate::color::srgb8_table();
            Vec4::new(t[r as usize], t[g as usize], t[b as usize], alpha)
        } else {
            Vec4::new(r as f32, g as f32, b as f32, a as f32) / 255.0
        }
    }

    /// The linear RGBA value at texture coordinate `uv` (`(0, 0)` the top-left corner of the
    /// image, `(1, 1)` the bottom-right), bilinearly filtered between the four nearest texel
    /// centres, after [`Texture::transform`]. A non-finite coordinate reads texel (0, 0).
    pub fn sample(&self, uv: Vec2) -> Vec4 {
        let ([t00, t10, t01, t11], fx, fy) = self.corners(uv);
        let top = t00.lerp(t10, fx);
        let bottom = t01.lerp(t11, fx);
        top.lerp(bottom, fy)
    }

    /// The gradient, with respect to `uv`, of the luminance (Rec. 709 weights) of the linear
    /// values [`Texture::sample`] reads: the bilinear interpolation's own derivative, constant
    /// between texel centres, through [`Texture::transform`]. Bump mapping reads a height map
    /// by it, as Mitsuba's `bumpmap` does with its bitmap's `eval_1_grad`.
    pub fn luminance_gradient(&self, uv: Vec2) -> Vec2 {
        const WEIGHTS: Vec4 = Vec4::new(0.2126, 0.7152, 0.0722, 0.0);
        let ([t00, t10, t01, t11], fx, fy) = self.corners(uv);
        let [l00, l10, l01, l11] = [t00, t10, t01, t11].map(|t| t.dot(WEIGHTS));
        // Texel centres are 1 / width apart in u and 1 / height in v.
        let d_dx = (l10 - l00) + ((l11 - l01) - (l10 - l00)) * fy;
        let d_dy = (l01 - l00) + ((l11 - l10) - (l01 - l00)) * fx;
        let g = Vec2::new(d_dx * self.width as f32, d_dy * self.height as f32);
        // Read through `uv' = A uv + b`: the gradient in `uv` is `A^T` times the one in `uv'`.
        self.transform.map_or(g, |t| t.matrix2.transpose() * g)
    }

    /// The four texels around `uv` (top-left, top-right, bottom-left, bottom-right) and the
    /// bilinear weights `(fx, fy)` between them, after [`Texture::transform`] and the wraps.
    fn corners(&self, uv: Vec2) -> ([Vec4; 4], f32, f32) {
        let uv = self.transform.map_or(uv, |t| t.transform_point2(uv));
        let uv = if uv.is_finite() { uv } else { Vec2::ZERO };
        // Texel centres sit at half-integers.
        let x = uv.x as f64 * self.width as f64 - 0.5;
        let y = uv.y as f64 * self.height as f64 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = ((x - x0) as f32, (y - y0) as f32);
        // Coordinates far outside [0, 1] (1e30) saturate; the wrap then picks a texel.
        let (x0, y0) = (x0 as i64, y0 as i64);
        let xs = [
            self.wrap_u.index(x0, self.width),
            self.wrap_u.index(x0.saturating_add(1), self.width),
        ];
        let ys = [
            self.wrap_v.index(y0, self.height),
            self.wrap_v.index(y0.saturating_add(1), self.height),
        ];
        (
            [
                self.texel(xs[0], ys[0]),
                self.texel(xs[1], ys[0]),
                self.texel(xs[0], ys[1]),
                self.texel(xs[1], ys[1]),
            ],
            fx,
            fy,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Luminance of the linear value `sample` reads, as [`Texture::luminance_gradient`] weighs it.
    fn luminance(t: &Texture, uv: Vec2) -> f32 {
        t.sample(uv)
            .truncate()
            .dot(glam::Vec3::new(0.2126, 0.7152, 0.0722))
    }

    /// A 5 x 4 texture of unrelated colours (every channel differs from texel to texel).
    fn texture() -> Texture {
        let texels = (0..20u32)
            .map(|i| {
                let c = |k: u32| ((i * 37 + k * 101) % 251) as u8;
                [c(0), c(1), c(2), 255]
            })
            .collect();
        Texture::from_rgba8("test".into(), 5, 4, texels, false)
    }

    /// The analytic gradient against central differences of the sampled luminance, at points
    /// away from the lines through texel centres (where the bilinear slope jumps), plain and
    /// through a transform that rotates, scales unevenly and moves: a gradient not scaled by the
    /// texture's size, or read through the transform untransposed, is off by far more.
    #[test]
    fn the_luminance_gradient_is_the_derivative_of_the_sampled_luminance() {
        let mut t = texture();
        let points = [
            (0.13, 0.21),
            (0.47, 0.62),
            (0.83, 0.07),
            (0.31, 0.93),
            (0.66, 0.41),
        ];
        for transform in [
            None,
            Some(Affine2::from_scale_angle_translation(
                Vec2::new(1.7, 0.6),
                0.5,
                Vec2::new(0.3, -0.2),
            )),
        ] {
            t.transform = transform;
            for (u, v) in points {
                let uv = Vec2::new(u, v);
                let h = 1e-4;
                let fd = Vec2::new(
                    luminance(&t, uv + Vec2::X * h) - luminance(&t, uv - Vec2::X * h),
                    luminance(&t, uv + Vec2::Y * h) - luminance(&t, uv - Vec2::Y * h),
                ) / (2.0 * h);
                let g = t.luminance_gradient(uv);
                assert!(
                    (g - fd).length() <= 2e-3 * fd.length().max(1.0),
                    "{transform:?} at {uv}: gradient {g}, differences {fd}"
                );
                assert!(fd.length() > 0.1, "the texture varies at {uv}: {fd}");
            }
        }
    }

    /// A flat texture has no gradient; one that rises by one texel's step per texel along `u`
    /// rises by `width` times that step per unit of `u`, whatever the wrap.
    #[test]
    fn a_ramp_has_the_slope_of_its_steps() {
        let ramp: Vec<[u8; 4]> = (0..8u8).map(|i| [i * 20, i * 20, i * 20, 255]).collect();
        let mut t = Texture::from_rgba8("ramp".into(), 8, 1, ramp, false);
        for wrap in [Wrap::Repeat, Wrap::ClampToEdge, Wrap::MirroredRepeat] {
            t.wrap_u = wrap;
            let g = t.luminance_gradient(Vec2::new(0.4, 0.5));
            let expected = 20.0 / 255.0 * 8.0;
            assert!((g.x - expected).abs() < 1e-5 && g.y == 0.0, "{wrap:?}: {g}");
        }
        let flat = Texture::from_rgba8("flat".into(), 3, 3, vec![[90, 90, 90, 255]; 9], false);
        assert_eq!(flat.luminance_gradient(Vec2::new(0.3, 0.7)), Vec2::ZERO);
    }
}
