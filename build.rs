//! Records the git commit the program is built from, for `tracery --version`.
//!
//! The build script reruns when HEAD moves (a checkout or a commit), and only then: it watches
//! HEAD and the ref it points to, not the work tree. Outside a git checkout (a source tarball)
//! the commit reads "unknown".

use std::path::Path;
use std::process::Command;

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

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
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
