//! Brute force: the simple answers the BVH is checked against.

use glam::{Vec3, Vec3A};

use super::Hit;
use crate::geometry::{PreparedRay, Ray, intersect_triangle, intersect_triangle_t};

/// Every triangle of a list, tested one by one. Triangles with a non-finite vertex are left
/// out, as the BVH leaves them out.
pub struct BruteForce {
    tris: Vec<[Vec3A; 3]>,
    ids: Vec<u32>,
}

impl BruteForce {
    /// Keeps the finite triangles of `triangles` (their indices are those of the list).
    pub fn new(triangles: &[[Vec3; 3]]) -> Self {
        let (tris, ids) = triangles
            .iter()
            .enumerate()
            .filter(|(_, t)| t.iter().all(|v| v.is_finite()))
            .map(|(i, t)| (t.map(Vec3A::from), i as u32))
            .unzip();
        Self { tris, ids }
    }

    /// Closest hit at `0 < t < t_max`, with the BVH's tie rule: on equal `t` the lowest index
    /// wins (the scan goes in index order and only a strictly closer hit replaces the best).
    pub fn closest(&self, ray: &Ray, t_max: f32) -> Option<Hit> {
        let pr = PreparedRay::new(ray);
        let mut best_t = t_max;
        let mut best = None;
        for (k, tri) in self.tris.iter().enumerate() {
            let t = intersect_triangle_t(&pr, tri, best_t);
            if t < best_t {
                best_t = t;
                best = Some(k);
            }
        }
        let k = best?;
        let h = intersect_triangle(&pr, &self.tris[k], best_t.next_up())?;
        Some(Hit {
            t: h.t,
            prim: self.ids[k],
            u: h.u,
            v: h.v,
        })
    }

    /// Every triangle hit at `0 < t < t_max`: `(index, t)` in index order.
    pub fn all_hits(&self, ray: &Ray, t_max: f32) -> Vec<(u32, f32)> {
        let pr = PreparedRay::new(ray);
        self.tris
            .iter()
            .zip(&self.ids)
            .filter_map(|(tri, &id)| {
                let t = intersect_triangle_t(&pr, tri, t_max);
                (t < t_max).then_some((id, t))
            })
            .collect()
    }
}

/// Closest hit by testing every triangle (see [`BruteForce::closest`]).
pub fn closest_hit_brute_force(triangles: &[[Vec3; 3]], ray: &Ray, t_max: f32) -> Option<Hit> {
    BruteForce::new(triangles).closest(ray, t_max)
}
