//! The GGX microfacet lobe (glTF metallic-roughness materials, scene files'
//! `metallic`/`roughness`), the conductor BRDF of the glTF 2.0 specification:
//! `F D G / (4 cos_i cos_o)` with the GGX (Trowbridge-Reitz) distribution of
//! `alpha = roughness^2`, Schlick's Fresnel from `f0` to `f90`, and Smith's masking-shadowing
//! in its separable form `G1(wi) G1(wo)` (Walter et al. 2007; what Mitsuba 3's
//! `roughconductor` uses, so the two can be compared). Sampled by its visible normals (Heitz
//! 2018), whose density is `G1(wo) D(h) / (4 cos_o)`. The diffuse lobe under it is dimmed by
//! its [`DielectricLayer`].

use glam::{Vec2, Vec3};

use super::compensation::multiple_scattering;
use super::dielectric::DielectricLayer;
use super::microfacet::{ggx_d, reflect_about_visible_normal, schlick, smith_g1};
use super::{Lobe, MIN_ALPHA, luminance};

/// A GGX lobe over a diffuse one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ggx {
    /// Reflectance at normal incidence.
    pub f0: Vec3,
    /// Reflectance at grazing incidence (1 but for a weakened dielectric).
    pub f90: f32,
    /// Width of the distribution (`roughness^2`), at least [`MIN_ALPHA`].
    pub alpha: f32,
    /// The dielectric that dims the diffuse lobe under it.
    pub dielectric: DielectricLayer,
    /// The light lost between the microfacets is put back ([`super::compensation`]).
    pub compensate: bool,
}

impl Lobe for Ggx {
    #[inline]
    fn eval(&self, n: Vec3, wi: Vec3, wo: Vec3, h: Vec3) -> Option<Vec3> {
        let (ci, co) = (n.dot(wi), n.dot(wo));
        if !(ci > 0.0 && co > 0.0 && h != Vec3::ZERO) {
            return None;
        }
        let vh = wo.dot(h).clamp(0.0, 1.0);
        let a = self.alpha.max(MIN_ALPHA);
        let d = ggx_d(n.dot(h), a);
        let g = smith_g1(ci, a) * smith_g1(co, a);
        let single = schlick(self.f0, self.f90, vh) * (d * g / (4.0 * ci * co));
        if !self.compensate {
            return Some(single);
        }
        Some(single + multiple_scattering(self.f0, self.f90, a, ci, co))
    }

    fn pdf(&self, n: Vec3, _wi: Vec3, wo: Vec3, h: Vec3) -> f32 {
        let (nh, vh) = (n.dot(h), wo.dot(h));
        if h == Vec3::ZERO || nh <= 0.0 || vh <= 0.0 {
            return 0.0;
        }
        let a = self.alpha.max(MIN_ALPHA);
        let co = n.dot(wo);
        smith_g1(co, a) * ggx_d(nh, a) / (4.0 * co)
    }

    fn sample(&self, n: Vec3, wo: Vec3, u: Vec2) -> Option<Vec3> {
        reflect_about_visible_normal(n, wo, self.alpha.max(MIN_ALPHA), u)
    }

    fn reflectance(&self, c: f32) -> f32 {
        luminance(schlick(self.f0, self.f90, c))
    }
}
