//! A render split by samples: each part traces the sample indices `A..B` of every pixel
//! ([`super::render_samples`]) and writes its sums as a partial film (an EXR); the parts of one
//! render merge into the film of the whole, bit for bit, because every sample is a function of
//! (pixel, sample index, seed) and the film's sums are exact integers ([`Sum`]).
//!
//! A part's EXR holds, per pixel: `R`, `G`, `B`, the raw sums as floats (to look at: divide by
//! `count` for the picture); `count`, the samples taken (a 32-bit integer channel); and the
//! exact sums, each channel's 64-bit integer as two 32-bit halves (`sum.R.hi`, `sum.R.lo`,
//! ...), which [`merge`] adds. Its header names the render: the build of Tracery that rendered
//! it, the scene's hash, the settings that choose the samples' values, and the range.

use std::ops::Range;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, anyhow, bail};

use super::RenderSettings;
use crate::film::{Film, Sum};
use crate::scene::Scene;

/// The build that writes parts: the program's version and the commit it was built from.
/// Parts of one render must come from one build, since a sample's value may change from one
/// build to the next (a new sampler, a fixed bug) while the scene and settings stay the same.
pub const BUILD: &str = concat!(env!("CARGO_PKG_VERSION"), " (", env!("TRACERY_COMMIT"), ")");

/// What every part of one render shares: merging parts whose keys differ is refused.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PartKey {
    /// The build of Tracery that rendered the part ([`BUILD`]; `unknown` in parts written
    /// before parts recorded it).
    pub build: String,
    /// The scene's hash ([`scene_hash`]).
    pub scene: String,
    /// The settings that choose the samples' values (resolution, seed, sampler, depth), as
    /// text.
    pub settings: String,
}

impl PartKey {
    /// The key of a render of `scene` with `settings` (its `spp` left out: parts differ in
    /// how many samples they take).
    pub fn of(scene: &Scene, settings: &RenderSettings) -> PartKey {
        let settings = RenderSettings {
            spp: 0,
            ..settings.clone()
        };
        PartKey {
            build: BUILD.to_string(),
            scene: scene_hash(scene),
            settings: format!("{settings:?}"),
        }
    }
}

/// The sums of the sample indices `range` of every pixel of a render.
#[derive(Clone, Debug, PartialEq)]
pub struct Part {
    /// The sums (`film.samples` is the range's length).
    pub film: Film,
    /// The sample indices, half-open.
    pub range: Range<u32>,
    /// The render it is part of.
    pub key: PartKey,
}

/// Header attributes of a part's EXR.
const SCENE: &str = "tracery.scene";
const SETTINGS: &str = "tracery.settings";
const RANGE: &str = "tracery.samples";
const REJECTED: &str = "tracery.rejected";
const BUILT_BY: &str = "tracery.build";

impl Part {
    /// Writes the part as an EXR at `path`: written beside it under another name first and
    /// renamed into place, so a part is there whole or not at all (a task run again writes
    /// the same file over it).
    pub fn save(&self, path: &Path) -> Result<()> {
        use exr::prelude::*;
        let f = &self.film;
        let n = f.sum.len();
        let mut channels: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::new();
        for (c, name) in ["R", "G", "B"].into_iter().enumerate() {
            let raw = f.sum.iter().map(|s| s.to_vec3()[c]).collect();
            channels.push(AnyChannel::new(name, FlatSamples::F32(raw)));
            let bits = |half: fn(i64) -> u32| f.sum.iter().map(|s| half(s.0[c])).collect();
            channels.push(AnyChannel::new(
                format!("sum.{name}.hi").as_str(),
                FlatSamples::U32(bits(|v| ((v as u64) >> 32) as u32)),
            ));
            channels.push(AnyChannel::new(
                format!("sum.{name}.lo").as_str(),
                FlatSamples::U32(bits(|v| v as u64 as u32)),
            ));
        }
        channels.push(AnyChannel::new(
            "count",
            FlatSamples::U32(vec![f.samples; n]),
        ));
        let mut attributes = LayerAttributes::named("tracery part");
        for (k, v) in [
            (BUILT_BY, self.key.build.clone()),
            (SCENE, self.key.scene.clone()),
            (SETTINGS, self.key.settings.clone()),
            (RANGE, format!("{}..{}", self.range.start, self.range.end)),
            (REJECTED, f.rejected.to_string()),
        ] {
            attributes
                .other
                .insert(Text::from(k), AttributeValue::Text(Text::from(v.as_str())));
        }
        let layer = Layer::new(
            (f.width as usize, f.height as usize),
            attributes,
            Encoding::SMALL_LOSSLESS,
            AnyChannels::sort(channels),
        );
        let name = path
            .file_name()
            .ok_or_else(|| anyhow!("{}: not a file name", path.display()))?;
        let mut temporary = name.to_os_string();
        temporary.push(format!(".partial-{}", std::process::id()));
        let temporary = path.with_file_name(temporary);
        Image::from_layer(layer)
            .write()
            .to_file(&temporary)
            .with_context(|| format!("{}: cannot write the part", temporary.display()))?;
        std::fs::rename(&temporary, path).with_context(|| {
            format!(
                "cannot move {} into place as {}",
                temporary.display(),
                path.display()
            )
        })
    }

    /// Reads a part written by [`Part::save`]; an EXR that is not one is an error naming the
    /// file and what is missing.
    pub fn load(path: &Path) -> Result<Part> {
        use exr::prelude::*;
        let image = read_all_flat_layers_from_file(path)
            .with_context(|| format!("{}: cannot read EXR", path.display()))?;
        let not_part = |what: &str| {
            anyhow!(
                "{}: not a Tracery part ({what}; parts are written by `tracery render --samples A..B`)",
                path.display()
            )
        };
        let layer = image
            .layer_data
            .first()
            .ok_or_else(|| not_part("no layer"))?;
        let text = |k: &str| match layer.attributes.other.get(&Text::from(k)) {
            Some(AttributeValue::Text(t)) => Ok(t.to_string()),
            _ => Err(not_part(&format!("no `{k}` attribute"))),
        };
        let key = PartKey {
            build: text(BUILT_BY).unwrap_or_else(|_| "unknown".into()),
            scene: text(SCENE)?,
            settings: text(SETTINGS)?,
        };
        let range = text(RANGE)?;
        let range = parse_range(&range).map_err(|e| not_part(&e))?;
        let rejected = text(REJECTED)?
            .parse::<u64>()
            .map_err(|_| not_part("a `tracery.rejected` that is not a count"))?;
        let (w, h) = (layer.size.0, layer.size.1);
        let channel = |name: &str| -> anyhow::Result<&[u32]> {
            layer
                .channel_data
                .list
                .iter()
                .find(|c| c.name.eq(name))
                .and_then(|c| match &c.sample_data {
                    FlatSamples::U32(v) => Some(&v[..]),
                    _ => None,
                })
                .ok_or_else(|| not_part(&format!("no 32-bit integer channel `{name}`")))
        };
        let count = channel("count")?;
        let samples = range.end - range.start;
        if let Some(c) = count.iter().find(|&&c| c != samples) {
            return Err(not_part(&format!(
                "a pixel counts {c} samples, the range {}..{} is {samples}",
                range.start, range.end
            )));
        }
        let mut sum = vec![Sum::ZERO; w * h];
        for (c, name) in ["R", "G", "B"].into_iter().enumerate() {
            let hi = channel(&format!("sum.{name}.hi"))?;
            let lo = channel(&format!("sum.{name}.lo"))?;
            for (s, (&hi, &lo)) in sum.iter_mut().zip(hi.iter().zip(lo)) {
                s.0[c] = (((hi as u64) << 32) | lo as u64) as i64;
            }
        }
        Ok(Part {
            film: Film {
                width: w as u32,
                height: h as u32,
                sum,
                samples,
                rejected,
            },
            range,
            key,
        })
    }
}

/// Reads `A..B` (half-open, `A < B`).
pub fn parse_range(s: &str) -> Result<Range<u32>, String> {
    let (a, b) = s
        .split_once("..")
        .ok_or_else(|| format!("`{s}` is not a range A..B"))?;
    let num = |x: &str| {
        x.trim()
            .parse::<u32>()
            .map_err(|_| format!("`{x}` in `{s}` is not a sample index"))
    };
    let (a, b) = (num(a)?, num(b)?);
    if a >= b {
        return Err(format!("the range {a}..{b} holds no samples (A < B)"));
    }
    Ok(a..b)
}

/// Adds the parts into the film of the whole render: refused, with the files named, when two
/// parts are of different builds of Tracery, scenes, settings or sizes, when their ranges
/// overlap, or when they leave a gap (the ranges must cover `0..N` for the largest end `N`).
pub fn merge(parts: &[(PathBuf, Part)]) -> Result<Film> {
    let Some((first_path, first)) = parts.first() else {
        bail!("no parts to merge");
    };
    for (path, p) in &parts[1..] {
        if p.key.build != first.key.build {
            bail!(
                "{} and {} were rendered by different builds of tracery ({} and {}): a sample's \
                 value may differ between builds, so render every part with one build",
                first_path.display(),
                path.display(),
                first.key.build,
                p.key.build
            );
        }
        let what = if p.key.scene != first.key.scene {
            Some("scenes")
        } else if p.key.settings != first.key.settings {
            Some("settings")
        } else if (p.film.width, p.film.height) != (first.film.width, first.film.height) {
            Some("sizes")
        } else {
            None
        };
        if let Some(what) = what {
            bail!(
                "{} and {} are parts of renders of different {what}",
                first_path.display(),
                path.display()
            );
        }
    }
    let mut order: Vec<&(PathBuf, Part)> = parts.iter().collect();
    order.sort_by_key(|(_, p)| (p.range.start, p.range.end));
    let mut next = 0u32;
    let mut last: Option<&Path> = None;
    for (path, p) in &order {
        if p.range.start < next {
            bail!(
                "{} ({}..{}) overlaps {}: each sample range once",
                path.display(),
                p.range.start,
                p.range.end,
                last.map_or("another part".into(), |l| l.display().to_string())
            );
        }
        if p.range.start > next {
            bail!(
                "samples {next}..{} are missing (before {}{})",
                p.range.start,
                path.display(),
                last.map_or(String::new(), |l| format!(", after {}", l.display()))
            );
        }
        next = p.range.end;
        last = Some(path);
    }
    let mut film = Film::new(first.film.width, first.film.height);
    for (_, p) in &order {
        for (s, o) in film.sum.iter_mut().zip(&p.film.sum) {
            s.add(*o);
        }
        film.rejected += p.film.rejected;
    }
    film.samples = next;
    Ok(film)
}

/// A hash of everything in `scene` that a sample's value depends on (its triangles and what
/// they carry, placements, materials and the texels of their textures, lights, camera, the
/// environment and its files' bytes, integrator), as 16 hex digits: parts of renders of
/// different scenes are told apart.
pub fn scene_hash(scene: &Scene) -> String {
    let mut h = blake3::Hasher::new();
    let mut mesh = |m: &crate::scene::Mesh| {
        for t in m.triangles.iter().chain(&m.normals).flatten() {
            h.update(le_bytes(*t).as_slice());
        }
        for id in &m.material_ids {
            h.update(&id.to_le_bytes());
        }
        for uv in m.uvs.iter().chain(&m.uvs1).flatten() {
            h.update(&uv.x.to_le_bytes());
            h.update(&uv.y.to_le_bytes());
        }
        for t in m.tangents.iter().flatten() {
            for x in t.to_array() {
                h.update(&x.to_le_bytes());
            }
        }
    };
    mesh(&scene.mesh);
    for m in &scene.instances.meshes {
        mesh(m);
    }
    // The images themselves: a texture or an environment file changed between two parts under
    // the same name must not pass for the same scene.
    for t in scene.materials.iter().flat_map(|m| m.textures()) {
        h.update(t.texel_bytes());
        h.update(format!("{:?}{:?}{}", t.size(), t.transform, t.uv_set).as_bytes());
    }
    let files: &[std::path::PathBuf] = match &scene.environment {
        crate::scene::Environment::CubeMap { faces, .. } => faces,
        crate::scene::Environment::Equirect { path, .. } => std::slice::from_ref(path),
        _ => &[],
    };
    for f in files {
        // An unreadable file fails the render's own load of it; its name is hashed below.
        if let Ok(bytes) = std::fs::read(f) {
            h.update(&bytes);
        }
    }
    let text = format!(
        "{:?}{:?}{:?}{:?}{:?}{}",
        scene.instances.placements(),
        scene.materials,
        scene.lights,
        scene.camera,
        scene.environment,
        scene.integrator
    );
    h.update(text.as_bytes());
    h.update(&[scene.energy_compensation as u8]);
    h.finalize().to_hex()[..16].to_string()
}

/// A point's bytes, little-endian.
fn le_bytes(v: glam::Vec3) -> [u8; 12] {
    let mut out = [0u8; 12];
    for (o, x) in out.chunks_exact_mut(4).zip(v.to_array()) {
        o.copy_from_slice(&x.to_le_bytes());
    }
    out
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::scene_hash;
    use crate::scene::{Environment, Scene, Texture};

    /// A texture or an environment file whose contents change under the same name changes the
    /// hash, so parts rendered before and after such a change are not merged.
    #[test]
    fn the_hash_reads_texels_and_environment_files_not_only_names() {
        let mut scene = Scene::cornell_box();
        let plain = scene_hash(&scene);
        let wall = |v: u8| {
            let texels = vec![[v, v, v, 255]; 4];
            Arc::new(Texture::from_rgba8("wall.png".into(), 2, 2, texels, true))
        };
        scene.materials[0].diffuse_map = Some(wall(10));
        let textured = scene_hash(&scene);
        scene.materials[0].diffuse_map = Some(wall(11));
        let retextured = scene_hash(&scene);
        assert!(plain != textured && textured != retextured);

        let dir = std::env::temp_dir().join(format!("tracery-scene-hash-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let sky = dir.join("sky.hdr");
        std::fs::write(&sky, b"one sky").unwrap();
        scene.environment = Environment::Equirect {
            path: sky.clone(),
            intensity: 1.0,
            rotation_deg: 0.0,
        };
        let before = scene_hash(&scene);
        std::fs::write(&sky, b"another sky").unwrap();
        let after = scene_hash(&scene);
        std::fs::remove_dir_all(&dir).unwrap();
        assert_ne!(before, after);
        assert_eq!(scene_hash(&scene), scene_hash(&scene.clone()));
    }
}
