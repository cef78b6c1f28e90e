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

    /// Width and height in texels.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// One texel in linear values.
    fn texel(&self, x: usize, y: usize) -> Vec4 {
        let [r, g, b, a] = self.texels[y * self.width as usize + x];
        let alpha = a as f32 / 255.0;
        if self.srgb {
            let t = crate::film::srgb8_table();
            Vec4::new(t[r as usize], t[g as usize], t[b as usize], alpha)
        } else {
            Vec4::new(r as f32, g as f32, b as f32, a as f32) / 255.0
        }
    }

    /// The linear RGBA value at texture coordinate `uv` (`(0, 0)` the top-left corner of the
    /// image, `(1, 1)` the bottom-right), bilinearly filtered between the four nearest texel
    /// centres, after [`Texture::transform`]. A non-finite coordinate reads texel (0, 0).
    pub fn sample(&self, uv: Vec2) -> Vec4 {
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
        let top = self.texel(xs[0], ys[0]).lerp(self.texel(xs[1], ys[0]), fx);
        let bottom = self.texel(xs[0], ys[1]).lerp(self.texel(xs[1], ys[1]), fx);
        top.lerp(bottom, fy)
    }
}
