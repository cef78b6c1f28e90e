//! Scene loading: OBJ with MTL, PLY (ASCII and binary), scene files, the Cornell box, and the
//! errors bad files give.

mod common;

use std::path::{Path, PathBuf};

use glam::Vec3;
use tracery::scene::{Environment, Light, Scene};

fn write(dir: &Path, name: &str, text: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

fn err(r: anyhow::Result<Scene>) -> String {
    format!("{:#}", r.expect_err("an error"))
}

/// Each case's scene (`text` with `from` replaced by `to`, written as `bad.toml` into `dir`)
/// fails to load with an error naming `bad.toml` and the case's line.
fn assert_errors_at(dir: &Path, text: &str, cases: &[(&str, &str, usize)]) {
    for (from, to, line) in cases {
        let p = write(dir, "bad.toml", text.replace(from, to).as_bytes());
        let e = err(Scene::load(&p));
        assert!(e.contains(&format!("bad.toml:{line}")), "{to}: {e}");
    }
}

#[test]
fn cornell_box_has_32_triangles_its_materials_and_light() {
    let s = Scene::cornell_box();
    assert_eq!(s.triangle_count(), 32);
    let names: Vec<&str> = s.materials.iter().map(|m| m.name.as_str()).collect();
    for m in ["white", "red", "green", "light"] {
        assert!(names.contains(&m), "{names:?}");
    }
    assert!(s.materials.iter().any(|m| m.is_emissive()));
    assert!(matches!(s.lights.as_slice(), [Light::Rect { .. }]));
    // The on-disk scene file is the same scene.
    let disk = Scene::load(Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/assets/scenes/cornell_box.toml"
    )))
    .unwrap();
    assert_eq!(disk.mesh, s.mesh);
    assert_eq!(disk.lights, s.lights);
}

#[test]
fn obj_polygons_are_fan_triangulated_with_negative_indices_and_computed_normals() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(
        dir.path(),
        "quad.obj",
        b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\n# a pentagon-ish polygon with relative indices\nf -5 -4 -3 -2\nf 1 2 5\n",
    );
    let s = Scene::load(&p).unwrap();
    assert_eq!(s.triangle_count(), 3);
    let t = &s.mesh.triangles;
    assert_eq!(t[0], [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0)]);
    assert_eq!(t[1], [Vec3::ZERO, Vec3::new(1.0, 1.0, 0.0), Vec3::Y]);
    // Without normals or smoothing groups in the file, every face is flat.
    for (t, n) in s.mesh.triangles.iter().zip(&s.mesh.normals) {
        assert_eq!(*n, [tracery::scene::face_normal(t); 3]);
    }
    assert_eq!(s.mesh.normals[0], [Vec3::Z; 3]);
}

/// A unit cube's six faces as OBJ quads sharing its eight corners, after `header`.
fn cube_obj(header: &str) -> String {
    let mut text = String::from(header);
    for v in [
        [0, 0, 0],
        [1, 0, 0],
        [1, 1, 0],
        [0, 1, 0],
        [0, 0, 1],
        [1, 0, 1],
        [1, 1, 1],
        [0, 1, 1],
    ] {
        text += &format!("v {} {} {}\n", v[0], v[1], v[2]);
    }
    for f in [
        "1 4 3 2", "5 6 7 8", "1 2 6 5", "4 8 7 3", "1 5 8 4", "2 3 7 6",
    ] {
        text += &format!("f {f}\n");
    }
    text
}

/// True when every corner's normal is its face's (to rounding: scene files transform normals).
fn all_flat(s: &Scene) -> bool {
    s.mesh.triangles.iter().zip(&s.mesh.normals).all(|(t, n)| {
        let f = tracery::scene::face_normal(t);
        n.iter().all(|c| (*c - f).length() < 1e-6)
    })
}

#[test]
fn obj_faces_are_flat_unless_a_smoothing_group_asks() {
    let dir = tempfile::tempdir().unwrap();
    // No `s`, `s off`, `s 0`: a box keeps its edges.
    for header in ["", "s off\n", "s 0\n"] {
        let s = Scene::load(&write(dir.path(), "c.obj", cube_obj(header).as_bytes())).unwrap();
        assert_eq!(s.triangle_count(), 12);
        assert!(all_flat(&s), "header {header:?}");
    }
    // `s 1`: the corners average the three faces that meet there.
    let s = Scene::load(&write(dir.path(), "c.obj", cube_obj("s 1\n").as_bytes())).unwrap();
    let corner = s.mesh.normals[0][0];
    assert!(
        (corner - Vec3::splat(-1.0).normalize()).length() < 1e-5,
        "{corner}"
    );
    assert!(!all_flat(&s));
    // A group switched off half way: the faces after `s off` are flat again.
    let mut text = cube_obj("s 1\n");
    let cut = text.match_indices("f ").nth(3).unwrap().0;
    text.insert_str(cut, "s off\n");
    let s = Scene::load(&write(dir.path(), "c.obj", text.as_bytes())).unwrap();
    for (i, (t, n)) in s.mesh.triangles.iter().zip(&s.mesh.normals).enumerate() {
        let flat = [tracery::scene::face_normal(t); 3];
        assert_eq!(*n == flat, i >= 6, "triangle {i}");
    }
}

#[test]
fn ply_without_normals_keeps_edges_above_the_crease_angle() {
    // A box edge (90 degrees) stays sharp; a fold of 10 degrees is smoothed.
    let fold = |deg: f32| {
        let (s, c) = deg.to_radians().sin_cos();
        format!(
            "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n0 1 0\n-1 0 0\n{c} 0 {s}\n3 0 1 2\n3 0 3 1\n"
        )
    };
    let dir = tempfile::tempdir().unwrap();
    let s = Scene::load(&write(dir.path(), "box.ply", fold(90.0).as_bytes())).unwrap();
    assert!(all_flat(&s));
    let s = Scene::load(&write(dir.path(), "fold.ply", fold(10.0).as_bytes())).unwrap();
    assert!(!all_flat(&s));
    // The shared edge's corners agree on both faces.
    assert_eq!(s.mesh.normals[0][0], s.mesh.normals[1][0]);
    assert_eq!(s.mesh.normals[0][1], s.mesh.normals[1][2]);
    // A scene file's crease angle overrides the rule either way.
    write(dir.path(), "box.ply", fold(90.0).as_bytes());
    let scene = |angle: f32| {
        let toml = format!("[[meshes]]\npath = \"box.ply\"\ncrease_angle = {angle:?}\n");
        Scene::load(&write(dir.path(), "s.toml", toml.as_bytes())).unwrap()
    };
    assert!(!all_flat(&scene(120.0)));
    assert!(all_flat(&scene(0.0)));
    let toml = "[[meshes]]\npath = \"box.ply\"\ncrease_angle = 200.0\n";
    let e = err(Scene::load(&write(dir.path(), "s.toml", toml.as_bytes())));
    assert!(e.contains("s.toml:3") && e.contains("crease_angle"), "{e}");
}

#[test]
fn cornell_box_faces_are_flat() {
    // Its OBJ has no normals and no smoothing groups: the blocks keep their edges.
    assert!(all_flat(&Scene::cornell_box()));
}

#[test]
fn obj_mtl_fields_become_materials() {
    let dir = tempfile::tempdir().unwrap();
    write(
        dir.path(),
        "m.mtl",
        b"newmtl glass\nKd 0.1 0.2 0.3\nKs 0.5 0.5 0.5\nNs 64\nTr 0.75\nNi 1.5\nillum 7\nnewmtl lamp\nKe 4 3 2\nd 1\nillum 2\n",
    );
    let p = write(
        dir.path(),
        "m.obj",
        b"mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl glass\nf 1 2 3\nusemtl lamp\nf 1 3 2\n",
    );
    let s = Scene::load(&p).unwrap();
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    let glass = s.material_of(0);
    assert_eq!(glass.name, "glass");
    assert_eq!(glass.diffuse, Vec3::new(0.1, 0.2, 0.3));
    assert_eq!(glass.specular, Vec3::splat(0.5));
    assert_eq!(glass.shininess, 64.0);
    assert!((glass.opacity - 0.25).abs() < 1e-6);
    assert_eq!(glass.ior, 1.5);
    assert_eq!(glass.illum, 7);
    assert_eq!(glass.mirror, Vec3::splat(0.5), "illum 7 reflects with Ks");
    let lamp = s.material_of(1);
    assert_eq!(lamp.emission, Vec3::new(4.0, 3.0, 2.0));
    assert!(!lamp.is_mirror() && !lamp.is_transparent());
}

#[test]
fn obj_with_a_missing_mtl_loads_with_a_warning() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(
        dir.path(),
        "a.obj",
        b"mtllib nowhere.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    );
    let s = Scene::load(&p).unwrap();
    assert_eq!(s.triangle_count(), 1);
    assert!(s.warnings[0].contains("nowhere.mtl"), "{:?}", s.warnings);
}

#[test]
fn obj_errors_name_the_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(
        dir.path(),
        "bad.obj",
        b"v 0 0 0\nv 1 0 0\nv 0 one 0\nf 1 2 3\n",
    );
    let e = err(Scene::load(&p));
    assert!(e.contains("bad.obj:3"), "{e}");
    let p = write(
        dir.path(),
        "range.obj",
        b"v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 1 2 9\n",
    );
    let e = err(Scene::load(&p));
    assert!(e.contains("range.obj:5") && e.contains("9"), "{e}");
    let e = err(Scene::load(&dir.path().join("missing.obj")));
    assert!(e.contains("missing.obj"), "{e}");
}

const PLY_ASCII: &str = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n";

#[test]
fn ply_ascii_loads_and_fan_triangulates() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(dir.path(), "q.ply", PLY_ASCII.as_bytes());
    let s = Scene::load(&p).unwrap();
    assert_eq!(s.triangle_count(), 2);
    assert_eq!(
        s.mesh.triangles[1],
        [Vec3::ZERO, Vec3::new(1.0, 1.0, 0.0), Vec3::Y]
    );
}

#[test]
fn ply_binary_little_endian_with_doubles_and_normals_loads() {
    let mut data = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty double x\nproperty double y\nproperty double z\nproperty float nx\nproperty float ny\nproperty float nz\nelement face 1\nproperty list uchar uint vertex_indices\nend_header\n".to_vec();
    for v in [[0.0f64, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 2.0, 0.0]] {
        for c in v {
            data.extend(c.to_le_bytes());
        }
        for c in [0.0f32, 0.0, 1.0] {
            data.extend(c.to_le_bytes());
        }
    }
    data.push(3);
    for i in [0u32, 1, 2] {
        data.extend(i.to_le_bytes());
    }
    let dir = tempfile::tempdir().unwrap();
    let p = write(dir.path(), "b.ply", &data);
    let s = Scene::load(&p).unwrap();
    assert_eq!(
        s.mesh.triangles,
        vec![[
            Vec3::ZERO,
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(0.0, 2.0, 0.0)
        ]]
    );
    assert_eq!(s.mesh.normals[0], [Vec3::Z; 3]);
}

#[test]
fn ply_errors_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let bad = PLY_ASCII.replace("4 0 1 2 3", "3 0 1 7");
    let e = err(Scene::load(&write(dir.path(), "r.ply", bad.as_bytes())));
    assert!(e.contains("r.ply") && e.contains("7"), "{e}");
    let bad = PLY_ASCII.replace("1 1 0\n", "1 x 0\n");
    let e = err(Scene::load(&write(dir.path(), "p.ply", bad.as_bytes())));
    assert!(e.contains("p.ply:12"), "{e}");
    // One line, the faulty text quoted, no parser dump, no position that reads as line 1.
    assert!(!e.contains('\n') && e.contains("\"1 x 0\""), "{e}");
    assert!(!e.contains("ParseError") && !e.contains("1:"), "{e}");
}

/// A count the bytes after the header cannot hold is refused before any record is read, and
/// binary elements without properties (records of no bytes) are not read at all: the parser
/// pushed one empty record per count, and a mutant with four billion such faces filled memory
/// until CI's mutation test was killed.
#[test]
fn a_ply_count_the_file_cannot_hold_is_refused_up_front() {
    let dir = tempfile::tempdir().unwrap();
    let binary = |vertices: u32, faces: &str| {
        let mut d = format!("ply\nformat binary_little_endian 1.0\nelement vertex {vertices}\nproperty float x\nproperty float y\nproperty float z\nelement face {faces}\nend_header\n").into_bytes();
        for c in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
            d.extend(c.to_le_bytes());
        }
        d
    };
    // Faces without properties: no bytes per record, none read, no triangles.
    for faces in ["2", "4000000000"] {
        let s = Scene::load(&write(dir.path(), "empty_faces.ply", &binary(3, faces))).unwrap();
        assert_eq!(s.triangle_count(), 0);
    }
    // Vertices the payload cannot hold: 1000 records of 12 bytes in 36 bytes.
    let e = err(Scene::load(&write(
        dir.path(),
        "short.ply",
        &binary(1000, "0"),
    )));
    assert!(
        e.contains("short.ply") && e.contains("end of file before the 1000 `vertex` records"),
        "{e}"
    );
    // The same in ASCII: a line (at least a byte) per record.
    let ascii = PLY_ASCII.replace("element face 1", "element face 4000000000");
    let e = err(Scene::load(&write(dir.path(), "a.ply", ascii.as_bytes())));
    assert!(e.contains("a.ply") && e.contains("`face` records"), "{e}");
}

/// Blender 2.4 wrote a header line that is not a PLY keyword (`Blender 2.4 export`); assimp
/// reads such files, and so does tracery (the line counts as a comment).
#[test]
fn a_ply_header_line_without_a_keyword_is_read_as_a_comment() {
    let dir = tempfile::tempdir().unwrap();
    let blender = PLY_ASCII.replace(
        "format ascii 1.0\n",
        "format ascii 1.0\nBlender 2.4 export\n",
    );
    let s = Scene::load(&write(dir.path(), "b.ply", blender.as_bytes())).unwrap();
    assert_eq!(s.triangle_count(), 2);
    // Line numbers stay those of the file.
    let bad = blender.replace("1 1 0\n", "1 x 0\n");
    let e = err(Scene::load(&write(dir.path(), "bb.ply", bad.as_bytes())));
    assert!(e.contains("bb.ply:13"), "{e}");
}

#[test]
fn fetched_meshes_load_as_fetched() {
    if let Some(p) = common::external("bunny/bunny.obj") {
        let s = Scene::load(&p).unwrap();
        assert_eq!(s.triangle_count(), 69_666);
    }
    for (file, tris) in [
        ("dragon_vrip_res4.ply", 11_102),
        ("dragon_vrip_res3.ply", 47_794),
    ] {
        if let Some(p) = common::external(&format!("dragon/{file}")) {
            assert_eq!(Scene::load(&p).unwrap().triangle_count(), tris);
        }
    }
}

const SCENE: &str = r#"
[camera]
position = [0.0, 1.0, 5.0]
look_at = [0.0, 1.0, 0.0]
fov = 50.0

[materials.gold]
diffuse = [0.8, 0.6, 0.2]
mirror = [0.5, 0.5, 0.5]

[[meshes]]
path = "q.ply"
translate = [10.0, 0.0, 0.0]
scale = 2.0
material = "gold"

[[meshes]]
shape = "cube"

[[lights]]
kind = "point"
position = [0.0, 5.0, 0.0]
intensity = 20.0

[environment]
kind = "color"
color = [0.1, 0.2, 0.3]
"#;

#[test]
fn scene_file_resolves_paths_transforms_and_overrides() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "q.ply", PLY_ASCII.as_bytes());
    let p = write(dir.path(), "s.toml", SCENE.as_bytes());
    let s = Scene::load(&p).unwrap();
    assert_eq!(s.triangle_count(), 2 + 12);
    assert_eq!(s.mesh.triangles[0][1], Vec3::new(12.0, 0.0, 0.0));
    assert_eq!(s.material_of(0).name, "gold");
    assert_eq!(s.camera.vfov_deg, 50.0);
    assert_eq!(s.environment, Environment::Color(Vec3::new(0.1, 0.2, 0.3)));
    assert!(matches!(
        s.lights[0],
        Light::Point {
            intensity: 20.0,
            ..
        }
    ));
}

#[test]
fn scene_file_errors_name_the_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "q.ply", PLY_ASCII.as_bytes());
    let cases = [
        ("fov = 50.0", "fov = 50.0\nzoom = 2.0", "unknown field", 6),
        ("scale = 2.0", "scale = \"big\"", "", 14),
        (
            "path = \"q.ply\"",
            "path = \"nowhere.ply\"",
            "nowhere.ply",
            12,
        ),
        ("material = \"gold\"", "material = \"silver\"", "silver", 15),
        ("intensity = 20.0", "intensity = 2x", "", 23),
    ];
    for (from, to, what, line) in cases {
        let text = SCENE.replace(from, to);
        let p = write(dir.path(), "bad.toml", text.as_bytes());
        let e = err(Scene::load(&p));
        assert!(e.contains(&format!("bad.toml:{line}")), "{to}: {e}");
        assert!(e.contains(what), "{to}: {e}");
    }
}

#[test]
fn every_project_scene_loads_and_renders() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/scenes");
    let mut checked = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().and_then(|e| e.to_str()) != Some("toml") {
            continue;
        }
        let text = std::fs::read_to_string(&path).unwrap();
        let needs = text
            .split('"')
            .filter(|s| s.starts_with("../external/"))
            .map(|s| s.trim_start_matches("../external/").to_string())
            .collect::<Vec<_>>();
        if needs.iter().any(|n| common::external(n).is_none()) {
            continue;
        }
        let scene = Scene::load(&path).unwrap_or_else(|e| panic!("{}: {e:#}", path.display()));
        assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
        let bvh = tracery::bvh::Accel::for_scene(&scene, &Default::default()).unwrap();
        let settings = tracery::render::RenderSettings {
            width: 12,
            height: 9,
            spp: 2,
            ..Default::default()
        };
        let out = tracery::render::render(&scene, &bvh, &settings, &|_| {}).unwrap();
        assert_eq!(out.film.rejected, 0, "{}", path.display());
        assert!(out.film.mean().iter().all(|c| c.is_finite()));
        checked += 1;
    }
    assert!(checked >= 5, "only {checked} scenes checked");
}

#[test]
fn a_scene_file_without_an_environment_gets_the_procedural_sky() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(dir.path(), "bare.toml", b"[[meshes]]\nshape = \"cube\"\n");
    let s = Scene::load(&p).unwrap();
    assert!(
        matches!(s.environment, Environment::Sky { .. }),
        "{:?}",
        s.environment
    );
    let p = write(
        dir.path(),
        "dark.toml",
        b"[[meshes]]\nshape = \"cube\"\n[environment]\nkind = \"none\"\n",
    );
    assert_eq!(Scene::load(&p).unwrap().environment, Environment::None);
}

/// Spot lights in scene files: read with their cone (angles in degrees from the axis, the
/// direction normalized), and a cone that is not `0 <= inner < outer <= 90` or a zero
/// direction refused with the file and the light's line.
#[test]
fn scene_file_spot_lights() {
    use tracery::scene::Light;
    let good = r#"
[[meshes]]
shape = "quad"

[[lights]]
kind = "spot"
position = [0.0, 2.0, 0.0]
direction = [0.0, -3.0, 0.0]
inner_angle = 20.0
outer_angle = 30.0
intensity = 5.0
"#;
    let read = |p: &std::path::Path| -> anyhow::Result<Vec<u8>> {
        anyhow::bail!("{}: no files here", p.display())
    };
    let s =
        tracery::scene::file::parse(std::path::Path::new("spot.toml"), good, &read, false).unwrap();
    let Light::Spot {
        direction,
        cos_inner,
        cos_outer,
        intensity,
        ..
    } = s.lights[0]
    else {
        panic!("not a spot: {:?}", s.lights[0]);
    };
    assert!((direction - Vec3::NEG_Y).length() < 1e-6);
    assert!((cos_inner - 20f32.to_radians().cos()).abs() < 1e-6);
    assert!((cos_outer - 30f32.to_radians().cos()).abs() < 1e-6);
    assert_eq!(intensity, 5.0);
    for (bad, wants) in [
        (
            "inner_angle = 30.0\nouter_angle = 20.0",
            "0 <= inner < outer <= 90",
        ),
        ("outer_angle = 120.0", "0 <= inner < outer <= 90"),
        ("inner_angle = -5.0", "0 <= inner < outer <= 90"),
    ] {
        let text = good.replace("inner_angle = 20.0\nouter_angle = 30.0", bad);
        let e = tracery::scene::file::parse(std::path::Path::new("spot.toml"), &text, &read, false)
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("spot.toml:5:") && e.contains(wants),
            "{bad}: {e}"
        );
    }
    let text = good.replace("[0.0, -3.0, 0.0]", "[0.0, 0.0, 0.0]");
    let e = tracery::scene::file::parse(std::path::Path::new("spot.toml"), &text, &read, false)
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("spot.toml:5:") && e.contains("no length"),
        "{e}"
    );
}

/// An OBJ quad (2 x 2 about the origin in the xy plane, texture coordinates 0..1, `u` along
/// +x), no material.
const UV_QUAD_OBJ: &[u8] =
    b"v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n\
                             f 1/1 2/2 3/3\nf 1/1 3/3 4/4\n";

/// A scene file's material can name a normal map (`normal_map`, `normal_scale`): a mesh given
/// that material gets MikkTSpace's tangents, turned with the mesh's transform (an OBJ quad
/// whose `u` runs along +x, turned 90 degrees about z, has its tangents along +y); a shape
/// without texture coordinates keeps its normals, with a warning naming the line; a missing
/// image or a scale that is not a number is an error naming the file and line.
#[test]
fn scene_file_materials_can_name_a_normal_map() {
    let dir = tempfile::tempdir().unwrap();
    let img = image::RgbImage::from_raw(1, 1, vec![128, 218, 218]).unwrap();
    img.save(dir.path().join("n.png")).unwrap();
    write(dir.path(), "quad.obj", UV_QUAD_OBJ);
    let scene = |extra: &str| {
        format!(
            "[materials.bumpy]\ndiffuse = [0.8, 0.8, 0.8]\nnormal_map = \"n.png\"\nnormal_scale = 0.5\n\n\
             [[meshes]]\npath = \"quad.obj\"\nrotate = [0.0, 0.0, 90.0]\nmaterial = \"bumpy\"\n{extra}"
        )
    };
    let p = write(dir.path(), "s.toml", scene("").as_bytes());
    let s = Scene::load(&p).unwrap();
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    let m = s.material_of(0);
    assert!(
        m.normal_map.as_ref().is_some_and(|t| !t.srgb),
        "a linear map"
    );
    assert_eq!(m.normal_scale, 0.5);
    assert_eq!(s.mesh.tangents.len(), 2);
    for t in s.mesh.tangents.iter().flatten() {
        assert!(
            (t.truncate() - Vec3::Y).length() < 1e-5 && t.w == 1.0,
            "turned with the quad: {t}"
        );
    }
    // A cube (no texture coordinates) with the same material: a warning, no tangents for it.
    let p = write(
        dir.path(),
        "s.toml",
        scene("\n[[meshes]]\nshape = \"cube\"\nmaterial = \"bumpy\"\n").as_bytes(),
    );
    let s = Scene::load(&p).unwrap();
    assert_eq!(s.mesh.tangents.len(), 2 + 12);
    assert!(
        s.mesh.tangents[2..]
            .iter()
            .flatten()
            .all(|t| *t == glam::Vec4::ZERO)
    );
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("s.toml:11") && w.contains("no texture coordinates")),
        "{:?}",
        s.warnings
    );
    assert_errors_at(
        dir.path(),
        &scene(""),
        &[
            ("\"n.png\"", "\"missing.png\"", 3),
            ("normal_scale = 0.5", "normal_scale = nan", 4),
        ],
    );
}

/// A scene file's material can name a height map (`height_map`, `height_scale`): read as
/// linear values, no tangents made (bump mapping takes its frame from the texture
/// coordinates); a shape without texture coordinates given it is said to leave it unused,
/// naming the line; a missing image, a scale that is not a number, and a height map beside a
/// normal map are errors naming the file and line.
#[test]
fn scene_file_materials_can_name_a_height_map() {
    let dir = tempfile::tempdir().unwrap();
    let img = image::RgbImage::from_raw(1, 1, vec![90, 90, 90]).unwrap();
    img.save(dir.path().join("h.png")).unwrap();
    write(dir.path(), "quad.obj", UV_QUAD_OBJ);
    let scene = |extra: &str| {
        format!(
            "[materials.dented]\ndiffuse = [0.8, 0.8, 0.8]\nheight_map = \"h.png\"\nheight_scale = 0.02\n\n\
             [[meshes]]\npath = \"quad.obj\"\nmaterial = \"dented\"\n{extra}"
        )
    };
    let s = Scene::load(&write(dir.path(), "s.toml", scene("").as_bytes())).unwrap();
    assert!(s.warnings.is_empty(), "{:?}", s.warnings);
    let m = s.material_of(0);
    assert!(
        m.height_map.as_ref().is_some_and(|t| !t.srgb),
        "a linear map"
    );
    assert!(m.normal_map.is_none() && s.mesh.tangents.is_empty());
    assert_eq!(m.height_scale, 0.02);
    let s = Scene::load(&write(
        dir.path(),
        "s.toml",
        scene("\n[[meshes]]\nshape = \"cube\"\nmaterial = \"dented\"\n").as_bytes(),
    ))
    .unwrap();
    assert!(
        s.warnings.iter().any(|w| w.contains("s.toml:10")
            && w.contains("height map")
            && w.contains("no texture coordinates")),
        "{:?}",
        s.warnings
    );
    assert_errors_at(
        dir.path(),
        &scene(""),
        &[
            ("\"h.png\"", "\"missing.png\"", 3),
            ("height_scale = 0.02", "height_scale = nan", 4),
            (
                "height_map = \"h.png\"",
                "normal_map = \"h.png\"\nheight_map = \"h.png\"",
                4,
            ),
        ],
    );
}

/// A scene file's material with `sheen` (a colour) is a metallic-roughness material under
/// glTF's sheen layer (`sheen_roughness` 0.5 by default); a black sheen is none. A sheen
/// that is not a colour, a roughness outside [0, 1] or without a sheen, and a sheen mixed
/// with Blinn-Phong's keys are errors naming the file and line.
#[test]
fn scene_file_materials_can_have_a_sheen() {
    let dir = tempfile::tempdir().unwrap();
    let scene = |body: &str| {
        format!(
            "[materials.velvet]\ndiffuse = [0.3, 0.02, 0.05]\n{body}\n\n\
             [[meshes]]\nshape = \"sphere\"\nmaterial = \"velvet\"\n"
        )
    };
    let load = |body: &str| Scene::load(&write(dir.path(), "v.toml", scene(body).as_bytes()));
    let sheen = |body: &str| {
        let s = load(body).unwrap();
        let p = s.materials[0]
            .pbr
            .clone()
            .expect("metallic-roughness parameters");
        (p.metallic, p.roughness, p.sheen)
    };
    let (metallic, roughness, layer) = sheen("sheen = [1.0, 0.5, 0.6]\nsheen_roughness = 0.8");
    assert_eq!(
        (metallic, roughness),
        (0.0, 1.0),
        "glTF's defaults under the sheen"
    );
    let layer = layer.expect("a sheen");
    assert_eq!(
        (layer.color, layer.roughness),
        (Vec3::new(1.0, 0.5, 0.6), 0.8)
    );
    assert_eq!(sheen("sheen = [1.0, 1.0, 1.0]").2.unwrap().roughness, 0.5);
    assert_eq!(sheen("sheen = [0.0, 0.0, 0.0]\nroughness = 0.3").2, None);
    let (metallic, roughness, layer) =
        sheen("metallic = 1.0\nroughness = 0.4\nsheen = [0.2, 0.2, 0.2]");
    assert_eq!((metallic, roughness), (1.0, 0.4));
    assert!(layer.is_some());
    for (body, line, says) in [
        (
            "sheen_roughness = 0.5",
            3,
            "`sheen_roughness` without `sheen`",
        ),
        (
            "sheen = [1.0, 1.0, 1.0]\nsheen_roughness = 1.5",
            4,
            "sheen_roughness 1.5 is not in [0, 1]",
        ),
        ("sheen = [1.0, -1.0, 1.0]", 3, "is not a colour"),
        ("sheen = [1.0, nan, 1.0]", 3, "is not a colour"),
        (
            "shininess = 20.0\nsheen = [1.0, 1.0, 1.0]",
            4,
            "cannot be combined with `specular`",
        ),
    ] {
        let e = err(load(body));
        assert!(
            e.contains(&format!("v.toml:{line}")) && e.contains(says),
            "{body}: {e}"
        );
    }
}

/// A scene file's material with `metallic` or `roughness` is glTF's metallic-roughness model
/// (`diffuse` the base colour; metallic 0 and roughness 1 by default): the same lobes as a
/// glTF material of those factors. Out of range values, and either mixed with Blinn-Phong's
/// `specular`/`shininess` or a `mirror`, are errors naming the file and line.
#[test]
fn scene_file_materials_can_be_metallic_roughness() {
    let dir = tempfile::tempdir().unwrap();
    let scene = |body: &str| {
        format!(
            "[materials.metal]\ndiffuse = [0.9, 0.6, 0.3]\n{body}\n\n\
             [[meshes]]\nshape = \"cube\"\nmaterial = \"metal\"\n"
        )
    };
    let load = |body: &str| Scene::load(&write(dir.path(), "m.toml", scene(body).as_bytes()));
    let s = load("metallic = 1.0\nroughness = 0.5").unwrap();
    let m = &s.materials[0];
    let p = m.pbr.as_ref().expect("metallic-roughness parameters");
    assert_eq!(
        (p.base, p.metallic, p.roughness),
        (Vec3::new(0.9, 0.6, 0.3), 1.0, 0.5)
    );
    let lobes =
        tracery::scene::pbr::lobes(p.base, 1.0, 0.5, tracery::scene::pbr::Dielectric::DEFAULT);
    assert_eq!(
        (m.diffuse, m.specular, m.mirror),
        (lobes.diffuse, lobes.f0, lobes.mirror)
    );
    assert_eq!(m.diffuse, Vec3::ZERO, "a metal has no diffuse part");
    // Roughness alone: a rough dielectric, the base colour its diffuse colour.
    let s = load("roughness = 0.4").unwrap();
    let p = s.materials[0].pbr.as_ref().unwrap();
    assert_eq!((p.metallic, p.roughness), (0.0, 0.4));
    assert_eq!(s.materials[0].diffuse, Vec3::new(0.9, 0.6, 0.3));
    assert_eq!(s.materials[0].specular, Vec3::splat(0.04));
    // Smooth enough, a metal is a mirror of its base colour.
    let s = load("metallic = 1.0\nroughness = 0.05").unwrap();
    assert_eq!(s.materials[0].mirror, Vec3::new(0.9, 0.6, 0.3));
    assert!(s.materials[0].may_mirror());
    // Without either key: Blinn-Phong as before.
    assert!(load("").unwrap().materials[0].pbr.is_none());
    for (body, line, says) in [
        ("metallic = 1.5", 3, "metallic 1.5 is not in [0, 1]"),
        ("roughness = -0.1", 3, "roughness -0.1 is not in [0, 1]"),
        ("roughness = nan", 3, "roughness NaN is not in [0, 1]"),
        (
            "shininess = 20.0\nroughness = 0.5",
            4,
            "cannot be combined with `specular`",
        ),
        (
            "metallic = 1.0\nmirror = [1.0, 1.0, 1.0]",
            3,
            "cannot be combined with `specular`",
        ),
    ] {
        let e = err(load(body));
        assert!(
            e.contains(&format!("m.toml:{line}")) && e.contains(says),
            "{body}: {e}"
        );
    }
}
