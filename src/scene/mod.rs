//! Scenes: triangles with per-triangle materials, lights, a camera and an environment.
//!
//! Loaded from a scene file (TOML, [`mod@file`]), a bare OBJ with its MTL ([`obj`]), a PLY
//! ([`ply`]) or a glTF 2.0 file ([`gltf`]); or made in code ([`crate::geometry::shapes`], [`Scene::cornell_box`]). Every loader reports errors
//! as `file:line: message` where a line is known.

mod camera;
pub mod check;
pub mod file;
pub mod format;
pub mod gltf;
pub(crate) mod instances;
mod light;
mod material;
mod mesh;
mod meshopt;
pub mod normals;
pub mod obj;
pub mod objects;
pub mod pbr;
pub mod ply;
pub mod tangents;
pub mod texture;

use std::path::Path;

use anyhow::{Context, Result, bail};
use glam::Vec3;

use crate::geometry::Aabb;

pub use camera::{Camera, Environment};
pub use format::{Format, MeshFile};
pub use instances::{Instances, PlaceError, placed_bounds, placing};
pub use light::{Light, spot_falloff};
pub use material::{AlphaMode, Material};
pub use mesh::{Mesh, face_normal, local_frame};
pub use normals::NormalRule;
pub use objects::{Object, Place, Runs};
pub use texture::{Texture, Wrap};

/// How light is gathered at the surfaces the camera sees.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Integrator {
    /// Direct light only: emission, light from the light sources with hard (or transparent)
    /// shadows, and mirror and transparent surfaces followed.
    #[default]
    Direct,
    /// Unidirectional path tracing: bounces sampled from the surfaces' lobes carry indirect light,
    /// next-event estimation on the lights is combined with emission found by bounces by
    /// multiple importance sampling, Russian roulette ends long paths.
    Path,
}

impl std::fmt::Display for Integrator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Integrator::Direct => "direct",
            Integrator::Path => "path",
        })
    }
}

impl std::str::FromStr for Integrator {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "direct" => Ok(Integrator::Direct),
            "path" => Ok(Integrator::Path),
            other => Err(format!(
                "unknown integrator `{other}` (expected direct or path)"
            )),
        }
    }
}

/// Everything a render needs.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    /// Short name for messages and reports (the file stem).
    pub name: String,
    /// The triangles placed once, of all meshes in file order: triangles `0..n` of the
    /// scene.
    pub mesh: Mesh,
    /// Meshes placed more than once (a glTF mesh many nodes use, a scene file's `grid`), held
    /// once each: triangles `n..` of the scene, after [`Scene::mesh`]'s.
    pub instances: Instances,
    /// The objects the triangles make (what the files name): runs of [`Scene::mesh`]'s
    /// triangles and placements of [`Scene::instances`]' meshes, every triangle in one.
    pub objects: Vec<Object>,
    /// Materials the triangles refer to.
    pub materials: Vec<Material>,
    /// Light sources.
    pub lights: Vec<Light>,
    /// The camera.
    pub camera: Camera,
    /// What escaping rays see.
    pub environment: Environment,
    /// How light is gathered (scene files choose with `[render] integrator`).
    pub integrator: Integrator,
    /// GGX lobes put back the light lost between their microfacets (scene files turn it off
    /// with `[render] energy_compensation = false`).
    pub energy_compensation: bool,
    /// Problems found while loading that did not stop it (a missing MTL file, say).
    pub warnings: Vec<String>,
    /// How long the scene's glTF animations run, in seconds (their last keyframe); `None`
    /// when it has none. [`Scene::load_at`] plays them to an instant.
    pub animation: Option<f32>,
}

/// The view of a bare mesh of bounds `b`: the canonical camera, and a point light above and
/// behind it.
fn default_view(b: &Aabb) -> (Camera, Light) {
    let camera = Camera::canonical(b);
    let r = (camera.position - camera.look_at).length() / 2.2;
    let position = camera.position + Vec3::new(r, 2.0 * r, 0.0);
    let d2 = (position - camera.look_at).length_squared();
    let light = Light::Point {
        position,
        color: Vec3::ONE,
        intensity: std::f32::consts::PI * d2,
    };
    (camera, light)
}

impl Scene {
    /// Loads a scene file (`.toml`), an OBJ (`.obj`, with its MTL), a PLY (`.ply`) or a glTF
    /// (`.gltf`, `.glb`).
    pub fn load(path: &Path) -> Result<Scene> {
        Self::load_at(path, None)
    }

    /// [`Scene::load`], with the glTF animations (of a glTF, or of a scene file's glTF meshes)
    /// played to `time` in seconds when one is given; without, as the file places its nodes.
    pub fn load_at(path: &Path, time: Option<f64>) -> Result<Scene> {
        match Format::of(path) {
            Some(Format::SceneFile) => file::load_at(path, time),
            Some(_) => read_file(path).and_then(|bytes| {
                let read = |p: &Path| read_file(p);
                let d = format::load_mesh(path, &bytes, &read, None, time)?;
                // A file without a camera is framed by its bounds: at rest, when an instant of
                // its animation is asked for, so that every instant is seen from one place.
                let rest = match time {
                    Some(_) if d.camera.is_none() => {
                        let rest = format::load_mesh(path, &bytes, &read, None, None)?.mesh;
                        Some(rest.bounds_around(d.mesh.origin))
                    }
                    _ => None,
                };
                let own_lights = !d.lights.is_empty();
                let mut scene = gltf::scene_of(name_of(path), d)?;
                if let Some(b) = rest {
                    let (camera, light) = default_view(&b);
                    scene.camera = camera;
                    if !own_lights {
                        scene.lights = vec![light];
                    }
                }
                Ok(scene)
            }),
            None => bail!(
                "{}: unknown file type (expected {})",
                path.display(),
                Format::expected(false)
            ),
        }
        .map_err(|e| {
            // The loaders' messages name the file already: it is said once.
            let file = path.display().to_string();
            if format!("{e:#}").contains(&file) {
                e.context("cannot load scene")
            } else {
                e.context(format!("cannot load scene {file}"))
            }
        })
    }

    /// A scene for a bare mesh: the canonical camera, a point light above and behind the
    /// camera, and the procedural sky.
    pub fn from_mesh(name: String, mesh: Mesh, materials: Vec<Material>) -> Scene {
        let (camera, light) = default_view(&mesh.bounds());
        let materials = if materials.is_empty() {
            vec![Material::default()]
        } else {
            materials
        };
        Scene {
            objects: objects::list(&Runs::default(), mesh.triangles.len(), &[], &name),
            name,
            mesh,
            materials,
            lights: vec![light],
            camera,
            environment: Environment::Sky {
                intensity: 0.3,
                rotation_deg: 0.0,
            },
            integrator: Integrator::Direct,
            energy_compensation: true,
            warnings: Vec::new(),
            animation: None,
            instances: Instances::default(),
        }
    }

    /// The project's Cornell box (32 triangles: five walls, the ceiling light, two blocks),
    /// from the scene and model files built into the binary.
    pub fn cornell_box() -> Scene {
        file::load_embedded_cornell_box()
    }

    /// Number of triangles, each placement of a mesh placed many times counted.
    pub fn triangle_count(&self) -> usize {
        self.mesh.triangles.len() + self.instances.triangle_count() as usize
    }

    /// The material of triangle `prim`.
    #[inline]
    pub fn material_of(&self, prim: u32) -> &Material {
        &self.materials[self.material_id(prim) as usize]
    }

    /// The index in [`Scene::materials`] of triangle `prim`'s material.
    #[inline]
    pub fn material_id(&self, prim: u32) -> u32 {
        match self.mesh.material_ids.get(prim as usize) {
            Some(&id) => id,
            None => self.instances.material_id(self.placed(prim)),
        }
    }

    /// The number among the placed triangles of scene triangle `prim` (one past the scene
    /// mesh's own).
    #[inline]
    fn placed(&self, prim: u32) -> u32 {
        prim - self.mesh.triangles.len() as u32
    }

    /// Corners of triangle `prim`, in the scene's frame.
    #[inline]
    pub fn triangle(&self, prim: u32) -> [Vec3; 3] {
        match self.mesh.triangles.get(prim as usize) {
            Some(t) => *t,
            None => self.instances.triangle(self.placed(prim)),
        }
    }

    /// Shading normals of triangle `prim`'s corners, in the scene's frame.
    #[inline]
    pub fn normals(&self, prim: u32) -> [Vec3; 3] {
        match self.mesh.normals.get(prim as usize) {
            Some(n) => *n,
            None => self.instances.normals(self.placed(prim)),
        }
    }

    /// The texture coordinate of set `set` at barycentric `(u, v)` of triangle `prim` (see
    /// [`Mesh::uv_at`]).
    #[inline]
    pub fn uv_at(&self, set: u8, prim: u32, u: f32, v: f32) -> glam::Vec2 {
        if (prim as usize) < self.mesh.triangles.len() {
            self.mesh.uv_at(set, prim, u, v)
        } else {
            self.instances.uv_at(set, self.placed(prim), u, v)
        }
    }

    /// The tangent at barycentric `(u, v)` of triangle `prim` (see [`Mesh::tangent_at`]).
    #[inline]
    pub fn tangent_at(&self, prim: u32, u: f32, v: f32) -> glam::Vec4 {
        if (prim as usize) < self.mesh.triangles.len() {
            self.mesh.tangent_at(prim, u, v)
        } else {
            self.instances.tangent_at(self.placed(prim), u, v)
        }
    }

    /// Box around every triangle, placed ones included, in the scene's frame.
    pub fn bounds(&self) -> Aabb {
        self.mesh.bounds().union(&self.instances.bounds())
    }

    /// The same scene with every placement's triangles copied into [`Scene::mesh`], in the
    /// order they are numbered, each as [`Scene::triangle`] and the rest read it: the
    /// picture of the same samples differs only where the rays' hits differ in their last
    /// bits (a placed mesh is traced in its own frame).
    pub fn flattened(&self) -> Scene {
        let mut scene = self.clone();
        scene.instances = Instances::default();
        let origin = scene.mesh.origin;
        let own = self.mesh.triangles.len() as u32;
        for i in 0..self.instances.placements().len() {
            // In the scene's frame already: appended without moving a vertex.
            scene.mesh.append(self.instances.placed_mesh(i, origin), 0);
        }
        for o in &mut scene.objects {
            if let Place::Placed(p) = o.place {
                let first = own + self.instances.first_triangle(p);
                let count = self.instances.meshes[self.instances.placements()[p].mesh as usize]
                    .triangles
                    .len() as u32;
                o.place = Place::Own { first, count };
            }
        }
        scene
    }
}

/// The file stem, for scene names.
pub fn name_of(path: &Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "scene".into())
}

/// Reads a whole file, naming it in the error.
pub(crate) fn read_file(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).with_context(|| format!("{}: cannot read file", path.display()))
}

/// Splits the byte offset `pos` of `text` into a 1-based line number.
pub(crate) fn line_of(text: &str, pos: usize) -> usize {
    text[..pos.min(text.len())].matches('\n').count() + 1
}
