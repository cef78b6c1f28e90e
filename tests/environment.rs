//! Environment maps: cube-map faces, corners and edges, equirectangular lookups, bad images.

use glam::Vec3;
use tracery::render::environment::{CubeMap, EnvironmentMap, LinearImage, face_uv};
use tracery::rng::SplitMix64;
use tracery::scene::Environment;

fn face(n: u32, mut f: impl FnMut(u32, u32) -> Vec3) -> LinearImage {
    LinearImage {
        width: n,
        height: n,
        texels: (0..n * n).map(|k| f(k % n, k / n)).collect(),
    }
}

const AXES: [Vec3; 6] = [
    Vec3::X,
    Vec3::NEG_X,
    Vec3::Y,
    Vec3::NEG_Y,
    Vec3::Z,
    Vec3::NEG_Z,
];

#[test]
fn cube_map_face_centres_return_the_centre_texel() {
    // 3x3 faces: the centre texel of face f is (f, 1, 0), every other texel is 0.
    let faces = std::array::from_fn(|f| {
        face(3, |x, y| {
            if (x, y) == (1, 1) {
                Vec3::new(f as f32, 1.0, 0.0)
            } else {
                Vec3::ZERO
            }
        })
    });
    let map = CubeMap::new(faces).unwrap();
    for (f, axis) in AXES.iter().enumerate() {
        assert_eq!(map.lookup(*axis), Vec3::new(f as f32, 1.0, 0.0), "face {f}");
        assert_eq!(face_uv(*axis), (f, 0.5, 0.5));
    }
}

#[test]
fn cube_map_corners_average_the_three_faces_that_meet() {
    let colours: [Vec3; 6] = std::array::from_fn(|f| Vec3::new(f as f32, (f * f) as f32, 1.0));
    let map = CubeMap::new(std::array::from_fn(|f| face(4, |_, _| colours[f]))).unwrap();
    for sx in [1.0f32, -1.0] {
        for sy in [1.0f32, -1.0] {
            for sz in [1.0f32, -1.0] {
                let d = Vec3::new(sx, sy, sz);
                let face_of = |s: f32, pos: usize| if s > 0.0 { pos } else { pos + 1 };
                let expected =
                    (colours[face_of(sx, 0)] + colours[face_of(sy, 2)] + colours[face_of(sz, 4)])
                        / 3.0;
                let got = map.lookup(d);
                assert!(
                    (got - expected).abs().max_element() < 1e-5,
                    "{d}: {got} vs {expected}"
                );
                // The face a corner belongs to is decided, the same every time.
                assert_eq!(face_uv(d).0, face_of(sx, 0));
            }
        }
    }
}

#[test]
fn cube_map_is_continuous_across_every_edge() {
    let mut rng = SplitMix64::new(5);
    let n = 8;
    let faces = std::array::from_fn(|_| face(n, |_, _| Vec3::splat(rng.next_f32())));
    let map = CubeMap::new(faces).unwrap();
    let mut edges = 0;
    for a in 0..3 {
        for b in (a + 1)..3 {
            let c = 3 - a - b; // the axis along the edge
            for sa in [1.0f32, -1.0] {
                for sb in [1.0f32, -1.0] {
                    edges += 1;
                    for k in 0..=20 {
                        let t = -0.95 + 1.9 * k as f32 / 20.0;
                        let mut p = Vec3::ZERO;
                        p[a] = sa;
                        p[b] = sb;
                        p[c] = t;
                        let eps = 1e-4;
                        let mut p1 = p;
                        p1[a] *= 1.0 + eps;
                        let mut p2 = p;
                        p2[b] *= 1.0 + eps;
                        let (v1, v2) = (map.lookup(p1), map.lookup(p2));
                        assert_ne!(face_uv(p1).0, face_uv(p2).0, "the two sides are two faces");
                        assert!(
                            (v1 - v2).abs().max_element() < 0.02,
                            "edge {a}{b} at {t}: {v1} vs {v2}"
                        );
                    }
                }
            }
        }
    }
    assert_eq!(edges, 12);
}

#[test]
fn equirect_maps_minus_z_to_the_centre_and_plus_y_to_the_top() {
    let (w, h) = (16u32, 8u32);
    let image = LinearImage {
        width: w,
        height: h,
        texels: (0..w * h)
            .map(|k| Vec3::new((k % w) as f32, (k / w) as f32, 0.0))
            .collect(),
    };
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sky.exr");
    // The image crate takes float buffers as raw native-endian bytes.
    let bytes: Vec<u8> = image
        .texels
        .iter()
        .flat_map(|v| v.to_array())
        .flat_map(f32::to_ne_bytes)
        .collect();
    image::save_buffer(&path, &bytes, w, h, image::ColorType::Rgb32F).unwrap();
    let env = Environment::Equirect {
        path,
        intensity: 1.0,
        rotation_deg: 0.0,
    };
    let map = EnvironmentMap::load(&env, true).unwrap();
    let centre = map.radiance(Vec3::NEG_Z);
    assert!((centre.x - (w as f32 / 2.0 - 0.5)).abs() < 1e-3, "{centre}");
    assert!(map.radiance(Vec3::Y).y < 0.01);
    assert!(map.radiance(Vec3::NEG_Y).y > h as f32 - 1.01);
    // Rotating the environment by 90 degrees about +y brings +x's column to -z.
    let env_r = Environment::Equirect {
        path: dir.path().join("sky.exr"),
        intensity: 2.0,
        rotation_deg: 90.0,
    };
    let rotated = EnvironmentMap::load(&env_r, true).unwrap();
    let a = rotated.radiance(Vec3::NEG_Z);
    let b = map.radiance(Vec3::X) * 2.0;
    assert!((a - b).abs().max_element() < 1e-3, "{a} vs {b}");
}

#[test]
fn truncated_or_corrupt_images_give_an_error_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good.png");
    image::save_buffer(&good, &[255u8; 4 * 4 * 3], 4, 4, image::ColorType::Rgb8).unwrap();
    let bytes = std::fs::read(&good).unwrap();
    let truncated = dir.path().join("truncated.png");
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
    let corrupt = dir.path().join("corrupt.jpg");
    // A JPEG's start-of-image marker, then garbage.
    std::fs::write(&corrupt, b"\xff\xd8\xff this is not a jpeg").unwrap();
    for bad in [&truncated, &corrupt] {
        let mut faces: [std::path::PathBuf; 6] = std::array::from_fn(|_| good.clone());
        faces[3] = bad.clone();
        let env = Environment::CubeMap {
            faces,
            intensity: 1.0,
            rotation_deg: 0.0,
        };
        let e = format!("{:#}", EnvironmentMap::load(&env, true).unwrap_err());
        assert!(
            e.contains(bad.file_name().unwrap().to_str().unwrap()),
            "{e}"
        );
    }
    // A face of another size is refused too.
    let small = dir.path().join("small.png");
    image::save_buffer(&small, &[0u8; 2 * 2 * 3], 2, 2, image::ColorType::Rgb8).unwrap();
    let mut faces: [std::path::PathBuf; 6] = std::array::from_fn(|_| good.clone());
    faces[5] = small;
    let env = Environment::CubeMap {
        faces,
        intensity: 1.0,
        rotation_deg: 0.0,
    };
    assert!(format!("{:#}", EnvironmentMap::load(&env, true).unwrap_err()).contains("face 5"));
    // Not needed: nothing is loaded, so even a missing file is no error.
    let env = Environment::Equirect {
        path: dir.path().join("missing.exr"),
        intensity: 1.0,
        rotation_deg: 0.0,
    };
    assert!(matches!(
        EnvironmentMap::load(&env, false).unwrap(),
        EnvironmentMap::None
    ));
}
