//! Scenes that place meshes many times: a scene file's `grid` holds its mesh once and renders
//! the picture of the same scene with every copy flattened into one mesh; refused grids name
//! the file and line. A scene's objects: every triangle in one, and an object of the scene's
//! own triangles lifted into a placement of its own renders the picture it had.

mod common;

use std::path::Path;

use tracery::bvh::{Accel, BuildOptions, Bvh};
use tracery::render::{RenderSettings, render};
use tracery::scene::{Integrator, Scene};

/// A floor placed once; a grid of turned, non-uniformly scaled boxes; a mirrored grid of
/// spheres; a grid of glowing spheres (emissive triangles sampled as lights); a rectangle light.
const GRID: &str = r#"
[camera]
position = [3.0, 4.0, 9.0]
look_at = [3.0, 0.5, 2.0]
fov = 50.0

[materials.red]
diffuse = [0.8, 0.2, 0.1]

[materials.glow]
diffuse = [0.0, 0.0, 0.0]
emission = [4.0, 3.0, 1.0]

[materials.glass]
diffuse = [0.9, 0.9, 1.0]
opacity = 0.3

[[meshes]]
shape = "quad"
scale = 20.0

[[meshes]]
shape = "cube"
material = "red"
scale = [0.3, 0.6, 0.2]
translate = [0.0, 0.6, 0.0]
grid = { count = [4, 1, 3], step = [2.0, 0.0, 2.0], turn = 23.0 }

[[meshes]]
shape = "sphere"
subdivisions = 2
scale = [-0.35, 0.35, 0.5]
translate = [1.0, 0.4, 1.0]
grid = { count = [3, 2, 2], step = [2.0, 1.2, 2.0] }

[[meshes]]
shape = "sphere"
subdivisions = 1
material = "glow"
scale = 0.12
translate = [1.0, 2.2, 0.0]
grid = { count = [3, 1, 2], step = [2.0, 0.0, 3.0] }

[[meshes]]
shape = "cube"
material = "glass"
scale = 0.25
translate = [5.0, 0.3, 4.0]
grid = { count = [1, 1, 2], step = [0.0, 0.0, -1.5] }

[[lights]]
kind = "rect"
corner = [2.0, 5.0, 1.0]
edge_u = [1.5, 0.0, 0.0]
edge_v = [0.0, 0.0, 1.5]
intensity = 20.0
"#;

fn load(text: &str) -> anyhow::Result<Scene> {
    let path = Path::new("grid.toml");
    tracery::scene::file::parse(
        path,
        text,
        &|p| anyhow::bail!("{}: no files here", p.display()),
        false,
    )
}

/// Mean and largest difference of two pictures, relative to the first's mean, and the
/// number of pixels that differ by more than a thousandth of it (a 255th of a level of an
/// 8-bit picture of it).
fn difference(a: &[glam::Vec3], b: &[glam::Vec3]) -> (f64, f64, usize) {
    let mean_a = a.iter().map(|p| p.element_sum() as f64).sum::<f64>() / a.len() as f64;
    let (mut sum, mut max, mut differ) = (0.0f64, 0.0f64, 0usize);
    for (p, q) in a.iter().zip(b) {
        let d = (*p - *q).abs().element_sum() as f64;
        sum += d;
        max = max.max(d);
        differ += (d > 1e-3 * mean_a) as usize;
    }
    (sum / a.len() as f64 / mean_a, max / mean_a, differ)
}

#[test]
fn a_grid_renders_the_picture_of_its_copies_flattened() {
    for integrator in [Integrator::Direct, Integrator::Path] {
        let mut scene = load(GRID).unwrap();
        scene.integrator = integrator;
        assert_eq!(scene.instances.meshes.len(), 4);
        assert_eq!(scene.instances.placements().len(), 12 + 12 + 6 + 2);
        assert_eq!(
            scene.mesh.triangles.len(),
            2,
            "the floor alone is placed once"
        );
        let flat = scene.flattened();
        assert_eq!(flat.triangle_count(), scene.triangle_count());
        let settings = RenderSettings {
            width: 96,
            height: 72,
            spp: 16,
            ..RenderSettings::default()
        };
        let accel = Accel::for_scene(&scene, &BuildOptions::sah()).unwrap();
        assert!(accel.flat().is_none(), "two levels for a scene with grids");
        let placed = render(&scene, &accel, &settings, &|_| {}).unwrap();
        let bvh = Bvh::build(&flat.mesh.triangles, &BuildOptions::sah());
        let flattened = render(&flat, &bvh, &settings, &|_| {}).unwrap();
        let (a, b) = (placed.film.mean(), flattened.film.mean());
        let (mean, max, differ) = difference(&b, &a);
        println!(
            "{integrator}: mean difference {mean:.2e}, largest {max:.2e} of the mean, {differ} of {} pixels differ by more than 1e-3 of it",
            a.len()
        );
        // The same samples through the same triangles: pixels differ only where a hit's
        // last bits (found in the mesh's frame) send a path elsewhere.
        assert!(mean < 2e-3, "{integrator}: mean difference {mean}");
        assert!(
            differ * 50 < a.len(),
            "{integrator}: {differ} pixels differ"
        );
        // And the picture is not empty: the grid's lit boxes are in it.
        let lit = a.iter().filter(|p| p.max_element() > 0.05).count();
        assert!(lit * 4 > a.len(), "{lit} lit pixels");
        assert_eq!(placed.rays.camera, flattened.rays.camera);
    }
}

#[test]
fn every_placed_triangle_reads_as_its_flattened_copy() {
    let scene = load(GRID).unwrap();
    let flat = scene.flattened();
    for prim in 0..scene.triangle_count() as u32 {
        assert_eq!(
            scene.triangle(prim),
            flat.mesh.triangles[prim as usize],
            "{prim}"
        );
        assert_eq!(
            scene.normals(prim),
            flat.mesh.normals[prim as usize],
            "{prim}"
        );
        assert_eq!(
            scene.material_id(prim),
            flat.mesh.material_ids[prim as usize]
        );
    }
    // The mirrored spheres' normals still point out of them.
    let b = scene.bounds();
    assert!(b.min.y < 0.01 && b.max.y > 2.0, "{b:?}");
}

#[test]
fn bad_grids_are_refused_with_the_file_and_line() {
    let cases = [
        ("count = [0, 1, 1], step = [1.0, 0.0, 0.0]", "at least 1"),
        (
            "count = [1000, 1000, 2], step = [1.0, 1.0, 1.0]",
            "more than 1000000",
        ),
        ("count = [2, 1, 1], step = [nan, 0.0, 0.0]", "finite"),
    ];
    for (grid, want) in cases {
        let text = format!("[[meshes]]\nshape = \"cube\"\ngrid = {{ {grid} }}\n");
        let e = format!("{:#}", load(&text).unwrap_err());
        assert!(e.contains("grid.toml:3") && e.contains(want), "{grid}: {e}");
    }
    let text = "[[meshes]]\nshape = \"cube\"\nscale = [0.0, 1.0, 1.0]\ngrid = { count = [2, 1, 1], step = [1.0, 0.0, 0.0] }\n";
    let e = format!("{:#}", load(text).unwrap_err());
    assert!(
        e.contains("grid.toml") && e.contains("cannot be inverted"),
        "{e}"
    );
}

/// A thousand placements of the 202k dragon (202 million triangles) load and render in about
/// one dragon's memory: in child processes (this test run again), the peak memory of a scene
/// of one placement and of a thousand; the thousand cost at most 256 bytes each over the one,
/// counted by their structures and measured by the peak. Needs the fetched dragon.
#[test]
fn a_thousand_dragons_take_one_dragons_memory() {
    const CHILD: &str = "TRACERY_TEST_DRAGONS_CHILD";
    let Some(dragon) = common::external("dragon/dragon_vrip_res2.ply") else {
        return;
    };
    if let Some(count) = std::env::var_os(CHILD) {
        let count: u32 = count.to_str().unwrap().parse().unwrap();
        let (nx, nz) = if count == 1 { (1, 1) } else { (25, count / 25) };
        let text = format!(
            "[camera]\nposition = [-0.6, 0.9, 1.5]\nlook_at = [1.4, 0.0, -1.6]\n\
             [[meshes]]\npath = {:?}\ngrid = {{ count = [{nx}, 1, {nz}], step = [0.2, 0.0, -0.2], turn = 37.0 }}\n",
            dragon.display().to_string()
        );
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("dragons.toml");
        std::fs::write(&path, text).unwrap();
        let scene = Scene::load(&path).unwrap();
        let accel = Accel::for_scene(&scene, &BuildOptions::sah()).unwrap();
        let settings = RenderSettings {
            width: 64,
            height: 48,
            spp: 1,
            ..RenderSettings::default()
        };
        let out = render(&scene, &accel, &settings, &|_| {}).unwrap();
        // One copy is placed as the scene's own triangles, under no top level.
        let top = match &accel {
            Accel::TwoLevel(two) => two.bytes(),
            Accel::Flat(_) => 0,
        };
        assert_eq!(top == 0, count == 1);
        println!("triangles {}", scene.triangle_count());
        println!(
            "hit {}",
            out.film
                .mean()
                .iter()
                .filter(|p| p.max_element() > 0.0)
                .count()
        );
        println!("placements {}", scene.instances.bytes() + top);
        println!("peak {} kB", common::peak_kb());
        return;
    }
    let name = "a_thousand_dragons_take_one_dragons_memory";
    let one = common::run_child(name, CHILD, "1".as_ref());
    let many = common::run_child(name, CHILD, "1000".as_ref());
    let (peak1, peak) = (
        common::figure(&one, "peak "),
        common::figure(&many, "peak "),
    );
    let bytes = common::figure(&many, "placements ");
    assert_eq!(common::figure(&one, "placements "), 0);
    assert_eq!(common::figure(&many, "triangles "), 1000 * 202_520);
    assert!(common::figure(&many, "hit ") > 64 * 48 / 4, "{many}");
    let structures = bytes as f64 / 1000.0;
    println!(
        "peak memory: one dragon {peak1} kB, a thousand {peak} kB; each placement: {structures:.0} bytes (its transform, first triangle's number and share of the top level)"
    );
    assert!(structures <= 256.0, "{structures} bytes a placement");
    // Two processes' peaks differ by a few MB whatever they place (the allocator, the
    // threads' stacks): the thousand may take no more than their bytes and 1 MB over the one.
    assert!(
        peak.saturating_sub(peak1) * 1024 <= 1000 * 256 + (1 << 20),
        "a thousand dragons peaked {peak} kB against one's {peak1} kB"
    );
}

/// The cost views walk both levels: the visiting walk over two levels finds the hits the
/// query finds, and counts the top level's nodes and each entered placement's mesh nodes and
/// triangles (more than the top level alone wherever a placement is hit).
#[test]
fn the_cost_views_walk_both_levels() {
    use tracery::render::heatmap::{boxes_on_ray, ray_cost};
    let scene = load(GRID).unwrap();
    let accel = Accel::for_scene(&scene, &BuildOptions::sah()).unwrap();
    let Accel::TwoLevel(two) = &accel else {
        panic!("two levels")
    };
    let cam = tracery::camera::CameraRays::new(&scene.camera, 48, 36);
    let (mut placed_hits, mut top_only) = (0, 0);
    for ray in cam.pixel_center_rays() {
        let mut top = 0;
        let visited = two.intersect_visit(&ray, f32::INFINITY, |i, _| top += i.is_none() as u32);
        let hit = two.intersect_global(&ray, f32::INFINITY);
        assert_eq!(visited.map(|h| two.global(h)), hit);
        let cost = ray_cost(&accel, &ray);
        assert!(cost.nodes >= top, "{cost:?} against {top} top-level nodes");
        if hit.is_some_and(|h| h.prim >= scene.mesh.triangles.len() as u32) {
            placed_hits += 1;
            assert!(cost.nodes > top && cost.triangles > 0, "{cost:?}");
        }
        if boxes_on_ray(&accel, &ray, 0) == 1 {
            top_only += 1;
        }
    }
    assert!(placed_hits > 100, "{placed_hits} rays hit a placement");
    assert!(top_only > 0);
}

/// Renders `scene` through the trees it needs.
fn picture(scene: &Scene, settings: &RenderSettings) -> Vec<glam::Vec3> {
    let accel = Accel::for_scene(scene, &BuildOptions::sah()).unwrap();
    render(scene, &accel, settings, &|_| {})
        .unwrap()
        .film
        .mean()
}

#[test]
fn the_cornell_box_names_its_objects_and_every_triangle_is_in_one() {
    use tracery::scene::Place;
    let scene = Scene::cornell_box();
    let names: Vec<&str> = scene.objects.iter().map(|o| o.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "floor",
            "ceiling",
            "back_wall",
            "right_wall",
            "left_wall",
            "light",
            "short_block",
            "tall_block"
        ]
    );
    let mut seen = vec![0u32; scene.triangle_count()];
    for (i, o) in scene.objects.iter().enumerate() {
        let Place::Own { first, count } = o.place else {
            panic!("{}: the box places nothing twice", o.name);
        };
        for prim in first..first + count {
            seen[prim as usize] += 1;
            assert_eq!(scene.object_of(prim), Some(i), "triangle {prim}");
        }
    }
    assert!(seen.iter().all(|&n| n == 1), "{seen:?}");
    assert_eq!(scene.object_of(scene.triangle_count() as u32), None);

    // A grid's copies are one object each, after the floor.
    let grid = load(GRID).unwrap();
    assert_eq!(grid.objects.len(), 1 + grid.instances.placements().len());
    assert_eq!(grid.objects[0].name, "quad");
    let own = grid.mesh.triangles.len() as u32;
    for p in [0, 5, grid.instances.placements().len() - 1] {
        let prim = own + grid.instances.first_triangle(p);
        assert_eq!(
            grid.objects[grid.object_of(prim).unwrap()].place,
            Place::Placed(p)
        );
    }
}

/// Lifting the tall block out of the box's own triangles where it stands changes nothing in
/// the picture (the same samples through the same triangles, now traced through two levels);
/// lifted and moved, its triangles are where the new transform puts them and the rest stay.
#[test]
fn an_object_lifted_out_of_the_scene_renders_where_its_transform_puts_it() {
    use glam::{Affine3A, Quat, Vec3};
    use tracery::scene::Place;
    let scene = Scene::cornell_box();
    let tall = scene
        .objects
        .iter()
        .position(|o| o.name == "tall_block")
        .unwrap();
    let Place::Own { first, count } = scene.objects[tall].place else {
        panic!("the tall block is the box's own");
    };
    let (frame, local) = scene.object_frame(tall).unwrap();
    assert!(
        Vec3::from(local.max).abs_diff_eq(-Vec3::from(local.min), 1e-5),
        "centred"
    );

    let lifted = scene.lifted(tall, frame).unwrap();
    assert_eq!(lifted.objects.len(), scene.objects.len());
    assert_eq!(lifted.objects[tall].place, Place::Placed(0));
    assert_eq!(
        lifted.mesh.triangles.len(),
        scene.mesh.triangles.len() - count as usize
    );
    assert_eq!(lifted.triangle_count(), scene.triangle_count());
    for i in 0..scene.objects.len() {
        assert_eq!(lifted.objects[i].name, scene.objects[i].name);
    }
    for integrator in [Integrator::Direct, Integrator::Path] {
        let (mut a, mut b) = (scene.clone(), lifted.clone());
        a.integrator = integrator;
        b.integrator = integrator;
        let settings = RenderSettings {
            width: 80,
            height: 60,
            spp: 16,
            ..RenderSettings::default()
        };
        let (before, after) = (picture(&a, &settings), picture(&b, &settings));
        let (mean, max, differ) = difference(&before, &after);
        println!(
            "{integrator}: lifted against own: mean difference {mean:.2e}, largest {max:.2e}, {differ} pixels past 1e-3"
        );
        assert!(mean < 2e-3, "{integrator}: mean difference {mean}");
        assert!(
            differ * 50 < before.len(),
            "{integrator}: {differ} pixels differ"
        );
    }

    // Moved: up by 0.5 and turned a quarter about its own vertical axis.
    let to = Affine3A::from_translation(Vec3::from(frame.translation) + Vec3::new(0.0, 0.5, 0.0))
        * Affine3A::from_quat(Quat::from_rotation_y(std::f32::consts::FRAC_PI_2));
    let moved = scene.lifted(tall, to).unwrap().flattened();
    let by = to * frame.inverse();
    let placed_first = moved.mesh.triangles.len() as u32 - count;
    let Place::Own { first: f, .. } = moved.objects[tall].place else {
        panic!("flattened");
    };
    assert_eq!(f, placed_first, "the lifted block is numbered last");
    for k in 0..count {
        let want = scene.triangle(first + k).map(|v| by.transform_point3(v));
        let got = moved.triangle(placed_first + k);
        for (w, g) in want.iter().zip(&got) {
            assert!(
                w.abs_diff_eq(*g, 1e-4),
                "triangle {k}: {got:?}, expected {want:?}"
            );
        }
    }
    // Every other object's triangles are where they were.
    for (i, o) in scene.objects.iter().enumerate().filter(|(i, _)| *i != tall) {
        let (Place::Own { first: a, count: n }, Place::Own { first: b, .. }) =
            (o.place, moved.objects[i].place)
        else {
            panic!("{}: own", o.name);
        };
        for k in 0..n {
            assert_eq!(scene.triangle(a + k), moved.triangle(b + k), "{}", o.name);
        }
    }
    // And a ray down onto its new top meets it.
    let moved = scene.lifted(tall, to).unwrap();
    let accel = Accel::for_scene(&moved, &BuildOptions::sah()).unwrap();
    let top = Vec3::from(to.translation) + Vec3::Y * (Vec3::from(local.max).y + 0.5);
    let hit = accel
        .tree()
        .intersect(
            &tracery::geometry::Ray::new(top, Vec3::NEG_Y),
            f32::INFINITY,
        )
        .unwrap();
    assert_eq!(moved.object_of(hit.prim), Some(tall));
    // An object past the list is an error, not a panic.
    assert!(scene.lifted(scene.objects.len(), to).is_err());
}

/// The debug ray over two levels lists the nodes both levels' walks entered, in order (the
/// top level's and each placed mesh's), and marks the root, and a leaf of the placement hit,
/// as holding the hit.
#[test]
fn the_debug_ray_lists_the_nodes_of_both_levels() {
    use tracery::bvh::Visit;
    use tracery::render::{EnvironmentMap, RenderPlan, Tracer};
    let scene = load(GRID).unwrap();
    let accel = Accel::for_scene(&scene, &BuildOptions::sah()).unwrap();
    let Accel::TwoLevel(two) = &accel else {
        panic!("two levels")
    };
    let settings = RenderSettings::default();
    let plan = RenderPlan::new(&scene, &settings);
    let env = EnvironmentMap::load(&scene.environment, plan.environment).unwrap();
    let tracer = Tracer::new(&scene, &accel, plan, settings.max_depth, &env);
    let cam = tracery::camera::CameraRays::new(&scene.camera, 32, 24);
    let own = scene.mesh.triangles.len() as u32;
    let mut on_placements = 0;
    for ray in cam.pixel_center_rays() {
        let path = tracer.debug_path(&ray);
        let seg = &path.segments[0];
        let mut visited = Vec::new();
        let found = two.intersect_visit(&seg.ray, f32::INFINITY, |i, v| {
            if let Visit::Node { index, .. } = v {
                visited.push((i, index));
            }
        });
        assert_eq!(seg.hit.map(|h| h.prim), found.map(|h| two.global(h).prim));
        let listed: Vec<(Option<u32>, u32)> =
            seg.nodes.iter().map(|n| (n.instance, n.index)).collect();
        assert_eq!(listed, visited);
        // (A ray that misses the top level's box enters nothing.)
        if let Some(root) = seg.nodes.first() {
            assert_eq!((root.instance, root.index), (None, 0));
            assert_eq!(root.found_hit, seg.hit.is_some());
        } else {
            assert!(seg.hit.is_none());
        }
        if let (Some(h), Some(f)) = (seg.hit, found)
            && h.prim >= own
        {
            on_placements += 1;
            let placed: Vec<_> = seg
                .nodes
                .iter()
                .filter(|n| n.instance == Some(f.instance) && n.found_hit)
                .collect();
            let mesh = &two.meshes[two.mesh_of(f.instance as usize) as usize];
            assert!(
                placed
                    .iter()
                    .any(|n| mesh.nodes[n.index as usize].is_leaf()),
                "a leaf of the placement hit holds the hit"
            );
        }
    }
    assert!(on_placements > 20, "{on_placements} rays met placements");
}

/// Moving the Cornell box's light (its glowing quad) carries the rectangle light those
/// triangles show, when it is lifted out of the box's own triangles and again when its
/// placement moves: the triangles stay inside the light, which lights the room from where they
/// are. (Left behind, the rectangle would light the room from where the quad was while the
/// quad glowed elsewhere as a second light.)
#[test]
fn a_moved_light_object_carries_its_rectangle_light() {
    use glam::{Affine3A, Vec3};
    use tracery::scene::Light;
    let scene = Scene::cornell_box();
    let light = scene
        .objects
        .iter()
        .position(|o| o.name == "light")
        .unwrap();
    let carried = scene.lights_of(light);
    assert_eq!(carried.len(), 1, "{:?}", scene.lights);
    let corner = |s: &Scene| match s.lights[carried[0]] {
        Light::Rect { corner, .. } => corner,
        _ => panic!("a rectangle light"),
    };
    let step = Vec3::new(0.1, -0.5, 0.2);
    let (frame, _) = scene.object_frame(light).unwrap();
    let once = scene
        .lifted(light, Affine3A::from_translation(step) * frame)
        .unwrap();
    assert!(corner(&once).abs_diff_eq(corner(&scene) + step, 1e-5));
    assert_eq!(once.lights_of(light), carried);
    let (frame, _) = once.object_frame(light).unwrap();
    let twice = once
        .lifted(light, Affine3A::from_translation(step) * frame)
        .unwrap();
    assert!(corner(&twice).abs_diff_eq(corner(&scene) + 2.0 * step, 1e-5));
    assert_eq!(twice.lights_of(light), carried);
    // An object that shows no light carries none.
    let tall = scene
        .objects
        .iter()
        .position(|o| o.name == "tall_block")
        .unwrap();
    assert!(scene.lights_of(tall).is_empty());
    let (frame, _) = scene.object_frame(tall).unwrap();
    let moved = scene
        .lifted(tall, Affine3A::from_translation(step) * frame)
        .unwrap();
    assert_eq!(moved.lights, scene.lights);
}
