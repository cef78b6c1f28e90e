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
use crate::render::light::LightSet;
use crate::render::resample::{Filter, resize_rgba8};
use crate::render::{EnvironmentMap, Progressive, RayCounts, RenderPlan, Tracer};
use crate::scene::Scene;

mod moving;
mod still;

use moving::*;
use still::*;

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
    /// The tree of its own triangles.
    pub bvh: Arc<Bvh>,
    /// The two levels of a scene that places meshes many times (`bvh` one of their trees).
    pub placed: Option<Arc<crate::bvh::TwoLevel>>,
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

impl Job {
    /// What the job's rays are traced through.
    pub fn tree(&self) -> crate::bvh::Tree<'_> {
        match &self.placed {
            Some(t) => crate::bvh::Tree::TwoLevel(t),
            None => crate::bvh::Tree::Flat(&self.bvh),
        }
    }
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
    Tracer::with_lights(&job.scene, job.tree(), plan, max_depth, &job.env, lights)
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
