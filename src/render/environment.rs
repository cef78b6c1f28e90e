//! What rays that leave the scene see: nothing, a colour, the procedural sky, a cube map of
//! six images or an equirectangular image, with intensity and rotation about +y.

use std::path::Path;

use anyhow::{Context, Result, bail};
use glam::{Quat, Vec3};

use crate::color::srgb_to_linear;
use crate::scene::Environment;

/// An environment ready to sample: images loaded and converted to linear RGB.
#[derive(Clone, Debug)]
pub enum EnvironmentMap {
    /// Black (also what a render plan without an environment uses: nothing loaded).
    None,
    /// One colour everywhere.
    Color(Vec3),
    /// The procedural [`sky`].
    Sky {
        /// Brightness scale.
        intensity: f32,
        /// Turns world directions into map directions.
        rotation: Quat,
    },
    /// Six square faces.
    Cube {
        /// The faces.
        map: CubeMap,
        /// Brightness scale.
        intensity: f32,
        /// Turns world directions into map directions.
        rotation: Quat,
    },
    /// A latitude-longitude image.
    Equirect {
        /// The image.
        image: LinearImage,
        /// Brightness scale.
        intensity: f32,
        /// Turns world directions into map directions.
        rotation: Quat,
    },
}

fn rotation(deg: f32) -> Quat {
    Quat::from_rotation_y(-deg.to_radians())
}

impl EnvironmentMap {
    /// Loads what `env` names. With `needed` false (the render plan has no environment)
    /// nothing is loaded and the result is black.
    pub fn load(env: &Environment, needed: bool) -> Result<Self> {
        if !needed {
            return Ok(Self::None);
        }
        Ok(match env {
            Environment::None => Self::None,
            Environment::Color(c) => Self::Color(*c),
            Environment::Sky {
                intensity,
                rotation_deg,
            } => Self::Sky {
                intensity: *intensity,
                rotation: rotation(*rotation_deg),
            },
            Environment::CubeMap {
                faces,
                intensity,
                rotation_deg,
            } => {
                let mut images = Vec::with_capacity(6);
                for f in faces {
                    images.push(LinearImage::load(f)?);
                }
                let images: [LinearImage; 6] = images.try_into().expect("six faces");
                Self::Cube {
                    map: CubeMap::new(images).with_context(|| {
                        format!("cube map {} and its five sibling faces", faces[0].display())
                    })?,
                    intensity: *intensity,
                    rotation: rotation(*rotation_deg),
                }
            }
            Environment::Equirect {
                path,
                intensity,
                rotation_deg,
            } => Self::Equirect {
                image: LinearImage::load(path)?,
                intensity: *intensity,
                rotation: rotation(*rotation_deg),
            },
        })
    }

    /// Radiance arriving from direction `dir` (any length; zero or NaN gives black).
    pub fn radiance(&self, dir: Vec3) -> Vec3 {
        let Some(d) = dir.try_normalize() else {
            return Vec3::ZERO;
        };
        match self {
            Self::None => Vec3::ZERO,
            Self::Color(c) => *c,
            Self::Sky {
                intensity,
                rotation,
            } => sky(*rotation * d) * *intensity,
            Self::Cube {
                map,
                intensity,
                rotation,
            } => map.lookup(*rotation * d) * *intensity,
            Self::Equirect {
                image,
                intensity,
                rotation,
            } => equirect(image, *rotation * d) * *intensity,
        }
    }
}

/// A simple procedural sky: a horizon-to-zenith gradient over a darker ground, blended by the
/// square root of the direction's height (`sqrt`, not `powf(0.5)`: every ray that leaves the
/// scene asks, and `EnvironmentMap::radiance` went from 4.7 to 2.5% of a replayed orbit).
pub fn sky(dir: Vec3) -> Vec3 {
    let d = dir.try_normalize().unwrap_or(Vec3::Y);
    if d.y >= 0.0 {
        let t = d.y.sqrt();
        Vec3::new(0.85, 0.9, 1.0).lerp(Vec3::new(0.25, 0.45, 0.85), t)
    } else {
        let t = (-d.y).sqrt();
        Vec3::new(0.5, 0.47, 0.45).lerp(Vec3::new(0.2, 0.18, 0.16), t)
    }
}

/// An image in linear RGB, row 0 at the top.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearImage {
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// Texels, row by row.
    pub texels: Vec<Vec3>,
}

impl LinearImage {
    /// Loads PNG, JPEG, HDR or EXR. 8- and 16-bit images are taken as sRGB and decoded to
    /// linear; float images are already linear. Errors name the file.
    pub fn load(path: &Path) -> Result<Self> {
        let img =
            image::open(path).with_context(|| format!("{}: cannot read image", path.display()))?;
        let float = matches!(
            img.color(),
            image::ColorType::Rgb32F | image::ColorType::Rgba32F
        );
        let rgb = img.to_rgb32f();
        let (width, height) = rgb.dimensions();
        if width == 0 || height == 0 {
            bail!("{}: empty image", path.display());
        }
        let texels = rgb
            .pixels()
            .map(|p| {
                let v = Vec3::from(p.0);
                if float { v } else { v.map(srgb_to_linear) }
            })
            .collect();
        Ok(Self {
            width,
            height,
            texels,
        })
    }

    /// The texel at column `x`, row `y`.
    pub fn texel(&self, x: u32, y: u32) -> Vec3 {
        self.texels[(y * self.width + x) as usize]
    }
}

/// Six square faces in the usual cube-map order and orientation: +x, -x, +y, -y, +z, -z,
/// with the face coordinates of the OpenGL convention (row 0 at the top of each image).
#[derive(Clone, Debug)]
pub struct CubeMap {
    size: u32,
    faces: [LinearImage; 6],
}

impl CubeMap {
    /// Checks the faces are square and of one size.
    pub fn new(faces: [LinearImage; 6]) -> Result<Self> {
        let size = faces[0].width;
        for (i, f) in faces.iter().enumerate() {
            if f.width != f.height || f.width != size {
                bail!(
                    "face {i} is {}x{}; all six faces must be square and {size}x{size}",
                    f.width,
                    f.height
                );
            }
        }
        Ok(Self { size, faces })
    }

    /// Bilinear lookup that crosses face edges without a seam: a filter tap beyond an edge
    /// reads the neighbouring face (unfolded across the shared edge), and the one tap beyond
    /// a corner, where three faces meet, is the mean of the other three taps.
    pub fn lookup(&self, dir: Vec3) -> Vec3 {
        let (face, u, v) = face_uv(dir);
        let n = self.size as f32;
        let (x, y) = (u * n - 0.5, v * n - 0.5);
        let (i0, j0) = (x.floor(), y.floor());
        let (fx, fy) = (x - i0, y - j0);
        let (i0, j0) = (i0 as i64, j0 as i64);
        let mut taps = [Vec3::ZERO; 4];
        let mut corner = None;
        for (k, (di, dj)) in [(0, 0), (1, 0), (0, 1), (1, 1)].into_iter().enumerate() {
            match self.tap(face, i0 + di, j0 + dj) {
                Some(t) => taps[k] = t,
                None => corner = Some(k),
            }
        }
        if let Some(k) = corner {
            taps[k] = (taps.iter().sum::<Vec3>() - taps[k]) / 3.0;
        }
        let top = taps[0].lerp(taps[1], fx);
        let bottom = taps[2].lerp(taps[3], fx);
        top.lerp(bottom, fy)
    }

    /// Texel `(i, j)` of `face`, reading across an edge where it lies outside the face; `None`
    /// beyond a corner.
    fn tap(&self, face: usize, i: i64, j: i64) -> Option<Vec3> {
        let n = self.size as i64;
        let inside = |k: i64| (0..n).contains(&k);
        if inside(i) && inside(j) {
            return Some(self.faces[face].texel(i as u32, j as u32));
        }
        if !inside(i) && !inside(j) {
            return None;
        }
        // The texel centre on the face's plane, past one edge...
        let sc = 2.0 * (i as f32 + 0.5) / n as f32 - 1.0;
        let tc = 2.0 * (j as f32 + 0.5) / n as f32 - 1.0;
        let p = face_point(face, sc, tc);
        // ...unfolded onto the neighbouring face: the overshoot becomes the distance from the
        // shared edge on the neighbour, the coordinate along the edge stays.
        let a = face / 2;
        let b = (0..3)
            .filter(|&k| k != a)
            .max_by(|&k, &l| p[k].abs().total_cmp(&p[l].abs()))
            .expect("two other axes");
        let overshoot = p[b].abs() - 1.0;
        let mut q = p;
        q[b] = p[b].signum();
        q[a] = p[a].signum() * (1.0 - overshoot);
        let (f2, u2, v2) = face_uv(q);
        let clamp = |t: f32| ((t * n as f32) as i64).clamp(0, n - 1) as u32;
        Some(self.faces[f2].texel(clamp(u2), clamp(v2)))
    }
}

/// The face and face coordinates in `[0, 1]` of direction `d`. Ties between axes (edges and
/// corners) go to x, then y: every direction has exactly one face.
pub fn face_uv(d: Vec3) -> (usize, f32, f32) {
    let a = d.abs();
    let (face, ma, sc, tc) = if a.x >= a.y && a.x >= a.z {
        if d.x >= 0.0 {
            (0, a.x, -d.z, -d.y)
        } else {
            (1, a.x, d.z, -d.y)
        }
    } else if a.y >= a.z {
        if d.y >= 0.0 {
            (2, a.y, d.x, d.z)
        } else {
            (3, a.y, d.x, -d.z)
        }
    } else if d.z >= 0.0 {
        (4, a.z, d.x, -d.y)
    } else {
        (5, a.z, -d.x, -d.y)
    };
    if ma.is_nan() || ma <= 0.0 {
        return (0, 0.5, 0.5);
    }
    (face, 0.5 * (sc / ma + 1.0), 0.5 * (tc / ma + 1.0))
}

/// The point on the plane of `face` (at distance 1 from the centre) with face coordinates
/// `sc, tc` in `[-1, 1]` (or beyond, past an edge): the inverse of [`face_uv`].
pub fn face_point(face: usize, sc: f32, tc: f32) -> Vec3 {
    match face {
        0 => Vec3::new(1.0, -tc, -sc),
        1 => Vec3::new(-1.0, -tc, sc),
        2 => Vec3::new(sc, 1.0, tc),
        3 => Vec3::new(sc, -1.0, -tc),
        4 => Vec3::new(sc, -tc, 1.0),
        _ => Vec3::new(-sc, -tc, -1.0),
    }
}

/// Bilinear lookup in a latitude-longitude image: `+y` is the top row, `-z` the centre column.
fn equirect(img: &LinearImage, d: Vec3) -> Vec3 {
    let u = 0.5 + d.x.atan2(-d.z) / std::f32::consts::TAU;
    let v = d.y.clamp(-1.0, 1.0).acos() / std::f32::consts::PI;
    let (w, h) = (img.width as i64, img.height as i64);
    let x = u * w as f32 - 0.5;
    let y = (v * h as f32 - 0.5).clamp(0.0, (h - 1) as f32);
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let at = |i: i64, j: i64| img.texel(i.rem_euclid(w) as u32, j.clamp(0, h - 1) as u32);
    let (i, j) = (x0 as i64, y0 as i64);
    let top = at(i, j).lerp(at(i + 1, j), fx);
    let bottom = at(i, j + 1).lerp(at(i + 1, j + 1), fx);
    top.lerp(bottom, fy)
}
