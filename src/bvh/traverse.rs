//! The queries: closest hit, any hit, transmittance and every hit over the 8-wide layout
//! ([`super::wide`]), and a visiting variant over the binary tree of record that reports what
//! it touched.

use glam::{Vec3, Vec3A};

use super::tile::{PACKET, RayTile};
use super::wide::kernel;
use super::wide::packet::Bests;
use super::wide::traverse::{Best as Best8, Visits};
use super::{Bvh, BvhNode, MAX_DEPTH};
use crate::geometry::{PreparedRay, Ray, intersect_triangle, intersect_triangle_t, shear_axis};

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

impl Hit {
    /// The hit a closest-hit walk found, if any.
    #[inline(always)]
    fn of(best: Best8, t_max: f32) -> Option<Hit> {
        if best.prim == u32::MAX || best.t.is_nan() || best.t >= t_max {
            return None;
        }
        Some(Hit {
            t: best.t,
            prim: best.prim,
            u: best.u,
            v: best.v,
        })
    }
}

/// Calls `f(ids, rays)` for lists of up to [`PACKET`] of the `items`' rays (`ray` finds an
/// item's), `ids` their indices in `items`: every item once, the rays sorted by axis
/// permutation (the largest direction component's axis and sign, as the triangle test picks
/// them), so that rays tested in groups of one permutation fill their groups.
fn by_permutation<T>(items: &[T], ray: impl Fn(&T) -> &Ray, mut f: impl FnMut(&[u32], &[Ray])) {
    const KEYS: usize = 6;
    // NaN directions land in some bucket; the query leaves such rays out.
    let key = |r: &Ray| {
        let (kz, negative) = shear_axis(r.dir);
        2 * kz + negative as usize
    };
    let mut count = [0usize; KEYS + 1];
    for item in items {
        count[key(ray(item)) + 1] += 1;
    }
    for k in 0..KEYS {
        count[k + 1] += count[k];
    }
    let mut ids = vec![0u32; items.len()];
    for (i, item) in items.iter().enumerate() {
        let k = key(ray(item));
        ids[count[k]] = i as u32;
        count[k] += 1;
    }
    let mut list = [Ray::new(Vec3::ZERO, Vec3::X); PACKET];
    for chunk in ids.chunks(PACKET) {
        for (l, &i) in list.iter_mut().zip(chunk) {
            *l = *ray(&items[i as usize]);
        }
        f(chunk, &list[..chunk.len()]);
    }
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

use super::wide::traverse::CULL_SLACK;

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
    /// Whether a query of `ray` up to `t_max` walks the tree, and how: `None` when it can
    /// hit nothing (an empty tree, a `t_max` that is NaN or not positive, a ray with a NaN or
    /// infinite origin or direction, or a zero direction), else whether the ray needs the box
    /// test's NaN rule ([`kernel::check_ray`]).
    #[inline(always)]
    fn query_ray(&self, ray: &Ray, t_max: f32) -> Option<bool> {
        if self.is_empty() || t_max.is_nan() || t_max <= 0.0 {
            return None;
        }
        kernel::check_ray(ray)
    }

    /// The closest triangle the ray hits at `0 < t < t_max`. Ties in `t` go to the lowest
    /// triangle index. A ray with a NaN or infinite origin or direction, or a zero direction,
    /// hits nothing and walks no tree.
    #[inline]
    pub fn intersect(&self, ray: &Ray, t_max: f32) -> Option<Hit> {
        let safe = self.query_ray(ray, t_max)?;
        Hit::of(self.wide.closest::<false>(ray, t_max, safe), t_max)
    }

    /// [`Bvh::intersect`] for a ray whose neighbours take other paths through the tree: a
    /// path tracer's bounces, drawn at random from each surface's reflection. The same hit
    /// ([`Bvh::intersect`]'s, bit for bit) by a walk that leans less on the CPU's branch
    /// predictor (see [`crate::bvh::wide::traverse`]): faster for such rays (the secondary
    /// rays of `tracery bench`), slower for coherent ones such as a camera's, whose
    /// neighbours teach the predictor their path.
    #[inline]
    pub fn intersect_incoherent(&self, ray: &Ray, t_max: f32) -> Option<Hit> {
        let safe = self.query_ray(ray, t_max)?;
        Hit::of(self.wide.closest::<true>(ray, t_max, safe), t_max)
    }

    /// [`Bvh::intersect_incoherent`] of a batch of rays (a path tracer's bounces, one from each
    /// path of a batch), into `out` (one hit per ray, each the hit the ray gets alone).
    ///
    /// Where the whole tree is one leaf (a scene of a few dozen triangles, see
    /// [`crate::bvh::wide`]) and the kernel has a group test, up to [`PACKET`] rays at a time
    /// are grouped by axis permutation and each group tested against every triangle at once,
    /// instead of each ray against the triangles eight at a time.
    pub fn intersect_batch(&self, rays: &[Ray], out: &mut [Option<Hit>]) {
        assert_eq!(rays.len(), out.len(), "one result per ray");
        if self.wide.groups_root_leaf_rays() {
            by_permutation(
                rays,
                |r| r,
                |ids, list| {
                    let bests = self.root_leaf_rays(list, |_| f32::INFINITY);
                    for (i, &id) in ids.iter().enumerate() {
                        out[id as usize] = match &bests {
                            Some((b, active)) if active >> i & 1 == 1 => {
                                Hit::of(b.best(i), f32::INFINITY)
                            }
                            _ => None,
                        };
                    }
                },
            );
            return;
        }
        for (ray, o) in rays.iter().zip(out) {
            *o = self.intersect_incoherent(ray, f32::INFINITY);
        }
    }

    /// [`Bvh::occluded`] of a batch of rays, each with its own `t_max` (a path tracer's shadow
    /// rays, from each path of a batch), into `out` (each the answer the ray gets alone). A
    /// tree that is one leaf takes the rays in groups, as [`Bvh::intersect_batch`] does.
    pub fn occluded_batch(&self, rays: &[(Ray, f32)], out: &mut [bool]) {
        assert_eq!(rays.len(), out.len(), "one result per ray");
        if self.wide.groups_root_leaf_rays() {
            by_permutation(
                rays,
                |r| &r.0,
                |ids, list| {
                    let limit = |i: usize| rays[ids[i] as usize].1;
                    let bests = self.root_leaf_rays(list, limit);
                    for (i, &id) in ids.iter().enumerate() {
                        // Closer than the ray's own limit: something lies on it (a hit at the
                        // limit itself ties and is kept, but does not count).
                        out[id as usize] = bests
                            .as_ref()
                            .is_some_and(|(b, active)| active >> i & 1 == 1 && b.t[i] < limit(i));
                    }
                },
            );
            return;
        }
        for ((ray, t_max), o) in rays.iter().zip(out) {
            *o = self.occluded(ray, *t_max);
        }
    }

    /// The closest hits of up to [`PACKET`] rays, ray `i` below `t_max(i)`, against the root
    /// leaf in groups ([`crate::bvh::wide::WideBvh::root_leaf_rays`]), with the rays that
    /// query at all (valid rays, positive limits) as bits; `None` when none does.
    fn root_leaf_rays(&self, rays: &[Ray], t_max: impl Fn(usize) -> f32) -> Option<(Bests, u64)> {
        let mut bests = Bests::none(f32::INFINITY);
        let mut active = 0u64;
        for (i, ray) in rays.iter().enumerate() {
            let limit = t_max(i);
            if self.query_ray(ray, limit).is_some() {
                active |= 1 << i;
                bests.t[i] = limit;
            }
        }
        if active == 0 {
            return None;
        }
        self.wide.root_leaf_rays(rays, active, &mut bests);
        Some((bests, active))
    }

    /// [`Bvh::intersect`], adding to `visits` the nodes and triangle blocks its walk tested:
    /// a measure of the tree's quality for a set of rays that, unlike a time, does not depend
    /// on the machine or its load. Every kernel walks the same way; this runs the scalar one.
    pub fn intersect_counted(&self, ray: &Ray, t_max: f32, visits: &mut Visits) -> Option<Hit> {
        let safe = self.query_ray(ray, t_max)?;
        Hit::of(self.wide.closest_counted(ray, t_max, safe, visits), t_max)
    }

    /// Tests the triangles of leaf `node`, keeping the closest (lowest index on ties), telling
    /// `seen(prim, hit)` about every triangle tested.
    #[inline(always)]
    fn closest_in_leaf_seen(
        &self,
        ray: &PreparedRay,
        node: u32,
        best: &mut Best,
        seen: &mut impl FnMut(u32, bool),
    ) {
        let limit = best.t.next_up();
        for (id, tri) in self.leaf_triangles(node) {
            let t = intersect_triangle_t(ray, &tri, limit);
            // Against the current best (it shrinks within the leaf); a miss (+inf) never
            // counts, even while the best is still +inf.
            let hit = t <= best.t && t != f32::INFINITY;
            seen(id, hit);
            if hit && (t < best.t || id < best.id) {
                *best = Best { t, tri, id };
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
        // A zero, NaN or infinite ray has nowhere to go: no hit, and no node visited.
        if self.is_empty() || t_max.is_nan() || t_max <= 0.0 || !ray.is_valid() {
            return None;
        }
        let ray = &PreparedRay::new(ray);
        let mut best = Best {
            t: t_max,
            tri: [Vec3A::ZERO; 3],
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
                self.closest_in_leaf_seen(ray, current, &mut best, &mut |prim, hit| {
                    visit(Visit::Triangle { prim, hit })
                });
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
        if best.id == u32::MAX || best.t.is_nan() || best.t >= t_max {
            return None;
        }
        let h = intersect_triangle(ray, &best.tri, best.t.next_up())?;
        Some(Hit {
            t: h.t,
            prim: best.id,
            u: h.u,
            v: h.v,
        })
    }

    /// [`Bvh::intersect`] for many rays at once, `out[i]` for `rays[i]`: coherent rays (the
    /// camera rays of a tile of pixels) are traced in packets of up to [`PACKET`] that walk the
    /// tree together (see [`Bvh::intersect_tile`]).
    pub fn intersect_packet(&self, rays: &[Ray], t_max: f32, out: &mut [Option<Hit>]) {
        assert_eq!(rays.len(), out.len(), "one result per ray");
        for (rays, out) in rays.chunks(PACKET).zip(out.chunks_mut(PACKET)) {
            self.intersect_tile(RayTile::list(rays), t_max, |at, h| out[at] = h);
        }
    }

    /// [`Bvh::occluded`] for many rays at once, `out[i]` for `rays[i]`, in packets like
    /// [`Bvh::intersect_packet`] (see [`Bvh::occluded_tile`]).
    pub fn occluded_packet(&self, rays: &[Ray], t_max: f32, out: &mut [bool]) {
        assert_eq!(rays.len(), out.len(), "one result per ray");
        for (rays, out) in rays.chunks(PACKET).zip(out.chunks_mut(PACKET)) {
            self.occluded_tile(RayTile::list(rays), t_max, |at, b| out[at] = b);
        }
    }

    /// [`Bvh::intersect`] for a tile of coherent rays (the camera rays of up to 8 x 8 pixels,
    /// read where they lie in the image of rays): one packet walks the tree for all of them;
    /// a tile that cannot go together (other direction octants, invalid rays) is traced ray
    /// by ray. `out(at, hit)` is called once per ray, `at` its index in the slice the tile
    /// was made from. Every ray gets exactly the hit [`Bvh::intersect`] gives it.
    #[inline]
    pub fn intersect_tile(
        &self,
        tile: RayTile,
        t_max: f32,
        mut out: impl FnMut(usize, Option<Hit>),
    ) {
        // `out` called in each arm with its own answer: one call with the answer merged from
        // the arms assembled each hit on the stack and read it back whole, a store-forwarding
        // stall per ray (12% of the packets' time on the dragon).
        self.packets::<false>(tile, t_max, |b, i, at| match b {
            Some(b) if b.prim[i] != u32::MAX && b.t[i] < t_max => out(
                at,
                Some(Hit {
                    t: b.t[i],
                    prim: b.prim[i],
                    u: b.u[i],
                    v: b.v[i],
                }),
            ),
            Some(_) => out(at, None),
            None => out(at, self.intersect_alone(&tile.rays()[at], t_max)),
        });
    }

    /// [`Bvh::intersect`] for a ray of a tile that could not go as a packet: out of line, so
    /// that the single-ray dispatch is not inlined into the per-ray answer loop of every
    /// packet (it made that loop assemble each hit on the stack and read it back whole, a
    /// store-forwarding stall per ray: packets 12% slower).
    #[cold]
    #[inline(never)]
    fn intersect_alone(&self, ray: &Ray, t_max: f32) -> Option<Hit> {
        self.intersect(ray, t_max)
    }

    /// [`Bvh::occluded`] out of line (see [`Bvh::intersect_alone`]).
    #[cold]
    #[inline(never)]
    fn occluded_alone(&self, ray: &Ray, t_max: f32) -> bool {
        self.occluded(ray, t_max)
    }

    /// [`Bvh::occluded`] for a tile of coherent rays, traced like [`Bvh::intersect_tile`],
    /// each ray leaving the packet at its first hit: `out(at, blocked)` once per ray. Every
    /// ray gets exactly the answer [`Bvh::occluded`] gives it.
    #[inline]
    pub fn occluded_tile(&self, tile: RayTile, t_max: f32, mut out: impl FnMut(usize, bool)) {
        self.packets::<true>(tile, t_max, |b, i, at| {
            out(
                at,
                match b {
                    Some(b) => b.t[i] < t_max,
                    None => self.occluded_alone(&tile.rays()[at], t_max),
                },
            )
        });
    }

    /// The packet queries: the tile traced as one packet (first hits with `ANY`), then
    /// `answer(Some(bests), i, at)` for each ray (`i` its lane, `at` its index in the tile's
    /// slice); `answer(None, i, at)` for every ray when the tile cannot go together or nothing
    /// can be hit (the caller then traces the ray alone, which answers "nothing" at once).
    #[inline(always)]
    fn packets<const ANY: bool>(
        &self,
        tile: RayTile,
        t_max: f32,
        mut answer: impl FnMut(Option<&Bests>, usize, usize),
    ) {
        let nothing = self.is_empty() || t_max.is_nan() || t_max <= 0.0;
        let mut bests = Bests::none(t_max);
        let traced = !nothing && self.wide.trace_packet::<ANY>(&tile, t_max, &mut bests);
        let bests = traced.then_some(&bests);
        tile.for_each(|i, at| answer(bests, i, at));
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
    /// until `f` returns false. A NaN, infinite or zero ray hits nothing.
    pub fn for_each_hit(&self, ray: &Ray, t_max: f32, mut f: impl FnMut(u32, f32) -> bool) {
        let Some(safe) = self.query_ray(ray, t_max) else {
            return;
        };
        self.wide.each_hit(ray, t_max, safe, &mut f);
    }
}

/// The best hit so far of the visiting traversal.
struct Best {
    t: f32,
    tri: [Vec3A; 3],
    id: u32,
}

#[cfg(all(test, target_arch = "x86_64"))]
mod tests {
    use glam::Vec3;

    use crate::bvh::wide::Kernel;
    use crate::bvh::{BuildOptions, Bvh, RayTile};
    use crate::cpu::take_denormal_flag;
    use crate::geometry::Ray;
    use crate::geometry::shapes;

    /// Tracing takes no denormal operand (a microcode assist per instruction on Intel CPUs; see
    /// [`take_denormal_flag`]) with any kernel this CPU runs: closest hits, occlusion and 8x8
    /// packets of camera rays at a sphere inside a soup of triangles, on this thread.
    #[test]
    fn tracing_takes_no_denormal_operand() {
        let mut tris = shapes::icosphere(4);
        tris.extend(shapes::random_soup(5_000, 3.0, 11));
        let mut bvh = Bvh::build(&tris, &BuildOptions::sah());
        let side = 64;
        let eye = Vec3::new(0.3, 0.2, 6.0);
        let rays: Vec<Ray> = (0..side * side)
            .map(|i| {
                let at = |k: usize| (k as f32 + 0.5) / side as f32 * 2.0 - 1.0;
                Ray::new(eye, Vec3::new(at(i % side), at(i / side), -2.0))
            })
            .collect();
        for kernel in Kernel::available() {
            bvh.set_kernel(kernel).expect("an available kernel");
            take_denormal_flag();
            let hits = rays
                .iter()
                .filter(|r| bvh.intersect(r, f32::INFINITY).is_some())
                .count();
            let blocked = rays
                .iter()
                .filter(|r| bvh.occluded(r, f32::INFINITY))
                .count();
            let mut tiled = 0;
            for y in (0..side).step_by(8) {
                for x in (0..side).step_by(8) {
                    let tile = RayTile::new(&rays[y * side + x..], side, 8, 8).expect("a tile");
                    bvh.intersect_tile(tile, f32::INFINITY, |_, h| tiled += h.is_some() as usize);
                    bvh.occluded_tile(tile, f32::INFINITY, |_, b| tiled += b as usize);
                }
            }
            assert!(
                !take_denormal_flag(),
                "the {kernel} kernel took a denormal operand"
            );
            assert!(hits > 0 && hits < rays.len(), "{hits} hits");
            assert_eq!((blocked, tiled), (hits, 2 * hits), "{kernel}");
        }
    }
}
