//! glTF's `EXT_meshopt_compression` and `KHR_meshopt_compression`: the same models written by
//! gltfpack (meshoptimizer's glTF packer, the format's reference encoder) plain and compressed,
//! which must load to the same triangles; and compressed files made wrong, which must be refused with a message naming the
//! file and the view. The files are made by `scripts/fetch-assets meshopt` (gltfpack from npm,
//! run by node, from assimp's samples).

mod common;

use std::path::Path;

use glam::{Vec2, Vec3};
use serde_json::Value;
use tracery::scene::{Mesh, Scene};

fn load(path: &Path) -> Scene {
    Scene::load(path).unwrap_or_else(|e| panic!("{e:#}"))
}

/// The fetched pair `plain` and `compressed`, loaded.
fn pair(plain: &str, compressed: &str) -> Option<(Scene, Scene)> {
    let a = common::external(&format!("meshopt/{plain}"))?;
    let b = common::external(&format!("meshopt/{compressed}"))?;
    Some((load(&a), load(&b)))
}

/// A triangle's corners, normals and texture coordinates, turned (as a whole, so the winding
/// stays) to start at its lowest corner: the index codec keeps the triangles' order but may
/// start each one at another corner.
type Corners = ([Vec3; 3], [Vec3; 3], [Vec2; 3]);

fn turned(m: &Mesh) -> Vec<Corners> {
    let bits = |p: Vec3| p.to_array().map(f32::to_bits);
    (0..m.triangles.len())
        .map(|i| {
            let t = m.triangles[i];
            let n = m.normals[i];
            // The lowest corner by position, then normal: two corners may share a position.
            let first = (0..3)
                .min_by_key(|&k| {
                    let key = |j: usize| (bits(t[j]), bits(n[j]));
                    [key(k), key((k + 1) % 3), key((k + 2) % 3)]
                })
                .unwrap();
            let turn = |k: usize| (first + k) % 3;
            let uv = m.uvs.get(i).copied().unwrap_or([Vec2::ZERO; 3]);
            (
                [0, 1, 2].map(|k| t[turn(k)]),
                [0, 1, 2].map(|k| m.normals[i][turn(k)]),
                [0, 1, 2].map(|k| uv[turn(k)]),
            )
        })
        .collect()
}

/// Every triangle of `a` and `b`, in the same order, has the same corners, normals, texture
/// coordinates and material, bit for bit (each triangle maybe started at another corner).
fn assert_same_mesh(a: &Mesh, b: &Mesh, what: &str) {
    assert_eq!(
        a.triangles.len(),
        b.triangles.len(),
        "{what}: triangle count"
    );
    assert!(!a.triangles.is_empty(), "{what}: no triangles");
    assert_eq!(a.material_ids, b.material_ids, "{what}: materials differ");
    for (i, (x, y)) in turned(a).iter().zip(turned(b)).enumerate() {
        assert!(
            x.0 == y.0,
            "{what}: triangle {i}: positions {:?} and {:?}",
            x.0,
            y.0
        );
        assert!(
            x.1 == y.1,
            "{what}: triangle {i}: normals {:?} and {:?}",
            x.1,
            y.1
        );
        assert!(
            x.2 == y.2,
            "{what}: triangle {i}: texture coordinates {:?} and {:?}",
            x.2,
            y.2
        );
    }
}

/// gltfpack's quantized engine (positions as 16-bit integers, normals as 8-bit ones), plain and
/// compressed by the vertex and index codecs without filters, by either extension (`-c`, `-c
/// -ce khr`): the same triangles. Fails with the compressed views read as they are stored (the
/// loader refused the files before).
#[test]
fn compressed_engine_loads_as_the_plain_one() {
    for file in ["engine_c.glb", "engine_c_khr.glb"] {
        let Some((plain, packed)) = pair("engine.glb", file) else {
            return;
        };
        let n = plain.triangle_count();
        assert!(n > 100_000, "{n}");
        assert_same_mesh(&plain.mesh, &packed.mesh, file);
    }
}

/// The textured box: its texture coordinates (and the image in the GLB) come through the
/// compressed views as the plain file gives them.
#[test]
fn compressed_textured_box_loads_as_the_plain_one() {
    let Some((plain, packed)) = pair("box.glb", "box_c.glb") else {
        return;
    };
    assert!(plain.mesh.uvs.iter().flatten().any(|uv| *uv != Vec2::ZERO));
    assert_same_mesh(&plain.mesh, &packed.mesh, "box -c");
    assert_eq!(
        plain.materials.len(),
        packed.materials.len(),
        "box -c: materials"
    );
}

/// Positions kept as floats (`-vpf`), which the compressed file stores through the exponential
/// filter (a shared exponent per vector, fewer mantissa bits): within the filter's precision of
/// the plain file's, normals the same. Fails with the filter left out (the raw mantissas).
#[test]
fn exponential_filter_positions_match_within_their_precision() {
    let Some((plain, packed)) = pair("engine_vpf.glb", "engine_vpf_c.glb") else {
        return;
    };
    let (a, b) = (&plain.mesh, &packed.mesh);
    assert_eq!(a.triangles.len(), b.triangles.len());
    // gltfpack orders the triangles differently here: compared axis by axis, each axis's
    // coordinates sorted (sorting moves no value by more than the largest difference).
    let extent = a.bounds().extent().length();
    let mut worst = 0.0f32;
    for axis in 0..3 {
        let coords = |m: &Mesh| {
            let mut v: Vec<f32> = m.triangles.iter().flatten().map(|p| p[axis]).collect();
            v.sort_by(f32::total_cmp);
            v
        };
        for (x, y) in coords(a).iter().zip(coords(b)) {
            worst = worst.max((x - y).abs());
        }
    }
    assert!(
        worst > 0.0 && worst <= 1e-3 * extent,
        "positions differ by up to {worst} (extent {extent})"
    );
    let normals = |m: &Mesh| {
        let mut v: Vec<[u32; 3]> = m
            .normals
            .iter()
            .flatten()
            .map(|n| n.to_array().map(f32::to_bits))
            .collect();
        v.sort();
        v
    };
    assert!(normals(a) == normals(b), "normals differ");
}

/// `-cc` (EXT) and `-cz` (KHR, the vertex codec's second version) store normals by the
/// octahedral filter (two 8-bit angles' worth instead of three components): each within a few
/// degrees of the plain file's, the positions the same (the triangles in another order).
#[test]
fn octahedral_filter_normals_match_within_their_precision() {
    for file in ["engine_cc.glb", "engine_cz.glb"] {
        octahedral_pair(file);
    }
}

fn octahedral_pair(file: &str) {
    let Some((plain, packed)) = pair("engine.glb", file) else {
        return;
    };
    // In another order here: both sorted by their corners' positions.
    let sorted = |m: &Mesh| {
        let mut v = turned(m);
        v.sort_by_key(|c| c.0.map(|p| p.to_array().map(f32::to_bits)));
        v
    };
    let (a, b) = (sorted(&plain.mesh), sorted(&packed.mesh));
    assert_eq!(a.len(), b.len());
    let mut worst = 1.0f32;
    for (x, y) in a.iter().zip(&b) {
        assert!(x.0 == y.0, "{file}: positions {:?} and {:?}", x.0, y.0);
        for (na, nb) in x.1.iter().zip(&y.1) {
            worst = worst.min(na.normalize().dot(nb.normalize()));
        }
    }
    assert!(
        worst > 5f32.to_radians().cos(),
        "{file}: a normal turned by {} degrees",
        worst.acos().to_degrees()
    );
}

/// A change made to a compressed view's extension object and the file's binary buffer.
type Edit = dyn Fn(&mut Value, &mut Vec<u8>);

/// `engine_c.gltf` (its JSON and `.bin` copied into a temporary folder) with `edit` applied to
/// the first compressed view's extension object: the load's error, or `None` when it loads.
fn load_edited(edit: impl Fn(&mut Value, &mut Vec<u8>)) -> Option<Result<Scene, String>> {
    let src = common::external("meshopt/engine_c.gltf")?;
    let dir = tempfile::tempdir().unwrap();
    let mut json: Value = serde_json::from_slice(&std::fs::read(&src).unwrap()).unwrap();
    let mut bin = std::fs::read(src.with_extension("bin")).unwrap();
    let ext = json["bufferViews"]
        .as_array_mut()
        .unwrap()
        .iter_mut()
        .find_map(|v| v.pointer_mut("/extensions/EXT_meshopt_compression"))
        .expect("a compressed view");
    edit(ext, &mut bin);
    let path = dir.path().join("engine_c.gltf");
    std::fs::write(&path, serde_json::to_vec(&json).unwrap()).unwrap();
    std::fs::write(dir.path().join("engine_c.bin"), &bin).unwrap();
    Some(Scene::load(&path).map_err(|e| format!("{e:#}")))
}

/// Compressed data made wrong is an error naming the file, the view and what is wrong, never a
/// panic or a silently wrong mesh: the stream overwritten, an unknown mode and filter, a view
/// past its buffer, a count that is not the view's (a million times it: refused before
/// anything is decoded), a field missing. The file unchanged loads.
#[test]
fn bad_compressed_views_are_refused_by_name() {
    let Some(ok) = load_edited(|_, _| {}) else {
        return;
    };
    assert!(ok.is_ok(), "{:?}", ok.err());
    let cases: Vec<(&str, Box<Edit>, &str)> = vec![
        (
            "stream overwritten",
            Box::new(|ext, bin| {
                let start = ext["byteOffset"].as_u64().unwrap_or(0) as usize;
                let len = ext["byteLength"].as_u64().unwrap() as usize;
                bin[start..start + len].fill(0xff);
            }),
            "cannot decode",
        ),
        (
            "unknown mode",
            Box::new(|ext, _| ext["mode"] = "BOGUS".into()),
            "unknown mode BOGUS",
        ),
        (
            "unknown filter",
            Box::new(|ext, _| ext["filter"] = "FANCY".into()),
            "unknown filter FANCY",
        ),
        (
            "past its buffer",
            Box::new(|ext, _| ext["byteOffset"] = 10_000_000.into()),
            "run past buffers[",
        ),
        (
            "count not the view's",
            Box::new(|ext, _| {
                let n = ext["count"].as_u64().unwrap();
                ext["count"] = (n * 1_000_000).into();
            }),
            "where the view's byteLength is",
        ),
        (
            "count missing",
            Box::new(|ext, _| {
                ext.as_object_mut().unwrap().remove("count");
            }),
            "`count` is missing",
        ),
    ];
    for (what, edit, expected) in cases {
        let got = load_edited(edit).unwrap();
        let err = match got {
            Ok(_) => panic!("{what}: loaded"),
            Err(e) => e,
        };
        assert!(
            err.contains("engine_c.gltf")
                && err.contains("bufferViews[")
                && err.contains("EXT_meshopt_compression")
                && err.contains(expected),
            "{what}: {err}"
        );
    }
}
