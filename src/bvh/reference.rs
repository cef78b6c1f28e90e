//! Brute force: the simple answers the BVH is checked against.
//!
//! Every triangle is tested with the same watertight test the BVH uses. To keep checks of
//! millions of rays against the 202k-triangle dragon within minutes, the scan first runs the
//! test's edge-function stage on four triangles at once, in exactly the f32 operations of the
//! scalar test, and only the triangles it cannot reject go to the scalar test itself: the
//! answers are identical to testing each triangle alone.

use glam::{BVec4A, Vec3, Vec3A, Vec4};

use super::Hit;
use crate::geometry::{PreparedRay, Ray, intersect_triangle, intersect_triangle_t, is_degenerate};

/// Every triangle of a list, tested one by one. Triangles with a non-finite vertex or zero
/// area are left out, as the BVH leaves them out.
pub struct BruteForce {
    tris: Vec<[Vec3A; 3]>,
    ids: Vec<u32>,
    /// Groups of four triangles, component by component: `[vertex * 3 + axis]`.
    groups: Vec<[Vec4; 9]>,
}

impl BruteForce {
    /// Keeps the finite triangles of `triangles` (their indices are those of the list).
    pub fn new(triangles: &[[Vec3; 3]]) -> Self {
        let (tris, ids) = triangles
            .iter()
            .enumerate()
            .filter(|(_, t)| t.iter().all(|v| v.is_finite()) && !is_degenerate(t))
            .map(|(i, t)| (t.map(Vec3A::from), i as u32))
            .unzip();
        let tris: Vec<[Vec3A; 3]> = tris;
        let groups = tris
            .chunks(4)
            .map(|g| {
                std::array::from_fn(|c| {
                    let (vertex, axis) = (c / 3, c % 3);
                    Vec4::from_array(std::array::from_fn(|lane| {
                        g.get(lane).map_or(0.0, |t| t[vertex][axis])
                    }))
                })
            })
            .collect();
        Self { tris, ids, groups }
    }

    /// Calls `f(k)` for each triangle `k` the edge-function stage cannot reject (see the
    /// module docs), in index order.
    #[inline(always)]
    fn candidates(&self, pr: &PreparedRay, mut f: impl FnMut(usize)) {
        let [kx, ky, kz] = pr.k;
        let [sx, sy, _] = pr.shear.map(Vec4::splat);
        let o = pr.origin.to_array().map(Vec4::splat);
        let zero = Vec4::ZERO;
        for (g, v) in self.groups.iter().enumerate() {
            let sheared = |vertex: usize| {
                let z = v[vertex * 3 + kz] - o[kz];
                (
                    (v[vertex * 3 + kx] - o[kx]) - sx * z,
                    (v[vertex * 3 + ky] - o[ky]) - sy * z,
                )
            };
            let (ax, ay) = sheared(0);
            let (bx, by) = sheared(1);
            let (cx, cy) = sheared(2);
            let u = cx * by - cy * bx;
            let v = ax * cy - ay * cx;
            let w = bx * ay - by * ax;
            let any_zero: BVec4A = u.cmpeq(zero) | v.cmpeq(zero) | w.cmpeq(zero);
            let any_neg = u.cmplt(zero) | v.cmplt(zero) | w.cmplt(zero);
            let any_pos = u.cmpgt(zero) | v.cmpgt(zero) | w.cmpgt(zero);
            let mut keep = (!(any_neg & any_pos) | any_zero).bitmask();
            while keep != 0 {
                let k = g * 4 + keep.trailing_zeros() as usize;
                keep &= keep - 1;
                if k < self.tris.len() {
                    f(k);
                }
            }
        }
    }

    /// Closest hit at `0 < t < t_max`, with the BVH's tie rule: on equal `t` the lowest index
    /// wins (the scan goes in index order and only a strictly closer hit replaces the best).
    pub fn closest(&self, ray: &Ray, t_max: f32) -> Option<Hit> {
        let pr = PreparedRay::new(ray);
        let mut best_t = t_max;
        let mut best = None;
        self.candidates(&pr, |k| {
            let t = intersect_triangle_t(&pr, &self.tris[k], best_t);
            if t < best_t {
                best_t = t;
                best = Some(k);
            }
        });
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
        let mut out = Vec::new();
        self.candidates(&pr, |k| {
            let t = intersect_triangle_t(&pr, &self.tris[k], t_max);
            if t < t_max {
                out.push((self.ids[k], t));
            }
        });
        out
    }
}
