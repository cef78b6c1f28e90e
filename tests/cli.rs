//! The `tracery` command line, run as a user would.

mod common;

use std::path::Path;
use std::process::{Command, Output};

use tracery::bench::canonical_rays;
use tracery::bvh::BruteForce;
use tracery::scene::Scene;

fn tracery(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tracery"))
        .args(args)
        .output()
        .expect("the binary runs")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

#[test]
fn render_writes_the_png_it_names() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sub/cb.png");
    let o = tracery(&[
        "render",
        "-o",
        out.to_str().unwrap(),
        "--width",
        "40",
        "--height",
        "30",
        "--spp",
        "2",
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(text(&o.stdout).contains("cb.png"), "{}", text(&o.stdout));
    let img = image::open(&out).unwrap();
    assert_eq!((img.width(), img.height()), (40, 30));
}

#[test]
fn render_to_exr_and_hdr_writes_the_linear_radiance_of_the_same_render() {
    use tracery::bvh::{BuildOptions, Bvh};
    use tracery::render::{RenderSettings, render};
    let dir = tempfile::tempdir().unwrap();
    let scene = Scene::cornell_box();
    let settings = RenderSettings {
        width: 24,
        height: 18,
        spp: 3,
        ..RenderSettings::default()
    };
    let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
    let expected = render(&scene, &bvh, &settings, &|_| {})
        .unwrap()
        .film
        .mean();
    assert!(
        expected.iter().any(|v| v.max_element() > 1.0),
        "the light is brighter than 1"
    );
    for (name, rel) in [("cb.exr", 0.0), ("cb.hdr", 1.0 / 128.0)] {
        let out = dir.path().join(name);
        let o = tracery(&[
            "render",
            "-o",
            out.to_str().unwrap(),
            "--width",
            "24",
            "--height",
            "18",
            "--spp",
            "3",
        ]);
        assert!(o.status.success(), "{}", text(&o.stderr));
        let img = image::open(&out).unwrap().into_rgb32f();
        assert_eq!((img.width(), img.height()), (24, 18));
        for (px, want) in img.pixels().zip(&expected) {
            for c in 0..3 {
                // EXR holds the f32 values exactly; RGBE keeps 8 bits of mantissa under the
                // exponent of the pixel's largest component.
                let tol = rel * want.max_element();
                assert!(
                    (px[c] - want[c]).abs() <= tol,
                    "{name}: {} vs {}",
                    px[c],
                    want[c]
                );
            }
        }
    }
    // An unknown extension is refused before anything is rendered.
    let o = tracery(&["render", "-o", dir.path().join("x.tiff").to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(
        text(&o.stderr).contains("x.tiff: unknown image type"),
        "{}",
        text(&o.stderr)
    );
}

/// `--version` names the version, the commit it was built from, the features and the kernel
/// (the one `TRACERY_KERNEL` picks, among those this CPU runs); `-V` is the one-line form.
/// `render --denoise` writes the picture denoised, `--keep-noisy` the one as rendered beside
/// it, and `--aov` the layers into `STEM.aov.exr`; an unknown layer is refused by name.
#[cfg(feature = "denoise")]
#[test]
fn render_denoise_and_layers_write_the_files_they_name() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cb.png");
    let o = tracery(&[
        "render",
        "--integrator",
        "path",
        "--width",
        "48",
        "--height",
        "36",
        "--spp",
        "2",
        "--denoise",
        "--keep-noisy",
        "--aov",
        "albedo,depth",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(
        text(&o.stdout).contains(", denoised"),
        "{}",
        text(&o.stdout)
    );
    let (clean, noisy) = (
        image::open(&out).unwrap().to_rgb8(),
        image::open(dir.path().join("cb.noisy.png"))
            .unwrap()
            .to_rgb8(),
    );
    assert_ne!(clean, noisy, "the denoised picture is the noisy one");
    assert!(dir.path().join("cb.aov.exr").is_file());
    let bad = tracery(&["render", "--aov", "albedo,colour", "-o", "x.png"]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(
        text(&bad.stderr).contains("unknown render layer 'colour'"),
        "{}",
        text(&bad.stderr)
    );
}

/// A build without the denoiser refuses `--denoise` before rendering, saying how to get it.
/// (CI runs this in the test-only builds, which leave the default features out.)
#[cfg(not(feature = "denoise"))]
#[test]
fn denoise_without_the_feature_says_how_to_get_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cb.png");
    let o = tracery(&["render", "--denoise", "-o", out.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    let err = text(&o.stderr);
    assert!(err.contains("scripts/fetch-assets oidn"), "{err}");
    assert!(err.contains("no denoiser"), "{err}");
    assert!(!out.exists(), "rendered though it cannot denoise");
}

#[test]
fn version_names_the_commit_the_features_and_the_kernel() {
    let o = Command::new(env!("CARGO_BIN_EXE_tracery"))
        .arg("--version")
        .env("TRACERY_KERNEL", "scalar")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o.stderr));
    let v = text(&o.stdout);
    let first = v.lines().next().unwrap_or_default();
    assert!(
        first.starts_with(&format!("tracery {} (commit ", env!("CARGO_PKG_VERSION"))),
        "{v}"
    );
    let features = v
        .lines()
        .find_map(|l| l.strip_prefix("features: "))
        .expect("a features line");
    assert_eq!(features.contains("viewer"), cfg!(feature = "viewer"), "{v}");
    assert_eq!(
        features.contains("denoise"),
        cfg!(feature = "denoise"),
        "{v}"
    );
    let embree = v
        .lines()
        .find_map(|l| l.strip_prefix("embree: "))
        .expect("an embree line");
    assert_eq!(embree.contains("not found"), !common::embree(), "{v}");
    let kernel = v
        .lines()
        .find_map(|l| l.strip_prefix("kernel: "))
        .expect("a kernel line");
    assert!(kernel.starts_with("scalar (this CPU runs scalar"), "{v}");
    let short = tracery(&["-V"]);
    let short = text(&short.stdout);
    assert_eq!(short.lines().count(), 1, "{short}");
    assert!(
        short.starts_with(&format!("tracery {} (", env!("CARGO_PKG_VERSION"))),
        "{short}"
    );
}

#[test]
fn stats_json_has_both_builders() {
    let o = tracery(&["stats", "--json"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let rows = v.as_array().unwrap();
    assert_eq!(rows.len(), 2);
    for (row, split) in rows.iter().zip(["median", "sah"]) {
        assert_eq!(row["split"], split);
        assert_eq!(row["triangles"], 32);
        for key in [
            "nodes", "leaves", "levels", "sah_cost", "build_ms", "excluded",
        ] {
            assert!(row.get(key).is_some(), "{key} missing in {row}");
        }
        // The build's phases, each timed, together no more than the whole build.
        let ms = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
        let phases = ["references_ms", "tree_ms", "layout_ms"].map(|k| ms(&row["phases"][k]));
        let build = ms(&row["build_ms"]);
        assert!(
            phases.iter().all(|&p| p > 0.0) && phases.iter().sum::<f64>() <= build + 1e-9,
            "phases {phases:?} of a {build} ms build in {row}"
        );
    }
}

#[test]
fn report_threads_has_a_row_per_thread_count_up_to_every_core() {
    let o = tracery(&[
        "report", "threads", "--width", "16", "--height", "12", "--spp", "1", "--repeat", "1",
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let out = text(&o.stdout);
    // Rows: | threads | ms per sample | speed-up | build ms | speed-up |
    let rows: Vec<Vec<String>> = out
        .lines()
        .filter(|l| l.starts_with("| ") && l.as_bytes()[2].is_ascii_digit())
        .map(|l| l.split('|').map(|c| c.trim().to_string()).collect())
        .collect();
    let threads: Vec<usize> = rows.iter().map(|r| r[1].parse().unwrap()).collect();
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    assert_eq!(threads.first(), Some(&1), "{out}");
    assert_eq!(threads.last(), Some(&cores), "{out}");
    assert!(threads.windows(2).all(|w| w[0] < w[1]), "{out}");
    // One thread is the speed-ups' base; every time is a positive figure.
    assert_eq!(
        (rows[0][3].as_str(), rows[0][5].as_str()),
        ("1.00x", "1.00x"),
        "{out}"
    );
    for r in &rows {
        for c in [2, 4] {
            assert!(r[c].parse::<f64>().is_ok_and(|x| x > 0.0), "{out}");
        }
    }
}

/// Output into a pipe whose reader has gone (`tracery stats --json | head -0`) ends the process
/// quietly, as SIGPIPE ends other command-line tools, not with a panic.
#[cfg(unix)]
#[test]
fn printing_into_a_closed_pipe_ends_quietly() {
    use std::os::unix::process::ExitStatusExt;
    let (reader, writer) = std::io::pipe().expect("a pipe");
    drop(reader);
    let o = Command::new(env!("CARGO_BIN_EXE_tracery"))
        .args(["stats", "--json"])
        .stdout(writer)
        .output()
        .expect("the binary runs");
    let stderr = text(&o.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(o.status.signal(), Some(13), "{:?}: {stderr}", o.status);
}

#[test]
fn bench_json_and_output_files_follow_the_formats() {
    let dir = tempfile::tempdir().unwrap();
    let rays = dir.path().join("rays.bin");
    let hits = dir.path().join("hits.bin");
    let o = tracery(&[
        "bench",
        "--json",
        "--repeat",
        "1",
        "--threads",
        "2",
        "--rays-out",
        rays.to_str().unwrap(),
        "--hits-out",
        hits.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let rows = v.as_array().unwrap();
    let engines: Vec<&str> = rows.iter().map(|r| r["engine"].as_str().unwrap()).collect();
    let peers: &[&str] = &["obvhs-bvh2", "obvhs-cwbvh"];
    for &e in ["tracery-sah", "tracery-median"].iter().chain(peers) {
        assert_eq!(
            engines.iter().filter(|x| **x == e).count(),
            2,
            "{e}: one and two threads"
        );
    }
    for r in rows {
        for key in [
            "mesh",
            "triangles",
            "threads",
            "build_ms",
            "closest_mrays",
            "occluded_mrays",
            "closest_spread",
        ] {
            assert!(r.get(key).is_some(), "{key} missing in {r}");
        }
        assert!(r["closest_mrays"].as_f64().unwrap() > 0.0);
        // One round: the median is the fastest.
        assert_eq!(r["closest_spread"].as_f64(), Some(1.0), "{r}");
    }

    // Rays: u32 count then 6 f32 each; hits: u32 count then (f32 t, u32 prim).
    let rb = std::fs::read(&rays).unwrap();
    let hb = std::fs::read(&hits).unwrap();
    let n = u32::from_le_bytes(rb[..4].try_into().unwrap()) as usize;
    assert_eq!(n, 1024 * 1024);
    assert_eq!(rb.len(), 4 + 24 * n);
    assert_eq!(hb.len(), 4 + 8 * n);
    // The rays are the canonical camera's, and the hits are brute force's answers.
    let scene = Scene::cornell_box();
    let expected = canonical_rays(&scene.mesh.bounds());
    let read_back = tracery::bench::read_rays(&rays).unwrap();
    assert_eq!(read_back, expected);
    // The one-thread rows of single-ray engines carry their rates on the rays that hit and
    // those that miss apart, split as the hits file says.
    let hit_count = (0..n)
        .filter(|i| u32::from_le_bytes(hb[8 + 8 * i..12 + 8 * i].try_into().unwrap()) != u32::MAX)
        .count();
    assert!(
        hit_count > 0 && hit_count < n,
        "{hit_count} of {n} rays hit"
    );
    for r in rows {
        let engine = r["engine"].as_str().unwrap_or_default();
        let one = r["threads"] == 1;
        let single = one && engine != "tracery-packet" && !engine.ends_with("packet16");
        // Embree's packet engine times its stream queries on the secondary rays.
        let batched = one && engine == "embree-packet16";
        if !single {
            assert!(r.get("split").is_none(), "no split expected in {r}");
        }
        if !single && !batched {
            assert!(r.get("secondary").is_none(), "no secondary expected in {r}");
            continue;
        }
        // And on the secondary rays made from the hits: one bounce and one shadow ray each,
        // every engine finding the same hits and the same shadows.
        let sec = &r["secondary"];
        assert_eq!(sec["rays"], hit_count, "{r}");
        for key in ["bounce_closest_mrays", "shadow_occluded_mrays"] {
            assert!(sec[key].as_f64().unwrap() > 0.0, "{key} in {r}");
        }
        assert!(sec["bounce_agreement"].as_f64().unwrap() >= 0.9999, "{r}");
        let blocked = sec["shadow_blocked"].as_u64().unwrap() as usize;
        // (The Cornell box is closed above: its ceiling blocks every one.)
        assert!(blocked > 0 && blocked <= hit_count, "{r}");
        let first = &rows[0]["secondary"]["shadow_blocked"];
        assert_eq!(&sec["shadow_blocked"], first, "{r}");
        if batched {
            continue;
        }
        let s = &r["split"];
        assert_eq!(s["hit_rays"], hit_count, "{r}");
        assert_eq!(s["miss_rays"], n - hit_count, "{r}");
        for key in [
            "closest_hit_mrays",
            "closest_miss_mrays",
            "occluded_hit_mrays",
            "occluded_miss_mrays",
        ] {
            assert!(s[key].as_f64().unwrap() > 0.0, "{key} in {r}");
        }
    }
    let bf = BruteForce::new(&scene.mesh.triangles);
    for i in (0..n).step_by(997) {
        let rec = &hb[4 + 8 * i..12 + 8 * i];
        let t = f32::from_le_bytes(rec[..4].try_into().unwrap());
        let prim = u32::from_le_bytes(rec[4..].try_into().unwrap());
        match bf.closest(&expected[i], f32::INFINITY) {
            Some(h) => assert_eq!((t, prim), (h.t, h.prim), "ray {i}"),
            None => assert_eq!((t, prim), (f32::INFINITY, u32::MAX), "ray {i}"),
        }
    }
}

#[test]
fn bad_input_fails_with_a_message_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("broken.obj");
    std::fs::write(&bad, "v 0 0 0\nv 1 0\nf 1 2 3\n").unwrap();
    let out = dir.path().join("never.png");
    for args in [
        vec!["render", bad.to_str().unwrap(), "-o", out.to_str().unwrap()],
        vec!["stats", "/nonexistent/mesh.ply"],
        vec!["render", "--width", "0"],
        vec!["stats", "--bins", "1"],
    ] {
        let o = tracery(&args);
        assert!(!o.status.success(), "{args:?} should fail");
        let e = text(&o.stderr);
        assert!(e.starts_with("error: "), "{args:?}: {e}");
        assert!(!e.contains("panicked"), "{args:?}: {e}");
        if let Some(file) = args.iter().find(|a| a.contains('/')) {
            let name = Path::new(file).file_name().unwrap().to_str().unwrap();
            assert!(e.contains(name), "{args:?}: {e}");
        }
    }
}

#[cfg(feature = "viewer")]
#[test]
fn bad_viewer_arguments_fail_before_a_window_opens() {
    for (args, says) in [
        (
            vec!["view", "--look-from=1,2", "--look-at=0,0,0"],
            "expected three",
        ),
        (
            vec!["view", "--look-from=1,1,1", "--look-at=1,1,1"],
            "same point",
        ),
        (
            vec!["view", "--look-from=nan,0,0", "--look-at=0,0,0"],
            "finite",
        ),
        (vec!["view", "--look-from=1,1,1"], "--look-at"),
        (
            vec!["view", "--frames", "5", "--orbit-pictures", "out"],
            "needs --orbit",
        ),
    ] {
        let o = tracery(&args);
        assert!(!o.status.success(), "{args:?} should fail");
        let e = text(&o.stderr);
        assert!(
            e.starts_with("error: ") && e.contains(says),
            "{args:?}: {e}"
        );
    }
}

#[test]
fn check_mesh_exit_status_tells_clean_from_not_from_unreadable() {
    let dir = tempfile::tempdir().unwrap();
    // A closed tetrahedron: clean.
    let tet = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 3 1 4\n";
    let clean = dir.path().join("tet.obj");
    std::fs::write(&clean, tet).unwrap();
    let o = tracery(&["check-mesh", clean.to_str().unwrap()]);
    let out = text(&o.stdout);
    assert_eq!(o.status.code(), Some(0), "{out}");
    assert!(
        out.contains("4 triangles") && out.contains("clean"),
        "{out}"
    );
    // The same with a repeated face, a collinear one and a NaN vertex: not clean, each named.
    let dirty = dir.path().join("dirty.obj");
    std::fs::write(
        &dirty,
        format!("{tet}v 2 0 0\nv nan 0 0\nf 3 2 1\nf 1 2 5\nf 1 6 2\n"),
    )
    .unwrap();
    let o = tracery(&["check-mesh", "--json", dirty.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(r["triangles"], 7);
    assert_eq!(r["duplicates"]["examples"], serde_json::json!([4]));
    assert_eq!(r["degenerate"]["examples"], serde_json::json!([5]));
    assert_eq!(r["non_finite"]["examples"], serde_json::json!([6]));
    // Unreadable: 2, with the file named.
    let o = tracery(&["check-mesh", "/nonexistent/mesh.ply"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(text(&o.stderr).contains("mesh.ply"));
}

#[test]
fn bench_leaves_out_non_finite_triangles_before_any_engine_sees_them() {
    // A grid of triangles with a few NaN and infinite vertices among them: obvhs' CWBVH build
    // indexed out of bounds on such input before they were left out.
    let dir = tempfile::tempdir().unwrap();
    let mut obj = String::new();
    for i in 0..40 {
        for j in 0..40 {
            let (x, y) = (i as f32 * 0.1, j as f32 * 0.1);
            obj += &format!("v {x} {y} 0\nv {} {y} 0\nv {x} {} 0\n", x + 0.1, y + 0.1);
        }
    }
    obj += "v nan 0 0\nv 0 inf 0\nv 1 1 -inf\n";
    for k in 0..1600 {
        obj += &format!("f {} {} {}\n", 3 * k + 1, 3 * k + 2, 3 * k + 3);
    }
    obj += "f 4801 1 2\nf 3 4802 5\nf 4803 4801 4802\n";
    let path = dir.path().join("nan.obj");
    std::fs::write(&path, obj).unwrap();
    let o = tracery(&[
        "bench",
        path.to_str().unwrap(),
        "--repeat",
        "1",
        "--threads",
        "1",
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let out = text(&o.stdout);
    assert!(
        out.contains("3 with NaN or infinite vertices left out for every engine"),
        "{out}"
    );
    let peers: &[&str] = &["obvhs-bvh2", "obvhs-cwbvh"];
    for &engine in ["tracery-sah", "tracery-packet"].iter().chain(peers) {
        assert!(out.contains(engine), "{engine} missing: {out}");
    }
}

/// On two threads the text output ends with every engine's scaling from one thread, so that
/// ours reads against the others' measured in the same rounds, and, over several rounds, with
/// how far each engine's rounds spread.
#[test]
fn bench_prints_every_engines_scaling() {
    let o = tracery(&["bench", "--repeat", "2", "--threads", "2", "--no-peers"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let out = text(&o.stdout);
    let line = out
        .lines()
        .find(|l| l.starts_with("every engine's scaling, 2 threads over 1 (closest / occluded): "))
        .unwrap_or_else(|| panic!("no scaling line: {out}"));
    for engine in ["tracery-sah", "tracery-median", "tracery-packet"] {
        assert!(
            line.contains(&format!("{engine} ")),
            "{engine} missing: {line}"
        );
    }
    let ratios = line.matches("x / ").count();
    assert_eq!(ratios, 3, "one closest / occluded pair per engine: {line}");

    // The secondary rays' table: a row for each single-ray engine, none for our packets
    // (without peers, no Embree row).
    let table: Vec<&str> = out
        .lines()
        .skip_while(|l| !l.starts_with("one thread, secondary rays from the "))
        .skip(2)
        .take_while(|l| !l.contains(':'))
        .collect();
    let names: Vec<&str> = table
        .iter()
        .filter_map(|l| l.split_whitespace().next())
        .collect();
    assert_eq!(names, ["tracery-sah", "tracery-median"], "{out}");

    let prefix = "closest-hit rounds, median over fastest (1 / 2 threads): ";
    let line = out
        .lines()
        .find_map(|l| l.strip_prefix(prefix))
        .unwrap_or_else(|| panic!("no spread line: {out}"));
    for engine in ["tracery-sah", "tracery-median", "tracery-packet"] {
        let rest = line
            .split(", ")
            .find_map(|part| part.strip_prefix(&format!("{engine} ")))
            .unwrap_or_else(|| panic!("{engine} missing: {line}"));
        let spreads: Vec<f64> = rest
            .split(" / ")
            .map(|x| x.trim_end_matches('x').parse().unwrap())
            .collect();
        assert_eq!(spreads.len(), 2, "one and two threads: {line}");
        // The median of two rounds (the slower) is never faster than the fastest.
        assert!(spreads.iter().all(|&s| s >= 1.0), "{line}");
    }
}

/// One thread count alone: the spread line names it in the singular.
#[test]
fn bench_on_one_thread_prints_its_spread_for_one_thread() {
    let o = tracery(&["bench", "--repeat", "2", "--threads", "1", "--no-peers"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let out = text(&o.stdout);
    let line = out
        .lines()
        .find_map(|l| l.strip_prefix("closest-hit rounds, median over fastest (1 thread): "))
        .unwrap_or_else(|| panic!("no one-thread spread line: {out}"));
    assert_eq!(line.matches("x, ").count() + 1, 3, "three engines: {line}");
}

/// `--isa` holds our kernels (and Embree's, when built with it) to one instruction set: the
/// table's heading and every row of ours say so (scalar is never a CPU's fastest).
#[test]
fn bench_isa_holds_every_engine_to_one_instruction_set() {
    let args = [
        "bench",
        "--isa",
        "scalar",
        "--repeat",
        "1",
        "--threads",
        "1",
    ];
    let o = tracery(&args);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let out = text(&o.stdout);
    let expected = if common::embree() {
        "tracery kernel scalar, Embree held to isa=sse2"
    } else {
        "tracery kernel scalar"
    };
    assert!(out.contains(expected), "{out}");
    let o = tracery(&[&args[..], &["--json", "--no-peers"]].concat());
    assert!(o.status.success(), "{}", text(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    for r in v.as_array().unwrap() {
        assert_eq!(r["isa"].as_str(), Some("scalar"), "{r}");
    }
    let o = tracery(&["bench", "--isa", "neon"]);
    assert!(!o.status.success());
    assert!(
        text(&o.stderr).contains("unknown kernel `neon`"),
        "{}",
        text(&o.stderr)
    );
}

/// With one round there is no spread to show.
#[test]
fn bench_with_one_round_prints_no_spread() {
    let o = tracery(&["bench", "--repeat", "1", "--threads", "2", "--no-peers"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let out = text(&o.stdout);
    assert!(out.contains("every engine's scaling"), "{out}");
    assert!(!out.contains("median over fastest"), "{out}");
}

/// Every command that takes a mesh takes a glTF (the fetched textured box, a GLB with an
/// embedded PNG): `render` writes its picture, `stats` and `check-mesh` count its 12
/// triangles, `bench` traces it.
#[test]
fn every_mesh_command_takes_a_gltf() {
    let Some(glb) = common::external("gltf/BoxTextured-glTF-Binary/BoxTextured.glb") else {
        return;
    };
    let glb = glb.to_str().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("box.png");
    let o = tracery(&[
        "render",
        glb,
        "--width",
        "64",
        "--height",
        "48",
        "--spp",
        "2",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let img = image::open(&out).unwrap().to_rgb8();
    // The texture's blue and green show: more than one hue on the box.
    let blue = img
        .pixels()
        .filter(|p| p[2] > p[0] + 40 && p[2] > p[1])
        .count();
    let green = img
        .pixels()
        .filter(|p| p[1] > p[0] + 30 && p[1] > p[2])
        .count();
    assert!(blue > 20 && green > 20, "blue {blue}, green {green} pixels");
    let o = tracery(&["stats", glb, "--json", "--split", "sah"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(
        text(&o.stdout).contains("\"triangles\": 12"),
        "{}",
        text(&o.stdout)
    );
    let o = tracery(&["check-mesh", glb]);
    assert!(
        text(&o.stdout).contains("12 triangles"),
        "{}",
        text(&o.stdout)
    );
    let o = tracery(&[
        "bench",
        glb,
        "--repeat",
        "1",
        "--no-peers",
        "--threads",
        "1",
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
}

/// `report scaling` prints one row per input with each builder's speed-up from one thread to
/// all, the ratio of the row's own build times (and Embree's, when built with it).
#[test]
fn report_scaling_prints_each_builders_speed_up_from_one_thread_to_all() {
    let o = tracery(&[
        "report",
        "scaling",
        "--generated",
        "200000",
        "--repeat",
        "1",
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let stdout = text(&o.stdout);
    let lines: Vec<Vec<String>> = stdout
        .lines()
        .filter(|l| l.starts_with('|'))
        .map(|l| {
            l.trim_matches('|')
                .split('|')
                .map(|c| c.trim().to_string())
                .collect()
        })
        .collect();
    let (header, rows) = (&lines[0], &lines[2..]);
    assert_eq!(rows.len(), 1, "one row, the generated terrain:\n{stdout}");
    let column = |name: &dyn Fn(&str) -> bool| header.iter().position(|h| name(h));
    let engines: &[&str] = if common::embree() {
        &["ours", "Embree"]
    } else {
        &["ours"]
    };
    for engine in engines {
        let one = column(&|h| h == format!("{engine} 1 thread ms")).expect("one-thread column");
        let all = column(&|h| h.starts_with(engine) && h.ends_with("threads ms"))
            .expect("all-threads column");
        let speed_up = column(&|h| h.starts_with(engine) && h.ends_with("threads over 1"))
            .unwrap_or_else(|| panic!("no speed-up column for {engine}:\n{stdout}"));
        let row = &rows[0];
        let ms = |i: usize| row[i].parse::<f64>().expect("a time in ms");
        let printed: f64 = row[speed_up]
            .strip_suffix('x')
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("{engine}'s speed-up `{}` is not a ratio", row[speed_up]));
        let expected = ms(one) / ms(all);
        assert!(
            (printed - expected).abs() <= 0.01 + 0.01 * expected,
            "{engine}: printed {printed}x, its times give {expected:.3}x:\n{stdout}"
        );
    }
}

/// `--times A..B --fps F` renders the frames `A + i / F` below `B`, each to the output name
/// with its `#`s replaced by the frame number; an output name without `#` is refused.
#[test]
fn render_times_writes_one_numbered_picture_per_frame() {
    let Some(skin) = common::external("gltf/simple_skin/simple_skin.gltf") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let pattern = dir.path().join("frames/f_###.png");
    let small = ["--width", "16", "--height", "12", "--spp", "1"];
    let mut args = vec![
        "render",
        skin.to_str().unwrap(),
        "--times",
        "0..1",
        "--fps",
        "3",
        "-o",
        pattern.to_str().unwrap(),
    ];
    args.extend(small);
    let o = tracery(&args);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(
        text(&o.stdout).contains("rendered 3 frames"),
        "{}",
        text(&o.stdout)
    );
    for i in 0..3 {
        assert!(dir.path().join(format!("frames/f_{i:03}.png")).is_file());
    }
    assert!(!dir.path().join("frames/f_003.png").exists());
    // The skin bends between the first frame and the second.
    let frame = |i: usize| {
        image::open(dir.path().join(format!("frames/f_{i:03}.png")))
            .unwrap()
            .to_rgb8()
    };
    assert_ne!(frame(0), frame(1));
    // The second frame, traced with the first frame's tree refitted, is the picture of that
    // instant rendered alone (with a tree built for it).
    let alone = dir.path().join("alone.png");
    let third = format!("{}", 1.0f64 / 3.0);
    let mut args = vec![
        "render",
        skin.to_str().unwrap(),
        "--time",
        &third,
        "-o",
        alone.to_str().unwrap(),
    ];
    args.extend(small);
    let o = tracery(&args);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert_eq!(image::open(&alone).unwrap().to_rgb8(), frame(1));
    // A part of the clip (`--frames 1..3`, another machine's share): those frames alone,
    // under their own numbers, the pictures of the whole clip's.
    let part = dir.path().join("part/f_###.png");
    let mut args = vec![
        "render",
        skin.to_str().unwrap(),
        "--times",
        "0..1",
        "--fps",
        "3",
        "--frames",
        "1..3",
        "-o",
        part.to_str().unwrap(),
    ];
    args.extend(small);
    let o = tracery(&args);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(
        text(&o.stdout).contains("rendered 2 of 3 frames"),
        "{}",
        text(&o.stdout)
    );
    assert!(!dir.path().join("part/f_000.png").exists());
    for i in 1..3 {
        let p = dir.path().join(format!("part/f_{i:03}.png"));
        assert_eq!(image::open(p).unwrap().to_rgb8(), frame(i), "frame {i}");
    }
    let past = args
        .iter()
        .map(|a| if *a == "1..3" { "2..5" } else { a })
        .collect::<Vec<_>>();
    let o = tracery(&past);
    assert!(!o.status.success());
    assert!(
        text(&o.stderr).contains("the clip has 3 frames"),
        "{}",
        text(&o.stderr)
    );

    let plain = dir.path().join("frame.png");
    let mut args = vec![
        "render",
        skin.to_str().unwrap(),
        "--times",
        "0..1",
        "-o",
        plain.to_str().unwrap(),
    ];
    args.extend(small);
    let o = tracery(&args);
    assert!(!o.status.success());
    assert!(
        text(&o.stderr).contains("frame.png") && text(&o.stderr).contains('#'),
        "{}",
        text(&o.stderr)
    );
}

/// `render --samples A..B` writes parts that `merge` adds into the file one render of all the
/// samples writes, byte for byte; parts that do not fit are refused, naming the files.
#[test]
fn render_parts_merge_into_the_whole_render() {
    let dir = tempfile::tempdir().unwrap();
    let at = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let size = ["--width", "32", "--height", "24", "--seed", "3"];
    let run = |extra: &[&str]| {
        let mut args = vec!["render"];
        args.extend_from_slice(&size);
        args.extend_from_slice(extra);
        let o = tracery(&args);
        assert!(o.status.success(), "{}", text(&o.stderr));
        o
    };
    run(&["--spp", "8", "-o", &at("whole.exr")]);
    for (range, name) in [("0..3", "a.exr"), ("3..8", "b.exr")] {
        let o = run(&["--samples", range, "-o", &at(name)]);
        assert!(text(&o.stdout).contains(&format!("samples {range}")));
    }
    let o = tracery(&["merge", &at("b.exr"), &at("a.exr"), "-o", &at("merged.exr")]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(
        text(&o.stdout).contains("8 samples in every pixel"),
        "{}",
        text(&o.stdout)
    );
    assert_eq!(
        std::fs::read(at("whole.exr")).unwrap(),
        std::fs::read(at("merged.exr")).unwrap(),
        "the merged picture is the whole render's"
    );

    // A part of another seed, a gap, a file that is not a part, and a part written as PNG.
    let o = tracery(&[
        "render",
        "--width",
        "32",
        "--height",
        "24",
        "--seed",
        "4",
        "--samples",
        "3..8",
        "-o",
        &at("other.exr"),
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let refused = |args: &[&str], want: &str| {
        let o = tracery(args);
        assert!(!o.status.success());
        let e = text(&o.stderr);
        assert!(e.contains(want), "{e}");
    };
    refused(
        &["merge", &at("a.exr"), &at("other.exr"), "-o", &at("m.png")],
        "other.exr are parts of renders of different settings",
    );
    refused(
        &["merge", &at("b.exr"), "-o", &at("m.png")],
        "samples 0..3 are missing (before",
    );
    refused(
        &["merge", &at("a.exr"), &at("whole.exr"), "-o", &at("m.png")],
        "whole.exr: not a Tracery part",
    );
    refused(
        &["render", "--samples", "0..2", "-o", &at("p.png")],
        "a part (--samples) is written as EXR",
    );
    refused(
        &["render", "--samples", "4..4", "-o", &at("p.exr")],
        "holds no samples",
    );
}
