//! Pictures against an independent renderer: tracery's linear output for the scenes of
//! `tests/reference/scenes/` against Mitsuba 3 renders of the same scenes (made by
//! `scripts/reference`, committed as two independent renders per scene, `NAME_a.exr` and
//! `NAME_b.exr`, beside the Mitsuba scene each came from). Mitsuba is not needed here.
//!
//! Each scene is rendered twice with independent seeds. Two checks, both against noise
//! measured from the images themselves (the difference of the two renders of each renderer):
//! - per pixel: the squared difference between tracery and Mitsuba, summed over the image,
//!   may exceed the sum of both renders' noise variances by at most a little (a mismatch in
//!   geometry, camera, shading or light adds to it; noise alone gives a ratio of 1);
//! - per region (a 4 x 4 grid): the mean radiance agrees within 2% (per channel, relative to
//!   the region's brightness, with a floor for regions nearly black).

use std::path::{Path, PathBuf};

use glam::Vec3;
use tracery::bvh::{BuildOptions, Bvh};
use tracery::render::{RenderSettings, render};
use tracery::sampling::SamplerKind;
use tracery::scene::Scene;

const W: u32 = 160;
const H: u32 = 120;

/// Largest allowed ratio of the summed squared difference to the summed noise variance.
const MAX_EXCESS: f64 = 1.25;
/// Largest allowed relative difference of a region's mean.
const MAX_REGION: f64 = 0.02;
/// Regions per side.
const GRID: u32 = 4;
/// A region's difference may exceed `MAX_REGION` by this many standard deviations of its
/// noise (both renderers').
const NOISE_SIGMAS: f64 = 3.0;

fn dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/reference")
}

fn load_exr(name: &str) -> Vec<Vec3> {
    let path = dir().join(name);
    let img = image::open(&path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .into_rgb32f();
    assert_eq!((img.width(), img.height()), (W, H), "{}", path.display());
    img.pixels().map(|p| Vec3::from_array(p.0)).collect()
}

fn render_seed(scene: &Scene, bvh: &Bvh, spp: u32, seed: u64, soft_terminator: bool) -> Vec<Vec3> {
    let settings = RenderSettings {
        width: W,
        height: H,
        spp,
        seed,
        max_depth: 5,
        sampler: SamplerKind::Sobol,
        soft_terminator,
    };
    let out = render(scene, bvh, &settings, &|_| {}).unwrap();
    assert_eq!(out.film.rejected, 0);
    out.film.mean()
}

/// How tracery's picture of `name` compares with Mitsuba's.
struct Agreement {
    /// Summed squared difference over summed noise variance (1 for noise alone).
    excess: f64,
    /// The region that most exceeds the allowed difference: its excess difference over the
    /// allowance (positive: outside), relative difference, relative noise, index and channel.
    worst_region: (f64, f64, f64, u32, usize),
}

impl Agreement {
    fn holds(&self) -> bool {
        self.excess <= MAX_EXCESS && self.worst_region.0 <= 0.0
    }
}

/// Compares two independent renders `t` of tracery with two `r` of Mitsuba.
fn agreement(t: (&[Vec3], &[Vec3]), r: (&[Vec3], &[Vec3])) -> Agreement {
    let n = t.0.len();
    let cells = (GRID * GRID) as usize;
    let mut diff2 = 0.0f64;
    let mut noise = 0.0f64;
    // Per region and channel: sums of tracery's and Mitsuba's means, and of their variances.
    let mut sum_t = vec![[0.0f64; 3]; cells];
    let mut sum_r = vec![[0.0f64; 3]; cells];
    let mut var = vec![[0.0f64; 3]; cells];
    let mut count = vec![0.0f64; cells];
    let mut image_r = [0.0f64; 3];
    for i in 0..n {
        let (x, y) = (i as u32 % W, i as u32 / W);
        let k = ((y * GRID / H) * GRID + x * GRID / W) as usize;
        count[k] += 1.0;
        for c in 0..3 {
            let (ta, tb) = (t.0[i][c] as f64, t.1[i][c] as f64);
            let (ra, rb) = (r.0[i][c] as f64, r.1[i][c] as f64);
            let (tm, rm) = (0.5 * (ta + tb), 0.5 * (ra + rb));
            // Each mean's variance, estimated by its half difference squared.
            let (dt, dr) = (0.5 * (ta - tb), 0.5 * (ra - rb));
            diff2 += (tm - rm).powi(2);
            noise += dt * dt + dr * dr;
            sum_t[k][c] += tm;
            sum_r[k][c] += rm;
            var[k][c] += dt * dt + dr * dr;
            image_r[c] += rm;
        }
    }
    let mut worst = (f64::MIN, 0.0, 0.0, 0, 0);
    for k in 0..cells {
        for c in 0..3 {
            let m = count[k];
            let (mt, mr) = (sum_t[k][c] / m, sum_r[k][c] / m);
            let sigma = var[k][c].sqrt() / m;
            let scale = mr.max(0.1 * image_r[c] / n as f64);
            let over = (mt - mr).abs() - (MAX_REGION * scale + NOISE_SIGMAS * sigma);
            if over / scale > worst.0 {
                worst = (over / scale, (mt - mr) / scale, sigma / scale, k as u32, c);
            }
        }
    }
    Agreement {
        excess: diff2 / noise.max(1e-30),
        worst_region: worst,
    }
}

fn load_scene(name: &str) -> Scene {
    let path = dir().join("scenes").join(format!("{name}.toml"));
    Scene::load(&path).unwrap_or_else(|e| panic!("{e:#}"))
}

/// Renders `scene` (the reference scene `name`, or a changed copy) twice and compares.
fn compare(name: &str, scene: &Scene, spp: u32) -> Agreement {
    compare_with(name, scene, spp, true)
}

/// [`compare`], the shadow terminator of bent normals softened or not (the default: softened).
fn compare_with(name: &str, scene: &Scene, spp: u32, soft_terminator: bool) -> Agreement {
    let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
    let ta = render_seed(scene, &bvh, spp, 1, soft_terminator);
    let tb = render_seed(scene, &bvh, spp, 2, soft_terminator);
    let ra = load_exr(&format!("{name}_a.exr"));
    let rb = load_exr(&format!("{name}_b.exr"));
    let a = agreement((&ta, &tb), (&ra, &rb));
    let (over, rel, sigma, region, channel) = a.worst_region;
    eprintln!(
        "{name}: squared difference / noise {:.3}; closest region {region} channel {channel}: {:+.2}% (noise {:.2}%, {:+.2}% of the allowance left)",
        a.excess,
        rel * 100.0,
        sigma * 100.0,
        -over * 100.0
    );
    a
}

fn check(name: &str, spp: u32) {
    let a = compare(name, &load_scene(name), spp);
    let (_, rel, sigma, region, channel) = a.worst_region;
    assert!(
        a.excess <= MAX_EXCESS,
        "{name}: tracery and Mitsuba differ by {:.2}x the noise of both (at most {MAX_EXCESS})",
        a.excess
    );
    assert!(
        a.worst_region.0 <= 0.0,
        "{name}: region {region} (of a {GRID}x{GRID} grid, row by row), channel {channel}, is off by {:+.2}% (noise {:.2}%)",
        rel * 100.0,
        sigma * 100.0
    );
}

#[test]
fn cornell_box_direct_matches_mitsuba() {
    check("cornell_direct", 64);
}

#[test]
fn cornell_box_path_matches_mitsuba() {
    check("cornell_path", 64);
}

#[test]
fn mirror_matches_mitsuba() {
    check("mirror", 256);
}

#[test]
fn thin_lens_matches_mitsuba() {
    check("thin_lens", 64);
}

#[test]
fn environment_matches_mitsuba() {
    check("environment", 64);
}

/// Normal maps (an OBJ's `norm`, MikkTSpace's tangents) against Mitsuba's `normalmap` BSDF:
/// two panels on the back wall (one turned in its plane), one mirrored and tipped in the room.
#[test]
fn normal_maps_match_mitsuba() {
    check("normal_map", 64);
}

/// Height maps (an OBJ's grey `bump`, bump mapping from each triangle's texture frame and
/// the bilinear interpolation's own gradient) against Mitsuba's `bumpmap` BSDF: the panels of
/// `normal_map`, bumped by a height map of leaning domes instead.
#[test]
fn height_maps_match_mitsuba() {
    check("height_map", 64);
}

/// Rough metals (GGX with Smith's masking-shadowing, sampled by visible normals, weighted
/// against light samples) against Mitsuba's `roughconductor`: two white metal spheres in the
/// Cornell box, one showing the room blurred, one a broad highlight.
#[test]
fn rough_metal_matches_mitsuba() {
    check("rough_metal", 256);
}

/// Narrow GGX lobes under the direct integrator against Mitsuba's `direct`: the ceiling
/// light's reflection in two white metal spheres (roughness 0.15 and 0.3), found by the
/// lobes' own directions and by the light's samples, weighted against each other.
#[test]
fn glossy_direct_matches_mitsuba() {
    check("glossy_direct", 64);
}

/// A rectangle light no triangle covers, path-traced: above the Cornell box's open front, out
/// of the camera's view, reflected by the narrow-lobed spheres of `glossy_direct`, where
/// bounces look for it by its rectangle (they cannot hit it) and its samples are weighted
/// against them.
#[test]
fn hidden_light_on_glossy_spheres_matches_mitsuba() {
    check("glossy_hidden_light", 128);
}

/// Emissive triangles light the direct integrator as Mitsuba's `direct` samples its area
/// emitters: the Cornell box without its rectangle light, lit by the ceiling quad's triangles
/// alone (sampled by area), is the same picture as with it (Mitsuba's scene is the same); so
/// is `glossy_direct`'s, whose spheres also find the quad along their lobes (as their closest
/// hit), weighted against its samples.
#[test]
fn emissive_triangles_light_the_direct_integrator() {
    for (name, spp) in [("cornell_direct", 64), ("glossy_direct", 64)] {
        let mut scene = load_scene(name);
        scene.lights.clear();
        assert!(scene.materials.iter().any(|m| m.is_emissive()));
        let a = compare(name, &scene, spp);
        assert!(
            a.holds(),
            "{name} lit by its emissive quad alone differs from Mitsuba's by {:.2}x the noise, worst region {:?}",
            a.excess,
            a.worst_region
        );
    }
}

/// The comparison fails on deliberate errors of a few percent or a fraction of a pixel: a
/// light 4% too dim, the direct integrator where Mitsuba traced paths, the camera turned by
/// half a pixel, the mirror turned by a degree, the lens focused 25% too far, the environment
/// turned by 2 degrees, the normal maps ignored, read upside down (Y negated) or at 80% of
/// their tilt, the height maps ignored, inverted (dents for domes) or at 80% of their
/// height, either map's shadow terminator left hard, the rough metals drawn as Blinn-Phong or
/// 15% smoother.
#[test]
fn deliberate_errors_are_caught() {
    let mut cases: Vec<(&str, Scene, u32, &str)> = Vec::new();
    let mut s = load_scene("cornell_direct");
    for l in &mut s.lights {
        if let tracery::scene::Light::Rect { intensity, .. } = l {
            *intensity *= 0.96;
        }
    }
    for m in &mut s.materials {
        m.emission *= 0.96;
    }
    cases.push(("cornell_direct", s, 64, "light 4% dimmer"));
    let mut s = load_scene("cornell_path");
    s.integrator = tracery::render::Integrator::Direct;
    cases.push(("cornell_path", s, 64, "direct light only"));
    let mut s = load_scene("cornell_direct");
    // Half a pixel of the 120-pixel-high, 39.3-degree picture, sideways.
    let turn = glam::Quat::from_rotation_y((0.5 * 39.3 / 120.0f32).to_radians());
    s.camera.look_at = s.camera.position + turn * (s.camera.look_at - s.camera.position);
    cases.push(("cornell_direct", s, 64, "camera turned half a pixel"));
    let mut s = load_scene("thin_lens");
    s.camera.focus_distance *= 1.25;
    cases.push(("thin_lens", s, 64, "focus 25% too far"));
    let mut s = load_scene("environment");
    if let tracery::scene::Environment::Equirect { rotation_deg, .. } = &mut s.environment {
        *rotation_deg += 2.0;
    }
    cases.push(("environment", s, 64, "environment turned 2 degrees"));
    let mut s = load_scene("normal_map");
    for m in &mut s.materials {
        m.normal_map = None;
    }
    cases.push(("normal_map", s, 64, "normal maps ignored"));
    // The bitangent's sign negated: the map's Y read upside down.
    let mut s = load_scene("normal_map");
    for t in s.mesh.tangents.iter_mut().flatten() {
        t.w = -t.w;
    }
    cases.push(("normal_map", s, 64, "normal maps upside down"));
    let mut s = load_scene("normal_map");
    for m in &mut s.materials {
        m.normal_scale = 0.8;
    }
    cases.push(("normal_map", s, 64, "normal maps at 80% of their tilt"));
    for (scale, what) in [
        (0.0, "height maps ignored"),
        (-1.0, "height maps inverted"),
        (0.8, "height maps at 80% of their height"),
    ] {
        let mut s = load_scene("height_map");
        let mut bumped = 0;
        for m in s.materials.iter_mut().filter(|m| m.height_map.is_some()) {
            m.height_scale *= scale;
            bumped += 1;
        }
        assert!(bumped > 0, "the height_map scene's panels have height maps");
        cases.push(("height_map", s, 64, what));
    }
    // The spheres as Blinn-Phong lobes of about the same width (the exponent glTF's
    // roughness maps to, Walter et al. 2007), white: the highlights' shape differs.
    let mut s = load_scene("rough_metal");
    for m in &mut s.materials {
        if m.pbr.take().is_some() {
            assert_eq!(m.specular, Vec3::ONE);
        }
    }
    cases.push(("rough_metal", s, 256, "Blinn-Phong instead of GGX"));
    let mut s = load_scene("rough_metal");
    for m in &mut s.materials {
        if let Some(p) = &mut m.pbr {
            p.roughness *= 0.85;
        }
    }
    cases.push(("rough_metal", s, 256, "roughness 15% low"));
    for (name, scene, spp, what) in cases {
        let a = compare(name, &scene, spp);
        assert!(!a.holds(), "{name} with {what} passed the comparison");
    }
    // Mitsuba softens the shadow terminator of the normals its maps bend, as tracery does by
    // default: the hard terminator lights the panel tipped towards the light 4-9% brighter.
    for name in ["normal_map", "height_map"] {
        let a = compare_with(name, &load_scene(name), 64, false);
        assert!(
            !a.holds(),
            "{name} with a hard shadow terminator passed the comparison"
        );
    }
}
