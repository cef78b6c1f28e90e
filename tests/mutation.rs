//! Property-based bad input: valid OBJ, PLY (ASCII and binary), glTF (its JSON, its
//! buffer file, and GLB) and scene files are
//! mutated at random (bytes flipped, dropped, duplicated, tokens spliced in, the file cut
//! short) and loaded. Each load must return a scene or an error naming the file, within a
//! time bound, and never panic; a scene that loads must build a BVH and trace rays without
//! a panic or a NaN-poisoned tree. Failing inputs shrink to a small mutation list.

mod common;

use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Duration;

use base64::Engine as _;
use proptest::prelude::*;
use tracery::bvh::{Accel, BuildOptions};
use tracery::geometry::Ray;
use tracery::render::{RenderSettings, render};
use tracery::scene::Scene;

const OBJ: &str = "# a cube with a material library\nmtllib cube.mtl\no cube\nv -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\nvn 0 0 1\nvt 0.5 0.5\nusemtl red\nf 1 2 3 4\nf 5/1/1 6/1/1 7/1/1 8/1/1\nf 1 5 8 4\nf -7 -3 -2 -6\nf 4 3 7 8\nf 1 2 6 5\n";

const MTL: &str =
    "newmtl red\nKd 0.8 0.1 0.1\nKs 0.2 0.2 0.2\nNs 20\nd 0.5\nNi 1.5\nTf 0.9 0.9 0.9\n";

const PLY_ASCII: &str = "ply\nformat ascii 1.0\ncomment a square\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n";

const SCENE: &str = "[camera]\nposition = [0.0, 1.0, 5.0]\nlook_at = [0.0, 1.0, 0.0]\nfov = 50.0\nlens_radius = 0.1\nfocus_distance = 5.0\n\n[materials.gold]\ndiffuse = [0.8, 0.6, 0.2]\nmirror = [0.5, 0.5, 0.5]\nopacity = 0.5\nior = 1.3\n\n[[meshes]]\npath = \"square.ply\"\ntranslate = [1.0, 0.0, 0.0]\nrotate = [0.0, 30.0, 0.0]\nscale = [2.0, 1.0, 1.0]\nmaterial = \"gold\"\n\n[[meshes]]\nshape = \"sphere\"\nsubdivisions = 1\n\n[[lights]]\nkind = \"rect\"\ncorner = [-1.0, 4.0, -1.0]\nedge_u = [2.0, 0.0, 0.0]\nedge_v = [0.0, 0.0, 2.0]\nintensity = 20.0\nsamples = 2\n\n[environment]\nkind = \"sky\"\nintensity = 0.5\n";

/// A binary little-endian PLY: two triangles with float positions and uint indices.
fn ply_binary() -> Vec<u8> {
    let mut d = b"ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 2\nproperty list uchar uint vertex_indices\nend_header\n".to_vec();
    for v in [
        [0.0f32, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
    ] {
        for c in v {
            d.extend(c.to_le_bytes());
        }
    }
    for f in [[0u32, 1, 2], [0, 2, 3]] {
        d.push(3);
        for i in f {
            d.extend(i.to_le_bytes());
        }
    }
    d
}

/// A glTF quad under two nodes, its buffer in `quad.bin` ([`gltf_bin`]).
const GLTF: &str = r#"{"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[0]}],"nodes":[{"children":[1],"translation":[1,0,0]},{"mesh":0,"scale":[2,2,2]}],"meshes":[{"primitives":[{"attributes":{"POSITION":0,"NORMAL":1,"TEXCOORD_0":2},"indices":3,"material":0}]}],"materials":[{"pbrMetallicRoughness":{"baseColorFactor":[0.8,0.2,0.1,1.0],"metallicFactor":0.0},"alphaMode":"BLEND"}],"buffers":[{"byteLength":140,"uri":"quad.bin"}],"bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":48},{"buffer":0,"byteOffset":48,"byteLength":48,"byteStride":12},{"buffer":0,"byteOffset":96,"byteLength":32},{"buffer":0,"byteOffset":128,"byteLength":12}],"accessors":[{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3"},{"bufferView":1,"componentType":5126,"count":4,"type":"VEC3"},{"bufferView":2,"componentType":5126,"count":4,"type":"VEC2"},{"bufferView":3,"componentType":5123,"count":6,"type":"SCALAR"}]}"#;

/// The quad's buffer: positions, normals, texture coordinates (f32) and six u16 indices.
fn gltf_bin() -> Vec<u8> {
    let f: [f32; 32] = [
        0., 0., 0., 1., 0., 0., 1., 1., 0., 0., 1., 0., // positions
        0., 0., 1., 0., 0., 1., 0., 0., 1., 0., 0., 1., // normals
        0., 1., 1., 1., 1., 0., 0., 0., // texture coordinates
    ];
    let mut d: Vec<u8> = f.iter().flat_map(|x| x.to_le_bytes()).collect();
    d.extend([0u16, 1, 2, 0, 2, 3].iter().flat_map(|i| i.to_le_bytes()));
    d
}

/// The quad of [`GLTF`] with a morph target (at weight 0.5) and a skin of two joints, its
/// buffer in `skin.bin` ([`skinned_bin`]).
const SKINNED: &str = r#"{"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[0,1]}],"nodes":[{"mesh":0,"skin":0,"translation":[9,0,0]},{"translation":[0,0,1],"children":[2]},{"rotation":[0,0,0.7071068,0.7071068]}],"meshes":[{"primitives":[{"attributes":{"POSITION":0,"NORMAL":1,"TEXCOORD_0":2,"JOINTS_0":5,"WEIGHTS_0":6},"indices":3,"targets":[{"POSITION":4}]}],"weights":[0.5]}],"skins":[{"joints":[1,2],"inverseBindMatrices":7}],"buffers":[{"byteLength":400,"uri":"skin.bin"}],"bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":48},{"buffer":0,"byteOffset":48,"byteLength":48,"byteStride":12},{"buffer":0,"byteOffset":96,"byteLength":32},{"buffer":0,"byteOffset":128,"byteLength":12},{"buffer":0,"byteOffset":144,"byteLength":48},{"buffer":0,"byteOffset":192,"byteLength":16},{"buffer":0,"byteOffset":208,"byteLength":64},{"buffer":0,"byteOffset":272,"byteLength":128}],"accessors":[{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3"},{"bufferView":1,"componentType":5126,"count":4,"type":"VEC3"},{"bufferView":2,"componentType":5126,"count":4,"type":"VEC2"},{"bufferView":3,"componentType":5123,"count":6,"type":"SCALAR"},{"bufferView":4,"componentType":5126,"count":4,"type":"VEC3"},{"bufferView":5,"componentType":5121,"count":4,"type":"VEC4"},{"bufferView":6,"componentType":5126,"count":4,"type":"VEC4"},{"bufferView":7,"componentType":5126,"count":2,"type":"MAT4"}]}"#;

/// [`SKINNED`]'s buffer: the quad's, padded to 144 bytes, then the target's displacements
/// (the first vertex up by 2), joints (the first two vertices on joint 0, the others on joint
/// 1), weights and two identity inverse bind matrices.
fn skinned_bin() -> Vec<u8> {
    let mut d = gltf_bin();
    d.resize(144, 0);
    let f32s = |v: &[f32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
    d.extend(f32s(&[0., 0., 2., 0., 0., 0., 0., 0., 0., 0., 0., 0.]));
    d.extend([0u8, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0]);
    d.extend(f32s(&[1., 0., 0., 0.].repeat(4)));
    d.extend(f32s(&glam::Mat4::IDENTITY.to_cols_array().repeat(2)));
    d
}

/// The quad as one GLB: its JSON (without the buffer's URI) and its buffer as the BIN chunk.
fn glb() -> Vec<u8> {
    glb_of(
        GLTF.replace(r#","uri":"quad.bin""#, "").into_bytes(),
        gltf_bin(),
    )
}

/// A GLB of a JSON chunk and a BIN chunk.
fn glb_of(mut json: Vec<u8>, bin: Vec<u8>) -> Vec<u8> {
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let mut d = b"glTF".to_vec();
    d.extend(2u32.to_le_bytes());
    d.extend(((12 + 8 + json.len() + 8 + bin.len()) as u32).to_le_bytes());
    d.extend((json.len() as u32).to_le_bytes());
    d.extend(b"JSON");
    d.extend(json);
    d.extend((bin.len() as u32).to_le_bytes());
    d.extend(b"BIN\0");
    d.extend(bin);
    d
}

/// The quad's buffer followed by a PNG (buffer view 4), padded to four bytes.
fn textured_bin() -> Vec<u8> {
    let mut d = gltf_bin();
    assert!(
        d.len().is_multiple_of(4),
        "the PNG starts on a four-byte boundary"
    );
    d.extend(common::png_2x2());
    while !d.len().is_multiple_of(4) {
        d.push(0);
    }
    d
}

/// The quad with what the plain one leaves out: a masked material with a base colour texture
/// in a buffer view (moved by `KHR_texture_transform`, with a sampler) and an emissive one in a
/// data URI, a perspective camera and a spot light (`KHR_lights_punctual`). `uri` names the
/// buffer's file (`None` for GLB, whose buffer is its BIN chunk).
fn textured_gltf(uri: Option<&str>) -> String {
    let bin = textured_bin();
    let png = common::png_2x2();
    let mut buffer = serde_json::json!({"byteLength": bin.len()});
    if let Some(u) = uri {
        buffer["uri"] = u.into();
    }
    let data_uri = format!(
        "data:image/png;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(&png)
    );
    let doc = serde_json::json!({
        "asset": {"version": "2.0"},
        "extensionsUsed": ["KHR_lights_punctual", "KHR_texture_transform"],
        "extensions": {"KHR_lights_punctual": {"lights": [
            {"type": "spot", "color": [1.0, 0.9, 0.8], "intensity": 20.0,
             "spot": {"innerConeAngle": 0.3, "outerConeAngle": 0.6}}
        ]}},
        "scene": 0,
        "scenes": [{"nodes": [0, 2, 3]}],
        "nodes": [
            {"children": [1], "translation": [1, 0, 0]},
            {"mesh": 0, "rotation": [0, 0, 0.3826834, 0.9238795]},
            {"camera": 0, "translation": [0.5, 0.5, 3.0]},
            {"translation": [0.5, 0.5, 2.0],
             "extensions": {"KHR_lights_punctual": {"light": 0}}}
        ],
        "cameras": [{"type": "perspective",
                     "perspective": {"yfov": 0.8, "aspectRatio": 1.5, "znear": 0.01}}],
        "meshes": [{"primitives": [{
            "attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2},
            "indices": 3, "material": 0
        }]}],
        "materials": [{
            "pbrMetallicRoughness": {
                "baseColorTexture": {"index": 0, "extensions": {"KHR_texture_transform":
                    {"offset": [0.25, 0.0], "rotation": 0.5, "scale": [2.0, 2.0]}}},
                "baseColorFactor": [1.0, 0.8, 0.6, 1.0],
                "metallicFactor": 0.8,
                "roughnessFactor": 0.6,
                "metallicRoughnessTexture": {"index": 1, "extensions": {"KHR_texture_transform":
                    {"offset": [0.0, 0.5], "rotation": -0.3}}}
            },
            "emissiveTexture": {"index": 1},
            "emissiveFactor": [0.5, 0.5, 0.5],
            "normalTexture": {"index": 1, "scale": 0.7, "extensions": {"KHR_texture_transform":
                {"offset": [0.5, 0.0], "scale": [3.0, 1.0]}}},
            "alphaMode": "MASK",
            "alphaCutoff": 0.4
        }],
        "textures": [{"source": 0, "sampler": 0}, {"source": 1}],
        "samplers": [{"magFilter": 9729, "wrapS": 33071, "wrapT": 33648}],
        "images": [{"bufferView": 4, "mimeType": "image/png"}, {"uri": data_uri}],
        "buffers": [buffer],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 48},
            {"buffer": 0, "byteOffset": 48, "byteLength": 48, "byteStride": 12},
            {"buffer": 0, "byteOffset": 96, "byteLength": 32},
            {"buffer": 0, "byteOffset": 128, "byteLength": 12},
            {"buffer": 0, "byteOffset": gltf_bin().len(), "byteLength": png.len()}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3"},
            {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC3"},
            {"bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC2"},
            {"bufferView": 3, "componentType": 5123, "count": 6, "type": "SCALAR"}
        ]
    });
    serde_json::to_string_pretty(&doc).expect("JSON")
}

/// [`textured_gltf`] as one GLB.
fn textured_glb() -> Vec<u8> {
    glb_of(textured_gltf(None).into_bytes(), textured_bin())
}

/// Tokens that parsers trip over.
const TOKENS: &[&str] = &[
    "nan",
    "inf",
    "-inf",
    "1e40",
    "-1e-45",
    "-",
    "0",
    "-1",
    "4294967295",
    "99999999999999999999",
    "\n",
    " ",
    "\t",
    "/",
    "//",
    "f ",
    "v ",
    "vn ",
    "vt ",
    "#",
    "\"",
    "[",
    "]",
    "=",
    ",",
    ".",
    "\0",
    "\u{feff}",
    "é",
    "\r\n",
    "usemtl ",
    "mtllib ",
    "element face 4000000000\n",
    "property list uchar int vertex_indices\n",
    "end_header\n",
    "format binary_big_endian 1.0\n",
    "[[meshes]]\n",
    "[[lights]]\n",
    "kind = \"cube_map\"\n",
    "path = \"\"\n",
    "path = \"/\"\n",
    "shape = \"sphere\"\nsubdivisions = 40\n",
    "samples = 100000000\n",
    "= [1.0, 2.0]",
    "{",
    "}",
    ":",
    "\"mode\":6,",
    "\"children\":[0],",
    "\"byteStride\":4,",
    "\"sparse\":{\"count\":1},",
];

#[derive(Clone, Debug)]
enum Edit {
    /// Flip one byte at a fraction of the length.
    Flip(f64, u8),
    /// Remove up to `n` bytes there.
    Drop(f64, usize),
    /// Insert a token there.
    Splice(f64, usize),
    /// Repeat the line there.
    Repeat(f64),
    /// Cut the file short there.
    Cut(f64),
}

fn edit() -> impl Strategy<Value = Edit> {
    let at = 0.0..1.0f64;
    prop_oneof![
        (at.clone(), any::<u8>()).prop_map(|(a, b)| Edit::Flip(a, b)),
        (at.clone(), 1..24usize).prop_map(|(a, n)| Edit::Drop(a, n)),
        (at.clone(), 0..TOKENS.len()).prop_map(|(a, t)| Edit::Splice(a, t)),
        at.clone().prop_map(Edit::Repeat),
        at.prop_map(Edit::Cut),
    ]
}

fn apply(mut data: Vec<u8>, edits: &[Edit]) -> Vec<u8> {
    for e in edits {
        let pos = |f: f64, len: usize| ((f * len as f64) as usize).min(len);
        match *e {
            Edit::Flip(f, b) => {
                if !data.is_empty() {
                    let i = pos(f, data.len() - 1);
                    data[i] ^= b.max(1);
                }
            }
            Edit::Drop(f, n) => {
                let i = pos(f, data.len());
                let end = (i + n).min(data.len());
                data.drain(i..end);
            }
            Edit::Splice(f, t) => {
                let i = pos(f, data.len());
                data.splice(i..i, TOKENS[t].bytes());
            }
            Edit::Repeat(f) => {
                let i = pos(f, data.len());
                let start = data[..i]
                    .iter()
                    .rposition(|&c| c == b'\n')
                    .map_or(0, |p| p + 1);
                let end = data[i..]
                    .iter()
                    .position(|&c| c == b'\n')
                    .map_or(data.len(), |p| i + p + 1);
                let line = data[start..end].to_vec();
                data.splice(end..end, line);
            }
            Edit::Cut(f) => {
                let i = pos(f, data.len());
                data.truncate(i);
            }
        }
    }
    data
}

/// Loads `path` on a worker thread: the scene, or the error text; a hang fails the test.
fn load_bounded(path: PathBuf) -> Result<Scene, String> {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let r = std::panic::catch_unwind(|| Scene::load(&path).map_err(|e| format!("{e:#}")));
        let _ = tx.send(r);
    });
    match rx.recv_timeout(Duration::from_secs(20)) {
        Ok(Ok(r)) => r,
        Ok(Err(panic)) => {
            let msg = panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_default();
            panic!("the loader panicked: {msg}")
        }
        Err(_) => panic!("the loader took more than 20 s"),
    }
}

/// The property: a scene, usable, or an error that names one of `names`.
fn check(path: &Path, names: &[&str]) -> Result<(), TestCaseError> {
    checked(path, names).map(|_| ())
}

/// [`check`], handing back the scene that loaded and its trees.
fn checked(path: &Path, names: &[&str]) -> Result<Option<(Scene, Accel)>, TestCaseError> {
    match load_bounded(path.to_path_buf()) {
        Ok(scene) => {
            // The trees the command line builds: two levels when a mesh is placed more
            // than once (a mutation can make two nodes share one mesh).
            let Ok(accel) = Accel::for_scene(&scene, &BuildOptions::sah()) else {
                return Err(TestCaseError::fail(
                    "a loaded scene's placements are refused",
                ));
            };
            let tree = accel.tree();
            let b = tree.bounds();
            prop_assert!(
                tree.is_empty() || (b.min.is_finite() && b.max.is_finite()),
                "root bounds not finite"
            );
            for d in [
                glam::Vec3::X,
                glam::Vec3::NEG_Y,
                glam::Vec3::new(0.3, -0.2, -1.0),
            ] {
                let hit = tree.intersect(&Ray::new(glam::Vec3::splat(0.1), d), f32::INFINITY);
                prop_assert!(hit.is_none_or(|h| h.t.is_finite() && h.t > 0.0));
            }
            Ok(Some((scene, accel)))
        }
        Err(e) => {
            prop_assert!(
                names.iter().any(|n| e.contains(n)),
                "the error does not name the file: {e}"
            );
            Ok(None)
        }
    }
}

/// [`check`], and a scene that loads renders a small picture (its textures looked up through
/// their transforms and samplers, its camera and lights used) without a panic, every pixel
/// finite.
fn check_rendered(path: &Path, names: &[&str]) -> Result<(), TestCaseError> {
    if let Some((scene, bvh)) = checked(path, names)? {
        let settings = RenderSettings {
            width: 12,
            height: 8,
            spp: 1,
            ..RenderSettings::default()
        };
        let film = render(&scene, &bvh, &settings, &|_| {})
            .map_err(|e| TestCaseError::fail(format!("render failed: {e:#}")))?
            .film;
        prop_assert!(
            film.mean().iter().all(|p| p.is_finite()),
            "a pixel is not finite"
        );
    }
    Ok(())
}

fn config() -> ProptestConfig {
    ProptestConfig {
        cases: 500,
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

proptest! {
    #![proptest_config(config())]

    #[test]
    fn mutated_obj_files_load_or_fail_naming_the_file(edits in prop::collection::vec(edit(), 1..8)) {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("cube.mtl"), MTL).unwrap();
        let p = dir.path().join("mutant.obj");
        std::fs::write(&p, apply(OBJ.as_bytes().to_vec(), &edits)).unwrap();
        check(&p, &["mutant.obj", "cube.mtl"])?;
    }

    #[test]
    fn mutated_mtl_files_load_or_fail_naming_the_file(edits in prop::collection::vec(edit(), 1..8)) {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("cube.mtl"), apply(MTL.as_bytes().to_vec(), &edits)).unwrap();
        let p = dir.path().join("cube.obj");
        std::fs::write(&p, OBJ).unwrap();
        check(&p, &["cube.obj", "cube.mtl"])?;
    }

    #[test]
    fn mutated_ascii_ply_files_load_or_fail_naming_the_file(edits in prop::collection::vec(edit(), 1..8)) {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("mutant.ply");
        std::fs::write(&p, apply(PLY_ASCII.as_bytes().to_vec(), &edits)).unwrap();
        check(&p, &["mutant.ply"])?;
    }

    #[test]
    fn mutated_binary_ply_files_load_or_fail_naming_the_file(edits in prop::collection::vec(edit(), 1..8)) {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("mutant.ply");
        std::fs::write(&p, apply(ply_binary(), &edits)).unwrap();
        check(&p, &["mutant.ply"])?;
    }

    #[test]
    fn mutated_gltf_files_load_or_fail_naming_the_file(edits in prop::collection::vec(edit(), 1..8)) {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("quad.bin"), gltf_bin()).unwrap();
        let p = dir.path().join("mutant.gltf");
        std::fs::write(&p, apply(GLTF.as_bytes().to_vec(), &edits)).unwrap();
        check(&p, &["mutant.gltf", "quad.bin"])?;
    }

    #[test]
    fn mutated_gltf_buffers_load_or_fail_naming_the_file(edits in prop::collection::vec(edit(), 1..8)) {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("quad.bin"), apply(gltf_bin(), &edits)).unwrap();
        let p = dir.path().join("quad.gltf");
        std::fs::write(&p, GLTF).unwrap();
        check(&p, &["quad.gltf", "quad.bin"])?;
    }

    #[test]
    fn mutated_glb_files_load_or_fail_naming_the_file(edits in prop::collection::vec(edit(), 1..8)) {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("mutant.glb");
        std::fs::write(&p, apply(glb(), &edits)).unwrap();
        check(&p, &["mutant.glb"])?;
    }

    #[test]
    fn mutated_textured_gltf_files_load_or_fail_naming_the_file(edits in prop::collection::vec(edit(), 1..8)) {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("tex.bin"), textured_bin()).unwrap();
        let p = dir.path().join("mutant.gltf");
        std::fs::write(&p, apply(textured_gltf(Some("tex.bin")).into_bytes(), &edits)).unwrap();
        check_rendered(&p, &["mutant.gltf", "tex.bin"])?;
    }

    #[test]
    fn mutated_textured_glb_files_load_or_fail_naming_the_file(edits in prop::collection::vec(edit(), 1..8)) {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("mutant.glb");
        std::fs::write(&p, apply(textured_glb(), &edits)).unwrap();
        check_rendered(&p, &["mutant.glb"])?;
    }

    #[test]
    fn mutated_skinned_gltf_files_load_or_fail_naming_the_file(edits in prop::collection::vec(edit(), 1..8)) {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("skin.bin"), skinned_bin()).unwrap();
        let p = dir.path().join("mutant.gltf");
        std::fs::write(&p, apply(SKINNED.as_bytes().to_vec(), &edits)).unwrap();
        check_rendered(&p, &["mutant.gltf", "skin.bin"])?;
    }

    #[test]
    fn mutated_skinned_gltf_buffers_load_or_fail_naming_the_file(edits in prop::collection::vec(edit(), 1..8)) {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("skin.bin"), apply(skinned_bin(), &edits)).unwrap();
        let p = dir.path().join("skin.gltf");
        std::fs::write(&p, SKINNED).unwrap();
        check_rendered(&p, &["skin.gltf", "skin.bin"])?;
    }

    #[test]
    fn mutated_scene_files_load_or_fail_naming_the_file(edits in prop::collection::vec(edit(), 1..8)) {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("square.ply"), PLY_ASCII).unwrap();
        let p = dir.path().join("mutant.toml");
        std::fs::write(&p, apply(SCENE.as_bytes().to_vec(), &edits)).unwrap();
        // A mutated path may name another file: the error then names that one.
        check(&p, &["mutant.toml", "square.ply"])?;
    }
}

#[test]
fn the_unmutated_files_load() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("cube.mtl"), MTL).unwrap();
    std::fs::write(dir.path().join("cube.obj"), OBJ).unwrap();
    std::fs::write(dir.path().join("square.ply"), PLY_ASCII).unwrap();
    std::fs::write(dir.path().join("bin.ply"), ply_binary()).unwrap();
    std::fs::write(dir.path().join("scene.toml"), SCENE).unwrap();
    std::fs::write(dir.path().join("quad.bin"), gltf_bin()).unwrap();
    std::fs::write(dir.path().join("quad.gltf"), GLTF).unwrap();
    std::fs::write(dir.path().join("quad.glb"), glb()).unwrap();
    std::fs::write(dir.path().join("tex.bin"), textured_bin()).unwrap();
    std::fs::write(dir.path().join("tex.gltf"), textured_gltf(Some("tex.bin"))).unwrap();
    std::fs::write(dir.path().join("tex.glb"), textured_glb()).unwrap();
    std::fs::write(dir.path().join("skin.bin"), skinned_bin()).unwrap();
    std::fs::write(dir.path().join("skin.gltf"), SKINNED).unwrap();
    // The skinned quad: its first vertex lifted by the target (0.5 x 2) and by joint 0 (z 1),
    // its third turned a quarter about z by joint 1 (under joint 0: z 1), the node's own
    // translation ignored.
    let s = Scene::load(&dir.path().join("skin.gltf")).unwrap();
    assert!(s.warnings.is_empty(), "skin.gltf: {:?}", s.warnings);
    let v = |t: usize, k: usize| (s.mesh.origin + s.mesh.triangles[t][k].as_dvec3()).as_vec3();
    assert!(
        (v(0, 0) - glam::Vec3::new(0.0, 0.0, 2.0)).length() < 1e-5,
        "{}",
        v(0, 0)
    );
    assert!(
        (v(0, 2) - glam::Vec3::new(-1.0, 1.0, 1.0)).length() < 1e-5,
        "{}",
        v(0, 2)
    );
    for f in ["tex.gltf", "tex.glb"] {
        let s = Scene::load(&dir.path().join(f)).unwrap();
        assert!(s.warnings.is_empty(), "{f}: {:?}", s.warnings);
        assert_eq!(s.triangle_count(), 2, "{f}");
        let m = &s.materials[0];
        assert!(
            m.diffuse_map.is_some() && m.emission_map.is_some() && m.normal_map.is_some(),
            "{f}: the base colour, emissive and normal textures"
        );
        let mr = m.pbr.as_ref().and_then(|p| p.map.as_ref());
        assert!(
            mr.is_some_and(|t| t.transform.is_some()),
            "{f}: the metallic-roughness texture and its transform"
        );
        assert_eq!(m.normal_scale, 0.7, "{f}");
        assert!(
            m.normal_map.as_ref().unwrap().transform.is_some(),
            "{f}: the normal map's texture transform"
        );
        assert_eq!(s.mesh.tangents.len(), 2, "{f}: MikkTSpace's tangents");
        assert_eq!(s.lights.len(), 1, "{f}: the spot light");
        let eye = s.camera.position + s.mesh.origin.as_vec3();
        assert!(
            (eye - glam::Vec3::new(0.5, 0.5, 3.0)).abs().max_element() < 1e-5,
            "{f}: the file's camera, not one framing the quad: {eye}"
        );
    }
    let count = |f: &str| Scene::load(&dir.path().join(f)).unwrap().triangle_count();
    assert_eq!(count("quad.gltf"), 2);
    assert_eq!(count("quad.glb"), 2);
    assert_eq!(count("cube.obj"), 12);
    assert_eq!(count("square.ply"), 2);
    assert_eq!(count("bin.ply"), 2);
    assert_eq!(count("scene.toml"), 2 + 80);
    // A colour with two values made tobj's MTL parser panic: now a warning naming the line.
    std::fs::write(
        dir.path().join("cube.mtl"),
        MTL.replace("Kd 0.8 0.1 0.1", "Kd 0.8 0.1"),
    )
    .unwrap();
    let s = Scene::load(&dir.path().join("cube.obj")).unwrap();
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("cube.mtl:2: Kd needs three numbers")),
        "{:?}",
        s.warnings
    );
}

/// A token spliced into the textured glTF's node list that makes a second node place the
/// mesh, so the scene places a mesh twice: it renders through the two levels the command
/// line builds. (Through one tree over the scene's own
/// triangles, `render` says why it cannot, rather than panicking.)
#[test]
fn a_mutation_that_places_a_mesh_twice_renders() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("tex.bin"), textured_bin()).unwrap();
    let p = dir.path().join("mutant.gltf");
    let edits = [Edit::Splice(0.8877320547527232, 48)];
    std::fs::write(
        &p,
        apply(textured_gltf(Some("tex.bin")).into_bytes(), &edits),
    )
    .unwrap();
    let scene = Scene::load(&p).unwrap();
    assert!(
        !scene.instances.is_empty(),
        "the mutant places a mesh twice"
    );
    check_rendered(&p, &["mutant.gltf", "tex.bin"]).unwrap();
    let own = tracery::bvh::Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
    let settings = RenderSettings {
        width: 4,
        height: 4,
        spp: 1,
        ..RenderSettings::default()
    };
    let err = render(&scene, &own, &settings, &|_| {}).err().unwrap();
    assert!(format!("{err}").contains("Accel::for_scene"), "{err}");
}
