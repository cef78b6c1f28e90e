//! `tracery convergence`: image error against render time, per sampler.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use tracery::bvh::{BuildOptions, Bvh};
use tracery::convergence::{self, ConvergenceConfig, Peer, tick, time_to};
use tracery::render::Integrator;
use tracery::sampling::SamplerKind;

use super::{ensure_parent, load_flat_scene};

#[derive(Args, Debug)]
pub struct ConvergenceArgs {
    /// Scene file, OBJ, PLY or glTF (the built-in Cornell box when left out).
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
    /// RMSE at which to compare the times (default: the first peer's mean at its largest spp, else
    /// the first sampler's at --max-spp).
    #[arg(long)]
    target_rmse: Option<f64>,
    /// A reference image rendered elsewhere (linear EXR or HDR, of --width x --height),
    /// instead of rendering one.
    #[arg(long)]
    reference: Option<PathBuf>,
    /// Another renderer's measurements of the same picture against the same reference: a CSV
    /// with `spp,seconds,rmse` columns (a first `# label` line names it); may be repeated.
    #[arg(long)]
    peer: Vec<PathBuf>,
    /// Largest number of bounces after the camera's hit.
    #[arg(long, default_value_t = 5)]
    max_depth: u32,
    /// How light is gathered (default: the scene's).
    #[arg(long)]
    integrator: Option<Integrator>,
    /// Also denoise each render of the first sampler (Intel Open Image Denoise, guided by
    /// albedo and normal layers of the same samples) and draw it as a curve of its own, its
    /// time including the layers and the denoising.
    #[arg(long)]
    denoise: bool,
}

pub fn run(a: ConvergenceArgs) -> Result<()> {
    let mut scene = load_flat_scene(a.scene.as_deref(), "convergence")?;
    if let Some(i) = a.integrator {
        scene.integrator = i;
    }
    let peers = a
        .peer
        .iter()
        .map(|p| Peer::load(p))
        .collect::<Result<Vec<_>>>()?;
    let reference = a
        .reference
        .as_deref()
        .map(|p| convergence::load_reference(p, a.width, a.height))
        .transpose()?;
    let target_rmse = a.target_rmse.or_else(|| {
        // The first peer's mean error over its seeds at its largest sample count.
        peers
            .first()
            .and_then(|p| p.means().last().copied())
            .map(|(_, rmse)| rmse)
    });
    let config = ConvergenceConfig {
        width: a.width,
        height: a.height,
        max_spp: a.max_spp,
        seeds: a.seeds,
        reference_spp: a.reference_spp.unwrap_or(64 * a.max_spp),
        max_depth: a.max_depth,
        samplers: a.samplers,
        target_rmse,
        denoise: a.denoise,
    };
    config.validate(reference.is_some())?;
    let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
    let bar = ProgressBar::new(0).with_style(
        ProgressStyle::with_template(
            "{msg} {bar:40} {pos}/{len} renders, {elapsed} elapsed, eta {eta}",
        )
        .expect("valid template"),
    );
    bar.set_message(match &a.reference {
        Some(p) => format!("{}: against {},", scene.name, p.display()),
        None => format!(
            "{}: reference at {} spp, then",
            scene.name, config.reference_spp
        ),
    });
    let mut report = convergence::run(&scene, &bvh, &config, reference, &mut |done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    })?;
    report.peers = peers;
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

    match &a.reference {
        Some(p) => println!(
            "{} ({}): against {}; {} renders",
            scene.name,
            scene.integrator,
            p.display(),
            report.points.len()
        ),
        None => println!(
            "{} ({}): reference {} spp in {:.1} s; {} renders",
            scene.name,
            scene.integrator,
            config.reference_spp,
            report.reference_seconds,
            report.points.len()
        ),
    }
    print_tables(&report);
    println!("wrote {} and {}", csv.display(), png.display());
    Ok(())
}

/// The report's Markdown tables: each sampler's, the denoised curve's and each peer's slope
/// and time to the target error, then the comparison lines, then (with `--denoise`) the
/// rendered and denoised errors per sample count.
fn print_tables(report: &convergence::Report) {
    let target = report.target_rmse;
    println!(
        "| renderer | RMSE slope per spp | seconds to RMSE {} (measured) | (fitted) |",
        tick(target)
    );
    println!("|---|---:|---:|---:|");
    let show = |t: Option<f64>| t.map_or("not reached".to_string(), |t| format!("{t:.3}"));
    let mut measured = Vec::new();
    for f in &report.fits {
        let pts: Vec<(f64, f64)> = report
            .means
            .iter()
            .filter(|m| m.0 == f.sampler)
            .map(|m| (m.2, m.3))
            .collect();
        let t = time_to(&pts, target);
        measured.push((format!("tracery {}", f.sampler), t));
        println!(
            "| tracery {} | {:.3} | {} | {:.3} |",
            f.sampler,
            f.slope_spp,
            show(t),
            f.seconds_to_target
        );
    }
    if let (false, Some(f)) = (report.denoised.is_empty(), report.fits.first()) {
        let pts: Vec<(f64, f64)> = report.denoised.iter().map(|d| (d.1, d.2)).collect();
        let by_spp: Vec<(f64, f64)> = report
            .denoised
            .iter()
            .map(|d| ((d.0 as f64).ln(), d.2.ln()))
            .collect();
        let t = time_to(&pts, target);
        measured.push((format!("tracery {} denoised", f.sampler), t));
        println!(
            "| tracery {} denoised | {:.3} | {} | |",
            f.sampler,
            convergence::least_squares(&by_spp).0,
            show(t)
        );
    }
    for p in &report.peers {
        let pts = p.means();
        let by_spp: Vec<(f64, f64)> = p
            .points
            .iter()
            .filter(|q| q.0 > 0 && q.2 > 0.0)
            .map(|q| ((q.0 as f64).ln(), q.2.ln()))
            .collect();
        let t = time_to(&pts, target);
        measured.push((p.label.clone(), t));
        println!(
            "| {} | {:.3} | {} | |",
            p.label,
            convergence::least_squares(&by_spp).0,
            show(t)
        );
    }
    if let [(first, Some(t0)), rest @ ..] = measured.as_slice() {
        for (name, t) in rest {
            if let Some(t) = t {
                println!(
                    "{first} reaches RMSE {} in {:.2}x the time of {name}",
                    tick(target),
                    t0 / t
                );
            }
        }
    }
    print_denoised(report);
}

/// Per sample count, the first sampler's mean time and relative RMSE (the square root of
/// relMSE) as rendered and denoised (nothing without denoised renders).
fn print_denoised(report: &convergence::Report) {
    if !report.denoised.is_empty() {
        // Per sample count, the first sampler's mean time and relative RMSE (the square root
        // of relMSE) as rendered and denoised.
        let first = report.fits.first().map(|f| f.sampler);
        println!(
            "\n| spp | seconds | relative RMSE | seconds, denoised | relative RMSE, denoised |"
        );
        println!("|---:|---:|---:|---:|---:|");
        for &(spp, seconds, _, relmse) in &report.denoised {
            if let Some(m) = report
                .means
                .iter()
                .find(|m| Some(m.0) == first && m.1 == spp)
            {
                println!(
                    "| {spp} | {:.3} | {:.4} | {seconds:.3} | {:.4} |",
                    m.2,
                    m.4.sqrt(),
                    relmse.sqrt()
                );
            }
        }
    }
}
