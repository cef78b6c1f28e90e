//! Progressive rendering: an image refined pass by pass (one sample per pixel each), traced
//! in batches of rows within a time budget, so an interactive caller can trace a little every
//! frame and show the picture as it improves.
//!
//! Pass `p` takes sample `p` of every pixel's stream ([`SampleRange`]), so after `n` complete
//! passes the sums equal those of a one-shot [`super::render`] with `n` samples per pixel.
//!
//! Passes are traced in rounds: the first pass alone (a first picture soon), then rounds that
//! take each row up to four times its samples, at most [`MAX_ROUND`] passes at once. A row
//! takes a round's samples one after the other, tile by tile, as the one-shot render takes all
//! of a pixel's samples: the tile's part of the tree stays in cache between them, where a
//! sweep of the whole image per pass has to fetch it again (one pass at a time traced 3-9%
//! fewer rays per second than the one-shot render, same rays). A round under way is always
//! completed (its rows must agree in samples), so if `max_passes` drops during one, the passes
//! end past it by what is left of that round.
//!
//! A round is not cut to fit the caller's time budget: a batch of rows may take longer than
//! the budget, and a caller that must stop at once (the viewer, when the view changes) passes
//! a `cancel` check that the tracing reads before every sample of every tile. A cancelled
//! batch leaves the image as it was: its rows are traced into a copy, written back only when
//! every one of them is done.

use std::time::{Duration, Instant};

use glam::Vec3;
use rayon::prelude::*;

use super::{BAND, RayCounts, SampleRange, Tracer, trace_rows_until};
use crate::camera::CameraRays;
use crate::film::{Film, Sum, encode_rgba8};
use crate::sampling::SamplerKind;

/// Most passes one round traces (see the module docs): long enough rounds that a tile's
/// samples keep its part of the tree in cache as the one-shot render does, and short enough
/// that a refining picture shows progress.
pub const MAX_ROUND: u32 = 64;

/// An image being refined pass by pass.
#[derive(Debug)]
pub struct Progressive {
    width: u32,
    height: u32,
    sum: Vec<Sum>,
    /// Samples taken in each row: `passes + round` for rows of the current round already
    /// traced.
    row_samples: Vec<u32>,
    /// First row of the current round not yet traced.
    next_row: u32,
    passes: u32,
    /// Passes the current round adds (1 to [`MAX_ROUND`]).
    round: u32,
    /// Estimated wall time of one sample of one row, from the batches traced so far.
    row_seconds: Option<f64>,
    /// Rays traced since the last reset.
    pub rays: RayCounts,
    /// Non-finite samples left out since the last reset.
    pub rejected: u64,
}

impl Clone for Progressive {
    fn clone(&self) -> Self {
        let mut c = Self::new(0, 0);
        c.clone_from(self);
        c
    }

    /// Reuses this image's buffers (the viewer keeps a copy of each still picture it shows:
    /// a fresh 8 MB buffer would be faulted in page by page while the tracing waits).
    fn clone_from(&mut self, source: &Self) {
        self.width = source.width;
        self.height = source.height;
        self.sum.clone_from(&source.sum);
        self.row_samples.clone_from(&source.row_samples);
        self.next_row = source.next_row;
        self.passes = source.passes;
        self.round = source.round;
        self.row_seconds = source.row_seconds;
        self.rays = source.rays;
        self.rejected = source.rejected;
    }
}

/// What one call of [`Progressive::step`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepReport {
    /// Rows traced.
    pub rows: u32,
    /// Passes completed during the call.
    pub passes_completed: u32,
    /// Rays traced.
    pub rays: RayCounts,
    /// Wall time spent.
    pub seconds: f64,
    /// True when `cancel` stopped the last batch (its work was dropped).
    pub cancelled: bool,
}

impl Progressive {
    /// A black image of `width x height` with no samples.
    pub fn new(width: u32, height: u32) -> Self {
        let n = width as usize * height as usize;
        Self {
            width,
            height,
            sum: vec![Sum::ZERO; n],
            row_samples: vec![0; height as usize],
            next_row: 0,
            passes: 0,
            round: 1,
            row_seconds: None,
            rays: RayCounts::default(),
            rejected: 0,
        }
    }

    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Passes completed: every pixel has at least this many samples.
    pub fn passes(&self) -> u32 {
        self.passes
    }

    /// True when no pass is part-way done (every pixel has [`Progressive::passes`] samples).
    pub fn is_between_passes(&self) -> bool {
        self.next_row == 0
    }

    /// Forgets every sample (the camera, scene or settings changed). Keeps the row-time
    /// estimate, which still describes the scene well enough to plan the next batch.
    pub fn reset(&mut self) {
        self.sum.fill(Sum::ZERO);
        self.row_samples.fill(0);
        self.next_row = 0;
        self.passes = 0;
        self.round = 1;
        self.rays = RayCounts::default();
        self.rejected = 0;
    }

    /// Traces rows of the current round (and the rounds after it) with `rows` until `budget`
    /// is spent or `max_passes` passes are complete; always traces at least one batch when a
    /// pass is left to do, so progress never stalls. `rows(y0, samples, sums)` adds the
    /// samples `samples.0..samples.0 + samples.1` of every pixel of the rows from `y0` to
    /// `sums` (whole rows, at most [`BAND`] of them), each pixel's in order, and returns the
    /// rays it traced and the number of non-finite samples it left out, or `None` when it
    /// was cancelled (the step then stops, its last batch dropped). Bands of rows are traced
    /// in parallel on the rayon pool.
    pub fn step(
        &mut self,
        budget: Duration,
        max_passes: u32,
        rows: impl Fn(u32, (u32, u32), &mut [Sum]) -> Option<(RayCounts, u64)> + Sync,
    ) -> StepReport {
        let start = Instant::now();
        let mut report = StepReport::default();
        let w = self.width as usize;
        if w == 0 || self.height == 0 {
            return report;
        }
        let threads = rayon::current_num_threads().max(1) as u32;
        while self.passes < max_passes {
            let left = budget.as_secs_f64() - start.elapsed().as_secs_f64();
            if report.rows > 0 && left <= 0.0 {
                break;
            }
            if self.next_row == 0 {
                self.round = self.next_round(max_passes);
            }
            // Bands of rows that fit in what is left of the budget, in whole rounds of the
            // pool (`next_row` stays a multiple of the band until the round's last band).
            let band_seconds = self.row_seconds.map(|s| s * (BAND * self.round) as f64);
            let fit = BAND
                * match band_seconds {
                    Some(s) if s > 0.0 => ((left.max(0.0) / s) as u32 / threads).max(1) * threads,
                    _ => threads,
                };
            let first = self.next_row;
            let count = fit.min(self.height - first);
            let samples = (self.passes, self.round);
            let t0 = Instant::now();
            let span = &mut self.sum[first as usize * w..(first + count) as usize * w];
            // Traced into a copy (a memory copy, next to nothing beside the tracing), so that
            // a cancelled batch leaves the rows as they were.
            let mut batch = span.to_vec();
            let done: Option<Vec<(RayCounts, u64)>> = batch
                .par_chunks_mut(w * BAND as usize)
                .enumerate()
                .map(|(i, sums)| rows(first + i as u32 * BAND, samples, sums))
                .collect();
            let Some(done) = done else {
                report.cancelled = true;
                break;
            };
            span.copy_from_slice(&batch);
            let (rays, rejected) = done
                .into_iter()
                .fold((RayCounts::default(), 0), |a, b| (a.0 + b.0, a.1 + b.1));
            let per_row = t0.elapsed().as_secs_f64() / (count * self.round) as f64;
            self.row_seconds = Some(match self.row_seconds {
                Some(old) => 0.5 * old + 0.5 * per_row,
                None => per_row,
            });
            for s in &mut self.row_samples[first as usize..(first + count) as usize] {
                *s += self.round;
            }
            self.rays = self.rays + rays;
            self.rejected += rejected;
            report.rays = report.rays + rays;
            report.rows += count;
            self.next_row += count;
            if self.next_row == self.height {
                self.next_row = 0;
                self.passes += self.round;
                report.passes_completed += self.round;
            }
        }
        report.seconds = start.elapsed().as_secs_f64();
        report
    }

    /// Passes of the next round: the first pass alone, then up to three times the samples so
    /// far (the passes reach 1, 4, 16, 64), at most [`MAX_ROUND`] and no more than
    /// `max_passes` asks for.
    fn next_round(&self, max_passes: u32) -> u32 {
        let left = max_passes.saturating_sub(self.passes).max(1);
        (3 * self.passes).clamp(1, MAX_ROUND).min(left)
    }

    /// [`Progressive::step`] tracing the shaded image of `tracer` through `cam` (which must be
    /// framed for this image's size).
    pub fn step_shaded(
        &mut self,
        tracer: &Tracer,
        cam: &CameraRays,
        sampler: SamplerKind,
        seed: u64,
        budget: Duration,
        max_passes: u32,
    ) -> StepReport {
        self.step_shaded_until(tracer, cam, (sampler, seed), budget, max_passes, &|| false)
    }

    /// [`Progressive::step_shaded`] that stops as soon as `cancel` returns true, dropping
    /// its last batch ([`StepReport::cancelled`]).
    pub fn step_shaded_until(
        &mut self,
        tracer: &Tracer,
        cam: &CameraRays,
        (sampler, seed): (SamplerKind, u64),
        budget: Duration,
        max_passes: u32,
        cancel: &(dyn Fn() -> bool + Sync),
    ) -> StepReport {
        self.step(budget, max_passes, |y, (first, count), sums| {
            let samples = SampleRange {
                sampler,
                seed,
                first,
                count,
            };
            trace_rows_until(tracer, cam, &samples, y, sums, cancel)
        })
    }

    /// Tone maps (after `exposure`) and encodes sRGB to RGBA8, each row by its own sample
    /// count; rows without samples are black.
    pub fn to_rgba8(&self, exposure: f32) -> Vec<u8> {
        let w = self.width as usize;
        let mut out = vec![0u8; self.sum.len() * 4];
        if w == 0 {
            return out;
        }
        // Rows are encoded in runs of equal sample counts (at most two runs per image); rows
        // without samples get k = 0: black.
        let mut y = 0usize;
        while y < self.row_samples.len() {
            let n = self.row_samples[y];
            let end = y + self.row_samples[y..]
                .iter()
                .take_while(|&&m| m == n)
                .count();
            let k = if n == 0 { 0.0 } else { exposure / n as f32 };
            encode_rgba8(
                &self.sum[y * w..end * w],
                k,
                &mut out[y * w * 4..end * w * 4],
            );
            y = end;
        }
        out
    }

    /// The sums of the complete passes as a [`Film`]; `None` while a pass is part-way done
    /// (rows would hold different sample counts).
    pub fn to_film(&self) -> Option<Film> {
        if !self.is_between_passes() {
            return None;
        }
        Some(Film {
            width: self.width,
            height: self.height,
            sum: self.sum.clone(),
            samples: self.passes,
            rejected: self.rejected,
        })
    }

    /// Mean radiance of each pixel, each row by its own sample count (black where a row has
    /// none yet).
    pub fn mean(&self) -> Vec<Vec3> {
        let w = self.width as usize;
        let mut out = Vec::with_capacity(self.sum.len());
        for (row, &n) in self.sum.chunks(w.max(1)).zip(&self.row_samples) {
            let k = if n == 0 { 0.0 } else { 1.0 / n as f32 };
            out.extend(row.iter().map(|s| s.to_vec3() * k));
        }
        out
    }

    /// The raw per-pixel sums (row 0 at the top).
    pub fn sums(&self) -> &[Sum] {
        &self.sum
    }
}
