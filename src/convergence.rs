//! Error against run time: renders a high-sample reference, then 1, 2, 4, ... samples per
//! pixel with several independent seeds per sampler, and measures RMSE and relMSE on linear
//! radiance against the reference, with the render time of each point (BVH build excluded).

use std::io::Write;
use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use glam::Vec3;

use crate::bvh::Bvh;
use crate::render::{EnvironmentMap, RenderPlan, RenderSettings, render_with_plan};
use crate::sampling::SamplerKind;
use crate::scene::Scene;

/// What to measure.
#[derive(Clone, Debug)]
pub struct ConvergenceConfig {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Largest samples per pixel (a power of two); points at 1, 2, 4, ... up to it.
    pub max_spp: u32,
    /// Independent seeds per point.
    pub seeds: u32,
    /// Samples per pixel of the reference (at least 64 times `max_spp`).
    pub reference_spp: u32,
    /// Samplers to compare.
    pub samplers: Vec<SamplerKind>,
    /// Error at which to compare the samplers' times; default: the first sampler's RMSE at
    /// `max_spp`.
    pub target_rmse: Option<f64>,
}

impl ConvergenceConfig {
    /// Checks the settings; the message says what is wrong.
    pub fn validate(&self) -> Result<()> {
        if !self.max_spp.is_power_of_two() || self.max_spp < 4 {
            bail!(
                "--max-spp must be a power of two of at least 4 (three points to fit a slope), got {}",
                self.max_spp
            );
        }
        if self.reference_spp < 64 * self.max_spp {
            bail!(
                "the reference needs at least 64 x {} = {} samples per pixel, got {}",
                self.max_spp,
                64 * self.max_spp,
                self.reference_spp
            );
        }
        if self.seeds == 0 || self.samplers.is_empty() || self.width == 0 || self.height == 0 {
            bail!("need at least one seed, one sampler and a non-empty image");
        }
        Ok(())
    }
}

/// One render of the experiment.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Point {
    /// Sampler used.
    pub sampler: SamplerKind,
    /// Samples per pixel.
    pub spp: u32,
    /// Seed.
    pub seed: u64,
    /// Render time in seconds.
    pub seconds: f64,
    /// Root mean squared error against the reference (linear radiance, all channels).
    pub rmse: f64,
    /// Mean of `(x - ref)^2 / (ref^2 + 0.01)`.
    pub relmse: f64,
}

/// A sampler's fitted convergence.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Fit {
    /// Sampler.
    pub sampler: SamplerKind,
    /// Slope of log RMSE against log spp (-0.5 for independent random samples).
    pub slope_spp: f64,
    /// Slope of log RMSE against log seconds.
    pub slope_time: f64,
    /// Seconds needed to reach the target RMSE, from the time fit.
    pub seconds_to_target: f64,
}

/// Everything measured.
#[derive(Clone, Debug)]
pub struct Report {
    /// Every render.
    pub points: Vec<Point>,
    /// Per sampler, means over seeds: `(sampler, spp, seconds, rmse, relmse)`.
    pub means: Vec<(SamplerKind, u32, f64, f64, f64)>,
    /// Per sampler fits.
    pub fits: Vec<Fit>,
    /// The error the samplers' times are compared at.
    pub target_rmse: f64,
    /// Reference render time in seconds.
    pub reference_seconds: f64,
}

/// Runs the experiment. `progress(done, total)` counts renders.
pub fn run(
    scene: &Scene,
    bvh: &Bvh,
    config: &ConvergenceConfig,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Report> {
    config.validate()?;
    let base = RenderSettings {
        width: config.width,
        height: config.height,
        ..RenderSettings::default()
    };
    let plan = RenderPlan::new(scene, &base);
    let env = EnvironmentMap::load(&scene.environment, plan.environment)?;
    let render = |spp: u32, seed: u64, sampler: SamplerKind| {
        let settings = RenderSettings {
            spp,
            seed,
            sampler,
            ..base.clone()
        };
        let start = Instant::now();
        let out = render_with_plan(scene, bvh, &env, &settings, plan, &|_| {});
        (out.film.mean(), start.elapsed().as_secs_f64())
    };
    let levels: Vec<u32> = (0..=config.max_spp.trailing_zeros())
        .map(|k| 1 << k)
        .collect();
    let total = 1 + levels.len() * config.seeds as usize * config.samplers.len();
    let mut done = 0;
    let (reference, reference_seconds) = render(config.reference_spp, 0xDEC0DE, SamplerKind::Sobol);
    done += 1;
    progress(done, total);

    let mut points = Vec::new();
    for &spp in &levels {
        for seed in 1..=config.seeds as u64 {
            // Samplers interleaved, so load elsewhere on the machine hits both alike.
            for &sampler in &config.samplers {
                let (img, seconds) = render(spp, seed, sampler);
                let (rmse, relmse) = errors(&img, &reference);
                points.push(Point {
                    sampler,
                    spp,
                    seed,
                    seconds,
                    rmse,
                    relmse,
                });
                done += 1;
                progress(done, total);
            }
        }
    }

    let mut means = Vec::new();
    for &sampler in &config.samplers {
        for &spp in &levels {
            let p: Vec<&Point> = points
                .iter()
                .filter(|p| p.sampler == sampler && p.spp == spp)
                .collect();
            let n = p.len() as f64;
            let mean = |f: fn(&Point) -> f64| p.iter().map(|x| f(x)).sum::<f64>() / n;
            means.push((
                sampler,
                spp,
                mean(|p| p.seconds),
                mean(|p| p.rmse),
                mean(|p| p.relmse),
            ));
        }
    }
    let target = config.target_rmse.unwrap_or_else(|| {
        means
            .iter()
            .find(|m| m.0 == config.samplers[0] && m.1 == config.max_spp)
            .map(|m| m.3)
            .unwrap_or(0.0)
    });
    let fits = config
        .samplers
        .iter()
        .map(|&sampler| {
            let m: Vec<_> = means.iter().filter(|m| m.0 == sampler).collect();
            let by_spp: Vec<(f64, f64)> = m.iter().map(|m| ((m.1 as f64).ln(), m.3.ln())).collect();
            let by_time: Vec<(f64, f64)> = m.iter().map(|m| (m.2.ln(), m.3.ln())).collect();
            let (slope_spp, _) = least_squares(&by_spp);
            let (slope_time, intercept) = least_squares(&by_time);
            Fit {
                sampler,
                slope_spp,
                slope_time,
                seconds_to_target: ((target.ln() - intercept) / slope_time).exp(),
            }
        })
        .collect();
    Ok(Report {
        points,
        means,
        fits,
        target_rmse: target,
        reference_seconds,
    })
}

/// RMSE and relMSE of `img` against `reference` over all pixels and channels.
pub fn errors(img: &[Vec3], reference: &[Vec3]) -> (f64, f64) {
    let mut se = 0.0f64;
    let mut rel = 0.0f64;
    for (a, r) in img.iter().zip(reference) {
        for c in 0..3 {
            let d = (a[c] - r[c]) as f64;
            se += d * d;
            rel += d * d / ((r[c] as f64).powi(2) + 0.01);
        }
    }
    let n = (img.len() * 3) as f64;
    ((se / n).sqrt(), rel / n)
}

/// Least-squares line through `(x, y)` points: `(slope, intercept)`.
pub fn least_squares(p: &[(f64, f64)]) -> (f64, f64) {
    let n = p.len() as f64;
    let (sx, sy) = p.iter().fold((0.0, 0.0), |a, q| (a.0 + q.0, a.1 + q.1));
    let (mx, my) = (sx / n, sy / n);
    let (sxy, sxx) = p.iter().fold((0.0, 0.0), |a, q| {
        (a.0 + (q.0 - mx) * (q.1 - my), a.1 + (q.0 - mx).powi(2))
    });
    let slope = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    (slope, my - slope * mx)
}

/// Writes every render as CSV: sampler, spp, seed, seconds, rmse, relmse.
pub fn write_csv(path: &Path, report: &Report) -> Result<()> {
    let mut f = std::io::BufWriter::new(
        std::fs::File::create(path)
            .with_context(|| format!("{}: cannot create", path.display()))?,
    );
    writeln!(f, "sampler,spp,seed,seconds,rmse,relmse")?;
    for p in &report.points {
        writeln!(
            f,
            "{},{},{},{:.6},{:.8},{:.8}",
            p.sampler, p.spp, p.seed, p.seconds, p.rmse, p.relmse
        )?;
    }
    f.flush()
        .with_context(|| format!("{}: cannot write", path.display()))
}

/// Draws RMSE against render time, log-log, one line per sampler with its fitted slope, and
/// the target error with each sampler's time to reach it.
pub fn plot(path: &Path, report: &Report, title: &str) -> Result<()> {
    use plotters::prelude::*;
    crate::plot_font::ensure()?;
    let means = &report.means;
    let (tmin, tmax) = means
        .iter()
        .fold((f64::MAX, f64::MIN), |a, m| (a.0.min(m.2), a.1.max(m.2)));
    let (emin, emax) = means
        .iter()
        .fold((f64::MAX, f64::MIN), |a, m| (a.0.min(m.3), a.1.max(m.3)));
    let root = BitMapBackend::new(path, (900, 600)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| anyhow::anyhow!("{e}"))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 24))
        .margin(16)
        .x_label_area_size(48)
        .y_label_area_size(72)
        .build_cartesian_2d(
            (tmin * 0.7..tmax * 1.4).log_scale(),
            (emin * 0.7..emax * 1.4).log_scale(),
        )
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    chart
        .configure_mesh()
        .x_desc("render time (s), BVH build excluded")
        .y_desc("RMSE against the reference (linear radiance)")
        .label_style(("sans-serif", 15))
        .draw()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let colours = [RED, BLUE, GREEN, MAGENTA];
    for (k, fit) in report.fits.iter().enumerate() {
        let c = colours[k % colours.len()];
        let pts: Vec<(f64, f64)> = means
            .iter()
            .filter(|m| m.0 == fit.sampler)
            .map(|m| (m.2, m.3))
            .collect();
        chart
            .draw_series(LineSeries::new(pts.clone(), c.stroke_width(2)))
            .map_err(|e| anyhow::anyhow!("{e}"))?
            .label(format!(
                "{}: slope {:.2} per spp, {:.2} per second; {:.3} s to RMSE {:.4}",
                fit.sampler,
                fit.slope_spp,
                fit.slope_time,
                fit.seconds_to_target,
                report.target_rmse
            ))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
        chart
            .draw_series(pts.iter().map(|&p| Circle::new(p, 4, c.filled())))
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        chart
            .draw_series(std::iter::once(Cross::new(
                (fit.seconds_to_target, report.target_rmse),
                8,
                c.stroke_width(2),
            )))
            .map_err(|e| anyhow::anyhow!("{e}"))?;
    }
    chart
        .draw_series(LineSeries::new(
            vec![
                (tmin * 0.7, report.target_rmse),
                (tmax * 1.4, report.target_rmse),
            ],
            BLACK.mix(0.4),
        ))
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    chart
        .configure_series_labels()
        .border_style(BLACK)
        .background_style(WHITE.mix(0.9))
        .label_font(("sans-serif", 15))
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    root.present()
        .with_context(|| format!("{}: cannot write plot", path.display()))
}
