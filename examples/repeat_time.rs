//! Where a hitting ray's time goes, ours beside Embree's `rtcIntersect1`: the canonical camera
//! rays that hit the mesh (DESIGN.md), closest hits on one thread, traced four ways:
//!
//! - in image order, as `tracery bench` traces them;
//! - each `R` times in a row (the caches warm after the first, the branch predictor trained on
//!   the ray's own path);
//! - in a shuffled order (neighbours no longer share their paths: caches cold);
//! - one ray, the middle one, over and over (everything warm and predicted: the walk's own
//!   cost).
//!
//! The gap between image order and one ray is what the memory and the branch predictor cost
//! each engine. Rates are the best of `ROUNDS`, the two engines alternating.
//!
//! `cargo run --release --no-default-features --example repeat_time -- MESH [R] [ROUNDS]`

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use tracery::bench::canonical_rays;
use tracery::bench::embree::Embree;
use tracery::bvh::{BuildOptions, Bvh};
use tracery::geometry::Ray;
use tracery::scene::Scene;

/// The four ways, in order.
const WAYS: [&str; 4] = ["image order", "each R times", "shuffled", "one ray"];

/// Mrays/s of `hits` over the rays traced each of the four ways; also checks every ray hits.
fn time_ways(
    rays: &[Ray],
    shuffled: &[Ray],
    repeat: usize,
    hits: &dyn Fn(&Ray) -> bool,
) -> [f64; 4] {
    let rate = |n: usize, start: Instant| n as f64 / start.elapsed().as_secs_f64() / 1e6;
    let mut missed = 0usize;
    let start = Instant::now();
    for r in rays {
        missed += !hits(r) as usize;
    }
    let once = rate(rays.len(), start);
    let start = Instant::now();
    for r in rays {
        for _ in 0..repeat {
            missed += !hits(std::hint::black_box(r)) as usize;
        }
    }
    let repeated = rate(rays.len() * repeat, start);
    let start = Instant::now();
    for r in shuffled {
        missed += !hits(r) as usize;
    }
    let shuffled_rate = rate(shuffled.len(), start);
    let one = rays[rays.len() / 2];
    let start = Instant::now();
    for _ in 0..rays.len() {
        missed += !hits(std::hint::black_box(&one)) as usize;
    }
    let one_rate = rate(rays.len(), start);
    assert_eq!(missed, 0, "every ray traced hits the mesh");
    [once, repeated, shuffled_rate, one_rate]
}

fn main() -> Result<()> {
    let mut args = std::env::args().skip(1);
    let path = PathBuf::from(args.next().context("MESH")?);
    let repeat: usize = args.next().map_or(Ok(8), |s| s.parse()).context("R")?;
    let rounds: usize = args.next().map_or(Ok(3), |s| s.parse()).context("ROUNDS")?;
    anyhow::ensure!(repeat > 0 && rounds > 0, "R and ROUNDS are at least 1");
    let scene = Scene::load(&path)?;
    let triangles = &scene.mesh.triangles;
    let bvh = Bvh::build(triangles, &BuildOptions::sah());
    let embree = Embree::build(triangles, 1)?;
    let mut rays = canonical_rays(&bvh.bounds());
    rays.retain(|r| bvh.intersect(r, f32::INFINITY).is_some());
    anyhow::ensure!(!rays.is_empty(), "no canonical ray hits {}", path.display());
    // A fixed shuffle (Fisher-Yates on a linear congruential sequence): the same every run.
    let mut shuffled = rays.clone();
    let mut state = 0x2545_f491_4f6c_dd1du64;
    for i in (1..shuffled.len()).rev() {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        shuffled.swap(i, (state >> 33) as usize % (i + 1));
    }
    println!(
        "{} ({} triangles), {} canonical rays that hit, kernel {}, one thread, best of {rounds}:",
        path.display(),
        triangles.len(),
        rays.len(),
        bvh.kernel()
    );
    let (mut ours, mut theirs) = ([0.0f64; 4], [0.0f64; 4]);
    for _ in 0..rounds {
        let o = time_ways(&rays, &shuffled, repeat, &|r| {
            bvh.intersect(r, f32::INFINITY).is_some()
        });
        let e = time_ways(&rays, &shuffled, repeat, &|r| {
            embree.intersect1(r).prim != u32::MAX
        });
        for k in 0..4 {
            ours[k] = ours[k].max(o[k]);
            theirs[k] = theirs[k].max(e[k]);
        }
    }
    for k in 0..4 {
        let way = WAYS[k].replace('R', &repeat.to_string());
        println!(
            "  {way:14} tracery {:6.2}  embree {:6.2} Mrays/s  ratio {:.2}x",
            ours[k],
            theirs[k],
            ours[k] / theirs[k]
        );
    }
    // The time a ray loses to memory and misprediction: image order against one ray.
    let lost = |rates: &[f64; 4]| 1e3 / rates[0] - 1e3 / rates[3];
    println!(
        "  ns a ray beyond the one-ray case: tracery {:.1}, embree {:.1}",
        lost(&ours),
        lost(&theirs)
    );
    Ok(())
}
