//! What a surface point reflects: a Lambertian lobe and a glossy one, evaluated for a pair of
//! directions, and sampled in proportion to them for the path tracer's bounces.
//!
//! The glossy lobe is one of two models:
//! - **Blinn-Phong** (MTL `Ks`/`Ns`, scene files' `specular`/`shininess`): the normalised
//!   `Ks (Ns + 8) / (8 pi) cos^Ns(theta_h)`, sampled by its half vector, `cos^Ns` about the
//!   normal (density `(Ns + 1) / (2 pi) cos^Ns(theta_h)`, over `4 wo.h` for the reflected
//!   direction).
//! - **GGX** (glTF metallic-roughness materials and scene files' `metallic`/`roughness`), the
//!   BRDF of the glTF 2.0 specification: `F D G / (4 cos_i cos_o)` with the GGX (Trowbridge-
//!   Reitz) distribution of `alpha = roughness^2`, Schlick's Fresnel from the colour at normal
//!   incidence `f0`, and Smith's masking-shadowing in its separable form `G1(wi) G1(wo)`
//!   (Walter et al. 2007; what Mitsuba 3's `roughconductor` uses, so the two can be compared);
//!   the diffuse lobe under it is weighted by `1 - F` of the dielectric's `f0 = 0.04`, as the
//!   specification's `fresnel_mix` does. Sampled by its visible normals (Heitz 2018), whose
//!   density is `G1(wo) D(h) / (4 cos_o)`.
//!
//! A **clear coat** (glTF `KHR_materials_clearcoat`) may lie over either: a dielectric GGX
//! layer of its own width, weight `k` and `f0 = 0.04`, mixed as the extension specifies,
//! `f = (1 - k F(v.h)) f_base + k F(v.h) D G / (4 cos_i cos_o)`, about a normal of its own
//! (the surface's without the base's normal map, or the coat's own map's).
//!
//! A **sheen** (glTF `KHR_materials_sheen`, [`super::sheen`]) may lie between the two: the
//! fibres' own reflection added to the lobes under them, which are dimmed by the sheen's
//! albedo scaling; the coat covers both.
//!
//! A normal or height map's bent normal casts a hard shadow terminator on a smooth mesh: light
//! that the bent normal faces but the surface around it hardly does lights it fully, up to where
//! the light leaves the surface's hemisphere. A [`Bump`] softens it as Mitsuba 3's `normalmap`
//! and `bumpmap` do by default: the whole reflection is scaled by a microfacet shadowing term
//! `G = 2 / (1 + sqrt(1 + a^2 tan^2(theta_i)))`, whose roughness `a^2 = min(tan^2(theta_d) / 8,
//! 1)` grows with the angle `theta_d` the map bends the normal by, and `theta_i` is the light's
//! angle from the normal before the map (Chiang, Li and Burley, "Taming the Shadow
//! Terminator", SIGGRAPH 2019 talk; Mitsuba cites Estevez et al. 2019). Light from under the
//! unbent normal reflects nothing, as in Mitsuba.
//!
//! A bounce picks one lobe with a probability from the lobes' reflectances seen from `wo` and
//! samples it; its density is that of the mixture ([`Bsdf::pdf`]), which is also what
//! multiple importance sampling weighs light samples against. When the glossy lobe's
//! probability is zero, the bounce is exactly the cosine-weighted one of a diffuse surface (the
//! same random numbers give the same direction), so diffuse scenes render as before.

use std::f32::consts::{FRAC_1_PI, PI};

use glam::{Vec2, Vec3};

use super::sheen::Sheen;
use crate::sampling::concentric_disk;

/// The glossy lobe of a surface point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Gloss {
    /// No glossy reflection.
    None,
    /// Normalised Blinn-Phong with colour `color` and exponent `exponent`.
    Phong {
        /// Highlight colour (`Ks`).
        color: Vec3,
        /// Exponent (`Ns`), at least 0.
        exponent: f32,
    },
    /// GGX microfacets with Schlick's Fresnel from `f0` to `f90` and width `alpha`, over a
    /// diffuse lobe dimmed by `1 - weight F(dielectric_f0)`.
    Ggx {
        /// Reflectance at normal incidence.
        f0: Vec3,
        /// Reflectance at grazing incidence (1 but for a weakened dielectric).
        f90: f32,
        /// Width of the distribution (`roughness^2`), at least [`MIN_ALPHA`].
        alpha: f32,
        /// The dielectric's largest reflectance at normal incidence (0.04 by default).
        dielectric_f0: f32,
        /// The dielectric's Fresnel strength (`KHR_materials_specular`; 1 by default).
        weight: f32,
    },
}

pub use crate::scene::pbr::MIN_ALPHA;

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

/// The reflectance of one surface point about its shading normal.
#[derive(Clone, Copy, Debug)]
pub struct Bsdf {
    /// Unit shading normal.
    pub n: Vec3,
    /// Lambertian colour.
    pub diffuse: Vec3,
    /// Glossy lobe.
    pub gloss: Gloss,
    /// Sheen over both, under the coat ([`Sheen::NONE`]: none).
    pub sheen: Sheen,
    /// Clear coat over the rest ([`Coat::NONE`]: none).
    pub coat: Coat,
    /// Shadowing of a normal a map bent ([`Bump::NONE`]: none).
    pub bump: Bump,
}

/// The shadowing a normal or height map's bent normal is given (see the module docs): the
/// normal before the map, and the microfacet roughness the bend stands for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bump {
    /// Unit normal before the map bent it.
    pub n: Vec3,
    /// Squared roughness `min(tan^2(theta_d) / 8, 1)` (0: no shadowing at all).
    pub alpha2: f32,
}

impl Bump {
    /// No shadowing: the surface's normal is its own.
    pub const NONE: Bump = Bump {
        n: Vec3::Z,
        alpha2: 0.0,
    };

    /// The shadowing of `mapped`, the unit normal a map made of `plain` (unit, the same side).
    pub fn new(plain: Vec3, mapped: Vec3) -> Bump {
        let c2 = plain.dot(mapped).powi(2).min(1.0);
        let alpha2 = if c2 > 0.0 {
            (0.125 * (1.0 - c2) / c2).min(1.0)
        } else {
            1.0
        };
        Bump { n: plain, alpha2 }
    }

    /// The share of light from `wi` (unit, away from the surface) the bent normal's surface
    /// is not shadowed from: 1 without a bend, 0 from under the unbent normal.
    #[inline]
    pub fn shadowing(&self, wi: Vec3) -> f32 {
        if self.alpha2 <= 0.0 {
            return 1.0;
        }
        let c = self.n.dot(wi);
        if c <= 0.0 {
            return 0.0;
        }
        let c2 = (c * c).min(1.0);
        let tan2 = (1.0 - c2) / c2;
        2.0 / (1.0 + (1.0 + self.alpha2 * tan2).sqrt())
    }
}

/// A direction a bounce picked, and its density over solid angle.
#[derive(Clone, Copy, Debug)]
pub struct Sample {
    /// Unit direction away from the surface (it may lie under the surface: the caller drops
    /// it then).
    pub wi: Vec3,
    /// Density of the mixture of lobes at `wi` ([`Bsdf::pdf`]).
    pub pdf: f32,
}

impl Bsdf {
    /// True for a Lambertian lobe alone: no glossy lobe, sheen or coat, and no bent normal
    /// to shadow. [`Bsdf::eval`], [`Bsdf::pdf`], [`Bsdf::sample`] and
    /// [`Bsdf::gloss_probability`] then take a short path inlined where they are called, with
    /// the same bits as the general one (which reduces to it term by term).
    #[inline]
    fn is_lambertian(&self) -> bool {
        matches!(self.gloss, Gloss::None)
            && self.coat.weight <= 0.0
            && self.bump.alpha2 <= 0.0
            && !self.sheen.is_some()
    }

    /// The surface's colour for render layers ([`super::aov`]): its diffuse colour plus its
    /// glossy lobe's (Blinn-Phong's highlight colour, GGX's reflectance at normal incidence),
    /// clamped to 1. Not an exact directional albedo: a denoiser wants the texture's detail
    /// and the colour, not the lobes' angular falloff.
    pub fn albedo(&self) -> Vec3 {
        let gloss = match self.gloss {
            Gloss::None => Vec3::ZERO,
            Gloss::Phong { color, .. } => color,
            Gloss::Ggx { f0, .. } => f0,
        };
        (self.diffuse + gloss).clamp(Vec3::ZERO, Vec3::ONE)
    }

    /// Reflected radiance per unit irradiance from `wi` towards `wo` (both unit, away from the
    /// surface).
    #[inline]
    pub fn eval(&self, wi: Vec3, wo: Vec3) -> Vec3 {
        if self.is_lambertian() {
            return self.diffuse * FRAC_1_PI;
        }
        self.eval_layers(wi, wo)
    }

    /// [`Bsdf::eval`] of any lobes.
    #[inline(never)]
    fn eval_layers(&self, wi: Vec3, wo: Vec3) -> Vec3 {
        self.eval_unbent(wi, wo) * self.bump.shadowing(wi)
    }

    /// [`Bsdf::eval`] without the bent normal's shadowing.
    fn eval_unbent(&self, wi: Vec3, wo: Vec3) -> Vec3 {
        let base = self.eval_base(wi, wo);
        if self.coat.weight <= 0.0 {
            return base;
        }
        let n = self.coat.n;
        let (ci, co) = (n.dot(wi), n.dot(wo));
        let h = (wi + wo).normalize_or_zero();
        let f = self.coat.reflects(wo.dot(h));
        let mut out = base * (1.0 - f);
        if ci > 0.0 && co > 0.0 && h != Vec3::ZERO {
            let a = self.coat.alpha.max(MIN_ALPHA);
            let dg = ggx_d(n.dot(h), a) * smith_g1(ci, a) * smith_g1(co, a);
            out += Vec3::splat(f * dg / (4.0 * ci * co));
        }
        out
    }

    /// [`Bsdf::eval`] of the lobes under the coat: the sheen, and the lobes under it dimmed by
    /// its albedo scaling.
    fn eval_base(&self, wi: Vec3, wo: Vec3) -> Vec3 {
        if !self.sheen.is_some() {
            return self.eval_lobes(wi, wo);
        }
        let (ci, co) = (self.n.dot(wi).max(0.0), self.n.dot(wo).max(0.0));
        self.sheen.eval(self.n, wi, wo) + self.eval_lobes(wi, wo) * self.sheen.scaling(ci, co)
    }

    /// [`Bsdf::eval`] of the diffuse and glossy lobes.
    fn eval_lobes(&self, wi: Vec3, wo: Vec3) -> Vec3 {
        let n = self.n;
        match self.gloss {
            Gloss::None => self.diffuse * FRAC_1_PI,
            Gloss::Phong { color, exponent } => {
                let mut f = self.diffuse * FRAC_1_PI;
                if color != Vec3::ZERO {
                    let h = (wi + wo).normalize_or_zero();
                    let c = n.dot(h).max(0.0);
                    let e = exponent.max(0.0);
                    f += color * (e + 8.0) / (8.0 * PI) * c.powf(e);
                }
                f
            }
            Gloss::Ggx {
                f0,
                f90,
                alpha,
                dielectric_f0,
                weight,
            } => {
                let (ci, co) = (n.dot(wi), n.dot(wo));
                let h = (wi + wo).normalize_or_zero();
                let vh = wo.dot(h).clamp(0.0, 1.0);
                let mut f =
                    self.diffuse * FRAC_1_PI * (1.0 - weight * schlick_scalar(dielectric_f0, vh));
                if ci > 0.0 && co > 0.0 && h != Vec3::ZERO {
                    let a = alpha.max(MIN_ALPHA);
                    let d = ggx_d(n.dot(h), a);
                    let g = smith_g1(ci, a) * smith_g1(co, a);
                    f += schlick(f0, f90, vh) * (d * g / (4.0 * ci * co));
                }
                f
            }
        }
    }

    /// Probability that a bounce seen from `wo` samples a glossy lobe, the coat or the glossy
    /// lobe under it (0 without either, or when `wo` lies under the shading normal).
    #[inline]
    pub fn gloss_probability(&self, wo: Vec3) -> f32 {
        if self.is_lambertian() {
            return 0.0;
        }
        self.gloss_probability_layers(wo)
    }

    /// [`Bsdf::gloss_probability`] of any lobes.
    #[inline(never)]
    fn gloss_probability_layers(&self, wo: Vec3) -> f32 {
        let pc = self.coat_probability(wo);
        pc + (1.0 - pc) * self.base_gloss_probability(wo)
    }

    /// Probability that a bounce seen from `wo` samples the coat: its reflectance `k F(n.wo)`
    /// against the others' under it (0 without a coat or below the normal).
    fn coat_probability(&self, wo: Vec3) -> f32 {
        let co = self.coat.n.dot(wo);
        if self.coat.weight <= 0.0 || co <= 0.0 {
            return 0.0;
        }
        let f = self.coat.reflects(co);
        let under = (1.0 - f) * self.base_reflectance(self.n.dot(wo));
        if under > 0.0 && under.is_finite() {
            f / (f + under)
        } else {
            1.0
        }
    }

    /// The luminance of the lobes under the coat seen at cosine `co` (their glossy part by
    /// Fresnel at normal-incidence-free `co`, as [`Bsdf::base_gloss_probability`] weighs it).
    fn base_reflectance(&self, co: f32) -> f32 {
        let (gloss, diffuse) = self.lobe_reflectances(co.clamp(0.0, 1.0));
        gloss + diffuse
    }

    /// The luminances of the glossy and the diffuse lobe seen at cosine `c` in `[0, 1]`: a
    /// GGX lobe's Fresnel there and the diffuse colour under the dielectric's, a Blinn-Phong
    /// lobe's colour and the diffuse colour; under a sheen both dimmed by its scaling, and the
    /// sheen's own reflectance counted with the diffuse lobe's (the cosine-weighted bounces
    /// sample both).
    fn lobe_reflectances(&self, c: f32) -> (f32, f32) {
        let (gloss, diffuse) = match self.gloss {
            Gloss::None => (0.0, luminance(self.diffuse)),
            Gloss::Phong { color, .. } => (luminance(color), luminance(self.diffuse)),
            Gloss::Ggx {
                f0,
                f90,
                dielectric_f0,
                weight,
                ..
            } => (
                luminance(schlick(f0, f90, c)),
                luminance(self.diffuse) * (1.0 - weight * schlick_scalar(dielectric_f0, c)),
            ),
        };
        if !self.sheen.is_some() {
            return (gloss, diffuse);
        }
        let s = self.sheen.scaling(c, c);
        (gloss * s, diffuse * s + self.sheen.reflectance(c))
    }

    /// Probability that a bounce under the coat samples the glossy lobe: its share of the two
    /// lobes' reflectances (0 without a glossy lobe, or when `wo` lies under the shading
    /// normal).
    fn base_gloss_probability(&self, wo: Vec3) -> f32 {
        if matches!(self.gloss, Gloss::None) {
            return 0.0;
        }
        let co = self.n.dot(wo);
        let (gloss, diffuse) = self.lobe_reflectances(co.clamp(0.0, 1.0));
        if co <= 0.0 || gloss <= 0.0 || !gloss.is_finite() {
            0.0
        } else if diffuse <= 0.0 || !diffuse.is_finite() {
            1.0
        } else {
            gloss / (gloss + diffuse)
        }
    }

    /// Density over solid angle with which [`Bsdf::sample`] picks `wi` seen from `wo`.
    #[inline]
    pub fn pdf(&self, wi: Vec3, wo: Vec3) -> f32 {
        if self.is_lambertian() {
            return self.mixture_pdf(0.0, wi, wo);
        }
        self.pdf_layers(wi, wo)
    }

    /// [`Bsdf::pdf`] of any lobes.
    #[inline(never)]
    fn pdf_layers(&self, wi: Vec3, wo: Vec3) -> f32 {
        let pc = self.coat_probability(wo);
        let base = self.mixture_pdf(self.base_gloss_probability(wo), wi, wo);
        if pc == 0.0 {
            return base;
        }
        (1.0 - pc) * base + pc * self.coat_pdf(wi, wo)
    }

    /// The coat's own density at `wi` seen from `wo` (its visible normals).
    fn coat_pdf(&self, wi: Vec3, wo: Vec3) -> f32 {
        let n = self.coat.n;
        let h = (wi + wo).normalize_or_zero();
        let (nh, vh, co) = (n.dot(h), wo.dot(h), n.dot(wo));
        if h == Vec3::ZERO || nh <= 0.0 || vh <= 0.0 || co <= 0.0 {
            return 0.0;
        }
        let a = self.coat.alpha.max(MIN_ALPHA);
        smith_g1(co, a) * ggx_d(nh, a) / (4.0 * co)
    }

    /// [`Bsdf::pdf`] with the glossy lobe's probability `ps` already found.
    #[inline]
    fn mixture_pdf(&self, ps: f32, wi: Vec3, wo: Vec3) -> f32 {
        let cos = self.n.dot(wi);
        let diffuse = if cos > 0.0 { cos * FRAC_1_PI } else { 0.0 };
        if ps == 0.0 {
            return diffuse;
        }
        (1.0 - ps) * diffuse + ps * self.gloss_pdf(wi, wo)
    }

    /// A direction seen from `wo`, from the uniform random numbers `u` (`None` when the glossy
    /// lobe's half vector turns away from `wo`).
    #[inline]
    pub fn sample(&self, wo: Vec3, u: Vec2) -> Option<Sample> {
        if self.is_lambertian() {
            return Some(self.sample_cosine(u));
        }
        self.sample_layers(wo, u)
    }

    /// [`Bsdf::sample`] of any lobes.
    #[inline(never)]
    fn sample_layers(&self, wo: Vec3, u: Vec2) -> Option<Sample> {
        let pc = self.coat_probability(wo);
        if pc > 0.0 {
            // The first number picks the coat or the lobes under it and, stretched back to
            // [0, 1), samples what it picked.
            let wi = if u.x < pc {
                let v = Vec2::new((u.x / pc).min(ONE_MINUS_EPSILON), u.y);
                let a = self.coat.alpha.max(MIN_ALPHA);
                reflect_about_visible_normal(self.coat.n, wo, a, v)?
            } else {
                let v = Vec2::new(((u.x - pc) / (1.0 - pc)).min(ONE_MINUS_EPSILON), u.y);
                self.sample_base(wo, v)?.wi
            };
            return Some(Sample {
                wi,
                pdf: self.pdf(wi, wo),
            });
        }
        self.sample_base(wo, u)
    }

    /// [`Bsdf::sample`] of the lobes under the coat.
    fn sample_base(&self, wo: Vec3, u: Vec2) -> Option<Sample> {
        let ps = self.base_gloss_probability(wo);
        if ps == 0.0 {
            return Some(self.sample_cosine(u));
        }
        // The first number picks the lobe and, stretched back to [0, 1), samples it.
        let wi = if u.x < ps {
            let v = Vec2::new((u.x / ps).min(ONE_MINUS_EPSILON), u.y);
            self.sample_gloss(wo, v)?
        } else {
            let v = Vec2::new(((u.x - ps) / (1.0 - ps)).min(ONE_MINUS_EPSILON), u.y);
            cosine_direction(self.n, v)
        };
        Some(Sample {
            wi,
            pdf: self.mixture_pdf(ps, wi, wo),
        })
    }

    /// A cosine-weighted direction about the normal, with its density.
    #[inline]
    fn sample_cosine(&self, u: Vec2) -> Sample {
        let wi = cosine_direction(self.n, u);
        Sample {
            wi,
            pdf: self.n.dot(wi).max(0.0) * FRAC_1_PI,
        }
    }

    /// The glossy lobe's own density at `wi` seen from `wo` (`wo` above the shading normal).
    fn gloss_pdf(&self, wi: Vec3, wo: Vec3) -> f32 {
        let n = self.n;
        let h = (wi + wo).normalize_or_zero();
        let (nh, vh) = (n.dot(h), wo.dot(h));
        if h == Vec3::ZERO || nh <= 0.0 || vh <= 0.0 {
            return 0.0;
        }
        match self.gloss {
            Gloss::None => 0.0,
            Gloss::Phong { exponent, .. } => {
                let e = exponent.max(0.0);
                (e + 1.0) / (2.0 * PI) * nh.powf(e) / (4.0 * vh)
            }
            Gloss::Ggx { alpha, .. } => {
                let a = alpha.max(MIN_ALPHA);
                let co = n.dot(wo);
                smith_g1(co, a) * ggx_d(nh, a) / (4.0 * co)
            }
        }
    }

    /// A direction from the glossy lobe alone.
    fn sample_gloss(&self, wo: Vec3, u: Vec2) -> Option<Vec3> {
        let n = self.n;
        let (t, b) = n.any_orthonormal_pair();
        let h = match self.gloss {
            Gloss::None => return None,
            Gloss::Phong { exponent, .. } => {
                let cos = u.x.powf(1.0 / (exponent.max(0.0) + 1.0));
                let sin = (1.0 - cos * cos).max(0.0).sqrt();
                let phi = 2.0 * PI * u.y;
                t * (sin * phi.cos()) + b * (sin * phi.sin()) + n * cos
            }
            Gloss::Ggx { alpha, .. } => {
                return reflect_about_visible_normal(n, wo, alpha.max(MIN_ALPHA), u);
            }
        };
        let vh = wo.dot(h);
        if vh <= 0.0 {
            return None;
        }
        Some((2.0 * vh * h - wo).normalize())
    }
}

/// `wo` reflected about a GGX normal of width `a` (about `n`) visible from it ([`visible_normal`]),
/// `None` when the normal turns away from `wo`.
fn reflect_about_visible_normal(n: Vec3, wo: Vec3, a: f32, u: Vec2) -> Option<Vec3> {
    let (t, b) = n.any_orthonormal_pair();
    let local = Vec3::new(wo.dot(t), wo.dot(b), wo.dot(n));
    let m = visible_normal(local, a, u);
    let h = t * m.x + b * m.y + n * m.z;
    let vh = wo.dot(h);
    if vh <= 0.0 {
        return None;
    }
    Some((2.0 * vh * h - wo).normalize())
}

/// Largest `f32` below 1 (a stretched random number stays in `[0, 1)`).
const ONE_MINUS_EPSILON: f32 = 1.0 - f32::EPSILON / 2.0;

/// Cosine-weighted direction about `n` (Malley's method on the concentric disk).
pub fn cosine_direction(n: Vec3, u: Vec2) -> Vec3 {
    let d = concentric_disk(u);
    let z = (1.0 - d.length_squared()).max(0.0).sqrt();
    let (t, b) = n.any_orthonormal_pair();
    // Unit length already: an orthonormal frame and a point of the unit hemisphere.
    t * d.x + b * d.y + n * z
}

/// A GGX normal of width `a` visible from `wo` (in the frame whose `z` is the normal), drawn
/// in proportion to its projected area (Heitz 2018, "Sampling the GGX distribution of visible
/// normals").
fn visible_normal(wo: Vec3, a: f32, u: Vec2) -> Vec3 {
    // Stretch the view so that the distribution becomes the hemisphere of width 1.
    let v = Vec3::new(a * wo.x, a * wo.y, wo.z).normalize();
    let len2 = v.x * v.x + v.y * v.y;
    let t1 = if len2 > 0.0 {
        Vec3::new(-v.y, v.x, 0.0) / len2.sqrt()
    } else {
        Vec3::X
    };
    let t2 = v.cross(t1);
    // A point of the unit disk, squeezed onto the part of the hemisphere `v` sees.
    let r = u.x.sqrt();
    let phi = 2.0 * PI * u.y;
    let p1 = r * phi.cos();
    let s = 0.5 * (1.0 + v.z);
    let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * r * phi.sin();
    let nh = p1 * t1 + p2 * t2 + (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt() * v;
    // Back to the ellipsoid of width `a`.
    Vec3::new(a * nh.x, a * nh.y, nh.z.max(0.0)).normalize()
}

/// GGX distribution of normals of width `a` at `cos_h = n.h`.
fn ggx_d(cos_h: f32, a: f32) -> f32 {
    if cos_h <= 0.0 {
        return 0.0;
    }
    let a2 = a * a;
    let k = cos_h * cos_h * (a2 - 1.0) + 1.0;
    a2 / (PI * k * k)
}

/// Smith's masking of GGX width `a` for a direction at cosine `c` to the normal.
fn smith_g1(c: f32, a: f32) -> f32 {
    if c <= 0.0 {
        return 0.0;
    }
    let a2 = a * a;
    2.0 * c / (c + (a2 + (1.0 - a2) * c * c).sqrt())
}

/// Schlick's Fresnel reflectance from `f0` at cosine `c` between the view and the half vector.
fn schlick(f0: Vec3, f90: f32, c: f32) -> Vec3 {
    let k = (1.0 - c).clamp(0.0, 1.0).powi(5);
    f0 + (Vec3::splat(f90) - f0) * k
}

/// [`schlick`] for one channel.
fn schlick_scalar(f0: f32, c: f32) -> f32 {
    let k = (1.0 - c).clamp(0.0, 1.0).powi(5);
    f0 + (1.0 - f0) * k
}

/// Rec. 709 luminance.
pub(crate) fn luminance(c: Vec3) -> f32 {
    c.dot(Vec3::new(0.2126, 0.7152, 0.0722))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small deterministic generator for the tests (SplitMix64).
    struct Rng(u64);

    impl Rng {
        fn next(&mut self) -> f32 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
        }
        fn next_2d(&mut self) -> Vec2 {
            Vec2::new(self.next(), self.next())
        }
    }

    fn lobes() -> Vec<Bsdf> {
        let n = Vec3::new(0.3, 0.9, -0.2).normalize();
        let red = Vec3::new(0.8, 0.2, 0.1);
        let mut out = vec![Bsdf {
            n,
            diffuse: red,
            gloss: Gloss::None,
            sheen: Sheen::NONE,
            coat: Coat::NONE,
            bump: Bump::NONE,
        }];
        for exponent in [0.0, 10.0, 200.0] {
            out.push(Bsdf {
                n,
                diffuse: red * 0.5,
                gloss: Gloss::Phong {
                    color: Vec3::splat(0.3),
                    exponent,
                },
                sheen: Sheen::NONE,
                coat: Coat::NONE,
                bump: Bump::NONE,
            });
        }
        // The last a weakened, tinted dielectric (`KHR_materials_specular`): Fresnel from 0.06
        // to 0.3 over a diffuse lobe dimmed by `1 - 0.3 F(0.2)`.
        let ggx = [
            (1.0, 0.5, 1.0, 0.04, 1.0),
            (0.3, 0.0, 1.0, 0.04, 1.0),
            (0.05, 0.3, 1.0, 0.04, 1.0),
            (MIN_ALPHA, 0.0, 1.0, 0.04, 1.0),
            (0.4, 0.6, 0.3, 0.2, 0.3),
        ];
        for (alpha, diffuse, f90, dielectric_f0, weight) in ggx {
            out.push(Bsdf {
                n,
                diffuse: red * diffuse,
                gloss: Gloss::Ggx {
                    f0: if weight < 1.0 {
                        Vec3::new(0.2, 0.1, 0.05) * weight
                    } else {
                        Vec3::new(0.9, 0.6, 0.3)
                    },
                    f90,
                    alpha,
                    dielectric_f0,
                    weight,
                },
                sheen: Sheen::NONE,
                coat: Coat::NONE,
                bump: Bump::NONE,
            });
        }
        // Clear coats over a diffuse, a Blinn-Phong and two GGX lobes.
        let coats = [(1.0, 0.3, 0), (0.5, 0.6, 2), (0.8, 0.35, 4), (1.0, 0.5, 5)];
        for (weight, alpha, under) in coats {
            let mut b = out[under];
            b.coat = Coat {
                weight,
                alpha,
                n: b.n,
            };
            out.push(b);
        }
        // Sheens over a diffuse lobe, a GGX one, nothing (a black base) and a coated GGX lobe.
        let sheens = [
            (Vec3::ONE, 0.5, 0),
            (Vec3::new(0.9, 0.5, 0.2), 0.3, 5),
            (Vec3::splat(0.8), 1.0, usize::MAX),
            (Vec3::new(0.3, 0.6, 0.9), 0.7, 12),
        ];
        for (color, roughness, under) in sheens {
            let mut b = match under {
                usize::MAX => Bsdf {
                    diffuse: Vec3::ZERO,
                    ..out[0]
                },
                i => out[i],
            };
            b.sheen = Sheen::new(color, roughness);
            out.push(b);
        }
        out
    }

    fn views(n: Vec3) -> Vec<Vec3> {
        let (t, b) = n.any_orthonormal_pair();
        [0.99f32, 0.7, 0.3, 0.08]
            .iter()
            .map(|&c| (n * c + (t * 0.8 + b * 0.6) * (1.0 - c * c).sqrt()).normalize())
            .collect()
    }

    /// A Lambertian lobe's short path (taken inline at every call) gives the general path's
    /// bits: values, densities, sampled directions and the glossy odds, for directions above
    /// and below the normal, diffuse colours black and white included; and only Lambertian
    /// lobes take it (every other lobe of [`lobes`], a bent normal's shadowing too).
    #[test]
    fn the_lambertian_short_path_gives_the_general_paths_bits() {
        let mut rng = Rng(17);
        let mut lambertian = lobes()[0];
        assert!(lambertian.is_lambertian());
        for other in &lobes()[1..] {
            assert!(!other.is_lambertian(), "{other:?}");
        }
        let bent = Bsdf {
            bump: Bump::new(lambertian.n, Vec3::new(0.5, 0.8, 0.1).normalize()),
            ..lambertian
        };
        assert!(!bent.is_lambertian());
        let bits = |v: Vec3| v.to_array().map(f32::to_bits);
        for diffuse in [Vec3::ZERO, Vec3::new(0.8, 0.2, 0.1), Vec3::ONE] {
            lambertian.diffuse = diffuse;
            let b = lambertian;
            for _ in 0..2000 {
                let dir = |u: Vec2| {
                    let z = 1.0 - 2.0 * u.x;
                    let r = (1.0 - z * z).max(0.0).sqrt();
                    let phi = 2.0 * PI * u.y;
                    Vec3::new(r * phi.cos(), r * phi.sin(), z)
                };
                let (wi, wo) = (dir(rng.next_2d()), dir(rng.next_2d()));
                let u = rng.next_2d();
                assert_eq!(bits(b.eval(wi, wo)), bits(b.eval_layers(wi, wo)));
                assert_eq!(b.pdf(wi, wo).to_bits(), b.pdf_layers(wi, wo).to_bits());
                assert_eq!(
                    b.gloss_probability(wo).to_bits(),
                    b.gloss_probability_layers(wo).to_bits()
                );
                let (short, general) = (b.sample(wo, u), b.sample_layers(wo, u));
                let (short, general) = (short.expect("a cosine sample"), general.expect("one"));
                assert_eq!(bits(short.wi), bits(general.wi));
                assert_eq!(short.pdf.to_bits(), general.pdf.to_bits());
            }
        }
    }

    /// The bent normal's shadowing: 1 without a bend and along the unbent normal, falling
    /// towards the horizon (faster the more the map bends), 0 under it, the formula's values
    /// at known angles, and its roughness capped at 1 (a bend past `atan(sqrt(8))`).
    #[test]
    fn bump_shadowing_follows_the_formula() {
        let n = Vec3::new(0.3, 0.5, 0.8).normalize();
        let (t, b) = n.any_orthonormal_pair();
        let tilt = |deg: f32| {
            let a = deg.to_radians();
            (n * a.cos() + t * a.sin()).normalize()
        };
        assert_eq!(Bump::NONE.shadowing(-n), 1.0);
        let bent45 = Bump::new(n, tilt(45.0));
        assert!((bent45.alpha2 - 0.125).abs() < 1e-5, "{}", bent45.alpha2);
        assert!((bent45.shadowing(n) - 1.0).abs() < 1e-6);
        // Light 60 degrees from the unbent normal (tan^2 = 3), on the side away from the bend.
        let light = (n * 0.5 + b * 0.75f32.sqrt()).normalize();
        let expected = 2.0 / (1.0 + (1.0 + 0.125f32 * 3.0).sqrt());
        assert!((bent45.shadowing(light) - expected).abs() < 1e-5);
        assert_eq!(bent45.shadowing(-light), 0.0);
        let bent20 = Bump::new(n, tilt(20.0));
        let mut last = (1.0, 1.0);
        for deg in [10.0f32, 30.0, 50.0, 70.0, 85.0, 89.5] {
            let a = deg.to_radians();
            let wi = n * a.cos() + b * a.sin();
            let g = (bent20.shadowing(wi), bent45.shadowing(wi));
            assert!(g.0 < last.0 && g.1 < last.1 && g.1 < g.0, "{deg}: {g:?}");
            last = g;
        }
        assert!(last.1 < 0.25, "{last:?}");
        assert_eq!(Bump::new(n, tilt(75.0)).alpha2, 1.0);
        // The whole reflection is scaled, so a bounce's weight carries it too.
        let bsdf = Bsdf {
            n,
            bump: bent45,
            ..lobes()[1]
        };
        let unbent = Bsdf {
            bump: Bump::NONE,
            ..bsdf
        };
        let wo = (n + t * 0.2).normalize();
        let ratio = bsdf.eval(light, wo) / unbent.eval(light, wo);
        assert!((ratio - Vec3::splat(expected)).abs().max_element() < 1e-5);
    }

    /// Every sampled direction's density is what `pdf` says for it, and the glossy lobe's
    /// density integrates to at most 1 over the sphere (exactly 1 less what falls under the
    /// surface: checked by the share of samples that come back).
    #[test]
    fn sampled_densities_match_pdf() {
        let mut rng = Rng(7);
        for bsdf in lobes() {
            for wo in views(bsdf.n) {
                for _ in 0..2000 {
                    let Some(s) = bsdf.sample(wo, rng.next_2d()) else {
                        continue;
                    };
                    assert!((s.wi.length() - 1.0).abs() < 1e-4);
                    let p = bsdf.pdf(s.wi, wo);
                    assert!(
                        (s.pdf - p).abs() <= 1e-4 * p.max(1.0),
                        "{bsdf:?} {wo}: {} against {p}",
                        s.pdf
                    );
                    if bsdf.n.dot(s.wi) > 0.0 {
                        assert!(s.pdf > 0.0, "{bsdf:?}: a direction sampled at density 0");
                    }
                }
            }
        }
    }

    /// The density integrates to the share of samples above the surface: a Monte Carlo
    /// integral of `pdf` over the hemisphere (uniform directions) against the fraction of
    /// sampled directions that land there.
    #[test]
    fn pdf_integrates_to_the_sampled_share() {
        let mut rng = Rng(11);
        for bsdf in lobes() {
            let n = bsdf.n;
            for wo in views(n) {
                let count = 400_000;
                let mut integral = 0.0f64;
                for _ in 0..count {
                    let wi = uniform_direction(n, rng.next_2d());
                    integral += (bsdf.pdf(wi, wo) * 2.0 * PI) as f64;
                }
                integral /= count as f64;
                let draws = 40_000;
                let above = (0..draws)
                    .filter(|_| {
                        bsdf.sample(wo, rng.next_2d())
                            .is_some_and(|s| n.dot(s.wi) > 0.0)
                    })
                    .count() as f64
                    / draws as f64;
                // Narrow lobes make the uniform estimate noisy: the tolerance grows with the
                // peak of the density.
                let tol = match bsdf.gloss {
                    Gloss::Ggx { alpha, .. } if alpha < 0.1 => 0.25,
                    Gloss::Phong { exponent, .. } if exponent > 100.0 => 0.08,
                    _ => 0.02,
                };
                assert!(
                    (integral - above).abs() < tol,
                    "{bsdf:?} {wo}: integral {integral}, sampled share {above}"
                );
            }
        }
    }

    /// The estimate of the reflected fraction of uniform light, `f cos / pdf` over sampled
    /// directions, agrees with the same integral over uniform directions (so the sampling
    /// weights are right), and a white GGX metal reflects at most all of it.
    #[test]
    fn importance_sampling_is_unbiased() {
        let mut rng = Rng(5);
        for bsdf in lobes() {
            let n = bsdf.n;
            for wo in views(n) {
                let count = 300_000;
                let mut sampled = Vec3::ZERO;
                for _ in 0..count {
                    if let Some(s) = bsdf.sample(wo, rng.next_2d()) {
                        let c = n.dot(s.wi);
                        if c > 0.0 && s.pdf > 0.0 {
                            sampled += bsdf.eval(s.wi, wo) * c / s.pdf;
                        }
                    }
                }
                sampled /= count as f32;
                // A coat's lobes are wide (width 0.3 and up): uniform directions see them.
                let reference = match bsdf.gloss {
                    _ if bsdf.coat.weight > 0.0 || bsdf.sheen.is_some() => {
                        uniform_estimate(&bsdf, wo, &mut rng)
                    }
                    Gloss::Ggx { alpha, .. } => half_vector_estimate(&bsdf, alpha, wo, &mut rng),
                    _ => uniform_estimate(&bsdf, wo, &mut rng),
                };
                let tol = match bsdf.gloss {
                    _ if bsdf.coat.weight > 0.0 || bsdf.sheen.is_some() => 0.02,
                    Gloss::Phong { exponent, .. } if exponent > 100.0 => 0.1,
                    _ => 0.01,
                };
                assert!(
                    (sampled - reference).abs().max_element() < tol,
                    "{bsdf:?} {wo}: sampled {sampled}, reference {reference}"
                );
            }
        }
        let white = Bsdf {
            n: Vec3::Z,
            diffuse: Vec3::ZERO,
            gloss: Gloss::Ggx {
                f0: Vec3::ONE,
                f90: 1.0,
                alpha: 0.5,
                dielectric_f0: 0.04,
                weight: 1.0,
            },
            sheen: Sheen::NONE,
            coat: Coat::NONE,
            bump: Bump::NONE,
        };
        let mut rng = Rng(3);
        for wo in views(Vec3::Z) {
            let mut sum = Vec3::ZERO;
            for _ in 0..100_000 {
                if let Some(s) = white.sample(wo, rng.next_2d())
                    && s.wi.z > 0.0
                {
                    sum += white.eval(s.wi, wo) * s.wi.z / s.pdf;
                }
            }
            let albedo = sum.x / 100_000.0;
            // Single scattering loses energy: about 31% at this width (0.687 reflected seen
            // from the normal, 0.678 at cosine 0.7, 0.714 at 0.3, by quadrature).
            assert!(
                albedo <= 1.0 && albedo > 0.6,
                "white metal at {wo}: albedo {albedo}"
            );
        }
    }

    /// A white sheen over a white diffuse lobe reflects at most the light that arrives (the
    /// lobe under it dimmed by the sheen's albedo), and more than the sheen alone.
    #[test]
    fn a_sheen_over_white_keeps_to_the_light_it_gets() {
        let mut rng = Rng(13);
        for roughness in [0.3, 0.6, 1.0] {
            let white = Bsdf {
                n: Vec3::Z,
                diffuse: Vec3::ONE,
                gloss: Gloss::None,
                sheen: Sheen::new(Vec3::ONE, roughness),
                coat: Coat::NONE,
                bump: Bump::NONE,
            };
            for wo in views(Vec3::Z) {
                let albedo = uniform_estimate(&white, wo, &mut rng).x;
                let sheen = super::super::sheen::albedo(wo.z, roughness);
                assert!(
                    albedo <= 1.01 && albedo > sheen + 0.3,
                    "roughness {roughness}, {wo}: albedo {albedo} (the sheen's own {sheen})"
                );
            }
        }
    }

    /// `f cos` integrated over the hemisphere with uniform directions.
    fn uniform_estimate(bsdf: &Bsdf, wo: Vec3, rng: &mut Rng) -> Vec3 {
        let count = 300_000;
        let mut sum = Vec3::ZERO;
        for _ in 0..count {
            let wi = uniform_direction(bsdf.n, rng.next_2d());
            sum += bsdf.eval(wi, wo) * bsdf.n.dot(wi) * 2.0 * PI;
        }
        sum / count as f32
    }

    /// A direction of the hemisphere about `n`, uniform over solid angle (density
    /// `1 / (2 pi)`).
    fn uniform_direction(n: Vec3, u: Vec2) -> Vec3 {
        let (t, b) = n.any_orthonormal_pair();
        let z = u.x;
        let r = (1.0 - z * z).max(0.0).sqrt();
        let phi = 2.0 * PI * u.y;
        t * (r * phi.cos()) + b * (r * phi.sin()) + n * z
    }

    /// `f cos` integrated over the hemisphere with GGX half vectors drawn in proportion to
    /// `D(h) cos(theta_h)` (Walter et al. 2007; not the visible normals `sample` draws) plus
    /// cosine-weighted directions for the diffuse lobe, one estimator each.
    fn half_vector_estimate(bsdf: &Bsdf, alpha: f32, wo: Vec3, rng: &mut Rng) -> Vec3 {
        let n = bsdf.n;
        let (t, b) = n.any_orthonormal_pair();
        let a = alpha.max(MIN_ALPHA);
        let gloss_only = Bsdf {
            diffuse: Vec3::ZERO,
            ..*bsdf
        };
        let count = 300_000;
        let mut sum = Vec3::ZERO;
        for _ in 0..count {
            let u = rng.next_2d();
            let tan2 = a * a * u.x / (1.0 - u.x);
            let cos_h = 1.0 / (1.0 + tan2).sqrt();
            let sin_h = (1.0 - cos_h * cos_h).max(0.0).sqrt();
            let phi = 2.0 * PI * u.y;
            let h = t * (sin_h * phi.cos()) + b * (sin_h * phi.sin()) + n * cos_h;
            let vh = wo.dot(h);
            if vh <= 0.0 {
                continue;
            }
            let wi = 2.0 * vh * h - wo;
            let ci = n.dot(wi);
            if ci <= 0.0 {
                continue;
            }
            let pdf = ggx_d(cos_h, a) * cos_h / (4.0 * vh);
            sum += gloss_only.eval(wi, wo) * ci / pdf;
        }
        let mut diffuse = Vec3::ZERO;
        for _ in 0..count {
            let wi = cosine_direction(n, rng.next_2d());
            let ci = n.dot(wi);
            if ci > 0.0 {
                diffuse += (bsdf.eval(wi, wo) - gloss_only.eval(wi, wo)) * PI;
            }
        }
        (sum + diffuse) / count as f32
    }

    /// Without a glossy lobe a bounce is the cosine-weighted one, number for number.
    #[test]
    fn diffuse_bounces_are_cosine_weighted() {
        let bsdf = lobes()[0];
        let wo = views(bsdf.n)[1];
        let mut rng = Rng(1);
        for _ in 0..100 {
            let u = rng.next_2d();
            let s = bsdf.sample(wo, u).unwrap();
            assert_eq!(s.wi, cosine_direction(bsdf.n, u));
            assert_eq!(s.pdf, bsdf.n.dot(s.wi) * FRAC_1_PI);
        }
    }

    /// GGX and Smith against values worked out by hand.
    #[test]
    fn ggx_terms() {
        // Width 1: D = 1 / pi everywhere.
        assert!((ggx_d(0.3, 1.0) - FRAC_1_PI).abs() < 1e-6);
        // At the normal: D = 1 / (pi a^2).
        assert!((ggx_d(1.0, 0.5) - 1.0 / (PI * 0.25)).abs() < 1e-5);
        assert_eq!(ggx_d(-0.1, 0.5), 0.0);
        // Looking along the normal nothing is masked; at grazing everything is.
        assert!((smith_g1(1.0, 0.5) - 1.0).abs() < 1e-6);
        assert_eq!(smith_g1(0.0, 0.5), 0.0);
        // c = 0.5, a = 0.5: 2 c / (c + sqrt(a^2 + (1 - a^2) c^2)) = 1 / (0.5 + sqrt(0.4375)).
        assert!((smith_g1(0.5, 0.5) - 1.0 / (0.5 + 0.4375f32.sqrt())).abs() < 1e-6);
        assert_eq!(schlick(Vec3::splat(0.04), 1.0, 1.0), Vec3::splat(0.04));
        assert_eq!(schlick(Vec3::splat(0.04), 1.0, 0.0), Vec3::ONE);
        // A weakened dielectric reaches its own `f90` at grazing.
        assert_eq!(schlick(Vec3::splat(0.02), 0.5, 0.0), Vec3::splat(0.5));
    }
}
