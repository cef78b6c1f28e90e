//! Scenes: triangles with per-triangle materials, lights, a camera and an environment.
//!
//! Loaded from a scene file (TOML, [`mod@file`]), a bare OBJ with its MTL ([`obj`]), a PLY
//! ([`ply`]) or a glTF 2.0 file ([`gltf`]); or made in code ([`shapes`], [`Scene::cornell_box`]). Every loader reports errors
//! as `file:line: message` where a line is known.

pub mod check;
pub mod file;
pub mod gltf;
mod meshopt;
pub mod normals;
pub mod obj;
pub mod pbr;
pub mod ply;
pub mod shapes;
pub mod tangents;
pub mod texture;

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{Context, Result, bail};
use glam::{DVec3, Vec2, Vec3, Vec4};

use crate::geometry::Aabb;
pub use normals::NormalRule;
pub use texture::{Texture, Wrap};

/// Surface properties, following the MTL file's fields.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// Name (from the MTL file or the scene file).
    pub name: String,
    /// Diffuse colour `Kd`.
    pub diffuse: Vec3,
    /// Specular colour `Ks` (Blinn-Phong highlight).
    pub specular: Vec3,
    /// Specular exponent `Ns`.
    pub shininess: f32,
    /// Emitted radiance `Ke`.
    pub emission: Vec3,
    /// Opacity `d` (`1 - Tr`): 1 is opaque, 0 lets all light through.
    pub opacity: f32,
    /// Index of refraction `Ni`; 1 means light passes without bending.
    pub ior: f32,
    /// Mirror reflectance per channel (MTL `illum` 3, 5 or 7 use `Ks`; scene files set it).
    pub mirror: Vec3,
    /// Absorption coefficient per unit length inside a closed transparent mesh (Beer-Lambert).
    pub absorption: Vec3,
    /// MTL illumination model number, kept for reference.
    pub illum: u32,
    /// Image multiplying `diffuse` (OBJ `map_Kd`, glTF base colour texture), read at the
    /// triangle's texture coordinates.
    pub diffuse_map: Option<Arc<Texture>>,
    /// Image multiplying `emission` (glTF emissive texture).
    pub emission_map: Option<Arc<Texture>>,
    /// How `diffuse_map`'s alpha channel changes `opacity` (glTF `alphaMode`).
    pub alpha_mode: AlphaMode,
    /// Tangent-space normal map (glTF `normalTexture`, linear values), bending the shading
    /// normal where the mesh has tangents ([`Mesh::tangents`], [`tangents`]).
    pub normal_map: Option<Arc<Texture>>,
    /// Scale of the normal map's X and Y (glTF `normalTexture.scale`; 1 as the map is).
    pub normal_scale: f32,
    /// Height map (OBJ's grey `map_Bump` / `bump`, scene files' `height_map`; linear values,
    /// their luminance): the surface is shaded as if displaced along its normal by
    /// `height_scale` times the map's value, in scene units, without moving (bump mapping,
    /// Blinn 1978, as Mitsuba's `bumpmap` does it: [`Material::height_scale`]).
    pub height_map: Option<Arc<Texture>>,
    /// The height map's displacement per unit of its value, in scene units (OBJ's `-bm`,
    /// Mitsuba's `scale`; 1 by default).
    pub height_scale: f32,
    /// Metallic-roughness parameters (glTF materials, and scene-file materials that set
    /// `metallic` or `roughness`; `None` for the others). When set, the surface is shaded
    /// with a GGX lobe made from them ([`pbr::lobes`]) instead of `specular` and `shininess`;
    /// `diffuse`, `specular` (the lobe's `f0`) and `mirror` hold what its factors give, and
    /// where the material has textures, its base colour and metallic-roughness textures are
    /// applied to the factors at each shading point.
    pub pbr: Option<pbr::MetallicRoughness>,
}

/// How a material's opacity depends on the alpha channel of its diffuse texture (glTF
/// `alphaMode`; without a texture, `opacity` alone counts).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum AlphaMode {
    /// The texture's alpha is not read.
    #[default]
    Opaque,
    /// Opacity is `opacity` times the texture's alpha.
    Blend,
    /// Fully opaque where `opacity` times the texture's alpha reaches the cutoff, fully
    /// transparent elsewhere (cut-out leaves, fences).
    Mask(f32),
}

impl Default for Material {
    fn default() -> Self {
        Self {
            name: "default".into(),
            diffuse: Vec3::splat(0.7),
            specular: Vec3::ZERO,
            shininess: 1.0,
            emission: Vec3::ZERO,
            opacity: 1.0,
            ior: 1.0,
            mirror: Vec3::ZERO,
            absorption: Vec3::ZERO,
            illum: 2,
            diffuse_map: None,
            emission_map: None,
            alpha_mode: AlphaMode::Opaque,
            normal_map: None,
            normal_scale: 1.0,
            height_map: None,
            height_scale: 1.0,
            pbr: None,
        }
    }
}

impl Material {
    /// True when some light passes through the surface (somewhere, for a texture's alpha).
    pub fn is_transparent(&self) -> bool {
        self.opacity < 1.0 || self.alpha_from_map()
    }

    /// True when the diffuse texture's alpha channel decides the opacity.
    pub fn alpha_from_map(&self) -> bool {
        self.alpha_mode != AlphaMode::Opaque && self.diffuse_map.is_some()
    }

    /// The opacity where the diffuse texture's alpha is `a` (1 without a texture).
    pub fn opacity_at(&self, a: f32) -> f32 {
        match self.alpha_mode {
            AlphaMode::Opaque => self.opacity,
            AlphaMode::Blend => self.opacity * a,
            AlphaMode::Mask(cutoff) => {
                if self.opacity * a >= cutoff {
                    1.0
                } else {
                    0.0
                }
            }
        }
    }

    /// The colour of light passing through the surface where its opacity is `opacity` and its
    /// diffuse colour `diffuse`: glass and MTL transparency tint by the diffuse colour, glTF
    /// `BLEND` and `MASK` (coverage, not a medium) do not.
    pub fn transmission(&self, opacity: f32, diffuse: Vec3) -> Vec3 {
        let tint = match self.alpha_mode {
            AlphaMode::Opaque => diffuse.min(Vec3::ONE),
            _ => Vec3::ONE,
        };
        (1.0 - opacity) * tint
    }

    /// True when the surface reflects like a mirror (everywhere: its factors say so).
    pub fn is_mirror(&self) -> bool {
        self.mirror.max_element() > 0.0
    }

    /// True when some point of the surface may reflect like a mirror: it is one, or its
    /// metallic-roughness texture may make it one ([`pbr::MetallicRoughness::may_mirror`]).
    pub fn may_mirror(&self) -> bool {
        self.is_mirror() || self.pbr.as_ref().is_some_and(|p| p.may_mirror())
    }

    /// True when some point of the surface may reflect light diffusely or in a highlight
    /// (some diffuse or specular colour, or a metallic-roughness texture that may give one).
    pub fn reflects(&self) -> bool {
        self.diffuse != Vec3::ZERO
            || self.specular != Vec3::ZERO
            || self
                .pbr
                .as_ref()
                .is_some_and(|p| p.is_textured() || p.sheen.is_some())
    }

    /// True when the surface emits light.
    pub fn is_emissive(&self) -> bool {
        self.emission.max_element() > 0.0
    }

    /// True when a texture changes the surface's colour (or, through a metallic-roughness
    /// texture, its lobes) from point to point.
    pub fn is_textured(&self) -> bool {
        self.diffuse_map.is_some()
            || self.emission_map.is_some()
            || self.pbr.as_ref().is_some_and(|p| p.is_textured())
    }

    /// The material's textures: base colour, emission, metallic-roughness, normal map, height
    /// map, the clear coat's, the specular ones and the sheen's.
    pub fn textures(&self) -> impl Iterator<Item = &Arc<Texture>> {
        let coat = self.pbr.as_ref().and_then(|p| p.clearcoat.as_ref());
        let specular = self.pbr.as_ref().map(|p| &p.specular);
        let sheen = self.pbr.as_ref().and_then(|p| p.sheen.as_ref());
        [
            self.diffuse_map.as_ref(),
            self.emission_map.as_ref(),
            self.pbr.as_ref().and_then(|p| p.map.as_ref()),
            self.normal_map.as_ref(),
            self.height_map.as_ref(),
            coat.and_then(|c| c.map.as_ref()),
            coat.and_then(|c| c.roughness_map.as_ref()),
            coat.and_then(|c| c.normal_map.as_ref()),
            specular.and_then(|s| s.map.as_ref()),
            specular.and_then(|s| s.color_map.as_ref()),
            sheen.and_then(|s| s.color_map.as_ref()),
            sheen.and_then(|s| s.roughness_map.as_ref()),
        ]
        .into_iter()
        .flatten()
    }

    /// True when a height map bends the surface's normal (bump mapping; no tangents needed:
    /// the frame comes from each triangle's texture coordinates).
    pub fn has_height_map(&self) -> bool {
        self.height_map.is_some()
    }

    /// True when a normal map bends a normal of the surface: the material's, or its clear
    /// coat's (either needs tangents).
    pub fn has_normal_map(&self) -> bool {
        self.normal_map.is_some()
            || self
                .pbr
                .as_ref()
                .and_then(|p| p.clearcoat.as_ref())
                .is_some_and(|c| c.normal_map.is_some())
    }
}

/// A light source.
#[derive(Clone, Debug, PartialEq)]
pub enum Light {
    /// A point light: radiant intensity `color * intensity`, falling off with the squared
    /// distance.
    Point {
        /// Where the light is.
        position: Vec3,
        /// Colour (linear RGB).
        color: Vec3,
        /// Scale of the colour.
        intensity: f32,
    },
    /// A point light limited to a cone around `direction` (glTF's spot light): full
    /// intensity within `cos_inner` of the axis, none beyond `cos_outer`, a smooth fall-off
    /// between ([`spot_falloff`]).
    Spot {
        /// Where the light is.
        position: Vec3,
        /// Unit axis of the cone: the way the light shines.
        direction: Vec3,
        /// Colour (linear RGB).
        color: Vec3,
        /// Scale of the colour: radiant intensity on the axis.
        intensity: f32,
        /// Cosine of the angle from the axis within which the intensity is full.
        cos_inner: f32,
        /// Cosine of the angle from the axis beyond which there is no light
        /// (`cos_outer < cos_inner`).
        cos_outer: f32,
    },
    /// A one-sided rectangle `corner + s * edge_u + t * edge_v` (`s, t` in `[0, 1]`) emitting
    /// radiance `color * intensity` on the side `edge_u x edge_v` points to.
    Rect {
        /// One corner.
        corner: Vec3,
        /// First edge from the corner.
        edge_u: Vec3,
        /// Second edge from the corner.
        edge_v: Vec3,
        /// Colour (linear RGB).
        color: Vec3,
        /// Scale of the colour.
        intensity: f32,
        /// Shadow rays per shading point.
        samples: u32,
    },
}

impl Light {
    /// Where a point or spot light is and the radiant intensity it sends towards `p` (a
    /// spot's scaled by its cone's fall-off, [`spot_falloff`]); `None` where a spot sends
    /// nothing (no shadow ray is needed there) and for a rectangle light, which is not a point.
    pub fn point_towards(&self, p: Vec3) -> Option<(Vec3, Vec3)> {
        match *self {
            Light::Point {
                position,
                color,
                intensity,
            } => Some((position, color * intensity)),
            Light::Spot {
                position,
                direction,
                color,
                intensity,
                cos_inner,
                cos_outer,
            } => {
                let share =
                    spot_falloff(direction, cos_inner, cos_outer, (p - position).normalize());
                (share > 0.0).then(|| (position, color * intensity * share))
            }
            Light::Rect { .. } => None,
        }
    }

    /// Centre of the light (its position for a point light).
    pub fn center(&self) -> Vec3 {
        match self {
            Light::Point { position, .. } | Light::Spot { position, .. } => *position,
            Light::Rect {
                corner,
                edge_u,
                edge_v,
                ..
            } => *corner + 0.5 * (*edge_u + *edge_v),
        }
    }
}

/// The share of a spot light's intensity sent along unit direction `d` (from the light): 1
/// within `cos_inner` of the axis `direction`, 0 beyond `cos_outer`, and between them the
/// square of the linear ramp in the cosine, the fall-off the glTF specification suggests for
/// `KHR_lights_punctual`.
pub fn spot_falloff(direction: Vec3, cos_inner: f32, cos_outer: f32, d: Vec3) -> f32 {
    let scale = 1.0 / (cos_inner - cos_outer).max(1e-3);
    let t = ((direction.dot(d) - cos_outer) * scale).clamp(0.0, 1.0);
    t * t
}

/// A pinhole or thin-lens camera.
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    /// Eye position.
    pub position: Vec3,
    /// Point the camera looks at.
    pub look_at: Vec3,
    /// Up direction (need not be orthogonal to the view direction).
    pub up: Vec3,
    /// Vertical field of view in degrees.
    pub vfov_deg: f32,
    /// Lens radius; 0 is a pinhole.
    pub lens_radius: f32,
    /// Distance to the plane in focus.
    pub focus_distance: f32,
}

impl Camera {
    /// The benchmark camera of DESIGN.md for a scene with bounds `b`: center `c`, radius
    /// `r = |max - min| / 2`, eye `c + (0, 0.25 r, 2.2 r)`, looking at `c`, up `+y`, 45 degrees.
    pub fn canonical(b: &Aabb) -> Self {
        let (c, r) = if b.is_empty() {
            (Vec3::ZERO, 1.0)
        } else {
            let c = Vec3::from(b.center());
            let r = (Vec3::from(b.max) - Vec3::from(b.min)).length() * 0.5;
            (c, if r > 0.0 && r.is_finite() { r } else { 1.0 })
        };
        let position = c + Vec3::new(0.0, 0.25 * r, 2.2 * r);
        Self {
            position,
            look_at: c,
            up: Vec3::Y,
            vfov_deg: 45.0,
            lens_radius: 0.0,
            focus_distance: (position - c).length(),
        }
    }
}

/// What rays that leave the scene see.
#[derive(Clone, Debug, PartialEq)]
pub enum Environment {
    /// Black.
    None,
    /// One colour in every direction.
    Color(Vec3),
    /// The procedural sky (no files).
    Sky {
        /// Brightness scale.
        intensity: f32,
        /// Rotation about +y in degrees.
        rotation_deg: f32,
    },
    /// Six images, in the order +x, -x, +y, -y, +z, -z.
    CubeMap {
        /// The face images.
        faces: [PathBuf; 6],
        /// Brightness scale.
        intensity: f32,
        /// Rotation about +y in degrees.
        rotation_deg: f32,
    },
    /// One equirectangular image (HDR, EXR, PNG or JPEG).
    Equirect {
        /// The image.
        path: PathBuf,
        /// Brightness scale.
        intensity: f32,
        /// Rotation about +y in degrees.
        rotation_deg: f32,
    },
}

/// Triangles with their shading normals and materials, in file order.
///
/// Positions are f32 relative to `origin`, an f64 point in world coordinates: files are read in
/// f64 and placed near their own centre, so a mesh a million units from the world's origin keeps
/// the precision it has at the origin (a float at 1e6 is 1/16 apart).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// Vertex positions relative to `origin`, three per triangle.
    pub triangles: Vec<[Vec3; 3]>,
    /// Shading normals, three per triangle (computed when the file has none).
    pub normals: Vec<[Vec3; 3]>,
    /// Index into [`Scene::materials`] per triangle.
    pub material_ids: Vec<u32>,
    /// Texture coordinates, three per triangle; empty when no triangle has any (a triangle
    /// without them among others that have them gets `(0, 0)`).
    pub uvs: Vec<[Vec2; 3]>,
    /// A second set of texture coordinates (glTF `TEXCOORD_1`), read by textures whose
    /// [`Texture::uv_set`] is 1; empty unless a triangle's material has such a texture.
    pub uvs1: Vec<[Vec2; 3]>,
    /// Tangents for normal maps, three per triangle (xyz along `+u`, w the bitangent's sign:
    /// see [`tangents`]); empty when no triangle has any, [`Vec4::ZERO`] for a triangle
    /// without (its material has no normal map).
    pub tangents: Vec<[Vec4; 3]>,
    /// World position of the mesh's local origin (what the user sees is `origin + position`).
    pub origin: DVec3,
}

/// Appends per-triangle values that a mesh may leave empty (texture coordinates, tangents):
/// `mine` holds them for triangles `..before` or is empty, `other` for the triangles appended
/// (up to `after`) or is empty; an empty side is filled with `none` when the other has some.
fn append_optional<T: Copy>(
    mine: &mut Vec<T>,
    other: Vec<T>,
    before: usize,
    after: usize,
    none: T,
) {
    if mine.is_empty() && other.is_empty() {
        return;
    }
    mine.resize(before, none);
    if other.is_empty() {
        mine.resize(after, none);
    } else {
        mine.extend(other);
    }
}

impl Mesh {
    /// Appends another mesh, shifting its material ids by `material_offset`.
    pub fn append(&mut self, other: Mesh, material_offset: u32) {
        if self.triangles.is_empty() {
            self.origin = other.origin;
        }
        let delta = other.origin - self.origin;
        if delta == DVec3::ZERO {
            self.triangles.extend(other.triangles);
        } else {
            // Rebased in f64: each vertex rounds once, to the float nearest its position here.
            self.triangles.extend(
                other
                    .triangles
                    .iter()
                    .map(|t| t.map(|v| (delta + v.as_dvec3()).as_vec3())),
            );
        }
        let before = self.normals.len();
        self.normals.extend(other.normals);
        let after = self.normals.len();
        append_optional(&mut self.uvs, other.uvs, before, after, [Vec2::ZERO; 3]);
        append_optional(&mut self.uvs1, other.uvs1, before, after, [Vec2::ZERO; 3]);
        append_optional(
            &mut self.tangents,
            other.tangents,
            before,
            after,
            [Vec4::ZERO; 3],
        );
        self.material_ids
            .extend(other.material_ids.into_iter().map(|m| m + material_offset));
    }

    /// The texture coordinate of set `set` (0, or 1 for [`Mesh::uvs1`]) at barycentric
    /// `(u, v)` of triangle `prim` (`(0, 0)` when the mesh has none).
    pub fn uv_at(&self, set: u8, prim: u32, u: f32, v: f32) -> Vec2 {
        let uvs = if set == 0 { &self.uvs } else { &self.uvs1 };
        match uvs.get(prim as usize) {
            Some(t) => t[0] * (1.0 - u - v) + t[1] * u + t[2] * v,
            None => Vec2::ZERO,
        }
    }

    /// The tangent at barycentric `(u, v)` of triangle `prim` ([`Vec4::ZERO`] when it has
    /// none): the corners' tangents interpolated, the sign that of the first corner (a
    /// triangle's corners share one unless the texture is mirrored across it).
    pub fn tangent_at(&self, prim: u32, u: f32, v: f32) -> Vec4 {
        match self.tangents.get(prim as usize) {
            Some(t) => {
                let xyz =
                    t[0].truncate() * (1.0 - u - v) + t[1].truncate() * u + t[2].truncate() * v;
                xyz.extend(t[0].w)
            }
            None => Vec4::ZERO,
        }
    }

    /// Builds a mesh from an indexed triangle list, with normals computed by `rule`
    /// ([`normals`]; `groups` holds each face's smoothing group for [`NormalRule::Groups`]).
    /// Indices must be in range.
    pub fn from_indexed(
        positions: &[Vec3],
        indices: &[[u32; 3]],
        material: u32,
        rule: NormalRule,
        groups: &[u32],
    ) -> Mesh {
        let normals = normals::corner_normals(positions, indices, rule, groups);
        let triangles = indices
            .iter()
            .map(|f| f.map(|i| positions[i as usize]))
            .collect();
        Mesh {
            triangles,
            normals,
            material_ids: vec![material; indices.len()],
            uvs: Vec::new(),
            uvs1: Vec::new(),
            tangents: Vec::new(),
            origin: DVec3::ZERO,
        }
    }

    /// Builds a mesh from a triangle soup with flat normals.
    pub fn from_triangles(triangles: Vec<[Vec3; 3]>, material: u32) -> Mesh {
        let normals = triangles.iter().map(|t| [face_normal(t); 3]).collect();
        let material_ids = vec![material; triangles.len()];
        Mesh {
            triangles,
            normals,
            material_ids,
            uvs: Vec::new(),
            uvs1: Vec::new(),
            tangents: Vec::new(),
            origin: DVec3::ZERO,
        }
    }

    /// Applies an affine transform to positions and normals.
    pub fn transform(&mut self, m: &glam::DAffine3) {
        // World position T(origin + v) = T(origin) + L v: the origin moves in f64, the local
        // positions only turn and scale.
        let linear = m.matrix3.as_mat3();
        let normal_m = glam::Mat3A::from(linear).inverse().transpose();
        self.origin = m.transform_point3(self.origin);
        for t in &mut self.triangles {
            *t = t.map(|v| linear * v);
        }
        for n in &mut self.normals {
            *n = n.map(|v| Vec3::from(normal_m * glam::Vec3A::from(v)).normalize_or_zero());
        }
        // Tangents lie in the surface: they turn as positions do; a mirroring transform turns
        // the bitangent's handedness.
        let sign = if linear.determinant() < 0.0 {
            -1.0
        } else {
            1.0
        };
        for t in &mut self.tangents {
            *t = t.map(|v| {
                if v == Vec4::ZERO {
                    return v;
                }
                (linear * v.truncate())
                    .normalize_or_zero()
                    .extend(v.w * sign)
            });
        }
    }

    /// Moves the local frame to `origin` (world coordinates), each vertex rounded once.
    pub fn rebase(&mut self, origin: DVec3) {
        let delta = self.origin - origin;
        if delta != DVec3::ZERO {
            for t in &mut self.triangles {
                *t = t.map(|v| (delta + v.as_dvec3()).as_vec3());
            }
        }
        self.origin = origin;
    }

    /// Puts the local frame back at the world's origin when the mesh spans or nears it (the
    /// rule of [`local_frame`]), so a scene near the origin has the coordinates it is given.
    pub fn settle_origin(&mut self) {
        let b = self.bounds();
        if self.origin == DVec3::ZERO || b.is_empty() {
            return;
        }
        let (lo, hi) = (Vec3::from(b.min).as_dvec3(), Vec3::from(b.max).as_dvec3());
        let centre = self.origin + 0.5 * (lo + hi);
        if centre.abs().max_element() <= (hi - lo).max_element().max(1.0) {
            self.rebase(DVec3::ZERO);
        }
    }

    /// Box around all finite vertices.
    pub fn bounds(&self) -> Aabb {
        Aabb::of_finite_points(self.triangles.iter().flatten().copied())
    }
}

/// Unit normal of a triangle (`+z` for a degenerate one).
pub fn face_normal(t: &[Vec3; 3]) -> Vec3 {
    (t[1] - t[0])
        .cross(t[2] - t[0])
        .try_normalize()
        .unwrap_or(Vec3::Z)
}

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
    /// All triangles of all meshes, in file order.
    pub mesh: Mesh,
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
    /// Problems found while loading that did not stop it (a missing MTL file, say).
    pub warnings: Vec<String>,
}

impl Scene {
    /// Loads a scene file (`.toml`), an OBJ (`.obj`, with its MTL), a PLY (`.ply`) or a glTF
    /// (`.gltf`, `.glb`).
    pub fn load(path: &Path) -> Result<Scene> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase());
        match ext.as_deref() {
            Some("toml") => file::load(path),
            Some("obj") => {
                let d = obj::load(path)?;
                let mut scene = Scene::from_mesh(name_of(path), d.mesh, d.materials);
                scene.warnings = d.warnings;
                Ok(scene)
            }
            Some("ply") => {
                let mesh = ply::load(path)?;
                Ok(Scene::from_mesh(
                    name_of(path),
                    mesh,
                    vec![Material::default()],
                ))
            }
            Some("gltf" | "glb") => gltf::load(path),
            _ => bail!(
                "{}: unknown file type (expected .toml, .obj, .ply, .gltf or .glb)",
                path.display()
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
        let b = mesh.bounds();
        let camera = Camera::canonical(&b);
        let r = (camera.position - camera.look_at).length() / 2.2;
        let position = camera.position + Vec3::new(r, 2.0 * r, 0.0);
        let d2 = (position - camera.look_at).length_squared();
        let materials = if materials.is_empty() {
            vec![Material::default()]
        } else {
            materials
        };
        Scene {
            name,
            mesh,
            materials,
            lights: vec![Light::Point {
                position,
                color: Vec3::ONE,
                intensity: std::f32::consts::PI * d2,
            }],
            camera,
            environment: Environment::Sky {
                intensity: 0.3,
                rotation_deg: 0.0,
            },
            integrator: Integrator::Direct,
            warnings: Vec::new(),
        }
    }

    /// The project's Cornell box (32 triangles: five walls, the ceiling light, two blocks),
    /// from the scene and model files built into the binary.
    pub fn cornell_box() -> Scene {
        file::load_embedded_cornell_box()
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.mesh.triangles.len()
    }

    /// The material of triangle `prim`.
    pub fn material_of(&self, prim: u32) -> &Material {
        &self.materials[self.mesh.material_ids[prim as usize] as usize]
    }
}

/// A local frame for positions read in f64: an origin near the finite ones' centre (the world
/// origin for a mesh near it), and every position relative to it in f32 (non-finite ones stay
/// non-finite).
pub fn local_frame(positions: &[DVec3]) -> (DVec3, Vec<Vec3>) {
    let (lo, hi) = positions
        .iter()
        .filter(|p| p.is_finite())
        .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(*p), hi.max(*p))
        });
    if !lo.cmple(hi).all() {
        return (DVec3::ZERO, positions.iter().map(|p| p.as_vec3()).collect());
    }
    let (centre, extent) = (0.5 * (lo + hi), (hi - lo).max_element());
    // A mesh that already spans or nears the origin stays where it is (nothing to gain, and
    // the same floats as ever); one farther away is placed about its centre, rounded to a
    // power of two no smaller than its size so local coordinates stay short.
    let centre = if centre.abs().max_element() <= extent.max(1.0) {
        DVec3::ZERO
    } else {
        let step = extent.max(f64::MIN_POSITIVE).log2().ceil().exp2();
        (centre / step).round() * step
    };
    (
        centre,
        positions.iter().map(|p| (*p - centre).as_vec3()).collect(),
    )
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

/// Reads files named relative to `path`'s folder (an OBJ's MTL and images, a glTF's buffers
/// and images), naming each in its error.
pub(crate) fn beside(path: &Path) -> impl Fn(&Path) -> Result<Vec<u8>> {
    let dir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
    move |p: &Path| read_file(&dir.join(p))
}

/// Splits the byte offset `pos` of `text` into a 1-based line number.
pub(crate) fn line_of(text: &str, pos: usize) -> usize {
    text[..pos.min(text.len())].matches('\n').count() + 1
}
