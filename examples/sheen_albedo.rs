//! Writes `src/render/bsdf/sheen_albedo.rs`: the directional albedo of `KHR_materials_sheen`'s
//! Charlie sheen (colour 1) over roughness and the cosine of the view, integrated numerically
//! by `tracery::render::bsdf::sheen::integrate_albedo` (the midpoint rule, 512 cosines by 256
//! angles over half the circle about the normal). The renderer reads it to dim the lobes under a sheen; a test in
//! `src/render/bsdf/sheen.rs` integrates entries again and compares.
//!
//! `cargo run --release --example sheen_albedo`
use anyhow::Result;
use rayon::prelude::*;
use std::fmt::Write;
use tracery::render::bsdf::sheen::{integrate_albedo, table_cosine, table_roughness};
use tracery::render::bsdf::sheen_albedo::{COSINES, ROUGHNESSES};

fn main() -> Result<()> {
    let rows: Vec<Vec<f32>> = (0..ROUGHNESSES)
        .into_par_iter()
        .map(|i| {
            (0..COSINES)
                .map(|j| integrate_albedo(table_cosine(j), table_roughness(i), 512, 256) as f32)
                .collect()
        })
        .collect();
    let mut out = String::new();
    writeln!(
        out,
        "//! The directional albedo of the Charlie sheen of colour 1 (`super::sheen`), written by\n\
         //! `examples/sheen_albedo.rs`: row `i` for roughness `i / (ROUGHNESSES - 1)` (at least\n\
         //! `sheen::MIN_ROUGHNESS`), column `j` for the view's cosine `j / (COSINES - 1)` (at least\n\
         //! `sheen::MIN_COSINE`). Generated: do not edit by hand.\n\n\
         /// Rows of the table (roughness from 0 to 1).\n\
         pub const ROUGHNESSES: usize = {ROUGHNESSES};\n\n\
         /// Columns of the table (the view's cosine from 0 to 1).\n\
         pub const COSINES: usize = {COSINES};\n\n\
         /// The albedo by roughness, then cosine.\n\
         #[rustfmt::skip]\n\
         pub const ALBEDO: [[f32; COSINES]; ROUGHNESSES] = ["
    )?;
    for row in &rows {
        out += "    [";
        for (j, x) in row.iter().enumerate() {
            if j > 0 {
                out += ", ";
            }
            write!(out, "{x:?}")?;
        }
        out += "],\n";
    }
    out += "];\n";
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src/render/bsdf/sheen_albedo.rs");
    // Written only when the table changed: rewriting the same bytes would make cargo rebuild
    // the crate (and everything built on it) for nothing.
    if std::fs::read_to_string(&path).ok().as_deref() == Some(out.as_str()) {
        println!("{} is up to date", path.display());
    } else {
        std::fs::write(&path, out)?;
        println!("wrote {}", path.display());
    }
    Ok(())
}
