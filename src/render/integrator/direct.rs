//! The `direct` integrator: at the surface a camera ray meets, the light of the scene's lights
//! and emissive triangles reflected towards the camera, shadows included; mirrors and
//! transparent surfaces followed up to the depth limit.

use glam::Vec3;

use crate::bvh::Hit;
use crate::geometry::Ray;
use crate::render::RayCounts;
use crate::render::Tracer;
use crate::render::bsdf::{Bsdf, Sample};
use crate::render::light::RectLight;
use crate::render::light::power;
use crate::render::surface::Surface;
use crate::sampling::PathSampler;
use crate::scene::Light;

impl Tracer<'_> {
    pub(in crate::render) fn trace(
        &self,
        ray: &Ray,
        depth: u32,
        rng: &mut PathSampler,
        counts: &mut RayCounts,
    ) -> Vec3 {
        let hit = self.bvh.intersect(ray, f32::INFINITY);
        self.shade(ray, hit, depth, rng, counts)
    }

    /// Radiance along `ray` given its closest hit.
    pub(in crate::render) fn shade(
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
        let (s, alpha, wo) = self.vertex(ray, &hit);
        let mut l = alpha * (s.emission + self.direct(&s, wo, rng, counts));
        if depth < self.max_depth {
            for c in self
                .onward(ray, &s, alpha, wo, counts)
                .into_iter()
                .flatten()
            {
                l += c.tint * self.trace(&c.ray, depth + 1, rng, counts);
            }
        }
        l * self.absorption(&s, ray, &hit)
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
    pub(in crate::render) fn direct(
        &self,
        s: &Surface,
        wo: Vec3,
        rng: &mut PathSampler,
        counts: &mut RayCounts,
    ) -> Vec3 {
        let m = s.material;
        if !m.reflects() {
            return Vec3::ZERO;
        }
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
            let Some(rect) = RectLight::of(light, |n| self.capped_samples(n)) else {
                if let Some(r) = self.point_light(s, wo, light) {
                    sum += self.lit(r, counts);
                }
                continue;
            };
            let n = rect.samples as f32;
            let m = by_bsdf as f32;
            self.rect_light(
                s,
                wo,
                &rect,
                rng,
                |sample, _, area| {
                    if by_bsdf == 0 {
                        return 1.0;
                    }
                    let p_light = sample.d2 / (sample.cos_l * area);
                    power(n, p_light, m * bsdf.pdf(sample.wi, wo))
                },
                |r| sum += self.lit(r, counts),
            );
        }
        if let Some(e) = self.emissive_sample(s, wo, rng) {
            let r = e.shadow;
            let (pass, crossed) = self.shadow_through(r.origin, r.to, r.t_max, counts);
            // Where the lobes' directions could not have found the point, its sample counts
            // alone.
            let w = if by_bsdf == 0 || crossed {
                1.0
            } else {
                power(1.0, e.p_light, by_bsdf as f32 * bsdf.pdf(e.wi, wo))
            };
            sum += r.light * pass * w;
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
    pub(in crate::render) fn lights_by_bsdf(
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
            let mut l = Vec3::ZERO;
            self.rects_along(
                s,
                wi,
                pdf,
                count,
                |_, samples| Some(self.capped_samples(samples).max(1)),
                |r| l += self.lit(r, counts),
            );
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
}
