//! Scenes that place meshes many times: a scene file's `grid` holds its mesh once and renders
//! the picture of the same scene with every copy flattened into one mesh; refused grids name
//! the file and line.

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
        let visited = two.intersect_visit(&ray, f32::INFINITY, |is_top, _| top += is_top as u32);
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
