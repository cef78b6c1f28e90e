//! The traversal layout: the binary tree collapsed into 8-wide nodes whose child boxes are SIMD
//! lanes, with the triangles in blocks of four in structure-of-arrays form.
//!
//! The binary tree ([`super::Bvh::nodes`]) stays the tree of record (statistics, debug drawing,
//! the visiting traversal); this layout is derived from it after the build ([`collapse`]) and is
//! what the closest-hit, any-hit and every-hit queries walk. One traversal loop
//! ([`traverse`]) is written once over a small [`kernel`] interface with three
//! implementations chosen once, when the BVH is built: AVX2 when the CPU has AVX2 and FMA,
//! else SSE2 (two 4-wide halves per node), else plain scalar code, the readable reference
//! beside the SIMD kernels. Every kernel computes the same watertight triangle test as
//! [`crate::geometry::intersect_triangle`] operation for operation, so all three give the
//! same hits, bit for bit, as brute force.

mod collapse;
pub(crate) mod kernel;
pub mod traverse;

pub use kernel::Kernel;

use crate::geometry::PreparedRay;

/// Children per node (the SIMD width of the AVX2 box test).
pub const WIDTH: usize = 8;
/// Triangles per block (the SIMD width of the triangle test).
pub const BLOCK: usize = 4;

/// One 8-wide node: the boxes of up to eight children as lanes, and what each child is.
///
/// Unused lanes hold an empty box (`lo = +inf`, `hi = -inf`) that no ray can enter.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(64))]
pub struct WideNode {
    /// `[lo_x, hi_x, lo_y, hi_y, lo_z, hi_z]`, one lane per child.
    pub planes: [[f32; WIDTH]; 6],
    /// Per child: an inner node's index into [`WideBvh::nodes`], or a leaf's first block.
    pub child: [u32; WIDTH],
    /// Per child: 0 for an inner node (or an unused lane), else the leaf's number of blocks.
    pub blocks: [u32; WIDTH],
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
        blocks: [0; WIDTH],
    };

    /// Number of children in use.
    pub fn children(&self) -> usize {
        (0..WIDTH)
            .filter(|&k| self.planes[0][k] <= self.planes[1][k])
            .count()
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
    Avx2(kernel::Avx2Cpu),
}

impl WideBvh {
    /// The kernel the queries use.
    pub fn kernel(&self) -> Kernel {
        match self.dispatch {
            Dispatch::Scalar => Kernel::Scalar,
            #[cfg(target_arch = "x86_64")]
            Dispatch::Sse2 => Kernel::Sse2,
            #[cfg(target_arch = "x86_64")]
            Dispatch::Avx2(_) => Kernel::Avx2,
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
            Kernel::Avx2 => match kernel::Avx2Cpu::detect() {
                Some(cpu) => Dispatch::Avx2(cpu),
                None => return Err("this CPU cannot run the avx2 kernel".into()),
            },
            #[cfg(not(target_arch = "x86_64"))]
            other => return Err(format!("the {other} kernel exists on x86-64 only")),
        };
        Ok(())
    }

    /// Closest hit at `0 < t < t_max`, by the chosen kernel.
    #[inline]
    pub(crate) fn closest(&self, ray: &PreparedRay, t_max: f32) -> traverse::Best {
        let safe = !ray.inv_dir.is_finite();
        match (self.dispatch, safe) {
            (Dispatch::Scalar, false) => {
                traverse::closest::<kernel::Scalar, false>(self, ray, t_max)
            }
            (Dispatch::Scalar, true) => traverse::closest::<kernel::Scalar, true>(self, ray, t_max),
            #[cfg(target_arch = "x86_64")]
            (Dispatch::Sse2, false) => traverse::closest::<kernel::Sse2, false>(self, ray, t_max),
            #[cfg(target_arch = "x86_64")]
            (Dispatch::Sse2, true) => traverse::closest::<kernel::Sse2, true>(self, ray, t_max),
            #[cfg(target_arch = "x86_64")]
            (Dispatch::Avx2(cpu), false) => kernel::closest_avx2::<false>(cpu, self, ray, t_max),
            #[cfg(target_arch = "x86_64")]
            (Dispatch::Avx2(cpu), true) => kernel::closest_avx2::<true>(cpu, self, ray, t_max),
        }
    }

    /// Calls `f(prim, t)` for every hit at `0 < t < t_max` until it returns false; false when
    /// it was stopped.
    #[inline]
    pub(crate) fn each_hit<F: FnMut(u32, f32) -> bool>(
        &self,
        ray: &PreparedRay,
        t_max: f32,
        f: &mut F,
    ) -> bool {
        let safe = !ray.inv_dir.is_finite();
        match (self.dispatch, safe) {
            (Dispatch::Scalar, false) => {
                traverse::each_hit::<kernel::Scalar, false>(self, ray, t_max, f)
            }
            (Dispatch::Scalar, true) => {
                traverse::each_hit::<kernel::Scalar, true>(self, ray, t_max, f)
            }
            #[cfg(target_arch = "x86_64")]
            (Dispatch::Sse2, false) => {
                traverse::each_hit::<kernel::Sse2, false>(self, ray, t_max, f)
            }
            #[cfg(target_arch = "x86_64")]
            (Dispatch::Sse2, true) => traverse::each_hit::<kernel::Sse2, true>(self, ray, t_max, f),
            #[cfg(target_arch = "x86_64")]
            (Dispatch::Avx2(cpu), false) => {
                kernel::each_hit_avx2::<false, F>(cpu, self, ray, t_max, f)
            }
            #[cfg(target_arch = "x86_64")]
            (Dispatch::Avx2(cpu), true) => {
                kernel::each_hit_avx2::<true, F>(cpu, self, ray, t_max, f)
            }
        }
    }
}

pub(super) use collapse::collapse;
