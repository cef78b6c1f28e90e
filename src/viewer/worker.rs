//! The trace worker: a thread of its own that owns the pictures and traces continuously, off
//! Bevy's schedule (on the rayon pool), so a frame never waits for tracing.
//!
//! Systems send it jobs ([`Job`]: the view, the shared scene, BVH and environment, the
//! settings, a generation number) and pick up finished pictures ([`Picture`], tone mapped and
//! resized to the display already). The worker always works on the newest job: a job that a
//! newer one replaced is abandoned between two batches of pixels or rows (a few milliseconds).
//! A picture is only handed over while its job is the newest sent, or differs from the newest
//! only in its view (the moving picture left part-way is still shown, a frame late, while the
//! next is made); never one of other content or settings ([`Worker::send`] and the worker's
//! publishing take the same lock, and a send drops a waiting picture it makes stale).
//!
//! For each view the worker first shows the moving picture: the render cache carried over
//! from the previous view and refreshed where it changed ([`crate::render::cache`]). Once no
//! new view has come for the settings' `still_after_ms`, the still picture starts over from
//! fresh samples and refines pass by pass ([`crate::render::Progressive`]) up to the sample
//! limit; then the worker waits for the next job without using the CPU. After `n` passes the
//! still picture is exactly the headless render with `n` samples per pixel.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, Sender, TryRecvError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use bevy::prelude::UVec2;
use glam::Vec3;

use super::still_denoise::StillDenoise;
use super::trace::{RenderMode, ViewSettings, picture_of, step_mode};
use crate::bvh::Bvh;
use crate::camera::CameraRays;
use crate::render::cache::{RenderCache, TILE};
use crate::render::heatmap::heatmap_rgba8;
use crate::render::path::LightSet;
use crate::render::resample::{Filter, resize_rgba8};
use crate::render::{EnvironmentMap, Progressive, RayCounts, RenderPlan, Tracer};
use crate::scene::Scene;

/// While the view stays the same, the moving picture is shown again this often.
const MOVING_REFRESH: Duration = Duration::from_millis(33);

/// While still, a completed round of passes is shown when the passes reach a power of two
/// (after 1 and 4 passes: see [`crate::render::Progressive`]'s rounds), and otherwise
/// at most this often (the last at once): each picture costs the window a redraw, taken from
/// the tracing.
const STILL_REFRESH: Duration = Duration::from_millis(1000);

/// While still, a part-way pass is shown at most this often.
const STILL_PARTIAL: Duration = Duration::from_millis(1000);

/// A still picture that has refined this long seeds the moving picture at each completed pass
/// (one that finishes sooner, when it finishes).
const SEED_AFTER: Duration = Duration::from_secs(1);

/// Length of one slice of still tracing between checks for a newer job.
const STILL_SLICE: Duration = Duration::from_millis(15);

/// What the samples depend on besides the view: a change empties the moving picture's cache.
#[derive(Clone, Debug, PartialEq)]
pub struct Content {
    /// Scene generation.
    pub scene: u64,
    /// Identity of the BVH.
    pub bvh: usize,
    /// Environment generation.
    pub env: u64,
    /// Traced size.
    pub size: UVec2,
    /// The settings that change samples ([`ViewSettings::trace_key`]).
    pub settings: ViewSettings,
}

/// What to trace.
#[derive(Clone)]
pub struct Job {
    /// Numbers the jobs; a picture carries the generation of its job.
    pub generation: u64,
    /// The scene.
    pub scene: Arc<Scene>,
    /// Its BVH.
    pub bvh: Arc<Bvh>,
    /// The environment, loaded.
    pub env: Arc<EnvironmentMap>,
    /// The view at the traced resolution.
    pub camera: CameraRays,
    /// The display size the picture is resized to.
    pub display: UVec2,
    /// The render settings.
    pub settings: ViewSettings,
    /// What the samples depend on besides the view.
    pub content: Content,
}

/// A finished picture.
#[derive(Clone, Debug, Default)]
pub struct Picture {
    /// The job it belongs to.
    pub generation: u64,
    /// RGBA8 at the display size, sRGB, tone mapped.
    pub rgba: Vec<u8>,
    /// Display size.
    pub width: u32,
    /// Display size.
    pub height: u32,
    /// Samples per pixel behind it (0 for the moving picture).
    pub samples: u32,
    /// True for the moving picture.
    pub moving: bool,
    /// Samples traced into the moving picture since the one before.
    pub fresh: u64,
    /// Pixels of the moving picture holding no sample (filled from their neighbours).
    pub holes: u64,
    /// Heatmap mean and top (cost, overlap and work views).
    pub heat: (f32, f32),
    /// True for a denoised still picture.
    pub denoised: bool,
}

/// What the worker reports besides pictures.
#[derive(Clone, Debug, Default)]
pub struct WorkerStats {
    /// Generation of the job being worked on.
    pub generation: u64,
    /// Complete passes of the still picture.
    pub passes: u32,
    /// Rays traced for the still picture since it started over.
    pub still_rays: RayCounts,
    /// Seconds spent tracing the still picture since it started over.
    pub still_seconds: f64,
    /// Wall-clock seconds from the still picture's start to its last traced slice.
    pub still_wall: f64,
    /// Samples traced into the moving picture, in all.
    pub moving_samples: u64,
    /// Moving pictures published.
    pub moving_pictures: u64,
    /// Jobs left part-way because a newer one came.
    pub abandoned: u64,
    /// Rays per second of the last batch, in millions.
    pub mrays_per_s: f64,
    /// True while the worker has nothing to do.
    pub idle: bool,
    /// Seconds the moving picture spent carrying samples to new views, tracing, and making
    /// pictures (tone mapping, filling holes, resizing).
    pub moving_time: MovingTime,
    /// The still picture's denoising.
    pub denoise: DenoiseStats,
}

/// What denoising the still picture did since it started over.
#[derive(Clone, Debug, Default)]
pub struct DenoiseStats {
    /// Denoised pictures made.
    pub pictures: u32,
    /// Passes behind the last denoised picture.
    pub passes: u32,
    /// Seconds all of them took (their render layers included).
    pub seconds: f64,
    /// Seconds from the still picture's start to its first denoised picture being shown.
    pub first_after: Option<f64>,
    /// Why the denoiser cannot run, if it cannot.
    pub error: Option<String>,
}

/// Pictures kept for the `--orbit` report's denoising figures (traced size, RGBA8): the first
/// denoised picture of the still, shown `first.0` seconds after it started, and the picture
/// as traced at 16 times that time.
#[derive(Clone, Debug, Default)]
pub struct DenoiseProbe {
    /// Seconds after the start and the first denoised picture.
    pub first: Option<(f64, Vec<u8>)>,
    /// Seconds after the start and the picture as traced then.
    pub plain_later: Option<(f64, Vec<u8>)>,
}

/// Where the moving picture's time goes, in seconds.
#[derive(Clone, Copy, Debug, Default)]
pub struct MovingTime {
    /// Reprojecting the cache to new views.
    pub reproject: f64,
    /// Tracing fresh samples.
    pub trace: f64,
    /// Making pictures.
    pub picture: f64,
}

/// The picture slot: the newest generation sent and the newest picture not yet taken.
#[derive(Default)]
struct Slot {
    newest: u64,
    /// What the newest job traces besides its view: content, settings and display size.
    newest_key: Option<(Content, ViewSettings, UVec2)>,
    /// The first generation of a run of jobs that differ only in their view: pictures of
    /// these jobs may still be shown, a frame late, but none of an earlier one.
    view_run_from: u64,
    picture: Option<Picture>,
}

impl Slot {
    /// Whether a picture of job `generation` may be put in the slot: of the newest job's
    /// content and settings, and of a job no older than a picture waiting. A later picture of
    /// the same job replaces one waiting (the worker publishes them in order): refused, the
    /// still picture's last pass was lost whenever the app had not yet taken the one before,
    /// and the window stayed one pass short of the limit (the app test waiting for 4 samples
    /// hung in 3 of 40 runs beside a busy core).
    fn accepts(&self, generation: u64) -> bool {
        generation >= self.view_run_from
            && generation <= self.newest
            && self
                .picture
                .as_ref()
                .is_none_or(|p| p.generation <= generation)
    }
}

/// What the worker and the systems share.
#[derive(Default)]
pub struct Shared {
    /// Generation of the newest job sent (read without the lock to notice staleness).
    newest: AtomicU64,
    slot: Mutex<Slot>,
    /// The worker's figures.
    pub stats: Mutex<WorkerStats>,
    /// The still picture's film as last shown with a completed pass, for saving it.
    pub still: Mutex<Option<Progressive>>,
    /// Called after a picture is published (wakes a waiting event loop).
    pub wake: Mutex<Option<Box<dyn Fn() + Send>>>,
    /// The current still picture's first denoised picture, and the plain one 16 times later.
    pub probe: Mutex<DenoiseProbe>,
    /// Set to keep a copy of the samples of each moving picture published (see
    /// [`Shared::moving_samples`]): the `--orbit` report compares the moving picture's
    /// filters on the samples of its last picture.
    pub keep_moving_samples: AtomicBool,
    /// The job generations and the samples of the last [`KEPT_MOVING`] moving pictures
    /// published while [`Shared::keep_moving_samples`] was set, oldest first.
    pub moving_samples: Mutex<std::collections::VecDeque<(u64, RenderCache)>>,
}

impl Shared {
    /// A copy of the worker's figures.
    pub fn stats(&self) -> WorkerStats {
        self.stats.lock().map(|s| s.clone()).unwrap_or_default()
    }
}

/// Moving pictures whose samples [`Shared::moving_samples`] keeps: the one shown last may
/// not be the last one published.
pub const KEPT_MOVING: usize = 3;

/// The worker thread and its mailbox.
pub struct Worker {
    jobs: Option<Sender<Job>>,
    /// State shared with the thread.
    pub shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
}

impl Worker {
    /// Starts the worker: a pool of one thread per core, the worker's loop running on one of
    /// them, so the loop works on every batch it hands the pool itself rather than waiting
    /// for sleeping threads to be scheduled (the window's threads compete for the cores).
    pub fn start() -> Worker {
        let (tx, rx) = std::sync::mpsc::channel::<Job>();
        let shared = Arc::new(Shared::default());
        let s = shared.clone();
        let threads = std::thread::available_parallelism().map_or(2, |n| n.get());
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .thread_name(|i| format!("tracery-trace-{i}"))
            .build();
        let thread = std::thread::Builder::new()
            .name("tracery-trace".into())
            .spawn(move || match pool {
                Ok(pool) => pool.install(|| run(rx, s)),
                // No pool of its own: the global one.
                Err(_) => run(rx, s),
            })
            .expect("the system can start a thread");
        Worker {
            jobs: Some(tx),
            shared,
            thread: Some(thread),
        }
    }

    /// Hands the worker a job: it replaces whatever the worker was doing. A picture of an older
    /// job not yet taken is dropped, unless the two differ only in their view.
    pub fn send(&self, job: Job) {
        if let Ok(mut slot) = self.shared.slot.lock() {
            let key = (job.content.clone(), job.settings.clone(), job.display);
            if slot.newest_key.as_ref() != Some(&key) {
                slot.view_run_from = job.generation;
                slot.newest_key = Some(key);
            }
            slot.newest = job.generation;
            self.shared.newest.store(job.generation, Ordering::SeqCst);
            if slot
                .picture
                .as_ref()
                .is_some_and(|p| p.generation < slot.view_run_from)
            {
                slot.picture = None;
            }
        }
        if let Some(tx) = &self.jobs {
            // The thread only ends when the sender is dropped.
            let _ = tx.send(job);
        }
    }

    /// The newest picture not yet taken: of the newest job sent, or of an earlier one that
    /// differs from it only in the view (a moving picture a frame late).
    pub fn take_picture(&self) -> Option<Picture> {
        self.shared.slot.lock().ok()?.picture.take()
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        // A job under way notices the generation change; dropping the sender ends the wait.
        self.shared.newest.store(u64::MAX, Ordering::SeqCst);
        self.jobs = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// The moving picture and what it was traced for.
struct Moving {
    cache: RenderCache,
    view: CameraRays,
    content: Content,
    /// Pixels left without a sample by the last reprojection, not yet traced.
    holes: Vec<u32>,
    /// Samples traced since the last picture.
    fresh: u64,
    /// True while the cache holds the still picture of `view`, seeded from it.
    seeded: bool,
}

/// The worker's state between steps.
struct State {
    job: Option<Job>,
    /// When the view or the content last changed.
    since: Instant,
    /// True until the current view has had a picture.
    view_changed: bool,
    moving: Option<Moving>,
    /// The still picture (started once the view has been still long enough) and its start.
    still: Option<Progressive>,
    still_start: Instant,
    last_shown: Option<Instant>,
    /// Show the picture again though nothing was traced (exposure or display changed).
    reshow: bool,
    /// The light set of the last scene traced.
    lights: LightCache,
    /// The still picture's denoising.
    denoise: StillDenoise,
    done: bool,
}

fn run(rx: Receiver<Job>, shared: Arc<Shared>) {
    // The moving picture is made on one thread: while the camera moves, the window, Bevy and
    // the graphics driver need the other cores every frame, and a batch split over threads
    // waits for its slowest part (a thread the system put aside waits a whole time slice).
    // The still picture takes every core.
    let moving_pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .thread_name(|_| "tracery-trace-moving".into())
        .build()
        .ok();
    let mut st = State {
        job: None,
        since: Instant::now(),
        view_changed: true,
        moving: None,
        still: None,
        still_start: Instant::now(),
        last_shown: None,
        reshow: false,
        lights: None,
        denoise: StillDenoise::default(),
        done: true,
    };
    loop {
        // Wait for a job when there is nothing to do; otherwise take the newest waiting.
        let mut next = None;
        if st.done || st.job.is_none() {
            set_idle(&shared, true);
            match rx.recv() {
                Ok(j) => next = Some(j),
                Err(_) => return,
            }
        }
        loop {
            match rx.try_recv() {
                Ok(j) => next = Some(j),
                Err(TryRecvError::Empty) => break,
                Err(TryRecvError::Disconnected) => return,
            }
        }
        if let Some(j) = next {
            set_idle(&shared, false);
            adopt(&mut st, j, &shared);
        }
        let Some(job) = st.job.clone() else {
            continue;
        };
        let stale = || shared.newest.load(Ordering::SeqCst) != job.generation;
        if stale() {
            continue;
        }
        let traced = matches!(job.settings.mode, RenderMode::Shaded | RenderMode::Work);
        let still_after = Duration::from_secs_f32(job.settings.still_after_ms.max(0.0) * 1e-3);
        if traced && st.still.is_none() && st.since.elapsed() < still_after {
            match &moving_pool {
                Some(pool) => pool.install(|| moving_step(&mut st, &job, &shared, &stale)),
                None => moving_step(&mut st, &job, &shared, &stale),
            }
        } else {
            still_step(&mut st, &job, &shared, &stale);
        }
    }
}

/// Makes `job` the current one. The same view with the same content keeps the pictures (only
/// the tone mapping, the display or the limits changed): they are shown again.
fn adopt(st: &mut State, job: Job, shared: &Shared) {
    let same = st
        .job
        .as_ref()
        .is_some_and(|old| old.content == job.content && same_view(&old.camera, &job.camera));
    if !st.done
        && !same
        && st.job.is_some()
        && let Ok(mut s) = shared.stats.lock()
    {
        s.abandoned += 1;
    }
    if same {
        st.reshow = true;
    } else {
        st.since = Instant::now();
        st.view_changed = true;
        st.still = None;
    }
    if let Ok(mut s) = shared.stats.lock() {
        s.generation = job.generation;
    }
    st.job = Some(job);
    st.done = false;
}

fn set_idle(shared: &Shared, idle: bool) {
    if let Ok(mut s) = shared.stats.lock() {
        s.idle = idle;
    }
}

/// Hands over a picture of `job` unless a newer job with other content or settings has been
/// sent (or a newer picture waits); true if it was.
fn publish(shared: &Shared, job: &Job, mut p: Picture) -> bool {
    p.generation = job.generation;
    {
        let Ok(mut slot) = shared.slot.lock() else {
            return false;
        };
        if !slot.accepts(job.generation) {
            return false;
        }
        slot.picture = Some(p);
    }
    if let Ok(wake) = shared.wake.lock()
        && let Some(w) = wake.as_ref()
    {
        w();
    }
    true
}

/// Keeps the still picture's first denoised picture for the `--orbit` report.
fn keep_for_probe(still_start: Instant, shared: &Shared, rgba: &[u8], denoised: bool) {
    if !denoised {
        return;
    }
    if let Ok(mut p) = shared.probe.lock()
        && p.first.is_none()
    {
        p.first = Some((still_start.elapsed().as_secs_f64(), rgba.to_vec()));
    }
}

/// Keeps the still picture as traced at 16 times the time its first denoised picture took
/// from the camera's stop, for the `--orbit` report (the plain picture's error at that time
/// beside the denoised one's).
fn plain_for_probe(still_start: Instant, shared: &Shared, film: &Progressive, job: &Job) {
    let Ok(mut p) = shared.probe.lock() else {
        return;
    };
    let Some((first, _)) = p.first else {
        return;
    };
    // Both counted from when the camera stopped: the still picture starts `still_after_ms`
    // later.
    let stop = job.settings.still_after_ms.max(0.0) as f64 * 1e-3;
    let now = still_start.elapsed().as_secs_f64();
    let at_limit = film.passes() >= job.settings.max_samples.max(1);
    if p.plain_later.is_none() && (stop + now >= 16.0 * (stop + first) || at_limit) {
        p.plain_later = Some((now, film.to_rgba8(job.settings.exposure)));
    }
}

/// A picture of the traced size resized to the job's display (unchanged at the same size).
fn to_display(rgba: Vec<u8>, size: UVec2, job: &Job) -> Vec<u8> {
    let d = job.display;
    resize_rgba8(rgba, size.x, size.y, d.x, d.y, Filter::Nearest)
}

/// The tracer of a job (`light_samples`: a cap on area-light shadow rays) with the light set
/// kept for its scene.
fn tracer<'a>(job: &'a Job, light_samples: Option<u32>, lights: Arc<LightSet>) -> Tracer<'a> {
    let mut plan: RenderPlan = job.settings.plan(&job.scene);
    if light_samples.is_some() {
        plan.max_light_samples = light_samples;
    }
    let max_depth = job.settings.max_depth;
    Tracer::with_lights(&job.scene, &job.bvh, plan, max_depth, &job.env, lights)
}

/// The integrators' light set for the job's scene: found once per scene, not for every slice
/// (with many emissive triangles it walks them all).
fn lights_for(cache: &mut LightCache, job: &Job) -> Arc<LightSet> {
    let key = job.content.scene;
    if let Some((k, lights)) = cache.as_ref()
        && *k == key
    {
        return lights.clone();
    }
    let lights = Arc::new(LightSet::new(&job.scene));
    *cache = Some((key, lights.clone()));
    lights
}

/// The light set kept for a scene (its generation).
type LightCache = Option<(u64, Arc<LightSet>)>;

fn same_view(a: &CameraRays, b: &CameraRays) -> bool {
    a.eye == b.eye
        && a.forward == b.forward
        && a.right == b.right
        && a.up == b.up
        && a.width == b.width
        && a.height == b.height
        && a.tan_half == b.tan_half
}

/// One step of the moving picture: carry the cache to this view (once per view), trace the
/// pixels no sample reached, then fresh pixels by tile priority, until the picture is due;
/// publish. A newer job stops the tracing (the samples stay in the cache for the next view).
fn moving_step(st: &mut State, job: &Job, shared: &Shared, stale: &dyn Fn() -> bool) {
    let start = Instant::now();
    let cam = &job.camera;
    let size = UVec2::new(cam.width, cam.height);
    let m = moving_cache(&mut st.moving, job);
    if !same_view(&m.view, cam) {
        m.holes = m.cache.reproject(cam);
        m.view = *cam;
        m.seeded = false;
    }
    let reprojected = start.elapsed().as_secs_f64();
    // A new view gets the moving budget of tracing (the pixels the reprojection left empty
    // first, for up to four budgets while no newer view waits), then its picture is shown,
    // even if a newer view came meanwhile (that one's picture follows, a frame late): when the
    // worker falls behind, it skips views rather than pictures going without samples. A new
    // cache (other content) is shown one budget after the last picture; an unchanged view is
    // refined until a newer job comes, and shown at the refresh rate. Other content or
    // settings stop the tracing at once. A budget of 0 only carries the picture over.
    let budget = Duration::from_secs_f32(job.settings.moving_budget_ms.max(0.0) * 1e-3);
    let tracing_from = Instant::now();
    let view_changed = st.view_changed;
    let due = if budget.is_zero() {
        tracing_from
    } else if view_changed && m.cache.filled() > 0 {
        tracing_from + budget
    } else if view_changed {
        let since = st.last_shown.map_or(budget, |t| t.elapsed());
        start + budget.saturating_sub(since)
    } else {
        start + budget.max(MOVING_REFRESH)
    };
    let holes_until = tracing_from + 4 * budget;
    let content_stale = || !shared.slot.lock().is_ok_and(|s| s.accepts(job.generation));
    let t = tracer(job, Some(1), lights_for(&mut st.lights, job));
    let mut rays = RayCounts::default();
    let chunk = ((size.x * size.y) as usize / 64).clamp(1024, 16384);
    let mut traced = 0u64;
    loop {
        let now = Instant::now();
        // One batch at least (unless the budget is 0): if carrying the picture over took
        // longer than the frames come, the picture still gains samples.
        let first = traced == 0 && !budget.is_zero();
        if content_stale() {
            break;
        }
        let holes_left = !m.holes.is_empty() && now < holes_until && !stale();
        let past_due = now >= due;
        if !first && (past_due && !holes_left || !past_due && !view_changed && stale()) {
            break;
        }
        let pixels: Vec<u32> = if !m.holes.is_empty() {
            let n = chunk.min(m.holes.len());
            m.holes.drain(..n).collect()
        } else {
            m.cache.next_pixels(chunk)
        };
        rays = rays + m.cache.trace(&t, cam, &pixels);
        traced += pixels.len() as u64;
    }
    m.fresh += traced;
    let seconds = start.elapsed().as_secs_f64();
    if let Ok(mut s) = shared.stats.lock() {
        s.moving_time.reproject += reprojected;
        s.moving_time.trace += seconds - reprojected;
        s.moving_samples += traced;
        if seconds > 0.0 && traced > 0 {
            s.mrays_per_s = rays.total() as f64 / seconds / 1e6;
        }
    }
    if content_stale() {
        return;
    }
    let pictured = Instant::now();
    let work = m.cache.take_work();
    let (rgba, heat) = if job.settings.mode == RenderMode::Work {
        work_heatmap(&work, m.cache.tiles(), size, &job.settings)
    } else {
        (m.cache.to_rgba8(job.settings.moving_filter), (0.0, 0.0))
    };
    let holes = (size.x as u64 * size.y as u64).saturating_sub(m.cache.filled() as u64);
    let picture = Picture {
        rgba: to_display(rgba, size, job),
        width: job.display.x,
        height: job.display.y,
        samples: 0,
        moving: true,
        fresh: m.fresh,
        holes,
        heat,
        ..Picture::default()
    };
    if let Ok(mut s) = shared.stats.lock() {
        s.moving_time.picture += pictured.elapsed().as_secs_f64();
    }
    let kept = shared
        .keep_moving_samples
        .load(Ordering::Relaxed)
        .then(|| m.cache.samples_copy());
    if publish(shared, job, picture) {
        if let Some(samples) = kept
            && let Ok(mut slot) = shared.moving_samples.lock()
        {
            if slot.len() == KEPT_MOVING {
                slot.pop_front();
            }
            slot.push_back((job.generation, samples));
        }
        m.fresh = 0;
        st.view_changed = false;
        st.reshow = false;
        st.last_shown = Some(Instant::now());
        if let Ok(mut s) = shared.stats.lock() {
            s.moving_pictures += 1;
        }
    }
}

/// The moving picture's cache for the job's content (the traced size among it), a new one if
/// the content or the exposure changed (the cache keeps its colours tone mapped).
fn moving_cache<'a>(moving: &'a mut Option<Moving>, job: &Job) -> &'a mut Moving {
    let exposure = job.settings.exposure;
    let size = (job.camera.width, job.camera.height);
    let keep = moving.as_ref().is_some_and(|m| {
        m.content == job.content
            && m.cache.exposure() == exposure
            && (m.cache.width(), m.cache.height()) == size
    });
    if !keep {
        *moving = None;
    }
    moving.get_or_insert_with(|| Moving {
        cache: RenderCache::new(size.0, size.1, exposure),
        view: job.camera,
        content: job.content.clone(),
        holes: Vec::new(),
        fresh: 0,
        seeded: false,
    })
}

/// Makes the moving picture's cache the still picture `rgba` (traced size, `samples` per
/// pixel) of the job's view: the camera rays' hits traced once per view, the colours replaced
/// as the picture refines. A newer job stops the seeding (the cache stays as it was).
fn seed_moving(st: &mut State, job: &Job, shared: &Shared, rgba: &[u8], samples: u32) {
    let cam = &job.camera;
    let m = moving_cache(&mut st.moving, job);
    if m.seeded && same_view(&m.view, cam) {
        m.cache.set_colours(rgba, samples);
        return;
    }
    let t = tracer(job, Some(1), lights_for(&mut st.lights, job));
    let stop = || shared.newest.load(Ordering::SeqCst) != job.generation;
    if m.cache.seed(&t, cam, rgba, samples, &stop) {
        m.view = *cam;
        m.holes.clear();
        m.seeded = true;
    }
}

/// The work view: samples per pixel each tile took since the last picture, as a heatmap.
fn work_heatmap(
    work: &[u32],
    (cols, _): (u32, u32),
    size: UVec2,
    settings: &ViewSettings,
) -> (Vec<u8>, (f32, f32)) {
    let tile_pixels = |t: usize| {
        let (tx, ty) = (t as u32 % cols, t as u32 / cols);
        let w = (size.x - tx * TILE).min(TILE);
        let h = (size.y - ty * TILE).min(TILE);
        (w * h).max(1) as f32
    };
    let per_pixel: Vec<f32> = work
        .iter()
        .enumerate()
        .map(|(t, &n)| n as f32 / tile_pixels(t))
        .collect();
    let sums: Vec<Vec3> = (0..size.x * size.y)
        .map(|i| {
            let (x, y) = (i % size.x, i / size.x);
            Vec3::splat(per_pixel[((y / TILE) * cols + x / TILE) as usize])
        })
        .collect();
    let mean = per_pixel.iter().sum::<f32>() / per_pixel.len().max(1) as f32;
    let max = per_pixel.iter().copied().fold(0.0f32, f32::max);
    let top = if settings.heat_max > 0.0 {
        settings.heat_max
    } else {
        max.max(1e-6)
    };
    (heatmap_rgba8(&sums, top), (mean, top))
}

/// One slice of the still picture: start it over if needed, trace passes for a while, publish
/// now and then, stop at the sample limit.
fn still_step(st: &mut State, job: &Job, shared: &Shared, stale: &(dyn Fn() -> bool + Sync)) {
    let cam = &job.camera;
    let size = UVec2::new(cam.width, cam.height);
    let restarted = st.still.is_none();
    let film = st
        .still
        .get_or_insert_with(|| Progressive::new(size.x, size.y));
    if restarted {
        st.still_start = Instant::now();
        st.denoise.reset();
        if let Ok(mut s) = shared.stats.lock() {
            s.passes = 0;
            s.still_rays = RayCounts::default();
            s.still_seconds = 0.0;
            s.still_wall = 0.0;
            s.denoise = DenoiseStats {
                error: s.denoise.error.take(),
                ..DenoiseStats::default()
            };
        }
        if let Ok(mut p) = shared.probe.lock() {
            *p = DenoiseProbe::default();
        }
    }
    let traced = matches!(job.settings.mode, RenderMode::Shaded | RenderMode::Work);
    let target = if traced {
        job.settings.max_samples.max(1)
    } else {
        1
    };
    let mut completed = false;
    if film.passes() < target {
        let t = tracer(job, None, lights_for(&mut st.lights, job));
        let r = step_mode(
            film,
            &job.settings,
            &t,
            &job.bvh,
            cam,
            STILL_SLICE,
            target,
            stale,
        );
        if stale() {
            return;
        }
        completed = r.passes_completed > 0;
        if let Ok(mut s) = shared.stats.lock() {
            s.passes = film.passes();
            s.still_rays = film.rays;
            s.still_seconds += r.seconds;
            s.still_wall = st.still_start.elapsed().as_secs_f64();
            if r.seconds > 0.0 {
                s.mrays_per_s = r.rays.total() as f64 / r.seconds / 1e6;
            }
        }
    }
    let finished = film.passes() >= target;
    plain_for_probe(st.still_start, shared, film, job);
    let since = st.last_shown.map(|t| t.elapsed());
    let doubled = completed && film.passes().is_power_of_two();
    let due = match since {
        None => true,
        Some(t) => (completed && t >= STILL_REFRESH) || t >= STILL_PARTIAL,
    };
    // The moving picture stays up until the still one has a complete pass.
    let mut show = film.passes() >= 1 && (doubled || st.reshow || due || finished && completed);
    // Denoised: a new picture when one is due, the last one again when only the tone mapping
    // changed, and otherwise the last one stays up (see `still_denoise`).
    let denoising = job.settings.denoise
        && job.settings.mode == RenderMode::Shaded
        && st.denoise.error().is_none();
    let mut denoised: Option<Vec<u8>> = None;
    if denoising && show {
        let fresh = st.denoise.due(finished && completed, doubled);
        if fresh {
            let t = tracer(job, None, lights_for(&mut st.lights, job));
            let start = Instant::now();
            let made = st
                .denoise
                .run(film, &t, cam, (job.settings.sampler, job.settings.seed))
                .map(|p| p.to_vec());
            let took = start.elapsed().as_secs_f64();
            if stale() {
                return;
            }
            if let Ok(mut s) = shared.stats.lock() {
                match &made {
                    Ok(_) => {
                        s.denoise.pictures += 1;
                        s.denoise.passes = film.passes();
                        s.denoise.seconds += took;
                    }
                    Err(e) => s.denoise.error = Some(e.clone()),
                }
            }
        }
        match st.denoise.picture() {
            Some((p, _)) if fresh || st.reshow => {
                let mut rgba = vec![0u8; p.len() * 4];
                crate::film::encode_rgba8(p, job.settings.exposure, &mut rgba);
                denoised = Some(rgba);
            }
            // The last denoised picture stays up.
            Some(_) => show = st.reshow,
            None => {}
        }
    }
    if show {
        let (rgba, heat) = if job.settings.mode == RenderMode::Work {
            // Every pixel took the same samples.
            let cols = size.x.div_ceil(TILE);
            let tiles = (cols * size.y.div_ceil(TILE)) as usize;
            let per_tile: Vec<u32> = (0..tiles)
                .map(|t| {
                    let (tx, ty) = (t as u32 % cols, t as u32 / cols);
                    (size.x - tx * TILE).min(TILE) * (size.y - ty * TILE).min(TILE)
                })
                .collect();
            work_heatmap(&per_tile, (cols, 0), size, &job.settings)
        } else {
            picture_of(film, &job.settings)
        };
        let passes = film.passes();
        if let Ok(mut slot) = shared.still.lock() {
            match slot.as_mut() {
                Some(kept) => kept.clone_from(film),
                None => *slot = Some(film.clone()),
            }
        }
        // Once the still picture is done (the worker would wait), or refining for a second
        // already (a seed costs a tenth of that), it seeds the moving picture.
        let long = st.still_start.elapsed() >= SEED_AFTER;
        if completed && (finished || long) && job.settings.mode == RenderMode::Shaded {
            seed_moving(st, job, shared, &rgba, passes);
        }
        let was_denoised = denoised.is_some();
        let shown = denoised.unwrap_or(rgba);
        keep_for_probe(st.still_start, shared, &shown, was_denoised);
        let rgba = to_display(shown, size, job);
        let picture = Picture {
            rgba,
            width: job.display.x,
            height: job.display.y,
            samples: passes,
            moving: false,
            heat,
            denoised: was_denoised,
            ..Picture::default()
        };
        if publish(shared, job, picture) {
            st.last_shown = Some(Instant::now());
            st.reshow = false;
            st.view_changed = false;
            if was_denoised
                && let Ok(mut s) = shared.stats.lock()
                && s.denoise.first_after.is_none()
            {
                s.denoise.first_after = Some(st.still_start.elapsed().as_secs_f64());
            }
        }
    }
    if finished && !st.reshow {
        st.done = true;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn picture(generation: u64) -> Picture {
        Picture {
            generation,
            rgba: Vec::new(),
            width: 0,
            height: 0,
            samples: 1,
            moving: false,
            fresh: 0,
            holes: 0,
            heat: (0.0, 0.0),
            denoised: false,
        }
    }

    /// Jobs 3 to 5 differ only in their view (job 5 the newest sent): their pictures may be
    /// shown, none of job 2 or earlier, none of a job not yet sent.
    fn slot(waiting: Option<u64>) -> Slot {
        Slot {
            newest: 5,
            newest_key: None,
            view_run_from: 3,
            picture: waiting.map(picture),
        }
    }

    #[test]
    fn an_empty_slot_takes_pictures_of_the_current_run_of_views() {
        let s = slot(None);
        assert!(
            !s.accepts(2),
            "a job before the run (other content or settings)"
        );
        assert!(s.accepts(3) && s.accepts(4) && s.accepts(5));
        assert!(!s.accepts(6), "a job not yet sent");
    }

    #[test]
    fn a_later_picture_of_the_waiting_job_replaces_it_and_an_older_job_never_does() {
        // The still picture's passes come one after another for one job: the later pass must
        // replace the one the app has not taken yet, or the last pass is lost.
        let s = slot(Some(5));
        assert!(s.accepts(5), "a later pass of the waiting picture's job");
        assert!(
            !s.accepts(4),
            "an older job's picture over a newer one waiting"
        );
        let s = slot(Some(4));
        assert!(s.accepts(4) && s.accepts(5));
        assert!(!s.accepts(3));
    }
}
