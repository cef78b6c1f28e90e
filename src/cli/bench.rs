//! `tracery bench`: build and trace the canonical camera rays with our BVH, Embree (where its
//! library is installed) and obvhs.

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use clap::Args;
use tracery::bench::{self, BenchConfig, EngineResult};
use tracery::bvh::BuildOptions;
use tracery::bvh::wide::Kernel;
use tracery::scene::Scene;

use super::ensure_parent;

#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Meshes (OBJ, PLY, glTF) or scene files (TOML); the built-in Cornell box when left out.
    meshes: Vec<PathBuf>,
    /// Threads for the all-threads figures (default: every core). One thread is always measured.
    #[arg(long)]
    threads: Option<usize>,
    /// Repeat each measurement this many times and keep the best.
    #[arg(long, default_value_t = 3)]
    repeat: usize,
    /// SAH bins per axis for our SAH builder.
    #[arg(long, default_value_t = BuildOptions::DEFAULT_BINS)]
    bins: u32,
    /// Largest leaf size for our builders.
    #[arg(long, default_value_t = BuildOptions::DEFAULT_LEAF_SIZE)]
    leaf_size: u32,
    /// Hold our kernels and Embree's to one instruction set (scalar, sse2, avx2 or avx512):
    /// what a CPU without the wider ones would see. Embree has no scalar kernels (held to
    /// scalar, it runs SSE2); obvhs is compiled for the baseline (SSE2) either way. Default:
    /// each engine's fastest on this CPU.
    #[arg(long, value_name = "ISA")]
    isa: Option<Kernel>,
    /// Leave out every peer (Embree and obvhs).
    #[arg(long)]
    no_peers: bool,
    /// Leave out the obvhs peer.
    #[arg(long)]
    no_obvhs: bool,
    /// Print a JSON array (one object per engine and thread count) instead of tables.
    #[arg(long)]
    json: bool,
    /// Write the canonical rays to this file (a mesh-name suffix is added for several meshes).
    #[arg(long)]
    rays_out: Option<PathBuf>,
    /// Write the triangles the engines are given to this file (suffixed like --rays-out): the
    /// input of `src/bench/embree_build.c`, which times Embree's build in a C program.
    #[arg(long)]
    triangles_out: Option<PathBuf>,
    /// Write tracery-sah's closest hits to this file (suffixed like --rays-out).
    #[arg(long)]
    hits_out: Option<PathBuf>,
    /// Also draw every engine's one-thread rays per second on every mesh as bars to this PNG
    /// file.
    #[arg(long)]
    plot: Option<PathBuf>,
}

fn per_mesh(path: &Path, mesh: &str, several: bool) -> PathBuf {
    if !several {
        return path.to_path_buf();
    }
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy())
        .unwrap_or_default();
    let ext = path
        .extension()
        .map(|e| format!(".{}", e.to_string_lossy()))
        .unwrap_or_default();
    path.with_file_name(format!("{stem}-{mesh}{ext}"))
}

pub fn run(a: BenchArgs) -> Result<()> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let all = a.threads.unwrap_or(cores).max(1);
    let mut threads = vec![1];
    if all > 1 {
        threads.push(all);
    }
    let options = BuildOptions {
        bins: a.bins,
        max_leaf_size: a.leaf_size,
        ..BuildOptions::sah()
    };
    options.validate().map_err(anyhow::Error::msg)?;
    if let Some(isa) = a.isa {
        let runs = Kernel::available();
        if !runs.contains(&isa) {
            let runs: Vec<&str> = runs.iter().map(|k| k.name()).collect();
            bail!(
                "--isa {isa}: this CPU cannot run it (it runs {})",
                runs.join(", ")
            );
        }
    }
    let config = BenchConfig {
        threads,
        repeat: a.repeat,
        ours: BenchConfig::ours(options),
        obvhs: !a.no_peers && !a.no_obvhs,
        embree: !a.no_peers,
        packets: true,
        isa: a.isa,
    };
    if config.embree
        && let Err(why) = tracery::bench::embree::available()
    {
        eprintln!("note: Embree is not measured: {why}");
    }

    let sources: Vec<Option<PathBuf>> = if a.meshes.is_empty() {
        vec![None]
    } else {
        a.meshes.iter().cloned().map(Some).collect()
    };
    let several = sources.len() > 1;
    let mut all_results: Vec<EngineResult> = Vec::new();
    for src in &sources {
        let scene = match src {
            Some(p) => super::load_flat_scene(Some(p), "bench")?,
            None => Scene::cornell_box(),
        };
        let tris = &scene.mesh.triangles;
        let rays = bench::canonical_rays(&scene.mesh.bounds());
        eprintln!(
            "{}: {} triangles, {} canonical rays",
            scene.name,
            tris.len(),
            rays.len()
        );
        if let Some(p) = &a.rays_out {
            let p = ensure_parent(&per_mesh(p, &scene.name, several))?;
            bench::write_rays(&p, &rays)?;
            eprintln!("wrote rays to {}", p.display());
        }
        if let Some(p) = &a.triangles_out {
            let p = ensure_parent(&per_mesh(p, &scene.name, several))?;
            bench::write_triangles(&p, tris)?;
            eprintln!("wrote triangles to {}", p.display());
        }
        let out = bench::run(
            &scene.name,
            tris,
            &rays,
            bench::CANONICAL_SIZE as usize,
            &config,
            &mut |line| eprintln!("  {line}"),
        )?;
        if let Some(p) = &a.hits_out {
            let p = ensure_parent(&per_mesh(p, &scene.name, several))?;
            bench::write_hits(&p, &out.sah_hits)?;
            eprintln!("wrote tracery-sah hits to {}", p.display());
        }
        if !a.json {
            print_table(
                &scene.name,
                tris.len(),
                out.excluded,
                a.repeat,
                &out.results,
            );
        }
        all_results.extend(out.results);
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&all_results)?);
    }
    if let Some(p) = &a.plot {
        let p = ensure_parent(p)?;
        bench::chart::plot(&p, &all_results)?;
        eprintln!("wrote {}", p.display());
    }
    Ok(())
}

fn print_table(
    mesh: &str,
    triangles: usize,
    excluded: usize,
    rounds: usize,
    rows: &[EngineResult],
) {
    let left_out = if excluded > 0 {
        format!(", {excluded} with NaN or infinite vertices left out for every engine")
    } else {
        String::new()
    };
    let isa = |engine: &str| {
        rows.iter()
            .find(|r| r.engine == engine)
            .and_then(|r| r.isa.clone())
    };
    let kernel = isa("tracery-sah").unwrap_or_else(|| Kernel::detect().name().to_string());
    let embree = isa("embree").map_or(String::new(), |i| format!(", Embree held to isa={i}"));
    println!(
        "\n{mesh} ({triangles} triangles{left_out}), canonical camera 1024x1024, best of runs; tracery kernel {kernel}{embree}"
    );
    println!(
        "{:<15} {:>7} {:>9} {:>7} {:>8} {:>9} {:>13} {:>14} {:>9}",
        "engine",
        "threads",
        "build ms",
        "levels",
        "leaves",
        "SAH cost",
        "closest Mr/s",
        "occluded Mr/s",
        "agree %"
    );
    for r in rows {
        let (levels, leaves, sah) = match &r.stats {
            Some(s) => (
                s.levels.to_string(),
                s.leaves.to_string(),
                format!("{:.2}", s.sah_cost),
            ),
            None => ("-".into(), "-".into(), "-".into()),
        };
        println!(
            "{:<15} {:>7} {:>9.1} {:>7} {:>8} {:>9} {:>13.2} {:>14.2} {:>9.3}",
            r.engine,
            r.threads,
            r.build_ms,
            levels,
            leaves,
            sah,
            r.closest_mrays,
            r.occluded_mrays,
            r.agreement * 100.0
        );
    }
    let find = |e: &str, t: usize| rows.iter().find(|r| r.engine == e && r.threads == t);
    let threads: Vec<usize> = {
        let mut t: Vec<usize> = rows.iter().map(|r| r.threads).collect();
        t.dedup();
        t.sort();
        t.dedup();
        t
    };
    for (ours, peer) in [
        ("tracery-sah", "embree"),
        ("tracery-packet", "embree-packet16"),
        ("tracery-sah", "obvhs-bvh2"),
        ("tracery-sah", "obvhs-cwbvh"),
    ] {
        for &t in &threads {
            if let (Some(us), Some(them)) = (find(ours, t), find(peer, t)) {
                println!(
                    "{ours} / {peer} ({t} thread{}): build time {:.2}x, closest {:.2}x, occluded {:.2}x",
                    if t == 1 { "" } else { "s" },
                    us.build_ms / them.build_ms,
                    us.closest_mrays / them.closest_mrays,
                    us.occluded_mrays / them.occluded_mrays
                );
            }
        }
    }
    print_split(rows);
    print_secondary(rows);
    if let (Some(one), Some(&t)) = (find("tracery-sah", 1), threads.last())
        && t > 1
        && let Some(all) = find("tracery-sah", t)
    {
        println!(
            "tracery-sah scaling, {t} threads over 1: closest {:.2}x, occluded {:.2}x",
            all.closest_mrays / one.closest_mrays,
            all.occluded_mrays / one.occluded_mrays
        );
        // Every engine's, in the same rounds: on a shared machine the second core's load
        // moves them all, and a figure of ours reads against the others'.
        let each: Vec<String> = engine_names(rows)
            .iter()
            .filter_map(|&e| {
                let (one, all) = (find(e, 1)?, find(e, t)?);
                Some(format!(
                    "{e} {:.2}x / {:.2}x",
                    all.closest_mrays / one.closest_mrays,
                    all.occluded_mrays / one.occluded_mrays
                ))
            })
            .collect();
        println!(
            "every engine's scaling, {t} threads over 1 (closest / occluded): {}",
            each.join(", ")
        );
    }
    if rounds > 1 {
        print_spread(rows, &threads);
    }
}

/// Each engine's closest-hit rounds, the median over the fastest, per thread count: on a
/// shared machine a core that runs slowly for a while moves one engine's figures more than
/// another's, and this shows which figures it moved.
fn print_spread(rows: &[EngineResult], threads: &[usize]) {
    let each: Vec<String> = engine_names(rows)
        .iter()
        .map(|&e| {
            let spreads: Vec<String> = threads
                .iter()
                .filter_map(|&t| rows.iter().find(|r| r.engine == e && r.threads == t))
                .map(|r| format!("{:.2}x", r.closest_spread))
                .collect();
            format!("{e} {}", spreads.join(" / "))
        })
        .collect();
    let counts: Vec<String> = threads.iter().map(|t| t.to_string()).collect();
    let plural = if threads == [1] { "" } else { "s" };
    println!(
        "closest-hit rounds, median over fastest ({} thread{plural}): {}",
        counts.join(" / "),
        each.join(", ")
    );
}

/// The engines of `rows` in their order, each once (their rows come together, one per thread
/// count).
fn engine_names(rows: &[EngineResult]) -> Vec<&str> {
    let mut engines: Vec<&str> = rows.iter().map(|r| r.engine.as_str()).collect();
    engines.dedup();
    engines
}

/// The engines whose rows carry `part`, each with it (the one-thread rows of single-ray
/// engines, for the split and the secondary rays), in their order.
fn rows_with<T>(
    rows: &[EngineResult],
    part: impl Fn(&EngineResult) -> Option<T>,
) -> Vec<(&str, T)> {
    rows.iter()
        .filter_map(|r| Some((r.engine.as_str(), part(r)?)))
        .collect()
}

/// The one-thread single-ray rates on the rays that hit and on those that miss, apart, and
/// tracery-sah's ratios to Embree on each.
fn print_split(rows: &[EngineResult]) {
    let split = rows_with(rows, |r| r.split);
    let Some((_, first)) = split.first() else {
        return;
    };
    println!(
        "one thread, single rays, the {} rays that hit and the {} that miss apart (Mr/s):",
        first.hit_rays, first.miss_rays
    );
    println!(
        "{:<15} {:>12} {:>13} {:>13} {:>14}",
        "engine", "closest hit", "closest miss", "occluded hit", "occluded miss"
    );
    for (engine, s) in &split {
        println!(
            "{:<15} {:>12.2} {:>13.2} {:>13.2} {:>14.2}",
            engine,
            s.closest_hit_mrays,
            s.closest_miss_mrays,
            s.occluded_hit_mrays,
            s.occluded_miss_mrays
        );
    }
    let find = |e: &str| split.iter().find(|(n, _)| *n == e).map(|(_, s)| s);
    if let (Some(us), Some(them)) = (find("tracery-sah"), find("embree")) {
        println!(
            "tracery-sah / embree (1 thread): rays that hit: closest {:.2}x, occluded {:.2}x; \
             rays that miss: closest {:.2}x, occluded {:.2}x",
            us.closest_hit_mrays / them.closest_hit_mrays,
            us.occluded_hit_mrays / them.occluded_hit_mrays,
            us.closest_miss_mrays / them.closest_miss_mrays,
            us.occluded_miss_mrays / them.occluded_miss_mrays
        );
    }
}

/// The one-thread rates on the secondary rays (a diffuse bounce and a shadow ray from each
/// canonical hit): single rays, and Embree's batched query (`embree-packet16`: its stream
/// queries, 1024 rays a call, incoherent flag); tracery-sah's ratios to both.
fn print_secondary(rows: &[EngineResult]) {
    let second = rows_with(rows, |r| r.secondary);
    let Some((_, first)) = second.first() else {
        return;
    };
    println!(
        "one thread, secondary rays from the {} hits: a diffuse bounce each (closest) and a \
         shadow ray to a light above the mesh (occluded), single rays (embree-packet16: \
         rtcIntersect1M / rtcOccluded1M, 1024 rays a call) (Mr/s):",
        first.rays
    );
    println!(
        "{:<15} {:>15} {:>16} {:>9} {:>14}",
        "engine", "bounce closest", "shadow occluded", "agree %", "shadows blocked"
    );
    for (engine, s) in &second {
        println!(
            "{:<15} {:>15.2} {:>16.2} {:>9.3} {:>14}",
            engine,
            s.bounce_closest_mrays,
            s.shadow_occluded_mrays,
            s.bounce_agreement * 100.0,
            s.shadow_blocked
        );
    }
    let find = |e: &str| second.iter().find(|(n, _)| *n == e).map(|(_, s)| s);
    for peer in ["embree", "embree-packet16"] {
        if let (Some(us), Some(them)) = (find("tracery-sah"), find(peer)) {
            println!(
                "tracery-sah / {peer} (1 thread): secondary rays: bounce closest {:.2}x, shadow occluded {:.2}x",
                us.bounce_closest_mrays / them.bounce_closest_mrays,
                us.shadow_occluded_mrays / them.shadow_occluded_mrays
            );
        }
    }
}
