//! glTF 2.0 scenes and textures: files written here, whose answer is known (node
//! transforms, instancing, mirrored nodes, materials, camera and lights, embedded textures,
//! and every kind of bad input with the message it must give), and every glTF of assimp's test
//! models (fetched by `scripts/fetch-assets gltf`) against an independent loader's triangle
//! counts (`tests/gltf/trimesh_counts.csv`, written by `scripts/gltf-counts`).

mod common;

use common::{data_uri, f32_bytes};

use std::path::{Path, PathBuf};

use base64::Engine as _;
use glam::{Vec2, Vec3, Vec4};
use serde_json::{Value, json};
use tracery::bvh::{BuildOptions, Bvh};
use tracery::render::{RenderSettings, render};
use tracery::scene::{Light, Scene, Texture, Wrap, face_normal};

// ---------------------------------------------------------------------------------------
// Writing small glTF files
// ---------------------------------------------------------------------------------------

/// One triangle (0,0,0), (1,0,0), (0,1,0) with +z normals, texture coordinates and u16
/// indices: the buffer and the accessors 0 (POSITION), 1 (NORMAL), 2 (TEXCOORD_0), 3 (indices).
fn triangle_buffer() -> (Vec<u8>, Value, Value) {
    let mut bin = f32_bytes(&[0., 0., 0., 1., 0., 0., 0., 1., 0.]);
    bin.extend(f32_bytes(&[0., 0., 1., 0., 0., 1., 0., 0., 1.]));
    bin.extend(f32_bytes(&[0., 0., 1., 0., 0., 1.]));
    bin.extend([0u16, 1, 2].iter().flat_map(|i| i.to_le_bytes()));
    bin.extend([0, 0]); // pad to 4
    let views = json!([
        {"buffer": 0, "byteOffset": 0, "byteLength": 36},
        {"buffer": 0, "byteOffset": 36, "byteLength": 36},
        {"buffer": 0, "byteOffset": 72, "byteLength": 24},
        {"buffer": 0, "byteOffset": 96, "byteLength": 6}
    ]);
    let accessors = json!([
        {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"},
        {"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC3"},
        {"bufferView": 2, "componentType": 5126, "count": 3, "type": "VEC2"},
        {"bufferView": 3, "componentType": 5123, "count": 3, "type": "SCALAR"}
    ]);
    (bin, views, accessors)
}

/// A glTF document of the triangle mesh with the given nodes and extra top-level fields.
fn doc(nodes: Value, extra: Value) -> Value {
    let (bin, views, accessors) = triangle_buffer();
    let mut d = json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": (0..nodes.as_array().unwrap().len())
            .filter(|i| !is_child(&nodes, *i)).collect::<Vec<_>>()}],
        "nodes": nodes,
        "meshes": [{"primitives": [{
            "attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2},
            "indices": 3
        }]}],
        "buffers": [{"byteLength": bin.len(), "uri": data_uri(&bin)}],
        "bufferViews": views,
        "accessors": accessors
    });
    merge(&mut d, extra);
    d
}

fn is_child(nodes: &Value, i: usize) -> bool {
    nodes.as_array().unwrap().iter().any(|n| {
        n.get("children")
            .and_then(Value::as_array)
            .is_some_and(|c| c.iter().any(|x| x.as_u64() == Some(i as u64)))
    })
}

/// Overwrites (recursively for objects) the fields of `d` with those of `extra`.
fn merge(d: &mut Value, extra: Value) {
    match (d, extra) {
        (Value::Object(a), Value::Object(b)) => {
            for (k, v) in b {
                match a.get_mut(&k) {
                    Some(slot) if slot.is_object() && v.is_object() => merge(slot, v),
                    _ => {
                        a.insert(k, v);
                    }
                }
            }
        }
        (slot, v) => *slot = v,
    }
}

/// Writes `json` as `name` in `dir`.
fn write(dir: &Path, name: &str, json: &Value) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, serde_json::to_vec_pretty(json).unwrap()).unwrap();
    p
}

/// The message of a load that must fail, checked to name the file and to be one line.
fn error_of(path: &Path) -> String {
    let e = format!("{:#}", Scene::load(path).expect_err("the load must fail"));
    let name = path.file_name().unwrap().to_string_lossy();
    assert_eq!(e.matches(&*name).count(), 1, "names the file, once: {e}");
    assert!(!e.contains('\n'), "one line: {e}");
    e
}

/// World positions of triangle `i`.
fn world(scene: &Scene, i: usize) -> [Vec3; 3] {
    scene
        .triangle(i as u32)
        .map(|v| (scene.mesh.origin + v.as_dvec3()).as_vec3())
}

/// The texture coordinates of scene triangle `i`'s corners.
fn corner_uvs(scene: &Scene, i: usize) -> [Vec2; 3] {
    [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0)].map(|(u, v)| scene.uv_at(0, i as u32, u, v))
}

fn close(a: Vec3, b: Vec3) -> bool {
    (a - b).abs().max_element() < 1e-5
}

// ---------------------------------------------------------------------------------------
// Nodes, materials, camera, lights
// ---------------------------------------------------------------------------------------

/// One mesh placed by three nodes: on its own (translated), under a parent (translation and
/// scale composed), and mirrored (scale -1 in x). Every instance is there, where the composed
/// transforms put it, and the mirrored one keeps facing +z (its winding is turned back).
#[test]
fn node_transforms_compose_and_instances_and_mirrors_are_placed() {
    let dir = tempfile::tempdir().unwrap();
    let nodes = json!([
        {"mesh": 0, "translation": [10.0, 0.0, 0.0]},
        {"children": [2], "translation": [0.0, 5.0, 0.0], "scale": [2.0, 2.0, 2.0]},
        {"mesh": 0, "translation": [1.0, 0.0, 0.0]},
        {"mesh": 0, "scale": [-1.0, 1.0, 1.0]}
    ]);
    let p = write(dir.path(), "nodes.gltf", &doc(nodes, json!({})));
    let s = Scene::load(&p).unwrap();
    assert_eq!(s.triangle_count(), 3);
    // The mesh three nodes use is held once, each node a placement.
    assert_eq!(
        (s.instances.meshes.len(), s.instances.placements().len()),
        (1, 3)
    );
    let expect = [
        [
            Vec3::new(10., 0., 0.),
            Vec3::new(11., 0., 0.),
            Vec3::new(10., 1., 0.),
        ],
        [
            Vec3::new(2., 5., 0.),
            Vec3::new(4., 5., 0.),
            Vec3::new(2., 7., 0.),
        ],
        // Mirrored: corners 1 and 2 swapped back.
        [
            Vec3::new(0., 0., 0.),
            Vec3::new(0., 1., 0.),
            Vec3::new(-1., 0., 0.),
        ],
    ];
    for (i, want) in expect.iter().enumerate() {
        let got = world(&s, i);
        assert!(
            got.iter().zip(want).all(|(a, b)| close(*a, *b)),
            "triangle {i}: {got:?}, expected {want:?}"
        );
        assert!(close(face_normal(&got), Vec3::Z), "triangle {i} faces +z");
        for n in s.normals(i as u32) {
            assert!(close(n, Vec3::Z), "triangle {i}: shading normal {n}");
        }
        // Texture coordinates follow their corners.
        let uv = corner_uvs(&s, i);
        assert_eq!(uv[0], Vec2::new(0.0, 0.0));
    }
    assert_eq!(
        corner_uvs(&s, 0),
        [Vec2::ZERO, Vec2::new(1., 0.), Vec2::new(0., 1.)]
    );
    assert_eq!(
        corner_uvs(&s, 2),
        [Vec2::ZERO, Vec2::new(0., 1.), Vec2::new(1., 0.)]
    );
}

/// Each node placing a mesh no other node uses is an object of the scene's own triangles,
/// named by the node (or its mesh, or its index); a mesh several nodes use is one object per
/// node.
#[test]
fn nodes_are_the_scenes_objects() {
    use tracery::scene::Place;
    let dir = tempfile::tempdir().unwrap();
    let nodes = json!([
        {"name": "left", "mesh": 0},
        {"mesh": 1, "translation": [3.0, 0.0, 0.0]},
        {"mesh": 2, "translation": [6.0, 0.0, 0.0]},
        {"mesh": 2, "translation": [9.0, 0.0, 0.0]}
    ]);
    let d = doc(nodes, json!({}));
    let prim = d["meshes"][0].clone();
    let mut named = prim.clone();
    named["name"] = json!("middle");
    let d = {
        let mut d = d;
        d["meshes"] = json!([prim.clone(), named, prim]);
        d
    };
    let s = Scene::load(&write(dir.path(), "objects.gltf", &d)).unwrap();
    let got: Vec<(&str, Place)> = s
        .objects
        .iter()
        .map(|o| (o.name.as_str(), o.place))
        .collect();
    assert_eq!(
        got,
        [
            ("left", Place::Own { first: 0, count: 1 }),
            ("middle", Place::Own { first: 1, count: 1 }),
            ("mesh 0 #0", Place::Placed(0)),
            ("mesh 0 #1", Place::Placed(1)),
        ]
    );
    assert_eq!(s.object_of(1), Some(1));
    assert_eq!(s.object_of(3), Some(3));
}

/// Metallic-roughness materials as docs/formats.md's glTF table says.
#[test]
fn materials_map_base_colour_metal_emission_alpha_and_transmission() {
    let dir = tempfile::tempdir().unwrap();
    let materials = json!([
        {"name": "paint", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.2, 0.1, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0}},
        {"name": "chrome", "pbrMetallicRoughness": {"baseColorFactor": [0.9, 0.8, 0.7, 1.0], "metallicFactor": 1.0, "roughnessFactor": 0.1}},
        {"name": "lamp", "emissiveFactor": [1.0, 0.5, 0.0], "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 4.0}}},
        {"name": "tinted", "alphaMode": "BLEND", "pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 0.25]}},
        {"name": "cutout", "alphaMode": "MASK", "alphaCutoff": 0.5, "pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 0.3]}},
        {"name": "glass", "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1.0}, "KHR_materials_ior": {"ior": 1.33}}},
        {"name": "tinted glass", "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1.0},
            "KHR_materials_volume": {"thicknessFactor": 1.0, "attenuationColor": [0.5, 1.0, 0.25], "attenuationDistance": 2.0}}},
        {"name": "thin glass", "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1.0},
            "KHR_materials_volume": {"thicknessFactor": 0.0, "attenuationColor": [0.5, 1.0, 0.25], "attenuationDistance": 2.0}}}
    ]);
    let nodes: Vec<Value> = (0..8).map(|m| json!({"mesh": m})).collect();
    let prim = |m: usize| json!({"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1}, "indices": 3, "material": m}]});
    let meshes: Vec<Value> = (0..8).map(prim).collect();
    let d = doc(
        Value::Array(nodes),
        json!({
            "materials": materials,
            "meshes": meshes,
            "extensionsUsed": ["KHR_materials_emissive_strength", "KHR_materials_transmission", "KHR_materials_ior", "KHR_materials_volume"]
        }),
    );
    let s = Scene::load(&write(dir.path(), "materials.gltf", &d)).unwrap();
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    let m = |name: &str| {
        s.materials
            .iter()
            .find(|m| m.name == name)
            .unwrap_or_else(|| panic!("material {name}"))
    };
    let paint = m("paint");
    assert!(close(paint.diffuse, Vec3::new(0.8, 0.2, 0.1)));
    assert!(close(paint.specular, Vec3::splat(0.04)));
    assert_eq!(paint.mirror, Vec3::ZERO);
    let chrome = m("chrome");
    assert_eq!(chrome.diffuse, Vec3::ZERO, "a metal has no diffuse part");
    assert!(close(chrome.mirror, Vec3::new(0.9, 0.8, 0.7)));
    assert!(close(m("lamp").emission, Vec3::new(4.0, 2.0, 0.0)));
    assert_eq!(m("tinted").opacity, 0.25);
    assert_eq!(
        m("cutout").opacity_at(1.0),
        0.0,
        "alpha 0.3 under the cutoff 0.5"
    );
    assert_eq!(
        m("tinted").opacity_at(0.5),
        0.125,
        "BLEND: times the texture's alpha"
    );
    let glass = m("glass");
    assert_eq!((glass.opacity, glass.ior), (0.0, 1.33));
    assert_eq!(glass.absorption, Vec3::ZERO, "no volume: nothing absorbed");
    // KHR_materials_volume: white light turns the attenuation colour after the distance.
    let tinted = m("tinted glass");
    let want = Vec3::new(2f32.ln(), 0.0, 4f32.ln()) / 2.0;
    assert!(close(tinted.absorption, want), "{}", tinted.absorption);
    assert!(close(
        (-2.0 * tinted.absorption).exp(),
        Vec3::new(0.5, 1.0, 0.25)
    ));
    assert_eq!(
        m("thin glass").absorption,
        Vec3::ZERO,
        "thin-walled: no volume"
    );
}

/// The file's first perspective camera frames the scene; point and directional lights light
/// it; a file without lights gets the default lighting of a bare mesh.
#[test]
fn the_first_camera_and_punctual_lights_are_used() {
    let dir = tempfile::tempdir().unwrap();
    let nodes = json!([
        {"mesh": 0},
        {"camera": 0, "translation": [0.2, 0.3, 5.0]},
        {"extensions": {"KHR_lights_punctual": {"light": 0}}, "translation": [1.0, 2.0, 3.0]},
        // Rotated -90 degrees about x: its -z points down (-y).
        {"extensions": {"KHR_lights_punctual": {"light": 1}}, "rotation": [-0.70710677, 0.0, 0.0, 0.70710677]}
    ]);
    let d = doc(
        nodes,
        json!({
            "cameras": [{"type": "perspective", "perspective": {"yfov": 0.5, "znear": 0.1}}],
            "extensionsUsed": ["KHR_lights_punctual"],
            "extensions": {"KHR_lights_punctual": {"lights": [
                {"type": "point", "color": [1.0, 0.5, 0.25], "intensity": 20.0},
                {"type": "directional", "intensity": 3.0}
            ]}}
        }),
    );
    let s = Scene::load(&write(dir.path(), "lit.gltf", &d)).unwrap();
    let o = s.mesh.origin.as_vec3();
    assert!(close(s.camera.position + o, Vec3::new(0.2, 0.3, 5.0)));
    let forward = (s.camera.look_at - s.camera.position).normalize();
    assert!(
        close(forward, -Vec3::Z),
        "looks along the node's -z: {forward}"
    );
    assert!((s.camera.vfov_deg - 0.5f32.to_degrees()).abs() < 1e-4);
    assert_eq!(s.lights.len(), 2);
    match s.lights[0] {
        Light::Point {
            position,
            color,
            intensity,
        } => {
            assert!(close(position + o, Vec3::new(1.0, 2.0, 3.0)));
            assert_eq!((color, intensity), (Vec3::new(1.0, 0.5, 0.25), 20.0));
        }
        ref l => panic!("a point light: {l:?}"),
    }
    // The directional light: a point light far above (it shines down), giving the scene
    // its illuminance of 3 (intensity / distance^2).
    match s.lights[1] {
        Light::Point {
            position,
            intensity,
            ..
        } => {
            // The bounds' centre of the triangle (0,0,0), (1,0,0), (0,1,0).
            let to = position - (Vec3::new(0.5, 0.5, 0.0) - o);
            assert!(to.normalize().dot(Vec3::Y) > 0.999, "above: {to}");
            let d2 = to.length_squared();
            assert!((intensity / d2 - 3.0).abs() < 0.01, "{}", intensity / d2);
        }
        ref l => panic!("a point light: {l:?}"),
    }

    let plain = Scene::load(&write(
        dir.path(),
        "plain.gltf",
        &doc(json!([{"mesh": 0}]), json!({})),
    ))
    .unwrap();
    assert_eq!(plain.lights.len(), 1, "the default light of a bare mesh");
}

/// A spot light keeps its cone and its node's -z as its axis (angles in radians; the
/// specification's defaults 0 and pi/4 when left out), and a cone outside
/// `0 <= inner < outer <= pi/2` is clamped into it with a warning naming the light.
#[test]
fn spot_lights_keep_their_cones() {
    let dir = tempfile::tempdir().unwrap();
    // Rotated -90 degrees about x: the node's -z points down (-y).
    let down = [-0.70710677, 0.0, 0.0, 0.70710677];
    let nodes = json!([
        {"mesh": 0},
        {"extensions": {"KHR_lights_punctual": {"light": 0}}, "rotation": down, "translation": [0.0, 2.0, 0.0]},
        {"extensions": {"KHR_lights_punctual": {"light": 1}}},
        {"extensions": {"KHR_lights_punctual": {"light": 2}}}
    ]);
    let d = doc(
        nodes,
        json!({
            "extensionsUsed": ["KHR_lights_punctual"],
            "extensions": {"KHR_lights_punctual": {"lights": [
                {"type": "spot", "intensity": 7.0, "spot": {"innerConeAngle": 0.2, "outerConeAngle": 0.5}},
                {"type": "spot", "spot": {}},
                {"type": "spot", "spot": {"innerConeAngle": 0.9, "outerConeAngle": 0.4}}
            ]}}
        }),
    );
    let s = Scene::load(&write(dir.path(), "spots.gltf", &d)).unwrap();
    let cone = |l: &Light| match *l {
        Light::Spot {
            direction,
            cos_inner,
            cos_outer,
            intensity,
            ..
        } => (direction, cos_inner.acos(), cos_outer.acos(), intensity),
        ref l => panic!("a spot light: {l:?}"),
    };
    let (axis, inner, outer, intensity) = cone(&s.lights[0]);
    assert!(close(axis, -Vec3::Y), "{axis}");
    assert!(
        (inner - 0.2).abs() < 1e-4 && (outer - 0.5).abs() < 1e-4,
        "{inner} {outer}"
    );
    assert_eq!(intensity, 7.0);
    let (axis, inner, outer, _) = cone(&s.lights[1]);
    assert!(close(axis, -Vec3::Z), "{axis}");
    assert!(inner.abs() < 1e-3 && (outer - std::f32::consts::FRAC_PI_4).abs() < 1e-4);
    let (_, inner, outer, _) = cone(&s.lights[2]);
    assert!(
        inner < outer && (outer - 0.4).abs() < 1e-4,
        "{inner} {outer}"
    );
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("lights[2]") && w.contains("spot cone")),
        "{:?}",
        s.warnings
    );
}

// ---------------------------------------------------------------------------------------
// Textures
// ---------------------------------------------------------------------------------------

#[test]
fn textures_filter_bilinearly_decode_srgb_and_wrap() {
    let texels = vec![
        [255, 0, 0, 255],
        [0, 255, 0, 255],
        [0, 0, 255, 255],
        [128, 128, 128, 255],
    ];
    let mut t = Texture::from_rgba8("t".into(), 2, 2, texels, true);
    // Texel centres read their texel; sRGB 128 is linear 0.2159.
    assert_eq!(
        t.sample(Vec2::new(0.25, 0.25)),
        Vec4::new(1.0, 0.0, 0.0, 1.0)
    );
    let grey = t.sample(Vec2::new(0.75, 0.75));
    assert!((grey.x - 0.2159).abs() < 1e-3, "{grey}");
    // Halfway between red and green: the mean of the linear values.
    let mid = t.sample(Vec2::new(0.5, 0.25));
    assert!(close(mid.truncate(), Vec3::new(0.5, 0.5, 0.0)), "{mid}");
    // Repeat: u = 1.25 is u = 0.25; clamp: u = 1.25 reads the right column.
    assert_eq!(
        t.sample(Vec2::new(1.25, 0.25)),
        t.sample(Vec2::new(0.25, 0.25))
    );
    t.wrap_u = Wrap::ClampToEdge;
    assert_eq!(
        t.sample(Vec2::new(1.25, 0.25)),
        t.sample(Vec2::new(0.75, 0.25))
    );
    // Mirrored repeat: u = 1.25 mirrors to 0.75.
    t.wrap_u = Wrap::MirroredRepeat;
    assert_eq!(
        t.sample(Vec2::new(1.25, 0.25)),
        t.sample(Vec2::new(0.75, 0.25))
    );
    // Clamp between the edge texel centres and the edge gives the edge texel.
    t.wrap_u = Wrap::ClampToEdge;
    assert_eq!(
        t.sample(Vec2::new(0.0, 0.25)),
        t.sample(Vec2::new(0.25, 0.25))
    );
    // Non-finite coordinates read a texel, not NaN.
    assert!(t.sample(Vec2::new(f32::NAN, 1e30)).is_finite());
    // A linear (non-colour) texture keeps its bytes' values.
    let lin = Texture::from_rgba8("l".into(), 1, 1, vec![[128, 0, 0, 255]], false);
    assert!((lin.sample(Vec2::ZERO).x - 128.0 / 255.0).abs() < 1e-6);
}

/// A base colour texture embedded in the glTF (a buffer view and a data URI both), with its
/// sampler's wrap modes, on the material's diffuse colour.
#[test]
fn gltf_base_colour_and_emissive_textures_are_read_with_their_samplers() {
    let dir = tempfile::tempdir().unwrap();
    let png = common::png_2x2();
    let d = doc(
        json!([{"mesh": 0}]),
        json!({
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 2}, "indices": 3, "material": 0}]}],
            "materials": [{
                "name": "tex",
                "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "baseColorFactor": [0.5, 1.0, 1.0, 1.0], "metallicFactor": 0.0},
                "emissiveTexture": {"index": 1},
                "emissiveFactor": [1.0, 1.0, 1.0]
            }],
            "textures": [{"source": 0, "sampler": 0}, {"source": 1}],
            "samplers": [{"wrapS": 33071, "wrapT": 33648}],
            "images": [{"uri": format!("data:image/png;base64,{}", base64::engine::general_purpose::STANDARD.encode(&png))},
                       {"uri": "emit%20map.png"}]
        }),
    );
    std::fs::write(dir.path().join("emit map.png"), &png).unwrap();
    let s = Scene::load(&write(dir.path(), "textured.gltf", &d)).unwrap();
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    let m = &s.materials[0];
    let t = m.diffuse_map.as_ref().expect("base colour texture");
    assert_eq!(
        (t.wrap_u, t.wrap_v),
        (Wrap::ClampToEdge, Wrap::MirroredRepeat)
    );
    assert_eq!(
        t.sample(Vec2::new(0.75, 0.25)),
        Vec4::new(0.0, 1.0, 0.0, 1.0)
    );
    assert_eq!(
        m.diffuse,
        Vec3::new(0.5, 1.0, 1.0),
        "the factor multiplies the texture"
    );
    let e = m
        .emission_map
        .as_ref()
        .expect("emissive texture (a file with a space)");
    assert_eq!(
        e.sample(Vec2::new(0.25, 0.75)),
        Vec4::new(0.0, 0.0, 1.0, 1.0)
    );
    assert_eq!(e.size(), (2, 2));
    // An image that cannot be read is a warning; the material keeps its factor.
    std::fs::remove_file(dir.path().join("emit map.png")).unwrap();
    let s = Scene::load(&dir.path().join("textured.gltf")).unwrap();
    assert!(s.materials[0].emission_map.is_none());
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("emissiveTexture") && w.contains("emit map.png")),
        "{:?}",
        s.warnings
    );
}

/// Mean linear colour of the pixels of `film` in the box `[x0, x1) x [y0, y1)`.
fn mean_of(film: &tracery::film::Film, x0: u32, x1: u32, y0: u32, y1: u32) -> Vec3 {
    let px = film.mean();
    let mut sum = Vec3::ZERO;
    for y in y0..y1 {
        for x in x0..x1 {
            sum += px[(y * film.width + x) as usize];
        }
    }
    sum / ((x1 - x0) * (y1 - y0)) as f32
}

/// An OBJ quad with `map_Kd` of the 2x2 image (the file's `v` counts from the bottom): the
/// render shows red top left, green top right, blue bottom left, white bottom right. Without
/// the texture the quad is one colour.
#[test]
fn a_textured_obj_shows_its_texture() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("checker.png"), common::png_2x2()).unwrap();
    std::fs::write(
        dir.path().join("quad.mtl"),
        "newmtl tex\nKd 1 1 1\nmap_Kd checker.png\n",
    )
    .unwrap();
    let obj = "mtllib quad.mtl\nv -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\n\
               vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\nusemtl tex\n\
               f 1/1/1 2/2/1 3/3/1\nf 1/1/1 3/3/1 4/4/1\n";
    std::fs::write(dir.path().join("quad.obj"), obj).unwrap();
    let mut scene = Scene::load(&dir.path().join("quad.obj")).unwrap();
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    assert!(scene.materials[0].diffuse_map.is_some());
    scene.camera.position = Vec3::new(0.0, 0.0, 3.0);
    scene.camera.look_at = Vec3::ZERO;
    scene.camera.vfov_deg = 30.0;
    scene.lights = vec![Light::Point {
        position: Vec3::new(0.0, 0.0, 3.0),
        color: Vec3::ONE,
        intensity: 9.0,
    }];
    let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
    let settings = RenderSettings {
        width: 40,
        height: 40,
        spp: 4,
        ..RenderSettings::default()
    };
    let film = render(&scene, &bvh, &settings, &|_| {}).unwrap().film;
    // The quad fills the frame (x and y in +-0.8 seen); the texel centres, at +-0.5, are
    // near pixels 7.5 and 32.5.
    let (tl, tr) = (mean_of(&film, 6, 10, 6, 10), mean_of(&film, 30, 34, 6, 10));
    let (bl, br) = (
        mean_of(&film, 6, 10, 30, 34),
        mean_of(&film, 30, 34, 30, 34),
    );
    let dominant = |c: Vec3, k: usize| (0..3).all(|j| j == k || c[k] > 4.0 * c[j]);
    assert!(dominant(tl, 0), "top left red: {tl}");
    assert!(dominant(tr, 1), "top right green: {tr}");
    assert!(dominant(bl, 2), "bottom left blue: {bl}");
    assert!(
        br.min_element() > 0.5 * br.max_element(),
        "bottom right white: {br}"
    );
}

// ---------------------------------------------------------------------------------------
// Bad input
// ---------------------------------------------------------------------------------------

#[test]
fn an_index_out_of_range_names_the_primitive_and_the_vertex_count() {
    let dir = tempfile::tempdir().unwrap();
    let (mut bin, views, accessors) = triangle_buffer();
    bin[96..98].copy_from_slice(&7u16.to_le_bytes());
    let d = doc(
        json!([{"mesh": 0}]),
        json!({"buffers": [{"byteLength": bin.len(), "uri": data_uri(&bin)}], "bufferViews": views, "accessors": accessors}),
    );
    let e = error_of(&write(dir.path(), "index.gltf", &d));
    assert!(
        e.contains("meshes[0].primitives[0]: index 7 out of range (3 vertices)"),
        "{e}"
    );
}

#[test]
fn missing_short_and_overrun_buffers_are_errors_that_say_which() {
    let dir = tempfile::tempdir().unwrap();
    let (bin, _, _) = triangle_buffer();
    // A .bin file that is not there.
    let d = doc(
        json!([{"mesh": 0}]),
        json!({"buffers": [{"byteLength": bin.len(), "uri": "gone.bin"}]}),
    );
    let e = error_of(&write(dir.path(), "missing.gltf", &d));
    assert!(e.contains("buffers[0]") && e.contains("gone.bin"), "{e}");
    // A buffer shorter than its byteLength.
    let d = doc(
        json!([{"mesh": 0}]),
        json!({"buffers": [{"byteLength": 400, "uri": data_uri(&bin)}]}),
    );
    let e = error_of(&write(dir.path(), "short.gltf", &d));
    assert!(
        e.contains("buffers[0]: holds 104 bytes, its byteLength says 400"),
        "{e}"
    );
    // An accessor running past its view.
    let d = doc(
        json!([{"mesh": 0}]),
        json!({"accessors": [{"bufferView": 0, "componentType": 5126, "count": 30, "type": "VEC3"},
            {"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC3"},
            {"bufferView": 2, "componentType": 5126, "count": 3, "type": "VEC2"},
            {"bufferView": 3, "componentType": 5123, "count": 3, "type": "SCALAR"}]}),
    );
    let e = error_of(&write(dir.path(), "overrun.gltf", &d));
    assert!(
        e.contains("POSITION (accessors[0])") && e.contains("run past bufferViews[0]"),
        "{e}"
    );
    // A view running past its buffer.
    let d = doc(
        json!([{"mesh": 0}]),
        json!({"bufferViews": [{"buffer": 0, "byteOffset": 90, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": 36},
            {"buffer": 0, "byteOffset": 72, "byteLength": 24},
            {"buffer": 0, "byteOffset": 96, "byteLength": 6}]}),
    );
    let e = error_of(&write(dir.path(), "view.gltf", &d));
    assert!(
        e.contains("bufferViews[0]") && e.contains("runs past buffers[0]"),
        "{e}"
    );
}

#[test]
fn wrong_types_cycles_and_depth_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    // Wrong JSON type: file, line and column.
    let mut d = doc(json!([{"mesh": 0}]), json!({}));
    d["nodes"][0]["mesh"] = json!("zero");
    let e = error_of(&write(dir.path(), "type.gltf", &d));
    assert!(
        e.contains("type.gltf:") && e.contains("invalid type"),
        "{e}"
    );
    // A node that is its own grandchild.
    let d = doc(
        json!([{"mesh": 0, "children": [1]}, {"children": [0]}]),
        json!({"scenes": [{"nodes": [0]}]}),
    );
    let e = error_of(&write(dir.path(), "cycle.gltf", &d));
    assert!(e.contains("cycle"), "{e}");
    // A chain of 5000 nodes: refused, not followed into a stack overflow.
    let chain: Vec<Value> = (0..5000)
        .map(|i| {
            if i < 4999 {
                json!({"children": [i + 1]})
            } else {
                json!({"mesh": 0})
            }
        })
        .collect();
    let d = doc(Value::Array(chain), json!({"scenes": [{"nodes": [0]}]}));
    let e = error_of(&write(dir.path(), "deep.gltf", &d));
    assert!(e.contains("deeper than"), "{e}");
    // Positions as 32-bit integers: not what POSITION may be, even quantised.
    let mut d = doc(json!([{"mesh": 0}]), json!({}));
    d["accessors"][0]["componentType"] = json!(5125);
    let e = error_of(&write(dir.path(), "u32.gltf", &d));
    assert!(e.contains("POSITION (accessors[0])"), "{e}");
    // A required extension the loader does not read.
    let d = doc(
        json!([{"mesh": 0}]),
        json!({"extensionsUsed": ["KHR_draco_mesh_compression"], "extensionsRequired": ["KHR_draco_mesh_compression"]}),
    );
    let e = error_of(&write(dir.path(), "draco.gltf", &d));
    assert!(e.contains("KHR_draco_mesh_compression"), "{e}");
    // Not glTF at all.
    std::fs::write(dir.path().join("text.glb"), b"glTF\x02\0\0\0\x10\0\0\0").unwrap();
    let e = error_of(&dir.path().join("text.glb"));
    assert!(e.contains("GLB"), "{e}");
}

/// A 3 KB file whose nodes place a 200-triangle morphed mesh 262,144 times (each node lists
/// the next twice: 52 million triangles) is refused before anything is placed: in a child process
/// (this test run again), the load's peak memory grows by no more than a few MB.
#[test]
fn a_small_file_that_places_too_many_triangles_is_refused_before_taking_the_memory() {
    const CHILD: &str = "TRACERY_TEST_PLACEMENT_CHILD";
    let depth = 18;
    let mut nodes: Vec<Value> = (0..depth)
        .map(|i| json!({"children": [i + 1, i + 1]}))
        .collect();
    nodes.push(json!({"mesh": 0}));
    let mut d = doc(Value::Array(nodes), json!({"scenes": [{"nodes": [0]}]}));
    // 600 indices, all the one triangle's corners: 200 triangles from a 1.2 KB view.
    let mut bin = f32_bytes(&[0., 0., 0., 1., 0., 0., 0., 1., 0.]);
    bin.extend(
        [0u16, 1, 2]
            .repeat(200)
            .iter()
            .flat_map(|i| i.to_le_bytes()),
    );
    d["buffers"] = json!([{"byteLength": bin.len(), "uri": data_uri(&bin)}]);
    d["bufferViews"] = json!([
        {"buffer": 0, "byteOffset": 0, "byteLength": 36},
        {"buffer": 0, "byteOffset": 36, "byteLength": 1200}
    ]);
    d["accessors"] = json!([
        {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"},
        {"bufferView": 1, "componentType": 5123, "count": 600, "type": "SCALAR"}
    ]);
    // A morph target keeps the mesh from being held once (each node's copy could be
    // weighted its own way): every placement would be copied.
    d["meshes"] = json!([{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1,
        "targets": [{"POSITION": 0}]}]}]);
    if let Some(dir) = std::env::var_os(CHILD) {
        let path = write(Path::new(&dir), "many.gltf", &d);
        let before = common::peak_kb();
        let e = format!("{:#}", Scene::load(&path).expect_err("too many triangles"));
        println!(
            "peak growth {} kB",
            common::peak_kb().saturating_sub(before)
        );
        println!("error: {e}");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let text = common::run_child(
        "a_small_file_that_places_too_many_triangles_is_refused_before_taking_the_memory",
        CHILD,
        dir.path().as_os_str(),
    );
    let growth = common::figure(&text, "peak growth ");
    let size = std::fs::metadata(dir.path().join("many.gltf"))
        .unwrap()
        .len()
        / 1024;
    println!("file {size} kB, peak memory growth {growth} kB");
    assert!(
        growth < size + 4096,
        "the load took {growth} kB for a {size} kB file"
    );
    assert!(
        text.contains("many.gltf") && text.contains("more than 50000000 triangles"),
        "{text}"
    );
}

/// Sparse accessors (glTF 2.0 section 3.6.2.3) substitute some elements of their base, or of
/// zeros without one; indices that do not rise strictly, run past the accessor, or views too
/// short for the substitutions are errors that name the accessor.
#[test]
fn sparse_accessors_substitute_elements_and_malformed_ones_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let positions = |path: &Path| {
        let scene = Scene::load(path).unwrap_or_else(|e| panic!("{e:#}"));
        assert_eq!(scene.mesh.triangles.len(), 1);
        world(&scene, 0)
    };
    let (a, b, c) = (Vec3::ZERO, Vec3::X, Vec3::Y);
    // Vertex 1 replaced by the first normal, (0, 0, 1): the index is the second u16 of
    // bufferViews[3] ([0, 1, 2]), the value the start of bufferViews[1].
    let mut d = doc(json!([{"mesh": 0}]), json!({}));
    d["accessors"][0]["sparse"] = json!({"count": 1,
        "indices": {"bufferView": 3, "byteOffset": 2, "componentType": 5123},
        "values": {"bufferView": 1}});
    let t = positions(&write(dir.path(), "one.gltf", &d));
    assert!(
        close(t[0], a) && close(t[1], Vec3::Z) && close(t[2], c),
        "{t:?}"
    );
    // No base: zeros, all three replaced by the positions themselves.
    let mut d = doc(json!([{"mesh": 0}]), json!({}));
    d["accessors"][0]
        .as_object_mut()
        .unwrap()
        .remove("bufferView");
    d["accessors"][0]["sparse"] = json!({"count": 3,
        "indices": {"bufferView": 3, "componentType": 5123},
        "values": {"bufferView": 0}});
    let t = positions(&write(dir.path(), "no_base.gltf", &d));
    assert!(close(t[0], a) && close(t[1], b) && close(t[2], c), "{t:?}");
    // Two of them, the last left as zeros.
    d["accessors"][0]["sparse"]["count"] = json!(2);
    let t = positions(&write(dir.path(), "two.gltf", &d));
    assert!(
        close(t[0], a) && close(t[1], b) && close(t[2], Vec3::ZERO),
        "{t:?}"
    );
    let malformed = [
        // u8 indices over the u16 [0, 1, 2]: 0, 0.
        (
            json!({"count": 2, "indices": {"bufferView": 3, "componentType": 5121},
                   "values": {"bufferView": 0}}),
            "do not rise strictly",
        ),
        // u16 at byte 14 of the positions: the high half of 1.0f, 16256.
        (
            json!({"count": 1, "indices": {"bufferView": 0, "byteOffset": 14, "componentType": 5123},
                   "values": {"bufferView": 0}}),
            "sparse index 16256",
        ),
        // A 12-byte value from a 6-byte view.
        (
            json!({"count": 1, "indices": {"bufferView": 3, "componentType": 5123},
                   "values": {"bufferView": 3}}),
            "sparse values",
        ),
        // Indices past their view's end.
        (
            json!({"count": 3, "indices": {"bufferView": 3, "byteOffset": 2, "componentType": 5123},
                   "values": {"bufferView": 0}}),
            "sparse indices",
        ),
        (
            json!({"count": 4, "indices": {"bufferView": 3, "componentType": 5123},
                   "values": {"bufferView": 0}}),
            "sparse count 4",
        ),
    ];
    for (i, (sparse, what)) in malformed.into_iter().enumerate() {
        let mut d = doc(json!([{"mesh": 0}]), json!({}));
        d["accessors"][0]["sparse"] = sparse;
        let e = error_of(&write(dir.path(), &format!("bad{i}.gltf"), &d));
        assert!(
            e.contains("POSITION (accessors[0])") && e.contains(what),
            "{e}"
        );
    }
}

#[test]
fn nan_vertices_and_line_primitives_are_left_out_with_warnings() {
    let dir = tempfile::tempdir().unwrap();
    let (mut bin, views, accessors) = triangle_buffer();
    bin[0..4].copy_from_slice(&f32::NAN.to_le_bytes());
    let d = doc(
        json!([{"mesh": 0}, {"mesh": 1}]),
        json!({
            "buffers": [{"byteLength": bin.len(), "uri": data_uri(&bin)}],
            "bufferViews": views, "accessors": accessors,
            "meshes": [
                {"primitives": [{"attributes": {"POSITION": 0}, "indices": 3}]},
                {"primitives": [{"attributes": {"POSITION": 1}, "mode": 1}]}
            ]
        }),
    );
    let s = Scene::load(&write(dir.path(), "nan.gltf", &d)).unwrap();
    assert_eq!(s.triangle_count(), 0);
    let all = s.warnings.join("\n");
    assert!(all.contains("non-finite vertex left out"), "{all}");
    assert!(all.contains("mode Lines left out"), "{all}");
}

/// A binary glTF (GLB: header, JSON chunk, BIN chunk) of the same triangle reads the same;
/// cut short, it is an error naming the container.
#[test]
fn glb_files_read_like_gltf_and_truncated_ones_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let (bin, _, _) = triangle_buffer();
    let mut d = doc(
        json!([{"mesh": 0}, {"mesh": 0, "translation": [0, 0, 1]}]),
        json!({}),
    );
    d["buffers"] = json!([{"byteLength": bin.len()}]);
    let mut text = serde_json::to_vec(&d).unwrap();
    while !text.len().is_multiple_of(4) {
        text.push(b' ');
    }
    let mut glb = Vec::new();
    let total = 12 + 8 + text.len() + 8 + bin.len();
    glb.extend(b"glTF");
    glb.extend(2u32.to_le_bytes());
    glb.extend((total as u32).to_le_bytes());
    glb.extend((text.len() as u32).to_le_bytes());
    glb.extend(b"JSON");
    glb.extend(&text);
    glb.extend((bin.len() as u32).to_le_bytes());
    glb.extend(b"BIN\0");
    glb.extend(&bin);
    let p = dir.path().join("two.glb");
    std::fs::write(&p, &glb).unwrap();
    let s = Scene::load(&p).unwrap();
    assert_eq!(s.triangle_count(), 2);
    std::fs::write(&p, &glb[..glb.len() - 40]).unwrap();
    let e = error_of(&p);
    assert!(e.contains("GLB"), "{e}");
}

/// A scene file places a glTF like an OBJ (its transform applied, its materials kept).
#[test]
fn scene_files_reference_gltf_like_obj() {
    let dir = tempfile::tempdir().unwrap();
    write(
        dir.path(),
        "tri.gltf",
        &doc(json!([{"mesh": 0}]), json!({})),
    );
    std::fs::write(
        dir.path().join("scene.toml"),
        "[[meshes]]\npath = \"tri.gltf\"\ntranslate = [0.0, 0.0, -2.0]\n\n\
         [[lights]]\nkind = \"point\"\nposition = [0.0, 0.0, 5.0]\n",
    )
    .unwrap();
    let s = Scene::load(&dir.path().join("scene.toml")).unwrap();
    assert_eq!(s.triangle_count(), 1);
    assert!(close(world(&s, 0)[1], Vec3::new(1.0, 0.0, -2.0)));
}

// ---------------------------------------------------------------------------------------
// assimp's glTF 2.0 test models
// ---------------------------------------------------------------------------------------

/// Files where Tracery and trimesh count differently on purpose, and why.
const KNOWN_DIFFERENCES: &[(&str, &str)] = &[
    (
        "glTF-Asset-Generator/Mesh_PrimitiveMode/Mesh_PrimitiveMode_05.gltf",
        "TRIANGLE_FAN: trimesh reads no fans (0), Tracery 2",
    ),
    (
        "glTF-Asset-Generator/Mesh_PrimitiveMode/Mesh_PrimitiveMode_12.gltf",
        "indexed TRIANGLE_FAN: trimesh reads no fans (0), Tracery 2",
    ),
    (
        "BoxWithInfinites-glTF-Binary/BoxWithInfinites.glb",
        "every vertex infinite: Tracery leaves the triangles out (with a warning)",
    ),
];

fn gltf_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            gltf_files(&p, out);
        } else if p
            .extension()
            .is_some_and(|x| x.eq_ignore_ascii_case("gltf") || x.eq_ignore_ascii_case("glb"))
        {
            out.push(p);
        }
    }
}

/// Every glTF of the folder loads or fails with a one-line message naming it (no panic, no
/// hang); the ones that load have the triangle counts trimesh finds with every node placed,
/// but for the differences listed above.
#[test]
fn every_assimp_gltf_loads_or_fails_with_a_message_and_counts_match_trimesh() {
    let Some(probe) = common::external("gltf/2CylinderEngine-glTF-Binary/2CylinderEngine.glb")
    else {
        return;
    };
    let root = probe.parent().unwrap().parent().unwrap().to_path_buf();
    let mut files = Vec::new();
    gltf_files(&root, &mut files);
    files.sort();
    assert_eq!(files.len(), 46, "assimp-testmodels ships 46 glTF 2.0 files");
    let csv = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/gltf/trimesh_counts.csv"),
    )
    .unwrap();
    let trimesh: std::collections::HashMap<&str, &str> = csv
        .lines()
        .skip(1)
        .filter_map(|l| l.split_once(','))
        .collect();
    let (mut loaded, mut refused, mut compared) = (0, 0, 0);
    for f in &files {
        let rel = f
            .strip_prefix(&root)
            .unwrap()
            .to_string_lossy()
            .replace('\\', "/");
        match common::load_bounded(f) {
            Err(msg) => {
                let name = f.file_name().unwrap().to_string_lossy();
                assert!(msg.contains(&*name) && !msg.contains('\n'), "{rel}: {msg}");
                eprintln!("refused: {msg}");
                refused += 1;
            }
            Ok(count) => {
                loaded += 1;
                let theirs = trimesh
                    .get(rel.as_str())
                    .unwrap_or_else(|| panic!("{rel}: not in trimesh_counts.csv"));
                if KNOWN_DIFFERENCES.iter().any(|(k, _)| *k == rel) {
                    continue;
                }
                if let Ok(n) = theirs.parse::<usize>() {
                    assert_eq!(count, n, "{rel}: Tracery {count} triangles, trimesh {n}");
                    compared += 1;
                }
            }
        }
    }
    eprintln!("{loaded} loaded ({compared} counts equal to trimesh's), {refused} refused");
    assert!(
        compared >= 25 && refused >= 10,
        "{compared} compared, {refused} refused"
    );
    // The engine places 121,496 triangles through its node hierarchy.
    assert_eq!(Scene::load(&probe).unwrap().triangle_count(), 121_496);
}

/// A scene file's `crease_angle` smooths a glTF's primitives that have no normals (flat
/// otherwise, as the specification asks): two triangles folded by 20 degrees along their
/// shared edge share the normals of that edge's corners with the angle, not without it.
#[test]
fn crease_angle_smooths_a_gltf_without_normals() {
    let dir = tempfile::tempdir().unwrap();
    let z = (20f32).to_radians().tan();
    let mut bin = f32_bytes(&[0., 0., 0., 1., 0., 0., 1., 1., 0., 0., 1., z]);
    bin.extend([0u16, 1, 2, 0, 2, 3].iter().flat_map(|i| i.to_le_bytes()));
    let d = json!({
        "asset": {"version": "2.0"},
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "buffers": [{"byteLength": bin.len(), "uri": data_uri(&bin)}],
        "bufferViews": [{"buffer": 0, "byteLength": 48}, {"buffer": 0, "byteOffset": 48, "byteLength": 12}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3"},
                      {"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"}]
    });
    write(dir.path(), "fold.gltf", &d);
    let scene = |extra: &str| {
        let p = dir.path().join("s.toml");
        std::fs::write(&p, format!("[[meshes]]\npath = \"fold.gltf\"\n{extra}")).unwrap();
        Scene::load(&p).unwrap()
    };
    // Corner 0 of both triangles is vertex 0, on the shared edge.
    let flat = scene("");
    assert!(!close(flat.mesh.normals[0][0], flat.mesh.normals[1][0]));
    let smooth = scene("crease_angle = 60.0\n");
    assert!(close(smooth.mesh.normals[0][0], smooth.mesh.normals[1][0]));
    let sharp = scene("crease_angle = 10.0\n");
    assert!(!close(sharp.mesh.normals[0][0], sharp.mesh.normals[1][0]));
}

/// An attribute naming an accessor that does not exist is an error, not a panic (the gltf
/// crate's own POSITION check indexed the accessor list unchecked; the mutation test found it:
/// one byte dropped from the key `"accessors"`).
#[test]
fn an_attribute_past_the_accessor_list_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let mut d = doc(json!([{"mesh": 0}]), json!({}));
    d["accessors"] = json!([]);
    let e = error_of(&write(dir.path(), "noaccessors.gltf", &d));
    assert!(e.contains("meshes[0].primitives[0].attributes"), "{e}");
}

/// An image in a buffer view without its MIME type, and an image with neither a URI nor a
/// buffer view, break rules the glTF crate does not check and made its `Image::source` panic
/// (found by mutating a textured GLB): both are errors naming the image.
#[test]
fn an_image_without_mime_type_or_source_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let textured = |image: Value| {
        doc(
            json!([{"mesh": 0}]),
            json!({
                "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 2}, "indices": 3, "material": 0}]}],
                "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
                "textures": [{"source": 0}],
                "images": [image]
            }),
        )
    };
    let e = error_of(&write(
        dir.path(),
        "nomime.gltf",
        &textured(json!({"bufferView": 0})),
    ));
    assert!(e.contains("images[0].mimeType"), "{e}");
    let e = error_of(&write(
        dir.path(),
        "nosource.gltf",
        &textured(json!({"name": "lost"})),
    ));
    assert!(e.contains("images[0].uri"), "{e}");
}

/// Thirty levels of nodes, each listing the next twice, would place 2^30 copies of the mesh:
/// the loader stops with a message instead of hanging.
#[test]
fn a_node_graph_that_doubles_at_every_level_is_refused_not_followed() {
    let dir = tempfile::tempdir().unwrap();
    let nodes: Vec<Value> = (0..30)
        .map(|i| {
            if i < 29 {
                json!({"children": [i + 1, i + 1]})
            } else {
                json!({"mesh": 0})
            }
        })
        .collect();
    let d = doc(Value::Array(nodes), json!({"scenes": [{"nodes": [0]}]}));
    let p = write(dir.path(), "bomb.gltf", &d);
    let start = std::time::Instant::now();
    let e = error_of(&p);
    assert!(e.contains("more than"), "{e}");
    eprintln!("refused in {:?}", start.elapsed());
}

/// `KHR_texture_transform`: an offset of half the image reads the texel half an image along;
/// a quarter turn takes `u` to `-v` (the direction that points the extension sample's arrows
/// at their green markers: the picture in docs/formats.md); scale multiplies before the offset.
#[test]
fn texture_transforms_offset_rotate_and_scale_lookups() {
    use tracery::scene::gltf::uv_transform;
    let t = uv_transform([0.5, 0.0], 0.0, [1.0, 1.0]);
    assert!(close(
        t.transform_point2(Vec2::new(0.25, 0.25)).extend(0.0),
        Vec3::new(0.75, 0.25, 0.0)
    ));
    let r = uv_transform([0.0, 0.0], std::f32::consts::FRAC_PI_2, [1.0, 1.0]);
    assert!(close(
        r.transform_point2(Vec2::X).extend(0.0),
        Vec3::new(0.0, -1.0, 0.0)
    ));
    let s = uv_transform([0.1, 0.2], 0.0, [2.0, 3.0]);
    assert!(close(
        s.transform_point2(Vec2::ONE).extend(0.0),
        Vec3::new(2.1, 3.2, 0.0)
    ));

    let dir = tempfile::tempdir().unwrap();
    let png = common::png_2x2();
    let d = doc(
        json!([{"mesh": 0}]),
        json!({
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 2}, "indices": 3, "material": 0}]}],
            "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0,
                "extensions": {"KHR_texture_transform": {"offset": [0.5, 0.0]}}}}}],
            "textures": [{"source": 0}],
            "images": [{"uri": format!("data:image/png;base64,{}", base64::engine::general_purpose::STANDARD.encode(&png))}],
            "extensionsUsed": ["KHR_texture_transform"]
        }),
    );
    let s = Scene::load(&write(dir.path(), "shifted.gltf", &d)).unwrap();
    let tex = s.materials[0].diffuse_map.as_ref().unwrap();
    // (0.25, 0.25) is read at (0.75, 0.25): the green texel.
    assert_eq!(
        tex.sample(Vec2::new(0.25, 0.25)),
        Vec4::new(0.0, 1.0, 0.0, 1.0)
    );
}

/// A 2 x 2 quad of material `top` at height 1 (facing +y, texture coordinates `uv` of each
/// vertex) over an 8 x 8 grey floor, lit by a point light at `light`, seen from 6 above.
fn quad_over_floor(top: tracery::scene::Material, uv: impl Fn(Vec3) -> Vec2, light: Vec3) -> Scene {
    use tracery::scene::{Camera, Environment, Material, Mesh};
    let floor = Material {
        name: "floor".into(),
        diffuse: Vec3::splat(0.8),
        ..Material::default()
    };
    let quad = |h: f32, y: f32| {
        let [a, b, c, d] = [
            Vec3::new(-h, y, -h),
            Vec3::new(h, y, -h),
            Vec3::new(h, y, h),
            Vec3::new(-h, y, h),
        ];
        vec![[a, c, b], [a, d, c]]
    };
    let mut mesh = Mesh::from_triangles(quad(4.0, 0.0), 0);
    let mut top_quad = Mesh::from_triangles(quad(1.0, 1.0), 0);
    top_quad.uvs = top_quad.triangles.iter().map(|t| t.map(&uv)).collect();
    mesh.append(top_quad, 1);
    Scene {
        name: "quad over floor".into(),
        mesh,
        materials: vec![floor, top],
        lights: vec![Light::Point {
            position: light,
            color: Vec3::ONE,
            intensity: 10.0,
        }],
        camera: Camera {
            position: Vec3::new(0.0, 6.0, 0.0),
            look_at: Vec3::ZERO,
            up: Vec3::Z,
            vfov_deg: 60.0,
            lens_radius: 0.0,
            focus_distance: 6.0,
        },
        environment: Environment::None,
        integrator: tracery::scene::Integrator::Direct,
        energy_compensation: false,
        warnings: Vec::new(),
        animation: None,
        instances: Default::default(),
        objects: Vec::new(),
    }
}

/// A glTF `MASK` cut-out (a quad whose texture's left half has alpha 0) over a floor, lit from
/// the side: the camera sees the floor through the hole, the shadow falls only where the
/// texture is opaque (shadow rays read the alpha too), and light through the hole is not
/// tinted. With the texture's alpha ignored, the floor beside the quad lies in the hole's
/// shadow: the same measure tells them apart.
#[test]
fn a_masked_cut_out_lets_light_and_sight_through_its_transparent_texels() {
    use std::sync::Arc;
    use tracery::camera::CameraRays;
    use tracery::scene::{AlphaMode, Material};
    // Texel 0 (u < 0.5): red, alpha 0; texel 1: red, opaque.
    let mut tex = Texture::from_rgba8(
        "cut".into(),
        2,
        1,
        vec![[255, 0, 0, 0], [255, 0, 0, 255]],
        true,
    );
    tex.wrap_u = Wrap::ClampToEdge;
    let cut = Material {
        name: "cut".into(),
        diffuse: Vec3::ONE,
        diffuse_map: Some(Arc::new(tex)),
        alpha_mode: AlphaMode::Mask(0.5),
        ..Material::default()
    };
    // The cut-out at y = 1 over the floor (u = (x + 1) / 2).
    let mut scene = quad_over_floor(
        cut,
        |p| Vec2::new((p.x + 1.0) / 2.0, (p.z + 1.0) / 2.0),
        Vec3::new(2.0, 3.0, 0.0),
    );
    let (w, h) = (80u32, 80u32);
    // Mean colour of the pixels whose camera ray meets the floor at x in `lo..hi`, |z| < 0.7,
    // crossing y = 1 outside the quad or through its hole as `through` says.
    let measure = |scene: &Scene| {
        let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
        let settings = RenderSettings {
            width: w,
            height: h,
            spp: 4,
            ..RenderSettings::default()
        };
        let px = render(scene, &bvh, &settings, &|_| {}).unwrap().film.mean();
        let cam = CameraRays::new(&scene.camera, w, h);
        let group = |lo: f32, hi: f32| {
            let (mut sum, mut n) = (Vec3::ZERO, 0);
            for y in 0..h {
                for x in 0..w {
                    let r = cam.pinhole(x as f32 + 0.5, y as f32 + 0.5);
                    let t = -r.origin.y / r.dir.y;
                    let p = r.origin + r.dir * t;
                    if p.x > lo && p.x < hi && p.z.abs() < 0.7 {
                        sum += px[(y * w + x) as usize];
                        n += 1;
                    }
                }
            }
            assert!(n > 10, "{n} pixels in {lo}..{hi}");
            sum / n as f32
        };
        // Floor beside the quad where the hole's shadow would fall; floor seen through the
        // hole, in the opaque half's shadow; the opaque half itself (seen at floor x 0.3..0.9
        // = quad x 0.25..0.75); floor lit by nothing in the way.
        (
            group(-2.3, -1.5),
            group(-0.8, -0.2),
            group(0.3, 0.9),
            group(2.5, 3.3),
        )
    };
    let (beside, through, opaque, _) = measure(&scene);
    // The same floor with the quad fully transparent (nothing in the way).
    scene.materials[1].alpha_mode = AlphaMode::Blend;
    scene.materials[1].opacity = 0.0;
    let (beside_free, through_free, _, lit) = measure(&scene);
    let l = |c: Vec3| c.x + c.y + c.z;
    assert!(l(lit) > 0.0 && l(beside_free) > 0.0);
    assert!(
        (l(beside) / l(beside_free) - 1.0).abs() < 0.02,
        "beside the quad, lit as with nothing there: {beside} vs {beside_free}"
    );
    assert!(
        l(through) < 0.1 * l(through_free),
        "through the hole, in the opaque half's shadow: {through} vs {through_free}"
    );
    assert!(
        opaque.x > 5.0 * opaque.y && opaque.x > 0.0,
        "the opaque half is red: {opaque}"
    );
    // Grey, not red: the light reaching the floor beside the quad passed no tint.
    assert!(
        (beside.x - beside.y).abs() < 0.02 * beside.x,
        "untinted: {beside}"
    );

    // The texture's alpha ignored: the quad is opaque red everywhere, and the floor beside it
    // lies in its shadow.
    scene.materials[1].alpha_mode = AlphaMode::Opaque;
    scene.materials[1].opacity = 1.0;
    let (beside_opaque, _, _, _) = measure(&scene);
    assert!(
        l(beside_opaque) < 0.1 * l(beside),
        "{beside_opaque} vs {beside}"
    );
}

/// Light through a textured, partly transparent surface is tinted by the texture's colour
/// where the shadow ray crosses it, as the camera sees it: a half-transparent quad whose
/// white material carries a red texture casts a red shadow, not a grey one (fails with the
/// shadow tinted by the material's untextured colour, as before).
#[test]
fn light_through_a_textured_transparent_surface_takes_the_texture_colour() {
    use std::sync::Arc;
    use tracery::render::{EnvironmentMap, RayCounts, RenderPlan, Tracer};
    use tracery::sampling::{PathSampler, PixelSampler, SamplerKind};
    use tracery::scene::Material;
    let tex = Texture::from_rgba8("red".into(), 1, 1, vec![[255, 0, 0, 255]], true);
    let tinted = Material {
        name: "tinted".into(),
        diffuse: Vec3::ONE,
        diffuse_map: Some(Arc::new(tex)),
        opacity: 0.5,
        ..Material::default()
    };
    let scene = quad_over_floor(tinted, |_| Vec2::splat(0.5), Vec3::new(0.0, 3.0, 0.0));
    let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
    let settings = RenderSettings::default();
    let plan = RenderPlan::new(&scene, &settings);
    assert!(plan.transparent_shadows);
    let env = EnvironmentMap::None;
    let tracer = Tracer::new(&scene, &bvh, plan, settings.max_depth, &env);
    // The floor under the quad, seen from below the quad (between it and the floor).
    let ray = tracery::geometry::Ray::new(Vec3::new(0.1, 0.5, 0.2), -Vec3::Y);
    let mut rng = PathSampler::new(PixelSampler::new(SamplerKind::Sobol, 1, 0, 0));
    let l = tracer.radiance(&ray, &mut rng, &mut RayCounts::default());
    assert!(l.x > 0.0, "lit through the quad: {l}");
    assert!(l.y < 0.01 * l.x && l.z < 0.01 * l.x, "red: {l}");
}

/// PNG bytes of a 1x1 RGB image.
fn png_1x1(rgb: [u8; 3]) -> Vec<u8> {
    let img = image::RgbImage::from_raw(1, 1, rgb.to_vec()).unwrap();
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).unwrap();
    out.into_inner()
}

/// The buffer of a 2x2 quad in the xy plane facing +z (positions, normals, texture
/// coordinates with `v = 0` along y = 1, indices) with its views and accessors 0 to 3.
fn quad_buffer() -> (Vec<u8>, Vec<Value>, Vec<Value>) {
    let mut bin = f32_bytes(&[-1., -1., 0., 1., -1., 0., 1., 1., 0., -1., 1., 0.]);
    bin.extend(f32_bytes(&[0., 0., 1.].repeat(4)));
    bin.extend(f32_bytes(&[0., 1., 1., 1., 1., 0., 0., 0.]));
    bin.extend([0u16, 1, 2, 0, 2, 3].iter().flat_map(|i| i.to_le_bytes()));
    let views = vec![
        json!({"buffer": 0, "byteOffset": 0, "byteLength": 48}),
        json!({"buffer": 0, "byteOffset": 48, "byteLength": 48}),
        json!({"buffer": 0, "byteOffset": 96, "byteLength": 32}),
        json!({"buffer": 0, "byteOffset": 128, "byteLength": 12}),
    ];
    let accessors = vec![
        json!({"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [-1, -1, 0], "max": [1, 1, 0]}),
        json!({"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC3"}),
        json!({"bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC2"}),
        json!({"bufferView": 3, "componentType": 5123, "count": 6, "type": "SCALAR"}),
    ];
    (bin, views, accessors)
}

/// A 2x2 quad in the xy plane facing +z, its texture's top row (`v = 0`) along y = 1, as an
/// exporter writes it, with a normal map of one texel `rgb` (its `normalTexture` given the
/// fields of `extra` too) and, if given, a `TANGENT` for every vertex; a dielectric grey
/// material. The load's warnings are returned with the scene.
fn normal_mapped_quad_warned(
    dir: &Path,
    rgb: [u8; 3],
    tangent: Option<[f32; 4]>,
    extra: Value,
) -> Scene {
    let (mut bin, mut views, mut accessors) = quad_buffer();
    let mut attributes = json!({"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2});
    if let Some(t) = tangent {
        bin.extend(f32_bytes(&t.repeat(4)));
        views.push(json!({"buffer": 0, "byteOffset": 140, "byteLength": 64}));
        accessors.push(json!({"bufferView": 4, "componentType": 5126, "count": 4, "type": "VEC4"}));
        attributes["TANGENT"] = json!(4);
    }
    let png = png_1x1(rgb);
    let mut d = json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": attributes, "indices": 3, "material": 0}]}],
        "materials": [{
            "pbrMetallicRoughness": {"metallicFactor": 0.0, "roughnessFactor": 1.0},
            "normalTexture": {"index": 0, "scale": 1.0}
        }],
        "textures": [{"source": 0}],
        "images": [{"uri": format!("data:image/png;base64,{}", base64::engine::general_purpose::STANDARD.encode(&png))}],
        "buffers": [{"byteLength": bin.len(), "uri": data_uri(&bin)}],
        "bufferViews": views,
        "accessors": accessors
    });
    merge(&mut d["materials"][0]["normalTexture"], extra);
    Scene::load(&write(dir, "normal_mapped.gltf", &d)).unwrap()
}

/// [`normal_mapped_quad_warned`] of a file that must load without warnings.
fn normal_mapped_quad(dir: &Path, rgb: [u8; 3], tangent: Option<[f32; 4]>) -> Scene {
    let scene = normal_mapped_quad_warned(dir, rgb, tangent, json!({}));
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    scene
}

/// The radiance at the centre of the quad of [`normal_mapped_quad`], seen from +z, lit by a
/// point light at `light` alone (the direct integrator, Lambertian: no highlight, and no
/// Fresnel under it, which would depend on the light's direction).
fn centre_radiance(scene: &Scene, light: Vec3) -> Vec3 {
    let mut scene = scene.clone();
    scene.materials[0].pbr = None;
    scene.materials[0].specular = Vec3::ZERO;
    quad_picture(&scene, light, 1e5, tracery::scene::Environment::None)[4 * 9 + 4]
}

/// A 9x9 direct-lit picture of a quad about the origin facing +z, seen from +z (the centre
/// pixel on the origin), lit by a point light of `intensity` at `light` alone, with
/// `environment` as the sky.
fn quad_picture(
    scene: &Scene,
    light: Vec3,
    intensity: f32,
    environment: tracery::scene::Environment,
) -> Vec<Vec3> {
    quad_picture_fov(scene, light, intensity, environment, 30.0)
}

/// [`quad_picture`] with a vertical field of view of `vfov_deg` degrees.
fn quad_picture_fov(
    scene: &Scene,
    light: Vec3,
    intensity: f32,
    environment: tracery::scene::Environment,
    vfov_deg: f32,
) -> Vec<Vec3> {
    let mut scene = scene.clone();
    scene.lights = vec![Light::Point {
        position: light,
        color: Vec3::ONE,
        intensity,
    }];
    scene.camera = tracery::scene::Camera {
        position: Vec3::new(0.0, 0.0, 5.0),
        look_at: Vec3::ZERO,
        up: Vec3::Y,
        vfov_deg,
        lens_radius: 0.0,
        focus_distance: 5.0,
    };
    scene.environment = environment;
    scene.integrator = tracery::scene::Integrator::Direct;
    // The known answers these pictures are held to are the single-scattering lobes'.
    scene.energy_compensation = false;
    let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
    // The bent normal's cosines alone: without the shadowing that softens its terminator
    // (which scales both lights' light alike only where the sample lands at the very centre).
    let settings = RenderSettings {
        width: 9,
        height: 9,
        spp: 1,
        soft_terminator: false,
        ..RenderSettings::default()
    };
    render(&scene, &bvh, &settings, &|_| {})
        .unwrap()
        .film
        .mean()
}

/// A glTF normal map (`normalTexture`) on a quad facing the camera, its one texel leaning 45
/// degrees towards the image's up (green, +Y in tangent space): lit by a point light above
/// the quad's centre and then by one as far below it, the centre is brighter under the upper
/// one by the ratio of the bent normal's cosines to the two lights (3), where without
/// the map the two light it alike. The tangents are MikkTSpace's (the file gives none): +x,
/// with the image's up along +y. With a `TANGENT` whose sign mirrors the bitangent, the map
/// leans the other way (the ratio inverted). Fails with the green channel read upside down,
/// with the map read as sRGB (another angle), or with the map ignored (a ratio of 1).
#[test]
fn a_normal_map_bends_the_shading_normal_the_way_its_texels_lean() {
    let dir = tempfile::tempdir().unwrap();
    let rgb = [128u8, 218, 218];
    let scene = normal_mapped_quad(dir.path(), rgb, None);
    let map = scene.materials[0]
        .normal_map
        .as_ref()
        .expect("the normal map");
    assert!(!map.srgb, "normal maps hold linear values");
    assert_eq!(scene.mesh.tangents.len(), 2);
    for t in scene.mesh.tangents.iter().flatten() {
        assert!(close(t.truncate(), Vec3::X), "tangent {t}");
        assert!(
            close(Vec3::Z.cross(t.truncate()) * t.w, Vec3::Y),
            "sign {t}"
        );
    }
    // Far away, so that where in the centre pixel the sample lands does not matter.
    let (up, down) = (Vec3::new(0.0, 200.0, 400.0), Vec3::new(0.0, -200.0, 400.0));
    let m = Vec3::from(rgb.map(|c| c as f32 / 255.0 * 2.0 - 1.0)).normalize();
    let expected = m.dot(up.normalize()) / m.dot(down.normalize());
    assert!(expected > 2.5, "{expected}");
    let l = |c: Vec3| c.x + c.y + c.z;
    let ratio = |s: &Scene| {
        let (a, b) = (centre_radiance(s, up), centre_radiance(s, down));
        assert!(l(a) > 0.0 && l(b) > 0.0, "{a} {b}");
        l(a) / l(b)
    };
    let r = ratio(&scene);
    assert!((r / expected - 1.0).abs() < 1e-3, "{r} against {expected}");
    // Without the map, the two lights light the centre alike.
    let mut plain = scene.clone();
    plain.materials[0].normal_map = None;
    let r = ratio(&plain);
    assert!((r - 1.0).abs() < 1e-3, "{r}");
    // The render plan reads normal maps only where a material has one; switched off (the
    // viewer's toggle), the picture is the one without the map, bit for bit.
    let settings = RenderSettings {
        width: 9,
        height: 9,
        spp: 2,
        ..RenderSettings::default()
    };
    let plan = tracery::render::RenderPlan::new(&scene, &settings);
    assert!(plan.normal_maps);
    assert!(!tracery::render::RenderPlan::new(&plain, &settings).normal_maps);
    let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
    let env = tracery::render::EnvironmentMap::None;
    let off = tracery::render::RenderPlan {
        normal_maps: false,
        ..plan
    };
    let with_plan =
        |s: &Scene, p| tracery::render::render_with_plan(s, &bvh, &env, &settings, p, &|_| {}).film;
    let plain_plan = tracery::render::RenderPlan::new(&plain, &settings);
    assert_eq!(with_plan(&scene, off), with_plan(&plain, plain_plan));
    assert_ne!(with_plan(&scene, plan), with_plan(&plain, plain_plan));
    // The file's own tangents are used: a sign of -1 turns the bitangent to -y.
    let mirrored = normal_mapped_quad(dir.path(), rgb, Some([1.0, 0.0, 0.0, -1.0]));
    assert!(mirrored.mesh.tangents.iter().flatten().all(|t| t.w == -1.0));
    let r = ratio(&mirrored);
    assert!(
        (r * expected - 1.0).abs() < 1e-3,
        "{r} against 1 / {expected}"
    );
}

/// An OBJ quad (2 x 2 about the origin, facing +z, texture coordinates 0..1 with `v` up, a
/// normal per vertex) of material `m`.
const QUAD_OBJ: &str = "mtllib quad.mtl\nv -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\n\
                        vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\nusemtl m\n\
                        f 1/1/1 2/2/1 3/3/1\nf 1/1/1 3/3/1 4/4/1\n";

/// Writes [`QUAD_OBJ`] into `dir` and returns a loader of it whose material `m` is light grey
/// plus the MTL lines given.
fn obj_quad(dir: &Path) -> impl Fn(&str) -> Scene + '_ {
    std::fs::write(dir.join("quad.obj"), QUAD_OBJ).unwrap();
    move |mtl: &str| {
        std::fs::write(
            dir.join("quad.mtl"),
            format!("newmtl m\nKd 0.8 0.8 0.8\n{mtl}\n"),
        )
        .unwrap();
        Scene::load(&dir.join("quad.obj")).unwrap()
    }
}

/// An OBJ quad whose MTL names a normal map: `map_Bump` with a colour image (as exporters
/// write normal maps, `-bm` its scale) and `norm` are read as tangent-space normal maps, with
/// MikkTSpace tangents, and bend the shading normal as the glTF one does (the same ratio); a
/// grey `map_Bump` is a height map (no normal map, no tangents, `-bm` its scale); a `-bm`
/// that is not a number leaves the map out with a warning that says so.
#[test]
fn an_obj_normal_map_bends_like_gltf_and_a_grey_bump_map_is_a_height_map() {
    let dir = tempfile::tempdir().unwrap();
    let rgb = [128u8, 218, 218];
    std::fs::write(dir.path().join("n.png"), png_1x1(rgb)).unwrap();
    std::fs::write(dir.path().join("grey.png"), png_1x1([90, 90, 90])).unwrap();
    let load = obj_quad(dir.path());
    let (up, down) = (Vec3::new(0.0, 200.0, 400.0), Vec3::new(0.0, -200.0, 400.0));
    let m = Vec3::from(rgb.map(|c| c as f32 / 255.0 * 2.0 - 1.0)).normalize();
    let expected = m.dot(up.normalize()) / m.dot(down.normalize());
    let l = |c: Vec3| c.x + c.y + c.z;
    for mtl in ["map_Bump -bm 1.0 n.png", "norm n.png"] {
        let s = load(mtl);
        assert!(s.warnings.is_empty(), "{mtl}: {:?}", s.warnings);
        assert_eq!(s.materials[0].normal_scale, 1.0);
        assert!(!s.materials[0].normal_map.as_ref().expect(mtl).srgb);
        let r = l(centre_radiance(&s, up)) / l(centre_radiance(&s, down));
        assert!(
            (r / expected - 1.0).abs() < 1e-3,
            "{mtl}: {r} against {expected}"
        );
    }
    assert_eq!(load("bump -bm 0.25 n.png").materials[0].normal_scale, 0.25);
    let s = load("map_Bump -bm 0.5 grey.png");
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    let m = &s.materials[0];
    assert!(m.normal_map.is_none() && s.mesh.tangents.is_empty());
    assert!(
        m.height_map.as_ref().is_some_and(|t| !t.srgb),
        "a linear height map"
    );
    assert_eq!(m.height_scale, 0.5);
    for (mtl, why) in [
        ("map_Bump -bm nan grey.png", "-bm"),
        ("map_Bump -bm x n.png", "-bm"),
        ("norm missing.png", "missing.png"),
    ] {
        let s = load(mtl);
        assert!(s.materials[0].normal_map.is_none(), "{mtl}");
        assert!(s.materials[0].height_map.is_none(), "{mtl}");
        assert!(
            s.mesh.tangents.is_empty(),
            "{mtl}: no tangents without a map"
        );
        assert!(
            s.warnings
                .iter()
                .any(|w| w.contains(why) && w.contains("quad.obj")),
            "{mtl}: {:?}",
            s.warnings
        );
    }
}

/// Bump mapping: an OBJ quad (2 x 2, facing the camera along +z) whose grey 8 x 8 `bump`
/// rises by 10 levels a texel column towards +x and 15 a row towards the image's top (+y),
/// `-bm` its scale `s`: it is shaded as the plane of slopes `s 10 / 255 * 8 / 2` and
/// `s 15 / 255 * 8 / 2`, whose normal leans away from the rise, so that the quad's centre,
/// lit by a point light below it and then by one as far above it (and left and right), is
/// brighter under one of each pair by the ratio of that normal's cosines; the scale changes
/// the lean, a negated scale leans it the other way, a flat map and the plan's normal maps off
/// bend nothing, and a quad without texture coordinates is said to leave the map unused.
/// Fails with the gradient's sign, the triangle's `dp/dv` off by a multiple of `dp/du`, or
/// the map ignored (checked).
#[test]
fn a_height_map_bends_the_shading_normal_away_from_its_rise() {
    let dir = tempfile::tempdir().unwrap();
    let texels: Vec<u8> = (0..64u8)
        .flat_map(|i| [20 + 10 * (i % 8) + 15 * (7 - i / 8); 3])
        .collect();
    image::RgbImage::from_raw(8, 8, texels)
        .unwrap()
        .save(dir.path().join("ramp.png"))
        .unwrap();
    std::fs::write(dir.path().join("flat.png"), png_1x1([90, 90, 90])).unwrap();
    let load = obj_quad(dir.path());
    let pairs = [
        (Vec3::new(0.0, -200.0, 400.0), Vec3::new(0.0, 200.0, 400.0)),
        (Vec3::new(-200.0, 0.0, 400.0), Vec3::new(200.0, 0.0, 400.0)),
    ];
    let l = |c: Vec3| c.x + c.y + c.z;
    let ratio =
        |s: &Scene, (a, b): (Vec3, Vec3)| l(centre_radiance(s, a)) / l(centre_radiance(s, b));
    for scale in [1.0f32, 2.5, -2.5] {
        let s = load(&format!("bump -bm {scale} ramp.png"));
        assert!(s.warnings.is_empty(), "{:?}", s.warnings);
        let slope = |step: f32| scale * step / 255.0 * 8.0 / 2.0;
        let n = Vec3::new(-slope(10.0), -slope(15.0), 1.0).normalize();
        for (a, b) in pairs {
            let expected = n.dot(a.normalize()) / n.dot(b.normalize());
            assert!((expected - 1.0).abs() > 0.1, "{scale}: {expected}");
            let r = ratio(&s, (a, b));
            assert!(
                (r / expected - 1.0).abs() < 1e-3,
                "-bm {scale}, lights at {a} and {b}: {r} against {expected}"
            );
        }
    }
    for pair in pairs {
        let r = ratio(&load("bump -bm 2.5 flat.png"), pair);
        assert!((r - 1.0).abs() < 1e-3, "a flat map bends nothing: {r}");
    }
    // Extreme scales light the quad finitely: a near-vertical bent normal (kept where it is
    // above the horizon), or none at all.
    for scale in ["1e30", "-1e30", "3.4e38", "1e-30", "0"] {
        let s = load(&format!("bump -bm {scale} ramp.png"));
        for (a, b) in pairs {
            for light in [a, b] {
                let c = centre_radiance(&s, light);
                assert!(c.is_finite() && c.min_element() >= 0.0, "-bm {scale}: {c}");
            }
        }
    }
    // The plan's switch (the viewer's toggle) leaves the map unread.
    let s = load("bump -bm 2.5 ramp.png");
    let settings = RenderSettings {
        width: 9,
        height: 9,
        spp: 2,
        ..RenderSettings::default()
    };
    let plan = tracery::render::RenderPlan::new(&s, &settings);
    assert!(
        plan.normal_maps,
        "a height map turns the plan's normal maps on"
    );
    let mut plain = s.clone();
    plain.materials[0].height_map = None;
    let bvh = Bvh::build(&s.mesh.triangles, &BuildOptions::sah());
    let env = tracery::render::EnvironmentMap::None;
    let film =
        |s: &Scene, p| tracery::render::render_with_plan(s, &bvh, &env, &settings, p, &|_| {}).film;
    let plain_plan = tracery::render::RenderPlan::new(&plain, &settings);
    let off = tracery::render::RenderPlan {
        normal_maps: false,
        ..plan
    };
    assert_eq!(film(&s, off), film(&plain, plain_plan));
    assert_ne!(film(&s, plan), film(&plain, plain_plan));
    // Without texture coordinates the map cannot be placed: said, and left out.
    std::fs::write(
        dir.path().join("quad.obj"),
        QUAD_OBJ
            .replace("vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n", "")
            .replace("/1/1", "//1")
            .replace("/2/1", "//1")
            .replace("/3/1", "//1")
            .replace("/4/1", "//1"),
    )
    .unwrap();
    let s = load("bump -bm 2.5 ramp.png");
    assert!(s.materials[0].height_map.is_none());
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("quad.obj") && w.contains("height map not used")),
        "{:?}",
        s.warnings
    );
}

/// MTL texture lines as exporters write them: options before the image (`-s 1 1 1`) or after
/// it (`-bm 0.5`), and file names with spaces, name their images; a `-imfchan` other than `l`
/// on a bump line is said not to be read.
#[test]
fn mtl_texture_lines_name_their_images_past_options_and_spaces() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("my tex.png"), png_1x1([200, 30, 30])).unwrap();
    std::fs::write(dir.path().join("my bump.png"), png_1x1([90, 90, 90])).unwrap();
    let load = obj_quad(dir.path());
    let s = load("map_Kd -s 1 1 1 -o 0 0 my tex.png\nbump my bump.png -bm 0.5");
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    let m = &s.materials[0];
    assert!(
        m.diffuse_map
            .as_ref()
            .is_some_and(|t| t.name.ends_with("my tex.png"))
    );
    assert!(
        m.height_map
            .as_ref()
            .is_some_and(|t| t.name.ends_with("my bump.png"))
    );
    assert_eq!(m.height_scale, 0.5);
    let s = load("bump -imfchan r my bump.png");
    assert!(s.materials[0].height_map.is_some());
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("quad.obj") && w.contains("-imfchan r is not read")),
        "{:?}",
        s.warnings
    );
}

/// A normal texture's own `KHR_texture_transform` (which the gltf crate does not read on a
/// normal texture) is applied; malformed fields (an offset beyond f32, a rotation that is not
/// a number) fall back to their defaults with a warning naming them; a scale that is not a
/// number leaves the map out, said.
#[test]
fn a_normal_texture_transform_is_read_and_malformed_fields_are_said() {
    let dir = tempfile::tempdir().unwrap();
    let rgb = [128u8, 218, 218];
    let t = |extra: Value| normal_mapped_quad_warned(dir.path(), rgb, None, extra);
    let s = t(
        json!({"extensions": {"KHR_texture_transform": {"offset": [0.5, 0.25], "scale": [2.0, 2.0]}}}),
    );
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    let map = s.materials[0].normal_map.as_ref().unwrap();
    let m = map.transform.expect("the transform");
    assert!((m.transform_point2(Vec2::ZERO) - Vec2::new(0.5, 0.25)).length() < 1e-6);
    assert!((m.transform_point2(Vec2::X) - Vec2::new(2.5, 0.25)).length() < 1e-6);
    let s = t(
        json!({"extensions": {"KHR_texture_transform": {"offset": [1e300, 0.0], "rotation": "x"}}}),
    );
    assert!(s.materials[0].normal_map.is_some());
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("normalTexture") && w.contains("offset, rotation")),
        "{:?}",
        s.warnings
    );
    let m = s.materials[0]
        .normal_map
        .as_ref()
        .unwrap()
        .transform
        .unwrap();
    assert!(
        (m.transform_point2(Vec2::X) - Vec2::X).length() < 1e-6,
        "defaults"
    );
    let s = t(json!({"scale": 1e39}));
    assert!(s.materials[0].normal_map.is_none());
    assert!(s.mesh.tangents.is_empty());
    assert!(
        s.warnings.iter().any(|w| w.contains("normalTexture.scale")),
        "{:?}",
        s.warnings
    );
}

/// A 2x2 quad facing +z (texture coordinates as [`normal_mapped_quad_warned`]'s) with glTF
/// material `material`; when given, a one-texel base colour image is `textures[0]` and a
/// one-texel metallic-roughness image `textures[1]` (the material names them).
fn pbr_quad(
    dir: &Path,
    name: &str,
    material: Value,
    base: Option<[u8; 3]>,
    mr: Option<[u8; 3]>,
) -> Scene {
    let pngs = [
        png_1x1(base.unwrap_or([255; 3])),
        png_1x1(mr.unwrap_or([255; 3])),
    ];
    textured_quad(dir, name, material, &pngs)
}

/// The quad of [`quad_buffer`] with one material and texture `k` showing PNG image `k`.
fn textured_quad(dir: &Path, name: &str, material: Value, pngs: &[Vec<u8>]) -> Scene {
    let (bin, views, accessors) = quad_buffer();
    let uri = |png: &Vec<u8>| json!({"uri": format!("data:image/png;base64,{}", base64::engine::general_purpose::STANDARD.encode(png))});
    let images: Vec<Value> = pngs.iter().map(uri).collect();
    let textures: Vec<Value> = (0..pngs.len()).map(|k| json!({"source": k})).collect();
    let d = json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2}, "indices": 3, "material": 0}]}],
        "materials": [material],
        "textures": textures,
        "images": images,
        "buffers": [{"byteLength": bin.len(), "uri": data_uri(&bin)}],
        "bufferViews": views,
        "accessors": accessors
    });
    let scene = Scene::load(&write(dir, name, &d)).unwrap();
    assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
    scene
}

/// The sky colour of [`pbr_picture`]: what a mirror shows.
const PBR_SKY: Vec3 = Vec3::new(0.2, 0.5, 1.0);

/// The middle pixel of [`quad_picture`] with the light at the camera, `(0, 0, 5)`: the quad's
/// centre lit and seen along its normal.
fn centre_pixel(scene: &Scene, intensity: f32, environment: tracery::scene::Environment) -> Vec3 {
    quad_picture(scene, Vec3::new(0.0, 0.0, 5.0), intensity, environment)[4 * 9 + 4]
}

/// A 9x9 direct-lit picture of a [`pbr_quad`] seen from +z, a point light up and to the side
/// (its highlight on the quad), a one-colour sky.
fn pbr_picture(scene: &Scene) -> Vec<Vec3> {
    let sky = tracery::scene::Environment::Color(PBR_SKY);
    quad_picture(scene, Vec3::new(1.5, 1.0, 3.0), 30.0, sky)
}

/// Largest difference between two pictures, relative to the brighter pixel.
fn picture_difference(a: &[Vec3], b: &[Vec3]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(a, b)| ((*a - *b).abs().max_element()) / a.max(*b).max_element().max(1e-3))
        .fold(0.0, f32::max)
}

/// A glTF `metallicRoughnessTexture` multiplies the metalness factor by its blue channel and
/// the roughness factor by its green channel (linear values; red, packed occlusion, is not
/// read), at each point the surface is shaded: a quad whose texture holds one texel renders
/// as the quad whose factors equal the texel's values (a rough dielectric, a half-rough
/// metal, a mirror showing the sky). A base colour texture colours a metal's reflection as it
/// does a dielectric's diffuse colour. Fails with the texture ignored, its channels swapped,
/// read as sRGB, or the base texture applied to the diffuse colour only (each a different
/// picture, checked).
#[test]
fn metallic_roughness_textures_vary_the_factors_per_point() {
    let dir = tempfile::tempdir().unwrap();
    let textured = |name: &str, base: Option<[u8; 3]>, mr: [u8; 3], factors: Value| {
        let mut m = json!({"pbrMetallicRoughness": factors});
        m["pbrMetallicRoughness"]["metallicRoughnessTexture"] = json!({"index": 1});
        if base.is_some() {
            m["pbrMetallicRoughness"]["baseColorTexture"] = json!({"index": 0});
        }
        pbr_picture(&pbr_quad(dir.path(), name, m, base, Some(mr)))
    };
    let plain = |name: &str, pbr: Value| {
        pbr_picture(&pbr_quad(
            dir.path(),
            name,
            json!({"pbrMetallicRoughness": pbr}),
            None,
            None,
        ))
    };
    let half = 128.0 / 255.0;
    let cases = [
        // (texel: occlusion, roughness, metalness; factors it must equal)
        (
            [0u8, 255, 0],
            json!({"metallicFactor": 0.0, "roughnessFactor": 1.0}),
        ),
        (
            [255, 255, 0],
            json!({"metallicFactor": 0.0, "roughnessFactor": 1.0}),
        ),
        (
            [0, 128, 255],
            json!({"metallicFactor": 1.0, "roughnessFactor": half}),
        ),
        (
            [0, 0, 255],
            json!({"metallicFactor": 1.0, "roughnessFactor": 0.0}),
        ),
        (
            [0, 255, 255],
            json!({"metallicFactor": 1.0, "roughnessFactor": 1.0}),
        ),
    ];
    let mut pictures = Vec::new();
    for (i, (texel, factors)) in cases.iter().enumerate() {
        let want = plain(&format!("plain{i}.gltf"), factors.clone());
        let got = textured(&format!("mr{i}.gltf"), None, *texel, json!({}));
        let diff = picture_difference(&got, &want);
        assert!(
            diff < 1e-4,
            "texel {texel:?} against {factors}: differs by {diff}"
        );
        pictures.push(want);
    }
    // The cases are told apart (by 100 times the tolerance), the red channel aside: a texture
    // ignored, its channels swapped or its values read as sRGB would be seen.
    for i in 0..pictures.len() {
        for j in 0..i {
            if (i, j) != (1, 0) {
                let d = picture_difference(&pictures[i], &pictures[j]);
                assert!(d > 1e-2, "cases {j} and {i} render alike ({d})");
            }
        }
    }
    // The mirror shows the sky at the quad's centre (its base colour white).
    let centre = pictures[3][4 * 9 + 4];
    assert!(
        close(centre, PBR_SKY),
        "the mirror shows {centre}, not the sky"
    );
    // The base colour texture tints a metal's highlight and a mirror's reflection.
    for (i, rough) in [(0, 0.5f32), (1, 0.0)] {
        let want = plain(
            &format!("red{i}.gltf"),
            json!({"baseColorFactor": [1.0, 0.0, 0.0, 1.0], "metallicFactor": 1.0, "roughnessFactor": rough}),
        );
        let got = textured(
            &format!("red_texture{i}.gltf"),
            Some([255, 0, 0]),
            [0, 255, 255],
            json!({"roughnessFactor": rough}),
        );
        let diff = picture_difference(&got, &want);
        assert!(
            diff < 1e-4,
            "a red base texture on a metal of roughness {rough}: differs by {diff}"
        );
        // The quad's middle (3 by 3 pixels) reflects red light only (but for the white that
        // Schlick's Fresnel adds towards grazing, (1 - cos)^5: under 1e-6 here).
        for y in 3..6 {
            for x in 3..6 {
                let p = want[y * 9 + x];
                assert!(
                    p.x > 0.01 && p.y < 1e-6 * p.x.max(1.0) && p.z < 1e-6 * p.x.max(1.0),
                    "{p} at ({x}, {y})"
                );
            }
        }
    }
}

/// The quad of [`quad_buffer`] with every vertex's `TEXCOORD_0` on the red texel of
/// [`common::png_2x2`] and, when `set1`, every `TEXCOORD_1` on its green texel; black and
/// emissive through the 2x2 image (`emissiveTexture` is `info`, `extra` merged into the
/// material).
fn two_set_quad(dir: &Path, name: &str, info: Value, set1: bool, extra: Value) -> Scene {
    let (mut bin, mut views, mut accessors) = quad_buffer();
    let mut attributes = json!({"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 4});
    for (k, uv) in [[0.25f32, 0.25], [0.75, 0.25]].iter().enumerate() {
        let offset = bin.len();
        bin.extend(f32_bytes(&uv.repeat(4)));
        views.push(json!({"buffer": 0, "byteOffset": offset, "byteLength": 32}));
        accessors
            .push(json!({"bufferView": 4 + k, "componentType": 5126, "count": 4, "type": "VEC2"}));
    }
    if set1 {
        attributes["TEXCOORD_1"] = json!(5);
    }
    let png = common::png_2x2();
    let mut d = json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": attributes, "indices": 3, "material": 0}]}],
        "materials": [{
            "pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0], "metallicFactor": 0.0},
            "emissiveTexture": info,
            "emissiveFactor": [1.0, 1.0, 1.0]
        }],
        "textures": [{"source": 0}],
        "images": [{"uri": format!("data:image/png;base64,{}", base64::engine::general_purpose::STANDARD.encode(&png))}],
        "buffers": [{"byteLength": bin.len(), "uri": data_uri(&bin)}],
        "bufferViews": views,
        "accessors": accessors,
        "extensionsUsed": ["KHR_texture_transform"]
    });
    merge(&mut d["materials"][0], extra);
    Scene::load(&write(dir, name, &d)).unwrap()
}

/// A texture reads the coordinate set it names: `texCoord: 1` (or a `KHR_texture_transform`
/// whose `texCoord` is 1, which replaces the texture's own) shows the quad in the green texel
/// that `TEXCOORD_1` points at, where set 0 points at the red one; the second set is kept only
/// when a texture reads it. A set past 1, or a set the primitive does not have, is a warning
/// that names it. Fails with the texture's `texCoord` ignored (red, and a warning about the set).
#[test]
fn textures_read_the_texture_coordinate_set_they_name() {
    let dir = tempfile::tempdir().unwrap();
    let centre = |s: &Scene| centre_pixel(s, 0.0, tracery::scene::Environment::None);
    let (red, green) = (Vec3::X, Vec3::Y);

    let s = two_set_quad(
        dir.path(),
        "set1.gltf",
        json!({"index": 0, "texCoord": 1}),
        true,
        json!({}),
    );
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    assert_eq!(s.materials[0].emission_map.as_ref().unwrap().uv_set, 1);
    assert_eq!(
        s.mesh.uvs1.len(),
        2,
        "the second set, kept for both triangles"
    );
    assert!(close(centre(&s), green), "set 1: {}", centre(&s));

    let s = two_set_quad(
        dir.path(),
        "set0.gltf",
        json!({"index": 0}),
        true,
        json!({}),
    );
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    assert!(s.mesh.uvs1.is_empty(), "no texture reads set 1");
    assert!(close(centre(&s), red), "set 0: {}", centre(&s));

    let s = two_set_quad(
        dir.path(),
        "transform_set1.gltf",
        json!({"index": 0, "texCoord": 0, "extensions": {"KHR_texture_transform": {"texCoord": 1}}}),
        true,
        json!({}),
    );
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    assert!(
        close(centre(&s), green),
        "the transform's set: {}",
        centre(&s)
    );

    let s = two_set_quad(
        dir.path(),
        "set2.gltf",
        json!({"index": 0, "texCoord": 2}),
        true,
        json!({}),
    );
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("emissiveTexture uses TEXCOORD_2")),
        "{:?}",
        s.warnings
    );
    assert!(
        close(centre(&s), red),
        "set 2 read as set 0: {}",
        centre(&s)
    );

    let s = two_set_quad(
        dir.path(),
        "no_set1.gltf",
        json!({"index": 0, "texCoord": 1}),
        false,
        json!({}),
    );
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("meshes[0].primitives[0]") && w.contains("TEXCOORD_1")),
        "{:?}",
        s.warnings
    );

    // A normal map on set 1 gets its MikkTSpace tangents from set 1: with TEXCOORD_1 the
    // quad's coordinates with u and v swapped (u along +y, v along +x), the tangent (along +u)
    // is +y, where set 0's is +x.
    let (mut bin, mut views, mut accessors) = quad_buffer();
    let offset = bin.len();
    bin.extend(f32_bytes(&[0., 0., 0., 1., 1., 1., 1., 0.]));
    views.push(json!({"buffer": 0, "byteOffset": offset, "byteLength": 32}));
    accessors.push(json!({"bufferView": 4, "componentType": 5126, "count": 4, "type": "VEC2"}));
    let png = png_1x1([128, 128, 255]);
    let d = json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2, "TEXCOORD_1": 4}, "indices": 3, "material": 0}]}],
        "materials": [{"normalTexture": {"index": 0, "texCoord": 1}}],
        "textures": [{"source": 0}],
        "images": [{"uri": format!("data:image/png;base64,{}", base64::engine::general_purpose::STANDARD.encode(&png))}],
        "buffers": [{"byteLength": bin.len(), "uri": data_uri(&bin)}],
        "bufferViews": views,
        "accessors": accessors
    });
    let s = Scene::load(&write(dir.path(), "normal_set1.gltf", &d)).unwrap();
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    for t in s.mesh.tangents.iter().flatten() {
        assert!(close(t.truncate(), Vec3::Y), "tangent {t}");
    }
}

/// [`triangle_buffer`] with more `f32` data appended (each array its own view and accessor of
/// `ty`, numbered from 4): the buffer, views and accessors.
fn triangle_with(extra: &[(&[f32], &str, usize)]) -> (Vec<u8>, Vec<Value>, Vec<Value>) {
    let (mut bin, views, accessors) = triangle_buffer();
    let (mut views, mut accessors) = (
        views.as_array().unwrap().clone(),
        accessors.as_array().unwrap().clone(),
    );
    for (data, ty, count) in extra {
        let offset = bin.len();
        bin.extend(f32_bytes(data));
        views.push(json!({"buffer": 0, "byteOffset": offset, "byteLength": data.len() * 4}));
        accessors.push(json!({"bufferView": views.len() - 1, "componentType": 5126, "count": count, "type": ty}));
    }
    (bin, views, accessors)
}

/// A file of one buffer, the given nodes (roots: those no node lists as a child), meshes and
/// extra fields.
fn file_of(
    bin: &[u8],
    views: Vec<Value>,
    accessors: Vec<Value>,
    nodes: Value,
    extra: Value,
) -> Value {
    let mut d = json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": (0..nodes.as_array().unwrap().len())
            .filter(|i| !is_child(&nodes, *i)).collect::<Vec<_>>()}],
        "nodes": nodes,
        "buffers": [{"byteLength": bin.len(), "uri": data_uri(bin)}],
        "bufferViews": views,
        "accessors": accessors
    });
    merge(&mut d, extra);
    d
}

/// Morph targets are applied at the mesh's default weights, or at a node's own weights where
/// it has them (the static shape the specification defines when no animation plays): a target
/// lifting the first vertex by 1 and tilting every normal towards +x, at weight 0.5 under the
/// mesh's weights and at 1 under a node's, places the vertex at z 0.5 and 1 and bends the
/// normals by as much. A displacement accessor of the wrong length is an error naming it.
/// Fails with the targets ignored (z 0 everywhere) or the node's weights ignored.
#[test]
fn morph_targets_take_the_mesh_or_node_weights() {
    let dir = tempfile::tempdir().unwrap();
    let lift = [0., 0., 1., 0., 0., 0., 0., 0., 0.];
    let tilt = [1., 0., 0.].repeat(3);
    let (bin, views, accessors) = triangle_with(&[(&lift, "VEC3", 3), (&tilt, "VEC3", 3)]);
    let mesh = json!({"meshes": [{
        "primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1}, "indices": 3,
                        "targets": [{"POSITION": 4, "NORMAL": 5}]}],
        "weights": [0.5]
    }]});
    let nodes = json!([{"mesh": 0}, {"mesh": 0, "translation": [10, 0, 0], "weights": [1.0]}]);
    let d = file_of(&bin, views.clone(), accessors.clone(), nodes, mesh.clone());
    let s = Scene::load(&write(dir.path(), "morph.gltf", &d)).unwrap();
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    assert_eq!(s.mesh.triangles.len(), 2);
    let mut placed: Vec<[Vec3; 3]> = (0..2).map(|i| world(&s, i)).collect();
    placed.sort_by(|a, b| a[0].x.total_cmp(&b[0].x));
    assert!(
        close(placed[0][0], Vec3::new(0.0, 0.0, 0.5)),
        "{:?}",
        placed[0]
    );
    assert!(close(placed[0][1], Vec3::X), "{:?}", placed[0]);
    assert!(
        close(placed[1][0], Vec3::new(10.0, 0.0, 1.0)),
        "{:?}",
        placed[1]
    );
    // The normals tilt by the weight of the node that placed them.
    for i in 0..2 {
        let w = if world(&s, i)[0].x < 5.0 { 0.5 } else { 1.0 };
        let want = Vec3::new(w, 0.0, 1.0).normalize();
        for n in s.mesh.normals[i] {
            assert!(close(n, want), "normal {n}, want {want}");
        }
    }

    // No weights anywhere: every weight 0, no warning.
    let mut bare = mesh.clone();
    bare["meshes"][0].as_object_mut().unwrap().remove("weights");
    let d = file_of(
        &bin,
        views.clone(),
        accessors.clone(),
        json!([{"mesh": 0}]),
        bare,
    );
    let s = Scene::load(&write(dir.path(), "morph_bare.gltf", &d)).unwrap();
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    assert!(close(world(&s, 0)[0], Vec3::ZERO));

    // A displacement of two elements for three vertices.
    let mut short = accessors.clone();
    short[4]["count"] = json!(2);
    let d = file_of(&bin, views, short, json!([{"mesh": 0}]), mesh);
    let e = error_of(&write(dir.path(), "morph_short.gltf", &d));
    assert!(
        e.contains("targets[0].POSITION") && e.contains("3 vertices"),
        "{e}"
    );
}

/// A skinned mesh is placed by its joints, not by its node: each vertex goes where its joints'
/// world transforms times their inverse bind matrices take it, blended by its weights (the
/// first vertex on a joint 2 up in z, the second on a joint whose inverse bind matrix undoes
/// its place, the third half on each), while the translation of the mesh's own node is
/// ignored, as the specification asks. A joint past the skin's list and too few inverse bind
/// matrices are errors naming them. Fails with the skin ignored (the node's translation
/// applied) or the inverse bind matrices left out.
#[test]
fn a_skinned_mesh_is_placed_by_its_joints() {
    let dir = tempfile::tempdir().unwrap();
    let weights = [1., 0., 0., 0., 1., 0., 0., 0., 0.5, 0.5, 0., 0.];
    let mut inverse_bind = mat4_identity();
    inverse_bind.extend(mat4_translation([-5.0, -1.0, 0.0]));
    let (mut bin, mut views, mut accessors) =
        triangle_with(&[(&weights, "VEC4", 3), (&inverse_bind, "MAT4", 2)]);
    // JOINTS_0 as unsigned bytes: joint 0 / joint 1 / joints 0 and 1.
    let offset = bin.len();
    bin.extend([0u8, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0]);
    views.push(json!({"buffer": 0, "byteOffset": offset, "byteLength": 12}));
    accessors.push(json!({"bufferView": 6, "componentType": 5121, "count": 3, "type": "VEC4"}));
    let nodes = json!([
        {"mesh": 0, "skin": 0, "translation": [100, 0, 0]},
        {"translation": [0, 0, 2]},
        {"translation": [0, 1, 0], "children": [3]},
        {"translation": [5, 0, 0]}
    ]);
    let extra = |joints: Value| {
        json!({
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1, "JOINTS_0": 6, "WEIGHTS_0": 4}, "indices": 3}]}],
            "skins": [{"joints": joints, "inverseBindMatrices": 5}]
        })
    };
    let d = file_of(
        &bin,
        views.clone(),
        accessors.clone(),
        nodes.clone(),
        extra(json!([1, 3])),
    );
    let s = Scene::load(&write(dir.path(), "skin.gltf", &d)).unwrap();
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    let t = world(&s, 0);
    assert!(close(t[0], Vec3::new(0.0, 0.0, 2.0)), "{t:?}");
    assert!(close(t[1], Vec3::X), "{t:?}");
    assert!(close(t[2], Vec3::new(0.0, 1.0, 1.0)), "{t:?}");
    for n in s.mesh.normals[0] {
        assert!(close(n, Vec3::Z), "normal {n}");
    }

    // Three joints and two inverse bind matrices.
    let d = file_of(
        &bin,
        views.clone(),
        accessors.clone(),
        nodes.clone(),
        extra(json!([1, 3, 2])),
    );
    let e = error_of(&write(dir.path(), "skin_short.gltf", &d));
    assert!(
        e.contains("skins[0]") && e.contains("2 inverseBindMatrices for 3 joints"),
        "{e}"
    );

    // A vertex on joint 1 of a skin with one joint.
    let mut one = accessors.clone();
    one[5]["count"] = json!(1);
    let d = file_of(&bin, views, one, nodes, extra(json!([1])));
    let e = error_of(&write(dir.path(), "skin_joint.gltf", &d));
    assert!(
        e.contains("meshes[0].primitives[0]") && e.contains("joint 1 of a skin with 1 joints"),
        "{e}"
    );
}

/// Column-major 4x4 identity, as glTF stores matrices.
fn mat4_identity() -> Vec<f32> {
    glam::Mat4::IDENTITY.to_cols_array().to_vec()
}

/// Column-major translation matrix.
fn mat4_translation(t: [f32; 3]) -> Vec<f32> {
    glam::Mat4::from_translation(Vec3::from(t))
        .to_cols_array()
        .to_vec()
}

/// A file with animations says they are not played (assimp's animated morph cube, fetched).
#[test]
fn animations_are_said_not_played() {
    let Some(p) =
        common::external("gltf/glTF-Sample-Models/AnimatedMorphCube-glTF/AnimatedMorphCube.gltf")
    else {
        return;
    };
    let s = Scene::load(&p).unwrap();
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("1 animation(s) not played")),
        "{:?}",
        s.warnings
    );
}

/// An extension the file uses (not requires) and Tracery does not read is said, by name; one
/// it reads is not.
#[test]
fn extensions_used_but_not_read_are_said() {
    let dir = tempfile::tempdir().unwrap();
    let d = doc(
        json!([{"mesh": 0}]),
        json!({"extensionsUsed": ["KHR_materials_iridescence", "KHR_texture_transform"]}),
    );
    let s = Scene::load(&write(dir.path(), "iridescence.gltf", &d)).unwrap();
    assert_eq!(s.warnings.len(), 1, "{:?}", s.warnings);
    assert!(
        s.warnings[0].contains("KHR_materials_iridescence")
            && s.warnings[0].contains("iridescence.gltf"),
        "{:?}",
        s.warnings
    );
}

/// `KHR_mesh_quantization` (required, as gltfpack writes it): positions as unnormalised
/// 16-bit integers scaled back by the node, normals as normalised bytes, texture coordinates
/// as normalised 16-bit integers and a morph displacement as normalised 16-bit integers are
/// read as the floats they stand for (a normal's byte -128 as -1). Fails with the accessors'
/// `normalized` ignored, or with integer attributes refused.
#[test]
fn quantized_attributes_are_read_as_the_floats_they_stand_for() {
    let dir = tempfile::tempdir().unwrap();
    let mut bin: Vec<u8> = Vec::new();
    // POSITION, u16 (unnormalised), padded to 8 bytes a vertex: (0,0,0), (1000,0,0), (0,1000,0).
    for p in [[0u16, 0, 0], [1000, 0, 0], [0, 1000, 0]] {
        bin.extend(p.iter().flat_map(|c| c.to_le_bytes()));
        bin.extend([0, 0]);
    }
    // NORMAL, i8 normalised, padded to 4 bytes: +z, and -128 (clamped to -1) in z.
    for n in [[0i8, 0, 127], [0, 0, 127], [0, 0, -128]] {
        bin.extend(n.map(|c| c as u8));
        bin.push(0);
    }
    // TEXCOORD_0, u16 normalised: (0, 0), (1, 0), (0, 0.5).
    for t in [[0u16, 0], [65535, 0], [0, 32768]] {
        bin.extend(t.iter().flat_map(|c| c.to_le_bytes()));
    }
    // A morph target's POSITION, i16 normalised, padded to 8 bytes: the first vertex up by 1.
    for d in [[0i16, 0, 32767], [0, 0, 0], [0, 0, 0]] {
        bin.extend(d.iter().flat_map(|c| c.to_le_bytes()));
        bin.extend([0, 0]);
    }
    let d = json!({
        "asset": {"version": "2.0"},
        "extensionsUsed": ["KHR_mesh_quantization"],
        "extensionsRequired": ["KHR_mesh_quantization"],
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "scale": [0.001, 0.001, 0.001]}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2},
                                    "targets": [{"POSITION": 3}]}],
                    "weights": [0.5]}],
        "buffers": [{"byteLength": bin.len(), "uri": data_uri(&bin)}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 24, "byteStride": 8},
            {"buffer": 0, "byteOffset": 24, "byteLength": 12, "byteStride": 4},
            {"buffer": 0, "byteOffset": 36, "byteLength": 12},
            {"buffer": 0, "byteOffset": 48, "byteLength": 24, "byteStride": 8}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5123, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1000, 1000, 0]},
            {"bufferView": 1, "componentType": 5120, "normalized": true, "count": 3, "type": "VEC3"},
            {"bufferView": 2, "componentType": 5123, "normalized": true, "count": 3, "type": "VEC2"},
            {"bufferView": 3, "componentType": 5122, "normalized": true, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [0, 0, 1]}
        ]
    });
    let s = Scene::load(&write(dir.path(), "quantized.gltf", &d)).unwrap();
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    let t = world(&s, 0);
    // The target's displacement (1 at weight 0.5, in the node's frame) is scaled by the node.
    assert!(close(t[0], Vec3::new(0.0, 0.0, 0.0005)), "{t:?}");
    assert!(close(t[1], Vec3::X) && close(t[2], Vec3::Y), "{t:?}");
    let n = s.mesh.normals[0];
    assert!(close(n[0], Vec3::Z) && close(n[2], -Vec3::Z), "{n:?}");
    let uv = s.mesh.uvs[0];
    assert!(
        (uv[1] - Vec2::X).length() < 1e-6
            && (uv[2] - Vec2::new(0.0, 32768.0 / 65535.0)).length() < 1e-6,
        "{uv:?}"
    );
}

/// A mirror under a clear coat shows what it reflects dimmed by the light the coat reflects
/// away, `1 - k F(wo.n)`: seen along its normal, a coated white mirror (factor 1) shows 0.96
/// of the sky, an uncoated one all of it, and a half coat (factor 0.5) 0.98. No light: the
/// coat's own lobe adds nothing. Fails with the mirror traced apart from the coat (1x).
#[test]
fn a_clear_coat_dims_the_mirror_under_it() {
    let dir = tempfile::tempdir().unwrap();
    let mirror = json!({"pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 1.0], "metallicFactor": 1.0, "roughnessFactor": 0.0}});
    let coated = |k: f32| {
        let mut m = mirror.clone();
        m["extensions"] = json!({"KHR_materials_clearcoat": {"clearcoatFactor": k, "clearcoatRoughnessFactor": 0.5}});
        m
    };
    let centre = |s: &Scene| centre_pixel(s, 0.0, tracery::scene::Environment::Color(PBR_SKY));
    let plain = centre(&pbr_quad(
        dir.path(),
        "plain.gltf",
        mirror.clone(),
        None,
        None,
    ));
    assert!(
        (plain - PBR_SKY).abs().max_element() < 1e-4,
        "uncoated {plain}, want the sky {PBR_SKY}"
    );
    for (k, want) in [(1.0, 0.96), (0.5, 0.98)] {
        let c = centre(&pbr_quad(
            dir.path(),
            &format!("coated{k}.gltf"),
            coated(k),
            None,
            None,
        ));
        assert!(
            (c - want * PBR_SKY).abs().max_element() < 1e-4,
            "coat {k}: {c}, want {want} of the sky {PBR_SKY}"
        );
    }
}

/// Asserts that one of the scene's warnings holds every string of `what`.
fn assert_warned(s: &Scene, what: &[&str]) {
    assert!(
        s.warnings
            .iter()
            .any(|w| what.iter().all(|x| w.contains(x))),
        "a warning with {what:?}: {:?}",
        s.warnings
    )
}

/// A one-texel lossless WebP image of colour `rgb`.
fn webp_1x1(rgb: [u8; 3]) -> Vec<u8> {
    let mut out = Vec::new();
    image::codecs::webp::WebPEncoder::new_lossless(&mut out)
        .encode(
            &[rgb[0], rgb[1], rgb[2], 255],
            1,
            1,
            image::ExtendedColorType::Rgba8,
        )
        .unwrap();
    out
}

/// `EXT_texture_webp`: a texture's WebP source is read in place of its core one (a red PNG
/// behind a green WebP shows green), a texture with only a WebP source loads (the extension
/// required, as gltf-transform writes it), a WebP source naming no image is a warning and the
/// core source is used, and a texture with no image at all is a warning and no texture. Fails
/// with the extension ignored (red, checked).
#[test]
fn webp_textures_are_read_in_place_of_their_fallback() {
    let dir = tempfile::tempdir().unwrap();
    let (bin, views, accessors) = quad_buffer();
    let uri = |bytes: Vec<u8>, mime: &str| json!({"uri": format!("data:{mime};base64,{}", base64::engine::general_purpose::STANDARD.encode(bytes))});
    let textured = |k: usize| json!({"pbrMetallicRoughness": {"baseColorTexture": {"index": k}, "metallicFactor": 0.0}});
    let d = json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0, 1, 2, 3]}],
        "nodes": [{"mesh": 0}, {"mesh": 1}, {"mesh": 2}, {"mesh": 3}],
        "meshes": (0..4).map(|k| json!({"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2}, "indices": 3, "material": k}]})).collect::<Vec<_>>(),
        "materials": (0..4).map(textured).collect::<Vec<_>>(),
        "textures": [
            {"source": 0, "extensions": {"EXT_texture_webp": {"source": 1}}},
            {"extensions": {"EXT_texture_webp": {"source": 1}}},
            {"source": 0, "extensions": {"EXT_texture_webp": {"source": 9}}},
            {}
        ],
        "images": [uri(png_1x1([255, 0, 0]), "image/png"), uri(webp_1x1([0, 255, 0]), "image/webp")],
        "buffers": [{"byteLength": bin.len(), "uri": data_uri(&bin)}],
        "bufferViews": views,
        "accessors": accessors,
        "extensionsUsed": ["EXT_texture_webp"],
        "extensionsRequired": ["EXT_texture_webp"]
    });
    let s = Scene::load(&write(dir.path(), "webp.gltf", &d)).unwrap();
    let texel = |i: usize| {
        s.materials[i]
            .diffuse_map
            .as_ref()
            .map(|t| t.sample(Vec2::splat(0.5)).truncate())
    };
    let (red, green) = (Vec3::X, Vec3::Y);
    assert_eq!(
        texel(0),
        Some(green),
        "the WebP source, not the PNG fallback"
    );
    assert_eq!(texel(1), Some(green), "a WebP source alone");
    assert_eq!(
        texel(2),
        Some(red),
        "a WebP source naming no image: the core source"
    );
    assert_eq!(texel(3), None, "no image at all");
    let said = |what: &[&str]| assert_warned(&s, what);
    said(&[
        "materials[2]",
        "textures[2]'s EXT_texture_webp names no image (9)",
    ]);
    said(&["materials[3]", "textures[3] has no image"]);
    assert_eq!(s.warnings.len(), 2, "{:?}", s.warnings);
}

/// `KHR_materials_ior` and `KHR_materials_specular` set a dielectric's Fresnel, as the
/// extensions define it: a black rough dielectric lit and seen along its normal reflects
/// `weight f0 D / 4` of the light, with `f0 = ((ior - 1) / (ior + 1))^2` times the specular
/// colour (at most 1) and `weight` the specular factor, each times its texture (the colour
/// texture's sRGB decoded, the factor texture's alpha). A white diffuse dielectric's diffuse
/// lobe is dimmed by `1 - weight F`: not at all for factor 0. Fails with the index of
/// refraction read for glass only (1x instead of 2.8x), the colour or factor ignored, the
/// colour texture read as linear, or the diffuse lobe dimmed by the full Fresnel (checked).
#[test]
fn ior_and_specular_set_a_dielectrics_fresnel() {
    let dir = tempfile::tempdir().unwrap();
    let centre = |s: &Scene| centre_pixel(s, 100.0, tracery::scene::Environment::None);
    let material = |base: f32, extensions: Value| {
        json!({"pbrMetallicRoughness": {"baseColorFactor": [base, base, base, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0},
               "extensions": extensions})
    };
    let black = |extensions: Value| material(0.0, extensions);
    // Irradiance 100 / 5^2 = 4; GGX D at the normal 1 / pi (width 1), G 1, Fresnel f0.
    let per_f0 = 4.0 * std::f32::consts::FRAC_1_PI / 4.0;
    let pngs = [png_1x1([188, 255, 64]), png_rgba_1x1([255, 255, 255, 51])];
    let cases = [
        ("plain", json!({}), Vec3::splat(0.04)),
        (
            "ior",
            json!({"KHR_materials_ior": {"ior": 2.0}}),
            Vec3::splat(1.0 / 9.0),
        ),
        (
            "factor",
            json!({"KHR_materials_specular": {"specularFactor": 0.5}}),
            Vec3::splat(0.02),
        ),
        (
            "colour",
            json!({"KHR_materials_specular": {"specularColorFactor": [0.5, 1.0, 30.0]}}),
            Vec3::new(0.02, 0.04, 1.0),
        ),
        (
            "both",
            json!({"KHR_materials_ior": {"ior": 2.0}, "KHR_materials_specular": {"specularColorFactor": [2.0, 2.0, 2.0]}}),
            Vec3::splat(2.0 / 9.0),
        ),
        (
            "textures",
            json!({"KHR_materials_specular": {"specularColorTexture": {"index": 0}, "specularTexture": {"index": 1}}}),
            Vec3::new(srgb(188), 1.0, srgb(64)) * 0.04 * (51.0 / 255.0),
        ),
    ];
    for (name, extensions, f) in cases {
        let s = textured_quad(
            dir.path(),
            &format!("{name}.gltf"),
            black(extensions),
            &pngs,
        );
        let c = centre(&s);
        let want = f * per_f0;
        assert_near(c, want, name);
    }
    // A white diffuse dielectric: dimmed by `1 - weight F` under its specular lobe. Factor 0:
    // no lobe and no dimming, Lambertian, 4 / pi (4% off if dimmed as by default); factor
    // 0.5: `4 (0.98 + 0.02 / 4) / pi` (2% off if dimmed as by default).
    for (factor, want) in [(0.0, 4.0), (0.5, 4.0 * (0.98 + 0.02 / 4.0))] {
        let s = textured_quad(
            dir.path(),
            &format!("white{factor}.gltf"),
            material(
                1.0,
                json!({"KHR_materials_specular": {"specularFactor": factor}}),
            ),
            &pngs,
        );
        let c = centre(&s);
        let want = want * std::f32::consts::FRAC_1_PI;
        assert_near(c, Vec3::splat(want), &format!("white, factor {factor}"));
    }
}

/// The quad of [`quad_buffer`] once per material of `materials`, each its own mesh and node,
/// written as `name` with `extensionsUsed` `used`, loaded (its warnings kept).
fn quads_of(dir: &Path, name: &str, materials: &[Value], used: &[&str]) -> Scene {
    let (bin, views, accessors) = quad_buffer();
    let n = materials.len();
    let d = json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": (0..n).collect::<Vec<_>>()}],
        "nodes": (0..n).map(|k| json!({"mesh": k})).collect::<Vec<_>>(),
        "meshes": (0..n).map(|k| json!({"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1}, "indices": 3, "material": k}]})).collect::<Vec<_>>(),
        "materials": materials,
        "buffers": [{"byteLength": bin.len(), "uri": data_uri(&bin)}],
        "bufferViews": views,
        "accessors": accessors,
        "extensionsUsed": used
    });
    Scene::load(&write(dir, name, &d)).unwrap()
}

/// `c` within 0.5% of `want` in every channel (`what` names the case).
fn assert_near(c: Vec3, want: Vec3, what: &str) {
    assert!(
        ((c - want).abs() / want).max_element() < 0.005,
        "{what}: {c}, want {want}"
    );
}

/// The linear value of an sRGB-encoded byte.
fn srgb(c: u8) -> f32 {
    let c = c as f32 / 255.0;
    ((c + 0.055) / 1.055).powf(2.4)
}

/// A one-texel RGBA PNG.
fn png_rgba_1x1(rgba: [u8; 4]) -> Vec<u8> {
    let mut out = std::io::Cursor::new(Vec::new());
    image::RgbaImage::from_raw(1, 1, rgba.to_vec())
        .unwrap()
        .write_to(&mut out, image::ImageFormat::Png)
        .unwrap();
    out.into_inner()
}

/// Malformed `KHR_materials_specular` factors and a `KHR_materials_ior` index below 1 (but
/// for 0) are warnings naming the material and the field, and their defaults are used.
#[test]
fn malformed_specular_and_ior_are_warnings_and_defaults() {
    let dir = tempfile::tempdir().unwrap();
    let m =
        |ext: Value| json!({"pbrMetallicRoughness": {"metallicFactor": 0.0}, "extensions": ext});
    let s = quads_of(
        dir.path(),
        "specular.gltf",
        &[
            m(
                json!({"KHR_materials_specular": {"specularFactor": "shiny", "specularColorFactor": [1.0, -1.0, 0.0]}}),
            ),
            m(json!({"KHR_materials_ior": {"ior": 0.5}})),
            m(
                json!({"KHR_materials_ior": {"ior": 0.0}, "KHR_materials_specular": {"specularColorTexture": {"index": 4}}}),
            ),
        ],
        &["KHR_materials_specular", "KHR_materials_ior"],
    );
    let said = |what: &[&str]| assert_warned(&s, what);
    said(&["materials[0]", "specularFactor is malformed"]);
    said(&["materials[0]", "specularColorFactor is malformed"]);
    said(&["materials[1]", "ior 0.5"]);
    said(&["materials[2]", "specularColorTexture names no texture"]);
    assert_eq!(s.warnings.len(), 4, "{:?}", s.warnings);
    let spec = |i: usize| s.materials[i].pbr.as_ref().unwrap().specular.clone();
    assert_eq!((spec(0).factor, spec(0).color), (1.0, Vec3::ONE));
    assert_eq!(spec(1).ior, 1.5, "an index below 1 is the default");
    assert_eq!(spec(2).ior, 0.0, "0 is allowed: f0 = 1");
    assert!(spec(2).color_map.is_none());
}

/// `KHR_materials_sheen` (the fibres of cloth): a black base with a sheen, seen along its
/// normal and lit from low over it, shows `sheenColor D V cos` of the light
/// ([`tracery::render::bsdf::sheen::brdf`], itself checked against the extension's formulas), for
/// the colour and roughness factors and for their textures (the colour's sRGB decoded, the
/// roughness's alpha); a white diffuse base under a white sheen, lit and seen along its
/// normal (where the fibres reflect nothing), is dimmed by the sheen's albedo there, `1 -
/// E(1)`. Fails with the extension ignored (black), either texture ignored or the colour
/// texture read as linear, or the base left undimmed (checked).
#[test]
fn a_sheen_reflects_at_grazing_and_dims_the_base() {
    use tracery::render::bsdf::sheen::{albedo, brdf};
    let dir = tempfile::tempdir().unwrap();
    // No GGX lobe (specular factor 0): the base is its diffuse colour alone.
    let material = |base: f32, sheen: Value| {
        json!({"pbrMetallicRoughness": {"baseColorFactor": [base, base, base, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0},
               "extensions": {"KHR_materials_specular": {"specularFactor": 0.0}, "KHR_materials_sheen": sheen}})
    };
    let pngs = [png_1x1([188, 255, 64]), png_rgba_1x1([255, 255, 255, 153])];
    // The light low over the quad, at (4, 0, 1): cosine 1 / sqrt(17) there, the half vector
    // with the view along the normal at cosine sqrt((1 + ci) / 2). A narrow sheen changes
    // fast with the half vector: the picture's field of view is a twentieth of a degree, so
    // that where in its pixel the centre's sample falls moves neither direction.
    let light = Vec3::new(4.0, 0.0, 1.0);
    let ci = 1.0 / 17f32.sqrt();
    let nh = ((1.0 + ci) / 2.0).sqrt();
    let irradiance = 100.0 * ci / 17.0;
    let none = tracery::scene::Environment::None;
    let cases = [
        (
            "white",
            json!({"sheenColorFactor": [1.0, 1.0, 1.0], "sheenRoughnessFactor": 0.5}),
            Vec3::ONE,
            0.5,
        ),
        (
            "tinted",
            json!({"sheenColorFactor": [0.2, 0.5, 1.0], "sheenRoughnessFactor": 1.0}),
            Vec3::new(0.2, 0.5, 1.0),
            1.0,
        ),
        (
            "textures",
            json!({"sheenColorFactor": [1.0, 1.0, 1.0], "sheenColorTexture": {"index": 0},
                   "sheenRoughnessFactor": 1.0, "sheenRoughnessTexture": {"index": 1}}),
            Vec3::new(srgb(188), 1.0, srgb(64)),
            153.0 / 255.0,
        ),
    ];
    for (name, sheen, color, roughness) in cases {
        let s = textured_quad(
            dir.path(),
            &format!("{name}.gltf"),
            material(0.0, sheen),
            &pngs,
        );
        let c = quad_picture_fov(&s, light, 100.0, none.clone(), 0.05)[4 * 9 + 4];
        let want = color * brdf(roughness, nh, ci, 1.0) * irradiance;
        assert_near(c, want, name);
    }
    let s = textured_quad(
        dir.path(),
        "over_white.gltf",
        material(
            1.0,
            json!({"sheenColorFactor": [1.0, 1.0, 1.0], "sheenRoughnessFactor": 0.5}),
        ),
        &pngs,
    );
    let c = centre_pixel(&s, 100.0, tracery::scene::Environment::None);
    let want = 4.0 * std::f32::consts::FRAC_1_PI * (1.0 - albedo(1.0, 0.5));
    assert_near(c, Vec3::splat(want), "over white");
}

/// Malformed `KHR_materials_sheen` factors are warnings naming the material and the field,
/// and their defaults are used (a colour factor's is black: no sheen); a black colour factor
/// is no sheen, and the extension is read (no "not read" warning).
#[test]
fn malformed_sheen_factors_are_warnings_and_defaults() {
    let dir = tempfile::tempdir().unwrap();
    let m = |ext: Value| json!({"pbrMetallicRoughness": {"metallicFactor": 0.0}, "extensions": {"KHR_materials_sheen": ext}});
    let s = quads_of(
        dir.path(),
        "sheen.gltf",
        &[
            m(json!({"sheenColorFactor": "velvet"})),
            m(
                json!({"sheenColorFactor": [0.5, 0.4, 0.3], "sheenRoughnessFactor": [1], "sheenColorTexture": {"index": 7}}),
            ),
            m(json!({"sheenColorFactor": [0.0, 0.0, 0.0], "sheenRoughnessFactor": 0.5})),
        ],
        &["KHR_materials_sheen"],
    );
    let said = |what: &[&str]| assert_warned(&s, what);
    said(&["materials[0]", "sheenColorFactor is malformed"]);
    said(&["materials[1]", "sheenRoughnessFactor is malformed"]);
    said(&["materials[1]", "sheenColorTexture names no texture"]);
    assert_eq!(s.warnings.len(), 3, "{:?}", s.warnings);
    let sheen = |i: usize| s.materials[i].pbr.as_ref().unwrap().sheen.clone();
    assert_eq!(sheen(0), None);
    let read = sheen(1).unwrap();
    assert_eq!(
        (read.color, read.roughness),
        (Vec3::new(0.5, 0.4, 0.3), 0.0)
    );
    assert!(read.color_map.is_none());
    assert_eq!(sheen(2), None, "a black sheen is none");
}

/// `KHR_materials_clearcoat` is read: its factors (clamped), its three textures (the normal
/// texture with its scale, which also makes the primitive's tangents), a malformed factor and
/// a texture index past the list as warnings naming them, a factor of 0 as no coat, and no
/// "not read" warning for the extension.
#[test]
fn clear_coats_are_read_with_their_textures() {
    let dir = tempfile::tempdir().unwrap();
    let cc = |v: Value| json!({"pbrMetallicRoughness": {"metallicFactor": 0.0}, "extensions": {"KHR_materials_clearcoat": v}});
    let materials = json!([
        cc(
            json!({"clearcoatFactor": 0.8, "clearcoatRoughnessFactor": 1.5, "clearcoatTexture": {"index": 0},
                  "clearcoatRoughnessTexture": {"index": 0}, "clearcoatNormalTexture": {"index": 0, "scale": 0.5}})
        ),
        cc(json!({"clearcoatFactor": "much", "clearcoatRoughnessFactor": 0.2})),
        cc(json!({"clearcoatFactor": 0.5, "clearcoatTexture": {"index": 7}}))
    ]);
    let nodes: Vec<Value> = (0..3).map(|m| json!({"mesh": m})).collect();
    let prim = |m: usize| json!({"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2}, "indices": 3, "material": m}]});
    let png = common::png_2x2();
    let d = doc(
        Value::Array(nodes),
        json!({
            "materials": materials,
            "meshes": (0..3).map(prim).collect::<Vec<_>>(),
            "textures": [{"source": 0}],
            "images": [{"uri": format!("data:image/png;base64,{}", base64::engine::general_purpose::STANDARD.encode(&png))}],
            "extensionsUsed": ["KHR_materials_clearcoat"]
        }),
    );
    let s = Scene::load(&write(dir.path(), "coats.gltf", &d)).unwrap();
    let coat = |i: usize| s.materials[i].pbr.as_ref().unwrap().clearcoat.clone();
    let c = coat(0).expect("the first material's coat");
    assert_eq!((c.factor, c.roughness, c.normal_scale), (0.8, 1.0, 0.5));
    assert!(c.map.is_some() && c.roughness_map.is_some() && c.normal_map.is_some());
    assert!(
        !c.normal_map.as_ref().unwrap().srgb,
        "coat textures hold linear values"
    );
    assert!(
        s.mesh.tangents.iter().flatten().any(|t| *t != Vec4::ZERO),
        "the coat's normal map needs tangents"
    );
    assert!(
        coat(1).is_none(),
        "a malformed factor is its default, 0: no coat"
    );
    assert!(coat(2).is_some_and(|c| c.factor == 0.5 && c.map.is_none()));
    assert_eq!(s.warnings.len(), 2, "{:?}", s.warnings);
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("materials[1]") && w.contains("clearcoatFactor is malformed"))
    );
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("materials[2]") && w.contains("clearcoatTexture names no texture"))
    );
}

/// A clear coat adds its own highlight over the base, as the extension's formula says: a
/// black rough dielectric lit and seen along its normal reflects `F D G / 4` of its GGX lobe
/// (f0 0.04, width 1); coated (factor 1, roughness 1) that much less the coat's Fresnel (4%),
/// plus the coat's own `0.04 D(1) / 4`: 1.96 times as bright. Fails with the coat left out
/// (1x), or with the base not dimmed under it (2x: the tolerance is 0.5%).
#[test]
fn a_clear_coat_adds_its_highlight_over_the_base() {
    let dir = tempfile::tempdir().unwrap();
    let black = json!({"pbrMetallicRoughness": {"baseColorFactor": [0.0, 0.0, 0.0, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0}});
    let mut coated = black.clone();
    coated["extensions"] = json!({"KHR_materials_clearcoat": {"clearcoatFactor": 1.0, "clearcoatRoughnessFactor": 1.0}});
    let plain = pbr_quad(dir.path(), "plain.gltf", black, None, None);
    let coat = pbr_quad(dir.path(), "coated.gltf", coated, None, None);
    let centre = |s: &Scene| centre_pixel(s, 100.0, tracery::scene::Environment::None).x;
    // Irradiance 100 / 5^2; GGX D at the normal is 1 / (pi a^2), G 1, Fresnel 0.04.
    let d = |a: f32| 1.0 / (std::f32::consts::PI * a * a);
    let base = 0.04 * d(1.0) / 4.0;
    let want_plain = 4.0 * base;
    let want_coated = 4.0 * (base * 0.96 + 0.04 * d(1.0) / 4.0);
    let (p, c) = (centre(&plain), centre(&coat));
    assert!(
        (p / want_plain - 1.0).abs() < 0.015,
        "plain {p}, want {want_plain}"
    );
    assert!(
        (c / want_coated - 1.0).abs() < 0.015,
        "coated {c}, want {want_coated}"
    );
}

/// A mesh that many nodes place, unskinned and unmorphed, is held once: each node a
/// placement (mirrored ones keep their front faces front, nodes that scale it to nothing are
/// left out), its triangles where the nodes' transforms put them; a mesh one node places
/// stays among the scene's own triangles.
#[test]
fn a_mesh_many_nodes_place_is_held_once() {
    let dir = tempfile::tempdir().unwrap();
    let mut nodes: Vec<Value> = (0..400)
        .map(|i| json!({"mesh": 0, "translation": [(i % 20) as f64 * 2.0, (i / 20) as f64 * 2.0, 0.0]}))
        .collect();
    nodes.push(json!({"mesh": 0, "scale": [-1.0, 1.0, 1.0], "translation": [0.0, 0.0, 5.0]}));
    nodes.push(json!({"mesh": 0, "scale": [0.0, 0.0, 0.0]}));
    nodes.push(json!({"mesh": 1, "translation": [0.0, 0.0, -3.0]}));
    let mut d = doc(Value::Array(nodes), json!({}));
    let prim = d["meshes"][0].clone();
    d["meshes"] = json!([prim, prim]);
    let p = write(dir.path(), "forest.gltf", &d);
    let s = Scene::load(&p).unwrap();
    assert_eq!(s.instances.meshes.len(), 1, "mesh 0 held once");
    assert_eq!(
        s.instances.placements().len(),
        401,
        "the zero scale left out"
    );
    assert_eq!(
        s.mesh.triangles.len(),
        1,
        "mesh 1, placed once, is the scene's own"
    );
    assert_eq!(s.triangle_count(), 402);
    let at = |prim: u32| {
        s.triangle(prim)
            .map(|v| (s.mesh.origin + v.as_dvec3()).as_vec3())
    };
    for (k, prim) in [(0u32, 1u32), (57, 58), (399, 400)] {
        let o = Vec3::new((k % 20) as f32 * 2.0, (k / 20) as f32 * 2.0, 0.0);
        let want = [o, o + Vec3::X, o + Vec3::Y];
        let got = at(prim);
        assert!(
            got.iter().zip(&want).all(|(a, b)| close(*a, *b)),
            "{k}: {got:?}"
        );
        assert!(close(face_normal(&got), Vec3::Z));
    }
    // The mirrored node: corners 1 and 2 swapped back, facing +z, its texture coordinates
    // following their corners.
    let m = at(401);
    let o = Vec3::new(0.0, 0.0, 5.0);
    assert!(
        close(m[0], o) && close(m[1], o + Vec3::Y) && close(m[2], o - Vec3::X),
        "{m:?}"
    );
    assert!(close(face_normal(&m), Vec3::Z));
    assert!(s.normals(401).iter().all(|n| close(*n, Vec3::Z)));
    assert_eq!(s.uv_at(0, 401, 1.0, 0.0), Vec2::new(0.0, 1.0));
    // Rendered through two levels, the picture of its copies flattened.
    let accel = tracery::bvh::Accel::for_scene(&s, &BuildOptions::sah()).unwrap();
    let flat = s.flattened();
    let settings = tracery::render::RenderSettings {
        width: 48,
        height: 36,
        spp: 4,
        ..Default::default()
    };
    let a = tracery::render::render(&s, &accel, &settings, &|_| {})
        .unwrap()
        .film
        .mean();
    let bvh = Bvh::build(&flat.mesh.triangles, &BuildOptions::sah());
    let b = tracery::render::render(&flat, &bvh, &settings, &|_| {})
        .unwrap()
        .film
        .mean();
    let diff: f32 = a
        .iter()
        .zip(&b)
        .map(|(p, q)| (*p - *q).abs().element_sum())
        .sum();
    let total: f32 = b.iter().map(|p| p.element_sum()).sum();
    assert!(total > 0.0 && diff <= 1e-3 * total, "{diff} of {total}");
}
