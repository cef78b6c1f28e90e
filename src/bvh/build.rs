//! Top-down construction: median split or binned SAH (Wald 2007), written straight into the
//! flat node array.

use std::time::Instant;

use glam::{UVec3, Vec3, Vec3A};

use super::{BuildOptions, Bvh, BvhNode, BvhStats, MAX_DEPTH, SplitMethod, sah};
use crate::geometry::Aabb;

/// Past this depth both builders split by count, which halves the range each time.
const COUNT_SPLIT_DEPTH: u32 = (MAX_DEPTH - 32) as u32;
/// Largest bin count the SAH builder supports.
const MAX_BINS: usize = 64;

pub(super) fn build(triangles: &[[Vec3; 3]], options: &BuildOptions) -> Bvh {
    let start = Instant::now();
    let options = BuildOptions {
        bins: options.bins.clamp(2, MAX_BINS as u32),
        max_leaf_size: options.max_leaf_size.clamp(1, 255),
        ..*options
    };

    // Per-triangle bounds and centroids; triangles with a non-finite vertex are left out.
    let mut bounds = Vec::with_capacity(triangles.len());
    let mut centroids = Vec::with_capacity(triangles.len());
    let mut indices = Vec::with_capacity(triangles.len());
    let mut root_bounds = Aabb::EMPTY;
    let mut root_centroids = Aabb::EMPTY;
    for (i, t) in triangles.iter().enumerate() {
        if !(t[0].is_finite() && t[1].is_finite() && t[2].is_finite()) {
            continue;
        }
        let mut b = Aabb::EMPTY;
        for v in t {
            b.grow_point(Vec3A::from(*v));
        }
        let c = b.center();
        root_bounds.grow(&b);
        root_centroids.grow_point(c);
        bounds.push(b);
        centroids.push(c);
        indices.push(i as u32);
    }
    let excluded = triangles.len() - indices.len();

    // `local` indexes bounds/centroids; `indices` maps it back to the caller's triangle.
    let mut local: Vec<u32> = (0..indices.len() as u32).collect();
    let mut nodes = vec![
        BvhNode {
            min: [0.0; 3],
            first: 0,
            max: [0.0; 3],
            count: 0,
        };
        2
    ];
    if !local.is_empty() {
        let mut builder = Builder {
            bounds: &bounds,
            centroids: &centroids,
            nodes: &mut nodes,
            options: &options,
        };
        builder.run(&mut local, root_bounds, root_centroids);
    }

    let prim_ids: Vec<u32> = local.iter().map(|&l| indices[l as usize]).collect();
    let tris: Vec<[Vec3A; 3]> = prim_ids
        .iter()
        .map(|&i| triangles[i as usize].map(Vec3A::from))
        .collect();
    let mut bvh = Bvh {
        nodes,
        tris,
        prim_ids,
        stats: BvhStats::default(),
        options,
    };
    let build_time = start.elapsed();
    bvh.stats = BvhStats::measure(&bvh, excluded, build_time);
    bvh
}

struct Task {
    node: usize,
    start: usize,
    end: usize,
    depth: u32,
    bounds: Aabb,
    centroids: Aabb,
}

struct Builder<'a> {
    bounds: &'a [Aabb],
    centroids: &'a [Vec3A],
    nodes: &'a mut Vec<BvhNode>,
    options: &'a BuildOptions,
}

/// A chosen split: `local[start..mid]` goes left, `local[mid..end]` right, with their boxes.
struct Split {
    mid: usize,
    left: (Aabb, Aabb),
    right: (Aabb, Aabb),
}

#[derive(Clone, Copy)]
struct Bin {
    bounds: Aabb,
    count: u32,
}

impl Builder<'_> {
    fn run(&mut self, local: &mut [u32], root_bounds: Aabb, root_centroids: Aabb) {
        let mut stack = vec![Task {
            node: 0,
            start: 0,
            end: local.len(),
            depth: 0,
            bounds: root_bounds,
            centroids: root_centroids,
        }];
        while let Some(task) = stack.pop() {
            self.nodes[task.node].set_aabb(&task.bounds);
            let split = self.split(local, &task);
            match split {
                None => {
                    let n = &mut self.nodes[task.node];
                    n.first = task.start as u32;
                    n.count = (task.end - task.start) as u32;
                }
                Some(s) => {
                    let left = self.nodes.len();
                    let empty = self.nodes[1];
                    self.nodes.push(empty);
                    self.nodes.push(empty);
                    let n = &mut self.nodes[task.node];
                    n.first = left as u32;
                    n.count = 0;
                    // Right first so that the left subtree is laid out next (depth-first).
                    stack.push(Task {
                        node: left + 1,
                        start: s.mid,
                        end: task.end,
                        depth: task.depth + 1,
                        bounds: s.right.0,
                        centroids: s.right.1,
                    });
                    stack.push(Task {
                        node: left,
                        start: task.start,
                        end: s.mid,
                        depth: task.depth + 1,
                        bounds: s.left.0,
                        centroids: s.left.1,
                    });
                }
            }
        }
    }

    /// Decides how to split a range, or `None` for a leaf.
    fn split(&self, local: &mut [u32], task: &Task) -> Option<Split> {
        let n = task.end - task.start;
        let max_leaf = self.options.max_leaf_size as usize;
        if n <= 1 {
            return None;
        }
        if task.depth >= COUNT_SPLIT_DEPTH {
            return (n > max_leaf).then(|| self.split_by_count(local, task));
        }
        match self.options.split {
            SplitMethod::Median => (n > max_leaf).then(|| self.split_median(local, task)),
            SplitMethod::Sah => self.split_sah(local, task),
        }
    }

    /// Splits in the middle of the range as it stands (used when nothing better exists).
    fn split_by_count(&self, local: &mut [u32], task: &Task) -> Split {
        let mid = task.start + (task.end - task.start) / 2;
        self.finish(local, task.start, mid, task.end)
    }

    /// Object median along the longest axis of the centroid bounds.
    fn split_median(&self, local: &mut [u32], task: &Task) -> Split {
        let axis = task.centroids.longest_axis();
        let mid = task.start + (task.end - task.start) / 2;
        let c = self.centroids;
        local[task.start..task.end].select_nth_unstable_by(mid - task.start, |&a, &b| {
            c[a as usize][axis].total_cmp(&c[b as usize][axis])
        });
        self.finish(local, task.start, mid, task.end)
    }

    /// Computes both sides' boxes for a split at `mid`.
    fn finish(&self, local: &[u32], start: usize, mid: usize, end: usize) -> Split {
        let side = |r: &[u32]| {
            let mut b = Aabb::EMPTY;
            let mut c = Aabb::EMPTY;
            for &i in r {
                b.grow(&self.bounds[i as usize]);
                c.grow_point(self.centroids[i as usize]);
            }
            (b, c)
        };
        Split {
            mid,
            left: side(&local[start..mid]),
            right: side(&local[mid..end]),
        }
    }

    /// Binned SAH over the three axes of the centroid bounds, with SAH leaf termination.
    fn split_sah(&self, local: &mut [u32], task: &Task) -> Option<Split> {
        let n = task.end - task.start;
        let max_leaf = self.options.max_leaf_size as usize;
        let bins = self.options.bins as usize;
        let cmin = task.centroids.min;
        let extent = task.centroids.max - task.centroids.min;
        let scale = bin_scale(extent, bins);
        if scale == Vec3A::ZERO {
            // Every centroid in one point: no plane separates them.
            return (n > max_leaf).then(|| self.split_by_count(local, task));
        }

        let empty = Bin {
            bounds: Aabb::EMPTY,
            count: 0,
        };
        let mut grid = [[empty; MAX_BINS]; 3];
        let last = UVec3::splat(bins as u32 - 1);
        for &i in &local[task.start..task.end] {
            let k = bin_index(self.centroids[i as usize], cmin, scale, last);
            let b = &self.bounds[i as usize];
            for (axis, bins_of_axis) in grid.iter_mut().enumerate() {
                let bin = &mut bins_of_axis[k[axis] as usize];
                bin.bounds.grow(b);
                bin.count += 1;
            }
        }

        // Sweep each axis: cost of splitting before bin `p` (left = bins 0..p).
        let mut best: Option<(f64, usize, usize)> = None; // (cost, axis, p)
        let mut right_area = [0.0f64; MAX_BINS];
        let mut right_count = [0u32; MAX_BINS];
        for (axis, grid_axis) in grid.iter().enumerate() {
            if scale[axis] == 0.0 {
                continue;
            }
            let row = &grid_axis[..bins];
            let mut acc = Aabb::EMPTY;
            let mut count = 0;
            for p in (1..bins).rev() {
                acc.grow(&row[p].bounds);
                count += row[p].count;
                right_area[p] = acc.half_area();
                right_count[p] = count;
            }
            let mut acc = Aabb::EMPTY;
            let mut count = 0;
            for p in 1..bins {
                acc.grow(&row[p - 1].bounds);
                count += row[p - 1].count;
                if count == 0 || right_count[p] == 0 {
                    continue;
                }
                let cost =
                    count as f64 * acc.half_area() + right_count[p] as f64 * right_area[p];
                if best.is_none_or(|(c, _, _)| cost < c) {
                    best = Some((cost, axis, p));
                }
            }
        }

        let Some((cost, axis, p)) = best else {
            return (n > max_leaf).then(|| self.split_by_count(local, task));
        };
        // Compare un-normalized costs so that a flat node (zero area) does not divide by zero.
        let area = task.bounds.half_area();
        let split_cost = sah::C_TRAVERSE * area + sah::C_INTERSECT * cost;
        let leaf_cost = sah::C_INTERSECT * n as f64 * area;
        if n <= max_leaf && split_cost >= leaf_cost {
            return None;
        }

        // Partition by the chosen plane, with the same bin function as the binning pass.
        let mut i = task.start;
        let mut j = task.end;
        let mut left_c = Aabb::EMPTY;
        let mut right_c = Aabb::EMPTY;
        while i < j {
            let c = self.centroids[local[i] as usize];
            if (bin_index(c, cmin, scale, last)[axis] as usize) < p {
                left_c.grow_point(c);
                i += 1;
            } else {
                right_c.grow_point(c);
                j -= 1;
                local.swap(i, j);
            }
        }
        let row = &grid[axis][..bins];
        let left_b = row[..p].iter().fold(Aabb::EMPTY, |a, b| a.union(&b.bounds));
        let right_b = row[p..].iter().fold(Aabb::EMPTY, |a, b| a.union(&b.bounds));
        Some(Split {
            mid: i,
            left: (left_b, left_c),
            right: (right_b, right_c),
        })
    }
}

/// Per axis, `bins / extent` (slightly shrunk so the largest centroid lands in the last bin),
/// or zero where the extent is zero or not finite.
fn bin_scale(extent: Vec3A, bins: usize) -> Vec3A {
    let s = |e: f32| {
        if e > 0.0 && e.is_finite() {
            let s = bins as f32 * (1.0 - 1e-6) / e;
            if s.is_finite() { s } else { f32::MAX }
        } else {
            0.0
        }
    };
    Vec3A::new(s(extent.x), s(extent.y), s(extent.z))
}

#[inline(always)]
fn bin_index(c: Vec3A, cmin: Vec3A, scale: Vec3A, last: UVec3) -> UVec3 {
    // `as` casts saturate (NaN to 0), so this never indexes out of range.
    ((c - cmin) * scale).as_uvec3().min(last)
}
