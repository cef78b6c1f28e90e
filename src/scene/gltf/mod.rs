//! glTF 2.0 scenes (`.gltf` with external or embedded buffers, `.glb`), through the `gltf`
//! crate.
//!
//! What is read, and what it becomes:
//! - The default scene (else the first; a file with no scene but with nodes draws its root
//!   nodes, with a warning), its node hierarchy with transforms composed in f64. A mesh used by
//!   several nodes is placed once per node.
//! - Triangle primitives (`TRIANGLES`, `TRIANGLE_STRIP`, `TRIANGLE_FAN`), indexed or not;
//!   points and lines are counted and left out with a warning. Positions, `NORMAL` (flat
//!   normals where a primitive has none, as the glTF specification asks), `TEXCOORD_0`,
//!   `TEXCOORD_1` (where a texture of the primitive's material reads it) and `TANGENT`
//!   (MikkTSpace tangents where a normal-mapped primitive has none, as the specification asks:
//!   [`super::tangents`]). Triangles with a non-finite vertex are left out, with a warning.
//!   Attributes may be quantised (`KHR_mesh_quantization`: 8- and 16-bit integers, normalised
//!   or not, read as the floats they stand for).
//! - Materials (metallic-roughness) as [`Material`]s: see [`convert_material`]; their base
//!   colour, metallic-roughness, emissive and normal textures (`normalTexture` with its
//!   `scale`).
//! - The first perspective camera in the scene becomes the scene camera;
//!   `KHR_lights_punctual` lights become point lights (see [`Scene`] assembly in [`load_from`]).
//!   With no light, the default lighting of a bare mesh.
//!
//! - Morph targets at the node's weights, else the mesh's (positions, normals, tangents);
//!   skins in the pose their joint nodes give (each vertex by its joints' world transforms
//!   times their inverse bind matrices, blended by `WEIGHTS_n`; the skinned node's own
//!   transform ignored, as the specification asks).
//!
//! - Animations, played to a given time ([`animation`]: node translations, rotations, scales
//!   and morph weights, with the three interpolations; skins follow their animated joints).
//!   Without a time the scene is drawn as its nodes place it, with a warning.
//!
//! Ignored: orthographic cameras, texture coordinate sets past 1 (read as set 0, with a warning), and
//! the material extensions not named above.
//! `KHR_texture_transform` is applied to the texture's lookups (its `texCoord` replaces the
//! texture's own set).
//!
//! Bad input never panics: every accessor is checked against its buffer view and buffer before
//! it is read, and errors name the file and the JSON path (`meshes[0].primitives[1]: index 74
//! out of range (24 vertices)`).

use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

use ::gltf::accessor::{DataType, Dimensions};
use ::gltf::mesh::Mode;
use anyhow::{Result, anyhow, bail};
use base64::Engine as _;
use glam::{DMat3, DMat4, DVec3, Vec2, Vec3, Vec4};

use super::format::MeshFile;
use super::meshopt::{self, Buffer};
use super::pbr::{Clearcoat, SheenLayer};
use super::{Camera, Environment, Light, Material, Mesh, NormalRule, Runs, Scene, Texture, Wrap};

mod animation;
mod buffers;
mod materials;
mod nodes;
mod primitives;
mod validate;

use buffers::*;
pub use materials::{convert_material, uv_transform, volume_absorption};
use validate::*;

/// A glTF camera placed by its node.
#[derive(Clone, Debug, PartialEq)]
pub struct GltfCamera {
    /// Eye position (world).
    pub position: DVec3,
    /// Unit viewing direction (the node's `-z`).
    pub forward: DVec3,
    /// Unit up direction (the node's `+y`).
    pub up: DVec3,
    /// Vertical field of view in degrees.
    pub vfov_deg: f32,
}

/// A `KHR_lights_punctual` light placed by its node.
#[derive(Clone, Debug, PartialEq)]
pub struct GltfLight {
    /// Point, spot or directional.
    pub kind: LightKind,
    /// Position (world; unused for directional lights).
    pub position: DVec3,
    /// Unit direction the light shines (the node's `-z`; spot and directional lights).
    pub direction: DVec3,
    /// Linear RGB colour.
    pub color: Vec3,
    /// Candela for point and spot lights, lux for directional ones.
    pub intensity: f32,
    /// A spot light's cone: the angles (radians) from its axis of full and of no light.
    pub cone: Option<(f32, f32)>,
}

/// The kinds of `KHR_lights_punctual`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LightKind {
    /// Light in every direction from a point.
    Point,
    /// A point light limited to a cone.
    Spot,
    /// Parallel light from infinitely far away.
    Directional,
}

/// Builds the scene of a loaded mesh file: its camera and lights (a glTF's) moved into the
/// mesh's local frame, the defaults of a bare mesh where it has none.
pub fn scene_of(name: String, d: MeshFile) -> Result<Scene> {
    let mut mesh = d.mesh;
    let instances = super::instances::place(&mut mesh, d.shared, &d.placed)
        .map_err(|e| anyhow::anyhow!("{name}: {e}"))?;
    let mut scene = Scene::from_mesh(name, mesh, d.materials);
    scene.warnings = d.warnings;
    scene.animation = d.animation;
    scene.objects = super::objects::list(
        &d.objects,
        scene.mesh.triangles.len(),
        instances.placements(),
        &scene.name,
    );
    if !instances.is_empty() {
        scene.instances = instances;
        let (camera, light) = super::default_view(&scene.bounds());
        scene.camera = camera;
        scene.lights = vec![light];
    }
    let origin = scene.mesh.origin;
    let local = |p: DVec3| (p - origin).as_vec3();
    if let Some(c) = &d.camera {
        let distance = {
            let b = scene.bounds();
            if b.is_empty() {
                1.0
            } else {
                let centre = (Vec3::from(b.min) + Vec3::from(b.max)) * 0.5;
                (centre - local(c.position)).length().max(1e-3)
            }
        };
        scene.camera = Camera {
            position: local(c.position),
            look_at: local(c.position + c.forward * distance as f64),
            up: c.up.as_vec3(),
            vfov_deg: c.vfov_deg,
            lens_radius: 0.0,
            focus_distance: distance,
        };
    }
    if !d.lights.is_empty() {
        let b = scene.bounds();
        let (centre, radius) = if b.is_empty() {
            (Vec3::ZERO, 1.0)
        } else {
            let (lo, hi) = (Vec3::from(b.min), Vec3::from(b.max));
            ((lo + hi) * 0.5, ((hi - lo).length() * 0.5).max(1e-3))
        };
        scene.lights = d
            .lights
            .iter()
            .map(|l| match (l.kind, l.cone) {
                (LightKind::Spot, Some((inner, outer))) => Light::Spot {
                    position: local(l.position),
                    direction: l.direction.as_vec3(),
                    color: l.color,
                    intensity: l.intensity,
                    cos_inner: inner.cos(),
                    cos_outer: outer.cos(),
                },
                (LightKind::Point | LightKind::Spot, _) => Light::Point {
                    position: local(l.position),
                    color: l.color,
                    intensity: l.intensity,
                },
                // Far away along the light's direction, bright enough to give the scene the
                // light's illuminance: a point light at distance D of intensity E D^2.
                (LightKind::Directional, _) => {
                    let d = 1000.0 * radius;
                    Light::Point {
                        position: centre - l.direction.as_vec3() * d,
                        color: l.color,
                        intensity: l.intensity * d * d,
                    }
                }
            })
            .collect();
        // The file's own lights light it: no sky on top of them.
        scene.environment = Environment::Sky {
            intensity: 0.1,
            rotation_deg: 0.0,
        };
    }
    Ok(scene)
}

/// Loads glTF bytes named `path` (for messages), reading external buffers and images through
/// `read` (paths relative to the file's folder). Primitives without normals are flat, or
/// follow `rule` when one is given (a scene file's `crease_angle`). With a `time` (seconds),
/// the file's animations are played to that instant ([`animation`]); without, the nodes,
/// skins and morph weights stand as the file places them.
pub fn load_from(
    path: &Path,
    bytes: &[u8],
    read: &dyn Fn(&Path) -> Result<Vec<u8>>,
    rule: Option<NormalRule>,
    time: Option<f64>,
) -> Result<MeshFile> {
    let name = path.display().to_string();
    let doc = match ::gltf::Gltf::from_slice_without_validation(bytes) {
        Ok(d) => d,
        Err(e @ ::gltf::Error::Deserialize(_)) => {
            relaxed(bytes).ok_or_else(|| parse_error(&name, e))?
        }
        Err(e) => return Err(parse_error(&name, e)),
    };
    for ext in doc.extensions_required() {
        if !READ_EXTENSIONS.contains(&ext) && !DONE_WITHOUT_EXTENSIONS.contains(&ext) {
            bail!("{name}: needs the extension {ext}, which Tracery does not read");
        }
    }
    validate(&doc).map_err(|e| parse_error(&name, e))?;
    let mut warnings = Vec::new();
    // An extension used but not required has a fallback in the core specification, which is
    // what is drawn: said, since the picture differs from what the file's author saw.
    for ext in doc.extensions_used() {
        if !READ_EXTENSIONS.contains(&ext) {
            warnings.push(format!(
                "{name}: uses the extension {ext}, which Tracery does not read; drawn without it"
            ));
        }
    }
    let mut buffers = doc
        .buffers()
        .map(|b| load_buffer(&name, &b, doc.blob.as_deref(), read))
        .collect::<Vec<_>>();
    let doc = meshopt::decompress(&name, doc, &mut buffers)?;

    let mut loader = Loader {
        name: &name,
        nodes: doc.nodes().collect(),
        doc_textures: doc.textures().collect(),
        doc_images: doc.images().collect(),
        buffers: &buffers,
        read,
        rule,
        warnings: &mut warnings,
        buf: Buffers::default(),
        primitives: HashMap::new(),
        parents: {
            let mut parents = vec![None; doc.nodes().len()];
            for n in doc.nodes() {
                for c in n.children() {
                    parents[c.index()].get_or_insert(n.index());
                }
            }
            parents
        },
        skins: HashMap::new(),
        materials: Vec::new(),
        material_index: HashMap::new(),
        textures: HashMap::new(),
        camera: None,
        lights: Vec::new(),
        left_out: HashMap::new(),
        any_uvs: false,
        any_uvs1: false,
        visits: 0,
        share: std::collections::HashSet::new(),
        placed: Vec::new(),
        runs: Runs::default(),
        pose: animation::Pose::default(),
    };

    let roots: Vec<usize> = match doc.default_scene().or_else(|| doc.scenes().next()) {
        Some(s) => s.nodes().map(|n| n.index()).collect(),
        None => {
            let mut child = vec![false; doc.nodes().len()];
            for n in doc.nodes() {
                for c in n.children() {
                    child[c.index()] = true;
                }
            }
            let roots: Vec<usize> = (0..child.len()).filter(|&i| !child[i]).collect();
            if !roots.is_empty() {
                loader.warnings.push(format!(
                    "{name}: no scene; drawing the {} root node(s)",
                    roots.len()
                ));
            }
            roots
        }
    };
    let animations = doc.animations().len();
    let animation = match time {
        Some(t) if animations > 0 => {
            if !t.is_finite() {
                bail!("{name}: the time to play the animations to is {t}, not a number of seconds");
            }
            let (pose, end) = loader.pose_at(&doc, t)?;
            loader.pose = pose;
            Some(end)
        }
        Some(_) => {
            loader
                .warnings
                .push(format!("{name}: has no animation; a time changes nothing"));
            None
        }
        None if animations > 0 => {
            loader.warnings.push(format!(
                "{name}: {animations} animation(s) not played: drawn as the nodes, skins and morph weights place it (give a time to play them)"
            ));
            Some(loader.length(&doc)?)
        }
        None => None,
    };
    // The placements and their triangles are counted before anything is read or placed.
    loader.plan(&roots)?;
    let mut on_path = vec![false; doc.nodes().len()];
    for root in roots {
        loader.visit(root, DMat4::IDENTITY, &mut on_path, 0)?;
    }
    let mut file = loader.finish()?;
    file.animation = animation;
    Ok(file)
}

/// A primitive as read for a placement: mesh, primitive, morph weights (as bits), whether a
/// skin places it.
type PrimitiveKey = (usize, usize, Vec<u32>, bool);

/// Each vertex's joints and their weights (zero weights left out).
type Influences = Vec<Vec<(u16, f32)>>;

/// Most `JOINTS_n` / `WEIGHTS_n` sets read (four influences each).
const MAX_INFLUENCE_SETS: u32 = 8;

/// Where a vertex goes: its transform, the linear part (tangents), the normals' matrix, and
/// whether it mirrors (the winding turned back).
struct Transform {
    full: DMat4,
    linear: DMat3,
    normal: DMat3,
    flip: bool,
}

impl Transform {
    fn of(m: &DMat4) -> Transform {
        let linear = DMat3::from_mat4(*m);
        Transform {
            full: *m,
            linear,
            normal: linear.inverse().transpose(),
            flip: linear.determinant() < 0.0,
        }
    }
}

/// One primitive's vertices and triangles as the file gives them (before any node transform).
struct Primitive {
    positions: Vec<Vec3>,
    normals: Option<Vec<Vec3>>,
    /// Per-corner normals computed by the loader's rule where the file gives none.
    corner_normals: Option<Vec<[Vec3; 3]>>,
    uvs: Option<Vec<Vec2>>,
    /// `TEXCOORD_1`, read only when a texture of the material reads it.
    uvs1: Option<Vec<Vec2>>,
    /// The file's `TANGENT`s, read only when the material has a normal map.
    tangents: Option<Vec<Vec4>>,
    /// Each vertex's joints and weights (`JOINTS_n` with `WEIGHTS_n`, zero weights left out),
    /// for a node with a skin; `None` when the primitive has no `JOINTS_0`.
    influences: Option<Influences>,
    triangles: Vec<[u32; 3]>,
    material: u32,
}

struct Loader<'a> {
    name: &'a str,
    /// The nodes by index (the crate's iterator would be walked from the start per lookup).
    nodes: Vec<::gltf::Node<'a>>,
    /// The textures by index, for extensions the crate does not read (their JSON names them).
    doc_textures: Vec<::gltf::Texture<'a>>,
    /// The images by index, for `EXT_texture_webp` (which the crate does not read).
    doc_images: Vec<::gltf::Image<'a>>,
    buffers: &'a [Buffer],
    read: &'a dyn Fn(&Path) -> Result<Vec<u8>>,
    /// Normals for primitives without them (`None`: flat).
    rule: Option<NormalRule>,
    warnings: &'a mut Vec<String>,
    /// The triangles placed so far.
    buf: Buffers,
    /// Primitives read once, by (mesh, primitive, morph weights as bits, whether a skin
    /// places it), for every node that places them.
    primitives: HashMap<PrimitiveKey, Option<Arc<Primitive>>>,
    /// Each node's parent (the first that lists it), for the world transforms of joints.
    parents: Vec<Option<usize>>,
    /// Each skin's joint matrices (joint's world transform times its inverse bind matrix).
    skins: HashMap<usize, Arc<Vec<DMat4>>>,
    materials: Vec<Material>,
    /// glTF material index (`None`: the default material) to index in `materials`.
    material_index: HashMap<Option<usize>, u32>,
    /// Decoded images by (image, sRGB), each decoded once.
    textures: HashMap<(usize, bool), Option<Arc<Texture>>>,
    camera: Option<GltfCamera>,
    lights: Vec<GltfLight>,
    /// Primitives left out, by reason.
    left_out: HashMap<String, usize>,
    any_uvs: bool,
    any_uvs1: bool,
    /// Nodes placed so far (see [`MAX_NODE_VISITS`]).
    visits: usize,
    /// Meshes placed by several nodes, none skinned and none morphed: held once, each node
    /// a placement ([`Loader::plan`] finds them).
    share: std::collections::HashSet<usize>,
    /// The placements of the meshes in `share`: mesh and world transform, in node order.
    placed: Vec<(usize, DMat4)>,
    /// The nodes placing triangles of the scene's own, named, in the order they are placed.
    runs: Runs,
    /// The animations' nodes at the time asked for (empty without a time).
    pose: animation::Pose,
}

impl Loader<'_> {
    /// The mesh, with positions placed in a local frame and flat normals where the file has
    /// none, and each shared mesh in its own frame with its placements; warnings for what
    /// was left out.
    fn finish(mut self) -> Result<MeshFile> {
        // Each shared mesh's primitives, placed once at the identity into buffers of their
        // own and made a mesh as the scene's own triangles are.
        let mut ids: Vec<usize> = self.share.iter().copied().collect();
        ids.sort_unstable();
        let mut shared = Vec::with_capacity(ids.len());
        for &m in &ids {
            let own = std::mem::take(&mut self.buf);
            let mesh = self
                .nodes
                .iter()
                .find_map(|n| n.mesh().filter(|x| x.index() == m));
            if let Some(mesh) = mesh {
                for prim in mesh.primitives() {
                    self.place(m, prim, &[], &DMat4::IDENTITY, None)?;
                }
            }
            let materials = self.materials.clone();
            shared.push(self.mesh_of_buffers(&materials));
            self.buf = own;
        }
        let placed = std::mem::take(&mut self.placed)
            .into_iter()
            .map(|(m, w)| {
                let k = ids.binary_search(&m).expect("a shared mesh") as u32;
                (k, glam::DAffine3::from_mat4(w))
            })
            .collect();
        let mut file = self.finish_own()?;
        file.shared = shared;
        file.placed = placed;
        Ok(file)
    }

    /// The scene's own triangles (see [`Loader::finish`]).
    fn finish_own(mut self) -> Result<MeshFile> {
        let mut left: Vec<(String, usize)> =
            std::mem::take(&mut self.left_out).into_iter().collect();
        left.sort();
        for (why, count) in left {
            self.warnings.push(format!(
                "{}: {count} primitive(s) {} left out (only triangles are drawn)",
                self.name,
                if why.starts_with("without") {
                    why
                } else {
                    format!("of mode {why}")
                }
            ));
        }
        if self.buf.material_ids.is_empty() && self.placed.is_empty() && self.share.is_empty() {
            self.warnings
                .push(format!("{}: the scene holds no triangles", self.name));
        }
        let mut materials = std::mem::take(&mut self.materials);
        if materials.is_empty() {
            materials.push(Material::default());
        }
        let mesh = self.mesh_of_buffers(&materials);
        Ok(MeshFile {
            mesh,
            materials,
            camera: self.camera.take(),
            lights: std::mem::take(&mut self.lights),
            warnings: std::mem::take(self.warnings),
            animation: None,
            shared: Vec::new(),
            placed: Vec::new(),
            objects: std::mem::take(&mut self.runs),
        })
    }

    /// The triangles gathered in the buffers (taken, the buffers left empty) as a mesh in a
    /// local frame: flat normals where the file has none, MikkTSpace's tangents where a
    /// normal-mapped material needs them and the file gives none.
    fn mesh_of_buffers(&mut self, materials: &[Material]) -> Mesh {
        let b = std::mem::take(&mut self.buf);
        let (origin, local) = super::local_frame(&b.positions);
        let triangles: Vec<[Vec3; 3]> = local.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        let normals: Vec<[Vec3; 3]> = triangles
            .iter()
            .zip(&b.normals)
            .map(|(t, n)| {
                let flat = super::face_normal(t);
                match n {
                    Some(n) => n.map(|v| {
                        if v.is_finite() && v != Vec3::ZERO {
                            v
                        } else {
                            flat
                        }
                    }),
                    None => [flat; 3],
                }
            })
            .collect();
        let default = Material::default();
        let material = |i: usize| {
            materials
                .get(b.material_ids[i] as usize)
                .unwrap_or(&default)
        };
        let mapped = |i: usize| material(i).has_normal_map();
        let tangents = if (self.any_uvs || self.any_uvs1) && (0..triangles.len()).any(mapped) {
            // MikkTSpace's where the file gives none, the file's where it does; made from the
            // coordinate set the normal map reads: the base's normal map's, else the coat's.
            let set1 = |i: usize| {
                let m = material(i);
                let coat = m.pbr.as_ref().and_then(|p| p.clearcoat.as_ref());
                m.normal_map
                    .as_ref()
                    .or(coat.and_then(|c| c.normal_map.as_ref()))
                    .is_some_and(|t| t.uv_set == 1)
            };
            let uvs: Vec<[Vec2; 3]> = (0..triangles.len())
                .map(|i| if set1(i) { b.uvs1[i] } else { b.uvs[i] })
                .collect();
            let mut t = super::tangents::mikktspace(&triangles, &normals, &uvs, |i| {
                mapped(i) && b.tangents[i].is_none()
            });
            for (i, given) in b.tangents.iter().enumerate() {
                if let (Some(given), true) = (given, mapped(i)) {
                    t[i] = given.map(|v| if v.is_finite() { v } else { Vec4::ZERO });
                }
            }
            t
        } else {
            Vec::new()
        };
        Mesh {
            triangles,
            normals,
            material_ids: b.material_ids,
            uvs: if self.any_uvs { b.uvs } else { Vec::new() },
            uvs1: if self.any_uvs1 { b.uvs1 } else { Vec::new() },
            tangents,
            origin,
        }
    }
}

/// The triangles a [`Loader`] gathers.
#[derive(Default)]
struct Buffers {
    /// World positions, three per triangle.
    positions: Vec<DVec3>,
    /// World normals, three per triangle (`None` for flat).
    normals: Vec<Option<[Vec3; 3]>>,
    uvs: Vec<[Vec2; 3]>,
    /// `TEXCOORD_1`, three per triangle (zero where a primitive has none).
    uvs1: Vec<[Vec2; 3]>,
    /// World tangents, three per triangle, for normal-mapped primitives with `TANGENT`
    /// (`None` otherwise: MikkTSpace's are made in [`Loader::finish`] where the material has
    /// a normal map).
    tangents: Vec<Option<[Vec4; 3]>>,
    material_ids: Vec<u32>,
}
