//! What a ray costs each engine on two threads against one: the canonical camera rays traced
//! for closest hits by tracery-sah and by Embree's `rtcIntersect1`, in chunks of 1024 rays
//! on one-job-per-chunk rayon pools of one and of two threads (as `tracery bench` traces them),
//! timing each worker's time inside its chunks. Two threads over one in wall time falls short
//! of 2 by the time the workers spend outside chunks (waking, waiting: `examples/split_idle`)
//! and by how much more the same rays cost inside chunks when both cores trace at once, which
//! this prints per engine: the summed busy time of a two-thread trace over a one-thread one's.
//! Per round and engine: two one-thread traces, then two two-thread traces (the first of them
//! starts with the second core's caches holding the other engine's data); round 1 is left out
//! of the sums.
//!
//! `cargo run --release --no-default-features --example two_thread_cost -- MESH [ROUNDS]`
use anyhow::{Context, Result};
use rayon::prelude::*;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;
use tracery::bench::canonical_rays;
use tracery::bench::embree::Embree;
use tracery::bvh::{BuildOptions, Bvh};
use tracery::geometry::Ray;
use tracery::scene::Scene;

/// Rays a job traces, as in `tracery bench`.
const CHUNK: usize = 1024;

/// An engine's closest hit of a ray: its distance (infinite on a miss).
type Closest<'a> = &'a (dyn Fn(&Ray) -> f32 + Sync);

/// Wall time and summed busy time (inside chunks) of one trace of `rays` on `pool`, in ms.
fn trace(pool: &rayon::ThreadPool, rays: &[Ray], out: &mut [f32], closest: Closest) -> (f64, f64) {
    let busy = [AtomicU64::new(0), AtomicU64::new(0)];
    let start = Instant::now();
    pool.install(|| {
        out.par_chunks_mut(CHUNK)
            .enumerate()
            .with_max_len(1)
            .for_each(|(c, o)| {
                let s = Instant::now();
                for (o, r) in o.iter_mut().zip(&rays[c * CHUNK..]) {
                    *o = closest(r);
                }
                let i = rayon::current_thread_index().expect("on the pool");
                busy[i].fetch_add(s.elapsed().as_nanos() as u64, Ordering::Relaxed);
            })
    });
    let wall = start.elapsed().as_secs_f64() * 1e3;
    let busy: f64 = busy
        .iter()
        .map(|b| b.load(Ordering::Relaxed) as f64 / 1e6)
        .sum();
    (wall, busy)
}

fn main() -> Result<()> {
    let mut args = std::env::args().skip(1);
    let path = PathBuf::from(args.next().context("MESH")?);
    let rounds: usize = args.next().map_or(Ok(6), |s| s.parse()).context("ROUNDS")?;
    anyhow::ensure!(rounds > 1, "ROUNDS is at least 2 (the first is left out)");
    let scene = Scene::load(&path)?;
    let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
    let embree = Embree::build(&scene.mesh.triangles, 1)?;
    let rays = canonical_rays(&bvh.bounds());
    let p1 = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let p2 = rayon::ThreadPoolBuilder::new().num_threads(2).build()?;
    let mut out = vec![f32::INFINITY; rays.len()];
    let ours = |r: &Ray| {
        bvh.intersect(r, f32::INFINITY)
            .map_or(f32::INFINITY, |h| h.t)
    };
    let theirs = |r: &Ray| embree.intersect1(r).t;
    let engines: [(&str, Closest); 2] = [("tracery-sah", &ours), ("embree", &theirs)];
    // Per engine: busy and wall sums of [1T first, 1T second, 2T first, 2T second].
    let mut busy = [[0.0f64; 4]; 2];
    let mut wall = [[0.0f64; 4]; 2];
    for round in 0..rounds {
        for (e, (name, closest)) in engines.iter().enumerate() {
            let mut line = format!("round {:2} {name:12}", round + 1);
            for (k, pool) in [&p1, &p1, &p2, &p2].into_iter().enumerate() {
                let (w, b) = trace(pool, &rays, &mut out, *closest);
                if round > 0 {
                    busy[e][k] += b;
                    wall[e][k] += w;
                }
                let threads = if k < 2 { 1 } else { 2 };
                line += &format!(" | {threads}T wall {w:6.2} busy {b:6.2}");
            }
            println!("{line}");
        }
    }
    println!("sums over rounds 2 to {rounds}, two threads over one:");
    for (e, (name, _)) in engines.iter().enumerate() {
        let (b, w) = (busy[e], wall[e]);
        println!(
            "{name:12} busy time (the same rays' cost) first {:.4}x, second {:.4}x; wall-time speed-up first {:.3}x, second {:.3}x",
            b[2] / b[0],
            b[3] / b[1],
            w[0] / w[2],
            w[1] / w[3]
        );
    }
    Ok(())
}
