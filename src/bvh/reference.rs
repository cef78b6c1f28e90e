//! Brute force: the simple answers the BVH is checked against.

use glam::{Vec3, Vec3A};

use super::Hit;
use crate::geometry::{PreparedRay, Ray, intersect_triangle};

/// Closest hit by testing every triangle, with the same tie rule as the BVH (lowest index wins
/// on equal `t`). Triangles with a non-finite vertex are skipped, as the BVH leaves them out.
pub fn closest_hit_brute_force(triangles: &[[Vec3; 3]], ray: &Ray, t_max: f32) -> Option<Hit> {
    let pr = PreparedRay::new(ray);
    let mut best: Option<Hit> = None;
    for (i, t) in triangles.iter().enumerate() {
        if !(t[0].is_finite() && t[1].is_finite() && t[2].is_finite()) {
            continue;
        }
        let tri = t.map(Vec3A::from);
        let limit = best.map_or(t_max, |b| b.t.next_up());
        if let Some(h) = intersect_triangle(&pr, &tri, limit) {
            // Strictly closer wins; on a tie the earlier (lower) index stays.
            if best.is_none_or(|b| h.t < b.t) {
                best = Some(Hit {
                    t: h.t,
                    prim: i as u32,
                    u: h.u,
                    v: h.v,
                });
            }
        }
    }
    best
}

/// Every triangle hit at `0 < t < t_max`, by testing all of them: `(index, t)` in index order.
pub fn all_hits_brute_force(triangles: &[[Vec3; 3]], ray: &Ray, t_max: f32) -> Vec<(u32, f32)> {
    let pr = PreparedRay::new(ray);
    triangles
        .iter()
        .enumerate()
        .filter(|(_, t)| t.iter().all(|v| v.is_finite()))
        .filter_map(|(i, t)| {
            intersect_triangle(&pr, &t.map(Vec3A::from), t_max).map(|h| (i as u32, h.t))
        })
        .collect()
}
