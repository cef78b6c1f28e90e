//! The benchmark of DESIGN.md: canonical camera rays, the rays and hits file formats, and our
//! BVH traced side by side with the engines users would pick instead, on the same rays:
//! Embree 3 (`embree`, single rays and its own coherent 16-ray packets; loaded at run time
//! where it is installed) and the `obvhs` crate (`obvhs`).
//!
//! Triangles with a NaN or infinite vertex are left out before any engine sees them (some
//! peers would index out of bounds on them), and counted.

pub mod chart;
pub mod embree;
mod engines;
mod obvhs;
pub mod scaling;
pub mod secondary;

use std::io::{BufReader, BufWriter, Read, Write};
use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use glam::Vec3;
use serde::Serialize;

use crate::bvh::wide::Kernel;
use crate::bvh::{BuildOptions, Bvh, BvhStats, SplitMethod};
use crate::camera::CameraRays;
use crate::geometry::{Aabb, Ray};
use crate::scene::Camera;
use engines::Engine;

/// Side of the square benchmark image.
pub const CANONICAL_SIZE: u32 = 1024;

/// The canonical benchmark rays for a mesh with bounds `b`: one ray through each pixel centre
/// of a 1024 x 1024 image from [`Camera::canonical`], row 0 at the top, unit directions.
pub fn canonical_rays(b: &Aabb) -> Vec<Ray> {
    CameraRays::new(&Camera::canonical(b), CANONICAL_SIZE, CANONICAL_SIZE).pixel_center_rays()
}

/// A closest-hit result as stored in a hits file: `t = +inf`, `prim = u32::MAX` on a miss.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HitRecord {
    /// Distance, `+inf` on a miss.
    pub t: f32,
    /// Triangle index in file order, `u32::MAX` on a miss.
    pub prim: u32,
}

impl HitRecord {
    /// The record of a miss.
    pub const MISS: HitRecord = HitRecord {
        t: f32::INFINITY,
        prim: u32::MAX,
    };
}

/// Writes a rays file: `u32 count`, then `count` records of six `f32` (origin, direction),
/// little-endian.
pub fn write_rays(path: &Path, rays: &[Ray]) -> Result<()> {
    let mut w = BufWriter::new(
        std::fs::File::create(path)
            .with_context(|| format!("{}: cannot create", path.display()))?,
    );
    w.write_all(&(rays.len() as u32).to_le_bytes())?;
    for r in rays {
        for v in r.origin.to_array().into_iter().chain(r.dir.to_array()) {
            w.write_all(&v.to_le_bytes())?;
        }
    }
    w.flush()
        .with_context(|| format!("{}: cannot write", path.display()))
}

/// Writes the triangles the engines are given (the finite ones of `triangles`, in order) as a
/// little-endian `u32` count and nine `f32` a triangle: the input of the C program that times
/// Embree's build alone (`src/bench/embree_build.c`).
pub fn write_triangles(path: &Path, triangles: &[[Vec3; 3]]) -> Result<()> {
    let finite: Vec<&[Vec3; 3]> = triangles
        .iter()
        .filter(|t| t.iter().all(|v| v.is_finite()))
        .collect();
    let mut w = BufWriter::new(
        std::fs::File::create(path)
            .with_context(|| format!("{}: cannot create", path.display()))?,
    );
    w.write_all(&(finite.len() as u32).to_le_bytes())?;
    for v in finite.into_iter().flatten() {
        for x in v.to_array() {
            w.write_all(&x.to_le_bytes())?;
        }
    }
    w.flush()
        .with_context(|| format!("{}: cannot write", path.display()))
}

/// Reads a rays file written by [`write_rays`] (or another engine).
pub fn read_rays(path: &Path) -> Result<Vec<Ray>> {
    let mut r = BufReader::new(
        std::fs::File::open(path).with_context(|| format!("{}: cannot open", path.display()))?,
    );
    let mut word = [0u8; 4];
    r.read_exact(&mut word)
        .with_context(|| format!("{}: no ray count", path.display()))?;
    let count = u32::from_le_bytes(word) as usize;
    let mut buf = Vec::new();
    r.read_to_end(&mut buf)?;
    if buf.len() != count * 24 {
        bail!(
            "{}: header says {count} rays ({} bytes) but {} bytes follow",
            path.display(),
            count * 24,
            buf.len()
        );
    }
    Ok(buf
        .chunks_exact(24)
        .map(|c| {
            let f = |i: usize| f32::from_le_bytes(c[i * 4..i * 4 + 4].try_into().unwrap());
            Ray::new(Vec3::new(f(0), f(1), f(2)), Vec3::new(f(3), f(4), f(5)))
        })
        .collect())
}

/// Writes a hits file: `u32 count`, then `count` records of `f32 t`, `u32 prim`.
pub fn write_hits(path: &Path, hits: &[HitRecord]) -> Result<()> {
    let mut w = BufWriter::new(
        std::fs::File::create(path)
            .with_context(|| format!("{}: cannot create", path.display()))?,
    );
    w.write_all(&(hits.len() as u32).to_le_bytes())?;
    for h in hits {
        w.write_all(&h.t.to_le_bytes())?;
        w.write_all(&h.prim.to_le_bytes())?;
    }
    w.flush()
        .with_context(|| format!("{}: cannot write", path.display()))
}

/// One engine's figures on one mesh at one thread count.
#[derive(Clone, Debug, Serialize)]
pub struct EngineResult {
    /// `tracery-sah`, `tracery-median`, `embree`, `embree-packet16`, `obvhs-bvh2`, ...
    pub engine: String,
    /// Mesh name (file stem).
    pub mesh: String,
    /// Triangles the engines were given (the mesh's finite triangles).
    pub triangles: usize,
    /// Threads used for building and tracing (obvhs builds on one thread whatever the count).
    pub threads: usize,
    /// Build time in milliseconds with that many threads (best of the repeats).
    pub build_ms: f64,
    /// Closest-hit throughput, millions of rays per second (best of the repeats).
    pub closest_mrays: f64,
    /// Any-hit (occlusion) throughput on the same rays, millions of rays per second.
    pub occluded_mrays: f64,
    /// The median round's closest-hit time over the fastest's (1 with one round): how much
    /// the machine moved this engine's figure during the run. On a shared machine a core can
    /// run slowly for seconds, which shows here before it shows in a ratio.
    pub closest_spread: f64,
    /// Rays whose closest hit (triangle, or miss) equals the first engine's (`tracery-sah` by
    /// default), as a fraction; exact duplicate triangles count as one.
    pub agreement: f64,
    /// Our BVH's statistics (only for our engines).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stats: Option<BvhStats>,
    /// The instruction set the engine traced with: our kernel's name, the one Embree was held
    /// to (`None` when left to choose its own), `None` for obvhs.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub isa: Option<String>,
    /// One thread, single rays: the rates on the rays that hit the mesh and on those that miss
    /// it, apart (the one-thread row of each single-ray engine; `None` for the others).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub split: Option<SplitRates>,
    /// One thread: the rates on the secondary rays made from the canonical hits
    /// ([`secondary`]): single rays for the one-thread row of each single-ray engine, and a
    /// batched call for a packet engine with a query for streams of incoherent rays (Embree's
    /// `rtcIntersect1M` / `rtcOccluded1M`, 1024 rays a call); `None` for the others.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub secondary: Option<SecondaryRates>,
}

/// An engine's one-thread rates on the secondary rays of [`secondary::secondary_rays`] (one
/// bounce and one shadow ray from each canonical hit, as a path tracer makes them), in
/// millions of rays per second, and its answers beside the first engine's.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct SecondaryRates {
    /// Bounce rays, and as many shadow rays.
    pub rays: usize,
    /// Closest hits of the bounce rays.
    pub bounce_closest_mrays: f64,
    /// Occlusion of the shadow rays.
    pub shadow_occluded_mrays: f64,
    /// Bounce rays whose closest hit (triangle, or miss) equals the first engine's, as a
    /// fraction (exact duplicate triangles count as one).
    pub bounce_agreement: f64,
    /// Shadow rays this engine found blocked.
    pub shadow_blocked: usize,
}

/// An engine's one-thread rates on the canonical rays split by whether they hit the mesh (as
/// the first engine, `tracery-sah`, answers), in millions of rays per second. An image's rays
/// are mostly of one kind or the other, and engines differ most on rays that leave at the
/// root: this says which kind a whole-image figure is made of.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct SplitRates {
    /// Rays that hit the mesh.
    pub hit_rays: usize,
    /// Rays that miss it.
    pub miss_rays: usize,
    /// Closest hits of the rays that hit.
    pub closest_hit_mrays: f64,
    /// Closest hits of the rays that miss.
    pub closest_miss_mrays: f64,
    /// Occlusion of the rays that hit.
    pub occluded_hit_mrays: f64,
    /// Occlusion of the rays that miss.
    pub occluded_miss_mrays: f64,
}

/// Settings of a benchmark run.
#[derive(Clone, Debug)]
pub struct BenchConfig {
    /// Thread counts to trace with (for example `[1, 2]`).
    pub threads: Vec<usize>,
    /// Each measurement is repeated this many times and the best kept.
    pub repeat: usize,
    /// Our engines: a name and the build options of each (see [`BenchConfig::ours`]).
    pub ours: Vec<(String, BuildOptions)>,
    /// Also measure the `obvhs` crate.
    pub obvhs: bool,
    /// Also measure Embree (single rays and 16-ray packets); ignored without the `embree`
    /// feature.
    pub embree: bool,
    /// Also measure our packets of camera-ray tiles (`tracery-packet`, built as the first of
    /// `ours`).
    pub packets: bool,
    /// The instruction set our kernels and Embree's are held to (what a CPU without the wider
    /// ones would see); `None`: each engine's fastest on this CPU. The caller checks that this
    /// CPU runs it. Embree has no scalar kernels: held to `scalar`, it runs its SSE2 ones.
    /// obvhs is compiled for the target's baseline (SSE2 on x86-64) either way.
    pub isa: Option<Kernel>,
}

impl BenchConfig {
    /// Our two engines, `tracery-sah` and `tracery-median`, with `options` (split set per
    /// engine). `tracery-sah` comes first: the agreement column and the hits file use it.
    pub fn ours(options: BuildOptions) -> Vec<(String, BuildOptions)> {
        [SplitMethod::Sah, SplitMethod::Median]
            .map(|s| (format!("tracery-{s}"), options.with_split(s)))
            .into()
    }

    /// True when Embree 3 can be loaded on this machine ([`embree::available`] says why not).
    pub fn embree_available() -> bool {
        embree::available().is_ok()
    }
}

/// `bvh` held to the kernel `isa` names (unchanged for `None`).
fn held_to(mut bvh: Bvh, isa: Option<Kernel>) -> Result<Bvh> {
    if let Some(k) = isa {
        bvh.set_kernel(k).map_err(anyhow::Error::msg)?;
    }
    Ok(bvh)
}

fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("a thread pool can be made")
}

/// The median of `times` (the slower middle one of an even count); zero for none.
fn median(times: &mut [Duration]) -> Duration {
    times.sort_unstable();
    times.get(times.len() / 2).copied().unwrap_or_default()
}

/// For each triangle, the lowest index of a triangle with the same three vertices (in any
/// order): scanned meshes hold exact duplicates (1,489 in the fetched dragon), and a ray that
/// hits one copy hits the other at the same distance, so engines may name either.
fn first_copies(triangles: &[[Vec3; 3]]) -> Vec<u32> {
    let mut seen: std::collections::HashMap<[[u32; 3]; 3], u32> = Default::default();
    triangles
        .iter()
        .enumerate()
        .map(|(i, t)| {
            let mut key = t.map(|v| v.to_array().map(f32::to_bits));
            key.sort_unstable();
            *seen.entry(key).or_insert(i as u32)
        })
        .collect()
}

/// The share of rays whose closest hit names the same triangle (or a copy of it, see
/// [`first_copies`]), or that both miss.
fn agreement(a: &[HitRecord], b: &[HitRecord], copies: &[u32]) -> f64 {
    if a.is_empty() {
        return 1.0;
    }
    let same = |x: u32, y: u32| {
        x == y
            || (copies.get(x as usize).is_some()
                && copies.get(x as usize) == copies.get(y as usize))
    };
    a.iter()
        .zip(b)
        .filter(|(x, y)| same(x.prim, y.prim))
        .count() as f64
        / a.len() as f64
}

/// What [`run`] measured for one mesh, plus tracery-sah's closest hits (for `--hits-out`).
pub struct MeshBench {
    /// One row per engine and thread count.
    pub results: Vec<EngineResult>,
    /// The first engine's closest hits on the canonical rays (`tracery-sah` by default), with
    /// triangle indices of the caller's list.
    pub sah_hits: Vec<HitRecord>,
    /// Triangles left out before the engines were built (a NaN or infinite vertex).
    pub excluded: usize,
}

/// A built engine under test and its best build time per thread count.
struct Entry {
    name: String,
    build_ms: Vec<f64>,
    stats: Option<BvhStats>,
    engine: Box<dyn Engine>,
}

/// Builds one engine with a number of threads (on a rayon pool of that size): the engine and
/// its stats (ours only); an error when a peer cannot be built (Embree's library refusing the
/// CPU, say).
type Builder<'a> =
    Box<dyn Fn(usize) -> Result<(Box<dyn Engine>, Option<BvhStats>)> + Send + Sync + 'a>;

/// Builds every engine over the finite triangles of `triangles` and traces `rays` (a row-major
/// image `width` rays wide, which packet engines trace in tiles) with each thread count.
/// `progress` receives a line per step.
///
/// Measurements are interleaved: each round builds every engine once, then traces with every
/// engine and thread count once, and each figure keeps its best round. A burst of load from
/// another tenant of a shared machine then costs every engine a round, not one engine all of
/// its runs, so the ratios between engines stay fair.
pub fn run(
    mesh_name: &str,
    triangles: &[[Vec3; 3]],
    rays: &[Ray],
    width: usize,
    config: &BenchConfig,
    progress: &mut dyn FnMut(&str),
) -> Result<MeshBench> {
    // Only finite triangles reach the engines; `ids` maps their indices back.
    let (finite, ids): (Vec<[Vec3; 3]>, Vec<u32>) = triangles
        .iter()
        .enumerate()
        .filter(|(_, t)| t.iter().all(|v| v.is_finite()))
        .map(|(i, t)| (*t, i as u32))
        .unzip();
    let excluded = triangles.len() - finite.len();
    if excluded > 0 {
        progress(&format!(
            "{mesh_name}: {excluded} triangles with NaN or infinite vertices left out for every engine"
        ));
    }
    let tris = &finite[..];

    let builders = builders(tris, config)?;
    // Builds, interleaved, with each thread count. A peer's build time is its builder call
    // (plus putting its triangles in leaf order for obvhs; for Embree its scene's build, not
    // the device's creation); ours includes the 8-wide layout with its triangle blocks (the
    // tree's one copy of the triangles). Each engine is dropped as soon as its build is timed: Embree builds on
    // as many threads as the live device asking for the most (`getMaxNumThreads` in its
    // `device.cpp`), so a two-thread device kept alive would make the next one-thread build
    // run on two threads.
    let pools: Vec<(usize, rayon::ThreadPool)> =
        config.threads.iter().map(|&t| (t, pool(t))).collect();
    let (build_ms, stats) = time_builds(mesh_name, &builders, &pools, config.repeat, progress)?;
    let entries = engines_to_trace(mesh_name, &builders, &pools, build_ms, stats, progress)?;
    let one = pools.iter().position(|(t, _)| *t == 1);
    let sets = RaySets::new(
        mesh_name, tris, rays, width, &entries, &pools, one, progress,
    );
    let timings = Timings::measure(
        mesh_name,
        &entries,
        &pools,
        one,
        rays,
        width,
        &sets,
        config.repeat,
        progress,
    );
    let (results, reference) = results(
        mesh_name,
        triangles,
        finite.len(),
        &ids,
        rays,
        &entries,
        &pools,
        one,
        &sets,
        timings,
    );
    Ok(MeshBench {
        results,
        sah_hits: reference,
        excluded,
    })
}

/// The builders of every engine `config` asks for, over `tris` (an error where Embree cannot
/// make a device).
fn builders<'a>(tris: &'a [[Vec3; 3]], config: &BenchConfig) -> Result<Vec<(String, Builder<'a>)>> {
    let isa = config.isa;
    let mut builders: Vec<(String, Builder)> = Vec::new();
    for (name, options) in &config.ours {
        let options = *options;
        builders.push((
            name.clone(),
            Box::new(move |_| {
                let bvh = held_to(Bvh::build(tris, &options), isa)?;
                let stats = bvh.stats;
                Ok((Box::new(bvh) as Box<dyn Engine>, Some(stats)))
            }),
        ));
    }
    if config.packets {
        let options = config.ours.first().map_or(BuildOptions::sah(), |o| o.1);
        builders.push((
            "tracery-packet".into(),
            Box::new(move |_| {
                let bvh = held_to(Bvh::build(tris, &options), isa)?;
                let stats = bvh.stats;
                Ok((
                    Box::new(engines::Packets(bvh)) as Box<dyn Engine>,
                    Some(stats),
                ))
            }),
        ));
    }
    if config.embree && BenchConfig::embree_available() {
        // As Embree's users time a build: the triangles' buffers made once, `rtcCommitScene`
        // alone timed. Each build gets a device of its own, made before it and not timed:
        // Embree's thread count is the process's (the live device asking for the most sets
        // it), so a one-thread build cannot run beside a live two-thread device.
        let buffers = embree::Buffers::of(tris);
        let build = move |threads: usize| -> Result<embree::Embree> {
            embree::Embree::build_on(&embree::Device::new(threads, isa)?, &buffers)
        };
        let packets = build.clone();
        builders.push((
            "embree".into(),
            Box::new(move |threads| Ok((Box::new(build(threads)?) as Box<dyn Engine>, None))),
        ));
        builders.push((
            "embree-packet16".into(),
            Box::new(move |threads| {
                let e = embree::EmbreePackets(packets(threads)?);
                Ok((Box::new(e) as Box<dyn Engine>, None))
            }),
        ));
    }
    if config.obvhs {
        builders.push((
            "obvhs-bvh2".into(),
            Box::new(move |_| Ok((Box::new(obvhs::Bvh2::build(tris)) as Box<dyn Engine>, None))),
        ));
        builders.push((
            "obvhs-cwbvh".into(),
            Box::new(move |_| Ok((Box::new(obvhs::Cwbvh::build(tris)) as Box<dyn Engine>, None))),
        ));
    }
    Ok(builders)
}

/// Builds every engine on every pool, `repeat` rounds interleaved, each engine dropped as soon
/// as its build is timed: each engine's best build time per pool, and its stats (ours only).
#[allow(clippy::type_complexity)]
fn time_builds(
    mesh_name: &str,
    builders: &[(String, Builder)],
    pools: &[(usize, rayon::ThreadPool)],
    repeat: usize,
    progress: &mut dyn FnMut(&str),
) -> Result<(Vec<Vec<f64>>, Vec<Option<BvhStats>>)> {
    let mut build_ms = vec![vec![f64::INFINITY; pools.len()]; builders.len()];
    let mut stats = vec![None; builders.len()];
    for round in 0..repeat.max(1) {
        for (k, (name, build)) in builders.iter().enumerate() {
            for (p, (threads, pool)) in pools.iter().enumerate() {
                progress(&format!(
                    "{mesh_name}: building {name} on {threads} thread(s) (round {})",
                    round + 1
                ));
                let start = Instant::now();
                let (engine, s) = pool.install(|| build(*threads))?;
                let ms = engine
                    .build_ms()
                    .unwrap_or(start.elapsed().as_secs_f64() * 1e3);
                drop(engine);
                build_ms[k][p] = build_ms[k][p].min(ms);
                stats[k] = stats[k].or(s);
            }
        }
    }
    Ok((build_ms, stats))
}

/// The engines to trace with, built once more (untimed) with the most threads; tracing runs
/// on the caller's threads, whatever the build used.
fn engines_to_trace(
    mesh_name: &str,
    builders: &[(String, Builder)],
    pools: &[(usize, rayon::ThreadPool)],
    mut build_ms: Vec<Vec<f64>>,
    stats: Vec<Option<BvhStats>>,
    progress: &mut dyn FnMut(&str),
) -> Result<Vec<Entry>> {
    let mut entries: Vec<Entry> = Vec::with_capacity(builders.len());
    for (k, (name, build)) in builders.iter().enumerate() {
        let (threads, pool) = pools.last().expect("at least one thread count");
        progress(&format!("{mesh_name}: building {name} to trace with"));
        let (engine, _) = pool.install(|| build(*threads))?;
        entries.push(Entry {
            name: name.clone(),
            build_ms: std::mem::take(&mut build_ms[k]),
            stats: stats[k],
            engine,
        });
    }
    Ok(entries)
}

/// The rays traced besides the canonical ones, made from the first engine's hits with one
/// thread: the canonical rays that hit and those that miss, each in image order (for the
/// single-ray rates apart, `SplitRates`), and the secondary rays (`SecondaryRates`). Empty
/// without a one-thread pool.
struct RaySets {
    hits: Vec<Ray>,
    misses: Vec<Ray>,
    second: secondary::SecondaryRays,
}

impl RaySets {
    #[allow(clippy::too_many_arguments)]
    fn new(
        mesh_name: &str,
        tris: &[[Vec3; 3]],
        rays: &[Ray],
        width: usize,
        entries: &[Entry],
        pools: &[(usize, rayon::ThreadPool)],
        one: Option<usize>,
        progress: &mut dyn FnMut(&str),
    ) -> RaySets {
        let (hits, misses, second): (Vec<Ray>, Vec<Ray>, secondary::SecondaryRays) = match (
            one,
            entries.first(),
        ) {
            (Some(p), Some(first)) => {
                progress(&format!(
                    "{mesh_name}: splitting the rays into hits and misses, and making secondary rays"
                ));
                let mut first_hits = vec![HitRecord::MISS; rays.len()];
                pools[p].1.install(|| {
                    engines::trace_closest(&*first.engine, rays, width, &mut first_hits)
                });
                let bounds = Aabb::of_finite_points(tris.iter().flatten().copied());
                let second = secondary::secondary_rays(tris, rays, &first_hits, &bounds);
                let (h, m): (Vec<_>, Vec<_>) = rays
                    .iter()
                    .zip(&first_hits)
                    .partition(|(_, h)| h.prim != HitRecord::MISS.prim);
                (
                    h.into_iter().map(|(r, _)| *r).collect(),
                    m.into_iter().map(|(r, _)| *r).collect(),
                    second,
                )
            }
            _ => Default::default(),
        };
        RaySets {
            hits,
            misses,
            second,
        }
    }
}

/// What the tracing rounds measured, per engine and pool (`e * pools + p`) or per engine.
struct Timings {
    /// Best and every round's time of the canonical rays' closest hits.
    closest: Vec<Duration>,
    closest_rounds: Vec<Vec<Duration>>,
    /// Best time of their occlusion.
    occluded: Vec<Duration>,
    /// Their closest hits, written in place each round.
    hits: Vec<Vec<HitRecord>>,
    /// Per engine: best times of closest hit, closest miss, occluded hit, occluded miss.
    split: Vec<[Duration; 4]>,
    /// Per engine: best times of the bounce rays' closest hits and the shadow rays'
    /// occlusion, the bounce rays' hits and the shadow rays blocked.
    second_times: Vec<[Duration; 2]>,
    second_hits: Vec<Vec<HitRecord>>,
    second_blocked: Vec<usize>,
}

impl Timings {
    /// Traces, interleaved over engines and thread counts, `repeat` rounds.
    #[allow(clippy::too_many_arguments)]
    fn measure(
        mesh_name: &str,
        entries: &[Entry],
        pools: &[(usize, rayon::ThreadPool)],
        one: Option<usize>,
        rays: &[Ray],
        width: usize,
        sets: &RaySets,
        repeat: usize,
        progress: &mut dyn FnMut(&str),
    ) -> Timings {
        let (hit_rays, miss_rays, second) = (&sets.hits, &sets.misses, &sets.second);
        let n = entries.len() * pools.len();
        let mut closest = vec![Duration::MAX; n];
        let mut closest_rounds = vec![Vec::with_capacity(repeat.max(1)); n];
        let mut occluded = vec![Duration::MAX; n];
        // Written in place each round: allocating (and faulting in) 8 MB of fresh records inside
        // the timed call cost every engine the same 2-3 ms, which pulled every ratio towards 1.
        let mut hits = vec![vec![HitRecord::MISS; rays.len()]; n];
        // Per engine: best times of closest hit, closest miss, occluded hit, occluded miss.
        let mut split = vec![[Duration::MAX; 4]; entries.len()];
        let mut split_out = vec![HitRecord::MISS; hit_rays.len().max(miss_rays.len())];
        // Per engine: best times of the bounce rays' closest hits and the shadow rays' occlusion,
        // the bounce rays' hits and the shadow rays blocked.
        let mut second_times = vec![[Duration::MAX; 2]; entries.len()];
        let mut second_hits = vec![Vec::new(); entries.len()];
        let mut second_blocked = vec![0usize; entries.len()];
        for round in 0..repeat.max(1) {
            progress(&format!("{mesh_name}: tracing, round {}", round + 1));
            for (e, entry) in entries.iter().enumerate() {
                for (p, (_, pool)) in pools.iter().enumerate() {
                    let k = e * pools.len() + p;
                    let engine = &*entry.engine;
                    let start = Instant::now();
                    pool.install(|| engines::trace_closest(engine, rays, width, &mut hits[k]));
                    let took = start.elapsed();
                    closest[k] = closest[k].min(took);
                    closest_rounds[k].push(took);
                    let start = Instant::now();
                    pool.install(|| engines::trace_occluded(engine, rays, width));
                    occluded[k] = occluded[k].min(start.elapsed());
                }
                if let Some(p) = one
                    && entry.engine.tile().is_none()
                {
                    let (engine, pool) = (&*entry.engine, &pools[p].1);
                    for (i, set) in [hit_rays, miss_rays].into_iter().enumerate() {
                        let out = &mut split_out[..set.len()];
                        let start = Instant::now();
                        pool.install(|| engines::trace_closest(engine, set, width, out));
                        split[e][i] = split[e][i].min(start.elapsed());
                        let start = Instant::now();
                        pool.install(|| engines::trace_occluded(engine, set, width));
                        split[e][2 + i] = split[e][2 + i].min(start.elapsed());
                    }
                }
                // The secondary rays: one by one on a single-ray engine, by the batched query on
                // a packet engine that has one (the other packet engines get no figure).
                let single = entry.engine.tile().is_none();
                if let Some(p) = one
                    && (single || entry.engine.batched())
                    && !second.bounce.is_empty()
                {
                    let (engine, pool) = (&*entry.engine, &pools[p].1);
                    let out = &mut second_hits[e];
                    out.resize(second.bounce.len(), HitRecord::MISS);
                    let start = Instant::now();
                    pool.install(|| {
                        if single {
                            engines::trace_closest_incoherent(engine, &second.bounce, out)
                        } else {
                            engines::trace_closest_batched(engine, &second.bounce, out)
                        }
                    });
                    second_times[e][0] = second_times[e][0].min(start.elapsed());
                    let start = Instant::now();
                    let blocked = pool.install(|| {
                        if single {
                            engines::trace_occluded(engine, &second.shadow, width)
                        } else {
                            engines::trace_occluded_batched(engine, &second.shadow)
                        }
                    });
                    second_times[e][1] = second_times[e][1].min(start.elapsed());
                    second_blocked[e] = blocked;
                }
            }
        }
        Timings {
            closest,
            closest_rounds,
            occluded,
            hits,
            split,
            second_times,
            second_hits,
            second_blocked,
        }
    }
}

/// One row per engine and pool, the hits naming triangles of the caller's `triangles` (the
/// finite ones had `ids` there), and the first engine's hits (the reference of agreement).
#[allow(clippy::too_many_arguments)]
fn results(
    mesh_name: &str,
    triangles: &[[Vec3; 3]],
    finite: usize,
    ids: &[u32],
    rays: &[Ray],
    entries: &[Entry],
    pools: &[(usize, rayon::ThreadPool)],
    one: Option<usize>,
    sets: &RaySets,
    timings: Timings,
) -> (Vec<EngineResult>, Vec<HitRecord>) {
    let Timings {
        closest,
        mut closest_rounds,
        occluded,
        hits,
        split,
        second_times,
        second_hits,
        second_blocked,
    } = timings;
    let (hit_rays, miss_rays, second) = (&sets.hits, &sets.misses, &sets.second);
    // Hits name triangles of the caller's list.
    let map_back = |h: &[HitRecord]| -> Vec<HitRecord> {
        h.iter()
            .map(|r| match ids.get(r.prim as usize) {
                Some(&id) => HitRecord { t: r.t, prim: id },
                None => *r,
            })
            .collect()
    };
    let reference = map_back(&hits[0]);
    let copies = first_copies(triangles);
    let second_reference = second_hits.first().map(|h| map_back(h)).unwrap_or_default();
    let mut results = Vec::new();
    for (e, entry) in entries.iter().enumerate() {
        for (p, (threads, _)) in pools.iter().enumerate() {
            let k = e * pools.len() + p;
            let mut stats = entry.stats;
            if let Some(s) = &mut stats {
                s.build_ms = entry.build_ms[p];
            }
            results.push(EngineResult {
                engine: entry.name.clone(),
                mesh: mesh_name.to_string(),
                triangles: finite,
                threads: *threads,
                build_ms: entry.build_ms[p],
                closest_mrays: rays.len() as f64 / closest[k].as_secs_f64() / 1e6,
                occluded_mrays: rays.len() as f64 / occluded[k].as_secs_f64() / 1e6,
                closest_spread: median(&mut closest_rounds[k]).as_secs_f64()
                    / closest[k].as_secs_f64(),
                agreement: agreement(&reference, &map_back(&hits[k]), &copies),
                isa: entry.engine.isa().map(str::to_string),
                stats,
                split: (Some(p) == one
                    && split[e][0] != Duration::MAX
                    && !hit_rays.is_empty()
                    && !miss_rays.is_empty())
                .then(|| {
                    let rate = |n: usize, d: Duration| n as f64 / d.as_secs_f64() / 1e6;
                    SplitRates {
                        hit_rays: hit_rays.len(),
                        miss_rays: miss_rays.len(),
                        closest_hit_mrays: rate(hit_rays.len(), split[e][0]),
                        closest_miss_mrays: rate(miss_rays.len(), split[e][1]),
                        occluded_hit_mrays: rate(hit_rays.len(), split[e][2]),
                        occluded_miss_mrays: rate(miss_rays.len(), split[e][3]),
                    }
                }),
                secondary: (Some(p) == one && second_times[e][0] != Duration::MAX).then(|| {
                    let n = second.bounce.len();
                    let rate = |d: Duration| n as f64 / d.as_secs_f64() / 1e6;
                    SecondaryRates {
                        rays: n,
                        bounce_closest_mrays: rate(second_times[e][0]),
                        shadow_occluded_mrays: rate(second_times[e][1]),
                        bounce_agreement: agreement(
                            &second_reference,
                            &map_back(&second_hits[e]),
                            &copies,
                        ),
                        shadow_blocked: second_blocked[e],
                    }
                }),
            });
        }
    }
    (results, reference)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_median_round_is_the_middle_one_or_the_slower_middle_one() {
        let ms = |v: &[u64]| {
            v.iter()
                .map(|&m| Duration::from_millis(m))
                .collect::<Vec<_>>()
        };
        assert_eq!(median(&mut ms(&[30, 10, 20])), Duration::from_millis(20));
        assert_eq!(median(&mut ms(&[10, 40])), Duration::from_millis(40));
        assert_eq!(
            median(&mut ms(&[50, 10, 11, 12, 90])),
            Duration::from_millis(12)
        );
        assert_eq!(median(&mut []), Duration::ZERO);
    }
}
