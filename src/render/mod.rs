//! Rendering on all cores: camera rays, the tracer ([`tracer`]) with its integrators, surfaces,
//! lights and lobes, the environment, and the
//! [`RenderPlan`] that leaves out what a scene does not need.
//!
//! Every pixel draws its samples from its own random stream, seeded from the pixel index and
//! the sample index, so an image is the same for any number of threads.

pub mod aov;
pub mod bsdf;
pub mod cache;
pub mod debug;
pub mod environment;
pub mod heatmap;
pub mod integrator;
pub mod light;
pub mod part;
pub mod plan;
pub mod progressive;
pub mod resample;
pub mod surface;
pub mod tracer;

pub use crate::scene::Integrator;
pub use environment::{CubeMap, EnvironmentMap, LinearImage, sky};
pub use integrator::path::PathBatch;
pub use plan::{Explain, RenderPlan};
pub use progressive::Progressive;
pub use tracer::Tracer;

use std::sync::atomic::{AtomicUsize, Ordering};

use glam::Vec3;
use rayon::prelude::*;

use crate::bvh::Tree;
use crate::camera::CameraRays;
use crate::film::{Film, Sum};
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
    /// Soften the shadow terminator of normals that normal and height maps bend (see
    /// [`RenderPlan::soft_terminator`]); on by default.
    pub soft_terminator: bool,
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
            soft_terminator: true,
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
/// finished rows (from any thread). An error says so when the scene places meshes more than
/// once and `bvh` is one tree (over the scene's own triangles, without the placed meshes).
pub fn render<'a>(
    scene: &'a Scene,
    bvh: impl Into<Tree<'a>>,
    settings: &RenderSettings,
    progress: &(dyn Fn(usize) + Sync),
) -> anyhow::Result<RenderOutput> {
    let bvh: Tree<'a> = bvh.into();
    anyhow::ensure!(
        scene.instances.is_empty() || matches!(bvh, Tree::TwoLevel(_)),
        "the scene places meshes more than once, and one tree over its own triangles leaves \
         them out: build its trees with `Accel::for_scene`"
    );
    let plan = RenderPlan::new(scene, settings);
    let env = EnvironmentMap::load(&scene.environment, plan.environment)?;
    Ok(render_with_plan(scene, bvh, &env, settings, plan, progress))
}

/// [`render`] with a loaded environment and a given plan (tests compare a pruned plan with
/// [`RenderPlan::everything`]).
pub fn render_with_plan<'a>(
    scene: &'a Scene,
    bvh: impl Into<Tree<'a>>,
    env: &EnvironmentMap,
    settings: &RenderSettings,
    plan: RenderPlan,
    progress: &(dyn Fn(usize) + Sync),
) -> RenderOutput {
    render_samples(scene, bvh, env, settings, plan, 0..settings.spp, progress)
}

/// [`render_with_plan`] of the sample indices `samples` of every pixel alone (the render's
/// `settings.spp` is not read): the part of a render split by samples, whose film adds to the
/// other parts' to give the whole render's bits ([`part`]).
pub fn render_samples<'a>(
    scene: &'a Scene,
    bvh: impl Into<Tree<'a>>,
    env: &EnvironmentMap,
    settings: &RenderSettings,
    plan: RenderPlan,
    samples: std::ops::Range<u32>,
    progress: &(dyn Fn(usize) + Sync),
) -> RenderOutput {
    let (w, h) = (settings.width, settings.height);
    let cam = CameraRays::new(&scene.camera, w, h);
    let mut film = Film::new(w, h);
    let rows_done = AtomicUsize::new(0);
    let bvh: Tree<'a> = bvh.into();
    let tracer = Tracer::new(scene, bvh, plan, settings.max_depth, env);
    let count = samples.end.saturating_sub(samples.start);
    let samples = SampleRange {
        sampler: settings.sampler,
        seed: settings.seed,
        first: samples.start,
        count,
    };
    let (rays, rejected) = film
        .sum
        .par_chunks_mut((w * BAND).max(1) as usize)
        .enumerate()
        .map(|(band, rows)| {
            let r = trace_rows(&tracer, &cam, &samples, band as u32 * BAND, rows);
            let n = rows.len() / w.max(1) as usize;
            progress(rows_done.fetch_add(n, Ordering::Relaxed) + n);
            r
        })
        .reduce(|| (RayCounts::default(), 0), |a, b| (a.0 + b.0, a.1 + b.1));
    film.samples = count;
    film.rejected = rejected;
    RenderOutput { film, rays }
}

/// The render layers ([`aov`]) of the samples a render with `settings` takes: the same camera
/// rays, traced on all cores.
pub fn render_layers<'a>(
    scene: &'a Scene,
    bvh: impl Into<Tree<'a>>,
    env: &'a EnvironmentMap,
    settings: &RenderSettings,
    plan: RenderPlan,
) -> aov::AovFilm {
    let (w, h) = (settings.width, settings.height);
    let cam = CameraRays::new(&scene.camera, w, h);
    let tracer = Tracer::new(scene, bvh, plan, settings.max_depth, env);
    let mut layers = aov::AovFilm::new(w, h);
    let samples = SampleRange {
        sampler: settings.sampler,
        seed: settings.seed,
        first: 0,
        count: settings.spp,
    };
    layers.add(&tracer, &cam, &samples);
    layers
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

/// Rows traced together: camera rays go in tiles of [`TILE_WIDTH`] x `BAND` pixels.
pub const BAND: u32 = 8;
/// Columns of a camera-ray tile (a tile is one packet: `TILE_WIDTH * BAND` =
/// [`crate::bvh::PACKET`] rays).
pub const TILE_WIDTH: u32 = 8;

/// Adds the samples `samples` of every pixel of the rows from `y0` held in `rows` (whole rows
/// of `cam.width` pixels, at most [`BAND`] of them; one radiance sum per pixel); returns the
/// rays traced and the number of non-finite samples left out.
///
/// Camera rays go in packets of a [`TILE_WIDTH`] x [`BAND`] tile of pixels
/// ([`Bvh::intersect_packet`]), one sample index at a time: a square tile keeps the packet's
/// rays close in both directions, so the walk visits fewer boxes than for a row of 64 (1.6x
/// the rays per second on the dragon). The tiles are traced in parallel on the rayon pool, so
/// a batch of rows ends with every thread busy to within one tile (the viewer traces in short
/// batches). Each pixel still adds its samples in order and gets the hits single rays would,
/// so the image is the same bit for bit.
pub fn trace_rows(
    tracer: &Tracer,
    cam: &CameraRays,
    samples: &SampleRange,
    y0: u32,
    rows: &mut [Sum],
) -> (RayCounts, u64) {
    trace_rows_until(tracer, cam, samples, y0, rows, &|| false)
        .expect("a render that is never cancelled completes")
}

/// [`trace_rows`] that gives up as soon as `cancel` returns true (checked before each batch
/// of up to 16 samples of each tile, see `SAMPLES_PER_BATCH`): `None`, and `rows` as they
/// were. The viewer's still picture traces long
/// rounds of samples this way and still leaves them at once when the view changes.
pub fn trace_rows_until(
    tracer: &Tracer,
    cam: &CameraRays,
    samples: &SampleRange,
    y0: u32,
    rows: &mut [Sum],
    cancel: &(dyn Fn() -> bool + Sync),
) -> Option<(RayCounts, u64)> {
    use crate::bvh::PACKET;
    let w = cam.width as usize;
    if w == 0 {
        return Some((RayCounts::default(), 0));
    }
    debug_assert!(rows.len().is_multiple_of(w) && rows.len() / w <= BAND as usize);
    let height = rows.len() / w;
    let tile = TILE_WIDTH as usize;
    // The pixel of a tile's `k`-th ray: (x0 + k % tw, row k / tw of the band).
    let at = |x0: usize, tw: usize, k: usize| k / tw * w + x0 + k % tw;
    let before = &*rows;
    let tiles: Option<Vec<([Sum; PACKET], RayCounts, u64)>> = (0..w.div_ceil(tile))
        .into_par_iter()
        .map(|c| {
            let (x0, tw) = (c * tile, tile.min(w - c * tile));
            // The tile's sums so far, added to in order as in the film itself.
            let mut sums = [Sum::ZERO; PACKET];
            for (k, s) in sums[..tw * height].iter_mut().enumerate() {
                *s = before[at(x0, tw, k)];
            }
            // Denormals flushed for the tile's camera rays and shading (the thin lens' disk
            // sample took them too); see `Tracer::radiance_from_hit`.
            let (rays, rejected) = crate::cpu::with_denormals_flushed(|| {
                trace_tile(
                    tracer,
                    cam,
                    samples,
                    (x0, y0 as usize),
                    (tw, height),
                    &mut sums,
                    cancel,
                )
            })?;
            Some((sums, rays, rejected))
        })
        .collect();
    let tiles = tiles?;
    let mut rays = RayCounts::default();
    let mut rejected = 0u64;
    for (c, (sums, r, n)) in tiles.into_iter().enumerate() {
        let (x0, tw) = (c * tile, tile.min(w - c * tile));
        for (k, s) in sums[..tw * height].iter().enumerate() {
            rows[at(x0, tw, k)] = *s;
        }
        rays = rays + r;
        rejected += n;
    }
    Some((rays, rejected))
}

/// The camera ray of the sample `sampler` of pixel `(x, y)`: jittered within the pixel, and
/// from a point of the lens when `thin_lens`.
#[inline]
pub(crate) fn camera_ray(
    cam: &CameraRays,
    sampler: &PixelSampler,
    x: u32,
    y: u32,
    thin_lens: bool,
) -> crate::geometry::Ray {
    let jitter = sampler.get_2d(dim::PIXEL);
    let (px, py) = (x as f32 + jitter.x, y as f32 + jitter.y);
    if thin_lens {
        cam.thin_lens(px, py, concentric_disk(sampler.get_2d(dim::LENS)))
    } else {
        cam.pinhole(px, py)
    }
}

/// The samples of the `size.0 x size.1` tile of pixels from `corner` (at most one packet), added
/// to `sums` (row by row of the tile); returns the rays traced and the non-finite samples left
/// out, or `None` once `cancel` says to stop.
fn trace_tile(
    tracer: &Tracer,
    cam: &CameraRays,
    samples: &SampleRange,
    corner: (usize, usize),
    size: (usize, usize),
    sums: &mut [Sum; crate::bvh::PACKET],
    cancel: &(dyn Fn() -> bool + Sync),
) -> Option<(RayCounts, u64)> {
    use crate::bvh::PACKET;
    let ((x0, y0), (tw, height)) = (corner, size);
    let w = cam.width as u64;
    let n = tw * height;
    let mut rays = RayCounts::default();
    let mut rejected = 0u64;
    let thin_lens = tracer.plan.thin_lens && cam.lens_radius > 0.0;
    const ALL: usize = PACKET * SAMPLES_PER_BATCH;
    let mut camera_rays = [crate::geometry::Ray::new(Vec3::ZERO, Vec3::Z); ALL];
    let first = PixelSampler::new(samples.sampler, samples.seed, 0, 0);
    let mut firsts = [first; PACKET];
    let mut samplers = [first; ALL];
    let mut hits = [None; ALL];
    let mut radiance = [Vec3::ZERO; ALL];
    let mut batch = PathBatch::default();
    let pixel_of = |k: usize| (x0 + k % tw, y0 + k / tw);
    for (k, f) in firsts[..n].iter_mut().enumerate() {
        let (x, y) = pixel_of(k);
        *f = PixelSampler::new(samples.sampler, samples.seed, y as u64 * w + x as u64, 0);
    }
    let end = samples.first.saturating_add(samples.count);
    let mut s = samples.first;
    while s < end {
        if cancel() {
            return None;
        }
        // Up to SAMPLES_PER_BATCH samples of every pixel, sample after sample: each sample's
        // camera rays are one packet, and all their paths one batch.
        let m = ((end - s) as usize).min(SAMPLES_PER_BATCH);
        for j in 0..m {
            let at = j * n;
            for k in 0..n {
                let sampler = firsts[k].with_index(s + j as u32);
                let (x, y) = pixel_of(k);
                camera_rays[at + k] = camera_ray(cam, &sampler, x as u32, y as u32, thin_lens);
                samplers[at + k] = sampler;
            }
            tracer.bvh.intersect_packet(
                &camera_rays[at..at + n],
                f32::INFINITY,
                &mut hits[at..at + n],
            );
        }
        rays.camera += (m * n) as u64;
        let paths = samplers.map(PathSampler::new);
        tracer.radiance_batch(
            &mut batch,
            &camera_rays[..m * n],
            &hits[..m * n],
            &paths[..m * n],
            &mut rays,
            &mut radiance[..m * n],
        );
        // Added in sample order, as one sample a batch adds them.
        for l in radiance[..m * n].chunks_exact(n) {
            for (sum, l) in sums[..n].iter_mut().zip(l) {
                if l.is_finite() {
                    sum.add_sample(*l);
                } else {
                    rejected += 1;
                }
            }
        }
        s += m as u32;
    }
    Some((rays, rejected))
}

/// Samples of a tile's pixels whose paths advance as one batch ([`Tracer::radiance_batch`]):
/// more paths a batch fill the groups of rays a small scene's batches are traced in
/// ([`crate::bvh::Bvh::intersect_batch`]). A path's radiance does not depend on its batch.
const SAMPLES_PER_BATCH: usize = 16;

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use super::*;
    use crate::bvh::{BuildOptions, Bvh};
    use crate::cpu::{take_denormal_flag, with_denormals_flushed};
    use crate::scene::Scene;

    /// Inside `with_denormals_flushed` a denormal reads and is written as zero; outside it
    /// arithmetic is IEEE's again, on unwinding too.
    #[test]
    fn the_flush_is_on_inside_and_off_after() {
        let half_min = || std::hint::black_box(f32::MIN_POSITIVE) * std::hint::black_box(0.5);
        let tiny = std::hint::black_box(f32::from_bits(1));
        assert_eq!(with_denormals_flushed(half_min), 0.0);
        assert_eq!(with_denormals_flushed(|| tiny + 0.0), 0.0);
        assert_eq!(half_min(), f32::MIN_POSITIVE / 2.0);
        let unwound = std::panic::catch_unwind(|| with_denormals_flushed(|| panic!("inside")));
        assert!(unwound.is_err());
        assert_eq!(half_min(), f32::MIN_POSITIVE / 2.0);
        assert_eq!(tiny + 0.0, tiny);
    }

    /// Rendering takes no denormal operand outside the flushed regions (each a microcode
    /// assist on Intel CPUs; the compiler's vector code for three-float arithmetic computes
    /// spare lanes of stale data): the project's scenes with the direct and path integrators,
    /// a thin lens among them, on a pool of one thread whose MXCSR the check reads. Fails with
    /// the tiles' flush taken off (checked: the Cornell box); the flush covers the camera rays
    /// too, whose lens sample took denormals in one build of a probe and not in this test's.
    #[test]
    fn rendering_takes_no_denormal_operand_outside_the_flush() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/scenes");
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .expect("a pool of one thread");
        let settings = RenderSettings {
            width: 96,
            height: 64,
            spp: 8,
            ..Default::default()
        };
        for name in [
            "cornell_box.toml",
            "cornell_mirror_glass.toml",
            "depth_of_field.toml",
            "spot.toml",
            "transparent_shadow.toml",
        ] {
            let scene = Scene::load(&dir.join(name)).expect("a project scene");
            let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
            let took = pool.install(|| {
                take_denormal_flag();
                let out = render(&scene, &bvh, &settings, &|_| {}).expect("a render");
                assert!(out.rays.camera > 0);
                take_denormal_flag()
            });
            assert!(!took, "rendering {name} took a denormal operand");
        }
    }
}
