//! Embree 3 (Debian's `libembree-dev`), the engine users would pick instead, through the few
//! functions a benchmark needs: a device, a scene of one triangle geometry over shared buffers
//! at medium build quality, `rtcIntersect1` / `rtcOccluded1` for single rays,
//! `rtcIntersect16` / `rtcOccluded16` for coherent 4x4-pixel packets, and `rtcIntersect1M` /
//! `rtcOccluded1M` for streams of incoherent rays.
//!
//! Its build is timed as its users time it: the device ([`Device`], its thread pool) and the
//! triangles' buffers ([`Buffers`]) are made once, and `rtcCommitScene` alone is timed. The C
//! program `embree_build.c` beside this file times the same calls in a process of its own;
//! `scripts/embree-build-time` compares the two.
//!
//! Embree is not linked: its library (`libembree3.so.3`) is loaded when the benchmark first
//! asks for it ([`available`]), so every build has the peer where Embree is installed. The struct
//! layouts follow `embree3/rtcore_ray.h` and `rtcore_common.h` of Embree 3.13 with
//! `RTC_MAX_INSTANCE_LEVEL_COUNT` 1 and `RTC_MIN_WIDTH` 0, Debian's configuration;
//! `tests/embree.rs` checks single rays against brute force and packets against ours, on every
//! instruction set the device can be held to.
#![allow(
    unsafe_code,
    reason = "FFI to the Embree C library, each call's contract noted"
)]

use std::ffi::{c_char, c_int, c_uint, c_void};
use std::sync::Arc;

use anyhow::{Result, bail};
use glam::Vec3;

use super::HitRecord;
use super::engines::Engine;
use crate::bvh::wide::Kernel;
use crate::geometry::Ray;

type RtcDevice = *mut c_void;
type RtcScene = *mut c_void;
type RtcGeometry = *mut c_void;

const RTC_INVALID_GEOMETRY_ID: c_uint = u32::MAX;
const RTC_GEOMETRY_TYPE_TRIANGLE: c_int = 0;
const RTC_BUFFER_TYPE_INDEX: c_int = 0;
const RTC_BUFFER_TYPE_VERTEX: c_int = 1;
const RTC_FORMAT_UINT3: c_int = 0x5003;
const RTC_FORMAT_FLOAT3: c_int = 0x9003;
const RTC_BUILD_QUALITY_MEDIUM: c_int = 1;
const RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT: c_int = 0;
const RTC_INTERSECT_CONTEXT_FLAG_COHERENT: c_int = 1;

/// `struct RTCRay`.
#[repr(C, align(16))]
#[derive(Clone, Copy, Default)]
struct RtcRay {
    org: [f32; 3],
    tnear: f32,
    dir: [f32; 3],
    time: f32,
    tfar: f32,
    mask: c_uint,
    id: c_uint,
    flags: c_uint,
}

/// `struct RTCHit`.
#[repr(C, align(16))]
#[derive(Clone, Copy, Default)]
struct RtcHit {
    ng: [f32; 3],
    u: f32,
    v: f32,
    prim_id: c_uint,
    geom_id: c_uint,
    inst_id: [c_uint; 1],
}

/// `struct RTCRayHit`.
#[repr(C)]
#[derive(Clone, Copy, Default)]
struct RtcRayHit {
    ray: RtcRay,
    hit: RtcHit,
}

/// `struct RTCRay16`.
#[repr(C, align(64))]
struct RtcRay16 {
    org: [[f32; 16]; 3],
    tnear: [f32; 16],
    dir: [[f32; 16]; 3],
    time: [f32; 16],
    tfar: [f32; 16],
    mask: [c_uint; 16],
    id: [c_uint; 16],
    flags: [c_uint; 16],
}

/// `struct RTCHit16`.
#[repr(C, align(64))]
struct RtcHit16 {
    ng: [[f32; 16]; 3],
    u: [f32; 16],
    v: [f32; 16],
    prim_id: [c_uint; 16],
    geom_id: [c_uint; 16],
    inst_id: [[c_uint; 16]; 1],
}

/// `struct RTCRayHit16`.
#[repr(C)]
struct RtcRayHit16 {
    ray: RtcRay16,
    hit: RtcHit16,
}

/// `struct RTCIntersectContext` (as `rtcInitIntersectContext` fills it).
#[repr(C)]
struct RtcIntersectContext {
    flags: c_int,
    filter: Option<unsafe extern "C" fn(*const c_void)>,
    inst_id: [c_uint; 1],
}

impl RtcIntersectContext {
    fn new(flags: c_int) -> Self {
        Self {
            flags,
            filter: None,
            inst_id: [RTC_INVALID_GEOMETRY_ID],
        }
    }
}

/// The Embree 3 functions the benchmark calls, looked up in the shared library when the
/// benchmark first asks for Embree: a build of Tracery needs no Embree, and a machine that has
/// one gets it as a peer without a rebuild.
struct Api {
    new_device: unsafe extern "C" fn(config: *const c_char) -> RtcDevice,
    release_device: unsafe extern "C" fn(device: RtcDevice),
    get_device_error: unsafe extern "C" fn(device: RtcDevice) -> c_int,
    new_scene: unsafe extern "C" fn(device: RtcDevice) -> RtcScene,
    release_scene: unsafe extern "C" fn(scene: RtcScene),
    set_scene_build_quality: unsafe extern "C" fn(scene: RtcScene, quality: c_int),
    new_geometry: unsafe extern "C" fn(device: RtcDevice, kind: c_int) -> RtcGeometry,
    set_shared_geometry_buffer: unsafe extern "C" fn(
        geometry: RtcGeometry,
        kind: c_int,
        slot: c_uint,
        format: c_int,
        ptr: *const c_void,
        byte_offset: usize,
        byte_stride: usize,
        item_count: usize,
    ),
    commit_geometry: unsafe extern "C" fn(geometry: RtcGeometry),
    attach_geometry: unsafe extern "C" fn(scene: RtcScene, geometry: RtcGeometry) -> c_uint,
    release_geometry: unsafe extern "C" fn(geometry: RtcGeometry),
    commit_scene: unsafe extern "C" fn(scene: RtcScene),
    intersect1: unsafe extern "C" fn(
        scene: RtcScene,
        context: *mut RtcIntersectContext,
        rayhit: *mut RtcRayHit,
    ),
    occluded1:
        unsafe extern "C" fn(scene: RtcScene, context: *mut RtcIntersectContext, ray: *mut RtcRay),
    intersect16: unsafe extern "C" fn(
        valid: *const c_int,
        scene: RtcScene,
        context: *mut RtcIntersectContext,
        rayhit: *mut RtcRayHit16,
    ),
    occluded16: unsafe extern "C" fn(
        valid: *const c_int,
        scene: RtcScene,
        context: *mut RtcIntersectContext,
        ray: *mut RtcRay16,
    ),
    intersect1m: unsafe extern "C" fn(
        scene: RtcScene,
        context: *mut RtcIntersectContext,
        rayhit: *mut RtcRayHit,
        count: c_uint,
        byte_stride: usize,
    ),
    occluded1m: unsafe extern "C" fn(
        scene: RtcScene,
        context: *mut RtcIntersectContext,
        ray: *mut RtcRay,
        count: c_uint,
        byte_stride: usize,
    ),
    /// The file the functions came from.
    path: String,
    /// Keeps the library loaded while the function pointers above are in use (for the rest of
    /// the process: the `Api` lives in a static).
    _library: libloading::Library,
}

/// The file names tried, in order: the runtime library's SONAME (Debian's `libembree3-3`),
/// then the development link (`libembree-dev`).
const LIBRARY_NAMES: [&str; 2] = ["libembree3.so.3", "libembree3.so"];

impl Api {
    fn load() -> std::result::Result<Api, String> {
        let mut tried = Vec::new();
        for name in LIBRARY_NAMES {
            // SAFETY: loading Embree runs its library initialisers, which have no
            // preconditions on the caller; the library stays loaded for the process.
            match unsafe { libloading::Library::new(name) } {
                Ok(library) => return Self::from_library(library, name),
                Err(e) => tried.push(format!("{name}: {e}")),
            }
        }
        Err(format!(
            "Embree 3 not found ({}); on Debian or Ubuntu: apt-get install libembree-dev",
            tried.join("; ")
        ))
    }

    fn from_library(library: libloading::Library, name: &str) -> std::result::Result<Api, String> {
        /// Looks up one function; its Rust type must match Embree 3's C declaration.
        fn get<T: Copy>(
            library: &libloading::Library,
            symbol: &str,
        ) -> std::result::Result<T, String> {
            // SAFETY: each call below names a function of Embree 3's C API with the type of
            // its declaration in `embree3/rtcore_*.h` (the field's type), so calling the
            // pointer through that type is sound.
            unsafe { library.get::<T>(symbol.as_bytes()) }
                .map(|s| *s)
                .map_err(|e| format!("{symbol}: {e}"))
        }
        let l = &library;
        let path = format!("{name} (Embree 3)");
        Ok(Api {
            new_device: get(l, "rtcNewDevice")?,
            release_device: get(l, "rtcReleaseDevice")?,
            get_device_error: get(l, "rtcGetDeviceError")?,
            new_scene: get(l, "rtcNewScene")?,
            release_scene: get(l, "rtcReleaseScene")?,
            set_scene_build_quality: get(l, "rtcSetSceneBuildQuality")?,
            new_geometry: get(l, "rtcNewGeometry")?,
            set_shared_geometry_buffer: get(l, "rtcSetSharedGeometryBuffer")?,
            commit_geometry: get(l, "rtcCommitGeometry")?,
            attach_geometry: get(l, "rtcAttachGeometry")?,
            release_geometry: get(l, "rtcReleaseGeometry")?,
            commit_scene: get(l, "rtcCommitScene")?,
            intersect1: get(l, "rtcIntersect1")?,
            occluded1: get(l, "rtcOccluded1")?,
            intersect16: get(l, "rtcIntersect16")?,
            occluded16: get(l, "rtcOccluded16")?,
            intersect1m: get(l, "rtcIntersect1M")?,
            occluded1m: get(l, "rtcOccluded1M")?,
            path,
            _library: library,
        })
    }
}

/// Embree's functions, loaded on first use; the error says what was tried and how to install
/// Embree.
fn api() -> std::result::Result<&'static Api, &'static str> {
    static API: std::sync::OnceLock<std::result::Result<Api, String>> = std::sync::OnceLock::new();
    API.get_or_init(Api::load).as_ref().map_err(|e| e.as_str())
}

/// Whether Embree 3 can be loaded: the library's name, or why not (with how to install it).
pub fn available() -> std::result::Result<&'static str, &'static str> {
    api().map(|a| a.path.as_str())
}

/// An Embree device: its thread pool and its settings (thread count, instruction set), made
/// once and shared by every scene built on it, as Embree's users keep one.
pub struct Device {
    api: &'static Api,
    handle: RtcDevice,
    /// The instruction set the device was held to (`None`: Embree's choice).
    isa: Option<&'static str>,
}

// SAFETY: Embree's device functions are thread-safe (its API documentation: a device may be
// used from several threads), and the handle is only released in `drop`.
unsafe impl Send for Device {}
// SAFETY: as above.
unsafe impl Sync for Device {}

impl Device {
    /// A device building with `threads` threads, held to the instruction set of one of our
    /// kernels (its `isa` setting: [`Embree::isa_name`]) or, with `None`, choosing its kernels
    /// for the CPU. The CPU must run the instruction set.
    pub fn new(threads: usize, isa: Option<Kernel>) -> Result<Arc<Device>> {
        let api = api().map_err(anyhow::Error::msg)?;
        let isa = isa.map(Embree::isa_name);
        let held = isa.map_or(String::new(), |i| format!(",isa={i}"));
        let config = std::ffi::CString::new(format!("threads={}{held}", threads.max(1)))
            .expect("no NUL in a number or an ISA name");
        // SAFETY: `config` is a NUL-terminated string that outlives the call.
        let handle = unsafe { (api.new_device)(config.as_ptr()) };
        if handle.is_null() {
            bail!("Embree: rtcNewDevice failed (is this CPU one Embree supports?)");
        }
        Ok(Arc::new(Device { api, handle, isa }))
    }

    fn error(&self) -> c_int {
        // SAFETY: `self.handle` is live until `drop`.
        unsafe { (self.api.get_device_error)(self.handle) }
    }
}

impl Drop for Device {
    fn drop(&mut self) {
        // SAFETY: the handle is live and released once; every scene built on the device holds
        // an `Arc` of it, so none outlives it.
        unsafe { (self.api.release_device)(self.handle) }
    }
}

/// A triangle list as Embree's shared buffers: three vertices of its own per triangle (no
/// vertex is shared, as the triangles come) and their indices, made once and read by every
/// scene built over them.
pub struct Buffers {
    /// `9 n` floats and one more: Embree reads a vertex with a 16-byte load, so the buffer
    /// must be readable 4 bytes past the last vertex.
    vertices: Vec<f32>,
    /// `3 n` indices, `0..3 n`.
    indices: Vec<u32>,
}

impl Buffers {
    /// The buffers of `triangles` (finite ones: the benchmark leaves out the others before any
    /// engine sees them).
    pub fn of(triangles: &[[Vec3; 3]]) -> Arc<Buffers> {
        let mut vertices: Vec<f32> = triangles
            .iter()
            .flatten()
            .flat_map(|v| v.to_array())
            .collect();
        vertices.push(0.0);
        let indices = (0..3 * triangles.len() as u32).collect();
        Arc::new(Buffers { vertices, indices })
    }

    fn triangles(&self) -> usize {
        self.indices.len() / 3
    }
}

/// A committed Embree scene of one triangle geometry over shared [`Buffers`], on a [`Device`]
/// (built with the device's threads; tracing runs on whatever threads call it).
pub struct Embree {
    api: &'static Api,
    scene: RtcScene,
    /// Milliseconds `rtcCommitScene` took, the build alone: the device and the buffers were
    /// made before, as Embree's users time it (and as `src/bench/embree_build.c` does).
    pub build_ms: f64,
    /// Kept alive while the scene refers to them.
    device: Arc<Device>,
    _buffers: Arc<Buffers>,
}

// SAFETY: Embree documents a committed scene as safe to trace from any number of threads at
// once, and the scene handle is only released in `drop`; the device and the buffers are
// `Send` and `Sync` (the buffers are never written after they are made).
unsafe impl Send for Embree {}
// SAFETY: as above; `&Embree` only reaches the thread-safe trace calls.
unsafe impl Sync for Embree {}

impl Embree {
    /// Builds the scene at medium quality with `threads` threads, Embree choosing its kernels
    /// for the CPU, on a device and buffers of its own. Triangles must be finite.
    pub fn build(triangles: &[[Vec3; 3]], threads: usize) -> Result<Embree> {
        Self::build_for(triangles, threads, None)
    }

    /// [`Embree::build`] with Embree held to the instruction set of one of our kernels
    /// ([`Device::new`]).
    pub fn build_for(
        triangles: &[[Vec3; 3]],
        threads: usize,
        isa: Option<Kernel>,
    ) -> Result<Embree> {
        Self::build_on(&Device::new(threads, isa)?, &Buffers::of(triangles))
    }

    /// Builds a scene over `buffers` at medium quality on `device`, timing `rtcCommitScene`
    /// alone.
    pub fn build_on(device: &Arc<Device>, buffers: &Arc<Buffers>) -> Result<Embree> {
        let api = device.api;
        let handle = device.handle;
        // SAFETY: `handle` is a live device handle.
        let scene = unsafe { (api.new_scene)(handle) };
        if scene.is_null() {
            bail!("Embree: rtcNewScene failed ({})", device.error());
        }
        // From here `Drop` releases the scene.
        let mut e = Embree {
            api,
            scene,
            build_ms: 0.0,
            device: Arc::clone(device),
            _buffers: Arc::clone(buffers),
        };
        // SAFETY: `scene` is a live scene handle.
        unsafe { (api.set_scene_build_quality)(scene, RTC_BUILD_QUALITY_MEDIUM) };
        // SAFETY: `handle` is live; the geometry is released below after attaching.
        let geometry = unsafe { (api.new_geometry)(handle, RTC_GEOMETRY_TYPE_TRIANGLE) };
        if geometry.is_null() {
            bail!("Embree: rtcNewGeometry failed ({})", device.error());
        }
        let n = buffers.triangles();
        // SAFETY: `geometry` is live; the buffers hold `3 n` float3 vertices (plus the padding
        // Embree's loads need) and `n` uint3 triangles at the given strides, are never written
        // again, and outlive the scene (`e` holds an `Arc` of them); the scene keeps its own
        // reference to the geometry, so ours is released at once.
        unsafe {
            (api.set_shared_geometry_buffer)(
                geometry,
                RTC_BUFFER_TYPE_VERTEX,
                0,
                RTC_FORMAT_FLOAT3,
                buffers.vertices.as_ptr().cast(),
                0,
                12,
                3 * n,
            );
            (api.set_shared_geometry_buffer)(
                geometry,
                RTC_BUFFER_TYPE_INDEX,
                0,
                RTC_FORMAT_UINT3,
                buffers.indices.as_ptr().cast(),
                0,
                12,
                n,
            );
            (api.commit_geometry)(geometry);
            (api.attach_geometry)(scene, geometry);
            (api.release_geometry)(geometry);
        }
        let start = std::time::Instant::now();
        // SAFETY: `scene` is live, its geometry committed and attached.
        unsafe { (api.commit_scene)(scene) };
        e.build_ms = start.elapsed().as_secs_f64() * 1e3;
        match device.error() {
            0 => Ok(e),
            code => bail!("Embree: the scene build failed (error {code})"),
        }
    }
}

impl Drop for Embree {
    fn drop(&mut self) {
        // SAFETY: the scene handle is live and released once (the device, held by `self`,
        // outlives it).
        unsafe { (self.api.release_scene)(self.scene) }
    }
}

fn rtc_ray(r: &Ray) -> RtcRay {
    RtcRay {
        org: r.origin.to_array(),
        tnear: 0.0,
        dir: r.dir.to_array(),
        time: 0.0,
        tfar: f32::INFINITY,
        mask: u32::MAX,
        id: 0,
        flags: 0,
    }
}

impl Engine for Embree {
    fn build_ms(&self) -> Option<f64> {
        Some(self.build_ms)
    }
    fn isa(&self) -> Option<&'static str> {
        self.device.isa
    }
    fn closest(&self, ray: &Ray) -> HitRecord {
        self.intersect1(ray)
    }

    fn occluded(&self, ray: &Ray) -> bool {
        self.occluded1(ray)
    }
}

impl Embree {
    /// Embree's name for the instruction set of one of our kernels (its `isa` device setting).
    /// Embree has no scalar kernels: `scalar` maps to its SSE2 ones.
    pub fn isa_name(kernel: Kernel) -> &'static str {
        match kernel {
            Kernel::Scalar | Kernel::Sse2 => "sse2",
            Kernel::Avx2 => "avx2",
            Kernel::Avx512 => "avx512",
        }
    }

    /// `rtcIntersect1`: the closest hit of one ray.
    pub fn intersect1(&self, ray: &Ray) -> HitRecord {
        let mut rh = RtcRayHit {
            ray: rtc_ray(ray),
            hit: RtcHit {
                geom_id: RTC_INVALID_GEOMETRY_ID,
                inst_id: [RTC_INVALID_GEOMETRY_ID],
                ..RtcHit::default()
            },
        };
        let mut ctx = RtcIntersectContext::new(RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT);
        // SAFETY: the scene is committed and live; `ctx` and `rh` are valid, aligned and
        // exclusively borrowed for the call.
        unsafe { (self.api.intersect1)(self.scene, &mut ctx, &mut rh) };
        if rh.hit.geom_id == RTC_INVALID_GEOMETRY_ID {
            HitRecord::MISS
        } else {
            HitRecord {
                t: rh.ray.tfar,
                prim: rh.hit.prim_id,
            }
        }
    }

    /// `rtcOccluded1`: whether anything lies on the ray.
    pub fn occluded1(&self, ray: &Ray) -> bool {
        let mut r = rtc_ray(ray);
        let mut ctx = RtcIntersectContext::new(RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT);
        // SAFETY: as in `closest`.
        unsafe { (self.api.occluded1)(self.scene, &mut ctx, &mut r) };
        r.tfar == f32::NEG_INFINITY
    }

    /// `rtcIntersect1M` with the incoherent flag: the closest hits of a stream of rays that
    /// take different paths, in one call (Embree regroups them into packets itself); each
    /// ray's record to the same index of `out`.
    pub fn intersect_stream(&self, rays: &[Ray], out: &mut [HitRecord]) {
        assert_eq!(rays.len(), out.len(), "one record per ray");
        let mut stream: Vec<RtcRayHit> = rays
            .iter()
            .map(|r| RtcRayHit {
                ray: rtc_ray(r),
                hit: RtcHit {
                    geom_id: RTC_INVALID_GEOMETRY_ID,
                    inst_id: [RTC_INVALID_GEOMETRY_ID],
                    ..RtcHit::default()
                },
            })
            .collect();
        let mut ctx = RtcIntersectContext::new(RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT);
        // SAFETY: the scene is committed; `ctx` and the `stream.len()` records, each 16-byte
        // aligned and `size_of::<RtcRayHit>()` apart, are live and exclusively borrowed for
        // the call.
        unsafe {
            (self.api.intersect1m)(
                self.scene,
                &mut ctx,
                stream.as_mut_ptr(),
                stream.len() as c_uint,
                std::mem::size_of::<RtcRayHit>(),
            )
        };
        for (o, h) in out.iter_mut().zip(&stream) {
            *o = if h.hit.geom_id == RTC_INVALID_GEOMETRY_ID {
                HitRecord::MISS
            } else {
                HitRecord {
                    t: h.ray.tfar,
                    prim: h.hit.prim_id,
                }
            };
        }
    }

    /// `rtcOccluded1M` with the incoherent flag: whether anything lies on each ray of a
    /// stream, in one call, to the same index of `blocked`.
    pub fn occluded_stream(&self, rays: &[Ray], blocked: &mut [bool]) {
        assert_eq!(rays.len(), blocked.len(), "one answer per ray");
        let mut stream: Vec<RtcRay> = rays.iter().map(rtc_ray).collect();
        let mut ctx = RtcIntersectContext::new(RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT);
        // SAFETY: as in `intersect_stream`, with rays alone (`rtcOccluded1M` reads and writes
        // no hit).
        unsafe {
            (self.api.occluded1m)(
                self.scene,
                &mut ctx,
                stream.as_mut_ptr(),
                stream.len() as c_uint,
                std::mem::size_of::<RtcRay>(),
            )
        };
        for (b, r) in blocked.iter_mut().zip(&stream) {
            *b = r.tfar == f32::NEG_INFINITY;
        }
    }
}

/// Embree's own coherent packets: `rtcIntersect16` / `rtcOccluded16` on 4x4-pixel tiles with
/// the coherent context flag.
pub struct EmbreePackets(pub Embree);

/// A packet of 16 rays from the origin along zero with no hit: each query fills in its
/// rays and valid lanes.
fn empty_packet() -> RtcRayHit16 {
    RtcRayHit16 {
        ray: RtcRay16 {
            org: [[0.0; 16]; 3],
            tnear: [0.0; 16],
            dir: [[0.0; 16]; 3],
            time: [0.0; 16],
            tfar: [f32::INFINITY; 16],
            mask: [u32::MAX; 16],
            id: [0; 16],
            flags: [0; 16],
        },
        hit: RtcHit16 {
            ng: [[0.0; 16]; 3],
            u: [0.0; 16],
            v: [0.0; 16],
            prim_id: [0; 16],
            geom_id: [RTC_INVALID_GEOMETRY_ID; 16],
            inst_id: [[RTC_INVALID_GEOMETRY_ID; 16]],
        },
    }
}

/// The packet of a tile of up to 4 x 4 rays (see [`Engine::closest_tile`]; the rest of the
/// lanes invalid), with each lane's index in the band.
fn packet(band: &[Ray], width: usize, x0: usize) -> (RtcRayHit16, [c_int; 16], [usize; 16]) {
    let mut p = empty_packet();
    let mut valid = [0 as c_int; 16];
    let mut at = [usize::MAX; 16];
    let x1 = (x0 + 4).min(width);
    let mut k = 0;
    for y in 0..band.len() / width {
        for x in x0..x1 {
            let r = &band[y * width + x];
            for a in 0..3 {
                p.ray.org[a][k] = r.origin[a];
                p.ray.dir[a][k] = r.dir[a];
            }
            (valid[k], at[k]) = (-1, y * width + x);
            k += 1;
        }
    }
    (p, valid, at)
}

impl Engine for EmbreePackets {
    fn build_ms(&self) -> Option<f64> {
        Some(self.0.build_ms)
    }
    fn closest(&self, ray: &Ray) -> HitRecord {
        self.0.closest(ray)
    }

    fn occluded(&self, ray: &Ray) -> bool {
        self.0.occluded(ray)
    }

    fn isa(&self) -> Option<&'static str> {
        self.0.device.isa
    }
    fn tile(&self) -> Option<u32> {
        Some(4)
    }

    /// Embree's stream queries, `rtcIntersect1M` / `rtcOccluded1M` with the incoherent context
    /// flag: its batched query for rays that take different paths (it regroups a stream into
    /// packets itself), faster there than `rtcIntersect16` on 16 consecutive rays.
    fn batched(&self) -> bool {
        true
    }

    fn closest_batch(&self, rays: &[Ray], out: &mut [HitRecord]) {
        self.0.intersect_stream(rays, out);
    }

    fn occluded_batch(&self, rays: &[Ray]) -> usize {
        let mut blocked = vec![false; rays.len()];
        self.0.occluded_stream(rays, &mut blocked);
        blocked.into_iter().filter(|&b| b).count()
    }

    fn closest_tile(&self, band: &[Ray], width: usize, x0: usize, out: &mut [HitRecord]) {
        let (mut p, valid, at) = packet(band, width, x0);
        let mut ctx = RtcIntersectContext::new(RTC_INTERSECT_CONTEXT_FLAG_COHERENT);
        // SAFETY: the scene is committed; `valid`, `ctx` and the 64-byte aligned packet are
        // live and exclusively borrowed for the call; unused lanes are 0 in `valid`.
        unsafe { (self.0.api.intersect16)(valid.as_ptr(), self.0.scene, &mut ctx, &mut p) };
        for (k, &at) in at
            .iter()
            .enumerate()
            .take_while(|&(_, &at)| at != usize::MAX)
        {
            out[at] = if p.hit.geom_id[k] == RTC_INVALID_GEOMETRY_ID {
                HitRecord::MISS
            } else {
                HitRecord {
                    t: p.ray.tfar[k],
                    prim: p.hit.prim_id[k],
                }
            };
        }
    }

    fn occluded_tile(&self, band: &[Ray], width: usize, x0: usize) -> usize {
        let (mut p, valid, _) = packet(band, width, x0);
        let mut ctx = RtcIntersectContext::new(RTC_INTERSECT_CONTEXT_FLAG_COHERENT);
        // SAFETY: as in `closest_tile`; `rtcOccluded16` reads and writes the ray part only.
        unsafe { (self.0.api.occluded16)(valid.as_ptr(), self.0.scene, &mut ctx, &mut p.ray) };
        (0..16)
            .filter(|&k| valid[k] != 0 && p.ray.tfar[k] == f32::NEG_INFINITY)
            .count()
    }
}
