//! Replays the viewer's moving picture headlessly: the render cache of a 950 x 720 view carried
//! through a full orbit about the scene's look-at point on one thread, each view traced for the
//! moving budget as the viewer's trace worker does (the pixels the reprojection left empty
//! first, then fresh samples by tile priority), then made into a picture. Prints where the time
//! goes per view, the fresh samples per view and what one costs, and what the camera rays alone
//! of those samples cost (traced again after the orbit). No window, so no frame rate: a steady
//! figure for changes to the cache and the shading, beside the viewer's `--orbit` run.
//!
//! `cargo run --release --no-default-features --example moving_orbit -- [SCENE] [BUDGET_MS] [VIEWS]`
//! (defaults: `assets/scenes/dragon.toml`, which needs `scripts/fetch-assets`; 20 ms; 150).

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use glam::Quat;
use tracery::bvh::{BuildOptions, Bvh};
use tracery::camera::CameraRays;
use tracery::render::cache::RenderCache;
use tracery::render::{EnvironmentMap, RenderPlan, RenderSettings, Tracer};
use tracery::scene::Scene;

/// Pixels traced per batch between checks of the budget (the viewer's for this size).
const CHUNK: usize = 950 * 720 / 64;

fn main() -> Result<()> {
    let mut args = std::env::args().skip(1);
    let path = PathBuf::from(args.next().unwrap_or("assets/scenes/dragon.toml".into()));
    let budget_ms: f64 = args
        .next()
        .map_or(Ok(20.0), |s| s.parse())
        .context("budget (ms)")?;
    let views: usize = args
        .next()
        .map_or(Ok(150), |s| s.parse())
        .context("views")?;
    let scene = Scene::load(&path)?;
    let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
    let env = EnvironmentMap::load(&scene.environment, true)?;
    let (w, h) = (950u32, 720u32);
    // As the viewer's moving picture: the scene's integrator, one shadow ray per area light.
    let mut plan =
        RenderPlan::with_integrator(&scene, scene.integrator, &RenderSettings::default());
    plan.max_light_samples = Some(1);
    let tracer = Tracer::new(&scene, &bvh, plan, 5, &env);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let budget = Duration::from_secs_f64(budget_ms * 1e-3);
    pool.install(|| {
        let mut cam = CameraRays::new(&scene.camera, w, h);
        let mut cache = RenderCache::new(w, h, 1.0);
        cache.trace(&tracer, &cam, &(0..w * h).collect::<Vec<_>>());
        let centre = scene.camera.look_at;
        let q = Quat::from_rotation_y(std::f32::consts::TAU / views as f32);
        let (mut reproject, mut trace, mut picture) = (0.0, 0.0, 0.0);
        let mut traced: Vec<(CameraRays, Vec<u32>)> = Vec::new();
        let wall = Instant::now();
        for _ in 0..views {
            cam.eye = centre + q * (cam.eye - centre);
            (cam.forward, cam.right, cam.up) = (q * cam.forward, q * cam.right, q * cam.up);
            let t0 = Instant::now();
            let mut holes = cache.reproject(&cam);
            let t1 = Instant::now();
            let mut pixels = Vec::new();
            while t1.elapsed() < budget {
                let batch: Vec<u32> = if holes.is_empty() {
                    cache.next_pixels(CHUNK)
                } else {
                    holes.drain(..CHUNK.min(holes.len())).collect()
                };
                cache.trace(&tracer, &cam, &batch);
                pixels.extend(batch);
            }
            let t2 = Instant::now();
            std::hint::black_box(cache.to_rgba8(true));
            let t3 = Instant::now();
            reproject += (t1 - t0).as_secs_f64();
            trace += (t2 - t1).as_secs_f64();
            picture += (t3 - t2).as_secs_f64();
            traced.push((cam, pixels));
        }
        let wall = wall.elapsed().as_secs_f64();
        let samples: usize = traced.iter().map(|(_, p)| p.len()).sum();
        // The same samples' camera rays alone.
        let t = Instant::now();
        let mut hits = 0usize;
        for (cam, pixels) in &traced {
            for &i in pixels {
                let ray = cam.pinhole((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
                hits += bvh.intersect(&ray, f32::INFINITY).is_some() as usize;
            }
        }
        let camera = t.elapsed().as_secs_f64();
        let per_view = |s: f64| s * 1e3 / views as f64;
        println!(
            "{} views in {wall:.2} s, per view: reprojecting {:.2} ms, tracing {:.2} ms, making the picture {:.2} ms; {:.0} fresh samples per view",
            views,
            per_view(reproject),
            per_view(trace),
            per_view(picture),
            samples as f64 / views as f64,
        );
        println!(
            "a fresh sample: {:.0} ns ({:.2} M samples/s of tracing); its camera ray alone: {:.0} ns ({hits} of {samples} hit)",
            trace / samples as f64 * 1e9,
            samples as f64 / trace / 1e6,
            camera / samples as f64 * 1e9,
        );
    });
    Ok(())
}
