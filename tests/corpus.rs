//! Every OBJ in the fetched corpora (tinyobjloader's `models/`, assimp's `invalid/` and
//! `OBJ/`) and every PLY of assimp's `PLY/` loads or fails with an error naming the file (and
//! the line where the parser's error can be placed): no panic, no hang.

mod common;

use std::path::{Path, PathBuf};

use tracery::scene::Scene;

fn files_of(dir: &Path, ext: &str, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            files_of(&p, ext, out);
        } else if p.extension().is_some_and(|x| x.eq_ignore_ascii_case(ext)) {
            out.push(p);
        }
    }
}

fn objs(dir: &Path, out: &mut Vec<PathBuf>) {
    files_of(dir, "obj", out);
}

/// Loads every file on its own thread with a time bound: each loads, or fails with a message
/// naming it; returns (loaded, refused).
fn load_all(files: &[PathBuf]) -> (usize, usize) {
    let (mut loaded, mut failed) = (0, 0);
    for f in files {
        match common::load_bounded(f) {
            Ok(_) => loaded += 1,
            Err(msg) => {
                let name = f.file_name().unwrap().to_string_lossy();
                assert!(msg.contains(&*name), "{}: {msg}", f.display());
                assert!(
                    !msg.contains('\n'),
                    "{}: a one-line message: {msg}",
                    f.display()
                );
                failed += 1;
            }
        }
    }
    (loaded, failed)
}

#[test]
fn every_corpus_obj_loads_or_fails_with_a_message_naming_it() {
    let mut files = Vec::new();
    // One file of each folder proves the folder was fetched.
    for probe in [
        "corpus/tinyobjloader/cube.obj",
        "corpus/assimp/OBJ/box.obj",
        "corpus/assimp/invalid/malformed.obj",
    ] {
        let Some(p) = common::external(probe) else {
            return;
        };
        objs(p.parent().unwrap(), &mut files);
    }
    files.sort();
    files.dedup();
    assert!(files.len() > 50, "{} files", files.len());
    let (loaded, failed) = load_all(&files);
    eprintln!("{loaded} loaded, {failed} refused with a message");
    assert!(loaded > 0 && failed > 0);
}

#[test]
fn known_bad_corpus_files_name_their_line() {
    for (file, line) in [
        ("corpus/assimp/invalid/malformed.obj", 23),
        ("corpus/tinyobjloader/issue-140-zero-face-idx.obj", 16),
        ("corpus/assimp/OBJ/empty_mat.obj", 233),
        ("corpus/assimp/OBJ/box_UTF16BE.obj", 1),
    ] {
        let Some(p) = common::external(file) else {
            return;
        };
        let e = format!("{:#}", Scene::load(&p).unwrap_err());
        let name = p.file_name().unwrap().to_string_lossy();
        assert!(e.contains(&format!("{name}:{line}:")), "{e}");
    }
}

/// Every PLY of assimp's test models (ASCII and binary, a Blender 2.4 header, colours, points,
/// a truncated binary file) loads or fails with a one-line message naming it; the ones that
/// load have the triangles their headers promise.
#[test]
fn every_corpus_ply_loads_or_fails_with_a_message_naming_it() {
    let Some(probe) = common::external("corpus/assimp/PLY/cube.ply") else {
        return;
    };
    let mut files = Vec::new();
    files_of(probe.parent().unwrap(), "ply", &mut files);
    files.sort();
    assert!(files.len() >= 8, "{} files", files.len());
    let (loaded, failed) = load_all(&files);
    eprintln!("{loaded} loaded, {failed} refused with a message");
    assert!(loaded >= 5 && failed >= 1);
    // Blender 2.4's header line `Created by Blender3D 247 ...` is read as a comment: 3,732
    // triangles; the cube of six quads fans into 12, as does the binary one.
    for (file, tris) in [
        ("Wuson.ply", 3_732),
        ("cube.ply", 12),
        ("cube_binary.ply", 12),
    ] {
        let s = Scene::load(&probe.with_file_name(file)).unwrap();
        assert_eq!(s.triangle_count(), tris, "{file}");
    }
    let e = format!(
        "{:#}",
        Scene::load(&probe.with_file_name("pond.0.ply")).unwrap_err()
    );
    assert!(e.contains("pond.0.ply") && e.contains("end of file"), "{e}");
}
