//! Rendering on all cores: camera rays, shading ([`shade`]), the environment, and the
//! [`RenderPlan`] that leaves out what a scene does not need.
//!
//! Every pixel draws its samples from its own random stream, seeded from the pixel index and
//! the sample index, so an image is the same for any number of threads.

pub mod cache;
pub mod debug;
pub mod environment;
pub mod heatmap;
pub mod path;
pub mod plan;
pub mod progressive;
pub mod resample;
pub mod shade;

pub use crate::scene::Integrator;
pub use environment::{CubeMap, EnvironmentMap, LinearImage, sky};
pub use plan::{Explain, RenderPlan};
pub use progressive::Progressive;
pub use shade::Tracer;

use std::sync::atomic::{AtomicUsize, Ordering};

use glam::Vec3;
use rayon::prelude::*;

use crate::bvh::Bvh;
use crate::camera::CameraRays;
use crate::film::Film;
use crate::sampling::{PathSampler, PixelSampler, SamplerKind, concentric_disk, dim};
use crate::scene::Scene;

/// What to render.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSettings {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Samples per pixel.
    pub spp: u32,
    /// Seed of the random streams.
    pub seed: u64,
    /// Largest number of mirror reflections or transparent surfaces along a path.
    pub max_depth: u32,
    /// How pixel, lens and light samples are drawn.
    pub sampler: SamplerKind,
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            width: 512,
            height: 512,
            spp: 16,
            seed: 0,
            max_depth: 5,
            sampler: SamplerKind::Sobol,
        }
    }
}

impl RenderSettings {
    /// Checks that the image has pixels and samples; the message says what is wrong.
    pub fn validate(&self) -> Result<(), String> {
        if self.width == 0 || self.height == 0 {
            return Err(format!(
                "image size {}x{} has no pixels",
                self.width, self.height
            ));
        }
        if self.spp == 0 {
            return Err("samples per pixel must be at least 1".into());
        }
        if self.width as u64 * self.height as u64 > u32::MAX as u64 {
            return Err(format!(
                "image size {}x{} is too large",
                self.width, self.height
            ));
        }
        Ok(())
    }
}

/// Rays traced by kind.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct RayCounts {
    /// Rays from the camera.
    pub camera: u64,
    /// Shadow rays towards lights.
    pub shadow: u64,
    /// Rays reflected by mirrors.
    pub reflection: u64,
    /// Rays continuing through transparent surfaces.
    pub transmission: u64,
    /// Diffuse bounces of the path integrator.
    pub bounce: u64,
}

impl std::ops::Add for RayCounts {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        Self {
            camera: self.camera + o.camera,
            shadow: self.shadow + o.shadow,
            reflection: self.reflection + o.reflection,
            transmission: self.transmission + o.transmission,
            bounce: self.bounce + o.bounce,
        }
    }
}

impl RayCounts {
    /// All rays.
    pub fn total(&self) -> u64 {
        self.camera + self.shadow + self.reflection + self.transmission + self.bounce
    }
}

/// The result of a render.
pub struct RenderOutput {
    /// Accumulated radiance.
    pub film: Film,
    /// Rays traced by kind.
    pub rays: RayCounts,
}

/// Renders `scene` with a prebuilt `bvh` and the plan the scene needs, loading the
/// environment's images if the plan uses them. `progress` is called with the number of
/// finished rows (from any thread).
pub fn render(
    scene: &Scene,
    bvh: &Bvh,
    settings: &RenderSettings,
    progress: &(dyn Fn(usize) + Sync),
) -> anyhow::Result<RenderOutput> {
    let plan = RenderPlan::new(scene, settings);
    let env = EnvironmentMap::load(&scene.environment, plan.environment)?;
    Ok(render_with_plan(scene, bvh, &env, settings, plan, progress))
}

/// [`render`] with a loaded environment and a given plan (tests compare a pruned plan with
/// [`RenderPlan::everything`]).
pub fn render_with_plan(
    scene: &Scene,
    bvh: &Bvh,
    env: &EnvironmentMap,
    settings: &RenderSettings,
    plan: RenderPlan,
    progress: &(dyn Fn(usize) + Sync),
) -> RenderOutput {
    let (w, h) = (settings.width, settings.height);
    let cam = CameraRays::new(&scene.camera, w, h);
    let mut film = Film::new(w, h);
    let rows_done = AtomicUsize::new(0);
    let tracer = Tracer::new(scene, bvh, plan, settings.max_depth, env);
    let samples = SampleRange {
        sampler: settings.sampler,
        seed: settings.seed,
        first: 0,
        count: settings.spp,
    };
    let (rays, rejected) = film
        .sum
        .par_chunks_mut(w as usize)
        .enumerate()
        .map(|(y, row)| {
            let r = trace_row(&tracer, &cam, &samples, y as u32, row);
            progress(rows_done.fetch_add(1, Ordering::Relaxed) + 1);
            r
        })
        .reduce(|| (RayCounts::default(), 0), |a, b| (a.0 + b.0, a.1 + b.1));
    film.samples = settings.spp;
    film.rejected = rejected;
    RenderOutput { film, rays }
}

/// Which samples of each pixel to take: indices `first..first + count` of the pixel's
/// stream, so an image built up over several calls equals one rendered in a single call.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SampleRange {
    /// How samples are drawn.
    pub sampler: SamplerKind,
    /// Seed of the random streams.
    pub seed: u64,
    /// Index of the first sample.
    pub first: u32,
    /// Number of samples.
    pub count: u32,
}

/// Adds the samples `samples` of every pixel of row `y` into `row` (one radiance sum per
/// pixel); returns the rays traced and the number of non-finite samples left out.
///
/// Camera rays go in packets of [`crate::bvh::wide::packet::PACKET`] neighbouring pixels of
/// the row ([`Bvh::intersect_packet`]), one sample index at a time; each pixel still adds its
/// samples in order and gets the hits single rays would, so the image is the same bit for bit.
pub fn trace_row(
    tracer: &Tracer,
    cam: &CameraRays,
    samples: &SampleRange,
    y: u32,
    row: &mut [Vec3],
) -> (RayCounts, u64) {
    use crate::bvh::wide::packet::PACKET;
    let mut rays = RayCounts::default();
    let mut rejected = 0u64;
    let thin_lens = tracer.plan.thin_lens && cam.lens_radius > 0.0;
    let mut camera_rays = [crate::geometry::Ray::new(Vec3::ZERO, Vec3::Z); PACKET];
    let mut samplers = [PixelSampler::new(samples.sampler, samples.seed, 0, 0); PACKET];
    let mut hits = [None; PACKET];
    for (chunk, sums) in row.chunks_mut(PACKET).enumerate() {
        let x0 = chunk * PACKET;
        let n = sums.len();
        let firsts: Vec<PixelSampler> = (0..n)
            .map(|k| {
                let pixel = y as u64 * cam.width as u64 + (x0 + k) as u64;
                PixelSampler::new(samples.sampler, samples.seed, pixel, 0)
            })
            .collect();
        for s in samples.first..samples.first.saturating_add(samples.count) {
            for k in 0..n {
                let sampler = firsts[k].with_index(s);
                let jitter = sampler.get_2d(dim::PIXEL);
                let (px, py) = ((x0 + k) as f32 + jitter.x, y as f32 + jitter.y);
                camera_rays[k] = if thin_lens {
                    cam.thin_lens(px, py, concentric_disk(sampler.get_2d(dim::LENS)))
                } else {
                    cam.pinhole(px, py)
                };
                samplers[k] = sampler;
            }
            tracer
                .bvh
                .intersect_packet(&camera_rays[..n], f32::INFINITY, &mut hits[..n]);
            rays.camera += n as u64;
            for (k, px_sum) in sums.iter_mut().enumerate() {
                let l = tracer.radiance_from_hit(
                    &camera_rays[k],
                    hits[k],
                    &mut PathSampler::new(samplers[k]),
                    &mut rays,
                );
                if l.is_finite() {
                    *px_sum += l;
                } else {
                    rejected += 1;
                }
            }
        }
    }
    (rays, rejected)
}
