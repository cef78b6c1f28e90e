//! A debug ray: one camera ray followed through the scene as the shader follows it, with
//! every bounce, the shadow ray to each light and what fraction of the light passes, the
//! normal at each hit, and the BVH nodes each segment entered.

use std::collections::HashMap;

use glam::Vec3;

use super::RayCounts;
use super::Tracer;
use super::surface::{reflect, transmit};
use crate::bvh::{Bvh, BvhNode, TwoLevel, Visit};
use crate::geometry::{Ray, offset_ray_origin};
use crate::scene::Light;

/// How a segment of the path began.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SegmentKind {
    /// From the camera.
    Camera,
    /// Reflected by a mirror.
    Reflection,
    /// Continued through a transparent surface.
    Transmission,
}

/// A BVH node a segment entered.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EnteredNode {
    /// The tree it is a node of: `None` for the scene's one tree, or for the top level of
    /// two ([`crate::bvh::TwoLevel::top_nodes`]); `Some(i)` for the mesh tree of instance `i`
    /// of the two levels (its box in that mesh's frame).
    pub instance: Option<u32>,
    /// Index into that tree's nodes ([`Bvh::nodes`]).
    pub index: u32,
    /// Depth, root at 0.
    pub depth: u32,
    /// True when a triangle tested below this node (during this traversal) was hit; false
    /// marks a box the ray entered for nothing.
    pub found_hit: bool,
}

/// Where a segment ended on a surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SegmentHit {
    /// Distance along the segment's (unit) direction.
    pub t: f32,
    /// Triangle index in the scene's list.
    pub prim: u32,
    /// The hit point.
    pub point: Vec3,
    /// Shading normal, facing the incoming ray.
    pub normal: Vec3,
}

/// One straight piece of the path.
#[derive(Clone, Debug, PartialEq)]
pub struct Segment {
    /// How it began.
    pub kind: SegmentKind,
    /// Index of the segment it continues (`None` for the camera ray).
    pub parent: Option<usize>,
    /// The ray (unit direction).
    pub ray: Ray,
    /// The surface it met, if any (else it left the scene).
    pub hit: Option<SegmentHit>,
    /// The BVH nodes it entered, in traversal order.
    pub nodes: Vec<EnteredNode>,
}

/// A shadow ray from a hit point towards a light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShadowRay {
    /// Segment whose hit point it starts from.
    pub segment: usize,
    /// Index of the light in the scene.
    pub light: usize,
    /// Start (the hit point, offset off the surface).
    pub from: Vec3,
    /// The point on the light aimed at (a rectangle light's centre).
    pub to: Vec3,
    /// Fraction of the light that arrives, per channel (0: blocked, 1: visible).
    pub transmittance: Vec3,
}

impl ShadowRay {
    /// Blocked, visible, or attenuated (some but not all light passes).
    pub fn state(&self) -> ShadowState {
        let m = self.transmittance.max_element();
        if m <= 0.0 {
            ShadowState::Blocked
        } else if self.transmittance.min_element() >= 1.0 {
            ShadowState::Visible
        } else {
            ShadowState::Attenuated
        }
    }
}

/// What a shadow ray found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ShadowState {
    /// All light arrives.
    Visible,
    /// Nothing arrives.
    Blocked,
    /// Some light arrives through transparent surfaces.
    Attenuated,
}

/// A camera ray's whole path.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DebugPath {
    /// Segments, the camera ray first; each later one names its parent.
    pub segments: Vec<Segment>,
    /// Shadow rays from every hit that the shader lights directly.
    pub shadows: Vec<ShadowRay>,
}

impl Tracer<'_> {
    /// Follows `ray` as [`Tracer::radiance`] would, recording the path instead of shading it.
    /// Rectangle lights are aimed at their centre.
    pub fn debug_path(&self, ray: &Ray) -> DebugPath {
        let mut path = DebugPath::default();
        let ray = Ray::new(ray.origin, ray.dir.normalize_or_zero());
        self.debug_segment(&ray, SegmentKind::Camera, None, 0, &mut path);
        path
    }

    fn debug_segment(
        &self,
        ray: &Ray,
        kind: SegmentKind,
        parent: Option<usize>,
        depth: u32,
        path: &mut DebugPath,
    ) {
        let (hit, nodes) = match self.bvh {
            crate::bvh::Tree::Flat(bvh) => entered_nodes(bvh, ray),
            crate::bvh::Tree::TwoLevel(t) => entered_nodes_of_two(t, ray),
        };
        let index = path.segments.len();
        let Some(hit) = hit else {
            path.segments.push(Segment {
                kind,
                parent,
                ray: *ray,
                hit: None,
                nodes,
            });
            return;
        };
        let s = self.surface(ray, hit.prim, hit.u, hit.v);
        path.segments.push(Segment {
            kind,
            parent,
            ray: *ray,
            hit: Some(SegmentHit {
                t: hit.t,
                prim: hit.prim,
                point: s.p,
                normal: s.n(),
            }),
            nodes,
        });
        if s.bsdf.diffuse != Vec3::ZERO || s.bsdf.gloss != super::bsdf::Gloss::None {
            let origin = s.origin;
            for (li, light) in self.scene.lights.iter().enumerate() {
                let (to_point, t_max) = match *light {
                    Light::Point { position, .. } | Light::Spot { position, .. } => (position, 1.0),
                    Light::Rect { .. } => (light.center(), 1.0 - 1e-4),
                };
                let transmittance = if s.ng.dot(to_point - s.p) <= 0.0 {
                    Vec3::ZERO // the light is behind the surface
                } else {
                    self.shadow(origin, to_point - origin, t_max, &mut RayCounts::default())
                };
                path.shadows.push(ShadowRay {
                    segment: index,
                    light: li,
                    from: origin,
                    to: to_point,
                    transmittance,
                });
            }
        }
        if depth >= self.max_depth {
            return;
        }
        if self.plan.reflections && s.is_mirror() {
            let r = reflect(ray.dir, s.n());
            if r.dot(s.ng) > 0.0 {
                let bounce = Ray::new(s.origin, r.normalize());
                self.debug_segment(
                    &bounce,
                    SegmentKind::Reflection,
                    Some(index),
                    depth + 1,
                    path,
                );
            }
        }
        let alpha = if self.plan.transmission {
            s.opacity
        } else {
            1.0
        };
        if alpha < 1.0 {
            let (dir, side) = transmit(ray.dir, &s);
            let through = Ray::new(offset_ray_origin(s.p, s.p_err, side), dir.normalize());
            self.debug_segment(
                &through,
                SegmentKind::Transmission,
                Some(index),
                depth + 1,
                path,
            );
        }
    }
}

/// The closest hit of `ray` in `bvh` and every node the search entered, each marked with
/// whether a triangle tested below it was hit.
pub fn entered_nodes(bvh: &Bvh, ray: &Ray) -> (Option<crate::bvh::Hit>, Vec<EnteredNode>) {
    let mut order: Vec<(u32, u32)> = Vec::new();
    let mut leaf_hit: HashMap<u32, bool> = HashMap::new();
    let mut current_leaf = None;
    let hit = bvh.intersect_visit(ray, f32::INFINITY, |v| match v {
        Visit::Node { index, depth } => {
            order.push((index, depth));
            current_leaf = bvh.nodes[index as usize].is_leaf().then_some(index);
        }
        Visit::Triangle { hit, .. } => {
            if let Some(leaf) = current_leaf {
                *leaf_hit.entry(leaf).or_insert(false) |= hit;
            }
        }
    });
    let found = found_below(&bvh.nodes, order.iter().map(|o| o.0), &leaf_hit);
    let nodes = order
        .into_iter()
        .map(|(index, depth)| EnteredNode {
            instance: None,
            index,
            depth,
            found_hit: found.get(&index).copied().unwrap_or(false),
        })
        .collect();
    (hit, nodes)
}

/// [`entered_nodes`] over two levels: the top level's nodes and, in each instance entered,
/// its mesh tree's; a top-level leaf found a hit when a triangle of an instance walked from it
/// was hit.
pub fn entered_nodes_of_two(
    two: &TwoLevel,
    ray: &Ray,
) -> (Option<crate::bvh::Hit>, Vec<EnteredNode>) {
    let mut order: Vec<(Option<u32>, u32, u32)> = Vec::new();
    // Leaves that found a hit, by tree (`None`: the top level).
    let mut leaf_hit: HashMap<Option<u32>, HashMap<u32, bool>> = HashMap::new();
    let (mut top_leaf, mut mesh_leaf) = (None, None);
    let tree_of = |i: u32| &two.meshes[two.mesh_of(i as usize) as usize];
    let hit = two.intersect_visit(ray, f32::INFINITY, |instance, v| match (instance, v) {
        (None, Visit::Node { index, depth }) => {
            order.push((None, index, depth));
            top_leaf = two.top_nodes()[index as usize].is_leaf().then_some(index);
        }
        (Some(i), Visit::Node { index, depth }) => {
            order.push((Some(i), index, depth));
            mesh_leaf = tree_of(i).nodes[index as usize].is_leaf().then_some(index);
        }
        (Some(i), Visit::Triangle { hit, .. }) => {
            for (tree, leaf) in [(Some(i), mesh_leaf), (None, top_leaf)] {
                if let Some(leaf) = leaf {
                    *leaf_hit
                        .entry(tree)
                        .or_default()
                        .entry(leaf)
                        .or_insert(false) |= hit;
                }
            }
        }
        (None, Visit::Triangle { .. }) => {}
    });
    let mut found: HashMap<Option<u32>, HashMap<u32, bool>> = HashMap::new();
    let trees: std::collections::BTreeSet<Option<u32>> = order.iter().map(|o| o.0).collect();
    let none = HashMap::new();
    for tree in trees {
        let nodes = match tree {
            None => two.top_nodes(),
            Some(i) => &tree_of(i).nodes[..],
        };
        let entered = order.iter().filter(|o| o.0 == tree).map(|o| o.1);
        let leaves = leaf_hit.get(&tree).unwrap_or(&none);
        found.insert(tree, found_below(nodes, entered, leaves));
    }
    let nodes = order
        .into_iter()
        .map(|(instance, index, depth)| EnteredNode {
            instance,
            index,
            depth,
            found_hit: found
                .get(&instance)
                .and_then(|f| f.get(&index))
                .copied()
                .unwrap_or(false),
        })
        .collect();
    (hit.map(|h| two.global(h)), nodes)
}

/// Whether each of the `entered` nodes of a tree laid out as [`Bvh::nodes`] found a hit below
/// it: a leaf when `leaf_hit` says so, an inner node when either child did.
fn found_below(
    nodes: &[BvhNode],
    entered: impl Iterator<Item = u32>,
    leaf_hit: &HashMap<u32, bool>,
) -> HashMap<u32, bool> {
    // Children are stored after their parents: walking the entered nodes from the highest
    // index down settles every child before its parent.
    let mut found: HashMap<u32, bool> = HashMap::new();
    let mut by_index: Vec<u32> = entered.collect();
    by_index.sort_unstable_by(|a, b| b.cmp(a));
    by_index.dedup();
    for i in by_index {
        let n = &nodes[i as usize];
        let f = if n.is_leaf() {
            leaf_hit.get(&i).copied().unwrap_or(false)
        } else {
            [n.first, n.first + 1]
                .iter()
                .any(|c| found.get(c).copied().unwrap_or(false))
        };
        found.insert(i, f);
    }
    found
}
