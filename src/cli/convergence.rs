//! `tracery convergence`: image error against render time, per sampler.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use tracery::bvh::{BuildOptions, Bvh};
use tracery::convergence::{self, ConvergenceConfig};
use tracery::sampling::SamplerKind;

use super::{ensure_parent, load_scene};

#[derive(Args, Debug)]
pub struct ConvergenceArgs {
    /// Scene file, OBJ or PLY (the built-in Cornell box when left out).
    scene: Option<PathBuf>,
    /// Folder for convergence.csv and convergence.png.
    #[arg(long, default_value = "out/convergence")]
    out: PathBuf,
    /// Image width.
    #[arg(long, default_value_t = 128)]
    width: u32,
    /// Image height.
    #[arg(long, default_value_t = 96)]
    height: u32,
    /// Largest samples per pixel (a power of two); points at 1, 2, 4, ... up to it.
    #[arg(long, default_value_t = 256)]
    max_spp: u32,
    /// Independent seeds per point.
    #[arg(long, default_value_t = 5)]
    seeds: u32,
    /// Samples per pixel of the reference (default: 64 times --max-spp).
    #[arg(long)]
    reference_spp: Option<u32>,
    /// Samplers to compare, the first one sets the default target error.
    #[arg(long, value_delimiter = ',', default_value = "random,sobol")]
    samplers: Vec<SamplerKind>,
    /// RMSE at which to compare the samplers' times (default: the first sampler's at --max-spp).
    #[arg(long)]
    target_rmse: Option<f64>,
}

pub fn run(a: ConvergenceArgs) -> Result<()> {
    let scene = load_scene(a.scene.as_deref())?;
    let config = ConvergenceConfig {
        width: a.width,
        height: a.height,
        max_spp: a.max_spp,
        seeds: a.seeds,
        reference_spp: a.reference_spp.unwrap_or(64 * a.max_spp),
        samplers: a.samplers,
        target_rmse: a.target_rmse,
    };
    config.validate()?;
    let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
    let bar = ProgressBar::new(0).with_style(
        ProgressStyle::with_template(
            "{msg} {bar:40} {pos}/{len} renders, {elapsed} elapsed, eta {eta}",
        )
        .expect("valid template"),
    );
    bar.set_message(format!(
        "{}: reference at {} spp, then",
        scene.name, config.reference_spp
    ));
    let report = convergence::run(&scene, &bvh, &config, &mut |done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    })?;
    bar.finish_and_clear();

    std::fs::create_dir_all(&a.out)?;
    let csv = ensure_parent(&a.out.join("convergence.csv"))?;
    let png = a.out.join("convergence.png");
    convergence::write_csv(&csv, &report)?;
    let title = format!(
        "{}: RMSE against render time, {}x{}, {} seeds per point",
        scene.name, config.width, config.height, config.seeds
    );
    convergence::plot(&png, &report, &title)?;

    println!(
        "{}: reference {} spp in {:.1} s; {} renders",
        scene.name,
        config.reference_spp,
        report.reference_seconds,
        report.points.len()
    );
    println!(
        "| sampler | RMSE slope per spp | RMSE slope per second | seconds to RMSE {:.5} |",
        report.target_rmse
    );
    println!("|---|---:|---:|---:|");
    for f in &report.fits {
        println!(
            "| {} | {:.3} | {:.3} | {:.4} |",
            f.sampler, f.slope_spp, f.slope_time, f.seconds_to_target
        );
    }
    if let [first, rest @ ..] = report.fits.as_slice() {
        for f in rest {
            println!(
                "{} reaches the target error {:.2}x faster than {}",
                f.sampler,
                first.seconds_to_target / f.seconds_to_target,
                first.sampler
            );
        }
    }
    println!("wrote {} and {}", csv.display(), png.display());
    Ok(())
}
