//! The error of one linear image (EXR or HDR) against another of the same size: RMSE and
//! relative RMSE (the square root of the relative MSE the convergence report uses,
//! [`tracery::convergence::errors`]), over all pixels and channels.
//!
//! `cargo run --release --example image_error -- IMAGE REFERENCE`
use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use tracery::convergence::{errors, load_reference};

fn main() -> Result<()> {
    let args: Vec<PathBuf> = std::env::args_os().skip(1).map(PathBuf::from).collect();
    let [image, reference] = args.as_slice() else {
        bail!("usage: image_error IMAGE REFERENCE (linear EXR or HDR images of the same size)");
    };
    let (width, height) = image::image_dimensions(reference)
        .with_context(|| format!("{}: cannot read the image", reference.display()))?;
    let a = load_reference(image, width, height)?;
    let b = load_reference(reference, width, height)?;
    let (rmse, rel_mse) = errors(&a, &b);
    println!("rmse {rmse:.6e} relative_rmse {:.6e}", rel_mse.sqrt());
    Ok(())
}
