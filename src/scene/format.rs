//! The file formats a scene loads from, as one table: which extension names which format, and
//! the one dispatch every caller goes through (a scene opened by name, a scene file's mesh
//! entry, the viewer's list of files it can open).
//!
//! Every mesh format's loader returns a [`MeshFile`]; a scene file (`.toml`) is parsed by
//! [`super::file`] into a whole [`super::Scene`].

use std::path::Path;

use anyhow::{Result, bail};

use super::gltf::{GltfCamera, GltfLight};
use super::{Material, Mesh, NormalRule, Runs, gltf, obj, ply};

/// A kind of file a scene comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// The project's scene file (TOML): camera, lights, materials, meshes, environment.
    SceneFile,
    /// Wavefront OBJ, with its MTL materials.
    Obj,
    /// Stanford PLY (ASCII or binary).
    Ply,
    /// glTF 2.0, JSON with its buffers or one binary file.
    Gltf,
}

/// Every extension the loaders know (lower case), with its format, in the order messages
/// list them.
const EXTENSIONS: [(&str, Format); 5] = [
    ("toml", Format::SceneFile),
    ("obj", Format::Obj),
    ("ply", Format::Ply),
    ("gltf", Format::Gltf),
    ("glb", Format::Gltf),
];

impl Format {
    /// The format `path`'s extension names (any case), if any.
    pub fn of(path: &Path) -> Option<Format> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        EXTENSIONS
            .iter()
            .find(|(e, _)| *e == ext)
            .map(|&(_, format)| format)
    }

    /// Whether the format holds a mesh (and so can be a scene file's mesh entry).
    pub fn is_mesh(self) -> bool {
        self != Format::SceneFile
    }

    /// The extensions of every format, or of the mesh formats only, as a message lists them:
    /// `.toml, .obj, .ply, .gltf or .glb`.
    pub fn expected(meshes_only: bool) -> String {
        let names: Vec<String> = EXTENSIONS
            .iter()
            .filter(|(_, f)| !meshes_only || f.is_mesh())
            .map(|(e, _)| format!(".{e}"))
            .collect();
        match names.split_last() {
            Some((last, rest)) if !rest.is_empty() => format!("{} or {last}", rest.join(", ")),
            _ => names.concat(),
        }
    }
}

/// What a mesh file holds, as every mesh loader returns it.
pub struct MeshFile {
    /// Triangles in a local frame (see [`super::local_frame`]), material ids into `materials`.
    pub mesh: Mesh,
    /// The materials (at least one).
    pub materials: Vec<Material>,
    /// The file's first perspective camera, in world coordinates (glTF only).
    pub camera: Option<GltfCamera>,
    /// The file's punctual lights, in world coordinates (glTF only).
    pub lights: Vec<GltfLight>,
    /// Problems worth telling the user that did not stop the load (a missing MTL file, say).
    pub warnings: Vec<String>,
    /// How long the file's animations run, in seconds (glTF only; `None` without any).
    pub animation: Option<f32>,
    /// Meshes the file places more than once (a glTF mesh several nodes use, unskinned and
    /// without morph targets), each in its own frame, held once.
    pub shared: Vec<Mesh>,
    /// Their placements: a mesh of `shared` and its transform to the world.
    pub placed: Vec<(u32, glam::DAffine3)>,
    /// The objects `mesh`'s triangles make, as the file names them (empty: one, the file).
    pub objects: Runs,
}

impl MeshFile {
    /// A file that gave a mesh and its materials only.
    pub fn of_mesh(mesh: Mesh, materials: Vec<Material>, warnings: Vec<String>) -> MeshFile {
        MeshFile {
            mesh,
            materials,
            camera: None,
            lights: Vec::new(),
            warnings,
            animation: None,
            shared: Vec::new(),
            placed: Vec::new(),
            objects: Runs::default(),
        }
    }
}

/// Loads the mesh file `path` from its bytes, reading the files it names (an OBJ's MTL and
/// textures, a glTF's buffers and images) through `read`, relative to its folder. Normals the
/// file does not give follow `rule`, or the format's default when it is `None`. A glTF's
/// animations are played to `time` (seconds) when one is given; other formats have none.
pub fn load_mesh(
    path: &Path,
    bytes: &[u8],
    read: &dyn Fn(&Path) -> Result<Vec<u8>>,
    rule: Option<NormalRule>,
    time: Option<f64>,
) -> Result<MeshFile> {
    let dir = path.parent().unwrap_or(Path::new("")).to_path_buf();
    let beside = |p: &Path| read(&dir.join(p));
    match Format::of(path) {
        Some(Format::Obj) => obj::load_from(path, bytes, &beside, rule),
        Some(Format::Ply) => Ok(MeshFile::of_mesh(
            ply::load_from(path, bytes, rule)?,
            vec![Material::default()],
            Vec::new(),
        )),
        Some(Format::Gltf) => gltf::load_from(path, bytes, &beside, rule, time),
        Some(Format::SceneFile) | None => {
            bail!("unknown mesh type (expected {})", Format::expected(true))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn extensions_name_formats_in_any_case() {
        assert_eq!(Format::of(Path::new("a/b.TOML")), Some(Format::SceneFile));
        assert_eq!(Format::of(Path::new("b.Glb")), Some(Format::Gltf));
        assert_eq!(Format::of(Path::new("b.ply")), Some(Format::Ply));
        assert_eq!(Format::of(Path::new("b.stl")), None);
        assert_eq!(Format::of(Path::new("obj")), None);
    }

    #[test]
    fn messages_list_the_extensions() {
        assert_eq!(Format::expected(false), ".toml, .obj, .ply, .gltf or .glb");
        assert_eq!(Format::expected(true), ".obj, .ply, .gltf or .glb");
    }
}
