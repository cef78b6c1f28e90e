//! The tracer: a scene, its BVH, the render plan and the lights, and the radiance a ray
//! carries back through them by the plan's integrator ([`super::integrator`]). What a hit looks
//! like is in [`super::surface`], the lights and shadow rays in [`super::light`].

use glam::Vec3;

use super::environment::EnvironmentMap;
use super::integrator::path::PathBatch;
use super::light::LightSet;
use super::surface::{Look, textured};
use super::{RayCounts, RenderPlan};
use crate::bvh::{Hit, Tree};
use crate::geometry::Ray;
use crate::sampling::PathSampler;
use crate::scene::{Integrator, Scene};

/// What a ray that cannot be traced (zero, NaN or infinite direction or origin) returns:
/// black, never NaN.
pub const FALLBACK: Vec3 = Vec3::ZERO;

/// Traces rays through a scene and returns the radiance they carry back.
pub struct Tracer<'a> {
    /// The scene.
    pub scene: &'a Scene,
    /// Its trees (one BVH, or two levels for a scene that places meshes many times).
    pub bvh: Tree<'a>,
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
    /// Per material, its diffuse colour when the path integrator may take its vertices by the
    /// short path of a plain Lambertian surface (`Tracer::plain_round`): an untextured,
    /// opaque, non-emissive Lambertian lobe and nothing else the plan would look at. Empty
    /// when the scene's lights need more than that path samples (any but rectangle lights, or
    /// emissive triangles sampled on their own).
    pub(super) plain: Vec<Option<Vec3>>,
    /// The vector unit the plain vertices are stepped with (see
    /// `integrator::plain_x86::level`).
    pub(super) plain_level: u8,
}

/// The diffuse colour of `m` (whose look is `look` everywhere) when a path's vertices on it may
/// take the plain Lambertian path: a Lambertian lobe alone (no glossy lobe, sheen or coat), no
/// emission, fully opaque and not transparent, no mirror the plan traces, no normal or height
/// map the plan applies, and something to reflect.
fn plain(m: &crate::scene::Material, look: &Look, plan: &RenderPlan) -> Option<Vec3> {
    let lambertian = matches!(look.gloss, super::bsdf::Gloss::None)
        && !look.sheen.is_some()
        && look.coat.weight <= 0.0;
    let alpha = if plan.transmission { look.opacity } else { 1.0 };
    let flat = !plan.normal_maps || (m.normal_map.is_none() && m.height_map.is_none());
    let mirror = plan.reflections && look.mirror.max_element() > 0.0;
    (lambertian
        && !m.is_emissive()
        && alpha == 1.0
        && !m.is_transparent()
        && !mirror
        && flat
        && m.reflects())
    .then_some(look.diffuse)
}

impl<'a> Tracer<'a> {
    /// A tracer of `scene` with the plan's integrator (finding the emissive triangles both
    /// integrators sample as lights).
    pub fn new(
        scene: &'a Scene,
        bvh: impl Into<Tree<'a>>,
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
        bvh: impl Into<Tree<'a>>,
        plan: RenderPlan,
        max_depth: u32,
        env: &'a EnvironmentMap,
        lights: std::sync::Arc<LightSet>,
    ) -> Self {
        let bvh = bvh.into();
        assert!(
            scene.instances.is_empty() || matches!(bvh, Tree::TwoLevel(_)),
            "a scene that places meshes many times is traced through its two levels (Accel::for_scene)"
        );
        let looks: Vec<Option<Look>> = scene
            .materials
            .iter()
            .map(|m| (m.textures().next().is_none()).then(|| textured(scene, m, 0, 0.0, 0.0)))
            .collect();
        let rects_only = scene
            .lights
            .iter()
            .all(|l| matches!(l, crate::scene::Light::Rect { .. }));
        let plain = if rects_only && lights.tris.is_empty() {
            scene
                .materials
                .iter()
                .zip(&looks)
                .map(|(m, look)| look.as_ref().and_then(|look| plain(m, look, &plan)))
                .collect()
        } else {
            Vec::new()
        };
        Self {
            scene,
            bvh,
            plan,
            max_depth,
            env,
            lights,
            looks,
            plain,
            plain_level: super::integrator::plain_level(),
        }
    }

    /// The look of triangle `prim`'s material at barycentric `(u, v)` ([`textured`]): the one
    /// found at the start when no texture varies it.
    pub(super) fn look(&self, prim: u32, u: f32, v: f32) -> Look {
        let id = self.scene.material_id(prim) as usize;
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
        crate::cpu::with_denormals_flushed(|| self.radiance_from_hit(ray, hit, rng, counts))
    }

    /// [`Tracer::radiance`] of a ray whose closest hit is already known (`hit` is what
    /// `self.bvh.intersect(ray, f32::INFINITY)` gives, as a packet traced it).
    ///
    /// Callers run it inside [`crate::cpu::with_denormals_flushed`], once per
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
            Integrator::Path => self.path(ray, hit, rng, counts),
        }
    }

    /// [`Tracer::radiance_from_hit`] of many rays, `out[k]` for `rays[k]` with its closest hit
    /// `hits[k]` and its random numbers `samplers[k]`; the same radiance, bit for bit. With the
    /// path integrator their paths advance together, their shadow rays and bounces traced in
    /// batches ([`Tracer::paths`]); `batch` is the working space, kept between calls. Called
    /// inside [`crate::cpu::with_denormals_flushed`], as [`Tracer::radiance_from_hit`] is.
    pub fn radiance_batch(
        &self,
        batch: &mut PathBatch,
        rays: &[Ray],
        hits: &[Option<Hit>],
        samplers: &[PathSampler],
        counts: &mut RayCounts,
        out: &mut [Vec3],
    ) {
        assert!(
            rays.len() == hits.len() && rays.len() == samplers.len() && rays.len() == out.len(),
            "one hit, sampler and result per ray"
        );
        let together =
            matches!(self.plan.integrator, Integrator::Path) && rays.iter().all(|r| r.is_valid());
        if together {
            self.paths(batch, rays, hits, samplers, counts, out);
            return;
        }
        for k in 0..rays.len() {
            out[k] = self.radiance_from_hit(&rays[k], hits[k], &mut { samplers[k] }, counts);
        }
    }

    pub(super) fn background(&self, dir: Vec3) -> Vec3 {
        if self.plan.environment {
            self.env.radiance(dir)
        } else {
            Vec3::ZERO
        }
    }
}
