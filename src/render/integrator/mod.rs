//! The integrators: how the light arriving along a camera ray is gathered at the surfaces it
//! meets. [`direct`] takes the lights' light at the first surface (and through mirrors and
//! glass); [`path`] adds the light of bounces, path tracing. Both follow mirrors and
//! transparent surfaces the same way.

pub(super) mod direct;
pub(super) mod path;

use glam::Vec3;

use super::surface::{Surface, beer_lambert, reflect, transmit};
use super::{RayCounts, Tracer};
use crate::bvh::Hit;
use crate::geometry::{Ray, offset_ray_origin};

/// Which way a surface passes a ray on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(in crate::render) enum Onward {
    /// Reflected by its mirror.
    Mirror,
    /// Straight through it (it is not opaque), refracted by its index.
    Through,
}

impl Tracer<'_> {
    /// A surface vertex both integrators start from: where `ray` met the surface of `hit`, its
    /// opacity as the plan treats it (1 where transmission is off), and the unit direction back
    /// along the ray.
    pub(in crate::render) fn vertex(&self, ray: &Ray, hit: &Hit) -> (Surface<'_>, f32, Vec3) {
        let s = self.surface(ray, hit.prim, hit.u, hit.v);
        let alpha = if self.plan.transmission {
            s.opacity
        } else {
            1.0
        };
        (s, alpha, -ray.dir.normalize())
    }

    /// Adds to `l` the light the surface `s` (met by `ray`, of opacity `alpha`, seen from
    /// `wo`) passes on from further along: first along its mirror reflection (where the plan
    /// traces reflections, the surface mirrors and the reflection leaves above it), then
    /// through it (where it is not opaque). Each is `along(way, ray, tint)`, the radiance the
    /// integrator finds along the new ray, times the tint; the rays are counted.
    #[allow(clippy::too_many_arguments)]
    pub(in crate::render) fn pass_on(
        &self,
        ray: &Ray,
        s: &Surface,
        alpha: f32,
        wo: Vec3,
        l: &mut Vec3,
        counts: &mut RayCounts,
        mut along: impl FnMut(Onward, &Ray, Vec3, &mut RayCounts) -> Vec3,
    ) {
        if self.plan.reflections && s.is_mirror() {
            let r = reflect(ray.dir, s.n());
            if r.dot(s.ng) > 0.0 {
                counts.reflection += 1;
                let bounce = Ray::new(s.origin, r);
                let tint = alpha * s.mirror_tint(wo);
                *l += tint * along(Onward::Mirror, &bounce, tint, counts);
            }
        }
        if alpha < 1.0 {
            counts.transmission += 1;
            let (dir, side) = transmit(ray.dir, s);
            let through = Ray::new(offset_ray_origin(s.p, s.p_err, side), dir);
            let tint = s.material.transmission(alpha, s.bsdf.diffuse);
            *l += tint * along(Onward::Through, &through, tint, counts);
        }
    }

    /// Dims `l` by the absorption inside a closed transparent mesh when `ray`, which met `s`
    /// at `hit`, was leaving it (the segment just travelled ran inside: Beer-Lambert).
    pub(in crate::render) fn absorb(&self, s: &Surface, ray: &Ray, hit: &Hit, l: &mut Vec3) {
        let m = s.material;
        if self.plan.absorption && !s.entering && m.is_transparent() {
            *l *= beer_lambert(m.absorption, hit.t * ray.dir.length());
        }
    }
}
