//! Shading: the surfaces' lobes ([`super::bsdf`]) under point, spot and rectangular lights and
//! emissive triangles, shadows that let light through
//! transparent surfaces (with Beer-Lambert absorption inside closed meshes), mirror
//! reflections and transmission, each only where the [`RenderPlan`] says the scene needs it.

use glam::Vec3;

use super::bsdf::{Bsdf, Bump, Coat, Gloss, Sample};
use super::environment::EnvironmentMap;
use super::path::{Arrival, LightSet, power};
use super::sheen::Sheen;
use super::{RayCounts, RenderPlan};
use crate::bvh::{Bvh, Hit};
use crate::geometry::{Ray, interpolation_error, offset_ray_origin};
use crate::sampling::PathSampler;
use crate::scene::pbr::{Lobes, Texels};
use crate::scene::{Integrator, Light, Material, Scene, face_normal};

/// What a ray that cannot be traced (zero, NaN or infinite direction or origin) returns:
/// black, never NaN.
pub const FALLBACK: Vec3 = Vec3::ZERO;

/// Traces rays through a scene and returns the radiance they carry back.
pub struct Tracer<'a> {
    /// The scene.
    pub scene: &'a Scene,
    /// Its BVH.
    pub bvh: &'a Bvh,
    /// What to compute.
    pub plan: RenderPlan,
    /// Largest number of reflection or transmission events along a path.
    pub max_depth: u32,
    /// The environment, loaded (black when the plan has none).
    pub env: &'a EnvironmentMap,
    /// What both integrators sample besides the scene's lights: the emissive triangles no
    /// rectangle light stands for.
    pub lights: std::sync::Arc<LightSet>,
    /// Per material, its look when no texture varies it (the same at every point), found once
    /// instead of at every hit.
    looks: Vec<Option<Look>>,
}

/// Where a ray met a surface.
pub(super) struct Surface<'a> {
    pub(super) p: Vec3,
    /// Bound on the rounding error of `p`, per coordinate.
    pub(super) p_err: Vec3,
    /// Geometric normal facing the incoming ray.
    pub(super) ng: Vec3,
    /// `p` moved off the surface on the side of `ng` ([`offset_ray_origin`]): where shadow
    /// rays, bounces and reflections leave from, made once for all of them.
    pub(super) origin: Vec3,
    /// True when the ray arrived on the side the triangle's winding calls outside.
    pub(super) entering: bool,
    pub(super) material: &'a Material,
    /// The material's emitted radiance here (its texture applied).
    pub(super) emission: Vec3,
    /// The material's opacity here (its texture's alpha applied, for `BLEND` and `MASK`).
    pub(super) opacity: f32,
    /// The material's mirror reflectance here (zero: no reflection ray).
    pub(super) mirror: Vec3,
    /// What the surface reflects here, about its shading normal `n`: the material's diffuse
    /// colour (its texture applied), glossy lobe, sheen ([`Sheen::NONE`]: none) and clear
    /// coat ([`Coat::NONE`]: none) here, and the shadowing of a normal a map bent
    /// ([`Bump::NONE`]: none, or not softened). Kept whole, so that each use borrows it.
    pub(super) bsdf: Bsdf,
}

impl Surface<'_> {
    /// What the surface reflects here, about its shading normal.
    pub(super) fn bsdf(&self) -> &Bsdf {
        &self.bsdf
    }

    /// Shading normal on the same side as `ng` (the BSDF's).
    pub(super) fn n(&self) -> Vec3 {
        self.bsdf.n
    }

    /// True when the surface reflects like a mirror here.
    pub(super) fn is_mirror(&self) -> bool {
        self.mirror.max_element() > 0.0
    }

    /// What the mirror reflects of light arriving from `wo`'s mirror direction: its
    /// reflectance (at most 1), less what a clear coat over it reflects away, `1 - k F(wo.n)`,
    /// and dimmed by a sheen's albedo scaling (the coat's and the sheen's own reflection are
    /// their lobes in [`Surface::bsdf`]).
    pub(super) fn mirror_tint(&self, wo: Vec3) -> Vec3 {
        let b = &self.bsdf;
        let c = wo.dot(b.n);
        let shadowing = b.bump.shadowing(reflect(-wo, b.n));
        self.mirror.min(Vec3::ONE) * (1.0 - b.coat.reflects(c)) * b.sheen.scaling(c, c) * shadowing
    }
}

impl<'a> Tracer<'a> {
    /// A tracer of `scene` with the plan's integrator (finding the emissive triangles both
    /// integrators sample as lights).
    pub fn new(
        scene: &'a Scene,
        bvh: &'a Bvh,
        plan: RenderPlan,
        max_depth: u32,
        env: &'a EnvironmentMap,
    ) -> Self {
        let lights = LightSet::new(scene);
        Self::with_lights(
            scene,
            bvh,
            plan,
            max_depth,
            env,
            std::sync::Arc::new(lights),
        )
    }

    /// [`Tracer::new`] with the light set already found (the viewer keeps one per scene
    /// instead of finding it for every slice of tracing).
    pub fn with_lights(
        scene: &'a Scene,
        bvh: &'a Bvh,
        plan: RenderPlan,
        max_depth: u32,
        env: &'a EnvironmentMap,
        lights: std::sync::Arc<LightSet>,
    ) -> Self {
        let looks = scene
            .materials
            .iter()
            .map(|m| (m.textures().next().is_none()).then(|| textured(scene, m, 0, 0.0, 0.0)))
            .collect();
        Self {
            scene,
            bvh,
            plan,
            max_depth,
            env,
            lights,
            looks,
        }
    }

    /// The look of triangle `prim`'s material at barycentric `(u, v)` ([`textured`]): the one
    /// found at the start when no texture varies it.
    pub(super) fn look(&self, prim: u32, u: f32, v: f32) -> Look {
        let id = self.scene.mesh.material_ids[prim as usize] as usize;
        match self.looks.get(id) {
            Some(Some(look)) => *look,
            _ => textured(self.scene, &self.scene.materials[id], prim, u, v),
        }
    }

    /// Radiance arriving at the ray's origin from along the ray.
    pub fn radiance(&self, ray: &Ray, rng: &mut PathSampler, counts: &mut RayCounts) -> Vec3 {
        if !ray.is_valid() {
            // A zero, NaN or infinite direction (or origin) has nowhere to go.
            return FALLBACK;
        }
        let hit = self.bvh.intersect(ray, f32::INFINITY);
        crate::bvh::wide::kernel::with_denormals_flushed(|| {
            self.radiance_from_hit(ray, hit, rng, counts)
        })
    }

    /// [`Tracer::radiance`] of a ray whose closest hit is already known (`hit` is what
    /// `self.bvh.intersect(ray, f32::INFINITY)` gives, as a packet traced it).
    ///
    /// Callers run it inside [`crate::bvh::wide::kernel::with_denormals_flushed`], once per
    /// batch of samples (a tile, a chunk of the viewer's cache, [`Tracer::radiance`]): the
    /// compiler computes three-float arithmetic in four-lane (or two in four) vector
    /// instructions whose spare lanes hold whatever the registers and the stack held, often a
    /// denormal, and each such instruction cost Intel CPUs a microcode assist: on an Intel Xeon
    /// the Cornell box renders in 0.6x the time with the flush on. Values that small
    /// are far below anything a pixel shows.
    pub fn radiance_from_hit(
        &self,
        ray: &Ray,
        hit: Option<Hit>,
        rng: &mut PathSampler,
        counts: &mut RayCounts,
    ) -> Vec3 {
        if !ray.is_valid() {
            return FALLBACK;
        }
        match self.plan.integrator {
            Integrator::Direct => self.shade(ray, hit, 0, rng, counts),
            Integrator::Path => {
                let a = Arrival::Specular;
                self.path(ray, hit, 0, a, Vec3::ONE, rng, counts)
            }
        }
    }

    pub(super) fn background(&self, dir: Vec3) -> Vec3 {
        if self.plan.environment {
            self.env.radiance(dir)
        } else {
            Vec3::ZERO
        }
    }

    pub(super) fn surface(&self, ray: &Ray, prim: u32, u: f32, v: f32) -> Surface<'_> {
        let scene = self.scene;
        let tri = &scene.mesh.triangles[prim as usize];
        let ns = &scene.mesh.normals[prim as usize];
        let b = [1.0 - u - v, u, v];
        let p = tri[0] * b[0] + tri[1] * b[1] + tri[2] * b[2];
        let p_err = interpolation_error(tri, b);
        let outward = face_normal(tri);
        let entering = outward.dot(ray.dir) < 0.0;
        let ng = if entering { outward } else { -outward };
        let material = scene.material_of(prim);
        let interpolated = ns[0] * (1.0 - u - v) + ns[1] * u + ns[2] * v;
        let mut n = interpolated.try_normalize().unwrap_or(ng);
        // Both turned towards the ray when the interpolated normal faces away from it: a
        // normal map bends the normal of the side the ray sees as it does the other's.
        let side = if n.dot(ng) < 0.0 { -1.0 } else { 1.0 };
        n *= side;
        // The normal before any map bends it (a clear coat's own normal starts from it).
        let plain = n;
        if let Some(mapped) = self
            .plan
            .normal_maps
            .then(|| {
                normal_mapped(scene, material, prim, u, v, interpolated)
                    .or_else(|| bump_mapped(scene, material, prim, u, v, interpolated))
            })
            .flatten()
        {
            // A map bending the normal past the surface's horizon is not followed there.
            if (mapped * side).dot(ng) > 0.0 {
                n = mapped * side;
            }
        }
        let bump = if n != plain && self.plan.soft_terminator {
            Bump::new(plain, n)
        } else {
            Bump::NONE
        };
        let Look {
            diffuse,
            emission,
            opacity,
            gloss,
            sheen,
            mut coat,
            mirror,
        } = self.look(prim, u, v);
        if coat.weight > 0.0 {
            // The coat's own normal: the interpolated one, or its own map's about it.
            coat.n = plain;
            let cc = material.pbr.as_ref().and_then(|p| p.clearcoat.as_ref());
            if let Some(c) = cc.filter(|_| self.plan.normal_maps)
                && let Some(map) = &c.normal_map
                && let Some(mapped) =
                    normal_mapped_by(scene, map, c.normal_scale, prim, u, v, interpolated)
                && (mapped * side).dot(ng) > 0.0
            {
                coat.n = mapped * side;
            }
        }
        Surface {
            p,
            p_err,
            ng,
            origin: offset_ray_origin(p, p_err, ng),
            entering,
            material,
            emission,
            opacity,
            mirror,
            bsdf: Bsdf {
                n,
                diffuse,
                gloss,
                sheen,
                coat,
                bump,
            },
        }
    }

    fn trace(&self, ray: &Ray, depth: u32, rng: &mut PathSampler, counts: &mut RayCounts) -> Vec3 {
        let hit = self.bvh.intersect(ray, f32::INFINITY);
        self.shade(ray, hit, depth, rng, counts)
    }

    /// Radiance along `ray` given its closest hit.
    fn shade(
        &self,
        ray: &Ray,
        hit: Option<Hit>,
        depth: u32,
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

        let mut l = alpha * (s.emission + self.direct(&s, wo, rng, counts));
        if self.plan.reflections && s.is_mirror() && depth < self.max_depth {
            let r = reflect(ray.dir, s.n());
            if r.dot(s.ng) > 0.0 {
                counts.reflection += 1;
                let bounce = Ray::new(s.origin, r);
                l += alpha * s.mirror_tint(wo) * self.trace(&bounce, depth + 1, rng, counts);
            }
        }
        if alpha < 1.0 && depth < self.max_depth {
            counts.transmission += 1;
            let (dir, side) = transmit(ray.dir, &s);
            let through = Ray::new(offset_ray_origin(s.p, s.p_err, side), dir);
            let tint = m.transmission(alpha, s.bsdf.diffuse);
            l += tint * self.trace(&through, depth + 1, rng, counts);
        }
        if self.plan.absorption && !s.entering && m.is_transparent() {
            // The segment just travelled ran inside this material's closed mesh.
            l *= beer_lambert(m.absorption, hit.t * ray.dir.length());
        }
        l
    }

    /// Light arriving directly from the light sources, reflected towards `wo`.
    ///
    /// Point and spot lights are sampled at their point, the emissive triangles no rectangle
    /// light stands for by one point chosen by area. A rectangle light is sampled over its
    /// area. On a surface with a glossy lobe, the rectangle lights and emissive triangles are
    /// also found by directions drawn from the surface's lobes ([`Tracer::lights_by_bsdf`]),
    /// the two weighted against each other by multiple importance sampling (the power
    /// heuristic, Veach 1997), as Mitsuba's `direct` does: a narrow lobe under a large light is
    /// found by its own directions, a small light by its samples. A diffuse surface takes
    /// light samples only (the lobe's directions would rarely find a light it cannot already
    /// sample well), and so does an emissive triangle seen through a transparent surface
    /// (which a direction's closest hit cannot reach).
    fn direct(&self, s: &Surface, wo: Vec3, rng: &mut PathSampler, counts: &mut RayCounts) -> Vec3 {
        let m = s.material;
        if !m.reflects() {
            return Vec3::ZERO;
        }
        let origin = s.origin;
        let bsdf = s.bsdf();
        // Directions drawn from the lobes, as many as the most light samples a rectangle
        // light takes here (one for the emissive triangles); none without a glossy lobe.
        let by_bsdf = if bsdf.gloss_probability(wo) > 0.0 {
            let triangles = u32::from(self.lights.sampled_triangles() > 0);
            self.scene
                .lights
                .iter()
                .filter_map(|l| match *l {
                    Light::Rect { samples, .. } => Some(self.capped_samples(samples).max(1)),
                    _ => None,
                })
                .fold(triangles, u32::max)
        } else {
            0
        };
        let mut sum = Vec3::ZERO;
        for light in &self.scene.lights {
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
                    let rect = RectLight {
                        corner,
                        edge_u,
                        edge_v,
                        color,
                        intensity,
                        samples: self.capped_samples(samples),
                    };
                    let n = rect.samples as f32;
                    let m = by_bsdf as f32;
                    self.rect_light(s, wo, &rect, rng, counts, |sample, _, area| {
                        if by_bsdf == 0 {
                            return 1.0;
                        }
                        let p_light = sample.d2 / (sample.cos_l * area);
                        power(n, p_light, m * bsdf.pdf(sample.wi, wo))
                    })
                }
            };
        }
        if let Some(e) = self.emissive_sample(s, wo, rng, counts) {
            // Where the lobes' directions could not have found the point, its sample counts
            // alone.
            let w = if by_bsdf == 0 || e.crossed {
                1.0
            } else {
                power(1.0, e.p_light, by_bsdf as f32 * bsdf.pdf(e.wi, wo))
            };
            sum += e.value * w;
        }
        if by_bsdf > 0 {
            sum += self.lights_by_bsdf(s, bsdf, wo, by_bsdf, rng, counts);
        }
        sum
    }

    /// The light of the rectangle lights and emissive triangles at `s` (whose lobes are
    /// `bsdf`) towards `wo` estimated
    /// from `count` directions drawn from the surface's lobes, weighted against the lights' own
    /// samples ([`Tracer::direct`] weights those): a rectangle light met by its rectangle and a
    /// shadow ray ([`Tracer::rects_along`]), an emissive triangle as the direction's closest hit
    /// (when shadows are on: with them off, the triangles' samples count alone).
    fn lights_by_bsdf(
        &self,
        s: &Surface,
        bsdf: &Bsdf,
        wo: Vec3,
        count: u32,
        rng: &mut PathSampler,
        counts: &mut RayCounts,
    ) -> Vec3 {
        let mut acc = Vec3::ZERO;
        for _ in 0..count {
            let Some(Sample { wi, pdf }) = bsdf.sample(wo, rng.next_2d()) else {
                continue;
            };
            let cos = s.n().dot(wi);
            if cos <= 0.0 || wi.dot(s.ng) <= 0.0 || pdf <= 0.0 {
                continue;
            }
            let f = bsdf.eval(wi, wo) * cos / pdf;
            let mut l = self.rects_along(s, wi, pdf, count, counts, |_, samples| {
                Some(self.capped_samples(samples).max(1))
            });
            if self.plan.shadows && self.lights.sampled_triangles() > 0 {
                counts.shadow += 1;
                if let Some(hit) = self.bvh.intersect(&Ray::new(s.origin, wi), f32::INFINITY) {
                    l += self.emissive_along(s, wi, &hit, pdf, count);
                }
            }
            acc += l * f;
        }
        acc / count as f32
    }

    /// Radiance from the rectangle lights that the direction `wi` from `s` meets on their
    /// front, each seen through a shadow ray and weighted against the light's own samples by
    /// the power heuristic: `wi` is one of `count` directions drawn with density `pdf`, and
    /// `light_samples(i, samples)` says how many samples rectangle light `i` (of `samples`)
    /// takes here, or `None` to leave it out. Lights do not shadow each other, as with their
    /// samples: a direction counts every rectangle it meets.
    pub(super) fn rects_along(
        &self,
        s: &Surface,
        wi: Vec3,
        pdf: f32,
        count: u32,
        counts: &mut RayCounts,
        light_samples: impl Fn(usize, u32) -> Option<u32>,
    ) -> Vec3 {
        let mut acc = Vec3::ZERO;
        for (i, light) in self.scene.lights.iter().enumerate() {
            let Light::Rect {
                corner,
                edge_u,
                edge_v,
                color,
                intensity,
                samples,
            } = *light
            else {
                continue;
            };
            let Some(n) = light_samples(i, samples) else {
                continue;
            };
            let Some(hit) = rect_hit(s.p, wi, corner, edge_u, edge_v) else {
                continue;
            };
            let area = edge_u.cross(edge_v).length();
            let p_light = hit.d2 / (hit.cos_l * area);
            let w = power(count as f32, pdf, n as f32 * p_light);
            if w == 0.0 {
                continue;
            }
            let pass = self.shadow(s.origin, hit.q - s.origin, 1.0 - 1e-4, counts);
            acc += color * intensity * pass * w;
        }
        acc
    }

    /// Light a point light of radiant intensity `intensity` sends to `s` and `s` reflects
    /// towards `wo`, shadow ray from `origin` included (zero from behind the surface).
    pub(super) fn point_light(
        &self,
        s: &Surface,
        origin: Vec3,
        wo: Vec3,
        position: Vec3,
        intensity: Vec3,
        counts: &mut RayCounts,
    ) -> Vec3 {
        // The light's direction and distance from the surface point itself; only the shadow
        // ray starts from the offset origin.
        let to = position - s.p;
        let d2 = to.length_squared();
        let wi = to / d2.sqrt();
        if s.n().dot(wi) <= 0.0 || s.ng.dot(to) <= 0.0 {
            return Vec3::ZERO;
        }
        let pass = self.shadow(origin, position - origin, 1.0, counts);
        brdf(s, wi, wo) * s.n().dot(wi) * intensity * pass / d2
    }

    /// Light the rectangle light `rect` sends to `s` and `s` reflects towards `wo`, from
    /// `rect.samples` samples of it, each with its shadow ray (stopping just short of the
    /// light, so that its own quad does not shadow it). Each sample's term is scaled by
    /// `weight(sample, cos, area)` (`cos` at the surface, `area` the light's): the path
    /// tracer's multiple-importance weight, 1 for direct light alone; a sample weighted 0
    /// casts no shadow ray.
    pub(super) fn rect_light(
        &self,
        s: &Surface,
        wo: Vec3,
        rect: &RectLight,
        rng: &mut PathSampler,
        counts: &mut RayCounts,
        weight: impl Fn(&RectSample, f32, f32) -> f32,
    ) -> Vec3 {
        let RectLight {
            corner,
            edge_u,
            edge_v,
            color,
            intensity,
            samples: n,
        } = *rect;
        let origin = s.origin;
        let normal = edge_u.cross(edge_v);
        let area = normal.length();
        let ln = normal / area;
        let mut acc = Vec3::ZERO;
        for _ in 0..n {
            let Some(sample) = rect_sample(s, corner, edge_u, edge_v, ln, rng.next_2d()) else {
                continue;
            };
            let cos = s.n().dot(sample.wi);
            let w = weight(&sample, cos, area);
            if w == 0.0 {
                continue;
            }
            let RectSample { q, wi, d2, cos_l } = sample;
            let pass = self.shadow(origin, q - origin, 1.0 - 1e-4, counts);
            acc += brdf(s, wi, wo) * cos * cos_l * area / d2 * pass * w;
        }
        acc * color * intensity / n as f32
    }

    /// A rectangle light's `samples` after the plan's cap.
    pub(super) fn capped_samples(&self, samples: u32) -> u32 {
        self.plan
            .max_light_samples
            .map_or(samples, |cap| samples.min(cap.max(1)))
    }

    /// Fraction of light passing from `origin + to * t_max` back to `origin`, per channel.
    pub(super) fn shadow(
        &self,
        origin: Vec3,
        to: Vec3,
        t_max: f32,
        counts: &mut RayCounts,
    ) -> Vec3 {
        self.shadow_through(origin, to, t_max, counts).0
    }

    /// [`Tracer::shadow`], and whether the light it passes went through a transparent surface
    /// (or was not looked at, shadows being off): then a ray along `to` would not have reached
    /// the light as its closest hit.
    pub(super) fn shadow_through(
        &self,
        origin: Vec3,
        to: Vec3,
        t_max: f32,
        counts: &mut RayCounts,
    ) -> (Vec3, bool) {
        if !self.plan.shadows {
            return (Vec3::ONE, true);
        }
        counts.shadow += 1;
        let ray = Ray::new(origin, to);
        if !self.plan.transparent_shadows {
            let pass = if self.bvh.occluded(&ray, t_max) {
                Vec3::ZERO
            } else {
                Vec3::ONE
            };
            return (pass, false);
        }
        let mut crossed = false;
        let scene = self.scene;
        let len = to.length();
        // Absorption needs the distance travelled inside each medium. Summing `+t` over exits
        // and `-t` over entries gives it in any order, so hits need no sorting; a medium the
        // segment ends inside adds `t_max` once per unmatched entry.
        let mut inside: Vec<(u32, f32, i32)> = Vec::new();
        let mut pass = self.bvh.transmittance(&ray, t_max, |prim, t| {
            let m = scene.material_of(prim);
            if !m.is_transparent() {
                return Vec3::ZERO;
            }
            // A texture's alpha and colour are read where the shadow ray crosses the
            // triangle, as the camera would see them there.
            let (opacity, diffuse) = if m.is_textured() {
                let tri = &scene.mesh.triangles[prim as usize];
                let (u, v) = barycentric(tri, origin + to * t);
                let look = textured(scene, m, prim, u, v);
                (look.opacity, look.diffuse)
            } else {
                (m.opacity_at(1.0), m.diffuse)
            };
            if opacity >= 1.0 {
                return Vec3::ZERO;
            }
            crossed = true;
            if self.plan.absorption && m.absorption.max_element() > 0.0 {
                let id = scene.mesh.material_ids[prim as usize];
                let entering = face_normal(&scene.mesh.triangles[prim as usize]).dot(to) < 0.0;
                let (dt, db) = if entering { (-t, 1) } else { (t, -1) };
                match inside.iter_mut().find(|e| e.0 == id) {
                    Some(e) => {
                        e.1 += dt;
                        e.2 += db;
                    }
                    None => inside.push((id, dt, db)),
                }
            }
            m.transmission(opacity, diffuse)
        });
        for (id, sum, balance) in inside {
            let d = (sum + balance.max(0) as f32 * t_max) * len;
            pass *= beer_lambert(scene.materials[id as usize].absorption, d.max(0.0));
        }
        (pass, crossed)
    }
}

/// A rectangle light's shape and emission: the rectangle `corner + [0, 1] edge_u +
/// [0, 1] edge_v`, facing along `edge_u x edge_v`, `color * intensity`, and the number of
/// samples to estimate its light with.
#[derive(Clone, Copy)]
pub(super) struct RectLight {
    pub(super) corner: Vec3,
    pub(super) edge_u: Vec3,
    pub(super) edge_v: Vec3,
    pub(super) color: Vec3,
    pub(super) intensity: f32,
    pub(super) samples: u32,
}

/// A point on a rectangle light seen from a surface.
pub(super) struct RectSample {
    /// The point.
    pub(super) q: Vec3,
    /// Unit direction from the surface to it.
    pub(super) wi: Vec3,
    /// Squared distance.
    pub(super) d2: f32,
    /// Cosine at the light (positive: its front faces the surface).
    pub(super) cos_l: f32,
}

/// The point `u` of the rectangle `corner + u.x edge_u + u.y edge_v` (unit normal `ln`) as seen
/// from `s`, or `None` when it lies behind the surface or shows the surface its back.
pub(super) fn rect_sample(
    s: &Surface,
    corner: Vec3,
    edge_u: Vec3,
    edge_v: Vec3,
    ln: Vec3,
    u: glam::Vec2,
) -> Option<RectSample> {
    let q = corner + u.x * edge_u + u.y * edge_v;
    let to = q - s.p;
    let d2 = to.length_squared();
    let wi = to / d2.sqrt();
    let cos_l = -ln.dot(wi);
    if s.n().dot(wi) <= 0.0 || cos_l <= 0.0 || s.ng.dot(to) <= 0.0 {
        return None;
    }
    Some(RectSample { q, wi, d2, cos_l })
}

/// Where the ray from `p` along the unit direction `wi` meets the front of the rectangle
/// `corner + [0, 1] edge_u + [0, 1] edge_v` (which faces along `edge_u x edge_v`), as the
/// sample [`rect_sample`] would have drawn there; `None` when it misses the rectangle or
/// meets its back.
pub(super) fn rect_hit(
    p: Vec3,
    wi: Vec3,
    corner: Vec3,
    edge_u: Vec3,
    edge_v: Vec3,
) -> Option<RectSample> {
    let normal = edge_u.cross(edge_v);
    let ln = normal.try_normalize()?;
    let cos_l = -ln.dot(wi);
    if cos_l.is_nan() || cos_l <= 0.0 {
        return None;
    }
    let t = (corner - p).dot(ln) / -cos_l;
    if !(t > 0.0 && t.is_finite()) {
        return None;
    }
    let q = p + t * wi;
    // Coordinates along the edges by the dual basis (the edges need not be perpendicular).
    let d = q - corner;
    let a = d.dot(edge_v.cross(normal)) / edge_u.dot(edge_v.cross(normal));
    let b = d.dot(normal.cross(edge_u)) / edge_v.dot(normal.cross(edge_u));
    if !((0.0..=1.0).contains(&a) && (0.0..=1.0).contains(&b)) {
        return None;
    }
    Some(RectSample {
        q,
        wi,
        d2: t * t,
        cos_l,
    })
}

/// What a material looks like at one point of a surface.
#[derive(Clone, Copy)]
pub(super) struct Look {
    pub(super) diffuse: Vec3,
    pub(super) emission: Vec3,
    pub(super) opacity: f32,
    pub(super) gloss: Gloss,
    pub(super) sheen: Sheen,
    pub(super) coat: Coat,
    pub(super) mirror: Vec3,
}

/// The look of `m` at barycentric `(u, v)` of triangle `prim`: the material's factors times
/// its textures, read at the triangle's texture coordinates (the diffuse texture's alpha for
/// the opacity, as its alpha mode says). A glTF material's base colour and
/// metallic-roughness textures vary its base colour, metalness and roughness, from which its
/// lobes are made here ([`crate::scene::pbr`]), and its clear coat's textures vary the coat;
/// other materials' textures multiply the diffuse colour.
pub(super) fn textured(scene: &Scene, m: &Material, prim: u32, u: f32, v: f32) -> Look {
    // Each texture reads its own coordinate set (glTF's TEXCOORD_0 or TEXCOORD_1).
    let sample = |t: &crate::scene::Texture| t.sample(scene.mesh.uv_at(t.uv_set, prim, u, v));
    let coat = m
        .pbr
        .as_ref()
        .and_then(|p| p.clearcoat.as_ref())
        .map_or(Coat::NONE, |c| {
            let (weight, alpha) = c.at(
                c.map.as_deref().map(sample),
                c.roughness_map.as_deref().map(sample),
            );
            // The normal is the surface's: set by `Tracer::surface`.
            Coat {
                weight,
                alpha,
                n: Vec3::Z,
            }
        });
    let sheen = m
        .pbr
        .as_ref()
        .and_then(|p| p.sheen.as_ref())
        .map_or(Sheen::NONE, |s| {
            let (color, roughness) = s.at(
                s.color_map.as_deref().map(sample),
                s.roughness_map.as_deref().map(sample),
            );
            Sheen::new(color, roughness)
        });
    if !m.is_textured() {
        let (gloss, mirror) = match &m.pbr {
            Some(pbr) => {
                let lobes = pbr.lobes_at(Texels::default());
                (ggx(&lobes), lobes.mirror)
            }
            None => (phong(m), m.mirror),
        };
        return Look {
            diffuse: m.diffuse,
            emission: m.emission,
            opacity: m.opacity_at(1.0),
            gloss,
            sheen,
            coat,
            mirror,
        };
    }
    let base = m.diffuse_map.as_deref().map(sample);
    let emission = m
        .emission_map
        .as_deref()
        .map_or(m.emission, |t| m.emission * sample(t).truncate());
    let opacity = m.opacity_at(base.map_or(1.0, |b| b.w));
    match &m.pbr {
        Some(pbr) => {
            let lobes = pbr.lobes_at(Texels {
                base: base.map(|b| b.truncate()),
                mr: pbr.map.as_deref().map(sample),
                specular: pbr.specular.map.as_deref().map(sample),
                specular_color: pbr.specular.color_map.as_deref().map(sample),
            });
            Look {
                diffuse: lobes.diffuse,
                emission,
                opacity,
                gloss: ggx(&lobes),
                sheen,
                coat,
                mirror: lobes.mirror,
            }
        }
        None => Look {
            diffuse: base.map_or(m.diffuse, |b| m.diffuse * b.truncate()),
            emission,
            opacity,
            gloss: phong(m),
            sheen,
            coat,
            mirror: m.mirror,
        },
    }
}

/// The GGX lobe of metallic-roughness lobes (none where the point is a mirror).
fn ggx(lobes: &Lobes) -> Gloss {
    if lobes.f0 == Vec3::ZERO {
        Gloss::None
    } else {
        Gloss::Ggx {
            f0: lobes.f0,
            f90: lobes.f90,
            alpha: lobes.alpha,
            dielectric_f0: lobes.dielectric.f0.max_element(),
            weight: lobes.dielectric.weight,
        }
    }
}

/// The Blinn-Phong lobe of a material without metallic-roughness parameters.
fn phong(m: &Material) -> Gloss {
    if m.specular == Vec3::ZERO {
        Gloss::None
    } else {
        Gloss::Phong {
            color: m.specular,
            exponent: m.shininess,
        }
    }
}

/// The shading normal a material's normal map gives at barycentric `(u, v)` of triangle
/// `prim`, about the interpolated normal `n` (`None` without a map, without a tangent there,
/// or where the frame is degenerate: the caller keeps `n`). The map bends the normal on the
/// side of the surface `n` is on; [`Tracer::surface`] then turns the result towards the ray
/// as it does `n`.
pub(super) fn normal_mapped(
    scene: &Scene,
    m: &Material,
    prim: u32,
    u: f32,
    v: f32,
    n: Vec3,
) -> Option<Vec3> {
    let map = m.normal_map.as_ref()?;
    normal_mapped_by(scene, map, m.normal_scale, prim, u, v, n)
}

/// [`normal_mapped`] by the map `map` of scale `scale` (a material's, or its clear coat's).
fn normal_mapped_by(
    scene: &Scene,
    map: &crate::scene::Texture,
    scale: f32,
    prim: u32,
    u: f32,
    v: f32,
    n: Vec3,
) -> Option<Vec3> {
    let t = scene.mesh.tangent_at(prim, u, v);
    if t == glam::Vec4::ZERO {
        return None;
    }
    let texel = map
        .sample(scene.mesh.uv_at(map.uv_set, prim, u, v))
        .truncate();
    crate::scene::tangents::perturbed(n, t, texel, scale)
}

/// The shading normal a material's height map gives at barycentric `(u, v)` of triangle
/// `prim`, about the interpolated normal `n` (`None` without a map, or where the triangle's
/// texture coordinates or the result are degenerate: the caller keeps `n`), on `n`'s side.
///
/// The surface is taken as displaced along `n` by `height_scale` times the map's value
/// (its luminance), and the normal is that of the displaced surface, the normal's own change
/// across the triangle left out: with `dp/du`, `dp/dv` the triangle's derivatives by its
/// texture coordinates made tangent to `n`, and `g` the displacement's gradient in texture
/// space, `normalize((dp/du + g.x n) x (dp/dv + g.y n))`. This is Mitsuba's `bumpmap`
/// (which flips by the geometric normal; the reference scenes' meshes have face normals, where
/// the two agree).
pub(super) fn bump_mapped(
    scene: &Scene,
    m: &Material,
    prim: u32,
    u: f32,
    v: f32,
    n: Vec3,
) -> Option<Vec3> {
    let map = m.height_map.as_ref()?;
    let mesh = &scene.mesh;
    let tri = &mesh.triangles[prim as usize];
    let uv = |a: f32, b: f32| mesh.uv_at(map.uv_set, prim, a, b);
    let (t0, d1, d2) = (uv(0.0, 0.0), uv(1.0, 0.0), uv(0.0, 1.0));
    let (d1, d2) = (d1 - t0, d2 - t0);
    let det = d1.x * d2.y - d1.y * d2.x;
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let (e1, e2) = (tri[1] - tri[0], tri[2] - tri[0]);
    let dp_du = (e1 * d2.y - e2 * d1.y) / det;
    let dp_dv = (e2 * d1.x - e1 * d2.x) / det;
    let n = n.try_normalize()?;
    let g = map.luminance_gradient(uv(u, v)) * m.height_scale;
    let du = dp_du + n * (g.x - n.dot(dp_du));
    let dv = dp_dv + n * (g.y - n.dot(dp_dv));
    let bent = du.cross(dv).try_normalize()?;
    Some(if bent.dot(n) < 0.0 { -bent } else { bent })
}

/// Barycentric `(u, v)` (the weights of the second and third vertex) of a point `p` lying on
/// triangle `t` (Ericson, Real-Time Collision Detection, 3.4).
pub(super) fn barycentric(t: &[Vec3; 3], p: Vec3) -> (f32, f32) {
    let (e1, e2, d) = (t[1] - t[0], t[2] - t[0], p - t[0]);
    let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let (d1, d2) = (d.dot(e1), d.dot(e2));
    let den = d11 * d22 - d12 * d12;
    if den == 0.0 || !den.is_finite() {
        return (0.0, 0.0);
    }
    ((d22 * d1 - d12 * d2) / den, (d11 * d2 - d12 * d1) / den)
}

/// The surface's reflectance from `wi` towards `wo` at the shading point (its textures
/// applied): Lambertian plus its glossy lobe ([`super::bsdf`]).
pub(super) fn brdf(s: &Surface, wi: Vec3, wo: Vec3) -> Vec3 {
    s.bsdf().eval(wi, wo)
}

/// Mirror direction of `d` about the normal `n`.
pub fn reflect(d: Vec3, n: Vec3) -> Vec3 {
    d - 2.0 * d.dot(n) * n
}

/// Direction through a transparent surface (refracted by its index of refraction, or totally
/// reflected) and the side of the surface the new ray leaves from.
pub(super) fn transmit(d: Vec3, s: &Surface) -> (Vec3, Vec3) {
    let ior = s.material.ior;
    if ior == 1.0 || ior.is_nan() || ior <= 0.0 {
        return (d, -s.ng);
    }
    let eta = if s.entering { 1.0 / ior } else { ior };
    let dn = d.normalize();
    let cos_i = -dn.dot(s.n());
    let k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
    if k < 0.0 {
        (reflect(dn, s.n()), s.ng) // total internal reflection
    } else {
        (eta * dn + (eta * cos_i - k.sqrt()) * s.n(), -s.ng)
    }
}

/// `exp(-sigma d)` per channel.
pub fn beer_lambert(sigma: Vec3, d: f32) -> Vec3 {
    Vec3::new(
        (-sigma.x * d).exp(),
        (-sigma.y * d).exp(),
        (-sigma.z * d).exp(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A skewed rectangle (edges not perpendicular) facing along `edge_u x edge_v`.
    const CORNER: Vec3 = Vec3::new(1.0, 2.0, 0.5);
    const EDGE_U: Vec3 = Vec3::new(1.5, 0.0, 0.3);
    const EDGE_V: Vec3 = Vec3::new(0.4, 0.0, 1.2);

    fn towards(p: Vec3, a: f32, b: f32) -> Vec3 {
        (CORNER + a * EDGE_U + b * EDGE_V - p).normalize()
    }

    #[test]
    fn rect_hit_finds_the_point_a_direction_was_aimed_at() {
        // The front faces -y (edge_u x edge_v), so points below see it.
        assert!(EDGE_U.cross(EDGE_V).y < 0.0);
        let ln = EDGE_U.cross(EDGE_V).normalize();
        for (i, p) in [
            Vec3::ZERO,
            Vec3::new(3.0, -1.0, 2.0),
            Vec3::new(1.2, 1.9, 1.0),
        ]
        .into_iter()
        .enumerate()
        {
            for (a, b) in [(0.5, 0.5), (0.01, 0.98), (0.99, 0.02), (0.3, 0.7)] {
                let q = CORNER + a * EDGE_U + b * EDGE_V;
                let wi = towards(p, a, b);
                let hit = rect_hit(p, wi, CORNER, EDGE_U, EDGE_V)
                    .unwrap_or_else(|| panic!("point {i}, ({a}, {b}): missed"));
                assert!((hit.q - q).length() < 1e-5, "point {i}: {} vs {q}", hit.q);
                assert!((hit.d2 - (q - p).length_squared()).abs() < 1e-4 * hit.d2);
                assert!((hit.cos_l + ln.dot(wi)).abs() < 1e-6 && hit.cos_l > 0.0);
                assert_eq!(hit.wi, wi);
            }
        }
    }

    #[test]
    fn rect_hit_misses_outside_the_edges_behind_and_on_the_back() {
        let p = Vec3::new(1.5, 0.0, 1.0);
        for (a, b) in [
            (1.02, 0.5),
            (-0.02, 0.5),
            (0.5, 1.02),
            (0.5, -0.02),
            (1.1, 1.1),
        ] {
            assert!(rect_hit(p, towards(p, a, b), CORNER, EDGE_U, EDGE_V).is_none());
        }
        // Looking away from it, and from above (its back).
        assert!(rect_hit(p, -towards(p, 0.5, 0.5), CORNER, EDGE_U, EDGE_V).is_none());
        let above = Vec3::new(1.5, 4.0, 1.0);
        assert!(rect_hit(above, towards(above, 0.5, 0.5), CORNER, EDGE_U, EDGE_V).is_none());
        // Parallel to its plane, and a rectangle without area.
        assert!(rect_hit(p, Vec3::X, CORNER, EDGE_U, EDGE_V).is_none());
        assert!(rect_hit(p, towards(p, 0.5, 0.5), CORNER, EDGE_U, EDGE_U).is_none());
    }
}
