//! PLY meshes (ASCII and binary), through the maintained `ply-rs-bw` parser.
//!
//! Reads `vertex` elements (`x y z` of any numeric type, optional `nx ny nz`) and `face`
//! elements (`vertex_indices` or `vertex_index`, any integer list type); other elements are
//! read and dropped. Polygons are fan-triangulated as `(0, k, k + 1)`. Without normals in the
//! file, faces are smoothed across edges below a crease angle ([`super::normals`]).

use std::io::BufReader;
use std::path::Path;

use anyhow::{Result, anyhow, bail};
use glam::Vec3;
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{DefaultElement, Property, PropertyAccess, PropertyAccessResult};

use super::normals::{DEFAULT_CREASE_DEG, NormalRule};
use super::{Mesh, face_normal};

fn scalar(p: &Property) -> Option<f64> {
    Some(match *p {
        Property::Char(v) => v as f64,
        Property::UChar(v) => v as f64,
        Property::Short(v) => v as f64,
        Property::UShort(v) => v as f64,
        Property::Int(v) => v as f64,
        Property::UInt(v) => v as f64,
        Property::Float(v) => v as f64,
        Property::Double(v) => v,
        _ => return None,
    })
}

#[derive(Default)]
struct Vertex {
    p: [f32; 3],
    n: [f32; 3],
    has: u8, // bit 0..2 position, 3..5 normal
}

impl PropertyAccess for Vertex {
    fn new() -> Self {
        Self::default()
    }
    fn set_property(&mut self, key: &str, property: Property) -> PropertyAccessResult {
        let slot = match key {
            "x" => 0,
            "y" => 1,
            "z" => 2,
            "nx" => 3,
            "ny" => 4,
            "nz" => 5,
            _ => return PropertyAccessResult::Ignored,
        };
        let Some(v) = scalar(&property) else {
            return PropertyAccessResult::UnsupportedType;
        };
        if slot < 3 {
            self.p[slot] = v as f32;
        } else {
            self.n[slot - 3] = v as f32;
        }
        self.has |= 1 << slot;
        PropertyAccessResult::Set
    }
}

#[derive(Default)]
struct Face {
    indices: Vec<i64>,
}

impl PropertyAccess for Face {
    fn new() -> Self {
        Self::default()
    }
    fn set_property(&mut self, key: &str, property: Property) -> PropertyAccessResult {
        if key != "vertex_indices" && key != "vertex_index" {
            return PropertyAccessResult::Ignored;
        }
        self.indices = match property {
            Property::ListChar(v) => v.into_iter().map(i64::from).collect(),
            Property::ListUChar(v) => v.into_iter().map(i64::from).collect(),
            Property::ListShort(v) => v.into_iter().map(i64::from).collect(),
            Property::ListUShort(v) => v.into_iter().map(i64::from).collect(),
            Property::ListInt(v) => v.into_iter().map(i64::from).collect(),
            Property::ListUInt(v) => v.into_iter().map(i64::from).collect(),
            _ => return PropertyAccessResult::UnsupportedType,
        };
        PropertyAccessResult::Set
    }
}

/// Loads a PLY file.
pub fn load(path: &Path) -> Result<Mesh> {
    let file = std::fs::File::open(path)
        .map_err(|e| anyhow!("{}: cannot open file: {e}", path.display()))?;
    load_from(path, BufReader::new(file), None)
}

/// Parses PLY data named `path` (for messages). Normals the file does not give follow `rule`,
/// or a crease of [`DEFAULT_CREASE_DEG`] when it is `None`.
pub fn load_from(
    path: &Path,
    data: impl std::io::BufRead,
    rule: Option<NormalRule>,
) -> Result<Mesh> {
    let at = |e: ply_rs_bw::parser::ParseError| match e.line() {
        // The error's own text already says "Line N"; put it in the file:line form.
        Some(line) => anyhow!("{}:{line}: {}", path.display(), strip_line(&e.to_string())),
        None => anyhow!("{}: {e}", path.display()),
    };
    let mut reader = Reader::new(data);
    let vparser = Parser::<Vertex>::new();
    let fparser = Parser::<Face>::new();
    let other = Parser::<DefaultElement>::new();
    let header = vparser.read_header(&mut reader).map_err(at)?;
    let mut vertices: Vec<Vertex> = Vec::new();
    let mut faces: Vec<Face> = Vec::new();
    let mut seen_vertex = false;
    for (_, element) in &header.elements {
        match element.name.as_str() {
            "vertex" => {
                vertices = vparser
                    .read_payload_for_element(&mut reader, element, &header)
                    .map_err(at)?;
                seen_vertex = true;
            }
            "face" => {
                faces = fparser
                    .read_payload_for_element(&mut reader, element, &header)
                    .map_err(at)?;
            }
            _ => {
                other
                    .read_payload_for_element(&mut reader, element, &header)
                    .map_err(at)?;
            }
        }
    }
    if !seen_vertex {
        bail!("{}: no `vertex` element in the header", path.display());
    }
    if let Some(v) = vertices.first()
        && v.has & 0b111 != 0b111
    {
        bail!("{}: vertices need x, y and z properties", path.display());
    }
    let positions: Vec<Vec3> = vertices.iter().map(|v| Vec3::from(v.p)).collect();
    let has_normals = vertices
        .first()
        .is_some_and(|v| v.has & 0b111000 == 0b111000);

    let mut tris: Vec<[u32; 3]> = Vec::with_capacity(faces.len());
    for (fi, f) in faces.iter().enumerate() {
        if let Some(&bad) = f
            .indices
            .iter()
            .find(|&&i| i < 0 || i >= positions.len() as i64)
        {
            bail!(
                "{}: face {fi} refers to vertex {bad}, but there are {} vertices",
                path.display(),
                positions.len()
            );
        }
        for k in 1..f.indices.len().saturating_sub(1) {
            tris.push([
                f.indices[0] as u32,
                f.indices[k] as u32,
                f.indices[k + 1] as u32,
            ]);
        }
    }
    if has_normals {
        let mut mesh = Mesh::default();
        for t in &tris {
            let tri = t.map(|i| positions[i as usize]);
            let fallback = face_normal(&tri);
            mesh.normals.push(t.map(|i| {
                Vec3::from(vertices[i as usize].n)
                    .try_normalize()
                    .unwrap_or(fallback)
            }));
            mesh.triangles.push(tri);
            mesh.material_ids.push(0);
        }
        Ok(mesh)
    } else {
        let rule = rule.unwrap_or(NormalRule::Crease(DEFAULT_CREASE_DEG));
        Ok(Mesh::from_indexed(&positions, &tris, 0, rule, &[]))
    }
}

fn strip_line(msg: &str) -> String {
    match msg.strip_prefix("Line ") {
        Some(rest) => rest
            .split_once(": ")
            .map(|(_, m)| m.to_string())
            .unwrap_or_else(|| msg.to_string()),
        None => msg.to_string(),
    }
}
