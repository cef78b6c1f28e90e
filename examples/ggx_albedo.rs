//! Writes `src/render/bsdf/ggx_albedo.rs`: the GGX lobe's directional albedo with a Fresnel of
//! 1 over roughness and the cosine of the view, and its cosine-weighted mean per roughness,
//! integrated numerically by `tracery::render::bsdf::compensation::integrate_albedo` and
//! `integrate_average` (the midpoint rule on 256 x 256 visible normals; the mean on 64
//! cosines). The renderer reads it for the GGX lobe's energy compensation; a test in
//! `src/render/bsdf/compensation.rs` integrates entries again and compares.
//!
//! `cargo run --release --example ggx_albedo`
use std::fmt::Write;

use anyhow::Result;
use rayon::prelude::*;
use tracery::render::bsdf::compensation::{
    integrate_albedo, integrate_average, table_alpha, table_cosine,
};
use tracery::render::bsdf::ggx_albedo::{COSINES, ROUGHNESSES};

fn main() -> Result<()> {
    let rows: Vec<(Vec<f32>, f32)> = (0..ROUGHNESSES)
        .into_par_iter()
        .map(|i| {
            let a = table_alpha(i);
            let row = (0..COSINES)
                .map(|j| integrate_albedo(table_cosine(j), a, 256) as f32)
                .collect();
            (row, integrate_average(a, 64, 256) as f32)
        })
        .collect();
    let mut out = String::new();
    writeln!(
        out,
        "//! The GGX lobe's directional albedo with a Fresnel of 1 (`super::compensation`), written\n\
         //! by `examples/ggx_albedo.rs`: row `i` for roughness `i / (ROUGHNESSES - 1)` (width its\n\
         //! square, at least `MIN_ALPHA`), column `j` for the view's cosine `j / (COSINES - 1)` (at\n\
         //! least `compensation::MIN_COSINE`); and per row its cosine-weighted mean. Generated: do\n\
         //! not edit by hand.\n\n\
         /// Rows of the table (roughness from 0 to 1).\n\
         pub const ROUGHNESSES: usize = {ROUGHNESSES};\n\n\
         /// Columns of the table (the view's cosine from 0 to 1).\n\
         pub const COSINES: usize = {COSINES};\n\n\
         /// The albedo by roughness, then cosine.\n\
         #[rustfmt::skip]\n\
         pub const ALBEDO: [[f32; COSINES]; ROUGHNESSES] = ["
    )?;
    for (row, _) in &rows {
        out += "    [";
        for (j, x) in row.iter().enumerate() {
            if j > 0 {
                out += ", ";
            }
            write!(out, "{x:?}")?;
        }
        out += "],\n";
    }
    out += "];\n\n/// The albedo's cosine-weighted mean by roughness, `2 int E(mu) mu dmu`.\n#[rustfmt::skip]\npub const AVERAGE: [f32; ROUGHNESSES] = [";
    for (i, (_, average)) in rows.iter().enumerate() {
        if i > 0 {
            out += ", ";
        }
        write!(out, "{average:?}")?;
    }
    out += "];\n";
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src/render/bsdf/ggx_albedo.rs");
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
