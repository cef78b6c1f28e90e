//! The `--orbit` report: what the viewer did while moving and once still, against the
//! headless renderer on the same view, one phase a function.

use std::time::{Duration, Instant};

use bevy::prelude::*;

use super::{IDLE_WINDOW, OrbitRecord, Snapshot};
use crate::film::rmse_levels;
use crate::render::cache::MovingFilter;
use crate::render::resample::{Filter, resize_rgba8};
use crate::render::{Progressive, RenderSettings, Tracer, render_with_plan};
use crate::viewer::bvh::SceneBvh;
use crate::viewer::scene::CurrentScene;
use crate::viewer::trace::{
    LoadedEnvironment, TraceCamera, TraceStats, TraceWorker, ViewSettings, ViewportSize,
    camera_rays, picture_of,
};
use crate::viewer::worker::{Shared, WorkerStats};

/// What the report reads besides the script.
#[derive(bevy::ecs::system::SystemParam)]
pub(in crate::viewer) struct ReportViews<'w, 's> {
    worker: Res<'w, TraceWorker>,
    current: Res<'w, CurrentScene>,
    bvh: Res<'w, SceneBvh>,
    env: Res<'w, LoadedEnvironment>,
    viewport: Res<'w, ViewportSize>,
    camera: Query<'w, 's, (&'static Transform, &'static Projection), With<TraceCamera>>,
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

/// The `--orbit` report's denoising lines: what denoising cost the still picture, when its
/// first denoised picture came, and how close that was to the converged picture against the
/// picture as traced at 16 times that time.
fn denoise_report(
    w: &WorkerStats,
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

/// Prints the report of a finished orbit (`idle_cpu` as [`OrbitRecord::idle_cpu`] gave it).
pub(in crate::viewer) fn report(
    record: &OrbitRecord,
    stats: &TraceStats,
    settings: &ViewSettings,
    views: &ReportViews,
    idle_cpu: Option<(f64, u32)>,
) {
    let w = views.worker.0.shared.stats();
    let fresh_per_frame = moving(record, stats, settings);
    let Some((film, scene)) = still(settings, views, &w) else {
        println!("still: no converged picture to compare");
        return;
    };
    moving_picture(record, settings, views, &film, &scene, fresh_per_frame);
    match idle_cpu {
        Some((c, frames)) => println!(
            "converged and idle: the process used {:.1}% of one core over {:.0} s ({frames} frames drawn)",
            c * 100.0,
            IDLE_WINDOW.as_secs_f64()
        ),
        None => println!("converged and idle: CPU use unknown (no /proc/self/stat)"),
    }
}

/// The moving lines: frame times, fresh samples, CPU use and where the worker's time went.
/// Returns the fresh samples a frame.
fn moving(record: &OrbitRecord, stats: &TraceStats, settings: &ViewSettings) -> f64 {
    let v = {
        let mut v = record.moving_ms.clone();
        v.sort_by(f64::total_cmp);
        v
    };
    let fresh_per_frame = record.moving_work.0 as f64 / v.len().max(1) as f64;
    if v.is_empty() {
        return fresh_per_frame;
    }
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
        record.moving_work.0 as f64 / record.moving_seconds.max(1e-9) / 1e6,
        record.moving_work.1,
    );
    let [a, b] = record.moving_time;
    let wall = record.moving_seconds.max(1e-9);
    let [(w0, o0), (w1, o1)] = record.moving_cpu;
    println!(
        "moving CPU: trace worker {:.2} cores, everything else (Bevy, window, graphics driver) {:.2} cores",
        (w1 - w0) / wall,
        (o1 - o0) / wall
    );
    let [p0, p1] = record.moving_panel;
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
    fresh_per_frame
}

/// The still line: the converged picture's rays a second in the viewer against `tracery
/// render` of the same view and samples, then the denoiser's lines. Returns the converged film
/// and the scene as seen from the camera, or `None` without a converged picture.
fn still(
    settings: &ViewSettings,
    views: &ReportViews,
    w: &WorkerStats,
) -> Option<(Progressive, crate::scene::Scene)> {
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
        views.bvh.tracing(views.current.generation),
    ) else {
        return None;
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
    let denoising = settings.denoise && settings.mode == crate::viewer::trace::RenderMode::Shaded;
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
        denoise_report(w, views, settings, &film);
    }
    Some((film, scene))
}

/// The moving picture's lines: the last one shown against the converged picture of its pose,
/// beside stretched previews of as many fresh samples and the filters on its samples; and the
/// orbit's pictures saved where asked.
fn moving_picture(
    record: &OrbitRecord,
    settings: &ViewSettings,
    views: &ReportViews,
    film: &Progressive,
    scene: &crate::scene::Scene,
    fresh_per_frame: f64,
) {
    let display = views.viewport.0;
    let (Ok((_, projection)), Some(tree)) = (
        views.camera.single(),
        views.bvh.tracing(views.current.generation),
    ) else {
        return;
    };
    // The moving picture against the converged one of the same pose, and the stretched
    // preview (the earlier design: a reduced picture with as many fresh samples, bilinear).
    let converged = resize_rgba8(
        picture_of(film, settings).0,
        film.width(),
        film.height(),
        display.x,
        display.y,
        Filter::Nearest,
    );
    if let Some(snap) = &record.snapshot
        && let Some(pose) = snap.pose
        && snap.size == display
        && fresh_per_frame >= 1.0
    {
        let aspect = display.x as f64 / display.y as f64;
        let pw = ((fresh_per_frame * aspect).sqrt().round() as u32).clamp(1, display.x);
        let ph = ((fresh_per_frame / pw as f64).round() as u32).clamp(1, display.y);
        let mut plan = settings.plan(scene);
        plan.max_light_samples = Some(1);
        let tracer = Tracer::new(scene, tree, plan, settings.max_depth, &views.env.map);
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
        if let Some(dir) = &record.pictures {
            save_pictures(
                dir,
                display,
                &[
                    ("moving.png", &snap.rgba),
                    ("converged.png", &converged),
                    ("stretched.png", &same_samples.1),
                    ("earlier.png", &earlier.1),
                ],
            );
        }
    } else {
        println!("moving picture: none shown at the end of the orbit to compare");
    }
}

/// Saves the orbit's pictures (RGBA8 of `size`) as PNGs named in `dir`, and says so.
fn save_pictures(dir: &std::path::Path, size: UVec2, pictures: &[(&str, &Vec<u8>)]) {
    let saved = std::fs::create_dir_all(dir)
        .map_err(anyhow::Error::from)
        .and_then(|_| {
            pictures.iter().try_for_each(|(name, rgba)| {
                let path = dir.join(name);
                image::save_buffer(&path, rgba, size.x, size.y, image::ColorType::Rgba8)
                    .map_err(|e| anyhow::anyhow!("{}: cannot write PNG: {e}", path.display()))
            })
        });
    match saved {
        Ok(()) => println!("orbit pictures: saved in {}", dir.display()),
        Err(e) => println!("orbit pictures: {e:#}"),
    }
}
