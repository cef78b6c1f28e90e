//! Scene files (TOML): meshes with transforms and material overrides, materials, lights,
//! camera and environment. Paths resolve relative to the scene file; unknown keys, wrong types
//! and missing files are errors that name the file and line.
//!
//! ```toml
//! [camera]
//! position = [0.0, 1.0, 3.9]
//! look_at = [0.0, 1.0, 0.0]
//! fov = 40.0                 # vertical, degrees (default 45)
//!
//! [materials.white]
//! diffuse = [0.73, 0.73, 0.73]
//!
//! [materials.brass]
//! diffuse = [0.9, 0.7, 0.3]  # the base colour when metallic or roughness is set
//! metallic = 1.0             # glTF's metallic-roughness model, a GGX lobe (default 0)
//! roughness = 0.3            # (default 1); not with specular, shininess or mirror
//!
//! [materials.velvet]
//! diffuse = [0.3, 0.02, 0.05]
//! sheen = [1.0, 0.55, 0.6]   # glTF's sheen layer (cloth) over the metallic-roughness model
//! sheen_roughness = 0.5      # (default 0.5)
//!
//! [materials.bumpy]
//! diffuse = [0.8, 0.8, 0.8]
//! normal_map = "bumps.png"   # tangent-space normal map (+Y up); needs texture coordinates
//! normal_scale = 1.0         # its X and Y scaled (default 1)
//!
//! [materials.hammered]
//! diffuse = [0.8, 0.8, 0.8]
//! height_map = "dents.png"   # bump mapping (not with normal_map); needs texture coordinates
//! height_scale = 0.01        # displacement per unit of the map's value, scene units (default 1)
//!
//! [[meshes]]
//! path = "../models/cornell_box.obj"
//!
//! [[meshes]]
//! shape = "sphere"           # or "cube", "quad" (unit shapes), instead of a path
//! translate = [0.5, 0.3, 0.2]
//! scale = 0.3
//! material = "white"
//!
//! [[meshes]]
//! path = "bunny.obj"
//! crease_angle = 60.0        # computed normals smooth below 60 degrees (default: the file's rule)
//!
//! [[meshes]]
//! path = "dragon.ply"
//! scale = 0.5
//! grid = { count = [10, 1, 10], step = [1.2, 0.0, 1.2], turn = 37.0 }
//!                            # 100 copies of one mesh held once (instances), each moved by a
//!                            # step along x, y and z from the entry's place and turned `turn`
//!                            # degrees about y more than the one before (default 0)
//!
//! [[lights]]
//! kind = "rect"
//! corner = [-0.25, 1.98, -0.25]
//! edge_u = [0.5, 0.0, 0.0]
//! edge_v = [0.0, 0.0, 0.5]
//! intensity = 15.0
//!
//! [[lights]]
//! kind = "spot"              # or "point" (position, color, intensity only)
//! position = [0.0, 1.9, 0.0]
//! direction = [0.0, -1.0, 0.0]
//! inner_angle = 20.0         # degrees from the axis at full intensity (default 0)
//! outer_angle = 35.0         # degrees from the axis where the light ends (default 45, at most 90)
//! intensity = 2.0
//!
//! [environment]
//! kind = "sky"               # none, color, sky (the default), cubemap, equirect
//!
//! [render]
//! integrator = "path"        # or "direct" (the default): global illumination or direct light
//! ```

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Result, anyhow, bail};
use glam::{DAffine3, DQuat, DVec3, EulerRot, Vec3};
use serde::Deserialize;
use toml::Spanned;

use super::format::{self, Format, MeshFile};
use super::{
    Camera, Environment, Integrator, Light, Material, Mesh, NormalRule, Runs, Scene, Texture,
    line_of, name_of, read_file,
};
use crate::geometry::shapes;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SceneDef {
    camera: Option<CameraDef>,
    #[serde(default)]
    materials: BTreeMap<String, MaterialDef>,
    #[serde(default)]
    meshes: Vec<Spanned<MeshDef>>,
    #[serde(default)]
    lights: Vec<Spanned<LightDef>>,
    environment: Option<Spanned<EnvDef>>,
    render: Option<RenderDef>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RenderDef {
    integrator: Option<Integrator>,
    energy_compensation: Option<bool>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraDef {
    position: [f64; 3],
    look_at: [f64; 3],
    up: Option<[f32; 3]>,
    fov: Option<f32>,
    lens_radius: Option<f32>,
    focus_distance: Option<f32>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct MaterialDef {
    diffuse: Option<[f32; 3]>,
    specular: Option<[f32; 3]>,
    shininess: Option<f32>,
    emission: Option<[f32; 3]>,
    opacity: Option<f32>,
    ior: Option<f32>,
    mirror: Option<[f32; 3]>,
    absorption: Option<[f32; 3]>,
    normal_map: Option<Spanned<String>>,
    normal_scale: Option<Spanned<f32>>,
    height_map: Option<Spanned<String>>,
    height_scale: Option<Spanned<f32>>,
    metallic: Option<Spanned<f32>>,
    roughness: Option<Spanned<f32>>,
    sheen: Option<Spanned<[f32; 3]>>,
    sheen_roughness: Option<Spanned<f32>>,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(rename_all = "lowercase")]
enum ShapeDef {
    Sphere,
    Cube,
    Quad,
}

#[derive(Deserialize)]
#[serde(untagged)]
enum ScaleDef {
    Uniform(f64),
    PerAxis([f64; 3]),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MeshDef {
    path: Option<Spanned<String>>,
    shape: Option<ShapeDef>,
    subdivisions: Option<u32>,
    translate: Option<[f64; 3]>,
    /// Degrees about x, then y, then z.
    rotate: Option<[f64; 3]>,
    scale: Option<ScaleDef>,
    material: Option<Spanned<String>>,
    /// Normals the mesh file does not give: smooth across edges below this angle (degrees;
    /// 0 is flat), instead of the file type's own rule.
    crease_angle: Option<Spanned<f32>>,
    /// Copies of the mesh on a grid, the mesh held once.
    grid: Option<Spanned<GridDef>>,
}

/// A grid of copies of a mesh entry: `count[a]` copies along axis `a`, `step[a]` apart, each
/// turned `turn` degrees about its own vertical axis more than the one before.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct GridDef {
    count: [u32; 3],
    step: [f64; 3],
    turn: Option<f64>,
}

/// The most placements a scene file's grids may make.
pub const MAX_PLACEMENTS: u64 = 1_000_000;

#[derive(Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
enum LightDef {
    Point {
        position: [f64; 3],
        color: Option<[f32; 3]>,
        intensity: Option<f32>,
    },
    Spot {
        position: [f64; 3],
        direction: [f32; 3],
        color: Option<[f32; 3]>,
        intensity: Option<f32>,
        inner_angle: Option<f32>,
        outer_angle: Option<f32>,
    },
    Rect {
        corner: [f64; 3],
        edge_u: [f32; 3],
        edge_v: [f32; 3],
        color: Option<[f32; 3]>,
        intensity: Option<f32>,
        samples: Option<u32>,
    },
}

#[derive(Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
enum EnvDef {
    None,
    Color {
        color: [f32; 3],
    },
    Sky {
        intensity: Option<f32>,
        rotation: Option<f32>,
    },
    Cubemap {
        faces: [String; 6],
        intensity: Option<f32>,
        rotation: Option<f32>,
    },
    Equirect {
        path: String,
        intensity: Option<f32>,
        rotation: Option<f32>,
    },
}

/// A scene file's `sheen_roughness` when only `sheen` is given: glTF's default of 0 would
/// show almost nothing but at the silhouettes.
const DEFAULT_SHEEN_ROUGHNESS: f32 = 0.5;

/// What one `[[meshes]]` entry's file or shape gives.
struct Part {
    /// The triangles it places once.
    mesh: Mesh,
    /// Its materials.
    materials: Vec<Material>,
    /// The meshes its file places many times, each in its own frame.
    shared: Vec<Mesh>,
    /// Their placements: a mesh of `shared` and its transform within the file.
    placed: Vec<(u32, DAffine3)>,
    /// The objects `mesh`'s triangles make.
    objects: Runs,
}

/// What a scene file's `[[meshes]]` make.
struct Meshes {
    /// The entries placed once, as one mesh.
    mesh: Mesh,
    /// The meshes of the entries with a grid, each in its own frame.
    shared: Vec<Mesh>,
    /// Each grid copy: its mesh in `shared` and its transform to the world.
    placed: Vec<(u32, DAffine3)>,
    /// The objects `mesh`'s triangles make.
    objects: Runs,
    /// The files' warnings.
    warnings: Vec<String>,
    /// The longest animation of the glTF meshes, if any has one.
    animation: Option<f32>,
}

/// Reads files a scene refers to (the disk, or the files built into the binary).
type ReadFn<'a> = &'a dyn Fn(&Path) -> Result<Vec<u8>>;

/// Loads a scene file from disk.
pub fn load(path: &Path) -> Result<Scene> {
    load_at(path, None)
}

/// Loads a scene file from disk, its glTF meshes' animations played to `time` (seconds; see
/// [`super::gltf::load_from`]).
pub fn load_at(path: &Path, time: Option<f64>) -> Result<Scene> {
    let bytes = read_file(path)?;
    let text =
        String::from_utf8(bytes).map_err(|_| anyhow!("{}: not UTF-8 text", path.display()))?;
    parse_at(path, &text, &|p: &Path| read_file(p), true, time)
}

const CORNELL_TOML: &str = include_str!("../../assets/scenes/cornell_box.toml");
const CORNELL_OBJ: &[u8] = include_bytes!("../../assets/models/cornell_box.obj");
const CORNELL_MTL: &[u8] = include_bytes!("../../assets/models/cornell_box.mtl");

/// The Cornell box from the copies of its files built into the binary.
pub(super) fn load_embedded_cornell_box() -> Scene {
    let read = |p: &Path| -> Result<Vec<u8>> {
        match p.file_name().and_then(|n| n.to_str()) {
            Some("cornell_box.obj") => Ok(CORNELL_OBJ.to_vec()),
            Some("cornell_box.mtl") => Ok(CORNELL_MTL.to_vec()),
            _ => bail!("{}: not built in", p.display()),
        }
    };
    parse(
        Path::new("assets/scenes/cornell_box.toml"),
        CORNELL_TOML,
        &read,
        false,
    )
    .expect("the built-in Cornell box scene is valid (checked by a test)")
}

/// What the parse of one scene file reads from: the file's name and text (for messages), its
/// folder (paths in it are relative to it), how files are read, and whether environment images
/// must exist.
struct Ctx<'a> {
    path: &'a Path,
    text: &'a str,
    dir: PathBuf,
    read: ReadFn<'a>,
    check_files: bool,
    /// The instant the glTF meshes' animations are played to, if any.
    time: Option<f64>,
}

impl Ctx<'_> {
    /// An error at byte `pos` of the file: `file:line: msg`.
    fn at(&self, pos: usize, msg: String) -> anyhow::Error {
        anyhow!("{}:{}: {msg}", self.path.display(), line_of(self.text, pos))
    }

    /// A path the file names, relative to its folder.
    fn resolve(&self, p: &str) -> PathBuf {
        self.dir.join(p)
    }

    /// The `[materials]` tables in order, and each one's index by name.
    fn materials(
        &self,
        defs: &BTreeMap<String, MaterialDef>,
    ) -> Result<(Vec<Material>, BTreeMap<String, u32>)> {
        let mut materials = Vec::new();
        let mut by_name = BTreeMap::new();
        for (name, m) in defs {
            by_name.insert(name.clone(), materials.len() as u32);
            materials.push(self.material(name, m)?);
        }
        Ok((materials, by_name))
    }

    /// The material `name`: its fields checked (the metallic-roughness model or Blinn-Phong,
    /// not both), its normal or height map read.
    fn material(&self, name: &str, m: &MaterialDef) -> Result<Material> {
        let mut mat = material_from_def(name, m);
        let (metallic, roughness) = (&m.metallic, &m.roughness);
        if let Some(sr) = &m.sheen_roughness
            && m.sheen.is_none()
        {
            return Err(self.at(
                sr.span().start,
                format!("material `{name}`: `sheen_roughness` without `sheen` (its colour)"),
            ));
        }
        let first = [metallic, roughness]
            .into_iter()
            .flatten()
            .map(|v| v.span().start)
            .chain(m.sheen.as_ref().map(|v| v.span().start))
            .next();
        if let Some(first) = first {
            for (key, value) in [
                ("metallic", metallic),
                ("roughness", roughness),
                ("sheen_roughness", &m.sheen_roughness),
            ] {
                if let Some(value) = value
                    && !(0.0..=1.0).contains(value.get_ref())
                {
                    return Err(self.at(
                        value.span().start,
                        format!("{key} {} is not in [0, 1]", value.get_ref()),
                    ));
                }
            }
            if m.specular.is_some() || m.shininess.is_some() || m.mirror.is_some() {
                return Err(self.at(
                    first,
                    format!(
                        "material `{name}`: `metallic`, `roughness` and `sheen` (glTF's \
                     metallic-roughness model) cannot be combined with `specular`, \
                     `shininess` or `mirror` (Blinn-Phong and a mirror)"
                    ),
                ));
            }
            if let Some(sheen) = &m.sheen
                && !sheen.get_ref().iter().all(|c| c.is_finite() && *c >= 0.0)
            {
                return Err(self.at(
                    sheen.span().start,
                    format!(
                        "sheen {:?} is not a colour (three finite numbers, at least 0)",
                        sheen.get_ref()
                    ),
                ));
            }
            let pbr = super::pbr::MetallicRoughness {
                base: mat.diffuse.clamp(Vec3::ZERO, Vec3::ONE),
                metallic: metallic.as_ref().map_or(0.0, |v| *v.get_ref()),
                roughness: roughness.as_ref().map_or(1.0, |v| *v.get_ref()),
                map: None,
                clearcoat: None,
                sheen: m
                    .sheen
                    .as_ref()
                    .map(|c| Vec3::from(*c.get_ref()))
                    .filter(|&c| c != Vec3::ZERO)
                    .map(|color| super::pbr::SheenLayer {
                        color,
                        roughness: m
                            .sheen_roughness
                            .as_ref()
                            .map_or(DEFAULT_SHEEN_ROUGHNESS, |r| *r.get_ref()),
                        color_map: None,
                        roughness_map: None,
                    }),
                specular: super::pbr::Specular::DEFAULT,
            };
            let lobes = pbr.lobes_at(super::pbr::Texels::default());
            mat.diffuse = lobes.diffuse;
            mat.specular = lobes.f0;
            mat.shininess = super::pbr::phong_exponent(lobes.alpha);
            mat.mirror = lobes.mirror;
            mat.pbr = Some(pbr);
        }
        if let (Some(_), Some(height)) = (&m.normal_map, &m.height_map) {
            return Err(self.at(
                height.span().start,
                "a material takes a normal_map or a height_map, not both".into(),
            ));
        }
        for (key, scale, slot) in [
            ("normal_scale", &m.normal_scale, &mut mat.normal_scale),
            ("height_scale", &m.height_scale, &mut mat.height_scale),
        ] {
            if let Some(scale) = scale {
                if !scale.get_ref().is_finite() {
                    return Err(self.at(
                        scale.span().start,
                        format!("{key} {} is not a finite number", scale.get_ref()),
                    ));
                }
                *slot = *scale.get_ref();
            }
        }
        for (key, map, slot) in [
            ("normal_map", &m.normal_map, &mut mat.normal_map),
            ("height_map", &m.height_map, &mut mat.height_map),
        ] {
            if let Some(map) = map {
                let file = self.resolve(map.get_ref());
                let texture = (self.read)(&file)
                    .and_then(|bytes| Texture::decode(&file.display().to_string(), &bytes, false))
                    .map_err(|e| self.at(map.span().start, format!("{key}: {e:#}")))?;
                *slot = Some(std::sync::Arc::new(texture));
            }
        }
        Ok(mat)
    }

    /// The `[[meshes]]` entries, each placed by its transform, as one mesh, and the entries
    /// with a `grid` as meshes placed many times; the materials of mesh files appended to
    /// `materials` (an entry with `material` uses that one instead). Returns the mesh, the
    /// grids' meshes and placements, the warnings of the files, and the longest animation.
    fn meshes(
        &self,
        defs: &[Spanned<MeshDef>],
        materials: &mut Vec<Material>,
        by_name: &BTreeMap<String, u32>,
    ) -> Result<Meshes> {
        let mut mesh = Mesh::default();
        let mut objects = Runs::default();
        let mut shared = Vec::new();
        let mut placed = Vec::new();
        let mut placements = 0u64;
        let mut triangles = 0u64;
        let mut warnings = Vec::new();
        // The longest animation of the glTF meshes, if any has one.
        let mut animation: Option<f32> = None;
        for m in defs {
            let span = m.span();
            let m = m.get_ref();
            let override_id = match &m.material {
                Some(name) => Some(*by_name.get(name.get_ref()).ok_or_else(|| {
                    self.at(
                        name.span().start,
                        format!(
                            "unknown material `{}` (defined: {})",
                            name.get_ref(),
                            by_name.keys().cloned().collect::<Vec<_>>().join(", ")
                        ),
                    )
                })?),
                None => None,
            };
            let copies = match &m.grid {
                Some(g) => self.grid(g)?,
                None => Vec::new(),
            };
            let Part {
                mesh: part,
                materials: part_materials,
                shared: inner,
                placed: inner_placed,
                objects: part_objects,
            } = self.mesh_part(m, &span, &mut warnings, &mut animation)?;
            // The bounds, checked before a placement is made: each copy places the entry's
            // mesh and the meshes its file places many times.
            let per_copy = inner_placed.len() as u64 + 1;
            let per_copy_tris = part.triangles.len() as u64
                + inner_placed
                    .iter()
                    .map(|(k, _)| inner[*k as usize].triangles.len() as u64)
                    .sum::<u64>();
            let copies_n = copies.len().max(1) as u64;
            placements += copies_n * per_copy - 1;
            triangles += copies_n * per_copy_tris;
            let at = m.grid.as_ref().map_or(span.start, |g| g.span().start);
            if placements > MAX_PLACEMENTS {
                return Err(self.at(
                    at,
                    format!("the meshes make {placements} copies, more than {MAX_PLACEMENTS}"),
                ));
            }
            if triangles > crate::bvh::MAX_PLACED {
                return Err(self.at(
                    at,
                    format!(
                        "the meshes place {triangles} triangles, more than the {} one scene can number",
                        crate::bvh::MAX_PLACED
                    ),
                ));
            }
            let mut meshes: Vec<Mesh> = std::iter::once(part).chain(inner).collect();
            if let Some(id) = override_id
                && materials[id as usize].has_height_map()
                && meshes.iter().any(|p| p.uvs.is_empty())
            {
                warnings.push(format!(
                "{}:{}: material `{}` has a height map, but the mesh has no texture coordinates: not applied",
                self.path.display(),
                line_of(self.text, span.start),
                materials[id as usize].name
            ));
            }
            if let Some(id) = override_id
                && materials[id as usize].has_normal_map()
            {
                // The mesh's own tangents were made for its own materials: MikkTSpace's for the
                // whole mesh, in its own frame (turned with it below).
                if meshes.iter().any(|p| p.uvs.is_empty()) {
                    warnings.push(format!(
                    "{}:{}: material `{}` has a normal map, but the mesh has no texture coordinates: not applied",
                    self.path.display(),
                    line_of(self.text, span.start),
                    materials[id as usize].name
                ));
                }
                for part in &mut meshes {
                    part.tangents = if part.uvs.is_empty() {
                        Vec::new()
                    } else {
                        super::tangents::mikktspace(
                            &part.triangles,
                            &part.normals,
                            &part.uvs,
                            |_| true,
                        )
                    };
                }
            }
            let offset = materials.len() as u32;
            if override_id.is_none() {
                materials.extend(part_materials);
            }
            for part in &mut meshes {
                match override_id {
                    Some(id) => part.material_ids.iter_mut().for_each(|x| *x = id),
                    None => part.material_ids.iter_mut().for_each(|x| *x += offset),
                }
            }
            let transform = transform_of(m);
            let mut meshes = meshes.into_iter();
            let mut part = meshes.next().expect("the entry's own mesh");
            let first_inner = shared.len() as u32;
            shared.extend(meshes);
            let copies = if copies.is_empty() {
                vec![DAffine3::IDENTITY]
            } else {
                copies
            };
            for c in &copies {
                placed.extend(
                    inner_placed
                        .iter()
                        .map(|(k, w)| (first_inner + k, *c * transform * *w)),
                );
            }
            if copies.len() == 1 {
                // Placed once (a grid of one copy too): with the scene's own triangles, traced
                // through one tree without a top level.
                part.transform(&(copies[0] * transform));
                objects.extend(part_objects, None);
                mesh.append(part, 0);
            } else {
                let index = shared.len() as u32;
                placed.extend(copies.iter().map(|c| (index, *c * transform)));
                shared.push(part);
            }
        }
        Ok(Meshes {
            mesh,
            objects,
            shared,
            placed,
            warnings,
            animation,
        })
    }

    /// The transforms of a grid's copies (each applied after the entry's own transform).
    fn grid(&self, g: &Spanned<GridDef>) -> Result<Vec<DAffine3>> {
        let d = g.get_ref();
        let n = d.count.iter().map(|&c| c as u64).product::<u64>();
        if n == 0 {
            return Err(self.at(
                g.span().start,
                "a grid's count is at least 1 along each axis".into(),
            ));
        }
        if n > MAX_PLACEMENTS {
            return Err(self.at(
                g.span().start,
                format!("the grid makes {n} copies, more than {MAX_PLACEMENTS}"),
            ));
        }
        let turn = d.turn.unwrap_or(0.0);
        if !(d.step.iter().all(|s| s.is_finite()) && turn.is_finite()) {
            return Err(self.at(
                g.span().start,
                "a grid's step and turn are finite numbers".into(),
            ));
        }
        let mut out = Vec::with_capacity(n as usize);
        for z in 0..d.count[2] {
            for y in 0..d.count[1] {
                for x in 0..d.count[0] {
                    let k = out.len() as f64;
                    let at = DVec3::new(x as f64, y as f64, z as f64) * DVec3::from(d.step);
                    out.push(
                        DAffine3::from_translation(at)
                            * DAffine3::from_rotation_y((turn * k).to_radians()),
                    );
                }
            }
        }
        Ok(out)
    }

    /// One mesh entry's triangles, as its file or shape gives them, and their materials;
    /// `animation` raised to the length of the file's animations, if longer.
    fn mesh_part(
        &self,
        m: &MeshDef,
        span: &std::ops::Range<usize>,
        warnings: &mut Vec<String>,
        animation: &mut Option<f32>,
    ) -> Result<Part> {
        Ok(match (&m.path, m.shape) {
            (Some(p), None) => {
                let file = self.resolve(p.get_ref());
                let rule = match &m.crease_angle {
                    Some(a) if !(0.0..=180.0).contains(a.get_ref()) => {
                        return Err(self.at(
                            a.span().start,
                            format!("crease_angle {} is not in 0..=180 degrees", a.get_ref()),
                        ));
                    }
                    Some(a) => Some(NormalRule::Crease(*a.get_ref())),
                    None => None,
                };
                let loaded = load_mesh_file(&file, self.read, rule, self.time).map_err(|e| {
                    self.at(p.span().start, format!("mesh `{}`: {e:#}", p.get_ref()))
                })?;
                warnings.extend(loaded.warnings);
                if let Some(a) = loaded.animation {
                    *animation = Some(animation.map_or(a, |b| b.max(a)));
                }
                let mut objects = loaded.objects;
                if objects.is_empty() {
                    objects.push(name_of(&file), loaded.mesh.triangles.len());
                }
                Part {
                    mesh: loaded.mesh,
                    materials: loaded.materials,
                    shared: loaded.shared,
                    placed: loaded.placed,
                    objects,
                }
            }
            (None, Some(shape)) => {
                if let Some(a) = &m.crease_angle {
                    return Err(self.at(
                    a.span().start,
                    "crease_angle applies to mesh files; generated shapes have their own normals"
                        .into(),
                ));
                }
                let tris = match shape {
                    ShapeDef::Sphere => shapes::icosphere(m.subdivisions.unwrap_or(3).min(7)),
                    ShapeDef::Cube => shapes::cube(),
                    ShapeDef::Quad => shapes::quad(),
                };
                let part = match shape {
                    ShapeDef::Sphere => Mesh::smooth_sphere(tris),
                    _ => Mesh::from_triangles(tris, 0),
                };
                let mut objects = Runs::default();
                let name = match shape {
                    ShapeDef::Sphere => "sphere",
                    ShapeDef::Cube => "cube",
                    ShapeDef::Quad => "quad",
                };
                objects.push(name, part.triangles.len());
                Part {
                    mesh: part,
                    materials: vec![Material::default()],
                    shared: Vec::new(),
                    placed: Vec::new(),
                    objects,
                }
            }
            _ => {
                return Err(self.at(
                    span.start,
                    "a mesh needs exactly one of `path` or `shape`".into(),
                ));
            }
        })
    }

    /// The `[environment]` table, its image files checked when asked.
    fn environment(&self, environment: &Option<Spanned<EnvDef>>) -> Result<Environment> {
        Ok(match environment {
            // No [environment] table: the procedural sky, which needs no files.
            None => Environment::Sky {
                intensity: 1.0,
                rotation_deg: 0.0,
            },
            Some(e) => {
                let pos = e.span().start;
                let check = |p: PathBuf| -> Result<PathBuf> {
                    if self.check_files && !p.is_file() {
                        return Err(
                            self.at(pos, format!("environment image {} not found", p.display()))
                        );
                    }
                    Ok(p)
                };
                match e.get_ref() {
                    EnvDef::None => Environment::None,
                    EnvDef::Color { color } => Environment::Color(Vec3::from(*color)),
                    EnvDef::Sky {
                        intensity,
                        rotation,
                    } => Environment::Sky {
                        intensity: intensity.unwrap_or(1.0),
                        rotation_deg: rotation.unwrap_or(0.0),
                    },
                    EnvDef::Cubemap {
                        faces,
                        intensity,
                        rotation,
                    } => {
                        let mut out: [PathBuf; 6] = Default::default();
                        for (o, f) in out.iter_mut().zip(faces) {
                            *o = check(self.resolve(f))?;
                        }
                        Environment::CubeMap {
                            faces: out,
                            intensity: intensity.unwrap_or(1.0),
                            rotation_deg: rotation.unwrap_or(0.0),
                        }
                    }
                    EnvDef::Equirect {
                        path: p,
                        intensity,
                        rotation,
                    } => Environment::Equirect {
                        path: check(self.resolve(p))?,
                        intensity: intensity.unwrap_or(1.0),
                        rotation_deg: rotation.unwrap_or(0.0),
                    },
                }
            }
        })
    }
}

/// Parses scene text named `path`. `check_files` verifies environment images exist.
pub fn parse(path: &Path, text: &str, read: ReadFn, check_files: bool) -> Result<Scene> {
    parse_at(path, text, read, check_files, None)
}

/// [`parse`], the glTF meshes' animations played to `time` (seconds) when one is given.
pub fn parse_at(
    path: &Path,
    text: &str,
    read: ReadFn,
    check_files: bool,
    time: Option<f64>,
) -> Result<Scene> {
    let def: SceneDef = toml::from_str(text).map_err(|e| match e.span() {
        Some(span) => anyhow!(
            "{}:{}: {}",
            path.display(),
            line_of(text, span.start),
            e.message()
        ),
        None => anyhow!("{}: {}", path.display(), e.message()),
    })?;
    let ctx = Ctx {
        path,
        text,
        dir: path.parent().unwrap_or(Path::new("")).to_path_buf(),
        read,
        check_files,
        time,
    };
    let (mut materials, by_name) = ctx.materials(&def.materials)?;
    let Meshes {
        mut mesh,
        objects,
        shared,
        placed,
        warnings,
        animation,
    } = ctx.meshes(&def.meshes, &mut materials, &by_name)?;
    if materials.is_empty() {
        materials.push(Material::default());
    }

    // Camera and lights are given in world coordinates; the scene is traced in the mesh's
    // local frame (`Mesh::origin`, the world's origin for a scene near it), so they are moved
    // into it in f64.
    mesh.settle_origin();
    let instances = super::instances::place(&mut mesh, shared, &placed)
        .map_err(|e| anyhow!("{}: {e}", path.display()))?;
    let origin = mesh.origin;
    let local = |p: [f64; 3]| (DVec3::from(p) - origin).as_vec3();
    let lights = def
        .lights
        .iter()
        .map(|l| light_from_def(l.get_ref(), origin).map_err(|e| ctx.at(l.span().start, e)))
        .collect::<Result<Vec<_>>>()?;

    let bounds = mesh.bounds();
    let camera = match &def.camera {
        Some(c) => {
            let (position, look_at) = (local(c.position), local(c.look_at));
            let distance = (DVec3::from(c.look_at) - DVec3::from(c.position)).length() as f32;
            Camera {
                position,
                look_at,
                up: c.up.map(Vec3::from).unwrap_or(Vec3::Y),
                vfov_deg: c.fov.unwrap_or(45.0),
                lens_radius: c.lens_radius.unwrap_or(0.0),
                focus_distance: c.focus_distance.unwrap_or(distance),
            }
        }
        // Framed by the bounds: at rest when an instant of an animation is asked for, so
        // that every instant is seen from one place.
        None if ctx.time.is_some() => {
            let rest = Ctx {
                time: None,
                dir: ctx.dir.clone(),
                ..ctx
            };
            let mut m = materials.clone();
            let rest = rest.meshes(&def.meshes, &mut m, &by_name)?.mesh;
            Camera::canonical(&rest.bounds_around(origin).union(&instances.bounds()))
        }
        None => Camera::canonical(&bounds.union(&instances.bounds())),
    };

    let environment = ctx.environment(&def.environment)?;
    let render = def.render.unwrap_or_default();

    let name = name_of(path);
    Ok(Scene {
        objects: super::objects::list(
            &objects,
            mesh.triangles.len(),
            instances.placements(),
            &name,
        ),
        name,
        mesh,
        materials,
        lights,
        camera,
        environment,
        integrator: render.integrator.unwrap_or(Integrator::Direct),
        energy_compensation: render.energy_compensation.unwrap_or(true),
        warnings,
        animation,
        instances,
    })
}

/// Loads an OBJ, PLY or glTF through `read` (a glTF's own camera and lights are not used: the
/// scene file gives them).
fn load_mesh_file(
    file: &Path,
    read: ReadFn,
    rule: Option<NormalRule>,
    time: Option<f64>,
) -> Result<MeshFile> {
    if !Format::of(file).is_some_and(Format::is_mesh) {
        bail!("unknown mesh type (expected {})", Format::expected(true));
    }
    format::load_mesh(file, &read(file)?, read, rule, time)
}

/// The mesh entry's transform in f64 (a translation of 1e6 keeps its last digits).
fn transform_of(m: &MeshDef) -> DAffine3 {
    let scale = match m.scale {
        Some(ScaleDef::Uniform(s)) => DVec3::splat(s),
        Some(ScaleDef::PerAxis(s)) => DVec3::from(s),
        None => DVec3::ONE,
    };
    let r = m.rotate.unwrap_or([0.0; 3]).map(f64::to_radians);
    let rotation = DQuat::from_euler(EulerRot::ZYX, r[2], r[1], r[0]);
    let translation = DVec3::from(m.translate.unwrap_or([0.0; 3]));
    DAffine3::from_scale_rotation_translation(scale, rotation, translation)
}

fn material_from_def(name: &str, m: &MaterialDef) -> Material {
    let d = Material::default();
    let v = |a: Option<[f32; 3]>, dv: Vec3| a.map(Vec3::from).unwrap_or(dv);
    Material {
        name: name.to_string(),
        diffuse: v(m.diffuse, d.diffuse),
        specular: v(m.specular, d.specular),
        shininess: m.shininess.unwrap_or(d.shininess),
        emission: v(m.emission, d.emission),
        opacity: m.opacity.unwrap_or(1.0).clamp(0.0, 1.0),
        ior: m.ior.unwrap_or(1.0),
        mirror: v(m.mirror, d.mirror),
        absorption: v(m.absorption, d.absorption),
        ..d
    }
}

/// The light of `l`, moved into the frame whose world position is `origin`, or what is wrong
/// with it.
fn light_from_def(l: &LightDef, origin: DVec3) -> Result<Light, String> {
    let local = |p: &[f64; 3]| (DVec3::from(*p) - origin).as_vec3();
    Ok(match l {
        LightDef::Point {
            position,
            color,
            intensity,
        } => Light::Point {
            position: local(position),
            color: color.map(Vec3::from).unwrap_or(Vec3::ONE),
            intensity: intensity.unwrap_or(1.0),
        },
        LightDef::Rect {
            corner,
            edge_u,
            edge_v,
            color,
            intensity,
            samples,
        } => Light::Rect {
            corner: local(corner),
            edge_u: Vec3::from(*edge_u),
            edge_v: Vec3::from(*edge_v),
            color: color.map(Vec3::from).unwrap_or(Vec3::ONE),
            intensity: intensity.unwrap_or(1.0),
            samples: samples.unwrap_or(4).max(1),
        },
        LightDef::Spot {
            position,
            direction,
            color,
            intensity,
            inner_angle,
            outer_angle,
        } => {
            let (inner, outer) = (inner_angle.unwrap_or(0.0), outer_angle.unwrap_or(45.0));
            if !(0.0 <= inner && inner < outer && outer <= 90.0) {
                return Err(format!(
                    "spot light: inner_angle {inner} and outer_angle {outer} must satisfy \
                     0 <= inner < outer <= 90 (degrees)"
                ));
            }
            let d = Vec3::from(*direction);
            let Some(direction) = d.try_normalize() else {
                return Err(format!("spot light: direction {d} has no length"));
            };
            Light::Spot {
                position: local(position),
                direction,
                color: color.map(Vec3::from).unwrap_or(Vec3::ONE),
                intensity: intensity.unwrap_or(1.0),
                cos_inner: inner.to_radians().cos(),
                cos_outer: outer.to_radians().cos(),
            }
        }
    })
}
