//! Times tracing alone: the canonical camera rays of a mesh (DESIGN.md) traced on one thread,
//! `ROUNDS` times, one by one (closest hits, then shadow queries) and in packets of 8 x 8
//! pixel tiles (closest hits), and prints the fastest and median rates of each. Two builds of the traversal are compared by running
//! their binaries one after the other, alternating (the machines are noisy); Embree's rate
//! beside ours in one run is in `tracery bench`. `TRACERY_KERNEL` picks the
//! kernel as everywhere.
//!
//! `cargo run --release --no-default-features --example trace_time -- MESH [ROUNDS] [QUERY] [RAYS]`
//!
//! `QUERY` (`closest`, `occluded` or `packets`) times that query alone, for profiling. `RAYS`
//! (`hits` or `misses`) keeps only the rays that hit the mesh, or only those that miss it, in
//! image order (single rays only: packets need whole tiles), for example to count a hitting
//! ray's instructions under `valgrind --tool=callgrind`.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use tracery::bench::{CANONICAL_SIZE, canonical_rays};
use tracery::bvh::{BuildOptions, Bvh};
use tracery::geometry::Ray;
use tracery::scene::Scene;

fn main() -> Result<()> {
    let mut args = std::env::args().skip(1);
    let path = PathBuf::from(args.next().context("MESH")?);
    let rounds: usize = args.next().map_or(Ok(5), |s| s.parse()).context("ROUNDS")?;
    let only = args.next();
    let run = |q: &str| only.as_deref().is_none_or(|o| o == q);
    let scene = Scene::load(&path)?;
    let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
    let mut rays = canonical_rays(&bvh.bounds());
    if let Some(kind) = args.next() {
        let want_hits = match kind.as_str() {
            "hits" => true,
            "misses" => false,
            _ => anyhow::bail!("RAYS is `hits` or `misses`, not `{kind}`"),
        };
        anyhow::ensure!(
            matches!(only.as_deref(), Some("closest" | "occluded")),
            "RAYS needs QUERY `closest` or `occluded` (packets need whole tiles)"
        );
        rays.retain(|r| bvh.intersect(r, f32::INFINITY).is_some() == want_hits);
    }
    let mut closest = Vec::with_capacity(rounds);
    let mut occluded = Vec::with_capacity(rounds);
    let mut packets = Vec::with_capacity(rounds);
    let (mut hits, mut blocked, mut packet_hits) = (0usize, 0usize, 0usize);
    // The rays of each 8 x 8 tile side by side, as the renderer makes them.
    let size = CANONICAL_SIZE as usize;
    let tiles: Vec<Vec<Ray>> = (0..if run("packets") { size / 8 } else { 0 })
        .flat_map(|ty| (0..size / 8).map(move |tx| (ty, tx)))
        .map(|(ty, tx)| {
            (0..64)
                .map(|i| rays[(8 * ty + i / 8) * size + 8 * tx + i % 8])
                .collect()
        })
        .collect();
    let mut out = [None; 64];
    for _ in 0..rounds {
        if run("closest") {
            let start = Instant::now();
            hits = rays
                .iter()
                .filter(|r| bvh.intersect(r, f32::INFINITY).is_some())
                .count();
            closest.push(rays.len() as f64 / start.elapsed().as_secs_f64() / 1e6);
        }
        if run("occluded") {
            let start = Instant::now();
            blocked = rays
                .iter()
                .filter(|r| bvh.occluded(r, f32::INFINITY))
                .count();
            occluded.push(rays.len() as f64 / start.elapsed().as_secs_f64() / 1e6);
        }
        if run("packets") {
            let start = Instant::now();
            packet_hits = 0;
            for tile in &tiles {
                bvh.intersect_packet(tile, f32::INFINITY, &mut out);
                packet_hits += out.iter().filter(|h| h.is_some()).count();
            }
            packets.push(rays.len() as f64 / start.elapsed().as_secs_f64() / 1e6);
        }
    }
    anyhow::ensure!(
        only.is_some() || packet_hits == hits,
        "packets hit {packet_hits} rays, single rays {hits}"
    );
    let best_median = |v: &mut Vec<f64>| {
        v.sort_by(|a, b| b.total_cmp(a));
        (
            v.first().copied().unwrap_or(0.0),
            v.get(v.len() / 2).copied().unwrap_or(0.0),
        )
    };
    let (cb, cm) = best_median(&mut closest);
    let (ob, om) = best_median(&mut occluded);
    let (pb, pm) = best_median(&mut packets);
    println!(
        "{} ({} triangles), kernel {}, {} rays ({hits} hit, {blocked} blocked), {rounds} rounds on one thread: closest {cb:.2} Mr/s best, {cm:.2} median; occluded {ob:.2} best, {om:.2} median; packets {pb:.2} best, {pm:.2} median",
        path.display(),
        scene.mesh.triangles.len(),
        bvh.kernel(),
        rays.len(),
    );
    Ok(())
}
