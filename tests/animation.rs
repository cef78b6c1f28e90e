//! glTF animations played to a given time: vertex positions checked against values computed
//! by hand from the files' keyframes (two files of the fetched corpus: morph weights and a
//! skin), the three interpolations on small files written here, and bad keyframes refused.

mod common;

use common::{data_uri, f32_bytes};

use std::path::{Path, PathBuf};

use base64::Engine as _;
use glam::{DMat4, DQuat, DVec3, DVec4};
use serde_json::{Value, json};
use tracery::scene::Scene;

fn write(dir: &Path, name: &str, json: &Value) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, serde_json::to_vec_pretty(json).unwrap()).unwrap();
    p
}

/// World position of corner `c` of triangle `i` of a loaded scene.
fn corner(s: &Scene, i: usize, c: usize) -> DVec3 {
    s.mesh.origin + s.mesh.triangles[i][c].as_dvec3()
}

/// A file's accessor `index` read directly from its JSON and buffers (float and unsigned
/// short components), as flat numbers: the test's own reading, independent of the loader.
fn accessor(file: &Path, gltf: &Value, index: usize) -> Vec<f64> {
    let acc = &gltf["accessors"][index];
    let view = &gltf["bufferViews"][acc["bufferView"].as_u64().unwrap() as usize];
    let buffer = &gltf["buffers"][view["buffer"].as_u64().unwrap() as usize];
    let uri = buffer["uri"].as_str().unwrap();
    let bytes = match uri.split_once(";base64,") {
        Some((_, b64)) => base64::engine::general_purpose::STANDARD
            .decode(b64)
            .unwrap(),
        None => std::fs::read(file.with_file_name(uri)).unwrap(),
    };
    let n = match acc["type"].as_str().unwrap() {
        "SCALAR" => 1,
        "VEC3" => 3,
        "VEC4" => 4,
        "MAT4" => 16,
        t => panic!("type {t}"),
    };
    let size = match acc["componentType"].as_u64().unwrap() {
        5126 => 4,
        5123 => 2,
        t => panic!("component type {t}"),
    };
    let stride = view["byteStride"].as_u64().map_or(n * size, |s| s as usize);
    let start = view["byteOffset"].as_u64().unwrap_or(0) as usize
        + acc["byteOffset"].as_u64().unwrap_or(0) as usize;
    let count = acc["count"].as_u64().unwrap() as usize;
    let mut out = Vec::new();
    for e in 0..count {
        for k in 0..n {
            let at = start + e * stride + k * size;
            out.push(match size {
                4 => f64::from(f32::from_le_bytes(bytes[at..at + 4].try_into().unwrap())),
                _ => f64::from(u16::from_le_bytes(bytes[at..at + 2].try_into().unwrap())),
            });
        }
    }
    out
}

/// The keyframe interval around `t`: `(k, s)` with `times[k] <= t < times[k + 1]` and `s`
/// the fraction of the interval at `t`.
fn interval(times: &[f64], t: f64) -> (usize, f64) {
    let k = times.iter().rposition(|&x| x <= t).unwrap();
    (k, (t - times[k]) / (times[k + 1] - times[k]))
}

/// The morph cube's weights animation, at a time between two keyframes: every corner of
/// every triangle is where the node's transform puts the base position plus the two targets'
/// displacements at the weights interpolated linearly between the keyframes.
#[test]
fn morph_weights_play_to_a_time_between_keyframes() {
    let Some(p) =
        common::external("gltf/glTF-Sample-Models/AnimatedMorphCube-glTF/AnimatedMorphCube.gltf")
    else {
        return;
    };
    let gltf: Value = serde_json::from_slice(&std::fs::read(&p).unwrap()).unwrap();
    let times = accessor(&p, &gltf, 10);
    let weights = accessor(&p, &gltf, 11);
    let t = 0.3 * times[40] + 0.7 * times[41];
    let (k, s) = interval(&times, t);
    assert_eq!(k, 40);
    let w: Vec<f64> = (0..2)
        .map(|j| weights[2 * k + j] * (1.0 - s) + weights[2 * (k + 1) + j] * s)
        .collect();
    assert!(
        w.iter().any(|&w| w > 0.01),
        "a time where the cube is morphed: {w:?}"
    );
    let (base, t0, t1) = (
        accessor(&p, &gltf, 2),
        accessor(&p, &gltf, 4),
        accessor(&p, &gltf, 7),
    );
    let indices = accessor(&p, &gltf, 9);
    let node = &gltf["nodes"][0];
    let r: Vec<f64> = node["rotation"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    let sc = node["scale"][0].as_f64().unwrap();
    let m = DMat4::from_scale_rotation_translation(
        DVec3::splat(sc),
        DQuat::from_xyzw(r[0], r[1], r[2], r[3]).normalize(),
        DVec3::ZERO,
    );
    let s_at = Scene::load_at(&p, Some(t)).unwrap();
    let rest = Scene::load(&p).unwrap();
    assert_eq!(s_at.mesh.triangles.len(), indices.len() / 3);
    let mut moved = 0.0f64;
    for (i, tri) in indices.chunks(3).enumerate() {
        for (c, &v) in tri.iter().enumerate() {
            let v = v as usize;
            let local = DVec3::from_slice(&base[3 * v..])
                + w[0] * DVec3::from_slice(&t0[3 * v..])
                + w[1] * DVec3::from_slice(&t1[3 * v..]);
            let want = m.transform_point3(local);
            let got = corner(&s_at, i, c);
            assert!(
                (got - want).length() < 1e-4,
                "triangle {i} corner {c}: {got} against {want} by hand"
            );
            moved = moved.max((got - corner(&rest, i, c)).length());
        }
    }
    assert!(moved > 0.1, "the morph moves the cube's corners ({moved})");
}

/// Spherical linear interpolation written out: along the shorter arc between unit
/// quaternions `a` and `b`.
fn slerp(a: DVec4, b: DVec4, s: f64) -> DVec4 {
    let (a, mut b) = (a.normalize(), b.normalize());
    let mut d = a.dot(b);
    if d < 0.0 {
        b = -b;
        d = -d;
    }
    if d > 0.9995 {
        return (a + (b - a) * s).normalize();
    }
    let theta = d.acos();
    (a * ((1.0 - s) * theta).sin() + b * (s * theta).sin()) / theta.sin()
}

/// The simple skin's joint rotation at a time between two keyframes: every corner is its
/// vertex moved by the two joints' matrices (joint world transform times inverse bind
/// matrix) blended by its weights, the animated joint's rotation slerped by hand.
#[test]
fn a_skin_follows_its_animated_joint_between_keyframes() {
    let Some(p) = common::external("gltf/simple_skin/simple_skin.gltf") else {
        return;
    };
    let gltf: Value = serde_json::from_slice(&std::fs::read(&p).unwrap()).unwrap();
    let times = accessor(&p, &gltf, 5);
    let rotations = accessor(&p, &gltf, 6);
    let t = 0.25 * times[1] + 0.75 * times[2];
    let (k, s) = interval(&times, t);
    let q = slerp(
        DVec4::from_slice(&rotations[4 * k..]),
        DVec4::from_slice(&rotations[4 * (k + 1)..]),
        s,
    );
    let q = DQuat::from_xyzw(q.x, q.y, q.z, q.w);
    assert!(
        q.angle_between(DQuat::IDENTITY) > 0.1,
        "the joint is turned: {q:?}"
    );
    // Node 0 (the skinned mesh, identity) -> node 1 (translation) -> node 2 (animated).
    let t1 = DVec3::from_slice(
        &gltf["nodes"][1]["translation"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect::<Vec<_>>(),
    );
    let world1 = DMat4::from_translation(t1);
    let world2 = world1 * DMat4::from_quat(q);
    let ib = accessor(&p, &gltf, 4);
    let joints_m = [
        world1 * DMat4::from_cols_slice(&ib[0..16]),
        world2 * DMat4::from_cols_slice(&ib[16..32]),
    ];
    let (positions, joints, weights) = (
        accessor(&p, &gltf, 1),
        accessor(&p, &gltf, 2),
        accessor(&p, &gltf, 3),
    );
    let indices = accessor(&p, &gltf, 0);
    let s_at = Scene::load_at(&p, Some(t)).unwrap();
    for (i, tri) in indices.chunks(3).enumerate() {
        for (c, &v) in tri.iter().enumerate() {
            let v = v as usize;
            let (mut m, mut sum) = (DMat4::ZERO, 0.0);
            for j in 0..4 {
                let w = weights[4 * v + j];
                if w > 0.0 {
                    m += joints_m[joints[4 * v + j] as usize] * w;
                    sum += w;
                }
            }
            let want = (m * (1.0 / sum)).transform_point3(DVec3::from_slice(&positions[3 * v..]));
            let got = corner(&s_at, i, c);
            assert!(
                (got - want).length() < 1e-5,
                "triangle {i} corner {c}: {got} against {want} by hand"
            );
        }
    }
}

/// One triangle under a parent node: `animations` and `samplers` index the buffer's
/// accessors 3 onward (`times` then `values`, per sampler).
fn animated(channels: Value, samplers: &[(&[f32], &[f32], &str, &str)]) -> Value {
    let mut bin = f32_bytes(&[0., 0., 0., 1., 0., 0., 0., 1., 0.]);
    bin.extend(f32_bytes(&[0., 0., 1., 0., 0., 1., 0., 0., 1.]));
    bin.extend([0u16, 1, 2, 0].iter().flat_map(|i| i.to_le_bytes()));
    let mut views = vec![
        json!({"buffer": 0, "byteOffset": 0, "byteLength": 36}),
        json!({"buffer": 0, "byteOffset": 36, "byteLength": 36}),
        json!({"buffer": 0, "byteOffset": 72, "byteLength": 6}),
    ];
    let mut accessors = vec![
        json!({"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}),
        json!({"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC3"}),
        json!({"bufferView": 2, "componentType": 5123, "count": 3, "type": "SCALAR"}),
    ];
    let mut json_samplers = Vec::new();
    for (times, values, ty, interpolation) in samplers {
        let n = match *ty {
            "VEC3" => 3,
            "VEC4" => 4,
            _ => 1,
        };
        for (data, ty, count) in [
            (*times, "SCALAR", times.len()),
            (*values, *ty, values.len() / n),
        ] {
            views.push(json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": 4 * data.len()}));
            accessors.push(json!({"bufferView": views.len() - 1, "componentType": 5126,
                "count": count, "type": ty}));
            bin.extend(f32_bytes(data));
        }
        json_samplers.push(
            json!({"input": accessors.len() - 2, "output": accessors.len() - 1,
            "interpolation": interpolation}),
        );
    }
    json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"children": [1]}, {"mesh": 0, "translation": [0.0, 0.0, 5.0]}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1}, "indices": 2}]}],
        "buffers": [{"byteLength": bin.len(), "uri": data_uri(&bin)}],
        "bufferViews": views,
        "accessors": accessors,
        "animations": [{"channels": channels, "samplers": json_samplers}]
    })
}

/// Step and cubic-spline translations, and a linear rotation of the parent, at times before,
/// between and after the keyframes, against the values worked out by hand.
#[test]
fn the_three_interpolations_place_nodes_as_worked_out_by_hand() {
    let dir = tempfile::tempdir().unwrap();
    // Step: the child's translation is (0,0,5) from the node until t = 1, then (0,2,5) at
    // t = 1 and (0,4,5) from t = 3.
    let step = animated(
        json!([{"sampler": 0, "target": {"node": 1, "path": "translation"}}]),
        &[(&[1.0, 3.0], &[0., 2., 5., 0., 4., 5.], "VEC3", "STEP")],
    );
    let p = write(dir.path(), "step.gltf", &step);
    let at = |t: f64| corner(&Scene::load_at(&p, Some(t)).unwrap(), 0, 1);
    // Before the first keyframe the first value holds.
    assert!((at(0.0) - DVec3::new(1.0, 2.0, 5.0)).length() < 1e-9);
    assert!((at(2.9) - DVec3::new(1.0, 2.0, 5.0)).length() < 1e-9);
    assert!((at(3.0) - DVec3::new(1.0, 4.0, 5.0)).length() < 1e-9);
    assert!((at(9.0) - DVec3::new(1.0, 4.0, 5.0)).length() < 1e-9);

    // Cubic spline on x: keyframes at t = 0 and 2 with (in, value, out) tangents; at t = 0.5
    // the Hermite basis with s = 1/4 and the tangents scaled by the interval (2).
    let cubic = animated(
        json!([{"sampler": 0, "target": {"node": 1, "path": "translation"}}]),
        &[(
            &[0.0, 2.0],
            &[
                9., 0., 0., 1., 0., 0., 0.5, 0., 0., //
                -1., 0., 0., 3., 0., 0., 7., 0., 0.,
            ],
            "VEC3",
            "CUBICSPLINE",
        )],
    );
    let p = write(dir.path(), "cubic.gltf", &cubic);
    let s: f64 = 0.25;
    let x = (2.0 * s.powi(3) - 3.0 * s * s + 1.0) * 1.0
        + (s.powi(3) - 2.0 * s * s + s) * 2.0 * 0.5
        + (-2.0 * s.powi(3) + 3.0 * s * s) * 3.0
        - (s.powi(3) - s * s) * 2.0;
    let got = corner(&Scene::load_at(&p, Some(0.5)).unwrap(), 0, 1);
    // Corner 1 is the vertex (1, 0, 0): the translation's x plus one.
    assert!(
        (got - DVec3::new(x + 1.0, 0.0, 0.0)).length() < 1e-6,
        "{got} against x = {x}"
    );

    // Linear rotation of the parent from none to a quarter turn about z over one second: at
    // t = 0.25 a sixteenth of a turn (spherical interpolation: a normalised linear one would
    // turn it further), carrying the child (at z = 5) with it.
    let h = std::f32::consts::FRAC_1_SQRT_2;
    let turn = animated(
        json!([{"sampler": 0, "target": {"node": 0, "path": "rotation"}}]),
        &[(
            &[0.0, 1.0],
            &[0., 0., 0., 1., 0., 0., h, h],
            "VEC4",
            "LINEAR",
        )],
    );
    let p = write(dir.path(), "turn.gltf", &turn);
    let got = corner(&Scene::load_at(&p, Some(0.25)).unwrap(), 0, 1);
    let a = std::f64::consts::FRAC_PI_8;
    assert!(
        (got - DVec3::new(a.cos(), a.sin(), 5.0)).length() < 1e-6,
        "{got}"
    );
}

/// Without a time the file stands as its nodes place it, with a warning saying so; a time
/// given to a file without animations is said to change nothing.
#[test]
fn a_time_is_needed_to_play_and_is_said_when_there_is_nothing_to_play() {
    let dir = tempfile::tempdir().unwrap();
    let d = animated(
        json!([{"sampler": 0, "target": {"node": 1, "path": "translation"}}]),
        &[(&[1.0, 3.0], &[0., 2., 5., 0., 4., 5.], "VEC3", "LINEAR")],
    );
    let p = write(dir.path(), "a.gltf", &d);
    let s = Scene::load(&p).unwrap();
    assert!(
        s.warnings.iter().any(|w| w.contains("not played")),
        "{:?}",
        s.warnings
    );
    // The length of the animation is known without playing it (the last keyframe).
    assert_eq!(s.animation, Some(3.0));
    assert_eq!(Scene::load_at(&p, Some(0.5)).unwrap().animation, Some(3.0));
    assert!((corner(&s, 0, 1) - DVec3::new(1.0, 0.0, 5.0)).length() < 1e-9);
    let mut still = d.clone();
    still.as_object_mut().unwrap().remove("animations");
    let p = write(dir.path(), "still.gltf", &still);
    let s = Scene::load_at(&p, Some(1.0)).unwrap();
    assert!(
        s.warnings.iter().any(|w| w.contains("has no animation")),
        "{:?}",
        s.warnings
    );
    assert_eq!(s.animation, None);
}

/// A file without a camera is framed at rest, so every instant of its animation is seen from
/// the same place.
#[test]
fn every_instant_is_seen_from_one_place() {
    let dir = tempfile::tempdir().unwrap();
    let d = animated(
        json!([{"sampler": 0, "target": {"node": 1, "path": "translation"}}]),
        &[(&[0.0, 1.0], &[0., 0., 0., 0., 40., 5.], "VEC3", "LINEAR")],
    );
    let p = write(dir.path(), "a.gltf", &d);
    let (a, b) = (
        Scene::load_at(&p, Some(0.0)).unwrap(),
        Scene::load_at(&p, Some(1.0)).unwrap(),
    );
    let world = |s: &Scene| s.mesh.origin + s.camera.position.as_dvec3();
    assert!((world(&a) - world(&b)).length() < 1e-4);
    assert_ne!(corner(&a, 0, 0), corner(&b, 0, 0));
}

/// Keyframe times that do not increase, and too few output values, are refused with the
/// file and the channel named.
#[test]
fn bad_keyframes_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let d = animated(
        json!([{"sampler": 0, "target": {"node": 1, "path": "translation"}}]),
        &[(&[1.0, 1.0], &[0., 2., 5., 0., 4., 5.], "VEC3", "LINEAR")],
    );
    let p = write(dir.path(), "same.gltf", &d);
    let e = format!("{:#}", Scene::load_at(&p, Some(0.5)).unwrap_err());
    assert!(
        e.contains("same.gltf")
            && e.contains("animations[0].channels[0]")
            && e.contains("increase"),
        "{e}"
    );
    let d = animated(
        json!([{"sampler": 0, "target": {"node": 1, "path": "translation"}}]),
        &[(
            &[1.0, 2.0, 3.0],
            &[0., 2., 5., 0., 4., 5.],
            "VEC3",
            "CUBICSPLINE",
        )],
    );
    let p = write(dir.path(), "short.gltf", &d);
    let e = format!("{:#}", Scene::load_at(&p, Some(0.5)).unwrap_err());
    assert!(
        e.contains("short.gltf") && e.contains("need 27 output value(s)"),
        "{e}"
    );
}
