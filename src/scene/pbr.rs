//! glTF's metallic-roughness material model as the renderer's lobes: a Lambertian diffuse
//! colour, a GGX microfacet lobe (the glTF 2.0 specification's BRDF, evaluated in
//! [`crate::render::bsdf`]) and, for smooth metals, a mirror.
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
    /// The lobes where the base colour texture reads `base_texel` (linear RGB, `None`: no
    /// texture) and the metallic-roughness texture `mr_texel` (`None`: no texture).
    pub fn lobes_at(&self, base_texel: Option<Vec3>, mr_texel: Option<Vec4>) -> Lobes {
        let base = base_texel.map_or(self.base, |t| self.base * t);
        let (metallic, roughness) = match mr_texel {
            Some(t) => (self.metallic * t.z, self.roughness * t.y),
            None => (self.metallic, self.roughness),
        };
        lobes(base, metallic, roughness)
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
    /// Lambertian colour (under the dielectric's Fresnel, see [`crate::render::bsdf`]).
    pub diffuse: Vec3,
    /// GGX lobe's reflectance at normal incidence (zero where the point is a mirror).
    pub f0: Vec3,
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
/// clamped to `[0, 1]`):
/// - diffuse: `base (1 - metallic)`;
/// - GGX: the Fresnel colour at normal incidence, `f0 = mix(0.04, base, metallic)` (`0.04`
///   for a dielectric, the base colour for a metal), width `alpha = roughness^2`;
/// - mirror: a metal (metalness at least 0.5) with roughness at most 0.1 is drawn as a mirror
///   of reflectance `f0` instead of a GGX lobe.
pub fn lobes(base: Vec3, metallic: f32, roughness: f32) -> Lobes {
    let base = base.clamp(Vec3::ZERO, Vec3::ONE);
    let metallic = metallic.clamp(0.0, 1.0);
    let roughness = roughness.clamp(0.0, 1.0);
    let f0 = Vec3::splat(0.04).lerp(base, metallic);
    let alpha = (roughness * roughness).max(MIN_ALPHA);
    let mirror_like = metallic >= MIRROR_METALLIC && roughness <= MIRROR_ROUGHNESS;
    Lobes {
        diffuse: base * (1.0 - metallic),
        f0: if mirror_like { Vec3::ZERO } else { f0 },
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

    #[test]
    fn dielectrics_metals_and_mirrors() {
        let red = Vec3::new(0.8, 0.1, 0.1);
        let paint = lobes(red, 0.0, 1.0);
        assert_eq!(paint.diffuse, red);
        assert_eq!(paint.f0, Vec3::splat(0.04));
        assert_eq!(paint.alpha, 1.0);
        assert_eq!(phong_exponent(paint.alpha), 0.0, "roughness 1: exponent 0");
        assert_eq!(paint.mirror, Vec3::ZERO);
        let brushed = lobes(red, 1.0, 0.5);
        assert_eq!(brushed.diffuse, Vec3::ZERO);
        assert_eq!(brushed.f0, red);
        assert_eq!(brushed.alpha, 0.25);
        let chrome = lobes(red, 1.0, 0.1);
        assert_eq!((chrome.f0, chrome.mirror), (Vec3::ZERO, red));
        let glossy = lobes(red, 1.0, 0.11);
        assert_eq!((glossy.f0, glossy.mirror), (red, Vec3::ZERO));
        // A smooth dielectric keeps the narrowest GGX lobe.
        let lacquer = lobes(red, 0.0, 0.0);
        assert_eq!((lacquer.alpha, lacquer.mirror), (MIN_ALPHA, Vec3::ZERO));
        // Out of range and NaN-free inputs are clamped, never passed on.
        let wild = lobes(Vec3::splat(4.0), 2.0, -1.0);
        assert_eq!(wild.mirror, Vec3::ONE);
        assert_eq!(wild.alpha, MIN_ALPHA);
        assert_eq!(phong_exponent(1e-3), 10_000.0);
    }

    #[test]
    fn texels_multiply_the_factors_blue_metalness_green_roughness() {
        let m = MetallicRoughness {
            base: Vec3::new(1.0, 0.5, 0.25),
            metallic: 1.0,
            roughness: 1.0,
            map: None,
            clearcoat: None,
        };
        // Blue 1, green 0.5: a metal of roughness 0.5.
        let at = m.lobes_at(
            Some(Vec3::new(0.5, 1.0, 1.0)),
            Some(Vec4::new(0.0, 0.5, 1.0, 1.0)),
        );
        assert_eq!(at, lobes(Vec3::new(0.5, 0.5, 0.25), 1.0, 0.5));
        // Blue 0, green 1: a rough dielectric.
        let at = m.lobes_at(None, Some(Vec4::new(1.0, 1.0, 0.0, 0.0)));
        assert_eq!(at, lobes(m.base, 0.0, 1.0));
        assert_eq!(m.lobes_at(None, None), lobes(m.base, 1.0, 1.0));
    }

    #[test]
    fn a_texture_may_make_a_metal_a_mirror_but_not_a_dielectric() {
        let mut m = MetallicRoughness {
            base: Vec3::ONE,
            metallic: 1.0,
            roughness: 1.0,
            map: None,
            clearcoat: None,
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
