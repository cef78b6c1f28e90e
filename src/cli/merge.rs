//! `tracery merge`: the parts of a render split by samples added into the whole render.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use tracery::film::OutputKind;
use tracery::render::part::{Part, merge};

use super::ensure_parent;

#[derive(Args, Debug)]
pub struct MergeArgs {
    /// The parts (EXR files written by `tracery render --samples A..B`), in any order; their
    /// sample ranges must cover 0..N once each.
    #[arg(required = true)]
    parts: Vec<PathBuf>,
    /// Output image: `.png` (tone mapped, after `--exposure`), `.exr` or `.hdr` (linear
    /// radiance).
    #[arg(short, long, default_value = "out/merged.png")]
    output: PathBuf,
    /// Exposure multiplier applied before tone mapping (PNG).
    #[arg(long, default_value_t = 1.0)]
    exposure: f32,
}

pub fn run(a: MergeArgs) -> Result<()> {
    // Checked first: a typo in the output name does not cost the reading of every part.
    OutputKind::of(&a.output)?;
    let mut parts = Vec::with_capacity(a.parts.len());
    for p in &a.parts {
        let part = Part::load(p)?;
        eprintln!(
            "{}: samples {}..{}, {}x{}",
            p.display(),
            part.range.start,
            part.range.end,
            part.film.width,
            part.film.height
        );
        parts.push((p.clone(), part));
    }
    let film = merge(&parts)?;
    let path = ensure_parent(&a.output)?;
    film.save(&path, a.exposure)?;
    println!(
        "wrote {}: {} parts merged, {} samples in every pixel ({}x{}){}",
        path.display(),
        parts.len(),
        film.samples,
        film.width,
        film.height,
        if film.rejected > 0 {
            format!(", {} non-finite samples left out", film.rejected)
        } else {
            String::new()
        }
    );
    Ok(())
}
