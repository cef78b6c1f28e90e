//! Error against run time: renders a high-sample reference (or takes one rendered elsewhere,
//! an EXR of another renderer), then 1, 2, 4, ... samples per pixel with several independent
//! seeds per sampler, and measures RMSE and relMSE on linear radiance against the reference,
//! with the render time of each point (BVH build excluded). A peer's measurements of the same
//! picture (a CSV of `spp,seconds,rmse`) are drawn beside them, and the time each takes to reach
//! a given error is read off the measured points.

use std::io::Write;
use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use glam::Vec3;

use crate::bvh::Bvh;
use crate::denoise::{Denoiser, Inputs};
use crate::render::{EnvironmentMap, RenderPlan, RenderSettings, render_layers, render_with_plan};
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
    /// Samples per pixel of the reference (at least 64 times `max_spp`; unused when the
    /// reference is given).
    pub reference_spp: u32,
    /// Largest number of bounces after the camera's hit.
    pub max_depth: u32,
    /// Samplers to compare.
    pub samplers: Vec<SamplerKind>,
    /// Error at which to compare the samplers' times; default: the first sampler's RMSE at
    /// `max_spp`.
    pub target_rmse: Option<f64>,
    /// Also denoise each render of the first sampler ([`crate::denoise`], guided by render
    /// layers of the same samples) and measure it as a series of its own, timed with its
    /// layers and the denoising.
    pub denoise: bool,
}

impl ConvergenceConfig {
    /// Checks the settings; the message says what is wrong.
    pub fn validate(&self, external_reference: bool) -> Result<()> {
        if !self.max_spp.is_power_of_two() || self.max_spp < 4 {
            bail!(
                "--max-spp must be a power of two of at least 4 (three points to fit a slope), got {}",
                self.max_spp
            );
        }
        if !external_reference && self.reference_spp < 64 * self.max_spp {
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
    /// True for the render denoised (its time includes the layers and the denoising).
    pub denoised: bool,
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
    /// The first sampler's renders denoised, means over seeds: `(spp, seconds, rmse,
    /// relmse)` (empty unless asked for).
    pub denoised: Vec<(u32, f64, f64, f64)>,
    /// The error the samplers' times are compared at.
    pub target_rmse: f64,
    /// Reference render time in seconds (0 when the reference was given).
    pub reference_seconds: f64,
    /// Other renderers' measurements of the same picture, drawn beside tracery's.
    pub peers: Vec<Peer>,
}

/// Another renderer's error against time on the same picture and reference.
#[derive(Clone, Debug, PartialEq)]
pub struct Peer {
    /// What it is (the CSV's first `#` comment, else the file name).
    pub label: String,
    /// `(spp, seconds, rmse)` per measurement, in the file's order.
    pub points: Vec<(u32, f64, f64)>,
}

impl Peer {
    /// Reads a peer's CSV: an optional `# label` comment line, a header naming the columns
    /// `spp`, `seconds` and `rmse` (others are ignored), then one row per measurement.
    pub fn load(path: &Path) -> Result<Peer> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("{}: cannot read", path.display()))?;
        let mut label = None;
        let mut columns: Option<(usize, usize, usize)> = None;
        let mut points = Vec::new();
        for (n, line) in text.lines().enumerate() {
            let at = || format!("{}:{}", path.display(), n + 1);
            let line = line.trim();
            if line.is_empty() {
                continue;
            }
            if let Some(c) = line.strip_prefix('#') {
                if label.is_none() && points.is_empty() {
                    label = Some(c.trim().to_string());
                }
                continue;
            }
            let cells: Vec<&str> = line.split(',').map(str::trim).collect();
            let Some((i_spp, i_sec, i_rmse)) = columns else {
                let find = |name: &str| {
                    cells
                        .iter()
                        .position(|c| c.eq_ignore_ascii_case(name))
                        .with_context(|| format!("{}: no `{name}` column in the header", at()))
                };
                columns = Some((find("spp")?, find("seconds")?, find("rmse")?));
                continue;
            };
            let cell = |i: usize, name: &str| -> Result<f64> {
                let c = cells
                    .get(i)
                    .with_context(|| format!("{}: no `{name}` value", at()))?;
                let v: f64 = c
                    .parse()
                    .map_err(|_| anyhow::anyhow!("{}: `{c}` is not a number ({name})", at()))?;
                if !(v.is_finite() && v >= 0.0) {
                    bail!("{}: {name} {v} is not a finite non-negative number", at());
                }
                Ok(v)
            };
            points.push((
                cell(i_spp, "spp")? as u32,
                cell(i_sec, "seconds")?,
                cell(i_rmse, "rmse")?,
            ));
        }
        if points.is_empty() {
            bail!("{}: no measurements", path.display());
        }
        Ok(Peer {
            label: label.unwrap_or_else(|| crate::scene::name_of(path)),
            points,
        })
    }
}

impl Peer {
    /// `(seconds, rmse)` per sample count, each the mean over the rows of that count (several
    /// seeds), in order of sample count.
    pub fn means(&self) -> Vec<(f64, f64)> {
        let mut spps: Vec<u32> = self.points.iter().map(|p| p.0).collect();
        spps.sort_unstable();
        spps.dedup();
        spps.iter()
            .map(|&n| {
                let rows: Vec<_> = self.points.iter().filter(|p| p.0 == n).collect();
                let k = rows.len() as f64;
                (
                    rows.iter().map(|p| p.1).sum::<f64>() / k,
                    rows.iter().map(|p| p.2).sum::<f64>() / k,
                )
            })
            .collect()
    }
}

/// Seconds at which the error, falling along `(seconds, rmse)` points, first reaches `target`:
/// interpolated in log-log between the measured points around it (`None` if it never does).
pub fn time_to(points: &[(f64, f64)], target: f64) -> Option<f64> {
    let mut p: Vec<(f64, f64)> = points
        .iter()
        .copied()
        .filter(|&(t, e)| t > 0.0 && e > 0.0)
        .collect();
    p.sort_by(|a, b| a.0.total_cmp(&b.0));
    let first = *p.first()?;
    if first.1 <= target {
        return Some(first.0);
    }
    p.windows(2).find_map(|w| {
        let ((t0, e0), (t1, e1)) = (w[0], w[1]);
        (e1 <= target).then(|| {
            let f = (target.ln() - e0.ln()) / (e1.ln() - e0.ln());
            (t0.ln() + f * (t1.ln() - t0.ln())).exp()
        })
    })
}

/// Loads a linear RGB reference image (EXR or HDR) of `width x height`.
pub fn load_reference(path: &Path, width: u32, height: u32) -> Result<Vec<Vec3>> {
    let img = image::open(path)
        .with_context(|| format!("{}: cannot read the reference image", path.display()))?
        .into_rgb32f();
    if img.width() != width || img.height() != height {
        bail!(
            "{}: the reference is {}x{}, the renders {}x{} (give --width and --height to match)",
            path.display(),
            img.width(),
            img.height(),
            width,
            height
        );
    }
    let px: Vec<Vec3> = img.pixels().map(|p| Vec3::from_array(p.0)).collect();
    if let Some(i) = px.iter().position(|p| !p.is_finite()) {
        bail!(
            "{}: pixel ({}, {}) is not finite",
            path.display(),
            i as u32 % width,
            i as u32 / width
        );
    }
    Ok(px)
}

/// Runs the experiment against `reference` (rendered here at `reference_spp` when `None`).
/// `progress(done, total)` counts renders.
pub fn run(
    scene: &Scene,
    bvh: &Bvh,
    config: &ConvergenceConfig,
    reference: Option<Vec<Vec3>>,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Report> {
    config.validate(reference.is_some())?;
    let base = RenderSettings {
        width: config.width,
        height: config.height,
        max_depth: config.max_depth,
        ..RenderSettings::default()
    };
    let plan = RenderPlan::new(scene, &base);
    let env = EnvironmentMap::load(&scene.environment, plan.environment)?;
    let denoiser = config.denoise.then(Denoiser::new).transpose()?;
    let settings_of = |spp: u32, seed: u64, sampler: SamplerKind| RenderSettings {
        spp,
        seed,
        sampler,
        ..base.clone()
    };
    let render = |spp: u32, seed: u64, sampler: SamplerKind| {
        let settings = settings_of(spp, seed, sampler);
        let start = Instant::now();
        let out = render_with_plan(scene, bvh, &env, &settings, plan, &|_| {});
        (out.film.mean(), start.elapsed().as_secs_f64())
    };
    // The render's layers traced and the picture denoised: its image and the seconds taken.
    let denoise = |d: &Denoiser, img: &[Vec3], spp: u32, seed: u64, sampler| -> Result<_> {
        let settings = settings_of(spp, seed, sampler);
        let start = Instant::now();
        let layers = render_layers(scene, bvh, &env, &settings, plan);
        let clean = d.run(&Inputs {
            width: config.width,
            height: config.height,
            color: img,
            albedo: Some(&layers.albedo_mean()),
            normal: Some(&layers.normal_mean()),
        })?;
        Ok((clean, start.elapsed().as_secs_f64()))
    };
    let levels: Vec<u32> = (0..=config.max_spp.trailing_zeros())
        .map(|k| 1 << k)
        .collect();
    let own = usize::from(reference.is_none());
    let total = own
        + levels.len()
            * config.seeds as usize
            * (config.samplers.len() + usize::from(config.denoise));
    let mut done = 0;
    let (reference, reference_seconds) = match reference {
        Some(r) => (r, 0.0),
        None => {
            let r = render(config.reference_spp, 0xDEC0DE, SamplerKind::Sobol);
            done += 1;
            progress(done, total);
            r
        }
    };

    let mut points = Vec::new();
    for &spp in &levels {
        for seed in 1..=config.seeds as u64 {
            // Samplers interleaved, so load elsewhere on the machine hits both alike.
            for (k, &sampler) in config.samplers.iter().enumerate() {
                let (img, seconds) = render(spp, seed, sampler);
                let (rmse, relmse) = errors(&img, &reference);
                points.push(Point {
                    sampler,
                    spp,
                    seed,
                    seconds,
                    rmse,
                    relmse,
                    denoised: false,
                });
                done += 1;
                progress(done, total);
                if let (Some(d), 0) = (&denoiser, k) {
                    let (clean, more) = denoise(d, &img, spp, seed, sampler)?;
                    let (rmse, relmse) = errors(&clean, &reference);
                    points.push(Point {
                        sampler,
                        spp,
                        seed,
                        seconds: seconds + more,
                        rmse,
                        relmse,
                        denoised: true,
                    });
                    done += 1;
                    progress(done, total);
                }
            }
        }
    }

    let (means, denoised, fits, target) = summarise(&points, &levels, config);
    Ok(Report {
        points,
        means,
        fits,
        denoised,
        target_rmse: target,
        reference_seconds,
        peers: Vec::new(),
    })
}

/// The renders' means per sampler and sample count (seconds, RMSE, relMSE; the denoised ones
/// apart, by sample count), each sampler's fits, and the target error the fits are read at.
#[allow(clippy::type_complexity)]
fn summarise(
    points: &[Point],
    levels: &[u32],
    config: &ConvergenceConfig,
) -> (
    Vec<(SamplerKind, u32, f64, f64, f64)>,
    Vec<(u32, f64, f64, f64)>,
    Vec<Fit>,
    f64,
) {
    let mut means = Vec::new();
    for &sampler in &config.samplers {
        for &spp in levels {
            let p: Vec<&Point> = points
                .iter()
                .filter(|p| p.sampler == sampler && p.spp == spp && !p.denoised)
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
    let denoised = levels
        .iter()
        .filter_map(|&spp| {
            let p: Vec<&Point> = points
                .iter()
                .filter(|p| p.denoised && p.spp == spp)
                .collect();
            let n = p.len() as f64;
            let mean = |f: fn(&Point) -> f64| p.iter().map(|x| f(x)).sum::<f64>() / n;
            (!p.is_empty()).then(|| {
                (
                    spp,
                    mean(|p| p.seconds),
                    mean(|p| p.rmse),
                    mean(|p| p.relmse),
                )
            })
        })
        .collect();
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
    (means, denoised, fits, target)
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
    writeln!(f, "sampler,spp,seed,seconds,rmse,relmse,denoised")?;
    for p in &report.points {
        writeln!(
            f,
            "{},{},{},{:.6},{:.8},{:.8},{}",
            p.sampler, p.spp, p.seed, p.seconds, p.rmse, p.relmse, p.denoised
        )?;
    }
    f.flush()
        .with_context(|| format!("{}: cannot write", path.display()))
}

/// An axis label: at most three significant digits, no trailing zeros (`0.009`, `0.01`,
/// `1.5`, `20`), never the float's full expansion.
pub fn tick(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let digits = (2 - v.abs().log10().floor() as i32).max(0) as usize;
    let s = format!("{v:.digits$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// Draws RMSE against render time, log-log, one line per sampler with its fitted slope, and
/// the target error with each sampler's time to reach it.
pub fn plot(path: &Path, report: &Report, title: &str) -> Result<()> {
    use plotters::prelude::*;
    crate::plot_font::ensure()?;
    let means = &report.means;
    let all: Vec<(f64, f64)> = means
        .iter()
        .map(|m| (m.2, m.3))
        .chain(report.denoised.iter().map(|d| (d.1, d.2)))
        .chain(
            report
                .peers
                .iter()
                .flat_map(|p| p.points.iter().map(|q| (q.1, q.2))),
        )
        .filter(|&(t, e)| t > 0.0 && e > 0.0)
        .collect();
    let (tmin, tmax) = all
        .iter()
        .fold((f64::MAX, f64::MIN), |a, m| (a.0.min(m.0), a.1.max(m.0)));
    let (emin, emax) = all
        .iter()
        .fold((f64::MAX, f64::MIN), |a, m| (a.0.min(m.1), a.1.max(m.1)));
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
        .x_label_formatter(&|v| tick(*v))
        .y_label_formatter(&|v| tick(*v))
        .x_labels(8)
        .y_labels(8)
        .light_line_style(WHITE.mix(0.0))
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
                "tracery {}: slope {:.2} per spp; {} to RMSE {}",
                fit.sampler,
                fit.slope_spp,
                match time_to(&pts, report.target_rmse) {
                    Some(t) => format!("{} s", tick(t)),
                    None => format!("{} s (extrapolated)", tick(fit.seconds_to_target)),
                },
                tick(report.target_rmse)
            ))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
        chart
            .draw_series(pts.iter().map(|&p| Circle::new(p, 4, c.filled())))
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        // Where the measured line crosses the target error.
        if let Some(t) = time_to(&pts, report.target_rmse) {
            chart
                .draw_series(std::iter::once(Cross::new(
                    (t, report.target_rmse),
                    8,
                    c.stroke_width(2),
                )))
                .map_err(|e| anyhow::anyhow!("{e}"))?;
        }
    }
    if let (false, Some(fit)) = (report.denoised.is_empty(), report.fits.first()) {
        // The first sampler's colour, dashed.
        let c = colours[0];
        let pts: Vec<(f64, f64)> = report.denoised.iter().map(|d| (d.1, d.2)).collect();
        let reach = time_to(&pts, report.target_rmse)
            .map_or("never reaches".into(), |t| format!("{} s to", tick(t)));
        chart
            .draw_series(DashedLineSeries::new(pts.clone(), 8, 5, c.stroke_width(2)))
            .map_err(|e| anyhow::anyhow!("{e}"))?
            .label(format!(
                "tracery {} denoised (OIDN): {reach} RMSE {}",
                fit.sampler,
                tick(report.target_rmse)
            ))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(1)));
        chart
            .draw_series(pts.iter().map(|&p| TriangleMarker::new(p, 5, c.filled())))
            .map_err(|e| anyhow::anyhow!("{e}"))?;
    }
    let peer_colours = [BLACK, CYAN, RGBColor(230, 140, 0)];
    for (k, peer) in report.peers.iter().enumerate() {
        let c = peer_colours[k % peer_colours.len()];
        let pts = peer.means();
        let reach = time_to(&pts, report.target_rmse)
            .map_or("never reaches".into(), |t| format!("{} s to", tick(t)));
        chart
            .draw_series(LineSeries::new(pts.clone(), c.stroke_width(2)))
            .map_err(|e| anyhow::anyhow!("{e}"))?
            .label(format!(
                "{}: {reach} RMSE {}",
                peer.label,
                tick(report.target_rmse)
            ))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
        chart
            .draw_series(
                time_to(&pts, report.target_rmse)
                    .map(|t| Cross::new((t, report.target_rmse), 8, c.stroke_width(2))),
            )
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        chart
            .draw_series(
                peer.points
                    .iter()
                    .map(|p| TriangleMarker::new((p.1, p.2), 4, c.mix(0.5).filled())),
            )
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
