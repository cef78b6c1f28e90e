//! The font the plots are labelled with: DejaVu Sans from Debian's `fonts-dejavu-core`
//! (or the file `TRACERY_FONT` names), loaded once.

use std::sync::OnceLock;

use anyhow::{Result, anyhow};

const CANDIDATES: [&str; 2] = [
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
];

/// Registers the plot font with `plotters` (once); an error says how to get one.
pub fn ensure() -> Result<()> {
    static DONE: OnceLock<Result<(), String>> = OnceLock::new();
    DONE.get_or_init(|| {
        let path = std::env::var("TRACERY_FONT")
            .ok()
            .into_iter()
            .chain(CANDIDATES.iter().map(|s| s.to_string()))
            .find(|p| std::path::Path::new(p).is_file())
            .ok_or_else(|| {
                "no font for plot labels: install Debian's fonts-dejavu-core or set TRACERY_FONT to a .ttf file"
                    .to_string()
            })?;
        let bytes = std::fs::read(&path).map_err(|e| format!("{path}: {e}"))?;
        let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
        plotters::style::register_font("sans-serif", plotters::style::FontStyle::Normal, bytes)
            .map_err(|_| format!("{path}: not a usable TrueType font"))
    })
    .clone()
    .map_err(|e| anyhow!(e))
}
