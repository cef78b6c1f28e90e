//! Where the `denoise` feature finds Intel Open Image Denoise, and what it says when the
//! library is missing. Shared with `build.rs`, which checks the library before anything links
//! it (a clear message instead of a linker's) and writes its folder into the binaries' run
//! path (no `LD_LIBRARY_PATH` needed).

use std::path::{Path, PathBuf};

/// The command that fetches the library.
pub const FETCH: &str = "scripts/fetch-assets oidn";

/// The files the linker and the loader need, in the library folder: the name the linker looks
/// for, the library's own name (its soname) and the threading library it loads.
pub const FILES: [&str; 3] = [
    "libOpenImageDenoise.so",
    "libOpenImageDenoise.so.1",
    "libtbb.so.12",
];

/// The library folder under the install root `oidn_dir` (`OIDN_DIR`, which
/// `.cargo/config.toml` sets to `assets/external/oidn`).
pub fn lib_dir(oidn_dir: &Path) -> PathBuf {
    oidn_dir.join("lib")
}

/// Checks that the library folder `dir` holds every file of [`FILES`]; the message names the
/// missing file, the folder, the fetch script and how to build without the denoiser.
pub fn check(dir: &Path) -> Result<(), String> {
    for name in FILES {
        let path = dir.join(name);
        if !path.exists() {
            return Err(format!(
                "the denoiser (cargo feature `denoise`, on by default) needs Intel Open Image \
                 Denoise 1.4, and {} is missing.\nFetch it with `{FETCH}` (about 45 MB from \
                 PyPI), or build without the denoiser: `--no-default-features --features \
                 viewer`.",
                path.display()
            ));
        }
    }
    Ok(())
}
