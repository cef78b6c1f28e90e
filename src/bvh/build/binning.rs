//! The binned SAH split's parts (Wald 2007): how many bins a range takes, each reference's bin
//! and the bins' bounds and counts ([`BinPlan`]), and the stable partition of a range's
//! references by side, in rows on the rayon pool for the large ranges.

use super::*;

/// Ranges of fewer references than this bin into at most [`FEW_BINS`] bins, whatever
/// [`BuildOptions::bins`] asks: the bins count where ranges are large. More bins over the large
/// ranges make trees whose walks test fewer nodes and triangle blocks for little build time;
/// over the small ranges they make trees no better for more build time. `tracery report bins
/// MESH` prints the nodes and blocks the canonical rays' walks test for each bin count.
pub(super) const FEW_BINS_BELOW: usize = 256;

/// The bins of ranges under [`FEW_BINS_BELOW`] references.
pub(super) const FEW_BINS: usize = 12;

/// Ranges of up to this many references are split by [`Builder::split_sweep`]: sorting a few
/// references costs less than clearing, filling and sweeping bins for them.
pub(super) const SWEEP_MAX: usize = 32;

/// `x`'s bits as an integer that orders finite floats as `<` does (-0 just below +0).
#[inline(always)]
pub(super) fn ordered_bits(x: f32) -> u32 {
    let b = x.to_bits();
    if b >> 31 == 1 { !b } else { b | 1 << 31 }
}

/// The box and the centroid box of `refs` (one side of a split).
pub(super) fn side_bounds(refs: &[PrimRef]) -> (Aabb, Aabb) {
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
pub(super) fn finish(data: &[PrimRef], task: &Task, mid: usize) -> Split {
    Split {
        mid,
        left: side_bounds(&data[task.start..mid]),
        right: side_bounds(&data[mid..task.end]),
        in_scratch: task.in_scratch,
    }
}

/// Where a node's centroids fall into bins along its axis.
pub(super) struct BinPlan {
    pub(super) lo: f32,
    pub(super) scale: f32,
    pub(super) last: u32,
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
    pub(super) fn fill<const AXIS: usize>(
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
    pub(super) fn fill_on_pool<const AXIS: usize>(
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
pub(super) fn merge_bins(row: &mut [Bin], other: &[Bin]) {
    for (a, b) in row.iter_mut().zip(other) {
        a.bounds.grow(&b.bounds);
        a.centroids.grow(&b.centroids);
        a.count += b.count;
    }
}

/// Rows of bins a large range is binned into (see [`BinPlan::fill`]).
pub(super) const ROWS: usize = 4;

/// The rows of bins (see [`BinPlan::fill`]).
pub(super) type Grid = [[Bin; MAX_BINS]; ROWS];

/// Ranges from this size on are binned as [`ROWS`] parts into as many rows.
pub(super) const ROWS_MIN: usize = 64;

/// Writes the references of `src` whose bin (`keys`) is below `p` to the front of `dst` and
/// the others after them (from `left_count`), each side in its order in `src`: every
/// reference is read once and written once, to a slot chosen without a branch. Out of line
/// (see [`BinPlan::fill`]).
#[inline(never)]
pub(super) fn partition(
    src: &[PrimRef],
    keys: &[u8],
    p: u8,
    dst: &mut [PrimRef],
    left_count: usize,
) {
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
pub(super) fn partition_on_pool(
    src: &[PrimRef],
    keys: &[u8],
    p: u8,
    dst: &mut [PrimRef],
    left_count: usize,
) {
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
pub(super) fn bin_scale(extent: f32, bins: usize) -> f32 {
    if extent > 0.0 && extent.is_finite() {
        let s = bins as f32 * (1.0 - 1e-6) / extent;
        if s.is_finite() { s } else { f32::MAX }
    } else {
        0.0
    }
}

/// The bin of centroid coordinate `c`: `floor((c - lo) * scale)` within `[0, last]`.
#[inline(always)]
pub(super) fn bin_index(c: f32, lo: f32, scale: f32, last: u32) -> u32 {
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
