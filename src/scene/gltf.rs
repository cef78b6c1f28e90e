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
//! Ignored: animations (not played, with a warning: the scene is drawn as its nodes place it),
//! orthographic cameras, texture coordinate sets past 1 (read as set 0, with a warning), and
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

use super::meshopt::{self, Buffer};
use super::pbr::{Clearcoat, SheenLayer};
use super::{Camera, Environment, Light, Material, Mesh, NormalRule, Scene, Texture, Wrap};

/// What a glTF load produced besides the scene (used by scene files, which give their own
/// camera and lights).
pub struct GltfData {
    /// Triangles in a local frame (see [`super::local_frame`]), material ids into `materials`.
    pub mesh: Mesh,
    /// The materials (at least one).
    pub materials: Vec<Material>,
    /// The first perspective camera, in world coordinates.
    pub camera: Option<GltfCamera>,
    /// The punctual lights, in world coordinates.
    pub lights: Vec<GltfLight>,
    /// Problems that did not stop the load.
    pub warnings: Vec<String>,
}

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

/// Loads a `.gltf` or `.glb` file as a scene: its camera and lights when it has them, the
/// defaults of a bare mesh otherwise.
pub fn load(path: &Path) -> Result<Scene> {
    let bytes = super::read_file(path)?;
    let d = load_from(path, &bytes, &super::beside(path), None)?;
    Ok(scene_of(super::name_of(path), d))
}

/// Builds the scene of a loaded glTF: camera and lights moved into the mesh's local frame.
pub fn scene_of(name: String, d: GltfData) -> Scene {
    let mut scene = Scene::from_mesh(name, d.mesh, d.materials);
    scene.warnings = d.warnings;
    let origin = scene.mesh.origin;
    let local = |p: DVec3| (p - origin).as_vec3();
    if let Some(c) = &d.camera {
        let distance = {
            let b = scene.mesh.bounds();
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
        let b = scene.mesh.bounds();
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
    scene
}

/// Loads glTF bytes named `path` (for messages), reading external buffers and images through
/// `read` (paths relative to the file's folder). Primitives without normals are flat, or
/// follow `rule` when one is given (a scene file's `crease_angle`).
pub fn load_from(
    path: &Path,
    bytes: &[u8],
    read: &dyn Fn(&Path) -> Result<Vec<u8>>,
    rule: Option<NormalRule>,
) -> Result<GltfData> {
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
        positions: Vec::new(),
        normals: Vec::new(),
        uvs: Vec::new(),
        uvs1: Vec::new(),
        tangents: Vec::new(),
        material_ids: Vec::new(),
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
    if animations > 0 {
        loader.warnings.push(format!(
            "{name}: {animations} animation(s) not played: drawn as the nodes, skins and morph weights place it"
        ));
    }
    let mut on_path = vec![false; doc.nodes().len()];
    for root in roots {
        loader.visit(root, DMat4::IDENTITY, &mut on_path, 0)?;
    }
    loader.finish()
}

/// Component types of attributes that `KHR_mesh_quantization` lets be integers, normalised or
/// not (positions, texture coordinates).
const QUANTIZED: &[DataType] = &[
    DataType::F32,
    DataType::I8,
    DataType::U8,
    DataType::I16,
    DataType::U16,
];

/// Component types of attributes that `KHR_mesh_quantization` lets be signed normalised
/// integers (normals, tangents, morph displacements).
const SIGNED: &[DataType] = &[DataType::F32, DataType::I8, DataType::I16];

/// An accessor's elements (of two to four components, the rest 0) as floats, whatever its
/// component type: integers mapped to `[0, 1]` or `[-1, 1]` when the accessor is `normalized`
/// (signed ones clamped at -1, as the specification asks), taken as they are otherwise
/// (`KHR_mesh_quantization`). `None` when it cannot be read; the accessor must have been
/// checked ([`Loader::check_accessor`]).
fn read_floats<'a, 's, F>(acc: &::gltf::Accessor<'a>, get: F) -> Option<Vec<[f32; 4]>>
where
    F: Clone + Fn(::gltf::Buffer<'a>) -> Option<&'s [u8]>,
{
    use ::gltf::accessor::Iter;
    macro_rules! read {
        ($t:ty, $f:expr) => {{
            let f = $f;
            match acc.dimensions() {
                Dimensions::Vec2 => Iter::<[$t; 2]>::new(acc.clone(), get)?
                    .map(|a| [f(a[0]), f(a[1]), 0.0, 0.0])
                    .collect(),
                Dimensions::Vec3 => Iter::<[$t; 3]>::new(acc.clone(), get)?
                    .map(|a| [f(a[0]), f(a[1]), f(a[2]), 0.0])
                    .collect(),
                Dimensions::Vec4 => Iter::<[$t; 4]>::new(acc.clone(), get)?
                    .map(|a| a.map(f))
                    .collect(),
                _ => return None,
            }
        }};
    }
    // An integer `c` of largest value `max`, normalised or not.
    let norm = acc.normalized();
    let int = move |c: f32, max: f32| if norm { (c / max).max(-1.0) } else { c };
    Some(match acc.data_type() {
        DataType::F32 => read!(f32, |c: f32| c),
        DataType::I8 => read!(i8, |c: i8| int(f32::from(c), 127.0)),
        DataType::U8 => read!(u8, |c: u8| int(f32::from(c), 255.0)),
        DataType::I16 => read!(i16, |c: i16| int(f32::from(c), 32767.0)),
        DataType::U16 => read!(u16, |c: u16| int(f32::from(c), 65535.0)),
        DataType::U32 => return None,
    })
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

/// Each vertex's transform under a skin: its joints' matrices blended by its weights
/// (normalised to sum to 1; a vertex with no weight keeps the node's `world`). A joint past
/// the skin's list is an error.
fn skinning(
    at: &str,
    joints: &[DMat4],
    influences: &Influences,
    world: &DMat4,
) -> Result<Vec<Transform>> {
    influences
        .iter()
        .map(|inf| {
            let (mut m, mut sum) = (DMat4::ZERO, 0.0);
            for &(j, w) in inf {
                let Some(jm) = joints.get(j as usize) else {
                    bail!(
                        "{at}: a vertex names joint {j} of a skin with {} joints",
                        joints.len()
                    );
                };
                m += *jm * f64::from(w);
                sum += f64::from(w);
            }
            Ok(Transform::of(&if sum > 0.0 {
                m * (1.0 / sum)
            } else {
                *world
            }))
        })
        .collect()
}

/// A glTF (JSON, not GLB) that the gltf crate refuses only for a field the specification makes
/// optional and the crate does not: a scene without `nodes` (an empty scene). The field is
/// added and the file read again; `None` when that is not the problem.
fn relaxed(bytes: &[u8]) -> Option<::gltf::Gltf> {
    let mut json: serde_json::Value = serde_json::from_slice(bytes).ok()?;
    let mut changed = false;
    for scene in json.get_mut("scenes")?.as_array_mut()? {
        if let Some(obj) = scene.as_object_mut()
            && !obj.contains_key("nodes")
        {
            obj.insert("nodes".into(), serde_json::Value::Array(Vec::new()));
            changed = true;
        }
    }
    if !changed {
        return None;
    }
    ::gltf::Gltf::from_slice_without_validation(&serde_json::to_vec(&json).ok()?).ok()
}

/// Extensions the loader reads.
const READ_EXTENSIONS: &[&str] = &[
    "KHR_lights_punctual",
    "KHR_materials_clearcoat",
    "KHR_materials_sheen",
    "KHR_materials_specular",
    "KHR_materials_volume",
    "KHR_mesh_quantization",
    "KHR_materials_transmission",
    "KHR_materials_ior",
    "KHR_materials_emissive_strength",
    "KHR_texture_transform",
    "EXT_texture_webp",
    meshopt::EXTENSION,
    meshopt::KHR_EXTENSION,
];

/// Extensions the loader does not read but a file may require: it can safely do without them.
const DONE_WITHOUT_EXTENSIONS: &[&str] = &["KHR_materials_unlit"];

/// Most node placements (a node under several parents is placed once per path to it: a file
/// can make that grow exponentially with depth, so it is bounded, not followed into a hang).
const MAX_NODE_VISITS: usize = 1_000_000;

/// Most triangles placed (a mesh under many nodes multiplies them).
const MAX_TRIANGLES: usize = 50_000_000;

/// Deepest node hierarchy followed (a deeper one is reported, not followed into a stack
/// overflow).
const MAX_NODE_DEPTH: usize = 256;

/// The glTF crate's validation (every index in range, required fields present: after it,
/// looking an index up cannot fail), less two rules the loader does not need: accessor `min`
/// and `max` (bounds are computed from the positions; exporters often leave them out) and
/// required extensions (checked before, with a clearer message).
fn validate(doc: &::gltf::Gltf) -> std::result::Result<(), ::gltf::Error> {
    use ::gltf::json::validation::{Error, Validate};
    let root = doc.as_json();
    // The crate's check of POSITION's min and max indexes the accessor list without a bounds
    // check (a panic on a POSITION index past the list): those indices are checked first.
    let accessors = root.accessors.len();
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            if prim.attributes.values().any(|a| a.value() >= accessors) {
                let path = ::gltf::json::Path::new()
                    .field("meshes")
                    .index(m)
                    .field("primitives")
                    .index(p)
                    .field("attributes");
                return Err(::gltf::Error::Validation(vec![(
                    path,
                    Error::IndexOutOfBounds,
                )]));
            }
        }
    }
    let mut errors = Vec::new();
    // Two rules of the specification the crate does not check, and whose absence its
    // `Image::source` meets with a panic: an image in a buffer view names its MIME type, and
    // every image has a URI or a buffer view.
    for (i, image) in root.images.iter().enumerate() {
        let missing = match (&image.buffer_view, &image.uri) {
            (Some(_), _) if image.mime_type.is_none() => Some("mimeType"),
            (None, None) => Some("uri"),
            _ => None,
        };
        if let Some(field) = missing {
            let path = ::gltf::json::Path::new()
                .field("images")
                .index(i)
                .field(field);
            errors.push((path, Error::Missing));
        }
    }
    root.validate(root, ::gltf::json::Path::new, &mut |path, err| {
        let p = path();
        let at = p.to_string();
        let bounds = at.ends_with(".min") || at.ends_with(".max");
        if (matches!(err, Error::Missing) && bounds)
            || (matches!(err, Error::Unsupported) && at.starts_with("extensionsRequired"))
        {
            return;
        }
        errors.push((p, err));
    });
    if errors.is_empty() {
        Ok(())
    } else {
        Err(::gltf::Error::Validation(errors))
    }
}

/// A parse or validation error as one message naming the file (and line and column, or the
/// JSON path).
fn parse_error(name: &str, e: ::gltf::Error) -> anyhow::Error {
    match e {
        ::gltf::Error::Deserialize(e) => {
            // serde's message ends in " at line L column C": said once, up front.
            let msg = e.to_string();
            let msg = msg
                .rsplit_once(" at line ")
                .map_or(msg.as_str(), |(m, _)| m);
            anyhow!(
                "{name}:{}:{}: invalid glTF JSON: {msg}",
                e.line(),
                e.column()
            )
        }
        ::gltf::Error::Validation(errors) => {
            let shown: Vec<String> = errors
                .iter()
                .take(3)
                .map(|(path, err)| format!("{path}: {err}"))
                .collect();
            let more = match errors.len() {
                0..=3 => String::new(),
                n => format!(" (and {} more)", n - 3),
            };
            anyhow!("{name}: invalid glTF: {}{more}", shown.join("; "))
        }
        ::gltf::Error::Binary(e) => anyhow!("{name}: invalid GLB container: {e}"),
        e => anyhow!("{name}: {e}"),
    }
}

/// A buffer's bytes, or why they cannot be had (reported when an accessor needs them).
fn load_buffer(
    name: &str,
    b: &::gltf::Buffer,
    blob: Option<&[u8]>,
    read: &dyn Fn(&Path) -> Result<Vec<u8>>,
) -> Buffer {
    let i = b.index();
    if meshopt::is_fallback(b) {
        return Err(format!(
            "{name}: buffers[{i}]: the uncompressed fallback of the meshopt compression, which the file leaves out"
        ));
    }
    let data = match b.source() {
        ::gltf::buffer::Source::Bin => match blob {
            Some(d) => d.to_vec(),
            None => {
                return Err(format!(
                    "{name}: buffers[{i}]: the file has no binary chunk"
                ));
            }
        },
        ::gltf::buffer::Source::Uri(uri) => {
            uri_bytes(uri, read).map_err(|e| format!("{name}: buffers[{i}]: {e:#}"))?
        }
    };
    if data.len() < b.length() {
        return Err(format!(
            "{name}: buffers[{i}]: holds {} bytes, its byteLength says {}",
            data.len(),
            b.length()
        ));
    }
    Ok(data)
}

/// The bytes a URI names: a `data:` URI decoded, or a file beside the glTF (percent-decoded).
fn uri_bytes(uri: &str, read: &dyn Fn(&Path) -> Result<Vec<u8>>) -> Result<Vec<u8>> {
    if let Some(rest) = uri.strip_prefix("data:") {
        let Some((_, payload)) = rest.split_once(";base64,") else {
            bail!("data URI is not base64");
        };
        return base64::engine::general_purpose::STANDARD
            .decode(payload.trim())
            .map_err(|e| anyhow!("data URI: bad base64: {e}"));
    }
    if uri.contains("://") {
        bail!("{uri}: only files beside the glTF and data URIs are read");
    }
    let file = percent_encoding::percent_decode_str(uri).decode_utf8_lossy();
    read(Path::new(file.as_ref()))
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
}

impl Loader<'_> {
    fn visit(
        &mut self,
        index: usize,
        parent: DMat4,
        on_path: &mut [bool],
        depth: usize,
    ) -> Result<()> {
        if on_path[index] {
            bail!(
                "{}: nodes[{index}]: the node hierarchy has a cycle (nodes[{index}] is its own ancestor)",
                self.name
            );
        }
        if depth > MAX_NODE_DEPTH {
            bail!(
                "{}: nodes[{index}]: the node hierarchy is deeper than {MAX_NODE_DEPTH} levels",
                self.name
            );
        }
        self.visits += 1;
        if self.visits > MAX_NODE_VISITS {
            bail!(
                "{}: the node hierarchy places more than {MAX_NODE_VISITS} nodes (nodes under several parents?)",
                self.name
            );
        }
        let Some(node) = self.nodes.get(index).cloned() else {
            bail!("{}: nodes[{index}] does not exist", self.name);
        };
        let local = DMat4::from_cols_array_2d(&node.transform().matrix().map(|c| c.map(f64::from)));
        let world = parent * local;
        if !world.is_finite() {
            bail!("{}: nodes[{index}]: its transform is not finite", self.name);
        }
        if let Some(mesh) = node.mesh() {
            // Morph targets at the node's weights, else the mesh's (no animation is played).
            let weights = node.weights().or(mesh.weights()).unwrap_or(&[]);
            // A skinned mesh is placed by its joints; the node's own transform is ignored,
            // as the specification asks.
            let skin = match node.skin() {
                Some(skin) => Some(self.joint_matrices(&skin)?),
                None => None,
            };
            for prim in mesh.primitives() {
                self.place(
                    mesh.index(),
                    prim,
                    weights,
                    &world,
                    skin.as_deref().map(Vec::as_slice),
                )?;
            }
        }
        if self.camera.is_none()
            && let Some(cam) = node.camera()
        {
            match cam.projection() {
                ::gltf::camera::Projection::Perspective(p) => {
                    let forward = world.transform_vector3(-DVec3::Z).normalize_or_zero();
                    let up = world.transform_vector3(DVec3::Y).normalize_or_zero();
                    if forward != DVec3::ZERO && up != DVec3::ZERO {
                        self.camera = Some(GltfCamera {
                            position: world.transform_point3(DVec3::ZERO),
                            forward,
                            up,
                            vfov_deg: p.yfov().to_degrees().clamp(1.0, 179.0),
                        });
                    }
                }
                ::gltf::camera::Projection::Orthographic(_) => self.warnings.push(format!(
                    "{}: cameras[{}]: orthographic cameras are not supported; skipped",
                    self.name,
                    cam.index()
                )),
            }
        }
        if let Some(light) = node.light() {
            use ::gltf::khr_lights_punctual::Kind;
            let (kind, cone) = match light.kind() {
                Kind::Point => (LightKind::Point, None),
                Kind::Spot {
                    inner_cone_angle,
                    outer_cone_angle,
                } => {
                    // The specification asks for 0 <= inner < outer <= pi / 2; a cone outside
                    // that is clamped into it, with a warning.
                    let or = |a: f32, default: f32| if a.is_finite() { a } else { default };
                    let outer = or(outer_cone_angle, std::f32::consts::FRAC_PI_4)
                        .clamp(1e-4, std::f32::consts::FRAC_PI_2);
                    let inner = or(inner_cone_angle, 0.0).clamp(0.0, outer * 0.9999);
                    if !(outer == outer_cone_angle && inner == inner_cone_angle) {
                        self.warnings.push(format!(
                            "{}: lights[{}]: spot cone angles {inner_cone_angle} and \
                             {outer_cone_angle} are outside 0 <= inner < outer <= pi/2; \
                             used {inner} and {outer}",
                            self.name,
                            light.index()
                        ));
                    }
                    (LightKind::Spot, Some((inner, outer)))
                }
                Kind::Directional => (LightKind::Directional, None),
            };
            let intensity = light.intensity();
            if intensity.is_finite() && intensity >= 0.0 {
                self.lights.push(GltfLight {
                    kind,
                    position: world.transform_point3(DVec3::ZERO),
                    direction: world.transform_vector3(-DVec3::Z).normalize_or(-DVec3::Z),
                    color: Vec3::from(light.color()),
                    intensity,
                    cone,
                });
            }
        }
        on_path[index] = true;
        for child in node.children() {
            self.visit(child.index(), world, on_path, depth + 1)?;
        }
        on_path[index] = false;
        Ok(())
    }

    /// Places one primitive with the node's world transform, its morph targets at `weights`,
    /// or by the joint matrices of the node's skin.
    fn place(
        &mut self,
        mesh: usize,
        prim: ::gltf::Primitive,
        weights: &[f32],
        world: &DMat4,
        skin: Option<&[DMat4]>,
    ) -> Result<()> {
        let key = (
            mesh,
            prim.index(),
            weights.iter().map(|w| w.to_bits()).collect(),
            skin.is_some(),
        );
        let data = match self.primitives.get(&key) {
            Some(d) => d.clone(),
            None => {
                let skinned = skin.is_some();
                let d = self
                    .read_primitive(mesh, &prim, weights, skinned)?
                    .map(Arc::new);
                self.primitives.insert(key, d.clone());
                d
            }
        };
        let Some(p) = data else {
            return Ok(());
        };
        if self.material_ids.len() + p.triangles.len() > MAX_TRIANGLES {
            bail!(
                "{}: meshes[{mesh}] placed again would make more than {MAX_TRIANGLES} triangles",
                self.name
            );
        }
        let at = format!("{}: meshes[{mesh}].primitives[{}]", self.name, prim.index());
        // Each vertex's transform: the node's, or the blend of its joints' for a skin.
        let skinned = match (skin, &p.influences) {
            (Some(joints), Some(influences)) => Some(skinning(&at, joints, influences, world)?),
            (Some(_), None) => {
                self.warnings.push(format!(
                    "{at}: its node has a skin but the primitive has no JOINTS_0; placed by the node's transform"
                ));
                None
            }
            _ => None,
        };
        let one = Transform::of(world);
        let xf = |i: usize| skinned.as_ref().map_or(&one, |s| &s[i]);
        for (ti, t) in p.triangles.iter().enumerate() {
            // A mirroring transform turns the winding around: corners are swapped back so
            // that the front face stays the front face.
            let flip = xf(t[0] as usize).flip;
            let order: [usize; 3] = if flip { [0, 2, 1] } else { [0, 1, 2] };
            let c = order.map(|k| t[k] as usize);
            self.positions
                .extend(c.map(|i| xf(i).full.transform_point3(p.positions[i].as_dvec3())));
            let turn =
                |i: usize, n: Vec3| (xf(i).normal * n.as_dvec3()).normalize_or_zero().as_vec3();
            self.normals.push(match (&p.normals, &p.corner_normals) {
                (Some(n), _) => Some(c.map(|i| turn(i, n[i]))),
                (None, Some(cn)) => Some(order.map(|k| turn(t[k] as usize, cn[ti][k]))),
                (None, None) => None,
            });
            self.uvs.push(match &p.uvs {
                Some(uv) => c.map(|i| uv[i]),
                None => [Vec2::ZERO; 3],
            });
            self.uvs1.push(match &p.uvs1 {
                Some(uv) => c.map(|i| uv[i]),
                None => [Vec2::ZERO; 3],
            });
            // Tangents turn as positions do; a mirror turns the bitangent's handedness.
            self.tangents.push(p.tangents.as_ref().map(|t| {
                c.map(|i| {
                    let v = (xf(i).linear * t[i].truncate().as_dvec3()).normalize_or_zero();
                    v.as_vec3().extend(if flip { -t[i].w } else { t[i].w })
                })
            }));
            self.material_ids.push(p.material);
        }
        Ok(())
    }

    /// Reads a primitive's vertices and triangles (its morph targets at `weights`, its joints
    /// and weights when `skinned`), or `None` when it is left out (with the reason counted for
    /// the warnings).
    fn read_primitive(
        &mut self,
        mesh: usize,
        prim: &::gltf::Primitive,
        weights: &[f32],
        skinned: bool,
    ) -> Result<Option<Primitive>> {
        let at = format!("{}: meshes[{mesh}].primitives[{}]", self.name, prim.index());
        let mode = prim.mode();
        if !matches!(
            mode,
            Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
        ) {
            *self.left_out.entry(format!("{mode:?}")).or_default() += 1;
            return Ok(None);
        }
        let Some(pos_acc) = prim.get(&::gltf::Semantic::Positions) else {
            *self.left_out.entry("without POSITION".into()).or_default() += 1;
            return Ok(None);
        };
        self.check_accessor(&at, "POSITION", &pos_acc, QUANTIZED, Dimensions::Vec3)?;
        let buffers = self.buffers;
        let get = |b: ::gltf::Buffer| buffers.get(b.index()).and_then(|d| d.as_deref().ok());
        let reader = prim.reader(get);
        let positions: Vec<Vec3> = read_floats(&pos_acc, get)
            .ok_or_else(|| anyhow!("{at}: POSITION cannot be read"))?
            .into_iter()
            .map(|v| Vec4::from(v).truncate())
            .collect();
        let n = positions.len();

        let normals = match prim.get(&::gltf::Semantic::Normals) {
            Some(acc) => {
                self.check_accessor(&at, "NORMAL", &acc, SIGNED, Dimensions::Vec3)?;
                let normals = read_floats(&acc, get)
                    .map(|r| r.into_iter().map(|v| Vec4::from(v).truncate()).collect());
                self.per_vertex(&at, "NORMAL", normals, n, "flat normals used")
            }
            None => None,
        };
        let material = self.material(prim.material())?;
        let mut uvs = [None, None];
        for set in 0..2 {
            let reads = |m: &Material| m.textures().any(|t| t.uv_set == set);
            if set > 0 && !reads(&self.materials[material as usize]) {
                continue;
            }
            let what = format!("TEXCOORD_{set}");
            uvs[set as usize] = match prim.get(&::gltf::Semantic::TexCoords(set.into())) {
                Some(acc) => {
                    self.check_accessor(&at, &what, &acc, QUANTIZED, Dimensions::Vec2)?;
                    let uvs = read_floats(&acc, get).map(|r| {
                        r.into_iter()
                            .map(|v| Vec4::from(v).truncate().truncate())
                            .collect()
                    });
                    self.per_vertex(&at, &what, uvs, n, "ignored")
                }
                None if set > 0 => {
                    self.warnings.push(format!(
                        "{at}: a texture of its material reads {what}, which it does not have; (0, 0) is read"
                    ));
                    None
                }
                None => None,
            };
        }
        let [uvs, uvs1] = uvs;
        let normal_mapped = self.materials[material as usize].has_normal_map();
        let tangents = match prim.get(&::gltf::Semantic::Tangents) {
            Some(acc) if normal_mapped => {
                self.check_accessor(&at, "TANGENT", &acc, SIGNED, Dimensions::Vec4)?;
                let tangents =
                    read_floats(&acc, get).map(|r| r.into_iter().map(Vec4::from).collect());
                self.per_vertex(&at, "TANGENT", tangents, n, "MikkTSpace's used")
            }
            _ => None,
        };

        let mut positions = positions;
        let (mut normals, mut tangents) = (normals, tangents);
        self.morph(
            &at,
            prim,
            get,
            weights,
            &mut positions,
            &mut normals,
            &mut tangents,
        )?;
        // Joints and weights only where a skin places the primitive (elsewhere they are unused
        // and not checked).
        let influences = if skinned {
            self.influences(&at, prim, &reader, n)?
        } else {
            None
        };

        let indices: Vec<u32> = match prim.indices() {
            Some(acc) => {
                self.check_accessor(
                    &at,
                    "indices",
                    &acc,
                    &[DataType::U8, DataType::U16, DataType::U32],
                    Dimensions::Scalar,
                )?;
                let indices: Vec<u32> = reader
                    .read_indices()
                    .ok_or_else(|| anyhow!("{at}: indices cannot be read"))?
                    .into_u32()
                    .collect();
                if let Some(bad) = indices.iter().find(|&&i| i as usize >= n) {
                    bail!("{at}: index {bad} out of range ({n} vertices)");
                }
                indices
            }
            None => (0..n as u32).collect(),
        };
        let triangles = triangles_of(mode, &indices);
        if mode == Mode::Triangles && !indices.len().is_multiple_of(3) {
            self.warnings.push(format!(
                "{at}: {} {} is not a multiple of 3; the last {} left out",
                indices.len(),
                if prim.indices().is_some() {
                    "indices"
                } else {
                    "vertices"
                },
                indices.len() % 3
            ));
        }

        // Triangles with a non-finite vertex have no surface: left out, and said.
        let finite: Vec<bool> = positions.iter().map(|p| p.is_finite()).collect();
        let before = triangles.len();
        let triangles: Vec<[u32; 3]> = triangles
            .into_iter()
            .filter(|t| t.iter().all(|&i| finite[i as usize]))
            .collect();
        if triangles.len() < before {
            self.warnings.push(format!(
                "{at}: {} triangle(s) with a non-finite vertex left out",
                before - triangles.len()
            ));
        }
        self.any_uvs |= uvs.is_some();
        self.any_uvs1 |= uvs1.is_some();
        let corner_normals = match (&normals, self.rule) {
            (None, Some(rule)) => Some(super::normals::corner_normals(
                &positions,
                &triangles,
                rule,
                &[],
            )),
            _ => None,
        };
        Ok(Some(Primitive {
            positions,
            normals,
            corner_normals,
            uvs,
            uvs1,
            tangents,
            influences,
            triangles,
            material,
        }))
    }

    /// Adds a primitive's morph targets at `weights` to its positions, normals and tangents
    /// (every displacement accessor checked first, a count other than the vertex count an
    /// error; a weight the mesh lacks is 0, with a warning).
    #[allow(clippy::too_many_arguments)]
    fn morph<'a, 's, F>(
        &mut self,
        at: &str,
        prim: &::gltf::Primitive<'a>,
        get: F,
        weights: &[f32],
        positions: &mut [Vec3],
        normals: &mut Option<Vec<Vec3>>,
        tangents: &mut Option<Vec<Vec4>>,
    ) -> Result<()>
    where
        F: Clone + Fn(::gltf::Buffer<'a>) -> Option<&'s [u8]>,
    {
        let targets: Vec<_> = prim.morph_targets().collect();
        if targets.is_empty() {
            return Ok(());
        }
        // No weights at all means every weight 0 (the specification's default).
        if !weights.is_empty() && weights.len() != targets.len() {
            self.warnings.push(format!(
                "{at}: {} morph target(s) and {} weight(s); a missing weight is 0",
                targets.len(),
                weights.len()
            ));
        }
        for (k, t) in targets.iter().enumerate() {
            for (attr, acc) in [
                ("POSITION", t.positions()),
                ("NORMAL", t.normals()),
                ("TANGENT", t.tangents()),
            ] {
                if let Some(acc) = acc {
                    let what = format!("targets[{k}].{attr}");
                    self.check_accessor(at, &what, &acc, SIGNED, Dimensions::Vec3)?;
                }
            }
        }
        let n = positions.len();
        for (k, t) in targets.iter().enumerate() {
            let w = weights.get(k).copied().unwrap_or(0.0);
            if !w.is_finite() {
                self.warnings.push(format!(
                    "{at}: morph weight {k} is {w}; the target is left out"
                ));
                continue;
            }
            if w == 0.0 {
                continue;
            }
            let read =
                |attr: &str, acc: Option<::gltf::Accessor<'a>>| -> Result<Option<Vec<Vec3>>> {
                    let Some(acc) = acc else {
                        return Ok(None);
                    };
                    let d = read_floats(&acc, get.clone())
                        .ok_or_else(|| anyhow!("{at}: targets[{k}].{attr} cannot be read"))?;
                    if d.len() != n {
                        bail!(
                            "{at}: targets[{k}].{attr} has {} elements for {n} vertices",
                            d.len()
                        );
                    }
                    Ok(Some(
                        d.into_iter().map(|v| Vec4::from(v).truncate()).collect(),
                    ))
                };
            if let Some(d) = read("POSITION", t.positions())? {
                for (p, d) in positions.iter_mut().zip(d) {
                    *p += w * d;
                }
            }
            if let (Some(d), Some(ns)) = (read("NORMAL", t.normals())?, normals.as_mut()) {
                for (v, d) in ns.iter_mut().zip(d) {
                    *v += w * d;
                }
            }
            if let (Some(d), Some(ts)) = (read("TANGENT", t.tangents())?, tangents.as_mut()) {
                for (v, d) in ts.iter_mut().zip(d) {
                    *v += (w * d).extend(0.0);
                }
            }
        }
        Ok(())
    }

    /// Each vertex's joints and weights (`JOINTS_n` with `WEIGHTS_n`, every set there is), or
    /// `None` when the primitive has no `JOINTS_0`.
    fn influences<'a, 's, F>(
        &mut self,
        at: &str,
        prim: &::gltf::Primitive<'a>,
        reader: &::gltf::mesh::Reader<'a, 's, F>,
        n: usize,
    ) -> Result<Option<Influences>>
    where
        F: Clone + Fn(::gltf::Buffer<'a>) -> Option<&'s [u8]>,
    {
        use ::gltf::Semantic;
        let mut out: Option<Influences> = None;
        for set in 0..MAX_INFLUENCE_SETS {
            let (joints, weights) = (
                prim.get(&Semantic::Joints(set)),
                prim.get(&Semantic::Weights(set)),
            );
            let (Some(j), Some(w)) = (joints.clone(), weights.clone()) else {
                if joints.is_some() != weights.is_some() {
                    bail!("{at}: JOINTS_{set} and WEIGHTS_{set} come in pairs; one is missing");
                }
                break;
            };
            let (jw, ww) = (format!("JOINTS_{set}"), format!("WEIGHTS_{set}"));
            let ints = [DataType::U8, DataType::U16];
            self.check_accessor(at, &jw, &j, &ints, Dimensions::Vec4)?;
            let floats = [DataType::F32, DataType::U8, DataType::U16];
            self.check_accessor(at, &ww, &w, &floats, Dimensions::Vec4)?;
            let joints: Vec<[u16; 4]> = reader
                .read_joints(set)
                .ok_or_else(|| anyhow!("{at}: {jw} cannot be read"))?
                .into_u16()
                .collect();
            let weights: Vec<[f32; 4]> = reader
                .read_weights(set)
                .ok_or_else(|| anyhow!("{at}: {ww} cannot be read"))?
                .into_f32()
                .collect();
            if joints.len() != n || weights.len() != n {
                bail!(
                    "{at}: {jw} and {ww} have {} and {} elements for {n} vertices",
                    joints.len(),
                    weights.len()
                );
            }
            let out = out.get_or_insert_with(|| vec![Vec::new(); n]);
            for ((o, j), w) in out.iter_mut().zip(&joints).zip(&weights) {
                o.extend(
                    j.iter()
                        .zip(w)
                        .filter(|(_, w)| **w != 0.0)
                        .map(|(j, w)| (*j, *w)),
                );
            }
        }
        Ok(out)
    }

    /// A skin's joint matrices: each joint node's world transform times its inverse bind
    /// matrix (the identity when the skin gives none).
    fn joint_matrices(&mut self, skin: &::gltf::Skin) -> Result<Arc<Vec<DMat4>>> {
        if let Some(m) = self.skins.get(&skin.index()) {
            return Ok(m.clone());
        }
        let at = format!("{}: skins[{}]", self.name, skin.index());
        let joints: Vec<usize> = skin.joints().map(|j| j.index()).collect();
        let inverse_bind: Vec<DMat4> = match skin.inverse_bind_matrices() {
            Some(acc) => {
                let what = "inverseBindMatrices";
                self.check_accessor(&at, what, &acc, &[DataType::F32], Dimensions::Mat4)?;
                let buffers = self.buffers;
                let m: Vec<DMat4> = skin
                    .reader(|b| buffers.get(b.index()).and_then(|d| d.as_deref().ok()))
                    .read_inverse_bind_matrices()
                    .ok_or_else(|| anyhow!("{at}: {what} cannot be read"))?
                    .map(|m| DMat4::from_cols_array_2d(&m.map(|c| c.map(f64::from))))
                    .collect();
                if m.len() < joints.len() {
                    bail!("{at}: {} {what} for {} joints", m.len(), joints.len());
                }
                m
            }
            None => vec![DMat4::IDENTITY; joints.len()],
        };
        let mut out = Vec::with_capacity(joints.len());
        for (&j, ib) in joints.iter().zip(inverse_bind) {
            let m = self.world_of(j)? * ib;
            if !m.is_finite() {
                bail!("{at}: the matrix of joint nodes[{j}] is not finite");
            }
            out.push(m);
        }
        let out = Arc::new(out);
        self.skins.insert(skin.index(), out.clone());
        Ok(out)
    }

    /// A node's world transform, through its parents (the first that lists it).
    fn world_of(&self, node: usize) -> Result<DMat4> {
        let mut m = DMat4::IDENTITY;
        let mut i = node;
        for _ in 0..=MAX_NODE_DEPTH {
            let Some(n) = self.nodes.get(i) else {
                bail!("{}: nodes[{i}] does not exist", self.name);
            };
            m = DMat4::from_cols_array_2d(&n.transform().matrix().map(|c| c.map(f64::from))) * m;
            match self.parents[i] {
                Some(p) => i = p,
                None => return Ok(m),
            }
        }
        bail!(
            "{}: nodes[{node}]: its ancestors are deeper than {MAX_NODE_DEPTH} levels (or a cycle)",
            self.name
        )
    }

    /// A vertex attribute's values when there is one per vertex; otherwise `None`, with a
    /// warning saying what is done instead.
    fn per_vertex<T>(
        &mut self,
        at: &str,
        what: &str,
        values: Option<Vec<T>>,
        n: usize,
        instead: &str,
    ) -> Option<Vec<T>> {
        let values = values.unwrap_or_default();
        if values.len() == n {
            return Some(values);
        }
        self.warnings.push(format!(
            "{at}: {what} has {} entries for {n} vertices; {instead}",
            values.len()
        ));
        None
    }

    /// Checks that an accessor can be read as `dims` of one of `types`, and that every byte it
    /// covers lies inside its buffer view and buffer.
    fn check_accessor(
        &self,
        at: &str,
        what: &str,
        acc: &::gltf::Accessor,
        types: &[DataType],
        dims: Dimensions,
    ) -> Result<()> {
        let i = acc.index();
        let at = format!("{at}: {what} (accessors[{i}])");
        if !types.contains(&acc.data_type()) || acc.dimensions() != dims {
            bail!(
                "{at}: {:?} {:?}, expected {dims:?} of {types:?}",
                acc.dimensions(),
                acc.data_type()
            );
        }
        let count = acc.count();
        if count == 0 {
            bail!("{at}: no elements");
        }
        let size = acc.size();
        match acc.view() {
            Some(view) => {
                self.check_span(&at, "elements", &view, acc.offset(), count, size)?;
            }
            // Without a bufferView the elements are zeros, which a sparse accessor replaces
            // in part.
            None if acc.sparse().is_some() => {}
            None => bail!("{at}: no bufferView"),
        }
        if let Some(sparse) = acc.sparse() {
            self.check_sparse(&at, &sparse, count, size)?;
        }
        Ok(())
    }

    /// Checks that `count` elements of `size` bytes from byte `offset` of `view` (at its stride)
    /// lie inside it, and it inside its buffer; `what` names them in the message.
    fn check_span(
        &self,
        at: &str,
        what: &str,
        view: &::gltf::buffer::View,
        offset: usize,
        count: usize,
        size: usize,
    ) -> Result<&[u8]> {
        let stride = view.stride().unwrap_or(size);
        if stride < size {
            bail!("{at}: byteStride {stride} is smaller than an element ({size} bytes)");
        }
        let span = count
            .checked_sub(1)
            .and_then(|c| c.checked_mul(stride))
            .and_then(|s| s.checked_add(size))
            .and_then(|s| s.checked_add(offset));
        match span {
            Some(end) if end <= view.length() => {}
            _ => bail!(
                "{at}: {count} {what} from byte {offset} (stride {stride}) run past bufferViews[{}] ({} bytes)",
                view.index(),
                view.length()
            ),
        }
        let b = view.buffer().index();
        let data = match self.buffers.get(b) {
            Some(Ok(d)) => d,
            Some(Err(why)) => bail!("{why}"),
            None => bail!("{at}: buffers[{b}] does not exist"),
        };
        match view.offset().checked_add(view.length()) {
            Some(end) if end <= data.len() => Ok(&data[view.offset()..end]),
            _ => bail!(
                "{at}: bufferViews[{}] (bytes {}..+{}) runs past buffers[{b}] ({} bytes)",
                view.index(),
                view.offset(),
                view.length(),
                data.len()
            ),
        }
    }

    /// Checks a sparse accessor's substitutions into `count` elements of `size` bytes: their
    /// indices and values lie inside their views, and the indices rise strictly and stay below
    /// `count`, as the specification asks (a reader applies them in one pass, so any other
    /// order would silently drop some).
    fn check_sparse(
        &self,
        at: &str,
        sparse: &::gltf::accessor::sparse::Sparse,
        count: usize,
        size: usize,
    ) -> Result<()> {
        use ::gltf::accessor::sparse::IndexType;
        let n = sparse.count();
        if n == 0 || n > count {
            bail!("{at}: sparse count {n} is not between 1 and the accessor's count {count}");
        }
        let values = sparse.values();
        self.check_span(
            at,
            "sparse values",
            &values.view(),
            values.offset(),
            n,
            size,
        )?;
        let indices = sparse.indices();
        let width = match indices.index_type() {
            IndexType::U8 => 1,
            IndexType::U16 => 2,
            IndexType::U32 => 4,
        };
        let view = indices.view();
        let offset = indices.offset();
        let bytes = self.check_span(at, "sparse indices", &view, offset, n, width)?;
        let stride = view.stride().unwrap_or(width);
        let mut previous: Option<u32> = None;
        for k in 0..n {
            let b = &bytes[offset + k * stride..][..width];
            let i = match width {
                1 => b[0] as u32,
                2 => u16::from_le_bytes([b[0], b[1]]) as u32,
                _ => u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            };
            if i as usize >= count {
                bail!("{at}: sparse index {i} (entry {k}) is past the accessor's {count} elements");
            }
            if previous.is_some_and(|p| i <= p) {
                bail!(
                    "{at}: sparse indices do not rise strictly (entry {k}: {i} after {})",
                    previous.unwrap_or(0)
                );
            }
            previous = Some(i);
        }
        Ok(())
    }

    /// The index in `materials` of glTF material `m`, converting it on first use.
    fn material(&mut self, m: ::gltf::Material) -> Result<u32> {
        let key = m.index();
        if let Some(&id) = self.material_index.get(&key) {
            return Ok(id);
        }
        let mut mat = match key {
            // No material: the renderer's default grey, not glTF's black metal.
            None => Material::default(),
            Some(_) => convert_material(&m),
        };
        let label = match key {
            Some(i) => format!("{}: materials[{i}]", self.name),
            None => self.name.to_string(),
        };
        let pbr = m.pbr_metallic_roughness();
        if let Some(info) = pbr.base_color_texture() {
            mat.diffuse_map = self.texture(&label, "baseColorTexture", &info, true);
        }
        if let Some(info) = pbr.metallic_roughness_texture() {
            let map = self.texture(&label, "metallicRoughnessTexture", &info, false);
            if let Some(p) = mat.pbr.as_mut() {
                p.map = map;
            }
        }
        if let Some(info) = m.emissive_texture() {
            mat.emission_map = self.texture(&label, "emissiveTexture", &info, true);
        }
        if let Some(n) = m.normal_texture() {
            let scale = n.scale();
            if scale.is_finite() {
                // The gltf crate reads no KHR_texture_transform on a normal texture: its JSON
                // is read here.
                let read = n
                    .extension_value("KHR_texture_transform")
                    .map(|t| self.transform_json(&label, "normalTexture", t));
                let set = read.and_then(|(_, set)| set).unwrap_or(n.tex_coord());
                mat.normal_scale = scale;
                mat.normal_map = self.image_texture(
                    &label,
                    "normalTexture",
                    n.texture(),
                    set,
                    read.map(|(transform, _)| transform),
                    false,
                );
            } else {
                self.warnings.push(format!(
                    "{label}: normalTexture.scale {scale} is not finite; the normal map is not used"
                ));
            }
        }
        if let Some(json) = m.extension_value("KHR_materials_clearcoat") {
            let coat = self.clearcoat(&label, json);
            if let Some(p) = mat.pbr.as_mut() {
                p.clearcoat = coat;
            }
        }
        if let Some(ior) = m.ior().filter(|&i| !valid_ior(i)) {
            self.warnings.push(format!(
                "{label}: KHR_materials_ior.ior {ior} is neither 0 nor at least 1; 1.5 used"
            ));
        }
        if let Some(json) = m.extension_value("KHR_materials_specular") {
            let specular = self.specular(&label, json);
            if let Some(p) = mat.pbr.as_mut() {
                p.specular = super::pbr::Specular {
                    ior: p.specular.ior,
                    ..specular
                };
            }
        }
        if let Some(json) = m.extension_value("KHR_materials_sheen") {
            let sheen = self.sheen(&label, json);
            if let Some(p) = mat.pbr.as_mut() {
                p.sheen = sheen;
            }
        }
        let id = self.materials.len() as u32;
        self.materials.push(mat);
        self.material_index.insert(key, id);
        Ok(id)
    }

    /// A material's `KHR_materials_clearcoat` (`None` when its factor is 0: no coat); a
    /// malformed factor is said in a warning and its default used.
    fn clearcoat(&mut self, label: &str, json: &serde_json::Value) -> Option<Clearcoat> {
        let what = "KHR_materials_clearcoat";
        let factor = self.unit_factor(label, what, json, "clearcoatFactor", 0.0);
        let roughness = self.unit_factor(label, what, json, "clearcoatRoughnessFactor", 0.0);
        if factor == 0.0 {
            return None;
        }
        let mut texture = |key: &str| {
            let info = json.get(key)?;
            self.texture_json(label, &format!("{what}.{key}"), info, false)
        };
        let map = texture("clearcoatTexture");
        let roughness_map = texture("clearcoatRoughnessTexture");
        let normal_map = texture("clearcoatNormalTexture");
        let normal_scale = json
            .get("clearcoatNormalTexture")
            .and_then(|t| t.get("scale"))
            .and_then(serde_json::Value::as_f64)
            .map(|x| x as f32)
            .filter(|x| x.is_finite())
            .unwrap_or(1.0);
        Some(Clearcoat {
            factor,
            roughness,
            map,
            roughness_map,
            normal_map,
            normal_scale,
        })
    }

    /// A material's `KHR_materials_sheen` (`None` when its colour factor is black: no sheen);
    /// a malformed factor is said in a warning and its default used.
    fn sheen(&mut self, label: &str, json: &serde_json::Value) -> Option<SheenLayer> {
        let what = "KHR_materials_sheen";
        let color = self.color_factor(label, what, json, "sheenColorFactor", Vec3::ZERO);
        let roughness = self.unit_factor(label, what, json, "sheenRoughnessFactor", 0.0);
        if color == Vec3::ZERO {
            return None;
        }
        let mut texture = |key: &str, srgb: bool| {
            let info = json.get(key)?;
            self.texture_json(label, &format!("{what}.{key}"), info, srgb)
        };
        let color_map = texture("sheenColorTexture", true);
        let roughness_map = texture("sheenRoughnessTexture", false);
        Some(SheenLayer {
            color,
            roughness,
            color_map,
            roughness_map,
        })
    }

    /// The number `key` of an extension's JSON clamped to `[0, 1]`: `default` where it is
    /// missing, and where it is malformed (not a finite number), with a warning.
    fn unit_factor(
        &mut self,
        label: &str,
        what: &str,
        json: &serde_json::Value,
        key: &str,
        default: f32,
    ) -> f32 {
        match json.get(key) {
            None => default,
            Some(v) => match v.as_f64().map(|x| x as f32).filter(|x| x.is_finite()) {
                Some(x) => x.clamp(0.0, 1.0),
                None => {
                    self.warnings.push(format!(
                        "{label}: {what}.{key} is malformed; {default} used"
                    ));
                    default
                }
            },
        }
    }

    /// The colour `key` of an extension's JSON (three numbers, at least 0): `default` where
    /// it is missing, and where it is malformed, with a warning.
    fn color_factor(
        &mut self,
        label: &str,
        what: &str,
        json: &serde_json::Value,
        key: &str,
        default: Vec3,
    ) -> Vec3 {
        let Some(v) = json.get(key) else {
            return default;
        };
        match serde_json::from_value::<[f32; 3]>(v.clone())
            .ok()
            .filter(|c| c.iter().all(|x| x.is_finite() && *x >= 0.0))
        {
            Some(c) => Vec3::from(c),
            None => {
                let [r, g, b] = default.to_array();
                self.warnings.push(format!(
                    "{label}: {what}.{key} is malformed (three numbers, at least 0); [{r}, {g}, \
                     {b}] used"
                ));
                default
            }
        }
    }

    /// A material's `KHR_materials_specular` (index of refraction left at its default: the
    /// caller keeps `KHR_materials_ior`'s); a malformed factor is said in a warning and its
    /// default used.
    fn specular(&mut self, label: &str, json: &serde_json::Value) -> super::pbr::Specular {
        let what = "KHR_materials_specular";
        let factor = self.unit_factor(label, what, json, "specularFactor", 1.0);
        let color = self.color_factor(label, what, json, "specularColorFactor", Vec3::ONE);
        let map = json.get("specularTexture").and_then(|info| {
            self.texture_json(label, &format!("{what}.specularTexture"), info, false)
        });
        let color_map = json.get("specularColorTexture").and_then(|info| {
            self.texture_json(label, &format!("{what}.specularColorTexture"), info, true)
        });
        super::pbr::Specular {
            factor,
            color,
            map,
            color_map,
            ..super::pbr::Specular::DEFAULT
        }
    }

    /// A texture named by the JSON of a `textureInfo` in an extension the gltf crate does not
    /// read (`srgb`: a colour texture, else linear values): its `index`, `texCoord` and
    /// `KHR_texture_transform`; `None`, with a warning, when it names no texture or its image
    /// cannot be had.
    fn texture_json(
        &mut self,
        label: &str,
        what: &str,
        info: &serde_json::Value,
        srgb: bool,
    ) -> Option<Arc<Texture>> {
        let index = info.get("index").and_then(serde_json::Value::as_u64);
        let Some(tex) = index.and_then(|i| self.doc_textures.get(i as usize).cloned()) else {
            self.warnings
                .push(format!("{label}: {what} names no texture; not used"));
            return None;
        };
        let read = info
            .get("extensions")
            .and_then(|e| e.get("KHR_texture_transform"))
            .map(|t| self.transform_json(label, what, t));
        let own = info
            .get("texCoord")
            .and_then(serde_json::Value::as_u64)
            .map_or(0, |c| u32::try_from(c).unwrap_or(u32::MAX));
        let set = read.and_then(|(_, set)| set).unwrap_or(own);
        self.image_texture(label, what, tex, set, read.map(|(t, _)| t), srgb)
    }

    /// A texture of a material (`srgb`: a colour texture, else linear values), or `None` with
    /// a warning when its image cannot be had.
    fn texture(
        &mut self,
        label: &str,
        what: &str,
        info: &::gltf::texture::Info,
        srgb: bool,
    ) -> Option<Arc<Texture>> {
        let t = info.texture_transform();
        // The extension's `texCoord`, when given, replaces the texture's own.
        let set = t
            .as_ref()
            .and_then(|t| t.tex_coord())
            .unwrap_or(info.tex_coord());
        let transform = t.map(|t| uv_transform(t.offset(), t.rotation(), t.scale()));
        self.image_texture(label, what, info.texture(), set, transform, srgb)
    }

    /// [`Loader::texture`] from its parts: the texture, its coordinate set (`TEXCOORD_0` or
    /// `TEXCOORD_1`; another is read as 0, with a warning) and its `KHR_texture_transform`.
    fn image_texture(
        &mut self,
        label: &str,
        what: &str,
        tex: ::gltf::Texture,
        tex_coord: u32,
        transform: Option<glam::Affine2>,
        srgb: bool,
    ) -> Option<Arc<Texture>> {
        let uv_set = match u8::try_from(tex_coord) {
            Ok(set @ (0 | 1)) => set,
            _ => {
                self.warnings.push(format!(
                    "{label}: {what} uses TEXCOORD_{tex_coord}; only TEXCOORD_0 and TEXCOORD_1 are read, TEXCOORD_0 is read instead"
                ));
                0
            }
        };
        let index = self.texture_image(label, what, &tex)?;
        let image = self.doc_images[index].clone();
        let key = (image.index(), srgb);
        let decoded = match self.textures.get(&key) {
            Some(t) => t.clone(),
            None => {
                let t = match self.image_bytes(&image) {
                    Ok(bytes) => {
                        let name = format!("{}#images[{}]", self.name, image.index());
                        Texture::decode(&name, &bytes, srgb).map(Arc::new)
                    }
                    Err(e) => Err(e),
                };
                let t = match t {
                    Ok(t) => Some(t),
                    Err(e) => {
                        self.warnings
                            .push(format!("{label}: {what} not used ({e:#})"));
                        None
                    }
                };
                self.textures.insert(key, t.clone());
                t
            }
        }?;
        let sampler = tex.sampler();
        let wrap = |w: ::gltf::texture::WrappingMode| match w {
            ::gltf::texture::WrappingMode::ClampToEdge => Wrap::ClampToEdge,
            ::gltf::texture::WrappingMode::MirroredRepeat => Wrap::MirroredRepeat,
            ::gltf::texture::WrappingMode::Repeat => Wrap::Repeat,
        };
        let (wu, wv) = (wrap(sampler.wrap_s()), wrap(sampler.wrap_t()));
        if decoded.wrap_u == wu
            && decoded.wrap_v == wv
            && decoded.transform == transform
            && decoded.uv_set == uv_set
        {
            return Some(decoded);
        }
        // The same image with another sampler, transform or coordinate set: a copy with its
        // own.
        let mut t = (*decoded).clone();
        t.wrap_u = wu;
        t.wrap_v = wv;
        t.transform = transform;
        t.uv_set = uv_set;
        Some(Arc::new(t))
    }

    /// The index of the image a texture shows: its `EXT_texture_webp` source where it names
    /// one (the extension's own rule: a client that reads WebP uses it, the core source being
    /// the fallback for those that do not), else its core source; `None`, with a warning, when
    /// it has neither (a malformed WebP source is said, and the core source used).
    fn texture_image(&mut self, label: &str, what: &str, tex: &::gltf::Texture) -> Option<usize> {
        if let Some(ext) = tex.extension_value("EXT_texture_webp") {
            let source = ext.get("source").and_then(serde_json::Value::as_u64);
            match source
                .and_then(|i| usize::try_from(i).ok())
                .filter(|&i| i < self.doc_images.len())
            {
                Some(i) => return Some(i),
                None => self.warnings.push(format!(
                    "{label}: {what}: textures[{}]'s EXT_texture_webp names no image ({}); its core source used",
                    tex.index(),
                    ext.get("source").map_or("no source".into(), |v| v.to_string())
                )),
            }
        }
        let image = tex.source().map(|i| i.index());
        if image.is_none() {
            self.warnings.push(format!(
                "{label}: {what}: textures[{}] has no image Tracery can read; not used",
                tex.index()
            ));
        }
        image
    }

    /// A `KHR_texture_transform` object as [`uv_transform`] (defaults where a field is missing
    /// or malformed, with a warning for the latter), and its `texCoord` when it has one.
    fn transform_json(
        &mut self,
        label: &str,
        what: &str,
        t: &serde_json::Value,
    ) -> (glam::Affine2, Option<u32>) {
        let mut bad = Vec::new();
        let mut pair = |key: &str, default: [f32; 2]| match t.get(key) {
            None => default,
            Some(v) => match v
                .as_array()
                .map(|a| a.iter().map(serde_json::Value::as_f64).collect::<Vec<_>>())
            {
                Some(a)
                    if a.len() == 2
                        && a.iter().all(|x| x.is_some_and(|v| (v as f32).is_finite())) =>
                {
                    [a[0].unwrap_or(0.0) as f32, a[1].unwrap_or(0.0) as f32]
                }
                _ => {
                    bad.push(key.to_string());
                    default
                }
            },
        };
        let offset = pair("offset", [0.0, 0.0]);
        let scale = pair("scale", [1.0, 1.0]);
        let rotation = match t.get("rotation") {
            None => 0.0,
            Some(v) => match v.as_f64().filter(|x| (*x as f32).is_finite()) {
                Some(r) => r as f32,
                None => {
                    bad.push("rotation".to_string());
                    0.0
                }
            },
        };
        let set = match t.get("texCoord") {
            None => None,
            Some(v) => match v.as_u64().and_then(|c| u32::try_from(c).ok()) {
                Some(c) => Some(c),
                None => {
                    bad.push("texCoord".to_string());
                    None
                }
            },
        };
        if !bad.is_empty() {
            self.warnings.push(format!(
                "{label}: {what}'s KHR_texture_transform has a malformed {}; its default used",
                bad.join(", ")
            ));
        }
        (uv_transform(offset, rotation, scale), set)
    }

    /// The encoded bytes of an image: a buffer view or a URI.
    fn image_bytes(&self, image: &::gltf::Image) -> Result<Vec<u8>> {
        match image.source() {
            ::gltf::image::Source::View { view, .. } => {
                let b = view.buffer().index();
                let data = match self.buffers.get(b) {
                    Some(Ok(d)) => d,
                    Some(Err(why)) => bail!("{why}"),
                    None => bail!("buffers[{b}] does not exist"),
                };
                view.offset()
                    .checked_add(view.length())
                    .and_then(|end| data.get(view.offset()..end))
                    .map(<[u8]>::to_vec)
                    .ok_or_else(|| anyhow!("bufferViews[{}] runs past buffers[{b}]", view.index()))
            }
            ::gltf::image::Source::Uri { uri, .. } => uri_bytes(uri, self.read),
        }
    }

    /// The mesh, with positions placed in a local frame and flat normals where the file has
    /// none; warnings for what was left out.
    fn finish(self) -> Result<GltfData> {
        let mut left: Vec<(String, usize)> = self.left_out.into_iter().collect();
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
        let (origin, local) = super::local_frame(&self.positions);
        let triangles: Vec<[Vec3; 3]> = local.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        let normals: Vec<[Vec3; 3]> = triangles
            .iter()
            .zip(&self.normals)
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
        if triangles.is_empty() {
            self.warnings
                .push(format!("{}: the scene holds no triangles", self.name));
        }
        let mut materials = self.materials;
        if materials.is_empty() {
            materials.push(Material::default());
        }
        let mapped = |i: usize| materials[self.material_ids[i] as usize].has_normal_map();
        let tangents = if (self.any_uvs || self.any_uvs1) && (0..triangles.len()).any(mapped) {
            // MikkTSpace's where the file gives none, the file's where it does; made from the
            // coordinate set the normal map reads.
            // The base's normal map's set, else the coat's.
            let set1 = |i: usize| {
                let m = &materials[self.material_ids[i] as usize];
                let coat = m.pbr.as_ref().and_then(|p| p.clearcoat.as_ref());
                m.normal_map
                    .as_ref()
                    .or(coat.and_then(|c| c.normal_map.as_ref()))
                    .is_some_and(|t| t.uv_set == 1)
            };
            let uvs: Vec<[Vec2; 3]> = (0..triangles.len())
                .map(|i| if set1(i) { self.uvs1[i] } else { self.uvs[i] })
                .collect();
            let mut t = super::tangents::mikktspace(&triangles, &normals, &uvs, |i| {
                mapped(i) && self.tangents[i].is_none()
            });
            for (i, given) in self.tangents.iter().enumerate() {
                if let (Some(given), true) = (given, mapped(i)) {
                    t[i] = given.map(|v| if v.is_finite() { v } else { Vec4::ZERO });
                }
            }
            t
        } else {
            Vec::new()
        };
        Ok(GltfData {
            mesh: Mesh {
                triangles,
                normals,
                material_ids: self.material_ids,
                uvs: if self.any_uvs { self.uvs } else { Vec::new() },
                uvs1: if self.any_uvs1 { self.uvs1 } else { Vec::new() },
                tangents,
                origin,
            },
            materials,
            camera: self.camera,
            lights: self.lights,
            warnings: std::mem::take(self.warnings),
        })
    }
}

/// `KHR_texture_transform` as an affine map of texture coordinates: `T(offset) R(rotation)
/// S(scale)`. The rotation turns the image counter-clockwise as seen (its matrix has columns
/// `(cos, -sin)` and `(sin, cos)` in `(u, v)`, `v` pointing down the image): the extension's
/// sample (`TextureTransformTest`) points its arrow at the green marker this way, and at the
/// red one ("applied in the opposite direction") with the other sign.
pub fn uv_transform(offset: [f32; 2], rotation: f32, scale: [f32; 2]) -> glam::Affine2 {
    let (s, c) = rotation.sin_cos();
    let rotate = glam::Mat2::from_cols(Vec2::new(c, -s), Vec2::new(s, c));
    let m = rotate * glam::Mat2::from_diagonal(Vec2::from(scale));
    glam::Affine2::from_mat2_translation(m, Vec2::from(offset))
}

/// Triangles of a primitive's index list by its mode (strips alternate their winding so every
/// triangle faces the same way; degenerate ones, with a repeated index, are kept: the BVH
/// leaves zero-area triangles out).
fn triangles_of(mode: Mode, idx: &[u32]) -> Vec<[u32; 3]> {
    match mode {
        Mode::Triangles => idx.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        Mode::TriangleStrip => (2..idx.len())
            .map(|i| {
                if i % 2 == 0 {
                    [idx[i - 2], idx[i - 1], idx[i]]
                } else {
                    [idx[i - 1], idx[i - 2], idx[i]]
                }
            })
            .collect(),
        Mode::TriangleFan => (2..idx.len())
            .map(|i| [idx[0], idx[i - 1], idx[i]])
            .collect(),
        _ => Vec::new(),
    }
}

/// A glTF metallic-roughness material as the renderer's [`Material`] (textures are attached by
/// the loader):
/// - diffuse, specular (the GGX lobe's `f0`) and mirror from the base colour, metalness and
///   roughness factors ([`super::pbr::lobes`]), shininess the Blinn-Phong exponent of about
///   the GGX lobe's width (shown, not shaded with); the factors are kept in
///   [`Material::pbr`], from which shading makes the GGX lobe, with the base colour and
///   metallic-roughness textures varying them where a ray meets the surface;
/// - emission: emissive factor times `KHR_materials_emissive_strength`;
/// - opacity: base alpha (times the base colour texture's) for `BLEND`, 0 or 1 against the
///   cutoff for `MASK`, 1 for `OPAQUE`; light through `BLEND` and `MASK` is not tinted;
///   `KHR_materials_transmission` makes it glass: opacity `1 - transmission`, index of
///   refraction from `KHR_materials_ior` (1.5 by default), and `KHR_materials_volume` its
///   absorption inside ([`volume_absorption`]; `thicknessFactor` only says whether there is
///   a volume: the rays measure the real thickness).
pub fn convert_material(m: &::gltf::Material) -> Material {
    let pbr = m.pbr_metallic_roughness();
    let [r, g, b, alpha] = pbr.base_color_factor();
    let base = Vec3::new(r, g, b).clamp(Vec3::ZERO, Vec3::ONE);
    let metallic = pbr.metallic_factor().clamp(0.0, 1.0);
    let roughness = pbr.roughness_factor().clamp(0.0, 1.0);
    // `KHR_materials_ior`: the dielectric's Fresnel, and a glass's refraction.
    let dielectric_ior = m.ior().filter(|&i| valid_ior(i)).unwrap_or(1.5);
    let specular = super::pbr::Specular {
        ior: dielectric_ior,
        ..super::pbr::Specular::DEFAULT
    };
    let lobes = super::pbr::lobes(base, metallic, roughness, specular.at(None, None));
    let strength = m.emissive_strength().unwrap_or(1.0).max(0.0);
    let emission = Vec3::from(m.emissive_factor()).max(Vec3::ZERO) * strength;
    // BLEND and MASK: the base alpha here, times the base colour texture's where shaded
    // (`Material::opacity_at`).
    let alpha = alpha.clamp(0.0, 1.0);
    let (mut opacity, alpha_mode) = match m.alpha_mode() {
        ::gltf::material::AlphaMode::Opaque => (1.0, super::AlphaMode::Opaque),
        ::gltf::material::AlphaMode::Mask => (
            alpha,
            super::AlphaMode::Mask(m.alpha_cutoff().unwrap_or(0.5)),
        ),
        ::gltf::material::AlphaMode::Blend => (alpha, super::AlphaMode::Blend),
    };
    let mut ior = 1.0;
    let mut absorption = Vec3::ZERO;
    if let Some(t) = m.transmission() {
        let t = t.transmission_factor().clamp(0.0, 1.0);
        if t > 0.0 {
            opacity *= 1.0 - t;
            ior = dielectric_ior;
            absorption = m.volume().map_or(Vec3::ZERO, |v| {
                volume_absorption(
                    v.thickness_factor(),
                    Vec3::from(v.attenuation_color()),
                    v.attenuation_distance(),
                )
            });
        }
    }
    Material {
        name: m.name().unwrap_or("material").to_string(),
        diffuse: lobes.diffuse,
        specular: lobes.f0,
        shininess: super::pbr::phong_exponent(lobes.alpha),
        emission,
        opacity,
        ior,
        mirror: lobes.mirror,
        absorption,
        illum: 2,
        diffuse_map: None,
        emission_map: None,
        alpha_mode,
        normal_map: None,
        normal_scale: 1.0,
        height_map: None,
        height_scale: 1.0,
        pbr: Some(super::pbr::MetallicRoughness {
            base,
            metallic,
            roughness,
            map: None,
            clearcoat: None,
            sheen: None,
            specular,
        }),
    }
}

/// True for an index of refraction `KHR_materials_ior` allows: 0 (a dielectric of `f0 = 1`)
/// or at least 1.
fn valid_ior(ior: f32) -> bool {
    ior == 0.0 || (ior >= 1.0 && ior.is_finite())
}

/// The absorption coefficient of a `KHR_materials_volume`: white light turns `color` after
/// `distance` (world units), so `-ln(color) / distance` per channel (Beer-Lambert, the
/// specification's own formula). Zero for a thin-walled surface (`thickness` 0) or a
/// distance that is not positive and finite (the default, infinity: no absorption).
pub fn volume_absorption(thickness: f32, color: Vec3, distance: f32) -> Vec3 {
    if !(thickness > 0.0 && distance > 0.0 && distance.is_finite()) {
        return Vec3::ZERO;
    }
    // A channel of 0 absorbs everything: taken as e^-20 of it per `distance`.
    let c = color.clamp(Vec3::splat((-20.0f32).exp()), Vec3::ONE);
    Vec3::new(-c.x.ln(), -c.y.ln(), -c.z.ln()) / distance
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strips_keep_one_winding_and_fans_turn_about_the_first_vertex() {
        assert_eq!(
            triangles_of(Mode::TriangleStrip, &[0, 1, 2, 3]),
            vec![[0, 1, 2], [2, 1, 3]]
        );
        assert_eq!(
            triangles_of(Mode::TriangleFan, &[0, 1, 2, 3]),
            vec![[0, 1, 2], [0, 2, 3]]
        );
        assert_eq!(
            triangles_of(Mode::Triangles, &[0, 1, 2, 3]),
            vec![[0, 1, 2]]
        );
    }
}
