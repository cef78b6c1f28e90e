//! `tracery stats`: BVH statistics, median and SAH side by side.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use tracery::bvh::{BuildOptions, Bvh, BvhStats, SplitMethod};

use super::load_flat_scene;

#[derive(Args, Debug)]
pub struct StatsArgs {
    /// Mesh (OBJ, PLY, glTF) or scene file (TOML); the built-in Cornell box when left out.
    path: Option<PathBuf>,
    /// Only this split method (median or sah); both side by side when left out.
    #[arg(long)]
    split: Option<SplitMethod>,
    /// SAH bins per axis (2 to 64).
    #[arg(long, default_value_t = BuildOptions::DEFAULT_BINS)]
    bins: u32,
    /// Largest number of triangles in a leaf (1 to 255).
    #[arg(long, default_value_t = BuildOptions::DEFAULT_LEAF_SIZE)]
    leaf_size: u32,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
}

#[derive(serde::Serialize)]
struct Row {
    scene: String,
    split: SplitMethod,
    bins: u32,
    leaf_size: u32,
    #[serde(flatten)]
    stats: BvhStats,
}

pub fn run(a: StatsArgs) -> Result<()> {
    let scene = load_flat_scene(a.path.as_deref(), "stats")?;
    let base = BuildOptions {
        split: a.split.unwrap_or(SplitMethod::Sah),
        bins: a.bins,
        max_leaf_size: a.leaf_size,
    };
    base.validate().map_err(anyhow::Error::msg)?;
    let splits = match a.split {
        Some(s) => vec![s],
        None => vec![SplitMethod::Median, SplitMethod::Sah],
    };
    let mut rows = Vec::new();
    for split in splits {
        let options = base.with_split(split);
        let bvh = Bvh::build(&scene.mesh.triangles, &options);
        rows.push(Row {
            scene: scene.name.clone(),
            split,
            bins: options.bins,
            leaf_size: options.max_leaf_size,
            stats: bvh.stats,
        });
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
        return Ok(());
    }
    println!(
        "{}: {} triangles (SAH cost constants: traversal {}, a block of four triangles {}, two \
         blocks tested together {})",
        scene.name,
        scene.triangle_count(),
        tracery::bvh::sah::C_TRAVERSE,
        tracery::bvh::sah::C_INTERSECT,
        tracery::bvh::sah::C_INTERSECT * tracery::bvh::sah::PAIR_TEST
    );
    println!(
        "{:<8} {:>5} {:>5} {:>10} {:>9} {:>7} {:>16} {:>9} {:>10} {:>9} {:>10} {:>17} {:>11} {:>11} {:>13}",
        "split",
        "bins",
        "leaf",
        "nodes",
        "leaves",
        "levels",
        "leaf min/mean/max",
        "SAH cost",
        "non-finite",
        "zero-area",
        "build ms",
        "refs/tree/layout",
        "8-wide nodes",
        "blocks of 4",
        "bytes/tri b+w"
    );
    for r in &rows {
        let s = &r.stats;
        println!(
            "{:<8} {:>5} {:>5} {:>10} {:>9} {:>7} {:>16} {:>9.2} {:>10} {:>9} {:>10.2} {:>17} {:>11} {:>11} {:>13}",
            r.split.to_string(),
            if r.split == SplitMethod::Sah {
                r.bins.to_string()
            } else {
                "-".into()
            },
            r.leaf_size,
            s.nodes,
            s.leaves,
            s.levels,
            format!(
                "{}/{:.2}/{}",
                s.min_leaf_size, s.mean_leaf_size, s.max_leaf_size
            ),
            s.sah_cost,
            s.excluded,
            s.degenerate,
            s.build_ms,
            format!(
                "{:.1}/{:.1}/{:.1}",
                s.phases.references_ms, s.phases.tree_ms, s.phases.layout_ms
            ),
            s.wide_nodes,
            s.blocks,
            format!(
                "{:.0}+{:.0}",
                s.binary_bytes_per_triangle(),
                s.wide_bytes_per_triangle()
            )
        );
    }
    Ok(())
}
