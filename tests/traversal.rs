//! The queries besides closest hit: any hit, transmittance and the visiting traversal.

mod common;

use glam::Vec3;
use tracery::bvh::{BruteForce, Bvh, RayTile, Visit};
use tracery::geometry::Ray;
use tracery::geometry::shapes;

#[test]
fn occluded_agrees_with_brute_force() {
    let tris = shapes::random_soup(2000, 0.15, 21);
    let bf = BruteForce::new(&tris);
    let rays = common::random_rays(&tris, 20_000, 3);
    for (name, bvh) in common::all_bvhs(&tris) {
        for (i, r) in rays.iter().enumerate() {
            let t_max = 0.05 + (i % 10) as f32 * 0.1;
            assert_eq!(
                bvh.occluded(r, t_max),
                !bf.all_hits(r, t_max).is_empty(),
                "{name}, ray {i}"
            );
        }
    }
}

/// `rays` (ray `i` with the shadow limit `t_maxes[i]`) through `Bvh::intersect_batch` and
/// `Bvh::occluded_batch` in batches of the sizes `sizes`, in turn: every ray's closest hit and
/// whether its shadow segment is blocked.
fn batch_answers(
    bvh: &Bvh,
    rays: &[Ray],
    t_maxes: &[f32],
    sizes: &[usize],
) -> (Vec<Option<tracery::bvh::Hit>>, Vec<bool>) {
    let mut hits = vec![None; rays.len()];
    // Filled with the answer no batch gives to an invalid ray, so a ray left out shows.
    let mut blocked = vec![true; rays.len()];
    let mut start = 0;
    for size in sizes.iter().cycle() {
        if start >= rays.len() {
            break;
        }
        let end = (start + size).min(rays.len());
        bvh.intersect_batch(&rays[start..end], &mut hits[start..end]);
        let shadow: Vec<(Ray, f32)> = rays[start..end]
            .iter()
            .zip(&t_maxes[start..end])
            .map(|(r, &t)| (*r, t))
            .collect();
        bvh.occluded_batch(&shadow, &mut blocked[start..end]);
        start = end;
    }
    (hits, blocked)
}

/// The batch queries a path tracer's rounds use give each ray what brute force gives it: the
/// closest hit (the same triangle and distance) and, for shadow rays each with its own
/// `t_max`, whether anything lies on the segment; on every kernel and both builders, in
/// batches of every size up to a few hundred rays.
#[test]
fn batch_queries_agree_with_brute_force() {
    let tris = shapes::random_soup(1500, 0.15, 8);
    let bf = BruteForce::new(&tris);
    let rays = common::random_rays(&tris, 3000, 9);
    let t_maxes: Vec<f32> = (0..rays.len())
        .map(|i| 0.05 + (i % 7) as f32 * 0.15)
        .collect();
    for (name, bvh) in common::all_bvhs(&tris) {
        let (hits, blocked) = batch_answers(&bvh, &rays, &t_maxes, &[1, 2, 7, 64, 65, 300]);
        for (i, r) in rays.iter().enumerate() {
            let want = bf.closest(r, f32::INFINITY);
            assert_eq!(
                hits[i].map(|h| (h.prim, h.t)),
                want.map(|h| (h.prim, h.t)),
                "{name}, ray {i}"
            );
            let blocked_bf = !bf.all_hits(r, t_maxes[i]).is_empty();
            assert_eq!(blocked[i], blocked_bf, "{name}, shadow ray {i}");
        }
    }
}

/// Where the tree is one leaf (the Cornell box's 32 triangles), the batch queries test the
/// rays in groups of one axis permutation: each ray still gets the hit it gets alone, bit for
/// bit (distance and barycentrics), and brute force's answers, in batches of every size, with
/// rays from inside and outside the room, rays that cannot hit (NaN, zero direction) and
/// shadow rays whose limit is zero or below among them.
#[test]
fn batch_queries_on_one_leaf_agree_with_single_rays() {
    let tris = tracery::scene::Scene::cornell_box().mesh.triangles;
    let bf = BruteForce::new(&tris);
    let mut rays = common::random_rays(&tris, 4000, 17);
    for (i, r) in rays.iter_mut().enumerate().step_by(97) {
        *r = match i % 3 {
            0 => Ray::new(r.origin, Vec3::ZERO),
            1 => Ray::new(Vec3::new(f32::NAN, 1.0, 1.0), r.dir),
            _ => Ray::new(r.origin, Vec3::new(0.0, 0.0, -1.0)),
        };
    }
    let t_maxes: Vec<f32> = (0..rays.len())
        .map(|i| [0.0, -1.0, 0.5, 2.0, 8.0, f32::INFINITY][i % 6])
        .collect();
    let sah = Bvh::build(&tris, &tracery::bvh::BuildOptions::sah());
    assert!(sah.wide.root_leaf.is_some() && sah.wide.nodes.is_empty());
    let bits = |h: Option<tracery::bvh::Hit>| {
        h.map(|h| (h.prim, h.t.to_bits(), h.u.to_bits(), h.v.to_bits()))
    };
    for (name, bvh) in common::all_bvhs(&tris) {
        let sizes = [1, 3, 64, 65, 300, 1024];
        let (hits, blocked) = batch_answers(&bvh, &rays, &t_maxes, &sizes);
        for (i, r) in rays.iter().enumerate() {
            let alone = bvh.intersect(r, f32::INFINITY);
            assert_eq!(bits(hits[i]), bits(alone), "{name}, ray {i}");
            let t_max = t_maxes[i];
            assert_eq!(blocked[i], bvh.occluded(r, t_max), "{name}, shadow {i}");
            if !r.is_valid() {
                assert!(hits[i].is_none() && !blocked[i], "{name}, ray {i}");
                continue;
            }
            let want = bf.closest(r, f32::INFINITY);
            assert_eq!(hits[i].map(|h| h.prim), want.map(|h| h.prim), "{name}");
            let any = t_max > 0.0 && !bf.all_hits(r, t_max).is_empty();
            assert_eq!(blocked[i], any, "{name}, shadow ray {i}");
        }
    }
}

#[test]
fn for_each_hit_reports_every_hit_once() {
    let tris = shapes::random_soup(1500, 0.2, 5);
    let bf = BruteForce::new(&tris);
    let rays = common::random_rays(&tris, 5000, 17);
    for (name, bvh) in common::all_bvhs(&tris) {
        for r in &rays {
            let mut got = Vec::new();
            bvh.for_each_hit(r, f32::INFINITY, |p, t| {
                got.push((p, t));
                true
            });
            got.sort_by_key(|h| h.0);
            assert_eq!(got, bf.all_hits(r, f32::INFINITY), "{name}");
        }
    }
}

fn layers(k: usize) -> Vec<[Vec3; 3]> {
    common::layers(k, 1.0)
}

#[test]
fn transmittance_through_k_layers_is_t_to_the_k() {
    let tris = layers(8);
    let bvh = Bvh::build(&tris, &tracery::bvh::BuildOptions::sah());
    let t = 0.7f32;
    let ray = Ray::new(Vec3::new(0.3, 0.6, 0.0), Vec3::Z);
    for k in 0..=8 {
        // Stop the shadow ray between layer k and k + 1.
        let through = bvh.transmittance(&ray, k as f32 + 0.5, |_, _| Vec3::splat(t));
        assert!((through.x - t.powi(k)).abs() < 1e-6, "k = {k}: {through}");
    }
    // An opaque layer stops everything, and the walk stops early.
    let mut calls = 0;
    let through = bvh.transmittance(&ray, 100.0, |_, _| {
        calls += 1;
        Vec3::ZERO
    });
    assert_eq!((through, calls), (Vec3::ZERO, 1));
}

#[test]
fn transmittance_counts_a_shared_edge_once() {
    let tris = layers(1);
    let bvh = Bvh::build(&tris, &tracery::bvh::BuildOptions::sah());
    // The squares' diagonal x = y is the edge both triangles share.
    for i in 1..32 {
        let s = i as f32 / 32.0;
        let ray = Ray::new(Vec3::new(s, s, 0.0), Vec3::Z);
        let through = bvh.transmittance(&ray, 10.0, |_, _| Vec3::splat(0.5));
        assert_eq!(through, Vec3::splat(0.5), "s = {s}");
    }
}

#[test]
fn visiting_traversal_finds_the_same_hits_and_reports_its_work() {
    let tris = shapes::icosphere(3);
    let rays = common::random_rays(&tris, 5000, 12);
    for options in common::both_builders() {
        let bvh = Bvh::build(&tris, &options);
        for r in &rays {
            let mut nodes = 0;
            let mut tested = 0;
            let mut last_depth = None;
            let visited = bvh.intersect_visit(r, f32::INFINITY, |v| match v {
                Visit::Node { index, depth } => {
                    assert!((index as usize) < bvh.nodes.len() && index != 1);
                    if last_depth.is_none() {
                        assert_eq!((index, depth), (0, 0), "starts at the root");
                    }
                    last_depth = Some(depth);
                    nodes += 1;
                }
                Visit::Triangle { prim, .. } => {
                    assert!((prim as usize) < tris.len());
                    tested += 1;
                }
            });
            let fast = bvh.intersect(r, f32::INFINITY);
            assert_eq!(visited, fast);
            if fast.is_some() {
                assert!(nodes >= 1 && tested >= 1);
            }
        }
    }
}

/// The rays of the canonical camera in 8 x 8 tiles (and tiles of a thin lens, whose rays leave
/// from different points), as the renderer and the benchmark trace them.
fn camera_tiles(tris: &[[Vec3; 3]], size: u32, lens: f32) -> Vec<Vec<Ray>> {
    use tracery::camera::CameraRays;
    use tracery::scene::{Camera, Mesh};
    let mut camera = Camera::canonical(&Mesh::from_triangles(tris.to_vec(), 0).bounds());
    camera.lens_radius = lens;
    let cam = CameraRays::new(&camera, size, size);
    let mut rng = tracery::rng::SplitMix64::new(9);
    let mut tiles = Vec::new();
    for ty in (0..size).step_by(8) {
        for tx in (0..size).step_by(8) {
            let mut tile = Vec::new();
            for y in ty..(ty + 8).min(size) {
                for x in tx..(tx + 8).min(size) {
                    let (px, py) = (x as f32 + rng.next_f32(), y as f32 + rng.next_f32());
                    let lens = glam::Vec2::new(rng.next_f32(), rng.next_f32()) * 2.0 - 1.0;
                    tile.push(cam.thin_lens(px, py, lens * 0.7));
                }
            }
            tiles.push(tile);
        }
    }
    tiles
}

/// Tiles of rays from one point aimed exactly at triangle vertices and edge midpoints, grouped
/// by direction octant: they graze the boxes that hold those triangles, where a packet's
/// interval bounds must stay as conservative as each ray's own box test.
fn vertex_tiles(tris: &[[Vec3; 3]]) -> Vec<Vec<Ray>> {
    let b = tracery::scene::Mesh::from_triangles(tris.to_vec(), 0).bounds();
    let from = Vec3::from(b.center()) + Vec3::from(b.max - b.min) * Vec3::new(0.37, 0.61, 1.3);
    let mut by_octant: Vec<Vec<Ray>> = vec![Vec::new(); 8];
    for t in tris.iter().take(2000) {
        for target in [t[0], t[1], (t[0] + t[2]) * 0.5] {
            let d = target - from;
            let q =
                (d.x < 0.0) as usize | ((d.y < 0.0) as usize) << 1 | ((d.z < 0.0) as usize) << 2;
            by_octant[q].push(Ray::new(from, d));
        }
    }
    by_octant
        .iter()
        .flat_map(|v| v.chunks(64).map(|c| c.to_vec()))
        .collect()
}

/// A mesh's name, its triangles and tiles of rays.
type PacketCase = (&'static str, Vec<[Vec3; 3]>, Vec<Vec<Ray>>);

/// The meshes the packet tests run on, and for each the tiles of rays: camera tiles with and
/// without a lens, tiles that cannot go together (mixed octants, a partial tile), and tiles
/// aimed at vertices.
fn packet_cases() -> Vec<PacketCase> {
    let mut meshes = vec![
        (
            "cornell box",
            tracery::scene::Scene::cornell_box().mesh.triangles,
        ),
        ("icosphere", shapes::icosphere(4)),
        ("soup", shapes::random_soup(3000, 0.1, 7)),
        ("needles", shapes::needles(500, 1e4)),
    ];
    if let Some(p) = common::external("bunny/bunny.obj") {
        meshes.push((
            "bunny",
            tracery::scene::Scene::load(&p).unwrap().mesh.triangles,
        ));
    }
    meshes
        .into_iter()
        .map(|(name, tris)| {
            let mut rays: Vec<Vec<Ray>> = Vec::new();
            for lens in [0.0, 0.05] {
                rays.extend(camera_tiles(&tris, 96, lens));
            }
            rays.push(common::random_rays(&tris, 64, 3));
            rays.push(common::random_rays(&tris, 13, 4));
            rays.extend(vertex_tiles(&tris));
            (name, tris, rays)
        })
        .collect()
}

#[test]
fn packets_give_every_ray_its_single_ray_hit() {
    for (name, tris, rays) in packet_cases() {
        for (bvh_name, bvh) in common::all_bvhs(&tris) {
            for tile in &rays {
                for t_max in [f32::INFINITY, 2.0] {
                    let mut out = vec![None; tile.len()];
                    bvh.intersect_packet(tile, t_max, &mut out);
                    for (r, got) in tile.iter().zip(&out) {
                        let want = bvh.intersect(r, t_max);
                        let same = match (got, &want) {
                            (None, None) => true,
                            (Some(a), Some(b)) => {
                                a.prim == b.prim
                                    && a.t.to_bits() == b.t.to_bits()
                                    && a.u.to_bits() == b.u.to_bits()
                            }
                            _ => false,
                        };
                        assert!(same, "{name}, {bvh_name}: {r:?}: {got:?} vs {want:?}");
                    }
                }
            }
        }
    }
}

/// Tiles read in place from an image of camera rays (rows of the image apart, the right and
/// bottom edge tiles narrower and shorter) give every ray its single-ray hit and shadow answer,
/// each ray answered exactly once at its own index. (Before the check was written, a load of
/// the wrong rows went unnoticed with the canonical camera: its tiles then mixed octants and
/// went ray by ray.)
#[test]
fn tiles_read_in_place_give_every_ray_its_single_ray_answer() {
    use tracery::camera::CameraRays;
    use tracery::scene::{Camera, Mesh};
    let (width, height) = (100, 60);
    for (name, tris) in [
        ("icosphere", shapes::icosphere(4)),
        ("soup", shapes::random_soup(3000, 0.1, 7)),
    ] {
        // Looking along (-1, -1, -1) with a narrow field: every ray in one octant, so every
        // tile goes as a packet (a tile's rays read from the wrong rows would too).
        let mut camera = Camera::canonical(&Mesh::from_triangles(tris.clone(), 0).bounds());
        let distance = (camera.position - camera.look_at).length();
        camera.position = camera.look_at + Vec3::ONE.normalize() * distance;
        camera.vfov_deg = 25.0;
        let rays = CameraRays::new(&camera, width, height).pixel_center_rays();
        assert_eq!(rays.len(), (width * height) as usize);
        let width = width as usize;
        for (bvh_name, bvh) in common::all_bvhs(&tris) {
            let (mut hits, mut answered) = (0, vec![0u8; rays.len()]);
            for y0 in (0..rays.len() / width).step_by(8) {
                for x0 in (0..width).step_by(8) {
                    let rows = (rays.len() / width - y0).min(8);
                    let band = &rays[y0 * width..];
                    let tile = RayTile::new(&band[x0..], width, (width - x0).min(8), rows)
                        .expect("a tile inside the image");
                    bvh.intersect_tile(tile, f32::INFINITY, |at, got| {
                        let r = &band[x0 + at];
                        answered[y0 * width + x0 + at] += 1;
                        let want = bvh.intersect(r, f32::INFINITY);
                        hits += want.is_some() as usize;
                        assert_eq!(got, want, "{name}, {bvh_name}: {r:?}");
                    });
                    bvh.occluded_tile(tile, f32::INFINITY, |at, got| {
                        let r = &band[x0 + at];
                        assert_eq!(got, bvh.occluded(r, f32::INFINITY), "{name}, {bvh_name}");
                    });
                }
            }
            assert!(
                answered.iter().all(|&n| n == 1),
                "{name}: a ray answered twice or never"
            );
            assert!(hits > 500 && hits < rays.len(), "{name}: {hits} hits");
        }
    }
}

/// A tile is only made from rays it lies inside.
#[test]
fn tiles_outside_their_rays_are_refused() {
    let rays = vec![Ray::new(Vec3::ZERO, Vec3::Z); 100];
    assert!(RayTile::new(&rays, 10, 8, 8).is_some());
    assert!(
        RayTile::new(&rays, 10, 10, 10).is_none(),
        "more than a packet"
    );
    assert!(
        RayTile::new(&rays, 4, 8, 2).is_none(),
        "rows wider than the stride"
    );
    assert!(RayTile::new(&rays, 20, 8, 6).is_none(), "past the end");
    assert!(RayTile::new(&rays, 20, 0, 1).is_none(), "empty");
    assert_eq!(RayTile::list(&rays[..13]).len(), 13);
}

/// Packets of shadow rays (any hit) answer every ray as [`Bvh::occluded`] does, at an infinite
/// and a short `t_max`, and at a `t_max` equal to one ray's own closest hit (which must not
/// count: hits are at `t < t_max`).
#[test]
fn occlusion_packets_give_every_ray_its_single_ray_answer() {
    let (mut blocked, mut open) = (0usize, 0usize);
    for (name, tris, rays) in packet_cases() {
        for (bvh_name, bvh) in common::all_bvhs(&tris) {
            for tile in &rays {
                let first_hit = tile
                    .iter()
                    .find_map(|r| bvh.intersect(r, f32::INFINITY))
                    .map_or(1.0, |h| h.t);
                for t_max in [f32::INFINITY, 2.0, first_hit] {
                    let mut out = vec![false; tile.len()];
                    bvh.occluded_packet(tile, t_max, &mut out);
                    for (r, &got) in tile.iter().zip(&out) {
                        let want = bvh.occluded(r, t_max);
                        assert_eq!(got, want, "{name}, {bvh_name}, t_max {t_max}: {r:?}");
                        if got {
                            blocked += 1;
                        } else {
                            open += 1;
                        }
                    }
                }
            }
        }
    }
    assert!(
        blocked > 10_000 && open > 10_000,
        "{blocked} blocked, {open} open"
    );
}

/// A shadow ray whose blocker sits just before `t_max` is blocked, and one whose blocker sits
/// at `t_max` is not, for rays aimed at vertices (their hits lie on box faces, where a box's
/// computed entry distance may round past the hit: box culling needs the same slack as the
/// closest-hit search, and lacked it).
#[test]
fn a_blocker_just_before_t_max_blocks() {
    let tris = shapes::icosphere(4);
    let mut checked = 0;
    for (bvh_name, bvh) in common::all_bvhs(&tris) {
        for tile in vertex_tiles(&tris) {
            for r in &tile {
                let Some(h) = bvh.intersect(r, f32::INFINITY) else {
                    continue;
                };
                let after = f32::from_bits(h.t.to_bits() + 1);
                assert!(bvh.occluded(r, after), "{bvh_name}: {r:?} hit at {}", h.t);
                assert!(!bvh.occluded(r, h.t), "{bvh_name}: {r:?} hit at {}", h.t);
                let mut out = [false];
                bvh.occluded_packet(std::slice::from_ref(r), after, &mut out);
                assert!(out[0], "{bvh_name}: packet, {r:?} hit at {}", h.t);
                checked += 1;
            }
        }
    }
    assert!(checked > 1000, "{checked} rays checked");
}

/// A ray with a NaN, infinite or zero direction, or a NaN origin, has nowhere to go: every
/// query answers "nothing" without walking the tree (the visiting traversal reports no node).
#[test]
fn invalid_rays_get_no_hit_and_visit_no_node() {
    let tris = shapes::icosphere(3);
    let bvh = Bvh::build(&tris, &tracery::bvh::BuildOptions::sah());
    let nan = f32::NAN;
    for ray in [
        Ray::new(Vec3::new(0.0, 0.0, -3.0), Vec3::new(nan, 0.0, 1.0)),
        Ray::new(
            Vec3::new(0.0, 0.0, -3.0),
            Vec3::new(0.0, f32::INFINITY, 1.0),
        ),
        Ray::new(Vec3::new(0.0, 0.0, -3.0), Vec3::ZERO),
        Ray::new(Vec3::new(nan, 0.0, -3.0), Vec3::Z),
    ] {
        assert!(bvh.intersect(&ray, f32::INFINITY).is_none(), "{ray:?}");
        assert!(!bvh.occluded(&ray, f32::INFINITY), "{ray:?}");
        assert_eq!(
            bvh.transmittance(&ray, f32::INFINITY, |_, _| Vec3::ZERO),
            Vec3::ONE
        );
        let mut visits = 0;
        assert!(
            bvh.intersect_visit(&ray, f32::INFINITY, |_| visits += 1)
                .is_none()
        );
        assert_eq!(visits, 0, "{ray:?}: no node visited");
        let mut out = [Some(tracery::bvh::Hit {
            t: 1.0,
            prim: 0,
            u: 0.0,
            v: 0.0,
        })];
        bvh.intersect_packet(&[ray], f32::INFINITY, &mut out);
        assert!(out[0].is_none(), "{ray:?}");
        let mut blocked = [true];
        bvh.occluded_packet(&[ray], f32::INFINITY, &mut blocked);
        assert!(!blocked[0], "{ray:?}");
    }
    // The same ray made valid hits: the checks above are not vacuous.
    assert!(
        bvh.intersect(&Ray::new(Vec3::new(0.0, 0.0, -3.0), Vec3::Z), f32::INFINITY)
            .is_some()
    );
}

/// Every binary leaf's triangles, read from the blocks of the traversal layout (the only copy
/// the tree keeps), are the caller's triangles of its slots, each in exactly one leaf and
/// inside that leaf's box; nothing comes from an inner node. Left-out triangles (non-finite,
/// zero-area) appear nowhere.
#[test]
fn leaf_triangles_are_the_callers_triangles_of_each_slot() {
    // A tree of many leaves, and one that is a single leaf (three triangles left).
    for size in [3000, 5] {
        let mut tris = shapes::random_soup(size, 0.2, 9);
        tris[0] = [Vec3::splat(f32::NAN), Vec3::ONE, Vec3::ZERO];
        tris[1] = [Vec3::ONE; 3];
        let root_leaf = Bvh::build(&tris, &tracery::bvh::BuildOptions::sah()).nodes[0].is_leaf();
        assert_eq!(root_leaf, size == 5);
        leaf_triangles_match(&tris);
    }
}

fn leaf_triangles_match(tris: &[[Vec3; 3]]) {
    for (name, bvh) in common::all_bvhs(tris) {
        let mut seen = vec![0u32; tris.len()];
        for (i, n) in bvh.nodes.iter().enumerate() {
            if i == 1 {
                continue;
            }
            let leaf: Vec<_> = bvh.leaf_triangles(i as u32).collect();
            if !n.is_leaf() {
                assert!(leaf.is_empty(), "{name}: inner node {i}");
                continue;
            }
            assert_eq!(leaf.len(), n.count as usize, "{name}: leaf {i}");
            let b = n.aabb();
            for (k, (prim, t)) in leaf.into_iter().enumerate() {
                assert_eq!(prim, bvh.prim_ids[n.first as usize + k], "{name}: leaf {i}");
                assert_eq!(
                    t.map(Vec3::from),
                    tris[prim as usize],
                    "{name}: triangle {prim}"
                );
                assert!(
                    t.iter()
                        .all(|v| b.min.cmple(*v).all() && v.cmple(b.max).all())
                );
                seen[prim as usize] += 1;
            }
        }
        for (p, &count) in seen.iter().enumerate() {
            assert_eq!(count, u32::from(p > 1), "{name}: triangle {p}");
        }
    }
}

/// Trees refitted to moved triangles answer as brute force over the moved triangles does:
/// closest hits bit for bit and occlusion, on every kernel and both builders, for a sphere
/// whose vertices each moved by up to 1% of its size and for a soup whose triangles moved far
/// apart (a large move: the refitted tree is worse, never wrong).
#[test]
fn refitted_trees_agree_with_brute_force() {
    let sphere = shapes::icosphere(4);
    let soup = shapes::random_soup(1500, 0.1, 4);
    for (name, tris, reach) in [("sphere", sphere, 0.02f32), ("soup", soup, 0.5)] {
        // Each vertex moved by a function of its position, so vertices shared by triangles
        // move together.
        let moved: Vec<[Vec3; 3]> = tris
            .iter()
            .map(|t| {
                t.map(|v| {
                    let h = |k: u32| {
                        let bits = v.x.to_bits()
                            ^ v.y.to_bits().rotate_left(11)
                            ^ v.z.to_bits().rotate_left(22)
                            ^ k.wrapping_mul(0x9e37_79b9);
                        let x = bits.wrapping_mul(0x85eb_ca6b) ^ (bits >> 13);
                        (x as f32 / u32::MAX as f32 - 0.5) * reach
                    };
                    v + Vec3::new(h(1), h(2), h(3))
                })
            })
            .collect();
        let rays = common::random_rays(&moved, 4000, 5);
        let bf = BruteForce::new(&moved);
        for options in common::both_builders() {
            let mut bvh = Bvh::build(&tris, &options);
            let r = bvh.refit(&moved).unwrap();
            assert!(r.sah_cost.is_finite());
            for (kernel, k) in common::every_kernel(&bvh) {
                common::assert_matches_brute_force(
                    &format!("{name} refitted, {kernel}"),
                    &moved,
                    &[&k],
                    &rays,
                );
                for (i, ray) in rays.iter().enumerate().step_by(3) {
                    let t_max = 0.1 + (i % 9) as f32 * 0.2;
                    assert_eq!(
                        k.occluded(ray, t_max),
                        !bf.all_hits(ray, t_max).is_empty(),
                        "{name} refitted, {kernel}, shadow ray {i}"
                    );
                }
            }
        }
    }
}
