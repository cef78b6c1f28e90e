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
use crate::render::light::{Owner, RectLight, ShadowRay, power};
use crate::render::surface::Surface;
use crate::sampling::PathSampler;
use crate::scene::{Light, face_normal};

/// Bounce depth from which Russian roulette may end a path.
pub(super) const ROULETTE_DEPTH: u32 = 3;

/// Highest survival probability of Russian roulette (some paths always end, so no path runs
/// on forever between mirrors).
pub(super) const MAX_SURVIVAL: f32 = 0.95;

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

/// One path of a batch: the vertex it has reached, its random numbers, the light it has
/// gathered so far and the vertices its mirrors and transparent surfaces left waiting.
pub(super) struct Lane {
    pub(super) v: Vertex,
    pub(super) rng: PathSampler,
    pub(super) l: Vec3,
    /// Empty until a mirror or a transparent surface is met: no allocation on most paths.
    pub(super) pending: Vec<Vertex>,
}

/// The working space of a batch of paths ([`Tracer::paths`]): kept from one batch to the next,
/// so that a render's batches allocate nothing once the first has run.
#[derive(Default)]
pub struct PathBatch {
    lanes: Vec<Lane>,
    /// The paths whose next vertex's hit is known.
    ready: Vec<u32>,
    /// The same, for the next round.
    next: Vec<u32>,
    /// The paths whose bounce waits on its closest hit, their rays and the hits found.
    bouncing: Vec<u32>,
    rays: Vec<Ray>,
    hits: Vec<Option<Hit>>,
    /// The light samples waiting on their shadow rays, the path of each, and what passes.
    shadows: Vec<ShadowRay>,
    owners: Vec<u32>,
    passes: Vec<Vec3>,
    /// The paths whose vertex lies on a plain Lambertian surface ([`Tracer::plain_round`]).
    plain: Vec<u32>,
    /// The shadow rays as the batch query takes them, and its answers.
    shadow_rays: Vec<(Ray, f32)>,
    blocked: Vec<bool>,
}

impl Tracer<'_> {
    /// Radiance along the camera ray `ray`, whose closest hit is `hit`, by path tracing: a
    /// batch of one path ([`Tracer::paths`]).
    pub(in crate::render) fn path(
        &self,
        ray: &Ray,
        hit: Option<Hit>,
        rng: &PathSampler,
        counts: &mut RayCounts,
    ) -> Vec3 {
        let mut out = [Vec3::ZERO];
        self.paths(
            &mut PathBatch::default(),
            std::slice::from_ref(ray),
            &[hit],
            std::slice::from_ref(rng),
            counts,
            &mut out,
        );
        out[0]
    }

    /// Radiance along each camera ray `rays[k]`, whose closest hit is `hits[k]`, by path
    /// tracing with the random numbers of `samplers[k]`, into `out[k]`.
    ///
    /// The paths advance together, a vertex each per round ([`Tracer::path_vertex`]): each
    /// round's light samples queue their shadow rays and its bounces their rays, and both are
    /// traced as batches ([`crate::bvh::Bvh::occluded_batch`],
    /// [`crate::bvh::Bvh::intersect_batch`]) before the next round. A path also carried on by
    /// a mirror or through a transparent surface keeps those vertices on a stack of its own, each
    /// followed to its end after the bounce's, so every path draws its random numbers in the
    /// same order whatever the batch: a path's radiance is the same, bit for bit, in a batch of
    /// any size.
    pub(in crate::render) fn paths(
        &self,
        b: &mut PathBatch,
        rays: &[Ray],
        hits: &[Option<Hit>],
        samplers: &[PathSampler],
        counts: &mut RayCounts,
        out: &mut [Vec3],
    ) {
        debug_assert!(rays.len() == hits.len() && rays.len() == samplers.len());
        b.lanes.clear();
        b.ready.clear();
        for (k, ((ray, hit), rng)) in rays.iter().zip(hits).zip(samplers).enumerate() {
            b.lanes.push(Lane {
                v: Vertex {
                    ray: *ray,
                    hit: *hit,
                    depth: 0,
                    arrival: Arrival::Specular,
                    beta: Vec3::ONE,
                },
                rng: *rng,
                l: Vec3::ZERO,
                pending: Vec::new(),
            });
            b.ready.push(k as u32);
        }
        while !b.ready.is_empty() {
            b.next.clear();
            b.bouncing.clear();
            b.rays.clear();
            b.shadows.clear();
            b.owners.clear();
            b.plain.clear();
            for &k in &b.ready {
                let lane = &mut b.lanes[k as usize];
                if self.plain_at(lane).is_some() {
                    b.plain.push(k);
                    continue;
                }
                let (shadows, owners) = (&mut b.shadows, &mut b.owners);
                let push = |r| {
                    shadows.push(r);
                    owners.push(k);
                };
                let (found, goes_on) =
                    self.path_vertex(&mut lane.v, &mut lane.pending, &mut lane.rng, push, counts);
                lane.l += found;
                if goes_on {
                    b.bouncing.push(k);
                    b.rays.push(lane.v.ray);
                } else if let Some(p) = lane.pending.pop() {
                    lane.v = p;
                    b.next.push(k);
                }
            }
            self.plain_round(
                &mut b.lanes,
                &b.plain,
                (&mut b.shadows, &mut b.owners),
                (&mut b.bouncing, &mut b.rays, &mut b.next),
                counts,
            );
            self.shadow_batch(
                &b.shadows,
                (&mut b.shadow_rays, &mut b.blocked),
                &mut b.passes,
                counts,
            );
            for ((r, &k), pass) in b.shadows.iter().zip(&b.owners).zip(&b.passes) {
                b.lanes[k as usize].l += r.light * *pass;
            }
            b.hits.resize(b.rays.len(), None);
            // Drawn at random: neighbouring paths' bounces take other paths through the tree.
            self.bvh.intersect_batch(&b.rays, &mut b.hits);
            for (&k, hit) in b.bouncing.iter().zip(&b.hits) {
                b.lanes[k as usize].v.hit = *hit;
                b.next.push(k);
            }
            std::mem::swap(&mut b.ready, &mut b.next);
        }
        for (o, lane) in out.iter_mut().zip(&b.lanes) {
            *o = lane.l;
        }
    }

    /// The light that passes each light sample's shadow ray into `passes`: per channel through
    /// transparent surfaces where the plan says so, else all or nothing (the rays traced as one
    /// batch, `rays` and `blocked` its working space).
    fn shadow_batch(
        &self,
        shadows: &[ShadowRay],
        (rays, blocked): (&mut Vec<(Ray, f32)>, &mut Vec<bool>),
        passes: &mut Vec<Vec3>,
        counts: &mut RayCounts,
    ) {
        passes.clear();
        if !self.plan.shadows || self.plan.transparent_shadows {
            passes.extend(
                shadows
                    .iter()
                    .map(|r| self.shadow(r.origin, r.to, r.t_max, counts)),
            );
            return;
        }
        counts.shadow += shadows.len() as u64;
        rays.clear();
        rays.extend(shadows.iter().map(|r| (Ray::new(r.origin, r.to), r.t_max)));
        blocked.resize(shadows.len(), false);
        self.bvh.occluded_batch(rays, blocked);
        passes.extend(
            blocked
                .iter()
                .map(|&b| if b { Vec3::ZERO } else { Vec3::ONE }),
        );
    }

    /// One step of the path integrator: the light the path gathers at `v` (emission found,
    /// next-event estimation) times the path's throughput, and whether its bounce carries it
    /// on. The light samples' shadow rays go to `shadow`, with the light each brings (the
    /// throughput applied) when nothing blocks it. When the bounce carries the path on, `v`
    /// is the vertex it reaches (updated in place, as moving it costs time) with its ray set
    /// and its hit still to be found. The vertices its mirror and transmission carry it on to
    /// are pushed onto `pending` (the one to be met first last).
    pub(in crate::render) fn path_vertex(
        &self,
        v: &mut Vertex,
        pending: &mut Vec<Vertex>,
        rng: &mut PathSampler,
        mut shadow: impl FnMut(ShadowRay),
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
        let scale = beta * alpha;
        let mut scaled = |r: ShadowRay| {
            shadow(ShadowRay {
                light: r.light * scale,
                ..r
            })
        };
        self.lights_at(&s, wo, v.depth, rng, &mut scaled);
        let bounce = self.bounce(&s, wo, v.depth, scale, rng, &mut scaled);
        // Pushed in reverse, so that the mirror's path is met before the transmitted one.
        let onward = if alpha < 1.0 || s.is_mirror() {
            self.onward(ray, &s, alpha, wo, counts)
        } else {
            [None, None]
        };
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
        v.hit = None;
        v.arrival = Arrival::Bounce {
            pdf: b.pdf,
            from: v.depth,
            travelled: 0.0,
        };
        v.depth += 1;
        v.beta = scale * b.weight;
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
                let tri = &self.scene.triangle(hit.prim);
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
    /// emissive triangles, each weighted against the bounce that could find it, given to `out`
    /// with its shadow ray.
    pub(in crate::render) fn lights_at(
        &self,
        s: &Surface,
        wo: Vec3,
        depth: u32,
        rng: &mut PathSampler,
        mut out: impl FnMut(ShadowRay),
    ) {
        let m = s.material;
        if !m.reflects() {
            return;
        }
        let bsdf = s.bsdf();
        // Only the rectangle lights no triangles cover need it.
        let glossy = self.lights.hidden_rects && bsdf.gloss_probability(wo) > 0.0;
        for (i, light) in self.scene.lights.iter().enumerate() {
            let Some(rect) = RectLight::of(light, |n| self.rect_samples(n, depth)) else {
                if let Some(r) = self.point_light(s, wo, light) {
                    out(r);
                }
                continue;
            };
            let n = rect.samples as f32;
            // Bounces find the light when its triangles cover it; on a glossy surface they
            // look for it by its rectangle when they do not.
            let weighted = self.lights.visible[i] || glossy;
            self.rect_light(
                s,
                wo,
                &rect,
                rng,
                |sample, _, area| {
                    if weighted {
                        let p_light = sample.d2 / (sample.cos_l * area);
                        power(n, p_light, bsdf.pdf(sample.wi, wo))
                    } else {
                        1.0
                    }
                },
                &mut out,
            );
        }
        if let Some(e) = self.emissive_sample(s, wo, rng) {
            let w = power(1.0, e.p_light, bsdf.pdf(e.wi, wo));
            out(ShadowRay {
                light: e.shadow.light * w,
                ..e.shadow
            });
        }
    }

    /// The bounce from `s`, sampled from its lobes, unless the path ends here; the rectangle
    /// lights it finds by their rectangles (weighted by the surface's reflectance over the
    /// sampling density) go to `out` with their shadow rays. `beta` is the path's throughput
    /// at `s` (for Russian roulette).
    pub(in crate::render) fn bounce(
        &self,
        s: &Surface,
        wo: Vec3,
        depth: u32,
        beta: Vec3,
        rng: &mut PathSampler,
        mut out: impl FnMut(ShadowRay),
    ) -> Option<Bounce> {
        let m = s.material;
        if !m.reflects() {
            return None;
        }
        let bsdf = s.bsdf();
        // On a glossy surface the bounce also looks for the rectangle lights no triangles
        // cover (which it cannot hit), as `lights_at` weights their samples.
        let glossy = self.lights.hidden_rects && bsdf.gloss_probability(wo) > 0.0;
        let nothing_to_find = self.lights.owner.is_empty() && !self.plan.environment;
        if depth == self.max_depth && nothing_to_find && !glossy {
            // The last bounce only collects emission, and there is none to find.
            return None;
        }
        let u = rng.next_2d();
        let Sample { wi, pdf } = bsdf.sample(wo, u)?;
        let cos = s.n().dot(wi);
        if cos <= 0.0 || wi.dot(s.ng) <= 0.0 || pdf <= 0.0 {
            return None;
        }
        let mut weight = bsdf.eval(wi, wo) * cos / pdf;
        if glossy {
            self.rects_along(
                s,
                wi,
                pdf,
                1,
                |i, samples| (!self.lights.visible[i]).then(|| self.rect_samples(samples, depth)),
                |r| {
                    out(ShadowRay {
                        light: r.light * weight,
                        ..r
                    })
                },
            );
        }
        if depth == self.max_depth && nothing_to_find {
            return None;
        }
        if depth >= ROULETTE_DEPTH {
            let survive = (beta * weight).max_element().min(MAX_SURVIVAL);
            if rng.next_2d().x >= survive {
                return None;
            }
            weight /= survive;
        }
        Some(Bounce { wi, pdf, weight })
    }
}

#[cfg(test)]
mod tests {

    use crate::bvh::{BuildOptions, Bvh};
    use crate::camera::CameraRays;
    use crate::film::Sum;
    use crate::render::{BAND, trace_rows};
    use crate::render::{EnvironmentMap, RenderPlan, RenderSettings, SampleRange, Tracer};
    use crate::scene::{Integrator, Scene};

    /// The image's first band of rows traced with `tracer`.
    fn band(tracer: &Tracer, cam: &CameraRays, settings: &RenderSettings) -> Vec<Sum> {
        let samples = SampleRange {
            sampler: settings.sampler,
            seed: settings.seed,
            first: 0,
            count: settings.spp,
        };
        let mut rows = vec![Sum::ZERO; (cam.width * BAND) as usize];
        trace_rows(tracer, cam, &samples, settings.height / 2, &mut rows);
        rows
    }

    /// The plain Lambertian vertices' step gives the general step's light, bit for bit: the
    /// same pixels with it, at every vector width the CPU runs, and without it (the tracer's
    /// list of plain materials emptied), in scenes where most vertices take it and where some
    /// do not (a mirror, glass).
    #[test]
    fn plain_lambertian_vertices_give_the_general_paths_bits() {
        for path in [
            "assets/scenes/cornell_box.toml",
            "assets/scenes/cornell_mirror_glass.toml",
        ] {
            let mut scene = Scene::load(std::path::Path::new(path)).unwrap();
            scene.integrator = Integrator::Path;
            let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
            let settings = RenderSettings {
                width: 40,
                height: 30,
                spp: 4,
                seed: 3,
                ..RenderSettings::default()
            };
            let plan = RenderPlan::new(&scene, &settings);
            let env = EnvironmentMap::load(&scene.environment, plan.environment).unwrap();
            let mut general = Tracer::new(&scene, &bvh, plan, settings.max_depth, &env);
            general.plain.clear();
            let cam = CameraRays::new(&scene.camera, settings.width, settings.height);
            let b = band(&general, &cam, &settings);
            // Every vector width this CPU runs: the baseline's, AVX2's, AVX-512's.
            for level in crate::render::integrator::plain_x86::levels() {
                let mut fast = Tracer::new(&scene, &bvh, plan, settings.max_depth, &env);
                fast.plain_level = level;
                assert!(
                    fast.plain.iter().any(|d| d.is_some()),
                    "{path}: no plain material, nothing tested"
                );
                let a = band(&fast, &cam, &settings);
                assert!(a.iter().any(|l| *l != Sum::ZERO), "{path}: a black band");
                for (k, (a, b)) in a.iter().zip(&b).enumerate() {
                    assert_eq!(a, b, "{path}, vector level {level}: pixel {k}");
                }
            }
        }
    }
}
