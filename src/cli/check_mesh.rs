//! `tracery check-mesh`: what is wrong with a mesh, before it is rendered.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Result;
use clap::Args;
use tracery::scene::check::{Finding, MeshReport, NEEDLE_ASPECT, check_mesh};

use super::load_flat_scene;

#[derive(Args, Debug)]
pub struct CheckMeshArgs {
    /// Mesh (OBJ, PLY, glTF) or scene file (TOML: all its meshes together).
    path: PathBuf,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
}

/// Exit status 0: clean; 1: findings that change what a renderer sees (non-finite,
/// degenerate or duplicate triangles, non-manifold edges); 2: the file could not be read.
pub fn run(a: CheckMeshArgs) -> ExitCode {
    match check(&a) {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn check(a: &CheckMeshArgs) -> Result<bool> {
    let scene = load_flat_scene(Some(&a.path), "check-mesh")?;
    let mut r = check_mesh(&scene.mesh.triangles);
    // Bounds in world coordinates (the mesh is stored about its own origin).
    let o = scene.mesh.origin;
    if let Some(b) = r.bounds.as_mut() {
        for v in b.iter_mut() {
            *v = std::array::from_fn(|i| (o[i] + v[i] as f64) as f32);
        }
    }
    if a.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        print_report(&a.path.display().to_string(), &r);
    }
    Ok(r.is_clean())
}

fn line(label: &str, f: &Finding) {
    let examples = if f.examples.is_empty() {
        String::new()
    } else {
        let list: Vec<String> = f.examples.iter().map(usize::to_string).collect();
        let more = if f.count > f.examples.len() {
            ", ..."
        } else {
            ""
        };
        format!("  (triangles {}{more})", list.join(", "))
    };
    println!("{label:<22}{:>10}{examples}", f.count);
}

fn print_report(name: &str, r: &MeshReport) {
    println!(
        "{name}: {} triangles, {} distinct vertices",
        r.triangles, r.vertices
    );
    match r.bounds {
        Some([lo, hi]) => println!("{:<22}{lo:?} .. {hi:?}", "bounds"),
        None => println!("{:<22}none (no finite vertex)", "bounds"),
    }
    line("non-finite", &r.non_finite);
    line("degenerate (area 0)", &r.degenerate);
    line(&format!("needles (> {NEEDLE_ASPECT}:1)"), &r.needles);
    line("duplicates", &r.duplicates);
    line("open edges", &r.open_edges);
    line("non-manifold edges", &r.non_manifold_edges);
    println!(
        "{:<22}{}",
        "closed",
        if r.is_closed() { "yes" } else { "no" }
    );
    println!(
        "{:<22}{}",
        "result",
        if r.is_clean() {
            "clean"
        } else {
            "NOT CLEAN: the renderer leaves out non-finite and degenerate triangles, and \
             duplicates or non-manifold edges double surfaces"
        }
    );
}
