//! The `path` integrator: unidirectional path tracing.
//!
//! At every surface a path meets, next-event estimation samples the lights (point lights,
//! rectangle lights and the scene's emissive triangles), and a bounce carries the path on,
//! sampled from the surface's lobes (cosine-weighted for the diffuse one, by half vector or
//! visible normal for the glossy one: [`super::bsdf`]). Light a bounce finds by hitting an
//! emitter that next-event estimation also samples is weighted against it by multiple
//! importance sampling (the power heuristic, Veach 1997, against the density of the mixture
//! of lobes), so each path counts every light once. Mirrors and transparent surfaces are followed
//! as in the `direct` integrator. Russian roulette ends paths whose throughput has become
//! small, and a depth limit ends the rest: with `max_depth = D`, the vertices up to `D`
//! bounces after the camera's hit take light samples and bounce, and the bounce from the last
//! of them only collects emission (Mitsuba's `path` with `max_depth = D + 2`).
//!
//! A rectangle light and emissive triangles lying inside it (the Cornell box's ceiling light:
//! the quad the camera sees, and the light that lights the room) are one light: its samples
//! and a bounce that hits its triangles are weighted against each other; when the triangles do
//! not cover the whole rectangle, bounces that hit them add nothing (the samples count it all).
//! A rectangle light no triangles cover at all, which bounces cannot hit, is looked for along
//! a glossy surface's bounce by its rectangle (with a shadow ray) and weighted the same way.

use std::collections::HashMap;

use glam::{Vec2, Vec3};

use super::RayCounts;
use super::bsdf::Sample;
use super::shade::{RectLight, Surface, Tracer, brdf, reflect, transmit};
use crate::bvh::Hit;
use crate::geometry::{Ray, offset_ray_origin};
use crate::sampling::PathSampler;
use crate::scene::{Light, Scene, face_normal};

/// Bounce depth from which Russian roulette may end a path.
const ROULETTE_DEPTH: u32 = 3;

/// Highest survival probability of Russian roulette (some paths always end, so no path runs
/// on forever between mirrors).
const MAX_SURVIVAL: f32 = 0.95;

/// What stands for an emissive triangle when a bounce hits it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Owner {
    /// The set of emissive triangles sampled together by area.
    Set,
    /// The rectangle light with this index in [`Scene::lights`].
    Rect(u32),
}

/// The lights both integrators sample, besides the scene's point and rectangle lights: the
/// emissive triangles no rectangle light stands for, chosen by area.
#[derive(Clone, Debug, Default)]
pub struct LightSet {
    /// Emissive triangles sampled by area.
    tris: Vec<u32>,
    /// Running sum of their areas (the last is `area`).
    cdf: Vec<f32>,
    /// Their total area.
    area: f32,
    /// Every emissive triangle with area: what a bounce that hits it is weighted against.
    owner: HashMap<u32, Owner>,
    /// Per scene light: true when emissive triangles cover it, so bounces find it.
    visible: Vec<bool>,
    /// True when some rectangle light has no triangles covering it.
    hidden_rects: bool,
}

/// Relative tolerance for a triangle lying in a rectangle light's plane and inside it.
const COINCIDE: f32 = 1e-4;

impl LightSet {
    /// Finds the scene's emissive triangles and the rectangle lights they lie in.
    pub fn new(scene: &Scene) -> Self {
        let mut set = LightSet {
            visible: vec![false; scene.lights.len()],
            ..Default::default()
        };
        let emissive: Vec<bool> = scene.materials.iter().map(|m| m.is_emissive()).collect();
        if !emissive.iter().any(|&e| e) {
            set.hidden_rects = scene.lights.iter().any(|l| matches!(l, Light::Rect { .. }));
            return set;
        }
        let mut covered = vec![0.0f32; scene.lights.len()];
        for (prim, (tri, &mat)) in scene
            .mesh
            .triangles
            .iter()
            .zip(&scene.mesh.material_ids)
            .enumerate()
        {
            if !emissive[mat as usize] {
                continue;
            }
            let area = 0.5 * (tri[1] - tri[0]).cross(tri[2] - tri[0]).length();
            if !(area > 0.0 && area.is_finite()) {
                continue;
            }
            let rect = scene
                .lights
                .iter()
                .position(|l| rect_contains(l, tri))
                .map(|i| i as u32);
            let owner = match rect {
                Some(i) => {
                    covered[i as usize] += area;
                    Owner::Rect(i)
                }
                None => {
                    set.area += area;
                    set.tris.push(prim as u32);
                    set.cdf.push(set.area);
                    Owner::Set
                }
            };
            set.owner.insert(prim as u32, owner);
        }
        for (i, light) in scene.lights.iter().enumerate() {
            if let Light::Rect { edge_u, edge_v, .. } = light {
                let area = edge_u.cross(*edge_v).length();
                set.visible[i] = covered[i] >= area * (1.0 - 1e-3);
                set.hidden_rects |= !set.visible[i];
            }
        }
        set
    }

    /// Number of emissive triangles sampled as lights of their own.
    pub fn sampled_triangles(&self) -> usize {
        self.tris.len()
    }

    /// True when bounces can find scene light `i` (its triangles cover it).
    pub fn is_visible(&self, i: usize) -> bool {
        self.visible.get(i).copied().unwrap_or(false)
    }

    /// A triangle of the set chosen by area, and `u.x` rescaled to stay uniform.
    fn pick(&self, u: Vec2) -> (u32, Vec2) {
        let x = u.x * self.area;
        let i = self
            .cdf
            .partition_point(|&c| c <= x)
            .min(self.tris.len() - 1);
        let lo = if i == 0 { 0.0 } else { self.cdf[i - 1] };
        let a = self.cdf[i] - lo;
        let ux = ((x - lo) / a).clamp(0.0, 1.0 - f32::EPSILON);
        (self.tris[i], Vec2::new(ux, u.y))
    }
}

/// True when `light` is a rectangle and all of `tri` lies in its plane and inside it.
fn rect_contains(light: &Light, tri: &[Vec3; 3]) -> bool {
    let Light::Rect {
        corner,
        edge_u,
        edge_v,
        ..
    } = *light
    else {
        return false;
    };
    let n = edge_u.cross(edge_v);
    let size = edge_u.length() + edge_v.length();
    let Some(nu) = n.try_normalize() else {
        return false;
    };
    // Coordinates along the edges by the dual basis (the edges need not be perpendicular).
    let du = edge_v.cross(n);
    let dv = n.cross(edge_u);
    let (su, sv) = (edge_u.dot(du), edge_v.dot(dv));
    let inside = |x: f32| (-COINCIDE..=1.0 + COINCIDE).contains(&x);
    tri.iter().all(|&p| {
        let d = p - corner;
        d.dot(nu).abs() <= COINCIDE * size && inside(d.dot(du) / su) && inside(d.dot(dv) / sv)
    })
}

/// Power heuristic for a strategy with `n` samples of density `p` against one of density `q`.
#[inline]
pub(super) fn power(n: f32, p: f32, q: f32) -> f32 {
    let a = n * p;
    let a2 = a * a;
    if a2.is_infinite() {
        1.0
    } else if a2 + q * q > 0.0 {
        a2 / (a2 + q * q)
    } else {
        0.0
    }
}

/// One light sample of the emissive triangles ([`Tracer::emissive_sample`]).
pub(super) struct EmissiveSample {
    /// The light reflected towards the viewer, shadow included, before any weight.
    pub(super) value: Vec3,
    /// The sample's density over solid angle at the surface.
    pub(super) p_light: f32,
    /// Unit direction from the surface to the sampled point.
    pub(super) wi: Vec3,
    /// True when its shadow ray went through a transparent surface (or shadows are off): a
    /// direction drawn from the lobes would not have found the point as its closest hit.
    pub(super) crossed: bool,
}

/// How the ray that reached a surface was chosen: says how emission found there counts.
#[derive(Clone, Copy, Debug)]
pub(super) enum Arrival {
    /// From the camera or a mirror: emission counts in full.
    Specular,
    /// A bounce from a surface at bounce depth `from`, with solid-angle density `pdf`,
    /// `travelled` units ago (straight through transparent surfaces on the way): emission from a
    /// light that next-event estimation samples is weighted against it.
    Bounce { pdf: f32, from: u32, travelled: f32 },
}

impl Tracer<'_> {
    /// Radiance along `ray`, whose closest hit is `hit`, by path tracing. `depth` counts the
    /// bounces before this surface; `beta` is the path's throughput so far (for Russian
    /// roulette).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn path(
        &self,
        ray: &Ray,
        hit: Option<Hit>,
        depth: u32,
        arrival: Arrival,
        beta: Vec3,
        rng: &mut PathSampler,
        counts: &mut RayCounts,
    ) -> Vec3 {
        let Some(hit) = hit else {
            return self.background(ray.dir);
        };
        let s = self.surface(ray, hit.prim, hit.u, hit.v);
        let m = s.material;
        let alpha = if self.plan.transmission {
            s.opacity
        } else {
            1.0
        };
        let wo = -ray.dir.normalize();
        let mut l = Vec3::ZERO;
        if m.is_emissive() {
            l += alpha * self.emission_found(ray, &hit, s.emission, arrival);
        }
        // The bounce from the last vertex only collects emission.
        if depth <= self.max_depth {
            l += alpha * self.lights_at(&s, wo, depth, rng, counts);
            l += alpha * self.bounce(&s, wo, depth, beta * alpha, rng, counts);
            if self.plan.reflections && s.is_mirror() {
                let r = reflect(ray.dir, s.n());
                if r.dot(s.ng) > 0.0 {
                    counts.reflection += 1;
                    let bounce = Ray::new(s.origin, r);
                    let tint = alpha * s.mirror_tint(wo);
                    let h = self.bvh.intersect(&bounce, f32::INFINITY);
                    l += tint
                        * self.path(
                            &bounce,
                            h,
                            depth + 1,
                            Arrival::Specular,
                            beta * tint,
                            rng,
                            counts,
                        );
                }
            }
            if alpha < 1.0 {
                counts.transmission += 1;
                let (dir, side) = transmit(ray.dir, &s);
                let through = Ray::new(offset_ray_origin(s.p, s.p_err, side), dir);
                let tint = m.transmission(alpha, s.bsdf.diffuse);
                // Shadow rays pass straight through transparent surfaces: light a bounce
                // finds beyond one is weighted as if the bounce had found it directly.
                let arrival = match arrival {
                    Arrival::Bounce {
                        pdf,
                        from,
                        travelled,
                    } => Arrival::Bounce {
                        pdf,
                        from,
                        travelled: travelled + hit.t * ray.dir.length(),
                    },
                    a => a,
                };
                let h = self.bvh.intersect(&through, f32::INFINITY);
                l += tint * self.path(&through, h, depth + 1, arrival, beta * tint, rng, counts);
            }
        }
        if self.plan.absorption && !s.entering && m.is_transparent() {
            l *= super::shade::beer_lambert(m.absorption, hit.t * ray.dir.length());
        }
        l
    }

    /// Emission `le` of the triangle `hit` found, weighted for how the ray was chosen.
    fn emission_found(&self, ray: &Ray, hit: &Hit, le: Vec3, arrival: Arrival) -> Vec3 {
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
    fn rect_samples(&self, samples: u32, depth: u32) -> u32 {
        if depth > 0 {
            return 1;
        }
        self.capped_samples(samples).max(1)
    }

    /// Next-event estimation at `s`: every point and rectangle light, and one sample of the
    /// emissive triangles, each weighted against the bounce that could find it.
    fn lights_at(
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
        let origin = s.origin;
        let bsdf = s.bsdf();
        // Only the rectangle lights no triangles cover need it.
        let glossy = self.lights.hidden_rects && bsdf.gloss_probability(wo) > 0.0;
        let mut sum = Vec3::ZERO;
        for (i, light) in self.scene.lights.iter().enumerate() {
            sum += match *light {
                Light::Point { .. } | Light::Spot { .. } => light
                    .point_towards(s.p)
                    .map_or(Vec3::ZERO, |(position, i)| {
                        self.point_light(s, origin, wo, position, i, counts)
                    }),
                Light::Rect {
                    corner,
                    edge_u,
                    edge_v,
                    color,
                    intensity,
                    samples,
                } => {
                    let n = self.rect_samples(samples, depth);
                    let rect = RectLight {
                        corner,
                        edge_u,
                        edge_v,
                        color,
                        intensity,
                        samples: n,
                    };
                    // Bounces find the light when its triangles cover it; on a glossy
                    // surface they look for it by its rectangle when they do not.
                    let weighted = self.lights.visible[i] || glossy;
                    self.rect_light(s, wo, &rect, rng, counts, |sample, _, area| {
                        if weighted {
                            let p_light = sample.d2 / (sample.cos_l * area);
                            power(n as f32, p_light, bsdf.pdf(sample.wi, wo))
                        } else {
                            1.0
                        }
                    })
                }
            };
        }
        if let Some(e) = self.emissive_sample(s, wo, rng, counts) {
            sum += e.value * power(1.0, e.p_light, bsdf.pdf(e.wi, wo));
        }
        sum
    }

    /// One light sample of the emissive triangles no rectangle light stands for (a triangle
    /// chosen by area, a point uniform on it), with its shadow ray: the light `s` reflects
    /// towards `wo` from it, unweighted. `None` when there are none, or the point lies behind
    /// the surface.
    pub(super) fn emissive_sample(
        &self,
        s: &Surface,
        wo: Vec3,
        rng: &mut PathSampler,
        counts: &mut RayCounts,
    ) -> Option<EmissiveSample> {
        if self.lights.tris.is_empty() {
            return None;
        }
        let (prim, u) = self.lights.pick(rng.next_2d());
        let tri = &self.scene.mesh.triangles[prim as usize];
        let su = u.x.sqrt();
        let (b1, b2) = (su * (1.0 - u.y), su * u.y);
        let q = tri[0] * (1.0 - su) + tri[1] * b1 + tri[2] * b2;
        let to = q - s.p;
        let d2 = to.length_squared();
        let wi = to / d2.sqrt();
        let cos_l = face_normal(tri).dot(wi).abs();
        let cos = s.n().dot(wi);
        if cos <= 0.0 || cos_l <= 0.0 || s.ng.dot(to) <= 0.0 {
            return None;
        }
        let p_light = d2 / (cos_l * self.lights.area);
        let (pass, crossed) = self.shadow_through(s.origin, q - s.origin, 1.0 - 1e-4, counts);
        let le = self.look(prim, b1, b2).emission;
        Some(EmissiveSample {
            value: brdf(s, wi, wo) * cos * le * pass / p_light,
            p_light,
            wi,
            crossed,
        })
    }

    /// The emission of the triangle `hit` that a direction `wi` from `s` drawn with density
    /// `pdf` (one of `count`) reached as its closest hit, weighted against one light sample of
    /// the emissive triangles (the power heuristic); zero when `hit` is not one of them.
    pub(super) fn emissive_along(
        &self,
        s: &Surface,
        wi: Vec3,
        hit: &Hit,
        pdf: f32,
        count: u32,
    ) -> Vec3 {
        if self.lights.owner.get(&hit.prim) != Some(&Owner::Set) {
            return Vec3::ZERO;
        }
        let tri = &self.scene.mesh.triangles[hit.prim as usize];
        let cos_l = face_normal(tri).dot(wi).abs();
        if cos_l <= 0.0 {
            return Vec3::ZERO;
        }
        let d = (s.p - (s.origin + hit.t * wi)).length();
        let p_light = d * d / (cos_l * self.lights.area);
        let le = self.look(hit.prim, hit.u, hit.v).emission;
        le * power(count as f32, pdf, p_light)
    }

    /// The bounce from `s`, sampled from its lobes, and the light it brings back (weighted by
    /// the surface's reflectance over the sampling density).
    fn bounce(
        &self,
        s: &Surface,
        wo: Vec3,
        depth: u32,
        beta: Vec3,
        rng: &mut PathSampler,
        counts: &mut RayCounts,
    ) -> Vec3 {
        let m = s.material;
        if !m.reflects() {
            return Vec3::ZERO;
        }
        let bsdf = s.bsdf();
        // On a glossy surface the bounce also looks for the rectangle lights no triangles
        // cover (which it cannot hit), as `lights_at` weights their samples.
        let glossy = self.lights.hidden_rects && bsdf.gloss_probability(wo) > 0.0;
        if depth == self.max_depth
            && self.lights.owner.is_empty()
            && !self.plan.environment
            && !glossy
        {
            // The last bounce only collects emission, and there is none to find.
            return Vec3::ZERO;
        }
        let u = rng.next_2d();
        let Some(Sample { wi, pdf }) = bsdf.sample(wo, u) else {
            return Vec3::ZERO;
        };
        let cos = s.n().dot(wi);
        if cos <= 0.0 || wi.dot(s.ng) <= 0.0 || pdf <= 0.0 {
            return Vec3::ZERO;
        }
        let mut weight = bsdf.eval(wi, wo) * cos / pdf;
        let mut l = Vec3::ZERO;
        if glossy {
            l += weight
                * self.rects_along(s, wi, pdf, 1, counts, |i, samples| {
                    (!self.lights.visible[i]).then(|| self.rect_samples(samples, depth))
                });
        }
        if depth == self.max_depth && self.lights.owner.is_empty() && !self.plan.environment {
            return l;
        }
        if depth >= ROULETTE_DEPTH {
            let survive = (beta * weight).max_element().min(MAX_SURVIVAL);
            if rng.next_2d().x >= survive {
                return l;
            }
            weight /= survive;
        }
        counts.bounce += 1;
        let bounce = Ray::new(s.origin, wi);
        // Drawn at random: neighbouring paths' bounces take other paths through the tree.
        let hit = self.bvh.intersect_incoherent(&bounce, f32::INFINITY);
        let arrival = Arrival::Bounce {
            pdf,
            from: depth,
            travelled: 0.0,
        };
        l + weight * self.path(&bounce, hit, depth + 1, arrival, beta * weight, rng, counts)
    }
}
