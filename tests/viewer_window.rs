//! The viewer in a real window under Xvfb: it opens, traces, saves a window screenshot and
//! exits 0; the screenshot shows the traced scene (it matches the headless render of the same
//! camera), and gizmos, when enabled, change the picture; the inspector shown from its kept
//! pixels looks as egui draws it.
//!
//! Needs `xvfb-run` and Mesa's Vulkan driver (`.ci/run` installs them). Without `xvfb-run`
//! the test is skipped locally and fails in CI.
#![cfg(feature = "viewer")]

use std::path::{Path, PathBuf};
use std::process::Command;

const W: u32 = 320;
const H: u32 = 240;

fn have_xvfb() -> bool {
    let found = Command::new("sh")
        .args(["-c", "command -v xvfb-run"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !found {
        assert!(
            std::env::var_os("CI").is_none(),
            "xvfb-run is missing: CI must install xvfb"
        );
        eprintln!("skipped: xvfb-run not installed");
    }
    found
}

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_tracery")
}

/// Runs `tracery view` under Xvfb with `args` and returns the screenshot it saved.
fn screenshot(dir: &Path, name: &str, args: &[&str]) -> image::RgbImage {
    let size = [
        "--width",
        &W.to_string(),
        "--height",
        &H.to_string(),
        "--no-ui",
    ]
    .map(String::from);
    screenshot_with(dir, name, args, &size, &[]).0
}

/// Runs `tracery view` under Xvfb with `args`, `size` and environment `env`; returns the
/// screenshot it saved and what it printed.
fn screenshot_with(
    dir: &Path,
    name: &str,
    args: &[&str],
    size: &[String],
    env: &[(&str, &str)],
) -> (image::RgbImage, String) {
    let out = dir.join(name);
    let status = Command::new("xvfb-run")
        .args(["-a", "-s", "-screen 0 1280x1024x24", bin(), "view"])
        .args(args)
        .args(size)
        // The picture as traced: the test compares it with the headless render.
        .args([
            "--no-denoise",
            "--frames",
            "8",
            "--spp",
            "4",
            "--wait-spp",
            "--screenshot",
        ])
        .arg(&out)
        .env("WGPU_BACKEND", "vulkan")
        .envs(env.iter().copied())
        .output()
        .expect("xvfb-run starts");
    assert!(
        status.status.success(),
        "viewer failed: {}\nstdout:\n{}\nstderr:\n{}",
        status.status,
        String::from_utf8_lossy(&status.stdout),
        String::from_utf8_lossy(&status.stderr)
    );
    let shot = image::open(&out)
        .unwrap_or_else(|e| panic!("{}: {e}", out.display()))
        .to_rgb8();
    (shot, String::from_utf8_lossy(&status.stdout).into_owned())
}

fn mean_abs_diff(a: &image::RgbImage, b: &image::RgbImage) -> f64 {
    assert_eq!(a.dimensions(), b.dimensions());
    let sum: u64 = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(x, y)| x.abs_diff(*y) as u64)
        .sum();
    sum as f64 / a.as_raw().len() as f64
}

#[test]
fn window_shows_the_traced_scene_and_gizmos_change_it() {
    if !have_xvfb() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let scene = "assets/scenes/cornell_mirror_glass.toml";
    let plain = screenshot(dir.path(), "plain.png", &[scene]);
    assert_eq!(plain.dimensions(), (W, H));

    // The headless render of the same camera, size and samples.
    let reference: PathBuf = dir.path().join("reference.png");
    let status = Command::new(bin())
        .args([
            "render",
            scene,
            "--width",
            &W.to_string(),
            "--height",
            &H.to_string(),
        ])
        .args(["--spp", "4", "-o"])
        .arg(&reference)
        .status()
        .unwrap();
    assert!(status.success());
    let reference = image::open(&reference).unwrap().to_rgb8();
    let d = mean_abs_diff(&plain, &reference);
    eprintln!("screenshot vs headless render: mean abs difference {d:.3} levels");
    // Exactly: the picture is copied into the frame, with no shader pass, tone mapping or
    // dithering of the window's own.
    assert!(
        d == 0.0,
        "the window shows the traced image ({d:.3} levels off)"
    );
    let mean = plain.as_raw().iter().map(|&v| v as f64).sum::<f64>() / plain.as_raw().len() as f64;
    assert!(mean > 20.0, "not a black window (mean {mean:.1})");

    // Gizmos on: the BVH boxes of level 2, the debug ray's path and the box of the object the
    // click picked are drawn over the image.
    let gizmos = screenshot(
        dir.path(),
        "gizmos.png",
        &[
            scene, "--gizmos", "level", "--level", "2", "--ray", "160,120",
        ],
    );
    let changed = plain
        .pixels()
        .zip(gizmos.pixels())
        .filter(|(a, b)| a.0.iter().zip(b.0).any(|(x, y)| x.abs_diff(y) > 40))
        .count();
    eprintln!("gizmos changed {changed} pixels");
    assert!(
        changed > 500,
        "gizmos change the picture ({changed} pixels)"
    );
    // ... over a part of it only, while the rest of the picture is the same traced image.
    let total = (W * H) as usize;
    assert!(
        changed * 4 < total,
        "gizmos cover {changed} of {total} pixels"
    );
    let (mut sum, mut n) = (0u64, 0u64);
    for ((p, g), r) in plain.pixels().zip(gizmos.pixels()).zip(reference.pixels()) {
        if p.0.iter().zip(g.0).all(|(x, y)| x.abs_diff(y) <= 40) {
            sum +=
                g.0.iter()
                    .zip(r.0)
                    .map(|(x, y)| x.abs_diff(y) as u64)
                    .sum::<u64>();
            n += 3;
        }
    }
    let rest = sum as f64 / n.max(1) as f64;
    eprintln!("outside the gizmos: mean abs difference {rest:.3} levels from the headless render");
    assert!(
        rest < 2.0,
        "the picture under the gizmos changed ({rest:.3} levels)"
    );
}

/// The inspector panel shown from its kept pixels (`panel_cache`) against the same panel drawn
/// by egui in every frame: the picture the same to the bit, the panel the same but for the
/// figures that differ between runs (frame time, Mrays/s, BVH build time).
#[test]
fn inspector_from_kept_pixels_looks_as_egui_draws_it() {
    if !have_xvfb() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let scene = "assets/scenes/cornell_box.toml";
    let size = ["--width", "960", "--height", "540"].map(String::from);
    let (kept, said) = screenshot_with(dir.path(), "kept.png", &[scene], &size, &[]);
    let (drawn, said_off) = screenshot_with(
        dir.path(),
        "drawn.png",
        &[scene],
        &size,
        &[("TRACERY_PANEL_CACHE", "off")],
    );
    assert!(
        said.contains("inspector panel shown from its kept pixels"),
        "the screenshot frame reuses the kept panel:\n{said}"
    );
    assert!(
        said_off.contains("inspector panel drawn by egui, not kept"),
        "with the cache off, egui draws the panel:\n{said_off}"
    );
    assert_eq!(kept.dimensions(), (960, 540));
    // The picture is the window's left part; the panel the rest.
    let panel_x: u32 = said
        .split("screenshot: picture ")
        .nth(1)
        .and_then(|r| r.split('x').next())
        .and_then(|w| w.parse().ok())
        .unwrap_or_else(|| panic!("no picture size in:\n{said}"));
    assert!(
        (240..900).contains(&panel_x),
        "the inspector panel starts at column {panel_x}"
    );
    let (mut picture_diff, mut panel_diff, mut panel_pixels) = (0u64, 0u64, 0u64);
    for (x, y, a) in kept.enumerate_pixels() {
        let b = drawn.get_pixel(x, y);
        let differs = a.0 != b.0;
        if x + 1 < panel_x {
            picture_diff += differs as u64;
        } else {
            panel_pixels += 1;
            panel_diff += differs as u64;
        }
    }
    eprintln!(
        "panel from column {panel_x}: {panel_diff} of {panel_pixels} pixels differ; picture: {picture_diff}"
    );
    assert_eq!(picture_diff, 0, "the picture beside the panel is the same");
    assert!(
        panel_diff * 100 < panel_pixels * 3,
        "the kept panel is egui's drawing ({panel_diff} of {panel_pixels} pixels differ)"
    );
}
