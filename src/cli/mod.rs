//! Command-line parsing and the commands.

mod bench;
mod check_mesh;
mod convergence;
mod merge;
mod render;
mod report;
mod stats;
#[cfg(feature = "viewer")]
mod view;

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result};
use clap::{Args, CommandFactory, FromArgMatches, Parser, Subcommand};
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
    /// Add the parts of a render split by samples (`render --samples A..B`, EXR) into the
    /// picture of the whole render: the same bits as one render of all the samples.
    Merge(merge::MergeArgs),
    /// Build the BVH of a mesh or scene and print its statistics (median and SAH side by side).
    Stats(stats::StatsArgs),
    /// Benchmark the builders and traversal on the canonical camera rays, against Embree 3
    /// (where it is installed) and obvhs: single rays, camera-ray packets, build times.
    Bench(bench::BenchArgs),
    /// Check a mesh: bounds, counts, non-finite, degenerate, needle and duplicate triangles,
    /// open and non-manifold edges. Exit status 0 clean, 1 not clean, 2 unreadable.
    CheckMesh(check_mesh::CheckMeshArgs),
    /// Print the measurement tables of docs/benchmarks.md and docs/bvh.md (Markdown).
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

/// The commit the program was built from (and its date), as the build script found it.
const COMMIT: &str = env!("TRACERY_COMMIT");
const COMMIT_DATE: &str = env!("TRACERY_COMMIT_DATE");

/// The cargo features this build has (the ones that change what the program does).
fn features() -> Vec<&'static str> {
    let mut f = Vec::new();
    if cfg!(feature = "viewer") {
        f.push("viewer");
    }
    if cfg!(feature = "denoise") {
        f.push("denoise");
    }
    if cfg!(feature = "no-conservative-slab") {
        f.push("no-conservative-slab (test-only)");
    }
    if cfg!(feature = "no-watertight-fallback") {
        f.push("no-watertight-fallback (test-only)");
    }
    f
}

/// `tracery --version`: the version, the commit, the features, the traversal kernel this CPU
/// gets (`TRACERY_KERNEL` included) and whether Embree, the benchmark's peer, can be loaded.
pub fn long_version() -> String {
    use tracery::bvh::wide::Kernel;
    let date = if COMMIT_DATE.is_empty() {
        String::new()
    } else {
        format!(", {COMMIT_DATE}")
    };
    let features = features();
    let available: Vec<&str> = Kernel::available().iter().map(|k| k.name()).collect();
    format!(
        "{} (commit {COMMIT}{date})\nfeatures: {}\nkernel: {} (this CPU runs {})\nembree: {}",
        env!("CARGO_PKG_VERSION"),
        if features.is_empty() {
            "none".to_string()
        } else {
            features.join(", ")
        },
        Kernel::detect().name(),
        available.join(", "),
        match tracery::bench::embree::available() {
            Ok(library) => format!("{library}, for tracery bench"),
            Err(why) => why.to_string(),
        },
    )
}

/// Parses the command line (`--version` with [`long_version`]); exits on `--help`, `--version`
/// and usage errors, as clap does.
pub fn parse() -> Cli {
    // clap takes `&'static str`s; the two strings live for the one parse of the process.
    let version: &'static str =
        Box::leak(format!("{} ({COMMIT})", env!("CARGO_PKG_VERSION")).into_boxed_str());
    let long: &'static str = Box::leak(long_version().into_boxed_str());
    let matches = Cli::command()
        .version(version)
        .long_version(long)
        .get_matches();
    Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit())
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
        Some(Command::Merge(a)) => ok(merge::run(a)),
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

/// [`load_scene`] for a command that studies one tree over all of a scene's triangles: a
/// scene that places meshes many times is flattened into one mesh (said on stderr), or
/// refused when that would make more than [`FLAT_LIMIT`] triangles.
pub fn load_flat_scene(path: Option<&Path>, command: &str) -> Result<Scene> {
    let scene = load_scene(path)?;
    if scene.instances.is_empty() {
        return Ok(scene);
    }
    let n = scene.triangle_count();
    let placed = scene.instances.placements().len();
    if n > FLAT_LIMIT {
        anyhow::bail!(
            "{}: places {placed} copies of meshes, {n} triangles in all; `tracery {command}` studies them flattened into one mesh, which is refused past {FLAT_LIMIT} triangles (`tracery render` and `tracery view` trace the copies as placements)",
            scene.name
        );
    }
    eprintln!(
        "note: {}: its {placed} placed copies are flattened into one mesh of {n} triangles for `tracery {command}`",
        scene.name
    );
    Ok(scene.flattened())
}

/// The most triangles a scene of placed copies may be flattened into ([`load_flat_scene`]).
pub const FLAT_LIMIT: usize = 50_000_000;

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
