//! Top-down construction: median split or binned SAH (Wald 2007), into the flat node array.
//!
//! The top of the tree is built in parallel on the rayon pool: a node with many triangles is
//! split, then its two halves are built at once (`rayon::join`), each into a node array of its
//! own that the parent then joins to its own. Below [`PARALLEL_MIN`] triangles a subtree is
//! built by one thread into one array, depth first. On a one-thread pool the whole build runs
//! in order on that thread, and the tree is the same on any number of threads.

use std::time::Instant;

use glam::{Vec3, Vec3A, Vec4};

use super::{BuildOptions, Bvh, BvhNode, BvhStats, MAX_DEPTH, SplitMethod, sah};
use crate::geometry::{Aabb, is_degenerate};

/// Past this depth both builders split by count, which halves the range each time.
const COUNT_SPLIT_DEPTH: u32 = (MAX_DEPTH - 32) as u32;
/// Largest bin count the SAH builder supports.
const MAX_BINS: usize = 64;
/// Subtrees with at least this many triangles split in two that are built in parallel.
const PARALLEL_MIN: usize = 16 * 1024;

pub(super) fn build(triangles: &[[Vec3; 3]], options: &BuildOptions) -> Bvh {
    let start = Instant::now();
    let options = BuildOptions {
        bins: options.bins.clamp(2, MAX_BINS as u32),
        max_leaf_size: options.max_leaf_size.clamp(1, 255),
        ..*options
    };

    // One 32-byte reference per finite triangle: its box, with the triangle's index in the
    // spare lane. The builders partition these in place, so every pass reads memory in order.
    let mut refs: Vec<PrimRef> = Vec::with_capacity(triangles.len());
    let mut root_bounds = Aabb::EMPTY;
    let mut root_centroids = Aabb::EMPTY;
    let mut degenerate = 0;
    for (i, t) in triangles.iter().enumerate() {
        if !(t[0].is_finite() && t[1].is_finite() && t[2].is_finite()) {
            continue;
        }
        if is_degenerate(t) {
            degenerate += 1;
            continue;
        }
        let mut b = Aabb::EMPTY;
        for v in t {
            b.grow_point(Vec3A::from(*v));
        }
        root_bounds.grow(&b);
        root_centroids.grow_point(b.center());
        refs.push(PrimRef::new(&b, i as u32));
    }
    let excluded = triangles.len() - refs.len() - degenerate;

    let nodes = if refs.is_empty() {
        vec![EMPTY_NODE; 2]
    } else {
        let mut keys = vec![0u8; refs.len()];
        subtree(
            &options,
            &mut refs,
            &mut keys,
            0,
            root_bounds,
            root_centroids,
            0,
        )
    };

    use rayon::prelude::*;
    let prim_ids: Vec<u32> = refs
        .par_iter()
        .with_min_len(1 << 14)
        .map(PrimRef::id)
        .collect();
    let tris: Vec<[Vec3A; 3]> = prim_ids
        .par_iter()
        .with_min_len(1 << 14)
        .map(|&i| triangles[i as usize].map(Vec3A::from))
        .collect();
    let wide = super::wide::collapse(&nodes, &tris, &prim_ids);
    let mut bvh = Bvh {
        wide,
        nodes,
        tris,
        prim_ids,
        stats: BvhStats::default(),
        options,
    };
    let build_time = start.elapsed();
    bvh.stats = BvhStats::measure(&bvh, excluded, degenerate, build_time);
    bvh
}

/// A node before it is filled in (and the unused slot 1).
const EMPTY_NODE: BvhNode = BvhNode {
    min: [0.0; 3],
    first: 0,
    max: [0.0; 3],
    count: 0,
};

/// Builds the subtree over `local` (reference `offset` of the whole list onwards; `keys` is the
/// scratch of the same range) into a node array of its own: root at 0, slot 1 unused, sibling
/// pairs from 2, leaves pointing at whole-list reference slots.
fn subtree(
    options: &BuildOptions,
    local: &mut [PrimRef],
    keys: &mut [u8],
    offset: usize,
    bounds: Aabb,
    centroids: Aabb,
    depth: u32,
) -> Vec<BvhNode> {
    let builder = Builder::new(options, offset);
    if local.len() < PARALLEL_MIN {
        return builder.run(local, keys, bounds, centroids, depth);
    }
    let task = Task {
        node: 0,
        start: 0,
        end: local.len(),
        depth,
        bounds,
        centroids,
    };
    let Some(split) = builder.split(local, keys, &task) else {
        return builder.run(local, keys, bounds, centroids, depth);
    };
    let (left, right) = local.split_at_mut(split.mid);
    let (left_keys, right_keys) = keys.split_at_mut(split.mid);
    let (l, r) = rayon::join(
        || {
            subtree(
                options,
                left,
                left_keys,
                offset,
                split.left.0,
                split.left.1,
                depth + 1,
            )
        },
        || {
            subtree(
                options,
                right,
                right_keys,
                offset + split.mid,
                split.right.0,
                split.right.1,
                depth + 1,
            )
        },
    );
    join_subtrees(&bounds, l, r)
}

/// The node array of a node over `bounds` whose children are the roots of `l` and `r`.
fn join_subtrees(bounds: &Aabb, l: Vec<BvhNode>, r: Vec<BvhNode>) -> Vec<BvhNode> {
    // `l`'s nodes from index 2 go to 4.., `r`'s after them; inner nodes' child indices move
    // with them (leaves point at reference slots, which do not move).
    let (base_l, base_r) = (4u32, 4 + (l.len() as u32 - 2));
    let shift = |n: &BvhNode, base: u32| {
        if n.is_leaf() {
            *n
        } else {
            BvhNode {
                first: n.first - 2 + base,
                ..*n
            }
        }
    };
    let mut nodes = Vec::with_capacity(l.len() + r.len());
    let mut root = EMPTY_NODE;
    root.set_aabb(bounds);
    root.first = 2;
    nodes.extend([root, EMPTY_NODE, shift(&l[0], base_l), shift(&r[0], base_r)]);
    nodes.extend(l[2..].iter().map(|n| shift(n, base_l)));
    nodes.extend(r[2..].iter().map(|n| shift(n, base_r)));
    nodes
}

struct Task {
    node: usize,
    start: usize,
    end: usize,
    depth: u32,
    bounds: Aabb,
    centroids: Aabb,
}

/// One thread's builder of one subtree.
struct Builder<'a> {
    options: &'a BuildOptions,
    /// Index in the whole reference list of the subtree's first reference.
    offset: usize,
    /// Scratch bins, reused from node to node.
    grid: std::cell::RefCell<Box<[Bin; MAX_BINS]>>,
}

/// A triangle's box with its index stored in the `w` lane of `min`.
#[derive(Clone, Copy)]
struct PrimRef {
    min: Vec4,
    max: Vec4,
}

impl PrimRef {
    fn new(b: &Aabb, id: u32) -> Self {
        Self {
            min: b.min.extend(f32::from_bits(id)),
            max: b.max.extend(0.0),
        }
    }

    #[inline(always)]
    fn id(&self) -> u32 {
        self.min.w.to_bits()
    }

    #[inline(always)]
    fn bounds(&self) -> Aabb {
        Aabb {
            min: Vec3A::from_vec4(self.min),
            max: Vec3A::from_vec4(self.max),
        }
    }

    /// Box centre, as [`Aabb::center`] computes it.
    #[inline(always)]
    fn centroid(&self) -> Vec3A {
        Vec3A::from_vec4(self.min) * 0.5 + Vec3A::from_vec4(self.max) * 0.5
    }
}

/// A chosen split: `local[start..mid]` goes left, `local[mid..end]` right, with their boxes.
struct Split {
    mid: usize,
    left: (Aabb, Aabb),
    right: (Aabb, Aabb),
}

#[derive(Clone, Copy)]
struct Bin {
    /// Union of the triangles' boxes.
    bounds: Aabb,
    /// Union of the triangles' centroids.
    centroids: Aabb,
    count: u32,
}

impl<'a> Builder<'a> {
    fn new(options: &'a BuildOptions, offset: usize) -> Self {
        let empty = Bin {
            bounds: Aabb::EMPTY,
            centroids: Aabb::EMPTY,
            count: 0,
        };
        Self {
            options,
            offset,
            grid: std::cell::RefCell::new(Box::new([empty; MAX_BINS])),
        }
    }

    /// Builds the subtree over `local` on this thread, depth first (see [`subtree`]).
    fn run(
        &self,
        local: &mut [PrimRef],
        keys: &mut [u8],
        root_bounds: Aabb,
        root_centroids: Aabb,
        depth: u32,
    ) -> Vec<BvhNode> {
        let mut nodes = Vec::with_capacity(2 * local.len().div_ceil(2));
        nodes.extend([EMPTY_NODE; 2]);
        let mut stack = vec![Task {
            node: 0,
            start: 0,
            end: local.len(),
            depth,
            bounds: root_bounds,
            centroids: root_centroids,
        }];
        while let Some(task) = stack.pop() {
            nodes[task.node].set_aabb(&task.bounds);
            let split = self.split(local, keys, &task);
            match split {
                None => {
                    let n = &mut nodes[task.node];
                    n.first = (self.offset + task.start) as u32;
                    n.count = (task.end - task.start) as u32;
                }
                Some(s) => {
                    let left = nodes.len();
                    nodes.extend([EMPTY_NODE; 2]);
                    let n = &mut nodes[task.node];
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
        nodes
    }

    /// Decides how to split a range, or `None` for a leaf.
    fn split(&self, local: &mut [PrimRef], keys: &mut [u8], task: &Task) -> Option<Split> {
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
            SplitMethod::Sah => self.split_sah(local, keys, task),
        }
    }

    /// Splits in the middle of the range as it stands (used when nothing better exists).
    fn split_by_count(&self, local: &mut [PrimRef], task: &Task) -> Split {
        let mid = task.start + (task.end - task.start) / 2;
        self.finish(local, task.start, mid, task.end)
    }

    /// Object median along the longest axis of the centroid bounds.
    fn split_median(&self, local: &mut [PrimRef], task: &Task) -> Split {
        let axis = task.centroids.longest_axis();
        let mid = task.start + (task.end - task.start) / 2;
        local[task.start..task.end].select_nth_unstable_by(mid - task.start, |a, b| {
            a.centroid()[axis].total_cmp(&b.centroid()[axis])
        });
        self.finish(local, task.start, mid, task.end)
    }

    /// Computes both sides' boxes for a split at `mid`.
    fn finish(&self, local: &[PrimRef], start: usize, mid: usize, end: usize) -> Split {
        let side = |r: &[PrimRef]| {
            let mut b = Aabb::EMPTY;
            let mut c = Aabb::EMPTY;
            for p in r {
                b.grow(&p.bounds());
                c.grow_point(p.centroid());
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
    fn split_sah(&self, local: &mut [PrimRef], keys: &mut [u8], task: &Task) -> Option<Split> {
        let n = task.end - task.start;
        let max_leaf = self.options.max_leaf_size as usize;
        // Small nodes need no more bins than they have triangles: the per-node cost of
        // clearing and sweeping the bins would otherwise dominate the build.
        let bins = (self.options.bins as usize).min(n.max(2));
        // Wald (2007): bin along the axis where the centroids spread most (binning all three
        // axes costs three times as much for a tree about 3% better by SAH on the dragon).
        let axis = task.centroids.longest_axis();
        let lo = task.centroids.min[axis];
        let scale = bin_scale(task.centroids.max[axis] - lo, bins);
        if scale == 0.0 {
            // Every centroid in one point: no plane separates them.
            return (n > max_leaf).then(|| self.split_by_count(local, task));
        }

        let empty = Bin {
            bounds: Aabb::EMPTY,
            centroids: Aabb::EMPTY,
            count: 0,
        };
        // Only the bins in use are reset: clearing all MAX_BINS per node would cost more than
        // the binning itself deep in the tree, where nodes are small.
        let mut guard = self.grid.borrow_mut();
        let row: &mut [Bin] = &mut guard[..bins];
        row.fill(empty);
        let last = bins as u32 - 1;
        // Each triangle's bin is kept, so the partition below need not recompute it.
        let keys = &mut keys[task.start..task.end];
        for (p, key) in local[task.start..task.end].iter().zip(keys.iter_mut()) {
            let c = p.centroid();
            let k = bin_index(c[axis], lo, scale, last);
            *key = k as u8;
            let bin = &mut row[k as usize];
            bin.bounds.grow(&p.bounds());
            bin.centroids.grow_point(c);
            bin.count += 1;
        }

        // Sweep: cost of splitting before bin `p` (left = bins 0..p).
        let row = &*row;
        let mut right_area = [0.0f64; MAX_BINS];
        let mut right_count = [0u32; MAX_BINS];
        let mut acc = Aabb::EMPTY;
        let mut count = 0;
        for p in (1..bins).rev() {
            acc.grow(&row[p].bounds);
            count += row[p].count;
            right_area[p] = acc.half_area();
            right_count[p] = count;
        }
        let mut best: Option<(f64, usize)> = None; // (cost, p)
        let mut acc = Aabb::EMPTY;
        let mut count = 0;
        for p in 1..bins {
            acc.grow(&row[p - 1].bounds);
            count += row[p - 1].count;
            if count == 0 || right_count[p] == 0 {
                continue;
            }
            let cost = sah::blocks(count as usize) * acc.half_area()
                + sah::blocks(right_count[p] as usize) * right_area[p];
            if best.is_none_or(|(c, _)| cost < c) {
                best = Some((cost, p));
            }
        }
        let Some((cost, p)) = best else {
            return (n > max_leaf).then(|| self.split_by_count(local, task));
        };
        // Compare un-normalized costs so that a flat node (zero area) does not divide by zero.
        let area = task.bounds.half_area();
        let split_cost = sah::C_TRAVERSE * area + sah::C_INTERSECT * cost;
        let leaf_cost = sah::C_INTERSECT * sah::blocks(n) * area;
        if n <= max_leaf && split_cost >= leaf_cost {
            return None;
        }

        // Partition by the chosen plane, reading the bins kept above. Branchless Lomuto:
        // always swap, advance the boundary only for a left item (the side is as good as
        // random, so a branch would be mispredicted half the time).
        let local = &mut local[task.start..task.end];
        let mut i = 0;
        for j in 0..local.len() {
            let left = (keys[j] as usize) < p;
            local.swap(i, j);
            keys.swap(i, j);
            i += left as usize;
        }
        let i = task.start + i;
        let union = |bins: &[Bin]| {
            bins.iter().fold((Aabb::EMPTY, Aabb::EMPTY), |(b, c), bin| {
                (b.union(&bin.bounds), c.union(&bin.centroids))
            })
        };
        let (left_b, left_c) = union(&row[..p]);
        let (right_b, right_c) = union(&row[p..]);
        Some(Split {
            mid: i,
            left: (left_b, left_c),
            right: (right_b, right_c),
        })
    }
}

/// `bins / extent`, slightly shrunk so that the largest centroid lands in the last bin, or
/// zero where the extent is zero or not finite.
fn bin_scale(extent: f32, bins: usize) -> f32 {
    if extent > 0.0 && extent.is_finite() {
        let s = bins as f32 * (1.0 - 1e-6) / extent;
        if s.is_finite() { s } else { f32::MAX }
    } else {
        0.0
    }
}

/// The bin of centroid coordinate `c`: `floor((c - lo) * scale)` within `[0, last]`.
#[inline(always)]
fn bin_index(c: f32, lo: f32, scale: f32, last: u32) -> u32 {
    // Round `v - 0.5` to an integer by adding 1.5 * 2^23, where the spacing of f32 values is
    // exactly 1, and read the integer back from the bits: cheaper than a saturating cast. `v`
    // lies in [0, bins]; NaN or anything out of range lands in some valid bin after the
    // `min`, so this never indexes out of range. The `- 0.5` is applied to `v` first: added to
    // the constant (`MAGIC - 0.5`, as an earlier version did) it vanished, since f32 values at
    // that magnitude are 1 apart, and every centroid went to the nearest bin boundary's bin (bin
    // 0 half as wide, the last one and a half).
    const MAGIC: f32 = 12_582_912.0;
    let v = ((c - lo) * scale - 0.5) + MAGIC;
    v.to_bits().wrapping_sub(MAGIC.to_bits()).min(last)
}
