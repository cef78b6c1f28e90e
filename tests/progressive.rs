//! The viewer's building blocks in the core: progressive passes equal a one-shot render,
//! a camera pose frames rays like the scene camera, the debug ray follows the real
//! traversal, and the traversal-cost heatmap counts what the traversal does.

use std::time::Duration;

use glam::{Quat, Vec3};
use tracery::bvh::{BuildOptions, Bvh, Visit};
use tracery::camera::CameraRays;
use tracery::geometry::Ray;
use tracery::render::debug::{SegmentKind, ShadowState};
use tracery::render::heatmap::{cost_row, heat_color, pixel_cost};
use tracery::render::{EnvironmentMap, Progressive, RenderPlan, RenderSettings, Tracer, render};
use tracery::scene::Scene;

fn scene_and_bvh(path: Option<&str>) -> (Scene, Bvh) {
    let scene = match path {
        Some(p) => Scene::load(std::path::Path::new(p)).unwrap(),
        None => Scene::cornell_box(),
    };
    let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
    (scene, bvh)
}

/// A look-at camera's rotation in Bevy's convention (looking down local -z, +y up).
fn look_rotation(eye: Vec3, target: Vec3, up: Vec3) -> Quat {
    let f = (target - eye).normalize();
    let r = f.cross(up).normalize();
    let u = r.cross(f);
    Quat::from_mat3(&glam::Mat3::from_cols(r, u, -f))
}

/// Renders `settings` of the scene at `path` (the Cornell box for `None`) in one shot and
/// hands `check` that film with the tracer and camera a progressive film of the same settings
/// traces with.
fn against_one_shot(
    path: Option<&str>,
    settings: &RenderSettings,
    check: impl FnOnce(&tracery::film::Film, &Tracer, &CameraRays),
) {
    let (scene, bvh) = scene_and_bvh(path);
    let oneshot = render(&scene, &bvh, settings, &|_| {}).unwrap().film;
    let plan = RenderPlan::new(&scene, settings);
    let env = EnvironmentMap::load(&scene.environment, plan.environment).unwrap();
    let tracer = Tracer::new(&scene, &bvh, plan, settings.max_depth, &env);
    let cam = CameraRays::new(&scene.camera, settings.width, settings.height);
    check(&oneshot, &tracer, &cam);
}

#[test]
fn progressive_passes_equal_a_one_shot_render() {
    // The second size is no multiple of the 8 x 8 camera-ray tiles: partial tiles and bands.
    for (path, (width, height)) in [
        (None, (48, 40)),
        (Some("assets/scenes/cornell_mirror_glass.toml"), (48, 40)),
        (Some("assets/scenes/cornell_mirror_glass.toml"), (37, 29)),
    ] {
        let settings = RenderSettings {
            width,
            height,
            spp: 3,
            seed: 7,
            ..RenderSettings::default()
        };
        against_one_shot(path, &settings, |oneshot, tracer, cam| {
            let mut p = Progressive::new(settings.width, settings.height);
            // A zero budget still traces one batch per call: many small steps, as a frame would.
            let mut steps = 0;
            while p.passes() < settings.spp {
                let r = p.step_shaded(
                    tracer,
                    cam,
                    settings.sampler,
                    settings.seed,
                    Duration::ZERO,
                    3,
                );
                assert!(r.rows > 0, "a step always makes progress");
                steps += 1;
            }
            assert!(steps > 3, "passes were split over several steps ({steps})");
            // Asking for more than max_passes does nothing.
            assert_eq!(
                p.step_shaded(
                    tracer,
                    cam,
                    settings.sampler,
                    settings.seed,
                    Duration::ZERO,
                    3
                )
                .rows,
                0
            );
            let film = p.to_film().expect("between passes");
            assert_eq!(&film, oneshot, "{path:?}");
            assert_eq!(p.to_rgba8(1.0), oneshot.to_rgba8(1.0));

            p.reset();
            assert_eq!(p.passes(), 0);
            assert!(p.sums().iter().all(|s| *s == tracery::film::Sum::ZERO));
            assert!(p.to_rgba8(1.0).chunks(4).all(|c| c == [0, 0, 0, 255]));
        });
    }
}

/// With time to spare, passes go in rounds (the first alone, then up to four times the samples
/// so far): each row is traced once per round, and the picture is still the one-shot render's.
#[test]
fn rounds_of_passes_equal_a_one_shot_render() {
    let settings = RenderSettings {
        width: 37,
        height: 29,
        spp: 6,
        seed: 3,
        ..RenderSettings::default()
    };
    let path = Some("assets/scenes/cornell_mirror_glass.toml");
    against_one_shot(path, &settings, |oneshot, tracer, cam| {
        let mut p = Progressive::new(settings.width, settings.height);
        let step = |p: &mut Progressive, max_passes: u32| {
            p.step_shaded(
                tracer,
                cam,
                settings.sampler,
                settings.seed,
                Duration::from_secs(60),
                max_passes,
            )
        };
        // The first pass alone: the first picture comes as soon as one sample is everywhere.
        let first = step(&mut p, 1);
        assert_eq!((first.rows, p.passes()), (settings.height, 1));
        // Then rounds of 3 (to 4 passes) and of 2 (the limit): two sweeps of the rows, not five.
        let rest = step(&mut p, settings.spp);
        assert_eq!(p.passes(), settings.spp);
        assert_eq!(rest.passes_completed, settings.spp - 1);
        assert_eq!(rest.rows, 2 * settings.height, "rows traced once per round");
        assert_eq!(&p.to_film().expect("between passes"), oneshot);
    });
}

#[test]
fn part_way_pass_shows_rows_by_their_own_sample_count() {
    let (scene, bvh) = scene_and_bvh(None);
    let plan = RenderPlan::new(&scene, &RenderSettings::default());
    let env = EnvironmentMap::None;
    let tracer = Tracer::new(&scene, &bvh, plan, 5, &env);
    let cam = CameraRays::new(&scene.camera, 32, 64);
    let mut p = Progressive::new(32, 64);
    p.step_shaded(
        &tracer,
        &cam,
        tracery::sampling::SamplerKind::Sobol,
        0,
        Duration::ZERO,
        1,
    );
    assert!(!p.is_between_passes());
    assert!(
        p.to_film().is_none(),
        "no film while rows differ in samples"
    );
    let rgba = p.to_rgba8(1.0);
    // The last row is not traced yet: black.
    assert!(
        rgba[rgba.len() - 32 * 4..]
            .chunks(4)
            .all(|c| c == [0, 0, 0, 255])
    );
}

#[test]
fn camera_pose_frames_rays_like_the_scene_camera() {
    let (scene, _) = scene_and_bvh(None);
    let c = &scene.camera;
    let a = CameraRays::new(c, 320, 200);
    let b = CameraRays::from_pose(
        c.position,
        look_rotation(c.position, c.look_at, c.up),
        c.vfov_deg.to_radians(),
        320,
        200,
        c.lens_radius,
        c.focus_distance,
    );
    for (x, y) in [(0.0, 0.0), (160.0, 100.0), (319.5, 199.5), (10.0, 150.0)] {
        let (ra, rb) = (a.pinhole(x, y), b.pinhole(x, y));
        assert!(
            (ra.dir - rb.dir).length() < 1e-5,
            "{x},{y}: {} vs {}",
            ra.dir,
            rb.dir
        );
        assert_eq!(ra.origin, rb.origin);
    }
    // Broken inputs fall back to a usable frame instead of NaN rays.
    let odd = CameraRays::from_pose(
        Vec3::ZERO,
        Quat::from_xyzw(0.0, 0.0, 0.0, 0.0),
        f32::NAN,
        8,
        8,
        -1.0,
        f32::NAN,
    );
    assert!(odd.pinhole(4.0, 4.0).dir.is_finite());
    assert_eq!(odd.lens_radius, 0.0);
}

#[test]
fn debug_path_hits_equal_closest_hits() {
    let (scene, bvh) = scene_and_bvh(Some("assets/scenes/cornell_mirror_glass.toml"));
    let settings = RenderSettings::default();
    let plan = RenderPlan::new(&scene, &settings);
    let env = EnvironmentMap::load(&scene.environment, plan.environment).unwrap();
    let tracer = Tracer::new(&scene, &bvh, plan, settings.max_depth, &env);
    let cam = CameraRays::new(&scene.camera, 64, 64);
    let (mut bounces, mut shadows, mut kinds) = (0, 0, [0usize; 3]);
    for y in (0..64).step_by(3) {
        for x in (0..64).step_by(3) {
            let ray = cam.pinhole(x as f32 + 0.5, y as f32 + 0.5);
            let path = tracer.debug_path(&ray);
            assert_eq!(path.segments[0].kind, SegmentKind::Camera);
            for seg in &path.segments {
                let core = bvh.intersect(&seg.ray, f32::INFINITY);
                assert_eq!(seg.hit.map(|h| (h.t, h.prim)), core.map(|h| (h.t, h.prim)));
                // The nodes it entered are what the visiting traversal reports.
                let mut visited = Vec::new();
                bvh.intersect_visit(&seg.ray, f32::INFINITY, |v| {
                    if let Visit::Node { index, .. } = v {
                        visited.push(index)
                    }
                });
                assert_eq!(
                    seg.nodes.iter().map(|n| n.index).collect::<Vec<_>>(),
                    visited
                );
                // The root holds the hit exactly when there is one.
                if let Some(root) = seg.nodes.first() {
                    assert_eq!(root.found_hit, seg.hit.is_some());
                }
                // Checked without the traversal too: every node on the way from the root to
                // the hit's leaf is among them, and the ray crosses every box among them.
                if let Some(h) = seg.hit {
                    let path = nodes_on_path(&bvh, h.prim);
                    for n in &path {
                        assert!(seg.nodes.iter().any(|e| e.index == *n), "node {n} missing");
                    }
                }
                for e in &seg.nodes {
                    assert!(
                        crosses(&bvh.nodes[e.index as usize], &seg.ray),
                        "node {}",
                        e.index
                    );
                }
                kinds[seg.kind as usize] += 1;
            }
            bounces += path.segments.len() - 1;
            for s in &path.shadows {
                shadows += 1;
                assert!(s.transmittance.is_finite());
                // A visible shadow ray really meets nothing before the light.
                if s.state() == ShadowState::Visible {
                    assert!(!bvh.occluded(&Ray::new(s.from, s.to - s.from), 1.0 - 1e-4));
                }
            }
        }
    }
    assert!(bounces > 0 && shadows > 0);
    assert!(kinds[1] > 0, "some rays hit the mirror");
    assert!(kinds[2] > 0, "some rays pass the glass");
}

#[test]
fn heatmap_counts_the_nodes_the_traversal_enters() {
    let (scene, bvh) = scene_and_bvh(None);
    let cam = CameraRays::new(&scene.camera, 16, 16);
    let mut row = vec![tracery::film::Sum::ZERO; 16];
    cost_row(&bvh, &cam, 8, &mut row);
    for (x, px) in row.iter().enumerate() {
        let c = pixel_cost(&bvh, &cam, x as u32, 8);
        assert_eq!(px.to_vec3().x, c.nodes as f32);
        assert!(c.nodes >= 1, "every ray inside the box enters the root");
    }
    // The ramp runs from dark to bright and clamps outside [0, 1].
    let lum = |c: [u8; 3]| c.iter().map(|&v| v as u32).sum::<u32>();
    assert!(lum(heat_color(0.0)) < lum(heat_color(0.6)));
    assert_eq!(heat_color(-1.0), heat_color(0.0));
    assert_eq!(heat_color(2.0), heat_color(1.0));
    assert_eq!(heat_color(f32::NAN), heat_color(0.0));
}

/// The indices of the nodes from the root to the leaf holding triangle `prim`.
fn nodes_on_path(bvh: &Bvh, prim: u32) -> Vec<u32> {
    fn walk(bvh: &Bvh, node: u32, prim: u32, path: &mut Vec<u32>) -> bool {
        path.push(node);
        let n = &bvh.nodes[node as usize];
        let found = if n.is_leaf() {
            bvh.prim_ids[n.first as usize..(n.first + n.count) as usize].contains(&prim)
        } else {
            walk(bvh, n.first, prim, path) || walk(bvh, n.first + 1, prim, path)
        };
        if !found {
            path.pop();
        }
        found
    }
    let mut path = Vec::new();
    walk(bvh, 0, prim, &mut path);
    path
}

/// True when the ray crosses the node's box (grown a little), by a plain slab test.
fn crosses(n: &tracery::bvh::BvhNode, ray: &Ray) -> bool {
    let (mut t0, mut t1) = (0.0f32, f32::INFINITY);
    for a in 0..3 {
        let pad = 1e-4 * (1.0 + n.max[a].abs().max(n.min[a].abs()));
        let inv = 1.0 / ray.dir[a];
        let lo = (n.min[a] - pad - ray.origin[a]) * inv;
        let hi = (n.max[a] + pad - ray.origin[a]) * inv;
        let (lo, hi) = if lo <= hi { (lo, hi) } else { (hi, lo) };
        if !lo.is_nan() {
            t0 = t0.max(lo);
        }
        if !hi.is_nan() {
            t1 = t1.min(hi);
        }
    }
    t0 <= t1
}

/// Nodes whose box (grown a little) the ray crosses: every node of the array tested on its own
/// with a plain slab test. No traversal enters another.
fn nodes_crossed(bvh: &Bvh, ray: &Ray) -> usize {
    bvh.nodes
        .iter()
        .enumerate()
        .filter(|&(i, n)| i != 1 && crosses(n, ray)) // slot 1 is unused
        .count()
}

/// The heatmap's count against bounds found without the traversal: at least the nodes from
/// the root to the leaf of the hit (all of them are entered to find it), at most the nodes
/// whose boxes the ray crosses at all (before the hit is known, a traversal may enter boxes
/// that lie beyond it, never one the ray misses).
#[test]
fn heatmap_cost_lies_between_the_hit_path_and_the_boxes_crossed() {
    let (scene, bvh) = scene_and_bvh(Some("assets/scenes/cornell_mirror_glass.toml"));
    let cam = CameraRays::new(&scene.camera, 48, 36);
    let mut checked = 0;
    for y in 0..36 {
        for x in 0..48 {
            let ray = cam.pinhole(x as f32 + 0.5, y as f32 + 0.5);
            let cost = pixel_cost(&bvh, &cam, x, y).nodes as usize;
            let hit = bvh.intersect(&ray, f32::INFINITY);
            let most = nodes_crossed(&bvh, &ray);
            assert!(cost <= most, "pixel {x},{y}: {cost} nodes, {most} crossed");
            if let Some(h) = hit {
                let least = nodes_on_path(&bvh, h.prim).len();
                assert!(least > 0, "the hit's triangle is in some leaf");
                assert!(cost >= least, "pixel {x},{y}: {cost} nodes, path {least}");
                checked += 1;
            }
        }
    }
    assert!(checked > 1000, "{checked} hits checked");
}
