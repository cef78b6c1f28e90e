//! The bundle walks ([`super::bundle`]) compiled once more for AVX2 and for AVX-512, chosen by
//! the tree's kernel: the same loops over sixteen lanes in eight- or sixteen-lane vectors
//! instead of the baseline's four. The same operations in the same order (no fused
//! multiply-adds), so the same answers on every path.
#![allow(
    unsafe_code,
    reason = "calling functions compiled for AVX2 or AVX-512 once the CPU has them"
)]

use super::bundle::{closest_batch_in, occluded_batch_in};
use super::traverse::Best;
use super::{Dispatch, WideBvh};
use crate::geometry::Ray;

/// [`WideBvh::closest_batch`] in the widest instruction set the tree's kernel allows.
pub(super) fn closest_batch(w: &WideBvh, rays: &[Ray], t_max: f32, out: &mut [Best]) {
    match w.dispatch {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: an `Avx512` dispatch holds the proof (`Avx512Cpu`) that the CPU has AVX-512
        // F, VL, BW and DQ and AVX2, all the function is compiled for.
        Dispatch::Avx512(_) => unsafe { closest_avx512(w, rays, t_max, out) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: an `Avx2` dispatch holds the proof (`Avx2Cpu`) that the CPU has AVX2, all
        // the function is compiled for.
        Dispatch::Avx2(_) => unsafe { closest_avx2(w, rays, t_max, out) },
        _ => closest_batch_in(w, rays, t_max, out),
    }
}

/// [`WideBvh::occluded_batch`] in the widest instruction set the tree's kernel allows.
pub(super) fn occluded_batch(w: &WideBvh, rays: &[(Ray, f32)], out: &mut [bool]) {
    match w.dispatch {
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `closest_batch`: the dispatch holds the proof of the CPU's AVX-512.
        Dispatch::Avx512(_) => unsafe { occluded_avx512(w, rays, out) },
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `closest_batch`: the dispatch holds the proof of the CPU's AVX2.
        Dispatch::Avx2(_) => unsafe { occluded_avx2(w, rays, out) },
        _ => occluded_batch_in(w, rays, out),
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn closest_avx2(w: &WideBvh, rays: &[Ray], t_max: f32, out: &mut [Best]) {
    closest_batch_in(w, rays, t_max, out);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,avx512f,avx512vl,avx512bw,avx512dq")]
fn closest_avx512(w: &WideBvh, rays: &[Ray], t_max: f32, out: &mut [Best]) {
    closest_batch_in(w, rays, t_max, out);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn occluded_avx2(w: &WideBvh, rays: &[(Ray, f32)], out: &mut [bool]) {
    occluded_batch_in(w, rays, out);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,avx512f,avx512vl,avx512bw,avx512dq")]
fn occluded_avx512(w: &WideBvh, rays: &[(Ray, f32)], out: &mut [bool]) {
    occluded_batch_in(w, rays, out);
}
