//! What a glTF file must be before it is read: its JSON parsed (relaxed where the crate's
//! parser is stricter than the specification), its extensions known, its references in range,
//! and the limits that keep a hostile file from taking the machine.

use super::*;

/// A glTF (JSON, not GLB) that the gltf crate refuses only for a field the specification makes
/// optional and the crate does not: a scene without `nodes` (an empty scene). The field is
/// added and the file read again; `None` when that is not the problem.
pub(super) fn relaxed(bytes: &[u8]) -> Option<::gltf::Gltf> {
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
pub(super) const READ_EXTENSIONS: &[&str] = &[
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
pub(super) const DONE_WITHOUT_EXTENSIONS: &[&str] = &["KHR_materials_unlit"];

/// Most node placements (a node under several parents is placed once per path to it: a file
/// can make that grow exponentially with depth, so it is bounded, not followed into a hang).
pub(super) const MAX_NODE_VISITS: usize = 1_000_000;

/// Most triangles placed (a mesh under many nodes multiplies them).
pub(super) const MAX_TRIANGLES: usize = 50_000_000;

/// Deepest node hierarchy followed (a deeper one is reported, not followed into a stack
/// overflow).
pub(super) const MAX_NODE_DEPTH: usize = 256;

/// The glTF crate's validation (every index in range, required fields present: after it,
/// looking an index up cannot fail), less two rules the loader does not need: accessor `min`
/// and `max` (bounds are computed from the positions; exporters often leave them out) and
/// required extensions (checked before, with a clearer message).
pub(super) fn validate(doc: &::gltf::Gltf) -> std::result::Result<(), ::gltf::Error> {
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
pub(super) fn parse_error(name: &str, e: ::gltf::Error) -> anyhow::Error {
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
