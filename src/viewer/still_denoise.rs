//! The still picture denoised as it refines (the trace worker's part of
//! [`ViewSettings::denoise`](super::trace::ViewSettings::denoise)).
//!
//! When the still picture starts over, its render layers (albedo and normal, [`LAYER_SAMPLES`]
//! samples a pixel) are traced once; the picture is then denoised when its first pass is
//! complete, and again whenever its passes reach a power of two, as long as denoising takes at
//! most [`SHARE`] of the time since the last one (a scene whose passes come fast is not
//! denoised at every doubling). The last picture, at the sample limit, is always denoised.
//! Between denoised pictures the window keeps showing the last one. With passes doubling, the
//! 1024 passes of the default limit are denoised about ten times: on the 202k dragon at
//! 950x720, 0.5 s each against about two minutes of tracing.

use std::time::{Duration, Instant};

use glam::Vec3;

use crate::camera::CameraRays;
use crate::denoise::{Denoiser, Inputs};
use crate::render::aov::AovFilm;
use crate::render::{Progressive, SampleRange, Tracer};

/// Samples a pixel of the render layers that guide the denoiser (edges anti-aliased; more
/// would take longer before the first denoised picture than they improve it).
pub const LAYER_SAMPLES: u32 = 2;

/// Largest share of the worker's time that denoising takes while the picture refines.
pub const SHARE: f64 = 0.1;

/// The denoising state of one still picture.
#[derive(Default)]
pub struct StillDenoise {
    /// The denoiser, made on first use (its error, once, where it cannot start).
    denoiser: Option<Result<Denoiser, String>>,
    /// The render layers of the current still picture.
    layers: Option<AovFilm>,
    /// The last denoised picture (linear radiance) and the passes it was made from.
    picture: Option<(Vec<Vec3>, u32)>,
    /// When the last denoise ended, and how long it took.
    last: Option<(Instant, Duration)>,
}

impl StillDenoise {
    /// Forgets the picture and its layers (the still picture started over).
    pub fn reset(&mut self) {
        self.layers = None;
        self.picture = None;
        self.last = None;
    }

    /// Why the denoiser cannot run, once it was asked to.
    pub fn error(&self) -> Option<&str> {
        match &self.denoiser {
            Some(Err(e)) => Some(e),
            _ => None,
        }
    }

    /// The last denoised picture and the passes behind it.
    pub fn picture(&self) -> Option<(&[Vec3], u32)> {
        self.picture.as_ref().map(|(p, n)| (p.as_slice(), *n))
    }

    /// True when a new denoised picture is worth making now: none yet, the last picture of
    /// the still (`finished`), or the passes just `doubled` and the last denoise took at most
    /// [`SHARE`] of the time since.
    pub fn due(&self, finished: bool, doubled: bool) -> bool {
        match self.last {
            None => true,
            Some(_) if finished => true,
            Some((end, took)) => {
                doubled && took.as_secs_f64() <= SHARE * end.elapsed().as_secs_f64()
            }
        }
    }

    /// Denoises `film`, tracing its layers first if this still picture has none yet; the
    /// error says why it could not (then the caller shows the picture as traced).
    pub fn run(
        &mut self,
        film: &Progressive,
        tracer: &Tracer,
        cam: &CameraRays,
        samples: (crate::sampling::SamplerKind, u64),
    ) -> Result<&[Vec3], String> {
        let start = Instant::now();
        if self.denoiser.is_none() {
            self.denoiser = Some(Denoiser::new().map_err(|e| format!("{e:#}")));
        }
        let denoiser = match self.denoiser.as_ref() {
            Some(Ok(d)) => d,
            Some(Err(e)) => return Err(e.clone()),
            None => unreachable!("made above"),
        };
        let layers = self.layers.get_or_insert_with(|| {
            let mut l = AovFilm::new(film.width(), film.height());
            let range = SampleRange {
                sampler: samples.0,
                seed: samples.1,
                first: 0,
                count: LAYER_SAMPLES,
            };
            l.add(tracer, cam, &range);
            l
        });
        let (albedo, normal) = (layers.albedo_mean(), layers.normal_mean());
        let color = film.mean();
        let clean = denoiser
            .run(&Inputs {
                width: film.width(),
                height: film.height(),
                color: &color,
                albedo: Some(&albedo),
                normal: Some(&normal),
            })
            .map_err(|e| format!("{e:#}"))?;
        self.last = Some((Instant::now(), start.elapsed()));
        self.picture = Some((clean, film.passes()));
        Ok(&self.picture.as_ref().expect("just made").0)
    }
}
