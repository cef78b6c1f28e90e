//! Rendering on all cores: camera rays, closest hits, direct light with hard shadows.
//!
//! Every pixel draws its samples from its own random stream, seeded from the pixel index and
//! the sample index, so an image is the same for any number of threads.

use std::sync::atomic::{AtomicUsize, Ordering};

use glam::{Vec2, Vec3};
use rayon::prelude::*;

use crate::bvh::Bvh;
use crate::camera::CameraRays;
use crate::film::Film;
use crate::geometry::{Ray, offset_ray_origin};
use crate::sampling::{SplitMix64, mix64};
use crate::scene::{Environment, Light, Scene, face_normal};

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
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            width: 512,
            height: 512,
            spp: 16,
            seed: 0,
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
}

impl std::ops::Add for RayCounts {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        Self {
            camera: self.camera + o.camera,
            shadow: self.shadow + o.shadow,
        }
    }
}

impl RayCounts {
    /// All rays.
    pub fn total(&self) -> u64 {
        self.camera + self.shadow
    }
}

/// The result of a render.
pub struct RenderOutput {
    /// Accumulated radiance.
    pub film: Film,
    /// Rays traced by kind.
    pub rays: RayCounts,
}

/// Renders `scene` with a prebuilt `bvh`. `progress` is called with the number of finished
/// rows (from any thread).
pub fn render(
    scene: &Scene,
    bvh: &Bvh,
    settings: &RenderSettings,
    progress: &(dyn Fn(usize) + Sync),
) -> RenderOutput {
    let (w, h) = (settings.width, settings.height);
    let cam = CameraRays::new(&scene.camera, w, h);
    let mut film = Film::new(w, h);
    let rows_done = AtomicUsize::new(0);
    let tracer = Tracer { scene, bvh };
    let (rays, rejected) = film
        .sum
        .par_chunks_mut(w as usize)
        .enumerate()
        .map(|(y, row)| {
            let mut rays = RayCounts::default();
            let mut rejected = 0u64;
            for (x, px) in row.iter_mut().enumerate() {
                let pixel = y as u64 * w as u64 + x as u64;
                for s in 0..settings.spp {
                    let mut rng = SplitMix64::new(mix64(
                        settings.seed ^ mix64(pixel.wrapping_mul(0x1_0000_0001) ^ s as u64),
                    ));
                    let jitter = Vec2::new(rng.next_f32(), rng.next_f32());
                    let ray = cam.thin_lens(x as f32 + jitter.x, y as f32 + jitter.y, Vec2::ZERO);
                    rays.camera += 1;
                    let l = tracer.radiance(&ray, &mut rng, &mut rays);
                    if l.is_finite() {
                        *px += l;
                    } else {
                        rejected += 1;
                    }
                }
            }
            progress(rows_done.fetch_add(1, Ordering::Relaxed) + 1);
            (rays, rejected)
        })
        .reduce(|| (RayCounts::default(), 0), |a, b| (a.0 + b.0, a.1 + b.1));
    film.samples = settings.spp;
    film.rejected = rejected;
    RenderOutput { film, rays }
}

struct Tracer<'a> {
    scene: &'a Scene,
    bvh: &'a Bvh,
}

impl Tracer<'_> {
    fn radiance(&self, ray: &Ray, rng: &mut SplitMix64, rays: &mut RayCounts) -> Vec3 {
        let Some(hit) = self.bvh.intersect(ray, f32::INFINITY) else {
            return environment(&self.scene.environment, ray.dir);
        };
        let scene = self.scene;
        let mat = scene.material_of(hit.prim);
        let tri = &scene.mesh.triangles[hit.prim as usize];
        let ns = &scene.mesh.normals[hit.prim as usize];
        let (u, v) = (hit.u, hit.v);
        let p = tri[0] * (1.0 - u - v) + tri[1] * u + tri[2] * v;
        // Two-sided: both normals face the side the ray came from.
        let mut ng = face_normal(tri);
        if ng.dot(ray.dir) > 0.0 {
            ng = -ng;
        }
        let mut n = (ns[0] * (1.0 - u - v) + ns[1] * u + ns[2] * v)
            .try_normalize()
            .unwrap_or(ng);
        if n.dot(ng) < 0.0 {
            n = -n;
        }
        let origin = offset_ray_origin(p, ng);
        let brdf = mat.diffuse * std::f32::consts::FRAC_1_PI;
        let mut l = mat.emission;
        for light in &scene.lights {
            l += match light {
                Light::Point {
                    position,
                    color,
                    intensity,
                } => {
                    let to = *position - origin;
                    let d2 = to.length_squared();
                    let cos = n.dot(to) / d2.sqrt();
                    if cos <= 0.0 || ng.dot(to) <= 0.0 {
                        continue;
                    }
                    rays.shadow += 1;
                    if self.bvh.occluded(&Ray::new(origin, to), 1.0) {
                        continue;
                    }
                    brdf * *color * *intensity * cos / d2
                }
                Light::Rect {
                    corner,
                    edge_u,
                    edge_v,
                    color,
                    intensity,
                    samples,
                } => {
                    let normal = edge_u.cross(*edge_v);
                    let area = normal.length();
                    let ln = normal / area;
                    let mut sum = Vec3::ZERO;
                    for _ in 0..*samples {
                        let q = *corner + rng.next_f32() * *edge_u + rng.next_f32() * *edge_v;
                        let to = q - origin;
                        let d2 = to.length_squared();
                        let d = d2.sqrt();
                        let cos = n.dot(to) / d;
                        let cos_l = -ln.dot(to) / d;
                        if cos <= 0.0 || cos_l <= 0.0 || ng.dot(to) <= 0.0 {
                            continue;
                        }
                        rays.shadow += 1;
                        // Stop just short of the light so its own quad does not shadow it.
                        if self.bvh.occluded(&Ray::new(origin, to), 1.0 - 1e-4) {
                            continue;
                        }
                        sum += brdf * *color * *intensity * cos * cos_l * area / d2;
                    }
                    sum / *samples as f32
                }
            };
        }
        l
    }
}

/// Radiance the environment sends along `dir` (image-based environments arrive with the
/// renderer issue; until then they count as black).
pub fn environment(env: &Environment, dir: Vec3) -> Vec3 {
    match env {
        Environment::None | Environment::CubeMap { .. } | Environment::Equirect { .. } => {
            Vec3::ZERO
        }
        Environment::Color(c) => *c,
        Environment::Sky { intensity, .. } => sky(dir) * *intensity,
    }
}

/// A simple procedural sky: a horizon-to-zenith gradient over a darker ground.
pub fn sky(dir: Vec3) -> Vec3 {
    let d = dir.try_normalize().unwrap_or(Vec3::Y);
    if d.y >= 0.0 {
        let t = d.y.powf(0.5);
        Vec3::new(0.85, 0.9, 1.0).lerp(Vec3::new(0.25, 0.45, 0.85), t)
    } else {
        let t = (-d.y).powf(0.5);
        Vec3::new(0.5, 0.47, 0.45).lerp(Vec3::new(0.2, 0.18, 0.16), t)
    }
}
