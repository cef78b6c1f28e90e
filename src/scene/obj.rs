//! Wavefront OBJ with MTL materials, through `tobj`.
//!
//! Polygons are fan-triangulated as `(0, k, k + 1)` in file order (the benchmark convention),
//! negative (relative) indices are resolved by `tobj`, missing normals follow the file's
//! smoothing groups (`s`; flat outside them, see [`super::normals`]), and the MTL fields `Kd Ks Ns Ke d Tr Ni illum` become a
//! [`Material`], `map_Kd` its diffuse texture (an image that cannot be read is a warning), and
//! `norm` or a `map_Bump` / `bump` holding a colour image its normal map (tangent space, `+Y`
//! up, `-bm` its scale), with MikkTSpace tangents ([`super::tangents`]); a grey `map_Bump` /
//! `bump` is a height map (bump mapping, `-bm` the displacement per unit of its value in the
//! file's units: [`Material::height_scale`]). A map on a mesh without texture coordinates is a
//! warning. `tobj` reports what went wrong but not where; the loader then finds the first
//! offending line itself so that the error reads `file:line: message`.

use std::io::BufReader;
use std::path::Path;

use std::collections::HashMap;
use std::sync::Arc;

use anyhow::{Result, anyhow};
use glam::{Vec2, Vec3};

use super::format::MeshFile;
use super::normals::NormalRule;
use super::{Material, Mesh, Texture, face_normal};

/// Images named by the MTL file, each decoded once (per colour encoding) however many
/// materials use it.
#[derive(Default)]
struct TextureCache(HashMap<(String, bool), Arc<Texture>>);

impl TextureCache {
    /// The image a texture line names ([`TextureLine::file`]), read beside the OBJ through
    /// `read`; `srgb` for a colour image, linear values for a normal or height map.
    fn get(
        &mut self,
        spec: &str,
        srgb: bool,
        read: &dyn Fn(&Path) -> Result<Vec<u8>>,
    ) -> Result<Arc<Texture>> {
        let file = TextureLine::parse(spec).file;
        if let Some(t) = self.0.get(&(file.clone(), srgb)) {
            return Ok(t.clone());
        }
        let bytes = read(Path::new(&file))?;
        let t = Arc::new(Texture::decode(&file, &bytes, srgb)?);
        self.0.insert((file, srgb), t.clone());
        Ok(t)
    }
}

/// What an MTL texture line (`map_Kd`, `bump`, `norm`, ...) says: the image's file name and
/// the options read. The options of the MTL specification are skipped with their values
/// wherever they stand (exporters write some after the name), so that the words left, joined
/// by single spaces, name the file, spaces and all (`bump -bm 2 bump 01.png`). An unknown
/// word starting with `-` is taken as part of the name.
#[derive(Debug, PartialEq)]
struct TextureLine {
    /// The image, relative to the MTL file.
    file: String,
    /// The `-bm` value as written (`None` without one).
    bump: Option<String>,
    /// The `-imfchan` value (`None` without one).
    channel: Option<String>,
}

impl TextureLine {
    fn parse(spec: &str) -> Self {
        let words: Vec<&str> = spec.split_whitespace().collect();
        let (mut name, mut bump, mut channel) = (Vec::new(), None, None);
        let mut i = 0;
        while i < words.len() {
            let w = words[i];
            // Values each option takes; `-o`, `-s` and `-t` take one to three numbers.
            let takes = match w {
                "-blendu" | "-blendv" | "-boost" | "-cc" | "-clamp" | "-texres" | "-type"
                | "-colorspace" | "-bm" | "-imfchan" => 1,
                "-mm" => 2,
                "-o" | "-s" | "-t" => words[i + 1..]
                    .iter()
                    .take(3)
                    .take_while(|v| v.parse::<f32>().is_ok())
                    .count()
                    .max(1),
                _ => {
                    name.push(w);
                    i += 1;
                    continue;
                }
            };
            let value = words.get(i + 1).map(|v| v.to_string());
            match w {
                "-bm" => bump = Some(value.unwrap_or_default()),
                "-imfchan" => channel = value,
                _ => {}
            }
            i += 1 + takes;
        }
        Self {
            file: name.join(" "),
            bump,
            channel,
        }
    }

    /// The scale `-bm` gives (1 without one; `None` when its value is not a finite number).
    fn bump_multiplier(&self) -> Option<f32> {
        match &self.bump {
            None => Some(1.0),
            Some(v) => v.parse::<f32>().ok().filter(|x| x.is_finite()),
        }
    }
}

/// Checks what tobj 4.0 does not: a colour (`Ka`, `Kd`, `Ks`, `Ke`) with fewer than three
/// values makes its MTL parser panic, so such a line is reported here first, with its number.
fn check_mtl(text: &[u8]) -> Result<(), (usize, String)> {
    for (i, line) in String::from_utf8_lossy(text).lines().enumerate() {
        let mut words = line.split_whitespace();
        if let Some(key @ ("Ka" | "Kd" | "Ks" | "Ke")) = words.next()
            && words.count() < 3
        {
            return Err((
                i + 1,
                format!("{key} needs three numbers: `{}`", line.trim()),
            ));
        }
    }
    Ok(())
}

/// The smoothing group of every face with three or more corners, in file order: `s off` and
/// `s 0` are group 0 (flat), `s 1`, `s 2`, ... their number; any other word gets a number of
/// its own. tobj ignores `s` lines, so the loader reads them here.
fn smoothing_groups(text: &str) -> Vec<u32> {
    let mut named: Vec<String> = Vec::new();
    let mut current = 0u32;
    let mut groups = Vec::new();
    for line in text.lines() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("s") => {
                current = match words.next() {
                    None | Some("off") | Some("0") => 0,
                    Some(w) => match w.parse::<u32>() {
                        Ok(n) => n,
                        Err(_) => {
                            let at = named.iter().position(|n| n == w).unwrap_or_else(|| {
                                named.push(w.to_string());
                                named.len() - 1
                            });
                            // Named groups above every numbered one a file is likely to use.
                            u32::MAX - at as u32
                        }
                    },
                };
            }
            // tobj reads `l` lines like `f` ones: a triangle or polygon either way.
            Some("f" | "l") if line.split_whitespace().count() >= 4 => groups.push(current),
            _ => {}
        }
    }
    groups
}

/// Loads OBJ text named `path` (for messages), reading MTL files through `read_mtl`. Normals
/// the file does not give follow `rule`, or the file's smoothing groups when it is `None`.
pub fn load_from(
    path: &Path,
    bytes: &[u8],
    read_mtl: &dyn Fn(&Path) -> Result<Vec<u8>>,
    rule: Option<NormalRule>,
) -> Result<MeshFile> {
    let (models, materials, mtl_error) = parse(path, bytes, read_mtl)?;
    let mut warnings = Vec::new();
    let mut mats = match materials {
        Ok(m) => {
            let mut cache = TextureCache::default();
            m.iter()
                .map(|tm| material(path, tm, &mut cache, read_mtl, &mut warnings))
                .collect()
        }
        Err(e) => {
            let why = mtl_error.unwrap_or_else(|| e.to_string());
            warnings.push(format!(
                "{}: materials not loaded ({why}); using the default material",
                path.display()
            ));
            Vec::new()
        }
    };
    let default_id = mats.len() as u32;
    let mut need_default = false;
    let groups = face_groups(path, bytes, &models, &mut warnings);
    let mut next_face = 0usize;

    // Positions are read in f64 and placed about one origin for the whole file (see
    // `local_frame`): precise however far from the world's origin the file lies.
    let all: Vec<glam::DVec3> = models
        .iter()
        .flat_map(|m| {
            m.mesh
                .positions
                .chunks_exact(3)
                .map(|p| glam::DVec3::new(p[0], p[1], p[2]))
        })
        .collect();
    let (origin, local) = super::local_frame(&all);
    drop(all);
    let mut first_position = 0usize;

    let mut mesh = Mesh::default();
    let mut objects = super::Runs::default();
    let stem = super::name_of(path);
    for model in &models {
        let m = &model.mesh;
        let material = match m.material_id {
            Some(id) if id < mats.len() => id as u32,
            _ => {
                need_default = true;
                default_id
            }
        };
        let count = m.positions.len() / 3;
        let positions = &local[first_position..first_position + count];
        first_position += count;
        let before = mesh.triangles.len();
        append_model(
            &mut mesh,
            m,
            positions,
            material,
            (&groups, &mut next_face),
            rule,
        );
        // tobj calls what no `o` or `g` line names `unnamed_object`: the file's name is
        // better.
        let name = match model.name.as_str() {
            "" | "unnamed_object" => stem.as_str(),
            n => n,
        };
        objects.push(name, mesh.triangles.len() - before);
    }
    if !mesh.uvs.is_empty() {
        mesh.uvs.resize(mesh.triangles.len(), [Vec2::ZERO; 3]);
    }
    if need_default || mats.is_empty() {
        mats.push(Material::default());
    }
    if mesh.uvs.is_empty() {
        let mut used = vec![false; mats.len()];
        mesh.material_ids
            .iter()
            .for_each(|&i| used[i as usize] = true);
        for (m, _) in mats.iter_mut().zip(used).filter(|(_, used)| *used) {
            for (what, map) in [
                ("normal map", &mut m.normal_map),
                ("height map", &mut m.height_map),
            ] {
                if map.take().is_some() {
                    warnings.push(format!(
                        "{}: material {}: {what} not used (the mesh has no texture coordinates)",
                        path.display(),
                        m.name
                    ));
                }
            }
        }
    }
    let mapped = |i: usize| mats[mesh.material_ids[i] as usize].normal_map.is_some();
    if !mesh.uvs.is_empty() && (0..mesh.triangles.len()).any(mapped) {
        mesh.tangents =
            super::tangents::mikktspace(&mesh.triangles, &mesh.normals, &mesh.uvs, mapped);
    }
    mesh.origin = origin;
    let mut file = MeshFile::of_mesh(mesh, mats, warnings);
    file.objects = objects;
    Ok(file)
}

/// The OBJ text parsed by tobj, with its MTL files read through `read_mtl` and checked first:
/// the models, the materials (or why they could not be read, and the message of the file that
/// failed). An OBJ tobj cannot read is an error naming the file and, where it can be found,
/// the line.
#[allow(clippy::type_complexity)]
fn parse(
    path: &Path,
    bytes: &[u8],
    read_mtl: &dyn Fn(&Path) -> Result<Vec<u8>>,
) -> Result<(
    Vec<tobj::Model>,
    std::result::Result<Vec<tobj::Material>, tobj::LoadError>,
    Option<String>,
)> {
    let options = tobj::LoadOptions {
        single_index: false,
        triangulate: false,
        ignore_points: true,
        ignore_lines: true,
    };
    let mtl_error = std::cell::RefCell::new(None::<String>);
    let result = tobj::load_obj_buf(&mut BufReader::new(bytes), &options, |mtl_path| {
        let text = read_mtl(mtl_path).map_err(|e| {
            *mtl_error.borrow_mut() = Some(format!("{e:#}"));
            tobj::LoadError::OpenFileFailed
        })?;
        if let Err((line, why)) = check_mtl(&text) {
            *mtl_error.borrow_mut() = Some(format!("{}:{line}: {why}", mtl_path.display()));
            return Err(tobj::LoadError::MaterialParseError);
        }
        tobj::load_mtl_buf(&mut BufReader::new(&text[..])).inspect_err(|e| {
            *mtl_error.borrow_mut() = Some(format!("{}: {e}", mtl_path.display()));
        })
    });
    let (models, materials) = match result {
        Ok(r) => r,
        Err(e) => {
            let text = String::from_utf8_lossy(bytes);
            return Err(match locate_error(&text, e) {
                Some((line, why)) => anyhow!("{}:{line}: {e}: {why}", path.display()),
                None => anyhow!("{}: {e}", path.display()),
            });
        }
    };
    Ok((models, materials, mtl_error.into_inner()))
}

/// An MTL material as the renderer's, with its diffuse texture and its normal or height map
/// read (a map that cannot be used is left out, with a warning).
fn material(
    path: &Path,
    tm: &tobj::Material,
    cache: &mut TextureCache,
    read_mtl: &dyn Fn(&Path) -> Result<Vec<u8>>,
    warnings: &mut Vec<String>,
) -> Material {
    let mut mat = convert_material(tm);
    if let Some(spec) = &tm.diffuse_texture {
        match cache.get(spec, true, read_mtl) {
            Ok(t) => mat.diffuse_map = Some(t),
            Err(e) => warnings.push(format!(
                "{}: material {}: map_Kd not used ({e:#})",
                path.display(),
                tm.name
            )),
        }
    }
    // `norm` is a normal map by name; `map_Bump` and `bump` are one when
    // their image has colour (exporters write normal maps there too).
    let normal = match tm.unknown_param.get("norm") {
        Some(spec) => Some(("norm", spec)),
        None => tm.normal_texture.as_ref().map(|spec| ("map_Bump", spec)),
    };
    if let Some((key, spec)) = normal {
        let say = |why: String| {
            format!(
                "{}: material {}: {key} not used ({why})",
                path.display(),
                tm.name
            )
        };
        let line = TextureLine::parse(spec);
        if let Some(c) = line.channel.as_deref().filter(|&c| c != "l") {
            warnings.push(format!(
                "{}: material {}: {key}'s -imfchan {c} is not read (a height map's value is its luminance, a normal map's its RGB)",
                path.display(),
                tm.name
            ));
        }
        match (cache.get(spec, false, read_mtl), line.bump_multiplier()) {
            (Err(e), _) => warnings.push(say(format!("{e:#}"))),
            (Ok(_), None) => warnings.push(say("its -bm is not a number".into())),
            (Ok(t), Some(scale)) if key != "norm" && t.is_grey() => {
                mat.height_map = Some(t);
                mat.height_scale = scale;
            }
            (Ok(t), Some(scale)) => {
                mat.normal_map = Some(t);
                mat.normal_scale = scale;
            }
        }
    }
    mat
}

/// The smoothing group of every face, or all 0 (flat) where the file's `s` lines do not match
/// the faces tobj read (with a warning if any face had a group).
fn face_groups(
    path: &Path,
    bytes: &[u8],
    models: &[tobj::Model],
    warnings: &mut Vec<String>,
) -> Vec<u32> {
    let mut groups = smoothing_groups(&String::from_utf8_lossy(bytes));
    let face_count: usize = models
        .iter()
        .map(|m| match m.mesh.face_arities.len() {
            0 => m.mesh.indices.len() / 3,
            n => n,
        })
        .sum();
    if groups.len() != face_count {
        if groups.iter().any(|&g| g != 0) {
            warnings.push(format!(
                "{}: smoothing groups ignored ({} faces read, {} found by tobj); faces are flat",
                path.display(),
                groups.len(),
                face_count
            ));
        }
        groups = vec![0; face_count];
    }
    groups
}

/// Appends one model's faces to `mesh`, fan-triangulated, in `material`: with the file's
/// normals where every corner has one, else normals by `rule` (the smoothing groups, read from
/// `groups` at `next_face` onwards, by default); and its texture coordinates where it has
/// them.
fn append_model(
    mesh: &mut Mesh,
    m: &tobj::Mesh,
    positions: &[Vec3],
    material: u32,
    (groups, next_face): (&[u32], &mut usize),
    rule: Option<NormalRule>,
) {
    let normals: Vec<Vec3> = m
        .normals
        .chunks_exact(3)
        .map(|n| Vec3::new(n[0] as f32, n[1] as f32, n[2] as f32))
        .collect();
    let has_normals = !m.normal_indices.is_empty() && m.normal_indices.len() == m.indices.len();

    // Fan-triangulate every face: (0, k, k + 1).
    let mut faces: Vec<[usize; 3]> = Vec::new(); // corners as offsets into m.indices
    let mut face_groups: Vec<u32> = Vec::new(); // the smoothing group of each triangle
    let mut offset = 0usize;
    let arities: Box<dyn Iterator<Item = usize>> = if m.face_arities.is_empty() {
        Box::new(std::iter::repeat_n(3, m.indices.len() / 3))
    } else {
        Box::new(m.face_arities.iter().map(|&a| a as usize))
    };
    for arity in arities {
        let group = groups.get(*next_face).copied().unwrap_or(0);
        *next_face += 1;
        for k in 1..arity.saturating_sub(1) {
            faces.push([offset, offset + k, offset + k + 1]);
            face_groups.push(group);
        }
        offset += arity;
    }

    // Texture coordinates, `v` flipped: OBJ counts it from the image's bottom row.
    let has_uvs = !m.texcoords.is_empty() && m.texcoord_indices.len() == m.indices.len();
    let uvs: Option<Vec<[Vec2; 3]>> = has_uvs.then(|| {
        faces
            .iter()
            .map(|f| {
                f.map(|c| {
                    let i = m.texcoord_indices[c] as usize;
                    match m.texcoords.get(2 * i..2 * i + 2) {
                        Some(t) => Vec2::new(t[0] as f32, 1.0 - t[1] as f32),
                        None => Vec2::ZERO,
                    }
                })
            })
            .collect()
    });
    let before = mesh.triangles.len();

    if has_normals {
        for f in &faces {
            let tri = f.map(|c| positions[m.indices[c] as usize]);
            let fallback = face_normal(&tri);
            let n = f.map(|c| {
                normals
                    .get(m.normal_indices[c] as usize)
                    .and_then(|n| n.try_normalize())
                    .unwrap_or(fallback)
            });
            mesh.triangles.push(tri);
            mesh.normals.push(n);
            mesh.material_ids.push(material);
        }
    } else {
        let idx: Vec<[u32; 3]> = faces.iter().map(|f| f.map(|c| m.indices[c])).collect();
        let rule = rule.unwrap_or(NormalRule::Groups);
        mesh.append(
            Mesh::from_indexed(positions, &idx, material, rule, &face_groups),
            0,
        );
    }
    if let Some(uvs) = uvs {
        mesh.uvs.resize(before, [Vec2::ZERO; 3]);
        mesh.uvs.extend(uvs);
    }
}

fn convert_material(m: &tobj::Material) -> Material {
    // tobj reads in f64 (positions need it); material values are f32 here.
    let v = |a: Option<[f64; 3]>, d: Vec3| a.map(|c| Vec3::from(c.map(|x| x as f32))).unwrap_or(d);
    let f = |x: Option<f64>| x.map(|x| x as f32);
    let param = |k: &str| {
        m.unknown_param
            .get(k)
            .and_then(|s| s.trim().parse::<f32>().ok())
    };
    let illum = m.illumination_model.unwrap_or(2) as u32;
    let specular = v(m.specular, Vec3::ZERO);
    let opacity = f(m.dissolve)
        .or_else(|| param("Tr").map(|tr| 1.0 - tr))
        .unwrap_or(1.0)
        .clamp(0.0, 1.0);
    let emission = m
        .emissive
        .map(|c| Vec3::from(c.map(|x| x as f32)))
        .or_else(|| {
            m.unknown_param.get("Ke").and_then(|s| {
                let v: Vec<f32> = s
                    .split_whitespace()
                    .filter_map(|x| x.parse().ok())
                    .collect();
                (v.len() == 3).then(|| Vec3::new(v[0], v[1], v[2]))
            })
        })
        .unwrap_or(Vec3::ZERO);
    Material {
        name: m.name.clone(),
        diffuse: v(m.diffuse, Vec3::splat(0.7)),
        specular,
        shininess: f(m.shininess).unwrap_or(1.0),
        emission,
        opacity,
        ior: f(m.optical_density).unwrap_or(1.0),
        mirror: if matches!(illum, 3 | 5 | 7) {
            specular
        } else {
            Vec3::ZERO
        },
        absorption: Vec3::ZERO,
        illum,
        ..Material::default()
    }
}

/// Finds the first line that explains a `tobj` error: the line number and what is wrong.
fn locate_error(text: &str, err: tobj::LoadError) -> Option<(usize, String)> {
    use tobj::LoadError as E;
    if matches!(err, E::ReadError) {
        // tobj reads line by line as UTF-8; `text` was decoded lossily, so the first
        // replacement character marks the first line that is not UTF-8.
        return text.find('\u{FFFD}').map(|pos| {
            (
                super::line_of(text, pos),
                "not UTF-8 text (UTF-16 or another encoding?)".into(),
            )
        });
    }
    let (mut nv, mut nvt, mut nvn) = (0i64, 0i64, 0i64);
    let floats = |rest: &[&str], min: usize, max: usize| {
        rest.len() >= min && rest.len() <= max && rest.iter().all(|t| t.parse::<f32>().is_ok())
    };
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        let toks: Vec<&str> = raw.split_whitespace().collect();
        let Some((&key, rest)) = toks.split_first() else {
            continue;
        };
        match key {
            "usemtl" | "mtllib" if matches!(err, E::MaterialParseError) && rest.is_empty() => {
                return Some((line, format!("`{key}` needs a name")));
            }
            "v" => {
                if matches!(err, E::PositionParseError) && !floats(rest, 3, 7) {
                    return Some((line, format!("expected 3 numbers in `{}`", raw.trim())));
                }
                nv += 1;
            }
            "vt" => {
                if matches!(err, E::TexcoordParseError) && !floats(rest, 1, 3) {
                    return Some((line, format!("expected 1 to 3 numbers in `{}`", raw.trim())));
                }
                nvt += 1;
            }
            "vn" => {
                if matches!(err, E::NormalParseError) && !floats(rest, 3, 3) {
                    return Some((line, format!("expected 3 numbers in `{}`", raw.trim())));
                }
                nvn += 1;
            }
            "f" => {
                let face_err = matches!(
                    err,
                    E::FaceParseError
                        | E::InvalidPolygon
                        | E::FaceVertexOutOfBounds
                        | E::FaceTexCoordOutOfBounds
                        | E::FaceNormalOutOfBounds
                );
                if !face_err {
                    continue;
                }
                if rest.len() < 3 {
                    return Some((line, "a face needs at least 3 vertices".into()));
                }
                for corner in rest {
                    let mut parts = corner.split('/');
                    for (slot, count) in [nv, nvt, nvn].iter().enumerate() {
                        let Some(p) = parts.next() else { break };
                        if p.is_empty() && slot > 0 {
                            continue;
                        }
                        let Ok(idx) = p.parse::<i64>() else {
                            return Some((line, format!("`{corner}` is not a vertex reference")));
                        };
                        let resolved = if idx < 0 { count + idx } else { idx - 1 };
                        if idx == 0 || resolved < 0 || resolved >= *count {
                            let what = ["vertex", "texture coordinate", "normal"][slot];
                            return Some((
                                line,
                                format!(
                                    "{what} index {idx} is out of range ({count} defined so far)"
                                ),
                            ));
                        }
                    }
                }
            }
            _ => {}
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::TextureLine;

    fn line(file: &str, bump: Option<&str>, channel: Option<&str>) -> TextureLine {
        TextureLine {
            file: file.into(),
            bump: bump.map(Into::into),
            channel: channel.map(Into::into),
        }
    }

    /// Options are skipped with their values wherever they stand; the words left name the file,
    /// spaces included (lines of tinyobjloader's test models among them).
    #[test]
    fn a_texture_line_names_its_file_past_its_options() {
        for (spec, expected) in [
            ("tex.png", line("tex.png", None, None)),
            ("-s 1 1 1 -o 0.5 0.5 tex.png", line("tex.png", None, None)),
            ("-s 2 tex.png", line("tex.png", None, None)),
            ("-bm 2 bump 01.png", line("bump 01.png", Some("2"), None)),
            (
                "-imfchan r bumpmap2.jpg -bm 1.5",
                line("bumpmap2.jpg", Some("1.5"), Some("r")),
            ),
            (
                "-colorspace linear -bm 3 bumpmap.jpg",
                line("bumpmap.jpg", Some("3"), None),
            ),
            (
                "-clamp on -blendu off -mm 0 1 -texres 512 -type sphere t.png",
                line("t.png", None, None),
            ),
            ("-bm x n.png", line("n.png", Some("x"), None)),
            ("-weird t.png", line("-weird t.png", None, None)),
        ] {
            assert_eq!(TextureLine::parse(spec), expected, "{spec}");
        }
        assert_eq!(
            TextureLine::parse("-bm 0.25 n.png").bump_multiplier(),
            Some(0.25)
        );
        assert_eq!(TextureLine::parse("n.png").bump_multiplier(), Some(1.0));
        assert_eq!(TextureLine::parse("-bm nan n.png").bump_multiplier(), None);
        assert_eq!(TextureLine::parse("-bm x n.png").bump_multiplier(), None);
    }
}
