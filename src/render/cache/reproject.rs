//! Carrying the samples to a new view: each kept sample projected to the pixel it falls on
//! (the nearest wins a pixel), then moved within its surface's tangent plane onto that pixel's
//! centre ray.

#[cfg(target_arch = "x86_64")]
mod project_x86;

use glam::Vec3;
use rayon::prelude::*;

use super::schedule::{Rows, TILE, rows_coarse_to_fine};
use super::{NO_ALBEDO, NO_COLOUR, NO_NORMAL, NO_POINT, RenderCache, unpack_normal};
use crate::camera::CameraRays;

/// Largest relative change of a sample's depth when it moves to its new pixel's centre ray;
/// beyond it (a surface seen nearly edge-on) the sample stays where it was.
const MAX_RECENTRE: f32 = 0.05;

/// Pixels per unit of the camera's right and up axes on the plane at unit depth, for a
/// `w x h` picture of `to`.
pub(super) fn pixels_per_unit(to: &CameraRays, w: u32, h: u32) -> (f32, f32) {
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

impl RenderCache {
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::cache::pack_normal;

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
}
