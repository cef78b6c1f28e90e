//! The moving picture of the trace worker: the render cache carried to each new view, traced
//! where it has holes and then by priority, and seeded from the still picture.

use super::*;

/// One step of the moving picture: carry the cache to this view (once per view), trace the
/// pixels no sample reached, then fresh pixels by tile priority, until the picture is due;
/// publish. A newer job stops the tracing (the samples stay in the cache for the next view).
pub(super) fn moving_step(st: &mut State, job: &Job, shared: &Shared, stale: &dyn Fn() -> bool) {
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
pub(super) fn moving_cache<'a>(moving: &'a mut Option<Moving>, job: &Job) -> &'a mut Moving {
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
pub(super) fn seed_moving(st: &mut State, job: &Job, shared: &Shared, rgba: &[u8], samples: u32) {
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
