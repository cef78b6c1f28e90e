//! What the benchmark asks of an engine, our BVH as one, and the tiled tracing of coherent
//! packet engines.

use rayon::prelude::*;

use super::HitRecord;
use crate::bvh::Bvh;
use crate::geometry::Ray;

/// A ray tracing engine under test: built once, traced many times.
pub(super) trait Engine: Sync + Send {
    /// Closest hit of one ray.
    fn closest(&self, ray: &Ray) -> HitRecord;
    /// Whether anything lies on the ray.
    fn occluded(&self, ray: &Ray) -> bool;
    /// The build time the engine measured itself, when its builder call does more than build
    /// (Embree's creates a device, with its thread pool, first); `None`: the call's time.
    fn build_ms(&self) -> Option<f64> {
        None
    }
    /// Side of the square pixel tiles a packet engine traces at once; `None` for single rays.
    fn tile(&self) -> Option<u32> {
        None
    }
    /// Closest hits of one tile's rays (packet engines).
    fn closest_tile(&self, rays: &[Ray], out: &mut [HitRecord]) {
        for (o, r) in out.iter_mut().zip(rays) {
            *o = self.closest(r);
        }
    }
    /// Occluded rays among one tile's rays (packet engines).
    fn occluded_tile(&self, rays: &[Ray]) -> usize {
        rays.iter().filter(|r| self.occluded(r)).count()
    }
}

impl Engine for Bvh {
    fn closest(&self, ray: &Ray) -> HitRecord {
        match self.intersect(ray, f32::INFINITY) {
            Some(h) => HitRecord {
                t: h.t,
                prim: h.prim,
            },
            None => HitRecord::MISS,
        }
    }
    fn occluded(&self, ray: &Ray) -> bool {
        Bvh::occluded(self, ray, f32::INFINITY)
    }
}

/// Our BVH tracing camera-ray tiles of 8 x 8 as packets ([`Bvh::intersect_packet`],
/// [`Bvh::occluded_packet`]).
pub(super) struct Packets(pub Bvh);

impl Engine for Packets {
    fn closest(&self, ray: &Ray) -> HitRecord {
        self.0.closest(ray)
    }
    fn occluded(&self, ray: &Ray) -> bool {
        Bvh::occluded(&self.0, ray, f32::INFINITY)
    }
    fn tile(&self) -> Option<u32> {
        Some(8)
    }
    fn occluded_tile(&self, rays: &[Ray]) -> usize {
        let mut blocked = [false; crate::bvh::wide::packet::PACKET];
        let blocked = &mut blocked[..rays.len()];
        self.0.occluded_packet(rays, f32::INFINITY, blocked);
        blocked.iter().filter(|&&b| b).count()
    }
    fn closest_tile(&self, rays: &[Ray], out: &mut [HitRecord]) {
        let mut hits = [None; crate::bvh::wide::packet::PACKET];
        let hits = &mut hits[..rays.len()];
        self.0.intersect_packet(rays, f32::INFINITY, hits);
        for (o, h) in out.iter_mut().zip(hits.iter()) {
            *o = match h {
                Some(h) => HitRecord {
                    t: h.t,
                    prim: h.prim,
                },
                None => HitRecord::MISS,
            };
        }
    }
}

/// Gathers the rays of each `tile x tile` block of one band of `tile` rows (a row-major image
/// `width` rays wide) into a contiguous tile, as a renderer generating camera rays per tile
/// would have them, and calls `f(tile_rays, x0, tile_width)`.
fn for_each_tile_in_band(
    band: &[Ray],
    width: usize,
    tile: usize,
    mut f: impl FnMut(&[Ray], usize, usize),
) {
    let rows = band.len() / width;
    let mut gathered = Vec::with_capacity(tile * tile);
    for x0 in (0..width).step_by(tile) {
        let x1 = (x0 + tile).min(width);
        gathered.clear();
        for y in 0..rows {
            gathered.extend_from_slice(&band[y * width + x0..y * width + x1]);
        }
        f(&gathered, x0, x1 - x0);
    }
}

/// Closest hits of all rays on the current rayon pool: one ray at a time, or tile by tile for
/// a packet engine (`width` is the image width of the rays, row-major).
pub(super) fn trace_closest(engine: &dyn Engine, rays: &[Ray], width: usize) -> Vec<HitRecord> {
    let mut out = vec![HitRecord::MISS; rays.len()];
    match engine.tile() {
        None => out
            .par_chunks_mut(1024)
            .zip(rays.par_chunks(1024))
            .for_each(|(o, r)| {
                for (o, r) in o.iter_mut().zip(r) {
                    *o = engine.closest(r);
                }
            }),
        Some(t) => {
            let t = t as usize;
            out.par_chunks_mut(width * t)
                .zip(rays.par_chunks(width * t))
                .for_each(|(out, band)| {
                    let mut hits = vec![HitRecord::MISS; t * t];
                    for_each_tile_in_band(band, width, t, |tile, x0, tw| {
                        let hits = &mut hits[..tile.len()];
                        engine.closest_tile(tile, hits);
                        for (y, row) in hits.chunks_exact(tw).enumerate() {
                            out[y * width + x0..y * width + x0 + tw].copy_from_slice(row);
                        }
                    });
                });
        }
    }
    out
}

/// Number of occluded rays, traced like [`trace_closest`].
pub(super) fn trace_occluded(engine: &dyn Engine, rays: &[Ray], width: usize) -> usize {
    match engine.tile() {
        None => rays
            .par_chunks(1024)
            .map(|r| r.iter().filter(|r| engine.occluded(r)).count())
            .sum(),
        Some(t) => {
            let t = t as usize;
            rays.par_chunks(width * t)
                .map(|band| {
                    let mut n = 0;
                    for_each_tile_in_band(band, width, t, |tile, _, _| {
                        n += engine.occluded_tile(tile)
                    });
                    n
                })
                .sum()
        }
    }
}
