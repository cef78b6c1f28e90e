//! The dielectric layer of glTF's metallic-roughness BRDF: the share of light its Fresnel
//! reflection leaves for the diffuse lobe under it (the specification's `fresnel_mix`), with
//! `KHR_materials_specular`'s strength and colour at normal incidence.

use super::microfacet::schlick_scalar;

/// The dielectric over a diffuse lobe.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DielectricLayer {
    /// Its largest reflectance at normal incidence (0.04 by default).
    pub f0: f32,
    /// Its Fresnel strength (`KHR_materials_specular`; 1 by default).
    pub weight: f32,
}

impl DielectricLayer {
    /// The share of light that reaches the lobe under it, seen at cosine `c` to the half
    /// vector: `1 - weight F(c)`.
    #[inline]
    pub fn transmitted(&self, c: f32) -> f32 {
        1.0 - self.weight * schlick_scalar(self.f0, c)
    }
}
