//! Two levels: meshes placed many times. Each mesh has its own tree (the bottom level, a
//! [`Bvh`] in the mesh's own frame), each placement (an [`Instance`]) a transform, and a top
//! level, a binary tree over the instances' world boxes, finds the instances a ray may meet.
//! A query walks the top level and, in each instance it enters, carries the ray into the
//! mesh's frame (origin and direction by the inverse transform; the direction is not
//! normalised, so distances along the ray are the same in both frames) and asks the mesh's
//! tree. A mesh placed a thousand times is held once: an instance costs its transforms and
//! its share of the top level ([`TwoLevel::bytes`]).

use std::sync::Arc;
use std::time::Instant;

use glam::{Affine3A, Vec3A};

use super::{Bvh, BvhNode, Hit};
use crate::geometry::{Aabb, PreparedRay, Ray};

/// A mesh placed in the world.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Instance {
    /// The mesh it places: an index into [`TwoLevel::meshes`].
    pub mesh: u32,
    /// From the mesh's frame to the world.
    pub to_world: Affine3A,
}

/// The closest hit of a ray among instances: which instance, and the hit in its mesh
/// (`hit.prim` is the triangle's index in the mesh's list, `hit.t` the distance along the
/// world ray).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InstanceHit {
    /// Index of the instance in [`TwoLevel::instances`].
    pub instance: u32,
    /// The hit in the instance's mesh.
    pub hit: Hit,
}

/// Why instances cannot be placed.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum InstanceError {
    /// An instance names a mesh past the list.
    NoMesh {
        /// The instance.
        instance: usize,
        /// The mesh it names.
        mesh: u32,
    },
    /// An instance's transform is not finite or cannot be inverted (a zero scale).
    Singular(usize),
    /// The instances hold more triangles than one list can number (`u32`).
    TooManyTriangles(u64),
}

impl std::fmt::Display for InstanceError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            InstanceError::NoMesh { instance, mesh } => {
                write!(
                    f,
                    "instance {instance} places mesh {mesh}, which does not exist"
                )
            }
            InstanceError::Singular(i) => write!(
                f,
                "instance {i}'s transform is not finite or cannot be inverted (a zero scale?)"
            ),
            InstanceError::TooManyTriangles(n) => write!(
                f,
                "the instances place {n} triangles, more than the {MAX_PLACED} one scene can number"
            ),
        }
    }
}

impl std::error::Error for InstanceError {}

/// Meshes, their instances, and the top-level tree over the instances.
///
/// The triangles of all instances are numbered in one list, instance by instance in order,
/// each instance's in its mesh's order ([`TwoLevel::intersect_global`]): the numbering of the
/// same instances flattened into one mesh.
#[derive(Clone, Debug)]
pub struct TwoLevel {
    /// Each mesh's tree, in the mesh's frame.
    pub meshes: Vec<Arc<Bvh>>,
    /// The mesh each instance places.
    mesh_of: Vec<u32>,
    /// Each instance's transform from the world to its mesh's frame.
    to_mesh: Vec<Affine3A>,
    /// The number, in the list of all instances' triangles, of each instance's first one.
    first: Vec<u32>,
    /// The top level: root at 0, slot 1 unused, sibling pairs from 2 on (as [`Bvh::nodes`]);
    /// a leaf's `first` and `count` index `order`.
    nodes: Vec<BvhNode>,
    /// Instance indices in leaf order.
    order: Vec<u32>,
    /// Wall-clock time of the top level's build, milliseconds.
    pub build_ms: f64,
}

/// The deepest the top level may grow (its build splits by count past this, halving each
/// time).
const TOP_DEPTH: usize = 64;

/// Bins of the top level's SAH.
const TOP_BINS: usize = 16;

/// The most triangles the instances of one [`TwoLevel`] may place, counted with repeats: every
/// one is numbered by a `u32`, and [`u32::MAX`] means no hit.
pub const MAX_PLACED: u64 = u32::MAX as u64 - 1;

impl TwoLevel {
    /// Places `instances` of `meshes` and builds the top level over their world boxes (a
    /// binned SAH, one instance per leaf). An error names an instance whose mesh does not
    /// exist or whose transform cannot be inverted, or says the instances place more
    /// triangles than [`MAX_PLACED`].
    pub fn new(meshes: Vec<Arc<Bvh>>, instances: &[Instance]) -> Result<Self, InstanceError> {
        let start = Instant::now();
        let mut to_mesh = Vec::with_capacity(instances.len());
        let mut boxes = Vec::with_capacity(instances.len());
        let mut first = Vec::with_capacity(instances.len());
        let mut placed = 0u64;
        for (i, inst) in instances.iter().enumerate() {
            let Some(mesh) = meshes.get(inst.mesh as usize) else {
                return Err(InstanceError::NoMesh {
                    instance: i,
                    mesh: inst.mesh,
                });
            };
            let inverse = inst.to_world.inverse();
            let finite = inst.to_world.is_finite() && inverse.is_finite();
            if !finite || inst.to_world.matrix3.determinant() == 0.0 {
                return Err(InstanceError::Singular(i));
            }
            to_mesh.push(inverse);
            boxes.push(world_box(&mesh.bounds(), &inst.to_world));
            first.push(placed as u32);
            placed += mesh.triangle_count() as u64;
            if placed > MAX_PLACED {
                return Err(InstanceError::TooManyTriangles(placed));
            }
        }
        let (nodes, order) = build_top(&boxes);
        Ok(TwoLevel {
            meshes,
            mesh_of: instances.iter().map(|i| i.mesh).collect(),
            to_mesh,
            first,
            nodes,
            order,
            build_ms: start.elapsed().as_secs_f64() * 1e3,
        })
    }

    /// Bytes the instances take beyond their meshes: each one's mesh, transform and first
    /// triangle's number, and the top level's nodes and order.
    pub fn bytes(&self) -> usize {
        std::mem::size_of_val(&self.mesh_of[..])
            + std::mem::size_of_val(&self.to_mesh[..])
            + std::mem::size_of_val(&self.first[..])
            + std::mem::size_of_val(&self.nodes[..])
            + std::mem::size_of_val(&self.order[..])
    }

    /// Number of instances.
    pub fn instance_count(&self) -> usize {
        self.mesh_of.len()
    }

    /// The mesh instance `i` places.
    pub fn mesh_of(&self, i: usize) -> u32 {
        self.mesh_of[i]
    }

    /// Instance `i`'s transform from the world to its mesh's frame.
    pub fn to_mesh(&self, i: usize) -> &Affine3A {
        &self.to_mesh[i]
    }

    /// Number of triangles the instances place, counted with repeats.
    pub fn triangle_count(&self) -> u64 {
        match (self.first.last(), self.mesh_of.last()) {
            (Some(&f), Some(&m)) => f as u64 + self.meshes[m as usize].triangle_count() as u64,
            _ => 0,
        }
    }

    /// The top level's nodes (as [`Bvh::nodes`]: root at 0, sibling pairs from 2 on; a
    /// leaf's `first` indexes [`TwoLevel::leaf_instance`]).
    pub fn top_nodes(&self) -> &[BvhNode] {
        &self.nodes
    }

    /// The instance at position `k` of the top level's leaf order.
    pub fn leaf_instance(&self, k: u32) -> u32 {
        self.order[k as usize]
    }

    /// Box around every instance (empty without any).
    pub fn bounds(&self) -> Aabb {
        if self.order.is_empty() {
            Aabb::EMPTY
        } else {
            self.nodes[0].aabb()
        }
    }

    /// `ray` carried into instance `i`'s mesh frame.
    #[inline]
    fn local(&self, i: usize, ray: &Ray) -> Ray {
        let m = &self.to_mesh[i];
        Ray {
            origin: m.transform_point3(ray.origin),
            dir: m.transform_vector3(ray.dir),
        }
    }

    /// Calls `visit(instance)` for each instance whose world box the ray enters before
    /// `limit()` (asked again before each box, so a closest-hit search can shrink it),
    /// nearest box first where two siblings are both entered.
    fn walk(&self, ray: &Ray, limit: impl FnMut() -> f32, visit: impl FnMut(u32) -> bool) {
        self.walk_seen(ray, limit, visit, |_, _| {});
    }

    /// [`TwoLevel::walk`], telling `seen(node, depth)` about every top-level node entered.
    fn walk_seen(
        &self,
        ray: &Ray,
        mut limit: impl FnMut() -> f32,
        mut visit: impl FnMut(u32) -> bool,
        mut seen: impl FnMut(u32, u32),
    ) {
        if self.order.is_empty() || !ray.is_valid() {
            return;
        }
        let p = PreparedRay::new(ray);
        let enter = |n: &BvhNode, limit: f32| {
            let (near, far) = n.aabb().slab(&p);
            let near = near.max(0.0);
            (near <= far.min(limit)).then_some(near)
        };
        let root = &self.nodes[0];
        if enter(root, limit()).is_none() {
            return;
        }
        seen(0, 0);
        if root.is_leaf() {
            // One instance: no walk (and no stack to set up).
            for &inst in &self.order[root.first as usize..(root.first + root.count) as usize] {
                if !visit(inst) {
                    return;
                }
            }
            return;
        }
        // A walk keeps at most one sibling per level: depth is at most `TOP_DEPTH` plus the
        // halvings by count past it (32 at most).
        let mut stack = [(0u32, 0.0f32, 0u32); TOP_DEPTH + 40];
        let mut sp = 0;
        stack[sp] = (0, 0.0, 0);
        sp += 1;
        while sp > 0 {
            sp -= 1;
            let (i, near, depth) = stack[sp];
            if near > limit() {
                continue;
            }
            if i != 0 {
                seen(i, depth);
            }
            let n = &self.nodes[i as usize];
            if n.is_leaf() {
                for &inst in &self.order[n.first as usize..(n.first + n.count) as usize] {
                    if !visit(inst) {
                        return;
                    }
                }
                continue;
            }
            let lim = limit();
            let (l, r) = (n.first, n.first + 1);
            let a = enter(&self.nodes[l as usize], lim).map(|t| (l, t, depth + 1));
            let b = enter(&self.nodes[r as usize], lim).map(|t| (r, t, depth + 1));
            // The farther pushed first, so the nearer is walked first.
            let (first, second) = match (a, b) {
                (Some(a), Some(b)) if b.1 < a.1 => (Some(a), Some(b)),
                (a, b) => (b, a),
            };
            for e in [first, second].into_iter().flatten() {
                stack[sp] = e;
                sp += 1;
            }
        }
    }

    /// The closest hit at `0 < t < t_max` among all instances; ties in `t` go to the lowest
    /// instance, then (within it) to the lowest triangle index. A NaN, infinite or zero ray
    /// hits nothing.
    pub fn intersect(&self, ray: &Ray, t_max: f32) -> Option<InstanceHit> {
        if t_max.is_nan() || t_max <= 0.0 {
            return None;
        }
        if let [only] = self.order[..] {
            // One instance: its mesh's tree tests its own root box; no top level to walk.
            let i = only as usize;
            let local = self.local(i, ray);
            return self.meshes[self.mesh_of[i] as usize]
                .intersect(&local, t_max)
                .map(|hit| InstanceHit {
                    instance: only,
                    hit,
                });
        }
        let best = std::cell::Cell::new(None::<InstanceHit>);
        let limit = || best.get().map_or(t_max, |b| b.hit.t);
        self.walk(ray, limit, |i| {
            let mesh = self.mesh_of[i as usize];
            let local = self.local(i as usize, ray);
            let current = best.get();
            // Up to and including the best distance, so a tie is seen and decided.
            let reach = current.map_or(t_max, |b| b.hit.t.next_up());
            if let Some(h) = self.meshes[mesh as usize].intersect(&local, reach) {
                offer(&best, i, h, t_max);
            }
            true
        });
        best.get()
    }

    /// [`TwoLevel::intersect`], the triangle numbered in the list of all instances'
    /// triangles (see [`TwoLevel`]).
    #[inline]
    pub fn intersect_global(&self, ray: &Ray, t_max: f32) -> Option<Hit> {
        self.intersect(ray, t_max).map(|h| self.global(h))
    }

    /// [`TwoLevel::intersect`], calling `visit` for every top-level node entered (instance
    /// `None`, its index among [`TwoLevel::top_nodes`]) and, in each instance `i` entered,
    /// for every node and triangle its mesh's walk visits ([`Bvh::intersect_visit`];
    /// `Some(i)`, indices in that mesh's tree): the work of the two levels, for the cost views
    /// and the debug ray.
    pub fn intersect_visit(
        &self,
        ray: &Ray,
        t_max: f32,
        mut visit: impl FnMut(Option<u32>, super::Visit),
    ) -> Option<InstanceHit> {
        if t_max.is_nan() || t_max <= 0.0 {
            return None;
        }
        let best = std::cell::Cell::new(None::<InstanceHit>);
        let visit = std::cell::RefCell::new(&mut visit);
        self.walk_seen(
            ray,
            || best.get().map_or(t_max, |b| b.hit.t),
            |i| {
                let local = self.local(i as usize, ray);
                let current = best.get();
                let reach = current.map_or(t_max, |b| b.hit.t.next_up());
                let mesh = &self.meshes[self.mesh_of[i as usize] as usize];
                let found =
                    mesh.intersect_visit(&local, reach, |v| (visit.borrow_mut())(Some(i), v));
                if let Some(h) = found {
                    offer(&best, i, h, t_max);
                }
                true
            },
            |index, depth| (visit.borrow_mut())(None, super::Visit::Node { index, depth }),
        );
        best.get()
    }

    /// The hit `h`, its triangle numbered in the list of all instances' triangles; under a
    /// mirroring instance, `u` and `v` swapped: the world's triangle lists the mesh's
    /// corners 1 and 2 the other way round, so its front face stays the front face.
    #[inline]
    pub fn global(&self, h: InstanceHit) -> Hit {
        let i = h.instance as usize;
        let mirrored = self.to_mesh[i].matrix3.determinant() < 0.0;
        let (u, v) = if mirrored {
            (h.hit.v, h.hit.u)
        } else {
            (h.hit.u, h.hit.v)
        };
        Hit {
            prim: self.first[i] + h.hit.prim,
            u,
            v,
            ..h.hit
        }
    }

    /// Calls `f(prim, t)` for every triangle hit at `0 < t < t_max` along the world ray (its
    /// number in the list of all instances' triangles), in no particular order, until `f`
    /// returns false.
    pub fn for_each_hit(&self, ray: &Ray, t_max: f32, mut f: impl FnMut(u32, f32) -> bool) {
        if t_max.is_nan() || t_max <= 0.0 {
            return;
        }
        let mut going = true;
        self.walk(
            ray,
            || t_max,
            |i| {
                let first = self.first[i as usize];
                let mesh = &self.meshes[self.mesh_of[i as usize] as usize];
                mesh.for_each_hit(&self.local(i as usize, ray), t_max, |prim, t| {
                    going = f(first + prim, t);
                    going
                });
                going
            },
        );
    }

    /// Whether any instance has a triangle at `0 < t < t_max` along the ray.
    pub fn occluded(&self, ray: &Ray, t_max: f32) -> bool {
        if t_max.is_nan() || t_max <= 0.0 {
            return false;
        }
        let mut blocked = false;
        self.walk(
            ray,
            || t_max,
            |i| {
                let mesh = &self.meshes[self.mesh_of[i as usize] as usize];
                blocked = mesh.occluded(&self.local(i as usize, ray), t_max);
                !blocked
            },
        );
        blocked
    }
}

/// Keeps `h`, a hit in instance `i`, when it is nearer than the best so far (or as near, in
/// a lower instance) and before `t_max`.
#[inline]
fn offer(best: &std::cell::Cell<Option<InstanceHit>>, i: u32, h: Hit, t_max: f32) {
    let better = match best.get() {
        None => true,
        Some(b) => h.t < b.hit.t || (h.t == b.hit.t && i < b.instance),
    };
    if better && h.t < t_max {
        best.set(Some(InstanceHit {
            instance: i,
            hit: h,
        }));
    }
}

/// The world box of a mesh box under a transform: the box's centre moved, and its half
/// extent through the transform's linear part with every entry made positive (Arvo 1990: the
/// box around the eight moved corners, in two products instead of eight).
fn world_box(b: &Aabb, m: &Affine3A) -> Aabb {
    if b.is_empty() {
        return Aabb::EMPTY;
    }
    let centre = m.transform_point3a((b.min + b.max) * 0.5);
    let half = (b.max - b.min) * 0.5;
    let l = &m.matrix3;
    let extent = l.x_axis.abs() * half.x + l.y_axis.abs() * half.y + l.z_axis.abs() * half.z;
    // Rounding in the products may leave a moved corner a little outside: widened by a few
    // units in the last place of the largest coordinate, so no ray that meets an instance's
    // triangles misses its box.
    let lo = centre - extent;
    let hi = centre + extent;
    let pad = Vec3A::splat(lo.abs().max(hi.abs()).max_element() * 4.0 * f32::EPSILON);
    Aabb {
        min: lo - pad,
        max: hi + pad,
    }
}

/// The top level over `boxes`: a binned SAH on the boxes' centres, and for nodes of at most
/// [`TOP_SWEEP`] instances an exact sweep over every split of their centres in order; one
/// instance per leaf (an empty box, an instance of an empty mesh, is left out of the tree).
fn build_top(boxes: &[Aabb]) -> (Vec<BvhNode>, Vec<u32>) {
    let mut order: Vec<u32> = (0..boxes.len() as u32)
        .filter(|&i| !boxes[i as usize].is_empty())
        .collect();
    let empty = BvhNode {
        min: [0.0; 3],
        first: 0,
        max: [0.0; 3],
        count: 0,
    };
    if order.is_empty() {
        return (vec![empty], order);
    }
    // The boxes in `order`'s order, moved with it as it is partitioned, so that every pass
    // over a node's instances reads them in sequence rather than through the indices.
    let mut items: Vec<Aabb> = order.iter().map(|&i| boxes[i as usize]).collect();
    let mut bin_of = vec![0u8; items.len()];
    let mut scratch = (vec![Aabb::EMPTY; items.len()], vec![0u32; items.len()]);
    let mut nodes = Vec::with_capacity(2 * order.len());
    nodes.extend([empty, empty]);
    // (node, start, end, depth, the centres' box): each node's box is made from its bins
    // (or its instances), and its children's centre boxes as it is split.
    let mut tasks = vec![(0usize, 0usize, order.len(), 0usize, centre_box(&items))];
    while let Some((node, start, end, depth, spread)) = tasks.pop() {
        let (items, order, bin_of) = (
            &mut items[start..end],
            &mut order[start..end],
            &mut bin_of[start..end],
        );
        if end - start == 1 {
            nodes[node].set_aabb(&items[0]);
            nodes[node].first = start as u32;
            nodes[node].count = 1;
            continue;
        }
        let extent = spread.max - spread.min;
        let axis = if extent.x >= extent.y && extent.x >= extent.z {
            0
        } else if extent.y >= extent.z {
            1
        } else {
            2
        };
        let split = if items.len() == 2 {
            Some((
                items[0].union(&items[1]),
                1,
                centre_box(&items[..1]),
                centre_box(&items[1..]),
            ))
        } else if !(extent[axis] > 0.0 && depth < TOP_DEPTH - 2) {
            None
        } else if items.len() <= TOP_SWEEP {
            Some(sweep_split(items, order, axis))
        } else {
            let scratch = (&mut scratch.0[start..end], &mut scratch.1[start..end]);
            binned_split(items, order, bin_of, scratch, &spread, axis)
        };
        let (bounds, half, left, right) = match split {
            Some(split) => split,
            None => {
                // All centres at one point (or too deep): halves by count, in centre order.
                let mut both: Vec<(Aabb, u32)> =
                    items.iter().copied().zip(order.iter().copied()).collect();
                both.sort_by(|a, b| key(&a.0, axis).total_cmp(&key(&b.0, axis)));
                for (k, (b, i)) in both.into_iter().enumerate() {
                    (items[k], order[k]) = (b, i);
                }
                let half = items.len() / 2;
                (
                    union_of(items),
                    half,
                    centre_box(&items[..half]),
                    centre_box(&items[half..]),
                )
            }
        };
        nodes[node].set_aabb(&bounds);
        let first = nodes.len();
        nodes.push(empty);
        nodes.push(empty);
        nodes[node].first = first as u32;
        nodes[node].count = 0;
        tasks.push((first, start, start + half, depth + 1, left));
        tasks.push((first + 1, start + half, end, depth + 1, right));
    }
    (nodes, order)
}

/// Nodes of at most this many instances are split by [`sweep_split`].
const TOP_SWEEP: usize = 12;

/// A split's outcome: the node's box, how many instances go left, and the two sides' centre
/// boxes.
type Split = (Aabb, usize, Aabb, Aabb);

/// Twice a box's centre along `axis` (the order of centres, without the halving).
#[inline]
fn key(b: &Aabb, axis: usize) -> f32 {
    b.min[axis] + b.max[axis]
}

/// The box around the centres of `items`.
fn centre_box(items: &[Aabb]) -> Aabb {
    let mut spread = Aabb::EMPTY;
    for b in items {
        spread.grow_point((b.min + b.max) * 0.5);
    }
    spread
}

/// The box around all of `boxes`.
fn union_of(boxes: &[Aabb]) -> Aabb {
    boxes.iter().fold(Aabb::EMPTY, |a, b| a.union(b))
}

/// The split of a few instances with the least SAH cost among every split of their centres
/// in order along `axis` (sorted in place, `order` with them).
fn sweep_split(items: &mut [Aabb], order: &mut [u32], axis: usize) -> Split {
    let n = items.len();
    // The positions sorted by key, then the boxes moved once (when out of order).
    let mut keys = [(0.0f32, 0u8); TOP_SWEEP];
    for (k, b) in items.iter().enumerate() {
        keys[k] = (key(b, axis), k as u8);
    }
    let keys = &mut keys[..n];
    if !keys.is_sorted_by(|a, b| a.0 <= b.0) {
        keys.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        let mut was = [Aabb::EMPTY; TOP_SWEEP];
        let mut was_order = [0u32; TOP_SWEEP];
        was[..n].copy_from_slice(items);
        was_order[..n].copy_from_slice(order);
        for (to, &(_, from)) in keys.iter().enumerate() {
            items[to] = was[from as usize];
            order[to] = was_order[from as usize];
        }
    }
    // right[k]: the cost of the instances from k on.
    let mut right = [0.0f64; TOP_SWEEP];
    let mut acc = Aabb::EMPTY;
    for k in (1..n).rev() {
        acc.grow(&items[k]);
        right[k] = acc.half_area() * (n - k) as f64;
    }
    let mut left = Aabb::EMPTY;
    let mut best = (f64::INFINITY, 1);
    for k in 1..n {
        left.grow(&items[k - 1]);
        let cost = left.half_area() * k as f64 + right[k];
        if cost < best.0 {
            best = (cost, k);
        }
    }
    let half = best.1;
    (
        left.union(&items[n - 1]),
        half,
        centre_box(&items[..half]),
        centre_box(&items[half..]),
    )
}

/// The binned SAH's split of a node's instances along `axis` (partitioned in place, `order`
/// with them), or `None` when every instance falls in one bin.
fn binned_split(
    items: &mut [Aabb],
    order: &mut [u32],
    bin_of: &mut [u8],
    scratch: (&mut [Aabb], &mut [u32]),
    spread: &Aabb,
    axis: usize,
) -> Option<Split> {
    let lo = spread.min[axis] * 2.0;
    let scale = TOP_BINS as f32 / ((spread.max[axis] - spread.min[axis]) * 2.0);
    let mut counts = [0usize; TOP_BINS];
    let mut bins = [Aabb::EMPTY; TOP_BINS];
    let mut centres = [Aabb::EMPTY; TOP_BINS];
    for (b, slot) in items.iter().zip(bin_of.iter_mut()) {
        // (Through i32: a float-to-usize conversion saturates at both ends, at a cost.)
        let k = (((key(b, axis) - lo) * scale) as i32).clamp(0, TOP_BINS as i32 - 1) as usize;
        *slot = k as u8;
        counts[k] += 1;
        bins[k].grow(b);
        centres[k].grow_point((b.min + b.max) * 0.5);
    }
    // Cost of splitting after bin k: the two sides' areas times their counts.
    let mut right = [(Aabb::EMPTY, 0usize); TOP_BINS];
    let mut acc = (Aabb::EMPTY, 0);
    for k in (1..TOP_BINS).rev() {
        acc = (acc.0.union(&bins[k]), acc.1 + counts[k]);
        right[k] = acc;
    }
    let mut left = (Aabb::EMPTY, 0usize);
    let mut best = (f64::INFINITY, 0usize);
    for k in 0..TOP_BINS - 1 {
        left = (left.0.union(&bins[k]), left.1 + counts[k]);
        let (r, nr) = right[k + 1];
        if left.1 == 0 || nr == 0 {
            continue;
        }
        let cost = left.0.half_area() * left.1 as f64 + r.half_area() * nr as f64;
        if cost < best.0 {
            best = (cost, k);
        }
    }
    if !best.0.is_finite() {
        return None;
    }
    // Instances of bins up to `split` to the front, the rest after them, through the
    // scratch space and without a branch on the side (a coin toss for most instances).
    let split = best.1;
    let mid = counts[..=split].iter().sum();
    let (mut a, mut e) = (0, mid);
    for (j, &k) in bin_of.iter().enumerate() {
        let goes_left = k as usize <= split;
        let to = if goes_left { a } else { e };
        scratch.0[to] = items[j];
        scratch.1[to] = order[j];
        a += goes_left as usize;
        e += !goes_left as usize;
    }
    items.copy_from_slice(scratch.0);
    order.copy_from_slice(scratch.1);
    Some((
        left.0.union(&bins[TOP_BINS - 1]),
        mid,
        union_of(&centres[..=split]),
        union_of(&centres[split + 1..]),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// Walks the top level over `boxes`: every non-empty box in exactly one leaf, every
    /// leaf's box its instance's, every inner node's box around its children's; returns the
    /// depth.
    fn check(boxes: &[Aabb]) -> usize {
        let (nodes, order) = build_top(boxes);
        let mut seen = vec![0u32; boxes.len()];
        let mut deepest = 0;
        let mut stack = vec![(0usize, 0usize)];
        let holds = |outer: &BvhNode, min: [f32; 3], max: [f32; 3]| {
            (0..3).all(|a| outer.min[a] <= min[a] && max[a] <= outer.max[a])
        };
        while let Some((k, depth)) = stack.pop() {
            deepest = deepest.max(depth);
            let n = &nodes[k];
            if n.count > 0 {
                assert_eq!(n.count, 1);
                let i = order[n.first as usize] as usize;
                seen[i] += 1;
                assert_eq!((n.min, n.max), (boxes[i].min.into(), boxes[i].max.into()));
            } else if !order.is_empty() {
                for c in [n.first as usize, n.first as usize + 1] {
                    assert!(holds(n, nodes[c].min, nodes[c].max), "node {k}, child {c}");
                    stack.push((c, depth + 1));
                }
            }
        }
        for (i, b) in boxes.iter().enumerate() {
            assert_eq!(seen[i], u32::from(!b.is_empty()), "box {i}");
        }
        deepest
    }

    #[test]
    fn the_top_level_holds_every_box_once_inside_its_parents() {
        let mut rng = SplitMix64::new(5);
        let mut r = || rng.next_f32();
        for n in [0usize, 1, 2, 3, 5, 11, 12, 13, 17, 40, 100, 1000, 5000] {
            // Scattered boxes of many sizes, with repeats and an empty box now and then.
            let mut boxes: Vec<Aabb> = (0..n)
                .map(|_| {
                    let c = Vec3A::new(r() * 100.0, r() * 5.0, r() * 100.0);
                    let h = Vec3A::new(r(), r(), r()) * (r() * 10.0);
                    Aabb {
                        min: c - h,
                        max: c + h,
                    }
                })
                .collect();
            for k in (0..n).step_by(7) {
                boxes[k] = boxes[k / 2];
            }
            for k in (0..n).step_by(31) {
                boxes[k] = Aabb::EMPTY;
            }
            check(&boxes);
        }
        // Every centre at one point: split by count, halving, so the depth stays that of a
        // balanced tree.
        let same = vec![Aabb::new(glam::Vec3::ZERO, glam::Vec3::ONE); 3000];
        assert!(check(&same) <= 12);
        // Boxes along one line, each a third farther out than the one before: the depth
        // stays within the walks' stack.
        let line: Vec<Aabb> = (0..300)
            .map(|k| {
                let x = 1.3f32.powi(k);
                Aabb::new(
                    glam::Vec3::new(x, 0.0, 0.0),
                    glam::Vec3::new(x * 1.1, 1.0, 1.0),
                )
            })
            .collect();
        assert!(check(&line) <= TOP_DEPTH + 32);
    }
}
