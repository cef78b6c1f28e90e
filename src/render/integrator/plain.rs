//! The path integrator's vertices on plain Lambertian surfaces, sixteen paths side by side.
//!
//! A plain surface is untextured, opaque, not emissive, with a Lambertian lobe alone and no
//! mirror or map the plan would look at, in a scene lit by rectangle lights only (`Tracer::plain`
//! says which materials are). Such a vertex needs nothing of the general step
//! ([`Tracer::path_vertex`]) but the hit point and its normals, one sample of each rectangle
//! light and a cosine-weighted bounce, so a round's plain vertices are gathered into chunks of
//! [`W`] and stepped component by component: every stage is one loop over the chunk's lanes,
//! which the compiler turns into vector instructions (four lanes with the x86-64 baseline's
//! SSE2, eight or sixteen where `plain_x86` finds AVX2 or AVX-512). Each lane computes the
//! general step's operations in the same order, without fused multiply-adds: the same light
//! samples, bounce and random numbers as the general step, bit for bit (a test renders with
//! and without this path).

use std::f32::consts::FRAC_1_PI;

use glam::Vec3;

use super::path::{Arrival, Lane, MAX_SURVIVAL, ROULETTE_DEPTH};
use crate::bvh::Hit;
use crate::geometry::{Ray, gamma, offset_ray_origin};
use crate::render::light::{RectLight, ShadowRay, power};
use crate::render::{RayCounts, Tracer};
use crate::sampling::{SamplerKind, concentric_disk, point};

/// Lanes of a chunk.
pub(super) const W: usize = 16;

type F = [f32; W];

/// A chunk of up to [`W`] plain vertices, component by component: what the lanes start from,
/// and what the stages leave for the next.
#[derive(Clone, Copy)]
pub(super) struct Chunk {
    /// Lanes in use (the others repeat lane 0 and are never read back).
    n: usize,
    /// Each lane's path in the batch.
    ids: [u32; W],
    /// The arriving ray's direction, the hit's barycentric `(u, v)`.
    dir: [F; 3],
    u: F,
    v: F,
    /// The hit triangle's vertices and shading normals.
    tri: [[F; 3]; 3],
    ns: [[F; 3]; 3],
    /// The path's throughput, bounce depth, and the surface's reflectance over pi.
    beta: [F; 3],
    depth: [u32; W],
    f: [F; 3],
    /// The path's sampler: its kind (the render's), stream, sample index, the index's bits
    /// reversed and the next dimension pair.
    kind: SamplerKind,
    seed: [u64; W],
    index: [u32; W],
    index_rev: [u32; W],
    next: [u32; W],
    /// The surface point, its error bound, the normals and the offset origin.
    p: [F; 3],
    p_err: [F; 3],
    ng: [F; 3],
    shading: [F; 3],
    origin: [F; 3],
    /// The lane's path goes on from here, by the bounce `wi` of density `pdf` and weight.
    alive: [bool; W],
    wi: [F; 3],
    pdf: F,
    weight: [F; 3],
}

impl Tracer<'_> {
    /// The hit of `lane`'s vertex and the colour of its surface when it lies on a plain
    /// Lambertian surface that this module steps, else `None`.
    #[inline]
    pub(super) fn plain_at(&self, lane: &Lane) -> Option<(Hit, Vec3)> {
        let hit = lane.v.hit?;
        if lane.v.depth > self.max_depth {
            return None;
        }
        let id = self.scene.material_id(hit.prim);
        let diffuse = (*self.plain.get(id as usize)?)?;
        Some((hit, diffuse))
    }

    /// One round's step of the paths `ids` (every one at a vertex on a plain surface, as
    /// [`Tracer::plain_at`] found it), [`W`] at a time: the light samples' shadow rays go to
    /// `shadows` (their paths to `owners`), the paths that bounce to `bouncing` with their rays
    /// in `rays`, the others that have vertices waiting to `next` (the waiting vertex taken).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn plain_round(
        &self,
        lanes: &mut [Lane],
        ids: &[u32],
        (shadows, owners): (&mut Vec<ShadowRay>, &mut Vec<u32>),
        (bouncing, rays, next): (&mut Vec<u32>, &mut Vec<Ray>, &mut Vec<u32>),
        counts: &mut RayCounts,
    ) {
        for group in ids.chunks(W) {
            let mut c = self.gather(lanes, group);
            super::plain_x86::step(self.plain_level, self, &mut c, shadows, owners);
            for j in 0..c.n {
                let k = c.ids[j];
                let lane = &mut lanes[k as usize];
                let beta = Vec3::new(c.beta[0][j], c.beta[1][j], c.beta[2][j]);
                // What the general step adds at a vertex that finds no light of its own.
                lane.l += beta * Vec3::ZERO;
                lane.rng.set_next(c.next[j]);
                if c.alive[j] {
                    counts.bounce += 1;
                    let at = |a: &[F; 3]| Vec3::new(a[0][j], a[1][j], a[2][j]);
                    let v = &mut lane.v;
                    v.ray = Ray::new(at(&c.origin), at(&c.wi));
                    v.hit = None;
                    v.arrival = Arrival::Bounce {
                        pdf: c.pdf[j],
                        from: v.depth,
                        travelled: 0.0,
                    };
                    v.depth += 1;
                    v.beta = beta * at(&c.weight);
                    bouncing.push(k);
                    rays.push(v.ray);
                } else if let Some(p) = lane.pending.pop() {
                    lane.v = p;
                    next.push(k);
                }
            }
        }
    }

    /// The chunk of the paths `group` (at most [`W`]), read from their lanes.
    fn gather(&self, lanes: &[Lane], group: &[u32]) -> Chunk {
        let scene = self.scene;
        let first = &lanes[group[0] as usize];
        let kind = first.rng.parts().0;
        let mut c = Chunk {
            n: group.len(),
            ids: [group[0]; W],
            dir: [[0.0; W]; 3],
            u: [0.0; W],
            v: [0.0; W],
            tri: [[[0.0; W]; 3]; 3],
            ns: [[[0.0; W]; 3]; 3],
            beta: [[0.0; W]; 3],
            depth: [0; W],
            f: [[0.0; W]; 3],
            kind,
            seed: [0; W],
            index: [0; W],
            index_rev: [0; W],
            next: [0; W],
            p: [[0.0; W]; 3],
            p_err: [[0.0; W]; 3],
            ng: [[0.0; W]; 3],
            shading: [[0.0; W]; 3],
            origin: [[0.0; W]; 3],
            alive: [false; W],
            wi: [[0.0; W]; 3],
            pdf: [0.0; W],
            weight: [[0.0; W]; 3],
        };
        for j in 0..W {
            // Lanes past the group repeat its first path; nothing of theirs is kept.
            let k = group.get(j).copied().unwrap_or(group[0]);
            let lane = &lanes[k as usize];
            let (hit, diffuse) = self
                .plain_at(lane)
                .expect("a plain round takes plain vertices only");
            c.ids[j] = k;
            c.u[j] = hit.u;
            c.v[j] = hit.v;
            let tri = &scene.triangle(hit.prim);
            let ns = &scene.normals(hit.prim);
            for a in 0..3 {
                c.dir[a][j] = lane.v.ray.dir[a];
                c.beta[a][j] = lane.v.beta[a];
                c.f[a][j] = diffuse[a] * FRAC_1_PI;
                for (corner, (t, n)) in tri.iter().zip(ns).enumerate() {
                    c.tri[corner][a][j] = t[a];
                    c.ns[corner][a][j] = n[a];
                }
            }
            c.depth[j] = lane.v.depth;
            let (_, seed, index, index_rev, next) = lane.rng.parts();
            (c.seed[j], c.index[j], c.index_rev[j], c.next[j]) = (seed, index, index_rev, next);
        }
        c
    }
}

/// The chunk's step (see the module docs): compiled here for the baseline and again in
/// `plain_x86` for wider vector units, so it is inlined into both.
#[inline(always)]
pub(super) fn step(t: &Tracer, c: &mut Chunk, shadows: &mut Vec<ShadowRay>, owners: &mut Vec<u32>) {
    surface(c);
    lights(t, c, shadows, owners);
    bounce(t, c);
}

/// `x / |x|` where `|x|` is finite and positive (glam's `try_normalize`): `None` otherwise.
#[inline(always)]
fn try_normalize(x: f32, y: f32, z: f32) -> Option<(f32, f32, f32)> {
    let rcp = 1.0 / (x * x + y * y + z * z).sqrt();
    (rcp.is_finite() && rcp > 0.0).then_some((x * rcp, y * rcp, z * rcp))
}

/// `o` one float further along the sign of `n` ([`offset_ray_origin`]'s step) where `o` is
/// finite and not zero, as one integer step of its bits; `None` elsewhere.
#[inline(always)]
fn away(o: f32, n: f32) -> Option<f32> {
    let step = (n > 0.0) as i32 - (n < 0.0) as i32;
    let sign = 1 - 2 * (o.to_bits() >> 31) as i32;
    let out = f32::from_bits((o.to_bits() as i32).wrapping_add(step * sign) as u32);
    (o.is_finite() && o != 0.0).then_some(out)
}

/// The hit points, their error bounds, the geometric and shading normals facing the ray, and
/// the offset origins, as `Tracer::surface` finds them where no map bends the normal.
#[inline(always)]
fn surface(c: &mut Chunk) {
    let g7 = gamma(7);
    let mut fix = [false; W];
    for j in 0..W {
        let (u, w) = (c.u[j], c.v[j]);
        let b0 = 1.0 - u - w;
        let at = |m: &[[F; 3]; 3], k: usize, a: usize| m[k][a][j];
        let mut p = [0.0; 3];
        let mut err = [0.0; 3];
        for a in 0..3 {
            let (x, y, z) = (
                at(&c.tri, 0, a) * b0,
                at(&c.tri, 1, a) * u,
                at(&c.tri, 2, a) * w,
            );
            p[a] = x + y + z;
            err[a] = (x.abs() + y.abs() + z.abs()) * g7;
        }
        let e1: [f32; 3] = std::array::from_fn(|a| at(&c.tri, 1, a) - at(&c.tri, 0, a));
        let e2: [f32; 3] = std::array::from_fn(|a| at(&c.tri, 2, a) - at(&c.tri, 0, a));
        let cross = (
            e1[1] * e2[2] - e2[1] * e1[2],
            e1[2] * e2[0] - e2[2] * e1[0],
            e1[0] * e2[1] - e2[0] * e1[1],
        );
        let outward = try_normalize(cross.0, cross.1, cross.2).unwrap_or((0.0, 0.0, 1.0));
        let outward = [outward.0, outward.1, outward.2];
        let d = [c.dir[0][j], c.dir[1][j], c.dir[2][j]];
        let entering = outward[0] * d[0] + outward[1] * d[1] + outward[2] * d[2] < 0.0;
        let ng: [f32; 3] = std::array::from_fn(|a| if entering { outward[a] } else { -outward[a] });
        let interp: [f32; 3] = std::array::from_fn(|a| {
            at(&c.ns, 0, a) * (1.0 - u - w) + at(&c.ns, 1, a) * u + at(&c.ns, 2, a) * w
        });
        let n = try_normalize(interp[0], interp[1], interp[2]).unwrap_or((ng[0], ng[1], ng[2]));
        let n = [n.0, n.1, n.2];
        let side = if n[0] * ng[0] + n[1] * ng[1] + n[2] * ng[2] < 0.0 {
            -1.0
        } else {
            1.0
        };
        // The offset origin (`offset_ray_origin`); lanes it would not step as an integer
        // (a zero or non-finite coordinate) take the function itself below.
        let off = 2.0 * (ng[0].abs() * err[0] + ng[1].abs() * err[1] + ng[2].abs() * err[2]);
        let mut out = [0.0; 3];
        let mut exact = true;
        for a in 0..3 {
            let o = p[a] + ng[a] * off;
            match away(o, ng[a]) {
                Some(x) => out[a] = x,
                None => exact = false,
            }
        }
        let finite = out.iter().all(|x| x.is_finite());
        fix[j] = !exact;
        for a in 0..3 {
            c.p[a][j] = p[a];
            c.p_err[a][j] = err[a];
            c.ng[a][j] = ng[a];
            c.shading[a][j] = n[a] * side;
            c.origin[a][j] = if finite { out[a] } else { p[a] };
        }
    }
    for j in (0..c.n).filter(|&j| fix[j]) {
        let v = |m: &[F; 3]| Vec3::new(m[0][j], m[1][j], m[2][j]);
        let o = offset_ray_origin(v(&c.p), v(&c.p_err), v(&c.ng));
        for a in 0..3 {
            c.origin[a][j] = o[a];
        }
    }
}

/// The next 2D sample of each lane where `take` is set (moving its dimension on): the
/// sampler's own points, computed side by side.
#[inline(always)]
fn draw(c: &mut Chunk, take: &[bool; W]) -> (F, F) {
    let (mut x, mut y) = ([0.0; W], [0.0; W]);
    for j in 0..W {
        (x[j], y[j]) = point(c.kind, c.seed[j], c.index[j], c.index_rev[j], c.next[j]);
        c.next[j] += take[j] as u32;
    }
    (x, y)
}

/// Next-event estimation: each rectangle light's samples, as `Tracer::rect_light` takes them
/// and weighted as `Tracer::lights_at` weighs them, given to `shadows` lane by lane.
#[inline(always)]
fn lights(t: &Tracer, c: &mut Chunk, shadows: &mut Vec<ShadowRay>, owners: &mut Vec<u32>) {
    let live: [bool; W] = std::array::from_fn(|j| j < c.n);
    for (i, light) in t.scene.lights.iter().enumerate() {
        let Some(RectLight {
            corner,
            edge_u,
            edge_v,
            color,
            intensity,
            samples,
        }) = RectLight::of(light, |n| n)
        else {
            continue;
        };
        let weighted = t.lights.is_visible(i);
        let normal = edge_u.cross(edge_v);
        let area = normal.length();
        let ln = normal / area;
        // Samples at the camera's hit, one deeper.
        let first = t.rect_samples(samples, 0);
        let count: [u32; W] = std::array::from_fn(|j| if c.depth[j] > 0 { 1 } else { first });
        let most = (0..c.n).map(|j| count[j]).max().unwrap_or(0);
        for s in 0..most {
            let take: [bool; W] = std::array::from_fn(|j| live[j] && s < count[j]);
            let (ux, uy) = draw(c, &take);
            let mut light = [[0.0; W]; 3];
            let mut to = [[0.0; W]; 3];
            let mut keep = [false; W];
            for j in 0..W {
                let p = [c.p[0][j], c.p[1][j], c.p[2][j]];
                let n = [c.shading[0][j], c.shading[1][j], c.shading[2][j]];
                let ng = [c.ng[0][j], c.ng[1][j], c.ng[2][j]];
                let q: [f32; 3] =
                    std::array::from_fn(|a| corner[a] + ux[j] * edge_u[a] + uy[j] * edge_v[a]);
                let tq: [f32; 3] = std::array::from_fn(|a| q[a] - p[a]);
                let d2 = tq[0] * tq[0] + tq[1] * tq[1] + tq[2] * tq[2];
                let len = d2.sqrt();
                let wi: [f32; 3] = std::array::from_fn(|a| tq[a] / len);
                let cos_l = -(ln.x * wi[0] + ln.y * wi[1] + ln.z * wi[2]);
                let cos = n[0] * wi[0] + n[1] * wi[1] + n[2] * wi[2];
                let facing = ng[0] * tq[0] + ng[1] * tq[1] + ng[2] * tq[2];
                let seen = !(cos <= 0.0 || cos_l <= 0.0 || facing <= 0.0);
                let nf = count[j] as f32;
                let w = if weighted {
                    let p_light = d2 / (cos_l * area);
                    let pdf = if cos > 0.0 { cos * FRAC_1_PI } else { 0.0 };
                    power(nf, p_light, pdf)
                } else {
                    1.0
                };
                keep[j] = take[j] && seen && w != 0.0;
                for a in 0..3 {
                    let scale = color[a] * intensity / nf;
                    let l = c.f[a][j] * cos * cos_l * area / d2 * w * scale;
                    light[a][j] = l * c.beta[a][j];
                    to[a][j] = q[a] - c.origin[a][j];
                }
            }
            for j in (0..c.n).filter(|&j| keep[j]) {
                let v = |m: &[F; 3]| Vec3::new(m[0][j], m[1][j], m[2][j]);
                shadows.push(ShadowRay {
                    origin: v(&c.origin),
                    to: v(&to),
                    t_max: 1.0 - 1e-4,
                    light: v(&light),
                });
                owners.push(c.ids[j]);
            }
        }
    }
}

/// The cosine-weighted bounce, as `Tracer::bounce` draws it from a Lambertian lobe, and Russian
/// roulette: which lanes go on, in which direction, with which density and weight.
#[inline(always)]
fn bounce(t: &Tracer, c: &mut Chunk) {
    let nothing_to_find = t.lights.owner.is_empty() && !t.plan.environment;
    let go: [bool; W] =
        std::array::from_fn(|j| j < c.n && !(c.depth[j] == t.max_depth && nothing_to_find));
    let (ux, uy) = draw(c, &go);
    // The concentric disk's points, lane by lane (no call: its sine and cosine are
    // polynomials, so the loop vectorises).
    let mut dx = [0.0; W];
    let mut dy = [0.0; W];
    for j in 0..W {
        let d = concentric_disk(glam::Vec2::new(ux[j], uy[j]));
        (dx[j], dy[j]) = (d.x, d.y);
    }
    let mut survive = [0.0; W];
    let mut roulette = [false; W];
    for j in 0..W {
        let (dx, dy) = (dx[j], dy[j]);
        let z = (1.0 - (dx * dx + dy * dy)).max(0.0).sqrt();
        let n = [c.shading[0][j], c.shading[1][j], c.shading[2][j]];
        // glam's `any_orthonormal_pair` (Duff et al. 2017).
        let sign = n[2].signum();
        let a = -1.0 / (sign + n[2]);
        let b = n[0] * n[1] * a;
        let tx = [1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0]];
        let bx = [b, sign + n[1] * n[1] * a, -n[1]];
        let wi: [f32; 3] = std::array::from_fn(|k| tx[k] * dx + bx[k] * dy + n[k] * z);
        let cos = n[0] * wi[0] + n[1] * wi[1] + n[2] * wi[2];
        let pdf = cos.max(0.0) * FRAC_1_PI;
        let above = wi[0] * c.ng[0][j] + wi[1] * c.ng[1][j] + wi[2] * c.ng[2][j];
        let ok = go[j] && !(cos <= 0.0 || above <= 0.0 || pdf <= 0.0);
        let weight: [f32; 3] = std::array::from_fn(|k| c.f[k][j] * cos / pdf);
        // glam's `max_element` of the throughput times the weight.
        let bw: [f32; 3] = std::array::from_fn(|k| c.beta[k][j] * weight[k]);
        let max = |a: f32, b: f32| if a > b { a } else { b };
        survive[j] = max(bw[0], max(bw[1], bw[2])).min(MAX_SURVIVAL);
        roulette[j] = ok && c.depth[j] >= ROULETTE_DEPTH;
        c.alive[j] = ok;
        c.pdf[j] = pdf;
        for k in 0..3 {
            c.wi[k][j] = wi[k];
            c.weight[k][j] = weight[k];
        }
    }
    let (rx, _) = draw(c, &roulette);
    for j in 0..W {
        if roulette[j] {
            // Ends where the number reaches the survival odds (never where they are NaN, as
            // in the general step's `>=` test).
            let ends = rx[j] >= survive[j];
            c.alive[j] &= !ends;
            for k in 0..3 {
                c.weight[k][j] /= survive[j];
            }
        }
    }
}
