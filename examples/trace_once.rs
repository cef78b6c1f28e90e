//! Traces the canonical camera rays that hit the mesh (DESIGN.md) once, one by one, with one
//! engine and one query, on one thread: a run to count under `valgrind`, ours beside Embree's.
//!
//! Valgrind counts the whole process (the mesh's loading, both builds, the choice of rays), so
//! each engine is run twice, once with `setup` as the last argument (everything but the
//! tracing) and once without; the difference, divided by the rays printed, is what tracing
//! one hitting ray costs: instructions, cache misses of a simulated hierarchy, mispredicted
//! branches of a simulated predictor.
//!
//! ```text
//! cargo build --release --no-default-features --example trace_once
//! TRACERY_KERNEL=avx2 valgrind --tool=cachegrind --cache-sim=yes --branch-sim=yes \
//!     --D1=49152,12,64 --LL=2097152,16,64 target/release/examples/trace_once MESH ENGINE QUERY [setup]
//! ```
//!
//! `ENGINE` is `tracery` or `embree` (`rtcIntersect1` / `rtcOccluded1`), `QUERY` `closest` or
//! `occluded` (the canonical rays that hit), or `bounce` or `shadow` (closest hits of the
//! secondary rays' diffuse bounces from those hits, occlusion of their shadow rays: see
//! `tracery::bench::secondary`, ours by its walk for incoherent rays as the bench traces them;
//! the count printed is then the rays that hit, or are blocked, to compare between the
//! engines' runs). Valgrind runs no AVX-512: our kernel is picked by `TRACERY_KERNEL`, and Embree
//! picks its AVX2 kernels by itself when valgrind's CPU reports no AVX-512.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use tracery::bench::embree::Embree;
use tracery::bench::secondary::secondary_rays;
use tracery::bench::{HitRecord, canonical_rays};
use tracery::bvh::{BuildOptions, Bvh};
use tracery::scene::Scene;

fn main() -> Result<()> {
    let mut args = std::env::args().skip(1);
    let path = PathBuf::from(args.next().context("MESH")?);
    let engine = args.next().context("ENGINE (tracery or embree)")?;
    let query = args.next().context("QUERY (closest or occluded)")?;
    let setup_only = match args.next().as_deref() {
        None => false,
        Some("setup") => true,
        Some(other) => bail!("the last argument is `setup` or nothing, not `{other}`"),
    };
    let (closest, secondary) = match query.as_str() {
        "closest" => (true, false),
        "occluded" => (false, false),
        "bounce" => (true, true),
        "shadow" => (false, true),
        _ => bail!("QUERY is `closest`, `occluded`, `bounce` or `shadow`, not `{query}`"),
    };
    let scene = Scene::load(&path)?;
    let triangles = &scene.mesh.triangles;
    let bvh = Bvh::build(triangles, &BuildOptions::sah());
    let mut rays = canonical_rays(&bvh.bounds());
    rays.retain(|r| bvh.occluded(r, f32::INFINITY));
    if secondary {
        let hits: Vec<HitRecord> = rays
            .iter()
            .map(|r| {
                let h = bvh.intersect(r, f32::INFINITY).expect("a ray that hits");
                HitRecord {
                    t: h.t,
                    prim: h.prim,
                }
            })
            .collect();
        let second = secondary_rays(triangles, &rays, &hits, &bvh.bounds());
        rays = if closest {
            second.bounce
        } else {
            second.shadow
        };
    }
    let traced = if setup_only { 0 } else { rays.len() };
    let hits = match engine.as_str() {
        "tracery" => rays[..traced]
            .iter()
            .filter(|r| {
                if closest && secondary {
                    bvh.intersect_incoherent(r, f32::INFINITY).is_some()
                } else if closest {
                    bvh.intersect(r, f32::INFINITY).is_some()
                } else {
                    bvh.occluded(r, f32::INFINITY)
                }
            })
            .count(),
        "embree" => {
            let embree = Embree::build(triangles, 1)?;
            rays[..traced]
                .iter()
                .filter(|r| {
                    if closest {
                        embree.intersect1(r).prim != u32::MAX
                    } else {
                        embree.occluded1(r)
                    }
                })
                .count()
        }
        _ => bail!("ENGINE is `tracery` or `embree`, not `{engine}`"),
    };
    anyhow::ensure!(
        secondary || hits == traced,
        "{engine} found {hits} hits of {traced} rays"
    );
    println!(
        "{} ({} triangles): {engine} {query}, {traced} of {} rays traced ({hits} hit or blocked), kernel {}",
        path.display(),
        triangles.len(),
        rays.len(),
        bvh.kernel()
    );
    Ok(())
}
