//! Saving pictures and scripted runs: the full-resolution traced image as PNG (P or the
//! inspector's button), and for `tracery view --frames N`: an optional camera orbit that
//! measures frame times while moving, samples per second when still, a window screenshot and
//! a clean exit.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use bevy::prelude::*;
use bevy::render::view::screenshot::{Screenshot, ScreenshotCaptured};

use super::camera::FlyCamera;
use super::scene::{CurrentScene, ViewerStatus};
use super::trace::{Accumulation, TraceStats, TracedImage, ViewSettings, picture};

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
    /// Orbit the camera about the scene's look-at point for this many frames first
    /// (measuring frame times while moving).
    pub orbit_frames: u32,
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
            .add_systems(First, orbit)
            .add_systems(Last, (measure, finish).chain());
        }
    }
}

/// Save the full-resolution traced image (to the path, or to `out/` under a generated name).
#[derive(Message, Clone, Debug)]
pub struct SavePng(pub Option<PathBuf>);

fn save_png(
    mut requests: MessageReader<SavePng>,
    acc: Res<Accumulation>,
    settings: Res<ViewSettings>,
    current: Res<CurrentScene>,
    mut status: ResMut<ViewerStatus>,
) {
    let Some(SavePng(path)) = requests.read().last().cloned() else {
        return;
    };
    let Some(film) = acc.full().filter(|f| f.passes() > 0) else {
        status.notice =
            Some("nothing to save yet: the full-resolution image has no samples".into());
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
    let (rgba, _) = picture(film, &settings);
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

#[derive(Resource, Default)]
struct Script {
    script: CaptureScript,
    frame: u32,
    orbit_center: Option<Vec3>,
    moving_ms: Vec<f64>,
    moving_trace_ms: Vec<f64>,
    still_ms: Vec<f64>,
    still_start: Option<(f64, u64, u32)>,
    screenshot_requested: bool,
    saved: Arc<AtomicBool>,
    exit_in: Option<u32>,
}

fn orbit(
    mut script: ResMut<Script>,
    current: Res<CurrentScene>,
    mut camera: Query<&mut Transform, With<FlyCamera>>,
) {
    if script.frame >= script.script.orbit_frames || script.frame == 0 {
        return;
    }
    let center = *script
        .orbit_center
        .get_or_insert(current.scene.camera.look_at);
    for mut t in &mut camera {
        // A full turn over the orbit, about the vertical through the look-at point.
        let step = std::f32::consts::TAU / script.script.orbit_frames.max(1) as f32;
        let q = Quat::from_rotation_y(step);
        t.translation = center + q * (t.translation - center);
        t.rotation = q * t.rotation;
    }
}

fn measure(
    mut script: ResMut<Script>,
    time: Res<Time<Real>>,
    acc: Res<Accumulation>,
    stats: Res<TraceStats>,
) {
    script.frame += 1;
    let frame = script.frame;
    let orbit = script.script.orbit_frames;
    if orbit == 0 {
        return;
    }
    // Skip the first frames (window and pipelines start up) when timing.
    if frame > 3 && frame <= orbit {
        let ms = time.delta_secs_f64() * 1e3;
        script.moving_ms.push(ms);
        script.moving_trace_ms.push(stats.trace_ms);
    }
    if frame > orbit + 1 {
        let ms = time.delta_secs_f64() * 1e3;
        script.still_ms.push(ms);
    }
    if frame == orbit + 1 {
        script.still_start = Some((
            time.elapsed_secs_f64(),
            acc.full().map_or(0, |f| f.rays.total()),
            acc.full_passes(),
        ));
    }
}

fn finish(
    mut commands: Commands,
    mut script: ResMut<Script>,
    image: Res<TracedImage>,
    acc: Res<Accumulation>,
    stats: Res<TraceStats>,
    time: Res<Time<Real>>,
    mut exit: MessageWriter<AppExit>,
) {
    if let Some(n) = script.exit_in.as_mut() {
        if *n == 0 {
            exit.write(AppExit::Success);
        } else {
            *n -= 1;
        }
        return;
    }
    if script.frame < script.script.frames {
        return;
    }
    if let Some(target) = script.script.samples
        && (image.preview || image.samples < target)
    {
        return;
    }
    if !script.screenshot_requested {
        report(&script, &acc, &stats, &time);
        match script.script.screenshot.clone() {
            Some(path) => {
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
        return;
    }
    if script.saved.load(Ordering::SeqCst) {
        script.exit_in = Some(1);
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

fn report(script: &Script, acc: &Accumulation, stats: &TraceStats, time: &Time<Real>) {
    let s = &script.script;
    if s.orbit_frames > 0 && !script.moving_ms.is_empty() {
        let mut v = script.moving_ms.clone();
        v.sort_by(f64::total_cmp);
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        let p95 = v[((v.len() as f64 * 0.95) as usize).min(v.len() - 1)];
        let trace = script.moving_trace_ms.iter().sum::<f64>() / v.len() as f64;
        println!(
            "moving: {} frames, frame time mean {:.1} ms, p95 {:.1} ms, max {:.1} ms (tracing {:.1} ms of it); preview {}x{} of {}x{}",
            v.len(),
            mean,
            p95,
            v[v.len() - 1],
            trace,
            stats.preview_size.x,
            stats.preview_size.y,
            stats.size.x,
            stats.size.y
        );
    }
    if let Some((t0, rays0, spp0)) = script.still_start {
        let secs = time.elapsed_secs_f64() - t0;
        let spp = acc.full_passes().saturating_sub(spp0);
        let rays = acc
            .full()
            .map_or(0, |f| f.rays.total())
            .saturating_sub(rays0);
        let frames = script.still_ms.len().max(1);
        if secs > 0.0 {
            println!(
                "still: {} samples per pixel in {:.2} s = {:.2} spp/s at {}x{}, {:.2} Mrays/s; frame time mean {:.1} ms",
                spp,
                secs,
                spp as f64 / secs,
                stats.size.x,
                stats.size.y,
                rays as f64 / secs / 1e6,
                script.still_ms.iter().sum::<f64>() / frames as f64
            );
        }
    }
}
