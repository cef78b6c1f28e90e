//! `tracery render`: placeholder until the renderer lands below.
use anyhow::Result;
use clap::Args;

#[derive(Args, Debug)]
pub struct RenderArgs {}

pub fn run(_a: RenderArgs) -> Result<()> {
    anyhow::bail!("not yet")
}
