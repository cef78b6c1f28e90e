//! How long the idler of two threads waits for the other in one two-thread trace of the
//! canonical camera rays (closest hits, chunks of 1024 rays as `tracery bench` traces them),
//! with rayon's default split against one job per chunk (`with_max_len(1)`, what the bench
//! uses). The wait is the call's wall time less the thread's time inside chunks: waking the
//! workers, and a thread out of work while the other finishes its last piece.
//!
//! `cargo run --release --no-default-features --example split_idle -- MESH [ROUNDS]`
use anyhow::{Context, Result};
use rayon::prelude::*;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;
use tracery::bench::canonical_rays;
use tracery::bvh::{BuildOptions, Bvh};
use tracery::scene::Scene;

fn main() -> Result<()> {
    let mut args = std::env::args().skip(1);
    let path = PathBuf::from(args.next().context("MESH")?);
    let rounds: usize = args
        .next()
        .map_or(Ok(10), |s| s.parse())
        .context("ROUNDS")?;
    anyhow::ensure!(rounds > 0, "ROUNDS is at least 1");
    let scene = Scene::load(&path)?;
    let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
    let rays = canonical_rays(&bvh.bounds());
    let n = rays.len();
    let p2 = rayon::ThreadPoolBuilder::new().num_threads(2).build()?;
    let mut out = vec![f32::INFINITY; n];
    // Interleaved, twice each: the machine's noise falls on both.
    for fine in [false, true, false, true] {
        let mut idle = vec![];
        let mut walls = vec![];
        for _ in 0..rounds {
            let busy = [AtomicU64::new(0), AtomicU64::new(0)];
            let work = |(c, o): (usize, &mut [f32])| {
                let s = Instant::now();
                for (o, r) in o.iter_mut().zip(&rays[c * 1024..]) {
                    *o = bvh
                        .intersect(r, f32::INFINITY)
                        .map_or(f32::INFINITY, |h| h.t);
                }
                busy[rayon::current_thread_index().expect("on the pool")]
                    .fetch_add(s.elapsed().as_nanos() as u64, Ordering::Relaxed);
            };
            let s = Instant::now();
            if fine {
                p2.install(|| {
                    out.par_chunks_mut(1024)
                        .enumerate()
                        .with_max_len(1)
                        .for_each(work)
                });
            } else {
                p2.install(|| out.par_chunks_mut(1024).enumerate().for_each(work));
            }
            let wall = s.elapsed().as_nanos() as f64;
            let b: Vec<f64> = busy
                .iter()
                .map(|b| b.load(Ordering::Relaxed) as f64)
                .collect();
            idle.push((wall - b[0].min(b[1])) / 1e3);
            walls.push(wall / 1e6);
        }
        let best = walls.iter().cloned().fold(f64::INFINITY, f64::min);
        let mean_idle: f64 = idle.iter().sum::<f64>() / idle.len() as f64;
        println!(
            "{}: best wall {best:.2} ms; idle of the idler thread per call (us): {:?}; mean {mean_idle:.0} us",
            if fine {
                "one job per chunk"
            } else {
                "rayon default  "
            },
            idle.iter().map(|&i| i as i64).collect::<Vec<_>>()
        );
    }
    Ok(())
}
