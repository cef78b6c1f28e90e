//! Saving pictures and scripted runs: the full-resolution traced image as PNG (P or the
//! inspector's button), and for `tracery view --frames N`: an optional camera orbit that
//! measures frame times while moving, samples per second when still, a window screenshot and
//! a clean exit.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use bevy::prelude::*;
use bevy::render::view::screenshot::{Screenshot, ScreenshotCaptured};

use super::bvh::SceneBvh;
use super::camera::FlyCamera;
use super::scene::{CurrentScene, ViewerStatus};
use super::trace::{
    LoadedEnvironment, TraceCamera, TraceStats, TraceWorker, TracedImage, ViewSettings,
    ViewportSize, camera_rays, picture_of,
};
use super::worker::Shared;
use crate::film::rmse_levels;
use crate::render::cache::MovingFilter;
use crate::render::resample::{Filter, resize_rgba8};
use crate::render::{Progressive, RenderSettings, Tracer, render_with_plan};

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

/// How long the idle CPU use is measured for.
const IDLE_WINDOW: Duration = Duration::from_secs(4);

impl Plugin for CapturePlugin {
    fn build(&self, app: &mut App) {
        app.add_message::<SavePng>()
            .add_systems(Update, save_png.after(super::trace::TraceSystems));
        if let Some(script) = &self.script {
            app.insert_resource(Script {
                script: script.clone(),
                ..default()
            })
            // Frames keep coming until the orbit is over (the first orbit frame must not
            // include a reactive wait); the convergence after it is measured idle.
            .insert_resource(super::pacing::KeepAwake(true))
            .add_systems(First, orbit)
            .add_systems(
                Update,
                keep_snapshot
                    .after(super::trace::TraceSystems)
                    .before(super::display::ShowPicture),
            )
            .add_systems(Last, (measure, finish).chain());
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

/// The moving picture shown at the end of the orbit, and the pose it was traced for.
struct Snapshot {
    rgba: Vec<u8>,
    size: UVec2,
    /// The job generation it was traced for, until the pose is found.
    generation: u64,
    pose: Option<Transform>,
}

#[derive(Resource, Default)]
struct Script {
    script: CaptureScript,
    frame: u32,
    orbit_center: Option<Vec3>,
    moving_ms: Vec<f64>,
    /// Job generation and camera pose of recent frames.
    poses: std::collections::VecDeque<(u64, Transform)>,
    /// Worker moving samples and pictures when the timed orbit frames began.
    moving_from: Option<(u64, u64)>,
    /// Fresh samples and moving pictures over the timed orbit frames.
    moving_work: (u64, u64),
    /// The worker's moving-picture time when the timed orbit frames began and ended.
    moving_time: [super::worker::MovingTime; 2],
    /// Wall clock over the timed orbit frames.
    moving_wall: Option<Instant>,
    moving_seconds: f64,
    /// CPU seconds of the trace worker's threads and of all the others, when the timed orbit
    /// frames began and ended.
    moving_cpu: [(f64, f64); 2],
    /// How the inspector panel was shown (drawn, reused), when the timed orbit frames began
    /// and ended.
    moving_panel: [super::panel_cache::PanelCounts; 2],
    snapshot: Option<Snapshot>,
    /// Start of the idle measurement: wall clock and process CPU seconds.
    idle_from: Option<(Instant, f64, u32)>,
    screenshot_requested: bool,
    /// Frames drawn since the gizmos asked for at start were ready (and every render pipeline
    /// compiled).
    gizmo_frames: u32,
    /// When the screenshot began waiting for render pipelines.
    pipelines_from: Option<Instant>,
    /// Frames the screenshot passed over because egui drew the inspector afresh in them.
    panel_waits: u32,
    /// The orbit report is printed.
    reported: bool,
    saved: Arc<AtomicBool>,
    exit_in: Option<u32>,
}

/// How fast the orbit turns: 72 degrees a second, a full turn in 5 s (the 2.4 degrees a frame
/// of a 150-frame turn at 33 ms a frame). It turns by time, not by frame, as a person flying
/// would: a window that draws faster does not fly the camera faster, and the trace worker,
/// whose pictures come at their own pace, sees the same motion between them.
const ORBIT_DEGREES_PER_SECOND: f32 = 72.0;

fn orbit(
    script: Res<Script>,
    time: Res<Time<Real>>,
    current: Res<CurrentScene>,
    mut camera: Query<&mut Transform, With<FlyCamera>>,
) {
    let (frame, frames) = (script.frame, script.script.orbit_frames);
    if frames == 0 || frame == 0 || frame > frames {
        return;
    }
    for mut t in &mut camera {
        if frame == frames {
            // The orbit is over: stop at the pose of the last moving picture shown, so the
            // converged picture is of the same view.
            if let Some(pose) = script.snapshot.as_ref().and_then(|s| s.pose) {
                *t = pose;
            }
            continue;
        }
        // About the vertical through the look-at point, by the time since the last frame (at
        // most 0.1 s: a stall does not make the camera jump).
        let center = script.orbit_center.unwrap_or(current.scene.camera.look_at);
        let dt = time.delta_secs().min(0.1);
        let q = Quat::from_rotation_y(ORBIT_DEGREES_PER_SECOND.to_radians() * dt);
        t.translation = center + q * (t.translation - center);
        t.rotation = q * t.rotation;
    }
}

#[allow(clippy::too_many_arguments)]
fn measure(
    mut script: ResMut<Script>,
    time: Res<Time<Real>>,
    acc: Res<super::trace::Accumulation>,
    worker: Res<TraceWorker>,
    current: Res<CurrentScene>,
    ready: SceneReady,
    camera: Query<&Transform, With<TraceCamera>>,
    panel: Option<Res<super::panel_cache::PanelCounts>>,
) {
    let panel = panel.map(|p| *p).unwrap_or_default();
    // The script's frames count from the first picture of the scene asked for.
    if script.frame == 0 && !ready.is_ready(script.script.orbit_frames > 0) {
        return;
    }
    script.frame += 1;
    let frame = script.frame;
    let orbit = script.script.orbit_frames;
    if orbit == 0 || frame > orbit {
        return;
    }
    if script.orbit_center.is_none() {
        script.orbit_center = Some(current.scene.camera.look_at);
    }
    if let Ok(t) = camera.single() {
        script.poses.push_back((acc.generation, *t));
        if script.poses.len() > 64 {
            script.poses.pop_front();
        }
    }
    let w = worker.0.shared.stats();
    // Skip the first frames (window and pipelines start up) when timing.
    if frame == 3 {
        script.moving_from = Some((w.moving_samples, w.moving_pictures));
        script.moving_time[0] = w.moving_time;
        script.moving_wall = Some(Instant::now());
        script.moving_cpu[0] = thread_cpu_seconds();
        script.moving_panel[0] = panel;
    }
    if frame > 3 {
        script.moving_ms.push(time.delta_secs_f64() * 1e3);
    }
    if frame == orbit {
        if let Some((s0, p0)) = script.moving_from {
            script.moving_work = (w.moving_samples - s0, w.moving_pictures - p0);
        }
        script.moving_time[1] = w.moving_time;
        script.moving_cpu[1] = thread_cpu_seconds();
        script.moving_panel[1] = panel;
        script.moving_seconds = script
            .moving_wall
            .map_or(0.0, |t| t.elapsed().as_secs_f64());
        let poses = std::mem::take(&mut script.poses);
        if let Some(snap) = script.snapshot.as_mut() {
            snap.pose = poses
                .iter()
                .find(|(g, _)| *g == snap.generation)
                .map(|(_, t)| *t);
        }
        script.poses = poses;
    }
}

/// Keeps a copy of each moving picture of the orbit's last frames before the display takes its
/// pixels: the last one is compared with the converged picture of its pose.
fn keep_snapshot(mut script: ResMut<Script>, image: Res<TracedImage>, worker: Res<TraceWorker>) {
    let frame = script.frame + 1;
    let orbit = script.script.orbit_frames;
    if orbit == 0 || frame + 32 < orbit {
        return;
    }
    // The worker keeps the samples of its moving pictures over the orbit's last frames, to
    // compare the filters on the last one shown.
    let keep = &worker.0.shared.keep_moving_samples;
    keep.store(frame <= orbit, Ordering::Relaxed);
    if frame > orbit {
        return;
    }
    if !image.is_changed() {
        return;
    }
    if image.preview && !image.rgba.is_empty() {
        script.snapshot = Some(Snapshot {
            rgba: image.rgba.clone(),
            size: UVec2::new(image.width, image.height),
            generation: image.generation,
            pose: None,
        });
    }
}

/// The moving picture's error through each of its filters, made from the samples of the last
/// moving picture shown (the worker keeps them over the orbit's last frames).
fn moving_filters(shared: &Shared, snap: &Snapshot, settings: &ViewSettings, converged: &[u8]) {
    let kept = shared.moving_samples.lock().ok().and_then(|mut s| {
        let i = s.iter().position(|(g, _)| *g == snap.generation)?;
        let kept = s.remove(i);
        s.clear();
        kept
    });
    let Some((generation, mut cache)) = kept else {
        println!("moving picture's filters: the samples of the last moving picture were not kept");
        return;
    };
    if UVec2::new(cache.width(), cache.height()) != snap.size {
        println!(
            "moving picture's filters: traced at {}x{}, shown at {}x{}: compared only at a resolution scale of 1",
            cache.width(),
            cache.height(),
            snap.size.x,
            snap.size.y
        );
        return;
    }
    let errors: Vec<String> = MovingFilter::ALL
        .iter()
        .map(|&f| {
            let t = Instant::now();
            let rgba = cache.to_rgba8(f);
            let ms = t.elapsed().as_secs_f64() * 1e3;
            format!(
                "{} {:.2} levels ({ms:.1} ms)",
                f.name(),
                rmse_levels(&rgba, converged)
            )
        })
        .collect();
    println!(
        "moving picture's filters on the samples of picture {generation} against the converged one: {} (shown: {})",
        errors.join(", "),
        settings.moving_filter.name()
    );
}

/// Process CPU time (user and system) in seconds, from `/proc/self/stat` (Linux; the kernel
/// counts in USER_HZ = 100 ticks a second on every architecture it exports it for).
fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // The command name may hold spaces: fields are counted after its closing parenthesis.
    let rest = &stat[stat.rfind(')')? + 2..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let utime: f64 = fields.get(11)?.parse().ok()?;
    let stime: f64 = fields.get(12)?.parse().ok()?;
    Some((utime + stime) / 100.0)
}

/// CPU seconds (user and system) of the trace worker's threads and of the process's other
/// threads (Bevy, the window, the graphics driver), from `/proc/self/task` (Linux).
fn thread_cpu_seconds() -> (f64, f64) {
    let (mut worker, mut other) = (0.0, 0.0);
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else {
        return (0.0, 0.0);
    };
    for task in tasks.flatten() {
        let Ok(stat) = std::fs::read_to_string(task.path().join("stat")) else {
            continue;
        };
        let (Some(open), Some(close)) = (stat.find('('), stat.rfind(')')) else {
            continue;
        };
        let name = &stat[open + 1..close];
        let fields: Vec<&str> = stat[close + 2..].split_whitespace().collect();
        let ticks = |i: usize| {
            fields
                .get(i)
                .and_then(|f| f.parse::<f64>().ok())
                .unwrap_or(0.0)
        };
        let secs = (ticks(11) + ticks(12)) / 100.0;
        if name.starts_with("tracery-trace") {
            worker += secs;
        } else {
            other += secs;
        }
    }
    (worker, other)
}

#[allow(clippy::too_many_arguments)]
fn finish(
    mut commands: Commands,
    mut script: ResMut<Script>,
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
    if orbit && !script.reported && script.idle_from.is_none() {
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
    if orbit && !script.reported {
        // Converged: measure the CPU use with nothing to do before reporting.
        let Some((t0, cpu0, frame0)) = script.idle_from else {
            let cpu = process_cpu_seconds().unwrap_or(0.0);
            script.idle_from = Some((Instant::now(), cpu, script.frame));
            return;
        };
        if t0.elapsed() < IDLE_WINDOW {
            return;
        }
        let idle = process_cpu_seconds().map(|c| {
            let frames = script.frame - frame0;
            ((c - cpu0) / t0.elapsed().as_secs_f64(), frames)
        });
        report(&script, &stats, &settings, &views, idle);
        script.reported = true;
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
        let indexed = match (
            self.index.bvh(),
            self.bvh.for_scene(self.current.generation),
        ) {
            (Some(a), Some(b)) => Arc::ptr_eq(a, b),
            _ => false,
        };
        let ray_asked = self.debug.pending.is_some() || self.debug.pixel.is_some();
        let ray_traced = self.debug.pending.is_none() && !self.debug.path.segments.is_empty();
        (!boxes || indexed) && (!ray_asked || ray_traced)
    }
}

/// What the report reads besides the script.
#[derive(bevy::ecs::system::SystemParam)]
struct ReportViews<'w, 's> {
    worker: Res<'w, TraceWorker>,
    current: Res<'w, CurrentScene>,
    bvh: Res<'w, SceneBvh>,
    env: Res<'w, LoadedEnvironment>,
    viewport: Res<'w, ViewportSize>,
    camera: Query<'w, 's, (&'static Transform, &'static Projection), With<TraceCamera>>,
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

/// The `--orbit` report's denoising lines: what denoising cost the still picture, when its
/// first denoised picture came, and how close that was to the converged picture against the
/// picture as traced at 16 times that time.
fn denoise_report(
    w: &super::worker::WorkerStats,
    views: &ReportViews,
    settings: &ViewSettings,
    film: &Progressive,
) {
    let d = &w.denoise;
    if let Some(e) = &d.error {
        println!("denoised still: none ({e})");
        return;
    }
    let stop = settings.still_after_ms as f64 * 1e-3;
    println!(
        "denoised still: {} pictures in {:.2} s ({:.1}% of the still picture's {:.1} s), the last of {} spp",
        d.pictures,
        d.seconds,
        100.0 * d.seconds / w.still_wall.max(1e-9),
        w.still_wall,
        d.passes
    );
    let probe = views
        .worker
        .0
        .shared
        .probe
        .lock()
        .map(|p| p.clone())
        .unwrap_or_default();
    let converged = picture_of(film, settings).0;
    match (&probe.first, &probe.plain_later) {
        (Some((t, first)), Some((later, plain))) if first.len() == converged.len() => println!(
            "first denoised picture: {:.2} s after the camera stopped, RMSE {:.2} levels against the picture at the sample limit; the picture as traced {:.2} s after the camera stopped ({:.0}x later): RMSE {:.2} levels",
            stop + t,
            rmse_levels(first, &converged),
            stop + later,
            (stop + later) / (stop + t).max(1e-9),
            rmse_levels(plain, &converged),
        ),
        _ => println!("first denoised picture: none kept to compare"),
    }
}

fn report(
    script: &Script,
    stats: &TraceStats,
    settings: &ViewSettings,
    views: &ReportViews,
    idle_cpu: Option<(f64, u32)>,
) {
    let w = views.worker.0.shared.stats();
    let display = views.viewport.0;
    // Moving.
    let v = {
        let mut v = script.moving_ms.clone();
        v.sort_by(f64::total_cmp);
        v
    };
    let fresh_per_frame = script.moving_work.0 as f64 / v.len().max(1) as f64;
    if !v.is_empty() {
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        let p95 = v[((v.len() as f64 * 0.95) as usize).min(v.len() - 1)];
        println!(
            "moving: {} frames at {}x{} ({}), frame time mean {:.1} ms, p95 {:.1} ms, max {:.1} ms; {:.0} fresh samples per frame ({:.1}% of the pixels; {:.2} M a second, which does not depend on how fast the window draws), {} moving pictures",
            v.len(),
            stats.size.x,
            stats.size.y,
            if settings.frame_ms > 0.0 {
                format!("frames paced at {} ms", settings.frame_ms)
            } else {
                "frames as fast as the window draws".to_string()
            },
            mean,
            p95,
            v[v.len() - 1],
            fresh_per_frame,
            100.0 * fresh_per_frame / (stats.size.x * stats.size.y).max(1) as f64,
            script.moving_work.0 as f64 / script.moving_seconds.max(1e-9) / 1e6,
            script.moving_work.1,
        );
        let [a, b] = script.moving_time;
        let wall = script.moving_seconds.max(1e-9);
        let [(w0, o0), (w1, o1)] = script.moving_cpu;
        println!(
            "moving CPU: trace worker {:.2} cores, everything else (Bevy, window, graphics driver) {:.2} cores",
            (w1 - w0) / wall,
            (o1 - o0) / wall
        );
        let [p0, p1] = script.moving_panel;
        println!(
            "moving inspector panel: drawn by egui {} times, its kept pixels shown {} times, drawn without the cache {} times",
            p1.drawn - p0.drawn,
            p1.reused - p0.reused,
            p1.uncached - p0.uncached,
        );
        println!(
            "moving worker time: reprojecting {:.0}%, tracing {:.0}%, making pictures {:.0}% of the wall clock",
            100.0 * (b.reproject - a.reproject) / wall,
            100.0 * (b.trace - a.trace) / wall,
            100.0 * (b.picture - a.picture) / wall,
        );
    }
    // Still: the worker's rays over its wall time, against the headless render.
    let film = views
        .worker
        .0
        .shared
        .still
        .lock()
        .ok()
        .and_then(|f| f.clone());
    let (Some(film), Ok((transform, projection)), Some(tree)) = (
        film,
        views.camera.single(),
        views.bvh.for_scene(views.current.generation),
    ) else {
        println!("still: no converged picture to compare");
        return;
    };
    let viewer_mrays = w.still_rays.total() as f64 / w.still_wall.max(1e-9) / 1e6;
    println!(
        "still worker time: tracing {:.2} s of {:.2} s",
        w.still_seconds, w.still_wall
    );
    let cam = camera_rays(
        transform,
        projection,
        UVec2::new(film.width(), film.height()),
        settings,
    );
    let mut scene = (*views.current.scene).clone();
    scene.camera.position = cam.eye;
    scene.camera.look_at = cam.eye + cam.forward;
    scene.camera.up = cam.up;
    let plan = settings.plan(&scene);
    let render_settings = RenderSettings {
        width: film.width(),
        height: film.height(),
        spp: film.passes(),
        seed: settings.seed,
        max_depth: settings.max_depth,
        sampler: settings.sampler,
        soft_terminator: settings.soft_terminator,
    };
    let t0 = Instant::now();
    let headless = render_with_plan(
        &scene,
        tree,
        &views.env.map,
        &render_settings,
        plan,
        &|_| {},
    );
    let secs = t0.elapsed().as_secs_f64();
    let headless_mrays = headless.rays.total() as f64 / secs / 1e6;
    let denoising = settings.denoise && settings.mode == super::trace::RenderMode::Shaded;
    println!(
        "still: {} spp at {}x{} in {:.2} s (denoiser {}): viewer {:.2} Mrays/s, tracery render of the same view {:.2} Mrays/s ({:.2} s), ratio {:.2}",
        film.passes(),
        film.width(),
        film.height(),
        w.still_wall,
        if denoising { "on" } else { "off" },
        viewer_mrays,
        headless_mrays,
        secs,
        viewer_mrays / headless_mrays.max(1e-9)
    );
    if denoising {
        denoise_report(&w, views, settings, &film);
    }
    // The moving picture against the converged one of the same pose, and the stretched
    // preview (the earlier design: a reduced picture with as many fresh samples, bilinear).
    let converged = resize_rgba8(
        picture_of(&film, settings).0,
        film.width(),
        film.height(),
        display.x,
        display.y,
        Filter::Nearest,
    );
    if let Some(snap) = &script.snapshot
        && let Some(pose) = snap.pose
        && snap.size == display
        && fresh_per_frame >= 1.0
    {
        let aspect = display.x as f64 / display.y as f64;
        let pw = ((fresh_per_frame * aspect).sqrt().round() as u32).clamp(1, display.x);
        let ph = ((fresh_per_frame / pw as f64).round() as u32).clamp(1, display.y);
        let mut plan = settings.plan(&scene);
        plan.max_light_samples = Some(1);
        let tracer = Tracer::new(&scene, tree, plan, settings.max_depth, &views.env.map);
        // One pass at a reduced size, stretched to the display as the earlier design did.
        let stretched = |size: UVec2| {
            let mut preview = Progressive::new(size.x, size.y);
            let pcam = camera_rays(&pose, projection, size, settings);
            preview.step_shaded(
                &tracer,
                &pcam,
                settings.sampler,
                settings.seed,
                Duration::from_secs(3600),
                1,
            );
            let rgba = resize_rgba8(
                preview.to_rgba8(settings.exposure),
                size.x,
                size.y,
                display.x,
                display.y,
                Filter::Bilinear,
            );
            (rmse_levels(&rgba, &converged), rgba)
        };
        // The earlier design's pass: 240x135 for a 16:9 window, as many pixels (32,400) at
        // another shape.
        let ow = ((32_400.0 * aspect).sqrt().round() as u32).clamp(1, display.x);
        let old = UVec2::new(
            ow,
            ((32_400.0 / ow as f64).round() as u32).clamp(1, display.y),
        );
        let (same_samples, earlier, fresh) = (
            stretched(UVec2::new(pw, ph)),
            stretched(old),
            stretched(display),
        );
        println!(
            "moving picture against the converged one ({} spp) of the same pose: RMSE {:.2} levels; stretched preview with as many fresh samples ({}x{}): {:.2} levels; the earlier design's {}x{} preview: {:.2} levels; every pixel freshly traced with one sample (the floor for one sample a pixel, unfiltered): {:.2} levels",
            film.passes(),
            rmse_levels(&snap.rgba, &converged),
            pw,
            ph,
            same_samples.0,
            old.x,
            old.y,
            earlier.0,
            fresh.0,
        );
        moving_filters(&views.worker.0.shared, snap, settings, &converged);
        if let Some(dir) = &script.script.orbit_pictures {
            let pictures = [
                ("moving.png", &snap.rgba),
                ("converged.png", &converged),
                ("stretched.png", &same_samples.1),
                ("earlier.png", &earlier.1),
            ];
            let saved = std::fs::create_dir_all(dir)
                .map_err(anyhow::Error::from)
                .and_then(|_| {
                    pictures.iter().try_for_each(|(name, rgba)| {
                        let path = dir.join(name);
                        image::save_buffer(
                            &path,
                            rgba,
                            display.x,
                            display.y,
                            image::ColorType::Rgba8,
                        )
                        .map_err(|e| anyhow::anyhow!("{}: cannot write PNG: {e}", path.display()))
                    })
                });
            match saved {
                Ok(()) => println!("orbit pictures: saved in {}", dir.display()),
                Err(e) => println!("orbit pictures: {e:#}"),
            }
        }
    } else {
        println!("moving picture: none shown at the end of the orbit to compare");
    }
    match idle_cpu {
        Some((c, frames)) => println!(
            "converged and idle: the process used {:.1}% of one core over {:.0} s ({frames} frames drawn)",
            c * 100.0,
            IDLE_WINDOW.as_secs_f64()
        ),
        None => println!("converged and idle: CPU use unknown (no /proc/self/stat)"),
    }
}
