//! The still picture of the trace worker: passes traced in slices up to the sample limit,
//! published now and then, denoised as the passes double.

use super::*;

/// Keeps the still picture's first denoised picture for the `--orbit` report.
pub(super) fn keep_for_probe(still_start: Instant, shared: &Shared, rgba: &[u8], denoised: bool) {
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
pub(super) fn plain_for_probe(
    still_start: Instant,
    shared: &Shared,
    film: &Progressive,
    job: &Job,
) {
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

/// The work view: samples per pixel each tile took since the last picture, as a heatmap.
pub(super) fn work_heatmap(
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
pub(super) fn still_step(
    st: &mut State,
    job: &Job,
    shared: &Shared,
    stale: &(dyn Fn() -> bool + Sync),
) {
    let mut film = match st.still.take() {
        Some(film) => film,
        None => {
            restart_still(st, shared);
            Progressive::new(job.camera.width, job.camera.height)
        }
    };
    still_slice(st, &mut film, job, shared, stale);
    st.still = Some(film);
}

/// A still picture starts over: its clock, its denoiser and the figures it reports.
pub(super) fn restart_still(st: &mut State, shared: &Shared) {
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

/// [`still_step`] on the still picture's film (taken out of the state meanwhile).
pub(super) fn still_slice(
    st: &mut State,
    film: &mut Progressive,
    job: &Job,
    shared: &Shared,
    stale: &(dyn Fn() -> bool + Sync),
) {
    let traced = matches!(job.settings.mode, RenderMode::Shaded | RenderMode::Work);
    let target = if traced {
        job.settings.max_samples.max(1)
    } else {
        1
    };
    let Some(completed) = trace_still(st, film, job, shared, target, stale) else {
        return;
    };
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
    let mut denoised = None;
    if denoising && show {
        match denoise_still(
            st,
            film,
            job,
            shared,
            (finished, completed, doubled),
            &mut show,
            stale,
        ) {
            Some(picture) => denoised = picture,
            None => return,
        }
    }
    if show {
        publish_still(st, film, job, shared, (completed, finished), denoised);
    }
    if finished && !st.reshow {
        st.done = true;
    }
}

/// Traces the still picture for a slice, up to `target` passes: whether a pass was completed,
/// `None` when the view went stale meanwhile.
pub(super) fn trace_still(
    st: &mut State,
    film: &mut Progressive,
    job: &Job,
    shared: &Shared,
    target: u32,
    stale: &(dyn Fn() -> bool + Sync),
) -> Option<bool> {
    if film.passes() >= target {
        return Some(false);
    }
    let cam = &job.camera;
    let t = tracer(job, None, lights_for(&mut st.lights, job));
    let r = step_mode(
        film,
        &job.settings,
        &t,
        job.tree(),
        cam,
        STILL_SLICE,
        target,
        stale,
    );
    if stale() {
        return None;
    }
    if let Ok(mut s) = shared.stats.lock() {
        s.passes = film.passes();
        s.still_rays = film.rays;
        s.still_seconds += r.seconds;
        s.still_wall = st.still_start.elapsed().as_secs_f64();
        if r.seconds > 0.0 {
            s.mrays_per_s = r.rays.total() as f64 / r.seconds / 1e6;
        }
    }
    Some(r.passes_completed > 0)
}

/// The denoised picture to show, if one is (`Some(None)`: none new, `*show` cleared where the
/// last one stays up), or `None` when the view went stale while denoising. A new one is made
/// when one is due (`finished`, `completed` and `doubled` as `still_slice` found them).
pub(super) fn denoise_still(
    st: &mut State,
    film: &Progressive,
    job: &Job,
    shared: &Shared,
    (finished, completed, doubled): (bool, bool, bool),
    show: &mut bool,
    stale: &(dyn Fn() -> bool + Sync),
) -> Option<Option<Vec<u8>>> {
    let cam = &job.camera;
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
            return None;
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
            return Some(Some(rgba));
        }
        // The last denoised picture stays up.
        Some(_) => *show = st.reshow,
        None => {}
    }
    Some(None)
}

/// Publishes the still picture (the `denoised` one where given), seeds the moving picture
/// from it when it is done or has refined for a while, and keeps it for the report's probe.
pub(super) fn publish_still(
    st: &mut State,
    film: &Progressive,
    job: &Job,
    shared: &Shared,
    (completed, finished): (bool, bool),
    denoised: Option<Vec<u8>>,
) {
    let size = UVec2::new(job.camera.width, job.camera.height);
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
