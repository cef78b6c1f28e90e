//! `tracery view` (and `tracery` with no command): the real-time viewer.

use std::path::PathBuf;

use anyhow::{Result, bail};
use bevy::math::{UVec2, Vec2, Vec3};
use clap::{Args, ValueEnum};
use tracery::render::cache::MovingFilter;
use tracery::viewer::capture::CaptureScript;
use tracery::viewer::gizmos::LeafView;
use tracery::viewer::trace::{RenderMode, ViewSettings};
use tracery::viewer::{StartGizmos, ViewOptions};

use super::BvhArgs;

#[derive(Args, Debug)]
pub struct ViewArgs {
    /// Scene file (TOML), OBJ, PLY or glTF (`.gltf`, `.glb`); the built-in Cornell box when left out.
    scene: Option<PathBuf>,
    /// Window width in pixels.
    #[arg(long, default_value_t = 1280)]
    width: u32,
    /// Window height in pixels.
    #[arg(long, default_value_t = 720)]
    height: u32,
    /// Stop accumulating at this many samples per pixel.
    #[arg(long, default_value_t = 1024)]
    spp: u32,
    /// Largest number of mirror or transparent bounces.
    #[arg(long, default_value_t = 5)]
    max_depth: u32,
    /// Image resolution relative to the window.
    #[arg(long, default_value_t = 1.0)]
    scale: f32,
    /// While the picture changes, one frame every this many milliseconds (0: as fast as the
    /// window draws; every frame the window draws is CPU time the tracing does not get).
    #[arg(long, default_value_t = 30.0)]
    frame_ms: f32,
    /// What the image shows at start.
    #[arg(long, value_enum, default_value_t = Mode::Shaded)]
    mode: Mode,
    /// BVH level for the level gizmo and the overlap view.
    #[arg(long, default_value_t = 0)]
    level: u32,
    /// Gizmos on at start (comma-separated): level, leaves, leaf, ray-nodes.
    #[arg(long, value_delimiter = ',')]
    gizmos: Vec<Gizmo>,
    /// The leaf drawn alone with its triangles (`--gizmos leaf`).
    #[arg(long, default_value_t = 0)]
    leaf: u32,
    /// Shoot a debug ray through this window pixel at start: X,Y.
    #[arg(long, value_parser = parse_pixel)]
    ray: Option<Vec2>,
    /// Once the scene is up (and the --ray debug ray shot), move the camera here: X,Y,Z.
    /// Shows a debug ray from the side.
    #[arg(long, value_parser = parse_point, requires = "look_at")]
    look_from: Option<Vec3>,
    /// With --look-from: the point the camera then looks at, X,Y,Z.
    #[arg(long, value_parser = parse_point, requires = "look_from")]
    look_at: Option<Vec3>,
    /// Hide the inspector and status line (Tab shows them).
    #[arg(long)]
    no_ui: bool,
    /// Open a glTF's animations at this time, in seconds (the inspector's timeline scrubs
    /// them).
    #[arg(long, default_value_t = 0.0)]
    time: f64,
    /// Play the animations from the start (Space plays and pauses).
    #[arg(long)]
    play: bool,
    /// Show the still picture as traced, not denoised (N toggles it; the default in builds
    /// with the denoiser is on).
    #[arg(long)]
    no_denoise: bool,
    /// How the moving picture's samples, one per pixel, are filtered for display.
    #[arg(long, value_enum, default_value_t = MovingFilterArg::Wavelet)]
    moving_filter: MovingFilterArg,
    #[command(flatten)]
    bvh: BvhArgs,
    /// Scripted run: run this many frames, then save --screenshot (if given) and exit.
    #[arg(long)]
    frames: Option<u32>,
    /// With --frames: also wait until the full image has --spp samples per pixel.
    #[arg(long)]
    wait_spp: bool,
    /// With --frames: window screenshot to save before exiting (PNG).
    #[arg(long)]
    screenshot: Option<PathBuf>,
    /// With --frames: orbit the camera for this many frames (72 degrees a second about the
    /// scene's look-at point), then stop and let the picture converge to --spp; prints the moving frame times and fresh samples per frame, the
    /// moving picture's error against the converged one (and a stretched preview's), the
    /// still Mrays/s against `tracery render` of the same view, and the idle CPU use.
    #[arg(long, default_value_t = 0)]
    orbit: u32,
    /// With --orbit: save the last moving picture, the converged picture of its pose and the
    /// two stretched previews as PNGs into this directory (moving.png, converged.png,
    /// stretched.png, earlier.png).
    #[arg(long, value_name = "DIR")]
    orbit_pictures: Option<PathBuf>,
}

/// The moving picture's filters, as `--moving-filter` names them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum MovingFilterArg {
    /// The samples as traced.
    Off,
    /// Each sample averaged with its four neighbours on the same surface.
    Neighbours,
    /// Edge-avoiding à-trous wavelet filter guided by normals, positions and albedos.
    Wavelet,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ValueEnum)]
enum Mode {
    /// The shaded scene.
    #[default]
    Shaded,
    /// Traversal cost heatmap.
    Cost,
    /// Boxes of the level each ray crosses.
    Overlap,
    /// Where the samples go: samples per pixel of each tile in the last picture.
    Work,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum Gizmo {
    /// Boxes of --level.
    Level,
    /// All leaves.
    Leaves,
    /// Leaf --leaf with its triangles.
    Leaf,
    /// The nodes the debug ray entered.
    RayNodes,
}

fn parse_pixel(s: &str) -> Result<Vec2, String> {
    let (x, y) = s
        .split_once(',')
        .ok_or_else(|| format!("`{s}`: expected X,Y"))?;
    let p = |v: &str| v.trim().parse::<f32>().map_err(|e| format!("`{v}`: {e}"));
    Ok(Vec2::new(p(x)?, p(y)?))
}

fn parse_point(s: &str) -> Result<Vec3, String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|v| v.trim().parse::<f32>().map_err(|e| format!("`{v}`: {e}")))
        .collect::<Result<_, _>>()?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok(Vec3::new(x, y, z)),
        _ => Err(format!("`{s}`: expected three finite numbers X,Y,Z")),
    }
}

pub fn run(a: ViewArgs) -> Result<()> {
    if a.width == 0 || a.height == 0 {
        bail!("window size {}x{} has no pixels", a.width, a.height);
    }
    if !a.time.is_finite() {
        bail!("--time {}: expected a number of seconds", a.time);
    }
    if a.spp == 0 {
        bail!("--spp must be at least 1");
    }
    if !(a.scale > 0.0 && a.scale <= 1.0) {
        bail!("--scale must be in (0, 1], not {}", a.scale);
    }
    if !(a.frame_ms >= 0.0 && a.frame_ms <= 1000.0) {
        bail!("--frame-ms must be in [0, 1000], not {}", a.frame_ms);
    }
    if a.frames.is_none() && (a.screenshot.is_some() || a.orbit > 0 || a.wait_spp) {
        bail!("--screenshot, --orbit and --wait-spp need --frames");
    }
    if a.orbit_pictures.is_some() && a.orbit == 0 {
        bail!("--orbit-pictures needs --orbit");
    }
    if let (Some(from), Some(at)) = (a.look_from, a.look_at)
        && from == at
    {
        bail!("--look-from and --look-at are the same point: no view direction");
    }
    if let Some(p) = &a.scene
        && !p.exists()
    {
        bail!("{}: no such file", p.display());
    }
    let options = a.bvh.options()?;
    let settings = ViewSettings {
        max_samples: a.spp,
        max_depth: a.max_depth,
        scale: a.scale,
        level: a.level,
        frame_ms: a.frame_ms,
        denoise: tracery::denoise::AVAILABLE && !a.no_denoise,
        moving_filter: match a.moving_filter {
            MovingFilterArg::Off => MovingFilter::Off,
            MovingFilterArg::Neighbours => MovingFilter::Neighbours,
            MovingFilterArg::Wavelet => MovingFilter::Wavelet,
        },
        mode: match a.mode {
            Mode::Shaded => RenderMode::Shaded,
            Mode::Cost => RenderMode::TraversalCost,
            Mode::Overlap => RenderMode::Overlap,
            Mode::Work => RenderMode::Work,
        },
        ..ViewSettings::default()
    };
    let has = |g| a.gizmos.contains(&g);
    tracery::viewer::run(ViewOptions {
        scene: a.scene.clone(),
        window: UVec2::new(a.width, a.height),
        bvh: options,
        settings,
        inspector: !a.no_ui,
        gizmos: StartGizmos {
            level: has(Gizmo::Level),
            leaves: has(Gizmo::Leaves) || has(Gizmo::Leaf),
            ray_nodes: has(Gizmo::RayNodes),
        },
        leaves: LeafView {
            all: has(Gizmo::Leaves),
            index: a.leaf,
            ..LeafView::default()
        },
        ray: a.ray,
        look: a.look_from.zip(a.look_at),
        script: a.frames.map(|frames| CaptureScript {
            frames,
            samples: a.wait_spp.then_some(a.spp),
            screenshot: a.screenshot.clone(),
            orbit_frames: a.orbit,
            orbit_pictures: a.orbit_pictures.clone(),
        }),
        animation: (a.time, a.play),
    })
}
