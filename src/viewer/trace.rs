//! The ray-trace systems: every frame, `send_job` hands the view of the [`TraceCamera`] (with
//! the scene, BVH, environment and settings) to the trace worker ([`super::worker`]) when it
//! changed, and `take_picture` installs the newest picture the worker finished. The worker
//! traces on its own threads, so the frame never waits for it.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use bevy::prelude::*;

use super::bvh::SceneBvh;
use super::scene::{CurrentScene, SceneSystems};
use super::task::Background;
use super::worker::{Content, Job, Worker};
use crate::camera::CameraRays;
use crate::render::cache::MovingFilter;
use crate::render::heatmap::{cost_row, cost_summary, heatmap_rgba8, overlap_row};
use crate::render::progressive::StepReport;
use crate::render::{EnvironmentMap, Progressive, RayCounts, RenderPlan, RenderSettings, Tracer};
use crate::sampling::SamplerKind;
use crate::scene::{Environment, Integrator, Scene};

/// Hands the view to the trace worker and keeps [`TracedImage`] up to date.
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
            .insert_resource(TraceWorker(Worker::start()))
            .add_systems(
                PreUpdate,
                (scene_defaults, update_environment)
                    .chain()
                    .after(SceneSystems),
            )
            // The picture is taken before the next job is sent: a picture taken is always of
            // the newest job sent.
            .add_systems(
                Update,
                (take_picture, send_job).chain().in_set(TraceSystems),
            );
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
    /// Where the samples go: samples per pixel each 16 x 16 tile took for the last picture,
    /// as a heatmap (the moving picture gives changed and noisy tiles more).
    Work,
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
    /// Accumulation stops at this many samples per pixel.
    pub max_samples: u32,
    /// Largest number of bounces (mirror, transparent and, with the path integrator, diffuse).
    pub max_depth: u32,
    /// How light is gathered (`None`: the scene's choice).
    pub integrator: Option<Integrator>,
    /// Shadow rays on.
    pub shadows: bool,
    /// Shadow rays pass through transparent surfaces.
    pub transparent_shadows: bool,
    /// Materials' normal and height maps bend the shading normal.
    pub normal_maps: bool,
    /// The normals the maps bend get the shadowing term that softens their shadow terminator.
    pub soft_terminator: bool,
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
    /// Tracing time of each new view's moving picture, in milliseconds (its picture comes
    /// this long after the view's samples are carried over).
    pub moving_budget_ms: f32,
    /// Shortest time between two frames while something changes, in milliseconds (0: as
    /// fast as the window draws). Each frame costs the window a redraw on the CPU (under a
    /// software graphics driver, more than half a core at 50 frames a second), taken from
    /// the tracing; the moving picture changes at most once a frame anyway.
    pub frame_ms: f32,
    /// How long the view must stay the same before the still picture starts over from fresh
    /// samples, in milliseconds.
    pub still_after_ms: f32,
    /// How the moving picture's samples are filtered for display (the samples and the still
    /// picture are untouched).
    pub moving_filter: MovingFilter,
    /// Show the still picture denoised ([`crate::denoise`]; display only, the samples are
    /// untouched). On by default in builds with the denoiser.
    pub denoise: bool,
}

impl Default for ViewSettings {
    fn default() -> Self {
        let r = RenderSettings::default();
        Self {
            scale: 1.0,
            max_samples: 1024,
            max_depth: r.max_depth,
            integrator: None,
            shadows: true,
            transparent_shadows: true,
            normal_maps: true,
            soft_terminator: r.soft_terminator,
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
            moving_budget_ms: 20.0,
            frame_ms: 30.0,
            still_after_ms: 120.0,
            moving_filter: MovingFilter::default(),
            denoise: crate::denoise::AVAILABLE,
        }
    }
}

impl ViewSettings {
    /// The settings that change the traced samples (everything but exposure, the heatmap
    /// scale, the budgets, the frame pacing, the sample limit, the moving picture's smoothing
    /// and the still picture's denoising): a change of these starts the pictures over.
    pub fn trace_key(&self) -> ViewSettings {
        ViewSettings {
            exposure: 1.0,
            heat_max: 0.0,
            moving_budget_ms: 0.0,
            frame_ms: 0.0,
            still_after_ms: 0.0,
            moving_filter: MovingFilter::default(),
            denoise: false,
            max_samples: 0,
            // The work view traces what the shaded view traces.
            mode: if self.mode == RenderMode::Work {
                RenderMode::Shaded
            } else {
                self.mode
            },
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
        let mut plan = RenderPlan::with_integrator(
            scene,
            self.integrator.unwrap_or(scene.integrator),
            &RenderSettings {
                max_depth: self.max_depth,
                ..RenderSettings::default()
            },
        );
        plan.shadows &= self.shadows;
        plan.transparent_shadows &= self.transparent_shadows && self.shadows;
        plan.thin_lens = self.depth_of_field && self.lens_radius > 0.0;
        plan.normal_maps &= self.normal_maps;
        plan.soft_terminator &= self.soft_terminator;
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
    /// Samples per pixel behind it (of its least-sampled row; 0 for the moving picture).
    pub samples: u32,
    /// Bumped at every change.
    pub version: u64,
    /// True for the moving picture (shown while things change).
    pub preview: bool,
    /// Generation of the job it belongs to.
    pub generation: u64,
}

/// The trace worker ([`super::worker`]), owned by the app.
#[derive(Resource)]
pub struct TraceWorker(pub Worker);

/// What the worker has done for the views sent so far.
#[derive(Resource, Default)]
pub struct Accumulation {
    key: Option<TraceKey>,
    /// Generation of the last job sent.
    pub generation: u64,
    /// Jobs sent: the times the picture started over for a new view or setting.
    pub resets: u64,
    /// Complete passes of the still picture of the current job.
    passes: u32,
}

impl Accumulation {
    /// Samples per pixel of the still picture of the current view (0 while the moving
    /// picture is up).
    pub fn full_passes(&self) -> u32 {
        self.passes
    }
}

/// Everything a job depends on: any change sends a new one.
#[derive(Clone, Debug, PartialEq)]
struct TraceKey {
    content: Content,
    pose: [u32; 8],
    display: UVec2,
    settings: ViewSettings,
}

/// Figures for the status line.
#[derive(Resource, Default, Debug, Clone)]
pub struct TraceStats {
    /// Samples per pixel of the image shown (0 for the moving picture).
    pub spp: u32,
    /// Rays per second of the worker's last batch, in millions.
    pub mrays_per_s: f64,
    /// True when the picture shown is the moving one.
    pub moving: bool,
    /// Size of the traced picture.
    pub size: UVec2,
    /// Samples traced into the moving picture shown since the one before it.
    pub fresh: u64,
    /// Pixels of the moving picture shown that no sample reached.
    pub holes: u64,
    /// Mean and largest value of the heatmap shown (cost, overlap and work views).
    pub heat: (f32, f32),
    /// What is holding the image back, if anything ("building BVH", "loading environment").
    pub waiting: Option<&'static str>,
    /// The worker has nothing left to do (the picture reached its sample limit).
    pub idle: bool,
    /// Rays traced for the still picture since it started over.
    pub still_rays: u64,
    /// Seconds the worker spent tracing the still picture since it started over.
    pub still_seconds: f64,
    /// True when the picture shown is the still one denoised.
    pub denoised: bool,
    /// Why the still picture cannot be denoised, if it cannot.
    pub denoise_error: Option<String>,
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
pub(super) fn step_mode(
    film: &mut Progressive,
    settings: &ViewSettings,
    tracer: &Tracer,
    bvh: crate::bvh::Tree<'_>,
    cam: &CameraRays,
    budget: Duration,
    max_passes: u32,
    cancel: &(dyn Fn() -> bool + Sync),
) -> StepReport {
    match settings.mode {
        RenderMode::Shaded | RenderMode::Work => film.step_shaded_until(
            tracer,
            cam,
            (settings.sampler, settings.seed),
            budget,
            max_passes,
            cancel,
        ),
        RenderMode::TraversalCost | RenderMode::Overlap => {
            // One pass: the counts are exact, more samples would not change them.
            film.step(budget, max_passes.min(1), |y0, _, sums| {
                for (i, row) in sums.chunks_mut(cam.width.max(1) as usize).enumerate() {
                    let y = y0 + i as u32;
                    if settings.mode == RenderMode::Overlap {
                        overlap_row(bvh, cam, settings.level, y, row);
                    } else {
                        cost_row(bvh, cam, y, row);
                    }
                }
                let rays = RayCounts {
                    camera: sums.len() as u64,
                    ..Default::default()
                };
                Some((rays, 0))
            })
        }
    }
}

/// The picture of a film in the chosen mode, and the heatmap's mean and top.
pub(super) fn picture_of(film: &Progressive, settings: &ViewSettings) -> (Vec<u8>, (f32, f32)) {
    match settings.mode {
        RenderMode::Shaded | RenderMode::Work => (film.to_rgba8(settings.exposure), (0.0, 0.0)),
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

/// Sends the view to the worker when the view, the scene or a setting changed.
#[allow(clippy::too_many_arguments)]
fn send_job(
    current: Res<CurrentScene>,
    bvh: Res<SceneBvh>,
    env: Res<LoadedEnvironment>,
    settings: Res<ViewSettings>,
    viewport: Res<ViewportSize>,
    camera: Query<(&Transform, &Projection), With<TraceCamera>>,
    worker: Res<TraceWorker>,
    mut acc: ResMut<Accumulation>,
    mut stats: ResMut<TraceStats>,
) {
    let Ok((transform, projection)) = camera.single() else {
        return;
    };
    let (Some(tree), Some(_)) = (
        bvh.for_scene(current.generation),
        bvh.tracing(current.generation),
    ) else {
        stats.waiting = Some("building BVH");
        return;
    };
    if env.is_loading() {
        stats.waiting = Some("loading environment");
        return;
    }
    stats.waiting = None;
    let size = (viewport.0.as_vec2() * settings.scale.clamp(0.05, 1.0))
        .round()
        .as_uvec2()
        .max(UVec2::ONE);
    stats.size = size;
    let key = TraceKey {
        content: Content {
            scene: current.generation,
            bvh: Arc::as_ptr(tree) as usize,
            env: env.generation,
            size,
            settings: settings.trace_key(),
        },
        pose: pose_bits(transform, projection),
        display: viewport.0,
        settings: settings.clone(),
    };
    if acc.key.as_ref() == Some(&key) {
        return;
    }
    let restart = acc
        .key
        .as_ref()
        .is_none_or(|k| k.pose != key.pose || k.content != key.content);
    acc.generation += 1;
    if restart {
        acc.resets += 1;
        acc.passes = 0;
    }
    worker.0.send(Job {
        generation: acc.generation,
        scene: current.scene.clone(),
        bvh: tree.clone(),
        placed: bvh.placed.clone(),
        env: env.map.clone(),
        camera: camera_rays(transform, projection, size, &settings),
        display: viewport.0,
        settings: settings.clone(),
        content: key.content.clone(),
    });
    acc.key = Some(key);
}

/// Installs the newest picture the worker finished (of the newest job sent, or of one that
/// differs from it only in the view), and its figures.
fn take_picture(
    worker: Res<TraceWorker>,
    mut acc: ResMut<Accumulation>,
    mut image: ResMut<TracedImage>,
    mut stats: ResMut<TraceStats>,
) {
    let shared = &worker.0.shared;
    let w = shared.stats();
    if w.generation == acc.generation {
        acc.passes = w.passes;
        stats.still_rays = w.still_rays.total();
        stats.still_seconds = w.still_seconds;
    }
    stats.mrays_per_s = w.mrays_per_s;
    stats.idle = w.idle;
    if stats.denoise_error != w.denoise.error {
        stats.denoise_error = w.denoise.error;
    }
    let Some(p) = worker.0.take_picture() else {
        return;
    };
    stats.moving = p.moving;
    stats.heat = p.heat;
    stats.spp = p.samples;
    stats.denoised = p.denoised;
    stats.fresh = p.fresh;
    stats.holes = p.holes;
    image.rgba = p.rgba;
    image.width = p.width;
    image.height = p.height;
    image.samples = p.samples;
    image.preview = p.moving;
    image.generation = p.generation;
    image.version += 1;
}
