//! The sheen of cloth and velvet (glTF `KHR_materials_sheen`): a layer of fibres over the
//! other lobes that reflects light back at grazing angles.
//!
//! Its BRDF is the extension's: `sheenColor D(h) V(wi, wo)`, with the "Charlie" distribution
//! of Estevez and Kulla 2017, `D = (2 + 1 / alpha) sin(theta_h)^(1 / alpha) / (2 pi)` of
//! `alpha = sheenRoughness^2`, and their visibility, `V = min(1 / ((1 + L(wo) + L(wi)) 4
//! cos_i cos_o), 1)` with `L` their fitted `lambda` (no Fresnel; the bound is the Khronos
//! sample viewer's). The lobes under it are dimmed by the
//! extension's albedo scaling, `min(1 - max(sheenColor) E(cos_o), 1 - max(sheenColor)
//! E(cos_i))`, where `E` is the sheen's own directional albedo: integrated once, numerically,
//! into the table of [`super::sheen_albedo`] (`examples/sheen_albedo.rs` writes it; a test here
//! integrates entries again), and read between its entries.
//!
//! The path tracer samples it with the diffuse lobe's cosine-weighted directions: the broad lobe
//! of a cloth is covered by them, and a bounce's choice of lobe weighs it with the diffuse one
//! ([`super::Bsdf`]).

use std::f32::consts::PI;

use glam::Vec3;

use super::sheen_albedo::{ALBEDO, COSINES, ROUGHNESSES};

/// Smallest sheen roughness drawn (`alpha = 1e-4`): a smoother sheen reflects nothing but at
/// the horizon, which this one already all but does.
pub const MIN_ROUGHNESS: f32 = 0.01;

/// Smallest cosine the albedo table holds and the BRDF is evaluated at (a direction closer to
/// the horizon is read as this one).
pub const MIN_COSINE: f32 = 1e-3;

/// A sheen layer at one surface point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sheen {
    /// `sheenColor`, linear RGB, at least 0 (zero: no sheen).
    pub color: Vec3,
    /// `sheenRoughness`, in `[MIN_ROUGHNESS, 1]`.
    pub roughness: f32,
}

impl Sheen {
    /// No sheen.
    pub const NONE: Sheen = Sheen {
        color: Vec3::ZERO,
        roughness: 1.0,
    };

    /// A sheen of colour `color` and roughness `roughness` (clamped to `[MIN_ROUGHNESS, 1]`;
    /// a negative or NaN colour channel is 0).
    pub fn new(color: Vec3, roughness: f32) -> Sheen {
        Sheen {
            color: color.max(Vec3::ZERO),
            roughness: if roughness.is_nan() {
                MIN_ROUGHNESS
            } else {
                roughness.clamp(MIN_ROUGHNESS, 1.0)
            },
        }
    }

    /// True when the layer reflects anything.
    pub fn is_some(&self) -> bool {
        self.color.max_element() > 0.0
    }

    /// The sheen's BRDF from `wi` towards `wo` about the unit normal `n` (zero unless both lie
    /// above it).
    pub fn eval(&self, n: Vec3, wi: Vec3, wo: Vec3) -> Vec3 {
        if !self.is_some() {
            return Vec3::ZERO;
        }
        let (ci, co) = (n.dot(wi), n.dot(wo));
        let h = (wi + wo).normalize_or_zero();
        if ci <= 0.0 || co <= 0.0 || h == Vec3::ZERO {
            return Vec3::ZERO;
        }
        self.color * brdf(self.roughness, n.dot(h), ci, co)
    }

    /// The share of light the lobes under the sheen get, seen at cosines `ci` and `co`:
    /// `min(1 - max(color) E(co), 1 - max(color) E(ci))`, within `[0, 1]` (1 without a
    /// sheen).
    pub fn scaling(&self, ci: f32, co: f32) -> f32 {
        if !self.is_some() {
            return 1.0;
        }
        let m = self.color.max_element();
        let e = albedo(ci, self.roughness).max(albedo(co, self.roughness));
        (1.0 - m * e).clamp(0.0, 1.0)
    }

    /// The luminance the sheen reflects of light from everywhere above, seen at cosine `co`:
    /// its colour's luminance times `E(co)`, what a bounce's choice of lobe weighs it by.
    pub fn reflectance(&self, co: f32) -> f32 {
        if !self.is_some() {
            return 0.0;
        }
        super::luminance(self.color) * albedo(co, self.roughness)
    }
}

/// The Charlie sheen BRDF of colour 1 and roughness `roughness`, at cosines `nh` (normal to
/// half vector), `ci` and `co` (both positive).
pub fn brdf(roughness: f32, nh: f32, ci: f32, co: f32) -> f32 {
    let alpha = roughness.clamp(MIN_ROUGHNESS, 1.0).powi(2);
    let (ci, co) = (ci.max(MIN_COSINE), co.max(MIN_COSINE));
    let sin2 = (1.0 - nh * nh).max(0.0);
    let inv = 1.0 / alpha;
    let d = (2.0 + inv) * sin2.powf(0.5 * inv) / (2.0 * PI);
    // The visibility at most 1, as the Khronos sample viewer bounds it (without the bound
    // a smooth sheen seen near the horizon reflects several times the light it gets).
    let v = (1.0 / ((1.0 + lambda(co, alpha) + lambda(ci, alpha)) * (4.0 * ci * co))).min(1.0);
    d * v
}

/// Estevez and Kulla's fitted `lambda` of the Charlie distribution of width `alpha` at cosine
/// `cos` in `(0, 1]`.
fn lambda(cos: f32, alpha: f32) -> f32 {
    if cos < 0.5 {
        fit(cos, alpha).exp()
    } else {
        (2.0 * fit(0.5, alpha) - fit(1.0 - cos, alpha)).exp()
    }
}

/// The curve `a / (1 + b x^c) + d x + e` of Estevez and Kulla's fit, its five coefficients
/// interpolated between their values at `alpha = 0` and `alpha = 1` by `(1 - alpha)^2`.
fn fit(x: f32, alpha: f32) -> f32 {
    let t = (1.0 - alpha) * (1.0 - alpha);
    let mix = |at_one: f32, at_zero: f32| at_one + (at_zero - at_one) * t;
    let a = mix(21.5473, 25.3245);
    let b = mix(3.82987, 3.32435);
    let c = mix(0.19823, 0.16801);
    let d = mix(-1.97760, -1.27393);
    let e = mix(-4.32054, -4.85967);
    a / (1.0 + b * x.powf(c)) + d * x + e
}

/// The cosine the table's column `j` holds.
pub fn table_cosine(j: usize) -> f32 {
    (j as f32 / (COSINES - 1) as f32).max(MIN_COSINE)
}

/// The roughness the table's row `i` holds.
pub fn table_roughness(i: usize) -> f32 {
    (i as f32 / (ROUGHNESSES - 1) as f32).max(MIN_ROUGHNESS)
}

/// The sheen's directional albedo (colour 1) seen at cosine `cos`, for roughness `roughness`:
/// the table read between its entries (bilinearly).
pub fn albedo(cos: f32, roughness: f32) -> f32 {
    let at = |x: f32, n: usize| {
        let x = if x.is_nan() { 0.0 } else { x.clamp(0.0, 1.0) } * (n - 1) as f32;
        let i = (x as usize).min(n - 2);
        (i, x - i as f32)
    };
    let (i, fr) = at(roughness, ROUGHNESSES);
    let (j, fc) = at(cos, COSINES);
    let row = |i: usize| ALBEDO[i][j] * (1.0 - fc) + ALBEDO[i][j + 1] * fc;
    row(i) * (1.0 - fr) + row(i + 1) * fr
}

/// The sheen's directional albedo (colour 1) at cosine `co` and roughness `roughness`,
/// integrated over the hemisphere of incoming directions by the midpoint rule on `rings`
/// cosines by `2 sectors` angles about the normal (f64 sums; the BRDF in f32, as rendering
/// evaluates it). What `examples/sheen_albedo.rs` tabulates.
pub fn integrate_albedo(co: f32, roughness: f32, rings: usize, sectors: usize) -> f64 {
    let co = co.clamp(MIN_COSINE, 1.0);
    let wo = Vec3::new((1.0 - co * co).max(0.0).sqrt(), 0.0, co);
    let mut sum = 0.0f64;
    // Incoming directions by their cosine (uniform in it: solid angle d(cos) d(phi)) and their
    // angle about the normal over half the circle (the integrand is even in it).
    for r in 0..rings {
        let ci = (r as f64 + 0.5) / rings as f64;
        let si = (1.0 - ci * ci).max(0.0).sqrt();
        for s in 0..sectors {
            let phi = std::f64::consts::PI * (s as f64 + 0.5) / sectors as f64;
            let wi = Vec3::new((si * phi.cos()) as f32, (si * phi.sin()) as f32, ci as f32);
            let h = (wi + wo).normalize();
            sum += brdf(roughness, h.z, wi.z, co) as f64 * ci;
        }
    }
    // Each cell spans 1 / rings of cosine and pi / sectors of angle, twice (both halves).
    sum * 2.0 * std::f64::consts::PI / (rings * sectors) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The quadrature `examples/sheen_albedo.rs` wrote the table with.
    const RINGS: usize = 512;
    const SECTORS: usize = 256;

    #[test]
    fn the_table_is_what_the_integral_gives() {
        // Every fifth entry (rows and columns), and the corners.
        for i in (0..ROUGHNESSES).step_by(5).chain([ROUGHNESSES - 1]) {
            for j in (0..COSINES).step_by(5).chain([COSINES - 1]) {
                let (r, c) = (table_roughness(i), table_cosine(j));
                let e = integrate_albedo(c, r, RINGS, SECTORS) as f32;
                assert!(
                    (ALBEDO[i][j] - e).abs() <= 1e-5 * e.max(1.0),
                    "roughness {r}, cosine {c}: table {} against {e}",
                    ALBEDO[i][j]
                );
            }
        }
    }

    #[test]
    fn the_quadrature_has_converged() {
        // Twice the cells each way moves no entry by more than 1e-3 (a few, the smoothest
        // sheens, seen near the horizon, where the lobe is narrowest).
        for (r, c) in [
            (0.05, 0.05),
            (0.2, 0.1),
            (0.5, 0.5),
            (1.0, 0.02),
            (0.3, 1.0),
        ] {
            let a = integrate_albedo(c, r, RINGS, SECTORS);
            let b = integrate_albedo(c, r, 2 * RINGS, 2 * SECTORS);
            assert!(
                (a - b).abs() < 1e-3,
                "roughness {r}, cosine {c}: {a} against {b}"
            );
        }
    }

    #[test]
    fn the_brdf_is_the_extensions() {
        // The extension's formulas evaluated apart, in f64 (Python): D, V and their product.
        for (r, nh, ci, co, want) in [
            (0.5, 0.6, 0.3, 0.8, 0.095_631_53),
            (1.0, 0.5, 0.2, 0.9, 0.153_280_36),
        ] {
            let f = brdf(r, nh, ci, co);
            assert!((f - want).abs() < 1e-5 * want, "{f} against {want}");
        }
        // Symmetric in the two directions.
        assert_eq!(brdf(0.7, 0.5, 0.2, 0.9), brdf(0.7, 0.5, 0.9, 0.2));
    }

    #[test]
    fn albedo_reads_the_table_and_between() {
        assert_eq!(albedo(1.0, 1.0), ALBEDO[ROUGHNESSES - 1][COSINES - 1]);
        assert_eq!(albedo(0.0, 0.0), ALBEDO[0][0]);
        // Halfway between two columns, the mean of the two.
        let j = COSINES / 2;
        let c = (j as f32 + 0.5) / (COSINES - 1) as f32;
        let i = ROUGHNESSES - 1;
        let mean = 0.5 * (ALBEDO[i][j] + ALBEDO[i][j + 1]);
        assert!((albedo(c, 1.0) - mean).abs() < 1e-6);
        // Out of range and NaN are clamped, never read past the table.
        assert_eq!(albedo(2.0, 3.0), albedo(1.0, 1.0));
        assert_eq!(albedo(f32::NAN, f32::NAN), albedo(0.0, 0.0));
    }

    #[test]
    fn the_sheen_reflects_at_most_what_arrives_and_more_when_rougher() {
        // A white sheen seen from the normal: a dim veil (the fibres stand along the normal);
        // rougher fibres lean further and reflect more.
        let e: Vec<f32> = [0.3, 0.5, 0.7, 1.0]
            .iter()
            .map(|&r| albedo(1.0, r))
            .collect();
        assert!(e.windows(2).all(|w| w[0] < w[1]), "{e:?}");
        assert!(e.iter().all(|&x| x > 0.0 && x < 1.0), "{e:?}");
        // From roughness 0.2 every entry is a fraction of the light; smoother sheens seen at
        // the horizon reach past 1 (the scaling clamps the lobes under them to nothing there).
        for (i, row) in ALBEDO.iter().enumerate() {
            for &x in row {
                assert!((0.0..2.0).contains(&x), "{x}");
                assert!(table_roughness(i) < 0.2 || x < 1.0, "{x}");
            }
        }
    }

    #[test]
    fn the_layer_dims_what_is_under_it_by_its_albedo() {
        let s = Sheen::new(Vec3::new(0.2, 0.8, 0.4), 0.5);
        let e = albedo(0.7, 0.5).max(albedo(0.3, 0.5));
        assert!((s.scaling(0.3, 0.7) - (1.0 - 0.8 * e)).abs() < 1e-6);
        assert_eq!(s.scaling(0.3, 0.7), s.scaling(0.7, 0.3));
        assert_eq!(Sheen::NONE.scaling(0.3, 0.7), 1.0);
        assert!(!Sheen::NONE.is_some());
        assert_eq!(Sheen::NONE.eval(Vec3::Z, Vec3::Z, Vec3::Z), Vec3::ZERO);
        // Below the surface: nothing.
        let under = Vec3::new(0.0, 0.6, -0.8);
        assert_eq!(s.eval(Vec3::Z, under, Vec3::Z), Vec3::ZERO);
        // Sheen is brightest where light and view both graze the surface (back-scattering
        // fibres), dimmest seen and lit along the normal.
        let graze = Vec3::new(0.98, 0.0, 0.2).normalize();
        let f = |wi, wo| s.eval(Vec3::Z, wi, wo).y;
        assert!(f(graze, graze) > 5.0 * f(Vec3::Z, Vec3::Z));
        assert_eq!(
            Sheen::new(Vec3::new(-1.0, f32::NAN, 0.5), f32::NAN).color.x,
            0.0
        );
    }
}
