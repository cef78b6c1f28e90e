//! `tracery render`: render a scene to PNG (tone mapped) or EXR / HDR (linear radiance) on all
//! cores, with a progress bar; optionally its render layers (albedo, normal, depth, samples)
//! as EXR channels, and the picture denoised.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Result;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use tracery::bvh::{Accel, Bvh, Tree, Update};
use tracery::denoise::{Denoiser, Inputs};
use tracery::film::{Film, OutputKind, Sum};
use tracery::render::aov::Aov;
use tracery::render::{
    EnvironmentMap, Explain, Integrator, RenderPlan, RenderSettings, part, render_layers,
    render_samples, render_with_plan,
};
use tracery::sampling::SamplerKind;
use tracery::scene::{Format, Scene};

use super::{BvhArgs, ensure_parent, load_scene, set_threads};

#[derive(Args, Debug)]
pub struct RenderArgs {
    /// Scene file (TOML), OBJ, PLY or glTF (`.gltf`, `.glb`); the built-in Cornell box when left out.
    scene: Option<PathBuf>,
    /// Output image: `.png` (tone mapped, after `--exposure`), `.exr` or `.hdr` (linear
    /// radiance, no exposure or tone mapping).
    #[arg(short, long, default_value = "out/render.png")]
    output: PathBuf,
    /// Image width in pixels.
    #[arg(long, default_value_t = 512)]
    width: u32,
    /// Image height in pixels.
    #[arg(long, default_value_t = 512)]
    height: u32,
    /// Samples per pixel.
    #[arg(long, default_value_t = 16)]
    spp: u32,
    /// Seed of the random streams (the same seed gives the same image on any thread count).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Sampler for pixel, lens and light samples: sobol (Owen-scrambled) or random.
    #[arg(long, default_value_t = SamplerKind::Sobol)]
    sampler: SamplerKind,
    /// Largest number of bounces after the camera's hit (mirrors, transparent surfaces and,
    /// with the path integrator, diffuse bounces).
    #[arg(long, default_value_t = 5)]
    max_depth: u32,
    /// How light is gathered: direct (light from the lights and emissive surfaces only) or
    /// path (global illumination); default: the scene's (`[render] integrator`, else direct).
    #[arg(long)]
    integrator: Option<Integrator>,
    /// Print the render plan (what the scene needs and what is left out), then render.
    #[arg(long)]
    explain: bool,
    /// Shade the normals that normal and height maps bend as they are, without the shadowing
    /// term that softens their shadow terminator (on by default, as in Mitsuba 3).
    #[arg(long)]
    hard_terminator: bool,
    /// Exposure multiplier applied before tone mapping.
    #[arg(long, default_value_t = 1.0)]
    exposure: f32,
    #[command(flatten)]
    bvh: BvhArgs,
    /// Threads to render with (default: every core).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Render layers to write, comma-separated: albedo, normal, depth, samples. They go into
    /// the output as extra EXR channels (`albedo.R`, `normal.X`, `depth.Z`, `samples.N`, …)
    /// when it is `.exr`, else into `<output>.aov.exr` beside it.
    #[arg(long, value_delimiter = ',', value_parser = Aov::parse)]
    aov: Vec<Aov>,
    /// Denoise the picture (Intel Open Image Denoise, guided by the albedo and normal layers)
    /// before writing it.
    #[arg(long)]
    denoise: bool,
    /// With --denoise: also write the picture as rendered, to `<output>.noisy.<ext>`.
    #[arg(long, requires = "denoise")]
    keep_noisy: bool,
    /// Play the glTF animations (of a glTF, or of a scene file's glTF meshes) to this time in
    /// seconds and render that instant; without it the scene stands as the file places it.
    #[arg(long, conflicts_with = "times")]
    time: Option<f64>,
    /// Render an animation: one frame every 1/--fps seconds from A up to, not including, B
    /// (`0..2` at 24 fps: 48 frames), each written to the output name with its run of `#`
    /// replaced by the frame number counted from 0 (`-o out/frame_####.png`).
    #[arg(long, value_name = "A..B", value_parser = parse_times)]
    times: Option<(f64, f64)>,
    /// Frames per second of --times [default: 24].
    #[arg(long, requires = "times")]
    fps: Option<f64>,
    /// Render only the sample indices A up to, not including, B of every pixel (--spp is not
    /// read) and write them as a part of a render split by samples: an EXR of raw sums and
    /// counts that `tracery merge` adds to the other parts, giving the bits of the whole
    /// render.
    #[arg(long, value_name = "A..B", value_parser = part::parse_range,
          conflicts_with_all = ["times", "denoise", "aov"])]
    samples: Option<std::ops::Range<u32>>,
    /// With --times: render only the frames numbered A up to, not including, B (a part of the
    /// clip, to split it across machines; each frame is written under its own number).
    #[arg(long, value_name = "A..B", value_parser = part::parse_range, requires = "times")]
    frames: Option<std::ops::Range<u32>>,
}

/// Most frames one `--times` run renders.
const MAX_FRAMES: usize = 1_000_000;

/// `A..B` with finite `A < B` (seconds).
fn parse_times(s: &str) -> Result<(f64, f64), String> {
    let (a, b) = s
        .split_once("..")
        .ok_or_else(|| format!("`{s}`: expected a range of seconds A..B, such as 0..2.5"))?;
    let num = |x: &str| {
        x.trim()
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("`{s}`: `{x}` is not a number of seconds"))
    };
    let (a, b) = (num(a)?, num(b)?);
    if a >= b {
        return Err(format!("`{s}`: the range is empty (A must be less than B)"));
    }
    Ok((a, b))
}

/// The frames of `A..B` at `fps`: the times `A + i / fps` below `B`, with their numbers `i`.
pub fn frame_times((a, b): (f64, f64), fps: f64) -> Vec<(usize, f64)> {
    (0..)
        .map(|i| (i, a + i as f64 / fps))
        .take_while(|&(_, t)| t < b)
        .collect()
}

/// `pattern` with its last run of `#` replaced by `frame`, zero-padded to the run's length.
pub fn frame_path(pattern: &Path, frame: usize) -> Option<PathBuf> {
    let name = pattern.file_name()?.to_str()?;
    let end = name.rfind('#')? + 1;
    let start = name[..end].trim_end_matches('#').len();
    let width = end - start;
    let numbered = format!("{}{frame:0width$}{}", &name[..start], &name[end..]);
    Some(pattern.with_file_name(numbered))
}

/// `out/render.png` with `tag` and `ext`: `out/render.<tag>.<ext>`.
fn beside(path: &Path, tag: &str, ext: &str) -> PathBuf {
    let stem = path
        .file_stem()
        .map_or_else(Default::default, |s| s.to_os_string());
    let mut name = stem;
    name.push(format!(".{tag}.{ext}"));
    path.with_file_name(name)
}

pub fn run(a: RenderArgs) -> Result<()> {
    set_threads(a.threads)?;
    let Some(range) = a.times else {
        return render_frame(&a, a.time, &a.output, true, &mut None);
    };
    let fps = a.fps.unwrap_or(24.0);
    if !(fps.is_finite() && fps > 0.0) {
        anyhow::bail!("--fps {fps}: expected a positive number of frames per second");
    }
    if frame_path(&a.output, 0).is_none() {
        anyhow::bail!(
            "{}: --times writes one picture per frame: give the output name a run of # for the frame number (out/frame_####.png)",
            a.output.display()
        );
    }
    let count = (range.1 - range.0) * fps;
    if count > MAX_FRAMES as f64 {
        anyhow::bail!(
            "--times {}..{} at {fps} fps makes {count:.0} frames; at most {MAX_FRAMES} are rendered in one run",
            range.0,
            range.1
        );
    }
    let mut frames = frame_times(range, fps);
    let n = frames.len();
    if let Some(part) = &a.frames {
        if part.end as usize > n {
            anyhow::bail!(
                "--frames {}..{}: the clip has {n} frames (0..{n})",
                part.start,
                part.end
            );
        }
        frames.retain(|(i, _)| part.contains(&(*i as u32)));
    }
    let start = Instant::now();
    // Each frame's tree, refitted to the next frame's triangles where it can be.
    let mut tree = None;
    let rendered = frames.len();
    for (k, (i, t)) in frames.into_iter().enumerate() {
        let path = frame_path(&a.output, i).expect("checked above");
        eprintln!("frame {}/{n}: t = {t:.4} s", i + 1);
        render_frame(&a, Some(t), &path, k == 0, &mut tree)?;
    }
    let of = if rendered == n {
        String::new()
    } else {
        format!(" of {n}")
    };
    println!(
        "rendered {rendered}{of} frames ({:.3} to {:.3} s at {fps} fps) in {:.1} s",
        range.0,
        range.1,
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

/// A frame's BVH, kept for the next frame, and the SAH cost it had when last built.
type Kept = Option<(Bvh, f64)>;

/// Renders the scene at `time` (its glTF animations played to it, if given) to `output`;
/// load warnings printed when `warn`. With the previous frame's tree in `kept`, the tree is
/// refitted to this frame's triangles (or built again when it cannot be, or when refitting
/// has cost it too much quality: [`Bvh::refit_or_rebuild`]); this frame's is left there.
fn render_frame(
    a: &RenderArgs,
    time: Option<f64>,
    output: &Path,
    warn: bool,
    kept: &mut Kept,
) -> Result<()> {
    let settings = RenderSettings {
        width: a.width,
        height: a.height,
        spp: a.samples.as_ref().map_or(a.spp, |r| r.end - r.start),
        seed: a.seed,
        max_depth: a.max_depth,
        sampler: a.sampler,
        soft_terminator: !a.hard_terminator,
    };
    settings.validate().map_err(anyhow::Error::msg)?;
    tracery::film::OutputKind::of(output)?;
    if a.samples.is_some()
        && !output
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("exr"))
    {
        anyhow::bail!(
            "{}: a part (--samples) is written as EXR: give the output name .exr",
            output.display()
        );
    }
    let options = a.bvh.options()?;
    let mut scene = match (&a.scene, time) {
        (Some(p), Some(t)) => {
            let scene = Scene::load_at(p, Some(t))?;
            if warn {
                for w in &scene.warnings {
                    eprintln!("warning: {w}");
                }
                if matches!(Format::of(p), Some(Format::Obj | Format::Ply)) {
                    eprintln!(
                        "warning: {}: has no animation; a time changes nothing",
                        p.display()
                    );
                }
            }
            scene
        }
        (None, Some(_)) => anyhow::bail!(
            "--time and --times need a scene with animations (a glTF, or a scene file with glTF meshes)"
        ),
        (p, None) => load_scene(p.as_deref())?,
    };
    if let Some(i) = a.integrator {
        scene.integrator = i;
    }
    if a.explain {
        let plan = RenderPlan::new(&scene, &settings);
        eprintln!("{}", Explain(&plan, &scene, &settings));
    }
    if !scene.instances.is_empty() {
        // Meshes placed many times: their trees and a top level (not refitted between
        // instants: such a scene has no animation of its own).
        let accel = Accel::for_scene(&scene, &options)
            .map_err(|e| anyhow::anyhow!("{}: {e}", scene.name))?;
        let placed = &scene.instances;
        eprintln!(
            "{}: {} triangles ({} placed once, {} meshes placed {} times); BVHs ({}, {} bins, leaf {}) built in {:.1} ms, {:.1} MB",
            scene.name,
            scene.triangle_count(),
            scene.mesh.triangles.len(),
            placed.meshes.len(),
            placed.placements().len(),
            options.split,
            options.bins,
            options.max_leaf_size,
            accel.build_ms(),
            accel.bytes() as f64 / 1e6,
        );
        return finish(a, output, &scene, &settings, accel.tree());
    }
    let (bvh, built_cost, built) = match kept.take() {
        Some((mut bvh, built_cost)) => {
            match bvh.refit_or_rebuild(&scene.mesh.triangles, built_cost) {
                Update::Refitted(r) => {
                    eprintln!(
                        "{}: BVH refitted in {:.1} ms: SAH cost {:.2} ({:.2} when built)",
                        scene.name, r.ms, r.sah_cost, built_cost
                    );
                    (bvh, built_cost, false)
                }
                Update::Rebuilt(why) => {
                    eprintln!("{}: BVH built again: {why}", scene.name);
                    let cost = bvh.stats.sah_cost;
                    (bvh, cost, true)
                }
            }
        }
        None => {
            let bvh = Bvh::build(&scene.mesh.triangles, &options);
            let cost = bvh.stats.sah_cost;
            (bvh, cost, true)
        }
    };
    // (A refitted tree's line is above.)
    if built {
        let s = &bvh.stats;
        eprintln!(
            "{}: {} triangles; BVH ({}, {} bins, leaf {}) built in {:.1} ms: {} levels, {} leaves, SAH cost {:.2}{}",
            scene.name,
            scene.triangle_count(),
            options.split,
            options.bins,
            options.max_leaf_size,
            s.build_ms,
            s.levels,
            s.leaves,
            s.sah_cost,
            if s.excluded + s.degenerate > 0 {
                format!(
                    "; left out: {} with non-finite vertices, {} with zero area",
                    s.excluded, s.degenerate
                )
            } else {
                String::new()
            }
        );
    }
    finish(a, output, &scene, &settings, (&bvh).into())?;
    *kept = Some((bvh, built_cost));
    Ok(())
}

/// Renders `scene` through `bvh` to `output`, with the render layers and the denoiser when
/// asked, and says what it wrote.
fn finish(
    a: &RenderArgs,
    output: &Path,
    scene: &Scene,
    settings: &RenderSettings,
    bvh: Tree<'_>,
) -> Result<()> {
    // Asked before the render, so a build without the denoiser does not render for nothing.
    let denoiser = a.denoise.then(Denoiser::new).transpose()?;
    let bar = ProgressBar::new(settings.height as u64).with_style(
        ProgressStyle::with_template(
            "rendering {bar:40} {pos}/{len} rows, {elapsed} elapsed, eta {eta}",
        )
        .expect("valid template"),
    );
    let log = LogProgress::new(settings.height as u64);
    // Called with the rows finished so far, from any thread.
    let progress = |rows: usize| {
        bar.set_position(bar.position().max(rows as u64));
        log.at(rows as u64);
    };
    let plan = RenderPlan::new(scene, settings);
    let env = EnvironmentMap::load(&scene.environment, plan.environment)?;
    let start = Instant::now();
    if let Some(range) = &a.samples {
        let key = part::PartKey::of(scene, settings);
        let out = render_samples(scene, bvh, &env, settings, plan, range.clone(), &progress);
        let took = start.elapsed();
        bar.finish_and_clear();
        let path = ensure_parent(output)?;
        part::Part {
            film: out.film,
            range: range.clone(),
            key,
        }
        .save(&path)?;
        println!(
            "wrote {} (samples {}..{} of every pixel, {}x{}, in {:.2} s)",
            path.display(),
            range.start,
            range.end,
            settings.width,
            settings.height,
            took.as_secs_f64()
        );
        return Ok(());
    }
    let out = render_with_plan(scene, bvh, &env, settings, plan, &progress);
    let took = start.elapsed();
    bar.finish_and_clear();
    let path = ensure_parent(output)?;
    let mut written = a.aov.clone();
    written.sort();
    written.dedup();
    let layers = (!written.is_empty() || denoiser.is_some()).then(|| {
        let t = Instant::now();
        let layers = render_layers(scene, bvh, &env, settings, plan);
        (layers, t.elapsed().as_secs_f64())
    });
    if let Some((_, secs)) = &layers {
        eprintln!("render layers traced in {:.0} ms", secs * 1e3);
    }
    let film = match (&denoiser, &layers) {
        (Some(d), Some((l, _))) => {
            if a.keep_noisy {
                let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("png");
                let noisy = beside(&path, "noisy", ext);
                out.film.save(&noisy, a.exposure)?;
                println!("wrote {} (as rendered)", noisy.display());
            }
            let t = Instant::now();
            let (color, albedo, normal) = (out.film.mean(), l.albedo_mean(), l.normal_mean());
            let clean = d.run(&Inputs {
                width: settings.width,
                height: settings.height,
                color: &color,
                albedo: Some(&albedo),
                normal: Some(&normal),
            })?;
            eprintln!("denoised in {:.0} ms", t.elapsed().as_secs_f64() * 1e3);
            // Kept as sums over the render's samples, so the film's mean is the denoised picture.
            let k = settings.spp as f32;
            Film {
                sum: clean.into_iter().map(|c| Sum::of(c * k)).collect(),
                ..out.film.clone()
            }
        }
        _ => out.film.clone(),
    };
    if let (false, Some((l, _))) = (written.is_empty(), &layers) {
        if OutputKind::of(&path)? == OutputKind::Linear
            && path
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("exr"))
        {
            l.save_exr(&path, &written, Some(&film))?;
        } else {
            film.save(&path, a.exposure)?;
            let aov_path = beside(&path, "aov", "exr");
            l.save_exr(&aov_path, &written, None)?;
            println!(
                "wrote {} ({})",
                aov_path.display(),
                written
                    .iter()
                    .map(|l| l.name())
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        }
    } else {
        film.save(&path, a.exposure)?;
    }
    let secs = took.as_secs_f64();
    let r = &out.rays;
    println!(
        "wrote {}{} ({}x{}, {} spp) in {:.0} ms: rays {} camera, {} shadow, {} reflection, {} transmission, {} bounce; {:.2} Mrays/s{}",
        path.display(),
        if denoiser.is_some() { ", denoised" } else { "" },
        settings.width,
        settings.height,
        settings.spp,
        secs * 1e3,
        r.camera,
        r.shadow,
        r.reflection,
        r.transmission,
        r.bounce,
        out.rays.total() as f64 / secs / 1e6,
        if out.film.rejected > 0 {
            format!("; {} non-finite samples left out", out.film.rejected)
        } else {
            String::new()
        }
    );
    Ok(())
}

/// Progress lines for a log (a batch job's output, a pipe), where the bar is not drawn: one
/// at each tenth of the rows.
struct LogProgress {
    total: u64,
    /// Tenths said so far.
    said: std::sync::atomic::AtomicU64,
    on: bool,
    start: Instant,
}

impl LogProgress {
    fn new(total: u64) -> LogProgress {
        use std::io::IsTerminal;
        LogProgress {
            total: total.max(1),
            said: Default::default(),
            on: !std::io::stderr().is_terminal(),
            start: Instant::now(),
        }
    }

    /// `done` rows are finished: a line when that passes another tenth of them.
    fn at(&self, done: u64) {
        use std::sync::atomic::Ordering;
        if !self.on {
            return;
        }
        let tenths = done.min(self.total) * 10 / self.total;
        if self.said.fetch_max(tenths, Ordering::Relaxed) < tenths {
            eprintln!(
                "rendering: {}% ({done}/{} rows, {:.1} s)",
                tenths * 10,
                self.total,
                self.start.elapsed().as_secs_f64()
            );
        }
    }
}
