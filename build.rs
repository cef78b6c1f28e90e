//! Records the git commit the program is built from, for `tracery --version` and the header of
//! every part of a split render (`render --samples`); with the `denoise` feature, checks that
//! Intel Open Image Denoise has been fetched (a clear message instead of the linker's) and
//! writes its folder into the binaries' run path.
//!
//! The build script reruns when HEAD moves (a checkout or a commit), and only then: it watches
//! HEAD and the ref it points to, not the work tree. Outside a git checkout (a source tarball)
//! the commit reads "unknown".

use std::path::{Path, PathBuf};
use std::process::Command;

#[path = "src/denoise/library.rs"]
#[allow(dead_code)]
mod library;

/// A git command's trimmed output, or `None` where git or the repository is missing.
fn git(args: &[&str]) -> Option<String> {
    let out = Command::new("git").args(args).output().ok()?;
    if !out.status.success() {
        return None;
    }
    let s = String::from_utf8(out.stdout).ok()?.trim().to_string();
    (!s.is_empty()).then_some(s)
}

/// Asks cargo to rerun this script when the git file `name` (HEAD, a ref) changes.
fn watch(name: &str) {
    if let Some(path) = git(&["rev-parse", "--git-path", name]) {
        // A path that does not exist would make cargo rerun the script on every build.
        if Path::new(&path).exists() {
            println!("cargo:rerun-if-changed={path}");
        }
    }
}

/// The denoiser's library: stops the build with the fetch script's name when it is missing,
/// and gives the binaries, tests and examples its folder as their run path.
fn link_denoiser() {
    println!("cargo:rerun-if-env-changed=OIDN_DIR");
    let root = std::env::var_os("OIDN_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("assets/external/oidn"));
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").unwrap_or_default());
    let dir = manifest.join(library::lib_dir(&root));
    for name in library::FILES {
        println!("cargo:rerun-if-changed={}", dir.join(name).display());
    }
    if let Err(message) = library::check(&dir) {
        for line in message.lines() {
            println!("cargo::error={line}");
        }
        std::process::exit(1);
    }
    println!("cargo:rustc-link-arg=-Wl,-rpath,{}", dir.display());
}

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed=src/denoise/library.rs");
    if std::env::var_os("CARGO_FEATURE_DENOISE").is_some() {
        link_denoiser();
    }
    watch("HEAD");
    watch("packed-refs");
    if let Some(reference) = git(&["symbolic-ref", "-q", "HEAD"]) {
        watch(&reference);
    }
    let commit = git(&["rev-parse", "--short=10", "HEAD"]).unwrap_or_else(|| "unknown".into());
    let date = git(&["log", "-1", "--format=%cd", "--date=short"]).unwrap_or_default();
    println!("cargo:rustc-env=TRACERY_COMMIT={commit}");
    println!("cargo:rustc-env=TRACERY_COMMIT_DATE={date}");
}
