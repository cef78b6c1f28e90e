//! Times the moving picture's fixed costs per view alone: the render cache of a 950 x 720 view,
//! filled once, carried through an orbit about the scene's look-at point (`reproject`) and
//! made into a picture (`to_rgba8`, smoothed) at every step; between the two (untimed) only
//! the pixels the reprojection left empty are traced.
//! The A/B tool for the reprojection and the picture, beside `moving_orbit`.
//!
//! `cargo run --release --no-default-features --example reproject_time -- [SCENE] [VIEWS] [DEGREES_PER_VIEW]`
//! (defaults: `assets/scenes/dragon.toml`, 100 views, 2.4 degrees: the viewer's orbit at 30 ms
//! frames); `REPROJECT_TIME_THREADS=N` in the environment for N threads (default 1).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use glam::Quat;
use tracery::bvh::{BuildOptions, Bvh};
use tracery::camera::CameraRays;
use tracery::render::cache::{MovingFilter, RenderCache};
use tracery::render::{EnvironmentMap, RenderPlan, RenderSettings, Tracer};
use tracery::scene::Scene;

fn main() -> Result<()> {
    let mut args = std::env::args().skip(1);
    let path = PathBuf::from(args.next().unwrap_or("assets/scenes/dragon.toml".into()));
    let views: usize = args
        .next()
        .map_or(Ok(100), |s| s.parse())
        .context("views")?;
    let degrees: f32 = args
        .next()
        .map_or(Ok(2.4), |s| s.parse())
        .context("degrees per view")?;
    let threads: usize = std::env::var("REPROJECT_TIME_THREADS")
        .ok()
        .map(|s| s.parse())
        .transpose()
        .context("REPROJECT_TIME_THREADS")?
        .unwrap_or(1);
    let scene = Scene::load(&path)?;
    let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
    let env = EnvironmentMap::load(&scene.environment, true)?;
    let (w, h) = (950u32, 720u32);
    let mut plan =
        RenderPlan::with_integrator(&scene, scene.integrator, &RenderSettings::default());
    plan.max_light_samples = Some(1);
    let tracer = Tracer::new(&scene, &bvh, plan, 5, &env);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()?;
    pool.install(|| {
        let mut cam = CameraRays::new(&scene.camera, w, h);
        let mut cache = RenderCache::new(w, h, 1.0);
        cache.trace(&tracer, &cam, &(0..w * h).collect::<Vec<_>>());
        let centre = scene.camera.look_at;
        let q = Quat::from_rotation_y(degrees.to_radians());
        let (mut reproject, mut picture, mut holes) = (0.0, 0.0, 0usize);
        for _ in 0..views {
            cam.eye = centre + q * (cam.eye - centre);
            (cam.forward, cam.right, cam.up) = (q * cam.forward, q * cam.right, q * cam.up);
            let t0 = Instant::now();
            let empty = cache.reproject(&cam);
            reproject += t0.elapsed().as_secs_f64();
            // The pixels left empty are traced (untimed), as the viewer traces them first.
            holes += empty.len();
            cache.trace(&tracer, &cam, &empty);
            let t1 = Instant::now();
            std::hint::black_box(cache.to_rgba8(MovingFilter::Neighbours));
            picture += t1.elapsed().as_secs_f64();
        }
        let per_view = |s: f64| s * 1e3 / views as f64;
        println!(
            "{threads} thread(s), {views} views of {degrees} degrees: reprojecting {:.2} ms, making the picture {:.2} ms per view; {:.0} pixels left empty per view",
            per_view(reproject),
            per_view(picture),
            holes as f64 / views as f64
        );
    });
    Ok(())
}
