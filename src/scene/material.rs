//! A surface's material: the MTL file's fields, and the glTF metallic-roughness model beside
//! them ([`super::pbr`]), with the textures that vary them.

use std::sync::Arc;

use glam::Vec3;

use super::{Texture, pbr};

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
