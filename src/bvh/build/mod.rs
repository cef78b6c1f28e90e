//! Top-down construction: median split or binned SAH (Wald 2007), into the flat node array.
//!
//! The top of the tree is built in parallel on the rayon pool: a node with many triangles is
//! split, then its two halves are built at once (`rayon::join`), each into a node array of its
//! own, and the tree's array is made from them once, at the end ([`Part`]). Below [`PARALLEL_MIN`] triangles a subtree is
//! built by one thread into one array, depth first. The references are made on the pool too,
//! one per triangle in order. On a one-thread pool the whole build runs in order on that
//! thread, and the tree is the same on any number of threads.
//!
//! A SAH split moves each reference once: its two sides are written, in order, from the
//! references to a scratch array of the same length (or back), so a range's data alternates
//! between the two as the tree deepens, and a leaf whose data ends in the scratch array copies
//! it back. One pass reads and writes each reference once, where swapping in place read and
//! wrote it twice, and the order within each side is kept (a stable partition).

#[cfg(all(test, target_arch = "x86_64"))]
mod tests;

use std::time::Instant;

use glam::{Vec3, Vec3A, Vec4};

use super::stats::{BuildPhases, TreeCounts};
use super::{BuildOptions, Bvh, BvhNode, BvhStats, MAX_DEPTH, SplitMethod, sah};
use crate::geometry::{Aabb, is_degenerate};

/// Past this depth both builders split by count, which halves the range each time.
const COUNT_SPLIT_DEPTH: u32 = (MAX_DEPTH - 32) as u32;
/// Largest bin count the SAH builder supports.
const MAX_BINS: usize = 64;
/// Subtrees with at least this many triangles split in two that are built in parallel.
const PARALLEL_MIN: usize = 16 * 1024;
/// Ranges with at least this many references are split on the rayon pool (binned and
/// partitioned in pieces of [`POOL_CHUNK`]): the root's split of a large mesh otherwise
/// keeps every other thread waiting.
const POOL_SPLIT_MIN: usize = 1 << 18;
/// References per piece of a split on the rayon pool.
const POOL_CHUNK: usize = 1 << 16;
/// Triangles per piece of work when the references are made on the rayon pool.
const REF_CHUNK: usize = 16 * 1024;

pub(super) fn build(triangles: &[[Vec3; 3]], options: &BuildOptions) -> Bvh {
    let start = Instant::now();
    let options = BuildOptions {
        bins: options.bins.clamp(2, MAX_BINS as u32),
        max_leaf_size: options.max_leaf_size.clamp(1, 255),
        ..*options
    };

    // One 32-byte reference per finite triangle: its box, with the triangle's index in the
    // spare lane. The builders move these as they split (see the module docs), so every pass
    // reads memory in order. They are made on the rayon pool, one per triangle in the
    // triangles' order (written in place: a large mesh's references are a fresh mapping whose
    // pages fault in as they are written, on every thread at once), then tallied, and the
    // left-out triangles' references dropped, in order, when there are any.
    use rayon::prelude::*;
    let mut refs: Vec<PrimRef> = Vec::new();
    triangles
        .par_iter()
        .enumerate()
        .with_min_len(REF_CHUNK)
        .map(|(i, t)| PrimRef::of_triangle(t, i as u32))
        .collect_into_vec(&mut refs);
    let tally = refs
        .par_iter()
        .with_min_len(REF_CHUNK)
        .fold(RefTally::default, RefTally::add)
        .reduce(RefTally::default, RefTally::merge);
    let RefTally {
        bounds: root_bounds,
        centroids: root_centroids,
        excluded,
        degenerate,
    } = tally;
    if excluded + degenerate > 0 {
        refs.retain(PrimRef::is_kept);
    }

    let references = start.elapsed();
    let (nodes, counts) = if refs.is_empty() {
        (vec![EMPTY_NODE; 2], TreeCounts::EMPTY)
    } else {
        let mut scratch = vec![PrimRef::ZERO; refs.len()];
        let mut keys = vec![0u8; refs.len()];
        let root = Task {
            node: 0,
            start: 0,
            end: refs.len(),
            depth: 0,
            bounds: root_bounds,
            centroids: root_centroids,
            in_scratch: false,
        };
        let (part, counts) = subtree(
            &options,
            Buffers {
                refs: &mut refs,
                scratch: &mut scratch,
                keys: &mut keys,
            },
            0,
            root,
        );
        (part.into_nodes(), counts)
    };

    let tree = start.elapsed();
    let prim_ids: Vec<u32> = refs
        .par_iter()
        .with_min_len(1 << 14)
        .map(PrimRef::id)
        .collect();
    let (wide, leaf_blocks) = super::wide::collapse(
        &nodes,
        triangles,
        &prim_ids,
        one_leaf(&nodes, &counts, prim_ids.len()),
    );
    let mut bvh = Bvh {
        wide,
        nodes,
        leaf_blocks,
        prim_ids,
        stats: BvhStats::default(),
        options,
    };
    let build_time = start.elapsed();
    let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
    let phases = BuildPhases {
        references_ms: ms(references),
        tree_ms: ms(tree - references),
        layout_ms: ms(build_time - tree),
    };
    bvh.stats = BvhStats::new(&bvh, &counts, excluded, degenerate, build_time, phases);
    bvh
}

/// Whether the traversal layout tests the tree's `n` triangles as one root leaf: when that costs less
/// by the SAH than the tree built (whose leaves hold at most the options' leaf size). Only a
/// scene of a few dozen triangles can qualify, and one whose leaves' boxes overlap much: the
/// Cornell box's 32 triangles cost 6.0 block tests as one leaf against 7.7 as its tree of four
/// leaves (its walls' boxes span the room, and a ray from inside enters all of them).
fn one_leaf(nodes: &[BvhNode], counts: &TreeCounts, n: usize) -> bool {
    if nodes[0].is_leaf() || n > ONE_LEAF_MAX {
        return false;
    }
    let root_area = nodes[0].aabb().half_area();
    root_area > 0.0 && counts.sah_cost(root_area, n) > sah::C_INTERSECT * sah::leaf_tests(n)
}

/// The most triangles [`one_leaf`] considers: beyond, one leaf costs more than any tree.
const ONE_LEAF_MAX: usize = 256;

/// A node before it is filled in (and the unused slot 1).
const EMPTY_NODE: BvhNode = BvhNode {
    min: [0.0; 3],
    first: 0,
    max: [0.0; 3],
    count: 0,
};

/// Builds the subtree of `task` (whose range is all of `bufs`; `offset` is the position of
/// `bufs` in the whole reference list) as a [`Part`], and counts it for the statistics.
fn subtree(
    options: &BuildOptions,
    mut bufs: Buffers<'_>,
    offset: usize,
    task: Task,
) -> (Part, TreeCounts) {
    let mut builder = Builder::new(options, offset);
    if rayon::current_num_threads() > 1 {
        builder.pool_min = POOL_SPLIT_MIN;
    }
    // On one thread the halves would be built one after the other: build them in place
    // instead (one node array).
    if bufs.refs.len() < PARALLEL_MIN || rayon::current_num_threads() == 1 {
        let (nodes, counts) = builder.run(bufs, task);
        return (Part::Nodes(nodes), counts);
    }
    let Some(split) = builder.split(&mut bufs, &task) else {
        let (nodes, counts) = builder.run(bufs, task);
        return (Part::Nodes(nodes), counts);
    };
    let (left, right) = bufs.split_at(split.mid);
    // Each half's task over its own arrays: `len` references from 0.
    let child = |len: usize, (bounds, centroids): (Aabb, Aabb)| Task {
        node: 0,
        start: 0,
        end: len,
        depth: task.depth + 1,
        bounds,
        centroids,
        in_scratch: split.in_scratch,
    };
    let ((l, l_counts), (r, r_counts)) = rayon::join(
        || subtree(options, left, offset, child(split.mid, split.left)),
        || {
            subtree(
                options,
                right,
                offset + split.mid,
                child(task.end - split.mid, split.right),
            )
        },
    );
    let mut node = EMPTY_NODE;
    node.set_aabb(&task.bounds);
    let mut counts = l_counts;
    counts.add(&r_counts);
    counts.inner(&node);
    let len = l.len() + r.len();
    (
        Part::Split {
            node,
            halves: Box::new((l, r)),
            len,
        },
        counts,
    )
}

/// A subtree as the parallel build returns it: one thread's node array, or a node whose two
/// halves were built at once. Laid out in the tree's node array once, at the end
/// ([`Part::into_nodes`]): joining each pair of halves into a new array as they finished
/// copied every node once per parallel level above it, the root's join on one thread (tens of
/// milliseconds of a 4M-triangle build on two threads).
///
/// A part's array, as [`Part::into_nodes`] makes it, is its root at 0, slot 1 unused, then its
/// root's two children and the rest of its nodes (its body): a node whose children are the
/// pair at `c` has the first child's descendants from `c + 2` and the second's after them.
enum Part {
    /// One thread's node array in that layout, inner nodes' child indices into it.
    Nodes(Vec<BvhNode>),
    /// A node (its child index unset) over the parts of its two halves; `len` is the length
    /// of its array.
    Split {
        node: BvhNode,
        halves: Box<(Part, Part)>,
        len: usize,
    },
}

/// Parts with fewer nodes than this are laid out on one thread.
const PLACE_PARALLEL_MIN: usize = 4096;

impl Part {
    /// The length of the part's node array.
    fn len(&self) -> usize {
        match self {
            Part::Nodes(nodes) => nodes.len(),
            Part::Split { len, .. } => *len,
        }
    }

    /// The tree's node array: a single thread's is returned as it is; otherwise the array is
    /// made once (on the rayon pool, so that its fresh pages fault in on every thread) and
    /// each part written into its place.
    fn into_nodes(self) -> Vec<BvhNode> {
        if let Part::Nodes(nodes) = self {
            return nodes;
        }
        use rayon::prelude::*;
        let mut nodes = Vec::new();
        rayon::iter::repeat_n(EMPTY_NODE, self.len()).collect_into_vec(&mut nodes);
        let (head, body) = nodes.split_at_mut(2);
        self.place(&mut head[0], body, 2);
        nodes
    }

    /// Writes the part's root to `root` and the rest of its array (from index 2) to `body`,
    /// which starts at index `start` of the tree's array.
    fn place(&self, root: &mut BvhNode, body: &mut [BvhNode], start: u32) {
        match self {
            Part::Nodes(nodes) => {
                // Local index `j` (2 or more) is `start + j - 2` in the tree's array; leaves
                // point at reference slots, which do not move.
                let shift = |n: &BvhNode| {
                    if n.is_leaf() {
                        *n
                    } else {
                        BvhNode {
                            first: n.first - 2 + start,
                            ..*n
                        }
                    }
                };
                *root = shift(&nodes[0]);
                for (dst, n) in body.iter_mut().zip(&nodes[2..]) {
                    *dst = shift(n);
                }
            }
            Part::Split { node, halves, .. } => {
                let (l, r) = &**halves;
                *root = BvhNode {
                    first: start,
                    ..*node
                };
                let (pair, rest) = body.split_at_mut(2);
                let [l_root, r_root] = pair else {
                    unreachable!("a pair is two nodes")
                };
                let (l_body, r_body) = rest.split_at_mut(l.len() - 2);
                let r_start = start + 2 + (l.len() - 2) as u32;
                if self.len() >= PLACE_PARALLEL_MIN {
                    rayon::join(
                        || l.place(l_root, l_body, start + 2),
                        || r.place(r_root, r_body, r_start),
                    );
                } else {
                    l.place(l_root, l_body, start + 2);
                    r.place(r_root, r_body, r_start);
                }
            }
        }
    }
}

struct Task {
    node: usize,
    start: usize,
    end: usize,
    depth: u32,
    bounds: Aabb,
    centroids: Aabb,
    /// The range's references are in the scratch array, not the reference array.
    in_scratch: bool,
}

/// A subtree's references, their scratch twin (see the module docs) and each reference's bin.
struct Buffers<'a> {
    refs: &'a mut [PrimRef],
    scratch: &'a mut [PrimRef],
    keys: &'a mut [u8],
}

impl<'a> Buffers<'a> {
    /// The array holding the data of a range (`in_scratch` as its task says).
    fn data(&mut self, in_scratch: bool) -> &mut [PrimRef] {
        if in_scratch { self.scratch } else { self.refs }
    }

    /// Over `range`: the data (in the array `in_scratch` names), the other array, and the
    /// references' bins.
    fn parts(
        &mut self,
        in_scratch: bool,
        range: std::ops::Range<usize>,
    ) -> (&[PrimRef], &mut [PrimRef], &mut [u8]) {
        let (src, dst) = if in_scratch {
            (&*self.scratch, &mut *self.refs)
        } else {
            (&*self.refs, &mut *self.scratch)
        };
        (
            &src[range.clone()],
            &mut dst[range.clone()],
            &mut self.keys[range],
        )
    }

    /// The two halves at `mid`, each with its part of all three arrays.
    fn split_at(self, mid: usize) -> (Buffers<'a>, Buffers<'a>) {
        let (rl, rr) = self.refs.split_at_mut(mid);
        let (sl, sr) = self.scratch.split_at_mut(mid);
        let (kl, kr) = self.keys.split_at_mut(mid);
        (
            Buffers {
                refs: rl,
                scratch: sl,
                keys: kl,
            },
            Buffers {
                refs: rr,
                scratch: sr,
                keys: kr,
            },
        )
    }
}

/// One thread's builder of one subtree.
struct Builder<'a> {
    options: &'a BuildOptions,
    /// Index in the whole reference list of the subtree's first reference.
    offset: usize,
    /// Scratch bins, reused from node to node.
    grid: std::cell::RefCell<Box<Grid>>,
    /// Ranges of at least this many references are binned and partitioned on the rayon pool
    /// (`usize::MAX`: never).
    pool_min: usize,
}

/// A triangle's box with its index stored in the `w` lane of `min`, tagged with
/// [`PrimRef::ID_TAG`].
///
/// The lane goes through the boxes' arithmetic with the other three (the compiler computes
/// all four lanes even where it uses one), so the bits must read as a normal float: an index
/// alone reads as a denormal (every index below 2^23), and arithmetic on a denormal costs
/// Intel CPUs a microcode assist per instruction (a hundred cycles or more), which made every
/// build several times slower on an Intel Xeon. Clearing the lane before the arithmetic did not
/// hold: where one lane of the result was used, the compiler dropped the clearing and kept the
/// four-lane multiplication.
#[derive(Clone, Copy)]
struct PrimRef {
    min: Vec4,
    max: Vec4,
}

impl PrimRef {
    /// A placeholder (scratch slots before they are written).
    const ZERO: PrimRef = PrimRef {
        min: Vec4::ZERO,
        max: Vec4::ZERO,
    };

    /// Set in the stored index: the float's exponent is then 128 or more (a normal number of
    /// magnitude 2 or more, or for indices of 2^30 - 2^23 and up, which no tree holds, an
    /// infinity or NaN, which take no assist either).
    const ID_TAG: u32 = 1 << 30;

    /// In `max.w` of a triangle left out: not finite, or degenerate (0 for every kept one).
    const NOT_FINITE: f32 = 1.0;
    const DEGENERATE: f32 = 2.0;

    fn new(b: &Aabb, id: u32) -> Self {
        debug_assert!(id < Self::ID_TAG);
        Self {
            min: b.min.extend(f32::from_bits(id | Self::ID_TAG)),
            max: b.max.extend(0.0),
        }
    }

    /// The reference of triangle `id`, or for a triangle the tree leaves out (a vertex not
    /// finite, or no area) a reference marked as such, with no box.
    fn of_triangle(t: &[Vec3; 3], id: u32) -> Self {
        let left_out = |why: f32| PrimRef {
            min: Vec4::ZERO,
            max: Vec4::new(0.0, 0.0, 0.0, why),
        };
        if !(t[0].is_finite() && t[1].is_finite() && t[2].is_finite()) {
            return left_out(Self::NOT_FINITE);
        }
        if is_degenerate(t) {
            return left_out(Self::DEGENERATE);
        }
        let mut b = Aabb::EMPTY;
        for v in t {
            b.grow_point(Vec3A::from(*v));
        }
        Self::new(&b, id)
    }

    /// False for a left-out triangle's reference (see [`PrimRef::of_triangle`]).
    fn is_kept(&self) -> bool {
        self.max.w == 0.0
    }

    #[inline(always)]
    fn id(&self) -> u32 {
        self.min.w.to_bits() & !Self::ID_TAG
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

/// What the references of a run of triangles hold: the union of the kept ones' boxes and of
/// their centroids, and how many triangles were left out, by reason. Unions are order-free,
/// so the tally of the whole list is the same however its runs were split.
#[derive(Clone, Copy)]
struct RefTally {
    bounds: Aabb,
    centroids: Aabb,
    excluded: usize,
    degenerate: usize,
}

impl Default for RefTally {
    fn default() -> Self {
        Self {
            bounds: Aabb::EMPTY,
            centroids: Aabb::EMPTY,
            excluded: 0,
            degenerate: 0,
        }
    }
}

impl RefTally {
    fn add(mut self, r: &PrimRef) -> Self {
        if r.is_kept() {
            self.bounds.grow(&r.bounds());
            self.centroids.grow_point(r.centroid());
        } else if r.max.w == PrimRef::NOT_FINITE {
            self.excluded += 1;
        } else {
            self.degenerate += 1;
        }
        self
    }

    fn merge(mut self, other: Self) -> Self {
        self.bounds.grow(&other.bounds);
        self.centroids.grow(&other.centroids);
        self.excluded += other.excluded;
        self.degenerate += other.degenerate;
        self
    }
}

/// A chosen split: `start..mid` goes left, `mid..end` right, with their boxes and centroid
/// boxes; the sides' data are in the scratch array when `in_scratch`.
struct Split {
    mid: usize,
    left: (Aabb, Aabb),
    right: (Aabb, Aabb),
    in_scratch: bool,
}

#[derive(Clone, Copy)]
struct Bin {
    /// Union of the triangles' boxes.
    bounds: Aabb,
    /// Union of the triangles' centroids.
    centroids: Aabb,
    count: u32,
}

impl Bin {
    const EMPTY: Bin = Bin {
        bounds: Aabb::EMPTY,
        centroids: Aabb::EMPTY,
        count: 0,
    };
}

impl<'a> Builder<'a> {
    fn new(options: &'a BuildOptions, offset: usize) -> Self {
        Self {
            options,
            offset,
            grid: std::cell::RefCell::new(Box::new([[Bin::EMPTY; MAX_BINS]; ROWS])),
            pool_min: usize::MAX,
        }
    }

    /// Builds the subtree of `root` (whose range is all of `bufs`) on this thread, depth first
    /// (see [`subtree`]).
    fn run(&self, mut bufs: Buffers<'_>, root: Task) -> (Vec<BvhNode>, TreeCounts) {
        let mut counts = TreeCounts::EMPTY;
        let mut nodes = Vec::with_capacity(2 * bufs.refs.len().div_ceil(2));
        nodes.extend([EMPTY_NODE; 2]);
        let mut stack = vec![root];
        while let Some(task) = stack.pop() {
            nodes[task.node].set_aabb(&task.bounds);
            let split = self.split(&mut bufs, &task);
            match split {
                None => {
                    let n = &mut nodes[task.node];
                    n.first = (self.offset + task.start) as u32;
                    n.count = (task.end - task.start) as u32;
                    counts.leaf(n, task.depth);
                    // Leaves point into the reference array: bring the data home.
                    if task.in_scratch {
                        let range = task.start..task.end;
                        bufs.refs[range.clone()].copy_from_slice(&bufs.scratch[range]);
                    }
                }
                Some(s) => {
                    let left = nodes.len();
                    nodes.extend([EMPTY_NODE; 2]);
                    let n = &mut nodes[task.node];
                    n.first = left as u32;
                    n.count = 0;
                    counts.inner(n);
                    // Right first so that the left subtree is laid out next (depth-first).
                    stack.push(Task {
                        node: left + 1,
                        start: s.mid,
                        end: task.end,
                        depth: task.depth + 1,
                        bounds: s.right.0,
                        centroids: s.right.1,
                        in_scratch: s.in_scratch,
                    });
                    stack.push(Task {
                        node: left,
                        start: task.start,
                        end: s.mid,
                        depth: task.depth + 1,
                        bounds: s.left.0,
                        centroids: s.left.1,
                        in_scratch: s.in_scratch,
                    });
                }
            }
        }
        (nodes, counts)
    }

    /// Decides how to split a range, or `None` for a leaf.
    fn split(&self, bufs: &mut Buffers<'_>, task: &Task) -> Option<Split> {
        let n = task.end - task.start;
        let max_leaf = self.options.max_leaf_size as usize;
        if n <= 1 {
            return None;
        }
        // A leaf of one block costs one block test; any split costs a traversal step plus at
        // least one block test per side weighted by its area, never less while traversing
        // costs at least a block test (`C_TRAVERSE >= C_INTERSECT`). The SAH would bin and
        // sweep the node to decide the same: half the nodes of a tree are such leaves.
        if n <= max_leaf && sah::C_TRAVERSE >= sah::C_INTERSECT * sah::leaf_tests(n) {
            return None;
        }
        if task.depth >= COUNT_SPLIT_DEPTH {
            return (n > max_leaf).then(|| self.split_by_count(bufs, task));
        }
        match self.options.split {
            SplitMethod::Median => (n > max_leaf).then(|| self.split_median(bufs, task)),
            SplitMethod::Sah => self.split_sah(bufs, task),
        }
    }

    /// Splits in the middle of the range as it stands (used when nothing better exists).
    fn split_by_count(&self, bufs: &mut Buffers<'_>, task: &Task) -> Split {
        let mid = task.start + (task.end - task.start) / 2;
        finish(bufs.data(task.in_scratch), task, mid)
    }

    /// Object median along the longest axis of the centroid bounds.
    fn split_median(&self, bufs: &mut Buffers<'_>, task: &Task) -> Split {
        let axis = task.centroids.longest_axis();
        let mid = task.start + (task.end - task.start) / 2;
        let data = bufs.data(task.in_scratch);
        data[task.start..task.end].select_nth_unstable_by(mid - task.start, |a, b| {
            a.centroid()[axis].total_cmp(&b.centroid()[axis])
        });
        finish(data, task, mid)
    }

    /// Binned SAH along the longest axis of the centroid bounds, with SAH leaf termination.
    fn split_sah(&self, bufs: &mut Buffers<'_>, task: &Task) -> Option<Split> {
        let n = task.end - task.start;
        let max_leaf = self.options.max_leaf_size as usize;
        // Small nodes need no more bins than they have triangles, and ranges below
        // `FEW_BINS_BELOW` no more than `FEW_BINS`: the per-node cost of clearing and sweeping
        // the bins would otherwise dominate the build, for trees no better.
        let most = if n < FEW_BINS_BELOW {
            FEW_BINS
        } else {
            MAX_BINS
        };
        let bins = (self.options.bins as usize).min(most).min(n.max(2));
        // Wald (2007): bin along the axis where the centroids spread most (binning all three
        // axes costs three times as much for a tree about 3% better by SAH on the dragon).
        let axis = task.centroids.longest_axis();
        let lo = task.centroids.min[axis];
        let scale = bin_scale(task.centroids.max[axis] - lo, bins);
        if scale == 0.0 {
            // Every centroid in one point: no plane separates them.
            return (n > max_leaf).then(|| self.split_by_count(bufs, task));
        }
        if n <= SWEEP_MAX {
            return self.split_sweep(bufs, task, axis);
        }

        // Only the bins in use are reset: clearing all MAX_BINS per node would cost more than
        // the binning itself deep in the tree, where nodes are small.
        let mut guard = self.grid.borrow_mut();
        let grid: &mut Grid = &mut guard;
        grid[0][..bins].fill(Bin::EMPTY);
        let last = bins as u32 - 1;
        // Each triangle's bin is kept, so the partition below need not recompute it.
        let (src, _, keys) = bufs.parts(task.in_scratch, task.start..task.end);
        let bin = BinPlan { lo, scale, last };
        let on_pool = n >= self.pool_min;
        match (axis, on_pool) {
            (0, false) => bin.fill::<0>(src, keys, grid, bins),
            (1, false) => bin.fill::<1>(src, keys, grid, bins),
            (_, false) => bin.fill::<2>(src, keys, grid, bins),
            (0, true) => bin.fill_on_pool::<0>(src, keys, grid, bins),
            (1, true) => bin.fill_on_pool::<1>(src, keys, grid, bins),
            (_, true) => bin.fill_on_pool::<2>(src, keys, grid, bins),
        }

        // Sweep: cost of splitting before bin `p` (left = bins 0..p).
        let row = &grid[0][..bins];
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
        // (cost, p, left count); `p` 0 until a split is found. (An `Option` here was compared
        // while still `None`: its uninitialised cost, a denormal, went through the comparison.)
        let mut best = (f64::INFINITY, 0, 0);
        let mut acc = Aabb::EMPTY;
        let mut count = 0;
        for p in 1..bins {
            acc.grow(&row[p - 1].bounds);
            count += row[p - 1].count;
            if count == 0 || right_count[p] == 0 {
                continue;
            }
            let cost = sah::leaf_tests(count as usize) * acc.half_area()
                + sah::leaf_tests(right_count[p] as usize) * right_area[p];
            if best.1 == 0 || cost < best.0 {
                best = (cost, p, count as usize);
            }
        }
        let (cost, p, left_count) = best;
        if p == 0 {
            return (n > max_leaf).then(|| self.split_by_count(bufs, task));
        }
        // Compare un-normalized costs so that a flat node (zero area) does not divide by zero.
        let area = task.bounds.half_area();
        let split_cost = sah::C_TRAVERSE * area + sah::C_INTERSECT * cost;
        let leaf_cost = sah::C_INTERSECT * sah::leaf_tests(n) * area;
        if n <= max_leaf && split_cost >= leaf_cost {
            return None;
        }

        // Each side written in order to the other array, reading the bins kept above.
        let (src, dst, keys) = bufs.parts(task.in_scratch, task.start..task.end);
        if on_pool {
            partition_on_pool(src, keys, p as u8, dst, left_count);
        } else {
            partition(src, keys, p as u8, dst, left_count);
        }
        let union = |bins: &[Bin]| {
            bins.iter().fold((Aabb::EMPTY, Aabb::EMPTY), |(b, c), bin| {
                (b.union(&bin.bounds), c.union(&bin.centroids))
            })
        };
        Some(Split {
            mid: task.start + left_count,
            left: union(&row[..p]),
            right: union(&row[p..]),
            in_scratch: !task.in_scratch,
        })
    }
}

impl Builder<'_> {
    /// SAH over every split of a small range's references sorted by centroid along `axis`
    /// (a full sweep: exact where bins would round), with SAH leaf termination. The sides are
    /// written, sorted, to the other array.
    fn split_sweep(&self, bufs: &mut Buffers<'_>, task: &Task, axis: usize) -> Option<Split> {
        let n = task.end - task.start;
        debug_assert!((2..=SWEEP_MAX).contains(&n));
        let max_leaf = self.options.max_leaf_size as usize;
        let (src, dst, _) = bufs.parts(task.in_scratch, task.start..task.end);
        // Each reference's centroid as an integer in the same order as the floats (they are
        // finite), above its position: one sort orders by centroid, ties by position.
        let mut order = [0u64; SWEEP_MAX];
        for (i, (o, p)) in order.iter_mut().zip(src).enumerate() {
            *o = (ordered_bits(p.centroid()[axis]) as u64) << 32 | i as u64;
        }
        let order = &mut order[..n];
        order.sort_unstable();
        let at = |k: usize| &src[order[k] as u32 as usize];
        // Area of the boxes from the `k`-th on, for each `k`.
        let mut right_area = [0.0f64; SWEEP_MAX];
        let mut acc = Aabb::EMPTY;
        for k in (1..n).rev() {
            acc.grow(&at(k).bounds());
            right_area[k] = acc.half_area();
        }
        let (mut cost, mut split) = (f64::INFINITY, 0);
        let mut acc = Aabb::EMPTY;
        // A zip from 1: `.enumerate().take(n).skip(1)` left a call (`Take::nth`) in every
        // sweep (a few percent of a build's instructions).
        for (k, &right) in (1..n).zip(&right_area[1..n]) {
            acc.grow(&at(k - 1).bounds());
            let c = sah::leaf_tests(k) * acc.half_area() + sah::leaf_tests(n - k) * right;
            if c < cost {
                (cost, split) = (c, k);
            }
        }
        let area = task.bounds.half_area();
        let split_cost = sah::C_TRAVERSE * area + sah::C_INTERSECT * cost;
        let leaf_cost = sah::C_INTERSECT * sah::leaf_tests(n) * area;
        if n <= max_leaf && split_cost >= leaf_cost {
            return None;
        }
        for (d, &o) in dst.iter_mut().zip(order.iter()) {
            *d = src[o as u32 as usize];
        }
        Some(Split {
            mid: task.start + split,
            left: side_bounds(&dst[..split]),
            right: side_bounds(&dst[split..]),
            in_scratch: !task.in_scratch,
        })
    }
}

/// Ranges of fewer references than this bin into at most [`FEW_BINS`] bins, whatever
/// [`BuildOptions::bins`] asks: the bins count where ranges are large. More bins over the large
/// ranges make trees whose walks test fewer nodes and triangle blocks for little build time;
/// over the small ranges they make trees no better for more build time. `tracery report bins
/// MESH` prints the nodes and blocks the canonical rays' walks test for each bin count.
const FEW_BINS_BELOW: usize = 256;

/// The bins of ranges under [`FEW_BINS_BELOW`] references.
const FEW_BINS: usize = 12;

/// Ranges of up to this many references are split by [`Builder::split_sweep`]: sorting a few
/// references costs less than clearing, filling and sweeping bins for them.
const SWEEP_MAX: usize = 32;

/// `x`'s bits as an integer that orders finite floats as `<` does (-0 just below +0).
#[inline(always)]
fn ordered_bits(x: f32) -> u32 {
    let b = x.to_bits();
    if b >> 31 == 1 { !b } else { b | 1 << 31 }
}

/// The box and the centroid box of `refs` (one side of a split).
fn side_bounds(refs: &[PrimRef]) -> (Aabb, Aabb) {
    let mut b = Aabb::EMPTY;
    let mut c = Aabb::EMPTY;
    for p in refs {
        b.grow(&p.bounds());
        c.grow_point(p.centroid());
    }
    (b, c)
}

/// Both sides' boxes for a split of `task`'s range (in `data`) at `mid`; the data stay where
/// they are.
fn finish(data: &[PrimRef], task: &Task, mid: usize) -> Split {
    Split {
        mid,
        left: side_bounds(&data[task.start..mid]),
        right: side_bounds(&data[mid..task.end]),
        in_scratch: task.in_scratch,
    }
}

/// Where a node's centroids fall into bins along its axis.
struct BinPlan {
    lo: f32,
    scale: f32,
    last: u32,
}

impl BinPlan {
    /// Bins `refs` along axis `AXIS` (a constant, so the loop has no per-reference branch on
    /// the axis), writing each one's bin to `keys`. Ranges of [`ROWS_MIN`] references or more
    /// are binned as four quarters side by side into four rows, merged at the end:
    /// neighbouring triangles mostly share a bin, and with one row each update waited for the
    /// store of the one before. (Four rows build faster than two; the trees are the same.)
    ///
    /// Kept out of line, like [`partition`]: inlined into [`Builder::split`], the loops over
    /// every reference had their registers allocated together with the whole split's (the
    /// partition compared each slot against a length reloaded from the stack); out of line the
    /// build is faster and the trees are the same (`examples/build_time`, two binaries
    /// alternating).
    #[inline(never)]
    fn fill<const AXIS: usize>(
        &self,
        refs: &[PrimRef],
        keys: &mut [u8],
        grid: &mut Grid,
        bins: usize,
    ) {
        if refs.len() < ROWS_MIN {
            for (p, key) in refs.iter().zip(keys.iter_mut()) {
                *key = self.add::<AXIS>(p, &mut grid[0]);
            }
            return;
        }
        for row in &mut grid[1..] {
            row[..bins].fill(Bin::EMPTY);
        }
        let quarter = refs.len() / ROWS;
        let (r01, r23) = refs.split_at(2 * quarter);
        let (r0, r1) = r01.split_at(quarter);
        let (r2, r3) = r23.split_at(quarter);
        let (k01, k23) = keys.split_at_mut(2 * quarter);
        let (k0, k1) = k01.split_at_mut(quarter);
        let (k2, k3) = k23.split_at_mut(quarter);
        let [g0, g1, g2, g3] = grid;
        let refs = r0.iter().zip(r1).zip(r2.iter().zip(r3));
        let keys = k0.iter_mut().zip(k1).zip(k2.iter_mut().zip(k3.iter_mut()));
        for (((p0, p1), (p2, p3)), ((k0, k1), (k2, k3))) in refs.zip(keys) {
            *k0 = self.add::<AXIS>(p0, g0);
            *k1 = self.add::<AXIS>(p1, g1);
            *k2 = self.add::<AXIS>(p2, g2);
            *k3 = self.add::<AXIS>(p3, g3);
        }
        // The last quarter is longer by up to three references.
        for (p, k) in r3[quarter..].iter().zip(&mut k3[quarter..]) {
            *k = self.add::<AXIS>(p, g0);
        }
        for row in [&*g1, &*g2, &*g3] {
            merge_bins(&mut g0[..bins], &row[..bins]);
        }
    }

    /// [`BinPlan::fill`] on the rayon pool, in pieces of [`POOL_CHUNK`] references, each into
    /// rows of its own, merged. The same bins: a bin is a count and the union of boxes, the
    /// same in any order.
    fn fill_on_pool<const AXIS: usize>(
        &self,
        refs: &[PrimRef],
        keys: &mut [u8],
        grid: &mut Grid,
        bins: usize,
    ) {
        use rayon::prelude::*;
        let merge = |mut a: Box<Grid>, b: Box<Grid>| {
            merge_bins(&mut a[0][..bins], &b[0][..bins]);
            a
        };
        let empty = || Box::new([[Bin::EMPTY; MAX_BINS]; ROWS]);
        let merged = refs
            .par_chunks(POOL_CHUNK)
            .zip(keys.par_chunks_mut(POOL_CHUNK))
            .map(|(refs, keys)| {
                let mut g = empty();
                self.fill::<AXIS>(refs, keys, &mut g, bins);
                g
            })
            .reduce(empty, merge);
        grid[0][..bins].copy_from_slice(&merged[0][..bins]);
    }

    /// Adds one reference to its bin of `row`; returns the bin.
    #[inline(always)]
    fn add<const AXIS: usize>(&self, p: &PrimRef, row: &mut [Bin; MAX_BINS]) -> u8 {
        let c = p.centroid();
        let along = match AXIS {
            0 => c.x,
            1 => c.y,
            _ => c.z,
        };
        let k = bin_index(along, self.lo, self.scale, self.last);
        // `k <= last < MAX_BINS`: the mask changes nothing and spares the bounds check.
        let bin = &mut row[k as usize & (MAX_BINS - 1)];
        bin.bounds.grow(&p.bounds());
        bin.centroids.grow_point(c);
        bin.count += 1;
        k as u8
    }
}

/// Adds each bin of `other` to the same bin of `row`.
fn merge_bins(row: &mut [Bin], other: &[Bin]) {
    for (a, b) in row.iter_mut().zip(other) {
        a.bounds.grow(&b.bounds);
        a.centroids.grow(&b.centroids);
        a.count += b.count;
    }
}

/// Rows of bins a large range is binned into (see [`BinPlan::fill`]).
const ROWS: usize = 4;

/// The rows of bins (see [`BinPlan::fill`]).
type Grid = [[Bin; MAX_BINS]; ROWS];

/// Ranges from this size on are binned as [`ROWS`] parts into as many rows.
const ROWS_MIN: usize = 64;

/// Writes the references of `src` whose bin (`keys`) is below `p` to the front of `dst` and
/// the others after them (from `left_count`), each side in its order in `src`: every
/// reference is read once and written once, to a slot chosen without a branch. Out of line
/// (see [`BinPlan::fill`]).
#[inline(never)]
fn partition(src: &[PrimRef], keys: &[u8], p: u8, dst: &mut [PrimRef], left_count: usize) {
    let (mut left, mut right) = (0, left_count);
    for (r, &key) in src.iter().zip(keys) {
        let is_left = key < p;
        let at = if is_left { left } else { right };
        dst[at] = *r;
        left += is_left as usize;
        right += !is_left as usize;
    }
    debug_assert_eq!((left, right), (left_count, src.len()));
}

/// [`partition`] on the rayon pool: each piece of [`POOL_CHUNK`] references writes its two
/// sides after those of the pieces before it (counted first), so the result is the same.
fn partition_on_pool(src: &[PrimRef], keys: &[u8], p: u8, dst: &mut [PrimRef], left_count: usize) {
    use rayon::prelude::*;
    let lefts: Vec<usize> = keys
        .par_chunks(POOL_CHUNK)
        .map(|k| k.iter().filter(|&&key| key < p).count())
        .collect();
    // Each piece's slices of the left side and of the right side.
    let (mut left, mut right) = dst.split_at_mut(left_count);
    let mut pieces = Vec::with_capacity(lefts.len());
    for ((src, keys), &l) in src
        .chunks(POOL_CHUNK)
        .zip(keys.chunks(POOL_CHUNK))
        .zip(&lefts)
    {
        let (piece_left, rest_left) = left.split_at_mut(l);
        let (piece_right, rest_right) = right.split_at_mut(src.len() - l);
        (left, right) = (rest_left, rest_right);
        pieces.push((src, keys, piece_left, piece_right));
    }
    debug_assert!(left.is_empty() && right.is_empty());
    pieces.into_par_iter().for_each(|(src, keys, left, right)| {
        let (mut l, mut r) = (0, 0);
        for (x, &key) in src.iter().zip(keys) {
            if key < p {
                left[l] = *x;
                l += 1;
            } else {
                right[r] = *x;
                r += 1;
            }
        }
    });
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
