//! Times the viewer's still picture without a window: `SPP` samples a pixel of a 950 x 720
//! view of a scene traced as the headless render does (every band with all its samples, one
//! parallel loop) and as the viewer's worker does (`Progressive::step_shaded` in slices of
//! `SLICE_MS`, rounds of passes), alternating, and prints each one's Mrays/s and their ratio.
//!
//! `cargo run --release --no-default-features --example still_time -- [SCENE] [SPP] [SLICE_MS] [ROUNDS]`
//! (defaults: `assets/scenes/dragon.toml`, 4, 15, 5).

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use tracery::bvh::{BuildOptions, Bvh};
use tracery::camera::CameraRays;
use tracery::render::progressive::Progressive;
use tracery::render::{EnvironmentMap, RenderPlan, RenderSettings, Tracer, render_with_plan};
use tracery::scene::Scene;

fn main() -> Result<()> {
    let mut args = std::env::args().skip(1);
    let path = PathBuf::from(args.next().unwrap_or("assets/scenes/dragon.toml".into()));
    let spp: u32 = args.next().map_or(Ok(4), |s| s.parse()).context("SPP")?;
    let slice: u64 = args
        .next()
        .map_or(Ok(15), |s| s.parse())
        .context("SLICE_MS")?;
    let rounds: usize = args.next().map_or(Ok(5), |s| s.parse()).context("ROUNDS")?;
    let scene = Scene::load(&path)?;
    let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
    let settings = RenderSettings {
        width: 950,
        height: 720,
        spp,
        ..RenderSettings::default()
    };
    let plan = RenderPlan::new(&scene, &settings);
    let env = EnvironmentMap::load(&scene.environment, plan.environment)?;
    let cam = CameraRays::new(&scene.camera, settings.width, settings.height);
    let (mut headless, mut viewer) = (Vec::new(), Vec::new());
    for _ in 0..rounds {
        let t0 = Instant::now();
        let out = render_with_plan(&scene, &bvh, &env, &settings, plan, &|_| {});
        headless.push(out.rays.total() as f64 / t0.elapsed().as_secs_f64() / 1e6);

        let mut film = Progressive::new(settings.width, settings.height);
        let t0 = Instant::now();
        while film.passes() < spp {
            let tracer = Tracer::new(&scene, &bvh, plan, settings.max_depth, &env);
            film.step_shaded(
                &tracer,
                &cam,
                settings.sampler,
                settings.seed,
                Duration::from_millis(slice),
                spp,
            );
        }
        viewer.push(film.rays.total() as f64 / t0.elapsed().as_secs_f64() / 1e6);
    }
    let show = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{x:.2}"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    println!(
        "{} {spp} spp 950x720, slices of {slice} ms: headless {} Mrays/s; viewer's rounds {}",
        path.display(),
        show(&headless),
        show(&viewer)
    );
    Ok(())
}
