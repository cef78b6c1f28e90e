//! Saving pictures and scripted runs: the full-resolution traced image as PNG (P or the
//! inspector's button), and for `tracery view --frames N`: frames counted from the first
//! picture, an optional camera orbit measured and reported ([`super::orbit`]), a window
//! screenshot and a clean exit.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use bevy::prelude::*;
use bevy::render::view::screenshot::{Screenshot, ScreenshotCaptured};

use super::bvh::SceneBvh;
use super::orbit::{self, OrbitRecord, ReportViews, report};
use super::scene::{CurrentScene, ViewerStatus};
use super::trace::{TraceStats, TraceWorker, TracedImage, ViewSettings, picture_of};

/// Saves images on request and runs scripted captures.
pub struct CapturePlugin {
    /// The script, if the viewer was started with `--frames`.
    pub script: Option<CaptureScript>,
}

/// A scripted run.
#[derive(Clone, Debug, Default)]
pub struct CaptureScript {
    /// Frames to run before the screenshot (or exit).
    pub frames: u32,
    /// Also wait until the full image has this many samples per pixel.
    pub samples: Option<u32>,
    /// Window screenshot to save before exiting.
    pub screenshot: Option<PathBuf>,
    /// Orbit the camera about the scene's look-at point for this many frames first, then
    /// stop and let the picture converge: prints the moving frame times, the fresh samples per
    /// frame, the moving picture's error against the converged one (and the stretched
    /// previews' and a picture with every pixel traced afresh once), the still Mrays/s against `tracery render` of the same view, and the CPU
    /// use once converged.
    pub orbit_frames: u32,
    /// Directory for the orbit's pictures (the last moving one, the converged one of its pose,
    /// the two stretched previews), as PNGs.
    pub orbit_pictures: Option<PathBuf>,
}

impl Plugin for CapturePlugin {
    fn build(&self, app: &mut App) {
        app.add_message::<SavePng>()
            .add_systems(Update, save_png.after(super::trace::TraceSystems));
        if let Some(script) = &self.script {
            app.insert_resource(Script {
                script: script.clone(),
                ..default()
            })
            .insert_resource(OrbitRecord::new(
                script.orbit_frames,
                script.orbit_pictures.clone(),
            ))
            // Frames keep coming until the orbit is over (the first orbit frame must not
            // include a reactive wait); the convergence after it is measured idle.
            .insert_resource(super::pacing::KeepAwake(true))
            .add_systems(First, orbit::fly)
            .add_systems(
                Update,
                orbit::keep_snapshot
                    .after(super::trace::TraceSystems)
                    .before(super::display::ShowPicture),
            )
            .add_systems(Last, (count_frames, orbit::record, finish).chain());
            // The render world says when no pipeline is left compiling (without one, there is
            // nothing to wait for).
            let render = app.get_sub_app_mut(bevy::render::RenderApp);
            let ready = PipelinesReady(Arc::new(AtomicBool::new(render.is_none())));
            if let Some(render) = render {
                render.insert_resource(ready.clone()).add_systems(
                    bevy::render::Render,
                    note_pipelines.in_set(bevy::render::RenderSystems::Cleanup),
                );
            }
            app.insert_resource(ready);
        }
    }
}

/// Whether the render world's pipeline cache had nothing left to compile at the end of its
/// last frame. Pipelines compile on a background thread and draw nothing until they are done:
/// a screenshot must wait for them, or the gizmos it asked for may be missing (under load,
/// the line pipelines took longer than the frames the script waited, now and then).
#[derive(Resource, Clone)]
struct PipelinesReady(Arc<AtomicBool>);

fn note_pipelines(
    cache: Res<bevy::render::render_resource::PipelineCache>,
    ready: Res<PipelinesReady>,
) {
    let idle = cache.waiting_pipelines().next().is_none();
    ready.0.store(idle, Ordering::Relaxed);
}

/// Longest wait for pipelines before a screenshot (one that can never compile must not hang
/// the script).
const PIPELINE_WAIT: Duration = Duration::from_secs(30);

/// Save the full-resolution traced image (to the path, or to `out/` under a generated name).
#[derive(Message, Clone, Debug)]
pub struct SavePng(pub Option<PathBuf>);

fn save_png(
    mut requests: MessageReader<SavePng>,
    worker: Res<TraceWorker>,
    settings: Res<ViewSettings>,
    current: Res<CurrentScene>,
    mut status: ResMut<ViewerStatus>,
) {
    let Some(SavePng(path)) = requests.read().last().cloned() else {
        return;
    };
    let film = worker.0.shared.still.lock().ok().and_then(|f| f.clone());
    let Some(film) = film.filter(|f| f.passes() > 0) else {
        status.notice = Some(
            "nothing to save yet: the still picture has no complete pass (hold the camera still)"
                .into(),
        );
        return;
    };
    let path = path.unwrap_or_else(|| {
        let stamp = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        PathBuf::from(format!(
            "out/{}-{}spp-{stamp}.png",
            current.scene.name,
            film.passes()
        ))
    });
    let (rgba, _) = picture_of(&film, &settings);
    let result = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .map_or(Ok(()), std::fs::create_dir_all)
        .map_err(anyhow::Error::from)
        .and_then(|_| {
            image::save_buffer(
                &path,
                &rgba,
                film.width(),
                film.height(),
                image::ColorType::Rgba8,
            )
            .map_err(anyhow::Error::from)
        });
    status.notice = Some(match result {
        Ok(()) => format!(
            "saved {} ({}x{}, {} spp)",
            path.display(),
            film.width(),
            film.height(),
            film.passes()
        ),
        Err(e) => format!("{}: cannot write PNG: {e}", path.display()),
    });
    info!("{}", status.notice.as_deref().unwrap_or_default());
}

/// Where a scripted run is.
#[derive(Resource, Default)]
pub(super) struct Script {
    script: CaptureScript,
    /// Frames since the scene asked for was first shown.
    pub(super) frame: u32,
    screenshot_requested: bool,
    /// Frames drawn since the gizmos asked for at start were ready (and every render pipeline
    /// compiled).
    gizmo_frames: u32,
    /// When the screenshot began waiting for render pipelines.
    pipelines_from: Option<Instant>,
    /// Frames the screenshot passed over because egui drew the inspector afresh in them.
    panel_waits: u32,
    saved: Arc<AtomicBool>,
    exit_in: Option<u32>,
}

/// Counts the script's frames from the first picture of the scene asked for (for an orbit,
/// its still picture at the sample limit).
fn count_frames(mut script: ResMut<Script>, ready: SceneReady) {
    if script.frame == 0 && !ready.is_ready(script.script.orbit_frames > 0) {
        return;
    }
    script.frame += 1;
}

#[allow(clippy::too_many_arguments)]
fn finish(
    mut commands: Commands,
    mut script: ResMut<Script>,
    mut record: ResMut<OrbitRecord>,
    image: Res<TracedImage>,
    stats: Res<TraceStats>,
    settings: Res<ViewSettings>,
    mut keep_awake: ResMut<super::pacing::KeepAwake>,
    views: ReportViews,
    gizmos: GizmosShown,
    pipelines: Res<PipelinesReady>,
    mut exit: MessageWriter<AppExit>,
    panel: Option<Res<super::panel_cache::PanelCopy>>,
) {
    if let Some(n) = script.exit_in.as_mut() {
        if *n == 0 {
            exit.write(AppExit::Success);
        } else {
            *n -= 1;
        }
        return;
    }
    if script.frame < script.script.frames.max(script.script.orbit_frames) {
        return;
    }
    let orbit = script.script.orbit_frames > 0;
    if orbit && !record.reported && !record.measuring_idle() {
        keep_awake.0 = false;
    }
    let target = script
        .script
        .samples
        .or(orbit.then_some(settings.max_samples));
    if let Some(target) = target
        && (image.preview || image.samples < target)
    {
        return;
    }
    if script.screenshot_requested {
        if script.saved.load(Ordering::SeqCst) {
            script.exit_in = Some(1);
        }
        return;
    }
    if orbit && !record.reported {
        // Converged: measure the CPU use with nothing to do before reporting.
        let Some(idle) = record.idle_cpu(script.frame) else {
            return;
        };
        report(&record, &stats, &settings, &views, idle);
        record.reported = true;
        // The screenshot needs frames again.
        keep_awake.0 = true;
    }
    // The gizmos switched on are in the picture before it is saved: their BVH indexed, the
    // debug ray traced, their pipelines compiled, and eight frames drawn with them since.
    if script.script.screenshot.is_some() {
        if !gizmos.ready() {
            script.gizmo_frames = 0;
            return;
        }
        // Every pipeline compiled, so what the frame asks for is drawn.
        let waited = script
            .pipelines_from
            .get_or_insert_with(Instant::now)
            .elapsed();
        if !pipelines.0.load(Ordering::Relaxed) {
            if waited < PIPELINE_WAIT {
                script.gizmo_frames = 0;
                return;
            }
            if script.gizmo_frames == 0 {
                warn!(
                    "render pipelines still compiling after {PIPELINE_WAIT:?}; saving the screenshot anyway"
                );
            }
        }
        script.gizmo_frames += 1;
        if script.gizmo_frames < 8 {
            return;
        }
    }
    // The screenshot shows the inspector as most frames do: from its kept pixels while the
    // panel cache is in use (a frame whose panel egui draws afresh is passed over, up to 20).
    let panel = panel.map(|p| *p).unwrap_or_default();
    if script.script.screenshot.is_some()
        && matches!(panel, super::panel_cache::PanelCopy::Store { .. })
        && script.panel_waits < 20
    {
        script.panel_waits += 1;
        return;
    }
    match script.script.screenshot.clone() {
        Some(path) => {
            println!(
                "screenshot: picture {}x{}; inspector panel {}",
                stats.size.x,
                stats.size.y,
                match panel {
                    super::panel_cache::PanelCopy::Restore(_) => "shown from its kept pixels",
                    super::panel_cache::PanelCopy::Store { .. } => "drawn by egui and kept",
                    super::panel_cache::PanelCopy::Off => "drawn by egui, not kept",
                }
            );
            let saved = script.saved.clone();
            commands.spawn(Screenshot::primary_window()).observe(
                move |shot: On<ScreenshotCaptured>| {
                    save_screenshot(&shot.image, &path);
                    saved.store(true, Ordering::SeqCst);
                },
            );
            script.screenshot_requested = true;
        }
        None => script.exit_in = Some(0),
    }
}

/// Whether the scene asked for is up: loaded, its BVH built and a picture of it shown (for an
/// orbit, its still picture at the sample limit: people look before they fly).
#[derive(bevy::ecs::system::SystemParam)]
struct SceneReady<'w> {
    loading: Res<'w, super::scene::SceneLoading>,
    current: Res<'w, CurrentScene>,
    bvh: Res<'w, SceneBvh>,
    image: Res<'w, TracedImage>,
    settings: Res<'w, ViewSettings>,
}

impl SceneReady<'_> {
    fn is_ready(&self, converged: bool) -> bool {
        self.loading.current().is_none()
            && self.bvh.for_scene(self.current.generation).is_some()
            && self.image.version > 0
            && (!converged
                || !self.image.preview && self.image.samples >= self.settings.max_samples.max(1))
    }
}

/// Whether the BVH and debug-ray gizmos that are switched on have what they draw.
#[derive(bevy::ecs::system::SystemParam)]
struct GizmosShown<'w> {
    store: Res<'w, GizmoConfigStore>,
    index: Res<'w, super::gizmos::BvhIndex>,
    debug: Res<'w, super::debug_ray::DebugRay>,
    bvh: Res<'w, SceneBvh>,
    current: Res<'w, CurrentScene>,
}

impl GizmosShown<'_> {
    fn ready(&self) -> bool {
        use super::gizmos::{BvhLevelGizmos, LeafGizmos};
        let boxes = self.store.config::<BvhLevelGizmos>().0.enabled
            || self.store.config::<LeafGizmos>().0.enabled;
        // Indexed from the trees of the scene shown.
        let indexed = self.bvh.for_scene(self.current.generation).is_some()
            && self.index.made_for == self.bvh.key.map(|k| (k, self.bvh.top_builds));
        let ray_asked = self.debug.pending.is_some() || self.debug.pixel.is_some();
        let ray_traced = self.debug.pending.is_none() && !self.debug.path.segments.is_empty();
        (!boxes || indexed) && (!ray_asked || ray_traced)
    }
}

fn save_screenshot(image: &Image, path: &std::path::Path) {
    let result = image
        .clone()
        .try_into_dynamic()
        .map_err(|e| anyhow::anyhow!("{e:?}"))
        .and_then(|d| {
            if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
                std::fs::create_dir_all(parent)?;
            }
            d.to_rgb8().save(path)?;
            Ok(())
        });
    match result {
        Ok(()) => println!("screenshot {}", path.display()),
        Err(e) => eprintln!(
            "error: {}: cannot save the screenshot: {e:#}",
            path.display()
        ),
    }
}
