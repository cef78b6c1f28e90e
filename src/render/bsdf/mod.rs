//! What a surface point reflects ([`Bsdf`]): its lobes, one file each behind one interface
//! ([`Lobe`]: evaluate, density, sample, reflectance), and their layering, which is all here.
//!
//! The lobes:
//! - [`Lambert`] (`lambert.rs`): the diffuse colour, under everything else;
//! - a glossy lobe ([`Gloss`]) over it, one of [`Phong`] (`phong.rs`: normalised Blinn-Phong,
//!   MTL and scene files' `specular`/`shininess`) or [`Ggx`] (`ggx.rs`: the glTF 2.0
//!   metallic-roughness conductor BRDF), the latter dimming the diffuse lobe by its
//!   [`DielectricLayer`] (`dielectric.rs`, the specification's `fresnel_mix`);
//! - a [`Sheen`] (`sheen.rs`, glTF `KHR_materials_sheen`) over both: the fibres' own reflection
//!   added to the lobes under them, which are dimmed by the sheen's albedo scaling;
//! - a [`Coat`] (`coat.rs`, glTF `KHR_materials_clearcoat`) over the rest, about a normal of
//!   its own: `f = (1 - k F(v.h)) f_base + k F(v.h) D G / (4 cos_i cos_o)`.
//!
//! The GGX distribution, Smith's masking, Schlick's Fresnel and visible-normal sampling that the
//! GGX lobe and the coat share are in `microfacet.rs`.
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
//! A bounce picks one lobe with a probability from the lobes' reflectances seen from `wo` (the
//! coat against the rest, then the glossy lobe against the diffuse one and the sheen) and
//! samples it; its density is that of the mixture ([`Bsdf::pdf`]), which is also what multiple
//! importance sampling weighs light samples against. When the glossy lobe's probability is
//! zero, the bounce is exactly the cosine-weighted one of a diffuse surface (the same random
//! numbers give the same direction), so diffuse scenes render as before.
//!
//! A new lobe is a file with a type that implements [`Lobe`], a [`Gloss`] variant (or a layer
//! field on [`Bsdf`]) and its arms in the layering below.

mod bump;
mod coat;
pub mod compensation;
mod dielectric;
mod ggx;
pub mod ggx_albedo;
mod lambert;
mod microfacet;
mod phong;
pub mod sheen;
pub mod sheen_albedo;
#[cfg(test)]
mod tests;

use std::f32::consts::FRAC_1_PI;

use glam::{Vec2, Vec3};

pub use bump::Bump;
pub use coat::Coat;
pub use dielectric::DielectricLayer;
pub use ggx::Ggx;
pub use lambert::Lambert;
pub use phong::Phong;
pub use sheen::Sheen;

pub use crate::scene::pbr::MIN_ALPHA;

/// One lobe of a surface's reflectance, about a unit normal `n`, for unit directions `wi`
/// (towards the light) and `wo` (towards the viewer), both away from the surface, and their
/// half vector `h = normalize(wi + wo)` (zero when they are opposite). [`Bsdf`] layers the
/// lobes; each lobe's file says its model.
pub trait Lobe {
    /// The lobe's reflected radiance per unit irradiance from `wi` towards `wo` (no cosine),
    /// `None` where it reflects nothing (so that a sum of lobes keeps its bits).
    fn eval(&self, n: Vec3, wi: Vec3, wo: Vec3, h: Vec3) -> Option<Vec3>;

    /// The density over solid angle with which [`Lobe::sample`] picks `wi` seen from `wo`.
    fn pdf(&self, n: Vec3, wi: Vec3, wo: Vec3, h: Vec3) -> f32;

    /// A direction seen from `wo`, from the uniform random numbers `u` (`None` when the lobe
    /// turns the sample away from `wo`).
    fn sample(&self, n: Vec3, wo: Vec3, u: Vec2) -> Option<Vec3>;

    /// The luminance of the light the lobe reflects, seen at cosine `c` in `[0, 1]`: what a
    /// bounce's choice between lobes weighs it by.
    fn reflectance(&self, c: f32) -> f32;

    /// [`Lobe::eval`] of many lobes, one a hit: `out[k]` for `lobes[k]` about `n[k]` at
    /// `wi[k]`, `wo[k]` (zero where it reflects nothing). The form in which a batch of paths
    /// evaluates one kind of lobe.
    fn eval_each(lobes: &[Self], n: &[Vec3], wi: &[Vec3], wo: &[Vec3], out: &mut [Vec3])
    where
        Self: Sized,
    {
        for (k, o) in out.iter_mut().enumerate() {
            let h = (wi[k] + wo[k]).normalize_or_zero();
            *o = lobes[k].eval(n[k], wi[k], wo[k], h).unwrap_or(Vec3::ZERO);
        }
    }
}

/// The glossy lobe of a surface point, over its Lambertian one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Gloss {
    /// No glossy reflection.
    None,
    /// Normalised Blinn-Phong.
    Phong(Phong),
    /// GGX microfacets over a diffuse lobe dimmed by the dielectric's Fresnel.
    Ggx(Ggx),
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
            Gloss::Phong(p) => p.color,
            Gloss::Ggx(g) => g.f0,
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
        let h = (wi + wo).normalize_or_zero();
        let f = self.coat.reflects(wo.dot(h));
        let mut out = base * (1.0 - f);
        if let Some(coat) = self.coat.eval(self.coat.n, wi, wo, h) {
            out += coat;
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
        let h = (wi + wo).normalize_or_zero();
        let diffuse = self.diffuse * FRAC_1_PI;
        match self.gloss {
            Gloss::None => diffuse,
            Gloss::Phong(p) => {
                let mut f = diffuse;
                if let Some(gloss) = p.eval(n, wi, wo, h) {
                    f += gloss;
                }
                f
            }
            Gloss::Ggx(g) => {
                let vh = wo.dot(h).clamp(0.0, 1.0);
                let mut f = diffuse * g.dielectric.transmitted(vh);
                if let Some(gloss) = g.eval(n, wi, wo, h) {
                    f += gloss;
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
        let diffuse = Lambert(self.diffuse).reflectance(c);
        let (gloss, diffuse) = match self.gloss {
            Gloss::None => (0.0, diffuse),
            Gloss::Phong(p) => (p.reflectance(c), diffuse),
            Gloss::Ggx(g) => (g.reflectance(c), diffuse * g.dielectric.transmitted(c)),
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
        let h = (wi + wo).normalize_or_zero();
        self.coat.pdf(self.coat.n, wi, wo, h)
    }

    /// [`Bsdf::pdf`] with the glossy lobe's probability `ps` already found.
    #[inline]
    fn mixture_pdf(&self, ps: f32, wi: Vec3, wo: Vec3) -> f32 {
        let diffuse = Lambert(self.diffuse).pdf(self.n, wi, wo, Vec3::ZERO);
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
                self.coat.sample(self.coat.n, wo, v)?
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
            Lambert(self.diffuse).sample(self.n, wo, v)?
        };
        Some(Sample {
            wi,
            pdf: self.mixture_pdf(ps, wi, wo),
        })
    }

    /// A cosine-weighted direction about the normal, with its density.
    #[inline]
    fn sample_cosine(&self, u: Vec2) -> Sample {
        let wi = crate::sampling::cosine_direction(self.n, u);
        Sample {
            wi,
            pdf: self.n.dot(wi).max(0.0) * FRAC_1_PI,
        }
    }

    /// The glossy lobe's own density at `wi` seen from `wo` (`wo` above the shading normal).
    fn gloss_pdf(&self, wi: Vec3, wo: Vec3) -> f32 {
        let h = (wi + wo).normalize_or_zero();
        match self.gloss {
            Gloss::None => 0.0,
            Gloss::Phong(p) => p.pdf(self.n, wi, wo, h),
            Gloss::Ggx(g) => g.pdf(self.n, wi, wo, h),
        }
    }

    /// A direction from the glossy lobe alone.
    fn sample_gloss(&self, wo: Vec3, u: Vec2) -> Option<Vec3> {
        match self.gloss {
            Gloss::None => None,
            Gloss::Phong(p) => p.sample(self.n, wo, u),
            Gloss::Ggx(g) => g.sample(self.n, wo, u),
        }
    }
}

impl Bsdf {
    /// The light a uniform white environment gives, reflected towards `wo` (the directional
    /// albedo: the white furnace), estimated from `n x n` stratified samples of
    /// [`Bsdf::sample`], each weighted by `f cos / pdf`.
    pub fn reflectance_from(&self, wo: Vec3, n: usize) -> Vec3 {
        let mut sum = glam::DVec3::ZERO;
        for y in 0..n {
            for x in 0..n {
                let u = Vec2::new((x as f32 + 0.5) / n as f32, (y as f32 + 0.5) / n as f32);
                if let Some(s) = self.sample(wo, u) {
                    let cos = self.n.dot(s.wi);
                    if cos > 0.0 && s.pdf > 0.0 {
                        sum += (self.eval(s.wi, wo) * cos / s.pdf).as_dvec3();
                    }
                }
            }
        }
        (sum / (n * n) as f64).as_vec3()
    }
}

/// Largest `f32` below 1 (a stretched random number stays in `[0, 1)`).
const ONE_MINUS_EPSILON: f32 = 1.0 - f32::EPSILON / 2.0;

/// Rec. 709 luminance.
pub(crate) fn luminance(c: Vec3) -> f32 {
    c.dot(Vec3::new(0.2126, 0.7152, 0.0722))
}
