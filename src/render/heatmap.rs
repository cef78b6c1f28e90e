//! Traversal cost as a picture: the number of BVH nodes each pixel's camera ray entered,
//! mapped through a colour ramp, with the numbers a legend needs.

use glam::Vec3;

use crate::bvh::{BvhNode, Tree, Visit};
use crate::camera::CameraRays;
use crate::film::Sum;
use crate::geometry::Ray;

/// Work done by the closest-hit traversal of one ray.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TraversalCost {
    /// Nodes entered (inner nodes and leaves).
    pub nodes: u32,
    /// Triangles tested.
    pub triangles: u32,
}

/// Traces the ray through the centre of pixel `(x, y)` and counts its traversal work.
pub fn pixel_cost<'a>(bvh: impl Into<Tree<'a>>, cam: &CameraRays, x: u32, y: u32) -> TraversalCost {
    ray_cost(bvh, &cam.pinhole(x as f32 + 0.5, y as f32 + 0.5))
}

/// The traversal work of the closest-hit query of `ray`: over two levels, the top level's
/// nodes and, in each placement entered, its mesh tree's nodes and triangles.
pub fn ray_cost<'a>(bvh: impl Into<Tree<'a>>, ray: &Ray) -> TraversalCost {
    let mut cost = TraversalCost::default();
    let mut count = |v: Visit| match v {
        Visit::Node { .. } => cost.nodes += 1,
        Visit::Triangle { .. } => cost.triangles += 1,
    };
    match bvh.into() {
        Tree::Flat(b) => {
            b.intersect_visit(ray, f32::INFINITY, count);
        }
        Tree::TwoLevel(t) => {
            t.intersect_visit(ray, f32::INFINITY, |_, v| count(v));
        }
    }
    cost
}

/// Adds `count(ray)` for the camera ray through the centre of every pixel of row `y` to the
/// `x` lane of `row` (the layout of [`super::Progressive`]'s sums, so a count image refines
/// like the shaded one).
pub fn count_row(cam: &CameraRays, y: u32, row: &mut [Sum], count: impl Fn(&Ray) -> u32) {
    for (x, px) in row.iter_mut().enumerate() {
        let n = count(&cam.pinhole(x as f32 + 0.5, y as f32 + 0.5));
        px.add_sample(Vec3::new(n as f32, 0.0, 0.0));
    }
}

/// [`count_row`] of the nodes each ray's traversal enters.
pub fn cost_row<'a>(bvh: impl Into<Tree<'a>>, cam: &CameraRays, y: u32, row: &mut [Sum]) {
    let tree = bvh.into();
    count_row(cam, y, row, |ray| ray_cost(tree, ray).nodes);
}

/// The colour ramp of the heatmap: dark blue (cheap) through green and yellow to red and
/// white (expensive); `t` is clamped to `[0, 1]`. Returns sRGB bytes.
pub fn heat_color(t: f32) -> [u8; 3] {
    const STOPS: [[f32; 3]; 6] = [
        [0.05, 0.03, 0.25],
        [0.10, 0.35, 0.75],
        [0.15, 0.70, 0.45],
        [0.95, 0.85, 0.20],
        [0.90, 0.25, 0.10],
        [1.00, 1.00, 1.00],
    ];
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
    let x = t * (STOPS.len() - 1) as f32;
    let i = (x as usize).min(STOPS.len() - 2);
    let f = x - i as f32;
    let a = Vec3::from(STOPS[i]);
    let b = Vec3::from(STOPS[i + 1]);
    let c = a.lerp(b, f);
    [
        (c.x * 255.0 + 0.5) as u8,
        (c.y * 255.0 + 0.5) as u8,
        (c.z * 255.0 + 0.5) as u8,
    ]
}

/// Maps per-pixel node counts (the `x` lane of `sums`, one pass) to RGBA8, with `max` nodes
/// at the top of the ramp.
pub fn heatmap_rgba8<T: Copy + Into<Vec3>>(sums: &[T], max: f32) -> Vec<u8> {
    let k = if max > 0.0 { 1.0 / max } else { 0.0 };
    let mut out = Vec::with_capacity(sums.len() * 4);
    for s in sums {
        let [r, g, b] = heat_color((*s).into().x * k);
        out.extend_from_slice(&[r, g, b, 255]);
    }
    out
}

/// Mean and largest node counts of an image (the `x` lane of `sums`), for the legend.
pub fn cost_summary<T: Copy + Into<Vec3>>(sums: &[T]) -> (f32, f32) {
    if sums.is_empty() {
        return (0.0, 0.0);
    }
    let (mut total, mut max) = (0.0f64, 0.0f32);
    for s in sums {
        let x = (*s).into().x;
        total += x as f64;
        max = max.max(x);
    }
    ((total / sums.len() as f64) as f32, max)
}

/// Number of boxes at depth `level` (root 0) that `ray` passes through anywhere along its
/// length, whatever it hits: where boxes of one level overlap, a ray crosses several. Over
/// two levels, the boxes of the top level.
pub fn boxes_on_ray<'a>(bvh: impl Into<Tree<'a>>, ray: &Ray, level: u32) -> u32 {
    let tree = bvh.into();
    if tree.is_empty() {
        return 0;
    }
    let nodes: &[BvhNode] = match tree {
        Tree::Flat(b) => &b.nodes,
        Tree::TwoLevel(t) => t.top_nodes(),
    };
    let ray = crate::geometry::PreparedRay::new(ray);
    let crosses = |i: u32| {
        let (near, far) = nodes[i as usize].aabb().slab(&ray);
        near.max(0.0) <= far
    };
    if !crosses(0) {
        return 0;
    }
    let mut count = 0;
    let mut stack = vec![(0u32, 0u32)];
    while let Some((i, depth)) = stack.pop() {
        if depth == level {
            count += 1;
            continue;
        }
        let n = &nodes[i as usize];
        if !n.is_leaf() {
            for c in [n.first, n.first + 1] {
                if crosses(c) {
                    stack.push((c, depth + 1));
                }
            }
        }
    }
    count
}

/// [`count_row`] of the boxes of depth `level` each ray crosses.
pub fn overlap_row<'a>(
    bvh: impl Into<Tree<'a>>,
    cam: &CameraRays,
    level: u32,
    y: u32,
    row: &mut [Sum],
) {
    let tree = bvh.into();
    count_row(cam, y, row, |ray| boxes_on_ray(tree, ray, level));
}
