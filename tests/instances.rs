//! Meshes placed many times over two levels of trees: the closest hits and occlusion agree
//! with brute force, with rotations, non-uniform scales, mirrors and composed (deep)
//! transforms; bad placements are refused by name; an instance costs a few hundred bytes.

mod common;

use std::sync::Arc;

use glam::{Affine3A, Quat, Vec3};
use tracery::bvh::{BruteForce, BuildOptions, Bvh, Instance, InstanceError, TwoLevel};
use tracery::geometry::Ray;
use tracery::geometry::shapes;

/// Three meshes and fourteen placements of them: a grid, a rotation, a non-uniform scale, a
/// mirror, a chain of six composed transforms (a deep node hierarchy), and copies that tie.
fn scene() -> (Vec<Vec<[Vec3; 3]>>, Vec<Instance>) {
    let meshes = vec![
        shapes::icosphere(2),
        shapes::random_soup(300, 0.2, 7),
        shapes::cube(),
    ];
    let mut instances = Vec::new();
    for k in 0..6u32 {
        let at = Vec3::new((k % 3) as f32 * 2.5, (k / 3) as f32 * 2.5, 0.0);
        instances.push(Instance {
            mesh: k % 3,
            to_world: Affine3A::from_translation(at),
        });
    }
    let mut deep = Affine3A::IDENTITY;
    for level in 0..6 {
        deep *= Affine3A::from_scale_rotation_translation(
            Vec3::splat(1.05),
            Quat::from_rotation_y(0.3 + level as f32 * 0.1),
            Vec3::new(0.3, 0.1, 0.2),
        );
    }
    for (mesh, to_world) in [
        (
            0,
            Affine3A::from_scale_rotation_translation(
                Vec3::ONE,
                Quat::from_euler(glam::EulerRot::XYZ, 0.4, 1.1, -0.3),
                Vec3::new(1.0, -2.5, 0.5),
            ),
        ),
        (
            1,
            Affine3A::from_scale_rotation_translation(
                Vec3::new(2.0, 0.5, 1.0),
                Quat::IDENTITY,
                Vec3::new(4.0, -2.0, 1.0),
            ),
        ),
        (
            2,
            Affine3A::from_scale_rotation_translation(
                Vec3::new(-1.0, 1.0, 1.5),
                Quat::from_rotation_z(0.7),
                Vec3::new(-2.0, 1.0, -1.0),
            ),
        ),
        (
            1,
            deep * Affine3A::from_translation(Vec3::new(0.0, 0.0, -3.0)),
        ),
        // Overlapping an earlier one, for ties and culling across instances.
        (0, Affine3A::from_translation(Vec3::new(0.2, 0.1, 0.0))),
        (2, Affine3A::from_scale(Vec3::new(3.0, 0.2, 3.0))),
        // Two more copies of the first placement: every hit on them is a tie, which the
        // lowest instance wins.
        (0, Affine3A::IDENTITY),
        (0, Affine3A::IDENTITY),
    ] {
        instances.push(Instance { mesh, to_world });
    }
    (meshes, instances)
}

fn flat(meshes: &[Vec<[Vec3; 3]>], instances: &[Instance]) -> (Vec<[Vec3; 3]>, Vec<(u32, u32)>) {
    let mut tris = Vec::new();
    let mut owner = Vec::new();
    for (i, inst) in instances.iter().enumerate() {
        for (p, t) in meshes[inst.mesh as usize].iter().enumerate() {
            tris.push(t.map(|v| inst.to_world.transform_point3(v)));
            owner.push((i as u32, p as u32));
        }
    }
    (tris, owner)
}

#[test]
fn instances_agree_with_brute_force() {
    let (meshes, instances) = scene();
    let trees: Vec<Arc<Bvh>> = meshes
        .iter()
        .map(|m| Arc::new(Bvh::build(m, &BuildOptions::sah())))
        .collect();
    let two = TwoLevel::new(trees, &instances).unwrap();
    let brute: Vec<BruteForce> = meshes.iter().map(|m| BruteForce::new(m)).collect();
    let (world, owner) = flat(&meshes, &instances);
    let world_brute = BruteForce::new(&world);
    let rays = common::random_rays(&world, 6000, 11);
    let (mut same_world, mut both_hit) = (0usize, 0usize);
    for (r, ray) in rays.iter().enumerate() {
        // Brute force over every instance, the ray carried into each mesh's frame as the
        // query carries it: the same hit, bit for bit.
        let mut want: Option<(u32, u32, f32)> = None;
        for (i, inst) in instances.iter().enumerate() {
            let m = inst.to_world.inverse();
            let local = Ray {
                origin: m.transform_point3(ray.origin),
                dir: m.transform_vector3(ray.dir),
            };
            if let Some(h) = brute[inst.mesh as usize].closest(&local, f32::INFINITY)
                && want.is_none_or(|w| h.t < w.2)
            {
                want = Some((i as u32, h.prim, h.t));
            }
        }
        let got = two.intersect(ray, f32::INFINITY);
        assert_eq!(
            got.map(|g| (g.instance, g.hit.prim, g.hit.t)),
            want,
            "ray {r}"
        );
        // Occlusion, for a few lengths.
        let t_max = 0.5 + (r % 7) as f32;
        let blocked = want.is_some_and(|w| w.2 < t_max);
        assert_eq!(two.occluded(ray, t_max), blocked, "shadow ray {r}");
        // Against the triangles moved into the world (rounded differently): the same
        // triangle, at the same distance to a few units in the last place, for almost every ray.
        if let (Some(g), Some(w)) = (got, world_brute.closest(ray, f32::INFINITY)) {
            both_hit += 1;
            if owner[w.prim as usize] == (g.instance, g.hit.prim) {
                same_world += 1;
                assert!(
                    (g.hit.t - w.t).abs() <= 1e-4 * w.t.max(1.0),
                    "ray {r}: {} against {}",
                    g.hit.t,
                    w.t
                );
            }
        }
    }
    assert!(both_hit > 2000, "{both_hit} rays hit");
    assert!(
        same_world as f64 >= 0.99 * both_hit as f64,
        "{same_world} of {both_hit} rays hit the same triangle as in the flattened scene"
    );
}

#[test]
fn bad_placements_are_refused_by_name() {
    let tree = Arc::new(Bvh::build(&shapes::cube(), &BuildOptions::sah()));
    let e = TwoLevel::new(
        vec![tree.clone()],
        &[Instance {
            mesh: 1,
            to_world: Affine3A::IDENTITY,
        }],
    )
    .unwrap_err();
    assert_eq!(
        e,
        InstanceError::NoMesh {
            instance: 0,
            mesh: 1
        }
    );
    let e = TwoLevel::new(
        vec![tree],
        &[
            Instance {
                mesh: 0,
                to_world: Affine3A::IDENTITY,
            },
            Instance {
                mesh: 0,
                to_world: Affine3A::from_scale(Vec3::new(1.0, 0.0, 1.0)),
            },
        ],
    )
    .unwrap_err();
    assert_eq!(e, InstanceError::Singular(1));
    assert!(e.to_string().contains("instance 1"));
}

/// A thousand placements of one mesh hold the mesh once: the instances cost at most 256
/// bytes each beyond it.
#[test]
fn an_instance_costs_a_few_hundred_bytes() {
    let tree = Arc::new(Bvh::build(&shapes::icosphere(4), &BuildOptions::sah()));
    let instances: Vec<Instance> = (0..1000)
        .map(|k| Instance {
            mesh: 0,
            to_world: Affine3A::from_translation(Vec3::new(
                (k % 10) as f32 * 3.0,
                (k / 10 % 10) as f32 * 3.0,
                (k / 100) as f32 * 3.0,
            )),
        })
        .collect();
    let two = TwoLevel::new(vec![tree], &instances).unwrap();
    let per = two.bytes() as f64 / 1000.0;
    println!("{per:.0} bytes per instance");
    assert!(per <= 256.0, "{per} bytes per instance");
    // Every instance can be hit: a ray down onto each sphere's top meets that instance.
    for k in [0usize, 7, 123, 999] {
        let c = Vec3::new(
            (k % 10) as f32 * 3.0,
            (k / 10 % 10) as f32 * 3.0,
            (k / 100) as f32 * 3.0,
        );
        let ray = Ray::new(c + Vec3::new(0.01, 0.02, 1.5), Vec3::new(0.0, 0.0, -1.0));
        let h = two.intersect(&ray, f32::INFINITY).unwrap();
        assert_eq!(h.instance, k as u32);
    }
}
