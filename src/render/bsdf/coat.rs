//! The clear coat (glTF `KHR_materials_clearcoat`): a dielectric GGX layer of its own width,
//! weight `k` and `f0 = 0.04` over the other lobes, mixed as the extension specifies,
//! `f = (1 - k F(v.h)) f_base + k F(v.h) D G / (4 cos_i cos_o)`, about a normal of its own
//! (the surface's without the base's normal map, or the coat's own map's).

use glam::{Vec2, Vec3};

use super::microfacet::{ggx_d, reflect_about_visible_normal, schlick_scalar, smith_g1};
use super::{Lobe, MIN_ALPHA};

/// The clear coat's reflectance at normal incidence (index of refraction 1.5).
const DIELECTRIC_F0: f32 = 0.04;

/// A clear coat over the other lobes: a dielectric GGX layer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Coat {
    /// How much of the surface it covers, in `[0, 1]` (0: no coat).
    pub weight: f32,
    /// Width of its GGX distribution (`roughness^2`), at least [`MIN_ALPHA`].
    pub alpha: f32,
    /// Its unit normal, on the side of the shading normal.
    pub n: Vec3,
}

impl Coat {
    /// No coat.
    pub const NONE: Coat = Coat {
        weight: 0.0,
        alpha: 1.0,
        n: Vec3::Z,
    };

    /// The share of light the coat reflects, seen at cosine `cos = wo.h` to a microfacet
    /// normal `h`: `k F(cos)` (0 without a coat). The lobes under it get `1 - k F(cos)` of
    /// the light; a mirror under the coat reflects about the shading normal, its `h`.
    pub fn reflects(&self, cos: f32) -> f32 {
        if self.weight <= 0.0 {
            return 0.0;
        }
        self.weight * schlick_scalar(DIELECTRIC_F0, cos.clamp(0.0, 1.0))
    }
}

/// The coat's own reflection, about the normal `n` it is given (its own, [`Coat::n`]).
impl Lobe for Coat {
    #[inline]
    fn eval(&self, n: Vec3, wi: Vec3, wo: Vec3, h: Vec3) -> Option<Vec3> {
        let (ci, co) = (n.dot(wi), n.dot(wo));
        if !(ci > 0.0 && co > 0.0 && h != Vec3::ZERO) {
            return None;
        }
        let f = self.reflects(wo.dot(h));
        let a = self.alpha.max(MIN_ALPHA);
        let dg = ggx_d(n.dot(h), a) * smith_g1(ci, a) * smith_g1(co, a);
        Some(Vec3::splat(f * dg / (4.0 * ci * co)))
    }

    fn pdf(&self, n: Vec3, _wi: Vec3, wo: Vec3, h: Vec3) -> f32 {
        let (nh, vh, co) = (n.dot(h), wo.dot(h), n.dot(wo));
        if h == Vec3::ZERO || nh <= 0.0 || vh <= 0.0 || co <= 0.0 {
            return 0.0;
        }
        let a = self.alpha.max(MIN_ALPHA);
        smith_g1(co, a) * ggx_d(nh, a) / (4.0 * co)
    }

    fn sample(&self, n: Vec3, wo: Vec3, u: Vec2) -> Option<Vec3> {
        reflect_about_visible_normal(n, wo, self.alpha.max(MIN_ALPHA), u)
    }

    fn reflectance(&self, c: f32) -> f32 {
        self.reflects(c)
    }
}
