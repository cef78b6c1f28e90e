//! The benchmark of DESIGN.md: canonical camera rays, the rays and hits file formats, and our
//! builders traced side by side with the `obvhs` crate on the same rays.

use std::io::{BufReader, BufWriter, Read, Write};
use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use glam::Vec3;
use rayon::prelude::*;
use serde::Serialize;

use crate::bvh::{BuildOptions, Bvh, BvhStats, SplitMethod};
use crate::camera::CameraRays;
use crate::geometry::{Aabb, Ray};
use crate::scene::Camera;

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
    /// `tracery-sah`, `tracery-median`, `obvhs-bvh2` or `obvhs-cwbvh`.
    pub engine: String,
    /// Mesh name (file stem).
    pub mesh: String,
    /// Triangles in the mesh.
    pub triangles: usize,
    /// Threads used for tracing (builds are single-threaded for every engine).
    pub threads: usize,
    /// Build time in milliseconds (best of the repeats).
    pub build_ms: f64,
    /// Closest-hit throughput, millions of rays per second (best of the repeats).
    pub closest_mrays: f64,
    /// Any-hit (occlusion) throughput on the same rays, millions of rays per second.
    pub occluded_mrays: f64,
    /// Rays whose closest hit (triangle, or miss) equals the first engine's (`tracery-sah` by
    /// default), as a fraction.
    pub agreement: f64,
    /// Our BVH's statistics (only for our engines).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stats: Option<BvhStats>,
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
    pub peers: bool,
}

impl BenchConfig {
    /// Our two engines, `tracery-sah` and `tracery-median`, with `options` (split set per
    /// engine). `tracery-sah` comes first: the agreement column and the hits file use it.
    pub fn ours(options: BuildOptions) -> Vec<(String, BuildOptions)> {
        [SplitMethod::Sah, SplitMethod::Median]
            .map(|s| (format!("tracery-{s}"), options.with_split(s)))
            .into()
    }
}

/// A ray tracing engine under test: built once, traced many times.
trait Engine: Sync + Send {
    fn closest(&self, ray: &Ray) -> HitRecord;
    fn occluded(&self, ray: &Ray) -> bool;
}

impl Engine for Bvh {
    fn closest(&self, ray: &Ray) -> HitRecord {
        match self.intersect(ray, f32::INFINITY) {
            Some(h) => HitRecord {
                t: h.t,
                prim: h.prim,
            },
            None => HitRecord::MISS,
        }
    }
    fn occluded(&self, ray: &Ray) -> bool {
        Bvh::occluded(self, ray, f32::INFINITY)
    }
}

mod peers {
    //! The `obvhs` crate's BVH2 and CWBVH, each with triangles reordered into leaf order (as
    //! its examples recommend) and its own Möller-Trumbore triangle test.
    use glam_obvhs::Vec3A;
    use obvhs::ray::{Ray as ORay, RayHit};
    use obvhs::triangle::Triangle as OTri;

    use super::{Engine, HitRecord, Ray};

    pub(super) fn to_otris(tris: &[[glam::Vec3; 3]]) -> Vec<OTri> {
        let v = |p: glam::Vec3| Vec3A::new(p.x, p.y, p.z);
        tris.iter()
            .map(|t| OTri {
                v0: v(t[0]),
                v1: v(t[1]),
                v2: v(t[2]),
            })
            .collect()
    }

    fn oray(r: &Ray) -> ORay {
        ORay::new_inf(
            Vec3A::new(r.origin.x, r.origin.y, r.origin.z),
            Vec3A::new(r.dir.x, r.dir.y, r.dir.z),
        )
    }

    /// An obvhs BVH with its triangles in leaf order. Both kinds have the same traversal
    /// methods but no shared trait, hence the macro.
    macro_rules! obvhs_engine {
        ($name:ident, $bvh:ty) => {
            pub(super) struct $name {
                pub bvh: $bvh,
                pub tris: Vec<OTri>,
            }

            impl Engine for $name {
                fn closest(&self, ray: &Ray) -> HitRecord {
                    let mut hit = RayHit::none();
                    if self
                        .bvh
                        .ray_traverse(oray(ray), &mut hit, |r, id| self.tris[id].intersect(r))
                    {
                        HitRecord {
                            t: hit.t,
                            prim: self.bvh.primitive_indices[hit.primitive_id as usize],
                        }
                    } else {
                        HitRecord::MISS
                    }
                }
                fn occluded(&self, ray: &Ray) -> bool {
                    !self
                        .bvh
                        .ray_traverse_miss(oray(ray), |r, id| self.tris[id].intersect(r))
                }
            }
        };
    }

    obvhs_engine!(Bvh2, obvhs::bvh2::Bvh2);
    obvhs_engine!(Cwbvh, obvhs::cwbvh::CwBvh);
}

fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("a thread pool can be made")
}

/// Closest hits of all rays on the current rayon pool.
fn trace_closest(engine: &dyn Engine, rays: &[Ray]) -> Vec<HitRecord> {
    let mut out = vec![HitRecord::MISS; rays.len()];
    out.par_chunks_mut(1024)
        .zip(rays.par_chunks(1024))
        .for_each(|(o, r)| {
            for (o, r) in o.iter_mut().zip(r) {
                *o = engine.closest(r);
            }
        });
    out
}

fn trace_occluded(engine: &dyn Engine, rays: &[Ray]) -> usize {
    rays.par_chunks(1024)
        .map(|r| r.iter().filter(|r| engine.occluded(r)).count())
        .sum()
}

fn agreement(a: &[HitRecord], b: &[HitRecord]) -> f64 {
    if a.is_empty() {
        return 1.0;
    }
    a.iter().zip(b).filter(|(x, y)| x.prim == y.prim).count() as f64 / a.len() as f64
}

/// What [`run`] measured for one mesh, plus tracery-sah's closest hits (for `--hits-out`).
pub struct MeshBench {
    /// One row per engine and thread count.
    pub results: Vec<EngineResult>,
    /// The first engine's closest hits on the canonical rays (`tracery-sah` by default).
    pub sah_hits: Vec<HitRecord>,
}

/// A built engine under test and its best build time.
struct Entry {
    name: String,
    build_ms: f64,
    stats: Option<BvhStats>,
    engine: Box<dyn Engine>,
}

/// Builds one engine: its name, the engine, its stats (ours only).
type Builder<'a> = Box<dyn Fn() -> (Box<dyn Engine>, Option<BvhStats>) + Send + Sync + 'a>;

/// Builds every engine over `triangles` and traces `rays` with each thread count.
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
    config: &BenchConfig,
    progress: &mut dyn FnMut(&str),
) -> MeshBench {
    let one = pool(1);
    let mut builders: Vec<(String, Builder)> = Vec::new();
    for (name, options) in &config.ours {
        let options = *options;
        builders.push((
            name.clone(),
            Box::new(move || {
                let bvh = Bvh::build(triangles, &options);
                let stats = bvh.stats;
                (Box::new(bvh) as Box<dyn Engine>, Some(stats))
            }),
        ));
    }
    if config.peers {
        let otris = std::sync::Arc::new(peers::to_otris(triangles));
        // Each obvhs kind: build with the medium preset, then put its triangles in leaf order.
        macro_rules! peer {
            ($name:literal, $build:path, $engine:ident) => {{
                let o = otris.clone();
                builders.push((
                    $name.into(),
                    Box::new(move || {
                        let bvh = $build(
                            &o,
                            obvhs::BvhBuildParams::medium_build(),
                            &mut Duration::default(),
                        );
                        let tris = bvh
                            .primitive_indices
                            .iter()
                            .map(|&i| o[i as usize])
                            .collect();
                        (
                            Box::new(peers::$engine { bvh, tris }) as Box<dyn Engine>,
                            None,
                        )
                    }),
                ));
            }};
        }
        peer!(
            "obvhs-bvh2",
            obvhs::bvh2::builder::build_bvh2_from_tris,
            Bvh2
        );
        peer!(
            "obvhs-cwbvh",
            obvhs::cwbvh::builder::build_cwbvh_from_tris,
            Cwbvh
        );
    }

    // Builds, on one thread, interleaved. The obvhs build time is the builder call alone;
    // ours includes copying the triangles into leaf order.
    let mut entries: Vec<Entry> = Vec::new();
    for round in 0..config.repeat.max(1) {
        for (k, (name, build)) in builders.iter().enumerate() {
            progress(&format!(
                "{mesh_name}: building {name} (round {})",
                round + 1
            ));
            let start = Instant::now();
            let (engine, stats) = one.install(build);
            let ms = start.elapsed().as_secs_f64() * 1e3;
            match entries.get_mut(k) {
                Some(e) => {
                    e.build_ms = e.build_ms.min(ms);
                    e.engine = engine;
                }
                None => entries.push(Entry {
                    name: name.clone(),
                    build_ms: ms,
                    stats,
                    engine,
                }),
            }
        }
    }

    // Traces, interleaved over engines and thread counts.
    let pools: Vec<(usize, rayon::ThreadPool)> =
        config.threads.iter().map(|&t| (t, pool(t))).collect();
    let n = entries.len() * pools.len();
    let mut closest = vec![Duration::MAX; n];
    let mut occluded = vec![Duration::MAX; n];
    let mut hits: Vec<Option<Vec<HitRecord>>> = vec![None; n];
    for round in 0..config.repeat.max(1) {
        progress(&format!("{mesh_name}: tracing, round {}", round + 1));
        for (e, entry) in entries.iter().enumerate() {
            for (p, (_, pool)) in pools.iter().enumerate() {
                let k = e * pools.len() + p;
                let engine = &*entry.engine;
                let start = Instant::now();
                let h = pool.install(|| trace_closest(engine, rays));
                closest[k] = closest[k].min(start.elapsed());
                hits[k] = Some(h);
                let start = Instant::now();
                pool.install(|| trace_occluded(engine, rays));
                occluded[k] = occluded[k].min(start.elapsed());
            }
        }
    }

    let reference = hits[0].clone().unwrap_or_default();
    let mut results = Vec::new();
    for (e, entry) in entries.iter().enumerate() {
        for (p, (threads, _)) in pools.iter().enumerate() {
            let k = e * pools.len() + p;
            let mut stats = entry.stats;
            if let Some(s) = &mut stats {
                s.build_ms = entry.build_ms;
            }
            results.push(EngineResult {
                engine: entry.name.clone(),
                mesh: mesh_name.to_string(),
                triangles: triangles.len(),
                threads: *threads,
                build_ms: entry.build_ms,
                closest_mrays: rays.len() as f64 / closest[k].as_secs_f64() / 1e6,
                occluded_mrays: rays.len() as f64 / occluded[k].as_secs_f64() / 1e6,
                agreement: agreement(&reference, hits[k].as_deref().unwrap_or_default()),
                stats,
            });
        }
    }
    MeshBench {
        results,
        sah_hits: reference,
    }
}
