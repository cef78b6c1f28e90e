//! Secondary rays for `tracery bench`: the rays a path tracer traces after the camera's, made
//! from the canonical rays' hits. The canonical rays are coherent (neighbours in image order
//! take the same path through a tree, and a CPU predicts one from the other); these are not,
//! and a path-traced picture is mostly made of them.
//!
//! For every canonical ray that hits, at the hit point (taken from the triangle's own
//! barycentrics, moved off the surface by its rounding-error bound, as the renderer does):
//! - a **bounce ray**, cosine-weighted about the geometric normal on the camera's side (a
//!   diffuse bounce), traced for its closest hit;
//! - a **shadow ray** towards one point light above the mesh (two bounding-box diagonals
//!   above its centre along +y, off to one side), traced for occlusion. The light lies outside
//!   the bounds, so nothing lies beyond it and an unbounded occlusion query answers the
//!   segment's.
//!
//! The directions come from a fixed seed per ray: every engine and every run gets the same
//! rays.

use glam::{Vec2, Vec3, Vec3A};

use super::HitRecord;
use crate::geometry::{
    Aabb, PreparedRay, Ray, interpolation_error, intersect_triangle, offset_ray_origin,
};
use crate::rng::{SplitMix64, mix64};
use crate::sampling::cosine_direction;
use crate::scene::face_normal;

/// Seed of the bounce directions (each ray's stream is this mixed with its index).
const SEED: u64 = 0x5EC0_4DA7;

/// The secondary rays of one image, in the image order of the hits they start from.
#[derive(Clone, Debug, Default)]
pub struct SecondaryRays {
    /// Diffuse bounces from the hits (traced for the closest hit).
    pub bounce: Vec<Ray>,
    /// Rays from the same points towards the light, its position minus the origin (traced for
    /// occlusion).
    pub shadow: Vec<Ray>,
    /// The point light the shadow rays aim at.
    pub light: Vec3,
}

/// The point light of the shadow rays for a mesh with bounds `b`: two diagonals above the
/// centre along +y, a third of one off along +x and a quarter along +z (so that its rays are
/// not parallel to an axis-aligned mesh's faces).
pub fn light_above(b: &Aabb) -> Vec3 {
    let (lo, hi) = (Vec3::from(b.min), Vec3::from(b.max));
    let diagonal = (hi - lo).length();
    (lo + hi) * 0.5 + Vec3::new(0.33, 2.0, 0.25) * diagonal
}

/// The secondary rays of `rays` whose closest hits are `hits` (triangle indices of
/// `triangles`; misses and hits naming no triangle are skipped), with the shadow rays aimed at
/// [`light_above`]`(bounds)`.
pub fn secondary_rays(
    triangles: &[[Vec3; 3]],
    rays: &[Ray],
    hits: &[HitRecord],
    bounds: &Aabb,
) -> SecondaryRays {
    let light = light_above(bounds);
    let mut out = SecondaryRays {
        light,
        ..Default::default()
    };
    for (i, (ray, hit)) in rays.iter().zip(hits).enumerate() {
        let Some(tri) = triangles.get(hit.prim as usize) else {
            continue;
        };
        let Some(origin) = surface_point(ray, tri, hit.t) else {
            continue;
        };
        let mut n = face_normal(tri);
        if n.dot(ray.dir) > 0.0 {
            n = -n;
        }
        let origin = offset_ray_origin(origin.0, origin.1, n);
        let mut rng = SplitMix64::new(mix64(SEED ^ i as u64));
        let u = Vec2::new(rng.next_f32(), rng.next_f32());
        out.bounce.push(Ray::new(origin, cosine_direction(n, u)));
        out.shadow.push(Ray::new(origin, light - origin));
    }
    out
}

/// Where `ray` meets `tri` (found at about `t`), from the triangle's barycentrics, and the
/// point's rounding-error bound; `None` when the triangle test no longer finds the hit.
fn surface_point(ray: &Ray, tri: &[Vec3; 3], t: f32) -> Option<(Vec3, Vec3)> {
    let corners = tri.map(Vec3A::from);
    let h = intersect_triangle(&PreparedRay::new(ray), &corners, t.next_up().next_up())?;
    let b = [1.0 - h.u - h.v, h.u, h.v];
    let p = tri[0] * b[0] + tri[1] * b[1] + tri[2] * b[2];
    Some((p, interpolation_error(tri, b)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::canonical_rays;
    use crate::bvh::BruteForce;
    use crate::scene::Scene;

    /// The Cornell box's canonical rays, their brute-force hits as records, and the secondary
    /// rays made from them.
    fn cornell() -> (Scene, Vec<Ray>, Vec<HitRecord>, SecondaryRays) {
        let scene = Scene::cornell_box();
        let tris = &scene.mesh.triangles;
        let bounds = scene.mesh.bounds();
        let rays: Vec<Ray> = canonical_rays(&bounds).into_iter().step_by(61).collect();
        let bf = BruteForce::new(tris);
        let hits: Vec<HitRecord> = rays
            .iter()
            .map(|r| match bf.closest(r, f32::INFINITY) {
                Some(h) => HitRecord {
                    t: h.t,
                    prim: h.prim,
                },
                None => HitRecord::MISS,
            })
            .collect();
        let second = secondary_rays(tris, &rays, &hits, &bounds);
        (scene, rays, hits, second)
    }

    #[test]
    fn every_hit_gives_one_bounce_and_one_shadow_ray_from_its_side_of_the_surface() {
        let (scene, rays, hits, second) = cornell();
        let tris = &scene.mesh.triangles;
        let hitting: Vec<(&Ray, &HitRecord)> = rays
            .iter()
            .zip(&hits)
            .filter(|(_, h)| h.prim != HitRecord::MISS.prim)
            .collect();
        assert!(hitting.len() > 100 && hitting.len() < rays.len());
        assert_eq!(second.bounce.len(), hitting.len());
        assert_eq!(second.shadow.len(), hitting.len());
        let bounds = scene.mesh.bounds();
        assert!(
            second.light.y > bounds.max.y,
            "the light lies above the mesh"
        );
        let bf = BruteForce::new(tris);
        for (((ray, hit), bounce), shadow) in hitting.iter().zip(&second.bounce).zip(&second.shadow)
        {
            let tri = &tris[hit.prim as usize];
            let p = ray.origin + ray.dir * hit.t;
            let facing = -face_normal(tri) * face_normal(tri).dot(ray.dir).signum();
            // Near the hit, on the camera's side of the triangle's plane.
            assert!((bounce.origin - p).length() < 1e-3, "{p} {}", bounce.origin);
            assert!((bounce.origin - tri[0]).dot(facing) > 0.0);
            // A cosine-weighted direction about that side's normal, of unit length.
            assert!(bounce.dir.dot(facing) >= 0.0, "{bounce:?}");
            assert!((bounce.dir.length() - 1.0).abs() < 1e-5);
            // A flat triangle cannot be hit again by a ray leaving its front.
            if let Some(h) = bf.closest(bounce, f32::INFINITY) {
                assert_ne!(h.prim, hit.prim, "{bounce:?} hits where it starts");
            }
            assert_eq!(shadow.origin, bounce.origin);
            assert!((shadow.origin + shadow.dir - second.light).length() < 1e-4);
        }
    }

    #[test]
    fn the_directions_are_the_same_every_time_and_vary_from_ray_to_ray() {
        let (_, _, _, a) = cornell();
        let (_, _, _, b) = cornell();
        assert_eq!(a.bounce, b.bounce);
        let mut dirs: Vec<[u32; 3]> = a
            .bounce
            .iter()
            .map(|r| r.dir.to_array().map(f32::to_bits))
            .collect();
        dirs.sort_unstable();
        dirs.dedup();
        assert!(
            dirs.len() > a.bounce.len() * 99 / 100,
            "{} distinct",
            dirs.len()
        );
    }
}
