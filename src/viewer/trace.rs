//! The ray-trace system: traces the view of the [`TraceCamera`] into a progressive film within
//! a time budget per frame, accumulating while nothing changes and starting over (with a quick
//! low-resolution preview) whenever the camera, scene or settings change.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use bevy::prelude::*;

use super::bvh::SceneBvh;
use super::scene::{CurrentScene, SceneSystems};
use super::task::Background;
use crate::bvh::Bvh;
use crate::camera::CameraRays;
use crate::render::heatmap::{cost_row, cost_summary, heatmap_rgba8, overlap_row};
use crate::render::progressive::StepReport;
use crate::render::{EnvironmentMap, Progressive, RayCounts, RenderPlan, RenderSettings, Tracer};
use crate::sampling::SamplerKind;
use crate::scene::{Environment, Scene};

/// Traces the view every frame and keeps [`TracedImage`] up to date.
pub struct TracePlugin {
    /// Settings at start.
    pub settings: ViewSettings,
    /// Size of the full-resolution image until a window says otherwise.
    pub viewport: UVec2,
}

impl Plugin for TracePlugin {
    fn build(&self, app: &mut App) {
        app.insert_resource(self.settings.clone())
            .insert_resource(ViewportSize(self.viewport.max(UVec2::ONE)))
            .init_resource::<LoadedEnvironment>()
            .init_resource::<Accumulation>()
            .init_resource::<TracedImage>()
            .init_resource::<TraceStats>()
            .add_systems(
                PreUpdate,
                (scene_defaults, update_environment)
                    .chain()
                    .after(SceneSystems),
            )
            .add_systems(Update, trace.in_set(TraceSystems));
    }
}

/// The ray-trace system, for ordering (gizmos and the display run after it).
#[derive(SystemSet, Debug, Clone, PartialEq, Eq, Hash)]
pub struct TraceSystems;

/// Marks the camera whose transform and projection the traced rays come from.
#[derive(Component, Default)]
pub struct TraceCamera;

/// Size in physical pixels of the area the traced image fills (the window).
#[derive(Resource, Clone, Copy, Debug, PartialEq, Eq)]
pub struct ViewportSize(pub UVec2);

/// What the traced image shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum RenderMode {
    /// The shaded scene.
    #[default]
    Shaded,
    /// BVH nodes each pixel's camera ray entered, as a heatmap.
    TraversalCost,
    /// How many boxes of the chosen BVH level each pixel's ray passes through.
    Overlap,
}

/// Which environment rays that leave the scene see.
#[derive(Clone, Debug, PartialEq, Default)]
pub enum EnvChoice {
    /// The scene file's own.
    #[default]
    FromScene,
    /// Black.
    None,
    /// The procedural sky.
    Sky,
    /// The fetched six-face cube map.
    CubeMap,
    /// An equirectangular HDR image.
    Hdr(PathBuf),
}

/// The render settings edited in the inspector.
#[derive(Resource, Clone, Debug, PartialEq)]
pub struct ViewSettings {
    /// Image resolution relative to the window (1: one traced pixel per window pixel).
    pub scale: f32,
    /// Most passes (samples per pixel) traced in one frame.
    pub samples_per_frame: u32,
    /// Accumulation stops at this many samples per pixel.
    pub max_samples: u32,
    /// Largest number of mirror or transparent bounces.
    pub max_depth: u32,
    /// Shadow rays on.
    pub shadows: bool,
    /// Shadow rays pass through transparent surfaces.
    pub transparent_shadows: bool,
    /// How samples are drawn.
    pub sampler: SamplerKind,
    /// Seed of the random streams.
    pub seed: u64,
    /// Exposure before tone mapping (changing it re-maps the image without tracing again).
    pub exposure: f32,
    /// Thin-lens depth of field on.
    pub depth_of_field: bool,
    /// Lens radius in scene units.
    pub lens_radius: f32,
    /// Distance to the plane in focus.
    pub focus_distance: f32,
    /// The environment.
    pub environment: EnvChoice,
    /// Multiplies the environment's brightness.
    pub env_intensity: f32,
    /// Turns the environment about +y, in degrees (added to the scene's own rotation).
    pub env_rotation_deg: f32,
    /// What the image shows.
    pub mode: RenderMode,
    /// BVH level the overlap view counts (also the level gizmo's level).
    pub level: u32,
    /// Top of the heatmap scale (0: the image's largest value).
    pub heat_max: f32,
    /// Time the tracing may take per frame while the camera is still, in milliseconds.
    pub frame_budget_ms: f32,
    /// Time a preview pass should take while the camera moves, in milliseconds.
    pub moving_budget_ms: f32,
}

impl Default for ViewSettings {
    fn default() -> Self {
        let r = RenderSettings::default();
        Self {
            scale: 1.0,
            samples_per_frame: 1,
            max_samples: 1024,
            max_depth: r.max_depth,
            shadows: true,
            transparent_shadows: true,
            sampler: r.sampler,
            seed: r.seed,
            exposure: 1.0,
            depth_of_field: false,
            lens_radius: 0.0,
            focus_distance: 1.0,
            environment: EnvChoice::FromScene,
            env_intensity: 1.0,
            env_rotation_deg: 0.0,
            mode: RenderMode::Shaded,
            level: 0,
            heat_max: 0.0,
            frame_budget_ms: 20.0,
            moving_budget_ms: 8.0,
        }
    }
}

impl ViewSettings {
    /// The settings that change the traced samples (everything but exposure, the heatmap
    /// scale and the budgets): a change of these starts the accumulation over.
    fn trace_key(&self) -> ViewSettings {
        ViewSettings {
            exposure: 1.0,
            heat_max: 0.0,
            frame_budget_ms: 0.0,
            moving_budget_ms: 0.0,
            max_samples: 0,
            samples_per_frame: 0,
            level: if self.mode == RenderMode::Overlap {
                self.level
            } else {
                0
            },
            ..self.clone()
        }
    }

    /// The render plan of `scene` with these settings' switches applied.
    pub fn plan(&self, scene: &Scene) -> RenderPlan {
        let mut plan = RenderPlan::new(
            scene,
            &RenderSettings {
                max_depth: self.max_depth,
                ..RenderSettings::default()
            },
        );
        plan.shadows &= self.shadows;
        plan.transparent_shadows &= self.transparent_shadows && self.shadows;
        plan.thin_lens = self.depth_of_field && self.lens_radius > 0.0;
        plan
    }
}

/// The environment, loaded off the frame for the current scene and settings.
#[derive(Resource)]
pub struct LoadedEnvironment {
    /// The map in use.
    pub map: Arc<EnvironmentMap>,
    key: Option<EnvKey>,
    job: Background<EnvKey, anyhow::Result<EnvironmentMap>>,
    /// Counts the maps installed.
    pub generation: u64,
}

impl Default for LoadedEnvironment {
    fn default() -> Self {
        Self {
            map: Arc::new(EnvironmentMap::None),
            key: None,
            job: Background::default(),
            generation: 0,
        }
    }
}

impl LoadedEnvironment {
    /// True while a map is loading.
    pub fn is_loading(&self) -> bool {
        self.job.is_running()
    }
}

#[derive(Clone, Debug, PartialEq)]
struct EnvKey {
    scene: u64,
    choice: EnvChoice,
    intensity: f32,
    rotation: f32,
}

/// Where the fetched cube map and HDR skies live.
pub const EXTERNAL: &str = "assets/external";

/// The environment a choice stands for in `scene`, with the intensity and rotation applied.
pub fn environment_of(scene: &Scene, s: &ViewSettings) -> Environment {
    let (k, rot) = (s.env_intensity, s.env_rotation_deg);
    let base = match &s.environment {
        EnvChoice::FromScene => scene.environment.clone(),
        EnvChoice::None => Environment::None,
        EnvChoice::Sky => Environment::Sky {
            intensity: 1.0,
            rotation_deg: 0.0,
        },
        EnvChoice::CubeMap => {
            let dir = std::path::Path::new(EXTERNAL).join("cubemap");
            Environment::CubeMap {
                faces: ["px", "nx", "py", "ny", "pz", "nz"].map(|f| dir.join(format!("{f}.jpg"))),
                intensity: 1.0,
                rotation_deg: 0.0,
            }
        }
        EnvChoice::Hdr(path) => Environment::Equirect {
            path: path.clone(),
            intensity: 1.0,
            rotation_deg: 0.0,
        },
    };
    match base {
        Environment::None => Environment::None,
        Environment::Color(c) => Environment::Color(c * k),
        Environment::Sky {
            intensity,
            rotation_deg,
        } => Environment::Sky {
            intensity: intensity * k,
            rotation_deg: rotation_deg + rot,
        },
        Environment::CubeMap {
            faces,
            intensity,
            rotation_deg,
        } => Environment::CubeMap {
            faces,
            intensity: intensity * k,
            rotation_deg: rotation_deg + rot,
        },
        Environment::Equirect {
            path,
            intensity,
            rotation_deg,
        } => Environment::Equirect {
            path,
            intensity: intensity * k,
            rotation_deg: rotation_deg + rot,
        },
    }
}

/// When a new scene arrives, its camera's lens and its environment become the settings.
fn scene_defaults(current: Res<CurrentScene>, mut settings: ResMut<ViewSettings>) {
    if !current.is_changed() {
        return;
    }
    let cam = &current.scene.camera;
    let s = settings.as_mut();
    s.depth_of_field = cam.lens_radius > 0.0;
    s.lens_radius = cam.lens_radius;
    s.focus_distance = cam.focus_distance;
    s.environment = EnvChoice::FromScene;
    s.env_intensity = 1.0;
    s.env_rotation_deg = 0.0;
}

fn update_environment(
    current: Res<CurrentScene>,
    settings: Res<ViewSettings>,
    mut env: ResMut<LoadedEnvironment>,
    mut status: ResMut<super::scene::ViewerStatus>,
) {
    let wanted = EnvKey {
        scene: current.generation,
        choice: settings.environment.clone(),
        intensity: settings.env_intensity,
        rotation: settings.env_rotation_deg,
    };
    if let Some((key, result)) = env.job.poll()
        && key == wanted
    {
        match result.map_err(anyhow::Error::msg).and_then(|r| r) {
            Ok(map) => {
                env.map = Arc::new(map);
                env.generation += 1;
            }
            Err(e) => {
                status.error = Some(format!("environment: {e:#}"));
                env.map = Arc::new(EnvironmentMap::None);
                env.generation += 1;
            }
        }
        env.key = Some(key);
    }
    if env.key.as_ref() == Some(&wanted) || env.job.key() == Some(&wanted) {
        return;
    }
    let e = environment_of(&current.scene, &settings);
    env.job.start(wanted, "tracery-env", move || {
        EnvironmentMap::load(&e, true)
    });
}

/// The image the display shows, tone mapped (row 0 at the top).
#[derive(Resource, Default)]
pub struct TracedImage {
    /// RGBA8 pixels, sRGB.
    pub rgba: Vec<u8>,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Samples per pixel behind it (of its least-sampled row).
    pub samples: u32,
    /// Bumped at every change.
    pub version: u64,
    /// True for a low-resolution preview (taken while things change).
    pub preview: bool,
}

/// The progressive films: a full-resolution one, and the preview traced at every change.
#[derive(Resource)]
pub struct Accumulation {
    /// The full-resolution image being refined (see [`Accumulation::full`]).
    full: Progressive,
    /// The last preview.
    pub preview: Progressive,
    key: Option<TraceKey>,
    /// Preview resolution relative to the full one, adapted so a preview pass keeps to the
    /// moving budget.
    pub preview_scale: f32,
    /// Times the accumulation started over.
    pub resets: u64,
    shown: Option<(f32, f32)>,
    last_show: Option<Instant>,
    full_stale: bool,
}

impl Accumulation {
    /// The full-resolution image being refined; `None` after a change until tracing it
    /// resumes (it is cleared then, not on every frame of a camera move).
    pub fn full(&self) -> Option<&Progressive> {
        (!self.full_stale).then_some(&self.full)
    }

    /// Samples per pixel of the full-resolution image (0 after a change).
    pub fn full_passes(&self) -> u32 {
        self.full().map_or(0, Progressive::passes)
    }
}

impl Default for Accumulation {
    fn default() -> Self {
        Self {
            full: Progressive::new(1, 1),
            preview: Progressive::new(1, 1),
            key: None,
            preview_scale: 0.35,
            resets: 0,
            shown: None,
            last_show: None,
            full_stale: true,
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
struct TraceKey {
    scene: u64,
    bvh: usize,
    env: u64,
    pose: [u32; 8],
    size: UVec2,
    settings: ViewSettings,
}

/// Figures for the status line.
#[derive(Resource, Default, Debug, Clone)]
pub struct TraceStats {
    /// Samples per pixel of the image shown.
    pub spp: u32,
    /// Rays per second while tracing, in millions (smoothed).
    pub mrays_per_s: f64,
    /// Time the last frame's tracing took, in milliseconds.
    pub trace_ms: f64,
    /// True when the last frame saw a change (camera moving, settings edited).
    pub moving: bool,
    /// Size of the full-resolution image.
    pub size: UVec2,
    /// Size of the last preview.
    pub preview_size: UVec2,
    /// Mean and largest value of the heatmap shown (cost and overlap modes).
    pub heat: (f32, f32),
    /// What is holding the image back, if anything ("building BVH", "loading environment").
    pub waiting: Option<&'static str>,
}

/// The camera of a transform and projection, for an image of `size`.
pub fn camera_rays(
    transform: &Transform,
    projection: &Projection,
    size: UVec2,
    settings: &ViewSettings,
) -> CameraRays {
    let vfov = match projection {
        Projection::Perspective(p) => p.fov,
        _ => std::f32::consts::FRAC_PI_4,
    };
    let dof = settings.depth_of_field;
    CameraRays::from_pose(
        transform.translation,
        transform.rotation,
        vfov,
        size.x,
        size.y,
        if dof { settings.lens_radius } else { 0.0 },
        settings.focus_distance,
    )
}

fn pose_bits(t: &Transform, p: &Projection) -> [u32; 8] {
    let fov = match p {
        Projection::Perspective(p) => p.fov,
        _ => 0.0,
    };
    let (v, q) = (t.translation, t.rotation);
    [
        v.x.to_bits(),
        v.y.to_bits(),
        v.z.to_bits(),
        q.x.to_bits(),
        q.y.to_bits(),
        q.z.to_bits(),
        q.w.to_bits(),
        fov.to_bits(),
    ]
}

/// One [`Progressive::step`] of the chosen mode.
#[allow(clippy::too_many_arguments)]
fn step_mode(
    film: &mut Progressive,
    settings: &ViewSettings,
    tracer: &Tracer,
    bvh: &Bvh,
    cam: &CameraRays,
    budget: Duration,
    max_passes: u32,
) -> StepReport {
    match settings.mode {
        RenderMode::Shaded => film.step_shaded(
            tracer,
            cam,
            settings.sampler,
            settings.seed,
            budget,
            max_passes,
        ),
        RenderMode::TraversalCost | RenderMode::Overlap => {
            // One pass: the counts are exact, more samples would not change them.
            film.step(budget, max_passes.min(1), |y, _, sums| {
                if settings.mode == RenderMode::Overlap {
                    overlap_row(bvh, cam, settings.level, y, sums);
                } else {
                    cost_row(bvh, cam, y, sums);
                }
                let rays = RayCounts {
                    camera: sums.len() as u64,
                    ..Default::default()
                };
                (rays, 0)
            })
        }
    }
}

/// The picture of a film in the chosen mode, and the heatmap's mean and top.
pub(super) fn picture(film: &Progressive, settings: &ViewSettings) -> (Vec<u8>, (f32, f32)) {
    match settings.mode {
        RenderMode::Shaded => (film.to_rgba8(settings.exposure), (0.0, 0.0)),
        RenderMode::TraversalCost | RenderMode::Overlap => {
            let (mean, max) = cost_summary(film.sums());
            let top = if settings.heat_max > 0.0 {
                settings.heat_max
            } else {
                max.max(1.0)
            };
            (heatmap_rgba8(film.sums(), top), (mean, top))
        }
    }
}

fn show(
    image: &mut TracedImage,
    film: &Progressive,
    settings: &ViewSettings,
    preview: bool,
) -> (f32, f32) {
    let (rgba, heat) = picture(film, settings);
    image.rgba = rgba;
    image.width = film.width();
    image.height = film.height();
    image.samples = film.passes();
    image.preview = preview;
    image.version += 1;
    heat
}

/// The ray-trace system.
#[allow(clippy::too_many_arguments)]
fn trace(
    current: Res<CurrentScene>,
    bvh: Res<SceneBvh>,
    env: Res<LoadedEnvironment>,
    settings: Res<ViewSettings>,
    viewport: Res<ViewportSize>,
    camera: Query<(&Transform, &Projection), With<TraceCamera>>,
    mut acc: ResMut<Accumulation>,
    mut image: ResMut<TracedImage>,
    mut stats: ResMut<TraceStats>,
) {
    let Ok((transform, projection)) = camera.single() else {
        return;
    };
    let Some(tree) = bvh.for_scene(current.generation) else {
        stats.waiting = Some("building BVH");
        return;
    };
    if env.is_loading() {
        stats.waiting = Some("loading environment");
        return;
    }
    stats.waiting = None;
    let scene = &current.scene;
    let size = (viewport.0.as_vec2() * settings.scale.clamp(0.05, 1.0))
        .round()
        .as_uvec2()
        .max(UVec2::ONE);
    let key = TraceKey {
        scene: current.generation,
        bvh: Arc::as_ptr(tree) as usize,
        env: env.generation,
        pose: pose_bits(transform, projection),
        size,
        settings: settings.trace_key(),
    };
    let tracer = Tracer {
        scene,
        bvh: tree,
        plan: settings.plan(scene),
        max_depth: settings.max_depth,
        env: &env.map,
    };
    let acc = acc.as_mut();
    stats.size = size;
    if acc.key.as_ref() != Some(&key) {
        // Something changed: start over, and show a complete low-resolution pass at once.
        acc.key = Some(key);
        acc.resets += 1;
        let psize = (size.as_vec2() * acc.preview_scale)
            .round()
            .as_uvec2()
            .clamp(UVec2::ONE, size);
        if acc.preview.width() != psize.x || acc.preview.height() != psize.y {
            acc.preview = Progressive::new(psize.x, psize.y);
        } else {
            acc.preview.reset();
        }
        // The full image is cleared when tracing it resumes, not on every frame of a move.
        acc.full_stale = true;
        let cam = camera_rays(transform, projection, psize, &settings);
        // One shadow ray per area light while things change: the preview is redone next
        // frame anyway, and the time goes into resolution instead.
        let preview_tracer = Tracer {
            plan: RenderPlan {
                max_light_samples: Some(1),
                ..tracer.plan
            },
            ..tracer
        };
        let r = step_mode(
            &mut acc.preview,
            &settings,
            &preview_tracer,
            tree,
            &cam,
            Duration::MAX,
            1,
        );
        // Aim the next preview at the moving budget (square root: it scales both sides).
        let budget = settings.moving_budget_ms.max(1.0) as f64 * 1e-3;
        // Steps of 1/32 with a dead band, so the preview texture keeps its size while the
        // load is steady instead of being reallocated every frame.
        if r.seconds > 0.0 {
            let ideal = acc.preview_scale as f64 * (budget / r.seconds).sqrt();
            let next = ((ideal * 32.0).round() / 32.0).clamp(1.0 / 32.0, 1.0) as f32;
            if (next - acc.preview_scale).abs() > 0.08 * acc.preview_scale {
                acc.preview_scale = next;
            }
        }
        record(&mut stats, &r);
        stats.moving = true;
        stats.preview_size = psize;
        stats.heat = show(&mut image, &acc.preview, &settings, true);
        acc.shown = None;
        return;
    }
    stats.moving = false;
    let target = settings.max_samples.max(1);
    let mut completed = false;
    let mut traced = false;
    if acc.full_stale {
        acc.full_stale = false;
        if acc.full.width() != size.x || acc.full.height() != size.y {
            acc.full = Progressive::new(size.x, size.y);
        } else {
            acc.full.reset();
        }
    }
    if acc.full.passes() < target {
        let cam = camera_rays(transform, projection, size, &settings);
        let max = (acc.full.passes() + settings.samples_per_frame.max(1)).min(target);
        let budget = Duration::from_secs_f32(settings.frame_budget_ms.max(1.0) * 1e-3);
        let r = step_mode(&mut acc.full, &settings, &tracer, tree, &cam, budget, max);
        record(&mut stats, &r);
        traced = r.rows > 0;
        completed = r.passes_completed > 0;
    } else {
        stats.trace_ms = 0.0;
    }
    // Show the full image once it has a complete pass; redraw when a pass completes, when the
    // tone mapping changes, and now and then while a slow pass is under way.
    let look = (settings.exposure, settings.heat_max);
    let stale = acc
        .last_show
        .is_none_or(|t| t.elapsed() > Duration::from_millis(250));
    if acc.full.passes() >= 1
        && (completed || (traced && stale) || acc.shown != Some(look) || image.preview)
    {
        stats.heat = show(&mut image, &acc.full, &settings, false);
        acc.shown = Some(look);
        acc.last_show = Some(Instant::now());
    }
    stats.spp = image.samples;
}

fn record(stats: &mut TraceStats, r: &StepReport) {
    stats.trace_ms = r.seconds * 1e3;
    if r.seconds > 0.0 {
        let now = r.rays.total() as f64 / r.seconds / 1e6;
        stats.mrays_per_s = if stats.mrays_per_s == 0.0 {
            now
        } else {
            0.8 * stats.mrays_per_s + 0.2 * now
        };
    }
}
