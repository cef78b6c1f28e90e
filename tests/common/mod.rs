//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Duration;

use glam::Vec3;
use rayon::prelude::*;
use tracery::bvh::{BruteForce, BuildOptions, Bvh, Hit};
use tracery::geometry::{Aabb, Ray};
use tracery::rng::SplitMix64;

/// A fetched third-party asset, or `None` (with a note) when `scripts/fetch-assets` has not
/// run. In CI (`CI` set) a missing asset fails the test instead.
pub fn external(rel: &str) -> Option<PathBuf> {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("assets/external")
        .join(rel);
    if p.is_file() {
        return Some(p);
    }
    if std::env::var_os("CI").is_some() {
        panic!(
            "{} is missing: CI must run scripts/fetch-assets first",
            p.display()
        );
    }
    eprintln!(
        "skipped: {} not fetched (run scripts/fetch-assets)",
        p.display()
    );
    None
}

/// Whether Embree 3, the benchmark's peer, can be loaded here; when it cannot, a note (the
/// test then checks what it can without Embree), and in CI (`CI` set) a failure instead.
pub fn embree() -> bool {
    match tracery::bench::embree::available() {
        Ok(_) => true,
        Err(why) if std::env::var_os("CI").is_some() => panic!("CI needs Embree: {why}"),
        Err(why) => {
            eprintln!("without Embree: {why}");
            false
        }
    }
}

/// Loads `path` as a scene on its own thread: its triangle count, or the error's text (with
/// its causes). Panics, naming the file, when the loader panics or takes over 30 s.
pub fn load_bounded(path: &Path) -> Result<usize, String> {
    let (tx, rx) = mpsc::channel();
    let p = path.to_path_buf();
    std::thread::spawn(move || {
        let r = std::panic::catch_unwind(|| {
            tracery::scene::Scene::load(&p)
                .map(|s| s.triangle_count())
                .map_err(|e| format!("{e:#}"))
        });
        let _ = tx.send(r);
    });
    match rx.recv_timeout(Duration::from_secs(30)) {
        Ok(Ok(r)) => r,
        Ok(Err(_)) => panic!("{}: panicked", path.display()),
        Err(_) => panic!("{}: no answer within 30 s", path.display()),
    }
}

fn unit_vector(rng: &mut SplitMix64) -> Vec3 {
    loop {
        let v = Vec3::new(
            rng.next_f32() * 2.0 - 1.0,
            rng.next_f32() * 2.0 - 1.0,
            rng.next_f32() * 2.0 - 1.0,
        );
        let l = v.length_squared();
        if l > 1e-6 && l <= 1.0 {
            return v / l.sqrt();
        }
    }
}

/// `count` random rays for a mesh: half from random points around its bounds in random
/// directions, half aimed at a random point of a random triangle (so that many hit).
pub fn random_rays(tris: &[[Vec3; 3]], count: usize, seed: u64) -> Vec<Ray> {
    let mut rng = SplitMix64::new(seed);
    let mut b = Aabb::EMPTY;
    for t in tris {
        for v in t {
            b.grow_point((*v).into());
        }
    }
    let c = Vec3::from(b.center());
    let r = (Vec3::from(b.max) - Vec3::from(b.min)).length().max(1e-3);
    (0..count)
        .map(|i| {
            let origin = c + unit_vector(&mut rng) * r * (0.2 + 1.3 * rng.next_f32());
            if i % 2 == 0 || tris.is_empty() {
                Ray::new(origin, unit_vector(&mut rng))
            } else {
                let t = &tris[(rng.next_u64() % tris.len() as u64) as usize];
                let (mut u, mut v) = (rng.next_f32(), rng.next_f32());
                if u + v > 1.0 {
                    (u, v) = (1.0 - u, 1.0 - v);
                }
                let target = t[0] + (t[1] - t[0]) * u + (t[2] - t[0]) * v;
                Ray::new(origin, (target - origin).normalize_or(Vec3::X))
            }
        })
        .collect()
}

/// Checks BVHs against brute force on every ray: same hit or miss, same triangle, and the same
/// `t`, `u` and `v` bit for bit (every kernel computes the reference test's operations).
/// Brute force runs once per ray for all the BVHs. Panics with the first few differences.
pub fn assert_matches_brute_force(what: &str, tris: &[[Vec3; 3]], bvhs: &[&Bvh], rays: &[Ray]) {
    let reference = BruteForce::new(tris);
    // Each tree's both walks: the one for coherent rays and the one for incoherent rays (the
    // same hits, bit for bit), listed `2 k` and `2 k + 1` in a failure.
    type Walk = fn(&Bvh, &Ray, f32) -> Option<Hit>;
    let walks: [Walk; 2] = [Bvh::intersect, Bvh::intersect_incoherent];
    let bad: Vec<(usize, usize, Option<Hit>, Option<Hit>)> = rays
        .par_iter()
        .enumerate()
        .flat_map_iter(|(i, r)| {
            let slow = reference.closest(r, f32::INFINITY);
            let each = bvhs
                .iter()
                .flat_map(move |bvh| walks.map(|walk| (bvh, walk)));
            each.enumerate().filter_map(move |(k, (bvh, walk))| {
                let fast = walk(bvh, r, f32::INFINITY);
                let same = match (fast, slow) {
                    (None, None) => true,
                    (Some(a), Some(b)) => {
                        a.prim == b.prim
                            && a.t.to_bits() == b.t.to_bits()
                            && a.u.to_bits() == b.u.to_bits()
                            && a.v.to_bits() == b.v.to_bits()
                    }
                    _ => false,
                };
                (!same).then_some((i, k, fast, slow))
            })
        })
        .collect();
    assert!(
        bad.is_empty(),
        "{what}: {} (ray, walk) pairs of {} rays differ from brute force, first (ray, walk: 2 x bvh + incoherent, bvh hit, brute force hit): {:?}",
        bad.len(),
        rays.len(),
        &bad[..bad.len().min(5)]
    );
}

/// Both builders with their default settings.
pub fn both_builders() -> [BuildOptions; 2] {
    [BuildOptions::sah(), BuildOptions::median()]
}

/// The BVH once per kernel this CPU runs (scalar, SSE2, AVX2, AVX-512), named for messages.
pub fn every_kernel(bvh: &Bvh) -> Vec<(String, Bvh)> {
    tracery::bvh::wide::Kernel::available()
        .into_iter()
        .map(|k| {
            let mut b = bvh.clone();
            b.set_kernel(k).expect("an available kernel");
            (format!("{:?}/{k}", bvh.options.split), b)
        })
        .collect()
}

/// Both builders, each with every kernel.
pub fn all_bvhs(tris: &[[Vec3; 3]]) -> Vec<(String, Bvh)> {
    both_builders()
        .iter()
        .flat_map(|o| every_kernel(&Bvh::build(tris, o)))
        .collect()
}

/// `n` triangles fanned around the vertex `c` in the plane z = c.z, out to radius 1. The ring
/// points are computed once and shared, so neighbours meet exactly.
pub fn fan(n: usize, c: Vec3) -> Vec<[Vec3; 3]> {
    let ring: Vec<Vec3> = (0..n)
        .map(|i| {
            let a = i as f32 / n as f32 * std::f32::consts::TAU;
            c + Vec3::new(a.cos(), a.sin(), 0.0)
        })
        .collect();
    (0..n).map(|i| [c, ring[i], ring[(i + 1) % n]]).collect()
}

/// `k` unit squares (two triangles each, sharing the diagonal x = y) stacked along z at
/// z = dz, 2 dz, ..., k dz.
pub fn layers(k: usize, dz: f32) -> Vec<[Vec3; 3]> {
    (1..=k)
        .flat_map(|i| {
            let z = i as f32 * dz;
            let (a, b, c, d) = (
                Vec3::new(0.0, 0.0, z),
                Vec3::new(1.0, 0.0, z),
                Vec3::new(1.0, 1.0, z),
                Vec3::new(0.0, 1.0, z),
            );
            [[a, b, c], [a, c, d]]
        })
        .collect()
}

/// PNG bytes of a 2x2 RGBA image: red, green / blue, white (top row first).
pub fn png_2x2() -> Vec<u8> {
    let img = image::RgbaImage::from_raw(
        2,
        2,
        vec![
            255, 0, 0, 255, 0, 255, 0, 255, //
            0, 0, 255, 255, 255, 255, 255, 255,
        ],
    )
    .unwrap();
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).unwrap();
    out.into_inner()
}

/// Little-endian bytes of f32 values (glTF buffers written by the tests).
pub fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// A data URI holding `bytes` (a glTF buffer inside the file).
pub fn data_uri(bytes: &[u8]) -> String {
    use base64::Engine as _;
    format!(
        "data:application/octet-stream;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(bytes)
    )
}

/// The process's peak resident memory so far (`VmHWM`), kB.
pub fn peak_kb() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap();
    let line = status.lines().find(|l| l.starts_with("VmHWM:")).unwrap();
    line.split_whitespace().nth(1).unwrap().parse().unwrap()
}

/// Runs the test `name` of this test binary again in a child process with `var` set to
/// `value`, and returns its standard output (failing when the child fails).
pub fn run_child(name: &str, var: &str, value: &std::ffi::OsStr) -> String {
    let out = std::process::Command::new(std::env::current_exe().unwrap())
        .args([name, "--exact", "--nocapture", "--test-threads=1"])
        .env(var, value)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    text
}

/// The number after `key` in a child's output (`key 123`).
pub fn figure(text: &str, key: &str) -> u64 {
    text.lines()
        .find_map(|l| l.split(key).nth(1)?.split_whitespace().next()?.parse().ok())
        .unwrap_or_else(|| panic!("no `{key}` in: {text}"))
}
