//! The trees a scene's rays are traced through: one [`Bvh`] over its triangles when nothing
//! in it is placed more than once, else two levels ([`TwoLevel`]): the scene's own triangles
//! as one instance and each mesh placed many times once, under a top level over the
//! placements. Either way a hit names the scene's triangle number ([`crate::scene::Scene`]:
//! its own triangles first, then each placement's), so shading reads the same triangle
//! whichever was built.

use std::sync::Arc;

use glam::{Affine3A, Vec3};

use super::{BuildOptions, Bvh, Hit, Instance, InstanceError, TwoLevel};
use crate::geometry::{Aabb, Ray};
use crate::scene::Scene;

/// A scene's trees, owned.
#[derive(Clone, Debug)]
pub enum Accel {
    /// One tree over all the scene's triangles.
    Flat(Bvh),
    /// Two levels: the scene's own triangles (when it has any) as instance 0, then every
    /// placement of [`Scene::instances`].
    TwoLevel(TwoLevel),
}

/// A scene's trees, borrowed: what the renderer traces through.
#[derive(Clone, Copy, Debug)]
pub enum Tree<'a> {
    /// One tree over all the scene's triangles.
    Flat(&'a Bvh),
    /// Two levels (see [`Accel::TwoLevel`]).
    TwoLevel(&'a TwoLevel),
}

impl<'a> From<&'a Bvh> for Tree<'a> {
    fn from(b: &'a Bvh) -> Self {
        Tree::Flat(b)
    }
}

impl<'a> From<&'a TwoLevel> for Tree<'a> {
    fn from(t: &'a TwoLevel) -> Self {
        Tree::TwoLevel(t)
    }
}

impl<'a> From<&'a Accel> for Tree<'a> {
    fn from(a: &'a Accel) -> Self {
        match a {
            Accel::Flat(b) => Tree::Flat(b),
            Accel::TwoLevel(t) => Tree::TwoLevel(t),
        }
    }
}

impl Accel {
    /// The trees of `scene`: one BVH when it places no mesh more than once, else a BVH per
    /// mesh (the scene's own triangles one of them) and a top level over the placements.
    pub fn for_scene(scene: &Scene, options: &BuildOptions) -> Result<Accel, InstanceError> {
        if scene.instances.is_empty() {
            return Ok(Accel::Flat(Bvh::build(&scene.mesh.triangles, options)));
        }
        let own = !scene.mesh.triangles.is_empty();
        let mut meshes = Vec::with_capacity(scene.instances.meshes.len() + own as usize);
        if own {
            meshes.push(Arc::new(Bvh::build(&scene.mesh.triangles, options)));
        }
        for m in &scene.instances.meshes {
            meshes.push(Arc::new(Bvh::build(&m.triangles, options)));
        }
        Self::place(scene, meshes, own)
    }

    /// The two levels of `scene` over the trees `meshes` already built (the scene's own
    /// triangles' first when `own`, then [`Scene::instances`]' meshes'), the top level built
    /// anew: what moving a placement costs.
    pub fn place(scene: &Scene, meshes: Vec<Arc<Bvh>>, own: bool) -> Result<Accel, InstanceError> {
        let shift = own as u32;
        let placements = scene.instances.placements();
        let mut list = Vec::with_capacity(placements.len() + own as usize);
        if own {
            list.push(Instance {
                mesh: 0,
                to_world: Affine3A::IDENTITY,
            });
        }
        list.extend(placements.iter().map(|p| Instance {
            mesh: p.mesh + shift,
            ..*p
        }));
        TwoLevel::new(meshes, &list).map(Accel::TwoLevel)
    }

    /// Borrowed, for tracing.
    pub fn tree(&self) -> Tree<'_> {
        self.into()
    }

    /// The one tree of a scene that places nothing more than once.
    pub fn flat(&self) -> Option<&Bvh> {
        match self {
            Accel::Flat(b) => Some(b),
            Accel::TwoLevel(_) => None,
        }
    }

    /// Wall-clock time of the build, milliseconds: every mesh's tree and the top level.
    pub fn build_ms(&self) -> f64 {
        match self {
            Accel::Flat(b) => b.stats.build_ms,
            Accel::TwoLevel(t) => {
                t.build_ms + t.meshes.iter().map(|m| m.stats.build_ms).sum::<f64>()
            }
        }
    }

    /// Bytes of the trees: every mesh's once, and the placements' top level.
    pub fn bytes(&self) -> usize {
        let tree = |b: &Bvh| b.stats.binary_bytes + b.stats.wide_bytes;
        match self {
            Accel::Flat(b) => tree(b),
            Accel::TwoLevel(t) => t.bytes() + t.meshes.iter().map(|m| tree(m)).sum::<usize>(),
        }
    }
}

impl Tree<'_> {
    /// The closest hit at `0 < t < t_max` (see [`Bvh::intersect`]; two levels:
    /// [`TwoLevel::intersect_global`]).
    #[inline]
    pub fn intersect(&self, ray: &Ray, t_max: f32) -> Option<Hit> {
        match self {
            Tree::Flat(b) => b.intersect(ray, t_max),
            Tree::TwoLevel(t) => t.intersect_global(ray, t_max),
        }
    }

    /// Closest hits of a path tracer's bounces (see [`Bvh::intersect_batch`]).
    pub fn intersect_batch(&self, rays: &[Ray], out: &mut [Option<Hit>]) {
        match self {
            Tree::Flat(b) => b.intersect_batch(rays, out),
            Tree::TwoLevel(t) => {
                assert_eq!(rays.len(), out.len(), "one result per ray");
                for (ray, o) in rays.iter().zip(out) {
                    *o = t.intersect_global(ray, f32::INFINITY);
                }
            }
        }
    }

    /// Closest hits of coherent rays, `out[i]` for `rays[i]` (see [`Bvh::intersect_packet`];
    /// two levels trace them one by one).
    pub fn intersect_packet(&self, rays: &[Ray], t_max: f32, out: &mut [Option<Hit>]) {
        match self {
            Tree::Flat(b) => b.intersect_packet(rays, t_max, out),
            Tree::TwoLevel(t) => {
                assert_eq!(rays.len(), out.len(), "one result per ray");
                for (ray, o) in rays.iter().zip(out) {
                    *o = t.intersect_global(ray, t_max);
                }
            }
        }
    }

    /// Whether anything lies at `0 < t < t_max` along the ray.
    #[inline]
    pub fn occluded(&self, ray: &Ray, t_max: f32) -> bool {
        match self {
            Tree::Flat(b) => b.occluded(ray, t_max),
            Tree::TwoLevel(t) => t.occluded(ray, t_max),
        }
    }

    /// [`Tree::occluded`] of a batch of rays, each with its own `t_max`.
    pub fn occluded_batch(&self, rays: &[(Ray, f32)], out: &mut [bool]) {
        match self {
            Tree::Flat(b) => b.occluded_batch(rays, out),
            Tree::TwoLevel(t) => {
                assert_eq!(rays.len(), out.len(), "one result per ray");
                for ((ray, t_max), o) in rays.iter().zip(out) {
                    *o = t.occluded(ray, *t_max);
                }
            }
        }
    }

    /// Light that passes along the ray up to `t_max` (see [`Bvh::transmittance`]).
    pub fn transmittance(
        &self,
        ray: &Ray,
        t_max: f32,
        mut pass: impl FnMut(u32, f32) -> Vec3,
    ) -> Vec3 {
        match self {
            Tree::Flat(b) => b.transmittance(ray, t_max, pass),
            Tree::TwoLevel(t) => {
                let mut through = Vec3::ONE;
                t.for_each_hit(ray, t_max, |prim, t| {
                    through *= pass(prim, t);
                    through.max_element() > 0.0
                });
                through
            }
        }
    }

    /// The one tree of a scene that places nothing more than once.
    pub fn flat(&self) -> Option<&Bvh> {
        match self {
            Tree::Flat(b) => Some(b),
            Tree::TwoLevel(_) => None,
        }
    }

    /// Box around everything.
    pub fn bounds(&self) -> Aabb {
        match self {
            Tree::Flat(b) => b.bounds(),
            Tree::TwoLevel(t) => t.bounds(),
        }
    }

    /// Whether there is nothing to hit.
    pub fn is_empty(&self) -> bool {
        match self {
            Tree::Flat(b) => b.is_empty(),
            Tree::TwoLevel(t) => t.bounds().is_empty(),
        }
    }
}
