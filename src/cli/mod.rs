//! Command-line parsing and the commands.

mod bench;
mod check_mesh;
mod convergence;
mod render;
mod report;
mod stats;
#[cfg(feature = "viewer")]
mod view;

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result};
use clap::{Args, Parser, Subcommand};
use tracery::bvh::{BuildOptions, SplitMethod};
use tracery::scene::Scene;

/// Tracery: a CPU ray tracer with a BVH you can see into.
#[derive(Parser, Debug)]
#[command(version, about, long_about = None)]
pub struct Cli {
    /// With no command, the viewer opens on the built-in Cornell box.
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Open the real-time viewer on a scene file, OBJ, PLY or glTF (the built-in Cornell box by
    /// default): fly the camera, watch the image refine, inspect the BVH.
    #[cfg(feature = "viewer")]
    View(Box<view::ViewArgs>),
    /// Render a scene (TOML scene file, OBJ, PLY or glTF; the built-in Cornell box by default) to PNG, or
    /// to EXR / HDR in linear radiance.
    Render(render::RenderArgs),
    /// Build the BVH of a mesh or scene and print its statistics (median and SAH side by side).
    Stats(stats::StatsArgs),
    /// Benchmark the builders and traversal on the canonical camera rays, against Embree 3
    /// (with the `embree` feature) and obvhs: single rays, camera-ray packets, build times.
    Bench(bench::BenchArgs),
    /// Check a mesh: bounds, counts, non-finite, degenerate, needle and duplicate triangles,
    /// open and non-manifold edges. Exit status 0 clean, 1 not clean, 2 unreadable.
    CheckMesh(check_mesh::CheckMeshArgs),
    /// Print the README's measurement tables (Markdown).
    Report(report::ReportArgs),
    /// Measure image error against render time per sampler; write a CSV and a log-log plot.
    Convergence(convergence::ConvergenceArgs),
}

/// BVH settings shared by the commands.
#[derive(Args, Debug, Clone)]
pub struct BvhArgs {
    /// Split method: median or sah.
    #[arg(long, default_value_t = SplitMethod::Sah)]
    split: SplitMethod,
    /// SAH bins per axis (2 to 64).
    #[arg(long, default_value_t = BuildOptions::DEFAULT_BINS)]
    bins: u32,
    /// Largest number of triangles in a leaf (1 to 255).
    #[arg(long, default_value_t = BuildOptions::DEFAULT_LEAF_SIZE)]
    leaf_size: u32,
}

impl BvhArgs {
    pub fn options(&self) -> Result<BuildOptions> {
        let o = BuildOptions {
            split: self.split,
            bins: self.bins,
            max_leaf_size: self.leaf_size,
        };
        o.validate().map_err(anyhow::Error::msg)?;
        Ok(o)
    }
}

/// Runs the parsed command; the exit status is success unless the command says otherwise.
pub fn run(cli: Cli) -> Result<ExitCode> {
    let ok = |r: Result<()>| r.map(|()| ExitCode::SUCCESS);
    match cli.command {
        #[cfg(feature = "viewer")]
        None => run(Cli::parse_from(["tracery", "view"])),
        #[cfg(not(feature = "viewer"))]
        None => anyhow::bail!(
            "this build has no viewer (built without the `viewer` feature); try `tracery render`"
        ),
        #[cfg(feature = "viewer")]
        Some(Command::View(a)) => ok(view::run(*a)),
        Some(Command::Render(a)) => ok(render::run(a)),
        Some(Command::Stats(a)) => ok(stats::run(a)),
        Some(Command::CheckMesh(a)) => Ok(check_mesh::run(a)),
        Some(Command::Bench(a)) => ok(bench::run(a)),
        Some(Command::Report(a)) => ok(report::run(a)),
        Some(Command::Convergence(a)) => ok(convergence::run(a)),
    }
}

/// Loads a scene from a path, or the built-in Cornell box; prints load warnings.
pub fn load_scene(path: Option<&Path>) -> Result<Scene> {
    let scene = match path {
        Some(p) => Scene::load(p)?,
        None => Scene::cornell_box(),
    };
    for w in &scene.warnings {
        eprintln!("warning: {w}");
    }
    Ok(scene)
}

/// Makes the global rayon pool use `threads` threads (0: all cores).
pub fn set_threads(threads: usize) -> Result<()> {
    if threads > 0 {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build_global()
            .context("cannot set up the thread pool")?;
    }
    Ok(())
}

/// Creates the parent folder of an output file.
pub fn ensure_parent(path: &Path) -> Result<PathBuf> {
    if let Some(parent) = path.parent()
        && !parent.as_os_str().is_empty()
    {
        std::fs::create_dir_all(parent)
            .with_context(|| format!("{}: cannot create folder", parent.display()))?;
    }
    Ok(path.to_path_buf())
}
