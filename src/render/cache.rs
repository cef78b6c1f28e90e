//! The picture of a moving camera: a render cache (after Walter, Drettakis and Parker, "Interactive
//! Rendering using the Render Cache", 1999).
//!
//! Every pixel keeps its last sample: its colour as shown, where the camera ray met the scene
//! (or a point far along a ray that left it) and the surface's normal there. When the camera
//! moves, each kept sample is carried to the pixel it falls on in the new view
//! ([`RenderCache::reproject`]; the nearest sample wins a pixel), so the picture is at full
//! resolution at once. A carried sample is then moved within its surface's tangent plane to
//! where the new pixel's centre ray meets it: samples stay on the pixel grid, so a smooth
//! motion carries each pixel's sample to one pixel and only truly stretched or newly uncovered
//! parts lose samples (carried as they were, samples would scatter within their pixels and
//! collide more every frame: a third of them lost after a few frames of an orbit). (Filling
//! one-pixel cracks from a neighbour's sample, and tracing the holes spread over the picture,
//! were tried: both cost more than they gave, half the fresh samples and a worse picture.) Pixels no sample reaches
//! (newly uncovered) are traced first, a row's run of them at a time, the rows coarse to fine
//! so that a budget that runs out leaves the rest spread thin; then fresh samples go to 16 x 16 tiles by priority
//! ([`RenderCache::next_pixels`]): tiles whose new samples differed most from what they held
//! (changed or noisy) and tiles not visited for longest come first, and within a tile pixels
//! follow an ordered-dither order, so the fresh samples of one picture spread over the screen
//! instead of sweeping it row by row. For display, the samples go through a filter
//! ([`MovingFilter`]: the edge-avoiding wavelet filter of `wavelet`, or the four-neighbour
//! smoothing of `smooth`), and pixels still without a sample are filled from their
//! neighbourhood (pull-push).
//!
//! Samples are taken through pixel centres with one shadow ray per area light and kept tone
//! mapped for one exposure: the cache is for the moving picture; the still picture starts over
//! from fresh samples and becomes the headless render.

use glam::Vec3;
use rayon::prelude::*;

use super::{BAND, RayCounts, TILE_WIDTH, Tracer};

#[cfg(target_arch = "x86_64")]
mod project_x86;
mod smooth;
#[cfg(target_arch = "x86_64")]
mod smooth_sse2;
mod wavelet;
use crate::bvh::wide::packet::PACKET;
use crate::camera::CameraRays;
use crate::film::encode_pixel;
use crate::geometry::Ray;
use crate::sampling::{PathSampler, PixelSampler, SamplerKind};
use crate::scene::face_normal;

/// Side of the tiles samples are scheduled by.
pub const TILE: u32 = 16;

/// Pixels a tile gets per visit of [`RenderCache::next_pixels`].
const PER_VISIT: usize = 16;

/// Priority floor of a tile whose samples stopped changing: it is still visited as it ages.
const QUIET: f32 = 0.02;

/// Distance along its direction at which a ray that left the scene keeps its sample: beyond
/// any hit, so any surface in front wins its pixel, and far enough that moving the eye does not
/// move it on screen (a point at infinity).
const FAR: f32 = 1e30;

/// An empty pixel: a NaN point, and a colour of alpha 0.
const NO_POINT: [f32; 3] = [f32::NAN; 3];
const NO_COLOUR: [u8; 4] = [0; 4];

/// The normal of a sample that left the scene (or of an empty pixel).
const NO_NORMAL: [i8; 4] = [0; 4];

/// The albedo of an empty pixel (a sample that left the scene has `SKY_ALBEDO`).
const NO_ALBEDO: [u8; 4] = [0; 4];

/// How the moving picture's samples, one per pixel, are filtered for display (the samples and
/// the still picture are untouched).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MovingFilter {
    /// The samples as traced.
    Off,
    /// Each sample averaged with its four neighbours that show the same surface.
    Neighbours,
    /// The edge-avoiding à-trous wavelet filter (module `wavelet`): a footprint of up to 15 x 15
    /// pixels on each surface, guided by the samples' normals, points and albedos.
    #[default]
    Wavelet,
}

impl MovingFilter {
    /// Every filter, in the order the inspector lists them.
    pub const ALL: [MovingFilter; 3] = [Self::Off, Self::Neighbours, Self::Wavelet];

    /// The filter's name in reports and the inspector.
    pub fn name(self) -> &'static str {
        match self {
            Self::Off => "off",
            Self::Neighbours => "four neighbours",
            Self::Wavelet => "wavelet",
        }
    }
}

/// Largest relative change of a sample's depth when it moves to its new pixel's centre ray;
/// beyond it (a surface seen nearly edge-on) the sample stays where it was.
const MAX_RECENTRE: f32 = 0.05;

/// A unit normal packed in signed bytes.
fn pack_normal(n: Vec3) -> [i8; 4] {
    let q = |c: f32| (c.clamp(-1.0, 1.0) * 127.0) as i8;
    [q(n.x), q(n.y), q(n.z), 0]
}

fn unpack_normal(n: [i8; 4]) -> Vec3 {
    Vec3::new(n[0] as f32, n[1] as f32, n[2] as f32) * (1.0 / 127.0)
}

/// An albedo in `[0, 1]` packed in bytes (linear, in 255ths), beside the samples a colour
/// holds: one, for a fresh sample.
fn pack_albedo(a: Vec3) -> [u8; 4] {
    let q = |c: f32| (c.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
    [q(a.x), q(a.y), q(a.z), 1]
}

/// The albedo of a sample that left the scene, and of one whose albedo is not known: no colour,
/// one sample.
const SKY_ALBEDO: [u8; 4] = [0, 0, 0, 1];

/// How much a pixel's colour changed (0 to 1): the largest channel difference.
fn change(old: [u8; 4], new: [u8; 4]) -> f32 {
    (0..3).map(|c| old[c].abs_diff(new[c])).max().unwrap_or(0) as f32 / 255.0
}

/// The per-pixel samples of the moving picture and the schedule of fresh samples.
///
/// A pixel's sample is where its camera ray met the scene (or a point `FAR` along a ray that
/// left it), the surface normal there and its colour as shown, sRGB RGBA8; kept as separate
/// arrays, so the reprojection's first pass reads only the points and a picture is a copy of
/// the colours.
#[derive(Debug)]
pub struct RenderCache {
    width: u32,
    height: u32,
    /// Splits pixel indices into columns and rows.
    rows: Rows,
    points: Vec<[f32; 3]>,
    normals: Vec<[i8; 4]>,
    /// The albedo of the surface each sample hit, and in its fourth byte how many samples the
    /// colour averages (1 for a fresh sample, the still picture's count up to 255 for a colour
    /// from it; see `pack_albedo`): the wavelet filter's guide to material edges, and the
    /// weight it gives the colour.
    albedos: Vec<[u8; 4]>,
    colours: Vec<[u8; 4]>,
    /// Pixels holding no sample.
    holes: usize,
    /// Buffers the reprojection reuses (the next points, normals, albedos and colours, the
    /// winner of each pixel).
    spare_points: Vec<[f32; 3]>,
    spare_normals: Vec<[i8; 4]>,
    spare_albedos: Vec<[u8; 4]>,
    spare_colours: Vec<[u8; 4]>,
    winner: Vec<u64>,
    /// Exposure the colours were tone mapped with.
    exposure: f32,
    tiles: Tiles,
    /// Memory the wavelet filter reuses.
    wavelet: wavelet::Scratch,
    /// Calls of [`RenderCache::trace`] so far: the sample index of the next call's samples, so
    /// that a pixel traced again draws new light (and bounce) samples instead of repeating its
    /// last ones, and a noisy tile shows as changing and keeps its priority.
    traced: u32,
}

/// Per-tile schedule state.
#[derive(Clone, Debug)]
struct Tiles {
    cols: u32,
    rows: u32,
    /// How much the tile's last fresh samples differed from what its pixels held (0 to 1).
    change: Vec<f32>,
    /// Calls of `next_pixels` since the tile was last given pixels.
    age: Vec<u32>,
    /// Position of the tile in the ordered-dither order of its pixels.
    cursor: Vec<u16>,
    /// Samples traced in the tile since [`RenderCache::take_work`].
    work: Vec<u32>,
    /// Pixel offsets within a tile in ordered-dither order.
    order: Vec<(u8, u8)>,
}

/// Pixels per unit of the camera's right and up axes on the plane at unit depth, for a
/// `w x h` picture of `to`.
fn pixels_per_unit(to: &CameraRays, w: u32, h: u32) -> (f32, f32) {
    (
        0.5 * w as f32 / (to.tan_half * to.aspect),
        0.5 * h as f32 / to.tan_half,
    )
}

/// The pixel centres of a view, for moving samples onto them.
struct PixelGrid {
    eye: Vec3,
    forward: Vec3,
    /// One pixel's step right and down on the plane at unit depth.
    right: Vec3,
    up: Vec3,
    centre: (f32, f32),
    rows: Rows,
}

impl PixelGrid {
    fn new(to: &CameraRays, w: u32, h: u32) -> Self {
        let (kx, ky) = pixels_per_unit(to, w, h);
        Self {
            eye: to.eye,
            forward: to.forward,
            right: to.right / kx,
            up: to.up / ky,
            centre: (0.5 * w as f32, 0.5 * h as f32),
            rows: Rows::new(w),
        }
    }

    /// The centre ray of pixel `i`, scaled to unit depth along the view direction.
    fn centre_ray(&self, i: usize) -> Vec3 {
        let (x, y) = self.rows.xy(i as u32);
        let (x, y) = (x as f32 + 0.5, y as f32 + 0.5);
        self.forward + self.right * (x - self.centre.0) + self.up * (self.centre.1 - y)
    }

    /// Sample point `p` moved onto the centre ray `d` of its new pixel (from
    /// [`Self::centre_ray`]) within its tangent plane (normal `normal`); a sample that left the
    /// scene keeps its depth; one whose depth would change by more than [`MAX_RECENTRE`] (a
    /// surface seen nearly edge-on) stays where it is.
    fn recentre_along(&self, d: Vec3, p: [f32; 3], normal: [i8; 4]) -> [f32; 3] {
        let v = Vec3::from(p) - self.eye;
        let depth = v.dot(self.forward);
        if normal == NO_NORMAL {
            return (self.eye + d * depth).into();
        }
        let n = unpack_normal(normal);
        let s = v.dot(n) / d.dot(n);
        if (s - depth).abs() <= MAX_RECENTRE * depth {
            (self.eye + d * s).into()
        } else {
            p
        }
    }
}

/// Where a view's pixels are: the projection of points onto a `w x h` picture of a camera.
#[derive(Clone, Copy, Debug)]
pub(super) struct Projection {
    eye: Vec3,
    forward: Vec3,
    /// The camera's right and up axes scaled to pixels at unit depth.
    right: Vec3,
    up: Vec3,
    centre: (f32, f32),
    size: (f32, f32),
    width: i32,
}

impl Projection {
    fn new(to: &CameraRays, w: u32, h: u32) -> Self {
        let (kx, ky) = pixels_per_unit(to, w, h);
        Self {
            eye: to.eye,
            forward: to.forward,
            right: to.right * kx,
            up: to.up * ky,
            centre: (0.5 * w as f32, 0.5 * h as f32),
            size: (w as f32, h as f32),
            width: w as i32,
        }
    }
}

/// Projects each of `points` onto the picture of `to`: into `pixel` its pixel's index
/// (`u32::MAX` for none: behind the camera, outside the picture or an empty pixel's NaN point)
/// and into `depth` its depth's bits. Written without branches so that it vectorizes, and
/// inlined into each instruction set's copy (see [`project_x86`]).
#[inline(always)]
pub(super) fn project_points(
    to: &Projection,
    points: &[[f32; 3]],
    pixel: &mut [u32],
    depth: &mut [u32],
) {
    let (cx, cy) = to.centre;
    let (wf, hf) = to.size;
    for ((p, pixel), bits) in points.iter().zip(pixel).zip(depth) {
        let v = Vec3::from(*p) - to.eye;
        let z = v.dot(to.forward);
        let r = 1.0 / z;
        let (x, y) = (v.dot(to.right) * r + cx, cy - v.dot(to.up) * r);
        // (NaN fails every comparison.)
        let inside = z > 0.0 && x >= 0.0 && y >= 0.0 && x < wf && y < hf;
        // Truncation is the floor of these non-negative positions.
        let i = (y as i32).wrapping_mul(to.width).wrapping_add(x as i32) as u32;
        *pixel = if inside { i } else { u32::MAX };
        *bits = z.to_bits();
    }
}

/// [`project_points`] with the widest vectors the CPU has (AVX2 on x86-64 where present).
fn project_widest(to: &Projection, points: &[[f32; 3]], pixel: &mut [u32], depth: &mut [u32]) {
    #[cfg(target_arch = "x86_64")]
    project_x86::project_points(to, points, pixel, depth);
    #[cfg(not(target_arch = "x86_64"))]
    project_points(to, points, pixel, depth);
}

/// Writes each of `points` into `winner` at the pixel it falls on in the view `to` of a
/// `w x h` picture, where its key (depth, index in `points`) is the smallest so far; samples
/// behind the camera or outside the picture are left out.
fn scatter(to: &CameraRays, w: u32, h: u32, points: &[[f32; 3]], winner: &mut [u64]) {
    let to = Projection::new(to, w, h);
    // Runs of samples projected together, then written.
    const RUN: usize = 256;
    let mut pixel = [0u32; RUN];
    let mut depth = [0u32; RUN];
    for (run, ps) in points.chunks(RUN).enumerate() {
        let n = ps.len();
        project_widest(&to, ps, &mut pixel[..n], &mut depth[..n]);
        for (k, (&i, &bits)) in pixel[..n].iter().zip(&depth[..n]).enumerate() {
            if i != u32::MAX {
                let key = (u64::from(bits) << 32) | (run * RUN + k) as u64;
                let slot = &mut winner[i as usize];
                if key < *slot {
                    *slot = key;
                }
            }
        }
    }
}

/// The rows in the order holes are traced: every eighth row first (0, 8, 16, ...), then the
/// rows halfway between (4, 12, ...), then 2, 6, ..., then the odd rows; within a row, left to
/// right. `pixels` come in row order and keep it within each of the eight groups. A fast turn
/// opens more holes than one picture's tracing fills: traced in plain row order, the top of the
/// picture was traced and its bottom filled for display from far away (blocks); in this order
/// the traced rows spread over all the holes and the fill spans a few rows.
fn rows_coarse_to_fine(pixels: Vec<u32>, rows: Rows) -> Vec<u32> {
    // Row modulo 8 -> its group (three bits reversed).
    const GROUP: [usize; 8] = [0, 4, 2, 6, 1, 5, 3, 7];
    let group = |i: u32| GROUP[(rows.xy(i).1 % 8) as usize];
    let mut start = [0usize; 9];
    for &i in &pixels {
        start[group(i) + 1] += 1;
    }
    for g in 0..8 {
        start[g + 1] += start[g];
    }
    let mut out = vec![0u32; pixels.len()];
    for &i in &pixels {
        let g = group(i);
        out[start[g]] = i;
        start[g] += 1;
    }
    out
}

/// Splits pixel indices of a picture `width` wide into columns and rows with a multiply
/// instead of an integer division (which the compiler cannot take out of a loop over a width
/// known only at run time): for the camera rays, `is_dense` and `tile_of`, per sample.
#[derive(Clone, Copy, Debug)]
struct Rows {
    width: u32,
    inv: f64,
}

impl Rows {
    fn new(width: u32) -> Self {
        let width = width.max(1);
        Self {
            width,
            inv: 1.0 / f64::from(width),
        }
    }

    /// Column and row of pixel `i`. Exact for every `u32` index and width: `(i + 0.5) / width`
    /// lies at least `0.5 / width` from an integer, and the product's rounding error is below
    /// `2^-20 / width`.
    #[inline]
    fn xy(self, i: u32) -> (u32, u32) {
        let y = ((f64::from(i) + 0.5) * self.inv) as u32;
        (i - y * self.width, y)
    }
}

/// The rank of a tile position in a 16 x 16 ordered-dither (Bayer) matrix: consecutive ranks
/// are far apart, so taking a tile's pixels in rank order covers it evenly.
fn bayer_rank(x: u32, y: u32) -> u32 {
    let mut rank = 0;
    for bit in (0..4).rev() {
        let (bx, by) = ((x >> bit) & 1, (y >> bit) & 1);
        rank = rank * 4 + ((bx ^ by) << 1 | by);
    }
    rank
}

impl RenderCache {
    /// An empty cache for a `width x height` picture tone mapped after `exposure`.
    pub fn new(width: u32, height: u32, exposure: f32) -> Self {
        let (w, h) = (width.max(1), height.max(1));
        let (cols, rows) = (w.div_ceil(TILE), h.div_ceil(TILE));
        let n = (cols * rows) as usize;
        let mut order: Vec<(u8, u8)> = (0..TILE * TILE)
            .map(|i| ((i % TILE) as u8, (i / TILE) as u8))
            .collect();
        order.sort_by_key(|&(x, y)| bayer_rank(x as u32, y as u32));
        Self {
            width: w,
            height: h,
            rows: Rows::new(w),
            points: vec![NO_POINT; (w * h) as usize],
            normals: vec![NO_NORMAL; (w * h) as usize],
            albedos: vec![NO_ALBEDO; (w * h) as usize],
            colours: vec![NO_COLOUR; (w * h) as usize],
            holes: (w * h) as usize,
            spare_points: Vec::new(),
            spare_normals: Vec::new(),
            spare_albedos: Vec::new(),
            spare_colours: Vec::new(),
            winner: Vec::new(),
            exposure,
            wavelet: wavelet::Scratch::default(),
            traced: 0,
            tiles: Tiles {
                cols,
                rows,
                change: vec![1.0; n],
                age: vec![0; n],
                cursor: vec![0; n],
                work: vec![0; n],
                order,
            },
        }
    }

    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// A copy of the samples and their schedule, without the buffers the reprojection and the
    /// filter reuse: what a picture of any [`MovingFilter`] is made from, kept to compare the
    /// filters on the same samples.
    pub fn samples_copy(&self) -> RenderCache {
        RenderCache {
            width: self.width,
            height: self.height,
            rows: self.rows,
            points: self.points.clone(),
            normals: self.normals.clone(),
            albedos: self.albedos.clone(),
            colours: self.colours.clone(),
            holes: self.holes,
            spare_points: Vec::new(),
            spare_normals: Vec::new(),
            spare_albedos: Vec::new(),
            spare_colours: Vec::new(),
            winner: Vec::new(),
            exposure: self.exposure,
            tiles: self.tiles.clone(),
            wavelet: wavelet::Scratch::default(),
            traced: self.traced,
        }
    }

    /// Number of pixels holding a sample.
    pub fn filled(&self) -> usize {
        self.colours.len() - self.holes
    }

    /// The colour of pixel `(x, y)`, if it holds a sample.
    pub fn pixel(&self, x: u32, y: u32) -> Option<[u8; 4]> {
        let c = self.colours[(y * self.width + x) as usize];
        (c[3] != 0).then_some(c)
    }

    /// The exposure the colours were tone mapped with.
    pub fn exposure(&self) -> f32 {
        self.exposure
    }

    /// Tiles across and down.
    pub fn tiles(&self) -> (u32, u32) {
        (self.tiles.cols, self.tiles.rows)
    }

    /// Carries every sample to its pixel in the view `to` (the nearest sample wins a pixel; of
    /// equally near ones, the first in memory); samples that fall outside the picture or behind
    /// the camera are dropped. Each carried sample moves onto its new pixel's centre ray
    /// (within its tangent plane). Returns the pixels left without a sample, row by row (runs
    /// of neighbours, so their packets stay coherent), the rows coarse to fine (see
    /// [`rows_coarse_to_fine`]).
    pub fn reproject(&mut self, to: &CameraRays) -> Vec<u32> {
        let (w, h) = (self.width, self.height);
        let n = self.points.len();
        if self.holes == n {
            // Nothing to carry: every pixel, in tracing order.
            return rows_coarse_to_fine((0..n as u32).collect(), self.rows);
        }
        // Each pixel keeps the smallest (depth, source index): positive floats order like
        // their bits, so the minimum of the packed pair picks the nearest sample. One thread
        // writes them (no atomics: the frame's other threads compete for the cores, and a
        // plain minimum is a few times cheaper than an atomic one); the gather below leaves
        // every entry at MAX again for the next call.
        if self.winner.len() != n {
            self.winner = vec![u64::MAX; n];
        }
        scatter(to, w, h, &self.points, &mut self.winner);
        let (old_points, old_normals, old_albedos, old_colours) =
            (&self.points, &self.normals, &self.albedos, &self.colours);
        self.spare_points.resize(n, NO_POINT);
        self.spare_normals.resize(n, NO_NORMAL);
        self.spare_albedos.resize(n, NO_ALBEDO);
        self.spare_colours.resize(n, NO_COLOUR);
        let grid = PixelGrid::new(to, w, h);
        // The new samples, and the pixels left empty, row by row.
        let row = w as usize;
        let holes: Vec<u32> = self
            .spare_points
            .par_chunks_mut(row)
            .zip(self.spare_normals.par_chunks_mut(row))
            .zip(self.spare_albedos.par_chunks_mut(row))
            .zip(self.spare_colours.par_chunks_mut(row))
            .zip(self.winner.par_chunks_mut(row))
            .enumerate()
            .with_min_len(8)
            .flat_map_iter(|(y, ((((points, normals), albedos), colours), keys))| {
                let mut holes = Vec::new();
                let start = grid.centre_ray(y * row);
                for (x, ((((p, nrm), alb), col), key)) in points
                    .iter_mut()
                    .zip(normals)
                    .zip(albedos)
                    .zip(colours)
                    .zip(keys)
                    .enumerate()
                {
                    let found = *key;
                    if found == u64::MAX {
                        *p = NO_POINT;
                        *nrm = NO_NORMAL;
                        *alb = NO_ALBEDO;
                        *col = NO_COLOUR;
                        holes.push((y * row + x) as u32);
                    } else {
                        // Left at MAX again for the next call.
                        *key = u64::MAX;
                        let src = (found & 0xffff_ffff) as usize;
                        let d = start + grid.right * x as f32;
                        *p = grid.recentre_along(d, old_points[src], old_normals[src]);
                        *nrm = old_normals[src];
                        *alb = old_albedos[src];
                        *col = old_colours[src];
                    }
                }
                holes
            })
            .collect();
        let holes = rows_coarse_to_fine(holes, self.rows);
        std::mem::swap(&mut self.normals, &mut self.spare_normals);
        std::mem::swap(&mut self.points, &mut self.spare_points);
        std::mem::swap(&mut self.albedos, &mut self.spare_albedos);
        std::mem::swap(&mut self.colours, &mut self.spare_colours);

        self.holes = holes.len();
        // A tile with holes has changed as much as its share of holes says.
        let mut count = vec![0u32; self.tiles.change.len()];
        for &i in &holes {
            count[self.tile_of(i)] += 1;
        }
        let t = &mut self.tiles;
        for (c, n) in t.change.iter_mut().zip(count) {
            *c = c.max(n as f32 / (TILE * TILE) as f32);
        }
        holes
    }

    /// Fills every pixel with the sample of its centre ray in the view `cam` (framed for this
    /// cache's size) and the colour of the still picture `rgba` of that view (RGBA8, this
    /// cache's size, tone mapped with its exposure, `samples` per pixel): when the camera starts moving, the
    /// moving picture starts from the still one. Only the camera rays are traced, in bands of
    /// rows on the rayon pool; `stop` is asked between bands, and a stopped seed leaves the
    /// cache as it was. Returns false if it stopped.
    pub fn seed(
        &mut self,
        tracer: &Tracer,
        cam: &CameraRays,
        rgba: &[u8],
        samples: u32,
        stop: &(dyn Fn() -> bool + Sync),
    ) -> bool {
        let (w, n) = (self.width as usize, self.points.len());
        if rgba.len() != 4 * n {
            return false;
        }
        self.spare_points.resize(n, NO_POINT);
        self.spare_normals.resize(n, NO_NORMAL);
        self.spare_albedos.resize(n, NO_ALBEDO);
        let stopped = std::sync::atomic::AtomicBool::new(false);
        let band = (w * BAND as usize).max(1);
        self.spare_points
            .par_chunks_mut(band)
            .zip(self.spare_normals.par_chunks_mut(band))
            .zip(self.spare_albedos.par_chunks_mut(band))
            .enumerate()
            .for_each(|(b, ((points, normals), albedos))| {
                if stopped.load(std::sync::atomic::Ordering::Relaxed) {
                    return;
                }
                if stop() {
                    stopped.store(true, std::sync::atomic::Ordering::Relaxed);
                    return;
                }
                // Camera rays by tiles of TILE_WIDTH x BAND pixels, one packet each.
                let height = points.len() / w;
                for x0 in (0..w).step_by(TILE_WIDTH as usize) {
                    let tw = (TILE_WIDTH as usize).min(w - x0);
                    let pixel = |k: usize| k / tw * w + x0 + k % tw;
                    let rays: Vec<Ray> = (0..tw * height)
                        .map(|k| {
                            let y = b * BAND as usize + k / tw;
                            cam.pinhole((x0 + k % tw) as f32 + 0.5, y as f32 + 0.5)
                        })
                        .collect();
                    let mut hits = [None; PACKET];
                    tracer
                        .bvh
                        .intersect_packet(&rays, f32::INFINITY, &mut hits[..rays.len()]);
                    for (k, (ray, hit)) in rays.iter().zip(hits).enumerate() {
                        points[pixel(k)] = hit
                            .map_or(ray.origin + ray.dir * FAR, |h| ray.at(h.t))
                            .into();
                        normals[pixel(k)] = hit.map_or(NO_NORMAL, |h| {
                            pack_normal(face_normal(&tracer.scene.mesh.triangles[h.prim as usize]))
                        });
                        albedos[pixel(k)] = hit.map_or(SKY_ALBEDO, |h| albedo_at(tracer, ray, h));
                    }
                }
            });
        if stopped.into_inner() {
            return false;
        }
        std::mem::swap(&mut self.points, &mut self.spare_points);
        std::mem::swap(&mut self.normals, &mut self.spare_normals);
        std::mem::swap(&mut self.albedos, &mut self.spare_albedos);
        self.set_colours(rgba, samples);
        let t = &mut self.tiles;
        t.change.iter_mut().for_each(|c| *c = 0.0);
        t.age.iter_mut().for_each(|a| *a = 0);
        true
    }

    /// Replaces every pixel's colour with the still picture's `rgba` (RGBA8, this cache's
    /// size) of the view the samples were [`Self::seed`]ed for, as it refines: `samples` per
    /// pixel, which the wavelet filter weighs the colours by.
    pub fn set_colours(&mut self, rgba: &[u8], samples: u32) {
        if rgba.len() != 4 * self.colours.len() {
            return;
        }
        let weight = samples.clamp(1, 255) as u8;
        for ((c, a), px) in self
            .colours
            .iter_mut()
            .zip(&mut self.albedos)
            .zip(rgba.chunks_exact(4))
        {
            *c = [px[0], px[1], px[2], 255];
            a[3] = weight;
        }
        self.holes = 0;
    }

    fn tile_of(&self, pixel: u32) -> usize {
        let (x, y) = self.rows.xy(pixel);
        ((y / TILE) * self.tiles.cols + x / TILE) as usize
    }

    /// About `count` pixels for fresh samples: the tiles of highest priority (how much their
    /// last samples changed, times how long since they were visited) get `PER_VISIT` pixels
    /// each, the next in their ordered-dither order.
    pub fn next_pixels(&mut self, count: usize) -> Vec<u32> {
        let t = &mut self.tiles;
        let n = t.change.len();
        let mut out = Vec::with_capacity(count);
        let mut visited = vec![false; n];
        while out.len() < count {
            let visits = (count - out.len()).div_ceil(PER_VISIT).min(n);
            let priority = |i: usize| (t.change[i] + QUIET) * (1 + t.age[i]) as f32;
            let mut ids: Vec<usize> = (0..n).collect();
            if visits < n {
                ids.select_nth_unstable_by(visits, |&a, &b| priority(b).total_cmp(&priority(a)));
                ids.truncate(visits);
            }
            // Neighbouring tiles next to each other, so packets of their pixels stay coherent.
            ids.sort_unstable();
            for &tile in &ids {
                visited[tile] = true;
                let (tx, ty) = (tile as u32 % t.cols * TILE, tile as u32 / t.cols * TILE);
                let mut given = 0;
                for _ in 0..TILE * TILE {
                    let (dx, dy) = t.order[t.cursor[tile] as usize];
                    t.cursor[tile] = ((t.cursor[tile] as u32 + 1) % (TILE * TILE)) as u16;
                    let (x, y) = (tx + dx as u32, ty + dy as u32);
                    if x < self.width && y < self.height {
                        out.push(y * self.width + x);
                        given += 1;
                        if given == PER_VISIT {
                            break;
                        }
                    }
                }
                // Visited tiles start aging again from zero; a second round in the same call
                // takes the rest in order.
                t.age[tile] = 0;
            }
        }
        for (age, v) in t.age.iter_mut().zip(&visited) {
            if !v {
                *age = age.saturating_add(1);
            }
        }
        out.truncate(count);
        out
    }

    /// Traces one sample through the centre of each of `pixels` with `tracer` and the view
    /// `cam` (framed for this cache's size), on the rayon pool, and keeps it: camera rays in
    /// packets of neighbouring pixels where they lie close together, else one by one (see
    /// `is_dense`). Returns the rays traced.
    pub fn trace(&mut self, tracer: &Tracer, cam: &CameraRays, pixels: &[u32]) -> RayCounts {
        let rows = self.rows;
        let k = self.exposure;
        let index = self.traced;
        self.traced = self.traced.wrapping_add(1);
        // In the order given: holes come row by row (runs, traced as packets), fresh samples
        // tile by tile (spread, traced one by one). Sorting them by 8 x 8 block first, for
        // packets, cost a tenth of the tracing and no longer pays with single rays.
        // One sample: its pixel, point, normal and colour (alpha 0: not finite, not kept).
        type Sample = (u32, [f32; 3], [i8; 4], [u8; 4], [u8; 4]);
        let chunks: Vec<(Vec<Sample>, RayCounts)> = pixels
            .par_chunks(PACKET)
            .map(|chunk| {
                // Denormals flushed, as for the renderer's tiles (`Tracer::radiance_from_hit`).
                crate::bvh::wide::kernel::with_denormals_flushed(|| {
                    let rays: Vec<Ray> = chunk
                        .iter()
                        .map(|&i| {
                            let (x, y) = rows.xy(i);
                            cam.pinhole(x as f32 + 0.5, y as f32 + 0.5)
                        })
                        .collect();
                    let mut hits = [None; PACKET];
                    if is_dense(chunk, rows) {
                        tracer
                            .bvh
                            .intersect_packet(&rays, f32::INFINITY, &mut hits[..rays.len()]);
                    } else {
                        for (hit, ray) in hits.iter_mut().zip(&rays) {
                            *hit = tracer.bvh.intersect(ray, f32::INFINITY);
                        }
                    }
                    // The chunk's rays counted together, not one count per sample.
                    let mut counts = RayCounts {
                        camera: chunk.len() as u64,
                        ..Default::default()
                    };
                    let samples = chunk
                        .iter()
                        .zip(rays)
                        .zip(hits)
                        .map(|((&i, ray), hit)| {
                            let sampler =
                                PixelSampler::new(SamplerKind::Random, 0x5eed, i as u64, index);
                            let l = tracer.radiance_from_hit(
                                &ray,
                                hit,
                                &mut PathSampler::new(sampler),
                                &mut counts,
                            );
                            let point = hit.map_or(ray.origin + ray.dir * FAR, |h| ray.at(h.t));
                            let normal = hit.map_or(NO_NORMAL, |h| {
                                let tri = &tracer.scene.mesh.triangles[h.prim as usize];
                                pack_normal(face_normal(tri))
                            });
                            let albedo = hit.map_or(SKY_ALBEDO, |h| albedo_at(tracer, &ray, h));
                            let colour = if l.is_finite() && point.is_finite() {
                                encode_pixel(l, k)
                            } else {
                                NO_COLOUR
                            };
                            (i, point.into(), normal, albedo, colour)
                        })
                        .collect();
                    (samples, counts)
                })
            })
            .collect();
        let mut total = RayCounts::default();
        let tiles = self.tiles.change.len();
        let mut changed = vec![(0.0f32, 0u32); tiles];
        for (samples, counts) in chunks {
            total = total + counts;
            for (i, point, normal, albedo, colour) in samples {
                let tile = self.tile_of(i);
                self.tiles.work[tile] += 1;
                if colour[3] == 0 {
                    continue;
                }
                let i = i as usize;
                let old = self.colours[i];
                let d = if old[3] == 0 {
                    self.holes -= 1;
                    1.0
                } else {
                    change(old, colour)
                };
                changed[tile].0 += d;
                changed[tile].1 += 1;
                self.points[i] = point;
                self.normals[i] = normal;
                self.albedos[i] = albedo;
                self.colours[i] = colour;
            }
        }
        for (c, (sum, n)) in self.tiles.change.iter_mut().zip(changed) {
            if n > 0 {
                *c = 0.5 * *c + 0.5 * (sum / n as f32);
            }
        }
        total
    }

    /// Samples traced per tile since the last call (row by row of tiles), and zeroes them.
    pub fn take_work(&mut self) -> Vec<u32> {
        let n = self.tiles.work.len();
        std::mem::replace(&mut self.tiles.work, vec![0; n])
    }

    /// The picture, RGBA8: the colours through `filter` (one sample per pixel is noisy: see
    /// [`MovingFilter`]), holes filled from the nearest filled pixels around them (pull-push),
    /// black in an empty cache.
    pub fn to_rgba8(&mut self, filter: MovingFilter) -> Vec<u8> {
        let mut out = match filter {
            MovingFilter::Off => self.colours.as_flattened().to_vec(),
            MovingFilter::Neighbours => self.smoothed(true),
            MovingFilter::Wavelet => wavelet::Guides {
                width: self.width as usize,
                height: self.height as usize,
                points: &self.points,
                normals: &self.normals,
                albedos: &self.albedos,
                colours: &self.colours,
            }
            .filter(&mut self.wavelet),
        };
        if self.holes == 0 {
            return out;
        }
        let (w, h) = (self.width, self.height);
        let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
        let colours = &self.colours;
        let coarse = halve(w, h, 4096, |i| {
            let [r, g, b, a] = colours[i];
            (a != 0).then(|| Vec3::new(r as f32, g as f32, b as f32))
        });
        let coarse = pull_push(&coarse, cw, ch);
        out.par_chunks_mut(4 * 4096).enumerate().for_each(|(c, o)| {
            for (k, px) in o.chunks_exact_mut(4).enumerate() {
                if px[3] == 0 {
                    let i = (c * 4096 + k) as u32;
                    let (x, y) = (i % w, i / w);
                    let v = coarse[((y / 2) * cw + x / 2) as usize];
                    px.copy_from_slice(&[v.x as u8, v.y as u8, v.z as u8, 255]);
                }
            }
        });
        out
    }
}

/// The albedo of the surface `hit` by `ray` (packed, see `pack_albedo`): of a textured
/// material, its shading's at the hit; else its diffuse and specular colours, which the
/// filter needs only to tell materials apart (the full shading costs a fresh sample 7%).
fn albedo_at(tracer: &Tracer, ray: &Ray, hit: crate::bvh::Hit) -> [u8; 4] {
    let m = tracer.scene.material_of(hit.prim);
    if m.diffuse_map.is_some() {
        pack_albedo(tracer.surface(ray, hit.prim, hit.u, hit.v).bsdf.albedo())
    } else {
        pack_albedo(m.diffuse + m.specular)
    }
}

/// True when `pixels` (indices into rows of `width`) fill at least half of their bounding box:
/// a run of a row, a block. Such a packet's rays stay close; scattered pixels (fresh samples
/// spread over a tile) make a packet whose walk visits much of the tree for few hits, and
/// single rays trace them in half the time (45,000 fresh samples of the dragon's orbit on one
/// thread: 21.9 ms in packets, 10.8 ms one by one).
fn is_dense(pixels: &[u32], rows: Rows) -> bool {
    let (mut x0, mut x1, mut y0, mut y1) = (u32::MAX, 0, u32::MAX, 0);
    for &i in pixels {
        let (x, y) = rows.xy(i);
        (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
    }
    let area = (x1.saturating_sub(x0) as u64 + 1) * (y1.saturating_sub(y0) as u64 + 1);
    area <= 2 * pixels.len() as u64
}

/// The picture of half the size (rounded up) whose pixels average the filled pixels (`pixel(i)`
/// some) of each 2 x 2 block of a `w x h` one; a block with none stays empty.
fn halve(
    w: u32,
    h: u32,
    min_len: usize,
    pixel: impl Fn(usize) -> Option<Vec3> + Sync,
) -> Vec<Option<Vec3>> {
    let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
    (0..cw * ch)
        .into_par_iter()
        .with_min_len(min_len)
        .map(|c| {
            let (cx, cy) = (c % cw, c / cw);
            let mut sum = Vec3::ZERO;
            let mut n = 0;
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let (x, y) = (2 * cx + dx, 2 * cy + dy);
                if x < w
                    && y < h
                    && let Some(p) = pixel((y * w + x) as usize)
                {
                    sum += p;
                    n += 1;
                }
            }
            (n > 0).then(|| sum / n as f32)
        })
        .collect()
}

/// Fills the holes of a picture from coarser averages of its filled pixels (Gortler et al.,
/// "The Lumigraph", 1996): each level halves the size, averaging the filled pixels of each 2 x 2
/// block; going back up, a hole takes its block's average.
fn pull_push(pixels: &[Option<Vec3>], w: u32, h: u32) -> Vec<Vec3> {
    if w <= 1 && h <= 1 || pixels.iter().all(Option::is_some) {
        return pixels.iter().map(|p| p.unwrap_or(Vec3::ZERO)).collect();
    }
    let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
    let coarse = halve(w, h, 1024, |i| pixels[i]);
    let coarse = pull_push(&coarse, cw, ch);
    pixels
        .par_iter()
        .enumerate()
        .with_min_len(4096)
        .map(|(i, p)| {
            p.unwrap_or_else(|| {
                let (x, y) = (i as u32 % w, i as u32 / w);
                coarse[((y / 2) * cw + x / 2) as usize]
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_tile_is_visited_and_each_visit_takes_new_pixels() {
        let mut c = RenderCache::new(40, 33, 1.0);
        let mut seen = vec![0u32; 40 * 33];
        // 9 tiles (3 x 3), the edge ones partly outside: enough calls cover every pixel.
        for _ in 0..200 {
            for i in c.next_pixels(64) {
                seen[i as usize] += 1;
            }
        }
        assert!(seen.iter().all(|&n| n > 0), "a pixel was never given");
        // With equal priorities the first visits go to different tiles.
        let mut c = RenderCache::new(64, 64, 1.0);
        let first = c.next_pixels(16 * PER_VISIT);
        let tiles: std::collections::HashSet<usize> = first.iter().map(|&i| c.tile_of(i)).collect();
        assert_eq!(tiles.len(), 16);
    }

    /// The Cornell box's soft shadows and bounces are noisy: tracing the same pixels of the
    /// same view again gives other samples, and the tiles' change shows it. With one sample
    /// index for every call the second call would repeat the first exactly, so a noisy tile
    /// would look settled and lose its priority.
    #[test]
    fn pixels_traced_again_get_new_samples() {
        use crate::bvh::{BuildOptions, Bvh};
        use crate::render::{EnvironmentMap, RenderPlan, RenderSettings, Tracer};
        let scene = crate::scene::Scene::cornell_box();
        let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
        let settings = RenderSettings::default();
        let mut plan = RenderPlan::with_integrator(&scene, scene.integrator, &settings);
        plan.max_light_samples = Some(1);
        let env = EnvironmentMap::load(&scene.environment, plan.environment).unwrap();
        let tracer = Tracer::new(&scene, &bvh, plan, settings.max_depth, &env);
        let (w, h) = (32u32, 32u32);
        let cam = CameraRays::new(&scene.camera, w, h);
        let mut cache = RenderCache::new(w, h, 1.0);
        let all: Vec<u32> = (0..w * h).collect();
        cache.trace(&tracer, &cam, &all);
        let first = cache.colours.clone();
        cache.tiles.change.iter_mut().for_each(|c| *c = 0.0);
        cache.trace(&tracer, &cam, &all);
        let differ = first
            .iter()
            .zip(&cache.colours)
            .filter(|(a, b)| a != b)
            .count();
        assert!(
            differ > all.len() / 10,
            "{differ} of {} pixels changed when traced again",
            all.len()
        );
        assert!(cache.tiles.change.iter().all(|&c| c > 0.0));
    }

    #[test]
    fn changed_tiles_get_pixels_first() {
        let mut c = RenderCache::new(64, 64, 1.0);
        c.tiles.change.iter_mut().for_each(|x| *x = 0.0);
        c.tiles.change[5] = 1.0;
        let first = c.next_pixels(PER_VISIT);
        assert!(first.iter().all(|&i| c.tile_of(i) == 5));
        // Its new samples matched what it held: the others, older, come next.
        c.tiles.change[5] = 0.0;
        let next = c.next_pixels(PER_VISIT);
        assert!(next.iter().all(|&i| c.tile_of(i) != 5));
    }

    #[test]
    fn a_sideways_step_carries_every_sample_of_a_facing_wall_over_by_whole_pixels() {
        // A wall at distance 4 facing the camera; a step of exactly 3 pixels' width at that
        // distance moves every sample 3 pixels left, the rightmost 3 columns become holes.
        let (w, h) = (32u32, 24u32);
        let cam = CameraRays::from_pose(Vec3::ZERO, glam::Quat::IDENTITY, 0.8, w, h, 0.0, 1.0);
        let mut cache = RenderCache::new(w, h, 1.0);
        for y in 0..h {
            for x in 0..w {
                let ray = cam.pinhole(x as f32 + 0.5, y as f32 + 0.5);
                let t = 4.0 / ray.dir.dot(cam.forward);
                cache.points[(y * w + x) as usize] = ray.at(t).into();
                cache.normals[(y * w + x) as usize] = pack_normal(-cam.forward);
                cache.colours[(y * w + x) as usize] = [x as u8, y as u8, 7, 255];
            }
        }
        cache.holes = 0;
        let pixel = 2.0 * 4.0 * cam.tan_half * cam.aspect / w as f32;
        let mut moved = cam;
        moved.eye += cam.right * (3.0 * pixel);
        let holes = cache.reproject(&moved);
        assert_eq!(holes.len(), 3 * h as usize);
        for y in 0..h {
            for x in 0..w - 3 {
                assert_eq!(
                    cache.pixel(x, y),
                    Some([(x + 3) as u8, y as u8, 7, 255]),
                    "pixel {x},{y}"
                );
            }
            for x in w - 3..w {
                assert_eq!(cache.pixel(x, y), None);
            }
        }
    }

    /// A wall seen at an angle, the camera orbiting its centre by a fraction of a pixel per
    /// step: carried samples stay on their pixels' centre rays, so the steps lose few. Carried
    /// as they were, they would scatter within their pixels and collide more at every step.
    #[test]
    fn carried_samples_stay_on_pixel_centres_through_many_small_steps() {
        let (w, h) = (64u32, 48u32);
        let centre = Vec3::new(0.0, 0.0, -4.0);
        let view = |a: f32| {
            let q = glam::Quat::from_rotation_y(a);
            CameraRays::from_pose(
                centre + q * Vec3::new(0.0, 0.0, 4.0),
                q,
                0.8,
                w,
                h,
                0.0,
                1.0,
            )
        };
        let cam = view(0.0);
        // The plane through the centre with a normal turned 50 degrees from the view axis.
        let normal = glam::Quat::from_rotation_y(50f32.to_radians()) * Vec3::Z;
        let mut cache = RenderCache::new(w, h, 1.0);
        for y in 0..h {
            for x in 0..w {
                let ray = cam.pinhole(x as f32 + 0.5, y as f32 + 0.5);
                let t = (centre - ray.origin).dot(normal) / ray.dir.dot(normal);
                let i = (y * w + x) as usize;
                cache.points[i] = ray.at(t).into();
                cache.normals[i] = pack_normal(normal);
                cache.colours[i] = [x as u8, y as u8, 7, 255];
            }
        }
        cache.holes = 0;
        let steps = 30;
        let mut last = cam;
        for k in 1..=steps {
            last = view(k as f32 * 0.004);
            cache.reproject(&last);
        }
        // Pixels whose centre ray misses the wall's samples: the uncovered edge only.
        let holes = cache.holes;
        assert!(
            holes <= (w * h / 50) as usize,
            "{holes} of {} pixels lost their samples",
            w * h
        );
        // And each carried sample lies on its pixel's centre ray.
        for y in 0..h {
            for x in 0..w {
                let p = Vec3::from(cache.points[(y * w + x) as usize]);
                if p.is_finite() {
                    let d = last.pinhole(x as f32 + 0.5, y as f32 + 0.5).dir;
                    let v = p - last.eye;
                    let off = (v - d * v.dot(d)).length() / v.length();
                    assert!(off < 1e-4, "pixel {x},{y}: {off} off its centre ray");
                }
            }
        }
    }

    #[test]
    fn holes_come_rows_coarse_to_fine() {
        let (w, h) = (7u32, 21u32);
        // Every third pixel of a 7 x 21 picture, in row order, as the reprojection finds them.
        let pixels: Vec<u32> = (0..w * h).filter(|i| i % 3 != 1).collect();
        let out = rows_coarse_to_fine(pixels.clone(), Rows::new(w));
        let mut sorted = out.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, pixels, "the same pixels");
        let rows: Vec<u32> = out.iter().map(|i| i / w).collect();
        let mut order: Vec<u32> = rows.clone();
        order.dedup();
        assert_eq!(
            order,
            [
                0, 8, 16, 4, 12, 20, 2, 10, 18, 6, 14, 1, 9, 17, 5, 13, 3, 11, 19, 7, 15
            ],
            "rows coarse to fine"
        );
        // Within a row, left to right.
        assert!(out.windows(2).all(|p| p[0] / w != p[1] / w || p[0] < p[1]));
    }

    #[test]
    fn rows_split_indices_as_integer_division_does() {
        for width in [1, 2, 3, 7, 16, 950, 1280, 4095, 7680, 65535] {
            let rows = Rows::new(width);
            let n = width * 3000;
            let near_rows = (0..3000u32).flat_map(|y| {
                let i = y * width;
                [i, i + width - 1, i.saturating_sub(1), i + 1]
            });
            for i in near_rows.chain([0, n - 1, u32::MAX - width, u32::MAX]) {
                assert_eq!(rows.xy(i), (i % width, i / width), "{i} in rows of {width}");
            }
        }
    }

    #[test]
    fn runs_and_blocks_are_dense_and_spread_samples_are_not() {
        let w = 100;
        let run: Vec<u32> = (0..64).map(|x| 3 * w + 20 + x).collect();
        let block: Vec<u32> = (0..64).map(|k| (8 + k / 8) * w + 16 + k % 8).collect();
        let rows = Rows::new(w);
        assert!(is_dense(&run, rows) && is_dense(&block, rows));
        // What `next_pixels` hands out: a few pixels of each tile, spread over it.
        let mut c = RenderCache::new(w, 64, 1.0);
        let spread = c.next_pixels(64);
        assert!(!is_dense(&spread[..64], rows));
        assert!(is_dense(&[7], rows), "one pixel is its own box");
    }

    /// A cache of `w x h` pixels with these normals and grey levels (0: a hole).
    #[test]
    fn projecting_with_the_widest_vectors_equals_the_baseline_loop() {
        // Points in front of, beside and behind a camera, on the picture's edges, NaN and
        // infinite, at run lengths around the vector widths.
        let (w, h) = (37u32, 23u32);
        let cam = CameraRays::from_pose(
            Vec3::new(0.3, -0.2, 1.0),
            glam::Quat::from_rotation_y(0.3),
            0.8,
            w,
            h,
            0.0,
            1.0,
        );
        let to = Projection::new(&cam, w, h);
        let mut seed = 777u32;
        let mut next = move || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1 << 24) as f32
        };
        let mut points: Vec<[f32; 3]> = (0..300)
            .map(|_| [next() * 8.0 - 4.0, next() * 8.0 - 4.0, next() * 8.0 - 6.0])
            .collect();
        points.extend([
            NO_POINT,
            [f32::INFINITY, 0.0, -1.0],
            [0.0, f32::NEG_INFINITY, -1.0],
            cam.eye.into(),
            (cam.eye + cam.forward).into(),
        ]);
        let mut inside = 0;
        for n in [0, 1, 3, 4, 5, 7, 8, 9, 15, 16, 17, points.len()] {
            let (mut a, mut da) = (vec![0u32; n], vec![0u32; n]);
            let (mut b, mut db) = (vec![0u32; n], vec![0u32; n]);
            project_points(&to, &points[..n], &mut a, &mut da);
            project_widest(&to, &points[..n], &mut b, &mut db);
            assert_eq!((&a, &da), (&b, &db), "{n} points");
            inside = a.iter().filter(|&&i| i != u32::MAX).count();
            assert!(a.iter().all(|&i| i == u32::MAX || i < w * h));
        }
        // Some of them land on the picture, some do not.
        assert!(inside > 20 && inside < points.len() - 20, "{inside}");
    }

    #[test]
    fn pull_push_fills_holes_and_keeps_filled_pixels() {
        let mut p = vec![None; 8 * 8];
        p[0] = Some(Vec3::ONE);
        p[63] = Some(Vec3::splat(3.0));
        let out = pull_push(&p, 8, 8);
        assert_eq!(out[0], Vec3::ONE);
        assert_eq!(out[63], Vec3::splat(3.0));
        assert!(out.iter().all(|v| v.x >= 1.0 && v.x <= 3.0));
    }
}
