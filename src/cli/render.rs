//! `tracery render`: render a scene to PNG (tone mapped) or EXR / HDR (linear radiance) on all
//! cores, with a progress bar.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Result;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use tracery::bvh::Bvh;
use tracery::render::{Explain, Integrator, RenderPlan, RenderSettings, render};
use tracery::sampling::SamplerKind;

use super::{BvhArgs, ensure_parent, load_scene, set_threads};

#[derive(Args, Debug)]
pub struct RenderArgs {
    /// Scene file (TOML), OBJ, PLY or glTF (`.gltf`, `.glb`); the built-in Cornell box when left out.
    scene: Option<PathBuf>,
    /// Output image: `.png` (tone mapped, after `--exposure`), `.exr` or `.hdr` (linear
    /// radiance, no exposure or tone mapping).
    #[arg(short, long, default_value = "out/render.png")]
    output: PathBuf,
    /// Image width in pixels.
    #[arg(long, default_value_t = 512)]
    width: u32,
    /// Image height in pixels.
    #[arg(long, default_value_t = 512)]
    height: u32,
    /// Samples per pixel.
    #[arg(long, default_value_t = 16)]
    spp: u32,
    /// Seed of the random streams (the same seed gives the same image on any thread count).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Sampler for pixel, lens and light samples: sobol (Owen-scrambled) or random.
    #[arg(long, default_value_t = SamplerKind::Sobol)]
    sampler: SamplerKind,
    /// Largest number of bounces after the camera's hit (mirrors, transparent surfaces and,
    /// with the path integrator, diffuse bounces).
    #[arg(long, default_value_t = 5)]
    max_depth: u32,
    /// How light is gathered: direct (light from the lights and emissive surfaces only) or
    /// path (global illumination); default: the scene's (`[render] integrator`, else direct).
    #[arg(long)]
    integrator: Option<Integrator>,
    /// Print the render plan (what the scene needs and what is left out), then render.
    #[arg(long)]
    explain: bool,
    /// Shade the normals that normal and height maps bend as they are, without the shadowing
    /// term that softens their shadow terminator (on by default, as in Mitsuba 3).
    #[arg(long)]
    hard_terminator: bool,
    /// Exposure multiplier applied before tone mapping.
    #[arg(long, default_value_t = 1.0)]
    exposure: f32,
    #[command(flatten)]
    bvh: BvhArgs,
    /// Threads to render with (default: every core).
    #[arg(long, default_value_t = 0)]
    threads: usize,
}

pub fn run(a: RenderArgs) -> Result<()> {
    set_threads(a.threads)?;
    let settings = RenderSettings {
        width: a.width,
        height: a.height,
        spp: a.spp,
        seed: a.seed,
        max_depth: a.max_depth,
        sampler: a.sampler,
        soft_terminator: !a.hard_terminator,
    };
    settings.validate().map_err(anyhow::Error::msg)?;
    tracery::film::OutputKind::of(&a.output)?;
    let options = a.bvh.options()?;
    let mut scene = load_scene(a.scene.as_deref())?;
    if let Some(i) = a.integrator {
        scene.integrator = i;
    }
    if a.explain {
        let plan = RenderPlan::new(&scene, &settings);
        eprintln!("{}", Explain(&plan, &scene, &settings));
    }
    let bvh = Bvh::build(&scene.mesh.triangles, &options);
    let s = &bvh.stats;
    eprintln!(
        "{}: {} triangles; BVH ({}, {} bins, leaf {}) built in {:.1} ms: {} levels, {} leaves, SAH cost {:.2}{}",
        scene.name,
        scene.triangle_count(),
        options.split,
        options.bins,
        options.max_leaf_size,
        s.build_ms,
        s.levels,
        s.leaves,
        s.sah_cost,
        if s.excluded + s.degenerate > 0 {
            format!(
                "; left out: {} with non-finite vertices, {} with zero area",
                s.excluded, s.degenerate
            )
        } else {
            String::new()
        }
    );
    let bar = ProgressBar::new(settings.height as u64).with_style(
        ProgressStyle::with_template(
            "rendering {bar:40} {pos}/{len} rows, {elapsed} elapsed, eta {eta}",
        )
        .expect("valid template"),
    );
    let start = Instant::now();
    let out = render(&scene, &bvh, &settings, &|_| bar.inc(1))?;
    let took = start.elapsed();
    bar.finish_and_clear();
    let path = ensure_parent(&a.output)?;
    out.film.save(&path, a.exposure)?;
    let secs = took.as_secs_f64();
    let r = &out.rays;
    println!(
        "wrote {} ({}x{}, {} spp) in {:.0} ms: rays {} camera, {} shadow, {} reflection, {} transmission, {} bounce; {:.2} Mrays/s{}",
        path.display(),
        settings.width,
        settings.height,
        settings.spp,
        secs * 1e3,
        r.camera,
        r.shadow,
        r.reflection,
        r.transmission,
        r.bounce,
        out.rays.total() as f64 / secs / 1e6,
        if out.film.rejected > 0 {
            format!("; {} non-finite samples left out", out.film.rejected)
        } else {
            String::new()
        }
    );
    Ok(())
}
