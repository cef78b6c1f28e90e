//! The `--orbit` measurement of a scripted run (`tracery view --frames N --orbit M`): the
//! camera flown about the scene for `M` frames and each moving frame timed, the last moving
//! picture kept with its pose, and once the still picture has converged at that pose, the
//! process's idle CPU use; then [`report`] prints what the viewer did against what the
//! headless renderer does with the same view.

mod report;

use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use bevy::prelude::*;

use super::camera::FlyCamera;
use super::capture::Script;
use super::scene::CurrentScene;
use super::trace::{TraceCamera, TraceWorker, TracedImage};
pub(super) use report::{ReportViews, report};

/// How long the idle CPU use is measured for.
const IDLE_WINDOW: Duration = Duration::from_secs(4);

/// The moving picture shown at the end of the orbit, and the pose it was traced for.
struct Snapshot {
    rgba: Vec<u8>,
    size: UVec2,
    /// The job generation it was traced for, until the pose is found.
    generation: u64,
    pose: Option<Transform>,
}

/// What the orbit measured, and what its report compares.
#[derive(Resource, Default)]
pub(super) struct OrbitRecord {
    /// Frames the orbit lasts (0: no orbit).
    pub(super) frames: u32,
    /// Directory for the orbit's pictures (see [`super::capture::CaptureScript`]).
    pictures: Option<PathBuf>,
    /// The script's frame this record was last brought up to.
    frame: u32,
    /// The point the camera turns about: the scene's look-at point when the orbit began.
    center: Option<Vec3>,
    moving_ms: Vec<f64>,
    /// Job generation and camera pose of recent frames.
    poses: VecDeque<(u64, Transform)>,
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
    /// Start of the idle measurement: wall clock, process CPU seconds and the script's frame.
    idle_from: Option<(Instant, f64, u32)>,
    /// The report is printed.
    pub(super) reported: bool,
}

impl OrbitRecord {
    /// A record for an orbit of `frames` frames (0: none), saving its pictures in `pictures`.
    pub(super) fn new(frames: u32, pictures: Option<PathBuf>) -> OrbitRecord {
        OrbitRecord {
            frames,
            pictures,
            ..default()
        }
    }

    /// Whether the idle measurement has begun.
    pub(super) fn measuring_idle(&self) -> bool {
        self.idle_from.is_some()
    }

    /// The idle measurement, called once the picture has converged: the first call starts it
    /// at the script's frame `frame`; once [`IDLE_WINDOW`] has passed, the process's CPU use
    /// over it (in cores, where `/proc/self/stat` can be read) and the frames drawn.
    pub(super) fn idle_cpu(&mut self, frame: u32) -> Option<Option<(f64, u32)>> {
        let Some((t0, cpu0, frame0)) = self.idle_from else {
            let cpu = process_cpu_seconds().unwrap_or(0.0);
            self.idle_from = Some((Instant::now(), cpu, frame));
            return None;
        };
        if t0.elapsed() < IDLE_WINDOW {
            return None;
        }
        Some(process_cpu_seconds().map(|c| {
            let frames = frame - frame0;
            ((c - cpu0) / t0.elapsed().as_secs_f64(), frames)
        }))
    }
}

/// How fast the orbit turns: 72 degrees a second, a full turn in 5 s (the 2.4 degrees a frame
/// of a 150-frame turn at 33 ms a frame). It turns by time, not by frame, as a person flying
/// would: a window that draws faster does not fly the camera faster, and the trace worker,
/// whose pictures come at their own pace, sees the same motion between them.
const ORBIT_DEGREES_PER_SECOND: f32 = 72.0;

/// Turns the camera about the vertical through the scene's look-at point while the orbit
/// lasts, then stops it at the pose of the last moving picture shown.
pub(super) fn fly(
    record: Res<OrbitRecord>,
    time: Res<Time<Real>>,
    current: Res<CurrentScene>,
    mut camera: Query<&mut Transform, With<FlyCamera>>,
) {
    let (frame, frames) = (record.frame, record.frames);
    if frames == 0 || frame == 0 || frame > frames {
        return;
    }
    for mut t in &mut camera {
        if frame == frames {
            // The orbit is over: stop at the pose of the last moving picture shown, so the
            // converged picture is of the same view.
            if let Some(pose) = record.snapshot.as_ref().and_then(|s| s.pose) {
                *t = pose;
            }
            continue;
        }
        // About the vertical through the look-at point, by the time since the last frame (at
        // most 0.1 s: a stall does not make the camera jump).
        let center = record.center.unwrap_or(current.scene.camera.look_at);
        let dt = time.delta_secs().min(0.1);
        let q = Quat::from_rotation_y(ORBIT_DEGREES_PER_SECOND.to_radians() * dt);
        t.translation = center + q * (t.translation - center);
        t.rotation = q * t.rotation;
    }
}

/// Brings the record up to the script's frame: the moving frames timed (from the third, once
/// the window and its pipelines have started), the worker's counters read at the timed
/// frames' start and end, and the pose of the last moving picture found.
#[allow(clippy::too_many_arguments)]
pub(super) fn record(
    script: Res<Script>,
    mut record: ResMut<OrbitRecord>,
    time: Res<Time<Real>>,
    acc: Res<super::trace::Accumulation>,
    worker: Res<TraceWorker>,
    current: Res<CurrentScene>,
    camera: Query<&Transform, With<TraceCamera>>,
    panel: Option<Res<super::panel_cache::PanelCounts>>,
) {
    let panel = panel.map(|p| *p).unwrap_or_default();
    // Once a frame the script counts.
    if script.frame == record.frame {
        return;
    }
    record.frame = script.frame;
    let (frame, orbit) = (record.frame, record.frames);
    if orbit == 0 || frame > orbit {
        return;
    }
    if record.center.is_none() {
        record.center = Some(current.scene.camera.look_at);
    }
    if let Ok(t) = camera.single() {
        record.poses.push_back((acc.generation, *t));
        if record.poses.len() > 64 {
            record.poses.pop_front();
        }
    }
    let w = worker.0.shared.stats();
    // Skip the first frames (window and pipelines start up) when timing.
    if frame == 3 {
        record.moving_from = Some((w.moving_samples, w.moving_pictures));
        record.moving_time[0] = w.moving_time;
        record.moving_wall = Some(Instant::now());
        record.moving_cpu[0] = thread_cpu_seconds();
        record.moving_panel[0] = panel;
    }
    if frame > 3 {
        record.moving_ms.push(time.delta_secs_f64() * 1e3);
    }
    if frame == orbit {
        if let Some((s0, p0)) = record.moving_from {
            record.moving_work = (w.moving_samples - s0, w.moving_pictures - p0);
        }
        record.moving_time[1] = w.moving_time;
        record.moving_cpu[1] = thread_cpu_seconds();
        record.moving_panel[1] = panel;
        record.moving_seconds = record
            .moving_wall
            .map_or(0.0, |t| t.elapsed().as_secs_f64());
        let record = &mut *record;
        let poses = &record.poses;
        if let Some(snap) = record.snapshot.as_mut() {
            snap.pose = poses
                .iter()
                .find(|(g, _)| *g == snap.generation)
                .map(|(_, t)| *t);
        }
    }
}

/// Keeps a copy of each moving picture of the orbit's last frames before the display takes its
/// pixels: the last one is compared with the converged picture of its pose.
pub(super) fn keep_snapshot(
    mut record: ResMut<OrbitRecord>,
    image: Res<TracedImage>,
    worker: Res<TraceWorker>,
) {
    let (frame, orbit) = (record.frame + 1, record.frames);
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
        record.snapshot = Some(Snapshot {
            rgba: image.rgba.clone(),
            size: UVec2::new(image.width, image.height),
            generation: image.generation,
            pose: None,
        });
    }
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
