//! PLY meshes (ASCII and binary), through the maintained `ply-rs-bw` parser.
//!
//! Reads `vertex` elements (`x y z` of any numeric type, optional `nx ny nz`) and `face`
//! elements (`vertex_indices` or `vertex_index`, any integer list type); other elements are
//! read and dropped. Polygons are fan-triangulated as `(0, k, k + 1)`. Without normals in the
//! file, faces are smoothed across edges below a crease angle ([`super::normals`]).

use std::io::Read;
use std::path::Path;

use anyhow::{Result, anyhow, bail};
use glam::Vec3;
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{
    DefaultElement, ElementDef, Encoding, Property, PropertyAccess, PropertyAccessResult,
    PropertyType, ScalarType,
};

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
    p: [f64; 3],
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
            self.p[slot] = v;
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

/// Parses PLY data named `path` (for messages). Normals the file does not give follow `rule`,
/// or a crease of [`DEFAULT_CREASE_DEG`] when it is `None`.
pub fn load_from(path: &Path, data: &[u8], rule: Option<NormalRule>) -> Result<Mesh> {
    let at = |e: ply_rs_bw::parser::ParseError| {
        let msg = one_line(&e.to_string());
        match e.line() {
            // The error's own text already says "Line N"; put it in the file:line form.
            Some(line) => anyhow!("{}:{line}: {}", path.display(), strip_line(&msg)),
            None => anyhow!("{}: {msg}", path.display()),
        }
    };
    let mut data = data;
    let header = tolerant_header(&mut data)
        .map_err(|e| anyhow!("{}: cannot read the header: {e}", path.display()))?;
    let mut reader = Reader::new(std::io::Cursor::new(header).chain(data));
    let vparser = Parser::<Vertex>::new();
    let fparser = Parser::<Face>::new();
    let other = Parser::<DefaultElement>::new();
    let header = vparser.read_header(&mut reader).map_err(at)?;
    check_counts(path, &header.elements, &header.encoding, data.len())?;
    let mut vertices: Vec<Vertex> = Vec::new();
    let mut faces: Vec<Face> = Vec::new();
    let mut seen_vertex = false;
    for (_, element) in &header.elements {
        if element.properties.is_empty() && header.encoding != Encoding::Ascii {
            // Records of no bytes: nothing to read, however many the header counts.
            continue;
        }
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
    // Read in f64 and placed about their centre: precise however far from the origin.
    let (origin, positions) = super::local_frame(
        &vertices
            .iter()
            .map(|v| glam::DVec3::from(v.p))
            .collect::<Vec<_>>(),
    );
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
        mesh.origin = origin;
        Ok(mesh)
    } else {
        let rule = rule.unwrap_or(NormalRule::Crease(DEFAULT_CREASE_DEG));
        let mut mesh = Mesh::from_indexed(&positions, &tris, 0, rule, &[]);
        mesh.origin = origin;
        Ok(mesh)
    }
}

/// The parser's multi-line message (`Couldn't read element line.\n\tString: '1 x 0\n'\n\t
/// Error: ...`) on one line: `Couldn't read element line: "1 x 0" (Couldn't parse element
/// line.)`.
fn one_line(msg: &str) -> String {
    let mut head = String::new();
    let mut text = None;
    let mut cause = Vec::new();
    for part in msg
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && *l != "'")
    {
        if let Some(t) = part.strip_prefix("String: ") {
            text = Some(t.trim_matches('\'').trim().to_string());
        } else if let Some(c) = part.strip_prefix("Error: ") {
            cause.push(column_only(c.trim_end_matches('.')));
        } else if head.is_empty() {
            head = part.trim_end_matches('.').to_string();
        } else if text.as_deref() == Some("") {
            // The quoted line itself, when the quote spans two lines.
            text = Some(part.trim_matches('\'').to_string());
        }
    }
    let mut out = head;
    if let Some(t) = text {
        out.push_str(&format!(": \"{t}\""));
    }
    if !cause.is_empty() {
        out.push_str(&format!(" ({})", cause.join("; ")));
    }
    out
}

/// The parser reports a position inside the one line it was given (`error at 1:3: ...`), which
/// reads like line 1 of the file: keep the column only.
fn column_only(cause: &str) -> String {
    let Some((before, rest)) = cause.split_once("error at ") else {
        return cause.to_string();
    };
    let mut parts = rest.splitn(3, ':');
    match (parts.next(), parts.next(), parts.next()) {
        (Some(l), Some(c), Some(tail)) if l.parse::<u32>().is_ok() && c.parse::<u32>().is_ok() => {
            format!("{before}at column {c}:{tail}")
        }
        _ => cause.to_string(),
    }
}

/// Refuses an element whose count could not fit in the `payload` bytes after the header, before
/// the parser allocates a record per count. Every record takes at least its scalars' and list
/// lengths' bytes in binary, and at least one byte (its line break) in ASCII. (Binary elements
/// without properties take no bytes and are not read at all.)
fn check_counts(
    path: &Path,
    elements: &ply_rs_bw::ply::KeyMap<ElementDef>,
    encoding: &Encoding,
    payload: usize,
) -> Result<()> {
    let size = |t: &ScalarType| match t {
        ScalarType::Char | ScalarType::UChar => 1,
        ScalarType::Short | ScalarType::UShort => 2,
        ScalarType::Int | ScalarType::UInt | ScalarType::Float => 4,
        ScalarType::Double => 8,
    };
    let mut need = 0usize;
    for (name, element) in elements {
        let record = match encoding {
            Encoding::Ascii => 1,
            _ => element
                .properties
                .values()
                .map(|p| match &p.data_type {
                    PropertyType::Scalar(t) | PropertyType::List(t, _) => size(t),
                })
                .sum::<usize>(),
        };
        need = need.saturating_add(element.count.saturating_mul(record));
        if need > payload {
            bail!(
                "{}: end of file before the {} `{name}` records the header promises (they need \
                 at least {need} bytes after the header, the file has {payload})",
                path.display(),
                element.count
            );
        }
    }
    Ok(())
}

/// Reads the header up to and including `end_header`, and turns lines no PLY keyword starts
/// (Blender 2.4 wrote a bare `Blender 2.4 export` line, which assimp also reads) into comments,
/// so the parser accepts them; every line keeps its number. Nothing after the header is read.
fn tolerant_header(data: &mut impl std::io::BufRead) -> std::io::Result<Vec<u8>> {
    const KEYWORDS: [&str; 7] = [
        "ply",
        "format",
        "comment",
        "obj_info",
        "element",
        "property",
        "end_header",
    ];
    let mut out = Vec::new();
    let mut line = Vec::new();
    loop {
        line.clear();
        if data.read_until(b'\n', &mut line)? == 0 {
            break;
        }
        let text = String::from_utf8_lossy(&line);
        let word = text.split_whitespace().next().unwrap_or("");
        if !word.is_empty() && !KEYWORDS.contains(&word) && !out.is_empty() {
            out.extend_from_slice(b"comment ");
        }
        out.extend_from_slice(&line);
        if word == "end_header" {
            break;
        }
    }
    Ok(out)
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
