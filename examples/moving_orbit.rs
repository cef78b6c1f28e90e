//! Replays the viewer's moving picture headlessly: the render cache of a 950 x 720 view carried
//! through a full orbit about the scene's look-at point on one thread, each view traced for the
//! moving budget as the viewer's trace worker does (the pixels the reprojection left empty
//! first, then fresh samples by tile priority), then made into a picture. Prints where the time
//! goes per view, the fresh samples per view and what one costs, and what the camera rays alone
//! of those samples cost (traced again after the orbit). No window, so no frame rate: a steady
//! figure for changes to the cache and the shading, beside the viewer's `--orbit` run.
//!
//! With `QUALITY_EVERY` n > 0, every n-th view's picture is compared with the headless render
//! of its pose at `MOVING_ORBIT_REFERENCE_SPP` samples per pixel (default 64): the RMSE in 8-bit
//! levels of the picture through each of the moving picture's filters, and their means; the
//! views are traced and shown with `MOVING_ORBIT_FILTER` (`off`, `neighbours` or `wavelet`, the
//! default). With `MOVING_ORBIT_SAMPLES=N` in the
//! environment every view gets exactly N fresh samples instead of the time budget, so two
//! builds' pictures can be compared sample for sample. `MOVING_ORBIT_THREADS=N` traces on N
//! threads instead of one.
//!
//! `cargo run --release --no-default-features --example moving_orbit -- [SCENE] [BUDGET_MS] [VIEWS] [QUALITY_EVERY]`
//! (defaults: `assets/scenes/dragon.toml`, which needs `scripts/fetch-assets`; 20 ms; 150; 0).

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use glam::Quat;
use tracery::bvh::{BuildOptions, Bvh};
use tracery::camera::CameraRays;
use tracery::film::rmse_levels;
use tracery::render::cache::{MovingFilter, RenderCache};
use tracery::render::{EnvironmentMap, RenderPlan, RenderSettings, Tracer, render_with_plan};
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
    let quality_every: usize = args
        .next()
        .map_or(Ok(0), |s| s.parse())
        .context("quality every")?;
    let fixed: Option<usize> = std::env::var("MOVING_ORBIT_SAMPLES")
        .ok()
        .map(|s| s.parse())
        .transpose()
        .context("MOVING_ORBIT_SAMPLES")?;
    let reference_spp: u32 = std::env::var("MOVING_ORBIT_REFERENCE_SPP")
        .ok()
        .map(|s| s.parse())
        .transpose()
        .context("MOVING_ORBIT_REFERENCE_SPP")?
        .unwrap_or(64);
    let shown_filter = match std::env::var("MOVING_ORBIT_FILTER").as_deref() {
        Err(_) | Ok("wavelet") => MovingFilter::Wavelet,
        Ok("neighbours") => MovingFilter::Neighbours,
        Ok("off") => MovingFilter::Off,
        Ok(other) => {
            anyhow::bail!("MOVING_ORBIT_FILTER: {other}: expected off, neighbours or wavelet")
        }
    };
    let scene = Scene::load(&path)?;
    let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
    let env = EnvironmentMap::load(&scene.environment, true)?;
    let (w, h) = (950u32, 720u32);
    // As the viewer's moving picture: the scene's integrator, one shadow ray per area light.
    let mut plan =
        RenderPlan::with_integrator(&scene, scene.integrator, &RenderSettings::default());
    plan.max_light_samples = Some(1);
    let tracer = Tracer::new(&scene, &bvh, plan, 5, &env);
    let threads: usize = std::env::var("MOVING_ORBIT_THREADS")
        .ok()
        .map(|s| s.parse())
        .transpose()
        .context("MOVING_ORBIT_THREADS")?
        .unwrap_or(1);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()?;
    let budget = Duration::from_secs_f64(budget_ms * 1e-3);
    pool.install(|| {
        let mut cam = CameraRays::new(&scene.camera, w, h);
        let mut cache = RenderCache::new(w, h, 1.0);
        cache.trace(&tracer, &cam, &(0..w * h).collect::<Vec<_>>());
        let centre = scene.camera.look_at;
        let q = Quat::from_rotation_y(std::f32::consts::TAU / views as f32);
        let (mut reproject, mut trace, mut picture) = (0.0, 0.0, 0.0);
        let mut traced: Vec<(CameraRays, Vec<u32>)> = Vec::new();
        let mut errors = Vec::new();
        let mut reference_time = Duration::ZERO;
        let wall = Instant::now();
        for view in 0..views {
            cam.eye = centre + q * (cam.eye - centre);
            (cam.forward, cam.right, cam.up) = (q * cam.forward, q * cam.right, q * cam.up);
            let t0 = Instant::now();
            let mut holes = cache.reproject(&cam);
            let t1 = Instant::now();
            let mut pixels = Vec::new();
            let more = |traced: usize| match fixed {
                Some(n) => traced < n,
                None => t1.elapsed() < budget,
            };
            while more(pixels.len()) {
                let n = fixed.map_or(CHUNK, |n| CHUNK.min(n - pixels.len()));
                let batch: Vec<u32> = if holes.is_empty() {
                    cache.next_pixels(n)
                } else {
                    holes.drain(..n.min(holes.len())).collect()
                };
                cache.trace(&tracer, &cam, &batch);
                pixels.extend(batch);
            }
            let t2 = Instant::now();
            std::hint::black_box(cache.to_rgba8(shown_filter));
            let t3 = Instant::now();
            if quality_every > 0 && (view + 1) % quality_every == 0 {
                let r = Instant::now();
                let converged = reference(&scene, &bvh, &env, &cam, w, h, reference_spp);
                errors.push(MovingFilter::ALL.map(|f| rmse_levels(&cache.to_rgba8(f), &converged)));
                reference_time += r.elapsed();
            }
            reproject += (t1 - t0).as_secs_f64();
            trace += (t2 - t1).as_secs_f64();
            picture += (t3 - t2).as_secs_f64();
            traced.push((cam, pixels));
        }
        let wall = (wall.elapsed() - reference_time).as_secs_f64();
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
        for (k, filter) in MovingFilter::ALL.into_iter().enumerate() {
            if errors.is_empty() {
                break;
            }
            let list: Vec<String> = errors.iter().map(|e| format!("{:.2}", e[k])).collect();
            println!(
                "moving picture ({}) against the {reference_spp}-spp render of its pose, every {quality_every} views: RMSE {} levels, mean {:.2}",
                filter.name(),
                list.join(", "),
                errors.iter().map(|e| e[k]).sum::<f64>() / errors.len() as f64
            );
        }
    });
    Ok(())
}

/// The headless render of the view `cam` at `spp` samples per pixel, as RGBA8.
fn reference(
    scene: &Scene,
    bvh: &Bvh,
    env: &EnvironmentMap,
    cam: &CameraRays,
    w: u32,
    h: u32,
    spp: u32,
) -> Vec<u8> {
    let mut scene = scene.clone();
    scene.camera.position = cam.eye;
    scene.camera.look_at = cam.eye + cam.forward;
    scene.camera.up = cam.up;
    let settings = RenderSettings {
        width: w,
        height: h,
        spp,
        ..RenderSettings::default()
    };
    let plan = RenderPlan::new(&scene, &settings);
    render_with_plan(&scene, bvh, env, &settings, plan, &|_| {})
        .film
        .to_rgba8(1.0)
}
