//! The `path` integrator: unidirectional path tracing.
//!
//! At every surface a path meets, next-event estimation samples the lights (point lights,
//! rectangle lights and the scene's emissive triangles), and a bounce carries the path on,
//! sampled from the surface's lobes (cosine-weighted for the diffuse one, by half vector or
//! visible normal for the glossy one: [`crate::render::bsdf`]). Light a bounce finds by hitting an
//! emitter that next-event estimation also samples is weighted against it by multiple
//! importance sampling (the power heuristic, Veach 1997, against the density of the mixture
//! of lobes), so each path counts every light once. Mirrors and transparent surfaces are followed
//! as in the `direct` integrator. Russian roulette ends paths whose throughput has become
//! small, and a depth limit ends the rest: with `max_depth = D`, the vertices up to `D`
//! bounces after the camera's hit take light samples and bounce, and the bounce from the last
//! of them only collects emission (Mitsuba's `path` with `max_depth = D + 2`).
//!
//! The integrator is one loop over a path's vertices ([`Tracer::path`]) around one step per
//! vertex ([`Tracer::path_vertex`]), which multiplies the light found there by the path's
//! throughput: the unit a renderer that advances many paths together would run over batches.

use glam::Vec3;

use super::Onward;
use crate::bvh::Hit;
use crate::geometry::Ray;
use crate::render::RayCounts;
use crate::render::Tracer;
use crate::render::bsdf::Sample;
use crate::render::light::{Owner, RectLight, power};
use crate::render::surface::Surface;
use crate::sampling::PathSampler;
use crate::scene::{Light, face_normal};

/// Bounce depth from which Russian roulette may end a path.
const ROULETTE_DEPTH: u32 = 3;

/// Highest survival probability of Russian roulette (some paths always end, so no path runs
/// on forever between mirrors).
const MAX_SURVIVAL: f32 = 0.95;

/// How the ray that reached a surface was chosen: says how emission found there counts.
#[derive(Clone, Copy, Debug)]
pub(in crate::render) enum Arrival {
    /// From the camera or a mirror: emission counts in full.
    Specular,
    /// A bounce from a surface at bounce depth `from`, with solid-angle density `pdf`,
    /// `travelled` units ago (straight through transparent surfaces on the way): emission from a
    /// light that next-event estimation samples is weighted against it.
    Bounce { pdf: f32, from: u32, travelled: f32 },
}

/// A vertex a path has still to meet: the ray that reaches it, the ray's closest hit, and
/// what the path carries there.
#[derive(Clone, Copy, Debug)]
pub(in crate::render) struct Vertex {
    /// The ray arriving at the vertex.
    pub(in crate::render) ray: Ray,
    /// Its closest hit (none: the ray leaves the scene).
    pub(in crate::render) hit: Option<Hit>,
    /// Bounces before this vertex.
    pub(in crate::render) depth: u32,
    /// How the ray was chosen.
    pub(in crate::render) arrival: Arrival,
    /// The path's throughput: what light leaving the vertex towards the previous one is
    /// multiplied by on its way to the camera.
    pub(in crate::render) beta: Vec3,
}

/// A bounce sampled from a surface's lobes ([`Tracer::bounce`]).
pub(in crate::render) struct Bounce {
    /// Unit direction.
    wi: Vec3,
    /// Its density over solid angle.
    pdf: f32,
    /// The surface's reflectance along it times the cosine over the density (and over the
    /// chance of surviving Russian roulette).
    weight: Vec3,
}

impl Tracer<'_> {
    /// Radiance along the camera ray `ray`, whose closest hit is `hit`, by path tracing.
    ///
    /// One loop meets the path's vertices one at a time ([`Tracer::path_vertex`]). A vertex
    /// carries the path on by a bounce, and also by its mirror and through it where it has
    /// them: the bounce is met next, and the mirror's and the transmitted vertices wait on a
    /// stack, each followed to its end before the next (so they draw their random numbers in
    /// the same order on every run).
    pub(in crate::render) fn path(
        &self,
        ray: &Ray,
        hit: Option<Hit>,
        rng: &mut PathSampler,
        counts: &mut RayCounts,
    ) -> Vec3 {
        // Empty until a mirror or a transparent surface is met: no allocation on most paths.
        let mut pending = Vec::new();
        let mut v = Vertex {
            ray: *ray,
            hit,
            depth: 0,
            arrival: Arrival::Specular,
            beta: Vec3::ONE,
        };
        let mut l = Vec3::ZERO;
        loop {
            let (found, goes_on) = self.path_vertex(&mut v, &mut pending, rng, counts);
            l += found;
            if !goes_on {
                match pending.pop() {
                    Some(p) => v = p,
                    None => return l,
                }
            }
        }
    }

    /// One step of the path integrator: the light the path gathers at `v` (emission found,
    /// next-event estimation) times the path's throughput, and whether its bounce carries it
    /// on (then `v` is the vertex the bounce reaches; updated in place, as moving it costs
    /// time). The vertices its mirror and transmission carry it on to are pushed onto
    /// `pending` (the one to be met first last).
    pub(in crate::render) fn path_vertex(
        &self,
        v: &mut Vertex,
        pending: &mut Vec<Vertex>,
        rng: &mut PathSampler,
        counts: &mut RayCounts,
    ) -> (Vec3, bool) {
        let ray = &v.ray;
        let Some(hit) = v.hit else {
            return (v.beta * self.background(ray.dir), false);
        };
        let (s, alpha, wo) = self.vertex(ray, &hit);
        let beta = v.beta * self.absorption(&s, ray, &hit);
        let mut l = Vec3::ZERO;
        if s.material.is_emissive() {
            l += alpha * self.emission_found(ray, &hit, s.emission, v.arrival);
        }
        // The bounce from the last vertex only collects emission.
        if v.depth > self.max_depth {
            return (beta * l, false);
        }
        l += alpha * self.lights_at(&s, wo, v.depth, rng, counts);
        let (found, bounce) = self.bounce(&s, wo, v.depth, beta * alpha, rng, counts);
        l += alpha * found;
        // Pushed in reverse, so that the mirror's path is met before the transmitted one.
        let onward = self.onward(ray, &s, alpha, wo, counts);
        for c in onward.into_iter().rev().flatten() {
            // Shadow rays pass straight through transparent surfaces: light a bounce finds
            // beyond one is weighted as if the bounce had found it directly.
            let arrival = match (c.way, v.arrival) {
                (Onward::Mirror, _) => Arrival::Specular,
                (
                    Onward::Through,
                    Arrival::Bounce {
                        pdf,
                        from,
                        travelled,
                    },
                ) => Arrival::Bounce {
                    pdf,
                    from,
                    travelled: travelled + hit.t * ray.dir.length(),
                },
                (Onward::Through, a) => a,
            };
            pending.push(Vertex {
                ray: c.ray,
                hit: self.bvh.intersect(&c.ray, f32::INFINITY),
                depth: v.depth + 1,
                arrival,
                beta: beta * c.tint,
            });
        }
        let Some(b) = bounce else {
            return (beta * l, false);
        };
        counts.bounce += 1;
        v.ray = Ray::new(s.origin, b.wi);
        // Drawn at random: neighbouring paths' bounces take other paths through the tree.
        v.hit = self.bvh.intersect_incoherent(&v.ray, f32::INFINITY);
        v.arrival = Arrival::Bounce {
            pdf: b.pdf,
            from: v.depth,
            travelled: 0.0,
        };
        v.depth += 1;
        v.beta = beta * alpha * b.weight;
        (beta * l, true)
    }

    /// Emission `le` of the triangle `hit` found, weighted for how the ray was chosen.
    pub(in crate::render) fn emission_found(
        &self,
        ray: &Ray,
        hit: &Hit,
        le: Vec3,
        arrival: Arrival,
    ) -> Vec3 {
        let Arrival::Bounce {
            pdf,
            from,
            travelled,
        } = arrival
        else {
            return le;
        };
        let dir = ray.dir.normalize();
        let d = travelled + hit.t * ray.dir.length();
        match self.lights.owner.get(&hit.prim) {
            Some(Owner::Set) => {
                let tri = &self.scene.mesh.triangles[hit.prim as usize];
                let cos = face_normal(tri).dot(dir).abs();
                if cos <= 0.0 {
                    return Vec3::ZERO;
                }
                let p_light = d * d / (cos * self.lights.area);
                le * power(1.0, pdf, p_light)
            }
            Some(&Owner::Rect(i)) if self.lights.visible[i as usize] => {
                let Light::Rect {
                    edge_u,
                    edge_v,
                    samples,
                    ..
                } = self.scene.lights[i as usize]
                else {
                    return Vec3::ZERO;
                };
                let normal = edge_u.cross(edge_v);
                let area = normal.length();
                // The rectangle emits on its front side only.
                let cos = -(normal / area).dot(dir);
                if cos <= 0.0 {
                    return Vec3::ZERO;
                }
                let p_light = d * d / (cos * area);
                let n = self.rect_samples(samples, from) as f32;
                le * power(1.0, pdf, n * p_light)
            }
            // Part of a rectangle light its triangles do not cover: the light's samples count
            // it all.
            _ => Vec3::ZERO,
        }
    }

    /// Light samples a rectangle light with `samples` takes at bounce depth `depth`: its own
    /// count (capped by the plan) at the camera's hit, one deeper.
    pub(in crate::render) fn rect_samples(&self, samples: u32, depth: u32) -> u32 {
        if depth > 0 {
            return 1;
        }
        self.capped_samples(samples).max(1)
    }

    /// Next-event estimation at `s`: every point and rectangle light, and one sample of the
    /// emissive triangles, each weighted against the bounce that could find it.
    pub(in crate::render) fn lights_at(
        &self,
        s: &Surface,
        wo: Vec3,
        depth: u32,
        rng: &mut PathSampler,
        counts: &mut RayCounts,
    ) -> Vec3 {
        let m = s.material;
        if !m.reflects() {
            return Vec3::ZERO;
        }
        let bsdf = s.bsdf();
        // Only the rectangle lights no triangles cover need it.
        let glossy = self.lights.hidden_rects && bsdf.gloss_probability(wo) > 0.0;
        let mut sum = Vec3::ZERO;
        for (i, light) in self.scene.lights.iter().enumerate() {
            let Some(rect) = RectLight::of(light, |n| self.rect_samples(n, depth)) else {
                sum += self.point_light(s, wo, light, counts);
                continue;
            };
            let n = rect.samples as f32;
            // Bounces find the light when its triangles cover it; on a glossy surface they
            // look for it by its rectangle when they do not.
            let weighted = self.lights.visible[i] || glossy;
            sum += self.rect_light(s, wo, &rect, rng, counts, |sample, _, area| {
                if weighted {
                    let p_light = sample.d2 / (sample.cos_l * area);
                    power(n, p_light, bsdf.pdf(sample.wi, wo))
                } else {
                    1.0
                }
            });
        }
        if let Some(e) = self.emissive_sample(s, wo, rng, counts) {
            sum += e.value * power(1.0, e.p_light, bsdf.pdf(e.wi, wo));
        }
        sum
    }

    /// The bounce from `s`, sampled from its lobes: the light of the rectangle lights it finds
    /// by their rectangles (weighted by the surface's reflectance over the sampling density),
    /// and the bounce itself, unless the path ends here. `beta` is the
    /// path's throughput at `s` (for Russian roulette).
    pub(in crate::render) fn bounce(
        &self,
        s: &Surface,
        wo: Vec3,
        depth: u32,
        beta: Vec3,
        rng: &mut PathSampler,
        counts: &mut RayCounts,
    ) -> (Vec3, Option<Bounce>) {
        let m = s.material;
        if !m.reflects() {
            return (Vec3::ZERO, None);
        }
        let bsdf = s.bsdf();
        // On a glossy surface the bounce also looks for the rectangle lights no triangles
        // cover (which it cannot hit), as `lights_at` weights their samples.
        let glossy = self.lights.hidden_rects && bsdf.gloss_probability(wo) > 0.0;
        let nothing_to_find = self.lights.owner.is_empty() && !self.plan.environment;
        if depth == self.max_depth && nothing_to_find && !glossy {
            // The last bounce only collects emission, and there is none to find.
            return (Vec3::ZERO, None);
        }
        let u = rng.next_2d();
        let Some(Sample { wi, pdf }) = bsdf.sample(wo, u) else {
            return (Vec3::ZERO, None);
        };
        let cos = s.n().dot(wi);
        if cos <= 0.0 || wi.dot(s.ng) <= 0.0 || pdf <= 0.0 {
            return (Vec3::ZERO, None);
        }
        let mut weight = bsdf.eval(wi, wo) * cos / pdf;
        let mut found = Vec3::ZERO;
        if glossy {
            found = weight
                * self.rects_along(s, wi, pdf, 1, counts, |i, samples| {
                    (!self.lights.visible[i]).then(|| self.rect_samples(samples, depth))
                });
        }
        if depth == self.max_depth && nothing_to_find {
            return (found, None);
        }
        if depth >= ROULETTE_DEPTH {
            let survive = (beta * weight).max_element().min(MAX_SURVIVAL);
            if rng.next_2d().x >= survive {
                return (found, None);
            }
            weight /= survive;
        }
        (found, Some(Bounce { wi, pdf, weight }))
    }
}
