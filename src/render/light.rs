//! The lights both integrators sample: point, spot and rectangle lights, and the emissive
//! triangles no rectangle light stands for ([`LightSet`]), each sampled with its shadow ray
//! (through transparent surfaces where the plan says so); the power heuristic that weighs
//! light samples against a bounce's directions.
//!
//! A rectangle light and emissive triangles lying inside it (the Cornell box's ceiling light:
//! the quad the camera sees, and the light that lights the room) are one light: its samples
//! and a bounce that hits its triangles are weighted against each other; when the triangles do
//! not cover the whole rectangle, bounces that hit them add nothing (the samples count it all).

use std::collections::HashMap;

use glam::{Vec2, Vec3};

use super::surface::{Surface, barycentric, beer_lambert, brdf, textured};
use super::{RayCounts, Tracer};
use crate::bvh::Hit;
use crate::geometry::Ray;
use crate::sampling::PathSampler;
use crate::scene::{Light, Scene, face_normal};

/// What stands for an emissive triangle when a bounce hits it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Owner {
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
    pub(super) tris: Vec<u32>,
    /// Running sum of their areas (the last is `area`).
    pub(super) cdf: Vec<f32>,
    /// Their total area.
    pub(super) area: f32,
    /// Every emissive triangle with area: what a bounce that hits it is weighted against.
    pub(super) owner: HashMap<u32, Owner>,
    /// Per scene light: true when emissive triangles cover it, so bounces find it.
    pub(super) visible: Vec<bool>,
    /// True when some rectangle light has no triangles covering it.
    pub(super) hidden_rects: bool,
}

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
        // The scene's own triangles, then those of each placement whose mesh has an emissive
        // one (a mesh placed many times without any is not walked through once per placement).
        let own = scene.mesh.triangles.len() as u32;
        let placed = &scene.instances;
        let glowing: Vec<bool> = placed
            .meshes
            .iter()
            .map(|m| m.material_ids.iter().any(|&id| emissive[id as usize]))
            .collect();
        let prims = (0..own).chain(
            placed
                .placements()
                .iter()
                .enumerate()
                .filter(|(_, p)| glowing[p.mesh as usize])
                .flat_map(|(i, p)| {
                    let first = own + placed.first_triangle(i);
                    first..first + placed.meshes[p.mesh as usize].triangles.len() as u32
                }),
        );
        for prim in prims {
            if !emissive[scene.material_id(prim) as usize] {
                continue;
            }
            let tri = &scene.triangle(prim);
            let area = 0.5 * (tri[1] - tri[0]).cross(tri[2] - tri[0]).length();
            if !(area > 0.0 && area.is_finite()) {
                continue;
            }
            let rect = scene
                .lights
                .iter()
                .position(|l| l.holds_triangle(tri))
                .map(|i| i as u32);
            let owner = match rect {
                Some(i) => {
                    covered[i as usize] += area;
                    Owner::Rect(i)
                }
                None => {
                    set.area += area;
                    set.tris.push(prim);
                    set.cdf.push(set.area);
                    Owner::Set
                }
            };
            set.owner.insert(prim, owner);
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

/// A light sample waiting on its shadow ray: the segment from `origin` to `origin + to *
/// t_max`, and the light the sample brings when nothing on it blocks the light. The `direct`
/// integrator traces it at once ([`Tracer::lit`]); the `path` integrator queues the samples of a
/// batch of paths and traces them together.
#[derive(Clone, Copy, Debug)]
pub(in crate::render) struct ShadowRay {
    /// Where the shadow ray starts (the surface's offset origin).
    pub(in crate::render) origin: Vec3,
    /// Towards the light's point: the ray's direction, unnormalised.
    pub(in crate::render) to: Vec3,
    /// Where along `to` it stops (just short of the light, so that its own quad does not
    /// shadow it).
    pub(in crate::render) t_max: f32,
    /// The light reflected towards the viewer when the segment is clear.
    pub(in crate::render) light: Vec3,
}

/// One light sample of the emissive triangles ([`Tracer::emissive_sample`]).
pub(super) struct EmissiveSample {
    /// Its shadow ray, with the light reflected towards the viewer before any weight.
    pub(super) shadow: ShadowRay,
    /// The sample's density over solid angle at the surface.
    pub(super) p_light: f32,
    /// Unit direction from the surface to the sampled point.
    pub(super) wi: Vec3,
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

impl RectLight {
    /// `light` as a rectangle light estimated with `samples(n)` samples, `n` its own count;
    /// `None` for a point or spot light.
    pub(super) fn of(light: &Light, samples: impl FnOnce(u32) -> u32) -> Option<Self> {
        let Light::Rect {
            corner,
            edge_u,
            edge_v,
            color,
            intensity,
            samples: n,
        } = *light
        else {
            return None;
        };
        Some(Self {
            corner,
            edge_u,
            edge_v,
            color,
            intensity,
            samples: samples(n),
        })
    }
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
/// from the surface point `p` (shading normal `n`, geometric normal `ng`), or `None` when it
/// lies behind the surface or shows the surface its back.
#[inline]
pub(super) fn rect_sample(
    (p, n, ng): (Vec3, Vec3, Vec3),
    corner: Vec3,
    edge_u: Vec3,
    edge_v: Vec3,
    ln: Vec3,
    u: glam::Vec2,
) -> Option<RectSample> {
    let q = corner + u.x * edge_u + u.y * edge_v;
    let to = q - p;
    let d2 = to.length_squared();
    let wi = to / d2.sqrt();
    let cos_l = -ln.dot(wi);
    if n.dot(wi) <= 0.0 || cos_l <= 0.0 || ng.dot(to) <= 0.0 {
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

impl Tracer<'_> {
    /// The rectangle lights that the direction `wi` from `s` meets on their front, each as a
    /// shadow ray with its radiance weighted against the light's own samples by the power
    /// heuristic (given to `out`): `wi` is one of `count` directions drawn with density `pdf`,
    /// and `light_samples(i, samples)` says how many samples rectangle light `i` (of
    /// `samples`) takes here, or `None` to leave it out. Lights do not shadow each other, as
    /// with their samples: a direction counts every rectangle it meets.
    pub(super) fn rects_along(
        &self,
        s: &Surface,
        wi: Vec3,
        pdf: f32,
        count: u32,
        light_samples: impl Fn(usize, u32) -> Option<u32>,
        mut out: impl FnMut(ShadowRay),
    ) {
        for (i, light) in self.scene.lights.iter().enumerate() {
            let Some(rect) = RectLight::of(light, |n| n) else {
                continue;
            };
            let Some(n) = light_samples(i, rect.samples) else {
                continue;
            };
            let Some(hit) = rect_hit(s.p, wi, rect.corner, rect.edge_u, rect.edge_v) else {
                continue;
            };
            let area = rect.edge_u.cross(rect.edge_v).length();
            let p_light = hit.d2 / (hit.cos_l * area);
            let w = power(count as f32, pdf, n as f32 * p_light);
            if w == 0.0 {
                continue;
            }
            out(ShadowRay {
                origin: s.origin,
                to: hit.q - s.origin,
                t_max: 1.0 - 1e-4,
                light: rect.color * rect.intensity * w,
            });
        }
    }

    /// Light the point or spot light `light` sends to `s` and `s` reflects towards `wo`, with
    /// its shadow ray (none from behind the surface, and for a rectangle light).
    pub(super) fn point_light(&self, s: &Surface, wo: Vec3, light: &Light) -> Option<ShadowRay> {
        let (position, intensity) = light.point_towards(s.p)?;
        // The light's direction and distance from the surface point itself; only the shadow
        // ray starts from the offset origin.
        let to = position - s.p;
        let d2 = to.length_squared();
        let wi = to / d2.sqrt();
        if s.n().dot(wi) <= 0.0 || s.ng.dot(to) <= 0.0 {
            return None;
        }
        let origin = s.origin;
        Some(ShadowRay {
            origin,
            to: position - origin,
            t_max: 1.0,
            light: brdf(s, wi, wo) * s.n().dot(wi) * intensity / d2,
        })
    }

    /// Light the rectangle light `rect` sends to `s` and `s` reflects towards `wo`, from
    /// `rect.samples` samples of it, each given to `out` with its shadow ray (stopping just
    /// short of the light, so that its own quad does not shadow it) and its share of the
    /// estimate. Each sample's term is scaled by `weight(sample, cos, area)` (`cos` at the
    /// surface, `area` the light's): the path tracer's multiple-importance weight, 1 for direct
    /// light alone; a sample weighted 0 casts no shadow ray.
    pub(super) fn rect_light(
        &self,
        s: &Surface,
        wo: Vec3,
        rect: &RectLight,
        rng: &mut PathSampler,
        weight: impl Fn(&RectSample, f32, f32) -> f32,
        mut out: impl FnMut(ShadowRay),
    ) {
        let RectLight {
            corner,
            edge_u,
            edge_v,
            ..
        } = *rect;
        let n = rect.samples;
        let origin = s.origin;
        let normal = edge_u.cross(edge_v);
        let area = normal.length();
        let ln = normal / area;
        let scale = rect.color * rect.intensity / n as f32;
        for _ in 0..n {
            let at = (s.p, s.n(), s.ng);
            let Some(sample) = rect_sample(at, corner, edge_u, edge_v, ln, rng.next_2d()) else {
                continue;
            };
            let cos = s.n().dot(sample.wi);
            let w = weight(&sample, cos, area);
            if w == 0.0 {
                continue;
            }
            let RectSample { q, wi, d2, cos_l } = sample;
            out(ShadowRay {
                origin,
                to: q - origin,
                t_max: 1.0 - 1e-4,
                light: brdf(s, wi, wo) * cos * cos_l * area / d2 * w * scale,
            });
        }
    }

    /// A rectangle light's `samples` after the plan's cap.
    pub(super) fn capped_samples(&self, samples: u32) -> u32 {
        self.plan
            .max_light_samples
            .map_or(samples, |cap| samples.min(cap.max(1)))
    }

    /// The light of a light sample that passes its shadow ray, traced now.
    pub(super) fn lit(&self, r: ShadowRay, counts: &mut RayCounts) -> Vec3 {
        r.light * self.shadow(r.origin, r.to, r.t_max, counts)
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
                let tri = &scene.triangle(prim);
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
                let id = scene.material_id(prim);
                let entering = face_normal(&scene.triangle(prim)).dot(to) < 0.0;
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

    /// One light sample of the emissive triangles no rectangle light stands for (a triangle
    /// chosen by area, a point uniform on it), with its shadow ray and the light `s` reflects
    /// towards `wo` from it, unweighted. `None` when there are none, or the point lies behind
    /// the surface.
    pub(super) fn emissive_sample(
        &self,
        s: &Surface,
        wo: Vec3,
        rng: &mut PathSampler,
    ) -> Option<EmissiveSample> {
        if self.lights.tris.is_empty() {
            return None;
        }
        let (prim, u) = self.lights.pick(rng.next_2d());
        let tri = &self.scene.triangle(prim);
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
        let le = self.look(prim, b1, b2).emission;
        Some(EmissiveSample {
            shadow: ShadowRay {
                origin: s.origin,
                to: q - s.origin,
                t_max: 1.0 - 1e-4,
                light: brdf(s, wi, wo) * cos * le / p_light,
            },
            p_light,
            wi,
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
        let tri = &self.scene.triangle(hit.prim);
        let cos_l = face_normal(tri).dot(wi).abs();
        if cos_l <= 0.0 {
            return Vec3::ZERO;
        }
        let d = (s.p - (s.origin + hit.t * wi)).length();
        let p_light = d * d / (cos_l * self.lights.area);
        let le = self.look(hit.prim, hit.u, hit.v).emission;
        le * power(count as f32, pdf, p_light)
    }
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
