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
    /// Rays whose closest hit (triangle, or miss) equals `tracery-sah`'s, as a fraction.
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
    /// Options for our builders (the split method is set per engine).
    pub options: BuildOptions,
    /// Also measure the `obvhs` crate.
    pub peers: bool,
}

/// A ray tracing engine under test: built once, traced many times.
trait Engine: Sync {
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

    pub(super) struct Bvh2 {
        pub bvh: obvhs::bvh2::Bvh2,
        pub tris: Vec<OTri>,
    }

    impl Engine for Bvh2 {
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

    pub(super) struct Cwbvh {
        pub bvh: obvhs::cwbvh::CwBvh,
        pub tris: Vec<OTri>,
    }

    impl Engine for Cwbvh {
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
}

fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("a thread pool can be made")
}

/// Runs `f` `repeat` times and keeps the fastest run's result and time.
fn best_of<T>(repeat: usize, mut f: impl FnMut() -> T) -> (T, Duration) {
    let mut best: Option<(T, Duration)> = None;
    for _ in 0..repeat.max(1) {
        let start = Instant::now();
        let out = f();
        let took = start.elapsed();
        if best.as_ref().is_none_or(|(_, d)| took < *d) {
            best = Some((out, took));
        }
    }
    best.expect("at least one run")
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
    /// `tracery-sah`'s closest hits on the canonical rays.
    pub sah_hits: Vec<HitRecord>,
}

/// Builds every engine over `triangles` and traces `rays` with each thread count.
/// `progress` receives a line per step.
pub fn run(
    mesh_name: &str,
    triangles: &[[Vec3; 3]],
    rays: &[Ray],
    config: &BenchConfig,
    progress: &mut dyn FnMut(&str),
) -> MeshBench {
    let one = pool(1);
    let mut results = Vec::new();
    let mut reference: Option<Vec<HitRecord>> = None;

    let measure = |name: &str,
                   build_ms: f64,
                   stats: Option<BvhStats>,
                   engine: &dyn Engine,
                   results: &mut Vec<EngineResult>,
                   reference: &mut Option<Vec<HitRecord>>,
                   progress: &mut dyn FnMut(&str)| {
        for &threads in &config.threads {
            progress(&format!(
                "{mesh_name}: tracing {name} on {threads} thread(s)"
            ));
            let p = pool(threads);
            let (hits, closest) =
                p.install(|| best_of(config.repeat, || trace_closest(engine, rays)));
            let (_, occluded) =
                p.install(|| best_of(config.repeat, || trace_occluded(engine, rays)));
            let reference = reference.get_or_insert_with(|| hits.clone());
            results.push(EngineResult {
                engine: name.to_string(),
                mesh: mesh_name.to_string(),
                triangles: triangles.len(),
                threads,
                build_ms,
                closest_mrays: rays.len() as f64 / closest.as_secs_f64() / 1e6,
                occluded_mrays: rays.len() as f64 / occluded.as_secs_f64() / 1e6,
                agreement: agreement(reference, &hits),
                stats,
            });
        }
    };

    for split in [SplitMethod::Sah, SplitMethod::Median] {
        let name = format!("tracery-{split}");
        progress(&format!("{mesh_name}: building {name}"));
        let options = config.options.with_split(split);
        let (bvh, took) =
            one.install(|| best_of(config.repeat, || Bvh::build(triangles, &options)));
        let build_ms = took.as_secs_f64() * 1e3;
        let mut stats = bvh.stats;
        stats.build_ms = build_ms;
        measure(
            &name,
            build_ms,
            Some(stats),
            &bvh,
            &mut results,
            &mut reference,
            progress,
        );
    }
    let sah_hits = reference.clone().unwrap_or_default();

    if config.peers {
        let otris = peers::to_otris(triangles);
        progress(&format!("{mesh_name}: building obvhs-bvh2"));
        let (bvh, took) = one.install(|| {
            best_of(config.repeat, || {
                obvhs::bvh2::builder::build_bvh2_from_tris(
                    &otris,
                    obvhs::BvhBuildParams::medium_build(),
                    &mut Duration::default(),
                )
            })
        });
        let tris = bvh
            .primitive_indices
            .iter()
            .map(|&i| otris[i as usize])
            .collect();
        let engine = peers::Bvh2 { bvh, tris };
        measure(
            "obvhs-bvh2",
            took.as_secs_f64() * 1e3,
            None,
            &engine,
            &mut results,
            &mut reference,
            progress,
        );

        progress(&format!("{mesh_name}: building obvhs-cwbvh"));
        let (bvh, took) = one.install(|| {
            best_of(config.repeat, || {
                obvhs::cwbvh::builder::build_cwbvh_from_tris(
                    &otris,
                    obvhs::BvhBuildParams::medium_build(),
                    &mut Duration::default(),
                )
            })
        });
        let tris = bvh
            .primitive_indices
            .iter()
            .map(|&i| otris[i as usize])
            .collect();
        let engine = peers::Cwbvh { bvh, tris };
        measure(
            "obvhs-cwbvh",
            took.as_secs_f64() * 1e3,
            None,
            &engine,
            &mut results,
            &mut reference,
            progress,
        );
    }
    MeshBench { results, sah_hits }
}
