//! Times the SAH build alone: `BUILDS` builds of a mesh on a pool of `THREADS` threads, and
//! prints the fastest and the median (of the build as it times itself, and of the whole call as
//! `tracery bench` times it, statistics included) and the tree (SAH cost, leaves, levels), so
//! two builders can be compared by running their binaries one after the other (a shared
//! machine is noisy: alternate them, and compare runs made close together). Embree's build time, beside ours in
//! one run, is in `tracery bench`.
//!
//! `cargo run --release --no-default-features --example build_time -- MESH [BUILDS] [THREADS]
//! [cold]`
//!
//! With `cold`, 64 MB are allocated, written and freed before each build, as another engine's
//! build does between ours in `tracery bench`: the build then finds its memory out of the
//! caches, as the one build a scene load makes does. Without it, each build reuses the memory
//! the one before it left warm.

use std::path::PathBuf;

use anyhow::{Context, Result};
use tracery::bvh::{BuildOptions, Bvh};
use tracery::scene::Scene;

fn main() -> Result<()> {
    let mut args = std::env::args().skip(1);
    let path = PathBuf::from(args.next().context("MESH")?);
    let builds: usize = args
        .next()
        .map_or(Ok(20), |s| s.parse())
        .context("BUILDS")?;
    let threads: usize = args
        .next()
        .map_or(Ok(1), |s| s.parse())
        .context("THREADS")?;
    let cold = match args.next().as_deref() {
        None => false,
        Some("cold") => true,
        Some(other) => anyhow::bail!("the fourth argument is `cold` or nothing, not `{other}`"),
    };
    let scene = Scene::load(&path)?;
    let tris = &scene.mesh.triangles;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()?;
    let mut ours = Vec::with_capacity(builds);
    let mut calls = Vec::with_capacity(builds);
    let mut last = None;
    pool.install(|| {
        for _ in 0..builds {
            if cold {
                // Another workload's memory, written and freed.
                std::hint::black_box(&vec![1u8; 64 << 20]);
            }
            let start = std::time::Instant::now();
            let bvh = Bvh::build(tris, &BuildOptions::sah());
            calls.push(start.elapsed().as_secs_f64() * 1e3);
            ours.push(bvh.stats.build_ms);
            last = Some(bvh);
        }
    });
    ours.sort_by(f64::total_cmp);
    calls.sort_by(f64::total_cmp);
    let s = &last.context("no build")?.stats;
    println!(
        "{} ({} triangles), {threads} thread(s), {builds} builds{}: fastest {:.1} ms, median {:.1} ms (the whole call, statistics included, as `tracery bench` times it: fastest {:.1} ms, median {:.1} ms); SAH cost {:.2}, {} leaves, {} levels, {} wide nodes, {} blocks",
        path.display(),
        tris.len(),
        if cold { " (cold)" } else { "" },
        ours[0],
        ours[builds / 2],
        calls[0],
        calls[builds / 2],
        s.sah_cost,
        s.leaves,
        s.levels,
        s.wide_nodes,
        s.blocks
    );
    Ok(())
}
