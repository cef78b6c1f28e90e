//! Render layers (AOVs, "arbitrary output variables"): per pixel, the albedo and shading
//! normal of the first surface a camera ray meets that is not a perfect mirror or clear glass,
//! the distance to the first hit, and the samples taken. A denoiser is guided by the first two
//! ([`crate::denoise`]); all of them can be written as EXR channels ([`AovFilm::save_exr`]).
//!
//! The layers are traced in a pass of their own: each sample's camera ray is the colour
//! render's (same pixel jitter and lens sample, so edges are anti-aliased alike), and from its
//! hit the pass follows mirrors and transparent surfaces deterministically, as denoisers
//! expect (Intel Open Image Denoise's documentation: the albedo seen through a perfect
//! specular surface is that of what it shows, tinted by it). A surface counts as specular when
//! its mirror reflection or its transmission outweighs what it reflects diffusely or glossily;
//! the pass follows the larger of the two, at most `max_depth` times. A ray that leaves the
//! scene takes the environment's radiance, clamped to 1, as its albedo and a zero normal.
//!
//! The pass costs a camera ray per sample plus the specular chains: a few per cent of a path
//! traced render's rays.

use std::path::Path;

use anyhow::Context;
use glam::Vec3;
use rayon::prelude::*;

use super::surface::{reflect, transmit};
use super::{BAND, SampleRange, TILE_WIDTH, Tracer, camera_ray};
use crate::bvh::Hit;
use crate::bvh::PACKET;
use crate::camera::CameraRays;
use crate::film::Film;
use crate::geometry::{Ray, offset_ray_origin};
use crate::sampling::PixelSampler;

/// A render layer, as named on the command line (`--aov albedo,normal,depth,samples`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Aov {
    /// Reflectance of the first non-specular surface (linear RGB, 0 to 1).
    Albedo,
    /// Its shading normal (world space, averaged over the pixel's samples: not unit length
    /// where the normals within a pixel differ).
    Normal,
    /// Distance from the camera to the first hit along the ray (infinite where no sample hit).
    Depth,
    /// Samples the pixel's colour was averaged from.
    Samples,
}

impl Aov {
    /// Every layer, in the order they are written.
    pub const ALL: [Aov; 4] = [Aov::Albedo, Aov::Normal, Aov::Depth, Aov::Samples];

    /// The layer's name (its channels are `name.R`, `name.G`, … in an EXR).
    pub fn name(self) -> &'static str {
        match self {
            Aov::Albedo => "albedo",
            Aov::Normal => "normal",
            Aov::Depth => "depth",
            Aov::Samples => "samples",
        }
    }

    /// The layer called `name`; the message lists the names.
    pub fn parse(name: &str) -> Result<Aov, String> {
        let name = name.trim();
        Aov::ALL
            .into_iter()
            .find(|a| a.name() == name)
            .ok_or_else(|| {
                format!("unknown render layer '{name}' (expected albedo, normal, depth or samples)")
            })
    }
}

/// What one camera sample contributes to the layers.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AovSample {
    /// Albedo of the first non-specular surface, tinted by the specular ones before it.
    pub albedo: Vec3,
    /// Its shading normal (zero where the path left the scene).
    pub normal: Vec3,
    /// Distance to the camera ray's hit, if any.
    pub depth: Option<f32>,
}

/// The layers' sums over the samples taken.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AovFilm {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Sum of each pixel's albedo samples.
    pub albedo: Vec<Vec3>,
    /// Sum of each pixel's normal samples.
    pub normal: Vec<Vec3>,
    /// Sum of each pixel's hit distances.
    pub depth: Vec<f32>,
    /// Samples of each pixel that hit something.
    pub hits: Vec<u32>,
    /// Samples added to every pixel.
    pub samples: u32,
}

impl AovFilm {
    /// Empty layers of `width x height`.
    pub fn new(width: u32, height: u32) -> Self {
        let n = width as usize * height as usize;
        Self {
            width,
            height,
            albedo: vec![Vec3::ZERO; n],
            normal: vec![Vec3::ZERO; n],
            depth: vec![0.0; n],
            hits: vec![0; n],
            samples: 0,
        }
    }

    /// Mean albedo of each pixel.
    pub fn albedo_mean(&self) -> Vec<Vec3> {
        let k = 1.0 / self.samples.max(1) as f32;
        self.albedo.iter().map(|a| *a * k).collect()
    }

    /// Mean normal of each pixel.
    pub fn normal_mean(&self) -> Vec<Vec3> {
        let k = 1.0 / self.samples.max(1) as f32;
        self.normal.iter().map(|n| *n * k).collect()
    }

    /// Mean distance of each pixel's hits (infinite where none hit).
    pub fn depth_mean(&self) -> Vec<f32> {
        self.depth
            .iter()
            .zip(&self.hits)
            .map(|(d, &n)| if n > 0 { d / n as f32 } else { f32::INFINITY })
            .collect()
    }

    /// Adds the samples `samples` of every pixel, traced on all cores.
    pub fn add(&mut self, tracer: &Tracer, cam: &CameraRays, samples: &SampleRange) {
        let w = self.width as usize;
        if w == 0 || self.height == 0 {
            return;
        }
        let band = w * BAND as usize;
        self.albedo
            .par_chunks_mut(band)
            .zip(self.normal.par_chunks_mut(band))
            .zip(self.depth.par_chunks_mut(band))
            .zip(self.hits.par_chunks_mut(band))
            .enumerate()
            .for_each(|(b, (((albedo, normal), depth), hits))| {
                let y0 = b * BAND as usize;
                let rows = albedo.len() / w;
                for x0 in (0..w).step_by(TILE_WIDTH as usize) {
                    let tw = (TILE_WIDTH as usize).min(w - x0);
                    let at = |k: usize| k / tw * w + x0 + k % tw;
                    aov_tile(tracer, cam, samples, (x0, y0), (tw, rows), &mut |k, s| {
                        let i = at(k);
                        albedo[i] += s.albedo;
                        normal[i] += s.normal;
                        if let Some(d) = s.depth {
                            depth[i] += d;
                            hits[i] += 1;
                        }
                    });
                }
            });
        self.samples += samples.count;
    }

    /// Writes the chosen layers, and the colour `film` if given, as channels of one EXR
    /// (32-bit float, lossless): `R`, `G`, `B` for the colour, `albedo.R/G/B`,
    /// `normal.X/Y/Z`, `depth.Z` and `samples.N` for the layers.
    pub fn save_exr(&self, path: &Path, layers: &[Aov], film: Option<&Film>) -> anyhow::Result<()> {
        use exr::prelude::*;
        let n = self.width as usize * self.height as usize;
        let mut channels: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::new();
        let mut rgb = |names: [&str; 3], v: &[Vec3]| {
            for (c, name) in names.into_iter().enumerate() {
                let data = v.iter().map(|p| finite(p[c])).collect();
                channels.push(AnyChannel::new(name, FlatSamples::F32(data)));
            }
        };
        if let Some(f) = film {
            anyhow::ensure!(
                f.sum.len() == n,
                "the colour film is {}x{}, the layers {}x{}",
                f.width,
                f.height,
                self.width,
                self.height
            );
            rgb(["R", "G", "B"], &f.mean());
        }
        if layers.contains(&Aov::Albedo) {
            rgb(["albedo.R", "albedo.G", "albedo.B"], &self.albedo_mean());
        }
        if layers.contains(&Aov::Normal) {
            rgb(["normal.X", "normal.Y", "normal.Z"], &self.normal_mean());
        }
        if layers.contains(&Aov::Depth) {
            let d = self.depth_mean();
            channels.push(AnyChannel::new("depth.Z", FlatSamples::F32(d)));
        }
        if layers.contains(&Aov::Samples) {
            let s = film.map_or(self.samples, |f| f.samples) as f32;
            channels.push(AnyChannel::new("samples.N", FlatSamples::F32(vec![s; n])));
        }
        let size = (self.width as usize, self.height as usize);
        let layer = Layer::new(
            size,
            LayerAttributes::named("tracery"),
            Encoding::SMALL_LOSSLESS,
            AnyChannels::sort(channels),
        );
        Image::from_layer(layer)
            .write()
            .to_file(path)
            .with_context(|| format!("{}: cannot write EXR layers", path.display()))
    }
}

/// A float for a file: non-finite values but infinite depth become 0.
fn finite(x: f32) -> f32 {
    if x.is_finite() { x } else { 0.0 }
}

/// The layers' samples `samples` of the `size.0 x size.1` tile of pixels from `corner`,
/// handed to `add` with the tile index of their pixel (row by row of the tile).
fn aov_tile(
    tracer: &Tracer,
    cam: &CameraRays,
    samples: &SampleRange,
    corner: (usize, usize),
    size: (usize, usize),
    add: &mut dyn FnMut(usize, AovSample),
) {
    let ((x0, y0), (tw, height)) = (corner, size);
    let n = tw * height;
    let w = cam.width as u64;
    let thin_lens = tracer.plan.thin_lens && cam.lens_radius > 0.0;
    let mut rays = [Ray::new(Vec3::ZERO, Vec3::Z); PACKET];
    let mut hits = [None; PACKET];
    let pixel_of = |k: usize| (x0 + k % tw, y0 + k / tw);
    for s in samples.first..samples.first.saturating_add(samples.count) {
        for (k, ray) in rays[..n].iter_mut().enumerate() {
            let (x, y) = pixel_of(k);
            let pixel = y as u64 * w + x as u64;
            let sampler = PixelSampler::new(samples.sampler, samples.seed, pixel, s);
            *ray = camera_ray(cam, &sampler, x as u32, y as u32, thin_lens);
        }
        tracer
            .bvh
            .intersect_packet(&rays[..n], f32::INFINITY, &mut hits[..n]);
        for (k, (ray, hit)) in rays[..n].iter().zip(&hits[..n]).enumerate() {
            add(k, tracer.first_surface(ray, *hit));
        }
    }
}

impl Tracer<'_> {
    /// The layers' sample of a camera ray given its closest hit (see the module docs).
    pub fn first_surface(&self, ray: &Ray, hit: Option<Hit>) -> AovSample {
        let depth = hit.map(|h| h.t * ray.dir.length());
        let mut tint = Vec3::ONE;
        let mut ray = *ray;
        let mut hit = hit;
        for bounce in 0..=self.max_depth {
            let Some(h) = hit else {
                let sky = self.background(ray.dir).clamp(Vec3::ZERO, Vec3::ONE);
                return AovSample {
                    albedo: tint * sky,
                    normal: Vec3::ZERO,
                    depth,
                };
            };
            let s = self.surface(&ray, h.prim, h.u, h.v);
            let alpha = if self.plan.transmission {
                s.opacity
            } else {
                1.0
            };
            let albedo = s.bsdf.albedo();
            let wo = -ray.dir.normalize();
            let mirror = if self.plan.reflections && s.is_mirror() {
                alpha * s.mirror_tint(wo)
            } else {
                Vec3::ZERO
            };
            let through = s.material.transmission(alpha, s.bsdf.diffuse);
            let own = alpha * albedo.max_element();
            let specular = mirror.max_element().max(through.max_element());
            if own >= specular || bounce == self.max_depth {
                return AovSample {
                    albedo: tint * albedo,
                    normal: s.n(),
                    depth,
                };
            }
            ray = if mirror.max_element() >= through.max_element() {
                tint *= mirror;
                Ray::new(s.origin, reflect(ray.dir, s.n()))
            } else {
                tint *= through;
                let (dir, side) = transmit(ray.dir, &s);
                Ray::new(offset_ray_origin(s.p, s.p_err, side), dir)
            };
            tint = tint.min(Vec3::ONE);
            hit = self.bvh.intersect(&ray, f32::INFINITY);
        }
        AovSample {
            albedo: Vec3::ZERO,
            normal: Vec3::ZERO,
            depth,
        }
    }
}
