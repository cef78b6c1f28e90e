//! `tracery report`: the tables of docs/benchmarks.md and docs/bvh.md, printed as Markdown by
//! the command they cite.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Result;
use clap::{Args, Subcommand};
use glam::Vec3;
use tracery::bench::scaling::{self, ScalingRow, growth_per_doubling};
use tracery::bench::{self, BenchConfig};
use tracery::bvh::{BuildOptions, Bvh, SplitMethod, Visits};
use tracery::geometry::Aabb;
use tracery::render::{RenderSettings, render};
use tracery::rng::SplitMix64;
use tracery::scene::Scene;

use super::load_flat_scene;

#[derive(Args, Debug)]
pub struct ReportArgs {
    #[command(subcommand)]
    kind: ReportKind,
}

#[derive(Subcommand, Debug)]
enum ReportKind {
    /// Median vs SAH per mesh: build ms, levels, leaves, SAH cost, closest-hit Mrays/s (one
    /// thread and all threads, canonical camera) and render ms at 512x512 (1 spp, all threads).
    Splits {
        /// Meshes or scene files (the built-in Cornell box when left out).
        meshes: Vec<PathBuf>,
        /// Repeat each measurement and keep the best.
        #[arg(long, default_value_t = 3)]
        repeat: usize,
    },
    /// Build time against size: our SAH build (with the 8-wide collapse) and Embree's (where
    /// it is installed), on one thread and on every thread, with the growth per doubling
    /// of the triangle count and each builder's speed-up from one thread to all.
    Scaling {
        /// Meshes, smallest first.
        meshes: Vec<PathBuf>,
        /// Also a generated terrain of about this many triangles (0: none).
        #[arg(long, default_value_t = 4_000_000)]
        generated: u32,
        /// Repeat each measurement and keep the best.
        #[arg(long, default_value_t = 3)]
        repeat: usize,
        /// Also draw build time against triangle count, log-log, to this PNG file.
        #[arg(long)]
        plot: Option<PathBuf>,
    },
    /// Speed-up against threads: path tracing a scene (ms per sample) and our SAH build of a
    /// mesh, on 1, 2, 4, ... threads up to every core, in interleaved rounds, each figure its
    /// best round. On a machine with more cores, this is the table of how far they pay.
    Threads {
        /// Scene to path trace (the built-in Cornell box when left out); the path integrator
        /// is used whatever the scene says.
        scene: Option<PathBuf>,
        /// Mesh or scene whose BVH build is timed (the scene's when left out).
        #[arg(long)]
        build: Option<PathBuf>,
        /// Picture width in pixels.
        #[arg(long, default_value_t = 320)]
        width: u32,
        /// Picture height in pixels.
        #[arg(long, default_value_t = 240)]
        height: u32,
        /// Samples per pixel of each timed render.
        #[arg(long, default_value_t = 16)]
        spp: u32,
        /// Repeat each measurement and keep the best.
        #[arg(long, default_value_t = 3)]
        repeat: usize,
    },
    /// SAH bin counts against build ms, SAH cost, closest-hit Mrays/s (one thread) and the
    /// nodes and triangle blocks a canonical ray's closest-hit walk tests (counts that do not
    /// depend on the machine's load).
    Bins {
        /// Mesh or scene file.
        mesh: PathBuf,
        /// Bin counts to compare.
        #[arg(long, value_delimiter = ',', default_value = "4,8,12,16,32,64")]
        bins: Vec<u32>,
        /// Repeat each measurement and keep the best.
        #[arg(long, default_value_t = 5)]
        repeat: usize,
    },
    /// Instances over two levels of trees: the top level of `--count` placements of the mesh
    /// (a grid, each turned and scaled its own way) built on one thread, best of
    /// `--repeat`, and the bytes the placements take against the mesh's tree and against
    /// the mesh copied once per placement.
    Instances {
        /// Mesh or scene file (the built-in Cornell box when left out).
        mesh: Option<PathBuf>,
        /// Placements.
        #[arg(long, default_value_t = 10_000)]
        count: usize,
        /// Repeat each measurement and keep the best.
        #[arg(long, default_value_t = 5)]
        repeat: usize,
    },
    /// A scene that places meshes many times traced through its two levels against the same
    /// scene flattened into one mesh: the camera rays of the scene's own view (512x512, one
    /// per pixel centre), closest hits on one thread, best of `--repeat` alternating rounds,
    /// with each form's build time and bytes.
    Placed {
        /// Scene file or glTF with placements (a `grid`, or a mesh several nodes use).
        scene: PathBuf,
        /// Repeat each measurement and keep the best.
        #[arg(long, default_value_t = 5)]
        repeat: usize,
    },
    /// Refit against rebuild after the mesh's vertices move (each by up to `--move` of the
    /// mesh's size, shared vertices together): one thread, best of `--repeat` in alternating
    /// rounds, with the SAH cost and closest-hit speed (canonical camera rays, one thread) of
    /// each tree.
    Refit {
        /// Mesh or scene file.
        mesh: PathBuf,
        /// Largest move of a vertex along each axis, as a fraction of the mesh's diagonal.
        #[arg(long = "move", default_value_t = 0.01)]
        reach: f32,
        /// Repeat each measurement and keep the best.
        #[arg(long, default_value_t = 5)]
        repeat: usize,
    },
}

pub fn run(a: ReportArgs) -> Result<()> {
    match a.kind {
        ReportKind::Splits { meshes, repeat } => splits(meshes, repeat),
        ReportKind::Bins { mesh, bins, repeat } => bins_table(mesh, bins, repeat),
        ReportKind::Threads {
            scene,
            build,
            width,
            height,
            spp,
            repeat,
        } => threads_table(scene, build, (width, height, spp), repeat),
        ReportKind::Scaling {
            meshes,
            generated,
            repeat,
            plot,
        } => scaling(meshes, generated, repeat, plot),
        ReportKind::Refit {
            mesh,
            reach,
            repeat,
        } => refit_table(mesh, reach, repeat),
        ReportKind::Instances {
            mesh,
            count,
            repeat,
        } => instances_table(mesh, count, repeat),
        ReportKind::Placed { scene, repeat } => placed_table(scene, repeat),
    }
}

/// Each vertex of `tris` moved by up to `reach` along each axis, by a hash of its position
/// (so a vertex shared by several triangles moves the same way in each).
fn moved(tris: &[[Vec3; 3]], reach: f32) -> Vec<[Vec3; 3]> {
    let shift = |v: Vec3| {
        let axis = |k: u64| {
            let mut rng = SplitMix64::new(
                u64::from(v.x.to_bits())
                    ^ u64::from(v.y.to_bits()) << 21
                    ^ u64::from(v.z.to_bits()) << 42
                    ^ k,
            );
            (rng.next_f32() * 2.0 - 1.0) * reach
        };
        Vec3::new(axis(1), axis(2), axis(3))
    };
    tris.iter().map(|t| t.map(|v| v + shift(v))).collect()
}

fn instances_table(mesh: Option<PathBuf>, count: usize, repeat: usize) -> Result<()> {
    use std::sync::Arc;
    use tracery::bvh::{Instance, TwoLevel};
    let scene = load_flat_scene(mesh.as_deref(), "report")?;
    let tree = Arc::new(Bvh::build(&scene.mesh.triangles, &BuildOptions::sah()));
    let b = scene.mesh.bounds();
    let size = (Vec3::from(b.max) - Vec3::from(b.min)).length().max(1e-6);
    let side = (count as f64).cbrt().ceil() as usize;
    let instances: Vec<Instance> = (0..count)
        .map(|k| {
            let cell = Vec3::new(
                (k % side) as f32,
                (k / side % side) as f32,
                (k / (side * side)) as f32,
            );
            Instance {
                mesh: 0,
                to_world: glam::Affine3A::from_scale_rotation_translation(
                    Vec3::splat(0.5 + (k % 7) as f32 * 0.1),
                    glam::Quat::from_rotation_y(k as f32 * 0.7),
                    cell * size * 1.5,
                ),
            }
        })
        .collect();
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let mut best = f64::INFINITY;
    let mut two = None;
    for _ in 0..repeat.max(1) {
        let placed = instances.clone();
        // `build_ms`: the transforms inverted, the world boxes made, the top level built.
        let built = pool
            .install(|| TwoLevel::new(vec![tree.clone()], &placed))
            .map_err(anyhow::Error::msg)?;
        best = best.min(built.build_ms);
        two = Some(built);
    }
    let two = two.expect("built at least once");
    let mesh_bytes = tree.stats.binary_bytes + tree.stats.wide_bytes;
    println!(
        "{}: {} triangles, {count} placements; one thread, best of {}",
        scene.name,
        scene.triangle_count(),
        repeat.max(1)
    );
    println!("| what | figure |");
    println!("|---|---:|");
    println!("| top level built in | {best:.2} ms |");
    println!("| the mesh's tree | {mesh_bytes} bytes |");
    println!(
        "| the placements (transforms and top level) | {} bytes, {:.0} a placement |",
        two.bytes(),
        two.bytes() as f64 / count.max(1) as f64
    );
    println!(
        "| the mesh's tree copied once per placement | {} bytes |",
        mesh_bytes as u128 * count as u128
    );
    // One placement at the identity against the mesh's own tree: what the top level and
    // the ray's trip into the mesh's frame cost on the canonical camera rays, in
    // alternating rounds on one thread.
    let one = TwoLevel::new(
        vec![tree.clone()],
        &[Instance {
            mesh: 0,
            to_world: glam::Affine3A::IDENTITY,
        }],
    )
    .map_err(anyhow::Error::msg)?;
    let rays = bench::canonical_rays(&scene.mesh.bounds());
    let (flat_s, one_s, hits, placed) = alternating(
        repeat,
        || count_hits(&pool, &rays, |r| tree.intersect(r, f32::INFINITY).is_some()),
        || count_hits(&pool, &rays, |r| one.intersect(r, f32::INFINITY).is_some()),
    );
    anyhow::ensure!(
        hits == placed,
        "{hits} hits flat, {placed} through one placement"
    );
    let mrays = |s: f64| rays.len() as f64 / s / 1e6;
    println!(
        "| closest hits, the mesh's own tree ({} camera rays) | {:.2} Mrays/s |",
        rays.len(),
        mrays(flat_s)
    );
    println!(
        "| closest hits, one placement under a top level (scenes load a lone copy without one) | {:.2} Mrays/s ({:.2}x) |",
        mrays(one_s),
        flat_s / one_s
    );
    Ok(())
}

/// How many of `rays` `hit` says hit, on `pool`.
fn count_hits(
    pool: &rayon::ThreadPool,
    rays: &[tracery::geometry::Ray],
    hit: impl Fn(&tracery::geometry::Ray) -> bool + Sync,
) -> usize {
    pool.install(|| rays.iter().filter(|r| hit(r)).count())
}

/// Runs `a` and `b` in `repeat` alternating rounds (at least one): the best seconds of each,
/// and what each returned last.
fn alternating(
    repeat: usize,
    mut a: impl FnMut() -> usize,
    mut b: impl FnMut() -> usize,
) -> (f64, f64, usize, usize) {
    let (mut best_a, mut best_b, mut ra, mut rb) = (f64::INFINITY, f64::INFINITY, 0, 0);
    for _ in 0..repeat.max(1) {
        let t = Instant::now();
        ra = std::hint::black_box(a());
        best_a = best_a.min(t.elapsed().as_secs_f64());
        let t = Instant::now();
        rb = std::hint::black_box(b());
        best_b = best_b.min(t.elapsed().as_secs_f64());
    }
    (best_a, best_b, ra, rb)
}

fn placed_table(path: PathBuf, repeat: usize) -> Result<()> {
    use tracery::bvh::Accel;
    let scene = super::load_scene(Some(&path))?;
    anyhow::ensure!(
        !scene.instances.is_empty(),
        "{}: places no mesh more than once: nothing to compare (see `tracery report instances`)",
        path.display()
    );
    anyhow::ensure!(
        scene.triangle_count() <= super::FLAT_LIMIT,
        "{}: {} triangles flattened would pass {}: compare a smaller scene",
        path.display(),
        scene.triangle_count(),
        super::FLAT_LIMIT
    );
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let options = BuildOptions::sah();
    let (accel, flat_scene, flat) = pool.install(|| {
        let accel = Accel::for_scene(&scene, &options);
        let flat_scene = scene.flattened();
        let flat = Bvh::build(&flat_scene.mesh.triangles, &options);
        (accel, flat_scene, flat)
    });
    let accel = accel.map_err(anyhow::Error::msg)?;
    let tree = accel.tree();
    let cam = tracery::camera::CameraRays::new(&scene.camera, 512, 512);
    let rays = cam.pixel_center_rays();
    let (two_s, flat_s, a, b) = alternating(
        repeat,
        || count_hits(&pool, &rays, |r| tree.intersect(r, f32::INFINITY).is_some()),
        || count_hits(&pool, &rays, |r| flat.intersect(r, f32::INFINITY).is_some()),
    );
    // The two round differently: a ray grazing an edge may hit in one and not the other.
    anyhow::ensure!(
        a.abs_diff(b) * 1000 <= rays.len(),
        "{a} hits through two levels, {b} flattened"
    );
    let mrays = |s: f64| rays.len() as f64 / s / 1e6;
    let placed = &scene.instances;
    println!(
        "{}: {} triangles ({} placed once, {} meshes placed {} times); {} camera rays of its view, one thread, best of {}",
        scene.name,
        scene.triangle_count(),
        scene.mesh.triangles.len(),
        placed.meshes.len(),
        placed.placements().len(),
        rays.len(),
        repeat.max(1)
    );
    println!("| form | build ms | bytes (trees and placements) | closest Mrays/s |");
    println!("|---|---:|---:|---:|");
    println!(
        "| two levels | {:.1} | {} | {:.2} ({:.2}x) |",
        accel.build_ms(),
        accel.bytes() + placed.bytes(),
        mrays(two_s),
        flat_s / two_s
    );
    println!(
        "| flattened ({} triangles in one mesh) | {:.1} | {} | {:.2} |",
        flat_scene.mesh.triangles.len(),
        flat.stats.build_ms,
        flat.stats.binary_bytes + flat.stats.wide_bytes,
        mrays(flat_s)
    );
    Ok(())
}

fn refit_table(mesh: PathBuf, reach: f32, repeat: usize) -> Result<()> {
    if !(reach.is_finite() && reach >= 0.0) {
        anyhow::bail!("--move {reach}: expected a fraction of the mesh's size, 0 or more");
    }
    let scene = load_flat_scene(Some(&mesh), "report")?;
    let tris = &scene.mesh.triangles;
    let b = scene.mesh.bounds();
    let size = (Vec3::from(b.max) - Vec3::from(b.min)).length();
    let after = moved(tris, reach * size);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let options = BuildOptions::sah();
    let built = pool.install(|| Bvh::build(tris, &options));
    let (mut refit_ms, mut build_ms) = (f64::INFINITY, f64::INFINITY);
    let (mut refitted, mut rebuilt) = (built.clone(), built.clone());
    for round in 0..repeat.max(1) {
        eprintln!("  round {}/{}", round + 1, repeat.max(1));
        let mut r = built.clone();
        let t = Instant::now();
        pool.install(|| r.refit(&after))
            .map_err(anyhow::Error::msg)?;
        refit_ms = refit_ms.min(t.elapsed().as_secs_f64() * 1e3);
        refitted = r;
        let t = Instant::now();
        rebuilt = pool.install(|| Bvh::build(&after, &options));
        build_ms = build_ms.min(t.elapsed().as_secs_f64() * 1e3);
    }
    let rays = bench::canonical_rays(&Aabb::of_finite_points(after.iter().flatten().copied()));
    let speed = |bvh: &Bvh| {
        let mut best = f64::INFINITY;
        for _ in 0..repeat.max(1) {
            let t = Instant::now();
            let hits = pool.install(|| {
                rays.iter()
                    .filter(|r| bvh.intersect(r, f32::INFINITY).is_some())
                    .count()
            });
            std::hint::black_box(hits);
            best = best.min(t.elapsed().as_secs_f64());
        }
        rays.len() as f64 / best / 1e6
    };
    let (refit_speed, build_speed) = (speed(&refitted), speed(&rebuilt));
    println!(
        "{}: {} triangles, every vertex moved by up to {}% of the mesh's size ({:.4}) per axis; one thread, best of {}",
        scene.name,
        tris.len(),
        reach * 100.0,
        reach * size,
        repeat.max(1)
    );
    println!("| tree | ms | SAH cost | closest Mrays/s |");
    println!("|---|---:|---:|---:|");
    println!(
        "| built before the move | - | {:.2} | - |",
        built.stats.sah_cost
    );
    println!(
        "| refitted | {refit_ms:.2} | {:.2} | {refit_speed:.2} |",
        refitted.stats.sah_cost
    );
    println!(
        "| rebuilt | {build_ms:.2} | {:.2} | {build_speed:.2} |",
        rebuilt.stats.sah_cost
    );
    println!(
        "refit / rebuild: time {:.2}x, SAH cost {:.2}x, closest-hit speed {:.2}x",
        refit_ms / build_ms,
        refitted.stats.sah_cost / rebuilt.stats.sah_cost,
        refit_speed / build_speed
    );
    Ok(())
}

/// Runs the benchmark on the scene's canonical camera rays, progress on stderr.
fn measure(scene: &Scene, config: &BenchConfig) -> Result<bench::MeshBench> {
    let rays = bench::canonical_rays(&scene.mesh.bounds());
    bench::run(
        &scene.name,
        &scene.mesh.triangles,
        &rays,
        bench::CANONICAL_SIZE as usize,
        config,
        &mut |l| eprintln!("  {l}"),
    )
}

fn all_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

fn splits(meshes: Vec<PathBuf>, repeat: usize) -> Result<()> {
    let sources: Vec<Option<PathBuf>> = if meshes.is_empty() {
        vec![None]
    } else {
        meshes.into_iter().map(Some).collect()
    };
    let cores = all_threads();
    println!(
        "| scene | triangles | split | build ms | levels | leaves | SAH cost | Mrays/s 1 thread | Mrays/s {cores} threads | render ms 512x512 |"
    );
    println!("|---|---:|---|---:|---:|---:|---:|---:|---:|---:|");
    for src in &sources {
        let scene = load_flat_scene(src.as_deref(), "report")?;
        let config = BenchConfig {
            threads: vec![1, cores],
            repeat,
            ours: BenchConfig::ours(BuildOptions::sah()),
            obvhs: false,
            embree: false,
            packets: false,
            isa: None,
        };
        eprintln!("{}: measuring", scene.name);
        let out = measure(&scene, &config)?;
        for split in [SplitMethod::Median, SplitMethod::Sah] {
            let engine = format!("tracery-{split}");
            let row = |t: usize| {
                out.results
                    .iter()
                    .find(|r| r.engine == engine && r.threads == t)
            };
            let (Some(one), Some(all)) = (row(1), row(cores)) else {
                continue;
            };
            let stats = one.stats.expect("our engines report stats");
            let bvh = Bvh::build(
                &scene.mesh.triangles,
                &BuildOptions::sah().with_split(split),
            );
            let settings = RenderSettings {
                width: 512,
                height: 512,
                spp: 1,
                seed: 0,
                ..RenderSettings::default()
            };
            let mut best = f64::INFINITY;
            for _ in 0..repeat.max(1) {
                let start = Instant::now();
                render(&scene, &bvh, &settings, &|_| {})?;
                best = best.min(start.elapsed().as_secs_f64() * 1e3);
            }
            println!(
                "| {} | {} | {} | {:.1} | {} | {} | {:.2} | {:.2} | {:.2} | {:.1} |",
                scene.name,
                scene.triangle_count(),
                split,
                stats.build_ms,
                stats.levels,
                stats.leaves,
                stats.sah_cost,
                one.closest_mrays,
                all.closest_mrays,
                best
            );
        }
    }
    Ok(())
}

fn bins_table(mesh: PathBuf, bins: Vec<u32>, repeat: usize) -> Result<()> {
    let scene = load_flat_scene(Some(&mesh), "report")?;
    let mut ours = Vec::new();
    for &b in &bins {
        let options = BuildOptions {
            bins: b,
            ..BuildOptions::sah()
        };
        options.validate().map_err(anyhow::Error::msg)?;
        ours.push((format!("sah-{b}"), options));
    }
    // One run with every bin count as an engine, so builds and traces are interleaved and a
    // burst of load elsewhere on the machine does not favour one bin count.
    let config = BenchConfig {
        threads: vec![1],
        repeat,
        ours,
        obvhs: false,
        embree: false,
        packets: false,
        isa: None,
    };
    let out = measure(&scene, &config)?;
    println!(
        "| bins | build ms | SAH cost | levels | leaves | closest Mrays/s (1 thread) | nodes / ray | blocks / ray | nodes / hit | blocks / hit |"
    );
    println!("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for ((b, r), (_, options)) in bins.iter().zip(&out.results).zip(&config.ours) {
        let s = r.stats.expect("our engines report stats");
        let v = canonical_visits(&Bvh::build(&scene.mesh.triangles, options));
        println!(
            "| {b} | {:.1} | {:.2} | {} | {} | {:.2} | {:.3} | {:.3} | {:.3} | {:.3} |",
            r.build_ms,
            s.sah_cost,
            s.levels,
            s.leaves,
            r.closest_mrays,
            v.all.nodes as f64 / v.rays.max(1) as f64,
            v.all.blocks as f64 / v.rays.max(1) as f64,
            v.hits.nodes as f64 / v.hit_rays.max(1) as f64,
            v.hits.blocks as f64 / v.hit_rays.max(1) as f64,
        );
    }
    Ok(())
}

/// What the closest-hit walks of the canonical rays tested, over all of them and over those
/// that hit.
struct CanonicalVisits {
    rays: u64,
    hit_rays: u64,
    all: Visits,
    hits: Visits,
}

fn canonical_visits(bvh: &Bvh) -> CanonicalVisits {
    let rays = bench::canonical_rays(&bvh.bounds());
    let mut v = CanonicalVisits {
        rays: rays.len() as u64,
        hit_rays: 0,
        all: Visits::default(),
        hits: Visits::default(),
    };
    for ray in &rays {
        let mut one = Visits::default();
        let hit = bvh.intersect_counted(ray, f32::INFINITY, &mut one);
        v.all += one;
        if hit.is_some() {
            v.hit_rays += 1;
            v.hits += one;
        }
    }
    v
}

/// `x` with three significant digits (at least one decimal): a small mesh's build takes
/// microseconds.
fn three_digits(x: f64) -> String {
    let decimals = if x > 0.0 {
        (2 - x.log10().floor() as i32).clamp(1, 9) as usize
    } else {
        1
    };
    format!("{x:.decimals$}")
}

/// The thread counts the threads table measures: powers of two below `cores`, then `cores`.
fn thread_counts(cores: usize) -> Vec<usize> {
    let mut counts: Vec<usize> = std::iter::successors(Some(1usize), |t| Some(t * 2))
        .take_while(|&t| t < cores)
        .collect();
    counts.push(cores.max(1));
    counts
}

fn threads_table(
    scene: Option<PathBuf>,
    build: Option<PathBuf>,
    (width, height, spp): (u32, u32, u32),
    repeat: usize,
) -> Result<()> {
    let mut scene = load_flat_scene(scene.as_deref(), "report")?;
    scene.integrator = tracery::scene::Integrator::Path;
    let built = match &build {
        Some(p) => load_flat_scene(Some(p), "report")?,
        None => scene.clone(),
    };
    let settings = RenderSettings {
        width,
        height,
        spp,
        seed: 0,
        ..RenderSettings::default()
    };
    settings.validate().map_err(anyhow::Error::msg)?;
    let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
    let counts = thread_counts(all_threads());
    let pools = counts
        .iter()
        .map(|&t| rayon::ThreadPoolBuilder::new().num_threads(t).build())
        .collect::<Result<Vec<_>, _>>()?;
    eprintln!(
        "{}: path traced at {width}x{height}, {spp} spp; {} ({} triangles) built; threads {:?}",
        scene.name,
        built.name,
        built.mesh.triangles.len(),
        counts
    );
    // Interleaved rounds: every thread count once per round, so a burst of load elsewhere on
    // the machine costs them alike; the first round warms the pools and the caches, untimed.
    let mut best = vec![[f64::INFINITY; 2]; counts.len()]; // [render ms, build ms]
    for round in 0..=repeat.max(1) {
        for (k, pool) in pools.iter().enumerate() {
            eprintln!("  round {}: {} thread(s)", round, counts[k]);
            if round == 0 {
                pool.install(|| render(&scene, &bvh, &settings, &|_| {}))?;
                pool.install(|| Bvh::build(&built.mesh.triangles, &BuildOptions::sah()));
                continue;
            }
            let start = Instant::now();
            pool.install(|| render(&scene, &bvh, &settings, &|_| {}))?;
            best[k][0] = best[k][0].min(start.elapsed().as_secs_f64() * 1e3);
            let ms = build_ms(pool, || {
                Ok(Bvh::build(&built.mesh.triangles, &BuildOptions::sah()))
            })?;
            best[k][1] = best[k][1].min(ms);
        }
    }
    println!(
        "| threads | path tracing, ms per sample ({}, {width}x{height}) | speed-up | SAH build ms ({}) | speed-up |",
        scene.name, built.name
    );
    println!("|---:|---:|---:|---:|---:|");
    for (k, t) in counts.iter().enumerate() {
        let [render_ms, build] = best[k];
        println!(
            "| {t} | {} | {:.2}x | {} | {:.2}x |",
            three_digits(render_ms / spp as f64),
            best[0][0] / render_ms,
            three_digits(build),
            best[0][1] / build
        );
    }
    Ok(())
}

/// Time in ms of one `build` on `pool`; what it built is dropped after the clock stops.
fn build_ms<T: Send>(
    pool: &rayon::ThreadPool,
    build: impl FnOnce() -> Result<T> + Send,
) -> Result<f64> {
    let start = Instant::now();
    let built = pool.install(build)?;
    let ms = start.elapsed().as_secs_f64() * 1e3;
    drop(built);
    Ok(ms)
}

fn scaling(
    meshes: Vec<PathBuf>,
    generated: u32,
    repeat: usize,
    plot: Option<PathBuf>,
) -> Result<()> {
    let cores = all_threads();
    let mut inputs: Vec<(String, Vec<[glam::Vec3; 3]>)> = Vec::new();
    for m in &meshes {
        let scene = load_flat_scene(Some(m), "report")?;
        inputs.push((scene.name.clone(), scene.mesh.triangles));
    }
    if generated > 0 {
        let n = ((generated as f64 / 2.0).sqrt()).round() as u32;
        inputs.push((
            format!("terrain {n}x{n}"),
            tracery::geometry::shapes::terrain(n),
        ));
    }
    let embree = BenchConfig::embree_available();
    println!(
        "| mesh | triangles | ours 1 thread ms | ours {cores} threads ms | growth per doubling (1 thread) | ours {cores} threads over 1 |{}",
        if embree {
            format!(
                " Embree 1 thread ms | Embree {cores} threads ms | Embree growth per doubling | Embree {cores} threads over 1 | ours / Embree (1 thread) | ours / Embree ({cores} threads) |"
            )
        } else {
            String::new()
        }
    );
    println!(
        "|---|---:|---:|---:|---:|---:|{}",
        if embree {
            "---:|---:|---:|---:|---:|---:|"
        } else {
            ""
        }
    );
    let pools = [1, cores].map(|t| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(t).build();
        pool.map(|pool| (t, pool))
    });
    let pools = pools.into_iter().collect::<Result<Vec<_>, _>>()?;
    let mut rows: Vec<ScalingRow> = Vec::new();
    for (name, tris) in &inputs {
        eprintln!("{name}: {} triangles", tris.len());
        let buffers = embree.then(|| bench::embree::Buffers::of(tris));
        // Interleaved rounds, as in `tracery bench`: every engine on every pool once per
        // round, each figure its best round, so a burst of load from another tenant of the
        // machine costs both engines alike.
        let mut best = [[f64::INFINITY; 2]; 2]; // [ours, Embree][1 thread, all threads]
        for _ in 0..repeat.max(1) {
            for (p, (threads, pool)) in pools.iter().enumerate() {
                let ms = build_ms(pool, || Ok(Bvh::build(tris, &BuildOptions::sah())))?;
                best[0][p] = best[0][p].min(ms);
                if let Some(buffers) = &buffers {
                    // `rtcCommitScene` alone, on a device of its own, as `tracery bench` times
                    // it.
                    let device = bench::embree::Device::new(*threads, None)?;
                    let e = pool.install(|| bench::embree::Embree::build_on(&device, buffers))?;
                    best[1][p] = best[1][p].min(e.build_ms);
                }
            }
        }
        let row = ScalingRow {
            name: name.clone(),
            triangles: tris.len(),
            ours: best[0],
            embree: embree.then_some(best[1]),
        };
        let last = rows.last();
        let growth = |prev: Option<(usize, f64)>, ms: f64| {
            prev.and_then(|p| growth_per_doubling(p, row.triangles, ms))
                .map_or("-".into(), |g| format!("{g:.2}x"))
        };
        let [o1, on] = row.ours;
        print!(
            "| {name} | {} | {o1:.1} | {on:.1} | {} | {:.2}x |",
            row.triangles,
            growth(last.map(|l| (l.triangles, l.ours[0])), o1),
            o1 / on
        );
        if let Some([e1, en]) = row.embree {
            print!(
                " {e1:.1} | {en:.1} | {} | {:.2}x | {:.2}x | {:.2}x |",
                growth(last.and_then(|l| l.embree.map(|e| (l.triangles, e[0]))), e1),
                e1 / en,
                o1 / e1,
                on / en
            );
        }
        println!();
        rows.push(row);
    }
    if let Some(path) = plot {
        scaling::plot(&path, &rows, cores)?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}
