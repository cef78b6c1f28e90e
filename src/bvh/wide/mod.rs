//! The traversal layout: the binary tree collapsed into 8-wide nodes whose child boxes are SIMD
//! lanes, with the triangles in blocks of four in structure-of-arrays form.
//!
//! The binary tree ([`super::Bvh::nodes`]) stays the tree of record (statistics, debug drawing,
//! the visiting traversal); this layout is derived from it after the build (`collapse`) and is
//! what the closest-hit, any-hit and every-hit queries walk. One traversal loop
//! ([`traverse`]) is written once over a small `kernel` interface with three
//! implementations chosen once, when the BVH is built: AVX2 when the CPU has AVX2 and FMA
//! (compiled once more with AVX-512 enabled, for CPUs that have it), else SSE2 (two 4-wide
//! halves per node), else plain scalar code, the readable reference beside the SIMD kernels.
//! Every kernel computes the same watertight triangle test as
//! [`crate::geometry::intersect_triangle`] operation for operation, so all of them give the
//! same hits, bit for bit, as brute force.

mod collapse;
pub(crate) mod kernel;
pub mod packet;
pub mod traverse;

pub use kernel::Kernel;

use crate::geometry::Ray;

/// Children per node (the SIMD width of the AVX2 box test).
pub const WIDTH: usize = 8;
/// Triangles per block (the SIMD width of the triangle test).
pub const BLOCK: usize = 4;

/// One 8-wide node (256 bytes): the boxes of up to eight children as lanes, what each child
/// is, and the order to visit them in for each of the eight ray-direction octants.
///
/// Unused lanes hold an empty box (`lo = +inf`, `hi = -inf`) that no ray can enter.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(64))]
pub struct WideNode {
    /// `[lo_x, hi_x, lo_y, hi_y, lo_z, hi_z]`, one lane per child.
    pub planes: [[f32; WIDTH]; 6],
    /// Per child, a [`Child`] word: an inner node's index into [`WideBvh::nodes`], or a leaf's
    /// blocks.
    pub child: [u32; WIDTH],
    /// Visiting order per octant: bits `3q..3q + 3` of entry `i` hold the lane that comes `i`-th
    /// for a ray in octant `q` (bit `a` of `q` set when the direction's component `a` is
    /// negative), farthest first. The order sorts the children by how far along the octant's
    /// diagonal their boxes start (Fuetterling et al., "Accelerated Single Ray Tracing for Wide
    /// Vector Units", 2017): no distances need sorting while tracing.
    pub order: [u32; WIDTH],
}

impl WideNode {
    /// A node with no children.
    pub const EMPTY: WideNode = WideNode {
        planes: [
            [f32::INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
            [f32::INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
            [f32::INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
        ],
        child: [0; WIDTH],
        order: [0; WIDTH],
    };

    /// Number of children in use.
    pub fn children(&self) -> usize {
        (0..WIDTH)
            .filter(|&k| self.planes[0][k] <= self.planes[1][k])
            .count()
    }

    /// The lane visited `i`-th by rays of octant `q`.
    #[inline(always)]
    pub fn lane_in_order(&self, q: u32, i: usize) -> usize {
        ((self.order[i] >> (3 * q)) & 7) as usize
    }
}

/// A child word: an inner node's index (bit 31 clear), or a leaf (bit 31 set) of `count`
/// blocks from `first` (bits 0-26: first block; bits 27-30: count - 1). A binary leaf of more
/// than [`Child::MAX_BLOCKS`] blocks (over 64 triangles) becomes a node of such leaves.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Child(pub u32);

impl Child {
    const LEAF: u32 = 1 << 31;
    /// Blocks one leaf word can hold.
    pub const MAX_BLOCKS: u32 = 16;
    /// The last block a leaf can start at (2^27 - 1: over 500 million triangles).
    pub const MAX_FIRST_BLOCK: u32 = (1 << 27) - 1;

    /// An inner node.
    pub fn inner(index: u32) -> Child {
        debug_assert!(index < Self::LEAF);
        Child(index)
    }

    /// A leaf of `count` (1 to [`Child::MAX_BLOCKS`]) blocks from `first`.
    pub fn leaf(first: u32, count: u32) -> Child {
        debug_assert!((1..=Self::MAX_BLOCKS).contains(&count) && first <= Self::MAX_FIRST_BLOCK);
        Child(Self::LEAF | ((count - 1) << 27) | first)
    }

    /// True for a leaf.
    #[inline(always)]
    pub fn is_leaf(self) -> bool {
        self.0 & Self::LEAF != 0
    }

    /// An inner node's index.
    #[inline(always)]
    pub fn index(self) -> u32 {
        self.0
    }

    /// A leaf's first block and block count.
    #[inline(always)]
    pub fn blocks(self) -> (u32, u32) {
        (self.0 & Self::MAX_FIRST_BLOCK, ((self.0 >> 27) & 15) + 1)
    }
}

/// Four triangles, coordinate by coordinate: `v[vertex][axis][lane]`, with the caller's index
/// of each (160 bytes). Unused lanes have NaN vertices and index `u32::MAX`; the kernels mask
/// them out.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(16))]
pub struct TriBlock {
    /// Vertex coordinates.
    pub v: [[[f32; BLOCK]; 3]; 3],
    /// Index of each triangle in the list the BVH was built from.
    pub prim: [u32; BLOCK],
}

impl TriBlock {
    /// A block with no triangles.
    pub const EMPTY: TriBlock = TriBlock {
        v: [[[f32::NAN; BLOCK]; 3]; 3],
        prim: [u32::MAX; BLOCK],
    };

    /// The triangle in lane `k`.
    #[inline]
    pub fn triangle(&self, k: usize) -> [glam::Vec3A; 3] {
        std::array::from_fn(|vertex| {
            glam::Vec3A::new(
                self.v[vertex][0][k],
                self.v[vertex][1][k],
                self.v[vertex][2][k],
            )
        })
    }

    /// Bit `k` set for each lane holding a triangle.
    #[inline(always)]
    pub fn valid_mask(&self) -> u32 {
        let mut m = 0;
        for k in 0..BLOCK {
            m |= ((self.prim[k] != u32::MAX) as u32) << k;
        }
        m
    }
}

/// The 8-wide layout of a BVH.
#[derive(Clone, Debug, Default)]
pub struct WideBvh {
    /// Nodes in depth-first order, the root at 0. Empty when the whole tree is one leaf.
    pub nodes: Vec<WideNode>,
    /// Triangle blocks in leaf order.
    pub blocks: Vec<TriBlock>,
    /// The root when the tree is one leaf: its blocks `[first, first + count)`.
    pub root_leaf: Option<(u32, u32)>,
    /// The kernel every query uses, chosen when the layout was made. Private: the AVX2 kernel
    /// carries the proof that the CPU has AVX2 and FMA.
    dispatch: Dispatch,
}

/// The chosen kernel, as the queries dispatch on it.
#[derive(Clone, Copy, Debug, Default)]
enum Dispatch {
    #[default]
    Scalar,
    #[cfg(target_arch = "x86_64")]
    Sse2,
    #[cfg(target_arch = "x86_64")]
    Avx2(crate::cpu::Avx2Cpu),
    #[cfg(target_arch = "x86_64")]
    Avx512(crate::cpu::Avx512Cpu),
}

impl WideBvh {
    /// Bytes of the layout: nodes plus triangle blocks.
    pub fn bytes(&self) -> usize {
        std::mem::size_of_val(&self.nodes[..]) + std::mem::size_of_val(&self.blocks[..])
    }

    /// The kernel the queries use.
    pub fn kernel(&self) -> Kernel {
        match self.dispatch {
            Dispatch::Scalar => Kernel::Scalar,
            #[cfg(target_arch = "x86_64")]
            Dispatch::Sse2 => Kernel::Sse2,
            #[cfg(target_arch = "x86_64")]
            Dispatch::Avx2(_) => Kernel::Avx2,
            #[cfg(target_arch = "x86_64")]
            Dispatch::Avx512(_) => Kernel::Avx512,
        }
    }

    /// Chooses the kernel (tests and benchmarks compare them); an error when this CPU cannot
    /// run it.
    pub fn set_kernel(&mut self, kernel: Kernel) -> Result<(), String> {
        self.dispatch = match kernel {
            Kernel::Scalar => Dispatch::Scalar,
            #[cfg(target_arch = "x86_64")]
            Kernel::Sse2 => Dispatch::Sse2,
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx2 => match crate::cpu::Avx2Cpu::detect() {
                Some(cpu) => Dispatch::Avx2(cpu),
                None => return Err("this CPU cannot run the avx2 kernel".into()),
            },
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx512 => match crate::cpu::Avx512Cpu::detect() {
                Some(cpu) => Dispatch::Avx512(cpu),
                None => return Err("this CPU cannot run the avx512 kernel".into()),
            },
            #[cfg(not(target_arch = "x86_64"))]
            other => return Err(format!("the {other} kernel exists on x86-64 only")),
        };
        Ok(())
    }

    /// Closest hit at `0 < t < t_max`, by the chosen kernel. The ray is prepared inside the
    /// kernel, so its constants stay in registers (a prepared ray passed in memory was read
    /// back with wider loads than it was written with: a store-forwarding stall per ray).
    ///
    /// `safe`: the ray needs the box test's NaN rule ([`kernel::check_ray`]). `INCOHERENT`:
    /// the walk for rays whose neighbours take other paths ([`traverse`]'s module docs).
    #[inline]
    pub(crate) fn closest<const INCOHERENT: bool>(
        &self,
        ray: &Ray,
        t_max: f32,
        safe: bool,
    ) -> traverse::Best {
        match (self.dispatch, safe) {
            (Dispatch::Scalar, false) => {
                traverse::closest_apart::<kernel::Scalar, false, INCOHERENT>(self, ray, t_max)
            }
            (Dispatch::Scalar, true) => {
                traverse::closest_apart::<kernel::Scalar, true, INCOHERENT>(self, ray, t_max)
            }
            #[cfg(target_arch = "x86_64")]
            (Dispatch::Sse2, false) => {
                traverse::closest_apart::<kernel::Sse2, false, INCOHERENT>(self, ray, t_max)
            }
            #[cfg(target_arch = "x86_64")]
            (Dispatch::Sse2, true) => {
                traverse::closest_apart::<kernel::Sse2, true, INCOHERENT>(self, ray, t_max)
            }
            #[cfg(target_arch = "x86_64")]
            (Dispatch::Avx2(cpu), false) => {
                kernel::avx2::closest::<false, INCOHERENT>(cpu, self, ray, t_max)
            }
            #[cfg(target_arch = "x86_64")]
            (Dispatch::Avx2(cpu), true) => {
                kernel::avx2::closest::<true, INCOHERENT>(cpu, self, ray, t_max)
            }
            #[cfg(target_arch = "x86_64")]
            (Dispatch::Avx512(cpu), false) => {
                kernel::avx512::closest::<false, INCOHERENT>(cpu, self, ray, t_max)
            }
            #[cfg(target_arch = "x86_64")]
            (Dispatch::Avx512(cpu), true) => {
                kernel::avx512::closest::<true, INCOHERENT>(cpu, self, ray, t_max)
            }
        }
    }

    /// [`WideBvh::closest`] by the scalar kernel, adding what it tested to `visits`.
    pub(crate) fn closest_counted(
        &self,
        ray: &Ray,
        t_max: f32,
        safe: bool,
        visits: &mut traverse::Visits,
    ) -> traverse::Best {
        if safe {
            traverse::closest_tallied::<kernel::Scalar, true, false>(self, ray, t_max, visits)
        } else {
            traverse::closest_tallied::<kernel::Scalar, false, false>(self, ray, t_max, visits)
        }
    }

    /// Calls `f(prim, t)` for every hit at `0 < t < t_max` until it returns false; false when
    /// it was stopped. `safe` as for [`WideBvh::closest`].
    #[inline]
    pub(crate) fn each_hit<F: FnMut(u32, f32) -> bool>(
        &self,
        ray: &Ray,
        t_max: f32,
        safe: bool,
        f: &mut F,
    ) -> bool {
        match (self.dispatch, safe) {
            (Dispatch::Scalar, false) => {
                traverse::each_hit_apart::<kernel::Scalar, false, F>(self, ray, t_max, f)
            }
            (Dispatch::Scalar, true) => {
                traverse::each_hit_apart::<kernel::Scalar, true, F>(self, ray, t_max, f)
            }
            #[cfg(target_arch = "x86_64")]
            (Dispatch::Sse2, false) => {
                traverse::each_hit_apart::<kernel::Sse2, false, F>(self, ray, t_max, f)
            }
            #[cfg(target_arch = "x86_64")]
            (Dispatch::Sse2, true) => {
                traverse::each_hit_apart::<kernel::Sse2, true, F>(self, ray, t_max, f)
            }
            #[cfg(target_arch = "x86_64")]
            (Dispatch::Avx2(cpu), false) => {
                kernel::avx2::each_hit::<false, F>(cpu, self, ray, t_max, f)
            }
            #[cfg(target_arch = "x86_64")]
            (Dispatch::Avx2(cpu), true) => {
                kernel::avx2::each_hit::<true, F>(cpu, self, ray, t_max, f)
            }
            #[cfg(target_arch = "x86_64")]
            (Dispatch::Avx512(cpu), false) => {
                kernel::avx512::each_hit::<false, F>(cpu, self, ray, t_max, f)
            }
            #[cfg(target_arch = "x86_64")]
            (Dispatch::Avx512(cpu), true) => {
                kernel::avx512::each_hit::<true, F>(cpu, self, ray, t_max, f)
            }
        }
    }
}

impl WideBvh {
    /// The tile's rays traced together as a packet (see [`packet`]), into `bests`; `false`
    /// (nothing written) when they cannot be (invalid rays among them included).
    #[inline]
    pub(crate) fn trace_packet<const ANY: bool>(
        &self,
        tile: &crate::bvh::RayTile,
        t_max: f32,
        bests: &mut packet::Bests,
    ) -> bool {
        match self.dispatch {
            Dispatch::Scalar => {
                packet::trace_packet::<kernel::Scalar, ANY>(self, tile, t_max, bests)
            }
            #[cfg(target_arch = "x86_64")]
            Dispatch::Sse2 => packet::trace_packet::<kernel::Sse2, ANY>(self, tile, t_max, bests),
            #[cfg(target_arch = "x86_64")]
            Dispatch::Avx2(cpu) => kernel::avx2::trace_packet::<ANY>(cpu, self, tile, t_max, bests),
            #[cfg(target_arch = "x86_64")]
            Dispatch::Avx512(cpu) => {
                kernel::avx512::trace_packet::<ANY>(cpu, self, tile, t_max, bests)
            }
        }
    }
}

impl WideBvh {
    /// Whether [`WideBvh::root_leaf_rays`] tests rays in groups here: the layout is one root
    /// leaf and the kernel has a group test (AVX2, AVX-512).
    #[inline]
    pub(crate) fn groups_root_leaf_rays(&self) -> bool {
        #[cfg(target_arch = "x86_64")]
        let grouped = matches!(self.dispatch, Dispatch::Avx2(_) | Dispatch::Avx512(_));
        #[cfg(not(target_arch = "x86_64"))]
        let grouped = false;
        grouped && self.root_leaf.is_some() && self.nodes.is_empty()
    }

    /// The closest hits of up to [`crate::bvh::PACKET`] rays of any directions against the
    /// root leaf, the rays in groups (see [`packet::root_leaf_rays`]), when
    /// [`WideBvh::groups_root_leaf_rays`]; nothing otherwise.
    #[inline]
    pub(crate) fn root_leaf_rays(&self, rays: &[Ray], active: u64, bests: &mut packet::Bests) {
        match self.dispatch {
            #[cfg(target_arch = "x86_64")]
            Dispatch::Avx2(cpu) => kernel::avx2::root_leaf_rays(cpu, self, rays, active, bests),
            #[cfg(target_arch = "x86_64")]
            Dispatch::Avx512(cpu) => kernel::avx512::root_leaf_rays(cpu, self, rays, active, bests),
            _ => {}
        }
    }
}

pub(super) use collapse::{collapse, refit};
