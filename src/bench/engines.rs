//! What the benchmark asks of an engine, our BVH as one, and the tiled tracing of coherent
//! packet engines.

use rayon::prelude::*;

use super::HitRecord;
use crate::bvh::{Bvh, RayTile};
use crate::geometry::Ray;

/// A ray tracing engine under test: built once, traced many times.
pub(super) trait Engine: Sync + Send {
    /// Closest hit of one ray.
    fn closest(&self, ray: &Ray) -> HitRecord;
    /// Closest hit of one ray of an incoherent set (a path tracer's bounces, the bench's
    /// secondary rays): an engine with a walk for such rays uses it, the others
    /// [`Engine::closest`].
    fn closest_incoherent(&self, ray: &Ray) -> HitRecord {
        self.closest(ray)
    }
    /// Whether anything lies on the ray.
    fn occluded(&self, ray: &Ray) -> bool;
    /// Whether the engine has a batched query for incoherent rays
    /// ([`Engine::closest_batch`], [`Engine::occluded_batch`]).
    fn batched(&self) -> bool {
        false
    }
    /// Closest hits of a batch of incoherent rays in one call (an engine with
    /// [`Engine::batched`]; the others one by one); each ray's record to the same index of
    /// `out`.
    fn closest_batch(&self, rays: &[Ray], out: &mut [HitRecord]) {
        for (o, r) in out.iter_mut().zip(rays) {
            *o = self.closest_incoherent(r);
        }
    }
    /// Occluded rays among a batch of incoherent rays, in one call where the engine has one.
    fn occluded_batch(&self, rays: &[Ray]) -> usize {
        rays.iter().filter(|r| self.occluded(r)).count()
    }
    /// The build time the engine measured itself, when its builder call does more than build
    /// (Embree's creates a device, with its thread pool, first); `None`: the call's time.
    fn build_ms(&self) -> Option<f64> {
        None
    }
    /// The instruction set the engine traces with, when it says (see
    /// [`super::EngineResult::isa`]).
    fn isa(&self) -> Option<&'static str> {
        None
    }
    /// Side of the square pixel tiles a packet engine traces at once; `None` for single rays.
    fn tile(&self) -> Option<u32> {
        None
    }
    /// Closest hits of one tile's rays (packet engines): the tile of up to `tile()` rows of
    /// up to `tile()` rays (fewer at the image's right edge) whose first ray is `band[x0]`,
    /// rows `width` rays apart; each ray's record goes to the same index of `out`.
    fn closest_tile(&self, band: &[Ray], width: usize, x0: usize, out: &mut [HitRecord]) {
        for_each_in_tile(self, band.len(), width, x0, |at| {
            out[at] = self.closest(&band[at])
        });
    }
    /// Occluded rays among one tile's rays (the tile as in [`Engine::closest_tile`]).
    fn occluded_tile(&self, band: &[Ray], width: usize, x0: usize) -> usize {
        let mut n = 0;
        for_each_in_tile(self, band.len(), width, x0, |at| {
            n += self.occluded(&band[at]) as usize
        });
        n
    }
}

/// Calls `f(at)` with the index of every ray of the tile whose first ray is `x0` of a band of
/// `len` rays in rows `width` long, tiles being `engine.tile()` wide (one ray without one).
fn for_each_in_tile(
    engine: &(impl Engine + ?Sized),
    len: usize,
    width: usize,
    x0: usize,
    mut f: impl FnMut(usize),
) {
    let x1 = (x0 + engine.tile().unwrap_or(1) as usize).min(width);
    for y in 0..len / width {
        (x0..x1).for_each(|x| f(y * width + x));
    }
}

/// Our packets' tile (see [`Engine::closest_tile`]) as a [`RayTile`].
fn ray_tile(band: &[Ray], width: usize, x0: usize) -> RayTile<'_> {
    let cols = Packets::TILE.min(width - x0);
    RayTile::new(&band[x0..], width, cols, band.len() / width).expect("a tile of the band")
}

/// A hit of ours as a record.
fn record(hit: Option<crate::bvh::Hit>) -> HitRecord {
    match hit {
        Some(h) => HitRecord {
            t: h.t,
            prim: h.prim,
        },
        None => HitRecord::MISS,
    }
}

impl Engine for Bvh {
    fn closest(&self, ray: &Ray) -> HitRecord {
        record(self.intersect(ray, f32::INFINITY))
    }
    fn closest_incoherent(&self, ray: &Ray) -> HitRecord {
        record(self.intersect_incoherent(ray, f32::INFINITY))
    }
    fn occluded(&self, ray: &Ray) -> bool {
        Bvh::occluded(self, ray, f32::INFINITY)
    }
    fn isa(&self) -> Option<&'static str> {
        Some(self.kernel().name())
    }
}

/// Our BVH tracing camera-ray tiles of 8 x 8 as packets ([`Bvh::intersect_packet`],
/// [`Bvh::occluded_packet`]).
pub(super) struct Packets(pub Bvh);

impl Packets {
    /// Side of the tiles: one packet of 8 x 8 rays.
    const TILE: usize = 8;
}

impl Engine for Packets {
    fn closest(&self, ray: &Ray) -> HitRecord {
        self.0.closest(ray)
    }
    fn occluded(&self, ray: &Ray) -> bool {
        Bvh::occluded(&self.0, ray, f32::INFINITY)
    }
    fn isa(&self) -> Option<&'static str> {
        self.0.isa()
    }
    fn tile(&self) -> Option<u32> {
        Some(Self::TILE as u32)
    }
    fn occluded_tile(&self, band: &[Ray], width: usize, x0: usize) -> usize {
        let mut n = 0;
        self.0
            .occluded_tile(ray_tile(band, width, x0), f32::INFINITY, |_, b| {
                n += b as usize
            });
        n
    }
    fn closest_tile(&self, band: &[Ray], width: usize, x0: usize, out: &mut [HitRecord]) {
        let out = &mut out[x0..];
        self.0
            .intersect_tile(ray_tile(band, width, x0), f32::INFINITY, |at, h| {
                out[at] = record(h)
            });
    }
}

/// Rays a worker takes at a time when tracing single rays.
///
/// Every chunk (and every band of tiles) is a job of its own (`with_max_len(1)`): rayon's
/// default split makes four sequential pieces for two threads, and a thread that has finished
/// cannot take over a piece the other has started, so it waited out the other's last piece
/// (the canonical rays cost unevenly down the image). `examples/split_idle.rs` measures
/// the idle thread's wait per two-thread trace with and without it; what is left is mostly
/// waking the workers.
const CHUNK: usize = 1024;

/// Closest hits of all rays into `out` (one per ray) on the current rayon pool: one ray at a
/// time, or tile by tile for a packet engine (`width` is the image width of the rays,
/// row-major).
pub(super) fn trace_closest(
    engine: &dyn Engine,
    rays: &[Ray],
    width: usize,
    out: &mut [HitRecord],
) {
    assert_eq!(rays.len(), out.len(), "one record per ray");
    match engine.tile() {
        None => trace_singles(rays, out, |r| engine.closest(r)),
        Some(t) => {
            let band = width * t as usize;
            out.par_chunks_mut(band)
                .enumerate()
                .with_max_len(1)
                .for_each(|(b, out)| {
                    let band = &rays[b * band..(b * band + out.len())];
                    for x0 in (0..width).step_by(t as usize) {
                        engine.closest_tile(band, width, x0, out);
                    }
                });
        }
    }
}

/// Closest hits of all rays into `out` (one per ray) on the current rayon pool, one ray at a
/// time by [`Engine::closest_incoherent`] (packet engines too).
pub(super) fn trace_closest_incoherent(engine: &dyn Engine, rays: &[Ray], out: &mut [HitRecord]) {
    assert_eq!(rays.len(), out.len(), "one record per ray");
    trace_singles(rays, out, |r| engine.closest_incoherent(r));
}

/// Closest hits of an incoherent set by the engine's batched query, [`CHUNK`] consecutive
/// rays a call, on the current pool.
pub(super) fn trace_closest_batched(engine: &dyn Engine, rays: &[Ray], out: &mut [HitRecord]) {
    assert_eq!(rays.len(), out.len(), "one record per ray");
    out.par_chunks_mut(CHUNK)
        .enumerate()
        .with_max_len(1)
        .for_each(|(c, o)| {
            engine.closest_batch(&rays[c * CHUNK..c * CHUNK + o.len()], o);
        });
}

/// Occluded rays of an incoherent set by the engine's batched query, as
/// [`trace_closest_batched`].
pub(super) fn trace_occluded_batched(engine: &dyn Engine, rays: &[Ray]) -> usize {
    rays.par_chunks(CHUNK)
        .with_max_len(1)
        .map(|c| engine.occluded_batch(c))
        .sum()
}

/// `out[i] = closest(&rays[i])` for every ray, in chunks of [`CHUNK`] on the current pool.
fn trace_singles(
    rays: &[Ray],
    out: &mut [HitRecord],
    closest: impl Fn(&Ray) -> HitRecord + Sync + Send,
) {
    out.par_chunks_mut(CHUNK)
        .enumerate()
        .with_max_len(1)
        .for_each(|(c, o)| {
            for (o, r) in o.iter_mut().zip(&rays[c * CHUNK..]) {
                *o = closest(r);
            }
        });
}

/// Number of occluded rays, traced like [`trace_closest`].
pub(super) fn trace_occluded(engine: &dyn Engine, rays: &[Ray], width: usize) -> usize {
    match engine.tile() {
        None => rays
            .par_chunks(CHUNK)
            .with_max_len(1)
            .map(|r| r.iter().filter(|r| engine.occluded(r)).count())
            .sum(),
        Some(t) => {
            let t = t as usize;
            rays.par_chunks(width * t)
                .with_max_len(1)
                .map(|band| {
                    (0..width)
                        .step_by(t)
                        .map(|x0| engine.occluded_tile(band, width, x0))
                        .sum::<usize>()
                })
                .sum()
        }
    }
}
