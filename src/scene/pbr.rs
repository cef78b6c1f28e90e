//! glTF's metallic-roughness material model as the renderer's lobes: a Lambertian diffuse
//! colour, a GGX microfacet lobe (the glTF 2.0 specification's BRDF, evaluated in
//! the renderer's `render::bsdf`) and, for smooth metals, a mirror.
//!
//! [`lobes`] is the one mapping, used twice: by the glTF loader for a material's factors
//! ([`super::gltf::convert_material`]), and at every shading point of a material whose
//! textures vary those factors over its surface (the base colour texture, the
//! `metallicRoughnessTexture`), so that a texel equal to 1 everywhere gives the same picture as
//! the factors alone.

use std::sync::Arc;

use glam::{Vec3, Vec4};

use super::Texture;

/// A glTF metallic-roughness material's parameters, kept on [`super::Material::pbr`] so that
/// its textures can be applied where a ray meets it.
#[derive(Clone, Debug, PartialEq)]
pub struct MetallicRoughness {
    /// Base colour factor (linear RGB in `[0, 1]`); the base colour texture multiplies it.
    pub base: Vec3,
    /// Metalness factor in `[0, 1]`.
    pub metallic: f32,
    /// Perceptual roughness factor in `[0, 1]`.
    pub roughness: f32,
    /// The `metallicRoughnessTexture` (linear values): its blue channel multiplies
    /// `metallic`, its green channel `roughness` (red and alpha are not read: packed
    /// occlusion, say).
    pub map: Option<Arc<Texture>>,
    /// A clear coat over the surface (glTF `KHR_materials_clearcoat`).
    pub clearcoat: Option<Clearcoat>,
    /// The dielectric part's specular reflection (glTF `KHR_materials_ior` and
    /// `KHR_materials_specular`; [`Specular::DEFAULT`] without them).
    pub specular: Specular,
    /// A sheen over the surface, under any clear coat (glTF `KHR_materials_sheen`).
    pub sheen: Option<SheenLayer>,
}

/// A sheen's parameters (glTF `KHR_materials_sheen`): the fibres of cloth over the material
/// (evaluated in the renderer's `render::bsdf::sheen`).
#[derive(Clone, Debug, PartialEq)]
pub struct SheenLayer {
    /// `sheenColorFactor` (linear RGB, at least 0).
    pub color: Vec3,
    /// `sheenRoughnessFactor`, in `[0, 1]`.
    pub roughness: f32,
    /// `sheenColorTexture` (sRGB, decoded): its RGB multiplies `color`.
    pub color_map: Option<Arc<Texture>>,
    /// `sheenRoughnessTexture` (linear): its alpha channel multiplies `roughness`.
    pub roughness_map: Option<Arc<Texture>>,
}

impl SheenLayer {
    /// The sheen's colour and roughness where its textures read `color_texel` and
    /// `roughness_texel` (`None`: no texture there).
    pub fn at(&self, color_texel: Option<Vec4>, roughness_texel: Option<Vec4>) -> (Vec3, f32) {
        let color = color_texel.map_or(self.color, |t| self.color * t.truncate());
        let roughness = self.roughness * roughness_texel.map_or(1.0, |t| t.w);
        (color.max(Vec3::ZERO), roughness.clamp(0.0, 1.0))
    }
}

/// The specular reflection of a material's dielectric part: its index of refraction (glTF
/// `KHR_materials_ior`) and `KHR_materials_specular`'s strength and colour.
#[derive(Clone, Debug, PartialEq)]
pub struct Specular {
    /// Index of refraction (1.5 by default; 0 allowed, for `f0 = 1`).
    pub ior: f32,
    /// `specularFactor`, in `[0, 1]`: scales the dielectric's Fresnel, at grazing angles too.
    pub factor: f32,
    /// `specularColorFactor` (linear RGB, at least 0): tints the dielectric's `f0`.
    pub color: Vec3,
    /// `specularTexture` (linear): its alpha channel multiplies `factor`.
    pub map: Option<Arc<Texture>>,
    /// `specularColorTexture` (sRGB, decoded): its RGB multiplies `color`.
    pub color_map: Option<Arc<Texture>>,
}

impl Specular {
    /// Neither extension: index 1.5, full strength, white.
    pub const DEFAULT: Specular = Specular {
        ior: 1.5,
        factor: 1.0,
        color: Vec3::ONE,
        map: None,
        color_map: None,
    };

    /// The dielectric's Fresnel where its textures read `texel` and `color_texel` (`None`: no
    /// texture there), as `KHR_materials_specular` defines it: `f0 = min(((ior - 1) / (ior +
    /// 1))^2 color, 1)`, weight `factor`.
    pub fn at(&self, texel: Option<Vec4>, color_texel: Option<Vec4>) -> Dielectric {
        let r = ((self.ior as f64 - 1.0) / (self.ior as f64 + 1.0)).powi(2) as f32;
        let color = color_texel.map_or(self.color, |t| self.color * t.truncate());
        Dielectric {
            f0: (r * color).clamp(Vec3::ZERO, Vec3::ONE),
            weight: (self.factor * texel.map_or(1.0, |t| t.w)).clamp(0.0, 1.0),
        }
    }

    /// True when a texture varies it over the surface.
    pub fn is_textured(&self) -> bool {
        self.map.is_some() || self.color_map.is_some()
    }
}

/// The Fresnel of a material's dielectric part at one point: `weight (f0 + (1 - f0) (1 -
/// cos)^5)` on its specular lobe, and its largest channel dims the diffuse lobe under it
/// (`KHR_materials_specular`'s `fresnel_mix`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dielectric {
    /// Reflectance at normal incidence (before `weight`).
    pub f0: Vec3,
    /// Strength of the whole Fresnel term, in `[0, 1]`.
    pub weight: f32,
}

impl Dielectric {
    /// The core specification's dielectric: `f0 = 0.04` (index 1.5), full strength.
    pub const DEFAULT: Dielectric = Dielectric {
        f0: Vec3::splat(0.04),
        weight: 1.0,
    };
}

/// What the textures of a metallic-roughness material read at one point (`None`: no such
/// texture).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Texels {
    /// The base colour texture's linear RGB.
    pub base: Option<Vec3>,
    /// The metallic-roughness texture.
    pub mr: Option<Vec4>,
    /// `specularTexture`.
    pub specular: Option<Vec4>,
    /// `specularColorTexture` (decoded to linear).
    pub specular_color: Option<Vec4>,
}

/// A clear coat's parameters (glTF `KHR_materials_clearcoat`): a dielectric GGX layer over
/// the material.
#[derive(Clone, Debug, PartialEq)]
pub struct Clearcoat {
    /// How much of the surface the coat covers, in `[0, 1]`.
    pub factor: f32,
    /// The coat's perceptual roughness, in `[0, 1]`.
    pub roughness: f32,
    /// `clearcoatTexture` (linear): its red channel multiplies `factor`.
    pub map: Option<Arc<Texture>>,
    /// `clearcoatRoughnessTexture` (linear): its green channel multiplies `roughness`.
    pub roughness_map: Option<Arc<Texture>>,
    /// `clearcoatNormalTexture`: a tangent-space normal map of the coat alone (without it,
    /// the coat follows the surface's normal, not the base's normal map).
    pub normal_map: Option<Arc<Texture>>,
    /// The coat normal map's `scale`.
    pub normal_scale: f32,
}

impl Clearcoat {
    /// The coat's weight and GGX width where its textures read `texel` and `roughness_texel`
    /// (`None`: no texture there).
    pub fn at(&self, texel: Option<Vec4>, roughness_texel: Option<Vec4>) -> (f32, f32) {
        let weight = (self.factor * texel.map_or(1.0, |t| t.x)).clamp(0.0, 1.0);
        let r = (self.roughness * roughness_texel.map_or(1.0, |t| t.y)).clamp(0.0, 1.0);
        (weight, (r * r).max(MIN_ALPHA))
    }
}

impl MetallicRoughness {
    /// The lobes where the material's textures read `texels`.
    pub fn lobes_at(&self, texels: Texels) -> Lobes {
        let base = texels.base.map_or(self.base, |t| self.base * t);
        let (metallic, roughness) = match texels.mr {
            Some(t) => (self.metallic * t.z, self.roughness * t.y),
            None => (self.metallic, self.roughness),
        };
        let dielectric = self.specular.at(texels.specular, texels.specular_color);
        lobes(base, metallic, roughness, dielectric)
    }

    /// True when a texture varies the lobes over the surface (the clear coat's aside).
    pub fn is_textured(&self) -> bool {
        self.map.is_some() || self.specular.is_textured()
    }

    /// True when some point of the surface may reflect as a mirror: the factors say so, or a
    /// texture may lower the roughness enough where the metalness factor allows it.
    pub fn may_mirror(&self) -> bool {
        self.metallic >= MIRROR_METALLIC
            && (self.roughness <= MIRROR_ROUGHNESS || self.map.is_some())
    }
}

/// What the renderer's shading reads of a material at one point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lobes {
    /// Lambertian colour (under the dielectric's Fresnel, see the renderer's `render::bsdf`).
    pub diffuse: Vec3,
    /// GGX lobe's reflectance at normal incidence (zero where the point is a mirror).
    pub f0: Vec3,
    /// GGX lobe's reflectance at grazing incidence (1 but for a weakened dielectric).
    pub f90: f32,
    /// The dielectric's Fresnel, which dims the diffuse lobe.
    pub dielectric: Dielectric,
    /// GGX width `roughness^2`, at least [`MIN_ALPHA`].
    pub alpha: f32,
    /// Mirror reflectance (zero unless the point is a smooth metal).
    pub mirror: Vec3,
}

/// Narrowest GGX lobe drawn: roughness below 0.1 is drawn as this width, or, for a metal, as
/// a mirror.
pub const MIN_ALPHA: f32 = MIRROR_ROUGHNESS * MIRROR_ROUGHNESS;

/// Metalness from which a smooth surface is drawn as a mirror.
const MIRROR_METALLIC: f32 = 0.5;
/// Roughness up to which a metal is drawn as a mirror (a GGX lobe of width 0.01 shows its
/// surroundings almost as sharply, and the `direct` integrator traces mirror rays only).
const MIRROR_ROUGHNESS: f32 = 0.1;

/// The lobes of base colour `base`, metalness `metallic` and roughness `roughness` (each
/// clamped to `[0, 1]`) over a dielectric of Fresnel `dielectric` ([`Dielectric::DEFAULT`]
/// in the core specification):
/// - diffuse: `base (1 - metallic)` (dimmed under the dielectric's Fresnel when shaded);
/// - GGX: Schlick's Fresnel from `f0 = mix(weight f0_d, base, metallic)` at normal incidence
///   to `f90 = mix(weight, 1, metallic)` at grazing (for a dielectric its `f0` and `weight`,
///   for a metal the base colour and 1: the metallic mix of the two Fresnel terms, exactly),
///   width `alpha = roughness^2`;
/// - mirror: a metal (metalness at least 0.5) with roughness at most 0.1 is drawn as a mirror
///   of reflectance `f0` instead of a GGX lobe.
pub fn lobes(base: Vec3, metallic: f32, roughness: f32, dielectric: Dielectric) -> Lobes {
    let base = base.clamp(Vec3::ZERO, Vec3::ONE);
    let metallic = metallic.clamp(0.0, 1.0);
    let roughness = roughness.clamp(0.0, 1.0);
    let w = dielectric.weight;
    let f0 = (dielectric.f0 * w).lerp(base, metallic);
    let f90 = w + (1.0 - w) * metallic;
    let alpha = (roughness * roughness).max(MIN_ALPHA);
    let mirror_like = metallic >= MIRROR_METALLIC && roughness <= MIRROR_ROUGHNESS;
    Lobes {
        diffuse: base * (1.0 - metallic),
        f0: if mirror_like { Vec3::ZERO } else { f0 },
        f90,
        dielectric,
        alpha,
        mirror: if mirror_like { f0 } else { Vec3::ZERO },
    }
}

/// The Blinn-Phong exponent of about the width of a GGX lobe of width `alpha` (`2 / alpha^2 -
/// 2`, Walter et al. 2007), for showing a material's figures; shading uses the GGX lobe.
pub fn phong_exponent(alpha: f32) -> f32 {
    (2.0 / (alpha * alpha) - 2.0).clamp(0.0, 10_000.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    const D: Dielectric = Dielectric::DEFAULT;

    #[test]
    fn dielectrics_metals_and_mirrors() {
        let red = Vec3::new(0.8, 0.1, 0.1);
        let paint = lobes(red, 0.0, 1.0, D);
        assert_eq!(paint.diffuse, red);
        assert_eq!(paint.f0, Vec3::splat(0.04));
        assert_eq!(paint.alpha, 1.0);
        assert_eq!(phong_exponent(paint.alpha), 0.0, "roughness 1: exponent 0");
        assert_eq!(paint.mirror, Vec3::ZERO);
        let brushed = lobes(red, 1.0, 0.5, D);
        assert_eq!(brushed.diffuse, Vec3::ZERO);
        assert_eq!(brushed.f0, red);
        assert_eq!(brushed.alpha, 0.25);
        let chrome = lobes(red, 1.0, 0.1, D);
        assert_eq!((chrome.f0, chrome.mirror), (Vec3::ZERO, red));
        let glossy = lobes(red, 1.0, 0.11, D);
        assert_eq!((glossy.f0, glossy.mirror), (red, Vec3::ZERO));
        // A smooth dielectric keeps the narrowest GGX lobe.
        let lacquer = lobes(red, 0.0, 0.0, D);
        assert_eq!((lacquer.alpha, lacquer.mirror), (MIN_ALPHA, Vec3::ZERO));
        // Out of range and NaN-free inputs are clamped, never passed on.
        let wild = lobes(Vec3::splat(4.0), 2.0, -1.0, D);
        assert_eq!(wild.mirror, Vec3::ONE);
        assert_eq!(wild.alpha, MIN_ALPHA);
        assert_eq!(phong_exponent(1e-3), 10_000.0);
    }

    #[test]
    fn ior_and_specular_set_the_dielectrics_fresnel() {
        // The default is the core specification's, exactly (pictures without the extensions
        // do not change).
        assert_eq!(Specular::DEFAULT.at(None, None), D);
        let glassy = Specular {
            ior: 2.0,
            ..Specular::DEFAULT
        };
        assert_eq!(glassy.at(None, None).f0, Vec3::splat(1.0 / 9.0));
        let zero = Specular {
            ior: 0.0,
            ..Specular::DEFAULT
        };
        assert_eq!(zero.at(None, None).f0, Vec3::ONE, "ior 0: f0 = 1");
        let tinted = Specular {
            factor: 0.5,
            color: Vec3::new(30.0, 0.5, 0.0),
            ..Specular::DEFAULT
        };
        let at = tinted.at(
            Some(Vec4::new(0.0, 0.0, 0.0, 0.5)),
            Some(Vec4::new(1.0, 0.5, 1.0, 0.0)),
        );
        assert_eq!(at.weight, 0.25, "factor times the texture's alpha");
        assert_eq!(
            at.f0,
            Vec3::new(1.0, 0.01, 0.0),
            "f0 times colour and texel, at most 1"
        );
        // Half strength: a dielectric's Fresnel halved at grazing angles too; a metal's not.
        let half = Dielectric {
            f0: Vec3::splat(0.04),
            weight: 0.5,
        };
        let paint = lobes(Vec3::ONE, 0.0, 1.0, half);
        assert_eq!((paint.f0, paint.f90), (Vec3::splat(0.02), 0.5));
        let metal = lobes(Vec3::splat(0.5), 1.0, 1.0, half);
        assert_eq!((metal.f0, metal.f90), (Vec3::splat(0.5), 1.0));
        assert_eq!(lobes(Vec3::ONE, 0.0, 1.0, D).f90, 1.0);
    }

    #[test]
    fn texels_multiply_the_factors_blue_metalness_green_roughness() {
        let m = MetallicRoughness {
            base: Vec3::new(1.0, 0.5, 0.25),
            metallic: 1.0,
            roughness: 1.0,
            map: None,
            clearcoat: None,
            sheen: None,
            specular: Specular::DEFAULT,
        };
        // Blue 1, green 0.5: a metal of roughness 0.5.
        let at = m.lobes_at(Texels {
            base: Some(Vec3::new(0.5, 1.0, 1.0)),
            mr: Some(Vec4::new(0.0, 0.5, 1.0, 1.0)),
            ..Texels::default()
        });
        assert_eq!(at, lobes(Vec3::new(0.5, 0.5, 0.25), 1.0, 0.5, D));
        // Blue 0, green 1: a rough dielectric.
        let at = m.lobes_at(Texels {
            mr: Some(Vec4::new(1.0, 1.0, 0.0, 0.0)),
            ..Texels::default()
        });
        assert_eq!(at, lobes(m.base, 0.0, 1.0, D));
        assert_eq!(m.lobes_at(Texels::default()), lobes(m.base, 1.0, 1.0, D));
    }

    #[test]
    fn a_texture_may_make_a_metal_a_mirror_but_not_a_dielectric() {
        let mut m = MetallicRoughness {
            base: Vec3::ONE,
            metallic: 1.0,
            roughness: 1.0,
            map: None,
            clearcoat: None,
            sheen: None,
            specular: Specular::DEFAULT,
        };
        assert!(!m.may_mirror(), "rough everywhere");
        m.map = Some(Arc::new(Texture::from_rgba8(
            "t".into(),
            1,
            1,
            vec![[0, 0, 255, 255]],
            false,
        )));
        assert!(m.may_mirror(), "a texel may lower the roughness");
        m.metallic = 0.4;
        assert!(
            !m.may_mirror(),
            "no texel raises the metalness past its factor"
        );
    }
}
