//! The packet queries' input: up to [`PACKET`] coherent rays (a renderer's tile of camera
//! rays) handed to [`crate::bvh::Bvh::intersect_tile`] and [`crate::bvh::Bvh::occluded_tile`],
//! which walk the tree once for all of them.

use crate::geometry::Ray;

/// Rays per packet: an 8 x 8 tile.
pub const PACKET: usize = 64;

/// Up to [`PACKET`] coherent rays as a renderer's tile holds them: `rows` rows of `cols` rays,
/// row `y` starting at `rays[y * stride]` (a rectangle inside a row-major image of rays, or a
/// plain list). The packet's ray `i` is the tile's row `i / cols`, column `i % cols`.
#[derive(Clone, Copy, Debug)]
pub struct RayTile<'a> {
    pub(crate) rays: &'a [Ray],
    pub(crate) stride: usize,
    pub(crate) cols: usize,
    pub(crate) rows: usize,
    /// Number of rays: `cols * rows`, or fewer for a list whose last row is short.
    pub(crate) n: usize,
}

impl<'a> RayTile<'a> {
    /// The tile of `rows` rows of `cols` rays, row `y` starting at `rays[y * stride]`, or
    /// `None` when that is not a tile of `rays` (empty, more than [`PACKET`] rays, rows wider
    /// than `stride`, or past the end of `rays`).
    pub fn new(rays: &'a [Ray], stride: usize, cols: usize, rows: usize) -> Option<Self> {
        let fits = cols > 0
            && rows > 0
            && cols <= stride
            && cols * rows <= PACKET
            && (rows - 1) * stride + cols <= rays.len();
        fits.then_some(RayTile {
            rays,
            stride,
            cols,
            rows,
            n: cols * rows,
        })
    }

    /// Up to [`PACKET`] rays of a list as one tile (rows of eight, the last one shorter).
    pub fn list(rays: &'a [Ray]) -> Self {
        assert!(
            !rays.is_empty() && rays.len() <= PACKET,
            "a packet holds 1 to {PACKET} rays"
        );
        RayTile {
            rays,
            stride: 8,
            cols: rays.len().min(8),
            rows: rays.len().div_ceil(8),
            n: rays.len(),
        }
    }

    /// Number of rays.
    pub fn len(&self) -> usize {
        self.n
    }

    /// Whether the tile holds no ray (never: tiles are made with at least one).
    pub fn is_empty(&self) -> bool {
        false
    }

    /// Calls `f(i, at)` for every ray in packet order: `i` its place in the packet, `at` its
    /// index in the slice the tile was made from.
    #[inline(always)]
    pub fn for_each(&self, mut f: impl FnMut(usize, usize)) {
        let mut i = 0;
        for y in 0..self.rows {
            for x in 0..self.cols {
                if i == self.n {
                    return;
                }
                f(i, y * self.stride + x);
                i += 1;
            }
        }
    }

    /// The slice the tile was made from and its row stride, when the tile is eight full rows
    /// of eight rays (the shape the SIMD kernels load directly); `None` otherwise.
    #[inline(always)]
    pub(crate) fn rows_of_eight(&self) -> Option<(&'a [Ray], usize)> {
        (self.cols == 8 && self.rows == 8 && self.n == PACKET).then_some((self.rays, self.stride))
    }

    /// The slice the tile was made from.
    #[inline(always)]
    pub fn rays(&self) -> &'a [Ray] {
        self.rays
    }
}
