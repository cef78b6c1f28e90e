//! The plain vertices' step ([`super::plain::step`]) compiled once more for AVX-512 and for
//! AVX2, chosen at run time when the CPU has them: the same Rust loops in sixteen- or
//! eight-lane vectors instead of the baseline's four. The same operations in the same order (no
//! fused multiply-adds), so the same bits on every path.
#![allow(
    unsafe_code,
    reason = "calling functions compiled for AVX2 or AVX-512 once the CPU has them"
)]

use super::plain::{Chunk, step as baseline};
use crate::render::Tracer;
use crate::render::light::ShadowRay;

/// The widest vector unit the step uses: 2 for AVX-512 (F, VL, BW, DQ), 1 for AVX2, 0 for the
/// baseline; the BVH's kernel choice ([`crate::bvh::Kernel::detect`], which `TRACERY_KERNEL`
/// can hold to a narrower one) decides, so one setting holds both to an instruction set.
pub(in crate::render) fn level() -> u8 {
    use crate::bvh::wide::Kernel;
    match Kernel::detect() {
        Kernel::Avx512 => 2,
        Kernel::Avx2 => 1,
        Kernel::Sse2 | Kernel::Scalar => 0,
    }
}

/// Every level this CPU runs ([`level`]'s values), narrowest first.
#[cfg(test)]
pub(super) fn levels() -> Vec<u8> {
    use crate::bvh::wide::Kernel;
    let mut out = vec![0];
    out.extend(Kernel::available().iter().filter_map(|k| match k {
        Kernel::Avx2 => Some(1),
        Kernel::Avx512 => Some(2),
        _ => None,
    }));
    out
}

/// [`super::plain::step`] at `level` (one [`level`] gave, or [`levels`] listed).
#[inline]
pub(super) fn step(
    level: u8,
    t: &Tracer,
    c: &mut Chunk,
    shadows: &mut Vec<ShadowRay>,
    owners: &mut Vec<u32>,
) {
    #[cfg(target_arch = "x86_64")]
    match level {
        // SAFETY: level 2 is only given where the CPU has AVX-512 F, VL, BW and DQ and AVX2
        // (`level`, `levels`), all the function is compiled for.
        2 => unsafe { step_avx512(t, c, shadows, owners) },
        // SAFETY: level 1 is only given where the CPU has AVX2 (`level`, `levels`), all the
        // function is compiled for.
        1 => unsafe { step_avx2(t, c, shadows, owners) },
        _ => baseline(t, c, shadows, owners),
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = level;
        baseline(t, c, shadows, owners)
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn step_avx2(t: &Tracer, c: &mut Chunk, shadows: &mut Vec<ShadowRay>, owners: &mut Vec<u32>) {
    baseline(t, c, shadows, owners);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,avx512f,avx512vl,avx512bw,avx512dq")]
fn step_avx512(t: &Tracer, c: &mut Chunk, shadows: &mut Vec<ShadowRay>, owners: &mut Vec<u32>) {
    baseline(t, c, shadows, owners);
}
