//! Stack-based traversal: closest hit (nearer child first), any hit, transmittance, and a
//! visiting variant that reports what it touched.

use glam::Vec3;

use super::pairs::{RayLanes, by_octant, hits, test_pair};
use super::{Bvh, BvhNode, MAX_DEPTH};
use crate::geometry::{PreparedRay, Ray, intersect_triangle, intersect_triangle_t};

/// The closest hit of a ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Distance along the ray.
    pub t: f32,
    /// Index of the triangle in the list the BVH was built from.
    pub prim: u32,
    /// Barycentric weight of the triangle's second vertex.
    pub u: f32,
    /// Barycentric weight of the triangle's third vertex.
    pub v: f32,
}

/// One step of a traversal, as reported by [`Bvh::intersect_visit`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Visit {
    /// The ray entered this node (its box was hit and not culled).
    Node {
        /// Index into [`Bvh::nodes`].
        index: u32,
        /// Depth of the node, root at 0.
        depth: u32,
    },
    /// The ray was tested against this triangle.
    Triangle {
        /// Index of the triangle in the caller's list.
        prim: u32,
        /// Whether the test found an intersection in range (not necessarily the closest).
        hit: bool,
    },
}

/// Boxes are culled only when they start clearly beyond the best hit so far: the slack keeps a
/// box whose entry distance rounds a hair past an equally distant hit, so ties in `t` still go
/// to the lowest triangle index exactly as brute force decides them.
const CULL_SLACK: f32 = 1.0 + 1.0 / 65536.0;

/// Entry distance of the box if the ray meets it before `limit`, else `+inf`.
#[inline(always)]
fn enter(node: &BvhNode, ray: &PreparedRay, limit: f32) -> f32 {
    let (near, far) = node.aabb().slab(ray);
    let near = near.max(0.0);
    if near <= far.min(limit) {
        near
    } else {
        f32::INFINITY
    }
}

impl Bvh {
    /// The closest triangle the ray hits at `0 < t < t_max`. Ties in `t` go to the lowest
    /// triangle index.
    #[inline]
    pub fn intersect(&self, ray: &Ray, t_max: f32) -> Option<Hit> {
        self.intersect_prepared(&PreparedRay::new(ray), t_max)
    }

    /// [`Bvh::intersect`] for a ray already prepared (saves the setup when one ray is traced
    /// against several structures).
    #[inline]
    pub fn intersect_prepared(&self, ray: &PreparedRay, t_max: f32) -> Option<Hit> {
        if self.tris.is_empty() || t_max.is_nan() || t_max <= 0.0 {
            return None;
        }
        if enter(&self.nodes[0], ray, t_max) == f32::INFINITY {
            return None;
        }
        let mut best = Best {
            t: t_max,
            slot: usize::MAX,
            id: u32::MAX,
        };
        if self.pairs.is_empty() {
            self.closest_in_leaf(ray, 0, self.tris.len() as u32, &mut best);
        } else {
            by_octant!(ray.neg_mask, closest_pairs, self, ray, &mut best);
        }
        self.finish(ray, &best, t_max)
    }

    /// Tests a leaf's triangles, keeping the closest (lowest index on ties).
    #[inline(always)]
    fn closest_in_leaf(&self, ray: &PreparedRay, first: u32, count: u32, best: &mut Best) {
        self.closest_in_leaf_seen(ray, first, count, best, &mut |_, _| {});
    }

    /// [`Bvh::closest_in_leaf`], telling `seen(prim, hit)` about every triangle tested.
    #[inline(always)]
    fn closest_in_leaf_seen(
        &self,
        ray: &PreparedRay,
        first: u32,
        count: u32,
        best: &mut Best,
        seen: &mut impl FnMut(u32, bool),
    ) {
        let limit = best.t.next_up();
        for slot in first as usize..(first + count) as usize {
            let t = intersect_triangle_t(ray, &self.tris[slot], limit);
            // Against the current best (it shrinks within the leaf); a miss (+inf) never
            // counts, even while the best is still +inf.
            let hit = t <= best.t && t != f32::INFINITY;
            seen(self.prim_ids[slot], hit);
            if hit {
                let id = self.prim_ids[slot];
                if t < best.t || id < best.id {
                    *best = Best { t, slot, id };
                }
            }
        }
    }

    /// [`Bvh::intersect`] that also calls `visit` for every node entered and every triangle
    /// tested, in traversal order.
    ///
    /// This walks the node tree of record ([`Bvh::nodes`]) one box at a time: it is the simple
    /// traversal, kept for debugging, and its hits equal [`Bvh::intersect`]'s (a test checks).
    pub fn intersect_visit(
        &self,
        ray: &Ray,
        t_max: f32,
        mut visit: impl FnMut(Visit),
    ) -> Option<Hit> {
        let ray = &PreparedRay::new(ray);
        if self.tris.is_empty() || t_max.is_nan() || t_max <= 0.0 {
            return None;
        }
        let mut best = Best {
            t: t_max,
            slot: usize::MAX,
            id: u32::MAX,
        };
        let nodes = &self.nodes[..];
        if enter(&nodes[0], ray, t_max) == f32::INFINITY {
            return None;
        }
        // Each entry keeps the entry distance, so a pop can skip a box that now starts beyond
        // the best hit without testing it again.
        let mut stack = [(0u32, 0.0f32); MAX_DEPTH];
        let mut depths = [0u32; MAX_DEPTH];
        let mut sp = 0usize;
        let mut current = 0u32;
        let mut depth = 0u32;
        loop {
            let node = &nodes[current as usize];
            visit(Visit::Node {
                index: current,
                depth,
            });
            if node.is_leaf() {
                self.closest_in_leaf_seen(
                    ray,
                    node.first,
                    node.count,
                    &mut best,
                    &mut |prim, hit| visit(Visit::Triangle { prim, hit }),
                );
            } else {
                let cull = best.t * CULL_SLACK;
                let first = node.first;
                let d0 = enter(&nodes[first as usize], ray, cull);
                let d1 = enter(&nodes[first as usize + 1], ray, cull);
                let (near, near_d, far, far_d) = if d1 < d0 {
                    (first + 1, d1, first, d0)
                } else {
                    (first, d0, first + 1, d1)
                };
                if near_d != f32::INFINITY {
                    depth += 1;
                    if far_d != f32::INFINITY {
                        stack[sp] = (far, far_d);
                        depths[sp] = depth;
                        sp += 1;
                    }
                    current = near;
                    continue;
                }
            }
            // Pop, skipping boxes that now start beyond the best hit.
            loop {
                if sp == 0 {
                    return self.finish(ray, &best, t_max);
                }
                sp -= 1;
                let (n, d) = stack[sp];
                if d <= best.t * CULL_SLACK {
                    current = n;
                    depth = depths[sp];
                    break;
                }
            }
        }
    }

    /// The hit record of the best triangle, with its barycentric coordinates.
    fn finish(&self, ray: &PreparedRay, best: &Best, t_max: f32) -> Option<Hit> {
        if best.slot == usize::MAX || best.t.is_nan() || best.t >= t_max {
            return None;
        }
        let h = intersect_triangle(ray, &self.tris[best.slot], best.t.next_up())?;
        Some(Hit {
            t: h.t,
            prim: best.id,
            u: h.u,
            v: h.v,
        })
    }

    /// True when any triangle lies on the ray at `0 < t < t_max` (shadow rays).
    pub fn occluded(&self, ray: &Ray, t_max: f32) -> bool {
        let mut blocked = false;
        self.for_each_hit(ray, t_max, |_, _| {
            blocked = true;
            false
        });
        blocked
    }

    /// Light that passes along the ray up to `t_max`: the product of `pass(prim, t)` over every
    /// triangle the ray crosses at `0 < t < t_max`. Each triangle counts once, and a ray through
    /// a shared edge crosses exactly one of the two triangles (see
    /// [`crate::geometry::intersect_triangle`]). Stops as soon as nothing passes.
    pub fn transmittance(
        &self,
        ray: &Ray,
        t_max: f32,
        mut pass: impl FnMut(u32, f32) -> Vec3,
    ) -> Vec3 {
        let mut through = Vec3::ONE;
        self.for_each_hit(ray, t_max, |prim, t| {
            through *= pass(prim, t);
            through.max_element() > 0.0
        });
        through
    }

    /// Calls `f(prim, t)` for every triangle hit at `0 < t < t_max`, in no particular order,
    /// until `f` returns false.
    pub fn for_each_hit(&self, ray: &Ray, t_max: f32, mut f: impl FnMut(u32, f32) -> bool) {
        if self.tris.is_empty() || t_max.is_nan() || t_max <= 0.0 {
            return;
        }
        let ray = PreparedRay::new(ray);
        if enter(&self.nodes[0], &ray, t_max) == f32::INFINITY {
            return;
        }
        if self.pairs.is_empty() {
            self.hits_in_leaf(&ray, 0, self.tris.len() as u32, t_max, &mut f);
        } else {
            by_octant!(ray.neg_mask, all_hits_pairs, self, &ray, t_max, &mut f);
        }
    }

    /// Reports a leaf's hits; false when `f` asked to stop.
    #[inline(always)]
    fn hits_in_leaf(
        &self,
        ray: &PreparedRay,
        first: u32,
        count: u32,
        t_max: f32,
        f: &mut impl FnMut(u32, f32) -> bool,
    ) -> bool {
        for slot in first as usize..(first + count) as usize {
            let t = intersect_triangle_t(ray, &self.tris[slot], t_max);
            if t < t_max && !f(self.prim_ids[slot], t) {
                return false;
            }
        }
        true
    }
}

/// The best hit so far of a closest-hit traversal.
struct Best {
    t: f32,
    slot: usize,
    id: u32,
}

/// Closest hit over the pair layout, nearer child first (the root box was already entered).
/// Stack entries are children still to visit, inner or leaf, with their entry distance.
#[inline(always)]
fn closest_pairs<const NX: bool, const NY: bool, const NZ: bool>(
    bvh: &Bvh,
    ray: &PreparedRay,
    best: &mut Best,
) {
    let lanes = RayLanes::new(ray);
    let pairs = &bvh.pairs[..];
    // Entries name a child by its parent pair and slot (`pair * 2 + slot`), with its entry
    // distance: 8 bytes, so the stack a ray starts with is small to set up.
    let mut stack = [(0u32, 0.0f32); MAX_DEPTH];
    let mut sp = 0usize;
    let mut current = 0u32;
    'descend: loop {
        let n = &pairs[current as usize];
        let acc = test_pair::<NX, NY, NZ>(n, &lanes, best.t * CULL_SLACK);
        let (d0, d1) = (acc.x, acc.y);
        let pick = match hits(acc) {
            0 => None,
            1 => Some(0),
            2 => Some(1),
            _ => {
                let (near, far, far_d) = if d1 < d0 { (1, 0, d0) } else { (0, 1, d1) };
                stack[sp] = (current * 2 + far, far_d);
                sp += 1;
                Some(near as usize)
            }
        };
        if let Some(k) = pick {
            if n.count[k] == 0 {
                current = n.child[k];
                continue 'descend;
            }
            bvh.closest_in_leaf(ray, n.child[k], n.count[k], best);
        }
        // Pop, skipping entries that now start beyond the best hit; leaves are tested here.
        loop {
            if sp == 0 {
                return;
            }
            sp -= 1;
            let (entry, dist) = stack[sp];
            if dist > best.t * CULL_SLACK {
                continue;
            }
            let parent = &pairs[(entry / 2) as usize];
            let k = (entry & 1) as usize;
            if parent.count[k] == 0 {
                current = parent.child[k];
                continue 'descend;
            }
            bvh.closest_in_leaf(ray, parent.child[k], parent.count[k], best);
        }
    }
}

/// Every hit over the pair layout; stops when `f` returns false.
#[inline(always)]
fn all_hits_pairs<const NX: bool, const NY: bool, const NZ: bool>(
    bvh: &Bvh,
    ray: &PreparedRay,
    t_max: f32,
    f: &mut impl FnMut(u32, f32) -> bool,
) {
    let lanes = RayLanes::new(ray);
    let pairs = &bvh.pairs[..];
    let mut stack = [0u32; MAX_DEPTH];
    let mut sp = 0usize;
    let mut current = 0u32;
    loop {
        let n = &pairs[current as usize];
        let mask = hits(test_pair::<NX, NY, NZ>(n, &lanes, t_max));
        let mut next = u32::MAX;
        for k in 0..2 {
            if mask & (1 << k) == 0 {
                continue;
            }
            if n.count[k] > 0 {
                if !bvh.hits_in_leaf(ray, n.child[k], n.count[k], t_max, f) {
                    return;
                }
            } else if next == u32::MAX {
                next = n.child[k];
            } else {
                stack[sp] = n.child[k];
                sp += 1;
            }
        }
        if next != u32::MAX {
            current = next;
            continue;
        }
        if sp == 0 {
            return;
        }
        sp -= 1;
        current = stack[sp];
    }
}
