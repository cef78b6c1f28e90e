//! The two tests the traversal loop needs, behind one interface with three implementations:
//! eight child boxes against a ray ([`Lanes::node`]) and four triangles against a ray
//! ([`Lanes::block`]), or a leaf's eight at once ([`Lanes::block_pair`]).
//!
//! - [`scalar`]: plain Rust, one lane at a time, calling the reference triangle test. It is the
//!   readable specification and the fallback on any target.
//! - x86-64 only, chosen at run time: [`sse2`], which every x86-64 CPU has; [`avx2`] (AVX2 +
//!   FMA); [`avx512`], the AVX2 kernel compiled with AVX-512 enabled (32 vector registers) with
//!   a sixteen-lane packet test of its own; what they share is in `x86`.
//!   Their triangle tests, four, eight and sixteen lanes wide, are one generic function
//!   (`floats::watertight`) over the three register widths.
//!
//! The rules every implementation keeps, written out rather than left to what an instruction
//! does with NaN:
//! - Box test: `near = (plane - origin) * (1 / dir)` per axis, the near plane picked by the
//!   sign bit of the direction (so `-0` is negative), the far distance scaled by
//!   `1 + 2 gamma(4)` (Ize 2013, the scale folded into the reciprocal). A NaN distance arises
//!   only as `0 * inf`, an origin on the plane of a slab the ray runs parallel to; such a slab
//!   constrains nothing (a NaN near distance counts as `-inf`, a NaN far one as `+inf`). Rays
//!   whose reciprocal direction is finite cannot produce NaN (boxes are finite or the empty
//!   `+-inf` box), so the fast path skips that fix; the others take the `SAFE` path.
//! - Triangle test: the operations of [`crate::geometry::intersect_triangle`] in the same
//!   order, without fused multiply-adds, so every lane's `t` has the same bits as the scalar
//!   test's; lanes where an edge function is exactly zero, or whose distance or its error
//!   bound overflowed f32, are handed to the scalar test (its f64 path and tie rule).

#[cfg(target_arch = "x86_64")]
pub(crate) mod avx2;
#[cfg(target_arch = "x86_64")]
pub(crate) mod avx512;
#[cfg(target_arch = "x86_64")]
mod floats;
#[cfg(target_arch = "x86_64")]
mod group;
mod scalar;
#[cfg(target_arch = "x86_64")]
mod sse2;
pub(crate) mod stack;
#[cfg(target_arch = "x86_64")]
mod x86;

use super::packet::{Bests, Group, Rays, Tris, rays_entering_scalar};
use super::{BLOCK, TriBlock, WIDTH, WideNode};
use crate::bvh::PACKET;
use crate::geometry::{PreparedRay, Ray, gamma};
use stack::Stack;

/// Asks the CPU to bring the cache line holding `x` into its caches: a hint, with no other
/// effect (nothing on targets without the instruction).
#[inline(always)]
pub(crate) fn prefetch<T>(x: &T) {
    #[cfg(target_arch = "x86_64")]
    x86::prefetch(x);
    #[cfg(not(target_arch = "x86_64"))]
    let _ = x;
}

/// A direction component smaller than this (below `1 / f32::MAX`, with margin) may have an
/// infinite reciprocal, so that the box test can meet `0 * inf`: such rays take the kernels'
/// `SAFE` path, which maps NaN distances explicitly. Every other ray can skip it.
pub(crate) const TINY_DIRECTION: f32 = 1e-37;

/// `None` for a ray that hits nothing ([`Ray::is_valid`] false: a NaN or infinite component,
/// or a zero direction), else whether its box tests need the NaN rule (a direction component
/// smaller than [`TINY_DIRECTION`]). Every query starts here: on x86-64 it is a few SSE2
/// instructions instead of a dozen comparisons and branches.
#[inline(always)]
pub(crate) fn check_ray(ray: &Ray) -> Option<bool> {
    #[cfg(target_arch = "x86_64")]
    return x86::check_ray(ray);
    #[cfg(not(target_arch = "x86_64"))]
    check_ray_scalar(ray)
}

/// [`check_ray`] as plain comparisons: the reference the SSE2 version is tested against.
#[cfg(any(test, not(target_arch = "x86_64")))]
pub(crate) fn check_ray_scalar(ray: &Ray) -> Option<bool> {
    ray.is_valid()
        .then(|| ray.dir.abs().min_element() < TINY_DIRECTION)
}

/// Which implementation the traversal uses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Kernel {
    /// Plain scalar code, one lane at a time (any target).
    #[default]
    Scalar,
    /// SSE2: each 8-wide node as two 4-wide halves (every x86-64 CPU).
    Sse2,
    /// AVX2 with FMA: one 8-wide node test per instruction sequence.
    Avx2,
    /// The AVX2 kernel compiled for AVX-512 CPUs (F, VL, BW, DQ): the same operations, with
    /// 32 vector registers.
    Avx512,
}

impl Kernel {
    /// The kernel new BVHs use: the fastest this CPU runs, or the one the environment variable
    /// `TRACERY_KERNEL` names (`scalar`, `sse2`, `avx2` or `avx512`; tests run whole suites on each, and
    /// it helps to compare them). A name this CPU cannot run is reported once on stderr and the
    /// fastest kernel is used.
    pub fn detect() -> Kernel {
        static CHOSEN: std::sync::OnceLock<Kernel> = std::sync::OnceLock::new();
        *CHOSEN.get_or_init(|| {
            let best = Self::available().last().copied().unwrap_or(Kernel::Scalar);
            let Ok(name) = std::env::var("TRACERY_KERNEL") else {
                return best;
            };
            match name.parse::<Kernel>() {
                Ok(k) if Self::available().contains(&k) => k,
                Ok(k) => {
                    eprintln!("TRACERY_KERNEL={name}: this CPU cannot run {k}; using {best}");
                    best
                }
                Err(e) => {
                    eprintln!("TRACERY_KERNEL={name}: {e}; using {best}");
                    best
                }
            }
        })
    }

    /// Every kernel this CPU runs, slowest first.
    pub fn available() -> Vec<Kernel> {
        let mut k = vec![Kernel::Scalar];
        #[cfg(target_arch = "x86_64")]
        {
            k.push(Kernel::Sse2);
            if crate::cpu::Avx2Cpu::detect().is_some() {
                k.push(Kernel::Avx2);
            }
            if crate::cpu::Avx512Cpu::detect().is_some() {
                k.push(Kernel::Avx512);
            }
        }
        k
    }

    /// Short name for reports.
    pub fn name(self) -> &'static str {
        match self {
            Kernel::Scalar => "scalar",
            Kernel::Sse2 => "sse2",
            Kernel::Avx2 => "avx2",
            Kernel::Avx512 => "avx512",
        }
    }
}

impl std::str::FromStr for Kernel {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "scalar" => Ok(Kernel::Scalar),
            "sse2" => Ok(Kernel::Sse2),
            "avx2" => Ok(Kernel::Avx2),
            "avx512" => Ok(Kernel::Avx512),
            other => Err(format!(
                "unknown kernel `{other}` (expected scalar, sse2, avx2 or avx512)"
            )),
        }
    }
}

impl std::fmt::Display for Kernel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Far distances are scaled up by this (Ize 2013); one more rounding than the scalar slab test
/// because the scale is folded into the reciprocal, hence `gamma(4)`.
pub(crate) const FAR_SCALE: f32 = if cfg!(feature = "no-conservative-slab") {
    1.0
} else {
    1.0 + 2.0 * gamma(4)
};

/// What the box test needs of a ray, computed once per ray.
#[derive(Clone, Copy, Debug)]
pub(crate) struct NodeRay {
    pub origin: [f32; 3],
    pub inv: [f32; 3],
    /// `inv * FAR_SCALE`.
    pub inv_far: [f32; 3],
    /// Per axis, the index into [`WideNode::planes`] of the near plane (`2 axis + 1` when the
    /// direction's sign bit is set); the far plane is the other one (`near ^ 1`).
    pub near: [usize; 3],
    /// The direction's octant: bit `a` set when component `a` is negative (sign bit).
    pub octant: u32,
}

impl NodeRay {
    /// The box test's constants of `ray`, straight from the ray (before, or without, the
    /// triangle test's setup): the reciprocal direction (`+-inf` for `+-0`) as
    /// [`PreparedRay::new`] computes it, the near planes by the direction's sign bits (so `-0`
    /// counts as negative).
    #[inline(always)]
    pub fn of(ray: &Ray) -> Self {
        let d = glam::Vec3A::from(ray.dir);
        let inv = (glam::Vec3A::ONE / d).to_array();
        let neg = d.is_negative_bitmask();
        Self {
            origin: ray.origin.to_array(),
            inv,
            inv_far: inv.map(|i| i * FAR_SCALE),
            near: std::array::from_fn(|a| 2 * a + ((neg >> a) & 1) as usize),
            octant: neg,
        }
    }
}

/// What the triangle test needs of a ray: the prepared ray itself (its origin, axis
/// permutation and shear, and the scalar test's input).
#[derive(Clone, Copy, Debug)]
pub(crate) struct TriRay {
    /// The ray, for the scalar test.
    pub ray: PreparedRay,
}

impl TriRay {
    #[inline(always)]
    pub fn new(ray: &PreparedRay) -> Self {
        Self { ray: *ray }
    }
}

/// The two tests, for one kernel.
pub(crate) trait Lanes: Sized {
    /// The box test's ray data in this kernel's registers.
    type NodeRay: Copy;
    /// The triangle test's ray data in this kernel's registers.
    type TriRay: Copy;

    fn node_ray(r: &NodeRay) -> Self::NodeRay;
    fn tri_ray(r: &TriRay) -> Self::TriRay;

    /// Tests the eight child boxes of `n` against the ray for `0 <= t <= limit`: bit `k` of the
    /// result is set when child `k` is entered, `near[k]` then holds its entry distance. With
    /// `SAFE`, NaN distances follow the rule of the module docs.
    fn node<const SAFE: bool>(
        n: &WideNode,
        r: &Self::NodeRay,
        limit: f32,
        near: &mut [f32; WIDTH],
    ) -> u32;

    /// Pushes the children in `mask` (with their distances from `near`) but the nearest, in
    /// the node's visiting order for the ray's octant, farthest first: the walk goes on to the
    /// nearest (the last hit lane in that order), and the next nearest ends on top.
    /// With `DIST` false only the child words are pushed (for walks that pop with
    /// [`Stack::pop_child`]).
    #[inline(always)]
    fn push_others_in_order<const DIST: bool>(
        n: &WideNode,
        r: &Self::NodeRay,
        mask: u32,
        near: &[f32; WIDTH],
        stack: &mut Stack<'_>,
    ) {
        let octant = Self::octant(r);
        let mut left = mask.count_ones() - 1;
        for i in 0..WIDTH {
            let lane = n.lane_in_order(octant, i);
            if left > 0 && mask >> lane & 1 == 1 {
                if DIST {
                    stack.push(n.child[lane], near[lane]);
                } else {
                    stack.push_child(n.child[lane]);
                }
                left -= 1;
            }
        }
    }

    /// The ray's octant (see [`NodeRay::octant`]).
    fn octant(r: &Self::NodeRay) -> u32;

    /// The packet's rays (bit per ray) that enter the box of lane `lane` of `n` before their
    /// own `limit`; by default one ray at a time.
    #[inline(always)]
    fn rays_entering(n: &WideNode, lane: usize, r: &Rays, limit: &[f32; PACKET]) -> u64 {
        rays_entering_scalar(n, lane, r, limit)
    }

    /// Copies a whole packet of rays, eight rows of eight (row `y` at `rays[y * stride]`, every
    /// row inside `rays`), component by component into `origin` and `dir`, or returns `false`
    /// (the caller copies them) when this kernel has no faster way.
    #[inline(always)]
    fn load_rays(
        _rays: &[Ray],
        _stride: usize,
        _origin: &mut [[f32; PACKET]; 3],
        _dir: &mut [[f32; PACKET]; 3],
    ) -> bool {
        false
    }

    /// The fewest rays of a [`Group`] that [`Lanes::group_blocks`] tests together; smaller
    /// groups go ray by ray. By default no group is (kernels without a group test).
    const RAYS_TOGETHER: usize = usize::MAX;

    /// The most rays of a [`Group`]: as many as [`Lanes::group_blocks`] tests at once.
    const GROUP_MAX: usize = 8;

    /// A group of a packet's rays (sharing one axis permutation) against `blocks`, each
    /// triangle against every ray of the group at once, keeping each ray's closest hit.
    #[inline(always)]
    fn group_blocks(blocks: &[TriBlock], r: &Rays, tris: &Tris, g: &Group, bests: &mut Bests) {
        for &i in &g.idx[..g.n] {
            super::packet::ray_blocks::<Self>(blocks, r, tris, i, bests);
        }
    }

    /// The watertight test on the four lanes of `b` for `0 < t < limit`: the lanes hit (their
    /// distances and barycentric coordinates) and the lanes the scalar test must decide (an
    /// edge function was exactly zero, or the f32 distance overflowed).
    fn block(b: &TriBlock, r: &Self::TriRay, limit: f32) -> BlockHits;

    /// The per-lane values of [`Lanes::block_pair`], in this kernel's own form.
    type Pair: LaneValues;

    /// [`Lanes::block`] on two blocks at once: lanes 0-3 are `a`'s, 4-7 `b`'s. The scalar and
    /// SSE2 kernels make it of two block tests ([`pair_of_blocks`]); the AVX2 and AVX-512
    /// kernels test the eight lanes in 256-bit registers (leaves of five to eight triangles,
    /// the default leaf size's, cost one test).
    fn block_pair(
        a: &TriBlock,
        b: &TriBlock,
        r: &Self::TriRay,
        limit: f32,
    ) -> BlockHits<Self::Pair>;
}

/// [`Lanes::block_pair`] as two [`Lanes::block`] tests.
#[inline(always)]
pub(crate) fn pair_of_blocks<L: Lanes>(
    a: &TriBlock,
    b: &TriBlock,
    r: &L::TriRay,
    limit: f32,
) -> BlockHits<[[f32; 2 * BLOCK]; 3]> {
    let (x, y) = (L::block(a, r, limit), L::block(b, r, limit));
    BlockHits {
        hits: x.hits | y.hits << BLOCK,
        exact: x.exact | y.exact << BLOCK,
        tuv: std::array::from_fn(|i| {
            std::array::from_fn(|k| {
                if k < BLOCK {
                    x.tuv[i][k]
                } else {
                    y.tuv[i][k - BLOCK]
                }
            })
        }),
    }
}

/// What [`Lanes::block`] or [`Lanes::block_pair`] found: the lanes hit, the lanes the scalar
/// test must decide, and per lane the distance and the barycentric weights of the second and
/// third vertex (meaningful in the lanes hit only), as `V` holds them: arrays (`[t, u, v]`,
/// the default), or registers in the AVX2 and AVX-512 kernels' pair test.
#[derive(Clone, Copy, Debug)]
pub(crate) struct BlockHits<V = [[f32; BLOCK]; 3]> {
    pub hits: u32,
    pub exact: u32,
    pub tuv: V,
}

/// Per-lane values of a triangle test: distance, then the barycentric weights of the second
/// and third vertex.
///
/// The pair test of the AVX2 and AVX-512 kernels keeps them in registers and reads a lane by
/// a lane permutation (`x86`'s `Tuv8`). Written out to arrays, they cost the AVX-512 kernel's
/// closest-hit walk its only 512-bit instructions: the compiler zeroed the arrays with merged
/// 512-bit stores and read a lane's two weights with one masked 512-bit load, and on an
/// Intel Xeon that walk ran 8-9% slower than the same code compiled for AVX2 alone (dragon,
/// `examples/trace_time`); without them the two are level. `tests/codegen.rs` guards it.
pub(crate) trait LaneValues: Copy {
    /// Lane `k`'s distance.
    fn t(&self, k: usize) -> f32;
    /// Lane `k`'s barycentric weights of the second and third vertex.
    fn uv(&self, k: usize) -> (f32, f32);
}

impl<const N: usize> LaneValues for [[f32; N]; 3] {
    #[inline(always)]
    fn t(&self, k: usize) -> f32 {
        self[0][k & (N - 1)]
    }
    #[inline(always)]
    fn uv(&self, k: usize) -> (f32, f32) {
        (self[1][k & (N - 1)], self[2][k & (N - 1)])
    }
}

pub(crate) use scalar::Scalar;
#[cfg(target_arch = "x86_64")]
pub(crate) use sse2::Sse2;

/// The constants of the distance error bound of [`crate::geometry::intersect_triangle`].
pub(crate) const G2: f32 = gamma(2);
pub(crate) const G3: f32 = gamma(3);
pub(crate) const G5: f32 = gamma(5);

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// The SSE2 check answers as the plain comparisons on every mix of special values: zeros
    /// of both signs, tiny, denormal, huge, infinite and NaN components, in the origin and in
    /// the direction.
    #[test]
    fn check_ray_matches_the_plain_comparisons() {
        let values = [
            0.0,
            -0.0,
            1.0,
            -2.5,
            1e-38,
            -1e-38,
            1e-37,
            9.9e-38,
            1e-45,
            f32::MAX,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
        ];
        let origins = [
            Vec3::ZERO,
            Vec3::new(1.0, -2.0, 3.0),
            Vec3::new(f32::NAN, 0.0, 0.0),
            Vec3::new(0.0, f32::INFINITY, 0.0),
            Vec3::new(0.0, 0.0, f32::NEG_INFINITY),
            Vec3::new(f32::MAX, -f32::MAX, 1e-45),
        ];
        let (mut valid, mut tiny) = (0, 0);
        for o in origins {
            for x in values {
                for y in values {
                    for z in values {
                        let ray = Ray::new(o, Vec3::new(x, y, z));
                        let expected = check_ray_scalar(&ray);
                        assert_eq!(check_ray(&ray), expected, "{ray:?}");
                        valid += expected.is_some() as usize;
                        tiny += (expected == Some(true)) as usize;
                    }
                }
            }
        }
        // Both answers occur, and the NaN rule both ways.
        assert!(
            valid > 0 && tiny > 0 && tiny < valid,
            "{valid} valid, {tiny} tiny"
        );
    }
}
