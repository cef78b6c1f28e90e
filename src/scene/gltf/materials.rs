//! glTF materials and textures: the metallic-roughness model and its extensions as the
//! renderer's materials, images decoded once, `KHR_texture_transform`.

use super::*;

impl Loader<'_> {
    /// The index in `materials` of glTF material `m`, converting it on first use.
    pub(super) fn material(&mut self, m: ::gltf::Material) -> Result<u32> {
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
                p.specular = crate::scene::pbr::Specular {
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
    pub(super) fn clearcoat(&mut self, label: &str, json: &serde_json::Value) -> Option<Clearcoat> {
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
    pub(super) fn sheen(&mut self, label: &str, json: &serde_json::Value) -> Option<SheenLayer> {
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
    pub(super) fn unit_factor(
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
    pub(super) fn color_factor(
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
    pub(super) fn specular(
        &mut self,
        label: &str,
        json: &serde_json::Value,
    ) -> crate::scene::pbr::Specular {
        let what = "KHR_materials_specular";
        let factor = self.unit_factor(label, what, json, "specularFactor", 1.0);
        let color = self.color_factor(label, what, json, "specularColorFactor", Vec3::ONE);
        let map = json.get("specularTexture").and_then(|info| {
            self.texture_json(label, &format!("{what}.specularTexture"), info, false)
        });
        let color_map = json.get("specularColorTexture").and_then(|info| {
            self.texture_json(label, &format!("{what}.specularColorTexture"), info, true)
        });
        crate::scene::pbr::Specular {
            factor,
            color,
            map,
            color_map,
            ..crate::scene::pbr::Specular::DEFAULT
        }
    }

    /// A texture named by the JSON of a `textureInfo` in an extension the gltf crate does not
    /// read (`srgb`: a colour texture, else linear values): its `index`, `texCoord` and
    /// `KHR_texture_transform`; `None`, with a warning, when it names no texture or its image
    /// cannot be had.
    pub(super) fn texture_json(
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
    pub(super) fn texture(
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
    pub(super) fn image_texture(
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
    pub(super) fn texture_image(
        &mut self,
        label: &str,
        what: &str,
        tex: &::gltf::Texture,
    ) -> Option<usize> {
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
    pub(super) fn transform_json(
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

/// A glTF metallic-roughness material as the renderer's [`Material`] (textures are attached by
/// the loader):
/// - diffuse, specular (the GGX lobe's `f0`) and mirror from the base colour, metalness and
///   roughness factors ([`crate::scene::pbr::lobes`]), shininess the Blinn-Phong exponent of about
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
    let specular = crate::scene::pbr::Specular {
        ior: dielectric_ior,
        ..crate::scene::pbr::Specular::DEFAULT
    };
    let lobes = crate::scene::pbr::lobes(base, metallic, roughness, specular.at(None, None));
    let strength = m.emissive_strength().unwrap_or(1.0).max(0.0);
    let emission = Vec3::from(m.emissive_factor()).max(Vec3::ZERO) * strength;
    // BLEND and MASK: the base alpha here, times the base colour texture's where shaded
    // (`Material::opacity_at`).
    let alpha = alpha.clamp(0.0, 1.0);
    let (mut opacity, alpha_mode) = match m.alpha_mode() {
        ::gltf::material::AlphaMode::Opaque => (1.0, crate::scene::AlphaMode::Opaque),
        ::gltf::material::AlphaMode::Mask => (
            alpha,
            crate::scene::AlphaMode::Mask(m.alpha_cutoff().unwrap_or(0.5)),
        ),
        ::gltf::material::AlphaMode::Blend => (alpha, crate::scene::AlphaMode::Blend),
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
        shininess: crate::scene::pbr::phong_exponent(lobes.alpha),
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
        pbr: Some(crate::scene::pbr::MetallicRoughness {
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
pub(super) fn valid_ior(ior: f32) -> bool {
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
