//! The integrators: how the light arriving along a camera ray is gathered at the surfaces it
//! meets. [`direct`] takes the lights' light at the first surface (and through mirrors and
//! glass); [`path`] adds the light of bounces, path tracing. Both follow mirrors and
//! transparent surfaces the same way.

pub(super) mod direct;
pub mod path;
mod plain;
pub(in crate::render) mod plain_x86;

pub(in crate::render) use plain_x86::level as plain_level;

use glam::Vec3;

use super::surface::{Surface, beer_lambert, reflect, transmit};
use super::{RayCounts, Tracer};
use crate::bvh::Hit;
use crate::geometry::{Ray, offset_ray_origin};

/// A ray a surface passes light on from ([`Tracer::onward`]).
#[derive(Clone, Copy, Debug)]
pub(in crate::render) struct Continuation {
    /// Which way the surface passes it on.
    pub(in crate::render) way: Onward,
    /// The new ray.
    pub(in crate::render) ray: Ray,
    /// What the light found along it is multiplied by.
    pub(in crate::render) tint: Vec3,
}

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

    /// The rays the surface `s` (met by `ray`, of opacity `alpha`, seen from `wo`) passes
    /// light on from, in the order both integrators follow them: first its mirror reflection
    /// (where the plan traces reflections, the surface mirrors and the reflection leaves above
    /// it), then straight through it (where it is not opaque). Each comes with the tint the
    /// light it brings is multiplied by; the rays are counted.
    #[inline]
    pub(in crate::render) fn onward(
        &self,
        ray: &Ray,
        s: &Surface,
        alpha: f32,
        wo: Vec3,
        counts: &mut RayCounts,
    ) -> [Option<Continuation>; 2] {
        let mut mirror = None;
        if self.plan.reflections && s.is_mirror() {
            let r = reflect(ray.dir, s.n());
            if r.dot(s.ng) > 0.0 {
                counts.reflection += 1;
                mirror = Some(Continuation {
                    way: Onward::Mirror,
                    ray: Ray::new(s.origin, r),
                    tint: alpha * s.mirror_tint(wo),
                });
            }
        }
        let mut through = None;
        if alpha < 1.0 {
            counts.transmission += 1;
            let (dir, side) = transmit(ray.dir, s);
            through = Some(Continuation {
                way: Onward::Through,
                ray: Ray::new(offset_ray_origin(s.p, s.p_err, side), dir),
                tint: s.material.transmission(alpha, s.bsdf.diffuse),
            });
        }
        [mirror, through]
    }

    /// The absorption inside a closed transparent mesh that light arriving along `ray` at `s`
    /// (met at `hit`) went through: the segment just travelled ran inside the mesh when the
    /// ray is leaving it (Beer-Lambert), and is one otherwise.
    #[inline]
    pub(in crate::render) fn absorption(&self, s: &Surface, ray: &Ray, hit: &Hit) -> Vec3 {
        let m = s.material;
        if self.plan.absorption && !s.entering && m.is_transparent() {
            beer_lambert(m.absorption, hit.t * ray.dir.length())
        } else {
            Vec3::ONE
        }
    }
}
